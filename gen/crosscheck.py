#!/usr/bin/python3
"""C against torch: plastinet.h and the shipped models must compute what gen/ trains.

    /usr/bin/python3 gen/crosscheck.py        (tests/run.sh runs it when torch is installed)

1. The training target T(F) = tau(Z(F)) F^-T of gen/pn_torch.py against pn_return_map, for
   every material of gen/models.py in 2D and 3D, on 1e4 random F each: relative error <= 1e-6.
2. Every model in models/: Psi(F; F0, h) and grad Psi from pn_pnet_energy against torch
   (autograd through the invariant features of F, the weights read back from the C model, the
   linear correction of Eq. 8 with the torch T(F0)), on 1e4 random inputs: <= 1e-5 relative.
   Learned return mappings: T against the torch ReturnNet formula, <= 1e-5 relative.
3. If gen/ckpt/NAME.done.pt exists (a machine that trained), the header's weights are the
   checkpoint's rounded to float.
Prints "ok/FAIL name figures" lines and a last line "N passed, N failed".
"""
import ctypes
import os
import subprocess
import sys

import torch

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import pn_torch as pt  # noqa: E402
from models import MATERIALS  # noqa: E402

DT = pt.DT
EL = {"fixed_corotated": 1, "stvk_hencky": 2, "neo_hookean": 3, "neo_hookean_snow": 4}
PL = {"none": 0, "drucker_prager": 1, "von_mises": 2, "cam_clay": 3}
ACT = {1: torch.nn.functional.silu, 2: torch.tanh, 3: torch.nn.functional.softplus}
KIND = {k + 1: name for k, name in enumerate(pt.PARAMS)}   # pn_model_param_kind -> pn_torch.PARAMS
passed = failed = 0


def report(ok, name, text):
    global passed, failed
    if ok:
        passed += 1
    else:
        failed += 1
    print("%s %s: %s" % ("ok  " if ok else "FAIL", name, text), flush=True)


def build_lib():
    os.makedirs(os.path.join(ROOT, "build"), exist_ok=True)
    lib = os.path.join(ROOT, "build", "libpn_capi.so")
    cc = os.environ.get("CC", "cc")
    subprocess.check_call([cc, "-std=c99", "-O2", "-shared", "-fPIC", os.path.join(ROOT, "tests", "capi.c"),
                           "-lm", "-o", lib])
    return ctypes.CDLL(lib)


def ptr(t):
    return ctypes.c_void_p(t.data_ptr())


def random_F(n, d, gen, e_box=1.2):
    e = (torch.rand(n, d, dtype=DT, generator=gen) * 2 - 1) * e_box
    R1 = pt.random_rotations(n, d, gen)
    R2 = pt.random_rotations(n, d, gen)
    return (R1 @ torch.diag_embed(torch.exp(e)) @ R2).contiguous()


def rel_err(a, b, floor):
    """max over samples of |a - b| / max(|b|, floor)"""
    num = torch.linalg.vector_norm((a - b).reshape(a.shape[0], -1), dim=-1)
    den = torch.clamp(torch.linalg.vector_norm(b.reshape(b.shape[0], -1), dim=-1), min=floor)
    return float((num / den).max())


def check_targets(lib, n=10000):
    for name, spec in MATERIALS.items():
        mat = spec["mat"]
        par = torch.tensor([mat.E, mat.nu, mat.friction_angle_deg, mat.cohesion_strain, mat.yield_stress,
                            mat.hardening_modulus, mat.beta, mat.xi], dtype=DT)
        for d in (2, 3):
            gen = torch.Generator().manual_seed(100 + d)
            F = random_F(n, d, gen)
            lo, hi = spec["h"]
            h = (lo + (hi - lo) * torch.rand(n, dtype=DT, generator=gen)).contiguous()
            Tc = torch.zeros(n, d, d, dtype=DT)
            fails = lib.capi_T(EL[mat.elastic], PL[mat.plastic], ptr(par), d, n, ptr(F), ptr(h), ptr(Tc))
            Tt = pt.target_T(mat, F, h.unsqueeze(-1))
            scale = float(torch.linalg.matrix_norm(Tt).mean())
            err = rel_err(Tc, Tt, 1e-9 * scale)
            report(fails == 0 and err <= 1e-6, "target T %s %dD" % (name, d),
                   "max relative |T_C - T_torch| %.2e over %d F (bar 1e-6)" % (err, n))


