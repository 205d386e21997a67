/* test_energy.c - finite differences and invariants of every energy of plastinet.h: the four
   elastic models, the exact StVK-Hencky + von Mises energy and the lagged-plasticity energy.

   #included by test_main.c after plastinet.h (with PLASTINET_IMPLEMENTATION) and pn_test.h;
   defines pn_tests_energy. Expected values come from independent sources: central differences
   with Richardson extrapolation, the principal-stretch formulas of docs/method.md evaluated on
   singular values known by construction (F = R1 diag(s) R2), and the tests' own Jacobi
   eigen-solver for the PSD projection. The helpers shared with the other test files (products,
   norm, random rotations, the Jacobi solver, Lame constants) are in test_util.h; those of this
   file carry the t_en_ prefix (one translation unit is shared with the other test files). */


#define T_EN_NS 100          /* samples per (model, dimension, kind)                        */
#define T_EN_FD_TOL 1e-6     /* finite differences, relative (the figure)           */
#define T_EN_REF_TOL 1e-10   /* against the principal-stretch formulas, relative            */
#define T_EN_SYM_TOL 1e-12   /* asymmetry of dP/dF, relative                                */
#define T_EN_PSD_TOL 1e-10   /* projected dP/dF against our own projection, relative        */

/* ---- helpers of this file (the shared ones are in test_util.h) ----------------------------- */

static void t_en_maxto(double *worst, double v) {
    if (!(v <= *worst) && *worst == *worst) *worst = v; /* a NaN sticks */
}

/* Nearest PSD matrix of the symmetric part of H (t_jacobi, not pn_sym_eigen); returns the
   smallest eigenvalue. */
static double t_en_project_psd(int n, const double *H, double *out) {
    double Q[81], w[9];
    t_jacobi(n, H, Q, w);
    return t_psd_rebuild(n, Q, w, out);
}
/* smallest singular value by our own eigen-decomposition of A^T A */
static double t_en_smin(int dim, const double *A) {
    double AtA[9], Q[9], w[3], mn = HUGE_VAL;
    int i;
    t_mul_tn(dim, A, A, AtA);
    t_jacobi(dim, AtA, Q, w);
    for (i = 0; i < dim; ++i)
        if (w[i] < mn) mn = w[i];
    return sqrt(mn > 0 ? mn : 0);
}

/* ---- materials -------------------------------------------------------------------------------- */

static void t_en_desc(pn_material_desc *d, pn_elastic_model el, pn_plastic_model pl, double E, double nu) {
    memset(d, 0, sizeof *d);
    d->elastic = el;
    d->plastic = pl;
    d->youngs_modulus_pa = E;
    d->poisson_ratio = nu;
}
static int t_en_init(pn_test_ctx *pn__t, pn_material *m, const pn_material_desc *d) {
    char why[256] = "";
    pn_result r = pn_material_init(m, d, why, sizeof why);
    if (r != PN_OK) {
        char msg[512];
        snprintf(msg, sizeof msg, "pn_material_init failed (%d): %s", (int)r, why);
        pn_test__fail(pn__t, __FILE__, __LINE__, msg);
        return 0;
    }
    return 1;
}
static const double t_en_E[3] = {1e4, 1e6, 1e7};
static const double t_en_nu[3] = {0.3, 0.45, -0.3};

/* Lagged-energy test materials: sand, metal, Cam-Clay snow, Stomakhin snow. */
enum { T_EN_SAND, T_EN_METAL, T_EN_CAMCLAY, T_EN_STOMAKHIN, T_EN_NLAGGED };
static const char *const t_en_lagged_name[T_EN_NLAGGED] = {"Drucker-Prager sand", "von Mises metal",
                                                           "Cam-Clay snow", "Stomakhin snow"};
static void t_en_lagged_desc(pn_material_desc *d, int which, double E) {
    switch (which) {
    case T_EN_SAND:
        t_en_desc(d, PN_ELASTIC_DEFAULT, PN_PLASTIC_DRUCKER_PRAGER, E, 0.3);
        d->friction_angle_deg = 30;
        break;
    case T_EN_METAL:
        t_en_desc(d, PN_ELASTIC_DEFAULT, PN_PLASTIC_VON_MISES, E, 0.3);
        d->yield_stress_pa = 1e-3 * E;
        d->hardening_modulus_pa = 1e-2 * E;
        break;
    case T_EN_CAMCLAY:
        t_en_desc(d, PN_ELASTIC_DEFAULT, PN_PLASTIC_CAM_CLAY, E, 0.3);
        d->friction_angle_deg = 30;
        d->camclay_beta = 0.3;
        d->camclay_xi = 10;
        break;
    default:
        t_en_desc(d, PN_ELASTIC_DEFAULT, PN_PLASTIC_SNOW_STOMAKHIN, E, 0.3);
        d->snow_theta_c = 2.5e-2;
        d->snow_theta_s = 7.5e-3;
        d->snow_xi = 10;
        break;
    }
}
static double t_en_lagged_h0(pn_test_rng *rng, int which) {
    switch (which) {
    case T_EN_SAND: return 0;
    case T_EN_METAL: return pn_test_rng_range(rng, 0, 0.1);
    case T_EN_CAMCLAY: return t_randint(rng, 2) ? -0.05 : pn_test_rng_range(rng, -0.1, 0);
    default: return pn_test_rng_range(rng, -0.1, 0.1);
    }
}

/* ---- one interface over the three evaluators ------------------------------------------------ */

enum { T_EN_ELASTIC, T_EN_VM, T_EN_LAGGED, T_EN_PNET, T_EN_DP };
typedef struct t_en_fn {
    int kind;
    const pn_material *m;
    double h;        /* state (elastic: Stomakhin hardening; von Mises: frozen a; lagged: h_G) */
    const double *G; /* lagged only */
    const pn_pnet *net;          /* PlasticityNet only (test_pnet_*.c) */
    const pn_pnet_point *pt;
    double tau_y;                /* frozen-yield Drucker-Prager only */
} t_en_fn;

static pn_result t_en_eval(const t_en_fn *f, int dim, const double *F, double *psi, double *P,
                           double *dPdF, unsigned flags) {
    switch (f->kind) {
    case T_EN_ELASTIC: return pn_elastic_energy(f->m, dim, F, f->h, psi, P, dPdF, flags);
    case T_EN_VM: return pn_von_mises_energy(f->m, dim, F, f->h, psi, P, dPdF, flags);
    case T_EN_PNET: return pn_pnet_energy(f->net, f->pt, F, psi, P, dPdF, flags);
    case T_EN_DP: return pn_dp_energy(f->m, dim, F, f->h, f->tau_y, psi, P, dPdF, flags);
    default: return pn_lagged_energy(f->m, dim, F, f->G, f->h, psi, P, dPdF, flags);
    }
}

/* Central differences in every entry of F, Richardson-extrapolated over steps h and h/2
   (error O(h^4)). what = 0: d psi / dF (d^2 values); 1: dP/dF (d^4 values, same layout as
   the library). Returns the number of failed evaluations. */
static int t_en_fd(const t_en_fn *f, int dim, const double *F, double h, int what, double *out) {
    const int n2 = dim * dim;
    int kl, i, fails = 0, half;
    for (kl = 0; kl < n2; ++kl) {
        double D[2][9];
        for (half = 0; half < 2; ++half) {
            double step = half ? 0.5 * h : h, Fp[9], Fm[9], pp = 0, pm = 0, Pp[9], Pm[9];
            memcpy(Fp, F, sizeof(double) * (size_t)n2);
            memcpy(Fm, F, sizeof(double) * (size_t)n2);
            Fp[kl] += step;
            Fm[kl] -= step;
            step = 0.5 * (Fp[kl] - Fm[kl]); /* the step actually taken */
            if (what == 0) {
                fails += t_en_eval(f, dim, Fp, &pp, NULL, NULL, 0) != PN_OK;
                fails += t_en_eval(f, dim, Fm, &pm, NULL, NULL, 0) != PN_OK;
                D[half][0] = (pp - pm) / (2 * step);
            } else {
                fails += t_en_eval(f, dim, Fp, NULL, Pp, NULL, 0) != PN_OK;
                fails += t_en_eval(f, dim, Fm, NULL, Pm, NULL, 0) != PN_OK;
                for (i = 0; i < n2; ++i) D[half][i] = (Pp[i] - Pm[i]) / (2 * step);
            }
        }
        if (what == 0)
            out[kl] = (4 * D[1][0] - D[0][0]) / 3;
        else
            for (i = 0; i < n2; ++i) out[i * n2 + kl] = (4 * D[1][i] - D[0][i]) / 3;
    }
    return fails;
}

/* Figures of one evaluator over many samples. */
typedef struct t_en_stats {
    double grad, hess, sym, psd, psd_min, ref_psi, ref_P;
    long samples, skipped, eval_fail;
    double psd_excess; /* (|H - Hp| - |H - nearest|) / |H|: > 0 means Hp is not the nearest */
    double grad_F[9], hess_F[9], psd_F[9];
    int grad_dim, hess_dim, psd_dim;
} t_en_stats;

/* The lagged energy's projection contract (plastinet.h, pn_lagged_energy): the elastic Hessian
   at A = F G is projected to its nearest PSD matrix, then carried to F by the congruence
   d2Psi/dF_ij dF_kl = G_jm Hp[im][kb] G_lb (PSD, though not the nearest PSD matrix of the
   lagged Hessian since G is not orthogonal). The reference projects the unprojected elastic
   Hessian with this file's own eigen-solver. */
