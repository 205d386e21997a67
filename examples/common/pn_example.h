/* pn_example.h: what the examples and the MPM benchmark share, so each stays one .c file and a
   one-line build. Include it once, first, in a file that defines PLASTINET_IMPLEMENTATION:
       #define PLASTINET_IMPLEMENTATION
       #include "common/pn_example.h"  // from examples/: plastinet.h, plastinet_mpm.h, the sand and snow models
   Here: a monotonic clock, frames (PNG, animated PNG, PLY points, OBJ surfaces: pn_render.h),
   the scenes of docs/validation.md (sand column, snowball), a stepping helper that tallies
   solver statistics, the command line the examples share, and the mass IoU metric.
   Everything is static; no globals. */
#ifndef PN_EXAMPLE_H
#define PN_EXAMPLE_H
/* clock_gettime under -std=c99; must come before the first system header */
#if !defined(_POSIX_C_SOURCE) && !defined(_WIN32)
#define _POSIX_C_SOURCE 199309L
#endif
#include "../../plastinet.h"
#include "../../plastinet_mpm.h"
#include "../../models/pn_model_sand_2d.h"
#include "../../models/pn_model_sand_3d.h"
#include "../../models/pn_model_snow_2d.h"
#include "../../models/pn_model_snow_3d.h"
#include "pn_render.h"
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef _WIN32
#include <direct.h>
#define pn_ex__mkdir(path) _mkdir(path)
#else
#include <sys/stat.h>
#define pn_ex__mkdir(path) mkdir(path, 0777)
#endif

/* each program uses only some of these helpers */
#if defined(__GNUC__)
#define PN_EX_UNUSED __attribute__((unused))
#else
#define PN_EX_UNUSED
#endif

/* Wall-clock seconds from an arbitrary origin: CLOCK_MONOTONIC where POSIX has it (immune to
   clock changes, counts time lost to other processes), else processor time from clock(). */
PN_EX_UNUSED static double pn_ex_seconds(void) {
#if defined(CLOCK_MONOTONIC)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#else
    return (double)clock() / CLOCKS_PER_SEC;
#endif
}

/* pn_ex_seconds as a pn_mpm_desc.clock_s: the scenes' implicit steps time their stages */
static double pn_ex__clock(void *user) {
    (void)user;
    return pn_ex_seconds();
}

/* Create folder `path` and its parents (like mkdir -p); 1 when it exists afterwards. */
PN_EX_UNUSED static int pn_ex_mkdirs(const char *path) {
    char buf[1024];
    size_t i, n = strlen(path);
    if (n == 0 || n >= sizeof buf) return 0;
    memcpy(buf, path, n + 1);
    for (i = 1; i <= n; ++i)
        if (buf[i] == '/' || buf[i] == 0) {
            char c = buf[i];
            buf[i] = 0;
            if (pn_ex__mkdir(buf) != 0 && errno != EEXIST) return 0;
            buf[i] = c;
        }
    return 1;
}

/* What a frame shows: the scene's box, its floor and colliders, the time, a speed legend. */
typedef struct pn_ex_view {
    int width, height;           /* pixels [960 x 540]                                      */
    double lo[3], hi[3];         /* world box framed (m)                                    */
    double floor_m;              /* < lo[1]: no floor                                       */
    double field_hi;             /* the speed (m/s) at the top of the colour scale [1.5]     */
    const char *title;
} pn_ex_view;

/* Render the active particles of w coloured by speed into rgb (width x height x 3). */
PN_EX_UNUSED static int pn_ex_render(const pn_ex_view *v, const pn_mpm_world *w, unsigned char *rgb) {
    pn_render_desc d;
    pn_render_shape shapes[PN_MPM_MAX_COLLIDERS];
    pn_real *speed = (pn_real *)malloc(sizeof(pn_real) * (w->n ? w->n : 1));
    size_t p;
    int i, c, ok;
    if (!speed) return 0;
    for (p = 0; p < w->n; ++p) {
        double s2 = 0;
        for (i = 0; i < w->dim; ++i) s2 += (double)w->v[p * (size_t)w->dim + (size_t)i] * (double)w->v[p * (size_t)w->dim + (size_t)i];
        speed[p] = (pn_real)sqrt(s2);
    }
    memset(&d, 0, sizeof d);
    d.width = v->width;
    d.height = v->height;
    d.dim = w->dim;
    for (i = 0; i < 3; ++i) d.lo[i] = v->lo[i], d.hi[i] = v->hi[i];
    d.radius_m = 0.3 * (double)w->desc.dx_m; /* 2 per cell per axis: 0.6 x the spacing */
    d.has_floor = v->floor_m >= v->lo[1];
    d.floor_m = v->floor_m;
    d.yaw_deg = 30;
    d.pitch_deg = 20;
    d.field_name = "speed (m/s)";
    d.field_hi = v->field_hi > 0 ? v->field_hi : 1.5;
    d.time_s = (double)w->time_s;
    d.scale_bar = 1;
    d.title = v->title;
    for (c = 0; c < w->n_colliders; ++c) { /* where each collider is now */
        const pn_collider *k = &w->colliders[c];
        memset(&shapes[c], 0, sizeof shapes[c]);
        shapes[c].kind = k->shape == PN_SHAPE_HALF_SPACE ? PN_RENDER_HALF_SPACE
                         : k->shape == PN_SHAPE_BOX       ? PN_RENDER_BOX
                                                              : PN_RENDER_SPHERE;
        for (i = 0; i < 3; ++i) {
            shapes[c].center[i] = (double)(k->center_m[i] + w->time_s * k->velocity_m_s[i]);
            shapes[c].normal[i] = (double)k->normal[i];
            shapes[c].half_extent[i] = (double)k->half_extent_m[i];
        }
        shapes[c].radius = (double)k->radius_m;
    }
    d.shapes = shapes;
    d.n_shapes = w->n_colliders;
    ok = pn_render_particles(&d, w->n, w->x, speed, w->active, rgb);
    free(speed);
    return ok;
}

/* ASCII PLY point cloud of the active particles, "x y z vx vy vz" per vertex (z = vz = 0 in
   2D); Houdini, Blender and ParaView read it. 1 on success. */
PN_EX_UNUSED static int pn_ex_write_ply(const char *path, const pn_mpm_world *w) {
    FILE *f = fopen(path, "w");
    size_t p, n = 0;
    int ok;
    if (!f) return 0;
    for (p = 0; p < w->n; ++p) n += w->active[p];
    fprintf(f, "ply\nformat ascii 1.0\nelement vertex %lu\nproperty float x\nproperty float y\n"
               "property float z\nproperty float vx\nproperty float vy\nproperty float vz\nend_header\n",
            (unsigned long)n);
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim, *v = w->v + p * (size_t)w->dim;
        if (!w->active[p]) continue;
        fprintf(f, "%g %g %g %g %g %g\n", (double)x[0], (double)x[1], w->dim == 3 ? (double)x[2] : 0.0,
                (double)v[0], (double)v[1], w->dim == 3 ? (double)v[2] : 0.0);
    }
    ok = ferror(f) == 0;
    return (fclose(f) == 0) && ok;
}

