/* test_mpm_newton.c: the implicit step's solve, plastinet_mpm.h's >>newton, >>implicit and
   >>implicit-step rooms (implicit_*, newton_*): the substep fallback, a failed step leaves no
   trace (twin worlds agree to the bit), the line search descends, Newton's tail (unprojected
   Hessians near the minimum), Eisenstat-Walker forcing,
   CG capped at cg_max, the stage clock. Helpers: test_mpm_world.c. */

/* A step that cannot converge falls back to substeps: the world then equals the one stepped
   by hand with those substeps, and time and the step count advance by one step. */
PN_TEST(implicit_fallback) {
    int g, k, subs;
    pn_mpm_world *a = t_mpm_sand_world(32, 0.5, &g), *b = t_mpm_sand_world(32, 0.5, &g);
    double lo[2] = {0.4, 3.0 / 32}, sz[2] = {0.12, 0.24};
    pn_mpm_implicit_desc id;
    pn_mpm_stats st;
    size_t n = t_mpm_block(a, g, lo, sz, NULL);
    t_mpm_block(b, g, lo, sz, NULL);
    memset(&id, 0, sizeof id);
    id.newton_max = 2; /* too few for 2e-2 s from rest under gravity; enough for shorter steps */
    id.max_halvings = 6;
    id.newton_tol = 1e-7;
    PN_CHECK(pn_mpm_step_implicit(a, 2e-2, &id, &st) == PN_OK);
    PN_CHECK(st.substeps > 1);
    for (k = 0; k < st.substeps; ++k) PN_CHECK(pn_mpm_step_implicit(b, 2e-2 / st.substeps, &id, NULL) == PN_OK);
    PN_CHECK(memcmp(a->x, b->x, sizeof(pn_real) * n * 2) == 0 && memcmp(a->v, b->v, sizeof(pn_real) * n * 2) == 0);
    PN_CHECK(a->steps == 1 && a->time_s == (pn_real)2e-2);
    subs = st.substeps;
    id.max_halvings = -1; /* no fallback: the failure is reported, the world unchanged */
    {
        pn_real *copy = (pn_real *)malloc(sizeof(pn_real) * n * 2);
        memcpy(copy, a->x, sizeof(pn_real) * n * 2);
        PN_CHECK(pn_mpm_step_implicit(a, 2e-2, &id, &st) == PN_ERROR_NOT_CONVERGED);
        PN_CHECK(memcmp(copy, a->x, sizeof(pn_real) * n * 2) == 0 && a->steps == 1);
        free(copy);
    }
    PN_REPORT("2e-2 s step with 2 Newton iterations: %d substeps, identical to stepping them by hand", subs);
    pn_mpm_destroy(a);
    pn_mpm_destroy(b);
}

/* ---- a failed implicit step leaves nothing behind -------------------------------------- */

/* a world for the twin test: sand (Drucker-Prager) on a frictional floor, the group's
   implicit energy en (PlasticityNet from the shipped models). rest 0: a block (E 1e6 Pa)
   thrown at the floor; rest 1: a stiff layer (E 1e8 Pa) resting on it, where F moves less
   than PlasticityNet's reuse tolerance per step, so its Taylor models live across steps. */
static pn_mpm_world *t_twin_world(int dim, int rest, pn_energy en, pn_pnet *net) {
    int res = dim == 2 ? 32 : 10, g;
    double E = rest ? 1e8 : 1e6;
    pn_mpm_world *w = t_mpm_world(dim, res, -9.81, PN_BOUNDARY_SEPARATE);
    double lo[3] = {0.35, 3.0 / res, 0.35}, sz[3] = {0.3, 0.3, 0.3}, v[3] = {0.3, -1, 0.2}, v0[3] = {0, 0, 0};
    if (!w) return NULL;
    if (rest) lo[0] = lo[2] = 3.0 / res, sz[0] = sz[2] = 1 - 6.0 / res, sz[1] = 2.0 / res;
    w->desc.friction = 0.5;
    g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_DRUCKER_PRAGER, E);
#ifdef PN_TEST_HAVE_MODELS
    if (en == PN_ENERGY_PNET) {
        pn_material m;
        pn_pnet_desc nd;
        const pn_model *model = dim == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
        memset(&nd, 0, sizeof nd);
        nd.energy = model;
        if (pn_model_material(model, E, &m, NULL, 0) != PN_OK || pn_pnet_init(net, &nd, &m, dim, NULL, 0) != PN_OK) g = -1;
        else w->groups[g].material = m;
    }
