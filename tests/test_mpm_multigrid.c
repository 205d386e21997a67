/* test_mpm_multigrid.c: plastinet_mpm.h's >>multigrid room (multigrid_*): the assembled
   Hessian, the Galerkin hierarchy and the V-cycle against what they stand for, and CG
   iterations that barely grow with the step. Helpers: test_mpm_world.c. */

/* >>multigrid, checked against what it stands for. Inside a real Newton iteration (the trace
   of the first one of a step; a sand block on a Coulomb floor, so held contact directions
   are in the filter): the assembled matrix times a random filtered vector equals the
   matrix-free product over the particles (pn__mpm_hess_vec without the assembly); each
   coarse matrix equals restriction of the fine one applied to a prolonged vector
   (P^T A P xc, from the separately written prolongation and restriction, which must be each
   other's transposes); and the V-cycle is symmetric positive definite (x.By = y.Bx,
   x.Bx > 0), which CG needs. The levels store their blocks in float: products agree to
   float rounding, the V-cycle's symmetry to far below it. */
typedef struct t_mg_probe {
    pn_mpm_world *w;
    pn_real dt;
    int done, levels;
    double op_err, galerkin_err, transpose_err, sym_err, min_xbx;
} t_mg_probe;

static void t_mg_fill(pn_test_rng *rng, pn_mpm_world *w, size_t rows, pn_real *x, int filter) {
    size_t k;
    int i, d = w->dim;
    for (k = 0; k < rows; ++k) {
        for (i = 0; i < d; ++i) x[k * (size_t)d + (size_t)i] = (pn_real)pn_test_rng_range(rng, -1, 1);
        if (filter) pn__mpm_filter(w, k, x + k * (size_t)d);
    }
}

static double t_mg_dot(const pn_real *a, const pn_real *b, size_t n) {
    double s = 0;
    size_t i;
    for (i = 0; i < n; ++i) s += (double)a[i] * (double)b[i];
    return s;
}

static void t_mg_trace(void *user, int solve, int iteration, pn_real energy_j, pn_real residual) {
    t_mg_probe *pr = (t_mg_probe *)user;
    pn_mpm_world *w = pr->w;
    int d = w->dim, l, trial;
    size_t n = w->s.n_act * (size_t)d, i, cap = 0;
    pn_real *x, *y, *a, *b, *c;
    pn_test_rng rng = {12345};
    (void)energy_j, (void)residual;
    if (pr->done || solve != 1 || iteration != 0) return;
    pr->done = 1;
    pr->levels = w->s.mg_levels;
    for (l = 0; l < w->s.mg_levels; ++l) cap = cap > w->s.mg[l].n ? cap : w->s.mg[l].n;
    cap *= (size_t)d;
    x = (pn_real *)calloc(cap, sizeof(pn_real)), y = (pn_real *)calloc(cap, sizeof(pn_real));
    a = (pn_real *)calloc(cap, sizeof(pn_real)), b = (pn_real *)calloc(cap, sizeof(pn_real));
    c = (pn_real *)calloc(cap, sizeof(pn_real));
    if (!x || !y || !a || !b || !c) return;
    /* assembled against matrix-free */
    t_mg_fill(&rng, w, w->s.n_act, x, 1);
    pn__mpm_hess_vec(w, x, pr->dt, a);
    w->s.mg_on = 0;
    pn__mpm_hess_vec(w, x, pr->dt, b);
    w->s.mg_on = 1;
    for (i = 0; i < n; ++i) pr->op_err = fmax(pr->op_err, fabs((double)(a[i] - b[i])));
    pr->op_err /= sqrt(t_mg_dot(b, b, n) / (double)n);
    /* P^T A_l P = A_l+1, and restriction = prolongation^T */
    for (l = 0; l + 1 < w->s.mg_levels; ++l) {
        pn__mpm_level *F = &w->s.mg[l], *C = &w->s.mg[l + 1];
        size_t nf = F->n * (size_t)d, nc = C->n * (size_t)d;
        double nrm, ptu, u_pc;
        t_mg_fill(&rng, w, C->n, C->x, 0);
        memcpy(c, C->x, sizeof(pn_real) * nc);
        memset(x, 0, sizeof(pn_real) * nf);
        pn__mpm_mg_prolong(w, l, x);            /* x = P xc */
        pn__mpm_mg_apply(w, l, x, NULL, F->r);  /* A P xc */
        pn__mpm_mg_restrict(w, l);              /* C->b = P^T A P xc */
        pn__mpm_mg_apply(w, l + 1, c, NULL, y); /* A_c xc */
        nrm = sqrt(t_mg_dot(y, y, nc) / (double)nc);
        for (i = 0; i < nc; ++i) pr->galerkin_err = fmax(pr->galerkin_err, fabs((double)(y[i] - C->b[i])) / nrm);
        t_mg_fill(&rng, w, F->n, F->r, 0); /* u . P xc = P^T u . xc */
        pn__mpm_mg_restrict(w, l);
        ptu = t_mg_dot(C->b, c, nc);
        u_pc = t_mg_dot(F->r, x, nf);
        pr->transpose_err = fmax(pr->transpose_err, fabs(ptu - u_pc) / (fabs(u_pc) + 1e-300));
    }
    for (trial = 0; trial < 3; ++trial) { /* x.By = y.Bx, x.Bx > 0 */
        double xby, ybx, xbx;
        t_mg_fill(&rng, w, w->s.n_act, x, 1);
        t_mg_fill(&rng, w, w->s.n_act, y, 1);
        pn__mpm_mg_vcycle(w, 0, x, a);
        pn__mpm_mg_vcycle(w, 0, y, b);
        xby = t_mg_dot(x, b, n), ybx = t_mg_dot(y, a, n), xbx = t_mg_dot(x, a, n);
        pr->sym_err = fmax(pr->sym_err, fabs(xby - ybx) / sqrt(t_mg_dot(a, a, n) * t_mg_dot(y, y, n)));
        pr->min_xbx = trial == 0 ? xbx / t_mg_dot(x, x, n) : fmin(pr->min_xbx, xbx / t_mg_dot(x, x, n));
    }
    free(x), free(y), free(a), free(b), free(c);
}

