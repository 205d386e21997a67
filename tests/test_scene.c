/* test_scene.c: what a new user touches first in plastinet_mpm.h: filling shapes with
   particles (counts and volumes against the shapes' exact volumes), the explicit step bound
   (against the largest stable step found by search), honest large steps (never PN_OK with
   material lost), a domain placed anywhere, stepping a frame, and errors that name their
   culprit. Uses t_mpm_* of test_mpm_world.c and t_pn_* of test_pnet_mlp.c. */

#define T_SC_PI 3.14159265358979323846

/* ---- helpers ------------------------------------------------------------------------------ */

/* a world on [origin, origin + res dx]^dim, walls 3 cells, friction 0.5 (separate) */
static pn_mpm_world *t_sc_world(int dim, int res, double dx, const double *origin, double gy, size_t cap) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    int i;
    memset(&wd, 0, sizeof wd);
    wd.dim = dim;
    for (i = 0; i < dim; ++i) {
        wd.res[i] = res;
        wd.origin_m[i] = origin ? origin[i] : 0;
    }
    wd.dx_m = dx;
    wd.gravity[1] = gy;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = 0.5;
    wd.max_particles = cap;
    wd.filter_time_s = 2e-3;
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK) return NULL;
    return w;
}

/* a group: 0 sand (DP 30 deg, E 1e7, 1600), 1 rubber (Neo-Hookean, E 1e5, 1100), 2 snow
   (Cam-Clay, E 1e6, 400), 3 steel-like metal (von Mises, E 1e9, 7800) */
static int t_sc_group(pn_mpm_world *w, int kind) {
    pn_material_desc d;
    pn_material m;
    static const double rho[4] = {1600, 1100, 400, 7800};
    memset(&d, 0, sizeof d);
    d.poisson_ratio = 0.3;
    if (kind == 0) d.plastic = PN_PLASTIC_DRUCKER_PRAGER, d.youngs_modulus_pa = 1e7, d.friction_angle_deg = 30;
    if (kind == 1) d.elastic = PN_ELASTIC_NEO_HOOKEAN, d.youngs_modulus_pa = 1e5;
    if (kind == 2)
        d.plastic = PN_PLASTIC_CAM_CLAY, d.youngs_modulus_pa = 1e6, d.friction_angle_deg = 45, d.camclay_beta = 0.3,
        d.camclay_xi = 3;
    if (kind == 3)
        d.plastic = PN_PLASTIC_VON_MISES, d.youngs_modulus_pa = 1e9, d.yield_stress_pa = 1e6,
        d.hardening_modulus_pa = 1e7;
    if (pn_material_init(&m, &d, NULL, 0) != PN_OK) return -1;
    return pn_mpm_add_group(w, &m, rho[kind]);
}

static double t_sc_volume(const pn_mpm_world *w) {
    double v = 0;
    size_t p;
    for (p = 0; p < w->n; ++p) v += w->active[p] ? (double)w->vol0[p] : 0;
    return v;
}

static double t_sc_ke(const pn_mpm_world *w) {
    double ke = 0;
    size_t p;
    int i;
    for (p = 0; p < w->n; ++p)
        for (i = 0; i < w->dim; ++i) ke += 0.5 * w->mass[p] * w->v[p * w->dim + i] * w->v[p * w->dim + i];
    return ke;
}

/* lattice points (i + 1/2) h of [c - a, c + a] on one axis: an independent count */
static long t_sc_points(double c, double a, double h) {
    return (long)floor((c + a) / h - 0.5) - (long)ceil((c - a) / h - 0.5) + 1;
}

/* ---- filling shapes ----------------------------------------------------------------------- */

PN_TEST(scene_fill_box) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_sc_world(dim, 32, 1.0 / 32, NULL, 0, 100000);
        pn_mpm_fill_desc f;
        size_t added = 0, counted = 0;
        double h = 1.0 / 64, c[3] = {0.5, 0.41, 0.37}, a[3] = {0.123, 0.2, 0.0771}, want = 1, vol = 1;
        int i, per;
        PN_CHECK(w != NULL);
        if (!w) continue;
        memset(&f, 0, sizeof f);
        f.group = t_sc_group(w, 0);
        f.shape = PN_MPM_FILL_BOX;
        for (i = 0; i < dim; ++i) {
            f.center_m[i] = c[i];
            f.half_extent_m[i] = a[i];
            want *= (double)t_sc_points(c[i], a[i], h);
        }
        PN_CHECK(pn_mpm_fill_count(&w->desc, &f, &counted, NULL, 0) == PN_OK);
        PN_CHECK(pn_mpm_fill(w, &f, &added) == PN_OK);
        PN_CHECK(added == (size_t)want && counted == added && w->n == added);
        PN_CHECK_NEAR(w->mass[0], pow(h, dim) * 1600, 1e-12);
        /* a box on the lattice's cell boundaries is sampled exactly, at any density */
        for (per = 1; per <= (dim == 2 ? 3 : 2); ++per) {
            pn_mpm_world *v = t_sc_world(dim, 32, 1.0 / 32, NULL, 0, 100000);
            memset(&f, 0, sizeof f);
            f.group = t_sc_group(v, 0);
            f.per_axis = per;
            vol = 1;
            for (i = 0; i < dim; ++i) {
                f.center_m[i] = 0.5;
                f.half_extent_m[i] = 0.25;
                vol *= 0.5;
            }
            if (v && pn_mpm_fill(v, &f, NULL) != PN_OK) PN_REPORT("%s", pn_mpm_error(v));
            PN_CHECK(v && v->n > 0);
            if (v) PN_CHECK_NEAR(t_sc_volume(v), vol, 1e-12);
            pn_mpm_destroy(v);
        }
        pn_mpm_destroy(w);
    }
}

/* Sampled volume against the exact one: within the stated bound area x h sqrt(d) / 2, and
   closer on a finer lattice (regular and jittered). */
