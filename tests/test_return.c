/* test_return.c - return mappings: invariants, an independent reference, bad input.

   Every trial F is built as F = R1 diag(exp(e)) R2 with random rotations R1, R2, so its SVD is
   known exactly without calling the library. The expected Z, h_new, yield value and T come
   from a principal-space reference written here from docs/method.md and the header's
   documentation (material parameters read from the pn_material_desc, Lame constants
   recomputed), with root finds done by plain bisection. The library's Z is brought back into
   the test's frame, D = R1^T Z R2^T, which must be diagonal (coaxiality) and holds the
   projected stretches in the test's order.

   Checked per sample (thousands per material and dimension, elastic and plastic cases both
   required): Z and h_new against the reference; Z = F and h unchanged inside; the result on
   the yield surface (relative residual from pn_yield_function's scale); volume preserved
   where the model says so; idempotence; rotation equivariance Z(Q F R) = Q Z(F) R (and T);
   T = tau(Z) F^-T both through pn_kirchhoff_stress/pn_mat_inverse and through the closed-form
   principal stresses. Model-specific: von Mises hardening (h_new >= h, yield stress
   sigma_Y0 + K h_new reached, a += sqrt(2/3) |dH|, flow along the trial deviator), Drucker-
   Prager expansion to the apex, Cam-Clay tips at p0 / -beta p0, Stomakhin stretch box and
   log Jp update. Separate tests: the exact von Mises energy's gradient equals T, and bad
   input (non-finite F, bad parameters, unsupported combinations, inverted F). */

#define PN_TR_SAMPLES 2000 /* random trial F per material and dimension */

/* ---- small dense helpers, independent of the library (the shared ones: test_util.h) ---- */

static double pn_tr_maxabs(int n, const double *A) {
    double m = 0;
    int i;
    for (i = 0; i < n; ++i) m = fabs(A[i]) > m ? fabs(A[i]) : m;
    return m;
}

/* max |A - B| / max(max |B|, floor) */
static double pn_tr_reldiff(int n, const double *A, const double *B, double floor) {
    double m = 0, s = pn_tr_maxabs(n, B);
    int i;
    for (i = 0; i < n; ++i) m = fabs(A[i] - B[i]) > m ? fabs(A[i] - B[i]) : m;
    if (m != m) return HUGE_VAL;
    return m / (s > floor ? s : floor);
}

static double pn_tr_max(double a, double b) { return a > b ? a : b; }

static void pn_tr_rotation(pn_test_rng *rng, int d, double *R) {
    if (d == 2) {
        double a = pn_test_rng_range(rng, -3.14159265358979, 3.14159265358979);
        R[0] = cos(a); R[1] = -sin(a);
        R[2] = sin(a); R[3] = cos(a);
    } else { /* uniform unit quaternion (Shoemake) */
        double u1 = pn_test_rng_uniform(rng), u2 = 6.283185307179586 * pn_test_rng_uniform(rng);
        double u3 = 6.283185307179586 * pn_test_rng_uniform(rng);
        double w = sqrt(1 - u1) * sin(u2), x = sqrt(1 - u1) * cos(u2);
        double y = sqrt(u1) * sin(u3), z = sqrt(u1) * cos(u3);
        R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - z * w); R[2] = 2 * (x * z + y * w);
        R[3] = 2 * (x * y + z * w); R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - x * w);
        R[6] = 2 * (x * z - y * w); R[7] = 2 * (y * z + x * w); R[8] = 1 - 2 * (x * x + y * y);
    }
}

/* ---- the materials under test ---------------------------------------------------------- */

typedef struct pn_tr_case {
    const char *name;
    pn_material_desc desc;
    double mag_lo, mag_hi; /* log10 range of the trial log-strain magnitude            */
    double h_lo, h_hi;     /* range of the plastic state                                */
    double h_zero;         /* probability of exactly h = 0                              */
    int no_interior;       /* the model has no elastic interior (DP with phi = 0)       */
} pn_tr_case;

static void pn_tr_case_init(pn_tr_case *c, const char *name, pn_plastic_model p,
                            pn_elastic_model e, double E, double nu) {
    memset(c, 0, sizeof *c);
    c->name = name;
    c->desc.plastic = p;
    c->desc.elastic = e;
    c->desc.youngs_modulus_pa = E;
    c->desc.poisson_ratio = nu;
    c->mag_lo = -4;
    c->mag_hi = 0; /* |e_i| <= 1 as the brief asks */
    c->h_zero = 1;
}

static void pn_tr_dp(pn_tr_case *c, const char *name, double phi, double coh, int vc) {
    pn_tr_case_init(c, name, PN_PLASTIC_DRUCKER_PRAGER, PN_ELASTIC_DEFAULT, 1e7, 0.3);
    c->desc.friction_angle_deg = phi;
    c->desc.cohesion_strain = coh;
    c->desc.volume_correction = vc;
    if (vc) { /* a stored volume gain half of the time */
        c->h_hi = 0.05;
        c->h_zero = 0.5;
    }
}

static void pn_tr_vm(pn_tr_case *c, const char *name, pn_elastic_model e, double K) {
    pn_tr_case_init(c, name, PN_PLASTIC_VON_MISES, e, 200e9, 0.3);
    c->desc.yield_stress_pa = 250e6;
    c->desc.hardening_modulus_pa = K;
    c->mag_lo = -4.5;
    c->h_hi = 0.2;
    c->h_zero = 0.3;
}

static void pn_tr_cc(pn_tr_case *c, const char *name, double phi, double beta, double xi,
                     int no_hard) {
    pn_tr_case_init(c, name, PN_PLASTIC_CAM_CLAY, PN_ELASTIC_DEFAULT, 1e6, 0.3);
    c->desc.friction_angle_deg = phi;
    c->desc.camclay_beta = beta;
    c->desc.camclay_xi = xi;
    c->desc.camclay_no_hardening = no_hard;
    c->h_lo = -0.5;
    c->h_zero = 0.1;
}

static void pn_tr_snow(pn_tr_case *c, const char *name) {
    pn_tr_case_init(c, name, PN_PLASTIC_SNOW_STOMAKHIN, PN_ELASTIC_DEFAULT, 1.4e5, 0.2);
    c->desc.snow_theta_c = 2.5e-2;
    c->desc.snow_theta_s = 7.5e-3;
    c->desc.snow_xi = 10;
    c->mag_lo = -3;
    c->h_lo = -0.3;
    c->h_hi = 0.3;
    c->h_zero = 0.2;
}

/* ---- the reference return mapping (principal space, docs/method.md) ---------------------- */

enum { PN_TR_INSIDE, PN_TR_FLOW, PN_TR_TIP, PN_TR_TIP_TENSION };

typedef struct pn_tr_ref {
    int kind;       /* PN_TR_INSIDE ... */
    int border;     /* a decision within rounding of its threshold: skip case-specific checks */
    int h_checked;  /* the reference defines h_new for this sample */
    double z[3], hn;
    double y;       /* the yield function at the trial point (Stomakhin: only its sign) */
    double p_tip;   /* Cam-Clay: the pressure at the tip reached */
} pn_tr_ref;

typedef struct pn_tr_lame { double mu, la, kappa; } pn_tr_lame;

static pn_tr_lame pn_tr_lame_of(const pn_material_desc *p, int d) {
    pn_tr_lame l;
    double E = p->youngs_modulus_pa, nu = p->poisson_ratio;
    l.mu = t_mu(E, nu);
    l.la = t_lambda(E, nu);
    l.kappa = l.la + 2 * l.mu / d;
    return l;
}

/* the documented mapping (docs/method.md): 2D the in-plane Mohr-Coulomb limit, 3D the
   triaxial-compression fit; Cam-Clay's M uses the 3D one in both */
static double pn_tr_dp_alpha(double phi_deg, int d) {
    double s = sin(phi_deg * 3.14159265358979323846 / 180);
    return d == 2 ? s / sqrt(2.0) : sqrt(2.0 / 3) * 2 * s / (3 - s);
}

/* mean and deviator norm of v */
static double pn_tr_dev(int d, const double *v, double *dev) {
    double mean = 0, n2 = 0;
    int i;
    for (i = 0; i < d; ++i) mean += v[i] / d;
    for (i = 0; i < d; ++i) {
        dev[i] = v[i] - mean;
        n2 += dev[i] * dev[i];
    }
    return sqrt(n2);
}

static void pn_tr_ref_dp(const pn_material_desc *p, int d, const double *e, double h,
                         pn_tr_ref *r) {
    pn_tr_lame l = pn_tr_lame_of(p, d);
    double c = p->cohesion_strain, hv = p->volume_correction ? h : 0, ec[3] = {0, 0, 0}, eh[3], tr = 0;
    double alpha = pn_tr_dp_alpha(p->friction_angle_deg, d), bulk = d * l.la + 2 * l.mu, rn, dg;
    double ey[3] = {0, 0, 0}, ehy[3], try_ = 0;
    int i;
    for (i = 0; i < d; ++i) {
        ec[i] = e[i] - c + hv / d; /* cohesion shift; the volume credit added to tr e */
        ey[i] = e[i] - c;
        tr += ec[i];
        try_ += ey[i];
    }
    /* y = |dev tau| + alpha tr tau of the shifted strain (no credit): 2 mu |e^| + alpha bulk tr e */
    r->y = 2 * l.mu * pn_tr_dev(d, ey, ehy) + alpha * bulk * try_;
    rn = pn_tr_dev(d, ec, eh);
    r->h_checked = 1;
    r->hn = p->volume_correction ? 0 : h;
    if (tr >= 0) { /* Klar 2016: expansion goes to the stress-free apex */
        r->kind = PN_TR_TIP;
        r->border = tr < 1e-12;
        for (i = 0; i < d; ++i) r->z[i] = exp(c);
        if (p->volume_correction) r->hn = tr;
        return;
    }
    r->border = -tr < 1e-12;
    dg = rn + bulk / (2 * l.mu) * tr * alpha;
    if (fabs(dg) <= 1e-10 * (rn + fabs(tr))) r->border = 1;
    if (dg <= 0) {
        r->kind = PN_TR_INSIDE;
        for (i = 0; i < d; ++i) r->z[i] = exp(ec[i] + c);
        return;
    }
    r->kind = PN_TR_FLOW;
    for (i = 0; i < d; ++i) r->z[i] = exp(ec[i] - dg * eh[i] / rn + c);
}

