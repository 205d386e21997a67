"""Torch (CPU, float64) port of the constitutive formulas PlasticityNet trains against.

Everything works in principal space: a deformation F = U diag(s) V^T with U, V rotations is
handled through its singular values s (shape [B, d]); the force density of the return mapping is
T(F) = U diag(t(s)) V^T with t_i = tau_i(Z(s)) / s_i (PlasticityNet Eq. 7). The formulas follow
docs/method.md; gen/crosscheck.py compares them with plastinet.h on random inputs so
the two can never drift apart.
"""
import math

import torch

DT = torch.float64


# ---- materials -------------------------------------------------------------------------------

class Material:
    """Plain parameters of one elastoplastic material (E in Pa, angles in degrees)."""

    def __init__(self, elastic, plastic, E=1.0, nu=0.3, friction_angle_deg=0.0,
                 cohesion_strain=0.0, yield_stress=0.0, hardening_modulus=0.0,
                 camclay_beta=0.0, camclay_xi=0.0):
        self.elastic, self.plastic = elastic, plastic
        self.E, self.nu = float(E), float(nu)
        self.friction_angle_deg = float(friction_angle_deg)
        self.cohesion_strain = float(cohesion_strain)
        self.yield_stress, self.hardening_modulus = float(yield_stress), float(hardening_modulus)
        self.beta, self.xi = float(camclay_beta), float(camclay_xi)
        self.mu = self.E / (2 * (1 + self.nu))
        self.lam = self.E * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))
        self.sin_phi = math.sin(math.radians(self.friction_angle_deg))

    def kappa(self, d):
        return self.lam + 2 * self.mu / d


# The material parameters a conditioned model takes as inputs: name -> (Material attribute,
# plastinet.h pn_model_param_kind). Plastic stresses are ratios to E (E = 1 in training).
PARAMS = {
    "nu": ("nu", "PN_MODEL_PARAM_POISSON"),
    "friction_deg": ("friction_angle_deg", "PN_MODEL_PARAM_FRICTION_DEG"),
    "cohesion": ("cohesion_strain", "PN_MODEL_PARAM_COHESION"),
    "yield": ("yield_stress", "PN_MODEL_PARAM_YIELD_RATIO"),
    "hardening": ("hardening_modulus", "PN_MODEL_PARAM_HARDENING_RATIO"),
    "beta": ("beta", "PN_MODEL_PARAM_CAMCLAY_BETA"),
    "xi": ("xi", "PN_MODEL_PARAM_CAMCLAY_XI"),
}


def with_params(base, names, values):
    """A copy of material base whose parameters `names` are per sample: values [B, len(names)]
    (columns in the order of names). Every formula below broadcasts over the batch."""
    import copy
    m = copy.copy(base)
    for i, n in enumerate(names):
        setattr(m, PARAMS[n][0], values[:, i:i + 1])
    m.mu = m.E / (2 * (1 + m.nu))
    m.lam = m.E * m.nu / ((1 + m.nu) * (1 - 2 * m.nu))
    phi = m.friction_angle_deg
    m.sin_phi = torch.sin(phi * (math.pi / 180)) if torch.is_tensor(phi) else math.sin(math.radians(phi))
    return m


def dp_alpha(sin_phi, d):
    """Drucker-Prager cone coefficient for the Mohr-Coulomb angle (plastinet.h pn__dp_alpha):
    3D the triaxial-compression fit, 2D the exact in-plane Mohr-Coulomb limit sin(phi) / sqrt(2)."""
    if d == 2:
        return sin_phi / math.sqrt(2.0)
    return math.sqrt(2.0 / 3.0) * 2 * sin_phi / (3 - sin_phi)


# ---- elasticity: principal Kirchhoff stress tau_i(s) ------------------------------------------

def tau_principal(mat, s):
    d = s.shape[-1]
    mu, lam = mat.mu, mat.lam
    if mat.elastic == "stvk_hencky":          # tau_i = 2 mu e_i + lambda tr e
        e = torch.log(s)
        return 2 * mu * e + lam * e.sum(-1, keepdim=True)
    if mat.elastic == "neo_hookean":          # tau = mu (b - 1) + lambda log J
        logJ = torch.log(s).sum(-1, keepdim=True)
        return mu * (s * s - 1) + lam * logJ
    if mat.elastic == "neo_hookean_snow":     # tau = mu J^(-2/d) dev b + kappa/2 (J^2 - 1)
        J = s.prod(-1, keepdim=True)
        b = s * s
        dev = b - b.mean(-1, keepdim=True)
        return mu * J ** (-2.0 / d) * dev + mat.kappa(d) / 2 * (J * J - 1)
    if mat.elastic == "fixed_corotated":      # tau_i = 2 mu (s_i - 1) s_i + lambda (J - 1) J
        J = s.prod(-1, keepdim=True)
        return 2 * mu * (s - 1) * s + lam * (J - 1) * J
    raise ValueError(mat.elastic)


