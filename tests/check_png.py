#!/usr/bin/env python3
"""Independent check of the PNG and APNG files written by examples/common/pn_png.h (used by
tests/test_render.c). Standard library only: the chunks are parsed here, every CRC is checked
with zlib.crc32, image data is inflated by zlib (which also checks the Adler-32) and the PNG
filters are undone here, then the pixels are compared with the raw RGB the test wrote.

  check_png.py IMAGE.png IMAGE.rgb           a still image: RGB8, the raw bytes must match
  check_png.py --apng ANIM.png FRAMES.rgb N  an animation of N frames (FRAMES.rgb holds them
                                             one after another): acTL, fcTL/fdAT sequence
                                             numbers, frame count, every frame's pixels
  check_png.py --zlib DATA.z DATA.raw        a bare zlib stream must inflate to DATA.raw
Prints one line per file; exit status 0 when everything holds.
"""
import struct
import sys
import zlib


def chunks(data):
    """(type, payload) of every chunk; raises on a bad signature, CRC or truncation."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("bad PNG signature")
    pos, out = 8, []
    while pos < len(data):
        if pos + 12 > len(data):
            raise ValueError("truncated chunk header at %d" % pos)
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + n]
        if len(body) != n or pos + 12 + n > len(data):
            raise ValueError("truncated %r chunk" % kind)
        (crc,) = struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])
        if zlib.crc32(kind + body) & 0xFFFFFFFF != crc:
            raise ValueError("CRC mismatch in %r chunk at %d" % (kind, pos))
        out.append((kind.decode("latin-1"), body))
        pos += 12 + n
        if kind == b"IEND":
            break
    if pos != len(data):
        raise ValueError("%d bytes after IEND" % (len(data) - pos))
    if not out or out[0][0] != "IHDR" or out[-1][0] != "IEND":
        raise ValueError("IHDR must come first and IEND last")
    return out


def inflate(z):
    """zlib stream to bytes; the whole stream must be used, the checksum must hold."""
    d = zlib.decompressobj()
    raw = d.decompress(z) + d.flush()
    if not d.eof:
        raise ValueError("zlib stream ends early")
    if d.unused_data:
        raise ValueError("%d bytes after the zlib stream" % len(d.unused_data))
    return raw


def unfilter(raw, w, h, bpp=3):
    """Undo the per-row filters (PNG spec 9.2: None, Sub, Up, Average, Paeth)."""
    stride = w * bpp
    if len(raw) != h * (stride + 1):
        raise ValueError("inflated %d bytes, expected %d" % (len(raw), h * (stride + 1)))
    out = bytearray(h * stride)
    prev = bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        if f == 0:
            pass
        elif f == 1:
            for i in range(bpp, stride):
                line[i] = (line[i] + line[i - bpp]) & 255
        elif f == 2:
            for i in range(stride):
                line[i] = (line[i] + prev[i]) & 255
        elif f == 3:
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                line[i] = (line[i] + ((a + prev[i]) >> 1)) & 255
        elif f == 4:
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pr = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[i] = (line[i] + pr) & 255
        else:
            raise ValueError("row %d: unknown filter %d" % (y, f))
        out[y * stride:(y + 1) * stride] = line
        prev = line
    return bytes(out)


def header(ch):
    w, h, depth, color, comp, filt, inter = struct.unpack(">IIBBBBB", ch[0][1])
    if (depth, color, comp, filt, inter) != (8, 2, 0, 0, 0):
        raise ValueError("expected 8-bit RGB, deflate, adaptive filters, no interlace")
    return w, h


def compare(got, want, what):
    if got != want:
        first = next(i for i in range(min(len(got), len(want))) if got[i] != want[i]) \
            if len(got) == len(want) else -1
        raise ValueError("%s: pixels differ (sizes %d/%d, first difference at byte %d)"
                         % (what, len(got), len(want), first))


def check_still(png, rgb):
    data = open(png, "rb").read()
    ch = chunks(data)
    w, h = header(ch)
    z = b"".join(body for kind, body in ch if kind == "IDAT")
    compare(unfilter(inflate(z), w, h), open(rgb, "rb").read(), png)
    return "%s: %dx%d, %d bytes (%.2f%% of raw), CRCs, zlib and pixels ok" % (
        png, w, h, len(data), 100.0 * len(data) / (3 * w * h))


def check_apng(png, rgb, nframes):
    data = open(png, "rb").read()
    ch = chunks(data)
    w, h = header(ch)
    raw = open(rgb, "rb").read()
    size = 3 * w * h
    if len(raw) != nframes * size:
        raise ValueError("raw file holds %d bytes, expected %d frames" % (len(raw), nframes))
    actl = [body for kind, body in ch if kind == "acTL"]
    if len(actl) != 1:
        raise ValueError("expected one acTL chunk")
    frames, plays = struct.unpack(">II", actl[0])
    if frames != nframes or plays != 0:
        raise ValueError("acTL says %d frames, %d plays; expected %d, 0" % (frames, plays, nframes))
    if [k for k, _ in ch].index("acTL") > [k for k, _ in ch].index("IDAT"):
        raise ValueError("acTL must come before IDAT")
    # walk the frames: fcTL, then IDAT (frame 0) or fdAT chunks; sequence numbers 0, 1, 2, ...
    seq, cur, got = 0, None, []
    for kind, body in ch:
        if kind == "fcTL":
            if cur is not None:
                got.append(cur)
            s, fw, fh, fx, fy, dn, dd, dispose, blend = struct.unpack(">IIIIIHHBB", body)
            if s != seq:
                raise ValueError("fcTL sequence %d, expected %d" % (s, seq))
            seq += 1
            if (fw, fh, fx, fy) != (w, h, 0, 0) or dd == 0 or dispose > 2 or blend > 1:
                raise ValueError("fcTL %d: bad region or timing" % s)
            cur = [len(got), b""]
        elif kind == "IDAT":
            if cur is None or cur[0] != 0:
                raise ValueError("IDAT outside the first frame")
            cur[1] += body
        elif kind == "fdAT":
            (s,) = struct.unpack(">I", body[:4])
            if s != seq:
                raise ValueError("fdAT sequence %d, expected %d" % (s, seq))
            seq += 1
            if cur is None or cur[0] == 0:
                raise ValueError("fdAT in the first frame")
            cur[1] += body[4:]
    if cur is not None:
        got.append(cur)
    if len(got) != nframes:
        raise ValueError("%d frames found, %d expected" % (len(got), nframes))
    for i, (_, z) in enumerate(got):
        compare(unfilter(inflate(z), w, h), raw[i * size:(i + 1) * size], "%s frame %d" % (png, i))
    return "%s: %dx%d, %d frames, sequence 0..%d, %d bytes, CRCs, zlib and pixels ok" % (
        png, w, h, nframes, seq - 1, len(data))


def check_zlib(zfile, rawfile):
    z = open(zfile, "rb").read()
    compare(inflate(z), open(rawfile, "rb").read(), zfile)
    return "%s: %d bytes inflate to the %d of %s" % (zfile, len(z), len(open(rawfile, "rb").read()), rawfile)


def main(argv):
    try:
        if len(argv) == 4 and argv[1] == "--zlib":
            print(check_zlib(argv[2], argv[3]))
        elif len(argv) == 5 and argv[1] == "--apng":
            print(check_apng(argv[2], argv[3], int(argv[4])))
        elif len(argv) == 3:
            print(check_still(argv[1], argv[2]))
        else:
            print(__doc__)
            return 2
    except (ValueError, OSError, zlib.error, struct.error) as e:
        print("check_png: FAIL: %s" % e)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
