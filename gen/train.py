#!/usr/bin/python3
"""Train one plastinet model (PlasticityNet energy or learned return mapping) on the CPU.

    /usr/bin/python3 gen/train.py --model sand_2d          # train (resumes from gen/ckpt/)
    /usr/bin/python3 gen/train.py --model sand_2d --eval   # figures of the trained model

Deterministic: one thread, and every batch drawn from a generator seeded by (seed, iteration),
so a run that is cut off and resumed from its checkpoint gives the same weights bit for bit.
Checkpoints go to gen/ckpt/NAME.pt every 30 seconds; the finished weights to gen/ckpt/NAME.done.pt.
Export to a C header is gen/export.py.
"""
import argparse
import math
import os
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import pn_torch as pt  # noqa: E402
from models import MODELS  # noqa: E402

DT = pt.DT
HERE = os.path.dirname(os.path.abspath(__file__))
CKPT = os.path.join(HERE, "ckpt")
CKPT_SECONDS = float(os.environ.get("PN_CKPT_SECONDS", "30"))  # checkpoint interval

ACTIVATIONS = {"silu": torch.nn.SiLU, "tanh": torch.nn.Tanh, "softplus": torch.nn.Softplus}


def mlp(n_in, hidden, activation):
    layers, n = [], n_in
    for w in hidden:
        layers += [torch.nn.Linear(n, w), ACTIVATIONS[activation]()]
        n = w
    layers.append(torch.nn.Linear(n, 1))
    return torch.nn.Sequential(*layers).to(DT)


# ---- sampling ----------------------------------------------------------------------------------

SCALE_DECADES = 4.0              # scaled encoding: |e0| from e_box down to 1e-4 e_box
RATIO_DECADES = (-1.0, 2.0)      # and |de| / |e0| from 0.1 to 100 (capped at de)


def sample_box(cfg, n, gen):
    """PlasticityNet Section 5.1: F0 = R1 diag(exp(e)) R2, F = R3 diag(exp(e + de)) R4. Only the
    relative rotations A = R3^T R1 and B = R2 R4^T matter (both Haar-random)."""
    d = cfg["dim"]
    e = (torch.rand(n, d, dtype=DT, generator=gen) * 2 - 1) * cfg["e_box"]
    de = (torch.rand(n, d, dtype=DT, generator=gen) * 2 - 1) * cfg["de"]
    if cfg.get("encoding") == "scaled":
        # every strain scale alike: |e| log-uniform over SCALE_DECADES below e_box, the step de
        # RATIO_DECADES around it (a flowing material takes steps far above its elastic strain)
        lo0, (lo1, hi1) = SCALE_DECADES, RATIO_DECADES
        u = torch.rand(n, 1, dtype=DT, generator=gen)
        k = int(round(n * cfg.get("small", 0.0)))
        if k:   # small = f: the first f of the batch over the lower half of the decades only
            u = u.clone()
            u[:k] = 0.5 + 0.5 * u[:k]
        r0 = cfg["e_box"] * 10.0 ** (-lo0 * u)
        r1 = r0 * 10.0 ** (lo1 + (hi1 - lo1) * torch.rand(n, 1, dtype=DT, generator=gen))
        e = e / cfg["e_box"] * r0
        de = de / cfg["de"] * torch.clamp(r1, max=cfg["de"])
    lo, hi = cfg["h"]
    h = lo + (hi - lo) * torch.rand(n, 1, dtype=DT, generator=gen)
    A = pt.random_rotations(n, d, gen)
    B = pt.random_rotations(n, d, gen)
    return torch.exp(e), torch.exp(e + de), h, A, B, sample_params(cfg, n, gen)


