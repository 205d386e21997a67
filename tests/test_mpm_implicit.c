/* test_mpm_implicit.c: plastinet_mpm.h's >>implicit room (implicit_*): pn_mpm_step_implicit's
   energies against the explicit step (an elastic block, a sand column, with the lagged
   energy and with PlasticityNet), PlasticityNet's Taylor models (pnet_reuse_tol), the force
   error, large steps of a learned energy, the energy guard (energy_rise_tol), bad input.
   Expected values come from the explicit reference run here and from invariants.
   Helpers: test_mpm_world.c. */

/* Implicit with an elastic energy against explicit at the same small step: an elastic block
   with a shearing velocity field, no gravity, 20 ms at dt and at dt / 2. Both integrators
   discretize space alike (the MLS velocity gradient of >>implicit), so they differ by
   their time integration only: the gap must be small and shrink with dt (first order,
   symplectic against backward Euler). A tight Newton tolerance, so that the solver's own
   stopping error (about newton_tol dx per step) does not hide the comparison. */
static double t_mpm_elastic_gap(pn_test_ctx *pn__t, int dim, double dt, double *rel) {
    int res = dim == 2 ? 32 : 16, step, i, steps = (int)(0.02 / dt + 0.5);
    pn_mpm_world *a = t_mpm_world(dim, res, 0, PN_BOUNDARY_STICKY);
    pn_mpm_world *b = t_mpm_world(dim, res, 0, PN_BOUNDARY_STICKY);
    double lo[3] = {0.35, 0.35, 0.35}, sz[3] = {0.3, 0.3, 0.3}, diff = 0, disp = 0, *x0;
    pn_mpm_implicit_desc id;
    size_t n, p;
    *rel = 1;
    PN_CHECK(a && b);
    if (!a || !b) return 1;
    memset(&id, 0, sizeof id);
    id.newton_tol = 1e-9;
    n = t_mpm_block(a, t_mpm_group(a, PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e4), lo, sz, NULL);
    t_mpm_block(b, t_mpm_group(b, PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e4), lo, sz, NULL);
    for (p = 0; p < n; ++p) {
        a->v[p * dim] = b->v[p * dim] = 0.5 * (a->x[p * dim + 1] - 0.5);
        a->v[p * dim + 1] = b->v[p * dim + 1] = 0.3 * (a->x[p * dim] - 0.5);
    }
    x0 = (double *)malloc(sizeof(double) * n * dim);
    memcpy(x0, a->x, sizeof(double) * n * dim);
    for (step = 0; step < steps; ++step) {
        PN_CHECK(pn_mpm_step_explicit(a, dt, NULL) == PN_OK);
        PN_CHECK(pn_mpm_step_implicit(b, dt, &id, NULL) == PN_OK);
    }
    for (i = 0; i < (int)(n * dim); ++i) {
        diff = fmax(diff, fabs(a->x[i] - b->x[i]));
        disp = fmax(disp, fabs(a->x[i] - x0[i]));
    }
    free(x0);
    pn_mpm_destroy(a);
    pn_mpm_destroy(b);
    *rel = diff / disp;
    return diff;
}

/* One implicit step of an elastic block: its F update is the explicit step's, F_new =
   (I + dt C_new) F_old with C_new the APIC matrix the step leaves on each particle (the MLS
   gradient of >>implicit; weight gradients would miss this by O(dt |C|)). */