static void t_sc_shape_volume(pn_test_ctx *pn__t, int dim, pn_mpm_fill_shape shape, int jitter) {
    double err[2] = {0, 0}, V = 0, S = 0, r = 0.17, L = 0.21;
    int k;
    for (k = 0; k < 2; ++k) {
        pn_mpm_world *w = t_sc_world(dim, 32, 1.0 / 32, NULL, 0, 100000);
        pn_mpm_fill_desc f;
        double h = 1.0 / 32 / (2 << k), got;
        PN_CHECK(w != NULL);
        if (!w) return;
        memset(&f, 0, sizeof f);
        f.group = t_sc_group(w, 1);
        f.shape = shape;
        f.per_axis = 2 << k;
        f.jitter = jitter;
        f.seed = 7;
        f.center_m[0] = 0.493;
        f.center_m[1] = 0.511;
        f.center_m[2] = 0.502;
        f.radius_m = r;
        f.half_length_m = L;
        f.axis[0] = 1, f.axis[1] = 2, f.axis[2] = -0.5; /* oblique */
        if (shape == PN_MPM_FILL_SPHERE) {
            V = dim == 2 ? T_SC_PI * r * r : 4.0 / 3 * T_SC_PI * r * r * r;
            S = dim == 2 ? 2 * T_SC_PI * r : 4 * T_SC_PI * r * r;
        } else { /* 2D: a 2r x 2L rectangle; 3D: a cylinder */
            V = dim == 2 ? 4 * r * L : T_SC_PI * r * r * 2 * L;
            S = dim == 2 ? 4 * (r + L) : 2 * T_SC_PI * r * r + 2 * T_SC_PI * r * 2 * L;
        }
        PN_CHECK(pn_mpm_fill(w, &f, NULL) == PN_OK);
        got = t_sc_volume(w);
        err[k] = fabs(got - V) / V;
        PN_CHECK_LE(fabs(got - V), S * h * sqrt((double)dim) / 2);
        PN_REPORT("%dD %s%s, %d per axis: volume %.6g, exact %.6g, error %.2e (bound %.2e)", dim,
                  shape == PN_MPM_FILL_SPHERE ? "sphere" : "cylinder", jitter ? " jittered" : "", 2 << k, got, V,
                  err[k], S * h * sqrt((double)dim) / 2 / V);
        pn_mpm_destroy(w);
    }
    if (!jitter && shape == PN_MPM_FILL_SPHERE) PN_CHECK(err[1] < err[0]); /* flat faces alias */
}

PN_TEST(scene_fill_volume) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        t_sc_shape_volume(pn__t, dim, PN_MPM_FILL_SPHERE, 0);
        t_sc_shape_volume(pn__t, dim, PN_MPM_FILL_CYLINDER, 0);
        t_sc_shape_volume(pn__t, dim, PN_MPM_FILL_SPHERE, 1);
    }
}

/* jitter is a function of the seed and the lattice index alone */
PN_TEST(scene_fill_jitter_deterministic) {
    pn_mpm_world *a = t_sc_world(3, 16, 1.0 / 16, NULL, 0, 50000), *b = t_sc_world(3, 16, 1.0 / 16, NULL, 0, 50000),
                 *c = t_sc_world(3, 16, 1.0 / 16, NULL, 0, 50000);
    pn_mpm_fill_desc f;
    size_t p;
    double moved = 0, lattice_gap = 0;
    PN_CHECK(a && b && c);
    if (!a || !b || !c) return;
    memset(&f, 0, sizeof f);
    f.shape = PN_MPM_FILL_SPHERE;
    f.center_m[0] = f.center_m[1] = f.center_m[2] = 0.5;
    f.radius_m = 0.2;
    f.jitter = 1;
    f.seed = 42;
    f.group = t_sc_group(a, 0);
    t_sc_group(b, 0);
    t_sc_group(c, 0);
    PN_CHECK(pn_mpm_fill(a, &f, NULL) == PN_OK && pn_mpm_fill(b, &f, NULL) == PN_OK);
    f.seed = 43;
    PN_CHECK(pn_mpm_fill(c, &f, NULL) == PN_OK);
    PN_CHECK(a->n == b->n && a->n > 1000);
    PN_CHECK(memcmp(a->x, b->x, sizeof(pn_real) * a->n * 3) == 0);
    for (p = 0; p < a->n && p < c->n; ++p) moved = fmax(moved, fabs(a->x[p * 3] - c->x[p * 3]));
    for (p = 0; p < a->n * 3; ++p) { /* off the lattice (i + 1/2) h */
        double u = a->x[p] * 32 - 0.5;
        lattice_gap = fmax(lattice_gap, fabs(u - floor(u + 0.5)));
    }
    PN_CHECK(moved > 1e-3 && lattice_gap > 0.3);
    pn_mpm_destroy(a);
    pn_mpm_destroy(b);
    pn_mpm_destroy(c);
}

/* an octahedron refined k times onto the sphere of radius r about c: closed, outward */
static int t_sc_icosphere(double *v, int *t, int k, double r, const double *c, int *nv) {
    static const double o[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    static const int f0[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
    int nt = 8, i, j, level;
    *nv = 6;
    for (i = 0; i < 6; ++i)
        for (j = 0; j < 3; ++j) v[i * 3 + j] = o[i][j];
    memcpy(t, f0, sizeof f0);
    for (level = 0; level < k; ++level) { /* split each triangle in 4 (midpoints duplicated: fine for winding) */
        int nt2 = 0, *t2 = t + nt * 3 * 4;
        for (i = 0; i < nt; ++i) {
            int a = t[i * 3], b = t[i * 3 + 1], cc = t[i * 3 + 2], m[3], e;
            const int pa[3] = {a, b, cc}, pb[3] = {b, cc, a};
            for (e = 0; e < 3; ++e) {
                double s = 0;
                for (j = 0; j < 3; ++j) v[*nv * 3 + j] = v[pa[e] * 3 + j] + v[pb[e] * 3 + j];
                for (j = 0; j < 3; ++j) s += v[*nv * 3 + j] * v[*nv * 3 + j];
                for (j = 0; j < 3; ++j) v[*nv * 3 + j] /= sqrt(s);
                m[e] = (*nv)++;
            }
            {
                const int tri[4][3] = {{a, m[0], m[2]}, {m[0], b, m[1]}, {m[2], m[1], cc}, {m[0], m[1], m[2]}};
                memcpy(t2 + nt2 * 3, tri, sizeof tri);
                nt2 += 4;
            }
        }
        memmove(t, t2, sizeof(int) * (size_t)nt2 * 3);
        nt = nt2;
    }
    for (i = 0; i < *nv; ++i)
        for (j = 0; j < 3; ++j) v[i * 3 + j] = c[j] + r * v[i * 3 + j];
    return nt;
}

/* enclosed volume of a closed triangle mesh (divergence theorem) */
static double t_sc_mesh_volume(const double *v, const int *t, int nt) {
    double V = 0;
    int i;
    for (i = 0; i < nt; ++i) {
        const double *a = v + t[i * 3] * 3, *b = v + t[i * 3 + 1] * 3, *c = v + t[i * 3 + 2] * 3;
        V += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])) / 6;
    }
    return V;
}

