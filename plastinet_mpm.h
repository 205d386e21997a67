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
     >>implicit  optimization time integration: Newton + PCG + line search on the incremental
                 potential, fixed point on F0 (PlasticityNet Eqs. 3, 10, 11), for the
                 elastic, lagged, exact von Mises and PlasticityNet energies
     >>explicit  symplectic Euler with the analytic return mapping after the F update (the
                 reference integrator; Jiang et al. 2016 course notes, Hu et al. 2018 MLS)

   In progress (issue 4): colliders, OpenMP, the examples and the benchmarks arrive next.

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

/* The energy the implicit integrator minimizes for a group (the explicit one always uses the
   analytic return mapping). */
typedef enum pn_mpm_energy {
    PN_MPM_ENERGY_DEFAULT = 0,   /* elastic for PN_PLASTIC_NONE, else lagged                */
    PN_MPM_ENERGY_ELASTIC,       /* psi_el(F): plasticity ignored inside the solve          */
    PN_MPM_ENERGY_LAGGED,        /* psi_el(F G), G = F0^-1 Z(F0): the no-network baseline   */
    PN_MPM_ENERGY_EXACT_VM,      /* exact StVK-Hencky + von Mises energy (no fixed point)   */
    PN_MPM_ENERGY_PNET           /* PlasticityNet (set with pn_mpm_group_set_pnet)           */
} pn_mpm_energy;

typedef struct pn_mpm_group {
    pn_material material;
    pn_real density_kg_m3;
    pn_mpm_energy energy;
    pn_pnet pnet;                /* PN_MPM_ENERGY_PNET only                                 */
} pn_mpm_group;

/* Implicit step settings; zeroed fields mean the defaults in brackets. */
typedef struct pn_mpm_implicit_desc {
    int fixed_point_iters;       /* passes of the F0 fixed point (PlasticityNet Eq. 10) [2]  */
    int newton_max;              /* Newton iterations per pass [50]                          */
    int cg_max;                  /* conjugate-gradient iterations per Newton step [500]      */
    pn_real newton_tol;          /* stop when max |dv| < newton_tol dx / dt [1e-5]          */
    pn_real cg_rel_tol;          /* relative residual of the linear solve [1e-3]            */
} pn_mpm_implicit_desc;