static void pn_tr_ref_vm(const pn_material_desc *p, int d, const double *e, double h,
                         pn_tr_ref *r) {
    pn_tr_lame l = pn_tr_lame_of(p, d);
    double sy0 = p->yield_stress_pa, K = p->hardening_modulus_pa, tauy = sqrt(2.0 / 3) * (sy0 + K * h);
    double eh[3], rn = pn_tr_dev(d, e, eh), n[3], g;
    int i;
    r->h_checked = 1;
    r->hn = h;
    for (i = 0; i < d; ++i) r->z[i] = exp(e[i]);
    if (p->elastic == PN_ELASTIC_NEO_HOOKEAN) {
        /* Neo-Hookean: tau_i = mu (s_i^2 - 1) + lambda log J, so |dev tau| = mu |dev s^2| */
        double b[3], db[3];
        for (i = 0; i < d; ++i) b[i] = exp(2 * e[i]);
        r->y = l.mu * pn_tr_dev(d, b, db) - tauy;
    } else {
        r->y = 2 * l.mu * rn - tauy; /* StVK-Hencky: dev tau = 2 mu e^ */
    }
    r->kind = r->y > 0 ? PN_TR_FLOW : PN_TR_INSIDE;
    r->border = fabs(r->y) <= 1e-10 * tauy;
    if (r->kind == PN_TR_INSIDE) return;
    for (i = 0; i < d; ++i) n[i] = eh[i] / rn;
    if (p->elastic == PN_ELASTIC_NEO_HOOKEAN) {
        /* volume-preserving return H = e - g n with |dev tau(exp H)| = sqrt(2/3) sigma_Y(a + sqrt(2/3) g):
           plain bisection on [0, |e^|] (f > 0 at 0, f = -tau_Y < 0 at |e^| where dev H = 0) */
        double lo = 0, hi = rn;
        int it;
        for (it = 0; it < 200; ++it) {
            double mid = 0.5 * (lo + hi), b[3], db[3], f;
            if (mid <= lo || mid >= hi) break;
            for (i = 0; i < d; ++i) b[i] = exp(2 * (e[i] - mid * n[i]));
            f = l.mu * pn_tr_dev(d, b, db) - sqrt(2.0 / 3) * (sy0 + K * (h + sqrt(2.0 / 3) * mid));
            if (f > 0) lo = mid; else hi = mid;
        }
        g = 0.5 * (lo + hi);
    } else { /* closed form (docs/method.md, Simo-Hughes radial return) */
        g = (2 * l.mu * rn - tauy) / (2 * l.mu + 2 * K / 3);
    }
    for (i = 0; i < d; ++i) r->z[i] = exp(e[i] - g * n[i]);
    r->hn = h + sqrt(2.0 / 3) * g;
}

typedef struct pn_tr_cc_q { double kappa, mu, J, p, p0, M, q2, y; } pn_tr_cc_q;

static pn_tr_cc_q pn_tr_cc_eval(const pn_material_desc *p, int d, const double *s, double h) {
    pn_tr_lame l = pn_tr_lame_of(p, d);
    pn_tr_cc_q q;
    double b[3], db[3], alpha = pn_tr_dp_alpha(p->friction_angle_deg, 3), beta = p->camclay_beta, sh;
    int i;
    q.kappa = l.kappa;
    q.mu = l.mu;
    q.J = 1;
    for (i = 0; i < d; ++i) {
        q.J *= s[i];
        b[i] = s[i] * s[i];
    }
    q.p = -l.kappa / 2 * (q.J * q.J - 1);
    q.p0 = l.kappa * (1e-5 + sinh(p->camclay_xi * pn_tr_max(-h, 0)));
    q.M = alpha * d / sqrt(2.0 / (6 - d));
    sh = l.mu * pow(q.J, -2.0 / d) * pn_tr_dev(d, b, db);
    q.q2 = (6.0 - d) / 2 * sh * sh;
    q.y = (1 + 2 * beta) * q.q2 + q.M * q.M * (q.p + beta * q.p0) * (q.p - q.p0);
    return q;
}

static void pn_tr_ref_cc(const pn_material_desc *p, int d, const double *e, double h,
                         pn_tr_ref *r) {
    double s[3], beta = p->camclay_beta, Jn;
    int i, hard = !p->camclay_no_hardening;
    pn_tr_cc_q q;
    for (i = 0; i < d; ++i) s[i] = exp(e[i]);
    q = pn_tr_cc_eval(p, d, s, h);
    r->y = q.y;
    r->hn = h;
    r->h_checked = 1;
    for (i = 0; i < d; ++i) r->z[i] = s[i];
    r->border = fabs(q.p - q.p0) <= 1e-10 * q.kappa || fabs(q.p + beta * q.p0) <= 1e-10 * q.kappa;
    if (q.p > q.p0 || q.p < -beta * q.p0) { /* the tips: no shear, p onto p0 or -beta p0 */
        r->kind = q.p > q.p0 ? PN_TR_TIP : PN_TR_TIP_TENSION;
        r->p_tip = q.p > q.p0 ? q.p0 : -beta * q.p0;
        Jn = sqrt(1 - 2 * r->p_tip / q.kappa); /* p = -kappa/2 (J^2 - 1) */
        for (i = 0; i < d; ++i) r->z[i] = pow(Jn, 1.0 / d);
        if (hard) r->hn = h + log(q.J / Jn);
        return;
    }
    if (fabs(q.y) <= 1e-10 * (1 + 2 * beta) * q.q2) r->border = 1;
    if (q.y <= 0) {
        r->kind = PN_TR_INSIDE;
        return;
    }
    r->kind = PN_TR_FLOW;
    {
        /* keep p (so J) and the direction of dev b; |dev b| onto the surface:
           b_new = m 1 + c n with prod(m + c n_i) = J^2, m found by bisection */
        double b[3] = {0, 0, 0}, n[3], dn, q2t, c, lo, hi, logJ2 = 2 * log(q.J);
        int it;
        for (i = 0; i < d; ++i) b[i] = s[i] * s[i];
        dn = pn_tr_dev(d, b, n);
        for (i = 0; i < d; ++i) n[i] /= dn;
        q2t = -q.M * q.M * (q.p + beta * q.p0) * (q.p - q.p0) / (1 + 2 * beta);
        c = sqrt(q2t / ((6.0 - d) / 2)) / (q.mu * pow(q.J, -2.0 / d));
        lo = 0;
        for (i = 0; i < d; ++i) lo = pn_tr_max(lo, -c * n[i]);
        hi = lo + 1;
        for (it = 0; it < 200; ++it) { /* grow hi until prod(hi + c n_i) >= J^2 */
            double f = -logJ2;
            for (i = 0; i < d; ++i) f += log(hi + c * n[i]);
            if (f >= 0) break;
            hi = lo + 2 * (hi - lo);
        }
        for (it = 0; it < 300; ++it) {
            double mid = 0.5 * (lo + hi), f = -logJ2;
            if (mid <= lo || mid >= hi) break;
            for (i = 0; i < d; ++i) f += log(mid + c * n[i]);
            if (f < 0) lo = mid; else hi = mid;
        }
        for (i = 0; i < d; ++i) r->z[i] = sqrt(0.5 * (lo + hi) + c * n[i]);
    }
    if (hard) {
        /* Wolper 2019 hardening: the line from the trial (p, q) towards the ellipse centre
           (p0 (1 - beta) / 2, 0) crosses y = 0 at the "fake" pressure p_x; log Jp moves by
           log(J / J_x) with p_x = -kappa/2 (J_x^2 - 1). Bisection on t in [0, 1]. */
        double pc = (1 - beta) * q.p0 / 2, lo = 0, hi = 1, px, jx2;
        int it;
        for (it = 0; it < 200; ++it) {
            double t = 0.5 * (lo + hi), P = pc + t * (q.p - pc);
            double y = (1 + 2 * beta) * t * t * q.q2 + q.M * q.M * (P + beta * q.p0) * (P - q.p0);
            if (t <= lo || t >= hi) break;
            if (y > 0) hi = t; else lo = t;
        }
        px = pc + 0.5 * (lo + hi) * (q.p - pc);
        jx2 = 1 - 2 * px / q.kappa;
        if (jx2 > 0) r->hn = h + 0.5 * log(q.J * q.J / jx2);
        else r->h_checked = 0; /* the fake pressure has no volume: behaviour undocumented */
    }
}

static void pn_tr_ref_snow(const pn_material_desc *p, int d, const double *e, double h,
                           pn_tr_ref *r) {
    double lo = 1 - p->snow_theta_c, hi = 1 + p->snow_theta_s, J = 1, Jn = 1, margin = HUGE_VAL;
    int i, clamped = 0;
    r->y = -HUGE_VAL;
    for (i = 0; i < d; ++i) {
        double s = exp(e[i]);
        r->z[i] = s < lo ? lo : s > hi ? hi : s;
        clamped |= r->z[i] != s;
        J *= s;
        Jn *= r->z[i];
        r->y = pn_tr_max(r->y, pn_tr_max(s - hi, lo - s));
        if (fabs(s - hi) < margin) margin = fabs(s - hi);
        if (fabs(s - lo) < margin) margin = fabs(s - lo);
    }
    r->kind = clamped ? PN_TR_FLOW : PN_TR_INSIDE;
    r->border = margin <= 1e-13;
    r->h_checked = 1;
    r->hn = clamped ? h + log(J / Jn) : h; /* Stomakhin 2013: Jp absorbs the clamped volume */
}