def sample_solver(cfg, n, gen):
    """Pairs as an implicit solve visits them (measured on the sand column, docs/notebook.md):
    F0 is a step's trial deformation, often far outside the yield surface (a flowing material's
    deviatoric trial strain is up to 100x its volumetric one), and the solve moves F only a
    little from it (|F - F0| / |e0| from 1e-3 to 1, median about 0.05). So e0 = tr/d + dev with
    |tr| uniform below r0 (r0 over the decades of the box) and |dev| / r0 log-uniform in
    [0.03, 100] (capped at e_box), and F = (I + D) diag(exp(e0)) with D a Gaussian matrix of norm
    |e0| 10^U[-3, 0] (capped at de). Returns s0, s, the relative rotations A, B (F0 = diag(s0),
    F = A^T diag(s) B^T) and |D|^2, the scale the loss is taken relative to: near F0 the error
    is the Hessian's, (H_N - dT/dF) D, and this measures it whatever |D| is."""
    d = cfg["dim"]
    r0 = cfg["e_box"] * 10.0 ** (-SCALE_DECADES * torch.rand(n, 1, dtype=DT, generator=gen))
    tr = (torch.rand(n, 1, dtype=DT, generator=gen) * 2 - 1) * r0
    v = torch.randn(n, d, dtype=DT, generator=gen)
    v = v - v.mean(-1, keepdim=True)
    v = v / torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    dev = torch.clamp(r0 * 10.0 ** (-1.5 + 3.5 * torch.rand(n, 1, dtype=DT, generator=gen)), max=cfg["e_box"])
    e0 = tr / d + v * dev
    D = torch.randn(n, d, d, dtype=DT, generator=gen)
    size = torch.linalg.vector_norm(e0, dim=-1, keepdim=True) * 10.0 ** (-3.0 * torch.rand(n, 1, dtype=DT, generator=gen))
    size = torch.clamp(size, max=cfg["de"])
    D = D / torch.linalg.matrix_norm(D).reshape(n, 1, 1) * size.unsqueeze(-1)
    s0 = torch.exp(e0)
    F = (torch.eye(d, dtype=DT) + D) * s0.unsqueeze(-2)
    U, s, V = pt.svd_rot(F)
    return s0, s, U.transpose(-1, -2), V, (size * size)[:, 0]


def sample_pairs(cfg, n, gen):
    """A training batch: the box (sample_box) and, for a model with solver = f > 0, a fraction f
    of solver pairs (sample_solver) in place of the first box samples, drawn after everything
    else (the other models' batches do not change). W: per sample, what the squared error is
    taken relative to (None: the box's own measure)."""
    s0, s, h, A, B, prm = sample_box(cfg, n, gen)
    f = cfg.get("solver", 0.0)
    if not f:
        return s0, s, h, A, B, prm, None
    k = int(round(n * f))
    s0k, sk, Ak, Bk, Wk = sample_solver(cfg, k, gen)
    s0, s, A, B = s0.clone(), s.clone(), A.clone(), B.clone()
    s0[:k], s[:k], A[:k], B[:k] = s0k, sk, Ak, Bk
    W = torch.full((n,), float("nan"), dtype=DT)
    W[:k] = Wk
    return s0, s, h, A, B, prm, W


def sample_params(cfg, n, gen):
    """A conditioned model's material parameters, uniform over their ranges ([n, P]; [n, 0]
    for a single material). Drawn after everything else, so a single-material model's
    samples do not change."""
    ps = cfg.get("params", ())
    if not ps:
        return torch.zeros(n, 0, dtype=DT)
    lo = torch.tensor([p[1] for p in ps], dtype=DT)
    hi = torch.tensor([p[2] for p in ps], dtype=DT)
    return lo + (hi - lo) * torch.rand(n, len(ps), dtype=DT, generator=gen)


def material_of(cfg, prm):
    """The training material, with a conditioned model's parameters per sample."""
    ps = cfg.get("params", ())
    return pt.with_params(cfg["mat"], [p[0] for p in ps], prm) if ps else cfg["mat"]


# ---- learned return mapping (PlasticityNet Eqs. 12-13) ------------------------------------------
# dgamma(s, h) = |e_hat| - r(s, h), r = r_ref exp(NN(features)) > 0, so dgamma < |e_hat| always
# (the clamp of Eq. 12 never binds) and the network learns the log of a correction factor to the
# small-strain radius r_ref = (sqrt(2/3) sigma_Y(h) + 2K/3 |e_hat|) / (2 mu J^(2/d) + 2K/3).

def return_features(s, h):
    d = s.shape[-1]
    _, ehat, tr, r = pt.hencky_split(s)
    cols = [tr, r]
    if d == 3:
        n = ehat / torch.where(r > 0, r, torch.ones_like(r))
        cols.append(math.sqrt(6.0) * (n ** 3).sum(-1, keepdim=True))   # cos(3 Lode angle)
    cols.append(h)
    return torch.cat(cols, -1)


