/* test_mpm.c: the explicit MPM solver of plastinet_mpm.h on small scenes (seconds in all).
   Expected values are invariants (mass, momentum, rest, free fall) computed independently. */

/* a world of res^dim cells on the unit box, sticky walls, no gravity unless set */
static pn_mpm_world *t_mpm_world(int dim, int res, pn_real gy, pn_mpm_boundary b) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    memset(&wd, 0, sizeof wd);
    wd.dim = dim;
    wd.res[0] = wd.res[1] = wd.res[2] = res;
    wd.dx_m = 1.0 / res;
    wd.gravity[1] = gy;
    wd.boundary = b;
    wd.max_particles = 20000;
    if (pn_mpm_create(&wd, &w) != PN_OK) return NULL;
    return w;
}

static int t_mpm_group(pn_mpm_world *w, pn_elastic_model e, pn_plastic_model pl, double E) {
    pn_material_desc d;
    pn_material m;
    memset(&d, 0, sizeof d);
    d.elastic = e;
    d.plastic = pl;
    d.youngs_modulus_pa = E;
    d.poisson_ratio = 0.3;
    d.friction_angle_deg = 30;
    if (pn_material_init(&m, &d, NULL) != PN_OK) return -1;
    return pn_mpm_add_group(w, &m, 1000);
}

/* a block of particles, 2 per cell per axis, lower corner lo, size sz (m) */
static size_t t_mpm_block(pn_mpm_world *w, int g, const double *lo, const double *sz, const double *v) {
    double x[3 * 4096], dx = w->desc.dx_m / 2, vol = 1;
    size_t n = 0;
    int i, j, k, c[3], d = w->dim;
    for (i = 0; i < d; ++i) {
        c[i] = (int)(sz[i] / dx + 0.5);
        vol *= dx;
    }
    for (i = 0; i < c[0]; ++i)
        for (j = 0; j < c[1]; ++j)
            for (k = 0; k < (d == 3 ? c[2] : 1) && n < 4096; ++k) {
                x[n * d] = lo[0] + (i + 0.5) * dx;
                x[n * d + 1] = lo[1] + (j + 0.5) * dx;
                if (d == 3) x[n * d + 2] = lo[2] + (k + 0.5) * dx;
                ++n;
            }
    {
        double vv[3 * 4096];
        size_t p;
        for (p = 0; p < n; ++p)
            for (i = 0; i < d; ++i) vv[p * d + i] = v ? v[i] : 0;
        if (pn_mpm_add_particles(w, g, n, x, vv, vol) != PN_OK) return 0;
    }
    return n;
}

/* One step with random velocities, an elastic deformation and no walls in reach: the
   transfers keep mass exactly and momentum to rounding (sum_i grad w_i = 0). */
PN_TEST(mpm_transfer_conserves_mass_momentum) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 64 : 24, 0, PN_MPM_BOUNDARY_STICKY);
        double lo[3] = {0.35, 0.35, 0.35}, sz[3] = {0.3, 0.3, 0.3}, m0, m1, p0[3], p1[3], pscale = 0;
        pn_test_rng rng;
        size_t p, n;
        int g, i, step;
        double worst = 0;
        PN_CHECK(w != NULL);
        if (!w) continue;
        g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e4);
        n = t_mpm_block(w, g, lo, sz, NULL);
        PN_CHECK(n > 100);
        rng.s = 99u + (unsigned)dim;
        for (p = 0; p < n; ++p) /* random velocities and a random elastic F near I */
            for (i = 0; i < dim; ++i) {
                int j;
                w->v[p * dim + i] = pn_test_rng_range(&rng, -0.1, 0.1);
                for (j = 0; j < dim; ++j) w->F[p * dim * dim + i * dim + j] += pn_test_rng_range(&rng, -0.05, 0.05);
            }
        pn_mpm_totals(w, &m0, p0);
        for (i = 0; i < dim; ++i) pscale += fabs(p0[i]);
        for (p = 0; p < n; ++p) pscale += w->mass[p] * 0.1;
        for (step = 0; step < 5; ++step) PN_CHECK(pn_mpm_step_explicit(w, 1e-4, NULL) == PN_OK);
        pn_mpm_totals(w, &m1, p1);
        for (i = 0; i < dim; ++i) worst = fmax(worst, fabs(p1[i] - p0[i]) / pscale);
        PN_CHECK(m1 == m0);
        PN_CHECK_LE(worst, 1e-12);
        PN_REPORT("dim %d: %zu particles, 5 steps: mass change %.1e, momentum change %.2e of sum |m v|", dim, n,
                  fabs(m1 - m0), worst);
        pn_mpm_destroy(w);
    }
}

/* An undeformed elastic block with no gravity stays exactly at rest. */
PN_TEST(mpm_elastic_block_at_rest) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 64 : 24, 0, PN_MPM_BOUNDARY_SLIP);
        double lo[3] = {0.3, 0.3, 0.3}, sz[3] = {0.4, 0.3, 0.3}, vmax = 0;
        size_t p, n;
        int g, step;
        pn_mpm_stats st;
        PN_CHECK(w != NULL);
        if (!w) continue;
        g = t_mpm_group(w, PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e5);
        n = t_mpm_block(w, g, lo, sz, NULL);
        for (step = 0; step < 100; ++step) PN_CHECK(pn_mpm_step_explicit(w, 1e-4, &st) == PN_OK);
        for (p = 0; p < n * dim; ++p) vmax = fmax(vmax, fabs(w->v[p]));
        PN_CHECK_LE(vmax, 1e-12);
        PN_REPORT("dim %d: %zu particles, 100 steps: largest speed %.1e m/s", dim, n, vmax);
        pn_mpm_destroy(w);
    }
}

