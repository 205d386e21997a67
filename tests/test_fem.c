/* test_fem.c - FEM (plastinet_mpm.h >>fem): the structured mesh builder, the patch test,
   the incremental potential against finite differences, the barrier, continuous collision
   detection, the Newton line search, a cantilever against Euler-Bernoulli, explicit against
   implicit, and bad meshes refused. Included by test_main.c. */

/* a mesh of a grid (t_fem_grid), one material, no gravity unless set */
typedef struct t_fem {
    pn_real *X;
    int *el;
    size_t nn, ne;
    pn_fem_mesh *m;
} t_fem;

static pn_group t_fem_group(pn_elastic_model e, pn_plastic_model p, double E, double rho) {
    pn_group g;
    pn_material_desc md;
    memset(&md, 0, sizeof md);
    md.elastic = e, md.plastic = p, md.youngs_modulus_pa = (pn_real)E, md.poisson_ratio = (pn_real)0.3;
    md.yield_stress_pa = (pn_real)(3e-3 * E), md.hardening_modulus_pa = (pn_real)(1e-2 * E);
    memset(&g, 0, sizeof g);
    pn_material_init(&g.material, &md, NULL, 0);
    g.density_kg_m3 = (pn_real)rho;
    return g;
}

/* *X, *el (malloc'd, a linear mesh of *nn nodes and ne elements) replaced by the quadratic mesh
   (pn_fem_quadratic_mesh); 0 on failure (the linear arrays kept). Also test_couple.c's. */
static int t_fem_quadratic(int dim, pn_real **X, int **el, size_t *nn, size_t ne) {
    size_t n2;
    pn_real *X2;
    int *el2;
    if (pn_fem_quadratic_mesh(dim, *X, *nn, *el, ne, NULL, NULL, NULL, &n2) != PN_OK) return 0;
    X2 = (pn_real *)malloc(sizeof(pn_real) * n2 * (size_t)dim);
    el2 = (int *)malloc(sizeof(int) * ne * (size_t)((dim + 1) * (dim + 2) / 2));
    if (!X2 || !el2 || pn_fem_quadratic_mesh(dim, *X, *nn, *el, ne, NULL, X2, el2, &n2) != PN_OK) {
        free(X2), free(el2);
        return 0;
    }
    free(*X), free(*el);
    *X = X2, *el = el2, *nn = n2;
    return 1;
}

/* the grid's mesh, made quadratic (pn_fem_quadratic_mesh) when order is 2 */
static int t_fem_make_order(t_fem *t, const pn_fem_grid *g, const pn_group *grp, double gy, int order) {
    pn_fem_desc fd;
    char why[256];
    memset(t, 0, sizeof *t);
    if (pn_fem_grid_mesh(g, NULL, NULL, &t->nn, &t->ne) != PN_OK) return 0;
    t->X = (pn_real *)malloc(sizeof(pn_real) * t->nn * (size_t)g->dim);
    t->el = (int *)malloc(sizeof(int) * t->ne * (size_t)(g->dim + 1));
    if (!t->X || !t->el || pn_fem_grid_mesh(g, t->X, t->el, &t->nn, &t->ne) != PN_OK) return 0;
    if (order == 2 && !t_fem_quadratic(g->dim, &t->X, &t->el, &t->nn, t->ne)) return 0;
    memset(&fd, 0, sizeof fd);
    fd.dim = g->dim, fd.n_nodes = t->nn, fd.n_elements = t->ne, fd.rest_m = t->X, fd.elements = t->el, fd.order = order;
    fd.groups = grp, fd.n_groups = 1, fd.gravity[1] = (pn_real)gy;
    if (pn_fem_create(&fd, &t->m, why, sizeof why) != PN_OK) {
        fprintf(stderr, "  t_fem_make: %s\n", why);
        return 0;
    }
    return 1;
}

static int t_fem_make(t_fem *t, const pn_fem_grid *g, const pn_group *grp, double gy) {
    return t_fem_make_order(t, g, grp, gy, 1);
}

static void t_fem_free(t_fem *t) {
    pn_fem_destroy(t->m);
    free(t->X);
    free(t->el);
}

static pn_fem_grid t_fem_grid(int dim, int nx, int ny, int nz, double sx, double sy, double sz) {
    pn_fem_grid g;
    memset(&g, 0, sizeof g);
    g.dim = dim, g.cells[0] = nx, g.cells[1] = ny, g.cells[2] = nz;
    g.size_m[0] = (pn_real)sx, g.size_m[1] = (pn_real)sy, g.size_m[2] = (pn_real)sz;
    return g;
}

/* counts, orientation and the exact volume of boxes and frames (2D also crossed) */
PN_TEST(fem_grid_mesh) {
    int dim;
    for (dim = 2; dim <= 4; ++dim) {
        int crossed = dim == 4;
        pn_fem_grid g = t_fem_grid(crossed ? 2 : dim, 4, 5, 3, 0.4, 0.5, 0.3);
        size_t nn, ne, e;
        t_fem t;
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
        double vol = 0, expect;
        int hole;
        for (hole = 0; hole < 2; ++hole) {
            if (hole) { /* a frame: the middle 2 x 3 (x 1) cells out */
                g.hole_lo_m[0] = (pn_real)0.1, g.hole_lo_m[1] = (pn_real)0.1, g.hole_lo_m[2] = (pn_real)0.1;
                g.hole_size_m[0] = (pn_real)0.2, g.hole_size_m[1] = (pn_real)0.3, g.hole_size_m[2] = (pn_real)(dim == 3 ? 0.1 : 0);
            }
            g.crossed = crossed;
            PN_CHECK(pn_fem_grid_mesh(&g, NULL, NULL, &nn, &ne) == PN_OK);
            if (crossed) {
                expect = hole ? 0.2 - 0.06 : 0.2;
                PN_CHECK(ne == (size_t)(hole ? 4 * (20 - 6) : 80));
                PN_CHECK(nn == (size_t)(hole ? 30 - 2 + 14 : 30 + 20)); /* and a centre per cell */
            } else if (dim == 2) {
                expect = hole ? 0.2 - 0.06 : 0.2;
                PN_CHECK(ne == (size_t)(hole ? 2 * (20 - 6) : 40));
                PN_CHECK(nn == (size_t)(hole ? 30 - 2 : 30)); /* the hole's 2 inner nodes go */
            } else {
                expect = hole ? 0.06 - 0.006 : 0.06;
                PN_CHECK(ne == (size_t)(hole ? 6 * (60 - 6) : 360));
            }
            if (!t_fem_make(&t, &g, &grp, 0)) {
                PN_CHECK(0);
                continue;
            }
            PN_CHECK(t.nn == nn && t.ne == ne);
            for (vol = 0, e = 0; e < t.ne; ++e) {
                PN_CHECK(t.m->vol0[e] > 0);
                vol += t.m->vol0[e];
            }
            PN_CHECK_NEAR(vol, expect, 1e-12);
            t_fem_free(&t);
        }
    }
}

/* Patch test: positions x = A X + b give every element F = A, and the elastic forces cancel
   at every interior node (after one explicit step from rest without gravity, interior nodes
   stay at rest while the boundary ones feel the unbalanced traction). */
PN_TEST(fem_patch) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        static const double A[9] = {1.05, 0.02, -0.03, 0.01, 0.97, 0.04, 0.02, -0.01, 1.02};
        pn_fem_grid g = t_fem_grid(dim, 4, 4, 4, 1, 1, 1);
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
        t_fem t;
        size_t k, e;
        double vin = 0, vout = 0, ferr = 0;
        int i, j;
        if (!t_fem_make(&t, &g, &grp, 0)) {
            PN_CHECK(0);
            continue;
        }
        for (k = 0; k < t.nn; ++k)
            for (i = 0; i < dim; ++i) {
                double acc = 0.1 * (i + 1);
                for (j = 0; j < dim; ++j) acc += A[i * 3 + j] * t.X[k * (size_t)dim + (size_t)j];
                t.m->x[k * (size_t)dim + (size_t)i] = (pn_real)acc;
            }
        for (e = 0; e < t.ne; ++e) {
            pn_real Ds[9], F[9];
            pn__fem_jac(t.m, e, t.m->x, Ds); /* linear elements: one point each, J = Ds */
            pn_mat_mul(dim, Ds, t.m->Dm_inv + e * (size_t)(dim * dim), F);
            for (i = 0; i < dim; ++i)
                for (j = 0; j < dim; ++j) ferr = fmax(ferr, fabs(F[i * dim + j] - A[i * 3 + j]));
        }
        PN_CHECK_LE(ferr, 1e-13);
        PN_CHECK(pn_fem_step_explicit(t.m, (pn_real)1e-6, NULL) == PN_OK);
        for (k = 0; k < t.nn; ++k) {
            int inside = 1;
            double v2 = 0;
            for (i = 0; i < dim; ++i) {
                double c = t.X[k * (size_t)dim + (size_t)i];
                inside &= c > 1e-9 && c < 1 - 1e-9;
                v2 += t.m->v[k * (size_t)dim + (size_t)i] * t.m->v[k * (size_t)dim + (size_t)i];
            }
            if (inside) vin = fmax(vin, sqrt(v2));
            else vout = fmax(vout, sqrt(v2));
        }
        PN_CHECK(vout > 0);
        PN_CHECK_LE(vin, 1e-9 * vout);
        t_fem_free(&t);
    }
}

/* the barrier's derivatives by central differences */
PN_TEST(fem_barrier_fd) {
    double dhat = 1e-3, d;
    for (d = 1e-5; d < 1.2e-3; d *= 1.7) {
        pn_real b, b1, b2, bp, bm, b1p, b1m, t1, t2;
        double h = 1e-4 * d;
        pn__fem_barrier((pn_real)d, (pn_real)dhat, &b, &b1, &b2);
        pn__fem_barrier((pn_real)(d + h), (pn_real)dhat, &bp, &b1p, &t1);
        pn__fem_barrier((pn_real)(d - h), (pn_real)dhat, &bm, &b1m, &t2);
        if (d >= dhat) {
            PN_CHECK(b == 0 && b1 == 0 && b2 == 0);
            continue;
        }
        PN_CHECK(b > 0 && b1 < 0 && b2 > 0); /* positive, decreasing, convex on (0, dhat) */
        PN_CHECK_NEAR(b1, (bp - bm) / (2 * h), 1e-6 * fabs(b1) + 1e-12);
        PN_CHECK_NEAR(b2, (b1p - b1m) / (2 * h), 1e-6 * fabs(b2) + 1e-9);
    }
}

static pn_real t_fem_E(pn_fem_mesh *m, const pn_real *x) {
    pn_real E = 0;
    if (pn__fem_objective(m, x, 0, &E) != PN_OK) return (pn_real)NAN;
    return E;
}

/* entry (r, c) (rows of unknowns in the solver's order) of the assembled Hessian, from the
   skyline or from the blocks */
static double t_fem_hget(const pn__fem *s, size_t r, size_t c) {
    size_t a = r > c ? r : c, b = r > c ? c : r, d = (size_t)s->d;
    if (s->sparse) {
        size_t q;
        for (q = s->brs[a / d]; q < s->brs[a / d + 1]; ++q)
            if ((size_t)s->bcol[q] == b / d) return s->bA[q * d * d + (a % d) * d + b % d];
        return 0;
    }
    return b >= s->fc[a] ? s->L[s->rs[a] + b - s->fc[a]] : 0;
}

/* The incremental potential's gradient and Hessian against central differences, with an
   obstacle within dhat of some nodes and a moving one (its offset an unknown), both with
   friction (sliding and in the smoothed stick range), in 2D and 3D,
   for Neo-Hookean (convex here: the projection changes nothing) and exact von Mises; the
   Hessian as the skyline holds it and as PCG's blocks do; linear and quadratic elements. */
PN_TEST(fem_objective_fd) {
    int dim, mat;
    for (dim = 2; dim <= 3; ++dim)
        for (mat = 0; mat < 8; ++mat) {
            pn_fem_grid g = t_fem_grid(dim, 2, 2, 1, 0.02, 0.02, 0.01);
            pn_group grp = mat & 1 ? t_fem_group(PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_VON_MISES, 1e6, 1000)
                                   : t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
            pn_collider c;
            t_fem t;
            pn__fem *s;
            size_t k, l, nu, nd;
            double gerr = 0, gmax = 0, herr = 0, hmax = 0;
            pn_real *x, *g0, *gp;
            unsigned long seed = 7;
            g.lo_m[1] = (pn_real)2e-5;
            if (!t_fem_make_order(&t, &g, &grp, -9.81, mat & 4 ? 2 : 1)) {
                PN_CHECK(0);
                continue;
            }
            if (mat & 1) PN_CHECK(pn_fem_group_set_energy(t.m, 0, PN_ENERGY_EXACT_VM, NULL) == PN_OK);
            memset(&c, 0, sizeof c);
            c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1, c.friction = (pn_real)0.5; /* the floor, 2e-5 below */
            PN_CHECK(pn_fem_add_obstacle(t.m, &c, NULL) == PN_OK);
            memset(&c, 0, sizeof c); /* a box coming down from above */
            c.shape = PN_SHAPE_BOX, c.center_m[0] = (pn_real)0.01, c.center_m[1] = (pn_real)(0.02 + 2e-5 + 1.5e-5 + 0.005);
            c.center_m[2] = (pn_real)0.005, c.half_extent_m[0] = (pn_real)0.004, c.half_extent_m[1] = (pn_real)0.005;
            c.half_extent_m[2] = (pn_real)0.01; /* no node below its edges: the distance's curvature there is dropped */
            c.velocity_m_s[1] = (pn_real)-0.01, c.friction = (pn_real)0.3;
            PN_CHECK(pn_fem_add_obstacle(t.m, &c, NULL) == PN_OK);
            s = (pn__fem *)t.m->impl;
            /* the step's setup as pn__fem_implicit_once does it, then a random state */
            PN_CHECK(pn__fem_linear_setup(t.m, mat & 2 ? PN_FEM_LINEAR_PCG : PN_FEM_LINEAR_CHOLESKY) == PN_OK);
            s->dt = (pn_real)1e-3, s->t_end = (pn_real)1e-3;
            pn__fem_setup(t.m);
            s->n_mov = 1, s->mov[0] = 1;
            nd = t.nn * (size_t)dim;
            nu = s->nu = nd + (size_t)dim;
            s->al_k = 1;
            for (k = 0; k < (size_t)dim; ++k) s->target[k] = k == 1 ? (pn_real)-1e-5 : 0, s->al_lam[k] = (pn_real)0.1;
            x = (pn_real *)malloc(sizeof(pn_real) * nu * 3);
            g0 = x + nu, gp = g0 + nu;
            for (k = 0; k < nu; ++k) {
                seed = seed * 6364136223846793005UL + 1442695040888963407UL;
                x[k] = (k < nd ? t.m->x[k] : 0) + (pn_real)(2e-6 * ((double)(seed >> 11) / 9007199254740992.0 - 0.5));
                s->xt[k] = k < nd ? t.m->x[k] : 0;
            }
            for (k = 0; k < nd; ++k) x[k] += (pn_real)(k % (size_t)dim == 0 ? 1e-4 * t.X[k + 1] : 0); /* some shear */
            PN_CHECK(pn__fem_prepare(t.m, x) == PN_OK);
            memcpy(s->xlag, x, sizeof(pn_real) * nu); /* friction's normal forces from here */
            {
                pn_real E0;
                PN_CHECK(pn__fem_objective(t.m, x, 2, &E0) == PN_OK);
                PN_CHECK(s->dmin < t.m->dhat); /* the barrier is active */
            }
            memcpy(g0, s->g, sizeof(pn_real) * nu);
            for (k = 0; k < nu; ++k) { /* gradient: central differences of E */
                pn_real keep = x[k], h = (pn_real)1e-8, Ep, Em;
                x[k] = keep + h, Ep = t_fem_E(t.m, x);
                x[k] = keep - h, Em = t_fem_E(t.m, x);
                x[k] = keep;
                gerr = fmax(gerr, fabs((Ep - Em) / (2 * h) - g0[k]));
                gmax = fmax(gmax, fabs(g0[k]));
            }
            /* Hessian: central differences of the gradient, column by column */
            {
                pn_real E;
                for (k = 0; k < nu; ++k) {
                    pn_real keep = x[k], h = (pn_real)1e-9;
                    x[k] = keep + h;
                    pn__fem_objective(t.m, x, 1, &E);
                    memcpy(gp, s->g, sizeof(pn_real) * nu);
                    x[k] = keep - h;
                    pn__fem_objective(t.m, x, 1, &E);
                    x[k] = keep;
                    for (l = 0; l < nu; ++l) g0[l] = (gp[l] - s->g[l]) / (2 * h); /* column k by FD */
                    pn__fem_objective(t.m, x, 2, &E);
                    for (l = 0; l < nu; ++l) {
                        double an = t_fem_hget(s, pn__fem_row(t.m, k), pn__fem_row(t.m, l));
                        herr = fmax(herr, fabs(g0[l] - an));
                        hmax = fmax(hmax, fabs(an));
                    }
                }
            }
            PN_CHECK(gmax > 0 && hmax > 0);
            PN_CHECK_LE(gerr, 1e-5 * gmax);
            PN_CHECK_LE(herr, 1e-4 * hmax);
            if (mat & 4) PN_REPORT("%dD quadratic, %s: gradient %.1e, Hessian %.1e of their largest entries", dim,
                                   mat & 1 ? "von Mises" : "Neo-Hookean", gerr / gmax, herr / hmax);
            free(x);
            t_fem_free(&t);
        }
}

