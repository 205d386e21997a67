/* test_couple.c - MPM-FEM coupling (plastinet_mpm.h >>couple): momentum across the
   interface, a body at rest on a sand bed, explicit against implicit, 1 and 2 threads, bad
   input. The interface's own barrier and CCD are checked pair by pair in test_fem.c
   (fem_pair_barrier_ccd). Included by test_main.c. */

/* a sand box (StVK-Hencky + Drucker-Prager, E 1e6 Pa unless E_sand) and an elastic block
   mesh (Neo-Hookean, E_block, 3000 kg/m^3) above or beside it, coupled */
typedef struct t_cpl {
    pn_mpm_world *w;
    pn_fem_mesh *m;
    pn_coupled *c;
    pn_real *X;
    int *el;
    size_t nn, ne;
} t_cpl;

typedef struct t_cpl_scene {
    int dim, res, cells[3], order; /* order: the block's elements (0, 1: linear; 2: quadratic) */
    double gy, sand_lo[3], sand_size[3], block_lo[3], block_size[3], block_v[3], E_sand, E_block, friction;
    int elastic_sand;            /* the sand without its yield (no Drucker-Prager)          */
    pn_boundary boundary;
    pn_allocator allocator;      /* the world's and the mesh's (zero: malloc)               */
} t_cpl_scene;

/* an allocator that counts its calls */
static void *t_cpl_alloc(size_t n, void *user) {
    ++*(long *)user;
    return malloc(n);
}
static void t_cpl_release(void *p, void *user) {
    (void)user;
    free(p);
}

static void t_cpl_free(t_cpl *t) {
    pn_coupled_destroy(t->c);
    pn_fem_destroy(t->m);
    pn_mpm_destroy(t->w);
    free(t->X);
    free(t->el);
    memset(t, 0, sizeof *t);
}

static int t_cpl_make(t_cpl *t, const t_cpl_scene *sc) {
    pn_mpm_desc wd;
    pn_mpm_fill_desc f;
    pn_material_desc md;
    pn_material sand;
    pn_group fg;
    pn_fem_desc fd;
    pn_fem_grid g;
    pn_coupled_desc cd;
    char why[256] = "";
    char msg[256];
    size_t n = 0, k;
    int d = sc->dim, i;
    memset(t, 0, sizeof *t);
    memset(&wd, 0, sizeof wd);
    wd.dim = d;
    for (i = 0; i < d; ++i) wd.res[i] = sc->res;
    wd.dx_m = (pn_real)(1.0 / sc->res);
    wd.gravity[1] = (pn_real)sc->gy;
    wd.boundary = sc->boundary;
    wd.friction = (pn_real)0.5;
    wd.wall_cells = 3;
    wd.allocator = sc->allocator;
    memset(&f, 0, sizeof f);
    f.shape = PN_MPM_FILL_BOX;
    for (i = 0; i < d; ++i)
        f.center_m[i] = (pn_real)(sc->sand_lo[i] + sc->sand_size[i] / 2), f.half_extent_m[i] = (pn_real)(sc->sand_size[i] / 2);
    if (pn_mpm_fill_count(&wd, &f, &n, why, sizeof why) != PN_OK) return 0;
    wd.max_particles = n;
    if (pn_mpm_create(&wd, &t->w, why, sizeof why) != PN_OK) return 0;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_STVK_HENCKY, md.plastic = sc->elastic_sand ? PN_PLASTIC_NONE : PN_PLASTIC_DRUCKER_PRAGER;
    md.youngs_modulus_pa = (pn_real)(sc->E_sand > 0 ? sc->E_sand : 1e6), md.poisson_ratio = (pn_real)0.3;
    md.friction_angle_deg = 30;
    if (pn_material_init(&sand, &md, why, sizeof why) != PN_OK) return 0;
    f.group = pn_mpm_add_group(t->w, &sand, 1600);
    if (pn_mpm_fill(t->w, &f, NULL) != PN_OK) return 0;
    memset(&g, 0, sizeof g);
    g.dim = d;
    for (i = 0; i < d; ++i) g.cells[i] = sc->cells[i], g.lo_m[i] = (pn_real)sc->block_lo[i], g.size_m[i] = (pn_real)sc->block_size[i];
    if (pn_fem_grid_mesh(&g, NULL, NULL, &t->nn, &t->ne) != PN_OK) return 0;
    t->X = (pn_real *)malloc(sizeof(pn_real) * t->nn * (size_t)d);
    t->el = (int *)malloc(sizeof(int) * t->ne * (size_t)(d + 1));
    if (!t->X || !t->el || pn_fem_grid_mesh(&g, t->X, t->el, &t->nn, &t->ne) != PN_OK) return 0;
    if (sc->order == 2 && !t_fem_quadratic(d, &t->X, &t->el, &t->nn, t->ne)) return 0; /* test_fem.c */
    memset(&fg, 0, sizeof fg);
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_NEO_HOOKEAN, md.youngs_modulus_pa = (pn_real)sc->E_block, md.poisson_ratio = (pn_real)0.3;
    if (pn_material_init(&fg.material, &md, why, sizeof why) != PN_OK) return 0;
    fg.density_kg_m3 = 3000;
    memset(&fd, 0, sizeof fd);
    fd.dim = d, fd.n_nodes = t->nn, fd.n_elements = t->ne, fd.rest_m = t->X, fd.elements = t->el;
    fd.groups = &fg, fd.n_groups = 1, fd.gravity[1] = (pn_real)sc->gy, fd.allocator = sc->allocator, fd.order = sc->order;
    if (pn_fem_create(&fd, &t->m, msg, sizeof msg) != PN_OK) return 0;
    for (k = 0; k < t->nn; ++k)
        for (i = 0; i < d; ++i) t->m->v[k * (size_t)d + (size_t)i] = (pn_real)sc->block_v[i];
    memset(&cd, 0, sizeof cd);
    cd.friction = (pn_real)sc->friction;
    if (pn_coupled_create(t->w, t->m, &cd, &t->c, msg, sizeof msg) != PN_OK) {
        fprintf(stderr, "  t_cpl_make: %s\n", msg);
        return 0;
    }
    return 1;
}