static double t_mpm_f_update_gap(pn_test_ctx *pn__t, int dim) {
    pn_mpm_world *w = t_mpm_world(dim, dim == 2 ? 32 : 16, 0, PN_BOUNDARY_STICKY);
    double lo[3] = {0.35, 0.35, 0.35}, sz[3] = {0.3, 0.3, 0.3}, dt = 2e-3, worst = 0, *F0;
    size_t n, p;
    int dd = dim * dim, i, j, k;
    PN_CHECK(w != NULL);
    if (!w) return 1;
    n = t_mpm_block(w, t_mpm_group(w, PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e4), lo, sz, NULL);
    for (p = 0; p < n; ++p) { /* a shear and a spin, not aligned with the grid */
        w->v[p * dim] = 0.5 * (w->x[p * dim + 1] - 0.5) + 0.2 * (w->x[p * dim] - 0.5);
        w->v[p * dim + 1] = -0.4 * (w->x[p * dim] - 0.5);
    }
    PN_CHECK(pn_mpm_step_implicit(w, dt, NULL, NULL) == PN_OK); /* F_old is not I after it */
    F0 = (double *)malloc(sizeof(double) * n * dd);
    memcpy(F0, w->F, sizeof(double) * n * dd);
    PN_CHECK(pn_mpm_step_implicit(w, dt, NULL, NULL) == PN_OK);
    for (p = 0; p < n; ++p)
        for (i = 0; i < dim; ++i)
            for (j = 0; j < dim; ++j) {
                double e = F0[p * dd + i * dim + j];
                for (k = 0; k < dim; ++k) e += dt * w->C[p * dd + i * dim + k] * F0[p * dd + k * dim + j];
                worst = fmax(worst, fabs(w->F[p * dd + i * dim + j] - e));
            }
    free(F0);
    pn_mpm_destroy(w);
    return worst;
}

PN_TEST(implicit_elastic_matches_explicit) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        double fu = t_mpm_f_update_gap(pn__t, dim);
        PN_CHECK_LE(fu, 1e-13);
        PN_REPORT("dim %d: one implicit step, max |F_new - (I + dt C_new) F_old| = %.1e", dim, fu);
    }
    for (dim = 2; dim <= 3; ++dim) {
        double r1, r2, g1 = t_mpm_elastic_gap(pn__t, dim, 1e-4, &r1),
               g2 = t_mpm_elastic_gap(pn__t, dim, 5e-5, &r2);
        PN_CHECK_LE(r1, 0.005);
        PN_CHECK_LE(g2, 0.7 * g1);
        PN_REPORT("dim %d, 20 ms: max |x_implicit - x_explicit| %.2e at dt 0.1 ms (%.4f of the largest "
                  "displacement), %.2e at 0.05 ms (ratio %.2f)", dim, g1, r1, g2, g2 / g1);
    }
}

/* right edge and top of the first n particles of a 2D world */
static void t_mpm_extent(const pn_mpm_world *w, size_t n, double *xmax, double *ymax) {
    size_t p;
    *xmax = *ymax = 0;
    for (p = 0; p < n; ++p) {
        *xmax = fmax(*xmax, w->x[2 * p]);
        *ymax = fmax(*ymax, w->x[2 * p + 1]);
    }
}

/* A sand column collapse (2D, 64 x 64 cells, E = 1e5 Pa, about 14 s): implicit with the lagged energy at 10x the explicit
   step lands where explicit does (runout and final height), and stays finite at 100x. */
PN_TEST(implicit_sand_column) {
    pn_mpm_world *e = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
    pn_mpm_world *im = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
    pn_mpm_world *big = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
    double lo[3] = {0.4, 0.05, 0}, sz[3] = {0.2, 0.3, 0}, xe, xi, ye, yi, worst_fp = 0;
    pn_mpm_implicit_desc id;
    pn_mpm_stats st;
    size_t n, p;
    int step, finite = 1;
    PN_CHECK(e && im && big);
    if (!e || !im || !big) return;
    n = t_mpm_block(e, t_mpm_group(e, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e5), lo, sz, NULL);
    t_mpm_block(im, t_mpm_group(im, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e5), lo, sz, NULL);
    t_mpm_block(big, t_mpm_group(big, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e5), lo, sz, NULL);
    memset(&id, 0, sizeof id);
    id.fixed_point_iters = 4;
    for (step = 0; step < 3000; ++step) PN_CHECK(pn_mpm_step_explicit(e, 1e-4, NULL) == PN_OK);
    for (step = 0; step < 300; ++step) {
        PN_CHECK(pn_mpm_step_implicit(im, 1e-3, &id, &st) == PN_OK);
        worst_fp = fmax(worst_fp, st.fixed_point_residual);
    }
    for (step = 0; step < 30; ++step) PN_CHECK(pn_mpm_step_implicit(big, 1e-2, &id, NULL) == PN_OK);
    t_mpm_extent(e, n, &xe, &ye);
    t_mpm_extent(im, n, &xi, &yi);
    for (p = 0; p < n; ++p) finite &= t_finite(2, big->x + 2 * p) && t_finite(4, big->F + 4 * p);
    PN_CHECK_LE(fabs(xi - xe) / (xe - 0.5), 0.02);
    PN_CHECK_LE(fabs(yi - ye) / ye, 0.05);
    PN_CHECK(finite && big->left_total == 0 && im->left_total == 0);
    PN_REPORT("0.3 s: right edge explicit (dt 1e-4) %.4f, implicit lagged (dt 1e-3, 4 passes) %.4f; height %.4f, "
              "%.4f; largest fixed-point residual %.1e; dt 1e-2: finite %d",
              xe, xi, ye, yi, worst_fp, finite);
    pn_mpm_destroy(e);
    pn_mpm_destroy(im);
    pn_mpm_destroy(big);
}