PN_TEST(scene_fill_mesh) {
    static double v[3 * 20000];
    static int t[3 * 40000];
    double c[3] = {0.5, 0.52, 0.49}, V, got, S;
    int nv, nt, i;
    pn_mpm_world *w = t_sc_world(3, 32, 1.0 / 32, NULL, 0, 20000);
    pn_mpm_fill_desc f;
    pn_result r;
    PN_CHECK(w != NULL);
    if (!w) return;
    /* a polyhedral sphere: sampled volume against its exact (divergence theorem) volume */
    nt = t_sc_icosphere(v, t, 4, 0.2, c, &nv);
    V = t_sc_mesh_volume(v, t, nt);
    S = 4 * T_SC_PI * 0.04;
    memset(&f, 0, sizeof f);
    f.group = t_sc_group(w, 1);
    f.shape = PN_MPM_FILL_MESH;
    f.vertices_m = v;
    f.n_vertices = (size_t)nv;
    f.indices = t;
    f.n_elements = (size_t)nt;
    PN_CHECK(pn_mpm_fill(w, &f, NULL) == PN_OK);
    got = t_sc_volume(w);
    PN_CHECK(V > 0);
    PN_CHECK_LE(fabs(got - V), S * (1.0 / 64) * sqrt(3.0) / 2);
    PN_REPORT("3D mesh (%d triangles): volume %.6g, exact %.6g, error %.2e", nt, got, V, fabs(got - V) / V);
    pn_mpm_destroy(w);
    /* a cube as 12 triangles: off the lattice it holds exactly the box fill's points; with
       its vertices on lattice points (rays through edges and vertices) it keeps a count
       between the points strictly inside and those inside or on it */
    {
        static const int q[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                                     {2, 3, 7}, {2, 7, 6}, {1, 2, 6}, {1, 6, 5}, {0, 4, 7}, {0, 7, 3}};
        static const double span[2][2] = {{19.3 / 64, 38.7 / 64}, {19.5 / 64, 38.5 / 64}};
        int k;
        for (k = 0; k < 2; ++k) {
            double cv[8][3], lo = span[k][0], hi = span[k][1];
            size_t nm = 0, nb = 0;
            pn_mpm_world *a = t_sc_world(3, 32, 1.0 / 32, NULL, 0, 10000), *b = t_sc_world(3, 32, 1.0 / 32, NULL, 0, 10000);
            for (i = 0; i < 8; ++i) { /* 0..3 around the bottom (z = lo), 4..7 above them */
                cv[i][0] = (i % 4 == 1 || i % 4 == 2) ? hi : lo;
                cv[i][1] = (i % 4 >= 2) ? hi : lo;
                cv[i][2] = i >= 4 ? hi : lo;
            }
            PN_CHECK(a && b);
            if (a && b) {
                memset(&f, 0, sizeof f);
                f.shape = PN_MPM_FILL_MESH;
                f.group = t_sc_group(a, 1);
                t_sc_group(b, 1);
                f.vertices_m = &cv[0][0];
                f.n_vertices = 8;
                f.indices = &q[0][0];
                f.n_elements = 12;
                PN_CHECK_NEAR(t_sc_mesh_volume(&cv[0][0], &q[0][0], 12), pow(hi - lo, 3), 1e-12);
                PN_CHECK(pn_mpm_fill(a, &f, &nm) == PN_OK);
                memset(&f, 0, sizeof f);
                f.shape = PN_MPM_FILL_BOX;
                for (i = 0; i < 3; ++i) f.center_m[i] = (lo + hi) / 2, f.half_extent_m[i] = (hi - lo) / 2;
                PN_CHECK(pn_mpm_fill(b, &f, &nb) == PN_OK);
                if (k == 0) PN_CHECK(nm == nb && nb == 20 * 20 * 20);
                else PN_CHECK(nm >= 18 * 18 * 18 && nm <= 20 * 20 * 20 && nb == 20 * 20 * 20);
                PN_REPORT("cube mesh %s the lattice: %lu particles (box fill %lu)", k ? "on" : "off",
                          (unsigned long)nm, (unsigned long)nb);
                if (k == 0) { /* an open mesh is refused, naming why, and adds nothing */
                    memset(&f, 0, sizeof f);
                    f.shape = PN_MPM_FILL_MESH;
                    f.vertices_m = &cv[0][0];
                    f.n_vertices = 8;
                    f.indices = &q[0][0];
                    f.n_elements = 11;
                    nm = a->n;
                    r = pn_mpm_fill(a, &f, NULL);
                    PN_CHECK(r == PN_ERROR_INVALID_ARGUMENT && a->n == nm && strstr(pn_mpm_error(a), "not closed"));
                }
            }
            pn_mpm_destroy(a);
            pn_mpm_destroy(b);
        }
    }
    /* 2D: an L-shaped polygon (counter-clockwise), area by the shoelace formula */
    {
        static const double pv[6][2] = {{0.3, 0.3}, {0.7, 0.3}, {0.7, 0.45}, {0.45, 0.45}, {0.45, 0.7}, {0.3, 0.7}};
        static const int pe[6][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 4}, {4, 5}, {5, 0}};
        double A = 0, P = 0;
        pn_mpm_world *a = t_sc_world(2, 32, 1.0 / 32, NULL, 0, 100000);
        for (i = 0; i < 6; ++i) {
            const double *p0 = pv[i], *p1 = pv[(i + 1) % 6];
            A += (p0[0] * p1[1] - p1[0] * p0[1]) / 2;
            P += hypot(p1[0] - p0[0], p1[1] - p0[1]);
        }
        PN_CHECK(a != NULL);
        if (a) {
            memset(&f, 0, sizeof f);
            f.group = t_sc_group(a, 0);
            f.shape = PN_MPM_FILL_MESH;
            f.vertices_m = &pv[0][0];
            f.n_vertices = 6;
            f.indices = &pe[0][0];
            f.n_elements = 6;
            f.per_axis = 3;
            PN_CHECK(pn_mpm_fill(a, &f, NULL) == PN_OK);
            PN_CHECK_LE(fabs(t_sc_volume(a) - A), P * (1.0 / 96) * sqrt(2.0) / 2);
            PN_REPORT("2D L-shaped polygon: area %.6g, exact %.6g", t_sc_volume(a), A);
        }
        pn_mpm_destroy(a);
    }
}

