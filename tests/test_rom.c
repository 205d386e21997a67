/* test_rom.c: plastinet_rom.h. Expected values from finite differences, an affine map whose
   inverse and projections are written out here, and the full-order explicit step of
   plastinet_mpm.h (with every point sampled and an affine map, the reduced step is that step
   followed by a least-squares fit). */

/* A test map that is a diffeomorphism near the box [0.02, 0.06]^d: x = X + amp (small ELU
   network of X and xhat). Hidden width 12: units 0 .. d-1 carry Xn in the linear regime of
   ELU (bias +10), the rest are random and nonlinear; the last layer adds them with amp. */
typedef struct t_rom_net {
    pn_rom_model m;
    int width[5];
    double W[4][16 * 16], b[4][16];
    const double *Wp[4], *bp[4];
    double rest[8], sd[8];
} t_rom_net;

static void t_rom_random_model(t_rom_net *t, int d, int K, unsigned long long seed, double amp) {
    pn_test_rng r;
    int l, o, i, H = 12;
    r.s = seed;
    memset(t, 0, sizeof *t);
    t->width[0] = d + K, t->width[1] = H, t->width[2] = H, t->width[3] = H, t->width[4] = d;
    for (l = 0; l < 4; ++l) {
        int win = t->width[l], wout = t->width[l + 1];
        for (o = 0; o < wout; ++o) {
            for (i = 0; i < win; ++i) t->W[l][o * win + i] = pn_test_rng_range(&r, -0.6, 0.6);
            t->b[l][o] = pn_test_rng_range(&r, -0.3, 0.3);
        }
        for (o = 0; o < d; ++o) { /* the pass-through of Xn */
            for (i = 0; i < win; ++i) t->W[l][o * win + i] = l + 1 < 4 ? (i == o) : amp * t->W[l][o * win + i];
            if (l + 1 < 4) {
                for (i = d; i < win; ++i) t->W[l][o * win + i] = 0;
                t->b[l][o] = l == 0 ? 10 : 0;
            } else {
                t->W[l][o * win + o] = 1;
                t->b[l][o] = -10;
            }
        }
        if (l + 1 == 4)
            for (o = 0; o < d; ++o)
                for (i = d; i < win; ++i) t->W[l][o * win + i] = amp * pn_test_rng_range(&r, -1, 1);
    }
    for (l = 0; l < 4; ++l) t->Wp[l] = t->W[l], t->bp[l] = t->b[l];
    for (i = 0; i < K; ++i) t->rest[i] = 0, t->sd[i] = 1;
    t->m.format_version = PN_ROM_FORMAT_VERSION;
    t->m.name = "test";
    t->m.dim = d, t->m.latent = K, t->m.n_layers = 4;
    t->m.width = t->width, t->m.weight = t->Wp, t->m.bias = t->bp;
    t->m.activation = PN_ROM_ELU;
    for (i = 0; i < 3; ++i) t->m.in_lo[i] = 0.02, t->m.in_hi[i] = 0.06, t->m.out_mean[i] = 0.04, t->m.out_std[i] = 0.02;
    t->m.latent_rest = t->rest, t->m.latent_std = t->sd;
    t->m.latent_rest_count = t->m.latent_std_count = K, t->m.width_count = 5;
    for (l = 0; l < 4; ++l) t->m.weight_count[l] = t->width[l] * t->width[l + 1], t->m.bias_count[l] = t->width[l + 1];
    t->m.youngs_pa = 1e4, t->m.poisson = 0.3, t->m.density_kg_m3 = 1000, t->m.dx_m = 0.004, t->m.per_axis = 2;
    t->m.frame_dt_s = 1.0 / 144;
}

/* g, F and G of pn_rom_eval against central differences, 2D and 3D */
PN_TEST(rom_eval_fd) {
    int d;
    for (d = 2; d <= 3; ++d) {
        t_rom_net t;
        pn_test_rng r;
        double worst_F = 0, worst_G = 0;
        int trial;
        r.s = 5;
        t_rom_random_model(&t, d, 4, 11 + (unsigned)d, 0.3);
        PN_CHECK(pn_rom_model_check(&t.m, NULL, 0) == PN_OK);
        for (trial = 0; trial < 20; ++trial) {
            double X[3], xh[4], x[3], F[9], G[12], h = 1e-6, hx = 1e-6 * 0.02;
            int i, k;
            for (i = 0; i < d; ++i) X[i] = pn_test_rng_range(&r, 0.02, 0.06);
            for (i = 0; i < 4; ++i) xh[i] = pn_test_rng_range(&r, -1, 1);
            pn_rom_eval(&t.m, xh, 1, X, x, F, G);
            for (i = 0; i < d; ++i) {
                double Xp[3], Xm[3], xp[3], xm[3];
                memcpy(Xp, X, sizeof X), memcpy(Xm, X, sizeof X);
                Xp[i] += hx, Xm[i] -= hx;
                pn_rom_eval(&t.m, xh, 1, Xp, xp, NULL, NULL);
                pn_rom_eval(&t.m, xh, 1, Xm, xm, NULL, NULL);
                for (k = 0; k < d; ++k) worst_F = fmax(worst_F, fabs((xp[k] - xm[k]) / (2 * hx) - F[k * d + i]));
            }
            for (i = 0; i < 4; ++i) {
                double hp[4], hm[4], xp[3], xm[3];
                memcpy(hp, xh, sizeof hp), memcpy(hm, xh, sizeof hm);
                hp[i] += h, hm[i] -= h;
                pn_rom_eval(&t.m, hp, 1, X, xp, NULL, NULL);
                pn_rom_eval(&t.m, hm, 1, X, xm, NULL, NULL);
                for (k = 0; k < d; ++k) worst_G = fmax(worst_G, fabs((xp[k] - xm[k]) / (2 * h) - G[k * 4 + i]));
            }
        }
        PN_REPORT("%dD: F vs central differences %.2e, G (m per latent unit) %.2e", d, worst_F, worst_G);
        PN_CHECK_LE(worst_F, 1e-7);
        PN_CHECK_LE(worst_G, 1e-9);
    }
}

/* the float path (pn_rom_map) against the double reference, positions and F */
PN_TEST(rom_float_path) {
    t_rom_net t;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    double pts[3 * 200], xd[3], Fd[9], ex = 0, eF = 0, lat[4] = {0.3, -0.2, 0.5, 0.1};
    float Xf[3 * 200], xf[3 * 200], Ff[9 * 200];
    pn_test_rng r;
    int i, k;
    r.s = 9;
    t_rom_random_model(&t, 3, 4, 3, 0.3);
    for (i = 0; i < 3 * 200; ++i) pts[i] = pn_test_rng_range(&r, 0.02, 0.06), Xf[i] = (float)pts[i];
    memset(&desc, 0, sizeof desc);
    desc.model = &t.m, desc.points = pts, desc.n_points = 200, desc.point_volume_m3 = 1e-9;
    PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
    if (!w) return;
    PN_CHECK(pn_rom_set_latent(w, lat, NULL) == PN_OK);
    PN_CHECK(pn_rom_map(w, 200, Xf, xf, Ff) == PN_OK);
    for (i = 0; i < 200; ++i) {
        double X[3];
        for (k = 0; k < 3; ++k) X[k] = (double)Xf[3 * i + k];
        pn_rom_eval(&t.m, lat, 1, X, xd, Fd, NULL);
        for (k = 0; k < 3; ++k) ex = fmax(ex, fabs(xd[k] - xf[3 * i + k]));
        for (k = 0; k < 9; ++k) eF = fmax(eF, fabs(Fd[k] - Ff[9 * i + k]));
    }
    PN_REPORT("float path vs double: positions %.2e m (of 0.06 m), F %.2e", ex, eF);
    /* float rounding: the pass-through units carry Xn + 10 (~11), so the net's output has about
       11 x 6e-8 absolute error, times out_std 0.02 m */
    PN_CHECK_LE(ex, 1e-7);
    PN_CHECK_LE(eF, 2e-6);
    pn_rom_destroy(w);
}

/* a body of points on the lattice of spacing h filling the box lo .. lo + n h */
static size_t t_rom_box(int d, const double *lo, const int *n, double h, double *X) {
    size_t c = 0;
    int i, j, k;
    for (i = 0; i < n[0]; ++i)
        for (j = 0; j < n[1]; ++j)
            for (k = 0; k < (d == 3 ? n[2] : 1); ++k) {
                X[c * d] = lo[0] + (i + 0.5) * h, X[c * d + 1] = lo[1] + (j + 0.5) * h;
                if (d == 3) X[c * d + 2] = lo[2] + (k + 0.5) * h;
                c++;
            }
    return c;
}

/* The affine map with every point sampled and Lagrangian quadrature: the reduced step's
   trial state must be the full-order explicit step of plastinet_mpm.h from the same affine
   state, and the new latent the least-squares affine fit of that state (solved here by the
   normal equations on the basis (1, X)). 2D and 3D, APIC, with gravity and stress. */