class ReturnNet(torch.nn.Module):
    def __init__(self, cfg, shift, scale):
        super().__init__()
        self.cfg = cfg
        self.net = mlp(shift.numel(), cfg["hidden"], cfg["activation"])
        self.register_buffer("shift", shift)
        self.register_buffer("scale", scale)
        with torch.no_grad():   # start at r = r_ref
            self.net[-1].weight.zero_()
            self.net[-1].bias.zero_()

    def radius(self, mat, s, h):
        d = s.shape[-1]
        _, _, tr, r = pt.hencky_split(s)
        K = mat.hardening_modulus
        rref = (pt.vm_tau_y(mat, h) + 2 * K / 3 * r) / (2 * mat.mu * torch.exp(2 * tr / d) + 2 * K / 3)
        g = self.net((return_features(s, h) - self.shift) * self.scale)
        return rref * torch.exp(g)

    def dgamma(self, mat, s, h):
        _, _, _, r = pt.hencky_split(s)
        return torch.clamp(r - self.radius(mat, s, h), min=0)

    def project(self, mat, s, h):
        e, ehat, tr, r = pt.hencky_split(s)
        outside = pt.dev_norm(pt.tau_principal(mat, s)) > pt.vm_tau_y(mat, h)
        n = ehat / torch.where(r > 0, r, torch.ones_like(r))
        z = torch.exp(e - self.dgamma(mat, s, h) * n)
        return torch.where(outside, z, s)


def sample_return(cfg, n, gen):
    """Half from the energy's box, half with |e_hat| log-uniform in [1e-3, 2] (near the surface)."""
    d = cfg["dim"]
    s_box, _, h, _, _, _ = sample_box(cfg, n, gen)
    k = n // 2
    v = torch.randn(k, d, dtype=DT, generator=gen)
    v = v - v.mean(-1, keepdim=True)
    v = v / torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    mag = torch.exp(math.log(1e-3) + (math.log(2.0) - math.log(1e-3)) *
                    torch.rand(k, 1, dtype=DT, generator=gen))
    tr = (torch.rand(k, 1, dtype=DT, generator=gen) * 2 - 1) * cfg["e_box"]
    s_box[:k] = torch.exp(v * mag + tr / d)
    return s_box, h


def return_loss(model, mat, s, h):
    """Eq. 13 with the hardening of the reference: y(Z)^2 over points outside (scaled by
    tau_Y(h)^2) + max(dgamma - |e_hat|, 0)."""
    e, ehat, tr, r = pt.hencky_split(s)
    tauy = pt.vm_tau_y(mat, h)
    outside = (pt.dev_norm(pt.tau_principal(mat, s)) > tauy).squeeze(-1)
    s, h, r, e, ehat = s[outside], h[outside], r[outside], e[outside], ehat[outside]
    dg = r - model.radius(mat, s, h)
    n = ehat / r
    y = pt.vm_residual(mat, e, n, dg, h) / pt.vm_tau_y(mat, h)
    return (y ** 2).mean() + torch.clamp(dg - r, min=0).mean()


# ---- PlasticityNet energy (Eq. 8) ---------------------------------------------------------------
# N(F, F0, h) = out_scale * MLP([(x(F) - x(F0)) * sd, (x(F0) - m0) * s0, (h - mh) * sh, (p - mp) * sp])
# with x the rotation-invariant features of pn_torch.features (so grad_F N = U diag(dN/ds) V^T) and
# p a conditioned model's material parameters. output "softplus": out_scale * softplus(MLP) >= 0.