static pn_mpm_world *t_mg_scene(int dim, int res, double E, int elastic, pn_boundary wall, int *g) {
    pn_mpm_world *w = t_mpm_world(dim, res, -9.81, wall);
    double lo[3] = {0.3, 3.0 / res, 0.3}, sz[3] = {0.4, 0.3, 0.4};
    if (!w) return NULL;
    w->desc.friction = 0.5;
    if (dim == 3) lo[0] = lo[2] = 0.25, sz[0] = sz[2] = 0.5, sz[1] = 0.35;
    *g = elastic ? t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, E)
                 : t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, E);
    if (*g < 0 || t_mpm_block(w, *g, lo, sz, NULL) == 0) {
        pn_mpm_destroy(w);
        return NULL;
    }
    return w;
}

/* the velocities of a world, kept (NULL when out of memory), and the largest gap between
   two kept sets in cells per step (dt / dx scale), freeing both */
static pn_real *t_mg_keep_v(const pn_mpm_world *w, size_t *n) {
    pn_real *x;
    *n = w->n * (size_t)w->dim;
    x = (pn_real *)malloc(sizeof(pn_real) * *n);
    if (x) memcpy(x, w->v, sizeof(pn_real) * *n);
    return x;
}
static double t_mg_gap(pn_real *x[2], size_t n, double scale) {
    double worst = 0;
    size_t p;
    if (x[0] && x[1])
        for (p = 0; p < n; ++p) worst = fmax(worst, fabs((double)(x[0][p] - x[1][p])) * scale);
    free(x[0]), free(x[1]);
    return worst;
}

PN_TEST(multigrid_operators) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        int g, s;
        t_mg_probe pr;
        pn_mpm_implicit_desc id;
        pn_mpm_world *w = t_mg_scene(dim, dim == 2 ? 64 : 16, 1e7, 0, PN_BOUNDARY_SEPARATE, &g);
        PN_CHECK(w != NULL);
        if (!w) return;
        memset(&id, 0, sizeof id);
        id.linear_solver = PN_MPM_LINEAR_MULTIGRID; /* the default takes Jacobi at this size */
        for (s = 0; s < 5; ++s) PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_OK);
        memset(&pr, 0, sizeof pr);
        pr.w = w;
        pr.dt = (pn_real)1e-3;
        id.trace = t_mg_trace;
        id.trace_user = &pr;
        PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_OK);
        PN_CHECK(pr.done && pr.levels >= 2);
        /* the levels' blocks are stored in float (each entry to 6e-8 of itself; a row's product
           sums 125 blocks of mixed sign); the prolongation and restriction are exact */
        PN_CHECK_LE(pr.op_err, 1e-6);
        PN_CHECK_LE(pr.galerkin_err, 1e-6);
        PN_CHECK_LE(pr.transpose_err, 1e-12);
        PN_CHECK_LE(pr.sym_err, 1e-9);
        PN_CHECK(pr.min_xbx > 0);
        PN_REPORT("%dD, %lu particles, %d levels: assembled vs matrix-free %.1e, P^T A P vs coarse %.1e, restriction vs "
                  "P^T %.1e, V-cycle asymmetry %.1e, min x.Bx / x.x %.2e", dim, (unsigned long)w->n, pr.levels,
                  pr.op_err, pr.galerkin_err, pr.transpose_err, pr.sym_err, pr.min_xbx);
        pn_mpm_destroy(w);
    }
}