/* Statistics of the last step. */
typedef struct pn_mpm_stats {
    size_t particles;            /* active particles                                         */
    size_t plastic;              /* particles the return mapping projected                   */
    size_t left_domain;          /* particles deactivated this step for leaving the domain   */
    pn_real max_speed_m_s;       /* largest particle speed after the step                    */
    /* implicit steps */
    int fixed_point_iters, newton_iters, cg_iters; /* totals over the step                  */
    int line_search_failures;    /* Newton steps whose line search found no decrease        */
    pn_real newton_residual;     /* final max |dv| dt / dx of the last pass                  */
    pn_real fixed_point_residual;/* max_q |F0_new - F0| of the last pass                     */
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
    /* implicit solver storage, allocated by the first implicit step */
    pn_real *vstar, *vsol, *vtry, *grad, *dir, *cg_r, *cg_z, *cg_p, *cg_q, *diag;
    unsigned char *fixed;        /* per node and axis: 1 = velocity component held at 0     */
    pn_real *pP, *pH, *pG, *phG, *pF0;
    pn_pnet_point *ppt;
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

/* Choose the energy group g's particles use in implicit steps. PN_MPM_ENERGY_PNET needs net
   (a bound pn_pnet for the group's material, copied). PN_ERROR_INVALID_ARGUMENT or
   PN_ERROR_UNSUPPORTED (exact von Mises for another material) otherwise. */
PN_API pn_result pn_mpm_group_set_energy(pn_mpm_world *w, int g, pn_mpm_energy energy,
                                         const pn_pnet *net);

/* One implicit step (optimization time integration, PlasticityNet Eqs. 3, 10, 11): grid
   velocities minimize 1/2 |v - v*|_M^2 + sum_p V_p Psi_p(F_p(v)) by Newton with PSD-projected
   per-particle Hessians, Jacobi-preconditioned conjugate gradients and a backtracking line
   search; around it the fixed point on F0 (F0 = F(v) of the previous pass). The state update
   (APIC, return mapping) follows as in the explicit step. Walls inside the solve: sticky
   holds every velocity component of the wall nodes at zero, slip and separate hold the normal
   one (separate is treated as slip, without friction, in this release). The first call allocates the solver
   storage (PN_ERROR_OUT_OF_MEMORY possible); later calls allocate nothing. On failure the world
   is unchanged. desc may be NULL (defaults). */
PN_API pn_result pn_mpm_step_implicit(pn_mpm_world *w, pn_real dt_s, const pn_mpm_implicit_desc *desc,
                                      pn_mpm_stats *stats);

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
    pn_free(&a, w->vstar);
    pn_free(&a, w->vsol);
    pn_free(&a, w->vtry);
    pn_free(&a, w->grad);
    pn_free(&a, w->dir);
    pn_free(&a, w->cg_r);
    pn_free(&a, w->cg_z);
    pn_free(&a, w->cg_p);
    pn_free(&a, w->cg_q);
    pn_free(&a, w->diag);
    pn_free(&a, w->fixed);
    pn_free(&a, w->pP);
    pn_free(&a, w->pH);
    pn_free(&a, w->pG);
    pn_free(&a, w->phG);
    pn_free(&a, w->pF0);
    pn_free(&a, w->ppt);
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

/* where the 3^dim stencil stays on the grid: [dx, (res - 1) dx]. Particles sink into the wall
   band by up to about a cell before its held velocities stop them, so only one that leaves
   this region has gone through a wall. */
static int pn__mpm_in_grid(const pn_mpm_world *w, const pn_real *x) {
    int i;
    for (i = 0; i < w->dim; ++i) {
        pn_real lo = w->desc.dx_m, hi = (w->desc.res[i] - 1) * w->desc.dx_m;
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
   w2 = (fx - 0.5)^2 / 2 per axis. APIC with D^-1 = 4 / dx^2 (quadratic splines). The
   particle-to-grid and grid-to-particle passes themselves are shared by both integrators
   (pn__mpm_p2g_momentum, pn__mpm_g2p below).
   ====================================================================================== */

static size_t pn__mpm_node(const pn_mpm_world *w, const int *idx) {
    size_t k = (size_t)idx[0];
    int i;
    for (i = 1; i < w->dim; ++i) k = k * (size_t)(w->desc.res[i] + 1) + (size_t)idx[i];
    return k;
}

/* Stencil of particle p: nodes, weights, weight gradients (1/m) and offsets (m). */
typedef struct pn__mpm_kernel {
    int count;
    size_t node[27];
    pn_real w[27], gw[27][3], dpos[27][3];
} pn__mpm_kernel;

static void pn__mpm_kernel_at(const pn_mpm_world *w, const pn_real *x, pn__mpm_kernel *k) {
    int d = w->dim, a, b, c, i, nc = d == 3 ? 3 : 1;
    pn_real dx = w->desc.dx_m, wd[3][3] = {{0}}, dw[3][3] = {{0}}, fx[3] = {0, 0, 0};
    int base[3] = {0, 0, 0}, idx[3];
    for (i = 0; i < d; ++i) {
        pn_real xc = x[i] / dx, f;
        base[i] = (int)floor((double)(xc - (pn_real)0.5));
        f = xc - (pn_real)base[i];
        fx[i] = f;
        wd[i][0] = (pn_real)0.5 * ((pn_real)1.5 - f) * ((pn_real)1.5 - f);
        wd[i][1] = (pn_real)0.75 - (f - 1) * (f - 1);
        wd[i][2] = (pn_real)0.5 * (f - (pn_real)0.5) * (f - (pn_real)0.5);
        dw[i][0] = (f - (pn_real)1.5) / dx; /* d w / d x_p */
        dw[i][1] = -2 * (f - 1) / dx;
        dw[i][2] = (f - (pn_real)0.5) / dx;
    }
    if (d == 2) {
        fx[2] = 0;
        wd[2][0] = 1;
        dw[2][0] = 0;
    }
    k->count = 0;
    for (a = 0; a < 3; ++a)
        for (b = 0; b < 3; ++b)
            for (c = 0; c < nc; ++c) {
                int n = k->count++, o[3];
                o[0] = a; o[1] = b; o[2] = c;
                for (i = 0; i < 3; ++i) idx[i] = base[i] + o[i];
                k->node[n] = pn__mpm_node(w, idx);
                k->w[n] = wd[0][a] * wd[1][b] * wd[2][c];
                k->gw[n][0] = dw[0][a] * wd[1][b] * wd[2][c];
                k->gw[n][1] = wd[0][a] * dw[1][b] * wd[2][c];
                k->gw[n][2] = d == 3 ? wd[0][a] * wd[1][b] * dw[2][c] : 0;
                for (i = 0; i < 3; ++i) k->dpos[n][i] = ((pn_real)o[i] - fx[i]) * dx;
            }
}

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
   >>implicit: optimization time integration. Unknowns: the velocities of the grid nodes
   that carry mass. E(v) = sum_i m_i/2 |v_i - v*_i|^2 + sum_p V_p Psi_p(F_p(v)) with
   F_p(v) = (I + dt sum_i v_i grad w_ip^T) F_p^n. dE/dv_i = m_i (v_i - v*_i) +
   dt sum_p V_p P_p F_p^nT grad w_ip; the Hessian applies each particle's PSD dP/dF to
   dF_p = dt (sum_j d_j grad w_jp^T) F_p^n.
   ====================================================================================== */

static pn_result pn__mpm_alloc_implicit(pn_mpm_world *w) {
    const pn_mpm_desc *ds = &w->desc;
    size_t nd = w->nodes * (size_t)w->dim, cap = w->cap;
    int d = w->dim, fail = 0;
    if (w->vstar) return PN_OK;
    w->vstar = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->vsol = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->vtry = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->grad = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->dir = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->cg_r = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->cg_z = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->cg_p = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->cg_q = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->diag = (pn_real *)pn__mpm_alloc(ds, nd, sizeof(pn_real), &fail);
    w->fixed = (unsigned char *)pn__mpm_alloc(ds, nd, 1, &fail);
    w->pP = (pn_real *)pn__mpm_alloc(ds, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->pH = (pn_real *)pn__mpm_alloc(ds, cap * (size_t)(d * d * d * d), sizeof(pn_real), &fail);
    w->pG = (pn_real *)pn__mpm_alloc(ds, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->phG = (pn_real *)pn__mpm_alloc(ds, cap, sizeof(pn_real), &fail);
    w->pF0 = (pn_real *)pn__mpm_alloc(ds, cap * (size_t)(d * d), sizeof(pn_real), &fail);
    w->ppt = (pn_pnet_point *)pn__mpm_alloc(ds, cap, sizeof(pn_pnet_point), &fail);
    if (!fail) return PN_OK;
    /* leave the world as it was: free what this call allocated */
    {
        pn_real **r[] = {&w->vstar, &w->vsol, &w->vtry, &w->grad, &w->dir, &w->cg_r, &w->cg_z,
                         &w->cg_p, &w->cg_q, &w->diag, &w->pP, &w->pH, &w->pG, &w->phG, &w->pF0};
        size_t i;
        for (i = 0; i < sizeof r / sizeof r[0]; ++i) {
            pn_free(&ds->allocator, *r[i]);
            *r[i] = NULL;
        }
        pn_free(&ds->allocator, w->fixed);
        pn_free(&ds->allocator, w->ppt);
        w->fixed = NULL;
        w->ppt = NULL;
    }
    return PN_ERROR_OUT_OF_MEMORY;
}

PN__DEF pn_result pn_mpm_group_set_energy(pn_mpm_world *w, int g, pn_mpm_energy energy,
                                          const pn_pnet *net) {
    pn_mpm_group *gr;
    PN_ASSERT(w);
    if (g < 0 || g >= w->n_groups || energy < PN_MPM_ENERGY_DEFAULT || energy > PN_MPM_ENERGY_PNET)
        return PN_ERROR_INVALID_ARGUMENT;
    gr = &w->groups[g];
    if (energy == PN_MPM_ENERGY_PNET) {
        if (!net || !net->energy || net->energy->dim != w->dim) return PN_ERROR_INVALID_ARGUMENT;
        if (net->material.plastic != gr->material.plastic || net->material.elastic != gr->material.elastic)
            return PN_ERROR_INVALID_ARGUMENT;
        gr->pnet = *net;
    }
    if (energy == PN_MPM_ENERGY_EXACT_VM && (gr->material.plastic != PN_PLASTIC_VON_MISES ||
                                             gr->material.elastic != PN_ELASTIC_STVK_HENCKY))
        return PN_ERROR_UNSUPPORTED;
    gr->energy = energy;
    return PN_OK;
}

static pn_mpm_energy pn__mpm_energy_of(const pn_mpm_group *g) {
    if (g->energy != PN_MPM_ENERGY_DEFAULT) return g->energy;
    return g->material.plastic == PN_PLASTIC_NONE ? PN_MPM_ENERGY_ELASTIC : PN_MPM_ENERGY_LAGGED;
}

/* F_p(v) = (I + dt sum_i v_i grad w_ip^T) F_p^n */
static void pn__mpm_F_of(const pn_mpm_world *w, size_t p, const pn__mpm_kernel *k, const pn_real *v,
                         pn_real dt, pn_real *F) {
    int d = w->dim, i, j, n;
    pn_real Gv[9] = {0};
    for (n = 0; n < k->count; ++n) {
        const pn_real *vi = v + k->node[n] * (size_t)d;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) Gv[i * d + j] += dt * vi[i] * k->gw[n][j];
    }
    for (i = 0; i < d; ++i) Gv[i * d + i] += 1;
    pn_mat_mul(d, Gv, w->F + p * (size_t)(d * d), F);
}

/* Psi_p at F (energy density), with P and the PSD dP/dF when asked. */
static pn_result pn__mpm_psi(const pn_mpm_world *w, size_t p, const pn_real *F, pn_real *psi,
                             pn_real *P, pn_real *H) {
    const pn_mpm_group *g = &w->groups[w->group[p]];
    int d = w->dim, dd = d * d;
    switch (pn__mpm_energy_of(g)) {
    case PN_MPM_ENERGY_LAGGED:
        return pn_lagged_energy(&g->material, d, F, w->pG + p * (size_t)dd, w->phG[p], psi, P, H,
                                PN_EVAL_PROJECT_PSD);
    case PN_MPM_ENERGY_EXACT_VM:
        return pn_von_mises_energy(&g->material, d, F, w->h[p], psi, P, H, PN_EVAL_PROJECT_PSD);
    case PN_MPM_ENERGY_PNET:
        return pn_pnet_energy(&g->pnet, &w->ppt[p], F, psi, P, H, PN_EVAL_PROJECT_PSD);
    default:
        return pn_elastic_energy(&g->material, d, F, w->h[p], psi, P, H, PN_EVAL_PROJECT_PSD);
    }
}

/* E(v); with_derivs: also the gradient (w->grad) and each particle's P and dP/dF. A failed
   evaluation (an inverted F, say) gives *E = +inf with_derivs == 0, else its error. */
static pn_result pn__mpm_objective(pn_mpm_world *w, const pn_real *v, pn_real dt, int with_derivs,
                                   pn_real *E) {
    int d = w->dim, dd = d * d, i, j, l, n;
    size_t p, k;
    pn_real e = 0;
    if (with_derivs) memset(w->grad, 0, sizeof(pn_real) * w->nodes * (size_t)d);
    for (k = 0; k < w->nodes; ++k) {
        pn_real m = w->grid_m[k];
        if (m <= 0) continue;
        for (i = 0; i < d; ++i) {
            pn_real dv = v[k * (size_t)d + (size_t)i] - w->vstar[k * (size_t)d + (size_t)i];
            e += m / 2 * dv * dv;
            if (with_derivs) w->grad[k * (size_t)d + (size_t)i] = m * dv;
        }
    }
    for (p = 0; p < w->n; ++p) {
        pn__mpm_kernel kr;
        pn_real F[9], psi, *P = w->pP + p * (size_t)dd, *H = w->pH + p * (size_t)(dd * dd), PF[9];
        pn_result r;
        if (!w->active[p]) continue;
        pn__mpm_kernel_at(w, w->x + p * (size_t)d, &kr);
        pn__mpm_F_of(w, p, &kr, v, dt, F);
        r = pn__mpm_psi(w, p, F, &psi, with_derivs ? P : NULL, with_derivs ? H : NULL);
        if (r != PN_OK) {
            if (with_derivs) {
                w->error_particle = p;
                return r;
            }
            *E = (pn_real)HUGE_VAL;
            return PN_OK;
        }
        e += w->vol0[p] * psi;
        if (!with_derivs) continue;
        /* PF = V dt P F^nT */
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) {
                pn_real acc = 0;
                for (l = 0; l < d; ++l) acc += P[i * d + l] * w->F[p * (size_t)dd + (size_t)(j * d + l)];
                PF[i * d + j] = w->vol0[p] * dt * acc;
            }
        for (n = 0; n < kr.count; ++n) {
            pn_real *gi = w->grad + kr.node[n] * (size_t)d;
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j) gi[i] += PF[i * d + j] * kr.gw[n][j];
        }
    }
    *E = e;
    return PN_OK;
}

/* out = H x over the free components (fixed ones give 0) */
static void pn__mpm_hess_vec(pn_mpm_world *w, const pn_real *x, pn_real dt, pn_real *out) {
    int d = w->dim, dd = d * d, i, j, l, n;
    size_t p, k, nd = w->nodes * (size_t)d;
    for (k = 0; k < w->nodes; ++k)
        for (i = 0; i < d; ++i) out[k * (size_t)d + (size_t)i] = w->grid_m[k] * x[k * (size_t)d + (size_t)i];
    for (p = 0; p < w->n; ++p) {
        pn__mpm_kernel kr;
        pn_real Gx[9] = {0}, dF[9], dP[9], PF[9];
        const pn_real *Fn = w->F + p * (size_t)dd, *H = w->pH + p * (size_t)(dd * dd);
        if (!w->active[p]) continue;
        pn__mpm_kernel_at(w, w->x + p * (size_t)d, &kr);
        for (n = 0; n < kr.count; ++n) {
            const pn_real *xi = x + kr.node[n] * (size_t)d;
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j) Gx[i * d + j] += dt * xi[i] * kr.gw[n][j];
        }
        pn_mat_mul(d, Gx, Fn, dF);
        for (i = 0; i < dd; ++i) {
            pn_real acc = 0;
            for (j = 0; j < dd; ++j) acc += H[i * dd + j] * dF[j];
            dP[i] = acc;
        }
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) {
                pn_real acc = 0;
                for (l = 0; l < d; ++l) acc += dP[i * d + l] * Fn[j * d + l];
                PF[i * d + j] = w->vol0[p] * dt * acc;
            }
        for (n = 0; n < kr.count; ++n) {
            pn_real *oi = out + kr.node[n] * (size_t)d;
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j) oi[i] += PF[i * d + j] * kr.gw[n][j];
        }
    }
    for (k = 0; k < nd; ++k)
        if (w->fixed[k] || w->grid_m[k / (size_t)d] <= 0) out[k] = 0;
}

