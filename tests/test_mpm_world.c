/* test_mpm_world.c: plastinet_mpm.h's >>world and >>drive rooms (drive_*): particles driven
   rigidly along an exact helix, a load's impulse, bad input to drives and to
   pn_mpm_set_particles. Also the helpers every test_mpm_*.c file builds its scenes with:
   t_mpm_world (a world on the unit box), t_mpm_group, t_mpm_block (a block of particles),
   t_mpm_sand_world, t_snow_desc, t_stress_desc, t_stress_scene. (>>fill and >>stable-dt: test_scene.c.)
   Expected values are invariants (momentum, exact rigid motions) computed independently. */

/* a world of res^dim cells on the unit box, sticky walls, no gravity unless set; transfer
   filter time tf (0: APIC) */
static pn_mpm_world *t_mpm_world_f(int dim, int res, pn_real gy, pn_boundary b, double tf) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    memset(&wd, 0, sizeof wd);
    wd.dim = dim;
    wd.res[0] = wd.res[1] = wd.res[2] = res;
    wd.dx_m = 1.0 / res;
    wd.gravity[1] = gy;
    wd.boundary = b;
    wd.max_particles = 20000;
    wd.filter_time_s = tf;
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK) return NULL;
    return w;
}

static pn_mpm_world *t_mpm_world(int dim, int res, pn_real gy, pn_boundary b) {
    return t_mpm_world_f(dim, res, gy, b, 0);
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
    if (pn_material_init(&m, &d, NULL, 0) != PN_OK) return -1;
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

/* sand of the shipped material family (Drucker-Prager 30 deg) on a frictional floor */
static pn_mpm_world *t_mpm_sand_world(int res, double friction, int *g) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    memset(&wd, 0, sizeof wd);
    wd.dim = 2;
    wd.res[0] = wd.res[1] = res;
    wd.dx_m = 1.0 / res;
    wd.gravity[1] = -9.81;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = friction;
    wd.max_particles = 20000;
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK) return NULL;
    *g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e6);
    return w;
}

/* Stomakhin snow as in the 88-line MLS-MPM scene (fixed corotated, E 1.4e5 Pa) */
static void t_snow_desc(pn_material_desc *md) {
    memset(md, 0, sizeof *md);
    md->elastic = PN_ELASTIC_FIXED_COROTATED;
    md->plastic = PN_PLASTIC_SNOW_STOMAKHIN;
    md->youngs_modulus_pa = 1.4e5;
    md->poisson_ratio = 0.2;
    md->snow_theta_c = 2.5e-2;
    md->snow_theta_s = 7.5e-3;
    md->snow_xi = 10;
}

static pn_mpm_implicit_desc t_stress_desc(void) {
    pn_mpm_implicit_desc id;
    memset(&id, 0, sizeof id);
    id.formulation = PN_MPM_FORMULATION_STRESS;
    return id;
}

/* the stress tests' scene: a 2D world (t_mpm_world) with one StVK-Hencky block of plastic
   model pl and modulus E at lo, size sz; NULL (a failed check) if any of it fails */
static pn_mpm_world *t_stress_scene(pn_test_ctx *pn__t, int res, pn_real gy, pn_boundary b, pn_plastic_model pl,
                                    double E, const double *lo, const double *sz, size_t *n) {
    pn_mpm_world *w = t_mpm_world(2, res, gy, b);
    int g;
    PN_CHECK(w != NULL);
    if (!w) return NULL;
    g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, pl, E);
    *n = g < 0 ? 0 : t_mpm_block(w, g, lo, sz, NULL);
    PN_CHECK(*n > 0);
    if (*n == 0) {
        pn_mpm_destroy(w);
        return NULL;
    }
    return w;
}

/* >>drive: a bar whose left end is pulled along its axis and spun about it. The driven
   particles must sit on the exact helix (the rotation about x written out here, independent of
   the library's Rodrigues form), the bar must follow (its free end moves), and 1 and 2 threads
   give the same bits. */
