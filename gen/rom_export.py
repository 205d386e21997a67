#!/usr/bin/python3
"""Write a trained reduced-order model (gen/rom_train.py) as the C header models/rom_SCENE.h.

    /usr/bin/python3 gen/rom_export.py SCENE [--data data/rom] [--ckpt gen/ckpt/rom_SCENE.pt]
                                       [--out models/rom_SCENE.h]

Reads the checkpoint and the snapshots, measures the model on every frame of the test
instances (and of the training instances) and writes the header: g's weights as static const
double arrays (%.17g: they round-trip), the normalisations, the latent of the rest state and
the spread of the training latents, the occupancy cells of the reference domain, the material
and the banner with the data, the training and the measured errors. plastinet_rom.h reads it.

Errors (relative L2 over all frames and points of a set of instances, xhat_n = e(x_n)):
  x       sqrt(sum |g(X, xhat_n) - x_n|^2 / sum |x_n|^2)                      (the paper's)
  x - c   the same with both relative to the centroid c of the reference points
  F       sqrt(sum |dg/dX(X, xhat_n) - F_n|_F^2 / sum |F_n|_F^2)
  v       sqrt(sum |dg/dxhat(X, xhat_n) (xhat_n+1 - xhat_n)/frame_dt - v_n|^2 / sum |v_n|^2), n < last
"""
import argparse
import math
import os
import re
import sys

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import rom_train as rt  # noqa: E402

FORMAT_VERSION = 2          # PN_ROM_FORMAT_VERSION
TRAIN_EVAL_POINTS = 4096    # training instances with more points: measured on the encoder subset
CHUNK = 65536               # points per evaluation call


def g17(x):
    x = float(x)
    if not math.isfinite(x):
        raise ValueError("non-finite value %r in the model" % x)
    return "%.17g" % x


def c_ident(s):
    return re.sub(r"[^A-Za-z0-9_]", "_", s)


def array(ctype, name, vals, fmt, per_line, sep=", "):
    vals = [fmt(v) for v in vals]
    lines = ["    " + sep.join(vals[i:i + per_line]) + "," for i in range(0, len(vals), per_line)]
    return "static const %s %s[%d] = {\n%s\n};\n" % (ctype, name, len(vals), "\n".join(lines))


def wrap(text, width=96, indent="   ", cont="     "):
    """Wrap words into banner lines."""
    out, line = [], indent
    for w in text.split(" "):
        if len(line) + len(w) + 1 > width and line.strip():
            out.append(line.rstrip())
            line = cont
        line += w + " "
    if line.strip():
        out.append(line.rstrip())
    return out


# ---- evaluation --------------------------------------------------------------------------------

def encode_frames(model, scene, inst, frames=None):
    """Latents (T, K) in float64 of the given frames of an instance (all by default)."""
    mean = model.out_mean.double().numpy()
    std = model.out_std.double().numpy()
    ks = range(inst.frames) if frames is None else frames
    rows = [((inst.x(k)[scene.enc_idx].astype(np.float64) - mean) / std).T for k in ks]
    lat = []
    with torch.no_grad():
        for i in range(0, len(rows), 64):
            lat.append(model.encode(torch.from_numpy(np.stack(rows[i:i + 64]))))
    return torch.cat(lat).double()


def encode_positions(model, X):
    mean, std = model.out_mean.double(), model.out_std.double()
    xn = ((torch.as_tensor(X, dtype=torch.float64) - mean) / std).T[None]
    with torch.no_grad():
        return model.encode(xn)[0].double()


