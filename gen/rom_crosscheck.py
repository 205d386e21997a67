#!/usr/bin/python3
"""Reference values of a generated reduced-order model, from its header, for the C test.

    /usr/bin/python3 gen/rom_crosscheck.py SCENE [--header models/rom_SCENE.h]
                                           [--out build/rom_SCENE_ref.txt]

Parses the weights and normalisations back out of models/rom_SCENE.h (not the checkpoint: this
checks the header), evaluates g(X, xhat) = out_mean + out_std net(Xn, xhat) and its Jacobians
with torch float64 autograd at 64 deterministic inputs (X uniform in the in_lo..in_hi box,
xhat = latent_rest + 0.5 N(0, 1) latent_std, from a generator seeded with 20230601), and writes
a text file: first line "dim latent count", then one line per input with X (dim), xhat
(latent), g (dim), dg/dX (dim x dim, row-major, row = output component) and dg/dxhat
(dim x latent, row-major), every number %.17g.
"""
import argparse
import os
import re
import sys

import torch

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
COUNT = 64
SEED = 20230601
FIELDS = ["format_version", "name", "dim", "latent", "n_layers", "width", "weight", "bias", "activation", "in_lo",
          "in_hi", "out_mean", "out_std", "latent_rest", "latent_std", "cell_m", "origin_m", "cells", "occupied",
          "youngs_pa", "poisson", "density_kg_m3", "dx_m", "per_axis", "frame_dt_s"]
# format 2 appends the arrays' lengths (checked here against the arrays as parsed)
FIELDS_2 = FIELDS + ["width_count", "weight_count", "bias_count", "latent_rest_count", "latent_std_count",
                     "occupied_count"]


def strip_comments(s):
    return re.sub(r"/\*.*?\*/", " ", s, flags=re.S)


def split_top(s):
    """Split an initializer body at the commas outside braces and quotes."""
    out, depth, cur, quote = [], 0, "", False
    for ch in s:
        if ch == '"':
            quote = not quote
        if not quote:
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
            elif ch == "," and depth == 0:
                out.append(cur.strip())
                cur = ""
                continue
        cur += ch
    if cur.strip():
        out.append(cur.strip())
    return out


def parse_header(path):
    text = strip_comments(open(path).read())
    arrays = {}
    for m in re.finditer(r"static const (double|int|unsigned char) (\w+)\[(\d+)\] = \{(.*?)\};", text, re.S):
        ctype, name, n, body = m.group(1), m.group(2), int(m.group(3)), m.group(4)
        vals = [v for v in (t.strip() for t in body.split(",")) if v]
        if len(vals) != n:
            sys.exit("%s: %s has %d values, declared %d" % (path, name, len(vals), n))
        arrays[name] = [float(v) for v in vals] if ctype == "double" else [int(v) for v in vals]
    ptrs = {}
    for m in re.finditer(r"static const double \*const (\w+)\[(\d+)\] = \{(.*?)\};", text, re.S):
        ptrs[m.group(1)] = [t.strip() for t in m.group(3).split(",") if t.strip()]
    m = re.search(r"static const pn_rom_model (\w+) = \{(.*?)\};", text, re.S)
    if not m:
        sys.exit("%s: no pn_rom_model initializer" % path)
    vals = split_top(m.group(2))
    fields = FIELDS_2 if len(vals) == len(FIELDS_2) else FIELDS
    if len(vals) != len(fields):
        sys.exit("%s: the initializer has %d fields, pn_rom_model %d" % (path, len(vals), len(FIELDS_2)))
    f = dict(zip(fields, vals))
    num = lambda s: [float(t) for t in s.strip("{} ").split(",")]  # noqa: E731
    model = dict(name=f["name"].strip('"'), dim=int(f["dim"]), latent=int(f["latent"]), n_layers=int(f["n_layers"]),
                 activation=int(f["activation"]), format_version=int(f["format_version"]))
    for k in ("in_lo", "in_hi", "out_mean", "out_std"):
        model[k] = num(f[k])
    model["width"] = arrays[f["width"]]
    model["weight"] = [arrays[n] for n in ptrs[f["weight"]]]
    model["bias"] = [arrays[n] for n in ptrs[f["bias"]]]
    model["latent_rest"] = arrays[f["latent_rest"]]
    model["latent_std"] = arrays[f["latent_std"]]
    d, K, L, w = model["dim"], model["latent"], model["n_layers"], model["width"]
    if model["activation"] != 1 or len(w) != L + 1 or w[0] != d + K or w[-1] != d or len(model["weight"]) != L:
        sys.exit("%s: inconsistent sizes (activation %d, widths %s, %d layers)" % (path, model["activation"], w, L))
    for l in range(L):
        if len(model["weight"][l]) != w[l] * w[l + 1] or len(model["bias"][l]) != w[l + 1]:
            sys.exit("%s: layer %d has the wrong weight count" % (path, l))
    if fields is FIELDS_2:  # the declared lengths against the arrays themselves
        ints = lambda s: [int(t) for t in s.strip("{} ").split(",") if t.strip()]  # noqa: E731
        wc, bc = ints(f["weight_count"]), ints(f["bias_count"])
        if (int(f["width_count"]) != len(w) or wc[:L] != [len(x) for x in model["weight"]] or
                bc[:L] != [len(x) for x in model["bias"]] or int(f["latent_rest_count"]) != len(model["latent_rest"]) or
                int(f["latent_std_count"]) != len(model["latent_std"])):
            sys.exit("%s: the format-2 lengths disagree with the arrays" % path)
    return model