PN_TEST(drive_exact) {
    const double v = 0.2, om = 3.0, dt = 2e-4;
    int t, s;
    pn_real *keep = NULL;
    for (t = 1; t <= 2; ++t) {
        pn_mpm_world *w = t_mpm_world(3, 24, 0, PN_BOUNDARY_STICKY);
        double lo[3] = {0.3, 0.4, 0.4}, sz[3] = {0.4, 0.125, 0.125};
        pn_real vel[3] = {(pn_real)v, 0, 0}, c[3] = {0, 0.4625, 0.4625}, omega[3] = {(pn_real)om, 0, 0};
        pn_real blo[3] = {0, 0, 0}, bhi[3] = {0.35, 1, 1};
        size_t n, sel[4096], cnt = 0, k, far = 0;
        double x0[4096][3], err = 0, moved, farx0;
        int g, di = -1;
        PN_CHECK(w != NULL);
        if (!w) return;
        g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 2e4);
        w->desc.parallel_min_particles = 1;
#ifdef _OPENMP
        omp_set_num_threads(t);
#endif
        n = t_mpm_block(w, g, lo, sz, NULL);
        PN_CHECK(pn_mpm_select_box(w, blo, bhi, sel, 4096, &cnt) == PN_OK);
        PN_CHECK(cnt > 0 && cnt < n);
        for (k = 0; k < cnt; ++k)
            for (s = 0; s < 3; ++s) x0[k][s] = w->x[sel[k] * 3 + s];
        for (k = 0; k < n; ++k)
            if (w->x[k * 3] > w->x[far * 3]) far = k;
        farx0 = w->x[far * 3];
        PN_CHECK(pn_mpm_drive_particles(w, cnt, sel, vel, c, omega, &di) == PN_OK && di == 0);
        for (s = 0; s < 500; ++s)
            if (pn_mpm_step_explicit(w, dt, NULL) != PN_OK) break;
        PN_CHECK(s == 500);
        for (k = 0; k < cnt; ++k) {
            double T = 500 * dt, th = om * T, ry = x0[k][1] - c[1], rz = x0[k][2] - c[2];
            double e[3] = {x0[k][0] + v * T, c[1] + cos(th) * ry - sin(th) * rz, c[2] + sin(th) * ry + cos(th) * rz};
            for (s = 0; s < 3; ++s) err = fmax(err, fabs(w->x[sel[k] * 3 + s] - e[s]));
        }
        PN_REPORT("%d thread(s): driven particles off the helix by %.2e m; free end moved %.4f m along x", t, err,
                  w->x[far * 3] - farx0);
        PN_CHECK_LE(err, 1e-12);
        moved = w->x[far * 3] - farx0;
        /* the pull reached the far end: the drive moved 0.02 m, the P-wave crosses the bar in
           about 0.09 s of the 0.1 s, so the free end has started to follow, not caught up */
        PN_CHECK(moved > 0.005 && moved < 0.03);
        if (t == 1) {
            keep = (pn_real *)malloc(sizeof(pn_real) * n * 3);
            memcpy(keep, w->x, sizeof(pn_real) * n * 3);
        } else {
            PN_CHECK(memcmp(keep, w->x, sizeof(pn_real) * n * 3) == 0);
        }
        /* released: the end keeps its velocity and flies on; the step still conserves what it should */
        PN_CHECK(pn_mpm_release_drive(w, di) == PN_OK);
        PN_CHECK(pn_mpm_step_explicit(w, dt, NULL) == PN_OK);
        pn_mpm_destroy(w);
    }
#ifdef _OPENMP
    omp_set_num_threads(2);
#endif
    free(keep);
}

/* >>drive: a load's impulse. A free block (no gravity, far from the walls) under a force F for
   0.0105 s, stepped at dt = 1e-3 s (the window ends inside a step): its momentum must be F t
   to rounding, and stay there after the load ends; 2D and 3D. */
PN_TEST(drive_load_impulse) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_mpm_world(dim, 32, 0, PN_BOUNDARY_STICKY);
        double lo[3] = {0.4, 0.4, 0.4}, sz[3] = {0.2, 0.2, 0.2}, T = 0.0105;
        pn_real f[3] = {0.3, -0.2, 0.1}, blo[3] = {0.5, 0.5, 0.5}, bhi[3] = {1, 1, 1}, mass, mom[3];
        size_t sel[4096], cnt = 0;
        int g, s, i, li = -1;
        double err = 0;
        PN_CHECK(w != NULL);
        if (!w) return;
        g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e4);
        t_mpm_block(w, g, lo, sz, NULL);
        PN_CHECK(pn_mpm_select_box(w, blo, bhi, sel, 4096, &cnt) == PN_OK && cnt > 0);
        PN_CHECK(pn_mpm_add_load(w, cnt, sel, f, (pn_real)T, &li) == PN_OK && li == 0);
        for (s = 0; s < 20; ++s) PN_CHECK(pn_mpm_step_explicit(w, 1e-3, NULL) == PN_OK);
        pn_mpm_totals(w, &mass, mom);
        for (i = 0; i < dim; ++i) err = fmax(err, fabs(mom[i] - f[i] * T) / (0.3 * T));
        PN_REPORT("%dD: momentum after the load vs F t: relative error %.2e", dim, err);
        PN_CHECK_LE(err, 1e-10);
        pn_mpm_destroy(w);
    }
}