PN_TEST(scene_fill_errors) {
    pn_mpm_world *w = t_sc_world(2, 32, 1.0 / 32, NULL, 0, 2000);
    pn_mpm_fill_desc f;
    size_t n = 0, before;
    char why[256] = "";
    PN_CHECK(w != NULL);
    if (!w) return;
    memset(&f, 0, sizeof f);
    f.group = t_sc_group(w, 0);
    f.shape = PN_MPM_FILL_BOX;
    f.center_m[0] = 0.05; /* reaches into the left wall (3 cells = 0.094 m) */
    f.center_m[1] = 0.5;
    f.half_extent_m[0] = f.half_extent_m[1] = 0.3;
    PN_CHECK(pn_mpm_fill(w, &f, &n) == PN_ERROR_INVALID_ARGUMENT && w->n == 0 && n == 0);
    PN_CHECK(strstr(pn_mpm_error(w), "outside the walls") != NULL);
    f.clip = 1;
    PN_CHECK(pn_mpm_fill(w, &f, &n) == PN_OK && n == w->n && n > 0);
    PN_CHECK(w->x[0] >= 3.0 / 32);
    before = w->n;
    f.clip = 0;
    f.center_m[0] = 0.5;
    PN_CHECK(pn_mpm_fill(w, &f, &n) == PN_ERROR_CAPACITY && w->n == before);
    PN_CHECK(strstr(pn_mpm_error(w), "max_particles") != NULL);
    PN_REPORT("capacity message: %s", pn_mpm_error(w));
    /* a shape far larger than the domain: refused, or clipped to the walls in a time bounded
       by the domain (every interior lattice point: (32 - 6)^2 cells x 4) */
    {
        pn_mpm_desc wd = w->desc;
        pn_mpm_fill_desc big = f;
        big.shape = PN_MPM_FILL_SPHERE;
        big.radius_m = 1e6;
        PN_CHECK(pn_mpm_fill_count(&wd, &big, &n, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT);
        big.clip = 1;
        PN_CHECK(pn_mpm_fill_count(&wd, &big, &n, why, sizeof why) == PN_OK && n == 26 * 26 * 4);
        big.center_m[0] = 50; /* wholly outside: nothing to add, or refused */
        big.radius_m = 1;
        PN_CHECK(pn_mpm_fill_count(&wd, &big, &n, NULL, 0) == PN_OK && n == 0);
        big.clip = 0;
        PN_CHECK(pn_mpm_fill_count(&wd, &big, &n, NULL, 0) == PN_ERROR_INVALID_ARGUMENT);
    }
    f.radius_m = -1;
    f.shape = PN_MPM_FILL_SPHERE;
    PN_CHECK(pn_mpm_fill(w, &f, NULL) == PN_ERROR_INVALID_ARGUMENT && strstr(pn_mpm_error(w), "radius_m"));
    PN_CHECK(pn_mpm_fill_count(&w->desc, &f, &n, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && why[0] && strstr(why, "radius_m"));
    f.group = 5;
    PN_CHECK(pn_mpm_fill(w, &f, NULL) == PN_ERROR_INVALID_ARGUMENT && strstr(pn_mpm_error(w), "group"));
    pn_mpm_destroy(w);
}

/* ---- the explicit step bound -------------------------------------------------------------- */

/* run a scene for T s at k x pn_mpm_stable_dt; stable: no error and the kinetic energy
   never above 1.5x the largest of a run at half the bound (ke_cap; *ke: the largest; the run
   stops once above it, as an unstable run's speeds shrink the bound without end) */
static int t_sc_run_at(int kind, int dim, double k, double T, double ke_cap, double *ke) {
    int res = dim == 2 ? 64 : 24;
    pn_mpm_world *w = t_sc_world(dim, res, 1.0 / res, NULL, -9.81, 100000);
    pn_mpm_fill_desc f;
    double t = 0;
    int ok = 1, i;
    *ke = 0;
    if (!w) return 0;
    memset(&f, 0, sizeof f);
    f.group = t_sc_group(w, kind);
    for (i = 0; i < dim; ++i) f.center_m[i] = 0.5, f.half_extent_m[i] = 0.1;
    f.center_m[1] = 0.3;
    f.half_extent_m[1] = 0.15;
    f.velocity_m_s[1] = kind == 0 ? 0 : kind == 3 ? -5 : -2;
    if (pn_mpm_fill(w, &f, NULL) != PN_OK) ok = 0;
    while (ok && t < T) {
        pn_real dt;
        if (pn_mpm_stable_dt(w, &dt) != PN_OK || pn_mpm_step_explicit(w, k * dt, NULL) != PN_OK) ok = 0;
        t += k * dt;
        *ke = fmax(*ke, t_sc_ke(w));
        if (*ke > ke_cap) ok = 0;
    }
    pn_mpm_destroy(w);
    return ok;
}

PN_TEST(scene_stable_dt) {
    static const int kinds[6] = {0, 1, 2, 3, 0, 1}, dims[6] = {2, 2, 2, 2, 3, 3};
    static const char *names[4] = {"sand", "rubber", "snow", "metal"};
    int s;
    for (s = 0; s < 6; ++s) {
        double ke_ref, ke, k, largest = 0, T = kinds[s] == 3 ? 0.03 : 0.2;
        int stable_at_1, d = dims[s];
        if (d == 3 && !pn_test_full()) continue; /* 3D (16 of its 20 CPU s): PN_TEST_FULL=1 (make test-all, CI) */
        PN_CHECK(t_sc_run_at(kinds[s], d, 0.5, T, HUGE_VAL, &ke_ref));
        stable_at_1 = t_sc_run_at(kinds[s], d, 1.0, T, 1.5 * ke_ref + 1e-9, &ke);
        PN_CHECK(stable_at_1);
        for (k = 1.0; k <= 2.5; k *= 1.189207115) { /* rungs 2^(i/4), until the first unstable one */
            if (!t_sc_run_at(kinds[s], d, k, T, 1.5 * ke_ref + 1e-9, &ke)) break;
            largest = k;
        }
        PN_CHECK(largest >= 1.0 && largest <= 2.0);
        PN_REPORT("%dD %s: stable at pn_mpm_stable_dt; the largest stable step found is %.2fx it", d, names[kinds[s]],
                  largest);
    }
}

/* ---- honest large steps ------------------------------------------------------------------- */

/* a 2D world (res 32 on 1 m, gravity) holding a box of sand centred at (cx, cy) of half
   sizes (hx, hy), falling at vy; *n its particle count; NULL on failure */
static pn_mpm_world *t_sc_sand_box(double cx, double cy, double hx, double hy, double vy, size_t *n) {
    pn_mpm_world *w = t_sc_world(2, 32, 1.0 / 32, NULL, -9.81, 10000);
    pn_mpm_fill_desc f;
    if (!w) return NULL;
    memset(&f, 0, sizeof f);
    f.group = t_sc_group(w, 0);
    f.center_m[0] = cx, f.center_m[1] = cy;
    f.half_extent_m[0] = hx, f.half_extent_m[1] = hy;
    f.velocity_m_s[1] = vy;
    if (pn_mpm_fill(w, &f, n) != PN_OK) {
        pn_mpm_destroy(w);
        return NULL;
    }
    return w;
}

/* A sand layer falling at 2 m/s onto the floor, stepped once by dt: either PN_OK with every
   particle still active and inside the walls' grid, or an error with the state untouched. */
static void t_sc_big_step(pn_test_ctx *pn__t, int implicit, double dt, pn_result *out) {
    size_t n = 0, p;
    pn_mpm_world *w = t_sc_sand_box(0.5, 0.25, 0.3, 0.05, -2, &n);
    pn_real *x0, *v0;
    pn_result r;
    PN_CHECK(w != NULL);
    if (!w) return;
    x0 = (pn_real *)malloc(sizeof(pn_real) * n * 2);
    v0 = (pn_real *)malloc(sizeof(pn_real) * n * 2);
    memcpy(x0, w->x, sizeof(pn_real) * n * 2);
    memcpy(v0, w->v, sizeof(pn_real) * n * 2);
    r = implicit ? pn_mpm_step_implicit(w, dt, NULL, NULL) : pn_mpm_step_explicit(w, dt, NULL);
    *out = r;
    if (r == PN_OK) {
        size_t lost = 0;
        for (p = 0; p < n; ++p) lost += !w->active[p] || w->x[p * 2 + 1] < 1.0 / 32;
        PN_CHECK(lost == 0 && w->left_total == 0);
    } else {
        PN_CHECK(memcmp(x0, w->x, sizeof(pn_real) * n * 2) == 0 && memcmp(v0, w->v, sizeof(pn_real) * n * 2) == 0);
        PN_CHECK(w->steps == 0 && pn_mpm_error(w)[0] != 0);
    }
    free(x0);
    free(v0);
    pn_mpm_destroy(w);
}

PN_TEST(scene_large_steps_never_lose_material) {
    static const double dts[4] = {0.05, 0.1, 0.3, 1.0};
    int i;
    pn_result r;
    for (i = 0; i < 4; ++i) {
        t_sc_big_step(pn__t, 1, dts[i], &r);
        PN_REPORT("implicit dt %.2f s: %s", dts[i], pn_result_string(r));
    }
    PN_CHECK(r == PN_ERROR_STEP_TOO_LARGE); /* 1 s: 8 substeps still move ~1.6 m each */
    t_sc_big_step(pn__t, 0, 1e-2, &r);
    PN_REPORT("explicit dt 1e-2 s: %s", pn_result_string(r));
    /* the frame stepper takes as many steps as the advection limit asks: nothing lost */
    {
        size_t n = 0, p, bad = 0;
        pn_mpm_world *w = t_sc_sand_box(0.5, 0.5, 0.1, 0.1, -3, &n);
        pn_mpm_advance_desc a;
        pn_mpm_stats st;
        PN_CHECK(w != NULL);
        if (!w) return;
        memset(&a, 0, sizeof a);
        a.integrator = PN_MPM_IMPLICIT;
        a.max_step_s = 0.1;
        PN_CHECK(pn_mpm_advance(w, 0.5, &a, &st) == PN_OK);
        for (p = 0; p < n; ++p) bad += !w->active[p] || w->x[p * 2 + 1] < 2.0 / 32;
        PN_CHECK(bad == 0 && w->left_total == 0);
        PN_CHECK_NEAR(w->time_s, 0.5, 1e-12);
        PN_REPORT("pn_mpm_advance, implicit, a 0.5 s frame at most 0.1 s per step: %d steps, 0 particles lost",
                  st.substeps);
        pn_mpm_destroy(w);
    }
}

/* The block of explicit_particles_leaving_domain (400 m/s at a wall): refused as too large a step,
   refused as outflow with the limit raised, retired and counted when outflow is allowed. */
PN_TEST(scene_outflow) {
    int mode;
    for (mode = 0; mode < 3; ++mode) {
        pn_mpm_world *w = t_sc_world(2, 32, 1.0 / 32, NULL, 0, 10000);
        pn_mpm_fill_desc f;
        pn_mpm_stats st;
        pn_real *x0;
        size_t n = 0;
        pn_result r;
        PN_CHECK(w != NULL);
        if (!w) return;
        if (mode >= 1) w->desc.advection_limit = 100;
        if (mode == 2) w->desc.allow_outflow = 1;
        memset(&f, 0, sizeof f);
        f.group = t_sc_group(w, 1);
        f.center_m[0] = 0.75, f.center_m[1] = 0.45;
        f.half_extent_m[0] = f.half_extent_m[1] = 0.05;
        f.velocity_m_s[0] = 400;
        PN_CHECK(pn_mpm_fill(w, &f, &n) == PN_OK);
        x0 = (pn_real *)malloc(sizeof(pn_real) * n * 2);
        memcpy(x0, w->x, sizeof(pn_real) * n * 2);
        r = pn_mpm_step_explicit(w, 1e-3, &st);
        if (mode < 2) {
            PN_CHECK(r == (mode == 0 ? PN_ERROR_STEP_TOO_LARGE : PN_ERROR_OUTSIDE_DOMAIN));
            PN_CHECK(memcmp(x0, w->x, sizeof(pn_real) * n * 2) == 0 && w->error_particle >= 0 && (size_t)w->error_particle < n);
            PN_REPORT("%s", pn_mpm_error(w));
        } else {
            PN_CHECK(r == PN_OK && st.left_domain > 0 && st.left_domain + st.particles == n);
        }
        free(x0);
        pn_mpm_destroy(w);
    }
}

/* ---- a domain anywhere, a frame at a time --------------------------------------------------- */

PN_TEST(scene_origin) {
    double o[3] = {-3.7, 12.25, 0}, worst = 0;
    pn_mpm_world *a = t_sc_world(2, 32, 1.0 / 32, NULL, -9.81, 10000), *b = t_sc_world(2, 32, 1.0 / 32, o, -9.81, 10000);
    pn_mpm_fill_desc f;
    pn_collider c;
    size_t p;
    int s;
    PN_CHECK(a && b);
    if (!a || !b) return;
    memset(&f, 0, sizeof f);
    f.group = t_sc_group(a, 0);
    t_sc_group(b, 0);
    f.shape = PN_MPM_FILL_SPHERE;
    f.center_m[0] = 0.4, f.center_m[1] = 0.3;
    f.radius_m = 0.15;
    f.velocity_m_s[0] = 1;
    memset(&c, 0, sizeof c);
    c.shape = PN_SHAPE_SPHERE;
    c.boundary = PN_BOUNDARY_SLIP;
    c.center_m[0] = 0.7, c.center_m[1] = 0.2;
    c.radius_m = 0.08;
    PN_CHECK(pn_mpm_fill(a, &f, NULL) == PN_OK && pn_mpm_add_collider(a, &c, NULL) == PN_OK);
    f.center_m[0] += o[0], f.center_m[1] += o[1];
    c.center_m[0] += o[0], c.center_m[1] += o[1];
    PN_CHECK(pn_mpm_fill(b, &f, NULL) == PN_OK && pn_mpm_add_collider(b, &c, NULL) == PN_OK);
    PN_CHECK(a->n == b->n && a->n > 0);
    for (s = 0; s < 200; ++s) {
        PN_CHECK(pn_mpm_step_explicit(a, 2e-4, NULL) == PN_OK);
        PN_CHECK(pn_mpm_step_explicit(b, 2e-4, NULL) == PN_OK);
    }
    for (p = 0; p < a->n; ++p)
        worst = fmax(worst, fmax(fabs(b->x[p * 2] - o[0] - a->x[p * 2]), fabs(b->x[p * 2 + 1] - o[1] - a->x[p * 2 + 1])));
    PN_CHECK_LE(worst, 1e-9);
    PN_REPORT("the same scene at origin (-3.7, 12.25) m: positions agree to %.1e m after 200 steps", worst);
    pn_mpm_destroy(a);
    pn_mpm_destroy(b);
}

PN_TEST(scene_advance) {
    size_t n = 0;
    pn_mpm_world *w = t_sc_sand_box(0.5, 0.3, 0.1, 0.15, 0, &n);
    pn_mpm_advance_desc a;
    pn_mpm_stats st;
    pn_real dt;
    int frame;
    PN_CHECK(w != NULL && n > 0);
    if (!w) return;
    PN_CHECK(pn_mpm_stable_dt(w, &dt) == PN_OK);
    for (frame = 1; frame <= 3; ++frame) {
        PN_CHECK(pn_mpm_advance(w, 1.0 / 60, NULL, &st) == PN_OK);
        PN_CHECK_NEAR(w->time_s, frame / 60.0, 1e-12);
        PN_CHECK(st.substeps >= (int)floor(1.0 / 60 / dt)); /* no step beyond the bound */
    }
    PN_REPORT("explicit frames of 1/60 s: %d steps each (stable dt %.3g s)", st.substeps, dt);
    memset(&a, 0, sizeof a);
    a.integrator = (pn_mpm_integrator)7;
    PN_CHECK(pn_mpm_advance(w, 1.0 / 60, &a, NULL) == PN_ERROR_INVALID_ARGUMENT && strstr(pn_mpm_error(w), "integrator"));
    PN_CHECK(pn_mpm_advance(w, -1, NULL, NULL) == PN_ERROR_INVALID_ARGUMENT && strstr(pn_mpm_error(w), "frame_s"));
    pn_mpm_destroy(w);
}

/* ---- errors that name the culprit ---------------------------------------------------------- */

PN_TEST(scene_errors_name_the_culprit) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL, *w3 = NULL;
    char why[256] = "";
    pn_material m;
    pn_material_desc md;
    pn_mpm_implicit_desc id;
    pn_real x[2] = {0.5, 0.5};
    int g;
    /* pn_mpm_create checks the walls against every axis */
    memset(&wd, 0, sizeof wd);
    wd.dim = 2;
    wd.res[0] = 64, wd.res[1] = 8;
    wd.dx_m = 0.01;
    wd.wall_cells = 6;
    wd.max_particles = 10;
    PN_CHECK(pn_mpm_create(&wd, &w, why, sizeof why) == PN_ERROR_INVALID_ARGUMENT && !w && why[0] && strstr(why, "wall_cells"));
    wd.dim = 4;
    PN_CHECK(pn_mpm_create(&wd, &w, why, sizeof why) == PN_ERROR_DIMENSION && why[0] && strstr(why, "dim"));
    w = t_sc_world(2, 32, 1.0 / 32, NULL, 0, 100);
    PN_CHECK(w != NULL);
    if (!w) return;
    /* corrupt materials (a zeroed struct, an unknown plastic model, mu < 0, sin_phi 2) */
    memset(&md, 0, sizeof md);
    md.plastic = PN_PLASTIC_DRUCKER_PRAGER;
    md.youngs_modulus_pa = 1e7;
    md.poisson_ratio = 0.3;
    md.friction_angle_deg = 30;
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    {
        pn_material bad[4];
        int i;
        memset(&bad[0], 0, sizeof bad[0]);
        bad[1] = m, bad[1].plastic = (pn_plastic_model)99;
        bad[2] = m, bad[2].mu = -1;
        bad[3] = m, bad[3].sin_phi = 2;
        for (i = 0; i < 4; ++i) {
            PN_CHECK(pn_mpm_add_group(w, &bad[i], 1600) == -1 && w->n_groups == 0);
            PN_CHECK(strstr(pn_mpm_error(w), "material.") != NULL);
        }
    }
    PN_CHECK(pn_mpm_add_group(w, &m, -5) == -1 && strstr(pn_mpm_error(w), "density"));
    g = pn_mpm_add_group(w, &m, 1600);
    PN_CHECK(g == 0 && pn_mpm_error(w)[0] == 0);
    /* a volume whose mass overflows */
    PN_CHECK(pn_mpm_add_particles(w, g, 1, x, NULL, 1e307) == PN_ERROR_INVALID_ARGUMENT && w->n == 0);
    PN_CHECK(strstr(pn_mpm_error(w), "volume_m3") != NULL);
    /* over capacity names the capacity */
    {
        static pn_real many[2 * 101];
        int i;
        for (i = 0; i < 101; ++i) many[2 * i] = 0.3 + 0.003 * i, many[2 * i + 1] = 0.5;
        PN_CHECK(pn_mpm_add_particles(w, g, 101, many, NULL, 1e-4) == PN_ERROR_CAPACITY && w->n == 0);
        PN_CHECK(strstr(pn_mpm_error(w), "max_particles") != NULL);
    }
    PN_CHECK(pn_mpm_add_particles(w, g, 1, x, NULL, 1e-4) == PN_OK);
    /* NaN solver tolerances are refused, not replaced by defaults */
    memset(&id, 0, sizeof id);
    id.newton_tol = NAN;
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_ERROR_INVALID_ARGUMENT && w->steps == 0);
    PN_CHECK(strstr(pn_mpm_error(w), "newton_tol") != NULL);
    id.newton_tol = 0;
    id.cg_rel_tol = NAN;
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_ERROR_INVALID_ARGUMENT && w->steps == 0);
    /* negative counts are refused too (they used to become defaults); max_halvings < 0 is "none" */
    id.cg_rel_tol = 0;
    id.newton_max = -3;
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_ERROR_INVALID_ARGUMENT && w->steps == 0);
    PN_CHECK(strstr(pn_mpm_error(w), "newton_max") != NULL);
    id.newton_max = 0, id.sweeps_max = -1, id.formulation = PN_MPM_FORMULATION_STRESS;
    PN_CHECK(pn_mpm_step_implicit(w, 1e-3, &id, NULL) == PN_ERROR_INVALID_ARGUMENT && w->steps == 0);
    PN_CHECK(strstr(pn_mpm_error(w), "sweeps_max") != NULL);
    memset(&id, 0, sizeof id);
    /* a network bound to another material, or of another dimension */
    {
        t_pn_setup s;
        pn_material stiff;
        int g9;
        if (t_pn_setup_make(pn__t, &s, T_PN_SAND, 2, 1e7, 0, 5)) {
            md = s.desc;
            md.youngs_modulus_pa = 1e9;
            PN_CHECK(pn_material_init(&stiff, &md, NULL, 0) == PN_OK);
            g9 = pn_mpm_add_group(w, &stiff, 1600);
            PN_CHECK(pn_mpm_group_set_energy(w, g9, PN_ENERGY_PNET, &s.net) == PN_ERROR_INVALID_PARAMETER);
            PN_CHECK(strstr(pn_mpm_error(w), "another material") != NULL);
            md.youngs_modulus_pa = 1e7;
            md.poisson_ratio = 0.45;
            PN_CHECK(pn_material_init(&stiff, &md, NULL, 0) == PN_OK);
            g9 = pn_mpm_add_group(w, &stiff, 1600);
            PN_CHECK(pn_mpm_group_set_energy(w, g9, PN_ENERGY_PNET, &s.net) == PN_ERROR_INVALID_PARAMETER);
            g9 = pn_mpm_add_group(w, &s.m, 1600);
            PN_CHECK(pn_mpm_group_set_energy(w, g9, PN_ENERGY_PNET, &s.net) == PN_OK);
            w3 = t_sc_world(3, 16, 1.0 / 16, NULL, 0, 100);
            PN_CHECK(w3 != NULL);
            if (w3) {
                g9 = pn_mpm_add_group(w3, &s.m, 1600);
                PN_CHECK(pn_mpm_group_set_energy(w3, g9, PN_ENERGY_PNET, &s.net) == PN_ERROR_DIMENSION);
                PN_CHECK(strstr(pn_mpm_error(w3), "2D") != NULL);
                PN_REPORT("%s", pn_mpm_error(w3));
            }
            pn_mpm_destroy(w3);
        }
    }
    /* pn_model_material names a bad E */
    {
        t_pn_setup s;
        if (t_pn_setup_make(pn__t, &s, T_PN_SAND, 2, 1, 0, 6)) {
            why[0] = 0;
            PN_CHECK(pn_model_material(&s.energy.model, -1, &m, why, sizeof why) == PN_ERROR_INVALID_PARAMETER && why[0] &&
                     strstr(why, "youngs_modulus_pa"));
        }
    }
    pn_mpm_destroy(w);
}