/* CCD never reports a step past the true first contact: random and grazing straight paths
   of one node against a half-space and a moving box; the truth by fine sampling. */
PN_TEST(fem_ccd) {
    pn_fem_grid g = t_fem_grid(2, 1, 1, 1, 0.01, 0.01, 0.01);
    pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
    t_fem t;
    unsigned long seed = 99;
    int trial, shape, late = 0, hits = 0;
    if (!t_fem_make(&t, &g, &grp, 0)) {
        PN_CHECK(0);
        return;
    }
    for (shape = 0; shape < 2; ++shape)
        for (trial = 0; trial < 2000; ++trial) {
            pn__fem *s = (pn__fem *)t.m->impl;
            pn_collider *c = &t.m->obstacles[0];
            pn_real x[16], dir[16], nrm[3], amax;
            double r[8], tru = 2;
            int i, k;
            for (i = 0; i < 8; ++i) {
                seed = seed * 6364136223846793005UL + 1442695040888963407UL;
                r[i] = (double)(seed >> 11) / 9007199254740992.0 - 0.5;
            }
            memset(c, 0, sizeof *c);
            t.m->n_obstacles = 1;
            s->n_mov = 0, s->nu = t.nn * 2, s->t_end = 0;
            t.m->time_s = 0;
            if (shape == 0) c->shape = PN_SHAPE_HALF_SPACE, c->normal[0] = (pn_real)r[0], c->normal[1] = (pn_real)(r[1] + 0.7);
            else {
                c->shape = PN_SHAPE_BOX, c->half_extent_m[0] = (pn_real)0.02, c->half_extent_m[1] = (pn_real)0.01;
                s->n_mov = 1, s->mov[0] = 0, s->nu = t.nn * 2 + 2;
                c->velocity_m_s[0] = (pn_real)1e-3; /* moving: its offset is an unknown */
            }
            c->center_m[0] = (pn_real)(shape ? 0.005 + 0.03 * r[2] : 0), c->center_m[1] = (pn_real)(shape ? -0.02 - 0.005 * fabs(r[3]) : -0.001);
            for (k = 0; k < 16; ++k) x[k] = dir[k] = 0;
            for (k = 0; k < (int)t.nn; ++k) x[2 * k] = t.X[2 * k], x[2 * k + 1] = t.X[2 * k + 1];
            /* node 0 heads for the obstacle; grazing when trial is odd (tangent to it) */
            dir[0] = (pn_real)(0.02 * r[4]), dir[1] = (pn_real)(-0.03 * (fabs(r[5]) + (trial & 1 ? 0 : 0.2)));
            if (shape && trial % 3 == 0) dir[8] = (pn_real)(0.01 * r[6]), dir[9] = (pn_real)(0.02 * fabs(r[7])); /* box moves up */
            if (!(pn__fem_obstacle_sd(c, 2, 0, shape ? x + 8 : NULL, x, nrm) > 0)) continue;
            amax = pn__fem_ccd(t.m, x, dir);
            for (i = 1; i <= 20000; ++i) { /* the first sample inside, over twice the step */
                double a = 2.0 * i / 20000;
                pn_real p[2], u[2];
                p[0] = (pn_real)(x[0] + a * dir[0]), p[1] = (pn_real)(x[1] + a * dir[1]);
                u[0] = (pn_real)(a * dir[8]), u[1] = (pn_real)(a * dir[9]);
                if (!(pn__fem_obstacle_sd(c, 2, 0, shape ? u : NULL, p, nrm) > 0)) {
                    tru = a - 2.0 / 20000;
                    break;
                }
            }
            if (tru <= 1) hits++;
            if (amax > tru) late++;
            PN_CHECK(amax > 0 && amax <= 1);
        }
    PN_CHECK(hits > 1000);
    PN_CHECK(late == 0);
    t.m->n_obstacles = 0;
    t_fem_free(&t);
}

/* accepted Newton iterates lower the incremental potential within each minimization */
typedef struct t_fem_trace {
    int solve, rises, calls;
    double last;
} t_fem_trace;

static void t_fem_trace_fn(void *user, int solve, int it, pn_real E, pn_real res) {
    t_fem_trace *t = (t_fem_trace *)user;
    (void)res;
    if (it > 0 && solve == t->solve && E > t->last) t->rises++;
    t->solve = solve, t->last = E, t->calls++;
}

/* a block of metal dropped on the floor and pressed by a plate: every accepted Newton step
   lowers E, no node ever reaches an obstacle, the plate ends where it is driven */
PN_TEST(fem_line_search) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_fem_grid g = t_fem_grid(dim, 4, 4, 2, 0.04, 0.04, 0.02);
        pn_group grp = t_fem_group(PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_VON_MISES, 1e8, 1000);
        pn_fem_implicit_desc id;
        pn_collider c;
        t_fem_trace tr;
        t_fem t;
        int step;
        double dmin = 1;
        g.lo_m[1] = (pn_real)1e-3;
        if (!t_fem_make(&t, &g, &grp, -9.81)) {
            PN_CHECK(0);
            continue;
        }
        PN_CHECK(pn_fem_group_set_energy(t.m, 0, PN_ENERGY_EXACT_VM, NULL) == PN_OK);
        memset(&c, 0, sizeof c);
        c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1;
        PN_CHECK(pn_fem_add_obstacle(t.m, &c, NULL) == PN_OK);
        c.normal[1] = -1, c.center_m[1] = (pn_real)0.042, c.velocity_m_s[1] = (pn_real)-0.2;
        PN_CHECK(pn_fem_add_obstacle(t.m, &c, NULL) == PN_OK);
        memset(&tr, 0, sizeof tr);
        memset(&id, 0, sizeof id);
        id.trace = t_fem_trace_fn, id.trace_user = &tr;
        for (step = 0; step < 25; ++step) {
            pn_fem_stats st;
            tr.solve = -1;
            if (pn_fem_step_implicit(t.m, (pn_real)2e-3, &id, &st) != PN_OK) {
                fprintf(stderr, "  fem_line_search %dD step %d: %s\n", dim, step, pn_fem_error(t.m));
                PN_CHECK(0);
                break;
            }
            dmin = fmin(dmin, st.min_distance_m);
        }
        PN_CHECK(tr.calls > 25);
        PN_CHECK(tr.rises == 0);
        PN_CHECK(dmin > 0);
        { /* crushed: the top within dhat of the plate at 0.042 - 0.2 t (10 mm down) */
            size_t k;
            double top = 0;
            for (k = 0; k < t.nn; ++k) top = fmax(top, t.m->x[k * (size_t)dim + 1]);
            PN_CHECK(top < 0.042 - 0.2 * 0.05 && top > 0.042 - 0.2 * 0.05 - 2 * t.m->dhat);
        }
        t_fem_free(&t);
    }
}

/* Newton's last iterations: per minimization, the residual max |dx| / l is traced; from the
   last iterate that came below 1e-3 edge, a quadratically converging Newton reaches
   newton_tol (1e-5) in a few iterations. A slender elastic column (2D, crossed triangles,
   StVK-Hencky) held at its foot and driven down at its head, 3% of its height per step,
   buckles after 7 steps: its compressed elements have negative curvature (geometric
   stiffness), which a Hessian projected to PSD throughout drops, and Newton then converges
   linearly (27 iterations at worst, measured with the projection always on); with the whole
   Hessian near the minimum 6, at the straight column just past its critical load, a saddle
   where the whole Hessian is indefinite. Checked: at most 8. */
typedef struct t_fem_tail {
    int solve, first, worst, solves, last_it; /* first: where res last came below 1e-3 */
} t_fem_tail;

static void t_fem_tail_close(t_fem_tail *t) {
    if (t->solve >= 0 && t->first >= 0 && t->last_it - t->first > t->worst) t->worst = t->last_it - t->first;
}

static void t_fem_tail_fn(void *user, int solve, int it, pn_real E, pn_real res) {
    t_fem_tail *t = (t_fem_tail *)user;
    (void)E;
    if (solve != t->solve || it == 0) {
        t_fem_tail_close(t);
        t->solve = solve, t->first = -1, t->solves++;
    }
    if (res > 1e-3) t->first = -1;
    else if (t->first < 0) t->first = it;
    t->last_it = it;
}

PN_TEST(fem_newton_tail) {
    pn_fem_grid g = t_fem_grid(2, 3, 18, 1, 0.01, 0.06, 0.01);
    pn_group grp = t_fem_group(PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_NONE, 1e9, 7850);
    pn_fem_implicit_desc id;
    pn_real down[2] = {0, (pn_real)-0.9};
    int foot[16], head[16], nf = 0, nh = 0;
    t_fem_tail tr;
    t_fem t;
    size_t k;
    int step;
    g.crossed = 1;
    if (!t_fem_make(&t, &g, &grp, -9.81)) {
        PN_CHECK(0);
        return;
    }
    for (k = 0; k < t.nn; ++k) {
        if (t.m->X[2 * k + 1] < 1e-9 && nf < 16) foot[nf++] = (int)k;
        if (t.m->X[2 * k + 1] > 0.06 - 1e-9 && nh < 16) head[nh++] = (int)k;
    }
    PN_CHECK(nf == 4 && nh == 4);
    PN_CHECK(pn_fem_fix_nodes(t.m, (size_t)nf, foot, NULL) == PN_OK);
    PN_CHECK(pn_fem_fix_nodes(t.m, (size_t)nh, head, down) == PN_OK);
    memset(&tr, 0, sizeof tr);
    memset(&id, 0, sizeof id);
    tr.solve = -1, tr.first = -1;
    id.trace = t_fem_tail_fn, id.trace_user = &tr;
    for (step = 0; step < 10; ++step) {
        pn_fem_stats st;
        if (pn_fem_step_implicit(t.m, (pn_real)2e-3, &id, &st) != PN_OK) {
            fprintf(stderr, "  fem_newton_tail step %d: %s\n", step, pn_fem_error(t.m));
            PN_CHECK(0);
            break;
        }
        t_fem_tail_close(&tr);
        tr.solve = -1;
    }
    PN_REPORT("%d minimizations: at most %d Newton iterations from max |dx| <= 1e-3 l to the stop", tr.solves, tr.worst);
    PN_CHECK(tr.solves >= 10);
    PN_CHECK(tr.worst <= 8);
    t_fem_free(&t);
}

/* A static cantilever (plane strain, clamped at x = 0, its own weight): implicit steps of
   0.1 s settle it to the static solution (3 s, 5 periods). Euler-Bernoulli: tip deflection q L^4 / (8 E' I), E' =
   E / (1 - nu^2), q = rho g H. Linear triangles are stiff in bending (locking): the error
   is O(h^2), 13% at 4 elements through the depth, 4.1% at 8; so: below 6% at 8, and
   halving h cuts it by more than 2.5. Quadratic triangles: within 3% at 2 through the
   depth. */
static double t_fem_cantilever(int nx, int ny, int order) {
    pn_fem_grid g = t_fem_grid(2, nx, ny, 1, 1, 0.1, 1);
    pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e7, 1000);
    t_fem t;
    int fix[256], nf = 0;
    size_t k;
    double tip = 0;
    if (!t_fem_make_order(&t, &g, &grp, -9.81, order)) return 1e9;
    for (k = 0; k < t.nn; ++k)
        if (t.X[2 * k] == 0) fix[nf++] = (int)k;
    if (pn_fem_fix_nodes(t.m, (size_t)nf, fix, NULL) != PN_OK) return 1e9;
    for (k = 0; k < 30; ++k) /* backward Euler at dt 0.1 s damps the beam's 1.6 Hz bending 100x a step */
        if (pn_fem_step_implicit(t.m, (pn_real)0.1, NULL, NULL) != PN_OK) {
            fprintf(stderr, "  t_fem_cantilever: %s\n", pn_fem_error(t.m));
            t_fem_free(&t);
            return 1e9;
        }
    for (k = 0; k < t.nn; ++k) /* the mean deflection of the tip section */
        if (t.X[2 * k] == 1) tip += (t.m->x[2 * k + 1] - t.X[2 * k + 1]) / (order * ny + 1);
    t_fem_free(&t);
    return tip;
}

