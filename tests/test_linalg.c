/* test_linalg.c - SVD, polar decomposition, Hencky strain, symmetric eigen-decomposition, PSD
   projection and the small-matrix helpers of plastinet.h.

   #included by test_main.c after plastinet.h (with PLASTINET_IMPLEMENTATION) and pn_test.h;
   defines pn_tests_linalg. Every expected value comes from an independent source: matrices are
   built as R1 diag(s) R2 from known factors, and the reference eigen-solver, determinant,
   matrix exponential and PSD characterisation below are written here, not taken from the
   library. The helpers shared with the other test files (products, norm, determinant, random
   rotations, the Jacobi solver) are in test_util.h; those of this file carry the t_la_ prefix
   (one translation unit is shared with the other test files). */


#define T_LA_N 100000  /* random cases per kind and dimension (the issue asks for 1e5)      */
#define T_LA_TOL 1e-12 /* relative tolerance of reconstruction, orthogonality, ...         */

/* ---- small dense helpers (n x n row-major, n <= 12; the shared ones are in test_util.h) ---- */

/* |A^T A - I| */
static double t_la_orth_err(int n, const double *A) {
    double C[144];
    int i;
    t_mul_tn(n, A, A, C);
    for (i = 0; i < n; ++i) C[i * n + i] -= 1.0;
    return t_norm(n * n, C);
}
/* Inverse by the adjugate (cofactor transpose) / det. */
static void t_la_adj_inverse(int dim, const double *A, double *Ai) {
    double d = t_det(dim, A);
    if (dim == 2) {
        Ai[0] = A[3] / d;
        Ai[1] = -A[1] / d;
        Ai[2] = -A[2] / d;
        Ai[3] = A[0] / d;
        return;
    }
    Ai[0] = (A[4] * A[8] - A[5] * A[7]) / d;
    Ai[1] = -(A[1] * A[8] - A[2] * A[7]) / d;
    Ai[2] = (A[1] * A[5] - A[2] * A[4]) / d;
    Ai[3] = -(A[3] * A[8] - A[5] * A[6]) / d;
    Ai[4] = (A[0] * A[8] - A[2] * A[6]) / d;
    Ai[5] = -(A[0] * A[5] - A[2] * A[3]) / d;
    Ai[6] = (A[3] * A[7] - A[4] * A[6]) / d;
    Ai[7] = -(A[0] * A[7] - A[1] * A[6]) / d;
    Ai[8] = (A[0] * A[4] - A[1] * A[3]) / d;
}

/* ---- random factors -------------------------------------------------------------------------- */

/* Rotation about a unit axis (x, y, z) by angle a (Rodrigues). */
static void t_la_axis_angle(double x, double y, double z, double a, double *R) {
    double c = cos(a), s = sin(a), t = 1 - c;
    R[0] = c + x * x * t;     R[1] = x * y * t - z * s; R[2] = x * z * t + y * s;
    R[3] = y * x * t + z * s; R[4] = c + y * y * t;     R[5] = y * z * t - x * s;
    R[6] = z * x * t - y * s; R[7] = z * y * t + x * s; R[8] = c + z * z * t;
}
/* Random n x n orthogonal matrix: a product of n Householder reflections. */
static void t_la_rand_orth(pn_test_rng *r, int n, double *Q) {
    int i, j, k;
    for (i = 0; i < n * n; ++i) Q[i] = 0;
    for (i = 0; i < n; ++i) Q[i * n + i] = 1;
    for (k = 0; k < n; ++k) {
        double v[12], vv = 0, Qv[12];
        for (i = 0; i < n; ++i) {
            v[i] = t_gauss(r);
            vv += v[i] * v[i];
        }
        if (vv == 0) continue;
        for (i = 0; i < n; ++i) {
            Qv[i] = 0;
            for (j = 0; j < n; ++j) Qv[i] += Q[i * n + j] * v[j];
        }
        for (i = 0; i < n; ++i)
            for (j = 0; j < n; ++j) Q[i * n + j] -= 2.0 * Qv[i] * v[j] / vv;
    }
}

/* ---- reference symmetric eigen-solver (cyclic Jacobi, independent of pn_sym_eigen) -------- */

/* A (n x n symmetric, n <= 12) = Q diag(w) Q^T, w ascending, Q columns eigenvectors: t_jacobi,
   then sorted. */
static void t_la_jacobi(int n, const double *A_in, double *Q, double *w) {
    int i, j;
    t_jacobi(n, A_in, Q, w);
    for (i = 1; i < n; ++i) { /* insertion sort, ascending, columns follow */
        for (j = i; j > 0 && w[j - 1] > w[j]; --j) {
            double tw = w[j];
            int k;
            w[j] = w[j - 1];
            w[j - 1] = tw;
            for (k = 0; k < n; ++k) {
                double tq = Q[k * n + j];
                Q[k * n + j] = Q[k * n + j - 1];
                Q[k * n + j - 1] = tq;
            }
        }
    }
}

/* ---- case checker: SVD, polar, Hencky of one F ------------------------------------------- */

enum {
    T_LA_M_STATUS,  /* wrong result code of svd/polar                                 */
    T_LA_M_RECON,   /* |U diag(s) V^T - F| / |F|                                      */
    T_LA_M_ORTH,    /* |U^T U - I|, |V^T V - I|                                       */
    T_LA_M_DET,     /* |det U - 1|, |det V - 1|                                       */
    T_LA_M_ORDER,   /* |s_i| ordering or a negative s_i before the last (count)        */
    T_LA_M_SIGN,    /* last s negative iff det F < 0 (count, clear cases only)         */
    T_LA_M_SV,      /* singular values against the constructed ones, / |F|            */
    T_LA_M_PRECON,  /* |R S - F| / |F|                                                */
    T_LA_M_PORTH,   /* |R^T R - I|, |det R - 1|                                       */
    T_LA_M_PSYM,    /* |S - S^T| / |F|                                                */
    T_LA_M_PEIG,    /* eigenvalues of S = signed singular values, / |F|               */
    T_LA_M_PROT,    /* R = R1 R2 for well-conditioned positive constructions          */
    T_LA_M_HSTATUS, /* Hencky: wrong code, output touched on error, non-finite on OK  */
    T_LA_M_HEXP,    /* |exp(2 eps) - F F^T| / |F F^T| / max(1, 2 |eps|)               */
    T_LA_M_HREF,    /* |eps - R1 diag(log|s|) R1^T| / max(1, |eps|)                   */
    T_LA_M_COUNT
};
static const char *const t_la_metric_name[T_LA_M_COUNT] = {
    "status",       "svd recon",  "svd orth",     "svd det",      "svd order",
    "svd sign",     "svd values", "polar recon",  "polar orth",   "polar sym",
    "polar eig(S)", "polar R",    "hencky code",  "hencky exp",   "hencky ref"};
