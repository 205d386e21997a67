/* plastinet_rom.h - v0.21 - reduced-order MPM on a learned deformation map, on plastinet.h.
   Public domain or MIT, your choice: see the end of plastinet.h.

   Do this in exactly one C or C++ file, after plastinet.h:
       #define PLASTINET_IMPLEMENTATION
       #include "plastinet.h"
       #include "plastinet_rom.h"
       #include "models/rom_cylinder.h"          // a generated model (gen/rom_export.py)

   WHAT IT DOES (Chen, Xiao, Chen, Carlberg, Grinspun 2023: model reduction for MPM on a
   learned deformation map; docs/rom.md has the method and the measured errors)
   A small MLP g(X, xhat) maps a reference point X and a latent vector xhat (a few numbers)
   to the deformed position x. Its Jacobians give the deformation gradient F = dg/dX and the
   velocity v = dg/dxhat vhat of every point of the body, at any resolution. A step moves a
   few sampled points by one MPM step in the full space (the quadrature around them found
   from the map), then projects their new velocities and positions back onto the latent by
   least squares (Algorithm 2 of the paper):
     quadrature  LAGRANGIAN: the body's own points near the samples (Algorithm 3);
                 EULERIAN: l^dim points per grid cell around the samples, each mapped back
                 to X by Newton on g(X, xhat) = x (Algorithm 4), so no point is tracked
     projection  LINEAR: vhat from the velocities, xhat += dt vhat (Eq. 23);
                 NONLINEAR: vhat as well, xhat by Gauss-Newton on the positions (Eqs. 21-22)
     sampling    new random points every step, at least boundary_samples per drive (Sec. 3.3)
   That step is explicit: stable up to about the full-order MPM step. integrator =
   PN_ROM_BDF2 (or PN_ROM_IMPLICIT, PN_ROM_MIDPOINT) replaces it by an implicit step over the
   latent alone (>>implicit): the incremental potential summed over a fixed cubature of the
   body, minimized by Newton, stable at one step per frame.
   Either step costs the same whatever the body's point count; drawing the body costs one
   evaluation of g per drawn point (pn_rom_map, pn_rom_positions), or, through a render
   embedding (pn_rom_embed), one per lattice node plus a 3 x 3 product per point.

   WHAT IS HERE (banners in the implementation: // >>name, in file order)
     room        public functions                 what else
     >>model     pn_rom_model_check,              a model's checks, the affine map, the
                 pn_rom_affine_model,             reference domain and its lattice
                 pn_rom_inside, pn_rom_lattice
     >>mlp       pn_rom_eval                      g and its Jacobians in double
     >>lanes                                      the same in float lanes (the hot path)
     >>world     pn_rom_create, _destroy,         creation, drives, loads, the latent
                 _error, _drive, _release_drive,
                 _add_load, _remove_load,
                 _set_latent
     >>step      pn_rom_stable_dt, pn_rom_step    sampling, the quadrature, the full-space
                                                  update, the projections
     >>implicit                                   backward Euler / BDF2 / midpoint in the
                                                  latent over a fixed cubature
     >>fit, >>render  pn_rom_fit, pn_rom_positions,  the latent of a full state; g at many
                 pn_rom_map                       points
     >>embed     pn_rom_embed, _embed_positions,  a render lattice, points drawn by a
                 _embed_destroy                   Taylor step from their nearest node
   Messages, the hash, B-spline weights, dense Cholesky, the line search and the drives'
   rigid motion come from plastinet.h's >>kit.

   OPTIONS: those of plastinet.h (PN_REAL does not change the ROM's own arithmetic, which
   is double, with the networks in float lanes; PN_NO_STDIO shortens its messages to their
   fixed text; PN_NO_VECTOR_EXTENSIONS: plain loops for the lanes). It has none of its own.

   QUICK START
       pn_rom_desc d;  pn_rom_world *w;  char why[256];  pn_rom_region base;
       memset(&d, 0, sizeof d);                         // zeroed fields mean defaults
       d.model = pn_rom_model_cylinder();  d.gravity[1] = -9.81;
       pn_rom_create(&d, &w, why, sizeof why);          // the model's own point lattice
       memset(&base, 0, sizeof base);  base.hi[0] = 0.024;   // hold the points with X < 2.4 cm
       pn_rom_drive(w, &base, NULL, NULL, NULL, NULL);
       for (;;) { pn_rom_step(w, 1.0 / 144, NULL);  pn_rom_map(w, n, X, x, NULL); draw(x); }
   (d.integrator = PN_ROM_BDF2 before pn_rom_create: pn_rom_step(w, 1.0 / 60, NULL) per frame)

   MEMORY: pn_rom_create allocates the points, the float weights and the step's scratch for
   the sample count it is given; the first steps grow the quadrature buffers to what the
   scene needs (doubling), after which a step allocates nothing.
   ERRORS: every call that fails returns its pn_result, leaves the world as it was, and
   pn_rom_error(w) says why, naming the argument, point or model field at fault.
   STEP SIZE: the explicit step refuses dt above 1.5x pn_rom_stable_dt (PN_ERROR_STEP_TOO_LARGE);
   models are format 2 (PN_ROM_FORMAT_VERSION: array lengths; gen/upgrade_rom_format.py).
   THREADS: with -fopenmp the map evaluations (the bulk of a step) run on threads, each
   point into its own slot; sums over points run in point order on one thread, so the bits
   do not depend on the thread count.
*/
#ifndef PLASTINET_ROM_H
#define PLASTINET_ROM_H
#ifndef PLASTINET_H
#error "include plastinet.h first"
#endif
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Layout version of pn_rom_model (gen/rom_export.py writes it; another version is refused with
   PN_ERROR_FORMAT). Version 2 added the lengths of the model's arrays (width_count ..
   occupied_count), checked against the sizes they must have; gen/upgrade_rom_format.py
   converts version-1 headers. */
#define PN_ROM_FORMAT_VERSION 2
#define PN_ROM_MAX_LATENT 32   /* d_hat                                                      */
#define PN_ROM_MAX_WIDTH 64    /* a hidden layer of g                                        */
#define PN_ROM_MAX_LAYERS 8    /* linear layers of g                                         */
#define PN_ROM_MAX_DRIVES 8
#define PN_ROM_MAX_LOADS 16
#define PN_ROM_MAX_REFINE 64   /* pn_rom_desc.refine: 64^3 lattice points per occupancy cell    */
#define PN_ROM_MAX_CELLS 4096  /* occupancy cells per axis of a model's reference domain       */
#define PN_ROM_MAX_POINTS ((size_t)1 << 26) /* a world's points (67 million)                  */

/* g's activation: the kind of map */
enum {
    PN_ROM_AFFINE = 0,         /* no network: x = X + b + A X, xhat = (b, A row-major), d + d^2
                                  latents (pn_rom_affine_model): an affine body             */
    PN_ROM_ELU = 1             /* an MLP with ELU (alpha 1) hidden layers                     */
};

/* A deformation map, as gen/rom_export.py writes it (models/rom_*.h). */
typedef struct pn_rom_model {
    int format_version;            /* PN_ROM_FORMAT_VERSION                                  */
    const char *name;
    int dim, latent;               /* d, d_hat                                               */
    int n_layers;                  /* linear layers of g (hidden + 1)                        */
    const int *width;              /* n_layers + 1: d + d_hat, hidden widths ..., d          */
    const double *const *weight;   /* per layer: width[l+1] x width[l], row-major            */
    const double *const *bias;     /* per layer: width[l+1]                                  */
    int activation;                /* PN_ROM_ELU, PN_ROM_AFFINE                              */
    double in_lo[3], in_hi[3];     /* Xn = 2 (X - in_lo) / (in_hi - in_lo) - 1               */
    double out_mean[3], out_std[3];/* x = out_mean + out_std net(Xn, xhat)                   */
    const double *latent_rest;     /* d_hat: the latent of the rest state (NULL: zeros)      */
    const double *latent_std;      /* d_hat: spread of the training latents (NULL: ones)     */
    double cell_m;                 /* the reference domain: occupancy cells of this size     */
    double origin_m[3];            /* from this corner                                       */
    int cells[3];                  /* per axis (0: no domain, every X is material)           */
    const unsigned char *occupied; /* (i cells[1] + j) cells[2] + k: 1 = material            */
    double youngs_pa, poisson, density_kg_m3; /* the training data's material                */
    double dx_m;                   /* its MPM grid, particles per cell per axis,             */
    int per_axis;                  /* and snapshot interval                                  */
    double frame_dt_s;
    /* format 2: the lengths of the arrays above, each checked against the size it must have,
       so a model whose arrays are shorter than its sizes is refused instead of read past
       (weight and bias themselves hold n_layers pointers) */
    int width_count;               /* entries of width: n_layers + 1                         */
    int weight_count[PN_ROM_MAX_LAYERS]; /* entries of weight[l]: width[l+1] x width[l]       */
    int bias_count[PN_ROM_MAX_LAYERS];   /* entries of bias[l]: width[l+1]                    */
    int latent_rest_count, latent_std_count; /* latent each (0 with a NULL array)           */
    size_t occupied_count;         /* bytes of occupied: cells[0] x cells[1] x cells[2]      */
} pn_rom_model;

/* Checks a model (format, sizes, finite weights); PN_ERROR_FORMAT / PN_ERROR_DIMENSION /
   PN_ERROR_INVALID_ARGUMENT with why (optional) naming the field. */
PN_API pn_result pn_rom_model_check(const pn_rom_model *m, char *why, size_t why_cap);

/* The affine map of dimension dim (d + d^2 latents, latent 0 = the identity): a model with
   no network, for affine bodies and for testing the reduced step against full MPM. */
PN_API void pn_rom_affine_model(int dim, pn_rom_model *out);

/* g, F = dg/dX (d x d per point, row = output) and G = dg/dxhat (d x d_hat per point) at n
   reference points X for the latent xhat, in double, one point at a time: the reference the
   fast path is tested against. x, F, G may each be NULL. */
PN_API pn_result pn_rom_eval(const pn_rom_model *m, const double *xhat, size_t n, const double *X, double *x, double *F,
                             double *G);

/* Points of the reference domain: the occupied cells of the model, each sampled refine^dim
   times on a cell-centred lattice (refine 1: the training resolution). Writes up to cap points
   (dim doubles each; X may be NULL to count) and returns the count, counted in closed form
   (occupied cells x refine^dim; SIZE_MAX if that does not fit in a size_t). */
PN_API size_t pn_rom_lattice(const pn_rom_model *m, int refine, double *X, size_t cap);

/* Is X (dim doubles) material, by the model's occupancy cells? */
PN_API int pn_rom_inside(const pn_rom_model *m, const double *X);

typedef enum pn_rom_quadrature { PN_ROM_EULERIAN = 0, PN_ROM_LAGRANGIAN } pn_rom_quadrature;
typedef enum pn_rom_projection { PN_ROM_LINEAR = 0, PN_ROM_NONLINEAR } pn_rom_projection;
typedef enum pn_rom_integrator {
    PN_ROM_EXPLICIT = 0,           /* the paper's step (Algorithm 2): MPM in the full space about
                                      the samples, projected back; stable up to about the
                                      full-order step                                          */
    PN_ROM_IMPLICIT,               /* backward Euler in the latent: xhat minimizes the incremental
                                      potential summed over a fixed cubature of the body, by
                                      Newton; stable at a frame per step, and damps motion
                                      faster than about 1/dt (docs/rom.md, "The implicit step") */
    PN_ROM_BDF2,                   /* the same minimization for the second-order backward
                                      difference: far less damping (backward Euler first)    */
    PN_ROM_MIDPOINT                /* the implicit midpoint rule, minimized at the midpoint:
                                      no numerical damping                                     */
} pn_rom_integrator;
typedef enum pn_rom_transfer {
    PN_ROM_APIC = 0,               /* quadrature points carry C = dF/dt F^-1 (from the map)  */
    PN_ROM_PIC                     /* momentum m v only (the paper's Algorithm 5)            */
} pn_rom_transfer;

typedef struct pn_rom_desc {
    const pn_rom_model *model;
    const double *points;          /* the body's reference points (dim each), copied        */
    size_t n_points;               /* (NULL: the model's lattice at `refine`)                */
    int refine;                    /* [1] .. PN_ROM_MAX_REFINE                               */
    double point_volume_m3;        /* with points: each point's volume [(cell_m/refine)^d]   */
    double dx_m;                   /* the full-space grid [model dx_m]                       */
    double youngs_pa, poisson, density_kg_m3; /* fixed corotated [the model's]               */
    double gravity[3];             /* m/s^2                                                  */
    int samples;                   /* projection points per step [50]; < 0 or >= n: all     */
    int boundary_samples;          /* at least this many points of each drive per step [5]   */
    pn_rom_quadrature quadrature;
    pn_rom_projection projection;
    pn_rom_transfer transfer;
    int quad_per_axis;             /* EULERIAN: points per cell per axis [2]                 */
    int reference;                 /* nonzero: the double path everywhere (slow; for tests)  */
    unsigned long long seed;       /* of the sampling [1]                                    */
    int gn_max;                    /* NONLINEAR: Gauss-Newton iterations [10]                */
    int parallel_min;              /* -fopenmp: batches of fewer points stay on one thread [256] */
    pn_rom_integrator integrator;
    double cubature_m;             /* IMPLICIT: edge of the cubature cells [2 dx_m]: one point per
                                      cell, drive and load, at the centroid of its material;
                                      coarser is faster (4 dx_m: about 5 times fewer points)  */
    int newton_max;                /* IMPLICIT: Newton iterations per step [20]                */
    double newton_tol;             /* IMPLICIT: done when a Newton step moves each latent by less
                                      than this fraction of its training spread [1e-3]         */
    double drive_weight;           /* IMPLICIT: driven points' penalty, in units of their
                                      inertia plus elastic stiffness [100]                     */
    int drive_region_only;         /* IMPLICIT: nonzero drives just the region's points; 0: also
                                      the points MPM holds with them, whose whole interpolation
                                      stencil lies on nodes the region's points touch [0]      */
    pn_allocator allocator;
} pn_rom_desc;

/* A region of the reference domain: the box lo .. hi (a zero box: all of space) and, if
   radius > 0, the ball about center. */
typedef struct pn_rom_region {
    double lo[3], hi[3], center[3], radius;
} pn_rom_region;

typedef struct pn_rom_stats {
    size_t samples;                /* projection points                                      */
    size_t quad_points;            /* quadrature points used                                 */
    size_t nodes;                  /* grid nodes of the full-space update                    */
    size_t inverse_failed;         /* EULERIAN: lattice points whose X Newton did not find   */
    int gn_iters;             /* NONLINEAR                                              */
    double residual_m;             /* RMS distance of the projected samples to their trial   */
    size_t cubature_points;        /* IMPLICIT                                                */
    int newton_iters;         /* IMPLICIT                                                */
    double energy_j;               /* IMPLICIT: the incremental potential at the new latent   */
} pn_rom_stats;

typedef struct pn_rom_world pn_rom_world; /* below; read the public part, do not write it */

/* Create a world (*out set on success): the model checked, its weights copied to float, the
   points (desc->points, or the model's lattice) with their masses, the latent at the
   model's rest latent and at rest. PN_ERROR_* with why naming the field. */
PN_API pn_result pn_rom_create(const pn_rom_desc *desc, pn_rom_world **out, char *why, size_t why_cap);
PN_API void pn_rom_destroy(pn_rom_world *w);
PN_API const char *pn_rom_error(const pn_rom_world *w);

/* Drive the material of region r rigidly from now on (as pn_mpm_drive_particles: velocity
   dim reals, center dim reals, angular velocity 3 reals (2D: [2]); NULLs: zero, held). */
PN_API pn_result pn_rom_drive(pn_rom_world *w, const pn_rom_region *r, const double *velocity_m_s,
                              const double *center_m, const double *angular_velocity_rad_s, int *index);
PN_API pn_result pn_rom_release_drive(pn_rom_world *w, int index);

/* Apply force_N (in total) to the material of region r for duration_s from now (0: until
   removed), shared by mass (as pn_mpm_add_load). */
PN_API pn_result pn_rom_add_load(pn_rom_world *w, const pn_rom_region *r, const double *force_N, double duration_s,
                                 int *index);
PN_API pn_result pn_rom_remove_load(pn_rom_world *w, int index);

/* Set the latent and its velocity (d_hat each; vhat NULL: 0). */
PN_API pn_result pn_rom_set_latent(pn_rom_world *w, const double *xhat, const double *vhat);

/* The latent of a full state (Eq. 19): xhat minimizing sum_p |g(X_p, xhat) - x_p|^2 over the
   world's points by Gauss-Newton from the current latent, and (v not NULL) vhat minimizing
   sum_p |G_p vhat - v_p|^2. x, v: dim per point. *rms_m (optional): the RMS misfit. */
PN_API pn_result pn_rom_fit(pn_rom_world *w, const double *x, const double *v, double *rms_m);

/* One reduced step of dt seconds (Algorithm 2). PN_ERROR_NONFINITE when the state would not
   be finite (the step too large for the scene), PN_ERROR_NOT_CONVERGED when the projection
   fails; the world is unchanged then. The explicit step (PN_ROM_EXPLICIT) refuses dt_s above
   1.5x pn_rom_stable_dt with PN_ERROR_STEP_TOO_LARGE; the implicit ones refuse a step whose free
   flight (x_n + dt v_n + dt^2 g) would carry material beyond 1e4 body sizes,
   where the incremental potential is all rounding (PN_ERROR_STEP_TOO_LARGE too). */
PN_API pn_result pn_rom_step(pn_rom_world *w, double dt_s, pn_rom_stats *stats);

/* The largest explicit step (s) the current state allows, as pn_mpm_stable_dt:
       dt = PN_ROM_CFL dx / (c + |v|max),   c = sqrt((lambda + 2 mu) / rho),
   dx the full-space grid (pn_rom_desc.dx_m), lambda, mu, rho the world's material, |v|max the
   largest speed G vhat at up to 256 of the world's points (evenly strided). The factor, twice
   MPM's 0.9, is measured (docs/rom.md, "Step size"): on the cylinder every scheme (EL, EN, LL,
   LN) ran stable at 1.5 times this bound and the nonlinear projections blew up at twice it,
   the linear ones at three times. The implicit integrators are not bound by it. */
#define PN_ROM_CFL 1.8
#define PN__ROM_MAX_FLIGHT 1e4 /* implicit steps: free flight per step, in body sizes          */
PN_API pn_result pn_rom_stable_dt(const pn_rom_world *w, double *dt_s);

/* Reconstruction for drawing, from the current latent, in float: positions (and F, d x d,
   optional) of the world's points first .. first + n - 1, or of any reference points X. */