/* Jacobi preconditioner: the exact diagonal of H (mass plus each particle's contribution) */
static void pn__mpm_diagonal(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, dd = d * d, i, j, l, n, a, b;
    size_t p, k, nd = w->nodes * (size_t)d;
    for (k = 0; k < w->nodes; ++k)
        for (i = 0; i < d; ++i) w->diag[k * (size_t)d + (size_t)i] = w->grid_m[k];
    for (p = 0; p < w->n; ++p) {
        pn__mpm_kernel kr;
        const pn_real *Fn = w->F + p * (size_t)dd, *H = w->pH + p * (size_t)(dd * dd);
        if (!w->active[p]) continue;
        pn__mpm_kernel_at(w, w->x + p * (size_t)d, &kr);
        for (n = 0; n < kr.count; ++n) {
            pn_real q[3]; /* q = F^nT grad w */
            for (j = 0; j < d; ++j) {
                q[j] = 0;
                for (l = 0; l < d; ++l) q[j] += Fn[l * d + j] * kr.gw[n][l];
            }
            for (i = 0; i < d; ++i) {
                pn_real acc = 0; /* sum_ab H[(i a),(i b)] q_a q_b */
                for (a = 0; a < d; ++a)
                    for (b = 0; b < d; ++b) acc += H[(i * d + a) * dd + i * d + b] * q[a] * q[b];
                w->diag[kr.node[n] * (size_t)d + (size_t)i] += w->vol0[p] * dt * dt * acc;
            }
        }
    }
    for (k = 0; k < nd; ++k)
        if (!(w->diag[k] > 0)) w->diag[k] = 1;
}

