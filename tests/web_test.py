#!/usr/bin/env python3
"""Headless Chromium test of the browser demo (examples/web, built by `make web` into build/web).

Python 3 standard library only. Serves build/web on 127.0.0.1 (http.server in a thread), starts
Debian's chromedriver and drives /usr/bin/chromium through the W3C WebDriver protocol (HTTP/JSON
with urllib): loads the page, waits until the demo runs and the sand column has settled, takes a
screenshot, pushes the collider through the sand with W3C pointer actions, takes a second
screenshot, and checks that the sand moved (particle positions the page exposes, and pixels),
that the snow button works, that the console has no errors, the page no uncaught exceptions and
the simulation no failed steps, and that the frame time is shown. Screenshots and logs go to build/web_test/. One line per check; the last line is
"N passed, N failed"; exit status 0 when every check passed.
Usage: tests/web_test.py [--keep-open SECONDS]   (env: CHROMIUM, CHROMEDRIVER override the paths)
"""
import base64
import functools
import http.server
import json
import math
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WEB = os.path.join(ROOT, "build", "web")
OUT = os.path.join(ROOT, "build", "web_test")
CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("CHROMEDRIVER", "/usr/bin/chromedriver")
GLOBAL_TIMEOUT_S = 180

results = []


def check(name, ok, detail=""):
    results.append(ok)
    print(("ok   " if ok else "FAIL ") + "web: " + name + (" (" + detail + ")" if detail else ""), flush=True)


class Timeout(Exception):
    """A wait for the page timed out."""


class GlobalTimeout(Exception):
    """The whole test ran out of time (not a Timeout: waits must not swallow it)."""


def free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ---- PNG decoding: the independent decoder of the renderer's tests (tests/check_png.py) ------

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_png  # noqa: E402


def png_decode(data):
    """(width, height, channels, rows) of an 8-bit greyscale/RGB/RGBA non-interlaced PNG; rows
    is a list of bytes objects, one per row, without the filter byte."""
    ch = check_png.chunks(data)
    w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", ch[0][1])
    if depth != 8 or interlace or ctype not in (0, 2, 6):
        raise ValueError("unsupported PNG (depth %d, colour type %d, interlace %d)" % (depth, ctype, interlace))
    n = {0: 1, 2: 3, 6: 4}[ctype]
    pixels = check_png.unfilter(check_png.inflate(b"".join(b for k, b in ch if k == "IDAT")), w, h, n)
    return w, h, n, [bytes(pixels[y * w * n:(y + 1) * w * n]) for y in range(h)]


def changed_pixels(a, b, rect):
    """Pixels inside rect (x0, y0, x1, y1) whose RGB differs by more than 60 in sum, and the
    pixel count of rect."""
    (wa, ha, cha, ra), (wb, hb, chb, rb) = a, b
    x0, y0 = max(0, rect[0]), max(0, rect[1])
    x1, y1 = min(wa, wb, rect[2]), min(ha, hb, rect[3])
    changed = 0
    for y in range(y0, y1):
        la, lb = ra[y], rb[y]
        for x in range(x0, x1):
            i, j = x * cha, x * chb
            if abs(la[i] - lb[j]) + abs(la[i + 1] - lb[j + 1]) + abs(la[i + 2] - lb[j + 2]) > 60:
                changed += 1
    return changed, max(0, x1 - x0) * max(0, y1 - y0)


# ---- WebDriver over urllib ---------------------------------------------------------------------

class WebDriver:
    def __init__(self, port):
        self.base = "http://127.0.0.1:%d" % port
        self.session = None

    def call(self, method, path, body=None, timeout=60):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method,
                                     headers={"Content-Type": "application/json; charset=utf-8"})
        try:
            with urllib.request.urlopen(req, timeout=timeout) as r:
                reply = json.loads(r.read().decode() or "{}")
        except urllib.error.HTTPError as e:
            text = e.read().decode(errors="replace")
            try:
                v = json.loads(text)["value"]
                text = "%s: %s" % (v.get("error"), v.get("message", "").splitlines()[0] if v.get("message") else "")
            except (ValueError, KeyError, TypeError, AttributeError):
                pass
            raise RuntimeError("%s %s -> HTTP %d: %s" % (method, path, e.code, text[:400])) from None
        return reply.get("value")

    def s(self, method, path, body=None, timeout=60):
        return self.call(method, "/session/%s%s" % (self.session, path), body, timeout)

    def js(self, script, *args):
        return self.s("POST", "/execute/sync", {"script": script, "args": list(args)})

    def wait(self, script, timeout_s, what, interval=0.2):
        t0 = time.monotonic()
        while True:
            v = self.js(script)
            if v:
                return v
            if time.monotonic() - t0 > timeout_s:
                raise Timeout("timed out after %.0f s waiting for %s" % (timeout_s, what))
            time.sleep(interval)