PN_API pn_result pn_rom_positions(const pn_rom_world *w, size_t first, size_t n, float *x, float *F);
PN_API pn_result pn_rom_map(const pn_rom_world *w, size_t n, const float *X, float *x, float *F);

/* A render embedding: for drawing many points fast. Each of n reference points X is tied to
   the nearest node of a lattice of spacing spacing_m; pn_rom_embed_positions evaluates g and
   F once per used node and places each point at x_node + F_node (X - X_node), a first-order
   Taylor step: the error against pn_rom_map is about |d2g/dX2| spacing^2 / 4 (bench_rom
   measures it), the cost per point a 3 x 3 product. */
typedef struct pn_rom_embedding {
    int dim;
    size_t n, n_nodes;
    float *off;                    /* n x dim: X - X_node                                     */
    size_t *node;                  /* n: the point's node                                     */
    double *nX, *nx, *nF;          /* per node: X, and g and F at the last evaluation         */
    pn_allocator allocator;
} pn_rom_embedding;
PN_API pn_result pn_rom_embed(pn_rom_world *w, size_t n, const float *X, double spacing_m, pn_rom_embedding **out);
PN_API pn_result pn_rom_embed_positions(const pn_rom_world *w, pn_rom_embedding *e, float *x);
PN_API void pn_rom_embed_destroy(pn_rom_embedding *e);

/* ---- the world (read-only outside the library) ------------------------------------------ */
typedef struct pn__rom_drive {
    pn_rom_region r;
    double vel[3], center[3], omega[3], t0, xhat0[PN_ROM_MAX_LATENT];
    size_t *pts, n_pts;            /* the world's points in the region (boundary sampling)    */
    int on;
} pn__rom_drive;

typedef struct pn__rom_load {
    pn_rom_region r;
    double acc[3], t_end;
    int on;
} pn__rom_load;

typedef struct pn__rom_hash {      /* open addressing: packed integer triple -> slot         */
    unsigned long long *key;       /* key + 1 (0: empty)                                      */
    long *val;
    size_t cap, *used, n_used;
} pn__rom_hash;

struct pn_rom_world {
    pn_rom_desc desc;
    pn_rom_model model;            /* a copy (its arrays are the caller's)                   */
    int dim, latent;
    size_t n;                      /* points                                                 */
    double *X, *mass, *vol;        /* reference positions (dim each), masses, volumes        */
    double xhat[PN_ROM_MAX_LATENT], vhat[PN_ROM_MAX_LATENT], xhat_prev[PN_ROM_MAX_LATENT];
    double time_s;
    long steps;
    char error[256];
    pn_material material;
    pn__rom_drive drives[PN_ROM_MAX_DRIVES];
    pn__rom_load loads[PN_ROM_MAX_LOADS];
    int n_drives, n_loads;
    /* internal: float weights (W row-major out x in, then b, per layer), the scales */
    float *wf;
    size_t wf_off[PN_ROM_MAX_LAYERS + 1];
    double xs[3], xo[3];           /* Xn = xs X + xo                                         */
    /* internal: step scratch, grown as needed */
    unsigned long long rng;
    size_t *perm;                  /* a permutation of the points (sampling without replacement) */
    size_t cap_s, cap_q;
    size_t *sidx;                  /* sample point indices                                   */
    double *sx, *sF, *sG, *sv, *sxt; /* samples: x, F, G, trial v, trial x                    */
    int *sdrv;                     /* sample's drive (-1)                                    */
    double *sX;                    /* samples' reference positions                           */
    double *qx, *qX, *qF, *qG, *qv, *qC, *qT, *qm, *qV0; /* quadrature points (qT: Kirchhoff stress) */
    double *tX, *tx, *tF, *tG;     /* gathered batches (Newton, FD)                          */
    long *tI;
    int *qflag;                    /* bits 0..7 drive, bit 8 + load                           */
    long *qsrc;                    /* EULERIAN: the sample a lattice point came from         */
    unsigned char *qok;
    pn__rom_hash nodes, lat;
    pn__rom_hash xc;               /* EULERIAN: lattice point -> its last X (Newton's guess)  */
    double *xcX;
    size_t n_xc, cap_xc;
    unsigned long long *qkey;      /* EULERIAN: each quadrature point's lattice key          */
    size_t cap_n;
    long long *nidx;               /* node integer triples (3 each)                           */
    double *nm, *np, *nf;          /* node mass, momentum (dim), force (dim)                 */
    int *ndrv;                     /* node's drive (-1)                                      */
    double *px;                    /* LAGRANGIAN: every point's position                     */
    /* internal: IMPLICIT, the cubature (rebuilt when a drive or load changes) and its scratch */
    int cub_dirty, cvel_ok;        /* cvel_ok: 1 cvel holds the last step's velocities, 2 and
                                      cxp, cvp those before it (BDF2)                          */
    size_t n_c, cap_c;
    double *cX, *cm, *cV, *cvel;   /* centroid (dim), mass, volume, last velocity (dim)      */
    double *cxp, *cvp, *cv0;       /* position and velocity a step earlier (BDF2); v_n       */
    double h_prev;                 /* the last implicit step                                 */
    double size_m;                 /* the diagonal of the points' bounding box (at least dx_m) */
    int *cdrv;                     /* the cell's drive (-1)                                   */
    unsigned *cload;               /* its loads (bit k: load k)                               */
    double *cx, *cx0, *cF, *cG, *cJ, *cFt, *ctgt, *cw; /* x, x_n, F, G, dF/dxhat (d^2 x K), FD scratch,
                                      inertia target and weight                               */
};

#ifdef __cplusplus
}
#endif
#endif /* PLASTINET_ROM_H */

/* ==========================================================================================
   IMPLEMENTATION
   ========================================================================================== */
#if defined(PLASTINET_IMPLEMENTATION) && !defined(PLASTINET_ROM_IMPLEMENTATION_DONE)
#define PLASTINET_ROM_IMPLEMENTATION_DONE
#ifndef PLASTINET_IMPLEMENTATION_DONE
#error "plastinet_rom.h: the plastinet.h implementation must come first"
#endif
#include <math.h>
#include <stdarg.h>
#include <string.h>
#ifndef PN_NO_STDIO
#include <stdio.h>
#endif
#ifdef _OPENMP
#include <omp.h>
#endif

/* ======================================================================================
   >>model: checks, the affine map, the reference domain
   ====================================================================================== */

static int pn__rom_finite(double x) { return x == x && x - x == 0; }
static int pn__rom_all_finite(size_t n, const double *a) {
    size_t i;
    double s = 0;
    for (i = 0; i < n; ++i) s += a[i] - a[i];
    return s == 0;
}

#define PN__ROM_MAX_OCCUPANCY (1ull << 28) /* cells of a model's occupancy grid in all */

/* the model's name for messages */
static const char *pn__rom_name(const pn_rom_model *m) { return m->name ? m->name : "?"; }

/* the occupancy grid, the normalisation and the training material of any model */
static pn_result pn__rom_model_common(const pn_rom_model *m, char *why, size_t cap) {
    int i, d = m->dim;
    const char *nm = pn__rom_name(m);
    unsigned long long cells = 1;
    for (i = 0; i < d; ++i)
        if (!pn__rom_finite(m->in_lo[i]) || !pn__rom_finite(m->in_hi[i]) || !(m->in_hi[i] > m->in_lo[i]) ||
            !pn__rom_finite(m->out_mean[i]) || !pn__rom_finite(m->out_std[i]) || !(m->out_std[i] > 0)) {
            pn__msg(why, cap, "model %s: in_lo/in_hi or out_mean/out_std[%d] invalid (need finite, in_hi > in_lo, out_std > 0)",
                        nm, i);
            return PN_ERROR_FORMAT;
        }
    if (!pn__rom_finite(m->youngs_pa) || m->youngs_pa < 0 || !pn__rom_finite(m->density_kg_m3) || m->density_kg_m3 < 0 ||
        !pn__rom_finite(m->poisson) || !(m->poisson > -1 && m->poisson < 0.5) || !pn__rom_finite(m->dx_m) || m->dx_m < 0 ||
        !pn__rom_finite(m->frame_dt_s) || m->frame_dt_s < 0 || m->per_axis < 0) {
        pn__msg(why, cap, "model %s: youngs_pa %g, poisson %g, density_kg_m3 %g, dx_m %g, per_axis %d or frame_dt_s %g "
                    "is not finite or out of range", nm, m->youngs_pa, m->poisson, m->density_kg_m3, m->dx_m, m->per_axis,
                    m->frame_dt_s);
        return PN_ERROR_FORMAT;
    }
    if (m->cells[0] == 0 && m->cells[1] == 0 && m->cells[2] == 0) { /* no reference domain */
        if (m->occupied || m->occupied_count) {
            pn__msg(why, cap, "model %s: occupied is set (occupied_count %lu) but cells is 0 x 0 x 0", nm,
                        (unsigned long)m->occupied_count);
            return PN_ERROR_FORMAT;
        }
        return PN_OK;
    }
    for (i = 0; i < 3; ++i)
        if (m->cells[i] < 1 || m->cells[i] > (i < d ? PN_ROM_MAX_CELLS : 1)) {
            pn__msg(why, cap, "model %s: cells[%d] = %d outside 1 .. %d", nm, i, m->cells[i], i < d ? PN_ROM_MAX_CELLS : 1);
            return PN_ERROR_DIMENSION;
        }
    for (i = 0; i < 3; ++i) cells *= (unsigned long long)m->cells[i];
    if (cells > PN__ROM_MAX_OCCUPANCY) {
        pn__msg(why, cap, "model %s: cells %d x %d x %d: more than %llu occupancy cells", nm, m->cells[0], m->cells[1],
                    m->cells[2], PN__ROM_MAX_OCCUPANCY);
        return PN_ERROR_DIMENSION;
    }
    if (!m->occupied || (unsigned long long)m->occupied_count != cells) {
        pn__msg(why, cap, "model %s: occupied_count = %lu, but cells %d x %d x %d needs %llu bytes%s", nm,
                    (unsigned long)m->occupied_count, m->cells[0], m->cells[1], m->cells[2], cells,
                    m->occupied ? "" : " (occupied is NULL)");
        return PN_ERROR_FORMAT;
    }
    if (!pn__rom_finite(m->cell_m) || !(m->cell_m > 0) || !pn__rom_all_finite((size_t)d, m->origin_m)) {
        pn__msg(why, cap, "model %s: cell_m = %g must be finite and > 0, origin_m finite", nm, m->cell_m);
        return PN_ERROR_FORMAT;
    }
    for (i = 0; i < d; ++i) /* the domain's far corner within the range of the grid keys */
        if (!(fabs(m->origin_m[i]) + m->cell_m * m->cells[i] < 1e6)) {
            pn__msg(why, cap, "model %s: origin_m[%d] + cells x cell_m is beyond 1e6 m", nm, i);
            return PN_ERROR_FORMAT;
        }
    return PN_OK;
}