static pn_real pn__mpm_dot(size_t n, const pn_real *a, const pn_real *b) {
    pn_real s = 0;
    size_t i;
    for (i = 0; i < n; ++i) s += a[i] * b[i];
    return s;
}

/* Solve H dir = -grad by preconditioned CG over the free components; returns iterations. */
static int pn__mpm_pcg(pn_mpm_world *w, pn_real dt, int max_it, pn_real rel_tol) {
    size_t nd = w->nodes * (size_t)w->dim, k;
    pn_real rz, r0, rr;
    int it;
    pn__mpm_diagonal(w, dt);
    for (k = 0; k < nd; ++k) {
        int free_ = !w->fixed[k] && w->grid_m[k / (size_t)w->dim] > 0;
        w->dir[k] = 0;
        w->cg_r[k] = free_ ? -w->grad[k] : 0;
        w->cg_z[k] = w->cg_r[k] / w->diag[k];
        w->cg_p[k] = w->cg_z[k];
    }
    rz = pn__mpm_dot(nd, w->cg_r, w->cg_z);
    r0 = PN__SQRT(pn__mpm_dot(nd, w->cg_r, w->cg_r));
    if (r0 == 0) return 0;
    for (it = 0; it < max_it; ++it) {
        pn_real pq, alpha, rz_new, beta;
        pn__mpm_hess_vec(w, w->cg_p, dt, w->cg_q);
        pq = pn__mpm_dot(nd, w->cg_p, w->cg_q);
        if (!(pq > 0)) break; /* PSD Hessian plus mass: only rounding gets here */
        alpha = rz / pq;
        for (k = 0; k < nd; ++k) {
            w->dir[k] += alpha * w->cg_p[k];
            w->cg_r[k] -= alpha * w->cg_q[k];
        }
        rr = PN__SQRT(pn__mpm_dot(nd, w->cg_r, w->cg_r));
        if (rr <= rel_tol * r0) return it + 1;
        for (k = 0; k < nd; ++k) w->cg_z[k] = w->cg_r[k] / w->diag[k];
        rz_new = pn__mpm_dot(nd, w->cg_r, w->cg_z);
        beta = rz_new / rz;
        rz = rz_new;
        for (k = 0; k < nd; ++k) w->cg_p[k] = w->cg_z[k] + beta * w->cg_p[k];
    }
    return it;
}