#else
    (void)net;
#endif
    if (g < 0 || pn_mpm_group_set_energy(w, g, en, en == PN_ENERGY_PNET ? net : NULL) != PN_OK ||
        t_mpm_block(w, g, lo, sz, rest ? v0 : v) == 0) {
        pn_mpm_destroy(w);
        return NULL;
    }
    return w;
}

/* every state a later step reads: the particles, time and step count */
static int t_twin_same(const pn_mpm_world *a, const pn_mpm_world *b) {
    size_t n = a->n, d = (size_t)a->dim;
    return a->n == b->n && a->time_s == b->time_s && a->steps == b->steps &&
           memcmp(a->x, b->x, sizeof(pn_real) * n * d) == 0 && memcmp(a->v, b->v, sizeof(pn_real) * n * d) == 0 &&
           memcmp(a->C, b->C, sizeof(pn_real) * n * d * d) == 0 && memcmp(a->F, b->F, sizeof(pn_real) * n * d * d) == 0 &&
           memcmp(a->h, b->h, sizeof(pn_real) * n) == 0 && memcmp(a->active, b->active, n) == 0;
}

/* Twin worlds: one tries a step that fails, the other never does; the failure returns an
   error and leaves the visible state as it was, and the next good steps of both agree to
   the bit (four steps: a model left behind would be used in the first). For every implicit energy (PlasticityNet with and without its Taylor models), the
   stress formulation, Jacobi and multigrid, 2D and 3D, moving and resting sand, and three
   ways to fail: Newton capped (a first attempt that fails), the Newton budget spent over the
   substeps (every fallback level fails), and a step of 1e3 s (moving: the advection limit)
   or a linear solve capped at one CG iteration (resting). make test: 2D (PlasticityNet with
   its Taylor models, the state a failed step could leave behind), and 3D with the lagged
   energy; PN_TEST_FULL=1 (make test-all, CI): 3D with every energy, and 2D PlasticityNet
   without the models too. */
PN_TEST(implicit_failed_step_no_trace) {
    static const pn_energy ens[6] = {PN_ENERGY_ELASTIC, PN_ENERGY_LAGGED, PN_ENERGY_DP, PN_ENERGY_PNET,
                                         PN_ENERGY_PNET, PN_ENERGY_DEFAULT};
    static const char *names[6] = {"elastic", "lagged", "dp", "pnet", "pnet (no reuse)", "stress"};
    int dim, e, rest, mode, cases = 0, failed_ok = 0, twins_ok = 0;
    for (dim = 2; dim <= 3; ++dim)
        for (e = 0; e < 6; ++e)
            for (rest = 0; rest < 2; ++rest)
                for (mode = 0; mode < 3; ++mode) {
                    pn_pnet net[2];
                    pn_mpm_world *a, *b;
                    pn_mpm_implicit_desc good, bad;
                    pn_real dt_bad = mode == 2 && !rest ? (pn_real)1e3 : (pn_real)2e-2;
                    int k, same_before, same_after = 1;
                    pn_result r;
#ifndef PN_TEST_HAVE_MODELS
                    if (ens[e] == PN_ENERGY_PNET) continue;
#endif
                    if (e == 5 && mode == 2 && rest) continue; /* no CG in the stress formulation */
                    if (mode == 1 && !rest) continue;             /* the substeps' path: resting sand */
                    if (dim == 3 && e != 1 && !pn_test_full()) continue; /* make test: 3D lagged only */
                    if (e == 4 && !pn_test_full()) continue; /* and PlasticityNet with its Taylor models only */
                    a = t_twin_world(dim, rest, ens[e], &net[0]);
                    b = t_twin_world(dim, rest, ens[e], &net[1]);
                    PN_CHECK(a && b);
                    if (!a || !b) {
                        pn_mpm_destroy(a), pn_mpm_destroy(b);
                        continue;
                    }
                    memset(&good, 0, sizeof good);
                    if (e == 4) good.pnet_reuse_tol = -1;
                    if (e == 5) good.formulation = PN_MPM_FORMULATION_STRESS;
                    if (dim == 3 && rest) good.linear_solver = PN_MPM_LINEAR_MULTIGRID;
                    bad = good;
                    bad.newton_tol = (pn_real)1e-9, bad.sweeps_max = 2;
                    if (mode == 0) bad.newton_max = 1, bad.max_halvings = -1;
                    if (mode == 1) bad.newton_max = 1, bad.max_halvings = 2, bad.newton_budget = 2;
                    if (mode == 2 && rest) bad.cg_max = 1, bad.max_halvings = -1;
                    for (k = 0; k < 3; ++k) {
                        PN_CHECK(pn_mpm_step_implicit(a, 1e-3, &good, NULL) == PN_OK);
                        PN_CHECK(pn_mpm_step_implicit(b, 1e-3, &good, NULL) == PN_OK);
                    }
                    r = pn_mpm_step_implicit(a, dt_bad, &bad, NULL);
                    cases++;
                    failed_ok += r != PN_OK;
                    same_before = t_twin_same(a, b);
                    for (k = 0; k < 4; ++k) {
                        pn_result ra = pn_mpm_step_implicit(a, 1e-3, &good, NULL), rb = pn_mpm_step_implicit(b, 1e-3, &good, NULL);
                        PN_CHECK(ra == PN_OK && rb == PN_OK);
                    }
                    same_after = t_twin_same(a, b);
                    twins_ok += same_after;
                    if (r == PN_OK || !same_before || !same_after) {
                        fprintf(stderr, "  %dD %s, %s, failure %d (dt %g): the step returned %s; state %s after it, %s four "
                                "steps later\n", dim, names[e], rest ? "resting" : "moving", mode, (double)dt_bad,
                                pn_result_string(r), same_before ? "same" : "DIFFERENT", same_after ? "same" : "DIFFERENT");
                        PN_CHECK(0);
                    }
                    pn_mpm_destroy(a), pn_mpm_destroy(b);
                }
    PN_REPORT("%d failed steps of %d refused; twins identical four steps later in %d", failed_ok, cases, twins_ok);
}