static void t_en_lagged_psd_reference(const t_en_fn *f, int dim, const double *F, double *ref) {
    const int n2 = dim * dim;
    double A[9] = {0}, He[81], Hp[81];
    int i, j, k, l, m, b;
    t_mul(dim, F, f->G, A);
    if (pn_elastic_energy(f->m, dim, A, f->h, NULL, NULL, He, 0) != PN_OK) {
        for (i = 0; i < n2 * n2; ++i) ref[i] = NAN;
        return;
    }
    t_en_project_psd(n2, He, Hp);
    for (i = 0; i < dim; ++i)
        for (j = 0; j < dim; ++j)
            for (k = 0; k < dim; ++k)
                for (l = 0; l < dim; ++l) {
                    double acc = 0;
                    for (m = 0; m < dim; ++m)
                        for (b = 0; b < dim; ++b)
                            acc += f->G[j * dim + m] * Hp[(i * dim + m) * n2 + k * dim + b] * f->G[l * dim + b];
                    ref[(i * dim + j) * n2 + k * dim + l] = acc;
                }
}

/* Every check of one sample: FD of psi and of P, symmetry and PSD projection of dP/dF.
   E sets the floor of relative errors; h_fd the step. */
static void t_en_check_sample(t_en_stats *st, const t_en_fn *f, int dim, const double *F, double E,
                              double h_fd, int do_fd, double *eg, double *eh) {
    const int n2 = dim * dim, n4 = n2 * n2;
    double psi = 0, P[9], H[81], Hp[81], ref[81], fd[81], nH, e;
    *eg = *eh = 0;
    st->samples++;
    if (t_en_eval(f, dim, F, &psi, P, H, 0) != PN_OK) {
        st->eval_fail++;
        return;
    }
    if (t_en_eval(f, dim, F, NULL, NULL, Hp, PN_EVAL_PROJECT_PSD) != PN_OK) {
        st->eval_fail++;
        return;
    }
    nH = t_norm(n4, H);
    t_en_maxto(&st->sym, t_asym(n2, H) / (nH > 1e-8 * E ? nH : 1e-8 * E));
    {
        double Q[81], w[9];
        int i;
        double den = nH > 1e-8 * E ? nH : 1e-8 * E;
        if (f->kind == T_EN_LAGGED)
            t_en_lagged_psd_reference(f, dim, F, ref);
        else
            t_en_project_psd(n2, H, ref);
        e = t_dist(n4, Hp, ref) / den;
        if (!(e <= st->psd) && st->psd == st->psd) {
            st->psd = e;
            st->psd_dim = dim;
            memcpy(st->psd_F, F, sizeof(double) * (size_t)n2);
        }
        t_en_maxto(&st->psd_excess, (t_dist(n4, H, Hp) - t_dist(n4, H, ref)) / den);
        t_jacobi(n2, Hp, Q, w);
        for (i = 0; i < n2; ++i) t_en_maxto(&st->psd_min, -w[i] / (nH > 1e-8 * E ? nH : 1e-8 * E));
    }
    if (!do_fd) {
        st->skipped++;
        return;
    }
    st->eval_fail += t_en_fd(f, dim, F, h_fd, 0, fd);
    {
        double nP = t_norm(n2, P);
        e = t_dist(n2, fd, P) / (nP > 1e-8 * E ? nP : 1e-8 * E);
        *eg = e;
        if (!(e <= st->grad) && st->grad == st->grad) {
            st->grad = e;
            st->grad_dim = dim;
            memcpy(st->grad_F, F, sizeof(double) * (size_t)n2);
        }
    }
    st->eval_fail += t_en_fd(f, dim, F, h_fd, 1, fd);
    e = t_dist(n4, fd, H) / (nH > 1e-8 * E ? nH : 1e-8 * E);
    *eh = e;
    if (!(e <= st->hess) && st->hess == st->hess) {
        st->hess = e;
        st->hess_dim = dim;
        memcpy(st->hess_F, F, sizeof(double) * (size_t)n2);
    }
}

static void t_en_print_F(const char *what, int dim, const double *F) {
    int i;
    fprintf(stderr, "      worst %s at F = {", what);
    for (i = 0; i < dim * dim; ++i) fprintf(stderr, "%s%.17g", i ? ", " : "", F[i]);
    fprintf(stderr, "} (dim %d)\n", dim);
}

static void t_en_finish(pn_test_ctx *pn__t, const t_en_stats *st, int with_ref) {
    if (with_ref)
        PN_REPORT("%ld samples (%ld without FD): FD grad %.2e, FD hess %.2e, asym %.2e, PSD proj %.2e "
                  "(min eig %.1e); vs principal formulas psi %.2e, P %.2e",
                  st->samples, st->skipped, st->grad, st->hess, st->sym, st->psd, -st->psd_min,
                  st->ref_psi, st->ref_P);
    else
        PN_REPORT("%ld samples (%ld without FD): FD grad %.2e, FD hess %.2e, asym %.2e, PSD proj %.2e "
                  "(min eig %.1e)",
                  st->samples, st->skipped, st->grad, st->hess, st->sym, st->psd, -st->psd_min);
    PN_CHECK(st->eval_fail == 0);
    PN_CHECK(st->samples - st->skipped > 0);
    PN_CHECK_LE(st->grad, T_EN_FD_TOL);
    PN_CHECK_LE(st->hess, T_EN_FD_TOL);
    PN_CHECK_LE(st->sym, T_EN_SYM_TOL);
    PN_CHECK_LE(st->psd, T_EN_PSD_TOL);
    PN_CHECK_LE(st->psd_min, T_EN_PSD_TOL);
    if (with_ref) {
        PN_CHECK_LE(st->ref_psi, T_EN_REF_TOL);
        PN_CHECK_LE(st->ref_P, T_EN_REF_TOL);
    }
    if (!(st->grad <= T_EN_FD_TOL)) t_en_print_F("FD grad", st->grad_dim, st->grad_F);
    if (!(st->hess <= T_EN_FD_TOL)) t_en_print_F("FD hess", st->hess_dim, st->hess_F);
    if (!(st->psd <= T_EN_PSD_TOL)) {
        t_en_print_F("PSD projection", st->psd_dim, st->psd_F);
        fprintf(stderr, "      the projected dP/dF is up to %.3g |dP/dF| farther from dP/dF than its "
                "nearest PSD matrix\n", st->psd_excess);
    }
}

/* ---- principal-stretch reference energies (docs/method.md), signed s by construction -------- */

/* psi and dpsi/ds_i of an elastic model; P = R1 diag(dpsi/ds) R2 when F = R1 diag(s) R2. */
static void t_en_ref_elastic(pn_elastic_model model, double mu, double lam, int dim, const double *s,
                             double *psi, double *dpsi) {
    double J = 1, logJ = 0, I1 = 0, tr = 0, Jo[3];
    int i, j;
    for (i = 0; i < dim; ++i) {
        J *= s[i];
        I1 += s[i] * s[i];
        Jo[i] = 1;
        for (j = 0; j < dim; ++j)
            if (j != i) Jo[i] *= s[j]; /* J / s_i without dividing */
    }
    switch (model) {
    case PN_ELASTIC_FIXED_COROTATED:
        *psi = lam / 2 * (J - 1) * (J - 1);
        for (i = 0; i < dim; ++i) {
            *psi += mu * (s[i] - 1) * (s[i] - 1);
            dpsi[i] = 2 * mu * (s[i] - 1) + lam * (J - 1) * Jo[i];
        }
        break;
    case PN_ELASTIC_STVK_HENCKY:
        for (i = 0; i < dim; ++i) tr += log(s[i]);
        *psi = lam / 2 * tr * tr;
        for (i = 0; i < dim; ++i) {
            double e = log(s[i]);
            *psi += mu * e * e;
            dpsi[i] = (2 * mu * e + lam * tr) / s[i];
        }
        break;
    case PN_ELASTIC_NEO_HOOKEAN:
        for (i = 0; i < dim; ++i) logJ += log(s[i]);
        *psi = mu / 2 * (I1 - dim) - mu * logJ + lam / 2 * logJ * logJ;
        for (i = 0; i < dim; ++i) dpsi[i] = mu * s[i] + (lam * logJ - mu) / s[i];
        break;
    default: { /* Neo-Hookean snow */
        double kappa = lam + 2 * mu / dim, Jm;
        for (i = 0; i < dim; ++i) logJ += log(s[i]);
        Jm = exp(-2.0 / dim * logJ);
        *psi = mu / 2 * (Jm * I1 - dim) + kappa / 2 * ((J * J - 1) / 2 - logJ);
        for (i = 0; i < dim; ++i)
            dpsi[i] = mu * Jm * (s[i] - I1 / (dim * s[i])) + kappa / 2 * (J * J - 1) / s[i];
        break;
    }
    }
}

/* Exact StVK-Hencky + von Mises energy (docs/method.md) from the log stretches e: kappa/2
   (tr e)^2 + min over g >= 0 of mu (|dev e| - g)^2 + tauY g + beta/2 g^2 (beta = 2K/3), the
   minimizing g found by bisection on the derivative (not the library's closed form). Returns
   the signed distance |dev e| - r to the yield surface in strain. */