PN_TEST(rom_affine_equals_mpm) {
    int d;
    for (d = 2; d <= 3; ++d) {
        const double dx = 1.0 / 32, h = dx / 2, dt = 2e-4, E = 2e4, nu = 0.3, rho = 1000;
        double lo[3] = {0.35, 0.4, 0.38}, X[3 * 4096], A[9], Ad[9], b[3] = {0.01, -0.02, 0.015}, bd[3] = {0.1, 0.05, -0.2};
        double lat[12], vlat[12], ex = 0, el = 0, fit[12];
        int nb[3] = {12, 10, 8}, i, j, k, K = d + d * d;
        size_t n = t_rom_box(d, lo, nb, h, X), p;
        pn_test_rng r;
        pn_mpm_world *mw = t_mpm_world(d, 32, -9.81, PN_BOUNDARY_STICKY);
        pn_rom_model am;
        pn_rom_desc desc;
        pn_rom_world *w = NULL;
        pn_material_desc md;
        pn_material mat;
        pn_real *xs = (pn_real *)malloc(sizeof(pn_real) * n * 3), *vs = (pn_real *)malloc(sizeof(pn_real) * n * 3);
        pn_real *Cs = (pn_real *)malloc(sizeof(pn_real) * n * 9), *Fs = (pn_real *)malloc(sizeof(pn_real) * n * 9);
        int g;
        r.s = 77 + (unsigned)d;
        for (i = 0; i < d * d; ++i) A[i] = pn_test_rng_range(&r, -0.05, 0.05), Ad[i] = pn_test_rng_range(&r, -2, 2);
        memset(&md, 0, sizeof md);
        md.elastic = PN_ELASTIC_FIXED_COROTATED, md.plastic = PN_PLASTIC_NONE, md.youngs_modulus_pa = E, md.poisson_ratio = nu;
        PN_CHECK(mw != NULL && pn_material_init(&mat, &md, NULL, 0) == PN_OK);
        if (!mw) return;
        g = pn_mpm_add_group(mw, &mat, rho);
        {
            pn_real *x0 = (pn_real *)malloc(sizeof(pn_real) * n * 3);
            for (p = 0; p < n * (size_t)d; ++p) x0[p] = X[p];
            PN_CHECK(pn_mpm_add_particles(mw, g, n, x0, NULL, pow(h, d)) == PN_OK);
            free(x0);
        }
        { /* the affine state: x = X + b + A X, v = bd + Ad X, F = I + A, C = Ad (I + A)^-1 */
            double Fi[9], Ci[9], I_A[9];
            for (i = 0; i < d * d; ++i) I_A[i] = A[i] + ((i / d) == (i % d));
            if (d == 2) {
                double det = I_A[0] * I_A[3] - I_A[1] * I_A[2];
                Fi[0] = I_A[3] / det, Fi[1] = -I_A[1] / det, Fi[2] = -I_A[2] / det, Fi[3] = I_A[0] / det;
            } else {
                pn_real M[9], Mi[9];
                for (i = 0; i < 9; ++i) M[i] = I_A[i];
                pn_mat_inverse(3, M, Mi);
                for (i = 0; i < 9; ++i) Fi[i] = Mi[i];
            }
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j) {
                    Ci[i * d + j] = 0;
                    for (k = 0; k < d; ++k) Ci[i * d + j] += Ad[i * d + k] * Fi[k * d + j];
                }
            for (p = 0; p < n; ++p)
                for (i = 0; i < d; ++i) {
                    double s = X[p * d + i] + b[i], v = bd[i];
                    for (j = 0; j < d; ++j) s += A[i * d + j] * X[p * d + j], v += Ad[i * d + j] * X[p * d + j];
                    xs[p * d + i] = s, vs[p * d + i] = v;
                    for (j = 0; j < d; ++j) Cs[p * d * d + i * d + j] = Ci[i * d + j], Fs[p * d * d + i * d + j] = I_A[i * d + j];
                }
        }
        PN_CHECK(pn_mpm_set_particles(mw, 0, n, xs, vs, Cs, Fs, -1) == PN_OK);
        PN_CHECK(pn_mpm_step_explicit(mw, dt, NULL) == PN_OK);
        pn_rom_affine_model(d, &am);
        memset(&desc, 0, sizeof desc);
        desc.model = &am, desc.points = X, desc.n_points = n, desc.point_volume_m3 = pow(h, d);
        desc.dx_m = dx, desc.youngs_pa = E, desc.poisson = nu, desc.density_kg_m3 = rho, desc.gravity[1] = -9.81;
        desc.samples = -1, desc.quadrature = PN_ROM_LAGRANGIAN, desc.transfer = PN_ROM_APIC, desc.reference = 1;
        PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
        if (!w) return;
        for (i = 0; i < d; ++i) lat[i] = b[i], vlat[i] = bd[i];
        for (i = 0; i < d * d; ++i) lat[d + i] = A[i], vlat[d + i] = Ad[i];
        PN_CHECK(pn_rom_set_latent(w, lat, vlat) == PN_OK);
        PN_CHECK(pn_rom_step(w, dt, NULL) == PN_OK);
        for (p = 0; p < n; ++p) /* the trial state, sample p is point p (all sampled, in order) */
            for (i = 0; i < d; ++i) ex = fmax(ex, fabs(w->sxt[p * d + i] - mw->x[p * d + i]));
        { /* the affine least-squares fit of the full-order positions: per output row i,
             minimize sum_p (x_pi - c_i - sum_j M_ij X_pj)^2 over (c_i, M_i.) */
            double N[16], rhs[16];
            for (i = 0; i < d; ++i) {
                int a, c2, m1 = d + 1;
                for (a = 0; a < m1 * m1; ++a) N[a] = 0;
                for (a = 0; a < m1; ++a) rhs[a] = 0;
                for (p = 0; p < n; ++p) {
                    double phi[4];
                    phi[0] = 1;
                    for (j = 0; j < d; ++j) phi[1 + j] = X[p * d + j];
                    for (a = 0; a < m1; ++a) {
                        rhs[a] += phi[a] * (mw->x[p * d + i] - X[p * d + i]);
                        for (c2 = 0; c2 < m1; ++c2) N[a * m1 + c2] += phi[a] * phi[c2];
                    }
                }
                for (a = 0; a < m1; ++a) { /* Gauss-Jordan, N is SPD and small */
                    double piv = N[a * m1 + a];
                    for (c2 = 0; c2 < m1; ++c2) N[a * m1 + c2] /= piv;
                    rhs[a] /= piv;
                    for (k = 0; k < m1; ++k)
                        if (k != a) {
                            double f = N[k * m1 + a];
                            for (c2 = 0; c2 < m1; ++c2) N[k * m1 + c2] -= f * N[a * m1 + c2];
                            rhs[k] -= f * rhs[a];
                        }
                }
                fit[i] = rhs[0];
                for (j = 0; j < d; ++j) fit[d + i * d + j] = rhs[1 + j];
            }
        }
        for (i = 0; i < K; ++i) el = fmax(el, fabs(fit[i] - w->xhat[i]));
        PN_REPORT("%dD, %lu points: trial state vs the explicit MPM step %.2e m (dx %.3g m); latent vs the affine fit %.2e", d,
                  (unsigned long)n, ex, dx, el);
        PN_CHECK_LE(ex, 1e-13);
        PN_CHECK_LE(el, 1e-9);
        pn_rom_destroy(w);
        pn_mpm_destroy(mw);
        free(xs), free(vs), free(Cs), free(Fs);
    }
}

/* projections: a velocity field in the tangent space projects to its own vhat; a state on the
   manifold fits back to its latent (affine map: unique), and on the ELU map the fit's misfit
   vanishes */
PN_TEST(rom_projections) {
    pn_rom_model am;
    t_rom_net t;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    double lo[3] = {0.02, 0.02, 0.02}, X[3 * 4096], x[3 * 4096], v[3 * 4096], lat[12], vl[12], rms = 1, e = 0;
    int nb[3] = {8, 8, 8}, i;
    size_t n = t_rom_box(3, lo, nb, 0.005, X);
    pn_test_rng r;
    r.s = 4;
    pn_rom_affine_model(3, &am);
    memset(&desc, 0, sizeof desc);
    desc.model = &am, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.25e-7;
    PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
    if (!w) return;
    for (i = 0; i < 12; ++i) lat[i] = pn_test_rng_range(&r, -0.1, 0.1), vl[i] = pn_test_rng_range(&r, -1, 1);
    {
        double *G = (double *)malloc(sizeof(double) * n * 36);
        size_t p;
        int k, j;
        pn_rom_eval(&am, lat, n, X, x, NULL, G);
        for (p = 0; p < n; ++p)
            for (k = 0; k < 3; ++k) {
                v[p * 3 + k] = 0;
                for (j = 0; j < 12; ++j) v[p * 3 + k] += G[p * 36 + k * 12 + j] * vl[j];
            }
        free(G);
    }
    PN_CHECK(pn_rom_fit(w, x, v, &rms) == PN_OK);
    for (i = 0; i < 12; ++i) e = fmax(e, fmax(fabs(w->xhat[i] - lat[i]), fabs(w->vhat[i] - vl[i]) * 0.1));
    PN_REPORT("affine: fit of a state on the manifold: latent and velocity off by %.2e, misfit %.2e m", e, rms);
    PN_CHECK_LE(e, 1e-10);
    pn_rom_destroy(w);
    w = NULL;
    t_rom_random_model(&t, 3, 4, 21, 0.3);
    desc.model = &t.m;
    PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
    if (!w) return;
    {
        double l4[4] = {0.4, -0.3, 0.2, 0.6};
        pn_rom_eval(&t.m, l4, n, X, x, NULL, NULL);
        PN_CHECK(pn_rom_fit(w, x, NULL, &rms) == PN_OK);
        PN_REPORT("ELU map: fit of a state on the manifold from the rest latent: misfit %.2e m", rms);
        PN_CHECK_LE(rms, 1e-6); /* float Jacobians: converges to about float rounding of 0.06 m */
    }
    pn_rom_destroy(w);
}