class EnergyNet(torch.nn.Module):
    def __init__(self, cfg, stats):
        super().__init__()
        self.cfg = cfg
        nx = cfg["dim"] if cfg["dim"] == 3 else 2
        n_in = 2 * nx + 1 + (cfg.get("encoding") == "scaled") + len(cfg.get("params", ()))
        self.net = mlp(n_in, cfg["hidden"], cfg["activation"])
        for k, v in stats.items():
            self.register_buffer(k, v)

    def out(self, u):
        m = self.net(u)
        return torch.nn.functional.softplus(m) if self.cfg.get("output") == "softplus" else m

    def forward(self, s, s0, h, prm):
        x, x0 = pt.features(s), pt.features(s0)
        cond = [(prm - self.mp) * self.sp] if prm.shape[-1] else []
        if self.cfg.get("encoding") == "scaled":
            raw, S = pt.scaled_raw(x, x0)
            u = torch.cat([(raw - self.m0) * self.s0, (h - self.mh) * self.sh] + cond, -1)
            return self.out_scale * S * self.out(u)
        u = torch.cat([(x - x0) * self.sd, (x0 - self.m0) * self.s0, (h - self.mh) * self.sh] + cond, -1)
        return self.out_scale * self.out(u)

    def grad_s(self, s, s0, h, prm, create_graph):
        """dN/ds at the first slot, with F0 (s0), h and the material held fixed."""
        s = s.detach().requires_grad_(True)
        N = self.forward(s, s0, h, prm)
        (g,) = torch.autograd.grad(N.sum(), s, create_graph=create_graph)
        return g


def energy_stats(cfg, mat, learned):
    gen = torch.Generator().manual_seed(12345)
    s0, s, h, _, _, prm = sample_box(cfg, 100000, gen)
    mat = material_of(cfg, prm)
    x, x0 = pt.features(s), pt.features(s0)
    lo, hi = cfg["h"]
    t = target_of(cfg, mat, s, h, learned, s0)
    r = t - base_principal(cfg, mat, s, h, s0)   # what the network fits (t without a base)
    ps = cfg.get("params", ())   # parameters to [-1, 1]
    cond = {} if not ps else dict(
        mp=torch.tensor([(p[1] + p[2]) / 2 for p in ps], dtype=DT),
        sp=torch.tensor([2 / (p[2] - p[1]) if p[2] > p[1] else 0.0 for p in ps], dtype=DT))
    if cfg.get("encoding") == "scaled":
        # raw = [(x - x0)/s^p, x0/s^p, s]: one shift and scale per column; errors relative to s
        raw, S = pt.scaled_raw(x, x0)
        w = (t * t).sum(-1, keepdim=True) / S
        wr = (r * r).sum(-1, keepdim=True) / S
        return dict(m0=raw.mean(0), s0=1 / raw.std(0),
                    mh=torch.tensor([(lo + hi) / 2], dtype=DT),
                    sh=torch.tensor([2 / (hi - lo) if hi > lo else 0.0], dtype=DT),
                    out_scale=torch.sqrt(wr.mean()).reshape(1), t_rms=torch.sqrt(w.mean()).reshape(1), **cond)
    return dict(sd=1 / (x - x0).std(0), m0=x0.mean(0), s0=1 / x0.std(0),
                mh=torch.tensor([(lo + hi) / 2], dtype=DT),
                sh=torch.tensor([2 / (hi - lo) if hi > lo else 0.0], dtype=DT),
                out_scale=torch.sqrt((r * r).sum(-1).mean()).reshape(1),
                t_rms=torch.sqrt((t * t).sum(-1).mean()).reshape(1), **cond)


def base_principal(cfg, mat, s, h, s0):
    """The principal gradient of a model's analytic base energy B(F; F0, h) (0 without one):
    "von_mises_hencky" is the exact incremental potential of the StVK-Hencky von Mises return
    (plastinet.h pn_von_mises_energy) at the material's nu, yield and hardening; "dp_frozen"
    the frozen-yield Drucker-Prager energy (pn_dp_energy) with its yield stress taken at F0
    (pn_dp_prepare), whose gradient at F0 is T(F0). Either gradient is coaxial with F, as the
    network's is, so the residual T - grad B stays learnable."""
    if cfg.get("base") == "dp_frozen":
        return dp_frozen_principal(mat, s, s0)
    if cfg.get("base") != "von_mises_hencky":
        return torch.zeros_like(s)
    import copy
    mh = copy.copy(mat)
    mh.elastic = "stvk_hencky"
    return pt.target_principal(mh, s, h)