/* Per-pass preparation of every particle's energy at F0 = F(v) (lagged G, PlasticityNet
   point); returns max |F0_new - F0_old| in *res (0 on the first pass). */
static pn_result pn__mpm_prepare_pass(pn_mpm_world *w, const pn_real *v, pn_real dt, int first,
                                      pn_real *res) {
    int d = w->dim, dd = d * d, i;
    size_t p;
    pn_real worst = 0;
    for (p = 0; p < w->n; ++p) {
        const pn_mpm_group *g = &w->groups[w->group[p]];
        pn__mpm_kernel kr;
        pn_real F0[9], *old = w->pF0 + p * (size_t)dd;
        pn_result r = PN_OK;
        pn_mpm_energy en;
        if (!w->active[p]) continue;
        pn__mpm_kernel_at(w, w->x + p * (size_t)d, &kr);
        pn__mpm_F_of(w, p, &kr, v, dt, F0);
        if (!first)
            for (i = 0; i < dd; ++i) worst = PN__MAX(worst, PN__FABS(F0[i] - old[i]));
        memcpy(old, F0, sizeof(pn_real) * (size_t)dd);
        en = pn__mpm_energy_of(g);
        if (en == PN_MPM_ENERGY_LAGGED)
            r = pn_lagged_prepare(&g->material, d, F0, w->h[p], w->pG + p * (size_t)dd, &w->phG[p]);
        else if (en == PN_MPM_ENERGY_PNET)
            r = pn_pnet_prepare(&g->pnet, F0, w->h[p], &w->ppt[p], NULL, NULL);
        if (r != PN_OK) {
            w->error_particle = p;
            return r;
        }
    }
    *res = worst;
    return PN_OK;
}