static const double t_la_metric_tol[T_LA_M_COUNT] = {
    0, T_LA_TOL, T_LA_TOL, T_LA_TOL, 0, 0, T_LA_TOL, T_LA_TOL,
    T_LA_TOL, T_LA_TOL, T_LA_TOL, T_LA_TOL, 0, T_LA_TOL, T_LA_TOL};

typedef struct t_la_stats {
    double worst[T_LA_M_COUNT];
    long bad[T_LA_M_COUNT];      /* cases over the tolerance */
    double worst_F[T_LA_M_COUNT][9];
    int worst_dim[T_LA_M_COUNT];
    long cases, hencky_ok, hencky_inverted;
} t_la_stats;

static void t_la_stats_init(t_la_stats *st) { memset(st, 0, sizeof *st); }

static void t_la_note(t_la_stats *st, int m, double v, int dim, const double *F) {
    if (!(v <= t_la_metric_tol[m])) st->bad[m]++;
    if (!(v <= st->worst[m])) { /* also records NaN */
        if (st->worst[m] != st->worst[m]) return; /* keep the first NaN */
        st->worst[m] = v;
        st->worst_dim[m] = dim;
        memcpy(st->worst_F[m], F, sizeof(double) * (size_t)(dim * dim));
    }
}

/* Checks on one case. With con != 0, F was built as R1 diag(sc) R2 (R1, R2 rotations, sc signed).
   heavy: also run the checks that need the reference eigen-solver. */