/* total momentum of the particles and the mesh's nodes along each axis */
static void t_cpl_momentum(const t_cpl *t, double *p) {
    int d = t->w->dim, i;
    size_t k;
    for (i = 0; i < 3; ++i) p[i] = 0;
    for (k = 0; k < t->w->n; ++k)
        for (i = 0; i < d; ++i) p[i] += (double)t->w->mass[k] * (double)t->w->v[k * (size_t)d + (size_t)i];
    for (k = 0; k < t->nn; ++k)
        for (i = 0; i < d; ++i) p[i] += (double)t->m->mass[k] * (double)t->m->v[k * (size_t)d + (size_t)i];
}

static double t_cpl_block_mean(const t_cpl *t, int axis, int vel) {
    double s = 0;
    size_t k;
    for (k = 0; k < t->nn; ++k) s += (double)(vel ? t->m->v : t->m->x)[k * (size_t)t->w->dim + (size_t)axis];
    return s / (double)t->nn;
}

/* a block thrown sideways into a floating sand box, no gravity, walls far: the barrier's and
   friction's forces are equal and opposite, so the total momentum stays what it was (the
   implicit step to its Newton tolerance) while the block's own changes */
static t_cpl_scene t_cpl_collision(int dim) {
    t_cpl_scene sc;
    int i;
    memset(&sc, 0, sizeof sc);
    sc.dim = dim, sc.res = dim == 2 ? 32 : 16, sc.gy = 0, sc.E_block = 1e8, sc.friction = 0.3;
    sc.boundary = PN_BOUNDARY_SEPARATE;
    for (i = 0; i < dim; ++i) {
        sc.sand_lo[i] = 0.4, sc.sand_size[i] = 0.25;
        sc.block_lo[i] = 0.45, sc.block_size[i] = 0.1, sc.cells[i] = 2;
    }
    sc.block_lo[0] = 0.4 - 0.1 - 0.02, sc.block_lo[1] = 0.5; /* left of the sand, off-centre: it spins too */
    sc.block_v[0] = 2, sc.block_v[1] = -0.5;
    return sc;
}

PN_TEST(couple_momentum) {
    int dim, implicit; /* 0: explicit; 1: implicit, backward Euler; 2: the trapezoidal rule; 3: 1 with
                          quadratic elements */
    static const char *const names[4] = {"explicit dt 1e-5", "implicit dt 1e-3", "implicit dt 1e-3, theta 0.5",
                                         "implicit dt 1e-3, quadratic elements"};
    for (dim = 2; dim <= 3; ++dim)
        for (implicit = 0; implicit <= 3; ++implicit) {
            t_cpl t;
            t_cpl_scene sc = t_cpl_collision(dim);
            if (implicit == 3 && dim == 3 && !pn_test_full()) continue; /* 3D quadratic: make test-all */
            if (implicit == 3) sc.order = 2;
            double p0[3], p1[3], b0, b1, scale, err = 0, dmin = 1e30;
            int s, nsteps = implicit ? 40 : 4000, i, contact = 0;
            pn_coupled_implicit_desc od;
            if (!t_cpl_make(&t, &sc)) {
                PN_CHECK(0);
                t_cpl_free(&t);
                continue;
            }
            memset(&od, 0, sizeof od);
            od.mpm.newton_tol = (pn_real)1e-9, od.mpm.cg_rel_tol = (pn_real)1e-10, od.mpm.cg_max = 5000;
            od.theta = (pn_real)(implicit == 2 ? 0.5 : 0);
            t_cpl_momentum(&t, p0);
            b0 = t_cpl_block_mean(&t, 0, 1);
            scale = fabs(p0[0]) + fabs(p0[1]);
            for (s = 0; s < nsteps; ++s) {
                pn_coupled_stats st;
                pn_result r = implicit ? pn_coupled_step_implicit(t.c, 1e-3, &od, &st) : pn_coupled_step_explicit(t.c, 1e-5, &st);
                PN_CHECK(r == PN_OK);
                if (r != PN_OK) {
                    fprintf(stderr, "  %s\n", pn_coupled_error(t.c));
                    break;
                }
                contact += st.pairs > 0;
                if (st.pairs) dmin = PN__MIN(dmin, (double)st.min_distance_m);
            }
            t_cpl_momentum(&t, p1);
            b1 = t_cpl_block_mean(&t, 0, 1);
            for (i = 0; i < dim; ++i) err = PN__MAX(err, fabs(p1[i] - p0[i]) / scale);
            PN_CHECK(contact > 0);
            PN_CHECK(b1 < 0.8 * b0); /* the block was slowed: the coupling acted */
            PN_CHECK(err <= (implicit ? 1e-6 : 1e-9));
            PN_CHECK(dmin > 0);
            PN_REPORT("%dD %s: block's x velocity %.3f -> %.3f m/s, total momentum changed by %.2g of it; %d steps in "
                      "contact, smallest distance %.3g dhat", dim, names[implicit], b0, b1,
                      err, contact, dmin / (double)t.c->dhat);
            t_cpl_free(&t);
        }
}

/* the resting-block scene: a 0.2 x 0.1 m block (3000 kg/m^3, 8 x 4 cells) over a sand bed at
   res 32, at the gap where the barrier's law carries its weight *W (N per metre) shared by the
   *under top particles beneath it (the barrier's law solved by bisection); *ytop: the top
   row's height, *gap: the gap */
