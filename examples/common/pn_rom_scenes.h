/* pn_rom_scenes.h: the scenes of the reduced-order models (docs/rom.md), shared by the
   full-order data generator (gen/rom_data.c), the benchmark (bench/bench_rom.c) and the
   examples. A scene is a reference domain filled on a lattice, a material, a frame rate, and
   per instance (one point of its parameter sweep) the gravity, the drives (material held or
   moved rigidly) and the loads (a force on a region for a while). Everything is described in
   reference coordinates, so the full-order world (plastinet_mpm.h) and the reduced one
   (plastinet_rom.h) are set up from the same numbers.

   Scenes (after Chen et al. 2023, Table 2; what we chose where the paper is silent or its
   numbers do not fit is in docs/rom.md):
     cylinder  r 1 cm, 4 cm long, horizontal, one end held (attached to a wall); gravity
               g in [1, 10] m/s^2, 30 instances evenly spaced, 24 train / 6 test; 30 frames
     cuboid    1 x 1 x 4 cm; one end held, the other pulled along the axis at v in [0, 0.06] m/s
               and twisted about it at w in [0, 2] rad/s, 6 x 6 instances, 29 train / 7 test
     poke      the cylinder standing on its held base, poked at the top rim for 0.25 s from
               36 directions theta = k 10 deg, trained on the 12 multiples of 30 deg; 3 s
     tower     a three-tier tower with windows, base held, top moved at a constant velocity
               (r, theta, phi) drawn by Latin hypercube, 16 train / 4 test; 80 frames of 1/24 s
   Everything is static; no globals. Include after plastinet.h. */
#ifndef PN_ROM_SCENES_H
#define PN_ROM_SCENES_H
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__GNUC__)
#define PN_RS_UNUSED __attribute__((unused))
#else
#define PN_RS_UNUSED
#endif
#define PN_RS_MAX_DRIVES 2
#define PN_RS_MAX_LOADS 10
#define PN_RS_PI 3.14159265358979323846
/* --help: the explicit schemes' two letters (the examples' shared lines) */
#define PN_RS_SCHEME_HELP \
    "                    L   Lagrangian: the body's own points near the samples\n" \
    "                    E   Eulerian: points on a lattice of each grid cell near the samples, mapped back\n" \
    "                        to the reference domain by Newton (no point is tracked)\n" \
    "                    second letter, the projection onto the latent:\n" \
    "                    L   linear: the latent velocity by least squares on the velocities, then\n" \
    "                        latent += dt x latent velocity\n" \
    "                    N   nonlinear: the latent by Gauss-Newton on the sampled positions as well\n" \
    "                    so LN, LL, EN, EL are the four explicit variants (docs/rom.md)\n"

typedef struct pn_rs_region {  /* reference points in the box lo..hi, and within radius of   */
    double lo[3], hi[3];       /* center if radius > 0                                        */
    double center[3], radius;
} pn_rs_region;

typedef struct pn_rs_drive {   /* pn_mpm_drive_particles from t = 0                           */
    pn_rs_region region;
    double velocity[3], center[3], omega[3];
} pn_rs_drive;

typedef struct pn_rs_load {    /* pn_mpm_add_load: force (N, in total) from t_start for duration */
    pn_rs_region region;
    double force[3], t_start, duration;
} pn_rs_load;

typedef struct pn_rs_instance {
    double params[4];
    double gravity[3];
    int n_drives, n_loads;
    pn_rs_drive drive[PN_RS_MAX_DRIVES];
    pn_rs_load load[PN_RS_MAX_LOADS];
    int test;                  /* 1: a test instance (never trained on)                       */
} pn_rs_instance;

typedef struct pn_rs_scene {
    const char *name;
    int dim;
    double youngs_pa, poisson, density;
    double dx;                 /* the full-order grid (m)                                     */
    double dx_base;            /* the base resolution's grid: drive and load regions scale with it */
    int per_axis;              /* particles per cell per axis                                 */
    double frame_dt;           /* s between snapshots                                         */
    int frames;                /* snapshots, the rest state included                          */
    int res[3];                /* grid cells per axis (walls included)                        */
    double box_lo[3], box_hi[3]; /* the lattice is filled inside this box where inside() holds */
    int n_instances, n_params;
    const char *param_names[4];
    int id;                    /* which scene (pn_rs_inside, pn_rs_instance_of)               */
} pn_rs_scene;