static void t_la_check_case(t_la_stats *st, int dim, const double *F, int con, const double *sc,
                            const double *R1, const double *R2, int heavy) {
    double U[9], V[9], s[3], R[9], S[9], eps[9], T[9], T2[9], a[3], nF, w[3], Q[9];
    double sentinel[9], detF, a2[3];
    int i, j, detsign = 0, sign_clear = 0, posdef_con = 0;
    pn_result r;
    const int n2 = dim * dim;
    st->cases++;
    nF = t_norm(n2, F);

    /* expected |singular values|, descending, and the sign of det F */
    if (con) {
        double mn = HUGE_VAL, mx = 0;
        detsign = 1;
        for (i = 0; i < dim; ++i) {
            a[i] = fabs(sc[i]);
            if (sc[i] < 0) detsign = -detsign;
            if (sc[i] == 0) detsign = 0;
            if (a[i] < mn) mn = a[i];
            if (a[i] > mx) mx = a[i];
        }
        for (i = 1; i < dim; ++i)
            for (j = i; j > 0 && a[j - 1] < a[j]; --j) {
                double t = a[j];
                a[j] = a[j - 1];
                a[j - 1] = t;
            }
        /* rounding F perturbs the singular values by ~1e-16 |F|: the sign is clear above that */
        sign_clear = detsign != 0 && mn > 1e-10 * mx;
        posdef_con = 1;
        for (i = 0; i < dim; ++i)
            if (!(sc[i] > 0)) posdef_con = 0;
    } else {
        double FtF[9];
        t_mul_tn(dim, F, F, FtF);
        t_la_jacobi(dim, FtF, Q, w);
        for (i = 0; i < dim; ++i) {
            a2[i] = w[dim - 1 - i]; /* squared singular values, descending, accurate to eps |F|^2 */
            a[i] = sqrt(a2[i] > 0 ? a2[i] : 0);
        }
        detF = t_det(dim, F);
        detsign = detF > 0 ? 1 : (detF < 0 ? -1 : 0);
        sign_clear = fabs(detF) > 1e-8 * pow(nF, (double)dim);
    }

    /* ---- SVD ---- */
    r = pn_svd(dim, F, U, s, V);
    t_la_note(st, T_LA_M_STATUS, r == PN_OK ? 0 : 1, dim, F);
    if (r == PN_OK) {
        int order_bad = 0;
        t_adbt(dim, U, s, V, T);
        t_la_note(st, T_LA_M_RECON, nF > 0 ? t_dist(n2, T, F) / nF : t_norm(n2, T), dim, F);
        t_la_note(st, T_LA_M_ORTH, t_la_orth_err(dim, U), dim, F);
        t_la_note(st, T_LA_M_ORTH, t_la_orth_err(dim, V), dim, F);
        t_la_note(st, T_LA_M_DET, fabs(t_det(dim, U) - 1), dim, F);
        t_la_note(st, T_LA_M_DET, fabs(t_det(dim, V) - 1), dim, F);
        for (i = 0; i + 1 < dim; ++i) {
            if (!(fabs(s[i]) >= fabs(s[i + 1]))) order_bad = 1;
            if (!(s[i] >= 0)) order_bad = 1;
        }
        t_la_note(st, T_LA_M_ORDER, order_bad, dim, F);
        if (sign_clear)
            t_la_note(st, T_LA_M_SIGN, (s[dim - 1] < 0) != (detsign < 0) ? 1 : 0, dim, F);
        {
            double e = 0;
            for (i = 0; i < dim; ++i) {
                double d = con ? fabs(fabs(s[i]) - a[i]) : fabs(s[i] * s[i] - a2[i]) / (nF > 0 ? nF : 1);
                if (!(d <= e)) e = d;
            }
            if (nF > 0) e /= nF;
            t_la_note(st, T_LA_M_SV, e, dim, F);
        }
    }

    /* ---- polar ---- */
    r = pn_polar(dim, F, R, S);
    t_la_note(st, T_LA_M_STATUS, r == PN_OK ? 0 : 1, dim, F);
    if (r == PN_OK) {
        t_mul(dim, R, S, T);
        t_la_note(st, T_LA_M_PRECON, nF > 0 ? t_dist(n2, T, F) / nF : t_norm(n2, T), dim, F);
        t_la_note(st, T_LA_M_PORTH, t_la_orth_err(dim, R), dim, F);
        t_la_note(st, T_LA_M_PORTH, fabs(t_det(dim, R) - 1), dim, F);
        t_la_note(st, T_LA_M_PSYM, t_asym(dim, S) / (nF > 0 ? nF : 1), dim, F);
        if (heavy) {
            /* S^2 = F^T F, so the eigenvalues of S are +-s_i; the convention puts the one
               negative sign of an inverted F on the smallest magnitude. */
            double aw[3], e = 0, min_pos = HUGE_VAL, neg_mag = 0;
            int nneg = 0;
            t_la_jacobi(dim, S, Q, w);
            for (i = 0; i < dim; ++i) {
                aw[i] = fabs(w[i]);
                if (w[i] < 0) {
                    ++nneg;
                    neg_mag = -w[i];
                } else if (w[i] < min_pos)
                    min_pos = w[i];
            }
            for (i = 1; i < dim; ++i)
                for (j = i; j > 0 && aw[j - 1] < aw[j]; --j) {
                    double t = aw[j];
                    aw[j] = aw[j - 1];
                    aw[j - 1] = t;
                }
            /* magnitudes; for a raw F, a_i = sqrt(eig(F^T F)) is only accurate to
               eps |F|^2 / a_i, so compare squares there */
            for (i = 0; i < dim; ++i) {
                double d = con ? fabs(aw[i] - a[i]) : fabs(aw[i] * aw[i] - a2[i]) / (nF > 0 ? nF : 1);
                if (!(d <= e)) e = d;
            }
            if (sign_clear) {
                /* det S = det F: one negative eigenvalue iff inverted, the smallest in magnitude */
                if (nneg != (detsign < 0 ? 1 : 0)) e = HUGE_VAL;
                if (nneg == 1 && neg_mag > min_pos + T_LA_TOL * nF) e = HUGE_VAL;
            }
            t_la_note(st, T_LA_M_PEIG, nF > 0 ? e / nF : e, dim, F);
        }
        if (con && posdef_con) {
            /* unique polar factor; its sensitivity is |F| / (s_i + s_j) */
            double minpair = a[dim - 1] + a[dim - 2];
            if (minpair > 1e-3 * a[0]) {
                t_mul(dim, R1, R2, T);
                t_la_note(st, T_LA_M_PROT, t_dist(n2, T, R), dim, F);
            }
        }
    }

    /* ---- Hencky strain ---- */
    for (i = 0; i < 9; ++i) sentinel[i] = eps[i] = -7.25e33 + i;
    r = pn_hencky_strain(dim, F, eps);
    if (sign_clear && detsign < 0) {
        st->hencky_inverted++;
        t_la_note(st, T_LA_M_HSTATUS,
                  (r == PN_ERROR_INVERTED && memcmp(eps, sentinel, sizeof eps) == 0) ? 0 : 1, dim, F);
    } else if (sign_clear && detsign > 0) {
        int fin = t_finite(n2, eps);
        t_la_note(st, T_LA_M_HSTATUS, (r == PN_OK && fin) ? 0 : 1, dim, F);
        if (r == PN_OK && fin) {
            st->hencky_ok++;
            if (heavy) {
                /* exp(2 eps) = F F^T, exponential by our own eigen-decomposition */
                double ew[3], FFt[9];
                t_la_jacobi(dim, eps, Q, w);
                for (i = 0; i < dim; ++i) ew[i] = exp(2 * w[i]);
                t_adbt(dim, Q, ew, Q, T);
                t_mul_nt(dim, F, F, FFt);
                /* an absolute error d in eps is a relative error ~2d in exp(2 eps); both sides
                   round eps at ~1e-16 |eps|, so measure relative to max(1, 2 |eps|) */
                {
                    double wm = 1;
                    for (i = 0; i < dim; ++i)
                        if (2 * fabs(w[i]) > wm) wm = 2 * fabs(w[i]);
                    t_la_note(st, T_LA_M_HEXP, t_dist(n2, T, FFt) / t_norm(n2, FFt) / wm, dim, F);
                }
            }
            if (con && a[0] <= 1e3 * a[dim - 1]) {
                /* F F^T = R1 diag(s^2) R1^T whatever the signs of s */
                double ls[3], ne;
                for (i = 0; i < dim; ++i) ls[i] = log(fabs(sc[i]));
                t_adbt(dim, R1, ls, R1, T2);
                ne = t_norm(n2, T2);
                t_la_note(st, T_LA_M_HREF, t_dist(n2, eps, T2) / (ne > 1 ? ne : 1), dim, F);
            }
        }
    } else {
        /* det F at rounding level: either answer is fine, but never a silent inf/NaN */
        int ok = 1;
        if (r == PN_OK) {
            ok = t_finite(n2, eps);
        } else if (r == PN_ERROR_INVERTED) {
            if (memcmp(eps, sentinel, sizeof eps) != 0) ok = 0;
        } else
            ok = 0;
        t_la_note(st, T_LA_M_HSTATUS, ok ? 0 : 1, dim, F);
    }
}

static void t_la_print_matrix(int dim, const double *F) {
    int i;
    fprintf(stderr, "      F = {");
    for (i = 0; i < dim * dim; ++i) fprintf(stderr, "%s%.17g", i ? ", " : "", F[i]);
    fprintf(stderr, "} (dim %d)\n", dim);
}