/* A NaN deformation met by an implicit step: the error names the particle, the world is as
   it was. */
PN_TEST(implicit_bad_input) {
    pn_mpm_world *w = t_mpm_world(2, 32, -9.81, PN_BOUNDARY_STICKY);
    double lo[3] = {0.3, 0.3, 0}, sz[3] = {0.2, 0.2, 0}, *copy;
    size_t n, bytes;
    int g;
    PN_CHECK(w != NULL);
    if (!w) return;
    g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, 1e6);
    n = t_mpm_block(w, g, lo, sz, NULL);
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, NULL, NULL) == PN_OK);
    w->F[7 * 4] = NAN;
    bytes = sizeof(double) * n * 2;
    copy = (double *)malloc(bytes * 2);
    memcpy(copy, w->x, bytes);
    memcpy(copy + n * 2, w->v, bytes);
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, NULL, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(w->error_particle == 7);
    PN_CHECK(memcmp(copy, w->x, bytes) == 0 && memcmp(copy + n * 2, w->v, bytes) == 0 && w->steps == 1);
    PN_CHECK(pn_mpm_group_set_energy(w, g, PN_ENERGY_EXACT_VM, NULL) == PN_ERROR_UNSUPPORTED);
    PN_CHECK(pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, NULL) == PN_ERROR_INVALID_ARGUMENT);
    PN_CHECK(pn_mpm_group_set_energy(w, g, (pn_energy)99, NULL) == PN_ERROR_INVALID_ARGUMENT);
    g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_NONE, 1e6); /* DP needs a DP material */
    PN_CHECK(g >= 0 && pn_mpm_group_set_energy(w, g, PN_ENERGY_DP, NULL) == PN_ERROR_UNSUPPORTED);
    free(copy);
    pn_mpm_destroy(w);
}

/* The shipped PlasticityNet sand model in the implicit integrator (the same column, dt 1e-3,
   two fixed-point passes): it lands where explicit does. */
PN_TEST(implicit_pnet_sand_column) {
#ifdef PN_TEST_HAVE_MODELS
    pn_mpm_world *e = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
    pn_mpm_world *im = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
    double lo[3] = {0.4, 0.05, 0}, sz[3] = {0.2, 0.3, 0}, xe, xi, ye, yi;
    pn_material m;
    pn_pnet net;
    pn_pnet_desc nd;
    pn_mpm_implicit_desc id;
    size_t n;
    int step, ge, gi;
    PN_CHECK(e && im);
    if (!e || !im) return;
    PN_CHECK(pn_model_material(pn_model_sand_2d(), 1e5, &m, NULL, 0) == PN_OK);
    memset(&nd, 0, sizeof nd);
    nd.energy = pn_model_sand_2d();
    PN_CHECK(pn_pnet_init(&net, &nd, &m, 2, NULL, 0) == PN_OK);
    ge = pn_mpm_add_group(e, &m, 1000);
    gi = pn_mpm_add_group(im, &m, 1000);
    PN_CHECK(pn_mpm_group_set_energy(im, gi, PN_ENERGY_PNET, &net) == PN_OK);
    n = t_mpm_block(e, ge, lo, sz, NULL);
    t_mpm_block(im, gi, lo, sz, NULL);
    memset(&id, 0, sizeof id);
    /* two fixed-point passes: with one the runout lands 3.6% short (lagged 1.6%) since 2D sand
       means its full 30 degrees (docs/results.md); with the old 27.5 one pass was within 0.5% */
    id.fixed_point_iters = 2;
    for (step = 0; step < 3000; ++step) PN_CHECK(pn_mpm_step_explicit(e, 1e-4, NULL) == PN_OK);
    for (step = 0; step < 300; ++step) PN_CHECK(pn_mpm_step_implicit(im, 1e-3, &id, NULL) == PN_OK);
    t_mpm_extent(e, n, &xe, &ye);
    t_mpm_extent(im, n, &xi, &yi);
    PN_CHECK_LE(fabs(xi - xe) / (xe - 0.5), 0.02);
    PN_CHECK_LE(fabs(yi - ye) / ye, 0.05);
    PN_REPORT("0.3 s: right edge explicit %.4f, implicit PlasticityNet (dt 1e-3, 2 passes) %.4f; height %.4f, %.4f", xe, xi,
              ye, yi);
    pn_mpm_destroy(e);
    pn_mpm_destroy(im);
#else
    PN_REPORT("skipped: built without PN_TEST_HAVE_MODELS");
#endif
}