static double t_en_ref_vm(double mu, double lam, double tauY, double beta, int dim, const double *s, double *psi,
                          double *dpsi) {
    double e[3], tr = 0, nd = 0, kappa = lam + 2 * mu / dim, r = tauY / (2 * mu), g = 0, w1;
    int i;
    for (i = 0; i < dim; ++i) {
        e[i] = log(s[i]);
        tr += e[i];
    }
    for (i = 0; i < dim; ++i) nd += (e[i] - tr / dim) * (e[i] - tr / dim);
    nd = sqrt(nd);
    if (nd > r) { /* d/dg: -2 mu (nd - g) + tauY + beta g, increasing, < 0 at 0, > 0 at nd */
        double lo = 0, hi = nd;
        for (i = 0; i < 200 && hi > lo; ++i) {
            double mid = (lo + hi) / 2;
            if (-2 * mu * (nd - mid) + tauY + beta * mid > 0) hi = mid;
            else lo = mid;
        }
        g = (lo + hi) / 2;
    }
    *psi = kappa / 2 * tr * tr + mu * (nd - g) * (nd - g) + tauY * g + beta / 2 * g * g;
    w1 = nd > 0 ? 2 * mu * (nd - g) / nd : 0; /* dev tau = 2 mu (nd - g) n: the envelope theorem */
    for (i = 0; i < dim; ++i) dpsi[i] = (kappa * tr + w1 * (e[i] - tr / dim)) / s[i];
    return nd - r;
}

/* ---- samples --------------------------------------------------------------------------------- */

enum { T_EN_STRETCH, T_EN_EQUAL, T_EN_SINGULAR, T_EN_REST, T_EN_INVERTED, T_EN_DEGENERATE, T_EN_NKIND };
static const char *const t_en_kind_name[T_EN_NKIND] = {"stretch", "near-equal", "near-singular",
                                                       "near-rest", "inverted", "det~0"};

/* s signed, F = R1 diag(s) R2; returns the length scale of the FD step. */
static double t_en_sample(pn_test_rng *rng, int dim, int kind, double *s, double *R1, double *R2,
                          double *F) {
    int i, j;
    double scale = 1;
    t_rand_rot(rng, dim, R1);
    t_rand_rot(rng, dim, R2);
    for (i = 0; i < 3; ++i) s[i] = t_logu(rng, 0.2, 5);
    switch (kind) {
    case T_EN_EQUAL: {
        static const double gap[4] = {0, 1e-13, 1e-11, 1e-9};
        int v = t_randint(rng, 3);
        if (v == 0 || dim == 2) {
            for (i = 1; i < dim; ++i) s[i] = s[0] * (1 + gap[t_randint(rng, 4)] * pn_test_rng_uniform(rng));
        } else {
            int a = t_randint(rng, 3), b = (a + 1 + t_randint(rng, 2)) % 3;
            s[b] = s[a] * (1 + gap[t_randint(rng, 4)] * pn_test_rng_range(rng, -1, 1));
        }
        break;
    }
    case T_EN_SINGULAR:
        s[t_randint(rng, dim)] = t_logu(rng, 1e-3, 1e-2);
        break;
    case T_EN_REST:
        for (i = 0; i < 3; ++i) s[i] = 1 + 1e-3 * pn_test_rng_range(rng, -1, 1);
        break;
    case T_EN_INVERTED:
    case T_EN_DEGENERATE:
        for (i = 1; i < dim; ++i) /* descending magnitudes */
            for (j = i; j > 0 && s[j - 1] < s[j]; --j) {
                double t = s[j];
                s[j] = s[j - 1];
                s[j - 1] = t;
            }
        if (kind == T_EN_INVERTED) {
            /* keep s_(d-2) + s_(d-1) away from 0, where the rotation of F jumps */
            if (s[dim - 1] > 0.8 * s[dim - 2]) s[dim - 1] = 0.8 * s[dim - 2] * pn_test_rng_uniform(rng) + 1e-3;
            s[dim - 1] = -s[dim - 1];
        } else {
            static const double tiny[4] = {0, 1e-6, 1e-3, 1e-2};
            s[dim - 1] = tiny[t_randint(rng, 4)] * (t_randint(rng, 2) ? 1 : -1);
        }
        break;
    default:
        break;
    }
    for (i = dim; i < 3; ++i) s[i] = 1;
    t_adb(dim, R1, s, R2, F);
    if (kind == T_EN_INVERTED || kind == T_EN_DEGENERATE) {
        scale = s[dim - 2] + s[dim - 1];
    } else {
        for (i = 0; i < dim; ++i)
            if (fabs(s[i]) < scale) scale = fabs(s[i]);
    }
    return scale < 1 ? scale : 1;
}

/* ---- tests ------------------------------------------------------------------------------------ */

PN_TEST(energy_material_lame) {
    double worst = 0;
    int i, j, bad = 0;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) {
            pn_material_desc d;
            pn_material m;
            double E = t_en_E[i], nu = t_en_nu[j], mu = t_mu(E, nu), lam = t_lambda(E, nu);
            pn_real mu2 = 0, lam2 = 0;
            t_en_desc(&d, PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, E, nu);
            if (!t_en_init(pn__t, &m, &d)) continue;
            t_en_maxto(&worst, fabs(m.mu - mu) / mu);
            t_en_maxto(&worst, fabs(m.lambda - lam) / fabs(lam));
            if (pn_lame(E, nu, &mu2, &lam2) != PN_OK) ++bad;
            t_en_maxto(&worst, fabs(mu2 - mu) / mu);
            t_en_maxto(&worst, fabs(lam2 - lam) / fabs(lam));
        }
    PN_REPORT("mu, lambda against E/(2(1+nu)), E nu/((1+nu)(1-2nu)): worst relative %.2e", worst);
    PN_CHECK(bad == 0);
    PN_CHECK_LE(worst, 1e-15);
}

/* F = I: psi = 0, P = 0, dP/dF = the isotropic elasticity tensor
   mu (d_ik d_jl + d_il d_jk) + lambda d_ij d_kl for every model (they share their linearisation). */
PN_TEST(energy_rest_state) {
    double wpsi = 0, wP = 0, wH = 0, wHp = 0;
    int model, dim, ie, in, count = 0;
    for (model = PN_ELASTIC_FIXED_COROTATED; model <= PN_ELASTIC_NEO_HOOKEAN_SNOW + 2; ++model)
        for (dim = 2; dim <= 3; ++dim)
            for (ie = 0; ie < 3; ++ie)
                for (in = 0; in < 3; ++in) {
                    pn_material_desc d;
                    pn_material m;
                    t_en_fn f;
                    double E = t_en_E[ie], nu = t_en_nu[in], mu = t_mu(E, nu), lam = t_lambda(E, nu);
                    double F[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0}, psi = 1, P[9], H[81], Hp[81], C[81];
                    int i, j, k, l, n2 = dim * dim;
                    if (model <= PN_ELASTIC_NEO_HOOKEAN_SNOW) {
                        t_en_desc(&d, (pn_elastic_model)model, PN_PLASTIC_NONE, E, nu);
                        f.kind = T_EN_ELASTIC;
                    } else if (model == PN_ELASTIC_NEO_HOOKEAN_SNOW + 1) { /* Stomakhin, h = 0 */
                        t_en_lagged_desc(&d, T_EN_STOMAKHIN, E);
                        d.poisson_ratio = nu;
                        f.kind = T_EN_ELASTIC;
                    } else { /* exact von Mises energy */
                        t_en_lagged_desc(&d, T_EN_METAL, E);
                        d.poisson_ratio = nu;
                        f.kind = T_EN_VM;
                    }
                    if (!t_en_init(pn__t, &m, &d)) continue;
                    f.m = &m;
                    f.h = 0;
                    f.G = NULL;
                    for (i = 0; i < dim; ++i) F[i * dim + i] = 1;
                    if (t_en_eval(&f, dim, F, &psi, P, H, 0) != PN_OK ||
                        t_en_eval(&f, dim, F, NULL, NULL, Hp, PN_EVAL_PROJECT_PSD) != PN_OK) {
                        PN_CHECK(!"evaluation at F = I failed");
                        continue;
                    }
                    ++count;
                    for (i = 0; i < dim; ++i)
                        for (j = 0; j < dim; ++j)
                            for (k = 0; k < dim; ++k)
                                for (l = 0; l < dim; ++l)
                                    C[(i * dim + j) * n2 + k * dim + l] =
                                        mu * ((i == k && j == l) + (i == l && j == k)) + lam * (i == j && k == l);
                    t_en_maxto(&wpsi, fabs(psi) / E);
                    t_en_maxto(&wP, t_norm(n2, P) / E);
                    t_en_maxto(&wH, t_dist(n2 * n2, H, C) / t_norm(n2 * n2, C));
                    t_en_maxto(&wHp, t_dist(n2 * n2, Hp, C) / t_norm(n2 * n2, C)); /* C is PSD */
                }
    PN_REPORT("%d (model, dim, E, nu) at F = I: |psi|/E %.2e, |P|/E %.2e, dP/dF vs isotropic "
              "tensor %.2e (projected %.2e)",
              count, wpsi, wP, wH, wHp);
    PN_CHECK(count == 6 * 2 * 9);
    PN_CHECK_LE(wpsi, 1e-14);
    PN_CHECK_LE(wP, 1e-12);
    PN_CHECK_LE(wH, 1e-10);
    PN_CHECK_LE(wHp, 1e-10);
}