static void pn_tr_reference(const pn_material_desc *p, int d, const double *e, double h,
                            pn_tr_ref *r) {
    memset(r, 0, sizeof *r);
    switch (p->plastic) {
    case PN_PLASTIC_DRUCKER_PRAGER: pn_tr_ref_dp(p, d, e, h, r); break;
    case PN_PLASTIC_VON_MISES: pn_tr_ref_vm(p, d, e, h, r); break;
    case PN_PLASTIC_CAM_CLAY: pn_tr_ref_cc(p, d, e, h, r); break;
    default: pn_tr_ref_snow(p, d, e, h, r); break;
    }
}

/* Principal Kirchhoff stresses of the elastic model at stretches z (test's own formulas). */
static void pn_tr_tau_principal(const pn_material_desc *p, int d, const double *z, double h,
                                double *tau) {
    pn_tr_lame l = pn_tr_lame_of(p, d);
    double J = 1, lz[3], trl = 0;
    int i;
    for (i = 0; i < d; ++i) {
        J *= z[i];
        lz[i] = log(z[i]);
        trl += lz[i];
    }
    for (i = 0; i < d; ++i) {
        switch (p->plastic) {
        case PN_PLASTIC_DRUCKER_PRAGER: /* StVK-Hencky */
            tau[i] = 2 * l.mu * lz[i] + l.la * trl;
            break;
        case PN_PLASTIC_VON_MISES:
            if (p->elastic == PN_ELASTIC_NEO_HOOKEAN) tau[i] = l.mu * (z[i] * z[i] - 1) + l.la * trl;
            else tau[i] = 2 * l.mu * lz[i] + l.la * trl;
            break;
        case PN_PLASTIC_CAM_CLAY: { /* tau = mu J^(-2/d) dev(b) + kappa/2 (J^2 - 1) I */
            double trb = 0;
            int k;
            for (k = 0; k < d; ++k) trb += z[k] * z[k];
            tau[i] = l.mu * pow(J, -2.0 / d) * (z[i] * z[i] - trb / d) + l.kappa / 2 * (J * J - 1);
            break;
        }
        default: { /* fixed corotated with Lame scaled by exp(xi (1 - Jp)), Jp = exp(h) */
            double f = exp(p->snow_xi * (1 - exp(h)));
            tau[i] = 2 * l.mu * f * (z[i] - 1) * z[i] + l.la * f * (J - 1) * J;
            break;
        }
        }
    }
}

/* ---- the per-sample checks ------------------------------------------------------------- */

/* Rounding floors. Z and T come back as matrices with O(1) entries, so the log strain they
   carry is known to ~1e-16 absolute, not relative: at a strain of 1e-6 a relative figure
   cannot beat 1e-10 whatever the library does. Relative figures are therefore taken against
   at least the value at a log strain of 1e-4 (stress E 1e-4, yield-function 2 mu 1e-4 or its
   square for Cam-Clay, energy E 1e-8); a change of state against 1e-4 (1 + |h|), since h is
   itself a sum of logs known to ~1e-16 (1 + |h|) absolute. */
#define PN_TR_STRAIN_FLOOR 1e-4

static double pn_tr_h_err(double got, double want, double h_old) {
    double scale = pn_tr_max(fabs(want - h_old), PN_TR_STRAIN_FLOOR * (1 + fabs(want)));
    return fabs(got - want) / scale;
}

static double pn_tr_yield_floor(const pn_material_desc *p, int d) {
    double f = 2 * pn_tr_lame_of(p, d).mu * PN_TR_STRAIN_FLOOR;
    if (p->plastic == PN_PLASTIC_CAM_CLAY) return f * f;
    if (p->plastic == PN_PLASTIC_SNOW_STOMAKHIN) return 0; /* dimensionless, scale 1 */
    return f;
}

typedef struct pn_tr_stats {
    int n, inside, flow, tip, tip_t, border, errors, softened, h_unchecked, ident_h_bad;
    int vm_h_decreased, tip_h_wrong_sign;
    double y_ref, z_ref, h_ref, ident, resid, resid_tip, volume, coaxial, T_kirch, T_ref;
    double idem, idem_old, equiv, vm_yield, vm_da, vm_dir, snow_box;
    char first_error[240]; /* the first failing call, for the report */
} pn_tr_stats;

static void pn_tr_error(pn_tr_stats *st, const char *call, pn_result r, int d, const double *s,
                        double h) {
    if (!st->errors++)
        snprintf(st->first_error, sizeof st->first_error,
                 "%s -> %s (%d) at d=%d, F = R1 diag(%.17g, %.17g, %.17g) R2, h = %.17g", call,
                 pn_result_string(r), (int)r, d, s[0], s[1], d == 3 ? s[2] : 0.0, h);
}

static void pn_tr_max_into(double *acc, double v) {
    if (!(v <= *acc)) *acc = v; /* NaN sticks */
}