static void t_cpl_rest_scene(t_cpl_scene *sc, double *W, int *under, double *ytop, double *gap) {
    double dx = 1.0 / 32, lo = 0, hi = 1, kap, dh = dx / 4;
    int it;
    size_t k;
    memset(sc, 0, sizeof *sc);
    sc->dim = 2, sc->res = 32, sc->gy = -9.81, sc->E_sand = 1e7, sc->E_block = 1e9, sc->boundary = PN_BOUNDARY_SEPARATE;
    sc->sand_lo[0] = 3 * dx, sc->sand_size[0] = 1 - 6 * dx, sc->sand_lo[1] = 3 * dx, sc->sand_size[1] = 0.25;
    sc->block_lo[0] = 0.4, sc->block_size[0] = 0.2, sc->block_size[1] = 0.1, sc->cells[0] = 8, sc->cells[1] = 4;
    sc->friction = 0.5;
    *ytop = 3 * dx + 0.25 - dx / 4; /* the top row of particles (2 per cell per axis) */
    for (k = 0, *under = 0; k < 64; ++k) { /* the top row's particles under the block: x in [0.4, 0.6] */
        double x = 3 * dx + dx / 4 + (double)k * dx / 2;
        *under += x >= 0.4 && x <= 0.6;
    }
    *W = 3000 * 9.81 * 0.2 * 0.1;  /* the block's weight (N per metre) */
    kap = 0.1 * 1e7 * (dx / 2) / dh; /* kappa_p = k a_p / dhat, k = 0.1 E, a_p = V_p^(1/2) */
    for (it = 0; it < 100; ++it) {   /* kappa_p |b'(x dhat)| = W / under, by bisection on x */
        double x = (lo + hi) / 2, d = x * dh, b1 = -2 * (d - dh) * log(d / dh) - (d - dh) * (d - dh) / d;
        if (kap * -b1 > *W / *under) lo = x;
        else hi = x;
    }
    *gap = (lo + hi) / 2 * dh;
    sc->block_lo[1] = *ytop + *gap;
}

/* a block laid on a sand bed under gravity stays where it is. It starts at the gap where the
   barrier carries its weight (the barrier's law solved for the weight shared by the top
   particles under it), so nothing should move but the bed's own elastic settling under both
   weights (1e-4 of its height): at rest, its drift a small fraction of dhat. */
PN_TEST(couple_rest) {
    int implicit;
    for (implicit = 0; implicit <= 1; ++implicit) {
        t_cpl t;
        t_cpl_scene sc;
        double dx = 1.0 / 32, ytop = 0, y0, y1, vmax = 0, gap, W, dh = dx / 4;
        int s, nsteps = implicit ? 200 : 5000, under = 0;
        long allocs = 0, warm = 0;
        t_cpl_rest_scene(&sc, &W, &under, &ytop, &gap);
        sc.allocator.alloc = t_cpl_alloc, sc.allocator.free = t_cpl_release, sc.allocator.user = &allocs;
        if (!t_cpl_make(&t, &sc)) {
            PN_CHECK(0);
            t_cpl_free(&t);
            continue;
        }
        y0 = t_cpl_block_mean(&t, 1, 0);
        for (s = 0; s < nsteps; ++s) {
            pn_coupled_stats st;
            pn_result r = implicit ? pn_coupled_step_implicit(t.c, 1e-3, NULL, &st) : pn_coupled_step_explicit(t.c, 1e-5, &st);
            PN_CHECK(r == PN_OK && st.min_distance_m > 0);
            if (r != PN_OK) {
                fprintf(stderr, "  %s\n", pn_coupled_error(t.c));
                break;
            }
            vmax = PN__MAX(vmax, fabs(t_cpl_block_mean(&t, 1, 1)));
            if (s == nsteps / 2 - 1) warm = allocs;
        }
        y1 = t_cpl_block_mean(&t, 1, 0);
        PN_CHECK(fabs(y1 - y0) < 0.1 * dh);
        PN_CHECK(allocs == warm && warm > 0); /* no allocation in a step once warm */
        PN_CHECK(vmax < 0.05);
        PN_REPORT("%s: resting %.3f dhat above the bed, over %.2f s the block moved %.3g dhat, largest speed %.3g m/s (free "
                  "fall: %.2f m/s); %ld allocations in the second half's %d steps", implicit ? "implicit dt 1e-3" : "explicit dt 1e-5",
                  gap / dh, nsteps * (implicit ? 1e-3 : 1e-5), (y1 - y0) / dh, vmax, 9.81 * nsteps * (implicit ? 1e-3 : 1e-5),
                  allocs - warm, nsteps - nsteps / 2);
        t_cpl_free(&t);
    }
}

/* The interface's pairs as docs/method.md defines them, from the positions alone: every active
   particle against every boundary edge of the mesh (an edge of one triangle only), d its
   distance to the edge's closest point, a pair when d < dhat pushing the mesh with
   kappa |b'(d)| away from the particle. Counted: the pairs, the particles in one, the pairs
   beyond each particle's nearest (extra), those of them at the same vertex as another pair of
   the particle (dup: the same point-vertex term twice); the force on the mesh along y, and the
   part the extra pairs carry. */
typedef struct t_cpl_pairs {
    int pairs, particles, extra, dup;
    double fy, fy_extra;
} t_cpl_pairs;

static t_cpl_pairs t_cpl_count_pairs(const t_cpl *t, double dhat, double kap) {
    t_cpl_pairs r;
    int be[512], nb = 0, e, f, j, a;
    size_t p;
    memset(&r, 0, sizeof r);
    for (e = 0; e < 3 * (int)t->ne; ++e) { /* triangle e / 3, edge e % 3: boundary when no other has it */
        int u = t->el[e / 3 * 3 + e % 3], v = t->el[e / 3 * 3 + (e % 3 + 1) % 3], shared = 0;
        for (f = 0; f < 3 * (int)t->ne && !shared; ++f) {
            int u2 = t->el[f / 3 * 3 + f % 3], v2 = t->el[f / 3 * 3 + (f % 3 + 1) % 3];
            shared = f != e && ((u2 == u && v2 == v) || (u2 == v && v2 == u));
        }
        if (!shared && nb < 256) be[2 * nb] = u, be[2 * nb + 1] = v, nb++;
    }
    for (p = 0; p < t->w->n; ++p) {
        const pn_real *y = t->w->x + 2 * p;
        double dist[8], fy[8], dmin = 1e30, fsum = 0;
        int vert[8], n = 0, near = 0;
        if (!t->w->active[p]) continue;
        for (e = 0; e < nb && n < 8; ++e) {
            const pn_real *x0 = t->m->x + 2 * be[2 * e], *x1 = t->m->x + 2 * be[2 * e + 1];
            double l2 = 0, s = 0, c[2], d = 0, b1;
            for (a = 0; a < 2; ++a) l2 += (x1[a] - x0[a]) * (x1[a] - x0[a]), s += (y[a] - x0[a]) * (x1[a] - x0[a]);
            s = s / l2 < 0 ? 0 : s / l2 > 1 ? 1 : s / l2;
            for (a = 0; a < 2; ++a) c[a] = x0[a] + s * (x1[a] - x0[a]), d += (y[a] - c[a]) * (y[a] - c[a]);
            d = sqrt(d);
            if (!(d < dhat)) continue;
            b1 = -2 * (d - dhat) * log(d / dhat) - (d - dhat) * (d - dhat) / d; /* b'(d) < 0 */
            dist[n] = d, fy[n] = kap * b1 * (y[1] - c[1]) / d, vert[n] = s == 0 ? be[2 * e] : s == 1 ? be[2 * e + 1] : -1;
            n++;
        }
        if (!n) continue;
        r.pairs += n, r.particles++, r.extra += n - 1;
        for (j = 0; j < n; ++j) {
            if (dist[j] < dmin) dmin = dist[j], near = j;
            fsum += fy[j];
            for (f = 0; f < j; ++f) r.dup += vert[j] >= 0 && vert[f] == vert[j];
        }
        r.fy += fsum, r.fy_extra += fsum - fy[near];
    }
    return r;
}