/* trace of the implicit solve: the incremental potential at each Newton iterate */
typedef struct t_mpm_trace {
    int solve, calls, rises, solves;
    double last, worst_rise;
} t_mpm_trace;

static void t_mpm_on_newton(void *user, int solve, int iteration, pn_real energy, pn_real residual) {
    t_mpm_trace *t = (t_mpm_trace *)user;
    (void)residual;
    if (t->calls > 0 && solve == t->solve && iteration > 0 && energy > t->last) {
        t->rises++;
        t->worst_rise = fmax(t->worst_rise, (energy - t->last) / fabs(t->last));
    }
    if (iteration == 0) t->solves++;
    t->solve = solve;
    t->last = energy;
    t->calls++;
}

/* Every step the line search accepts lowers the incremental potential: within one
   minimization the traced energies never rise (sand column on a Coulomb floor, PlasticityNet
   where the models ship, else the lagged energy, 1 and 4 fixed-point passes; the frozen-yield
   Drucker-Prager energy, 2 passes; 1e-3 and 1e-2 s). */
PN_TEST(newton_line_search_descends) {
    int g, s, k;
    for (k = 0; k < 6; ++k) {
        pn_mpm_world *w = t_mpm_sand_world(32, 0.5, &g);
        double lo[2] = {0.4, 3.0 / 32}, sz[2] = {0.12, 0.24}, dt = k & 1 ? 1e-2 : 1e-3;
        pn_mpm_implicit_desc id;
        t_mpm_trace tr;
        const char *energy = "lagged";
        memset(&id, 0, sizeof id);
        memset(&tr, 0, sizeof tr);
        id.fixed_point_iters = k < 2 ? 1 : k < 4 ? 4 : 2;
        id.trace = t_mpm_on_newton;
        id.trace_user = &tr;
        t_mpm_block(w, g, lo, sz, NULL);
        if (k >= 4) {
            PN_CHECK(pn_mpm_group_set_energy(w, g, PN_ENERGY_DP, NULL) == PN_OK);
            energy = "frozen-yield DP";
        }
#ifdef PN_TEST_HAVE_MODELS
        if (k < 4) {
            pn_material m;
            pn_pnet net;
            pn_pnet_desc nd;
            pn_model_material(pn_model_sand_2d(), 1e6, &m, NULL, 0);
            w->groups[g].material = m;
            memset(&nd, 0, sizeof nd);
            nd.energy = pn_model_sand_2d();
            if (pn_pnet_init(&net, &nd, &m, 2, NULL, 0) == PN_OK && pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, &net) == PN_OK)
                energy = "PlasticityNet";
        }
#endif
        for (s = 0; s < (int)(0.2 / dt + 0.5); ++s) PN_CHECK(pn_mpm_step_implicit(w, dt, &id, NULL) == PN_OK);
        PN_CHECK(tr.calls > tr.solves && tr.rises == 0);
        PN_REPORT("%s, dt %g, %d passes: %d Newton iterates in %d minimizations, %d rises (worst %.1e relative)",
                  energy, dt, id.fixed_point_iters, tr.calls, tr.solves, tr.rises, tr.worst_rise);
        pn_mpm_destroy(w);
    }
}