def hencky_split(s):
    """e = log s, its deviatoric part, tr e and |e_hat| (all batched)."""
    e = torch.log(s)
    tr = e.sum(-1, keepdim=True)
    ehat = e - tr / s.shape[-1]
    r = torch.linalg.vector_norm(ehat, dim=-1, keepdim=True)
    return e, ehat, tr, r


def dev_norm(t):
    return torch.linalg.vector_norm(t - t.mean(-1, keepdim=True), dim=-1, keepdim=True)


# ---- return mappings Z(s, h) -> z --------------------------------------------------------------

def return_drucker_prager(mat, s):
    """Klar et al. 2016 in the cohesion-shifted strain (no volume correction: h unused)."""
    d = s.shape[-1]
    c = mat.cohesion_strain
    e = torch.log(s) - c
    tr = e.sum(-1, keepdim=True)
    ehat = e - tr / d
    r = torch.linalg.vector_norm(ehat, dim=-1, keepdim=True)
    alpha = dp_alpha(mat.sin_phi, d)
    dg = r + (d * mat.lam + 2 * mat.mu) / (2 * mat.mu) * tr * alpha
    rsafe = torch.where(r > 0, r, torch.ones_like(r))
    shear = torch.exp(e - dg * ehat / rsafe + c)
    z = torch.where(dg > 0, shear, s)
    z = torch.where(tr >= 0, torch.ones_like(s) * (torch.exp(c) if torch.is_tensor(c) else math.exp(c)), z)
    return z


def vm_tau_y(mat, h):
    return math.sqrt(2.0 / 3.0) * (mat.yield_stress + mat.hardening_modulus * h)


def return_von_mises_hencky(mat, s, h):
    """Closed form for StVK-Hencky: dev tau = 2 mu e_hat."""
    _, ehat, tr, r = hencky_split(s)
    e = torch.log(s)
    tauy = vm_tau_y(mat, h)
    outside = 2 * mat.mu * r > tauy
    dg = (2 * mat.mu * r - tauy) / (2 * mat.mu + 2 * mat.hardening_modulus / 3)
    rsafe = torch.where(r > 0, r, torch.ones_like(r))
    z = torch.exp(e - dg * ehat / rsafe)
    return torch.where(outside, z, s)


def vm_residual(mat, e, n, g, h):
    """f(g) = |dev tau(exp(e - g n))| - tau_Y(h + sqrt(2/3) g): the volume-preserving return."""
    z = torch.exp(e - g * n)
    return dev_norm(tau_principal(mat, z)) - vm_tau_y(mat, h) - 2 * mat.hardening_modulus / 3 * g


def return_von_mises_rootfind(mat, s, h, iters=64):
    """Any elasticity: bisection on f over [0, |e_hat|] (f > 0 at 0 outside, f < 0 at |e_hat|
    where the stress is hydrostatic): 64 halvings reach adjacent doubles (the interval is at
    most |e_hat| wide, and 2^-53 of it is below its rounding), so more would change nothing."""
    e, ehat, tr, r = hencky_split(s)
    tauy = vm_tau_y(mat, h)
    y0 = dev_norm(tau_principal(mat, s)) - tauy
    outside = y0 > 0
    rsafe = torch.where(r > 0, r, torch.ones_like(r))
    n = ehat / rsafe
    lo = torch.zeros_like(r)
    hi = r.clone()
    for _ in range(iters):
        mid = (lo + hi) / 2
        f = vm_residual(mat, e, n, mid, h)
        lo = torch.where(f > 0, mid, lo)
        hi = torch.where(f > 0, hi, mid)
    g = (lo + hi) / 2
    return torch.where(outside, torch.exp(e - g * n), s)