def run(wd, url):
    os.makedirs(OUT, exist_ok=True)
    wd.s("POST", "/url", {"url": url}, timeout=90)
    t_load = time.monotonic()
    frames = wd.wait("return document.documentElement.dataset.running === 'true' && window.demo && window.demo.frames",
                     45, "the demo to run (html[data-running])")
    check("page loads and the demo runs", True, "%d frames after %.1f s" % (frames, time.monotonic() - t_load))

    # let the column collapse into a heap and come to rest
    t0 = time.monotonic()
    try:
        wd.wait("return window.demo.maxSpeed < 0.05 && window.demo.frames > 30", 30, "the sand to settle", 0.3)
        settled = "settled after %.1f s" % (time.monotonic() - t0)
    except Timeout:  # a slow machine: push the moving heap anyway
        settled = "still moving at %.2f m/s after 30 s" % wd.js("return window.demo.maxSpeed")
    box_w, box_h, floor_y = wd.js("return window.demo.box")
    radius = wd.js("return window.demo.collider[2]")
    before = wd.js("return window.demo.positions()")
    shot_a = base64.b64decode(wd.s("GET", "/screenshot"))
    with open(os.path.join(OUT, "before.png"), "wb") as f:
        f.write(shot_a)

    # push: press in free space above the heap's left flank, dig in, sweep right through the
    # sand. Between pointer moves wait until the collider has caught up (it moves at a bounded
    # speed in simulated time, and simulated time may run slower than real time), at most 50 s
    # in all: after that the pointer goes on without waiting.
    y_dig = floor_y + 0.13
    path = [(0.55, min(box_h - 0.3, 1.2))] + [(0.6, y_dig)] + \
           [(0.6 + k * (box_w - 1.2) / 12, y_dig) for k in range(1, 13)]
    client = [wd.js("return window.demo.toClient(arguments[0], arguments[1])", x, y) for x, y in path]
    mouse = lambda acts: wd.s("POST", "/actions", {"actions": [
        {"type": "pointer", "id": "mouse", "parameters": {"pointerType": "mouse"}, "actions": acts}]})
    pt = lambda c: {"type": "pointerMove", "origin": "viewport", "x": int(round(c[0])), "y": int(round(c[1])),
                    "duration": 60}
    t_push = time.monotonic()
    mouse([pt(client[0]), {"type": "pointerDown", "button": 0}])
    lag = []
    for (x, y), c in zip(path[1:], client[1:]):
        mouse([pt(c)])
        t1 = time.monotonic()
        try:
            wd.wait("const c = window.demo.collider; return Math.hypot(c[0] - %r, c[1] - %r) < 0.03" % (x, y),
                    max(0.0, min(10.0, t_push + 50 - t1)), "the collider to reach (%.2f, %.2f)" % (x, y), 0.05)
        except Timeout:
            pass
        lag.append(time.monotonic() - t1)
    mouse([{"type": "pointerUp", "button": 0}])
    wd.s("DELETE", "/actions")
    push_s = time.monotonic() - t_push
    f0 = wd.js("return window.demo.frames")
    wd.wait("return window.demo.frames > %d" % (f0 + 20), 30, "20 more frames")
    after = wd.js("return window.demo.positions()")
    shot_b = base64.b64decode(wd.s("GET", "/screenshot"))
    with open(os.path.join(OUT, "after.png"), "wb") as f:
        f.write(shot_b)

    # (1a) particles near the path of the pointer moved
    x_lo, x_hi = path[1][0], path[-1][0]
    near = moved = 0
    biggest = 0.0
    for i in range(0, min(len(before), len(after)) - 1, 2):
        xa, ya, xb, yb = before[i], before[i + 1], after[i], after[i + 1]
        if xa is None or ya is None:
            continue
        if not (x_lo - radius <= xa <= x_hi + radius and abs(ya - y_dig) <= radius):
            continue
        near += 1
        d = float("inf") if xb is None or yb is None else math.hypot(xb - xa, yb - ya)
        biggest = max(biggest, d)
        if d > 0.05:
            moved += 1
    check("sand moved where the pointer passed", near >= 50 and moved >= 0.3 * near,
          "%d of %d particles within the collider's sweep moved > 5 cm, largest %.2f m; %s; push %.1f s, "
          "slowest catch-up %.1f s" % (moved, near, biggest, settled, push_s, max(lag)))

    # (1b) and the pixels changed there: the canvas region of the screenshots
    rect = wd.js("const r = document.getElementById('view').getBoundingClientRect(), d = window.devicePixelRatio;"
                 "return [r.left * d, r.top * d, r.right * d, r.bottom * d].map(Math.round)")
    img_a, img_b = png_decode(shot_a), png_decode(shot_b)
    changed, total = changed_pixels(img_a, img_b, rect)
    frac = changed / total if total else 0
    check("screenshots differ in the sand region", frac > 0.01,
          "%.1f%% of the canvas pixels changed; build/web_test/before.png, after.png" % (100 * frac))

    # the snow button: the scene switches and runs (the checks below cover it too)
    wd.js("document.getElementById('snow').click()")
    f0 = wd.js("return window.demo.frames")
    wd.wait("return window.demo.frames > %d" % (f0 + 30), 30, "30 frames of snow")
    kind, count = wd.js("return [window.demo.kind, window.demo.particles]")
    shot_c = base64.b64decode(wd.s("GET", "/screenshot"))
    with open(os.path.join(OUT, "snow.png"), "wb") as f:
        f.write(shot_c)
    check("snow button switches the material", kind == 1 and count > 1000,
          "kind %s, %s particles; build/web_test/snow.png" % (kind, count))

    # (2) no console errors, no uncaught exceptions
    logs = wd.s("POST", "/se/log", {"type": "browser"}) or []
    with open(os.path.join(OUT, "console.log"), "w") as f:
        for e in logs:
            f.write("%s %s\n" % (e.get("level"), e.get("message")))
    severe = [e.get("message", "") for e in logs if e.get("level") == "SEVERE"]
    check("no console errors", not severe, "; ".join(severe)[:300] or "%d console entries" % len(logs))
    errors = wd.js("return window.demoErrors")
    check("no uncaught exceptions", errors == [], "; ".join(map(str, errors or []))[:300] if errors else "")
    failures, retried = wd.js("return [window.demo.failures, window.demo.retried]")
    check("no failed simulation steps", failures == 0,
          "%s frames failed and reset the scene, %s steps retried at half the step" % (failures, retried))

    # (3) the frame time is shown and finite
    text = wd.js("return document.getElementById('stats').textContent")
    sim = re.search(r"sim ([0-9.eE+-]+|NaN|Infinity) ms", text or "")
    draw = re.search(r"draw ([0-9.eE+-]+|NaN|Infinity) ms", text or "")
    ok = bool(sim and draw) and all(math.isfinite(float(m.group(1))) and float(m.group(1)) >= 0 for m in (sim, draw))
    check("frame time shown and finite", ok, (text or "no #stats text").strip())