/* Newton near the minimum (PN__MPM_FULL_H): the particles' Hessians go unprojected once the
   step is small, so the tail converges quadratically where the PSD projection changes the
   Hessian: an elastic StVK-Hencky column (its energy is not convex in compression) crushed
   by a sticky lid at 0.5 m/s in steps of 1e-2 s. From a step of 1e-3 cells to the stop
   (newton_tol 1e-5) in a few iterations (with the Hessians projected throughout: up to 13,
   193 Newton iterations against 123). */
typedef struct t_mpm_tail {
    int solve, first, worst, solves, count;
} t_mpm_tail;

static void t_mpm_tail_close(t_mpm_tail *t) {
    if (t->first >= 0 && t->count - t->first > t->worst) t->worst = t->count - t->first;
}

static void t_mpm_on_tail(void *user, int solve, int iteration, pn_real energy, pn_real residual) {
    t_mpm_tail *t = (t_mpm_tail *)user;
    (void)energy;
    if (solve != t->solve || iteration == 0) { /* a new minimization */
        t_mpm_tail_close(t);
        t->solve = solve, t->first = -1, t->count = 0, t->solves++;
    }
    if (t->first < 0 && residual <= 1e-3) t->first = t->count;
    t->count++;
}

PN_TEST(implicit_newton_tail) {
    int g, s;
    pn_mpm_world *w = t_mpm_world(2, 32, (pn_real)-9.81, PN_BOUNDARY_STICKY);
    double lo[2] = {0.45, 3.0 / 32}, sz[2] = {0.06, 0.36};
    pn_mpm_implicit_desc id;
    pn_collider lid;
    t_mpm_tail tr;
    long newton = 0;
    PN_CHECK(w != NULL);
    if (!w) return;
    memset(&tr, 0, sizeof tr);
    tr.solve = -1, tr.first = -1;
    memset(&id, 0, sizeof id);
    id.trace = t_mpm_on_tail, id.trace_user = &tr;
    g = t_mpm_group(w, PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_NONE, 1e5);
    t_mpm_block(w, g, lo, sz, NULL);
    memset(&lid, 0, sizeof lid);
    lid.shape = PN_SHAPE_HALF_SPACE, lid.boundary = PN_BOUNDARY_STICKY, lid.normal[1] = -1;
    lid.center_m[1] = (pn_real)(lo[1] + sz[1] + 0.01), lid.velocity_m_s[1] = (pn_real)-0.5;
    PN_CHECK(pn_mpm_add_collider(w, &lid, NULL) == PN_OK);
    for (s = 0; s < 25; ++s) {
        pn_mpm_stats st;
        if (pn_mpm_step_implicit(w, 1e-2, &id, &st) != PN_OK) {
            fprintf(stderr, "  implicit_newton_tail, step %d: %s\n", s, pn_mpm_error(w));
            PN_CHECK(0);
            break;
        }
        newton += st.newton_iters;
    }
    t_mpm_tail_close(&tr);
    PN_REPORT("%d minimizations, %ld Newton iterations: at most %d from a step of 1e-3 cells to the stop", tr.solves, newton,
              tr.worst);
    PN_CHECK(tr.solves >= 25);
    PN_CHECK(tr.worst <= 4);
    pn_mpm_destroy(w);
}

/* Newton's stop without a confirming solve (pn__newton_done): after a full step that shrank
   to at most a tenth of the one before, Newton stops once the steps still to come, summed at
   that contraction, are below newton_tol dx / dt. An elastic 2D block (StVK-Hencky, E 1e5
   Pa) thrown at a sticky floor at 10 speeds, one step of 1e-2 s each at the default
   newton_tol (1e-5) beside the same step solved to 1e-8 (Newton and CG): some solves end
   that way (their last traced step above the bound, which a solve that measured its last
   step never leaves), and every step's positions are within newton_tol dx of the tight ones
   (the stop's promise: x = x^n + dt v). */