/* Eulerian quadrature: every kept point's X maps back onto its lattice position (checked with
   the double path, the world's Newton runs on the float one), and with the affine map X is
   the exact inverse written out here */
PN_TEST(rom_inverse_map) {
    t_rom_net t;
    pn_rom_model am;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    double lo[3] = {0.02, 0.02, 0.02}, X[3 * 4096], worst = 0, l4[4] = {0.3, 0.2, -0.4, 0.1};
    int nb[3] = {16, 16, 16}, pass;
    size_t n = t_rom_box(3, lo, nb, 0.0025, X), q, kept = 0;
    t_rom_random_model(&t, 3, 4, 8, 0.3);
    pn_rom_affine_model(3, &am);
    for (pass = 0; pass < 2; ++pass) {
        pn_rom_stats st;
        double A[12] = {0.01, -0.02, 0.005, 0.03, 0.02, 0.01, -0.01, 0.04, -0.02, 0.01, 0.02, -0.03};
        memset(&desc, 0, sizeof desc);
        desc.model = pass ? &am : &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.5625e-8;
        desc.dx_m = 0.004, desc.samples = 30, desc.youngs_pa = 1e4, desc.poisson = 0.3, desc.density_kg_m3 = 1000;
        PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
        if (!w) return;
        PN_CHECK(pn_rom_set_latent(w, pass ? A : l4, NULL) == PN_OK);
        PN_CHECK(pn_rom_step(w, 1e-4, &st) == PN_OK);
        /* a second step finds most X from the first one's (its cache of X per lattice point);
           the step keeps its last quadrature: check it at the latent it was built for */
        memcpy(pass ? A : l4, w->xhat, sizeof(double) * (pass ? 12 : 4));
        PN_CHECK(pn_rom_step(w, 1e-4, &st) == PN_OK);
        worst = 0, kept = 0;
        for (q = 0; q < st.quad_points; ++q) {
            double x[3], e = 0;
            int i;
            if (!w->qok[q]) continue;
            kept++;
            if (!pass) {
                pn_rom_eval(&t.m, l4, 1, w->qX + 3 * q, x, NULL, NULL);
                for (i = 0; i < 3; ++i) e = fmax(e, fabs(x[i] - w->qx[3 * q + i]));
            } else { /* X = (I + A)^-1 (x - b) */
                pn_real M[9], Mi[9];
                double r[3];
                int j;
                for (i = 0; i < 9; ++i) M[i] = A[3 + i] + (i / 3 == i % 3);
                pn_mat_inverse(3, M, Mi);
                for (i = 0; i < 3; ++i) r[i] = w->qx[3 * q + i] - A[i];
                for (i = 0; i < 3; ++i) {
                    double s = 0;
                    for (j = 0; j < 3; ++j) s += Mi[i * 3 + j] * r[j];
                    e = fmax(e, fabs(s - w->qX[3 * q + i]));
                }
            }
            worst = fmax(worst, e);
        }
        PN_REPORT("%s: %lu of %lu lattice points kept, %lu not inverted; worst |g(X) - x| or |X - X_exact| %.2e m (dx 4e-3)",
                  pass ? "affine" : "ELU", (unsigned long)kept, (unsigned long)st.quad_points, (unsigned long)st.inverse_failed,
                  worst);
        PN_CHECK(kept > 1000);
        PN_CHECK(st.inverse_failed == 0);
        PN_CHECK_LE(worst, pass ? 1e-12 : 1e-7); /* float: Newton stops within 1e-5 dx of its own float map */
        pn_rom_destroy(w);
        w = NULL;
    }
}

