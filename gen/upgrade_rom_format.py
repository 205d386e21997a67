#!/usr/bin/python3
"""Rewrite format-1 reduced-order model headers (models/rom_*.h) as format 2, from their own
arrays.

    /usr/bin/python3 gen/upgrade_rom_format.py models/rom_*.h

Format 2 appends the lengths of the model's arrays to the pn_rom_model initializer (width_count,
weight_count[8], bias_count[8], latent_rest_count, latent_std_count, occupied_count), which
plastinet_rom.h checks against the sizes the arrays must have, so a malformed model is refused
instead of read past. Each length is read from its array's declaration in the header and must
equal the size the widths, the latent count and the occupancy cells give; anything else stops
the conversion. The weights, the banner's text and everything else stay byte for byte: the
result is what gen/rom_export.py (FORMAT_VERSION 2) writes from the same trained network,
without retraining. Needs no torch. Format-2 headers are left alone.
"""
import re
import sys

MAX_LAYERS = 8  # PN_ROM_MAX_LAYERS


def upgrade(path):
    src = open(path).read()
    if "Format version 2 (PN_ROM_FORMAT_VERSION)" in src:
        return "already format 2"
    if "Format version 1 (PN_ROM_FORMAT_VERSION)" not in src:
        raise SystemExit("%s: not a format-1 reduced-order model header" % path)
    decl = {m.group(2): (m.group(1), int(m.group(3)))
            for m in re.finditer(r"static const (double|int|unsigned char) (\w+)\[(\d+)\] = \{", src)}
    init = re.search(r"static const pn_rom_model (\w+) = \{\n    1,\n(.*?)\};\n", src, re.S)
    if not init:
        raise SystemExit("%s: pn_rom_model initializer not found" % path)
    fields = [f.strip() for f in re.split(r",\n    ", init.group(2).strip())]
    if len(fields) != 24:
        raise SystemExit("%s: %d fields after the format version, a format-1 model has 24" % (path, len(fields)))
    dim, latent, n_layers = int(fields[1]), int(fields[2]), int(fields[3])
    width_name, weight_name, bias_name = fields[4], fields[5], fields[6]
    rest_name, std_name, cells, occ_name = fields[12], fields[13], fields[16], fields[17]
    widths = [int(v) for v in re.search(r"static const int %s\[\d+\] = \{([^}]*)\}" % width_name, src).group(1)
              .replace("\n", " ").split(",") if v.strip()]
    if decl[width_name][1] != n_layers + 1 or len(widths) != n_layers + 1:
        raise SystemExit("%s: %s has %d entries, n_layers %d needs %d" % (path, width_name, decl[width_name][1], n_layers,
                                                                          n_layers + 1))
    if widths[0] != dim + latent or widths[-1] != dim:
        raise SystemExit("%s: widths %s disagree with dim %d and latent %d" % (path, widths, dim, latent))

    def pointers(name):
        m = re.search(r"static const double \*const %s\[(\d+)\] = \{([^}]*)\};" % name, src)
        names = [v.strip() for v in m.group(2).split(",")]
        if int(m.group(1)) != n_layers or len(names) != n_layers:
            raise SystemExit("%s: %s does not hold n_layers = %d arrays" % (path, name, n_layers))
        return names

    wc, bc = [], []
    for l, (wn, bn) in enumerate(zip(pointers(weight_name), pointers(bias_name))):
        if decl[wn][1] != widths[l] * widths[l + 1] or decl[bn][1] != widths[l + 1]:
            raise SystemExit("%s: layer %d arrays (%d, %d) disagree with the widths %d x %d" % (
                path, l, decl[wn][1], decl[bn][1], widths[l + 1], widths[l]))
        wc.append(decl[wn][1])
        bc.append(decl[bn][1])
    counts = []
    for name in (rest_name, std_name):
        if name == "NULL":
            counts.append(0)
        elif decl[name][1] != latent:
            raise SystemExit("%s: %s has %d entries, latent is %d" % (path, name, decl[name][1], latent))
        else:
            counts.append(latent)
    c = [int(v) for v in cells.strip("{}").split(",")]
    n_cells = c[0] * c[1] * c[2] if c[0] > 0 else 0
    occ = 0 if occ_name == "NULL" else decl[occ_name][1]
    if occ != n_cells:
        raise SystemExit("%s: %s has %d bytes, cells %s need %d" % (path, occ_name, occ, cells, n_cells))
    pad = lambda xs: ", ".join(str(v) for v in xs + [0] * (MAX_LAYERS - len(xs)))  # noqa: E731
    extra = [str(n_layers + 1), "{%s}" % pad(wc), "{%s}" % pad(bc), str(counts[0]), str(counts[1]), str(occ)]
    body = "static const pn_rom_model %s = {\n    2,\n%s,\n    %s};\n" % (init.group(1), init.group(2).rstrip(),
                                                                       ",\n    ".join(extra))
    out = src[:init.start()] + body + src[init.end():]
    out = out.replace("Format version 1 (PN_ROM_FORMAT_VERSION)", "Format version 2 (PN_ROM_FORMAT_VERSION)", 1)
    open(path, "w").write(out)
    return "format 2 (%d layers, %d occupancy cells)" % (n_layers, occ)


if __name__ == "__main__":
    for p in sys.argv[1:]:
        print(p, upgrade(p))