typedef struct t_mpm_stop {
    int solves, early;
    double last, bound;
} t_mpm_stop;

static void t_mpm_on_stop(void *user, int solve, int iteration, pn_real energy_j, pn_real residual) {
    t_mpm_stop *t = (t_mpm_stop *)user;
    (void)solve, (void)energy_j;
    if (iteration == 0 && t->solves++ > 0) t->early += t->last > t->bound;
    t->last = (double)residual;
}

PN_TEST(implicit_newton_stop) {
    int g, s, k, ok = 1;
    double lo[2] = {0.4, 3.0 / 32 + 0.01}, sz[2] = {0.2, 0.2}, worst = 0, dx = 1.0 / 32;
    t_mpm_stop tr;
    memset(&tr, 0, sizeof tr);
    tr.bound = 1e-5;
    for (s = 0; s < 10 && ok; ++s) {
        double v[2] = {0.1 * s, -0.5 - 0.2 * s};
        pn_mpm_world *w[2];
        size_t p;
        for (k = 0; k < 2; ++k) {
            pn_mpm_implicit_desc id;
            w[k] = t_mpm_world(2, 32, (pn_real)-9.81, PN_BOUNDARY_STICKY);
            ok &= w[k] != NULL;
            if (!w[k]) break;
            g = t_mpm_group(w[k], PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_NONE, 1e5);
            t_mpm_block(w[k], g, lo, sz, v);
            memset(&id, 0, sizeof id);
            if (k == 0) id.trace = t_mpm_on_stop, id.trace_user = &tr;
            else id.newton_tol = 1e-8, id.cg_rel_tol = 1e-8;
            ok &= pn_mpm_step_implicit(w[k], 1e-2, &id, NULL) == PN_OK;
        }
        for (p = 0; ok && p < w[0]->n * 2; ++p) worst = fmax(worst, fabs((double)(w[0]->x[p] - w[1]->x[p])) / dx);
        pn_mpm_destroy(w[0]);
        if (k == 2) pn_mpm_destroy(w[1]);
    }
    tr.early += tr.last > tr.bound;
    PN_REPORT("%d of %d solves stopped on the contraction; positions against newton_tol and cg_rel_tol 1e-8: at most %.2e dx "
              "(the promise: 1e-5)", tr.early, tr.solves, worst);
    PN_CHECK(ok);
    PN_CHECK(tr.early > 0);
    PN_CHECK_LE(worst, 1e-5);
}

/* PlasticityNet in float lanes near Newton's minimum: the lanes round each particle's
   energy to about 1e-7 of its network's value, so once Newton's predicted decrease is below
   about 1e-6 of the energy the line search sees rounding, and Newton stalled at one
   residual (the snow press at 10k particles: 50 iterations in a step). Now it stops there
   within the acceptance band, and short of it goes on with the network in pn_real. A 3D
   Cam-Clay snow layer (snow_3d, E 1e6 Pa, 1,280 particles) pressed by a sticky plate in
   steps of 1e-2 s: the lanes take about as many Newton iterations as the double reference
   (pnet_double; before: 13.1 a step against its 4.3) and move the snow as it does. */
#ifdef PN_TEST_HAVE_MODELS
static pn_mpm_world *t_mpm_snow_press(void) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material m;
    pn_pnet net;
    pn_pnet_desc nd;
    pn_collider plate;
    double dx = 0.5 / 16, lo[3] = {0.125, 3 * dx, 0.125}, sz[3] = {0.25, 0.075, 0.25};
    pn_real h[4096];
    size_t n, p;
    int g;
    memset(&wd, 0, sizeof wd);
    wd.dim = 3;
    wd.res[0] = wd.res[1] = wd.res[2] = 16;
    wd.dx_m = (pn_real)dx;
    wd.gravity[1] = (pn_real)-9.81;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = (pn_real)0.5;
    wd.wall_cells = 3;
    wd.filter_time_s = (pn_real)2e-3;
    wd.max_particles = 4096;
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK) return NULL;
    memset(&nd, 0, sizeof nd);
    nd.energy = pn_model_snow_3d();
    if (pn_model_material(nd.energy, 1e6, &m, NULL, 0) != PN_OK || (g = pn_mpm_add_group(w, &m, 400)) < 0 ||
        pn_pnet_init(&net, &nd, &m, 3, NULL, 0) != PN_OK || pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, &net) != PN_OK ||
        (n = t_mpm_block(w, g, lo, sz, NULL)) == 0) {
        pn_mpm_destroy(w);
        return NULL;
    }
    for (p = 0; p < n; ++p) h[p] = (pn_real)-0.01; /* a little consolidated */
    memset(&plate, 0, sizeof plate);
    plate.shape = PN_SHAPE_BOX, plate.boundary = PN_BOUNDARY_STICKY;
    plate.center_m[0] = plate.center_m[2] = (pn_real)0.25, plate.center_m[1] = (pn_real)(lo[1] + sz[1] + 0.025);
    plate.half_extent_m[0] = plate.half_extent_m[2] = (pn_real)0.05, plate.half_extent_m[1] = (pn_real)0.025;
    plate.velocity_m_s[1] = (pn_real)-0.2;
    if (pn_mpm_set_state(w, 0, n, h) != PN_OK || pn_mpm_add_collider(w, &plate, NULL) != PN_OK) {
        pn_mpm_destroy(w);
        return NULL;
    }
    return w;
}
#endif

