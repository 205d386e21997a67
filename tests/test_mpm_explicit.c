/* test_mpm_explicit.c: plastinet_mpm.h's >>explicit room (explicit_*): pn_mpm_step_explicit on
   small scenes: a block at rest stays at rest, free fall, bad input, outflow through a wall,
   the 2D closed-form snow clamp and stress of the vector lanes against plastinet.h's return
   mapping, inverted F. Expected values are invariants (rest, free fall g t, mass) computed
   independently. Helpers: test_mpm_world.c. */

/* An undeformed elastic block with no gravity stays exactly at rest. */
PN_TEST(explicit_elastic_block_at_rest) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 64 : 24, 0, PN_BOUNDARY_SLIP);
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
PN_TEST(explicit_free_fall) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 64 : 24, -9.81, PN_BOUNDARY_STICKY);
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
PN_TEST(explicit_bad_input) {
    pn_mpm_world *w = t_mpm_world(2, 32, -9.81, PN_BOUNDARY_STICKY);
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
    PN_CHECK(pn_mpm_create(&bad, &w2, NULL, 0) == PN_ERROR_INVALID_ARGUMENT && w2 == NULL);
    bad.dx_m = 1.0 / 32;
    bad.filter_time_s = -1e-3;
    PN_CHECK(pn_mpm_create(&bad, &w2, NULL, 0) == PN_ERROR_INVALID_ARGUMENT && w2 == NULL);
    bad.filter_time_s = NAN;
    PN_CHECK(pn_mpm_create(&bad, &w2, NULL, 0) == PN_ERROR_INVALID_ARGUMENT && w2 == NULL);
}

/* With outflow allowed (and the advection limit raised), particles thrown through a wall
   faster than the walls can stop them are retired and counted, not lost or left outside the
   grid (test_scene.c, scene_outflow: refused by default). */
PN_TEST(explicit_particles_leaving_domain) {
    pn_mpm_world *w = t_mpm_world(2, 32, 0, PN_BOUNDARY_SEPARATE);
    double lo[3] = {0.7, 0.4, 0}, sz[3] = {0.1, 0.1, 0}, v[3] = {400, 0, 0}, m, mom[3];
    size_t n;
    int g;
    pn_mpm_stats st;
    PN_CHECK(w != NULL);
    if (!w) return;
    w->desc.allow_outflow = 1;
    w->desc.advection_limit = 100;
    g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e3);
    n = t_mpm_block(w, g, lo, sz, v);
    PN_CHECK(pn_mpm_step_explicit(w, 1e-3, &st) == PN_OK);
    PN_CHECK(st.left_domain > 0 && st.left_domain + st.particles == n && w->left_total == st.left_domain);
    pn_mpm_totals(w, &m, mom);
    PN_CHECK(pn_mpm_step_explicit(w, 1e-3, &st) == PN_OK);
    PN_REPORT("%zu particles at 400 m/s: %zu retired, %zu stay", n, (size_t)w->left_total, st.particles);
    pn_mpm_destroy(w);
}

/* The explicit step's 2D closed-form Stomakhin clamp and fixed-corotated stress (the vector
   lanes of pn__mpm_xg2p2_lanes) against the SVD-based return mapping and stress of
   plastinet.h, on random F: near the identity, stretched past the box in one or both
   directions, inverted, pure dilations (no deviator: r = 0) and pure rotations. */