/* ---- scenes (docs/validation.md) ---------------------------------------------------------

   Both live in a cube of side domain_m (1 m in 2D, 0.5 m in 3D) cut into res cells per axis,
   with walls 3 cells thick (so the floor is at y = 3 dx), gravity 9.81 m/s^2 along -y, and
   2 x 2 (x 2) particles per cell (pn_mpm_fill: a lattice aligned with the grid, or jittered).
   The material is the one the embedded PlasticityNet model was trained for, at Young's
   modulus E_pa.
   - sand column: StVK-Hencky + Drucker-Prager (nu 0.3, friction angle 30 deg), E 1e7 Pa,
     1600 kg/m^3; a column of width W = 0.12 m (a square prism in 3D) and height a W, a = 2,
     standing on the floor at the centre of the domain, at rest.
   - snowball: Neo-Hookean snow + Cam-Clay with hardening (nu 0.3, 45 deg, beta 0.3, xi 3),
     E 1e6 Pa, 400 kg/m^3; a disk (2D, radius 0.1 m) or ball (3D, radius 0.08 m, mid-depth)
     that starts 0.05 domain_m from the left wall and 0.1 domain_m above the floor, thrown at
     3 m/s, 45 deg below the horizontal, towards +x. Its initial h = log J_p = -0.01 sits
     inside the model's trained range [-0.15, 0]; it sets the consolidation pressure
     p0 = kappa sinh(-xi h) (25-29 kPa at E = 1e6), which gives the snow cohesion but is
     exceeded by the impact (about rho c v = 60 kPa, c = sqrt(E / rho)), so the ball breaks
     (at h0 = -0.03 it bounces off whole).
   - snow press: the snowball's snow (initial h -0.01) as a layer 0.15 domain_m deep and
     0.5 domain_m wide (0.5 x 0.5 in 3D) on the floor, pressed by a plate (a box collider
     0.2 domain_m wide, STICKY) that comes down at press_m_s [0.4 domain_m
     per second: 0.4 m/s in 2D, 0.2 in 3D] from the layer's top: a rut compacted by a boot
     or a wheel. The snow compacts under the plate and shears at its edges without the
     snowball's fracture, so its mass field converges as the step shrinks (the snowball's
     does not: docs/results.md).
   Walls: SEPARATE with Coulomb friction 0.5 (the frictional floor); STICKY or SLIP on request. */

typedef enum pn_ex_scene_kind { PN_EX_SAND_COLUMN = 0, PN_EX_SNOWBALL, PN_EX_SNOW_PRESS } pn_ex_scene_kind;

typedef struct pn_ex_scene {
    pn_ex_scene_kind kind;
    int dim;                     /* 2 or 3                                                 */
    int res;                     /* grid cells per axis [64 in 2D, 24 in 3D]               */
    double domain_m;             /* side of the cubic domain [1 in 2D, 0.5 in 3D]           */
    double E_pa;                 /* Young's modulus [sand 1e7, snow 1e6]                    */
    double density_kg_m3;        /* [sand 1600, snow 400]                                   */
    pn_boundary boundary;    /* domain walls [SEPARATE]                                 */
    double friction;             /* Coulomb coefficient of SEPARATE walls [0.5]             */
    double filter_s;             /* transfer filter time (pn_mpm_desc.filter_time_s) [2e-3]  */
    double regularizer;          /* PlasticityNet's w (pn_pnet_desc.regularizer) [0: 1]     */
    pn_energy energy;        /* what implicit steps minimize [PNET]; ignored by explicit */
    double width_m, aspect;      /* sand column: W [0.12], a = H / W [2]                    */
    double radius_m;             /* snowball: [0.1 in 2D, 0.08 in 3D]                       */
    double speed_m_s, angle_deg; /* snowball: throw speed [3] and angle below horizontal [45] */
    double h0;                   /* snowball: initial log J_p [-0.01]                       */
    int no_hardening;            /* snowball: Cam-Clay with h held (no hardening) [0]        */
    double press_m_s;            /* snow press: the plate's speed, downwards [0.4 domain_m/s] */
    int jitter;                  /* particles jittered in their lattice cells [0]           */
    const pn_model *model;       /* the PlasticityNet model [NULL: the scene's own]          */
    double nu, friction_deg;     /* another Poisson ratio / friction angle [0: the model's]:
                                    a PNET energy then needs a model conditioned on them
                                    (pn_model_sand_any_2d)                                  */
} pn_ex_scene;

/* Fill s with the defaults above for a scene kind and dimension. */
PN_EX_UNUSED static void pn_ex_scene_default(pn_ex_scene *s, pn_ex_scene_kind kind, int dim) {
    int sand = kind == PN_EX_SAND_COLUMN;
    memset(s, 0, sizeof *s);
    s->kind = kind;
    s->dim = dim;
    s->res = dim == 2 ? 64 : 24;
    s->domain_m = dim == 2 ? 1.0 : 0.5;
    s->E_pa = sand ? 1e7 : 1e6;
    s->density_kg_m3 = sand ? 1600 : 400;
    s->boundary = PN_BOUNDARY_SEPARATE;
    s->friction = 0.5;
    s->filter_s = 2e-3;
    s->energy = PN_ENERGY_PNET;
    s->width_m = 0.12;
    s->aspect = 2;
    s->radius_m = dim == 2 ? 0.1 : 0.08;
    s->speed_m_s = 3;
    s->angle_deg = 45;
    s->h0 = -0.01;
    s->press_m_s = 0.4 * s->domain_m; /* 0.08 domain_m deep in 0.2 s */
}

#define PN_EX_WALL_CELLS 3

PN_EX_UNUSED static double pn_ex_scene_dx(const pn_ex_scene *s) { return s->domain_m / s->res; }
/* height of the floor (m): the top of the bottom wall */
PN_EX_UNUSED static double pn_ex_scene_floor(const pn_ex_scene *s) { return PN_EX_WALL_CELLS * pn_ex_scene_dx(s); }

PN_EX_UNUSED static const pn_model *pn_ex_scene_model(const pn_ex_scene *s) {
    if (s->model) return s->model;
    if (s->kind == PN_EX_SAND_COLUMN) return s->dim == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
    return s->dim == 2 ? pn_model_snow_2d() : pn_model_snow_3d();
}

/* The scene's world description and its particles as a pn_mpm_fill (group 0). The column
   is snapped to whole lattice cells, so it holds floor(W / spacing) particles across.
   examples/sand_column.c makes the same column with the library's calls (column_world): a
   change to the sand column goes into both. */
static void pn_ex__scene_setup(const pn_ex_scene *s, pn_mpm_desc *wd, pn_mpm_fill_desc *f) {
    int d = s->dim, i;
    double dx = pn_ex_scene_dx(s), sp = dx / 2, fl = pn_ex_scene_floor(s);
    memset(wd, 0, sizeof *wd);
    wd->dim = d;
    for (i = 0; i < d; ++i) wd->res[i] = s->res;
    wd->dx_m = (pn_real)dx;
    wd->gravity[1] = (pn_real)-9.81;
    wd->boundary = s->boundary;
    wd->friction = (pn_real)s->friction;
    wd->filter_time_s = (pn_real)s->filter_s;
    wd->wall_cells = PN_EX_WALL_CELLS;
    wd->clock_s = pn_ex__clock;
    memset(f, 0, sizeof *f);
    f->per_axis = 2;
    f->jitter = s->jitter;
    f->seed = 1;
    if (s->kind == PN_EX_SAND_COLUMN) {
        int na = (int)(s->width_m / sp), nb = (int)(s->aspect * s->width_m / sp);
        double lo = floor((s->domain_m / 2 - na * sp / 2) / sp + 0.5) * sp; /* on a lattice line */
        f->shape = PN_MPM_FILL_BOX;
        for (i = 0; i < d; ++i) {
            f->center_m[i] = (pn_real)(lo + na * sp / 2);
            f->half_extent_m[i] = (pn_real)(na * sp / 2);
        }
        f->center_m[1] = (pn_real)(fl + nb * sp / 2);
        f->half_extent_m[1] = (pn_real)(nb * sp / 2);
    } else if (s->kind == PN_EX_SNOW_PRESS) {
        f->shape = PN_MPM_FILL_BOX;
        for (i = 0; i < d; ++i) {
            f->center_m[i] = (pn_real)(0.5 * s->domain_m);
            f->half_extent_m[i] = (pn_real)(0.25 * s->domain_m);
        }
        f->center_m[1] = (pn_real)(fl + 0.075 * s->domain_m);
        f->half_extent_m[1] = (pn_real)(0.075 * s->domain_m);
        f->state = (pn_real)s->h0;
    } else {
        double a = s->angle_deg * 3.14159265358979 / 180;
        f->shape = PN_MPM_FILL_SPHERE;
        f->center_m[0] = (pn_real)(fl + 0.05 * s->domain_m + s->radius_m); /* the walls are alike */
        f->center_m[1] = (pn_real)(fl + 0.1 * s->domain_m + s->radius_m);
        f->center_m[2] = (pn_real)(0.5 * s->domain_m);
        f->radius_m = (pn_real)s->radius_m;
        f->velocity_m_s[0] = (pn_real)(s->speed_m_s * cos(a));
        f->velocity_m_s[1] = (pn_real)(-s->speed_m_s * sin(a));
        f->state = (pn_real)s->h0; /* the snow's initial consolidation: h = log J_p = h0 */
    }
}