/* pn_mpm_implicit_desc.pnet_reuse_tol: PlasticityNet's Taylor models. (1) Where the stress is
   well above E |dF| (away from the sand's cone apex, where the energy bends on the scale of
   the elastic strain), their error against the network at the same point shrinks as the
   square of the distance: a quarter of the distance, about a sixteenth of the error (the
   stale stress, a zero-order model: a quarter). (2) A column collapsing under its own weight
   moves as it does with reuse off, within 1e-3 dx over 60 steps. (3) A layer at rest: a step
   keeps at least 95% of the prepared points (so the network is not evaluated there; the
   rest are still settling), and prepares anew only those F0 has left by more than 1e-5. */
PN_TEST(implicit_pnet_reuse) {
#ifdef PN_TEST_HAVE_MODELS
    pn_mpm_world *w[2];
    double lo[3] = {0.4, 0.1, 0}, sz[3] = {0.2, 0.2, 0}, err[2] = {0, 0}, err0[2] = {0, 0}, worst = 0, dx;
    pn_material m;
    pn_pnet net;
    pn_pnet_desc nd;
    pn_mpm_implicit_desc id[2];
    size_t n = 0, p;
    int step, i, a, kept = 0, nlayer = 0, models = 0, loaded = 0;
    PN_CHECK(pn_model_material(pn_model_sand_2d(), 1e5, &m, NULL, 0) == PN_OK);
    memset(&nd, 0, sizeof nd);
    nd.energy = pn_model_sand_2d();
    PN_CHECK(pn_pnet_init(&net, &nd, &m, 2, NULL, 0) == PN_OK);
    for (i = 0; i < 2; ++i) {
        int g;
        w[i] = t_mpm_world(2, 48, -9.81, PN_BOUNDARY_SEPARATE);
        PN_CHECK(w[i] != NULL);
        if (!w[i]) return;
        g = pn_mpm_add_group(w[i], &m, 1000);
        PN_CHECK(pn_mpm_group_set_energy(w[i], g, PN_ENERGY_PNET, &net) == PN_OK);
        n = t_mpm_block(w[i], g, lo, sz, NULL);
        PN_CHECK(n > 100);
        memset(&id[i], 0, sizeof id[i]);
        id[i].pnet_reuse_tol = i ? -1 : 0; /* the default (1e-4), off */
    }
    dx = w[0]->desc.dx_m;
    for (step = 0; step < 60; ++step)
        for (i = 0; i < 2; ++i) PN_CHECK(pn_mpm_step_implicit(w[i], 1e-3, &id[i], NULL) == PN_OK);
    for (p = 0; p < n; ++p)
        for (a = 0; a < 2; ++a) worst = fmax(worst, fabs(w[0]->x[2 * p + a] - w[1]->x[2 * p + a]));
    PN_CHECK(w[1]->s.tok == NULL && w[0]->s.tok != NULL);
    /* (1) at each model, F moved by r (1e-3, then a quarter of it) in a fixed direction */
    for (p = 0; w[0]->s.tok && p < n; ++p) {
        const pn_real *F0 = w[0]->s.tF + 4 * p;
        pn_real F[4], psi, Pm[4], Pe[4];
        if (!w[0]->s.tok[p]) continue;
        models++;
        if (!(fabs(w[0]->s.tP[4 * p] + w[0]->s.tP[4 * p + 3]) > 0.005 * 1e5)) continue; /* |tr P| / 2 > 25 E |dF| */
        loaded++;
        for (i = 0; i < 2; ++i) {
            pn_real r = i ? 2.5e-5 : 1e-4, save = w[0]->s.reuse_tol;
            const pn_pnet_point *pt = &w[0]->s.ppt[p];
            pn_result st;
            for (a = 0; a < 4; ++a) F[a] = F0[a] + r * (a == 0 ? 1 : a == 3 ? -0.5 : 0.7);
            w[0]->s.reuse_tol = 1;
            PN_CHECK(pn__mpm_taylor(w[0], p, F, &psi, Pm));
            w[0]->s.reuse_tol = save;
            /* the network as the solver evaluates it (float lanes) */
            PN_CHECK(pn_pnet_energy_lanes(&net, 1, &pt, F, &psi, Pe, NULL, 0, &st) == PN_OK);
            for (a = 0; a < 4; ++a) {
                err[i] += fabs(Pm[a] - Pe[a]);
                err0[i] += fabs(w[0]->s.tP[4 * p + a] - Pe[a]);
            }
        }
    }
    PN_CHECK(models > (int)n / 2 && loaded > 20);
    PN_CHECK(err[0] > 0 && err[0] / err[1] > 8 && err0[0] / err0[1] < 5);
    PN_CHECK_LE(worst / dx, 1e-3);
    /* (3) a layer over the whole floor, 0.15 s to settle, then one more step */
    {
        pn_mpm_world *b = t_mpm_world(2, 32, -9.81, PN_BOUNDARY_SEPARATE);
        double blo[3], bsz[3] = {0, 0.08, 0};
        pn_pnet_point *before = NULL;
        size_t nb = 0, same = 0;
        int g, left_ok = 1;
        PN_CHECK(b != NULL);
        if (b) {
            blo[0] = b->s.wall_lo[0], blo[1] = b->s.wall_lo[1], bsz[0] = b->s.wall_hi[0] - b->s.wall_lo[0];
            g = pn_mpm_add_group(b, &m, 1000);
            PN_CHECK(pn_mpm_group_set_energy(b, g, PN_ENERGY_PNET, &net) == PN_OK);
            nb = t_mpm_block(b, g, blo, bsz, NULL);
            nlayer = (int)nb;
            PN_CHECK(nb > 100);
            for (step = 0; step < 150; ++step) PN_CHECK(pn_mpm_step_implicit(b, 1e-3, &id[0], NULL) == PN_OK);
            before = (pn_pnet_point *)malloc(sizeof(pn_pnet_point) * nb);
        }
        if (before) {
            memcpy(before, b->s.ppt, sizeof(pn_pnet_point) * nb);
            PN_CHECK(pn_mpm_step_implicit(b, 1e-3, &id[0], NULL) == PN_OK);
            for (p = 0; p < nb; ++p) { /* a point is prepared anew only when F0 has left it */
                double moved = 0;
                for (a = 0; a < 4; ++a) moved = fmax(moved, fabs(b->s.ppt[p].F0[a] - before[p].F0[a]));
                if (memcmp(&before[p], &b->s.ppt[p], sizeof(pn_pnet_point)) == 0) same++;
                else left_ok &= moved > 1e-5;
            }
            kept = (int)same;
            PN_CHECK(left_ok && same >= nb * 95 / 100);
        }
        free(before);
        pn_mpm_destroy(b);
    }
    PN_REPORT("%d Taylor models, %d loaded: |P model - P network| summed %.3e Pa at |dF| 1e-4, %.3e at a quarter (ratio "
              "%.1f; the stale stress: %.1f); column, 60 steps of 1e-3 s: reuse on against off within %.2e dx; a layer at "
              "rest keeps %d points of %d",
              models, loaded, err[0], err[1], err[0] / err[1], err0[0] / err0[1], worst / dx, kept, nlayer);
    pn_mpm_destroy(w[0]);
    pn_mpm_destroy(w[1]);
#else
    PN_REPORT("skipped: built without PN_TEST_HAVE_MODELS");
#endif
}