def measure(model32, model64, scene, insts, frame_dt, max_points=None):
    """Sums for the relative errors over instances insts, all frames (the finite-difference
    velocity on frames n < last). g is evaluated in float32 (as the C fast path), the latents
    in float64, the sums in float64. Returns dict of errors and per-instance position errors."""
    tot = dict(ex=0.0, x2=0.0, xc2=0.0, eF=0.0, F2=0.0, ev=0.0, v2=0.0, efd=0.0)
    per_inst = []
    for inst in insts:
        if max_points is not None and scene.n_points > max_points:
            idx = scene.enc_idx
        else:
            idx = np.arange(scene.n_points)
        X_all = inst.X.astype(np.float64)
        c = X_all.mean(0)
        X = torch.from_numpy(X_all[idx]).float()
        lat = encode_frames(model64, scene, inst)
        ie, ix = 0.0, 0.0
        for k in range(inst.frames):
            x_t = torch.from_numpy(inst.x(k)[idx].astype(np.float64))
            F_t = torch.from_numpy(inst.F(k)[idx].astype(np.float64))
            has_v = k + 1 < inst.frames
            v_t = torch.from_numpy(inst.v(k)[idx].astype(np.float64)) if has_v else None
            if has_v:   # the data's own finite difference against v_n: the floor of the v error
                fd = (inst.x(k + 1)[idx].astype(np.float64) - x_t.numpy()) / frame_dt
                tot["efd"] += float(((torch.from_numpy(fd) - v_t) ** 2).sum())
            vhat = ((lat[k + 1] - lat[k]) / frame_dt).float() if has_v else None
            xh = lat[k].float()
            for s in range(0, len(idx), CHUNK):
                e = min(len(idx), s + CHUNK)
                m = e - s
                with torch.no_grad():
                    gx, gF, gv = model32.jet(X[s:e], xh.expand(m, -1), vhat.expand(m, -1) if has_v else None)
                gx, gF = gx.double(), gF.double()
                xs = x_t[s:e]
                dx2 = float(((gx - xs) ** 2).sum())
                tot["ex"] += dx2
                tot["x2"] += float((xs ** 2).sum())
                tot["xc2"] += float(((xs - torch.from_numpy(c)) ** 2).sum())
                tot["eF"] += float(((gF - F_t[s:e]) ** 2).sum())
                tot["F2"] += float((F_t[s:e] ** 2).sum())
                ie += dx2
                ix += float((xs ** 2).sum())
                if has_v:
                    tot["ev"] += float(((gv.double() - v_t[s:e]) ** 2).sum())
                    tot["v2"] += float((v_t[s:e] ** 2).sum())
        per_inst.append((inst, math.sqrt(ie / ix) if ix > 0 else float("nan")))
    r = lambda a, b: math.sqrt(tot[a] / tot[b]) if tot[b] > 0 else float("nan")  # noqa: E731
    return dict(x=r("ex", "x2"), xc=r("ex", "xc2"), F=r("eF", "F2"), v=r("ev", "v2"), v_fd=r("efd", "v2"),
                rms_x=math.sqrt(tot["ex"] / max(1, sum(i.frames for i in insts) * len(idx))),
                per_inst=per_inst, points=len(idx) if insts else 0)


def occupancy(X, cell, dim):
    lo = X.min(0) - cell / 2
    cells = np.floor((X.max(0) - lo) / cell).astype(np.int64) + 1
    ijk = np.clip(np.floor((X - lo) / cell).astype(np.int64), 0, cells - 1)
    if dim == 2:
        lo = np.array([lo[0], lo[1], 0.0])
        cells = np.array([cells[0], cells[1], 1])
        ijk = np.concatenate([ijk, np.zeros((len(X), 1), np.int64)], 1)
    occ = np.zeros(int(np.prod(cells)), np.uint8)
    occ[(ijk[:, 0] * cells[1] + ijk[:, 1]) * cells[2] + ijk[:, 2]] = 1
    return lo, cells, occ


# ---- the header --------------------------------------------------------------------------------

def fmt_params(insts, names):
    parts = []
    for i in insts:
        p = ", ".join("%.4g" % v for v in i.params)
        parts.append("%d (%s)" % (i.id, p) if len(i.params) != 1 else "%d: %s" % (i.id, p))
    return "; ".join(parts)