/* bad models and bad input are refused, naming the culprit, with nothing changed */
PN_TEST(rom_bad_input) {
    t_rom_net t;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    char why[256];
    double X[3 * 64], lo[3] = {0.02, 0.02, 0.02}, nanv[3] = {0, 0, 0}, f[3] = {1, 0, 0}, keep[4];
    int nb[3] = {4, 4, 4};
    size_t n = t_rom_box(3, lo, nb, 0.005, X);
    pn_rom_region reg;
    t_rom_random_model(&t, 3, 4, 1, 0.3);
    memset(&desc, 0, sizeof desc);
    desc.model = &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.25e-7;
    t.m.format_version = 99;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_FORMAT && w == NULL);
    PN_CHECK(strstr(why, "format_version") != NULL);
    t.m.format_version = PN_ROM_FORMAT_VERSION;
    t.m.dim = 2; /* a model of the wrong dimension for its widths */
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_DIMENSION);
    PN_CHECK(strstr(why, "width") != NULL);
    t.m.dim = 3;
    t.W[1][5] = NAN; /* a malformed model: PN_ERROR_FORMAT, as pn_model_check */
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_FORMAT);
    PN_CHECK(strstr(why, "layer 1") != NULL);
    t.W[1][5] = 0.1;
    desc.quadrature = (pn_rom_quadrature)7;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(strstr(why, "quadrature") != NULL);
    desc.quadrature = PN_ROM_EULERIAN;
    desc.integrator = (pn_rom_integrator)9;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && strstr(why, "integrator") != NULL);
    desc.integrator = PN_ROM_BDF2, desc.cubature_m = -1;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && strstr(why, "cubature_m") != NULL);
    desc.cubature_m = 0, desc.drive_weight = NAN;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && strstr(why, "drive_weight") != NULL);
    desc.integrator = PN_ROM_EXPLICIT, desc.drive_weight = 0;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_OK);
    if (!w) return;
    memcpy(keep, w->xhat, sizeof keep);
    memset(&reg, 0, sizeof reg);
    reg.lo[0] = 1, reg.hi[0] = 2; /* holds no point */
    PN_CHECK(pn_rom_drive(w, &reg, NULL, NULL, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(strstr(pn_rom_error(w), "none of the world's points") != NULL);
    memset(&reg, 0, sizeof reg);
    nanv[0] = NAN;
    PN_CHECK(pn_rom_drive(w, &reg, nanv, NULL, NULL, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(pn_rom_add_load(w, &reg, nanv, 1, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(pn_rom_add_load(w, &reg, f, -1, NULL) == PN_ERROR_INVALID_ARGUMENT);
    reg.radius = -1;
    PN_CHECK(pn_rom_drive(w, &reg, NULL, NULL, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_rom_step(w, -1, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_rom_step(w, NAN, NULL) == PN_ERROR_INVALID_ARGUMENT);
    {
        double nl[4] = {0, NAN, 0, 0}; /* the latent has 4 entries */
        PN_CHECK(pn_rom_set_latent(w, nl, NULL) == PN_ERROR_NONFINITE);
    }
    PN_CHECK(memcmp(keep, w->xhat, sizeof keep) == 0 && w->time_s == 0 && w->n_drives == 0 && w->n_loads == 0);
    pn_rom_destroy(w);
}

/* the same bits for 1 and 2 threads (Eulerian, Lagrangian and implicit, with a drive and a load) */
PN_TEST(rom_threads_identical) {
    t_rom_net t;
    double lo[3] = {0.02, 0.02, 0.02}, X[3 * 4096], keep[2][4];
    int nb[3] = {16, 16, 16}, quad, th, s;
    size_t n = t_rom_box(3, lo, nb, 0.0025, X);
    t_rom_random_model(&t, 3, 4, 2, 0.3);
    for (quad = 0; quad < 3; ++quad) {
        for (th = 1; th <= 2; ++th) {
            pn_rom_desc desc;
            pn_rom_world *w = NULL;
            pn_rom_region reg;
            double f[3] = {0.01, 0, -0.02};
            memset(&desc, 0, sizeof desc);
            desc.model = &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.5625e-8;
            desc.quadrature = quad ? PN_ROM_LAGRANGIAN : PN_ROM_EULERIAN, desc.parallel_min = 1, desc.gravity[2] = -9.81;
            desc.projection = quad ? PN_ROM_NONLINEAR : PN_ROM_LINEAR;
            desc.integrator = quad == 2 ? PN_ROM_BDF2 : PN_ROM_EXPLICIT, desc.cubature_m = 0.004;
            PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
            if (!w) return;
            memset(&reg, 0, sizeof reg);
            reg.lo[0] = reg.lo[1] = reg.lo[2] = 0, reg.hi[0] = reg.hi[1] = 1, reg.hi[2] = 0.025;
            PN_CHECK(pn_rom_drive(w, &reg, NULL, NULL, NULL, NULL) == PN_OK);
            reg.lo[2] = 0.055, reg.hi[2] = 1;
            PN_CHECK(pn_rom_add_load(w, &reg, f, 0.01, NULL) == PN_OK);
#ifdef _OPENMP
            omp_set_num_threads(th);
#endif
            for (s = 0; s < 5; ++s) PN_CHECK(pn_rom_step(w, quad == 2 ? 1e-2 : 1e-3, NULL) == PN_OK);
            memcpy(keep[th - 1], w->xhat, sizeof keep[0]);
            pn_rom_destroy(w);
        }
#ifdef _OPENMP
        omp_set_num_threads(2);
#endif
        PN_CHECK(memcmp(keep[0], keep[1], sizeof keep[0]) == 0);
        PN_REPORT("%s: latent after 5 steps %.6g %.6g ... identical for 1 and 2 threads",
                  quad == 2 ? "implicit (BDF2)" : quad ? "Lagrangian" : "Eulerian",
                  keep[0][0], keep[0][1]);
    }
}

/* The implicit integrators on an affine body in pure dilation about its centre, x = c + s(t)
   (X - c), no gravity and no drive: the latent minimization must reproduce the scalar
   recurrence of each scheme for s, written here from the energy of a dilation,
       min_s  I beta / 2 (s - sigma)^2 + V psi(s),   psi(s) = d mu (s - 1)^2 + lambda/2 (s^d - 1)^2
   (I = sum m |X - c|^2, fixed corotated at F = s 1), solved by scalar Newton. Every point is
   its own cubature point (cubature_m below the spacing), so the sums are exact. */
static double t_rom_dilation_step(int d, double I, double V, double mu, double lam, double beta, double sigma) {
    double s = sigma;
    int it;
    for (it = 0; it < 100; ++it) {
        double sd = pow(s, d), g = I * beta * (s - sigma) + V * (2 * d * mu * (s - 1) + lam * d * pow(s, d - 1) * (sd - 1));
        double H = I * beta + V * (2 * d * mu + lam * d * ((d - 1) * pow(s, d - 2) * (sd - 1) + d * pow(s, 2 * d - 2)));
        s -= g / H;
        if (fabs(g / H) < 1e-16) break;
    }
    return s;
}

PN_TEST(rom_implicit_dilation) {
    int d, scheme;
    for (d = 2; d <= 3; ++d)
        for (scheme = PN_ROM_IMPLICIT; scheme <= PN_ROM_MIDPOINT; ++scheme) {
            const double hx = 0.005, rho = 1000, E = 1e4, nu = 0.3, dt = 4e-3, sdot0 = 20;
            double X[3 * 216], lo[3] = {0.02, 0.02, 0.02}, c[3], xh[12], vh[12], I = 0, V, mu, lam, s = 1, sv = sdot0;
            double sp = 1, svp = sdot0, worst = 0, amp = 0, drift = -1;
            int nb[3] = {6, 6, 6}, i, step;
            size_t n = t_rom_box(d, lo, nb, hx, X), p;
            pn_rom_model am;
            pn_rom_desc desc;
            pn_rom_world *w = NULL;
            pn_rom_affine_model(d, &am);
            memset(&desc, 0, sizeof desc);
            desc.model = &am, desc.points = X, desc.n_points = n, desc.point_volume_m3 = pow(hx, d), desc.dx_m = 2 * hx;
            desc.youngs_pa = E, desc.poisson = nu, desc.density_kg_m3 = rho, desc.integrator = (pn_rom_integrator)scheme;
            desc.cubature_m = hx / 2, desc.newton_tol = 1e-12;
            PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
            if (!w) return;
            for (i = 0; i < d; ++i) c[i] = lo[i] + nb[i] * hx / 2;
            for (i = 0; i < d + d * d; ++i) xh[i] = vh[i] = 0;
            for (i = 0; i < d; ++i) vh[i] = -sdot0 * c[i], vh[d + i * d + i] = sdot0; /* b' = -s' c, A' = s' 1 */
            PN_CHECK(pn_rom_set_latent(w, xh, vh) == PN_OK);
            V = (double)n * pow(hx, d);
            for (p = 0; p < n; ++p)
                for (i = 0; i < d; ++i) I += rho * pow(hx, d) * (X[p * d + i] - c[i]) * (X[p * d + i] - c[i]);
            mu = E / (2 * (1 + nu)), lam = E * nu / ((1 + nu) * (1 - 2 * nu));
            for (step = 1; step <= 12; ++step) {
                double sn, svn, got = 0;
                int bdf = scheme == PN_ROM_BDF2 && step > 1;
                if (scheme == PN_ROM_MIDPOINT) {
                    double m = t_rom_dilation_step(d, I, V, mu, lam, 4 / (dt * dt), s + dt / 2 * sv);
                    sn = 2 * m - s, svn = 4 * (m - s) / dt - sv; /* v_n+1 = 2 v_n+1/2 - v_n */
                } else if (bdf) {
                    double tau = 2 * dt / 3;
                    sn = t_rom_dilation_step(d, I, V, mu, lam, 1 / (tau * tau), (4 * s - sp) / 3 + tau * (4 * sv - svp) / 3);
                    svn = (3 * sn - 4 * s + sp) / (2 * dt);
                } else {
                    sn = t_rom_dilation_step(d, I, V, mu, lam, 1 / (dt * dt), s + dt * sv);
                    svn = (sn - s) / dt;
                }
                sp = s, svp = sv, s = sn, sv = svn;
                amp = fmax(amp, fabs(s - 1));
                { /* the recurrence against an invariant: the midpoint rule keeps the energy
                     I s'^2 / 2 + V psi(s) (here nearly quadratic), the others only lose it */
                    double en = I * sv * sv / 2 + V * (d * mu * (s - 1) * (s - 1) + lam / 2 * (pow(s, d) - 1) * (pow(s, d) - 1));
                    double e0 = I * sdot0 * sdot0 / 2;
                    drift = fmax(drift, scheme == PN_ROM_MIDPOINT ? fabs(en - e0) / e0 : (en - e0) / e0);
                }
                PN_CHECK(pn_rom_step(w, dt, NULL) == PN_OK);
                for (i = 0; i < d; ++i) got += (w->xhat[d + i * d + i] + 1) / d; /* s = 1 + A_ii */
                worst = fmax(worst, fabs(got - s));
                for (i = 0; i < d; ++i) worst = fmax(worst, fabs(w->xhat[d + i * d + i] + 1 - s));
            }
            PN_REPORT("%dD %s: s after 12 steps %.6f (the scalar recurrence %.6f, amplitude %.3f), largest difference %.1e, "
                      "energy drift %+.2e", d, scheme == PN_ROM_IMPLICIT ? "backward Euler" : scheme == PN_ROM_BDF2 ? "BDF2" : "midpoint",
                      1 + w->xhat[d], s, amp, worst, drift);
            PN_CHECK(amp > 0.01); /* it moved */
            PN_CHECK_LE(drift, scheme == PN_ROM_MIDPOINT ? 0.05 : 1e-9);
            PN_CHECK_LE(worst, 1e-9);
            pn_rom_destroy(w);
        }
}

/* The implicit step's gradient (from F's central differences in the latent) against central
   differences of the incremental potential itself, on a nonlinear test map in double; and its
   Gauss-Newton Hessian against differences of the gradient on the affine map, where g is
   linear in the latent and (stretched, so dP/dF needs no projection) the Hessian is exact. */
PN_TEST(rom_implicit_gradient) {
    int d, aff;
    for (d = 2; d <= 3; ++d)
        for (aff = 0; aff <= 1; ++aff) {
            t_rom_net t;
            pn_rom_model am;
            pn_rom_desc desc;
            pn_rom_world *w = NULL;
            pn_test_rng r;
            double X[3 * 64], lo[3] = {0.02, 0.02, 0.02}, z[12], g[12], H[144], gp[12], gm[12], Hs[144], E, Ep, Em;
            double eg = 0, ng = 0, eh = 0, nh = 0;
            int nb[3] = {4, 4, 4}, K, i, j;
            size_t n = t_rom_box(d, lo, nb, 0.005, X), c;
            r.s = 5 + (unsigned long long)d;
            t_rom_random_model(&t, d, 4, 3, 0.3);
            pn_rom_affine_model(d, &am);
            memset(&desc, 0, sizeof desc);
            desc.model = aff ? &am : &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = pow(0.005, d);
            desc.reference = 1, desc.integrator = PN_ROM_IMPLICIT, desc.cubature_m = 0.01, desc.dx_m = 0.005;
            PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
            if (!w) return;
            K = w->latent;
            PN_CHECK(pn__rom_cubature(w) == PN_OK && w->n_c == (d == 2 ? 4u : 8u));
            for (c = 0; c < w->n_c; ++c) {
                w->cw[c] = pn_test_rng_range(&r, 10, 100);
                for (i = 0; i < d; ++i) w->ctgt[c * d + i] = w->cX[c * d + i] + pn_test_rng_range(&r, -0.002, 0.002);
            }
            for (i = 0; i < K; ++i) z[i] = w->xhat[i] + pn_test_rng_range(&r, -0.05, 0.05);
            if (aff)
                for (i = 0; i < d; ++i) z[d + i * d + i] = 0.1 + 0.05 * i; /* stretched */
            PN_CHECK(pn__rom_ip(w, z, &E, g, H));
            for (i = 0; i < K; ++i) {
                const double e = 1e-6;
                double zz[12];
                memcpy(zz, z, sizeof zz);
                zz[i] = z[i] + e;
                pn__rom_ip(w, zz, &Ep, gp, Hs);
                zz[i] = z[i] - e;
                pn__rom_ip(w, zz, &Em, gm, Hs);
                eg = fmax(eg, fabs((Ep - Em) / (2 * e) - g[i])), ng = fmax(ng, fabs(g[i]));
                for (j = 0; j < K; ++j) eh = fmax(eh, fabs((gp[j] - gm[j]) / (2 * e) - H[j * K + i])), nh = fmax(nh, fabs(H[j * K + i]));
            }
            PN_REPORT("%dD %s map: gradient against differences of E %.1e (of %.2g)", d, aff ? "affine" : "ELU", eg, ng);
            PN_CHECK_LE(eg, 1e-6 * ng);
            if (aff) {
                PN_REPORT("%dD affine map: Hessian against differences of the gradient %.1e (of %.2g)", d, eh, nh);
                PN_CHECK_LE(eh, 1e-6 * nh);
            }
            pn_rom_destroy(w);
        }
}

/* The render embedding: on the affine map the Taylor step from a node is exact (to float
   rounding); on a nonlinear map its error against pn_rom_map falls as spacing^2 (checked:
   halving the spacing divides it by more than 3); bad spacing and points refused. */
PN_TEST(rom_embed) {
    t_rom_net t;
    pn_rom_model am;
    int aff;
    for (aff = 1; aff >= 0; --aff) {
        pn_rom_desc desc;
        pn_rom_world *w = NULL;
        pn_rom_embedding *e = NULL;
        double lo[3] = {0.02, 0.02, 0.02}, X[3 * 512], err[2] = {0, 0}, xh[12];
        float Xf[3 * 512], xe[3 * 512], xr[3 * 512];
        int nb[3] = {8, 8, 8}, k, i;
        size_t n = t_rom_box(3, lo, nb, 0.005, X), p;
        t_rom_random_model(&t, 3, 4, 9, 0.3);
        pn_rom_affine_model(3, &am);
        memset(&desc, 0, sizeof desc);
        desc.model = aff ? &am : &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.25e-7, desc.dx_m = 0.005;
        PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
        if (!w) return;
        for (i = 0; i < w->latent; ++i) xh[i] = 0.1 * sin(1.0 + i); /* a deformed state */
        PN_CHECK(pn_rom_set_latent(w, xh, NULL) == PN_OK);
        for (p = 0; p < 3 * n; ++p) Xf[p] = (float)X[p];
        PN_CHECK(pn_rom_map(w, n, Xf, xr, NULL) == PN_OK);
        for (k = 0; k < 2; ++k) {
            PN_CHECK(pn_rom_embed(w, n, Xf, k ? 0.01 : 0.02, &e) == PN_OK);
            if (!e) return;
            PN_CHECK(e->n_nodes < n);
            PN_CHECK(pn_rom_embed_positions(w, e, xe) == PN_OK);
            for (p = 0; p < 3 * n; ++p) err[k] = fmax(err[k], fabs((double)xe[p] - (double)xr[p]));
            pn_rom_embed_destroy(e);
        }
        if (aff) {
            PN_REPORT("affine map: embedding off the exact map by %.1e m at most (float rounding)", fmax(err[0], err[1]));
            PN_CHECK_LE(fmax(err[0], err[1]), 1e-7);
        } else {
            PN_REPORT("ELU map: embedding off the exact map by %.2e m (spacing 2 cm), %.2e m (1 cm): ratio %.2f", err[0], err[1],
                      err[0] / err[1]);
            PN_CHECK(err[1] > 1e-7 && err[0] > 3 * err[1]);
        }
        Xf[4] = NAN;
        PN_CHECK(pn_rom_embed(w, n, Xf, 0.01, &e) == PN_ERROR_NONFINITE && e == NULL);
        PN_CHECK(strstr(pn_rom_error(w), "point 1") != NULL);
        Xf[4] = 0.03f;
        PN_CHECK(pn_rom_embed(w, n, Xf, 0, &e) == PN_ERROR_INVALID_ARGUMENT && e == NULL);
        pn_rom_destroy(w);
    }
}


/* ---- issue 42: hardening ------------------------------------------------------------------ */

/* Everything in a world that a later call reads, serialized into buf (NULL: the size): the
   struct (its error text left out) and every state array it points to (points, masses,
   sampling permutation, float weights, drives' point lists, the implicit cubature with its
   velocity history, the Eulerian inverse-map cache). Step scratch is rewritten before it is
   read and is left out. */
static void t_rom_put(unsigned char *buf, size_t *len, const void *ptr, size_t bytes) {
    if (!ptr) return;
    if (buf && bytes) memcpy(buf + *len, ptr, bytes);
    *len += bytes;
}

static size_t t_rom_state(const pn_rom_world *w, unsigned char *buf) {
    size_t len = 0, d = (size_t)w->dim;
    int a;
    pn_rom_world c = *w;
    memset(c.error, 0, sizeof c.error);
    t_rom_put(buf, &len, &c, sizeof c);
    t_rom_put(buf, &len, w->X, w->n * d * sizeof(double));
    t_rom_put(buf, &len, w->mass, w->n * sizeof(double));
    t_rom_put(buf, &len, w->vol, w->n * sizeof(double));
    t_rom_put(buf, &len, w->perm, w->n * sizeof(size_t));
    t_rom_put(buf, &len, w->px, w->n * d * sizeof(double));
    t_rom_put(buf, &len, w->wf, w->wf_off[w->model.activation == PN_ROM_ELU ? w->model.n_layers : 0] * sizeof(float));
    for (a = 0; a < w->n_drives; ++a) t_rom_put(buf, &len, w->drives[a].pts, w->drives[a].n_pts * sizeof(size_t));
    t_rom_put(buf, &len, w->cX, w->n_c * d * sizeof(double));
    t_rom_put(buf, &len, w->cm, w->n_c * sizeof(double));
    t_rom_put(buf, &len, w->cV, w->n_c * sizeof(double));
    t_rom_put(buf, &len, w->cvel, w->n_c * d * sizeof(double));
    t_rom_put(buf, &len, w->cxp, w->n_c * d * sizeof(double));
    t_rom_put(buf, &len, w->cvp, w->n_c * d * sizeof(double));
    t_rom_put(buf, &len, w->cv0, w->n_c * d * sizeof(double));
    t_rom_put(buf, &len, w->cdrv, w->n_c * sizeof(int));
    t_rom_put(buf, &len, w->cload, w->n_c * sizeof(unsigned));
    t_rom_put(buf, &len, w->xcX, w->n_xc * d * sizeof(double));
    t_rom_put(buf, &len, w->xc.key, w->xc.cap * sizeof(unsigned long long));
    t_rom_put(buf, &len, w->xc.val, w->xc.cap * sizeof(long));
    t_rom_put(buf, &len, w->xc.used, w->xc.n_used * sizeof(size_t));
    return len;
}

/* a serialized copy of w's state (free it) */
static unsigned char *t_rom_keep(const pn_rom_world *w, size_t *len) {
    unsigned char *b;
    *len = t_rom_state(w, NULL);
    b = (unsigned char *)malloc(*len);
    if (b) t_rom_state(w, b);
    return b;
}

/* w's state is bit for bit the copy kept */
static int t_rom_same(const pn_rom_world *w, const unsigned char *kept, size_t len) {
    unsigned char *now;
    size_t n;
    int same;
    if (!kept) return 0;
    now = t_rom_keep(w, &n);
    same = now && n == len && memcmp(now, kept, len) == 0;
    free(now);
    return same;
}

/* the test model with an occupancy grid of cells c^3 (cell h from 0.02 m): occupied where
   (i + j + k) % 3 != 0, or everywhere if full; returns the occupied count, counted here */
static size_t t_rom_occupy(t_rom_net *t, unsigned char *occ, int c, double h, int full) {
    int i, j, k;
    size_t n = 0;
    for (i = 0; i < c; ++i)
        for (j = 0; j < c; ++j)
            for (k = 0; k < c; ++k) {
                unsigned char o = (unsigned char)(full || (i + j + k) % 3 != 0);
                occ[(i * c + j) * c + k] = o;
                n += o;
            }
    t->m.cells[0] = t->m.cells[1] = t->m.cells[2] = c;
    t->m.cell_m = h;
    t->m.origin_m[0] = t->m.origin_m[1] = t->m.origin_m[2] = 0.02;
    t->m.occupied = occ, t->m.occupied_count = (size_t)(c * c * c);
    return n;
}

/* pn_rom_desc.refine: counted in closed form (refine 2000 used to count 1.6e13 points one at a
   time), refused above PN_ROM_MAX_REFINE and when the lattice would exceed PN_ROM_MAX_POINTS,
   naming refine; the lattice's first points where the cell-centred lattice puts them. */
PN_TEST(rom_refine_bound) {
    t_rom_net t;
    unsigned char occ[8 * 8 * 8];
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    char why[256];
    double X[3 * 10];
    size_t occupied, n;
    int i;
    t_rom_random_model(&t, 3, 4, 1, 0.3);
    occupied = t_rom_occupy(&t, occ, 4, 0.01, 0);
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_OK);
    PN_CHECK(pn_rom_lattice(&t.m, 1, NULL, 0) == occupied);
    n = pn_rom_lattice(&t.m, 3, X, 10);
    PN_CHECK(n == occupied * 27);
    /* the first occupied cell is (0, 0, 1): its 27 points at 0.02 + (c + (k + 1/2) / 3) 0.01 */
    for (i = 0; i < 10; ++i) {
        PN_CHECK_NEAR(X[3 * i + 0], 0.02 + (0 + (i / 9 + 0.5) / 3) * 0.01, 1e-15);
        PN_CHECK_NEAR(X[3 * i + 1], 0.02 + (0 + (i / 3 % 3 + 0.5) / 3) * 0.01, 1e-15);
        PN_CHECK_NEAR(X[3 * i + 2], 0.02 + (1 + (i % 3 + 0.5) / 3) * 0.01, 1e-15);
    }
    if (sizeof(size_t) >= 8) PN_CHECK(pn_rom_lattice(&t.m, 2000, NULL, 0) == occupied * (size_t)8000000000ull);
    PN_CHECK(pn_rom_lattice(&t.m, 1 << 30, NULL, 0) == (size_t)-1); /* (2^30)^3 does not fit */
    memset(&desc, 0, sizeof desc);
    desc.model = &t.m, desc.refine = 2000;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && w == NULL);
    PN_CHECK(strstr(why, "refine = 2000") != NULL && strstr(why, "PN_ROM_MAX_REFINE") != NULL);
    PN_REPORT("refine 2000: %s", why);
    desc.refine = -3;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && strstr(why, "refine = -3") != NULL);
    desc.refine = 2;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_OK && w && w->n == occupied * 8);
    pn_rom_destroy(w), w = NULL;
    /* 512 occupied cells at refine 64: 1.3e8 points, above PN_ROM_MAX_POINTS (6.7e7) */
    occupied = t_rom_occupy(&t, occ, 8, 0.005, 1);
    desc.refine = 64;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_CAPACITY && w == NULL);
    PN_CHECK(strstr(why, "refine = 64") != NULL && strstr(why, "PN_ROM_MAX_POINTS") != NULL);
    PN_REPORT("%lu cells at refine 64: %s", (unsigned long)occupied, why);
}

/* The explicit step's bound: pn_rom_stable_dt is 1.8 dx / (c + |v|), c the P-wave speed
   written out here from E, nu, rho; on an affine body released from a stretch (every point
   sampled, Lagrangian quadrature) 400 steps at half the bound stay finite with the total energy
   (kinetic + fixed corotated elastic, summed here from the affine state) bounded: within 25 %
   of the start, and not growing from the first 100 steps to the last 100; 20 times the bound, and the 10 s, are refused naming the bound with the world
   bit for bit as it was. The implicit step refuses 1e30 s of gravity (free flight of 1e60 m)
   the same way, held or not, and still takes a frame. */
PN_TEST(rom_stable_dt) {
    const double E = 1e4, nu = 0.3, rho = 1000, dx = 1.0 / 64, h = dx / 2;
    const double lam = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu)), c = sqrt((lam + 2 * mu) / rho);
    double lo[3] = {0.3, 0.35, 0}, X[2 * 400], lat[6] = {0, 0, 0.04, 0, 0, -0.03}, vl[6] = {1, 0, 0, 0, 0, 0};
    double bound = 0, E0 = 0, Emax = 0, Emin = HUGE_VAL, Ekmax = 0, Efirst = 0, Elast = 0;
    int nb[3] = {20, 16, 1}, s, i;
    size_t n = t_rom_box(2, lo, nb, h, X), p, len;
    pn_rom_model am;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    pn_material mat;
    pn_material_desc md;
    unsigned char *kept;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED, md.plastic = PN_PLASTIC_NONE, md.youngs_modulus_pa = E, md.poisson_ratio = nu;
    PN_CHECK(pn_material_init(&mat, &md, NULL, 0) == PN_OK);
    pn_rom_affine_model(2, &am);
    memset(&desc, 0, sizeof desc);
    desc.model = &am, desc.points = X, desc.n_points = n, desc.point_volume_m3 = h * h, desc.dx_m = dx;
    desc.youngs_pa = E, desc.poisson = nu, desc.density_kg_m3 = rho, desc.samples = -1;
    desc.quadrature = PN_ROM_LAGRANGIAN;
    PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
    if (!w) return;
    PN_CHECK(pn_rom_stable_dt(w, &bound) == PN_OK);
    PN_CHECK_NEAR(bound, 1.8 * dx / c, 1e-12 * bound);
    PN_CHECK(pn_rom_set_latent(w, lat, vl) == PN_OK); /* moving at 1 m/s: the bound shrinks */
    PN_CHECK(pn_rom_stable_dt(w, &bound) == PN_OK);
    PN_CHECK_NEAR(bound, 1.8 * dx / (c + 1), 1e-12 * bound);
    PN_CHECK(pn_rom_set_latent(w, lat, NULL) == PN_OK);
    PN_CHECK(pn_rom_stable_dt(w, &bound) == PN_OK);
    for (s = 0; s <= 400; ++s) {
        const double *b = w->xhat, *vb = w->vhat; /* x = X + b + A X: F = 1 + A, v = vb + vA X */
        pn_real F[4], psi = 0;
        double Ek = 0, Et;
        for (i = 0; i < 4; ++i) F[i] = (pn_real)((i == 0 || i == 3) + b[2 + i]);
        pn_elastic_energy(&mat, 2, F, 0, &psi, NULL, NULL, 0);
        for (p = 0; p < n; ++p) {
            const double *Xp = X + 2 * p;
            double v0 = vb[0] + vb[2] * Xp[0] + vb[3] * Xp[1], v1 = vb[1] + vb[4] * Xp[0] + vb[5] * Xp[1];
            Ek += 0.5 * rho * h * h * (v0 * v0 + v1 * v1);
        }
        Et = Ek + (double)n * h * h * (double)psi;
        if (s == 0) E0 = Et;
        Emax = fmax(Emax, Et), Emin = fmin(Emin, Et), Ekmax = fmax(Ekmax, Ek);
        if (s < 100) Efirst = fmax(Efirst, Et);
        if (s > 300) Elast = fmax(Elast, Et);
        if (s == 400) break;
        if (pn_rom_step(w, 0.5 * bound, NULL) != PN_OK) {
            PN_CHECK(!"a step at half the bound failed");
            break;
        }
    }
    PN_REPORT("bound %.4g s (1.8 dx / c, c = %.3f m/s); 400 steps at half of it: total energy %.4g J at the start, %.4g .. "
              "%.4g J, kinetic up to %.3g J; largest in steps 0-99 %.4g J, in 301-400 %.4g J", bound, c, E0, Emin, Emax, Ekmax,
              Efirst, Elast);
    PN_CHECK(pn__rom_all_finite(6, w->xhat) && pn__rom_all_finite(6, w->vhat));
    /* symplectic Euler's energy swings by about omega dt / 2 (here ~10 %) but must not grow */
    PN_CHECK_LE(Emax, 1.25 * E0);
    PN_CHECK_LE(Elast, 1.05 * Efirst);
    PN_CHECK(Emin > 0.5 * E0 && Ekmax > 0.2 * E0); /* it moved, and did not lose the energy either */
    kept = t_rom_keep(w, &len);
    PN_CHECK(pn_rom_step(w, 20 * bound, NULL) == PN_ERROR_STEP_TOO_LARGE);
    PN_CHECK(strstr(pn_rom_error(w), "pn_rom_stable_dt") != NULL);
    PN_REPORT("20 x the bound: %s", pn_rom_error(w));
    PN_CHECK(pn_rom_step(w, 10, NULL) == PN_ERROR_STEP_TOO_LARGE);
    PN_CHECK(pn_rom_step(w, 1e30, NULL) == PN_ERROR_STEP_TOO_LARGE);
    PN_CHECK(t_rom_same(w, kept, len));
    free(kept);
    PN_CHECK(pn_rom_stable_dt(w, &bound) == PN_OK && pn_rom_step(w, bound, NULL) == PN_OK); /* at the bound: taken */
    PN_CHECK(pn_rom_stable_dt(w, &bound) == PN_OK && pn_rom_step(w, 1.49 * bound, NULL) == PN_OK); /* measured stable */
    PN_CHECK(pn_rom_stable_dt(w, &bound) == PN_OK && pn_rom_step(w, 1.51 * bound, NULL) == PN_ERROR_STEP_TOO_LARGE);
    pn_rom_destroy(w), w = NULL;
    { /* BDF2 under gravity: 1e30 s refused (free and held), a frame taken */
        t_rom_net t;
        double B[3 * 512], lo3[3] = {0.02, 0.02, 0.02};
        int nb3[3] = {8, 8, 8}, held;
        size_t n3 = t_rom_box(3, lo3, nb3, 0.005, B);
        t_rom_random_model(&t, 3, 4, 1, 0.3);
        for (held = 0; held <= 1; ++held) {
            pn_rom_region base;
            memset(&desc, 0, sizeof desc);
            desc.model = &t.m, desc.points = B, desc.n_points = n3, desc.point_volume_m3 = 1.25e-7;
            desc.integrator = PN_ROM_BDF2, desc.gravity[2] = -9.81, desc.cubature_m = 0.01;
            PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
            if (!w) return;
            memset(&base, 0, sizeof base);
            base.hi[0] = base.hi[1] = 1, base.hi[2] = 0.026;
            if (held) PN_CHECK(pn_rom_drive(w, &base, NULL, NULL, NULL, NULL) == PN_OK);
            PN_CHECK(pn_rom_step(w, 1.0 / 60, NULL) == PN_OK);
            PN_CHECK(pn_rom_step(w, 1.0 / 60, NULL) == PN_OK);
            kept = t_rom_keep(w, &len);
            PN_CHECK(pn_rom_step(w, 1e30, NULL) == PN_ERROR_STEP_TOO_LARGE);
            PN_CHECK(strstr(pn_rom_error(w), "dt_s = 1e+30") != NULL && strstr(pn_rom_error(w), "body's size") != NULL);
            if (held) PN_REPORT("BDF2, held, 1e30 s: %s", pn_rom_error(w));
            PN_CHECK(t_rom_same(w, kept, len));
            free(kept);
            PN_CHECK(pn_rom_step(w, 1.0 / 60, NULL) == PN_OK);
            pn_rom_destroy(w), w = NULL;
        }
    }
}