/* Create the world of scene s in *out, filled and ready to step, with the energy s->energy
   bound for implicit steps. On failure *out is NULL, why (why_cap bytes) says what went wrong. */
PN_EX_UNUSED static pn_result pn_ex_scene_create(const pn_ex_scene *s, pn_mpm_world **out, char *why,
                                                    size_t why_cap) {
    const pn_model *model;
    pn_mpm_desc wd;
    pn_mpm_fill_desc f;
    pn_mpm_world *w = NULL;
    pn_material m;
    size_t n = 0;
    int g, d = s->dim, i;
    pn_result r;
    *out = NULL;
    if (why[0] && why_cap) why[0] = 0;
    if ((d != 2 && d != 3) || s->res < 16 || s->res > 1024 || !(s->domain_m > 0)) {
        snprintf(why, why_cap, "dim must be 2 or 3, res in [16, 1024], domain_m > 0");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    model = pn_ex_scene_model(s);
    if ((r = pn_model_check(model, d, why, why_cap)) != PN_OK) return r;
    { /* the model's material, or another Poisson ratio or friction angle */
        pn_material_desc md;
        pn_model_material_desc(model, (pn_real)s->E_pa, &md);
        if (s->nu > 0) md.poisson_ratio = (pn_real)s->nu;
        if (s->friction_deg > 0) md.friction_angle_deg = (pn_real)s->friction_deg;
        if ((r = pn_material_init(&m, &md, why, why_cap)) != PN_OK) return r;
    }
    if (s->no_hardening) m.camclay_hardening = 0;
    pn_ex__scene_setup(s, &wd, &f);
    if ((r = pn_mpm_fill_count(&wd, &f, &n, why, why_cap)) != PN_OK) return r;
    if (n == 0) {
        snprintf(why, why_cap, "the scene has no particles (size below half a cell)");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    wd.max_particles = n;
    if ((r = pn_mpm_create(&wd, &w, why, why_cap)) != PN_OK) return r;
    if ((g = pn_mpm_add_group(w, &m, (pn_real)s->density_kg_m3)) < 0) {
        r = PN_ERROR_INVALID_ARGUMENT;
        goto fail;
    }
    f.group = g;
    if ((r = pn_mpm_fill(w, &f, NULL)) != PN_OK) goto fail;
    if (s->kind == PN_EX_SNOW_PRESS) { /* the plate, its lower face on the layer's top at t = 0 */
        pn_collider c;
        memset(&c, 0, sizeof c);
        c.shape = PN_SHAPE_BOX;
        /* sticky, as snow under a sole: with a separating plate (Coulomb 0.5) 20-40 particles
           squeezed at its edges flew off at 4-11 m/s, by an amount that depended on the step */
        c.boundary = PN_BOUNDARY_STICKY;
        for (i = 0; i < d; ++i) {
            c.center_m[i] = (pn_real)(0.5 * s->domain_m);
            c.half_extent_m[i] = (pn_real)(0.1 * s->domain_m);
        }
        c.half_extent_m[1] = (pn_real)(0.05 * s->domain_m);
        c.center_m[1] = (pn_real)(pn_ex_scene_floor(s) + 0.15 * s->domain_m + 0.05 * s->domain_m);
        c.velocity_m_s[1] = (pn_real)-s->press_m_s;
        if ((r = pn_mpm_add_collider(w, &c, NULL)) != PN_OK) goto fail;
    }
    if (s->energy == PN_ENERGY_PNET) {
        pn_pnet net;
        pn_pnet_desc nd;
        memset(&nd, 0, sizeof nd);
        nd.energy = model;
        nd.regularizer = (pn_real)s->regularizer;
        if ((r = pn_pnet_init(&net, &nd, &m, d, why, why_cap)) != PN_OK) {
            pn_mpm_destroy(w);
            return r;
        }
        r = pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, &net);
    } else {
        r = pn_mpm_group_set_energy(w, g, s->energy, NULL);
    }
    if (r != PN_OK) goto fail;
    *out = w;
    return PN_OK;
fail:
    snprintf(why, why_cap, "%s", pn_mpm_error(w));
    pn_mpm_destroy(w);
    return r;
}

/* How a scene is framed in pictures: the whole domain in 3D; in 2D the floor and the space
   the material reaches, at 16:9. */
PN_EX_UNUSED static void pn_ex_scene_view(const pn_ex_scene *s, pn_ex_view *v) {
    double L = s->domain_m;
    memset(v, 0, sizeof *v);
    v->width = 960;
    v->height = 540;
    v->floor_m = pn_ex_scene_floor(s);
    v->field_hi = s->kind == PN_EX_SAND_COLUMN ? 1.5 : s->kind == PN_EX_SNOW_PRESS ? 0.5 : 3;
    v->title = s->kind == PN_EX_SAND_COLUMN ? "sand column" : s->kind == PN_EX_SNOW_PRESS ? "snow press" : "snowball";
    v->hi[0] = v->hi[1] = v->hi[2] = L;
    if (s->dim == 2) {
        double w = s->kind == PN_EX_SNOWBALL ? L : 0.8 * L;
        v->lo[0] = (L - w) / 2;
        v->hi[0] = (L + w) / 2;
        v->hi[1] = w * 9 / 16;
    }
}

/* ---- stepping --------------------------------------------------------------------------- */

/* Solver statistics summed over steps. */
typedef struct pn_ex_tally {
    long steps, newton, cg, fixed_point, line_search_failures;
    long halved;                     /* implicit steps retried as substeps (the fallback)    */
    double max_fixed_point_residual; /* max_q |F0_new - F0| at the end of a step, worst step  */
    double max_speed_m_s;            /* fastest particle after any step                      */
    double max_dt_over_cfl;          /* largest step over pn_mpm_stable_dt at its start      */
    long cg_capped;                  /* Newton steps whose linear solve stopped at cg_max    */
    long sweeps;                     /* stress formulation: Gauss-Seidel sweeps              */
    long coarse, coarse_rejected;    /* stress formulation: coarse corrections, those undone  */
    double stage_s[PN_MPM_STAGES];   /* implicit: seconds per pn_mpm_stage (the scenes' clock) */
    /* pn_mpm_implicit_desc.measure_force_error: per-step values summed (mean = sum / steps) */
    double force_error, force_error_regularizer, apex_fraction;
} pn_ex_tally;

/* Adds one step's statistics st (pn_mpm_step_implicit's when implicit, else
   pn_mpm_step_explicit's) to *t. */
PN_EX_UNUSED static void pn_ex_tally_step(pn_ex_tally *t, const pn_mpm_stats *st, int implicit) {
    int i;
    if (implicit && (double)st->dt_over_cfl > t->max_dt_over_cfl) t->max_dt_over_cfl = (double)st->dt_over_cfl;
    t->cg_capped += st->cg_capped;
    t->sweeps += st->sweeps;
    t->coarse += st->coarse_corrections;
    t->coarse_rejected += st->coarse_rejected;
    if (implicit)
        for (i = 0; i < PN_MPM_STAGES; ++i) t->stage_s[i] += st->stage_s[i];
    t->steps++;
    t->newton += st->newton_iters;
    t->cg += st->cg_iters;
    t->fixed_point += st->fixed_point_iters;
    t->line_search_failures += st->line_search_failures;
    t->halved += implicit && st->substeps > 1;
    if ((double)st->fixed_point_residual > t->max_fixed_point_residual)
        t->max_fixed_point_residual = (double)st->fixed_point_residual;
    if ((double)st->max_speed_m_s > t->max_speed_m_s) t->max_speed_m_s = (double)st->max_speed_m_s;
    t->force_error += (double)st->force_error;
    t->force_error_regularizer += (double)st->force_error_regularizer;
    t->apex_fraction += (double)st->apex_fraction;
}

/* n steps of dt_s seconds, implicit (with id, which may be NULL for its defaults) or explicit;
   adds to *t. Stops at the first failed step and returns its code (pn_mpm_error says why;
   the world stays as before that step). */
PN_EX_UNUSED static pn_result pn_ex_steps(pn_mpm_world *w, int implicit, double dt_s,
                                          const pn_mpm_implicit_desc *id, long n, pn_ex_tally *t) {
    long k;
    for (k = 0; k < n; ++k) {
        pn_mpm_stats st;
        pn_real cfl = 0;
        pn_result r;
        /* an explicit step does not compute its bound: once per call is enough here */
        if (!implicit && k == 0 && pn_mpm_stable_dt(w, &cfl) == PN_OK && dt_s / (double)cfl > t->max_dt_over_cfl)
            t->max_dt_over_cfl = dt_s / (double)cfl;
        r = implicit ? pn_mpm_step_implicit(w, (pn_real)dt_s, id, &st) : pn_mpm_step_explicit(w, (pn_real)dt_s, &st);
        if (r != PN_OK) return r;
        pn_ex_tally_step(t, &st, implicit);
    }
    return PN_OK;
}

/* One frame of frame_s seconds in explicit steps of pn_mpm_stable_dt (pn_mpm_advance); adds
   them to *t. Returns the first failure's code (pn_mpm_error says why). */
PN_EX_UNUSED static pn_result pn_ex_advance_explicit(pn_mpm_world *w, double frame_s, pn_ex_tally *t) {
    pn_mpm_advance_desc a;
    pn_mpm_stats st;
    pn_result r;
    memset(&a, 0, sizeof a);
    a.integrator = PN_MPM_EXPLICIT;
    if ((r = pn_mpm_advance(w, (pn_real)frame_s, &a, &st)) != PN_OK) return r;
    t->steps += st.substeps;
    if ((double)st.dt_over_cfl > t->max_dt_over_cfl) t->max_dt_over_cfl = (double)st.dt_over_cfl;
    if ((double)st.max_speed_m_s > t->max_speed_m_s) t->max_speed_m_s = (double)st.max_speed_m_s;
    return PN_OK;
}

/* Ends an example's JSON line: the means over the steps of the force-error statistics when they
   were measured (--force-error, implicit), then the closing brace. */
PN_EX_UNUSED static void pn_ex_json_end(const pn_ex_tally *t, int measured) {
    if (measured && t->steps > 0)
        printf(", \"force_error\": %.4f, \"force_error_regularizer\": %.4f, \"apex_fraction\": %.3f",
               t->force_error / (double)t->steps, t->force_error_regularizer / (double)t->steps,
               t->apex_fraction / (double)t->steps);
    printf("}\n");
}

/* ---- the command line every example shares --------------------------------------------- */

static const char *const pn_ex_walls[] = {"sticky", "slip", "separate"};

typedef struct pn_ex_cli {
    int dim, implicit, frames, fps, res, png, ply, obj, apng, quiet, boundary, jitter;
    pn_mpm_implicit_desc solver; /* --fixed-point, --contact-rounds, --newton-tol, --cg-tol,
                                    --cg-forcing, --force-error                            */
    double dt;                   /* the step (s); 0: the integrator's default (implicit 1e-3,
                                    explicit pn_mpm_stable_dt before each step)            */
    double E, friction, filter;  /* filter < 0: the scene's default                        */
    double regularizer;          /* PlasticityNet's w (0: 1, < 0: off)                     */
    const char *energy, *out;    /* the energy's name as given; the example maps it        */
} pn_ex_cli;

/* defaults: 2D, implicit, pnet, the energy formulation, dt 0 (implicit 1e-3 s, explicit the
   stable step), 1 pass, 30 frames at 30 fps, the scene's res and E (0: the scene's default),
   separate walls with friction 0.5, particles on the lattice, frames into out. An example
   may change these before parsing; pn_ex_cli_usage prints them. */
PN_EX_UNUSED static void pn_ex_cli_default(pn_ex_cli *c, const char *out) {
    memset(c, 0, sizeof *c);
    c->dim = 2;
    c->implicit = 1;
    c->solver.fixed_point_iters = 1;
    c->solver.contact_rounds = 1;
    c->frames = c->fps = 30;
    c->boundary = PN_BOUNDARY_SEPARATE;
    c->friction = 0.5;
    c->filter = -1;
    c->energy = "pnet";
    c->out = out;
}

/* flag a has its value v; says so on stderr otherwise */
PN_EX_UNUSED static int pn_ex__need(const char *prog, const char *a, const char *v) {
    if (!v) fprintf(stderr, "%s: %s needs a value (--help lists the flags)\n", prog, a);
    return v != NULL;
}

/* v as a number for flag a; says what is wrong on stderr (prog: the program) otherwise */
PN_EX_UNUSED static int pn_ex_number(const char *prog, const char *a, const char *v, double *out) {
    char *end = NULL;
    double x;
    if (!pn_ex__need(prog, a, v)) return 0;
    x = strtod(v, &end);
    if (end == v || *end || x != x) {
        fprintf(stderr, "%s: %s needs a number, not '%s'\n", prog, a, v);
        return 0;
    }
    *out = x;
    return 1;
}

PN_EX_UNUSED static int pn_ex_integer(const char *prog, const char *a, const char *v, int *out) {
    double x;
    if (!pn_ex_number(prog, a, v, &x)) return 0;
    if (x != floor(x) || x < -1e9 || x > 1e9) {
        fprintf(stderr, "%s: %s needs a whole number, not '%s'\n", prog, a, v);
        return 0;
    }
    *out = (int)x;
    return 1;
}

/* v one of the n names for flag a: its index; -1 (said on stderr) otherwise */
PN_EX_UNUSED static int pn_ex_choice(const char *prog, const char *a, const char *v, const char *const *names, int n) {
    int i;
    if (!pn_ex__need(prog, a, v)) return -1;
    for (i = 0; i < n; ++i)
        if (!strcmp(v, names[i])) return i;
    fprintf(stderr, "%s: %s must be one of", prog, a);
    for (i = 0; i < n; ++i) fprintf(stderr, " %s", names[i]);
    fprintf(stderr, ", not '%s'\n", v);
    return -1;
}

/* If flag a (with its value v, NULL at the end) is a shared one, take it: returns how many
   arguments it used (1 or 2); 0 for a flag the example must handle; -1 for a bad or missing
   value (said on stderr). Flags match whole words only. */
PN_EX_UNUSED static int pn_ex_cli_flag(const char *prog, pn_ex_cli *c, const char *a, const char *v) {
    static const char *const integrators[] = {"explicit", "implicit"};
    static const char *const linear[] = {"default", "jacobi", "multigrid"};
    double x = 0;
    int ok = 1;
    if (!strcmp(a, "--png")) return c->png = 1;
    if (!strcmp(a, "--ply")) return c->ply = 1;
    if (!strcmp(a, "--obj")) return c->obj = 1;
    if (!strcmp(a, "--apng")) return c->apng = 1;
    if (!strcmp(a, "--jitter")) return c->jitter = 1;
    if (!strcmp(a, "--lattice")) return (c->jitter = 0) + 1;
    if (!strcmp(a, "--quiet")) return c->quiet = 1;
    if (!strcmp(a, "--force-error")) return c->solver.measure_force_error = 1;
    if (!strcmp(a, "--pnet-double")) return c->solver.pnet_double = 1;
    if (!strcmp(a, "--dim")) ok = pn_ex_integer(prog, a, v, &c->dim);
    else if (!strcmp(a, "--integrator")) ok = (c->implicit = pn_ex_choice(prog, a, v, integrators, 2)) >= 0;
    else if (!strcmp(a, "--energy")) ok = pn_ex__need(prog, a, v), c->energy = v;
    else if (!strcmp(a, "--boundary")) ok = (c->boundary = pn_ex_choice(prog, a, v, pn_ex_walls, 3)) >= 0;
    else if (!strcmp(a, "--friction")) ok = pn_ex_number(prog, a, v, &c->friction);
    else if (!strcmp(a, "--filter")) ok = pn_ex_number(prog, a, v, &c->filter);
    else if (!strcmp(a, "--regularizer")) ok = pn_ex_number(prog, a, v, &c->regularizer);
    else if (!strcmp(a, "--dt")) ok = pn_ex_number(prog, a, v, &c->dt);
    else if (!strcmp(a, "--fixed-point")) ok = pn_ex_integer(prog, a, v, &c->solver.fixed_point_iters);
    else if (!strcmp(a, "--contact-rounds")) ok = pn_ex_integer(prog, a, v, &c->solver.contact_rounds);
    else if (!strcmp(a, "--newton-tol")) ok = pn_ex_number(prog, a, v, &x), c->solver.newton_tol = (pn_real)x;
    else if (!strcmp(a, "--cg-tol")) ok = pn_ex_number(prog, a, v, &x), c->solver.cg_rel_tol = (pn_real)x;
    else if (!strcmp(a, "--cg-forcing")) ok = pn_ex_number(prog, a, v, &x), c->solver.cg_forcing_max = (pn_real)x;
    else if (!strcmp(a, "--linear")) {
        int k = pn_ex_choice(prog, a, v, linear, 3);
        ok = k >= 0;
        c->solver.linear_solver = (pn_mpm_linear_solver)(k < 0 ? 0 : k);
    } else if (!strcmp(a, "--formulation")) {
        static const char *const forms[] = {"energy", "stress"};
        int k = pn_ex_choice(prog, a, v, forms, 2);
        ok = k >= 0;
        c->solver.formulation = (pn_mpm_formulation)(k < 0 ? 0 : k);
    } else if (!strcmp(a, "--sweeps")) ok = pn_ex_integer(prog, a, v, &c->solver.sweeps_max);
    else if (!strcmp(a, "--coarse-every")) ok = pn_ex_integer(prog, a, v, &c->solver.coarse_every);
    else if (!strcmp(a, "--coarse-cg")) ok = pn_ex_integer(prog, a, v, &c->solver.coarse_cg);
    else if (!strcmp(a, "--coarse-tol")) ok = pn_ex_number(prog, a, v, &x), c->solver.coarse_tol = (pn_real)x;
    else if (!strcmp(a, "--sweep-tol")) ok = pn_ex_number(prog, a, v, &x), c->solver.sweep_tol = (pn_real)x;
    else if (!strcmp(a, "--anderson")) {
        static const char *const onoff[] = {"on", "off"};
        int k = pn_ex_choice(prog, a, v, onoff, 2);
        ok = k >= 0;
        c->solver.anderson = k == 1 ? -1 : 0;
    }
    else if (!strcmp(a, "--cell-relax")) ok = pn_ex_number(prog, a, v, &x), c->solver.cell_relax = (pn_real)x;
    else if (!strcmp(a, "--stress-unknowns")) {
        static const char *const where[] = {"particles", "cells", "cells-then-particles"};
        int k = pn_ex_choice(prog, a, v, where, 3);
        ok = k >= 0;
        c->solver.stress_unknowns = (pn_mpm_stress_unknowns)(k < 0 ? 0 : k);
    }
    else if (!strcmp(a, "--mg-levels")) ok = pn_ex_integer(prog, a, v, &c->solver.mg_levels);
    else if (!strcmp(a, "--mg-rebuild")) ok = pn_ex_integer(prog, a, v, &c->solver.mg_rebuild);
    else if (!strcmp(a, "--frames")) ok = pn_ex_integer(prog, a, v, &c->frames);
    else if (!strcmp(a, "--fps")) ok = pn_ex_integer(prog, a, v, &c->fps);
    else if (!strcmp(a, "--E")) ok = pn_ex_number(prog, a, v, &c->E);
    else if (!strcmp(a, "--res")) ok = pn_ex_integer(prog, a, v, &c->res);
    else if (!strcmp(a, "--out")) ok = pn_ex__need(prog, a, v), c->out = v ? v : c->out;
    else return 0;
    return ok ? 2 : -1;
}

/* The shared flags in range (naming the first that is not, on stderr), and scene s (made with
   pn_ex_scene_default for c->dim) set from them. Returns 0 when a value is out of range. */
PN_EX_UNUSED static int pn_ex_cli_apply(const char *prog, const pn_ex_cli *c, pn_ex_scene *s) {
    const char *bad = NULL;
    if (c->dim != 2 && c->dim != 3) bad = "--dim must be 2 or 3";
    else if (!(c->friction >= 0)) bad = "--friction must be >= 0";
    else if (!(c->dt >= 0)) bad = "--dt must be > 0 (0: the integrator's default)";
    else if (c->solver.fixed_point_iters < 1) bad = "--fixed-point must be >= 1";
    else if (c->solver.contact_rounds < 1) bad = "--contact-rounds must be >= 1";
    else if (!(c->solver.newton_tol >= 0)) bad = "--newton-tol must be >= 0 (0: the default)";
    else if (!(c->solver.cg_rel_tol >= 0 && c->solver.cg_rel_tol < 1)) bad = "--cg-tol must be in [0, 1)";
    else if (!(c->solver.cg_forcing_max >= 0 && c->solver.cg_forcing_max < 1)) bad = "--cg-forcing must be in [0, 1)";
    else if (c->solver.mg_levels < 0 || c->solver.mg_levels > 8) bad = "--mg-levels must be in 1 .. 8 (0: the default)";
    else if (c->solver.mg_rebuild < 0 || c->solver.mg_rebuild > 1) bad = "--mg-rebuild must be 0 or 1";
    else if (c->frames < 1) bad = "--frames must be >= 1";
    else if (c->fps < 1) bad = "--fps must be >= 1";
    else if (!(c->E >= 0)) bad = "--E must be > 0";
    else if (c->res && (c->res < 16 || c->res > 1024)) bad = "--res must be in 16 .. 1024";
    else if (!(c->filter >= 0 || c->filter == -1)) bad = "--filter must be >= 0";
    if (bad) {
        fprintf(stderr, "%s: %s\n", prog, bad);
        return 0;
    }
    if (c->filter >= 0) s->filter_s = c->filter;
    s->regularizer = c->regularizer;
    if (c->res) s->res = c->res;
    if (c->E > 0) s->E_pa = c->E;
    s->boundary = (pn_boundary)c->boundary;
    s->friction = c->friction;
    s->jitter = c->jitter;
    return 1;
}

/* The flags every example takes, for its --help, with the example's defaults d (what
   pn_ex_cli_default gave, as the example changed it). Each example lists its own --energy
   names: they differ. */
PN_EX_UNUSED static void pn_ex_cli_usage(FILE *f, const pn_ex_cli *d) {
    int stress = d->solver.formulation == PN_MPM_FORMULATION_STRESS;
    fprintf(f, "  --dim 2|3                  dimension [2]\n"
               "  --integrator implicit|explicit  [%s]\n"
               "  --dt S                     step (s) [implicit 1e-3; explicit: pn_mpm_stable_dt before each\n"
               "                             step (pn_mpm_advance), a fixed step only when --dt is given]\n"
               "  --frames N  --fps N        frames and frames per second [%d, %d]\n"
               "  --res N                    grid cells per axis [64 in 2D, 24 in 3D]\n"
               "  --E PA                     Young's modulus [the scene's]\n"
               "  --boundary sticky|slip|separate  --friction MU   the domain walls [separate, 0.5]\n"
               "  --filter S                 transfer filter time (pn_mpm_desc.filter_time_s) [2e-3; 0: APIC]\n"
               "  --regularizer W            PlasticityNet's w [1; < 0: off]\n"
               "  --fixed-point N  --contact-rounds N  --newton-tol X  --cg-tol X  --cg-forcing X\n"
               "                             pn_mpm_implicit_desc [1, 1, and the library's defaults]\n"
               "  --linear jacobi|multigrid  --mg-levels N  --mg-rebuild 0|1\n"
               "                             the Newton systems' solver (pn_mpm_implicit_desc) [multigrid, 8, 0]\n"
               "  --formulation energy|stress  --sweeps N  --sweep-tol X  --anderson on|off\n"
               "                             what implicit steps solve for; the stress formulation's Gauss-Seidel\n"
               "                             sweeps, tolerance and Anderson acceleration (pn_mpm_implicit_desc)\n"
               "                             [%s, 1000, 1e-4, on]\n"
               "  --coarse-every N  --coarse-cg N  --coarse-tol X\n"
               "                             the stress formulation's coarse correction on elastic material: after\n"
               "                             every N sweeps, CG to X in at most N iterations (pn_mpm_implicit_desc)\n"
               "                             [4, 50, 1e-3; --coarse-every -1: never]\n"
               "  --stress-unknowns particles|cells|cells-then-particles  --cell-relax X\n"
               "                             where the stress formulation's stresses live, and the cells'\n"
               "                             over-relaxation (pn_mpm_implicit_desc) [particles; 1, or 1.8 without\n"
               "                             the acceleration]\n"
               "  --pnet-double              PlasticityNet one particle at a time in double (the reference;\n"
               "                             default: its network in float vector lanes)\n"
               "  --force-error              measure the energy's force error (pn_mpm_stats)\n"
               "  --jitter  --lattice        particles jittered in their lattice cells, or on the lattice [%s]\n"
               "  --out DIR                  where frames go (created) [%s]\n"
               "  --png  --apng  --ply  --obj   frames as PNG pictures, one animated PNG (DIR/preview.png),\n"
               "                             PLY points, OBJ surfaces (3D; marching tetrahedra)\n"
               "  --quiet                    no progress line\n"
               "  --help                     this text\n",
            d->implicit ? "implicit" : "explicit", d->frames, d->fps, stress ? "stress" : "energy",
            d->jitter ? "jitter" : "lattice", d->out);
}

/* ---- frames and the run loop ------------------------------------------------------------ */

/* What a run writes, and the picture buffer. */
typedef struct pn_ex_output {
    const char *out;
    int png, ply, obj;
    pn_apng *apng;
    unsigned char *rgb;
    pn_ex_view view;
} pn_ex_output;

/* Get ready to write the frames the command line c asks for, framed as view v: the folder,
   the picture buffer, the animated preview. Returns 0 after a failure (said on stderr;
   nothing to close). */
PN_EX_UNUSED static int pn_ex_output_open(const char *prog, const pn_ex_cli *c, const pn_ex_view *v, pn_ex_output *o) {
    char path[1024];
    memset(o, 0, sizeof *o);
    o->out = c->out;
    o->png = c->png;
    o->ply = c->ply;
    o->obj = c->obj;
    o->view = *v;
    if ((c->png || c->apng || c->ply || c->obj) && !pn_ex_mkdirs(c->out)) {
        fprintf(stderr, "%s: cannot create the folder %s\n", prog, c->out);
        return 0;
    }
    if (c->png || c->apng) {
        o->rgb = (unsigned char *)malloc((size_t)v->width * (size_t)v->height * 3);
        snprintf(path, sizeof path, "%s/preview.png", c->out);
        if (!o->rgb || (c->apng && !(o->apng = pn_apng_open(path, v->width, v->height, c->fps)))) {
            fprintf(stderr, "%s: cannot start %s\n", prog, c->apng ? path : "the pictures");
            free(o->rgb);
            o->rgb = NULL;
            return 0;
        }
    }
    return 1;
}

/* Finish the animated preview and free the picture buffer. Returns ok, or 0 when the
   preview cannot be finished (said on stderr). */
PN_EX_UNUSED static int pn_ex_output_close(const char *prog, pn_ex_output *o, int ok) {
    if (o->apng && !pn_apng_close(o->apng) && ok) {
        fprintf(stderr, "%s: cannot finish %s/preview.png\n", prog, o->out);
        ok = 0;
    }
    o->apng = NULL;
    free(o->rgb);
    o->rgb = NULL;
    return ok;
}

#ifndef PN_NO_FEM /* the examples that simulate only particles leave FEM out */
/* ---- FEM meshes: VTU (ParaView) with per-element fields, OBJ surfaces (Blender) ---- */

/* VTK unstructured grid of mesh m at its positions (quadratic elements as VTK's quadratic
   cells), n_fields per-element arrays (names[f], fields[f][e]); 1 on success */
PN_EX_UNUSED static int pn_ex_write_vtu(const char *path, const pn_fem_mesh *m, int n_fields, const char *const *names,
                                        const double *const *fields) {
    FILE *f = fopen(path, "w");
    static const int vtk10[10] = {0, 1, 2, 3, 4, 5, 6, 7, 9, 8}; /* VTK's edge order: 01 12 20 30 31 32 */
    int d = m->dim, dp = m->nodes_per_element, a, q;
    size_t k, e;
    if (!f) return 0;
    fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
               "<UnstructuredGrid><Piece NumberOfPoints=\"%lu\" NumberOfCells=\"%lu\">\n<Points><DataArray type=\"Float64\" "
               "NumberOfComponents=\"3\" format=\"ascii\">\n",
            (unsigned long)m->n_nodes, (unsigned long)m->n_elems);
    for (k = 0; k < m->n_nodes; ++k)
        fprintf(f, "%.9g %.9g %.9g\n", (double)m->x[k * (size_t)d], (double)m->x[k * (size_t)d + 1], d == 3 ? (double)m->x[k * 3 + 2] : 0.0);
    fprintf(f, "</DataArray></Points>\n<Cells><DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    for (e = 0; e < m->n_elems; ++e) {
        for (a = 0; a < dp; ++a) fprintf(f, "%d ", m->elem[e * (size_t)dp + (size_t)(dp == 10 ? vtk10[a] : a)]);
        fputc('\n', f);
    }
    fprintf(f, "</DataArray><DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for (e = 0; e < m->n_elems; ++e) fprintf(f, "%lu\n", (unsigned long)((e + 1) * (size_t)dp));
    fprintf(f, "</DataArray><DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for (e = 0; e < m->n_elems; ++e) /* VTK_TRIANGLE, VTK_TETRA, VTK_QUADRATIC_TRIANGLE, _TETRA */
        fprintf(f, "%d\n", m->order == 2 ? (d == 2 ? 22 : 24) : (d == 2 ? 5 : 10));
    fprintf(f, "</DataArray></Cells>\n<CellData>");
    for (q = 0; q < n_fields; ++q) {
        fprintf(f, "<DataArray type=\"Float64\" Name=\"%s\" format=\"ascii\">\n", names[q]);
        for (e = 0; e < m->n_elems; ++e) fprintf(f, "%.6g\n", fields[q][e]);
        fprintf(f, "</DataArray>");
    }
    fprintf(f, "</CellData>\n</Piece></UnstructuredGrid></VTKFile>\n");
    return fclose(f) == 0;
}

PN_EX_UNUSED static int pn_ex__cmp3(const void *pa, const void *pb) {
    const int *a = (const int *)pa, *b = (const int *)pb;
    int i;
    for (i = 0; i < 3; ++i)
        if (a[i] != b[i]) return a[i] < b[i] ? -1 : 1;
    return 0;
}

/* OBJ of mesh m: 3D its surface (the faces of one tetrahedron only), 2D the triangles (of
   quadratic elements: their corners) */
PN_EX_UNUSED static int pn_ex_write_mesh_obj(const char *path, const pn_fem_mesh *m) {
    FILE *f = fopen(path, "w");
    static const int face[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}}; /* outward for det > 0 */
    int d = m->dim, np = m->nodes_per_element;
    size_t k, e, nf;
    int *keys;
    if (!f) return 0;
    for (k = 0; k < m->n_nodes; ++k)
        fprintf(f, "v %.9g %.9g %.9g\n", (double)m->x[k * (size_t)d], (double)m->x[k * (size_t)d + 1], d == 3 ? (double)m->x[k * 3 + 2] : 0.0);
    if (d == 2) {
        for (e = 0; e < m->n_elems; ++e)
            fprintf(f, "f %d %d %d\n", m->elem[np * e] + 1, m->elem[np * e + 1] + 1, m->elem[np * e + 2] + 1);
        return fclose(f) == 0;
    }
    nf = 4 * m->n_elems; /* sorted keys: a face is on the surface when it occurs once */
    keys = (int *)malloc(sizeof(int) * 4 * (nf ? nf : 1));
    if (!keys) {
        fclose(f);
        return 0;
    }
    for (e = 0; e < m->n_elems; ++e)
        for (k = 0; k < 4; ++k) {
            int *q = keys + 4 * (4 * e + k), a, b, t;
            for (a = 0; a < 3; ++a) q[a] = m->elem[(size_t)np * e + (size_t)face[k][a]];
            for (a = 0; a < 3; ++a) /* sort the three for the comparison */
                for (b = a + 1; b < 3; ++b)
                    if (q[b] < q[a]) t = q[a], q[a] = q[b], q[b] = t;
            q[3] = (int)(4 * e + k);
        }
    qsort(keys, nf, sizeof(int) * 4, pn_ex__cmp3);
    for (k = 0; k < nf; ++k) {
        int *q = keys + 4 * k, same = (k > 0 && !pn_ex__cmp3(q, q - 4)) || (k + 1 < nf && !pn_ex__cmp3(q, q + 4));
        if (!same) {
            size_t ee = (size_t)q[3] / 4, ff = (size_t)q[3] % 4;
            fprintf(f, "f %d %d %d\n", m->elem[(size_t)np * ee + (size_t)face[ff][0]] + 1,
                    m->elem[(size_t)np * ee + (size_t)face[ff][1]] + 1, m->elem[(size_t)np * ee + (size_t)face[ff][2]] + 1);
        }
    }
    free(keys);
    return fclose(f) == 0;
}
#endif

/* OBJ iso-surface of the active particles (3D), for Blender */
static int pn_ex__write_obj(const char *path, const pn_mpm_world *w) {
    pn_mesh mesh;
    int ok;
    memset(&mesh, 0, sizeof mesh);
    if (w->dim != 3) return 1;
    ok = pn_iso_from_particles(w->n, w->x, w->active, (double)w->desc.dx_m / 4, (double)w->desc.dx_m / 8, &mesh) &&
         pn_mesh_write_obj(path, &mesh);
    pn_mesh_free(&mesh);
    return ok;
}

/* The outputs of frame `frame` (pictures, points, surfaces). Says what failed on stderr
   (prog: the program's name) and returns 0 then. */
PN_EX_UNUSED static int pn_ex_outputs(const char *prog, const pn_mpm_world *w, pn_ex_output *o, int frame) {
    char path[1024];
    if ((o->png || o->apng) && !pn_ex_render(&o->view, w, o->rgb)) {
        fprintf(stderr, "\n%s: out of memory for a picture\n", prog);
        return 0;
    }
    snprintf(path, sizeof path, "%s/frame_%04d.png", o->out, frame);
    if (o->png && !pn_png_write(path, o->view.width, o->view.height, o->rgb)) {
        fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
        return 0;
    }
    if (o->apng && !pn_apng_add(o->apng, o->rgb)) {
        fprintf(stderr, "\n%s: cannot write %s/preview.png\n", prog, o->out);
        return 0;
    }
    snprintf(path, sizeof path, "%s/frame_%04d.ply", o->out, frame);
    if (o->ply && !pn_ex_write_ply(path, w)) {
        fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
        return 0;
    }
    snprintf(path, sizeof path, "%s/frame_%04d.obj", o->out, frame);
    if (o->obj && !pn_ex__write_obj(path, w)) {
        fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
        return 0;
    }
    return 1;
}

/* An example's whole run: frames of 1/fps s at dt_s (implicit steps with the settings id;
   dt_s 0: 1e-3 s implicit, explicit steps of pn_mpm_stable_dt), the outputs of each frame,
   a progress line on stderr unless quiet; *wall_s gets the wall seconds of the steps (not
   of the outputs). Returns 0 after a failure (said on stderr). */
PN_EX_UNUSED static int pn_ex_run(const char *prog, pn_mpm_world *w, int implicit, double dt_s,
                                  const pn_mpm_implicit_desc *id, int frames, int fps, pn_ex_output *o, int quiet,
                                  pn_ex_tally *tally, double *wall_s) {
    int stable = !implicit && !(dt_s > 0), frame;
    long steps_per_frame;
    if (implicit && !(dt_s > 0)) dt_s = 1e-3;
    steps_per_frame = stable ? 0 : (long)(1.0 / fps / dt_s + 0.5);
    memset(tally, 0, sizeof *tally);
    *wall_s = 0;
    if (steps_per_frame < 1) steps_per_frame = 1;
    for (frame = 1; frame <= frames; ++frame) {
        double t0 = pn_ex_seconds();
        pn_result r = stable ? pn_ex_advance_explicit(w, 1.0 / fps, tally)
                             : pn_ex_steps(w, implicit, dt_s, id, steps_per_frame, tally);
        *wall_s += pn_ex_seconds() - t0;
        if (r != PN_OK) {
            fprintf(stderr, "\n%s: step %ld failed: %s (%s)\n", prog, tally->steps + 1, pn_mpm_error(w),
                    pn_result_string(r));
            return 0;
        }
        if (!pn_ex_outputs(prog, w, o, frame)) return 0;
        if (!quiet)
            fprintf(stderr, "\rframe %d/%d  t = %.3f s  wall %.1f s  Newton/step %.1f  CG/step %.0f   ", frame, frames,
                    (double)w->time_s, *wall_s, implicit ? (double)tally->newton / (double)tally->steps : 0.0,
                    implicit ? (double)tally->cg / (double)tally->steps : 0.0);
    }
    if (!quiet) fprintf(stderr, "\n");
    return 1;
}

/* Bounding box of the active particles (lo, hi: dim values); 0 when none is active. */
PN_EX_UNUSED static int pn_ex_bounds(const pn_mpm_world *w, double *lo, double *hi) {
    size_t p;
    int i, any = 0;
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim;
        if (!w->active[p]) continue;
        for (i = 0; i < w->dim; ++i) {
            if (!any || x[i] < lo[i]) lo[i] = (double)x[i];
            if (!any || x[i] > hi[i]) hi[i] = (double)x[i];
        }
        any = 1;
    }
    return any;
}