/* The point of multigrid: CG iterations that barely grow with the step over the explicit
   bound. An elastic block settling on a sticky floor, one step of 1e-2 s at E 1e5, 1e7 and
   1e9 Pa (dt / dt_CFL 8 to 825), solved to a relative residual of 1e-6: Jacobi CG needs
   iterations growing with dt / dt_CFL; the V-cycle's grow by less than 3x over those 100x,
   and both land on the same velocities (the same minimum, to the Newton tolerance). Then a
   3D sand step on 1 and 2 threads gives the same bits with a smoothed coarsest level. */
PN_TEST(multigrid_iterations) {
    double Es[3] = {1e5, 1e7, 1e9}, per[2][3], worst = 0;
    int e, k, dim = 2;
    for (e = 0; e < 3; ++e) {
        pn_real *x[2] = {NULL, NULL};
        size_t n = 0;
        double ratio = 0;
        for (k = 0; k < 2; ++k) {
            int g;
            pn_mpm_implicit_desc id;
            pn_mpm_stats st;
            pn_mpm_world *w = t_mg_scene(dim, 64, Es[e], 1, PN_BOUNDARY_STICKY, &g);
            PN_CHECK(w != NULL);
            if (!w) return;
            memset(&id, 0, sizeof id);
            id.linear_solver = k ? PN_MPM_LINEAR_MULTIGRID : PN_MPM_LINEAR_JACOBI;
            id.newton_tol = 1e-9;
            id.cg_rel_tol = 1e-6;
            id.cg_max = 5000;
            PN_CHECK(pn_mpm_step_implicit(w, 1e-2, &id, &st) == PN_OK);
            per[k][e] = st.newton_iters ? (double)st.cg_iters / st.newton_iters : 0;
            ratio = (double)st.dt_over_cfl;
            x[k] = t_mg_keep_v(w, &n);
            pn_mpm_destroy(w);
        }
        worst = fmax(worst, t_mg_gap(x, n, 1e-2 * 64));
        PN_REPORT("E %.0e Pa, dt / dt_CFL %.0f: CG iterations per Newton step, Jacobi %.0f, multigrid %.1f", Es[e], ratio,
                  per[0][e], per[1][e]);
    }
    /* Jacobi grows with dt / dt_CFL until the iterations reach the block's size in nodes
       (about 30 here); the V-cycle's grow far less, and stay several times below */
    PN_CHECK(per[0][2] > 2 * per[0][0]);
    PN_CHECK_LE(per[1][2], 3 * per[1][0]);
    PN_CHECK_LE(5 * per[1][2], per[0][2]);
    PN_CHECK_LE(worst, 1e-6);              /* in cells per step: the same minimum             */
    PN_REPORT("largest velocity gap between the two solvers: %.1e dx per step", worst);
#ifdef _OPENMP
    {
        pn_real *keep = NULL;
        size_t n = 0;
        int t, same = 0, levels = 0;
        for (t = 1; t <= 2; ++t) {
            int g, s;
            pn_mpm_implicit_desc id;
            pn_mpm_world *w = t_mg_scene(3, 16, 1e7, 0, PN_BOUNDARY_SEPARATE, &g);
            PN_CHECK(w != NULL);
            if (!w) break;
            w->desc.parallel_min_particles = 1;
            omp_set_num_threads(t);
            memset(&id, 0, sizeof id);
            id.linear_solver = PN_MPM_LINEAR_MULTIGRID;
            id.mg_levels = 2; /* a coarsest level too large to factor: smoothed */
            for (s = 0; s < 4; ++s) PN_CHECK(pn_mpm_step_implicit(w, 2e-3, &id, NULL) == PN_OK);
            levels = w->s.mg_levels;
            n = w->n * 3;
            if (t == 1) {
                keep = (pn_real *)malloc(sizeof(pn_real) * n);
                if (keep) memcpy(keep, w->v, sizeof(pn_real) * n);
            } else
                same = keep && memcmp(keep, w->v, sizeof(pn_real) * n) == 0;
            pn_mpm_destroy(w);
        }
        omp_set_num_threads(2);
        free(keep);
        PN_CHECK(same && levels == 2);
        PN_REPORT("3D sand, %d levels (coarsest smoothed), 1 and 2 threads: %s", levels, same ? "bitwise identical" : "DIFFER");
    }
#endif
}