PN_TEST(implicit_pnet_lanes_converge) {
#ifdef PN_TEST_HAVE_MODELS
    pn_mpm_world *w[2];
    long newton[2] = {0, 0};
    int k, s, steps = 10;
    double worst = 0;
    size_t p;
    for (k = 0; k < 2; ++k) {
        pn_mpm_implicit_desc id;
        memset(&id, 0, sizeof id);
        id.pnet_double = k; /* 0: the lanes; 1: the reference */
        w[k] = t_mpm_snow_press();
        PN_CHECK(w[k] != NULL);
        if (!w[k]) return;
        for (s = 0; s < steps; ++s) {
            pn_mpm_stats st;
            if (pn_mpm_step_implicit(w[k], (pn_real)1e-2, &id, &st) != PN_OK) {
                fprintf(stderr, "  implicit_pnet_lanes_converge (%s), step %d: %s\n", k ? "double" : "lanes", s,
                        pn_mpm_error(w[k]));
                PN_CHECK(0);
                break;
            }
            newton[k] += st.newton_iters;
        }
    }
    for (p = 0; p < w[0]->n; ++p) {
        int i;
        for (i = 0; i < 3; ++i) worst = fmax(worst, fabs((double)(w[0]->x[p * 3 + i] - w[1]->x[p * 3 + i])));
    }
    worst /= (double)w[0]->desc.dx_m;
    PN_REPORT("Newton iterations a step: lanes %.1f, double %.1f; positions after %d steps at most %.2e cells apart",
              (double)newton[0] / steps, (double)newton[1] / steps, steps, worst);
    PN_CHECK(newton[0] <= newton[1] + steps); /* at most one iteration a step more */
    PN_CHECK_LE(worst, 0.05);
    pn_mpm_destroy(w[0]);
    pn_mpm_destroy(w[1]);
#else
    PN_REPORT("skipped: built without PN_TEST_HAVE_MODELS");
#endif
}

/* Eisenstat-Walker forcing (pn_mpm_implicit_desc.cg_forcing_max) only changes how the
   Newton iterates get to the minimum: a sand column on a Coulomb floor with the frozen-yield
   Drucker-Prager energy (kinks, where the linear model often fails) ends where every solve
   to cg_rel_tol puts it, to the Newton tolerance, with looser solves on the way (Jacobi CG:
   on this small grid multigrid solves exactly in one iteration). */
PN_TEST(implicit_newton_forcing) {
    pn_mpm_world *w[2];
    double lo[2] = {0.4, 3.0 / 32}, sz[2] = {0.12, 0.24}, worst = 0;
    long cg[2] = {0, 0}, newton[2] = {0, 0};
    int g, k, s;
    size_t n = 0, p;
    for (k = 0; k < 2; ++k) {
        pn_mpm_implicit_desc id;
        pn_mpm_stats st;
        w[k] = t_mpm_sand_world(32, 0.5, &g);
        PN_CHECK(w[k] != NULL);
        if (!w[k]) return;
        n = t_mpm_block(w[k], g, lo, sz, NULL);
        PN_CHECK(pn_mpm_group_set_energy(w[k], g, PN_ENERGY_DP, NULL) == PN_OK);
        memset(&id, 0, sizeof id);
        id.fixed_point_iters = 1;
        id.newton_tol = 1e-9;
        id.cg_forcing_max = k ? 0 : 0.5; /* 0: off, the default */
        id.linear_solver = PN_MPM_LINEAR_JACOBI; /* where CG iterations are many enough to save */
        for (s = 0; s < 100; ++s) {
            PN_CHECK(pn_mpm_step_implicit(w[k], 1e-3, &id, &st) == PN_OK);
            cg[k] += st.cg_iters;
            newton[k] += st.newton_iters;
        }
    }
    for (p = 0; p < 2 * n; ++p) worst = fmax(worst, fabs(w[0]->x[p] - w[1]->x[p]));
    PN_CHECK_LE(worst * 32, 1e-5); /* in cells: 100 steps of 1e-9 dx, with room for the kinks */
    PN_CHECK(cg[0] * newton[1] < cg[1] * newton[0]); /* looser solves: fewer CG per Newton step */
    PN_REPORT("0.1 s: positions agree to %.1e dx; Newton / CG iterations %ld / %ld with forcing, %ld / %ld without",
              worst * 32, newton[0], cg[0], newton[1], cg[1]);
    pn_mpm_destroy(w[0]);
    pn_mpm_destroy(w[1]);
}