PN_TEST(fem_cantilever) {
    double E = 1e7, nu = 0.3, H = 0.1, eb = -(1000 * 9.81 * H) / (8 * (E / (1 - nu * nu)) * (H * H * H / 12));
    double e4 = fabs(t_fem_cantilever(40, 4, 1) / eb - 1), e8 = fabs(t_fem_cantilever(80, 8, 1) / eb - 1);
    double q2 = fabs(t_fem_cantilever(20, 2, 2) / eb - 1), q4 = fabs(t_fem_cantilever(40, 4, 2) / eb - 1);
    printf("    [fem_cantilever] tip deflection against Euler-Bernoulli: linear %.1f%% (4 elements deep), %.1f%% (8); "
           "quadratic %.1f%% (2), %.1f%% (4)\n", 100 * e4, 100 * e8, 100 * q2, 100 * q4);
    PN_CHECK_LE(e8, 0.06);
    PN_CHECK_LE(2.5 * e8, e4);
    PN_CHECK_LE(q2, 0.03);
    PN_CHECK_LE(q4, 0.03);
}

/* Quadratic elements (pn_fem_quadratic_mesh, pn_fem_desc.order 2): the node count (corners,
   then one per edge of the grid's triangulation, counted by hand: alternating diagonals in
   2D, Kuhn's one diagonal per face and per cube in 3D), the rest volume over the points, the
   HRZ masses (positive, summing to rho V), and exactness: positions quadratic in X give every
   integration point F = dx/dX there, to rounding (quadratic elements reproduce quadratic
   fields); the points' positions from the degree-2 rules' barycentric coordinates. */
PN_TEST(fem_quadratic_mesh) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_fem_grid g = t_fem_grid(dim, 3, 2, 2, 0.3, 0.2, 0.2);
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
        size_t corners = dim == 2 ? 4 * 3 : 4 * 3 * 3, edges, k, p;
        double vol = 0, mass = 0, mmin = 1e9, ferr = 0, box = dim == 2 ? 0.06 : 0.012;
        t_fem t;
        int i, j, nq = dim + 1;
        edges = dim == 2 ? 3 * 3 + 4 * 2 + 3 * 2 /* horizontal, vertical, diagonal */
                         : (3 * 3 * 3 + 4 * 2 * 3 + 4 * 3 * 2) + (3 * 2 * 3 + 3 * 3 * 2 + 4 * 2 * 2) + 3 * 2 * 2;
        if (!t_fem_make_order(&t, &g, &grp, 0, 2)) {
            PN_CHECK(0);
            continue;
        }
        PN_CHECK(t.nn == corners + edges);
        PN_CHECK(t.m->order == 2 && t.m->nodes_per_element == (dim == 2 ? 6 : 10) && t.m->points_per_element == nq);
        PN_CHECK(t.m->n_points == t.ne * (size_t)nq);
        for (p = 0; p < t.m->n_points; ++p) vol += t.m->vol0[p];
        for (k = 0; k < t.nn; ++k) mass += t.m->mass[k], mmin = fmin(mmin, t.m->mass[k]);
        PN_CHECK_NEAR(vol, box, 1e-12);
        PN_CHECK_NEAR(mass, 1000 * box, 1e-9);
        PN_CHECK(mmin > 0);
        for (k = 0; k < t.nn; ++k) { /* x = X + u(X), u quadratic */
            const pn_real *X = t.X + k * (size_t)dim;
            pn_real *x = t.m->x + k * (size_t)dim;
            double z = dim == 3 ? X[2] : 0;
            x[0] = X[0] + (pn_real)(0.3 * X[0] * X[1] + 0.2 * z * z);
            x[1] = X[1] + (pn_real)(0.1 * X[0] * X[0] - 0.25 * X[1] * z + 0.05 * X[1] * X[1]);
            if (dim == 3) x[2] = X[2] + (pn_real)(0.15 * X[0] * X[2] + 0.05 * X[1] * X[1]);
        }
        for (p = 0; p < t.m->n_points; ++p) {
            const int *el = t.el + (p / (size_t)nq) * (size_t)t.m->nodes_per_element;
            double Xq[3] = {0, 0, 0}, Fa[9], lam;
            pn_real J[9], F[9];
            int q = (int)(p % (size_t)nq);
            for (i = 0; i <= dim; ++i) { /* the point: barycentric (2/3, 1/6, 1/6) or (a, b, b, b) */
                lam = dim == 2 ? (i == q ? 2.0 / 3 : 1.0 / 6) : (i == q ? (5 + 3 * sqrt(5.0)) / 20 : (5 - sqrt(5.0)) / 20);
                for (j = 0; j < dim; ++j) Xq[j] += lam * t.X[(size_t)el[i] * (size_t)dim + (size_t)j];
            }
            for (i = 0; i < 9; ++i) Fa[i] = 0;
            Fa[0] = 1 + 0.3 * Xq[1], Fa[1] = 0.3 * Xq[0];
            Fa[dim + 0] = 0.2 * Xq[0], Fa[dim + 1] = 1 - 0.25 * Xq[2] + 0.1 * Xq[1];
            if (dim == 3) {
                Fa[2] = 0.4 * Xq[2], Fa[5] = -0.25 * Xq[1];
                Fa[6] = 0.15 * Xq[2], Fa[7] = 0.1 * Xq[1], Fa[8] = 1 + 0.15 * Xq[0];
            }
            pn__fem_jac(t.m, p, t.m->x, J);
            pn_mat_mul(dim, J, t.m->Dm_inv + p * (size_t)(dim * dim), F);
            for (i = 0; i < dim * dim; ++i) ferr = fmax(ferr, fabs(F[i] - Fa[i]));
        }
        PN_REPORT("%dD: %lu nodes, volume and mass exact, F of a quadratic field off by %.1e", dim, (unsigned long)t.nn, ferr);
        PN_CHECK_LE(ferr, 1e-13);
        t_fem_free(&t);
    }
    { /* bad input: an index out of range; a mid-edge node placed past its edge's far corner */
        pn_real X[8] = {0, 0, 1, 0, 0, 1, 1, 1};
        int el[3] = {0, 1, 4}, el2[6];
        size_t n2 = 0;
        PN_CHECK(pn_fem_quadratic_mesh(2, X, 4, el, 1, NULL, NULL, NULL, &n2) == PN_ERROR_INVALID_ARGUMENT);
        el[2] = 2;
        PN_CHECK(pn_fem_quadratic_mesh(2, X, 4, el, 1, NULL, NULL, NULL, &n2) == PN_OK && n2 == 7);
        {
            pn_real X2[14];
            pn_fem_desc fd;
            pn_fem_mesh *m = NULL;
            pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
            char why[256];
            PN_CHECK(pn_fem_quadratic_mesh(2, X, 4, el, 1, NULL, X2, el2, &n2) == PN_OK);
            X2[2 * el2[3]] = (pn_real)1.3; /* edge 0-1's node beyond corner 1 */
            memset(&fd, 0, sizeof fd);
            fd.dim = 2, fd.n_nodes = n2, fd.n_elements = 1, fd.rest_m = X2, fd.elements = el2, fd.order = 2;
            fd.groups = &grp, fd.n_groups = 1;
            PN_CHECK(pn_fem_create(&fd, &m, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && m == NULL);
            PN_CHECK(strstr(why, "element 0") != NULL && strstr(why, "Jacobian") != NULL);
            fd.order = 3;
            PN_CHECK(pn_fem_create(&fd, &m, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && strstr(why, "order") != NULL);
        }
    }
}

/* A 3D cantilever, 1 x 0.1 x 0.1 m, clamped at x = 0, under its own weight (E 1e9 Pa, nu 0.3,
   1000 kg/m^3: the tip moves 1.5 mm, linear theory holds), settled by one implicit step of
   10 s (backward Euler: the step leaves 1e-6 of the static deflection to go), against
   Timoshenko's tip deflection q L^4 / (8 E I) + q L^2 / (2 k G A), k = 10 (1 + nu) / (12 +
   11 nu) for a rectangle. Linear tetrahedra lock in bending: far short with 2 or 4 through
   the depth. Quadratic ones: within 5% at 4 through the depth (and at 2). */
static double t_fem_cantilever_3d(int nx, int nyz, int order) {
    pn_fem_grid g = t_fem_grid(3, nx, nyz, nyz, 1, 0.1, 0.1);
    pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e9, 1000);
    t_fem t;
    int *fix;
    size_t k, nf = 0, nt = 0;
    double tip = 0;
    if (!t_fem_make_order(&t, &g, &grp, -9.81, order)) return 1e9;
    fix = (int *)malloc(sizeof(int) * t.nn);
    for (k = 0; k < t.nn; ++k)
        if (t.X[3 * k] == 0) fix[nf++] = (int)k;
    if (!fix || pn_fem_fix_nodes(t.m, nf, fix, NULL) != PN_OK || pn_fem_step_implicit(t.m, (pn_real)10, NULL, NULL) != PN_OK) {
        fprintf(stderr, "  t_fem_cantilever_3d: %s\n", pn_fem_error(t.m));
        tip = 1e9;
    } else
        for (k = 0; k < t.nn; ++k) /* the mean deflection of the tip section's nodes */
            if (t.X[3 * k] == 1) tip += t.m->x[3 * k + 1] - t.X[3 * k + 1], nt++;
    free(fix);
    t_fem_free(&t);
    return tip == 1e9 ? tip : tip / (double)nt;
}

PN_TEST(fem_cantilever_3d) {
    double E = 1e9, nu = 0.3, H = 0.1, A = H * H, I = H * H * H * H / 12, q = 1000 * 9.81 * A, G = E / (2 * (1 + nu));
    double kap = 10 * (1 + nu) / (12 + 11 * nu), tim = -(q / (8 * E * I) + q / (2 * kap * G * A));
    double l2 = t_fem_cantilever_3d(20, 2, 1) / tim, l4 = t_fem_cantilever_3d(20, 4, 1) / tim;
    double q2 = t_fem_cantilever_3d(10, 2, 2) / tim, q4 = t_fem_cantilever_3d(10, 4, 2) / tim;
    PN_REPORT("tip deflection over Timoshenko's: linear tetrahedra %.3f (2 through the depth), %.3f (4); quadratic %.3f (2), "
              "%.3f (4)", l2, l4, q2, q4);
    PN_CHECK_LE(fabs(q4 - 1), 0.05);
    PN_CHECK_LE(fabs(q2 - 1), 0.05);
    PN_CHECK(l2 < l4 && l4 < 0.9); /* the locking the quadratic elements remove */
}

/* explicit and implicit agree at a small step: an elastic block dropped on the floor (2D; 3D
   too with PN_TEST_FULL=1: make test-all, CI) */
PN_TEST(fem_explicit_implicit) {
    int dim, order;
    for (dim = 2; dim <= (pn_test_full() ? 3 : 2); ++dim)
        for (order = 1; order <= (pn_test_full() ? 2 : 1); ++order) { /* quadratic: make test-all */
        pn_fem_grid g = t_fem_grid(dim, 3, 3, 3, 0.03, 0.03, 0.03);
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e5, 1000);
        t_fem a, b;
        pn_collider c;
        pn_real sdt = 0;
        double T = 0.06, dt_e, err = 0, t_now;
        long k, nimp = dim == 3 && order == 2 ? 4000 : 12000; /* 3D quadratic: 5 of its 6 CPU minutes were these */
        g.lo_m[1] = (pn_real)0.01;
        if (!t_fem_make_order(&a, &g, &grp, -9.81, order) || !t_fem_make_order(&b, &g, &grp, -9.81, order)) {
            PN_CHECK(0);
            continue;
        }
        memset(&c, 0, sizeof c);
        c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1;
        PN_CHECK(pn_fem_add_obstacle(a.m, &c, NULL) == PN_OK && pn_fem_add_obstacle(b.m, &c, NULL) == PN_OK);
        for (t_now = 0, k = 0; t_now < T - 1e-12 && k < 10000000; ++k) { /* at half the bound of each step */
            PN_CHECK(pn_fem_stable_dt(a.m, &sdt) == PN_OK && sdt > 0);
            dt_e = fmin(0.5 * sdt, T - t_now);
            if (pn_fem_step_explicit(a.m, (pn_real)dt_e, NULL) != PN_OK) {
                fprintf(stderr, "  explicit step %ld: %s\n", k, pn_fem_error(a.m));
                PN_CHECK(0);
                break;
            }
            t_now += dt_e;
        }
        for (k = 0; k < nimp; ++k) /* backward Euler damps by (omega dt)^2 / 2 a step: the barrier's
                                       spring, omega ~ 2e4 / s, needs dt ~ 1e-6 */
            if (pn_fem_step_implicit(b.m, (pn_real)(T / nimp), NULL, NULL) != PN_OK) {
                fprintf(stderr, "  implicit step %ld: %s\n", k, pn_fem_error(b.m));
                PN_CHECK(0);
                break;
            }
        for (k = 0; k < (long)(a.nn * (size_t)dim); ++k) err = fmax(err, fabs(a.m->x[k] - b.m->x[k]));
        PN_CHECK(a.m->x[1] < 0.004); /* it fell onto the floor (at 0.045 s) and bounced */
        PN_CHECK(a.m->x[1] > 0);
        PN_CHECK_LE(err, 0.03 * 0.03 * sqrt((double)dim)); /* 3% of the block's diagonal */
        PN_REPORT("%dD, %s elements: explicit and implicit %.1e m apart (bar 3%% of the diagonal, %.1e)", dim,
                  order == 2 ? "quadratic" : "linear", err, 0.03 * 0.03 * sqrt((double)dim));
        t_fem_free(&a);
        t_fem_free(&b);
    }
}

/* PN_FEM_LINEAR_PCG against PN_FEM_LINEAR_CHOLESKY: a von Mises block in 2D and 3D dropped on
   a rough floor and pressed by a rough plate moving down (the plate's offset an unknown whose
   row couples to every node), 12 steps of 5 ms: 6 mm, a fifth of its height, past yield. Both minimize the same
   potential to newton_tol: the final nodes agree to a small fraction of an edge. A bad
   linear_solver is refused with the mesh unchanged; stats say which solver ran, and the
   default switches to PCG where the factor would cost more than PN_FEM_CHOLESKY_MAX_GFLOP_*. */