/* Report every metric, fail those over tolerance, show the worst input of a failing one. */
static void t_la_finish(pn_test_ctx *pn__t, const t_la_stats *st) {
    int m;
    PN_REPORT("%ld cases; svd recon %.2e, orth %.2e, det %.2e, values %.2e; polar recon %.2e, "
              "orth %.2e, sym %.2e, eig %.2e, R %.2e; hencky exp %.2e, ref %.2e "
              "(%ld ok, %ld inverted)",
              st->cases, st->worst[T_LA_M_RECON], st->worst[T_LA_M_ORTH], st->worst[T_LA_M_DET],
              st->worst[T_LA_M_SV], st->worst[T_LA_M_PRECON], st->worst[T_LA_M_PORTH],
              st->worst[T_LA_M_PSYM], st->worst[T_LA_M_PEIG], st->worst[T_LA_M_PROT],
              st->worst[T_LA_M_HEXP], st->worst[T_LA_M_HREF], st->hencky_ok, st->hencky_inverted);
    for (m = 0; m < T_LA_M_COUNT; ++m) {
        if (st->bad[m] == 0) continue;
        {
            char msg[200];
            snprintf(msg, sizeof msg, "%s: %ld cases over tolerance %.1e, worst %.3e",
                     t_la_metric_name[m], st->bad[m], t_la_metric_tol[m], st->worst[m]);
            pn_test__fail(pn__t, __FILE__, __LINE__, msg);
        }
        t_la_print_matrix(st->worst_dim[m], st->worst_F[m]);
    }
}

/* ---- case generators ------------------------------------------------------------------- */

enum {
    T_LA_GENERIC,
    T_LA_REPEATED,
    T_LA_ZERO,
    T_LA_TINY,
    T_LA_HUGE,
    T_LA_DIAGONAL,
    T_LA_ROTATION,
    T_LA_INVERTED,
    T_LA_EXTREME
};

/* Fill F (and the factors when constructed); returns 1 when F = R1 diag(sc) R2. */
static int t_la_gen(pn_test_rng *rng, int kind, int dim, double *F, double *sc, double *R1,
                    double *R2) {
    int i, v;
    t_rand_rot(rng, dim, R1);
    t_rand_rot(rng, dim, R2);
    for (i = 0; i < 3; ++i) sc[i] = t_logu(rng, 0.1, 10.0);
    switch (kind) {
    case T_LA_GENERIC:
        v = t_randint(rng, 4);
        if (v == 0) { /* raw random entries */
            for (i = 0; i < dim * dim; ++i) F[i] = pn_test_rng_range(rng, -1, 1);
            return 0;
        }
        if (v == 1) sc[t_randint(rng, dim)] *= -1; /* any sign pattern */
        break;
    case T_LA_REPEATED: {
        double base = sc[0], rel[4] = {0, 1e-15, 1e-12, 1e-9};
        double d1 = rel[t_randint(rng, 4)] * pn_test_rng_uniform(rng);
        double d2 = rel[t_randint(rng, 4)] * pn_test_rng_uniform(rng);
        v = t_randint(rng, 4);
        if (dim == 2) {
            sc[0] = base;
            sc[1] = base * (1 + d1);
        } else if (v == 0) { /* all three */
            sc[0] = base;
            sc[1] = base * (1 + d1);
            sc[2] = base * (1 + d2);
        } else if (v == 1) { /* the two largest */
            sc[0] = sc[1] = base * 3;
            sc[1] *= 1 + d1;
            sc[2] = base;
        } else { /* the two smallest, or equal in any position */
            sc[0] = base;
            sc[1] = sc[2] = base * 0.3;
            sc[1 + t_randint(rng, 2)] *= 1 + d1;
        }
        if (t_randint(rng, 4) == 0) sc[t_randint(rng, dim)] *= -1;
        break;
    }
    case T_LA_ZERO:
        v = t_randint(rng, 6);
        if (v == 0) { /* rank one outer product */
            double x[3], y[3];
            int j;
            for (i = 0; i < 3; ++i) {
                x[i] = pn_test_rng_range(rng, -1, 1);
                y[i] = pn_test_rng_range(rng, -1, 1);
            }
            for (i = 0; i < dim; ++i)
                for (j = 0; j < dim; ++j) F[i * dim + j] = x[i] * y[j];
            return 0;
        }
        {
            int nz = 1 + t_randint(rng, dim); /* 1 .. dim zeros, at random places */
            for (i = 0; i < nz; ++i) sc[t_randint(rng, dim)] = 0;
            if (v == 1) sc[0] = sc[1] = sc[2] = 0; /* F = 0 */
            if (t_randint(rng, 3) == 0) sc[t_randint(rng, dim)] *= -1;
        }
        break;
    case T_LA_TINY:
        for (i = 0; i < 3; ++i) sc[i] *= 1e-8;
        v = t_randint(rng, 3);
        if (v == 1) sc[t_randint(rng, dim)] /= 1e-8; /* one O(1) value */
        if (v == 2 && dim == 3) sc[0] /= 1e-8, sc[1] /= 1e-8;
        if (t_randint(rng, 4) == 0) sc[t_randint(rng, dim)] *= -1;
        break;
    case T_LA_HUGE:
        for (i = 0; i < 3; ++i) sc[i] *= 1e8;
        v = t_randint(rng, 4);
        if (v == 1) sc[t_randint(rng, dim)] *= 1e-8; /* one O(1) value */
        if (v == 2) sc[t_randint(rng, dim)] *= 1e-16; /* one 1e-8 value (ratio 1e16) */
        if (v == 3 && dim == 3) sc[1] *= 1e-8, sc[2] *= 1e-8;
        if (t_randint(rng, 4) == 0) sc[t_randint(rng, dim)] *= -1;
        break;
    case T_LA_DIAGONAL: {
        static const double pick[5] = {0.5, 1, 2, 3, 0};
        v = t_randint(rng, 3);
        for (i = 0; i < dim; ++i) {
            if (v == 1) sc[i] = pick[t_randint(rng, 4)]; /* repeats likely */
            if (v == 2) sc[i] = pick[t_randint(rng, 5)]; /* with zeros */
            if (t_randint(rng, 2)) sc[i] = -sc[i];
        }
        for (i = 0; i < 9; ++i) R1[i] = R2[i] = 0;
        for (i = 0; i < dim; ++i) R1[i * dim + i] = R2[i * dim + i] = 1;
        break;
    }
    case T_LA_ROTATION:
        sc[0] = sc[1] = sc[2] = 1;
        v = t_randint(rng, 8);
        for (i = 0; i < 9; ++i) R2[i] = 0;
        for (i = 0; i < dim; ++i) R2[i * dim + i] = 1;
        if (v == 0) { /* half turn about a random axis (trace -1) or the identity */
            if (dim == 2) {
                R1[0] = R1[3] = t_randint(rng, 2) ? -1 : 1;
                R1[1] = R1[2] = 0;
            } else {
                double x = t_gauss(rng), y = t_gauss(rng), z = t_gauss(rng);
                double n = sqrt(x * x + y * y + z * z);
                t_la_axis_angle(x / n, y / n, z / n, 3.141592653589793, R1);
            }
        } else if (v == 1 && dim == 3) { /* exact half turns about coordinate axes */
            int ax = t_randint(rng, 3);
            for (i = 0; i < 9; ++i) R1[i] = 0;
            for (i = 0; i < 3; ++i) R1[i * 3 + i] = (i == ax) ? 1 : -1;
        } else if (v == 2) { /* tiny angle */
            double ang = pn_test_rng_range(rng, -1e-9, 1e-9);
            if (dim == 2) {
                R1[0] = cos(ang); R1[1] = -sin(ang);
                R1[2] = sin(ang); R1[3] = cos(ang);
            } else
                t_la_axis_angle(0.6, 0.8, 0.0, ang, R1);
        }
        break;
    case T_LA_INVERTED:
        v = t_randint(rng, 4);
        if (v == 0) { /* raw random entries with det < 0 */
            do {
                for (i = 0; i < dim * dim; ++i) F[i] = pn_test_rng_range(rng, -1, 1);
            } while (!(t_det(dim, F) < -1e-3));
            return 0;
        }
        if (v == 1) { /* reflection */
            sc[0] = sc[1] = sc[2] = 1;
            sc[t_randint(rng, dim)] = -1;
        } else if (v == 2 && dim == 3) { /* three negatives */
            sc[0] = -sc[0];
            sc[1] = -sc[1];
            sc[2] = -sc[2];
        } else if (v == 3) { /* repeated magnitudes across the sign: (a, b, -b) */
            sc[dim - 1] = -sc[dim - 2];
        } else
            sc[t_randint(rng, dim)] *= -1;
        break;
    case T_LA_EXTREME: {
        double scale = pow(10.0, (double)(t_randint(rng, 301) - 150));
        for (i = 0; i < 3; ++i) sc[i] *= scale;
        if (t_randint(rng, 4) == 0) sc[t_randint(rng, dim)] *= -1;
        break;
    }
    default:
        break;
    }
    for (i = dim; i < 3; ++i) sc[i] = 0;
    t_adb(dim, R1, sc, R2, F);
    return 1;
}