/* A Newton step whose linear solve stops at cg_max is not a converged one: an elastic block
   landing on the floor at 1e-2 s (about 20 explicit steps per step) with cg_max = 3 must
   fail with PN_ERROR_NOT_CONVERGED, naming cg_max, count its capped solves and leave the
   world as it was (no fallback: max_halvings < 0; Jacobi CG); with the fallback, newton_budget bounds
   the Newton iterations of all its attempts (traced); with the defaults the same step
   converges, no solve is capped, and the step reports dt / dt_CFL against the analytic
   P-wave bound. */
static void t_count_trace(void *user, int solve, int iteration, pn_real energy_j, pn_real residual) {
    (void)solve, (void)iteration, (void)energy_j, (void)residual;
    ++*(int *)user;
}

PN_TEST(implicit_cg_capped) {
    pn_mpm_world *w = t_mpm_world(2, 32, -9.81, PN_BOUNDARY_SEPARATE);
    int traced = 0;
    double lo[2] = {0.4, 3.0 / 32 + 0.02}, sz[2] = {0.2, 0.1}, v[2] = {0, -1};
    pn_mpm_implicit_desc id;
    pn_mpm_stats st;
    pn_real *x0;
    size_t n, p;
    int g, same = 1;
    PN_CHECK(w != NULL);
    if (!w) return;
    g = t_mpm_group(w, PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE, 1e6);
    n = t_mpm_block(w, g, lo, sz, v);
    x0 = (pn_real *)malloc(sizeof(pn_real) * 2 * n);
    PN_CHECK(n > 0 && x0 != NULL);
    if (!x0) return;
    memcpy(x0, w->x, sizeof(pn_real) * 2 * n);
    memset(&id, 0, sizeof id);
    id.cg_max = 3;
    id.max_halvings = -1;
    id.linear_solver = PN_MPM_LINEAR_JACOBI; /* multigrid needs fewer than 3 here */
    PN_CHECK(pn_mpm_step_implicit(w, 1e-2, &id, &st) == PN_ERROR_NOT_CONVERGED);
    PN_CHECK(strstr(pn_mpm_error(w), "cg_max") != NULL);
    for (p = 0; p < 2 * n; ++p) same &= w->x[p] == x0[p];
    PN_CHECK(same && w->time_s == 0);
    PN_CHECK(st.cg_capped > 0);
    PN_REPORT("cg_max 3: %s (%d of %d Newton steps capped)", pn_mpm_error(w), st.cg_capped, st.newton_iters);
    /* with the fallback on, newton_budget bounds the Newton iterations of all attempts */
    id.max_halvings = 3;
    id.newton_budget = 70;
    id.trace = t_count_trace;
    id.trace_user = &traced;
    PN_CHECK(pn_mpm_step_implicit(w, 1e-2, &id, &st) == PN_ERROR_NOT_CONVERGED);
    PN_CHECK(traced <= 70 && traced > 50 && strstr(pn_mpm_error(w), "newton_budget") != NULL);
    for (p = 0, same = 1; p < 2 * n; ++p) same &= w->x[p] == x0[p];
    PN_CHECK(same && w->time_s == 0);
    PN_REPORT("cg_max 3, newton_budget 70: %d Newton iterations in all, then: %s", traced, pn_mpm_error(w));
    memset(&id, 0, sizeof id); /* the defaults */
    PN_CHECK(pn_mpm_step_implicit(w, 1e-2, &id, &st) == PN_OK);
    PN_CHECK(st.cg_capped == 0);
    { /* the explicit bound 0.9 dx / (c + |v|): P-wave speed c = sqrt(E (1 - nu) / ((1 + nu)(1 - 2 nu)) / rho)
         of E 1e6 Pa, nu 0.3, 1000 kg/m^3 at rest (J = 1), the block falling at 1 m/s */
        double c = sqrt(1e6 * 0.7 / (1.3 * 0.4) / 1000), want = 1e-2 * (c + 1) / (0.9 / 32);
        PN_CHECK_LE(fabs((double)st.dt_over_cfl - want), 1e-6 * want);
    }
    PN_REPORT("default cg_max: converged in %d Newton / %d CG iterations, none capped; dt / dt_CFL %.1f",
              st.newton_iters, st.cg_iters, (double)st.dt_over_cfl);
    free(x0);
    pn_mpm_destroy(w);
}