static void pn_tr_sample(const pn_tr_case *c, const pn_material *m, int d, pn_test_rng *rng,
                         pn_tr_stats *st) {
    const pn_material_desc *p = &c->desc;
    double R1[9], R2[9], e[3], s[3], F[9], h, mag, Fi[9], tmp[9], D[9];
    double z[3], tauZ[9], Tk[9], Tr[9], w[3], yF, scF, Z[9], T[9], hn;
    pn_real Fr[9], Zr[9], Tl[9], hnr, y, sc, tau_l[9], Fi_l[9];
    pn_tr_ref ref;
    int n = d * d, i, j;
    pn_result r;
    pn_tr_rotation(rng, d, R1);
    pn_tr_rotation(rng, d, R2);
    mag = pow(10.0, pn_test_rng_range(rng, c->mag_lo, c->mag_hi));
    for (i = 0; i < d; ++i) {
        e[i] = mag * pn_test_rng_range(rng, -1, 1);
        s[i] = exp(e[i]);
    }
    h = pn_test_rng_uniform(rng) < c->h_zero ? 0 : pn_test_rng_range(rng, c->h_lo, c->h_hi);
    t_adb(d, R1, s, R2, F);
    for (i = 0; i < n; ++i) Fr[i] = F[i];
    pn_tr_reference(p, d, e, h, &ref);
    st->n++;

    r = pn_yield_function(m, d, Fr, h, &y, &sc);
    if (r != PN_OK) { pn_tr_error(st, "pn_yield_function(F)", r, d, s, h); return; }
    yF = y;
    scF = sc;
    r = pn_return_map(m, d, Fr, h, Zr, &hnr, Tl);
    if (r != PN_OK) { pn_tr_error(st, "pn_return_map(F)", r, d, s, h); return; }
    for (i = 0; i < n; ++i) {
        Z[i] = Zr[i];
        T[i] = Tl[i];
    }
    hn = hnr;

    /* the yield function against the reference (Stomakhin: only the sign is specified) */
    if (p->plastic == PN_PLASTIC_SNOW_STOMAKHIN) {
        if (!ref.border && ((yF > 0) != (ref.y > 0))) pn_tr_max_into(&st->y_ref, 1);
    } else {
        pn_tr_max_into(&st->y_ref, fabs(yF - ref.y) / pn_tr_max(scF, pn_tr_yield_floor(p, d)));
    }

    /* Z in the test's frame: D = R1^T Z R2^T must be diagonal */
    t_mul_tn(d, R1, Z, tmp);
    t_mul_nt(d, tmp, R2, D);
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j)
            if (i != j) pn_tr_max_into(&st->coaxial, fabs(D[i * d + j]) / pn_tr_maxabs(n, Z));
    for (i = 0; i < d; ++i) z[i] = D[i * d + i];

    if (ref.border) {
        st->border++;
    } else {
        double zmax = 0, dz = 0;
        for (i = 0; i < d; ++i) {
            zmax = pn_tr_max(zmax, fabs(ref.z[i]));
            dz = pn_tr_max(dz, fabs(z[i] - ref.z[i]));
        }
        pn_tr_max_into(&st->z_ref, dz / zmax);
        if (ref.h_checked)
            pn_tr_max_into(&st->h_ref, pn_tr_h_err(hn, ref.hn, h));
        else
            st->h_unchecked++;
        switch (ref.kind) {
        case PN_TR_INSIDE: st->inside++; break;
        case PN_TR_FLOW: st->flow++; break;
        case PN_TR_TIP: st->tip++; break;
        default: st->tip_t++; break;
        }
        /* inside: Z = F and h unchanged (a pending DP volume credit is absorbed by design) */
        if (ref.kind == PN_TR_INSIDE && !(p->volume_correction && h != 0)) {
            pn_tr_max_into(&st->ident, pn_tr_reldiff(n, Z, F, 0));
            if (hn != h) st->ident_h_bad++;
        }
        if (ref.kind == PN_TR_FLOW) {
            /* on the yield surface; Cam-Clay projects onto the surface of the old state */
            pn_real yz, scz;
            r = pn_yield_function(m, d, Zr, p->plastic == PN_PLASTIC_CAM_CLAY ? h : hn, &yz, &scz);
            if (r != PN_OK) pn_tr_error(st, "pn_yield_function(Z)", r, d, s, h);
            else pn_tr_max_into(&st->resid, fabs(yz) / pn_tr_max(scz, pn_tr_yield_floor(p, d)));
            /* isochoric flow; a DP volume correction adds its stored log-volume h by design */
            if (p->plastic != PN_PLASTIC_SNOW_STOMAKHIN)
                pn_tr_max_into(&st->volume, fabs(t_det(d, Z) / t_det(d, F) /
                                                     exp(p->volume_correction ? h : 0) - 1));
        }
        if (ref.kind == PN_TR_TIP || ref.kind == PN_TR_TIP_TENSION) {
            if (p->plastic == PN_PLASTIC_DRUCKER_PRAGER) {
                /* apex: Z = exp(c) R1 R2 (singular values exp(c)); stress free without cohesion */
                double RR[9], cz[3];
                for (i = 0; i < d; ++i) cz[i] = exp(p->cohesion_strain);
                t_adb(d, R1, cz, R2, RR);
                pn_tr_max_into(&st->resid_tip, pn_tr_reldiff(n, Z, RR, 0));
                if (p->cohesion_strain == 0)
                    pn_tr_max_into(&st->resid_tip, pn_tr_maxabs(n, T) / p->youngs_modulus_pa);
            } else { /* Cam-Clay: p(Z) = -kappa/2 (det Z^2 - 1) equals p0 or -beta p0 */
                pn_tr_lame l = pn_tr_lame_of(p, d);
                double Jz = t_det(d, Z), pz = -l.kappa / 2 * (Jz * Jz - 1);
                double p0 = l.kappa * (1e-5 + sinh(p->camclay_xi * pn_tr_max(-h, 0)));
                pn_tr_max_into(&st->resid_tip, fabs(pz - ref.p_tip) / (p0 * pn_tr_max(1, p->camclay_beta)));
                /* compaction hardens (log Jp falls), tension softens */
                if (!p->camclay_no_hardening &&
                    (ref.kind == PN_TR_TIP ? !(hn < h) : !(hn > h)))
                    st->tip_h_wrong_sign++;
            }
        }
        if (p->plastic == PN_PLASTIC_VON_MISES) {
            /* hardening is monotone; the new surface is sigma_Y0 + K h_new; a grows by
               sqrt(2/3) |dH|; dH points against the trial deviatoric log strain */
            double tz[3], dt[3], dH[3], eh[3], rn = pn_tr_dev(d, e, eh), ndH = 0, dir = 0;
            if (hn < h) st->vm_h_decreased++;
            if (ref.kind == PN_TR_FLOW) {
                pn_tr_tau_principal(p, d, z, hn, tz);
                pn_tr_max_into(&st->vm_yield,
                               fabs(sqrt(1.5) * pn_tr_dev(d, tz, dt) /
                                        (p->yield_stress_pa + p->hardening_modulus_pa * hn) - 1));
                for (i = 0; i < d; ++i) {
                    dH[i] = log(z[i]) - e[i];
                    ndH += dH[i] * dH[i];
                }
                ndH = sqrt(ndH);
                pn_tr_max_into(&st->vm_da, fabs((hn - h) - sqrt(2.0 / 3) * ndH) / (sqrt(2.0 / 3) * ndH));
                for (i = 0; i < d; ++i) dir = pn_tr_max(dir, fabs(dH[i] + ndH * eh[i] / rn));
                pn_tr_max_into(&st->vm_dir, dir / ndH);
            }
        }
        if (p->plastic == PN_PLASTIC_SNOW_STOMAKHIN) {
            /* stretches inside [1 - theta_c, 1 + theta_s]; log Jp += log(det F / det Z) */
            double bad = 0;
            for (i = 0; i < d; ++i) {
                bad = pn_tr_max(bad, z[i] - (1 + p->snow_theta_s));
                bad = pn_tr_max(bad, (1 - p->snow_theta_c) - z[i]);
            }
            pn_tr_max_into(&st->snow_box, bad);
            pn_tr_max_into(&st->h_ref, pn_tr_h_err(hn, h + log(t_det(d, F) / t_det(d, Z)), h));
        }
    }

    /* T = tau(Z) F^-T, through the library's own stress and inverse ... */
    r = pn_kirchhoff_stress(m, d, Zr, hnr, tau_l);
    if (r == PN_OK) r = pn_mat_inverse(d, Fr, Fi_l);
    if (r != PN_OK) {
        pn_tr_error(st, "pn_kirchhoff_stress(Z) / pn_mat_inverse(F)", r, d, s, h);
    } else {
        for (i = 0; i < n; ++i) {
            tauZ[i] = tau_l[i];
            Fi[i] = Fi_l[i];
        }
        t_mul_nt(d, tauZ, Fi, Tk);
        pn_tr_max_into(&st->T_kirch, pn_tr_reldiff(n, T, Tk, PN_TR_STRAIN_FLOOR * p->youngs_modulus_pa));
    }
    /* ... and through the test's principal stresses: T = R1 diag(tau_i(z) / s_i) R2 */
    pn_tr_tau_principal(p, d, z, hn, w);
    for (i = 0; i < d; ++i) w[i] /= s[i];
    t_adb(d, R1, w, R2, Tr);
    pn_tr_max_into(&st->T_ref, pn_tr_reldiff(n, T, Tr, PN_TR_STRAIN_FLOOR * p->youngs_modulus_pa));

    /* idempotence: project the result again with the new state. Cam-Clay softens in tension
       (log Jp grows, the surface shrinks), so with the new state it is idempotent only when
       the state hardened; with the old state it must always be. */
    {
        pn_real Z2[9], h2;
        double Z2d[9];
        int soft = p->plastic == PN_PLASTIC_CAM_CLAY && hn > h;
        if (soft) st->softened++;
        if (!soft) {
            r = pn_return_map(m, d, Zr, hnr, Z2, &h2, NULL);
            if (r != PN_OK) pn_tr_error(st, "pn_return_map(Z, h_new)", r, d, s, h);
            else {
                for (i = 0; i < n; ++i) Z2d[i] = Z2[i];
                pn_tr_max_into(&st->idem, pn_tr_reldiff(n, Z2d, Z, 0));
                pn_tr_max_into(&st->idem, pn_tr_h_err(h2, hn, h));
            }
        }
        if (p->plastic == PN_PLASTIC_CAM_CLAY) {
            r = pn_return_map(m, d, Zr, h, Z2, &h2, NULL);
            if (r != PN_OK) pn_tr_error(st, "pn_return_map(Z, h)", r, d, s, h);
            else {
                for (i = 0; i < n; ++i) Z2d[i] = Z2[i];
                pn_tr_max_into(&st->idem_old, pn_tr_reldiff(n, Z2d, Z, 0));
            }
        }
    }

    /* rotation equivariance: Z(Q F R) = Q Z(F) R, T(Q F R) = Q T(F) R, same h_new */
    {
        double Q[9], Rr[9], QF[9], QFR[9], QZ[9], QZR[9], QT[9], QTR[9], Zq[9], Tq[9];
        pn_real Fq[9], Zqr[9], Tqr[9], hq;
        pn_tr_rotation(rng, d, Q);
        pn_tr_rotation(rng, d, Rr);
        t_mul(d, Q, F, QF);
        t_mul(d, QF, Rr, QFR);
        for (i = 0; i < n; ++i) Fq[i] = QFR[i];
        r = pn_return_map(m, d, Fq, h, Zqr, &hq, Tqr);
        if (r != PN_OK) {
            pn_tr_error(st, "pn_return_map(Q F R)", r, d, s, h);
        } else {
            for (i = 0; i < n; ++i) {
                Zq[i] = Zqr[i];
                Tq[i] = Tqr[i];
            }
            t_mul(d, Q, Z, QZ);
            t_mul(d, QZ, Rr, QZR);
            t_mul(d, Q, T, QT);
            t_mul(d, QT, Rr, QTR);
            if (!ref.border) {
                pn_tr_max_into(&st->equiv, pn_tr_reldiff(n, Zq, QZR, 0));
                pn_tr_max_into(&st->equiv, pn_tr_reldiff(n, Tq, QTR, PN_TR_STRAIN_FLOOR * p->youngs_modulus_pa));
                pn_tr_max_into(&st->equiv, pn_tr_h_err(hq, hn, h));
            }
        }
    }
}