/* pn_mpm_stats.force_error: a soft von Mises block (sigma_Y = 2e3 Pa) slammed onto the floor
   at 2 m/s yields within every step. The exact von Mises energy's gradient is the return
   mapping's T(F) by construction, so its force error is rounding; the lagged energy, elastic
   within a step, is off by a finite share; off, the fields read -1. */
PN_TEST(implicit_force_error) {
    double lo[3] = {0.35, 0.12, 0}, sz[3] = {0.3, 0.15, 0}, v0[3] = {0, -2, 0}, worst[2] = {0, 0}, least_lag = 1e300;
    long plastic[2] = {0, 0};
    int which, step, off_ok = 1;
    for (which = 0; which < 2; ++which) {
        pn_mpm_world *w = t_mpm_world(2, 48, -9.81, PN_BOUNDARY_SEPARATE);
        pn_material_desc d;
        pn_material m;
        pn_mpm_implicit_desc id;
        int g;
        PN_CHECK(w != NULL);
        if (!w) return;
        memset(&d, 0, sizeof d);
        d.elastic = PN_ELASTIC_STVK_HENCKY;
        d.plastic = PN_PLASTIC_VON_MISES;
        d.youngs_modulus_pa = 1e6;
        d.poisson_ratio = 0.3;
        d.yield_stress_pa = 2e3;
        PN_CHECK(pn_material_init(&m, &d, NULL, 0) == PN_OK);
        g = pn_mpm_add_group(w, &m, 1000);
        PN_CHECK(pn_mpm_group_set_energy(w, g, which ? PN_ENERGY_LAGGED : PN_ENERGY_EXACT_VM, NULL) == PN_OK);
        t_mpm_block(w, g, lo, sz, v0);
        memset(&id, 0, sizeof id);
        id.fixed_point_iters = 1;
        for (step = 0; step < 60; ++step) {
            pn_mpm_stats st;
            id.measure_force_error = step % 2 == 0;
            PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, &st) == PN_OK);
            if (!id.measure_force_error) {
                off_ok &= st.force_error == -1 && st.force_error_regularizer == -1 && st.apex_fraction == -1;
                continue;
            }
            plastic[which] += (long)st.plastic;
            worst[which] = fmax(worst[which], st.force_error);
            if (which && st.plastic > 0) least_lag = fmin(least_lag, st.force_error);
            PN_CHECK(st.force_error_regularizer == 0); /* no PlasticityNet regularizer here */
        }
        pn_mpm_destroy(w);
    }
    PN_REPORT("von Mises block at 2 m/s on the floor, dt 1e-3 s, 30 measured steps each: force error exact "
              "energy %.1e (%ld plastic particle-steps), lagged %.3f..%.3f (%ld)", worst[0], plastic[0], least_lag,
              worst[1], plastic[1]);
    PN_CHECK(plastic[0] > 1000 && plastic[1] > 1000);
    PN_CHECK_LE(worst[0], 1e-10);
    PN_CHECK(least_lag > 1e-3);
    PN_CHECK(off_ok);
}