/* An example's simulation: the scene's world, run as the command line says (pn_ex_run), with
   the particles' bounding box before and after. */
typedef struct pn_ex_outcome {
    pn_mpm_world *w;             /* the caller destroys it                                  */
    pn_ex_tally tally;
    double wall_s, lo0[3], hi0[3], lo[3], hi[3];
} pn_ex_outcome;

/* Returns 0 after a failure (said on stderr; nothing left to destroy). */
PN_EX_UNUSED static int pn_ex_simulate(const char *prog, const pn_ex_cli *c, const pn_ex_scene *sc,
                                       pn_ex_outcome *o) {
    char why[256] = "";
    pn_ex_view view;
    pn_ex_output out;
    pn_result r;
    int ok;
    memset(o, 0, sizeof *o);
    pn_ex_scene_view(sc, &view);
    if (!pn_ex_output_open(prog, c, &view, &out)) return 0;
    if ((r = pn_ex_scene_create(sc, &o->w, why, sizeof why)) != PN_OK) {
        fprintf(stderr, "%s: %s (%s)\n", prog, why, pn_result_string(r));
        pn_ex_output_close(prog, &out, 0);
        return 0;
    }
    pn_ex_bounds(o->w, o->lo0, o->hi0);
    ok = pn_ex_run(prog, o->w, c->implicit, c->dt, &c->solver, c->frames, c->fps, &out, c->quiet, &o->tally, &o->wall_s);
    ok = pn_ex_output_close(prog, &out, ok);
    if (!ok) {
        pn_mpm_destroy(o->w);
        o->w = NULL;
        return 0;
    }
    pn_ex_bounds(o->w, o->lo, o->hi);
    return 1;
}