/* FD, reference and PSD checks of one elastic model over every sample kind it is defined on. */
static void t_en_run_elastic(pn_test_ctx *pn__t, pn_elastic_model model, unsigned long long seed) {
    t_en_stats st;
    pn_test_rng rng;
    int dim, kind, k, nkind = model == PN_ELASTIC_FIXED_COROTATED ? T_EN_NKIND : T_EN_INVERTED;
    double wk_grad[T_EN_NKIND], wk_hess[T_EN_NKIND];
    memset(&st, 0, sizeof st);
    memset(wk_grad, 0, sizeof wk_grad);
    memset(wk_hess, 0, sizeof wk_hess);
    rng.s = seed;
    for (dim = 2; dim <= 3; ++dim)
        for (kind = 0; kind < nkind; ++kind)
            for (k = 0; k < T_EN_NS; ++k) {
                pn_material_desc d;
                pn_material m;
                t_en_fn f;
                double E = t_en_E[k % 3], nu = t_en_nu[(k / 3) % 3], s[3], R1[9], R2[9], F[9];
                double scale = t_en_sample(&rng, dim, kind, s, R1, R2, F), eg, eh;
                t_en_desc(&d, model, PN_PLASTIC_NONE, E, nu);
                if (!t_en_init(pn__t, &m, &d)) return;
                f.kind = T_EN_ELASTIC;
                f.m = &m;
                f.h = 0;
                f.G = NULL;
                if (model == PN_ELASTIC_FIXED_COROTATED) {
                    /* smooth except where the rotation of F jumps (s_i + s_j = 0), also at s_i = 0 */
                    int i, j;
                    scale = 1;
                    for (i = 0; i < dim; ++i)
                        for (j = i + 1; j < dim; ++j)
                            if (s[i] + s[j] < scale) scale = s[i] + s[j];
                }
                t_en_check_sample(&st, &f, dim, F, E, 1e-4 * scale, 1, &eg, &eh);
                t_en_maxto(&wk_grad[kind], eg);
                t_en_maxto(&wk_hess[kind], eh);
                { /* the principal-stretch formulas on the constructed s */
                    /* floor: the stress of a 1e-3 strain (rounding F to doubles moves P by
                       ~1e-16 |dP/dF| |F|, which is all there is near rest) */
                    double psi_ref, dpsi[3], Pref[9], psi = 0, P[9], nP;
                    double floor = 1e-3 * (2 * t_mu(E, nu) + fabs(t_lambda(E, nu)));
                    int n2 = dim * dim;
                    t_en_ref_elastic(model, t_mu(E, nu), t_lambda(E, nu), dim, s, &psi_ref, dpsi);
                    t_adb(dim, R1, dpsi, R2, Pref);
                    if (pn_elastic_energy(&m, dim, F, 0, &psi, P, NULL, 0) == PN_OK) {
                        nP = t_norm(n2, Pref);
                        t_en_maxto(&st.ref_psi, fabs(psi - psi_ref) / (fabs(psi_ref) + nP * t_norm(n2, F) + floor));
                        t_en_maxto(&st.ref_P, t_dist(n2, P, Pref) / (nP + floor));
                    } else
                        st.eval_fail++;
                }
            }
    t_en_finish(pn__t, &st, 1);
    for (kind = 0; kind < nkind; ++kind)
        PN_REPORT("  %-13s worst FD grad %.2e, hess %.2e", t_en_kind_name[kind], wk_grad[kind], wk_hess[kind]);
}

PN_TEST(energy_fd_fixed_corotated) { t_en_run_elastic(pn__t, PN_ELASTIC_FIXED_COROTATED, 201); }
PN_TEST(energy_fd_stvk_hencky) { t_en_run_elastic(pn__t, PN_ELASTIC_STVK_HENCKY, 202); }
PN_TEST(energy_fd_neo_hookean) { t_en_run_elastic(pn__t, PN_ELASTIC_NEO_HOOKEAN, 203); }
PN_TEST(energy_fd_neo_hookean_snow) { t_en_run_elastic(pn__t, PN_ELASTIC_NEO_HOOKEAN_SNOW, 204); }

/* Stomakhin snow: fixed corotated with mu, lambda scaled by exp(xi (1 - J_p)), J_p = exp(h). */
PN_TEST(energy_stomakhin_hardening) {
    pn_test_rng rng;
    double wpsi = 0, wP = 0;
    int k, model_ok = 1;
    rng.s = 205;
    for (k = 0; k < 2000; ++k) {
        pn_material_desc d;
        pn_material m;
        int dim = 2 + (k & 1), n2 = dim * dim;
        double E = t_en_E[k % 3], s[3], R1[9], R2[9], F[9], h = pn_test_rng_range(&rng, -0.2, 0.2);
        double sc, psi_ref, dpsi[3], Pref[9], psi = 0, P[9], nP;
        t_en_sample(&rng, dim, k % 4, s, R1, R2, F);
        t_en_lagged_desc(&d, T_EN_STOMAKHIN, E);
        if (!t_en_init(pn__t, &m, &d)) return;
        if (m.elastic != PN_ELASTIC_FIXED_COROTATED) model_ok = 0;
        sc = exp(10.0 * (1 - exp(h)));
        t_en_ref_elastic(PN_ELASTIC_FIXED_COROTATED, sc * t_mu(E, 0.3), sc * t_lambda(E, 0.3), dim, s,
                         &psi_ref, dpsi);
        t_adb(dim, R1, dpsi, R2, Pref);
        if (pn_elastic_energy(&m, dim, F, h, &psi, P, NULL, 0) != PN_OK) {
            PN_CHECK(!"pn_elastic_energy failed");
            continue;
        }
        nP = t_norm(n2, Pref);
        t_en_maxto(&wpsi, fabs(psi - psi_ref) / (fabs(psi_ref) + nP * t_norm(n2, F) + 1e-4 * E * sc));
        t_en_maxto(&wP, t_dist(n2, P, Pref) / (nP + 1e-4 * E * sc));
    }
    PN_REPORT("h in [-0.2, 0.2]: psi %.2e, P %.2e relative to the scaled fixed-corotated formulas", wpsi, wP);
    PN_CHECK(model_ok);
    PN_CHECK_LE(wpsi, T_EN_REF_TOL);
    PN_CHECK_LE(wP, T_EN_REF_TOL);
}

/* Singular values for the von Mises samples: elastic region, across it, large stretch. */
static double t_en_vm_sample(pn_test_rng *rng, int dim, int kind, double r, double *s, double *R1,
                             double *R2, double *F) {
    int i;
    double scale = 1;
    if (kind == 0 || kind == 4) {
        /* e = t 1 + rho n, n a unit deviatoric direction, rho in [0, 3r] (kind 0) or
           r (1 +- 1e-8 .. 1e-2), on either side of the yield surface (kind 4) */
        double n[3], mean = 0, nn = 0, t = pn_test_rng_range(rng, -0.3, 0.3), rho = 3 * r * pn_test_rng_uniform(rng);
        if (kind == 4) rho = r * (1 + (t_randint(rng, 2) ? 1 : -1) * pow(10.0, pn_test_rng_range(rng, -8, -2)));
        for (i = 0; i < dim; ++i) {
            n[i] = t_gauss(rng);
            mean += n[i] / dim;
        }
        for (i = 0; i < dim; ++i) {
            n[i] -= mean;
            nn += n[i] * n[i];
        }
        nn = sqrt(nn);
        for (i = 0; i < dim; ++i) s[i] = exp(t + rho * n[i] / nn);
        for (i = dim; i < 3; ++i) s[i] = 1;
        t_rand_rot(rng, dim, R1);
        t_rand_rot(rng, dim, R2);
        t_adb(dim, R1, s, R2, F);
        for (i = 0; i < dim; ++i)
            if (s[i] < scale) scale = s[i];
        return scale;
    }
    return t_en_sample(rng, dim, kind == 1 ? T_EN_STRETCH : kind == 2 ? T_EN_EQUAL : T_EN_SINGULAR, s, R1, R2, F);
}