/* Force balance at the interface on the resting-block scene (no friction, Newton to 1e-9):
   (a) the pairs the step reports are the (particle, boundary edge) pairs within dhat counted
   from the positions alone, and their number is what the scene's geometry gives: the 12 top
   particles under the block, each against the edge above it, plus one more pair for each
   particle within sqrt(dhat^2 - gap^2) across of a vertex of the block's bottom: the 2 just
   outside the block's corners (against the bottom edge and the side edge: the same
   point-vertex term twice) and 2 near interior vertices (the edge above them, and the next
   edge's end); (b) the barrier's force on the block summed over them is, in every step, its
   momentum balance M dv/dt + W (implicit: the forces at the step's end; explicit: those at
   its start), so where it differs from the weight W = rho g V, the block is accelerating: in
   the first implicit steps it sinks into the bed's settling and the sum is 0.57-0.88 W,
   and once settled it is W (explicit, undamped, it keeps swinging); the extra pairs carry a few percent of it. */
PN_TEST(couple_force_balance) {
    int implicit;
    for (implicit = 1; implicit >= 0; --implicit) {
        t_cpl t;
        t_cpl_scene sc;
        pn_coupled_implicit_desc od;
        double dx = 1.0 / 32, dh = dx / 4, ytop, gap, W, M = 0, kap = 0.1 * 1e7 * (dx / 2) / dh, reach, dt = implicit ? 1e-3 : 1e-5;
        double bal = 0, settled = 0, worst = 0, extra_share = 0;
        int under, s, nsteps = implicit ? 200 : 3000, nset = 0, e_particles = 0, e_pairs = 0, e_dup = 0, same = 1, j;
        size_t k;
        t_cpl_pairs pr;
        memset(&pr, 0, sizeof pr);
        t_cpl_rest_scene(&sc, &W, &under, &ytop, &gap);
        sc.friction = 0; /* friction's force along a tilted normal would enter the balance */
        memset(&od, 0, sizeof od);
        od.mpm.newton_tol = (pn_real)1e-9, od.mpm.cg_rel_tol = (pn_real)1e-10, od.mpm.cg_max = 5000;
        /* the expected pairs: the top row's x against the bottom's vertices 0.4 + 0.025 i */
        reach = sqrt(dh * dh - gap * gap);
        for (j = 0; j < 64; ++j) {
            double x = 3 * dx + dx / 4 + j * dx / 2, v = 0.4 + 0.025 * floor((x - 0.4) / 0.025 + 0.5);
            if (x < 0.4 - reach || x > 0.6 + reach) continue;
            e_particles++, e_pairs++;
            if (fabs(x - v) < reach) e_pairs++, e_dup += x < 0.4 || x > 0.6;
        }
        if (!t_cpl_make(&t, &sc)) {
            PN_CHECK(0);
            t_cpl_free(&t);
            continue;
        }
        for (k = 0; k < t.nn; ++k) M += (double)t.m->mass[k];
        PN_CHECK(fabs(M * 9.81 - W) < 1e-9 * W); /* the mesh's mass is the block's */
        for (s = 0; s < nsteps; ++s) {
            pn_coupled_stats st;
            double p0 = 0, p1 = 0, fb;
            pn_result r;
            t_cpl_pairs before = t_cpl_count_pairs(&t, dh, kap);
            for (k = 0; k < t.nn; ++k) p0 += (double)t.m->mass[k] * (double)t.m->v[2 * k + 1];
            r = implicit ? pn_coupled_step_implicit(t.c, (pn_real)dt, &od, &st) : pn_coupled_step_explicit(t.c, (pn_real)dt, &st);
            PN_CHECK(r == PN_OK);
            if (r != PN_OK) {
                fprintf(stderr, "  %s\n", pn_coupled_error(t.c));
                break;
            }
            for (k = 0; k < t.nn; ++k) p1 += (double)t.m->mass[k] * (double)t.m->v[2 * k + 1];
            pr = t_cpl_count_pairs(&t, dh, kap);
            same &= st.pairs == (size_t)pr.pairs;
            fb = implicit ? pr.fy : before.fy; /* backward Euler: the end's forces; explicit: the start's */
            bal = PN__MAX(bal, fabs(fb - ((p1 - p0) / dt + W)) / W);
            worst = PN__MAX(worst, fabs(fb - W) / W);
            if (s >= nsteps - nsteps / 5) settled += pr.fy / W, extra_share += pr.fy_extra / W, nset++;
        }
        settled /= nset, extra_share /= nset;
        PN_CHECK(same);                                   /* the reported count is the pairs' */
        PN_CHECK(pr.particles == e_particles && pr.pairs == e_pairs && pr.extra == e_pairs - e_particles);
        PN_CHECK(pr.dup == e_dup && e_dup == 2);          /* the corners' two terms at one vertex */
        PN_CHECK(bal < (implicit ? 1e-5 : 1e-9));         /* the sum is the block's momentum balance */
        PN_CHECK(worst > 0.1);                            /* ...which is not the weight while it moves */
        if (implicit) PN_CHECK(fabs(settled - 1) < 2e-3); /* settled: the weight */
        PN_CHECK(extra_share > 0.01 && extra_share < 0.1);
        PN_REPORT("%s: %d pairs within dhat over %d particles (expected %d over %d: %d extra near vertices, %d of them the "
                  "same point-vertex term twice); the barrier's force on the block against its momentum balance: within "
                  "%.2g W in every step, against the weight W: up to %.2f W off while the block moves, %.4f W over the last "
                  "fifth of the run; the extra pairs carry %.3f W", implicit ? "implicit dt 1e-3" : "explicit dt 1e-5",
                  pr.pairs, pr.particles, e_pairs, e_particles, e_pairs - e_particles, e_dup, bal, worst, settled, extra_share);
        t_cpl_free(&t);
    }
}