/* Run a material over both dimensions and check every figure. */
static void pn_tr_run_case(pn_test_ctx *pn__t, const pn_tr_case *c, unsigned long long seed) {
    pn_material m;
    pn_tr_stats st;
    pn_test_rng rng;
    char why[256] = "";
    int d, k, plastic_cases;
    pn_result r = pn_material_init(&m, &c->desc, why, sizeof why);
    PN_CHECK(r == PN_OK);
    if (r != PN_OK) return;
    memset(&st, 0, sizeof st);
    rng.s = seed;
    for (d = 2; d <= 3; ++d)
        for (k = 0; k < PN_TR_SAMPLES; ++k) pn_tr_sample(c, &m, d, &rng, &st);
    plastic_cases = st.flow + st.tip + st.tip_t;
    PN_REPORT("%s: %d samples: %d inside, %d flow, %d tip, %d tension tip, %d border, "
              "%d errors", c->name, st.n, st.inside, st.flow, st.tip, st.tip_t, st.border,
              st.errors);
    PN_REPORT("%s: worst: Z vs ref %.2e, h vs ref %.2e, yield fn vs ref %.2e, inside |Z-F| "
              "%.2e, residual %.2e, tip %.2e, volume %.2e, coaxial %.2e", c->name, st.z_ref,
              st.h_ref, st.y_ref, st.ident, st.resid, st.resid_tip, st.volume, st.coaxial);
    PN_REPORT("%s: worst: T vs kirchhoff %.2e, T vs ref %.2e, idempotence %.2e (old state "
              "%.2e, %d softened), equivariance %.2e", c->name, st.T_kirch, st.T_ref, st.idem,
              st.idem_old, st.softened, st.equiv);
    if (st.errors) PN_REPORT("%s: first failing call: %s", c->name, st.first_error);
    PN_CHECK(st.errors == 0);
    PN_CHECK(c->no_interior ? st.inside == 0 : st.inside >= st.n / 20); /* both regimes */
    PN_CHECK(plastic_cases >= st.n / 20);
    PN_CHECK_LE(st.y_ref, 1e-9);
    PN_CHECK_LE(st.z_ref, 1e-10);
    PN_CHECK_LE(st.h_ref, 1e-9);
    PN_CHECK_LE(st.ident, 1e-13);
    PN_CHECK(st.ident_h_bad == 0);
    PN_CHECK_LE(st.resid, 1e-9);
    PN_CHECK_LE(st.resid_tip, 1e-9);
    PN_CHECK_LE(st.volume, 1e-12);
    PN_CHECK_LE(st.coaxial, 1e-12);
    PN_CHECK_LE(st.T_kirch, 1e-10);
    PN_CHECK_LE(st.T_ref, 1e-10);
    PN_CHECK_LE(st.idem, 1e-10);
    PN_CHECK_LE(st.idem_old, 1e-10);
    PN_CHECK_LE(st.equiv, 1e-10);
    PN_CHECK(st.tip_h_wrong_sign == 0);
    PN_CHECK(st.h_unchecked <= st.n / 100);
    if (c->desc.plastic == PN_PLASTIC_VON_MISES) {
        PN_REPORT("%s: worst: yield stress sigma_Y0 + K h_new %.2e, da = sqrt(2/3)|dH| %.2e, "
                  "flow direction %.2e", c->name, st.vm_yield, st.vm_da, st.vm_dir);
        PN_CHECK(st.vm_h_decreased == 0);
        PN_CHECK_LE(st.vm_yield, 1e-9);
        PN_CHECK_LE(st.vm_da, 1e-9);
        PN_CHECK_LE(st.vm_dir, 1e-9);
    }
    if (c->desc.plastic == PN_PLASTIC_SNOW_STOMAKHIN) {
        PN_REPORT("%s: worst stretch outside [1-theta_c, 1+theta_s]: %.2e", c->name, st.snow_box);
        PN_CHECK_LE(st.snow_box, 4e-15); /* z read back from the matrix Z */
    }
    if (c->desc.plastic == PN_PLASTIC_DRUCKER_PRAGER) PN_CHECK(st.tip >= st.n / 20);
    if (c->desc.plastic == PN_PLASTIC_CAM_CLAY) PN_CHECK(st.flow >= st.n / 50);
}

/* ---- the tests --------------------------------------------------------------------------- */

PN_TEST(return_drucker_prager) {
    pn_tr_case c;
    pn_tr_dp(&c, "dp phi=30", 30, 0, 0);
    pn_tr_run_case(pn__t, &c, 101);
    pn_tr_dp(&c, "dp phi=0", 0, 0, 0); /* alpha = 0: a cone of radius 0, every point flows */
    c.no_interior = 1;
    pn_tr_run_case(pn__t, &c, 102);
}

PN_TEST(return_drucker_prager_cohesion) {
    pn_tr_case c;
    pn_tr_dp(&c, "dp phi=35 cohesion=0.01", 35, 0.01, 0);
    pn_tr_run_case(pn__t, &c, 103);
}

PN_TEST(return_drucker_prager_volume_correction) {
    pn_tr_case c;
    pn_tr_dp(&c, "dp phi=30 volume correction", 30, 0, 1);
    pn_tr_run_case(pn__t, &c, 104);
    pn_tr_dp(&c, "dp phi=25 cohesion=0.02 volume correction", 25, 0.02, 1);
    pn_tr_run_case(pn__t, &c, 105);
}

PN_TEST(return_von_mises_stvk_hencky) {
    pn_tr_case c;
    pn_tr_vm(&c, "vm hencky K=2e9", PN_ELASTIC_STVK_HENCKY, 2e9);
    pn_tr_run_case(pn__t, &c, 201);
    pn_tr_vm(&c, "vm hencky K=0", PN_ELASTIC_DEFAULT, 0);
    pn_tr_run_case(pn__t, &c, 202);
}

PN_TEST(return_von_mises_neo_hookean) {
    pn_tr_case c;
    pn_tr_vm(&c, "vm neo-hookean K=2e9", PN_ELASTIC_NEO_HOOKEAN, 2e9);
    pn_tr_run_case(pn__t, &c, 301);
    pn_tr_vm(&c, "vm neo-hookean K=0", PN_ELASTIC_NEO_HOOKEAN, 0);
    pn_tr_run_case(pn__t, &c, 302);
}

/* Neo-Hookean von Mises with a yield stress far below mu (sigma_Y0 / E down to 1e-3, the range
   of the conditioned metal models): the root find must stop at the rounding of its own
   residual, whose terms are of size mu, not of size sigma_Y. The first F is one it once did
   not converge on (nu 0.4, 1e-3 E, K 0, h 0.7); then random near-rotations with log stretches
   from 1e-4 to 0.1 at the corners of the ranges. Every call succeeds and, where it flows,
   |dev tau(Z)| = sqrt(2/3) (sigma_Y0 + K h_new) to 1e-10 of it. */
PN_TEST(return_von_mises_small_yield) {
    static const double nus[2] = {0.2, 0.4}, ys[2] = {1e-3, 1e-2}, ks[2] = {0, 0.05};
    const double F1[4] = {-0.099748060892002666, -0.99389819270239921, 0.99656816310224705, -0.10683792589787294};
    long calls = 0, fails = 0, plastic = 0;
    double worst = 0;
    pn_test_rng rng;
    int dim, a, b, c, i, k;
    rng.s = 4242;
    for (dim = 2; dim <= 3; ++dim)
        for (a = 0; a < 2; ++a)
            for (b = 0; b < 2; ++b)
                for (c = 0; c < 2; ++c) {
                    pn_material_desc d;
                    pn_material m;
                    memset(&d, 0, sizeof d);
                    d.elastic = PN_ELASTIC_NEO_HOOKEAN, d.plastic = PN_PLASTIC_VON_MISES, d.youngs_modulus_pa = 1;
                    d.poisson_ratio = nus[a], d.yield_stress_pa = ys[b], d.hardening_modulus_pa = ks[c];
                    if (pn_material_init(&m, &d, NULL, 0) != PN_OK) {
                        PN_CHECK(!"pn_material_init");
                        continue;
                    }
                    for (i = 0; i < 1500; ++i) {
                        double F[9], R1[9], R2[9], e[3], sv[3], Z[9], hn, h = pn_test_rng_range(&rng, 0, 1), mag;
                        pn_real tau[9];
                        double tr = 0, dev = 0;
                        if (i == 0 && dim == 2) {
                            memcpy(F, F1, sizeof F1);
                            h = 0.70002116677622517;
                        } else {
                            t_rand_rot(&rng, dim, R1);
                            t_rand_rot(&rng, dim, R2);
                            mag = pow(10.0, pn_test_rng_range(&rng, -4, -1));
                            for (k = 0; k < dim; ++k) e[k] = mag * pn_test_rng_range(&rng, -1, 1), sv[k] = exp(e[k]);
                            t_adb(dim, R1, sv, R2, F);
                        }
                        ++calls;
                        if (pn_return_map(&m, dim, F, h, Z, &hn, NULL) != PN_OK ||
                            pn_kirchhoff_stress(&m, dim, Z, hn, tau) != PN_OK) {
                            ++fails;
                            continue;
                        }
                        if (hn == h) continue; /* inside: Z = F */
                        ++plastic;
                        for (k = 0; k < dim; ++k) tr += tau[k * dim + k] / dim;
                        for (k = 0; k < dim * dim; ++k) {
                            double v = tau[k] - (k % (dim + 1) == 0 ? tr : 0);
                            dev += v * v;
                        }
                        {
                            double ty = sqrt(2.0 / 3.0) * (ys[b] + ks[c] * hn);
                            worst = fmax(worst, fabs(sqrt(dev) - ty) / ty);
                        }
                    }
                }
    PN_REPORT("%ld calls (2D, 3D; nu 0.2, 0.4; sigma_Y0 1e-3, 1e-2 E; K 0, 0.05 E), %ld plastic: |dev tau| against "
              "sqrt(2/3) sigma_Y %.2e; failed %ld", calls, plastic, worst, fails);
    PN_CHECK(fails == 0);
    PN_CHECK(plastic > calls / 10);
    PN_CHECK_LE(worst, 1e-10);
}

PN_TEST(return_cam_clay) {
    pn_tr_case c;
    pn_tr_cc(&c, "cam-clay phi=35 beta=0.3 xi=0.5", 35, 0.3, 0.5, 0);
    pn_tr_run_case(pn__t, &c, 401);
    pn_tr_cc(&c, "cam-clay phi=30 beta=0.3 xi=10", 30, 0.3, 10, 0);
    c.h_lo = -0.2; /* p0 = kappa sinh(10 * 0.5) = 74 kappa would leave almost no shear cases */
    pn_tr_run_case(pn__t, &c, 402);
    pn_tr_cc(&c, "cam-clay phi=40 beta=0.5 xi=3 no hardening", 40, 0.5, 3, 1);
    pn_tr_run_case(pn__t, &c, 403);
}

/* A 3D shear-case trial point far outside the surface (found by the random test above):
   the projection keeps J and the direction of dev b, so it must succeed, land on the surface
   of the old state and keep det F. */