/* A learned energy must not run away along a solve: PlasticityNet sand (the shipped sand_2d
   model) stepped at 0.1 s and 1 s, E 1e7 and 1e9 Pa, 3 steps each. A step either fails with
   the world unchanged or succeeds with every particle on the grid and slower than a fall
   from the top of the domain (sqrt(2 g 1 m) = 4.4 m/s), and no Newton iterate's incremental
   potential goes below -1e4 J (the column's m g h over the whole domain is 590 J; a
   runaway once reached -3.5e6 J and launched the sand at 42 m/s). */
static void t_min_trace(void *user, int solve, int iteration, pn_real energy_j, pn_real residual) {
    (void)solve, (void)iteration, (void)residual;
    if ((double)energy_j < *(double *)user) *(double *)user = (double)energy_j;
}

PN_TEST(implicit_pnet_large_steps) {
#ifdef PN_TEST_HAVE_MODELS
    static const double dts[2] = {0.1, 1.0}, Es[2] = {1e7, 1e9};
    int a, b, s;
    for (a = 0; a < 2; ++a)
        for (b = 0; b < 2; ++b) {
            pn_mpm_world *w = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
            double lo[2] = {0.4, 3.0 / 64}, sz[2] = {0.2, 0.3}, emin = 1e300, vmax = 0;
            pn_material m;
            pn_pnet net;
            pn_pnet_desc nd;
            pn_mpm_implicit_desc id;
            pn_mpm_stats st;
            size_t n, p;
            int g, ok = 0, failed = 0, bad = 0;
            PN_CHECK(w != NULL);
            if (!w) return;
            PN_CHECK(pn_model_material(pn_model_sand_2d(), Es[b], &m, NULL, 0) == PN_OK);
            memset(&nd, 0, sizeof nd);
            nd.energy = pn_model_sand_2d();
            PN_CHECK(pn_pnet_init(&net, &nd, &m, 2, NULL, 0) == PN_OK);
            g = pn_mpm_add_group(w, &m, 1000);
            PN_CHECK(pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, &net) == PN_OK);
            n = t_mpm_block(w, g, lo, sz, NULL);
            memset(&id, 0, sizeof id);
            id.trace = t_min_trace;
            id.trace_user = &emin;
            for (s = 0; s < 3; ++s) {
                double t0 = (double)w->time_s, x0 = (double)w->x[0];
                if (pn_mpm_step_implicit(w, (pn_real)dts[a], &id, &st) == PN_OK) {
                    ok++;
                    for (p = 0; p < n; ++p) {
                        vmax = fmax(vmax, hypot((double)w->v[2 * p], (double)w->v[2 * p + 1]));
                        bad |= !w->active[p];
                    }
                } else {
                    failed++;
                    bad |= (double)w->time_s != t0 || (double)w->x[0] != x0;
                }
            }
            PN_CHECK(!bad);
            PN_CHECK_LE(vmax, 4.43);
            PN_CHECK(emin >= -1e4);
            if (emin > 1e299) /* every attempt failed at its start (an inverted first iterate) */
                PN_REPORT("dt %g s, E %.0e: %d steps ok, %d failed (world unchanged) before any Newton iterate", dts[a],
                          Es[b], ok, failed);
            else
                PN_REPORT("dt %g s, E %.0e: %d steps ok, %d failed (world unchanged), fastest particle %.3f m/s, lowest "
                          "incremental potential %.3g J", dts[a], Es[b], ok, failed, vmax, emin);
            pn_mpm_destroy(w);
        }