PN_TEST(fem_pcg) {
    int dim, order;
    for (dim = 2; dim <= 3; ++dim)
        for (order = 1; order <= (dim == 2 || pn_test_full() ? 2 : 1); ++order) { /* quadratic: as many nodes on half
                                                                                     the cells (3D: make test-all) */
        pn_fem_grid g = order == 2 ? t_fem_grid(dim, 3, 3, 2, 0.03, 0.03, 0.018) : t_fem_grid(dim, 5, 5, 3, 0.03, 0.03, 0.018);
        pn_group grp = t_fem_group(PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_VON_MISES, 1e8, 1000);
        t_fem a[2];
        pn_collider c;
        pn_fem_implicit_desc id;
        pn_fem_stats st;
        double apart = 0, plastic = 0;
        int s, step, ok = 1;
        size_t k;
        g.lo_m[1] = (pn_real)1e-4;
        for (s = 0; s < 2; ++s) {
            if (!t_fem_make_order(&a[s], &g, &grp, -9.81, order)) {
                PN_CHECK(0);
                return;
            }
            PN_CHECK(pn_fem_group_set_energy(a[s].m, 0, PN_ENERGY_EXACT_VM, NULL) == PN_OK);
            memset(&c, 0, sizeof c);
            c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1, c.friction = (pn_real)0.3;
            PN_CHECK(pn_fem_add_obstacle(a[s].m, &c, NULL) == PN_OK);
            c.normal[1] = -1, c.center_m[1] = (pn_real)(0.03 + 3e-4), c.velocity_m_s[1] = (pn_real)-0.1;
            PN_CHECK(pn_fem_add_obstacle(a[s].m, &c, NULL) == PN_OK);
        }
        memset(&id, 0, sizeof id);
        id.linear_solver = (pn_fem_linear_solver)7; /* refused, nothing moves */
        PN_CHECK(pn_fem_step_implicit(a[1].m, (pn_real)5e-3, &id, &st) == PN_ERROR_INVALID_ARGUMENT);
        PN_CHECK(strstr(pn_fem_error(a[1].m), "linear_solver") != NULL);
        PN_CHECK(a[1].m->time_s == 0 && !memcmp(a[1].m->x, a[1].X, sizeof(pn_real) * a[1].nn * (size_t)dim));
        for (step = 0; step < 12 && ok; ++step)
            for (s = 0; s < 2; ++s) {
                id.linear_solver = s ? PN_FEM_LINEAR_PCG : PN_FEM_LINEAR_DEFAULT;
                if (pn_fem_step_implicit(a[s].m, (pn_real)5e-3, &id, &st) != PN_OK) {
                    fprintf(stderr, "  fem_pcg %dD %s, step %d: %s\n", dim, s ? "PCG" : "Cholesky", step, pn_fem_error(a[s].m));
                    ok = 0;
                    break;
                }
                PN_CHECK(st.linear_solver == (s ? PN_FEM_LINEAR_PCG : PN_FEM_LINEAR_CHOLESKY)); /* small: the default factors */
                PN_CHECK(s ? st.cg_iters > 0 : 1);
            }
        PN_CHECK(ok);
        for (k = 0; k < a[0].nn; ++k) {
            double d2 = 0;
            int i;
            for (i = 0; i < dim; ++i) d2 += pow(a[0].m->x[k * (size_t)dim + (size_t)i] - a[1].m->x[k * (size_t)dim + (size_t)i], 2);
            apart = fmax(apart, sqrt(d2) / a[0].m->edge_mean);
        }
        for (k = 0; k < a[0].m->n_points; ++k) plastic = fmax(plastic, a[0].m->h[k]);
        printf("    [fem_pcg] %dD %s: after 12 steps PCG and Cholesky %.2g of an edge apart; plate %.1f mm down, max plastic "
               "state %.3f\n", dim, order == 2 ? "quadratic" : "linear", apart, 12 * 5e-3 * 0.1 * 1e3, plastic);
        PN_CHECK(plastic > 0.01);          /* crushed past yield */
        PN_CHECK_LE(apart, 1e-2);          /* newton_tol 1e-5 of an edge per step, a 100x margin */
        { /* the default: Cholesky unless its factor would be too costly (here: made to look so) */
            pn__fem *sv = (pn__fem *)a[0].m->impl;
            double keep = sv->sky_gflop;
            id.linear_solver = PN_FEM_LINEAR_DEFAULT;
            sv->sky_gflop = 2.0 * (dim == 2 ? PN_FEM_CHOLESKY_MAX_GFLOP_2D : PN_FEM_CHOLESKY_MAX_GFLOP_3D);
            PN_CHECK(pn_fem_step_implicit(a[0].m, (pn_real)5e-3, &id, &st) == PN_OK && st.linear_solver == PN_FEM_LINEAR_PCG);
            sv->sky_gflop = keep;
            PN_CHECK(pn_fem_step_implicit(a[0].m, (pn_real)5e-3, &id, &st) == PN_OK && st.linear_solver == PN_FEM_LINEAR_CHOLESKY);
        }
        t_fem_free(&a[0]);
        t_fem_free(&a[1]);
    }
}

/* Coulomb friction: a block sliding on the floor at v0 stops after v0^2 / (2 mu g), explicit
   and implicit within 3% (the smoothing lets it creep at most friction_velocity_m_s, 1e-3
   m/s; the block is elastic, so only nearly rigid) */
PN_TEST(fem_friction_slide) {
    int implicit;
    for (implicit = 0; implicit < 2; ++implicit) {
        pn_fem_grid g = t_fem_grid(2, 8, 4, 1, 0.1, 0.05, 1);
        /* explicit: stiff, so that the block's elastic ringing (undamped) barely lifts the
           nodes off the barrier's reach, where they would lose their friction (at 1e7 Pa
           it slides 9% too far) */
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, implicit ? 1e7 : 1e9, 1000);
        pn_collider c;
        t_fem t;
        size_t k;
        double t_now = 0, T = 0.3, x0 = 0, x1 = 0, mu = 0.5, v0 = 1, expect = v0 * v0 / (2 * mu * 9.81);
        g.lo_m[1] = (pn_real)1e-5;
        if (!t_fem_make(&t, &g, &grp, -9.81)) {
            PN_CHECK(0);
            continue;
        }
        memset(&c, 0, sizeof c);
        c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1, c.friction = (pn_real)mu;
        PN_CHECK(pn_fem_add_obstacle(t.m, &c, NULL) == PN_OK);
        /* settle on the floor first (at rest), then slide */
        for (k = 0; k < 50; ++k) PN_CHECK(pn_fem_step_implicit(t.m, (pn_real)1e-3, NULL, NULL) == PN_OK);
        for (k = 0; k < t.nn; ++k) t.m->v[2 * k] = (pn_real)v0, t.m->v[2 * k + 1] = 0, x0 += t.m->x[2 * k] / (double)t.nn;
        while (t_now < T - 1e-12) {
            pn_real sdt = 0;
            double dt = 1e-3;
            if (!implicit) {
                PN_CHECK(pn_fem_stable_dt(t.m, &sdt) == PN_OK);
                dt = fmin(0.5 * sdt, T - t_now);
            }
            if ((implicit ? pn_fem_step_implicit(t.m, (pn_real)dt, NULL, NULL) : pn_fem_step_explicit(t.m, (pn_real)dt, NULL)) != PN_OK) {
                fprintf(stderr, "  fem_friction_slide: %s\n", pn_fem_error(t.m));
                PN_CHECK(0);
                break;
            }
            t_now += dt;
        }
        for (k = 0; k < t.nn; ++k) x1 += t.m->x[2 * k] / (double)t.nn;
        printf("    [fem_friction_slide] %s: slid %.4f m, Coulomb %.4f m\n", implicit ? "implicit dt 1e-3" : "explicit",
               x1 - x0, expect);
        PN_CHECK_NEAR(x1 - x0, expect, 0.03 * expect);
        t_fem_free(&t);
    }
}

/* squared distance between points of two simplices, by sampling both on a lattice of step
   1/n in barycentric coordinates (the test's own closest points: no feature logic) */
static double t_pair_sampled(int kind, int d, const pn_real *y, int n) {
    int na = kind == PN__FEM_EE ? 2 : 1, nb = kind == PN__FEM_PT ? 3 : 2, i, j, k, l, c;
    double best = 1e300;
    for (i = 0; i <= (na == 2 ? n : 0); ++i)
        for (j = 0; j <= n; ++j)
            for (k = 0; k <= (nb == 3 ? n - j : 0); ++k) {
                double p[3] = {0, 0, 0}, q[3] = {0, 0, 0}, s = (double)i / n, u = (double)j / n, v = (double)k / n, r2 = 0;
                for (c = 0; c < d; ++c) {
                    p[c] = na == 1 ? y[c] : (1 - s) * y[c] + s * y[d + c];
                    l = na * d;
                    q[c] = nb == 2 ? (1 - u) * y[l + c] + u * y[l + d + c] : (1 - u - v) * y[l + c] + u * y[l + d + c] + v * y[l + 2 * d + c];
                    r2 += (p[c] - q[c]) * (p[c] - q[c]);
                }
                if (r2 < best) best = r2;
            }
    return best;
}

/* the squared distance between boundary primitives (2D point-edge, 3D point-triangle and
   edge-edge): the value against sampling both primitives, its gradient and Hessian against
   central differences; random pairs whose closest points fall on vertices, edges and faces
   (told apart by the distances to the vertices) */
PN_TEST(fem_pair_distance_fd) {
    static const int kinds[3] = {PN__FEM_PE, PN__FEM_PT, PN__FEM_EE}, dims[3] = {2, 3, 3};
    unsigned long seed = 4242;
    int kk;
    for (kk = 0; kk < 3; ++kk) {
        int kind = kinds[kk], d = dims[kk], nv = kind == PN__FEM_PE ? 3 : 4, n = nv * d, trial, at_vertex = 0, inside = 0;
        double gerr = 0, herr = 0, verr = 0, over = 0;
        for (trial = 0; trial < 400; ++trial) {
            pn_real x[12], g[12], H[144], gp[12], gm[12], g1[12], Ht[144], sq;
            double vmin = 1e300, smp;
            int i, j, kink = 0;
            for (i = 0; i < n; ++i) {
                seed = seed * 6364136223846793005UL + 1442695040888963407UL;
                x[i] = (pn_real)((double)(seed >> 11) / 9007199254740992.0 - 0.5);
            }
            sq = pn__fem_pair_d2(kind, d, x, g, H);
            smp = t_pair_sampled(kind, d, x, 200);
            { /* sampling finds points as far or farther, by at most the lattice's reach */
                double reach = 0;
                for (i = 1; i < nv; ++i) {
                    double r2 = 0;
                    int c;
                    for (c = 0; c < d; ++c) r2 += (x[i * d + c] - x[(i - 1) * d + c]) * (x[i * d + c] - x[(i - 1) * d + c]);
                    reach += 2 * sqrt(r2) / 200;
                }
                over = fmax(over, sq - smp);
                verr = fmax(verr, (sqrt(smp) - sqrt(sq)) / reach);
            }
            for (i = 0; i < nv; ++i) /* the pair's vertex-vertex distances: a vertex case is one of them */
                for (j = 0; j < nv; ++j) {
                    int side_i = i < (kind == PN__FEM_EE ? 2 : 1), side_j = j < (kind == PN__FEM_EE ? 2 : 1), c;
                    double r2 = 0;
                    if (side_i == side_j) continue;
                    for (c = 0; c < d; ++c) r2 += (x[i * d + c] - x[j * d + c]) * (x[i * d + c] - x[j * d + c]);
                    vmin = fmin(vmin, r2);
                }
            for (i = 0; i < n; ++i) {
                pn_real keep = x[i], h = (pn_real)1e-6;
                x[i] = keep + h, (void)pn__fem_pair_d2(kind, d, x, gp, Ht);
                x[i] = keep - h, (void)pn__fem_pair_d2(kind, d, x, gm, Ht);
                x[i] = keep;
                for (j = 0; j < n; ++j) /* the one-sided differences disagree only across a kink */
                    if (fabs(gp[j] - g[j] - (g[j] - gm[j])) > 1e-3 * h * (fabs(H[j * n + i]) + 1)) kink = 1;
            }
            if (kink) continue;
            at_vertex += fabs(sq - vmin) < 1e-12, inside += fabs(sq - vmin) >= 1e-12;
            for (i = 0; i < n; ++i) {
                pn_real keep = x[i], h = (pn_real)1e-6, sp, sm;
                x[i] = keep + h, sp = pn__fem_pair_d2(kind, d, x, gp, Ht);
                x[i] = keep - h, sm = pn__fem_pair_d2(kind, d, x, gm, Ht);
                x[i] = keep;
                gerr = fmax(gerr, fabs((sp - sm) / (2 * h) - g[i]) / (fabs(g[i]) + 1e-3));
                for (j = 0; j < n; ++j) herr = fmax(herr, fabs((gp[j] - gm[j]) / (2 * h) - H[j * n + i]) / (fabs(H[j * n + i]) + 1e-2));
            }
            (void)g1;
        }
        printf("    [fem_pair_distance_fd] %s: over sampling %.2g, under it %.2g of the lattice's reach, gradient %.2g, Hessian %.2g; %d at vertices, %d on edges or faces\n",
               kind == PN__FEM_PE ? "point-edge" : kind == PN__FEM_PT ? "point-triangle" : "edge-edge", over, verr, gerr, herr, at_vertex, inside);
        PN_CHECK(at_vertex > 20 && inside > 20);
        PN_CHECK_LE(over, 1e-12);
        PN_CHECK_LE(verr, 1);
        PN_CHECK_LE(gerr, 1e-6);
        PN_CHECK_LE(herr, 1e-5);
    }
}

/* The pair barrier and the pair CCD shared by self-contact and the MPM-FEM interface (a
   particle against a boundary edge in 2D, a boundary triangle in 3D: point-edge and
   point-triangle pairs).
   (a) pn__pair_barrier: the gradient against central differences of its energy, the exact
       Hessian against the central differences of the gradient and the projected one against
       their nearest PSD matrix, on random pairs within dhat (away from the kinks where the
       closest feature switches).
   (b) pn__pair_ccd: a point and a primitive moving linearly, heading through it or grazing
       it (passing at 1e-9 of the primitive's size): the step it returns is never later than
       the first crossing found by sampling the path 20,000 times, and the pair is apart
       there. */
static double t_pair_side(int d, const pn_real *y) { /* signed side of the point against the primitive's line or plane */
    double a[3], b[3], w[3], nrm[3];
    int i;
    if (d == 2) return (y[4] - y[2]) * (y[1] - y[3]) - (y[5] - y[3]) * (y[0] - y[2]);
    for (i = 0; i < 3; ++i) w[i] = y[i] - y[3 + i];
    for (i = 0; i < 3; ++i) a[i] = y[6 + i] - y[3 + i], b[i] = y[9 + i] - y[3 + i];
    nrm[0] = a[1] * b[2] - a[2] * b[1], nrm[1] = a[2] * b[0] - a[0] * b[2], nrm[2] = a[0] * b[1] - a[1] * b[0];
    return nrm[0] * w[0] + nrm[1] * w[1] + nrm[2] * w[2];
}

static int t_pair_over(int d, const pn_real *y) { /* does the point project inside the primitive? */
    if (d == 2) {
        double e0 = y[4] - y[2], e1 = y[5] - y[3], t = ((y[0] - y[2]) * e0 + (y[1] - y[3]) * e1) / (e0 * e0 + e1 * e1);
        return t > 0 && t < 1;
    }
    {
        double e0[3], e1[3], w[3], A00 = 0, A01 = 0, A11 = 0, b0 = 0, b1 = 0, det, u, v;
        int i;
        for (i = 0; i < 3; ++i) e0[i] = y[6 + i] - y[3 + i], e1[i] = y[9 + i] - y[3 + i], w[i] = y[i] - y[3 + i];
        for (i = 0; i < 3; ++i) A00 += e0[i] * e0[i], A01 += e0[i] * e1[i], A11 += e1[i] * e1[i], b0 += w[i] * e0[i], b1 += w[i] * e1[i];
        det = A00 * A11 - A01 * A01;
        u = (A11 * b0 - A01 * b1) / det, v = (A00 * b1 - A01 * b0) / det;
        return u > 0 && v > 0 && u + v < 1;
    }
}

