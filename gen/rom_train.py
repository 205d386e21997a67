#!/usr/bin/python3
"""Train a reduced-order model of MPM (Chen et al., J. Comput. Phys. 2023, "Model reduction for
the material point method via an implicit neural representation of the deformation map").

    /usr/bin/python3 gen/rom_train.py SCENE [--data data/rom] [--latent 6] [--iters N]
                                     [--out gen/ckpt/rom_SCENE.pt] [--threads 1] [--minutes 60]

Learns the manifold parameterisation g(X, xhat) -> x (an MLP of the reference position X and a
latent xhat) together with a convolutional encoder xhat = e(x_vec) that gives each snapshot of
the training instances its latent (the encoder is used in training only), from the snapshots
in DATA/SCENE/ (manifest.json + one .pnrs file per instance; format in gen/README_rom.md).

Loss (paper Eq. 24), mean over B snapshot pairs (n, n+1) of training instances x P points p:
    |(g(X_p, xhat_n) - x_pn) / out_std|^2 + lambda_F |dg/dX(X_p, xhat_n) - F_pn|_F^2
      + lambda_v |(dg/dxhat(X_p, xhat_n) (xhat_n+1 - xhat_n) / frame_dt - v_pn) / v_scale|^2
with xhat_n = e(x_vec_n), out_std the per-component std of the training positions and v_scale
the RMS of the training velocity components. The Jacobians go by forward mode through the
MLP (one value stream plus d + 1 tangent streams), so a batch costs about 5 forward passes.

Deterministic: the batch of iteration `it` comes from a generator seeded by (seed, it), the
learning rate is a function of `it`, and the checkpoint (written every 30 s of wall time,
atomically, to --out) holds the weights, the Adam state and the normalisations, so a run cut
off and rerun resumes and ends with the same weights bit for bit (same --threads). The budget
is a number of iterations (--iters); --minutes only warns when the estimate exceeds it.
Export to a C header: gen/rom_export.py.
"""
import argparse
import hashlib
import json
import math
import os
import sys
import time

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
CKPT_SECONDS = float(os.environ.get("PN_CKPT_SECONDS", "30"))

MAGIC = b"PNROMS1\n"
HEADER_BYTES = 256
ENC_MAX_POINTS = 4096     # the encoder sees all points up to this count, else an even subset
ENC_CHANNELS = 16         # channels of every convolution of the encoder
ENC_KERNEL, ENC_STRIDE = 6, 2
ENC_FLAT_MIN = 32         # convolutions shrink channels x length to the least value >= this
ENC_DENSE = 32

DEFAULTS = dict(latent=6, hidden=(30, 30, 30, 30, 30), iters=30000, batch=16, points=256,
                lr_max=1e-3, lr_min=1e-6, lambda_f=100.0, lambda_v=0.01, seed=1, v_target="n")
# per scene: the tower (the largest body, the richest shape) halves its position loss with twice
# the iterations (test reconstruction 0.84 % -> 0.68 %, 43 minutes on one thread)
SCENE_DEFAULTS = {"tower": dict(iters=60000)}


# ---- data ------------------------------------------------------------------------------------