PN__DEF pn_result pn_rom_model_check(const pn_rom_model *m, char *why, size_t cap) {
    int l, i, d, K;
    const char *nm;
    pn_result r;
    if (!m) {
        pn__msg(why, cap, "model is NULL");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    nm = pn__rom_name(m);
    if (m->format_version != PN_ROM_FORMAT_VERSION) {
        pn__msg(why, cap, "model %s: format_version %d, this plastinet_rom.h reads %d (regenerate it, or convert it with "
                    "gen/upgrade_rom_format.py)", nm, m->format_version, PN_ROM_FORMAT_VERSION);
        return PN_ERROR_FORMAT;
    }
    d = m->dim, K = m->latent;
    if (d != 2 && d != 3) {
        pn__msg(why, cap, "model %s: dim %d is not 2 or 3", nm, d);
        return PN_ERROR_DIMENSION;
    }
    if (m->activation != PN_ROM_ELU && m->activation != PN_ROM_AFFINE) {
        pn__msg(why, cap, "model %s: activation %d is not PN_ROM_ELU or PN_ROM_AFFINE", nm, m->activation);
        return PN_ERROR_FORMAT;
    }
    if (m->activation == PN_ROM_AFFINE ? K != d + d * d : K < 1 || K > PN_ROM_MAX_LATENT) {
        pn__msg(why, cap, "model %s: latent %d must be %s", nm, K,
                    m->activation == PN_ROM_AFFINE ? "dim + dim^2 (affine)" : "1 .. PN_ROM_MAX_LATENT = 32");
        return PN_ERROR_DIMENSION;
    }
    if ((m->latent_rest ? m->latent_rest_count != K : m->latent_rest_count != 0) ||
        (m->latent_std ? m->latent_std_count != K : m->latent_std_count != 0)) {
        pn__msg(why, cap, "model %s: latent_rest_count %d and latent_std_count %d must be latent = %d (0 for a NULL array)",
                    nm, m->latent_rest_count, m->latent_std_count, K);
        return PN_ERROR_FORMAT;
    }
    if ((m->latent_rest && !pn__rom_all_finite((size_t)K, m->latent_rest)) ||
        (m->latent_std && !pn__rom_all_finite((size_t)K, m->latent_std))) {
        pn__msg(why, cap, "model %s: latent_rest or latent_std is not finite", nm);
        return PN_ERROR_FORMAT;
    }
    if (m->latent_std)
        for (i = 0; i < K; ++i)
            if (m->latent_std[i] < 0) {
                pn__msg(why, cap, "model %s: latent_std[%d] = %g < 0", nm, i, m->latent_std[i]);
                return PN_ERROR_FORMAT;
            }
    if ((r = pn__rom_model_common(m, why, cap)) != PN_OK) return r;
    if (m->activation == PN_ROM_AFFINE) return PN_OK;
    if (m->n_layers < 2 || m->n_layers > PN_ROM_MAX_LAYERS || !m->width || !m->weight || !m->bias) {
        pn__msg(why, cap, "model %s: n_layers %d outside 2 .. %d, or width, weight or bias is NULL", nm, m->n_layers,
                    PN_ROM_MAX_LAYERS);
        return PN_ERROR_DIMENSION;
    }
    if (m->width_count != m->n_layers + 1) {
        pn__msg(why, cap, "model %s: width_count = %d, but n_layers %d needs %d widths", nm, m->width_count, m->n_layers,
                    m->n_layers + 1);
        return PN_ERROR_FORMAT;
    }
    if (m->width[0] != d + K || m->width[m->n_layers] != d) {
        pn__msg(why, cap, "model %s: width[0] = %d must be dim + latent = %d and width[%d] = %d must be dim", nm, m->width[0],
                    d + K, m->n_layers, m->width[m->n_layers]);
        return PN_ERROR_DIMENSION;
    }
    for (l = 1; l < m->n_layers; ++l)
        if (m->width[l] < 1 || m->width[l] > PN_ROM_MAX_WIDTH) {
            pn__msg(why, cap, "model %s: width[%d] = %d outside 1 .. %d", nm, l, m->width[l], PN_ROM_MAX_WIDTH);
            return PN_ERROR_DIMENSION;
        }
    for (l = 0; l < PN_ROM_MAX_LAYERS; ++l) {
        int wc = l < m->n_layers ? m->width[l] * m->width[l + 1] : 0, bc = l < m->n_layers ? m->width[l + 1] : 0;
        if (m->weight_count[l] != wc || m->bias_count[l] != bc) {
            pn__msg(why, cap, "model %s: weight_count[%d] = %d and bias_count[%d] = %d, but the widths need %d and %d", nm, l,
                        m->weight_count[l], l, m->bias_count[l], wc, bc);
            return PN_ERROR_FORMAT;
        }
    }
    for (l = 0; l < m->n_layers; ++l)
        if (!m->weight[l] || !m->bias[l] || !pn__rom_all_finite((size_t)m->weight_count[l], m->weight[l]) ||
            !pn__rom_all_finite((size_t)m->bias_count[l], m->bias[l])) {
            pn__msg(why, cap, "model %s: layer %d has missing or non-finite weights (weight[%d], bias[%d])", nm, l, l, l);
            return PN_ERROR_FORMAT;
        }
    return PN_OK;
}

PN__DEF void pn_rom_affine_model(int dim, pn_rom_model *out) {
    int i;
    memset(out, 0, sizeof *out);
    out->format_version = PN_ROM_FORMAT_VERSION;
    out->name = "affine";
    out->dim = dim;
    out->latent = dim + dim * dim;
    out->activation = PN_ROM_AFFINE;
    for (i = 0; i < 3; ++i) out->in_lo[i] = -1, out->in_hi[i] = 1, out->out_std[i] = 1;
    out->youngs_pa = 1e5, out->poisson = 0.3, out->density_kg_m3 = 1000, out->dx_m = 0.01, out->per_axis = 2;
    out->frame_dt_s = 1.0 / 60;
}

PN__DEF int pn_rom_inside(const pn_rom_model *m, const double *X) {
    long c[3] = {0, 0, 0};
    int i;
    if (m->cells[0] <= 0) return 1;
    for (i = 0; i < m->dim; ++i) {
        double u = (X[i] - m->origin_m[i]) / m->cell_m;
        if (!(u >= 0 && u < m->cells[i])) return 0;
        c[i] = (long)u;
    }
    return m->occupied[((size_t)c[0] * (size_t)m->cells[1] + (size_t)c[1]) * (size_t)m->cells[2] + (size_t)c[2]] != 0;
}

/* a x b, or SIZE_MAX when it would not fit in a size_t */
static size_t pn__rom_mul(size_t a, size_t b) { return a && b > (size_t)-1 / a ? (size_t)-1 : a * b; }

PN__DEF size_t pn_rom_lattice(const pn_rom_model *m, int refine, double *X, size_t cap) {
    size_t n = 0, per = 1, occ = 0;
    long c[3], k[3];
    int d = m->dim, r = refine > 1 ? refine : 1, i;
    double h = m->cell_m / r;
    if (m->cells[0] <= 0) return 0;
    for (i = 0; i < d; ++i) per = pn__rom_mul(per, (size_t)r);
    for (c[0] = 0; c[0] < m->cells[0]; ++c[0])
        for (c[1] = 0; c[1] < m->cells[1]; ++c[1])
            for (c[2] = 0; c[2] < (d == 3 ? m->cells[2] : 1); ++c[2]) {
                if (!m->occupied[((size_t)c[0] * (size_t)m->cells[1] + (size_t)c[1]) * (size_t)m->cells[2] + (size_t)c[2]])
                    continue;
                occ++;
                if (!X || n >= cap) continue; /* counted in closed form below */
                for (k[0] = 0; k[0] < r; ++k[0])
                    for (k[1] = 0; k[1] < r; ++k[1])
                        for (k[2] = 0; k[2] < (d == 3 ? r : 1) && n < cap; ++k[2], ++n)
                            for (i = 0; i < d; ++i)
                                X[n * (size_t)d + (size_t)i] = m->origin_m[i] + (double)c[i] * m->cell_m + ((double)k[i] + 0.5) * h;
            }
    return pn__rom_mul(occ, per);
}

/* ======================================================================================
   >>mlp: g and its Jacobians. net(u), u = (Xn, xhat); forward through the hidden layers
   a_l = elu(W_l a_(l-1) + b_l), then out = W_L a + b_L; x = mean + std out. The Jacobian by
   reverse mode, the d output rows at once: lambda_L = W_L rows, lambda_(l-1) = W_l^T (elu'
   (z_l) lambda_l), so J = lambda_0 (d x (d + d_hat)); F = std J_X 2/(hi - lo), G = std J_xhat.
   ====================================================================================== */

/* the affine map: x = X + b + A X, F = I + A, G = [I | X-blocks] */
static void pn__rom_affine(int d, const double *xhat, const double *X, double *x, double *F, double *G) {
    int i, j, K = d + d * d;
    const double *A = xhat + d;
    for (i = 0; i < d; ++i) {
        double s = X[i] + xhat[i];
        for (j = 0; j < d; ++j) s += A[i * d + j] * X[j];
        if (x) x[i] = s;
        if (F)
            for (j = 0; j < d; ++j) F[i * d + j] = (i == j) + A[i * d + j];
        if (G) {
            for (j = 0; j < K; ++j) G[i * K + j] = 0;
            G[i * K + i] = 1;
            for (j = 0; j < d; ++j) G[i * K + d + i * d + j] = X[j];
        }
    }
}

static double pn__rom_elu(double z, double *slope) {
    if (z > 0) {
        *slope = 1;
        return z;
    }
    *slope = exp(z);
    return expm1(z);
}

PN__DEF pn_result pn_rom_eval(const pn_rom_model *m, const double *xhat, size_t n, const double *X, double *x, double *F,
                              double *G) {
    int d = m->dim, K = m->latent, L = m->n_layers;
    size_t p;
    if (m->activation == PN_ROM_AFFINE) {
        for (p = 0; p < n; ++p)
            pn__rom_affine(d, xhat, X + p * (size_t)d, x ? x + p * (size_t)d : NULL, F ? F + p * (size_t)(d * d) : NULL,
                           G ? G + p * (size_t)(d * K) : NULL);
        return PN_OK;
    }
    for (p = 0; p < n; ++p) {
        double a[PN_ROM_MAX_WIDTH + PN_ROM_MAX_LATENT], z[PN_ROM_MAX_WIDTH], s[PN_ROM_MAX_LAYERS][PN_ROM_MAX_WIDTH];
        double lam[3][PN_ROM_MAX_WIDTH + PN_ROM_MAX_LATENT], nl[PN_ROM_MAX_WIDTH + PN_ROM_MAX_LATENT];
        const double *Xp = X + p * (size_t)d;
        int l, o, i, k, win;
        for (i = 0; i < d; ++i) a[i] = 2 * (Xp[i] - m->in_lo[i]) / (m->in_hi[i] - m->in_lo[i]) - 1;
        for (i = 0; i < K; ++i) a[d + i] = xhat[i];
        for (l = 0; l < L; ++l) {
            const double *W = m->weight[l], *b = m->bias[l];
            win = m->width[l];
            for (o = 0; o < m->width[l + 1]; ++o) {
                double t = b[o];
                for (i = 0; i < win; ++i) t += W[o * win + i] * a[i];
                z[o] = t;
            }
            for (o = 0; o < m->width[l + 1]; ++o) a[o] = l + 1 < L ? pn__rom_elu(z[o], &s[l][o]) : z[o];
        }
        if (x)
            for (k = 0; k < d; ++k) x[p * (size_t)d + (size_t)k] = m->out_mean[k] + m->out_std[k] * a[k];
        if (!F && !G) continue;
        for (k = 0; k < d; ++k) { /* reverse mode, one adjoint per output row */
            for (i = 0; i < m->width[L - 1]; ++i) lam[k][i] = m->weight[L - 1][k * m->width[L - 1] + i];
            for (l = L - 2; l >= 0; --l) {
                const double *W = m->weight[l];
                win = m->width[l];
                for (i = 0; i < win; ++i) nl[i] = 0;
                for (o = 0; o < m->width[l + 1]; ++o) {
                    double mu = s[l][o] * lam[k][o];
                    for (i = 0; i < win; ++i) nl[i] += W[o * win + i] * mu;
                }
                for (i = 0; i < win; ++i) lam[k][i] = nl[i];
            }
            for (i = 0; i < d; ++i)
                if (F) F[p * (size_t)(d * d) + (size_t)(k * d + i)] = m->out_std[k] * lam[k][i] * 2 / (m->in_hi[i] - m->in_lo[i]);
            for (i = 0; i < K; ++i)
                if (G) G[p * (size_t)(d * K) + (size_t)(k * K + i)] = m->out_std[k] * lam[k][d + i];
        }
    }
    return PN_OK;
}

/* ======================================================================================
   >>lanes: the float path. PN__ROM_B points at a time, each layer a (width x B) block whose
   inner loops run over the B points (the compiler vectorizes them at -O2); exp for ELU is a
   branch-free polynomial (pn__rom_expf) so it vectorizes too. Same formulas as >>mlp.
   ====================================================================================== */
#define PN__ROM_B 16

/* e^z for z <= 0 in float: z = n ln2 + r, |r| <= ln2/2, e^r by a degree-6 polynomial
   (relative error < 2e-7), 2^n by the exponent bits; z < -87 gives ~0 */
static inline float pn__rom_expf(float z) {
    float n, r, p;
    int ni;
    union {
        float f;
        int i;
    } u;
    z = z < -87.0f ? -87.0f : z;
    n = (float)(int)(z * 1.44269504f - 0.5f); /* round to nearest for z <= 0 */
    r = z - n * 0.693145752f - n * 1.42860677e-6f;
    p = 1.0f + r * (1.0f + r * (0.5f + r * (0.166666672f + r * (0.0416666679f + r * (0.00833333377f + r * 0.00138888892f)))));
    ni = (int)n;
    u.i = (ni + 127) << 23;
    return p * u.f;
}

/* the float net of world w at nb (<= B) points: Xn (d x B, normalized), the first layer's
   latent part c1 (width[1]: W1 xhat + b1); out (d x B, the net's raw output) and, if J, the
   raw Jacobian J[(k (d + K) + i) B + b] */
static void pn__rom_lanes(const pn_rom_world *w, const float *c1, const float *Xn, float *out, float *J) {
    const pn_rom_model *m = &w->model;
    int d = w->dim, K = w->latent, L = m->n_layers, l, o, i, k, b;
    float a[2][PN_ROM_MAX_WIDTH][PN__ROM_B], s[PN_ROM_MAX_LAYERS][PN_ROM_MAX_WIDTH][PN__ROM_B];
    int cur = 0;
    { /* layer 0: the X columns on top of c1 */
        const float *W = w->wf + w->wf_off[0];
        int win = m->width[0];
        for (o = 0; o < m->width[1]; ++o) {
            float z[PN__ROM_B];
            for (b = 0; b < PN__ROM_B; ++b) z[b] = c1[o];
            for (i = 0; i < d; ++i) {
                float wv = W[o * win + i];
                for (b = 0; b < PN__ROM_B; ++b) z[b] += wv * Xn[i * PN__ROM_B + b];
            }
            for (b = 0; b < PN__ROM_B; ++b) {
                float e = pn__rom_expf(z[b] < 0 ? z[b] : 0.0f);
                a[cur][o][b] = z[b] > 0 ? z[b] : e - 1.0f;
                s[0][o][b] = z[b] > 0 ? 1.0f : e;
            }
        }
    }
    for (l = 1; l < L; ++l) {
        const float *W = w->wf + w->wf_off[l], *bias = W + m->width[l + 1] * m->width[l];
        int win = m->width[l], last = l + 1 == L;
        for (o = 0; o < m->width[l + 1]; ++o) {
            float z[PN__ROM_B];
            for (b = 0; b < PN__ROM_B; ++b) z[b] = bias[o];
            for (i = 0; i < win; ++i) {
                float wv = W[o * win + i];
                for (b = 0; b < PN__ROM_B; ++b) z[b] += wv * a[cur][i][b];
            }
            if (last) {
                for (b = 0; b < PN__ROM_B; ++b) out[o * PN__ROM_B + b] = z[b];
            } else {
                for (b = 0; b < PN__ROM_B; ++b) {
                    float e = pn__rom_expf(z[b] < 0 ? z[b] : 0.0f);
                    a[1 - cur][o][b] = z[b] > 0 ? z[b] : e - 1.0f;
                    s[l][o][b] = z[b] > 0 ? 1.0f : e;
                }
            }
        }
        cur = 1 - cur;
    }
    if (!J) return;
    for (k = 0; k < d; ++k) {
        float lam[2][PN_ROM_MAX_WIDTH + PN_ROM_MAX_LATENT][PN__ROM_B];
        const float *WL = w->wf + w->wf_off[L - 1];
        int c = 0;
        for (i = 0; i < m->width[L - 1]; ++i)
            for (b = 0; b < PN__ROM_B; ++b) lam[c][i][b] = WL[k * m->width[L - 1] + i];
        for (l = L - 2; l >= 0; --l) {
            const float *W = w->wf + w->wf_off[l];
            int win = m->width[l];
            for (i = 0; i < win; ++i)
                for (b = 0; b < PN__ROM_B; ++b) lam[1 - c][i][b] = 0;
            for (o = 0; o < m->width[l + 1]; ++o) {
                float mu[PN__ROM_B];
                for (b = 0; b < PN__ROM_B; ++b) mu[b] = s[l][o][b] * lam[c][o][b];
                for (i = 0; i < win; ++i) {
                    float wv = W[o * win + i];
                    for (b = 0; b < PN__ROM_B; ++b) lam[1 - c][i][b] += wv * mu[b];
                }
            }
            c = 1 - c;
        }
        for (i = 0; i < d + K; ++i)
            for (b = 0; b < PN__ROM_B; ++b) J[((size_t)k * (size_t)(d + K) + (size_t)i) * PN__ROM_B + (size_t)b] = lam[c][i][b];
    }
}

/* g (and F, G) of world w at n points X (dim doubles each) for latent xhat, into doubles:
   the float lanes, or pn_rom_eval when the world is in reference mode or affine. Threads
   take whole batches; each point writes only its own outputs. */
static void pn__rom_map(const pn_rom_world *w, const double *xhat, size_t n, const double *X, double *x, double *F,
                        double *G) {
    const pn_rom_model *m = &w->model;
    int d = w->dim, K = w->latent;
    long nb = (long)((n + PN__ROM_B - 1) / PN__ROM_B), lb;
    float c1[PN_ROM_MAX_WIDTH];
    if (w->desc.reference || m->activation == PN_ROM_AFFINE) {
        pn_rom_eval(m, xhat, n, X, x, F, G);
        return;
    }
    {
        const float *W = w->wf + w->wf_off[0];
        int o, i, win = m->width[0];
        for (o = 0; o < m->width[1]; ++o) {
            double t = (double)W[m->width[1] * win + o]; /* the bias follows W */
            for (i = 0; i < K; ++i) t += (double)W[o * win + d + i] * xhat[i];
            c1[o] = (float)t;
        }
    }
#if defined(_OPENMP)
#pragma omp parallel for schedule(dynamic, 4) if (n >= (size_t)w->desc.parallel_min)
#endif
    for (lb = 0; lb < nb; ++lb) {
        float Xn[3 * PN__ROM_B], out[3 * PN__ROM_B], J[3 * (3 + PN_ROM_MAX_LATENT) * PN__ROM_B];
        size_t p0 = (size_t)lb * PN__ROM_B, p;
        int b, i, k, cnt = (int)(n - p0 < PN__ROM_B ? n - p0 : PN__ROM_B);
        for (i = 0; i < d; ++i)
            for (b = 0; b < PN__ROM_B; ++b)
                Xn[i * PN__ROM_B + b] = b < cnt ? (float)(w->xs[i] * X[(p0 + (size_t)b) * (size_t)d + (size_t)i] + w->xo[i]) : 0.0f;
        pn__rom_lanes(w, c1, Xn, out, (F || G) ? J : NULL);
        for (b = 0; b < cnt; ++b) {
            p = p0 + (size_t)b;
            for (k = 0; k < d; ++k) {
                if (x) x[p * (size_t)d + (size_t)k] = m->out_mean[k] + m->out_std[k] * (double)out[k * PN__ROM_B + b];
                if (F)
                    for (i = 0; i < d; ++i)
                        F[p * (size_t)(d * d) + (size_t)(k * d + i)] =
                            m->out_std[k] * w->xs[i] * (double)J[((size_t)k * (size_t)(d + K) + (size_t)i) * PN__ROM_B + (size_t)b];
                if (G)
                    for (i = 0; i < K; ++i)
                        G[p * (size_t)(d * K) + (size_t)(k * K + i)] =
                            m->out_std[k] * (double)J[((size_t)k * (size_t)(d + K) + (size_t)(d + i)) * PN__ROM_B + (size_t)b];
            }
        }
    }
}

/* the kit's line search in double, and the misfit it halves on in the Gauss-Newton
   projections: sum over the n points of |target - g(X, xhat)|^2 (x: scratch for g) */
PN__ARMIJO_DEF(pn__rom_armijo, double)
typedef struct pn__rom_misfit_ctx {
    const pn_rom_world *w;
    size_t n;
    const double *X, *target;
    double *x;
} pn__rom_misfit_ctx;

static pn_result pn__rom_misfit(void *ctx, const double *xhat, double *E) {
    const pn__rom_misfit_ctx *c = (const pn__rom_misfit_ctx *)ctx;
    size_t s, nd = c->n * (size_t)c->w->dim;
    double e = 0;
    pn__rom_map(c->w, xhat, c->n, c->X, c->x, NULL, NULL);
    for (s = 0; s < nd; ++s) e += (c->target[s] - c->x[s]) * (c->target[s] - c->x[s]);
    *E = e;
    return PN_OK;
}

/* ======================================================================================
   >>world: creation, drives, loads, the latent
   ====================================================================================== */

/* the const calls' failure message: the world's error text is the one thing they write */
#define PN__ROM_CFAIL(w, r, ...) PN__FAIL((pn_rom_world *)(w), r, __VA_ARGS__) /* >>kit */

PN__DEF const char *pn_rom_error(const pn_rom_world *w) { return w ? w->error : ""; }

static void *pn__rom_alloc(const pn_rom_world *w, size_t count, size_t size, int *fail) {
    void *p;
    if (*fail) return NULL;
    if (size && count > ((size_t)-1 - 1) / size) { /* count x size would wrap */
        *fail = 1;
        return NULL;
    }
    p = pn_alloc(&w->desc.allocator, count * size + 1);
    if (!p) *fail = 1;
    else memset(p, 0, count * size + 1);
    return p;
}

static void pn__rom_hash_free(const pn_rom_world *w, pn__rom_hash *h) {
    pn_free(&w->desc.allocator, h->key), pn_free(&w->desc.allocator, h->val), pn_free(&w->desc.allocator, h->used);
    memset(h, 0, sizeof *h);
}

static void pn__rom_scratch_free(pn_rom_world *w) {
    void *a[] = {w->sidx, w->sX, w->sx, w->sF, w->sG, w->sv, w->sxt, w->sdrv, w->qx, w->qX, w->qF, w->qG, w->qv, w->qC,
                 w->qT, w->qm, w->qV0, w->qflag, w->qsrc, w->qkey, w->qok, w->tX, w->tx, w->tF, w->tG, w->tI,
                 w->nidx, w->nm, w->np, w->nf, w->ndrv};
    size_t i;
    for (i = 0; i < sizeof a / sizeof a[0]; ++i) pn_free(&w->desc.allocator, a[i]);
    w->sidx = NULL, w->sX = w->sx = w->sF = w->sG = w->sv = w->sxt = NULL, w->sdrv = NULL;
    w->qx = w->qX = w->qF = w->qG = w->qv = w->qC = w->qT = w->qm = w->qV0 = NULL, w->qflag = NULL, w->qsrc = NULL;
    w->qok = NULL, w->tX = w->tx = w->tF = w->tG = NULL, w->tI = NULL, w->qkey = NULL;
    w->nidx = NULL, w->nm = w->np = w->nf = NULL, w->ndrv = NULL;
    w->cap_s = w->cap_q = w->cap_n = 0;
}

PN__DEF void pn_rom_destroy(pn_rom_world *w) {
    int a;
    if (!w) return;
    pn__rom_scratch_free(w);
    pn__rom_hash_free(w, &w->nodes);
    pn__rom_hash_free(w, &w->lat);
    pn__rom_hash_free(w, &w->xc);
    pn_free(&w->desc.allocator, w->xcX);
    {
        void *c[] = {w->cX, w->cm, w->cV, w->cvel, w->cxp, w->cvp, w->cv0, w->cdrv, w->cload, w->cx, w->cx0, w->cF, w->cG, w->cJ, w->cFt, w->ctgt, w->cw};
        size_t k;
        for (k = 0; k < sizeof c / sizeof c[0]; ++k) pn_free(&w->desc.allocator, c[k]);
    }
    for (a = 0; a < w->n_drives; ++a) pn_free(&w->desc.allocator, w->drives[a].pts);
    pn_free(&w->desc.allocator, w->X), pn_free(&w->desc.allocator, w->mass), pn_free(&w->desc.allocator, w->vol);
    pn_free(&w->desc.allocator, w->wf), pn_free(&w->desc.allocator, w->perm), pn_free(&w->desc.allocator, w->px);
    pn_free(&w->desc.allocator, w);
}

PN__DEF pn_result pn_rom_create(const pn_rom_desc *desc, pn_rom_world **out, char *why, size_t cap) {
    pn_rom_desc d;
    pn_rom_world *w;
    pn_material_desc md;
    const pn_rom_model *m;
    pn_result r;
    int fail = 0, i, dim;
    size_t p, n;
    const char *bad;
    if (!out || !desc) {
        pn__msg(why, cap, "pn_rom_create: desc or out is NULL");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    *out = NULL;
    d = *desc;
    m = d.model;
    if ((r = pn_rom_model_check(m, why, cap)) != PN_OK) return r;
    dim = m->dim;
    if ((d.allocator.alloc == NULL) != (d.allocator.free == NULL)) {
        pn__msg(why, cap, "pn_rom_desc.allocator: set both alloc and free, or neither");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    /* every numeric field: zero means the default; NaN, infinity, negative or out of range
       is refused, naming the field (as pn_mpm_create) */
    bad = !pn__rom_finite(d.dx_m) || d.dx_m < 0 ? "dx_m must be finite and >= 0 (0: the model's)"
          : !pn__rom_finite(d.youngs_pa) || d.youngs_pa < 0 ? "youngs_pa must be finite and >= 0 (0: the model's)"
          : !pn__rom_finite(d.poisson) ? "poisson must be finite (0: the model's)"
          : !pn__rom_finite(d.density_kg_m3) || d.density_kg_m3 < 0 ? "density_kg_m3 must be finite and >= 0 (0: the model's)"
          : !pn__rom_finite(d.point_volume_m3) || d.point_volume_m3 < 0 ? "point_volume_m3 must be finite and >= 0"
          : !pn__rom_all_finite(3, d.gravity) ? "gravity is not finite"
          : d.boundary_samples < 0 ? "boundary_samples must be >= 0 (0: 5)"
          : d.quad_per_axis < 0 || d.quad_per_axis > 8 ? "quad_per_axis must be 0 .. 8 (0: 2)"
          : d.gn_max < 0 || d.gn_max > 1000 ? "gn_max must be 0 .. 1000 (0: 10)"
          : d.parallel_min < 0 ? "parallel_min must be >= 0 (0: 256)"
          : !pn__rom_finite(d.cubature_m) || d.cubature_m < 0 ? "cubature_m must be finite and >= 0 (0: 2 dx_m)"
          : d.newton_max < 0 || d.newton_max > 1000 ? "newton_max must be 0 .. 1000 (0: 20)"
          : !pn__rom_finite(d.newton_tol) || d.newton_tol < 0 ? "newton_tol must be finite and >= 0 (0: 1e-3)"
          : !pn__rom_finite(d.drive_weight) || d.drive_weight < 0 ? "drive_weight must be finite and >= 0 (0: 100)"
          : !d.points && d.n_points ? "n_points is set but points is NULL"
          : NULL;
    if (bad) {
        pn__msg(why, cap, "pn_rom_desc.%s", bad);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    if (d.refine < 0 || d.refine > PN_ROM_MAX_REFINE) {
        pn__msg(why, cap, "pn_rom_desc.refine = %d must be 0 .. PN_ROM_MAX_REFINE = %d (0: 1)", d.refine, PN_ROM_MAX_REFINE);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    if (d.refine == 0) d.refine = 1;
    if (d.dx_m == 0) d.dx_m = m->dx_m;
    if (d.youngs_pa == 0) d.youngs_pa = m->youngs_pa;
    if (d.poisson == 0) d.poisson = m->poisson;
    if (d.density_kg_m3 == 0) d.density_kg_m3 = m->density_kg_m3;
    if (d.samples == 0) d.samples = 50;
    if (d.boundary_samples == 0) d.boundary_samples = 5;
    if (d.quad_per_axis == 0) d.quad_per_axis = 2;
    if (d.seed == 0) d.seed = 1;
    if (d.gn_max == 0) d.gn_max = 10;
    if (d.parallel_min == 0) d.parallel_min = 256;
    if (d.cubature_m == 0) d.cubature_m = 2 * d.dx_m;
    if (d.newton_max == 0) d.newton_max = 20;
    if (d.newton_tol == 0) d.newton_tol = 1e-3;
    if (d.drive_weight == 0) d.drive_weight = 100;
    bad = !(d.dx_m > 0) ? "dx_m (and the model's dx_m) must be > 0"
          : !(d.youngs_pa > 0) ? "youngs_pa (and the model's youngs_pa) must be > 0"
          : !(d.density_kg_m3 > 0) ? "density_kg_m3 (and the model's density_kg_m3) must be > 0"
          : d.quadrature != PN_ROM_EULERIAN && d.quadrature != PN_ROM_LAGRANGIAN ? "quadrature is not a pn_rom_quadrature"
          : d.projection != PN_ROM_LINEAR && d.projection != PN_ROM_NONLINEAR ? "projection is not a pn_rom_projection"
          : d.transfer != PN_ROM_APIC && d.transfer != PN_ROM_PIC ? "transfer is not a pn_rom_transfer"
          : (int)d.integrator < PN_ROM_EXPLICIT || (int)d.integrator > PN_ROM_MIDPOINT ? "integrator is not a pn_rom_integrator"
          : d.points && (d.n_points == 0 || d.n_points > PN_ROM_MAX_POINTS) ? "points: n_points must be 1 .. PN_ROM_MAX_POINTS"
          : d.points && !pn__rom_all_finite(d.n_points * (size_t)dim, d.points) ? "points are not all finite"
          : !d.points && m->cells[0] <= 0 ? "points is NULL and the model has no reference domain to fill"
          : NULL;
    if (bad) {
        pn__msg(why, cap, "pn_rom_desc.%s", bad);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    n = d.points ? d.n_points : pn_rom_lattice(m, d.refine, NULL, 0);
    if (n > PN_ROM_MAX_POINTS) { /* counted in closed form: nothing allocated yet */
        pn__msg(why, cap, "pn_rom_desc.refine = %d: the model's lattice has %.4g points, more than PN_ROM_MAX_POINTS = %lu "
                    "(draw finer lattices with pn_rom_lattice and pn_rom_map instead)", d.refine, (double)n,
                    (unsigned long)PN_ROM_MAX_POINTS);
        return PN_ERROR_CAPACITY;
    }
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED;
    md.plastic = PN_PLASTIC_NONE;
    md.youngs_modulus_pa = (pn_real)d.youngs_pa;
    md.poisson_ratio = (pn_real)d.poisson;
    w = (pn_rom_world *)pn_alloc(&d.allocator, sizeof *w);
    if (!w) {
        pn__msg(why, cap, "pn_rom_create: out of memory");
        return PN_ERROR_OUT_OF_MEMORY;
    }
    memset(w, 0, sizeof *w);
    w->desc = d;
    w->model = *m;
    w->dim = dim, w->latent = m->latent;
    if ((r = pn__material_init_why(&w->material, &md, &bad)) != PN_OK) {
        pn__msg(why, cap, "pn_rom_desc: youngs_pa / poisson: %s", bad ? bad : "invalid");
        pn_rom_destroy(w);
        return PN_ERROR_INVALID_PARAMETER;
    }
    w->n = n;
    w->X = (double *)pn__rom_alloc(w, n * (size_t)dim, sizeof(double), &fail);
    w->mass = (double *)pn__rom_alloc(w, n, sizeof(double), &fail);
    w->vol = (double *)pn__rom_alloc(w, n, sizeof(double), &fail);
    w->perm = (size_t *)pn__rom_alloc(w, n, sizeof(size_t), &fail);
    if (m->activation == PN_ROM_ELU) {
        size_t tot = 0;
        int l;
        for (l = 0; l < m->n_layers; ++l) {
            w->wf_off[l] = tot;
            tot += (size_t)m->width[l + 1] * (size_t)(m->width[l] + 1);
        }
        w->wf_off[m->n_layers] = tot;
        w->wf = (float *)pn__rom_alloc(w, tot, sizeof(float), &fail);
        if (!fail)
            for (l = 0; l < m->n_layers; ++l) {
                size_t nw = (size_t)m->width[l + 1] * (size_t)m->width[l], k;
                for (k = 0; k < nw; ++k) w->wf[w->wf_off[l] + k] = (float)m->weight[l][k];
                for (k = 0; k < (size_t)m->width[l + 1]; ++k) w->wf[w->wf_off[l] + nw + k] = (float)m->bias[l][k];
            }
    }
    if (fail) {
        pn__msg(why, cap, "pn_rom_create: out of memory for %lu points", (unsigned long)n);
        pn_rom_destroy(w);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    if (d.points) memcpy(w->X, d.points, sizeof(double) * n * (size_t)dim);
    else pn_rom_lattice(m, d.refine, w->X, n);
    {
        double h = m->cells[0] > 0 ? m->cell_m / d.refine : 0, v = 1;
        for (i = 0; i < dim; ++i) v *= h;
        if (d.points && d.point_volume_m3 > 0) v = d.point_volume_m3;
        if (!(v > 0)) {
            pn__msg(why, cap, "pn_rom_desc.point_volume_m3 is needed: the model has no cell size");
            pn_rom_destroy(w);
            return PN_ERROR_INVALID_ARGUMENT;
        }
        for (p = 0; p < n; ++p) w->vol[p] = v, w->mass[p] = v * d.density_kg_m3, w->perm[p] = p;
    }
    { /* the body's size: the diagonal of its reference points' box */
        double lo[3], hi[3], s2 = 0;
        for (i = 0; i < dim; ++i) lo[i] = hi[i] = w->X[i];
        for (p = 0; p < n; ++p)
            for (i = 0; i < dim; ++i) lo[i] = fmin(lo[i], w->X[p * (size_t)dim + (size_t)i]), hi[i] = fmax(hi[i], w->X[p * (size_t)dim + (size_t)i]);
        for (i = 0; i < dim; ++i) s2 += (hi[i] - lo[i]) * (hi[i] - lo[i]);
        w->size_m = fmax(sqrt(s2), d.dx_m);
    }
    for (i = 0; i < 3; ++i) {
        w->xs[i] = 2 / (m->in_hi[i] - m->in_lo[i]);
        w->xo[i] = -2 * m->in_lo[i] / (m->in_hi[i] - m->in_lo[i]) - 1;
    }
    for (i = 0; i < w->latent; ++i) w->xhat[i] = w->xhat_prev[i] = m->latent_rest ? m->latent_rest[i] : 0;
    w->rng = d.seed;
    w->cub_dirty = 1;
    *out = w;
    return PN_OK;
}

static int pn__rom_in_region(const pn_rom_region *r, int d, const double *X) {
    int i, box = 0;
    double d2 = 0;
    for (i = 0; i < d; ++i) box |= r->lo[i] != 0 || r->hi[i] != 0;
    for (i = 0; i < d; ++i) {
        if (box && (X[i] < r->lo[i] || X[i] > r->hi[i])) return 0;
        d2 += (X[i] - r->center[i]) * (X[i] - r->center[i]);
    }
    return r->radius > 0 ? d2 <= r->radius * r->radius : 1;
}

static const char *pn__rom_region_bad(const pn_rom_region *r) {
    if (!r) return "region is NULL";
    if (!pn__rom_all_finite(3, r->lo) || !pn__rom_all_finite(3, r->hi) || !pn__rom_all_finite(3, r->center) ||
        !pn__rom_finite(r->radius) || r->radius < 0)
        return "region has a non-finite field or a negative radius";
    return NULL;
}

PN__DEF pn_result pn_rom_drive(pn_rom_world *w, const pn_rom_region *r, const double *velocity, const double *center,
                               const double *omega, int *index) {
    pn__rom_drive D;
    const char *bad = pn__rom_region_bad(r);
    int d = w->dim, a, i, spin = 0, fail = 0;
    size_t p;
    w->error[0] = 0;
    if (bad) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_drive: %s", bad);
    if ((velocity && !pn__rom_all_finite((size_t)d, velocity)) || (center && !pn__rom_all_finite((size_t)d, center)) ||
        (omega && !pn__rom_all_finite(3, omega)))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_drive: velocity, center or angular velocity is not finite");
    memset(&D, 0, sizeof D);
    D.r = *r;
    for (i = 0; i < 3; ++i) {
        D.vel[i] = velocity && i < d ? velocity[i] : 0;
        D.center[i] = center && i < d ? center[i] : 0;
        D.omega[i] = omega && (d == 3 || i == 2) ? omega[i] : 0;
        spin |= D.omega[i] != 0;
    }
    if (spin && !center) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_drive: a rotation needs center_m");
    for (p = 0; p < w->n; ++p) D.n_pts += (size_t)pn__rom_in_region(r, d, w->X + p * (size_t)d);
    if (!D.n_pts) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_drive: the region holds none of the world's points");
    for (a = 0; a < w->n_drives && w->drives[a].on; ++a) {}
    if (a == PN_ROM_MAX_DRIVES)
        return PN__FAIL(w, PN_ERROR_CAPACITY, "pn_rom_drive: all PN_ROM_MAX_DRIVES = %d are in use", PN_ROM_MAX_DRIVES);
    D.pts = (size_t *)pn__rom_alloc(w, D.n_pts, sizeof(size_t), &fail);
    if (fail) return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "pn_rom_drive: out of memory");
    for (D.n_pts = 0, p = 0; p < w->n; ++p)
        if (pn__rom_in_region(r, d, w->X + p * (size_t)d)) D.pts[D.n_pts++] = p;
    D.t0 = w->time_s;
    memcpy(D.xhat0, w->xhat, sizeof D.xhat0);
    D.on = 1;
    w->cub_dirty = 1;
    pn_free(&w->desc.allocator, w->drives[a].pts);
    w->drives[a] = D;
    if (a == w->n_drives) w->n_drives++;
    if (index) *index = a;
    return PN_OK;
}

PN__DEF pn_result pn_rom_release_drive(pn_rom_world *w, int index) {
    w->error[0] = 0;
    if (index < 0 || index >= w->n_drives || index >= PN_ROM_MAX_DRIVES)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_release_drive: drive %d does not exist", index);
    w->drives[index].on = 0;
    w->cub_dirty = 1;
    return PN_OK;
}

PN__DEF pn_result pn_rom_add_load(pn_rom_world *w, const pn_rom_region *r, const double *force, double duration_s, int *index) {
    pn__rom_load L;
    const char *bad = pn__rom_region_bad(r);
    double mass = 0;
    int d = w->dim, a, i;
    size_t p;
    w->error[0] = 0;
    if (bad) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_add_load: %s", bad);
    if (!force || !pn__rom_all_finite((size_t)d, force))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_add_load: force_N is NULL or not finite");
    if (!pn__rom_finite(duration_s) || duration_s < 0)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_add_load: duration_s = %g must be finite and >= 0", duration_s);
    for (p = 0; p < w->n; ++p)
        if (pn__rom_in_region(r, d, w->X + p * (size_t)d)) mass += w->mass[p];
    if (!(mass > 0)) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_add_load: the region holds none of the world's points");
    for (a = 0; a < w->n_loads && w->loads[a].on; ++a) {}
    if (a == PN_ROM_MAX_LOADS)
        return PN__FAIL(w, PN_ERROR_CAPACITY, "pn_rom_add_load: all PN_ROM_MAX_LOADS = %d are in use", PN_ROM_MAX_LOADS);
    memset(&L, 0, sizeof L);
    L.r = *r;
    for (i = 0; i < d; ++i) L.acc[i] = force[i] / mass;
    L.t_end = duration_s > 0 ? w->time_s + duration_s : HUGE_VAL;
    L.on = 1;
    w->cub_dirty = 1;
    w->loads[a] = L;
    if (a == w->n_loads) w->n_loads++;
    if (index) *index = a;
    return PN_OK;
}

PN__DEF pn_result pn_rom_remove_load(pn_rom_world *w, int index) {
    w->error[0] = 0;
    if (index < 0 || index >= w->n_loads || index >= PN_ROM_MAX_LOADS)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_remove_load: load %d does not exist", index);
    w->loads[index].on = 0;
    w->cub_dirty = 1;
    return PN_OK;
}

PN__DEF pn_result pn_rom_set_latent(pn_rom_world *w, const double *xhat, const double *vhat) {
    int K = w->latent, i;
    w->error[0] = 0;
    if (!xhat || !pn__rom_all_finite((size_t)K, xhat) || (vhat && !pn__rom_all_finite((size_t)K, vhat)))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_set_latent: xhat is NULL, or xhat or vhat not finite");
    for (i = 0; i < K; ++i) w->xhat[i] = w->xhat_prev[i] = xhat[i], w->vhat[i] = vhat ? vhat[i] : 0;
    w->cvel_ok = 0;
    return PN_OK;
}

/* ======================================================================================
   >>step: scratch, hashes, sampling, the quadrature, the full-space update, the projections
   ====================================================================================== */

/* grow an array to hold n entries (doubling); 0 on failure, nothing lost */
static int pn__rom_grow(pn_rom_world *w, void **a, size_t have, size_t n, size_t size) {
    void *b;
    if (n <= have && *a) return 1;
    if (size && n > ((size_t)-1 - 1) / size) return 0;
    b = pn_alloc(&w->desc.allocator, n * size + 1);
    if (!b) return 0;
    memset(b, 0, n * size + 1);
    if (*a && have) memcpy(b, *a, have * size);
    pn_free(&w->desc.allocator, *a);
    *a = b;
    return 1;
}

/* room for ns samples and nq quadrature points (the per-point arrays of both) */
static int pn__rom_reserve(pn_rom_world *w, size_t ns, size_t nq) {
    int d = w->dim, K = w->latent, ok = 1;
    size_t dd = (size_t)(d * d), dK = (size_t)(d * K), c;
    if (ns > w->cap_s) {
        c = ns > 2 * w->cap_s ? ns : 2 * w->cap_s;
        ok &= pn__rom_grow(w, (void **)&w->sidx, w->cap_s, c, sizeof(size_t));
        ok &= pn__rom_grow(w, (void **)&w->sX, w->cap_s * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->sx, w->cap_s * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->sF, w->cap_s * dd, c * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->sG, w->cap_s * dK, c * dK, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->sv, w->cap_s * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->sxt, w->cap_s * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->sdrv, w->cap_s, c, sizeof(int));
        if (!ok) return 0;
        w->cap_s = c;
    }
    if (nq > w->cap_q) {
        c = nq > 2 * w->cap_q ? nq : 2 * w->cap_q;
        ok &= pn__rom_grow(w, (void **)&w->qx, w->cap_q * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qX, w->cap_q * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qF, w->cap_q * dd, c * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qG, w->cap_q * dK, c * dK, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qv, w->cap_q * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qC, w->cap_q * dd, c * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qT, w->cap_q * dd, c * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qm, w->cap_q, c, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qV0, w->cap_q, c, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->qflag, w->cap_q, c, sizeof(int));
        ok &= pn__rom_grow(w, (void **)&w->qsrc, w->cap_q, c, sizeof(long));
        ok &= pn__rom_grow(w, (void **)&w->qkey, w->cap_q, c, sizeof(unsigned long long));
        ok &= pn__rom_grow(w, (void **)&w->qok, w->cap_q, c, 1);
        ok &= pn__rom_grow(w, (void **)&w->tX, w->cap_q * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->tx, w->cap_q * (size_t)d, c * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->tF, w->cap_q * dd, c * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->tG, w->cap_q * dK, c * dK, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->tI, w->cap_q, c, sizeof(long));
        if (!ok) return 0;
        w->cap_q = c;
    }
    return 1;
}

/* a grid or lattice index triple packed in 63 bits (each coordinate within +-2^20) */
static unsigned long long pn__rom_key(const long long *i) {
    return ((unsigned long long)(i[0] + (1 << 20)) << 42) | ((unsigned long long)(i[1] + (1 << 20)) << 21) |
           (unsigned long long)(i[2] + (1 << 20));
}

static void pn__rom_hash_clear(pn__rom_hash *h) {
    size_t k;
    for (k = 0; k < h->n_used; ++k) h->key[h->used[k]] = 0;
    h->n_used = 0;
}

/* the stored value of key, or NULL */
static long *pn__rom_hash_ref(const pn__rom_hash *h, unsigned long long key) {
    size_t s;
    if (!h->cap) return NULL;
    s = (size_t)((key * 0x9E3779B97F4A7C15ULL) >> 20) & (h->cap - 1);
    while (h->key[s]) {
        if (h->key[s] == key + 1) return h->val + s;
        s = (s + 1) & (h->cap - 1);
    }
    return NULL;
}

/* the value of key, or -1 */
static long pn__rom_hash_get(const pn__rom_hash *h, unsigned long long key) {
    const long *v = pn__rom_hash_ref(h, key);
    return v ? *v : -1;
}

/* insert key with value val unless present; returns the stored value, or -2 out of memory */
static long pn__rom_hash_put(pn_rom_world *w, pn__rom_hash *h, unsigned long long key, long val) {
    size_t s;
    if (2 * (h->n_used + 1) > h->cap) { /* grow: rehash every used slot */
        pn__rom_hash g;
        size_t k, cap = h->cap ? 2 * h->cap : 1024;
        int fail = 0;
        memset(&g, 0, sizeof g);
        g.key = (unsigned long long *)pn__rom_alloc(w, cap, sizeof(unsigned long long), &fail);
        g.val = (long *)pn__rom_alloc(w, cap, sizeof(long), &fail);
        g.used = (size_t *)pn__rom_alloc(w, cap, sizeof(size_t), &fail);
        if (fail) {
            pn__rom_hash_free(w, &g);
            return -2;
        }
        g.cap = cap;
        for (k = 0; k < h->n_used; ++k) {
            size_t o = h->used[k], t = (size_t)(((h->key[o] - 1) * 0x9E3779B97F4A7C15ULL) >> 20) & (cap - 1);
            while (g.key[t]) t = (t + 1) & (cap - 1);
            g.key[t] = h->key[o], g.val[t] = h->val[o], g.used[g.n_used++] = t;
        }
        pn__rom_hash_free(w, h);
        *h = g;
    }
    s = (size_t)((key * 0x9E3779B97F4A7C15ULL) >> 20) & (h->cap - 1);
    while (h->key[s]) {
        if (h->key[s] == key + 1) return h->val[s];
        s = (s + 1) & (h->cap - 1);
    }
    h->key[s] = key + 1, h->val[s] = val, h->used[h->n_used++] = s;
    return val;
}

static double pn__rom_rand(unsigned long long *st) { /* splitmix64, [0, 1) */
    unsigned long long z = pn__mix64(*st += 0x9E3779B97F4A7C15ULL);
    return (double)(z >> 11) / 9007199254740992.0;
}

/* quadratic B-spline weights of the 3 nodes from base (f = x/dx - base in [0.5, 1.5)) */
static void pn__rom_spline(double f, double *wt) {
    PN__BSPLINE2(wt[0], wt[1], wt[2], f, double);
}

/* the kit's dense Cholesky in double: the normal equations of the reduced models */
PN__CHOLESKY_DEF(pn__rom_cholesky, pn__rom_cholesky_solve, double, sqrt, pn__rom_finite)

/* solve the symmetric positive definite K x K system A x = b in place (Cholesky); 0 if A is
   not positive definite */
static int pn__rom_spd_solve(int K, double *A, double *b) {
    if (pn__rom_cholesky(A, (size_t)K, 0, 0, 0) < (size_t)K) return 0;
    pn__rom_cholesky_solve(A, (size_t)K, b, b);
    return 1;
}

/* the least-squares solution of sum_p |G_p y - r_p|^2 (n points, G d x K each) into y: the
   normal equations, in point order, with a relative ridge of 1e-15 against exact
   rank deficiency; 0 if singular */
static int pn__rom_lsq(int d, int K, size_t n, const double *G, const double *r, double *y) {
    double A[PN_ROM_MAX_LATENT * PN_ROM_MAX_LATENT], tr = 0;
    size_t p;
    int i, j, k;
    for (i = 0; i < K * K; ++i) A[i] = 0;
    for (i = 0; i < K; ++i) y[i] = 0;
    for (p = 0; p < n; ++p) {
        const double *Gp = G + p * (size_t)(d * K), *rp = r + p * (size_t)d;
        for (k = 0; k < d; ++k)
            for (i = 0; i < K; ++i) {
                y[i] += Gp[k * K + i] * rp[k];
                for (j = 0; j <= i; ++j) A[i * K + j] += Gp[k * K + i] * Gp[k * K + j];
            }
    }
    for (i = 0; i < K; ++i) {
        for (j = 0; j < i; ++j) A[j * K + i] = A[i * K + j];
        tr += A[i * K + i];
    }
    for (i = 0; i < K; ++i) A[i * K + i] += 1e-15 * tr / K + 1e-300;
    return pn__rom_spd_solve(K, A, y);
}

static double pn__rom_det(int d, const double *F) {
    if (d == 2) return F[0] * F[3] - F[1] * F[2];
    return F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) + F[2] * (F[3] * F[7] - F[4] * F[6]);
}

/* y = F^-1 r (0 if F is singular) */
static int pn__rom_solve_F(int d, const double *F, const double *r, double *y) {
    double det = pn__rom_det(d, F);
    if (!(det != 0) || !pn__rom_finite(det)) return 0;
    if (d == 2) {
        y[0] = (F[3] * r[0] - F[1] * r[1]) / det, y[1] = (-F[2] * r[0] + F[0] * r[1]) / det;
    } else {
        double I[9];
        int i;
        I[0] = F[4] * F[8] - F[5] * F[7], I[1] = F[2] * F[7] - F[1] * F[8], I[2] = F[1] * F[5] - F[2] * F[4];
        I[3] = F[5] * F[6] - F[3] * F[8], I[4] = F[0] * F[8] - F[2] * F[6], I[5] = F[2] * F[3] - F[0] * F[5];
        I[6] = F[3] * F[7] - F[4] * F[6], I[7] = F[1] * F[6] - F[0] * F[7], I[8] = F[0] * F[4] - F[1] * F[3];
        for (i = 0; i < 3; ++i) y[i] = (I[3 * i] * r[0] + I[3 * i + 1] * r[1] + I[3 * i + 2] * r[2]) / det;
    }
    return 1;
}

/* the rigid motion of drive D: its centre at time t, and the velocity there at x */
/* a drive's rigid motion: the kit's (pn__rom_drive_at: its centre at t and where a point
   that was at x0 at t0 is; pn__rom_drive_vel: the velocity at x) */
PN__RIGID_DEF(pn__rom_drive_at, pn__rom_drive_vel, pn__rom_drive, double, sqrt, cos, sin)
static void pn__rom_drive_center(const pn__rom_drive *D, double t, double *c) { pn__rom_drive_at(D, 3, t, NULL, c, NULL); }
static void pn__rom_drive_pos(const pn__rom_drive *D, int d, double t, const double *x0, double *x) {
    double c[3];
    pn__rom_drive_at(D, d, t, x0, c, x);
}

/* the first live drive whose region holds X, or -1 */
static int pn__rom_drive_of(const pn_rom_world *w, const double *X) {
    int a;
    for (a = 0; a < w->n_drives; ++a)
        if (w->drives[a].on && pn__rom_in_region(&w->drives[a].r, w->dim, X)) return a;
    return -1;
}

/* draw the samples: at least boundary_samples of each live drive, then random points of the
   rest, without replacement (a partial Fisher-Yates shuffle of a persistent permutation) */
static size_t pn__rom_sample(pn_rom_world *w) {
    size_t n = w->n, want, ns = 0, i, nb = 0;
    int a, d = w->dim;
    if (w->desc.samples < 0 || (size_t)w->desc.samples >= n) {
        for (i = 0; i < n; ++i) w->sidx[i] = i;
        ns = n;
    } else {
        want = (size_t)w->desc.samples;
        for (a = 0; a < w->n_drives; ++a) { /* boundary points first */
            pn__rom_drive *D = &w->drives[a];
            size_t k, m = (size_t)w->desc.boundary_samples < D->n_pts ? (size_t)w->desc.boundary_samples : D->n_pts;
            if (!D->on) continue;
            for (k = 0; k < m; ++k) {
                size_t j = k + (size_t)(pn__rom_rand(&w->rng) * (double)(D->n_pts - k)), t = D->pts[k];
                D->pts[k] = D->pts[j], D->pts[j] = t;
                w->sidx[ns++] = D->pts[k];
            }
        }
        nb = ns;
        for (i = 0; ns < nb + want && i < n; ++i) {
            size_t j = i + (size_t)(pn__rom_rand(&w->rng) * (double)(n - i)), t = w->perm[i], k;
            int dup = 0;
            w->perm[i] = w->perm[j], w->perm[j] = t;
            for (k = 0; k < nb; ++k) dup |= w->sidx[k] == w->perm[i];
            if (!dup) w->sidx[ns++] = w->perm[i];
        }
    }
    for (i = 0; i < ns; ++i) {
        memcpy(w->sX + i * (size_t)d, w->X + w->sidx[i] * (size_t)d, sizeof(double) * (size_t)d);
        w->sdrv[i] = pn__rom_drive_of(w, w->sX + i * (size_t)d);
    }
    return ns;
}

/* the stencil base node of a point at x (in cells: base = floor(x/dx - 1/2)) and fx = x/dx - base */
static void pn__rom_base(int d, double inv_dx, const double *x, long long *base, double *fx) {
    int i;
    for (i = 0; i < d; ++i) {
        double u = x[i] * inv_dx;
        base[i] = (long long)floor(u - 0.5);
        fx[i] = u - (double)base[i];
    }
    for (i = d; i < 3; ++i) base[i] = 0, fx[i] = 1;
}

/* Eulerian quadrature (Algorithm 4): the lattice of spacing dx/l (cell-centred) within reach
   of the samples' stencil nodes, each point mapped back to X by Newton on g(X, xhat) = x from
   its sample's affine guess X_s + F_s^-1 (x - x_s); points whose X is not material, or that
   Newton does not bring within 1e-5 dx (float; 1e-10 dx on the double path), are left out. */
static pn_result pn__rom_quad_eulerian(pn_rom_world *w, size_t ns, size_t *nq_out, size_t *failed) {
    int d = w->dim, K = w->latent, l = w->desc.quad_per_axis, it, i;
    double dx = w->desc.dx_m, h = dx / l, Vq = 1;
    double tol = (w->desc.reference || w->model.activation == PN_ROM_AFFINE ? 1e-10 : 1e-5) * dx; /* float: its rounding */
    size_t s, nq = 0, na, j, q, nf = 0, dd = (size_t)(d * d), dK = (size_t)(d * K);
    pn__rom_hash_clear(&w->lat);
    for (i = 0; i < d; ++i) Vq *= h;
    for (s = 0; s < ns; ++s) {
        long long b[3], a[3], lo[3], hi[3];
        double fx[3];
        pn__rom_base(d, 1 / dx, w->sx + s * (size_t)d, b, fx);
        for (i = 0; i < 3; ++i) { /* (a + 1/2)/l - b in (-1.5, 3.5): within reach of nodes b .. b+2 */
            lo[i] = i < d ? (long long)l * b[i] - 2 * l : 0;
            hi[i] = i < d ? (long long)l * b[i] + 4 * l : 0;
        }
        for (a[0] = lo[0]; a[0] <= hi[0]; ++a[0])
            for (a[1] = lo[1]; a[1] <= hi[1]; ++a[1])
                for (a[2] = lo[2]; a[2] <= hi[2]; ++a[2]) {
                    int in = 1;
                    long v;
                    for (i = 0; i < d; ++i) {
                        double u = ((double)a[i] + 0.5) / l - (double)b[i];
                        in &= u > -1.5 && u < 3.5;
                    }
                    if (!in) continue;
                    if (nq == w->cap_q && !pn__rom_reserve(w, w->cap_s, nq + 1)) return PN_ERROR_OUT_OF_MEMORY;
                    v = pn__rom_hash_put(w, &w->lat, pn__rom_key(a), (long)nq);
                    if (v == -2) return PN_ERROR_OUT_OF_MEMORY;
                    if (v != (long)nq) continue; /* another sample's */
                    for (i = 0; i < d; ++i) w->qx[nq * (size_t)d + (size_t)i] = ((double)a[i] + 0.5) * h;
                    w->qsrc[nq] = (long)s;
                    w->qkey[nq] = pn__rom_key(a);
                    nq++;
                }
    }
    for (q = 0; q < nq; ++q) { /* the guess: the point's X of an earlier step, else the sample's tangent map */
        const double *xs = w->sx + (size_t)w->qsrc[q] * (size_t)d, *Xs = w->sX + (size_t)w->qsrc[q] * (size_t)d;
        double r[3], y[3] = {0, 0, 0};
        long ci = pn__rom_hash_get(&w->xc, w->qkey[q]);
        if (ci >= 0) {
            memcpy(w->tX + q * (size_t)d, w->xcX + (size_t)ci * (size_t)d, sizeof(double) * (size_t)d);
        } else {
            for (i = 0; i < d; ++i) r[i] = w->qx[q * (size_t)d + (size_t)i] - xs[i];
            pn__rom_solve_F(d, w->sF + (size_t)w->qsrc[q] * dd, r, y);
            for (i = 0; i < d; ++i) w->tX[q * (size_t)d + (size_t)i] = Xs[i] + y[i];
        }
        w->tI[q] = (long)q;
        w->qok[q] = 0;
    }
    na = nq;
    for (it = 0; it <= 10 && na; ++it) { /* Newton on the points not yet converged, compacted */
        size_t keep = 0;
        pn__rom_map(w, w->xhat, na, w->tX, w->tx, w->tF, w->tG);
        for (j = 0; j < na; ++j) {
            double r[3], y[3], rr = 0;
            int near;
            q = (size_t)w->tI[j];
            for (i = 0; i < d; ++i) {
                r[i] = w->tx[j * (size_t)d + (size_t)i] - w->qx[q * (size_t)d + (size_t)i];
                rr += r[i] * r[i];
            }
            /* within 1e-3 dx, one more Newton step lands within ~1e-6 dx (quadratic
               convergence): take it and keep F and G of this evaluation */
            near = rr <= 1e-6 * dx * dx && pn__rom_solve_F(d, w->tF + j * dd, r, y);
            if (rr <= tol * tol || near) { /* converged: X, F, G */
                for (i = 0; i < d; ++i) w->qX[q * (size_t)d + (size_t)i] = w->tX[j * (size_t)d + (size_t)i] - (rr > tol * tol ? y[i] : 0);
                memcpy(w->qF + q * dd, w->tF + j * dd, sizeof(double) * dd);
                memcpy(w->qG + q * dK, w->tG + j * dK, sizeof(double) * dK);
                w->qok[q] = pn_rom_inside(&w->model, w->qX + q * (size_t)d) && pn__rom_det(d, w->qF + q * dd) > 0;
                continue;
            }
            if (!pn__rom_finite(rr) || it == 10 || !pn__rom_solve_F(d, w->tF + j * dd, r, y)) {
                nf++;
                continue;
            }
            w->tI[keep] = (long)q;
            for (i = 0; i < d; ++i) w->tX[keep * (size_t)d + (size_t)i] = w->tX[j * (size_t)d + (size_t)i] - y[i];
            keep++;
        }
        na = keep;
    }
    if (w->n_xc > 16 * w->cap_q) { /* a body that travels: forget the lattice points left behind */
        pn__rom_hash_clear(&w->xc);
        w->n_xc = 0;
    }
    for (q = 0; q < nq; ++q) { /* remember each X found for the next steps' guesses */
        long ci;
        if (!w->qok[q] && pn__rom_hash_get(&w->xc, w->qkey[q]) < 0) continue;
        if (w->n_xc == w->cap_xc) {
            size_t c = w->cap_xc ? 2 * w->cap_xc : 4096;
            if (!pn__rom_grow(w, (void **)&w->xcX, w->cap_xc * (size_t)d, c * (size_t)d, sizeof(double))) return PN_ERROR_OUT_OF_MEMORY;
            w->cap_xc = c;
        }
        ci = pn__rom_hash_put(w, &w->xc, w->qkey[q], (long)w->n_xc);
        if (ci == -2) return PN_ERROR_OUT_OF_MEMORY;
        if (ci == (long)w->n_xc) w->n_xc++;
        if (w->qok[q]) memcpy(w->xcX + (size_t)ci * (size_t)d, w->qX + q * (size_t)d, sizeof(double) * (size_t)d);
    }
    for (q = 0; q < nq; ++q) {
        double J;
        if (!w->qok[q]) continue;
        J = pn__rom_det(d, w->qF + q * dd);
        w->qV0[q] = Vq / J;
        w->qm[q] = w->desc.density_kg_m3 * Vq / J;
    }
    *nq_out = nq;
    *failed = nf;
    return PN_OK;
}

/* Lagrangian quadrature (Algorithm 3): the world's points whose stencil reaches a node of the
   samples' (their positions from g at every point: the cost the paper measures) */
static pn_result pn__rom_quad_lagrangian(pn_rom_world *w, size_t *nq_out) {
    int d = w->dim, i;
    size_t p, nq = 0, dd = (size_t)(d * d);
    double inv = 1 / w->desc.dx_m;
    if (!w->px) {
        int fail = 0;
        w->px = (double *)pn__rom_alloc(w, w->n * (size_t)d, sizeof(double), &fail);
        if (fail) return PN_ERROR_OUT_OF_MEMORY;
    }
    pn__rom_map(w, w->xhat, w->n, w->X, w->px, NULL, NULL);
    for (p = 0; p < w->n; ++p) {
        long long b[3], o[3], k[3];
        double fx[3];
        int hit = 0;
        pn__rom_base(d, inv, w->px + p * (size_t)d, b, fx);
        for (o[0] = 0; o[0] < 3 && !hit; ++o[0])
            for (o[1] = 0; o[1] < 3 && !hit; ++o[1])
                for (o[2] = 0; o[2] < (d == 3 ? 3 : 1) && !hit; ++o[2]) {
                    for (i = 0; i < 3; ++i) k[i] = b[i] + o[i];
                    hit = pn__rom_hash_get(&w->nodes, pn__rom_key(k)) >= 0;
                }
        if (!hit) continue;
        if (nq == w->cap_q && !pn__rom_reserve(w, w->cap_s, nq + 1)) return PN_ERROR_OUT_OF_MEMORY;
        memcpy(w->qX + nq * (size_t)d, w->X + p * (size_t)d, sizeof(double) * (size_t)d);
        memcpy(w->qx + nq * (size_t)d, w->px + p * (size_t)d, sizeof(double) * (size_t)d);
        w->qm[nq] = w->mass[p], w->qV0[nq] = w->vol[p], w->qok[nq] = 1;
        nq++;
    }
    pn__rom_map(w, w->xhat, nq, w->qX, NULL, w->qF, w->qG);
    for (p = 0; p < nq; ++p) w->qok[p] = pn__rom_det(d, w->qF + p * dd) > 0;
    *nq_out = nq;
    return PN_OK;
}

/* the samples' grid nodes (3^dim each) into the node hash, numbered in order */
static pn_result pn__rom_nodes(pn_rom_world *w, size_t ns, size_t *nn_out) {
    int d = w->dim, i;
    size_t s, nn = 0;
    double inv = 1 / w->desc.dx_m;
    pn__rom_hash_clear(&w->nodes);
    for (s = 0; s < ns; ++s) {
        long long b[3], o[3], k[3];
        double fx[3];
        pn__rom_base(d, inv, w->sx + s * (size_t)d, b, fx);
        for (o[0] = 0; o[0] < 3; ++o[0])
            for (o[1] = 0; o[1] < 3; ++o[1])
                for (o[2] = 0; o[2] < (d == 3 ? 3 : 1); ++o[2]) {
                    long v;
                    for (i = 0; i < 3; ++i) k[i] = b[i] + o[i];
                    if (nn == w->cap_n) {
                        size_t c = w->cap_n ? 2 * w->cap_n : 1024;
                        int ok = pn__rom_grow(w, (void **)&w->nidx, w->cap_n * 3, c * 3, sizeof(long long)) &&
                                 pn__rom_grow(w, (void **)&w->nm, w->cap_n, c, sizeof(double)) &&
                                 pn__rom_grow(w, (void **)&w->np, w->cap_n * 3, c * 3, sizeof(double)) &&
                                 pn__rom_grow(w, (void **)&w->nf, w->cap_n * 3, c * 3, sizeof(double)) &&
                                 pn__rom_grow(w, (void **)&w->ndrv, w->cap_n, c, sizeof(int));
                        if (!ok) return PN_ERROR_OUT_OF_MEMORY;
                        w->cap_n = c;
                    }
                    v = pn__rom_hash_put(w, &w->nodes, pn__rom_key(k), (long)nn);
                    if (v == -2) return PN_ERROR_OUT_OF_MEMORY;
                    if (v != (long)nn) continue;
                    memcpy(w->nidx + 3 * nn, k, sizeof k);
                    nn++;
                }
    }
    *nn_out = nn;
    return PN_OK;
}

/* the stencil of a point at x: for each of its nodes in the node hash, the node's index, the
   weight and the node's offset x_i - x */
typedef struct pn__rom_st {
    long node[27];
    double wt[27], off[27][3];
    int n;
} pn__rom_st;

static void pn__rom_stencil(const pn_rom_world *w, const double *x, pn__rom_st *st) {
    int d = w->dim, i;
    double dx = w->desc.dx_m, inv = 1 / dx, fx[3], W[3][3];
    long long b[3], o[3], k[3];
    pn__rom_base(d, inv, x, b, fx);
    for (i = 0; i < d; ++i) pn__rom_spline(fx[i], W[i]);
    for (i = d; i < 3; ++i) W[i][0] = 1;
    st->n = 0;
    for (o[0] = 0; o[0] < 3; ++o[0])
        for (o[1] = 0; o[1] < 3; ++o[1])
            for (o[2] = 0; o[2] < (d == 3 ? 3 : 1); ++o[2]) {
                long v;
                int c = st->n;
                for (i = 0; i < 3; ++i) k[i] = b[i] + o[i];
                v = pn__rom_hash_get(&w->nodes, pn__rom_key(k));
                if (v < 0) continue;
                st->node[c] = v;
                st->wt[c] = W[0][o[0]] * W[1][o[1]] * W[2][o[2]];
                for (i = 0; i < d; ++i) st->off[c][i] = ((double)o[i] - fx[i]) * dx;
                st->n++;
            }
}

/* the driven position and velocity at time t of a point of drive a at X: where the drive puts
   the point g(X, xhat at the drive's start) */
static void pn__rom_driven(const pn_rom_world *w, int a, const double *X, double t, double *x, double *v) {
    const pn__rom_drive *D = &w->drives[a];
    double x0[3], c[3];
    pn_rom_eval(&w->model, D->xhat0, 1, X, x0, NULL, NULL);
    pn__rom_drive_pos(D, w->dim, t, x0, x);
    pn__rom_drive_center(D, t, c);
    pn__rom_drive_vel(D, w->dim, c, x, v);
}

static pn_result pn__rom_step_implicit(pn_rom_world *w, double h, pn_rom_stats *st);

/* the material's P-wave speed sqrt((lambda + 2 mu) / rho) at rest */
static double pn__rom_wave_speed(const pn_rom_world *w) {
    return sqrt(((double)w->material.lambda + 2 * (double)w->material.mu) / w->desc.density_kg_m3);
}

/* the largest speed G vhat at up to 256 of the world's points, evenly strided (no allocation) */
static double pn__rom_vmax(const pn_rom_world *w) {
    enum { PTS = 256, B = 16 };
    int d = w->dim, K = w->latent, i, j;
    size_t stride = w->n > PTS ? w->n / PTS : 1, p = 0;
    double vmax = 0;
    while (p < w->n) { /* G vhat at every stride-th point, B at a time */
        double X[3 * B], G[3 * PN_ROM_MAX_LATENT * B];
        size_t nb = 0, b;
        for (; nb < B && p < w->n; ++nb, p += stride) memcpy(X + nb * (size_t)d, w->X + p * (size_t)d, sizeof(double) * (size_t)d);
        pn__rom_map(w, w->xhat, nb, X, NULL, NULL, G);
        for (b = 0; b < nb; ++b) {
            double v2 = 0;
            for (i = 0; i < d; ++i) {
                double v = 0;
                for (j = 0; j < K; ++j) v += G[b * (size_t)(d * K) + (size_t)(i * K + j)] * w->vhat[j];
                v2 += v * v;
            }
            vmax = v2 == v2 ? fmax(vmax, sqrt(v2)) : HUGE_VAL;
        }
    }
    return vmax;
}

PN__DEF pn_result pn_rom_stable_dt(const pn_rom_world *w, double *dt_s) {
    double vmax, c = pn__rom_wave_speed(w), dt;
    if (!dt_s) return PN__ROM_CFAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_stable_dt: dt_s is NULL");
    vmax = pn__rom_vmax(w);
    dt = PN_ROM_CFL * w->desc.dx_m / (c + vmax);
    if (!pn__rom_finite(dt) || !(dt > 0))
        return PN__ROM_CFAIL(w, PN_ERROR_NONFINITE, "pn_rom_stable_dt: the wave speed %g m/s or the body's speed %g m/s is not "
                             "finite", c, vmax);
    *dt_s = dt;
    return PN_OK;
}

PN__DEF pn_result pn_rom_step(pn_rom_world *w, double dt, pn_rom_stats *stats) {
    int d = w->dim, K = w->latent, i, j, a;
    size_t ns, nq = 0, nn, q, s, failed = 0, dd = (size_t)(d * d), dK = (size_t)(d * K);
    double xh[PN_ROM_MAX_LATENT], vh[PN_ROM_MAX_LATENT], t = w->time_s, g[3] = {0, 0, 0}, tmid = t + dt / 2;
    double inv4 = 4 / (w->desc.dx_m * w->desc.dx_m), rms = 0;
    pn_rom_stats st;
    pn_result r;
    long lq;
    w->error[0] = 0;
    memset(&st, 0, sizeof st);
    if (!pn__rom_finite(dt) || !(dt > 0)) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_step: dt_s = %g must be > 0", dt);
    if (w->desc.integrator != PN_ROM_EXPLICIT) {
        r = pn__rom_step_implicit(w, dt, &st);
        if (r == PN_OK && stats) *stats = st;
        return r;
    }
    { /* the explicit step's bound, before anything is touched */
        double bound = 0;
        if ((r = pn_rom_stable_dt(w, &bound)) != PN_OK) return r;
        if (dt > 1.5 * bound) /* measured stable to 1.5x the bound (docs/rom.md): beyond, refused */
            return PN__FAIL(w, PN_ERROR_STEP_TOO_LARGE, "pn_rom_step: dt_s = %g s is above 1.5x the explicit bound "
                                "pn_rom_stable_dt = %g s (grid dx_m %g m, wave speed %g m/s): take %.0f substeps, or an "
                                "implicit integrator", dt, bound, w->desc.dx_m, pn__rom_wave_speed(w), ceil(dt / bound));
    }
    for (i = 0; i < d; ++i) g[i] = w->desc.gravity[i];
    /* 1. samples and their kinematics at the current latent */
    ns = w->desc.samples < 0 || (size_t)w->desc.samples >= w->n ? w->n
                                                                 : (size_t)w->desc.samples + (size_t)(w->desc.boundary_samples * w->n_drives);
    if (!pn__rom_reserve(w, ns, w->cap_q ? w->cap_q : 64 * ns)) return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "pn_rom_step: out of memory");
    ns = pn__rom_sample(w);
    pn__rom_map(w, w->xhat, ns, w->sX, w->sx, w->sF, w->sG);
    /* 2. their grid nodes, and the quadrature points that reach them */
    if ((r = pn__rom_nodes(w, ns, &nn)) != PN_OK) return PN__FAIL(w, r, "pn_rom_step: out of memory (grid nodes)");
    r = w->desc.quadrature == PN_ROM_EULERIAN ? pn__rom_quad_eulerian(w, ns, &nq, &failed) : pn__rom_quad_lagrangian(w, &nq);
    if (r != PN_OK) return PN__FAIL(w, r, "pn_rom_step: out of memory (quadrature)");
    /* 3. velocity, affine velocity (APIC: C = dF/dt F^-1, dF/dt by a central difference of
          F along vhat), stress and flags of each quadrature point */
    for (q = 0; q < nq; ++q) {
        double *v = w->qv + q * (size_t)d;
        const double *G = w->qG + q * dK;
        for (i = 0; i < d; ++i) {
            v[i] = 0;
            for (j = 0; j < K; ++j) v[i] += G[i * K + j] * w->vhat[j];
        }
    }
    {
        double vn = 0, eps, xp[PN_ROM_MAX_LATENT], xm[PN_ROM_MAX_LATENT];
        size_t nk = 0, k;
        for (i = 0; i < K; ++i) {
            double sc = w->model.latent_std ? w->model.latent_std[i] : 1;
            vn = fmax(vn, fabs(w->vhat[i]) / (sc > 0 ? sc : 1));
        }
        memset(w->qC, 0, sizeof(double) * nq * dd);
        if (w->desc.transfer == PN_ROM_APIC && vn > 0) {
            eps = (w->desc.reference || w->model.activation == PN_ROM_AFFINE ? 1e-6 : 1e-3) / vn;
            for (i = 0; i < K; ++i) xp[i] = w->xhat[i] + eps * w->vhat[i], xm[i] = w->xhat[i] - eps * w->vhat[i];
            for (q = 0; q < nq; ++q) /* the kept points, gathered */
                if (w->qok[q]) {
                    memcpy(w->tX + nk * (size_t)d, w->qX + q * (size_t)d, sizeof(double) * (size_t)d);
                    w->tI[nk++] = (long)q;
                }
            pn__rom_map(w, xp, nk, w->tX, NULL, w->qT, NULL); /* qT: scratch here, the stresses below */
            pn__rom_map(w, xm, nk, w->tX, NULL, w->tF, NULL);
            for (k = 0; k < nk; ++k) {
                double Fd[9], Ci[9], *C;
                const double *F;
                q = (size_t)w->tI[k];
                C = w->qC + q * dd, F = w->qF + q * dd;
                for (i = 0; i < (int)dd; ++i) Fd[i] = (w->qT[k * dd + (size_t)i] - w->tF[k * dd + (size_t)i]) / (2 * eps);
                for (i = 0; i < d; ++i) { /* row i of C solves C F = Fd: F^T c_i = fd_i */
                    double Ft[9], rhs[3], y[3] = {0, 0, 0};
                    int c;
                    for (j = 0; j < d; ++j)
                        for (c = 0; c < d; ++c) Ft[j * d + c] = F[c * d + j];
                    for (c = 0; c < d; ++c) rhs[c] = Fd[i * d + c];
                    pn__rom_solve_F(d, Ft, rhs, y);
                    for (c = 0; c < d; ++c) Ci[i * d + c] = y[c];
                }
                memcpy(C, Ci, sizeof(double) * dd);
            }
        }
    }
#if defined(_OPENMP)
#pragma omp parallel for schedule(dynamic, 256) if (nq >= (size_t)w->desc.parallel_min)
#endif
    for (lq = 0; lq < (long)nq; ++lq) {
        pn_real F[9], tau[9];
        size_t qq = (size_t)lq;
        int k, fl = 0;
        if (!w->qok[qq]) continue;
        for (k = 0; k < (int)dd; ++k) F[k] = (pn_real)w->qF[qq * dd + (size_t)k];
        if (pn_kirchhoff_stress(&w->material, d, F, 0, tau) != PN_OK) {
            w->qok[qq] = 0;
            continue;
        }
        for (k = 0; k < (int)dd; ++k) w->qT[qq * dd + (size_t)k] = (double)tau[k];
        k = pn__rom_drive_of(w, w->qX + qq * (size_t)d);
        fl = k >= 0 ? k + 1 : 0;
        for (k = 0; k < w->n_loads; ++k)
            if (w->loads[k].on && w->loads[k].t_end > t && pn__rom_in_region(&w->loads[k].r, d, w->qX + qq * (size_t)d))
                fl |= 1 << (8 + k);
        w->qflag[qq] = fl;
    }
    /* 4. particle to grid (MLS-MPM, as plastinet_mpm.h's explicit step), in point order */
    memset(w->nm, 0, sizeof(double) * nn);
    memset(w->np, 0, sizeof(double) * nn * 3);
    memset(w->nf, 0, sizeof(double) * nn * 3);
    for (s = 0; s < nn; ++s) w->ndrv[s] = -1;
    for (q = 0; q < nq; ++q) {
        pn__rom_st stn;
        const double *v = w->qv + q * (size_t)d, *C = w->qC + q * dd, *T = w->qT + q * dd;
        double m = w->qm[q], V0 = w->qV0[q], acc[3] = {0, 0, 0};
        int c, k;
        if (!w->qok[q]) continue;
        for (k = 0; k < w->n_loads; ++k)
            if (w->qflag[q] & (1 << (8 + k))) {
                double span = fmin(dt, w->loads[k].t_end - t) / dt;
                for (i = 0; i < d; ++i) acc[i] += w->loads[k].acc[i] * span;
            }
        pn__rom_stencil(w, w->qx + q * (size_t)d, &stn);
        for (c = 0; c < stn.n; ++c) {
            long nd = stn.node[c];
            double wt = stn.wt[c], *e = stn.off[c];
            w->nm[nd] += wt * m;
            for (i = 0; i < d; ++i) {
                double ce = 0, te = 0;
                for (j = 0; j < d; ++j) ce += C[i * d + j] * e[j], te += T[i * d + j] * e[j];
                w->np[nd * 3 + (size_t)i] += wt * m * (v[i] + ce);
                w->nf[nd * 3 + (size_t)i] += -V0 * inv4 * wt * te + wt * m * acc[i];
            }
            if (w->qflag[q] & 0xff) w->ndrv[nd] = (w->qflag[q] & 0xff) - 1;
        }
    }
    /* 5. grid update: v = (p + dt f) / m + dt g, then the drives' rigid velocity (mid-step) */
    for (s = 0; s < nn; ++s) {
        double *v = w->np + s * 3;
        if (!(w->nm[s] > 0)) continue;
        for (i = 0; i < d; ++i) v[i] = (v[i] + dt * w->nf[s * 3 + (size_t)i]) / w->nm[s] + dt * g[i];
        if (w->ndrv[s] >= 0) {
            double xn[3], c[3];
            for (i = 0; i < d; ++i) xn[i] = (double)w->nidx[3 * s + (size_t)i] * w->desc.dx_m;
            pn__rom_drive_center(&w->drives[w->ndrv[s]], tmid, c);
            pn__rom_drive_vel(&w->drives[w->ndrv[s]], d, c, xn, v);
        }
    }
    /* 6. grid to samples: the trial velocity (over the nodes with mass) and position; driven
          samples exactly where their drive puts them */
    for (s = 0; s < ns; ++s) {
        pn__rom_st stn;
        double vs[3] = {0, 0, 0}, ws = 0, *xt = w->sxt + s * (size_t)d, *vt = w->sv + s * (size_t)d;
        int c;
        if (w->sdrv[s] >= 0) {
            pn__rom_driven(w, w->sdrv[s], w->sX + s * (size_t)d, t + dt, xt, vt);
            continue;
        }
        pn__rom_stencil(w, w->sx + s * (size_t)d, &stn);
        for (c = 0; c < stn.n; ++c) {
            long nd = stn.node[c];
            if (!(w->nm[nd] > 0)) continue;
            ws += stn.wt[c];
            for (i = 0; i < d; ++i) vs[i] += stn.wt[c] * w->np[nd * 3 + (size_t)i];
        }
        for (i = 0; i < d; ++i) {
            vt[i] = ws > 0 ? vs[i] / ws : 0;
            xt[i] = w->sx[s * (size_t)d + (size_t)i] + dt * vt[i];
        }
    }
    /* 7. projection: vhat by least squares on the velocities (Eq. 21/23); xhat += dt vhat
          (LINEAR) or by Gauss-Newton on the positions from 2 xhat - xhat_prev (Eq. 22) */
    if (!pn__rom_lsq(d, K, ns, w->sG, w->sv, vh))
        return PN__FAIL(w, PN_ERROR_NOT_CONVERGED, "pn_rom_step: the velocity projection is singular (%lu samples)",
                            (unsigned long)ns);
    if (w->desc.projection == PN_ROM_LINEAR) {
        for (i = 0; i < K; ++i) xh[i] = w->xhat[i] + dt * vh[i];
        pn__rom_map(w, xh, ns, w->sX, w->tx, NULL, NULL);
    } else {
        double obj = 0, dlt[PN_ROM_MAX_LATENT];
        int it;
        for (i = 0; i < K; ++i) xh[i] = 2 * w->xhat[i] - w->xhat_prev[i];
        for (it = 0; it < w->desc.gn_max; ++it) {
            double step = 1, nobj = 0, dn = 0, xn = 0;
            pn__rom_map(w, xh, ns, w->sX, w->tx, NULL, w->tG);
            for (obj = 0, s = 0; s < ns * (size_t)d; ++s) {
                w->tX[s] = w->sxt[s] - w->tx[s];
                obj += w->tX[s] * w->tX[s];
            }
            if (!pn__rom_lsq(d, K, ns, w->tG, w->tX, dlt)) break;
            for (i = 0; i < K; ++i) dn += dlt[i] * dlt[i], xn += xh[i] * xh[i];
            st.gn_iters = it + 1;
            { /* backtracking (the kit's): halve until the misfit does not rise, down to 2^-14 */
                double xt[PN_ROM_MAX_LATENT];
                pn__rom_misfit_ctx mc;
                mc.w = w, mc.n = ns, mc.X = w->sX, mc.target = w->sxt, mc.x = w->tx;
                step = pn__rom_armijo(pn__rom_misfit, &mc, (size_t)K, xh, dlt, obj, 0, 1, 1.0 / 16384, xt, &nobj);
            }
            if (step == 0) break;
            for (i = 0; i < K; ++i) xh[i] += step * dlt[i];
            obj = nobj;
            if (step * step * dn <= 1e-24 * (xn + 1)) break;
        }
        pn__rom_map(w, xh, ns, w->sX, w->tx, NULL, NULL);
    }
    for (s = 0; s < ns * (size_t)d; ++s) rms += (w->sxt[s] - w->tx[s]) * (w->sxt[s] - w->tx[s]);
    if (!pn__rom_all_finite((size_t)K, xh) || !pn__rom_all_finite((size_t)K, vh) || !pn__rom_finite(rms))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_step: the latent would not be finite (dt = %g s too large for the "
                            "scene?)", dt);
    for (i = 0; i < K; ++i) w->xhat_prev[i] = w->xhat[i], w->xhat[i] = xh[i], w->vhat[i] = vh[i];
    w->cvel_ok = 0;
    w->time_s += dt;
    w->steps++;
    for (a = 0; a < w->n_loads; ++a)
        if (w->loads[a].on && w->loads[a].t_end <= w->time_s) w->loads[a].on = 0;
    st.samples = ns, st.quad_points = nq, st.nodes = nn, st.inverse_failed = failed;
    st.residual_m = sqrt(rms / (double)(ns ? ns : 1));
    if (stats) *stats = st;
    return PN_OK;
}

/* ======================================================================================
   >>implicit: backward Euler in the latent (PN_ROM_IMPLICIT). The new latent z minimizes the
   incremental potential of the body, summed over a cubature c of the reference domain:
       E(z) = sum_c  w_c/2 |g(X_c, z) - t_c|^2  +  V_c psi(F(X_c, z))
   with w_c = m_c / h^2 and t_c = x_c + h v_c + h^2 (gravity + loads) for free material, and
   for driven material w_c = drive_weight (m_c / h^2 + E V_c / l^2) and t_c the drive's
   position at the end of the step (a penalty: the latent space cannot hold it exactly). Its
   gradient and Gauss-Newton Hessian in z:
       grad = sum_c w_c G_c^T (g_c - t_c) + V_c J_c^T P(F_c)
       H    = sum_c w_c G_c^T G_c + V_c J_c^T [dP/dF]+ J_c,     J_c = dF_c/dz
   (G = dg/dz; [dP/dF]+ the PSD projection; J by central differences of F along each latent).
   Newton with an Armijo line search from z_n + h vhat_n. The cubature is one point per cell
   of edge cubature_m, per drive and per set of loads, at the centroid of that material with
   its mass and volume: the midpoint rule, exact for the mass and first moment of each cell.
   ====================================================================================== */

typedef struct pn__rom_cent { /* a point's cubature class, for the sort */
    unsigned long long key;
    unsigned cls;
    size_t p;
} pn__rom_cent;

static int pn__rom_cent_cmp(const void *a, const void *b) {
    const pn__rom_cent *u = (const pn__rom_cent *)a, *v = (const pn__rom_cent *)b;
    if (u->key != v->key) return u->key < v->key ? -1 : 1;
    if (u->cls != v->cls) return u->cls < v->cls ? -1 : 1;
    return u->p < v->p ? -1 : u->p > v->p;
}

/* The drive of each point as MPM applies it (into drv): a driven particle's whole stencil of
   grid nodes takes the drive's velocity, so a free particle whose stencil lies entirely on
   such nodes moves with the drive too: the reference is stiffer by that layer of material
   (about half a cell). Reference positions; a node touched by two drives holds no one. */
static int pn__rom_drive_marks(pn_rom_world *w, int *drv) {
    int d = w->dim, i;
    size_t n = w->n, p;
    double inv = 1 / w->desc.dx_m;
    pn__rom_hash held;
    memset(&held, 0, sizeof held);
    for (p = 0; p < n; ++p) drv[p] = pn__rom_drive_of(w, w->X + p * (size_t)d);
    if (w->desc.drive_region_only || !w->n_drives) return 1;
    for (p = 0; p < n; ++p) { /* the nodes the driven points touch, by drive (-2: two drives) */
        long long b[3], k[3] = {0, 0, 0}, o;
        double fx[3];
        if (drv[p] < 0) continue;
        pn__rom_base(d, inv, w->X + p * (size_t)d, b, fx);
        for (o = 0; o < (d == 3 ? 27 : 9); ++o) {
            long v;
            for (i = 0; i < d; ++i) k[i] = b[i] + (i == 0 ? o % 3 : i == 1 ? o / 3 % 3 : o / 9);
            v = pn__rom_hash_put(w, &held, pn__rom_key(k), drv[p]);
            if (v == -2) {
                pn__rom_hash_free(w, &held);
                return 0;
            }
            if (v != drv[p]) *pn__rom_hash_ref(&held, pn__rom_key(k)) = -2;
        }
    }
    for (p = 0; p < n; ++p) { /* free points wholly on one drive's nodes */
        long long b[3], k[3] = {0, 0, 0}, o;
        double fx[3];
        long a = -1;
        if (drv[p] >= 0) continue;
        pn__rom_base(d, inv, w->X + p * (size_t)d, b, fx);
        for (o = 0; o < (d == 3 ? 27 : 9); ++o) {
            long v;
            for (i = 0; i < d; ++i) k[i] = b[i] + (i == 0 ? o % 3 : i == 1 ? o / 3 % 3 : o / 9);
            v = pn__rom_hash_get(&held, pn__rom_key(k));
            if (v < 0 || (a >= 0 && v != a)) break;
            a = v;
        }
        if (o == (d == 3 ? 27 : 9)) drv[p] = (int)a;
    }
    pn__rom_hash_free(w, &held);
    return 1;
}

/* (re)build the cubature from the world's points, their drives and live loads */
static pn_result pn__rom_cubature(pn_rom_world *w) {
    int d = w->dim, K = w->latent, i, a, ok = 1, *drv;
    size_t n = w->n, p, c, nc = 0, dd = (size_t)(d * d), dK = (size_t)(d * K);
    double inv = 1 / w->desc.cubature_m;
    pn__rom_cent *e = (pn__rom_cent *)pn_alloc(&w->desc.allocator, n * sizeof *e + 1);
    drv = (int *)pn_alloc(&w->desc.allocator, n * sizeof *drv + 1);
    if (!e || !drv || !pn__rom_drive_marks(w, drv)) {
        pn_free(&w->desc.allocator, e), pn_free(&w->desc.allocator, drv);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    for (p = 0; p < n; ++p) {
        const double *X = w->X + p * (size_t)d;
        long long k[3] = {0, 0, 0};
        unsigned cls = (unsigned)(drv[p] + 1);
        for (i = 0; i < d; ++i) k[i] = (long long)floor(X[i] * inv);
        for (a = 0; a < w->n_loads; ++a)
            if (w->loads[a].on && pn__rom_in_region(&w->loads[a].r, d, X)) cls |= 1u << (8 + a);
        e[p].key = pn__rom_key(k), e[p].cls = cls, e[p].p = p;
    }
    qsort(e, n, sizeof *e, pn__rom_cent_cmp);
    for (p = 0; p < n; ++p) nc += p == 0 || e[p].key != e[p - 1].key || e[p].cls != e[p - 1].cls;
    if (nc > w->cap_c) {
        size_t h = w->cap_c;
        ok &= pn__rom_grow(w, (void **)&w->cX, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cm, h, nc, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cV, h, nc, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cvel, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cxp, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cvp, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cv0, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cdrv, h, nc, sizeof(int));
        ok &= pn__rom_grow(w, (void **)&w->cload, h, nc, sizeof(unsigned));
        ok &= pn__rom_grow(w, (void **)&w->cx, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cx0, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cF, h * dd, nc * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cG, h * dK, nc * dK, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cJ, h * dd * (size_t)K, nc * dd * (size_t)K, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cFt, h * dd, nc * dd, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->ctgt, h * (size_t)d, nc * (size_t)d, sizeof(double));
        ok &= pn__rom_grow(w, (void **)&w->cw, h, nc, sizeof(double));
        if (ok) w->cap_c = nc;
    }
    if (!ok) {
        pn_free(&w->desc.allocator, e), pn_free(&w->desc.allocator, drv);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    for (c = 0, p = 0; p < n; ++c) { /* one run of equal classes: its mass, volume, centroid */
        size_t q = p;
        double *X = w->cX + c * (size_t)d, m = 0, V = 0;
        for (i = 0; i < d; ++i) X[i] = 0;
        for (; q < n && e[q].key == e[p].key && e[q].cls == e[p].cls; ++q) {
            m += w->mass[e[q].p], V += w->vol[e[q].p];
            for (i = 0; i < d; ++i) X[i] += w->mass[e[q].p] * w->X[e[q].p * (size_t)d + (size_t)i];
        }
        for (i = 0; i < d; ++i) X[i] /= m;
        w->cm[c] = m, w->cV[c] = V;
        w->cdrv[c] = (int)(e[p].cls & 0xffu) - 1, w->cload[c] = e[p].cls >> 8;
        p = q;
    }
    pn_free(&w->desc.allocator, e), pn_free(&w->desc.allocator, drv);
    w->n_c = nc;
    w->cub_dirty = 0, w->cvel_ok = 0;
    return PN_OK;
}

/* E(z) and, if grad, its gradient and Gauss-Newton Hessian H (K x K); 0 if not finite */
static int pn__rom_ip(pn_rom_world *w, const double *z, double *E, double *grad, double *H) {
    int d = w->dim, K = w->latent, i, j, k, l;
    size_t C = w->n_c, c, dd = (size_t)(d * d), dK = (size_t)(d * K);
    double e = 0;
    pn__rom_map(w, z, C, w->cX, w->cx, w->cF, grad ? w->cG : NULL);
    if (grad) {
        double zt[PN_ROM_MAX_LATENT];
        for (i = 0; i < K; ++i) grad[i] = 0;
        for (i = 0; i < K * K; ++i) H[i] = 0;
        for (k = 0; k < K; ++k) { /* J[:, k] = (F(z + eps e_k) - F(z - eps e_k)) / (2 eps) */
            double sc = w->model.latent_std && w->model.latent_std[k] > 0 ? w->model.latent_std[k] : 1;
            double eps = (w->model.activation == PN_ROM_AFFINE ? 1 : w->desc.reference ? 1e-6 : 1e-2) * sc; /* affine: F is linear */
            int sgn;
            for (sgn = 1; sgn >= -1; sgn -= 2) {
                memcpy(zt, z, sizeof(double) * (size_t)K);
                zt[k] += sgn * eps;
                pn__rom_map(w, zt, C, w->cX, NULL, w->cFt, NULL);
                for (c = 0; c < C; ++c)
                    for (i = 0; i < (int)dd; ++i)
                        w->cJ[(c * dd + (size_t)i) * (size_t)K + (size_t)k] =
                            (sgn > 0 ? 0 : w->cJ[(c * dd + (size_t)i) * (size_t)K + (size_t)k]) +
                            sgn * w->cFt[c * dd + (size_t)i] / (2 * eps);
            }
        }
    }
    for (c = 0; c < C; ++c) {
        pn_real F[9], P[9], A[81], psi;
        double r[3], Pd[9], JtA[PN_ROM_MAX_LATENT * 9];
        const double *x = w->cx + c * (size_t)d, *t = w->ctgt + c * (size_t)d, *G = w->cG + c * dK, *J = w->cJ + c * dd * (size_t)K;
        double wc = w->cw[c], V = w->cV[c];
        for (i = 0; i < (int)dd; ++i) F[i] = (pn_real)w->cF[c * dd + (size_t)i];
        if (pn_elastic_energy(&w->material, d, F, 0, &psi, grad ? P : NULL, grad ? A : NULL, PN_EVAL_PROJECT_PSD) != PN_OK)
            return 0;
        for (i = 0; i < d; ++i) r[i] = x[i] - t[i], e += 0.5 * wc * r[i] * r[i];
        e += V * (double)psi;
        if (!grad) continue;
        for (i = 0; i < (int)dd; ++i) Pd[i] = (double)P[i];
        for (i = 0; i < K; ++i) { /* inertia: w G^T r, w G^T G */
            double s = 0;
            for (l = 0; l < d; ++l) s += G[l * K + i] * r[l];
            grad[i] += wc * s;
            for (j = 0; j <= i; ++j) {
                double q = 0;
                for (l = 0; l < d; ++l) q += G[l * K + i] * G[l * K + j];
                H[i * K + j] += wc * q;
            }
        }
        for (i = 0; i < K; ++i) { /* elasticity: V J^T P, V J^T A J */
            double s = 0;
            for (l = 0; l < (int)dd; ++l) s += J[(size_t)l * (size_t)K + (size_t)i] * Pd[l];
            grad[i] += V * s;
            for (l = 0; l < (int)dd; ++l) {
                double q = 0;
                for (j = 0; j < (int)dd; ++j) q += J[(size_t)j * (size_t)K + (size_t)i] * (double)A[j * (int)dd + l];
                JtA[i * 9 + l] = q;
            }
            for (j = 0; j <= i; ++j) {
                double q = 0;
                for (l = 0; l < (int)dd; ++l) q += JtA[i * 9 + l] * J[(size_t)l * (size_t)K + (size_t)j];
                H[i * K + j] += V * q;
            }
        }
    }
    if (grad)
        for (i = 0; i < K; ++i)
            for (j = 0; j < i; ++j) H[j * K + i] = H[i * K + j];
    *E = e;
    return pn__rom_finite(e) && (!grad || pn__rom_all_finite((size_t)K, grad));
}

/* the incremental potential's value for the kit's line search */
static pn_result pn__rom_ip_value(void *ctx, const double *z, double *E) {
    return pn__rom_ip((pn_rom_world *)ctx, z, E, NULL, NULL) ? PN_OK : PN_ERROR_NONFINITE;
}

static pn_result pn__rom_step_implicit(pn_rom_world *w, double h, pn_rom_stats *st) {
    int d = w->dim, K = w->latent, i, it, a, mode = (int)w->desc.integrator;
    size_t C, c, dK = (size_t)(d * K);
    double z[PN_ROM_MAX_LATENT], grad[PN_ROM_MAX_LATENT], H[PN_ROM_MAX_LATENT * PN_ROM_MAX_LATENT], E = 0, g[3] = {0, 0, 0};
    double t = w->time_s, l2 = w->desc.cubature_m * w->desc.cubature_m, E_pa = w->desc.youngs_pa, beta, tau, td;
    pn_result r;
    { /* the free flight x_n + h v_n + h^2 (g + loads), before anything is touched: beyond
         PN__ROM_MAX_FLIGHT body sizes no learned map follows it, and far beyond it the
         incremental potential is rounding (its inertia target swamps every position) */
        double acc = 0, v = pn__rom_vmax(w), flight;
        for (i = 0; i < d; ++i) acc += w->desc.gravity[i] * w->desc.gravity[i];
        acc = sqrt(acc);
        for (a = 0; a < w->n_loads; ++a)
            if (w->loads[a].on) {
                double l2 = 0;
                for (i = 0; i < d; ++i) l2 += w->loads[a].acc[i] * w->loads[a].acc[i];
                acc += sqrt(l2);
            }
        flight = h * v + h * h * acc;
        if (!(flight <= PN__ROM_MAX_FLIGHT * w->size_m))
            return PN__FAIL(w, PN_ERROR_STEP_TOO_LARGE, "pn_rom_step: dt_s = %g s would carry free material %.3g m in one step "
                                "(speed %.3g m/s, acceleration %.3g m/s^2), more than %g times the body's size %.3g m: take "
                                "steps of at most %.3g s", h, flight, v, acc, PN__ROM_MAX_FLIGHT, w->size_m,
                                v > 0 || acc > 0 ? 2 * PN__ROM_MAX_FLIGHT * w->size_m / (v + sqrt(v * v + 4 * acc * PN__ROM_MAX_FLIGHT * w->size_m)) : h);
    }
    if (w->cub_dirty && (r = pn__rom_cubature(w)) != PN_OK) return PN__FAIL(w, r, "pn_rom_step: out of memory (cubature)");
    C = w->n_c;
    if (mode == PN_ROM_BDF2 && (w->cvel_ok < 2 || h != w->h_prev)) mode = PN_ROM_IMPLICIT; /* BDF2 starts as backward Euler */
    /* each scheme as one minimization: inertia weight beta m, target x_n + tau v_n + tau^2 a
       (BDF2: the two-step extrapolation), drives at time td:
         backward Euler  beta = 1/h^2,    tau = h
         BDF2            beta = 9/(4h^2), tau = 2h/3,  from 4/3 x_n - 1/3 x_n-1 and 4/3 v_n - 1/3 v_n-1
         midpoint        beta = 4/h^2,    tau = h/2,   the minimizer is the midpoint state */
    beta = mode == PN_ROM_MIDPOINT ? 4 / (h * h) : mode == PN_ROM_BDF2 ? 9 / (4 * h * h) : 1 / (h * h);
    tau = mode == PN_ROM_MIDPOINT ? h / 2 : mode == PN_ROM_BDF2 ? 2 * h / 3 : h;
    td = mode == PN_ROM_MIDPOINT ? t + h / 2 : t + h;
    for (i = 0; i < d; ++i) g[i] = w->desc.gravity[i];
    /* the state at the start: x_n, v_n (the last step's velocity, else G vhat), the targets */
    pn__rom_map(w, w->xhat, C, w->cX, w->cx0, NULL, w->cG);
    for (c = 0; c < C; ++c) {
        double *tg = w->ctgt + c * (size_t)d, *v = w->cv0 + c * (size_t)d, acc[3], vd[3];
        const double *x0 = w->cx0 + c * (size_t)d, *G = w->cG + c * dK;
        for (i = 0; i < d; ++i) {
            int j;
            if (w->cvel_ok) v[i] = w->cvel[c * (size_t)d + (size_t)i];
            else
                for (v[i] = 0, j = 0; j < K; ++j) v[i] += G[i * K + j] * w->vhat[j];
            acc[i] = g[i];
        }
        if (w->cdrv[c] >= 0) {
            pn__rom_driven(w, w->cdrv[c], w->cX + c * (size_t)d, td, tg, vd);
            w->cw[c] = w->desc.drive_weight * (w->cm[c] * beta + E_pa * w->cV[c] / l2);
            continue;
        }
        for (a = 0; a < w->n_loads; ++a)
            if ((w->cload[c] >> a & 1u) && w->loads[a].on && w->loads[a].t_end > t) {
                double span = fmin(h, w->loads[a].t_end - t) / h;
                for (i = 0; i < d; ++i) acc[i] += w->loads[a].acc[i] * span;
            }
        for (i = 0; i < d; ++i) {
            const size_t k = c * (size_t)d + (size_t)i;
            if (mode == PN_ROM_BDF2)
                tg[i] = (4 * x0[i] - w->cxp[k]) / 3 + tau * (4 * v[i] - w->cvp[k]) / 3 + tau * tau * acc[i];
            else
                tg[i] = x0[i] + tau * v[i] + tau * tau * acc[i];
        }
        w->cw[c] = w->cm[c] * beta;
    }
    /* Newton from the predictor z_n + tau vhat_n */
    for (i = 0; i < K; ++i) z[i] = w->xhat[i] + tau * w->vhat[i];
    for (it = 0; it < w->desc.newton_max; ++it) {
        double dz[PN_ROM_MAX_LATENT], A[PN_ROM_MAX_LATENT * PN_ROM_MAX_LATENT], gd = 0, alpha = 1, Et = 0, tr = 0, lam = 0, big = 0;
        int tries;
        if (!pn__rom_ip(w, z, &E, grad, H))
            return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_step: the implicit step's energy is not finite (dt = %g s)", h);
        for (i = 0; i < K; ++i) tr += H[i * K + i];
        for (tries = 0; tries < 30; ++tries) { /* Cholesky, with a growing ridge if it fails */
            memcpy(A, H, sizeof(double) * (size_t)(K * K));
            for (i = 0; i < K; ++i) A[i * K + i] += lam, dz[i] = -grad[i];
            if (pn__rom_spd_solve(K, A, dz)) break;
            lam = lam > 0 ? 10 * lam : 1e-10 * tr / K + 1e-300;
        }
        for (i = 0; i < K; ++i) {
            double sc = w->model.latent_std && w->model.latent_std[i] > 0 ? w->model.latent_std[i] : 1;
            gd += grad[i] * dz[i];
            big = fmax(big, fabs(dz[i]) / sc);
        }
        if (tries == 30 || !(gd < 0)) break; /* no descent left (the float path's noise floor) */
        if (big < w->desc.newton_tol) { /* converged: the last, small step needs no line search */
            for (i = 0; i < K; ++i) z[i] += dz[i];
            st->newton_iters = it + 1;
            break;
        }
        { /* Armijo backtracking (the kit's) */
            double zt[PN_ROM_MAX_LATENT];
            alpha = pn__rom_armijo(pn__rom_ip_value, w, (size_t)K, z, dz, E, gd, 1, 1e-4, zt, &Et);
        }
        if (alpha == 0) break;
        for (i = 0; i < K; ++i) z[i] += alpha * dz[i];
        E = Et;
        st->newton_iters = it + 1;
    }
    if (!pn__rom_all_finite((size_t)K, z))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_step: the latent would not be finite (dt = %g s)", h);
    /* the new state: the latent (midpoint: extrapolated from the midpoint state, z_n+1 =
       2 z_n+1/2 - z_n), the cubature velocities by the scheme's difference formula (midpoint:
       v_n+1 = 2 v_n+1/2 - v_n = 2 (x_n+1 - x_n) / h - v_n), the latent velocity by difference */
    if (mode == PN_ROM_MIDPOINT)
        for (i = 0; i < K; ++i) z[i] = 2 * z[i] - w->xhat[i];
    pn__rom_map(w, z, C, w->cX, w->cx, NULL, NULL);
    for (c = 0; c < C * (size_t)d; ++c) {
        double x1 = w->cx[c], x0 = w->cx0[c], v0 = w->cv0[c];
        w->cvel[c] = mode == PN_ROM_MIDPOINT ? 2 * (x1 - x0) / h - v0
                     : mode == PN_ROM_BDF2   ? (3 * x1 - 4 * x0 + w->cxp[c]) / (2 * h)
                                             : (x1 - x0) / h;
        w->cxp[c] = x0, w->cvp[c] = v0;
    }
    for (i = 0; i < K; ++i) w->xhat_prev[i] = w->xhat[i], w->vhat[i] = (z[i] - w->xhat[i]) / h, w->xhat[i] = z[i];
    w->cvel_ok = 2, w->h_prev = h;
    w->time_s += h;
    w->steps++;
    for (a = 0; a < w->n_loads; ++a)
        if (w->loads[a].on && w->loads[a].t_end <= w->time_s) w->loads[a].on = 0;
    st->cubature_points = C, st->energy_j = E;
    return PN_OK;
}

/* ======================================================================================
   >>fit and >>render: the latent of a full state (Eq. 19), and g at many points in float
   ====================================================================================== */

PN__DEF pn_result pn_rom_fit(pn_rom_world *w, const double *x, const double *v, double *rms_m) {
    int d = w->dim, K = w->latent, i, it;
    size_t n = w->n, p, nd = n * (size_t)d;
    double xh[PN_ROM_MAX_LATENT], dl[PN_ROM_MAX_LATENT], obj = HUGE_VAL, *gx = NULL, *G = NULL, *r = NULL;
    int fail = 0;
    w->error[0] = 0;
    if (!x || !pn__rom_all_finite(nd, x) || (v && !pn__rom_all_finite(nd, v)))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_fit: x is NULL, or x or v not finite");
    gx = (double *)pn__rom_alloc(w, nd, sizeof(double), &fail);
    r = (double *)pn__rom_alloc(w, nd, sizeof(double), &fail);
    G = (double *)pn__rom_alloc(w, nd * (size_t)K, sizeof(double), &fail);
    if (fail) {
        pn_free(&w->desc.allocator, gx), pn_free(&w->desc.allocator, r), pn_free(&w->desc.allocator, G);
        return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "pn_rom_fit: out of memory");
    }
    memcpy(xh, w->xhat, sizeof xh);
    for (it = 0; it < 50; ++it) { /* Gauss-Newton with halving */
        double step = 1, nobj = 0, dn = 0, xn = 0;
        pn__rom_map(w, xh, n, w->X, gx, NULL, G);
        for (obj = 0, p = 0; p < nd; ++p) r[p] = x[p] - gx[p], obj += r[p] * r[p];
        if (!pn__rom_lsq(d, K, n, G, r, dl)) break;
        for (i = 0; i < K; ++i) dn += dl[i] * dl[i], xn += xh[i] * xh[i];
        { /* backtracking (the kit's): halve until the misfit does not rise, down to 2^-20 */
            double xt[PN_ROM_MAX_LATENT];
            pn__rom_misfit_ctx mc;
            mc.w = w, mc.n = n, mc.X = w->X, mc.target = x, mc.x = gx;
            step = pn__rom_armijo(pn__rom_misfit, &mc, (size_t)K, xh, dl, obj, 0, 1, 1.0 / 1048576, xt, &nobj);
        }
        if (step == 0) break;
        for (i = 0; i < K; ++i) xh[i] += step * dl[i];
        obj = nobj;
        if (step * step * dn <= 1e-28 * (xn + 1)) break;
    }
    if (!pn__rom_all_finite((size_t)K, xh)) {
        pn_free(&w->desc.allocator, gx), pn_free(&w->desc.allocator, r), pn_free(&w->desc.allocator, G);
        return PN__FAIL(w, PN_ERROR_NOT_CONVERGED, "pn_rom_fit: Gauss-Newton did not converge");
    }
    for (i = 0; i < K; ++i) w->xhat[i] = w->xhat_prev[i] = xh[i], w->vhat[i] = 0;
    w->cvel_ok = 0;
    if (v) {
        pn__rom_map(w, xh, n, w->X, NULL, NULL, G);
        if (pn__rom_lsq(d, K, n, G, v, dl))
            for (i = 0; i < K; ++i) w->vhat[i] = dl[i];
    }
    if (rms_m) *rms_m = sqrt(obj / (double)(n ? n : 1));
    pn_free(&w->desc.allocator, gx), pn_free(&w->desc.allocator, r), pn_free(&w->desc.allocator, G);
    return PN_OK;
}

/* float positions (and F) at n reference points X from the current latent */
static void pn__rom_render(const pn_rom_world *w, size_t n, const float *Xf, const double *Xd, float *x, float *F) {
    const pn_rom_model *m = &w->model;
    int d = w->dim, K = w->latent;
    long nb = (long)((n + PN__ROM_B - 1) / PN__ROM_B), lb;
    float c1[PN_ROM_MAX_WIDTH];
    if (m->activation == PN_ROM_AFFINE || w->desc.reference) {
        size_t p;
        for (p = 0; p < n; ++p) {
            double X[3], xx[3], FF[9];
            int i;
            for (i = 0; i < d; ++i) X[i] = Xf ? (double)Xf[p * (size_t)d + (size_t)i] : Xd[p * (size_t)d + (size_t)i];
            pn_rom_eval(m, w->xhat, 1, X, xx, F ? FF : NULL, NULL);
            for (i = 0; i < d; ++i) x[p * (size_t)d + (size_t)i] = (float)xx[i];
            if (F)
                for (i = 0; i < d * d; ++i) F[p * (size_t)(d * d) + (size_t)i] = (float)FF[i];
        }
        return;
    }
    {
        const float *W = w->wf + w->wf_off[0];
        int o, i, win = m->width[0];
        for (o = 0; o < m->width[1]; ++o) {
            double t = (double)W[m->width[1] * win + o];
            for (i = 0; i < K; ++i) t += (double)W[o * win + d + i] * w->xhat[i];
            c1[o] = (float)t;
        }
    }
#if defined(_OPENMP)
#pragma omp parallel for schedule(dynamic, 16) if (n >= (size_t)w->desc.parallel_min)
#endif
    for (lb = 0; lb < nb; ++lb) {
        float Xn[3 * PN__ROM_B], out[3 * PN__ROM_B], J[3 * (3 + PN_ROM_MAX_LATENT) * PN__ROM_B];
        size_t p0 = (size_t)lb * PN__ROM_B;
        int b, i, k, cnt = (int)(n - p0 < PN__ROM_B ? n - p0 : PN__ROM_B);
        for (i = 0; i < d; ++i)
            for (b = 0; b < PN__ROM_B; ++b) {
                size_t at = (p0 + (size_t)(b < cnt ? b : 0)) * (size_t)d + (size_t)i;
                double X = Xf ? (double)Xf[at] : Xd[at];
                Xn[i * PN__ROM_B + b] = (float)(w->xs[i] * X + w->xo[i]);
            }
        pn__rom_lanes(w, c1, Xn, out, F ? J : NULL);
        for (b = 0; b < cnt; ++b)
            for (k = 0; k < d; ++k) {
                size_t p = p0 + (size_t)b;
                x[p * (size_t)d + (size_t)k] = (float)(m->out_mean[k] + m->out_std[k] * (double)out[k * PN__ROM_B + b]);
                if (F)
                    for (i = 0; i < d; ++i)
                        F[p * (size_t)(d * d) + (size_t)(k * d + i)] =
                            (float)(m->out_std[k] * w->xs[i]) * J[((size_t)k * (size_t)(d + K) + (size_t)i) * PN__ROM_B + (size_t)b];
            }
    }
}

PN__DEF pn_result pn_rom_positions(const pn_rom_world *w, size_t first, size_t n, float *x, float *F) {
    if (!x || first > w->n || n > w->n - first)
        return PN__ROM_CFAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_positions: x is NULL, or points %lu .. +%lu beyond the "
                             "world's %lu", (unsigned long)first, (unsigned long)n, (unsigned long)w->n);
    pn__rom_render(w, n, NULL, w->X + first * (size_t)w->dim, x, F);
    return PN_OK;
}

PN__DEF pn_result pn_rom_map(const pn_rom_world *w, size_t n, const float *X, float *x, float *F) {
    size_t p;
    if (!X || !x) return PN__ROM_CFAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_map: X or x is NULL");
    for (p = 0; p < n * (size_t)w->dim; ++p)
        if (!pn__rom_finite((double)X[p]))
            return PN__ROM_CFAIL(w, PN_ERROR_NONFINITE, "pn_rom_map: reference point %lu (X[%lu]) is not finite",
                                 (unsigned long)(p / (size_t)w->dim), (unsigned long)p);
    pn__rom_render(w, n, X, NULL, x, F);
    return PN_OK;
}

/* ======================================================================================
   >>embed: a render lattice; points drawn by a Taylor step from their nearest node
   ====================================================================================== */

typedef struct pn__rom_ekey {
    unsigned long long key;
    size_t p;
} pn__rom_ekey;

static int pn__rom_ekey_cmp(const void *a, const void *b) {
    const pn__rom_ekey *u = (const pn__rom_ekey *)a, *v = (const pn__rom_ekey *)b;
    if (u->key != v->key) return u->key < v->key ? -1 : 1;
    return u->p < v->p ? -1 : u->p > v->p;
}

PN__DEF void pn_rom_embed_destroy(pn_rom_embedding *e) {
    pn_allocator a;
    if (!e) return;
    a = e->allocator;
    pn_free(&a, e->off), pn_free(&a, e->node), pn_free(&a, e->nX), pn_free(&a, e->nx), pn_free(&a, e->nF);
    pn_free(&a, e);
}

PN__DEF pn_result pn_rom_embed(pn_rom_world *w, size_t n, const float *X, double spacing, pn_rom_embedding **out) {
    int d = w->dim, fail = 0, i;
    size_t p, k, nn = 0;
    pn__rom_ekey *t;
    pn_rom_embedding *e;
    w->error[0] = 0;
    if (!out) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_embed: out is NULL");
    *out = NULL;
    if (!pn__rom_finite(spacing) || !(spacing > 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_embed: spacing_m = %g must be > 0", spacing);
    if (!X || !n) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_rom_embed: no points");
    for (p = 0; p < n * (size_t)d; ++p)
        if (!pn__rom_finite((double)X[p]) || fabs((double)X[p]) / spacing > 1e6)
            return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_rom_embed: point %lu is not finite, or beyond 1e6 spacings",
                                (unsigned long)(p / (size_t)d));
    t = (pn__rom_ekey *)pn__rom_alloc(w, n, sizeof *t, &fail);
    e = (pn_rom_embedding *)pn__rom_alloc(w, 1, sizeof *e, &fail);
    if (e) {
        e->allocator = w->desc.allocator, e->dim = d, e->n = n;
        e->off = (float *)pn__rom_alloc(w, n * (size_t)d, sizeof(float), &fail);
        e->node = (size_t *)pn__rom_alloc(w, n, sizeof(size_t), &fail);
    }
    if (fail) {
        pn_free(&w->desc.allocator, t), pn_rom_embed_destroy(e);
        return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "pn_rom_embed: out of memory for %lu points", (unsigned long)n);
    }
    for (p = 0; p < n; ++p) {
        long long c[3] = {0, 0, 0};
        for (i = 0; i < d; ++i) c[i] = (long long)floor((double)X[p * (size_t)d + (size_t)i] / spacing + 0.5);
        t[p].key = pn__rom_key(c), t[p].p = p;
    }
    qsort(t, n, sizeof *t, pn__rom_ekey_cmp);
    for (p = 0; p < n; ++p) nn += p == 0 || t[p].key != t[p - 1].key;
    e->n_nodes = nn;
    e->nX = (double *)pn__rom_alloc(w, nn * (size_t)d, sizeof(double), &fail);
    e->nx = (double *)pn__rom_alloc(w, nn * (size_t)d, sizeof(double), &fail);
    e->nF = (double *)pn__rom_alloc(w, nn * (size_t)(d * d), sizeof(double), &fail);
    if (fail) {
        pn_free(&w->desc.allocator, t), pn_rom_embed_destroy(e);
        return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "pn_rom_embed: out of memory for %lu nodes", (unsigned long)nn);
    }
    for (k = 0, p = 0; p < n; ++p) {
        const float *Xp = X + t[p].p * (size_t)d;
        if (p > 0 && t[p].key != t[p - 1].key) k++;
        if (p == 0 || t[p].key != t[p - 1].key)
            for (i = 0; i < d; ++i) e->nX[k * (size_t)d + (size_t)i] = floor((double)Xp[i] / spacing + 0.5) * spacing;
        e->node[t[p].p] = k;
        for (i = 0; i < d; ++i) e->off[t[p].p * (size_t)d + (size_t)i] = (float)((double)Xp[i] - e->nX[k * (size_t)d + (size_t)i]);
    }
    pn_free(&w->desc.allocator, t);
    *out = e;
    return PN_OK;
}

PN__DEF pn_result pn_rom_embed_positions(const pn_rom_world *w, pn_rom_embedding *e, float *x) {
    int d = w->dim;
    long lp;
    if (!e || !x || e->dim != d) return PN_ERROR_INVALID_ARGUMENT;
    pn__rom_map(w, w->xhat, e->n_nodes, e->nX, e->nx, e->nF, NULL);
#if defined(_OPENMP)
#pragma omp parallel for schedule(static) if (e->n >= (size_t)w->desc.parallel_min)
#endif
    for (lp = 0; lp < (long)e->n; ++lp) {
        size_t p = (size_t)lp, k = e->node[p];
        const double *xn = e->nx + k * (size_t)d, *F = e->nF + k * (size_t)(d * d);
        const float *o = e->off + p * (size_t)d;
        int i, j;
        for (i = 0; i < d; ++i) {
            double v = xn[i];
            for (j = 0; j < d; ++j) v += F[i * d + j] * (double)o[j];
            x[p * (size_t)d + (size_t)i] = (float)v;
        }
    }
    return PN_OK;
}

#endif /* PLASTINET_ROM_IMPLEMENTATION */
