/* test_mpm_transfer.c: plastinet_mpm.h's >>bin and >>transfer rooms (transfer_*): particle to
   grid and back keeps mass and momentum (APIC and the transfer filter), the filter keeps its
   share per simulated second in both integrators, and 1 and 2 OpenMP threads give the same
   bits (explicit, implicit, the stress formulation). Helpers: test_mpm_world.c. */

/* One step with random velocities, an elastic deformation and no walls in reach: the
   transfers keep mass exactly and momentum to rounding (sum_i grad w_i = 0), with APIC and
   with the FLIP share of the transfer filter (sum_p m_p sum_i w_ip v_i^n = sum_p m_p v_p). */
PN_TEST(transfer_conserves_mass_momentum) {
    int dim, f;
    for (dim = 2; dim <= 3; ++dim)
    for (f = 0; f < 2; ++f) {
        pn_mpm_world *w = t_mpm_world_f(dim, dim == 2 ? 64 : 24, 0, PN_BOUNDARY_STICKY, f ? 1e-3 : 0);
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
        PN_REPORT("dim %d, %s: %zu particles, 5 steps: mass change %.1e, momentum change %.2e of sum |m v|", dim,
                  f ? "filter 1e-3 s" : "APIC", n, fabs(m1 - m0), worst);
        pn_mpm_destroy(w);
    }
}

/* Kinetic energy left after T = 2 ms of a shear wave of 8 cells, v_x = sin(2 pi y / 8 dx) (a
   near-stress-free block, no gravity, no wall in reach), stepping at dt. */
static double t_mpm_filter_ke(int dim, int implicit, double tf, double dt) {
    pn_mpm_world *w = t_mpm_world_f(dim, dim == 2 ? 64 : 24, 0, PN_BOUNDARY_STICKY, tf);
    double lo[3] = {0.35, 0.35, 0.35}, sz[3] = {0.3, 0.3, 0.3}, ke[2] = {0, 0};
    size_t p, n;
    int g, i, k, steps = (int)(2e-3 / dt + 0.5), ok = 1;
    if (!w) return -1;
    g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1);
    n = t_mpm_block(w, g, lo, sz, NULL);
    for (p = 0; p < n; ++p) { /* and C = grad v, so that no step starts from a PIC transfer */
        double k = 2 * 3.14159265358979 / (8 * w->desc.dx_m);
        w->v[p * dim] = sin(k * w->x[p * dim + 1]);
        w->C[p * dim * dim + 1] = k * cos(k * w->x[p * dim + 1]);
    }
    for (k = 0; k < 2; ++k) {
        for (p = 0; p < n; ++p)
            for (i = 0; i < dim; ++i) ke[k] += 0.5 * w->mass[p] * w->v[p * dim + i] * w->v[p * dim + i];
        for (i = 0; i < steps && !k; ++i)
            ok &= (implicit ? pn_mpm_step_implicit(w, dt, NULL, NULL) : pn_mpm_step_explicit(w, dt, NULL)) == PN_OK;
    }
    pn_mpm_destroy(w);
    return ok ? ke[1] / ke[0] : -1;
}

/* APIC filters the velocities at every grid round trip, so the share of a wave's energy it
   keeps after T falls with the number of steps; the transfer filter keeps a share
   set per simulated second (exp(-(1 - c) T / tf) for a mode a round trip keeps as c). */
PN_TEST(transfer_filter_per_second) {
    int dim, imp;
    for (dim = 2; dim <= 3; ++dim)
        for (imp = 0; imp < 1 + (dim == 2); ++imp) {
            double a1 = t_mpm_filter_ke(dim, imp, 0, 1e-4), a2 = t_mpm_filter_ke(dim, imp, 0, 5e-5);
            double f1 = t_mpm_filter_ke(dim, imp, 1e-3, 1e-4), f2 = t_mpm_filter_ke(dim, imp, 1e-3, 5e-5);
            PN_CHECK(a1 > 0 && a2 > 0 && f1 > 0 && f2 > 0);
            /* the scene shows the effect: APIC at dt / 2 loses much more (twice, per step) */
            PN_CHECK_LE(1.3 * (1 - a1), 1 - a2);
            /* the filter still filters, and loses the same share at either dt */
            PN_CHECK_LE(f2, 0.99);
            PN_CHECK_LE(fabs(f1 - f2), 0.1 * (1 - f2));
            PN_REPORT("dim %d %s: energy kept after 2 ms at dt 1e-4 / 5e-5 s: APIC %.3f / %.3f, filter 1 ms %.3f / %.3f",
                      dim, imp ? "implicit" : "explicit", a1, a2, f1, f2);
        }
}

/* A column collapsing on a frictional floor, explicit and implicit: 1 and 2 OpenMP threads
   give the same bits (the gather P2G and the chunked reductions fix every summation order). */

/* The explicit step's vector lanes and thread slabs on a scene that exercises them: 2D snow
   thrown into the floor (clamped and elastic particles) beside a jelly block, and a 3D block
   falling on the floor; 1 and 2 threads give the same bits. */