PN_TEST(return_cam_clay_large_shear_3d) {
    pn_tr_case c;
    pn_material m;
    pn_real F[9], Z[9], hn = 0, y = 1, sc = 1;
    double s[3], h = -0.13280955232689262, e[3], Zd[9];
    pn_tr_ref ref;
    pn_result r;
    int i;
    s[0] = 1.8022507796734351;
    s[1] = 0.39203361551350102;
    s[2] = 0.4258398603552494;
    pn_tr_cc(&c, "cam-clay phi=30 beta=0.3 xi=10", 30, 0.3, 10, 0);
    PN_CHECK(pn_material_init(&m, &c.desc, NULL, 0) == PN_OK);
    for (i = 0; i < 9; ++i) F[i] = 0;
    for (i = 0; i < 3; ++i) {
        F[i * 4] = s[i];
        e[i] = log(s[i]);
    }
    pn_tr_reference(&c.desc, 3, e, h, &ref);
    PN_CHECK(ref.kind == PN_TR_FLOW); /* the shear case, not a tip */
    r = pn_return_map(&m, 3, F, h, Z, &hn, NULL);
    PN_REPORT("pn_return_map(diag(%.17g, %.17g, %.17g), h = %.17g) -> %s", s[0], s[1], s[2], h,
              pn_result_string(r));
    PN_CHECK(r == PN_OK);
    if (r != PN_OK) return;
    for (i = 0; i < 9; ++i) Zd[i] = Z[i];
    PN_CHECK(pn_yield_function(&m, 3, Z, h, &y, &sc) == PN_OK);
    PN_CHECK_LE(fabs(y) / sc, 1e-9);
    PN_CHECK_LE(fabs(t_det(3, Zd) / (s[0] * s[1] * s[2]) - 1), 1e-12);
    for (i = 0; i < 3; ++i) PN_CHECK_NEAR(Zd[i * 4], ref.z[i], 1e-10);
}

PN_TEST(return_snow_stomakhin) {
    pn_tr_case c;
    pn_tr_snow(&c, "stomakhin snow");
    pn_tr_run_case(pn__t, &c, 501);
}

/* The exact StVK-Hencky + von Mises energy (the return mapping's incremental potential from
   state h): its gradient is T of pn_return_map at (F, h), hardening included (half the
   samples), and for a K = 0 material with sigma_Y0' = sigma_Y0 + K h (the other half) that of
   the perfectly plastic return. Also its value against docs/method.md and a central
   difference of it. */
PN_TEST(return_von_mises_energy_gradient) {
    pn_material_desc dk, d0;
    pn_material mk, m0;
    pn_test_rng rng;
    double worst_grad = 0, worst_psi = 0, worst_fd = 0;
    int d, k, errors = 0, plastic = 0, n_samples = 0;
    memset(&dk, 0, sizeof dk);
    dk.plastic = PN_PLASTIC_VON_MISES;
    dk.youngs_modulus_pa = 200e9;
    dk.poisson_ratio = 0.3;
    dk.yield_stress_pa = 250e6;
    dk.hardening_modulus_pa = 2e9;
    PN_CHECK(pn_material_init(&mk, &dk, NULL, 0) == PN_OK);
    rng.s = 601;
    for (d = 2; d <= 3; ++d)
        for (k = 0; k < 1500; ++k) {
            double R1[9], R2[9], e[3], s[3], F[9], h, eh[3], rn, tr = 0, psi_ref, dF[9], Fp[9], Fm[9];
            double Pd[9], Td[9], tauy, kappa, mu, la, fd, dir = 0;
            pn_real Fr[9], P[9], T[9], psi, pp, pm, Fpr[9], Fmr[9];
            int i, n = d * d, use_k = k % 2;
            pn_tr_rotation(&rng, d, R1);
            pn_tr_rotation(&rng, d, R2);
            for (i = 0; i < d; ++i) {
                e[i] = pow(10.0, pn_test_rng_range(&rng, -4.5, 0)) * pn_test_rng_range(&rng, -1, 1);
                s[i] = exp(e[i]);
                tr += e[i];
            }
            h = k % 3 ? pn_test_rng_range(&rng, 0, 0.1) : 0;
            t_adb(d, R1, s, R2, F);
            for (i = 0; i < n; ++i) Fr[i] = F[i];
            /* K = 0 material with the frozen yield stress of (mk, h) */
            d0 = dk;
            d0.hardening_modulus_pa = 0;
            d0.yield_stress_pa = dk.yield_stress_pa + dk.hardening_modulus_pa * h;
            if (pn_material_init(&m0, &d0, NULL, 0) != PN_OK) { errors++; continue; }
            if (pn_von_mises_energy(use_k ? &mk : &m0, d, Fr, use_k ? h : 0, &psi, P, NULL, 0) != PN_OK ||
                pn_return_map(use_k ? &mk : &m0, d, Fr, use_k ? h : 0, NULL, NULL, T) != PN_OK) {
                errors++;
                continue;
            }
            n_samples++;
            for (i = 0; i < n; ++i) {
                Pd[i] = P[i];
                Td[i] = T[i];
            }
            pn_tr_max_into(&worst_grad, pn_tr_reldiff(n, Pd, Td, PN_TR_STRAIN_FLOOR * dk.youngs_modulus_pa));
            /* docs/method.md: kappa/2 tr^2 + mu |e^|^2 inside, kappa/2 tr^2 + mu (|e^| - g)^2 + tau_Y g +
               beta/2 g^2 outside, g = (2 mu |e^| - tau_Y) / (2 mu + beta), beta = 2K/3 */
            mu = dk.youngs_modulus_pa / (2 * (1 + dk.poisson_ratio));
            la = dk.youngs_modulus_pa * dk.poisson_ratio / ((1 + dk.poisson_ratio) * (1 - 2 * dk.poisson_ratio));
            kappa = la + 2 * mu / d;
            tauy = sqrt(2.0 / 3) * d0.yield_stress_pa;
            rn = pn_tr_dev(d, e, eh);
            if (2 * mu * rn <= tauy) psi_ref = kappa / 2 * tr * tr + mu * rn * rn;
            else {
                double beta = use_k ? 2 * dk.hardening_modulus_pa / 3 : 0, g = (2 * mu * rn - tauy) / (2 * mu + beta);
                psi_ref = kappa / 2 * tr * tr + mu * (rn - g) * (rn - g) + tauy * g + beta / 2 * g * g;
                plastic++;
            }
            /* floor: the energy at the floor strain (psi carries e to ~1e-16 absolute) */
            pn_tr_max_into(&worst_psi, fabs(psi - psi_ref) /
                                           pn_tr_max(fabs(psi_ref), PN_TR_STRAIN_FLOOR * PN_TR_STRAIN_FLOOR * dk.youngs_modulus_pa));
            /* central difference along a random direction; the step is small because the
               energy is only C1 at the yield surface (an O(step) error when straddling it) */
            for (i = 0; i < n; ++i) dF[i] = pn_test_rng_range(&rng, -1, 1);
            for (i = 0; i < n; ++i) {
                Fp[i] = F[i] + 1e-7 * dF[i];
                Fm[i] = F[i] - 1e-7 * dF[i];
                Fpr[i] = Fp[i];
                Fmr[i] = Fm[i];
                dir += Td[i] * dF[i];
            }
            if (pn_von_mises_energy(use_k ? &mk : &m0, d, Fpr, use_k ? h : 0, &pp, NULL, NULL, 0) != PN_OK ||
                pn_von_mises_energy(use_k ? &mk : &m0, d, Fmr, use_k ? h : 0, &pm, NULL, NULL, 0) != PN_OK) {
                errors++;
                continue;
            }
            fd = (pp - pm) / 2e-7;
            pn_tr_max_into(&worst_fd, fabs(fd - dir) / (pn_tr_maxabs(n, Td) * pn_tr_maxabs(n, dF) +
                                                        PN_TR_STRAIN_FLOOR * dk.youngs_modulus_pa));
        }
    PN_REPORT("%d samples (%d plastic): worst |P_energy - T| / |T| = %.2e, psi vs docs/method.md "
              "%.2e, central difference %.2e", n_samples, plastic, worst_grad, worst_psi, worst_fd);
    PN_CHECK(errors == 0);
    PN_CHECK(plastic >= n_samples / 10 && plastic <= n_samples * 9 / 10);
    PN_CHECK_LE(worst_grad, 1e-8);
    PN_CHECK_LE(worst_psi, 1e-10);
    PN_CHECK_LE(worst_fd, 1e-5);
}

/* ---- bad input ------------------------------------------------------------------------- */

static int pn_tr_init_case(pn_tr_case *cases) {
    int n = 0;
    pn_tr_dp(&cases[n++], "dp", 30, 0.01, 1);
    pn_tr_vm(&cases[n++], "vm hencky", PN_ELASTIC_STVK_HENCKY, 2e9);
    pn_tr_vm(&cases[n++], "vm neo-hookean", PN_ELASTIC_NEO_HOOKEAN, 2e9);
    pn_tr_cc(&cases[n++], "cam-clay", 35, 0.3, 3, 0);
    pn_tr_snow(&cases[n++], "stomakhin");
    return n;
}

/* sentinel-filled outputs; 1 if any changed */
static int pn_tr_touched(const pn_real *Z, pn_real h, const pn_real *T) {
    int i;
    for (i = 0; i < 9; ++i)
        if (Z[i] != (pn_real)-7.25 || T[i] != (pn_real)-7.25) return 1;
    return h != (pn_real)-7.25;
}

static void pn_tr_sentinel(pn_real *Z, pn_real *h, pn_real *T) {
    int i;
    for (i = 0; i < 9; ++i) Z[i] = T[i] = (pn_real)-7.25;
    *h = (pn_real)-7.25;
}