PN_TEST(fem_pair_barrier_ccd) {
    unsigned long seed = 777;
    int d;
#define T_RND() (seed = seed * 6364136223846793005UL + 1442695040888963407UL, (double)(seed >> 11) / 9007199254740992.0 - 0.5)
    for (d = 2; d <= 3; ++d) {
        const int kind = d == 2 ? PN__FEM_PE : PN__FEM_PT, nv = d + 1, n = nv * d;
        const pn_real dhat = (pn_real)1e-2;
        double gerr = 0, herr = 0, xerr = 0, ratio = 0;
        int trial, tested = 0, late = 0, touched = 0, crossings = 0, grazes = 0;
        for (trial = 0; trial < 600; ++trial) { /* (a) */
            pn_real y[12], g[12], H[144], Hx[144], gp[12], gm[12], Hfd[144], Hs[144], Ht[144], E, Ep, Em, dist,
                w = (pn_real)3.7;
            int i, j, kink = 0;
            for (i = d; i < n; ++i) y[i] = (pn_real)(0.05 * T_RND());
            for (i = 0; i < d; ++i) { /* the point near the primitive's centroid, lifted within dhat of its plane */
                double cen = 0;
                for (j = 1; j < nv; ++j) cen += y[j * d + i] / (nv - 1);
                y[i] = (pn_real)(cen + 0.02 * T_RND());
            }
            if (!pn__pair_barrier(kind, d, nv, y, dhat, w, 2, &E, g, H, &dist, 1) || dist >= dhat) continue;
            (void)pn__pair_barrier(kind, d, nv, y, dhat, w, 2, &E, g, Hx, &dist, 0);
            for (i = 0; i < n; ++i) {
                pn_real keep = y[i], h = (pn_real)1e-4 * PN__MIN(dist, dhat - dist), dd; /* b's scales: d, dhat - d */
                y[i] = keep + h, (void)pn__pair_barrier(kind, d, nv, y, dhat, w, 1, &Ep, gp, Ht, &dd, 0);
                y[i] = keep - h, (void)pn__pair_barrier(kind, d, nv, y, dhat, w, 1, &Em, gm, Ht, &dd, 0);
                y[i] = keep;
                for (j = 0; j < n; ++j) /* the one-sided differences disagree only across a kink */
                    if (fabs(gp[j] - g[j] - (g[j] - gm[j])) > 1e-2 * (fabs(gp[j] - gm[j]) + 1e-9 * fabs(g[j]) + 1e-12)) kink = 1;
                for (j = 0; j < n; ++j) Hfd[j * n + i] = (gp[j] - gm[j]) / (2 * h);
                Hs[i] = (Ep - Em) / (2 * h); /* the gradient's differences, kept in Hs for a moment */
            }
            if (kink) continue;
            ++tested;
            {
                double gmax = 0, hmax = 0;
                for (i = 0; i < n; ++i) gmax = fmax(gmax, fabs(g[i]));
                for (i = 0; i < n; ++i) gerr = fmax(gerr, fabs(Hs[i] - g[i]) / gmax);
                for (i = 0; i < n; ++i)
                    for (j = 0; j < n; ++j) Ht[i * n + j] = (Hfd[i * n + j] + Hfd[j * n + i]) / 2;
                for (i = 0; i < n * n; ++i) hmax = fmax(hmax, fabs(Ht[i]));
                for (i = 0; i < n * n; ++i) xerr = fmax(xerr, fabs(Ht[i] - Hx[i]) / hmax);
                hmax = 0;
                pn_sym_project_psd(n, Ht);
                for (i = 0; i < n * n; ++i) hmax = fmax(hmax, fabs(Ht[i]));
                for (i = 0; i < n * n; ++i) herr = fmax(herr, fabs(Ht[i] - H[i]) / hmax);
            }
        }
        for (trial = 0; trial < 4000; ++trial) { /* (b) */
            pn_real y[12], dy[12], yt[12], t;
            double tc = 2, s0;
            int i, j, graze = trial & 1;
            for (i = d; i < n; ++i) y[i] = (pn_real)(0.05 * T_RND()), dy[i] = (pn_real)(0.01 * T_RND());
            for (i = 0; i < d; ++i) {
                double cen = 0, end = 0;
                for (j = 1; j < nv; ++j) cen += y[j * d + i] / (nv - 1), end += (y[j * d + i] + dy[j * d + i]) / (nv - 1);
                y[i] = (pn_real)(cen + 0.05 * T_RND());
                /* heading through the primitive's moved centroid, or (grazing) past its first
                   node at 1e-9 of its size, offset along a random direction */
                dy[i] = (pn_real)((graze ? y[d + i] + dy[d + i] + 1e-9 * 0.05 * T_RND() : end + 0.01 * T_RND()) - y[i]);
            }
            s0 = t_pair_side(d, y);
            {
                pn_real E0, g0[12], H0[144], d0;
                if (!pn__pair_barrier(kind, d, nv, y, dhat, 1, 0, &E0, g0, H0, &d0, 0) || d0 < 1e-6) continue;
            }
            for (i = 1; i <= 20000; ++i) { /* the first crossing of the primitive's interior, over [0, 2]: */
                double lo = 2.0 * (i - 1) / 20000, hi = 2.0 * i / 20000, sl; /* a root of the side (a polynomial */
                int k, it;                                                 /* in time), the point over it there */
                for (k = 0; k < n; ++k) yt[k] = (pn_real)(y[k] + lo * dy[k]);
                sl = t_pair_side(d, yt);
                for (k = 0; k < n; ++k) yt[k] = (pn_real)(y[k] + hi * dy[k]);
                if (sl * t_pair_side(d, yt) > 0) continue;
                for (it = 0; it < 60; ++it) {
                    double mid = (lo + hi) / 2;
                    for (k = 0; k < n; ++k) yt[k] = (pn_real)(y[k] + mid * dy[k]);
                    if (t_pair_side(d, yt) * sl > 0) lo = mid;
                    else hi = mid;
                }
                if (t_pair_over(d, yt)) {
                    tc = lo;
                    break;
                }
            }
            (void)s0;
            t = pn__pair_ccd(kind, d, nv, 1, y, dy, 0, 1);
            for (j = 0; j < n; ++j) yt[j] = y[j] + t * dy[j];
            {
                pn_real E1, g1[12], H1[144], d1;
                touched += !pn__pair_barrier(kind, d, nv, yt, dhat, 1, 0, &E1, g1, H1, &d1, 0);
            }
            if (tc <= 1) crossings++, ratio += t / tc;
            grazes += graze;
            if (t > tc) late++;
            PN_CHECK(t > 0 && t <= 1);
        }
        PN_REPORT("%s: barrier gradient %.2e, exact Hessian %.2e against central differences, projected %.2e against "
                  "their PSD part (%d pairs within dhat); CCD: %d crossings (mean step / crossing time %.2f), %d grazing "
                  "paths, %d late, %d touching",
                  d == 2 ? "point-edge" : "point-triangle", gerr, xerr, herr, tested, crossings,
                  crossings ? ratio / crossings : 0, grazes, late, touched);
        PN_CHECK(tested > 100);
        PN_CHECK_LE(gerr, 1e-5);
        PN_CHECK_LE(xerr, 1e-4);
        PN_CHECK_LE(herr, 1e-4);
        PN_CHECK(crossings > 500);
        PN_CHECK(late == 0);
        PN_CHECK(touched == 0);
    }
#undef T_RND
}

/* Self-contact: two elastic blocks of one mesh, one thrown at the other (no gravity). No
   boundary node ever reaches an edge of the other block (smallest distance > 0 at every
   step, and no node inside a triangle of the other block), momentum is kept (the
   barrier's forces are internal), and they part with the thrown one slower than the hit
   one. Implicit at 1e-3 s and explicit. */
PN_TEST(fem_self_contact) {
    int implicit;
    for (implicit = 0; implicit < 2; ++implicit) {
        pn_fem_grid g = t_fem_grid(2, 4, 4, 1, 0.04, 0.04, 1);
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e5, 1000);
        pn_fem_desc fd;
        pn_fem_mesh *m = NULL;
        size_t nn, ne, k, half;
        pn_real *X;
        int *el, step;
        char why[256];
        double p0 = 0, p1 = 0, dmin = 1, t = 0, T = 0.2, overlap = 0;
        pn_fem_grid_mesh(&g, NULL, NULL, &nn, &ne);
        X = (pn_real *)malloc(sizeof(pn_real) * 4 * nn);
        el = (int *)malloc(sizeof(int) * 6 * ne);
        pn_fem_grid_mesh(&g, X, el, &nn, &ne);
        for (k = 0; k < nn; ++k) X[2 * (nn + k)] = X[2 * k] + (pn_real)0.05, X[2 * (nn + k) + 1] = X[2 * k + 1]; /* the second block, level */
        for (k = 0; k < 3 * ne; ++k) el[3 * ne + k] = el[k] + (int)nn;
        half = nn;
        memset(&fd, 0, sizeof fd);
        fd.dim = 2, fd.n_nodes = 2 * nn, fd.n_elements = 2 * ne, fd.rest_m = X, fd.elements = el, fd.groups = &grp, fd.n_groups = 1;
        if (pn_fem_create(&fd, &m, why, sizeof why) != PN_OK) {
            fprintf(stderr, "  fem_self_contact: %s\n", why);
            PN_CHECK(0);
            continue;
        }
        for (k = 0; k < half; ++k) m->v[2 * k] = 1; /* the first block at 1 m/s toward the second, 1 cm away */
        for (k = 0; k < 2 * nn; ++k) p0 += m->mass[k] * m->v[2 * k];
        for (step = 0; t < T - 1e-12 && step < 2000000; ++step) {
            pn_fem_stats st;
            pn_real sdt = 0;
            double dt = 1e-3, r0 = -1e9, l1 = 1e9;
            if (!implicit) {
                pn_fem_stable_dt(m, &sdt);
                dt = fmin(0.5 * sdt, T - t);
            }
            if ((implicit ? pn_fem_step_implicit(m, (pn_real)dt, NULL, &st) : pn_fem_step_explicit(m, (pn_real)dt, &st)) != PN_OK) {
                fprintf(stderr, "  fem_self_contact: %s\n", pn_fem_error(m));
                PN_CHECK(0);
                break;
            }
            t += dt;
            dmin = fmin(dmin, pn__fem_min_distance(m, m->time_s));
            (void)r0, (void)l1;
            for (k = 0; k < 2 * nn; ++k) { /* no node inside a triangle of the other block */
                size_t e0 = k < half ? ne : 0, e;
                for (e = e0; e < e0 + ne; ++e) {
                    const pn_real *a = m->x + 2 * (size_t)m->elem[3 * e], *b = m->x + 2 * (size_t)m->elem[3 * e + 1];
                    const pn_real *c = m->x + 2 * (size_t)m->elem[3 * e + 2], *q = m->x + 2 * k;
                    double w0 = (b[0] - q[0]) * (c[1] - q[1]) - (c[0] - q[0]) * (b[1] - q[1]);
                    double w1 = (c[0] - q[0]) * (a[1] - q[1]) - (a[0] - q[0]) * (c[1] - q[1]);
                    double w2 = (a[0] - q[0]) * (b[1] - q[1]) - (b[0] - q[0]) * (a[1] - q[1]);
                    if (w0 > 0 && w1 > 0 && w2 > 0) overlap += 1;
                }
            }
        }
        for (k = 0; k < 2 * nn; ++k) p1 += m->mass[k] * m->v[2 * k];
        {
            double v0 = 0, v1 = 0, m0 = 0, m1 = 0;
            for (k = 0; k < 2 * nn; ++k) {
                if (k < half) v0 += m->mass[k] * m->v[2 * k], m0 += m->mass[k];
                else v1 += m->mass[k] * m->v[2 * k], m1 += m->mass[k];
            }
            printf("    [fem_self_contact] %s: smallest node-edge distance %.3g m, momentum %.6f -> %.6f, after: %.3f and %.3f m/s\n",
                   implicit ? "implicit dt 1e-3" : "explicit", dmin, p0, p1, v0 / m0, v1 / m1);
            PN_CHECK(v1 / m1 > v0 / m0 && v1 / m1 > 0.3); /* they hit and parted */
        }
        PN_CHECK(dmin > 0);
        PN_CHECK(overlap == 0);
        PN_CHECK_NEAR(p1, p0, 1e-6 * p0);
        pn_fem_destroy(m);
        free(X);
        free(el);
    }
}

/* Spun nodes follow the exact arc: a block (2D and 3D) all of whose nodes are spun about an
   axis through its centre turns rigidly (every node where the rotation matrix puts it,
   explicit and implicit steps, no strain energy); released, it flies on freely: explicit
   steps keep its angular momentum (a rotation-invariant energy, symplectic Euler). */