def camclay_quantities(mat, s, h):
    d = s.shape[-1]
    kappa = mat.kappa(d)
    J = s.prod(-1, keepdim=True)
    b = s * s
    p = -kappa / 2 * (J * J - 1)
    p0 = kappa * (1e-5 + torch.sinh(mat.xi * torch.clamp(-h, min=0)))
    alpha = dp_alpha(mat.sin_phi, 3)  # Cam-Clay's M: the triaxial mapping in 2D as well
    M = alpha * d / math.sqrt(2.0 / (6 - d))
    shat = mat.mu * J ** (-2.0 / d) * (b - b.mean(-1, keepdim=True))
    q2 = (6 - d) / 2 * (shat * shat).sum(-1, keepdim=True)
    y = (1 + 2 * mat.beta) * q2 + M * M * (p + mat.beta * p0) * (p - p0)
    return kappa, J, p, p0, M, q2, y


def camclay_shear(s, J, c):
    """b_new = c n + m 1 with det b_new = J^2 (exact: keeps p), n the unit direction of dev b."""
    d = s.shape[-1]
    b = s * s
    nb = b - b.mean(-1, keepdim=True)
    nn = torch.linalg.vector_norm(nb, dim=-1, keepdim=True)
    n = nb / torch.where(nn > 0, nn, torch.ones_like(nn))
    if d == 2:
        m = torch.sqrt(J * J + c * c * n[:, :1] ** 2)
    else:
        m = b.mean(-1, keepdim=True)   # f(m) = prod(m + c n_i) - J^2: convex, Newton decreases
        for _ in range(60):             # monotone and quadratic: stop once no step is left
            a = m + c * n
            f = a.prod(-1, keepdim=True) - J * J
            fp = a[:, 1:2] * a[:, 2:3] + a[:, 0:1] * a[:, 2:3] + a[:, 0:1] * a[:, 1:2]
            step = f / fp
            m = torch.where(step > 0, m - step, m)
            if not bool((step > 1e-15 * m).any()):
                break
    return torch.sqrt(m + c * n)


def return_camclay(mat, s, h):
    d = s.shape[-1]
    kappa, J, p, p0, M, q2, y = camclay_quantities(mat, s, h)
    beta = mat.beta
    comp = p > p0
    tens = p < -beta * p0
    Jn = torch.where(comp, torch.sqrt(torch.clamp(1 - 2 * p0 / kappa, min=0)),
                     torch.sqrt(1 + 2 * beta * p0 / kappa))
    tip = Jn ** (1.0 / d) * torch.ones_like(s)
    q2t = -M * M * (p + beta * p0) * (p - p0) / (1 + 2 * beta)
    shat_t = torch.sqrt(torch.clamp(q2t, min=0) / ((6 - d) / 2))
    c = shat_t / (mat.mu * J ** (-2.0 / d))
    shear = camclay_shear(s, J, c)
    z = torch.where(y > 0, shear, s)
    return torch.where(comp | tens, tip, z)


def return_map(mat, s, h, learned=None):
    """z = Z(s, h) for the material; learned: a ReturnNet replacing the von Mises root find."""
    if mat.plastic == "drucker_prager":
        return return_drucker_prager(mat, s)
    if mat.plastic == "von_mises":
        if learned is not None:
            return learned.project(mat, s, h)
        if mat.elastic == "stvk_hencky":
            return return_von_mises_hencky(mat, s, h)
        return return_von_mises_rootfind(mat, s, h)
    if mat.plastic == "cam_clay":
        return return_camclay(mat, s, h)
    if mat.plastic == "none":
        return s
    raise ValueError(mat.plastic)


def target_principal(mat, s, h, learned=None):
    """t_i = tau_i(Z(s)) / s_i: T(F) = U diag(t) V^T (PlasticityNet Eq. 7)."""
    z = return_map(mat, s, h, learned)
    return tau_principal(mat, z) / s


def svd_rot(F):
    """SVD with rotation-valued U, V (det F > 0 assumed): F = U diag(s) V^T."""
    U, s, Vh = torch.linalg.svd(F)
    V = Vh.transpose(-1, -2)
    flip = (torch.det(U) < 0)
    sign = torch.ones_like(s)
    sign[flip, -1] = -1
    U = U * sign.unsqueeze(-2)
    V = V * sign.unsqueeze(-2)
    return U, s, V


def target_T(mat, F, h, learned=None):
    """T(F) = tau(Z(F)) F^-T for a batch of matrices F [B, d, d], h [B, 1]."""
    U, s, V = svd_rot(F)
    t = target_principal(mat, s, h, learned)
    return U @ torch.diag_embed(t) @ V.transpose(-1, -2)