static void t_la_run_kind(pn_test_ctx *pn__t, int kind, unsigned long long seed, long n) {
    t_la_stats st;
    pn_test_rng rng;
    int dim;
    long k;
    t_la_stats_init(&st);
    rng.s = seed;
    for (dim = 2; dim <= 3; ++dim)
        for (k = 0; k < n; ++k) {
            double F[9], sc[3], R1[9], R2[9];
            int con = t_la_gen(&rng, kind, dim, F, sc, R1, R2);
            t_la_check_case(&st, dim, F, con, sc, R1, R2, (k & 3) == 0);
        }
    t_la_finish(pn__t, &st);
}

PN_TEST(linalg_svd_generic) { t_la_run_kind(pn__t, T_LA_GENERIC, 101, T_LA_N); }
PN_TEST(linalg_svd_repeated) { t_la_run_kind(pn__t, T_LA_REPEATED, 102, T_LA_N); }
PN_TEST(linalg_svd_zero) { t_la_run_kind(pn__t, T_LA_ZERO, 103, T_LA_N); }
PN_TEST(linalg_svd_tiny) { t_la_run_kind(pn__t, T_LA_TINY, 104, T_LA_N); }
PN_TEST(linalg_svd_huge) { t_la_run_kind(pn__t, T_LA_HUGE, 105, T_LA_N); }
PN_TEST(linalg_svd_diagonal) { t_la_run_kind(pn__t, T_LA_DIAGONAL, 106, T_LA_N); }
PN_TEST(linalg_svd_rotation) { t_la_run_kind(pn__t, T_LA_ROTATION, 107, T_LA_N); }
PN_TEST(linalg_svd_inverted) { t_la_run_kind(pn__t, T_LA_INVERTED, 108, T_LA_N); }
/* scales 1e-150 .. 1e150: squaring F would under/overflow */
PN_TEST(linalg_svd_extreme_scale) { t_la_run_kind(pn__t, T_LA_EXTREME, 109, T_LA_N / 10); }

/* Exactly singular and inverted F: PN_ERROR_INVERTED, output untouched. */
PN_TEST(linalg_hencky_rejects_det_le_0) {
    static const double sing3[4][9] = {{1, 2, 3, 1, 2, 3, 4, 5, 6},
                                       {1, 0, 0, 0, 2, 0, 0, 0, 0},
                                       {0, 0, 0, 0, 0, 0, 0, 0, 0},
                                       {1, 0, 0, 0, -1, 0, 0, 0, 1}};
    static const double sing2[4][4] = {{1, 2, 2, 4}, {1, 0, 0, 0}, {0, 0, 0, 0}, {-1, 0, 0, 1}};
    int c, i, bad = 0, n = 0;
    pn_test_rng rng;
    rng.s = 110;
    for (c = 0; c < 4; ++c) {
        double eps[9], keep[9];
        pn_result r;
        for (i = 0; i < 9; ++i) keep[i] = eps[i] = 3.5 + i;
        r = pn_hencky_strain(3, sing3[c], eps);
        PN_CHECK(r == PN_ERROR_INVERTED);
        PN_CHECK(memcmp(eps, keep, sizeof eps) == 0);
        r = pn_hencky_strain(2, sing2[c], eps);
        PN_CHECK(r == PN_ERROR_INVERTED);
        PN_CHECK(memcmp(eps, keep, sizeof eps) == 0);
    }
    for (c = 0; c < 2000; ++c) {
        int dim = 2 + (c & 1);
        double F[9], eps[9], keep[9];
        pn_result r;
        do {
            for (i = 0; i < dim * dim; ++i) F[i] = pn_test_rng_range(&rng, -2, 2);
        } while (!(t_det(dim, F) < -1e-6));
        for (i = 0; i < 9; ++i) keep[i] = eps[i] = -1.25 * i;
        r = pn_hencky_strain(dim, F, eps);
        ++n;
        if (r != PN_ERROR_INVERTED || memcmp(eps, keep, sizeof eps) != 0) ++bad;
    }
    PN_REPORT("%d random inverted F, %d not rejected cleanly", n, bad);
    PN_CHECK(bad == 0);
}