PN_TEST(fem_spin_release) {
    int dim, implicit;
    for (dim = 2; dim <= 3; ++dim)
        for (implicit = 0; implicit < 2; ++implicit) {
            pn_fem_grid g = t_fem_grid(dim, 3, 2, 2, 0.03, 0.02, 0.02);
            pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e5, 1000);
            t_fem t;
            pn_real centre[3] = {(pn_real)0.015, (pn_real)0.01, (pn_real)0.01}, w[3] = {0, 0, 3};
            double dt = 1e-3, err = 0, el = 0, kin = 0, L0[3] = {0, 0, 0}, L1[3] = {0, 0, 0}, Lerr = 0, ax[3];
            int *all, step, i;
            size_t k;
            pn_real elj, kinj;
            if (dim == 3) w[0] = 1, w[1] = 2; /* a skew axis */
            if (!t_fem_make(&t, &g, &grp, 0)) {
                PN_CHECK(0);
                continue;
            }
            all = (int *)malloc(sizeof(int) * t.nn);
            for (k = 0; k < t.nn; ++k) all[k] = (int)k;
            PN_CHECK(pn_fem_spin_nodes(t.m, t.nn, all, centre, w) == PN_OK);
            for (step = 0; step < 50; ++step) {
                pn_fem_stats st;
                PN_CHECK((implicit ? pn_fem_step_implicit(t.m, (pn_real)dt, NULL, &st) : pn_fem_step_explicit(t.m, (pn_real)dt, &st)) == PN_OK);
            }
            { /* the rotation by angle |w| T about w / |w| (Rodrigues), applied to the rest positions */
                double rate = sqrt((double)(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])), th = rate * 50 * dt, c = cos(th), sn = sin(th);
                for (i = 0; i < 3; ++i) ax[i] = w[i] / rate;
                for (k = 0; k < t.nn; ++k) {
                    double r[3] = {0, 0, 0}, cr[3], ad = 0, x;
                    for (i = 0; i < dim; ++i) r[i] = t.X[k * (size_t)dim + (size_t)i] - centre[i], ad += ax[i] * r[i];
                    cr[0] = ax[1] * r[2] - ax[2] * r[1], cr[1] = ax[2] * r[0] - ax[0] * r[2], cr[2] = ax[0] * r[1] - ax[1] * r[0];
                    for (i = 0; i < dim; ++i) {
                        x = centre[i] + r[i] * c + cr[i] * sn + ax[i] * ad * (1 - c);
                        err = fmax(err, fabs(t.m->x[k * (size_t)dim + (size_t)i] - x));
                    }
                }
            }
            PN_CHECK(pn_fem_energy(t.m, &elj, &kinj) == PN_OK);
            el = elj, kin = kinj;
            PN_CHECK(pn_fem_release_nodes(t.m, t.nn, all) == PN_OK);
            for (step = 0; step < 40; ++step) {
                pn_fem_stats st;
                double *L = step == 0 ? L0 : L1;
                if (step == 1 || step == 39) /* angular momentum sum m r x v about the centre, after the first free step */
                    for (i = 0; i < 3; ++i) L[i] = 0;
                for (k = 0; (step == 1 || step == 39) && k < t.nn; ++k) {
                    double r[3] = {0, 0, 0}, v[3] = {0, 0, 0};
                    for (i = 0; i < dim; ++i) r[i] = t.m->x[k * (size_t)dim + (size_t)i] - centre[i], v[i] = t.m->v[k * (size_t)dim + (size_t)i];
                    L = step == 1 ? L0 : L1;
                    L[0] += t.m->mass[k] * (r[1] * v[2] - r[2] * v[1]), L[1] += t.m->mass[k] * (r[2] * v[0] - r[0] * v[2]);
                    L[2] += t.m->mass[k] * (r[0] * v[1] - r[1] * v[0]);
                }
                PN_CHECK(pn_fem_step_explicit(t.m, (pn_real)(dt / 10), &st) == PN_OK);
            }
            for (i = 0; i < 3; ++i) Lerr = fmax(Lerr, fabs(L1[i] - L0[i]) / sqrt(L0[0] * L0[0] + L0[1] * L0[1] + L0[2] * L0[2]));
            printf("    [fem_spin_release] %dD %s: off the exact arc by %.2g m, strain energy %.2g J (kinetic %.3g), released: "
                   "angular momentum moved %.2g\n", dim, implicit ? "implicit" : "explicit", err, el, kin, Lerr);
            PN_CHECK_LE(err, 1e-12);
            PN_CHECK_LE(fabs(el), 1e-9 * kin);
            PN_CHECK_LE(Lerr, 1e-6);
            free(all);
            t_fem_free(&t);
        }
}

/* 1 and 2 threads give the same bits: a von Mises block pressed by a plate (2D and 3D, over
   512 elements so the element loops run threaded), implicit steps with the exact energy and
   with the lagged one (its fixed point), then explicit steps */
PN_TEST(fem_threads_same_bits) {
#ifdef _OPENMP
    int dim, en;
    for (dim = 2; dim <= 3; ++dim)
        for (en = 0; en < 2; ++en) {
            pn_real *xs[2] = {NULL, NULL};
            size_t nn = 0, k;
            int t, same = 1;
            for (t = 1; t <= 2; ++t) {
                pn_fem_grid g = dim == 2 ? t_fem_grid(2, 24, 12, 1, 0.06, 0.03, 0) : t_fem_grid(3, 8, 6, 4, 0.04, 0.03, 0.02);
                pn_group grp = t_fem_group(PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_VON_MISES, 1e8, 1000);
                pn_collider c;
                t_fem tf;
                int step;
                g.lo_m[1] = (pn_real)1e-3, g.crossed = 1;
                omp_set_num_threads(t);
                if (!t_fem_make(&tf, &g, &grp, -9.81)) {
                    PN_CHECK(0);
                    break;
                }
                PN_CHECK(pn_fem_group_set_energy(tf.m, 0, en ? PN_ENERGY_LAGGED : PN_ENERGY_EXACT_VM, NULL) == PN_OK);
                memset(&c, 0, sizeof c);
                c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1;
                PN_CHECK(pn_fem_add_obstacle(tf.m, &c, NULL) == PN_OK);
                c.normal[1] = -1, c.center_m[1] = (pn_real)0.0315, c.velocity_m_s[1] = (pn_real)-0.5;
                PN_CHECK(pn_fem_add_obstacle(tf.m, &c, NULL) == PN_OK);
                for (step = 0; step < 4; ++step) {
                    pn_fem_stats st;
                    PN_CHECK(pn_fem_step_implicit(tf.m, (pn_real)2e-3, NULL, &st) == PN_OK);
                }
                for (step = 0; step < 20; ++step) {
                    pn_fem_stats st;
                    pn_real sdt;
                    pn_fem_stable_dt(tf.m, &sdt);
                    PN_CHECK(pn_fem_step_explicit(tf.m, sdt / 2, &st) == PN_OK);
                }
                nn = tf.m->n_nodes * (size_t)dim;
                xs[t - 1] = (pn_real *)malloc(sizeof(pn_real) * nn);
                memcpy(xs[t - 1], tf.m->x, sizeof(pn_real) * nn);
                t_fem_free(&tf);
            }
            omp_set_num_threads(2);
            for (k = 0; xs[0] && xs[1] && k < nn; ++k) same &= memcmp(&xs[0][k], &xs[1][k], sizeof(pn_real)) == 0;
            printf("    [fem_threads_same_bits] %dD %s: 1 and 2 threads %s\n", dim, en ? "lagged" : "exact", same ? "identical" : "DIFFER");
            PN_CHECK(xs[0] && xs[1] && same);
            free(xs[0]), free(xs[1]);
        }
#else
    PN_REPORT("skipped: built without -fopenmp");
#endif
}

/* the curvature 2c of the least-squares parabola a + b x + c x^2 through the nodes at rest
   height 0 with rest x in [x0, x1] (small slopes: the arc's curvature to (k x1)^2) */
static double t_fem_curvature(const pn_fem_mesh *m, double x0, double x1) {
    double S[5] = {0, 0, 0, 0, 0}, T[3] = {0, 0, 0}, A[9], det, c;
    size_t k;
    int i;
    for (k = 0; k < m->n_nodes; ++k) {
        double X = m->X[2 * k], x = m->x[2 * k], y = m->x[2 * k + 1], p = 1;
        if (fabs(m->X[2 * k + 1]) > 1e-12 || X < x0 || X > x1) continue;
        for (i = 0; i < 5; ++i) S[i] += p, p *= x;
        T[0] += y, T[1] += y * x, T[2] += y * x * x;
    }
    for (i = 0; i < 9; ++i) A[i] = S[i / 3 + i % 3];
    det = A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) + A[2] * (A[3] * A[7] - A[4] * A[6]);
    c = (A[0] * (A[4] * T[2] - T[1] * A[7]) - A[1] * (A[3] * T[2] - T[1] * A[6]) + T[0] * (A[3] * A[7] - A[4] * A[6])) / det;
    return 2 * c;
}

/* A bar bent past yield keeps a permanent set: pure bending of a bar of depth h to about
   3 k_y (its ends held to the exact arc of plane sections, in steps slow enough to be
   static), then its far end let go. Elastic-perfectly-plastic beam theory: a section bent to
   k > k_y carries M = M_y (3/2) (1 - (k_y / k)^2 / 3) and springs back elastically by
   M / (E' I) = k_y (3/2) (1 - (k_y / k)^2 / 3) when released. For the 2D von Mises model in
   uniaxial stress: E' = E / (1 - nu^2), the yield stress 2 sigma_Y / sqrt(3) (|dev tau| of
   diag(s, 0) is s / sqrt(2)), k_y = 2 sigma_y' / (E' h). Curvatures from parabolas fitted to
   the neutral axis over the middle half: the held ends (no lateral contraction there) are
   stiffer and bend less, so the middle bends a little more than the imposed mean; the
   spring-back is predicted from the middle's own curvature. Exact von Mises energy, no
   hardening, 4 triangles per square, 8 deep. */
PN_TEST(fem_permanent_set) {
    double E = 1e7, nu = 0.3, sy = 1e4, L = 0.2, h = 0.02, Ep = E / (1 - nu * nu), syp = 2 * sy / sqrt(3.0);
    double ky = 2 * syp / (Ep * h), kmax = 3 * ky, kres, kload = 0, kr = 0;
    pn_fem_grid g = t_fem_grid(2, 40, 8, 1, L, h, 1);
    pn_group grp;
    pn_material_desc md;
    t_fem t;
    int *right, nr = 0, step, ok = 1;
    size_t k;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_STVK_HENCKY, md.plastic = PN_PLASTIC_VON_MISES, md.youngs_modulus_pa = (pn_real)E;
    md.poisson_ratio = (pn_real)nu, md.yield_stress_pa = (pn_real)sy;
    memset(&grp, 0, sizeof grp);
    PN_CHECK(pn_material_init(&grp.material, &md, NULL, 0) == PN_OK);
    grp.density_kg_m3 = 1000; /* static: inertia is 1e-9 of the stiffness over a step of 1 s */
    grp.energy = PN_ENERGY_EXACT_VM;
    g.crossed = 1, g.lo_m[1] = (pn_real)(-h / 2);
    if (!t_fem_make(&t, &g, &grp, 0)) {
        PN_CHECK(0);
        return;
    }
    right = (int *)malloc(sizeof(int) * t.nn);
    for (k = 0; k < t.nn; ++k) {
        int node = (int)k;
        if (t.m->X[2 * k] < 1e-12) pn_fem_fix_nodes(t.m, 1, &node, NULL); /* the left end held */
        if (t.m->X[2 * k] > L - 1e-12) right[nr++] = node;
    }
    for (step = 1; step <= 12 && ok; ++step) { /* the right end along the arc: (L, y) -> centre (0, 1 / k) + (1 / k - y) (sin kL, -cos kL) */
        double kc = kmax * step / 12;
        int j;
        pn_fem_stats st;
        for (j = 0; j < nr; ++j) {
            double y = t.m->X[2 * (size_t)right[j] + 1], r = 1 / kc - y;
            pn_real v[2];
            v[0] = (pn_real)(r * sin(kc * L) - t.m->x[2 * (size_t)right[j]]);
            v[1] = (pn_real)(1 / kc - r * cos(kc * L) - t.m->x[2 * (size_t)right[j] + 1]);
            pn_fem_fix_nodes(t.m, 1, &right[j], v); /* there in a step of 1 s */
        }
        if (pn_fem_step_implicit(t.m, 1, NULL, &st) != PN_OK) {
            fprintf(stderr, "  fem_permanent_set: %s\n", pn_fem_error(t.m));
            ok = 0;
        }
    }
    kload = t_fem_curvature(t.m, L / 4, 3 * L / 4);
    pn_fem_release_nodes(t.m, (size_t)nr, right);
    for (step = 0; step < 30 && ok; ++step) { /* spring back to rest */
        pn_fem_stats st;
        double moved = 0;
        if (pn_fem_step_implicit(t.m, 1, NULL, &st) != PN_OK) {
            fprintf(stderr, "  fem_permanent_set: %s\n", pn_fem_error(t.m));
            ok = 0;
        }
        for (k = 0; k < 2 * t.nn; ++k) moved = fmax(moved, fabs(t.m->v[k]));
        if (moved < 1e-9) break;
    }
    kr = t_fem_curvature(t.m, L / 4, 3 * L / 4);
    kres = kload - 1.5 * ky * (1 - ky * ky / (3 * kload * kload));
    printf("    [fem_permanent_set] curvature loaded %.4f 1/m (imposed mean %.4f), after release %.4f, beam theory %.4f (%.1f%%; "
           "k_y %.4f; springing back fully would leave 0, not at all %.4f)\n", kload, kmax, kr, kres, 100 * (kr / kres - 1), ky, kload);
    PN_CHECK(ok);
    PN_CHECK_NEAR(kload, kmax, 0.05 * kmax);
    PN_CHECK_NEAR(kr, kres, 0.03 * kres);
    free(right);
    t_fem_free(&t);
}

/* does segment (p, q) cross triangle (a, b, c)? (signed volumes: the test's own) */
static int t_seg_tri(const pn_real *p, const pn_real *q, const pn_real *a, const pn_real *b, const pn_real *c) {
    const pn_real *v[3];
    double s[3], sp, sq;
    int i;
    v[0] = a, v[1] = b, v[2] = c;
#define T_VOL(P, Q, R, S)                                                                                           \
    (((Q)[0] - (P)[0]) * (((R)[1] - (P)[1]) * ((S)[2] - (P)[2]) - ((R)[2] - (P)[2]) * ((S)[1] - (P)[1])) -              \
     ((Q)[1] - (P)[1]) * (((R)[0] - (P)[0]) * ((S)[2] - (P)[2]) - ((R)[2] - (P)[2]) * ((S)[0] - (P)[0])) +              \
     ((Q)[2] - (P)[2]) * (((R)[0] - (P)[0]) * ((S)[1] - (P)[1]) - ((R)[1] - (P)[1]) * ((S)[0] - (P)[0])))
    sp = T_VOL(a, b, c, p), sq = T_VOL(a, b, c, q);
    if ((sp > 0) == (sq > 0)) return 0; /* both ends on one side of the plane */
    for (i = 0; i < 3; ++i) s[i] = T_VOL(p, q, v[i], v[(i + 1) % 3]);
#undef T_VOL
    return (s[0] > 0 && s[1] > 0 && s[2] > 0) || (s[0] < 0 && s[1] < 0 && s[2] < 0);
}

/* 3D self-contact, edge against edge: two square bars of one mesh, crossed, each turned 45
   degrees about its axis so that an edge of one meets an edge of the other first (no node
   comes near a face before the edges touch); the upper one thrown down at the lower. No
   edge of either bar ever crosses a face of the other (the test's own segment-triangle
   test over every element edge and face), momentum is kept and the bars part. Implicit at
   1e-3 s and explicit. */