/* the new state in scratch becomes the world */
static void pn__mpm_commit(pn_mpm_world *w, pn_real dt, pn_mpm_stats *st) {
    pn_real *t;
    unsigned char *u;
    t = w->x; w->x = w->sx; w->sx = t;
    t = w->v; w->v = w->sv; w->sv = t;
    t = w->C; w->C = w->sC; w->sC = t;
    t = w->F; w->F = w->sF; w->sF = t;
    t = w->h; w->h = w->sh; w->sh = t;
    u = w->active; w->active = w->sactive; w->sactive = u;
    w->left_total += st->left_domain;
    w->time_s += dt;
    w->steps++;
}

/* Grid to particles into scratch: APIC v, C; x += dt v; F from gradF (0: (I + dt C) F as in
   the explicit step, 1: F(v) with the weight gradients, as the implicit energy saw it); then
   the return mapping. */
static pn_result pn__mpm_g2p(pn_mpm_world *w, const pn_real *gv_all, pn_real dt, int gradF,
                             pn_mpm_stats *st) {
    int d = w->dim, dd = d * d, i, j, n;
    size_t p;
    pn_real inv_dx = 1 / w->desc.dx_m;
    for (p = 0; p < w->n; ++p) {
        const pn_mpm_group *g = &w->groups[w->group[p]];
        pn__mpm_kernel kr;
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
        pn__mpm_kernel_at(w, xp, &kr);
        for (n = 0; n < kr.count; ++n) {
            const pn_real *gv = gv_all + kr.node[n] * (size_t)d;
            for (i = 0; i < d; ++i) {
                nv[i] += kr.w[n] * gv[i];
                for (j = 0; j < d; ++j) nC[i * d + j] += 4 * inv_dx * inv_dx * kr.w[n] * gv[i] * kr.dpos[n][j];
            }
        }
        if (gradF) {
            pn__mpm_F_of(w, p, &kr, gv_all, dt, Fn);
        } else {
            for (i = 0; i < dd; ++i) G[i] = dt * nC[i];
            for (i = 0; i < d; ++i) G[i * d + i] += 1;
            pn_mat_mul(d, G, w->F + p * (size_t)dd, Fn);
        }
        r = pn_return_map(&g->material, d, Fn, w->h[p], Z, &hn, NULL);
        if (r == PN_OK && (!pn__all_finite(d, nv) || !pn__all_finite(dd, nC))) r = PN_ERROR_OVERFLOW;
        if (r != PN_OK) {
            w->error_particle = p;
            return r;
        }
        if (hn != w->h[p] || memcmp(Z, Fn, sizeof(pn_real) * (size_t)dd) != 0) st->plastic++;
        for (i = 0; i < d; ++i) {
            w->sv[p * (size_t)d + (size_t)i] = nv[i];
            w->sx[p * (size_t)d + (size_t)i] = xp[i] + dt * nv[i];
            sp += nv[i] * nv[i];
        }
        memcpy(w->sC + p * (size_t)dd, nC, sizeof(pn_real) * (size_t)dd);
        memcpy(w->sF + p * (size_t)dd, Z, sizeof(pn_real) * (size_t)dd);
        w->sh[p] = hn;
        if (!pn__mpm_in_grid(w, w->sx + p * (size_t)d)) { /* went through a wall: retire it */
            w->sactive[p] = 0;
            st->left_domain++;
            continue;
        }
        st->particles++;
        st->max_speed_m_s = PN__MAX(st->max_speed_m_s, PN__SQRT(sp));
    }
    return PN_OK;
}

