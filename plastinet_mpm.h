/* plastinet_mpm.h - v0.21 - material point method and finite element solvers on plastinet.h.
   Public domain or MIT, your choice: see the end of plastinet.h.

   Do this in exactly one C or C++ file, after plastinet.h:
       #define PLASTINET_IMPLEMENTATION
       #include "plastinet.h"
       #include "plastinet_mpm.h"

   ======================================================================================
   WHAT IS HERE
   ======================================================================================
   The declarations read as the API: PART I MPM, PART II FEM, PART III COUPLING. The
   implementation follows in rooms, each under a banner // >>name (grep '>>name'), in this
   order; a room calls only rooms above it (the three exceptions are declared where used).

     room            public functions                what else
     >>group         (shared)                        a group's implicit energy, checked the
                                                     same way for worlds and meshes (the line
                                                     search, PCG, messages, the substep
                                                     fallback: plastinet.h's >>kit)
     >>world         pn_mpm_create, _destroy,        the world's arrays, groups, particles,
                     _error, _add_group,             colliders, walls, a step's statistics,
                     _add_particles, _set_state,     the checks of a state
                     _add_collider, _move_collider,
                     _totals
     >>drive         pn_mpm_drive_particles,         particles driven rigidly (held,
                     _release_drive, _add_load,      translated, spun) and loads, applied by
                     _remove_load, _select_box,      explicit steps; selection by box;
                     _set_particles                  overwriting a state
     >>fill          pn_mpm_fill, _fill_count        particles in boxes, spheres, cylinders
                                                     and closed meshes
     >>stable-dt     pn_mpm_stable_dt                the explicit bound from the wave speed
     >>bin                                           implicit: quadratic B-spline stencils,
                                                     particles sorted by base node, the
                                                     active nodes
     >>transfer                                      implicit: P2G as a gather per node, G2P
                                                     per particle (APIC, or AFLIP), commit
     >>contact                                       domain walls and analytic colliders:
                                                     sticky, slip, separate with friction
     >>explicit      pn_mpm_step_explicit            symplectic Euler, MLS-MPM, the return
                                                     mapping after the F update (the
                                                     reference): a dense grid scattered in
                                                     particle order, 2D fixed corotated and
                                                     snow in vector lanes
     >>implicit      pn_mpm_group_set_energy         the incremental potential (PlasticityNet
                                                     Eqs. 3, 10, 11), its gradient, Hessian
                                                     product and CG; Taylor models and their
                                                     journal
     >>friction                                      lagged Coulomb friction of separating
                                                     contacts, the active set
     >>multigrid                                     the Hessian assembled on the active nodes,
                                                     a Galerkin hierarchy, coloured block
                                                     Gauss-Seidel: CG's V-cycle
     >>stress                                        the stress formulation: stresses as
                                                     unknowns, projected Gauss-Seidel
     >>implicit-step pn_mpm_step_implicit            the driver: a step's start, its passes
                                                     and contact rounds, the substep fallback
     >>advance       pn_mpm_advance                  a frame in as many steps as it needs
     >>fem                                           (PN_NO_FEM leaves out every room from
                                                     here on) the mesh's internals, messages
     >>fem-mesh      pn_fem_grid_mesh,               the structured mesh builder; linear to
                     _quadratic_mesh                 quadratic
     >>fem-create    pn_fem_create, _destroy,        reference shapes, masses, boundary, RCM
                     _error, _group_set_energy       order, solver storage
     >>fem-nodes     pn_fem_fix_nodes, _spin_nodes,  held and driven nodes
                     _release_nodes
     >>fem-obstacles pn_fem_add_obstacle             analytic obstacles, box-simplex test
     >>fem-energy                                    per-element F, energy, F0 preparation
     >>fem-linear                                    skyline Cholesky; block IC(0) PCG; the
                                                     Hessian's storage
     >>fem-contact                                   IPC barrier against obstacles and between
                                                     boundary primitives, CCD
     >>fem-objective                                 the incremental potential and its
                                                     derivatives
     >>fem-step      pn_fem_stable_dt,               what both steps share; the explicit step
                     pn_fem_step_explicit
     >>fem-implicit  pn_fem_step_implicit,           projected Newton, CCD-filtered line
                     pn_fem_energy                   search, friction, moving obstacles
     >>fem-io        pn_fem_parse_msh, _tetgen,      Gmsh and TetGen loaders
                     pn_fem_mesh_data_free
     >>couple        pn_coupled_create, _destroy,    the coupled object and its storage
                     _error
     >>couple-barrier  pn_coupled_min_distance       particle-mesh pairs, barrier, CCD
     >>couple-friction                               lagged Coulomb friction at the interface
     >>couple-implicit pn_coupled_step_implicit      one Newton over grid velocities and mesh
                                                     positions
     >>couple-explicit pn_coupled_step_explicit,     both explicit, forces exchanged as loads
                     pn_coupled_stable_dt

   OPTIONS (define before including the implementation; plastinet.h's apply too)
     macro                          default  effect
     PN_NO_FEM                      off      leaves out PART II (FEM) and PART III (coupling):
                                             a game that simulates only particles compiles
                                             38% less code (gcc -O2, x86-64)
     PN_FEM_CHOLESKY_MAX_MB         1024     PN_FEM_LINEAR_DEFAULT factors by skyline
     PN_FEM_CHOLESKY_MAX_GFLOP_2D   4        Cholesky while its factor stays under these
     PN_FEM_CHOLESKY_MAX_GFLOP_3D   8        (storage, work per factorization), PCG beyond
     -fopenmp (compiler flag)       off      particle and node loops on threads (THREADS)

   QUICK START (README.md has it as a complete program)
       pn_mpm_desc wd;  pn_mpm_fill_desc f;  pn_mpm_world *w;  pn_material sand;  size_t n;  char why[256];
       memset(&wd, 0, sizeof wd);                            // zeroed fields mean defaults
       wd.dim = 2; wd.res[0] = wd.res[1] = 64; wd.dx_m = 1.0 / 64; wd.gravity[1] = -9.81;
       wd.boundary = PN_BOUNDARY_SEPARATE; wd.friction = 0.5;
       memset(&f, 0, sizeof f);                              // a block of sand
       f.shape = PN_MPM_FILL_BOX; f.center_m[0] = 0.5; f.center_m[1] = 0.2;
       f.half_extent_m[0] = 0.1; f.half_extent_m[1] = 0.1;
       pn_mpm_fill_count(&wd, &f, &n, NULL, 0);  wd.max_particles = n;
       pn_mpm_create(&wd, &w, why, sizeof why);             // why: the field at fault
       f.group = pn_mpm_add_group(w, &sand, 1600);           // material, density kg/m^3
       pn_mpm_fill(w, &f, NULL);                             // pn_mpm_error(w) says why not
       pn_mpm_advance(w, 1.0 / 60, NULL, NULL);              // a frame: stable explicit steps
       pn_mpm_step_implicit(w, 1e-3, NULL, NULL);            // or one implicit step
       pn_mpm_destroy(w);

   MEMORY: pn_mpm_create allocates every array through the allocator of the desc (both
   callbacks or neither) for max_particles particles and the grid; the first implicit step
   allocates the solver storage; after that a step allocates nothing.
   WORK: an implicit step sorts the particles by grid node, and an explicit one marks the
   blocks of 4^dim nodes they occupy; both work only on the nodes the stencils touch.
   WALLS act at their planes, origin + wall_cells dx and origin + (res - wall_cells) dx:
   no particle ends a step beyond one (one that would leave the grid went through: outflow
   or an error).
   ERRORS: every call that fails returns its pn_result and leaves the world as it was, and
   pn_mpm_error(w) says why in a sentence naming the field, particle, group or capacity at
   fault (pn_mpm_create, which has no world yet, through its why argument). A step that
   meets a non-finite value, an invalid state, material that would move more than
   advection_limit cells or leave through a wall (PN_ERROR_STEP_TOO_LARGE,
   PN_ERROR_OUTSIDE_DOMAIN) or (implicit) a solve that does not converge after the fallback
   names the particle in pn_mpm_world.error_particle and leaves the world exactly as it was
   before the step (the new state is built in scratch arrays and swapped in), down to what
   only later steps read (PlasticityNet's Taylor models, the multigrid's lag): the next steps
   are those of a world that never tried the failed one. No step
   returns PN_OK with material lost: outflow is an error unless allow_outflow is set.
   THREADS: compile with -fopenmp to run the particle and node loops on OpenMP threads
   (worlds of at least desc.parallel_min_particles particles, 4096 by default; smaller ones
   stay on one thread, where a parallel region costs more than its work).
   Results are bitwise identical for any thread count: particle-to-grid is a gather over
   particles sorted by node (implicit) or a scatter in particle order where each thread adds
   only to its own slab of rows (explicit): no atomics, a fixed summation order; every
   reduction sums fixed-size chunks in a fixed order. FEM meshes of at least 512 elements
   evaluate each element's energy, stress, Hessian, F0 preparation and return mapping on
   threads into per-element slots, then sum and assemble in element order. One world or
   mesh must not be stepped from two threads at once; different ones may.
   DETERMINISM: as for plastinet.h: with -ffp-contract=off (and without -ffast-math) gcc,
   g++ and clang give the same bits at any -O level for every integrator and energy
   (tests/cross_compiler.sh).
*/
#ifndef PLASTINET_MPM_H
#define PLASTINET_MPM_H
#ifndef PLASTINET_H
#error "include plastinet.h first"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ######################################################################################
   SHARED by MPM and FEM: how a wall or collider acts, analytic colliders, the energy an
   implicit step minimizes, a group (material, density, energy)
   ###################################################################################### */

typedef enum pn_boundary {
    PN_BOUNDARY_STICKY = 0,  /* velocity equals the obstacle's                           */
    PN_BOUNDARY_SLIP,        /* normal velocity equals the obstacle's, tangential free   */
    PN_BOUNDARY_SEPARATE     /* only approaching normal velocity removed; Coulomb friction */
} pn_boundary;

typedef enum pn_shape {
    PN_SHAPE_HALF_SPACE = 0, /* solid where (x - center) . normal < 0                     */
    PN_SHAPE_BOX,            /* axis-aligned, |x_i - center_i| < half_extent_i            */
    PN_SHAPE_SPHERE          /* |x - center| < radius (a disk in 2D)                      */
} pn_shape;

/* An analytic collider: an MPM world's (pn_mpm_add_collider) or an FEM mesh's obstacle
   (pn_fem_add_obstacle) */
typedef struct pn_collider {
    pn_shape shape;
    pn_boundary boundary;
    pn_real friction;            /* Coulomb coefficient (SEPARATE), >= 0                    */
    pn_real center_m[3];         /* at t = 0; a point of the plane for a half-space          */
    pn_real normal[3];           /* half-space: points out of the solid; need not be unit    */
    pn_real half_extent_m[3];    /* box                                                      */
    pn_real radius_m;            /* sphere                                                   */
    pn_real velocity_m_s[3];     /* the shape translates: center(t) = center + t velocity    */
} pn_collider;

/* The energy the implicit integrator minimizes for a group (the explicit one always uses the
   analytic return mapping). */
typedef enum pn_energy {
    PN_ENERGY_DEFAULT = 0,   /* elastic for PN_PLASTIC_NONE, else lagged                */
    PN_ENERGY_ELASTIC,       /* psi_el(F): plasticity ignored inside the solve          */
    PN_ENERGY_LAGGED,        /* psi_el(F G), G = F0^-1 Z(F0): the no-network baseline   */
    PN_ENERGY_EXACT_VM,      /* exact StVK-Hencky + von Mises energy (no fixed point)   */
    PN_ENERGY_PNET,          /* PlasticityNet (set with pn_mpm_group_set_energy)         */
    PN_ENERGY_DP             /* Drucker-Prager with the yield stress frozen at F0
                                    (pn_dp_energy): plastic shear free within the step      */
} pn_energy;

/* A group of particles or elements: one material, density and implicit energy */
typedef struct pn_group {
    pn_material material;
    pn_real density_kg_m3;
    pn_energy energy;
    pn_pnet pnet;                /* PN_ENERGY_PNET only                                 */
} pn_group;

/* ######################################################################################
   PART I: MPM (pn_mpm_*): a world of particles on a background grid
   ###################################################################################### */

#define PN_MPM_MAX_GROUPS 16
#define PN_MPM_MAX_COLLIDERS 16
#define PN_MPM_MAX_DRIVES 16 /* pn_mpm_drive_particles */
#define PN_MPM_MAX_LOADS 16  /* pn_mpm_add_load */

/* World description; zeroed fields mean defaults where one is stated. The domain is the box
   origin + [0, res_i dx]^dim; its walls are wall_cells thick, so material lives in
   origin + [wall dx, (res_i - wall) dx] on each axis. */
typedef struct pn_mpm_desc {
    int dim;                     /* 2 or 3                                                  */
    int res[3];                  /* grid cells per axis, 8 .. 16384                         */
    pn_real dx_m;                /* cell size (m) > 0                                       */
    pn_real origin_m[3];         /* the domain's lowest corner (m) [0]                      */
    pn_real gravity[3];          /* m/s^2                                                   */
    pn_boundary boundary;    /* domain walls                                            */
    pn_real friction;            /* Coulomb coefficient of SEPARATE walls, >= 0             */
    pn_real filter_time_s;       /* time scale of the transfer filter, >= 0 [0: APIC]. APIC
                                    filters the particle velocities at every grid round trip,
                                    a loss per step, so its damping per simulated second grows
                                    as dt shrinks and results do not converge in dt (near
                                    walls that hold material, noticeably). > 0: each step keeps
                                    the FLIP share 1 - s of the particle's own velocity change,
                                    s = min(1, dt / filter_time_s) (AFLIP, Fei et al. 2021, with
                                    the same filtering per simulated second at any dt)     */
    int wall_cells;              /* thickness of the walls in cells; 0 = 3                  */
    size_t max_particles;        /* capacity, > 0                                           */
    size_t parallel_min_particles; /* with -fopenmp: the particle loops of a world with fewer
                                    particles run on one thread [4096; 1: always parallel] */
    int allow_outflow;           /* nonzero: a particle that passes through a wall is retired
                                    (inactive, counted in left_domain). 0: such a step fails
                                    with PN_ERROR_OUTSIDE_DOMAIN and the world is unchanged
                                    (implicit steps first retry as substeps) [0]            */
    pn_real advection_limit;     /* the most a particle may move in one step, in cells: a
                                    step that would move one further fails with
                                    PN_ERROR_STEP_TOO_LARGE, world unchanged (implicit steps
                                    first retry as substeps; pn_mpm_advance picks steps that
                                    respect it) [1]                                          */
    pn_allocator allocator;
    /* optional: a clock (seconds, any origin, e.g. clock_gettime's CLOCK_MONOTONIC) that
       implicit steps read between their stages to fill pn_mpm_stats.stage_s; NULL: not
       measured (the library itself reads no clock) */
    double (*clock_s)(void *user);
    void *clock_user;
} pn_mpm_desc;

/* Analytic collider: grid nodes inside it take its velocity as the boundary says. */
/* How the implicit step solves each Newton system (conjugate gradients, preconditioned). */
typedef enum pn_mpm_linear_solver {
    PN_MPM_LINEAR_DEFAULT = 0,   /* Jacobi for systems of fewer than 4096 unknowns (about
                                    2000 active nodes in 2D), where assembling costs more
                                    than the CG iterations it saves; above, multigrid in 2D;
                                    in 3D, where a particle's Hessian spreads over 27 x 27
                                    node pairs, Jacobi until its solves take more than 200
                                    CG iterations per Newton iteration (or one stops at
                                    cg_max), then multigrid, Jacobi tried again every 16
                                    steps (docs/results.md#multigrid-preconditioned-newton) */
    PN_MPM_LINEAR_JACOBI,        /* matrix-free products over the particles, Jacobi (diagonal)
                                    preconditioner: no assembly; iterations grow like
                                    dt / dt_CFL                                              */
    PN_MPM_LINEAR_MULTIGRID      /* the Hessian assembled on the active nodes, one V-cycle of a
                                    Galerkin hierarchy with block Gauss-Seidel smoothing per
                                    iteration: iterations nearly independent of dt / dt_CFL  */
} pn_mpm_linear_solver;

/* What an implicit step solves for (pn_mpm_implicit_desc.formulation). */
typedef enum pn_mpm_formulation {
    PN_MPM_FORMULATION_ENERGY = 0, /* the grid velocities, by Newton on the incremental
                                    potential of each group's pn_energy                 */
    PN_MPM_FORMULATION_STRESS      /* each particle's stress as well: elasticity enters as a
                                    compliance and plasticity as the return mapping of the
                                    stress, so plastic flow within the step is exact (Daviet
                                    and Bertails-Descoubes 2016); solved by projected
                                    Gauss-Seidel over the particles and the contact nodes.
                                    StVK-Hencky groups, elastic or Drucker-Prager (sand),
                                    and Neo-Hookean snow, elastic or Cam-Clay (snow);
                                    PN_ERROR_UNSUPPORTED for other materials                */
} pn_mpm_formulation;

/* Where the stress formulation's stresses live (pn_mpm_implicit_desc.stress_unknowns). A cell:
   the particles that share a stencil base node and a material group, whose stress is solved
   as one (their volume average); each keeps its own F, moved by the cell's velocity
   gradient (method.md, stress formulation). */
typedef enum pn_mpm_stress_unknowns {
    PN_MPM_STRESS_PARTICLES = 0, /* one per particle, as the explicit step has them          */
    PN_MPM_STRESS_CELLS,         /* one per cell: 4x (2D) to 8x (3D) fewer unknowns, cheaper
                                    sweeps and over-relaxation; a coarser stress field, which
                                    costs accuracy (docs/results.md#where-the-stresses-live) */
    PN_MPM_STRESS_CELLS_THEN_PARTICLES /* the cells to 10 sweep_tol first, then the particles
                                    from their stresses: the per-particle solution, faster
                                    on stiff material and large piles, slower on soft
                                    material (docs/results.md#where-the-stresses-live)       */
} pn_mpm_stress_unknowns;

/* Implicit step settings; zeroed fields mean the defaults in brackets. */
typedef struct pn_mpm_implicit_desc {
    int fixed_point_iters;       /* passes of the F0 fixed point (PlasticityNet Eq. 10) [1]:
                                    at equal cost a smaller step with one pass is the better
                                    buy (docs/notebook.md, "a smaller step beats more passes") */
    int newton_max;              /* Newton iterations per pass [50]                          */
    int cg_max;                  /* conjugate-gradient iterations per Newton step [500]      */
    pn_real newton_tol;          /* stop when max |dv| < newton_tol dx / dt [1e-5]: about
                                    newton_tol dx of position error per step               */
    pn_real cg_rel_tol;          /* relative residual of the linear solve, the tightest one
                                    with forcing [1e-3]                                      */
    pn_real cg_forcing_max;      /* > cg_rel_tol (e.g. 0.5): after a minimization's first
                                    solve, each is only as tight as the last step's linear
                                    model proved right (Eisenstat-Walker forcing), between
                                    cg_rel_tol and this; a solve that would stop Newton is
                                    finished to cg_rel_tol. Pays where the energy has kinks
                                    (DP; docs/notebook.md, "optional Eisenstat-Walker
                                    forcing") [0: off, every solve to cg_rel_tol]           */
    int contact_rounds;          /* solves per pass while separating contact changes its
                                    stick / slip / release set; 1: the set is corrected once
                                    per pass, for the next one (lagged, like the friction
                                    impulse) [1]                                            */
    /* optional trace: called at every Newton iteration with the incremental potential E (J)
       at the current iterate and max |dv| dt / dx of the step it takes next; `solve` counts
       the minimizations of the step (each fixed-point pass, contact round and substep starts
       a new one, with a new objective) */
    void (*trace)(void *user, int solve, int iteration, pn_real energy_j, pn_real residual);
    void *trace_user;
    int max_halvings;            /* a step that fails is retried as 2, 4, ... substeps, at
                                    most this many halvings [3]; < 0: never                 */
    int newton_budget;           /* Newton iterations one call may spend over its attempts
                                    and substeps; when they are spent the step fails
                                    (PN_ERROR_NOT_CONVERGED, world unchanged) instead of
                                    retrying on [newton_max fixed_point_iters contact_rounds
                                    2^max_halvings: what the deepest level may take, half
                                    of what every level taken in full would]                */
    int measure_force_error;     /* nonzero: at each converged step, compare the energy's
                                    force density with the return mapping's T(F) (one return
                                    mapping per particle; see pn_mpm_stats.force_error)    */
    pn_mpm_linear_solver linear_solver; /* [PN_MPM_LINEAR_DEFAULT]                         */
    int mg_levels;               /* multigrid: at most this many grid levels, the finest
                                    included [8]; 1: symmetric Gauss-Seidel alone           */
    int pnet_double;             /* nonzero: PlasticityNet evaluated one particle at a time in
                                    pn_real (pn_pnet_energy, the reference); 0: its network
                                    over blocks of PN_MLP_LANES particles in float vector
                                    lanes (pn_pnet_energy_lanes), faster (docs/results.md#implicit-steps) [0] */
    int mg_rebuild;              /* multigrid: when the hierarchy is built. 0: at each solve's
                                    first Newton iteration; the later ones precondition with
                                    it (lagged: CG multiplies by their own Hessian over the
                                    particles) unless that took 1.5 times the CG iterations
                                    of the fresh one, after which every Newton iteration
                                    builds its own (tried again every 16 steps); 1: at every
                                    Newton iteration [0]                                    */
    pn_mpm_formulation formulation; /* [PN_MPM_FORMULATION_ENERGY]                          */
    pn_real pnet_reuse_tol;      /* PlasticityNet in lanes: while a particle's F stays within
                                    this (largest entry of the change) of where its network
                                    last gave a Hessian, its energy, stress and Hessian come
                                    from the second-order Taylor model there (stress error
                                    of order tol^2 E), and while its F0 moves less than this
                                    its prepared point is kept, so material at rest costs no
                                    network evaluation (docs/method.md, "Reusing the
                                    network") [0: 1e-5, the strain Newton's own tolerance
                                    leaves; < 0: off]                                       */
    int sweeps_max;              /* STRESS: Gauss-Seidel sweeps per step (per phase of
                                    PN_MPM_STRESS_CELLS_THEN_PARTICLES); a step that has not
                                    converged by then fails (PN_ERROR_NOT_CONVERGED, then
                                    the substeps) [1000]                                     */
    pn_real sweep_tol;           /* STRESS: converged when the velocity error left, estimated
                                    from the last sweep's change and the rate of the last two
                                    (res rho / (1 - rho)), is below sweep_tol dx / dt, nodes
                                    lighter than the mean particle weighted by their mass
                                    [1e-4]                                                   */
    pn_mpm_stress_unknowns stress_unknowns; /* STRESS: where the stresses live
                                    [PN_MPM_STRESS_PARTICLES]                                */
    pn_real cell_relax;          /* STRESS, cells: over-relaxation of the cells' Gauss-Seidel
                                    updates, in [1, 2) [0: 1 with Anderson acceleration, which
                                    over-relaxed sweeps throw off; 1.8 without]              */
    pn_real energy_rise_tol;     /* a step whose mechanical energy (kinetic, elastic, and
                                    gravitational above the domain's floor) rises by more than
                                    this share of it fails (PN_ERROR_STEP_TOO_LARGE, then the
                                    substeps): a solve that converged to a wrong answer (a
                                    learned energy driven far from its data) launches
                                    material, and backward Euler only ever takes energy
                                    away. Not checked while a collider moves (its work is not
                                    counted). Costs two elastic energies per particle [0:
                                    0.25 for FORMULATION_ENERGY, off for FORMULATION_STRESS,
                                    whose steps only lose energy; < 0: never; > 0: this
                                    tolerance for either]                                    */
    int coarse_every;            /* STRESS, particles, elastic material: a coarse correction
                                    (the step's linearized problem in the velocities, solved
                                    by multigrid-preconditioned CG) after every this many
                                    sweeps, so the sweeps needed stop growing with the
                                    grid's width and dt / dt_CFL (docs/method.md, "the
                                    coarse correction"); not taken while any group is
                                    plastic, nor with linear_solver JACOBI [0: 4; < 0:
                                    never]                                                   */
    int coarse_cg;               /* STRESS: CG iterations per coarse correction, at most [50] */
    pn_real coarse_tol;          /* STRESS: its CG's relative tolerance [1e-3]              */
    int anderson;                /* STRESS: Anderson acceleration of the sweeps (each sweep's
                                    result combined with the one before, so that the change
                                    left is least; docs/method.md, "Anderson acceleration")
                                    [0: on; < 0: off]                                        */
} pn_mpm_implicit_desc;

/* The stages of an implicit step (pn_mpm_stats.stage_s, with pn_mpm_desc.clock_s). */
typedef enum pn_mpm_stage {
    PN_MPM_STAGE_SETUP = 0,      /* binning, particle-to-grid, contact                        */
    PN_MPM_STAGE_ENERGY,         /* every particle's energy, its derivatives and preparation
                                    (PlasticityNet's network: here); the stress formulation's
                                    start stresses                                         */
    PN_MPM_STAGE_LINEAR,         /* Hessian assembly, multigrid hierarchy, CG                 */
    PN_MPM_STAGE_SWEEPS,         /* the stress formulation's Gauss-Seidel sweeps              */
    PN_MPM_STAGE_G2P,            /* grid-to-particle, return mapping, energy guard            */
    PN_MPM_STAGES
} pn_mpm_stage;

/* Statistics of the last step (of a failed implicit step: its first attempt). */
typedef struct pn_mpm_stats {
    size_t particles;            /* active particles                                         */
    size_t plastic;              /* particles the return mapping projected                   */
    size_t left_domain;          /* particles deactivated this step for leaving the domain   */
    size_t active_nodes;         /* grid nodes that carried work                             */
    pn_real max_speed_m_s;       /* largest particle speed after the step                    */
    /* implicit steps (totals over the step and its substeps) */
    int substeps;                /* 1, or 2^k after k halvings (the fallback)                */
    int fixed_point_iters, newton_iters, cg_iters;
    int active_set_rounds;       /* re-solves after separating contact changed its set
                                    (contact_rounds > 1)                                    */
    int line_search_failures;    /* Newton steps whose line search found no decrease        */
    int cg_capped;               /* Newton steps whose linear solve stopped at cg_max short
                                    of its tolerance: never counted as converged (a step
                                    whose last one was fails, PN_ERROR_NOT_CONVERGED)       */
    int solves;                  /* minimizations (passes x contact rounds x substeps)      */
    int mg_builds;               /* multigrid hierarchies built (assemblies of the Hessian) */
    pn_real newton_residual;     /* largest final max |dv| dt / dx over the passes           */
    pn_real fixed_point_residual;/* largest max_q |F0_new - F0| at the last pass             */
    /* measure_force_error only: over the particles of plastic groups, at the solution,
       sum V |dPsi/dF(F) - T(F)| / sum V |T(F)|, T the return mapping's force density (how far
       the minimized energy is from the plastic forces it stands for; 0 for an exact energy),
       the part of it the PlasticityNet regularizer makes (sum V |w mu (F - F0)| over the
       same denominator), and the share of those particles where T = 0 (sand at the
       Drucker-Prager apex: in tension, free to separate). Largest over substeps; -1 when off
       (and for explicit steps).                                                            */
    pn_real force_error, force_error_regularizer, apex_fraction;
    /* the step over the explicit bound pn_mpm_stable_dt at its start: how many explicit
       steps one implicit step stands for (pn_mpm_advance: the largest of its steps; -1 for
       an explicit step taken alone, which does not compute the bound)                      */
    pn_real dt_over_cfl;
    int sweeps;                  /* FORMULATION_STRESS: Gauss-Seidel sweeps                  */
    int anderson_steps;          /* STRESS: sweeps whose result Anderson acceleration moved   */
    int coarse_corrections, coarse_rejected; /* STRESS: coarse corrections taken, and those
                                    undone for leaving the velocities worse              */
    pn_real energy_rise;         /* implicit: the step's change of mechanical energy over its
                                    size at the start (pn_mpm_implicit_desc.energy_rise_tol;
                                    the largest over substeps); 0 when not checked           */
    double stage_s[PN_MPM_STAGES]; /* implicit, with pn_mpm_desc.clock_s: seconds in each
                                    pn_mpm_stage, of the attempt that succeeded (all its
                                    substeps); else 0                                       */
} pn_mpm_stats;

/* >>drive: a rigidly driven set of particles, and a load (internal) */
typedef struct pn__mpm_drive {
    size_t n, *idx;              /* the particles, and their positions at t0 (dim each)      */
    pn_real *x0, t0, center[3], vel[3], omega[3];
    int on;                      /* 0: released                                               */
} pn__mpm_drive;
typedef struct pn__mpm_load {
    size_t n, *idx;
    pn_real acc[3], t_end;       /* the acceleration force / mass, until t_end (inf: always)  */
    int on;
} pn__mpm_load;

/* >>multigrid: one grid level of the implicit Hessian (internal) */
#define PN__MPM_EXPLICIT_MAX 4 /* explicit steps beyond this many times the wave-speed bound are refused */
#define PN__MPM_MG_MAX 8     /* most grid levels                                               */
#define PN__MPM_MG_DENSE 192 /* the coarsest level is factored (Cholesky) up to these unknowns */
#define PN__MPM_MG_MIN 4096  /* PN_MPM_LINEAR_DEFAULT: multigrid from this many unknowns, where
                                it overtakes Jacobi (docs/results.md#multigrid-preconditioned-newton) */
#define PN__MPM_JACOBI_MAX 200 /* PN_MPM_LINEAR_DEFAULT, 3D: Jacobi while its solves take at most
                                this many CG iterations per Newton iteration (the same place) */
typedef struct pn__mpm_level {
    int nn[3];                   /* nodes per axis (level l + 1: nn_l / 2 + 1)                */
    size_t stride[3], nodes;     /* flat node = sum idx_a stride_a                             */
    size_t n, cap;               /* rows (the level's active nodes) and the arrays' room       */
    size_t *node;                /* row -> flat node, ascending (level 0: act)                 */
    long *dof;                   /* flat node -> row or -1 (level 0: dof)                      */
    unsigned char *mark;
    long *nbr;                   /* per row: the rows at offsets -2..2 per axis, -1 if none    */
    float *A;                    /* per row: a dim x dim block per neighbour, in float: the
                                    V-cycles and CG's products stream them (125 blocks a row
                                    in 3D), and neither the preconditioner nor Newton's linear
                                    model needs more digits; assembled in pn_real            */
    pn_real *Dinv;               /* per row: the diagonal block's (pseudo-)inverse           */
    pn_real *x, *b, *r;          /* V-cycle vectors                                            */
    size_t *crow, cstart[28];    /* rows by colour (node index mod 3 per axis)                 */
} pn__mpm_level;

/* The solver's own state: stencils, the compact and dense grids, contact, the implicit
   solver's storage and hierarchy, the Taylor models and their journal, drives and loads.
   Private: read and written only by the library (pn_mpm_world.s). */
typedef struct pn__mpm_solver {
    int wall;                    /* the walls' thickness in cells                           */
    size_t nodes, stride[3];     /* grid nodes; flat node = sum idx_a stride_a               */
    int ns, slot[27][3];         /* stencil size 3^dim and its offsets per axis             */
    size_t slot_off[27];         /* flat node offset of each stencil slot                   */
    pn__mpm_drive drives[PN_MPM_MAX_DRIVES]; /* >>drive: pn_mpm_drive_particles, pn_mpm_add_load */
    pn__mpm_load loads[PN_MPM_MAX_LOADS];
    int n_drives, n_loads;
    long newton_left;            /* implicit: Newton iterations the current call may still take */
    /* >>bin: stencils, sort, active nodes */
    size_t *pbase;               /* flat index of each particle's stencil base node          */
    pn_real *pw, *pfx;           /* per axis: 3 weights and x/dx - base                      */
    size_t *order, *start;       /* particles sorted by base node; start[node] into order    */
    size_t *act, n_act;          /* active nodes, ascending                                  */
    long *dof;                   /* node -> index into act, or -1                            */
    unsigned char *mark;
    /* compact grid (index into act) and per-particle scratch */
    pn_real *grid_m, *grid_v, *grid_v0; /* grid_v0: velocity of the transfer alone (AFLIP) */
    pn_real *pmat, *pscal, *part;
    int *pstat;
    pn_real *sx, *sv, *sC, *sF, *sh;
    unsigned char *sactive;
    /* contact per active node: held directions and the obstacle's velocity */
    unsigned char *cn, *ckind, *chold;
    pn_real *cdir, *cvel, *cmu, *clam, *ctan;
    /* implicit solver storage, allocated by the first implicit step */
    pn_real *vstar, *vsol, *vtry, *grad, *dir, *cg_r, *cg_z, *cg_p, *cg_q, *diag;
    pn_real *pP, *pH, *pG, *phG, *pF0, *pty;
    pn_pnet_point *ppt;
    /* per step (>>implicit setup), by sorted index j (particle order[j], j = prank[p]):
       q_js = F^nT g_ps (>>implicit) for each stencil slot s and the slot's compact node; each active
       node's (j, slot) incidences in the fixed gather order. The Hessian product then
       touches no spline and no sort, and reads neighbours from nearby memory. */
    pn_real *pq;
    pn_real *pb;                 /* >>stress by cell: sum V_p g_ps over the cell's particles,
                                    at its first particle's sorted index (allocated by the
                                    first such step)                                          */
    long *pdof;
    size_t *inc, *inc_start, *prank;
    size_t *sgrp;                /* >>stress: the colour groups, then each particle's cell (5 cap) */
    pn_real *ptau;               /* >>stress, the coarse correction: stresses before it, energies (cap (dim^2 + 1)) */
    pn_real *paa;                /* >>stress, Anderson acceleration: per unknown the last sweep's
                                    result and change, four sums (cap (2 dim^2 + 4))             */
    size_t *paai;                /* >>stress, Anderson acceleration: the unknowns' storage (cap) */
    pn_real *bx, *bv, *bC, *bF, *bh; /* the state before a step that falls back             */
    unsigned char *bactive;
    /* contact memory of the last implicit step: the nodes a separating contact held, ascending,
       as node << 3 | the directions held (bit b: the node's obstacle direction b), and their
       normal force L/dt (N; negative: the node stuck). Only the directions held: holding
       every direction of a lagged node slowed a block sliding away from a side wall
       (docs/notebook.md, "walls: the sheet on the plane"). */
    size_t *lnode, *blnode, n_lag, bn_lag;
    pn_real *lval, *blval;
    /* >>explicit: the dense grid, its touched spans and the P2G records */
    size_t nblk[3], bstride[3], nblocks; /* blocks of PN__MPM_BLOCK^dim nodes                */
    unsigned char *bmark;        /* blocks holding a particle's stencil base node this step  */
    size_t *bact, n_bact;        /* the blocks P2G touched: marked ones and their upper neighbours */
    size_t *rowcount;            /* particles per stencil base row of axis 0 (the thread slabs) */
    pn_real *gdense;             /* (m, m v) per node, 4 reals (2D: one unused, for SIMD)     */
    pn_real *gdense0;            /* the transfer's own momentum per node (AFLIP only), dim reals */
    pn_real *ppay, *spay;        /* P2G record of each particle's state (and scratch)        */
    int *prow, *srow;            /* stencil base row (axis 0) of each particle (and scratch) */
    int rec_ok;                  /* ppay belongs to the current state                        */
    /* >>implicit-step: the Kirchhoff stress of each particle's state, upper triangle (the
       implicit G2P's return mapping makes it with Z, from the same SVD), so that the next stress
       step starts without another SVD. ctau serves the state when ctau_ok; the G2P writes stau
       (stau_state: for every active particle), which a successful call swaps in. */
    pn_real *ctau, *stau;
    int ctau_ok, stau_state, stau_committed;
    /* >>stress: each sorted particle j's volume and plastic state (pjvh, 2 reals) and group
       (pjg), so that a sweep reads them in its own order */
    pn_real *pjvh;
    int *pjg;
    pn_real inv_dx, grid_lo[3], grid_hi[3]; /* 1 / dx; [0.75 dx, (res - 0.75) dx] + origin (>>world) */
    pn_real wall_lo[3], wall_hi[3]; /* the wall planes [wall dx, (res - wall) dx] + origin   */
    /* >>multigrid: the assembled Hessian and its hierarchy (implicit, linear_solver MULTIGRID) */
    pn__mpm_level mg[PN__MPM_MG_MAX];
    int mg_max, mg_levels, mg_on; /* levels the grid allows, built, in use this step         */
    int mg_current;              /* the finest level is this Newton iteration's Hessian     */
    int pnet_lanes;              /* implicit: PlasticityNet in float lanes this step         */
    int full_h, curv;            /* implicit: the particles' Hessians unprojected (Newton near
                                    its minimum); the last CG met negative curvature         */
    pn_real reuse_tol;           /* implicit: pn_mpm_implicit_desc.pnet_reuse_tol this step
                                    (0: off)                                                */
    /* >>implicit, PlasticityNet's Taylor models: where the network was last evaluated with
       its Hessian (tF), its energy density, P and unprojected dP/dF there, all at the
       point ppt; tok: the model is valid (cleared when the point is prepared anew) */
    pn_real *tF, *tpsi, *tP, *tH;
    unsigned char *tok;
    /* >>implicit, the models as the call found them (pn__mpm_touch): a failed call puts them
       back, so what it tried leaves no trace in later steps. jst: 0 untouched this call, 1
       saved without a model, 2 saved with one (jF, jpsi, jP, jH, jpH, jppt) */
    pn_real *jF, *jpsi, *jP, *jH, *jpH;
    pn_pnet_point *jppt;
    unsigned char *jst;
    int mg_stale;                /* a lagged hierarchy cost too many CG iterations lately    */
    int lin_auto;                /* this step's solver is LINEAR_DEFAULT's 3D choice, which
                                    may move to multigrid within the step                   */
    int lin_mg;                  /* LINEAR_DEFAULT in 3D: Jacobi cost too many CG iterations
                                    per Newton iteration lately, so multigrid               */
    double clock_last;           /* pn_mpm_desc.clock_s at the last stage mark                */
    int stress_on;               /* this implicit step is FORMULATION_STRESS: pq holds g, not
                                    F^nT g (>>stress); 2: by cells, whose L makes F          */
    size_t mg_dense_n;           /* unknowns of the factored coarsest level (0: smoothed)      */
    pn_real *mg_dense;
    /* >>couple: forces on particles xf_idx[0 .. xf_n) (N, dim each in xf) for the next
       explicit step only (pn_coupled_step_explicit sets them and clears them after) */
    const size_t *xf_idx;
    const pn_real *xf;
    size_t xf_n;
} pn__mpm_solver;

/* The world. Particle arrays (structure of arrays, read-only for users): x, v (dim per
   particle), C (affine velocity, dim^2), F (elastic deformation gradient, dim^2), h (plastic
   state), vol0 (initial volume m^3), mass (kg), group, active. A step builds the new state in
   scratch arrays and swaps them in, so x, v, C, F, h and active point elsewhere after every
   step: read w->x after the step, never keep the pointer across one. Particle p keeps its
   index for the life of the world. Everything a user reads is here; s is the solver's. */
typedef struct pn_mpm_world {
    pn_mpm_desc desc;            /* as given, defaults resolved                              */
    int dim;                     /* 2 or 3                                                   */
    size_t n, cap;               /* particles (active or retired) and max_particles          */
    pn_real *x, *v, *C, *F, *h, *vol0, *mass;
    int *group;
    unsigned char *active;
    pn_group groups[PN_MPM_MAX_GROUPS];
    int n_groups;
    pn_collider colliders[PN_MPM_MAX_COLLIDERS];
    int n_colliders;
    pn_real time_s;              /* simulated time (s)                                       */
    long steps;                  /* steps taken                                              */
    long error_particle;         /* particle that made the last step fail (-1: none)         */
    size_t left_total;           /* particles deactivated for leaving the domain, in total  */
    char error[256];             /* why the last call failed (pn_mpm_error)                 */
    pn__mpm_solver s;            /* private                                                  */
} pn_mpm_world;

/* Create a world (*out set on success). PN_ERROR_DIMENSION for a dim other than 2 or 3 (or
   compiled out); PN_ERROR_INVALID_ARGUMENT for res outside 8 .. 16384, walls that leave no
   room, dx <= 0, a non-finite origin or gravity, friction < 0, capacity 0, a bad boundary or
   half an allocator, a negative or non-finite filter_time_s or advection_limit;
   PN_ERROR_OUT_OF_MEMORY if an allocation fails (nothing leaks). On failure why (optional)
   names the field. */
PN_API pn_result pn_mpm_create(const pn_mpm_desc *desc, pn_mpm_world **out, char *why, size_t why_cap);
PN_API void pn_mpm_destroy(pn_mpm_world *w);

/* Why the last failed call on w failed: the field, particle, group or capacity at fault and
   what to do, in one sentence ("" after a success). Valid until the next call on w. */
PN_API const char *pn_mpm_error(const pn_mpm_world *w);

/* Add a particle group of one material and density; returns its index, or -1 (the reason in
   pn_mpm_error: PN_MPM_MAX_GROUPS reached, a density that is not positive and finite, or a
   material pn_material_check refuses). */
PN_API int pn_mpm_add_group(pn_mpm_world *w, const pn_material *m, pn_real density_kg_m3);

/* Add n particles of group g at positions x (dim per particle, m), velocities v (NULL: at
   rest), each of volume volume_m3, F = I, h = the material's initial state (0; for Cam-Clay
   set it with pn_mpm_set_state). All or nothing: PN_ERROR_NONFINITE,
   PN_ERROR_INVALID_ARGUMENT (outside the walls, bad group, a volume or mass that is not
   positive and finite) or PN_ERROR_CAPACITY (more than max_particles), with the world
   unchanged, error_particle naming the first bad one and pn_mpm_error saying why. Most
   programs use pn_mpm_fill instead. */
PN_API pn_result pn_mpm_add_particles(pn_mpm_world *w, int g, size_t n, const pn_real *x,
                                      const pn_real *v, pn_real volume_m3);

/* ---- scene helpers: fill shapes with particles ------------------------------------------ */

typedef enum pn_mpm_fill_shape {
    PN_MPM_FILL_BOX = 0,         /* |x_i - center_i| <= half_extent_i                       */
    PN_MPM_FILL_SPHERE,          /* |x - center| <= radius (a disk in 2D)                   */
    PN_MPM_FILL_CYLINDER,        /* |(x - center) . axis| <= half_length and the distance
                                    from the axis <= radius (in 2D: a rotated rectangle)   */
    PN_MPM_FILL_MESH             /* inside a closed, consistently oriented triangle mesh
                                    (3D) or polygon (2D: edges as index pairs)              */
} pn_mpm_fill_shape;

/* What to fill and how; zeroed fields mean the defaults in brackets. */
typedef struct pn_mpm_fill_desc {
    pn_mpm_fill_shape shape;
    int group;                   /* the particles' group (pn_mpm_add_group)                 */
    pn_real center_m[3];         /* box, sphere, cylinder                                   */
    pn_real half_extent_m[3];    /* box                                                      */
    pn_real radius_m;            /* sphere, cylinder                                         */
    pn_real axis[3];             /* cylinder, need not be unit [the y axis]                  */
    pn_real half_length_m;       /* cylinder                                                 */
    const pn_real *vertices_m;   /* mesh: dim reals per vertex                               */
    size_t n_vertices;
    const int *indices;          /* mesh: dim vertex indices per element (3D triangles with
                                    outward normals by the right-hand rule; 2D edges a -> b
                                    with the inside on the left, i.e. counter-clockwise)   */
    size_t n_elements;
    int per_axis;                /* particles per cell along each axis: per_axis^dim per cell
                                    [2: 4 in 2D, 8 in 3D]                                   */
    int jitter;                  /* nonzero: each particle moves to a random point of its
                                    lattice cell (deterministic from seed) [0: lattice]    */
    unsigned long seed;          /* jitter's seed [0]                                        */
    pn_real velocity_m_s[3];     /* initial velocity [0]                                     */
    pn_real state;               /* initial plastic state h [0] (pn_mpm_set_state)          */
    int clip;                    /* nonzero: the part outside the walls is left out [0: a
                                    shape that reaches beyond the walls is refused, naming
                                    a point of it outside]                                  */
} pn_mpm_fill_desc;

/* Fill a shape with particles of group f->group: the points of a lattice of spacing dx /
   per_axis aligned with the grid (so shapes that touch neither overlap nor leave gaps) that
   fall inside the shape, each of volume (dx / per_axis)^dim and mass volume x density. The
   sampled volume converges to the shape's as the lattice refines: its error is at most the
   volume of the band of half a lattice diagonal about the surface, about area x spacing x
   sqrt(dim) / 2 (0 for a box aligned with the lattice). *added (optional) gets the count.
   All or nothing, as pn_mpm_add_particles; PN_ERROR_CAPACITY says how many are needed. */
PN_API pn_result pn_mpm_fill(pn_mpm_world *w, const pn_mpm_fill_desc *f, size_t *added);

/* How many particles pn_mpm_fill would add to a world of description wd (to size
   max_particles before creating it). PN_ERROR_INVALID_ARGUMENT for a bad shape (why). */
PN_API pn_result pn_mpm_fill_count(const pn_mpm_desc *wd, const pn_mpm_fill_desc *f, size_t *count,
                                   char *why, size_t why_cap);

/* The largest explicit step (s) the current state allows:
       dt = 0.9 dx / max_p (c_p + |v_p|),   c_p = sqrt(K_p / rho_p),
   K_p the particle's P-wave modulus (lambda + 2 mu, stiffened by compression: divided by J,
   times the hardening of Stomakhin snow), rho_p its current density. The factor 0.9 is
   measured: on sand, rubber, snow and metal scenes in 2D and sand and rubber in 3D the
   largest step found stable by search was above this one (scene_stable_dt in
   tests/test_scene.c; docs/results.md#scene-helpers-step-bounds-and-errors). Without
   particles, the groups' materials at rest.
   PN_ERROR_INVALID_ARGUMENT without groups. */
PN_API pn_result pn_mpm_stable_dt(const pn_mpm_world *w, pn_real *dt_s);

/* ---- stepping a frame ------------------------------------------------------------------- */

typedef enum pn_mpm_integrator {
    PN_MPM_EXPLICIT = 0,         /* symplectic Euler at pn_mpm_stable_dt                      */
    PN_MPM_IMPLICIT              /* optimization time integration at max_step_s              */
} pn_mpm_integrator;

typedef struct pn_mpm_advance_desc {
    pn_mpm_integrator integrator;
    pn_real max_step_s;          /* implicit: the longest step [1e-3]; explicit: an upper
                                    bound besides pn_mpm_stable_dt [none]                    */
    pn_real courant;             /* explicit: the fraction of pn_mpm_stable_dt taken [1]     */
    const pn_mpm_implicit_desc *implicit; /* NULL: the defaults                              */
} pn_mpm_advance_desc;

/* Advance the world by frame_s seconds in as many steps as it takes: each explicit step at
   the stable step of the current state, each implicit step at most max_step_s and short
   enough that no particle moves more than advection_limit cells (from the fastest particle
   and gravity; a step that still would is retried as substeps). stats (optional) gets the
   totals, stats->substeps the number of steps. On failure the world is as it was after the
   last step that succeeded, and pn_mpm_error says why. desc may be NULL (explicit). */
PN_API pn_result pn_mpm_advance(pn_mpm_world *w, pn_real frame_s, const pn_mpm_advance_desc *desc,
                                pn_mpm_stats *stats);

/* Set the plastic state h of particles first .. first + n - 1 (e.g. Cam-Clay log Jp < 0 for
   snow with strength). PN_ERROR_NONFINITE / PN_ERROR_INVALID_ARGUMENT with nothing changed. */
PN_API pn_result pn_mpm_set_state(pn_mpm_world *w, size_t first, size_t n, const pn_real *h);

/* Add a collider (copied; *index optional). PN_ERROR_INVALID_ARGUMENT for a full list, a bad
   shape or boundary, non-finite or non-positive sizes, a zero half-space normal or a
   negative friction. */
PN_API pn_result pn_mpm_add_collider(pn_mpm_world *w, const pn_collider *c, int *index);

/* Move collider `index` (a mouse-driven pusher, a kinematic body driven by a game): from now
   (w->time_s) it is at center_m and translates at velocity_m_s (NULL: at rest). The velocity
   is what contact imposes on the material it holds, so pass the collider's real velocity
   (displacement since the last frame / frame time) to push material rather than teleport
   through it. PN_ERROR_INVALID_ARGUMENT for a bad index, PN_ERROR_NONFINITE for NaN or inf. */
PN_API pn_result pn_mpm_move_collider(pn_mpm_world *w, int index, const pn_real *center_m,
                                      const pn_real *velocity_m_s);

/* ---- driven particles and loads (explicit steps) ------------------------------------------ */

/* Drive particles rigidly (a wall a body is attached to, the clamped ends of a bar under
   tension and torsion, a moving lid): from now (w->time_s = t0) particle p follows
   x_p(t) = c(t) + R(t) (x_p(t0) - c(t0)), c(t) = center_m + (t - t0) velocity_m_s, R(t) the
   rotation by angular_velocity_rad_s (dim = 3: the axis times the rate, right-handed; 2D: [2]
   is the rate about z) times (t - t0). NULL velocity or angular velocity: zero (held in
   place); center_m may be NULL without rotation. Each explicit step sets the grid nodes
   the driven particles touch to the rigid motion's velocity (their reaction holds the rest
   of the body), then puts the driven particles at their exact x_p(t) with the rigid
   velocity and velocity gradient. n particles by index, each active and in no other drive;
   *index (optional) names the drive for pn_mpm_release_drive. PN_ERROR_CAPACITY beyond
   PN_MPM_MAX_DRIVES, PN_ERROR_NONFINITE / PN_ERROR_INVALID_ARGUMENT naming the culprit, with
   nothing changed; PN_ERROR_OUT_OF_MEMORY. Implicit steps refuse a world with a drive
   (PN_ERROR_UNSUPPORTED). */
PN_API pn_result pn_mpm_drive_particles(pn_mpm_world *w, size_t n, const size_t *particles,
                                        const pn_real *velocity_m_s, const pn_real *center_m,
                                        const pn_real *angular_velocity_rad_s, int *index);

/* Let drive `index` go: its particles move freely from the next step, at the velocity they
   have. Releasing a released drive is a no-op. */
PN_API pn_result pn_mpm_release_drive(pn_mpm_world *w, int index);

/* Apply force_N (dim reals, in total) to n particles for duration_s from now (0: until
   pn_mpm_remove_load), shared in proportion to their masses: a poke, a hand, a thruster.
   Each explicit step adds m_p a dt to the momentum the particle scatters, a = force / (the
   particles' mass). Errors as pn_mpm_drive_particles (PN_MPM_MAX_LOADS). */
PN_API pn_result pn_mpm_add_load(pn_mpm_world *w, size_t n, const size_t *particles, const pn_real *force_N,
                                 pn_real duration_s, int *index);
PN_API pn_result pn_mpm_remove_load(pn_mpm_world *w, int index);

/* The active particles inside the box lo .. hi (dim reals each, m): their indices, ascending,
   into out (room for cap), *count how many there are (may exceed cap: then out holds the
   first cap). For pn_mpm_drive_particles and pn_mpm_add_load. */
PN_API pn_result pn_mpm_select_box(const pn_mpm_world *w, const pn_real *lo, const pn_real *hi, size_t *out,
                                   size_t cap, size_t *count);

/* Overwrite the kinematic state of particles first .. first + n - 1 (to restore a checkpoint,
   or set an initial motion): x, v (dim reals each), C (the affine velocity, dim^2), F (dim^2);
   a NULL array keeps those values. time_s >= 0 sets w->time_s (negative: unchanged). All or
   nothing: PN_ERROR_NONFINITE, PN_ERROR_INVALID_ARGUMENT (outside the walls, a particle that
   does not exist), naming the particle. */
PN_API pn_result pn_mpm_set_particles(pn_mpm_world *w, size_t first, size_t n, const pn_real *x, const pn_real *v,
                                      const pn_real *C, const pn_real *F, pn_real time_s);

/* One explicit step of dt_s seconds (symplectic Euler, APIC or AFLIP, return mapping after the F
   update). On failure the world is unchanged and w->error_particle names the culprit. A step
   more than 4x the wave-speed bound (pn_mpm_stable_dt with the material at rest) is refused
   at once with PN_ERROR_STEP_TOO_LARGE; a particle whose x was written by hand into NaN or
   beyond the grid, with PN_ERROR_NONFINITE or PN_ERROR_OUTSIDE_DOMAIN. */
PN_API pn_result pn_mpm_step_explicit(pn_mpm_world *w, pn_real dt_s, pn_mpm_stats *stats);

/* Choose the energy group g's particles use in implicit steps. PN_ENERGY_PNET needs net
   (a bound pn_pnet for the group's material, copied). PN_ERROR_INVALID_ARGUMENT or
   PN_ERROR_UNSUPPORTED (exact von Mises or DP for another material) otherwise. */
PN_API pn_result pn_mpm_group_set_energy(pn_mpm_world *w, int g, pn_energy energy,
                                         const pn_pnet *net);

/* One implicit step (optimization time integration, PlasticityNet Eqs. 3, 10, 11): the
   velocities of the active grid nodes minimize
       E(v) = 1/2 |v - v*|_M^2 + sum_p V_p Psi_p(F_p(v))
   by Newton with PSD-projected per-particle Hessians, Jacobi-preconditioned conjugate
   gradients filtered by the contact constraints, and a backtracking (Armijo) line search,
   stopping when max |dv| < newton_tol dx / dt (positions then carry about newton_tol dx of
   solver error per step; long runs at small steps may want it tighter). F_p(v) = (I + dt
   C_p(v)) F_p^n with C the APIC (MLS) velocity gradient of the explicit step, so the two
   integrators share one discretization in space. Around it the fixed point on F0 = F(v) and the
   plastic state. Contact: sticky and slip hold velocity components at the obstacle's;
   separate holds the normal component while the contact pushes and sticks (all components
   held) or slides against the Coulomb force mu L t, L the normal impulse at the start of the
   pass; the set is corrected after each solve (an active set; contact_rounds re-solves).
   The state update (APIC, return mapping) follows as in the explicit step. A step that
   fails (an error, a non-finite value, Newton short of 100 newton_tol, or a last linear
   solve stopped at cg_max) is retried as two half steps, then four, up to max_halvings
   times; stats->substeps says so. The first call allocates the solver storage
   (PN_ERROR_OUT_OF_MEMORY possible); later calls allocate nothing. On failure the world is
   unchanged and stats describe the first attempt. desc may be NULL. */
PN_API pn_result pn_mpm_step_implicit(pn_mpm_world *w, pn_real dt_s, const pn_mpm_implicit_desc *desc,
                                      pn_mpm_stats *stats);

/* Total mass (kg) and momentum (kg m/s) of the active particles. */
PN_API void pn_mpm_totals(const pn_mpm_world *w, pn_real *mass, pn_real *momentum);

#ifndef PN_NO_FEM
/* ######################################################################################
   PART II: FEM (pn_fem_*): meshes of linear triangles and tetrahedra (PN_NO_FEM: left out
   with PART III)
   ###################################################################################### */

/* ======================================================================================
   FEM: triangles (2D) and tetrahedra (3D), linear or quadratic, with the same materials,
   energies and return mappings as the particle groups, incremental-potential contact (IPC,
   Li et al. 2020) against analytic obstacles, an explicit and an implicit integrator.
   Positions are the unknowns; F = sum_a x_a grad N_a at each integration point (linear
   elements: one, F = Ds(x) Dm^-1), F = Fe Fp with Fp^-1 and h stored per point.
   ====================================================================================== */

#define PN_FEM_MAX_GROUPS 16
#define PN_FEM_MAX_OBSTACLES 16


/* Mesh description; zeroed fields mean the defaults in brackets. Elements are positively
   oriented: det [x1 - x0, x2 - x0 (, x3 - x0)] > 0 (counter-clockwise triangles). */
typedef struct pn_fem_desc {
    int dim;                     /* 2 (triangles; plane strain, per metre of thickness) or 3 */
    size_t n_nodes, n_elements;
    const pn_real *rest_m;       /* dim reals per node: the rest (and start) positions      */
    const int *elements;         /* per element its corners, then with order 2 one node per
                                    edge (Gmsh's order: triangles 01 12 20, tetrahedra 01 12
                                    20 30 32 31): 3 / 4 nodes (order 1), 6 / 10 (order 2)  */
    int order;                   /* 1: linear elements, one integration point (stiff in
                                    bending: a beam needs many through its depth); 2:
                                    quadratic, 3 / 4 points, HRZ-lumped masses (mid-edge
                                    nodes may sit off the edge's middle: curved elements);
                                    contact sees each quadratic side as 2 segments (2D) or
                                    4 triangles (3D) through its nodes [0: 1]; or build a
                                    quadratic mesh from a linear one: pn_fem_quadratic_mesh */
    const int *element_group;    /* per element, into groups [NULL: all group 0]            */
    const pn_group *groups;  /* materials; energy and pnet as for pn_mpm_group_set_energy */
    int n_groups;                /* 1 .. PN_FEM_MAX_GROUPS                                  */
    pn_real gravity[3];          /* m/s^2                                                   */
    pn_real contact_distance_m;  /* IPC's dhat: the barrier acts at distances below it
                                    [1e-3 of the rest bounding box diagonal]               */
    pn_real contact_stiffness;   /* IPC's kappa (Pa m^(dim - 2)): the barrier energy is kappa
                                    b(d) per node [0: 0.1 E l^(dim - 1) / dhat, E the
                                    stiffest material's, l the mean edge: docs/method.md]   */
    pn_real friction_velocity_m_s; /* IPC's epsilon_v: Coulomb friction (each obstacle's
                                    pn_collider.friction) is smoothed below this sliding
                                    speed, a stick that creeps at most that fast [1e-3]      */
    pn_allocator allocator;
    double (*clock_s)(void *user); /* optional, as pn_mpm_desc.clock_s                       */
    void *clock_user;
} pn_fem_desc;

/* Obstacles: half-spaces and boxes of pn_collider (shape, center_m, normal,
   half_extent_m, velocity_m_s: translating at a constant velocity; friction: the Coulomb
   coefficient; boundary is not used: contact is the barrier's). */

/* How an implicit FEM step solves each Newton system. */
typedef enum pn_fem_linear_solver {
    PN_FEM_LINEAR_DEFAULT = 0,   /* Cholesky while its factor is small (PN_FEM_CHOLESKY_MAX_MB of
                                    storage, PN_FEM_CHOLESKY_MAX_GFLOP_2D or _3D per
                                    factorization), PCG beyond: the factorization's cost
                                    grows as unknowns^7/3 in 3D, PCG's step about linearly
                                    (where each wins on the metal frame:
                                    docs/results.md#against-the-issues-bars-make-bench-fem) */
    PN_FEM_LINEAR_CHOLESKY,      /* skyline Cholesky in a reverse Cuthill-McKee order: exact, its
                                    storage grows as unknowns x profile (3D: about n^5/3)   */
    PN_FEM_LINEAR_PCG            /* conjugate gradients preconditioned by a block incomplete
                                    Cholesky, IC(0) on the node blocks: storage linear in the
                                    mesh, iterations grow with its resolution               */
} pn_fem_linear_solver;
#ifndef PN_FEM_CHOLESKY_MAX_MB
#define PN_FEM_CHOLESKY_MAX_MB 1024
#endif
#ifndef PN_FEM_CHOLESKY_MAX_GFLOP_2D
#define PN_FEM_CHOLESKY_MAX_GFLOP_2D 4
#endif
#ifndef PN_FEM_CHOLESKY_MAX_GFLOP_3D
#define PN_FEM_CHOLESKY_MAX_GFLOP_3D 8
#endif

typedef struct pn_fem_implicit_desc {
    int fixed_point_iters;       /* passes of the F0 fixed point (lagged, PlasticityNet) [1] */
    int newton_max;              /* Newton iterations per minimization [100]                */
    pn_real newton_tol;          /* stop when max |dx| < newton_tol l dt-free: l the mean
                                    rest edge length (quadratic elements: half, the nodes'
                                    spacing; pn_fem_mesh.edge_mean) [1e-5]                  */
    int max_halvings;            /* a failed step is retried as 2, 4, .. substeps [5; < 0:
                                    none]                                                   */
    pn_fem_linear_solver linear_solver; /* [PN_FEM_LINEAR_DEFAULT]                          */
    pn_real cg_rel_tol;          /* PCG: the relative residual of each Newton solve [1e-6]  */
    int cg_max;                  /* PCG: iterations per Newton solve [5000]                 */
    /* optional trace: called at every Newton iteration with the incremental potential E at
       the iterate and max |dx| / l of the step it takes next; `solve` counts the
       minimizations of the step (each fixed-point pass, augmented-Lagrangian round and
       substep minimizes a new objective) */
    void (*trace)(void *user, int solve, int iteration, pn_real energy_j, pn_real residual);
    void *trace_user;
} pn_fem_implicit_desc;

typedef struct pn_fem_stats {
    int substeps, newton_iters, factorizations, fixed_point_iters, line_search_failures;
    int al_iters;                /* augmented-Lagrangian rounds moving the obstacles        */
    int friction_relags;         /* re-solves with friction lagged at the solution, for nodes
                                    that came into contact with a rough obstacle in the step */
    int solves;                  /* minimizations (passes x rounds x substeps)              */
    int cg_iters;                /* conjugate-gradient iterations (PCG; with Cholesky,
                                    self-contact pairs beyond the factor's profile make the
                                    solve iterative)                                       */
    pn_fem_linear_solver linear_solver; /* what the step used: CHOLESKY or PCG           */
    pn_real newton_residual;     /* max |dx| / l at the last Newton iteration               */
    pn_real min_distance_m;      /* the smallest node-obstacle distance at the step's end
                                    (and over its line searches: never <= 0)                */
    size_t plastic;              /* integration points the return mapping projected (linear
                                    elements: one each)                                    */
    pn_real dt_over_cfl;         /* the step over pn_fem_stable_dt                          */
    pn_real kappa;               /* the barrier stiffness used                              */
} pn_fem_stats;

typedef struct pn_fem_mesh {
    pn_fem_desc desc;            /* the arrays of desc are not kept                          */
    int dim;
    size_t n_nodes, n_elems;
    int order, nodes_per_element, points_per_element; /* 1, dim + 1, 1 or 2, 6 / 10, 3 / 4 */
    size_t n_points;             /* integration points: n_elems x points_per_element; element
                                    e's are e * points_per_element ..                       */
    pn_real *x, *v, *X;          /* positions, velocities, rest positions (dim per node)    */
    pn_real *mass;               /* lumped node mass (kg; per metre in 2D)                  */
    int *elem, *egroup;          /* nodes_per_element node indices per element; its group   */
    pn_real *Dm_inv, *vol0;      /* per point: the inverse of the rest Jacobian dX/dxi (dim^2;
                                    linear elements: Ds(X)^-1), its share of the rest volume */
    pn_real *Fp_inv, *h;         /* per point: inverse plastic deformation, plastic state   */
    pn_group groups[PN_FEM_MAX_GROUPS];
    int n_groups;
    unsigned char *fixed;        /* per node: 0 free, 1 driven (held: velocity 0), 2 spun    */
    pn_real *drive;              /* per node: the driven velocity (dim reals)                */
    pn_real *spin;               /* per node: the spin's centre (3 reals), angular velocity (3) */
    pn_collider obstacles[PN_FEM_MAX_OBSTACLES];
    int n_obstacles;
    pn_real time_s, dhat, kappa, edge_mean; /* edge_mean: of the rest edges (quadratic: half) */
    long steps;
    long error_element, error_node; /* the culprit of the last failure, -1: none             */
    char error[256];
    void *impl;                  /* solver storage (internal)                               */
} pn_fem_mesh;

/* Create a mesh. All or nothing: PN_ERROR_DIMENSION, PN_ERROR_INVALID_ARGUMENT (an index out
   of range, a degenerate or inverted element, no groups, a bad group index or density, half
   an allocator), PN_ERROR_NONFINITE (a coordinate), PN_ERROR_OUT_OF_MEMORY; why (optional,
   why_cap bytes) names the element or node at fault. */
PN_API pn_result pn_fem_create(const pn_fem_desc *desc, pn_fem_mesh **out, char *why, size_t why_cap);
PN_API void pn_fem_destroy(pn_fem_mesh *m);
PN_API const char *pn_fem_error(const pn_fem_mesh *m);

/* The energy implicit steps use for group g (as pn_mpm_group_set_energy). */
PN_API pn_result pn_fem_group_set_energy(pn_fem_mesh *m, int g, pn_energy energy, const pn_pnet *net);

/* Nodes held (velocity NULL) or driven at a constant velocity (dim reals); n nodes by index. */
PN_API pn_result pn_fem_fix_nodes(pn_fem_mesh *m, size_t n, const int *nodes, const pn_real *velocity_m_s);

/* Nodes driven in a rigid rotation about the axis through center_m (dim reals) at
   angular_velocity_rad_s (3 reals: the axis times the rate, right-handed; 2D uses [2], the
   rate about z): each step moves them along the exact arc. */
PN_API pn_result pn_fem_spin_nodes(pn_fem_mesh *m, size_t n, const int *nodes, const pn_real *center_m,
                                   const pn_real *angular_velocity_rad_s);

/* Let held, driven or spun nodes go: they move freely from the next step, at the velocity
   they had. */
PN_API pn_result pn_fem_release_nodes(pn_fem_mesh *m, size_t n, const int *nodes);

/* Add an obstacle (a half-space or a box; copied). Every node must be outside it, further
   than nothing, and a box must not reach into an element between its nodes (the barrier acts
   on nodes): PN_ERROR_INVALID_ARGUMENT names the node or element. A step after which a box
   reaches into an element (a coarse element over a small box) fails with
   PN_ERROR_UNSUPPORTED, the mesh unchanged. */
PN_API pn_result pn_fem_add_obstacle(pn_fem_mesh *m, const pn_collider *c, int *index);

/* The largest explicit step the mesh allows: 0.5 l / c over the elements (l the smallest
   altitude, c the P-wave speed), and with obstacles: a quarter of each node's distance to
   each over their speeds added, and sqrt(m_i / (kappa b''(d_i))) over the nodes within dhat
   of an obstacle (the barrier's spring). */
PN_API pn_result pn_fem_stable_dt(const pn_fem_mesh *m, pn_real *dt_s);

/* One explicit step: symplectic Euler with the barrier's force, the return mapping after
   the position update. PN_ERROR_STEP_TOO_LARGE (mesh unchanged) if a node would reach an
   obstacle or an element invert. */
PN_API pn_result pn_fem_step_explicit(pn_fem_mesh *m, pn_real dt_s, pn_fem_stats *stats);

/* One implicit step: the nodal positions minimize
       1/2 |x - x~|_M^2 + dt^2 (sum_e V_e Psi_e(Fe(x)) + kappa sum b(d(x)) + D(x))
   (b over node-obstacle distances and the mesh's own boundary pairs: 2D point-edge, 3D
   point-triangle and edge-edge; D lagged smoothed friction against rough obstacles) by
   Newton (PSD-projected element Hessians; the linear solver of desc->linear_solver: a
   skyline Cholesky factorization in a reverse Cuthill-McKee order, or conjugate gradients
   preconditioned by its block incomplete Cholesky on large meshes) with a backtracking line search whose first step no node can take
   into an obstacle or through the mesh (continuous collision detection); moving obstacles
   follow their velocity by an augmented Lagrangian; friction is lagged again where a node
   came into contact during the step. Then the return mapping of each element. A step that
   fails is retried as substeps; the mesh is unchanged when it fails. The first step with a
   solver (or with more moving obstacles than before) allocates its storage: with Cholesky
   on a mesh too large for it PN_ERROR_OUT_OF_MEMORY, the message says so. */
PN_API pn_result pn_fem_step_implicit(pn_fem_mesh *m, pn_real dt_s, const pn_fem_implicit_desc *desc,
                                      pn_fem_stats *stats);

/* Structured meshes for tests and examples: the cells of an nx x ny (x nz) grid over the
   box lo + [0, size], without those inside the hole (a box in the same frame; a zero size:
   none), each square split into 2 triangles (4 with crossed) or each cube into 6
   tetrahedra (conforming). With nodes / elements NULL, only counts. */
typedef struct pn_fem_grid {
    int dim, cells[3];
    pn_real lo_m[3], size_m[3];
    pn_real hole_lo_m[3], hole_size_m[3];
    int crossed;                 /* 2D: four triangles per square around a node at its centre
                                    (crossed diagonals), which do not lock under incompressible
                                    (von Mises) plastic flow as two per square do (Nagtegaal,
                                    Parks and Rice 1974) [0: two, the diagonal alternating]  */
    pn_allocator allocator;      /* for the builder's scratch                                */
} pn_fem_grid;
PN_API pn_result pn_fem_grid_mesh(const pn_fem_grid *g, pn_real *nodes, int *elements, size_t *n_nodes,
                                  size_t *n_elements);

/* A quadratic mesh (pn_fem_desc.order 2) from a linear one: the corners keep their indices,
   a node at the middle of each edge follows them, and each element lists its corners, then
   its edge nodes in pn_fem_desc's order. nodes_out (dim reals per node) and elements_out
   ((dim + 1)(dim + 2) / 2 per element) NULL: only the count *n_nodes_out. Scratch from al
   (NULL: malloc). PN_ERROR_INVALID_ARGUMENT for a node index out of range. */
PN_API pn_result pn_fem_quadratic_mesh(int dim, const pn_real *nodes, size_t n_nodes, const int *elements,
                                       size_t n_elements, const pn_allocator *al, pn_real *nodes_out, int *elements_out,
                                       size_t *n_nodes_out);

/* Meshes from files users have, parsed from memory (read the file yourself): Gmsh ASCII .msh
   of versions 2.2 and 4.1 (3-node triangles, type 2, for dim 2; 4-node tetrahedra, type 4, for
   dim 3; or their quadratic kinds, 6-node triangles, type 9, and 10-node tetrahedra, type 11:
   order 2, in pn_fem_desc's node order, which is Gmsh's; a file with both kinds is refused;
   other element types skipped; x, y of each node in 2D) and TetGen .node / .ele (3D; 10-node
   tetrahedra keep their corners). Elements are reordered to positive
   orientation; element_tags holds Gmsh's physical tag or TetGen's region attribute (0 when
   none). The arrays are allocated through al (NULL: malloc): free them with
   pn_fem_mesh_data_free. A file that does not parse is refused with PN_ERROR_FORMAT and why
   names its line (and the node or element); nothing is allocated then. Pass the arrays to
   pn_fem_desc (rest_m = nodes, elements, element_group from element_tags as you map them). */
typedef struct pn_fem_mesh_data {
    int dim, order;              /* order 1 (dim + 1 nodes per element) or 2 (pn_fem_desc.order) */
    size_t n_nodes, n_elements;
    pn_real *nodes;
    int *elements, *element_tags;
} pn_fem_mesh_data;
PN_API pn_result pn_fem_parse_msh(const char *text, size_t len, int dim, const pn_allocator *al, pn_fem_mesh_data *out,
                                  char *why, size_t why_cap);
PN_API pn_result pn_fem_parse_tetgen(const char *node_text, size_t node_len, const char *ele_text, size_t ele_len,
                                     const pn_allocator *al, pn_fem_mesh_data *out, char *why, size_t why_cap);
PN_API void pn_fem_mesh_data_free(pn_fem_mesh_data *d, const pn_allocator *al);

/* Total elastic energy of the elements' Fe and kinetic energy of the nodes (J; per metre of
   thickness in 2D). PN_ERROR_INVERTED for an element the elastic energy is undefined at. */
PN_API pn_result pn_fem_energy(const pn_fem_mesh *m, pn_real *elastic_j, pn_real *kinetic_j);

/* ######################################################################################
   PART III: COUPLING (pn_coupled_*): an MPM world and an FEM mesh in one step
   ###################################################################################### */

/* ======================================================================================
   COUPLING: an MPM world and an FEM mesh stepped together (BFEMP, Li, Fang, Li and Jiang
   2021). They meet through an IPC barrier between every particle and the mesh's boundary
   (2D edges, 3D triangles), so they never interpenetrate: particle p's barrier is
   kappa_p b(d), b(d) = -(d - dhat)^2 ln(d / dhat) below dhat, kappa_p = k a_p / dhat with
   a_p = V_p^((dim - 1) / dim) the particle's share of a surface. In an implicit step d is
   measured from where the step puts the particle, y_p = x_p + dt sum_i w_ip v_i (its APIC
   update, BFEMP's grid-interpolated position), to the mesh at its new positions; in an
   explicit step from the positions at the step's start. Friction at the interface is
   Coulomb's, lagged and smoothed as IPC's (below friction_velocity_m_s it creeps).
   Several bodies go into one mesh (their contact with each other is the mesh's own). The
   coupled object borrows the world and the mesh: step them only through it while it
   lives, and destroy it before them.
   ====================================================================================== */
typedef struct pn_coupled_desc {
    pn_real contact_distance_m;  /* dhat [0: a quarter of the world's dx]                   */
    pn_real contact_stiffness;   /* k (Pa) [0: 0.1 E, E the stiffest particle group's]      */
    pn_real friction;            /* the Coulomb coefficient at the interface [0]            */
    pn_real friction_velocity_m_s; /* IPC's epsilon_v: below this sliding speed friction is
                                    smoothed (a stick creeps at most that fast) [1e-2: fewer
                                    Newton iterations than 1e-3 on the drop scene;
                                    docs/notebook.md, "the time gap"]                       */
} pn_coupled_desc;

typedef struct pn_coupled_implicit_desc {
    pn_mpm_implicit_desc mpm;    /* fixed_point_iters, newton_max, newton_tol (the step stops
                                    when max |dv| and max |dx| / dt over particles' nodes and
                                    mesh nodes are below newton_tol dx / dt), cg_max,
                                    cg_rel_tol (CG on the coupled system), cg_forcing_max
                                    (pays for the lagged energy in 3D, not for PlasticityNet,
                                    whose extra Newton iterations cost more than the CG
                                    saved: docs/notebook.md, "Session eight"), contact_rounds,
                                    linear_solver (the grid block's preconditioner),
                                    max_halvings, pnet_double, trace as for
                                    pn_mpm_step_implicit, with other defaults where the
                                    coupled system needs them: cg_max [1000] (pn_mpm_step_
                                    implicit: 500), cg_rel_tol [1e-3]; the energy
                                    formulation only                                        */
    pn_fem_linear_solver fem_linear_solver; /* the mesh block's preconditioner: its exact
                                    factor (Cholesky) or block IC (PCG) [DEFAULT]            */
    pn_real theta;               /* the theta method: the forces taken at theta of the way
                                    from the step's start to its end (all of them: both
                                    sides' elasticity, the interface). 1: backward Euler,
                                    which damps (a block's rebound off elastic sand); 0.5:
                                    the trapezoidal rule, second order and without that
                                    damping; in [0.5, 1] [0: 1]                             */
} pn_coupled_implicit_desc;

typedef struct pn_coupled_stats {
    int substeps, newton_iters, cg_iters, fixed_point_iters, line_search_failures, solves;
    size_t pairs;                /* particle-boundary pairs within dhat at the step's end    */
    pn_real min_distance_m;      /* the smallest particle-boundary distance the step met (its
                                    line searches and its end; explicit: the end; > 0)      */
    pn_real newton_residual;     /* max |dz| dt / dx at the last Newton iteration            */
    size_t plastic_particles, plastic_elements;
} pn_coupled_stats;

typedef struct pn_coupled {
    pn_mpm_world *mpm;
    pn_fem_mesh *fem;
    pn_real dhat, stiffness, friction, eps_v;
    long error_particle, error_node; /* the culprit of the last failure, -1: none           */
    char error[256];
    void *impl;
} pn_coupled;

/* Couple world w and mesh m (the same dim). PN_ERROR_DIMENSION; PN_ERROR_INVALID_ARGUMENT for
   a negative or non-finite field, or a particle inside the mesh or on its boundary (named);
   PN_ERROR_OUTSIDE_DOMAIN for a mesh node outside the world's walls (named);
   PN_ERROR_OUT_OF_MEMORY. why (optional) says why. The pair storage is reserved here, for the
   mesh's boundary at the particles' spacing: steps allocate nothing unless the contact grows
   far beyond that. */
PN_API pn_result pn_coupled_create(pn_mpm_world *w, pn_fem_mesh *m, const pn_coupled_desc *desc, pn_coupled **out,
                                   char *why, size_t why_cap);
PN_API void pn_coupled_destroy(pn_coupled *c); /* the world and mesh stay */
PN_API const char *pn_coupled_error(const pn_coupled *c);

/* The explicit bound: the smaller of the world's and the mesh's, and sqrt(m / (kappa_p b''))
   over the pairs within dhat (the barrier's spring, m the lighter side's mass). */
PN_API pn_result pn_coupled_stable_dt(pn_coupled *c, pn_real *dt_s);

/* One explicit step of both at dt_s: each first takes the barrier's and friction's forces
   at the step's start (the world through its particles' momentum, the mesh on its nodes),
   then steps as pn_mpm_step_explicit and pn_fem_step_explicit do. PN_ERROR_STEP_TOO_LARGE
   if a particle would cross the boundary within the step (continuous collision detection);
   on failure both are as they were. */
PN_API pn_result pn_coupled_step_explicit(pn_coupled *c, pn_real dt_s, pn_coupled_stats *stats);

/* One implicit step of both: the grid velocities v and the mesh's positions x minimize
       E_mpm(v) + E_fem(x) / dt^2 + sum kappa_p b(d(y_p(v), x)) + D(v, x)
   (E_mpm as pn_mpm_step_implicit, E_fem as pn_fem_step_implicit over dt^2, D the lagged
   interface friction) by one Newton iteration over both: CG on the whole Hessian,
   preconditioned by each side's own solver, and a line search that starts at the largest
   step continuous collision detection allows. Around it the fixed point on F0 of both
   sides and the world's wall contact rounds. Refused: drives or loads on, moving mesh
   obstacles, the stress formulation (PN_ERROR_UNSUPPORTED). A failed step is retried as
   substeps; when none works both are as they were. */
PN_API pn_result pn_coupled_step_implicit(pn_coupled *c, pn_real dt_s, const pn_coupled_implicit_desc *desc,
                                          pn_coupled_stats *stats);

/* The smallest particle-boundary distance now (m; 1e30 when no particle is near the mesh). */
PN_API pn_result pn_coupled_min_distance(pn_coupled *c, pn_real *dist_m);

#endif /* PN_NO_FEM */

#ifdef __cplusplus
}
#endif
#endif /* PLASTINET_MPM_H */

#if defined(PLASTINET_IMPLEMENTATION) && !defined(PLASTINET_MPM_IMPLEMENTATION_DONE)
#define PLASTINET_MPM_IMPLEMENTATION_DONE
#ifndef PLASTINET_IMPLEMENTATION_DONE
#error "plastinet_mpm.h: the plastinet.h implementation must come first"
#endif
/* OpenMP loops that compile away (and do not warn) without -fopenmp. Each iteration writes
   only its own outputs, so the schedule cannot change a result. A world of fewer particles
   than desc.parallel_min_particles runs them on one thread: a parallel region costs more
   than its work there, and on a busy machine a thread waiting for a core stalls every one
   of the step's dozens of regions. Every use has the world in scope as w. */
#if defined(__SSE2__) || defined(__AVX__)
#include <immintrin.h> /* >>explicit: pn__mpm_sqrt_lanes */
#endif

#ifdef _OPENMP
#include <omp.h>
#define PN__OMP_FOR _Pragma("omp parallel for schedule(dynamic, 64) if(w->n >= w->desc.parallel_min_particles)")
#define PN__FEM_OMP_FOR _Pragma("omp parallel for schedule(dynamic, 64) if(m->n_elems >= 512)") /* >>fem, mesh m */
#else
#define PN__OMP_FOR
#define PN__FEM_OMP_FOR
#endif

#if defined(__GNUC__)
#define PN__MPM_INLINE static inline __attribute__((always_inline))
#else
#define PN__MPM_INLINE static inline
#endif

#define PN__MPM_BLOCK 4 /* >>explicit: nodes per block edge (>= 3: a stencil reaches one block up) */

#define PN__MPM_LANES 8 /* >>explicit: particles per batch of the 2D G2P */

#define PN__MPM_SLABS 256 /* >>explicit: the most threads P2G splits the rows among */

#define PN__MPM_PAY(d) ((d) == 2 ? 4 : 7) /* >>explicit: reals per P2G record */

/* >>explicit: entry k of particle p's record in buf: blocks of PN__MPM_LANES particles, entry
   by entry (the lanes of G2P and P2G load a block's entry as one vector) */
#define PN__MPM_REC(buf, p, k, pay)                                                               \
    ((buf)[((size_t)(p) / PN__MPM_LANES * (size_t)(pay) + (size_t)(k)) * PN__MPM_LANES + (size_t)(p) % PN__MPM_LANES])

#define PN__MPM_CHUNK 1024 /* reductions sum chunks of this size, then the chunks in order */

/* ======================================================================================
   >>group: a group's implicit energy (pn_mpm_group_set_energy, pn_fem_group_set_energy)
   checked one way for worlds and meshes
   ====================================================================================== */

/* A group's implicit energy (pn_mpm_group_set_energy, pn_fem_group_set_energy): checks net
   and the material; msg says why not. */
static pn_result pn__group_set_energy(pn_group *gr, int g, int dim, pn_energy energy, const pn_pnet *net,
                                      char *msg, size_t cap) {
    msg[0] = 0;
#define PN__MSG(...) pn__msg(msg, cap, __VA_ARGS__)
    if (energy < PN_ENERGY_DEFAULT || energy > PN_ENERGY_DP) {
        PN__MSG("energy %d is not a pn_energy", (int)energy);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    if (energy == PN_ENERGY_PNET) {
        const pn_material *a, *b = &gr->material;
        if (!net || !net->energy) {
            PN__MSG("PN_ENERGY_PNET needs a pn_pnet bound with pn_pnet_init");
            return PN_ERROR_INVALID_ARGUMENT;
        }
        if (net->energy->dim != dim) {
            PN__MSG("the network %s is %dD, the world %dD", net->energy->name ? net->energy->name : "", net->energy->dim, dim);
            return PN_ERROR_DIMENSION;
        }
        a = &net->material;
        /* the solve minimizes the network's energy, the state update return-maps the group's
           material: they must be the same material, or the two disagree */
        if (a->plastic != b->plastic || a->elastic != b->elastic || a->E != b->E || a->nu != b->nu ||
            a->sin_phi != b->sin_phi || a->cohesion_strain != b->cohesion_strain ||
            a->volume_correction != b->volume_correction || a->yield_stress != b->yield_stress ||
            a->hardening_modulus != b->hardening_modulus || a->beta != b->beta || a->xi != b->xi ||
            a->camclay_hardening != b->camclay_hardening) {
            PN__MSG("the network is bound to another material (E %g Pa, nu %g) than group %d's (E %g Pa, nu %g, or a "
                    "plastic parameter): bind it with pn_pnet_init to the group's material",
                    (double)a->E, (double)a->nu, g, (double)b->E, (double)b->nu);
            return PN_ERROR_INVALID_PARAMETER;
        }
    }
    if (energy == PN_ENERGY_EXACT_VM && (gr->material.plastic != PN_PLASTIC_VON_MISES ||
                                             gr->material.elastic != PN_ELASTIC_STVK_HENCKY)) {
        PN__MSG("EXACT_VM needs group %d to be StVK-Hencky + von Mises", g);
        return PN_ERROR_UNSUPPORTED;
    }
    if (energy == PN_ENERGY_DP && (gr->material.plastic != PN_PLASTIC_DRUCKER_PRAGER ||
                                       gr->material.elastic != PN_ELASTIC_STVK_HENCKY)) {
        PN__MSG("DP needs group %d to be StVK-Hencky + Drucker-Prager", g);
        return PN_ERROR_UNSUPPORTED;
    }
#undef PN__MSG
    if (energy == PN_ENERGY_PNET) gr->pnet = *net;
    gr->energy = energy;
    return PN_OK;
}

/* ======================================================================================
   >>world: creation (pn_mpm_create checks every desc field, then allocates every array
   once), groups, particles, colliders, the walls' planes, a step's statistics and the
   checks a step makes of the state it would commit (pn__mpm_first_error)
   ====================================================================================== */

static void *pn__mpm_alloc(const pn_mpm_desc *d, size_t count, size_t size, int *fail) {
    void *p;
    if (*fail) return NULL;
    p = pn_alloc(&d->allocator, count * size);
    if (!p) *fail = 1;
    else memset(p, 0, count * size);
    return p;
}

/* every array the world owns (X-macro: one list for destroy) */
#define PN__MPM_ARRAYS(X)                                                                       \
    X(x) X(v) X(C) X(F) X(h) X(vol0) X(mass) X(group) X(active) X(s.pbase) X(s.pw) X(s.pfx)    \
    X(s.order) X(s.start) X(s.act) X(s.dof) X(s.mark) X(s.grid_m) X(s.grid_v) X(s.grid_v0) X(s.pmat) X(s.pscal) X(s.part)        \
    X(s.pstat) X(s.sx) X(s.sv) X(s.sC) X(s.sF) X(s.sh) X(s.sactive) X(s.cn) X(s.ckind) X(s.chold) X(s.cdir) X(s.cvel)   \
    X(s.cmu) X(s.clam) X(s.ctan) X(s.vstar) X(s.vsol) X(s.vtry) X(s.grad) X(s.dir) X(s.cg_r) X(s.cg_z) X(s.cg_p) X(s.cg_q)      \
    X(s.diag) X(s.pP) X(s.pH) X(s.pG) X(s.phG) X(s.pF0) X(s.pty) X(s.ppt) X(s.tF) X(s.tpsi) X(s.tP) X(s.tH) X(s.tok) X(s.jF) X(s.jpsi) X(s.jP) X(s.jH) X(s.jpH) X(s.jppt) X(s.jst) X(s.pq) X(s.pb) X(s.sgrp) X(s.ptau) X(s.paa) X(s.paai) X(s.pdof) X(s.inc) X(s.inc_start) X(s.prank) X(s.bx) X(s.bv) X(s.bC) X(s.bF) X(s.bh) X(s.bactive)  \
    X(s.lnode) X(s.blnode) X(s.lval) X(s.blval) X(s.bmark) X(s.bact) X(s.rowcount) X(s.gdense) X(s.gdense0) X(s.ppay) X(s.spay) X(s.prow) X(s.srow) X(s.ctau) X(s.stau) X(s.pjvh) X(s.pjg)

PN__DEF void pn_mpm_destroy(pn_mpm_world *w) {
    pn_allocator a;
    if (!w) return;
    a = w->desc.allocator;
#define PN__MPM_FREE(f) pn_free(&a, w->f);
    PN__MPM_ARRAYS(PN__MPM_FREE)
#undef PN__MPM_FREE
    {
        int l;
        for (l = 0; l < w->s.n_drives; ++l) pn_free(&a, w->s.drives[l].idx), pn_free(&a, w->s.drives[l].x0);
        for (l = 0; l < w->s.n_loads; ++l) pn_free(&a, w->s.loads[l].idx);
        for (l = 0; l < PN__MPM_MG_MAX; ++l) {
            pn__mpm_level *L = &w->s.mg[l];
            void *m[] = {L->node, L->dof, L->mark, L->nbr, L->A, L->Dinv, L->x, L->b, L->r, L->crow};
            size_t i;
            for (i = 0; i < sizeof m / sizeof m[0]; ++i) pn_free(&a, m[i]);
        }
        pn_free(&a, w->s.mg_dense);
    }
    pn_free(&a, w);
}

/* the stencil slots s = 0 .. 3^d - 1: offsets per axis and flat node offsets, once */
static void pn__mpm_slots(pn_mpm_world *w) {
    int s, i;
    w->s.ns = w->dim == 3 ? 27 : 9;
    for (s = 0; s < w->s.ns; ++s) {
        int r = s;
        w->s.slot_off[s] = 0;
        w->s.slot[s][2] = 0;
        for (i = w->dim - 1; i >= 0; --i) {
            w->s.slot[s][i] = r % 3;
            r /= 3;
            w->s.slot_off[s] += (size_t)w->s.slot[s][i] * w->s.stride[i];
        }
    }
}

#define PN__MPM_REFUSE(msg)                                                                 \
    do {                                                                                    \
        if (why) *why = msg;                                                                \
        return PN_ERROR_INVALID_ARGUMENT;                                                   \
    } while (0)

static pn_result pn__mpm_create_why(const pn_mpm_desc *desc, pn_mpm_world **out, const char **why) {
    pn_mpm_world *w;
    int d, dd, i, fail = 0, wall;
    size_t cap, nodes = 1, k, nparts;
    PN_ASSERT(desc && out);
    d = desc->dim;
    if (!pn__dim_ok(d)) {
        if (why) *why = "pn_mpm_desc.dim must be 2 or 3 (and not compiled out by PN_NO_2D / PN_NO_3D)";
        return PN_ERROR_DIMENSION;
    }
    if (!pn__finite(desc->dx_m) || !(desc->dx_m > 0)) PN__MPM_REFUSE("pn_mpm_desc.dx_m must be finite and > 0");
    if (!pn__finite(desc->friction) || !(desc->friction >= 0))
        PN__MPM_REFUSE("pn_mpm_desc.friction must be finite and >= 0");
    if (!pn__finite(desc->filter_time_s) || !(desc->filter_time_s >= 0))
        PN__MPM_REFUSE("pn_mpm_desc.filter_time_s must be finite and >= 0");
    if (!pn__finite(desc->advection_limit) || !(desc->advection_limit >= 0))
        PN__MPM_REFUSE("pn_mpm_desc.advection_limit must be finite and >= 0 (0: 1 cell)");
    if (desc->max_particles == 0) PN__MPM_REFUSE("pn_mpm_desc.max_particles must be > 0");
    if (desc->wall_cells < 0) PN__MPM_REFUSE("pn_mpm_desc.wall_cells must be >= 0 (0: 3)");
    if (desc->boundary < PN_BOUNDARY_STICKY || desc->boundary > PN_BOUNDARY_SEPARATE)
        PN__MPM_REFUSE("pn_mpm_desc.boundary is not a pn_boundary");
    if ((desc->allocator.alloc == NULL) != (desc->allocator.free == NULL))
        PN__MPM_REFUSE("pn_mpm_desc.allocator needs both alloc and free, or neither");
    wall = desc->wall_cells ? desc->wall_cells : 3;
    for (i = 0; i < d; ++i) {
        if (desc->res[i] < 8 || desc->res[i] > 1 << 14)
            PN__MPM_REFUSE("pn_mpm_desc.res: every axis needs 8 .. 16384 cells");
        if (!pn__finite(desc->gravity[i])) PN__MPM_REFUSE("pn_mpm_desc.gravity is not finite");
        if (!pn__finite(desc->origin_m[i])) PN__MPM_REFUSE("pn_mpm_desc.origin_m is not finite");
        if (wall * 2 + 2 > desc->res[i])
            PN__MPM_REFUSE("pn_mpm_desc.wall_cells: the walls leave less than 2 cells on some axis of res");
        nodes *= (size_t)(desc->res[i] + 1);
    }
    dd = d * d;
    cap = desc->max_particles;
    w = (pn_mpm_world *)pn__mpm_alloc(desc, 1, sizeof *w, &fail);
    if (!w) return PN_ERROR_OUT_OF_MEMORY;
    w->desc = *desc;
    for (i = d; i < 3; ++i) w->desc.origin_m[i] = 0;
    if (!(w->desc.advection_limit > 0)) w->desc.advection_limit = 1;
    if (w->desc.parallel_min_particles == 0) w->desc.parallel_min_particles = 4096;
    w->dim = d;
    w->s.wall = wall;
    w->cap = cap;
    w->s.nodes = nodes;
    w->error_particle = -1;
    w->s.stride[d - 1] = 1;
    for (i = d - 2; i >= 0; --i) w->s.stride[i] = w->s.stride[i + 1] * (size_t)(desc->res[i + 1] + 1);
    w->s.nblocks = 1;
    for (i = 0; i < d; ++i) {
        w->s.nblk[i] = (size_t)desc->res[i] / PN__MPM_BLOCK + 1; /* covers the res + 1 nodes */
        w->s.nblocks *= w->s.nblk[i];
    }
    w->s.bstride[d - 1] = 1;
    for (i = d - 2; i >= 0; --i) w->s.bstride[i] = w->s.bstride[i + 1] * w->s.nblk[i + 1];
    w->s.inv_dx = 1 / desc->dx_m;
    for (i = 0; i < d; ++i) {
        /* where a stencil fits (base node >= 0, base + 2 <= res: [0.5 dx, (res - 0.5) dx)), with
           a quarter cell to spare for rounding. A wall of one cell has its plane at dx: a
           particle a hair past it is put back on it, not taken for one that went through */
        w->s.grid_lo[i] = w->desc.origin_m[i] + (pn_real)0.75 * desc->dx_m;
        w->s.grid_hi[i] = w->desc.origin_m[i] + ((pn_real)desc->res[i] - (pn_real)0.75) * desc->dx_m;
        w->s.wall_lo[i] = w->desc.origin_m[i] + wall * desc->dx_m;
        w->s.wall_hi[i] = w->desc.origin_m[i] + (desc->res[i] - wall) * desc->dx_m;
    }
    pn__mpm_slots(w);
    nparts = (cap > nodes * (size_t)d ? cap : nodes * (size_t)d) / PN__MPM_CHUNK + 2;
#define PN__MPM_A(f, count, type) w->f = (type *)pn__mpm_alloc(desc, count, sizeof(type), &fail)
    PN__MPM_A(x, cap * (size_t)d, pn_real);
    PN__MPM_A(v, cap * (size_t)d, pn_real);
    PN__MPM_A(C, cap * (size_t)dd, pn_real);
    PN__MPM_A(F, cap * (size_t)dd, pn_real);
    PN__MPM_A(h, cap, pn_real);
    PN__MPM_A(vol0, cap, pn_real);
    PN__MPM_A(mass, cap, pn_real);
    PN__MPM_A(group, cap, int);
    PN__MPM_A(active, cap, unsigned char);
    PN__MPM_A(s.pbase, cap, size_t);
    PN__MPM_A(s.pw, cap * 9, pn_real);
    PN__MPM_A(s.pfx, cap * 3, pn_real);
    PN__MPM_A(s.order, cap, size_t);
    PN__MPM_A(s.start, nodes + 1, size_t);
    PN__MPM_A(s.act, nodes, size_t);
    PN__MPM_A(s.dof, nodes, long);
    PN__MPM_A(s.mark, nodes, unsigned char);
    PN__MPM_A(s.grid_m, nodes, pn_real);
    PN__MPM_A(s.grid_v, nodes * (size_t)d, pn_real);
    PN__MPM_A(s.grid_v0, nodes * (size_t)d, pn_real);
    PN__MPM_A(s.pmat, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.pscal, cap > nodes ? cap : nodes, pn_real);
    PN__MPM_A(s.part, nparts, pn_real);
    PN__MPM_A(s.pstat, cap, int);
    PN__MPM_A(s.sx, cap * (size_t)d, pn_real);
    PN__MPM_A(s.sv, cap * (size_t)d, pn_real);
    PN__MPM_A(s.sC, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.sF, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.sh, cap, pn_real);
    PN__MPM_A(s.sactive, cap, unsigned char);
    PN__MPM_A(s.cn, nodes, unsigned char);
    PN__MPM_A(s.ckind, nodes, unsigned char);
    PN__MPM_A(s.chold, nodes, unsigned char);
    PN__MPM_A(s.cdir, nodes * 9, pn_real);
    PN__MPM_A(s.cvel, nodes * 3, pn_real);
    PN__MPM_A(s.cmu, nodes, pn_real);
    PN__MPM_A(s.clam, nodes, pn_real);
    PN__MPM_A(s.ctan, nodes * 3, pn_real);
    PN__MPM_A(s.bmark, w->s.nblocks, unsigned char);
    PN__MPM_A(s.bact, w->s.nblocks, size_t);
    PN__MPM_A(s.rowcount, (size_t)desc->res[0] + 1, size_t);
    PN__MPM_A(s.gdense, nodes * 4, pn_real); /* zero: each explicit step leaves it so */
    if (desc->filter_time_s > 0) PN__MPM_A(s.gdense0, nodes * (size_t)d, pn_real);
    PN__MPM_A(s.ppay, (cap + PN__MPM_LANES - 1) / PN__MPM_LANES * PN__MPM_LANES * (size_t)PN__MPM_PAY(d), pn_real);
    PN__MPM_A(s.spay, (cap + PN__MPM_LANES - 1) / PN__MPM_LANES * PN__MPM_LANES * (size_t)PN__MPM_PAY(d), pn_real);
    PN__MPM_A(s.prow, cap, int);
    PN__MPM_A(s.srow, cap, int);
    if (fail) {
        pn_mpm_destroy(w);
        if (why) *why = "out of memory for max_particles particles and the grid";
        return PN_ERROR_OUT_OF_MEMORY;
    }
    for (k = 0; k < nodes; ++k) w->s.dof[k] = -1;
    *out = w;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_create(const pn_mpm_desc *desc, pn_mpm_world **out, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__mpm_create_why(desc, out, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}
#undef PN__MPM_REFUSE

PN__DEF const char *pn_mpm_error(const pn_mpm_world *w) { return w ? w->error : ""; }

PN__DEF int pn_mpm_add_group(pn_mpm_world *w, const pn_material *m, pn_real density_kg_m3) {
    const char *why = "";
    PN_ASSERT(w && m);
    w->error[0] = 0;
    if (w->n_groups >= PN_MPM_MAX_GROUPS) {
        PN__FAIL(w, PN_ERROR_CAPACITY, "pn_mpm_add_group: all PN_MPM_MAX_GROUPS = %d groups are in use",
                     PN_MPM_MAX_GROUPS);
        return -1;
    }
    if (!pn__finite(density_kg_m3) || !(density_kg_m3 > 0)) {
        PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_group: density_kg_m3 = %g must be finite and > 0",
                     (double)density_kg_m3);
        return -1;
    }
    if (pn__material_check_why(m, &why) != PN_OK) {
        PN__FAIL(w, PN_ERROR_INVALID_PARAMETER, "pn_mpm_add_group: %s", why);
        return -1;
    }
    memset(&w->groups[w->n_groups], 0, sizeof w->groups[0]);
    w->groups[w->n_groups].material = *m;
    w->groups[w->n_groups].density_kg_m3 = density_kg_m3;
    return w->n_groups++;
}

/* inside the walls: origin + [wall dx, (res - wall) dx] on every axis */
static int pn__mpm_inside(const pn_mpm_world *w, const pn_real *x) {
    int i;
    for (i = 0; i < w->dim; ++i)
        if (!(x[i] >= w->s.wall_lo[i] && x[i] <= w->s.wall_hi[i])) return 0;
    return 1;
}

/* where the 3^dim stencil stays on the grid, with a quarter cell to spare: [0.75 dx,
   (res - 0.75) dx]. A step that ends a particle in the wall band puts it back on the wall's
   plane (pn__mpm_wall_plane); only one that leaves this region has gone through a wall. */
/* The walls act at their planes, origin + wall dx and origin + (res - wall) dx. The node
   rows on the planes are held with the walls (pn__mpm_obstacle): holding only the rows
   behind them let material sink up to about a cell in, and once particles were put back on
   the plane, the material above a floor, still moving into it, piled into one dense sheet
   on the plane (a compacted snow layer piled up in its bottom row, its mass field
   depending on the step). A particle that still ends a step past a plane but on the grid
   is put back on the plane, its velocity left to the grid (zeroing its normal part as
   well drains momentum at every contact: the sand column ran out shorter; figures in
   docs/notebook.md, "is the reference converged?"); one that left the grid went through
   (outflow). */
static inline void pn__mpm_wall_plane(const pn_mpm_world *w, pn_real *x) {
    int i;
    for (i = 0; i < w->dim; ++i) {
        if (x[i] < w->s.wall_lo[i]) x[i] = w->s.wall_lo[i];
        else if (x[i] > w->s.wall_hi[i]) x[i] = w->s.wall_hi[i];
    }
}

static inline int pn__mpm_in_grid(const pn_mpm_world *w, const pn_real *x) {
    int i, in = 1;
    for (i = 0; i < w->dim; ++i) in &= x[i] >= w->s.grid_lo[i] && x[i] <= w->s.grid_hi[i];
    return in;
}

PN__DEF pn_result pn_mpm_add_particles(pn_mpm_world *w, int g, size_t n, const pn_real *x,
                                       const pn_real *v, pn_real volume_m3) {
    int d, i;
    size_t p;
    PN_ASSERT(w && (x || n == 0));
    d = w->dim;
    w->error[0] = 0;
    if (g < 0 || g >= w->n_groups)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_particles: group %d does not exist (%d groups)",
                            g, w->n_groups);
    if (!pn__finite(volume_m3) || !(volume_m3 > 0) || !pn__finite(volume_m3 * w->groups[g].density_kg_m3) ||
        !(volume_m3 * w->groups[g].density_kg_m3 > 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT,
                            "pn_mpm_add_particles: volume_m3 = %g (mass %g kg at the group's density) must be "
                            "positive and finite", (double)volume_m3, (double)(volume_m3 * w->groups[g].density_kg_m3));
    if (n > w->cap - w->n)
        return PN__FAIL(w, PN_ERROR_CAPACITY,
                            "pn_mpm_add_particles: %lu more particles need max_particles >= %lu (it is %lu, %lu in use)",
                            (unsigned long)n, (unsigned long)(w->n + n), (unsigned long)w->cap, (unsigned long)w->n);
    for (p = 0; p < n; ++p) {
        if (!pn__all_finite(d, x + p * (size_t)d) || (v && !pn__all_finite(d, v + p * (size_t)d))) {
            w->error_particle = (long)(w->n + p);
            return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_mpm_add_particles: particle %lu of the call has a NaN or "
                                "infinite %s", (unsigned long)p, pn__all_finite(d, x + p * (size_t)d) ? "velocity" : "position");
        }
        if (!pn__mpm_inside(w, x + p * (size_t)d)) {
            w->error_particle = (long)(w->n + p);
            return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_particles: particle %lu of the call at "
                                "(%g, %g, %g) m is outside the walls (origin_m + [%d dx, (res - %d) dx] on each axis)",
                                (unsigned long)p, (double)x[p * (size_t)d], (double)x[p * (size_t)d + 1],
                                d == 3 ? (double)x[p * (size_t)d + 2] : 0.0, w->s.wall, w->s.wall);
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
    w->s.rec_ok = 0;
    w->s.ctau_ok = 0, w->s.stau_committed = 0;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_set_state(pn_mpm_world *w, size_t first, size_t n, const pn_real *h) {
    size_t p;
    PN_ASSERT(w && (h || n == 0));
    w->error[0] = 0;
    if (first > w->n || n > w->n - first)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_set_state: particles %lu .. %lu + %lu do not exist "
                            "(%lu particles)", (unsigned long)first, (unsigned long)first, (unsigned long)n, (unsigned long)w->n);
    for (p = 0; p < n; ++p)
        if (!pn__finite(h[p])) {
            w->error_particle = (long)(first + p);
            return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_mpm_set_state: h of particle %lu is NaN or infinite",
                                (unsigned long)(first + p));
        }
    memcpy(w->h + first, h, sizeof(pn_real) * n);
    w->s.rec_ok = 0;
    w->s.ctau_ok = 0, w->s.stau_committed = 0;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_add_collider(pn_mpm_world *w, const pn_collider *c, int *index) {
    pn_collider k;
    pn_real nn = 0;
    int i, d;
    PN_ASSERT(w && c);
    d = w->dim;
    k = *c;
    w->error[0] = 0;
    if (w->n_colliders >= PN_MPM_MAX_COLLIDERS)
        return PN__FAIL(w, PN_ERROR_CAPACITY, "pn_mpm_add_collider: all PN_MPM_MAX_COLLIDERS = %d are in use",
                            PN_MPM_MAX_COLLIDERS);
    if (k.shape < PN_SHAPE_HALF_SPACE || k.shape > PN_SHAPE_SPHERE)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: shape %d is not a pn_shape", (int)k.shape);
    if (k.boundary < PN_BOUNDARY_STICKY || k.boundary > PN_BOUNDARY_SEPARATE)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: boundary %d is not a pn_boundary",
                            (int)k.boundary);
    if (!pn__finite(k.friction) || !(k.friction >= 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: friction must be finite and >= 0");
    if (!pn__all_finite(d, k.center_m) || !pn__all_finite(d, k.velocity_m_s))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: center_m or velocity_m_s is not finite");
    for (i = d; i < 3; ++i) k.center_m[i] = k.normal[i] = k.half_extent_m[i] = k.velocity_m_s[i] = 0;
    if (k.shape == PN_SHAPE_HALF_SPACE) {
        if (pn__all_finite(d, k.normal))
            for (i = 0; i < d; ++i) nn += k.normal[i] * k.normal[i];
        nn = PN__SQRT(nn);
        if (!(nn > 0) || !pn__finite(nn))
            return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: the half-space normal is zero or not finite");
        for (i = 0; i < d; ++i) k.normal[i] /= nn;
    } else if (k.shape == PN_SHAPE_BOX) {
        for (i = 0; i < d; ++i)
            if (!pn__finite(k.half_extent_m[i]) || !(k.half_extent_m[i] > 0))
                return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: half_extent_m must be finite and > 0");
    } else if (!pn__finite(k.radius_m) || !(k.radius_m > 0)) {
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_add_collider: radius_m must be finite and > 0");
    }
    w->colliders[w->n_colliders] = k;
    if (index) *index = w->n_colliders;
    w->n_colliders++;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_move_collider(pn_mpm_world *w, int index, const pn_real *center_m,
                                       const pn_real *velocity_m_s) {
    pn_collider *c;
    int i, d;
    PN_ASSERT(w && center_m);
    d = w->dim;
    w->error[0] = 0;
    if (index < 0 || index >= w->n_colliders)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_move_collider: collider %d does not exist (%d colliders)",
                            index, w->n_colliders);
    if (!pn__all_finite(d, center_m) || (velocity_m_s && !pn__all_finite(d, velocity_m_s)))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_mpm_move_collider: center_m or velocity_m_s is NaN or infinite");
    c = &w->colliders[index];
    for (i = 0; i < d; ++i) { /* center(t) = center + t velocity passes center_m at time_s */
        c->velocity_m_s[i] = velocity_m_s ? velocity_m_s[i] : 0;
        c->center_m[i] = center_m[i] - w->time_s * c->velocity_m_s[i];
    }
    return PN_OK;
}

PN__DEF void pn_mpm_totals(const pn_mpm_world *w, pn_real *mass, pn_real *momentum) {
    size_t p;
    int i, d;
    pn_real m = 0, mom[3] = {0, 0, 0};
    PN_ASSERT(w);
    d = w->dim;
    for (p = 0; p < w->n; ++p) {
        if (!w->active[p]) continue;
        m += w->mass[p];
        for (i = 0; i < d; ++i) mom[i] += w->mass[p] * w->v[p * (size_t)d + (size_t)i];
    }
    if (mass) *mass = m;
    if (momentum)
        for (i = 0; i < d; ++i) momentum[i] = mom[i];
}

/* Deterministic sum: fixed chunks (in parallel), then the chunk sums in order. */
static pn_real pn__mpm_sum(pn_mpm_world *w, size_t n, const pn_real *a, const pn_real *b) {
    long c, nc = (long)((n + PN__MPM_CHUNK - 1) / PN__MPM_CHUNK);
    pn_real s = 0;
    PN__OMP_FOR
    for (c = 0; c < nc; ++c) {
        size_t i, lo = (size_t)c * PN__MPM_CHUNK, hi = PN__MIN(n, lo + PN__MPM_CHUNK);
        pn_real acc = 0;
        if (b)
            for (i = lo; i < hi; ++i) acc += a[i] * b[i];
        else
            for (i = lo; i < hi; ++i) acc += a[i];
        w->s.part[c] = acc;
    }
    for (c = 0; c < nc; ++c) s += w->s.part[c];
    return s;
}

/* The first particle (lowest index) whose pstat holds an error, with its code and why: an
   error code (0xff), else moving past the advection limit (0x400: what makes material tunnel),
   else passing through a wall where outflow is not allowed (0x800). */
static pn_result pn__mpm_first_error(pn_mpm_world *w, pn_real dt) {
    size_t p;
    int d = w->dim, i, pass, any = 0;
    static const int bits[3] = {0xff, 0x400, 0x800};
    for (p = 0; p < w->n; ++p) any |= w->s.pstat[p];
    if (!(any & 0xcff)) return PN_OK;
    for (pass = 0; pass < 3; ++pass)
        for (p = 0; p < w->n; ++p) {
            pn_real far = 0;
            if (!w->active[p] || !(w->s.pstat[p] & bits[pass])) continue;
            w->error_particle = (long)p;
            if (pass == 0)
                return PN__FAIL(w, (pn_result)(w->s.pstat[p] & 0xff), "step of %g s: particle %lu (group %d): %s",
                                    (double)dt, (unsigned long)p, w->group[p],
                                    pn_result_string((pn_result)(w->s.pstat[p] & 0xff)));
            for (i = 0; i < d; ++i)
                far = PN__MAX(far, PN__FABS(w->s.sx[p * (size_t)d + (size_t)i] - w->x[p * (size_t)d + (size_t)i]));
            if (pass == 1)
                return PN__FAIL(w, PN_ERROR_STEP_TOO_LARGE, "step of %g s: particle %lu would move %.2f cells (the "
                                    "advection limit is %g): take steps of at most %.3g s (pn_mpm_advance picks them)",
                                    (double)dt, (unsigned long)p, (double)(far / w->desc.dx_m),
                                    (double)w->desc.advection_limit, (double)(dt * w->desc.advection_limit * w->desc.dx_m / far));
            return PN__FAIL(w, PN_ERROR_OUTSIDE_DOMAIN, "step of %g s: particle %lu would pass through a wall to "
                                "(%g, %g, %g) m (smaller steps, or pn_mpm_desc.allow_outflow to let material leave)",
                                (double)dt, (unsigned long)p, (double)w->s.sx[p * (size_t)d],
                                (double)w->s.sx[p * (size_t)d + 1], d == 3 ? (double)w->s.sx[p * (size_t)d + 2] : 0.0);
        }
    return PN_OK;
}

/* State check at the start of a step: x, v, C, F, h finite. */
static pn_result pn__mpm_check_state(pn_mpm_world *w) {
    int d = w->dim, dd = d * d;
    size_t p;
    for (p = 0; p < w->n; ++p) {
        if (!w->active[p]) continue;
        if (!pn__all_finite(d, w->x + p * (size_t)d) || !pn__all_finite(d, w->v + p * (size_t)d) ||
            !pn__all_finite(dd, w->C + p * (size_t)dd) || !pn__all_finite(dd, w->F + p * (size_t)dd) ||
            !pn__finite(w->h[p])) {
            w->error_particle = (long)p;
            return PN__FAIL(w, PN_ERROR_NONFINITE, "particle %lu has a NaN or infinite x, v, C, F or h (was it "
                                "written by hand?)", (unsigned long)p);
        }
    }
    return PN_OK;
}

/* zeroed stats of one step; the force-error fields -1 unless measured */
static void pn__mpm_stats_clear(pn_mpm_stats *st, int measure) {
    memset(st, 0, sizeof *st);
    st->substeps = 1;
    st->force_error = st->force_error_regularizer = st->apex_fraction = measure ? 0 : -1;
    st->dt_over_cfl = -1;
}

/* ======================================================================================
   >>drive: particles driven rigidly and loads on particles. A drive is a Dirichlet condition
   carried by material: the grid nodes its particles touch take the rigid motion's velocity
   (pn__mpm_xdrive_grid), and its particles are then put at their exact positions
   (pn__mpm_xdrive_state). A load adds m_p a dt to the momentum a particle scatters.
   ====================================================================================== */

/* checks a particle list: each exists, is active, and (drives) is in no other live drive */
static pn_result pn__mpm_list_check(pn_mpm_world *w, size_t n, const size_t *idx, int drive, const char *fn) {
    size_t k, j;
    int a;
    if (n == 0 || !idx) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "%s: no particles (n = 0 or NULL)", fn);
    for (k = 0; k < n; ++k) {
        if (idx[k] >= w->n || !w->active[idx[k]]) {
            w->error_particle = idx[k] < w->n ? (long)idx[k] : -1;
            return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "%s: particle %lu (entry %lu) %s", fn, (unsigned long)idx[k],
                                (unsigned long)k, idx[k] >= w->n ? "does not exist" : "is not active");
        }
    }
    if (!drive) return PN_OK;
    for (a = 0; a < w->s.n_drives; ++a) {
        const pn__mpm_drive *D = &w->s.drives[a];
        if (!D->on) continue;
        for (k = 0; k < n; ++k)
            for (j = 0; j < D->n; ++j)
                if (D->idx[j] == idx[k]) {
                    w->error_particle = (long)idx[k];
                    return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "%s: particle %lu is already driven by drive %d "
                                        "(pn_mpm_release_drive it first)", fn, (unsigned long)idx[k], a);
                }
    }
    return PN_OK;
}

PN__DEF pn_result pn_mpm_drive_particles(pn_mpm_world *w, size_t n, const size_t *particles, const pn_real *velocity_m_s,
                                         const pn_real *center_m, const pn_real *angular_velocity_rad_s, int *index) {
    static const char *fn = "pn_mpm_drive_particles";
    pn__mpm_drive D;
    pn_result r;
    int d, i, a, spin = 0, fail = 0;
    size_t k;
    PN_ASSERT(w);
    d = w->dim;
    w->error[0] = 0;
    if ((velocity_m_s && !pn__all_finite(d, velocity_m_s)) || (center_m && !pn__all_finite(d, center_m)) ||
        (angular_velocity_rad_s && !pn__all_finite(3, angular_velocity_rad_s)))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "%s: velocity_m_s, center_m or angular_velocity_rad_s is NaN or infinite", fn);
    memset(&D, 0, sizeof D);
    for (i = 0; i < 3; ++i) {
        D.vel[i] = velocity_m_s && i < d ? velocity_m_s[i] : 0;
        D.center[i] = center_m && i < d ? center_m[i] : 0;
        D.omega[i] = angular_velocity_rad_s && (d == 3 || i == 2) ? angular_velocity_rad_s[i] : 0;
        spin |= D.omega[i] != 0;
    }
    if (spin && !center_m) return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "%s: a rotation needs center_m", fn);
    if ((r = pn__mpm_list_check(w, n, particles, 1, fn)) != PN_OK) return r;
    for (a = 0; a < w->s.n_drives && w->s.drives[a].on; ++a) {} /* a released slot is reused */
    if (a == PN_MPM_MAX_DRIVES) a = -1;
    if (a < 0) return PN__FAIL(w, PN_ERROR_CAPACITY, "%s: all PN_MPM_MAX_DRIVES = %d are in use", fn, PN_MPM_MAX_DRIVES);
    D.idx = (size_t *)pn__mpm_alloc(&w->desc, n, sizeof(size_t), &fail);
    D.x0 = (pn_real *)pn__mpm_alloc(&w->desc, n * (size_t)d, sizeof(pn_real), &fail);
    if (fail) {
        pn_free(&w->desc.allocator, D.idx);
        pn_free(&w->desc.allocator, D.x0);
        return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "%s: out of memory for %lu particles", fn, (unsigned long)n);
    }
    D.n = n;
    D.t0 = w->time_s;
    D.on = 1;
    memcpy(D.idx, particles, sizeof(size_t) * n);
    for (k = 0; k < n; ++k) memcpy(D.x0 + k * (size_t)d, w->x + particles[k] * (size_t)d, sizeof(pn_real) * (size_t)d);
    pn_free(&w->desc.allocator, w->s.drives[a].idx); /* a released drive's */
    pn_free(&w->desc.allocator, w->s.drives[a].x0);
    w->s.drives[a] = D;
    if (a == w->s.n_drives) w->s.n_drives++;
    if (index) *index = a;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_release_drive(pn_mpm_world *w, int index) {
    PN_ASSERT(w);
    w->error[0] = 0;
    if (index < 0 || index >= w->s.n_drives || index >= PN_MPM_MAX_DRIVES)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_release_drive: drive %d does not exist (%d drives)", index,
                            w->s.n_drives);
    w->s.drives[index].on = 0;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_add_load(pn_mpm_world *w, size_t n, const size_t *particles, const pn_real *force_N,
                                  pn_real duration_s, int *index) {
    static const char *fn = "pn_mpm_add_load";
    pn__mpm_load L;
    pn_result r;
    pn_real mass = 0;
    int d, i, a, fail = 0;
    size_t k;
    PN_ASSERT(w);
    d = w->dim;
    w->error[0] = 0;
    if (!force_N || !pn__all_finite(d, force_N))
        return PN__FAIL(w, PN_ERROR_NONFINITE, "%s: force_N is NULL, NaN or infinite", fn);
    if (!pn__finite(duration_s) || !(duration_s >= 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "%s: duration_s = %g must be finite and >= 0 (0: until removed)", fn,
                            (double)duration_s);
    if ((r = pn__mpm_list_check(w, n, particles, 0, fn)) != PN_OK) return r;
    for (a = 0; a < w->s.n_loads && w->s.loads[a].on; ++a) {}
    if (a == PN_MPM_MAX_LOADS) a = -1;
    if (a < 0) return PN__FAIL(w, PN_ERROR_CAPACITY, "%s: all PN_MPM_MAX_LOADS = %d are in use", fn, PN_MPM_MAX_LOADS);
    memset(&L, 0, sizeof L);
    L.idx = (size_t *)pn__mpm_alloc(&w->desc, n, sizeof(size_t), &fail);
    if (fail) return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "%s: out of memory for %lu particles", fn, (unsigned long)n);
    memcpy(L.idx, particles, sizeof(size_t) * n);
    for (k = 0; k < n; ++k) mass += w->mass[particles[k]];
    for (i = 0; i < d; ++i) L.acc[i] = force_N[i] / mass;
    L.n = n;
    L.t_end = duration_s > 0 ? w->time_s + duration_s : (pn_real)HUGE_VAL;
    L.on = 1;
    pn_free(&w->desc.allocator, w->s.loads[a].idx);
    w->s.loads[a] = L;
    if (a == w->s.n_loads) w->s.n_loads++;
    if (index) *index = a;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_remove_load(pn_mpm_world *w, int index) {
    PN_ASSERT(w);
    w->error[0] = 0;
    if (index < 0 || index >= w->s.n_loads || index >= PN_MPM_MAX_LOADS)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_remove_load: load %d does not exist (%d loads)", index,
                            w->s.n_loads);
    w->s.loads[index].on = 0;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_select_box(const pn_mpm_world *w, const pn_real *lo, const pn_real *hi, size_t *out, size_t cap,
                                    size_t *count) {
    size_t p, c = 0;
    int d, i;
    PN_ASSERT(w && lo && hi && count && (out || cap == 0));
    d = w->dim;
    *count = 0;
    if (!pn__all_finite(d, lo) || !pn__all_finite(d, hi)) return PN_ERROR_NONFINITE;
    for (p = 0; p < w->n; ++p) {
        int in = w->active[p];
        for (i = 0; i < d; ++i) in &= w->x[p * (size_t)d + (size_t)i] >= lo[i] && w->x[p * (size_t)d + (size_t)i] <= hi[i];
        if (!in) continue;
        if (c < cap) out[c] = p;
        c++;
    }
    *count = c;
    return PN_OK;
}

PN__DEF pn_result pn_mpm_set_particles(pn_mpm_world *w, size_t first, size_t n, const pn_real *x, const pn_real *v,
                                       const pn_real *C, const pn_real *F, pn_real time_s) {
    size_t p;
    int d, dd;
    PN_ASSERT(w);
    d = w->dim, dd = d * d;
    w->error[0] = 0;
    if (first > w->n || n > w->n - first)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_set_particles: particles %lu .. %lu + %lu do not exist "
                            "(%lu particles)", (unsigned long)first, (unsigned long)first, (unsigned long)n, (unsigned long)w->n);
    if (!pn__finite(time_s)) return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_mpm_set_particles: time_s is NaN or infinite");
    for (p = 0; p < n; ++p) {
        const char *bad = NULL;
        if (x && !pn__all_finite(d, x + p * (size_t)d)) bad = "x";
        else if (v && !pn__all_finite(d, v + p * (size_t)d)) bad = "v";
        else if (C && !pn__all_finite(dd, C + p * (size_t)dd)) bad = "C";
        else if (F && !pn__all_finite(dd, F + p * (size_t)dd)) bad = "F";
        if (bad) {
            w->error_particle = (long)(first + p);
            return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_mpm_set_particles: %s of particle %lu is NaN or infinite", bad,
                                (unsigned long)(first + p));
        }
        if (x && !pn__mpm_inside(w, x + p * (size_t)d)) {
            w->error_particle = (long)(first + p);
            return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_set_particles: x of particle %lu is outside the walls",
                                (unsigned long)(first + p));
        }
    }
    if (x) memcpy(w->x + first * (size_t)d, x, sizeof(pn_real) * n * (size_t)d);
    if (v) memcpy(w->v + first * (size_t)d, v, sizeof(pn_real) * n * (size_t)d);
    if (C) memcpy(w->C + first * (size_t)dd, C, sizeof(pn_real) * n * (size_t)dd);
    if (F) memcpy(w->F + first * (size_t)dd, F, sizeof(pn_real) * n * (size_t)dd);
    if (time_s >= 0) w->time_s = time_s;
    w->s.rec_ok = 0;
    w->s.ctau_ok = 0, w->s.stau_committed = 0;
    w->s.n_lag = 0;
    return PN_OK;
}

/* the rigid motion of drive D (pn__mpm_drive_at, pn__mpm_drive_vel): the kit's */
PN__RIGID_DEF(pn__mpm_drive_at, pn__mpm_drive_vel, pn__mpm_drive, pn_real, PN__SQRT, PN__COS, PN__SIN)

#define PN__MPM_FLOOR(x) ((pn_real)floor((double)(x)))

/* ======================================================================================
   >>fill: particles on a lattice of spacing dx / per_axis aligned with the grid (points at
   origin + (i + 1/2) h), kept where they fall inside the shape. Jitter moves each point to
   a random spot of its lattice cell from a counter-based hash of (seed, i, j, k), so the
   result does not depend on the order of the walk. Inside a mesh: the winding number of a
   ray cast along +x, triangles binned by their (y, z) extent (edges by y in 2D); a point
   on an edge or vertex of the projection is resolved by a symbolic perturbation of the
   ray (q + (eps, eps^2)), the same for every element, so each crossing counts exactly once.
   ====================================================================================== */

typedef struct pn__mpm_mesh_bins {
    int d, nb[2];                /* bins over the projection (y in 2D; y, z in 3D)         */
    pn_real lo[2], h;            /* first bin's corner and bin size                        */
    size_t *start, *item;        /* CSR: elements of bin b at item[start[b] .. start[b+1]) */
} pn__mpm_mesh_bins;

static pn_real pn__mpm_hash01(unsigned long seed, long i, long j, long k, int axis) {
    unsigned long long z = (unsigned long long)seed * 0x9E3779B97F4A7C15ULL;
    z ^= (unsigned long long)i * 0xBF58476D1CE4E5B9ULL + (unsigned long long)j * 0x94D049BB133111EBULL +
         (unsigned long long)k * 0xD6E8FEB86659FD93ULL + (unsigned long long)axis * 0xA0761D6478BD642FULL;
    z = pn__mix64(z);
    return (pn_real)((double)(z >> 11) * (1.0 / 9007199254740992.0));
}

/* orient(u, v, q) in the projection, and its sign under the perturbation q + (eps, eps^2) */
static int pn__mpm_side(const pn_real *u, const pn_real *v, const pn_real *q) {
    pn_real e = (v[0] - u[0]) * (q[1] - u[1]) - (v[1] - u[1]) * (q[0] - u[0]);
    if (e != 0) return e > 0 ? 1 : -1;
    if (v[1] != u[1]) return v[1] > u[1] ? -1 : 1;
    return v[0] > u[0] ? 1 : (v[0] < u[0] ? -1 : 0);
}

/* the projection of vertex a of a mesh element (y or y, z) */
static void pn__mpm_proj(const pn_mpm_fill_desc *f, int d, int a, pn_real *q) {
    q[0] = f->vertices_m[(size_t)a * (size_t)d + 1];
    q[1] = d == 3 ? f->vertices_m[(size_t)a * (size_t)d + 2] : 0;
}

/* winding of the ray from x along +x (*all: the winding of the whole line, 0 when closed) */
static int pn__mpm_winding(const pn_mpm_fill_desc *f, const pn__mpm_mesh_bins *b, const pn_real *x, int *all) {
    int d = b->d, wn = 0, i;
    long bi[2] = {0, 0};
    size_t s, bin;
    *all = 0;
    for (i = 0; i < d - 1; ++i) {
        bi[i] = (long)floor((double)((x[i + 1] - b->lo[i]) / b->h));
        if (bi[i] < 0 || bi[i] >= b->nb[i]) return 0;
    }
    bin = (size_t)bi[0] * (size_t)b->nb[1] + (size_t)bi[1];
    for (s = b->start[bin]; s < b->start[bin + 1]; ++s) {
        const int *e = f->indices + b->item[s] * (size_t)d;
        const pn_real *V = f->vertices_m;
        pn_real xc;
        int sg;
        if (d == 2) {
            pn_real ya = V[(size_t)e[0] * 2 + 1], yb = V[(size_t)e[1] * 2 + 1], xa = V[(size_t)e[0] * 2], xb = V[(size_t)e[1] * 2];
            if ((ya <= x[1]) == (yb <= x[1])) continue; /* half-open: a vertex counts once */
            xc = xa + (x[1] - ya) * (xb - xa) / (yb - ya);
            sg = yb > ya ? 1 : -1;
        } else {
            pn_real A[2], B[2], C[2], q[2], wa, wb, wc, area;
            int s0, s1, s2;
            pn__mpm_proj(f, 3, e[0], A);
            pn__mpm_proj(f, 3, e[1], B);
            pn__mpm_proj(f, 3, e[2], C);
            q[0] = x[1];
            q[1] = x[2];
            s0 = pn__mpm_side(B, C, q);
            s1 = pn__mpm_side(C, A, q);
            s2 = pn__mpm_side(A, B, q);
            if (!((s0 > 0 && s1 > 0 && s2 > 0) || (s0 < 0 && s1 < 0 && s2 < 0))) continue;
            wa = (C[0] - B[0]) * (q[1] - B[1]) - (C[1] - B[1]) * (q[0] - B[0]);
            wb = (A[0] - C[0]) * (q[1] - C[1]) - (A[1] - C[1]) * (q[0] - C[0]);
            wc = (B[0] - A[0]) * (q[1] - A[1]) - (B[1] - A[1]) * (q[0] - A[0]);
            area = wa + wb + wc;
            if (area == 0) continue;
            xc = (wa * V[(size_t)e[0] * 3] + wb * V[(size_t)e[1] * 3] + wc * V[(size_t)e[2] * 3]) / area;
            sg = s0 > 0 ? 1 : -1; /* the sign of the normal's x component */
        }
        *all += sg;
        if (xc > x[0]) wn += sg;
    }
    return wn;
}

/* a shape's bounding box, and whether x is inside */
static void pn__mpm_fill_box(const pn_mpm_fill_desc *f, int d, const pn_real *axis, pn_real *lo, pn_real *hi) {
    int i;
    size_t v;
    for (i = 0; i < d; ++i) {
        pn_real r = 0;
        if (f->shape == PN_MPM_FILL_BOX) r = f->half_extent_m[i];
        else if (f->shape == PN_MPM_FILL_SPHERE) r = f->radius_m;
        else if (f->shape == PN_MPM_FILL_CYLINDER)
            r = f->half_length_m * PN__FABS(axis[i]) + f->radius_m * PN__SQRT(PN__MAX(0, 1 - axis[i] * axis[i]));
        lo[i] = f->center_m[i] - r;
        hi[i] = f->center_m[i] + r;
    }
    if (f->shape != PN_MPM_FILL_MESH) return;
    for (v = 0; v < f->n_vertices; ++v)
        for (i = 0; i < d; ++i) {
            pn_real c = f->vertices_m[v * (size_t)d + (size_t)i];
            if (v == 0 || c < lo[i]) lo[i] = c;
            if (v == 0 || c > hi[i]) hi[i] = c;
        }
}

static int pn__mpm_fill_inside(const pn_mpm_fill_desc *f, const pn__mpm_mesh_bins *b, int d, const pn_real *axis,
                               const pn_real *x, int *open) {
    pn_real r[3] = {0, 0, 0}, rr = 0, t = 0;
    int i, all;
    for (i = 0; i < d; ++i) r[i] = x[i] - f->center_m[i];
    switch (f->shape) {
    case PN_MPM_FILL_BOX:
        for (i = 0; i < d; ++i)
            if (!(PN__FABS(r[i]) <= f->half_extent_m[i])) return 0;
        return 1;
    case PN_MPM_FILL_SPHERE:
        for (i = 0; i < d; ++i) rr += r[i] * r[i];
        return rr <= f->radius_m * f->radius_m;
    case PN_MPM_FILL_CYLINDER:
        for (i = 0; i < d; ++i) t += r[i] * axis[i];
        if (!(PN__FABS(t) <= f->half_length_m)) return 0;
        for (i = 0; i < d; ++i) rr += (r[i] - t * axis[i]) * (r[i] - t * axis[i]);
        return rr <= f->radius_m * f->radius_m;
    default:
        i = pn__mpm_winding(f, b, x, &all);
        if (all != 0) *open = 1;
        return i != 0;
    }
}

/* A fill's parameters; *why on failure. */
static pn_result pn__mpm_fill_valid(const pn_mpm_desc *wd, const pn_mpm_fill_desc *f, pn_real *axis, const char **why) {
    int d = wd->dim, i;
    pn_real n = 0;
    size_t e;
#define PN__MPM_BAD(msg)                                                                    \
    do {                                                                                    \
        *why = msg;                                                                         \
        return PN_ERROR_INVALID_ARGUMENT;                                                   \
    } while (0)
    if (f->shape < PN_MPM_FILL_BOX || f->shape > PN_MPM_FILL_MESH) PN__MPM_BAD("pn_mpm_fill_desc.shape is not a pn_mpm_fill_shape");
    if (f->per_axis < 0 || f->per_axis > 8) PN__MPM_BAD("pn_mpm_fill_desc.per_axis must be in 1 .. 8 (0: 2)");
    if (!pn__all_finite(d, f->center_m) || !pn__all_finite(d, f->velocity_m_s) || !pn__finite(f->state))
        PN__MPM_BAD("pn_mpm_fill_desc: center_m, velocity_m_s or state is not finite");
    if (f->shape == PN_MPM_FILL_BOX)
        for (i = 0; i < d; ++i)
            if (!pn__finite(f->half_extent_m[i]) || !(f->half_extent_m[i] >= 0))
                PN__MPM_BAD("pn_mpm_fill_desc.half_extent_m must be finite and >= 0");
    if ((f->shape == PN_MPM_FILL_SPHERE || f->shape == PN_MPM_FILL_CYLINDER) &&
        (!pn__finite(f->radius_m) || !(f->radius_m >= 0)))
        PN__MPM_BAD("pn_mpm_fill_desc.radius_m must be finite and >= 0");
    for (i = 0; i < 3; ++i) axis[i] = 0;
    if (f->shape == PN_MPM_FILL_CYLINDER) {
        if (!pn__finite(f->half_length_m) || !(f->half_length_m >= 0))
            PN__MPM_BAD("pn_mpm_fill_desc.half_length_m must be finite and >= 0");
        if (!pn__all_finite(d, f->axis)) PN__MPM_BAD("pn_mpm_fill_desc.axis is not finite");
        for (i = 0; i < d; ++i) n += f->axis[i] * f->axis[i];
        if (n == 0) axis[1] = 1;
        else
            for (i = 0; i < d; ++i) axis[i] = f->axis[i] / PN__SQRT(n);
    }
    if (f->shape == PN_MPM_FILL_MESH) {
        if (!f->vertices_m || !f->indices || f->n_vertices == 0 || f->n_elements == 0)
            PN__MPM_BAD("pn_mpm_fill_desc: a mesh needs vertices_m, indices, n_vertices and n_elements");
        for (e = 0; e < f->n_vertices; ++e)
            if (!pn__all_finite(d, f->vertices_m + e * (size_t)d))
                PN__MPM_BAD("pn_mpm_fill_desc.vertices_m has a NaN or infinite coordinate");
        for (e = 0; e < f->n_elements * (size_t)d; ++e)
            if (f->indices[e] < 0 || (size_t)f->indices[e] >= f->n_vertices)
                PN__MPM_BAD("pn_mpm_fill_desc.indices has an index outside 0 .. n_vertices - 1");
    }
#undef PN__MPM_BAD
    return PN_OK;
}

/* Bin the mesh's elements over the projection, bins of size h (allocated with a). */
static pn_result pn__mpm_bins_make(pn__mpm_mesh_bins *b, const pn_mpm_fill_desc *f, int d, pn_real h,
                                   const pn_real *lo, const pn_real *hi, const pn_allocator *a) {
    size_t e, nbins, total = 0, pass;
    int i;
    memset(b, 0, sizeof *b);
    b->d = d;
    b->h = h;
    b->nb[1] = 1;
    for (i = 0; i < d - 1; ++i) {
        b->lo[i] = lo[i + 1] - h;
        b->nb[i] = (int)PN__MAX(1, PN__MPM_FLOOR((hi[i + 1] - lo[i + 1]) / h) + 3); /* bins of a cell, in the walls */
    }
    nbins = (size_t)b->nb[0] * (size_t)b->nb[1];
    b->start = (size_t *)pn_alloc(a, sizeof(size_t) * (nbins + 1));
    if (!b->start) return PN_ERROR_OUT_OF_MEMORY;
    memset(b->start, 0, sizeof(size_t) * (nbins + 1));
    for (pass = 0; pass < 2; ++pass) { /* count per bin, then place */
        for (e = 0; e < f->n_elements; ++e) {
            pn_real elo[2] = {0, 0}, ehi[2] = {0, 0};
            long r0[2] = {0, 0}, r1[2] = {0, 0}, y, z;
            int k;
            for (k = 0; k < d; ++k) {
                pn_real q[2];
                pn__mpm_proj(f, d, f->indices[e * (size_t)d + (size_t)k], q);
                for (i = 0; i < d - 1; ++i) {
                    if (k == 0 || q[i] < elo[i]) elo[i] = q[i];
                    if (k == 0 || q[i] > ehi[i]) ehi[i] = q[i];
                }
            }
            for (i = 0; i < d - 1; ++i) {
                r0[i] = (long)PN__MAX(0, PN__MPM_FLOOR((elo[i] - b->lo[i]) / h));
                r1[i] = (long)PN__MIN(b->nb[i] - 1, PN__MPM_FLOOR((ehi[i] - b->lo[i]) / h));
            }
            for (y = r0[0]; y <= r1[0]; ++y)
                for (z = r0[1]; z <= r1[1]; ++z) {
                    size_t bin = (size_t)y * (size_t)b->nb[1] + (size_t)z;
                    if (pass == 0) b->start[bin + 1]++;
                    else b->item[b->start[bin]++] = e;
                }
        }
        if (pass == 0) {
            for (e = 0; e < nbins; ++e) b->start[e + 1] += b->start[e];
            total = b->start[nbins];
            b->item = (size_t *)pn_alloc(a, sizeof(size_t) * (total ? total : 1));
            if (!b->item) {
                pn_free(a, b->start);
                return PN_ERROR_OUT_OF_MEMORY;
            }
        } else { /* start[bin] was advanced to the next bin's start: shift back */
            for (e = nbins; e > 0; --e) b->start[e] = b->start[e - 1];
            b->start[0] = 0;
        }
    }
    return PN_OK;
}

/* Walk the lattice points of the fill: count them (x NULL) or write them to x. Returns
   PN_OK, or the first point outside the walls (*bad) / an open mesh. */
/* The part of the shape's bounding box [lo, hi] inside the walls. Unless the fill clips, a
   shape that reaches beyond a wall by more than half a lattice spacing (where a lattice
   point could lie) is refused (*bad: a point of it outside). The bounding box is exact for
   boxes, spheres and cylinders, and holds a mesh's vertices, so this is the shape's own
   extent; and every walk stays inside the walls, its cost bounded by the domain's. */
static pn_result pn__mpm_fill_range(const pn_mpm_desc *wd, int wall, const pn_mpm_fill_desc *f, const pn_real *axis,
                                    pn_real h, pn_real *lo, pn_real *hi, pn_real *bad) {
    int d = wd->dim, i, j;
    pn__mpm_fill_box(f, d, axis, lo, hi);
    for (i = 0; i < d; ++i) {
        pn_real o = wd->origin_m[i], wlo = o + wall * wd->dx_m, whi = o + (wd->res[i] - wall) * wd->dx_m;
        if (!f->clip && (lo[i] < wlo - h / 2 || hi[i] > whi + h / 2)) {
            for (j = 0; j < 3; ++j) bad[j] = j < d ? (lo[j] + hi[j]) / 2 : 0;
            bad[i] = lo[i] < wlo - h / 2 ? lo[i] : hi[i];
            return PN_ERROR_INVALID_ARGUMENT;
        }
        lo[i] = PN__MAX(lo[i], wlo);
        hi[i] = PN__MIN(hi[i], whi);
    }
    return PN_OK;
}

static pn_result pn__mpm_fill_walk(const pn_mpm_desc *wd, int wall, const pn_mpm_fill_desc *f,
                                   const pn__mpm_mesh_bins *b, const pn_real *axis, const pn_real *lo,
                                   const pn_real *hi, pn_real *x, size_t *count, pn_real *bad, int *open) {
    int d = wd->dim, i, per = f->per_axis ? f->per_axis : 2;
    pn_real h = wd->dx_m / (pn_real)per;
    long i0[3] = {0, 0, 0}, i1[3] = {0, 0, 0}, a, c, e;
    size_t n = 0;
    for (i = 0; i < d; ++i) { /* lattice cells that can hold a point of the shape */
        i0[i] = (long)PN__MPM_FLOOR((lo[i] - wd->origin_m[i]) / h) - 1;
        i1[i] = (long)PN__MPM_FLOOR((hi[i] - wd->origin_m[i]) / h) + 1;
    }
    for (a = i0[0]; a <= i1[0]; ++a)
        for (c = i0[1]; c <= i1[1]; ++c)
            for (e = i0[2]; e <= (d == 3 ? i1[2] : i0[2]); ++e) {
                long idx[3];
                pn_real p[3] = {0, 0, 0};
                int in = 1;
                idx[0] = a, idx[1] = c, idx[2] = e;
                for (i = 0; i < d; ++i) {
                    pn_real u = f->jitter ? pn__mpm_hash01(f->seed, a, c, e, i) : (pn_real)0.5;
                    p[i] = wd->origin_m[i] + ((pn_real)idx[i] + u) * h;
                }
                if (!pn__mpm_fill_inside(f, b, d, axis, p, open)) continue;
                for (i = 0; i < d; ++i) {
                    pn_real o = wd->origin_m[i];
                    in &= p[i] >= o + wall * wd->dx_m && p[i] <= o + (wd->res[i] - wall) * wd->dx_m;
                }
                if (!in) {
                    if (f->clip) continue;
                    for (i = 0; i < 3; ++i) bad[i] = p[i];
                    return PN_ERROR_INVALID_ARGUMENT;
                }
                if (x)
                    for (i = 0; i < d; ++i) x[n * (size_t)d + (size_t)i] = p[i];
                ++n;
            }
    *count = n;
    return *open ? PN_ERROR_INVALID_ARGUMENT : PN_OK;
}

/* Count (x NULL) or write the fill's points; the mesh bins live for the call. On failure
   *why is a static sentence, or "" for a point outside the walls (bad: the point). */
static pn_result pn__mpm_fill_do(const pn_mpm_desc *wd, const pn_mpm_fill_desc *f, pn_real *x, size_t *count,
                                 const char **why, pn_real *bad) {
    pn__mpm_mesh_bins b;
    pn_real axis[3], lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0}, h = wd->dx_m / (pn_real)(f->per_axis ? f->per_axis : 2);
    int open = 0, wall = wd->wall_cells ? wd->wall_cells : 3;
    pn_result r = pn__mpm_fill_valid(wd, f, axis, why);
    *count = 0;
    memset(&b, 0, sizeof b);
    if (r == PN_OK && (r = pn__mpm_fill_range(wd, wall, f, axis, h, lo, hi, bad)) != PN_OK) *why = "";
    if (r == PN_OK && f->shape == PN_MPM_FILL_MESH) {
        r = pn__mpm_bins_make(&b, f, wd->dim, wd->dx_m, lo, hi, &wd->allocator);
        if (r != PN_OK) *why = "out of memory for the mesh's bins";
    }
    if (r == PN_OK) {
        r = pn__mpm_fill_walk(wd, wall, f, &b, axis, lo, hi, x, count, bad, &open);
        *why = open ? "pn_mpm_fill_desc: the mesh is not closed (a line crosses it an odd number of times)" : "";
    }
    if (b.start) pn_free(&wd->allocator, b.start);
    if (b.item) pn_free(&wd->allocator, b.item);
    return r;
}

static pn_result pn__mpm_fill_count_why(const pn_mpm_desc *wd, const pn_mpm_fill_desc *f, size_t *count, const char **why) {
    pn_real bad[3];
    const char *w = "";
    pn_result r;
    PN_ASSERT(wd && f && count);
    *count = 0;
    if (!pn__dim_ok(wd->dim) || !(wd->dx_m > 0) || !pn__finite(wd->dx_m)) {
        if (why) *why = "pn_mpm_fill_count: the world description's dim or dx_m is invalid";
        return PN_ERROR_INVALID_ARGUMENT;
    }
    r = pn__mpm_fill_do(wd, f, NULL, count, &w, bad);
    if (r != PN_OK && why) *why = *w ? w : "pn_mpm_fill_count: the shape reaches outside the walls (move it, or set clip)";
    return r;
}

PN__DEF pn_result pn_mpm_fill_count(const pn_mpm_desc *wd, const pn_mpm_fill_desc *f, size_t *count, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__mpm_fill_count_why(wd, f, count, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}

PN__DEF pn_result pn_mpm_fill(pn_mpm_world *w, const pn_mpm_fill_desc *f, size_t *added) {
    size_t n = 0, p, q;
    int d, i;
    pn_real vol, mass, bad[3] = {0, 0, 0};
    const char *why = "";
    pn_result r;
    PN_ASSERT(w && f);
    d = w->dim;
    w->error[0] = 0;
    if (added) *added = 0;
    if (f->group < 0 || f->group >= w->n_groups)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_fill: group %d does not exist (%d groups)", f->group,
                            w->n_groups);
    r = pn__mpm_fill_do(&w->desc, f, NULL, &n, &why, bad);
    if (r != PN_OK && *why) return PN__FAIL(w, r, "%s", why);
    if (r != PN_OK)
        return PN__FAIL(w, r, "pn_mpm_fill: the shape reaches outside the walls at (%g, %g, %g) m (move it, or set "
                            "pn_mpm_fill_desc.clip)", (double)bad[0], (double)bad[1], (double)bad[2]);
    if (n > w->cap - w->n)
        return PN__FAIL(w, PN_ERROR_CAPACITY, "pn_mpm_fill: the shape holds %lu particles; max_particles must be >= %lu "
                            "(it is %lu, %lu in use; pn_mpm_fill_count tells before creating the world)",
                            (unsigned long)n, (unsigned long)(w->n + n), (unsigned long)w->cap, (unsigned long)w->n);
    vol = PN__POW(w->desc.dx_m / (pn_real)(f->per_axis ? f->per_axis : 2), d);
    mass = vol * w->groups[f->group].density_kg_m3;
    if (!(vol > 0) || !pn__finite(mass) || !(mass > 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_fill: particle volume %g m^3 gives mass %g kg", (double)vol,
                            (double)mass);
    /* the walk writes straight into the particle arrays, past the particles in use */
    r = pn__mpm_fill_do(&w->desc, f, w->x + w->n * (size_t)d, &q, &why, bad);
    if (r != PN_OK || q != n) return r != PN_OK ? r : PN_ERROR_INVALID_ARGUMENT;
    for (p = w->n; p < w->n + n; ++p) {
        for (i = 0; i < d; ++i) w->v[p * (size_t)d + (size_t)i] = f->velocity_m_s[i];
        memset(w->C + p * (size_t)(d * d), 0, sizeof(pn_real) * (size_t)(d * d));
        pn__identity(d, w->F + p * (size_t)(d * d));
        w->h[p] = f->state;
        w->vol0[p] = vol;
        w->mass[p] = mass;
        w->group[p] = f->group;
        w->active[p] = 1;
    }
    w->n += n;
    w->s.rec_ok = 0;
    w->s.ctau_ok = 0, w->s.stau_committed = 0;
    if (added) *added = n;
    return PN_OK;
}

/* ======================================================================================
   >>stable-dt: the explicit step bound from the P-wave speed and the particle speeds.
   ====================================================================================== */

/* P-wave modulus of particle p's material in its current state (Pa) */
static pn_real pn__mpm_pwave(const pn_material *m, pn_real h, pn_real J) {
    pn_real K = m->lambda + 2 * m->mu;
    if (m->plastic == PN_PLASTIC_SNOW_STOMAKHIN) K *= PN__EXP(m->snow_xi * (1 - PN__EXP(h)));
    if (J > 0 && J < 1) K /= J; /* compressed material is stiffer (log-strain models ~ 1/J) */
    return K;
}

/* The bound of pn_mpm_stable_dt with every material at rest: never below it (the particles'
   speeds and compression only lower it), and O(groups) where pn_mpm_stable_dt is O(n). 0
   without groups. */
static pn_real pn__mpm_rest_dt(const pn_mpm_world *w) {
    pn_real worst = 0;
    int g;
    for (g = 0; g < w->n_groups; ++g)
        worst = PN__MAX(worst, PN__SQRT(pn__mpm_pwave(&w->groups[g].material, 0, 1) / w->groups[g].density_kg_m3));
    return worst > 0 ? (pn_real)0.9 * w->desc.dx_m / worst : 0;
}

PN__DEF pn_result pn_mpm_stable_dt(const pn_mpm_world *w, pn_real *dt_s) {
    int d, g;
    size_t p;
    pn_real worst = 0;
    PN_ASSERT(w && dt_s);
    d = w->dim;
    if (w->n_groups == 0) return PN_ERROR_INVALID_ARGUMENT;
    for (g = 0; g < w->n_groups; ++g) /* the materials at rest bound it from below */
        worst = PN__MAX(worst, PN__SQRT(pn__mpm_pwave(&w->groups[g].material, 0, 1) / w->groups[g].density_kg_m3));
    for (p = 0; p < w->n; ++p) {
        const pn_group *gr = &w->groups[w->group[p]];
        pn_real J, v2 = 0, c;
        int i;
        if (!w->active[p]) continue;
        J = pn_mat_det(d, w->F + p * (size_t)(d * d));
        for (i = 0; i < d; ++i) v2 += w->v[p * (size_t)d + (size_t)i] * w->v[p * (size_t)d + (size_t)i];
        /* current density rho0 / J */
        c = PN__SQRT(pn__mpm_pwave(&gr->material, w->h[p], J) * (J > 0 ? J : 1) / gr->density_kg_m3);
        worst = PN__MAX(worst, c + PN__SQRT(v2));
    }
    if (!pn__finite(worst) || !(worst > 0)) return PN_ERROR_NONFINITE;
    *dt_s = (pn_real)0.9 * w->desc.dx_m / worst;
    return PN_OK;
}

/* ======================================================================================
   >>bin: quadratic B-splines. For a particle at x (in cells), base = floor(x - 0.5),
   fx = x - base in [0.5, 1.5): w0 = (1.5 - fx)^2 / 2, w1 = 0.75 - (fx - 1)^2,
   w2 = (fx - 0.5)^2 / 2 per axis. Particles are sorted by base node (a stable counting
   sort), so the particles that reach node i are those whose base is i - o, o in {0,1,2}^d,
   and a gather over them sums in a fixed order whatever the thread count.
   ====================================================================================== */

static void pn__mpm_stencil(pn_mpm_world *w, size_t p) {
    int d = w->dim, i;
    pn_real dx = w->desc.dx_m, *W = w->s.pw + p * 9, *fx = w->s.pfx + p * 3;
    size_t flat = 0;
    for (i = 0; i < d; ++i) {
        pn_real xc = (w->x[p * (size_t)d + (size_t)i] - w->desc.origin_m[i]) / dx, f;
        int b = (int)floor((double)(xc - (pn_real)0.5));
        f = xc - (pn_real)b;
        fx[i] = f;
        PN__BSPLINE2(W[i * 3 + 0], W[i * 3 + 1], W[i * 3 + 2], f, pn_real);
        flat += (size_t)b * w->s.stride[i];
    }
    w->s.pbase[p] = flat;
}

/* weight of particle p at its stencil offset o (0..2 per axis) and the offset node -
   particle (m) */
static pn_real pn__mpm_weight(const pn_mpm_world *w, size_t p, const int *o, pn_real *dpos) {
    const pn_real *W = w->s.pw + p * 9, *fx = w->s.pfx + p * 3;
    pn_real dx = w->desc.dx_m, a = W[o[0]], b = W[3 + o[1]], c = 1;
    if (w->dim == 3) {
        c = W[6 + o[2]];
        dpos[2] = ((pn_real)o[2] - fx[2]) * dx;
    }
    dpos[0] = ((pn_real)o[0] - fx[0]) * dx;
    dpos[1] = ((pn_real)o[1] - fx[1]) * dx;
    return a * b * c;
}

static void pn__mpm_node_index(const pn_mpm_world *w, size_t node, int *idx) {
    int i;
    for (i = w->dim - 1; i >= 0; --i) {
        idx[i] = (int)(node % (size_t)(w->desc.res[i] + 1));
        node /= (size_t)(w->desc.res[i] + 1);
    }
}

/* The base nodes (and the slot each is seen from: its offsets o, its index sl) whose
   particles reach node `node`. */
static int pn__mpm_node_bases(const pn_mpm_world *w, size_t node, size_t *base, int (*o)[3], int *sl) {
    int idx[3], s, i, n = 0;
    pn__mpm_node_index(w, node, idx);
    for (s = 0; s < w->s.ns; ++s) {
        int ok = 1;
        for (i = 0; i < w->dim; ++i) ok &= idx[i] >= w->s.slot[s][i];
        if (!ok) continue;
        for (i = 0; i < 3; ++i) o[n][i] = w->s.slot[s][i];
        sl[n] = s;
        base[n++] = node - w->s.slot_off[s];
    }
    return n;
}

static void pn__mpm_bin(pn_mpm_world *w) {
    size_t p, k, prev = (size_t)-1;
    long lp;
    int s;
    for (k = 0; k < w->s.n_act; ++k) w->s.dof[w->s.act[k]] = -1;
    PN__OMP_FOR
    for (lp = 0; lp < (long)w->n; ++lp)
        if (w->active[lp]) pn__mpm_stencil(w, (size_t)lp);
    /* stable counting sort by base node */
    memset(w->s.start, 0, sizeof(size_t) * (w->s.nodes + 1));
    for (p = 0; p < w->n; ++p)
        if (w->active[p]) w->s.start[w->s.pbase[p] + 1]++;
    for (k = 0; k < w->s.nodes; ++k) w->s.start[k + 1] += w->s.start[k];
    for (p = 0; p < w->n; ++p)
        if (w->active[p]) w->s.order[w->s.start[w->s.pbase[p]]++] = p;
    for (k = w->s.nodes; k > 0; --k) w->s.start[k] = w->s.start[k - 1];
    w->s.start[0] = 0;
    /* active nodes: the stencils of the occupied base nodes, listed in ascending order */
    for (k = 0; k < w->s.start[w->s.nodes]; ++k) {
        size_t b = w->s.pbase[w->s.order[k]];
        if (b == prev) continue;
        prev = b;
        for (s = 0; s < w->s.ns; ++s) w->s.mark[b + w->s.slot_off[s]] = 1;
    }
    w->s.n_act = 0;
    for (k = 0; k < w->s.nodes; ++k)
        if (w->s.mark[k]) {
            w->s.mark[k] = 0;
            w->s.dof[k] = (long)w->s.n_act;
            w->s.act[w->s.n_act++] = k;
        }
}

/* E = exp(M) (d x d) by scaling and squaring: M / 2^s with |M / 2^s|_1 <= 1/4, its Taylor
   series to degree 12 (a remainder below 3e-18 of the result), then s squarings */
/* C = A B for d x d matrices: pn_mat_mul's sums, each as it makes them (0 + the first product,
   so even the sign of a zero is the same), spelled out in 3D where the loops of a runtime d
   cost more than the products */
static inline void pn__mpm_mul(int d, const pn_real *A, const pn_real *B, pn_real *C) {
    int i, j;
    if (d != 3) {
        pn_mat_mul(d, A, B, C);
        return;
    }
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) C[i * 3 + j] = ((0 + A[i * 3] * B[j]) + A[i * 3 + 1] * B[3 + j]) + A[i * 3 + 2] * B[6 + j];
}

static void pn__mpm_mat_exp(int d, const pn_real *M, pn_real *E) {
    int dd = d * d, i, k, s = 0;
    pn_real A[9], T[9], R[9], norm = 0;
    for (i = 0; i < d; ++i) { /* the 1-norm: largest column sum */
        pn_real col = 0;
        for (k = 0; k < d; ++k) col += PN__FABS(M[k * d + i]);
        norm = PN__MAX(norm, col);
    }
    while (norm > (pn_real)0.25 && s < 60) norm /= 2, ++s;
    for (i = 0; i < dd; ++i) A[i] = (pn_real)ldexp((double)M[i], -s);
    for (i = 0; i < dd; ++i) E[i] = (i % (d + 1) == 0) + A[i] / 12; /* Horner: I + A/12 */
    for (k = 11; k >= 1; --k) { /* E = I + A E / k */
        pn__mpm_mul(d, A, E, T);
        for (i = 0; i < dd; ++i) E[i] = (i % (d + 1) == 0) + T[i] / (pn_real)k;
    }
    for (k = 0; k < s; ++k) {
        pn__mpm_mul(d, E, E, R);
        memcpy(E, R, sizeof(pn_real) * (size_t)dd);
    }
}

/* ======================================================================================
   >>transfer: APIC with D^-1 = 4 / dx^2 (quadratic splines). Particle to grid is a gather
   per active node (the implicit step's compact grid; >>explicit scatters to a dense one):
   mass and momentum m_p (v_p + C_p (x_i - x_p)). grid_v holds momentum after this; with
   filter_time_s > 0, grid_v0 holds the velocity of the transfer, the v_i^n of the FLIP update.
   ====================================================================================== */

static void pn__mpm_p2g(pn_mpm_world *w) {
    int d = w->dim, dd = d * d;
    long lk;
    PN__OMP_FOR
    for (lk = 0; lk < (long)w->s.n_act; ++lk) {
        size_t k = (size_t)lk, base[27], s;
        int o[27][3], sl[27], nb = pn__mpm_node_bases(w, w->s.act[k], base, o, sl), b, i, j;
        pn_real m = 0, mom[3] = {0, 0, 0};
        if (d == 3) { /* spelled out (see pn__mpm_push2), each term as the loops below make it */
            pn_real m0 = 0, m1 = 0, m2 = 0, dx = w->desc.dx_m;
            for (b = 0; b < nb; ++b)
                for (s = w->s.start[base[b]]; s < w->s.start[base[b] + 1]; ++s) {
                    size_t p = w->s.order[s];
                    const pn_real *W = w->s.pw + p * 9, *fx = w->s.pfx + p * 3;
                    const pn_real *vp = w->v + p * 3, *C = w->C + p * 9;
                    pn_real wm = W[o[b][0]] * W[3 + o[b][1]] * W[6 + o[b][2]] * w->mass[p];
                    pn_real d0 = ((pn_real)o[b][0] - fx[0]) * dx, d1 = ((pn_real)o[b][1] - fx[1]) * dx;
                    pn_real d2 = ((pn_real)o[b][2] - fx[2]) * dx;
                    m += wm;
                    m0 += wm * (vp[0] + C[0] * d0 + C[1] * d1 + C[2] * d2);
                    m1 += wm * (vp[1] + C[3] * d0 + C[4] * d1 + C[5] * d2);
                    m2 += wm * (vp[2] + C[6] * d0 + C[7] * d1 + C[8] * d2);
                }
            mom[0] = m0, mom[1] = m1, mom[2] = m2;
        } else
        for (b = 0; b < nb; ++b)
            for (s = w->s.start[base[b]]; s < w->s.start[base[b] + 1]; ++s) {
                size_t p = w->s.order[s];
                pn_real dpos[3], wt = pn__mpm_weight(w, p, o[b], dpos), wm = wt * w->mass[p];
                const pn_real *vp = w->v + p * (size_t)d, *C = w->C + p * (size_t)dd;
                m += wm;
                for (i = 0; i < d; ++i) {
                    pn_real acc = vp[i];
                    for (j = 0; j < d; ++j) acc += C[i * d + j] * dpos[j];
                    mom[i] += wm * acc;
                }
            }
        w->s.grid_m[k] = m;
        for (i = 0; i < d; ++i) {
            w->s.grid_v[k * (size_t)d + (size_t)i] = mom[i];
            if (w->desc.filter_time_s > 0) w->s.grid_v0[k * (size_t)d + (size_t)i] = m > 0 ? mom[i] / m : 0;
        }
    }
}

/* out = base + dt sum_s v_(node of slot s) q_ps^T (base NULL: 0). With base F_p^n this is
   F_p(v) = (I + dt sum_i v_i g_ip^T) F_p^n (>>implicit); q and the slots' nodes come from
   pn__mpm_implicit_setup, so only implicit steps use it. */
/* The dimension is spelled out in the two kernels: with loops of a runtime (or even a
   constant) length of 2 or 3, gcc -O2 keeps the accumulators in memory and this product,
   the inner loop of every Hessian product, runs several times slower. */
/* the _at kernels take one stencil's weights q and nodes dof (>>stress: a cell's as well) */
static void pn__mpm_push2_at(const pn_real *q, const long *dof, const pn_real *v, pn_real dt,
                             const pn_real *base, pn_real *out) {
    pn_real a00 = 0, a01 = 0, a10 = 0, a11 = 0;
    int s;
    for (s = 0; s < 9; ++s, q += 2) {
        const pn_real *vi = v + (size_t)dof[s] * 2;
        a00 += vi[0] * q[0];
        a01 += vi[0] * q[1];
        a10 += vi[1] * q[0];
        a11 += vi[1] * q[1];
    }
    out[0] = (base ? base[0] : 0) + dt * a00;
    out[1] = (base ? base[1] : 0) + dt * a01;
    out[2] = (base ? base[2] : 0) + dt * a10;
    out[3] = (base ? base[3] : 0) + dt * a11;
}

static void pn__mpm_push3_at(const pn_real *q, const long *dof, const pn_real *v, pn_real dt,
                             const pn_real *base, pn_real *out) {
    pn_real a[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    pn_real a00 = 0, a01 = 0, a02 = 0, a10 = 0, a11 = 0, a12 = 0, a20 = 0, a21 = 0, a22 = 0;
    int s, i;
    for (s = 0; s < 27; ++s, q += 3) {
        const pn_real *vi = v + (size_t)dof[s] * 3;
        a00 += vi[0] * q[0];
        a01 += vi[0] * q[1];
        a02 += vi[0] * q[2];
        a10 += vi[1] * q[0];
        a11 += vi[1] * q[1];
        a12 += vi[1] * q[2];
        a20 += vi[2] * q[0];
        a21 += vi[2] * q[1];
        a22 += vi[2] * q[2];
    }
    a[0] = a00, a[1] = a01, a[2] = a02, a[3] = a10, a[4] = a11, a[5] = a12, a[6] = a20, a[7] = a21, a[8] = a22;
    for (i = 0; i < 9; ++i) out[i] = (base ? base[i] : 0) + dt * a[i];
}

static void pn__mpm_push2(const pn_mpm_world *w, size_t j, const pn_real *v, pn_real dt,
                          const pn_real *base, pn_real *out) { /* by sorted index j */
    pn__mpm_push2_at(w->s.pq + j * 18, w->s.pdof + j * 9, v, dt, base, out);
}

static void pn__mpm_push3(const pn_mpm_world *w, size_t j, const pn_real *v, pn_real dt,
                          const pn_real *base, pn_real *out) {
    pn__mpm_push3_at(w->s.pq + j * 81, w->s.pdof + j * 27, v, dt, base, out);
}

static void pn__mpm_push(const pn_mpm_world *w, size_t p, const pn_real *v, pn_real dt,
                         const pn_real *base, pn_real *out) { /* by particle index p */
    if (w->dim == 2) pn__mpm_push2(w, w->s.prank[p], v, dt, base, out);
    else pn__mpm_push3(w, w->s.prank[p], v, dt, base, out);
}

/* Grid to particles into scratch: APIC v, C (with filter_time_s > 0, AFLIP: v = v_PIC +
   (1 - s)(v_p - sum_i w_ip v_i^n), v_i^n the transfer's own velocity); x += dt v_PIC;
   F = F^n + dt sum v q^T, as the implicit energy saw it; then the return mapping. gvel
   (optional; the coupled theta method): the grid's end-of-step velocities for v and C, the
   motion (x, F) from gv_all. Per particle: pstat = error code | 0x100 plastic | 0x200 left the grid
   (retired) | 0x400 moved past the advection limit | 0x800 left where outflow is not allowed. */
static pn_result pn__return_tau(const pn_material *m, int d, const pn_real *F, pn_real h, pn_real *Z,
                                pn_real *h_new, pn_real *tau, int *plastic); /* >>explicit */

/* pn__mpm_g2p's sums over particle q's stencil in 3D, spelled out (see pn__mpm_push2: loops of
   the runtime dimension keep the sums in memory), each term as the generic loop makes it, so the
   bits are the same: nv, nC from gv, nm from gm, ov from g0 (NULL: not summed) */
static void pn__mpm_g2p_sums3(const pn_mpm_world *w, size_t q, const pn_real *gv, const pn_real *gm,
                              const pn_real *g0, pn_real *nv, pn_real *nm, pn_real *ov, pn_real *nC) {
    const pn_real *W = w->s.pw + q * 9, *fx = w->s.pfx + q * 3;
    pn_real dx = w->desc.dx_m, k = 4 * (1 / dx) * (1 / dx);
    pn_real v0 = 0, v1 = 0, v2 = 0, m0 = 0, m1 = 0, m2 = 0, o0 = 0, o1 = 0, o2 = 0;
    pn_real c00 = 0, c01 = 0, c02 = 0, c10 = 0, c11 = 0, c12 = 0, c20 = 0, c21 = 0, c22 = 0;
    int s;
    for (s = 0; s < 27; ++s) {
        const int *o = w->s.slot[s];
        size_t node = (size_t)w->s.dof[w->s.pbase[q] + w->s.slot_off[s]] * 3;
        pn_real wt = W[o[0]] * W[3 + o[1]] * W[6 + o[2]];
        pn_real d0 = ((pn_real)o[0] - fx[0]) * dx, d1 = ((pn_real)o[1] - fx[1]) * dx, d2 = ((pn_real)o[2] - fx[2]) * dx;
        const pn_real *a = gv + node, *b = gm + node;
        pn_real kw = k * wt, e0 = kw * a[0], e1 = kw * a[1], e2 = kw * a[2];
        v0 += wt * a[0], v1 += wt * a[1], v2 += wt * a[2];
        m0 += wt * b[0], m1 += wt * b[1], m2 += wt * b[2];
        if (g0) o0 += wt * g0[node], o1 += wt * g0[node + 1], o2 += wt * g0[node + 2];
        c00 += e0 * d0, c01 += e0 * d1, c02 += e0 * d2;
        c10 += e1 * d0, c11 += e1 * d1, c12 += e1 * d2;
        c20 += e2 * d0, c21 += e2 * d1, c22 += e2 * d2;
    }
    nv[0] = v0, nv[1] = v1, nv[2] = v2, nm[0] = m0, nm[1] = m1, nm[2] = m2, ov[0] = o0, ov[1] = o1, ov[2] = o2;
    nC[0] = c00, nC[1] = c01, nC[2] = c02, nC[3] = c10, nC[4] = c11, nC[5] = c12, nC[6] = c20, nC[7] = c21, nC[8] = c22;
}

static pn_result pn__mpm_g2p(pn_mpm_world *w, const pn_real *gv_all, const pn_real *gvel, pn_real dt, pn_mpm_stats *st) {
    int d = w->dim, dd = d * d, nt = d * (d + 1) / 2;
    long lp;
    size_t p;
    pn_real inv_dx = 1 / w->desc.dx_m, tf = w->desc.filter_time_s;
    pn_real flip = tf > 0 && dt < tf ? 1 - dt / tf : 0; /* the FLIP share 1 - s */
    pn_real reach = w->desc.advection_limit * w->desc.dx_m / dt; /* the fastest honest speed */
    pn_result r;
    if (w->s.stress_on == 2) { /* each cell's dt L_c, once: after its two stresses in the cell's record */
        size_t np = w->s.start[w->s.nodes];
        const size_t *crep = w->s.sgrp + 2 * np;
        PN__OMP_FOR
        for (lp = 0; lp < (long)np; ++lp) {
            size_t r = (size_t)lp;
            const pn_real *b = w->s.pb + r * (size_t)(w->s.ns * d);
            pn_real *Lc = w->s.pH + r * (size_t)(dd * dd) + 2 * dd + 2;
            if (crep[r] != r || w->s.phG[r] == 0) continue;
            if (d == 2) pn__mpm_push2_at(b, w->s.pdof + r * (size_t)w->s.ns, gv_all, dt / w->s.phG[r], NULL, Lc);
            else pn__mpm_push3_at(b, w->s.pdof + r * (size_t)w->s.ns, gv_all, dt / w->s.phG[r], NULL, Lc);
        }
    }
    PN__OMP_FOR
    for (lp = 0; lp < (long)w->n; ++lp) {
        size_t q = (size_t)lp;
        const pn_group *g = &w->groups[w->group[q]];
        pn_real nv[3] = {0, 0, 0}, nm[3] = {0, 0, 0}, ov[3] = {0, 0, 0}, nC[9] = {0}, Fn[9], Z[9], tau[9], hn;
        pn_real *xp = w->x + q * (size_t)d;
        int i, j, s, stat, plastic = 0;
        w->s.sactive[q] = w->active[q];
        w->s.pstat[q] = 0;
        if (!w->active[q]) { /* retired particles keep their last state */
            memcpy(w->s.sx + q * (size_t)d, xp, sizeof(pn_real) * (size_t)d);
            memcpy(w->s.sv + q * (size_t)d, w->v + q * (size_t)d, sizeof(pn_real) * (size_t)d);
            memcpy(w->s.sC + q * (size_t)dd, w->C + q * (size_t)dd, sizeof(pn_real) * (size_t)dd);
            memcpy(w->s.sF + q * (size_t)dd, w->F + q * (size_t)dd, sizeof(pn_real) * (size_t)dd);
            w->s.sh[q] = w->h[q];
            continue;
        }
        if (d == 3)
            pn__mpm_g2p_sums3(w, q, gvel ? gvel : gv_all, gv_all, flip > 0 ? w->s.grid_v0 : NULL, nv, nm, ov, nC);
        else
        for (s = 0; s < w->s.ns; ++s) {
            size_t node = (size_t)w->s.dof[w->s.pbase[q] + w->s.slot_off[s]] * (size_t)d;
            const pn_real *gv = (gvel ? gvel : gv_all) + node;
            pn_real dpos[3], wt = pn__mpm_weight(w, q, w->s.slot[s], dpos);
            for (i = 0; i < d; ++i) {
                nv[i] += wt * gv[i];
                nm[i] += wt * gv_all[node + (size_t)i];
                if (flip > 0) ov[i] += wt * w->s.grid_v0[node + (size_t)i];
                for (j = 0; j < d; ++j) nC[i * d + j] += 4 * inv_dx * inv_dx * wt * gv[i] * dpos[j];
            }
        }
        if (w->s.stress_on) { /* pq holds g: F = exp(dt sum v g^T) F^n (cells: L_c, >>stress) */
            pn_real L[9];
            if (gvel) pn__mpm_push(w, q, gv_all, dt, NULL, L);
            else /* C above is sum v g^T (g = (4/dx^2) w dpos), which push would sum again */
                for (i = 0; i < dd; ++i) L[i] = dt * nC[i];
            if (w->s.stress_on == 2) { /* the cell's strain rate, the particle's own spin */
                size_t r = w->s.sgrp[2 * w->s.start[w->s.nodes] + w->s.prank[q]];
                const pn_real *Lc0 = w->s.pH + r * (size_t)(dd * dd) + 2 * dd + 2;
                pn_real Lc[9];
                int a, e;
                for (a = 0; a < d; ++a)
                    for (e = 0; e < d; ++e)
                        Lc[a * d + e] = (Lc0[a * d + e] + Lc0[e * d + a]) / 2 + (L[a * d + e] - L[e * d + a]) / 2;
                memcpy(L, Lc, sizeof(pn_real) * (size_t)dd);
            }
            { /* F = exp(dt L) F^n, what the rate law integrates to: with I + dt L instead, the
                 step's rotations stretch F by (dt |W|)^2 / 2, which the solve's stresses never
                 saw (at 1/60 s, E = 1e7 Pa, a column gained 12% of its energy in a step, and
                 ran out 10% further; with the exponential it loses energy, 3% short) */
                pn_real Ex[9];
                pn__mpm_mat_exp(d, L, Ex);
                pn__mpm_mul(d, Ex, w->F + q * (size_t)dd, Fn);
            }
        } else {
            pn__mpm_push(w, q, gv_all, dt, w->F + q * (size_t)dd, Fn);
        }
        /* pn_return_map's Z and its checks, and the stress of Z from the same SVD */
        stat = !pn__all_finite(dd, Fn) || !pn__finite(w->h[q])
                   ? (int)PN_ERROR_NONFINITE
                   : (int)pn__return_tau(&g->material, d, Fn, w->h[q], Z, &hn, tau, &plastic);
        if (stat == PN_OK && (!pn__finite(hn) || !pn__all_finite(dd, Z) || !pn__all_finite(dd, tau) ||
                              !pn__all_finite(d, nv) || !pn__all_finite(dd, nC)))
            stat = PN_ERROR_OVERFLOW;
        if (stat != PN_OK) {
            w->s.pstat[q] = stat;
            continue;
        }
        for (s = 0, i = 0; i < d; ++i)
            for (j = i; j < d; ++j) w->s.stau[q * (size_t)nt + (size_t)s++] = tau[i * d + j];
        if (hn != w->h[q] || memcmp(Z, Fn, sizeof(pn_real) * (size_t)dd) != 0) stat |= 0x100;
        for (i = 0; i < d; ++i) {
            w->s.sv[q * (size_t)d + (size_t)i] = nv[i] + flip * (w->v[q * (size_t)d + (size_t)i] - ov[i]);
            w->s.sx[q * (size_t)d + (size_t)i] = xp[i] + dt * nm[i];
            if (!(PN__FABS(nm[i]) <= reach)) stat |= 0x400; /* more than the limit along an axis */
        }
        memcpy(w->s.sC + q * (size_t)dd, nC, sizeof(pn_real) * (size_t)dd);
        memcpy(w->s.sF + q * (size_t)dd, Z, sizeof(pn_real) * (size_t)dd);
        w->s.sh[q] = hn;
        if (!pn__mpm_in_grid(w, w->s.sx + q * (size_t)d)) { /* went through a wall */
            w->s.sactive[q] = 0;
            stat |= w->desc.allow_outflow ? 0x200 : 0x800;
        } else {
            pn__mpm_wall_plane(w, w->s.sx + q * (size_t)d);
        }
        w->s.pstat[q] = stat;
    }
    w->s.stau_state = 0;
    r = pn__mpm_first_error(w, dt);
    if (r != PN_OK) return r;
    w->s.stau_state = 1;
    for (p = 0; p < w->n; ++p) {
        pn_real sp = 0;
        int i;
        if (!w->active[p]) continue;
        if (w->s.pstat[p] & 0x100) st->plastic++;
        if (w->s.pstat[p] & 0x200) {
            st->left_domain++;
            continue;
        }
        for (i = 0; i < d; ++i) sp += w->s.sv[p * (size_t)d + (size_t)i] * w->s.sv[p * (size_t)d + (size_t)i];
        st->particles++;
        st->max_speed_m_s = PN__MAX(st->max_speed_m_s, PN__SQRT(sp));
    }
    return PN_OK;
}

/* the new state in scratch becomes the world */
static void pn__mpm_commit(pn_mpm_world *w, pn_real dt, pn_mpm_stats *st) {
    pn_real *t;
    unsigned char *u;
    t = w->x; w->x = w->s.sx; w->s.sx = t;
    t = w->v; w->v = w->s.sv; w->s.sv = t;
    t = w->C; w->C = w->s.sC; w->s.sC = t;
    t = w->F; w->F = w->s.sF; w->s.sF = t;
    t = w->h; w->h = w->s.sh; w->s.sh = t;
    u = w->active; w->active = w->s.sactive; w->s.sactive = u;
    w->s.rec_ok = 0; /* the explicit step, which keeps the stress, sets it again */
    w->s.ctau_ok = 0; /* a successful implicit call swaps stau in (pn__mpm_tau_keep) */
    w->s.stau_committed = w->s.stau_state;
    w->s.stau_state = 0;
    w->left_total += st->left_domain;
    w->time_s += dt;
    w->steps++;
    w->error_particle = -1;
    w->error[0] = 0;
}

/* a successful implicit call: the stresses its last G2P made become the state's (>>implicit-step) */
static void pn__mpm_tau_keep(pn_mpm_world *w) {
    if (w->s.stau_committed) {
        pn_real *t = w->s.ctau;
        w->s.ctau = w->s.stau, w->s.stau = t;
        w->s.ctau_ok = 1;
    }
    w->s.stau_committed = 0;
}

/* The mechanical energy of a state (x, v, F, h of the active particles): kinetic, elastic
   (each group's elastic energy at its elastic F) and gravitational above the domain's lowest
   point along gravity, so every term is >= 0 and the sum is the scale of a change. Per
   particle on threads into pscal, summed in fixed chunks (pn__mpm_sum): the same bits for any
   thread count. 0 if an elastic energy fails. */
static int pn__mpm_mech_energy(pn_mpm_world *w, const pn_real *x, const pn_real *v, const pn_real *F,
                               const pn_real *h, const unsigned char *active, double *e) {
    int d = w->dim, dd = d * d, i;
    long lp;
    double low = 0;
    for (i = 0; i < d; ++i) /* the grid's corner lowest along gravity */
        low += (double)w->desc.gravity[i] * (double)(w->desc.gravity[i] < 0 ? w->s.grid_lo[i] : w->s.grid_hi[i]);
    PN__OMP_FOR
    for (lp = 0; lp < (long)w->n; ++lp) {
        size_t p = (size_t)lp;
        pn_real psi;
        double ke = 0, pe = 0;
        int a;
        w->s.pscal[p] = 0;
        if (!active[p]) continue;
        if (pn_elastic_energy(&w->groups[w->group[p]].material, d, F + p * (size_t)dd, h[p], &psi, NULL, NULL, 0) != PN_OK) {
            w->s.pscal[p] = (pn_real)HUGE_VAL - (pn_real)HUGE_VAL; /* a NaN: the sum says it failed */
            continue;
        }
        for (a = 0; a < d; ++a) {
            ke += (double)v[p * (size_t)d + (size_t)a] * (double)v[p * (size_t)d + (size_t)a];
            pe += (double)w->desc.gravity[a] * (double)x[p * (size_t)d + (size_t)a];
        }
        w->s.pscal[p] = (pn_real)((double)w->mass[p] * (ke / 2 + (low - pe)) + (double)w->vol0[p] * (double)psi);
    }
    *e = (double)pn__mpm_sum(w, w->n, w->s.pscal, NULL);
    return pn__finite((pn_real)*e);
}

/* Before pn__mpm_commit: the step's new state (the scratch arrays) against the current one.
   A rise beyond energy_rise_tol of the current energy fails the step, which leaves the world
   as it was (nothing is committed yet). */
static pn_result pn__mpm_energy_guard(pn_mpm_world *w, const pn_mpm_implicit_desc *o, pn_real dt, pn_mpm_stats *st) {
    double e0, e1, tol = (double)o->energy_rise_tol;
    if (tol == 0) tol = o->formulation == PN_MPM_FORMULATION_STRESS ? -1 : 0.25; /* the default */
    int c;
    if (tol < 0) return PN_OK;
    for (c = 0; c < w->n_colliders; ++c)
        if (w->colliders[c].velocity_m_s[0] != 0 || w->colliders[c].velocity_m_s[1] != 0 ||
            w->colliders[c].velocity_m_s[2] != 0)
            return PN_OK;
    if (!pn__mpm_mech_energy(w, w->x, w->v, w->F, w->h, w->active, &e0) ||
        !pn__mpm_mech_energy(w, w->s.sx, w->s.sv, w->s.sF, w->s.sh, w->s.sactive, &e1) || !(e0 > 0))
        return PN_OK; /* nothing to measure by: the step's own checks stand */
    st->energy_rise = PN__MAX(st->energy_rise, (pn_real)((e1 - e0) / e0));
    if (e1 - e0 > tol * e0)
        return PN__FAIL(w, PN_ERROR_STEP_TOO_LARGE, "implicit step of %g s: the mechanical energy rose from %.4g J to "
                            "%.4g J, by %.3g of it (energy_rise_tol %g), with no work done on the material: the solve's "
                            "answer is wrong for this step; a smaller one holds", (double)dt, e0, e1, (e1 - e0) / e0, tol);
    return PN_OK;
}

/* ======================================================================================
   >>contact: each active node gets the obstacle it is in (the domain walls first, then the
   first collider that contains it): up to d orthonormal directions that point out of the
   obstacle, the obstacle's velocity, its boundary kind and friction. Sticky holds every
   component (relative to the obstacle), slip the normal ones, separate the normal ones
   while the contact pushes. Nodes without mass are held at rest.
   ====================================================================================== */

/* signed distance of x from collider c at time t (negative inside) and the outward normal */
static pn_real pn__mpm_collider_phi(const pn_collider *c, int d, const pn_real *x, pn_real t, pn_real *n) {
    pn_real r[3], phi = 0, len = 0;
    int i, best = 0;
    for (i = 0; i < d; ++i) r[i] = x[i] - (c->center_m[i] + t * c->velocity_m_s[i]);
    for (i = 0; i < 3; ++i) n[i] = 0;
    if (c->shape == PN_SHAPE_HALF_SPACE) {
        for (i = 0; i < d; ++i) {
            phi += r[i] * c->normal[i];
            n[i] = c->normal[i];
        }
        return phi;
    }
    if (c->shape == PN_SHAPE_SPHERE) {
        for (i = 0; i < d; ++i) len += r[i] * r[i];
        len = PN__SQRT(len);
        for (i = 0; i < d; ++i) n[i] = len > 0 ? r[i] / len : (i == d - 1);
        return len - c->radius_m;
    }
    /* box: inside, the nearest face decides the normal */
    for (i = 0; i < d; ++i) {
        pn_real q = PN__FABS(r[i]) - c->half_extent_m[i];
        if (i == 0 || q > phi) {
            phi = q;
            best = i;
        }
    }
    n[best] = r[best] < 0 ? -1 : 1;
    return phi;
}

/* The obstacle grid node idx (with mass m) is in at time t: the number of held directions
   (0: none), the directions (3 per row), the obstacle's velocity, its boundary kind and
   friction. */
static int pn__mpm_obstacle(const pn_mpm_world *w, const int *idx, pn_real m, pn_real t, pn_real *dir, pn_real *vel,
                            int *kind_out, pn_real *mu_out) {
    int d = w->dim, i, j, c, cn = 0, kind = (int)w->desc.boundary;
    pn_real mu = w->desc.friction, xn[3], nrm[3];
    for (i = 0; i < 9; ++i) dir[i] = 0;
    for (i = 0; i < 3; ++i) vel[i] = 0;
    for (i = 0; i < d; ++i) { /* the rows on the planes too (see pn__mpm_wall_plane) */
        if (idx[i] <= w->s.wall) dir[3 * cn++ + i] = 1;
        else if (idx[i] >= w->desc.res[i] - w->s.wall) dir[3 * cn++ + i] = -1;
    }
    if (cn == 0) {
        for (i = 0; i < d; ++i) xn[i] = w->desc.origin_m[i] + (pn_real)idx[i] * w->desc.dx_m;
        for (c = 0; c < w->n_colliders; ++c) {
            const pn_collider *co = &w->colliders[c];
            if (pn__mpm_collider_phi(co, d, xn, t, nrm) > 0) continue;
            cn = 1;
            for (i = 0; i < 3; ++i) {
                dir[i] = nrm[i];
                vel[i] = co->velocity_m_s[i];
            }
            kind = (int)co->boundary;
            mu = co->friction;
            break;
        }
    }
    if (!(m > 0)) { /* no mass: nothing moves it */
        cn = d;
        kind = PN_BOUNDARY_STICKY;
        for (i = 0; i < 3; ++i) vel[i] = 0;
    }
    if (cn > 0 && kind == PN_BOUNDARY_STICKY) {
        cn = d;
        for (i = 0; i < 9; ++i) dir[i] = 0;
        for (j = 0; j < d; ++j) dir[3 * j + j] = 1;
    }
    *kind_out = kind;
    *mu_out = mu;
    return cn;
}

static void pn__mpm_contact(pn_mpm_world *w, pn_real t) {
    long lk;
    PN__OMP_FOR
    for (lk = 0; lk < (long)w->s.n_act; ++lk) {
        size_t k = (size_t)lk;
        int idx[3], kind, cn;
        pn_real mu;
        pn__mpm_node_index(w, w->s.act[k], idx);
        cn = pn__mpm_obstacle(w, idx, w->s.grid_m[k], t, w->s.cdir + k * 9, w->s.cvel + k * 3, &kind, &mu);
        w->s.cn[k] = (unsigned char)cn;
        w->s.ckind[k] = (unsigned char)kind;
        w->s.cmu[k] = mu;
        w->s.clam[k] = 0;
        w->s.chold[k] = (unsigned char)((1 << cn) - 1);
    }
}

/* Explicit grid velocity projection (Stomakhin et al. 2013 style): relative to the obstacle,
   sticky zeroes the velocity, slip removes the normal part, separate removes an approaching
   normal part and reduces the tangential speed by mu |v_n| (Coulomb), not below zero. */
static void pn__mpm_project(int d, int cn, int kind, const pn_real *dir, const pn_real *vel, pn_real mu, pn_real *v) {
    int b, i;
    pn_real u[3] = {0, 0, 0};
    if (cn == 0) return;
    for (i = 0; i < d; ++i) u[i] = kind == PN_BOUNDARY_STICKY ? 0 : v[i] - vel[i];
    for (b = 0; b < cn && kind != PN_BOUNDARY_STICKY; ++b) {
        const pn_real *n = dir + 3 * b;
        pn_real un = 0, ut = 0, sc;
        for (i = 0; i < d; ++i) un += u[i] * n[i];
        if (kind == PN_BOUNDARY_SEPARATE && un >= 0) continue;
        for (i = 0; i < d; ++i) u[i] -= un * n[i];
        if (kind != PN_BOUNDARY_SEPARATE || !(mu > 0)) continue;
        for (i = 0; i < d; ++i) ut += u[i] * u[i];
        ut = PN__SQRT(ut);
        sc = ut > 0 ? PN__MAX(0, ut - mu * PN__FABS(un)) / ut : 0;
        for (i = 0; i < d; ++i) u[i] *= sc;
    }
    for (i = 0; i < d; ++i) v[i] = vel[i] + u[i];
}

#define PN__MPM_STICK 0x80 /* chold flag: separating contact that sticks (every component held) */

/* remove the held components of x (a node vector) */
static void pn__mpm_filter(const pn_mpm_world *w, size_t k, pn_real *x) {
    int d = w->dim, b, i;
    const pn_real *dir = w->s.cdir + k * 9;
    if (w->s.chold[k] & PN__MPM_STICK) {
        for (i = 0; i < d; ++i) x[i] = 0;
        return;
    }
    for (b = 0; b < w->s.cn[k]; ++b) {
        pn_real xn = 0;
        if (!(w->s.chold[k] >> b & 1)) continue;
        for (i = 0; i < d; ++i) xn += x[i] * dir[3 * b + i];
        for (i = 0; i < d; ++i) x[i] -= xn * dir[3 * b + i];
    }
}

/* set the held components of v to the obstacle's */
static void pn__mpm_hold(const pn_mpm_world *w, size_t k, pn_real *v) {
    int d = w->dim, i;
    const pn_real *vel = w->s.cvel + k * 3;
    pn_real u[3];
    for (i = 0; i < d; ++i) u[i] = v[i] - vel[i];
    pn__mpm_filter(w, k, u);
    for (i = 0; i < d; ++i) v[i] = vel[i] + u[i];
}

/* ======================================================================================
   >>explicit: symplectic Euler, MLS-MPM (Hu et al. 2018): P2G of mass, momentum and the
   stress impulse, grid update with gravity and contact, G2P with F = (I + dt C) F and the
   return mapping. Unlike the implicit step's compact gather, it works on a dense grid of
   (m, m v) per node, and P2G scatters the particles in index order: no sort. With threads,
   each thread owns a slab of rows of axis 0 and adds only to them (pn__mpm_xp2g), so each
   node sums its contributions in one fixed order whatever the thread count. P2G widens a
   touched span per line of nodes; the grid update works on the spans, and after G2P they
   are zeroed again. Each particle's Kirchhoff stress comes from the G2P that made its
   state, packed with what P2G reads into one record: one SVD per particle and step.
   ====================================================================================== */

/* 2D fixed corotated, branch-free (pn__mpm_xg2p2_lanes runs it in vector lanes). Write F =
   [e + f, g - hh; g + hh, e - f] (e, hh its conformal part, f, g the anticonformal one): with
   q = |(e, hh)| and r = |(f, g)| the singular values are s0 = q + r and the signed s1 = q - r,
   the polar rotation is R = [c -sn; sn c], (c, sn) = (e, hh) / q, and the stretch R^T F =
   q I + D has the deviator D = R^T F - q I of size r. No division has a condition on it or
   on its divisor (gcc then branches, and does not vectorize): at q = 0 (e = hh = 0) the
   rotation is the identity. pn__fcr2_norms gives q^2 and r^2. */
PN__MPM_INLINE void pn__fcr2_norms(const pn_real *F, pn_real *qq, pn_real *rr) {
    pn_real e = (F[0] + F[3]) / 2, hh = (F[2] - F[1]) / 2, f = (F[0] - F[3]) / 2, g = (F[2] + F[1]) / 2;
    *qq = e * e + hh * hh, *rr = f * f + g * g;
}

PN__MPM_INLINE void pn__fcr2_rotation(const pn_real *F, pn_real q, pn_real *c, pn_real *sn) {
    pn_real qd = q + (q > 0 ? 0 : 1); /* q >= 0: 1 where 0 */
    *c = (F[0] + F[3]) / 2 / qd + (q > 0 ? 0 : 1), *sn = (F[2] - F[1]) / 2 / qd;
}

/* the Kirchhoff stress tau = 2 mu (Z - R) Z^T + lambda (J - 1) J I of a state Z with polar
   rotation R = [c -sn; sn c] */
PN__MPM_INLINE void pn__fcr2_stress(const pn_real *Z, pn_real c, pn_real sn, pn_real mu, pn_real la, pn_real *tau) {
    pn_real J = Z[0] * Z[3] - Z[1] * Z[2], vol = la * (J - 1) * J;
    pn_real A0 = 2 * mu * (Z[0] - c), A1 = 2 * mu * (Z[1] + sn); /* 2 mu (Z - R) */
    pn_real A2 = 2 * mu * (Z[2] - sn), A3 = 2 * mu * (Z[3] - c);
    tau[0] = A0 * Z[0] + A1 * Z[1] + vol, tau[1] = A0 * Z[2] + A1 * Z[3];
    tau[2] = A2 * Z[0] + A3 * Z[1], tau[3] = A2 * Z[2] + A3 * Z[3] + vol;
}

/* The Stomakhin clamp of the stretches to [lo, hi] (Stomakhin et al. 2013), closed form: the
   clamped stretch is m' I + beta D, m' and beta r the mean and half difference of the
   clamped s0, s1, so Z = R (m' I + beta D) = (m' - q beta) R + beta F (F itself where nothing
   clamps). The smallest stretch is signed: an inverted F (s1 < 0) clamps back to det > 0.
   Returns 1 if it clamped, else 0 (a real: the lanes keep every flag as wide as their data,
   or gcc -O2 does not vectorize them in double); ratio = |s0 s1| / (z0 z1), the factor on J_p. */
PN__MPM_INLINE pn_real pn__snow2_clamp(const pn_real *F, pn_real q, pn_real r, pn_real c, pn_real sn, pn_real lo, pn_real hi,
                                   pn_real *Z, pn_real *ratio) {
    pn_real s0 = q + r, s1 = q - r, z0 = PN__MIN(PN__MAX(s0, lo), hi), z1 = PN__MIN(PN__MAX(s1, lo), hi);
    pn_real beta = (z0 - z1) / 2 / (r + (r > 0 ? 0 : 1)), alpha = (z0 + z1) / 2 - q * beta;
    pn_real k = ((z0 != s0) | (z1 != s1)) ? 1 : 0; /* a blend, not a select: gcc would put beta's division under the condition */
    Z[0] = F[0] + k * (alpha * c + beta * F[0] - F[0]), Z[1] = F[1] + k * (-alpha * sn + beta * F[1] - F[1]);
    Z[2] = F[2] + k * (alpha * sn + beta * F[2] - F[2]), Z[3] = F[3] + k * (alpha * c + beta * F[3] - F[3]);
    *ratio = PN__FABS(s0 * s1) / (z0 * z1);
    return k;
}

/* The fast path's parameters of material m: 0 unless it is fixed corotated, elastic or with
   the Stomakhin clamp; else its Lame parameters and box [lo, hi] (+-1e30 without the clamp). */
static int pn__fcr2_params(const pn_material *m, pn_real *mu, pn_real *la, pn_real *lo, pn_real *hi) {
    int snow = m->plastic == PN_PLASTIC_SNOW_STOMAKHIN;
    *mu = m->mu, *la = m->lambda;
    *lo = snow ? 1 - m->theta_c : (pn_real)-1e30, *hi = snow ? 1 + m->theta_s : (pn_real)1e30;
    return m->elastic == PN_ELASTIC_FIXED_COROTATED && (snow || m->plastic == PN_PLASTIC_NONE);
}

/* The 2D Kirchhoff stress of an elastic state F, when the material takes the fast path and F
   is inside its box (then F is its own return mapping); 0 (tau unspecified) otherwise. hard:
   pn__hardening at the plastic state. */
PN__MPM_INLINE int pn__tau_fcr2(const pn_material *m, const pn_real *F, pn_real hard, pn_real *tau) {
    pn_real mu, la, lo, hi, q, r, c, sn;
    if (!pn__fcr2_params(m, &mu, &la, &lo, &hi)) return 0;
    pn__fcr2_norms(F, &q, &r);
    q = PN__SQRT(q), r = PN__SQRT(r);
    if (!(q + r <= hi && q - r >= lo)) return 0;
    pn__fcr2_rotation(F, q, &c, &sn);
    pn__fcr2_stress(F, c, sn, mu * hard, la * hard, tau);
    return 1;
}

/* For the explicit step: Z, h_new and the Kirchhoff stress of the result
   tau(Z) = U diag(t) U^T, all from one SVD. F must be finite; outputs unchecked. */
static pn_result pn__return_tau(const pn_material *m, int d, const pn_real *F, pn_real h, pn_real *Z,
                                pn_real *h_new, pn_real *tau, int *plastic) {
    pn_real U[9], s[3], V[9], z[3], t[3];
    pn_result r;
    if (d == 2 && pn__tau_fcr2(m, F, pn__hardening(m, h), tau)) {
        memcpy(Z, F, sizeof(pn_real) * 4);
        *h_new = h;
        *plastic = 0;
        return PN_OK;
    }
    r = pn__return_core(m, d, F, h, U, s, V, z, h_new, plastic, t);
    if (r != PN_OK) return r;
    if (d == 2) { /* U diag V^T spelled out (the loops of pn__udvt do not unroll for a runtime d) */
        if (*plastic) {
            Z[0] = U[0] * z[0] * V[0] + U[1] * z[1] * V[1], Z[1] = U[0] * z[0] * V[2] + U[1] * z[1] * V[3];
            Z[2] = U[2] * z[0] * V[0] + U[3] * z[1] * V[1], Z[3] = U[2] * z[0] * V[2] + U[3] * z[1] * V[3];
        } else {
            memcpy(Z, F, sizeof(pn_real) * 4);
        }
        tau[0] = U[0] * t[0] * U[0] + U[1] * t[1] * U[1], tau[1] = U[0] * t[0] * U[2] + U[1] * t[1] * U[3];
        tau[2] = tau[1], tau[3] = U[2] * t[0] * U[2] + U[3] * t[1] * U[3];
        return PN_OK;
    }
    if (*plastic) pn__udvt(d, U, z, V, Z);
    else memcpy(Z, F, sizeof(pn_real) * (size_t)(d * d));
    pn__udvt(d, U, t, U, tau);
    return PN_OK;
}

/* the stencil of a particle at x (inside the grid: x/dx >= 1, so truncation is floor): base
   node per axis and x/dx - base, in [0.5, 1.5) */
static inline void pn__mpm_base(const pn_mpm_world *w, const pn_real *x, int *base, pn_real *fx) {
    int i, d = w->dim;
    for (i = 0; i < d; ++i) {
        pn_real xc = (x[i] - w->desc.origin_m[i]) * w->s.inv_dx;
        base[i] = (int)(xc - (pn_real)0.5);
        fx[i] = xc - (pn_real)base[i];
    }
}

#define PN__MPM_SPLINE(W, f) PN__BSPLINE2(W[0], W[1], W[2], f, pn_real) /* >>kit */

/* the stencil base row (axis 0) of a particle at x inside the grid */
static inline int pn__mpm_row_of(const pn_mpm_world *w, const pn_real *x) {
    return (int)((x[0] - w->desc.origin_m[0]) * w->s.inv_dx - (pn_real)0.5);
}

/* What P2G needs of a particle's state beyond x, v, C and m, in one record (written by the G2P
   that made the state, read in index order): k = -V0 (4/dx^2) tau (symmetric, upper triangle),
   so the stress impulse of a step dt is dt k (x_i - x_p) (MLS-MPM, Hu et al. 2018); last, the
   state's pn__hardening, which the next G2P reuses while the particle stays elastic. (x, m v
   and m C are read from the state itself: copies here cost more memory traffic than the
   multiplications they save, and traffic is what bounds a step on two threads.) */
PN__MPM_INLINE void pn__mpm_pack(const pn_mpm_world *w, size_t p, const pn_real *tau, pn_real hard, pn_real *buf,
                                 const int d) {
    int i, j, n = 0, pay = PN__MPM_PAY(d);
    pn_real out[PN__MPM_PAY(3)];
    pn_real k = -w->vol0[p] * (4 * w->s.inv_dx * w->s.inv_dx); /* no division per particle */
    for (i = 0; i < d; ++i)
        for (j = i; j < d; ++j) out[n++] = k * tau[i * d + j];
    out[n] = hard;
    buf = &PN__MPM_REC(buf, p, 0, pay);
    for (i = 0; i < pay; ++i) buf[i * PN__MPM_LANES] = out[i];
}

/* Particle record r's MLS-MPM contribution to the dense grid, on the stencil rows i0 <= i < i1
   (of 0 .. 2; a thread's slab may hold only some): mass and momentum m v + Q (x_i - x_p),
   Q = m C + dt k; when v0 != NULL also the transfer's own momentum m v + m C (x_i - x_p)
   (AFLIP). The dimension is spelled out: see >>transfer. */
static inline void pn__mpm_scatter2(pn_mpm_world *w, size_t p, pn_real dt, pn_real *v0, int i0, int i1, int mark) {
    pn_real k[3], dx = w->desc.dx_m, m = w->mass[p], fx[3], wx[3], wy[3], q00, q01, q10, q11, mv[2], mC[4];
    const pn_real *x = w->x + p * 2, *v = w->v + p * 2, *C = w->C + p * 4;
    pn_real *g;
    int base[3], i, j;
    size_t s0 = w->s.stride[0];
    for (i = 0; i < 3; ++i) k[i] = PN__MPM_REC(w->s.ppay, p, i, PN__MPM_PAY(2));
    for (i = 0; i < 2; ++i) mv[i] = m * v[i];
    for (i = 0; i < 4; ++i) mC[i] = m * C[i];
    q00 = mC[0] + dt * k[0], q01 = mC[1] + dt * k[1], q10 = mC[2] + dt * k[1], q11 = mC[3] + dt * k[2];
    pn__mpm_base(w, x, base, fx);
    PN__MPM_SPLINE(wx, fx[0]);
    PN__MPM_SPLINE(wy, fx[1]);
    if (mark) w->s.bmark[(unsigned)base[0] / PN__MPM_BLOCK * w->s.bstride[0] + (unsigned)base[1] / PN__MPM_BLOCK] = 1;
    g = w->s.gdense + ((size_t)(base[0] + i0) * s0 + (size_t)base[1]) * 4;
    for (i = i0; i < i1; ++i, g += s0 * 4) {
        pn_real ex = ((pn_real)i - fx[0]) * dx, a0 = mv[0] + q00 * ex, a1 = mv[1] + q10 * ex;
        for (j = 0; j < 3; ++j) {
            pn_real ey = ((pn_real)j - fx[1]) * dx, wt = wx[i] * wy[j];
            g[4 * j] += wt * m;
            g[4 * j + 1] += wt * (a0 + q01 * ey);
            g[4 * j + 2] += wt * (a1 + q11 * ey);
        }
    }
    if (v0) {
        pn_real *o = v0 + ((size_t)(base[0] + i0) * s0 + (size_t)base[1]) * 2;
        for (i = i0; i < i1; ++i, o += s0 * 2)
            for (j = 0; j < 3; ++j) {
                pn_real ex = ((pn_real)i - fx[0]) * dx, ey = ((pn_real)j - fx[1]) * dx, wt = wx[i] * wy[j];
                o[2 * j] += wt * (mv[0] + mC[0] * ex + mC[1] * ey);
                o[2 * j + 1] += wt * (mv[1] + mC[2] * ex + mC[3] * ey);
            }
    }
}

static inline void pn__mpm_scatter3(pn_mpm_world *w, size_t p, pn_real dt, pn_real *v0, int i0, int i1, int mark) {
    static const int sym[9] = {0, 1, 2, 1, 3, 4, 2, 4, 5}; /* upper triangle of k */
    pn_real k[6], dx = w->desc.dx_m, m = w->mass[p], fx[3], W[3][3], q[9], mv[3], mC[9];
    const pn_real *x = w->x + p * 3, *v = w->v + p * 3, *C = w->C + p * 9;
    pn_real *g;
    int base[3], i, j, l, c;
    size_t s0 = w->s.stride[0], s1 = w->s.stride[1];
    for (i = 0; i < 6; ++i) k[i] = PN__MPM_REC(w->s.ppay, p, i, PN__MPM_PAY(3));
    for (i = 0; i < 3; ++i) mv[i] = m * v[i];
    for (i = 0; i < 9; ++i) mC[i] = m * C[i];
    pn__mpm_base(w, x, base, fx);
    for (i = 0; i < 3; ++i) PN__MPM_SPLINE(W[i], fx[i]);
    for (c = 0; c < 9; ++c) q[c] = mC[c] + dt * k[sym[c]];
    if (mark)
        w->s.bmark[(unsigned)base[0] / PN__MPM_BLOCK * w->s.bstride[0] + (unsigned)base[1] / PN__MPM_BLOCK * w->s.bstride[1] +
                 (unsigned)base[2] / PN__MPM_BLOCK] = 1;
    g = w->s.gdense + ((size_t)base[0] * s0 + (size_t)base[1] * s1 + (size_t)base[2]) * 4;
    for (i = i0; i < i1; ++i) {
        pn_real ex = ((pn_real)i - fx[0]) * dx;
        pn_real a0 = mv[0] + q[0] * ex, a1 = mv[1] + q[3] * ex, a2 = mv[2] + q[6] * ex;
        for (j = 0; j < 3; ++j) {
            pn_real ey = ((pn_real)j - fx[1]) * dx, wij = W[0][i] * W[1][j];
            pn_real b0 = a0 + q[1] * ey, b1 = a1 + q[4] * ey, b2 = a2 + q[7] * ey;
            pn_real *gn = g + ((size_t)i * s0 + (size_t)j * s1) * 4;
            for (l = 0; l < 3; ++l) {
                pn_real ez = ((pn_real)l - fx[2]) * dx, wt = wij * W[2][l];
                gn[4 * l] += wt * m;
                gn[4 * l + 1] += wt * (b0 + q[2] * ez);
                gn[4 * l + 2] += wt * (b1 + q[5] * ez);
                gn[4 * l + 3] += wt * (b2 + q[8] * ez);
            }
        }
    }
    if (v0)
        for (i = i0; i < i1; ++i)
            for (j = 0; j < 3; ++j)
                for (l = 0; l < 3; ++l) {
                    pn_real e[3], wt = W[0][i] * W[1][j] * W[2][l];
                    pn_real *o = v0 + ((size_t)(base[0] + i) * s0 + (size_t)(base[1] + j) * s1 + (size_t)(base[2] + l)) * 3;
                    e[0] = ((pn_real)i - fx[0]) * dx, e[1] = ((pn_real)j - fx[1]) * dx, e[2] = ((pn_real)l - fx[2]) * dx;
                    for (c = 0; c < 3; ++c) o[c] += wt * (mv[c] + mC[3 * c] * e[0] + mC[3 * c + 1] * e[1] + mC[3 * c + 2] * e[2]);
                }
}

/* Float nodes take one 4-wide vector add (mass, momentum, the zero pad of a 2D node) where
   the target has one: the bits of four scalar adds. (Double gains nothing: two adds for three
   values, and the transposition costs more than it saves.) */
#if defined(__SSE2__) || defined(__AVX__)
#define PN__MPM_ADD4 (sizeof(pn_real) == 4)
#else
#define PN__MPM_ADD4 0
#endif

/* t[l][0 .. 3] = (r[0][l], r[1][l], r[2][l], 0), l < PN__MPM_LANES (8), for float: three lane
   rows turned into one 4-vector per lane, for pn__mpm_add4 */
static inline void pn__mpm_transpose3(pn_real (*r)[PN__MPM_LANES], pn_real (*t)[4]) {
#if defined(__SSE2__) || defined(__AVX__)
    int h;
    for (h = 0; h < PN__MPM_LANES; h += 4) {
        __m128 a = _mm_loadu_ps((const float *)r[0] + h), b = _mm_loadu_ps((const float *)r[1] + h);
        __m128 c = _mm_loadu_ps((const float *)r[2] + h), z = _mm_setzero_ps();
        _MM_TRANSPOSE4_PS(a, b, c, z);
        _mm_storeu_ps((float *)t[h], a), _mm_storeu_ps((float *)t[h + 1], b);
        _mm_storeu_ps((float *)t[h + 2], c), _mm_storeu_ps((float *)t[h + 3], z);
    }
#else
    (void)r, (void)t;
#endif
}

/* g[0 .. 3] += c[0 .. 3] in float */
static inline void pn__mpm_add4(pn_real *g, const pn_real *c) {
#if defined(__SSE2__) || defined(__AVX__)
    _mm_storeu_ps((float *)g, _mm_add_ps(_mm_loadu_ps((const float *)g), _mm_loadu_ps((const float *)c)));
#else
    (void)g, (void)c;
#endif
}

/* 2D P2G (APIC) of n <= PN__MPM_LANES particles, rows [r0, r1) of axis 0: idx[0 .. n - 1]
   (ascending), or with idx NULL the whole block of PN__MPM_LANES from p0. Each one's nine node
   contributions are computed in lanes the compiler can vectorize, then added particle by
   particle, node by node (mass, momentum and the zero pad of a 2D node in one vector add):
   pn__mpm_scatter2's arithmetic and order, so the same bits. mark as there, per particle. */
static void pn__mpm_scatter2_lanes(pn_mpm_world *w, size_t p0, const size_t *idx, int n, pn_real dt, int r0, int r1,
                                   const unsigned char *mark) {
    enum { L = PN__MPM_LANES, pay = PN__MPM_PAY(2) };
    pn_real rec[12][L], c[9][3][L], t[9][L][4], fx0[L], fx1[L], wx[3][L], wy[3][L], q00[L], q01[L], q10[L], q11[L];
    pn_real dx = w->desc.dx_m, inv_dx = w->s.inv_dx;
    pn_real ox = w->desc.origin_m[0], oy = w->desc.origin_m[1];
    unsigned char *bmark = w->s.bmark;
    int b0[L], b1[L], i, j, l, k;
    size_t s0 = w->s.stride[0], bs0 = w->s.bstride[0];
    if (!idx) { /* a whole block: x, m, m v, m C (as pn__mpm_scatter2) and the record's k */
        const pn_real *X = w->x + p0 * 2, *V = w->v + p0 * 2, *Cp = w->C + p0 * 4, *M = w->mass + p0;
        const pn_real *R = &PN__MPM_REC(w->s.ppay, p0, 0, pay);
        for (l = 0; l < L; ++l) {
            pn_real m = M[l];
            rec[0][l] = X[2 * l], rec[1][l] = X[2 * l + 1], rec[2][l] = m;
            rec[3][l] = m * V[2 * l], rec[4][l] = m * V[2 * l + 1];
            for (k = 0; k < 4; ++k) rec[5 + k][l] = m * Cp[4 * l + k];
            for (k = 0; k < 3; ++k) rec[9 + k][l] = R[k * L + l];
        }
    } else
        for (l = 0; l < L; ++l) { /* past n: lane 0 */
            size_t q = idx[l < n ? l : 0];
            pn_real m = w->mass[q];
            rec[0][l] = w->x[2 * q], rec[1][l] = w->x[2 * q + 1], rec[2][l] = m;
            rec[3][l] = m * w->v[2 * q], rec[4][l] = m * w->v[2 * q + 1];
            for (k = 0; k < 4; ++k) rec[5 + k][l] = m * w->C[4 * q + (size_t)k];
            for (k = 0; k < 3; ++k) rec[9 + k][l] = PN__MPM_REC(w->s.ppay, q, k, pay);
        }
    for (l = 0; l < L; ++l) { /* loops over l innermost: gcc -O2 vectorizes them, and unrolls no inner loop */
        pn_real xc = (rec[0][l] - ox) * inv_dx, yc = (rec[1][l] - oy) * inv_dx;
        q00[l] = rec[5][l] + dt * rec[9][l], q01[l] = rec[6][l] + dt * rec[10][l];
        q10[l] = rec[7][l] + dt * rec[10][l], q11[l] = rec[8][l] + dt * rec[11][l];
        b0[l] = (int)(xc - (pn_real)0.5), b1[l] = (int)(yc - (pn_real)0.5);
        fx0[l] = xc - (pn_real)b0[l], fx1[l] = yc - (pn_real)b1[l];
        PN__BSPLINE2(wx[0][l], wx[1][l], wx[2][l], fx0[l], pn_real);
        PN__BSPLINE2(wy[0][l], wy[1][l], wy[2][l], fx1[l], pn_real);
    }
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) {
            for (l = 0; l < L; ++l) {
                pn_real ex = ((pn_real)i - fx0[l]) * dx, a0 = rec[3][l] + q00[l] * ex, a1 = rec[4][l] + q10[l] * ex;
                pn_real ey = ((pn_real)j - fx1[l]) * dx, wt = wx[i][l] * wy[j][l];
                c[3 * i + j][0][l] = wt * rec[2][l];
                c[3 * i + j][1][l] = wt * (a0 + q01[l] * ey);
                c[3 * i + j][2][l] = wt * (a1 + q11[l] * ey);
            }
            if (PN__MPM_ADD4) pn__mpm_transpose3(c[3 * i + j], t[3 * i + j]);
        }
    for (l = 0; l < n; ++l) {
        int i0 = PN__MAX(r0 - b0[l], 0), i1 = PN__MIN(r1 - b0[l], 3);
        pn_real *g = w->s.gdense + ((size_t)b0[l] * s0 + (size_t)b1[l]) * 4;
        if (mark[l]) bmark[(unsigned)b0[l] / PN__MPM_BLOCK * bs0 + (unsigned)b1[l] / PN__MPM_BLOCK] = 1;
        for (i = i0; i < i1; ++i) {
            pn_real *gi = g + (size_t)i * s0 * 4;
            if (PN__MPM_ADD4) {
                pn__mpm_add4(gi, t[3 * i][l]);
                pn__mpm_add4(gi + 4, t[3 * i + 1][l]);
                pn__mpm_add4(gi + 8, t[3 * i + 2][l]);
            } else
                for (j = 0; j < 3; ++j) {
                    gi[4 * j] += c[3 * i + j][0][l];
                    gi[4 * j + 1] += c[3 * i + j][1][l];
                    gi[4 * j + 2] += c[3 * i + j][2][l];
                }
        }
    }
}

/* One slab of P2G: the particles, in index order, whose stencils reach rows [r0, r1) of axis 0,
   added to those rows only; each marks its base node's block in the slab that holds its base
   row (slabs start at block rows, so no two threads write one mark). The whole grid in one
   slab: every particle, every row (the constant bounds let the compiler unroll the rows). In
   2D, record blocks whose particles all take part go to the lanes whole; the others' members
   are gathered into batches (a batch is flushed before a whole block, to keep the order). */
static void pn__mpm_xp2g_slab(pn_mpm_world *w, pn_real dt, int r0, int r1) {
    enum { L = PN__MPM_LANES };
    int d = w->dim, whole = r0 == 0 && r1 > w->desc.res[0], nl = 0, l;
    pn_real *v0 = w->s.gdense0;
    size_t p, idx[2 * L];
    unsigned char mark[2 * L], bm[L], in[L];
    const int *prow = w->s.prow;
    const unsigned char *active = w->active;
    if (d == 2 && !v0) {
        for (p = 0; p < w->n; p += L) {
            int cnt = (int)PN__MIN((size_t)L, w->n - p), all = cnt == L;
            for (l = 0; l < cnt; ++l) {
                int b = prow[p + (size_t)l];
                in[l] = (unsigned char)((active[p + (size_t)l] != 0) & (whole | ((b + 3 > r0) & (b < r1))));
                bm[l] = (unsigned char)(b >= r0);
                all &= in[l];
            }
            if (all) {
                if (nl) pn__mpm_scatter2_lanes(w, 0, idx, nl, dt, r0, r1, mark), nl = 0;
                pn__mpm_scatter2_lanes(w, p, NULL, L, dt, r0, r1, bm);
                continue;
            }
            for (l = 0; l < cnt; ++l) /* compacted without a branch: membership is random here */
                idx[nl] = p + (size_t)l, mark[nl] = bm[l], nl += in[l];
            if (nl >= L) {
                pn__mpm_scatter2_lanes(w, 0, idx, L, dt, r0, r1, mark);
                for (l = L; l < nl; ++l) idx[l - L] = idx[l], mark[l - L] = mark[l];
                nl -= L;
            }
        }
        if (nl) pn__mpm_scatter2_lanes(w, 0, idx, nl, dt, r0, r1, mark);
        return;
    }
    for (p = 0; p < w->n; ++p) {
        int b = prow[p];
        if (!active[p] || !(whole || (b + 3 > r0 && b < r1))) continue;
        if (whole) {
            if (d == 2) pn__mpm_scatter2(w, p, dt, v0, 0, 3, 1);
            else pn__mpm_scatter3(w, p, dt, v0, 0, 3, 1);
        } else {
            int i0 = PN__MAX(r0 - b, 0), i1 = PN__MIN(r1 - b, 3);
            if (d == 2) pn__mpm_scatter2(w, p, dt, v0, i0, i1, b >= r0);
            else pn__mpm_scatter3(w, p, dt, v0, i0, i1, b >= r0);
        }
    }
}

/* P2G in particle index order. With threads, the rows of axis 0 are cut into as many slabs as
   threads, of about equal particle counts, and each thread scans every particle but adds only
   to its own slab's rows: each node still sums its contributions in index order, so the
   result is bitwise the same for any thread count, without a sort and without atomics. Then
   the touched blocks: the marked ones and their upper neighbours, which their stencils reach. */
static void pn__mpm_xp2g(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, rows = w->desc.res[0] + 1, ns = 1, cut[PN__MPM_SLABS + 1];
    long ls;
    size_t b;
#ifdef _OPENMP
    if (w->n >= w->desc.parallel_min_particles) ns = PN__MIN(omp_get_max_threads(), PN__MPM_SLABS);
#endif
    cut[0] = 0;
    if (ns > 1) { /* cut the cumulative row histogram at equal shares, at block rows. The cut
                     only balances the threads (any cut gives the same bits), so a sample of
                     every stride-th particle makes it: a serial pass over all of them cost
                     4% of a 2D step at 30k particles */
        size_t p, tot = 0, acc = 0, stride = w->n / 8192 + 1;
        int row, k = 1;
        memset(w->s.rowcount, 0, sizeof(size_t) * (size_t)rows);
        for (p = 0; p < w->n; p += stride)
            if (w->active[p]) w->s.rowcount[w->s.prow[p]]++, tot++;
        for (row = 0; row < rows && k < ns; ++row) {
            acc += w->s.rowcount[row];
            if ((row + 1) % PN__MPM_BLOCK) continue;
            while (k < ns && acc * (size_t)ns >= tot * (size_t)k) cut[k++] = row + 1;
        }
        while (k < ns) cut[k++] = rows;
    }
    cut[ns] = rows;
#if defined(_OPENMP)
#pragma omp parallel for schedule(static, 1) num_threads(ns) if (ns > 1)
#endif
    for (ls = 0; ls < ns; ++ls) pn__mpm_xp2g_slab(w, dt, cut[ls], cut[ls + 1]);
    for (b = 0; b < w->s.nblocks; ++b) { /* upper neighbours of marked blocks get mark 2 */
        size_t r = b, up[3];
        int i, o;
        if (w->s.bmark[b] != 1) continue;
        for (i = d - 1; i >= 0; --i) {
            up[i] = r % w->s.nblk[i] + 1 < w->s.nblk[i];
            r /= w->s.nblk[i];
        }
        for (o = 1; o < 1 << d; ++o) {
            size_t nb = b;
            int ok = 1;
            for (i = 0; i < d; ++i)
                if (o >> i & 1) ok &= (int)up[i], nb += w->s.bstride[i];
            if (ok && !w->s.bmark[nb]) w->s.bmark[nb] = 2;
        }
    }
    w->s.n_bact = 0;
    for (b = 0; b < w->s.nblocks; ++b)
        if (w->s.bmark[b]) w->s.bmark[b] = 0, w->s.bact[w->s.n_bact++] = b;
}

/* the node range of block b, clipped to the grid: lo, hi (exclusive) per axis */
static void pn__mpm_block_nodes(const pn_mpm_world *w, size_t b, int *lo, int *hi) {
    int i;
    for (i = w->dim - 1; i >= 0; --i) {
        lo[i] = (int)(b % w->s.nblk[i]) * PN__MPM_BLOCK;
        hi[i] = PN__MIN(lo[i] + PN__MPM_BLOCK, w->desc.res[i] + 1);
        b /= w->s.nblk[i];
    }
    if (w->dim == 2) lo[2] = 0, hi[2] = 1;
}

/* Grid update on the touched blocks: v = p/m + dt g, then the obstacles (>>contact) */
static size_t pn__mpm_xgrid(pn_mpm_world *w, pn_real dt) {
    int d = w->dim;
    long lb;
    size_t count = 0;
    pn_real *v0 = w->s.gdense0;
    int walls_or_colliders = w->s.wall > 0 || w->n_colliders > 0;
#if defined(_OPENMP)
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : count) if (w->n >= w->desc.parallel_min_particles)
#endif
    for (lb = 0; lb < (long)w->s.n_bact; ++lb) {
        int lo[3], hi[3], idx[3], i;
        pn__mpm_block_nodes(w, w->s.bact[lb], lo, hi);
        for (idx[0] = lo[0]; idx[0] < hi[0]; ++idx[0])
            for (idx[1] = lo[1]; idx[1] < hi[1]; ++idx[1])
                for (idx[2] = lo[2]; idx[2] < hi[2]; ++idx[2]) {
                    size_t node = (size_t)idx[0] * w->s.stride[0] + (size_t)idx[1] * w->s.stride[1] + (size_t)idx[2];
                    pn_real *g = w->s.gdense + node * 4, m = g[0], dir[9], vel[3], mu;
                    int kind, cn = 0;
                    if (!(m > 0)) continue;
                    count++;
                    for (i = 0; i < d; ++i) g[1 + i] = g[1 + i] / m + dt * w->desc.gravity[i];
                    if (v0)
                        for (i = 0; i < d; ++i) v0[node * (size_t)d + (size_t)i] /= m;
                    if (!walls_or_colliders) continue;
                    if (w->n_colliders == 0) { /* only walls: an interior node has no obstacle */
                        int inside = 1;
                        for (i = 0; i < d; ++i) inside &= idx[i] > w->s.wall && idx[i] < w->desc.res[i] - w->s.wall;
                        if (inside) continue;
                    }
                    cn = pn__mpm_obstacle(w, idx, m, w->time_s, dir, vel, &kind, &mu);
                    if (cn) pn__mpm_project(d, cn, kind, dir, vel, mu, g + 1);
                }
    }
    return count;
}

/* drives (>>drive) in the explicit step: the 3^dim stencil of a point x on the dense grid, its nodes'
   flat indices, weights and positions; returns the count */
static int pn__mpm_xstencil(const pn_mpm_world *w, const pn_real *x, size_t *node, pn_real *wt, pn_real (*pos)[3]) {
    int d = w->dim, base[3], o[3] = {0, 0, 0}, i, n = 0;
    pn_real fx[3], W[3][3];
    pn__mpm_base(w, x, base, fx);
    for (i = 0; i < d; ++i) PN__MPM_SPLINE(W[i], fx[i]);
    for (o[0] = 0; o[0] < 3; ++o[0])
        for (o[1] = 0; o[1] < 3; ++o[1])
            for (o[2] = 0; o[2] < (d == 3 ? 3 : 1); ++o[2], ++n) {
                size_t f = 0;
                wt[n] = 1;
                for (i = 0; i < d; ++i) {
                    f += (size_t)(base[i] + o[i]) * w->s.stride[i];
                    wt[n] *= W[i][o[i]];
                    pos[n][i] = w->desc.origin_m[i] + (pn_real)(base[i] + o[i]) * w->desc.dx_m;
                }
                node[n] = f;
            }
    return n;
}

/* loads: each loaded particle adds m_p a times the part of [t, t + dt] inside the load's window
   to the momentum of its nodes (before the grid update divides by the mass) */
static void pn__mpm_xloads(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, a, s, i, ns;
    for (a = 0; a < w->s.n_loads; ++a) {
        const pn__mpm_load *L = &w->s.loads[a];
        pn_real span = L->on ? PN__MIN(dt, L->t_end - w->time_s) : 0;
        size_t k, node[27];
        pn_real wt[27], pos[27][3];
        if (!(span > 0)) continue;
        for (k = 0; k < L->n; ++k) {
            size_t p = L->idx[k];
            if (!w->active[p]) continue;
            ns = pn__mpm_xstencil(w, w->x + p * (size_t)d, node, wt, pos);
            for (s = 0; s < ns; ++s)
                for (i = 0; i < d; ++i) w->s.gdense[node[s] * 4 + 1 + (size_t)i] += wt[s] * w->mass[p] * L->acc[i] * span;
        }
    }
}

/* the coupling's forces on particles (>>couple-explicit), as loads: f dt to the momentum of their nodes */
static void pn__mpm_xforces(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, s, i, ns;
    size_t k, node[27];
    pn_real wt[27], pos[27][3];
    for (k = 0; k < w->s.xf_n; ++k) {
        size_t p = w->s.xf_idx[k];
        if (!w->active[p]) continue;
        ns = pn__mpm_xstencil(w, w->x + p * (size_t)d, node, wt, pos);
        for (s = 0; s < ns; ++s)
            for (i = 0; i < d; ++i) w->s.gdense[node[s] * 4 + 1 + (size_t)i] += wt[s] * w->s.xf[k * (size_t)d + (size_t)i] * dt;
    }
}

/* drives: the nodes a driven particle touches take the rigid velocity at mid-step (the chord
   of a rotation to second order; the particles themselves land exactly, pn__mpm_xdrive_state) */
static void pn__mpm_xdrive_grid(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, a, s, ns;
    for (a = 0; a < w->s.n_drives; ++a) {
        const pn__mpm_drive *D = &w->s.drives[a];
        pn_real c[3], wt[27], pos[27][3];
        size_t k, node[27];
        if (!D->on) continue;
        pn__mpm_drive_at(D, d, w->time_s + dt / 2, NULL, c, NULL);
        for (k = 0; k < D->n; ++k) {
            size_t p = D->idx[k];
            if (!w->active[p]) continue;
            ns = pn__mpm_xstencil(w, w->x + p * (size_t)d, node, wt, pos);
            for (s = 0; s < ns; ++s)
                if (w->s.gdense[node[s] * 4] > 0) pn__mpm_drive_vel(D, d, c, pos[s], w->s.gdense + node[s] * 4 + 1);
        }
    }
}

/* drives after G2P: each driven particle at its exact position at t + dt, with the rigid
   velocity and velocity gradient (a particle the step failed on, or one the motion would
   carry through a wall, keeps what G2P made of it) */
static void pn__mpm_xdrive_state(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, dd = d * d, a, i;
    for (a = 0; a < w->s.n_drives; ++a) {
        const pn__mpm_drive *D = &w->s.drives[a];
        pn_real c[3], xn[3], Wm[9] = {0};
        size_t k;
        if (!D->on) continue;
        if (d == 2) Wm[1] = -D->omega[2], Wm[2] = D->omega[2];
        else {
            Wm[1] = -D->omega[2], Wm[2] = D->omega[1], Wm[3] = D->omega[2];
            Wm[5] = -D->omega[0], Wm[6] = -D->omega[1], Wm[7] = D->omega[0];
        }
        for (k = 0; k < D->n; ++k) {
            size_t p = D->idx[k];
            int in = 1;
            if (!w->active[p] || !w->s.sactive[p] || (w->s.pstat[p] & 0xcff)) continue;
            pn__mpm_drive_at(D, d, w->time_s + dt, D->x0 + k * (size_t)d, c, xn);
            for (i = 0; i < d; ++i) in &= xn[i] >= w->s.wall_lo[i] && xn[i] <= w->s.wall_hi[i];
            if (!in) continue;
            memcpy(w->s.sx + p * (size_t)d, xn, sizeof(pn_real) * (size_t)d);
            pn__mpm_drive_vel(D, d, c, xn, w->s.sv + p * (size_t)d);
            memcpy(w->s.sC + p * (size_t)dd, Wm, sizeof(pn_real) * (size_t)dd);
            w->s.srow[p] = pn__mpm_row_of(w, xn);
        }
    }
}

/* After G2P: the touched blocks back to zero, as the next P2G expects the grid */
static void pn__mpm_xclear(pn_mpm_world *w) {
    int d = w->dim;
    long lb;
#if defined(_OPENMP)
#pragma omp parallel for schedule(static, 16) if (w->n >= w->desc.parallel_min_particles)
#endif
    for (lb = 0; lb < (long)w->s.n_bact; ++lb) {
        int lo[3], hi[3], a, b;
        pn__mpm_block_nodes(w, w->s.bact[lb], lo, hi);
        for (a = lo[0]; a < hi[0]; ++a)
            for (b = lo[1]; b < hi[1]; ++b) {
                size_t n0 = (size_t)a * w->s.stride[0] + (size_t)b * w->s.stride[1] + (size_t)lo[2];
                memset(w->s.gdense + n0 * 4, 0, sizeof(pn_real) * (size_t)((hi[2] - lo[2]) * 4));
                if (w->s.gdense0) memset(w->s.gdense0 + n0 * (size_t)d, 0, sizeof(pn_real) * (size_t)((hi[2] - lo[2]) * d));
            }
    }
    w->s.n_bact = 0;
}

/* The grid velocity at a particle at x: v = sum_i w_i v_i and C = (4/dx^2) sum_i w_i v_i
   (x_i - x_p)^T = (4/dx) (sum_i w_i v_i o_i^T - v fx^T), o_i the node's offset in cells
   (APIC / MLS-MPM). Spelled out per dimension (see >>transfer). */
static void pn__mpm_vel2(const pn_mpm_world *w, const pn_real *x, pn_real *v, pn_real *C) {
    pn_real fx[3], wx[3], wy[3], v0 = 0, v1 = 0, g00 = 0, g01 = 0, g10 = 0, g11 = 0, k = 4 * w->s.inv_dx;
    const pn_real *gb;
    int base[3], i, j;
    size_t s0 = w->s.stride[0] * 4;
    pn__mpm_base(w, x, base, fx);
    PN__MPM_SPLINE(wx, fx[0]);
    PN__MPM_SPLINE(wy, fx[1]);
    gb = w->s.gdense + ((size_t)base[0] * w->s.stride[0] + (size_t)base[1]) * 4;
    for (i = 0; i < 3; ++i, gb += s0) {
        pn_real a0 = 0, a1 = 0, b0 = 0, b1 = 0; /* sums over j: w_j v and w_j v j */
        for (j = 0; j < 3; ++j) {
            pn_real t0 = wy[j] * gb[4 * j + 1], t1 = wy[j] * gb[4 * j + 2];
            a0 += t0, a1 += t1;
            b0 += t0 * (pn_real)j, b1 += t1 * (pn_real)j;
        }
        v0 += wx[i] * a0, v1 += wx[i] * a1;
        g00 += wx[i] * a0 * (pn_real)i, g10 += wx[i] * a1 * (pn_real)i;
        g01 += wx[i] * b0, g11 += wx[i] * b1;
    }
    v[0] = v0, v[1] = v1;
    C[0] = k * (g00 - v0 * fx[0]), C[1] = k * (g01 - v0 * fx[1]);
    C[2] = k * (g10 - v1 * fx[0]), C[3] = k * (g11 - v1 * fx[1]);
}

static void pn__mpm_vel3(const pn_mpm_world *w, const pn_real *x, pn_real *v, pn_real *C) {
    pn_real fx[3], W[3][3], g[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}}, k = 4 * w->s.inv_dx;
    const pn_real *gb;
    int base[3], i, j, l, c;
    pn__mpm_base(w, x, base, fx);
    for (i = 0; i < 3; ++i) PN__MPM_SPLINE(W[i], fx[i]);
    v[0] = v[1] = v[2] = 0;
    gb = w->s.gdense + ((size_t)base[0] * w->s.stride[0] + (size_t)base[1] * w->s.stride[1] + (size_t)base[2]) * 4;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j) {
            const pn_real *gn = gb + ((size_t)i * w->s.stride[0] + (size_t)j * w->s.stride[1]) * 4;
            pn_real wij = W[0][i] * W[1][j];
            for (l = 0; l < 3; ++l) {
                pn_real wt = wij * W[2][l], a = wt * gn[4 * l + 1], b = wt * gn[4 * l + 2], e = wt * gn[4 * l + 3];
                v[0] += a, v[1] += b, v[2] += e;
                g[0][0] += a * (pn_real)i, g[0][1] += a * (pn_real)j, g[0][2] += a * (pn_real)l;
                g[1][0] += b * (pn_real)i, g[1][1] += b * (pn_real)j, g[1][2] += b * (pn_real)l;
                g[2][0] += e * (pn_real)i, g[2][1] += e * (pn_real)j, g[2][2] += e * (pn_real)l;
            }
        }
    for (i = 0; i < 3; ++i)
        for (c = 0; c < 3; ++c) C[3 * i + c] = k * (g[i][c] - v[i] * fx[c]);
}

/* the transfer-only grid velocity at x (AFLIP's sum_i w_i v_i^n) */
static void pn__mpm_vel0(const pn_mpm_world *w, const pn_real *x, pn_real *ov) {
    int d = w->dim, base[3], i, j, l, c;
    pn_real fx[3], W[3][3] = {{0, 0, 0}, {0, 0, 0}, {1, 0, 0}};
    pn__mpm_base(w, x, base, fx);
    for (i = 0; i < d; ++i) PN__MPM_SPLINE(W[i], fx[i]);
    for (c = 0; c < d; ++c) ov[c] = 0;
    for (i = 0; i < 3; ++i)
        for (j = 0; j < 3; ++j)
            for (l = 0; l < (d == 3 ? 3 : 1); ++l) {
                size_t node = (size_t)(base[0] + i) * w->s.stride[0] + (size_t)(base[1] + j) * w->s.stride[1] +
                              (d == 3 ? (size_t)(base[2] + l) : 0);
                pn_real wt = W[0][i] * W[1][j] * W[2][l];
                for (c = 0; c < d; ++c) ov[c] += wt * w->s.gdense0[node * (size_t)d + (size_t)c];
            }
}

/* G2P for particle p into scratch (as pn__mpm_g2p: APIC v and C, AFLIP when filtering, x += dt
   v, F = (I + dt C) F, the return mapping), and the P2G record of the new state. Called with
   a constant d and inlined, so every loop over the dimension unrolls. vc (2D, or NULL): v and
   C already gathered, in lane `lane` of pn__mpm_xg2p2_lanes. */
PN__MPM_INLINE void pn__mpm_xg2p(pn_mpm_world *w, size_t p, pn_real dt, pn_real flip, pn_real reach, const int d,
                                 const pn_real *vc, int lane) {
    const int dd = d * d, pay = PN__MPM_PAY(d);
    int i, j, plastic = 0, stat;
    const pn_real *F = w->F + p * (size_t)dd;
    const pn_material *mat = &w->groups[w->group[p]].material;
    pn_real nv[3], ov[3] = {0, 0, 0}, nC[9], Fn[9], Z[9] = {0}, tau[9] = {0}, hn = w->h[p], chk[4] = {0, 0, 0, 0}, fin = 0;
    pn_real x[3], hard = PN__MPM_REC(w->s.ppay, p, pay - 1, pay);
    for (i = 0; i < d; ++i) x[i] = w->x[p * (size_t)d + (size_t)i];
    pn_real *sx = w->s.sx + p * (size_t)d, *sv = w->s.sv + p * (size_t)d;
    if (vc) { /* found by pn__mpm_xg2p2_lanes */
        for (i = 0; i < 2; ++i) nv[i] = vc[i * PN__MPM_LANES + lane];
        for (i = 0; i < 4; ++i) nC[i] = vc[(i + 2) * PN__MPM_LANES + lane];
    }
    else if (d == 2) pn__mpm_vel2(w, x, nv, nC);
    else pn__mpm_vel3(w, x, nv, nC);
    if (flip > 0) pn__mpm_vel0(w, x, ov);
    for (i = 0; i < d; ++i) /* Fn = (I + dt C) F */
        for (j = 0; j < d; ++j) {
            pn_real cf = nC[i * d] * F[j];
            int k;
            for (k = 1; k < d; ++k) cf += nC[i * d + k] * F[k * d + j];
            Fn[i * d + j] = F[i * d + j] + dt * cf;
        }
    if (d == 2 && pn__tau_fcr2(mat, Fn, hard, tau)) { /* the 2D elastic fast path: the state is Fn (checked below) */
        stat = PN_OK;
        for (i = 0; i < dd; ++i) Z[i] = Fn[i];
        hn = w->h[p];
    } else {
        for (i = 0; i < dd; ++i) fin += Fn[i] - Fn[i];
        stat = fin == 0 ? (int)pn__return_tau(mat, d, Fn, w->h[p], Z, &hn, tau, &plastic) : (int)PN_ERROR_OVERFLOW;
        if (plastic) hard = pn__hardening(mat, hn);
    }
    w->s.sactive[p] = 1;
    for (i = 0; i < d; ++i) {
        sv[i] = nv[i] + flip * (w->v[p * (size_t)d + (size_t)i] - ov[i]);
        sx[i] = x[i] + dt * nv[i];
        if (!(PN__FABS(nv[i]) <= reach)) stat |= 0x400; /* more than the limit along an axis */
    }
    if ((stat & 0xff) == PN_OK) { /* everything the next step reads, checked at once (four partial sums) */
        for (i = 0; i < dd; ++i) chk[i & 3] += (Z[i] - Z[i]) + (tau[i] - tau[i]);
        for (i = 0; i < d; ++i) chk[i] += (sv[i] - sv[i]) + (nC[i] - nC[i]);
        chk[3] += hn - hn;
        if (!(chk[0] + chk[1] + chk[2] + chk[3] == 0)) stat = PN_ERROR_OVERFLOW | (stat & ~0xff);
    }
    if ((stat & 0xff) != PN_OK) { /* an input written by hand, or the deformation overflowed */
        if (!pn__all_finite(dd, F) || !pn__finite(w->h[p])) stat = PN_ERROR_NONFINITE;
        w->s.pstat[p] = stat & 0xff;
        return;
    }
    if (plastic) stat |= 0x100;
    for (i = 0; i < dd; ++i) w->s.sC[p * (size_t)dd + (size_t)i] = nC[i], w->s.sF[p * (size_t)dd + (size_t)i] = Z[i];
    w->s.sh[p] = hn;
    {
        int in = 1;
        for (i = 0; i < d; ++i) in &= sx[i] >= w->s.grid_lo[i] && sx[i] <= w->s.grid_hi[i];
        if (!in) { /* went through a wall */
            w->s.sactive[p] = 0;
            stat |= w->desc.allow_outflow ? 0x200 : 0x800;
            w->s.pstat[p] = stat;
            return;
        }
    }
    for (i = 0; i < d; ++i) sx[i] = PN__MIN(PN__MAX(sx[i], w->s.wall_lo[i]), w->s.wall_hi[i]); /* pn__mpm_wall_plane */
    w->s.srow[p] = pn__mpm_row_of(w, sx);
    pn__mpm_pack(w, p, tau, hard, w->s.spay, d);
    w->s.pstat[p] = stat;
}

/* x[l] = sqrt(x[l]) for the PN__MPM_LANES (8) lanes, correctly rounded as PN__SQRT: one
   instruction per register where the target has one. libm's sqrt does not vectorize: it
   may set errno, so the compiler keeps a branch around it. */
static inline void pn__mpm_sqrt_lanes(pn_real *x) {
#if defined(__AVX__)
    if (sizeof(pn_real) == 4) {
        _mm256_storeu_ps((float *)x, _mm256_sqrt_ps(_mm256_loadu_ps((const float *)x)));
    } else {
        _mm256_storeu_pd((double *)x, _mm256_sqrt_pd(_mm256_loadu_pd((const double *)x)));
        _mm256_storeu_pd((double *)x + 4, _mm256_sqrt_pd(_mm256_loadu_pd((const double *)x + 4)));
    }
#elif defined(__SSE2__)
    int i;
    if (sizeof(pn_real) == 4)
        for (i = 0; i < 8; i += 4) _mm_storeu_ps((float *)x + i, _mm_sqrt_ps(_mm_loadu_ps((const float *)x + i)));
    else
        for (i = 0; i < 8; i += 2) _mm_storeu_pd((double *)x + i, _mm_sqrt_pd(_mm_loadu_pd((const double *)x + i)));
#else
    int i;
    for (i = 0; i < PN__MPM_LANES; ++i) x[i] = PN__SQRT(x[i]);
#endif
}

/* 2D G2P (APIC) of particles p0 .. p0 + n - 1, n <= PN__MPM_LANES, in lanes the compiler can
   vectorize: the grid gather, F = (I + dt C) F, the Stomakhin clamp in closed form
   (pn__snow2_clamp) and the fixed-corotated stress run in every lane; only J_p and the
   hardening of the clamped particles, which need log and exp, are scalar. A particle is
   finished here (done[l] = 1) when its group is 2D fixed corotated, elastic or with the clamp
   (gpar: ok, mu, lambda, lo, hi per group, pn__fcr2_params), and its new state is finite,
   within reach and on the grid; the rest go through pn__mpm_xg2p with the velocity and C
   found here (vc: v0, v1, C00, C01, C10, C11 per lane). Elastic states get the bits of
   pn__mpm_xg2p's fast path (the arithmetic is pn__mpm_vel2's and pn__tau_fcr2's, in order). */
static void pn__mpm_xg2p2_lanes(pn_mpm_world *w, size_t p0, int n, pn_real dt, pn_real reach, const pn_real *gpar,
                                unsigned char *done, pn_real (*vc)[PN__MPM_LANES], size_t *n_done, size_t *n_clamped,
                                pn_real *v2max) {
    enum { L = PN__MPM_LANES, pay = PN__MPM_PAY(2) };
    pn_real fx0[L], fx1[L], wx[3][L], wy[3][L], g00[L], g01[L], g10[L], g11[L], Fn[4][L], tau[4][L], nx[2][L];
    pn_real qq[L], rr[L], mu[L], la[L], lo[L], hi[L], hard[L], k = 4 * w->s.inv_dx, inv_dx = w->s.inv_dx;
    pn_real rot[2][L], ratio[L], hnew[L], Fin[4][L];
    pn_real ox = w->desc.origin_m[0], oy = w->desc.origin_m[1], v0[L], v1[L], C[4][L], px[L], py[L];
    const pn_real *G = w->s.gdense;
    pn_real ok[L], clamped[L], vol[L]; /* flags as reals: see pn__snow2_clamp */
    int b0[L], b1[L], i, j, l;
    size_t s0 = w->s.stride[0], nd[L];
    const pn_real *F0 = w->F + p0 * 4, *X = w->x + p0 * 2, *rb = &PN__MPM_REC(w->s.ppay, p0, 0, pay); /* p0: a block's first */
    /* x clamped to the grid: a no-op for an active particle; a retired one's may be anywhere */
    pn_real glo0 = w->s.grid_lo[0], glo1 = w->s.grid_lo[1], ghi0 = w->s.grid_hi[0], ghi1 = w->s.grid_hi[1];
    if (n == L) { /* the inputs: contiguous, F strided, the group's parameters a gather */
        const int *grp = w->group + p0;
        const unsigned char *act = w->active + p0;
        const pn_real *vl = w->vol0 + p0;
        for (l = 0; l < L; ++l) {
            px[l] = PN__MIN(PN__MAX(X[2 * l], glo0), ghi0), py[l] = PN__MIN(PN__MAX(X[2 * l + 1], glo1), ghi1);
            hard[l] = rb[(pay - 1) * L + l], vol[l] = vl[l];
            for (i = 0; i < 4; ++i) Fin[i][l] = F0[l * 4 + i];
        }
        for (l = 0; l < L; ++l) {
            const pn_real *gp = gpar + 5 * grp[l];
            ok[l] = ((gp[0] != 0) & (act[l] != 0)) ? 1 : 0;
            mu[l] = gp[1] * hard[l], la[l] = gp[2] * hard[l], lo[l] = gp[3], hi[l] = gp[4];
        }
    } else
        for (l = 0; l < L; ++l) { /* the same, lanes past n a copy of lane 0 */
            int src = l < n ? l : 0;
            const pn_real *gp = gpar + 5 * w->group[p0 + (size_t)src];
            px[l] = X[2 * src], py[l] = X[2 * src + 1], hard[l] = rb[(pay - 1) * L + src];
            for (i = 0; i < 4; ++i) Fin[i][l] = F0[src * 4 + i];
            ok[l] = l < n && gp[0] != 0 && w->active[p0 + (size_t)l] ? 1 : 0;
            px[l] = PN__MIN(PN__MAX(px[l], glo0), ghi0), py[l] = PN__MIN(PN__MAX(py[l], glo1), ghi1);
            vol[l] = w->vol0[p0 + (size_t)src];
            mu[l] = gp[1] * hard[l], la[l] = gp[2] * hard[l], lo[l] = gp[3], hi[l] = gp[4];
        }
    /* every vector loop runs over all L lanes: a constant trip count, which gcc -O2 (its very
       cheap cost model) vectorizes too */
    for (l = 0; l < L; ++l) { /* pn__mpm_base and the splines */
        pn_real xc = (px[l] - ox) * inv_dx, yc = (py[l] - oy) * inv_dx;
        b0[l] = (int)(xc - (pn_real)0.5), b1[l] = (int)(yc - (pn_real)0.5);
        fx0[l] = xc - (pn_real)b0[l], fx1[l] = yc - (pn_real)b1[l];
        PN__BSPLINE2(wx[0][l], wx[1][l], wx[2][l], fx0[l], pn_real);
        PN__BSPLINE2(wy[0][l], wy[1][l], wy[2][l], fx1[l], pn_real);
        v0[l] = v1[l] = g00[l] = g01[l] = g10[l] = g11[l] = 0;
        nd[l] = ((size_t)b0[l] * s0 + (size_t)b1[l]) * 4;
    }
    for (i = 0; i < 3; ++i) /* pn__mpm_vel2 */
        for (l = 0; l < L; ++l) {
            size_t o = nd[l] + (size_t)i * s0 * 4;
            pn_real a0 = 0, a1 = 0, c0 = 0, c1 = 0;
            for (j = 0; j < 3; ++j) {
                pn_real t0 = wy[j][l] * G[o + 4 * (size_t)j + 1], t1 = wy[j][l] * G[o + 4 * (size_t)j + 2];
                a0 += t0, a1 += t1;
                c0 += t0 * (pn_real)j, c1 += t1 * (pn_real)j;
            }
            v0[l] += wx[i][l] * a0, v1[l] += wx[i][l] * a1;
            g00[l] += wx[i][l] * a0 * (pn_real)i, g10[l] += wx[i][l] * a1 * (pn_real)i;
            g01[l] += wx[i][l] * c0, g11[l] += wx[i][l] * c1;
        }
    for (l = 0; l < L; ++l) { /* C, F = (I + dt C) F as pn__mpm_xg2p, the norms of pn__tau_fcr2 */
        pn_real Fl[4], F[4];
        F[0] = Fin[0][l], F[1] = Fin[1][l], F[2] = Fin[2][l], F[3] = Fin[3][l];
        C[0][l] = k * (g00[l] - v0[l] * fx0[l]), C[1][l] = k * (g01[l] - v0[l] * fx1[l]);
        C[2][l] = k * (g10[l] - v1[l] * fx0[l]), C[3][l] = k * (g11[l] - v1[l] * fx1[l]);
        Fl[0] = F[0] + dt * (C[0][l] * F[0] + C[1][l] * F[2]), Fl[1] = F[1] + dt * (C[0][l] * F[1] + C[1][l] * F[3]);
        Fl[2] = F[2] + dt * (C[2][l] * F[0] + C[3][l] * F[2]), Fl[3] = F[3] + dt * (C[2][l] * F[1] + C[3][l] * F[3]);
        pn__fcr2_norms(Fl, qq + l, rr + l);
        Fn[0][l] = Fl[0], Fn[1][l] = Fl[1], Fn[2][l] = Fl[2], Fn[3][l] = Fl[3];
    }
    pn__mpm_sqrt_lanes(qq);
    pn__mpm_sqrt_lanes(rr);
    for (l = 0; l < L; ++l) { /* the polar rotation and the clamp */
        pn_real Fl[4], Z[4];
        Fl[0] = Fn[0][l], Fl[1] = Fn[1][l], Fl[2] = Fn[2][l], Fl[3] = Fn[3][l];
        pn__fcr2_rotation(Fl, qq[l], rot[0] + l, rot[1] + l);
        clamped[l] = pn__snow2_clamp(Fl, qq[l], rr[l], rot[0][l], rot[1][l], lo[l], hi[l], Z, ratio + l);
        Fn[0][l] = Z[0], Fn[1][l] = Z[1], Fn[2][l] = Z[2], Fn[3][l] = Z[3];
    }
    for (l = 0; l < n; ++l) { /* J_p and the hardening of the clamped (scalar: log and exp) */
        const pn_material *m = &w->groups[w->group[p0 + (size_t)l]].material;
        pn_real hn = w->h[p0 + (size_t)l];
        if (clamped[l] == 0 || ok[l] == 0) {
            hnew[l] = hn;
            continue;
        }
        hn += PN__LOG(ratio[l]); /* as pn__return_principal */
        if (m->snow_h_min < 0 && hn < m->snow_h_min) hn = m->snow_h_min;
        if (m->snow_h_max > 0 && hn > m->snow_h_max) hn = m->snow_h_max;
        hnew[l] = hn;
        hard[l] = pn__hardening(m, hn);
        mu[l] = gpar[5 * w->group[p0 + (size_t)l] + 1] * hard[l], la[l] = gpar[5 * w->group[p0 + (size_t)l] + 2] * hard[l];
    }
    for (l = 0; l < L; ++l) { /* the stress, the move and every check of pn__mpm_xg2p */
        pn_real Zl[4], tl[4], chk;
        Zl[0] = Fn[0][l], Zl[1] = Fn[1][l], Zl[2] = Fn[2][l], Zl[3] = Fn[3][l];
        pn__fcr2_stress(Zl, rot[0][l], rot[1][l], mu[l], la[l], tl);
        nx[0][l] = px[l] + dt * v0[l], nx[1][l] = py[l] + dt * v1[l];
        chk = (Zl[0] - Zl[0]) + (Zl[1] - Zl[1]) + (Zl[2] - Zl[2]) + (Zl[3] - Zl[3]) + (tl[0] - tl[0]) +
              (tl[1] - tl[1]) + (tl[3] - tl[3]) + (C[0][l] - C[0][l]) + (C[1][l] - C[1][l]) +
              (C[2][l] - C[2][l]) + (C[3][l] - C[3][l]) + (v0[l] - v0[l]) + (v1[l] - v1[l]) + (hnew[l] - hnew[l]);
        ok[l] = ((chk == 0) & (PN__FABS(v0[l]) <= reach) & (PN__FABS(v1[l]) <= reach) & (nx[0][l] >= w->s.grid_lo[0]) &
                 (nx[0][l] <= w->s.grid_hi[0]) & (nx[1][l] >= w->s.grid_lo[1]) & (nx[1][l] <= w->s.grid_hi[1]))
                    ? ok[l]
                    : 0;
        tau[0][l] = tl[0], tau[1][l] = tl[1], tau[2][l] = tl[2], tau[3][l] = tl[3];
    }
    for (l = 0; l < L; ++l) { /* the statistics of the finished (the step counts the rest) */
        pn_real sp = v0[l] * v0[l] + v1[l] * v1[l];
        *n_done += (size_t)(ok[l] != 0), *n_clamped += (size_t)(ok[l] * clamped[l] != 0);
        *v2max = ok[l] != 0 && sp > *v2max ? sp : *v2max;
    }
    for (l = 0; l < n; ++l) /* v and C for the particles pn__mpm_xg2p finishes */
        if (ok[l] == 0) {
            memcpy(vc[0], v0, sizeof v0), memcpy(vc[1], v1, sizeof v1), memcpy(vc[2], C, sizeof C);
            break;
        }
    { /* every lane's P2G record, as pn__mpm_pack, into the record block (a lane that did not
         finish here is written again by pn__mpm_xg2p) */
        pn_real *out = &PN__MPM_REC(w->s.spay, p0, 0, pay), kk = -(4 * w->s.inv_dx * w->s.inv_dx);
        pn_real wl0 = w->s.wall_lo[0], wl1 = w->s.wall_lo[1], wh0 = w->s.wall_hi[0], wh1 = w->s.wall_hi[1]; /* out may alias w */
        for (l = 0; l < L; ++l) {
            pn_real k = vol[l] * kk;
            nx[0][l] = PN__MIN(PN__MAX(nx[0][l], wl0), wh0); /* pn__mpm_wall_plane */
            nx[1][l] = PN__MIN(PN__MAX(nx[1][l], wl1), wh1);
            out[l] = k * tau[0][l], out[L + l] = k * tau[1][l], out[2 * L + l] = k * tau[3][l], out[3 * L + l] = hard[l];
        }
    }
    for (l = 0; l < n; ++l) {
        size_t p = p0 + (size_t)l;
        pn_real *sx = w->s.sx + p * 2, *sv = w->s.sv + p * 2, *sC = w->s.sC + p * 4, *sF = w->s.sF + p * 4;
        done[l] = (unsigned char)(ok[l] != 0);
        if (!done[l]) continue;
        sv[0] = v0[l], sv[1] = v1[l], sx[0] = nx[0][l], sx[1] = nx[1][l];
        for (i = 0; i < 4; ++i) sC[i] = C[i][l], sF[i] = Fn[i][l];
        w->s.sh[p] = hnew[l];
        w->s.sactive[p] = 1;
        w->s.srow[p] = pn__mpm_row_of(w, sx);
        w->s.pstat[p] = clamped[l] != 0 ? 0x100 : 0;
    }
}

/* The P2G records of every particle, when the state did not come from an explicit step; the
   state is checked on the way (x inside the grid, everything finite). */
static pn_result pn__mpm_xrecords(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, dd = d * d;
    long lp;
    PN__OMP_FOR
    for (lp = 0; lp < (long)w->n; ++lp) {
        size_t p = (size_t)lp;
        const pn_real *x = w->x + p * (size_t)d;
        pn_real tau[9] = {0}, hard;
        w->s.pstat[p] = 0;
        if (!w->active[p]) continue;
        if (!pn__mpm_in_grid(w, x)) { /* also NaN */
            w->s.pstat[p] = pn__all_finite(d, x) ? 0x1000 : 0x2000;
            continue;
        }
        if (!pn__all_finite(d, w->v + p * (size_t)d) || !pn__all_finite(dd, w->C + p * (size_t)dd)) {
            w->s.pstat[p] = PN_ERROR_NONFINITE;
            continue;
        }
        w->s.pstat[p] = (int)pn_kirchhoff_stress(&w->groups[w->group[p]].material, d, w->F + p * (size_t)dd, w->h[p], tau);
        if (w->s.pstat[p] != PN_OK) continue;
        w->s.prow[p] = pn__mpm_row_of(w, x);
        hard = pn__hardening(&w->groups[w->group[p]].material, w->h[p]);
        if (d == 2) pn__mpm_pack(w, p, tau, hard, w->s.ppay, 2);
        else pn__mpm_pack(w, p, tau, hard, w->s.ppay, 3);
    }
    {
        size_t p;
        for (p = 0; p < w->n; ++p) { /* the first particle at fault */
            if (!w->active[p] || !w->s.pstat[p]) continue;
            if (w->s.pstat[p] < 0x1000) break;
            w->error_particle = (long)p;
            if (w->s.pstat[p] == 0x2000)
                return PN__FAIL(w, PN_ERROR_NONFINITE, "particle %lu has a NaN or infinite x (was it written by "
                                    "hand?)", (unsigned long)p);
            return PN__FAIL(w, PN_ERROR_OUTSIDE_DOMAIN, "particle %lu is outside the grid (was x written by "
                                "hand?)", (unsigned long)p);
        }
    }
    return pn__mpm_first_error(w, dt);
}

/* The records of the last explicit step serve the next, but x is a public array: a particle
   written by hand since (NaN, outside the grid, another row of nodes) would make P2G write
   out of bounds. Each active particle's x is checked against the grid and its row of axis 0
   (prow) taken again: one pass over x, branch-free. */
static pn_result pn__mpm_xcheck(pn_mpm_world *w) {
    int d = w->dim, i, bad = 0, moved = 0;
    long lp;
#if defined(_OPENMP)
#pragma omp parallel for schedule(static) reduction(| : bad, moved) if (w->n >= w->desc.parallel_min_particles)
#endif
    for (lp = 0; lp < (long)w->n; ++lp) { /* read only: the rows are written again only if one moved */
        const pn_real *x = w->x + (size_t)lp * (size_t)d;
        int in = w->active[lp] != 0, k;
        for (k = 0; k < d; ++k) in &= x[k] >= w->s.grid_lo[k] && x[k] <= w->s.grid_hi[k]; /* also NaN */
        bad |= w->active[lp] && !in;
        moved |= in && w->s.prow[lp] != pn__mpm_row_of(w, x); /* (a retired particle's x may be anything) */
    }
    if (moved && !bad)
        for (lp = 0; lp < (long)w->n; ++lp)
            if (w->active[lp]) w->s.prow[lp] = pn__mpm_row_of(w, w->x + (size_t)lp * (size_t)d);
    if (!bad) return PN_OK;
    for (lp = 0; lp < (long)w->n; ++lp) {
        const pn_real *x = w->x + (size_t)lp * (size_t)d;
        if (!w->active[lp] || pn__mpm_in_grid(w, x)) continue;
        w->error_particle = (long)lp;
        for (i = 0; i < d && pn__finite(x[i]); ++i) {
        }
        if (i < d)
            return PN__FAIL(w, PN_ERROR_NONFINITE, "particle %lu has a NaN or infinite x (was it written by hand?)",
                                (unsigned long)lp);
        return PN__FAIL(w, PN_ERROR_OUTSIDE_DOMAIN, "particle %lu is outside the grid (was x written by hand?)",
                            (unsigned long)lp);
    }
    return PN_OK;
}

PN__DEF pn_result pn_mpm_step_explicit(pn_mpm_world *w, pn_real dt, pn_mpm_stats *stats) {
    int d, dd;
    long l;
    pn_real tf, flip, reach, v2max = 0, *t;
    int *row;
    pn_mpm_stats st;
    pn_result r;
    PN_ASSERT(w);
    w->error[0] = 0;
    if (!pn__finite(dt) || !(dt > 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_step_explicit: dt_s = %g must be finite and > 0", (double)dt);
    { /* far beyond the wave-speed bound no explicit step is stable (the largest found stable
         is below 2x pn_mpm_stable_dt: tests/test_scene.c): refused before anything is spent */
        pn_real rest = pn__mpm_rest_dt(w), sdt;
        if (rest > 0 && dt > PN__MPM_EXPLICIT_MAX * rest)
            return PN__FAIL(w, PN_ERROR_STEP_TOO_LARGE, "pn_mpm_step_explicit: dt_s = %g s is more than %dx the stable "
                                "step (pn_mpm_stable_dt: %g s here; pn_mpm_advance takes stable steps)", (double)dt,
                                PN__MPM_EXPLICIT_MAX, pn_mpm_stable_dt(w, &sdt) == PN_OK ? (double)sdt : (double)rest);
    }
    d = w->dim;
    dd = d * d;
    tf = w->desc.filter_time_s;
    flip = tf > 0 && dt < tf ? 1 - dt / tf : 0; /* the FLIP share 1 - s */
    reach = w->desc.advection_limit * w->desc.dx_m / dt; /* the fastest honest speed */
    pn__mpm_stats_clear(&st, 0);
    if (!w->s.rec_ok && (r = pn__mpm_xrecords(w, dt)) != PN_OK) return r;
    if (w->s.rec_ok && (r = pn__mpm_xcheck(w)) != PN_OK) return r;
    w->s.rec_ok = 1;
    pn__mpm_xp2g(w, dt);
    if (w->s.n_loads) pn__mpm_xloads(w, dt);
    if (w->s.xf_n) pn__mpm_xforces(w, dt);
    st.active_nodes = pn__mpm_xgrid(w, dt);
    if (w->s.n_drives) pn__mpm_xdrive_grid(w, dt);
    { /* G2P in index order (the particle arrays stream), retired particles copied, and the
         statistics: integer counts and a max, the same whatever the thread count */
        size_t n_plastic = 0, n_left = 0, n_alive = 0;
        long nb = (long)((w->n + PN__MPM_LANES - 1) / PN__MPM_LANES);
        int any = 0, g, lanes = d == 2 && flip == 0 && w->s.gdense0 == NULL, chunk = 8;
#if defined(_OPENMP)
        /* about 16 chunks per thread: enough to even out a busy core, few enough that the
           chunks' shared edges (every output array's cache line there) and the queue stay rare */
        chunk = (int)PN__MAX(8L, nb / (16L * omp_get_max_threads()));
#else
        (void)chunk;
#endif
        pn_real gpar[5 * PN_MPM_MAX_GROUPS];
        for (g = 0; g < w->n_groups; ++g)
            gpar[5 * g] = (pn_real)pn__fcr2_params(&w->groups[g].material, gpar + 5 * g + 1, gpar + 5 * g + 2,
                                                   gpar + 5 * g + 3, gpar + 5 * g + 4);
#if defined(_OPENMP)
#pragma omp parallel for schedule(dynamic, chunk) reduction(+ : n_plastic, n_left, n_alive) reduction(max : v2max) \
    reduction(| : any) if (w->n >= w->desc.parallel_min_particles)
#endif
        for (l = 0; l < nb; ++l) { /* batches of PN__MPM_LANES particles */
            size_t q0 = (size_t)l * PN__MPM_LANES, q;
            int nl = (int)PN__MIN((size_t)PN__MPM_LANES, w->n - q0);
            unsigned char done[PN__MPM_LANES] = {0};
            pn_real vc[6][PN__MPM_LANES];
            if (lanes) pn__mpm_xg2p2_lanes(w, q0, nl, dt, reach, gpar, done, vc, &n_alive, &n_plastic, &v2max);
            for (q = q0; q < q0 + (size_t)nl; ++q) {
                const pn_real *sv = w->s.sv + q * (size_t)d;
                pn_real sp = 0;
                int i, stat;
                if (done[q - q0]) continue; /* counted in the lanes */
                if (!w->active[q]) { /* retired particles keep their last state */
                    w->s.pstat[q] = 0;
                    w->s.sactive[q] = 0;
                    memcpy(w->s.sx + q * (size_t)d, w->x + q * (size_t)d, sizeof(pn_real) * (size_t)d);
                    memcpy(w->s.sv + q * (size_t)d, w->v + q * (size_t)d, sizeof(pn_real) * (size_t)d);
                    memcpy(w->s.sC + q * (size_t)dd, w->C + q * (size_t)dd, sizeof(pn_real) * (size_t)dd);
                    memcpy(w->s.sF + q * (size_t)dd, w->F + q * (size_t)dd, sizeof(pn_real) * (size_t)dd);
                    w->s.sh[q] = w->h[q];
                    continue;
                }
                if (d == 2) pn__mpm_xg2p(w, q, dt, flip, reach, 2, lanes ? vc[0] : NULL, (int)(q - q0));
                else pn__mpm_xg2p(w, q, dt, flip, reach, 3, NULL, 0);
                stat = w->s.pstat[q];
                any |= stat;
                n_plastic += (size_t)((stat & 0x100) != 0);
                if (stat & 0x200) {
                    n_left++;
                    continue;
                }
                for (i = 0; i < d; ++i) sp += sv[i] * sv[i];
                n_alive++;
                v2max = PN__MAX(v2max, sp);
            }
        }
        if (w->s.n_drives) pn__mpm_xdrive_state(w, dt);
        pn__mpm_xclear(w);
        if ((any & 0xcff) && (r = pn__mpm_first_error(w, dt)) != PN_OK) return r;
        st.plastic = n_plastic;
        st.left_domain = n_left;
        st.particles = n_alive;
    }
    st.max_speed_m_s = PN__SQRT(v2max);
    pn__mpm_commit(w, dt, &st);
    t = w->s.ppay, w->s.ppay = w->s.spay, w->s.spay = t;
    row = w->s.prow, w->s.prow = w->s.srow, w->s.srow = row;
    w->s.rec_ok = 1;
    w->s.n_lag = 0; /* the implicit friction memory is stale now */
    if (stats) *stats = st;
    return PN_OK;
}

/* ======================================================================================
   >>implicit: optimization time integration. Unknowns: the velocities of the active nodes.
   E(v) = sum_i m_i/2 |v_i - v*_i|^2 + sum_p V_p Psi_p(F_p(v)) over the velocities the
   contact leaves free, with F_p(v) = (I + dt sum_i v_i g_ip^T) F_p^n.
   dE/dv_i = m_i (v_i - v*_i) + dt sum_p V_p P_p F_p^nT g_ip; the Hessian
   applies each particle's PSD dP/dF to dF_p = dt (sum_j d_j g_jp^T) F_p^n. Particle
   terms are computed per particle, then gathered per node (the fixed order of >>bin).
   The velocity gradient weights are g_ip = (4/dx^2) w_ip (x_i - x_p), the MLS-MPM form
   (Hu et al. 2018) rather than grad w_ip: then F_p(v) = (I + dt C_p(v)) F_p^n with C the
   APIC matrix, and the forces are those of the explicit step, so the two integrators
   share one discretization in space and the implicit one tends to the explicit reference
   as dt -> 0 (sand column at dt 1e-4 s, 4 passes, min/max mass IoU against it: 0.97,
   0.92 with grad w). Both reproduce affine velocities exactly.
   ====================================================================================== */

static pn_result pn__mpm_alloc_implicit(pn_mpm_world *w) {
    const pn_mpm_desc *desc = &w->desc;
    size_t nd = w->s.nodes * (size_t)w->dim, cap = w->cap;
    int d = w->dim, dd = d * d, fail = 0;
    if (w->s.vstar) return PN_OK;
    PN__MPM_A(s.vstar, nd, pn_real);
    PN__MPM_A(s.vsol, nd, pn_real);
    PN__MPM_A(s.vtry, nd, pn_real);
    PN__MPM_A(s.grad, nd, pn_real);
    PN__MPM_A(s.dir, nd, pn_real);
    PN__MPM_A(s.cg_r, nd, pn_real);
    PN__MPM_A(s.cg_z, nd, pn_real);
    PN__MPM_A(s.cg_p, nd, pn_real);
    PN__MPM_A(s.cg_q, nd, pn_real);
    PN__MPM_A(s.diag, nd, pn_real);
    PN__MPM_A(s.pP, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.pH, cap * (size_t)(dd * dd), pn_real);
    PN__MPM_A(s.pG, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.phG, cap, pn_real);
    PN__MPM_A(s.pF0, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.pty, cap, pn_real);
    PN__MPM_A(s.ppt, cap, pn_pnet_point);
    PN__MPM_A(s.pq, cap * (size_t)(w->s.ns * d), pn_real);
    PN__MPM_A(s.pdof, cap * (size_t)w->s.ns, long);
    PN__MPM_A(s.inc, cap * (size_t)w->s.ns, size_t);
    PN__MPM_A(s.inc_start, w->s.nodes + 1, size_t);
    PN__MPM_A(s.prank, cap, size_t);
    PN__MPM_A(s.bx, cap * (size_t)d, pn_real);
    PN__MPM_A(s.bv, cap * (size_t)d, pn_real);
    PN__MPM_A(s.bC, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.bF, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.bh, cap, pn_real);
    PN__MPM_A(s.bactive, cap, unsigned char);
    PN__MPM_A(s.lnode, w->s.nodes, size_t);
    PN__MPM_A(s.blnode, w->s.nodes, size_t);
    PN__MPM_A(s.lval, w->s.nodes, pn_real);
    PN__MPM_A(s.blval, w->s.nodes, pn_real);
    PN__MPM_A(s.ctau, cap * (size_t)(d * (d + 1) / 2), pn_real);
    PN__MPM_A(s.stau, cap * (size_t)(d * (d + 1) / 2), pn_real);
    if (!fail) return PN_OK;
    { /* leave the world as it was: free what this call allocated */
        void **r[] = {(void **)&w->s.vstar, (void **)&w->s.vsol, (void **)&w->s.vtry, (void **)&w->s.grad,
                      (void **)&w->s.dir, (void **)&w->s.cg_r, (void **)&w->s.cg_z, (void **)&w->s.cg_p,
                      (void **)&w->s.cg_q, (void **)&w->s.diag, (void **)&w->s.pP, (void **)&w->s.pH,
                      (void **)&w->s.pG, (void **)&w->s.phG, (void **)&w->s.pF0, (void **)&w->s.pty,
                      (void **)&w->s.ppt, (void **)&w->s.pq, (void **)&w->s.pdof, (void **)&w->s.inc,
                      (void **)&w->s.inc_start, (void **)&w->s.prank,
                      (void **)&w->s.bx, (void **)&w->s.bv, (void **)&w->s.bC, (void **)&w->s.bF,
                      (void **)&w->s.bh, (void **)&w->s.bactive, (void **)&w->s.lnode, (void **)&w->s.blnode,
                      (void **)&w->s.lval, (void **)&w->s.blval, (void **)&w->s.ctau, (void **)&w->s.stau};
        size_t i;
        for (i = 0; i < sizeof r / sizeof r[0]; ++i) {
            pn_free(&desc->allocator, *r[i]);
            *r[i] = NULL;
        }
    }
    return PN_ERROR_OUT_OF_MEMORY;
}
#undef PN__MPM_A

PN__DEF pn_result pn_mpm_group_set_energy(pn_mpm_world *w, int g, pn_energy energy,
                                          const pn_pnet *net) {
    char msg[256];
    pn_result r;
    PN_ASSERT(w);
    w->error[0] = 0;
    if (g < 0 || g >= w->n_groups)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_group_set_energy: group %d does not exist (%d groups)",
                            g, w->n_groups);
    r = pn__group_set_energy(&w->groups[g], g, w->dim, energy, net, msg, sizeof msg);
    if (r != PN_OK) return PN__FAIL(w, r, "pn_mpm_group_set_energy: %s", msg);
    if (w->s.tok) memset(w->s.tok, 0, w->cap); /* the Taylor models belong to the old network */
    return PN_OK;
}

static pn_energy pn__mpm_energy_of(const pn_group *g) {
    if (g->energy != PN_ENERGY_DEFAULT) return g->energy;
    return g->material.plastic == PN_PLASTIC_NONE ? PN_ENERGY_ELASTIC : PN_ENERGY_LAGGED;
}

/* A group's implicit energy density at F (a particle's or an element's), with P and dP/dF
   when asked (PSD-projected under PN_EVAL_PROJECT_PSD in flags): h the plastic state, G and
   hG the lagged energy's, pt PlasticityNet's point, ty the frozen DP yield stress (each
   prepared at F0). */
static pn_result pn__group_psi(const pn_group *g, int d, const pn_real *F, pn_real h, const pn_real *G, pn_real hG,
                               const pn_pnet_point *pt, pn_real ty, pn_real *psi, pn_real *P, pn_real *H, unsigned flags) {
    switch (pn__mpm_energy_of(g)) {
    case PN_ENERGY_LAGGED:
        return pn_lagged_energy(&g->material, d, F, G, hG, psi, P, H, flags);
    case PN_ENERGY_EXACT_VM:
        return pn_von_mises_energy(&g->material, d, F, h, psi, P, H, flags);
    case PN_ENERGY_PNET:
        return pn_pnet_energy(&g->pnet, pt, F, psi, P, H, flags);
    case PN_ENERGY_DP:
        return pn_dp_energy(&g->material, d, F, h, ty, psi, P, H, flags);
    default:
        return pn_elastic_energy(&g->material, d, F, h, psi, P, H, flags);
    }
}

/* Psi_p at F (energy density), with P and dP/dF when asked (PSD-projected unless Newton asked
   for the full Hessian: w->s.full_h). */
static pn_result pn__mpm_psi(const pn_mpm_world *w, size_t p, const pn_real *F, pn_real *psi,
                             pn_real *P, pn_real *H) {
    int dd = w->dim * w->dim;
    return pn__group_psi(&w->groups[w->group[p]], w->dim, F, w->h[p], w->s.pG + p * (size_t)dd, w->s.phG[p], &w->s.ppt[p],
                         w->s.pty[p], psi, P, H, w->s.full_h ? 0u : (unsigned)PN_EVAL_PROJECT_PSD);
}

/* The Taylor models' storage (pn_mpm_implicit_desc.pnet_reuse_tol), once a step needs it:
   a PlasticityNet group and reuse on. */
#define PN__MPM_A(f, count, type) w->f = (type *)pn__mpm_alloc(desc, count, sizeof(type), &fail)

static pn_result pn__mpm_alloc_reuse(pn_mpm_world *w) {
    const pn_mpm_desc *desc = &w->desc;
    size_t cap = w->cap;
    int d = w->dim, dd = d * d, fail = 0, g, any = 0;
    for (g = 0; g < w->n_groups; ++g) any |= pn__mpm_energy_of(&w->groups[g]) == PN_ENERGY_PNET;
    if (w->s.tok || !any || !(w->s.reuse_tol > 0)) return PN_OK;
    PN__MPM_A(s.tF, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.tpsi, cap, pn_real);
    PN__MPM_A(s.tP, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.tH, cap * (size_t)(dd * dd), pn_real);
    PN__MPM_A(s.tok, cap, unsigned char);
    PN__MPM_A(s.jF, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.jpsi, cap, pn_real);
    PN__MPM_A(s.jP, cap * (size_t)dd, pn_real);
    PN__MPM_A(s.jH, cap * (size_t)(dd * dd), pn_real);
    PN__MPM_A(s.jpH, cap * (size_t)(dd * dd), pn_real);
    PN__MPM_A(s.jppt, cap, pn_pnet_point);
    PN__MPM_A(s.jst, cap, unsigned char);
    if (!fail) return PN_OK;
    {
        void *all[] = {w->s.tF, w->s.tpsi, w->s.tP, w->s.tH, w->s.tok, w->s.jF, w->s.jpsi, w->s.jP, w->s.jH, w->s.jpH, w->s.jppt, w->s.jst};
        size_t i;
        for (i = 0; i < sizeof all / sizeof all[0]; ++i) pn_free(&desc->allocator, all[i]);
    }
    w->s.tF = w->s.tpsi = w->s.tP = w->s.tH = w->s.jF = w->s.jpsi = w->s.jP = w->s.jH = w->s.jpH = NULL;
    w->s.tok = w->s.jst = NULL, w->s.jppt = NULL;
    return PN_ERROR_OUT_OF_MEMORY;
}
#undef PN__MPM_A

/* particle p's Taylor model (tF, tP, tH, tpsi), its PSD dP/dF in pH and the point ppt it
   belongs to: into the journal (restore = 0) or back from it (restore = 1) */
static void pn__mpm_journal_copy(pn_mpm_world *w, size_t p, int restore) {
    size_t dd = (size_t)(w->dim * w->dim);
#define PN__MPM_J(live, kept, count) \
    memcpy(restore ? (live) : (kept), restore ? (kept) : (live), sizeof(pn_real) * (count))
    PN__MPM_J(w->s.tF + p * dd, w->s.jF + p * dd, dd);
    PN__MPM_J(w->s.tP + p * dd, w->s.jP + p * dd, dd);
    PN__MPM_J(w->s.tH + p * dd * dd, w->s.jH + p * dd * dd, dd * dd);
    PN__MPM_J(w->s.pH + p * dd * dd, w->s.jpH + p * dd * dd, dd * dd);
    PN__MPM_J(w->s.tpsi + p, w->s.jpsi + p, 1);
#undef PN__MPM_J
    if (restore) w->s.ppt[p] = w->s.jppt[p];
    else w->s.jppt[p] = w->s.ppt[p];
}

/* before a call's first change to particle p's model (a new model, its point prepared anew,
   pH taken as scratch): the model as the call found it */
static void pn__mpm_touch(pn_mpm_world *w, size_t p) {
    if (w->s.jst[p]) return;
    w->s.jst[p] = (unsigned char)(1 + (w->s.tok[p] != 0));
    if (w->s.tok[p]) pn__mpm_journal_copy(w, p, 0);
}

/* a call starts: nothing saved yet */
static void pn__mpm_journal_begin(pn_mpm_world *w) {
    if (w->s.jst) memset(w->s.jst, 0, w->n);
}

/* a failed call (or attempt): every model it changed back as the call found it */
static void pn__mpm_journal_undo(pn_mpm_world *w) {
    size_t p;
    if (!w->s.jst) return;
    for (p = 0; p < w->n; ++p) {
        if (w->s.jst[p] == 2) pn__mpm_journal_copy(w, p, 1);
        if (w->s.jst[p]) w->s.tok[p] = (unsigned char)(w->s.jst[p] == 2);
        w->s.jst[p] = 0;
    }
}

/* reuse_tol of a step from its desc, and the Taylor models' storage if it needs it */
static pn_real pn__mpm_reuse_tol(const pn_mpm_implicit_desc *o) {
    return o->pnet_double || o->pnet_reuse_tol < 0 ? 0 : o->pnet_reuse_tol > 0 ? o->pnet_reuse_tol : (pn_real)1e-5;
}
static pn_result pn__mpm_reuse_on(pn_mpm_world *w, const pn_mpm_implicit_desc *o) {
    w->s.reuse_tol = pn__mpm_reuse_tol(o);
    return pn__mpm_alloc_reuse(w);
}

/* Per implicit step, after >>bin, by sorted index j (particle p = order[j]): q_js =
   F_p^nT g_ps and the compact node of each slot s, and each active node k's incidences
   inc[inc_start[k] ..] = j ns + s in the order of a gather over pn__mpm_node_bases (base
   nodes by slot, particles sorted), so every per-node sum keeps one fixed order whatever
   the thread count. */
static void pn__mpm_implicit_setup(pn_mpm_world *w, int incidences) {
    int d = w->dim, dd = d * d, ns = w->s.ns;
    long l;
    size_t k;
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.start[w->s.nodes]; ++l) {
        size_t j = (size_t)l, p = w->s.order[j];
        const pn_real *Fn = w->F + p * (size_t)dd;
        int s, a, b;
        w->s.prank[p] = j;
        if (d == 3) { /* spelled out (see pn__mpm_push2), each term as the loop below makes it */
            const pn_real *W = w->s.pw + p * 9, *fx = w->s.pfx + p * 3;
            pn_real dx = w->desc.dx_m, k = 4 / (dx * dx);
            for (s = 0; s < 27; ++s) {
                const int *o = w->s.slot[s];
                pn_real *q = w->s.pq + (j * 27 + (size_t)s) * 3, g = k * (W[o[0]] * W[3 + o[1]] * W[6 + o[2]]);
                pn_real d0 = ((pn_real)o[0] - fx[0]) * dx, d1 = ((pn_real)o[1] - fx[1]) * dx;
                pn_real d2 = ((pn_real)o[2] - fx[2]) * dx;
                if (w->s.stress_on) q[0] = g * d0, q[1] = g * d1, q[2] = g * d2;
                else
                    for (b = 0; b < 3; ++b)
                        q[b] = ((0 + Fn[b] * g * d0) + Fn[3 + b] * g * d1) + Fn[6 + b] * g * d2;
                w->s.pdof[j * 27 + (size_t)s] = w->s.dof[w->s.pbase[p] + w->s.slot_off[s]];
            }
            continue;
        }
        for (s = 0; s < ns; ++s) {
            pn_real dpos[3], *q = w->s.pq + (j * (size_t)ns + (size_t)s) * (size_t)d;
            pn_real g = 4 / (w->desc.dx_m * w->desc.dx_m) * pn__mpm_weight(w, p, w->s.slot[s], dpos);
            for (b = 0; b < d; ++b) { /* q = F^nT g, g = (4/dx^2) w dpos (>>stress: g itself) */
                q[b] = 0;
                if (w->s.stress_on) q[b] = g * dpos[b];
                else
                    for (a = 0; a < d; ++a) q[b] += Fn[a * d + b] * g * dpos[a];
            }
            w->s.pdof[j * (size_t)ns + (size_t)s] = w->s.dof[w->s.pbase[p] + w->s.slot_off[s]];
        }
    }
    if (!incidences) return; /* (the stress formulation's sweeps scatter by particle) */
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.n_act; ++l) { /* counts, then offsets, then the lists */
        size_t base[27], c = 0;
        int o[27][3], sl[27], nb = pn__mpm_node_bases(w, w->s.act[l], base, o, sl), b;
        for (b = 0; b < nb; ++b) c += w->s.start[base[b] + 1] - w->s.start[base[b]];
        w->s.inc_start[l + 1] = c;
    }
    w->s.inc_start[0] = 0;
    for (k = 0; k < w->s.n_act; ++k) w->s.inc_start[k + 1] += w->s.inc_start[k];
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.n_act; ++l) {
        size_t base[27], e = w->s.inc_start[l], s;
        int o[27][3], sl[27], nb = pn__mpm_node_bases(w, w->s.act[l], base, o, sl), b;
        for (b = 0; b < nb; ++b)
            for (s = w->s.start[base[b]]; s < w->s.start[base[b] + 1]; ++s)
                w->s.inc[e++] = s * (size_t)ns + (size_t)sl[b];
    }
}

/* node vector out_k += sum_j pmat_j q_jk over node k's incidences (pmat by sorted index:
   V dt P, so this is dt V P F^nT g) */
/* (spelled out per dimension for the reason given at pn__mpm_push2; ns a constant, so
   p = ps / ns is no division instruction) */
static void pn__mpm_gather2(const pn_mpm_world *w, size_t k, pn_real *out) {
    size_t e;
    pn_real a0 = 0, a1 = 0;
    for (e = w->s.inc_start[k]; e < w->s.inc_start[k + 1]; ++e) {
        size_t ps = w->s.inc[e];
        const pn_real *A = w->s.pmat + ps / 9 * 4, *q = w->s.pq + ps * 2; /* ps = j ns + s */
        a0 += A[0] * q[0] + A[1] * q[1];
        a1 += A[2] * q[0] + A[3] * q[1];
    }
    out[0] += a0;
    out[1] += a1;
}

static void pn__mpm_gather3(const pn_mpm_world *w, size_t k, pn_real *out) {
    size_t e;
    pn_real a0 = 0, a1 = 0, a2 = 0;
    for (e = w->s.inc_start[k]; e < w->s.inc_start[k + 1]; ++e) {
        size_t ps = w->s.inc[e];
        const pn_real *A = w->s.pmat + ps / 27 * 9, *q = w->s.pq + ps * 3;
        a0 += A[0] * q[0] + A[1] * q[1] + A[2] * q[2];
        a1 += A[3] * q[0] + A[4] * q[1] + A[5] * q[2];
        a2 += A[6] * q[0] + A[7] * q[1] + A[8] * q[2];
    }
    out[0] += a0;
    out[1] += a1;
    out[2] += a2;
}

/* particle p's part of a Hessian product: pmat = V dt dP/dF : dF, dF = dt sum x_i q_ip^T
   (rows summed in independent parts: one long chain of dependent additions per row is what
   limited the 3D product) */
static void pn__mpm_hmul2(pn_mpm_world *w, size_t j, const pn_real *x, pn_real dt) {
    size_t p = w->s.order[j];
    pn_real dF[4], s = w->vol0[p] * dt, *out = w->s.pmat + j * 4;
    const pn_real *H = w->s.pH + p * 16;
    int i;
    pn__mpm_push2(w, j, x, dt, NULL, dF);
    for (i = 0; i < 4; ++i, H += 4) out[i] = s * ((H[0] * dF[0] + H[1] * dF[1]) + (H[2] * dF[2] + H[3] * dF[3]));
}

static void pn__mpm_hmul3(pn_mpm_world *w, size_t j, const pn_real *x, pn_real dt) {
    size_t p = w->s.order[j];
    pn_real dF[9], s = w->vol0[p] * dt, *out = w->s.pmat + j * 9;
    const pn_real *H = w->s.pH + p * 81;
    int i;
    pn__mpm_push3(w, j, x, dt, NULL, dF);
    for (i = 0; i < 9; ++i, H += 9)
        out[i] = s * ((H[0] * dF[0] + H[1] * dF[1] + H[2] * dF[2]) + (H[3] * dF[3] + H[4] * dF[4] + H[5] * dF[5]) +
                      (H[6] * dF[6] + H[7] * dF[7] + H[8] * dF[8]));
}

static void pn__mpm_gather_pmat(const pn_mpm_world *w, size_t k, pn_real *out) {
    if (w->dim == 2) pn__mpm_gather2(w, k, out);
    else pn__mpm_gather3(w, k, out);
}

/* PlasticityNet's energy density and P at F from particle p's Taylor model (>>implicit: tF,
   tpsi, tP, tH) when F is within reuse_tol of tF: psi + P:dF + dF:H:dF / 2 and P + H dF,
   dF = F - tF (P optional); 0 when F is too far. The model's error is of order |dF|^3 in
   the energy and |dF|^2 in P. */
static int pn__mpm_taylor(const pn_mpm_world *w, size_t p, const pn_real *F, pn_real *psi, pn_real *P) {
    int dd = w->dim * w->dim, a, b;
    const pn_real *F0 = w->s.tF + p * (size_t)dd, *P0 = w->s.tP + p * (size_t)dd, *H = w->s.tH + p * (size_t)(dd * dd);
    pn_real dF[9], e = 0;
    for (a = 0; a < dd; ++a)
        if (!(PN__FABS(dF[a] = F[a] - F0[a]) <= w->s.reuse_tol)) return 0;
    for (a = 0; a < dd; ++a) {
        pn_real hd = 0;
        for (b = 0; b < dd; ++b) hd += H[a * dd + b] * dF[b];
        e += dF[a] * (P0[a] + hd / 2);
        if (P) P[a] = P0[a] + hd;
    }
    *psi = w->s.tpsi[p] + e;
    return 1;
}

/* E(v); with_derivs: also the gradient (w->s.grad) and each particle's P, and with_derivs == 2
   each particle's PSD dP/dF for the Hessian. A failed
   particle evaluation (an inverted F, say) gives *E = +inf without derivatives, else its
   error (w->error_particle says which). */
static pn_result pn__mpm_objective(pn_mpm_world *w, const pn_real *v, pn_real dt, int with_derivs,
                                   pn_real *E) {
    int d = w->dim, dd = d * d, reuse = w->s.tok && w->s.reuse_tol > 0;
    long l, nblk = (long)((w->n + PN_MLP_LANES - 1) / PN_MLP_LANES);
    pn_result r;
    PN__OMP_FOR
    for (l = 0; l < nblk; ++l) { /* blocks of PN_MLP_LANES particles: PlasticityNet's in lanes */
        size_t p0 = (size_t)l * PN_MLP_LANES, p1 = PN__MIN(w->n, p0 + PN_MLP_LANES), p, lp[PN_MLP_LANES];
        pn_real Fl[PN_MLP_LANES * 9], psil[PN_MLP_LANES], Pl[PN_MLP_LANES * 9], Hl[PN_MLP_LANES * 81];
        const pn_pnet_point *ptl[PN_MLP_LANES];
        pn_result stl[PN_MLP_LANES];
        int nl = 0, gl = -1, i, k;
        for (p = p0; p < p1; ++p) {
            pn_real F[9], psi = 0, *P = w->s.pP + p * (size_t)dd, *H = w->s.pH + p * (size_t)(dd * dd);
            w->s.pscal[p] = 0;
            w->s.pstat[p] = 0;
            if (!w->active[p]) continue;
            pn__mpm_push(w, p, v, dt, w->F + p * (size_t)dd, F);
            if (reuse && w->s.tok[p] && pn__mpm_taylor(w, p, F, &psi, with_derivs ? P : NULL)) {
                w->s.pscal[p] = w->vol0[p] * psi; /* pH keeps the PSD dP/dF at tF */
                continue;
            }
            if (w->s.pnet_lanes && pn__mpm_energy_of(&w->groups[w->group[p]]) == PN_ENERGY_PNET &&
                (gl < 0 || gl == w->group[p])) { /* one network per block's lanes */
                gl = w->group[p];
                lp[nl] = p;
                ptl[nl] = &w->s.ppt[p];
                memcpy(Fl + nl * dd, F, sizeof(pn_real) * (size_t)dd);
                nl++;
                continue;
            }
            w->s.pstat[p] = (int)pn__mpm_psi(w, p, F, &psi, with_derivs ? P : NULL, with_derivs > 1 ? H : NULL);
            w->s.pscal[p] = w->vol0[p] * psi;
        }
        if (nl) {
            int keep = reuse && with_derivs > 1; /* a new Taylor model: dP/dF unprojected, then projected here */
            pn_pnet_energy_lanes(&w->groups[gl].pnet, nl, ptl, Fl, psil, with_derivs ? Pl : NULL,
                                 with_derivs > 1 ? Hl : NULL, keep || w->s.full_h ? 0u : (unsigned)PN_EVAL_PROJECT_PSD, stl);
            for (k = 0; k < nl; ++k) {
                pn_real *H = w->s.pH + (p = lp[k]) * (size_t)(dd * dd);
                if (keep) pn__mpm_touch(w, p); /* before pH and the model change */
                if (stl[k] == PN_OK && with_derivs > 1) {
                    memcpy(H, Hl + k * dd * dd, sizeof(pn_real) * (size_t)(dd * dd));
                    if (keep && !w->s.full_h) stl[k] = pn_sym_project_psd(dd, H);
                }
                w->s.pstat[p] = (int)stl[k];
                if (stl[k] != PN_OK) continue;
                w->s.pscal[p] = w->vol0[p] * psil[k];
                if (with_derivs) memcpy(w->s.pP + p * (size_t)dd, Pl + k * dd, sizeof(pn_real) * (size_t)dd);
                if (keep) {
                    w->s.tok[p] = 1, w->s.tpsi[p] = psil[k];
                    memcpy(w->s.tF + p * (size_t)dd, Fl + k * dd, sizeof(pn_real) * (size_t)dd);
                    memcpy(w->s.tP + p * (size_t)dd, Pl + k * dd, sizeof(pn_real) * (size_t)dd);
                    memcpy(w->s.tH + p * (size_t)(dd * dd), Hl + k * dd * dd, sizeof(pn_real) * (size_t)(dd * dd));
                }
            }
        }
        for (p = p0; with_derivs && p < p1; ++p) /* pmat (by sorted index) = V dt P */
            if (w->active[p] && w->s.pstat[p] == PN_OK)
                for (i = 0; i < dd; ++i) w->s.pmat[w->s.prank[p] * (size_t)dd + (size_t)i] = w->vol0[p] * dt * w->s.pP[p * (size_t)dd + (size_t)i];
    }
    r = pn__mpm_first_error(w, dt);
    if (r != PN_OK) {
        if (with_derivs) return r;
        *E = (pn_real)HUGE_VAL;
        return PN_OK;
    }
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.n_act; ++l) {
        size_t k = (size_t)l;
        const pn_real *vk = v + k * (size_t)d, *sk = w->s.vstar + k * (size_t)d;
        pn_real *gk = w->s.grad + k * (size_t)d, e = 0;
        int i;
        for (i = 0; i < d; ++i) {
            pn_real dv = vk[i] - sk[i];
            e += w->s.grid_m[k] / 2 * dv * dv;
            if (with_derivs) gk[i] = w->s.grid_m[k] * dv;
        }
        if (w->s.clam[k] > 0 && !(w->s.chold[k] & PN__MPM_STICK)) { /* sliding: mu L t . u */
            pn_real f = w->s.cmu[k] * w->s.clam[k];
            for (i = 0; i < d; ++i) {
                e += f * w->s.ctan[k * 3 + (size_t)i] * (vk[i] - w->s.cvel[k * 3 + (size_t)i]);
                if (with_derivs) gk[i] += f * w->s.ctan[k * 3 + (size_t)i];
            }
        }
        if (with_derivs) pn__mpm_gather_pmat(w, k, gk);
        w->s.cg_q[k] = e; /* the node's energy, summed below */
    }
    *E = pn__mpm_sum(w, w->n, w->s.pscal, NULL) + pn__mpm_sum(w, w->s.n_act, w->s.cg_q, NULL);
    return PN_OK;
}

/* defined below, used here: */
static void pn__mpm_mg_apply(pn_mpm_world *w, int l, const pn_real *x, const pn_real *b, pn_real *out); /* >>multigrid */

/* out = S H x (S: the contact filter) */
static void pn__mpm_hess_vec(pn_mpm_world *w, const pn_real *x, pn_real dt, pn_real *out) {
    int d = w->dim;
    long l;
    if (w->s.mg_on && w->s.mg_current) { /* the assembled matrix: A^ x = S A x on filtered x */
        size_t k;
        pn__mpm_mg_apply(w, 0, x, NULL, out);
        for (k = 0; k < w->s.n_act; ++k) pn__mpm_filter(w, k, out + k * (size_t)d);
        return;
    }
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.start[w->s.nodes]; ++l) { /* the active particles, sorted */
        if (d == 2) pn__mpm_hmul2(w, (size_t)l, x, dt);
        else pn__mpm_hmul3(w, (size_t)l, x, dt);
    }
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.n_act; ++l) {
        size_t k = (size_t)l;
        const pn_real *xk = x + k * (size_t)d;
        pn_real *ok = out + k * (size_t)d;
        int i;
        for (i = 0; i < d; ++i) ok[i] = w->s.grid_m[k] * xk[i];
        pn__mpm_gather_pmat(w, k, ok);
        pn__mpm_filter(w, k, ok);
    }
}

/* Jacobi preconditioner: the diagonal of H (mass and each particle's contribution) */
static void pn__mpm_diagonal(pn_mpm_world *w, pn_real dt) {
    int d = w->dim, dd = d * d;
    long l;
    PN__OMP_FOR
    for (l = 0; l < (long)w->s.n_act; ++l) {
        size_t k = (size_t)l, e;
        int i, a, c;
        pn_real *dg = w->s.diag + k * (size_t)d;
        for (i = 0; i < d; ++i) dg[i] = w->s.grid_m[k];
        for (e = w->s.inc_start[k]; e < w->s.inc_start[k + 1]; ++e) {
            size_t ps = w->s.inc[e], p = w->s.order[ps / (size_t)w->s.ns];
            const pn_real *H = w->s.pH + p * (size_t)(dd * dd), *q = w->s.pq + ps * (size_t)d;
            for (i = 0; i < d; ++i) {
                pn_real acc = 0; /* sum_ac H[(i a),(i c)] q_a q_c, q = F^nT g */
                for (a = 0; a < d; ++a)
                    for (c = 0; c < d; ++c) acc += H[(i * d + a) * dd + i * d + c] * q[a] * q[c];
                dg[i] += w->vol0[p] * dt * dt * acc;
            }
        }
        for (i = 0; i < d; ++i)
            if (!(dg[i] > 0)) dg[i] = 1;
    }
}

/* defined below, used here: */
static void pn__mpm_mg_vcycle(pn_mpm_world *w, int l, const pn_real *b, pn_real *x); /* >>multigrid */

/* z = S B r: B the V-cycle (multigrid) or the inverse diagonal (Jacobi) */
static void pn__mpm_precondition(pn_mpm_world *w, const pn_real *r, pn_real *z) {
    int d = w->dim;
    size_t k, i;
    if (w->s.mg_on) pn__mpm_mg_vcycle(w, 0, r, z);
    for (k = 0; k < w->s.n_act; ++k) {
        if (!w->s.mg_on)
            for (i = 0; i < (size_t)d; ++i) z[k * (size_t)d + i] = r[k * (size_t)d + i] / w->s.diag[k * (size_t)d + i];
        pn__mpm_filter(w, k, z + k * (size_t)d);
    }
}

/* the world and the step for the shared solvers (>>kit, plastinet.h): the filtered Hessian, the
   preconditioner and the chunked dot for pn__pcg, the objective for pn__armijo */
typedef struct pn__mpm_cg {
    pn_mpm_world *w;
    pn_real dt;
} pn__mpm_cg;

static void pn__mpm_cg_apply(void *ctx, const pn_real *x, pn_real *y) {
    pn__mpm_cg *c = (pn__mpm_cg *)ctx;
    pn__mpm_hess_vec(c->w, x, c->dt, y);
}

static void pn__mpm_cg_precond(void *ctx, const pn_real *r, pn_real *z) { pn__mpm_precondition(((pn__mpm_cg *)ctx)->w, r, z); }

static pn_real pn__mpm_cg_dot(void *ctx, size_t n, const pn_real *a, const pn_real *b) {
    return pn__mpm_sum(((pn__mpm_cg *)ctx)->w, n, a, b);
}

/* Solve S H S dir = -S grad by preconditioned CG (>>kit, plastinet.h) to |r| <= rel_tol |S grad|;
   returns iterations. warm: resume from the dir of the last call (same H and grad). */
static int pn__mpm_pcg(pn_mpm_world *w, pn_real dt, int max_it, pn_real rel_tol, int warm, int *capped) {
    int d = w->dim;
    size_t k, i;
    pn__mpm_cg c;
    pn__cg_ops op;
    if (!warm && !w->s.mg_on) pn__mpm_diagonal(w, dt);
    for (k = 0; k < w->s.n_act; ++k) {
        for (i = 0; i < (size_t)d; ++i) w->s.cg_r[k * (size_t)d + i] = -w->s.grad[k * (size_t)d + i];
        pn__mpm_filter(w, k, w->s.cg_r + k * (size_t)d);
    }
    c.w = w, c.dt = dt;
    w->s.curv = 0; /* set when a Hessian of unprojected particles is not positive definite */
    op.ctx = &c, op.apply = pn__mpm_cg_apply, op.precond = pn__mpm_cg_precond, op.dot = pn__mpm_cg_dot, op.curv = &w->s.curv;
    return pn__pcg(&op, w->s.n_act * (size_t)d, w->s.dir, w->s.cg_r, w->s.cg_z, w->s.cg_p, w->s.cg_q, max_it, rel_tol, warm, capped);
}

/* Per-pass preparation of every particle's energy at F0 = F(v) (lagged G, PlasticityNet
   point); returns max |F0_new - F0_old| in *res (0 on the first pass). The DP yield of the
   first pass comes from F^n, not F(v*): v* is free fall onto the held floor nodes, which
   compresses the bottom cells by g dt^2 / dx (0.17 at dt = 1/60 s, res 64), a pressure
   hundreds of times the hydrostatic one, and the column then stands as if elastic (runout
   -32% at 1/60 s; from F^n -2% with 3 contact rounds). For the same reason PlasticityNet's
   first F0 is F(va) when va is given: the step's motion without gravity's kick (at dt 1e-3
   s the kick's compression, 6e-4 at res 64, is twice the column's elastic strain, and the
   network's error, relative to the pair's strain, then dwarfs the stress at the solution). */
static pn_result pn__mpm_prepare_pass(pn_mpm_world *w, const pn_real *v, const pn_real *va, pn_real dt, int first,
                                      pn_real *res) {
    int d = w->dim, dd = d * d;
    long l, nblk = (long)((w->n + PN_MLP_LANES - 1) / PN_MLP_LANES);
    size_t p;
    pn_real worst = 0;
    PN__OMP_FOR
    for (l = 0; l < nblk; ++l) { /* blocks of PN_MLP_LANES particles: PlasticityNet's in lanes */
        size_t p0 = (size_t)l * PN_MLP_LANES, p1 = PN__MIN(w->n, p0 + PN_MLP_LANES), q, lp[PN_MLP_LANES];
        pn_real Fl[PN_MLP_LANES * 9], hl[PN_MLP_LANES];
        pn_pnet_point ptl[PN_MLP_LANES];
        pn_result stl[PN_MLP_LANES];
        int nl = 0, gl = -1, k;
        for (q = p0; q < p1; ++q) {
            const pn_group *g = &w->groups[w->group[q]];
            pn_real F0[9], *old = w->s.pF0 + q * (size_t)dd, diff = 0;
            pn_energy en;
            int i;
            w->s.pstat[q] = 0;
            w->s.pscal[q] = 0;
            if (!w->active[q]) continue;
            en = pn__mpm_energy_of(g);
            pn__mpm_push(w, q, first && va && en == PN_ENERGY_PNET ? va : v, dt, w->F + q * (size_t)dd, F0);
            if (!first)
                for (i = 0; i < dd; ++i) diff = PN__MAX(diff, PN__FABS(F0[i] - old[i]));
            w->s.pscal[q] = diff;
            memcpy(old, F0, sizeof(pn_real) * (size_t)dd);
            if (en == PN_ENERGY_PNET && w->s.tok && w->s.tok[q]) { /* keep a point F0 has not left */
                const pn_pnet_point *pt = &w->s.ppt[q];
                int keep = w->s.reuse_tol > 0 && pt->h == w->h[q];
                for (i = 0; keep && i < dd; ++i) keep = PN__FABS(F0[i] - pt->F0[i]) <= w->s.reuse_tol;
                if (keep) continue;
                pn__mpm_touch(w, q);
                w->s.tok[q] = 0;
            }
            if (en == PN_ENERGY_PNET && w->s.pnet_lanes && (gl < 0 || gl == w->group[q])) {
                gl = w->group[q]; /* one network per block's lanes */
                lp[nl] = q;
                hl[nl] = w->h[q];
                memcpy(Fl + nl * dd, F0, sizeof(pn_real) * (size_t)dd);
                nl++;
            } else if (en == PN_ENERGY_LAGGED)
                w->s.pstat[q] = (int)pn_lagged_prepare(&g->material, d, F0, w->h[q], w->s.pG + q * (size_t)dd, &w->s.phG[q]);
            else if (en == PN_ENERGY_PNET)
                w->s.pstat[q] = (int)pn_pnet_prepare(&g->pnet, F0, w->h[q], &w->s.ppt[q], NULL, NULL);
            else if (en == PN_ENERGY_DP)
                w->s.pstat[q] = (int)pn_dp_prepare(&g->material, d, first ? w->F + q * (size_t)dd : F0, w->h[q],
                                                 &w->s.pty[q]);
        }
        if (nl) {
            pn_pnet_prepare_lanes(&w->groups[gl].pnet, nl, Fl, hl, ptl, stl);
            for (k = 0; k < nl; ++k) {
                w->s.pstat[lp[k]] = (int)stl[k];
                if (stl[k] == PN_OK) w->s.ppt[lp[k]] = ptl[k];
            }
        }
    }
    for (p = 0; p < w->n; ++p) worst = PN__MAX(worst, w->s.pscal[p]);
    *res = worst;
    return pn__mpm_first_error(w, dt);
}

/* st += a later step's sub: counts add up, the state figures are the later one's, the
   residuals and errors the worst (substeps and solves are the caller's) */
static void pn__mpm_stats_add(pn_mpm_stats *st, const pn_mpm_stats *sub) {
    int i;
    st->particles = sub->particles;
    st->plastic += sub->plastic;
    st->left_domain += sub->left_domain;
    st->active_nodes = PN__MAX(st->active_nodes, sub->active_nodes);
    st->max_speed_m_s = sub->max_speed_m_s;
    st->fixed_point_iters += sub->fixed_point_iters;
    st->newton_iters += sub->newton_iters;
    st->cg_iters += sub->cg_iters;
    st->mg_builds += sub->mg_builds;
    st->active_set_rounds += sub->active_set_rounds;
    st->line_search_failures += sub->line_search_failures;
    st->cg_capped += sub->cg_capped;
    st->newton_residual = PN__MAX(st->newton_residual, sub->newton_residual);
    st->fixed_point_residual = PN__MAX(st->fixed_point_residual, sub->fixed_point_residual);
    st->force_error = PN__MAX(st->force_error, sub->force_error);
    st->force_error_regularizer = PN__MAX(st->force_error_regularizer, sub->force_error_regularizer);
    st->apex_fraction = PN__MAX(st->apex_fraction, sub->apex_fraction);
    st->dt_over_cfl = PN__MAX(st->dt_over_cfl, sub->dt_over_cfl);
    st->sweeps += sub->sweeps;
    st->energy_rise = PN__MAX(st->energy_rise, sub->energy_rise);
    for (i = 0; i < PN_MPM_STAGES; ++i) st->stage_s[i] += sub->stage_s[i];
}

/* pn_mpm_stats.force_error and its parts at the grid velocities v (serial: a diagnostic). */
static void pn__mpm_force_error(pn_mpm_world *w, const pn_real *v, pn_real dt, pn_mpm_stats *st) {
    int d = w->dim, dd = d * d, i;
    size_t p;
    double err = 0, reg = 0, tot = 0, n = 0, apex = 0;
    for (p = 0; p < w->n; ++p) {
        const pn_group *g = &w->groups[w->group[p]];
        pn_real F[9], P[9], T[9], psi;
        double e = 0, r = 0, t = 0;
        if (!w->active[p] || g->material.plastic == PN_PLASTIC_NONE) continue;
        pn__mpm_push(w, p, v, dt, w->F + p * (size_t)dd, F);
        if (pn__mpm_psi(w, p, F, &psi, P, NULL) != PN_OK ||
            pn_return_map(&g->material, d, F, w->h[p], NULL, NULL, T) != PN_OK)
            continue;
        for (i = 0; i < dd; ++i) {
            e += (double)((P[i] - T[i]) * (P[i] - T[i]));
            t += (double)(T[i] * T[i]);
            if (pn__mpm_energy_of(g) == PN_ENERGY_PNET) {
                double df = (double)(g->pnet.reg * (F[i] - w->s.ppt[p].F0[i]));
                r += df * df;
            }
        }
        err += (double)w->vol0[p] * sqrt(e);
        reg += (double)w->vol0[p] * sqrt(r);
        tot += (double)w->vol0[p] * sqrt(t);
        n += 1;
        apex += t == 0;
    }
    if (n > 0 && tot > 0) {
        st->force_error = PN__MAX(st->force_error, (pn_real)(err / tot));
        st->force_error_regularizer = PN__MAX(st->force_error_regularizer, (pn_real)(reg / tot));
        st->apex_fraction = PN__MAX(st->apex_fraction, (pn_real)(apex / n));
    }
}

/* |S ((1 - alpha) grad) - alpha r|: the gradient the linear model predicts after the step
   alpha dir, with r = -S grad - S H dir the linear solve's residual; alpha = 0: |S grad|
   (the gradient on the free directions, what CG's relative residual is taken of) */
static pn_real pn__mpm_model_norm(pn_mpm_world *w, pn_real alpha) {
    int d = w->dim, i;
    size_t k;
    double s = 0;
    for (k = 0; k < w->s.n_act; ++k) {
        pn_real g[3];
        for (i = 0; i < d; ++i) g[i] = w->s.grad[k * (size_t)d + (size_t)i];
        pn__mpm_filter(w, k, g);
        for (i = 0; i < d; ++i) {
            pn_real e = alpha == 0 ? g[i] : (1 - alpha) * g[i] - alpha * w->s.cg_r[k * (size_t)d + (size_t)i];
            s += (double)(e * e);
        }
    }
    return (pn_real)sqrt(s);
}

/* Relative residual of Newton iteration it's linear solve: Eisenstat and Walker's choice 1
   (SIAM J. Sci. Comput. 17, 1996), eta = | |g_k| - |g_k-1 + H_k-1 s_k-1| | / |g_k-1|, how far
   the gradient strayed from the linear model's prediction (pred), with their safeguard
   eta >= eta_k-1^1.618 while that exceeds 0.1; between cg_rel_tol and cg_forcing_max. Where
   the quadratic model holds (a smooth energy near its minimum) solves stay tight; across the
   kinks of a plastic energy, where a precise direction is wasted, they stay loose. */
static pn_real pn__mpm_forcing(const pn_mpm_implicit_desc *o, int it, pn_real eta_prev, pn_real gprev,
                               pn_real pred, pn_real g) {
    pn_real lo = o->cg_rel_tol, hi = o->cg_forcing_max, eta, floor_prev;
    if (!(hi > lo)) return lo;
    if (it == 0 || !(gprev > 0)) return lo; /* no model yet: trust it (the full Newton step) */
    eta = PN__FABS(g - pred) / gprev;
    floor_prev = (pn_real)pow((double)eta_prev, 1.618);
    if (floor_prev > (pn_real)0.1) eta = PN__MAX(eta, floor_prev);
    return PN__MIN(PN__MAX(eta, lo), hi);
}

/* The stage clock: the time since the last mark goes to stage s (< 0: only the mark) */
static void pn__mpm_mark(pn_mpm_world *w, pn_mpm_stats *st, int s) {
    double t;
    if (!w->desc.clock_s) return;
    t = w->desc.clock_s(w->desc.clock_user);
    if (s >= 0) st->stage_s[s] += t - w->s.clock_last;
    w->s.clock_last = t;
}

/* the incremental potential's value for the shared line search (>>kit, plastinet.h) */
static pn_result pn__mpm_value(void *ctx, const pn_real *v, pn_real *E) {
    pn__mpm_cg *c = (pn__mpm_cg *)ctx;
    return pn__mpm_objective(c->w, v, c->dt, 0, E);
}

/* ======================================================================================
   >>friction: Coulomb friction of separating contacts, lagged as in IPC. The normal impulse L
   of a node is fixed for a solve; the node sticks (every component held) or slides against
   the constant force mu L t, t its tangential direction. Where L comes from:
   - a solution of this step (later passes and contact rounds): the held normal reaction;
   - the first solve of a step: the reaction at the end of the last implicit step (w->s.lnode,
     as a force, times dt), else, for a new contact, the impulse that stops the node's own
     approach, m max(0, -u_n), as the explicit projection uses.
   The start value of L matters: the gradient at v* overstates it (the elastic push of the
   material still falling onto a held node), a sliding block then stops several times short.
   The active set of separating contacts (which nodes hold, which let go) is here too.
   ====================================================================================== */

/* the node's held normal reaction in gradient g (kg m/s), 0 where nothing holds it */
static pn_real pn__mpm_reaction(const pn_mpm_world *w, size_t k, const pn_real *g) {
    const pn_real *dir = w->s.cdir + k * 9;
    pn_real L = 0;
    int b, i;
    for (b = 0; b < w->s.cn[k]; ++b) {
        pn_real gn = 0;
        if (!(w->s.chold[k] >> b & 1)) continue;
        for (i = 0; i < w->dim; ++i) gn += g[i] * dir[3 * b + i];
        L += PN__MAX(gn, 0);
    }
    return L;
}

static int pn__mpm_has_friction(const pn_mpm_world *w, size_t k) {
    return w->s.ckind[k] == PN_BOUNDARY_SEPARATE && (w->s.chold[k] & 0x7f) && w->s.cmu[k] > 0;
}

/* node k with normal impulse L: stick (when lagged_stick, or for a new friction state when
   mu L can stop its tangential momentum) or slide along its tangential velocity in v */
static void pn__mpm_stick_or_slide(pn_mpm_world *w, size_t k, pn_real *v, pn_real L, int fresh, int stick) {
    int d = w->dim, i;
    pn_real *vk = v + k * (size_t)d, u[3], ut = 0;
    w->s.clam[k] = L;
    if (!(L > 0)) {
        w->s.chold[k] = (unsigned char)(w->s.chold[k] & ~PN__MPM_STICK);
        w->s.clam[k] = 0;
        return;
    }
    for (i = 0; i < d; ++i) u[i] = vk[i] - w->s.cvel[k * 3 + (size_t)i];
    pn__mpm_filter(w, k, u);
    for (i = 0; i < d; ++i) ut += u[i] * u[i];
    ut = PN__SQRT(ut);
    if (fresh) stick = w->s.grid_m[k] * ut <= w->s.cmu[k] * L;
    if (stick || !(ut > 0)) {
        w->s.chold[k] = (unsigned char)(w->s.chold[k] | PN__MPM_STICK);
        pn__mpm_hold(w, k, vk);
        return;
    }
    w->s.chold[k] = (unsigned char)(w->s.chold[k] & ~PN__MPM_STICK);
    for (i = 0; i < d; ++i) w->s.ctan[k * 3 + (size_t)i] = u[i] / ut;
}

/* friction for the first solve of a step at start velocities v (v*: w->s.vstar) */
static void pn__mpm_friction_start(pn_mpm_world *w, pn_real *v, pn_real dt) {
    int d = w->dim, b, i;
    size_t k, j;
    for (k = 0; k < w->s.n_act; ++k) {
        w->s.clam[k] = -1; /* not set yet */
        w->s.chold[k] = (unsigned char)(w->s.chold[k] & ~PN__MPM_STICK);
    }
    for (j = 0; j < w->s.n_lag; ++j) { /* the contact held at the end of the last step holds on, */
        long kk = w->s.dof[w->s.lnode[j] >> 3]; /* along the directions it held then */
        if (kk < 0 || w->s.ckind[kk] != PN_BOUNDARY_SEPARATE || !w->s.cn[kk]) continue;
        w->s.chold[kk] = (unsigned char)(w->s.chold[kk] | ((w->s.lnode[j] & 7) & ((1u << w->s.cn[kk]) - 1)));
        pn__mpm_hold(w, (size_t)kk, v + (size_t)kk * (size_t)d);
        if (pn__mpm_has_friction(w, (size_t)kk))
            pn__mpm_stick_or_slide(w, (size_t)kk, v, PN__FABS(w->s.lval[j]) * dt, 0, w->s.lval[j] < 0);
    }
    for (k = 0; k < w->s.n_act; ++k) {
        pn_real L = 0;
        if (w->s.clam[k] >= 0) continue;
        w->s.clam[k] = 0;
        if (!pn__mpm_has_friction(w, k)) continue;
        for (b = 0; b < w->s.cn[k]; ++b) { /* the node's own approach */
            pn_real un = 0;
            if (!(w->s.chold[k] >> b & 1)) continue;
            for (i = 0; i < d; ++i)
                un += (w->s.vstar[k * (size_t)d + (size_t)i] - w->s.cvel[k * 3 + (size_t)i]) * w->s.cdir[k * 9 + (size_t)(3 * b + i)];
            L += w->s.grid_m[k] * PN__MAX(-un, 0);
        }
        pn__mpm_stick_or_slide(w, k, v, L, 1, 0);
    }
}

/* friction for a later solve: L from the reaction at the last solution (w->s.grad at v); the
   stick flags are those the active set left, a node with no friction before starts afresh */
static void pn__mpm_friction_update(pn_mpm_world *w, pn_real *v) {
    size_t k;
    for (k = 0; k < w->s.n_act; ++k) {
        int fresh = !(w->s.clam[k] > 0);
        if (!pn__mpm_has_friction(w, k)) {
            w->s.clam[k] = 0;
            continue;
        }
        pn__mpm_stick_or_slide(w, k, v, pn__mpm_reaction(w, k, w->s.grad + k * (size_t)w->dim), fresh,
                               (w->s.chold[k] & PN__MPM_STICK) != 0);
    }
}

/* the contact memory for the next step: the nodes a separating contact held with a positive
   reaction, their reaction force and stick flag at the solution */
static void pn__mpm_friction_record(pn_mpm_world *w, pn_real dt) {
    size_t k;
    w->s.n_lag = 0;
    for (k = 0; k < w->s.n_act; ++k) {
        pn_real L;
        if (w->s.ckind[k] != PN_BOUNDARY_SEPARATE || !(w->s.chold[k] & 0x7f)) continue;
        L = pn__mpm_reaction(w, k, w->s.grad + k * (size_t)w->dim);
        if (!(L > 0)) continue;
        w->s.lnode[w->s.n_lag] = w->s.act[k] << 3 | (size_t)(w->s.chold[k] & 7); /* the node, its held directions */
        w->s.lval[w->s.n_lag++] = (w->s.chold[k] & PN__MPM_STICK ? -L : L) / dt;
    }
}

/* Separating contact after a solve (grad at the solution): release held normals the
   solution pulls on, hold free ones it pushes through; a sticking node whose tangential
   reaction exceeds mu L slides, a sliding node that friction turned back sticks. Returns 1
   when the set changed. */
static int pn__mpm_active_set(pn_mpm_world *w, pn_real *v, pn_real vtol) {
    int d = w->dim, changed = 0;
    size_t k;
    for (k = 0; k < w->s.n_act; ++k) {
        const pn_real *dir = w->s.cdir + k * 9, *vel = w->s.cvel + k * 3, *g = w->s.grad + k * (size_t)d;
        pn_real *vk = v + k * (size_t)d, m = w->s.grid_m[k], f = w->s.cmu[k] * w->s.clam[k], gt[3], u[3], a = 0;
        int b, i, ch = 0, stick = (w->s.chold[k] & PN__MPM_STICK) != 0;
        if (w->s.ckind[k] != PN_BOUNDARY_SEPARATE || w->s.cn[k] == 0) continue;
        for (b = 0; b < w->s.cn[k]; ++b) {
            pn_real gn = 0, un = 0;
            for (i = 0; i < d; ++i) {
                gn += g[i] * dir[3 * b + i];
                un += (vk[i] - vel[i]) * dir[3 * b + i];
            }
            if ((w->s.chold[k] >> b & 1) && gn < -vtol * m) { /* pulls away: let go */
                w->s.chold[k] = (unsigned char)(w->s.chold[k] & ~(1 << b) & ~PN__MPM_STICK);
                ch = 1;
            } else if (!(w->s.chold[k] >> b & 1) && un < -vtol) { /* goes in: hold it */
                w->s.chold[k] = (unsigned char)(w->s.chold[k] | 1 << b);
                ch = 1;
            }
        }
        if (!ch && stick) { /* tangential reaction against the friction cone */
            w->s.chold[k] = (unsigned char)(w->s.chold[k] & ~PN__MPM_STICK);
            for (i = 0; i < d; ++i) gt[i] = g[i];
            pn__mpm_filter(w, k, gt);
            for (i = 0; i < d; ++i) a += gt[i] * gt[i];
            a = PN__SQRT(a);
            if (a > f + vtol * m) {
                for (i = 0; i < d; ++i) w->s.ctan[k * 3 + (size_t)i] = -gt[i] / a;
                ch = 1;
            } else {
                w->s.chold[k] = (unsigned char)(w->s.chold[k] | PN__MPM_STICK);
            }
        } else if (!ch && f > 0) { /* sliding: did friction turn it back? */
            for (i = 0; i < d; ++i) u[i] = vk[i] - vel[i];
            pn__mpm_filter(w, k, u);
            for (i = 0; i < d; ++i) a += u[i] * w->s.ctan[k * 3 + (size_t)i];
            if (a < 0) {
                w->s.chold[k] = (unsigned char)(w->s.chold[k] | PN__MPM_STICK);
                ch = 1;
            }
        }
        if (ch) pn__mpm_hold(w, k, vk);
        changed |= ch;
    }
    return changed;
}

/* ======================================================================================
   >>multigrid: the implicit Hessian assembled on the active nodes, and a Galerkin
   hierarchy over coarser grids for CG. Node I of level l + 1 sits at node 2I of level l;
   the prolongation is linear, P_iI = product over axes of 1 (i = 2I) or 1/2 (i = 2I +- 1),
   and A_l+1 = P^T A_l P, so quadratic B-splines' 5^dim coupling stays 5^dim on every level
   (|i - j| <= 2 per axis gives |I - J| <= 2). The smoother is block Gauss-Seidel in 3^dim
   colours (node index mod 3 per axis): rows of one colour are 3 or more apart, so they
   update independently and any thread count gives the same bits. One V-cycle, forward
   sweeps down and backward sweeps up, is symmetric positive definite whatever the coarse
   matrices (M + M^T - A = D > 0 for Gauss-Seidel), so it can precondition CG even when
   the hierarchy is older than the fine matrix. Held contact directions enter as
   A^_kl = S_k^T A_kl S_l (S the contact filter): on the filtered vectors CG works on,
   A^ x = S A x; the held directions have no stiffness, the smoother (a pseudo-inverse of
   each diagonal block) never moves them, and P^T A^ P is the coarse operator of the
   filtered prolongation S P, so coarse corrections respect the contacts. Each row is
   assembled in pn_real and stored in float: the smoother and CG's products stream the rows
   (125 blocks of 3x3 in 3D), and half the bytes made the 3D snow press's linear solve a
   quarter faster per Newton iteration; the preconditioner and Newton's linear model need no
   more digits than float keeps. (HOT, Wang et al. 2020, solves MPM's implicit step with the
   same ingredients.)
   ====================================================================================== */

#define PN__MPM_NB(d) ((d) == 2 ? 25 : 125) /* neighbours of a row: offsets -2..2 per axis */
#define PN__MPM_MG_SWEEPS 2 /* Gauss-Seidel sweeps down and up: V(2,2) took 40% fewer CG
                                iterations than V(1,1) at the same wall time (2D sand, 30k) */

static void pn__mpm_mg_idx(const pn__mpm_level *L, int d, size_t flat, int *idx) {
    int a;
    for (a = d - 1; a >= 0; --a) {
        idx[a] = (int)(flat % (size_t)L->nn[a]);
        flat /= (size_t)L->nn[a];
    }
}

/* the row arrays of level L for n rows (grown, never shrunk: no allocation once warm) */
static pn_result pn__mpm_mg_reserve(pn_mpm_world *w, pn__mpm_level *L, size_t n, int coarse) {
    const pn_allocator *al = &w->desc.allocator;
    int d = w->dim, dd = d * d, nb = PN__MPM_NB(d), fail = 0;
    size_t cap;
    if (n <= L->cap) return PN_OK;
    cap = n + n / 2 + 16;
#define PN__MPM_MGA(f, count, type)                                                         \
    pn_free(al, L->f);                                                                      \
    L->f = (type *)pn__mpm_alloc(&w->desc, count, sizeof(type), &fail)
    PN__MPM_MGA(nbr, cap * (size_t)nb, long);
    PN__MPM_MGA(A, cap * (size_t)(nb * dd), float);
    PN__MPM_MGA(Dinv, cap * (size_t)dd, pn_real);
    PN__MPM_MGA(x, cap * (size_t)d, pn_real);
    PN__MPM_MGA(b, cap * (size_t)d, pn_real);
    PN__MPM_MGA(r, cap * (size_t)d, pn_real);
    PN__MPM_MGA(crow, 2 * cap, size_t); /* rows by colour; scratch */
    if (coarse) {
        PN__MPM_MGA(node, cap, size_t);
    }
#undef PN__MPM_MGA
    L->cap = fail ? 0 : cap;
    return fail ? PN_ERROR_OUT_OF_MEMORY : PN_OK;
}

/* levels' grids and node maps, once (the first multigrid step) */
static pn_result pn__mpm_mg_init(pn_mpm_world *w) {
    int d = w->dim, l, a, fail = 0;
    pn__mpm_level *L = w->s.mg;
    if (w->s.mg_max) return PN_OK;
    for (a = 0; a < 3; ++a) {
        L[0].nn[a] = a < d ? w->desc.res[a] + 1 : 1;
        L[0].stride[a] = w->s.stride[a];
    }
    L[0].nodes = w->s.nodes;
    for (l = 1; l < PN__MPM_MG_MAX; ++l) {
        size_t s = 1;
        int small = 0;
        for (a = 0; a < d; ++a) small |= L[l - 1].nn[a] < 6;
        if (small) break;
        for (a = 2; a >= 0; --a) {
            L[l].nn[a] = a < d ? L[l - 1].nn[a] / 2 + 1 : 1;
            L[l].stride[a] = s;
            s *= (size_t)L[l].nn[a];
        }
        L[l].nodes = s;
        L[l].dof = (long *)pn__mpm_alloc(&w->desc, s, sizeof(long), &fail);
        L[l].mark = (unsigned char *)pn__mpm_alloc(&w->desc, s, 1, &fail);
        if (fail) break;
        memset(L[l].dof, 0xff, sizeof(long) * s); /* -1 */
    }
    w->s.mg_dense = (pn_real *)pn__mpm_alloc(&w->desc, (size_t)PN__MPM_MG_DENSE * PN__MPM_MG_DENSE, sizeof(pn_real),
                                           &fail);
    if (fail) return PN_ERROR_OUT_OF_MEMORY; /* pn_mpm_destroy frees what was made */
    w->s.mg_max = l;
    return PN_OK;
}

/* neighbour rows of every row of level l (-1: inactive or off the grid) and the colour lists */
static void pn__mpm_mg_rows(pn_mpm_world *w, int l) {
    pn__mpm_level *L = &w->s.mg[l];
    int d = w->dim, nb = PN__MPM_NB(d), nc = d == 2 ? 9 : 27, c;
    size_t k, count[28];
    const size_t *node = l ? L->node : w->s.act;
    const long *dof = l ? L->dof : w->s.dof;
    long lk;
    PN__OMP_FOR
    for (lk = 0; lk < (long)L->n; ++lk) {
        int idx[3], t, a;
        long *row = L->nbr + (size_t)lk * (size_t)nb;
        pn__mpm_mg_idx(L, d, node[lk], idx);
        for (t = 0; t < nb; ++t) {
            int r = t, ok = 1;
            size_t flat = node[lk];
            for (a = d - 1; a >= 0; --a, r /= 5) {
                int o = r % 5 - 2;
                ok &= idx[a] + o >= 0 && idx[a] + o < L->nn[a];
                flat += (size_t)((long)o * (long)L->stride[a]);
            }
            row[t] = ok ? dof[flat] : -1;
        }
    }
    memset(count, 0, sizeof count);
    for (k = 0; k < L->n; ++k) { /* colour = node index mod 3 per axis */
        int idx[3], a;
        pn__mpm_mg_idx(L, d, node[k], idx);
        for (c = 0, a = 0; a < d; ++a) c = c * 3 + idx[a] % 3;
        L->crow[L->cap + k] = (size_t)c;
        count[c + 1]++;
    }
    for (c = 0; c < nc; ++c) count[c + 1] += count[c];
    memcpy(L->cstart, count, sizeof(size_t) * (size_t)(nc + 1));
    for (k = 0; k < L->n; ++k) L->crow[count[L->crow[L->cap + k]]++] = k; /* ascending in a colour */
}

/* the contact filter of node k as a matrix (column i = the filtered e_i); 0 where nothing
   is held (S = I) */
static int pn__mpm_filter_matrix(const pn_mpm_world *w, size_t k, pn_real *S) {
    int d = w->dim, i, j;
    if (!(w->s.chold[k] & PN__MPM_STICK) && !(w->s.chold[k] & ((1 << w->s.cn[k]) - 1))) return 0;
    for (j = 0; j < d; ++j) {
        pn_real e[3] = {0, 0, 0};
        e[j] = 1;
        pn__mpm_filter(w, k, e);
        for (i = 0; i < d; ++i) S[i * d + j] = e[i];
    }
    return 1;
}

/* the pseudo-inverse of a row's diagonal block (symmetric positive semi-definite: held
   directions, and coarse rows all of whose children hold a direction, have none of it) */
static void pn__mpm_mg_dinv(int d, const pn_real *D, pn_real *out) {
    pn_real Q[9], ev[3], top;
    int i, j, m;
    memset(out, 0, sizeof(pn_real) * (size_t)(d * d));
    if (pn_sym_eigen(d, D, Q, ev) != PN_OK) return;
    top = ev[d - 1];
    for (m = 0; m < d; ++m) {
        if (!(ev[m] > (pn_real)1e-12 * top)) continue;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) out[i * d + j] += Q[i * d + m] * Q[j * d + m] / ev[m];
    }
}

/* Row k of level 0, assembled in pn_real (A), through the contact filter: stored in float
   (out), and its diagonal block's pseudo-inverse (Dinv) */
static void pn__mpm_mg_fine_store(pn_mpm_world *w, size_t k, pn_real *A, float *out, pn_real *Dinv) {
    const pn__mpm_level *L = w->s.mg;
    int d = w->dim, dd = d * d, nb = PN__MPM_NB(d), ctr = nb / 2, hk, i, j, m, t;
    pn_real Sk[9], Sl[9], T[9];
    const long *nbr = L->nbr + k * (size_t)nb;
    hk = pn__mpm_filter_matrix(w, k, Sk);
    for (t = 0; t < nb; ++t) {
        pn_real *B = A + t * dd;
        int hl = nbr[t] >= 0 && pn__mpm_filter_matrix(w, (size_t)nbr[t], Sl);
        if (hl) { /* B S_l */
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j)
                    for (T[i * d + j] = 0, m = 0; m < d; ++m) T[i * d + j] += B[i * d + m] * Sl[m * d + j];
            memcpy(B, T, sizeof(pn_real) * (size_t)dd);
        }
        if (hk) { /* S_k^T B */
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j)
                    for (T[i * d + j] = 0, m = 0; m < d; ++m) T[i * d + j] += Sk[m * d + i] * B[m * d + j];
            memcpy(B, T, sizeof(pn_real) * (size_t)dd);
        }
    }
    pn__mpm_mg_dinv(d, A + ctr * dd, Dinv);
    for (i = 0; i < nb * dd; ++i) out[i] = (float)A[i];
}

/* Level 0 from the particles' PSD dP/dF (pH): the block of nodes k, l is
   sum_p V_p dt^2 sum_ce H_p[(a c),(b e)] q_pk,c q_pl,e (q = F^nT g as in >>implicit), plus
   m_k I on the diagonal; gathered per row over the row's incidences (their fixed order). */
static void pn__mpm_mg_fine(pn_mpm_world *w, pn_real dt) {
    pn__mpm_level *L = w->s.mg;
    int d = w->dim, dd = d * d, ns = w->s.ns, nb = PN__MPM_NB(d), ctr = nb / 2, s, s2;
    int up[27][27], nup[27]; /* per slot s: the slots t whose neighbour index from s is >= the centre's */
    long lk;
    for (s = 0; s < ns; ++s) /* the neighbour index o of slot s2 seen from slot s: the pairs with o >= ctr */
        for (nup[s] = 0, s2 = 0; s2 < ns; ++s2) {
            int o = 0, a;
            for (a = 0; a < d; ++a) o = o * 5 + w->s.slot[s2][a] - w->s.slot[s][a] + 2;
            if (o >= ctr) up[s][nup[s]++] = s2 * 128 + o; /* slot and neighbour index */
        }
    L->n = w->s.n_act;
    pn__mpm_mg_rows(w, 0);
    /* Blocks are symmetric, A_lk = A_kl^T (each particle's H is): a row assembles its
       blocks from the centre on (t >= ctr) and takes the others from its neighbours'. The
       contact filter keeps the symmetry: (S_k^T A_kl S_l)^T = S_l^T A_lk S_k. */
    PN__OMP_FOR
    for (lk = 0; lk < (long)L->n; ++lk) {
        size_t k = (size_t)lk, e;
        pn_real A[125 * 9]; /* the row in pn_real, then filtered, then stored */
        int i, t;
        memset(A, 0, sizeof(pn_real) * (size_t)(nb * dd));
        for (e = w->s.inc_start[k]; e < w->s.inc_start[k + 1]; ++e) {
            size_t ps = w->s.inc[e], j = ps / (size_t)ns, p = w->s.order[j];
            int sk = (int)(ps - j * (size_t)ns), n2 = nup[sk];
            const pn_real *H = w->s.pH + p * (size_t)(dd * dd), *qs = w->s.pq + ps * (size_t)d;
            const pn_real *q = w->s.pq + j * (size_t)(ns * d);
            const int *pr = up[sk];
            pn_real c = w->vol0[p] * dt * dt, u[27];
            if (d == 2) { /* u_abe = c sum_c H[(a c),(b e)] qs_c; block_ab += sum_e u_abe q_e */
                for (i = 0; i < 8; ++i) {
                    int ab = i >> 1, be = (ab & 1) * 2 + (i & 1), row = (ab >> 1) * 2;
                    u[i] = c * (H[row * 4 + be] * qs[0] + H[(row + 1) * 4 + be] * qs[1]);
                }
                for (t = 0; t < n2; ++t) {
                    const pn_real *qt = q + (pr[t] >> 7) * 2;
                    pn_real *B = A + (pr[t] & 127) * 4;
                    B[0] += u[0] * qt[0] + u[1] * qt[1];
                    B[1] += u[2] * qt[0] + u[3] * qt[1];
                    B[2] += u[4] * qt[0] + u[5] * qt[1];
                    B[3] += u[6] * qt[0] + u[7] * qt[1];
                }
            } else {
                for (i = 0; i < 27; ++i) { /* u[9 e + ab], ab = 3 a + b */
                    int ab = i % 9, be = (ab % 3) * 3 + i / 9, row = (ab / 3) * 3;
                    u[i] = c * (H[row * 9 + be] * qs[0] + H[(row + 1) * 9 + be] * qs[1] + H[(row + 2) * 9 + be] * qs[2]);
                }
                for (t = 0; t < n2; ++t) {
                    const pn_real *qt = q + (pr[t] >> 7) * 3;
                    pn_real *B = A + (pr[t] & 127) * 9, q0 = qt[0], q1 = qt[1], q2 = qt[2];
                    for (i = 0; i < 8; ++i) B[i] += u[i] * q0 + u[9 + i] * q1 + u[18 + i] * q2; /* 8 + 1: vectorizes at -O2 */
                    B[8] += u[8] * q0 + u[17] * q1 + u[26] * q2;
                }
            }
        }
        for (i = 0; i < d; ++i) A[ctr * dd + i * d + i] += w->s.grid_m[k];
        pn__mpm_mg_fine_store(w, k, A, L->A + k * (size_t)(nb * dd), L->Dinv + k * (size_t)dd);
    }
    PN__OMP_FOR
    for (lk = 0; lk < (long)L->n; ++lk) { /* the blocks before the centre: A_kt = A_lt'^T, l = nbr[t] */
        float *Ak = L->A + (size_t)lk * (size_t)(nb * dd);
        const long *nbr = L->nbr + (size_t)lk * (size_t)nb;
        int t, a, b;
        for (t = 0; t < ctr; ++t) {
            const float *Bl = nbr[t] < 0 ? NULL : L->A + ((size_t)nbr[t] * (size_t)nb + (size_t)(nb - 1 - t)) * (size_t)dd;
            for (a = 0; a < d; ++a)
                for (b = 0; b < d; ++b) Ak[t * dd + a * d + b] = Bl ? Bl[b * d + a] : 0;
        }
    }
}

/* the coarse rows a fine node at index i (per axis) feeds: i even, I = i / 2 (weight 1);
   odd, (i - 1) / 2 and (i + 1) / 2 (1/2 each). Combination m (bit a: the upper one on axis
   a) of fine idx gives I and its weight; 0 if m asks for an upper parent on an even axis. */
static pn_real pn__mpm_mg_parent(int d, const int *idx, int m, int *I) {
    int a;
    pn_real wt = 1;
    for (a = 0; a < d; ++a) {
        int up = m >> a & 1;
        if (!(idx[a] & 1)) {
            if (up) return 0;
            I[a] = idx[a] / 2;
        } else {
            I[a] = (idx[a] - 1) / 2 + up;
            wt *= (pn_real)0.5;
        }
    }
    return wt;
}

/* level l + 1 from level l: its rows (the parents of level l's rows) and P^T A_l P */
static pn_result pn__mpm_mg_coarsen(pn_mpm_world *w, int l) {
    pn__mpm_level *F = &w->s.mg[l], *C = &w->s.mg[l + 1];
    int d = w->dim, dd = d * d, nb = PN__MPM_NB(d), ctr = nb / 2;
    const size_t *fnode = l ? F->node : w->s.act;
    const long *fdof = l ? F->dof : w->s.dof;
    size_t k, n = 0, flat;
    long lk;
    int toff[125][3], tt, ax;
    pn_result r;
    for (k = 0; k < C->n; ++k) C->dof[C->node[k]] = -1;
    C->n = 0;
    for (k = 0; k < F->n; ++k) {
        int idx[3], I[3] = {0, 0, 0}, m, a;
        pn__mpm_mg_idx(F, d, fnode[k], idx);
        for (m = 0; m < 1 << d; ++m)
            if (pn__mpm_mg_parent(d, idx, m, I) > 0) {
                for (flat = 0, a = 0; a < d; ++a) flat += (size_t)I[a] * C->stride[a];
                C->mark[flat] = 1;
            }
    }
    for (flat = 0; flat < C->nodes; ++flat) n += C->mark[flat];
    r = pn__mpm_mg_reserve(w, C, n, 1);
    if (r != PN_OK) {
        memset(C->mark, 0, C->nodes);
        return r;
    }
    for (flat = 0; flat < C->nodes; ++flat)
        if (C->mark[flat]) {
            C->mark[flat] = 0;
            C->dof[flat] = (long)C->n;
            C->node[C->n++] = flat;
        }
    pn__mpm_mg_rows(w, l + 1);
    /* Per axis, a child at 2I + a and its neighbour at offset o sit at s = a + o in -3..3
       from 2I: s even has one parent, I + s/2 (weight 1); s odd two, I + (s -+ 1)/2 (1/2
       each). The parents of a neighbour are then products of at most two per axis. */
    for (tt = 0; tt < nb; ++tt) {
        int q = tt;
        for (ax = d - 1; ax >= 0; --ax, q /= 5) toff[tt][ax] = q % 5 - 2;
    }
    PN__OMP_FOR
    for (lk = 0; lk < (long)C->n; ++lk) { /* row I gathers w_iI A_ij w_jJ over its children i */
        int I[3], c, nc = d == 2 ? 9 : 27, a, t;
        size_t fi;
        pn_real A[125 * 9]; /* the row in pn_real, then stored */
        float *out = C->A + (size_t)lk * (size_t)(nb * dd);
        memset(A, 0, sizeof(pn_real) * (size_t)(nb * dd));
        pn__mpm_mg_idx(C, d, C->node[lk], I);
        for (c = 0; c < nc; ++c) {
            int i[3], ao[3] = {0, 0, 0}, ok = 1, r5 = c;
            long ri;
            pn_real wi = 1;
            const long *nbr;
            const float *Ai;
            for (fi = 0, a = d - 1; a >= 0; --a, r5 /= 3) {
                ao[a] = r5 % 3 - 1;
                i[a] = 2 * I[a] + ao[a];
                ok &= i[a] >= 0 && i[a] < F->nn[a];
                if (ao[a]) wi *= (pn_real)0.5;
                fi += (size_t)((long)i[a] * (long)F->stride[a]);
            }
            if (!ok || (ri = fdof[fi]) < 0) continue;
            nbr = F->nbr + (size_t)ri * (size_t)nb;
            Ai = F->A + (size_t)ri * (size_t)(nb * dd);
            for (t = 0; t < nb; ++t) {
                const float *B = Ai + t * dd;
                int sx = ao[0] + toff[t][0], sy = ao[1] + toff[t][1], sz = d == 3 ? ao[2] + toff[t][2] : 0;
                int nx = ((sx + 4) & 1) + 1, ny = ((sy + 4) & 1) + 1, nz = ((sz + 4) & 1) + 1, ex, ey, ez, e;
                pn_real wt = wi * (nx == 2 ? (pn_real)0.5 : 1) * (ny == 2 ? (pn_real)0.5 : 1) *
                             (nz == 2 ? (pn_real)0.5 : 1);
                if (nbr[t] < 0) continue;
                for (ez = 0; ez < nz; ++ez)
                    for (ey = 0; ey < ny; ++ey)
                        for (ex = 0; ex < nx; ++ex) { /* parent I + (s - (n - 1) + 2 e) / 2 per axis */
                            int tJ = ((sx - nx + 1) / 2 + ex + 2) * 5 + (sy - ny + 1) / 2 + ey + 2;
                            pn_real *Cb;
                            if (d == 3) tJ = tJ * 5 + (sz - nz + 1) / 2 + ez + 2;
                            Cb = A + tJ * dd;
                            for (e = 0; e < dd; ++e) Cb[e] += wt * B[e];
                        }
            }
        }
        pn__mpm_mg_dinv(d, A + ctr * dd, C->Dinv + (size_t)lk * (size_t)dd);
        for (t = 0; t < nb * dd; ++t) out[t] = (float)A[t];
    }
    return PN_OK;
}

/* acc = sum_t A_kt x_t over row k's neighbours, less the diagonal's with `skip`; spelled out
   per dimension for the compiler. A missing neighbour's block is zero: it reads x_k instead
   (no branch). */
static void pn__mpm_mg_row(int d, int nb, size_t k, const float *A, const long *nbr, const pn_real *x, int skip,
                           pn_real *acc) {
    int t;
    if (d == 2) {
        pn_real a0 = 0, a1 = 0;
        const float *D = A + (nb / 2) * 4;
        const pn_real *xk = x + k * 2;
        for (t = 0; t < nb; ++t, A += 4) {
            const pn_real *xt = x + (size_t)(nbr[t] < 0 ? (long)k : nbr[t]) * 2;
            a0 += A[0] * xt[0] + A[1] * xt[1];
            a1 += A[2] * xt[0] + A[3] * xt[1];
        }
        if (skip) a0 -= D[0] * xk[0] + D[1] * xk[1], a1 -= D[2] * xk[0] + D[3] * xk[1];
        acc[0] = a0, acc[1] = a1;
    } else {
        pn_real a0 = 0, a1 = 0, a2 = 0;
        const float *D = A + (nb / 2) * 9;
        const pn_real *xk = x + k * 3;
        for (t = 0; t < nb; ++t, A += 9) {
            const pn_real *xt = x + (size_t)(nbr[t] < 0 ? (long)k : nbr[t]) * 3;
            a0 += A[0] * xt[0] + A[1] * xt[1] + A[2] * xt[2];
            a1 += A[3] * xt[0] + A[4] * xt[1] + A[5] * xt[2];
            a2 += A[6] * xt[0] + A[7] * xt[1] + A[8] * xt[2];
        }
        if (skip) {
            a0 -= D[0] * xk[0] + D[1] * xk[1] + D[2] * xk[2];
            a1 -= D[3] * xk[0] + D[4] * xk[1] + D[5] * xk[2];
            a2 -= D[6] * xk[0] + D[7] * xk[1] + D[8] * xk[2];
        }
        acc[0] = a0, acc[1] = a1, acc[2] = a2;
    }
}

/* out = A_l x (b NULL) or b - A_l x */
static void pn__mpm_mg_apply(pn_mpm_world *w, int l, const pn_real *x, const pn_real *b, pn_real *out) {
    const pn__mpm_level *L = &w->s.mg[l];
    int d = w->dim, dd = d * d, nb = PN__MPM_NB(d);
    long lk;
    PN__OMP_FOR
    for (lk = 0; lk < (long)L->n; ++lk) {
        size_t k = (size_t)lk;
        pn_real acc[3];
        int i;
        pn__mpm_mg_row(d, nb, k, L->A + k * (size_t)(nb * dd), L->nbr + k * (size_t)nb, x, 0, acc);
        for (i = 0; i < d; ++i) out[k * (size_t)d + (size_t)i] = b ? b[k * (size_t)d + (size_t)i] - acc[i] : acc[i];
    }
}

/* one block Gauss-Seidel sweep on A_l x = b, colours in order (or reversed) */
static void pn__mpm_mg_smooth(pn_mpm_world *w, int l, const pn_real *b, pn_real *x, int backward) {
    const pn__mpm_level *L = &w->s.mg[l];
    int d = w->dim, dd = d * d, nb = PN__MPM_NB(d), nc = d == 2 ? 9 : 27, ci;
    for (ci = 0; ci < nc; ++ci) {
        int c = backward ? nc - 1 - ci : ci;
        long lr;
        PN__OMP_FOR
        for (lr = (long)L->cstart[c]; lr < (long)L->cstart[c + 1]; ++lr) {
            size_t k = L->crow[lr];
            pn_real acc[3], rk[3];
            const pn_real *Di = L->Dinv + k * (size_t)dd;
            int i, j;
            pn__mpm_mg_row(d, nb, k, L->A + k * (size_t)(nb * dd), L->nbr + k * (size_t)nb, x, 1, acc);
            for (i = 0; i < d; ++i) rk[i] = b[k * (size_t)d + (size_t)i] - acc[i];
            for (i = 0; i < d; ++i) {
                pn_real s = 0;
                for (j = 0; j < d; ++j) s += Di[i * d + j] * rk[j];
                x[k * (size_t)d + (size_t)i] = s;
            }
        }
    }
}

/* coarse b_I = sum over children i of w_iI r_i (level l's r to level l + 1's b) */
static void pn__mpm_mg_restrict(pn_mpm_world *w, int l) {
    const pn__mpm_level *F = &w->s.mg[l];
    pn__mpm_level *C = &w->s.mg[l + 1];
    int d = w->dim, nc = d == 2 ? 9 : 27;
    const long *fdof = l ? F->dof : w->s.dof;
    long lk;
    PN__OMP_FOR
    for (lk = 0; lk < (long)C->n; ++lk) {
        int I[3], c, a, i;
        pn_real acc[3] = {0, 0, 0};
        pn__mpm_mg_idx(C, d, C->node[lk], I);
        for (c = 0; c < nc; ++c) {
            int r3 = c, ok = 1;
            size_t flat = 0;
            long ri;
            pn_real wi = 1;
            for (a = d - 1; a >= 0; --a, r3 /= 3) {
                int o = r3 % 3 - 1, ia = 2 * I[a] + o;
                ok &= ia >= 0 && ia < F->nn[a];
                if (o) wi *= (pn_real)0.5;
                flat += (size_t)((long)ia * (long)F->stride[a]);
            }
            if (!ok || (ri = fdof[flat]) < 0) continue;
            for (i = 0; i < d; ++i) acc[i] += wi * F->r[(size_t)ri * (size_t)d + (size_t)i];
        }
        for (i = 0; i < d; ++i) C->b[(size_t)lk * (size_t)d + (size_t)i] = acc[i];
    }
}

/* x_i += sum over parents I of w_iI x_I (level l + 1's x into level l's x) */
static void pn__mpm_mg_prolong(pn_mpm_world *w, int l, pn_real *x) {
    const pn__mpm_level *F = &w->s.mg[l], *C = &w->s.mg[l + 1];
    int d = w->dim;
    const size_t *fnode = l ? F->node : w->s.act;
    long lk;
    PN__OMP_FOR
    for (lk = 0; lk < (long)F->n; ++lk) {
        int idx[3], I[3] = {0, 0, 0}, m, a, i;
        pn__mpm_mg_idx(F, d, fnode[lk], idx);
        for (m = 0; m < 1 << d; ++m) {
            pn_real wt = pn__mpm_mg_parent(d, idx, m, I);
            size_t flat = 0;
            long rI;
            if (wt == 0) continue;
            for (a = 0; a < d; ++a) flat += (size_t)I[a] * C->stride[a];
            rI = C->dof[flat];
            for (i = 0; i < d; ++i) x[(size_t)lk * (size_t)d + (size_t)i] += wt * C->x[(size_t)rI * (size_t)d + (size_t)i];
        }
    }
}

/* the coarsest level exactly (dense Cholesky, factored with the hierarchy) when it is small */
static void pn__mpm_mg_dense_factor(pn_mpm_world *w) {
    const pn__mpm_level *L = &w->s.mg[w->s.mg_levels - 1];
    int d = w->dim, dd = d * d, nb = PN__MPM_NB(d), t, a, b;
    size_t n = L->n * (size_t)d, k;
    pn_real *M = w->s.mg_dense;
    w->s.mg_dense_n = 0;
    if (n > PN__MPM_MG_DENSE) return;
    memset(M, 0, sizeof(pn_real) * n * n);
    for (k = 0; k < L->n; ++k)
        for (t = 0; t < nb; ++t) {
            long c = L->nbr[k * (size_t)nb + (size_t)t];
            if (c < 0) continue;
            for (a = 0; a < d; ++a)
                for (b = 0; b < d; ++b)
                    M[(k * (size_t)d + (size_t)a) * n + (size_t)c * (size_t)d + (size_t)b] =
                        L->A[(k * (size_t)nb + (size_t)t) * (size_t)dd + (size_t)(a * d + b)];
        }
    /* M = L L^T; a direction without stiffness (all held) gets x_j = b_j; not semi-definite:
       smooth instead (mg_dense_n stays 0) */
    if (pn__cholesky(M, n, (pn_real)1e-10, 0, 1) < n) return;
    w->s.mg_dense_n = n;
}

static void pn__mpm_mg_coarsest(pn_mpm_world *w, int l, const pn_real *b, pn_real *x) {
    size_t n = w->s.mg_dense_n;
    const pn_real *M = w->s.mg_dense;
    if (!n) { /* two symmetric sweeps */
        memset(x, 0, sizeof(pn_real) * w->s.mg[l].n * (size_t)w->dim);
        pn__mpm_mg_smooth(w, l, b, x, 0);
        pn__mpm_mg_smooth(w, l, b, x, 1);
        pn__mpm_mg_smooth(w, l, b, x, 0);
        pn__mpm_mg_smooth(w, l, b, x, 1);
        return;
    }
    pn__cholesky_solve(M, n, b, x);
}

/* x = B b, B one V(1,1)-cycle from level l down */
static void pn__mpm_mg_vcycle(pn_mpm_world *w, int l, const pn_real *b, pn_real *x) {
    pn__mpm_level *L = &w->s.mg[l], *C = &w->s.mg[l + 1];
    if (l == w->s.mg_levels - 1) {
        pn__mpm_mg_coarsest(w, l, b, x);
        return;
    }
    int s;
    memset(x, 0, sizeof(pn_real) * L->n * (size_t)w->dim);
    for (s = 0; s < PN__MPM_MG_SWEEPS; ++s) pn__mpm_mg_smooth(w, l, b, x, 0);
    pn__mpm_mg_apply(w, l, x, b, L->r);
    pn__mpm_mg_restrict(w, l);
    pn__mpm_mg_vcycle(w, l + 1, C->b, C->x);
    pn__mpm_mg_prolong(w, l, x);
    for (s = 0; s < PN__MPM_MG_SWEEPS; ++s) pn__mpm_mg_smooth(w, l, b, x, 1);
}

/* The hierarchy at the current Hessian, or (fresh == 0) kept from an earlier Newton
   iteration of the solve: a lagged preconditioner, still SPD, and CG multiplies by the
   current Hessian over the particles. */
static pn_result pn__mpm_mg_build(pn_mpm_world *w, pn_real dt, int fresh, int max_levels) {
    int d = w->dim;
    pn_result r = pn__mpm_mg_init(w);
    w->s.mg_current = 0;
    if (!fresh && w->s.mg_levels > 0) return PN_OK;
    if (r == PN_OK) r = pn__mpm_mg_reserve(w, &w->s.mg[0], w->s.n_act, 0);
    if (r != PN_OK) return r;
    pn__mpm_mg_fine(w, dt);
    w->s.mg_current = 1;
    w->s.mg_levels = 1;
    while (w->s.mg_levels < PN__MIN(max_levels, w->s.mg_max) &&
           w->s.mg[w->s.mg_levels - 1].n * (size_t)d > PN__MPM_MG_DENSE) {
        r = pn__mpm_mg_coarsen(w, w->s.mg_levels - 1);
        if (r != PN_OK) {
            w->s.mg_levels = 0;
            return r;
        }
        w->s.mg_levels++;
    }
    pn__mpm_mg_dense_factor(w);
    return PN_OK;
}

/* ======================================================================================
   >>stress: the stress formulation (PN_MPM_FORMULATION_STRESS). Unknowns: the grid
   velocities v and each particle's Kirchhoff stress tau_p, with
       m_i v_i = m_i v*_i - dt sum_p V_p tau_p g_ip + r_i            (momentum; r: contact)
       tau_p = Z(tau^_p + dt C : D_p(v)),  D_p = sym(sum_i v_i g_ip^T) (the constitutive law)
   tau^ the stress of F^n, C the Hencky elasticity (2 mu on the deviator, kappa = lambda +
   2 mu / d on the trace), Z the Drucker-Prager return mapping of pn_return_map written on
   stresses: the trace kept, the deviator s scaled back to the cone |s| <= -alpha d (m - m_c)
   (m = tr tau / d, m_c = d kappa c the cohesion's apex), the apex where m >= m_c. Power
   balance holds exactly (the force of tau is the adjoint of D), elasticity is a compliance,
   and plastic flow is exact within the step: no viscosity E dt, however stiff the material
   (Daviet and Bertails-Descoubes 2016 pose granular MPM this way).
   Projected Gauss-Seidel: particles in sorted order, each solving its own constitutive law
   with the rest frozen, then each contact node its velocity projection (the explicit rule,
   which for one node with mass m is its exact local solve). A particle's stress moves its
   own D by -dt V_p sym(dtau G_p), G_p = sum_i g_ip g_ip^T / m_i; with G_p replaced by
   gamma I, gamma >= its largest eigenvalue, the local law has the closed form below and the
   update never overshoots its exact local solve. The first iterate is tau = tau^: the
   explicit step's velocities, which is where a quasi-static pile already is. Afterwards the
   grid-to-particle transfer of >>transfer makes the state, with F = exp(dt sum v g^T) F^n
   (the rate law's own integral; the energy formulation's I + dt L would add the step's
   rotations as stretch), then pn_return_map. The sweeps go by colour
   (pn__mpm_stress_groups), so threads share them and any thread count gives the same bits.
   ====================================================================================== */

static pn_result pn__return_tau(const pn_material *m, int d, const pn_real *F, pn_real h, pn_real *Z,
                                pn_real *h_new, pn_real *tau, int *plastic); /* >>explicit */

/* group g's material in the stress formulation: 0 if it has none */
static int pn__mpm_stress_ok(const pn_material *m) {
    return (m->elastic == PN_ELASTIC_STVK_HENCKY &&
            (m->plastic == PN_PLASTIC_NONE || m->plastic == PN_PLASTIC_DRUCKER_PRAGER)) ||
           (m->elastic == PN_ELASTIC_NEO_HOOKEAN_SNOW &&
            (m->plastic == PN_PLASTIC_NONE || m->plastic == PN_PLASTIC_CAM_CLAY));
}

/* The local law of one stress unknown (a particle, or a cell): tau from its velocity
   gradient L at the current velocities, its stress cur, its start stress hat, hardening
   state h and compliance c = dt V gamma; returns the new stress in tau.
   The rate law is tau = hat + dt (2 mu dev D + kappa' tr D I), D = sym L. StVK-Hencky:
   kappa' = kappa, exact in the log strain. Neo-Hookean snow (tau = kappa/2 (J^2 - 1) I +
   mu J^(-2/d) dev b): its tangent at the start, kappa' = kappa J^2 = kappa + 2 tr(hat) / d
   on the trace, 2 mu on the deviator (to first order in the elastic shear strain); the
   transfer back makes the state from F itself, so this only steers the velocities.
   The return mappings written on stresses, both of which keep the trace in shear and scale
   the deviator s back radially, |s| <= R(m) (m = tr tau / d):
   - Drucker-Prager: R = -alpha d (m - m_c), m_c = d kappa c the cohesion's apex; m >= m_c:
     the apex;
   - Cam-Clay (pn_return_map's, Gaume et al. 2018 with the hardening frozen at h within the
     step): with p = -m, (1 + 2 beta) q^2 + M^2 (p + beta p0)(p - p0) <= 0, q^2 = (6 - d)/2
     |s|^2; outside [-beta p0, p0] in p, the tip (s = 0, p at the bound).
   Both laws are radial in s, so the particle's own share of D, moved to the left, only
   shrinks the trial deviator (by 1 + bs) and mean (by 1 + bm): the closed form below. */
static void pn__mpm_stress_local(const pn_material *m, int d, const pn_real *hat, const pn_real *cur, pn_real h,
                                 const pn_real *L, pn_real c, pn_real dt, pn_real *tau, pn_real *H) {
    int dd = d * d, i, k;
    pn_real dr = (pn_real)d, kappa = m->lambda + 2 * m->mu / dr, trL = 0, mcur = 0, mhat = 0;
    pn_real mc = 0, am, bm, bs, as[9], an = 0, mnew, sc, mu2 = 2 * m->mu * dt, mean, rad2 = -1;
    int dp = m->plastic == PN_PLASTIC_DRUCKER_PRAGER, cam = m->plastic == PN_PLASTIC_CAM_CLAY;
    for (i = 0; i < d; ++i) {
        trL += L[i * d + i];
        mcur += cur[i * d + i];
        mhat += hat[i * d + i];
    }
    mcur /= dr, mhat /= dr;
    if (m->elastic == PN_ELASTIC_NEO_HOOKEAN_SNOW) kappa = PN__MAX(kappa + 2 * mhat, (pn_real)1e-3 * kappa);
    if (dp) mc = dr * kappa * m->cohesion_strain;
    /* trial with this particle's own share of D moved to the left: deviator as - bs s,
       shifted mean am - bm (m - mc) */
    bs = mu2 * c;
    bm = kappa * dt * c * dr;
    am = mhat - mc + kappa * dt * trL + bm * (mcur - mc);
    if (dp && m->volume_correction) am += kappa * h;
    for (i = 0; i < d; ++i)
        for (k = 0; k < d; ++k) as[i * d + k] = hat[i * d + k] + mu2 * (L[i * d + k] + L[k * d + i]) / 2 + bs * cur[i * d + k];
    mean = mhat + mu2 * trL / dr + bs * mcur; /* as -= its mean: the deviator */
    for (i = 0; i < d; ++i) as[i * d + i] -= mean;
    for (i = 0; i < dd; ++i) an += as[i] * as[i];
    mnew = am / (1 + bm);
    if (dp && am >= 0) mnew = 0, rad2 = 0; /* expansion: the apex */
    if (dp && am < 0) rad2 = pn__dp_alpha(m->sin_phi, d) * dr * mnew, rad2 *= rad2;
    if (cam) { /* p0 and M as pn_return_map's (pn__camclay_eval) */
        pn_real p0 = (m->lambda + 2 * m->mu / dr) * ((pn_real)1e-5 + PN__SINH(m->xi * PN__MAX(-h, 0)));
        pn_real M = pn__dp_alpha(m->sin_phi, 3) * dr / PN__SQRT(2 / (6 - dr));
        pn_real beta = m->beta, p = -mnew;
        if (p >= p0 || p <= -beta * p0) mnew = p >= p0 ? -p0 : beta * p0, rad2 = 0; /* the tips */
        else rad2 = -M * M * (p + beta * p0) * (p - p0) / ((1 + 2 * beta) * (6 - dr) / 2);
    }
    sc = 1 / (1 + bs);
    if (rad2 >= 0 && an * sc * sc > rad2) sc = PN__SQRT(rad2 / an); /* an > 0 here */
    for (i = 0; i < dd; ++i) tau[i] = sc * as[i];
    for (i = 0; i < d; ++i) tau[i * d + i] += mnew + mc;
    if (H) { /* (c = 0, elastic material: >>stress, the coarse correction) the trial and its
                tangent d tau / (dt dL): 2 mu on the deviator (made symmetric), kappa on the mean */
        int a, b, cc, e;
        for (i = 0; i < dd; ++i) tau[i] = as[i];
        for (i = 0; i < d; ++i) tau[i * d + i] += am / (1 + bm) + mc;
        for (a = 0; a < d; ++a)
            for (cc = 0; cc < d; ++cc)
                for (b = 0; b < d; ++b)
                    for (e = 0; e < d; ++e)
                        H[(a * d + cc) * dd + b * d + e] = m->mu * ((a == b && cc == e) + (a == e && cc == b)) +
                                                           (a == cc && b == e) * (kappa - 2 * m->mu / dr);
    }
}

/* v_k of every stencil node (dof) += -sV / m_k dtau g_k: a particle's force (g its weights, sV =
   dt V) or a cell's (g = sum V g over its particles, sV = dt) */
static void pn__mpm_stress_apply(pn_mpm_world *w, const pn_real *g, const long *dof, const pn_real *dtau, pn_real sV,
                                 pn_real *v) {
    int s;
    if (w->dim == 2) { /* spelled out: see pn__mpm_push2 */
        for (s = 0; s < 9; ++s, g += 2) {
            pn_real f = w->s.diag[dof[s]] * sV, *vk = v + (size_t)dof[s] * 2;
            vk[0] -= f * (dtau[0] * g[0] + dtau[1] * g[1]);
            vk[1] -= f * (dtau[2] * g[0] + dtau[3] * g[1]);
        }
        return;
    }
    for (s = 0; s < 27; ++s, g += 3) {
        pn_real f = w->s.diag[dof[s]] * sV, *vk = v + (size_t)dof[s] * 3;
        vk[0] -= f * (dtau[0] * g[0] + dtau[1] * g[1] + dtau[2] * g[2]);
        vk[1] -= f * (dtau[3] * g[0] + dtau[4] * g[1] + dtau[5] * g[2]);
        vk[2] -= f * (dtau[6] * g[0] + dtau[7] * g[1] + dtau[8] * g[2]);
    }
}

/* the contact nodes' Gauss-Seidel: each node's velocity without its contact impulse r,
   projected by the explicit rule, and r again */
static void pn__mpm_stress_contact(pn_mpm_world *w, pn_real *v, pn_real *r) {
    int d = w->dim, i;
    size_t k;
    for (k = 0; k < w->s.n_act; ++k) {
        pn_real *vk = v + k * (size_t)d, *rk = r + k * (size_t)d, m = w->s.grid_m[k], fr[3];
        if (!w->s.cn[k]) continue;
        for (i = 0; i < d; ++i) fr[i] = vk[i] - rk[i] * w->s.diag[k];
        for (i = 0; i < d; ++i) vk[i] = fr[i];
        pn__mpm_project(d, w->s.cn[k], w->s.ckind[k], w->s.cdir + k * 9, w->s.cvel + k * 3, w->s.cmu[k], vk);
        for (i = 0; i < d; ++i) rk[i] = m * (vk[i] - fr[i]);
    }
}

/* The sweep's order: the particles grouped by stencil base node (they are sorted by it), the
   groups by colour (base node index mod 3 per axis, 3^dim colours). Two groups of one colour
   are at least three nodes apart on some axis, so their 3-wide stencils share no node and a
   colour's groups can run on any threads at once; within a group the particles go in sorted
   order, so every thread count gives the same sweep. Group q of colour c: particles
   grp[2q] .. grp[2q + 1] - 1 (sorted indices), q from cstart[c] to cstart[c + 1] - 1, grp = sgrp
   (the node incidences, inc, stay for the coarse correction's assembly). */
static void pn__mpm_stress_groups(pn_mpm_world *w, size_t *cstart) {
    size_t j, np = w->s.start[w->s.nodes], count[28] = {0}, ng = 0, *grp = w->s.sgrp, *tmp;
    int c, idx[3], i, d = w->dim, nc = d == 2 ? 9 : 27;
    tmp = grp + 2 * np; /* unsorted groups: start, end, colour (sgrp has 5 per particle) */
    for (j = 0; j < np;) {
        size_t b = w->s.pbase[w->s.order[j]], e = j + 1;
        while (e < np && w->s.pbase[w->s.order[e]] == b) ++e;
        pn__mpm_node_index(w, b, idx);
        for (c = 0, i = d - 1; i >= 0; --i) c = c * 3 + idx[i] % 3;
        tmp[3 * ng] = j, tmp[3 * ng + 1] = e, tmp[3 * ng + 2] = (size_t)c;
        count[c + 1]++;
        ++ng, j = e;
    }
    for (c = 0; c < nc; ++c) count[c + 1] += count[c];
    for (c = 0; c <= nc; ++c) cstart[c] = count[c];
    for (j = 0; j < ng; ++j) { /* stable: groups keep their sorted order within a colour */
        size_t q = count[tmp[3 * j + 2]]++;
        grp[2 * q] = tmp[3 * j], grp[2 * q + 1] = tmp[3 * j + 1];
    }
}

/* one Gauss-Seidel pass over the unknowns of sorted particles j0 .. j1 - 1 (one stencil base
   node): each particle's, or (cells) each cell's at its first particle (pn__mpm_stress_cells);
   f (optional): each unknown's change, at its storage index (pn__mpm_stress_anderson) */
static void pn__mpm_stress_group(pn_mpm_world *w, size_t j0, size_t j1, pn_real dt, pn_real *v, int cells,
                                 pn_real *f) {
    int d = w->dim, dd = d * d, ns = w->s.ns, i;
    size_t j;
    for (j = j0; j < j1; ++j) {
        pn_real L[9], tau[9], dtau[9], *cur = w->s.pP + j * (size_t)dd, sV, h;
        const pn_real *g;
        const long *dof = w->s.pdof + j * (size_t)ns;
        const pn_real *hat = w->s.pF0 + j * (size_t)dd;
        pn_real c = w->s.pty[j];
        if (cells) {
            pn_real *cell = w->s.pH + j * (size_t)(dd * dd);
            if (w->s.phG[j] == 0) continue;
            g = w->s.pb + j * (size_t)(ns * d), sV = dt, h = cell[2 * dd + 1], hat = cell, cur = cell + dd, c = cell[2 * dd];
            if (d == 2) pn__mpm_push2_at(g, dof, v, 1 / w->s.phG[j], NULL, L);
            else pn__mpm_push3_at(g, dof, v, 1 / w->s.phG[j], NULL, L);
        } else {
            g = w->s.pq + j * (size_t)(ns * d), sV = dt * w->s.pjvh[2 * j], h = w->s.pjvh[2 * j + 1];
            if (d == 2) pn__mpm_push2_at(g, dof, v, 1, NULL, L);
            else pn__mpm_push3_at(g, dof, v, 1, NULL, L);
        }
        pn__mpm_stress_local(&w->groups[w->s.pjg[j]].material, d, hat, cur, h, L, c, dt, tau, NULL);
        for (i = 0; i < dd; ++i) {
            dtau[i] = tau[i] - cur[i];
            cur[i] = tau[i];
        }
        if (f) memcpy(f + j * (size_t)dd, dtau, sizeof(pn_real) * (size_t)dd);
        pn__mpm_stress_apply(w, g, dof, dtau, sV, v);
    }
}

/* c = dt V gamma of one unknown: gamma >= the largest eigenvalue of G = sum_s g_s g_s^T / m_s
   (Gershgorin), g its weights (a cell: sum V g, scaled by 1 / V) */
static pn_real pn__mpm_stress_compliance(const pn_mpm_world *w, const pn_real *g, const long *dof, pn_real V,
                                         pn_real dt, pn_real scale) {
    int d = w->dim, s, a, b;
    pn_real G[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0}, gam = 0;
    for (s = 0; s < w->s.ns; ++s, g += d)
        for (a = 0; a < d; ++a)
            for (b = 0; b < d; ++b) G[a * d + b] += g[a] * g[b] * w->s.diag[dof[s]] * scale * scale;
    for (a = 0; a < d; ++a) {
        pn_real row = 0;
        for (b = 0; b < d; ++b) row += PN__FABS(G[a * d + b]);
        gam = PN__MAX(gam, row);
    }
    return dt * V * gam;
}

/* The cells (PN_MPM_STRESS_CELLS): the particles of one stencil base node and one material group
   share one stress, tau_c = Z(tau^_c + dt C sym(L_c)) with L_c = sum_s v_s b_s^T / V_c,
   b_s = sum_p V_p g_ps and V_c = sum_p V_p, tau^_c and h_c the volume averages; the force
   on node s is -tau_c b_s, whose power is -V_c tau_c : L_c, so the pair stays adjoint. A
   cell lives at its first particle's sorted index r: b in pb, V in phG (0 at its other
   particles), and in pH (dim^4 >= 2 dim^2 + 2 reals) tau^, tau, c and h; each particle's
   cell in crep (sgrp after the colour groups). Material groups mixed in one cell give it one
   unknown per group. The first iterate is tau^_c, applied to v; the particles' own tau^
   (pF0) and compliances stay, for a per-particle solve after it. At the end the particles
   of a cell take its velocity gradient L_c for their F (pn__mpm_g2p), not their own: a
   velocity field whose L averages to zero over every cell but not at each particle (an
   hourglass mode) meets no stress, and with their own L the particles' F drift in it (an
   elastic layer at rest showed stresses 2.3 times the hydrostatic ones, in a sawtooth). */
static void pn__mpm_stress_cells(pn_mpm_world *w, const size_t *cstart, pn_real dt, pn_real relax, pn_real *v) {
    int d = w->dim, dd = d * d, ns = w->s.ns, nsd = ns * d, i;
    size_t q, nq = cstart[d == 2 ? 9 : 27], *crep = w->s.sgrp + 2 * w->s.start[w->s.nodes];
    for (q = 0; q < nq; ++q) {
        size_t j0 = w->s.sgrp[2 * q], j1 = w->s.sgrp[2 * q + 1], j, r;
        for (j = j0; j < j1; ++j) {
            size_t p = w->s.order[j];
            pn_real V = w->vol0[p], *cell;
            const pn_real *g = w->s.pq + j * (size_t)nsd, *hat = w->s.pF0 + j * (size_t)dd;
            for (r = j0; r < j && !(crep[r] == r && w->group[w->s.order[r]] == w->group[p]); ++r) {
            }
            w->s.phG[j] = 0;
            crep[j] = r;
            if (r == j) { /* the first particle of its group here: the cell's unknown */
                memset(w->s.pH + j * (size_t)(dd * dd), 0, sizeof(pn_real) * (size_t)(2 * dd + 2));
                memset(w->s.pb + j * (size_t)nsd, 0, sizeof(pn_real) * (size_t)nsd);
            }
            cell = w->s.pH + r * (size_t)(dd * dd);
            w->s.phG[r] += V, cell[2 * dd + 1] += V * w->h[p];
            for (i = 0; i < nsd; ++i) w->s.pb[r * (size_t)nsd + (size_t)i] += V * g[i];
            for (i = 0; i < dd; ++i) cell[i] += V * hat[i];
        }
        for (j = j0; j < j1; ++j) {
            pn_real V = w->s.phG[j], *cell = w->s.pH + j * (size_t)(dd * dd);
            const pn_real *b = w->s.pb + j * (size_t)nsd;
            const long *dof = w->s.pdof + j * (size_t)ns;
            if (V == 0) continue;
            cell[2 * dd + 1] /= V;
            for (i = 0; i < dd; ++i) cell[i] /= V, cell[dd + i] = cell[i];
            cell[2 * dd] = pn__mpm_stress_compliance(w, b, dof, V, dt, 1 / V) / relax;
            pn__mpm_stress_apply(w, b, dof, cell, dt, v);
        }
    }
}

/* the cells' stresses handed to their particles (tau_p = tau_c: the same forces, so v stays) */
static void pn__mpm_stress_uncell(pn_mpm_world *w) {
    int dd = w->dim * w->dim;
    size_t j, np = w->s.start[w->s.nodes], *crep = w->s.sgrp + 2 * np;
    for (j = 0; j < np; ++j)
        memcpy(w->s.pP + j * (size_t)dd, w->s.pH + crep[j] * (size_t)(dd * dd) + dd, sizeof(pn_real) * (size_t)dd);
}

/* The coarse correction (pn_mpm_implicit_desc.coarse_every; elastic material only). A
   Gauss-Seidel sweep moves information about one cell, so a step many explicit steps long
   needs sweeps in proportion to the grid's width and to dt / dt_CFL. The sweeps descend the
   dual objective J(tau) of pn__mpm_stress_dual (for elastic material a quadratic). Every few
   sweeps the stresses take the step that minimizes J, found in the velocities: the law
   linearized at the current v, tau_p = hat_p + dt C (D_p(v) + D_p(dv)), in the momentum
   balance gives
       (M + dt^2 sum_p V_p B_p^T C B_p) dv = -dt sum_p V_p B_p^T (trial_p - tau_p),
   trial_p the law's stress at v and B_p v = sum_i v_i g_ip^T; the matrix is assembled into
   the multigrid hierarchy of >>multigrid (contact nodes held at the velocities the sweeps
   gave them: whole where there is friction, along their normals where they slip) and solved by CG to coarse_tol, preconditioned by its V-cycles.
   Then tau += alpha (trial - tau + dt C dL(dv)), the velocities following by the force of
   the change (by colour, as a sweep), and the contact nodes take their exact local solve
   (the sweeps' contact step: their impulses stay admissible, so J stays the step's dual
   objective); alpha = 1 unless J does not decrease (then 1/4, 1/16, 1/64, else undone).
   For elastic material away from contact alpha = 1 lands on the step's solution up to CG's
   tolerance. On yielding sand four variants were tried and none converged to the sweeps'
   answer (docs/notebook.md, "a coarse correction for yielding sand"). build: assemble the matrix
   (the step's first correction; for elastic material it does not change within the step).
   Returns the alpha taken, 0 when undone, -1 when the hierarchy could not be allocated. */
typedef struct pn__mpm_coarse {
    pn_mpm_world *w;
} pn__mpm_coarse;

static void pn__mpm_coarse_apply(void *ctx, const pn_real *x, pn_real *y) {
    pn__mpm_mg_apply(((pn__mpm_coarse *)ctx)->w, 0, x, NULL, y);
}

static void pn__mpm_coarse_precond(void *ctx, const pn_real *r, pn_real *z) {
    pn_mpm_world *w = ((pn__mpm_coarse *)ctx)->w;
    size_t k;
    pn__mpm_mg_vcycle(w, 0, r, z);
    for (k = 0; k < w->s.n_act; ++k) pn__mpm_filter(w, k, z + k * (size_t)w->dim);
}

static pn_real pn__mpm_coarse_dot(void *ctx, size_t n, const pn_real *a, const pn_real *b) {
    return pn__mpm_sum(((pn__mpm_coarse *)ctx)->w, n, a, b);
}

/* The dual objective the sweeps descend, J = 1/2 sum_k m_k |v_k|^2 + sum_p V_p / 2 (tau_p -
   hat_p) : C^-1 : (tau_p - hat_p) (v the velocities the stresses and contact impulses make;
   C^-1 X = dev X / (2 mu) + tr X I / (d^2 kappa), kappa as the local law has it), less the
   contact impulses' work r . v_obstacle; e: scratch of np reals */
static pn_real pn__mpm_stress_dual(pn_mpm_world *w, const pn_real *v, const pn_real *r, pn_real *e) {
    int d = w->dim, dd = d * d;
    size_t np = w->s.start[w->s.nodes];
    long lj, lk;
    pn_real *ek = w->s.cg_z;
    PN__OMP_FOR
    for (lj = 0; lj < (long)np; ++lj) {
        size_t j = (size_t)lj, p = w->s.order[j];
        const pn_material *m = &w->groups[w->group[p]].material;
        const pn_real *t = w->s.pP + j * (size_t)dd, *hat = w->s.pF0 + j * (size_t)dd;
        pn_real X[9], tr = 0, mhat = 0, dev2 = 0, dr = (pn_real)d, kappa = m->lambda + 2 * m->mu / dr;
        int i;
        for (i = 0; i < dd; ++i) X[i] = t[i] - hat[i];
        for (i = 0; i < d; ++i) tr += X[i * d + i], mhat += hat[i * d + i] / dr;
        if (m->elastic == PN_ELASTIC_NEO_HOOKEAN_SNOW) kappa = PN__MAX(kappa + 2 * mhat, (pn_real)1e-3 * kappa);
        for (i = 0; i < d; ++i) X[i * d + i] -= tr / dr;
        for (i = 0; i < dd; ++i) dev2 += X[i] * X[i];
        e[j] = w->vol0[p] / 2 * (dev2 / (2 * m->mu) + tr * tr / (dr * dr * kappa));
    }
    PN__OMP_FOR
    for (lk = 0; lk < (long)w->s.n_act; ++lk) {
        size_t k = (size_t)lk;
        int i;
        ek[k] = 0;
        for (i = 0; i < d; ++i) /* and the contact impulses' work against the obstacles */
            ek[k] += w->s.grid_m[k] / 2 * v[k * (size_t)d + (size_t)i] * v[k * (size_t)d + (size_t)i] -
                     r[k * (size_t)d + (size_t)i] * w->s.cvel[k * 3 + (size_t)i];
    }
    return pn__mpm_sum(w, np, e, NULL) + pn__mpm_sum(w, w->s.n_act, ek, NULL);
}

/* the stresses tau0 + alpha dtau and the velocities their change makes (by colour, as a
   sweep), then the contact nodes' exact local solve (the sweeps' contact step), so their
   impulses r stay admissible and J stays the dual objective of the step */
static void pn__mpm_stress_move(pn_mpm_world *w, const size_t *cstart, pn_real dt, pn_real alpha, const pn_real *tau0,
                                const pn_real *dtau, pn_real *v, pn_real *r) {
    int d = w->dim, dd = d * d, ns = w->s.ns, c;
    for (c = 0; c < (d == 2 ? 9 : 27); ++c) {
        long q;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (w->n >= w->desc.parallel_min_particles)
#endif
        for (q = (long)cstart[c]; q < (long)cstart[c + 1]; ++q) {
            size_t j;
            for (j = w->s.sgrp[2 * (size_t)q]; j < w->s.sgrp[2 * (size_t)q + 1]; ++j) {
                size_t p = w->s.order[j];
                pn_real D[9], *cur = w->s.pP + j * (size_t)dd;
                int i;
                for (i = 0; i < dd; ++i) {
                    pn_real t = tau0[j * (size_t)dd + (size_t)i] + alpha * dtau[j * (size_t)dd + (size_t)i];
                    D[i] = t - cur[i], cur[i] = t;
                }
                pn__mpm_stress_apply(w, w->s.pq + j * (size_t)(ns * d), w->s.pdof + j * (size_t)ns, D, dt * w->vol0[p], v);
            }
        }
    }
    pn__mpm_stress_contact(w, v, r);
}

static pn_real pn__mpm_stress_coarse(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *o, const size_t *cstart,
                                     int build, pn_real *v, pn_real *r, pn_mpm_stats *st) {
    int d = w->dim, dd = d * d, ns = w->s.ns, capped, it, tries;
    size_t np = w->s.start[w->s.nodes], nd = w->s.n_act * (size_t)d;
    pn_real *dtau = w->s.pG, *b = w->s.cg_r, *dv = w->s.dir, *tau0 = w->s.ptau, *e = w->s.ptau + w->cap * (size_t)dd;
    pn_real J0, J1 = 0, alpha = 1;
    long lj, lk;
    pn__mpm_coarse cc;
    pn__cg_ops op;
    PN__OMP_FOR
    for (lj = 0; lj < (long)np; ++lj) { /* the law linearized at v, each particle: trial - tau */
        size_t j = (size_t)lj, p = w->s.order[j];
        pn_real L[9], Z[9], *cur = w->s.pP + j * (size_t)dd;
        int i;
        pn__mpm_push(w, p, v, 1, NULL, L);
        pn__mpm_stress_local(&w->groups[w->group[p]].material, d, w->s.pF0 + j * (size_t)dd, cur, w->h[p], L, 0, dt, Z,
                             w->s.pH + p * (size_t)(dd * dd));
        for (i = 0; i < dd; ++i) dtau[j * (size_t)dd + (size_t)i] = Z[i] - cur[i];
    }
    PN__OMP_FOR
    for (lk = 0; lk < (long)w->s.n_act; ++lk) { /* b = -dt sum V (trial - tau) g, gathered per node */
        size_t ei, k = (size_t)lk;
        pn_real acc[3] = {0, 0, 0};
        int a, c;
        for (ei = w->s.inc_start[k]; ei < w->s.inc_start[k + 1]; ++ei) {
            size_t ps = w->s.inc[ei], j = ps / (size_t)ns;
            const pn_real *g = w->s.pq + ps * (size_t)d, *z = dtau + j * (size_t)dd;
            pn_real sV = dt * w->vol0[w->s.order[j]];
            for (a = 0; a < d; ++a)
                for (c = 0; c < d; ++c) acc[a] -= sV * z[a * d + c] * g[c];
        }
        for (a = 0; a < d; ++a) b[k * (size_t)d + (size_t)a] = acc[a];
        pn__mpm_filter(w, k, b + k * (size_t)d);
    }
    if (build) { /* the matrix is the step's own (elastic C, the step's weights and masses): once */
        if (pn__mpm_mg_build(w, dt, 1, o->mg_levels ? o->mg_levels : PN__MPM_MG_MAX) != PN_OK) return -1;
        st->mg_builds++;
    }
    cc.w = w;
    op.ctx = &cc, op.apply = pn__mpm_coarse_apply, op.precond = pn__mpm_coarse_precond, op.dot = pn__mpm_coarse_dot;
    op.curv = NULL;
    it = pn__pcg(&op, nd, dv, b, w->s.cg_z, w->s.cg_p, w->s.cg_q, o->coarse_cg, o->coarse_tol, 0, &capped);
    st->cg_iters += it;
    PN__OMP_FOR
    for (lj = 0; lj < (long)np; ++lj) { /* dtau = trial - tau + dt C dL(dv) */
        size_t j = (size_t)lj, p = w->s.order[j];
        const pn_real *H = w->s.pH + p * (size_t)(dd * dd);
        pn_real L[9], *z = dtau + j * (size_t)dd;
        int i, k;
        pn__mpm_push(w, p, dv, 1, NULL, L);
        for (i = 0; i < dd; ++i) {
            pn_real t = 0;
            for (k = 0; k < dd; ++k) t += H[i * dd + k] * L[k];
            z[i] += dt * t;
        }
    }
    J0 = pn__mpm_stress_dual(w, v, r, e);
    memcpy(tau0, w->s.pP, sizeof(pn_real) * np * (size_t)dd);
    memcpy(w->s.vtry, v, sizeof(pn_real) * nd);
    memcpy(w->s.cg_p, r, sizeof(pn_real) * nd);
    for (tries = 0; tries < 4; ++tries, alpha /= 4) { /* backtracking on J */
        pn__mpm_stress_move(w, cstart, dt, alpha, tau0, dtau, v, r);
        J1 = pn__mpm_stress_dual(w, v, r, e);
        if (J1 < J0) break;
        memcpy(w->s.pP, tau0, sizeof(pn_real) * np * (size_t)dd);
        memcpy(v, w->s.vtry, sizeof(pn_real) * nd);
        memcpy(r, w->s.cg_p, sizeof(pn_real) * nd);
    }
    st->coarse_corrections++;
    st->coarse_rejected += tries == 4;
    return tries < 4 ? alpha : 0;
}

/* Anderson acceleration of the sweeps (pn_mpm_implicit_desc.anderson; Walker and Ni 2011,
   depth one). A sweep maps the stresses x to g = S(x), and the velocities and the contact
   impulses r follow the stresses affinely (v = v* + M^-1 (r - dt sum V B^T tau)), so the
   step's answer is S's fixed point. Projected Gauss-Seidel converges on it linearly, and
   slowly where information must cross the grid. With f_k = g_k - x_k, the sweep's change,
   and the previous sweep's g and f, the next iterate is
       x = g_k - gamma (g_k - g_{k-1}),   gamma = <df, f_k> / <df, df>,   df = f_k - f_{k-1}
   (the combination of the two results whose changes, extrapolated linearly, cancel most),
   and v and r take the same combination of their values after those sweeps: momentum stays
   exact, and no particle is visited. A stress taken outside the yield surface is brought
   back by its next local solve, and the contact nodes' impulses by the next contact step;
   the sweeps stop only on a sweep's own change. When a sweep changed more than the one
   before (|f_k| > |f_{k-1}|, ff holding |f_{k-1}|^2), its result stands and the history
   starts again from it. Storage: paa holds per unknown g_{k-1}, f_{k-1} (dim^2 each, unknown
   u) and four sums; the unknowns' storage indices are paai (cells) or the sorted indices; f_k
   comes from the sweep in pG; v_{k-1} and r_{k-1} in dir and cg_z. have: the previous
   sweep's results are recorded. This part: the sums, gamma, and q = |dx| / |df|, the secant
   of (I - S)^-1 (the stopping rule's estimate of the error left over the change); returns 1
   when gamma is to be taken, 0 when the sweep's result stands (only recorded). */
static int pn__mpm_stress_anderson(pn_mpm_world *w, int cells, size_t nu, int have, pn_real *gamma, pn_real *q,
                                   pn_real *ff) {
    int dd = w->dim * w->dim;
    pn_real *gp = w->s.paa, *fp = w->s.paa + w->cap * (size_t)dd, *e1 = fp + w->cap * (size_t)dd, *e2 = e1 + w->cap;
    pn_real *e3 = e2 + w->cap, *e4 = e3 + w->cap, a, b, c, fk;
    long lu;
    PN__OMP_FOR
    for (lu = 0; lu < (long)nu; ++lu) { /* per unknown: df . f_k, |df|^2, |dx|^2; then f_{k-1} = f_k */
        size_t u = (size_t)lu, j = cells ? w->s.paai[u] : u;
        const pn_real *f = w->s.pG + j * (size_t)dd;
        const pn_real *x = cells ? w->s.pH + j * (size_t)(dd * dd) + dd : w->s.pP + j * (size_t)dd;
        pn_real *fu = fp + u * (size_t)dd, *gu = gp + u * (size_t)dd, s1 = 0, s2 = 0, s3 = 0, s4 = 0;
        int i;
        for (i = 0; i < dd; ++i) {
            pn_real df = f[i] - fu[i], dx = x[i] - gu[i] - df;
            s1 += df * f[i], s2 += df * df, s3 += dx * dx, s4 += f[i] * f[i];
            fu[i] = f[i];
        }
        e1[u] = s1, e2[u] = s2, e3[u] = s3, e4[u] = s4;
    }
    *q = *gamma = 0;
    fk = pn__mpm_sum(w, nu, e4, NULL);
    if (!have || !(fk <= *ff)) { /* the first record, or the change grew: the sweep's own result, a new start */
        *ff = fk;
        return 0;
    }
    *ff = fk;
    a = pn__mpm_sum(w, nu, e1, NULL);
    b = pn__mpm_sum(w, nu, e2, NULL);
    c = pn__mpm_sum(w, nu, e3, NULL);
    if (!(b > 0)) return 0;
    *gamma = a / b, *q = PN__SQRT(c / b);
    if (!pn__finite(*gamma) || !pn__finite(*q)) *gamma = *q = 0;
    return *gamma != 0;
}

/* the accelerated iterate: x = g_k - gamma (g_k - g_{k-1}), and v and r alike; then g_{k-1} = g_k */
static void pn__mpm_stress_anderson_move(pn_mpm_world *w, int cells, size_t nu, pn_real gamma, pn_real *v, pn_real *r) {
    int dd = w->dim * w->dim;
    size_t nd = w->s.n_act * (size_t)w->dim;
    pn_real *gp = w->s.paa, *vp = w->s.dir, *rp = w->s.cg_z;
    long lu, lk;
    PN__OMP_FOR
    for (lu = 0; lu < (long)nu; ++lu) {
        size_t u = (size_t)lu, j = cells ? w->s.paai[u] : u;
        pn_real *x = cells ? w->s.pH + j * (size_t)(dd * dd) + dd : w->s.pP + j * (size_t)dd, *gu = gp + u * (size_t)dd;
        int i;
        for (i = 0; i < dd; ++i) {
            pn_real g = x[i];
            x[i] = g - gamma * (g - gu[i]);
            gu[i] = g;
        }
    }
    PN__OMP_FOR
    for (lk = 0; lk < (long)nd; ++lk) {
        size_t k = (size_t)lk;
        pn_real vk = v[k], rk = r[k];
        v[k] = vk - gamma * (vk - vp[k]), vp[k] = vk;
        r[k] = rk - gamma * (rk - rp[k]), rp[k] = rk;
    }
}

/* Gauss-Seidel sweeps (by colour; the cells' or the particles') and the contact nodes' until
   the velocity error left, estimated, is below sweep_tol dx / dt: a linear rate rho leaves
   about res rho / (1 - rho) after a sweep that moved res; stop on that, not on res (a slow,
   smooth mode moves little per sweep); rho the slower of the last two rates (they are noisy).
   With Anderson acceleration (pn__mpm_stress_anderson) the rate is the acceleration's, not
   the sweeps': rho / (1 - rho) is estimated by q - 1, q the secant |dx| / |df|. */
static pn_result pn__mpm_stress_sweeps(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *o, pn_real tol,
                                       const size_t *cstart, int cells, int coarse, pn_real mref, pn_real *v,
                                       pn_real *r, pn_mpm_stats *st) {
    int d = w->dim, i, sweep;
    size_t k, nd = w->s.n_act * (size_t)d;
    pn_real *v0 = w->s.vtry, vscale = tol * w->desc.dx_m / dt, res = 0, prev = 0, prev2 = 0;
    int gap = coarse, next = coarse - 1, built = 0, aa = o->anderson >= 0, have = 0, acc = 0;
    pn_real gamma = 0, qa = 0, ff = 0;
    size_t nu = w->s.start[w->s.nodes], j;
    if (aa && cells) /* the cells' storage indices */
        for (nu = 0, j = 0; j < w->s.start[w->s.nodes]; ++j)
            if (w->s.phG[j] != 0) w->s.paai[nu++] = j;
    if (coarse > 0) /* in the corrections' linear systems, contact nodes with friction held whole (slip: the normal) */
        for (k = 0; k < w->s.n_act; ++k)
            if (w->s.cn[k] && (w->s.ckind[k] == PN_BOUNDARY_STICKY || w->s.cmu[k] > 0))
                w->s.chold[k] = (unsigned char)(w->s.chold[k] | PN__MPM_STICK);
    for (sweep = 0; sweep < o->sweeps_max; ++sweep) {
        int c;
        memcpy(v0, v, sizeof(pn_real) * nd);
        for (c = 0; c < (d == 2 ? 9 : 27); ++c) {
            long q;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) if (w->n >= w->desc.parallel_min_particles)
#endif
            for (q = (long)cstart[c]; q < (long)cstart[c + 1]; ++q)
                pn__mpm_stress_group(w, w->s.sgrp[2 * (size_t)q], w->s.sgrp[2 * (size_t)q + 1], dt, v, cells,
                                     aa ? w->s.pG : NULL);
        }
        pn__mpm_stress_contact(w, v, r);
        for (res = 0, k = 0; k < w->s.n_act; ++k) {
            pn_real sc = mref > 0 ? PN__MIN(w->s.grid_m[k] / mref, 1) : 1;
            for (i = 0; i < d; ++i)
                res = PN__MAX(res, sc * PN__FABS(v[k * (size_t)d + (size_t)i] - v0[k * (size_t)d + (size_t)i]));
        }
        st->sweeps++;
        if (!pn__finite(res))
            return PN__FAIL(w, PN_ERROR_OVERFLOW, "implicit step of %g s (stress formulation): the velocities "
                                "overflowed", (double)dt);
        if (res == 0) break; /* nothing moved: converged (material in free flight) */
        if (aa) acc = pn__mpm_stress_anderson(w, cells, nu, have, &gamma, &qa, &ff);
        if (sweep > 1 && res <= vscale) {
            pn_real rho = prev > 0 && prev2 > 0 ? PN__MAX(res / prev, prev / prev2) : 1;
            if (acc && qa > 0) { /* accelerated, the rate says little: the secant of the change */
                if (res * (qa - 1) <= vscale) break;
            } else if (rho < 1 && res * rho <= vscale * (1 - rho)) break;
        }
        prev2 = prev;
        prev = res;
        if (coarse > 0 && sweep == next) { /* a correction; after one that took less than a quarter step, wait longer */
            pn_real alpha = pn__mpm_stress_coarse(w, dt, o, cstart, !built, v, r, st);
            built = 1;
            if (alpha < 0) coarse = 0; /* no room for the hierarchy: the sweeps alone */
            gap = alpha >= (pn_real)0.25 ? coarse : 2 * gap;
            next = sweep + gap;
            if (alpha > 0) prev = prev2 = 0; /* a new start for the rate */
            have = 0; /* and for the acceleration, whose records the correction used as scratch */
        } else if (aa) {
            pn__mpm_stress_anderson_move(w, cells, nu, acc ? gamma : 0, v, r); /* gamma 0: records g, v, r */
            st->anderson_steps += acc;
            have = 1;
        }
    }
    st->newton_residual = PN__MAX(st->newton_residual, res * dt / w->desc.dx_m);
    if (sweep == o->sweeps_max)
        return PN__FAIL(w, PN_ERROR_NOT_CONVERGED, "implicit step of %g s (stress formulation): sweeps_max = %d "
                            "Gauss-Seidel sweeps%s did not converge (the last one moved the grid by %.3g dx / dt, "
                            "tolerance %g): raise sweeps_max or take a smaller step", (double)dt, o->sweeps_max,
                            cells ? " of the cells" : "", (double)(res * dt / w->desc.dx_m), (double)tol);
    return PN_OK;
}

static pn_result pn__mpm_stress_once(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *o, pn_mpm_stats *st) {
    int d = w->dim, dd = d * d, ns = w->s.ns, nt = d * (d + 1) / 2, i, cells = o->stress_unknowns != PN_MPM_STRESS_PARTICLES;
    const pn_real *tc;
    int cascade = o->stress_unknowns == PN_MPM_STRESS_CELLS_THEN_PARTICLES, coarse;
    size_t k, j, np, total = 0, cstart[28];
    pn_real *v = w->s.vsol, *r = w->s.grad, mref = 0;
    pn_result rr;
    if (w->s.tok) /* pH becomes scratch here: no Taylor model survives */
        for (k = 0; k < w->n; ++k)
            if (w->s.tok[k]) pn__mpm_touch(w, k), w->s.tok[k] = 0;
    if (!w->s.sgrp || !w->s.pjvh || !w->s.pjg) {
        int fail = 0;
        if (!w->s.sgrp) w->s.sgrp = (size_t *)pn__mpm_alloc(&w->desc, w->cap * 5, sizeof(size_t), &fail);
        if (!fail && !w->s.pjvh) w->s.pjvh = (pn_real *)pn__mpm_alloc(&w->desc, w->cap * 2, sizeof(pn_real), &fail);
        if (!fail && !w->s.pjg) w->s.pjg = (int *)pn__mpm_alloc(&w->desc, w->cap, sizeof(int), &fail);
        if (fail)
            return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "implicit step (stress formulation): out of memory "
                                "for the sweeps' groups and particle records (%lu particles)", (unsigned long)w->cap);
    }
    if (!cells || cascade) { /* the coarse correction's scratch */
        int fail = 0;
        if (!w->s.ptau) w->s.ptau = (pn_real *)pn__mpm_alloc(&w->desc, w->cap * (size_t)(dd + 1), sizeof(pn_real), &fail);
        if (fail)
            return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "implicit step (stress formulation): out of memory "
                                "for the coarse correction (%lu reals)", (unsigned long)(w->cap * (size_t)(dd + 1)));
    }
    if (o->anderson >= 0 && (!w->s.paa || !w->s.paai)) {
        int fail = 0;
        if (!w->s.paai) w->s.paai = (size_t *)pn__mpm_alloc(&w->desc, w->cap, sizeof(size_t), &fail);
        if (!fail && !w->s.paa) w->s.paa = (pn_real *)pn__mpm_alloc(&w->desc, w->cap * (size_t)(2 * dd + 4), sizeof(pn_real), &fail);
        if (fail)
            return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "implicit step (stress formulation): out of memory "
                                "for the sweeps' Anderson acceleration (%lu values)",
                                (unsigned long)(w->cap * (size_t)(2 * dd + 5)));
    }
    if (cells && !w->s.pb) {
        int fail = 0;
        w->s.pb = (pn_real *)pn__mpm_alloc(&w->desc, w->cap * (size_t)(ns * d), sizeof(pn_real), &fail);
        if (fail)
            return PN__FAIL(w, PN_ERROR_OUT_OF_MEMORY, "implicit step (stress formulation): out of memory "
                                "for the cells' weights (%lu reals)", (unsigned long)(w->cap * (size_t)(ns * d)));
    }
    coarse = o->coarse_every > 0 ? o->coarse_every : o->coarse_every == 0 && o->linear_solver != PN_MPM_LINEAR_JACOBI ? 4 : 0;
    for (i = 0; i < w->n_groups; ++i) /* elastic material only (docs/notebook.md, "a coarse correction for yielding sand") */
        if (w->groups[i].material.plastic != PN_PLASTIC_NONE) coarse = 0;
    pn__mpm_mark(w, st, -1);
    w->s.stress_on = 1;
    pn__mpm_bin(w);
    pn__mpm_implicit_setup(w, coarse && (!cells || cascade)); /* the coarse correction gathers by node */
    w->s.stress_on = 0; /* set again around the transfer back */
    pn__mpm_p2g(w);
    pn__mpm_contact(w, w->time_s);
    np = w->s.start[w->s.nodes];
    st->active_nodes = w->s.n_act;
    for (k = 0; k < w->s.n_act; ++k) {
        pn_real m = w->s.grid_m[k];
        w->s.diag[k] = m > 0 ? 1 / m : 0;
        for (i = 0; i < d; ++i) {
            size_t c = k * (size_t)d + (size_t)i;
            v[c] = w->s.vstar[c] = m > 0 ? w->s.grid_v[c] / m + dt * w->desc.gravity[i] : 0;
            r[c] = 0;
        }
    }
    tc = w->s.ctau_ok ? w->s.ctau : w->s.stau_committed ? w->s.stau : NULL; /* the state's stresses, if kept */
    for (j = 0; j < np; ++j) { /* tau^ (the state's own stress), c, the first iterate */
        size_t p = w->s.order[j];
        const pn_material *m = &w->groups[w->group[p]].material;
        pn_real Z[9], hn;
        int plastic, a, b;
        if (tc) {
            const pn_real *t = tc + p * (size_t)nt;
            pn_real *hat = w->s.pF0 + j * (size_t)dd;
            for (a = 0; a < d; ++a)
                for (b = a; b < d; ++b) hat[a * d + b] = hat[b * d + a] = *t++;
            rr = PN_OK;
        } else
            rr = pn__return_tau(m, d, w->F + p * (size_t)dd, w->h[p], Z, &hn, w->s.pF0 + j * (size_t)dd, &plastic);
        if (rr != PN_OK) {
            w->error_particle = (long)p;
            return PN__FAIL(w, rr, "implicit step (stress formulation): particle %lu (group %d): %s",
                                (unsigned long)p, w->group[p], pn_result_string(rr));
        }
        total += w->active[p];
        w->s.pjvh[2 * j] = w->vol0[p], w->s.pjvh[2 * j + 1] = w->h[p], w->s.pjg[j] = w->group[p];
        mref += w->active[p] ? w->mass[p] : 0;
        {
            const pn_real *g = w->s.pq + j * (size_t)(ns * d);
            const long *dof = w->s.pdof + j * (size_t)ns;
            if (!cells || cascade) /* a particle's own compliance: only its own sweeps use it */
                w->s.pty[j] = pn__mpm_stress_compliance(w, g, dof, w->vol0[p], dt, 1);
            memcpy(w->s.pP + j * (size_t)dd, w->s.pF0 + j * (size_t)dd, sizeof(pn_real) * (size_t)dd);
            if (!cells) pn__mpm_stress_apply(w, g, dof, w->s.pP + j * (size_t)dd, dt * w->vol0[p], v);
        }
    }
    mref = total ? mref / (pn_real)total : 0;
    pn__mpm_mark(w, st, PN_MPM_STAGE_ENERGY); /* the start stresses (setup counted in) */
    pn__mpm_stress_groups(w, cstart);
    if (cells) pn__mpm_stress_cells(w, cstart, dt, o->cell_relax, v);
    pn__mpm_stress_contact(w, v, r);
    rr = pn__mpm_stress_sweeps(w, dt, o, cascade ? 10 * o->sweep_tol : o->sweep_tol, cstart, cells, cells ? 0 : coarse,
                               mref, v, r, st);
    if (rr != PN_OK) return rr;
    if (cascade) { /* the particles from the cells' stresses: the same forces, so v holds */
        pn__mpm_stress_uncell(w);
        if ((rr = pn__mpm_stress_sweeps(w, dt, o, o->sweep_tol, cstart, 0, coarse, mref, v, r, st)) != PN_OK) return rr;
    }
    pn__mpm_mark(w, st, PN_MPM_STAGE_SWEEPS);
    w->s.stress_on = cells && !cascade ? 2 : 1;
    rr = pn__mpm_g2p(w, v, NULL, dt, st);
    w->s.stress_on = 0;
    if (rr == PN_OK) rr = pn__mpm_energy_guard(w, o, dt, st);
    pn__mpm_mark(w, st, PN_MPM_STAGE_G2P);
    if (rr != PN_OK) return rr;
    w->s.n_lag = 0; /* no friction memory for a later energy-formulation step */
    pn__mpm_commit(w, dt, st);
    return PN_OK;
}

/* ======================================================================================
   >>implicit-step: the driver of an implicit step (pn_mpm_step_implicit). The step's start
   (bin, setup, particle to grid, contact), one pass of the chosen formulation (the energy's
   Newton solve of >>implicit, or the stress sweeps of >>stress), the fixed point on F0 and
   the contact rounds around it, the state kept for a failed try, and the fallback: halving
   the step into substeps.
   ====================================================================================== */

/* LINEAR_DEFAULT in 3D: a step solved with Jacobi at more than PN__MPM_JACOBI_MAX CG iterations
   per Newton iteration (cg of them over newton) hands the next steps to multigrid; a
   multigrid step leaves the choice as it was (Jacobi's retry every 16 steps decides). A
   Jacobi solve capped at cg_max moves the step itself to multigrid (pn__mpm_lin_escape). */
static void pn__mpm_lin_record(pn_mpm_world *w, long cg, long newton) {
    if (w->s.lin_auto && !w->s.mg_on) w->s.lin_mg = cg > (long)PN__MPM_JACOBI_MAX * newton;
}
static int pn__mpm_lin_escape(pn_mpm_world *w, int capped) {
    if (!capped || !w->s.lin_auto || w->s.mg_on) return 0;
    w->s.mg_on = w->s.lin_mg = 1;
    w->s.mg_levels = 0;
    return 1;
}

/* The start of an implicit step (the coupled one's too): bin, setup, particle to grid,
   contact; v* = momentum / mass + dt g, separating contacts held where they approach, vsol
   = v* with the holds and (friction) the first friction lag. Returns 1 when a node has a
   separating contact. */
static int pn__mpm_implicit_begin(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *o, pn_mpm_stats *st) {
    int d = w->dim, i, has_sep = 0;
    size_t k, nd;
    pn__mpm_mark(w, st, -1);    pn__mpm_bin(w);
    pn__mpm_implicit_setup(w, 1);
    pn__mpm_p2g(w);
    pn__mpm_contact(w, w->time_s);
    pn__mpm_mark(w, st, PN_MPM_STAGE_SETUP);
    nd = w->s.n_act * (size_t)d;
    w->s.pnet_lanes = !o->pnet_double; /* (a solve may turn both off: >>implicit-step) */
    w->s.reuse_tol = pn__mpm_reuse_tol(o);
    w->s.lin_auto = o->linear_solver == PN_MPM_LINEAR_DEFAULT && nd >= PN__MPM_MG_MIN && d == 3;
    w->s.mg_on = o->linear_solver == PN_MPM_LINEAR_MULTIGRID ||
                 (o->linear_solver == PN_MPM_LINEAR_DEFAULT && nd >= PN__MPM_MG_MIN &&
                  (d == 2 || (w->s.lin_mg && w->steps % 16 != 0)));
    w->s.mg_levels = 0; /* a new active set: the hierarchy is built afresh */
    st->active_nodes = w->s.n_act;
    /* v* = momentum / mass + dt g; separating contacts start held where they approach */
    for (k = 0; k < w->s.n_act; ++k) {
        pn_real m = w->s.grid_m[k];
        for (i = 0; i < d; ++i) {
            size_t c = k * (size_t)d + (size_t)i;
            w->s.vstar[c] = m > 0 ? w->s.grid_v[c] / m + dt * w->desc.gravity[i] : 0;
        }
        if (w->s.ckind[k] == PN_BOUNDARY_SEPARATE && w->s.cn[k]) {
            int b;
            has_sep = 1;
            w->s.chold[k] = 0;
            for (b = 0; b < w->s.cn[k]; ++b) {
                pn_real un = 0;
                for (i = 0; i < d; ++i) un += (w->s.vstar[k * (size_t)d + (size_t)i] - w->s.cvel[k * 3 + (size_t)i]) * w->s.cdir[k * 9 + (size_t)(3 * b + i)];
                if (un <= 0) w->s.chold[k] = (unsigned char)(w->s.chold[k] | 1 << b);
            }
        }
    }
    memcpy(w->s.vsol, w->s.vstar, sizeof(pn_real) * nd);
    for (k = 0; k < w->s.n_act; ++k) pn__mpm_hold(w, k, w->s.vsol + k * (size_t)d);
    if (has_sep) pn__mpm_friction_start(w, w->s.vsol, dt);
    return has_sep;
}

/* After a line search from E0 along a direction with gd = grad . dir that took alpha: 0 go
   on; 1 stop, converged; 2 the rest of the attempt evaluates PlasticityNet in pn_real. A
   shortened step whose predicted decrease is below about 1e-6 of the energy: the float
   lanes' rounding now decides the line search, and Newton would stall at it (the snow press:
   50 iterations at one residual; a nonconvex energy's genuine backtracking is at 1e-5 and
   above). Within the acceptance band (in_band) that is convergence; short of it, the network
   in pn_real, without the Taylor models the lanes left (their values jump by that rounding). */
static int pn__mpm_lanes_stall(pn_mpm_world *w, pn_real gd, pn_real E0, pn_real alpha, int in_band) {
    int g, any = 0;
    for (g = 0; g < w->n_groups; ++g) any |= pn__mpm_energy_of(&w->groups[g]) == PN_ENERGY_PNET;
    if (!any || !w->s.pnet_lanes || !(alpha < 1) || !pn__unresolved(gd, E0, (pn_real)FLT_EPSILON / 100)) return 0;
    if (in_band) return 1;
    w->s.pnet_lanes = 0, w->s.reuse_tol = 0;
    return 2;
}

/* Newton's step (max |dv| dt / dx, cells) under which the particles' Hessians are used as
   they are, not PSD-projected: near the minimum projection only slows Newton (linear
   convergence where an energy is not convex: a network without its regularizer), as in FEM
   (PN__FEM_FULL_H) */
#define PN__MPM_FULL_H ((pn_real)1e-2)

/* One implicit step without fallback; the world is unchanged unless it returns PN_OK. */
static pn_result pn__mpm_implicit_once(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *o,
                                       pn_mpm_stats *st) {
    int d = w->dim, pass, has_sep, capped = 0, any_pnet = 0, g, i; /* capped: the last linear solve stopped at cg_max */
    size_t k, nd;
    pn_result r;
    pn_real vscale = o->newton_tol * w->desc.dx_m / dt, last_res = 0;
    has_sep = pn__mpm_implicit_begin(w, dt, o, st);
    for (g = 0; g < w->n_groups; ++g) any_pnet |= pn__mpm_energy_of(&w->groups[g]) == PN_ENERGY_PNET;
    nd = w->s.n_act * (size_t)d;
    for (pass = 0; pass < o->fixed_point_iters; ++pass) {
        pn_real fp_res = 0;
        int round;
        pn__mpm_mark(w, st, PN_MPM_STAGE_SETUP);
        if (pass == 0 && any_pnet) { /* PlasticityNet's anchor: v* without gravity's kick */
            for (k = 0; k < w->s.n_act; ++k) {
                for (i = 0; i < d; ++i) {
                    size_t c = k * (size_t)d + (size_t)i;
                    w->s.vtry[c] = w->s.grid_m[k] > 0 ? w->s.vstar[c] - dt * w->desc.gravity[i] : 0;
                }
                pn__mpm_hold(w, k, w->s.vtry + k * (size_t)d);
            }
        }
        r = pn__mpm_prepare_pass(w, w->s.vsol, pass == 0 && any_pnet ? w->s.vtry : NULL, dt, pass == 0, &fp_res);
        pn__mpm_mark(w, st, PN_MPM_STAGE_ENERGY);
        if (r != PN_OK) return r;
        if (pass > 0) st->fixed_point_residual = PN__MAX(st->fixed_point_residual, fp_res);
        st->fixed_point_iters++;
        for (round = 0; round < o->contact_rounds; ++round) {
            int it, cg, cg_fresh = 0, fresh, stale = w->s.mg_stale && w->steps % 16 != 0;
            pn_real eta = 0, gprev = 0, pred = 0; /* forcing: last eta, |S g|, predicted |S g| */
            pn_real dprev = 0, left = 0; /* the last full Newton step's max |dv| (0: none yet) */
            pn_real full_below = PN__MPM_FULL_H; /* Newton's steps (cells) under which Hessians go unprojected */
            if (has_sep && pass + round > 0) pn__mpm_friction_update(w, w->s.vsol);
            st->solves++;
            for (it = 0; it < o->newton_max; ++it) {
                pn_real E0, E1, gd, alpha = 1, dmax = 0, gnorm;
                int full = it > 0 && last_res <= full_below, redo = 0, stall;
                if (w->s.newton_left-- <= 0)
                    return PN__FAIL(w, PN_ERROR_NOT_CONVERGED, "implicit step: its newton_budget of %d Newton iterations "
                                        "is spent (over its attempts and substeps): take a smaller step", o->newton_budget);
                pn__mpm_mark(w, st, PN_MPM_STAGE_LINEAR); /* the last iteration's bookkeeping */
                for (;;) { /* near the minimum the Hessian as it is (quadratic convergence); where it is
                              not positive definite, projected until the steps are 10x shorter */
                    w->s.full_h = full;
                    r = pn__mpm_objective(w, w->s.vsol, dt, 2, &E0);
                    w->s.full_h = 0;
                    pn__mpm_mark(w, st, PN_MPM_STAGE_ENERGY);
                    if (r != PN_OK) return r;
                    gnorm = pn__mpm_model_norm(w, 0);
                    eta = pn__mpm_forcing(o, it, eta, gprev, pred, gnorm);
                    fresh = it == 0 || o->mg_rebuild || stale || redo;
                    if (w->s.mg_on && (r = pn__mpm_mg_build(w, dt, fresh, o->mg_levels)) != PN_OK)
                        return PN__FAIL(w, r, "implicit step: out of memory for the multigrid hierarchy of %lu active "
                                            "nodes", (unsigned long)w->s.n_act);
                    cg = pn__mpm_pcg(w, dt, o->cg_max, eta, 0, &capped);
                    st->cg_iters += cg;
                    st->mg_builds += w->s.mg_on && fresh;
                    if (pn__mpm_lin_escape(w, capped)) { /* Jacobi gave up: this iteration again by multigrid */
                        redo = 1;
                        continue;
                    }
                    if (!full || !w->s.curv) break;
                    full = 0, full_below = last_res / 10, redo = 1; /* and a hierarchy of the projected H */
                }
                gprev = gnorm;
                /* a lagged hierarchy that costs half as many iterations again as a fresh one is
                   rebuilt at every Newton iteration from then on (the energy's Hessian moves
                   fast: DP's kinks), retried every 16 steps */
                if (fresh) cg_fresh = cg;
                if (!fresh) w->s.mg_stale = stale = 2 * cg > 3 * cg_fresh + 4;
                st->newton_iters++;
                for (k = 0; k < nd; ++k) dmax = PN__MAX(dmax, PN__FABS(w->s.dir[k]));
                if (dmax <= vscale && eta > o->cg_rel_tol) { /* a loose solve may stop Newton early */
                    st->cg_iters += pn__mpm_pcg(w, dt, o->cg_max, o->cg_rel_tol, 1, &capped);
                    for (dmax = 0, k = 0; k < nd; ++k) dmax = PN__MAX(dmax, PN__FABS(w->s.dir[k]));
                }
                st->cg_capped += capped;
                last_res = dmax / (w->desc.dx_m / dt);
                if (last_res > PN__MPM_FULL_H) full_below = PN__MPM_FULL_H; /* moved on */
                if (o->trace) o->trace(o->trace_user, st->solves, it, E0, last_res);
                if (!pn__finite(dmax))
                    return PN__FAIL(w, PN_ERROR_OVERFLOW, "implicit step of %g s: the Newton direction is not finite "
                                        "(the Hessian overflowed)", (double)dt);
                /* a small direction from a solve cut at cg_max proves nothing: go on */
                if (dmax <= vscale && !capped) break;
                gd = pn__mpm_sum(w, nd, w->s.grad, w->s.dir);
                pn__mpm_mark(w, st, PN_MPM_STAGE_LINEAR);
                /* within the acceptance band and below the energy's rounding: converged as far as
                   the values resolve (line searches would only take ever shorter steps) */
                if (last_res <= 100 * o->newton_tol && pn__unresolved(gd, E0, PN__EPS) && !capped) break;
                {
                    pn__mpm_cg c;
                    c.w = w, c.dt = dt;
                    alpha = pn__armijo(pn__mpm_value, &c, nd, w->s.vsol, w->s.dir, E0, gd, 1, (pn_real)1e-10, w->s.vtry, &E1);
                }
                pn__mpm_mark(w, st, PN_MPM_STAGE_ENERGY);
                if ((stall = pn__mpm_lanes_stall(w, gd, E0, alpha, last_res <= 100 * o->newton_tol)) == 1) break;
                if (stall == 2 && alpha == 0) continue; /* again, in pn_real */
                if (alpha == 0) { /* no decrease: keep v, count it, stop this round */
                    st->line_search_failures++;
                    break;
                }
                pred = pn__mpm_model_norm(w, alpha);
                memcpy(w->s.vsol, w->s.vtry, sizeof(pn_real) * nd);
                if (alpha == 1 && !capped && pn__newton_done(dmax, dprev, vscale, &left)) { /* no solve to confirm it */
                    last_res = left / (w->desc.dx_m / dt);
                    /* the gradient at the solution, without the Hessian: the contact's
                       active set and the friction it records for the next step read it */
                    if (has_sep && (r = pn__mpm_objective(w, w->s.vsol, dt, 1, &E1)) != PN_OK) return r;
                    break;
                }
                dprev = alpha == 1 ? dmax : 0;
            }
            if (!has_sep || !pn__mpm_active_set(w, w->s.vsol, vscale)) break;
            if (round + 1 < o->contact_rounds) st->active_set_rounds++;
        }
    }
    st->newton_residual = PN__MAX(st->newton_residual, last_res);
    if (capped)
        return PN__FAIL(w, PN_ERROR_NOT_CONVERGED, "implicit step of %g s: the last linear solve stopped at cg_max = %d "
                            "short of cg_rel_tol %g, so Newton did not converge: raise cg_max or take a smaller step",
                            (double)dt, o->cg_max, (double)o->cg_rel_tol);
    if (!(last_res <= 100 * o->newton_tol))
        return PN__FAIL(w, PN_ERROR_NOT_CONVERGED, "implicit step of %g s: Newton stopped at max |dv| dt / dx = %.3g "
                            "(newton_tol %g, newton_max %d; %d line searches failed): a smaller step converges",
                            (double)dt, (double)last_res, (double)o->newton_tol, o->newton_max, st->line_search_failures);
    if (o->measure_force_error) pn__mpm_force_error(w, w->s.vsol, dt, st);
    pn__mpm_lin_record(w, st->cg_iters, st->newton_iters);
    pn__mpm_mark(w, st, PN_MPM_STAGE_LINEAR);
    r = pn__mpm_g2p(w, w->s.vsol, NULL, dt, st);
    if (r == PN_OK) r = pn__mpm_energy_guard(w, o, dt, st);
    pn__mpm_mark(w, st, PN_MPM_STAGE_G2P);
    if (r != PN_OK) return r;
    pn__mpm_friction_record(w, dt);
    pn__mpm_commit(w, dt, st);
    return PN_OK;
}

static pn_result pn__mpm_once(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *o, pn_mpm_stats *st) {
    return o->formulation == PN_MPM_FORMULATION_STRESS ? pn__mpm_stress_once(w, dt, o, st)
                                                       : pn__mpm_implicit_once(w, dt, o, st);
}

static void pn__mpm_backup(pn_mpm_world *w, int restore) {
    int d = w->dim, dd = d * d;
    size_t n = w->n;
#define PN__MPM_COPY(a, b, count, type) memcpy(restore ? w->a : w->b, restore ? w->b : w->a, sizeof(type) * (count))
    PN__MPM_COPY(x, s.bx, n * (size_t)d, pn_real);
    PN__MPM_COPY(v, s.bv, n * (size_t)d, pn_real);
    PN__MPM_COPY(C, s.bC, n * (size_t)dd, pn_real);
    PN__MPM_COPY(F, s.bF, n * (size_t)dd, pn_real);
    PN__MPM_COPY(h, s.bh, n, pn_real);
    PN__MPM_COPY(active, s.bactive, n, unsigned char);
    PN__MPM_COPY(s.lnode, s.blnode, restore ? w->s.bn_lag : w->s.n_lag, size_t);
    PN__MPM_COPY(s.lval, s.blval, restore ? w->s.bn_lag : w->s.n_lag, pn_real);
    if (restore) w->s.n_lag = w->s.bn_lag;
    else w->s.bn_lag = w->s.n_lag;
#undef PN__MPM_COPY
}

/* the counts of an implicit desc that are never negative (0: the default); the first that is,
   or NULL (max_halvings < 0 means no fallback, and is not among them) */
static const char *pn__mpm_negative_count(const pn_mpm_implicit_desc *o) {
    if (o->fixed_point_iters < 0) return "fixed_point_iters";
    if (o->newton_max < 0) return "newton_max";
    if (o->cg_max < 0) return "cg_max";
    if (o->contact_rounds < 0) return "contact_rounds";
    if (o->newton_budget < 0) return "newton_budget";
    if (o->sweeps_max < 0) return "sweeps_max";
    if (o->coarse_cg < 0) return "coarse_cg";
    return NULL;
}

/* pn_mpm_step_implicit's tries for the kit's substep fallback (pn__halve) */
typedef struct pn__mpm_retry {
    pn_mpm_world *w;
    const pn_mpm_implicit_desc *o;
    pn_real dt, cfl, t0;
    pn_mpm_stats *st, first;     /* the current try's stats; the first try's               */
    long steps0, culprit;
    size_t left0;
    int stale0, rec0, lin0, ctau0;
    char why[sizeof ((pn_mpm_world *)0)->error];
} pn__mpm_retry;

static pn_result pn__mpm_try(void *ctx, int n_sub) {
    pn__mpm_retry *t = (pn__mpm_retry *)ctx;
    pn_mpm_world *w = t->w;
    pn_mpm_stats *st = t->st;
    pn_result r = PN_OK;
    int s;
    if (n_sub == 1) { /* the whole step: it builds the new state aside and swaps it in */
        r = pn__mpm_once(w, t->dt, t->o, st);
        st->dt_over_cfl = t->cfl;
        return r;
    }
    pn__mpm_stats_clear(st, t->o->measure_force_error);
    for (s = 0; s < n_sub; ++s) {
        pn_mpm_stats sub;
        pn__mpm_stats_clear(&sub, t->o->measure_force_error);
        sub.solves = st->solves; /* numbered on through the substeps */
        r = pn__mpm_once(w, t->dt / (pn_real)n_sub, t->o, &sub);
        if (r != PN_OK) return r;
        pn__mpm_stats_add(st, &sub);
        st->solves = sub.solves;
    }
    st->substeps = n_sub;
    st->dt_over_cfl = t->cfl;
    w->time_s = t->t0 + t->dt;
    w->steps = t->steps0 + 1;
    return PN_OK;
}

static void pn__mpm_untry(void *ctx, int n_sub) {
    pn__mpm_retry *t = (pn__mpm_retry *)ctx;
    pn_mpm_world *w = t->w;
    if (n_sub > 1) pn__mpm_backup(w, 1); /* a failed whole step changed nothing but the models */
    pn__mpm_journal_undo(w);
    w->s.mg_stale = t->stale0, w->s.rec_ok = t->rec0, w->s.lin_mg = t->lin0;
    w->s.ctau_ok = t->ctau0, w->s.stau_committed = 0, w->s.stau_state = 0;
    if (n_sub > 1) w->time_s = t->t0, w->steps = t->steps0, w->left_total = t->left0;
}

static void pn__mpm_keep_first(void *ctx) {
    pn__mpm_retry *t = (pn__mpm_retry *)ctx;
    t->first = *t->st;
    t->culprit = t->w->error_particle;
    memcpy(t->why, t->w->error, sizeof t->why);
    pn__mpm_backup(t->w, 0); /* the substeps change the world: keep it (the whole step does not) */
}

static int pn__mpm_spent(void *ctx, int n_sub) { /* the Newton budget is spent */
    return n_sub > 1 && ((pn__mpm_retry *)ctx)->w->s.newton_left < 0;
}

/* The defaults of an implicit desc (zero fields), resolved here for pn_mpm_step_implicit and
   pn_coupled_step_implicit alike; the CG's differ (the coupled system needs more) */
static void pn__mpm_implicit_defaults(pn_mpm_implicit_desc *o, int cg_max, pn_real cg_rel_tol) {
    if (o->fixed_point_iters <= 0) o->fixed_point_iters = 1;
    if (o->newton_max <= 0) o->newton_max = 50;
    if (o->cg_max <= 0) o->cg_max = cg_max;
    if (!(o->newton_tol > 0)) o->newton_tol = (pn_real)1e-5;
    if (!(o->cg_rel_tol > 0)) o->cg_rel_tol = cg_rel_tol;
    if (o->contact_rounds <= 0) o->contact_rounds = 1;
    if (o->mg_levels == 0) o->mg_levels = PN__MPM_MG_MAX;
    if (o->max_halvings == 0) o->max_halvings = 3;
    if (o->max_halvings > 10) o->max_halvings = 10;
    if (o->coarse_cg <= 0) o->coarse_cg = 50;
    if (o->coarse_tol == 0) o->coarse_tol = (pn_real)1e-3; /* negative or NaN: refused */
}

/* the first drive (*load = 0) or load (*load = 1) acting now, or -1: implicit steps refuse them */
static int pn__mpm_drive_on(const pn_mpm_world *w, int *load) {
    int a;
    for (*load = 0, a = 0; a < w->s.n_drives; ++a)
        if (w->s.drives[a].on) return a;
    for (*load = 1, a = 0; a < w->s.n_loads; ++a)
        if (w->s.loads[a].on && w->s.loads[a].t_end > w->time_s) return a;
    return -1;
}

PN__DEF pn_result pn_mpm_step_implicit(pn_mpm_world *w, pn_real dt, const pn_mpm_implicit_desc *desc,
                                       pn_mpm_stats *stats) {
    pn_mpm_implicit_desc o;
    pn_mpm_stats st;
    pn_result r;
    pn_real cfl; /* the explicit bound, then dt over it */
    pn__mpm_retry t;
    pn__halving h;
    PN_ASSERT(w);
    w->error[0] = 0;
    if (!pn__finite(dt) || !(dt > 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_step_implicit: dt_s = %g must be finite and > 0", (double)dt);
    {
        int load, a = pn__mpm_drive_on(w, &load);
        if (a >= 0)
            return PN__FAIL(w, PN_ERROR_UNSUPPORTED, "pn_mpm_step_implicit: %s %d is on: drives and loads work with "
                                "explicit steps (pn_mpm_step_explicit)", load ? "load" : "drive", a);
    }
    memset(&o, 0, sizeof o);
    if (desc) o = *desc;
    if (pn__mpm_negative_count(&o))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_implicit_desc: %s must be >= 0 (0: the default)",
                            pn__mpm_negative_count(&o));
    if (!pn__finite(o.newton_tol) || !pn__finite(o.cg_rel_tol) || !pn__finite(o.cg_forcing_max) ||
        o.newton_tol < 0 || o.cg_rel_tol < 0 || o.cg_forcing_max < 0)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_implicit_desc: newton_tol, cg_rel_tol and cg_forcing_max "
                            "must be finite and >= 0 (0: the default)");
    pn__mpm_implicit_defaults(&o, 500, (pn_real)1e-3);
    if (o.linear_solver < PN_MPM_LINEAR_DEFAULT || o.linear_solver > PN_MPM_LINEAR_MULTIGRID || o.mg_levels < 0 ||
        o.mg_rebuild < 0 || o.mg_rebuild > 1)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_implicit_desc: linear_solver %d is not a "
                            "pn_mpm_linear_solver, mg_levels %d < 0 or mg_rebuild %d not 0 or 1", (int)o.linear_solver,
                            o.mg_levels, o.mg_rebuild);
    if (o.formulation < PN_MPM_FORMULATION_ENERGY || o.formulation > PN_MPM_FORMULATION_STRESS ||
        !pn__finite(o.sweep_tol) || o.sweep_tol < 0 || !pn__finite(o.coarse_tol) || o.coarse_tol < 0)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_implicit_desc: formulation %d is not a "
                            "pn_mpm_formulation, or sweep_tol %g or coarse_tol %g is not finite and >= 0",
                            (int)o.formulation, (double)o.sweep_tol, (double)o.coarse_tol);
    if (!pn__finite(o.energy_rise_tol) || !pn__finite(o.pnet_reuse_tol))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_implicit_desc: energy_rise_tol %g or pnet_reuse_tol %g "
                            "is not finite", (double)o.energy_rise_tol, (double)o.pnet_reuse_tol);
    if (!pn__finite(o.cell_relax) || !(o.cell_relax == 0 || (o.cell_relax >= 1 && o.cell_relax < 2)) ||
        o.stress_unknowns < PN_MPM_STRESS_PARTICLES || o.stress_unknowns > PN_MPM_STRESS_CELLS_THEN_PARTICLES)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_implicit_desc: cell_relax %g is not 0 (the "
                            "default) or in [1, 2), or stress_unknowns %d is not a pn_mpm_stress_unknowns",
                            (double)o.cell_relax, (int)o.stress_unknowns);
    if (o.sweeps_max <= 0) o.sweeps_max = 1000;
    if (!(o.sweep_tol > 0)) o.sweep_tol = (pn_real)1e-4;
    if (o.cell_relax == 0) o.cell_relax = o.anderson >= 0 ? 1 : (pn_real)1.8;
    if (o.formulation == PN_MPM_FORMULATION_STRESS) {
        int g;
        for (g = 0; g < w->n_groups; ++g)
            if (!pn__mpm_stress_ok(&w->groups[g].material))
                return PN__FAIL(w, PN_ERROR_UNSUPPORTED, "pn_mpm_implicit_desc: the stress formulation takes "
                                    "StVK-Hencky groups (elastic or Drucker-Prager) and Neo-Hookean snow groups (elastic "
                                    "or Cam-Clay); group %d is not one", g);
    }
    if (o.newton_budget <= 0) { /* the deepest level's full work: half of every level's in full */
        double b = (double)o.newton_max * o.fixed_point_iters * o.contact_rounds * (double)(1 << PN__MAX(o.max_halvings, 0));
        o.newton_budget = b < 1e9 ? (int)b : 1000000000;
    }
    w->s.newton_left = o.newton_budget;
    r = pn__mpm_check_state(w);
    if (r != PN_OK) return r;
    r = pn__mpm_alloc_implicit(w);
    if (r == PN_OK) r = pn__mpm_reuse_on(w, &o);
    if (r != PN_OK) return PN__FAIL(w, r, "pn_mpm_step_implicit: out of memory for the solver storage");
    if (pn_mpm_stable_dt(w, &cfl) == PN_OK) cfl = dt / cfl;
    else cfl = -1;
    pn__mpm_stats_clear(&st, o.measure_force_error);
    pn__mpm_journal_begin(w);
    memset(&t, 0, sizeof t);
    t.w = w, t.o = &o, t.dt = dt, t.cfl = cfl, t.st = &st;
    t.t0 = w->time_s, t.steps0 = w->steps, t.left0 = w->left_total;
    t.stale0 = w->s.mg_stale, t.rec0 = w->s.rec_ok, t.lin0 = w->s.lin_mg; /* what a failed call must also leave as it was */
    t.ctau0 = w->s.ctau_ok;
    h.ctx = &t, h.try_step = pn__mpm_try, h.undo = pn__mpm_untry, h.keep_first = pn__mpm_keep_first;
    h.stop = pn__mpm_spent;
    r = pn__halve(&h, o.max_halvings);
    if (r == PN_OK) {
        pn__mpm_tau_keep(w);
        if (stats) *stats = st;
        return PN_OK;
    }
    /* the world as it was; the message, culprit and stats of the first try (how it failed:
       cg_capped, line searches), and whether halving was tried */
    w->error_particle = t.culprit;
    memcpy(w->error, t.why, sizeof w->error);
    if (stats) *stats = t.first;
    if (o.max_halvings > 0)
        pn__append(w->error, sizeof w->error, w->s.newton_left < 0 ? " [and substeps until newton_budget was spent]"
                                                                 : " [also as 2^max_halvings substeps]");
    return r;
}

/* ======================================================================================
   >>advance: a frame in as many steps as the physics asks for.
   ====================================================================================== */

PN__DEF pn_result pn_mpm_advance(pn_mpm_world *w, pn_real frame_s, const pn_mpm_advance_desc *desc,
                                 pn_mpm_stats *stats) {
    pn_mpm_advance_desc a;
    pn_mpm_stats tot, st;
    pn_real done = 0, g2 = 0, courant, stable = 0;
    long steps = 0;
    int i, d;
    PN_ASSERT(w);
    d = w->dim;
    w->error[0] = 0;
    memset(&a, 0, sizeof a);
    if (desc) a = *desc;
    if (!pn__finite(frame_s) || !(frame_s > 0))
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_advance: frame_s = %g must be finite and > 0", (double)frame_s);
    if (a.integrator != PN_MPM_EXPLICIT && a.integrator != PN_MPM_IMPLICIT)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_advance_desc.integrator %d is not a pn_mpm_integrator",
                            (int)a.integrator);
    if (!pn__finite(a.max_step_s) || a.max_step_s < 0 || !pn__finite(a.courant) || a.courant < 0)
        return PN__FAIL(w, PN_ERROR_INVALID_ARGUMENT, "pn_mpm_advance_desc: max_step_s and courant must be finite "
                            "and >= 0 (0: the default)");
    courant = a.courant > 0 ? a.courant : 1;
    if (a.integrator == PN_MPM_IMPLICIT && !(a.max_step_s > 0)) a.max_step_s = (pn_real)1e-3;
    for (i = 0; i < d; ++i) g2 += w->desc.gravity[i] * w->desc.gravity[i];
    pn__mpm_stats_clear(&tot, 0);
    tot.substeps = 0;
    while (frame_s - done > (pn_real)1e-9 * frame_s) {
        pn_real dt, left = frame_s - done;
        pn_result r;
        if (a.integrator == PN_MPM_EXPLICIT) {
            if ((r = pn_mpm_stable_dt(w, &dt)) != PN_OK)
                return PN__FAIL(w, r, "pn_mpm_advance: no stable step (no group, or a non-finite state)");
            stable = dt;
            dt *= courant;
            if (a.max_step_s > 0) dt = PN__MIN(dt, a.max_step_s);
        } else { /* at most max_step_s, and short enough for the fastest particle and gravity */
            pn_real vmax = 0, reach = (pn_real)0.9 * w->desc.advection_limit * w->desc.dx_m;
            size_t p;
            for (p = 0; p < w->n; ++p) {
                pn_real v2 = 0;
                if (!w->active[p]) continue;
                for (i = 0; i < d; ++i) v2 += w->v[p * (size_t)d + (size_t)i] * w->v[p * (size_t)d + (size_t)i];
                vmax = PN__MAX(vmax, v2);
            }
            vmax = PN__SQRT(vmax);
            dt = a.max_step_s;
            if ((vmax + PN__SQRT(g2) * dt) * dt > reach) /* solve (vmax + |g| dt) dt = reach */
                dt = g2 > 0 ? 2 * reach / (vmax + PN__SQRT(vmax * vmax + 4 * PN__SQRT(g2) * reach)) : reach / vmax;
        }
        if (!(dt > 0) || !pn__finite(dt))
            return PN__FAIL(w, PN_ERROR_NONFINITE, "pn_mpm_advance: the step came out as %g s", (double)dt);
        if (left <= dt * (pn_real)1.0001) dt = left;
        else if (left < 2 * dt) dt = left / 2; /* no sliver of a last step */
        if (++steps > 1000000L)
            return PN__FAIL(w, PN_ERROR_STEP_TOO_LARGE, "pn_mpm_advance: a frame of %g s needs more than 1e6 steps of "
                                "%g s (a stiffer material than the frame rate allows explicitly: use the implicit integrator)",
                                (double)frame_s, (double)dt);
        r = a.integrator == PN_MPM_EXPLICIT ? pn_mpm_step_explicit(w, dt, &st) : pn_mpm_step_implicit(w, dt, a.implicit, &st);
        if (r != PN_OK) return r;
        if (a.integrator == PN_MPM_EXPLICIT) st.dt_over_cfl = dt / stable;
        pn__mpm_stats_add(&tot, &st);
        tot.solves += st.solves;
        tot.substeps += st.substeps;
        done += dt;
    }
    if (stats) *stats = tot;
    return PN_OK;
}

#ifndef PN_NO_FEM
/* ======================================================================================
   >>fem: linear triangles and tetrahedra. Element e with nodes n_0 .. n_d: F = Ds Dm^-1,
   Ds = [x_1 - x_0, ..., x_d - x_0], and the elastic part Fe = F Fp^-1 = Ds B with
   B = Dm^-1 Fp^-1, so Fe = sum_a x_a q_a^T with q_a the row a of B (a >= 1) and
   q_0 = -sum_a q_a: the same linear map from unknowns to F as the implicit MPM step's
   q = F^nT g. Force on node a: -V P q_a; stiffness block (a, b): V sum H[(j m),(k n)] q_am q_bn.
   ====================================================================================== */

#define PN__FEM_ALIGN(n) (((n) + 7) & ~(size_t)7)
#define PN__FEM_FAR ((pn_real)1e30) /* farther than anything (and a float) */
#define PN__FEM_PAIR_H(d) ((d) == 2 ? 36 : 144) /* >>fem self-contact: reals in a pair's Hessian */

typedef struct pn__fem {
    size_t nu;                   /* unknowns: dim per node, then dim per moving obstacle     */
    int n_mov, mov[PN_FEM_MAX_OBSTACLES]; /* moving obstacles, by index                       */
    size_t *perm, *iperm;        /* RCM: node at position k, position of node i              */
    size_t *fc, *rs;             /* skyline: first column and start of each row of L        */
    size_t nnz;
    pn_real *L;                  /* the Hessian, factored in place (lower, by rows)          */
    pn_real *xt, *xs, *g, *dir, *xtry; /* x~, the iterate, gradient, direction, a try          */
    pn_real *xlag;               /* where friction's normal force and directions are taken   */
    pn_real *A, *cgx, *cgz, *cgp, *cgq; /* self-contact beyond the profile: the unfactored matrix,
                                    CG's vectors                                           */
    double sky_mb, sky_gflop;    /* the skyline's storage and one factorization's cost      */
    /* >>fem sparse: the Hessian's lower triangle in d x d blocks by block row (a node in RCM
       position order, then the moving obstacles' rows, dense), columns ascending, the
       diagonal block last (its lower half used); its block incomplete Cholesky
       L D L^T on the same pattern */
    int sparse;                  /* this step's Hessian is in the blocks (PCG), not the skyline */
    int d;
    size_t *brs;                 /* start of each block row (n + PN_FEM_MAX_OBSTACLES + 1)   */
    int *bcol;                   /* block columns                                            */
    size_t nblk, bcap;           /* blocks of the node rows; room in bcol, bA, bL            */
    int brows;                   /* block rows the obstacle rows are laid out for (n + n_mov) */
    pn_real *bA, *bL, *bDi;      /* the Hessian's blocks, the factor's L, D^-1 per row       */
    pn_real *bT;                 /* the factorization's row of L D (one block per column)    */
    int *bmark;                  /* per block column: its position in the row being factored */
    long bmiss;                  /* Hessian entries outside the pattern (never: a bug)       */
    pn_real bshift;              /* the diagonal shift the last factorization needed        */
    /* >>fem sparse, the coarse level: aggregates of nodes (by block row), and per aggregate
       its rigid motions at the iterate (d translations, d(d-1)/2 rotations), orthonormal:
       the prolongation P; the coarse matrix P^T A P in a skyline (aggregates in RCM order) */
    int nm;                      /* modes per aggregate                                      */
    size_t nagg, cnc;            /* aggregates; coarse unknowns (nagg nm)                   */
    int *agg;                    /* per node row: its aggregate                              */
    size_t *abeg, *arow;         /* the rows of aggregate a: arow[abeg[a] .. abeg[a + 1])    */
    size_t *apos, *cfc, *crs;    /* per aggregate its coarse position; the coarse skyline    */
    pn_real *cL, *cv, *P;        /* coarse matrix (factored), coarse vector; d x nm per row  */
    pn_real *pt, *pz;            /* the V-cycle's fine vectors                               */
    int coarse;                  /* the coarse level is set up and factored for this matrix */
    pn_real omega;               /* the smoother's damping: omega (L D L^T)^-1               */
    int one_level;               /* benchmarks: PCG on the block IC(0) alone                */
    int *bedge, *bface;          /* the boundary's edges (node pairs, nbe) and 3D faces
                                    (node triples, nbf): the self-contact primitives        */
    size_t *bnode, nbe, nbf, nbn; /* the nodes on the boundary                               */
    size_t ntgt, nitem;          /* grid items: the targets of the nodes (2D edges, 3D faces),
                                    then (3D) the edges; nitem in all                       */
    pn_real *ebox;               /* per item: its box (lo, then hi; 3 reals each)           */
    pn_real *off;                /* side list: the Hessian blocks of pairs beyond the profile,
                                    PN__FEM_PAIR_H reals each                               */
    int *off_node;               /* their nodes (4 per pair, -1 past the pair's own)        */
    size_t n_off, cap_off;
    size_t *gstart, *gitem, gcap; /* the items' grid: CSR of item indices by cell (gcap cells) */
    pn_real glo[3], gcs;         /* its origin and cell size                                 */
    long gn[3];                  /* cells per axis                                           */
    pn_real *B, *q;              /* per point: Dm^-1 Fp^-1 (dd), q_a (d per element node)    */
    const pn_real *fext;         /* >>couple: nodal forces for the next explicit step (or NULL) */
    pn_real *eP, *eH;            /* per point: P (dd) and dP/dF (dd^2)                       */
    pn_real *pG, *phG, *pty, *F0; /* per point: lagged G, h_G; DP yield; the pass's F0       */
    pn_pnet_point *ppt;
    pn_real *bx, *bv, *bFp, *bh; /* the state before the step (restored on failure)         */
    pn_real bt;
    unsigned char *elast;        /* per point: needs det Fe > 0 (all but fixed corotated)    */
    pn_real *epsi;               /* per point: Psi (the threaded loop's output)              */
    int *estat;                  /* per point: what the threaded loop found (0: fine)        */
    pn_real al_k;                /* augmented Lagrangian stiffness of the obstacle unknowns  */
    pn_real al_lam[PN_FEM_MAX_OBSTACLES * 3], target[PN_FEM_MAX_OBSTACLES * 3];
    pn_real dt, t_end;           /* this step's dt and end time                              */
    pn_real dmin;                /* the smallest distance the last objective saw             */
    unsigned hflags;             /* the element Hessians' flags: PN_EVAL_PROJECT_PSD, or 0
                                    near a minimum (pn__fem_minimize)                       */
} pn__fem;

/* Element shapes. The reference simplex has its corners at 0 and the unit vectors of xi;
   in barycentric coordinates l (l_0 = 1 - sum xi, l_a = xi_a) the linear shape functions
   are N_a = l_a; the quadratic ones N_a = l_a (2 l_a - 1) at corner a and 4 l_a l_b at the
   node of edge (a, b), listed in Gmsh's order. Quadratic elements integrate at the points
   of the degree-2 rules (exact for the products of their strains at small strain): a
   triangle's 3 at l = (2/3, 1/6, 1/6) and its turns, weights 1/3; a tetrahedron's 4 at
   (a, b, b, b), a = (5 + 3 sqrt 5) / 20, b = (5 - sqrt 5) / 20, weights 1/4. Linear
   elements: one point, weight 1. */
static const int pn__fem_edge2[3][2] = {{0, 1}, {1, 2}, {2, 0}};
static const int pn__fem_edge3[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};
/* quadratic elements cut into linear ones through their nodes (corner pieces, then the
   middle: a triangle, or an octahedron cut along its 4 - 8 diagonal): where contact,
   obstacles and the stable step see them */
static const int pn__fem_sub2[4][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}, {3, 4, 5}};
static const int pn__fem_sub3[8][4] = {{0, 4, 6, 7}, {4, 1, 5, 9}, {6, 5, 2, 8}, {7, 9, 8, 3},
                                       {4, 8, 5, 6}, {4, 8, 6, 7}, {4, 8, 7, 9}, {4, 8, 9, 5}};
static const int pn__fem_sub1[4] = {0, 1, 2, 3};

static int pn__fem_nodes_of(int d, int order) { return order == 2 ? (d + 1) * (d + 2) / 2 : d + 1; }
static int pn__fem_points_of(int d, int order) { return order == 2 ? d + 1 : 1; }

/* the local node on the edge between corners a and b (order 2) */
static int pn__fem_edge_node(int d, int a, int b) {
    int k, ne = d == 2 ? 3 : 6;
    for (k = 0; k < ne; ++k) {
        const int *ed = d == 2 ? pn__fem_edge2[k] : pn__fem_edge3[k];
        if ((ed[0] == a && ed[1] == b) || (ed[0] == b && ed[1] == a)) return d + 1 + k;
    }
    return -1;
}

/* the linear pieces of an element: how many, and piece k's d + 1 local nodes */
static int pn__fem_nsub(const pn_fem_mesh *m) { return m->order == 2 ? (m->dim == 2 ? 4 : 8) : 1; }
static const int *pn__fem_sub(const pn_fem_mesh *m, int k) {
    return m->order != 2 ? pn__fem_sub1 : m->dim == 2 ? pn__fem_sub2[k] : pn__fem_sub3[k];
}

/* the weight of integration point k (its share of the element) and the reference gradients
   dN_a / dxi (a row of d per element node) there */
static pn_real pn__fem_ref_grad(int d, int order, int k, pn_real *dN) {
    int a, j, nn = pn__fem_nodes_of(d, order);
    pn_real l[4], dl[4][3];
    for (a = 0; a <= d; ++a) {
        for (j = 0; j < d; ++j) dl[a][j] = a == 0 ? -1 : (a - 1 == j);
        l[a] = d == 2 ? (a == k ? (pn_real)2 / 3 : (pn_real)1 / 6)
                      : (a == k ? (5 + 3 * PN__SQRT((pn_real)5)) / 20 : (5 - PN__SQRT((pn_real)5)) / 20);
    }
    if (order != 2) {
        for (a = 0; a < nn; ++a)
            for (j = 0; j < d; ++j) dN[a * d + j] = dl[a][j];
        return 1;
    }
    for (a = 0; a <= d; ++a)
        for (j = 0; j < d; ++j) dN[a * d + j] = (4 * l[a] - 1) * dl[a][j];
    for (a = d + 1; a < nn; ++a) {
        const int *ed = d == 2 ? pn__fem_edge2[a - d - 1] : pn__fem_edge3[a - d - 1];
        for (j = 0; j < d; ++j) dN[a * d + j] = 4 * (l[ed[0]] * dl[ed[1]][j] + l[ed[1]] * dl[ed[0]][j]);
    }
    return (pn_real)1 / (d + 1);
}

/* HRZ lumping (Hinton, Rock and Zienkiewicz 1976) of a quadratic element: each node's share
   of the mass in proportion to the consistent mass matrix's diagonal, int N_a^2: a
   triangle's corner 1/30 A, edge node 8/45 A, so 3/57 and 16/57 of the mass; a
   tetrahedron's 1/70 V and 8/105 V, so 1/36 and 4/27. (Row sums would give the corners a
   share <= 0.) */
static pn_real pn__fem_mass_share(int d, int order, int a) {
    if (order != 2) return (pn_real)1 / (d + 1);
    if (a <= d) return d == 2 ? (pn_real)3 / 57 : (pn_real)1 / 36;
    return d == 2 ? (pn_real)16 / 57 : (pn_real)4 / 27;
}

/* the Jacobian dx / dxi (row-major d x d) of point p's element at positions x */
static void pn__fem_jac(const pn_fem_mesh *m, size_t p, const pn_real *x, pn_real *J) {
    int d = m->dim, nn = m->nodes_per_element, a, i, j;
    const int *el = m->elem + (p / (size_t)m->points_per_element) * (size_t)nn;
    pn_real dN[30];
    pn__fem_ref_grad(d, m->order, (int)(p % (size_t)m->points_per_element), dN);
    for (i = 0; i < d * d; ++i) J[i] = 0;
    for (a = 0; a < nn; ++a)
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) J[i * d + j] += x[(size_t)el[a] * (size_t)d + (size_t)i] * dN[a * d + j];
}

/* signed volume of a simplex with edge matrix Ds: det / d! */
static pn_real pn__fem_volume(int d, const pn_real *Ds) { return pn_mat_det(d, Ds) / (d == 2 ? 2 : 6); }

/* records of w longs compared by their first `keys` (lexicographic) */
static int pn__fem_cmp_longs(const long *a, const long *b, int keys) {
    int i;
    for (i = 0; i < keys; ++i)
        if (a[i] != b[i]) return a[i] < b[i] ? -1 : 1;
    return 0;
}

static void pn__fem_swap_longs(long *a, long *b, int w) {
    int i;
    for (i = 0; i < w; ++i) {
        long t = a[i];
        a[i] = b[i], b[i] = t;
    }
}

/* heap sort of n records of w longs by their first `keys` (the loaders' (id, index) pairs,
   the boundary's node tuples): no allocation, n log n at worst */
static void pn__fem_sort_longs(long *a, size_t n, int w, int keys) {
    size_t i, start, end, W = (size_t)w;
    for (start = n / 2, end = n;;) {
        if (start > 0) --start; /* heapify, then pop */
        else {
            if (end-- <= 1) break;
            pn__fem_swap_longs(a, a + W * end, w);
        }
        for (i = start;;) { /* sift down */
            size_t c = 2 * i + 1;
            if (c >= end) break;
            if (c + 1 < end && pn__fem_cmp_longs(a + W * (c + 1), a + W * c, keys) > 0) c++;
            if (pn__fem_cmp_longs(a + W * i, a + W * c, keys) >= 0) break;
            pn__fem_swap_longs(a + W * i, a + W * c, w);
            i = c;
        }
    }
}

/* ======================================================================================
   >>fem-mesh: the structured mesh builder (pn_fem_grid_mesh): a box of cells, each split
   into triangles or Kuhn tetrahedra, cells kept by a user callback; a linear mesh made
   quadratic (pn_fem_quadratic_mesh).
   ====================================================================================== */

/* the 6 tetrahedra of a cube around its diagonal 0 - 7 (corners by bits x, y, z): conforming
   when every cube is split the same way (Freudenthal / Kuhn) */
static const int pn__fem_kuhn[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};

static int pn__fem_cell_kept(const pn_fem_grid *g, const int *c) {
    int a, in = 1;
    for (a = 0; a < g->dim; ++a) {
        pn_real lo = g->lo_m[a] + g->size_m[a] * c[a] / g->cells[a];
        pn_real hi = g->lo_m[a] + g->size_m[a] * (c[a] + 1) / g->cells[a], mid = (lo + hi) / 2;
        if (!(g->hole_size_m[a] > 0)) return 1;
        in &= mid > g->hole_lo_m[a] && mid < g->hole_lo_m[a] + g->hole_size_m[a];
    }
    return !in;
}

PN__DEF pn_result pn_fem_grid_mesh(const pn_fem_grid *g, pn_real *nodes, int *elements, size_t *n_nodes,
                                   size_t *n_elements) {
    int d, a, c[3] = {0, 0, 0}, np[3] = {1, 1, 1};
    size_t total = 1, ne = 0, nn = 0, k;
    int *map = NULL;
    if (!g || !n_nodes || !n_elements || (g->dim != 2 && g->dim != 3) ||
        (g->allocator.alloc == NULL) != (g->allocator.free == NULL))
        return PN_ERROR_INVALID_ARGUMENT;
    d = g->dim;
    for (a = 0; a < d; ++a) {
        if (g->cells[a] < 1 || g->cells[a] > 4096 || !(g->size_m[a] > 0) || !pn__finite(g->lo_m[a]) ||
            !pn__finite(g->size_m[a]) || !pn__finite(g->hole_lo_m[a]) || !pn__finite(g->hole_size_m[a]))
            return PN_ERROR_INVALID_ARGUMENT;
        np[a] = g->cells[a] + 1;
        total *= (size_t)np[a];
    }
    if (nodes) { /* number the nodes used by kept cells in grid order */
        map = (int *)pn_alloc(&g->allocator, sizeof(int) * total);
        if (!map) return PN_ERROR_OUT_OF_MEMORY;
        for (k = 0; k < total; ++k) map[k] = -1;
    }
    for (c[2] = 0; c[2] < (d == 3 ? g->cells[2] : 1); ++c[2])
        for (c[1] = 0; c[1] < g->cells[1]; ++c[1])
            for (c[0] = 0; c[0] < g->cells[0]; ++c[0]) {
                int corner[8], b, t;
                if (!pn__fem_cell_kept(g, c)) continue;
                for (b = 0; b < (1 << d); ++b) {
                    int i = c[0] + (b & 1), j = c[1] + (b >> 1 & 1), l = d == 3 ? c[2] + (b >> 2 & 1) : 0;
                    corner[b] = (int)(((size_t)l * (size_t)np[1] + (size_t)j) * (size_t)np[0] + (size_t)i);
                    if (map && map[corner[b]] < 0) {
                        map[corner[b]] = (int)nn;
                        nodes[nn * (size_t)d] = g->lo_m[0] + g->size_m[0] * i / g->cells[0];
                        nodes[nn * (size_t)d + 1] = g->lo_m[1] + g->size_m[1] * j / g->cells[1];
                        if (d == 3) nodes[nn * 3 + 2] = g->lo_m[2] + g->size_m[2] * l / g->cells[2];
                        nn++;
                    }
                }
                if (d == 2 && g->crossed) { /* a centre node, four triangles */
                    int mid = (int)nn;
                    if (map) { /* (the counting pass counts it below) */
                        nodes[nn * 2] = g->lo_m[0] + g->size_m[0] * (c[0] + (pn_real)0.5) / g->cells[0];
                        nodes[nn * 2 + 1] = g->lo_m[1] + g->size_m[1] * (c[1] + (pn_real)0.5) / g->cells[1];
                        nn++;
                    }
                    if (elements) {
                        static const int ring[4] = {0, 1, 3, 2}; /* counter-clockwise corners */
                        for (t = 0; t < 4; ++t) {
                            elements[(ne + (size_t)t) * 3] = map[corner[ring[t]]];
                            elements[(ne + (size_t)t) * 3 + 1] = map[corner[ring[(t + 1) % 4]]];
                            elements[(ne + (size_t)t) * 3 + 2] = mid;
                        }
                    }
                    ne += 4;
                } else if (d == 2) { /* the diagonal alternates (a symmetric mesh for symmetric loads) */
                    int alt = (c[0] + c[1]) & 1;
                    int tri[2][3];
                    if (!alt) {
                        tri[0][0] = corner[0], tri[0][1] = corner[1], tri[0][2] = corner[3];
                        tri[1][0] = corner[0], tri[1][1] = corner[3], tri[1][2] = corner[2];
                    } else {
                        tri[0][0] = corner[0], tri[0][1] = corner[1], tri[0][2] = corner[2];
                        tri[1][0] = corner[1], tri[1][1] = corner[3], tri[1][2] = corner[2];
                    }
                    for (t = 0; t < 2; ++t, ++ne)
                        if (elements)
                            for (b = 0; b < 3; ++b) elements[ne * 3 + (size_t)b] = map[tri[t][b]];
                } else {
                    for (t = 0; t < 6; ++t, ++ne)
                        if (elements) {
                            int *el = elements + ne * 4;
                            for (b = 0; b < 4; ++b) el[b] = map[corner[pn__fem_kuhn[t][b]]];
                        }
                }
            }
    if (map) {
        pn_free(&g->allocator, map);
    } else {
        int *used = (int *)pn_alloc(&g->allocator, sizeof(int) * total); /* count the used nodes */
        if (!used) return PN_ERROR_OUT_OF_MEMORY;
        memset(used, 0, sizeof(int) * total);
        for (c[2] = 0; c[2] < (d == 3 ? g->cells[2] : 1); ++c[2])
            for (c[1] = 0; c[1] < g->cells[1]; ++c[1])
                for (c[0] = 0; c[0] < g->cells[0]; ++c[0]) {
                    int b;
                    if (!pn__fem_cell_kept(g, c)) continue;
                    for (b = 0; b < (1 << d); ++b) {
                        size_t id = ((size_t)(d == 3 ? c[2] + (b >> 2 & 1) : 0) * (size_t)np[1] + (size_t)(c[1] + (b >> 1 & 1))) *
                                        (size_t)np[0] + (size_t)(c[0] + (b & 1));
                        if (!used[id]) used[id] = 1, nn++;
                    }
                    nn += d == 2 && g->crossed; /* the centre */
                }
        pn_free(&g->allocator, used);
    }
    if (nodes && elements) /* orient every element positively */
        for (k = 0; k < ne; ++k) {
            int *el = elements + k * (size_t)(d + 1), i, b, tmp;
            pn_real Ds[9];
            for (b = 1; b <= d; ++b)
                for (i = 0; i < d; ++i) Ds[i * d + b - 1] = nodes[(size_t)el[b] * (size_t)d + i] - nodes[(size_t)el[0] * (size_t)d + i];
            if (pn_mat_det(d, Ds) < 0) tmp = el[1], el[1] = el[2], el[2] = tmp;
        }
    *n_nodes = nn;
    *n_elements = ne;
    return PN_OK;
}

/* the quadratic mesh of a linear one: every element's edges as records (lower node, upper
   node, element, local edge), sorted; each run of one edge gets the next new node */
PN__DEF pn_result pn_fem_quadratic_mesh(int dim, const pn_real *nodes, size_t n_nodes, const int *elements,
                                        size_t n_elements, const pn_allocator *al, pn_real *nodes_out, int *elements_out,
                                        size_t *n_nodes_out) {
    static const pn_allocator none = {NULL, NULL, NULL};
    int dp = dim + 1, ned = dim == 2 ? 3 : 6, nn = (dim + 1) * (dim + 2) / 2, k, i;
    size_t ne = n_elements * (size_t)ned, e, q, j, nnew = 0;
    long *rec;
    if ((dim != 2 && dim != 3) || !elements || !n_nodes_out || (nodes_out && !nodes) || n_elements < 1)
        return PN_ERROR_INVALID_ARGUMENT;
    if (!al) al = &none;
    if ((al->alloc == NULL) != (al->free == NULL)) return PN_ERROR_INVALID_ARGUMENT;
    for (e = 0; e < n_elements * (size_t)dp; ++e)
        if (elements[e] < 0 || (size_t)elements[e] >= n_nodes) return PN_ERROR_INVALID_ARGUMENT;
    rec = (long *)pn_alloc(al, sizeof(long) * 4 * ne);
    if (!rec) return PN_ERROR_OUT_OF_MEMORY;
    for (e = 0; e < n_elements; ++e)
        for (k = 0; k < ned; ++k) {
            const int *ed = dim == 2 ? pn__fem_edge2[k] : pn__fem_edge3[k];
            long u = elements[e * (size_t)dp + (size_t)ed[0]], v = elements[e * (size_t)dp + (size_t)ed[1]], *r = rec + 4 * (e * (size_t)ned + (size_t)k);
            r[0] = PN__MIN(u, v), r[1] = PN__MAX(u, v), r[2] = (long)e, r[3] = k;
        }
    pn__fem_sort_longs(rec, ne, 4, 2);
    for (q = 0; q < ne; q = j, ++nnew) {
        size_t id = n_nodes + nnew;
        for (j = q; j < ne && rec[4 * j] == rec[4 * q] && rec[4 * j + 1] == rec[4 * q + 1]; ++j)
            if (elements_out) elements_out[(size_t)rec[4 * j + 2] * (size_t)nn + (size_t)dp + (size_t)rec[4 * j + 3]] = (int)id;
        if (nodes_out)
            for (i = 0; i < dim; ++i)
                nodes_out[id * (size_t)dim + (size_t)i] =
                    (nodes[(size_t)rec[4 * q] * (size_t)dim + (size_t)i] + nodes[(size_t)rec[4 * q + 1] * (size_t)dim + (size_t)i]) / 2;
    }
    pn_free(al, rec);
    if (nodes_out) memcpy(nodes_out, nodes, sizeof(pn_real) * n_nodes * (size_t)dim);
    if (elements_out)
        for (e = 0; e < n_elements; ++e)
            for (k = 0; k < dp; ++k) elements_out[e * (size_t)nn + (size_t)k] = elements[e * (size_t)dp + (size_t)k];
    *n_nodes_out = n_nodes + nnew;
    return n_nodes + nnew > 0x7fffffff ? PN_ERROR_CAPACITY : PN_OK;
}

/* ======================================================================================
   >>fem-create: a mesh from nodes and elements (pn_fem_create, pn_fem_destroy,
   pn_fem_error): the reference shapes, masses, the boundary (edges, faces), the RCM order
   and the implicit solver's storage; a group's implicit energy.
   ====================================================================================== */

/* Reverse Cuthill-McKee order of the node graph (a skyline of small profile for the
   Cholesky factor): breadth first from a node of least degree, neighbours by degree,
   reversed; each connected piece in turn. Node i's neighbours: adj[beg[i] .. end[i]). */
static void pn__fem_rcm(size_t n, const size_t *beg, const size_t *end, const size_t *adj, size_t *perm,
                        unsigned char *seen, size_t *deg) {
    size_t head = 0, tail = 0, i, k;
    for (i = 0; i < n; ++i) seen[i] = 0, deg[i] = end[i] - beg[i];
    while (tail < n) {
        size_t start = n;
        for (i = 0; i < n; ++i)
            if (!seen[i] && (start == n || deg[i] < deg[start])) start = i;
        perm[tail++] = start;
        seen[start] = 1;
        while (head < tail) {
            size_t u = perm[head++], first = tail;
            for (k = beg[u]; k < end[u]; ++k)
                if (!seen[adj[k]]) seen[adj[k]] = 1, perm[tail++] = adj[k];
            for (i = first + 1; i < tail; ++i) { /* insertion sort of the new ones by degree */
                size_t v = perm[i], j = i;
                while (j > first && (deg[perm[j - 1]] > deg[v] || (deg[perm[j - 1]] == deg[v] && perm[j - 1] > v))) {
                    perm[j] = perm[j - 1];
                    --j;
                }
                perm[j] = v;
            }
        }
    }
    for (i = 0; i < n / 2; ++i) k = perm[i], perm[i] = perm[n - 1 - i], perm[n - 1 - i] = k;
}

PN__DEF void pn_fem_destroy(pn_fem_mesh *m) {
    pn__fem *s;
    const pn_allocator *al;
    if (!m) return;
    al = &m->desc.allocator;
    s = (pn__fem *)m->impl;
    if (s) {
        pn_free(al, s->perm);
        pn_free(al, s->fc);
        pn_free(al, s->L);
        pn_free(al, s->xt);
        pn_free(al, s->B);
        pn_free(al, s->ppt);
        pn_free(al, s->elast);
        pn_free(al, s->estat);
        pn_free(al, s->bx);
        pn_free(al, s->A);
        pn_free(al, s->brs);
        pn_free(al, s->bcol);
        pn_free(al, s->bA);
        pn_free(al, s->bL);
        pn_free(al, s->bDi);
        pn_free(al, s->bmark);
        pn_free(al, s->agg);
        pn_free(al, s->abeg);
        pn_free(al, s->cL);
        pn_free(al, s->P);
        pn_free(al, s->bedge);
        pn_free(al, s->bface);
        pn_free(al, s->bnode);
        pn_free(al, s->ebox);
        pn_free(al, s->off);
        pn_free(al, s->off_node);
        pn_free(al, s->gstart);
        pn_free(al, s);
    }
    pn_free(al, m->x);
    pn_free(al, m->elem);
    pn_free(al, m->fixed);
    pn_free(al, m);
}

PN__DEF const char *pn_fem_error(const pn_fem_mesh *m) { return m ? m->error : ""; }

static void pn__fem_sort3(int *v, int n) { /* n <= 3 ints, ascending */
    int i, j;
    for (i = 1; i < n; ++i)
        for (j = i; j > 0 && v[j - 1] > v[j]; --j) {
            int t = v[j];
            v[j] = v[j - 1], v[j - 1] = t;
        }
}

/* the arrays of the solver: one block per type (freed in pn_fem_destroy) */
static pn_result pn__fem_alloc_solver(pn_fem_mesh *m) {
    const pn_allocator *al = &m->desc.allocator;
    int d = m->dim, dd = d * d, nn = m->nodes_per_element;
    size_t n = m->n_nodes, ne = m->n_elems, np = m->n_points, nu = n * (size_t)d + (size_t)(PN_FEM_MAX_OBSTACLES * d), i, k, e;
    size_t *xadj, *adj, *deg, *cnt;
    unsigned char *seen;
    pn__fem *s = (pn__fem *)pn_alloc(al, sizeof(pn__fem));
    if (!s) return PN_ERROR_OUT_OF_MEMORY;
    memset(s, 0, sizeof *s);
    m->impl = s;
    s->hflags = PN_EVAL_PROJECT_PSD; /* every evaluation but Newton's whole-Hessian tries */
    s->perm = (size_t *)pn_alloc(al, sizeof(size_t) * 2 * n);
    s->fc = (size_t *)pn_alloc(al, sizeof(size_t) * (2 * nu + 1));
    s->xt = (pn_real *)pn_alloc(al, sizeof(pn_real) * (11 * PN__FEM_ALIGN(nu)));
    s->B = (pn_real *)pn_alloc(al, sizeof(pn_real) * np * (size_t)(dd + d * nn + dd + dd * dd + dd + 1 + 1 + dd + 1));
    s->estat = (int *)pn_alloc(al, sizeof(int) * (np + 1));
    s->ppt = (pn_pnet_point *)pn_alloc(al, sizeof(pn_pnet_point) * np);
    s->elast = (unsigned char *)pn_alloc(al, np);
    s->bx = (pn_real *)pn_alloc(al, sizeof(pn_real) * (2 * n * (size_t)d + np * (size_t)(dd + 1)));
    if (!s->perm || !s->fc || !s->xt || !s->B || !s->ppt || !s->elast || !s->bx || !s->estat) return PN_ERROR_OUT_OF_MEMORY;
    s->bv = s->bx + n * (size_t)d;
    s->bFp = s->bv + n * (size_t)d;
    s->bh = s->bFp + np * (size_t)dd;
    s->iperm = s->perm + n;
    s->rs = s->fc + nu;
    s->g = s->xt + PN__FEM_ALIGN(nu);
    s->dir = s->g + PN__FEM_ALIGN(nu);
    s->xtry = s->dir + PN__FEM_ALIGN(nu);
    s->xs = s->xtry + PN__FEM_ALIGN(nu);
    s->xlag = s->xs + PN__FEM_ALIGN(nu);
    s->cgx = s->xlag + PN__FEM_ALIGN(nu);
    s->cgz = s->cgx + PN__FEM_ALIGN(nu);
    s->cgp = s->cgz + PN__FEM_ALIGN(nu);
    s->cgq = s->cgp + PN__FEM_ALIGN(nu);
    s->q = s->B + np * (size_t)dd;
    s->eP = s->q + np * (size_t)(d * nn);
    s->eH = s->eP + np * (size_t)dd;
    s->pG = s->eH + np * (size_t)(dd * dd);
    s->phG = s->pG + np * (size_t)dd;
    s->pty = s->phG + np;
    s->F0 = s->pty + np;
    s->epsi = s->F0 + np * (size_t)dd;
    /* node graph (CSR) for the ordering: temporary */
    xadj = (size_t *)pn_alloc(al, sizeof(size_t) * (n + 1));
    cnt = (size_t *)pn_alloc(al, sizeof(size_t) * (n + 1));
    adj = (size_t *)pn_alloc(al, sizeof(size_t) * (ne * (size_t)(nn * (nn - 1)) + 1));
    deg = (size_t *)pn_alloc(al, sizeof(size_t) * (n + 1));
    seen = (unsigned char *)pn_alloc(al, n + 1);
    if (!xadj || !adj || !deg || !seen || !cnt) {
        pn_free(al, xadj), pn_free(al, adj), pn_free(al, deg), pn_free(al, seen), pn_free(al, cnt);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    memset(cnt, 0, sizeof(size_t) * (n + 1));
    for (e = 0; e < ne; ++e)
        for (i = 0; i < (size_t)nn; ++i) cnt[m->elem[e * (size_t)nn + i]] += (size_t)(nn - 1);
    xadj[0] = 0;
    for (i = 0; i < n; ++i) xadj[i + 1] = xadj[i] + cnt[i];
    for (i = 0; i < n; ++i) cnt[i] = xadj[i];
    for (e = 0; e < ne; ++e) /* with repeats: RCM only needs the neighbour sets */
        for (i = 0; i < (size_t)nn; ++i)
            for (k = 0; k < (size_t)nn; ++k)
                if (k != i) adj[cnt[m->elem[e * (size_t)nn + i]]++] = (size_t)m->elem[e * (size_t)nn + k];
    for (i = 0; i < n; ++i) { /* drop repeats: node i's neighbours are adj[xadj[i] .. cnt[i]) */
        size_t w = xadj[i], r, j;
        for (r = xadj[i]; r < cnt[i]; ++r) {
            for (j = xadj[i]; j < w && adj[j] != adj[r]; ++j) {}
            if (j == w) adj[w++] = adj[r];
        }
        cnt[i] = w;
    }
    pn__fem_rcm(n, xadj, cnt, adj, s->perm, seen, deg);
    for (i = 0; i < n; ++i) s->iperm[s->perm[i]] = i;
    /* skyline of the node rows (then the obstacle rows, full): first column per dof row */
    for (i = 0; i < n; ++i) {
        size_t pos = s->iperm[i], lo = pos, c;
        for (k = xadj[i]; k < cnt[i]; ++k) lo = PN__MIN(lo, s->iperm[adj[k]]);
        for (c = 0; c < (size_t)d; ++c) s->fc[pos * (size_t)d + c] = lo * (size_t)d;
    }
    for (k = n * (size_t)d; k < nu; ++k) s->fc[k] = 0;
    s->nnz = 0;
    for (k = 0; k < nu; ++k) s->rs[k] = s->nnz, s->nnz += k - s->fc[k] + 1;
    s->rs[nu] = s->nnz;
    { /* what the skyline (allocated at its first use) would take: L and the copy CG needs, and
         a factorization's multiply-adds, sum over rows of the row's length squared / 2 */
        double fl = 0;
        for (k = 0; k < n * (size_t)d; ++k) fl += 0.5 * (double)(k - s->fc[k] + 1) * (double)(k - s->fc[k] + 1);
        s->sky_mb = 2.0 * (double)s->nnz * sizeof(pn_real) / 1e6, s->sky_gflop = 2 * fl / 1e9;
    }
    /* the block pattern of the node rows (>>fem sparse): row at position p holds the
       neighbours before it, then p */
    s->d = d;
    s->brs = (size_t *)pn_alloc(al, sizeof(size_t) * (n + PN_FEM_MAX_OBSTACLES + 1));
    s->nblk = n;
    for (i = 0; i < n; ++i)
        for (k = xadj[i]; k < cnt[i]; ++k) s->nblk += s->iperm[adj[k]] < s->iperm[i];
    s->bcap = s->nblk;
    s->bcol = (int *)pn_alloc(al, sizeof(int) * s->bcap);
    if (!s->brs || !s->bcol) {
        pn_free(al, xadj), pn_free(al, adj), pn_free(al, deg), pn_free(al, seen), pn_free(al, cnt);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    s->brs[0] = 0;
    for (k = 0; k < n; ++k) {
        size_t i0 = s->perm[k], w = 0, r, c;
        int *row;
        for (r = xadj[i0]; r < cnt[i0]; ++r) w += s->iperm[adj[r]] < k;
        s->brs[k + 1] = s->brs[k] + w + 1;
        row = s->bcol + s->brs[k];
        for (w = 0, r = xadj[i0]; r < cnt[i0]; ++r)
            if (s->iperm[adj[r]] < k) {
                int v = (int)s->iperm[adj[r]];
                for (c = w++; c > 0 && row[c - 1] > v; --c) row[c] = row[c - 1]; /* insertion: rows are short */
                row[c] = v;
            }
        row[w] = (int)k;
    }
    s->brows = (int)n;
    pn_free(al, xadj), pn_free(al, adj), pn_free(al, deg), pn_free(al, seen), pn_free(al, cnt);
    { /* the boundary: the sides (2D edges, 3D faces) of one element only, by their sorted
         corners; each side's facets (itself; order 2: the 2 segments or 4 triangles through
         its nodes); then (3D) the facets' edges. Sorted node tuples, counted. */
        int w = d, nsd = d + 1, W = d + 2, nfs = m->order == 2 ? (d == 2 ? 2 : 4) : 1, sv[6], c0;
        size_t ns = (size_t)nsd * ne, q, j, nb = 0, nfc;
        long *key = (long *)pn_alloc(al, sizeof(long) * ((size_t)W * ns + 1)), *fac;
        unsigned char *on = (unsigned char *)pn_alloc(al, n);
        if (!key || !on) {
            pn_free(al, key), pn_free(al, on);
            return PN_ERROR_OUT_OF_MEMORY;
        }
        for (e = 0; e < ne; ++e)
            for (i = 0; i < (size_t)nsd; ++i) { /* side i: all corners but corner i */
                int c = 0, a0;
                long *kr = key + (size_t)W * (e * (size_t)nsd + i);
                for (a0 = 0; a0 < nsd; ++a0)
                    if ((size_t)a0 != i) sv[c++] = m->elem[e * (size_t)nn + (size_t)a0];
                pn__fem_sort3(sv, w);
                for (c = 0; c < w; ++c) kr[c] = sv[c];
                kr[w] = (long)e, kr[w + 1] = (long)i;
            }
        pn__fem_sort_longs(key, ns, W, w);
        for (q = 0; q < ns; q = j) {
            for (j = q + 1; j < ns && !pn__fem_cmp_longs(key + (size_t)W * j, key + (size_t)W * q, w); ++j) {}
            if (j - q == 1) { /* a boundary side: compacted to the front */
                for (c0 = 0; c0 < W; ++c0) key[(size_t)W * nb + (size_t)c0] = key[(size_t)W * q + (size_t)c0];
                nb++;
            }
        }
        nfc = nb * (size_t)nfs;
        fac = (long *)pn_alloc(al, sizeof(long) * ((size_t)w * nfc + 6 * nfc + 1));
        if (!fac) {
            pn_free(al, key), pn_free(al, on);
            return PN_ERROR_OUT_OF_MEMORY;
        }
        for (q = 0; q < nb; ++q) {
            const long *kr = key + (size_t)W * q;
            const int *el = m->elem + (size_t)kr[w] * (size_t)nn;
            int lc[3], c = 0, a0, f, t;
            long *fr = fac + (size_t)w * (size_t)nfs * q;
            for (a0 = 0; a0 < nsd; ++a0)
                if (a0 != (int)kr[w + 1]) lc[c++] = a0;
            if (m->order != 2) {
                for (c = 0; c < w; ++c) fr[c] = kr[c];
                continue;
            }
            if (d == 2) { /* corner, edge node, corner: 2 segments */
                int mid = pn__fem_edge_node(2, lc[0], lc[1]);
                int seg[2][2] = {{lc[0], mid}, {mid, lc[1]}};
                for (f = 0; f < 2; ++f) {
                    sv[0] = el[seg[f][0]], sv[1] = el[seg[f][1]];
                    pn__fem_sort3(sv, 2);
                    fr[2 * f] = sv[0], fr[2 * f + 1] = sv[1];
                }
            } else { /* 3 corners and 3 edge nodes: 4 triangles */
                int m01 = pn__fem_edge_node(3, lc[0], lc[1]), m12 = pn__fem_edge_node(3, lc[1], lc[2]);
                int m20 = pn__fem_edge_node(3, lc[2], lc[0]);
                int tri[4][3] = {{lc[0], m01, m20}, {m01, lc[1], m12}, {m20, m12, lc[2]}, {m01, m12, m20}};
                for (f = 0; f < 4; ++f) {
                    for (t = 0; t < 3; ++t) sv[t] = el[tri[f][t]];
                    pn__fem_sort3(sv, 3);
                    for (t = 0; t < 3; ++t) fr[3 * f + t] = sv[t];
                }
            }
        }
        pn_free(al, key);
        key = fac, nb = nfc;
        if (d == 2) s->nbe = nb;
        else { /* 3D: the faces' edges after them, sorted, once each */
            long *ek = key + 3 * nb;
            s->nbf = nb;
            for (q = 0; q < nb; ++q)
                for (c0 = 0; c0 < 3; ++c0) {
                    long u = key[3 * q + (size_t)c0], v = key[3 * q + (size_t)(c0 + 1) % 3];
                    ek[2 * (3 * q + (size_t)c0)] = PN__MIN(u, v), ek[2 * (3 * q + (size_t)c0) + 1] = PN__MAX(u, v);
                }
            pn__fem_sort_longs(ek, 3 * nb, 2, 2);
            for (q = 0; q < 3 * nb; q = j) {
                for (j = q + 1; j < 3 * nb && !pn__fem_cmp_longs(ek + 2 * j, ek + 2 * q, 2); ++j) {}
                ek[2 * s->nbe] = ek[2 * q], ek[2 * s->nbe + 1] = ek[2 * q + 1], s->nbe++;
            }
        }
        s->ntgt = d == 2 ? s->nbe : s->nbf;
        s->nitem = s->ntgt + (d == 3 ? s->nbe : 0);
        s->bedge = (int *)pn_alloc(al, sizeof(int) * (2 * s->nbe + 1));
        s->bface = (int *)pn_alloc(al, sizeof(int) * (3 * s->nbf + 1));
        s->bnode = (size_t *)pn_alloc(al, sizeof(size_t) * (n + 1));
        s->ebox = (pn_real *)pn_alloc(al, sizeof(pn_real) * (6 * s->nitem + 1));
        s->cap_off = (d == 2 ? 8 : 2) * nb + 64; /* pairs, by boundary sides; grown when a step needs more */
        s->off = (pn_real *)pn_alloc(al, sizeof(pn_real) * PN__FEM_PAIR_H(d) * s->cap_off);
        s->off_node = (int *)pn_alloc(al, sizeof(int) * 4 * s->cap_off);
        s->gcap = 4 * s->nitem + 16;
        s->gstart = (size_t *)pn_alloc(al, sizeof(size_t) * (s->gcap + 1 + (size_t)(1 << d) * s->nitem + 4));
        s->gitem = s->gstart ? s->gstart + s->gcap + 1 : NULL;
        if (!s->bedge || !s->bface || !s->bnode || !s->ebox || !s->off || !s->off_node || !s->gstart) {
            pn_free(al, key), pn_free(al, on);
            return PN_ERROR_OUT_OF_MEMORY;
        }
        memset(on, 0, n);
        for (q = 0; q < nb * (size_t)w; ++q) on[key[q]] = 1;
        if (d == 2)
            for (q = 0; q < 2 * s->nbe; ++q) s->bedge[q] = (int)key[q];
        else {
            for (q = 0; q < 3 * s->nbf; ++q) s->bface[q] = (int)key[q];
            for (q = 0; q < 2 * s->nbe; ++q) s->bedge[q] = (int)key[3 * nb + q];
        }
        for (q = 0; q < n; ++q)
            if (on[q]) s->bnode[s->nbn++] = q;
        pn_free(al, key), pn_free(al, on);
    }
    return PN_OK;
}

PN__DEF pn_result pn_fem_create(const pn_fem_desc *desc, pn_fem_mesh **out, char *why, size_t why_cap) {
    pn_fem_mesh *m;
    const pn_allocator *al;
    int d, dd, dp, g, nn, nq;
    size_t n, ne, np, i, e;
    pn_real lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0}, diag = 0, emax = 0, esum = 0;
    long nedge = 0;
    pn_result r;
    if (why && why_cap) why[0] = 0;
    if (!desc || !out) return PN_ERROR_INVALID_ARGUMENT;
    *out = NULL;
    d = desc->dim;
    if (!pn__dim_ok(d)) {
        pn__msg(why, why_cap, "pn_fem_desc.dim is %d: 2 or 3 (and not compiled out by PN_NO_2D / PN_NO_3D)", d);
        return PN_ERROR_DIMENSION;
    }
    if (desc->order < 0 || desc->order > 2) {
        pn__msg(why, why_cap, "pn_fem_desc.order is %d: 1 (linear elements, 0 says the same) or 2 (quadratic)", desc->order);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    dd = d * d, dp = d + 1, n = desc->n_nodes, ne = desc->n_elements;
    nn = pn__fem_nodes_of(d, desc->order), nq = pn__fem_points_of(d, desc->order), np = ne * (size_t)nq;
    if (!desc->rest_m || !desc->elements || n < (size_t)nn || ne < 1 || n > 0x7fffffff) {
        pn__msg(why, why_cap, "pn_fem_desc: rest_m and elements are required, with at least %d nodes and one element "
                    "(fewer than 2^31 nodes)", nn);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    if (!desc->groups || desc->n_groups < 1 || desc->n_groups > PN_FEM_MAX_GROUPS) {
        pn__msg(why, why_cap, "pn_fem_desc.n_groups is %d: 1 .. %d groups are needed", desc->n_groups, PN_FEM_MAX_GROUPS);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    if ((desc->allocator.alloc == NULL) != (desc->allocator.free == NULL)) {
        pn__msg(why, why_cap, "pn_fem_desc.allocator: set both alloc and free, or neither");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    for (i = 0; i < 3; ++i)
        if (!pn__finite(desc->gravity[i])) {
            pn__msg(why, why_cap, "pn_fem_desc.gravity[%d] is not finite", (int)i);
            return PN_ERROR_NONFINITE;
        }
    if (!(desc->contact_distance_m >= 0) || !pn__finite(desc->contact_distance_m) || !(desc->contact_stiffness >= 0) ||
        !pn__finite(desc->contact_stiffness) || !(desc->friction_velocity_m_s >= 0) || !pn__finite(desc->friction_velocity_m_s)) {
        pn__msg(why, why_cap, "pn_fem_desc: contact_distance_m, contact_stiffness and friction_velocity_m_s must be finite "
                    "and >= 0");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    for (g = 0; g < desc->n_groups; ++g) {
        const char *mw = NULL;
        if (pn__material_check_why(&desc->groups[g].material, &mw) != PN_OK) {
            pn__msg(why, why_cap, "pn_fem_desc.groups[%d].material: %s", g, mw ? mw : "invalid");
            return PN_ERROR_INVALID_PARAMETER;
        }
        if (!(desc->groups[g].density_kg_m3 > 0) || !pn__finite(desc->groups[g].density_kg_m3)) {
            pn__msg(why, why_cap, "pn_fem_desc.groups[%d].density_kg_m3 must be positive and finite", g);
            return PN_ERROR_INVALID_ARGUMENT;
        }
    }
    for (i = 0; i < n * (size_t)d; ++i)
        if (!pn__finite(desc->rest_m[i])) {
            pn__msg(why, why_cap, "node %lu: coordinate %d is not finite", (unsigned long)(i / (size_t)d), (int)(i % (size_t)d));
            return PN_ERROR_NONFINITE;
        }
    for (i = 0; i < n; ++i)
        for (g = 0; g < d; ++g) {
            pn_real c = desc->rest_m[i * (size_t)d + (size_t)g];
            lo[g] = i ? PN__MIN(lo[g], c) : c, hi[g] = i ? PN__MAX(hi[g], c) : c;
        }
    for (g = 0; g < d; ++g) diag += (hi[g] - lo[g]) * (hi[g] - lo[g]);
    diag = PN__SQRT(diag);
    for (e = 0; e < ne; ++e) {
        const int *el = desc->elements + e * (size_t)nn;
        pn_real Ds[9], vol, lmax = 0;
        int a, b;
        for (a = 0; a < nn; ++a) {
            if (el[a] < 0 || (size_t)el[a] >= n) {
                pn__msg(why, why_cap, "element %lu: node index %d is out of range (%lu nodes)", (unsigned long)e, el[a],
                            (unsigned long)n);
                return PN_ERROR_INVALID_ARGUMENT;
            }
            for (b = 0; b < a; ++b)
                if (el[a] == el[b]) {
                    pn__msg(why, why_cap, "element %lu: node %d appears twice", (unsigned long)e, el[a]);
                    return PN_ERROR_INVALID_ARGUMENT;
                }
        }
        if (desc->element_group && (desc->element_group[e] < 0 || desc->element_group[e] >= desc->n_groups)) {
            pn__msg(why, why_cap, "element %lu: group %d does not exist (%d groups)", (unsigned long)e, desc->element_group[e],
                        desc->n_groups);
            return PN_ERROR_INVALID_ARGUMENT;
        }
        for (a = 1; a <= d; ++a)
            for (b = 0; b < d; ++b)
                Ds[b * d + a - 1] = desc->rest_m[(size_t)el[a] * (size_t)d + (size_t)b] - desc->rest_m[(size_t)el[0] * (size_t)d + (size_t)b];
        for (a = 0; a < dp; ++a) /* longest edge */
            for (b = 0; b < a; ++b) {
                pn_real l2 = 0;
                int c;
                for (c = 0; c < d; ++c) {
                    pn_real t = desc->rest_m[(size_t)el[a] * (size_t)d + (size_t)c] - desc->rest_m[(size_t)el[b] * (size_t)d + (size_t)c];
                    l2 += t * t;
                }
                lmax = PN__MAX(lmax, PN__SQRT(l2));
                esum += PN__SQRT(l2) / (nn > dp ? 2 : 1), nedge++; /* order 2: the nodes' spacing */
            }
        vol = pn__fem_volume(d, Ds);
        /* degenerate: volume below 1e-9 of the longest edge's cube (square) */
        if (!(PN__FABS(vol) > (pn_real)1e-9 * (d == 2 ? lmax * lmax : lmax * lmax * lmax))) {
            pn__msg(why, why_cap, "element %lu (nodes %d %d %d%s%s) is degenerate: volume %g", (unsigned long)e, el[0], el[1],
                        el[2], d == 3 ? " ..." : "", "", (double)vol);
            return PN_ERROR_INVALID_ARGUMENT;
        }
        if (vol < 0) {
            pn__msg(why, why_cap, "element %lu is inverted (negative volume %g): list its nodes %s", (unsigned long)e,
                        (double)vol, d == 2 ? "counter-clockwise" : "so that (x1-x0) x (x2-x0) . (x3-x0) > 0");
            return PN_ERROR_INVALID_ARGUMENT;
        }
        for (a = 0; a < nq && nn > dp; ++a) { /* quadratic: positive at every point */
            pn_real dN[30], J[9];
            int i2, j2, c;
            pn__fem_ref_grad(d, 2, a, dN);
            for (i2 = 0; i2 < dd; ++i2) J[i2] = 0;
            for (c = 0; c < nn; ++c)
                for (i2 = 0; i2 < d; ++i2)
                    for (j2 = 0; j2 < d; ++j2) J[i2 * d + j2] += desc->rest_m[(size_t)el[c] * (size_t)d + (size_t)i2] * dN[c * d + j2];
            if (!(pn_mat_det(d, J) > (pn_real)1e-3 * pn_mat_det(d, Ds))) {
                pn__msg(why, why_cap, "element %lu: its Jacobian at integration point %d is %g of its corners' (an edge "
                            "node far from its edge's middle, or listed out of order)", (unsigned long)e, a,
                            (double)(pn_mat_det(d, J) / pn_mat_det(d, Ds)));
                return PN_ERROR_INVALID_ARGUMENT;
            }
        }
        emax = PN__MAX(emax, lmax);
    }
    al = &desc->allocator;
    m = (pn_fem_mesh *)pn_alloc(al, sizeof *m);
    if (!m) return PN_ERROR_OUT_OF_MEMORY;
    memset(m, 0, sizeof *m);
    m->desc = *desc;
    m->desc.rest_m = NULL, m->desc.elements = NULL, m->desc.element_group = NULL, m->desc.groups = NULL;
    m->dim = d, m->n_nodes = n, m->n_elems = ne;
    m->order = nn > dp ? 2 : 1, m->desc.order = m->order, m->nodes_per_element = nn, m->points_per_element = nq;
    m->n_points = np;
    m->error_element = m->error_node = -1;
    m->n_groups = desc->n_groups;
    for (g = 0; g < desc->n_groups; ++g) m->groups[g] = desc->groups[g];
    m->x = (pn_real *)pn_alloc(al, sizeof(pn_real) * (n * (size_t)(4 * d + 1 + 6) + np * (size_t)(2 * dd + 2)));
    m->elem = (int *)pn_alloc(al, sizeof(int) * ne * (size_t)(nn + 1));
    m->fixed = (unsigned char *)pn_alloc(al, n);
    if (!m->x || !m->elem || !m->fixed) {
        pn_fem_destroy(m);
        return PN_ERROR_OUT_OF_MEMORY;
    }
    m->v = m->x + n * (size_t)d;
    m->X = m->v + n * (size_t)d;
    m->drive = m->X + n * (size_t)d;
    m->mass = m->drive + n * (size_t)d;
    m->Dm_inv = m->mass + n;
    m->Fp_inv = m->Dm_inv + np * (size_t)dd;
    m->vol0 = m->Fp_inv + np * (size_t)dd;
    m->h = m->vol0 + np;
    m->spin = m->h + np;
    m->egroup = m->elem + ne * (size_t)nn;
    memcpy(m->x, desc->rest_m, sizeof(pn_real) * n * (size_t)d);
    memcpy(m->X, desc->rest_m, sizeof(pn_real) * n * (size_t)d);
    memset(m->v, 0, sizeof(pn_real) * n * (size_t)d);
    memset(m->drive, 0, sizeof(pn_real) * n * (size_t)d);
    memset(m->spin, 0, sizeof(pn_real) * n * 6);
    memset(m->mass, 0, sizeof(pn_real) * n);
    memset(m->fixed, 0, n);
    memcpy(m->elem, desc->elements, sizeof(int) * ne * (size_t)nn);
    for (e = 0; e < ne; ++e) {
        pn_real mass = 0;
        int a, gi = desc->element_group ? desc->element_group[e] : 0;
        m->egroup[e] = gi;
        for (a = 0; a < nq; ++a) {
            size_t p = e * (size_t)nq + (size_t)a;
            pn_real J[9], dN[30], wq = pn__fem_ref_grad(d, m->order, a, dN);
            int i2;
            pn__fem_jac(m, p, m->X, J);
            m->vol0[p] = wq * pn__fem_volume(d, J);
            pn_mat_inverse(d, J, m->Dm_inv + p * (size_t)dd);
            for (i2 = 0; i2 < dd; ++i2) m->Fp_inv[p * (size_t)dd + (size_t)i2] = (i2 % (d + 1)) == 0;
            m->h[p] = 0;
            mass += m->vol0[p] * m->groups[gi].density_kg_m3;
        }
        for (a = 0; a < nn; ++a) /* lumped: linear, an equal share per node; quadratic, HRZ */
            m->mass[m->elem[e * (size_t)nn + (size_t)a]] += mass * pn__fem_mass_share(d, m->order, a);
    }
    for (i = 0; i < n; ++i)
        if (!(m->mass[i] > 0)) {
            pn__msg(why, why_cap, "node %lu belongs to no element (it would have no mass)", (unsigned long)i);
            pn_fem_destroy(m);
            return PN_ERROR_INVALID_ARGUMENT;
        }
    m->edge_mean = nedge ? esum / (pn_real)nedge : emax;
    m->dhat = desc->contact_distance_m > 0 ? desc->contact_distance_m : (pn_real)1e-3 * diag;
    if (!(m->desc.friction_velocity_m_s > 0)) m->desc.friction_velocity_m_s = (pn_real)1e-3;
    if (desc->contact_stiffness > 0) m->kappa = desc->contact_stiffness;
    else { /* the barrier's force at dhat / 2, kappa |b'| ~ kappa dhat, holds a stress of 0.1 E on
              a node's share of the surface, l^(dim - 1): the gap stays near dhat / 2 up to
              stresses far above yield, and under impacts of rho v c < 0.1 E */
        pn_real E = 0;
        for (g = 0; g < m->n_groups; ++g) E = PN__MAX(E, m->groups[g].material.E);
        m->kappa = (pn_real)0.1 * E * (d == 3 ? m->edge_mean * m->edge_mean : m->edge_mean) / m->dhat;
    }
    r = pn__fem_alloc_solver(m);
    if (r != PN_OK) {
        pn_fem_destroy(m);
        pn__msg(why, why_cap, "out of memory for a mesh of %lu nodes and %lu elements", (unsigned long)n, (unsigned long)ne);
        return r;
    }
    *out = m;
    return PN_OK;
}

PN__DEF pn_result pn_fem_group_set_energy(pn_fem_mesh *m, int g, pn_energy energy, const pn_pnet *net) {
    char msg[256];
    pn_result r;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    if (g < 0 || g >= m->n_groups)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_group_set_energy: group %d does not exist (%d groups)", g,
                            m->n_groups);
    r = pn__group_set_energy(&m->groups[g], g, m->dim, energy, net, msg, sizeof msg);
    if (r != PN_OK) return PN__FAIL(m, r, "pn_fem_group_set_energy: %s", msg);
    return PN_OK;
}

/* ======================================================================================
   >>fem-nodes: held and driven nodes (pn_fem_fix_nodes, pn_fem_spin_nodes,
   pn_fem_release_nodes): the Dirichlet conditions both steps apply.
   ====================================================================================== */

static void pn__fem_cross(const pn_real *a, const pn_real *b, pn_real *c) {
    c[0] = a[1] * b[2] - a[2] * b[1], c[1] = a[2] * b[0] - a[0] * b[2], c[2] = a[0] * b[1] - a[1] * b[0];
}

/* the node list of a pn_fem_*_nodes call checked; PN_OK or the failure, named */
static pn_result pn__fem_node_list(pn_fem_mesh *m, size_t n, const int *nodes, const char *who) {
    size_t k;
    if (n && !nodes) return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "%s: nodes is NULL", who);
    for (k = 0; k < n; ++k)
        if (nodes[k] < 0 || (size_t)nodes[k] >= m->n_nodes)
            return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "%s: node index %d (entry %lu) is out of range", who, nodes[k],
                                (unsigned long)k);
    return PN_OK;
}

PN__DEF pn_result pn_fem_fix_nodes(pn_fem_mesh *m, size_t n, const int *nodes, const pn_real *velocity_m_s) {
    size_t k;
    int i;
    pn_result r;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    if ((r = pn__fem_node_list(m, n, nodes, "pn_fem_fix_nodes")) != PN_OK) return r;
    if (velocity_m_s)
        for (i = 0; i < m->dim; ++i)
            if (!pn__finite(velocity_m_s[i]))
                return PN__FAIL(m, PN_ERROR_NONFINITE, "pn_fem_fix_nodes: velocity[%d] is not finite", i);
    for (k = 0; k < n; ++k) {
        size_t p = (size_t)nodes[k];
        m->fixed[p] = 1;
        for (i = 0; i < m->dim; ++i) m->drive[p * (size_t)m->dim + (size_t)i] = velocity_m_s ? velocity_m_s[i] : 0;
        for (i = 0; i < m->dim; ++i) m->v[p * (size_t)m->dim + (size_t)i] = velocity_m_s ? velocity_m_s[i] : 0;
    }
    return PN_OK;
}

PN__DEF pn_result pn_fem_spin_nodes(pn_fem_mesh *m, size_t n, const int *nodes, const pn_real *center_m,
                                    const pn_real *angular_velocity_rad_s) {
    size_t k;
    int i;
    pn_result r;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    if ((r = pn__fem_node_list(m, n, nodes, "pn_fem_spin_nodes")) != PN_OK) return r;
    if (!center_m || !angular_velocity_rad_s)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_spin_nodes: center_m or angular_velocity_rad_s is NULL");
    for (i = 0; i < 3; ++i)
        if ((i < m->dim && !pn__finite(center_m[i])) || !pn__finite(angular_velocity_rad_s[i]))
            return PN__FAIL(m, PN_ERROR_NONFINITE, "pn_fem_spin_nodes: center_m[%d] or angular_velocity_rad_s[%d] is not "
                                "finite", i, i);
    for (k = 0; k < n; ++k) {
        size_t p = (size_t)nodes[k];
        pn_real *sp = m->spin + 6 * p, w[3], rr[3] = {0, 0, 0};
        m->fixed[p] = 2;
        for (i = 0; i < 3; ++i) sp[i] = i < m->dim ? center_m[i] : 0, sp[3 + i] = angular_velocity_rad_s[i];
        if (m->dim == 2) sp[3] = sp[4] = 0;
        for (i = 0; i < m->dim; ++i) rr[i] = m->x[p * (size_t)m->dim + (size_t)i] - sp[i];
        pn__fem_cross(sp + 3, rr, w); /* v = omega x r */
        for (i = 0; i < m->dim; ++i) m->v[p * (size_t)m->dim + (size_t)i] = w[i];
    }
    return PN_OK;
}

PN__DEF pn_result pn_fem_release_nodes(pn_fem_mesh *m, size_t n, const int *nodes) {
    size_t k;
    pn_result r;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    if ((r = pn__fem_node_list(m, n, nodes, "pn_fem_release_nodes")) != PN_OK) return r;
    for (k = 0; k < n; ++k) m->fixed[nodes[k]] = 0;
    return PN_OK;
}

/* where driven node k is after a step of dt: translated, or turned along the exact arc
   (Rodrigues' formula about the spin's axis) */
static void pn__fem_driven(const pn_fem_mesh *m, size_t k, pn_real dt, pn_real *xn) {
    int d = m->dim, i;
    const pn_real *x = m->x + k * (size_t)d;
    if (m->fixed[k] == 2) {
        const pn_real *sp = m->spin + 6 * k;
        pn_real rate = PN__SQRT(sp[3] * sp[3] + sp[4] * sp[4] + sp[5] * sp[5]), a[3], r[3] = {0, 0, 0}, axr[3], ad, c, s;
        for (i = 0; i < d; ++i) r[i] = x[i] - sp[i];
        if (!(rate > 0)) {
            for (i = 0; i < d; ++i) xn[i] = x[i];
            return;
        }
        for (i = 0; i < 3; ++i) a[i] = sp[3 + i] / rate;
        c = PN__COS(rate * dt), s = PN__SIN(rate * dt);
        pn__fem_cross(a, r, axr);
        ad = a[0] * r[0] + a[1] * r[1] + a[2] * r[2];
        for (i = 0; i < d; ++i) xn[i] = sp[i] + r[i] * c + axr[i] * s + a[i] * ad * (1 - c);
    } else
        for (i = 0; i < d; ++i) xn[i] = x[i] + dt * m->drive[k * (size_t)d + (size_t)i];
}

/* ======================================================================================
   >>fem-obstacles: analytic obstacles (half-spaces, boxes, spheres, moving): their signed
   distance, and the check that none reaches into an element (pn_fem_add_obstacle).
   ====================================================================================== */

/* signed distance from x to obstacle c at time t (> 0 outside), and its gradient n */
static pn_real pn__fem_obstacle_sd(const pn_collider *c, int d, pn_real t, const pn_real *u, const pn_real *x, pn_real *n) {
    pn_real r[3], dist = 0;
    int i;
    for (i = 0; i < d; ++i) r[i] = x[i] - (c->center_m[i] + t * c->velocity_m_s[i] + (u ? u[i] : 0));
    if (c->shape == PN_SHAPE_HALF_SPACE) {
        pn_real nn = 0;
        for (i = 0; i < d; ++i) nn += c->normal[i] * c->normal[i];
        nn = 1 / PN__SQRT(nn);
        for (i = 0; i < d; ++i) n[i] = c->normal[i] * nn, dist += r[i] * n[i];
        return dist;
    } else { /* box */
        pn_real q[3], out2 = 0, inmax = -PN__FEM_FAR;
        int arg = 0;
        for (i = 0; i < d; ++i) {
            q[i] = PN__FABS(r[i]) - c->half_extent_m[i];
            if (q[i] > 0) out2 += q[i] * q[i];
            if (q[i] > inmax) inmax = q[i], arg = i;
        }
        if (out2 > 0) {
            dist = PN__SQRT(out2);
            for (i = 0; i < d; ++i) n[i] = q[i] > 0 ? (r[i] < 0 ? -q[i] : q[i]) / dist : 0;
            return dist;
        }
        for (i = 0; i < d; ++i) n[i] = 0;
        n[arg] = r[arg] < 0 ? -1 : 1;
        return inmax;
    }
}

/* Do the interiors of the axis-aligned box [lo, hi] and the simplex P (d + 1 points) meet?
   Separating axes: the box's faces, the simplex's faces and, in 3D, each simplex edge
   crossed with each box axis; touching is not meeting. */
static int pn__fem_box_meets_simplex(int d, const pn_real *lo, const pn_real *hi, const pn_real *P) {
    pn_real axes[3 + 4 + 18][3], c[3], h[3]; /* box faces, simplex faces, edge crossings */
    int na = 0, a, i, j, k;
    for (i = 0; i < d; ++i) c[i] = (lo[i] + hi[i]) / 2, h[i] = (hi[i] - lo[i]) / 2;
    for (i = 0; i < d; ++i) {
        for (k = 0; k < 3; ++k) axes[na][k] = 0;
        axes[na++][i] = 1;
    }
    if (d == 2)
        for (i = 0; i < 3; ++i) { /* edge normals */
            const pn_real *p = P + 2 * i, *q = P + 2 * ((i + 1) % 3);
            axes[na][0] = q[1] - p[1], axes[na][1] = p[0] - q[0], axes[na++][2] = 0;
        }
    else {
        for (i = 0; i < 4; ++i) { /* face normals */
            const pn_real *p = P + 3 * ((i + 1) % 4), *q = P + 3 * ((i + 2) % 4), *r = P + 3 * ((i + 3) % 4);
            pn_real u[3], v[3];
            for (k = 0; k < 3; ++k) u[k] = q[k] - p[k], v[k] = r[k] - p[k];
            axes[na][0] = u[1] * v[2] - u[2] * v[1], axes[na][1] = u[2] * v[0] - u[0] * v[2];
            axes[na++][2] = u[0] * v[1] - u[1] * v[0];
        }
        for (i = 0; i < 4; ++i)
            for (j = i + 1; j < 4; ++j) /* edges x box axes: e x e_a */
                for (a = 0; a < 3; ++a) {
                    pn_real e[3];
                    for (k = 0; k < 3; ++k) e[k] = P[3 * j + k] - P[3 * i + k];
                    axes[na][a] = 0, axes[na][(a + 1) % 3] = e[(a + 2) % 3], axes[na++][(a + 2) % 3] = -e[(a + 1) % 3];
                }
    }
    for (a = 0; a < na; ++a) {
        pn_real smin = PN__FEM_FAR, smax = -PN__FEM_FAR, bc = 0, br = 0;
        for (i = 0; i <= d; ++i) {
            pn_real t = 0;
            for (k = 0; k < d; ++k) t += axes[a][k] * P[i * d + k];
            smin = PN__MIN(smin, t), smax = PN__MAX(smax, t);
        }
        for (k = 0; k < d; ++k) bc += axes[a][k] * c[k], br += PN__FABS(axes[a][k]) * h[k];
        if (br == 0 && smax == smin) continue; /* a degenerate axis separates nothing */
        if (smax <= bc - br || smin >= bc + br) return 0;
    }
    return 1;
}

/* the first element whose interior a box obstacle's (at time t) meets (a quadratic one: one
   of its linear pieces), or -1: its nodes may all be outside the box (a small box inside a
   large element), where the nodes' barrier cannot see it */
static long pn__fem_obstacle_in_element(const pn_fem_mesh *m, const pn_collider *c, pn_real t) {
    int d = m->dim, i, a, k;
    pn_real lo[3], hi[3], P[12];
    size_t e;
    if (c->shape != PN_SHAPE_BOX) return -1; /* a half-space meets an element only where a node is inside */
    for (i = 0; i < d; ++i) {
        pn_real ci = c->center_m[i] + t * c->velocity_m_s[i];
        lo[i] = ci - c->half_extent_m[i], hi[i] = ci + c->half_extent_m[i];
    }
    for (e = 0; e < m->n_elems; ++e)
        for (k = 0; k < pn__fem_nsub(m); ++k) {
            const int *el = m->elem + e * (size_t)m->nodes_per_element, *sub = pn__fem_sub(m, k);
            int out = 0;
            for (a = 0; a <= d; ++a)
                for (i = 0; i < d; ++i) P[a * d + i] = m->x[(size_t)el[sub[a]] * (size_t)d + (size_t)i];
            for (i = 0; i < d && !out; ++i) { /* the bounding boxes first */
                pn_real emin = P[i], emax = P[i];
                for (a = 1; a <= d; ++a) emin = PN__MIN(emin, P[a * d + i]), emax = PN__MAX(emax, P[a * d + i]);
                out = emax <= lo[i] || emin >= hi[i];
            }
            if (!out && pn__fem_box_meets_simplex(d, lo, hi, P)) return (long)e;
        }
    return -1;
}

PN__DEF pn_result pn_fem_add_obstacle(pn_fem_mesh *m, const pn_collider *c, int *index) {
    int i, d;
    size_t k;
    pn_real nn = 0, nrm[3];
    if (!m || !c) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    d = m->dim;
    if (m->n_obstacles >= PN_FEM_MAX_OBSTACLES)
        return PN__FAIL(m, PN_ERROR_CAPACITY, "pn_fem_add_obstacle: the mesh has its %d obstacles", PN_FEM_MAX_OBSTACLES);
    if (c->shape != PN_SHAPE_HALF_SPACE && c->shape != PN_SHAPE_BOX)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_add_obstacle: shape %d: half-spaces and boxes only", (int)c->shape);
    for (i = 0; i < d; ++i) {
        if (!pn__finite(c->center_m[i]) || !pn__finite(c->normal[i]) || !pn__finite(c->velocity_m_s[i]) ||
            !pn__finite(c->half_extent_m[i]))
            return PN__FAIL(m, PN_ERROR_NONFINITE, "pn_fem_add_obstacle: a coordinate of axis %d is not finite", i);
        nn += c->normal[i] * c->normal[i];
        if (c->shape == PN_SHAPE_BOX && !(c->half_extent_m[i] > 0 && pn__finite(c->friction)))
            return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_add_obstacle: half_extent_m[%d] must be > 0", i);
    }
    if (!(c->friction >= 0) || !pn__finite(c->friction))
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_add_obstacle: friction must be finite and >= 0");
    if (c->shape == PN_SHAPE_HALF_SPACE && !(nn > 0))
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_add_obstacle: the half-space's normal is zero");
    for (k = 0; k < m->n_nodes; ++k)
        if (!(pn__fem_obstacle_sd(c, d, m->time_s, NULL, m->x + k * (size_t)d, nrm) > 0)) {
            m->error_node = (long)k;
            return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_add_obstacle: node %lu is inside the obstacle",
                                (unsigned long)k);
        }
    if ((m->error_element = pn__fem_obstacle_in_element(m, c, m->time_s)) >= 0)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_add_obstacle: the obstacle reaches into element %ld (no "
                            "node of it inside the obstacle, so the nodes' barrier cannot see it)", m->error_element);
    m->obstacles[m->n_obstacles] = *c;
    for (i = d; i < 3; ++i) m->obstacles[m->n_obstacles].velocity_m_s[i] = 0;
    if (index) *index = m->n_obstacles;
    m->n_obstacles++;
    return PN_OK;
}

/* ======================================================================================
   >>fem-energy: per integration point, F = sum_a x_a grad N_a (linear elements: Ds Dm^-1),
   the elastic energy density of Fe and the group's implicit energy (its F0 and network
   state) prepared for a step.
   ====================================================================================== */

#define PN__FEM_ELEM(m, p) ((p) / (size_t)(m)->points_per_element) /* point p's element */

/* Psi of point p at Fe with its group's energy (P and the Hessian when asked, PSD-projected
   unless the Newton iteration asked for the full one: s->hflags) */
static pn_result pn__fem_psi(const pn_fem_mesh *m, size_t p, const pn_real *Fe, pn_real *psi, pn_real *P, pn_real *H) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int dd = m->dim * m->dim;
    return pn__group_psi(&m->groups[m->egroup[PN__FEM_ELEM(m, p)]], m->dim, Fe, m->h[p], s->pG + p * (size_t)dd, s->phG[p],
                         &s->ppt[p], s->pty[p], psi, P, H, s->hflags);
}

/* Fe = sum_a x_a q_a^T at point p */
static void pn__fem_fe(const pn_fem_mesh *m, size_t p, const pn_real *x, pn_real *Fe) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int d = m->dim, nn = m->nodes_per_element, a, i, j;
    const int *el = m->elem + PN__FEM_ELEM(m, p) * (size_t)nn;
    const pn_real *q = s->q + p * (size_t)(d * nn);
    for (i = 0; i < d * d; ++i) Fe[i] = 0;
    for (a = 0; a < nn; ++a) {
        const pn_real *xa = x + (size_t)el[a] * (size_t)d;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) Fe[i * d + j] += xa[i] * q[a * d + j];
    }
}

/* per step: B = Dm^-1 Fp^-1 and the q_a = B^T dN_a / dxi of each point */
static void pn__fem_setup(pn_fem_mesh *m) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, dd = d * d, nn = m->nodes_per_element, nq = m->points_per_element, a, j, k;
    pn_real dN[4][30];
    size_t p;
    for (k = 0; k < nq; ++k) pn__fem_ref_grad(d, m->order, k, dN[k]);
    for (p = 0; p < m->n_points; ++p) {
        const pn_material *mt = &m->groups[m->egroup[PN__FEM_ELEM(m, p)]].material;
        const pn_real *g = dN[p % (size_t)nq];
        pn_real *B = s->B + p * (size_t)dd, *q = s->q + p * (size_t)(d * nn);
        pn_mat_mul(d, m->Dm_inv + p * (size_t)dd, m->Fp_inv + p * (size_t)dd, B);
        for (a = 0; a < nn; ++a)
            for (j = 0; j < d; ++j) {
                pn_real acc = 0;
                for (k = 0; k < d; ++k) acc += g[a * d + k] * B[k * d + j];
                q[a * d + j] = acc;
            }
        s->elast[p] = mt->elastic != PN_ELASTIC_FIXED_COROTATED || mt->plastic != PN_PLASTIC_NONE;
    }
}

/* ======================================================================================
   >>fem-linear: the Newton systems' solvers: skyline Cholesky; the Hessian in d x d node
   blocks (the lower triangle by block rows: nodes in RCM position order, then the moving
   obstacles' dense rows), its block incomplete Cholesky L D L^T on the same pattern (block
   IC(0)), a coarse correction, and the products PCG needs. Storage grows with the mesh, not
   with its profile: the solver for meshes the skyline cannot hold. One thread: the
   factorization and the triangular solves are sequential, the product is memory-bound on
   these sizes, and the bits do not depend on the thread count.
   ====================================================================================== */

/* the skyline row of unknown k (nodes in RCM order, then the moving obstacles) */
static size_t pn__fem_row(const pn_fem_mesh *m, size_t k) {
    const pn__fem *s = (const pn__fem *)m->impl;
    size_t nd = m->n_nodes * (size_t)m->dim;
    if (k >= nd) return k;
    return s->iperm[k / (size_t)m->dim] * (size_t)m->dim + k % (size_t)m->dim;
}

static pn_real *pn__fem_blk(const pn__fem *s, size_t br, size_t bc); /* >>fem sparse */

/* add v at (r, c) of the Hessian (the skyline, or the blocks with s->sparse) */
static void pn__fem_hadd(pn__fem *s, size_t r, size_t c, pn_real v) {
    if (r < c) {
        size_t t = r;
        r = c, c = t;
    }
    if (s->sparse) {
        size_t d = (size_t)s->d;
        pn_real *b = pn__fem_blk(s, r / d, c / d);
        if (b) b[(r % d) * d + c % d] += v;
        else s->bmiss++;
        return;
    }
    s->L[s->rs[r] + c - s->fc[r]] += v;
}

/* node block (na, nb) of the Hessian += v (d x d, row i for na's unknown i; na == nb: the
   lower half only): one block lookup where pn__fem_hadd makes one per entry, the same sums */
static void pn__fem_hadd_block(const pn_fem_mesh *m, pn__fem *s, size_t na, size_t nb, const pn_real *v) {
    int d = m->dim, i, k;
    if (s->sparse) {
        size_t pa = s->iperm[na], pb = s->iperm[nb];
        pn_real *b = pn__fem_blk(s, PN__MAX(pa, pb), PN__MIN(pa, pb));
        if (!b) {
            s->bmiss += na == nb ? d * (d + 1) / 2 : d * d;
            return;
        }
        for (i = 0; i < d; ++i)
            for (k = 0; k < (na == nb ? i + 1 : d); ++k) b[pa >= pb ? i * d + k : k * d + i] += v[i * d + k];
        return;
    }
    for (i = 0; i < d; ++i)
        for (k = 0; k < (na == nb ? i + 1 : d); ++k)
            pn__fem_hadd(s, pn__fem_row(m, na * (size_t)d + (size_t)i), pn__fem_row(m, nb * (size_t)d + (size_t)k), v[i * d + k]);
}

/* is node k's unknown free (not driven)? */
#define PN__FEM_FREE(m, node) (!(m)->fixed[node])

/* Is the block of nodes i and j inside the skyline's profile (the blocks' pattern)? */
static int pn__fem_in_profile(const pn_fem_mesh *m, size_t i, size_t j) {
    const pn__fem *s = (const pn__fem *)m->impl;
    size_t pi = s->iperm[i], pj = s->iperm[j], lo = PN__MIN(pi, pj), hi = PN__MAX(pi, pj);
    if (s->sparse) return pn__fem_blk(s, hi, lo) != NULL;
    return lo * (size_t)m->dim >= s->fc[hi * (size_t)m->dim];
}

/* In-place Cholesky of the first nu rows of the skyline matrix L (row r: columns fc[r] .. r
   from L + rs[r]); 0 if not positive definite. */
static int pn__sky_cholesky(const size_t *fc, const size_t *rs, pn_real *L, size_t nu) {
    size_t r, c, k;
    for (r = 0; r < nu; ++r) {
        pn_real *Lr = L + rs[r], diag;
        size_t fr = fc[r];
        for (c = fr; c < r; ++c) {
            const pn_real *Lc = L + rs[c];
            size_t fcc = fc[c], k0 = PN__MAX(fr, fcc);
            pn_real acc = Lr[c - fr];
            for (k = k0; k < c; ++k) acc -= Lr[k - fr] * Lc[k - fcc];
            Lr[c - fr] = acc / Lc[c - fcc];
        }
        diag = Lr[r - fr];
        for (k = fr; k < r; ++k) diag -= Lr[k - fr] * Lr[k - fr];
        if (!(diag > 0)) return 0;
        Lr[r - fr] = PN__SQRT(diag);
    }
    return 1;
}

/* solve L L^T y = b in place (skyline rows) */
static void pn__sky_solve(const size_t *fc, const size_t *rs, const pn_real *L, size_t nu, pn_real *y) {
    size_t r, k;
    for (r = 0; r < nu; ++r) {
        const pn_real *Lr = L + rs[r];
        pn_real acc = y[r];
        for (k = fc[r]; k < r; ++k) acc -= Lr[k - fc[r]] * y[k];
        y[r] = acc / Lr[r - fc[r]];
    }
    for (r = nu; r-- > 0;) {
        const pn_real *Lr = L + rs[r];
        y[r] /= Lr[r - fc[r]];
        for (k = fc[r]; k < r; ++k) y[k] -= Lr[k - fc[r]] * y[r];
    }
}

static pn_result pn__fem_coarse_setup(pn_fem_mesh *m);

/* room for this step's obstacle rows (dense: every column before them); the first step with
   more moving obstacles than before allocates */
static pn_result pn__fem_sparse_reserve(pn_fem_mesh *m) {
    const pn_allocator *al = &m->desc.allocator;
    pn__fem *s = (pn__fem *)m->impl;
    size_t n = m->n_nodes, rows = n + (size_t)s->n_mov, total = s->nblk, j, c, dd = (size_t)(s->d * s->d);
    for (j = 0; j < (size_t)s->n_mov; ++j) total += n + j + 1;
    if (!s->bDi) {
        s->bDi = (pn_real *)pn_alloc(al, sizeof(pn_real) * 2 * (n + PN_FEM_MAX_OBSTACLES) * dd);
        s->bmark = (int *)pn_alloc(al, sizeof(int) * (n + PN_FEM_MAX_OBSTACLES));
        if (!s->bDi || !s->bmark) return PN_ERROR_OUT_OF_MEMORY;
        s->bT = s->bDi + (n + PN_FEM_MAX_OBSTACLES) * dd;
        for (c = 0; c < n + PN_FEM_MAX_OBSTACLES; ++c) s->bmark[c] = -1;
    }
    if (!s->agg && pn__fem_coarse_setup(m) != PN_OK) return PN_ERROR_OUT_OF_MEMORY;
    if (!s->bA || total > s->bcap) {
        int *nc = (int *)pn_alloc(al, sizeof(int) * total);
        pn_real *na = (pn_real *)pn_alloc(al, sizeof(pn_real) * total * dd), *nl = (pn_real *)pn_alloc(al, sizeof(pn_real) * total * dd);
        if (!nc || !na || !nl) {
            pn_free(al, nc), pn_free(al, na), pn_free(al, nl);
            return PN_ERROR_OUT_OF_MEMORY;
        }
        memcpy(nc, s->bcol, sizeof(int) * s->nblk);
        pn_free(al, s->bcol), pn_free(al, s->bA), pn_free(al, s->bL);
        s->bcol = nc, s->bA = na, s->bL = nl, s->bcap = total;
        s->brows = -1; /* lay the obstacle rows out again */
    }
    if ((size_t)s->brows != rows) {
        for (j = n; j < rows; ++j) {
            s->brs[j + 1] = s->brs[j] + j + 1;
            for (c = 0; c <= j; ++c) s->bcol[s->brs[j] + c] = (int)c;
        }
        s->brows = (int)rows;
    }
    return PN_OK;
}

/* block (br, bc), br >= bc, of the Hessian; NULL outside the pattern */
static pn_real *pn__fem_blk(const pn__fem *s, size_t br, size_t bc) {
    size_t lo = s->brs[br], hi = s->brs[br + 1];
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if ((size_t)s->bcol[mid] < bc) lo = mid + 1;
        else hi = mid;
    }
    return lo < s->brs[br + 1] && (size_t)s->bcol[lo] == bc ? s->bA + lo * (size_t)(s->d * s->d) : NULL;
}

/* y = A x (the blocks; the diagonal block's lower half mirrored); d a constant where inlined */
PN__MPM_INLINE void pn__fem_bmul_d(const pn__fem *s, const pn_real *x, pn_real *y, const int d) {
    int dd = d * d, i, j;
    size_t r, q;
    memset(y, 0, sizeof(pn_real) * (size_t)s->brows * (size_t)d);
    for (r = 0; r < (size_t)s->brows; ++r) {
        const pn_real *xr = x + r * (size_t)d, *B;
        pn_real *yr = y + r * (size_t)d;
        for (q = s->brs[r]; q + 1 < s->brs[r + 1]; ++q) {
            const pn_real *xc = x + (size_t)s->bcol[q] * (size_t)d;
            pn_real *yc = y + (size_t)s->bcol[q] * (size_t)d;
            B = s->bA + q * (size_t)dd;
            for (i = 0; i < d; ++i)
                for (j = 0; j < d; ++j) yr[i] += B[i * d + j] * xc[j], yc[j] += B[i * d + j] * xr[i];
        }
        B = s->bA + q * (size_t)dd;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) yr[i] += B[i >= j ? i * d + j : j * d + i] * xr[j];
    }
}

static void pn__fem_bmul(const pn__fem *s, const pn_real *x, pn_real *y) {
    if (s->d == 3) pn__fem_bmul_d(s, x, y, 3);
    else pn__fem_bmul_d(s, x, y, 2);
}

/* Ai = A^-1 of a symmetric d x d block (lower half read) by Cholesky; 0 if A is not positive
   definite */
static int pn__fem_spd_inv(int d, const pn_real *A, pn_real *Ai) {
    pn_real L[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0}, y[3];
    int i, j, k, c;
    for (i = 0; i < d; ++i)
        for (j = 0; j <= i; ++j) {
            pn_real acc = A[i * d + j];
            for (k = 0; k < j; ++k) acc -= L[i * d + k] * L[j * d + k];
            if (i == j) {
                if (!(acc > 0)) return 0;
                L[i * d + i] = PN__SQRT(acc);
            } else L[i * d + j] = acc / L[j * d + j];
        }
    for (c = 0; c < d; ++c) { /* column c of A^-1: L y = e_c, L^T x = y */
        for (i = 0; i < d; ++i) {
            pn_real acc = i == c;
            for (k = 0; k < i; ++k) acc -= L[i * d + k] * y[k];
            y[i] = acc / L[i * d + i];
        }
        for (i = d - 1; i >= 0; --i) {
            pn_real acc = y[i];
            for (k = i + 1; k < d; ++k) acc -= L[k * d + i] * Ai[k * d + c];
            Ai[i * d + c] = acc / L[i * d + i];
        }
    }
    return 1;
}

/* Block IC(0) of A + shift diag(A): A = L D L^T with L unit lower, kept on A's pattern. Row i,
   columns k < i in order: T_ik = A_ik - sum_j T_ij L_kj^T (j < k in both rows' patterns),
   L_ik = T_ik D_k^-1; then D_i = A_ii - sum_k T_ik L_ik^T. 0 if a D_i is not positive
   definite (the factorization of a positive definite matrix can break down too: a shift
   then helps). */
static int pn__fem_bic(pn__fem *s, pn_real shift) {
    int d = s->d, dd = d * d, a, b, c;
    size_t i, q, p;
    for (i = 0; i < (size_t)s->brows; ++i) {
        size_t b0 = s->brs[i], b1 = s->brs[i + 1] - 1; /* b1: the diagonal block */
        pn_real Dm[9];
        int ok;
        for (q = b0; q < b1; ++q) s->bmark[s->bcol[q]] = (int)(q - b0);
        for (q = b0; q < b1; ++q) {
            size_t k = (size_t)s->bcol[q];
            pn_real *T = s->bT + (q - b0) * (size_t)dd, *Lq = s->bL + q * (size_t)dd;
            const pn_real *Dk = s->bDi + k * (size_t)dd;
            memcpy(T, s->bA + q * (size_t)dd, sizeof(pn_real) * (size_t)dd);
            for (p = s->brs[k]; p + 1 < s->brs[k + 1]; ++p) {
                int jj = s->bmark[s->bcol[p]];
                const pn_real *Tij, *Lkj;
                if (jj < 0) continue;
                Tij = s->bT + (size_t)jj * (size_t)dd, Lkj = s->bL + p * (size_t)dd;
                for (a = 0; a < d; ++a)
                    for (b = 0; b < d; ++b)
                        for (c = 0; c < d; ++c) T[a * d + b] -= Tij[a * d + c] * Lkj[b * d + c];
            }
            for (a = 0; a < d; ++a)
                for (b = 0; b < d; ++b) {
                    pn_real acc = 0;
                    for (c = 0; c < d; ++c) acc += T[a * d + c] * Dk[c * d + b];
                    Lq[a * d + b] = acc;
                }
        }
        for (a = 0; a < d; ++a)
            for (b = 0; b <= a; ++b) {
                pn_real acc = s->bA[b1 * (size_t)dd + (size_t)(a * d + b)] * (a == b ? 1 + shift : 1);
                for (q = b0; q < b1; ++q)
                    for (c = 0; c < d; ++c) acc -= s->bT[(q - b0) * (size_t)dd + (size_t)(a * d + c)] * s->bL[q * (size_t)dd + (size_t)(b * d + c)];
                Dm[a * d + b] = Dm[b * d + a] = acc;
            }
        for (q = b0; q < b1; ++q) s->bmark[s->bcol[q]] = -1;
        ok = pn__fem_spd_inv(d, Dm, s->bDi + i * (size_t)dd);
        if (!ok) return 0;
    }
    return 1;
}

/* the factor, shifted as far as it needs (Manteuffel 1980): 0 if even a shift of 16 diag(A)
   breaks down (a diagonal block not positive definite: the Hessian is not) */
static int pn__fem_bfactor(pn__fem *s) {
    pn_real shift = 0;
    int t;
    for (t = 0; t < 8; ++t) {
        if (pn__fem_bic(s, shift)) {
            s->bshift = shift;
            return 1;
        }
        shift = shift > 0 ? 4 * shift : (pn_real)1e-3;
    }
    return 0;
}

/* z = (L D L^T)^-1 r; d a constant where inlined */
PN__MPM_INLINE void pn__fem_bic_solve_d(const pn__fem *s, const pn_real *r, pn_real *z, const int d) {
    int dd = d * d, a, b;
    size_t i, q, rows = (size_t)s->brows;
    memcpy(z, r, sizeof(pn_real) * rows * (size_t)d);
    for (i = 0; i < rows; ++i) /* L y = r */
        for (q = s->brs[i]; q + 1 < s->brs[i + 1]; ++q) {
            const pn_real *Lq = s->bL + q * (size_t)dd, *zk = z + (size_t)s->bcol[q] * (size_t)d;
            for (a = 0; a < d; ++a)
                for (b = 0; b < d; ++b) z[i * (size_t)d + (size_t)a] -= Lq[a * d + b] * zk[b];
        }
    for (i = 0; i < rows; ++i) { /* D^-1 */
        pn_real t[3];
        const pn_real *Di = s->bDi + i * (size_t)dd;
        for (a = 0; a < d; ++a) {
            t[a] = 0;
            for (b = 0; b < d; ++b) t[a] += Di[a * d + b] * z[i * (size_t)d + (size_t)b];
        }
        for (a = 0; a < d; ++a) z[i * (size_t)d + (size_t)a] = t[a];
    }
    for (i = rows; i-- > 0;) /* L^T x = y: row i final, pushed into the columns before it */
        for (q = s->brs[i]; q + 1 < s->brs[i + 1]; ++q) {
            const pn_real *Lq = s->bL + q * (size_t)dd, *zi = z + i * (size_t)d;
            pn_real *zk = z + (size_t)s->bcol[q] * (size_t)d;
            for (a = 0; a < d; ++a)
                for (b = 0; b < d; ++b) zk[b] -= Lq[a * d + b] * zi[a];
        }
}

static void pn__fem_bic_solve(const pn__fem *s, const pn_real *r, pn_real *z) {
    if (s->d == 3) pn__fem_bic_solve_d(s, r, z, 3);
    else pn__fem_bic_solve_d(s, r, z, 2);
}

/* The coarse level's structure, once (at the first PCG step): aggregates grown greedily in
   row order on the node graph (a row whose neighbours are all free takes them; rows left over
   join a neighbouring aggregate, or start their own), the aggregates' graph in RCM order and
   its skyline. Vanek, Mandel and Brezina 1996 (aggregation, rigid-body modes). */
static pn_result pn__fem_coarse_setup(pn_fem_mesh *m) {
    const pn_allocator *al = &m->desc.allocator;
    pn__fem *s = (pn__fem *)m->impl;
    size_t n = m->n_nodes, p, q, a, b, na = 0, nnz = 0, *beg, *adj, *cnt, *deg, *ab, *aadj, *acnt, *pos;
    int d = s->d, nm = d == 2 ? 3 : 6, *mark;
    unsigned char *seen;
    pn_result r = PN_ERROR_OUT_OF_MEMORY;
    beg = (size_t *)pn_alloc(al, sizeof(size_t) * (3 * (n + 1) + 2 * s->nblk + 2 * (n + 1) + 4 * s->nblk + 4));
    mark = (int *)pn_alloc(al, sizeof(int) * (n + 1));
    seen = (unsigned char *)pn_alloc(al, n + 1);
    s->agg = (int *)pn_alloc(al, sizeof(int) * (n + 1));
    if (!beg || !mark || !seen || !s->agg) goto done;
    cnt = beg + n + 1, adj = cnt + n + 1, deg = adj + 2 * s->nblk, ab = deg + n + 1, aadj = ab + n + 1, acnt = aadj + 2 * s->nblk;
    /* the node graph, both ways, from the lower block rows */
    memset(cnt, 0, sizeof(size_t) * (n + 1));
    for (p = 0; p < n; ++p)
        for (q = s->brs[p]; q + 1 < s->brs[p + 1]; ++q) cnt[p]++, cnt[s->bcol[q]]++;
    for (beg[0] = 0, p = 0; p < n; ++p) beg[p + 1] = beg[p] + cnt[p], cnt[p] = beg[p];
    for (p = 0; p < n; ++p)
        for (q = s->brs[p]; q + 1 < s->brs[p + 1]; ++q) adj[cnt[p]++] = (size_t)s->bcol[q], adj[cnt[s->bcol[q]]++] = p;
    for (p = 0; p < n; ++p) s->agg[p] = -1;
    for (p = 0; p < n; ++p) { /* 1: a row and all its neighbours, where none is taken */
        int free_all = s->agg[p] < 0;
        for (q = beg[p]; q < cnt[p] && free_all; ++q) free_all = s->agg[adj[q]] < 0;
        if (!free_all) continue;
        s->agg[p] = (int)na;
        for (q = beg[p]; q < cnt[p]; ++q) s->agg[adj[q]] = (int)na;
        na++;
    }
    for (p = 0; p < n; ++p) mark[p] = s->agg[p]; /* 2: the rest join a neighbour's (of step 1) */
    for (p = 0; p < n; ++p)
        if (s->agg[p] < 0)
            for (q = beg[p]; q < cnt[p]; ++q)
                if (mark[adj[q]] >= 0) {
                    s->agg[p] = mark[adj[q]];
                    break;
                }
    for (p = 0; p < n; ++p) /* 3: isolated rows (a node of no element) alone */
        if (s->agg[p] < 0) s->agg[p] = (int)na++;
    s->nagg = na, s->nm = nm, s->cnc = na * (size_t)nm;
    /* the aggregates' rows (counting sort) and graph */
    s->abeg = (size_t *)pn_alloc(al, sizeof(size_t) * ((na + 1) + n + na + 2 * s->cnc + 1));
    if (!s->abeg) goto done;
    s->arow = s->abeg + na + 1, s->apos = s->arow + n, s->cfc = s->apos + na, s->crs = s->cfc + s->cnc;
    memset(s->abeg, 0, sizeof(size_t) * (na + 1));
    for (p = 0; p < n; ++p) s->abeg[s->agg[p] + 1]++;
    for (a = 0; a < na; ++a) s->abeg[a + 1] += s->abeg[a];
    for (a = 0; a < na; ++a) ab[a] = s->abeg[a];
    for (p = 0; p < n; ++p) s->arow[ab[s->agg[p]]++] = p;
    for (a = 0; a < na; ++a) mark[a] = -1;
    for (ab[0] = 0, a = 0; a < na; ++a) { /* neighbours of aggregate a: at most the fine edges out of it */
        acnt[a] = ab[a];
        for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b)
            for (p = s->arow[b], q = beg[p]; q < cnt[p]; ++q) {
                int o = s->agg[adj[q]];
                if (o != (int)a && mark[o] != (int)a) mark[o] = (int)a, aadj[acnt[a]++] = (size_t)o;
            }
        ab[a + 1] = acnt[a];
    }
    pos = beg; /* reused: the RCM order of the aggregates */
    pn__fem_rcm(na, ab, acnt, aadj, pos, seen, deg);
    for (a = 0; a < na; ++a) s->apos[pos[a]] = a;
    for (a = 0; a < na; ++a) { /* the skyline: row (position, mode) from the first neighbour's position */
        size_t lo = s->apos[a], c;
        int k;
        for (q = ab[a]; q < acnt[a]; ++q) lo = PN__MIN(lo, s->apos[aadj[q]]);
        for (k = 0; k < nm; ++k) s->cfc[s->apos[a] * (size_t)nm + (size_t)k] = lo * (size_t)nm;
        (void)c;
    }
    for (q = 0; q < s->cnc; ++q) s->crs[q] = nnz, nnz += q - s->cfc[q] + 1;
    s->crs[s->cnc] = nnz;
    s->cL = (pn_real *)pn_alloc(al, sizeof(pn_real) * (nnz + s->cnc));
    s->P = (pn_real *)pn_alloc(al, sizeof(pn_real) * (n * (size_t)(d * nm) + 2 * (n + PN_FEM_MAX_OBSTACLES) * (size_t)d));
    if (!s->cL || !s->P) goto done;
    s->cv = s->cL + nnz;
    s->pt = s->P + n * (size_t)(d * nm), s->pz = s->pt + (n + PN_FEM_MAX_OBSTACLES) * (size_t)d;
    r = PN_OK;
done:
    pn_free(al, beg), pn_free(al, mark), pn_free(al, seen);
    return r;
}

/* the coarse add of v at coarse unknowns (r, c), either triangle */
#define PN__FEM_CADD(s, r, c, v)                                                                  \
    do {                                                                                          \
        size_t r_ = (r), c_ = (c);                                                                \
        if (r_ < c_) r_ = (c), c_ = (r);                                                          \
        (s)->cL[(s)->crs[r_] + c_ - (s)->cfc[r_]] += (v);                                         \
    } while (0)

/* P at the iterate x (rigid motions of each aggregate about its centre, rotations over its
   size, orthonormalized by Gram-Schmidt; a mode an aggregate cannot have, a rotation of one
   node, stays 0; driven nodes have none), then P^T A P, factored. 0 if that is not positive
   definite. */
static int pn__fem_coarse_build(pn_fem_mesh *m, const pn_real *x) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = s->d, nm = s->nm, dd = d * d, i, j, k, l;
    size_t a, b, p, q;
    memset(s->P, 0, sizeof(pn_real) * m->n_nodes * (size_t)(d * nm));
    for (a = 0; a < s->nagg; ++a) {
        pn_real c[3] = {0, 0, 0}, size = 0, cnt = 0;
        for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b) {
            size_t node = s->perm[s->arow[b]];
            if (!PN__FEM_FREE(m, node)) continue;
            for (i = 0; i < d; ++i) c[i] += x[node * (size_t)d + (size_t)i];
            cnt += 1;
        }
        if (!(cnt > 0)) continue;
        for (i = 0; i < d; ++i) c[i] /= cnt;
        for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b) {
            size_t node = s->perm[s->arow[b]];
            pn_real *Pp = s->P + s->arow[b] * (size_t)(d * nm), rr[3] = {0, 0, 0};
            if (!PN__FEM_FREE(m, node)) continue;
            for (i = 0; i < d; ++i) rr[i] = x[node * (size_t)d + (size_t)i] - c[i], size = PN__MAX(size, PN__FABS(rr[i]));
            for (i = 0; i < d; ++i) Pp[i * nm + i] = 1; /* translations */
            if (d == 2) Pp[0 * nm + 2] = -rr[1], Pp[1 * nm + 2] = rr[0];
            else { /* omega x r for omega = e_0, e_1, e_2 */
                Pp[1 * nm + 3] = -rr[2], Pp[2 * nm + 3] = rr[1];
                Pp[0 * nm + 4] = rr[2], Pp[2 * nm + 4] = -rr[0];
                Pp[0 * nm + 5] = -rr[1], Pp[1 * nm + 5] = rr[0];
            }
        }
        for (k = 0; k < nm; ++k) { /* modified Gram-Schmidt over the aggregate's rows */
            pn_real nrm = 0, ref = k < d ? 1 : size * size; /* a rotation's scale */
            for (l = 0; l < k; ++l) {
                pn_real dot = 0;
                for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b)
                    for (i = 0; i < d; ++i) {
                        const pn_real *Pp = s->P + s->arow[b] * (size_t)(d * nm);
                        dot += Pp[i * nm + k] * Pp[i * nm + l];
                    }
                for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b)
                    for (i = 0; i < d; ++i) {
                        pn_real *Pp = s->P + s->arow[b] * (size_t)(d * nm);
                        Pp[i * nm + k] -= dot * Pp[i * nm + l];
                    }
            }
            for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b)
                for (i = 0; i < d; ++i) nrm += s->P[s->arow[b] * (size_t)(d * nm) + (size_t)(i * nm + k)] * s->P[s->arow[b] * (size_t)(d * nm) + (size_t)(i * nm + k)];
            nrm = PN__SQRT(nrm);
            for (b = s->abeg[a]; b < s->abeg[a + 1]; ++b)
                for (i = 0; i < d; ++i) {
                    pn_real *Pp = s->P + s->arow[b] * (size_t)(d * nm);
                    Pp[i * nm + k] = nrm > (pn_real)1e-6 * PN__SQRT(ref) ? Pp[i * nm + k] / nrm : 0;
                }
        }
    }
    memset(s->cL, 0, sizeof(pn_real) * s->crs[s->cnc]);
    for (p = 0; p < m->n_nodes; ++p) /* P^T A P over the node blocks (both triangles of A) */
        for (q = s->brs[p]; q < s->brs[p + 1]; ++q) {
            size_t kr = (size_t)s->bcol[q], I = s->apos[s->agg[p]], J = s->apos[s->agg[kr]];
            const pn_real *A = s->bA + q * (size_t)dd, *Pp = s->P + p * (size_t)(d * nm), *Pk = s->P + kr * (size_t)(d * nm);
            pn_real AP[18], W[36];
            int diag = kr == p;
            for (i = 0; i < d; ++i) /* A_pk P_k */
                for (l = 0; l < nm; ++l) {
                    pn_real acc = 0;
                    for (j = 0; j < d; ++j) acc += (diag ? A[i >= j ? i * d + j : j * d + i] : A[i * d + j]) * Pk[j * nm + l];
                    AP[i * nm + l] = acc;
                }
            for (k = 0; k < nm; ++k)
                for (l = 0; l < nm; ++l) {
                    pn_real acc = 0;
                    for (i = 0; i < d; ++i) acc += Pp[i * nm + k] * AP[i * nm + l];
                    W[k * nm + l] = acc;
                }
            for (k = 0; k < nm; ++k)
                for (l = 0; l < nm; ++l) {
                    size_t rr = I * (size_t)nm + (size_t)k, cc = J * (size_t)nm + (size_t)l;
                    if (diag) { /* P_p^T A_pp P_p: symmetric, its lower half once */
                        if (l <= k) PN__FEM_CADD(s, rr, cc, W[k * nm + l]);
                    } else if (I != J || k != l) PN__FEM_CADD(s, rr, cc, W[k * nm + l]); /* and its mirror block */
                    else PN__FEM_CADD(s, rr, cc, 2 * W[k * nm + l]);
                }
        }
    for (q = 0; q < s->cnc; ++q) /* modes an aggregate lacks: decoupled */
        if (s->cL[s->crs[q] + q - s->cfc[q]] == 0) s->cL[s->crs[q] + q - s->cfc[q]] = 1;
    return pn__sky_cholesky(s->cfc, s->crs, s->cL, s->cnc);
}

static void pn__fem_cg_apply(void *ctx, const pn_real *x, pn_real *y);

/* The two-grid cycle is symmetric positive definite where the smoothing converges on its
   own, omega lambda_max((L D L^T)^-1 A) < 2; an incomplete factorization that broke down and
   was shifted can exceed that (CG then took 4,299 iterations; damped, 67). lambda_max by
   8 power iterations (an estimate from below), omega = min(1, 1.5 / lambda). */
static pn_real pn__fem_smoother_damping(pn_fem_mesh *m) {
    pn__fem *s = (pn__fem *)m->impl;
    size_t k, nu = s->nu;
    pn_real lam = 0, *v = s->cgp, *w = s->cgq;
    int it;
    for (k = 0; k < nu; ++k) v[k] = (pn_real)1 + (pn_real)(k % 7) / 7; /* fixed: the same bits every run */
    for (it = 0; it < 8; ++it) {
        pn_real vAv = 0, wAv = 0, nrm = 0;
        pn__fem_cg_apply(m, v, w); /* w = A v */
        for (k = 0; k < nu; ++k) vAv += v[k] * w[k];
        pn__fem_bic_solve(s, w, s->pz); /* B^-1 A v */
        for (k = 0; k < nu; ++k) wAv += w[k] * s->pz[k];
        if (!(vAv > 0)) break;
        lam = wAv / vAv; /* the Rayleigh quotient of B^-1 A in the A inner product */
        for (k = 0; k < nu; ++k) nrm = PN__MAX(nrm, PN__FABS(s->pz[k]));
        if (!(nrm > 0)) break;
        for (k = 0; k < nu; ++k) v[k] = s->pz[k] / nrm;
    }
    return lam > (pn_real)1.5 ? (pn_real)1.5 / lam : 1;
}

/* z += P Ac^-1 P^T t */
static void pn__fem_coarse_correct(const pn__fem *s, size_t n, const pn_real *t, pn_real *z) {
    int d = s->d, nm = s->nm, i, k;
    size_t p;
    memset(s->cv, 0, sizeof(pn_real) * s->cnc);
    for (p = 0; p < n; ++p) {
        const pn_real *Pp = s->P + p * (size_t)(d * nm);
        pn_real *cv = s->cv + s->apos[s->agg[p]] * (size_t)nm;
        for (k = 0; k < nm; ++k)
            for (i = 0; i < d; ++i) cv[k] += Pp[i * nm + k] * t[p * (size_t)d + (size_t)i];
    }
    pn__sky_solve(s->cfc, s->crs, s->cL, s->cnc, s->cv);
    for (p = 0; p < n; ++p) {
        const pn_real *Pp = s->P + p * (size_t)(d * nm), *cv = s->cv + s->apos[s->agg[p]] * (size_t)nm;
        for (i = 0; i < d; ++i)
            for (k = 0; k < nm; ++k) z[p * (size_t)d + (size_t)i] += Pp[i * nm + k] * cv[k];
    }
}

/* defined below, used here: */
static void pn__fem_off_apply(const pn_fem_mesh *m, const pn_real *x, pn_real *y); /* >>fem-objective */

/* the shared CG (>>kit, plastinet.h) on the skyline matrix (or the blocks) plus the side list, in row
   order; the skyline's Cholesky factor (or the blocks' incomplete one) preconditions */
static void pn__fem_cg_apply(void *ctx, const pn_real *x, pn_real *y) {
    const pn_fem_mesh *m = (const pn_fem_mesh *)ctx;
    const pn__fem *s = (const pn__fem *)m->impl;
    size_t r, c, nu = s->nu;
    if (s->sparse) {
        pn__fem_bmul(s, x, y);
        pn__fem_off_apply(m, x, y);
        return;
    }
    for (r = 0; r < nu; ++r) y[r] = 0;
    for (r = 0; r < nu; ++r) {
        const pn_real *Ar = s->A + s->rs[r];
        size_t f = s->fc[r];
        for (c = f; c < r; ++c) {
            y[r] += Ar[c - f] * x[c];
            y[c] += Ar[c - f] * x[r];
        }
        y[r] += Ar[r - f] * x[r];
    }
    pn__fem_off_apply(m, x, y);
}

static void pn__fem_cg_precond(void *ctx, const pn_real *r, pn_real *z) {
    const pn_fem_mesh *m = (const pn_fem_mesh *)ctx;
    const pn__fem *s = (const pn__fem *)m->impl;
    if (s->sparse) { /* a two-grid V(1,1) cycle: IC(0) smoothing, the rigid motions' correction */
        size_t k, nu = s->nu;
        pn__fem_bic_solve(s, r, z);
        if (!s->coarse) return;
        for (k = 0; k < nu; ++k) z[k] *= s->omega;
        pn__fem_cg_apply(ctx, z, s->pt);
        for (k = 0; k < nu; ++k) s->pt[k] = r[k] - s->pt[k];
        pn__fem_coarse_correct(s, m->n_nodes, s->pt, z);
        pn__fem_cg_apply(ctx, z, s->pt);
        for (k = 0; k < nu; ++k) s->pt[k] = r[k] - s->pt[k];
        pn__fem_bic_solve(s, s->pt, s->pz);
        for (k = 0; k < nu; ++k) z[k] += s->omega * s->pz[k];
        return;
    }
    memcpy(z, r, sizeof(pn_real) * s->nu);
    pn__sky_solve(s->fc, s->rs, s->L, s->nu, z);
}

static pn_real pn__fem_cg_dot(void *ctx, size_t n, const pn_real *a, const pn_real *b) {
    pn_real acc = 0;
    size_t k;
    (void)ctx;
    for (k = 0; k < n; ++k) acc += a[k] * b[k];
    return acc;
}

/* choose the step's linear solver and give it its storage (the first step that uses it) */
static pn_result pn__fem_linear_setup(pn_fem_mesh *m, pn_fem_linear_solver ls) {
    pn__fem *s = (pn__fem *)m->impl;
    const pn_allocator *al = &m->desc.allocator;
    int i;
    if (ls < PN_FEM_LINEAR_DEFAULT || ls > PN_FEM_LINEAR_PCG)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_step_implicit: linear_solver %d is not a pn_fem_linear_solver",
                            (int)ls);
    s->sparse = ls == PN_FEM_LINEAR_PCG ||
                (ls == PN_FEM_LINEAR_DEFAULT &&
                 (s->sky_mb > PN_FEM_CHOLESKY_MAX_MB ||
                  s->sky_gflop > (m->dim == 2 ? PN_FEM_CHOLESKY_MAX_GFLOP_2D : PN_FEM_CHOLESKY_MAX_GFLOP_3D)));
    if (s->sparse) {
        for (s->n_mov = 0, i = 0; i < m->n_obstacles; ++i) {
            const pn_real *v = m->obstacles[i].velocity_m_s;
            s->n_mov += v[0] != 0 || v[1] != 0 || v[2] != 0;
        }
        if (pn__fem_sparse_reserve(m) != PN_OK)
            return PN__FAIL(m, PN_ERROR_OUT_OF_MEMORY, "pn_fem_step_implicit: out of memory for the sparse Hessian of %lu "
                                "nodes", (unsigned long)m->n_nodes);
        return PN_OK;
    }
    if (!s->L) {
        s->L = (pn_real *)pn_alloc(al, sizeof(pn_real) * s->nnz);
        s->A = (pn_real *)pn_alloc(al, sizeof(pn_real) * s->nnz);
        if (!s->L || !s->A) {
            pn_free(al, s->L), pn_free(al, s->A);
            s->L = s->A = NULL;
            return PN__FAIL(m, PN_ERROR_OUT_OF_MEMORY, "pn_fem_step_implicit: out of memory for the Cholesky factor "
                                "(%.0f MB; PN_FEM_LINEAR_PCG needs far less)", s->sky_mb);
        }
    }
    return PN_OK;
}

/* ======================================================================================
   >>fem-contact: IPC's barrier b(d) = -(d - dhat)^2 log(d / dhat) on (0, dhat), 0 beyond,
   against the obstacles and between boundary primitives of the mesh (self-contact): in 2D
   each boundary node against each boundary edge (point-edge), in 3D each boundary node
   against each boundary face (point-triangle) and each boundary edge against each other
   (edge-edge); pairs sharing a node are skipped. d is the distance between the primitives'
   closest points. Candidate pairs come from a uniform grid of the items' boxes; continuous
   collision detection bounds the line search's first try.
   ====================================================================================== */

static void pn__fem_barrier(pn_real dist, pn_real dhat, pn_real *b, pn_real *b1, pn_real *b2) {
    pn_real t, l;
    if (dist >= dhat) {
        *b = *b1 = *b2 = 0;
        return;
    }
    t = dist - dhat, l = PN__LOG(dist / dhat);
    *b = -t * t * l;
    *b1 = -2 * t * l - t * t / dist;
    *b2 = -2 * l - 4 * t / dist + t * t / (dist * dist);
}

enum { PN__FEM_PE, PN__FEM_PT, PN__FEM_EE }; /* pair kinds: nodes (p, a, b), (p, a, b, c), (a, b, c, d) */

/* the squared distance |r|^2 of r = sum_i c_i y_i over nv nodes y (d reals each), with c
   affine in nf free parameters t (dC[j] = dc/dt_j) at the t that minimizes it: the gradient
   is 2 c_i r (t optimal: the envelope theorem) and the Hessian is the Schur complement on t
   of the Hessian of f(y, t) = |r|^2 in (y, t). gn: the Gauss-Newton part only (2 c_i c_k I),
   for nearly parallel edges, whose exact Hessian grows as 1 / sin^2 of their angle. */
static pn_real pn__fem_pair_eval(int d, int nv, const pn_real *y, const pn_real *c, int nf, const pn_real *dC, int gn,
                                 pn_real *g, pn_real *H) {
    pn_real r[3] = {0, 0, 0}, R[2][3] = {{0, 0, 0}, {0, 0, 0}}, X[12][2], Tt[2][2], det, Ti[2][2];
    int n = nv * d, i, k, a, b, j, l;
    for (i = 0; i < nv; ++i)
        for (a = 0; a < d; ++a) {
            r[a] += c[i] * y[i * d + a];
            for (j = 0; j < nf; ++j) R[j][a] += dC[4 * j + i] * y[i * d + a];
        }
    if (g)
        for (i = 0; i < nv; ++i)
            for (a = 0; a < d; ++a) g[i * d + a] = 2 * c[i] * r[a];
    if (H) {
        for (i = 0; i < n; ++i)
            for (k = 0; k < n; ++k) H[i * n + k] = i % d == k % d ? 2 * c[i / d] * c[k / d] : 0;
        if (nf && !gn) {
            for (i = 0; i < nv; ++i) /* f's mixed derivatives d2f / dy_ia dt_j */
                for (a = 0; a < d; ++a)
                    for (j = 0; j < nf; ++j) X[i * d + a][j] = 2 * (c[i] * R[j][a] + r[a] * dC[4 * j + i]);
            for (j = 0; j < nf; ++j)
                for (l = 0; l < nf; ++l) {
                    Tt[j][l] = 0;
                    for (a = 0; a < d; ++a) Tt[j][l] += 2 * R[j][a] * R[l][a];
                }
            if (nf == 1) Ti[0][0] = 1 / Tt[0][0];
            else {
                det = Tt[0][0] * Tt[1][1] - Tt[0][1] * Tt[1][0];
                Ti[0][0] = Tt[1][1] / det, Ti[1][1] = Tt[0][0] / det, Ti[0][1] = Ti[1][0] = -Tt[0][1] / det;
            }
            for (i = 0; i < n; ++i)
                for (k = 0; k < n; ++k)
                    for (j = 0; j < nf; ++j)
                        for (b = 0; b < nf; ++b) H[i * n + k] -= X[i][j] * Ti[j][b] * X[k][b];
        }
    }
    return r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
}

/* node slot ip against the segment of slots ia, ib: c and dC (zeroed first) for the closest
   point, the number of free parameters; the squared distance */
static pn_real pn__fem_pseg(int d, const pn_real *y, int ip, int ia, int ib, pn_real *c, pn_real *dC, int *nf) {
    pn_real e2 = 0, we = 0, t, dist2 = 0;
    int a;
    for (a = 0; a < 8; ++a) c[a % 4] = 0, dC[a] = 0;
    for (a = 0; a < d; ++a) {
        pn_real e = y[ib * d + a] - y[ia * d + a];
        e2 += e * e, we += (y[ip * d + a] - y[ia * d + a]) * e;
    }
    t = e2 > 0 ? we / e2 : 0;
    c[ip] = 1, *nf = 0;
    if (t <= 0) c[ia] = -1;
    else if (t >= 1) c[ib] = -1;
    else c[ia] = -(1 - t), c[ib] = -t, dC[ia] = 1, dC[ib] = -1, *nf = 1;
    for (a = 0; a < d; ++a) {
        pn_real r = c[ip] * y[ip * d + a] + c[ia] * y[ia * d + a] + c[ib] * y[ib * d + a];
        dist2 += r * r;
    }
    return dist2;
}

/* the squared distance of a pair (kind PN__FEM_PE in d = 2, PT or EE in d = 3; y the nodes'
   positions) with its gradient g and Hessian H (optional) over the nodes' coordinates. The
   closest points' features (vertex, edge interior, face interior) are found first; on a
   feature switch the distance is C1, its Hessian jumps. */
static pn_real pn__fem_pair_d2(int kind, int d, const pn_real *y, pn_real *g, pn_real *H) {
    pn_real c[4] = {0, 0, 0, 0}, dC[8] = {0, 0, 0, 0, 0, 0, 0, 0}, cb[4], dCb[8], best = PN__FEM_FAR, e[2][3], w[3];
    pn_real A00 = 0, A01 = 0, A11 = 0, b0 = 0, b1 = 0, det, u, v;
    int nf = 0, nfb, gn = 0, nv = kind == PN__FEM_PE ? 3 : 4, a, k, interior = 0;
    static const int pt_edges[3][2] = {{1, 2}, {2, 3}, {3, 1}}, ee_ends[4][3] = {{0, 2, 3}, {1, 2, 3}, {2, 0, 1}, {3, 0, 1}};
    if (kind == PN__FEM_PE) {
        (void)pn__fem_pseg(d, y, 0, 1, 2, c, dC, &nf);
        return pn__fem_pair_eval(d, 3, y, c, nf, dC, 0, g, H);
    }
    /* PT: the projection on the face's plane, p - a = u e0 + v e1 + r; EE: the lines' closest
       points, r = (a - c) + u (b - a) - v (d - c) */
    for (a = 0; a < 3; ++a) {
        if (kind == PN__FEM_PT) e[0][a] = y[6 + a] - y[3 + a], e[1][a] = y[9 + a] - y[3 + a], w[a] = y[a] - y[3 + a];
        else e[0][a] = y[3 + a] - y[a], e[1][a] = y[9 + a] - y[6 + a], w[a] = y[a] - y[6 + a];
        A00 += e[0][a] * e[0][a], A01 += e[0][a] * e[1][a], A11 += e[1][a] * e[1][a];
        b0 += w[a] * e[0][a], b1 += w[a] * e[1][a];
    }
    det = A00 * A11 - A01 * A01;
    if (kind == PN__FEM_PT && det > (pn_real)1e-12 * A00 * A11) {
        u = (A11 * b0 - A01 * b1) / det, v = (A00 * b1 - A01 * b0) / det;
        if (u > 0 && v > 0 && u + v < 1) {
            c[0] = 1, c[1] = -(1 - u - v), c[2] = -u, c[3] = -v;
            dC[1] = 1, dC[2] = -1, dC[5] = 1, dC[7] = -1, nf = 2, interior = 1;
        }
    } else if (kind == PN__FEM_EE && det > (pn_real)1e-12 * A00 * A11) {
        /* minimize |w + u e0 - v e1|^2: [A00 -A01; -A01 A11] (u, v) = (-b0, b1) */
        u = (-A11 * b0 + A01 * b1) / det, v = (A00 * b1 - A01 * b0) / det;
        if (u > 0 && u < 1 && v > 0 && v < 1) {
            c[0] = 1 - u, c[1] = u, c[2] = -(1 - v), c[3] = -v;
            dC[0] = -1, dC[1] = 1, dC[6] = 1, dC[7] = -1, nf = 2, interior = 1;
            gn = det < (pn_real)1e-6 * A00 * A11; /* nearly parallel */
        }
    }
    if (!interior) /* the closest points lie on the features' boundaries: the least of the
                      point-segment distances there (a convex problem's minimum off its
                      unconstrained one is on the boundary) */
        for (k = 0; k < (kind == PN__FEM_PT ? 3 : 4); ++k) {
            pn_real q = kind == PN__FEM_PT ? pn__fem_pseg(d, y, 0, pt_edges[k][0], pt_edges[k][1], cb, dCb, &nfb)
                                           : pn__fem_pseg(d, y, ee_ends[k][0], ee_ends[k][1], ee_ends[k][2], cb, dCb, &nfb);
            if (q < best) {
                best = q, nf = nfb;
                memcpy(c, cb, sizeof c), memcpy(dC, dCb, sizeof dC);
            }
        }
    return pn__fem_pair_eval(d, nv, y, c, nf, dC, gn, g, H);
}

/* The barrier w b(d) of a pair (kind as pn__fem_pair_d2, nv nodes at y) with the distance d
   of its closest points into *dist; when d < dhat, w b(d) into *E and, by level, its gradient
   g (level >= 1) and its Hessian H over the nv d coordinates (level >= 2; PSD-projected when
   project), all zero when d >= dhat. Returns 0 when d <= 0 (the primitives touch: no barrier
   exists), else 1. FEM self-contact and the MPM-FEM interface share it. */
static int pn__pair_barrier(int kind, int d, int nv, const pn_real *y, pn_real dhat, pn_real w, int level, pn_real *E,
                            pn_real *g, pn_real *H, pn_real *dist, int project) {
    pn_real sq, dd, bb, b1, b2, gs[12];
    int n = nv * d, i, j;
    sq = pn__fem_pair_d2(kind, d, y, level >= 1 ? gs : NULL, level >= 2 ? H : NULL);
    dd = *dist = PN__SQRT(sq);
    *E = 0;
    for (i = 0; level >= 1 && i < n; ++i) g[i] = 0;
    if (!(dd > 0)) return 0;
    if (dd >= dhat) {
        for (i = 0; level >= 2 && i < n * n; ++i) H[i] = 0;
        return 1;
    }
    pn__fem_barrier(dd, dhat, &bb, &b1, &b2);
    *E = w * bb;
    for (i = 0; level >= 1 && i < n; ++i) g[i] = w * b1 * gs[i] / (2 * dd); /* grad b(d) = b' grad s / (2 d) */
    if (level < 2) return 1;
    for (i = 0; i < n; ++i) /* b'' grad d grad d^T + b' hess d */
        for (j = 0; j < n; ++j) {
            pn_real gi = gs[i] / (2 * dd), gj = gs[j] / (2 * dd);
            H[i * n + j] = w * (b2 * gi * gj + b1 * (H[i * n + j] / (2 * dd) - gs[i] * gs[j] / (4 * dd * dd * dd)));
        }
    if (project) pn_sym_project_psd(n, H);
    return 1;
}

/* Additive CCD (Li, Kaufman and Jiang 2021) of a pair moving from y along dy (nv nodes, the
   first na on one side): the largest t in [0, tmax] to which the pair can move without its
   distance closing below a tenth of the starting one. Advance while the distance cannot have
   closed, by 0.9 of the distance over the bound of the pair's relative motion (each side's
   largest motion after the pair's mean translation). lower: a lower bound on the starting
   distance (or 0), which returns tmax at once when the first advance would reach it. */
static pn_real pn__pair_ccd(int kind, int d, int nv, int na, const pn_real *y, const pn_real *dy, pn_real lower,
                            pn_real tmax) {
    pn_real mean[3] = {0, 0, 0}, la = 0, lb = 0, lp, t = 0, d0 = 0, yt[12];
    int i, j, it;
    for (j = 0; j < nv; ++j)
        for (i = 0; i < d; ++i) mean[i] += dy[j * d + i] / (pn_real)nv;
    for (j = 0; j < nv; ++j) {
        pn_real v2 = 0;
        for (i = 0; i < d; ++i) v2 += (dy[j * d + i] - mean[i]) * (dy[j * d + i] - mean[i]);
        if (j < na) la = PN__MAX(la, PN__SQRT(v2));
        else lb = PN__MAX(lb, PN__SQRT(v2));
    }
    lp = la + lb;
    if (!(lp > 0) || (pn_real)0.9 * lower / lp >= tmax) return tmax;
    for (it = 0; it < 1000; ++it) {
        pn_real dist, step;
        for (i = 0; i < nv * d; ++i) yt[i] = y[i] + t * dy[i];
        dist = PN__SQRT(pn__fem_pair_d2(kind, d, yt, NULL, NULL));
        if (it == 0) d0 = dist;
        else if (dist < (pn_real)0.1 * d0) break;
        step = (pn_real)0.9 * dist / lp;
        if (t + step >= tmax) return tmax;
        t += step;
    }
    return t;
}

/* the box of grid item k (a target: 2D edge, 3D face; then a 3D edge) at x, swept along
   alpha dir when dir is given, grown by grow */
static void pn__fem_item_box(const pn_fem_mesh *m, size_t k, const pn_real *x, const pn_real *dir, pn_real alpha,
                             pn_real grow, pn_real *lo, pn_real *hi) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int d = m->dim, nv = d == 3 && k < s->ntgt ? 3 : 2, j, i;
    const int *nd = d == 3 && k < s->ntgt ? s->bface + 3 * k : s->bedge + 2 * (k < s->ntgt ? k : k - s->ntgt);
    for (i = 0; i < d; ++i) lo[i] = PN__FEM_FAR, hi[i] = -PN__FEM_FAR;
    for (j = 0; j < nv; ++j)
        for (i = 0; i < d; ++i) {
            size_t c = (size_t)nd[j] * (size_t)d + (size_t)i;
            pn_real a = x[c], b = dir ? x[c] + alpha * dir[c] : a;
            lo[i] = PN__MIN(lo[i], PN__MIN(a, b)), hi[i] = PN__MAX(hi[i], PN__MAX(a, b));
        }
    for (i = 0; i < d; ++i) lo[i] -= grow, hi[i] += grow;
}

/* the cell range [c0, c1] per axis a box covers in the items' grid (clamped) */
static void pn__fem_cells(const pn__fem *s, int d, const pn_real *lo, const pn_real *hi, long *c0, long *c1) {
    int i;
    for (i = 0; i < d; ++i) {
        pn_real a = (lo[i] - s->glo[i]) / s->gcs, b = (hi[i] - s->glo[i]) / s->gcs;
        c0[i] = a < 0 ? 0 : a >= (pn_real)s->gn[i] ? s->gn[i] - 1 : (long)a;
        c1[i] = b < 0 ? 0 : b >= (pn_real)s->gn[i] ? s->gn[i] - 1 : (long)b;
    }
}

static size_t pn__fem_cell_at(const pn__fem *s, const long *c) { return (size_t)((c[2] * s->gn[1] + c[1]) * s->gn[0] + c[0]); }

/* the box of boundary node p (swept) */
static void pn__fem_node_box(const pn_fem_mesh *m, size_t p, const pn_real *x, const pn_real *dir, pn_real alpha,
                             pn_real *lo, pn_real *hi) {
    int i, d = m->dim;
    for (i = 0; i < d; ++i) {
        pn_real a = x[p * (size_t)d + (size_t)i], b = dir ? a + alpha * dir[p * (size_t)d + (size_t)i] : a;
        lo[i] = PN__MIN(a, b), hi[i] = PN__MAX(a, b);
    }
}

/* The broad phase: the items' boxes and a uniform grid over them with cells as large as the
   largest box (of the items and the boundary nodes: each box in at most 2 cells per axis),
   no more than gcap cells; CSR of item indices per cell */
static void pn__fem_grid_build(pn_fem_mesh *m, const pn_real *x, const pn_real *dir, pn_real alpha, pn_real grow) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, i;
    pn_real hi[3] = {-PN__FEM_FAR, -PN__FEM_FAR, -PN__FEM_FAR}, ext = 0, lo[3], up[3];
    size_t k, q, cells;
    long c, c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0}, cc[3];
    int pass;
    s->glo[0] = s->glo[1] = s->glo[2] = 0;
    for (i = 0; i < d; ++i) s->glo[i] = PN__FEM_FAR;
    for (k = 0; k < s->nitem; ++k) {
        pn_real *b = s->ebox + 6 * k;
        pn__fem_item_box(m, k, x, dir, alpha, grow, b, b + 3);
        for (i = 0; i < d; ++i)
            s->glo[i] = PN__MIN(s->glo[i], b[i]), hi[i] = PN__MAX(hi[i], b[3 + i]), ext = PN__MAX(ext, b[3 + i] - b[i]);
    }
    for (q = 0; q < s->nbn; ++q) {
        pn__fem_node_box(m, s->bnode[q], x, dir, alpha, lo, up);
        for (i = 0; i < d; ++i) ext = PN__MAX(ext, up[i] - lo[i]);
    }
    s->gcs = ext > 0 ? ext : 1;
    s->gn[2] = 1;
    for (;;) {
        for (cells = 1, i = 0; i < d; ++i) s->gn[i] = (long)((hi[i] - s->glo[i]) / s->gcs) + 1, cells *= (size_t)s->gn[i];
        if (cells <= s->gcap) break;
        s->gcs *= 2;
    }
    for (c = 0; c <= (long)cells; ++c) s->gstart[c] = 0;
    for (pass = 0; pass < 2; ++pass) { /* count, then place (a counting sort by cell) */
        for (k = 0; k < s->nitem; ++k) {
            pn__fem_cells(s, d, s->ebox + 6 * k, s->ebox + 6 * k + 3, c0, c1);
            for (cc[2] = c0[2]; cc[2] <= c1[2]; ++cc[2])
                for (cc[1] = c0[1]; cc[1] <= c1[1]; ++cc[1])
                    for (cc[0] = c0[0]; cc[0] <= c1[0]; ++cc[0]) {
                        size_t cell = pn__fem_cell_at(s, cc);
                        if (pass == 0) s->gstart[cell + 1]++;
                        else s->gitem[s->gstart[cell]++] = k;
                    }
        }
        if (pass == 0)
            for (c = 0; c < (long)cells; ++c) s->gstart[c + 1] += s->gstart[c];
    }
    for (c = (long)cells; c > 0; --c) s->gstart[c] = s->gstart[c - 1]; /* back to starts */
    s->gstart[0] = 0;
}

typedef struct pn__fem_pair {
    int kind, nv, na; /* kind, nodes, the nodes on the first side (1: a node, 2: an edge) */
    size_t n[4];
} pn__fem_pair;

/* a pair's visitor: nonzero stops the search */
typedef int (*pn__fem_visit)(pn_fem_mesh *m, const pn__fem_pair *pr, void *ctx);

/* do boxes a and b (lo[3], hi[3]) overlap, and is cell cc the one of their overlap's low
   corner (so that a pair found in several cells is visited once)? */
static int pn__fem_pair_here(const pn__fem *s, int d, const pn_real *alo, const pn_real *ahi, const pn_real *blo,
                             const pn_real *bhi, const long *cc) {
    pn_real lo[3] = {0, 0, 0};
    long c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0};
    int i;
    for (i = 0; i < d; ++i) {
        if (ahi[i] < blo[i] || alo[i] > bhi[i]) return 0;
        lo[i] = PN__MAX(alo[i], blo[i]);
    }
    pn__fem_cells(s, d, lo, lo, c0, c1);
    for (i = 0; i < d; ++i)
        if (c0[i] != cc[i]) return 0;
    return 1;
}

/* the pair of boundary node p (or 3D edge p when edge) and item k: 0 when they share a node
   or all its nodes are held */
static int pn__fem_pair_make(const pn_fem_mesh *m, int edge, size_t p, size_t k, pn__fem_pair *pr) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int d = m->dim, j, i, fixed = 1;
    const int *tn = edge ? s->bedge + 2 * (k - s->ntgt) : d == 2 ? s->bedge + 2 * k : s->bface + 3 * k;
    pr->kind = edge ? PN__FEM_EE : d == 2 ? PN__FEM_PE : PN__FEM_PT;
    pr->nv = edge ? 4 : d + 1, pr->na = edge ? 2 : 1;
    if (edge) pr->n[0] = (size_t)s->bedge[2 * p], pr->n[1] = (size_t)s->bedge[2 * p + 1];
    else pr->n[0] = p;
    for (j = pr->na; j < pr->nv; ++j) pr->n[j] = (size_t)tn[j - pr->na];
    for (j = 0; j < pr->nv; ++j) {
        fixed &= m->fixed[pr->n[j]] != 0;
        for (i = pr->na; j < pr->na && i < pr->nv; ++i)
            if (pr->n[i] == pr->n[j]) return 0;
    }
    return !fixed;
}

/* a lower bound on the distance between the pair's two sides at x: the distance of their
   bounding spheres (centre the side's mean node, radius its farthest node); rules out at a
   few flops the pairs a box test lets through, coplanar neighbours on a flat surface above all */
static pn_real pn__fem_pair_bound(const pn_fem_mesh *m, const pn__fem_pair *pr, const pn_real *x) {
    int d = m->dim, side, j, i;
    pn_real c[2][3] = {{0, 0, 0}, {0, 0, 0}}, rad[2] = {0, 0}, cc = 0;
    for (side = 0; side < 2; ++side) {
        int j0 = side ? pr->na : 0, j1 = side ? pr->nv : pr->na;
        for (j = j0; j < j1; ++j)
            for (i = 0; i < d; ++i) c[side][i] += x[pr->n[j] * (size_t)d + (size_t)i] / (pn_real)(j1 - j0);
        for (j = j0; j < j1; ++j) {
            pn_real r2 = 0;
            for (i = 0; i < d; ++i) {
                pn_real u = x[pr->n[j] * (size_t)d + (size_t)i] - c[side][i];
                r2 += u * u;
            }
            rad[side] = PN__MAX(rad[side], r2);
        }
    }
    for (i = 0; i < d; ++i) cc += (c[0][i] - c[1][i]) * (c[0][i] - c[1][i]);
    return PN__SQRT(cc) - PN__SQRT(rad[0]) - PN__SQRT(rad[1]);
}

/* Every boundary pair whose boxes overlap (at x, swept along alpha dir when dir is given,
   the items' grown by grow), once each, in a fixed order, except pairs of held nodes only:
   the boundary nodes against the targets, then (3D) each edge against the later edges; fn
   visits them. Returns nonzero when fn stopped. */
static int pn__fem_pairs(pn_fem_mesh *m, const pn_real *x, const pn_real *dir, pn_real alpha, pn_real grow,
                         pn__fem_visit fn, void *ctx) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, i;
    size_t q, it, nq = s->nbn + (d == 3 ? s->nbe : 0);
    long c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0}, cc[3];
    pn_real lo[3], hi[3];
    pn__fem_pair pr;
    if (!s->nitem) return 0;
    pn__fem_grid_build(m, x, dir, alpha, grow);
    for (q = 0; q < nq; ++q) {
        int edge = q >= s->nbn;
        size_t qe = q - (edge ? s->nbn : 0);
        if (edge)
            for (i = 0; i < d; ++i) lo[i] = s->ebox[6 * (s->ntgt + qe) + (size_t)i], hi[i] = s->ebox[6 * (s->ntgt + qe) + 3 + (size_t)i];
        else pn__fem_node_box(m, s->bnode[q], x, dir, alpha, lo, hi);
        pn__fem_cells(s, d, lo, hi, c0, c1);
        for (cc[2] = c0[2]; cc[2] <= c1[2]; ++cc[2])
            for (cc[1] = c0[1]; cc[1] <= c1[1]; ++cc[1])
                for (cc[0] = c0[0]; cc[0] <= c1[0]; ++cc[0]) {
                    size_t cell = pn__fem_cell_at(s, cc);
                    for (it = s->gstart[cell]; it < s->gstart[cell + 1]; ++it) {
                        size_t k = s->gitem[it];
                        if (edge ? k <= s->ntgt + qe : k >= s->ntgt) continue;
                        if (!pn__fem_pair_here(s, d, lo, hi, s->ebox + 6 * k, s->ebox + 6 * k + 3, cc)) continue;
                        if (!pn__fem_pair_make(m, edge, edge ? qe : s->bnode[q], k, &pr)) continue;
                        if (!dir && pn__fem_pair_bound(m, &pr, x) >= grow) continue; /* not within grow */
                        if (fn(m, &pr, ctx)) return 1;
                    }
                }
    }
    return 0;
}

/* the pair's nodes' positions at x + t dir (dir optional) */
static void pn__fem_pair_y(const pn_fem_mesh *m, const pn__fem_pair *pr, const pn_real *x, const pn_real *dir, pn_real t,
                           pn_real *y) {
    int j, i, d = m->dim;
    for (j = 0; j < pr->nv; ++j)
        for (i = 0; i < d; ++i) {
            size_t c = pr->n[j] * (size_t)d + (size_t)i;
            y[j * d + i] = x[c] + (dir ? t * dir[c] : 0);
        }
}

typedef struct pn__fem_self_ctx {
    const pn_real *x;
    int mode;
    pn_real E, dmin;
    pn_result r;
} pn__fem_self_ctx;

/* one pair's barrier into E (and g, the skyline or the side list by mode) */
static int pn__fem_self_visit(pn_fem_mesh *m, const pn__fem_pair *pr, void *vctx) {
    pn__fem_self_ctx *cx = (pn__fem_self_ctx *)vctx;
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, n = pr->nv * d, i, j, full = 1;
    pn_real y[12], g[12], H[144], dist, e;
    pn__fem_pair_y(m, pr, cx->x, NULL, 0, y);
    if (!pn__pair_barrier(pr->kind, d, pr->nv, y, m->dhat, s->dt * s->dt * m->kappa, cx->mode, &e, g, H, &dist,
                          (s->hflags & PN_EVAL_PROJECT_PSD) != 0)) {
        cx->dmin = PN__MIN(cx->dmin, dist);
        m->error_node = (long)pr->n[0];
        cx->r = PN_ERROR_STEP_TOO_LARGE;
        return 1;
    }
    cx->dmin = PN__MIN(cx->dmin, dist);
    if (dist >= m->dhat) return 0;
    cx->E += e;
    if (cx->mode >= 1)
        for (i = 0; i < n; ++i)
            if (PN__FEM_FREE(m, pr->n[i / d])) s->g[pr->n[i / d] * (size_t)d + (size_t)(i % d)] += g[i];
    if (cx->mode < 2) return 0;
    for (i = 0; i < pr->nv; ++i)
        for (j = 0; j < i; ++j) full &= pn__fem_in_profile(m, pr->n[i], pr->n[j]);
    if (!full && s->n_off >= s->cap_off) { /* more pairs than ever before: twice the room */
        const pn_allocator *al = &m->desc.allocator;
        size_t cap = 2 * s->cap_off;
        pn_real *o2 = (pn_real *)pn_alloc(al, sizeof(pn_real) * PN__FEM_PAIR_H(d) * cap);
        int *n2 = (int *)pn_alloc(al, sizeof(int) * 4 * cap);
        if (!o2 || !n2) {
            pn_free(al, o2), pn_free(al, n2);
            cx->r = PN__FAIL(m, PN_ERROR_OUT_OF_MEMORY, "self-contact: out of memory for %lu pairs outside the "
                                 "Hessian's pattern", (unsigned long)cap);
            return 1;
        }
        memcpy(o2, s->off, sizeof(pn_real) * PN__FEM_PAIR_H(d) * s->n_off);
        memcpy(n2, s->off_node, sizeof(int) * 4 * s->n_off);
        pn_free(al, s->off), pn_free(al, s->off_node);
        s->off = o2, s->off_node = n2, s->cap_off = cap;
    }
    for (i = 0; i < n; ++i)
        for (j = 0; j <= i; ++j) {
            size_t ni = pr->n[i / d], nj = pr->n[j / d];
            if (!PN__FEM_FREE(m, ni) || !PN__FEM_FREE(m, nj)) continue;
            if (full || ni == nj)
                pn__fem_hadd(s, pn__fem_row(m, ni * (size_t)d + (size_t)(i % d)), pn__fem_row(m, nj * (size_t)d + (size_t)(j % d)),
                             H[i * n + j]);
        }
    if (!full) { /* the off-diagonal node blocks go to the side list */
        pn_real *o = s->off + PN__FEM_PAIR_H(d) * s->n_off;
        for (i = 0; i < n; ++i)
            for (j = 0; j < n; ++j) {
                int free2 = PN__FEM_FREE(m, pr->n[i / d]) && PN__FEM_FREE(m, pr->n[j / d]);
                o[i * n + j] = i / d != j / d && free2 ? H[i * n + j] : 0;
            }
        for (i = 0; i < 4; ++i) s->off_node[4 * s->n_off + (size_t)i] = i < pr->nv ? (int)pr->n[i] : -1;
        s->n_off++;
    }
    return 0;
}

/* The barrier of every pair within dhat into E (and g, the skyline or the side list by mode);
   the smallest distance into *dmin; PN_ERROR_STEP_TOO_LARGE with error_node set when two
   primitives touch. */
static pn_result pn__fem_self(pn_fem_mesh *m, const pn_real *x, int mode, pn_real *E, pn_real *dmin) {
    pn__fem *s = (pn__fem *)m->impl;
    pn__fem_self_ctx cx;
    if (mode >= 2) s->n_off = 0;
    cx.x = x, cx.mode = mode, cx.E = 0, cx.dmin = *dmin, cx.r = PN_OK;
    pn__fem_pairs(m, x, NULL, 0, m->dhat, pn__fem_self_visit, &cx);
    *E += cx.E, *dmin = cx.dmin;
    return cx.r;
}

typedef struct pn__fem_ccd_ctx {
    const pn_real *x, *dir;
    pn_real best;
} pn__fem_ccd_ctx;

/* one pair's CCD (pn__pair_ccd), the best step so far its limit */
static int pn__fem_ccd_visit(pn_fem_mesh *m, const pn__fem_pair *pr, void *vctx) {
    pn__fem_ccd_ctx *cx = (pn__fem_ccd_ctx *)vctx;
    int d = m->dim, i, j;
    pn_real y[12], dy[12];
    pn__fem_pair_y(m, pr, cx->x, NULL, 0, y);
    for (j = 0; j < pr->nv; ++j)
        for (i = 0; i < d; ++i) dy[j * d + i] = cx->dir[pr->n[j] * (size_t)d + (size_t)i];
    cx->best = pn__pair_ccd(pr->kind, d, pr->nv, pr->na, y, dy, pn__fem_pair_bound(m, pr, cx->x), cx->best);
    return 0;
}

/* the largest step (at most amax) along dir that no boundary pair takes through contact */
static pn_real pn__fem_self_ccd(pn_fem_mesh *m, const pn_real *x, const pn_real *dir, pn_real amax) {
    pn__fem_ccd_ctx cx;
    cx.x = x, cx.dir = dir, cx.best = amax;
    pn__fem_pairs(m, x, dir, amax, 0, pn__fem_ccd_visit, &cx);
    return cx.best;
}

/* The largest step along dir (<= 1) no node takes into an obstacle: 0.9 of the first time of
   contact of each node's straight path with each obstacle (moving with its offset's own step). */
static pn_real pn__fem_ccd(const pn_fem_mesh *m, const pn_real *x, const pn_real *dir) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int d = m->dim, o, i, j;
    size_t k, nd = m->n_nodes * (size_t)d;
    pn_real amax = 1;
    for (o = 0; o < m->n_obstacles; ++o) {
        const pn_collider *c = &m->obstacles[o];
        const pn_real *u = NULL, *du = NULL;
        pn_real t = s->t_end;
        for (j = 0; j < s->n_mov; ++j)
            if (s->mov[j] == o) u = x + nd + (size_t)(j * d), du = dir + nd + (size_t)(j * d), t = m->time_s;
        for (k = 0; k < m->n_nodes; ++k) {
            pn_real r0[3], w[3], hit = 2;
            const pn_real *xk = x + k * (size_t)d;
            if (!PN__FEM_FREE(m, k)) continue;
            for (i = 0; i < d; ++i) {
                r0[i] = xk[i] - (c->center_m[i] + t * c->velocity_m_s[i] + (u ? u[i] : 0));
                w[i] = dir[k * (size_t)d + (size_t)i] - (du ? du[i] : 0);
            }
            if (c->shape == PN_SHAPE_HALF_SPACE) {
                pn_real d0 = 0, rate = 0;
                for (i = 0; i < d; ++i) d0 += r0[i] * c->normal[i], rate += w[i] * c->normal[i];
                if (rate < 0) hit = d0 / -rate;
            } else { /* slabs: the entry of r0 + a w into the box, a in [0, 1] */
                pn_real lo = 0, hi = 1;
                for (i = 0; i < d && lo <= hi; ++i) {
                    pn_real hx = c->half_extent_m[i];
                    if (w[i] == 0) {
                        if (r0[i] <= -hx || r0[i] >= hx) lo = 2;
                    } else {
                        pn_real a1 = (-hx - r0[i]) / w[i], a2 = (hx - r0[i]) / w[i];
                        if (a1 > a2) {
                            pn_real tmp = a1;
                            a1 = a2, a2 = tmp;
                        }
                        lo = PN__MAX(lo, a1), hi = PN__MIN(hi, a2);
                    }
                }
                if (lo <= hi && lo <= 1) hit = lo;
            }
            if (hit <= 1) amax = PN__MIN(amax, (pn_real)0.9 * hit);
        }
    }
    return amax;
}

typedef struct pn__fem_contact_ctx {
    pn_real dmin, *gap_speed, *spring;
} pn__fem_contact_ctx;

/* one self-contact pair's distance, and its terms of the stable step (pn__fem_contacts) */
static int pn__fem_contact_visit(pn_fem_mesh *m, const pn__fem_pair *pr, void *vctx) {
    pn__fem_contact_ctx *cx = (pn__fem_contact_ctx *)vctx;
    int d = m->dim, i, j;
    pn_real y[12], dist, sa = 0, sb = 0, mm = PN__FEM_FAR, bb, b1, b2;
    pn__fem_pair_y(m, pr, m->x, NULL, 0, y);
    dist = PN__SQRT(pn__fem_pair_d2(pr->kind, d, y, NULL, NULL));
    cx->dmin = PN__MIN(cx->dmin, dist);
    if (!cx->gap_speed || !(dist > 0) || dist > 4 * m->dhat) return 0;
    for (j = 0; j < pr->nv; ++j) { /* each side's fastest node: their sum bounds the closing speed */
        pn_real v2 = 0;
        for (i = 0; i < d; ++i) v2 += m->v[pr->n[j] * (size_t)d + (size_t)i] * m->v[pr->n[j] * (size_t)d + (size_t)i];
        if (j < pr->na) sa = PN__MAX(sa, PN__SQRT(v2));
        else sb = PN__MAX(sb, PN__SQRT(v2));
        mm = PN__MIN(mm, m->mass[pr->n[j]]);
    }
    if (sa + sb > 0) *cx->gap_speed = PN__MIN(*cx->gap_speed, (pn_real)0.25 * dist / (sa + sb));
    if (dist < m->dhat) {
        pn__fem_barrier(dist, m->dhat, &bb, &b1, &b2);
        *cx->spring = PN__MIN(*cx->spring, PN__SQRT(mm / (m->kappa * b2)));
    }
    return 0;
}

/* The smallest node-obstacle distance with the obstacles at time t, and (2D) node-edge
   distance of the boundary (of the pairs within 4 dhat); with gap_speed and spring (optional, for pn_fem_stable_dt): the
   least over the contacts of a quarter of the gap over the closing speeds' bound, and of
   sqrt(m / (kappa b''(d))) within dhat. */
static pn_real pn__fem_contacts(const pn_fem_mesh *m, pn_real t, pn_real *gap_speed, pn_real *spring) {
    pn__fem *s = (pn__fem *)m->impl; /* the grid is scratch */
    pn_real dmin = PN__FEM_FAR, nrm[3], bb, b1, b2;
    int o, d = m->dim, i;
    size_t k;
    for (o = 0; o < m->n_obstacles; ++o) {
        const pn_real *vo = m->obstacles[o].velocity_m_s;
        pn_real so = PN__SQRT(vo[0] * vo[0] + vo[1] * vo[1] + vo[2] * vo[2]);
        for (k = 0; k < m->n_nodes; ++k) {
            pn_real dist, v2 = 0, sp;
            if (!PN__FEM_FREE(m, k)) continue;
            dist = pn__fem_obstacle_sd(&m->obstacles[o], d, t, NULL, m->x + k * (size_t)d, nrm);
            dmin = PN__MIN(dmin, dist);
            if (!gap_speed || !(dist > 0)) continue;
            for (i = 0; i < d; ++i) v2 += m->v[k * (size_t)d + (size_t)i] * m->v[k * (size_t)d + (size_t)i];
            sp = PN__SQRT(v2) + so;
            if (sp > 0) *gap_speed = PN__MIN(*gap_speed, (pn_real)0.25 * dist / sp);
            if (dist < m->dhat) {
                pn__fem_barrier(dist, m->dhat, &bb, &b1, &b2);
                *spring = PN__MIN(*spring, PN__SQRT(m->mass[k] / (m->kappa * b2)));
            }
        }
    }
    if (s->nitem) { /* self-contact: the pairs within 4 dhat */
        pn__fem_contact_ctx cx;
        cx.dmin = dmin, cx.gap_speed = gap_speed, cx.spring = spring;
        pn__fem_pairs((pn_fem_mesh *)m, m->x, NULL, 0, 4 * m->dhat, pn__fem_contact_visit, &cx);
        dmin = cx.dmin;
    }
    return dmin;
}

static pn_real pn__fem_min_distance(const pn_fem_mesh *m, pn_real t) { return pn__fem_contacts(m, t, NULL, NULL); }

/* ======================================================================================
   >>fem-objective: the incremental potential of an implicit step, its gradient and Hessian
   (skyline profile in RCM order, or d x d node blocks). Pairs whose Hessian couples nodes
   outside the skyline's profile (two walls of the mesh far apart in the RCM order) go to a
   side list: the solve is then preconditioned CG on the full Hessian with the skyline
   factor (holding those pairs' diagonal blocks) as the preconditioner.
   ====================================================================================== */

/* y += the side list's blocks times x (unknowns in skyline row order) */
static void pn__fem_off_apply(const pn_fem_mesh *m, const pn_real *x, pn_real *y) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int d = m->dim;
    size_t q;
    int i, j;
    for (q = 0; q < s->n_off; ++q) {
        const pn_real *o = s->off + PN__FEM_PAIR_H(d) * q;
        const int *nd = s->off_node + 4 * q;
        int n = (nd[3] < 0 ? 3 : 4) * d;
        size_t row[12];
        for (i = 0; i < n; ++i) row[i] = pn__fem_row(m, (size_t)nd[i / d] * (size_t)d + (size_t)(i % d));
        for (i = 0; i < n; ++i)
            for (j = 0; j < n; ++j) y[row[i]] += o[i * n + j] * x[row[j]];
    }
}

/* E(x) at unknowns x (nodes, then the moving obstacles' offsets u); mode 1: and the gradient
   into s->g; mode 2: and the Hessian into s->L. PN_ERROR_INVERTED for an element turned
   inside out, PN_ERROR_STEP_TOO_LARGE for a node in an obstacle (the line search backs off
   both). */
static pn_result pn__fem_objective(pn_fem_mesh *m, const pn_real *x, int mode, pn_real *E_out) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, dd = d * d, nn = m->nodes_per_element, a, b, i, j, o;
    size_t n = m->n_nodes, nd = n * (size_t)d, k, e, nu = s->nu;
    pn_real dt2 = s->dt * s->dt, E = 0, dmin = PN__FEM_FAR;
    if (mode >= 1) memset(s->g, 0, sizeof(pn_real) * nu);
    if (mode >= 2 && s->sparse) memset(s->bA, 0, sizeof(pn_real) * s->brs[s->brows] * (size_t)(d * d)), s->bmiss = 0;
    else if (mode >= 2) memset(s->L, 0, sizeof(pn_real) * s->rs[nu]);
    for (k = 0; k < n; ++k) { /* inertia */
        if (!PN__FEM_FREE(m, k)) continue;
        for (i = 0; i < d; ++i) {
            size_t c = k * (size_t)d + (size_t)i;
            pn_real dx = x[c] - s->xt[c];
            E += m->mass[k] * dx * dx / 2;
            if (mode >= 1) s->g[c] += m->mass[k] * dx;
            if (mode >= 2) pn__fem_hadd(s, pn__fem_row(m, c), pn__fem_row(m, c), m->mass[k]);
        }
    }
    PN__FEM_OMP_FOR /* each point's Psi, P and H on threads; summed below in point order */
    for (e = 0; e < m->n_points; ++e) {
        pn_real Fe[9];
        pn_result r;
        pn__fem_fe(m, e, x, Fe);
        if (s->elast[e] && !(pn_mat_det(d, Fe) > 0)) {
            s->estat[e] = PN_ERROR_INVERTED;
            continue;
        }
        r = pn__fem_psi(m, e, Fe, &s->epsi[e], mode >= 1 ? s->eP + e * (size_t)dd : NULL,
                        mode >= 2 ? s->eH + e * (size_t)(dd * dd) : NULL);
        s->estat[e] = r != PN_OK ? (int)r : !pn__finite(s->epsi[e]) ? (int)PN_ERROR_OVERFLOW : 0;
    }
    for (e = 0; e < m->n_points; ++e) { /* (e: the point) */
        const pn_real *P = s->eP + e * (size_t)dd, *H = s->eH + e * (size_t)(dd * dd);
        const int *el = m->elem + PN__FEM_ELEM(m, e) * (size_t)nn;
        const pn_real *q = s->q + e * (size_t)(d * nn);
        pn_real V = m->vol0[e] * dt2;
        if (s->estat[e]) {
            m->error_element = (long)PN__FEM_ELEM(m, e);
            return (pn_result)s->estat[e];
        }
        E += V * s->epsi[e];
        if (mode >= 1)
            for (a = 0; a < nn; ++a) {
                size_t na = (size_t)el[a];
                if (!PN__FEM_FREE(m, na)) continue;
                for (i = 0; i < d; ++i) {
                    pn_real acc = 0;
                    for (j = 0; j < d; ++j) acc += P[i * d + j] * q[a * d + j];
                    s->g[na * (size_t)d + (size_t)i] += V * acc;
                }
            }
        if (mode >= 2)
            for (a = 0; a < nn; ++a) {
                size_t na = (size_t)el[a];
                if (!PN__FEM_FREE(m, na)) continue;
                for (b = 0; b <= a; ++b) {
                    size_t nb = (size_t)el[b];
                    int kk, mm, ll;
                    if (!PN__FEM_FREE(m, nb)) continue;
                    pn_real blk[9];
                    for (i = 0; i < d; ++i)
                        for (kk = 0; kk < d; ++kk) {
                            pn_real acc = 0;
                            if (a == b && kk > i) continue; /* the diagonal block's upper half */
                            for (mm = 0; mm < d; ++mm)
                                for (ll = 0; ll < d; ++ll) acc += H[(i * d + mm) * dd + kk * d + ll] * q[a * d + mm] * q[b * d + ll];
                            blk[i * d + kk] = V * acc;
                        }
                    pn__fem_hadd_block(m, s, na, nb, blk);
                }
            }
    }
    for (o = 0; o < m->n_obstacles; ++o) { /* the barrier */
        const pn_collider *c = &m->obstacles[o];
        const pn_real *u = NULL;
        size_t uo = 0;
        for (j = 0; j < s->n_mov; ++j)
            if (s->mov[j] == o) uo = nd + (size_t)(j * d), u = x + uo;
        for (k = 0; k < n; ++k) {
            pn_real nrm[3], dist, bb, b1, b2, w = dt2 * m->kappa;
            if (!PN__FEM_FREE(m, k)) continue;
            dist = pn__fem_obstacle_sd(c, d, u ? m->time_s : s->t_end, u, x + k * (size_t)d, nrm);
            dmin = PN__MIN(dmin, dist);
            if (!(dist > 0)) {
                m->error_node = (long)k;
                s->dmin = dist;
                return PN_ERROR_STEP_TOO_LARGE;
            }
            if (dist >= m->dhat) continue;
            pn__fem_barrier(dist, m->dhat, &bb, &b1, &b2);
            E += w * bb;
            if (mode >= 1)
                for (i = 0; i < d; ++i) {
                    s->g[k * (size_t)d + (size_t)i] += w * b1 * nrm[i];
                    if (u) s->g[uo + (size_t)i] -= w * b1 * nrm[i];
                }
            if (mode >= 2) /* b'' n n^T (the curvature of a box's distance, NSD times b' < 0, dropped) */
                for (i = 0; i < d; ++i)
                    for (j = 0; j < d; ++j) {
                        pn_real hv = w * b2 * nrm[i] * nrm[j];
                        size_t ri = pn__fem_row(m, k * (size_t)d + (size_t)i), rj = pn__fem_row(m, k * (size_t)d + (size_t)j);
                        if (j <= i) pn__fem_hadd(s, ri, rj, hv);
                        if (u) {
                            if (j <= i) pn__fem_hadd(s, uo + (size_t)i, uo + (size_t)j, hv);
                            pn__fem_hadd(s, uo + (size_t)i, rj, -hv);
                        }
                    }
        }
    }
    if (s->nitem) { /* self-contact */
        pn_result r = pn__fem_self(m, x, mode, &E, &dmin);
        if (r != PN_OK) {
            s->dmin = dmin;
            return r;
        }
    }
    for (o = 0; o < m->n_obstacles; ++o) { /* lagged smoothed Coulomb friction (IPC) */
        const pn_collider *c = &m->obstacles[o];
        const pn_real *u = NULL, *ul = NULL;
        pn_real eps = m->desc.friction_velocity_m_s * s->dt;
        size_t uo = 0;
        if (!(c->friction > 0)) continue;
        for (j = 0; j < s->n_mov; ++j)
            if (s->mov[j] == o) uo = nd + (size_t)(j * d), u = x + uo, ul = s->xlag + uo;
        for (k = 0; k < n; ++k) {
            pn_real nrm[3], w[3], ut[3], dl, bb, b1, b2, wn = 0, y = 0, f0, f1, f1p, coef;
            if (!PN__FEM_FREE(m, k)) continue;
            dl = pn__fem_obstacle_sd(c, d, u ? m->time_s : s->t_end, ul, s->xlag + k * (size_t)d, nrm);
            if (!(dl > 0) || dl >= m->dhat) continue;
            pn__fem_barrier(dl, m->dhat, &bb, &b1, &b2);
            coef = dt2 * c->friction * m->kappa * -b1; /* mu lambda, lambda the lagged normal force */
            for (i = 0; i < d; ++i) w[i] = x[k * (size_t)d + (size_t)i] - m->x[k * (size_t)d + (size_t)i] - (u ? u[i] : 0), wn += w[i] * nrm[i];
            for (i = 0; i < d; ++i) ut[i] = w[i] - wn * nrm[i], y += ut[i] * ut[i];
            y = PN__SQRT(y);
            if (y < eps) { /* f0(y) = -y^3 / (3 eps^2) + y^2 / eps + eps / 3, C1 at eps */
                f0 = -y * y * y / (3 * eps * eps) + y * y / eps + eps / 3;
                f1 = -y * y / (eps * eps) + 2 * y / eps;
                f1p = -2 * y / (eps * eps) + 2 / eps;
            } else f0 = y, f1 = 1, f1p = 0;
            E += coef * f0;
            if (mode >= 1 && y > 0)
                for (i = 0; i < d; ++i) {
                    s->g[k * (size_t)d + (size_t)i] += coef * f1 * ut[i] / y;
                    if (u) s->g[uo + (size_t)i] -= coef * f1 * ut[i] / y;
                }
            if (mode >= 2) /* f1' u^ u^T + (f1 / y)(P - u^ u^T) on the tangent plane: PSD */
                for (i = 0; i < d; ++i)
                    for (j = 0; j < d; ++j) {
                        pn_real P = (i == j) - nrm[i] * nrm[j], uu = y > 0 ? ut[i] * ut[j] / (y * y) : 0;
                        pn_real hv = coef * (y > 0 ? f1p * uu + f1 / y * (P - uu) : 2 / eps * P);
                        size_t ri = pn__fem_row(m, k * (size_t)d + (size_t)i), rj = pn__fem_row(m, k * (size_t)d + (size_t)j);
                        if (j <= i) pn__fem_hadd(s, ri, rj, hv);
                        if (u) {
                            if (j <= i) pn__fem_hadd(s, uo + (size_t)i, uo + (size_t)j, hv);
                            pn__fem_hadd(s, uo + (size_t)i, rj, -hv);
                        }
                    }
        }
    }
    for (j = 0; j < s->n_mov; ++j) /* the augmented Lagrangian pulling each obstacle to its target */
        for (i = 0; i < d; ++i) {
            size_t c = nd + (size_t)(j * d + i);
            pn_real du = x[c] - s->target[j * d + i];
            E += s->al_k * du * du / 2 - s->al_lam[j * d + i] * du;
            if (mode >= 1) s->g[c] += s->al_k * du - s->al_lam[j * d + i];
            if (mode >= 2) pn__fem_hadd(s, c, c, s->al_k);
        }
    if (mode >= 2) /* driven nodes: identity rows */
        for (k = 0; k < n; ++k)
            if (!PN__FEM_FREE(m, k))
                for (i = 0; i < d; ++i) pn__fem_hadd(s, pn__fem_row(m, k * (size_t)d + (size_t)i), pn__fem_row(m, k * (size_t)d + (size_t)i), 1);
    s->dmin = dmin;
    *E_out = E;
    return pn__finite(E) ? PN_OK : PN_ERROR_OVERFLOW;
}

static pn_result pn__fem_objective_value(void *ctx, const pn_real *x, pn_real *E) {
    return pn__fem_objective((pn_fem_mesh *)ctx, x, 0, E);
}

/* ======================================================================================
   >>fem-step: what both steps share (the state kept for a failed step, the return mapping
   after a step, the checks of a step's input), the explicit step bound and the explicit step
   (pn_fem_stable_dt, pn_fem_step_explicit).
   ====================================================================================== */

/* the state before a step, kept (restore = 0) or put back (restore = 1) */
static void pn__fem_keep(pn_fem_mesh *m, int restore) {
    pn__fem *s = (pn__fem *)m->impl;
    size_t nd = m->n_nodes * (size_t)m->dim, ne = m->n_points, dd = (size_t)(m->dim * m->dim);
    pn_real *live[4], *kept[4];
    size_t len[4];
    int i;
    live[0] = m->x, kept[0] = s->bx, len[0] = nd;
    live[1] = m->v, kept[1] = s->bv, len[1] = nd;
    live[2] = m->Fp_inv, kept[2] = s->bFp, len[2] = ne * dd;
    live[3] = m->h, kept[3] = s->bh, len[3] = ne;
    for (i = 0; i < 4; ++i) memcpy(restore ? live[i] : kept[i], restore ? kept[i] : live[i], sizeof(pn_real) * len[i]);
    if (restore) m->time_s = s->bt;
    else s->bt = m->time_s;
}

#define pn__fem_backup(m) pn__fem_keep(m, 0)
#define pn__fem_restore(m) pn__fem_keep(m, 1)

/* The return mapping of every integration point at the new positions (F = Fe Fp: Fp^-1 <-
   Fp^-1 Fe^-1 Z); the count of projected points in *plastic. */
static pn_result pn__fem_return(pn_fem_mesh *m, size_t *plastic) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, dd = d * d;
    size_t e;
    enum { KEPT = 0, PROJECTED, INVERTED, SINGULAR, FAILED }; /* estat: FAILED + the pn_result */
    *plastic = 0;
    PN__FEM_OMP_FOR /* each point's own state on threads; counted and judged below in order */
    for (e = 0; e < m->n_points; ++e) { /* (e: the point) */
        const pn_group *g = &m->groups[m->egroup[PN__FEM_ELEM(m, e)]];
        pn_real Fe[9], Z[9], Fi[9], T[9], hn, moved = 0;
        pn_result r;
        int i;
        s->estat[e] = KEPT;
        pn__fem_fe(m, e, m->x, Fe);
        if (s->elast[e] && !(pn_mat_det(d, Fe) > 0)) {
            s->estat[e] = INVERTED;
            continue;
        }
        if (g->material.plastic == PN_PLASTIC_NONE) continue;
        r = pn__mpm_energy_of(g) == PN_ENERGY_PNET && g->pnet.return_map
                ? pn_learned_return_map(g->pnet.return_map, &g->material, d, Fe, m->h[e], Z, &hn, NULL)
                : pn_return_map(&g->material, d, Fe, m->h[e], Z, &hn, NULL);
        if (r != PN_OK || !pn__finite(hn)) {
            s->estat[e] = FAILED + (int)(r != PN_OK ? r : PN_ERROR_OVERFLOW);
            continue;
        }
        for (i = 0; i < dd; ++i) moved = PN__MAX(moved, PN__FABS(Z[i] - Fe[i]));
        if (moved == 0 && hn == m->h[e]) continue;
        if (pn_mat_inverse(d, Fe, Fi) != PN_OK) {
            s->estat[e] = SINGULAR;
            continue;
        }
        s->estat[e] = PROJECTED;
        pn_mat_mul(d, m->Fp_inv + e * (size_t)dd, Fi, T);
        pn_mat_mul(d, T, Z, m->Fp_inv + e * (size_t)dd);
        m->h[e] = hn;
    }
    for (e = 0; e < m->n_points; ++e) {
        int st = s->estat[e];
        unsigned long el = (unsigned long)PN__FEM_ELEM(m, e);
        if (st == PROJECTED) (*plastic)++;
        if (st <= PROJECTED) continue;
        m->error_element = (long)el;
        if (st == INVERTED) {
            pn_real Fe[9];
            pn__fem_fe(m, e, m->x, Fe);
            return PN__FAIL(m, PN_ERROR_INVERTED, "element %lu turned inside out (det Fe = %g)", el, (double)pn_mat_det(d, Fe));
        }
        if (st == SINGULAR) return PN__FAIL(m, PN_ERROR_INVERTED, "element %lu: Fe is singular", el);
        return PN__FAIL(m, (pn_result)(st - FAILED), "element %lu: the return mapping failed (%s)", el,
                            pn_result_string((pn_result)(st - FAILED)));
    }
    return PN_OK;
}

PN__DEF pn_result pn_fem_stable_dt(const pn_fem_mesh *m, pn_real *dt_s) {
    int d, dp, a, b, c, k;
    size_t e;
    pn_real best = PN__FEM_FAR;
    if (!m || !dt_s) return PN_ERROR_INVALID_ARGUMENT;
    d = m->dim, dp = d + 1;
    for (e = 0; e < m->n_elems; ++e) /* the smallest altitude of a linear piece over the P-wave speed */
        for (k = 0; k < pn__fem_nsub(m); ++k) {
            const pn_group *g = &m->groups[m->egroup[e]];
            const int *sub = pn__fem_sub(m, k), *en = m->elem + e * (size_t)m->nodes_per_element;
            int el[4];
            pn_real Ds[9], vol, fmax = 0, cp, alt;
            for (a = 0; a < dp; ++a) el[a] = en[sub[a]];
            for (a = 1; a <= d; ++a)
                for (c = 0; c < d; ++c) Ds[c * d + a - 1] = m->x[(size_t)el[a] * (size_t)d + (size_t)c] - m->x[(size_t)el[0] * (size_t)d + (size_t)c];
            vol = PN__FABS(pn__fem_volume(d, Ds));
            for (a = 0; a < dp; ++a) { /* the face opposite node a: its length (2D) or area (3D) */
                pn_real p[3][3], f;
                int nf = 0;
                for (b = 0; b < dp; ++b)
                    if (b != a) {
                        for (c = 0; c < d; ++c) p[nf][c] = m->x[(size_t)el[b] * (size_t)d + (size_t)c];
                        nf++;
                    }
                if (d == 2) f = PN__SQRT((p[1][0] - p[0][0]) * (p[1][0] - p[0][0]) + (p[1][1] - p[0][1]) * (p[1][1] - p[0][1]));
                else {
                    pn_real u[3], v[3], w[3];
                    for (c = 0; c < 3; ++c) u[c] = p[1][c] - p[0][c], v[c] = p[2][c] - p[0][c];
                    w[0] = u[1] * v[2] - u[2] * v[1], w[1] = u[2] * v[0] - u[0] * v[2], w[2] = u[0] * v[1] - u[1] * v[0];
                    f = PN__SQRT(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]) / 2;
                }
                fmax = PN__MAX(fmax, f);
            }
            alt = d * vol / fmax;
            cp = PN__SQRT((g->material.lambda + 2 * g->material.mu) / g->density_kg_m3);
            best = PN__MIN(best, (pn_real)0.5 * alt / cp);
        }
    { /* contacts: no node closes more than a quarter of its gap per step; the barrier's spring */
        pn_real gs = PN__FEM_FAR, sp = PN__FEM_FAR;
        pn__fem_contacts(m, m->time_s, &gs, &sp);
        best = PN__MIN(best, PN__MIN(gs, sp));
    }
    *dt_s = best;
    return PN_OK;
}

static pn_result pn__fem_check_dt(pn_fem_mesh *m, pn_real dt, const char *who) {
    if (!(dt > 0) || !pn__finite(dt))
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "%s: dt %g must be positive and finite", who, (double)dt);
    return PN_OK;
}

/* the first node whose position or velocity (public arrays a caller may write) is NaN or
   infinite, or -1 */
static long pn__fem_nonfinite_node(const pn_fem_mesh *m) {
    size_t k, nd = m->n_nodes * (size_t)m->dim;
    for (k = 0; k < nd; ++k)
        if (!pn__finite(m->x[k]) || !pn__finite(m->v[k])) return (long)(k / (size_t)m->dim);
    return -1;
}

/* after a step: no box obstacle reaches into an element between its nodes */
static pn_result pn__fem_obstacles_clear(pn_fem_mesh *m, const char *who) {
    int o;
    for (o = 0; o < m->n_obstacles; ++o)
        if ((m->error_element = pn__fem_obstacle_in_element(m, &m->obstacles[o], m->time_s)) >= 0)
            return PN__FAIL(m, PN_ERROR_UNSUPPORTED, "%s: obstacle %d reached into element %ld between its nodes (the "
                                "barrier acts on nodes: a finer mesh there, or a larger obstacle)", who, o, m->error_element);
    return PN_OK;
}

/* a step's checks: dt, and a state every step can start from (x, v finite) */
static pn_result pn__fem_check_step(pn_fem_mesh *m, pn_real dt, const char *who) {
    pn_result r = pn__fem_check_dt(m, dt, who);
    if (r != PN_OK) return r;
    if ((m->error_node = pn__fem_nonfinite_node(m)) >= 0)
        return PN__FAIL(m, PN_ERROR_NONFINITE, "%s: node %ld has a NaN or infinite position or velocity (was it "
                            "written by hand?)", who, m->error_node);
    return PN_OK;
}

PN__DEF pn_result pn_fem_step_explicit(pn_fem_mesh *m, pn_real dt, pn_fem_stats *stats) {
    pn__fem *s;
    int d, nn, a, i, j, o;
    size_t e, k, plastic = 0;
    pn_result r;
    pn_real *f;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    m->error_element = m->error_node = -1;
    if ((r = pn__fem_check_step(m, dt, "pn_fem_step_explicit")) != PN_OK) return r;
    s = (pn__fem *)m->impl;
    d = m->dim, nn = m->nodes_per_element;
    if (stats) memset(stats, 0, sizeof *stats);
    pn__fem_setup(m);
    pn__fem_backup(m);
    f = s->xtry; /* forces */
    for (k = 0; k < m->n_nodes; ++k)
        for (i = 0; i < d; ++i)
            f[k * (size_t)d + (size_t)i] = m->mass[k] * m->desc.gravity[i] + (s->fext ? s->fext[k * (size_t)d + (size_t)i] : 0);
    PN__FEM_OMP_FOR /* each point's P on threads; the forces gathered below in point order */
    for (e = 0; e < m->n_points; ++e) {
        pn_real Fe[9];
        pn__fem_fe(m, e, m->x, Fe);
        s->estat[e] = (int)pn_elastic_energy(&m->groups[m->egroup[PN__FEM_ELEM(m, e)]].material, d, Fe, m->h[e], NULL,
                                             s->eP + e * (size_t)(d * d), NULL, 0);
    }
    for (e = 0; e < m->n_points; ++e) { /* (e: the point) */
        const int *el = m->elem + PN__FEM_ELEM(m, e) * (size_t)nn;
        const pn_real *q = s->q + e * (size_t)(d * nn), *P = s->eP + e * (size_t)(d * d);
        if (s->estat[e]) {
            m->error_element = (long)PN__FEM_ELEM(m, e);
            return PN__FAIL(m, (pn_result)s->estat[e], "pn_fem_step_explicit: element %lu: %s", (unsigned long)m->error_element,
                                pn_result_string((pn_result)s->estat[e]));
        }
        for (a = 0; a < nn; ++a)
            for (i = 0; i < d; ++i) {
                pn_real acc = 0;
                for (j = 0; j < d; ++j) acc += P[i * d + j] * q[a * d + j];
                f[(size_t)el[a] * (size_t)d + (size_t)i] -= m->vol0[e] * acc;
            }
    }
    for (o = 0; o < m->n_obstacles; ++o)
        for (k = 0; k < m->n_nodes; ++k) {
            pn_real nrm[3], bb, b1, b2, dist = pn__fem_obstacle_sd(&m->obstacles[o], d, m->time_s, NULL, m->x + k * (size_t)d, nrm);
            if (dist >= m->dhat) continue;
            pn__fem_barrier(dist, m->dhat, &bb, &b1, &b2);
            for (i = 0; i < d; ++i) f[k * (size_t)d + (size_t)i] -= m->kappa * b1 * nrm[i];
        }
    if (s->nitem) { /* the self-contact barrier's forces: its gradient with dt = 1 */
        pn_real Es = 0, dm = PN__FEM_FAR;
        memset(s->g, 0, sizeof(pn_real) * m->n_nodes * (size_t)d);
        s->dt = 1;
        r = pn__fem_self(m, m->x, 1, &Es, &dm);
        if (r != PN_OK) {
            pn__fem_restore(m);
            return PN__FAIL(m, r, "pn_fem_step_explicit: node %ld touches an edge of the mesh", m->error_node);
        }
        for (k = 0; k < m->n_nodes * (size_t)d; ++k) f[k] -= s->g[k];
    }
    for (k = 0; k < m->n_nodes; ++k) {
        pn_real xn[3];
        if (m->fixed[k]) pn__fem_driven(m, k, dt, xn);
        for (i = 0; i < d; ++i) {
            size_t c = k * (size_t)d + (size_t)i;
            m->v[c] = m->fixed[k] ? (xn[i] - m->x[c]) / dt : m->v[c] + dt * f[c] / m->mass[k];
            m->x[c] = m->fixed[k] ? xn[i] : m->x[c] + dt * m->v[c];
            if (!pn__finite(m->x[c])) {
                pn__fem_restore(m);
                m->error_node = (long)k;
                return PN__FAIL(m, PN_ERROR_OVERFLOW, "pn_fem_step_explicit: node %lu's position is not finite: take a "
                                    "smaller step (pn_fem_stable_dt)", (unsigned long)k);
            }
        }
    }
    if (s->nitem) { /* self-contact must not be crossed within the step either */
        for (k = 0; k < m->n_nodes * (size_t)d; ++k) s->dir[k] = m->x[k] - s->bx[k];
        if (pn__fem_self_ccd(m, s->bx, s->dir, 1) < 1) {
            pn__fem_restore(m);
            return PN__FAIL(m, PN_ERROR_STEP_TOO_LARGE, "pn_fem_step_explicit: a boundary node would close on an edge "
                                "of the mesh in a step of %g s: take a smaller step (pn_fem_stable_dt)", (double)dt);
        }
    }
    for (o = 0; o < m->n_obstacles; ++o) { /* Coulomb friction on the new velocities: slows the
                                                sliding by at most dt mu lambda / m, never reverses it */
        const pn_collider *c = &m->obstacles[o];
        if (!(c->friction > 0)) continue;
        for (k = 0; k < m->n_nodes; ++k) {
            pn_real nrm[3], vt[3], vn = 0, sp = 0, bb, b1, b2, cut, dist;
            if (m->fixed[k]) continue;
            dist = pn__fem_obstacle_sd(c, d, m->time_s, NULL, s->bx + k * (size_t)d, nrm); /* at x^n */
            if (!(dist > 0) || dist >= m->dhat) continue;
            pn__fem_barrier(dist, m->dhat, &bb, &b1, &b2);
            for (i = 0; i < d; ++i) vt[i] = m->v[k * (size_t)d + (size_t)i] - c->velocity_m_s[i], vn += vt[i] * nrm[i];
            for (i = 0; i < d; ++i) vt[i] -= vn * nrm[i], sp += vt[i] * vt[i];
            sp = PN__SQRT(sp);
            if (!(sp > 0)) continue;
            cut = PN__MIN(1, dt * c->friction * m->kappa * -b1 / (m->mass[k] * sp));
            for (i = 0; i < d; ++i) {
                m->v[k * (size_t)d + (size_t)i] -= cut * vt[i];
                m->x[k * (size_t)d + (size_t)i] -= dt * cut * vt[i];
            }
        }
    }
    if (m->n_obstacles && !(pn__fem_min_distance(m, m->time_s + dt) > 0)) {
        pn__fem_restore(m);
        return PN__FAIL(m, PN_ERROR_STEP_TOO_LARGE, "pn_fem_step_explicit: a node would reach an obstacle in a step of %g "
                            "s: take a smaller step (pn_fem_stable_dt)", (double)dt);
    }
    r = pn__fem_return(m, &plastic);
    if (r != PN_OK) {
        char msg[256];
        memcpy(msg, m->error, sizeof msg);
        pn__fem_restore(m);
        return PN__FAIL(m, PN_ERROR_STEP_TOO_LARGE, "pn_fem_step_explicit: %s: take a smaller step", msg);
    }
    m->time_s += dt;
    if ((r = pn__fem_obstacles_clear(m, "pn_fem_step_explicit")) != PN_OK) {
        pn__fem_restore(m);
        return r;
    }
    m->steps++;
    if (stats) {
        pn_real sdt;
        stats->substeps = 1;
        stats->plastic = plastic;
        stats->min_distance_m = m->n_obstacles ? pn__fem_min_distance(m, m->time_s) : -1;
        stats->kappa = m->kappa;
        pn_fem_stable_dt(m, &sdt);
        stats->dt_over_cfl = dt / sdt;
    }
    return PN_OK;
}

/* ======================================================================================
   >>fem-implicit: the implicit step (pn_fem_step_implicit): projected Newton on the
   incremental potential with a CCD-filtered line search, the fixed point on F0, friction
   rounds, moving obstacles by augmented Lagrangian; the mesh's energy (pn_fem_energy).
   ====================================================================================== */

/* Newton's step, under which the element Hessians are used as they are (PN__FEM_FULL_H) */
#define PN__FEM_FULL_H ((pn_real)1e-2) /* of the mean edge */

/* Newton on the incremental potential from s->xs (feasible) to its minimum.
   Element Hessians are PSD-projected (projected Newton: every direction descends) until the
   steps are short; then they are used whole. Clamping the negative curvature of compressed
   elements (their geometric stiffness) leaves a model that is wrong near the minimum, and
   Newton converges linearly there (a ratio of 0.9 per iteration on a crushed frame); at a
   strict minimum the whole Hessian is positive definite and convergence is quadratic again.
   Where it is not (the factorization fails: a saddle the iterate passes) or its step finds no
   decrease, the iteration projects again until its steps are 10 times shorter, or long again
   (it left for another minimum): the idea of Chen et al. 2024, trust-region eigenvalue
   filtering, to project only where the quadratic model is poor. */
static pn_result pn__fem_minimize(pn_fem_mesh *m, const pn_fem_implicit_desc *o, pn_fem_stats *st) {
    pn__fem *s = (pn__fem *)m->impl;
    size_t nu = s->nu, nd = m->n_nodes * (size_t)m->dim, k;
    int it;
    pn_real tol = o->newton_tol * m->edge_mean, res = 0, gres = 0, gfloor = 0, full_below = PN__FEM_FULL_H * m->edge_mean;
    for (it = 0; it < o->newton_max; ++it) {
        pn_real E0, E1, gd = 0, a0, alpha;
        pn_result r;
        int full = it > 0 && res <= full_below, capped = 0;
        for (;;) {
            pn__cg_ops op;
            int curv = 0;
            s->hflags = full ? 0 : PN_EVAL_PROJECT_PSD;
            r = pn__fem_objective(m, s->xs, 2, &E0);
            s->hflags = PN_EVAL_PROJECT_PSD; /* what every other evaluation uses */
            if (r != PN_OK)
                return PN__FAIL(m, r, "implicit step: the energy at an accepted iterate failed (%s, element %ld, node %ld)",
                                    pn_result_string(r), m->error_element, m->error_node);
            if (s->sparse && s->bmiss)
                return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "implicit step: %ld Hessian entries fell outside the "
                                    "block pattern (a bug: please report)", s->bmiss);
            for (k = 0; k < nu; ++k) s->xtry[pn__fem_row(m, k)] = -s->g[k];
            op.ctx = m, op.apply = pn__fem_cg_apply, op.precond = pn__fem_cg_precond, op.dot = pn__fem_cg_dot, op.curv = &curv;
            st->factorizations++;
            if (s->sparse) { /* PCG to cg_rel_tol. Looser solves far from the minimum (Eisenstat-Walker
                                forcing, min(1e-2, |g| / |g_0|)) cost more Newton iterations than they
                                saved CG ones: 131 against 102 per step on the 3D frame's first step */
                if (pn__fem_bfactor(s)) {
                    s->coarse = !s->one_level && pn__fem_coarse_build(m, s->xs);
                    if (s->coarse) s->omega = pn__fem_smoother_damping(m);
                    st->cg_iters += pn__pcg(&op, nu, s->cgx, s->xtry, s->cgz, s->cgp, s->cgq, o->cg_max, o->cg_rel_tol, 0, &capped);
                    memcpy(s->xtry, s->cgx, sizeof(pn_real) * nu); /* capped or curved: CG from 0 still descends */
                    if (!(curv && full)) break;
                }
            } else {
                if (s->n_off) memcpy(s->A, s->L, sizeof(pn_real) * s->rs[nu]); /* kept for CG's products */
                if (pn__sky_cholesky(s->fc, s->rs, s->L, nu)) {
                    if (s->n_off) { /* self-contact beyond the profile: CG on the whole Hessian, the factor preconditions */
                        st->cg_iters += pn__pcg(&op, nu, s->cgx, s->xtry, s->cgz, s->cgp, s->cgq, 200, (pn_real)1e-10, 0, &capped);
                        memcpy(s->xtry, s->cgx, sizeof(pn_real) * nu); /* capped: still a descent direction (CG from 0) */
                        capped = 0; /* preconditioned by the exact factor of most of it: as good as converged */
                    } else
                        pn__sky_solve(s->fc, s->rs, s->L, nu, s->xtry);
                    break;
                }
            }
            if (!full)
                return PN__FAIL(m, PN_ERROR_NOT_CONVERGED, "implicit step: the Hessian is not positive definite (a "
                                    "material's energy is not convex where it was projected)");
            full = 0, full_below = res / 10; /* indefinite here (a saddle on the way): project until
                                                 the steps are 10x shorter */
        }
        for (res = 0, gres = 0, k = 0; k < nu; ++k) {
            s->dir[k] = s->xtry[pn__fem_row(m, k)];
            res = PN__MAX(res, PN__FABS(s->dir[k]));
            gd += s->g[k] * s->dir[k];
            if (k < nd && PN__FEM_FREE(m, k / (size_t)m->dim)) gres = PN__MAX(gres, PN__FABS(s->g[k]) / m->mass[k / (size_t)m->dim]);
        }
        st->newton_iters++;
        st->newton_residual = res / m->edge_mean;
        if (res > PN__FEM_FULL_H * m->edge_mean) full_below = PN__FEM_FULL_H * m->edge_mean; /* moved on */
        if (o->trace) o->trace(o->trace_user, st->solves, it, E0, res / m->edge_mean);
        if (!pn__finite(res))
            return PN__FAIL(m, PN_ERROR_OVERFLOW, "implicit step: the Newton direction is not finite");
        /* converged: the step is below tol and so is each node's residual force over its mass
           times dt^2 (the move it would cause through inertia alone). The second matters
           where a stiff term is flat: at the edge of the barrier's reach b is cubic, Newton
           converges linearly there, and a small step can leave a force of several weights.
           Stiff material at large steps cannot resolve forces that finely (the energy's
           rounding): there 1e-6 of the minimization's first residual is enough. The first
           step is always taken: x^n is no answer. */
        if (it == 0) gfloor = PN__MAX(tol, (pn_real)1e-6 * gres); /* or 1e-6 of the first residual */
        if (res <= tol && gres <= gfloor && it > 0 && !capped) return PN_OK; /* (a solve cut short proves nothing) */
        a0 = pn__fem_self_ccd(m, s->xs, s->dir, pn__fem_ccd(m, s->xs, s->dir));
        alpha = pn__armijo(pn__fem_objective_value, m, nu, s->xs, s->dir, E0, gd, a0, (pn_real)1e-10, s->xtry, &E1);
        if (alpha == 0 && pn__unresolved(gd, E0, PN__EPS) && a0 == 1) {
            /* the decrease Newton predicts is below the energy's rounding (near a minimum of
               a large energy): the values cannot judge the step; take it if it is feasible,
               and let the residuals decide */
            for (k = 0; k < nu; ++k) s->xtry[k] = s->xs[k] + s->dir[k];
            if (pn__fem_objective(m, s->xtry, 0, &E1) == PN_OK) alpha = 1;
        }
        if (alpha == 0) {
            st->line_search_failures++;
            /* a step below tol that the energy cannot tell from no step: converged as far as
               its rounding resolves (stiff material at a large step) */
            if (res <= tol || (res <= 100 * tol && gres <= 100 * gfloor)) return PN_OK;
            if (full) { /* the whole Hessian's step found no decrease: project again */
                full_below = res / 10;
                continue;
            }
            return PN__FAIL(m, PN_ERROR_NOT_CONVERGED, "implicit step: the line search found no decrease at max |dx| = "
                                "%.3g of the mean edge (newton_tol %g)", (double)(res / m->edge_mean), (double)o->newton_tol);
        }
        memcpy(s->xs, s->xtry, sizeof(pn_real) * nu);
        if (res <= tol && !(E1 < E0)) return PN_OK; /* the step below tol no longer lowers the energy
            at all: what force is left, the energy's rounding cannot resolve (a stiff contact pressed
            hard, where b'' is large: a force of weights for a move of 1e-12 m) */
    }
    if (res <= 100 * tol && gres <= 100 * gfloor) return PN_OK; /* within 100 newton_tol, as MPM's */
    return PN__FAIL(m, PN_ERROR_NOT_CONVERGED, "implicit step of %g s: Newton stopped after %d iterations at max |dx| = %.3g "
                        "of the mean edge (newton_tol %g): a smaller step converges", (double)s->dt, o->newton_max,
                        (double)(res / m->edge_mean), (double)o->newton_tol);
}

/* each point's energy prepared at F0 = Fe(x) (fixed point); points x inverts use x^n */
static pn_result pn__fem_prepare(pn_fem_mesh *m, const pn_real *x) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, dd = d * d;
    size_t e;
    PN__FEM_OMP_FOR
    for (e = 0; e < m->n_points; ++e) { /* (e: the point) */
        const pn_group *g = &m->groups[m->egroup[PN__FEM_ELEM(m, e)]];
        pn_real F0[9];
        pn_result r = PN_OK;
        pn_energy en = pn__mpm_energy_of(g);
        s->estat[e] = 0;
        if (en != PN_ENERGY_LAGGED && en != PN_ENERGY_PNET && en != PN_ENERGY_DP) continue;
        pn__fem_fe(m, e, x, F0);
        if (!(pn_mat_det(d, F0) > 0)) pn__fem_fe(m, e, m->x, F0);
        if (en == PN_ENERGY_LAGGED) r = pn_lagged_prepare(&g->material, d, F0, m->h[e], s->pG + e * (size_t)dd, &s->phG[e]);
        else if (en == PN_ENERGY_PNET) r = pn_pnet_prepare(&g->pnet, F0, m->h[e], &s->ppt[e], NULL, NULL);
        else r = pn_dp_prepare(&g->material, d, F0, m->h[e], &s->pty[e]);
        s->estat[e] = (int)r;
    }
    for (e = 0; e < m->n_points; ++e)
        if (s->estat[e]) {
            m->error_element = (long)PN__FEM_ELEM(m, e);
            return PN__FAIL(m, (pn_result)s->estat[e], "element %lu: preparing its energy at F0 failed (%s)",
                                (unsigned long)m->error_element, pn_result_string((pn_result)s->estat[e]));
        }
    return PN_OK;
}

/* minimize, and (with moving obstacles) the augmented-Lagrangian rounds that pull their
   offsets to the targets */
static pn_result pn__fem_rounds(pn_fem_mesh *m, const pn_fem_implicit_desc *o, pn_fem_stats *st, pn_real tol) {
    pn__fem *s = (pn__fem *)m->impl;
    size_t nd = m->n_nodes * (size_t)m->dim, k;
    int round;
    for (round = 0;; ++round) {
        pn_real off = 0;
        pn_result r;
        st->solves++;
        r = pn__fem_minimize(m, o, st);
        if (r != PN_OK) return r;
        if (!s->n_mov) return PN_OK;
        st->al_iters++;
        for (k = nd; k < s->nu; ++k) off = PN__MAX(off, PN__FABS(s->xs[k] - s->target[k - nd]));
        if (off <= tol) return PN_OK;
        if (round >= 30)
            return PN__FAIL(m, PN_ERROR_NOT_CONVERGED, "implicit step of %g s: a moving obstacle is still %g m short of "
                                "its position after %d rounds: a smaller step", (double)s->dt, (double)off, round + 1);
        for (k = nd; k < s->nu; ++k) s->al_lam[k - nd] -= s->al_k * (s->xs[k] - s->target[k - nd]);
    }
}

/* does a node lie within dhat of an obstacle with friction at the solution s->xs but not
   where friction was lagged (s->xlag)? */
static int pn__fem_new_friction(const pn_fem_mesh *m) {
    const pn__fem *s = (const pn__fem *)m->impl;
    int o, j, d = m->dim;
    size_t k, nd = m->n_nodes * (size_t)d;
    for (o = 0; o < m->n_obstacles; ++o) {
        const pn_collider *c = &m->obstacles[o];
        const pn_real *u = NULL, *ul = NULL;
        if (!(c->friction > 0)) continue;
        for (j = 0; j < s->n_mov; ++j)
            if (s->mov[j] == o) u = s->xs + nd + (size_t)(j * d), ul = s->xlag + nd + (size_t)(j * d);
        for (k = 0; k < m->n_nodes; ++k) {
            pn_real nrm[3];
            if (!PN__FEM_FREE(m, k)) continue;
            if (pn__fem_obstacle_sd(c, d, u ? m->time_s : s->t_end, u, s->xs + k * (size_t)d, nrm) < m->dhat &&
                !(pn__fem_obstacle_sd(c, d, u ? m->time_s : s->t_end, ul, s->xlag + k * (size_t)d, nrm) < m->dhat))
                return 1;
        }
    }
    return 0;
}

static pn_result pn__fem_implicit_once(pn_fem_mesh *m, pn_real dt, const pn_fem_implicit_desc *o, pn_fem_stats *st) {
    pn__fem *s = (pn__fem *)m->impl;
    int d = m->dim, i, j, pass, round, a;
    size_t n = m->n_nodes, nd = n * (size_t)d, k, e, plastic = 0;
    pn_real kmax = 0, tol = o->newton_tol * m->edge_mean;
    pn_result r;
    s->dt = dt;
    s->t_end = m->time_s + dt;
    pn__fem_setup(m);
    s->n_mov = 0;
    for (i = 0; i < m->n_obstacles; ++i) {
        const pn_real *v = m->obstacles[i].velocity_m_s;
        if (v[0] != 0 || v[1] != 0 || v[2] != 0) {
            for (j = 0; j < d; ++j) s->target[s->n_mov * d + j] = v[j] * dt, s->al_lam[s->n_mov * d + j] = 0;
            s->mov[s->n_mov++] = i;
        }
    }
    s->nu = nd + (size_t)(s->n_mov * d);
    for (k = 0; k < n; ++k) {
        pn_real xn[3];
        if (m->fixed[k]) pn__fem_driven(m, k, dt, xn);
        for (i = 0; i < d; ++i) {
            size_t c = k * (size_t)d + (size_t)i;
            if (m->fixed[k]) s->xt[c] = s->xs[c] = xn[i];
            else s->xt[c] = m->x[c] + dt * m->v[c] + dt * dt * m->desc.gravity[i], s->xs[c] = m->x[c];
        }
    }
    for (k = nd; k < s->nu; ++k) s->xs[k] = 0;
    { /* start at the inertial prediction x~ where it is near (no node moves half an edge),
         no node passes an obstacle to it and no element is inverted there; else at x^n */
        pn_real E, far = 0;
        for (k = 0; k < nd; ++k) s->dir[k] = s->xt[k] - s->xs[k], far = PN__MAX(far, PN__FABS(s->dir[k]));
        for (k = nd; k < s->nu; ++k) s->dir[k] = 0;
        if (far <= m->edge_mean / 2 && pn__fem_self_ccd(m, s->xs, s->dir, pn__fem_ccd(m, s->xs, s->dir)) >= (pn_real)0.9) {
            memcpy(s->xtry, s->xs, sizeof(pn_real) * s->nu);
            for (k = 0; k < nd; ++k) s->xs[k] = s->xt[k];
            s->al_k = 0;
            if (pn__fem_prepare(m, s->xt) != PN_OK || pn__fem_objective(m, s->xs, 0, &E) != PN_OK)
                memcpy(s->xs, s->xtry, sizeof(pn_real) * s->nu);
        }
    }
    /* the obstacles' pull: 1e4 times the stiffest node's diagonal (mass, elements, barrier) */
    for (e = 0; e < m->n_points; ++e) {
        const pn_material *mt = &m->groups[m->egroup[PN__FEM_ELEM(m, e)]].material;
        const pn_real *q = s->q + e * (size_t)(d * m->nodes_per_element);
        pn_real qq = 0;
        for (a = 0; a < d * m->nodes_per_element; ++a) qq = PN__MAX(qq, q[a] * q[a]);
        kmax = PN__MAX(kmax, dt * dt * m->vol0[e] * (mt->lambda + 2 * mt->mu) * qq * d);
    }
    for (k = 0; k < n; ++k) kmax = PN__MAX(kmax, m->mass[k]);
    kmax += dt * dt * m->kappa * 10;
    s->al_k = 1e4 * kmax;
    for (pass = 0; pass < o->fixed_point_iters; ++pass) {
        r = pn__fem_prepare(m, pass == 0 ? s->xt : s->xs);
        if (r != PN_OK) return r;
        if (pass == 0) { /* friction's normal forces and directions: at x^n, then each pass's solution */
            memcpy(s->xlag, m->x, sizeof(pn_real) * nd);
            for (k = nd; k < s->nu; ++k) s->xlag[k] = 0;
        } else memcpy(s->xlag, s->xs, sizeof(pn_real) * s->nu);
        st->fixed_point_iters++;
        if ((r = pn__fem_rounds(m, o, st, tol)) != PN_OK) return r;
    }
    for (round = 0; round < 2 && pn__fem_new_friction(m); ++round) { /* friction lagged again (IPC's lagged
        iterations) where a node came within dhat of a rough obstacle during the step: lagged at x^n it
        had no normal force and slid freely for the whole step */
        memcpy(s->xlag, s->xs, sizeof(pn_real) * s->nu);
        st->friction_relags++;
        /* and solved again from x^n: the first solve, frictionless where the contact began,
           may have gone far down another branch (the frame swaying sideways under the plate) */
        for (k = 0; k < n; ++k)
            if (PN__FEM_FREE(m, k)) memcpy(s->xs + k * (size_t)d, m->x + k * (size_t)d, sizeof(pn_real) * (size_t)d);
        for (k = nd; k < s->nu; ++k) s->xs[k] = 0;
        if ((r = pn__fem_rounds(m, o, st, tol)) != PN_OK) return r;
    }
    for (k = 0; k < nd; ++k) m->v[k] = (s->xs[k] - m->x[k]) / dt, m->x[k] = s->xs[k];
    r = pn__fem_return(m, &plastic);
    if (r != PN_OK) return r;
    m->time_s += dt;
    st->plastic += plastic;
    return PN_OK;
}

/* pn_fem_step_implicit's tries for the kit's substep fallback (pn__halve) */
typedef struct pn__fem_retry {
    pn_fem_mesh *m;
    const pn_fem_implicit_desc *o;
    pn_real dt;
    pn_fem_stats *st, first;     /* the current try's stats; the first try's               */
    long element, node;
    int stopped;                 /* a step that worked left an obstacle inside: halving will not help */
    char why[sizeof ((pn_fem_mesh *)0)->error];
} pn__fem_retry;

static pn_result pn__fem_try(void *ctx, int n_sub) {
    pn__fem_retry *t = (pn__fem_retry *)ctx;
    pn_result r = PN_OK;
    int sub;
    memset(t->st, 0, sizeof *t->st);
    t->st->substeps = n_sub;
    for (sub = 0; sub < n_sub && r == PN_OK; ++sub) r = pn__fem_implicit_once(t->m, t->dt / n_sub, t->o, t->st);
    if (r == PN_OK && (r = pn__fem_obstacles_clear(t->m, "pn_fem_step_implicit")) != PN_OK) t->stopped = 1;
    return r;
}

static void pn__fem_untry(void *ctx, int n_sub) {
    (void)n_sub;
    pn__fem_restore(((pn__fem_retry *)ctx)->m);
}

static void pn__fem_keep_first(void *ctx) {
    pn__fem_retry *t = (pn__fem_retry *)ctx;
    t->first = *t->st;
    memcpy(t->why, t->m->error, sizeof t->why);
    t->element = t->m->error_element, t->node = t->m->error_node;
}

static int pn__fem_stop(void *ctx, int n_sub) {
    (void)n_sub;
    return ((pn__fem_retry *)ctx)->stopped;
}

PN__DEF pn_result pn_fem_step_implicit(pn_fem_mesh *m, pn_real dt, const pn_fem_implicit_desc *desc, pn_fem_stats *stats) {
    pn_fem_implicit_desc o;
    pn_fem_stats st;
    pn_result r;
    pn__fem_retry t;
    pn__halving h;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    m->error[0] = 0;
    m->error_element = m->error_node = -1;
    if ((r = pn__fem_check_step(m, dt, "pn_fem_step_implicit")) != PN_OK) return r;
    memset(&o, 0, sizeof o);
    if (desc) o = *desc;
    /* zero means the default; NaN, infinite or negative is refused, never replaced */
    if (o.fixed_point_iters < 0 || o.newton_max < 0 || o.cg_max < 0)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_implicit_desc: fixed_point_iters %d, newton_max %d and "
                            "cg_max %d must be >= 0 (0: the default)", o.fixed_point_iters, o.newton_max, o.cg_max);
    if (!pn__finite(o.newton_tol) || o.newton_tol < 0 || !pn__finite(o.cg_rel_tol) || o.cg_rel_tol < 0)
        return PN__FAIL(m, PN_ERROR_INVALID_ARGUMENT, "pn_fem_implicit_desc: newton_tol %g and cg_rel_tol %g must be "
                            "finite and >= 0 (0: the default)", (double)o.newton_tol, (double)o.cg_rel_tol);
    if (!o.fixed_point_iters) o.fixed_point_iters = 1;
    if (!o.newton_max) o.newton_max = 100;
    if (!(o.newton_tol > 0)) o.newton_tol = (pn_real)1e-5;
    if (!o.max_halvings) o.max_halvings = 5;
    if (!(o.cg_rel_tol > 0)) o.cg_rel_tol = (pn_real)1e-6;
    if (!o.cg_max) o.cg_max = 5000;
    if ((r = pn__fem_linear_setup(m, o.linear_solver)) != PN_OK) return r;
    pn__fem_backup(m);
    memset(&t, 0, sizeof t);
    t.m = m, t.o = &o, t.dt = dt, t.st = &st;
    h.ctx = &t, h.try_step = pn__fem_try, h.undo = pn__fem_untry, h.keep_first = pn__fem_keep_first, h.stop = pn__fem_stop;
    if ((r = pn__halve(&h, o.max_halvings)) == PN_OK) {
        m->steps++;
        st.linear_solver = ((pn__fem *)m->impl)->sparse ? PN_FEM_LINEAR_PCG : PN_FEM_LINEAR_CHOLESKY;
        st.min_distance_m = m->n_obstacles ? pn__fem_min_distance(m, m->time_s) : -1;
        st.kappa = m->kappa;
        {
            pn_real sdt;
            pn_fem_stable_dt(m, &sdt);
            st.dt_over_cfl = dt / sdt;
        }
        if (stats) *stats = st;
        return PN_OK;
    }
    memcpy(m->error, t.why, sizeof m->error); /* the first try's message and stats */
    m->error_element = t.element, m->error_node = t.node;
    if (stats) *stats = t.first;
    if (o.max_halvings > 0 && !t.stopped) pn__append(m->error, sizeof m->error, " [also as 2^max_halvings substeps]");
    return r;
}

PN__DEF pn_result pn_fem_energy(const pn_fem_mesh *m, pn_real *elastic_j, pn_real *kinetic_j) {
    int d, dd;
    size_t e, k;
    pn_real el = 0, kin = 0;
    if (!m) return PN_ERROR_INVALID_ARGUMENT;
    d = m->dim, dd = d * d;
    for (e = 0; e < m->n_points; ++e) { /* (e: the point) */
        pn_real J[9], F[9], Fe[9], psi = 0;
        pn__fem_jac(m, e, m->x, J);
        pn_mat_mul(d, J, m->Dm_inv + e * (size_t)dd, F);
        pn_mat_mul(d, F, m->Fp_inv + e * (size_t)dd, Fe);
        if (pn_elastic_energy(&m->groups[m->egroup[PN__FEM_ELEM(m, e)]].material, d, Fe, m->h[e], &psi, NULL, NULL, 0) != PN_OK)
            return PN_ERROR_INVERTED;
        el += m->vol0[e] * psi;
    }
    for (k = 0; k < m->n_nodes * (size_t)d; ++k) kin += m->mass[k / (size_t)d] * m->v[k] * m->v[k] / 2;
    if (elastic_j) *elastic_j = el;
    if (kinetic_j) *kinetic_j = kin;
    return PN_OK;
}

/* ======================================================================================
   >>fem-io: loaders: Gmsh .msh (ASCII 2.2 and 4.1), TetGen .node / .ele.
   ====================================================================================== */

typedef struct pn__fem_lex {
    const char *p, *end;
    long line;                   /* 1-based line of the next token                          */
} pn__fem_lex;

/* the next whitespace-separated token into tok (cap bytes, NUL-terminated); 0 at the end or
   for a token longer than cap - 1. TetGen's '#' comments run to the end of the line. */
static int pn__fem_tok(pn__fem_lex *L, char *tok, size_t cap, int comments) {
    size_t n = 0;
    for (;;) {
        while (L->p < L->end && (*L->p == ' ' || *L->p == '\t' || *L->p == '\r' || *L->p == '\n')) {
            if (*L->p == '\n') L->line++;
            L->p++;
        }
        if (comments && L->p < L->end && *L->p == '#') {
            while (L->p < L->end && *L->p != '\n') L->p++;
            continue;
        }
        break;
    }
    if (L->p >= L->end) return 0;
    while (L->p < L->end && !(*L->p == ' ' || *L->p == '\t' || *L->p == '\r' || *L->p == '\n')) {
        if (n + 1 >= cap) return 0;
        tok[n++] = *L->p++;
    }
    tok[n] = 0;
    return 1;
}

static int pn__fem_long(pn__fem_lex *L, long *v, int comments) {
    char t[64], *e;
    long x;
    if (!pn__fem_tok(L, t, sizeof t, comments)) return 0;
    x = strtol(t, &e, 10);
    if (*e || e == t) return 0;
    *v = x;
    return 1;
}

static int pn__fem_real(pn__fem_lex *L, pn_real *v, int comments) {
    char t[64], *e;
    double x;
    if (!pn__fem_tok(L, t, sizeof t, comments)) return 0;
    x = strtod(t, &e);
    if (*e || e == t || !(x == x) || x - x != 0) return 0;
    *v = (pn_real)x;
    return 1;
}

/* skip to the line after the next one that starts with `tag` (e.g. "$Nodes"); 0 if none */
static int pn__fem_section(pn__fem_lex *L, const char *tag) {
    size_t n = strlen(tag);
    const char *p = L->p;
    long line = L->line;
    while (p < L->end) {
        int at_start = p == L->p || p[-1] == '\n';
        if (at_start && (size_t)(L->end - p) >= n && !memcmp(p, tag, n) &&
            (p + n == L->end || p[n] == '\n' || p[n] == '\r' || p[n] == ' ')) {
            L->p = p + n;
            L->line = line;
            return 1;
        }
        if (*p == '\n') line++;
        p++;
    }
    return 0;
}

PN__DEF void pn_fem_mesh_data_free(pn_fem_mesh_data *d, const pn_allocator *al) {
    if (!d) return;
    pn_free(al, d->nodes);
    pn_free(al, d->elements);
    pn_free(al, d->element_tags);
    memset(d, 0, sizeof *d);
}

/* node id -> index by binary search over ids sorted with their index (pairs) */
static long pn__fem_find(const long *pairs, size_t n, long id) {
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        if (pairs[2 * mid] < id) lo = mid + 1;
        else hi = mid;
    }
    return lo < n && pairs[2 * lo] == id ? pairs[2 * lo + 1] : -1;
}

/* The loaders' common end: element node ids to indices, orientation, duplicates of ids */
static pn_result pn__fem_finish(pn_fem_mesh_data *d, long *ids, char *why, size_t cap) {
    size_t k, e;
    int dp = pn__fem_nodes_of(d->dim, d->order), a;
    pn__fem_sort_longs(ids, d->n_nodes, 2, 1);
    for (k = 1; k < d->n_nodes; ++k)
        if (ids[2 * k] == ids[2 * k - 2]) {
            pn__msg(why, cap, "node id %ld appears twice", ids[2 * k]);
            return PN_ERROR_FORMAT;
        }
    for (e = 0; e < d->n_elements; ++e) {
        int *el = d->elements + e * (size_t)dp;
        pn_real Ds[9];
        for (a = 0; a < dp; ++a) {
            long ix = pn__fem_find(ids, d->n_nodes, (long)el[a]);
            if (ix < 0) {
                pn__msg(why, cap, "element %lu names node %d, which is not in the file", (unsigned long)e, el[a]);
                return PN_ERROR_FORMAT;
            }
            el[a] = (int)ix;
        }
        for (a = 1; a <= d->dim; ++a) { /* orient positively (Gmsh and TetGen may list either way) */
            int i;
            for (i = 0; i < d->dim; ++i)
                Ds[i * d->dim + a - 1] = d->nodes[(size_t)el[a] * (size_t)d->dim + (size_t)i] - d->nodes[(size_t)el[0] * (size_t)d->dim + (size_t)i];
        }
        if (pn_mat_det(d->dim, Ds) < 0) { /* corners 1 and 2 swap; so do the edge nodes they name */
            int t = el[1];
            el[1] = el[2], el[2] = t;
            if (d->order == 2 && d->dim == 2) t = el[3], el[3] = el[5], el[5] = t;    /* 01 <-> 02 */
            if (d->order == 2 && d->dim == 3) {
                t = el[4], el[4] = el[6], el[6] = t; /* 01 <-> 02 */
                t = el[8], el[8] = el[9], el[9] = t; /* 32 <-> 31 */
            }
        }
    }
    return PN_OK;
}

/* the loaders' end: the ids to indices and the orientation (pn__fem_finish) when r is PN_OK,
   then d handed to *out, or freed on failure; ids freed either way */
static pn_result pn__fem_loaded(pn_fem_mesh_data *d, long *ids, const pn_allocator *al, pn_result r, pn_fem_mesh_data *out,
                                char *why, size_t cap) {
    if (r == PN_OK) r = pn__fem_finish(d, ids, why, cap);
    pn_free(al, ids);
    if (r == PN_OK) {
        *out = *d;
        return PN_OK;
    }
    pn_fem_mesh_data_free(d, al);
    return r;
}

/* grow an array to hold n items of size bytes (capacity doubling; the capacity in *capn) */
static int pn__fem_grow(const pn_allocator *al, void **arr, size_t *capn, size_t n, size_t size) {
    void *p;
    size_t nc;
    if (n <= *capn) return 1;
    nc = *capn ? *capn : 64;
    while (nc < n) nc *= 2;
    p = pn_alloc(al, nc * size);
    if (!p) return 0;
    if (*arr) memcpy(p, *arr, *capn * size), pn_free(al, *arr);
    *arr = p;
    *capn = nc;
    return 1;
}

PN__DEF pn_result pn_fem_parse_msh(const char *text, size_t len, int dim, const pn_allocator *al, pn_fem_mesh_data *out,
                                   char *why, size_t cap) {
    pn__fem_lex L;
    pn_fem_mesh_data d;
    long *ids = NULL, v, nblocks, k, j;
    pn_real version = 0;
    size_t cap_el = 0, cap_tag = 0, nn = 0;
    int want = dim == 2 ? 2 : 4, v4; /* Gmsh element types: 2 the 3-node triangle, 4 the 4-node tetrahedron */
    int want2 = dim == 2 ? 9 : 11;   /* 9 the 6-node triangle, 11 the 10-node tetrahedron */
    pn_result r = PN_ERROR_FORMAT;
    if (why && cap) why[0] = 0;
    if (!out || (!text && len)) return PN_ERROR_INVALID_ARGUMENT;
    memset(out, 0, sizeof *out);
    if (!pn__dim_ok(dim)) return PN_ERROR_DIMENSION;
    if (al && (al->alloc == NULL) != (al->free == NULL)) return PN_ERROR_INVALID_ARGUMENT;
    memset(&d, 0, sizeof d);
    d.dim = dim, d.order = 1;
    L.p = text, L.end = text ? text + len : text, L.line = 1; /* NULL + 0 is undefined in C */
#define PN__MSH_FAIL(...) do { pn__msg(why, cap, __VA_ARGS__); goto fail; } while (0)
    if (!pn__fem_section(&L, "$MeshFormat") || !pn__fem_real(&L, &version, 0)) PN__MSH_FAIL("line %ld: no $MeshFormat", L.line);
    if (!(version >= 2 && version < 3) && !(version >= 4 && version < 5))
        PN__MSH_FAIL("line %ld: MeshFormat %g: versions 2.x and 4.x are read", L.line, (double)version);
    v4 = version >= 4;
    if (!pn__fem_long(&L, &v, 0) || v != 0) PN__MSH_FAIL("line %ld: only ASCII .msh files are read (file-type 0)", L.line);
    if (!pn__fem_section(&L, "$Nodes")) PN__MSH_FAIL("no $Nodes section");
    if (v4) {
        long total, minmax;
        if (!pn__fem_long(&L, &nblocks, 0) || !pn__fem_long(&L, &total, 0) || !pn__fem_long(&L, &minmax, 0) ||
            !pn__fem_long(&L, &minmax, 0) || nblocks < 0 || total < 0 || total > 0x7fffffffL)
            PN__MSH_FAIL("line %ld: a bad $Nodes header", L.line);
        d.n_nodes = (size_t)total;
    } else {
        if (!pn__fem_long(&L, &v, 0) || v < 0 || v > 0x7fffffffL) PN__MSH_FAIL("line %ld: a bad node count", L.line);
        d.n_nodes = (size_t)v, nblocks = 1;
    }
    if ((size_t)(L.end - L.p) / 4 < d.n_nodes) PN__MSH_FAIL("line %ld: %lu nodes cannot fit in the rest of the file", L.line, (unsigned long)d.n_nodes);
    d.nodes = (pn_real *)pn_alloc(al, sizeof(pn_real) * (d.n_nodes ? d.n_nodes : 1) * (size_t)dim);
    ids = (long *)pn_alloc(al, sizeof(long) * 2 * (d.n_nodes ? d.n_nodes : 1));
    if (!d.nodes || !ids) {
        r = PN_ERROR_OUT_OF_MEMORY;
        PN__MSH_FAIL("out of memory for %lu nodes", (unsigned long)d.n_nodes);
    }
    for (k = 0; k < nblocks; ++k) {
        long in_block = (long)d.n_nodes, param = 0, ent, edim = 0;
        if (v4 && (!pn__fem_long(&L, &edim, 0) || !pn__fem_long(&L, &ent, 0) || !pn__fem_long(&L, &param, 0) ||
                   !pn__fem_long(&L, &in_block, 0) || in_block < 0 || (size_t)in_block > d.n_nodes - nn || edim < 0 || edim > 3))
            PN__MSH_FAIL("line %ld: a bad node block", L.line);
        if (v4)
            for (j = 0; j < in_block; ++j) /* v4: the tags first, then the coordinates */
                if (!pn__fem_long(&L, &ids[2 * (nn + (size_t)j)], 0)) PN__MSH_FAIL("line %ld: a bad node tag", L.line);
        for (j = 0; j < in_block; ++j) {
            pn_real xyz[3], skip;
            size_t at = nn + (size_t)j;
            int i;
            if (!v4 && !pn__fem_long(&L, &ids[2 * at], 0)) PN__MSH_FAIL("line %ld: a bad node tag", L.line);
            for (i = 0; i < 3; ++i)
                if (!pn__fem_real(&L, &xyz[i], 0)) PN__MSH_FAIL("line %ld: node %ld: a coordinate that is not a finite number", L.line, ids[2 * at]);
            if (v4 && param) /* the parametric coordinates on the entity: skipped */
                for (i = 0; i < (int)edim; ++i)
                    if (!pn__fem_real(&L, &skip, 0)) PN__MSH_FAIL("line %ld: node %ld: a bad parametric coordinate", L.line, ids[2 * at]);
            for (i = 0; i < dim; ++i) d.nodes[at * (size_t)dim + (size_t)i] = xyz[i];
            ids[2 * at + 1] = (long)at;
        }
        nn += (size_t)in_block;
    }
    if (nn != d.n_nodes) PN__MSH_FAIL("line %ld: the node blocks hold %lu nodes, the header says %lu", L.line, (unsigned long)nn,
                                      (unsigned long)d.n_nodes);
    if (!pn__fem_section(&L, "$Elements")) PN__MSH_FAIL("no $Elements section");
    if (v4) {
        long total, mm;
        if (!pn__fem_long(&L, &nblocks, 0) || !pn__fem_long(&L, &total, 0) || !pn__fem_long(&L, &mm, 0) || !pn__fem_long(&L, &mm, 0) ||
            nblocks < 0 || total < 0)
            PN__MSH_FAIL("line %ld: a bad $Elements header", L.line);
    } else {
        if (!pn__fem_long(&L, &v, 0) || v < 0) PN__MSH_FAIL("line %ld: a bad element count", L.line);
        nblocks = v; /* v2: one element per "block" */
    }
    for (k = 0; k < nblocks; ++k) {
        long type, in_block = 1, tag = 0, ntags, ent;
        if (v4) {
            if (!pn__fem_long(&L, &ent, 0) || !pn__fem_long(&L, &tag, 0) || !pn__fem_long(&L, &type, 0) ||
                !pn__fem_long(&L, &in_block, 0) || in_block < 0)
                PN__MSH_FAIL("line %ld: a bad element block", L.line);
        }
        for (j = 0; j < in_block; ++j) {
            long id, nv, t, q;
            if (!pn__fem_long(&L, &id, 0)) PN__MSH_FAIL("line %ld: a bad element", L.line);
            if (!v4) {
                if (!pn__fem_long(&L, &type, 0) || !pn__fem_long(&L, &ntags, 0) || ntags < 0 || ntags > 64)
                    PN__MSH_FAIL("line %ld: element %ld: a bad type or tag count", L.line, id);
                for (t = 0; t < ntags; ++t) {
                    if (!pn__fem_long(&L, &q, 0)) PN__MSH_FAIL("line %ld: element %ld: a bad tag", L.line, id);
                    if (t == 0) tag = q; /* the physical group */
                }
            }
            /* vertices per element type: 15 point, 1 line, 2 triangle, 3 quad, 4 tet, 5 hex, 6 prism, 7 pyramid,
               8 line3, 9 tri6, 11 tet10 */
            nv = type == 15 ? 1 : type == 1 ? 2 : type == 2 ? 3 : type == 3 ? 4 : type == 4 ? 4 : type == 5 ? 8 : type == 6 ? 6
                 : type == 7 ? 5 : type == 8 ? 3 : type == 9 ? 6 : type == 11 ? 10 : -1;
            if (nv < 0) PN__MSH_FAIL("line %ld: element %ld: type %ld is not read (triangles and tetrahedra are)", L.line, id, type);
            if (type == want || type == want2) {
                int *el, o = type == want2 ? 2 : 1;
                if (d.n_elements && o != d.order)
                    PN__MSH_FAIL("line %ld: element %ld: the file has both linear and quadratic %s", L.line, id,
                                 dim == 2 ? "triangles" : "tetrahedra");
                d.order = o;
                if (!pn__fem_grow(al, (void **)&d.elements, &cap_el, (d.n_elements + 1) * (size_t)nv, sizeof(int)) ||
                    !pn__fem_grow(al, (void **)&d.element_tags, &cap_tag, d.n_elements + 1, sizeof(int))) {
                    r = PN_ERROR_OUT_OF_MEMORY;
                    PN__MSH_FAIL("out of memory at element %ld", id);
                }
                el = d.elements + d.n_elements * (size_t)nv;
                for (t = 0; t < nv; ++t) {
                    if (!pn__fem_long(&L, &q, 0) || q < -0x7fffffffL || q > 0x7fffffffL)
                        PN__MSH_FAIL("line %ld: element %ld: a bad node tag", L.line, id);
                    el[t] = (int)q;
                }
                d.element_tags[d.n_elements++] = (int)(tag > 0x7fffffffL || tag < -0x7fffffffL ? 0 : tag);
            } else
                for (t = 0; t < nv; ++t)
                    if (!pn__fem_long(&L, &q, 0)) PN__MSH_FAIL("line %ld: element %ld: a bad node tag", L.line, id);
        }
    }
    if (!d.n_elements)
        PN__MSH_FAIL("the file has no %s", dim == 2 ? "3- or 6-node triangles (type 2, 9)" : "4- or 10-node tetrahedra (type 4, 11)");
    return pn__fem_loaded(&d, ids, al, PN_OK, out, why, cap);
fail:
#undef PN__MSH_FAIL
    return pn__fem_loaded(&d, ids, al, r == PN_OK ? PN_ERROR_FORMAT : r, out, why, cap);
}

PN__DEF pn_result pn_fem_parse_tetgen(const char *node_text, size_t node_len, const char *ele_text, size_t ele_len,
                                      const pn_allocator *al, pn_fem_mesh_data *out, char *why, size_t cap) {
    pn__fem_lex L;
    pn_fem_mesh_data d;
    long *ids = NULL, n, dimf, nattr, nmark, ne, per, rattr, k;
    pn_result r = PN_ERROR_FORMAT;
    if (why && cap) why[0] = 0;
    if (!out || (!node_text && node_len) || (!ele_text && ele_len)) return PN_ERROR_INVALID_ARGUMENT;
    memset(out, 0, sizeof *out);
    if (al && (al->alloc == NULL) != (al->free == NULL)) return PN_ERROR_INVALID_ARGUMENT;
    if (!pn__dim_ok(3)) return PN_ERROR_DIMENSION;
    memset(&d, 0, sizeof d);
    d.dim = 3, d.order = 1;
#define PN__TG_FAIL(...) do { pn__msg(why, cap, __VA_ARGS__); goto fail; } while (0)
    L.p = node_text, L.end = node_text ? node_text + node_len : node_text, L.line = 1;
    if (!pn__fem_long(&L, &n, 1) || !pn__fem_long(&L, &dimf, 1) || !pn__fem_long(&L, &nattr, 1) || !pn__fem_long(&L, &nmark, 1) ||
        n < 0 || n > 0x7fffffffL || dimf != 3 || nattr < 0 || nattr > 64 || nmark < 0 || nmark > 1)
        PN__TG_FAIL(".node line %ld: a bad header (count, dimension 3, attributes, boundary marker 0 or 1)", L.line);
    if ((size_t)(L.end - L.p) / 4 < (size_t)n) PN__TG_FAIL(".node line %ld: %ld nodes cannot fit in the file", L.line, n);
    d.n_nodes = (size_t)n;
    d.nodes = (pn_real *)pn_alloc(al, sizeof(pn_real) * 3 * (d.n_nodes ? d.n_nodes : 1));
    ids = (long *)pn_alloc(al, sizeof(long) * 2 * (d.n_nodes ? d.n_nodes : 1));
    if (!d.nodes || !ids) {
        r = PN_ERROR_OUT_OF_MEMORY;
        PN__TG_FAIL("out of memory for %ld nodes", n);
    }
    for (k = 0; k < n; ++k) {
        pn_real skip;
        long ks;
        int i;
        if (!pn__fem_long(&L, &ids[2 * k], 1)) PN__TG_FAIL(".node line %ld: a bad node index", L.line);
        ids[2 * k + 1] = k;
        for (i = 0; i < 3; ++i)
            if (!pn__fem_real(&L, &d.nodes[(size_t)k * 3 + (size_t)i], 1))
                PN__TG_FAIL(".node line %ld: node %ld: a coordinate that is not a finite number", L.line, ids[2 * k]);
        for (i = 0; i < nattr; ++i)
            if (!pn__fem_real(&L, &skip, 1)) PN__TG_FAIL(".node line %ld: node %ld: a bad attribute", L.line, ids[2 * k]);
        if (nmark && !pn__fem_long(&L, &ks, 1)) PN__TG_FAIL(".node line %ld: node %ld: a bad boundary marker", L.line, ids[2 * k]);
    }
    L.p = ele_text, L.end = ele_text ? ele_text + ele_len : ele_text, L.line = 1;
    if (!pn__fem_long(&L, &ne, 1) || !pn__fem_long(&L, &per, 1) || !pn__fem_long(&L, &rattr, 1) || ne < 0 || ne > 0x7fffffffL ||
        (per != 4 && per != 10) || (rattr != 0 && rattr != 1))
        PN__TG_FAIL(".ele line %ld: a bad header (count, 4 or 10 nodes per tetrahedron, region attribute 0 or 1)", L.line);
    if ((size_t)(L.end - L.p) / 8 < (size_t)ne) PN__TG_FAIL(".ele line %ld: %ld elements cannot fit in the file", L.line, ne);
    d.n_elements = (size_t)ne;
    d.elements = (int *)pn_alloc(al, sizeof(int) * 4 * (d.n_elements ? d.n_elements : 1));
    d.element_tags = (int *)pn_alloc(al, sizeof(int) * (d.n_elements ? d.n_elements : 1));
    if (!d.elements || !d.element_tags) {
        r = PN_ERROR_OUT_OF_MEMORY;
        PN__TG_FAIL("out of memory for %ld elements", ne);
    }
    for (k = 0; k < ne; ++k) {
        long id, q, i;
        pn_real at = 0;
        if (!pn__fem_long(&L, &id, 1)) PN__TG_FAIL(".ele line %ld: a bad element index", L.line);
        for (i = 0; i < per; ++i) {
            if (!pn__fem_long(&L, &q, 1) || q < -0x7fffffffL || q > 0x7fffffffL)
                PN__TG_FAIL(".ele line %ld: element %ld: a bad node index", L.line, id);
            if (i < 4) d.elements[(size_t)k * 4 + (size_t)i] = (int)q;
        }
        if (rattr && !pn__fem_real(&L, &at, 1)) PN__TG_FAIL(".ele line %ld: element %ld: a bad region attribute", L.line, id);
        d.element_tags[k] = at > -2e9 && at < 2e9 ? (int)at : 0;
    }
    if (!d.n_elements) PN__TG_FAIL(".ele: no tetrahedra");
    return pn__fem_loaded(&d, ids, al, PN_OK, out, why, cap);
fail:
#undef PN__TG_FAIL
    return pn__fem_loaded(&d, ids, al, r == PN_OK ? PN_ERROR_FORMAT : r, out, why, cap);
}

/* ======================================================================================
   >>couple: an MPM world and an FEM mesh in one step (BFEMP: Li, Fang, Li and Jiang 2021).
   The interface is the IPC barrier of pn__pair_barrier between each particle and each
   boundary target of the mesh (2D edges, 3D triangles), weight kappa_p = k a_p / dhat.
   Implicit, in velocity units (the MPM step's E(v); the mesh's incremental potential over
   dt^2 with x = x^n + dt u, so its Hessian in u is its Hessian in x, mass + dt^2 K):
       E(v, u) = E_mpm(v) + E_fem(x^n + dt u) / dt^2 + sum kappa_p b(d(y_p, x)) + D
   y_p = x_p^n + dt sum_i w_ip v_i is linear in v and x in u, so the pair's derivatives
   follow by the chain rule (dy_p/dv_i = dt w_ip, dx_a/du_a = dt) and additive CCD
   applies along a Newton direction as it does to the mesh alone. D is IPC's lagged
   friction: mu lambda f0(|T r|), r = dt (sum w v - sum beta_a u_a) the relative tangential
   motion at the lagged closest point (weights beta), lambda the lagged normal force.
   ====================================================================================== */

typedef struct pn__cpl {
    size_t nv, nu, nz, zcap;     /* unknowns: grid velocities (n_act dim), mesh (nodes dim)  */
    pn_real *z, *g, *dir, *zt, *r, *zz, *pp, *qq; /* iterate, gradient, direction, try, CG  */
    pn_real *gf;                 /* Newton: the filtered gradient's negative, -S g             */
    pn_real *xf, *xd, *pa, *pb;  /* mesh positions, its direction in positions, row scratch */
    pn_real *y, *yd;             /* per particle: y_p, and its motion along the direction   */
    size_t *cp, *ck, nc, ccap;   /* candidate pairs: particle, boundary target               */
    pn_real *ch;                 /* per candidate (PN__CPL_H reals): the barrier's Hessian in
                                    y, or 0s, then its mesh-mesh block's exact part less the
                                    projected one the mesh's matrix holds (exact: else 0s)   */
    int exact;                   /* this iteration's pair Hessians are exact (not projected) */
    unsigned char *con;          /* the candidate is within dhat at the Hessian's iterate    */
    size_t *fp, nf, fcap;        /* lagged friction pairs: particle, target nodes (3 each),  */
    long *fnode;                 /* the weights beta (3), the normal (3), mu lambda, and the */
    pn_real *fdat;               /* friction's Hessian in r (9): 19 reals each               */
    pn_real *fx;                 /* explicit: the particles' forces (dim each), then those of
                                    the particles that have one, compact                    */
    size_t *fidx;                /* explicit: the particles that have one                   */
    pn_real *vn, *g0, *m0;       /* theta < 1: the unknowns' velocities at the step's start,
                                    the potentials' gradient there, the grid's and the
                                    mesh's masses                                           */
    pn_real theta, lin;          /* this step's theta; the start gradient's weight in E:
                                    (1 - theta) / theta (0: backward Euler)                 */
    pn_real dt, dmin, kap_area;  /* kappa_p = kap_area a_p                                  */
} pn__cpl;

#define PN__CPL_FD 19
#define PN__CPL_H(d) (PN__FEM_PAIR_H(d) + (d) * (d) * (d) * (d))

/* particle p's stencil: compact node indices (into the implicit step's active nodes) and
   weights */
static int pn__cpl_stencil(const pn_mpm_world *w, size_t p, long *node, pn_real *wt) {
    int s;
    pn_real dpos[3];
    for (s = 0; s < w->s.ns; ++s) {
        node[s] = w->s.dof[w->s.pbase[p] + w->s.slot_off[s]];
        wt[s] = pn__mpm_weight(w, p, w->s.slot[s], dpos);
    }
    return w->s.ns;
}

static pn_real pn__cpl_kappa(const pn_coupled *c, size_t p) {
    const pn__cpl *k = (const pn__cpl *)c->impl;
    int d = c->mpm->dim;
    pn_real v = c->mpm->vol0[p];
    return k->kap_area * (d == 2 ? PN__SQRT(v) : (pn_real)pow((double)v, 2.0 / 3));
}

/* grow an array of count items to at least need (doubling); 0 when out of memory */
static int pn__cpl_grow(const pn_allocator *al, void **a, size_t have, size_t need, size_t size) {
    void *b;
    if (need <= have) return 1;
    b = pn_alloc(al, need * size);
    if (!b) return 0;
    if (*a) memcpy(b, *a, have * size);
    pn_free(al, *a);
    *a = b;
    return 1;
}

/* the candidate pairs' arrays (cp, ck, ch, con) for at least need pairs */
static pn_result pn__cpl_grow_pairs(pn_coupled *c, size_t need) {
    pn__cpl *k = (pn__cpl *)c->impl;
    const pn_allocator *al = &c->fem->desc.allocator;
    size_t h = PN__CPL_H(c->mpm->dim);
    if (need <= k->ccap) return PN_OK;
    if (!pn__cpl_grow(al, (void **)&k->cp, k->ccap, need, sizeof(size_t)) ||
        !pn__cpl_grow(al, (void **)&k->ck, k->ccap, need, sizeof(size_t)) ||
        !pn__cpl_grow(al, (void **)&k->ch, k->ccap * h, need * h, sizeof(pn_real)) ||
        !pn__cpl_grow(al, (void **)&k->con, k->ccap, need, 1))
        return PN__FAIL(c, PN_ERROR_OUT_OF_MEMORY, "coupled step: out of memory for %lu particle-boundary pairs",
                            (unsigned long)need);
    k->ccap = need;
    return PN_OK;
}

/* the friction pairs' arrays (fp, fnode, fdat) for at least need pairs */
static pn_result pn__cpl_grow_friction(pn_coupled *c, size_t need) {
    pn__cpl *k = (pn__cpl *)c->impl;
    const pn_allocator *al = &c->fem->desc.allocator;
    if (need <= k->fcap) return PN_OK;
    if (!pn__cpl_grow(al, (void **)&k->fp, k->fcap, need, sizeof(size_t)) ||
        !pn__cpl_grow(al, (void **)&k->fnode, 3 * k->fcap, 3 * need, sizeof(long)) ||
        !pn__cpl_grow(al, (void **)&k->fdat, PN__CPL_FD * k->fcap, PN__CPL_FD * need, sizeof(pn_real)))
        return PN__FAIL(c, PN_ERROR_OUT_OF_MEMORY, "coupled step: out of memory for the friction pairs");
    k->fcap = need;
    return PN_OK;
}

/* the target's nodes (d of them: a 2D edge's 2, a 3D triangle's 3) */
static const int *pn__cpl_target(const pn_fem_mesh *m, size_t t) {
    const pn__fem *s = (const pn__fem *)m->impl;
    return m->dim == 2 ? s->bedge + 2 * t : s->bface + 3 * t;
}

/* the mesh's positions and velocities finite (the world's checks its own) */
static pn_result pn__cpl_check_mesh(pn_coupled *c, const char *who) {
    if ((c->error_node = pn__fem_nonfinite_node(c->fem)) >= 0)
        return PN__FAIL(c, PN_ERROR_NONFINITE, "%s: the mesh's node %ld has a non-finite position or velocity", who,
                            c->error_node);
    return PN_OK;
}

/* The candidate and friction pairs' storage, reserved once so that steps do not allocate:
   each target's box grown by dhat and a cell on every side (what a step's motion adds), at
   the densest particle spacing, twice over; never more than every particle with every
   target. A scene beyond it (a mesh that stretches a great deal) still grows the arrays,
   doubling, in the step that needs it. */
static pn_result pn__cpl_reserve(pn_coupled *c) {
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn__fem *s = (pn__fem *)m->impl;
    pn_result r;
    int d = w->dim, i;
    size_t t, p, active = 0, need;
    double vmin = HUGE_VAL, est = 0, pad = 2 * ((double)c->dhat + (double)w->desc.dx_m);
    for (p = 0; p < w->n; ++p)
        if (w->active[p]) active++, vmin = PN__MIN(vmin, (double)w->vol0[p]);
    if (!active || !(vmin > 0)) return PN_OK;
    for (t = 0; t < s->ntgt; ++t) {
        const int *tn = pn__cpl_target(m, t);
        double box = 1;
        for (i = 0; i < d; ++i) {
            double lo = HUGE_VAL, hi = -HUGE_VAL;
            int j;
            for (j = 0; j < d; ++j) {
                double x = (double)m->x[(size_t)tn[j] * (size_t)d + (size_t)i];
                lo = PN__MIN(lo, x), hi = PN__MAX(hi, x);
            }
            box *= hi - lo + pad;
        }
        est += 2 * box / vmin;
    }
    need = est < (double)active * (double)s->ntgt ? (size_t)est + 256 : active * s->ntgt;
    if ((r = pn__cpl_grow_pairs(c, need)) != PN_OK) return r;
    return c->friction > 0 ? pn__cpl_grow_friction(c, need) : PN_OK;
}

/* the coupled solver's storage for the world's grid and the mesh: once */
static pn_result pn__cpl_alloc(pn_coupled *c) {
    pn__cpl *k = (pn__cpl *)c->impl;
    const pn_allocator *al = &c->fem->desc.allocator;
    int d = c->mpm->dim;
    size_t nd = c->fem->n_nodes * (size_t)d, np = c->mpm->cap * (size_t)d, zc = c->mpm->s.nodes * (size_t)d + nd;
    if (k->z) return PN_OK;
    k->z = (pn_real *)pn_alloc(al, sizeof(pn_real) * (12 * zc + 4 * nd + 4 * np + 8));
    k->fidx = (size_t *)pn_alloc(al, sizeof(size_t) * (c->mpm->cap + 1));
    if (!k->z || !k->fidx) {
        pn_free(al, k->z), pn_free(al, k->fidx);
        k->z = NULL, k->fidx = NULL;
        return PN__FAIL(c, PN_ERROR_OUT_OF_MEMORY, "coupled step: out of memory for the solver storage");
    }
    k->zcap = zc;
    k->g = k->z + zc, k->dir = k->g + zc, k->zt = k->dir + zc, k->r = k->zt + zc, k->zz = k->r + zc, k->pp = k->zz + zc;
    k->qq = k->pp + zc, k->xf = k->qq + zc, k->xd = k->xf + nd, k->pa = k->xd + nd, k->pb = k->pa + nd;
    k->y = k->pb + nd, k->yd = k->y + np, k->fx = k->yd + np, k->vn = k->fx + 2 * np, k->g0 = k->vn + zc;
    k->m0 = k->g0 + zc, k->gf = k->m0 + zc;
    return pn__cpl_reserve(c);
}

PN__DEF void pn_coupled_destroy(pn_coupled *c) {
    pn__cpl *k;
    const pn_allocator *al;
    if (!c) return;
    k = (pn__cpl *)c->impl, al = &c->fem->desc.allocator;
    if (k) {
        pn_free(al, k->z), pn_free(al, k->fidx), pn_free(al, k->cp), pn_free(al, k->ck), pn_free(al, k->ch);
        pn_free(al, k->con), pn_free(al, k->fp), pn_free(al, k->fnode), pn_free(al, k->fdat);
        pn_free(al, k);
    }
    pn_free(al, c);
}

PN__DEF const char *pn_coupled_error(const pn_coupled *c) { return c ? c->error : ""; }

PN__DEF pn_result pn_coupled_create(pn_mpm_world *w, pn_fem_mesh *m, const pn_coupled_desc *desc, pn_coupled **out,
                                    char *why, size_t why_cap) {
    pn_coupled_desc de;
    pn_coupled *c;
    pn__cpl *k;
    const pn_allocator *al;
    pn_real emax = 0, dist;
    pn_result r;
    int g, d;
    size_t p, e;
    if (why && why_cap) why[0] = 0;
    if (!w || !m || !out) {
        pn__msg(why, why_cap, "pn_coupled_create: the world, the mesh and out must not be NULL");
        return PN_ERROR_INVALID_ARGUMENT;
    }
    *out = NULL;
    if (w->dim != m->dim) {
        pn__msg(why, why_cap, "pn_coupled_create: the world is %dD, the mesh %dD", w->dim, m->dim);
        return PN_ERROR_DIMENSION;
    }
    d = w->dim;
    memset(&de, 0, sizeof de);
    if (desc) de = *desc;
    if (!pn__finite(de.contact_distance_m) || de.contact_distance_m < 0 || !pn__finite(de.contact_stiffness) ||
        de.contact_stiffness < 0 || !pn__finite(de.friction) || de.friction < 0 || !pn__finite(de.friction_velocity_m_s) ||
        de.friction_velocity_m_s < 0) {
        pn__msg(why, why_cap, "pn_coupled_desc: contact_distance_m %g, contact_stiffness %g, friction %g and "
                    "friction_velocity_m_s %g must be finite and >= 0 (0: the default)", (double)de.contact_distance_m,
                    (double)de.contact_stiffness, (double)de.friction, (double)de.friction_velocity_m_s);
        return PN_ERROR_INVALID_ARGUMENT;
    }
    for (e = 0; e < m->n_nodes * (size_t)d; ++e) { /* the mesh within the walls, where the particles are */
        int a = (int)(e % (size_t)d);
        if (!(m->x[e] >= w->s.wall_lo[a] && m->x[e] <= w->s.wall_hi[a])) {
            pn__msg(why, why_cap, "pn_coupled_create: the mesh's node %lu is at %g m on axis %d, outside the world's "
                        "walls [%g, %g] m", (unsigned long)(e / (size_t)d), (double)m->x[e], a, (double)w->s.wall_lo[a],
                        (double)w->s.wall_hi[a]);
            return pn__finite(m->x[e]) ? PN_ERROR_OUTSIDE_DOMAIN : PN_ERROR_NONFINITE;
        }
    }
    for (g = 0; g < w->n_groups; ++g) emax = PN__MAX(emax, w->groups[g].material.E);
    al = &m->desc.allocator;
    c = (pn_coupled *)pn_alloc(al, sizeof *c);
    k = (pn__cpl *)pn_alloc(al, sizeof *k);
    if (!c || !k) {
        pn_free(al, c), pn_free(al, k);
        pn__msg(why, why_cap, "pn_coupled_create: out of memory");
        return PN_ERROR_OUT_OF_MEMORY;
    }
    memset(c, 0, sizeof *c);
    memset(k, 0, sizeof *k);
    c->impl = k, c->mpm = w, c->fem = m;
    c->dhat = de.contact_distance_m > 0 ? de.contact_distance_m : w->desc.dx_m / 4;
    c->stiffness = de.contact_stiffness > 0 ? de.contact_stiffness : (pn_real)0.1 * (emax > 0 ? emax : 1);
    c->friction = de.friction;
    c->eps_v = de.friction_velocity_m_s > 0 ? de.friction_velocity_m_s : (pn_real)1e-2;
    k->kap_area = c->stiffness / c->dhat;
    c->error_particle = c->error_node = -1;
    if ((r = pn__cpl_alloc(c)) != PN_OK) {
        pn_coupled_destroy(c);
        pn__msg(why, why_cap, "pn_coupled_create: out of memory");
        return r;
    }
    /* no particle on the boundary or inside the mesh: the barrier keeps them apart only if
       they start apart */
    if ((r = pn_coupled_min_distance(c, &dist)) != PN_OK || !(dist > 0)) {
        pn__msg(why, why_cap, "pn_coupled_create: particle %ld touches the mesh's boundary", c->error_particle);
        pn_coupled_destroy(c);
        return r != PN_OK ? r : PN_ERROR_INVALID_ARGUMENT;
    }
    for (e = 0; e < m->n_elems * (size_t)pn__fem_nsub(m); ++e) { /* each element's linear pieces */
        pn_real Ds[9], Di[9], lo[3], hi[3];
        const int *en = m->elem + (e / (size_t)pn__fem_nsub(m)) * (size_t)m->nodes_per_element;
        const int *sub = pn__fem_sub(m, (int)(e % (size_t)pn__fem_nsub(m)));
        int a, j, el[4];
        for (j = 0; j <= d; ++j) el[j] = en[sub[j]];
        for (j = 1; j <= d; ++j)
            for (a = 0; a < d; ++a) Ds[a * d + j - 1] = m->x[(size_t)el[j] * (size_t)d + (size_t)a] - m->x[(size_t)el[0] * (size_t)d + (size_t)a];
        if (pn_mat_inverse(d, Ds, Di) != PN_OK) continue;
        for (a = 0; a < d; ++a) lo[a] = hi[a] = m->x[(size_t)el[0] * (size_t)d + (size_t)a];
        for (j = 1; j <= d; ++j)
            for (a = 0; a < d; ++a) {
                pn_real x = m->x[(size_t)el[j] * (size_t)d + (size_t)a];
                lo[a] = PN__MIN(lo[a], x), hi[a] = PN__MAX(hi[a], x);
            }
        for (p = 0; p < w->n; ++p) {
            const pn_real *x = w->x + p * (size_t)d;
            pn_real lam[3], sum = 0, rel[3];
            int in = w->active[p];
            for (a = 0; a < d && in; ++a) in = x[a] >= lo[a] && x[a] <= hi[a];
            if (!in) continue;
            for (a = 0; a < d; ++a) rel[a] = x[a] - m->x[(size_t)el[0] * (size_t)d + (size_t)a];
            for (a = 0; a < d; ++a) { /* barycentric: Ds^-1 (x - x_0) */
                lam[a] = 0;
                for (j = 0; j < d; ++j) lam[a] += Di[a * d + j] * rel[j];
                sum += lam[a];
                in &= lam[a] >= 0;
            }
            if (in && sum <= 1) {
                pn__msg(why, why_cap, "pn_coupled_create: particle %lu lies inside element %lu of the mesh",
                            (unsigned long)p, (unsigned long)(e / (size_t)pn__fem_nsub(m)));
                pn_coupled_destroy(c);
                return PN_ERROR_INVALID_ARGUMENT;
            }
        }
    }
    *out = c;
    return PN_OK;
}

/* ======================================================================================
   >>couple-barrier: particle-mesh pairs: each particle's position at the step's end, the
   boundary items near it (a grid of the items' boxes), the barrier's value and derivatives,
   continuous collision detection and the closest distance (pn_coupled_min_distance).
   ====================================================================================== */

/* positions: the mesh at x^n + dt u (and dt du), the particles at y_p(v) (and dt sum w dv);
   implicit == 0: the particles where they are, the mesh at its positions (dir: the motion
   each made, given as positions already) */
static void pn__cpl_positions(pn_coupled *c, int implicit, const pn_real *z, const pn_real *dz) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    int d = w->dim;
    size_t nd = m->n_nodes * (size_t)d, i;
    long lp;
    if (!implicit) return;
    for (i = 0; i < nd; ++i) {
        k->xf[i] = m->x[i] + k->dt * z[k->nv + i];
        if (dz) k->xd[i] = k->dt * dz[k->nv + i];
    }
    PN__OMP_FOR
    for (lp = 0; lp < (long)w->n; ++lp) {
        size_t p = (size_t)lp;
        long node[27];
        pn_real wt[27];
        int s, a, ns;
        if (!w->active[p]) continue;
        ns = pn__cpl_stencil(w, p, node, wt);
        for (a = 0; a < d; ++a) {
            pn_real acc = 0, acd = 0;
            for (s = 0; s < ns; ++s) {
                acc += wt[s] * z[(size_t)node[s] * (size_t)d + (size_t)a];
                if (dz) acd += wt[s] * dz[(size_t)node[s] * (size_t)d + (size_t)a];
            }
            k->y[p * (size_t)d + (size_t)a] = w->x[p * (size_t)d + (size_t)a] + k->dt * acc;
            k->yd[p * (size_t)d + (size_t)a] = dz ? k->dt * acd : 0;
        }
    }
}

/* The candidate pairs: every active particle and boundary target whose boxes (the target's
   grown by dhat; both swept along the direction when sweep) overlap, once each, in particle
   order. The mesh's broad-phase grid over its targets finds them. */
static pn_result pn__cpl_find(pn_coupled *c, int sweep) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn__fem *s = (pn__fem *)m->impl;
    int d = w->dim, i;
    size_t p, it;
    pn_real ghi[3];
    long c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0}, cc[3];
    k->nc = 0;
    pn__fem_grid_build(m, k->xf, sweep ? k->xd : NULL, 1, c->dhat);
    for (i = 0; i < d; ++i) ghi[i] = s->glo[i] + s->gcs * (pn_real)s->gn[i];
    for (p = 0; p < w->n; ++p) {
        pn_real lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
        const pn_real *y = k->y + p * (size_t)d, *yd = k->yd + p * (size_t)d;
        int out = 0;
        if (!w->active[p]) continue;
        for (i = 0; i < d; ++i) {
            pn_real a = y[i], b = sweep ? y[i] + yd[i] : a;
            lo[i] = PN__MIN(a, b), hi[i] = PN__MAX(a, b);
            out |= hi[i] < s->glo[i] || lo[i] > ghi[i];
        }
        if (out) continue;
        pn__fem_cells(s, d, lo, hi, c0, c1);
        for (cc[2] = c0[2]; cc[2] <= c1[2]; ++cc[2])
            for (cc[1] = c0[1]; cc[1] <= c1[1]; ++cc[1])
                for (cc[0] = c0[0]; cc[0] <= c1[0]; ++cc[0])
                    for (it = s->gstart[pn__fem_cell_at(s, cc)]; it < s->gstart[pn__fem_cell_at(s, cc) + 1]; ++it) {
                        size_t t = s->gitem[it];
                        if (t >= s->ntgt || !pn__fem_pair_here(s, d, lo, hi, s->ebox + 6 * t, s->ebox + 6 * t + 3, cc)) continue;
                        if (k->nc == k->ccap) {
                            pn_result r = pn__cpl_grow_pairs(c, 2 * k->ccap + 256);
                            if (r != PN_OK) return r;
                        }
                        k->cp[k->nc] = p, k->ck[k->nc] = t, k->nc++;
                    }
    }
    return PN_OK;
}

/* candidate i's coordinates [y_p, x_a, x_b (, x_c)] at the current positions (and their
   motion along the direction into dy when given) */
static void pn__cpl_pair_y(const pn_coupled *c, size_t i, pn_real *yy, pn_real *dy) {
    const pn__cpl *k = (const pn__cpl *)c->impl;
    int d = c->mpm->dim, j, a;
    const int *tn = pn__cpl_target(c->fem, k->ck[i]);
    for (a = 0; a < d; ++a) {
        yy[a] = k->y[k->cp[i] * (size_t)d + (size_t)a];
        if (dy) dy[a] = k->yd[k->cp[i] * (size_t)d + (size_t)a];
    }
    for (j = 0; j < d; ++j)
        for (a = 0; a < d; ++a) {
            yy[d + j * d + a] = k->xf[(size_t)tn[j] * (size_t)d + (size_t)a];
            if (dy) dy[d + j * d + a] = k->xd[(size_t)tn[j] * (size_t)d + (size_t)a];
        }
}

/* The barrier over the candidates at the current positions: its energy into *E, the
   smallest distance into k->dmin; level >= 1: its gradient in z into g (the chain rule:
   dt w_ip to the grid nodes, dt to the mesh nodes; held mesh nodes take none); level >= 2:
   each near pair's Hessian in y kept for CG, and its mesh-mesh part (times dt^2) added to
   the mesh's matrix. 0 when a pair touches (no barrier there).
   The mesh's matrix takes the projected (PSD) Hessians, so that its factor exists; with
   k->exact, CG's products take the exact ones (the mesh-mesh difference kept beside each).
   Projecting a pair adds curvature wherever b' hess d is indefinite, which a block resting
   on the sand is (the contact forces turn with the faces): along Newton's direction the
   projected Hessians held about twice the exact curvature, and Newton converged linearly at
   rate 1/2 (28 iterations in a 1e-2 s step of the 3D bench scene). The sum is positive
   definite near a solution, where pn__cpl_newton asks for the exact ones (and solves an
   iteration again projected where the sum is not).
   Every (particle, target) pair within dhat is one term, so a particle near a boundary
   vertex has two (3D: more, at edges and vertices): on a flat run of edges, one within
   sqrt(dhat^2 - d^2) across of a vertex has the edge over it and the next edge's end; just
   outside a convex corner both edges give the same point-vertex distance, twice that
   particle's barrier (force, stiffness). The interface stays in balance (each term's forces
   sum to zero: the sum over pairs on the mesh is its momentum change less gravity); the
   terms shift where a body rests (couple_force_balance: 18 pairs over 14 particles, the 4
   extra carry 4% of the block's weight). Kept: counting a point-vertex term once jumps the
   energy by b(d) where a particle crosses a target's end normal (one term to two), which
   Newton's line search and IPC's guarantee cannot take; the continuous edge-minus-vertex sum
   (Convergent IPC, Li et al. 2023) subtracts terms whose Hessians are not PSD where they do
   not cancel a pair's own (concave vertices), and friction's lagged forces would need it too. */
static int pn__cpl_barrier(pn_coupled *c, int level, pn_real *E) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn__fem *s = (pn__fem *)m->impl;
    int d = w->dim, n = d * (d + 1), kind = d == 2 ? PN__FEM_PE : PN__FEM_PT, j, a, b, e, f, ex = level >= 2 && k->exact;
    size_t i, h = PN__CPL_H(d);
    pn_real dt = k->dt;
    for (i = 0; i < k->nc; ++i) {
        pn_real yy[12], gl[12], Eb, dist, Hp[144], *H = k->ch + i * h, *P = ex ? Hp : H;
        long node[27];
        pn_real wt[27];
        const int *tn = pn__cpl_target(m, k->ck[i]);
        int ns;
        if (level >= 2) k->con[i] = 0;
        pn__cpl_pair_y(c, i, yy, NULL);
        if (!pn__pair_barrier(kind, d, d + 1, yy, c->dhat, pn__cpl_kappa(c, k->cp[i]), level, &Eb, gl, H, &dist, !ex)) {
            k->dmin = 0;
            c->error_particle = (long)k->cp[i];
            return 0;
        }
        k->dmin = PN__MIN(k->dmin, dist);
        if (!(dist < c->dhat)) continue;
        *E += Eb;
        if (level < 1) continue;
        ns = pn__cpl_stencil(w, k->cp[i], node, wt);
        for (j = 0; j < ns; ++j)
            for (a = 0; a < d; ++a) k->g[(size_t)node[j] * (size_t)d + (size_t)a] += dt * wt[j] * gl[a];
        for (j = 0; j < d; ++j)
            if (PN__FEM_FREE(m, (size_t)tn[j]))
                for (a = 0; a < d; ++a) k->g[k->nv + (size_t)tn[j] * (size_t)d + (size_t)a] += dt * gl[d + j * d + a];
        if (level < 2) continue;
        k->con[i] = 1;
        if (ex) { /* the mesh's matrix takes the projection */
            memcpy(Hp, H, sizeof(pn_real) * (size_t)(n * n));
            pn_sym_project_psd(n, Hp);
        }
        for (a = d; ex && a < n; ++a)
            for (b = d; b < n; ++b) H[n * n + (a - d) * (n - d) + b - d] = H[a * n + b] - Hp[a * n + b];
        for (e = 0; e < d; ++e) /* the mesh-mesh block, lower half once (pn__fem_hadd orders it) */
            for (a = 0; a < d; ++a)
                for (f = 0; f <= e; ++f)
                    for (b = 0; b < d; ++b) {
                        int r = d + e * d + a, q = d + f * d + b;
                        if (f == e && b > a) continue;
                        if (!PN__FEM_FREE(m, (size_t)tn[e]) || !PN__FEM_FREE(m, (size_t)tn[f])) continue;
                        pn__fem_hadd(s, pn__fem_row(m, (size_t)tn[e] * (size_t)d + (size_t)a),
                                     pn__fem_row(m, (size_t)tn[f] * (size_t)d + (size_t)b), dt * dt * P[r * n + q]);
                    }
    }
    return 1;
}

/* the closest point on target t (nodes X, d of them) to y: its weights beta and the unit
   normal from it to y; returns the distance */
static pn_real pn__cpl_closest(int d, const pn_real *y, const pn_real *X, pn_real *beta, pn_real *nrm) {
    pn_real best = PN__FEM_FAR, cpt[3] = {0, 0, 0}, dist = 0;
    int e, a, ne = d == 2 ? 1 : 3;
    static const int ed[3][2] = {{0, 1}, {1, 2}, {2, 0}};
    for (a = 0; a < 3; ++a) beta[a] = 0;
    if (d == 3) { /* inside the triangle's projection */
        pn_real e0[3], e1[3], wv[3], A00 = 0, A01 = 0, A11 = 0, b0 = 0, b1 = 0, det, u, v;
        for (a = 0; a < 3; ++a) {
            e0[a] = X[3 + a] - X[a], e1[a] = X[6 + a] - X[a], wv[a] = y[a] - X[a];
            A00 += e0[a] * e0[a], A01 += e0[a] * e1[a], A11 += e1[a] * e1[a], b0 += wv[a] * e0[a], b1 += wv[a] * e1[a];
        }
        det = A00 * A11 - A01 * A01;
        if (det > 0) {
            u = (A11 * b0 - A01 * b1) / det, v = (A00 * b1 - A01 * b0) / det;
            if (u >= 0 && v >= 0 && u + v <= 1) {
                beta[0] = 1 - u - v, beta[1] = u, beta[2] = v, ne = 0;
                for (a = 0; a < 3; ++a) cpt[a] = X[a] + u * e0[a] + v * e1[a];
            }
        }
    }
    for (e = 0; e < ne; ++e) { /* the edges */
        const pn_real *p0 = X + ed[e][0] * d, *p1 = X + ed[e][1] * d;
        pn_real l2 = 0, t = 0, q = 0, cp[3];
        for (a = 0; a < d; ++a) l2 += (p1[a] - p0[a]) * (p1[a] - p0[a]), t += (y[a] - p0[a]) * (p1[a] - p0[a]);
        t = l2 > 0 ? PN__MAX((pn_real)0, PN__MIN((pn_real)1, t / l2)) : 0;
        for (a = 0; a < d; ++a) cp[a] = p0[a] + t * (p1[a] - p0[a]), q += (y[a] - cp[a]) * (y[a] - cp[a]);
        if (q < best) {
            best = q;
            beta[0] = beta[1] = beta[2] = 0;
            beta[ed[e][0]] = 1 - t, beta[ed[e][1]] = t;
            memcpy(cpt, cp, sizeof cp);
        }
    }
    for (a = 0; a < d; ++a) nrm[a] = y[a] - cpt[a], dist += nrm[a] * nrm[a];
    dist = PN__SQRT(dist);
    for (a = 0; a < d; ++a) nrm[a] = dist > 0 ? nrm[a] / dist : 0;
    return dist;
}

/* the largest step fraction in [0, 1] along dir (positions and their motion set, the
   candidates found along it): the interface's additive CCD, the mesh's obstacles and its
   own boundary */
static pn_real pn__cpl_ccd(pn_coupled *c) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_fem_mesh *m = c->fem;
    int d = m->dim, kind = d == 2 ? PN__FEM_PE : PN__FEM_PT;
    size_t i;
    pn_real a0 = pn__fem_self_ccd(m, k->xf, k->xd, pn__fem_ccd(m, k->xf, k->xd));
    for (i = 0; i < k->nc; ++i) {
        pn_real yy[12], dy[12];
        pn__cpl_pair_y(c, i, yy, dy);
        a0 = PN__MIN(a0, pn__pair_ccd(kind, d, d + 1, 1, yy, dy, 0, a0));
    }
    return a0;
}

/* the positions as they are (explicit steps, checks): particles at x, the mesh at x */
static void pn__cpl_here(pn_coupled *c) {
    pn__cpl *k = (pn__cpl *)c->impl;
    size_t nd = c->fem->n_nodes * (size_t)c->fem->dim, np = c->mpm->n * (size_t)c->mpm->dim;
    memcpy(k->y, c->mpm->x, sizeof(pn_real) * np);
    memset(k->yd, 0, sizeof(pn_real) * np);
    memcpy(k->xf, c->fem->x, sizeof(pn_real) * nd);
    memset(k->xd, 0, sizeof(pn_real) * nd);
}

/* the smallest distance over the candidates at the current positions, and how many are
   within dhat */
static pn_real pn__cpl_closest_pair(pn_coupled *c, size_t *near) {
    pn__cpl *k = (pn__cpl *)c->impl;
    int d = c->mpm->dim;
    size_t i;
    pn_real best = PN__FEM_FAR;
    if (near) *near = 0;
    for (i = 0; i < k->nc; ++i) {
        pn_real yy[12], dist;
        pn__cpl_pair_y(c, i, yy, NULL);
        dist = PN__SQRT(pn__fem_pair_d2(d == 2 ? PN__FEM_PE : PN__FEM_PT, d, yy, NULL, NULL));
        if (dist < best) best = dist, c->error_particle = (long)k->cp[i];
        if (near && dist < c->dhat) (*near)++;
    }
    return best;
}

PN__DEF pn_result pn_coupled_min_distance(pn_coupled *c, pn_real *dist_m) {
    pn_result r;
    if (!c || !dist_m) return PN_ERROR_INVALID_ARGUMENT;
    pn__cpl_here(c);
    if ((r = pn__cpl_find(c, 0)) != PN_OK) return r;
    *dist_m = pn__cpl_closest_pair(c, NULL);
    return PN_OK;
}

/* ======================================================================================
   >>couple-friction: Coulomb friction at the interface, lagged and smoothed as IPC's.
   ====================================================================================== */

/* Friction lagged at the current positions: for each candidate within dhat, the target
   nodes, the closest point's weights, the normal and mu lambda (lambda = kappa_p |b'(d)|) */
static pn_result pn__cpl_friction_lag(pn_coupled *c) {
    pn__cpl *k = (pn__cpl *)c->impl;
    int d = c->mpm->dim, j;
    size_t i;
    k->nf = 0;
    if (!(c->friction > 0)) return PN_OK;
    for (i = 0; i < k->nc; ++i) {
        pn_real yy[12], beta[3], nrm[3], dist, bb, b1, b2, *fd;
        const int *tn = pn__cpl_target(c->fem, k->ck[i]);
        pn__cpl_pair_y(c, i, yy, NULL);
        dist = pn__cpl_closest(d, yy, yy + d, beta, nrm);
        if (!(dist > 0) || dist >= c->dhat) continue;
        if (k->nf == k->fcap) {
            pn_result r = pn__cpl_grow_friction(c, 2 * k->fcap + 64);
            if (r != PN_OK) return r;
        }
        pn__fem_barrier(dist, c->dhat, &bb, &b1, &b2);
        fd = k->fdat + PN__CPL_FD * k->nf;
        memset(fd, 0, sizeof(pn_real) * PN__CPL_FD);
        for (j = 0; j < 3; ++j) k->fnode[3 * k->nf + (size_t)j] = j < d ? tn[j] : -1, fd[j] = beta[j], fd[3 + j] = nrm[j];
        fd[6] = c->friction * pn__cpl_kappa(c, k->cp[i]) * -b1;
        k->fp[k->nf++] = k->cp[i];
    }
    return PN_OK;
}

/* the relative tangential motion of friction pair i at z: r = T dt (sum w v - sum beta u) */
static void pn__cpl_fric_r(const pn_coupled *c, size_t i, const pn_real *z, pn_real *r) {
    const pn__cpl *k = (const pn__cpl *)c->impl;
    const pn_mpm_world *w = c->mpm;
    const pn_real *fd = k->fdat + PN__CPL_FD * i;
    int d = w->dim, a, j, ns;
    long node[27];
    pn_real wt[27], u[3] = {0, 0, 0}, un = 0;
    ns = pn__cpl_stencil(w, k->fp[i], node, wt);
    for (a = 0; a < d; ++a) {
        for (j = 0; j < ns; ++j) u[a] += wt[j] * z[(size_t)node[j] * (size_t)d + (size_t)a];
        for (j = 0; j < d; ++j)
            if (PN__FEM_FREE(c->fem, (size_t)k->fnode[3 * i + (size_t)j]))
                u[a] -= fd[j] * z[k->nv + (size_t)k->fnode[3 * i + (size_t)j] * (size_t)d + (size_t)a];
        u[a] *= k->dt;
        un += u[a] * fd[3 + a];
    }
    for (a = 0; a < d; ++a) r[a] = u[a] - un * fd[3 + a];
}

/* scatter a force-like vector q (in r's space) of friction pair i into out: dt w to the
   grid nodes, -dt beta to the mesh nodes */
static void pn__cpl_fric_scatter(const pn_coupled *c, size_t i, const pn_real *q, pn_real *out) {
    const pn__cpl *k = (const pn__cpl *)c->impl;
    const pn_mpm_world *w = c->mpm;
    const pn_real *fd = k->fdat + PN__CPL_FD * i;
    int d = w->dim, a, j, ns;
    long node[27];
    pn_real wt[27];
    ns = pn__cpl_stencil(w, k->fp[i], node, wt);
    for (a = 0; a < d; ++a) {
        for (j = 0; j < ns; ++j) out[(size_t)node[j] * (size_t)d + (size_t)a] += k->dt * wt[j] * q[a];
        for (j = 0; j < d; ++j)
            if (PN__FEM_FREE(c->fem, (size_t)k->fnode[3 * i + (size_t)j]))
                out[k->nv + (size_t)k->fnode[3 * i + (size_t)j] * (size_t)d + (size_t)a] -= k->dt * fd[j] * q[a];
    }
}

/* IPC's smoothed friction over the lagged pairs: E += mu lambda f0(|r|), gradient, and each
   pair's PSD Hessian in r (fdat + 9) */
static void pn__cpl_friction(pn_coupled *c, const pn_real *z, int level, pn_real *E) {
    pn__cpl *k = (pn__cpl *)c->impl;
    int d = c->mpm->dim, a, b;
    size_t i;
    pn_real eps = c->eps_v * k->dt;
    for (i = 0; i < k->nf; ++i) {
        pn_real r[3], y = 0, f0, f1, f1p, q[3], *fd = k->fdat + PN__CPL_FD * i, coef = fd[6];
        pn__cpl_fric_r(c, i, z, r);
        for (a = 0; a < d; ++a) y += r[a] * r[a];
        y = PN__SQRT(y);
        if (y < eps) { /* f0(y) = -y^3 / (3 eps^2) + y^2 / eps + eps / 3, C1 at eps (IPC) */
            f0 = -y * y * y / (3 * eps * eps) + y * y / eps + eps / 3;
            f1 = -y * y / (eps * eps) + 2 * y / eps;
            f1p = -2 * y / (eps * eps) + 2 / eps;
        } else f0 = y, f1 = 1, f1p = 0;
        *E += coef * f0;
        if (level >= 1 && y > 0) {
            for (a = 0; a < d; ++a) q[a] = coef * f1 * r[a] / y;
            pn__cpl_fric_scatter(c, i, q, k->g);
        }
        if (level >= 2) /* f1' rr^T / y^2 + (f1 / y)(T - rr^T / y^2) on the tangent plane: PSD */
            for (a = 0; a < d; ++a)
                for (b = 0; b < d; ++b) {
                    pn_real T = (a == b) - fd[3 + a] * fd[3 + b], uu = y > 0 ? r[a] * r[b] / (y * y) : 0;
                    fd[9 + a * d + b] = coef * (y > 0 ? f1p * uu + f1 / y * (T - uu) : 2 / eps * T);
                }
    }
}

/* ======================================================================================
   >>couple-implicit: one Newton over grid velocities and mesh positions
   (pn_coupled_step_implicit): the joint objective, its Hessian product and preconditioner,
   the passes of the F0 fixed point and contact rounds, the substep fallback.
   ====================================================================================== */

/* E(z) and by level its gradient (k->g) and Hessian data; positions at z must be set
   (pn__cpl_positions). A failure of either side's energy or a touching pair: *E = +inf
   (level 0, for the line search) or its error. */
static pn_result pn__cpl_objective(pn_coupled *c, const pn_real *z, int level, pn_real *E_out) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn__fem *s = (pn__fem *)m->impl;
    pn_real E1 = 0, E2 = 0, E = 0;
    pn_result r;
    size_t i;
    r = pn__mpm_objective(w, z, k->dt, level, &E1);
    if (r == PN_OK) r = pn__fem_objective(m, k->xf, level, &E2);
    if (r == PN_OK && !pn__finite(E1)) r = PN_ERROR_INVERTED;
    if (r != PN_OK) {
        if (level) return r;
        *E_out = (pn_real)HUGE_VAL;
        return PN_OK;
    }
    if (level >= 1) {
        memcpy(k->g, w->s.grad, sizeof(pn_real) * k->nv);
        for (i = 0; i < k->nu; ++i) k->g[k->nv + i] = s->g[i] / k->dt;
    }
    E = E1 + E2 / (k->dt * k->dt);
    if (!pn__cpl_barrier(c, level, &E)) {
        if (level) return PN_ERROR_STEP_TOO_LARGE;
        *E_out = (pn_real)HUGE_VAL;
        return PN_OK;
    }
    pn__cpl_friction(c, z, level, &E);
    if (k->lin != 0) /* theta < 1: the start's forces, (1 - theta) / theta g0 . z */
        for (i = 0; i < k->nz; ++i) {
            E += k->lin * k->g0[i] * z[i];
            if (level >= 1) k->g[i] += k->lin * k->g0[i];
        }
    if (level >= 1) /* the grid's reactions (wall contact, friction) see the interface too */
        memcpy(w->s.grad, k->g, sizeof(pn_real) * k->nv);
    *E_out = E;
    return pn__finite(E) ? PN_OK : PN_ERROR_OVERFLOW;
}

static pn_result pn__cpl_value(void *ctx, const pn_real *z, pn_real *E) {
    pn_coupled *c = (pn_coupled *)ctx;
    pn__cpl_positions(c, 1, z, NULL);
    return pn__cpl_objective(c, z, 0, E);
}

/* y = H x over the coupled unknowns: the grid's filtered Hessian, the mesh's matrix (with
   the barrier's mesh-mesh blocks), the barrier's other blocks and friction through the
   chain rule, the grid part filtered again (the filter is a projection) */
static void pn__cpl_apply(void *ctx, const pn_real *x, pn_real *y) {
    pn_coupled *c = (pn_coupled *)ctx;
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    int d = w->dim, n = d * (d + 1), a, b, j, ns;
    size_t i, h = PN__CPL_H(d);
    pn__mpm_hess_vec(w, x, k->dt, y);
    for (i = 0; i < k->nu; ++i) k->pa[pn__fem_row(m, i)] = x[k->nv + i];
    pn__fem_cg_apply(m, k->pa, k->pb);
    for (i = 0; i < k->nu; ++i) y[k->nv + i] = k->pb[pn__fem_row(m, i)];
    for (i = 0; i < k->nc; ++i) {
        const pn_real *H = k->ch + i * h;
        const int *tn;
        long node[27];
        pn_real wt[27], l[12], o[12];
        if (!k->con[i]) continue;
        tn = pn__cpl_target(m, k->ck[i]);
        ns = pn__cpl_stencil(w, k->cp[i], node, wt);
        for (a = 0; a < d; ++a) {
            l[a] = 0;
            for (j = 0; j < ns; ++j) l[a] += k->dt * wt[j] * x[(size_t)node[j] * (size_t)d + (size_t)a];
        }
        for (j = 0; j < d; ++j)
            for (a = 0; a < d; ++a)
                l[d + j * d + a] = PN__FEM_FREE(m, (size_t)tn[j]) ? k->dt * x[k->nv + (size_t)tn[j] * (size_t)d + (size_t)a] : 0;
        for (a = 0; a < n; ++a) { /* all but the mesh-mesh block, which the mesh's matrix holds */
            o[a] = 0;
            for (b = 0; b < n; ++b)
                if (a < d || b < d) o[a] += H[a * n + b] * l[b];
                else if (k->exact) o[a] += H[n * n + (a - d) * (n - d) + b - d] * l[b]; /* less its projection */
        }
        for (j = 0; j < ns; ++j)
            for (a = 0; a < d; ++a) y[(size_t)node[j] * (size_t)d + (size_t)a] += k->dt * wt[j] * o[a];
        for (j = 0; j < d; ++j)
            if (PN__FEM_FREE(m, (size_t)tn[j]))
                for (a = 0; a < d; ++a) y[k->nv + (size_t)tn[j] * (size_t)d + (size_t)a] += k->dt * o[d + j * d + a];
    }
    for (i = 0; i < k->nf; ++i) {
        const pn_real *Hr = k->fdat + PN__CPL_FD * i + 9;
        pn_real r[3], q[3] = {0, 0, 0};
        pn__cpl_fric_r(c, i, x, r);
        for (a = 0; a < d; ++a)
            for (b = 0; b < d; ++b) q[a] += Hr[a * d + b] * r[b];
        pn__cpl_fric_scatter(c, i, q, y);
    }
    for (i = 0; i < w->s.n_act; ++i) pn__mpm_filter(w, i, y + i * (size_t)d);
}

/* z = B r: the grid's preconditioner on its block, the mesh's factor on its own */
static void pn__cpl_precond(void *ctx, const pn_real *r, pn_real *z) {
    pn_coupled *c = (pn_coupled *)ctx;
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_fem_mesh *m = c->fem;
    size_t i;
    pn__mpm_precondition(c->mpm, r, z);
    for (i = 0; i < k->nu; ++i) k->pa[pn__fem_row(m, i)] = r[k->nv + i];
    pn__fem_cg_precond(m, k->pa, k->pb);
    for (i = 0; i < k->nu; ++i) z[k->nv + i] = k->pb[pn__fem_row(m, i)];
}

static pn_real pn__cpl_dot(void *ctx, size_t n, const pn_real *a, const pn_real *b) {
    pn_coupled *c = (pn_coupled *)ctx;
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_real acc = pn__mpm_sum(c->mpm, k->nv, a, b), t = 0;
    size_t i;
    for (i = k->nv; i < n; ++i) t += a[i] * b[i];
    return acc + t;
}

/* Newton on E(v, u) from k->z (feasible). Every Hessian (the particles', the elements', the
   barrier's pairs': pn__cpl_barrier) is PSD-projected until Newton's steps are shorter than
   PN__MPM_FULL_H cells, then taken as it is, as the grid's and the mesh's own Newton do:
   projection clamps the negative curvature of compressed material and of contact forces that
   turn with the faces, a model wrong near the minimum where Newton then converges linearly
   (a block resting on the sand: twice the curvature along Newton's direction, rate 1/2, 28
   iterations in a 1e-2 s step of the 3D bench scene). Where the whole is not positive
   definite (the mesh's factor fails, CG meets negative curvature, the direction does not
   descend, or its line search finds no decrease), the iteration is solved again projected,
   and projected it stays until the steps are 10 times shorter. */
static pn_result pn__cpl_newton(pn_coupled *c, const pn_mpm_implicit_desc *o, pn_coupled_stats *st, pn_real *res_out,
                                int *capped_out) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn__fem *s = (pn__fem *)m->impl;
    pn_real dt = k->dt, vscale = o->newton_tol * w->desc.dx_m / dt, res = 0, rprev = 0, left = 0;
    size_t i, nz = k->nz;
    pn_real full_h = PN__MPM_FULL_H * w->desc.dx_m / dt, full_below = full_h; /* steps (max |dz|): Hessians whole */
    pn_real eta = 0, gprev = 0, pred = 0, gnorm; /* forcing (pn__mpm_forcing): last eta, |S g|, predicted |S g| */
    int it, capped = 0, cg, cg_fresh = 0, fresh, stale = w->s.mg_stale && w->steps % 16 != 0, stall, redo = 0, curv;
    int full = 0, again = 0;
    pn_result r;
    pn__cg_ops op;
    op.ctx = c, op.apply = pn__cpl_apply, op.precond = pn__cpl_precond, op.dot = pn__cpl_dot, op.curv = &curv;
    pn__cpl_positions(c, 1, k->z, NULL);
    if ((r = pn__cpl_find(c, 0)) != PN_OK) return r;
    for (it = 0; it < o->newton_max; ++it) {
        pn_real E0, E1, gd, a0, alpha;
        if (again) /* the whole Hessian failed here: projected until the steps are 10x shorter */
            full = 0, full_below = res / 10, redo = 1, again = 0;
        else
            full = it > 0 && res <= full_below;
        k->dmin = PN__FEM_FAR;
        pn__cpl_positions(c, 1, k->z, NULL);
        k->exact = full, w->s.full_h = full, s->hflags = full ? 0 : PN_EVAL_PROJECT_PSD;
        r = pn__cpl_objective(c, k->z, 2, &E0);
        w->s.full_h = 0, s->hflags = PN_EVAL_PROJECT_PSD; /* what every other evaluation uses */
        if (r != PN_OK)
            return PN__FAIL(c, r, "coupled implicit step of %g s: the energy at an accepted iterate failed (%s; "
                                "particle %ld, element %ld)", (double)dt, pn_result_string(r),
                                w->error_particle, m->error_element);
        st->min_distance_m = PN__MIN(st->min_distance_m, k->dmin);
        fresh = it == 0 || o->mg_rebuild || stale || redo; /* the grid's hierarchy lagged as its own step does */
        redo = 0;
        if (w->s.mg_on && (r = pn__mpm_mg_build(w, dt, fresh, o->mg_levels)) != PN_OK)
            return PN__FAIL(c, r, "coupled implicit step: out of memory for the grid's multigrid hierarchy");
        if (!w->s.mg_on) pn__mpm_diagonal(w, dt);
        if (s->sparse) {
            if (!pn__fem_bfactor(s)) {
                if (full) { /* this iteration again, projected */
                    again = 1, --it;
                    continue;
                }
                return PN__FAIL(c, PN_ERROR_NOT_CONVERGED, "coupled implicit step: the mesh's matrix has no "
                                    "incomplete factor");
            }
            s->coarse = !s->one_level && pn__fem_coarse_build(m, k->xf);
            if (s->coarse) s->omega = pn__fem_smoother_damping(m);
        } else {
            memcpy(s->A, s->L, sizeof(pn_real) * s->rs[s->nu]); /* kept for CG's products */
            if (!pn__sky_cholesky(s->fc, s->rs, s->L, s->nu)) {
                if (full) {
                    again = 1, --it;
                    continue;
                }
                return PN__FAIL(c, PN_ERROR_NOT_CONVERGED, "coupled implicit step: the mesh's Hessian is not "
                                    "positive definite");
            }
        }
        for (i = 0; i < nz; ++i) k->r[i] = -k->g[i];
        for (i = 0; i < w->s.n_act; ++i) pn__mpm_filter(w, i, k->r + i * (size_t)w->dim);
        memcpy(k->gf, k->r, sizeof(pn_real) * nz); /* -S g, for the model's prediction */
        gnorm = PN__SQRT(pn__cpl_dot(c, nz, k->r, k->r));
        eta = pn__mpm_forcing(o, it, eta, gprev, pred, gnorm);
        gprev = gnorm;
        curv = 0;
        cg = pn__pcg(&op, nz, k->dir, k->r, k->zz, k->pp, k->qq, o->cg_max, eta, 0, &capped);
        st->cg_iters += cg;
        for (gd = 0, i = 0; i < nz; ++i) gd += k->g[i] * k->dir[i];
        if (full && (curv || !(gd < 0))) {
            again = 1, --it;
            continue;
        }
        if (pn__mpm_lin_escape(w, capped)) { /* Jacobi gave up: this iteration again by multigrid */
            redo = 1;
            --it;
            continue;
        }
        if (fresh) cg_fresh = cg;
        else w->s.mg_stale = stale = 2 * cg > 3 * cg_fresh + 4;
        st->newton_iters++;
        for (res = 0, i = 0; i < nz; ++i) res = PN__MAX(res, PN__FABS(k->dir[i]));
        if (res <= vscale && eta > o->cg_rel_tol && !curv) { /* a loose solve may stop Newton early */
            memcpy(k->r, k->gf, sizeof(pn_real) * nz); /* the right side again: the solve resumes from dir */
            st->cg_iters += pn__pcg(&op, nz, k->dir, k->r, k->zz, k->pp, k->qq, o->cg_max, o->cg_rel_tol, 1, &capped);
            for (res = 0, i = 0; i < nz; ++i) res = PN__MAX(res, PN__FABS(k->dir[i]));
        }
        if (o->trace) o->trace(o->trace_user, st->solves, it, E0, res / (w->desc.dx_m / dt));
        if (!pn__finite(res))
            return PN__FAIL(c, PN_ERROR_OVERFLOW, "coupled implicit step of %g s: the Newton direction is not finite",
                                (double)dt);
        if (res <= vscale && !capped) break;
        if (res <= 100 * vscale && pn__unresolved(gd, E0, PN__EPS) && !capped) break; /* as the grid's own */
        pn__cpl_positions(c, 1, k->z, k->dir);
        if ((r = pn__cpl_find(c, 1)) != PN_OK) return r;
        a0 = pn__cpl_ccd(c);
        alpha = a0 > 0 ? pn__armijo(pn__cpl_value, c, nz, k->z, k->dir, E0, gd, a0, (pn_real)1e-10, k->zt, &E1) : 0;
        if ((stall = pn__mpm_lanes_stall(w, gd, E0, alpha, res <= 100 * vscale)) == 1) break;
        if (stall == 2 && alpha == 0) continue;
        if (alpha == 0 && full) { /* the whole Hessian's step found no decrease */
            again = 1;
            continue;
        }
        if (alpha == 0) {
            st->line_search_failures++;
            break;
        }
        for (pred = 0, i = 0; i < nz; ++i) { /* |S g| the linear model predicts after the step */
            pn_real e = -(1 - alpha) * k->gf[i] - alpha * k->r[i];
            pred += e * e;
        }
        pred = PN__SQRT(pred);
        memcpy(k->z, k->zt, sizeof(pn_real) * nz);
        st->min_distance_m = PN__MIN(st->min_distance_m, k->dmin);
        if (res > full_h) full_below = full_h; /* moved on */
        if (alpha == 1 && !capped && pn__newton_done(res, rprev, vscale, &left)) { /* as the grid's own */
            res = left;
            pn__cpl_positions(c, 1, k->z, NULL); /* the gradient at the solution (contact, friction) */
            if ((r = pn__cpl_objective(c, k->z, 1, &E1)) != PN_OK) return r;
            break;
        }
        rprev = alpha == 1 ? res : 0;
    }
    *res_out = res / (w->desc.dx_m / dt);
    *capped_out = capped;
    return PN_OK;
}

/* The fixed-point passes and contact rounds of a coupled step, each a Newton solve from
   k->z; *last_res and *capped as Newton left them. */
static pn_result pn__cpl_passes(pn_coupled *c, const pn_mpm_implicit_desc *o, int has_sep, pn_coupled_stats *st,
                                pn_real *last_res, int *capped) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn_real dt = k->dt, vscale = o->newton_tol * w->desc.dx_m / dt;
    int pass;
    pn_result r;
    for (pass = 0; pass < o->fixed_point_iters; ++pass) {
        pn_real fp = 0;
        int round;
        pn__cpl_positions(c, 1, k->z, NULL);
        r = pn__mpm_prepare_pass(w, k->z, NULL, dt, pass == 0, &fp);
        if (r == PN_OK) r = pn__fem_prepare(m, k->xf);
        if (r != PN_OK) return PN__FAIL(c, r, "coupled implicit step: preparing the energies at F0 failed (%s)",
                                            w->error[0] ? w->error : m->error);
        st->fixed_point_iters++;
        /* interface friction lagged at the step's start, then at each pass's solution */
        if (pass == 0) {
            memset(k->zt, 0, sizeof(pn_real) * k->nz);
            pn__cpl_positions(c, 1, k->zt, NULL);
        }
        if ((r = pn__cpl_find(c, 0)) != PN_OK || (r = pn__cpl_friction_lag(c)) != PN_OK) return r;
        for (round = 0; round < o->contact_rounds; ++round) {
            memcpy(w->s.vsol, k->z, sizeof(pn_real) * k->nv);
            if (has_sep && pass + round > 0) pn__mpm_friction_update(w, w->s.vsol);
            memcpy(k->z, w->s.vsol, sizeof(pn_real) * k->nv);
            st->solves++;
            if ((r = pn__cpl_newton(c, o, st, last_res, capped)) != PN_OK) return r;
            memcpy(w->s.vsol, k->z, sizeof(pn_real) * k->nv);
            if (!has_sep || !pn__mpm_active_set(w, w->s.vsol, vscale)) break;
            memcpy(k->z, w->s.vsol, sizeof(pn_real) * k->nv);
        }
    }
    pn__mpm_lin_record(w, st->cg_iters, st->newton_iters);
    return PN_OK;
}

/* theta < 1: both sides' masses times s (the theta method's objective, divided by theta^2,
   weighs the inertia by 1 / theta^2 against the potentials) */
static void pn__cpl_mass_scale(pn_coupled *c, pn_real s) {
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    size_t q;
    for (q = 0; q < w->s.n_act; ++q) w->s.grid_m[q] *= s;
    for (q = 0; q < m->n_nodes; ++q) m->mass[q] *= s;
}

/* theta < 1: the potentials' gradient at the step's start (z = 0: the particles at x^n, the
   mesh at x^n), the energies prepared there, into k->g0: the start's forces times -dt. The
   walls' sliding friction is left out (it is a force of the solve's own). */
static pn_result pn__cpl_start_forces(pn_coupled *c) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn_real fp = 0, E = 0;
    size_t q;
    int d = w->dim, i;
    pn_result r;
    memset(k->zt, 0, sizeof(pn_real) * k->nz);
    pn__cpl_positions(c, 1, k->zt, NULL);
    r = pn__mpm_prepare_pass(w, k->zt, NULL, k->dt, 1, &fp);
    if (r == PN_OK) r = pn__fem_prepare(m, k->xf);
    if (r == PN_OK) r = pn__cpl_find(c, 0);
    if (r != PN_OK) return r;
    k->nf = 0, k->lin = 0;
    pn__cpl_mass_scale(c, 0);
    r = pn__cpl_objective(c, k->zt, 1, &E);
    if (r != PN_OK) return r;
    memcpy(k->g0, k->g, sizeof(pn_real) * k->nz);
    for (q = 0; q < w->s.n_act; ++q)
        if (w->s.clam[q] > 0 && !(w->s.chold[q] & PN__MPM_STICK))
            for (i = 0; i < d; ++i) k->g0[q * (size_t)d + (size_t)i] -= w->s.cmu[q] * w->s.clam[q] * w->s.ctan[q * 3 + (size_t)i];
    return PN_OK;
}

/* One coupled implicit step without fallback: both sides unchanged unless PN_OK (the
   caller keeps and restores the mesh). Backward Euler, or the theta method: with u the
   mean velocity over the step (x^{n+1} = x^n + dt u, F^{n+1} = (I + dt grad u) F^n) and
   v^{n+1} = (u - (1 - theta) v^n) / theta, momentum M (v^{n+1} - v^n) = dt ((1 - theta) f^n
   + theta f^{n+1}) makes u the minimiser of |u - u~|^2_M / (2 theta^2) + Phi(u) + (1 - theta)
   / theta grad Phi(0) . u, u~ = v^n + theta dt g, Phi every potential (the two sides'
   elasticity, the barrier, friction). */
static pn_result pn__cpl_once(pn_coupled *c, pn_real dt, const pn_coupled_implicit_desc *od, pn_coupled_stats *st) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn__fem *s = (pn__fem *)m->impl;
    const pn_mpm_implicit_desc *o = &od->mpm;
    pn_real th = od->theta;
    int d = w->dim, i, has_sep, capped = 0;
    size_t n = m->n_nodes, nd = n * (size_t)d, q, plastic = 0;
    pn_real last_res = 0, a, E, *gm0 = k->m0, *mm0 = k->m0 + k->zcap - n;
    pn_mpm_stats mst;
    pn_result r;
    pn__mpm_stats_clear(&mst, 0);
    k->dt = dt, k->theta = th, k->lin = 0;
    /* the grid side as pn_mpm_step_implicit starts; the mesh's as pn_fem_step_implicit */
    has_sep = pn__mpm_implicit_begin(w, dt, o, &mst);
    k->nv = w->s.n_act * (size_t)d, k->nu = nd, k->nz = k->nv + nd;
    s->dt = dt, s->t_end = m->time_s + dt, s->n_mov = 0, s->nu = nd, s->hflags = PN_EVAL_PROJECT_PSD;
    pn__fem_setup(m);
    if (th < 1) { /* v^n, and the target u~ = v^n + theta dt g */
        for (q = 0; q < k->nv; ++q) {
            pn_real gq = w->desc.gravity[q % (size_t)d];
            k->vn[q] = w->s.grid_m[q / (size_t)d] > 0 ? w->s.vstar[q] - dt * gq : 0;
            w->s.vstar[q] -= (1 - th) * dt * gq;
        }
        memcpy(k->vn + k->nv, m->v, sizeof(pn_real) * nd);
    }
    for (q = 0; q < n; ++q) {
        pn_real xn[3];
        if (m->fixed[q]) pn__fem_driven(m, q, dt, xn);
        for (i = 0; i < d; ++i) {
            size_t e = q * (size_t)d + (size_t)i;
            s->xt[e] = m->fixed[q] ? xn[i] : m->x[e] + dt * m->v[e] + th * dt * dt * m->desc.gravity[i];
            k->zt[k->nv + e] = m->fixed[q] ? (xn[i] - m->x[e]) / dt : 0; /* the base: held where it is */
            k->dir[k->nv + e] = (s->xt[e] - m->x[e]) / dt - k->zt[k->nv + e];
        }
    }
    memcpy(s->xlag, m->x, sizeof(pn_real) * nd); /* the mesh's friction with its obstacles: at x^n */
    if (th < 1) {
        /* the start's forces; the masses kept and scaled */
        memcpy(gm0, w->s.grid_m, sizeof(pn_real) * w->s.n_act);
        memcpy(mm0, m->mass, sizeof(pn_real) * n);
        r = pn__cpl_start_forces(c);
        for (q = 0; q < w->s.n_act; ++q) w->s.grid_m[q] = gm0[q] / (th * th);
        for (q = 0; q < n; ++q) m->mass[q] = mm0[q] / (th * th);
        if (r != PN_OK) {
            memcpy(m->mass, mm0, sizeof(pn_real) * n);
            return PN__FAIL(c, r, "coupled implicit step: the forces at the step's start failed (%s)",
                                w->error[0] ? w->error : m->error);
        }
        k->lin = (1 - th) / th;
        /* the start iterate's direction, as above, with the new targets */
        for (q = 0; q < nd; ++q) k->dir[k->nv + q] = (s->xt[q] - m->x[q]) / dt - k->zt[k->nv + q];
    }
    /* start at [v*, x~] as far as it is free of crossings from the base [held at rest, x^n] */
    memset(k->zt, 0, sizeof(pn_real) * k->nv);
    for (q = 0; q < w->s.n_act; ++q) pn__mpm_hold(w, q, k->zt + q * (size_t)d);
    for (q = 0; q < k->nv; ++q) k->dir[q] = w->s.vsol[q] - k->zt[q];
    pn__cpl_positions(c, 1, k->zt, k->dir);
    r = pn__cpl_find(c, 1);
    if (r == PN_OK) {
        a = pn__cpl_ccd(c);
        for (q = 0; q < k->nz; ++q) k->z[q] = k->zt[q] + a * k->dir[q];
        if (pn__fem_prepare(m, s->xt) != PN_OK || pn__cpl_value(c, k->z, &E) != PN_OK || !pn__finite(E))
            memcpy(k->z, k->zt, sizeof(pn_real) * k->nz);
        r = pn__cpl_passes(c, o, has_sep, st, &last_res, &capped);
    }
    if (th < 1) { /* the masses back (the mesh's are its state) */
        memcpy(m->mass, mm0, sizeof(pn_real) * n);
        memcpy(w->s.grid_m, gm0, sizeof(pn_real) * w->s.n_act);
    }
    if (r != PN_OK) return r;
    st->newton_residual = PN__MAX(st->newton_residual, last_res);
    if (capped)
        return PN__FAIL(c, PN_ERROR_NOT_CONVERGED, "coupled implicit step of %g s: the last linear solve stopped at "
                            "cg_max = %d short of cg_rel_tol %g: raise cg_max or take a smaller step", (double)dt, o->cg_max,
                            (double)o->cg_rel_tol);
    if (!(last_res <= 100 * o->newton_tol))
        return PN__FAIL(c, PN_ERROR_NOT_CONVERGED, "coupled implicit step of %g s: Newton stopped at max |dz| dt / dx = "
                            "%.3g (newton_tol %g): a smaller step converges", (double)dt, (double)last_res,
                            (double)o->newton_tol);
    if (th < 1) /* the grid's end velocities; held components keep their held values */
        for (q = 0; q < w->s.n_act; ++q) {
            for (i = 0; i < d; ++i) {
                size_t e = q * (size_t)d + (size_t)i;
                k->zt[e] = (k->z[e] - (1 - th) * k->vn[e]) / th;
            }
            pn__mpm_hold(w, q, k->zt + q * (size_t)d);
        }
    r = pn__mpm_g2p(w, k->z, th < 1 ? k->zt : NULL, dt, &mst);
    if (r != PN_OK) return PN__FAIL(c, r, "coupled implicit step: %s", w->error);
    pn__cpl_positions(c, 1, k->z, NULL);
    for (q = 0; q < nd; ++q) {
        pn_real u = (k->xf[q] - m->x[q]) / dt;
        m->v[q] = th < 1 && !m->fixed[q / (size_t)d] ? (u - (1 - th) * k->vn[k->nv + q]) / th : u;
        m->x[q] = k->xf[q];
    }
    if ((r = pn__fem_return(m, &plastic)) != PN_OK) return PN__FAIL(c, r, "coupled implicit step: %s", m->error);
    m->time_s += dt;
    pn__mpm_friction_record(w, dt);
    pn__mpm_commit(w, dt, &mst);
    st->plastic_particles += mst.plastic;
    st->plastic_elements += plastic;
    return PN_OK;
}

/* pn_coupled_step_implicit's tries for the kit's substep fallback (pn__halve) */
typedef struct pn__cpl_retry {
    pn_coupled *c;
    const pn_coupled_implicit_desc *od;
    pn_real dt, t0;
    pn_coupled_stats *st, first; /* the current try's stats; the first try's               */
    long steps0, fsteps0;
    size_t left0;
    int stale0, rec0, lin0, ctau0;
    int stopped;                 /* a step that worked failed a check halving cannot pass   */
    char why[sizeof ((pn_coupled *)0)->error];
} pn__cpl_retry;

static pn_result pn__cpl_try(void *ctx, int n_sub) {
    pn__cpl_retry *t = (pn__cpl_retry *)ctx;
    pn_coupled *c = t->c;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    pn_coupled_stats *st = t->st;
    pn_result r = PN_OK;
    pn_real dmin;
    int sub;
    memset(st, 0, sizeof *st);
    st->min_distance_m = PN__FEM_FAR;
    st->substeps = n_sub;
    for (sub = 0; sub < n_sub && r == PN_OK; ++sub) r = pn__cpl_once(c, t->dt / (pn_real)n_sub, t->od, st);
    if (r != PN_OK) return r;
    w->time_s = t->t0 + t->dt, w->steps = t->steps0 + 1, m->steps = t->fsteps0 + 1;
    pn__cpl_here(c);
    if ((r = pn__cpl_find(c, 0)) != PN_OK) {
        t->stopped = 1;
        return r;
    }
    if ((r = pn__fem_obstacles_clear(m, "pn_coupled_step_implicit")) != PN_OK) {
        t->stopped = 1;
        return PN__FAIL(c, r, "%s", m->error);
    }
    dmin = pn__cpl_closest_pair(c, &st->pairs);
    st->min_distance_m = PN__MIN(st->min_distance_m, dmin);
    return PN_OK;
}

static void pn__cpl_untry(void *ctx, int n_sub) {
    pn__cpl_retry *t = (pn__cpl_retry *)ctx;
    pn_mpm_world *w = t->c->mpm;
    pn_fem_mesh *m = t->c->fem;
    (void)n_sub;
    pn__mpm_backup(w, 1);
    pn__mpm_journal_undo(w);
    pn__fem_restore(m);
    w->time_s = t->t0, w->steps = t->steps0, w->left_total = t->left0, m->steps = t->fsteps0;
    w->s.mg_stale = t->stale0, w->s.rec_ok = t->rec0, w->s.lin_mg = t->lin0;
    w->s.ctau_ok = t->ctau0, w->s.stau_committed = 0, w->s.stau_state = 0;
}

static void pn__cpl_keep_first(void *ctx) {
    pn__cpl_retry *t = (pn__cpl_retry *)ctx;
    pn_coupled *c = t->c;
    t->first = *t->st;
    memcpy(t->why, c->error[0] ? c->error : c->mpm->error[0] ? c->mpm->error : c->fem->error, sizeof t->why);
}

static int pn__cpl_stop(void *ctx, int n_sub) {
    (void)n_sub;
    return ((pn__cpl_retry *)ctx)->stopped;
}

PN__DEF pn_result pn_coupled_step_implicit(pn_coupled *c, pn_real dt, const pn_coupled_implicit_desc *desc,
                                           pn_coupled_stats *stats) {
    pn_coupled_implicit_desc od;
    pn_mpm_implicit_desc *o = &od.mpm;
    pn_coupled_stats st;
    pn_mpm_world *w;
    pn_fem_mesh *m;
    pn_result r;
    int a, load;
    pn__cpl_retry t;
    pn__halving h;
    if (!c) return PN_ERROR_INVALID_ARGUMENT;
    w = c->mpm, m = c->fem;
    c->error[0] = 0, c->error_particle = c->error_node = -1;
    if (!pn__finite(dt) || !(dt > 0))
        return PN__FAIL(c, PN_ERROR_INVALID_ARGUMENT, "pn_coupled_step_implicit: dt_s = %g must be finite and > 0",
                            (double)dt);
    memset(&od, 0, sizeof od);
    if (desc) od = *desc;
    if ((a = pn__mpm_drive_on(w, &load)) >= 0)
        return PN__FAIL(c, PN_ERROR_UNSUPPORTED, "pn_coupled_step_implicit: %s %d is on (drives and loads work with "
                            "explicit steps)", load ? "load" : "drive", a);
    for (a = 0; a < m->n_obstacles; ++a) {
        const pn_real *u = m->obstacles[a].velocity_m_s;
        if (u[0] != 0 || u[1] != 0 || u[2] != 0)
            return PN__FAIL(c, PN_ERROR_UNSUPPORTED, "pn_coupled_step_implicit: the mesh's obstacle %d moves (only "
                                "pn_fem_step_implicit moves obstacles)", a);
    }
    if (o->formulation != PN_MPM_FORMULATION_ENERGY)
        return PN__FAIL(c, PN_ERROR_UNSUPPORTED, "pn_coupled_step_implicit: only the energy formulation couples");
    if (pn__mpm_negative_count(o))
        return PN__FAIL(c, PN_ERROR_INVALID_ARGUMENT, "pn_coupled_implicit_desc: mpm.%s must be >= 0 (0: the "
                            "default)", pn__mpm_negative_count(o));
    if (!pn__finite(o->newton_tol) || o->newton_tol < 0 || !pn__finite(o->cg_rel_tol) || o->cg_rel_tol < 0 ||
        !pn__finite(o->pnet_reuse_tol) ||
        o->linear_solver < PN_MPM_LINEAR_DEFAULT || o->linear_solver > PN_MPM_LINEAR_MULTIGRID || o->mg_levels < 0)
        return PN__FAIL(c, PN_ERROR_INVALID_ARGUMENT, "pn_coupled_implicit_desc: newton_tol %g and cg_rel_tol %g must "
                            "be finite and >= 0, pnet_reuse_tol finite, linear_solver %d a pn_mpm_linear_solver, "
                            "mg_levels %d >= 0",
                            (double)o->newton_tol, (double)o->cg_rel_tol, (int)o->linear_solver, o->mg_levels);
    if (od.theta == 0) od.theta = 1;
    if (!(od.theta >= (pn_real)0.5 && od.theta <= 1))
        return PN__FAIL(c, PN_ERROR_INVALID_ARGUMENT, "pn_coupled_implicit_desc: theta %g is not in [0.5, 1] (0: 1, "
                            "backward Euler)", (double)od.theta);
    pn__mpm_implicit_defaults(o, 1000, (pn_real)1e-3); /* the coupled system's CG defaults */
    if ((r = pn__mpm_check_state(w)) != PN_OK) return PN__FAIL(c, r, "pn_coupled_step_implicit: %s", w->error);
    if ((r = pn__cpl_check_mesh(c, "pn_coupled_step_implicit")) != PN_OK) return r;
    if ((r = pn__mpm_alloc_implicit(w)) != PN_OK || (r = pn__mpm_reuse_on(w, o)) != PN_OK)
        return PN__FAIL(c, r, "pn_coupled_step_implicit: out of memory for the world's solver storage");
    if ((r = pn__fem_linear_setup(m, od.fem_linear_solver)) != PN_OK)
        return PN__FAIL(c, r, "pn_coupled_step_implicit: %s", m->error);
    if ((r = pn__cpl_alloc(c)) != PN_OK) return r;
    memset(&t, 0, sizeof t);
    t.c = c, t.od = &od, t.dt = dt, t.st = &st;
    t.t0 = w->time_s, t.steps0 = w->steps, t.fsteps0 = m->steps, t.left0 = w->left_total;
    t.stale0 = w->s.mg_stale, t.rec0 = w->s.rec_ok, t.lin0 = w->s.lin_mg, t.ctau0 = w->s.ctau_ok;
    pn__mpm_backup(w, 0);
    pn__mpm_journal_begin(w);
    pn__fem_backup(m);
    h.ctx = &t, h.try_step = pn__cpl_try, h.undo = pn__cpl_untry, h.keep_first = pn__cpl_keep_first, h.stop = pn__cpl_stop;
    if ((r = pn__halve(&h, o->max_halvings)) == PN_OK) {
        pn__mpm_tau_keep(w);
        c->error[0] = 0, c->error_particle = -1;
        if (stats) *stats = st;
        return PN_OK;
    }
    memcpy(c->error, t.why, sizeof c->error); /* the first try's message and stats */
    if (stats) *stats = t.first;
    if (o->max_halvings > 0 && !t.stopped) pn__append(c->error, sizeof c->error, " [also as 2^max_halvings substeps]");
    return r;
}

/* ======================================================================================
   >>couple-explicit: both explicit at the coupled step bound, the barrier's forces exchanged
   as loads (pn_coupled_step_explicit, pn_coupled_stable_dt).
   ====================================================================================== */

/* the interface's forces at the positions as they are (explicit): the barrier's, and
   Coulomb friction that at most stops the relative sliding within the step. Particle
   forces into k->fx (dim per particle), the mesh's into k->pa (dim per node). */
static void pn__cpl_forces(pn_coupled *c, pn_real dt) {
    pn__cpl *k = (pn__cpl *)c->impl;
    pn_mpm_world *w = c->mpm;
    pn_fem_mesh *m = c->fem;
    int d = w->dim, j, a, kind = d == 2 ? PN__FEM_PE : PN__FEM_PT;
    size_t i, nd = m->n_nodes * (size_t)d;
    memset(k->fx, 0, sizeof(pn_real) * w->n * (size_t)d);
    memset(k->pa, 0, sizeof(pn_real) * nd);
    for (i = 0; i < k->nc; ++i) {
        size_t p = k->cp[i];
        const int *tn = pn__cpl_target(m, k->ck[i]);
        pn_real yy[12], gl[12], Eb, dist, kap = pn__cpl_kappa(c, p);
        pn__cpl_pair_y(c, i, yy, NULL);
        if (!pn__pair_barrier(kind, d, d + 1, yy, c->dhat, kap, 1, &Eb, gl, NULL, &dist, 0) || dist >= c->dhat) continue;
        for (a = 0; a < d; ++a) k->fx[p * (size_t)d + (size_t)a] -= gl[a];
        for (j = 0; j < d; ++j)
            for (a = 0; a < d; ++a) k->pa[(size_t)tn[j] * (size_t)d + (size_t)a] -= gl[d + j * d + a];
        if (c->friction > 0) {
            pn_real beta[3], nrm[3], vr[3], vn = 0, sp = 0, bb, b1, b2, f;
            pn__cpl_closest(d, yy, yy + d, beta, nrm);
            pn__fem_barrier(dist, c->dhat, &bb, &b1, &b2);
            for (a = 0; a < d; ++a) {
                vr[a] = w->v[p * (size_t)d + (size_t)a];
                for (j = 0; j < d; ++j) vr[a] -= beta[j] * m->v[(size_t)tn[j] * (size_t)d + (size_t)a];
                vn += vr[a] * nrm[a];
            }
            for (a = 0; a < d; ++a) vr[a] -= vn * nrm[a], sp += vr[a] * vr[a];
            sp = PN__SQRT(sp);
            if (!(sp > 0)) continue;
            f = PN__MIN(c->friction * kap * -b1, w->mass[p] * sp / dt);
            for (a = 0; a < d; ++a) {
                k->fx[p * (size_t)d + (size_t)a] -= f * vr[a] / sp;
                for (j = 0; j < d; ++j) k->pa[(size_t)tn[j] * (size_t)d + (size_t)a] += beta[j] * f * vr[a] / sp;
            }
        }
    }
}

PN__DEF pn_result pn_coupled_step_explicit(pn_coupled *c, pn_real dt, pn_coupled_stats *stats) {
    pn__cpl *k;
    pn_mpm_world *w;
    pn_fem_mesh *m;
    pn__fem *s;
    pn_mpm_stats mst;
    pn_fem_stats fst;
    pn_result r;
    pn_real t0, *fc;
    long steps0;
    size_t left0, p, nf = 0, i, nd;
    int d, a, kind, rec0, ctau0;
    if (!c) return PN_ERROR_INVALID_ARGUMENT;
    k = (pn__cpl *)c->impl, w = c->mpm, m = c->fem, s = (pn__fem *)m->impl;
    d = w->dim, nd = m->n_nodes * (size_t)d, kind = d == 2 ? PN__FEM_PE : PN__FEM_PT;
    c->error[0] = 0, c->error_particle = c->error_node = -1;
    if (!pn__finite(dt) || !(dt > 0))
        return PN__FAIL(c, PN_ERROR_INVALID_ARGUMENT, "pn_coupled_step_explicit: dt_s = %g must be finite and > 0",
                            (double)dt);
    if ((r = pn__mpm_alloc_implicit(w)) != PN_OK || (r = pn__cpl_alloc(c)) != PN_OK)
        return PN__FAIL(c, PN_ERROR_OUT_OF_MEMORY, "pn_coupled_step_explicit: out of memory for the storage");
    if ((r = pn__mpm_check_state(w)) != PN_OK) return PN__FAIL(c, r, "pn_coupled_step_explicit: %s", w->error);
    if ((r = pn__cpl_check_mesh(c, "pn_coupled_step_explicit")) != PN_OK) return r;
    pn__cpl_here(c);
    if ((r = pn__cpl_find(c, 0)) != PN_OK) return r;
    pn__cpl_forces(c, dt);
    fc = k->fx + w->n * (size_t)d; /* the loaded particles' forces, compact */
    for (p = 0; p < w->n; ++p) {
        const pn_real *f = k->fx + p * (size_t)d;
        if (f[0] == 0 && f[1] == 0 && (d == 2 || f[2] == 0)) continue;
        for (a = 0; a < d; ++a) fc[nf * (size_t)d + (size_t)a] = f[a];
        k->fidx[nf++] = p;
    }
    t0 = w->time_s, steps0 = w->steps, left0 = w->left_total, rec0 = w->s.rec_ok, ctau0 = w->s.ctau_ok;
    pn__mpm_backup(w, 0);
    w->s.xf_idx = k->fidx, w->s.xf = fc, w->s.xf_n = nf;
    r = pn_mpm_step_explicit(w, dt, &mst);
    w->s.xf_idx = NULL, w->s.xf = NULL, w->s.xf_n = 0;
    if (r != PN_OK) {
        c->error_particle = w->error_particle;
        return PN__FAIL(c, r, "pn_coupled_step_explicit: %s", w->error);
    }
    s->fext = k->pa;
    r = pn_fem_step_explicit(m, dt, &fst);
    s->fext = NULL;
    if (r == PN_OK) { /* no particle crossed the boundary within the step */
        for (i = 0; i < nd; ++i) k->xf[i] = s->bx[i], k->xd[i] = m->x[i] - s->bx[i];
        for (i = 0; i < w->n * (size_t)d; ++i) k->y[i] = w->s.bx[i], k->yd[i] = w->x[i] - w->s.bx[i];
        if ((r = pn__cpl_find(c, 1)) != PN_OK) return r;
        for (i = 0; i < k->nc; ++i) {
            pn_real yy[12], dy[12];
            pn__cpl_pair_y(c, i, yy, dy);
            if (pn__pair_ccd(kind, d, d + 1, 1, yy, dy, 0, 1) < 1) {
                c->error_particle = (long)k->cp[i];
                r = PN__FAIL(c, PN_ERROR_STEP_TOO_LARGE, "pn_coupled_step_explicit: particle %lu would close on the "
                                 "mesh's boundary in a step of %g s: take a smaller step (pn_coupled_stable_dt)",
                                 (unsigned long)k->cp[i], (double)dt);
                pn__fem_restore(m);
                m->steps--;
                break;
            }
        }
    } else
        r = PN__FAIL(c, r, "pn_coupled_step_explicit: %s", m->error);
    if (r != PN_OK) { /* the world back as it was, with the P2G records the step swapped out */
        pn_real *t = w->s.ppay;
        int *row = w->s.prow;
        pn__mpm_backup(w, 1);
        w->s.ppay = w->s.spay, w->s.spay = t, w->s.prow = w->s.srow, w->s.srow = row;
        w->time_s = t0, w->steps = steps0, w->left_total = left0, w->s.rec_ok = rec0;
        w->s.ctau_ok = ctau0, w->s.stau_committed = 0;
        return r;
    }
    if (stats) {
        memset(stats, 0, sizeof *stats);
        stats->substeps = 1;
        stats->plastic_particles = mst.plastic, stats->plastic_elements = fst.plastic;
        pn__cpl_here(c);
        if (pn__cpl_find(c, 0) == PN_OK) stats->min_distance_m = pn__cpl_closest_pair(c, &stats->pairs);
    }
    return PN_OK;
}

PN__DEF pn_result pn_coupled_stable_dt(pn_coupled *c, pn_real *dt_s) {
    pn__cpl *k;
    pn_real a, b, best;
    pn_result r;
    size_t i;
    int d;
    if (!c || !dt_s) return PN_ERROR_INVALID_ARGUMENT;
    k = (pn__cpl *)c->impl, d = c->mpm->dim;
    if ((r = pn_mpm_stable_dt(c->mpm, &a)) != PN_OK || (r = pn_fem_stable_dt(c->fem, &b)) != PN_OK) return r;
    best = PN__MIN(a, b);
    if ((r = pn__cpl_alloc(c)) != PN_OK) return r;
    pn__cpl_here(c);
    if ((r = pn__cpl_find(c, 0)) != PN_OK) return r;
    for (i = 0; i < k->nc; ++i) { /* the barrier's spring on the lighter side */
        pn_real yy[12], dist, bb, b1, b2, mass = c->mpm->mass[k->cp[i]];
        const int *tn = pn__cpl_target(c->fem, k->ck[i]);
        int j;
        pn__cpl_pair_y(c, i, yy, NULL);
        dist = PN__SQRT(pn__fem_pair_d2(d == 2 ? PN__FEM_PE : PN__FEM_PT, d, yy, NULL, NULL));
        if (!(dist > 0) || dist >= c->dhat) continue;
        pn__fem_barrier(dist, c->dhat, &bb, &b1, &b2);
        for (j = 0; j < d; ++j) mass = PN__MIN(mass, c->fem->mass[tn[j]]);
        best = PN__MIN(best, PN__SQRT(mass / (pn__cpl_kappa(c, k->cp[i]) * b2)));
    }
    *dt_s = best;
    return PN_OK;
}

#undef PN__CPL_FD
#endif /* PN_NO_FEM */

#undef PN__FEM_FREE

#undef pn__fem_backup

#undef pn__fem_restore

#undef PN__FEM_ALIGN

#undef PN__FEM_FAR

#undef PN__OMP_FOR

#undef PN__MPM_SPLINE

#undef PN__MPM_ADD4

#undef PN__MPM_PAY

#undef PN__MPM_REC

#undef PN__MPM_SLABS

#undef PN__MPM_LANES

#undef PN__MPM_BLOCK
#undef PN__MPM_INLINE
#undef PN__MPM_ARRAYS
#endif /* PLASTINET_MPM_IMPLEMENTATION */