def export(a):
    torch.set_num_threads(a.threads)
    ckpt = a.ckpt or os.path.join(ROOT, "gen", "ckpt", "rom_%s.pt" % a.scene)
    if not os.path.exists(ckpt):
        sys.exit("no checkpoint %s: train first (gen/rom_train.py %s)" % (ckpt, a.scene))
    model32, st = rt.load_checkpoint(ckpt)
    cfg = st["cfg"]
    if not st.get("done") and not a.allow_unfinished:
        sys.exit("%s is unfinished (iteration %d of %d): finish gen/rom_train.py %s, or --allow-unfinished" %
                 (ckpt, st["it"], cfg["iters"], a.scene))
    model32.eval()
    model64, _ = rt.load_checkpoint(ckpt)
    model64 = model64.double().eval()
    scene = rt.Scene(a.data, a.scene, a.allow_partial)
    if cfg["scene"] != scene.name or cfg["n_points"] != scene.n_points or cfg["dim"] != scene.dim:
        sys.exit("%s was trained on %s (%d points), the data is %s (%d points)" %
                 (ckpt, cfg["scene"], cfg["n_points"], scene.name, scene.n_points))
    if scene.fingerprint(scene.train) != cfg["data_fingerprint"]:
        print("warning: the training data changed since %s was trained" % ckpt, file=sys.stderr)
    d, K = scene.dim, cfg["latent"]
    name = scene.name
    ident = c_ident(name)
    up = ident.upper()
    frame_dt = scene.frame_dt

    # latents of the rest state and of every training frame
    lat_rest = encode_positions(model64, scene.X[scene.enc_idx])
    train_lat = torch.cat([encode_frames(model64, scene, i) for i in scene.train])
    lat_std = train_lat.std(0, unbiased=False)
    lat_std = torch.where(lat_std > 0, lat_std, torch.ones_like(lat_std))

    print("%s: measuring %d test and %d training instances" % (name, len(scene.test), len(scene.train)), flush=True)
    err_test = measure(model32, model64, scene, scene.test, frame_dt) if scene.test else None
    err_train = measure(model32, model64, scene, scene.train, frame_dt, TRAIN_EVAL_POINTS)

    lin = list(model64.g)
    widths = [lin[0].in_features] + [m.out_features for m in lin]
    n_par = sum(m.weight.numel() + m.bias.numel() for m in lin)
    pad3 = lambda v, z: [float(t) for t in v] + [z] * (3 - len(v))  # noqa: E731
    in_lo, in_hi = pad3(model64.in_lo.tolist(), 0.0), pad3(model64.in_hi.tolist(), 1.0)
    out_mean, out_std = pad3(model64.out_mean.tolist(), 0.0), pad3(model64.out_std.tolist(), 1.0)
    m = scene.manifest
    cell = float(m["spacing_m"])
    origin, cells, occ = occupancy(scene.X, cell, d)
    n_frames = scene.frames
    final = st.get("final") or dict(zip(("loss", "x", "F", "v"), [float(v) for v in st["avg"]]))

    # ---- banner
    B = []
    B.append("/* rom_%s.h - reduced-order MPM: a learned deformation map x = g(X, xhat) of the %s scene," %
             (ident, name))
    B.append("   after Chen et al., J. Comput. Phys. 2023 (implicit neural representation of the deformation map).")
    B.append("   Generated by gen/rom_export.py - do not edit. Regenerate: make models MODEL=rom_%s" % ident)
    B.append("   Format version %d (PN_ROM_FORMAT_VERSION)." % FORMAT_VERSION)
    if not st.get("done"):
        B.append("   UNFINISHED: exported from a checkpoint at iteration %d of %d." % (st["it"], cfg["iters"]))
    B.append("")
    B += wrap("Data: %s (%s), %dD, %d points (lattice spacing %g m), %d frames of %.6g s each (frame 0 = rest); "
              "material: fixed corotated E = %g Pa, nu = %g, rho = %g kg/m^3, MPM dx = %g m, %d particles per cell per "
              "axis. Parameters: %s." % (
                  name, m.get("solver", "full-order MPM"), d, scene.n_points, cell, n_frames, frame_dt, m["youngs_pa"],
                  m["poisson"], m["density_kg_m3"], m["dx_m"], m["per_axis"], ", ".join(scene.param_names) or "none"))
    B += wrap("Training instances (%d): %s." % (len(scene.train), fmt_params(scene.train, scene.param_names)))
    B += wrap("Test instances (%d): %s." % (len(scene.test), fmt_params(scene.test, scene.param_names) or "none"))
    B.append("")
    B += wrap("Map g: MLP of (Xn, xhat), %d + %d inputs, %d hidden layers %s (ELU, alpha 1), linear output of %d; "
              "%d parameters. Xn = 2 (X - in_lo) / (in_hi - in_lo) - 1 (min/max of the reference points); "
              "x = out_mean + out_std net(Xn, xhat) (per-component mean/std of every training position); "
              "xhat enters unnormalised. F = dg/dX and dg/dxhat by differentiating g." % (
                  d, K, len(widths) - 2, "-".join(str(w) for w in widths[1:-1]), d, n_par))
    B += wrap("Encoder (training only: the latent of a snapshot, xhat = e(x)): the positions of %s, normalised "
              "like the output, as %d channels of length %d; %d Conv1d layers (%d channels, kernel %d, stride %d, "
              "ELU; lengths %s) down to %d = channels x length, dense %d (ELU), dense %d. latent_rest = e(rest "
              "state), latent_std = per-component std of the latents of every training frame." % (
                  "all points" if len(scene.enc_idx) == scene.n_points else
                  "%d points (point floor(k n / %d), k = 0 .. %d)" % (len(scene.enc_idx), len(scene.enc_idx),
                                                                      len(scene.enc_idx) - 1),
                  d, len(scene.enc_idx), len(model64.enc_lengths), rt.ENC_CHANNELS, rt.ENC_KERNEL, rt.ENC_STRIDE,
                  ", ".join(str(v) for v in model64.enc_lengths) or "-", model64.enc_flat, rt.ENC_DENSE, K))
    B += wrap("Loss (paper Eq. 24), mean over snapshot pairs (n, n+1) of training instances and points: "
              "|(g - x) / out_std|^2 + %g |dg/dX - F|_F^2 + %g |(dg/dxhat (xhat_n+1 - xhat_n) / frame_dt - v) / "
              "v_scale|^2, xhat_n = e(x_n); out_std per component (m), F as is, v_scale = %.6g m/s (RMS of the "
              "training velocity components)." % (cfg["lambda_f"], cfg["lambda_v"], float(model64.v_scale[0])))
    B += wrap("Training: gen/rom_train.py %s: Adam, %d iterations x %d snapshot pairs x %d points, learning rate "
              "cosine %g -> %g, Xavier initialisation, seed %d, %d thread(s), float32, %.0f s; final loss %.4g "
              "(x %.3g, F %.3g, v %.3g; running means over the last ~100 iterations)." % (
                  name, cfg["iters"], cfg["batch"], cfg["points"], cfg["lr_max"], cfg["lr_min"], cfg["seed"],
                  cfg["threads"], st["seconds"], final["loss"], final["x"], final["F"], final["v"]))
    if cfg.get("v_target", "n") == "mid":
        B += wrap("Velocity target (--v-target mid): (v_n + v_n+1) / 2 instead of v_n.")
    B.append("")
    B.append("   Measured (relative L2 over all frames and points, latents xhat_n = e(x_n), g in float32;")
    B.append("   v floor: the data's own (x_n+1 - x_n)/frame_dt against v_n, for comparison with v):")

    def err_lines(label, e, what):
        if e is None:
            return ["     %s: none" % label]
        worst = max(e["per_inst"], key=lambda t: t[1])
        return ["     %s (%s): x %.3g, x - centroid %.3g, F %.3g, v %.3g;" % (
                    label, what, e["x"], e["xc"], e["F"], e["v"]),
                "       RMS position error %.3g m; worst instance %d: x %.3g; v floor %.3g" % (
                    e["rms_x"], worst[0].id, worst[1], e["v_fd"])]
    B += err_lines("test", err_test, "%d instances, %d points" % (len(scene.test), scene.n_points))
    B += err_lines("train", err_train, "%d instances, %s" % (
        len(scene.train), "%d points" % scene.n_points if err_train["points"] == scene.n_points else
        "the %d encoder points" % err_train["points"]))
    B.append("")
    B += wrap("Use: #include \"plastinet.h\" and \"plastinet_rom.h\" first, then this header; the weights are "
              "compiled where PLASTINET_IMPLEMENTATION is defined. pn_rom_model_%s() returns the model." % ident)
    B.append("*/")

    # ---- code
    pre = "pn__rom_%s" % ident
    o = ["\n".join(B) + "\n"]
    o.append("#ifndef PN_ROM_MODEL_%s_H\n#define PN_ROM_MODEL_%s_H\n" % (up, up))
    o.append('#ifndef PLASTINET_ROM_H\n#error "include plastinet.h and plastinet_rom.h first"\n#endif\n')
    o.append('#ifdef __cplusplus\nextern "C" {\n#endif\n')
    o.append("PN_API const pn_rom_model *pn_rom_model_%s(void);\n" % ident)
    o.append("#ifdef __cplusplus\n}\n#endif\n#endif /* PN_ROM_MODEL_%s_H */\n\n" % up)
    o.append("#if defined(PLASTINET_IMPLEMENTATION) && !defined(PN_ROM_MODEL_%s_IMPLEMENTATION_DONE)\n" % up)
    o.append("#define PN_ROM_MODEL_%s_IMPLEMENTATION_DONE\n" % up)
    wn, bn, wcount, bcount = [], [], [], []
    for i, layer in enumerate(lin):
        w = layer.weight.detach().double().reshape(-1).tolist()
        b = layer.bias.detach().double().reshape(-1).tolist()
        o.append(array("double", "%s_w%d" % (pre, i), w, g17, 4))
        o.append(array("double", "%s_b%d" % (pre, i), b, g17, 4))
        wn.append("%s_w%d" % (pre, i))
        wcount.append(len(w))
        bcount.append(len(b))
        bn.append("%s_b%d" % (pre, i))
    o.append(array("int", pre + "_width", widths, str, 16))
    o.append("static const double *const %s_weight[%d] = {%s};\n" % (pre, len(wn), ", ".join(wn)))
    o.append("static const double *const %s_bias[%d] = {%s};\n" % (pre, len(bn), ", ".join(bn)))
    o.append(array("double", pre + "_latent_rest", lat_rest.tolist(), g17, 4))
    o.append(array("double", pre + "_latent_std", lat_std.tolist(), g17, 4))
    o.append("/* occupancy: %d x %d x %d cells of %g m, %d occupied */\n" %
             (cells[0], cells[1], cells[2], cell, int(occ.sum())))
    o.append(array("unsigned char", pre + "_occupied", occ.tolist(), str, 64, ","))
    fields = [
        "%d" % FORMAT_VERSION, '"%s"' % name, "%d" % d, "%d" % K, "%d" % len(lin), pre + "_width",
        pre + "_weight", pre + "_bias", "1 /* ELU */",
        "{%s}" % ", ".join(g17(v) for v in in_lo), "{%s}" % ", ".join(g17(v) for v in in_hi),
        "{%s}" % ", ".join(g17(v) for v in out_mean), "{%s}" % ", ".join(g17(v) for v in out_std),
        pre + "_latent_rest", pre + "_latent_std", g17(cell),
        "{%s}" % ", ".join(g17(v) for v in origin), "{%s}" % ", ".join("%d" % v for v in cells), pre + "_occupied",
        g17(m["youngs_pa"]), g17(m["poisson"]), g17(m["density_kg_m3"]), g17(m["dx_m"]), "%d" % int(m["per_axis"]),
        g17(frame_dt),
        # format 2: the arrays' lengths (plastinet_rom.h checks each against the sizes)
        "%d" % len(widths),
        "{%s}" % ", ".join(str(v) for v in wcount + [0] * (8 - len(wcount))),
        "{%s}" % ", ".join(str(v) for v in bcount + [0] * (8 - len(bcount))),
        "%d" % len(lat_rest.tolist()), "%d" % len(lat_std.tolist()), "%d" % len(occ.tolist()),
    ]
    o.append("static const pn_rom_model %s_model = {\n    %s};\n" % (pre, ",\n    ".join(fields)))
    o.append("PN__DEF const pn_rom_model *pn_rom_model_%s(void) { return &%s_model; }\n" % (ident, pre))
    o.append("#endif /* PLASTINET_IMPLEMENTATION */\n")
    out = a.out or os.path.join(ROOT, "models", "rom_%s.h" % ident)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    tmp = out + ".tmp"
    with open(tmp, "w") as f:
        f.write("".join(o))
    os.replace(tmp, out)
    for label, e in (("test", err_test), ("train", err_train)):
        if e:
            print("%s %-5s x %.4g  x-c %.4g  F %.4g  v %.4g (floor %.4g)" % (name, label, e["x"], e["xc"], e["F"],
                                                                              e["v"], e["v_fd"]))
    print(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--data", default=os.path.join(ROOT, "data", "rom"), help="snapshot root [data/rom]")
    ap.add_argument("--ckpt", help="checkpoint [gen/ckpt/rom_SCENE.pt]")
    ap.add_argument("--out", help="header [models/rom_SCENE.h]")
    ap.add_argument("--threads", type=int, default=1, help="torch threads [1]")
    ap.add_argument("--allow-unfinished", action="store_true", help="export a checkpoint still training (tests)")
    ap.add_argument("--allow-partial", action="store_true", help="accept incomplete data (tests)")
    a = ap.parse_args()
    export(a)
    if not a.out:
        write_index()


def write_index():
    """models/pn_rom_models.h: every models/rom_*.h, and a NULL-terminated table of accessors."""
    mdir = os.path.join(ROOT, "models")
    names = sorted(f[4:-2] for f in os.listdir(mdir) if f.startswith("rom_") and f.endswith(".h"))
    lines = ["/* pn_rom_models.h - every reduced-order model header in models/, and a table of them.",
             "   Generated by gen/rom_export.py - do not edit. Include plastinet.h and plastinet_rom.h first.",
             "   A program that needs one model includes only its header; this index is for tools and tests. */",
             "#ifndef PN_ROM_MODELS_H", "#define PN_ROM_MODELS_H"]
    lines += ['#include "rom_%s.h"' % n for n in names]
    lines += ["#define PN_ROM_MODEL_COUNT %d" % len(names),
              "/* The accessors of every model, in a fixed order (NULL-terminated). */",
              "typedef const pn_rom_model *(*pn_rom_model_accessor)(void);",
              "static const pn_rom_model_accessor pn_rom_models_all[PN_ROM_MODEL_COUNT + 1] = {"]
    lines += ["    pn_rom_model_%s," % n for n in names]
    lines += ["    0};", "#endif /* PN_ROM_MODELS_H */", ""]
    with open(os.path.join(mdir, "pn_rom_models.h"), "w") as f:
        f.write("\n".join(lines))


if __name__ == "__main__":
    main()