class CModel:
    """A model rebuilt in torch from the numbers the C library holds."""

    def __init__(self, lib, i):
        ints = (ctypes.c_int * 24)()
        dbl = (ctypes.c_double * 46)()
        lib.capi_model_info(i, ints, dbl)
        self.name = lib.capi_model_name(i).decode()
        self.kind, self.dim, nl, act = ints[0], ints[1], ints[2], ints[3]
        self.sizes = [ints[4 + k] for k in range(nl + 1)]
        self.rm_index = ints[13]
        self.act = ACT[act]
        nin = self.sizes[0]
        self.shift = torch.tensor(dbl[0:nin], dtype=DT)
        self.scale = torch.tensor(dbl[16:16 + nin], dtype=DT)
        self.out_scale, self.E = dbl[32], dbl[33]
        self.h = (dbl[34], dbl[35])
        self.e_box, self.de_box = dbl[36], dbl[37]
        # a conditioned model: its parameters (pn_torch.PARAMS names) and ranges, softplus output
        self.params = [(KIND[ints[16 + k]], dbl[38 + 2 * k], dbl[39 + 2 * k]) for k in range(ints[14])]
        self.softplus = ints[15] == 1
        self.base = ints[20]   # 1: PN_MODEL_BASE_VON_MISES_HENCKY
        self.layers = []
        for l in range(nl):
            W = torch.zeros(self.sizes[l + 1], self.sizes[l], dtype=torch.float32)
            b = torch.zeros(self.sizes[l + 1], dtype=torch.float32)
            lib.capi_model_layer(i, l, ptr(W), ptr(b))
            self.layers.append((W.to(DT), b.to(DT)))

    def mlp(self, u):
        for k, (W, b) in enumerate(self.layers):
            u = u @ W.T + b
            if k < len(self.layers) - 1:
                u = self.act(u)
        return u

    def out(self, u):
        m = self.mlp(u)
        return torch.nn.functional.softplus(m) if self.softplus else m

    def energy_N(self, F, F0, h, prm):
        """N at F; prm [B, n_params]: a conditioned model's parameter inputs, after h"""
        x, x0 = pt.features_F(F), pt.features_F(F0)
        hc = torch.clamp(h, self.h[0], self.h[1])
        if len(self.shift) - len(self.params) == 2 * x.shape[-1] + 2:   # scaled encoding (pn_torch.scaled_raw)
            raw, S = pt.scaled_raw(x, x0)
            return self.out_scale * S * self.out((torch.cat([raw, hc, prm], -1) - self.shift) * self.scale)
        raw = torch.cat([x - x0, x0, hc, prm], -1)
        return self.out_scale * self.out((raw - self.shift) * self.scale)

    def radius(self, mat, s, h):
        import train  # the ReturnNet formula, with these weights
        d = s.shape[-1]
        _, _, tr, r = pt.hencky_split(s)
        K = mat.hardening_modulus
        rref = (pt.vm_tau_y(mat, h) + 2 * K / 3 * r) / (2 * mat.mu * torch.exp(2 * tr / d) + 2 * K / 3)
        hc = torch.clamp(h, self.h[0], self.h[1])
        g = self.mlp((train.return_features(s, hc) - self.shift) * self.scale)
        return rref * torch.exp(self.out_scale * g)

    def project(self, mat, s, h):
        e, ehat, tr, r = pt.hencky_split(s)
        outside = pt.dev_norm(pt.tau_principal(mat, s)) > pt.vm_tau_y(mat, h)
        n = ehat / torch.where(r > 0, r, torch.ones_like(r))
        dg = torch.clamp(r - self.radius(mat, s, h), min=0)
        dg = torch.minimum(dg, r)
        return torch.where(outside, torch.exp(e - dg * n), s)


def material_of(name):
    """the MATERIALS entry a model name starts with (longest match)"""
    key = max((k for k in MATERIALS if name.startswith(k + "_")), key=len)
    return key, MATERIALS[key]


def check_export(m):
    """on a machine that trained m: the header's weights are the checkpoint's, rounded to float"""
    ck = os.path.join(HERE, "ckpt", m.name + ".done.pt")
    if not os.path.exists(ck):
        return
    state = torch.load(ck)["model"]
    ws = [v for k, v in state.items() if k.startswith("net.") and k.endswith(".weight")]
    bs = [v for k, v in state.items() if k.startswith("net.") and k.endswith(".bias")]
    same = len(ws) == len(m.layers) and all(
        torch.equal(w.to(torch.float32).to(DT), W) and torch.equal(b.to(torch.float32).to(DT), B)
        for w, b, (W, B) in zip(ws, bs, m.layers))
    report(same, "model %s export" % m.name,
           "header weights %s the checkpoint's rounded to float" % ("are" if same else "are NOT"))


def check_models(lib, n=10000):
    count = lib.capi_model_count()
    models = [CModel(lib, i) for i in range(count)]
    for i, m in enumerate(models):
        key, spec = material_of(m.name)
        mat = spec["mat"]
        d = m.dim
        gen = torch.Generator().manual_seed(200 + i)
        lo, hi = m.h
        h = (lo + (hi - lo) * torch.rand(n, dtype=DT, generator=gen)).contiguous()
        if m.kind == 2:   # learned return mapping
            F = random_F(n, d, gen, m.e_box)
            Tc = torch.zeros(n, d, d, dtype=DT)
            fails = lib.capi_learned_T(i, n, ptr(F), ptr(h), ptr(Tc))
            U, s, V = pt.svd_rot(F)
            with torch.no_grad():
                z = m.project(mat, s, h.unsqueeze(-1))
            Tt = U @ torch.diag_embed(pt.tau_principal(mat, z) / s) @ V.transpose(-1, -2)
            err = rel_err(Tc, Tt, 1e-9 * float(torch.linalg.matrix_norm(Tt).mean()))
            report(fails == 0 and err <= 1e-5, "model %s" % m.name,
                   "learned T: max relative |T_C - T_torch| %.2e over %d F (bar 1e-5)" % (err, n))
            check_export(m)
            continue
        for point in range(3 if m.params else 1):   # a conditioned model: its low corner, centre, a random point
            check_energy(lib, models, i, m, mat, n, gen, h, point)
        check_export(m)


