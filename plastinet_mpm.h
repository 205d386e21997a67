/* plastinet_mpm.h - v0.1 (in progress) - material point method solvers on plastinet.h.
   Public domain or MIT, your choice: see the end of plastinet.h.

   Do this in exactly one C or C++ file, after plastinet.h:
       #define PLASTINET_IMPLEMENTATION
       #include "plastinet.h"
       #include "plastinet_mpm.h"

   ======================================================================================
   WHAT IS HERE (greppable banners in the implementation: // >>name)
   ======================================================================================
     >>world     creation, particle groups and particles (structure of arrays), validation
     >>transfer  quadratic B-spline weights, APIC particle-to-grid and grid-to-particle
     >>grid      grid velocity update, gravity, domain walls (sticky, slip, separate with
                 Coulomb friction)
     >>explicit  symplectic Euler with the analytic return mapping after the F update (the
                 reference integrator; Jiang et al. 2016 course notes, Hu et al. 2018 MLS)

   This release holds the explicit reference integrator. The implicit optimization integrator
   (Newton on the incremental potential, PlasticityNet fixed point), colliders, benchmarks and
   OpenMP arrive next (issue 4).

   QUICK START
       pn_mpm_desc wd;  pn_mpm_world *w;  pn_material sand;  int g;
       memset(&wd, 0, sizeof wd);
       wd.dim = 2; wd.res[0] = wd.res[1] = 64; wd.dx_m = 1.0 / 64; wd.gravity[1] = -9.81;
       wd.max_particles = 100000;
       pn_mpm_create(&wd, &w);
       g = pn_mpm_add_group(w, &sand, 1600);                 // material, density kg/m^3
       pn_mpm_add_particles(w, g, n, x, NULL, volume_m3);    // positions (m), optional v
       pn_mpm_step_explicit(w, 1e-4, NULL);                  // dt in seconds
       pn_mpm_destroy(w);

   MEMORY: every array is allocated by pn_mpm_create through the allocator of the desc (both
   callbacks or neither) for max_particles particles and the grid; a step allocates nothing.
   ERRORS: a step that meets a non-finite value or a failed return mapping returns its
   pn_result, names the particle in pn_mpm_world.error_particle, and leaves the world exactly
   as it was before the step (the new state is built in scratch arrays and swapped in).
   THREADS: one world per thread; the step itself is serial in this release.
*/
#ifndef PLASTINET_MPM_H
#define PLASTINET_MPM_H
#ifndef PLASTINET_H
#error "include plastinet.h first"
#endif