enum { PN_RS_CYLINDER = 0, PN_RS_CUBOID, PN_RS_POKE, PN_RS_POKE_SEQ, PN_RS_TOWER, PN_RS_COUNT };

/* the domain's origin is 0; walls are 3 cells; the bodies sit well inside */
PN_RS_UNUSED static pn_rs_scene pn_rs_get(int id, int fine) {
    pn_rs_scene s;
    memset(&s, 0, sizeof s);
    s.id = id;
    s.dim = 3;
    s.density = 1000;
    s.per_axis = 2;
    switch (id) {
    case PN_RS_CYLINDER: /* axis x, held at x = 2 cm, free end at 6 cm, centre y 6 cm, z 3.2 cm */
        s.name = "cylinder", s.youngs_pa = 12500, s.poisson = 0.3, s.dx = 0.004, s.frame_dt = 1.0 / 144, s.frames = 31;
        s.res[0] = 20, s.res[1] = 24, s.res[2] = 16;
        s.box_lo[0] = 0.02, s.box_lo[1] = 0.05, s.box_lo[2] = 0.022;
        s.box_hi[0] = 0.06, s.box_hi[1] = 0.07, s.box_hi[2] = 0.042;
        s.n_instances = 30, s.n_params = 1, s.param_names[0] = "gravity_m_s2";
        break;
    case PN_RS_CUBOID: /* axis x from 2 cm to 6 cm, cross-section 1 x 1 cm centred at (4, 4) cm */
        s.name = "cuboid", s.youngs_pa = 12500, s.poisson = 0.3, s.dx = 0.0025, s.frame_dt = 1.0 / 144, s.frames = 31;
        s.res[0] = 40, s.res[1] = 32, s.res[2] = 32;
        s.box_lo[0] = 0.02, s.box_lo[1] = 0.035, s.box_lo[2] = 0.035;
        s.box_hi[0] = 0.06, s.box_hi[1] = 0.045, s.box_hi[2] = 0.045;
        s.n_instances = 36, s.n_params = 2, s.param_names[0] = "pull_m_s", s.param_names[1] = "twist_rad_s";
        break;
    case PN_RS_POKE:
    case PN_RS_POKE_SEQ: /* axis z from 1.2 cm up 4 cm, centred at (4, 4) cm */
        s.name = id == PN_RS_POKE ? "poke" : "poke_seq";
        s.youngs_pa = 12500, s.poisson = 0.3, s.dx = 0.004, s.frame_dt = 1.0 / 144;
        s.frames = id == PN_RS_POKE ? 433 : 4321;
        s.res[0] = 20, s.res[1] = 20, s.res[2] = 20;
        s.box_lo[0] = 0.03, s.box_lo[1] = 0.03, s.box_lo[2] = 0.012;
        s.box_hi[0] = 0.05, s.box_hi[1] = 0.05, s.box_hi[2] = 0.052;
        s.n_instances = id == PN_RS_POKE ? 36 : 1, s.n_params = id == PN_RS_POKE ? 1 : 0;
        s.param_names[0] = id == PN_RS_POKE ? "theta_deg" : NULL;
        break;
    default: /* tower: footprint 8 x 8 cm centred at (8, 8) cm, from z = 1.2 cm to 17.2 cm */
        s.name = "tower", s.youngs_pa = 80000, s.poisson = 0.2, s.dx = 0.004, s.frame_dt = 1.0 / 24, s.frames = 81;
        s.res[0] = 40, s.res[1] = 40, s.res[2] = 52;
        s.box_lo[0] = 0.04, s.box_lo[1] = 0.04, s.box_lo[2] = 0.012;
        s.box_hi[0] = 0.12, s.box_hi[1] = 0.12, s.box_hi[2] = 0.172;
        s.n_instances = 20, s.n_params = 3, s.param_names[0] = "speed_cm_s", s.param_names[1] = "theta_rad",
        s.param_names[2] = "phi_rad";
        break;
    }
    s.dx_base = s.dx;
    if (fine > 1) { /* the same scene at a finer grid (super-resolution ground truth) */
        s.dx /= fine;
        s.res[0] *= fine, s.res[1] *= fine, s.res[2] *= fine;
    }
    return s;
}

PN_RS_UNUSED static int pn_rs_find(const char *name) {
    int i;
    for (i = 0; i < PN_RS_COUNT; ++i)
        if (!strcmp(pn_rs_get(i, 1).name, name)) return i;
    return -1;
}