/* The explicit reference (docs/validation.md): ref, a world made as the run's was (the same
   particles), run to t_end_s in `frames` equal frames of explicit steps at pn_mpm_stable_dt,
   with no outputs. *t gets the steps, *wall_s their wall seconds. Returns 0 after a failure
   (said on stderr; the caller still destroys ref). */
PN_EX_UNUSED static int pn_ex_reference(const char *prog, pn_mpm_world *ref, double t_end_s, int frames, pn_ex_tally *t,
                                        double *wall_s) {
    pn_result r;
    int k;
    *wall_s = 0;
    memset(t, 0, sizeof *t);
    for (k = 0; k < frames && t_end_s > 0; ++k) {
        double t0 = pn_ex_seconds();
        r = pn_ex_advance_explicit(ref, t_end_s / frames, t);
        *wall_s += pn_ex_seconds() - t0;
        if (r != PN_OK) {
            fprintf(stderr, "%s: the reference failed at t = %g s: %s (%s)\n", prog, (double)ref->time_s,
                    pn_mpm_error(ref), pn_result_string(r));
            return 0;
        }
    }
    return 1;
}

/* ---- mass IoU (PlasticityNet Fig. 5a-b; docs/validation.md) -----------------------------------

   Each run's particle mass is spread onto the simulation grid's nodes with the quadratic
   B-spline weights of the MPM transfers (so the field is what the solver itself sees) and
   divided by its maximum, giving a and b in [0, 1]. Three scores per pair of fields:
   - soft: sum(a b) / sum(a + b - a b), the formula of docs/validation.md. It is below 1 even for
     identical fields wherever a is fractional (edges, thin layers, a denser node setting the
     maximum): compare runs with the reference's score against itself, its ceiling.
   - minmax: sum(min(a, b)) / sum(max(a, b)) (weighted Jaccard): the same as soft on 0/1
     fields, exactly 1 for identical fields, so its deficit from 1 is all disagreement.
   - binary: |A & B| / |A | B| of the nodes above PN_EX_OCCUPIED of the maximum. */