/* a clock that ticks once per reading: stage_s then counts the readings that closed each stage */
static double t_tick(void *user) {
    return (double)++*(long *)user;
}

/* pn_mpm_desc.clock_s: an energy-formulation step fills setup, energy, linear and g2p and no
   sweeps; a stress-formulation step setup or energy, sweeps and g2p and no linear solve; the
   stages add up to the clock's advance over the step (every interval counted once); without
   a clock nothing is measured. */
PN_TEST(implicit_stage_clock) {
    double lo[3] = {0.4, 0.1, 0}, sz[3] = {0.2, 0.2, 0};
    size_t n;
    int k, s;
    for (k = 0; k < 3; ++k) {
        pn_mpm_world *w = t_stress_scene(pn__t, 32, -9.81, PN_BOUNDARY_SEPARATE, PN_PLASTIC_DRUCKER_PRAGER, 1e6, lo, sz, &n);
        pn_mpm_implicit_desc id = t_stress_desc();
        pn_mpm_stats st;
        long ticks = 0, before;
        double sum = 0;
        if (!w) return;
        if (k != 1) id.formulation = PN_MPM_FORMULATION_ENERGY;
        if (k < 2) w->desc.clock_s = t_tick, w->desc.clock_user = &ticks;
        before = ticks;
        PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, &st) == PN_OK && st.substeps == 1);
        for (s = 0; s < PN_MPM_STAGES; ++s) {
            sum += st.stage_s[s];
            PN_CHECK(st.stage_s[s] >= 0);
        }
        if (k == 0)
            PN_CHECK(st.stage_s[PN_MPM_STAGE_SETUP] > 0 && st.stage_s[PN_MPM_STAGE_ENERGY] > 0 &&
                     st.stage_s[PN_MPM_STAGE_LINEAR] > 0 && st.stage_s[PN_MPM_STAGE_G2P] > 0 &&
                     st.stage_s[PN_MPM_STAGE_SWEEPS] == 0);
        if (k == 1)
            PN_CHECK(st.stage_s[PN_MPM_STAGE_ENERGY] > 0 && st.stage_s[PN_MPM_STAGE_SWEEPS] > 0 &&
                     st.stage_s[PN_MPM_STAGE_G2P] > 0 && st.stage_s[PN_MPM_STAGE_LINEAR] == 0);
        if (k < 2) PN_CHECK(sum == (double)(ticks - before - 1)); /* n readings close n - 1 intervals */
        if (k == 2) PN_CHECK(sum == 0);
        PN_REPORT("%s: stage readings setup %g, energy %g, linear %g, sweeps %g, g2p %g", k == 0 ? "energy formulation"
                  : k == 1 ? "stress formulation" : "no clock", st.stage_s[0], st.stage_s[1], st.stage_s[2], st.stage_s[3],
                  st.stage_s[4]);
        pn_mpm_destroy(w);
    }
}

static const pn_test_case pn_tests_mpm_newton[] = {
    {"implicit_newton_stop", implicit_newton_stop},
    {"implicit_fallback", implicit_fallback},
    {"implicit_failed_step_no_trace", implicit_failed_step_no_trace},
    {"newton_line_search_descends", newton_line_search_descends},
    {"implicit_newton_tail", implicit_newton_tail},
    {"implicit_pnet_lanes_converge", implicit_pnet_lanes_converge},
    {"implicit_newton_forcing", implicit_newton_forcing},
    {"implicit_cg_capped", implicit_cg_capped},
    {"implicit_stage_clock", implicit_stage_clock},
};