PN_TEST(energy_fd_von_mises) {
    t_en_stats st;
    pn_test_rng rng;
    int dim, kind, k;
    long n_el = 0, n_pl = 0;
    double wk_grad[5] = {0, 0, 0, 0, 0}, wk_hess[5] = {0, 0, 0, 0, 0};
    static const char *const vm_kind[5] = {"around yield", "stretch", "near-equal", "near-singular", "at yield"};
    memset(&st, 0, sizeof st);
    rng.s = 206;
    for (dim = 2; dim <= 3; ++dim)
        for (kind = 0; kind < 5; ++kind)
            for (k = 0; k < 2 * T_EN_NS; ++k) {
                pn_material_desc d;
                pn_material m;
                t_en_fn f;
                double E = t_en_E[k % 3], nu = t_en_nu[(k / 3) % 3], mu = t_mu(E, nu), lam = t_lambda(E, nu);
                double K = (k & 1) ? 0.05 * E : 0, h = pn_test_rng_range(&rng, 0, 0.2);
                double tauY = sqrt(2.0 / 3.0) * (1e-3 * E + K * h), r = tauY / (2 * mu);
                double s[3], R1[9], R2[9], F[9], scale, dist, psi_ref, dpsi[3], Pref[9], psi = 0, P[9];
                double step, eg, eh;
                int n2 = dim * dim;
                t_en_desc(&d, PN_ELASTIC_DEFAULT, PN_PLASTIC_VON_MISES, E, nu);
                d.yield_stress_pa = 1e-3 * E;
                d.hardening_modulus_pa = K;
                if (!t_en_init(pn__t, &m, &d)) return;
                scale = t_en_vm_sample(&rng, dim, kind, r, s, R1, R2, F);
                f.kind = T_EN_VM;
                f.m = &m;
                f.h = h;
                f.G = NULL;
                dist = t_en_ref_vm(mu, lam, tauY, 2 * K / 3, dim, s, &psi_ref, dpsi);
                if (dist <= 0) ++n_el; else ++n_pl;
                /* only C1 at the yield surface: no FD stencil may cross it. A step h in one entry
                   moves the log strains, hence |dev e|, by at most ~h / s_min: keep 20x away.
                   Steps below 1e-7 s_min would be all rounding: no FD there (the principal
                   formulas below still check those samples). */
                step = scale * (fabs(dist) / 20 < 1e-4 ? fabs(dist) / 20 : 1e-4);
                t_en_check_sample(&st, &f, dim, F, E, step, fabs(dist) >= 2e-6, &eg, &eh);
                t_en_maxto(&wk_grad[kind], eg);
                t_en_maxto(&wk_hess[kind], eh);
                t_adb(dim, R1, dpsi, R2, Pref);
                if (pn_von_mises_energy(&m, dim, F, h, &psi, P, NULL, 0) == PN_OK) {
                    double nP = t_norm(n2, Pref);
                    t_en_maxto(&st.ref_psi, fabs(psi - psi_ref) / (fabs(psi_ref) + nP * t_norm(n2, F) + 1e-6 * E));
                    t_en_maxto(&st.ref_P, t_dist(n2, P, Pref) / (nP + 1e-6 * E));
                } else
                    st.eval_fail++;
            }
    t_en_finish(pn__t, &st, 1);
    for (kind = 0; kind < 5; ++kind)
        PN_REPORT("  %-13s worst FD grad %.2e, hess %.2e", vm_kind[kind], wk_grad[kind], wk_hess[kind]);
    PN_REPORT("  %ld elastic and %ld plastic samples (sigma_Y0 = 1e-3 E, K = 0 or 0.05 E, from state h)", n_el, n_pl);
    PN_CHECK(n_el > 100 && n_pl > 100);
}

/* The frozen-yield Drucker-Prager energy (pn_dp_energy). Sample F = R1 diag(exp e) R2 with a
   volumetric strain tr e of either sign over 1e-5..1e-1 and a deviator 0.1..10 times the cone's
   radius there. (1) With tau_y prepared at F itself its gradient is T(F) of pn_return_map, the
   independent return-mapping code: apex, cone and inside alike, with cohesion and with a
   volume credit. (2) With tau_y frozen at another point: FD of psi and P, symmetry and the PSD
   projection, with stencils kept 20x away from the two kinks (the cylinder and tr e = 0). */
PN_TEST(energy_dp_frozen_yield) {
    t_en_stats st;
    pn_test_rng rng;
    double worst = 0, worst_lag = -1;
    long n_reg[3] = {0, 0, 0}; /* apex, cone, inside */
    int k, fails = 0;
    memset(&st, 0, sizeof st);
    rng.s = 212;
    for (k = 0; k < 3000; ++k) {
        pn_material_desc d;
        pn_material m;
        t_en_fn f;
        int dim = 2 + (k & 1), n2 = dim * dim, i, variant = (k / 2) % 3;
        double E = t_en_E[k % 3], nu = t_en_nu[(k / 3) % 3], mu = t_mu(E, nu), lam = t_lambda(E, nu);
        double kappa = lam + 2 * mu / dim, alpha, sp, c, h, v, tr, rcone, r, e[3], dir[3], nd = 0, s[3];
        double R1[9], R2[9], F[9], P[9], T[9], Z[9], hn, nT, tau_y, eg, eh, dist, step;
        t_en_desc(&d, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, E, nu);
        d.friction_angle_deg = pn_test_rng_range(&rng, 20, 40);
        d.cohesion_strain = variant == 1 ? 1e-3 : 0;
        d.volume_correction = variant == 2;
        if (!t_en_init(pn__t, &m, &d)) return;
        sp = sin(d.friction_angle_deg * 3.14159265358979323846 / 180); /* docs/method.md: the cone per dimension */
        alpha = dim == 2 ? sp / sqrt(2.0) : sqrt(2.0 / 3.0) * 2 * sp / (3 - sp);
        c = d.cohesion_strain;
        h = variant == 2 ? pn_test_rng_range(&rng, 0, 1e-3) : 0;
        v = variant == 2 ? h : 0;
        /* shifted strain e - c + v/d has trace tr (30% on the apex side) and deviator r */
        tr = pow(10.0, pn_test_rng_range(&rng, -5, -1)) * (pn_test_rng_range(&rng, 0, 1) < 0.3 ? 1 : -1);
        rcone = tr < 0 ? -dim * kappa * alpha * tr / (2 * mu) : 1e-3 * fabs(tr);
        r = rcone * pow(10.0, pn_test_rng_range(&rng, -1, 1));
        for (i = 0; i < dim; ++i) nd += (dir[i] = pn_test_rng_range(&rng, -1, 1));
        for (i = 0; i < dim; ++i) dir[i] -= nd / dim;
        nd = 0;
        for (i = 0; i < dim; ++i) nd += dir[i] * dir[i];
        nd = sqrt(nd);
        for (i = 0; i < dim; ++i) {
            e[i] = tr / dim + r * dir[i] / nd;
            s[i] = exp(e[i] + c - v / dim);
        }
        t_rand_rot(&rng, dim, R1);
        t_rand_rot(&rng, dim, R2);
        t_adb(dim, R1, s, R2, F);
        /* (1) tau_y at F: the gradient is the return-mapped force */
        if (pn_dp_prepare(&m, dim, F, h, &tau_y) != PN_OK || pn_dp_energy(&m, dim, F, h, tau_y, NULL, P, NULL, 0) != PN_OK ||
            pn_return_map(&m, dim, F, h, Z, &hn, T) != PN_OK) {
            ++fails;
            continue;
        }
        n_reg[tr >= 0 ? 0 : r > rcone ? 1 : 2]++;
        nT = t_norm(n2, T);
        t_en_maxto(&worst, t_dist(n2, P, T) / (nT > 1e-9 * E ? nT : 1e-9 * E));
        /* (2) frozen at a point of another volumetric strain: FD away from the kinks */
        tau_y *= pn_test_rng_range(&rng, 0.5, 2);
        if (tr >= 0 && k % 4 == 0) tau_y = dim * kappa * alpha * 1e-3; /* apex with a stale cone */
        {   /* the force error is the friction lag: |P - T| <= |tau_y - tau_y(F)| / s_min, and
               |tau_y - tau_y(F)| <= d kappa alpha |tr e0 - tr e| for tau_y = -d kappa alpha tr e0 */
            double smin = s[0], lag;
            for (i = 1; i < dim; ++i) smin = s[i] < smin ? s[i] : smin;
            lag = fabs(tau_y - (tr < 0 ? -dim * kappa * alpha * tr : 0)) / smin;
            if (pn_dp_energy(&m, dim, F, h, tau_y, NULL, P, NULL, 0) != PN_OK) ++fails;
            else t_en_maxto(&worst_lag, (t_dist(n2, P, T) - lag) / (nT > 1e-9 * E ? nT : 1e-9 * E));
        }
        f.kind = T_EN_DP;
        f.m = &m;
        f.h = h;
        f.G = NULL;
        f.tau_y = tau_y;
        dist = fabs(2 * mu * r - tau_y) / (2 * mu);
        if (fabs(tr) < dist) dist = fabs(tr);
        step = dist / 20 < 1e-4 ? dist / 20 : 1e-4;
        t_en_check_sample(&st, &f, dim, F, E * (fabs(tr) + r), step, dist >= 2e-6, &eg, &eh);
    }
    PN_REPORT("tau_y at F: |P - T| / max(|T|, 1e-9 E) worst %.2e over %ld apex, %ld cone, %ld inside samples",
              worst, n_reg[0], n_reg[1], n_reg[2]);
    PN_REPORT("tau_y frozen elsewhere: worst (|P - T| - lag bound) / |T| %.2e", worst_lag);
    t_en_finish(pn__t, &st, 0);
    PN_CHECK(fails == 0);
    PN_CHECK_LE(worst_lag, 1e-9);
    PN_CHECK(n_reg[0] > 300 && n_reg[1] > 300 && n_reg[2] > 300);
    PN_CHECK_LE(worst, 1e-8);
    {   /* contract: another material is refused, a bad tau_y too, outputs untouched */
        pn_material_desc d;
        pn_material vm, sand;
        double F[4] = {1.01, 0.002, 0, 0.98}, P[4] = {7, 7, 7, 7}, psi = 7, ty = 0;
        t_en_desc(&d, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_VON_MISES, 1e7, 0.3);
        d.yield_stress_pa = 1e4;
        if (!t_en_init(pn__t, &vm, &d)) return;
        t_en_desc(&d, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e7, 0.3);
        d.friction_angle_deg = 30;
        if (!t_en_init(pn__t, &sand, &d)) return;
        PN_CHECK(pn_dp_prepare(&vm, 2, F, 0, &ty) == PN_ERROR_UNSUPPORTED);
        PN_CHECK(pn_dp_energy(&vm, 2, F, 0, 1e4, &psi, P, NULL, 0) == PN_ERROR_UNSUPPORTED);
        PN_CHECK(pn_dp_energy(&sand, 2, F, 0, -1, &psi, P, NULL, 0) == PN_ERROR_INVALID_ARGUMENT);
        PN_CHECK(pn_dp_energy(&sand, 2, F, 0, NAN, &psi, P, NULL, 0) == PN_ERROR_INVALID_ARGUMENT);
        PN_CHECK(pn_dp_energy(&sand, 4, F, 0, 1e4, &psi, P, NULL, 0) == PN_ERROR_DIMENSION);
        PN_CHECK(psi == 7 && P[0] == 7 && P[3] == 7 && ty == 0);
    }
}