/* Is the reference point X material? */
PN_RS_UNUSED static int pn_rs_inside(const pn_rs_scene *s, const double *X) {
    int i;
    for (i = 0; i < 3; ++i)
        if (X[i] < s->box_lo[i] || X[i] > s->box_hi[i]) return 0;
    switch (s->id) {
    case PN_RS_CYLINDER: {
        double dy = X[1] - 0.06, dz = X[2] - 0.032;
        return dy * dy + dz * dz <= 0.01 * 0.01;
    }
    case PN_RS_POKE:
    case PN_RS_POKE_SEQ: {
        double dx = X[0] - 0.04, dy = X[1] - 0.04;
        return dx * dx + dy * dy <= 0.01 * 0.01;
    }
    case PN_RS_TOWER: {
        /* tiers (z from the base at 1.2 cm): a 8 x 8 cm plinth 2 cm high; a 6 x 6 cm storey
           8 cm high, hollow (walls 1.8 cm) with a 2 x 3 cm window through each wall; a
           4 x 4 cm solid spire 4 cm high; a 6 x 6 x 2 cm cap on top (the driven lid) */
        double z = X[2] - 0.012, ax = fabs(X[0] - 0.08), ay = fabs(X[1] - 0.08), m = ax > ay ? ax : ay;
        if (z < 0.02) return 1;
        if (z < 0.10) {
            double zw = z - 0.045; /* window centre height in the storey */
            if (m > 0.03) return 0;
            if (m < 0.012) return 0; /* the hollow core */
            if (fabs(zw) < 0.015 && ((ax > 0.012 && ay < 0.01) || (ay > 0.012 && ax < 0.01))) return 0;
            return 1;
        }
        if (z < 0.14) return m <= 0.02;
        return m <= 0.03;
    }
    default: /* cuboid: the box itself */
        return 1;
    }
}

/* The reference points: a lattice of spacing dx / per_axis, points at cell-centred positions
   (i + 1/2) h from the origin, kept where pn_rs_inside holds. Writes up to cap points into X
   (3 per point; NULL: count only) and returns the count. refine > 1 samples the same domain
   refine times finer per axis (super-resolution point sets). */
PN_RS_UNUSED static size_t pn_rs_points(const pn_rs_scene *s, int refine, double *X, size_t cap) {
    double h = s->dx / s->per_axis / (refine > 1 ? refine : 1);
    long lo[3], hi[3], i, j, k;
    size_t n = 0;
    int a;
    for (a = 0; a < 3; ++a) {
        lo[a] = (long)floor(s->box_lo[a] / h - 0.5) - 1;
        hi[a] = (long)ceil(s->box_hi[a] / h - 0.5) + 1;
    }
    for (i = lo[0]; i <= hi[0]; ++i)
        for (j = lo[1]; j <= hi[1]; ++j)
            for (k = lo[2]; k <= hi[2]; ++k) {
                double p[3];
                p[0] = (i + 0.5) * h, p[1] = (j + 0.5) * h, p[2] = (k + 0.5) * h;
                if (!pn_rs_inside(s, p)) continue;
                if (X && n < cap) memcpy(X + 3 * n, p, sizeof p);
                n++;
            }
    return n;
}

PN_RS_UNUSED static int pn_rs_in_region(const pn_rs_region *r, const double *X) {
    int i;
    double d2 = 0;
    for (i = 0; i < 3; ++i) {
        if (X[i] < r->lo[i] || X[i] > r->hi[i]) return 0;
        d2 += (X[i] - r->center[i]) * (X[i] - r->center[i]);
    }
    return r->radius > 0 ? d2 <= r->radius * r->radius : 1;
}

PN_RS_UNUSED static void pn_rs_box(pn_rs_region *r, double x0, double x1, double y0, double y1, double z0, double z1) {
    memset(r, 0, sizeof *r);
    r->lo[0] = x0, r->hi[0] = x1, r->lo[1] = y0, r->hi[1] = y1, r->lo[2] = z0, r->hi[2] = z1;
}