#ifdef _OPENMP
static void t_mpm_threads_explicit(pn_test_ctx *pn__t, int dim) {
    pn_real *keep = NULL;
    size_t n = 0, bytes = 0, plastic = 0;
    int t, s;
    for (t = 1; t <= 2; ++t) {
        pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 64 : 24, -9.81, PN_BOUNDARY_SEPARATE);
        double lo[3] = {0.2, 0.15, 0.3}, sz[3] = {0.25, 0.2, 0.3}, lo2[3] = {0.55, 0.3, 0.3}, v[3] = {1, -3, 0};
        pn_material_desc md;
        pn_material m;
        int gs, gj;
        PN_CHECK(w != NULL);
        if (!w) return;
        t_snow_desc(&md);
        PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
        gs = pn_mpm_add_group(w, &m, 400);
        gj = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e5);
        w->desc.parallel_min_particles = 1; /* this small world on 2 threads too */
        omp_set_num_threads(t);
        n = t_mpm_block(w, gs, lo, sz, v);
        n += t_mpm_block(w, gj, lo2, sz, NULL);
        bytes = sizeof(pn_real) * n * (size_t)dim;
        plastic = 0;
        for (s = 0; s < 300; ++s) {
            pn_mpm_stats st;
            pn_result r = pn_mpm_step_explicit(w, 2e-4, &st);
            PN_CHECK(r == PN_OK);
            if (r != PN_OK) break;
            plastic += st.plastic;
        }
        if (t == 1) {
            keep = (pn_real *)malloc(bytes * (2 + dim));
            memcpy(keep, w->x, bytes);
            memcpy(keep + n * dim, w->v, bytes);
            memcpy(keep + 2 * n * dim, w->F, bytes * dim);
        } else {
            int same = memcmp(keep, w->x, bytes) == 0 && memcmp(keep + n * dim, w->v, bytes) == 0 &&
                       memcmp(keep + 2 * n * dim, w->F, bytes * dim) == 0;
            PN_CHECK(same && plastic > 0);
            PN_REPORT("explicit dim %d, snow and jelly, %zu particles, 300 steps (%zu clamped particle-steps): 1 and 2 "
                      "threads %s", dim, n, plastic, same ? "bitwise identical" : "DIFFER");
        }
        pn_mpm_destroy(w);
    }
    free(keep);
    omp_set_num_threads(2);
}
#endif

PN_TEST(transfer_threads_identical) {
#ifdef _OPENMP
    int implicit, t, g, s;
    static const char *const names[5] = {"explicit", "implicit", "implicit, stress formulation (1/60 s steps)",
                                         "implicit, stress per cell (1/60 s steps)",
                                         "implicit, stress by cells then particles (1/60 s steps)"};
    /* 2-4: the stress formulation's coloured sweeps; make test runs 0-2 and the 2D explicit scene,
       PN_TEST_FULL=1 (make test-all, CI) every one */
    for (implicit = 0; implicit < (pn_test_full() ? 5 : 3); ++implicit) {
        pn_real *keep = NULL;
        size_t n = 0, bytes = 0;
        for (t = 1; t <= 2; ++t) {
            pn_mpm_world *w = t_mpm_sand_world(32, 0.5, &g);
            double lo[2] = {0.4, 3.0 / 32}, sz[2] = {0.12, 0.24};
            pn_mpm_implicit_desc id;
            memset(&id, 0, sizeof id);
            id.fixed_point_iters = 2;
            if (implicit >= 2) id.formulation = PN_MPM_FORMULATION_STRESS;
            id.stress_unknowns = implicit == 3   ? PN_MPM_STRESS_CELLS
                                 : implicit == 4 ? PN_MPM_STRESS_CELLS_THEN_PARTICLES
                                                 : PN_MPM_STRESS_PARTICLES;
            if (w) w->desc.parallel_min_particles = 1; /* this small world on 2 threads too */
            omp_set_num_threads(t);
            n = t_mpm_block(w, g, lo, sz, NULL);
            bytes = sizeof(pn_real) * n * 2;
            for (s = 0; s < (implicit >= 2 ? 6 : implicit ? 40 : 400); ++s) {
                pn_result r = implicit >= 2 ? pn_mpm_step_implicit(w, 1.0 / 60, &id, NULL)
                              : implicit    ? pn_mpm_step_implicit(w, 1e-3, &id, NULL)
                                            : pn_mpm_step_explicit(w, 1e-4, NULL);
                PN_CHECK(r == PN_OK);
                if (r != PN_OK) break;
            }
            if (t == 1) {
                keep = (pn_real *)malloc(bytes * 2);
                memcpy(keep, w->x, bytes);
                memcpy(keep + n * 2, w->v, bytes);
            } else {
                PN_CHECK(memcmp(keep, w->x, bytes) == 0 && memcmp(keep + n * 2, w->v, bytes) == 0);
                PN_REPORT("%s, %zu particles, %s s: 1 and 2 threads %s", names[implicit], n,
                          implicit >= 2 ? "0.1" : "0.04", memcmp(keep, w->x, bytes) == 0 ? "bitwise identical" : "DIFFER");
            }
            pn_mpm_destroy(w);
        }
        free(keep);
        omp_set_num_threads(2);
    }
    t_mpm_threads_explicit(pn__t, 2);
    if (pn_test_full()) t_mpm_threads_explicit(pn__t, 3);
#else
    PN_REPORT("skipped: built without -fopenmp");
#endif
}

static const pn_test_case pn_tests_mpm_transfer[] = {
    {"transfer_conserves_mass_momentum", transfer_conserves_mass_momentum},
    {"transfer_filter_per_second", transfer_filter_per_second},
    {"transfer_threads_identical", transfer_threads_identical},
};