PN_TEST(fem_self_contact_3d) {
    int implicit;
    for (implicit = 0; implicit < 3; ++implicit) { /* 2: implicit with PCG (the pairs all off its block pattern) */
        pn_fem_grid g = t_fem_grid(3, 8, 2, 2, 0.08, 0.02, 0.02);
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e5, 1000);
        pn_fem_desc fd;
        pn_fem_mesh *m = NULL;
        size_t nn, ne, k, e, f;
        pn_real *X;
        int *el, step, a, b;
        char why[256];
        double p0 = 0, p1 = 0, dmin = 1, t = 0, T = 0.04, r = 0.7071067811865476, vz[2] = {0, 0}, mz[2] = {0, 0};
        long crossings = 0;
        pn_fem_implicit_desc id;
        memset(&id, 0, sizeof id);
        id.linear_solver = implicit == 2 ? PN_FEM_LINEAR_PCG : PN_FEM_LINEAR_DEFAULT;
        pn_fem_grid_mesh(&g, NULL, NULL, &nn, &ne);
        X = (pn_real *)malloc(sizeof(pn_real) * 6 * nn);
        el = (int *)malloc(sizeof(int) * 8 * ne);
        pn_fem_grid_mesh(&g, X, el, &nn, &ne);
        for (k = 0; k < nn; ++k) { /* centred, the lower bar along x, the upper along y; each turned about its axis */
            double x = X[3 * k] - 0.04, y = X[3 * k + 1] - 0.01, z = X[3 * k + 2] - 0.01;
            X[3 * k] = (pn_real)x, X[3 * k + 1] = (pn_real)(r * y - r * z), X[3 * k + 2] = (pn_real)(r * y + r * z);
            X[3 * (nn + k)] = (pn_real)(r * y - r * z), X[3 * (nn + k) + 1] = (pn_real)x;
            X[3 * (nn + k) + 2] = (pn_real)(r * y + r * z + 2 * 0.01 * 1.41421356 + 0.004); /* edges 4 mm apart */
        }
        for (k = 0; k < 4 * ne; ++k) el[4 * ne + k] = el[k] + (int)nn;
        for (e = 0; e < ne; ++e) { /* the upper bar's elements: the mirror (x <-> y) turned them inside out */
            int t0 = el[4 * (ne + e) + 1];
            el[4 * (ne + e) + 1] = el[4 * (ne + e) + 2], el[4 * (ne + e) + 2] = t0;
        }
        memset(&fd, 0, sizeof fd);
        fd.dim = 3, fd.n_nodes = 2 * nn, fd.n_elements = 2 * ne, fd.rest_m = X, fd.elements = el, fd.groups = &grp, fd.n_groups = 1;
        if (pn_fem_create(&fd, &m, why, sizeof why) != PN_OK) {
            fprintf(stderr, "  fem_self_contact_3d: %s\n", why);
            PN_CHECK(0);
            free(X), free(el);
            continue;
        }
        for (k = nn; k < 2 * nn; ++k) m->v[3 * k + 2] = -1; /* the upper bar down at 1 m/s */
        for (k = 0; k < 2 * nn; ++k) p0 += m->mass[k] * m->v[3 * k + 2];
        for (step = 0; t < T - 1e-12 && step < 100000; ++step) {
            pn_fem_stats st;
            pn_real sdt = 0;
            double dt = 1e-3;
            if (!implicit) {
                pn_fem_stable_dt(m, &sdt);
                dt = fmin(0.5 * sdt, T - t);
            }
            if ((implicit ? pn_fem_step_implicit(m, (pn_real)dt, &id, &st) : pn_fem_step_explicit(m, (pn_real)dt, &st)) != PN_OK) {
                fprintf(stderr, "  fem_self_contact_3d: %s\n", pn_fem_error(m));
                PN_CHECK(0);
                break;
            }
            t += dt;
            dmin = fmin(dmin, pn__fem_min_distance(m, m->time_s));
            if (!implicit && step % 32) continue;
            for (e = 0; e < 2 * ne; ++e) /* every element edge of one bar against every element face of the other */
                for (a = 0; a < 4; ++a)
                    for (b = a + 1; b < 4; ++b)
                        for (f = e < ne ? ne : 0; f < (e < ne ? 2 * ne : ne); ++f) {
                            int o, c[3], nc;
                            const pn_real *P = m->x + 3 * (size_t)m->elem[4 * e + (size_t)a], *Q = m->x + 3 * (size_t)m->elem[4 * e + (size_t)b];
                            for (o = 0; o < 4; ++o) {
                                for (nc = 0, k = 0; k < 4; ++k)
                                    if ((int)k != o) c[nc++] = m->elem[4 * f + k];
                                crossings += t_seg_tri(P, Q, m->x + 3 * (size_t)c[0], m->x + 3 * (size_t)c[1], m->x + 3 * (size_t)c[2]);
                            }
                        }
        }
        for (k = 0; k < 2 * nn; ++k) {
            p1 += m->mass[k] * m->v[3 * k + 2];
            vz[k >= nn] += m->mass[k] * m->v[3 * k + 2], mz[k >= nn] += m->mass[k];
        }
        printf("    [fem_self_contact_3d] %s: smallest distance %.3g m, %ld crossings, z momentum %.6f -> %.6f, after: lower %.3f, "
               "upper %.3f m/s\n", implicit == 2 ? "implicit dt 1e-3, PCG" : implicit ? "implicit dt 1e-3" : "explicit", dmin, crossings, p0, p1, vz[0] / mz[0], vz[1] / mz[1]);
        PN_CHECK(dmin > 0);
        PN_CHECK(crossings == 0);
        PN_CHECK(vz[0] / mz[0] < -0.3 && vz[1] / mz[1] > vz[0] / mz[0]); /* they hit and parted */
        PN_CHECK_NEAR(p1, p0, 1e-6 * fabs(p0));
        pn_fem_destroy(m);
        free(X);
        free(el);
    }
}

/* bad meshes are refused, naming the culprit, and create nothing */
PN_TEST(fem_bad_mesh) {
    static const pn_real X[] = {0, 0, 1, 0, 0, 1, 1, 1, 2, 2};
    static const int good[] = {0, 1, 2, 1, 3, 2};
    pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
    pn_fem_desc fd;
    pn_fem_mesh *m = NULL;
    char why[256];
    int el[6], i;
    pn_real Xb[10];
    memset(&fd, 0, sizeof fd);
    fd.dim = 2, fd.n_nodes = 4, fd.n_elements = 2, fd.rest_m = X, fd.elements = good, fd.groups = &grp, fd.n_groups = 1;
    PN_CHECK(pn_fem_create(&fd, &m, why, sizeof why) == PN_OK && m);
    pn_fem_destroy(m);
    for (i = 0; i < 7; ++i) {
        pn_fem_desc bad = fd;
        pn_result r;
        const char *needle;
        memcpy(el, good, sizeof el);
        memcpy(Xb, X, sizeof Xb);
        bad.elements = el, bad.rest_m = Xb;
        switch (i) {
        case 0: el[4] = 4, needle = "element 1"; break;                       /* index out of range */
        case 1: el[4] = -1, needle = "element 1"; break;
        case 2: el[1] = 0, needle = "element 0"; break;                       /* a node twice       */
        case 3: el[3] = 1, el[4] = 2, el[5] = 3, Xb[6] = 0.5, Xb[7] = 0.5, needle = "element 1"; break; /* degenerate */
        case 4: el[4] = 2, el[5] = 3, needle = "element 1"; break;            /* inverted           */
        case 5: Xb[5] = (pn_real)NAN, needle = "node 2"; break;
        default: bad.n_nodes = 5, needle = "node 4"; break;                   /* a node of no element */
        }
        m = (pn_fem_mesh *)1;
        why[0] = 0;
        r = pn_fem_create(&bad, &m, why, sizeof why);
        PN_CHECK(r != PN_OK);
        PN_CHECK(m == NULL);
        if (!strstr(why, needle)) {
            fprintf(stderr, "  case %d: '%s' does not name %s\n", i, why, needle);
            PN_CHECK(0);
        }
    }
    { /* an obstacle with a node inside is refused, the mesh unchanged */
        pn_collider c;
        PN_CHECK(pn_fem_create(&fd, &m, why, sizeof why) == PN_OK);
        memset(&c, 0, sizeof c);
        c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1, c.center_m[1] = (pn_real)0.5;
        PN_CHECK(pn_fem_add_obstacle(m, &c, NULL) == PN_ERROR_INVALID_ARGUMENT);
        PN_CHECK(strstr(pn_fem_error(m), "node 0") != NULL);
        PN_CHECK(m->n_obstacles == 0);
        PN_CHECK(pn_fem_step_implicit(m, (pn_real)NAN, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT);
        pn_fem_destroy(m);
    }
}

/* the mesh's state, bit for bit (nodes, elements' plastic state, time, steps) */
static int t_fem_same(const pn_fem_mesh *m, const pn_real *x, const pn_real *v, const pn_real *Fp, const pn_real *h, double t,
                      long steps) {
    size_t nd = m->n_nodes * (size_t)m->dim, ne = m->n_elems, dd = (size_t)(m->dim * m->dim);
    return memcmp(m->x, x, sizeof(pn_real) * nd) == 0 && memcmp(m->v, v, sizeof(pn_real) * nd) == 0 &&
           memcmp(m->Fp_inv, Fp, sizeof(pn_real) * ne * dd) == 0 && memcmp(m->h, h, sizeof(pn_real) * ne) == 0 &&
           m->time_s == t && m->steps == steps;
}

/* A NaN or infinite node position or velocity written by hand is refused by both steps
   (PN_ERROR_NONFINITE naming the node, the mesh unchanged) before any of it reaches the
   self-contact grid (where it once became an integer: a crash). 2D and 3D, with self-contact.
   Solver settings that are NaN, infinite or negative are refused, not replaced by defaults. */
PN_TEST(fem_nonfinite_state) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_fem_grid g = t_fem_grid(dim, 4, 3, 2, 0.4, 0.3, 0.2);
        pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_VON_MISES, 1e6, 1000);
        pn_fem_implicit_desc id;
        t_fem t;
        pn_real *x, *v, *Fp, *h;
        size_t nd, k = 5;
        int bad, which;
        if (!t_fem_make(&t, &g, &grp, -9.81)) {
            PN_CHECK(0);
            continue;
        }
        nd = t.nn * (size_t)dim;
        x = (pn_real *)malloc(sizeof(pn_real) * nd), v = (pn_real *)malloc(sizeof(pn_real) * nd);
        Fp = (pn_real *)malloc(sizeof(pn_real) * t.ne * (size_t)(dim * dim)), h = (pn_real *)malloc(sizeof(pn_real) * t.ne);
        PN_CHECK(pn_fem_step_implicit(t.m, 1e-3, NULL, NULL) == PN_OK);
        for (bad = 0; bad < 4; ++bad)
            for (which = 0; which < 2; ++which) {
                pn_real *arr = bad < 2 ? t.m->v : t.m->x, keep = arr[k * (size_t)dim + 1];
                pn_result r;
                arr[k * (size_t)dim + 1] = bad % 2 ? (pn_real)HUGE_VAL : (pn_real)NAN;
                memcpy(x, t.m->x, sizeof(pn_real) * nd), memcpy(v, t.m->v, sizeof(pn_real) * nd);
                memcpy(Fp, t.m->Fp_inv, sizeof(pn_real) * t.ne * (size_t)(dim * dim));
                memcpy(h, t.m->h, sizeof(pn_real) * t.ne);
                r = which ? pn_fem_step_explicit(t.m, 1e-5, NULL) : pn_fem_step_implicit(t.m, 1e-3, NULL, NULL);
                PN_CHECK(r == PN_ERROR_NONFINITE);
                PN_CHECK(t.m->error_node == (long)k && strstr(pn_fem_error(t.m), "node 5") != NULL);
                PN_CHECK(t_fem_same(t.m, x, v, Fp, h, t.m->time_s, 1));
                arr[k * (size_t)dim + 1] = keep;
            }
        for (bad = 0; bad < 5; ++bad) {
            memset(&id, 0, sizeof id);
            if (bad == 0) id.newton_tol = (pn_real)NAN;
            if (bad == 1) id.newton_tol = -1;
            if (bad == 2) id.cg_rel_tol = (pn_real)HUGE_VAL;
            if (bad == 3) id.newton_max = -2;
            if (bad == 4) id.cg_max = -1;
            PN_CHECK(pn_fem_step_implicit(t.m, 1e-3, &id, NULL) == PN_ERROR_INVALID_ARGUMENT && t.m->steps == 1);
            PN_CHECK(strstr(pn_fem_error(t.m), bad < 2 ? "newton_tol" : bad == 2 ? "cg_rel_tol" : bad == 3 ? "newton_max" : "cg_max"));
        }
        PN_CHECK(pn_fem_step_implicit(t.m, 1e-3, NULL, NULL) == PN_OK);
        free(x), free(v), free(Fp), free(h);
        t_fem_free(&t);
    }
}

/* A box obstacle that reaches into an element with none of the element's nodes inside it (a
   small box inside a coarse element, or a thin one through an element's middle) is refused
   by pn_fem_add_obstacle naming the element; a box beside the mesh is taken. The test's own
   check: points sampled inside the box, located by barycentric coordinates. */
PN_TEST(fem_obstacle_inside_element) {
    int dim, cs;
    for (dim = 2; dim <= 3; ++dim)
        for (cs = 0; cs < 3; ++cs) {
            pn_fem_grid g = t_fem_grid(dim, 2, 2, 2, 1, 1, 1);
            pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
            pn_collider c;
            t_fem t;
            int i, inside_any = 0, s;
            pn_result r;
            if (!t_fem_make(&t, &g, &grp, 0)) {
                PN_CHECK(0);
                continue;
            }
            memset(&c, 0, sizeof c);
            c.shape = PN_SHAPE_BOX;
            for (i = 0; i < dim; ++i) c.center_m[i] = (pn_real)0.27, c.half_extent_m[i] = (pn_real)0.05;
            if (cs == 1) c.center_m[0] = (pn_real)0.5, c.half_extent_m[0] = (pn_real)0.7, c.half_extent_m[1] = (pn_real)0.01,
                         c.center_m[1] = (pn_real)0.27; /* a thin bar right through the mesh, between node rows */
            if (cs == 2) c.center_m[0] = (pn_real)1.3; /* beside the mesh */
            /* independent: sample the box, is any sample inside any element? */
            for (s = 0; s < 4096 && !inside_any; ++s) {
                pn_real q[3];
                size_t e;
                for (i = 0; i < dim; ++i)
                    q[i] = c.center_m[i] + c.half_extent_m[i] * (pn_real)(2 * ((s >> (4 * i)) % 16 + 0.5) / 16 - 1);
                for (e = 0; e < t.ne && !inside_any; ++e) {
                    double A[9], b[3], lam[4], sum = 0;
                    const int *el = t.el + e * (size_t)(dim + 1);
                    int a, j, ok = 1;
                    for (a = 0; a < dim; ++a) {
                        b[a] = q[a] - t.X[el[0] * dim + a];
                        for (j = 0; j < dim; ++j) A[a * dim + j] = t.X[el[j + 1] * dim + a] - t.X[el[0] * dim + a];
                    }
                    for (a = 0; a < dim; ++a) { /* Cramer */
                        double Ai[9];
                        memcpy(Ai, A, sizeof Ai);
                        for (j = 0; j < dim; ++j) Ai[j * dim + a] = b[j];
                        lam[a] = t_det(dim, Ai) / t_det(dim, A);
                    }
                    for (a = 0; a < dim; ++a) ok &= lam[a] > 1e-9, sum += lam[a];
                    inside_any = ok && sum < 1 - 1e-9;
                }
            }
            PN_CHECK(inside_any == (cs < 2));
            r = pn_fem_add_obstacle(t.m, &c, NULL);
            PN_CHECK(r == (cs < 2 ? PN_ERROR_INVALID_ARGUMENT : PN_OK));
            if (cs < 2) PN_CHECK(t.m->n_obstacles == 0 && strstr(pn_fem_error(t.m), "element") != NULL);
            t_fem_free(&t);
        }
}