/* a deterministic generator for the splits and the Latin hypercube (splitmix64) */
PN_RS_UNUSED static double pn_rs_rand(unsigned long long *st) {
    unsigned long long z = (*st += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    z ^= z >> 31;
    return (double)(z >> 11) / 9007199254740992.0;
}

/* test[k] = 1 for n_test instances of n, drawn without replacement by a seeded shuffle */
PN_RS_UNUSED static void pn_rs_split(int n, int n_test, unsigned long long seed, int *test) {
    int perm[64], i;
    for (i = 0; i < n; ++i) perm[i] = i, test[i] = 0;
    for (i = n - 1; i > 0; --i) {
        int j = (int)(pn_rs_rand(&seed) * (i + 1)), t = perm[i];
        perm[i] = perm[j], perm[j] = t;
    }
    for (i = 0; i < n_test; ++i) test[perm[i]] = 1;
}

/* the poke: a force of 0.06 N on the top of the body within 8 mm of the rim point at angle theta + pi,
   pointing across the axis towards theta, tilted 15 degrees down, for 0.25 s */
PN_RS_UNUSED static void pn_rs_poke(pn_rs_load *L, double theta, double t_start) {
    double px = 0.04 - 0.01 * cos(theta), py = 0.04 - 0.01 * sin(theta), ph = 75 * PN_RS_PI / 180, f = 0.06;
    pn_rs_box(&L->region, -1, 1, -1, 1, -1, 1);
    L->region.center[0] = px, L->region.center[1] = py, L->region.center[2] = 0.052, L->region.radius = 0.008;
    L->force[0] = f * sin(ph) * cos(theta), L->force[1] = f * sin(ph) * sin(theta), L->force[2] = -f * cos(ph);
    L->t_start = t_start, L->duration = 0.25;
}

/* Instance k of scene s */
PN_RS_UNUSED static pn_rs_instance pn_rs_instance_of(const pn_rs_scene *s, int k) {
    pn_rs_instance in;
    int test[64], i;
    memset(&in, 0, sizeof in);
    switch (s->id) {
    case PN_RS_CYLINDER:
        pn_rs_split(30, 6, 19, test);
        in.params[0] = 1 + 9.0 * k / 29;
        in.gravity[1] = -in.params[0];
        in.n_drives = 1; /* the end face against the wall: the first two lattice layers */
        pn_rs_box(&in.drive[0].region, -1, 0.02 + s->dx_base, -1, 1, -1, 1);
        in.test = test[k];
        break;
    case PN_RS_CUBOID:
        pn_rs_split(36, 7, 23, test);
        in.params[0] = 0.06 * (k / 6) / 5, in.params[1] = 2.0 * (k % 6) / 5;
        in.n_drives = 2;
        pn_rs_box(&in.drive[0].region, -1, 0.02 + s->dx_base, -1, 1, -1, 1);
        pn_rs_box(&in.drive[1].region, 0.06 - s->dx_base, 1, -1, 1, -1, 1);
        in.drive[1].velocity[0] = in.params[0];
        in.drive[1].center[0] = 0.06, in.drive[1].center[1] = 0.04, in.drive[1].center[2] = 0.04;
        in.drive[1].omega[0] = in.params[1];
        in.test = test[k];
        break;
    case PN_RS_POKE:
        in.params[0] = 10.0 * k;
        in.n_drives = 1; /* the base: the first two lattice layers */
        pn_rs_box(&in.drive[0].region, -1, 1, -1, 1, -1, 0.012 + s->dx_base);
        in.n_loads = 1;
        pn_rs_poke(&in.load[0], in.params[0] * PN_RS_PI / 180, 0);
        in.test = k % 3 != 0;
        break;
    case PN_RS_POKE_SEQ: { /* ten pokes in random directions, one every 3 s */
        unsigned long long st = 77;
        in.n_drives = 1;
        pn_rs_box(&in.drive[0].region, -1, 1, -1, 1, -1, 0.012 + s->dx_base);
        in.n_loads = 10;
        for (i = 0; i < 10; ++i) pn_rs_poke(&in.load[i], 2 * PN_RS_PI * pn_rs_rand(&st), 3.0 * i);
        in.test = 1;
        break;
    }
    default: { /* tower: Latin hypercube over speed [0.6, 0.8) cm/s, theta [0, pi/2), phi [-2pi/3, -pi/3) */
        unsigned long long st = 31;
        int perm[3][20], a;
        double u[3] = {0, 0, 0};
        for (a = 0; a < 3; ++a) {
            for (i = 0; i < 20; ++i) perm[a][i] = i;
            for (i = 19; i > 0; --i) {
                int j = (int)(pn_rs_rand(&st) * (i + 1)), t = perm[a][i];
                perm[a][i] = perm[a][j], perm[a][j] = t;
            }
        }
        for (i = 0; i <= k && i < 20; ++i) /* the jitter of instance k: drawn in order, so k's depends only on k */
            for (a = 0; a < 3; ++a) u[a] = (perm[a][i] + pn_rs_rand(&st)) / 20;
        in.params[0] = 0.6 + 0.2 * u[0], in.params[1] = PN_RS_PI / 2 * u[1], in.params[2] = -2 * PN_RS_PI / 3 + PN_RS_PI / 3 * u[2];
        in.n_drives = 2;
        pn_rs_box(&in.drive[0].region, -1, 1, -1, 1, -1, 0.012 + s->dx_base);
        pn_rs_box(&in.drive[1].region, -1, 1, -1, 1, 0.172 - s->dx_base, 1);
        in.drive[1].velocity[0] = 0.01 * in.params[0] * cos(in.params[2]) * cos(in.params[1]);
        in.drive[1].velocity[1] = 0.01 * in.params[0] * cos(in.params[2]) * sin(in.params[1]);
        in.drive[1].velocity[2] = 0.01 * in.params[0] * sin(in.params[2]);
        in.test = k >= 16;
        break;
    }
    }
    return in;
}

/* Set up instance `in` on an empty world of scene s (a group already added): the lattice
   points of the scene (refine: see pn_rs_points) with the drives from t = 0, and the loads
   that are on at time t (restarting at t: its part of a load still to come; loads that start
   later are added by pn_rs_events). flags (optional, one per point): bit d set for drive d,
   bit 2 for a load. Returns the point count, 0 on failure (message on stderr). */
PN_RS_UNUSED static size_t pn_rs_setup(pn_mpm_world *w, int group, const pn_rs_scene *s, const pn_rs_instance *in, int refine,
                          unsigned char *flags, double *X, size_t cap) {
    size_t n = pn_rs_points(s, refine, X, cap), p, *sel, ns;
    double h = s->dx / s->per_axis / (refine > 1 ? refine : 1);
    pn_real *x;
    int a;
    if (n > cap || n == 0) return 0;
    x = (pn_real *)malloc(sizeof(pn_real) * 3 * n);
    sel = (size_t *)malloc(sizeof(size_t) * n);
    for (p = 0; p < 3 * n; ++p) x[p] = (pn_real)X[p];
    if (pn_mpm_add_particles(w, group, n, x, NULL, (pn_real)(h * h * h)) != PN_OK) {
        fprintf(stderr, "pn_rs_setup: %s\n", pn_mpm_error(w));
        free(x), free(sel);
        return 0;
    }
    if (flags) memset(flags, 0, n);
    for (a = 0; a < in->n_drives; ++a) {
        const pn_rs_drive *D = &in->drive[a];
        pn_real v[3], c[3], om[3];
        int i;
        for (ns = 0, p = 0; p < n; ++p)
            if (pn_rs_in_region(&D->region, X + 3 * p)) {
                sel[ns++] = p;
                if (flags) flags[p] |= (unsigned char)(1 << a);
            }
        for (i = 0; i < 3; ++i) v[i] = (pn_real)D->velocity[i], c[i] = (pn_real)D->center[i], om[i] = (pn_real)D->omega[i];
        if (pn_mpm_drive_particles(w, ns, sel, v, c, om, NULL) != PN_OK) {
            fprintf(stderr, "pn_rs_setup: drive %d: %s\n", a, pn_mpm_error(w));
            free(x), free(sel);
            return 0;
        }
    }
    for (a = 0; a < in->n_loads; ++a)
        if (flags)
            for (p = 0; p < n; ++p)
                if (pn_rs_in_region(&in->load[a].region, X + 3 * p)) flags[p] |= 4;
    free(x), free(sel);
    return n;
}

/* Add the loads of `in` that are on at time t and not yet added: a load is added at the first
   call with t >= t_start (with what remains of its duration); *next_load counts those added. */
PN_RS_UNUSED static int pn_rs_events(pn_mpm_world *w, const pn_rs_instance *in, const double *X, size_t n, double t, int *next_load) {
    while (*next_load < in->n_loads && t >= in->load[*next_load].t_start - 1e-12) {
        const pn_rs_load *L = &in->load[*next_load];
        double left = L->t_start + L->duration - t;
        size_t *sel = (size_t *)malloc(sizeof(size_t) * n), ns = 0, p;
        pn_real f[3];
        int i;
        for (p = 0; p < n; ++p)
            if (pn_rs_in_region(&L->region, X + 3 * p)) sel[ns++] = p;
        for (i = 0; i < 3; ++i) f[i] = (pn_real)L->force[i];
        if (left > 0 && pn_mpm_add_load(w, ns, sel, f, (pn_real)left, NULL) != PN_OK) {
            fprintf(stderr, "pn_rs_events: load %d: %s\n", *next_load, pn_mpm_error(w));
            free(sel);
            return 0;
        }
        free(sel);
        ++*next_load;
    }
    return 1;
}
#ifdef PLASTINET_ROM_H
PN_RS_UNUSED static pn_rom_region pn_rs_rom_region(const pn_rs_region *r) {
    pn_rom_region o;
    memcpy(o.lo, r->lo, sizeof o.lo), memcpy(o.hi, r->hi, sizeof o.hi), memcpy(o.center, r->center, sizeof o.center);
    o.radius = r->radius;
    return o;
}

/* the drives of instance `in` on a reduced world at t = 0 (gravity is the desc's) */
PN_RS_UNUSED static int pn_rs_rom_setup(pn_rom_world *w, const pn_rs_instance *in) {
    int a;
    for (a = 0; a < in->n_drives; ++a) {
        pn_rom_region r = pn_rs_rom_region(&in->drive[a].region);
        if (pn_rom_drive(w, &r, in->drive[a].velocity, in->drive[a].center, in->drive[a].omega, NULL) != PN_OK) {
            fprintf(stderr, "pn_rs_rom_setup: drive %d: %s\n", a, pn_rom_error(w));
            return 0;
        }
    }
    return 1;
}

/* the loads of `in` due at time t (as pn_rs_events) */
PN_RS_UNUSED static int pn_rs_rom_events(pn_rom_world *w, const pn_rs_instance *in, double t, int *next_load) {
    while (*next_load < in->n_loads && t >= in->load[*next_load].t_start - 1e-12) {
        const pn_rs_load *L = &in->load[*next_load];
        pn_rom_region r = pn_rs_rom_region(&L->region);
        double left = L->t_start + L->duration - t;
        if (left > 0 && pn_rom_add_load(w, &r, L->force, left, NULL) != PN_OK) {
            fprintf(stderr, "pn_rs_rom_events: load %d: %s\n", *next_load, pn_rom_error(w));
            return 0;
        }
        ++*next_load;
    }
    return 1;
}
#endif

#ifdef PN_RENDER_H
/* A picture of n reduced-order points x (z up in the scenes, y up in the renderer) coloured by
   their displacement from X, times scale (the legend's unit: 100 for cm, 1000 for mm), in the
   box lo .. hi (scene coordinates), written to path as PNG (pn_rs_draw) or into an RGB buffer
   (pn_rs_render). 1 on success. */
#define PN_RS_DRAW_W 960
#define PN_RS_DRAW_H 540
/* the same picture into rgb (PN_RS_DRAW_W x PN_RS_DRAW_H x 3), e.g. for an animated PNG */
PN_RS_UNUSED static int pn_rs_render(unsigned char *rgb, size_t n, const float *x, const double *X, double spacing, double t,
                                     const double *lo, const double *hi, double floor_z, const char *field, double scale,
                                     double field_hi, const char *title) {
    pn_render_desc d;
    pn_real *xr = (pn_real *)malloc(sizeof(pn_real) * 3 * n), *disp = (pn_real *)malloc(sizeof(pn_real) * n);
    size_t p;
    int ok;
    if (!xr || !disp || !rgb) {
        free(xr), free(disp);
        return 0;
    }
    for (p = 0; p < n; ++p) {
        double e0 = x[3 * p] - X[3 * p], e1 = x[3 * p + 1] - X[3 * p + 1], e2 = x[3 * p + 2] - X[3 * p + 2];
        xr[3 * p] = x[3 * p], xr[3 * p + 1] = x[3 * p + 2], xr[3 * p + 2] = x[3 * p + 1];
        disp[p] = (pn_real)(scale * sqrt(e0 * e0 + e1 * e1 + e2 * e2));
    }
    memset(&d, 0, sizeof d);
    d.width = 960, d.height = 540, d.dim = 3;
    d.lo[0] = lo[0], d.lo[1] = lo[2], d.lo[2] = lo[1], d.hi[0] = hi[0], d.hi[1] = hi[2], d.hi[2] = hi[1];
    d.radius_m = 0.6 * spacing;
    d.has_floor = 1, d.floor_m = floor_z;
    d.yaw_deg = 30, d.pitch_deg = 20;
    d.field_name = field, d.field_lo = 0, d.field_hi = field_hi;
    d.time_s = t, d.scale_bar = 1;
    d.title = title;
    ok = pn_render_particles(&d, n, xr, disp, NULL, rgb);
    free(xr), free(disp);
    return ok;
}

PN_RS_UNUSED static int pn_rs_draw(const char *path, size_t n, const float *x, const double *X, double spacing, double t,
                                   const double *lo, const double *hi, double floor_z, const char *field, double scale,
                                   double field_hi, const char *title) {
    unsigned char *rgb = (unsigned char *)malloc(PN_RS_DRAW_W * PN_RS_DRAW_H * 3);
    int ok = rgb && pn_rs_render(rgb, n, x, X, spacing, t, lo, hi, floor_z, field, scale, field_hi, title) &&
             pn_png_write(path, PN_RS_DRAW_W, PN_RS_DRAW_H, rgb);
    free(rgb);
    return ok;
}
#endif

/* A snapshot file of gen/rom_data.c (format: gen/README.md), read whole: the reference points
   X and per frame x, v, F as float. pn_rs_read returns 0 (message on stderr) if the file is
   missing or cut short of `frames` frames (0: as many as it holds). */
typedef struct pn_rs_snap {
    int n, frames;
    double frame_dt;
    float *X;                  /* n x 3                                                     */
    unsigned char *flags;      /* n                                                         */
    float *data;               /* frames x (x n x 3, v n x 3, F n x 9)                      */
} pn_rs_snap;

PN_RS_UNUSED static int pn_rs_read(const char *path, int frames, pn_rs_snap *s) {
    FILE *f = fopen(path, "rb");
    unsigned char h[256];
    long size, off, fb;
    int have;
    memset(s, 0, sizeof *s);
    if (!f) {
        fprintf(stderr, "cannot open %s (make rom-data writes it)\n", path);
        return 0;
    }
    if (fread(h, 1, 256, f) != 256 || memcmp(h, "PNROMS1\n", 8) != 0) {
        fprintf(stderr, "%s is not a snapshot file\n", path);
        fclose(f);
        return 0;
    }
    s->n = (int)((unsigned)h[16] | (unsigned)h[17] << 8 | (unsigned)h[18] << 16 | (unsigned)h[19] << 24);
    memcpy(&s->frame_dt, h + 24, 8);
    fseek(f, 0, SEEK_END);
    size = ftell(f);
    off = 256 + 12L * s->n + (s->n + 3) / 4 * 4;
    fb = 60L * s->n;
    have = (int)((size - off) / fb);
    if (frames <= 0) frames = have;
    if (have < frames) {
        fprintf(stderr, "%s holds %d of %d frames (make rom-data resumes it)\n", path, have, frames);
        fclose(f);
        return 0;
    }
    s->frames = frames;
    s->X = (float *)malloc(sizeof(float) * 3 * (size_t)s->n);
    s->flags = (unsigned char *)malloc((size_t)s->n + 4);
    s->data = (float *)malloc((size_t)fb * (size_t)frames);
    fseek(f, 256, SEEK_SET);
    if (fread(s->X, 4, 3 * (size_t)s->n, f) != 3 * (size_t)s->n || fread(s->flags, 1, (size_t)(s->n + 3) / 4 * 4, f) == 0 ||
        fread(s->data, (size_t)fb, (size_t)frames, f) != (size_t)frames) {
        fprintf(stderr, "%s: short read\n", path);
        fclose(f);
        return 0;
    }
    fclose(f);
    return 1;
}

PN_RS_UNUSED static void pn_rs_free(pn_rs_snap *s) {
    free(s->X), free(s->flags), free(s->data);
    memset(s, 0, sizeof *s);
}

/* frame k's positions (n x 3 floats) */
PN_RS_UNUSED static const float *pn_rs_x(const pn_rs_snap *s, int k) { return s->data + (size_t)k * 15 * (size_t)s->n; }
PN_RS_UNUSED static const float *pn_rs_v(const pn_rs_snap *s, int k) { return s->data + (size_t)k * 15 * (size_t)s->n + 3 * (size_t)s->n; }

#endif /* PN_ROM_SCENES_H */