/* pn_rom_model carries its arrays' lengths (format 2): every disagreement between a length
   and the sizes, an occupancy grid of absurd or overflowing size, and non-finite values are
   refused naming the field (under the sanitizers: without reading past an array) */
PN_TEST(rom_model_counts) {
    t_rom_net t;
    unsigned char occ[16];
    char why[256];
    pn_rom_model am;
    int i;
    t_rom_random_model(&t, 3, 4, 1, 0.3);
    memset(occ, 1, sizeof occ);
    t.m.cells[0] = 2, t.m.cells[1] = 2, t.m.cells[2] = 4, t.m.cell_m = 0.01, t.m.occupied = occ, t.m.occupied_count = 16;
    t.m.origin_m[0] = t.m.origin_m[1] = t.m.origin_m[2] = 0.02;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_OK);
    t.width[1] = 16; /* wider than the weight arrays hold: the counts say so */
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "weight_count[0] = 84") != NULL);
    t.width[1] = 12;
    t.m.width_count = 4;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "width_count = 4") != NULL);
    t.m.width_count = 5;
    t.m.bias_count[2] = 11;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "bias_count[2] = 11") != NULL);
    t.m.bias_count[2] = 12;
    t.m.weight_count[5] = 3; /* a length past n_layers */
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "weight_count[5]") != NULL);
    t.m.weight_count[5] = 0;
    t.m.latent_std_count = 3;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "latent_std_count") != NULL);
    t.m.latent_std_count = 4;
    t.sd[2] = NAN;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "latent_std") != NULL);
    t.sd[2] = 1;
    t.b[3][1] = INFINITY;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "layer 3") != NULL);
    t.b[3][1] = 0;
    t.m.in_hi[1] = NAN;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "in_lo/in_hi") != NULL);
    t.m.in_hi[1] = 0.06;
    t.m.youngs_pa = NAN;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "youngs_pa") != NULL);
    t.m.youngs_pa = 1e4;
    /* the issue's: 2^20 cells per axis over a 16-byte occupancy array */
    t.m.cells[0] = t.m.cells[1] = t.m.cells[2] = 1 << 20;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_DIMENSION && strstr(why, "cells[0] = 1048576") != NULL);
    PN_REPORT("2^20 cells per axis: %s", why);
    t.m.cells[0] = t.m.cells[1] = t.m.cells[2] = 4096; /* each axis allowed, the product (2^36) is not */
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_DIMENSION && strstr(why, "occupancy cells") != NULL);
    t.m.cells[0] = 2, t.m.cells[1] = 2, t.m.cells[2] = 4;
    t.m.occupied_count = 15;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "occupied_count = 15") != NULL);
    t.m.occupied_count = 16, t.m.cells[1] = -2;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_DIMENSION && strstr(why, "cells[1] = -2") != NULL);
    t.m.cells[1] = 2, t.m.cell_m = -0.01;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_ERROR_FORMAT && strstr(why, "cell_m") != NULL);
    t.m.cell_m = 0.01;
    PN_CHECK(pn_rom_model_check(&t.m, why, sizeof why) == PN_OK);
    /* an affine model is checked as well (its domain used to pass unchecked) */
    pn_rom_affine_model(3, &am);
    PN_CHECK(pn_rom_model_check(&am, why, sizeof why) == PN_OK);
    am.cells[0] = am.cells[1] = am.cells[2] = 1 << 20, am.occupied = occ, am.occupied_count = 16, am.cell_m = 0.01;
    PN_CHECK(pn_rom_model_check(&am, why, sizeof why) == PN_ERROR_DIMENSION);