/* ---- determinant, inverse, product ----------------------------------------------------------- */

PN_TEST(linalg_det_inverse_mul) {
    pn_test_rng rng;
    int c, i, dim;
    double worst_det = 0, worst_int = 0, worst_inv = 0, worst_id = 0, worst_mul = 0;
    rng.s = 111;
    for (c = 0; c < 20000; ++c) {
        double A[9], B[9], C[9], Cref[9], Ai[9], Ar[9], keep[9], I[9];
        double d, dr, scale;
        pn_result r;
        dim = 2 + (c & 1);
        /* small integers: every formula is exact */
        for (i = 0; i < dim * dim; ++i) A[i] = (double)(t_randint(&rng, 19) - 9);
        d = pn_mat_det(dim, A);
        dr = t_det(dim, A);
        if (fabs(d - dr) > worst_int) worst_int = fabs(d - dr);
        for (i = 0; i < 9; ++i) keep[i] = Ai[i] = 1e300;
        r = pn_mat_inverse(dim, A, Ai);
        if (dr == 0) {
            PN_CHECK(r == PN_ERROR_INVERTED);
            PN_CHECK(memcmp(Ai, keep, sizeof Ai) == 0);
        } else {
            PN_CHECK(r == PN_OK);
        }
        /* random reals, conditioned by construction */
        {
            double R1[9], R2[9], s[3];
            for (i = 0; i < 3; ++i) s[i] = t_logu(&rng, 0.1, 10) * (t_randint(&rng, 2) ? 1 : -1);
            scale = t_logu(&rng, 1e-6, 1e6);
            for (i = 0; i < 3; ++i) s[i] *= scale;
            t_rand_rot(&rng, dim, R1);
            t_rand_rot(&rng, dim, R2);
            t_adb(dim, R1, s, R2, A);
        }
        d = pn_mat_det(dim, A);
        dr = t_det(dim, A);
        /* both are backward stable: error ~ eps |A|^dim (the condition number is <= 100) */
        {
            double e = fabs(d - dr) / fabs(dr);
            if (!(e <= worst_det)) worst_det = e;
        }
        r = pn_mat_inverse(dim, A, Ai);
        PN_CHECK(r == PN_OK);
        t_la_adj_inverse(dim, A, Ar);
        {
            double e = t_dist(dim * dim, Ai, Ar) / t_norm(dim * dim, Ar);
            if (!(e <= worst_inv)) worst_inv = e;
        }
        t_mul(dim, A, Ai, I);
        for (i = 0; i < dim; ++i) I[i * dim + i] -= 1;
        {
            double e = t_norm(dim * dim, I);
            if (!(e <= worst_id)) worst_id = e;
        }
        for (i = 0; i < dim * dim; ++i) B[i] = pn_test_rng_range(&rng, -3, 3);
        pn_mat_mul(dim, A, B, C);
        t_mul(dim, A, B, Cref);
        {
            double e = t_dist(dim * dim, C, Cref) / (t_norm(dim * dim, A) * t_norm(dim * dim, B));
            if (!(e <= worst_mul)) worst_mul = e;
        }
    }
    PN_REPORT("det: integer |err| %.2e, real rel %.2e; inverse vs adjugate rel %.2e, |A A^-1 - I| "
              "%.2e; mul rel %.2e",
              worst_int, worst_det, worst_inv, worst_id, worst_mul);
    PN_CHECK(worst_int == 0);
    PN_CHECK_LE(worst_det, 1e-13);
    PN_CHECK_LE(worst_inv, 1e-12);
    PN_CHECK_LE(worst_id, 1e-12);
    PN_CHECK_LE(worst_mul, 1e-15);
}

/* ---- symmetric eigen-decomposition ------------------------------------------------------ */

/* Random symmetric n x n test matrix of a kind; fills the eigenvalues when known (ascending). */
static int t_la_sym_gen(pn_test_rng *rng, int n, int kind, double *A, double *wk) {
    double Q[144];
    int i, j;
    switch (kind) {
    case 0: /* random entries */
        for (i = 0; i < n; ++i)
            for (j = i; j < n; ++j) A[i * n + j] = A[j * n + i] = pn_test_rng_range(rng, -1, 1);
        return 0;
    case 1:   /* repeated eigenvalues */
    case 2:   /* zero eigenvalues, rank deficient */
    case 3:   /* spread 1e-8 .. 1e8 */
    case 6: { /* O(1) and tiny ones of either sign, down to 1e-12 */
        for (i = 0; i < n; ++i) {
            if (kind == 6)
                wk[i] = (t_randint(rng, 2) ? 1 : -1) * pow(10.0, -12.0 * pn_test_rng_uniform(rng));
            else if (kind == 1)
                wk[i] = (double)(t_randint(rng, 3) - 1);
            else if (kind == 2)
                wk[i] = t_randint(rng, 2) ? 0.0 : pn_test_rng_range(rng, -2, 2);
            else
                wk[i] = (t_randint(rng, 2) ? 1 : -1) * t_logu(rng, 1e-8, 1e8);
        }
        t_la_rand_orth(rng, n, Q);
        t_adbt(n, Q, wk, Q, A);
        for (i = 0; i < n; ++i) /* exactly symmetric */
            for (j = i + 1; j < n; ++j) A[j * n + i] = A[i * n + j];
        break;
    }
    case 4: /* diagonal, any order */
        for (i = 0; i < n * n; ++i) A[i] = 0;
        for (i = 0; i < n; ++i) A[i * n + i] = wk[i] = (double)(t_randint(rng, 7) - 3);
        break;
    default: /* zero matrix */
        for (i = 0; i < n * n; ++i) A[i] = 0;
        for (i = 0; i < n; ++i) wk[i] = 0;
        break;
    }
    for (i = 1; i < n; ++i)
        for (j = i; j > 0 && wk[j - 1] > wk[j]; --j) {
            double t = wk[j];
            wk[j] = wk[j - 1];
            wk[j - 1] = t;
        }
    return 1;
}