/* The energy's gradient is the return-mapped force density T of pn_return_map, with and
   without hardening (K = 0 or 0.05 E): the energy is the return mapping's potential. */
PN_TEST(energy_von_mises_matches_return_map) {
    pn_test_rng rng;
    double worst = 0;
    int k, fails = 0;
    long n_el = 0, n_pl = 0;
    rng.s = 207;
    for (k = 0; k < 4000; ++k) {
        pn_material_desc d;
        pn_material m;
        int dim = 2 + (k & 1), n2 = dim * dim;
        double E = t_en_E[k % 3], nu = t_en_nu[(k / 3) % 3], mu = t_mu(E, nu), K = (k / 2) & 1 ? 0.05 * E : 0;
        double s[3], R1[9], R2[9], F[9], P[9], T[9], Z[9], h = pn_test_rng_range(&rng, 0, 0.3), hn, nT;
        double tauY = sqrt(2.0 / 3.0) * (1e-3 * E + K * h), psi_ref, dpsi[3];
        t_en_desc(&d, PN_ELASTIC_DEFAULT, PN_PLASTIC_VON_MISES, E, nu);
        d.yield_stress_pa = 1e-3 * E, d.hardening_modulus_pa = K;
        if (!t_en_init(pn__t, &m, &d)) return;
        t_en_vm_sample(&rng, dim, (k / 4) % 5, tauY / (2 * mu), s, R1, R2, F);
        if (t_en_ref_vm(mu, t_lambda(E, nu), tauY, 2 * K / 3, dim, s, &psi_ref, dpsi) <= 0) ++n_el; else ++n_pl;
        if (pn_von_mises_energy(&m, dim, F, h, NULL, P, NULL, 0) != PN_OK ||
            pn_return_map(&m, dim, F, h, Z, &hn, T) != PN_OK) {
            ++fails;
            continue;
        }
        nT = t_norm(n2, T);
        t_en_maxto(&worst, t_dist(n2, P, T) / (nT > 1e-6 * E ? nT : 1e-6 * E));
    }
    PN_REPORT("%ld elastic, %ld plastic F (K = 0 and 0.05 E): |P - T| / max(|T|, 1e-6 E) worst %.2e", n_el, n_pl, worst);
    PN_CHECK(fails == 0);
    PN_CHECK(n_el > 100 && n_pl > 100);
    PN_CHECK_LE(worst, 1e-8);
}

/* F0 = R1 diag(exp(e0)) R2 with e0 of random size; F near it (as in the PlasticityNet loss). */
static void t_en_lagged_pair(pn_test_rng *rng, int dim, int which, double *F0, double *F, int variant) {
    static const double size[3] = {0.005, 0.05, 0.3};
    double e0[3], s[3], R1[9], R2[9], c = size[t_randint(rng, 3)], de = which >= T_EN_CAMCLAY ? 0.2 : 0.1;
    int i;
    for (i = 0; i < 3; ++i) {
        e0[i] = i < dim ? c * pn_test_rng_range(rng, -1, 1) : 0;
        s[i] = exp(e0[i]);
    }
    t_rand_rot(rng, dim, R1);
    t_rand_rot(rng, dim, R2);
    t_adb(dim, R1, s, R2, F0);
    if (variant == 0) { /* F = F0 */
        memcpy(F, F0, sizeof(double) * 9);
    } else if (variant == 1) { /* F = R3 diag(exp(e0 + de)) R4 */
        for (i = 0; i < dim; ++i) s[i] = exp(e0[i] + de * pn_test_rng_range(rng, -1, 1));
        t_rand_rot(rng, dim, R1);
        t_rand_rot(rng, dim, R2);
        t_adb(dim, R1, s, R2, F);
    } else { /* F = F0 (I + small) */
        double A[9];
        for (i = 0; i < 9; ++i) A[i] = 0;
        for (i = 0; i < dim * dim; ++i) A[i] = 0.02 * pn_test_rng_range(rng, -1, 1);
        for (i = 0; i < dim; ++i) A[i * dim + i] += 1;
        t_mul(dim, F0, A, F);
    }
}

static void t_en_run_lagged(pn_test_ctx *pn__t, int which, unsigned long long seed) {
    t_en_stats st;
    pn_test_rng rng;
    int dim, k;
    long outside = 0, inside = 0, prep_fail = 0;
    double wG = 0;
    memset(&st, 0, sizeof st);
    rng.s = seed;
    for (dim = 2; dim <= 3; ++dim)
        for (k = 0; k < 3 * T_EN_NS; ++k) {
            pn_material_desc d;
            pn_material m;
            t_en_fn f;
            double E = t_en_E[k % 3], F0[9], F[9], G[9], Z[9], FG[9], FG0[9], hG = 0, h0, hn, step, eg, eh;
            int n2 = dim * dim;
            t_en_lagged_desc(&d, which, E);
            if (!t_en_init(pn__t, &m, &d)) return;
            h0 = t_en_lagged_h0(&rng, which);
            t_en_lagged_pair(&rng, dim, which, F0, F, 1 + (k & 1));
            if (pn_lagged_prepare(&m, dim, F0, h0, G, &hG) != PN_OK ||
                pn_return_map(&m, dim, F0, h0, Z, &hn, NULL) != PN_OK) {
                ++prep_fail;
                continue;
            }
            if (t_dist(n2, Z, F0) > 1e-12 * t_norm(n2, F0)) ++outside; else ++inside;
            /* G = F0^-1 Z(F0): F0 G = Z */
            t_mul(dim, F0, G, FG0);
            t_en_maxto(&wG, t_dist(n2, FG0, Z) / t_norm(n2, Z));
            f.kind = T_EN_LAGGED;
            f.m = &m;
            f.h = hG;
            f.G = G;
            t_mul(dim, F, G, FG);
            /* a step h in F moves F G by at most h |G| */
            step = 1e-4 * t_en_smin(dim, FG) / t_norm(n2, G);
            if (step > 1e-4) step = 1e-4;
            t_en_check_sample(&st, &f, dim, F, E, step, 1, &eg, &eh);
        }
    t_en_finish(pn__t, &st, 0);
    PN_REPORT("  %s: F0 outside the yield surface %ld, inside %ld; |F0 G - Z(F0)| / |Z| %.2e", t_en_lagged_name[which],
              outside, inside, wG);
    PN_CHECK(prep_fail == 0);
    PN_CHECK(outside > 0 && inside > 0);
    PN_CHECK_LE(wG, 1e-12);
}

PN_TEST(energy_fd_lagged_sand) { t_en_run_lagged(pn__t, T_EN_SAND, 208); }
PN_TEST(energy_fd_lagged_metal) { t_en_run_lagged(pn__t, T_EN_METAL, 209); }
PN_TEST(energy_fd_lagged_camclay) { t_en_run_lagged(pn__t, T_EN_CAMCLAY, 210); }
PN_TEST(energy_fd_lagged_stomakhin) { t_en_run_lagged(pn__t, T_EN_STOMAKHIN, 211); }

/* grad Psi_lag(F0) = T(F0) exactly (PlasticityNet Eq. 8 without a network). */
PN_TEST(energy_lagged_gradient_matches_return_map) {
    pn_test_rng rng;
    double worst[T_EN_NLAGGED], whG = 0;
    long n_out[T_EN_NLAGGED];
    int which, k, fails = 0;
    rng.s = 212;
    for (which = 0; which < T_EN_NLAGGED; ++which) {
        worst[which] = 0;
        n_out[which] = 0;
        for (k = 0; k < 2000; ++k) {
            pn_material_desc d;
            pn_material m;
            int dim = 2 + (k & 1), n2 = dim * dim;
            double E = t_en_E[k % 3], F0[9], F[9], G[9], Z[9], T[9], P[9], hG = 0, hn = 0, h0, nT;
            t_en_lagged_desc(&d, which, E);
            if (!t_en_init(pn__t, &m, &d)) return;
            h0 = t_en_lagged_h0(&rng, which);
            t_en_lagged_pair(&rng, dim, which, F0, F, 0);
            if (pn_lagged_prepare(&m, dim, F0, h0, G, &hG) != PN_OK ||
                pn_return_map(&m, dim, F0, h0, Z, &hn, T) != PN_OK ||
                pn_lagged_energy(&m, dim, F0, G, hG, NULL, P, NULL, 0) != PN_OK) {
                ++fails;
                continue;
            }
            if (t_dist(n2, Z, F0) > 1e-12 * t_norm(n2, F0)) ++n_out[which];
            nT = t_norm(n2, T);
            /* floor 1e-4 E: at the Drucker-Prager tip T = 0 exactly, while F0 G = Z only up to
               rounding, which leaves |P_lag| ~ 1e-15 E */
            t_en_maxto(&worst[which], t_dist(n2, P, T) / (nT > 1e-4 * E ? nT : 1e-4 * E));
            t_en_maxto(&whG, fabs(hG - hn) / (fabs(hn) > 1 ? fabs(hn) : 1));
        }
        PN_REPORT("%-20s |P_lag(F0) - T(F0)| / max(|T|, 1e-4 E) %.2e (%ld of 2000 F0 outside)", t_en_lagged_name[which],
                  worst[which], n_out[which]);
        PN_CHECK_LE(worst[which], 1e-10);
        PN_CHECK(n_out[which] > 0 && n_out[which] < 2000);
    }
    PN_REPORT("h_G against h_new of pn_return_map: %.2e", whG);
    PN_CHECK(fails == 0);
    PN_CHECK_LE(whG, 1e-14);
}