def dp_frozen_principal(mat, s, s0):
    """grad of plastinet.h pn_dp_energy at s with tau_y from s0 (pn_dp_prepare), principal:
    Psi = kappa/2 min(tr e, 0)^2 + d kappa c tr e + psi_dev(|e_hat|; tau_y) in e = log s - c,
    psi_dev = mu r^2 up to 2 mu r = tau_y and tau_y r - tau_y^2 / (4 mu) beyond."""
    d = s.shape[-1]
    c = mat.cohesion_strain
    kappa = mat.kappa(d)
    tr0 = (torch.log(s0) - c).sum(-1, keepdim=True)
    tau_y = torch.clamp(-d * kappa * pt.dp_alpha(mat.sin_phi, d) * tr0, min=0)
    e = torch.log(s) - c
    tr = e.sum(-1, keepdim=True)
    ehat = e - tr / d
    r = torch.linalg.vector_norm(ehat, dim=-1, keepdim=True)
    rsafe = torch.where(r > 0, r, torch.ones_like(r))
    dev = torch.where(2 * mat.mu * r <= tau_y, 2 * mat.mu * ehat, tau_y * ehat / rsafe)
    ge = kappa * (torch.clamp(tr, max=0) + d * c) + dev
    return ge / s


def target_of(cfg, mat, s, h, learned, s0):
    """What grad Psi(F; F0) is trained to: T(F) (PlasticityNet Eq. 9), or with target =
    "dp_frozen" the gradient of the frozen-yield Drucker-Prager energy with its yield at F0,
    which equals T(F0) at F0 and drops the return's non-associative part (the yield's
    dependence on tr e within the step): the best potential of T has that part's symmetric
    half, a coupling of the free plastic shear to the volume that turns the energy's minimum
    into a saddle (docs/notebook.md)."""
    if cfg.get("target") == "dp_frozen":
        return dp_frozen_principal(mat, s, s0)
    return pt.target_principal(mat, s, h, learned)


def energy_error(model, mat, learned, s0, s, h, A, B, prm, create_graph=False, W=None):
    """|grad Psi(F, F0) - T(F)|^2 per sample, in the principal frames (see README); mat is the
    batch's material (material_of), prm its parameter inputs. With a base energy the network
    fits T - grad B (both coaxial with F, so the same principal-frame algebra holds). W (from
    sample_pairs): where finite, the error is taken relative to it (solver pairs)."""
    cfg = model.cfg
    with torch.no_grad():
        t_full = target_of(cfg, mat, s, h, learned, s0)
        t = t_full - base_principal(cfg, mat, s, h, s0)
        t0 = pt.target_principal(mat, s0, h, learned) - base_principal(cfg, mat, s0, h, s0)
    diff = model.grad_s(s, s0, h, prm, create_graph) - t
    c = model.grad_s(s0, s0, h, prm, create_graph) - t0
    cross = torch.einsum("bi,bij,bj,bji->b", diff, A, c, B)
    err2 = (diff * diff).sum(-1) + (c * c).sum(-1) - 2 * cross
    if cfg.get("encoding") == "scaled":   # relative to the strain scale of the pair
        _, S = pt.scaled_raw(pt.features(s), pt.features(s0))
        err2, t_full = err2 / S[:, 0], t_full / torch.sqrt(S)
    if cfg.get("loss") == "stress":   # relative to the stresses themselves, floored at 10% of the scale's
        with torch.no_grad():
            t2 = (t_full * t_full).sum(-1) + 1e-2 * float(model.t_rms) ** 2
        return err2 / t2, t_full
    if W is not None:   # solver pairs: relative to |F - F0|^2 instead
        solver = torch.isfinite(W)
        if cfg.get("encoding") == "scaled":
            err2 = torch.where(solver, err2 * S[:, 0] / torch.where(solver, W, torch.ones_like(W)), err2)
        else:
            err2 = torch.where(solver, err2 / torch.where(solver, W, torch.ones_like(W)), err2)
    return err2, t_full


def lagged_and_constant_error(mat, learned, s0, s, h, A, B):
    """Baselines on the same samples: the lagged energy psi_el(F G), G = F0^-1 Z(F0), and the
    constant T(F0). F0 = diag(s0), F = A^T diag(s) B^T (the relative rotations only)."""
    d = s.shape[-1]
    z0 = pt.return_map(mat, s0, h, learned)
    G = torch.diag_embed(z0 / s0)
    F = A.transpose(-1, -2) @ torch.diag_embed(s) @ B.transpose(-1, -2)
    T = A.transpose(-1, -2) @ torch.diag_embed(pt.target_principal(mat, s, h, learned)) @ B.transpose(-1, -2)
    U, sg, V = pt.svd_rot(F @ G)
    P = U @ torch.diag_embed(pt.tau_principal(mat, sg) / sg) @ V.transpose(-1, -2)
    lag = torch.linalg.matrix_norm(P @ G.transpose(-1, -2) - T)
    T0 = torch.diag_embed(pt.target_principal(mat, s0, h, learned))
    const = torch.linalg.matrix_norm(T0 - T)
    del d
    return lag, const