PN_TEST(linalg_sym_eigen) {
    pn_test_rng rng;
    int n, c, i, j, order_bad = 0, status_bad = 0, lower_bad = 0;
    double w_recon = 0, w_orth = 0, w_vals = 0, w_known = 0;
    rng.s = 112;
    for (n = 1; n <= 12; ++n)
        for (c = 0; c < 6000; ++c) {
            double A[144], Q[144], w[12], T[144], Qr[144], wr[12], wk[12], nA, L[144], Q2[144], w2[12];
            int kind = c % 7, known;
            pn_result r;
            known = t_la_sym_gen(&rng, n, kind, A, wk);
            nA = t_norm(n * n, A);
            r = pn_sym_eigen(n, A, Q, w);
            if (r != PN_OK) {
                ++status_bad;
                continue;
            }
            for (i = 0; i + 1 < n; ++i)
                if (!(w[i] <= w[i + 1])) ++order_bad;
            t_adbt(n, Q, w, Q, T);
            {
                double e = nA > 0 ? t_dist(n * n, T, A) / nA : t_norm(n * n, T);
                if (!(e <= w_recon)) w_recon = e;
                e = t_la_orth_err(n, Q);
                if (!(e <= w_orth)) w_orth = e;
            }
            t_la_jacobi(n, A, Qr, wr);
            for (i = 0; i < n; ++i) {
                double e = fabs(w[i] - wr[i]) / (nA > 0 ? nA : 1);
                if (!(e <= w_vals)) w_vals = e;
                if (known) {
                    e = fabs(w[i] - wk[i]) / (nA > 0 ? nA : 1);
                    if (!(e <= w_known)) w_known = e;
                }
            }
            /* only the upper part is read: garbage below the diagonal changes nothing */
            memcpy(L, A, sizeof(double) * (size_t)(n * n));
            for (i = 0; i < n; ++i)
                for (j = 0; j < i; ++j) L[i * n + j] = 1e3 * (double)(i + j + 1);
            r = pn_sym_eigen(n, L, Q2, w2);
            if (r != PN_OK || memcmp(w, w2, sizeof(double) * (size_t)n) != 0 ||
                memcmp(Q, Q2, sizeof(double) * (size_t)(n * n)) != 0)
                ++lower_bad;
        }
    PN_REPORT("n = 1..12, 72000 cases: recon %.2e, orth %.2e, eigenvalues vs reference Jacobi %.2e, "
              "vs constructed %.2e (relative to |A|)",
              w_recon, w_orth, w_vals, w_known);
    PN_CHECK(status_bad == 0);
    PN_CHECK(order_bad == 0);
    PN_CHECK(lower_bad == 0);
    PN_CHECK_LE(w_recon, T_LA_TOL);
    PN_CHECK_LE(w_orth, T_LA_TOL);
    PN_CHECK_LE(w_vals, T_LA_TOL);
    PN_CHECK_LE(w_known, T_LA_TOL);
}

/* Nearest PSD matrix, characterised without an eigen-solver (Moreau decomposition over the
   cone of PSD matrices): A = P + N with P PSD, N negative semi-definite and <P, N> = 0. */
PN_TEST(linalg_sym_project_psd) {
    pn_test_rng rng;
    int n, c, i, status_bad = 0;
    double w_ref = 0, w_minP = 0, w_maxN = 0, w_inner = 0, w_fixed = 0, w_idem = 0, w_sym = 0;
    double w_near = 0;
    rng.s = 113;
    for (n = 1; n <= 12; ++n)
        for (c = 0; c < 6000; ++c) {
            double A[144], P[144], N[144], Q[144], w[12], wk[12], ref[144], P2[144], nA, ip = 0;
            int kind = c % 7;
            pn_result r;
            t_la_sym_gen(&rng, n, kind, A, wk);
            if (c % 12 == 7) { /* PSD input: must come back unchanged */
                double B[144];
                t_mul_tn(n, A, A, B);
                for (i = 0; i < n * n; ++i) A[i] = B[i];
                {
                    int a2, b2;
                    for (a2 = 0; a2 < n; ++a2)
                        for (b2 = a2 + 1; b2 < n; ++b2) A[b2 * n + a2] = A[a2 * n + b2];
                }
            }
            nA = t_norm(n * n, A);
            memcpy(P, A, sizeof(double) * (size_t)(n * n));
            r = pn_sym_project_psd(n, P);
            if (r != PN_OK) {
                ++status_bad;
                continue;
            }
            if (nA == 0) nA = 1;
            for (i = 0; i < n * n; ++i) N[i] = A[i] - P[i];
            {
                double e = t_asym(n, P) / nA;
                if (!(e <= w_sym)) w_sym = e;
            }
            t_la_jacobi(n, P, Q, w);
            if (!(-w[0] / nA <= w_minP)) w_minP = -w[0] / nA;
            t_la_jacobi(n, N, Q, w);
            if (!(w[n - 1] / nA <= w_maxN)) w_maxN = w[n - 1] / nA;
            for (i = 0; i < n * n; ++i) ip += P[i] * N[i];
            if (!(fabs(ip) / (nA * nA) <= w_inner)) w_inner = fabs(ip) / (nA * nA);
            /* reference: clamp the eigenvalues of our own decomposition */
            t_la_jacobi(n, A, Q, w);
            t_psd_rebuild(n, Q, w, ref);
            {
                double e = t_dist(n * n, P, ref) / nA;
                if (!(e <= w_ref)) w_ref = e;
            }
            if (c % 12 == 7) {
                double e = t_dist(n * n, P, A) / nA;
                if (!(e <= w_fixed)) w_fixed = e;
            }
            /* idempotent */
            memcpy(P2, P, sizeof(double) * (size_t)(n * n));
            if (pn_sym_project_psd(n, P2) == PN_OK) {
                double e = t_dist(n * n, P2, P) / nA;
                if (!(e <= w_idem)) w_idem = e;
            } else
                ++status_bad;
            /* nearest: no random PSD matrix is closer */
            {
                double X[144], B[144], dP = t_dist(n * n, A, P), dX;
                int k;
                for (k = 0; k < n * n; ++k) B[k] = P[k] + 0.01 * nA * pn_test_rng_range(&rng, -1, 1);
                t_la_jacobi(n, B, Q, w); /* symmetrises B, then clamp */
                t_psd_rebuild(n, Q, w, X);
                dX = t_dist(n * n, A, X);
                if (!((dP - dX) / nA <= w_near)) w_near = (dP - dX) / nA;
            }
        }
    PN_REPORT("n = 1..12, 72000 cases: vs reference %.2e, min eig(P) %.2e, max eig(A-P) %.2e, "
              "<P, A-P> %.2e, PSD input moved %.2e, idempotence %.2e, asym %.2e, "
              "nearer random PSD %.2e (all relative to |A|)",
              w_ref, -w_minP, w_maxN, w_inner, w_fixed, w_idem, w_sym, w_near);
    PN_CHECK(status_bad == 0);
    PN_CHECK_LE(w_ref, T_LA_TOL);
    PN_CHECK_LE(w_minP, T_LA_TOL);
    PN_CHECK_LE(w_maxN, T_LA_TOL);
    PN_CHECK_LE(w_inner, T_LA_TOL);
    PN_CHECK_LE(w_fixed, T_LA_TOL);
    PN_CHECK_LE(w_idem, T_LA_TOL);
    PN_CHECK_LE(w_sym, T_LA_TOL);
    PN_CHECK_LE(w_near, T_LA_TOL);
}