/* a snapshot of every particle array a step reads (to see that a refused step changed nothing) */
typedef struct t_sc_snap {
    size_t n, bytes;
    unsigned char *buf;
} t_sc_snap;

static void t_sc_snap_take(t_sc_snap *s, const pn_mpm_world *w) {
    size_t d = (size_t)w->dim, n = w->n, off = 0;
    s->n = n;
    s->bytes = sizeof(pn_real) * n * (2 * d + 2 * d * d + 1) + n + sizeof w->time_s + sizeof w->steps;
    s->buf = (unsigned char *)malloc(s->bytes);
    if (!s->buf) return;
#define T_SC_PUT(ptr, size) memcpy(s->buf + off, ptr, size), off += size
    T_SC_PUT(w->x, sizeof(pn_real) * n * d);
    T_SC_PUT(w->v, sizeof(pn_real) * n * d);
    T_SC_PUT(w->C, sizeof(pn_real) * n * d * d);
    T_SC_PUT(w->F, sizeof(pn_real) * n * d * d);
    T_SC_PUT(w->h, sizeof(pn_real) * n);
    T_SC_PUT(w->active, n);
    T_SC_PUT(&w->time_s, sizeof w->time_s);
    T_SC_PUT(&w->steps, sizeof w->steps);
#undef T_SC_PUT
}