#ifdef __cplusplus
extern "C" {
#endif

#define PN_MPM_MAX_GROUPS 16

typedef enum pn_mpm_boundary {
    PN_MPM_BOUNDARY_STICKY = 0,  /* velocity zeroed in the wall cells                        */
    PN_MPM_BOUNDARY_SLIP,        /* normal velocity into the wall removed, tangential kept   */
    PN_MPM_BOUNDARY_SEPARATE     /* only approaching normal velocity removed; Coulomb friction */
} pn_mpm_boundary;

/* World description; zeroed fields mean defaults where one is stated. The domain is the box
   [0, res_i dx]^dim. */
typedef struct pn_mpm_desc {
    int dim;                     /* 2 or 3                                                  */
    int res[3];                  /* grid cells per axis, >= 8                               */
    pn_real dx_m;                /* cell size (m) > 0                                       */
    pn_real gravity[3];          /* m/s^2                                                   */
    pn_mpm_boundary boundary;    /* domain walls                                            */
    pn_real friction;            /* Coulomb coefficient of SEPARATE walls, >= 0             */
    int wall_cells;              /* thickness of the walls in cells; 0 = 3                  */
    size_t max_particles;        /* capacity, > 0                                           */
    pn_allocator allocator;
} pn_mpm_desc;

typedef struct pn_mpm_group {
    pn_material material;
    pn_real density_kg_m3;
} pn_mpm_group;

/* Statistics of the last step. */
typedef struct pn_mpm_stats {
    size_t particles;            /* active particles                                         */
    size_t plastic;              /* particles the return mapping projected                   */
    size_t left_domain;          /* particles deactivated this step for leaving the domain   */
    pn_real max_speed_m_s;       /* largest particle speed after the step                    */
} pn_mpm_stats;

/* The world. Particle arrays (structure of arrays, read-only for users): x, v (dim per
   particle), C (affine velocity, dim^2), F (elastic deformation gradient, dim^2), h (plastic
   state), vol0 (initial volume m^3), mass (kg), group, active. */
typedef struct pn_mpm_world {
    pn_mpm_desc desc;
    int dim, wall;
    size_t n, cap, nodes;
    pn_real *x, *v, *C, *F, *h, *vol0, *mass;
    int *group;
    unsigned char *active;
    pn_real *grid_m, *grid_v;    /* node mass and velocity (momentum during the transfer)  */
    pn_real *sx, *sv, *sC, *sF, *sh; /* scratch for the new state                         */
    unsigned char *sactive;
    pn_mpm_group groups[PN_MPM_MAX_GROUPS];
    int n_groups;
    pn_real time_s;
    long steps;
    size_t error_particle;       /* particle that made the last step fail                  */
    size_t left_total;           /* particles deactivated for leaving the domain, in total  */
} pn_mpm_world;

/* Create a world (*out set on success). PN_ERROR_INVALID_PARAMETER names nothing here: the
   checks are dim, res >= 8, dx > 0, finite gravity, friction >= 0, capacity > 0;
   PN_ERROR_OUT_OF_MEMORY if an allocation fails (nothing leaks). */
PN_API pn_result pn_mpm_create(const pn_mpm_desc *desc, pn_mpm_world **out);
PN_API void pn_mpm_destroy(pn_mpm_world *w);

/* Add a particle group of one material and density; returns its index or -1 (full, or a
   density that is not positive and finite). */
PN_API int pn_mpm_add_group(pn_mpm_world *w, const pn_material *m, pn_real density_kg_m3);

/* Add n particles of group g at positions x (dim per particle, m), velocities v (NULL: at
   rest), each of volume volume_m3, F = I, h = 0. All or nothing: PN_ERROR_NONFINITE or
   PN_ERROR_INVALID_ARGUMENT (outside the walls, bad group or volume, over capacity) with the
   world unchanged. */
PN_API pn_result pn_mpm_add_particles(pn_mpm_world *w, int g, size_t n, const pn_real *x,
                                      const pn_real *v, pn_real volume_m3);

/* One explicit step of dt_s seconds (symplectic Euler, APIC, return mapping after the F
   update). On failure the world is unchanged and w->error_particle names the culprit. */
PN_API pn_result pn_mpm_step_explicit(pn_mpm_world *w, pn_real dt_s, pn_mpm_stats *stats);

/* Total mass (kg) and momentum (kg m/s) of the active particles. */
PN_API void pn_mpm_totals(const pn_mpm_world *w, pn_real *mass, pn_real *momentum);

#ifdef __cplusplus
}
#endif
#endif /* PLASTINET_MPM_H */

#if defined(PLASTINET_IMPLEMENTATION) && !defined(PLASTINET_MPM_IMPLEMENTATION_DONE)
#define PLASTINET_MPM_IMPLEMENTATION_DONE
#ifndef PLASTINET_IMPLEMENTATION_DONE
#error "plastinet_mpm.h: the plastinet.h implementation must come first"
#endif

/* ======================================================================================
   >>world
   ====================================================================================== */

static void *pn__mpm_alloc(const pn_mpm_desc *d, size_t count, size_t size, int *fail) {
    void *p;
    if (*fail) return NULL;
    p = pn_alloc(&d->allocator, count * size);
    if (!p) *fail = 1;
    else memset(p, 0, count * size);
    return p;
}

PN__DEF void pn_mpm_destroy(pn_mpm_world *w) {
    pn_allocator a;
    if (!w) return;
    a = w->desc.allocator;
    pn_free(&a, w->x);
    pn_free(&a, w->v);
    pn_free(&a, w->C);
    pn_free(&a, w->F);
    pn_free(&a, w->h);
    pn_free(&a, w->vol0);
    pn_free(&a, w->mass);
    pn_free(&a, w->group);
    pn_free(&a, w->active);
    pn_free(&a, w->grid_m);
    pn_free(&a, w->grid_v);
    pn_free(&a, w->sx);
    pn_free(&a, w->sv);
    pn_free(&a, w->sC);
    pn_free(&a, w->sF);
    pn_free(&a, w->sh);
    pn_free(&a, w->sactive);
    pn_free(&a, w);
}