#endif
}

/* the mechanical energy of a world, computed here: kinetic + elastic + m |g| (y - the grid's
   low edge, 0.75 dx) for gravity along -y */
static double t_mech_energy(const pn_mpm_world *w) {
    double e = 0, low = 0.75 * w->desc.dx_m, g = -w->desc.gravity[1];
    size_t p;
    for (p = 0; p < w->n; ++p) {
        pn_real psi;
        const double *v = w->v + 2 * p;
        if (!w->active[p]) continue;
        PN_ASSERT(pn_elastic_energy(&w->groups[w->group[p]].material, 2, w->F + 4 * p, w->h[p], &psi, NULL, NULL, 0) ==
                  PN_OK);
        e += w->mass[p] * ((v[0] * v[0] + v[1] * v[1]) / 2 + g * (w->x[2 * p + 1] - low)) + w->vol0[p] * psi;
    }
    return e;
}

/* The energy guard (pn_mpm_implicit_desc.energy_rise_tol): PlasticityNet sand (E 1e7 Pa) at
   one step per frame (1/60 s, about 250 explicit steps) can gain energy in a step
   (the learned energy minimized to a wrong answer): 0.05 of the energy before its first anchor
   left out gravity's kick, none in these six steps since. The rise the guard reports equals the
   change computed here from the particles; with a tolerance of half the largest rise
   without the guard, the steps that gain more are refused and taken as substeps (more steps
   split than the advection limit splits alone), so no accepted step or substep gains more;
   off (< 0), nothing is measured; NaN is refused. */