PN_TEST(return_bad_input_nonfinite) {
    pn_tr_case cases[8];
    int nc = pn_tr_init_case(cases), c, d, i, k, wrong = 0, touched = 0, calls = 0;
    double bad[3];
    bad[0] = HUGE_VAL;
    bad[1] = -HUGE_VAL;
    bad[2] = HUGE_VAL - HUGE_VAL; /* NaN without relying on the NAN macro */
    for (c = 0; c < nc; ++c) {
        pn_material m;
        PN_CHECK(pn_material_init(&m, &cases[c].desc, NULL, 0) == PN_OK);
        for (d = 2; d <= 3; ++d)
            for (i = 0; i <= d * d; ++i)      /* i == d*d: the state h is the bad value */
                for (k = 0; k < 3; ++k) {
                    pn_real F[9], Z[9], T[9], hn, y = (pn_real)-7.25, h = 0;
                    int j;
                    for (j = 0; j < 9; ++j) F[j] = (pn_real)(j % (d + 1) == 0 ? 1.01 : 0.02);
                    if (i < d * d) F[i] = (pn_real)bad[k];
                    else h = (pn_real)bad[k];
                    pn_tr_sentinel(Z, &hn, T);
                    calls += 2;
                    if (pn_return_map(&m, d, F, h, Z, &hn, T) != PN_ERROR_NONFINITE) wrong++;
                    if (pn_tr_touched(Z, hn, T)) touched++;
                    if (pn_yield_function(&m, d, F, h, &y, NULL) != PN_ERROR_NONFINITE) wrong++;
                    if (y != (pn_real)-7.25) touched++;
                }
    }
    PN_REPORT("%d calls with NaN/inf in F or h: %d wrong codes, %d touched outputs", calls, wrong,
              touched);
    PN_CHECK(wrong == 0);
    PN_CHECK(touched == 0);
}

/* One bad parameter: init must fail with `want`, name it, and leave m untouched. */
static void pn_tr_expect_init_fail(pn_test_ctx *pn__t, const pn_material_desc *desc,
                                   pn_result want, const char *what) {
    pn_material m, copy;
    char why[256] = "";
    pn_result r;
    memset(&m, 0xA5, sizeof m);
    memcpy(&copy, &m, sizeof m);
    r = pn_material_init(&m, desc, why, sizeof why);
    if (r != want || !why[0] || memcmp(&m, &copy, sizeof m) != 0) {
        char msg[512];
        snprintf(msg, sizeof msg, "%s: got %d (want %d), why %s, material %s", what, (int)r,
                 (int)want, why,
                 memcmp(&m, &copy, sizeof m) ? "modified" : "untouched");
        pn_test__fail(pn__t, __FILE__, __LINE__, msg);
    }
    /* a NULL why must be accepted too */
    if (pn_material_init(&m, desc, NULL, 0) != want)
        pn_test__fail(pn__t, __FILE__, __LINE__, "different result with why == NULL");
}

PN_TEST(return_bad_parameters) {
    pn_tr_case cases[8];
    int nc = pn_tr_init_case(cases), c;
    for (c = 0; c < nc; ++c) {
        pn_material_desc d = cases[c].desc;
        double bad_E[3], bad_nu[5];
        int i;
        bad_E[0] = 0; bad_E[1] = -1e7; bad_E[2] = HUGE_VAL - HUGE_VAL;
        bad_nu[0] = 0.5; bad_nu[1] = 0.7; bad_nu[2] = -1; bad_nu[3] = -1.5;
        bad_nu[4] = HUGE_VAL - HUGE_VAL;
        for (i = 0; i < 3; ++i) {
            d = cases[c].desc;
            d.youngs_modulus_pa = bad_E[i];
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "bad E");
        }
        for (i = 0; i < 5; ++i) {
            d = cases[c].desc;
            d.poisson_ratio = bad_nu[i];
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "bad nu");
        }
        d = cases[c].desc;
        if (d.plastic == PN_PLASTIC_DRUCKER_PRAGER || d.plastic == PN_PLASTIC_CAM_CLAY) {
            d.friction_angle_deg = -5;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "negative friction");
            d.friction_angle_deg = 90;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "friction 90");
        }
        d = cases[c].desc;
        if (d.plastic == PN_PLASTIC_VON_MISES) {
            d.yield_stress_pa = 0;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "yield stress 0");
            d.yield_stress_pa = -250e6;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "negative yield stress");
            d = cases[c].desc;
            d.hardening_modulus_pa = -1;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "negative hardening");
        }
        d = cases[c].desc;
        if (d.plastic == PN_PLASTIC_DRUCKER_PRAGER) {
            d.cohesion_strain = -0.01;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "negative cohesion");
        }
        d = cases[c].desc;
        if (d.plastic == PN_PLASTIC_SNOW_STOMAKHIN) {
            d.snow_theta_c = 1;
            pn_tr_expect_init_fail(pn__t, &d, PN_ERROR_INVALID_PARAMETER, "theta_c = 1");
        }
    }
}

PN_TEST(return_unsupported_combinations) {
    pn_tr_case c;
    pn_tr_cc(&c, "cam-clay stvk", 35, 0.3, 3, 0);
    c.desc.elastic = PN_ELASTIC_STVK_HENCKY;
    pn_tr_expect_init_fail(pn__t, &c.desc, PN_ERROR_UNSUPPORTED, "cam-clay + stvk_hencky");
    pn_tr_dp(&c, "dp neo-hookean", 30, 0, 0);
    c.desc.elastic = PN_ELASTIC_NEO_HOOKEAN;
    pn_tr_expect_init_fail(pn__t, &c.desc, PN_ERROR_UNSUPPORTED, "drucker-prager + neo_hookean");
}

/* det F <= 0 with a Hencky or Neo-Hookean model: PN_ERROR_INVERTED, outputs untouched. */
PN_TEST(return_inverted) {
    pn_tr_case cases[8];
    pn_test_rng rng;
    int nc = pn_tr_init_case(cases), c, d, k, wrong = 0, touched = 0, calls = 0;
    rng.s = 701;
    for (c = 0; c < nc; ++c) {
        pn_material m;
        if (cases[c].desc.plastic == PN_PLASTIC_SNOW_STOMAKHIN) continue; /* fixed corotated */
        PN_CHECK(pn_material_init(&m, &cases[c].desc, NULL, 0) == PN_OK);
        for (d = 2; d <= 3; ++d)
            for (k = 0; k < 40; ++k) {
                double R1[9], R2[9], s[3], F[9];
                pn_real Fr[9], Z[9], T[9], hn, y = (pn_real)-7.25;
                int i;
                pn_tr_rotation(&rng, d, R1);
                pn_tr_rotation(&rng, d, R2);
                for (i = 0; i < d; ++i) s[i] = exp(pn_test_rng_range(&rng, -0.5, 0.5));
                s[k % d] = k % 4 == 0 ? 0 : -s[k % d]; /* singular or reflected */
                t_adb(d, R1, s, R2, F);
                for (i = 0; i < d * d; ++i) Fr[i] = F[i];
                if (k % 4 == 0) /* exactly singular: repeat a row */
                    for (i = 0; i < d; ++i) Fr[d + i] = Fr[i];
                pn_tr_sentinel(Z, &hn, T);
                calls += 2;
                if (pn_return_map(&m, d, Fr, 0, Z, &hn, T) != PN_ERROR_INVERTED) wrong++;
                if (pn_tr_touched(Z, hn, T)) touched++;
                if (pn_yield_function(&m, d, Fr, 0, &y, NULL) != PN_ERROR_INVERTED) wrong++;
                if (y != (pn_real)-7.25) touched++;
            }
    }
    PN_REPORT("%d calls with det F <= 0: %d wrong codes, %d touched outputs", calls, wrong, touched);
    PN_CHECK(wrong == 0);
    PN_CHECK(touched == 0);
}