/* Free fall before any contact: every particle's velocity is g t (the block is stress free
   and moves rigidly). dt = 2e-4 s is within the explicit limit (wave speed 10 m/s). */
PN_TEST(mpm_free_fall) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 64 : 24, -9.81, PN_MPM_BOUNDARY_STICKY);
        double lo[3] = {0.4, 0.6, 0.4}, sz[3] = {0.2, 0.2, 0.2}, worst = 0;
        size_t p, n;
        int g, step;
        PN_CHECK(w != NULL);
        if (!w) continue;
        g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e5);
        n = t_mpm_block(w, g, lo, sz, NULL);
        for (step = 0; step < 250; ++step) PN_CHECK(pn_mpm_step_explicit(w, 2e-4, NULL) == PN_OK);
        for (p = 0; p < n; ++p) worst = fmax(worst, fabs(w->v[p * dim + 1] - (-9.81 * 0.05)) / (9.81 * 0.05));
        PN_CHECK_LE(worst, 1e-10);
        PN_REPORT("dim %d: 250 steps of 0.2 ms: vertical velocity vs g t, worst relative %.1e", dim, worst);
        pn_mpm_destroy(w);
    }
}

/* Bad input: a NaN particle is refused whole; a step that meets a NaN deformation fails,
   names the particle and leaves every array as it was. */
PN_TEST(mpm_bad_input) {
    pn_mpm_world *w = t_mpm_world(2, 32, -9.81, PN_MPM_BOUNDARY_STICKY);
    double lo[3] = {0.3, 0.3, 0}, sz[3] = {0.2, 0.2, 0}, x[4] = {0.5, 0.5, NAN, 0.5};
    double *copy;
    size_t n, bytes;
    int g;
    pn_mpm_desc bad;
    pn_mpm_world *w2 = NULL;
    PN_CHECK(w != NULL);
    if (!w) return;
    g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e6);
    n = t_mpm_block(w, g, lo, sz, NULL);
    PN_CHECK(pn_mpm_add_particles(w, g, 2, x, NULL, 1e-4) == PN_ERROR_NONFINITE && w->n == n);
    x[2] = 0.001; /* inside the wall */
    PN_CHECK(pn_mpm_add_particles(w, g, 2, x, NULL, 1e-4) == PN_ERROR_INVALID_ARGUMENT && w->n == n);
    PN_CHECK(pn_mpm_add_particles(w, 7, 1, x, NULL, 1e-4) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_mpm_step_explicit(w, 1e-3, NULL) == PN_OK);
    w->F[5 * 4 + 1] = NAN; /* corrupt particle 5 */
    bytes = sizeof(double) * n * 2;
    copy = (double *)malloc(bytes * 2);
    memcpy(copy, w->x, bytes);
    memcpy(copy + n * 2, w->v, bytes);
    PN_CHECK(pn_mpm_step_explicit(w, 1e-3, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(w->error_particle == 5);
    PN_CHECK(memcmp(copy, w->x, bytes) == 0 && memcmp(copy + n * 2, w->v, bytes) == 0);
    PN_CHECK(w->steps == 1);
    PN_CHECK(pn_mpm_step_explicit(w, NAN, NULL) == PN_ERROR_INVALID_ARGUMENT);
    free(copy);
    pn_mpm_destroy(w);
    memset(&bad, 0, sizeof bad);
    bad.dim = 2;
    bad.res[0] = bad.res[1] = 32;
    bad.dx_m = -1;
    bad.max_particles = 10;
    PN_CHECK(pn_mpm_create(&bad, &w2) == PN_ERROR_INVALID_ARGUMENT && w2 == NULL);
}

/* Particles thrown through a wall faster than the walls can stop them are retired and counted,
   not lost or left outside the grid. */
PN_TEST(mpm_particles_leaving_domain) {
    pn_mpm_world *w = t_mpm_world(2, 32, 0, PN_MPM_BOUNDARY_SEPARATE);
    double lo[3] = {0.7, 0.4, 0}, sz[3] = {0.1, 0.1, 0}, v[3] = {400, 0, 0}, m, mom[3];
    size_t n;
    int g;
    pn_mpm_stats st;
    PN_CHECK(w != NULL);
    if (!w) return;
    g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e3);
    n = t_mpm_block(w, g, lo, sz, v);
    PN_CHECK(pn_mpm_step_explicit(w, 1e-3, &st) == PN_OK);
    PN_CHECK(st.left_domain > 0 && st.left_domain + st.particles == n && w->left_total == st.left_domain);
    pn_mpm_totals(w, &m, mom);
    PN_CHECK(pn_mpm_step_explicit(w, 1e-3, &st) == PN_OK);
    PN_REPORT("%zu particles at 400 m/s: %zu retired, %zu stay", n, (size_t)w->left_total, st.particles);
    pn_mpm_destroy(w);
}

static const pn_test_case pn_tests_mpm[] = {
    {"mpm_transfer_conserves_mass_momentum", mpm_transfer_conserves_mass_momentum},
    {"mpm_elastic_block_at_rest", mpm_elastic_block_at_rest},
    {"mpm_free_fall", mpm_free_fall},
    {"mpm_bad_input", mpm_bad_input},
    {"mpm_particles_leaving_domain", mpm_particles_leaving_domain},
};