# ---- building, training, checkpoints ------------------------------------------------------------

def load_learned(cfg):
    if not cfg.get("return_map"):
        return None
    rcfg = MODELS[cfg["return_map"]]
    path = os.path.join(CKPT, rcfg["name"] + ".done.pt")
    if not os.path.exists(path):
        sys.exit("train %s first (%s is missing)" % (rcfg["name"], path))
    model = build(rcfg)
    model.load_state_dict(torch.load(path)["model"])
    model.eval()
    for p in model.parameters():
        p.requires_grad_(False)
    return model


def build(cfg, learned=None):
    mat = cfg["mat"]
    if cfg["kind"] == "return_map":
        gen = torch.Generator().manual_seed(12345)
        s, h = sample_return(cfg, 100000, gen)
        f = return_features(s, h)
        std = f.std(0)
        return ReturnNet(cfg, f.mean(0), torch.where(std > 0, 1 / std, torch.zeros_like(std)))
    return EnergyNet(cfg, energy_stats(cfg, mat, learned))


def lr_at(cfg, it):
    """Cosine decay from lr to lr/100 after a short warm-up."""
    warm = 200
    if it < warm:
        return cfg["lr"] * (it + 1) / warm
    x = (it - warm) / max(1, cfg["iters"] - warm)
    return cfg["lr"] * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * x)))


def batch_loss(cfg, model, learned, it, norm):
    gen = torch.Generator().manual_seed(cfg["seed"] * 1000003 + it)
    if cfg["kind"] == "return_map":
        s, h = sample_return(cfg, cfg["batch"], gen)
        return return_loss(model, cfg["mat"], s, h)
    s0, s, h, A, B, prm, W = sample_pairs(cfg, cfg["batch"], gen)
    err2, _ = energy_error(model, material_of(cfg, prm), learned, s0, s, h, A, B, prm, create_graph=True, W=W)
    return err2.mean() / norm


def save_atomic(obj, path):
    tmp = path + ".tmp"
    torch.save(obj, tmp)
    os.replace(tmp, path)


def train(cfg, quiet=False):
    torch.manual_seed(cfg["seed"])
    os.makedirs(CKPT, exist_ok=True)
    done = os.path.join(CKPT, cfg["name"] + ".done.pt")
    ck = os.path.join(CKPT, cfg["name"] + ".pt")
    learned = load_learned(cfg)
    model = build(cfg, learned)
    opt = torch.optim.Adam(model.parameters(), lr=cfg["lr"])
    start, history, seconds, avg = 0, [], 0.0, None
    if os.path.exists(done):
        print("%s: already trained (%s)" % (cfg["name"], done))
        return
    if os.path.exists(ck):
        state = torch.load(ck)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["opt"])
        start, history, seconds = state["it"], state["history"], state["seconds"]
        avg = state.get("avg")
        print("%s: resuming at iteration %d" % (cfg["name"], start))
    norm = float(model.t_rms ** 2) if cfg["kind"] == "energy" else 1.0
    t_last, t0 = time.time(), time.time()
    for it in range(start, cfg["iters"]):
        for g in opt.param_groups:
            g["lr"] = lr_at(cfg, it)
        loss = batch_loss(cfg, model, learned, it, norm)
        opt.zero_grad()
        loss.backward()
        opt.step()
        lv = float(loss)
        avg = lv if avg is None else 0.99 * avg + 0.01 * lv
        if (it + 1) % 100 == 0:
            history.append((it + 1, avg))
            if not quiet:
                print("%s it %6d loss %.4e (avg %.4e) %.0fs" %
                      (cfg["name"], it + 1, lv, avg, seconds + time.time() - t0), flush=True)
        if time.time() - t_last > CKPT_SECONDS or it + 1 == cfg["iters"]:
            save_atomic(dict(model=model.state_dict(), opt=opt.state_dict(), it=it + 1, avg=avg,
                             history=history, seconds=seconds + time.time() - t0), ck)
            t_last = time.time()
    seconds += time.time() - t0
    save_atomic(dict(model=model.state_dict(), history=history, seconds=seconds,
                     final_loss=history[-1][1] if history else float("nan")), done)
    if os.path.exists(ck):
        os.remove(ck)
    print("%s: trained in %.0f s, final loss %.4e" % (cfg["name"], seconds, history[-1][1]))