/* ---- bad input ---------------------------------------------------------------------------- */

PN_TEST(linalg_nonfinite_rejected) {
    const double bad[3] = {NAN, HUGE_VAL, -HUGE_VAL};
    int dim, pos, b, n, fails = 0, tried = 0;
    for (dim = 2; dim <= 3; ++dim)
        for (pos = 0; pos < dim * dim; ++pos)
            for (b = 0; b < 3; ++b) {
                double F[9] = {1.1, 0.2, -0.3, 0.1, 0.9, 0.2, 0.05, -0.1, 1.2};
                double o1[9], o2[9], o3[9], k1[9], k2[9], k3[9];
                int i;
                pn_result r;
                F[pos] = bad[b];
                for (i = 0; i < 9; ++i) k1[i] = o1[i] = 11.5 + i, k2[i] = o2[i] = -2.5 * i, k3[i] = o3[i] = 1e-3 * i;
                r = pn_svd(dim, F, o1, o2, o3);
                tried++;
                if (r != PN_ERROR_NONFINITE || memcmp(o1, k1, sizeof o1) || memcmp(o2, k2, sizeof o2) ||
                    memcmp(o3, k3, sizeof o3)) {
                    ++fails;
                    fprintf(stderr, "      pn_svd dim %d, F[%d] = %g: result %d\n", dim, pos, F[pos], (int)r);
                }
                r = pn_polar(dim, F, o1, o2);
                tried++;
                if (r != PN_ERROR_NONFINITE || memcmp(o1, k1, sizeof o1) || memcmp(o2, k2, sizeof o2)) {
                    ++fails;
                    fprintf(stderr, "      pn_polar dim %d, F[%d] = %g: result %d\n", dim, pos, F[pos], (int)r);
                }
                r = pn_hencky_strain(dim, F, o1);
                tried++;
                if (r != PN_ERROR_NONFINITE || memcmp(o1, k1, sizeof o1)) {
                    ++fails;
                    fprintf(stderr, "      pn_hencky_strain dim %d, F[%d] = %g: result %d\n", dim, pos, F[pos], (int)r);
                }
            }
    for (n = 1; n <= 12; ++n)
        for (pos = 0; pos < n * n; ++pos)
            for (b = 0; b < 3; ++b) {
                double A[144], K[144], Q[144], w[12], kQ[144], kw[12];
                int i, j;
                if (pos % n < pos / n) continue; /* the upper part (incl. diagonal) is read */
                for (i = 0; i < n; ++i)
                    for (j = 0; j < n; ++j) A[i * n + j] = (i == j) ? 2.0 : 0.1 * (double)(i + j);
                A[pos] = bad[b];
                if (pos % n != pos / n) A[(pos % n) * n + pos / n] = bad[b]; /* keep it symmetric */
                memcpy(K, A, sizeof A);
                for (i = 0; i < 144; ++i) kQ[i] = Q[i] = 0.5 * i;
                for (i = 0; i < 12; ++i) kw[i] = w[i] = -0.5 * i;
                tried++;
                if (pn_sym_eigen(n, A, Q, w) != PN_ERROR_NONFINITE || memcmp(Q, kQ, sizeof Q) ||
                    memcmp(w, kw, sizeof w)) {
                    ++fails;
                    fprintf(stderr, "      pn_sym_eigen n %d, A[%d] = %g\n", n, pos, bad[b]);
                }
                tried++;
                if (pn_sym_project_psd(n, A) != PN_ERROR_NONFINITE || memcmp(A, K, sizeof A)) {
                    ++fails;
                    fprintf(stderr, "      pn_sym_project_psd n %d, A[%d] = %g\n", n, pos, bad[b]);
                }
            }
    PN_REPORT("%d calls with NaN/inf input, %d not rejected with outputs untouched", tried, fails);
    PN_CHECK(fails == 0);
}

static const pn_test_case pn_tests_linalg[] = {
    {"linalg_det_inverse_mul", linalg_det_inverse_mul},
    {"linalg_svd_generic", linalg_svd_generic},
    {"linalg_svd_repeated", linalg_svd_repeated},
    {"linalg_svd_zero", linalg_svd_zero},
    {"linalg_svd_tiny", linalg_svd_tiny},
    {"linalg_svd_huge", linalg_svd_huge},
    {"linalg_svd_diagonal", linalg_svd_diagonal},
    {"linalg_svd_rotation", linalg_svd_rotation},
    {"linalg_svd_inverted", linalg_svd_inverted},
    {"linalg_svd_extreme_scale", linalg_svd_extreme_scale},
    {"linalg_hencky_rejects_det_le_0", linalg_hencky_rejects_det_le_0},
    {"linalg_sym_eigen", linalg_sym_eigen},
    {"linalg_sym_project_psd", linalg_sym_project_psd},
    {"linalg_nonfinite_rejected", linalg_nonfinite_rejected},
};