/* Particle to grid without stress: node mass and APIC momentum (grid_v holds momentum). */
static void pn__mpm_p2g_momentum(pn_mpm_world *w) {
    int d = w->dim, dd = d * d, i, j, n;
    size_t p;
    memset(w->grid_m, 0, sizeof(pn_real) * w->nodes);
    memset(w->grid_v, 0, sizeof(pn_real) * w->nodes * (size_t)d);
    for (p = 0; p < w->n; ++p) {
        pn__mpm_kernel kr;
        const pn_real *vp = w->v + p * (size_t)d, *C = w->C + p * (size_t)dd;
        if (!w->active[p]) continue;
        pn__mpm_kernel_at(w, w->x + p * (size_t)d, &kr);
        for (n = 0; n < kr.count; ++n) {
            pn_real *gv = w->grid_v + kr.node[n] * (size_t)d, wm = kr.w[n] * w->mass[p];
            w->grid_m[kr.node[n]] += wm;
            for (i = 0; i < d; ++i) {
                pn_real acc = vp[i];
                for (j = 0; j < d; ++j) acc += C[i * d + j] * kr.dpos[n][j];
                gv[i] += wm * acc;
            }
        }
    }
}

PN__DEF pn_result pn_mpm_step_implicit(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *desc,
                                       pn_mpm_stats *stats) {
    pn_mpm_implicit_desc o;
    pn_mpm_stats st;
    int d, i, pass;
    size_t k, nd;
    pn_result r;
    pn_real vscale;
    PN_ASSERT(w);
    if (!pn__finite(dt) || !(dt > 0)) return PN_ERROR_INVALID_ARGUMENT;
    memset(&o, 0, sizeof o);
    if (desc) o = *desc;
    if (o.fixed_point_iters <= 0) o.fixed_point_iters = 2;
    if (o.newton_max <= 0) o.newton_max = 50;
    if (o.cg_max <= 0) o.cg_max = 500;
    if (!(o.newton_tol > 0)) o.newton_tol = (pn_real)1e-5;
    if (!(o.cg_rel_tol > 0)) o.cg_rel_tol = (pn_real)1e-3;
    r = pn__mpm_alloc_implicit(w);
    if (r != PN_OK) return r;
    d = w->dim;
    nd = w->nodes * (size_t)d;
    vscale = o.newton_tol * w->desc.dx_m / dt;
    memset(&st, 0, sizeof st);
    /* v* = momentum / mass + dt g; wall components held at zero (sticky: all; slip and
       separate: the normal one, which the solve treats as slip) */
    pn__mpm_p2g_momentum(w);
    for (k = 0; k < w->nodes; ++k) {
        pn_real m = w->grid_m[k];
        size_t rem = k;
        int idx[3];
        for (i = d - 1; i >= 0; --i) {
            idx[i] = (int)(rem % (size_t)(w->desc.res[i] + 1));
            rem /= (size_t)(w->desc.res[i] + 1);
        }
        for (i = 0; i < d; ++i) {
            size_t c = k * (size_t)d + (size_t)i;
            w->vstar[c] = m > 0 ? w->grid_v[c] / m + dt * w->desc.gravity[i] : 0;
            w->fixed[c] = 0;
        }
        for (i = 0; i < d; ++i) {
            int wall = idx[i] < w->wall || idx[i] > w->desc.res[i] - w->wall, j;
            if (!wall) continue;
            if (w->desc.boundary == PN_MPM_BOUNDARY_STICKY)
                for (j = 0; j < d; ++j) w->fixed[k * (size_t)d + (size_t)j] = 1;
            else
                w->fixed[k * (size_t)d + (size_t)i] = 1;
        }
        for (i = 0; i < d; ++i)
            if (w->fixed[k * (size_t)d + (size_t)i]) w->vstar[k * (size_t)d + (size_t)i] = 0;
    }
    memcpy(w->vsol, w->vstar, sizeof(pn_real) * nd);
    for (pass = 0; pass < o.fixed_point_iters; ++pass) {
        pn_real fp_res = 0;
        int it;
        r = pn__mpm_prepare_pass(w, w->vsol, dt, pass == 0, &fp_res);
        if (r != PN_OK) return r;
        if (pass > 0) st.fixed_point_residual = fp_res;
        st.fixed_point_iters++;
        for (it = 0; it < o.newton_max; ++it) {
            pn_real E0, E1, gd, alpha = 1, dmax = 0;
            r = pn__mpm_objective(w, w->vsol, dt, 1, &E0);
            if (r != PN_OK) return r;
            st.cg_iters += pn__mpm_pcg(w, dt, o.cg_max, o.cg_rel_tol);
            st.newton_iters++;
            for (k = 0; k < nd; ++k) dmax = PN__MAX(dmax, PN__FABS(w->dir[k]));
            st.newton_residual = dmax / (w->desc.dx_m / dt);
            if (!pn__finite(dmax)) {
                w->error_particle = 0;
                return PN_ERROR_OVERFLOW;
            }
            if (dmax <= vscale) break;
            gd = pn__mpm_dot(nd, w->grad, w->dir);
            for (;;) { /* backtracking with the Armijo condition */
                for (k = 0; k < nd; ++k) w->vtry[k] = w->vsol[k] + alpha * w->dir[k];
                pn__mpm_objective(w, w->vtry, dt, 0, &E1);
                if (E1 <= E0 + (pn_real)1e-4 * alpha * gd) break;
                alpha /= 2;
                if (alpha < (pn_real)1e-10) break;
            }
            if (alpha < (pn_real)1e-10) { /* no decrease: keep v, count it, stop this pass */
                st.line_search_failures++;
                break;
            }
            memcpy(w->vsol, w->vtry, sizeof(pn_real) * nd);
        }
    }
    for (k = 0; k < nd; ++k)
        if (!pn__finite(w->vsol[k])) return PN_ERROR_OVERFLOW;
    r = pn__mpm_g2p(w, w->vsol, dt, 1, &st);
    if (r != PN_OK) return r;
    pn__mpm_commit(w, dt, &st);
    if (stats) *stats = st;
    return PN_OK;
}