/* Objectivity psi(QF) = psi(F), P(QF) = Q P(F), dP/dF rotated alike; isotropy
   psi(FQ) = psi(F), P(FQ) = P(F) Q (not for the lagged energy: G is not isotropic). */
PN_TEST(energy_rotation_invariance) {
    pn_test_rng rng;
    double wpsi = 0, wP = 0, wH = 0;
    int c, k, fails = 0;
    rng.s = 213;
    for (c = 0; c < 7; ++c)
        for (k = 0; k < 400; ++k) {
            pn_material_desc d;
            pn_material m;
            t_en_fn f;
            int dim = 2 + (k & 1), n2 = dim * dim, side, i, j, kk, l, a, b;
            double E = t_en_E[k % 3], s[3], R1[9], R2[9], F[9], Q[9], QF[9], G[9], hG = 0;
            double psi = 0, P[9], H[81], psi2 = 0, P2[9], H2[81], Pt[9], Ht[81], nP, nH;
            f.kind = T_EN_ELASTIC;
            f.h = 0;
            f.G = NULL;
            if (c < 4) {
                t_en_desc(&d, (pn_elastic_model)(PN_ELASTIC_FIXED_COROTATED + c), PN_PLASTIC_NONE, E, 0.3);
            } else if (c == 4) {
                t_en_lagged_desc(&d, T_EN_METAL, E);
                f.kind = T_EN_VM;
                f.h = 0.05;
            } else
                t_en_lagged_desc(&d, c == 5 ? T_EN_SAND : T_EN_CAMCLAY, E);
            if (!t_en_init(pn__t, &m, &d)) return;
            f.m = &m;
            t_en_sample(&rng, dim, (c == 0 && (k & 2)) ? T_EN_INVERTED : T_EN_STRETCH, s, R1, R2, F);
            if (c >= 5) {
                double F0[9];
                t_en_lagged_pair(&rng, dim, c == 5 ? T_EN_SAND : T_EN_CAMCLAY, F0, F, 1);
                if (pn_lagged_prepare(&m, dim, F0, c == 5 ? 0 : -0.05, G, &hG) != PN_OK) {
                    ++fails;
                    continue;
                }
                f.kind = T_EN_LAGGED;
                f.G = G;
                f.h = hG;
            }
            t_rand_rot(&rng, dim, Q);
            if (t_en_eval(&f, dim, F, &psi, P, H, 0) != PN_OK) {
                ++fails;
                continue;
            }
            for (side = 0; side < (c >= 5 ? 1 : 2); ++side) {
                if (side == 0)
                    t_mul(dim, Q, F, QF);
                else
                    t_mul(dim, F, Q, QF);
                if (t_en_eval(&f, dim, QF, &psi2, P2, H2, 0) != PN_OK) {
                    ++fails;
                    continue;
                }
                if (side == 0)
                    t_mul(dim, Q, P, Pt);
                else
                    t_mul(dim, P, Q, Pt);
                for (i = 0; i < dim; ++i)
                    for (j = 0; j < dim; ++j)
                        for (kk = 0; kk < dim; ++kk)
                            for (l = 0; l < dim; ++l) {
                                double acc = 0;
                                for (a = 0; a < dim; ++a)
                                    for (b = 0; b < dim; ++b)
                                        acc += side == 0 ? Q[i * dim + a] * Q[kk * dim + b] * H[(a * dim + j) * n2 + b * dim + l]
                                                         : H[(i * dim + a) * n2 + kk * dim + b] * Q[a * dim + j] * Q[b * dim + l];
                                Ht[(i * dim + j) * n2 + kk * dim + l] = acc;
                            }
                nP = t_norm(n2, P);
                nH = t_norm(n2 * n2, H);
                t_en_maxto(&wpsi, fabs(psi2 - psi) / (fabs(psi) + 1e-8 * E));
                t_en_maxto(&wP, t_dist(n2, P2, Pt) / (nP + 1e-8 * E));
                t_en_maxto(&wH, t_dist(n2 * n2, H2, Ht) / (nH + 1e-8 * E));
            }
        }
    PN_REPORT("4 elastic models, von Mises energy, lagged sand/snow (left only): psi %.2e, P %.2e, dP/dF %.2e",
              wpsi, wP, wH);
    PN_CHECK(fails == 0);
    PN_CHECK_LE(wpsi, 1e-11);
    PN_CHECK_LE(wP, 1e-11);
    PN_CHECK_LE(wH, 1e-10);
}

/* Each output is optional and does not depend on which others are requested. */
PN_TEST(energy_optional_outputs) {
    pn_test_rng rng;
    double worst = 0;
    int c, k, fails = 0;
    rng.s = 214;
    for (c = 0; c < 6; ++c)
        for (k = 0; k < 100; ++k) {
            pn_material_desc d;
            pn_material m;
            t_en_fn f;
            int dim = 2 + (k & 1), n2 = dim * dim;
            double E = 1e6, s[3], R1[9], R2[9], F[9], G[9], hG = 0;
            double psi = 0, P[9], H[81], psi1 = 0, P1[9], H1[81], Hp[81], Hp1[81];
            f.kind = T_EN_ELASTIC;
            f.h = 0;
            f.G = NULL;
            if (c < 4)
                t_en_desc(&d, (pn_elastic_model)(PN_ELASTIC_FIXED_COROTATED + c), PN_PLASTIC_NONE, E, 0.3);
            else
                t_en_lagged_desc(&d, c == 4 ? T_EN_METAL : T_EN_STOMAKHIN, E);
            if (!t_en_init(pn__t, &m, &d)) return;
            f.m = &m;
            t_en_sample(&rng, dim, T_EN_STRETCH, s, R1, R2, F);
            if (c == 4) {
                f.kind = T_EN_VM;
                f.h = 0.1;
            } else if (c == 5) {
                if (pn_lagged_prepare(&m, dim, F, 0.05, G, &hG) != PN_OK) {
                    ++fails;
                    continue;
                }
                f.kind = T_EN_LAGGED;
                f.G = G;
                f.h = hG;
                F[0] += 0.01;
            }
            fails += t_en_eval(&f, dim, F, &psi, P, H, 0) != PN_OK;
            fails += t_en_eval(&f, dim, F, &psi1, NULL, NULL, 0) != PN_OK;
            fails += t_en_eval(&f, dim, F, NULL, P1, NULL, 0) != PN_OK;
            fails += t_en_eval(&f, dim, F, NULL, NULL, H1, 0) != PN_OK;
            fails += t_en_eval(&f, dim, F, NULL, NULL, Hp, PN_EVAL_PROJECT_PSD) != PN_OK;
            fails += t_en_eval(&f, dim, F, &psi1, P1, Hp1, PN_EVAL_PROJECT_PSD) != PN_OK;
            t_en_maxto(&worst, fabs(psi1 - psi) / (fabs(psi) + 1e-12 * E));
            t_en_maxto(&worst, t_dist(n2, P1, P) / (t_norm(n2, P) + 1e-12 * E));
            t_en_maxto(&worst, t_dist(n2 * n2, H1, H) / t_norm(n2 * n2, H));
            t_en_maxto(&worst, t_dist(n2 * n2, Hp1, Hp) / t_norm(n2 * n2, H));
        }
    PN_REPORT("psi / P / dP/dF requested alone or together: worst relative difference %.2e", worst);
    PN_CHECK(fails == 0);
    PN_CHECK_LE(worst, 1e-14);
}

/* det F <= 0: PN_ERROR_INVERTED with outputs untouched wherever the model is undefined;
   fixed corotated stays defined. */