def g_of(model):
    d, L, w = model["dim"], model["n_layers"], model["width"]
    W = [torch.tensor(model["weight"][l], dtype=torch.float64).reshape(w[l + 1], w[l]) for l in range(L)]
    b = [torch.tensor(model["bias"][l], dtype=torch.float64) for l in range(L)]
    lo = torch.tensor(model["in_lo"][:d], dtype=torch.float64)
    hi = torch.tensor(model["in_hi"][:d], dtype=torch.float64)
    mean = torch.tensor(model["out_mean"][:d], dtype=torch.float64)
    std = torch.tensor(model["out_std"][:d], dtype=torch.float64)

    def g(X, xhat):
        a = torch.cat([2 * (X - lo) / (hi - lo) - 1, xhat], -1)
        for l in range(L):
            a = a @ W[l].T + b[l]
            if l + 1 < L:
                a = torch.nn.functional.elu(a)
        return mean + std * a
    return g


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--header", help="[models/rom_SCENE.h]")
    ap.add_argument("--out", help="[build/rom_SCENE_ref.txt]")
    a = ap.parse_args()
    torch.set_num_threads(1)
    ident = re.sub(r"[^A-Za-z0-9_]", "_", a.scene)
    header = a.header or os.path.join(ROOT, "models", "rom_%s.h" % ident)
    out = a.out or os.path.join(ROOT, "build", "rom_%s_ref.txt" % ident)
    model = parse_header(header)
    d, K = model["dim"], model["latent"]
    g = g_of(model)
    gen = torch.Generator().manual_seed(SEED)
    lo = torch.tensor(model["in_lo"][:d], dtype=torch.float64)
    hi = torch.tensor(model["in_hi"][:d], dtype=torch.float64)
    X = lo + (hi - lo) * torch.rand(COUNT, d, dtype=torch.float64, generator=gen)
    xhat = (torch.tensor(model["latent_rest"], dtype=torch.float64) +
            0.5 * torch.randn(COUNT, K, dtype=torch.float64, generator=gen) *
            torch.tensor(model["latent_std"], dtype=torch.float64))
    Xr, xr = X.clone().requires_grad_(True), xhat.clone().requires_grad_(True)
    y = g(Xr, xr)
    JX, JL = [], []
    for i in range(d):   # row i of the Jacobians: each output depends on its own input only
        gX, gL = torch.autograd.grad(y[:, i].sum(), (Xr, xr), retain_graph=True)
        JX.append(gX)
        JL.append(gL)
    JX = torch.stack(JX, 1)    # (count, d out, d in)
    JL = torch.stack(JL, 1)    # (count, d out, K)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out, "w") as f:
        f.write("%d %d %d\n" % (d, K, COUNT))
        for p in range(COUNT):
            vals = (X[p].tolist() + xhat[p].tolist() + y[p].tolist() + JX[p].reshape(-1).tolist() +
                    JL[p].reshape(-1).tolist())
            f.write(" ".join("%.17g" % v for v in vals) + "\n")
    print("%s: %d inputs from %s -> %s" % (model["name"], COUNT, header, out))


if __name__ == "__main__":
    main()