PN__DEF pn_result pn_mpm_create(const pn_mpm_desc *desc, pn_mpm_world **out) {
    pn_mpm_world *w;
    int d, i, fail = 0;
    size_t cap, nodes = 1;
    PN_ASSERT(desc && out);
    d = desc->dim;
    if (!pn__dim_ok(d)) return PN_ERROR_DIMENSION;
    if (!pn__finite(desc->dx_m) || !(desc->dx_m > 0) || !pn__finite(desc->friction) ||
        !(desc->friction >= 0) || desc->max_particles == 0 || desc->wall_cells < 0 ||
        desc->boundary < PN_MPM_BOUNDARY_STICKY || desc->boundary > PN_MPM_BOUNDARY_SEPARATE ||
        (desc->allocator.alloc == NULL) != (desc->allocator.free == NULL))
        return PN_ERROR_INVALID_ARGUMENT;
    for (i = 0; i < d; ++i) {
        if (desc->res[i] < 8 || desc->res[i] > 1 << 14 || !pn__finite(desc->gravity[i]))
            return PN_ERROR_INVALID_ARGUMENT;
        nodes *= (size_t)(desc->res[i] + 1);
    }
    cap = desc->max_particles;
    w = (pn_mpm_world *)pn__mpm_alloc(desc, 1, sizeof *w, &fail);
    if (!w) return PN_ERROR_OUT_OF_MEMORY;
    w->desc = *desc;
    w->dim = d;
    w->wall = desc->wall_cells ? desc->wall_cells : 3;
    w->cap = cap;
    w->nodes = nodes;
    w->x = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)d, sizeof(pn_real), &fail);
    w->v = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)d, sizeof(pn_real), &fail);
    w->C = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->F = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->h = (pn_real *)pn__mpm_alloc(desc, cap, sizeof(pn_real), &fail);
    w->vol0 = (pn_real *)pn__mpm_alloc(desc, cap, sizeof(pn_real), &fail);
    w->mass = (pn_real *)pn__mpm_alloc(desc, cap, sizeof(pn_real), &fail);
    w->group = (int *)pn__mpm_alloc(desc, cap, sizeof(int), &fail);
    w->active = (unsigned char *)pn__mpm_alloc(desc, cap, 1, &fail);
    w->grid_m = (pn_real *)pn__mpm_alloc(desc, nodes, sizeof(pn_real), &fail);
    w->grid_v = (pn_real *)pn__mpm_alloc(desc, nodes * (size_t)d, sizeof(pn_real), &fail);
    w->sx = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)d, sizeof(pn_real), &fail);
    w->sv = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)d, sizeof(pn_real), &fail);
    w->sC = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->sF = (pn_real *)pn__mpm_alloc(desc, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->sh = (pn_real *)pn__mpm_alloc(desc, cap, sizeof(pn_real), &fail);
    w->sactive = (unsigned char *)pn__mpm_alloc(desc, cap, 1, &fail);
    if (fail) {
        pn_mpm_destroy(w);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    *out = w;
    return PN_OK;
}

PN__DEF int pn_mpm_add_group(pn_mpm_world *w, const pn_material *m, pn_real density_kg_m3) {
    PN_ASSERT(w && m);
    if (w->n_groups >= PN_MPM_MAX_GROUPS || !pn__finite(density_kg_m3) || !(density_kg_m3 > 0))
        return -1;
    w->groups[w->n_groups].material = *m;
    w->groups[w->n_groups].density_kg_m3 = density_kg_m3;
    return w->n_groups++;
}

/* inside the walls: [wall dx, (res - wall) dx] on every axis */
static int pn__mpm_inside(const pn_mpm_world *w, const pn_real *x) {
    int i;
    for (i = 0; i < w->dim; ++i) {
        pn_real lo = w->wall * w->desc.dx_m, hi = (w->desc.res[i] - w->wall) * w->desc.dx_m;
        if (!(x[i] >= lo && x[i] <= hi)) return 0;
    }
    return 1;
}

PN__DEF pn_result pn_mpm_add_particles(pn_mpm_world *w, int g, size_t n, const pn_real *x,
                                       const pn_real *v, pn_real volume_m3) {
    int d, i;
    size_t p;
    PN_ASSERT(w && (x || n == 0));
    d = w->dim;
    if (g < 0 || g >= w->n_groups || !pn__finite(volume_m3) || !(volume_m3 > 0) ||
        n > w->cap - w->n)
        return PN_ERROR_INVALID_ARGUMENT;
    for (p = 0; p < n; ++p) {
        if (!pn__all_finite(d, x + p * (size_t)d) || (v && !pn__all_finite(d, v + p * (size_t)d))) {
            w->error_particle = w->n + p;
            return PN_ERROR_NONFINITE;
        }
        if (!pn__mpm_inside(w, x + p * (size_t)d)) {
            w->error_particle = w->n + p;
            return PN_ERROR_INVALID_ARGUMENT;
        }
    }
    for (p = 0; p < n; ++p) {
        size_t q = w->n + p;
        for (i = 0; i < d; ++i) {
            w->x[q * (size_t)d + (size_t)i] = x[p * (size_t)d + (size_t)i];
            w->v[q * (size_t)d + (size_t)i] = v ? v[p * (size_t)d + (size_t)i] : 0;
        }
        memset(w->C + q * (size_t)(d * d), 0, sizeof(pn_real) * (size_t)(d * d));
        pn__identity(d, w->F + q * (size_t)(d * d));
        w->h[q] = 0;
        w->vol0[q] = volume_m3;
        w->mass[q] = volume_m3 * w->groups[g].density_kg_m3;
        w->group[q] = g;
        w->active[q] = 1;
    }
    w->n += n;
    return PN_OK;
}

PN__DEF void pn_mpm_totals(const pn_mpm_world *w, pn_real *mass, pn_real *momentum) {
    size_t p;
    int i, d = w->dim;
    pn_real m = 0, mom[3] = {0, 0, 0};
    for (p = 0; p < w->n; ++p) {
        if (!w->active[p]) continue;
        m += w->mass[p];
        for (i = 0; i < d; ++i) mom[i] += w->mass[p] * w->v[p * (size_t)d + (size_t)i];
    }
    if (mass) *mass = m;
    if (momentum)
        for (i = 0; i < d; ++i) momentum[i] = mom[i];
}

/* ======================================================================================
   >>transfer: quadratic B-splines. For a particle at x (in cells), base = floor(x - 0.5),
   fx = x - base in [0.5, 1.5): w0 = (1.5 - fx)^2 / 2, w1 = 0.75 - (fx - 1)^2,
   w2 = (fx - 0.5)^2 / 2 per axis. APIC with D^-1 = 4 / dx^2 (quadratic splines).
   ====================================================================================== */

typedef struct pn__mpm_stencil {
    int base[3];
    pn_real w[3][3];   /* w[axis][k] */
    pn_real fx[3];
} pn__mpm_stencil;

static void pn__mpm_stencil_at(const pn_mpm_world *w, const pn_real *x, pn__mpm_stencil *s) {
    int i;
    for (i = 0; i < w->dim; ++i) {
        pn_real xc = x[i] / w->desc.dx_m, f;
        s->base[i] = (int)floor((double)(xc - (pn_real)0.5));
        f = xc - (pn_real)s->base[i];
        s->fx[i] = f;
        s->w[i][0] = (pn_real)0.5 * ((pn_real)1.5 - f) * ((pn_real)1.5 - f);
        s->w[i][1] = (pn_real)0.75 - (f - 1) * (f - 1);
        s->w[i][2] = (pn_real)0.5 * (f - (pn_real)0.5) * (f - (pn_real)0.5);
    }
}

static size_t pn__mpm_node(const pn_mpm_world *w, const int *idx) {
    size_t k = (size_t)idx[0];
    int i;
    for (i = 1; i < w->dim; ++i) k = k * (size_t)(w->desc.res[i] + 1) + (size_t)idx[i];
    return k;
}

/* Visit the 3^dim stencil nodes: node index, weight, offset (x_i - x_p) / dx */
#define PN__MPM_FOR_STENCIL(w, s, body)                                                    \
    do {                                                                                   \
        int pn__a, pn__b, pn__c, pn__nc = (w)->dim == 3 ? 3 : 1;                           \
        for (pn__a = 0; pn__a < 3; ++pn__a)                                                \
            for (pn__b = 0; pn__b < 3; ++pn__b)                                            \
                for (pn__c = 0; pn__c < pn__nc; ++pn__c) {                                 \
                    int idx_[3];                                                           \
                    pn_real wt, dpos[3];                                                   \
                    size_t node;                                                           \
                    idx_[0] = (s).base[0] + pn__a;                                         \
                    idx_[1] = (s).base[1] + pn__b;                                         \
                    idx_[2] = (w)->dim == 3 ? (s).base[2] + pn__c : 0;                     \
                    wt = (s).w[0][pn__a] * (s).w[1][pn__b] * ((w)->dim == 3 ? (s).w[2][pn__c] : 1); \
                    dpos[0] = (pn_real)pn__a - (s).fx[0];                                  \
                    dpos[1] = (pn_real)pn__b - (s).fx[1];                                  \
                    dpos[2] = (w)->dim == 3 ? (pn_real)pn__c - (s).fx[2] : 0;              \
                    node = pn__mpm_node((w), idx_);                                        \
                    body                                                                   \
                }                                                                          \
    } while (0)

/* ======================================================================================
   >>grid: v = momentum / mass + dt g, then the walls.
   ====================================================================================== */

static void pn__mpm_grid_update(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, i, idx[3];
    size_t k;
    for (k = 0; k < w->nodes; ++k) {
        pn_real *v = w->grid_v + k * (size_t)d, m = w->grid_m[k];
        size_t r = k;
        if (m <= 0) continue;
        for (i = 0; i < d; ++i) v[i] = v[i] / m + dt * w->desc.gravity[i];
        for (i = d - 1; i >= 0; --i) { /* node coordinates from the flat index */
            idx[i] = (int)(r % (size_t)(w->desc.res[i] + 1));
            r /= (size_t)(w->desc.res[i] + 1);
        }
        for (i = 0; i < d; ++i) {
            int lo = idx[i] < w->wall, hi = idx[i] > w->desc.res[i] - w->wall;
            pn_real vn, vt2 = 0, vt, scale;
            int j;
            if (!lo && !hi) continue;
            if (w->desc.boundary == PN_MPM_BOUNDARY_STICKY) {
                for (j = 0; j < d; ++j) v[j] = 0;
                break;
            }
            vn = v[i];
            if ((lo && vn >= 0) || (hi && vn <= 0)) { /* leaving the wall */
                if (w->desc.boundary == PN_MPM_BOUNDARY_SEPARATE) continue;
            }
            v[i] = 0;
            if (w->desc.boundary == PN_MPM_BOUNDARY_SEPARATE && w->desc.friction > 0) {
                /* Coulomb: the tangential speed drops by mu |vn|, not below zero */
                for (j = 0; j < d; ++j)
                    if (j != i) vt2 += v[j] * v[j];
                vt = PN__SQRT(vt2);
                scale = vt > 0 ? PN__MAX(0, vt - w->desc.friction * PN__FABS(vn)) / vt : 0;
                for (j = 0; j < d; ++j)
                    if (j != i) v[j] *= scale;
            }
        }
    }
}

/* ======================================================================================
   >>explicit
   ====================================================================================== */

PN__DEF pn_result pn_mpm_step_explicit(pn_mpm_world *w, pn_real dt, pn_mpm_stats *stats) {
    int d, dd, i, j;
    size_t p;
    pn_real inv_dx, dx;
    pn_mpm_stats st;
    PN_ASSERT(w);
    if (!pn__finite(dt) || !(dt > 0)) return PN_ERROR_INVALID_ARGUMENT;
    d = w->dim;
    dd = d * d;
    dx = w->desc.dx_m;
    inv_dx = 1 / dx;
    memset(&st, 0, sizeof st);
    memset(w->grid_m, 0, sizeof(pn_real) * w->nodes);
    memset(w->grid_v, 0, sizeof(pn_real) * w->nodes * (size_t)d);
    /* particle to grid: mass, APIC momentum and the stress impulse
       -dt V0 (4/dx^2) tau (x_i - x_p) with tau the Kirchhoff stress of the elastic F */
    for (p = 0; p < w->n; ++p) {
        pn__mpm_stencil s;
        const pn_mpm_group *g = &w->groups[w->group[p]];
        pn_real tau[9] = {0}, A[9], *xp = w->x + p * (size_t)d, *vp = w->v + p * (size_t)d;
        pn_result r;
        if (!w->active[p]) continue;
        r = pn_kirchhoff_stress(&g->material, d, w->F + p * (size_t)dd, w->h[p], tau);
        if (r != PN_OK) {
            w->error_particle = p;
            return r;
        }
        for (i = 0; i < dd; ++i)
            A[i] = -dt * w->vol0[p] * 4 * inv_dx * inv_dx * tau[i] + w->mass[p] * w->C[p * (size_t)dd + (size_t)i];
        pn__mpm_stencil_at(w, xp, &s);
        PN__MPM_FOR_STENCIL(w, s, {
            pn_real *gv = w->grid_v + node * (size_t)d;
            w->grid_m[node] += wt * w->mass[p];
            for (i = 0; i < d; ++i) {
                pn_real acc = w->mass[p] * vp[i];
                for (j = 0; j < d; ++j) acc += A[i * d + j] * dpos[j] * dx;
                gv[i] += wt * acc;
            }
        });
    }
    pn__mpm_grid_update(w, dt);
    /* grid to particle, into scratch: v, C, x, F = (I + dt C) F, then the return mapping */
    for (p = 0; p < w->n; ++p) {
        pn__mpm_stencil s;
        const pn_mpm_group *g = &w->groups[w->group[p]];
        pn_real nv[3] = {0, 0, 0}, nC[9] = {0}, G[9], Fn[9], Z[9], hn, sp = 0;
        pn_real *xp = w->x + p * (size_t)d;
        pn_result r;
        w->sactive[p] = w->active[p];
        if (!w->active[p]) { /* retired particles keep their last state */
            memcpy(w->sx + p * (size_t)d, xp, sizeof(pn_real) * (size_t)d);
            memcpy(w->sv + p * (size_t)d, w->v + p * (size_t)d, sizeof(pn_real) * (size_t)d);
            memcpy(w->sC + p * (size_t)dd, w->C + p * (size_t)dd, sizeof(pn_real) * (size_t)dd);
            memcpy(w->sF + p * (size_t)dd, w->F + p * (size_t)dd, sizeof(pn_real) * (size_t)dd);
            w->sh[p] = w->h[p];
            continue;
        }
        pn__mpm_stencil_at(w, xp, &s);
        PN__MPM_FOR_STENCIL(w, s, {
            const pn_real *gv = w->grid_v + node * (size_t)d;
            for (i = 0; i < d; ++i) {
                nv[i] += wt * gv[i];
                for (j = 0; j < d; ++j) nC[i * d + j] += 4 * inv_dx * wt * gv[i] * dpos[j];
            }
        });
        for (i = 0; i < dd; ++i) G[i] = dt * nC[i];
        for (i = 0; i < d; ++i) G[i * d + i] += 1;
        pn_mat_mul(d, G, w->F + p * (size_t)dd, Fn);
        r = pn_return_map(&g->material, d, Fn, w->h[p], Z, &hn, NULL);
        if (r == PN_OK && (!pn__all_finite(d, nv) || !pn__all_finite(dd, nC))) r = PN_ERROR_OVERFLOW;
        if (r != PN_OK) {
            w->error_particle = p;
            return r;
        }
        if (hn != w->h[p] || memcmp(Z, Fn, sizeof(pn_real) * (size_t)dd) != 0) st.plastic++;
        for (i = 0; i < d; ++i) {
            w->sv[p * (size_t)d + (size_t)i] = nv[i];
            w->sx[p * (size_t)d + (size_t)i] = xp[i] + dt * nv[i];
            sp += nv[i] * nv[i];
        }
        memcpy(w->sC + p * (size_t)dd, nC, sizeof(pn_real) * (size_t)dd);
        memcpy(w->sF + p * (size_t)dd, Z, sizeof(pn_real) * (size_t)dd);
        w->sh[p] = hn;
        if (!pn__mpm_inside(w, w->sx + p * (size_t)d)) { /* left through a wall: retire it */
            w->sactive[p] = 0;
            st.left_domain++;
            continue;
        }
        st.particles++;
        st.max_speed_m_s = PN__MAX(st.max_speed_m_s, PN__SQRT(sp));
    }
    /* every particle succeeded: the new state becomes the world */
    {
        pn_real *t;
        unsigned char *u;
        t = w->x; w->x = w->sx; w->sx = t;
        t = w->v; w->v = w->sv; w->sv = t;
        t = w->C; w->C = w->sC; w->sC = t;
        t = w->F; w->F = w->sF; w->sF = t;
        t = w->h; w->h = w->sh; w->sh = t;
        u = w->active; w->active = w->sactive; w->sactive = u;
    }
    w->left_total += st.left_domain;
    w->time_s += dt;
    w->steps++;
    if (stats) *stats = st;
    return PN_OK;
}

#endif /* PLASTINET_MPM_IMPLEMENTATION */