def base_vm_hencky(mat, F, h):
    """B(F; h) of PN_MODEL_BASE_VON_MISES_HENCKY: the StVK-Hencky von Mises incremental potential
    (docs/method.md) with the material's nu, yield and hardening, from the singular values."""
    d = F.shape[-1]
    e = torch.log(torch.linalg.svdvals(F))
    tr = e.sum(-1)
    r = torch.linalg.vector_norm(e - tr.unsqueeze(-1) / d, dim=-1)
    mu, lam = mat.mu, mat.lam
    if torch.is_tensor(mu):
        mu, lam = mu.squeeze(-1), lam.squeeze(-1)
    K = mat.hardening_modulus.squeeze(-1) if torch.is_tensor(mat.hardening_modulus) else mat.hardening_modulus
    kappa, beta = lam + 2 * mu / d, 2 * K / 3
    tauy = pt.vm_tau_y(mat, h).squeeze(-1)
    g = torch.clamp((2 * mu * r - tauy) / (2 * mu + beta), min=0)
    return kappa / 2 * tr * tr + mu * (r - g) ** 2 + tauy * g + beta / 2 * g * g


def check_energy(lib, models, i, m, mat, n, gen, h, point):
    """Psi and grad Psi of energy model m (at parameter point `point` if conditioned): C against torch"""
    d = m.dim
    u = [0.0, 0.5, float(torch.rand(1, dtype=DT, generator=gen))][point]
    values = torch.tensor([lo + u * (hi - lo) for _, lo, hi in m.params], dtype=DT)
    prm = values.expand(n, len(m.params))
    if m.params:
        mat = pt.with_params(mat, [p[0] for p in m.params], prm)
    F0 = random_F(n, d, gen, m.e_box)
    dF = (torch.rand(n, d, d, dtype=DT, generator=gen) * 2 - 1) * m.de_box
    F = (F0 + dF @ F0).contiguous()     # near F0, in every direction
    psi_c = torch.zeros(n, dtype=DT)
    P_c = torch.zeros(n, d, d, dtype=DT)
    fails = lib.capi_energy(i, ptr(values), n, ptr(F0), ptr(F), ptr(h), ptr(psi_c), ptr(P_c))
    hh = h.unsqueeze(-1)
    learned = models[m.rm_index] if m.rm_index >= 0 else None
    # T(F0) in torch: the analytic map, or this learned return mapping
    U, s0, V = pt.svd_rot(F0)
    with torch.no_grad():
        z0 = learned.project(mat, s0, hh) if learned else pt.return_map(mat, s0, hh)
    T0 = U @ torch.diag_embed(pt.tau_principal(mat, z0) / s0) @ V.transpose(-1, -2)
    F0g = F0.clone().requires_grad_(True)
    (gN0,) = torch.autograd.grad(m.energy_N(F0g, F0, hh, prm).sum(), F0g)
    C = gN0 - T0
    Fg = F.clone().requires_grad_(True)
    N = m.energy_N(Fg, F0, hh, prm).squeeze(-1)
    CF = (C * Fg).sum((-1, -2))
    if m.base == 1:   # the base energy B(F; h), in the gradient at F0 too
        F0g = F0.clone().requires_grad_(True)
        (gB0,) = torch.autograd.grad(base_vm_hencky(mat, F0g, hh).sum(), F0g)
        C = C + gB0
        CF = (C * Fg).sum((-1, -2))
        N = N + base_vm_hencky(mat, Fg, hh)
    psi_t = N - CF
    (P_t,) = torch.autograd.grad(psi_t.sum(), Fg)
    psi_t = psi_t.detach()
    mag = N.detach().abs() + CF.detach().abs() + 1e-12
    e_psi = float(((psi_c - psi_t).abs() / mag).max())
    e_P = rel_err(P_c, P_t, 1e-9 * float(torch.linalg.matrix_norm(P_t).mean()))
    at = (" at " + ", ".join("%s %.4g" % (p[0], float(v)) for p, v in zip(m.params, values))) if m.params else ""
    report(fails == 0 and e_psi <= 1e-5 and e_P <= 1e-5, "model %s%s" % (m.name, at),
           "max relative error psi %.2e, grad %.2e over %d inputs (bar 1e-5)" % (e_psi, e_P, n))


def main():
    torch.set_num_threads(1)
    lib = build_lib()
    lib.capi_model_name.restype = ctypes.c_char_p
    check_targets(lib)
    check_models(lib)
    print("%d passed, %d failed" % (passed, failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