class Instance:
    """One .pnrs snapshot file, memory-mapped. x(n), v(n), F(n) are views of frame n."""

    def __init__(self, path, meta, dim, n_points, max_frames):
        self.path, self.meta = path, meta
        self.id, self.params, self.split = meta["id"], list(meta.get("params", [])), meta["split"]
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(HEADER_BYTES)
        if len(head) < HEADER_BYTES or head[:8] != MAGIC:
            raise ValueError("%s: not a PNROMS1 file" % path)
        version, hdim, hn, npar = np.frombuffer(head, "<i4", 4, 8)
        if version != 1 or hdim != dim or hn != n_points:
            raise ValueError("%s: version %d dim %d n_points %d (manifest: dim %d, n_points %d)" %
                             (path, version, hdim, hn, dim, n_points))
        self.frame_dt = float(np.frombuffer(head, "<f8", 1, 24)[0])
        d, n = dim, n_points
        self.dim, self.n = d, n
        x_off = HEADER_BYTES
        flag_off = x_off + 4 * n * d
        self.offset = flag_off + ((n + 3) // 4) * 4
        self.frame_floats = n * (2 * d + d * d)
        whole = max(0, (size - self.offset) // (4 * self.frame_floats))
        self.frames_on_disk = int(whole)
        self.frames = int(min(whole, max_frames))
        self.X = np.array(np.memmap(path, "<f4", "r", x_off, (n, d)))
        self.flags = np.array(np.memmap(path, "u1", "r", flag_off, (n,)))
        self.mm = (np.memmap(path, "<f4", "r", self.offset, (self.frames, self.frame_floats))
                   if self.frames > 0 else None)

    def prefetch(self):
        """Ask the kernel to read the whole file ahead (the batches gather random points)."""
        try:
            import mmap
            self.mm._mmap.madvise(mmap.MADV_WILLNEED)
        except (AttributeError, OSError, ValueError):
            pass

    def x(self, k):
        return self.mm[k, :self.n * self.dim].reshape(self.n, self.dim)

    def v(self, k):
        d = self.dim
        return self.mm[k, self.n * d:2 * self.n * d].reshape(self.n, d)

    def F(self, k):
        d = self.dim
        return self.mm[k, 2 * self.n * d:].reshape(self.n, d, d)


class Scene:
    def __init__(self, data_dir, scene, allow_partial=False):
        self.dir = os.path.join(data_dir, scene)
        mpath = os.path.join(self.dir, "manifest.json")
        if not os.path.exists(mpath):
            sys.exit("no %s: write the snapshots first (gen/rom_data.c)" % mpath)
        with open(mpath) as f:
            self.manifest = m = json.load(f)
        self.name = m.get("scene", scene)
        self.dim, self.n_points, self.frames = int(m["dim"]), int(m["n_points"]), int(m["frames"])
        self.frame_dt = float(m["frame_dt_s"])
        self.param_names = list(m.get("params", []))
        self.instances, problems = [], []
        for meta in m["instances"]:
            p = os.path.join(self.dir, meta["file"])
            if not os.path.exists(p):
                problems.append("%s missing" % meta["file"])
                continue
            inst = Instance(p, meta, self.dim, self.n_points, self.frames)
            if inst.frames < self.frames:
                problems.append("%s has %d of %d frames" % (meta["file"], inst.frames, self.frames))
            if inst.frames < 2:
                continue
            self.instances.append(inst)
        if problems:
            msg = "%s: incomplete data: %s" % (self.dir,
                                               "; ".join(problems[:6]) + (" ..." if len(problems) > 6 else ""))
            if not allow_partial:
                sys.exit(msg + " (finish gen/rom_data.c, or --allow-partial to use what is there)")
            print("warning: " + msg, file=sys.stderr)
        self.train = [i for i in self.instances if i.split == "train"]
        self.test = [i for i in self.instances if i.split == "test"]
        if not self.instances:
            sys.exit("%s: no usable instance" % self.dir)
        ref = (self.train or self.instances)[0]
        self.X = ref.X.astype(np.float64)
        for inst in self.instances:
            if not np.array_equal(inst.X, ref.X):
                print("warning: %s: reference points differ from %s's; each instance uses its own" %
                      (inst.meta["file"], ref.meta["file"]), file=sys.stderr)
        n = self.n_points
        if n <= ENC_MAX_POINTS:
            self.enc_idx = np.arange(n, dtype=np.int64)
        else:   # a fixed, even subset in index order: point floor(k n / 4096), k = 0 .. 4095
            self.enc_idx = (np.arange(ENC_MAX_POINTS, dtype=np.int64) * n) // ENC_MAX_POINTS

    def fingerprint(self, instances):
        h = hashlib.sha256()
        h.update(json.dumps(self.manifest, sort_keys=True).encode())
        for i in instances:
            h.update(("%s:%d;" % (i.meta["file"], i.frames)).encode())
            h.update(i.X.tobytes())
        return h.hexdigest()[:16]


def compute_stats(scene):
    """Normalisations: in_lo/in_hi (min/max of the reference points), out_mean/out_std (per
    component over every position of every training frame), v_scale (RMS of the training
    velocity components, every frame)."""
    d = scene.dim
    s1, s2, sv, cnt = np.zeros(d), np.zeros(d), 0.0, 0
    for inst in scene.train:
        for k in range(inst.frames):
            x = inst.x(k).astype(np.float64)
            v = inst.v(k).astype(np.float64)
            s1 += x.sum(0)
            s2 += (x * x).sum(0)
            sv += float((v * v).sum())
            cnt += x.shape[0]
    mean = s1 / cnt
    std = np.sqrt(np.maximum(s2 / cnt - mean * mean, 0.0))
    std = np.where(std > 0, std, 1.0)
    v_scale = math.sqrt(sv / (cnt * d))
    if not v_scale > 0:
        v_scale = 1.0
    lo, hi = scene.X.min(0), scene.X.max(0)
    hi = np.where(hi > lo, hi, lo + 1.0)
    return dict(in_lo=lo, in_hi=hi, out_mean=mean, out_std=std, v_scale=np.array([v_scale]))


# ---- the model -------------------------------------------------------------------------------

def encoder_layout(dim, length):
    """Lengths after each convolution: add layers while channels x length stays >= 32."""
    lengths = []
    L = length
    while True:
        nL = (L - ENC_KERNEL) // ENC_STRIDE + 1
        if nL < 1 or ENC_CHANNELS * nL < ENC_FLAT_MIN:
            break
        lengths.append(nL)
        L = nL
    flat = ENC_CHANNELS * lengths[-1] if lengths else dim * length
    return lengths, flat


class RomNet(torch.nn.Module):
    """g(X, xhat) = out_mean + out_std * mlp(Xn, xhat), Xn = 2 (X - in_lo)/(in_hi - in_lo) - 1,
    and the encoder e: (S, dim, L) normalised positions -> (S, latent)."""

    def __init__(self, dim, latent, hidden, enc_len, stats):
        super().__init__()
        self.dim, self.latent = dim, latent
        widths = [dim + latent] + list(hidden) + [dim]
        self.g = torch.nn.ModuleList(torch.nn.Linear(widths[i], widths[i + 1]) for i in range(len(widths) - 1))
        lengths, flat = encoder_layout(dim, enc_len)
        convs, c = [], dim
        for _ in lengths:
            convs += [torch.nn.Conv1d(c, ENC_CHANNELS, ENC_KERNEL, ENC_STRIDE), torch.nn.ELU()]
            c = ENC_CHANNELS
        self.enc = torch.nn.Sequential(*convs, torch.nn.Flatten(), torch.nn.Linear(flat, ENC_DENSE), torch.nn.ELU(),
                                       torch.nn.Linear(ENC_DENSE, latent))
        self.enc_lengths, self.enc_flat = lengths, flat
        for k, v in stats.items():
            self.register_buffer(k, torch.as_tensor(np.asarray(v, dtype=np.float64), dtype=torch.float32))
        for mod in self.modules():
            if isinstance(mod, (torch.nn.Linear, torch.nn.Conv1d)):
                torch.nn.init.xavier_uniform_(mod.weight)
                torch.nn.init.zeros_(mod.bias)

    def normalise_X(self, X):
        return 2 * (X - self.in_lo) / (self.in_hi - self.in_lo) - 1

    def encode(self, xn):
        """xn: (S, dim, L) positions already normalised by out_mean/out_std."""
        return self.enc(xn)

    def jet(self, X, xhat, vhat=None, jac_X=True):
        """Forward mode through the MLP. X (M, d), xhat (M, K), vhat (M, K) or None.
        Returns x (M, d); F = dg/dX (M, d, d) if jac_X; dg/dxhat vhat (M, d) if vhat is given.
        The value stream u (M, width) and the tangent streams t (M, T, width) go through the
        layers side by side: t_l = elu'(z_l) * (W_l t_(l-1)); elu'(z) = 1 + min(elu(z), 0)."""
        d, K = self.dim, self.latent
        M = X.shape[0]
        u = torch.cat([self.normalise_X(X), xhat], 1)
        seeds = []
        if jac_X:
            eye = torch.zeros(d, d + K, dtype=u.dtype)
            eye[:, :d] = torch.eye(d, dtype=u.dtype)
            seeds.append(eye.expand(M, d, d + K))
        if vhat is not None:
            seeds.append(torch.cat([torch.zeros(M, d, dtype=u.dtype), vhat], 1)[:, None, :])
        T = sum(s.shape[1] for s in seeds)
        t = torch.cat(seeds, 1).reshape(M * T, d + K) if T else None
        last = len(self.g) - 1
        for li, lin in enumerate(self.g):
            z = linear(u, lin.weight, lin.bias)
            zt = linear(t, lin.weight) if T else None
            if li == last:
                u, t = z, zt
            else:
                u = torch.nn.functional.elu(z)
                if T:
                    slope = 1 + torch.clamp(u, max=0.0)
                    t = (zt.view(M, T, -1) * slope[:, None, :]).view(M * T, -1)
        x = self.out_mean + self.out_std * u
        F = V = None
        if T:
            t = t.view(M, T, d)
        k = 0
        if jac_X:
            # t[:, j, i] = d net_i / d Xn_j: transpose to (out i, in j), then the chain rule
            F = self.out_std[:, None] * t[:, :d].transpose(1, 2) * (2.0 / (self.in_hi - self.in_lo))[None, :]
            k = d
        if vhat is not None:
            V = self.out_std * t[:, k]
        return x, F, V


def linear(x, w, b=None):
    """x w^T + b. In float32 as a 1x1 convolution: oneDNN is several times faster than the
    reference BLAS Debian's torch links (and than its own matmul); float64 by matmul."""
    if x.dtype == torch.float32:
        return torch.nn.functional.conv1d(x[:, :, None], w[:, :, None], b)[:, :, 0]
    return torch.nn.functional.linear(x, w, b)


# ---- training --------------------------------------------------------------------------------

class Batches:
    """The training snapshots: the encoder input of every training frame in memory (float32,
    normalised), the per-point data read from the memory maps when a batch is drawn."""

    def __init__(self, scene, model):
        self.scene = scene
        self.pairs, self.row = [], {}
        rows = []
        for inst in scene.train:
            inst.prefetch()
        mean = model.out_mean.double().numpy()
        std = model.out_std.double().numpy()
        for ii, inst in enumerate(scene.train):
            for k in range(inst.frames):
                self.row[(ii, k)] = len(rows)
                xe = (inst.x(k)[scene.enc_idx].astype(np.float64) - mean) / std
                rows.append(xe.T.astype(np.float32))
                if k + 1 < inst.frames:
                    self.pairs.append((ii, k))
        self.enc_x = torch.from_numpy(np.stack(rows))          # (S, dim, L)

    def draw(self, it, seed, B, P, v_target="n"):
        gen = torch.Generator().manual_seed(seed * 1000003 + it)
        pick = torch.randint(0, len(self.pairs), (B,), generator=gen).tolist()
        pts = torch.randint(0, self.scene.n_points, (B, P), generator=gen).numpy()
        X, x, v, F, r0, r1 = [], [], [], [], [], []
        for b, j in enumerate(pick):
            ii, k = self.pairs[j]
            inst = self.scene.train[ii]
            idx = pts[b]
            X.append(inst.X[idx])
            x.append(inst.x(k)[idx])
            v.append(inst.v(k)[idx] if v_target == "n" else 0.5 * (inst.v(k)[idx] + inst.v(k + 1)[idx]))
            F.append(inst.F(k)[idx])
            r0.append(self.row[(ii, k)])
            r1.append(self.row[(ii, k + 1)])
        t = lambda a: torch.from_numpy(np.concatenate(a).astype(np.float32))  # noqa: E731
        return t(X), t(x), t(v), t(F), self.enc_x[r0 + r1]


def loss_terms(model, batch, frame_dt, B, P):
    X, x, v, F, xe = batch
    lat = model.encode(xe)
    xh0, xh1 = lat[:B], lat[B:]
    vhat = (xh1 - xh0) / frame_dt
    rep = lambda a: a.repeat_interleave(P, 0)  # noqa: E731
    gx, gF, gv = model.jet(X, rep(xh0), rep(vhat))
    lx = (((gx - x) / model.out_std) ** 2).sum(1).mean()
    lF = ((gF - F) ** 2).sum((1, 2)).mean()
    lv = (((gv - v) / model.v_scale) ** 2).sum(1).mean()
    return lx, lF, lv


def lr_at(cfg, it):
    """Cosine from lr_max to lr_min over the iterations."""
    t = min(1.0, it / max(1, cfg["iters"]))
    return cfg["lr_min"] + (cfg["lr_max"] - cfg["lr_min"]) * 0.5 * (1 + math.cos(math.pi * t))


def save_atomic(obj, path):
    tmp = path + ".tmp"
    torch.save(obj, tmp)
    os.replace(tmp, path)


def build_model(cfg, stats):
    return RomNet(cfg["dim"], cfg["latent"], cfg["hidden"], cfg["enc_len"], stats)


def load_checkpoint(path):
    """(model, state) from a checkpoint written by this script."""
    st = torch.load(path)
    cfg = st["cfg"]
    stats = {k: st["model"][k].double().numpy() for k in ("in_lo", "in_hi", "out_mean", "out_std", "v_scale")}
    model = build_model(cfg, stats)
    model.load_state_dict(st["model"])
    return model, st


def train(a):
    torch.set_num_threads(a.threads)
    scene = Scene(a.data, a.scene, a.allow_partial)
    if not scene.train:
        sys.exit("%s: no training instances (every instance is a test instance)" % scene.dir)
    cfg = dict(DEFAULTS)
    cfg.update(SCENE_DEFAULTS.get(scene.name, {}))
    cfg.update(scene=scene.name, dim=scene.dim, n_points=scene.n_points, enc_len=len(scene.enc_idx),
               frame_dt=scene.frame_dt, threads=a.threads, data_fingerprint=scene.fingerprint(scene.train))
    for k in ("latent", "iters", "batch", "points", "seed", "lambda_f", "lambda_v", "v_target"):
        if getattr(a, k) is not None:
            cfg[k] = getattr(a, k)
    cfg["hidden"] = tuple(cfg["hidden"])
    out = a.out or os.path.join(ROOT, "gen", "ckpt", "rom_%s.pt" % a.scene)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    state = None
    if os.path.exists(out):
        state = torch.load(out)
        old = state["cfg"]
        keys = ("scene", "dim", "n_points", "enc_len", "latent", "hidden", "iters", "batch", "points", "seed",
                "lambda_f", "lambda_v", "lr_max", "lr_min", "v_target", "data_fingerprint")
        diff = [k for k in keys if old.get(k, DEFAULTS.get(k)) != cfg[k]]
        if diff:
            sys.exit("%s was trained with other settings or data (%s); delete it or choose --out" %
                     (out, ", ".join("%s %s -> %s" % (k, old.get(k), cfg[k]) for k in diff)))
        if old.get("threads") != cfg["threads"]:
            print("warning: resuming a run started with --threads %s on %d threads: the weights will not "
                  "match an uninterrupted run bit for bit" % (old.get("threads"), cfg["threads"]), file=sys.stderr)
        if state.get("done"):
            print("%s: already trained (%s); delete it to retrain" % (scene.name, out))
            return
    torch.manual_seed(cfg["seed"])
    if state is None:
        stats = compute_stats(scene)
    else:
        stats = {k: state["model"][k].double().numpy() for k in ("in_lo", "in_hi", "out_mean", "out_std", "v_scale")}
    model = build_model(cfg, stats)
    opt = torch.optim.Adam(model.parameters(), lr=cfg["lr_max"])
    start, history, seconds, avg = 0, [], 0.0, None
    if state is not None:
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["opt"])
        start, history, seconds, avg = state["it"], state["history"], state["seconds"], state["avg"]
        print("%s: resuming at iteration %d of %d" % (scene.name, start, cfg["iters"]), flush=True)
    batches = Batches(scene, model)
    B, P, lf, lv_w = cfg["batch"], cfg["points"], cfg["lambda_f"], cfg["lambda_v"]
    n_par = sum(p.numel() for p in model.g.parameters())
    n_enc = sum(p.numel() for p in model.enc.parameters())
    if start == 0:
        print("%s: %d train / %d test instances, %d pairs, %d points (encoder %d), dim %d latent %d; "
              "g %d parameters, encoder %d (conv lengths %s, flat %d); %d iterations x %d x %d" %
              (scene.name, len(scene.train), len(scene.test), len(batches.pairs), scene.n_points,
               cfg["enc_len"], cfg["dim"], cfg["latent"], n_par, n_enc, model.enc_lengths, model.enc_flat,
               cfg["iters"], B, P), flush=True)
    t0 = t_last = time.time()
    warned = False
    it = start
    for it in range(start, cfg["iters"]):
        for gr in opt.param_groups:
            gr["lr"] = lr_at(cfg, it)
        lx, lF, lv = loss_terms(model, batches.draw(it, cfg["seed"], B, P, cfg["v_target"]), cfg["frame_dt"], B, P)
        loss = lx + lf * lF + lv_w * lv
        opt.zero_grad()
        loss.backward()
        opt.step()
        cur = np.array([float(loss), float(lx), float(lF), float(lv)])
        avg = cur if avg is None else 0.99 * avg + 0.01 * cur
        done_it = it + 1
        if done_it % 100 == 0:
            history.append((done_it, avg.tolist()))
            el = seconds + time.time() - t0
            if not a.quiet and done_it % a.print_every == 0:
                print("%s it %6d loss %.4e (x %.3e F %.3e v %.3e) lr %.2e %.0fs" %
                      (scene.name, done_it, avg[0], avg[1], avg[2], avg[3], lr_at(cfg, it), el), flush=True)
            if not warned and done_it - start >= 200:
                est = (time.time() - t0) / (done_it - start) * (cfg["iters"] - start) + seconds
                if est > 60 * a.minutes:
                    print("warning: estimated %.0f min for %d iterations, over --minutes %g" %
                          (est / 60, cfg["iters"], a.minutes), file=sys.stderr, flush=True)
                warned = True
        if time.time() - t_last > CKPT_SECONDS and done_it < cfg["iters"]:
            save_atomic(dict(cfg=cfg, model=model.state_dict(), opt=opt.state_dict(), it=done_it, avg=avg,
                             history=history, seconds=seconds + time.time() - t0, done=False), out)
            t_last = time.time()
    seconds += time.time() - t0
    final = dict(zip(("loss", "x", "F", "v"), (avg.tolist() if avg is not None else [float("nan")] * 4)))
    save_atomic(dict(cfg=cfg, model=model.state_dict(), opt=opt.state_dict(), it=cfg["iters"], avg=avg,
                     history=history, seconds=seconds, done=True, final=final), out)
    print("%s: trained %d iterations in %.0f s, final loss %.4e (x %.3e, F %.3e, v %.3e) -> %s" %
          (scene.name, cfg["iters"], seconds, final["loss"], final["x"], final["F"], final["v"], out), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--data", default=os.path.join(ROOT, "data", "rom"), help="snapshot root [data/rom]")
    ap.add_argument("--out", help="checkpoint [gen/ckpt/rom_SCENE.pt]")
    ap.add_argument("--latent", type=int, help="latent size [%d]" % DEFAULTS["latent"])
    ap.add_argument("--iters", type=int, help="iterations [%d; tower 60000]" % DEFAULTS["iters"])
    ap.add_argument("--batch", type=int, help="snapshot pairs per batch [%d]" % DEFAULTS["batch"])
    ap.add_argument("--points", type=int, help="points per snapshot [%d]" % DEFAULTS["points"])
    ap.add_argument("--seed", type=int, help="[%d]" % DEFAULTS["seed"])
    ap.add_argument("--lambda-f", dest="lambda_f", type=float, help="[%g]" % DEFAULTS["lambda_f"])
    ap.add_argument("--lambda-v", dest="lambda_v", type=float, help="[%g]" % DEFAULTS["lambda_v"])
    ap.add_argument("--v-target", dest="v_target", choices=("n", "mid"),
                    help="velocity the latent finite difference is fit to: v_n (paper Eq. 24) or "
                         "(v_n + v_n+1)/2, which the data's own (x_n+1 - x_n)/dt matches better [n]")
    ap.add_argument("--threads", type=int, default=1,
                    help="torch threads [1]; 2 only on an idle machine (with the other core busy a 2-thread run "
                         "is many times slower); resume with the same count")
    ap.add_argument("--minutes", type=float, default=60, help="warn if the run looks longer than this [60]")
    ap.add_argument("--allow-partial", action="store_true", help="train on incomplete data (tests)")
    ap.add_argument("--print-every", type=int, default=1000)
    ap.add_argument("--quiet", action="store_true")
    train(ap.parse_args())


if __name__ == "__main__":
    main()