/* >>drive: bad input is refused with the culprit named and nothing changed */
PN_TEST(drive_bad_input) {
    pn_mpm_world *w = t_mpm_world(3, 16, 0, PN_BOUNDARY_STICKY);
    double lo[3] = {0.3, 0.3, 0.3}, sz[3] = {0.25, 0.25, 0.25};
    pn_real nanv[3] = {0, 0, 0}, f[3] = {1, 0, 0}, om[3] = {0, 0, 1}, c[3] = {0.4, 0.4, 0.4};
    size_t sel[2] = {0, 1}, bad[1] = {999999};
    int g, k, di;
    pn_mpm_implicit_desc o;
    PN_CHECK(w != NULL);
    if (!w) return;
    g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e4);
    t_mpm_block(w, g, lo, sz, NULL);
    nanv[1] = (pn_real)NAN;
    PN_CHECK(pn_mpm_drive_particles(w, 2, sel, nanv, NULL, NULL, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(pn_mpm_drive_particles(w, 1, bad, NULL, NULL, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(strstr(pn_mpm_error(w), "999999") != NULL);
    PN_CHECK(pn_mpm_drive_particles(w, 0, sel, NULL, NULL, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_mpm_drive_particles(w, 2, sel, NULL, NULL, om, NULL) == PN_ERROR_INVALID_ARGUMENT); /* spin, no centre */
    PN_CHECK(w->s.n_drives == 0);
    PN_CHECK(pn_mpm_drive_particles(w, 2, sel, NULL, c, om, &di) == PN_OK);
    PN_CHECK(pn_mpm_drive_particles(w, 1, sel + 1, NULL, NULL, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT); /* driven twice */
    PN_CHECK(strstr(pn_mpm_error(w), "particle 1") != NULL);
    for (k = 1; k < PN_MPM_MAX_DRIVES; ++k) {
        size_t one = (size_t)(10 + k);
        PN_CHECK(pn_mpm_drive_particles(w, 1, &one, NULL, NULL, NULL, NULL) == PN_OK);
    }
    {
        size_t one = 100;
        PN_CHECK(pn_mpm_drive_particles(w, 1, &one, NULL, NULL, NULL, NULL) == PN_ERROR_CAPACITY);
        PN_CHECK(pn_mpm_release_drive(w, 3) == PN_OK); /* a released slot is reused */
        PN_CHECK(pn_mpm_drive_particles(w, 1, &one, NULL, NULL, NULL, &di) == PN_OK && di == 3);
    }
    PN_CHECK(pn_mpm_release_drive(w, PN_MPM_MAX_DRIVES) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_mpm_add_load(w, 2, sel, f, -1, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_mpm_add_load(w, 2, sel, nanv, 1, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(w->s.n_loads == 0);
    memset(&o, 0, sizeof o);
    {
        pn_real x0 = w->x[0];
        PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &o, NULL) == PN_ERROR_UNSUPPORTED);
        PN_CHECK(strstr(pn_mpm_error(w), "drive") != NULL);
        PN_CHECK(w->x[0] == x0 && w->time_s == 0);
    }
    {
        pn_real xb[3] = {0.5, (pn_real)NAN, 0.5}, xo[3] = {2, 0.5, 0.5}, keep[3];
        memcpy(keep, w->x + 3 * 5, sizeof keep);
        PN_CHECK(pn_mpm_set_particles(w, 5, 1, xb, NULL, NULL, NULL, -1) == PN_ERROR_NONFINITE);
        PN_CHECK(pn_mpm_set_particles(w, 5, 1, xo, NULL, NULL, NULL, -1) == PN_ERROR_INVALID_ARGUMENT);
        PN_CHECK(pn_mpm_set_particles(w, w->n, 1, keep, NULL, NULL, NULL, -1) == PN_ERROR_INVALID_ARGUMENT);
        PN_CHECK(memcmp(keep, w->x + 3 * 5, sizeof keep) == 0);
    }
    pn_mpm_destroy(w);
}

static const pn_test_case pn_tests_mpm_world[] = {
    {"drive_exact", drive_exact},
    {"drive_load_impulse", drive_load_impulse},
    {"drive_bad_input", drive_bad_input},
};
