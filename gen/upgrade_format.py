#!/usr/bin/python3
"""Rewrite format-1, -2 or -3 model headers (models/pn_model_*.h) as format 4, from their own
arrays.

    /usr/bin/python3 gen/upgrade_format.py models/pn_model_*.h

Format 2 adds the lengths of the weight and bias arrays to the pn_mlp initializer (plastinet.h
checks them against the layer sizes, so a malformed network is refused instead of read past).
The lengths are read from the arrays' declarations and must equal the products of the layer
sizes. Format 3 appends the material-parameter inputs of a conditioned model and the output
form: none and linear for every model made before it. Format 4 appends the base energy: none
before it. The weights, the banner and everything else stay byte for byte: the result is what
gen/export.py (FORMAT_VERSION 4) writes from the same trained network, without retraining.
Needs no torch. Format-4 headers are left alone.
"""
import re
import sys


def upgrade(path):
    src = open(path).read()
    if "Format version 4 (PN_MODEL_FORMAT_VERSION)" in src:
        return "already format 4"
    if "Format version 3 (PN_MODEL_FORMAT_VERSION)" in src:
        return upgrade_3_to_4(path, src)
    if "Format version 2 (PN_MODEL_FORMAT_VERSION)" in src:
        return upgrade_2_to_3(path, src)
    decl = {m.group(1): int(m.group(2)) for m in re.finditer(r"static const float (\w+)\[(\d+)\]", src)}
    init = re.search(r"\{(\d+), \{([\d, ]+)\}, (PN_ACTIVATION_\w+), \{([\w, ]+)\}, \{([\w, ]+)\}\}", src)
    if not init or "Format version 1 (PN_MODEL_FORMAT_VERSION)" not in src:
        raise SystemExit("%s: not a format-1 model header" % path)
    n_layers = int(init.group(1))
    sizes = [int(v) for v in init.group(2).split(",")]
    weights = [v.strip() for v in init.group(4).split(",")][:n_layers]
    biases = [v.strip() for v in init.group(5).split(",")][:n_layers]
    wc, bc = [], []
    for l in range(n_layers):
        if decl[weights[l]] != sizes[l] * sizes[l + 1] or decl[biases[l]] != sizes[l + 1]:
            raise SystemExit("%s: layer %d arrays disagree with the sizes" % (path, l))
        wc.append(decl[weights[l]])
        bc.append(decl[biases[l]])
    pad = lambda xs: ", ".join(str(v) for v in xs + [0] * (8 - len(xs)))  # noqa: E731
    new_init = init.group(0)[:-1] + ", {%s}, {%s}}" % (pad(wc), pad(bc))
    out = src.replace(init.group(0), new_init)
    out = out.replace("Format version 1 (PN_MODEL_FORMAT_VERSION)", "Format version 2 (PN_MODEL_FORMAT_VERSION)")
    head, sep, tail = out.partition("static const pn_model m = {\n        1,")
    if not sep:
        raise SystemExit("%s: pn_model initializer not found" % path)
    open(path, "w").write(head + "static const pn_model m = {\n        2," + tail)
    return "format 2 (%d layers); " % n_layers + upgrade_2_to_3(path, open(path).read())


def upgrade_2_to_3(path, src):
    head, sep, tail = src.partition("static const pn_model m = {\n        2,")
    end = re.search(r'(\n        "[^"\n]*")\};\n', tail)
    if not sep or not end:
        raise SystemExit("%s: pn_model initializer not found" % path)
    tail = tail[:end.end(1)] + (",\n        0,\n        {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}},"
                                "\n        PN_MODEL_OUTPUT_LINEAR") + tail[end.end(1):]
    out = head + "static const pn_model m = {\n        3," + tail
    out = out.replace("Format version 2 (PN_MODEL_FORMAT_VERSION)", "Format version 3 (PN_MODEL_FORMAT_VERSION)")
    open(path, "w").write(out)
    return "format 3; " + upgrade_3_to_4(path, out)


def upgrade_3_to_4(path, src):
    head, sep, tail = src.partition("static const pn_model m = {\n        3,")
    end = re.search(r"\n        (PN_MODEL_OUTPUT_\w+)\};\n", tail)
    if not sep or not end:
        raise SystemExit("%s: pn_model initializer not found" % path)
    tail = tail[:end.end(1)] + ",\n        PN_MODEL_BASE_NONE" + tail[end.end(1):]
    out = head + "static const pn_model m = {\n        4," + tail
    out = out.replace("Format version 3 (PN_MODEL_FORMAT_VERSION)", "Format version 4 (PN_MODEL_FORMAT_VERSION)")
    open(path, "w").write(out)
    return "format 4"


if __name__ == "__main__":
    for p in sys.argv[1:]:
        print(p, upgrade(p))