/* LINEAR_DEFAULT in 3D above PN__MPM_MG_MIN unknowns: Jacobi while its solves are cheap,
   multigrid once they are not. An elastic block on a sticky floor (res 28, about 16,000
   particles). Soft (E 1e5 Pa) at 1e-3 s: Jacobi, no hierarchy built. Stiff (E 4e8 Pa) at
   1e-2 s, dt / dt_CFL in the hundreds: Jacobi's first solve needs more than
   PN__MPM_JACOBI_MAX CG iterations per Newton iteration or stops at cg_max, and the next
   step builds the hierarchy; the first step lands where MULTIGRID's does (the same minimum,
   to the Newton tolerance). A call that fails (newton_max 1, no fallback) leaves the choice as it
   was: the next world state is not the failed try's. */
PN_TEST(multigrid_default_3d) {
    int k, g, s, builds[2] = {0, 0}, lin_after_fail = -1;
    double per_soft = 0, worst = 0;
    pn_real *x[2] = {NULL, NULL};
    size_t n = 0;
    pn_mpm_implicit_desc id;
    pn_mpm_stats st;
    pn_mpm_world *w = t_mg_scene(3, 28, 1e5, 1, PN_BOUNDARY_STICKY, &g);
    PN_CHECK(w != NULL);
    if (!w) return;
    memset(&id, 0, sizeof id);
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, &st) == PN_OK);
    PN_CHECK(w->s.n_act * 3 >= PN__MPM_MG_MIN); /* the size where the choice is made */
    per_soft = st.newton_iters ? (double)st.cg_iters / st.newton_iters : 0;
    PN_CHECK(st.mg_builds == 0 && w->s.lin_mg == 0);
    PN_CHECK_LE(per_soft, PN__MPM_JACOBI_MAX);
    PN_REPORT("E 1e5 Pa, dt 1e-3 s (dt / dt_CFL %.1f): Jacobi, %.1f CG per Newton iteration, %d hierarchies",
              (double)st.dt_over_cfl, per_soft, st.mg_builds);
    pn_mpm_destroy(w);
    for (k = 0; k < 2; ++k) {
        w = t_mg_scene(3, 28, 4e8, 1, PN_BOUNDARY_STICKY, &g);
        PN_CHECK(w != NULL);
        if (!w) break;
        memset(&id, 0, sizeof id);
        id.linear_solver = k ? PN_MPM_LINEAR_MULTIGRID : PN_MPM_LINEAR_DEFAULT;
        id.newton_tol = 1e-7;
        id.cg_rel_tol = 1e-5;
        if (k == 0) { /* a failed call first */
            id.newton_max = 1, id.max_halvings = -1;
            PN_CHECK(pn_mpm_step_implicit(w, 1e-2, &id, NULL) == PN_ERROR_NOT_CONVERGED);
            lin_after_fail = w->s.lin_mg;
            id.newton_max = 0, id.max_halvings = 0;
        }
        for (s = 0; s < 2 - k; ++s) { /* the default's two steps, MULTIGRID's first */
            PN_CHECK(pn_mpm_step_implicit(w, 1e-2, &id, &st) == PN_OK);
            if (s == 0) x[k] = t_mg_keep_v(w, &n);
            if (k == 0) builds[s] = st.mg_builds;
            if (k == 0 && s == 0)
                PN_REPORT("E 4e8 Pa, dt 1e-2 s (dt / dt_CFL %.0f), the default's first step: %d CG in %d Newton "
                          "iterations, %d capped, %d hierarchies", (double)st.dt_over_cfl, st.cg_iters, st.newton_iters,
                          st.cg_capped, st.mg_builds);
        }
        pn_mpm_destroy(w);
    }
    worst = t_mg_gap(x, n, 1e-2 * 28);
    PN_REPORT("the default's second step built %d hierarchies; its first step's velocities against MULTIGRID's: %.1e dx "
              "per step; the choice after a failed call: %d", builds[1], worst, lin_after_fail);
    PN_CHECK(lin_after_fail == 0);
    PN_CHECK(builds[1] > 0);
    PN_CHECK_LE(worst, 1e-6);
}

static const pn_test_case pn_tests_mpm_multigrid[] = {
    {"multigrid_operators", multigrid_operators},
    {"multigrid_iterations", multigrid_iterations},
    {"multigrid_default_3d", multigrid_default_3d},
};