/* the world as the snapshot holds it (frees the snapshot) */
static int t_sc_snap_same(t_sc_snap *s, const pn_mpm_world *w) {
    t_sc_snap now;
    int same;
    t_sc_snap_take(&now, w);
    same = s->buf && now.buf && s->n == w->n && memcmp(s->buf, now.buf, s->bytes) == 0;
    free(now.buf);
    free(s->buf);
    s->buf = NULL;
    return same;
}

/* a world of the step tests (res 32 in 2D, 16 in 3D, gravity) holding a filled box of group
   kind (t_sc_group) centred at (0.5, cy, 0.5) of half side half; NULL (after a failed check)
   if any of it fails */
static pn_mpm_world *t_sc_box_world(pn_test_ctx *pn__t, int dim, int kind, double half, double cy) {
    pn_mpm_world *w = t_sc_world(dim, dim == 2 ? 32 : 16, dim == 2 ? 1.0 / 32 : 1.0 / 16, NULL, -9.81, 20000);
    pn_mpm_fill_desc f;
    int i;
    PN_CHECK(w != NULL);
    if (!w) return NULL;
    memset(&f, 0, sizeof f);
    f.group = t_sc_group(w, kind);
    for (i = 0; i < dim; ++i) f.center_m[i] = 0.5, f.half_extent_m[i] = (pn_real)half;
    f.center_m[1] = (pn_real)cy;
    if (pn_mpm_fill(w, &f, NULL) != PN_OK) {
        PN_CHECK(0);
        pn_mpm_destroy(w);
        return NULL;
    }
    return w;
}