/* a block dropped onto a sand bed, explicit at 1e-5 s against implicit at 1e-5 s (Newton
   to 1e-8), 1e-4 s and 1e-3 s: both integrators discretize the same interface and the
   same MPM, so at the same step they agree to the solver's tolerance, and implicit Euler's
   O(dt) error shrinks with its step; the trapezoidal rule (theta 0.5), which does not damp
   the rebound, is closer at 1e-3 s */
PN_TEST(couple_explicit_implicit) {
    t_cpl_scene sc;
    double dx = 1.0 / 32, T = 0.02, err[7] = {0, 0, 0, 0, 0, 0, 0}, perr[7] = {0, 0, 0, 0, 0, 0, 0}, *yb[7], *xp = NULL;
    double fdiff = 0, fpdiff = 0, *xf = NULL;
    static const double dts[7] = {1e-5, 1e-5, 1e-4, 1e-3, 1e-4, 1e-3, 1e-4};
    int run, n_out = 4;
    size_t np = 0;
    memset(&sc, 0, sizeof sc);
    sc.dim = 2, sc.res = 32, sc.gy = -9.81, sc.E_sand = 1e7, sc.E_block = 1e9, sc.boundary = PN_BOUNDARY_SEPARATE;
    sc.sand_lo[0] = 3 * dx, sc.sand_size[0] = 1 - 6 * dx, sc.sand_lo[1] = 3 * dx, sc.sand_size[1] = 0.25;
    sc.block_lo[0] = 0.4, sc.block_size[0] = 0.2, sc.block_size[1] = 0.1, sc.cells[0] = 8, sc.cells[1] = 4;
    sc.block_lo[1] = 3 * dx + 0.25 + 0.3 * dx, sc.block_v[1] = -1.5, sc.friction = 0.5; /* just beyond dhat */
    for (run = 0; run < 7; ++run) yb[run] = (double *)calloc((size_t)n_out, sizeof(double));
    for (run = 0; run < 7; ++run) {
        t_cpl t;
        int s, nsteps = (int)(T / dts[run] + 0.5), every = nsteps / n_out;
        size_t k;
        pn_coupled_implicit_desc od;
        memset(&od, 0, sizeof od);
        if (run == 1) od.mpm.newton_tol = (pn_real)1e-8;
        if (run == 4 || run == 5) od.theta = (pn_real)0.5; /* the trapezoidal rule */
        if (run == 6) od.mpm.cg_forcing_max = (pn_real)0.5; /* run 2 with Eisenstat-Walker forcing */
        if (!t_cpl_make(&t, &sc)) {
            PN_CHECK(0);
            t_cpl_free(&t);
            continue;
        }
        for (s = 0; s < nsteps; ++s) {
            pn_result r = run ? pn_coupled_step_implicit(t.c, dts[run], &od, NULL) : pn_coupled_step_explicit(t.c, dts[run], NULL);
            PN_CHECK(r == PN_OK);
            if (r != PN_OK) {
                fprintf(stderr, "  %s\n", pn_coupled_error(t.c));
                break;
            }
            if ((s + 1) % every == 0 && (s + 1) / every <= n_out) yb[run][(s + 1) / every - 1] = t_cpl_block_mean(&t, 1, 0);
        }
        if (run == 0) {
            np = t.w->n;
            xp = (double *)malloc(sizeof(double) * np * 2);
            for (k = 0; k < 2 * np; ++k) xp[k] = (double)t.w->x[k];
        } else {
            for (s = 0; s < n_out; ++s) err[run] = PN__MAX(err[run], fabs(yb[run][s] - yb[0][s]));
            for (k = 0; k < np; ++k)
                perr[run] += sqrt(pow((double)t.w->x[2 * k] - xp[2 * k], 2) + pow((double)t.w->x[2 * k + 1] - xp[2 * k + 1], 2)) / (double)np;
            if (run == 2 && (xf = (double *)malloc(sizeof(double) * np * 2)) != NULL)
                for (k = 0; k < 2 * np; ++k) xf[k] = (double)t.w->x[k];
            if (run == 6 && xf) {
                for (s = 0; s < n_out; ++s) fdiff = PN__MAX(fdiff, fabs(yb[6][s] - yb[2][s]));
                for (k = 0; k < 2 * np; ++k) fpdiff = PN__MAX(fpdiff, fabs((double)t.w->x[k] - xf[k]));
            }
        }
        t_cpl_free(&t);
    }
    PN_CHECK(err[1] < 0.02 * dx && perr[1] < 0.01 * dx); /* the same step: the same answer */
    PN_CHECK(err[2] < err[3] && perr[2] < perr[3]);     /* larger steps: further off */
    PN_CHECK(err[5] < err[3] && perr[5] < perr[3]);     /* the trapezoidal rule: closer at 1e-3 s */
    PN_CHECK(xf && fdiff < 1e-3 * dx && fpdiff < 1e-2 * dx); /* loose solves: the same answer */
    PN_REPORT("the block's height over %.2f s against explicit at 1e-5 s, implicit at 1e-5 s: within %.3g dx, 1e-4 s: %.3g "
              "dx, 1e-3 s: %.3g dx; the particles' mean distance at the end %.3g, %.3g, %.3g dx; the trapezoidal rule "
              "(theta 0.5) at 1e-4 s: %.3g dx (particles %.3g), 1e-3 s: %.3g dx (%.3g)", T, err[1] / dx,
              err[2] / dx, err[3] / dx, perr[1] / dx, perr[2] / dx, perr[3] / dx, err[4] / dx, perr[4] / dx, err[5] / dx,
              perr[5] / dx);
    PN_REPORT("with Eisenstat-Walker forcing (cg_forcing_max 0.5) at 1e-4 s: the block within %.3g dx of the default "
              "solve's, every particle within %.3g dx", fdiff / dx, fpdiff / dx);
    for (run = 0; run < 7; ++run) free(yb[run]);
    free(xp), free(xf);
}