/* von Mises state is an accumulated plastic strain: h < 0 is out of its domain. */
PN_TEST(return_von_mises_negative_state) {
    pn_tr_case c;
    pn_material m;
    pn_real F[9], Z[9], T[9], hn;
    int i;
    pn_tr_vm(&c, "vm", PN_ELASTIC_STVK_HENCKY, 2e9);
    PN_CHECK(pn_material_init(&m, &c.desc, NULL, 0) == PN_OK);
    for (i = 0; i < 9; ++i) F[i] = (pn_real)(i % 4 == 0 ? 1.1 : 0);
    pn_tr_sentinel(Z, &hn, T);
    PN_CHECK(pn_return_map(&m, 3, F, -0.01, Z, &hn, T) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(!pn_tr_touched(Z, hn, T));
}

/* Stability at the extremes: every public evaluator over random materials (any elastic and
   plastic model, E from 1e3 to 1e12 Pa, the whole parameter ranges) and random F with
   log-stretches up to +-15, some inverted, random states. Each call must either succeed with
   finite outputs, or return an error code with every output untouched; a finite input must
   never be reported as PN_ERROR_NONFINITE (an overflow is PN_ERROR_OVERFLOW). */
static int t_ex_untouched(int n, const pn_real *a) {
    int i;
    for (i = 0; i < n; ++i)
        if (a[i] != 7) return 0;
    return 1;
}
PN_TEST(return_extremes_fuzz) {
    pn_test_rng rng;
    long calls = 0, ok = 0, bad = 0, codes[PN_RESULT_COUNT];
    int t, i;
    rng.s = 991;
    for (i = 0; i < (int)PN_RESULT_COUNT; ++i) codes[i] = 0;
    for (t = 0; t < 60000; ++t) {
        int d = 2 + (t & 1), n = d * d;
        pn_material_desc ds;
        pn_material m;
        double R1[9], R2[9], s[3], Fd[9], range = t % 3 == 0 ? 15 : t % 3 == 1 ? 3 : 0.5;
        pn_real F[9], F2[9], Z[9], T[9], P[9], H[81], G[9], psi = 7, hn = 7, hG = 7, y = 7, sc = 7, h;
        pn_result r[6];
        int k;
        memset(&ds, 0, sizeof ds);
        ds.plastic = (pn_plastic_model)(pn_test_rng_u64(&rng) % PN_PLASTIC_MODEL_COUNT);
        ds.elastic = (pn_elastic_model)(pn_test_rng_u64(&rng) % PN_ELASTIC_MODEL_COUNT);
        ds.youngs_modulus_pa = pow(10, pn_test_rng_range(&rng, 3, 12));
        ds.poisson_ratio = pn_test_rng_range(&rng, -0.49, 0.49);
        ds.friction_angle_deg = pn_test_rng_range(&rng, 1, 89);
        ds.cohesion_strain = pn_test_rng_range(&rng, 0, 0.1);
        ds.volume_correction = (int)(pn_test_rng_u64(&rng) & 1);
        ds.yield_stress_pa = ds.youngs_modulus_pa * pow(10, pn_test_rng_range(&rng, -7, -1));
        ds.hardening_modulus_pa = ds.youngs_modulus_pa * pn_test_rng_range(&rng, 0, 0.2);
        ds.camclay_beta = pn_test_rng_range(&rng, 0, 2);
        ds.camclay_xi = pn_test_rng_range(&rng, 0, 20);
        ds.snow_theta_c = pn_test_rng_range(&rng, 0.01, 0.2);
        ds.snow_theta_s = pn_test_rng_range(&rng, 0, 0.02);
        ds.snow_xi = pn_test_rng_range(&rng, 0, 20);
        if (pn_material_init(&m, &ds, NULL, 0) != PN_OK) continue; /* unsupported pairs */
        t_rand_rot(&rng, d, R1);
        t_rand_rot(&rng, d, R2);
        for (k = 0; k < d; ++k) s[k] = exp(pn_test_rng_range(&rng, -range, range));
        if (t % 7 == 0) s[d - 1] = -s[d - 1];
        t_adb(d, R1, s, R2, Fd);
        for (k = 0; k < n; ++k) F[k] = Fd[k];
        for (k = 0; k < n; ++k) F2[k] = F[k] * (1 + 0.01 * pn_test_rng_range(&rng, -1, 1));
        h = ds.plastic == PN_PLASTIC_VON_MISES ? pn_test_rng_range(&rng, 0, 1) : pn_test_rng_range(&rng, -1, 1);
        for (k = 0; k < 9; ++k) Z[k] = T[k] = P[k] = G[k] = 7;
        for (k = 0; k < 81; ++k) H[k] = 7;
        r[0] = pn_return_map(&m, d, F, h, Z, &hn, T);
        bad += r[0] == PN_OK ? !(t_finite(n, Z) && t_finite(n, T) && t_finite(1, &hn))
                             : !(t_ex_untouched(n, Z) && t_ex_untouched(n, T) && hn == 7);
        r[1] = pn_yield_function(&m, d, F, h, &y, &sc);
        bad += r[1] == PN_OK ? !(t_finite(1, &y) && t_finite(1, &sc)) : !(y == 7 && sc == 7);
        for (k = 0; k < 81; ++k) H[k] = 7;
        for (k = 0; k < 9; ++k) P[k] = 7;
        psi = 7;
        r[2] = pn_elastic_energy(&m, d, F, h, &psi, P, H, (t & 2) ? (unsigned)PN_EVAL_PROJECT_PSD : 0u);
        bad += r[2] == PN_OK ? !(t_finite(1, &psi) && t_finite(n, P) && t_finite(n * n, H))
                             : !(psi == 7 && t_ex_untouched(n, P) && t_ex_untouched(n * n, H));
        r[3] = pn_lagged_prepare(&m, d, F, h, G, &hG);
        bad += r[3] == PN_OK ? !(t_finite(n, G) && t_finite(1, &hG)) : !(t_ex_untouched(n, G) && hG == 7);
        r[4] = PN_OK;
        if (r[3] == PN_OK) {
            for (k = 0; k < 81; ++k) H[k] = 7;
            for (k = 0; k < 9; ++k) P[k] = 7;
            psi = 7;
            r[4] = pn_lagged_energy(&m, d, F2, G, hG, &psi, P, H, PN_EVAL_PROJECT_PSD);
            bad += r[4] == PN_OK ? !(t_finite(1, &psi) && t_finite(n, P) && t_finite(n * n, H))
                                 : !(psi == 7 && t_ex_untouched(n, P) && t_ex_untouched(n * n, H));
        }
        for (k = 0; k < 81; ++k) H[k] = 7;
        for (k = 0; k < 9; ++k) P[k] = 7;
        psi = 7;
        r[5] = pn_von_mises_energy(&m, d, F, h < 0 ? -h : h, &psi, P, H, 0);
        bad += r[5] == PN_OK ? !(t_finite(1, &psi) && t_finite(n, P) && t_finite(n * n, H))
                             : !(psi == 7 && t_ex_untouched(n, P) && t_ex_untouched(n * n, H));
        for (k = 0; k < 6; ++k) {
            calls++;
            ok += r[k] == PN_OK;
            if ((int)r[k] >= 0 && r[k] < PN_RESULT_COUNT) codes[r[k]]++;
        }
    }
    PN_REPORT("%ld calls: %ld ok, %ld inverted, %ld unsupported, %ld overflow, %ld not-converged, "
              "%ld with a wrong output", calls, ok, codes[PN_ERROR_INVERTED],
              codes[PN_ERROR_UNSUPPORTED], codes[PN_ERROR_OVERFLOW], codes[PN_ERROR_NOT_CONVERGED], bad);
    PN_CHECK(bad == 0);
    PN_CHECK(codes[PN_ERROR_NONFINITE] == 0);     /* every input here is finite */
    PN_CHECK(codes[PN_ERROR_NOT_CONVERGED] == 0); /* the root finds are bracketed */
    PN_CHECK(ok > calls / 2);
}

/* What a friction angle means, from the stresses alone: drive a material point in Drucker-
   Prager sand (StVK-Hencky, 1 MPa) along a shear path at fixed compression until it flows,
   then read the Mohr-Coulomb angle off the returned principal Kirchhoff stresses,
   sin(phi) = (tau_max - tau_min) / -(tau_max + tau_min). 2D: biaxial shear e = (-v + g, -v - g),
   the angle in the plane (plane strain as the 2D law sees it); 3D: triaxial compression
   e = (-v - 2g, -v + g, -v + g), the meridian where the cone meets the Mohr-Coulomb pyramid.
   Both must give the angle the material was made with. */
PN_TEST(return_dp_friction_angle) {
    static const double phis[3] = {15, 30, 45};
    int d, k;
    for (d = 2; d <= 3; ++d)
        for (k = 0; k < 3; ++k) {
            pn_material_desc md;
            pn_material m;
            double mu, la, worst = 0, got = 0;
            int step, flowed = 0;
            memset(&md, 0, sizeof md);
            md.elastic = PN_ELASTIC_STVK_HENCKY;
            md.plastic = PN_PLASTIC_DRUCKER_PRAGER;
            md.youngs_modulus_pa = 1e6;
            md.poisson_ratio = 0.3;
            md.friction_angle_deg = phis[k];
            PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
            mu = t_mu(1e6, 0.3);
            la = t_lambda(1e6, 0.3);
            for (step = 1; step <= 400; ++step) {
                double g = 2.5e-5 * step, v = 1e-3, e[3], F[9] = {0}, Z[9], h, T[9], z[3], tr = 0, tau[3], hi, lo, sphi;
                int i;
                if (d == 2) e[0] = -v + g, e[1] = -v - g;
                else e[0] = -v - 2 * g, e[1] = e[2] = -v + g;
                for (i = 0; i < d; ++i) F[i * d + i] = exp(e[i]);
                PN_CHECK(pn_return_map(&m, d, F, 0, Z, &h, T) == PN_OK);
                for (i = 0; i < d; ++i) {
                    z[i] = log(Z[i * d + i]);
                    tr += z[i];
                }
                if (fabs(z[0] - e[0]) < 1e-12) continue; /* still elastic */
                flowed++;
                for (i = 0; i < d; ++i) tau[i] = 2 * mu * z[i] + la * tr;
                hi = lo = tau[0];
                for (i = 1; i < d; ++i) hi = fmax(hi, tau[i]), lo = fmin(lo, tau[i]);
                sphi = (hi - lo) / -(hi + lo);
                got = asin(sphi) * 180 / 3.14159265358979323846;
                worst = fmax(worst, fabs(got - phis[k]));
            }
            PN_CHECK(flowed > 10);
            PN_CHECK_LE(worst, 0.5);
            PN_REPORT("%dD, friction angle %g deg: Mohr-Coulomb angle of the flowing stress %.6f deg (%d plastic points)", d,
                      phis[k], got, flowed);
        }
}

static const pn_test_case pn_tests_return[] = {
    {"return_drucker_prager", return_drucker_prager},
    {"return_dp_friction_angle", return_dp_friction_angle},
    {"return_drucker_prager_cohesion", return_drucker_prager_cohesion},
    {"return_drucker_prager_volume_correction", return_drucker_prager_volume_correction},
    {"return_von_mises_stvk_hencky", return_von_mises_stvk_hencky},
    {"return_von_mises_neo_hookean", return_von_mises_neo_hookean},
    {"return_von_mises_small_yield", return_von_mises_small_yield},
    {"return_cam_clay", return_cam_clay},
    {"return_cam_clay_large_shear_3d", return_cam_clay_large_shear_3d},
    {"return_snow_stomakhin", return_snow_stomakhin},
    {"return_von_mises_energy_gradient", return_von_mises_energy_gradient},
    {"return_bad_input_nonfinite", return_bad_input_nonfinite},
    {"return_bad_parameters", return_bad_parameters},
    {"return_unsupported_combinations", return_unsupported_combinations},
    {"return_inverted", return_inverted},
    {"return_von_mises_negative_state", return_von_mises_negative_state},
    {"return_extremes_fuzz", return_extremes_fuzz},
};