/* a unit square of two triangles (one listed clockwise), with a line and a point element */
static const char t_fem_msh2[] = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n10 0 0 0\n20 1 0 0\n30 1 1 0\n40 0 1 0\n$EndNodes\n"
                                 "$Elements\n4\n1 15 2 0 1 10\n2 1 2 7 1 10 20\n3 2 2 5 1 10 20 30\n4 2 2 5 1 10 40 30\n$EndElements\n";
/* a unit cube corner tetrahedron and its neighbour, version 4.1 with two node blocks (the
   second with parametric coordinates) */
static const char t_fem_msh4[] = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n2 5 1 5\n0 1 0 1\n1\n0 0 0\n2 1 1 4\n2\n3\n4\n5\n"
                                 "1 0 0 0.5 0.5\n0 1 0 0.5 0.5\n0 0 1 0.5 0.5\n1 1 1 0.5 0.5\n$EndNodes\n$Elements\n1 2 1 2\n3 1 4 2\n1 1 2 3 4\n"
                                 "2 2 3 4 5\n$EndElements\n";
/* quadratic elements listed clockwise (the loader turns them, corners and edge nodes): a
   10-node tetrahedron and a 6-node triangle, Gmsh 2.2 */
static const char t_fem_msh_tet10[] = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n10\n1 0 0 0\n2 0 1 0\n3 1 0 0\n4 0 0 1\n"
                                      "5 0 0.5 0\n6 0.5 0.5 0\n7 0.5 0 0\n8 0 0 0.5\n9 0.5 0 0.5\n10 0 0.5 0.5\n$EndNodes\n"
                                      "$Elements\n1\n1 11 2 3 1 1 2 3 4 5 6 7 8 9 10\n$EndElements\n";
static const char t_fem_msh_tri6[] = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n6\n1 0 0 0\n2 0 1 0\n3 1 0 0\n4 0 0.5 0\n"
                                     "5 0.5 0.5 0\n6 0.5 0 0\n$EndNodes\n$Elements\n2\n1 9 2 3 1 1 2 3 4 5 6\n2 2 2 3 1 1 2 3\n$EndElements\n";
static const char t_fem_node[] = "# a TetGen mesh\n5 3 0 1\n1 0 0 0 0\n2 1 0 0 0\n3 0 1 0 0\n4 0 0 1 1\n5 1 1 1 0\n";
static const char t_fem_ele[] = "2 4 1\n1 1 2 3 4 7\n2 2 4 3 5 8\n";

/* The loaders: each format to the right mesh (counts, tags, orientation, pn_fem_create takes
   it); bad files refused naming the line; 1e5 mutated files never crash or leak (ASan, UBSan
   in make test-sanitize) and what parses is a mesh pn_fem_create takes or refuses. */
PN_TEST(fem_loaders) {
    pn_fem_mesh_data d;
    pn_group grp = t_fem_group(PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE, 1e6, 1000);
    char why[256], buf[1024];
    int pass, ok_parse = 0, created = 0;
    unsigned long seed = 12345;
    for (pass = 0; pass < 3; ++pass) {
        pn_result r = pass == 0   ? pn_fem_parse_msh(t_fem_msh2, sizeof t_fem_msh2 - 1, 2, NULL, &d, why, sizeof why)
                      : pass == 1 ? pn_fem_parse_msh(t_fem_msh4, sizeof t_fem_msh4 - 1, 3, NULL, &d, why, sizeof why)
                                  : pn_fem_parse_tetgen(t_fem_node, sizeof t_fem_node - 1, t_fem_ele, sizeof t_fem_ele - 1, NULL, &d, why,
                                                        sizeof why);
        pn_fem_desc fd;
        pn_fem_mesh *m = NULL;
        if (r != PN_OK) fprintf(stderr, "  fem_loaders %d: %s\n", pass, why);
        PN_CHECK(r == PN_OK);
        if (r != PN_OK) continue;
        PN_CHECK(d.n_nodes == (size_t)(pass == 0 ? 4 : 5) && d.n_elements == 2);
        PN_CHECK(d.element_tags[0] == (pass == 0 ? 5 : pass == 1 ? 1 : 7) && d.element_tags[1] == (pass == 0 ? 5 : pass == 1 ? 1 : 8));
        if (pass == 0) PN_CHECK(d.nodes[2] == 1 && d.nodes[5] == 1); /* node 20 at (1, 0), 30 at (1, 1) */
        memset(&fd, 0, sizeof fd);
        fd.dim = d.dim, fd.n_nodes = d.n_nodes, fd.n_elements = d.n_elements, fd.rest_m = d.nodes, fd.elements = d.elements;
        fd.groups = &grp, fd.n_groups = 1;
        if (pn_fem_create(&fd, &m, why, sizeof why) != PN_OK) fprintf(stderr, "  fem_loaders %d: %s\n", pass, why);
        PN_CHECK(m != NULL); /* positive orientation after the reorder */
        pn_fem_destroy(m);
        pn_fem_mesh_data_free(&d, NULL);
    }
    for (pass = 0; pass < 2; ++pass) { /* quadratic elements, turned; a file with both kinds refused */
        pn_fem_desc fd;
        pn_fem_mesh *m = NULL;
        pn_result r = pass ? pn_fem_parse_msh(t_fem_msh_tet10, sizeof t_fem_msh_tet10 - 1, 3, NULL, &d, why, sizeof why)
                           : pn_fem_parse_msh(t_fem_msh_tri6, sizeof t_fem_msh_tri6 - 1, 2, NULL, &d, why, sizeof why);
        if (!pass) { /* the triangle file has a linear triangle too */
            if (!strstr(why, "both")) fprintf(stderr, "  fem_loaders: '%s' does not say the file has both kinds\n", why);
            PN_CHECK(r == PN_ERROR_FORMAT && strstr(why, "both") != NULL && d.nodes == NULL);
            { /* the file without its linear triangle */
                char one[512];
                size_t n = strstr(t_fem_msh_tri6, "$Elements") - t_fem_msh_tri6;
                memcpy(one, t_fem_msh_tri6, n);
                snprintf(one + n, sizeof one - n, "$Elements\n1\n1 9 2 3 1 1 2 3 4 5 6\n$EndElements\n");
                r = pn_fem_parse_msh(one, strlen(one), 2, NULL, &d, why, sizeof why);
            }
        }
        PN_CHECK(r == PN_OK);
        if (r != PN_OK) {
            fprintf(stderr, "  fem_loaders quadratic %d: %s\n", pass, why);
            continue;
        }
        PN_CHECK(d.order == 2 && d.n_elements == 1 && d.n_nodes == (size_t)(pass ? 10 : 6));
        memset(&fd, 0, sizeof fd);
        fd.dim = d.dim, fd.n_nodes = d.n_nodes, fd.n_elements = d.n_elements, fd.rest_m = d.nodes, fd.elements = d.elements;
        fd.groups = &grp, fd.n_groups = 1, fd.order = d.order;
        if (pn_fem_create(&fd, &m, why, sizeof why) != PN_OK) fprintf(stderr, "  fem_loaders quadratic %d: %s\n", pass, why);
        PN_CHECK(m != NULL); /* turned whole: the Jacobian is the corners' at every point */
        if (m) {
            double vol = 0;
            size_t p;
            for (p = 0; p < m->n_points; ++p) vol += m->vol0[p];
            PN_CHECK_NEAR(vol, pass ? 1.0 / 6 : 0.5, 1e-14);
        }
        pn_fem_destroy(m);
        pn_fem_mesh_data_free(&d, NULL);
    }
    { /* bad files name their line */
        static const char *bad[] = {"$MeshFormat\n3.0 0 8\n$EndMeshFormat\n",
                                    "$MeshFormat\n2.2 1 8\n$EndMeshFormat\n",
                                    "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n1 0 0 0\n2 nan 0 0\n$EndNodes\n",
                                    "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n$Elements\n1\n1 2 0 1 2 9\n$EndElements\n"};
        static const char *needle[] = {"line 2", "line 2", "line 7", "node 9"};
        int i;
        for (i = 0; i < 4; ++i) {
            why[0] = 0;
            PN_CHECK(pn_fem_parse_msh(bad[i], strlen(bad[i]), 2, NULL, &d, why, sizeof why) == PN_ERROR_FORMAT);
            PN_CHECK(d.nodes == NULL && d.elements == NULL);
            if (!strstr(why, needle[i])) {
                fprintf(stderr, "  bad file %d: '%s' does not name %s\n", i, why, needle[i]);
                PN_CHECK(0);
            }
        }
    }
    for (pass = 0; pass < 100000; ++pass) { /* mutation fuzz */
        const char *src = pass % 4 == 0 ? t_fem_msh2 : pass % 4 == 1 ? t_fem_msh4 : pass % 4 == 2 ? t_fem_ele : t_fem_msh_tet10;
        size_t n = strlen(src), k;
        int muts, q;
        pn_result r;
        memcpy(buf, src, n);
        seed = seed * 6364136223846793005UL + 1442695040888963407UL;
        muts = 1 + (int)(seed >> 60);
        for (q = 0; q < muts; ++q) {
            seed = seed * 6364136223846793005UL + 1442695040888963407UL;
            k = n ? (size_t)(seed >> 33) % n : 0;
            switch ((seed >> 20) % 5) {
            case 0: buf[k] = (char)(seed >> 8); break;                          /* a random byte       */
            case 1: buf[k] = "0123456789-.e \n$"[(seed >> 8) % 17]; break;     /* a plausible one     */
            case 2: if (n + 1 < sizeof buf) memmove(buf + k + 1, buf + k, n - k), buf[k] = "91 \n"[(seed >> 8) % 4], n++; break;
            case 3: if (n > 1) memmove(buf + k, buf + k + 1, n - k - 1), n--; break; /* a deletion      */
            default: n = k; break;                                              /* truncation          */
            }
        }
        r = pass % 4 == 2 ? pn_fem_parse_tetgen(t_fem_node, sizeof t_fem_node - 1, buf, n, NULL, &d, why, sizeof why)
                          : pn_fem_parse_msh(buf, n, pass % 4 == 0 ? 2 : 3, NULL, &d, why, sizeof why);
        if (r == PN_OK) {
            pn_fem_desc fd;
            pn_fem_mesh *m = NULL;
            size_t e;
            ok_parse++;
            for (e = 0; e < d.n_elements * (size_t)(d.order == 2 ? (d.dim + 1) * (d.dim + 2) / 2 : d.dim + 1); ++e)
                PN_CHECK(d.elements[e] >= 0 && (size_t)d.elements[e] < d.n_nodes);
            memset(&fd, 0, sizeof fd);
            fd.dim = d.dim, fd.n_nodes = d.n_nodes, fd.n_elements = d.n_elements, fd.rest_m = d.nodes, fd.elements = d.elements;
            fd.groups = &grp, fd.n_groups = 1, fd.order = d.order;
            if (pn_fem_create(&fd, &m, why, sizeof why) == PN_OK) created++;
            pn_fem_destroy(m);
            pn_fem_mesh_data_free(&d, NULL);
        } else
            PN_CHECK(d.nodes == NULL && d.elements == NULL && d.element_tags == NULL);
    }
    printf("    [fem_loaders] 100000 mutated files: %d parsed, %d of those made a mesh, the rest refused\n", ok_parse, created);
}

/* A malformed mesh file: PN_ERROR_FORMAT's sentence fits a mesh (not "unknown model format
   version", as it said for every model and mesh error), and why names the line and the field.
   Empty input given as NULL (length 0, which the loaders allow) is refused the same way
   (it computed NULL + 0, undefined in C: UBSan, make test-sanitize). */
PN_TEST(fem_loader_errors) {
    static const char bad_count[] = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\nthree\n$EndNodes\n";
    const char *s = pn_result_string(PN_ERROR_FORMAT);
    pn_fem_mesh_data d;
    char why[256];
    PN_CHECK(strstr(s, "mesh") != NULL && strstr(s, "model") != NULL && strstr(s, "unknown") == NULL);
    why[0] = 0;
    PN_CHECK(pn_fem_parse_msh(bad_count, sizeof bad_count - 1, 2, NULL, &d, why, sizeof why) == PN_ERROR_FORMAT);
    if (!strstr(why, "line 5") || !strstr(why, "node count")) {
        fprintf(stderr, "  fem_loader_errors: '%s' does not name line 5 and the node count\n", why);
        PN_CHECK(0);
    }
    why[0] = 0;
    PN_CHECK(pn_fem_parse_msh(NULL, 0, 3, NULL, &d, why, sizeof why) == PN_ERROR_FORMAT && why[0] && d.nodes == NULL);
    why[0] = 0;
    PN_CHECK(pn_fem_parse_tetgen(t_fem_node, sizeof t_fem_node - 1, NULL, 0, NULL, &d, why, sizeof why) == PN_ERROR_FORMAT);
    PN_CHECK(strstr(why, ".ele line 1") != NULL && d.nodes == NULL && d.elements == NULL);
    why[0] = 0;
    PN_CHECK(pn_fem_parse_tetgen(NULL, 0, t_fem_ele, sizeof t_fem_ele - 1, NULL, &d, why, sizeof why) == PN_ERROR_FORMAT);
    PN_CHECK(strstr(why, ".node line 1") != NULL && d.nodes == NULL);
}

static const pn_test_case pn_tests_fem[] = {
    {"fem_loaders", fem_loaders},
    {"fem_loader_errors", fem_loader_errors},
    {"fem_grid_mesh", fem_grid_mesh},
    {"fem_patch", fem_patch},
    {"fem_barrier_fd", fem_barrier_fd},
    {"fem_objective_fd", fem_objective_fd},
    {"fem_ccd", fem_ccd},
    {"fem_line_search", fem_line_search},
    {"fem_newton_tail", fem_newton_tail},
    {"fem_cantilever", fem_cantilever},
    {"fem_quadratic_mesh", fem_quadratic_mesh},
    {"fem_cantilever_3d", fem_cantilever_3d},
    {"fem_explicit_implicit", fem_explicit_implicit},
    {"fem_pcg", fem_pcg},
    {"fem_friction_slide", fem_friction_slide},
    {"fem_pair_distance_fd", fem_pair_distance_fd},
    {"fem_pair_barrier_ccd", fem_pair_barrier_ccd},
    {"fem_self_contact_3d", fem_self_contact_3d},
    {"fem_permanent_set", fem_permanent_set},
    {"fem_spin_release", fem_spin_release},
    {"fem_threads_same_bits", fem_threads_same_bits},
    {"fem_self_contact", fem_self_contact},
    {"fem_bad_mesh", fem_bad_mesh},
    {"fem_nonfinite_state", fem_nonfinite_state},
    {"fem_obstacle_inside_element", fem_obstacle_inside_element},
};