/* the collision scene stepped on 1 and 2 threads: the same bits (explicit, implicit with
   every other step the trapezoidal rule, and forcing on half the steps) */
PN_TEST(couple_threads_identical) {
#ifdef _OPENMP
    int implicit, t, dim;
    for (dim = 2; dim <= 3; ++dim)
        for (implicit = 0; implicit <= 1; ++implicit) {
            pn_real *keep = NULL;
            size_t bytes = 0, fbytes = 0;
            int same = 0, contact = 0;
            for (t = 1; t <= 2; ++t) {
                t_cpl c;
                t_cpl_scene sc = t_cpl_collision(dim);
                int s;
                contact = 0;
                sc.block_lo[0] += 0.016; /* 4 mm from the sand: in contact within 2 ms */
                if (!t_cpl_make(&c, &sc)) {
                    PN_CHECK(0);
                    t_cpl_free(&c);
                    break;
                }
                c.w->desc.parallel_min_particles = 1; /* this small world on 2 threads too */
                omp_set_num_threads(t);
                for (s = 0; s < (implicit ? 8 : 600); ++s) {
                    pn_coupled_stats cs;
                    pn_coupled_implicit_desc od;
                    pn_result r;
                    memset(&od, 0, sizeof od);
                    od.theta = (pn_real)(s % 2 ? 0.5 : 1);
                    od.mpm.cg_forcing_max = (pn_real)(s % 4 >= 2 ? 0.5 : 0); /* and with forcing */
                    r = implicit ? pn_coupled_step_implicit(c.c, 1e-3, &od, &cs) : pn_coupled_step_explicit(c.c, 1e-5, &cs);
                    PN_CHECK(r == PN_OK);
                    if (r != PN_OK) break;
                    contact += cs.pairs > 0;
                }
                bytes = sizeof(pn_real) * c.w->n * (size_t)dim, fbytes = sizeof(pn_real) * c.nn * (size_t)dim;
                if (t == 1) {
                    keep = (pn_real *)malloc(2 * bytes + fbytes);
                    memcpy(keep, c.w->x, bytes), memcpy((char *)keep + bytes, c.w->v, bytes);
                    memcpy((char *)keep + 2 * bytes, c.m->x, fbytes);
                } else {
                    same = memcmp(keep, c.w->x, bytes) == 0 && memcmp((char *)keep + bytes, c.w->v, bytes) == 0 &&
                           memcmp((char *)keep + 2 * bytes, c.m->x, fbytes) == 0;
                    PN_CHECK(same && contact);
                    PN_REPORT("%dD %s: particles and mesh on 1 and 2 threads %s (%d steps in contact)", dim,
                              implicit ? "implicit" : "explicit", same ? "bitwise identical" : "DIFFER", contact);
                }
                t_cpl_free(&c);
            }
            free(keep);
            omp_set_num_threads(2);
        }
#else
    PN_CHECK(1); /* one thread only: nothing to compare */
#endif
}

/* bad input: refused with a message naming the culprit, and a failed step leaves both as
   they were */