PN_TEST(explicit_snow2_closed_form) {
    pn_test_rng rng = {2013};
    pn_material_desc md;
    pn_material m[2];
    double worst_z = 0, worst_t = 0, worst_h = 0;
    int v, k, clamped_count = 0, inverted = 0, flag_mismatch = 0;
    t_snow_desc(&md);
    PN_CHECK(pn_material_init(&m[0], &md, NULL, 0) == PN_OK);
    md.snow_jp_min = 0.6, md.snow_jp_max = 20; /* with the J_p bounds */
    PN_CHECK(pn_material_init(&m[1], &md, NULL, 0) == PN_OK);
    for (v = 0; v < 2; ++v)
        for (k = 0; k < 4000; ++k) {
            pn_real F[4], Z[4], Z2[4], tau[4], tau2[4], h = (pn_real)pn_test_rng_range(&rng, -0.6, 0.6), hn, hn2 = h;
            pn_real mu, la, lo, hi, q, r, c, sn, ratio;
            double R[4], R2[4], big = 1;
            int i, kind = k % 5, clamped;
            t_rand_rot(&rng, 2, R);
            t_rand_rot(&rng, 2, R2);
            if (kind == 0 || kind == 4) { /* R diag(s0, s1) R2^T (4: R s0, a rotation times a dilation: r = 0) */
                double s0 = pn_test_rng_range(&rng, 0.9, 1.05), s1 = kind == 4 ? s0 : pn_test_rng_range(&rng, 0.9, 1.05);
                if (kind == 4) R2[0] = R[0], R2[1] = R[1], R2[2] = R[2], R2[3] = R[3];
                F[0] = (pn_real)(R[0] * s0 * R2[0] + R[1] * s1 * R2[1]), F[1] = (pn_real)(R[0] * s0 * R2[2] + R[1] * s1 * R2[3]);
                F[2] = (pn_real)(R[2] * s0 * R2[0] + R[3] * s1 * R2[1]), F[3] = (pn_real)(R[2] * s0 * R2[2] + R[3] * s1 * R2[3]);
            } else { /* R (I + a perturbation), sometimes reflected (inverted) */
                double E[4], sc = kind == 1 ? 0.01 : 0.2;
                for (i = 0; i < 4; ++i) E[i] = (i == 0 || i == 3 ? 1 : 0) + sc * t_gauss(&rng);
                if (kind == 3) E[1] = -E[1], E[3] = -E[3];
                F[0] = (pn_real)(R[0] * E[0] + R[1] * E[2]), F[1] = (pn_real)(R[0] * E[1] + R[1] * E[3]);
                F[2] = (pn_real)(R[2] * E[0] + R[3] * E[2]), F[3] = (pn_real)(R[2] * E[1] + R[3] * E[3]);
            }
            if (F[0] * F[3] - F[1] * F[2] < 0) inverted++;
            if (pn_return_map(&m[v], 2, F, h, Z, &hn, NULL) != PN_OK ||
                pn_kirchhoff_stress(&m[v], 2, Z, hn, tau) != PN_OK) {
                PN_CHECK(0);
                continue;
            }
            PN_CHECK(pn__fcr2_params(&m[v], &mu, &la, &lo, &hi));
            pn__fcr2_norms(F, &q, &r);
            q = PN__SQRT(q), r = PN__SQRT(r);
            pn__fcr2_rotation(F, q, &c, &sn);
            clamped = pn__snow2_clamp(F, q, r, c, sn, lo, hi, Z2, &ratio) != 0;
            if (clamped) { /* as pn__mpm_xg2p2_lanes */
                hn2 = h + PN__LOG(ratio);
                if (m[v].snow_h_min < 0 && hn2 < m[v].snow_h_min) hn2 = m[v].snow_h_min;
                if (m[v].snow_h_max > 0 && hn2 > m[v].snow_h_max) hn2 = m[v].snow_h_max;
            }
            clamped_count += clamped;
            flag_mismatch += clamped != (hn != h || memcmp(Z, F, sizeof Z) != 0);
            pn__fcr2_stress(Z2, c, sn, mu * pn__hardening(&m[v], hn2), la * pn__hardening(&m[v], hn2), tau2);
            for (i = 0; i < 4; ++i) {
                big = fabs((double)tau[i]) > big ? fabs((double)tau[i]) : big;
                worst_z = fabs((double)(Z[i] - Z2[i])) > worst_z ? fabs((double)(Z[i] - Z2[i])) : worst_z;
            }
            for (i = 0; i < 4; ++i)
                worst_t = fabs((double)(tau[i] - tau2[i])) / big > worst_t ? fabs((double)(tau[i] - tau2[i])) / big : worst_t;
            worst_h = fabs((double)(hn - hn2)) > worst_h ? fabs((double)(hn - hn2)) : worst_h;
        }
    /* independent paths (SVD and the invariants): rounding only. In double 1e-12; in float
       the SVD's own rounding at the smallest stretches dominates */
    PN_CHECK_LE(worst_z, sizeof(pn_real) == 4 ? 2e-5 : 1e-12);
    PN_CHECK_LE(worst_t, sizeof(pn_real) == 4 ? 2e-4 : 1e-10);
    PN_CHECK_LE(worst_h, sizeof(pn_real) == 4 ? 2e-5 : 1e-12);
    PN_CHECK(flag_mismatch == 0 && clamped_count > 1000 && inverted > 500);
    PN_REPORT("8000 random F (%d clamped, %d inverted): max |Z - Z_svd| %.1e, stress %.1e of its largest entry, "
              "log J_p %.1e; clamp decisions that differ: %d", clamped_count, inverted, worst_z, worst_t, worst_h,
              flag_mismatch);
}

/* Fixed corotated elasticity is defined for inverted F, and the Stomakhin clamp takes an
   inverted trial state back to det > 0: two snow blocks meeting at a step where the
   material inverts keep going; Neo-Hookean blocks, whose energy is undefined there, still
   fail with PN_ERROR_INVERTED and leave the world as it was. */