PN_TEST(implicit_energy_guard) {
#ifdef PN_TEST_HAVE_MODELS
    double lo[3] = {0.4, 0.05, 0}, sz[3] = {0.2, 0.3, 0}, worst = 0, err = 0, tol = 0;
    int k, step, refused = 0, measured = 0, split = 0;
    pn_material m;
    pn_pnet net;
    pn_pnet_desc nd;
    PN_CHECK(pn_model_material(pn_model_sand_2d(), 1e7, &m, NULL, 0) == PN_OK);
    memset(&nd, 0, sizeof nd);
    nd.energy = pn_model_sand_2d();
    PN_CHECK(pn_pnet_init(&net, &nd, &m, 2, NULL, 0) == PN_OK);
    for (k = 0; k < 3; ++k) {
        pn_mpm_world *w = t_mpm_world(2, 64, -9.81, PN_BOUNDARY_SEPARATE);
        pn_mpm_implicit_desc id;
        int g = w ? pn_mpm_add_group(w, &m, 1000) : -1;
        PN_CHECK(g >= 0 && pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, &net) == PN_OK);
        if (g < 0) {
            pn_mpm_destroy(w);
            return;
        }
        t_mpm_block(w, g, lo, sz, NULL);
        memset(&id, 0, sizeof id);
        tol = worst / 2; /* k = 1: after k = 0 measured worst */
        id.energy_rise_tol = k == 0 ? 1e30 : k == 1 ? (pn_real)tol : -1;
        for (step = 0; step < 6; ++step) {
            pn_mpm_stats st;
            double e0 = t_mech_energy(w), e1;
            pn_result r = pn_mpm_step_implicit(w, 1.0 / 60, &id, &st);
            PN_CHECK(r == PN_OK);
            if (r != PN_OK) break;
            e1 = t_mech_energy(w);
            if (k == 0) { /* the guard's figure against this one's (one step, no substeps) */
                if (st.substeps == 1) err = fmax(err, fabs(st.energy_rise - fmax((e1 - e0) / e0, 0)));
                worst = fmax(worst, st.energy_rise);
                split += st.substeps > 1; /* without the guard */
            }
            if (k == 1) {
                refused += st.substeps > 1;
                PN_CHECK_LE(st.energy_rise, tol);
            }
            if (k == 2) measured += st.energy_rise != 0;
        }
        pn_mpm_destroy(w);
    }
    PN_CHECK_LE(err, 1e-9);
    /* the refusal: only where a step gained energy (none has since the anchor; a scene that
       does is wanted, docs/notebook.md) */
    PN_CHECK(measured == 0 && (worst == 0 || refused > split));
    {
        double lo2[3] = {0.4, 0.1, 0};
        size_t n;
        pn_mpm_world *w = t_stress_scene(pn__t, 32, -9.81, PN_BOUNDARY_SEPARATE, PN_PLASTIC_DRUCKER_PRAGER, 1e6, lo2, sz, &n);
        pn_mpm_implicit_desc id = t_stress_desc();
        if (!w) return;
        id.energy_rise_tol = NAN;
        PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_ERROR_INVALID_ARGUMENT && w->steps == 0);
        PN_CHECK(strstr(pn_mpm_error(w), "energy_rise_tol") != NULL);
        pn_mpm_destroy(w);
    }
    PN_REPORT("PlasticityNet sand at 1/60 s: largest rise in a step %.2e of the energy (the guard's figure within "
              "%.1e of the particles'); at energy_rise_tol %.2e, %d of 6 steps taken as substeps (%d without the "
              "guard)", worst, err, tol, refused, split);
#else
    PN_REPORT("skipped: built without PN_TEST_HAVE_MODELS");
#endif
}

static const pn_test_case pn_tests_mpm_implicit[] = {
    {"implicit_elastic_matches_explicit", implicit_elastic_matches_explicit},
    {"implicit_sand_column", implicit_sand_column},
    {"implicit_bad_input", implicit_bad_input},
    {"implicit_pnet_sand_column", implicit_pnet_sand_column},
    {"implicit_pnet_reuse", implicit_pnet_reuse},
    {"implicit_force_error", implicit_force_error},
    {"implicit_pnet_large_steps", implicit_pnet_large_steps},
    {"implicit_energy_guard", implicit_energy_guard},
};