/* ======================================================================================
   >>explicit: symplectic Euler. P2G of mass, APIC momentum and the stress impulse
   -dt V0 (4/dx^2) tau (x_i - x_p) (tau the Kirchhoff stress of the elastic F; MLS-MPM,
   Hu et al. 2018); grid update; G2P with F = (I + dt C) F and the return mapping.
   ====================================================================================== */

PN__DEF pn_result pn_mpm_step_explicit(pn_mpm_world *w, pn_real dt, pn_mpm_stats *stats) {
    int d, dd, i, j, n;
    size_t p;
    pn_real inv_dx;
    pn_mpm_stats st;
    pn_result r;
    PN_ASSERT(w);
    if (!pn__finite(dt) || !(dt > 0)) return PN_ERROR_INVALID_ARGUMENT;
    d = w->dim;
    dd = d * d;
    inv_dx = 1 / w->desc.dx_m;
    memset(&st, 0, sizeof st);
    pn__mpm_p2g_momentum(w);
    for (p = 0; p < w->n; ++p) {
        pn__mpm_kernel kr;
        const pn_mpm_group *g = &w->groups[w->group[p]];
        pn_real tau[9] = {0}, A[9];
        if (!w->active[p]) continue;
        r = pn_kirchhoff_stress(&g->material, d, w->F + p * (size_t)dd, w->h[p], tau);
        if (r != PN_OK) {
            w->error_particle = p;
            return r;
        }
        for (i = 0; i < dd; ++i) A[i] = -dt * w->vol0[p] * 4 * inv_dx * inv_dx * tau[i];
        pn__mpm_kernel_at(w, w->x + p * (size_t)d, &kr);
        for (n = 0; n < kr.count; ++n) {
            pn_real *gv = w->grid_v + kr.node[n] * (size_t)d;
            for (i = 0; i < d; ++i) {
                pn_real acc = 0;
                for (j = 0; j < d; ++j) acc += A[i * d + j] * kr.dpos[n][j];
                gv[i] += kr.w[n] * acc;
            }
        }
    }
    pn__mpm_grid_update(w, dt);
    r = pn__mpm_g2p(w, w->grid_v, dt, 0, &st);
    if (r != PN_OK) return r;
    pn__mpm_commit(w, dt, &st);
    if (stats) *stats = st;
    return PN_OK;
}

#endif /* PLASTINET_MPM_IMPLEMENTATION */