PN_TEST(couple_bad_input) {
    t_cpl t;
    t_cpl_scene sc = t_cpl_collision(2);
    pn_coupled *c2 = NULL;
    pn_coupled_desc cd;
    char why[256];
    pn_real *keep;
    size_t bytes, fbytes;
    if (!t_cpl_make(&t, &sc)) {
        PN_CHECK(0);
        t_cpl_free(&t);
        return;
    }
    memset(&cd, 0, sizeof cd);
    cd.friction = (pn_real)NAN;
    PN_CHECK(pn_coupled_create(t.w, t.m, &cd, &c2, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && !c2 &&
             strstr(why, "friction"));
    cd.friction = 0, cd.contact_distance_m = -1;
    PN_CHECK(pn_coupled_create(t.w, t.m, &cd, &c2, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && !c2 &&
             strstr(why, "contact_distance_m"));
    PN_CHECK(pn_coupled_step_implicit(t.c, (pn_real)NAN, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT &&
             strstr(pn_coupled_error(t.c), "dt_s"));
    PN_CHECK(pn_coupled_step_explicit(t.c, -1, NULL) == PN_ERROR_INVALID_ARGUMENT);
    { /* the stress formulation does not couple; theta outside [0.5, 1] */
        pn_coupled_implicit_desc od;
        memset(&od, 0, sizeof od);
        od.mpm.formulation = PN_MPM_FORMULATION_STRESS;
        PN_CHECK(pn_coupled_step_implicit(t.c, 1e-3, &od, NULL) == PN_ERROR_UNSUPPORTED);
        od.mpm.formulation = PN_MPM_FORMULATION_ENERGY, od.theta = (pn_real)0.3;
        PN_CHECK(pn_coupled_step_implicit(t.c, 1e-3, &od, NULL) == PN_ERROR_INVALID_ARGUMENT &&
                 strstr(pn_coupled_error(t.c), "theta"));
        od.theta = (pn_real)NAN;
        PN_CHECK(pn_coupled_step_implicit(t.c, 1e-3, &od, NULL) == PN_ERROR_INVALID_ARGUMENT);
        od.theta = 0, od.mpm.cg_max = -1; /* a negative count: refused, not the default */
        PN_CHECK(pn_coupled_step_implicit(t.c, 1e-3, &od, NULL) == PN_ERROR_INVALID_ARGUMENT &&
                 strstr(pn_coupled_error(t.c), "cg_max"));
    }
    /* a step so large the block would pass through the sand: explicit refuses it (CCD), and
       both are unchanged, bit for bit */
    bytes = sizeof(pn_real) * t.w->n * 2, fbytes = sizeof(pn_real) * t.nn * 2;
    keep = (pn_real *)malloc(2 * bytes + 2 * fbytes);
    memcpy(keep, t.w->x, bytes), memcpy((char *)keep + bytes, t.w->v, bytes);
    memcpy((char *)keep + 2 * bytes, t.m->x, fbytes), memcpy((char *)keep + 2 * bytes + fbytes, t.m->v, fbytes);
    {
        size_t k;
        for (k = 0; k < t.nn; ++k) t.m->v[2 * k] = 400; /* 4 m in a 1e-2 s step */
        memcpy((char *)keep + 2 * bytes + fbytes, t.m->v, fbytes);
    }
    PN_CHECK(pn_coupled_step_explicit(t.c, 1e-2, NULL) != PN_OK);
    PN_CHECK(memcmp(keep, t.w->x, bytes) == 0 && memcmp((char *)keep + bytes, t.w->v, bytes) == 0);
    PN_CHECK(memcmp((char *)keep + 2 * bytes, t.m->x, fbytes) == 0 && memcmp((char *)keep + 2 * bytes + fbytes, t.m->v, fbytes) == 0);
    PN_CHECK(pn_coupled_error(t.c)[0] != 0);
    PN_REPORT("explicit step through the sand refused: %s", pn_coupled_error(t.c));
    /* a NaN velocity is refused, naming the node; both unchanged */
    t.m->v[3] = (pn_real)NAN;
    memcpy((char *)keep + 2 * bytes + fbytes, t.m->v, fbytes);
    PN_CHECK(pn_coupled_step_implicit(t.c, 1e-3, NULL, NULL) == PN_ERROR_NONFINITE &&
             strstr(pn_coupled_error(t.c), "node 1"));
    PN_CHECK(pn_coupled_step_explicit(t.c, 1e-5, NULL) == PN_ERROR_NONFINITE);
    PN_CHECK(memcmp(keep, t.w->x, bytes) == 0 && memcmp((char *)keep + bytes, t.w->v, bytes) == 0);
    PN_CHECK(memcmp((char *)keep + 2 * bytes, t.m->x, fbytes) == 0 && memcmp((char *)keep + 2 * bytes + fbytes, t.m->v, fbytes) == 0);
    PN_REPORT("a NaN mesh velocity refused: %s", pn_coupled_error(t.c));
    free(keep);
    pn_coupled_destroy(t.c);
    t.c = NULL;
    { /* a mesh outside the world's walls, or straddling one, is refused naming the node */
        size_t k;
        pn_real *x0 = (pn_real *)malloc(fbytes);
        memcpy(x0, t.m->x, fbytes);
        for (k = 0; k < t.nn; ++k) t.m->x[2 * k] += (pn_real)5; /* entirely outside */
        PN_CHECK(pn_coupled_create(t.w, t.m, NULL, &c2, why, sizeof why) == PN_ERROR_OUTSIDE_DOMAIN && !c2 &&
                 strstr(why, "node 0") && strstr(why, "walls"));
        memcpy(t.m->x, x0, fbytes);
        for (k = 0; k < t.nn; ++k) t.m->x[2 * k + 1] += (pn_real)0.4; /* its top beyond the upper wall */
        PN_CHECK(pn_coupled_create(t.w, t.m, NULL, &c2, why, sizeof why) == PN_ERROR_OUTSIDE_DOMAIN && !c2);
        PN_REPORT("a mesh straddling the wall: %s", why);
        memcpy(t.m->x, x0, fbytes);
        free(x0);
    }
    { /* a particle inside the mesh, and meshes of another dimension */
        size_t k;
        pn_real x0[2];
        memcpy(x0, t.w->x, sizeof x0);
        for (k = 0; k < 2; ++k) t.w->x[k] = t.m->x[k] + (pn_real)0.01; /* inside the block's first element */
        PN_CHECK(pn_coupled_create(t.w, t.m, NULL, &c2, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && !c2 &&
                 strstr(why, "particle 0"));
        PN_REPORT("a particle in the block: %s", why);
        memcpy(t.w->x, x0, sizeof x0);
    }
    {
        t_cpl t3;
        t_cpl_scene s3 = t_cpl_collision(3);
        if (t_cpl_make(&t3, &s3)) {
            PN_CHECK(pn_coupled_create(t.w, t3.m, NULL, &c2, why, sizeof why) == PN_ERROR_DIMENSION && !c2);
            PN_REPORT("a 2D world with a 3D mesh: %s", why);
        } else
            PN_CHECK(0);
        t_cpl_free(&t3);
    }
    t_cpl_free(&t);
}

/* Warm coupled steps allocate nothing: a block thrown into the sand (contact pairs appear
   and grow through the impact) with a counting allocator on the world and the mesh: after
   two steps none of the next thirty implicit ones, nor of 1,500 explicit ones at the coupled
   bound, calls it. 2D and 3D. */
PN_TEST(couple_warm_no_alloc) {
    int dim, implicit;
    for (dim = 2; dim <= 3; ++dim)
        for (implicit = 0; implicit <= 1; ++implicit) {
            t_cpl t;
            t_cpl_scene sc = t_cpl_collision(dim);
            long allocs = 0, warm = 0;
            size_t pairs = 0;
            int s, ok = 1, nsteps = implicit ? 32 : 1500; /* explicit: the block reaches the sand at ~0.01 s */
            sc.allocator.alloc = t_cpl_alloc, sc.allocator.free = t_cpl_release, sc.allocator.user = &allocs;
            if (!t_cpl_make(&t, &sc)) {
                PN_CHECK(0);
                t_cpl_free(&t);
                continue;
            }
            for (s = 0; s < nsteps && ok; ++s) {
                pn_coupled_stats st;
                pn_real dt = (pn_real)(implicit ? 1e-3 : 0);
                pn_result r;
                if (!implicit) pn_coupled_stable_dt(t.c, &dt);
                r = implicit ? pn_coupled_step_implicit(t.c, dt, NULL, &st) : pn_coupled_step_explicit(t.c, dt, &st);
                PN_CHECK(r == PN_OK);
                ok = r == PN_OK;
                if (!ok) fprintf(stderr, "  %s\n", pn_coupled_error(t.c));
                if (s == 1) warm = allocs;
                pairs = PN__MAX(pairs, st.pairs);
            }
            PN_CHECK(allocs == warm);
            PN_CHECK(pairs > 0);
            PN_REPORT("%dD %s: %ld allocations in %d warm steps (up to %lu pairs within dhat)", dim,
                      implicit ? "implicit dt 1e-3" : "explicit at the coupled bound", allocs - warm, nsteps - 2,
                      (unsigned long)pairs);
            t_cpl_free(&t);
        }
}

/* Newton's whole Hessian near the minimum (pn__cpl_newton: the particles', the elements' and
   the barrier pairs' Hessians unprojected once the steps are short). The collision scene at
   1e-3 s, 2D and 3D, the sand elastic and the interface without friction (smooth: no yield
   surface or friction kink within the differences): at every Newton iteration with pairs
   within dhat, the coupled Hessian times Newton's direction against the central differences
   of the coupled gradient along it (the trace callback probes the solver mid-solve and puts
   its gradient back bit for bit). The whole Hessian's iterations match; the projected ones
   (the first of each solve) are reported, off by the curvature projection adds. */
typedef struct t_cpl_probe {
    pn_coupled *c;
    double worst[2], most[2]; /* [exact, projected]: the largest and the smallest relative gap */
    int probes[2], restored;     /* restored: the solver's gradient put back bit for bit     */
} t_cpl_probe;

static void t_cpl_probe_trace(void *user, int solve, int it, pn_real E, pn_real res) {
    t_cpl_probe *f = (t_cpl_probe *)user;
    pn_coupled *c = f->c;
    pn__cpl *k = (pn__cpl *)c->impl;
    size_t nz = k->nz, q, any = 0;
    pn_real *Hd, *g0, *gp, *zp, dmax = 0, eps, Ed;
    double num = 0, den = 0;
    int side, ex = k->exact;
    (void)solve, (void)it, (void)E, (void)res;
    for (q = 0; q < k->nc; ++q) any += k->con[q];
    for (q = 0; q < nz; ++q) dmax = PN__MAX(dmax, PN__FABS(k->dir[q]));
    if (!any || !(dmax > 0)) return;
    Hd = (pn_real *)malloc(sizeof(pn_real) * 4 * nz);
    if (!Hd) return;
    g0 = Hd + nz, gp = g0 + nz, zp = gp + nz;
    memcpy(g0, k->g, sizeof(pn_real) * nz);
    pn__cpl_apply(c, k->dir, Hd);
    eps = (pn_real)1e-5 * c->dhat / (k->dt * dmax); /* the positions move 1e-5 dhat at most */
    for (side = 1; side >= -1; side -= 2) {
        for (q = 0; q < nz; ++q) zp[q] = k->z[q] + side * eps * k->dir[q];
        pn__cpl_positions(c, 1, zp, NULL);
        (void)pn__cpl_objective(c, zp, 1, &Ed);
        for (q = 0; q < nz; ++q) gp[q] = side > 0 ? k->g[q] : (gp[q] - k->g[q]) / (2 * eps);
    }
    for (q = 0; q < k->nv / (size_t)c->mpm->dim; ++q) pn__mpm_filter(c->mpm, q, gp + q * (size_t)c->mpm->dim);
    for (q = 0; q < nz; ++q) num += (double)((gp[q] - Hd[q]) * (gp[q] - Hd[q])), den += (double)(gp[q] * gp[q]);
    pn__cpl_positions(c, 1, k->z, NULL); /* the solver's state back: its gradient at z */
    (void)pn__cpl_objective(c, k->z, 1, &Ed);
    for (q = 0; q < nz; ++q) f->restored &= k->g[q] == g0[q];
    if (den > 0) {
        double gap = sqrt(num / den);
        f->worst[!ex] = PN__MAX(f->worst[!ex], gap);
        f->most[!ex] = f->probes[!ex] ? PN__MIN(f->most[!ex], gap) : gap;
        f->probes[!ex]++;
    }
    free(Hd);
}

PN_TEST(couple_exact_hessian) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        t_cpl t;
        t_cpl_scene sc = t_cpl_collision(dim);
        t_cpl_probe f;
        sc.friction = 0, sc.elastic_sand = 1; /* smooth: no yield surface or friction kink within the differences */
        pn_coupled_implicit_desc od;
        int s;
        if (!t_cpl_make(&t, &sc)) {
            PN_CHECK(0);
            t_cpl_free(&t);
            continue;
        }
        memset(&f, 0, sizeof f);
        f.c = t.c, f.restored = 1;
        memset(&od, 0, sizeof od);
        od.mpm.newton_tol = (pn_real)1e-7;
        od.mpm.trace = t_cpl_probe_trace, od.mpm.trace_user = &f;
        for (s = 0; s < (dim == 2 ? 40 : 25); ++s) {
            pn_result r = pn_coupled_step_implicit(t.c, 1e-3, &od, NULL);
            PN_CHECK(r == PN_OK);
            if (r != PN_OK) {
                fprintf(stderr, "  %s\n", pn_coupled_error(t.c));
                break;
            }
        }
        PN_REPORT("%dD: H d against the gradient's central differences along d: the whole Hessian within %.2e (%d "
                  "iterations in contact), projected %.2e to %.2e (%d)", dim, f.worst[0], f.probes[0], f.most[1],
                  f.worst[1], f.probes[1]);
        PN_CHECK(f.probes[0] >= 5 && f.restored);
        PN_CHECK_LE(f.worst[0], 1e-4);
        t_cpl_free(&t);
    }
}

static const pn_test_case pn_tests_couple[] = {
    {"couple_bad_input", couple_bad_input},
    {"couple_threads_identical", couple_threads_identical},
    {"couple_explicit_implicit", couple_explicit_implicit},
    {"couple_rest", couple_rest},
    {"couple_force_balance", couple_force_balance},
    {"couple_momentum", couple_momentum},
    {"couple_warm_no_alloc", couple_warm_no_alloc},
    {"couple_exact_hessian", couple_exact_hessian},
};