def main():
    keep_open = 0
    if len(sys.argv) > 2 and sys.argv[1] == "--keep-open":
        keep_open = float(sys.argv[2])
    if not os.path.isfile(os.path.join(WEB, "index.html")) or not os.path.isfile(os.path.join(WEB, "demo.wasm")):
        check("build/web exists", False, "run make web first")
        print("0 passed, 1 failed")
        return 1
    for tool in (CHROMIUM, CHROMEDRIVER):
        if not os.access(tool, os.X_OK):
            check("%s found" % tool, False, "apt-get install -y chromium chromium-driver")
            print("0 passed, 1 failed")
            return 1
    os.makedirs(OUT, exist_ok=True)

    def on_alarm(signum, frame):
        raise GlobalTimeout("the whole test took more than %d s" % GLOBAL_TIMEOUT_S)

    signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(GLOBAL_TIMEOUT_S)
    t_start = time.monotonic()
    server = driver = wd = None
    profile = tempfile.mkdtemp(prefix="plastinet-web-test-")
    driver_log = open(os.path.join(OUT, "chromedriver.log"), "w")
    try:
        # the page server
        class Quiet(http.server.SimpleHTTPRequestHandler):
            def log_message(self, *args):
                pass

        Quiet.extensions_map = dict(Quiet.extensions_map, **{".wasm": "application/wasm", ".js": "text/javascript"})
        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Quiet, directory=WEB))
        threading.Thread(target=server.serve_forever, daemon=True).start()
        url = "http://127.0.0.1:%d/index.html" % server.server_address[1]

        # chromedriver, in its own process group so chromium goes with it
        port = free_port()
        driver = subprocess.Popen([CHROMEDRIVER, "--port=%d" % port], stdout=driver_log, stderr=subprocess.STDOUT,
                                  stdin=subprocess.DEVNULL, start_new_session=True)
        wd = WebDriver(port)
        t0 = time.monotonic()
        while True:
            try:
                if (wd.call("GET", "/status", timeout=5) or {}).get("ready"):
                    break
            except (OSError, RuntimeError):
                pass
            if driver.poll() is not None or time.monotonic() - t0 > 30:
                raise RuntimeError("chromedriver did not start (build/web_test/chromedriver.log)")
            time.sleep(0.1)
        args = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--user-data-dir=" + profile, "--window-size=1000,800"]
        caps = {"browserName": "chrome", "goog:chromeOptions": {"binary": CHROMIUM, "args": args},
                "goog:loggingPrefs": {"browser": "ALL"}}
        reply = wd.call("POST", "/session", {"capabilities": {"alwaysMatch": caps}}, timeout=90)
        wd.session = reply["sessionId"]
        run(wd, url)
        if keep_open:
            time.sleep(keep_open)
    except Exception as e:  # a stage failed: say which, then clean up
        check("test run", False, "%s: %s" % (type(e).__name__, e))
    finally:
        signal.alarm(0)
        if wd is not None and wd.session:
            try:
                wd.call("DELETE", "/session/" + wd.session, timeout=20)
            except Exception:
                pass
        if driver is not None:
            try:
                os.killpg(driver.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                driver.wait(10)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(driver.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                driver.wait(10)
        driver_log.close()
        if server is not None:
            server.shutdown()
            server.server_close()
        shutil.rmtree(profile, ignore_errors=True)
    passed = sum(1 for r in results if r)
    failed = len(results) - passed
    print("# %.1f s" % (time.monotonic() - t_start))
    print("%d passed, %d failed" % (passed, failed))
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