# ---- sampling (PlasticityNet Section 5.1) ------------------------------------------------------

def random_rotations(n, d, gen):
    """Haar-random rotations: QR of a Gaussian matrix with the sign fix, det forced to +1."""
    A = torch.randn(n, d, d, dtype=DT, generator=gen)
    Q, R = torch.linalg.qr(A)
    Q = Q * torch.sign(torch.diagonal(R, dim1=-2, dim2=-1)).unsqueeze(-2)
    flip = torch.det(Q) < 0
    Q[flip, :, 0] = -Q[flip, :, 0]
    return Q


# ---- rotation-invariant features of F ----------------------------------------------------------
# Smooth functions of the invariants of C = F^T F (no SVD needed in C): x1 = log J,
#   2D: a = log(tr C / 2) - log J  (= log cosh(e_1 - e_2) ~ |e_hat|^2)
#   3D: a = log(tr C / 3) - 2/3 log J, b = log(II_C / 3) - 4/3 log J,
#       features ((a + b)/2 ~ 2/3 |e_hat|^2, a - b ~ 8/9 tr e_hat^3)
# Psi built on them is exactly objective and isotropic; plastinet.h computes the same values
# and their F-derivatives from C.

def features(s):
    d = s.shape[-1]
    logJ = torch.log(s).sum(-1, keepdim=True)
    b = s * s
    if d == 2:
        a = torch.log(b.sum(-1, keepdim=True) / 2) - logJ
        return torch.cat([logJ, a], -1)
    a = torch.log(b.mean(-1, keepdim=True)) - 2.0 / 3.0 * logJ
    ii = (b[:, 0:1] * b[:, 1:2] + b[:, 0:1] * b[:, 2:3] + b[:, 1:2] * b[:, 2:3]) / 3
    c = torch.log(ii) - 4.0 / 3.0 * logJ
    return torch.cat([logJ, (a + c) / 2, a - c], -1)


def features_F(F):
    """The same features computed from C = F^T F (used by the cross-check)."""
    d = F.shape[-1]
    C = F.transpose(-1, -2) @ F
    I1 = torch.diagonal(C, dim1=-2, dim2=-1).sum(-1, keepdim=True)
    logJ = torch.log(torch.det(F)).unsqueeze(-1)
    if d == 2:
        return torch.cat([logJ, torch.log(I1 / 2) - logJ], -1)
    I2 = (C * C).sum((-1, -2)).unsqueeze(-1)
    II = (I1 * I1 - I2) / 2
    a = torch.log(I1 / 3) - 2.0 / 3.0 * logJ
    c = torch.log(II / 3) - 4.0 / 3.0 * logJ
    return torch.cat([logJ, (a + c) / 2, a - c], -1)


# ---- scale-normalised inputs of the energy network ("scaled" encoding) --------------------------
# Cohesionless Drucker-Prager on StVK-Hencky is positively homogeneous: scaling every Hencky strain
# by k scales the projected stress by k. A sand column at E = 1e7 Pa lives at strains ~1e-4..1e-3,
# where a smooth network of raw features is just its linearisation at F0 = I (an elastic response,
# no better than the lagged energy). So the network sees the features divided by a strain scale s
# of the pair (F, F0), to the power that makes each degree 0, plus s itself, and N = s^2 M(u):
#   q(x) = x1^2 / d + c x2  (~ |e|^2, c = 1 in 2D, 3/2 in 3D),  s^2 = q(x) + q(x0) + EPS^2,
#   raw = [(x - x0) / s^p, x0 / s^p, s, h],  p = (1, 2, 2) for (log J, quadratic, cubic): the cubic
#   one (the Lode angle, a difference of two logarithms exact to ~1e-16 only) fades at small
#   strains rather than amplify its rounding; Drucker-Prager and Hencky do not depend on it.
SCALED_EPS = 1e-6


def scaled_raw(x, x0):
    """raw inputs of the scaled encoding and s^2 (see above)."""
    d = 2 if x.shape[-1] == 2 else 3
    c = 1.0 if d == 2 else 1.5
    q = lambda v: v[:, 0:1] ** 2 / d + c * v[:, 1:2]  # noqa: E731
    S = q(x) + q(x0) + SCALED_EPS ** 2
    s = torch.sqrt(S)
    pw = torch.cat([s, S] + ([S] if d == 3 else []), -1)
    return torch.cat([(x - x0) / pw, x0 / pw, s], -1), S