#define PN_EX_OCCUPIED 0.1

/* Number of grid nodes, the length of a mass field. */
PN_EX_UNUSED static size_t pn_ex_field_size(const pn_mpm_world *w) {
    size_t n = 1;
    int i;
    for (i = 0; i < w->dim; ++i) n *= (size_t)(w->desc.res[i] + 1);
    return n;
}

/* The normalized mass field of the active particles (pn_ex_field_size values). */
PN_EX_UNUSED static void pn_ex_mass_field(const pn_mpm_world *w, double *field) {
    size_t nodes = pn_ex_field_size(w), p, k;
    int d = w->dim, i, a, b, c;
    double inv_dx = 1 / (double)w->desc.dx_m, mx = 0;
    memset(field, 0, sizeof(double) * nodes);
    for (p = 0; p < w->n; ++p) {
        double wt[3][3] = {{1, 0, 0}, {1, 0, 0}, {1, 0, 0}};
        int base[3] = {0, 0, 0}, nc = d == 3 ? 3 : 1;
        if (!w->active[p]) continue;
        for (i = 0; i < d; ++i) {
            double xc = (double)w->x[p * (size_t)d + (size_t)i] * inv_dx, f;
            base[i] = (int)floor(xc - 0.5);
            if (base[i] < 0) base[i] = 0; /* active particles stay a cell inside; be safe */
            if (base[i] > w->desc.res[i] - 2) base[i] = w->desc.res[i] - 2;
            f = xc - base[i];
            wt[i][0] = 0.5 * (1.5 - f) * (1.5 - f);
            wt[i][1] = 0.75 - (f - 1) * (f - 1);
            wt[i][2] = 0.5 * (f - 0.5) * (f - 0.5);
        }
        for (a = 0; a < 3; ++a)
            for (b = 0; b < 3; ++b)
                for (c = 0; c < nc; ++c) {
                    k = (size_t)(base[0] + a) * (size_t)(w->desc.res[1] + 1) + (size_t)(base[1] + b);
                    if (d == 3) k = k * (size_t)(w->desc.res[2] + 1) + (size_t)(base[2] + c);
                    field[k] += (double)w->mass[p] * wt[0][a] * wt[1][b] * wt[2][c];
                }
    }
    for (k = 0; k < nodes; ++k)
        if (field[k] > mx) mx = field[k];
    if (mx > 0)
        for (k = 0; k < nodes; ++k) field[k] /= mx;
}