def load_trained(cfg):
    learned = load_learned(cfg)
    model = build(cfg, learned)
    state = torch.load(os.path.join(CKPT, cfg["name"] + ".done.pt"))
    model.load_state_dict(state["model"])
    return model, learned, state


def evaluate(cfg, model, learned, n=100000, seed=777, at=None):
    """Python-side figures on n fresh samples (models/REPORT.md has the C-side ones); at: a
    conditioned model's parameter values to hold fixed (else drawn over the ranges)."""
    mat = cfg["mat"]
    gen = torch.Generator().manual_seed(seed)
    if cfg["kind"] == "return_map":
        s, h = sample_return(cfg, n, gen)
        with torch.no_grad():
            z = model.project(mat, s, h)
            zr = pt.return_von_mises_rootfind(mat, s, h)
        rel = torch.linalg.vector_norm(torch.log(z) - torch.log(zr), dim=-1)
        return dict(log_z_err_mean=float(rel.mean()), log_z_err_max=float(rel.max()))
    errs, lags, consts, tn = [], [], [], []
    for k in range(0, n, 10000):
        s0, s, h, A, B, prm = sample_box(cfg, 10000, gen)
        if at is not None:
            prm = torch.tensor([list(at)], dtype=DT).expand(10000, len(at))
        mat = material_of(cfg, prm)
        e2, t = energy_error(model, mat, learned, s0, s, h, A, B, prm)
        lag, const = lagged_and_constant_error(mat, learned, s0, s, h, A, B)
        if cfg.get("encoding") == "scaled":   # the same relative measure as energy_error
            _, S = pt.scaled_raw(pt.features(s), pt.features(s0))
            lag, const = lag / torch.sqrt(S[:, 0]), const / torch.sqrt(S[:, 0])
        errs.append(torch.sqrt(torch.clamp(e2.detach(), min=0)))
        lags.append(lag)
        consts.append(const)
        tn.append(torch.linalg.vector_norm(t, dim=-1))
    err, lag, const = torch.cat(errs), torch.cat(lags), torch.cat(consts)
    tm = float(torch.cat(tn).mean())
    q = lambda v: float(torch.quantile(v[:50000], 0.95)) / tm  # noqa: E731
    return dict(mean_T=tm, net_mean=float(err.mean()) / tm, net_p95=q(err),
                lagged_mean=float(lag.mean()) / tm, lagged_p95=q(lag),
                const_mean=float(const.mean()) / tm, const_p95=q(const),
                ratio=float(err.mean()) / float(lag.mean()))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", required=True, choices=sorted(MODELS))
    ap.add_argument("--eval", action="store_true", help="print the figures of the trained model")
    ap.add_argument("--iters", type=int, help="override the iteration budget (experiments)")
    ap.add_argument("--hidden", help="override the hidden sizes, e.g. 32,32 (experiments)")
    ap.add_argument("--tag", help="train under another name (experiments)")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--at", help="--eval a conditioned model at these parameter values, e.g. 0.3,30")
    a = ap.parse_args()
    torch.set_num_threads(1)
    cfg = dict(MODELS[a.model])
    if a.iters:
        cfg["iters"] = a.iters
    if a.hidden:
        cfg["hidden"] = tuple(int(v) for v in a.hidden.split(","))
    if a.tag:
        cfg["name"] = a.tag
    if a.eval:
        model, learned, state = load_trained(cfg)
        print(cfg["name"], "trained %.0f s, final loss %.4e" % (state["seconds"], state["final_loss"]))
        at = tuple(float(v) for v in a.at.split(",")) if a.at else None
        for k, v in evaluate(cfg, model, learned, at=at).items():
            print("  %-16s %.4g" % (k, v))
        return
    train(cfg, a.quiet)


if __name__ == "__main__":
    main()