#ifdef PN_TEST_HAVE_ROM_MODELS
    for (i = 0; i < PN_ROM_MODEL_COUNT; ++i) { /* the converted headers: lengths as the sizes give them */
        const pn_rom_model *m = pn_rom_models_all[i]();
        int l, ok = m->format_version == 2 && m->width_count == m->n_layers + 1;
        for (l = 0; l < m->n_layers; ++l) ok &= m->weight_count[l] == m->width[l] * m->width[l + 1] && m->bias_count[l] == m->width[l + 1];
        ok &= m->occupied_count == (size_t)m->cells[0] * (size_t)m->cells[1] * (size_t)m->cells[2];
        ok &= m->latent_rest_count == m->latent && m->latent_std_count == m->latent;
        PN_CHECK(ok && pn_rom_model_check(m, why, sizeof why) == PN_OK);
    }
#else
    (void)i;
#endif
}

/* NaN, infinite, negative or out-of-range description fields are refused naming the field
   (zero still means the default); pn_rom_map refuses a NaN or infinite reference point and
   writes nothing */
PN_TEST(rom_desc_nan) {
    static const char *const field[] = {"youngs_pa", "dx_m", "refine", "poisson", "density_kg_m3", "youngs_pa",
                                        "dx_m", "point_volume_m3", "gravity", "boundary_samples", "quad_per_axis",
                                        "gn_max", "parallel_min", "cubature_m", "newton_max", "newton_tol",
                                        "drive_weight", "density_kg_m3", "n_points", "newton_tol", "gn_max"};
    t_rom_net t;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    char why[256];
    double X[3 * 64], lo[3] = {0.02, 0.02, 0.02};
    int nb[3] = {4, 4, 4}, k;
    size_t n = t_rom_box(3, lo, nb, 0.005, X), len;
    float Xf[3 * 4], xf[3 * 4];
    unsigned char *kept;
    t_rom_random_model(&t, 3, 4, 1, 0.3);
    for (k = 0; k < (int)(sizeof field / sizeof field[0]); ++k) {
        memset(&desc, 0, sizeof desc);
        desc.model = &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.25e-7;
        switch (k) {
        case 0: desc.youngs_pa = NAN; break;
        case 1: desc.dx_m = -1; break;
        case 2: desc.refine = -3; break;
        case 3: desc.poisson = NAN; break;
        case 4: desc.density_kg_m3 = -1000; break;
        case 5: desc.youngs_pa = INFINITY; break;
        case 6: desc.dx_m = NAN; break;
        case 7: desc.point_volume_m3 = NAN; break;
        case 8: desc.gravity[2] = INFINITY; break;
        case 9: desc.boundary_samples = -1; break;
        case 10: desc.quad_per_axis = -2; break;
        case 11: desc.gn_max = -1; break;
        case 12: desc.parallel_min = -5; break;
        case 13: desc.cubature_m = NAN; break;
        case 14: desc.newton_max = -1; break;
        case 15: desc.newton_tol = -1e-3; break;
        case 16: desc.drive_weight = -INFINITY; break;
        case 17: desc.density_kg_m3 = NAN; break;
        case 18: desc.points = NULL; break; /* n_points without points */
        case 19: desc.newton_tol = NAN; break;
        default: desc.gn_max = 1 << 30; break; /* a hang per step */
        }
        PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && w == NULL);
        if (!strstr(why, field[k])) {
            PN_CHECK(!"the message names the field");
            fprintf(stderr, "    case %d (%s): %s\n", k, field[k], why);
        }
    }
    memset(&desc, 0, sizeof desc); /* zeros: the defaults */
    desc.model = &t.m, desc.points = X, desc.n_points = n, desc.point_volume_m3 = 1.25e-7;
    PN_CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_OK);
    if (!w) return;
    PN_CHECK(w->desc.youngs_pa == t.m.youngs_pa && w->desc.dx_m == t.m.dx_m && w->desc.refine == 1);
    for (k = 0; k < 12; ++k) Xf[k] = 0.03f, xf[k] = -7.0f;
    kept = t_rom_keep(w, &len);
    Xf[7] = NAN; /* point 2, axis 1 */
    PN_CHECK(pn_rom_map(w, 4, Xf, xf, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(strstr(pn_rom_error(w), "reference point 2") != NULL);
    Xf[7] = 0.03f, Xf[11] = INFINITY;
    PN_CHECK(pn_rom_map(w, 4, Xf, xf, NULL) == PN_ERROR_NONFINITE);
    for (k = 0; k < 12; ++k) PN_CHECK(xf[k] == -7.0f);
    PN_CHECK(pn_rom_positions(w, n - 1, 2, xf, NULL) == PN_ERROR_INVALID_ARGUMENT && strstr(pn_rom_error(w), "beyond") != NULL);
    PN_CHECK(t_rom_same(w, kept, len));
    free(kept);
    Xf[11] = 0.03f;
    PN_CHECK(pn_rom_map(w, 4, Xf, xf, NULL) == PN_OK && xf[0] != -7.0f);
    pn_rom_destroy(w);
}

#ifdef PN_TEST_HAVE_ROM_MODELS
/* The shipped cylinder model against the full-order explicit MPM of plastinet_mpm.h on a
   test instance (g = 9.38 m/s^2, never trained on), both from rest for 6 frames (0.042 s,
   the first quarter swing): the reduced model (Eulerian quadrature, linear projection, 50
   projection points, at the full-order step) must stay within 1% relative L2 position error
   (the paper's measure; its cylinder reaches < 1% with 10 points) and its occupancy lattice
   must be the training points. */
/* the cylinder scene's instance `in` as a full-order MPM world (fixed corotated, sticky
   walls, its drives), its points in X; returns the point count (0 on failure) */
static size_t t_rom_cylinder_mpm(const pn_rs_scene *s, const pn_rs_instance *in, pn_mpm_world **mw, double *X, size_t cap) {
    pn_mpm_desc wd;
    pn_material_desc md;
    pn_material mat;
    int g, i;
    memset(&wd, 0, sizeof wd);
    wd.dim = 3, wd.dx_m = s->dx, wd.boundary = PN_BOUNDARY_STICKY, wd.max_particles = cap;
    for (i = 0; i < 3; ++i) wd.res[i] = s->res[i], wd.gravity[i] = in->gravity[i];
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED, md.plastic = PN_PLASTIC_NONE, md.youngs_modulus_pa = s->youngs_pa;
    md.poisson_ratio = s->poisson;
    *mw = NULL;
    if (pn_mpm_create(&wd, mw, NULL, 0) != PN_OK || pn_material_init(&mat, &md, NULL, 0) != PN_OK) return 0;
    g = pn_mpm_add_group(*mw, &mat, s->density);
    return pn_rs_setup(*mw, g, s, in, 1, NULL, X, cap);
}

PN_TEST(rom_cylinder_vs_mpm) {
    const pn_rom_model *m = pn_rom_model_cylinder();
    pn_rs_scene s = pn_rs_get(PN_RS_CYLINDER, 1);
    pn_rs_instance in = pn_rs_instance_of(&s, 27);
    size_t cap = pn_rs_points(&s, 1, NULL, 0), n, p;
    double *X = (double *)malloc(sizeof(double) * 3 * cap), *L = (double *)malloc(sizeof(double) * 3 * cap), se = 0, sn = 0;
    float *x = (float *)malloc(sizeof(float) * 3 * cap);
    pn_mpm_world *mw = NULL;
    pn_rom_desc desc;
    pn_rom_world *w = NULL, *wi = NULL;
    pn_real dts;
    double sei = 0;
    int f, k, nsub, same = 1;
    PN_CHECK(in.test == 1);
    n = t_rom_cylinder_mpm(&s, &in, &mw, X, cap);
    if (!mw) return;
    PN_CHECK(n == 1600 && pn_rom_lattice(m, 1, NULL, 0) == n);
    pn_rom_lattice(m, 1, L, n);
    for (p = 0; p < 3 * n; ++p) same &= fabs(L[p] - X[p]) < 1e-8; /* the header's cells come from float32 X */
    PN_CHECK(same);
    memset(&desc, 0, sizeof desc);
    desc.model = m, desc.gravity[1] = in.gravity[1], desc.samples = 50;
    PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
    if (!w) return;
    PN_CHECK(pn_rs_rom_setup(w, &in));
    PN_CHECK(pn_rom_fit(w, X, NULL, NULL) == PN_OK);
    desc.integrator = PN_ROM_BDF2, desc.cubature_m = 2 * s.dx; /* the implicit twin: one step per frame */
    PN_CHECK(pn_rom_create(&desc, &wi, NULL, 0) == PN_OK);
    if (!wi) return;
    PN_CHECK(pn_rs_rom_setup(wi, &in));
    PN_CHECK(pn_rom_fit(wi, X, NULL, NULL) == PN_OK);
    pn_mpm_stable_dt(mw, &dts);
    nsub = (int)ceil(s.frame_dt / (0.7 * (double)dts));
    for (f = 1; f <= 6; ++f) {
        for (k = 0; k < nsub; ++k) {
            PN_CHECK(pn_mpm_step_explicit(mw, s.frame_dt / nsub, NULL) == PN_OK);
            PN_CHECK(pn_rom_step(w, s.frame_dt / nsub, NULL) == PN_OK);
        }
        PN_CHECK(pn_rom_step(wi, s.frame_dt, NULL) == PN_OK);
    }
    pn_rom_positions(wi, 0, n, x, NULL);
    for (p = 0; p < 3 * n; ++p) sei += ((double)x[p] - mw->x[p]) * ((double)x[p] - mw->x[p]);
    pn_rom_positions(w, 0, n, x, NULL);
    for (p = 0; p < 3 * n; ++p) se += ((double)x[p] - mw->x[p]) * ((double)x[p] - mw->x[p]), sn += (double)mw->x[p] * mw->x[p];
    PN_REPORT("implicit (BDF2, cubature of 2 dx cells), 6 steps of a frame: relative L2 position error %.3f%%", 100 * sqrt(sei / sn));
    PN_CHECK_LE(sqrt(sei / sn), 0.01);
    pn_rom_destroy(wi);
    {
        double tip = 0, tipr = 0;
        for (p = 0; p < n; ++p)
            if (X[3 * p] > 0.059) tip = fmin(tip, mw->x[3 * p + 1] - X[3 * p + 1]), tipr = fmin(tipr, x[3 * p + 1] - X[3 * p + 1]);
        PN_REPORT("after 6 frames (%d steps): relative L2 position error %.3f%%; free end sags %.2f mm (full order %.2f mm)",
                  6 * nsub, 100 * sqrt(se / sn), -1e3 * tipr, -1e3 * tip);
        PN_CHECK(tip < -1e-3); /* the scene moved */
    }
    PN_CHECK_LE(sqrt(se / sn), 0.01);
    pn_rom_destroy(w);
    pn_mpm_destroy(mw);
    free(X), free(L), free(x);
}
/* The implicit step drives what MPM holds: MPM sets every node a driven particle touches to
   the drive's velocity, so a free particle whose whole stencil lies on such nodes is held
   too. Measured here on plastinet_mpm.h itself (the cylinder against its wall, one step under
   gravity: the particles left exactly at rest), against the implicit cubature's driven
   points at one point per cubature cell; and with drive_region_only, just the region. */
PN_TEST(rom_drive_as_mpm) {
    const pn_rom_model *m = pn_rom_model_cylinder();
    pn_rs_scene s = pn_rs_get(PN_RS_CYLINDER, 1);
    pn_rs_instance in = pn_rs_instance_of(&s, 27);
    size_t cap = pn_rs_points(&s, 1, NULL, 0), n, p, c, held = 0, region = 0, agree = 0, agree_r = 0;
    double *X = (double *)malloc(sizeof(double) * 3 * cap);
    unsigned char *rest = (unsigned char *)calloc(cap, 1);
    pn_mpm_world *mw = NULL;
    int only;
    n = t_rom_cylinder_mpm(&s, &in, &mw, X, cap);
    if (!mw) return;
    PN_CHECK(pn_mpm_step_explicit(mw, s.frame_dt / 20, NULL) == PN_OK);
    for (p = 0; p < n; ++p) {
        rest[p] = mw->v[3 * p] == 0 && mw->v[3 * p + 1] == 0 && mw->v[3 * p + 2] == 0;
        held += rest[p], region += pn_rs_in_region(&in.drive[0].region, X + 3 * p);
    }
    for (only = 0; only <= 1; ++only) {
        pn_rom_desc desc;
        pn_rom_world *w = NULL;
        memset(&desc, 0, sizeof desc);
        desc.model = m, desc.integrator = PN_ROM_BDF2, desc.cubature_m = s.dx / 2, desc.drive_region_only = only;
        PN_CHECK(pn_rom_create(&desc, &w, NULL, 0) == PN_OK);
        if (!w) break;
        PN_CHECK(pn_rs_rom_setup(w, &in));
        PN_CHECK(pn_rom_step(w, s.frame_dt, NULL) == PN_OK);
        PN_CHECK(w->n_c == n); /* one point per cell */
        for (c = 0; c < w->n_c; ++c) /* the cubature point's own point: the same X */
            for (p = 0; p < n; ++p)
                if (fabs(w->cX[3 * c] - X[3 * p]) + fabs(w->cX[3 * c + 1] - X[3 * p + 1]) + fabs(w->cX[3 * c + 2] - X[3 * p + 2]) < 1e-7) {
                    int mine = only ? pn_rs_in_region(&in.drive[0].region, X + 3 * p) : rest[p];
                    *(only ? &agree_r : &agree) += (w->cdrv[c] >= 0) == mine;
                    break;
                }
        pn_rom_destroy(w);
    }
    PN_REPORT("MPM holds %lu of %lu particles exactly at rest (%lu in the drive's region); the implicit step drives the same: "
              "%lu of %lu agree (region only: %lu of %lu)",
              (unsigned long)held, (unsigned long)n, (unsigned long)region, (unsigned long)agree, (unsigned long)n,
              (unsigned long)agree_r, (unsigned long)n);
    PN_CHECK(held > region && region > 0); /* MPM holds more than the region */
    PN_CHECK(agree == n && agree_r == n);
    pn_mpm_destroy(mw);
    free(X), free(rest);
}
#endif

static const pn_test_case pn_tests_rom[] = {
    {"rom_eval_fd", rom_eval_fd},
    {"rom_float_path", rom_float_path},
    {"rom_affine_equals_mpm", rom_affine_equals_mpm},
    {"rom_projections", rom_projections},
    {"rom_inverse_map", rom_inverse_map},
    {"rom_bad_input", rom_bad_input},
    {"rom_threads_identical", rom_threads_identical},
    {"rom_implicit_dilation", rom_implicit_dilation},
    {"rom_implicit_gradient", rom_implicit_gradient},
    {"rom_embed", rom_embed},
    {"rom_refine_bound", rom_refine_bound},
    {"rom_stable_dt", rom_stable_dt},
    {"rom_model_counts", rom_model_counts},
    {"rom_desc_nan", rom_desc_nan},
#ifdef PN_TEST_HAVE_ROM_MODELS
    {"rom_cylinder_vs_mpm", rom_cylinder_vs_mpm},
    {"rom_drive_as_mpm", rom_drive_as_mpm},
#endif
};