typedef struct pn_ex_iou_scores {
    double soft, minmax, binary;
} pn_ex_iou_scores;

/* The three scores of two normalized fields of n nodes; two empty fields agree (1). */
PN_EX_UNUSED static pn_ex_iou_scores pn_ex_iou(const double *a, const double *b, size_t n) {
    double prod = 0, uni = 0, lo = 0, hi = 0;
    size_t k, bi = 0, bu = 0;
    pn_ex_iou_scores r;
    for (k = 0; k < n; ++k) {
        int oa = a[k] > PN_EX_OCCUPIED, ob = b[k] > PN_EX_OCCUPIED;
        prod += a[k] * b[k];
        uni += a[k] + b[k] - a[k] * b[k];
        lo += a[k] < b[k] ? a[k] : b[k];
        hi += a[k] < b[k] ? b[k] : a[k];
        bi += (size_t)(oa && ob);
        bu += (size_t)(oa || ob);
    }
    r.soft = uni > 0 ? prod / uni : 1.0;
    r.minmax = hi > 0 ? lo / hi : 1.0;
    r.binary = bu ? (double)bi / (double)bu : 1.0;
    return r;
}

/* The scores of the mass fields of two worlds on the same grid; 0 when out of memory. */
PN_EX_UNUSED static int pn_ex_iou_worlds(const pn_mpm_world *a, const pn_mpm_world *b, pn_ex_iou_scores *s) {
    size_t nodes = pn_ex_field_size(a);
    double *fa = (double *)malloc(sizeof(double) * nodes), *fb = (double *)malloc(sizeof(double) * nodes);
    int ok = fa && fb;
    if (ok) {
        pn_ex_mass_field(a, fa);
        pn_ex_mass_field(b, fb);
        *s = pn_ex_iou(fa, fb, nodes);
    }
    free(fa);
    free(fb);
    return ok;
}

#endif /* PN_EXAMPLE_H */