/* The explicit step keeps its P2G records from one step to the next; a particle whose x a
   caller wrote in between is checked, not read out of bounds: NaN (PN_ERROR_NONFINITE), beyond
   the grid (PN_ERROR_OUTSIDE_DOMAIN), both naming the particle, the world unchanged; moved to
   another row of nodes by hand, it is stepped where it now is (its mass lands there). 2D, 3D. */
PN_TEST(scene_explicit_hand_written_x) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_sc_box_world(pn__t, dim, 0, 0.15, 0.5);
        pn_real dt, keep[3];
        t_sc_snap snap;
        int k, bad;
        size_t p = 7;
        if (!w) continue;
        PN_CHECK(w->n > p);
        PN_CHECK(pn_mpm_stable_dt(w, &dt) == PN_OK);
        for (k = 0; k < 3; ++k) PN_CHECK(pn_mpm_step_explicit(w, dt, NULL) == PN_OK);
        memcpy(keep, w->x + p * (size_t)dim, sizeof(pn_real) * (size_t)dim);
        for (bad = 0; bad < 3; ++bad) {
            pn_result r;
            w->x[p * (size_t)dim + 1] = bad == 0 ? (pn_real)NAN : bad == 1 ? (pn_real)HUGE_VAL : (pn_real)-5;
            t_sc_snap_take(&snap, w);
            r = pn_mpm_step_explicit(w, dt, NULL);
            PN_CHECK(r == (bad < 2 ? PN_ERROR_NONFINITE : PN_ERROR_OUTSIDE_DOMAIN));
            PN_CHECK(w->error_particle == (long)p && strstr(pn_mpm_error(w), "particle 7") != NULL);
            PN_CHECK(t_sc_snap_same(&snap, w));
        }
        /* moved by hand 0.2 m along axis 0 (several rows of nodes): stepped from there */
        memcpy(w->x + p * (size_t)dim, keep, sizeof(pn_real) * (size_t)dim);
        w->x[p * (size_t)dim] = keep[0] + (pn_real)0.2;
        PN_CHECK(pn_mpm_step_explicit(w, dt, NULL) == PN_OK);
        PN_CHECK(fabs(w->x[p * (size_t)dim] - (keep[0] + 0.2)) < 0.01);
        pn_mpm_destroy(w);
    }
}