PN_TEST(energy_inverted_rejected) {
    pn_test_rng rng;
    int c, k, bad = 0, n = 0, fc_bad = 0, unsup_bad = 0;
    rng.s = 215;
    for (c = 0; c < 8; ++c)
        for (k = 0; k < 200; ++k) {
            pn_material_desc d;
            pn_material m;
            t_en_fn f;
            int dim = 2 + (k & 1), i;
            double E = 1e6, F[9], G[9], hG = 0, psi = 4.5, P[9], H[81], kP[9], kH[81], F0[9];
            pn_result r;
            f.kind = T_EN_ELASTIC;
            f.h = 0;
            f.G = NULL;
            if (c < 4)
                t_en_desc(&d, (pn_elastic_model)(PN_ELASTIC_FIXED_COROTATED + c), PN_PLASTIC_NONE, E, 0.3);
            else
                t_en_lagged_desc(&d, c == 4 ? T_EN_METAL : c - 5, E); /* metal; lagged sand, metal, snow */
            if (!t_en_init(pn__t, &m, &d)) return;
            f.m = &m;
            if (c == 4) f.kind = T_EN_VM;
            if (c >= 5) { /* a regular F0, so G is fine and F G is inverted */
                t_en_lagged_pair(&rng, dim, c - 5, F0, F, 0);
                if (pn_lagged_prepare(&m, dim, F0, c == 7 ? -0.05 : 0, G, &hG) != PN_OK) {
                    ++bad;
                    continue;
                }
                f.kind = T_EN_LAGGED;
                f.G = G;
                f.h = hG;
            }
            if (k % 4 == 0 && c < 5) { /* exactly singular (integer entries: det is exactly 0) */
                for (i = 0; i < 9; ++i) F[i] = (double)((i * 7) % 5) - 2;
                for (i = 0; i < dim; ++i) F[(dim - 1) * dim + i] = 2 * F[i]; /* last row = 2 x first */
                if (k % 8 == 0)
                    for (i = 0; i < dim; ++i) F[(dim - 1) * dim + i] = 0;
            } else {
                do {
                    for (i = 0; i < dim * dim; ++i) F[i] = pn_test_rng_range(&rng, -2, 2);
                } while (!(t_det(dim, F) < -1e-3));
            }
            for (i = 0; i < 9; ++i) kP[i] = P[i] = 1.5 * i;
            for (i = 0; i < 81; ++i) kH[i] = H[i] = -0.5 * i;
            r = t_en_eval(&f, dim, F, &psi, P, H, 0);
            ++n;
            if (c == 0) { /* fixed corotated: defined */
                if (r != PN_OK || !t_finite(1, &psi) || !t_finite(dim * dim, P) ||
                    (k % 4 != 0 && !t_finite(dim * dim * dim * dim, H)))
                    ++fc_bad;
            } else if (r != PN_ERROR_INVERTED || psi != 4.5 || memcmp(P, kP, sizeof P) || memcmp(H, kH, sizeof H)) {
                ++bad;
                if (bad <= 3) fprintf(stderr, "      case %d (dim %d, det %g): result %d\n", c, dim, t_det(dim, F), (int)r);
            }
        }
    /* the exact von Mises energy needs a von Mises material with StVK-Hencky elasticity */
    {
        pn_material_desc d;
        pn_material m;
        double F[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, psi = 2.5, P[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
        t_en_lagged_desc(&d, T_EN_SAND, 1e6);
        if (t_en_init(pn__t, &m, &d) && (pn_von_mises_energy(&m, 3, F, 0, &psi, P, NULL, 0) != PN_ERROR_UNSUPPORTED || psi != 2.5))
            ++unsup_bad;
        t_en_lagged_desc(&d, T_EN_METAL, 1e6);
        d.elastic = PN_ELASTIC_NEO_HOOKEAN;
        if (t_en_init(pn__t, &m, &d) && (pn_von_mises_energy(&m, 3, F, 0, &psi, P, NULL, 0) != PN_ERROR_UNSUPPORTED || psi != 2.5))
            ++unsup_bad;
    }
    PN_REPORT("%d inverted or singular F: %d not rejected cleanly, %d fixed-corotated failures, "
              "%d unsupported-material misses", n, bad, fc_bad, unsup_bad);
    PN_CHECK(bad == 0);
    PN_CHECK(fc_bad == 0);
    PN_CHECK(unsup_bad == 0);
}

/* NaN/inf in F, G or a state that matters: PN_ERROR_NONFINITE, outputs untouched. */
PN_TEST(energy_nonfinite_rejected) {
    const double badv[3] = {NAN, HUGE_VAL, -HUGE_VAL};
    int c, dim, pos, b, tried = 0, fails = 0;
    for (c = 0; c < 10; ++c)
        for (dim = 2; dim <= 3; ++dim)
            for (pos = -1; pos < dim * dim; ++pos)
                for (b = 0; b < 3; ++b) {
                    pn_material_desc d;
                    pn_material m;
                    t_en_fn f;
                    double F[9] = {1.1, 0.1, 0.0, -0.1, 0.9, 0.05, 0.02, 0.0, 1.05}, G[9], hG = 0, kG[9];
                    if (dim == 2) F[2] = -0.1, F[3] = 0.9; /* [1.1 0.1; -0.1 0.9] */
                    double psi = 7.5, P[9], H[81], kP[9], kH[81], khG;
                    int i, target = 0; /* 0: F, 1: G, 2: h, 3: lagged_prepare F0, 4: prepare h0 */
                    pn_result r;
                    f.kind = T_EN_ELASTIC;
                    f.h = 0;
                    f.G = NULL;
                    if (c < 4)
                        t_en_desc(&d, (pn_elastic_model)(PN_ELASTIC_FIXED_COROTATED + c), PN_PLASTIC_NONE, 1e6, 0.3);
                    else if (c == 4) /* Stomakhin: h scales the Lame constants */
                        t_en_lagged_desc(&d, T_EN_STOMAKHIN, 1e6);
                    else if (c == 5) /* von Mises energy, K > 0: h sets the yield stress */
                        t_en_lagged_desc(&d, T_EN_METAL, 1e6);
                    else
                        t_en_lagged_desc(&d, c - 6, 1e6);
                    if (!t_en_init(pn__t, &m, &d)) return;
                    f.m = &m;
                    if (c == 5) f.kind = T_EN_VM;
                    if (c >= 6) {
                        double F0[9];
                        memcpy(F0, F, sizeof F);
                        if (pn_lagged_prepare(&m, dim, F0, c == 8 ? -0.05 : 0, G, &hG) != PN_OK) {
                            ++fails;
                            continue;
                        }
                        f.kind = T_EN_LAGGED;
                        f.G = G;
                        f.h = hG;
                    }
                    if (pos < 0) { /* a bad state (where it matters) or the prepare inputs */
                        if (c == 4 || c == 5) {
                            f.h = badv[b];
                            target = 2;
                        } else if (c >= 6) {
                            target = 3;
                        } else
                            continue;
                    } else if (c >= 6 && b == 0 && (pos & 1)) {
                        target = 1; /* NaN in G */
                        G[pos] = badv[b];
                    } else
                        F[pos] = badv[b];
                    for (i = 0; i < 9; ++i) kP[i] = P[i] = 3.25 * i;
                    for (i = 0; i < 81; ++i) kH[i] = H[i] = -0.75 * i;
                    ++tried;
                    if (target == 3) {
                        /* pn_lagged_prepare with NaN/inf in F0 (b) and in h0 for the snow state */
                        double F0[9];
                        for (i = 0; i < 9; ++i) kG[i] = G[i] = 9.5 + i;
                        khG = hG = 0.125;
                        memcpy(F0, F, sizeof F);
                        F0[b % (dim * dim)] = badv[b];
                        r = pn_lagged_prepare(&m, dim, F0, 0, G, &hG);
                        if (r != PN_ERROR_NONFINITE || memcmp(G, kG, sizeof G) || hG != khG) {
                            ++fails;
                            fprintf(stderr, "      lagged_prepare %s F0[%d] = %g: result %d\n", t_en_lagged_name[c - 6],
                                    b % (dim * dim), badv[b], (int)r);
                        }
                        if (c == 7 || c == 8 || c == 9) { /* h0 matters for metal, snow */
                            ++tried;
                            r = pn_lagged_prepare(&m, dim, F, badv[b], G, &hG);
                            if (r != PN_ERROR_NONFINITE || memcmp(G, kG, sizeof G) || hG != khG) {
                                ++fails;
                                fprintf(stderr, "      lagged_prepare %s h0 = %g: result %d\n", t_en_lagged_name[c - 6],
                                        badv[b], (int)r);
                            }
                        }
                        continue;
                    }
                    r = t_en_eval(&f, dim, F, &psi, P, H, 0);
                    if (r != PN_ERROR_NONFINITE || psi != 7.5 || memcmp(P, kP, sizeof P) || memcmp(H, kH, sizeof H)) {
                        ++fails;
                        fprintf(stderr, "      evaluator %d dim %d, bad value %g in %s[%d]: result %d\n", c, dim, badv[b],
                                target == 0 ? "F" : target == 1 ? "G" : "h", pos, (int)r);
                    }
                }
    PN_REPORT("%d calls with NaN/inf input, %d not rejected with outputs untouched", tried, fails);
    PN_CHECK(fails == 0);
}

static const pn_test_case pn_tests_energy[] = {
    {"energy_material_lame", energy_material_lame},
    {"energy_rest_state", energy_rest_state},
    {"energy_fd_fixed_corotated", energy_fd_fixed_corotated},
    {"energy_fd_stvk_hencky", energy_fd_stvk_hencky},
    {"energy_fd_neo_hookean", energy_fd_neo_hookean},
    {"energy_fd_neo_hookean_snow", energy_fd_neo_hookean_snow},
    {"energy_stomakhin_hardening", energy_stomakhin_hardening},
    {"energy_fd_von_mises", energy_fd_von_mises},
    {"energy_von_mises_matches_return_map", energy_von_mises_matches_return_map},
    {"energy_dp_frozen_yield", energy_dp_frozen_yield},
    {"energy_fd_lagged_sand", energy_fd_lagged_sand},
    {"energy_fd_lagged_metal", energy_fd_lagged_metal},
    {"energy_fd_lagged_camclay", energy_fd_lagged_camclay},
    {"energy_fd_lagged_stomakhin", energy_fd_lagged_stomakhin},
    {"energy_lagged_gradient_matches_return_map", energy_lagged_gradient_matches_return_map},
    {"energy_rotation_invariance", energy_rotation_invariance},
    {"energy_optional_outputs", energy_optional_outputs},
    {"energy_inverted_rejected", energy_inverted_rejected},
    {"energy_nonfinite_rejected", energy_nonfinite_rejected},
};