PN_TEST(explicit_inversion) {
    pn_material_desc md;
    pn_material snow, nh;
    pn_real F[4] = {1, 0, 0, -0.2}, Z[4], h = 0, T[4];
    int model;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED;
    md.plastic = PN_PLASTIC_SNOW_STOMAKHIN;
    md.youngs_modulus_pa = 1e4;
    md.poisson_ratio = 0.2;
    md.snow_theta_c = 2.5e-2;
    md.snow_theta_s = 7.5e-3;
    md.snow_xi = 10;
    md.snow_jp_min = 0.6;
    md.snow_jp_max = 20;
    PN_CHECK(pn_material_init(&snow, &md, NULL, 0) == PN_OK);
    /* the material point: clamped to [1 - theta_c, 1 + theta_s], J_p = 0.2 / 0.975 -> 0.6 */
    PN_CHECK(pn_return_map(&snow, 2, F, 0, Z, &h, T) == PN_OK);
    PN_CHECK(pn_mat_det(2, Z) > 0 && fabs(Z[0] - 1) < 1e-12 && fabs(Z[3] - 0.975) < 1e-12);
    PN_CHECK(fabs(h - log(0.6)) < 1e-12);
    md.plastic = PN_PLASTIC_NONE;
    md.elastic = PN_ELASTIC_NEO_HOOKEAN;
    PN_CHECK(pn_material_init(&nh, &md, NULL, 0) == PN_OK);
    PN_CHECK(pn_return_map(&nh, 2, F, 0, Z, &h, T) == PN_ERROR_INVERTED);
    md.snow_jp_min = 1; /* the bounds must straddle 1 */
    md.plastic = PN_PLASTIC_SNOW_STOMAKHIN;
    md.elastic = PN_ELASTIC_FIXED_COROTATED;
    PN_CHECK(pn_material_init(&nh, &md, NULL, 0) == PN_ERROR_INVALID_PARAMETER);
    md.plastic = PN_PLASTIC_NONE;
    md.elastic = PN_ELASTIC_NEO_HOOKEAN;
    PN_CHECK(pn_material_init(&nh, &md, NULL, 0) == PN_OK);
    for (model = 0; model < 2; ++model) { /* the MPM scene: two blocks meet at 2 x 20 m/s, twice the stable step */
        pn_mpm_world *w = t_mpm_world(2, 32, 0, PN_BOUNDARY_SEPARATE);
        double lo[3] = {0.25, 0.4, 0}, sz[3] = {0.2, 0.2, 0}, v[3] = {20, 0, 0};
        size_t n;
        int g, s, inverted = 0, failed = 0;
        pn_real dt;
        PN_CHECK(w != NULL);
        if (!w) continue;
        w->desc.advection_limit = 4;
        g = pn_mpm_add_group(w, model ? &nh : &snow, 400);
        n = t_mpm_block(w, g, lo, sz, v);
        lo[0] = 0.55, v[0] = -20;
        n += t_mpm_block(w, g, lo, sz, v);
        pn_mpm_stable_dt(w, &dt);
        for (s = 0; s < 40 && !failed; ++s) {
            pn_real x0 = w->x[0];
            long steps0 = w->steps;
            pn_result r = pn_mpm_step_explicit(w, 2 * dt, NULL);
            if (r != PN_OK) {
                failed = 1;
                if (model == 0) fprintf(stderr, "      snow, step %d: %s\n", s, pn_mpm_error(w));
                PN_CHECK(r == PN_ERROR_INVERTED && model == 1 && w->steps == steps0 && w->x[0] == x0);
            }
        }
        if (model == 0) {
            size_t p;
            for (p = 0; p < n; ++p) inverted += !(pn_mat_det(2, w->F + 4 * p) > 0) || !(w->h[p] >= log(0.6) - 1e-12);
            PN_CHECK(!failed && inverted == 0 && w->left_total == 0);
        } else {
            PN_CHECK(failed);
        }
        PN_REPORT("blocks meeting at 2 x 20 m/s, twice the stable step: %s %s", model ? "Neo-Hookean" : "Stomakhin snow",
                  failed ? "stops with PN_ERROR_INVERTED, world unchanged" : "runs 40 steps, every F with det > 0");
        pn_mpm_destroy(w);
    }
}

static const pn_test_case pn_tests_mpm_explicit[] = {
    {"explicit_elastic_block_at_rest", explicit_elastic_block_at_rest},
    {"explicit_free_fall", explicit_free_fall},
    {"explicit_bad_input", explicit_bad_input},
    {"explicit_particles_leaving_domain", explicit_particles_leaving_domain},
    {"explicit_snow2_closed_form", explicit_snow2_closed_form},
    {"explicit_inversion", explicit_inversion},
};