/* An explicit step far beyond the wave-speed bound (10 s, 1e3 s; over 4x pn_mpm_stable_dt)
   is refused with PN_ERROR_STEP_TOO_LARGE naming the bound, the world unchanged; steps up to
   the largest stable one (below 2x: scene_stable_dt) are not refused by it. */
PN_TEST(scene_explicit_step_too_large) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_sc_box_world(pn__t, dim, 3, 0.1, 0.5); /* metal, E 1e9 */
        pn_real dt, big[3];
        t_sc_snap snap;
        int i;
        if (!w) continue;
        PN_CHECK(pn_mpm_stable_dt(w, &dt) == PN_OK);
        big[0] = 10, big[1] = 1e3, big[2] = 5 * dt;
        for (i = 0; i < 3; ++i) {
            t_sc_snap_take(&snap, w);
            PN_CHECK(pn_mpm_step_explicit(w, big[i], NULL) == PN_ERROR_STEP_TOO_LARGE);
            PN_CHECK(strstr(pn_mpm_error(w), "pn_mpm_stable_dt") != NULL);
            PN_CHECK(t_sc_snap_same(&snap, w));
        }
        PN_CHECK(pn_mpm_step_explicit(w, 2 * dt, NULL) == PN_OK);
        PN_CHECK(pn_mpm_step_explicit(w, dt, NULL) == PN_OK);
        pn_mpm_destroy(w);
    }
}

/* The stress formulation on material in free flight: the sweeps change nothing, which is
   convergence (it used to run to sweeps_max and fail); the block falls as g t^2 / 2. */
PN_TEST(scene_stress_free_flight) {
    int dim;
    for (dim = 2; dim <= 3; ++dim) {
        pn_mpm_world *w = t_sc_box_world(pn__t, dim, 0, 0.1, 0.6);
        pn_mpm_implicit_desc id;
        double y0 = 0, y1 = 0;
        size_t p;
        int k;
        if (!w) continue;
        memset(&id, 0, sizeof id);
        id.formulation = PN_MPM_FORMULATION_STRESS;
        for (p = 0; p < w->n; ++p) y0 += w->x[p * (size_t)dim + 1] / (double)w->n;
        for (k = 0; k < 5; ++k) {
            pn_result r = pn_mpm_step_implicit(w, 1e-3, &id, NULL);
            PN_CHECK(r == PN_OK);
            if (r != PN_OK) fprintf(stderr, "  %s\n", pn_mpm_error(w));
        }
        for (p = 0; p < w->n; ++p) y1 += w->x[p * (size_t)dim + 1] / (double)w->n;
        /* implicit Euler: v_k = -g k dt, x drops g dt^2 (1 + .. + 5) = 15 g dt^2 */
        PN_CHECK(fabs((y0 - y1) - 15 * 9.81 * 1e-6) < 1e-9);
        pn_mpm_destroy(w);
    }
}

static const pn_test_case pn_tests_scene[] = {
    {"scene_fill_box", scene_fill_box},
    {"scene_fill_volume", scene_fill_volume},
    {"scene_fill_jitter_deterministic", scene_fill_jitter_deterministic},
    {"scene_fill_mesh", scene_fill_mesh},
    {"scene_fill_errors", scene_fill_errors},
    {"scene_stable_dt", scene_stable_dt},
    {"scene_large_steps_never_lose_material", scene_large_steps_never_lose_material},
    {"scene_outflow", scene_outflow},
    {"scene_origin", scene_origin},
    {"scene_advance", scene_advance},
    {"scene_errors_name_the_culprit", scene_errors_name_the_culprit},
    {"scene_explicit_hand_written_x", scene_explicit_hand_written_x},
    {"scene_explicit_step_too_large", scene_explicit_step_too_large},
    {"scene_stress_free_flight", scene_stress_free_flight},
};
