/* plastinet.h - v0.21 - elastoplastic constitutive core for sand, snow, metal and rubber.
   Public domain or MIT, your choice: see the end of this file.

   Do this in exactly one C or C++ file:
       #define PLASTINET_IMPLEMENTATION
       #include "plastinet.h"
   and include it without the define everywhere else.

   ======================================================================================
   QUICK START
   ======================================================================================

       pn_material_desc d;
       pn_material sand;
       char why[256];
       memset(&d, 0, sizeof d);                       // zeroed fields mean defaults
       d.plastic = PN_PLASTIC_DRUCKER_PRAGER;         // elastic defaults to StVK-Hencky
       d.youngs_modulus_pa = 1e7; d.poisson_ratio = 0.3; d.friction_angle_deg = 30;
       if (pn_material_init(&sand, &d, why, sizeof why) != PN_OK) puts(why);

       pn_real F[9] = {1.02, 0.01, 0, 0, 0.97, 0, 0, 0, 1};  // 3x3 row-major, trial elastic F
       pn_real Z[9], T[9], h = 0, h_new;
       pn_return_map(&sand, 3, F, h, Z, &h_new, T);   // Z: F projected onto the yield surface,
                                                      // T = tau(Z(F)) F^-T, the force density

       // an implicit solver instead asks an energy for psi, P = dpsi/dF and a PSD dP/dF:
       pn_real G[9], hG, psi, P[9], H[81];
       pn_lagged_prepare(&sand, 3, F, h, G, &hG);     // once per F0 (here F0 = F)
       pn_lagged_energy(&sand, 3, F, G, hG, &psi, P, H, PN_EVAL_PROJECT_PSD);

   PlasticityNet: a learned energy for plasticity in implicit solvers (models/README.md):

       #include "models/pn_model_sand_2d.h"          // after plastinet.h
       pn_material sand2d;  pn_pnet net;  pn_pnet_desc nd;  pn_pnet_point pt;
       pn_model_material(pn_model_sand_2d(), 1e7, &sand2d);   // its training material, E = 1e7
       memset(&nd, 0, sizeof nd);  nd.energy = pn_model_sand_2d();
       pn_pnet_init(&net, &nd, &sand2d, 2, why, sizeof why);
       pn_real F0[4] = {1, 0, 0, 0.98}, F1[4] = {1.01, 0, 0.02, 0.97}, P2[4], H2[16];
       pn_pnet_prepare(&net, F0, 0, &pt, NULL, NULL); // once per F0 (each fixed-point pass)
       pn_pnet_energy(&net, &pt, F1, &psi, P2, H2, PN_EVAL_PROJECT_PSD);

   Matrices are row-major arrays of dim*dim reals (F[i*dim+j] = F_ij), dim = 2 or 3.
   A pn_real[9] serves both dimensions. Fourth-order tensors (dP/dF) are dim^2 x dim^2
   row-major: dPdF[(i*dim+j)*dim*dim + k*dim+l] = dP_ij / dF_kl.

   What is here (greppable banners in the implementation: // >>name), in file order, with
   each room's public functions:
     >>config   every option resolved in one place; pn_result_string, pn_alloc, pn_free
     >>kit      the private helpers every module shares (plastinet_mpm.h and plastinet_rom.h
                too): messages, a hash, B-spline weights, dense Cholesky, the backtracking
                line search, preconditioned CG, a rigid drive's motion, the substep fallback
     >>matrix   small dense 2D/3D matrix helpers: pn_mat_det, pn_mat_inverse, pn_mat_mul
     >>svd      SVD with rotation-valued U and V (det +1), the sign of an inverted F carried
                by the smallest singular value; polar decomposition; Hencky strain: pn_svd,
                pn_polar, pn_hencky_strain
     >>eigen    symmetric eigen-decomposition (Jacobi) and PSD projection, n <= 12:
                pn_sym_eigen, pn_sym_project_psd
     >>material parameter validation, Lame constants, names: pn_material_init, _check,
                _describe, pn_lame, pn_elastic_model_name / _from_name, pn_plastic_model_name
                / _from_name
     >>elastic  fixed corotated, StVK-Hencky, Neo-Hookean, and the Neo-Hookean variant used by
                Cam-Clay snow: energy, P, dP/dF, PSD-projected dP/dF: pn_elastic_energy,
                pn_kirchhoff_stress
     >>return-mapping  Drucker-Prager (sand), von Mises (metal, closed form for StVK-Hencky,
                safeguarded root find otherwise), non-associative Cam-Clay (snow), and the
                singular-value clamp snow of Stomakhin et al. 2013: pn_return_map,
                pn_yield_function
     >>energy-vm      exact StVK-Hencky + von Mises elastoplastic energy (the return mapping's
                      incremental potential, hardening included): pn_von_mises_energy
     >>energy-dp      the frozen-yield Drucker-Prager energy: pn_dp_prepare, pn_dp_energy
     >>energy-lagged  lagged-plasticity energy Psi_el(F G), G = F0^-1 Z(F0):
                      pn_lagged_prepare, pn_lagged_energy
     >>mlp      inference of small MLPs stored as float arrays: value, input gradient and the
                exact input Hessian (forward-mode second order): pn_mlp_eval, _eval_lanes
     >>features rotation invariants of F (from C = F^T F, no SVD) and their F-derivatives
     >>pnet     PlasticityNet learned elastoplastic energy Psi(F; F0, h) (Li et al. 2022,
                Eqs. 8 and 11) from a model header in models/, rescaled to any E:
                pn_model_check, pn_model_material, _material_desc, pn_model_param_set,
                pn_pnet_init, pn_pnet_prepare, _prepare_lanes, pn_pnet_energy, _energy_lanes
     >>learned-return  learned volume-preserving von Mises return mapping (Eqs. 12-13):
                pn_learned_return_map

   ======================================================================================
   CONVENTIONS (all four modules: core, MPM, FEM and coupling, ROM)
   ======================================================================================
   Names     pn_<module>_<verb>[_<object>] (pn_mpm_fill, pn_fem_step_implicit); private
             names pn__, private macros PN__; the types MPM and FEM share are neutral
             (pn_collider, pn_energy, pn_group).
   Units     a field or argument with a unit says it: _m, _s, _m_s, _pa, _kg_m3, _N, _j
             (joules), _deg; iteration counters end in _iters.
   Objects   pn_<module>_create(desc, &out, why, why_cap) allocates through desc's
             allocator; _destroy(NULL) does nothing; _error(obj) is why obj's last call
             failed ("" when none, and for NULL). A description zeroed by memset means
             defaults; each module resolves its defaults in one function.
   Why       every call that can refuse without an object to hold the message (creates,
             inits, checks, loaders) takes char *why, size_t why_cap: a sentence naming the
             field or value at fault (NULL or 0: not wanted).
   Indices   particles and their counts are size_t; mesh nodes and elements are int (as
             the element arrays and the loaders hold them); groups, colliders, drives and
             loads are int. The culprit of a failed step is a long, -1 for none
             (error_particle, error_node, error_element).
   Results   every fallible call returns a pn_result; on failure its object and outputs
             are as they were (ERRORS below).

   ======================================================================================
   OPTIONS (define before including the implementation)
   ======================================================================================

     macro               default         effect
     PN_REAL             double          scalar type; float works (tolerances loosen)
     PLASTINET_STATIC    off             every function is static (private to one file)
     PN_ASSERT(x)        assert(x)       programming errors (not bad data: that gets a pn_result)
     PN_MALLOC(sz,u)     malloc(sz)      default allocator when a pn_allocator has no callbacks
     PN_FREE(p,u)        free(p)
     PN_NO_STDIO         off             removes pn_material_describe (the only use of stdio)
     PN_NO_2D            off             dim = 2 is rejected with PN_ERROR_DIMENSION
     PN_NO_3D            off             dim = 3 is rejected with PN_ERROR_DIMENSION
     PN_NO_VECTOR_EXTENSIONS off         plain C loops instead of gcc/clang vector types (the
                                         float lanes of the networks)
     plastinet_mpm.h and plastinet_rom.h add their own (their OPTIONS tables)

   ======================================================================================
   MEMORY
   ======================================================================================
   The core allocates nothing: every function works on caller-provided arrays (pn_mlp_eval
   keeps its work arrays on the stack: about 10500 reals, 82 KB in double, since
   PN_MLP_MAX_DIFF is 8 for the scaled encoding (a 64 KB thread stack is too small);
   model weights are static const data in the model headers). Solvers built
   on it take a pn_allocator (both callbacks or neither, with a user pointer) and store it with
   the object they allocate.

   ======================================================================================
   ERRORS
   ======================================================================================
   Every fallible call returns a pn_result; pn_result_string() explains it. Bad data (NaN or
   inf, impossible parameters, a deformation where the model is undefined) never crashes and
   never writes a partial result: on any error every output is left exactly as it was.
   pn_material_init additionally names the offending parameter. NULL required pointers and
   similar programming errors trip PN_ASSERT. NaN or inf in an input is PN_ERROR_NONFINITE; a
   result that overflows for finite inputs (stretches far beyond any physical range) is
   PN_ERROR_OVERFLOW.

   Inverted deformations: the Hencky-strain models (StVK-Hencky, Drucker-Prager, von Mises,
   exact von Mises energy) and the Neo-Hookean models are undefined for det F <= 0 and return
   PN_ERROR_INVERTED; so do all return mappings of plastic models. Fixed corotated is defined
   for every F (its Hessian is singular where s_i + s_j = 0, where the rotation is undefined;
   there the divisor is clamped to machine epsilon).

   ======================================================================================
   THREADS AND DETERMINISM
   ======================================================================================
   No global state: every function is reentrant and may run on any number of threads at once.
   Results depend only on the inputs (no randomness, no thread-count dependence). For bitwise
   identical results across compilers and optimization levels compile without -ffast-math
   and with -ffp-contract=off (where the target has fma, clang fuses a * b + c within a
   statement by default, gcc anywhere in its GNU modes). Checked on x86-64 (SSE2; 32-bit x87
   builds round differently) for gcc 12, g++ 12, clang 14 and clang++ 14 at -O0 to -O3 with
   every MPM integrator and energy (tests/cross_compiler.sh). The bits also depend on the C
   library: sqrt is correctly rounded, but exp, log, log1p, pow, sin, sinh and tanh come from
   libm, so compare builds linked against the same libm. The code never calls pow with an
   exponent that may become -1 or 0.5 (or 2): compilers replace those by 1 / x or sqrt (x * x),
   at some -O levels and not others, while libm's pow is not always correctly rounded.

   ======================================================================================
   VERSION
   ======================================================================================
   One version for the three headers (the banners and PN_VERSION_MAJOR / _MINOR below);
   CHANGELOG.md has what each version changed, with every rename and refusal it added.
*/
#ifndef PLASTINET_H
#define PLASTINET_H

#include <stddef.h>

#ifndef PN_REAL
#define PN_REAL double
#endif

#ifdef PLASTINET_STATIC
#define PN_API static
#else
#define PN_API extern
#endif

#define PN_VERSION_MAJOR 0
#define PN_VERSION_MINOR 21

#ifdef __cplusplus
extern "C" {
#endif

typedef PN_REAL pn_real;

/* ---- results ------------------------------------------------------------------------ */

typedef enum pn_result {
    PN_OK = 0,
    PN_ERROR_INVALID_ARGUMENT,  /* an argument out of its domain (dim, a state value)     */
    PN_ERROR_INVALID_PARAMETER, /* a material parameter out of range                       */
    PN_ERROR_NONFINITE,         /* NaN or inf in an input                                  */
    PN_ERROR_INVERTED,          /* det F <= 0 where the model is undefined                 */
    PN_ERROR_UNSUPPORTED,       /* combination not supported (e.g. Cam-Clay with StVK)     */
    PN_ERROR_NOT_CONVERGED,     /* an iterative method failed to converge                  */
    PN_ERROR_OUT_OF_MEMORY,
    PN_ERROR_DIMENSION,         /* dimension compiled out, or a model of the wrong dim     */
    PN_ERROR_FORMAT,            /* malformed model or mesh data (version, sizes, values)   */
    PN_ERROR_OVERFLOW,          /* finite inputs, but the result overflowed (NaN or inf):
                                   the deformation is too extreme for the model          */
    PN_ERROR_STEP_TOO_LARGE,    /* a time step beyond what the solver can take honestly
                                   (material would move more than the advection limit)   */
    PN_ERROR_OUTSIDE_DOMAIN,    /* material would leave the simulation domain (through a
                                   wall) where outflow is not allowed                     */
    PN_ERROR_CAPACITY,          /* a fixed capacity (particles, groups, colliders) is full  */
    PN_RESULT_COUNT
} pn_result;

/* A static, human-readable sentence for a result code. */
PN_API const char *pn_result_string(pn_result r);

/* ---- allocator hooks (used by the solver modules; the core allocates nothing) ------- */

typedef struct pn_allocator {
    void *(*alloc)(size_t size_bytes, void *user); /* both or neither */
    void (*free)(void *ptr, void *user);
    void *user;
} pn_allocator;

/* Allocate through a (possibly NULL or zeroed) allocator; falls back to PN_MALLOC/PN_FREE. */
PN_API void *pn_alloc(const pn_allocator *a, size_t size_bytes);
PN_API void pn_free(const pn_allocator *a, void *ptr);

/* ---- small matrices (row-major, dim x dim) --------------------------------------------- */

PN_API pn_real pn_mat_det(int dim, const pn_real *A);
/* Inverse; PN_ERROR_INVERTED when A is singular (det == 0), A_inv untouched. */
PN_API pn_result pn_mat_inverse(int dim, const pn_real *A, pn_real *A_inv);
/* C = A B (C may alias neither input). */
PN_API void pn_mat_mul(int dim, const pn_real *A, const pn_real *B, pn_real *C);

/* SVD F = U diag(s) V^T with det U = det V = +1. |s_0| >= |s_1| (>= |s_2|); all s_i >= 0
   except the last, which is negative when det F < 0. Exact zeros give an arbitrary but
   orthonormal completion. PN_ERROR_NONFINITE on NaN/inf. */
PN_API pn_result pn_svd(int dim, const pn_real *F, pn_real *U, pn_real *s, pn_real *V);

/* Right polar decomposition F = R S, R a rotation (det +1), S symmetric. For an inverted F,
   S has one negative eigenvalue (the sign convention of pn_svd). */
PN_API pn_result pn_polar(int dim, const pn_real *F, pn_real *R, pn_real *S);

/* Spatial Hencky strain log V = U diag(log s) U^T. PN_ERROR_INVERTED when det F <= 0. */
PN_API pn_result pn_hencky_strain(int dim, const pn_real *F, pn_real *eps);

/* Symmetric eigen-decomposition A = Q diag(w) Q^T (cyclic Jacobi), n <= 12, Q row-major with
   eigenvectors as columns, w ascending. A must be symmetric (only the upper part is read). */
PN_API pn_result pn_sym_eigen(int n, const pn_real *A, pn_real *Q, pn_real *w);
/* Replace symmetric A (n x n, n <= 12: a 3D contact pair's four nodes) with its nearest
   positive semi-definite matrix. */
PN_API pn_result pn_sym_project_psd(int n, pn_real *A);

/* ---- materials -------------------------------------------------------------------------- */

typedef enum pn_elastic_model {
    PN_ELASTIC_DEFAULT = 0,        /* the natural elasticity of the plastic model (below) */
    PN_ELASTIC_FIXED_COROTATED,    /* mu sum (s_i-1)^2 + lambda/2 (J-1)^2                 */
    PN_ELASTIC_STVK_HENCKY,        /* mu |log s|^2 + lambda/2 (tr log s)^2                */
    PN_ELASTIC_NEO_HOOKEAN,        /* mu/2 (|F|^2 - d) - mu log J + lambda/2 (log J)^2    */
    PN_ELASTIC_NEO_HOOKEAN_SNOW,   /* mu/2 (J^(-2/d)|F|^2 - d) + kappa/2 ((J^2-1)/2 - log J) */
    PN_ELASTIC_MODEL_COUNT
} pn_elastic_model;

typedef enum pn_plastic_model {
    PN_PLASTIC_NONE = 0,           /* purely elastic; default elasticity fixed corotated  */
    PN_PLASTIC_DRUCKER_PRAGER,     /* sand (Klar et al. 2016); needs StVK-Hencky           */
    PN_PLASTIC_VON_MISES,          /* metal, linear isotropic hardening; StVK-Hencky (closed
                                      form, default) or any other elasticity (root find)  */
    PN_PLASTIC_CAM_CLAY,           /* snow (Gaume et al. 2018); needs Neo-Hookean snow     */
    PN_PLASTIC_SNOW_STOMAKHIN,     /* singular-value clamp snow (Stomakhin et al. 2013);
                                      default elasticity fixed corotated                  */
    PN_PLASTIC_MODEL_COUNT
} pn_plastic_model;

/* Material description. Zeroed fields mean defaults where a default is stated; physical
   parameters without one must be set. The plastic state h (one real per point) means:
     NONE            unused (pass 0)
     DRUCKER_PRAGER  stored log-volume gain of the volume correction (>= 0; 0 without it)
     VON_MISES       accumulated equivalent plastic strain a (>= 0)
     CAM_CLAY        log J_p, the volumetric plastic strain (<= 0 gives the snow strength)
     SNOW_STOMAKHIN  log J_p (plastic volume ratio; Lame constants scale by exp(xi (1-J_p))) */
typedef struct pn_material_desc {
    pn_elastic_model elastic;
    pn_plastic_model plastic;
    pn_real youngs_modulus_pa;      /* E > 0, required                                     */
    pn_real poisson_ratio;          /* nu in (-1, 0.5)                                     */
    /* Drucker-Prager and Cam-Clay */
    pn_real friction_angle_deg;     /* phi in [0, 90) for DP, (0, 90) for Cam-Clay        */
    /* Drucker-Prager */
    pn_real cohesion_strain;        /* >= 0: log-strain shift of the cone apex (tensile
                                       strength); 0 = cohesionless                         */
    int volume_correction;          /* nonzero: Tampubolon et al. 2017 volume correction  */
    /* von Mises */
    pn_real yield_stress_pa;        /* uniaxial yield stress sigma_Y0 > 0                  */
    pn_real hardening_modulus_pa;   /* K >= 0: sigma_Y = sigma_Y0 + K a                    */
    /* Cam-Clay */
    pn_real camclay_beta;           /* cohesion ratio >= 0 (tension/compression strength) */
    pn_real camclay_xi;             /* hardening factor >= 0 in p0 = kappa sinh(xi max(-h,0)) */
    int camclay_no_hardening;       /* nonzero: h never changes                            */
    /* Stomakhin snow */
    pn_real snow_theta_c;           /* critical compression in (0, 1), e.g. 2.5e-2         */
    pn_real snow_theta_s;           /* critical stretch >= 0, e.g. 7.5e-3                  */
    pn_real snow_xi;                /* hardening coefficient >= 0, e.g. 10                 */
    pn_real snow_jp_min, snow_jp_max; /* bounds on the plastic volume ratio J_p, min in (0, 1)
                                       and max > 1, 0: none. E.g. 0.6 and 20: the hardening
                                       exp(xi (1 - J_p)) stays in [exp(-19 xi), exp(0.4 xi)] */
} pn_material_desc;

/* A validated material with derived constants. Treat as read-only. */
typedef struct pn_material {
    pn_elastic_model elastic;
    pn_plastic_model plastic;
    pn_real E, nu, mu, lambda;      /* Pa */
    pn_real sin_phi;                /* friction: sin of the friction angle */
    pn_real cohesion_strain;
    int volume_correction;
    pn_real yield_stress, hardening_modulus;
    pn_real beta, xi;
    int camclay_hardening;
    pn_real theta_c, theta_s, snow_xi;
    pn_real snow_h_min, snow_h_max; /* log J_p bounds, < 0 and > 0 (0: none)               */
} pn_material;

/* Validate desc and fill m. On failure m is untouched, and why (if not NULL) gets
   a static sentence naming the offending parameter. */
PN_API pn_result pn_material_init(pn_material *m, const pn_material_desc *desc, char *why, size_t why_cap);

/* Check a pn_material that did not come from pn_material_init (a copy, a file, a tweak of a
   field): the models and their combination, mu and lambda consistent with E and nu, and the
   plastic parameters in the ranges pn_material_init enforces. why names the field. */
PN_API pn_result pn_material_check(const pn_material *m, char *why, size_t why_cap);

/* Lame constants from Young's modulus and Poisson ratio (PN_ERROR_INVALID_PARAMETER if out of
   range; outputs untouched). kappa = lambda + 2 mu / dim is the bulk-like coefficient. */
PN_API pn_result pn_lame(pn_real E, pn_real nu, pn_real *mu, pn_real *lambda);

/* Names for printing and parsing ("stvk_hencky", "drucker_prager", ...). from_name returns
   -1 for an unknown name. */
PN_API const char *pn_elastic_model_name(pn_elastic_model e);
PN_API const char *pn_plastic_model_name(pn_plastic_model p);
PN_API int pn_elastic_model_from_name(const char *name);
PN_API int pn_plastic_model_from_name(const char *name);

#ifndef PN_NO_STDIO
/* One line describing the material; returns what snprintf returns. */
PN_API int pn_material_describe(const pn_material *m, char *buf, size_t cap);
#endif

/* ---- elastic energies --------------------------------------------------------------------- */

/* Flags for the energy evaluators. */
enum { PN_EVAL_PROJECT_PSD = 1 }; /* dP/dF replaced by a PSD matrix for Newton: the nearest
                                     one (elastic, exact von Mises); see pn_lagged_energy */

/* Elastic energy density psi(F) (J/m^3 = Pa), first Piola stress P (Pa) and dP/dF (Pa), each
   output optional (NULL). h only matters for SNOW_STOMAKHIN (hardened Lame constants). */
PN_API pn_result pn_elastic_energy(const pn_material *m, int dim, const pn_real *F, pn_real h,
                                   pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags);

/* Kirchhoff stress tau = P F^T (Pa) of the elastic model at F (F is the elastic part). */
PN_API pn_result pn_kirchhoff_stress(const pn_material *m, int dim, const pn_real *F, pn_real h,
                                     pn_real *tau);

/* ---- return mappings --------------------------------------------------------------------- */

/* Project the trial elastic deformation F onto the elastic region of the plastic model with
   state h. Outputs (each optional): Z = Z(F, h) the projected F, h_new the updated state, and
   T = tau(Z) F^-T the target force density (PlasticityNet Eq. 7). Inside the elastic region
   Z = F and h_new = h (except that a Drucker-Prager volume correction is absorbed into Z).
   Z lies on the yield surface of the state h the projection used; hardening then moves the
   surface (von Mises and the Cam-Clay compression side grow it, so Z stays inside; Cam-Clay
   softens on its tension side, so Z(Z, h_new) may project again). Plastic models need
   det F > 0 (PN_ERROR_INVERTED otherwise); with PN_PLASTIC_NONE, T = P(F). */
PN_API pn_result pn_return_map(const pn_material *m, int dim, const pn_real *F, pn_real h,
                               pn_real *Z, pn_real *h_new, pn_real *T);

/* Yield function at an elastic F and state h: <= 0 inside, 0 on the surface. Units:
   Drucker-Prager and von Mises Pa (|dev tau| + alpha tr tau resp. |dev tau| - sqrt(2/3)
   sigma_Y), Cam-Clay Pa^2 ((1 + 2 beta) q^2 + M^2 (p + beta p0)(p - p0)), Stomakhin
   dimensionless (distance of the singular values outside [1 - theta_c, 1 + theta_s]),
   NONE: -1. A scale (same units: the magnitude of the terms of y at F) for relative residuals
   goes to *scale if not NULL. At the Drucker-Prager apex and the Cam-Clay tips both y and the
   scale vanish (to rounding): measure a projection's residual there against the scale of the
   trial point instead. */
PN_API pn_result pn_yield_function(const pn_material *m, int dim, const pn_real *F, pn_real h,
                                   pn_real *y, pn_real *scale);

/* ---- elastoplastic energies -------------------------------------------------------------- */

/* Exact StVK-Hencky + von Mises energy: the incremental potential of the return mapping
   from plastic state h (the accumulated plastic strain at the step's start), linear hardening
   included: its gradient is tau(Z(F)) F^-T of pn_return_map at (F, h) exactly, so a
   minimization with it and the return mapping after it agree. C1 across the yield surface.
   Needs a von Mises material with StVK-Hencky elasticity (PN_ERROR_UNSUPPORTED otherwise). */
PN_API pn_result pn_von_mises_energy(const pn_material *m, int dim, const pn_real *F, pn_real h,
                                     pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags);

/* Drucker-Prager energy with the yield stress frozen at F0, for DRUCKER_PRAGER on
   STVK_HENCKY (PN_ERROR_UNSUPPORTED otherwise). The Klar et al. cone |dev tau| <= -alpha tr tau
   is a von Mises cylinder whose radius tau_y = -d kappa alpha tr e follows the volumetric strain,
   and the non-associative return keeps tr e; so with tau_y held fixed,
       Psi_dp(e) = kappa/2 min(tr e, 0)^2 + d kappa c tr e + psi_dev(|dev e|; tau_y),
       psi_dev = mu r^2 (2 mu r <= tau_y), tau_y r - tau_y^2 / (4 mu) (beyond),
   in the shifted Hencky strain e = log s - c + v/d (c the cohesion strain, v the volume
   credit h with the volume correction), is an exact potential of the return-mapped stress:
   its gradient is T(F) of pn_return_map wherever tr e equals that of the point tau_y was
   taken at, and the apex (tr e >= 0) is stress free (up to the cohesion's d kappa c). The
   error elsewhere is alpha d kappa |tr e - tr e0|, a friction lag, not an elastic stiffness
   against the flow: plastic shear is free within the step. C1, convex in e; prepare tau_y at
   F0 once, then evaluate at any F. */
PN_API pn_result pn_dp_prepare(const pn_material *m, int dim, const pn_real *F0, pn_real h,
                               pn_real *tau_y);
PN_API pn_result pn_dp_energy(const pn_material *m, int dim, const pn_real *F, pn_real h,
                              pn_real tau_y, pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags);

/* Lagged-plasticity energy Psi_lag(F; F0) = psi_el(F G, h_G), G = F0^-1 Z(F0, h0): the
   no-network baseline whose gradient at F = F0 is exactly T(F0). Prepare G and h_G once per
   F0, then evaluate at any F. With PN_EVAL_PROJECT_PSD the elastic Hessian at F G is projected
   (nearest PSD) and then carried to F by the congruence with G: PSD and cheap, but not the
   nearest PSD matrix of the lagged Hessian, since G is not a rotation. */
PN_API pn_result pn_lagged_prepare(const pn_material *m, int dim, const pn_real *F0, pn_real h0,
                                   pn_real *G, pn_real *h_G);
PN_API pn_result pn_lagged_energy(const pn_material *m, int dim, const pn_real *F,
                                  const pn_real *G, pn_real h_G, pn_real *psi, pn_real *P,
                                  pn_real *dPdF, unsigned flags);

/* ---- learned models: MLP inference, PlasticityNet energies, learned return mapping ---------- */

/* Layout version of the pn_model structs written by gen/export.py; a model of another version
   is refused with PN_ERROR_FORMAT. Version 2 added the array lengths of pn_mlp (weight_count,
   bias_count), checked against the layer sizes; version 3 the material parameters a model
   takes as inputs and the output form; version 4 the base energy (gen/upgrade_format.py
   converts versions 1 to 3). */
#define PN_MODEL_FORMAT_VERSION 4
#define PN_MODEL_MAX_PARAMS 4   /* material parameters a conditioned model takes as inputs */
#define PN_MLP_MAX_LAYERS 8     /* linear layers */
#define PN_MLP_MAX_WIDTH 64     /* units per layer (inputs and outputs included) */
#define PN_MLP_MAX_DIFF 8       /* inputs an evaluation can differentiate with respect to */

typedef enum pn_activation {
    PN_ACTIVATION_SILU = 1,     /* z / (1 + exp(-z)) */
    PN_ACTIVATION_TANH,
    PN_ACTIVATION_SOFTPLUS      /* log(1 + exp(z)) */
} pn_activation;

/* A multilayer perceptron with float weights (computed in pn_real): linear layers with the
   activation after each one but the last. weight[l] is size[l+1] x size[l], row-major (torch's
   nn.Linear layout), bias[l] has size[l+1] entries. */
typedef struct pn_mlp {
    int n_layers;
    int size[PN_MLP_MAX_LAYERS + 1]; /* size[0] inputs, size[n_layers] outputs */
    pn_activation activation;
    const float *weight[PN_MLP_MAX_LAYERS];
    const float *bias[PN_MLP_MAX_LAYERS];
    /* lengths of the weight and bias arrays (size[l+1] x size[l] and size[l+1]): a network
       whose sizes disagree with them is refused instead of read past */
    int weight_count[PN_MLP_MAX_LAYERS], bias_count[PN_MLP_MAX_LAYERS];
} pn_mlp;

/* Evaluate out = mlp(in) and, when n_diff > 0, the derivatives with respect to the first n_diff
   inputs (n_diff <= PN_MLP_MAX_DIFF): grad[o * n_diff + k] = d out_o / d in_k and, if hess is
   not NULL, hess[(o * n_diff + k) * n_diff + l] = d2 out_o / d in_k d in_l (exact: forward
   tangents and a backward pass). grad and hess may be NULL. PN_ERROR_FORMAT for a malformed
   network, PN_ERROR_NONFINITE for NaN/inf inputs, PN_ERROR_OVERFLOW if a result is not finite;
   outputs are written only on success. */
PN_API pn_result pn_mlp_eval(const pn_mlp *mlp, const pn_real *in, int n_diff, pn_real *out,
                             pn_real *grad, pn_real *hess);

/* The same for up to PN_MLP_LANES points at once, in float, lane-interleaved:
   in[k * PN_MLP_LANES + i] is input k of point i (i < n), out[i], grad[k * PN_MLP_LANES + i],
   hess[(k * n_diff + l) * PN_MLP_LANES + i]. The loops run over the lanes, so compilers turn
   them into vector instructions (SSE, AVX2, AVX-512: whatever the build targets). For
   networks of one output, silu or tanh, and at most PN_MLP_LANES_HIDDEN hidden units
   (PN_ERROR_FORMAT otherwise: use pn_mlp_eval); about 80 KB of stack. Float rounding: a
   relative error of about 1e-6 against pn_mlp_eval in double. */
#define PN_MLP_LANES 8
#define PN_MLP_LANES_HIDDEN 128
PN_API pn_result pn_mlp_eval_lanes(const pn_mlp *mlp, int n, const float *in, int n_diff, float *out,
                                   float *grad, float *hess);

typedef enum pn_model_kind {
    PN_MODEL_ENERGY = 1,        /* PlasticityNet energy N(F, F0, h) (Li et al. 2022, Eq. 8)    */
    PN_MODEL_RETURN_MAP         /* learned volume-preserving return mapping (Eqs. 12-13)       */
} pn_model_kind;

/* Material parameters a conditioned model takes as network inputs (pn_model.param), in the
   units of pn_material_desc; plastic stresses as ratios to E. */
typedef enum pn_model_param_kind {
    PN_MODEL_PARAM_POISSON = 1,      /* poisson_ratio                                       */
    PN_MODEL_PARAM_FRICTION_DEG,     /* friction_angle_deg (Drucker-Prager, Cam-Clay)       */
    PN_MODEL_PARAM_COHESION,         /* cohesion_strain (Drucker-Prager)                    */
    PN_MODEL_PARAM_YIELD_RATIO,      /* yield_stress_pa / E (von Mises)                     */
    PN_MODEL_PARAM_HARDENING_RATIO,  /* hardening_modulus_pa / E (von Mises)                */
    PN_MODEL_PARAM_CAMCLAY_BETA,     /* camclay_beta                                        */
    PN_MODEL_PARAM_CAMCLAY_XI        /* camclay_xi                                          */
} pn_model_param_kind;

typedef struct pn_model_param {
    int kind;                        /* a pn_model_param_kind                               */
    double lo, hi;                   /* the range the model was trained over               */
} pn_model_param;

/* The energy network's output m as N (at E = E_train): out_scale m, or out_scale softplus(m)
   >= 0, which bounds the energy below (see pn_pnet_init). */
typedef enum pn_model_output {
    PN_MODEL_OUTPUT_LINEAR = 0,
    PN_MODEL_OUTPUT_SOFTPLUS = 1
} pn_model_output;

/* An analytic energy B the network is a correction to: N fits T - grad B. */
typedef enum pn_model_base {
    PN_MODEL_BASE_NONE = 0,
    /* pn_von_mises_energy of the material with StVK-Hencky elasticity (same nu, yield and
       hardening), from the point's h: exact for StVK-Hencky, and within second order in the
       strain of any von Mises metal whose elasticity linearizes alike (Neo-Hookean) */
    PN_MODEL_BASE_VON_MISES_HENCKY = 1,
    /* pn_dp_energy of the material, its yield stress frozen at the point's F0 (pn_dp_prepare):
       a Drucker-Prager sand's return-mapped stress up to the friction lag, kinks and apex
       included, so the network fits only what a frozen yield misses */
    PN_MODEL_BASE_DP_FROZEN = 2
} pn_model_base;

/* A trained model as a generated header in models/ describes it (see models/README.md). The
   material fields describe what it was trained for; plastic stresses are ratios to E. */
typedef struct pn_model {
    int format_version;              /* PN_MODEL_FORMAT_VERSION of the generator           */
    const char *name;                /* "sand_2d", ...                                     */
    pn_model_kind kind;
    int dim;                         /* 2 or 3                                             */
    pn_elastic_model elastic;
    pn_plastic_model plastic;
    double youngs_modulus_train_pa;  /* E of the training data                             */
    double poisson_ratio;
    double friction_angle_deg;       /* Drucker-Prager, Cam-Clay                           */
    double cohesion_strain;          /* Drucker-Prager                                     */
    double yield_stress_ratio;       /* von Mises sigma_Y0 / E                             */
    double hardening_ratio;          /* von Mises K / E                                    */
    double camclay_beta, camclay_xi; /* Cam-Clay                                           */
    double h_min, h_max;             /* hardening-state range of the training data         */
    double e_box, de_box;            /* sampling: log stretches of F0 in [-e_box, e_box]^d,
                                        those of F within de_box of them (Section 5.1)     */
    const char *return_map;          /* name of the learned return mapping the energy was
                                        trained with, or NULL (analytic return mapping)   */
    int n_inputs;                    /* network inputs, = mlp.size[0]                      */
    double in_shift[16], in_scale[16]; /* network input u_i = (raw_i - shift_i) * scale_i  */
    double out_scale;                /* energy: N = out_scale mlp(u) at E = E_train        */
    pn_mlp mlp;
    const char *summary;             /* training and quality summary, one line             */
    int n_params;                    /* conditioned: material parameters as network inputs,
                                        after h (0: one material, the fields above)       */
    pn_model_param param[PN_MODEL_MAX_PARAMS]; /* which, and the range served             */
    int output;                      /* a pn_model_output                                   */
    int base;                        /* a pn_model_base                                     */
} pn_model;

/* Check a model's format version, kind, layout and dimension (dim = 0: any), that its array
   lengths (format 2) match its layer sizes, and that every weight is finite. On failure why
   (if not NULL) names the problem. */
PN_API pn_result pn_model_check(const pn_model *model, int dim, char *why, size_t why_cap);

/* The material a model was trained for, at Young's modulus E (Pa). On failure (a bad E, a
   malformed model) m is untouched and why (optional) says why. */
PN_API pn_result pn_model_material(const pn_model *model, pn_real E, pn_material *m, char *why, size_t why_cap);

/* The same as a description, to change what a conditioned model takes as inputs before
   pn_material_init (pn_model.param lists them and their ranges), e.g. another friction angle:
     pn_model_material_desc(pn_model_sand_any_2d(), 1e7, &d); d.friction_angle_deg = 40; */
PN_API void pn_model_material_desc(const pn_model *model, pn_real E, pn_material_desc *d);

/* Set parameter `kind` (a pn_model_param_kind, in its units: ratios to E are multiplied by
   d->youngs_modulus_pa) of a description: how tools walk a conditioned model's ranges. */
PN_API void pn_model_param_set(pn_material_desc *d, int kind, double value);

/* PlasticityNet (Li et al. 2022): the energy
     Psi(F; F0, h) = N(F, F0, h) - (grad_F N(F0, F0, h) - T(F0)) : F + R(F, F0)
   (Eqs. 8 and 11) whose gradient at F = F0 is exactly T(F0) = tau(Z(F0)) F0^-T and approximates
   T(F) nearby. A model with a base energy B (pn_model.base) adds B(F; F0, h) to N, in the
   correction too. N is a function of rotation invariants of F and F0 (exactly objective and
   isotropic), scaled by E / E_train. R is the regularizer, zero with zero gradient at F0:
     PN_PNET_REG_DISPLACEMENT  w mu/2 |F - F0|^2 (Eq. 11): it also resists rotating F, a
                               viscosity on spin that suits MPM's small rotations per step;
     PN_PNET_REG_STRAIN        w mu/8 |F^T F - F0^T F0|^2: the same stiffness on stretches at
                               small strain, none on rotations (objective). For FEM bodies that
                               bend and buckle: the displacement form makes turning an element
                               cost as much as straining it, and a crushed frame then squashes
                               instead of folding (docs/notebook.md, "what changed since the
                               last measurement"). */
typedef enum pn_pnet_regularizer {
    PN_PNET_REG_DISPLACEMENT = 0,
    PN_PNET_REG_STRAIN = 1
} pn_pnet_regularizer;

typedef struct pn_pnet_desc {
    const pn_model *energy;          /* required, kind PN_MODEL_ENERGY                      */
    const pn_model *return_map;      /* the learned return mapping energy->return_map names;
                                        NULL when that is NULL                             */
    pn_real regularizer;             /* w: 0 means 1; negative means 0 (off)               */
    pn_pnet_regularizer regularizer_form; /* R's form [PN_PNET_REG_DISPLACEMENT]            */
} pn_pnet_desc;

typedef struct pn_pnet {
    const pn_model *energy, *return_map;
    pn_material material;            /* the simulated material (any E)                     */
    pn_real scale;                   /* E / E_train                                        */
    pn_real reg;                     /* w mu (Pa)                                          */
    pn_pnet_regularizer reg_form;
    pn_real cond[PN_MODEL_MAX_PARAMS]; /* a conditioned model's parameter inputs            */
    pn_material base;                /* the base energy's material (pn_model.base)          */
    char message[192];               /* pn_pnet_init's reason, when it names numbers       */
} pn_pnet;

/* Per-point data, computed once per F0 by pn_pnet_prepare. */
typedef struct pn_pnet_point {
    pn_real F0[9];
    pn_real x0[3];                   /* invariant features of F0                            */
    pn_real h;                       /* hardening state (the network sees it clamped to the
                                        model's range; T(F0) used it as given)            */
    pn_real C[9];                    /* linear correction (E-scaled grad N(F0) - T(F0))      */
    pn_real tau_y;                   /* PN_MODEL_BASE_DP_FROZEN: the base's yield stress at F0 */
} pn_pnet_point;

/* Bind a model to a material. The material must match the model's training material (models,
   Poisson ratio, plastic parameters relative to E; E itself is free) and dim the model's
   (dim = 0 accepts the model's own):
   PN_ERROR_INVALID_PARAMETER, PN_ERROR_DIMENSION or PN_ERROR_FORMAT otherwise, with why. */
PN_API pn_result pn_pnet_init(pn_pnet *net, const pn_pnet_desc *desc, const pn_material *m,
                              int dim, char *why, size_t why_cap);

/* Prepare a point for F0 and hardening state h: computes T(F0) by the return mapping (analytic,
   or the learned one) and the linear correction. h_new (optional) gets the return mapping's
   updated state at F0, T0 (optional) T(F0). */
PN_API pn_result pn_pnet_prepare(const pn_pnet *net, const pn_real *F0, pn_real h,
                                 pn_pnet_point *pt, pn_real *h_new, pn_real *T0);

/* Psi(F; F0, h) (Pa), P = dPsi/dF and dP/dF, each optional, at a prepared point. With
   PN_EVAL_PROJECT_PSD dP/dF is replaced by its nearest PSD matrix. PN_ERROR_INVERTED for
   det F <= 0 (the invariants need J > 0). */
PN_API pn_result pn_pnet_energy(const pn_pnet *net, const pn_pnet_point *pt, const pn_real *F,
                                pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags);

/* pn_pnet_energy at n <= PN_MLP_LANES points at once, the network in float lanes
   (pn_mlp_eval_lanes; the rest in pn_real): F, psi, P and dPdF hold the points one after
   another (dim^2 and dim^4 reals each; outputs optional as there), pt[i] each point's
   prepared state, status[i] each point's result; returns the first point's error, if any.
   A network without a lane path is evaluated one point at a time. The float network moves
   the results by about 1e-6 relative: pn_pnet_energy is the reference. */
PN_API pn_result pn_pnet_energy_lanes(const pn_pnet *net, int n, const pn_pnet_point *const *pt, const pn_real *F,
                                      pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags,
                                      pn_result *status);

/* pn_pnet_prepare at n <= PN_MLP_LANES points at once, the network's gradient at F0 in float
   lanes: F0 and h hold the points one after another (dim^2 and 1 reals each), pt[i] and
   status[i] each point's result; returns the first point's error, if any. Points prepared
   here are exact at F0 for pn_pnet_energy_lanes (the same float network on both sides),
   to about 1e-6 relative for pn_pnet_energy. */
PN_API pn_result pn_pnet_prepare_lanes(const pn_pnet *net, int n, const pn_real *F0, const pn_real *h,
                                       pn_pnet_point *pt, pn_result *status);

/* Learned volume-preserving von Mises return mapping (Eqs. 12-13): as pn_return_map, with the
   plastic multiplier from the network: dgamma = min(|e_hat| - r(s, h), |e_hat|) clamped at 0,
   r = r_ref exp(mlp(u)). m must match the model's training material. */
PN_API pn_result pn_learned_return_map(const pn_model *model, const pn_material *m, int dim,
                                       const pn_real *F, pn_real h, pn_real *Z, pn_real *h_new,
                                       pn_real *T);

#ifdef __cplusplus
}
#endif
#endif /* PLASTINET_H */

/* ======================================================================================
   IMPLEMENTATION
   ====================================================================================== */
#if defined(PLASTINET_IMPLEMENTATION) && !defined(PLASTINET_IMPLEMENTATION_DONE)
#define PLASTINET_IMPLEMENTATION_DONE

/* >>config: every option resolved in one place. */
#include <float.h>
#include <math.h>
#include <stdint.h> /* int32_t: the exponent bits of pn__expf_lanes */
#include <string.h>
#ifndef PN_ASSERT
#include <assert.h>
#define PN_ASSERT(x) assert(x)
#endif
#if !defined(PN_MALLOC) || !defined(PN_FREE)
#include <stdlib.h>
#undef PN_MALLOC
#undef PN_FREE
#define PN_MALLOC(sz, u) ((void)(u), malloc(sz))
#define PN_FREE(p, u) ((void)(u), free(p))
#endif
#ifndef PN_NO_STDIO
#include <stdio.h>
#endif

#ifdef PLASTINET_STATIC /* a file need not call every function it compiles */
#if defined(__GNUC__) || defined(__clang__)
#define PN__DEF static __attribute__((unused))
#else
#define PN__DEF static
#endif
#else
#define PN__DEF
#endif

/* Math in double whatever pn_real is: float builds gain accuracy and need no f-suffixed calls. */
#define PN__SQRT(x) ((pn_real)sqrt((double)(x)))
#define PN__LOG(x) ((pn_real)log((double)(x)))
#define PN__LOG1P(x) ((pn_real)log1p((double)(x)))
#define PN__EXP(x) ((pn_real)exp((double)(x)))
#define PN__POW(x, y) ((pn_real)pow((double)(x), (double)(y)))
#define PN__SIN(x) ((pn_real)sin((double)(x)))
#define PN__COS(x) ((pn_real)cos((double)(x)))
#define PN__SINH(x) ((pn_real)sinh((double)(x)))
#define PN__FABS(x) ((pn_real)fabs((double)(x)))
#define PN__EPS ((pn_real)(sizeof(pn_real) < sizeof(double) ? FLT_EPSILON : DBL_EPSILON))
#define PN__PI ((pn_real)3.14159265358979323846)
#define PN__MAX(a, b) ((a) > (b) ? (a) : (b))
#define PN__MIN(a, b) ((a) < (b) ? (a) : (b))

static int pn__finite(pn_real x) { return x == x && x - x == 0; }

/* x^(k/d) for k = 1 or -2, d = 2 or 3: sqrt(x) and 1 / x in 2D, pow in 3D. Never pow with an
   exponent that can become 0.5 or -1: compilers fold pow(x, -1.0) to 1 / x (gcc and clang)
   and pow(x, 0.5) to sqrt (clang with -fno-math-errno) once d is a known constant (inlining,
   cloning), and libm's pow is not always correctly rounded, so the bits would depend on the
   compiler and the optimization level (THREADS AND DETERMINISM). */
static pn_real pn__pow_dim(pn_real x, int k, int d) {
    PN_ASSERT((k == 1 || k == -2) && (d == 2 || d == 3));
    if (d == 2) return k == 1 ? PN__SQRT(x) : 1 / x;
    return PN__POW(x, (pn_real)k / (pn_real)d);
}

/* x - x is +0 for finite x and NaN otherwise, and NaN survives the sum: no branch per entry */
static int pn__all_finite(int n, const pn_real *a) {
    pn_real z = 0;
    int i;
    for (i = 0; i < n; ++i) z += a[i] - a[i];
    return z == 0;
}

static int pn__dim_ok(int d) {
#ifndef PN_NO_2D
    if (d == 2) return 1;
#endif
#ifndef PN_NO_3D
    if (d == 3) return 1;
#endif
    return 0;
}

PN__DEF const char *pn_result_string(pn_result r) {
    switch (r) {
    case PN_OK: return "ok";
    case PN_ERROR_INVALID_ARGUMENT: return "invalid argument (dimension, state or option out of range)";
    case PN_ERROR_INVALID_PARAMETER: return "invalid material parameter";
    case PN_ERROR_NONFINITE: return "NaN or infinity in an input";
    case PN_ERROR_INVERTED: return "inverted or singular deformation (det F <= 0) where the model is undefined";
    case PN_ERROR_UNSUPPORTED: return "unsupported combination of elastic and plastic models";
    case PN_ERROR_NOT_CONVERGED: return "an iterative solve did not converge";
    case PN_ERROR_OUT_OF_MEMORY: return "out of memory";
    case PN_ERROR_DIMENSION: return "unsupported dimension (not 2 or 3, compiled out, or a model of another dimension)";
    case PN_ERROR_FORMAT: return "malformed model or mesh data (format version, sizes or values)";
    case PN_ERROR_OVERFLOW: return "the result overflowed (NaN or infinity) although the inputs are finite: the deformation is too extreme for the model";
    case PN_ERROR_STEP_TOO_LARGE: return "time step too large: material would move more than the advection limit in one step (use a smaller step or substeps)";
    case PN_ERROR_OUTSIDE_DOMAIN: return "material would leave the simulation domain through a wall (outflow not allowed)";
    case PN_ERROR_CAPACITY: return "capacity exceeded (particles, groups or colliders)";
    case PN_RESULT_COUNT: break;
    }
    return "unknown pn_result";
}

PN__DEF void *pn_alloc(const pn_allocator *a, size_t size_bytes) {
    if (a && a->alloc) return a->alloc(size_bytes, a->user);
    return PN_MALLOC(size_bytes, a ? a->user : NULL);
}

PN__DEF void pn_free(const pn_allocator *a, void *ptr) {
    if (!ptr) return;
    if (a && a->free) {
        a->free(ptr, a->user);
        return;
    }
    PN_FREE(ptr, a ? a->user : NULL);
}

/* ======================================================================================
   >>kit: the private helpers every module shares (plastinet_mpm.h and plastinet_rom.h call
   them too): messages, a hash, quadratic B-spline weights, dense Cholesky, the
   backtracking line search, a rigid drive's motion, the substep fallback of implicit
   steps and preconditioned conjugate gradients. Written once, here; where a module needs
   one in double as well as pn_real, a PN__*_DEF macro defines it for each type.
   ====================================================================================== */
#include <stdarg.h>
#if defined(__GNUC__) || defined(__clang__)
#define PN__KIT static __attribute__((unused)) /* a build may leave a helper without a caller */
#else
#define PN__KIT static
#endif

/* A message into buf[cap] (nothing when buf is NULL or cap 0). Without stdio
   (PN_NO_STDIO) the message is the format's text up to its first conversion. */
PN__KIT void pn__vmsg(char *buf, size_t cap, const char *fmt, va_list ap) {
    if (!buf || !cap) return;
#ifndef PN_NO_STDIO
    vsnprintf(buf, cap, fmt, ap);
#else
    {
        size_t i;
        (void)ap;
        for (i = 0; fmt[i] && fmt[i] != '%' && i + 1 < cap; ++i) buf[i] = fmt[i];
        buf[i] = 0;
    }
#endif
}

PN__KIT void pn__msg(char *buf, size_t cap, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    pn__vmsg(buf, cap, fmt, ap);
    va_end(ap);
}

/* A fixed message into buf[cap], truncated (nothing when buf is NULL or cap 0) */
PN__KIT void pn__put(char *buf, size_t cap, const char *s) {
    size_t i;
    if (!buf || !cap) return;
    for (i = 0; s[i] && i + 1 < cap; ++i) buf[i] = s[i];
    buf[i] = 0;
}

/* Record why a call failed in buf and return its code r: every module's failure path.
   PN__FAIL(obj, r, ...) writes obj->error (a world's, mesh's or coupled object's). */
PN__KIT pn_result pn__fail(char *buf, size_t cap, pn_result r, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    pn__vmsg(buf, cap, fmt, ap);
    va_end(ap);
    return r;
}
#define PN__FAIL(obj, r, ...) pn__fail((obj)->error, sizeof (obj)->error, r, __VA_ARGS__)

/* The splitmix64 finalizer: a bijection of 64-bit integers whose output bits each depend on
   every input bit (random numbers: mix a counter; hashes: mix a key). */
PN__KIT unsigned long long pn__mix64(unsigned long long z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/* Quadratic B-spline weights of a stencil's three nodes, f = x/dx - base in [0.5, 1.5)
   (base = floor(x/dx - 0.5)), in arithmetic of type T */
#define PN__BSPLINE2(w0, w1, w2, f, T)                                                       \
    do {                                                                                     \
        (w0) = (T)0.5 * ((T)1.5 - (f)) * ((T)1.5 - (f));                                     \
        (w1) = (T)0.75 - ((f) - 1) * ((f) - 1);                                              \
        (w2) = (T)0.5 * ((f) - (T)0.5) * ((f) - (T)0.5);                                     \
    } while (0)

/* Dense Cholesky, in place: the lower triangle of the symmetric n x n row-major A becomes L
   with A = L L^T (the strict upper triangle is not read or written). Pivot j fails when
   s_j = A_jj - sum_k L_jk^2 is not above rel * (top > 0 ? top : A_jj) (0 when rel is 0);
   then, with held_ok and A_jj finite and >= 0, the direction is taken as held (L_jj = 1, the
   column below 0), else the factorization stops. Returns n, or the column it stopped at.
   pn__cholesky_solve: x = (L L^T)^-1 b (x may be b). Defined for pn_real and, for the
   reduced models' normal equations, double (PN__CHOLESKY_DEF below). */
#define PN__CHOLESKY_DEF(factor, solve, T, SQRT, FINITE)                                     \
    PN__KIT size_t factor(T *A, size_t n, T rel, T top, int held_ok) {                       \
        size_t i, j, k;                                                                      \
        for (j = 0; j < n; ++j) {                                                            \
            T s = A[j * n + j], s0 = s, floor_j = rel > 0 ? rel * (top > 0 ? top : s0) : 0;  \
            for (k = 0; k < j; ++k) s -= A[j * n + k] * A[j * n + k];                        \
            if (!(s > floor_j)) {                                                            \
                if (!held_ok || !(s0 >= 0) || !FINITE(s0)) return j;                         \
                A[j * n + j] = 1;                                                            \
                for (i = j + 1; i < n; ++i) A[i * n + j] = 0;                                \
                continue;                                                                    \
            }                                                                                \
            A[j * n + j] = SQRT(s);                                                          \
            for (i = j + 1; i < n; ++i) {                                                    \
                T v = A[i * n + j];                                                          \
                for (k = 0; k < j; ++k) v -= A[i * n + k] * A[j * n + k];                    \
                A[i * n + j] = v / A[j * n + j];                                             \
            }                                                                                \
        }                                                                                    \
        return n;                                                                            \
    }                                                                                        \
    PN__KIT void solve(const T *L, size_t n, const T *b, T *x) {                             \
        size_t i, k;                                                                         \
        for (i = 0; i < n; ++i) {                                                            \
            T s = b[i];                                                                      \
            for (k = 0; k < i; ++k) s -= L[i * n + k] * x[k];                                \
            x[i] = s / L[i * n + i];                                                         \
        }                                                                                    \
        for (i = n; i-- > 0;) {                                                              \
            T s = x[i];                                                                      \
            for (k = i + 1; k < n; ++k) s -= L[k * n + i] * x[k];                            \
            x[i] = s / L[i * n + i];                                                         \
        }                                                                                    \
    }
#define PN__KIT_FINITE(x) ((x) == (x) && (x) - (x) == 0)
PN__CHOLESKY_DEF(pn__cholesky, pn__cholesky_solve, pn_real, PN__SQRT, PN__KIT_FINITE)

typedef pn_result (*pn__objective_fn)(void *ctx, const pn_real *x, pn_real *E);

/* Backtracking along dir from x (Armijo): x + alpha dir for alpha = alpha0, alpha0 / 2, ..
   down to alpha_min, until f <= E0 + 1e-4 alpha gd (gd = grad . dir < 0; gd = 0: until f
   does not rise). Returns alpha, with xt and *E1 the accepted point, or 0 when no step
   decreases f. A try where f fails (an element turned inside out, a node in an obstacle, a
   non-finite energy) is no decrease. Defined for pn_real (pn__armijo) and, for the reduced
   models, double (PN__ARMIJO_DEF). */
#define PN__ARMIJO_DEF(NAME, T)                                                                \
    PN__KIT T NAME(pn_result (*f)(void *ctx, const T *x, T *E), void *ctx, size_t n, const T *x,  \
                   const T *dir, T E0, T gd, T alpha0, T alpha_min, T *xt, T *E1) {              \
        T alpha = alpha0;                                                                      \
        while (alpha >= alpha_min) {                                                           \
            T e = 0;                                                                           \
            size_t k;                                                                          \
            for (k = 0; k < n; ++k) xt[k] = x[k] + alpha * dir[k];                             \
            if (f(ctx, xt, &e) == PN_OK && e <= E0 + (T)1e-4 * alpha * gd) {                   \
                *E1 = e;                                                                       \
                return alpha;                                                                  \
            }                                                                                  \
            alpha /= 2;                                                                        \
        }                                                                                      \
        return 0;                                                                              \
    }
PN__ARMIJO_DEF(pn__armijo, pn_real)

/* Newton's predicted decrease -gd (gd = grad . dir) is below the rounding of an energy of
   size E0 summed in precision eps: the values can no longer judge a step (near the minimum
   of a large energy) */
PN__KIT int pn__unresolved(pn_real gd, pn_real E0, pn_real eps) { return -gd <= (pn_real)1e3 * eps * PN__FABS(E0); }

/* Newton's stop without one more solve: after a full step of size step (a norm of the
   update), the last full step's size prev (0: none) gives the contraction theta =
   step / prev; once Newton contracts fast (theta <= 0.1: quadratic convergence near the
   minimum; a kinked energy's linear phases stay above), what is left of the error is at most
   theta / (1 - theta) step, the steps still to come summed at that rate (Deuflhard's error
   estimate; quadratic convergence only shrinks them faster). Converged when that is at most
   tol: *left gets it. The solve that would have measured the next step is saved. */
PN__KIT int pn__newton_done(pn_real step, pn_real prev, pn_real tol, pn_real *left) {
    pn_real theta;
    if (!(prev > 0)) return 0;
    theta = step / prev;
    if (!(theta <= (pn_real)0.1)) return 0;
    *left = theta / (1 - theta) * step;
    return *left <= tol;
}

/* A rigid drive's motion (particles held, translated and spun; MPM's and the reduced models'
   drives, whose struct D has center, vel, omega and t0): at(D, d, t, x0, c, x) gives the
   centre c(t) = center + (t - t0) vel and, unless x is NULL, where a point that was at x0 at
   t0 is at t (Rodrigues: rotation by |omega| (t - t0) about omega); vel(D, d, c, x, v) the
   velocity vel + omega x (x - c) at x. Defined per drive and real type (PN__RIGID_DEF). */
#define PN__RIGID_DEF(AT, VEL, D_T, T, SQRT, COS, SIN)                                         \
    PN__KIT void AT(const D_T *D, int d, T t, const T *x0, T *c, T *x) {                      \
        T s = t - D->t0, r[3] = {0, 0, 0}, wn = 0, k[3] = {0, 0, 0}, th, cs, sn, kr, kx[3];    \
        int i;                                                                                 \
        for (i = 0; i < 3; ++i) c[i] = D->center[i] + s * D->vel[i];                           \
        if (!x) return;                                                                        \
        for (i = 0; i < d; ++i) r[i] = x0[i] - D->center[i];                                   \
        for (i = 0; i < 3; ++i) wn += D->omega[i] * D->omega[i];                               \
        wn = SQRT(wn);                                                                         \
        if (!(wn > 0)) {                                                                       \
            for (i = 0; i < d; ++i) x[i] = c[i] + r[i];                                        \
            return;                                                                            \
        }                                                                                      \
        for (i = 0; i < 3; ++i) k[i] = D->omega[i] / wn;                                       \
        th = wn * s, cs = COS(th), sn = SIN(th);                                               \
        kr = k[0] * r[0] + k[1] * r[1] + k[2] * r[2];                                          \
        kx[0] = k[1] * r[2] - k[2] * r[1], kx[1] = k[2] * r[0] - k[0] * r[2];                  \
        kx[2] = k[0] * r[1] - k[1] * r[0];                                                     \
        for (i = 0; i < d; ++i) x[i] = c[i] + r[i] * cs + kx[i] * sn + k[i] * kr * (1 - cs);   \
    }                                                                                          \
    PN__KIT void VEL(const D_T *D, int d, const T *c, const T *x, T *v) {                     \
        T r[3] = {0, 0, 0};                                                                    \
        int i;                                                                                 \
        for (i = 0; i < d; ++i) r[i] = x[i] - c[i];                                            \
        v[0] = D->vel[0] + D->omega[1] * r[2] - D->omega[2] * r[1];                            \
        v[1] = D->vel[1] + D->omega[2] * r[0] - D->omega[0] * r[2];                            \
        if (d == 3) v[2] = D->vel[2] + D->omega[0] * r[1] - D->omega[1] * r[0];                \
    }

/* The substep fallback of every implicit step, with one rule. try_step(ctx, n) takes the step
   as n equal substeps: 1, then 2, 4, .. 2^max_halvings (max_halvings <= 0: the whole step
   only); after each failed try undo(ctx, n) puts the state back as it was before the step;
   keep_first(ctx), after the first failure, sets its message and statistics aside (the
   caller restores them: the first failure says why the step failed, the smaller steps only
   that halving did not help); stop(ctx, n) (optional) ends the halving early. Returns PN_OK
   from the first try that works, else the first try's code. */
typedef struct pn__halving {
    void *ctx;
    pn_result (*try_step)(void *ctx, int n_sub);
    void (*undo)(void *ctx, int n_sub);
    void (*keep_first)(void *ctx);
    int (*stop)(void *ctx, int n_sub);
} pn__halving;

PN__KIT pn_result pn__halve(const pn__halving *h, int max_halvings) {
    pn_result first = PN_OK, r;
    int level, top = max_halvings > 0 ? max_halvings : 0;
    for (level = 0; level <= top; ++level) {
        if ((r = h->try_step(h->ctx, 1 << level)) == PN_OK) return PN_OK;
        h->undo(h->ctx, 1 << level);
        if (level == 0) {
            first = r;
            if (h->keep_first) h->keep_first(h->ctx);
        }
        if (h->stop && h->stop(h->ctx, 1 << level)) break;
    }
    return first;
}

/* tail appended to the message in buf[cap] when it fits whole */
PN__KIT void pn__append(char *buf, size_t cap, const char *tail) {
    size_t len = strlen(buf), n = strlen(tail);
    if (len + n < cap) memcpy(buf + len, tail, n + 1);
}

/* What preconditioned CG needs of a solver: y = A x, z = B r, and a dot product (MPM sums in
   fixed chunks so that any thread count gives the same bits). */
typedef struct pn__cg_ops {
    void *ctx;
    void (*apply)(void *ctx, const pn_real *x, pn_real *y);
    void (*precond)(void *ctx, const pn_real *r, pn_real *z);
    pn_real (*dot)(void *ctx, size_t n, const pn_real *a, const pn_real *b);
    int *curv;                   /* optional: set to 1 where a direction of curvature <= 0
                                    stopped the iteration (A is not positive definite)      */
} pn__cg_ops;

/* Solve A x = b by preconditioned conjugate gradients to |r| <= rel_tol |b|, b given in r
   (overwritten by the residual); z, p and q are scratch. warm: start from x (r = b - A x),
   else from 0. Returns the iterations; *capped when it stopped at max_it short of rel_tol
   (then x is no solution: never count it as converged). */
PN__KIT int pn__pcg(const pn__cg_ops *op, size_t n, pn_real *x, pn_real *r, pn_real *z, pn_real *p, pn_real *q, int max_it,
                   pn_real rel_tol, int warm, int *capped) {
    pn_real rz, r0, rr;
    size_t k;
    int it;
    *capped = 0;
    if (warm) op->apply(op->ctx, x, q);
    else
        for (k = 0; k < n; ++k) x[k] = 0;
    r0 = PN__SQRT(op->dot(op->ctx, n, r, r)); /* |b| */
    if (warm)
        for (k = 0; k < n; ++k) r[k] -= q[k];
    op->precond(op->ctx, r, z);
    memcpy(p, z, sizeof(pn_real) * n);
    rz = op->dot(op->ctx, n, r, z);
    if (r0 == 0) return 0;
    if (PN__SQRT(op->dot(op->ctx, n, r, r)) <= rel_tol * r0) return 0;
    for (it = 0; it < max_it; ++it) {
        pn_real pq, alpha, rz_new, beta;
        op->apply(op->ctx, p, q);
        pq = op->dot(op->ctx, n, p, q);
        if (!(pq > 0)) { /* A positive definite: only rounding gets here */
            if (op->curv) *op->curv = 1;
            break;
        }
        alpha = rz / pq;
        for (k = 0; k < n; ++k) {
            x[k] += alpha * p[k];
            r[k] -= alpha * q[k];
        }
        rr = PN__SQRT(op->dot(op->ctx, n, r, r));
        if (rr <= rel_tol * r0) return it + 1;
        op->precond(op->ctx, r, z);
        rz_new = op->dot(op->ctx, n, r, z);
        beta = rz_new / rz;
        rz = rz_new;
        for (k = 0; k < n; ++k) p[k] = z[k] + beta * p[k];
    }
    *capped = it == max_it;
    return it;
}

/* ======================================================================================
   >>matrix: dense dim x dim helpers (row-major)
   ====================================================================================== */

PN__DEF pn_real pn_mat_det(int d, const pn_real *A) {
    if (d == 2) return A[0] * A[3] - A[1] * A[2];
    return A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) +
           A[2] * (A[3] * A[7] - A[4] * A[6]);
}

PN__DEF pn_result pn_mat_inverse(int d, const pn_real *A, pn_real *Ai) {
    pn_real det, c[9];
    int i;
    if (!pn__dim_ok(d)) return PN_ERROR_DIMENSION;
    if (!pn__all_finite(d * d, A)) return PN_ERROR_NONFINITE;
    det = pn_mat_det(d, A);
    if (det == 0 || !pn__finite(det)) return PN_ERROR_INVERTED;
    if (d == 2) {
        c[0] = A[3]; c[1] = -A[1]; c[2] = -A[2]; c[3] = A[0];
    } else { /* adjugate = transposed cofactors */
        c[0] = A[4] * A[8] - A[5] * A[7]; c[1] = A[2] * A[7] - A[1] * A[8]; c[2] = A[1] * A[5] - A[2] * A[4];
        c[3] = A[5] * A[6] - A[3] * A[8]; c[4] = A[0] * A[8] - A[2] * A[6]; c[5] = A[2] * A[3] - A[0] * A[5];
        c[6] = A[3] * A[7] - A[4] * A[6]; c[7] = A[1] * A[6] - A[0] * A[7]; c[8] = A[0] * A[4] - A[1] * A[3];
    }
    for (i = 0; i < d * d; ++i) c[i] /= det;
    if (!pn__all_finite(d * d, c)) return PN_ERROR_INVERTED;
    memcpy(Ai, c, sizeof(pn_real) * (size_t)(d * d));
    return PN_OK;
}

PN__DEF void pn_mat_mul(int d, const pn_real *A, const pn_real *B, pn_real *C) {
    int i, j, k;
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) {
            pn_real acc = 0;
            for (k = 0; k < d; ++k) acc += A[i * d + k] * B[k * d + j];
            C[i * d + j] = acc;
        }
}

/* out = U diag(w) V^T */
static void pn__udvt(int d, const pn_real *U, const pn_real *w, const pn_real *V, pn_real *out) {
    int i, j, k;
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) {
            pn_real acc = 0;
            for (k = 0; k < d; ++k) acc += U[i * d + k] * w[k] * V[j * d + k];
            out[i * d + j] = acc;
        }
}

static void pn__identity(int d, pn_real *A) {
    int i;
    for (i = 0; i < d * d; ++i) A[i] = 0;
    for (i = 0; i < d; ++i) A[i * d + i] = 1;
}

/* ======================================================================================
   >>svd: one-sided (Hestenes) Jacobi on the columns of F.
   Rotating columns of B = F V until they are mutually orthogonal gives singular values with
   high relative accuracy even when they differ by many orders of magnitude, and U columns
   b_i / |b_i| orthogonal to working precision (the convergence test is relative to the
   column norms). F is scaled by its largest entry first so squares never overflow.
   ====================================================================================== */

static void pn__swap_cols(int d, pn_real *A, int p, int q) {
    int i;
    for (i = 0; i < d; ++i) {
        pn_real t = A[i * d + p];
        A[i * d + p] = A[i * d + q];
        A[i * d + q] = t;
    }
}

/* 2x2 in closed form (the hot path of 2D MPM): the polar rotation R of F from
   (F00 + F11, F10 - F01), then the one Jacobi rotation J that diagonalizes the symmetric
   S = R^T F, so F = (R J) diag(l) J^T. l_0 + l_1 = tr S >= 0; the smaller one is det F / l_0
   (relative accuracy where F is nearly singular). Same conventions as the Jacobi path. */
static void pn__svd2(const pn_real *F, pn_real *U, pn_real *s, pn_real *V) {
    pn_real a, b, c, e, x, y, r, cs, sn, s00, s01, s11, cj, sj, l0, l1, det, scale = 0;
    int i;
    for (i = 0; i < 4; ++i) scale = PN__MAX(scale, PN__FABS(F[i]));
    if (!(scale > 0) || !pn__finite(scale)) { /* zero (or not finite: the callers check F) */
        U[0] = U[3] = V[0] = V[3] = 1;
        U[1] = U[2] = V[1] = V[2] = 0;
        s[0] = s[1] = scale == 0 ? 0 : scale - scale;
        return;
    }
    /* squares stay normal and finite for entries in [2^-30, 2^30]: scale only outside */
    if (scale > (pn_real)1073741824.0 || scale < (pn_real)9.3132257461547852e-10) {
        pn_real inv = 1 / scale;
        a = F[0] * inv, b = F[1] * inv, c = F[2] * inv, e = F[3] * inv;
    } else {
        scale = 1;
        a = F[0], b = F[1], c = F[2], e = F[3];
    }
    x = a + e;
    y = c - b;
    r = PN__SQRT(x * x + y * y);
    if (r > 0) {
        pn_real ir = 1 / r;
        cs = x * ir, sn = y * ir;
    } else {
        cs = 1, sn = 0; /* F is a scaled reflection: already symmetric */
    }
    s00 = cs * a + sn * c;
    s01 = cs * b + sn * e;
    s11 = cs * e - sn * b;
    if (s01 != 0) {
        pn_real zeta = (s11 - s00) / (2 * s01), t;
        if (PN__FABS(zeta) > 1 / PN__EPS) t = 1 / (2 * zeta);
        else t = (zeta >= 0 ? 1 : -1) / (PN__FABS(zeta) + PN__SQRT(1 + zeta * zeta));
        cj = 1 / PN__SQRT(1 + t * t);
        sj = t * cj;
        l0 = s00 - t * s01;
        l1 = s11 + t * s01;
    } else {
        cj = 1, sj = 0, l0 = s00, l1 = s11;
    }
    /* V = J = [cj sj; -sj cj]; order descending (a swap with one column negated keeps det +1) */
    if (l0 >= l1) {
        V[0] = cj, V[1] = sj, V[2] = -sj, V[3] = cj;
    } else {
        pn_real t = l0;
        l0 = l1, l1 = t;
        V[0] = sj, V[1] = -cj, V[2] = cj, V[3] = sj;
    }
    det = a * e - b * c;
    if (l0 > 0) l1 = det / l0;
    if (PN__FABS(l1) > l0) l1 = l1 < 0 ? -l0 : l0; /* l0 >= |l1| exactly (tr S >= 0), not only up to rounding */
    U[0] = cs * V[0] - sn * V[2], U[1] = cs * V[1] - sn * V[3];
    U[2] = sn * V[0] + cs * V[2], U[3] = sn * V[1] + cs * V[3];
    s[0] = l0 * scale;
    s[1] = l1 * scale;
}

static void pn__svd(int d, const pn_real *F, pn_real *U, pn_real *s, pn_real *V) {
    pn_real B[9], scale = 0, eps = PN__EPS, tiny;
    int i, j, p, q, sweep;
    if (d == 2) {
        pn__svd2(F, U, s, V);
        return;
    }
    for (i = 0; i < d * d; ++i) scale = PN__MAX(scale, PN__FABS(F[i]));
    pn__identity(d, V);
    if (scale == 0) {
        pn__identity(d, U);
        for (i = 0; i < d; ++i) s[i] = 0;
        return;
    }
    for (i = 0; i < d * d; ++i) B[i] = F[i] / scale;
    for (sweep = 0; sweep < 40; ++sweep) {
        int rotated = 0;
        for (p = 0; p < d - 1; ++p)
            for (q = p + 1; q < d; ++q) {
                pn_real alpha = 0, beta = 0, gamma = 0, zeta, t, c, sn;
                for (i = 0; i < d; ++i) {
                    alpha += B[i * d + p] * B[i * d + p];
                    beta += B[i * d + q] * B[i * d + q];
                    gamma += B[i * d + p] * B[i * d + q];
                }
                if (PN__FABS(gamma) <= eps * PN__SQRT(alpha * beta)) continue;
                rotated = 1;
                /* t = tan of the angle that zeroes b_p . b_q: root of t^2 + 2 zeta t - 1 = 0 */
                zeta = (beta - alpha) / (2 * gamma);
                if (PN__FABS(zeta) > 1 / eps)
                    t = 1 / (2 * zeta);
                else
                    t = (zeta >= 0 ? 1 : -1) / (PN__FABS(zeta) + PN__SQRT(1 + zeta * zeta));
                c = 1 / PN__SQRT(1 + t * t);
                sn = c * t;
                for (i = 0; i < d; ++i) {
                    pn_real bp = B[i * d + p], bq = B[i * d + q];
                    pn_real vp = V[i * d + p], vq = V[i * d + q];
                    B[i * d + p] = c * bp - sn * bq;
                    B[i * d + q] = sn * bp + c * bq;
                    V[i * d + p] = c * vp - sn * vq;
                    V[i * d + q] = sn * vp + c * vq;
                }
            }
        if (!rotated) break;
    }
    for (j = 0; j < d; ++j) {
        pn_real n2 = 0;
        for (i = 0; i < d; ++i) n2 += B[i * d + j] * B[i * d + j];
        s[j] = PN__SQRT(n2);
    }
    /* sort descending; a swap of two columns is a reflection, so negate one to keep det V */
    for (p = 0; p < d - 1; ++p)
        for (q = 0; q < d - 1 - p; ++q)
            if (s[q] < s[q + 1]) {
                pn_real t = s[q];
                s[q] = s[q + 1];
                s[q + 1] = t;
                pn__swap_cols(d, B, q, q + 1);
                pn__swap_cols(d, V, q, q + 1);
                for (i = 0; i < d; ++i) {
                    B[i * d + q] = -B[i * d + q];
                    V[i * d + q] = -V[i * d + q];
                }
            }
    /* U: normalized columns; columns negligible against s_0 (zero, or below eps^2 s_0 where
       their direction is noise) are completed to a rotation instead */
    tiny = s[0] * eps * eps;
    for (j = 0; j < d; ++j) {
        if (s[j] > tiny)
            for (i = 0; i < d; ++i) U[i * d + j] = B[i * d + j] / s[j];
    }
    if (d == 2) {
        if (!(s[1] > tiny)) {
            U[1] = -U[2];
            U[3] = U[0];
        }
    } else {
        if (!(s[1] > tiny)) { /* any unit vector orthogonal to u0 */
            pn_real a = U[0], b = U[3], c = U[6], n;
            if (PN__FABS(a) <= PN__FABS(b) && PN__FABS(a) <= PN__FABS(c)) {
                U[1] = 0; U[4] = -c; U[7] = b;
            } else if (PN__FABS(b) <= PN__FABS(c)) {
                U[1] = -c; U[4] = 0; U[7] = a;
            } else {
                U[1] = -b; U[4] = a; U[7] = 0;
            }
            n = PN__SQRT(U[1] * U[1] + U[4] * U[4] + U[7] * U[7]);
            U[1] /= n; U[4] /= n; U[7] /= n;
        }
        if (!(s[2] > tiny)) { /* u2 = u0 x u1 */
            U[2] = U[3] * U[7] - U[6] * U[4];
            U[5] = U[6] * U[1] - U[0] * U[7];
            U[8] = U[0] * U[4] - U[3] * U[1];
        }
    }
    /* rotations only: V is a product of rotations and sign-fixed swaps (det +1); a reflection
       left in U means det F < 0, carried by the smallest singular value */
    if (pn_mat_det(d, U) < 0) {
        for (i = 0; i < d; ++i) U[i * d + d - 1] = -U[i * d + d - 1];
        s[d - 1] = -s[d - 1];
    }
    for (i = 0; i < d; ++i) s[i] *= scale;
}

PN__DEF pn_result pn_svd(int d, const pn_real *F, pn_real *U, pn_real *s, pn_real *V) {
    pn_real u[9], w[3], v[9];
    if (!pn__dim_ok(d)) return PN_ERROR_DIMENSION;
    if (!pn__all_finite(d * d, F)) return PN_ERROR_NONFINITE;
    pn__svd(d, F, u, w, v);
    memcpy(U, u, sizeof(pn_real) * (size_t)(d * d));
    memcpy(s, w, sizeof(pn_real) * (size_t)d);
    memcpy(V, v, sizeof(pn_real) * (size_t)(d * d));
    return PN_OK;
}

PN__DEF pn_result pn_polar(int d, const pn_real *F, pn_real *R, pn_real *S) {
    pn_real U[9], s[3], V[9], one[3] = {1, 1, 1}, r[9], st[9];
    if (!pn__dim_ok(d)) return PN_ERROR_DIMENSION;
    if (!pn__all_finite(d * d, F)) return PN_ERROR_NONFINITE;
    pn__svd(d, F, U, s, V);
    pn__udvt(d, U, one, V, r);
    pn__udvt(d, V, s, V, st);
    memcpy(R, r, sizeof(pn_real) * (size_t)(d * d));
    memcpy(S, st, sizeof(pn_real) * (size_t)(d * d));
    return PN_OK;
}

PN__DEF pn_result pn_hencky_strain(int d, const pn_real *F, pn_real *eps) {
    pn_real U[9], s[3], V[9], e[3], out[9];
    int i;
    if (!pn__dim_ok(d)) return PN_ERROR_DIMENSION;
    if (!pn__all_finite(d * d, F)) return PN_ERROR_NONFINITE;
    pn__svd(d, F, U, s, V);
    if (!(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    for (i = 0; i < d; ++i) e[i] = PN__LOG(s[i]);
    pn__udvt(d, U, e, U, out);
    memcpy(eps, out, sizeof(pn_real) * (size_t)(d * d));
    return PN_OK;
}

/* ======================================================================================
   >>eigen: cyclic Jacobi for small symmetric matrices, and the PSD projection
   ====================================================================================== */

/* A (n x n, overwritten) = Q diag(w) Q^T, w ascending. */
#define PN__SYM_MAX 12 /* pn_sym_eigen, pn_sym_project_psd: the largest n */
static void pn__jacobi_eigen(int n, pn_real *A, pn_real *Q, pn_real *w) {
    pn_real norm = 0;
    int i, j, p, q, k, sweep;
    for (i = 0; i < n * n; ++i) norm += A[i] * A[i];
    norm = PN__SQRT(norm);
    for (i = 0; i < n * n; ++i) Q[i] = 0;
    for (i = 0; i < n; ++i) Q[i * n + i] = 1;
    for (sweep = 0; sweep < 60 && norm > 0; ++sweep) {
        int rotated = 0;
        for (p = 0; p < n - 1; ++p)
            for (q = p + 1; q < n; ++q) {
                pn_real apq = A[p * n + q], theta, t, c, s;
                if (PN__FABS(apq) <= PN__EPS * 1e-2 * norm) {
                    A[p * n + q] = A[q * n + p] = 0;
                    continue;
                }
                rotated = 1;
                /* J^T A J zeroes A_pq when t = tan satisfies t^2 + 2 theta t - 1 = 0 */
                theta = (A[q * n + q] - A[p * n + p]) / (2 * apq);
                if (PN__FABS(theta) > 1 / PN__EPS)
                    t = 1 / (2 * theta);
                else
                    t = (theta >= 0 ? 1 : -1) / (PN__FABS(theta) + PN__SQRT(theta * theta + 1));
                c = 1 / PN__SQRT(t * t + 1);
                s = t * c;
                for (k = 0; k < n; ++k) { /* A J */
                    pn_real akp = A[k * n + p], akq = A[k * n + q];
                    A[k * n + p] = c * akp - s * akq;
                    A[k * n + q] = s * akp + c * akq;
                }
                for (k = 0; k < n; ++k) { /* J^T (A J) */
                    pn_real apk = A[p * n + k], aqk = A[q * n + k];
                    A[p * n + k] = c * apk - s * aqk;
                    A[q * n + k] = s * apk + c * aqk;
                }
                A[p * n + q] = A[q * n + p] = 0;
                for (k = 0; k < n; ++k) { /* Q J */
                    pn_real qkp = Q[k * n + p], qkq = Q[k * n + q];
                    Q[k * n + p] = c * qkp - s * qkq;
                    Q[k * n + q] = s * qkp + c * qkq;
                }
            }
        if (!rotated) break;
    }
    for (i = 0; i < n; ++i) w[i] = A[i * n + i];
    for (i = 0; i < n - 1; ++i) /* selection sort, ascending */
        for (j = i + 1; j < n; ++j)
            if (w[j] < w[i]) {
                pn_real t = w[i];
                w[i] = w[j];
                w[j] = t;
                for (k = 0; k < n; ++k) {
                    t = Q[k * n + i];
                    Q[k * n + i] = Q[k * n + j];
                    Q[k * n + j] = t;
                }
            }
}

PN__DEF pn_result pn_sym_eigen(int n, const pn_real *A, pn_real *Q, pn_real *w) {
    pn_real a[PN__SYM_MAX * PN__SYM_MAX], q[PN__SYM_MAX * PN__SYM_MAX], ww[PN__SYM_MAX];
    int i, j;
    if (n < 1 || n > PN__SYM_MAX) return PN_ERROR_INVALID_ARGUMENT;
    for (i = 0; i < n; ++i)
        for (j = i; j < n; ++j) {
            if (!pn__finite(A[i * n + j])) return PN_ERROR_NONFINITE;
            a[i * n + j] = a[j * n + i] = A[i * n + j];
        }
    pn__jacobi_eigen(n, a, q, ww);
    memcpy(Q, q, sizeof(pn_real) * (size_t)(n * n));
    memcpy(w, ww, sizeof(pn_real) * (size_t)n);
    return PN_OK;
}

/* A <- Q max(w, 0) Q^T (only the upper part of A is read) */
static void pn__project_psd(int n, pn_real *A) {
    pn_real a[PN__SYM_MAX * PN__SYM_MAX], q[PN__SYM_MAX * PN__SYM_MAX], w[PN__SYM_MAX], top = 0;
    int i, j, k, pd = 1;
    for (i = 0; i < n; ++i) {
        for (j = i; j < n; ++j) a[i * n + j] = a[j * n + i] = A[i * n + j];
        top = PN__MAX(top, PN__FABS(A[i * n + i]));
    }
    memcpy(q, a, sizeof(pn_real) * (size_t)(n * n)); /* Cholesky first: a positive definite A is its own projection */
    pd = pn__cholesky(q, (size_t)n, (pn_real)1e-12, top, 0) == (size_t)n;
    if (pd) {
        for (i = 0; i < n; ++i)
            for (j = 0; j < i; ++j) A[i * n + j] = A[j * n + i]; /* symmetric from the upper part, as below */
        return;
    }
    pn__jacobi_eigen(n, a, q, w);
    for (i = 0; i < n; ++i)
        for (j = i; j < n; ++j) {
            pn_real acc = 0;
            for (k = 0; k < n; ++k)
                if (w[k] > 0) acc += q[i * n + k] * w[k] * q[j * n + k];
            A[i * n + j] = A[j * n + i] = acc;
        }
}

PN__DEF pn_result pn_sym_project_psd(int n, pn_real *A) {
    int i, j;
    if (n < 1 || n > PN__SYM_MAX) return PN_ERROR_INVALID_ARGUMENT;
    for (i = 0; i < n; ++i)
        for (j = i; j < n; ++j)
            if (!pn__finite(A[i * n + j])) return PN_ERROR_NONFINITE;
    pn__project_psd(n, A);
    return PN_OK;
}

/* ======================================================================================
   >>material: validation and derived constants
   ====================================================================================== */

PN__DEF pn_result pn_lame(pn_real E, pn_real nu, pn_real *mu, pn_real *lambda) {
    if (!pn__finite(E) || !pn__finite(nu)) return PN_ERROR_NONFINITE;
    if (!(E > 0) || !(nu > -1) || !(nu < (pn_real)0.5)) return PN_ERROR_INVALID_PARAMETER;
    *mu = E / (2 * (1 + nu));
    *lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
    return PN_OK;
}

static const char *const pn__elastic_names[] = {"default", "fixed_corotated", "stvk_hencky",
                                                "neo_hookean", "neo_hookean_snow"};
static const char *const pn__plastic_names[] = {"none", "drucker_prager", "von_mises", "cam_clay",
                                                "snow_stomakhin"};

PN__DEF const char *pn_elastic_model_name(pn_elastic_model e) {
    return ((int)e >= 0 && e < PN_ELASTIC_MODEL_COUNT) ? pn__elastic_names[e] : "unknown";
}
PN__DEF const char *pn_plastic_model_name(pn_plastic_model p) {
    return ((int)p >= 0 && p < PN_PLASTIC_MODEL_COUNT) ? pn__plastic_names[p] : "unknown";
}
PN__DEF int pn_elastic_model_from_name(const char *name) {
    int i;
    for (i = 0; name && i < (int)PN_ELASTIC_MODEL_COUNT; ++i)
        if (!strcmp(name, pn__elastic_names[i])) return i;
    return -1;
}
PN__DEF int pn_plastic_model_from_name(const char *name) {
    int i;
    for (i = 0; name && i < (int)PN_PLASTIC_MODEL_COUNT; ++i)
        if (!strcmp(name, pn__plastic_names[i])) return i;
    return -1;
}

#define PN__REFUSE(code, msg)                                                                 \
    do {                                                                                    \
        if (why) *why = msg;                                                                \
        return code;                                                                        \
    } while (0)

static pn_result pn__material_init_why(pn_material *out, const pn_material_desc *desc,
                                   const char **why) {
    pn_material m;
    const pn_material_desc *dd = desc;
    PN_ASSERT(out && desc);
    memset(&m, 0, sizeof m);
    if ((int)dd->plastic < 0 || dd->plastic >= PN_PLASTIC_MODEL_COUNT)
        PN__REFUSE(PN_ERROR_INVALID_ARGUMENT, "plastic: unknown plastic model");
    if ((int)dd->elastic < 0 || dd->elastic >= PN_ELASTIC_MODEL_COUNT)
        PN__REFUSE(PN_ERROR_INVALID_ARGUMENT, "elastic: unknown elastic model");
    m.plastic = dd->plastic;
    m.elastic = dd->elastic;
    if (m.elastic == PN_ELASTIC_DEFAULT) {
        switch (m.plastic) {
        case PN_PLASTIC_DRUCKER_PRAGER:
        case PN_PLASTIC_VON_MISES: m.elastic = PN_ELASTIC_STVK_HENCKY; break;
        case PN_PLASTIC_CAM_CLAY: m.elastic = PN_ELASTIC_NEO_HOOKEAN_SNOW; break;
        default: m.elastic = PN_ELASTIC_FIXED_COROTATED; break;
        }
    }
    if (!pn__finite(dd->youngs_modulus_pa) || !(dd->youngs_modulus_pa > 0))
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "youngs_modulus_pa must be finite and > 0");
    if (!pn__finite(dd->poisson_ratio) || !(dd->poisson_ratio > -1) ||
        !(dd->poisson_ratio < (pn_real)0.5))
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "poisson_ratio must be in (-1, 0.5)");
    m.E = dd->youngs_modulus_pa;
    m.nu = dd->poisson_ratio;
    pn_lame(m.E, m.nu, &m.mu, &m.lambda);
    switch (m.plastic) {
    case PN_PLASTIC_NONE: break;
    case PN_PLASTIC_DRUCKER_PRAGER:
        if (m.elastic != PN_ELASTIC_STVK_HENCKY)
            PN__REFUSE(PN_ERROR_UNSUPPORTED, "drucker_prager needs stvk_hencky elasticity");
        if (!pn__finite(dd->friction_angle_deg) || !(dd->friction_angle_deg >= 0) ||
            !(dd->friction_angle_deg < 90))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "friction_angle_deg must be in [0, 90)");
        if (!pn__finite(dd->cohesion_strain) || !(dd->cohesion_strain >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "cohesion_strain must be finite and >= 0");
        m.sin_phi = PN__SIN(dd->friction_angle_deg * PN__PI / 180);
        m.cohesion_strain = dd->cohesion_strain;
        m.volume_correction = dd->volume_correction != 0;
        break;
    case PN_PLASTIC_VON_MISES:
        if (!pn__finite(dd->yield_stress_pa) || !(dd->yield_stress_pa > 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "yield_stress_pa must be finite and > 0");
        if (!pn__finite(dd->hardening_modulus_pa) || !(dd->hardening_modulus_pa >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "hardening_modulus_pa must be finite and >= 0");
        m.yield_stress = dd->yield_stress_pa;
        m.hardening_modulus = dd->hardening_modulus_pa;
        break;
    case PN_PLASTIC_CAM_CLAY:
        if (m.elastic != PN_ELASTIC_NEO_HOOKEAN_SNOW)
            PN__REFUSE(PN_ERROR_UNSUPPORTED, "cam_clay needs neo_hookean_snow elasticity");
        if (!pn__finite(dd->friction_angle_deg) || !(dd->friction_angle_deg > 0) ||
            !(dd->friction_angle_deg < 90))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "friction_angle_deg must be in (0, 90) for cam_clay");
        if (!pn__finite(dd->camclay_beta) || !(dd->camclay_beta >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "camclay_beta must be finite and >= 0");
        if (!pn__finite(dd->camclay_xi) || !(dd->camclay_xi >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "camclay_xi must be finite and >= 0");
        m.sin_phi = PN__SIN(dd->friction_angle_deg * PN__PI / 180);
        m.beta = dd->camclay_beta;
        m.xi = dd->camclay_xi;
        m.camclay_hardening = !dd->camclay_no_hardening;
        break;
    case PN_PLASTIC_SNOW_STOMAKHIN:
        if (!pn__finite(dd->snow_theta_c) || !(dd->snow_theta_c > 0) || !(dd->snow_theta_c < 1))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "snow_theta_c must be in (0, 1)");
        if (!pn__finite(dd->snow_theta_s) || !(dd->snow_theta_s >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "snow_theta_s must be finite and >= 0");
        if (!pn__finite(dd->snow_xi) || !(dd->snow_xi >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "snow_xi must be finite and >= 0");
        if (!pn__finite(dd->snow_jp_min) || !(dd->snow_jp_min >= 0 && dd->snow_jp_min < 1))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "snow_jp_min must be in (0, 1), or 0 for no bound");
        if (!pn__finite(dd->snow_jp_max) || !(dd->snow_jp_max == 0 || dd->snow_jp_max > 1))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "snow_jp_max must be > 1, or 0 for no bound");
        m.theta_c = dd->snow_theta_c;
        m.theta_s = dd->snow_theta_s;
        m.snow_xi = dd->snow_xi;
        m.snow_h_min = dd->snow_jp_min > 0 ? PN__LOG(dd->snow_jp_min) : 0;
        m.snow_h_max = dd->snow_jp_max > 0 ? PN__LOG(dd->snow_jp_max) : 0;
        break;
    default: break;
    }
    *out = m;
    return PN_OK;
}

PN__DEF pn_result pn_material_init(pn_material *m, const pn_material_desc *desc, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__material_init_why(m, desc, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}

static pn_result pn__material_check_why(const pn_material *m, const char **why) {
    pn_real mu, lambda;
    PN_ASSERT(m);
    if ((int)m->plastic < 0 || m->plastic >= PN_PLASTIC_MODEL_COUNT)
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.plastic: unknown plastic model");
    if ((int)m->elastic <= 0 || m->elastic >= PN_ELASTIC_MODEL_COUNT)
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.elastic: unknown elastic model (use pn_material_init)");
    if (!pn__finite(m->E) || !(m->E > 0))
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.E must be finite and > 0");
    if (!pn__finite(m->nu) || !(m->nu > -1) || !(m->nu < (pn_real)0.5))
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.nu must be in (-1, 0.5)");
    pn_lame(m->E, m->nu, &mu, &lambda);
    if (!(PN__FABS(m->mu - mu) <= (pn_real)1e-6 * mu) ||
        !(PN__FABS(m->lambda - lambda) <= (pn_real)1e-6 * (PN__FABS(lambda) + mu)))
        PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.mu and lambda disagree with E and nu (use pn_material_init)");
    switch (m->plastic) {
    case PN_PLASTIC_DRUCKER_PRAGER:
        if (m->elastic != PN_ELASTIC_STVK_HENCKY)
            PN__REFUSE(PN_ERROR_UNSUPPORTED, "drucker_prager needs stvk_hencky elasticity");
        if (!pn__finite(m->sin_phi) || !(m->sin_phi >= 0) || !(m->sin_phi < 1))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.sin_phi must be in [0, 1)");
        if (!pn__finite(m->cohesion_strain) || !(m->cohesion_strain >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.cohesion_strain must be finite and >= 0");
        break;
    case PN_PLASTIC_VON_MISES:
        if (!pn__finite(m->yield_stress) || !(m->yield_stress > 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.yield_stress must be finite and > 0");
        if (!pn__finite(m->hardening_modulus) || !(m->hardening_modulus >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.hardening_modulus must be finite and >= 0");
        break;
    case PN_PLASTIC_CAM_CLAY:
        if (m->elastic != PN_ELASTIC_NEO_HOOKEAN_SNOW)
            PN__REFUSE(PN_ERROR_UNSUPPORTED, "cam_clay needs neo_hookean_snow elasticity");
        if (!pn__finite(m->sin_phi) || !(m->sin_phi > 0) || !(m->sin_phi < 1))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.sin_phi must be in (0, 1) for cam_clay");
        if (!pn__finite(m->beta) || !(m->beta >= 0) || !pn__finite(m->xi) || !(m->xi >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.beta and xi must be finite and >= 0");
        break;
    case PN_PLASTIC_SNOW_STOMAKHIN:
        if (!pn__finite(m->theta_c) || !(m->theta_c > 0) || !(m->theta_c < 1) ||
            !pn__finite(m->theta_s) || !(m->theta_s >= 0) || !pn__finite(m->snow_xi) || !(m->snow_xi >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.theta_c must be in (0, 1), theta_s and snow_xi >= 0");
        if (!pn__finite(m->snow_h_min) || !(m->snow_h_min <= 0) || !pn__finite(m->snow_h_max) || !(m->snow_h_max >= 0))
            PN__REFUSE(PN_ERROR_INVALID_PARAMETER, "material.snow_h_min must be <= 0 and snow_h_max >= 0 (log J_p "
                                                 "bounds, 0: none)");
        break;
    default: break;
    }
    return PN_OK;
}

PN__DEF pn_result pn_material_check(const pn_material *m, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__material_check_why(m, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}
#undef PN__REFUSE

#ifndef PN_NO_STDIO
PN__DEF int pn_material_describe(const pn_material *m, char *buf, size_t cap) {
    char extra[160];
    extra[0] = 0;
    switch (m->plastic) {
    case PN_PLASTIC_DRUCKER_PRAGER:
        snprintf(extra, sizeof extra, " friction_deg=%g cohesion_strain=%g volume_correction=%d",
                 (double)(asin((double)m->sin_phi) * 180 / 3.14159265358979323846),
                 (double)m->cohesion_strain, m->volume_correction);
        break;
    case PN_PLASTIC_VON_MISES:
        snprintf(extra, sizeof extra, " yield_stress_pa=%g hardening_modulus_pa=%g",
                 (double)m->yield_stress, (double)m->hardening_modulus);
        break;
    case PN_PLASTIC_CAM_CLAY:
        snprintf(extra, sizeof extra, " friction_deg=%g beta=%g xi=%g hardening=%d",
                 (double)(asin((double)m->sin_phi) * 180 / 3.14159265358979323846),
                 (double)m->beta, (double)m->xi, m->camclay_hardening);
        break;
    case PN_PLASTIC_SNOW_STOMAKHIN:
        snprintf(extra, sizeof extra, " theta_c=%g theta_s=%g xi=%g jp=[%g, %g]", (double)m->theta_c,
                 (double)m->theta_s, (double)m->snow_xi, m->snow_h_min < 0 ? exp((double)m->snow_h_min) : 0.0,
                 m->snow_h_max > 0 ? exp((double)m->snow_h_max) : 0.0);
        break;
    default: break;
    }
    return snprintf(buf, cap, "elastic=%s plastic=%s E=%g nu=%g mu=%g lambda=%g%s",
                    pn_elastic_model_name(m->elastic), pn_plastic_model_name(m->plastic),
                    (double)m->E, (double)m->nu, (double)m->mu, (double)m->lambda, extra);
}
#endif

/* ======================================================================================
   >>elastic: isotropic energies in principal stretches.
   For psi(s) with derivatives g_i = dpsi/ds_i and Hs_ij = d2psi/ds_i ds_j, in the frame of
   the SVD the Hessian dP/dF is block diagonal (Teran et al. 2005; Smith et al. 2019): the
   d x d block Hs on the diagonal entries, and for each pair a < b two modes
   (u_a v_b^T +- u_b v_a^T)/sqrt(2) with eigenvalues
       dminus = (g_a - g_b)/(s_a - s_b),   dplus = (g_a + g_b)/(s_a + s_b).
   Each model writes these quotients in a form without cancellation at s_a = s_b, so the
   Hessian stays accurate for repeated singular values; the same structure makes the PSD
   projection exact and cheap (clamp the mode eigenvalues).
   ====================================================================================== */

typedef struct pn__principal {
    pn_real psi;
    pn_real g[3];     /* dpsi/ds_i                                   */
    pn_real H[9];     /* d2psi/ds_i ds_j, stride 3                  */
    pn_real dm[3];    /* dminus for pairs (0,1), (0,2), (1,2)       */
    pn_real dp[3];    /* dplus                                       */
} pn__principal;

static const int pn__pair_a[3] = {0, 0, 1};
static const int pn__pair_b[3] = {1, 2, 2};

static int pn__npairs(int d) { return d == 2 ? 1 : 3; }

/* (log a - log b)/(a - b) for a, b > 0, accurate as a -> b */
static pn_real pn__log_quotient(pn_real a, pn_real b) {
    pn_real x = (a - b) / b;
    if (x == 0) return 1 / b;
    if (PN__FABS(x) < (pn_real)0.5) return PN__LOG1P(x) / (x * b);
    return (PN__LOG(a) - PN__LOG(b)) / (a - b);
}

/* Energies of Hencky strain e = log s: given dpsi/de (ge), d2psi/de2 (Ae, stride 3) and the
   shear coefficient c with ge_a - ge_b = c (e_a - e_b), fill g, H, dminus, dplus. */
static void pn__hencky_to_s(int d, const pn_real *s, const pn_real *ge, const pn_real *Ae, pn_real c,
                            pn__principal *pr) {
    int i, j, k;
    for (i = 0; i < d; ++i) pr->g[i] = ge[i] / s[i];
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j)
            pr->H[i * 3 + j] = Ae[i * 3 + j] / (s[i] * s[j]) - (i == j ? ge[i] / (s[i] * s[i]) : 0);
    for (k = 0; k < pn__npairs(d); ++k) {
        int a = pn__pair_a[k], b = pn__pair_b[k];
        /* g_a - g_b = (ge_a - ge_b)/s_a + ge_b (1/s_a - 1/s_b) */
        pr->dm[k] = c * pn__log_quotient(s[a], s[b]) / s[a] - ge[b] / (s[a] * s[b]);
        pr->dp[k] = (pr->g[a] + pr->g[b]) / (s[a] + s[b]);
    }
}

/* Energies whose gradient has the form g_i = c s_i + q / s_i with c, q symmetric functions
   (Neo-Hookean and its snow variant): dminus = c - q/(s_a s_b), dplus = c + q/(s_a s_b). */
static void pn__cq_pairs(int d, const pn_real *s, pn_real c, pn_real q, pn__principal *pr) {
    int k;
    for (k = 0; k < pn__npairs(d); ++k) {
        int a = pn__pair_a[k], b = pn__pair_b[k];
        pr->dm[k] = c - q / (s[a] * s[b]);
        pr->dp[k] = c + q / (s[a] * s[b]);
    }
}

/* Fill pr for elastic model `model` with Lame constants mu, la at stretches s (without hess,
   only psi and g: all a stress needs). Hencky and Neo-Hookean models need s > 0 (checked by
   the callers). */
static void pn__elastic_principal(pn_elastic_model model, pn_real mu, pn_real la, int d,
                                  const pn_real *s, pn__principal *pr, int hess) {
    pn_real J = 1;
    int i, j, k;
    for (i = 0; i < d; ++i) J *= s[i];
    if (hess) memset(pr, 0, sizeof *pr);
    else pr->psi = 0, pr->g[0] = pr->g[1] = pr->g[2] = 0;
    switch (model) {
    case PN_ELASTIC_FIXED_COROTATED: {
        /* psi = mu sum (s_i - 1)^2 + la/2 (J - 1)^2; Jh_i = J / s_i and Jh_ab = J/(s_a s_b)
           as products of the other stretches, so s_i = 0 is fine */
        pn_real Jh[3];
        for (i = 0; i < d; ++i) {
            Jh[i] = 1;
            for (j = 0; j < d; ++j)
                if (j != i) Jh[i] *= s[j];
        }
        for (i = 0; i < d; ++i) pr->psi += mu * (s[i] - 1) * (s[i] - 1);
        pr->psi += la / 2 * (J - 1) * (J - 1);
        for (i = 0; i < d; ++i) pr->g[i] = 2 * mu * (s[i] - 1) + la * (J - 1) * Jh[i];
        if (!hess) break;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) {
                pn_real Jab = 1;
                for (k = 0; k < d; ++k)
                    if (k != i && k != j) Jab *= s[k];
                pr->H[i * 3 + j] =
                    i == j ? 2 * mu + la * Jh[i] * Jh[i] : la * (Jh[i] * Jh[j] + (J - 1) * Jab);
            }
        for (k = 0; k < pn__npairs(d); ++k) {
            int a = pn__pair_a[k], b = pn__pair_b[k];
            pn_real Jab = d == 2 ? 1 : s[3 - a - b], sum = s[a] + s[b];
            pr->dm[k] = 2 * mu - la * (J - 1) * Jab;
            /* singular where s_a + s_b = 0 (the rotation of F is undefined there) */
            if (PN__FABS(sum) < PN__EPS) sum = sum < 0 ? -PN__EPS : PN__EPS;
            pr->dp[k] = 2 * mu - 4 * mu / sum + la * (J - 1) * Jab;
        }
        break;
    }
    case PN_ELASTIC_STVK_HENCKY: {
        pn_real e[3], tr = 0, ge[3], Ae[9];
        for (i = 0; i < d; ++i) {
            e[i] = PN__LOG(s[i]);
            tr += e[i];
        }
        for (i = 0; i < d; ++i) pr->psi += mu * e[i] * e[i];
        pr->psi += la / 2 * tr * tr;
        for (i = 0; i < d; ++i) ge[i] = 2 * mu * e[i] + la * tr;
        if (!hess) {
            for (i = 0; i < d; ++i) pr->g[i] = ge[i] / s[i];
            break;
        }
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) Ae[i * 3 + j] = la + (i == j ? 2 * mu : 0);
        pn__hencky_to_s(d, s, ge, Ae, 2 * mu, pr);
        break;
    }
    case PN_ELASTIC_NEO_HOOKEAN: {
        /* g_i = mu s_i + q / s_i, q = -mu + la log J */
        pn_real lj = PN__LOG(J), q = -mu + la * lj;
        for (i = 0; i < d; ++i) pr->psi += mu / 2 * s[i] * s[i];
        pr->psi += -mu / 2 * d - mu * lj + la / 2 * lj * lj;
        for (i = 0; i < d; ++i) pr->g[i] = mu * s[i] + q / s[i];
        if (!hess) break;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j)
                pr->H[i * 3 + j] = la / (s[i] * s[j]) + (i == j ? mu - q / (s[i] * s[i]) : 0);
        pn__cq_pairs(d, s, mu, q, pr);
        break;
    }
    case PN_ELASTIC_NEO_HOOKEAN_SNOW: {
        /* psi = mu/2 (J^(-2/d) S - d) + kappa/2 ((J^2 - 1)/2 - log J), S = sum s^2;
           g_i = c s_i + q / s_i with c = mu J^(-2/d), q = -c S/d + kappa/2 (J^2 - 1) */
        pn_real kappa = la + 2 * mu / d, S = 0, c, q, dd = (pn_real)d;
        for (i = 0; i < d; ++i) S += s[i] * s[i];
        c = mu * pn__pow_dim(J, -2, d);
        q = -c * S / dd + kappa / 2 * (J * J - 1);
        pr->psi = mu / 2 * (c / mu * S - dd) + kappa / 2 * ((J * J - 1) / 2 - PN__LOG(J));
        for (i = 0; i < d; ++i) pr->g[i] = c * s[i] + q / s[i];
        if (!hess) break;
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j)
                pr->H[i * 3 + j] = (i == j ? c - q / (s[i] * s[i]) : 0) - 2 / dd * c * s[i] / s[j] -
                                   2 / dd * c * s[j] / s[i] +
                                   (2 / (dd * dd) * c * S + kappa * J * J) / (s[i] * s[j]);
        pn__cq_pairs(d, s, c, q, pr);
        break;
    }
    default: break;
    }
}

/* Modes of dP/dF: vec(M) for M = U B V^T is the d*d matrix sum U_ia B_ab V_jb */
static void pn__mode(int d, const pn_real *U, const pn_real *V, int a, int b, pn_real sign,
                     pn_real *m) {
    /* (u_a v_b^T + sign u_b v_a^T) / sqrt(2) for a != b, u_a v_a^T for a == b */
    int i, j;
    pn_real w = a == b ? 1 : (pn_real)0.70710678118654752440;
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j)
            m[i * d + j] = w * (U[i * d + a] * V[j * d + b] +
                                (a == b ? 0 : sign * U[i * d + b] * V[j * d + a]));
}

static void pn__add_outer(int n, pn_real w, const pn_real *x, const pn_real *y, pn_real *A) {
    int i, j;
    if (w == 0) return;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) A[i * n + j] += w * x[i] * y[j];
}

/* P = U diag(g) V^T and dP/dF from the principal data (PSD-projected if psd). */
static void pn__assemble(int d, const pn_real *U, const pn_real *V, const pn__principal *pr,
                         pn_real *P, pn_real *dPdF, int psd) {
    int n = d * d, i, j, k;
    pn_real D[3][9], m[9];
    if (P) pn__udvt(d, U, pr->g, V, P);
    if (!dPdF) return;
    for (i = 0; i < n * n; ++i) dPdF[i] = 0;
    for (i = 0; i < d; ++i) pn__mode(d, U, V, i, i, 0, D[i]);
    if (psd) {
        pn_real A[9], Q[9], w[3], x[9];
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) A[i * d + j] = pr->H[i * 3 + j];
        pn__jacobi_eigen(d, A, Q, w);
        for (k = 0; k < d; ++k) {
            if (!(w[k] > 0)) continue;
            for (i = 0; i < n; ++i) {
                x[i] = 0;
                for (j = 0; j < d; ++j) x[i] += Q[j * d + k] * D[j][i];
            }
            pn__add_outer(n, w[k], x, x, dPdF);
        }
    } else {
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) pn__add_outer(n, pr->H[i * 3 + j], D[i], D[j], dPdF);
    }
    for (k = 0; k < pn__npairs(d); ++k) {
        pn_real lm = pr->dm[k], lp = pr->dp[k];
        if (psd) {
            lm = PN__MAX(lm, 0);
            lp = PN__MAX(lp, 0);
        }
        pn__mode(d, U, V, pn__pair_a[k], pn__pair_b[k], 1, m);
        pn__add_outer(n, lm, m, m, dPdF);
        pn__mode(d, U, V, pn__pair_a[k], pn__pair_b[k], -1, m);
        pn__add_outer(n, lp, m, m, dPdF);
    }
}

/* Lame constants at plastic state h (Stomakhin snow hardens them; others ignore h). */
/* the factor on mu and lambda at plastic state h: Stomakhin's hardening exp(xi (1 - J_p)) */
static pn_real pn__hardening(const pn_material *m, pn_real h) {
    return m->plastic == PN_PLASTIC_SNOW_STOMAKHIN ? PN__EXP(m->snow_xi * (1 - PN__EXP(h))) : 1;
}

static void pn__lame_at(const pn_material *m, pn_real h, pn_real *mu, pn_real *la) {
    pn_real f = pn__hardening(m, h);
    *mu = m->mu * f;
    *la = m->lambda * f;
}

static int pn__needs_positive(pn_elastic_model e) { return e != PN_ELASTIC_FIXED_COROTATED; }

static pn_result pn__check_F(int d, const pn_real *F) {
    if (!pn__dim_ok(d)) return PN_ERROR_DIMENSION;
    if (!pn__all_finite(d * d, F)) return PN_ERROR_NONFINITE;
    return PN_OK;
}

/* Common path of the energy evaluators: outputs written only when everything is finite. */
static pn_result pn__energy_out(int d, const pn_real *U, const pn_real *V, const pn__principal *pr,
                                pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags) {
    pn_real p[9], h[81];
    int n = d * d;
    pn__assemble(d, U, V, pr, p, dPdF ? h : NULL, (flags & PN_EVAL_PROJECT_PSD) != 0);
    if (!pn__finite(pr->psi) || !pn__all_finite(n, p) || (dPdF && !pn__all_finite(n * n, h)))
        return PN_ERROR_OVERFLOW;
    if (psi) *psi = pr->psi;
    if (P) memcpy(P, p, sizeof(pn_real) * (size_t)n);
    if (dPdF) memcpy(dPdF, h, sizeof(pn_real) * (size_t)(n * n));
    return PN_OK;
}

/* Validate F and h, then the SVD of F and the principal data of the elastic model there. */
static pn_result pn__elastic_at(const pn_material *m, int d, const pn_real *F, pn_real h, pn_real *U,
                                pn_real *s, pn_real *V, pn__principal *pr) {
    pn_real mu, la;
    pn_result r = pn__check_F(d, F);
    if (r != PN_OK) return r;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    pn__svd(d, F, U, s, V);
    if (pn__needs_positive(m->elastic) && !(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    pn__lame_at(m, h, &mu, &la);
    pn__elastic_principal(m->elastic, mu, la, d, s, pr, 1);
    return PN_OK;
}

PN__DEF pn_result pn_elastic_energy(const pn_material *m, int d, const pn_real *F, pn_real h,
                                    pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags) {
    pn_real U[9], s[3], V[9];
    pn__principal pr;
    pn_result r;
    PN_ASSERT(m && F);
    r = pn__elastic_at(m, d, F, h, U, s, V, &pr);
    if (r != PN_OK) return r;
    return pn__energy_out(d, U, V, &pr, psi, P, dPdF, flags);
}

PN__DEF pn_result pn_kirchhoff_stress(const pn_material *m, int d, const pn_real *F, pn_real h,
                                      pn_real *tau) {
    pn_real U[9], s[3], V[9], t[3] = {0, 0, 0}, out[9];
    pn__principal pr;
    int i;
    pn_result r;
    PN_ASSERT(m && F && tau);
    r = pn__elastic_at(m, d, F, h, U, s, V, &pr);
    if (r != PN_OK) return r;
    for (i = 0; i < d; ++i) t[i] = s[i] * pr.g[i]; /* tau = P F^T = U diag(s g) U^T */
    pn__udvt(d, U, t, U, out);
    if (!pn__all_finite(d * d, out)) return PN_ERROR_OVERFLOW;
    memcpy(tau, out, sizeof(pn_real) * (size_t)(d * d));
    return PN_OK;
}

/* ======================================================================================
   >>return-mapping: all models act on the singular values, Z(F) = U diag(z) V^T.
   ====================================================================================== */

/* Hencky split of the shifted log stretches e_i = log s_i - c + v/d: e, its deviatoric part
   ehat (optional), tr e and |ehat|. c shifts the strain (cohesion), v adds a log-volume. */
static void pn__hencky_split(int d, const pn_real *s, pn_real c, pn_real v, pn_real *e,
                             pn_real *ehat, pn_real *tr, pn_real *r) {
    pn_real t = 0, r2 = 0, dd = (pn_real)d, el[3] = {0, 0, 0}; /* el: gcc 12 -O3 -march=native
                                                                 takes e for uninitialized */
    int i;
    for (i = 0; i < d; ++i) {
        e[i] = el[i] = PN__LOG(s[i]) - c + v / dd;
        t += el[i];
    }
    for (i = 0; i < d; ++i) {
        pn_real x = el[i] - t / dd;
        if (ehat) ehat[i] = x;
        r2 += x * x;
    }
    *tr = t;
    *r = PN__SQRT(r2);
}

/* Drucker-Prager friction coefficient of the cone |dev tau| + alpha tr tau <= 0 for the
   Mohr-Coulomb angle phi. 3D: alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi)), the cone through
   the compression corners of the Mohr-Coulomb pyramid (triaxial compression). 2D (plane
   strain as the 2D law sees it, in-plane stresses only): |dev tau| = |tau1 - tau2| / sqrt(2),
   so alpha = sin(phi) / sqrt(2) is exactly |tau1 - tau2| <= -sin(phi) (tau1 + tau2), the
   Mohr-Coulomb limit in the plane (the 3D value there would mean 27.5 deg for 30). */
static pn_real pn__dp_alpha(pn_real sin_phi, int d) {
    if (d == 2) return sin_phi * (pn_real)0.70710678118654752440;
    return PN__SQRT((pn_real)2 / 3) * 2 * sin_phi / (3 - sin_phi);
}

static pn_real pn__vm_tau_y(const pn_material *m, pn_real a) {
    return PN__SQRT((pn_real)2 / 3) * (m->yield_stress + m->hardening_modulus * a);
}

/* Cam-Clay quantities at stretches s (Gaume et al. 2018, Wolper et al. 2019) */
typedef struct pn__camclay {
    pn_real kappa, J, p, p0, M, q2, shat[3], shat_norm, y, yscale;
} pn__camclay;

static void pn__camclay_eval(const pn_material *m, int d, const pn_real *s, pn_real h,
                             pn__camclay *c) {
    /* the critical-state slope M keeps the triaxial-compression mapping in 2D as well (the
       shipped snow models were trained with it) */
    pn_real dd = (pn_real)d, trb = 0, alpha = pn__dp_alpha(m->sin_phi, 3), jm, n2 = 0, a, b;
    int i;
    c->kappa = m->lambda + 2 * m->mu / dd;
    c->J = 1;
    for (i = 0; i < d; ++i) {
        c->J *= s[i];
        trb += s[i] * s[i];
    }
    c->p = -c->kappa / 2 * (c->J * c->J - 1);
    c->p0 = c->kappa * ((pn_real)1e-5 + PN__SINH(m->xi * PN__MAX(-h, 0)));
    c->M = alpha * dd / PN__SQRT(2 / (6 - dd));
    jm = m->mu * pn__pow_dim(c->J, -2, d);
    for (i = 0; i < d; ++i) {
        c->shat[i] = jm * (s[i] * s[i] - trb / dd);
        n2 += c->shat[i] * c->shat[i];
    }
    c->shat_norm = PN__SQRT(n2);
    c->q2 = (6 - dd) / 2 * n2;
    a = (1 + 2 * m->beta) * c->q2;
    b = c->M * c->M * (c->p + m->beta * c->p0) * (c->p - c->p0);
    c->y = a + b;
    c->yscale = a + PN__FABS(b);
}

/* Principal Kirchhoff stresses tau_i = s_i dpsi/ds_i of the elastic model. */
static void pn__tau_principal(const pn_material *m, pn_real h, int d, const pn_real *s,
                              pn_real *tau) {
    pn__principal pr;
    pn_real mu, la;
    int i;
    pn__lame_at(m, h, &mu, &la);
    pn__elastic_principal(m->elastic, mu, la, d, s, &pr, 0);
    for (i = 0; i < d; ++i) tau[i] = s[i] * pr.g[i];
}

static pn_real pn__dev_norm(int d, const pn_real *t) {
    pn_real mean = 0, n2 = 0;
    int i;
    for (i = 0; i < d; ++i) mean += t[i];
    mean /= d;
    for (i = 0; i < d; ++i) n2 += (t[i] - mean) * (t[i] - mean);
    return PN__SQRT(n2);
}

/* Yield function in principal stretches; see pn_yield_function for units. */
static void pn__yield_principal(const pn_material *m, int d, const pn_real *s, pn_real h, pn_real *y,
                                pn_real *scale) {
    pn_real e[3], tr = 0, full2 = 0, mu2 = 2 * m->mu;
    int i;
    switch (m->plastic) {
    case PN_PLASTIC_DRUCKER_PRAGER: {
        /* cone in stress: |dev tau| + alpha tr tau <= 0 with tau of the cohesion-shifted strain;
           the volume-correction credit h is not part of the stress state */
        pn_real bulk = d * m->lambda + mu2, alpha = pn__dp_alpha(m->sin_phi, d), dev;
        pn__hencky_split(d, s, m->cohesion_strain, 0, e, NULL, &tr, &dev);
        for (i = 0; i < d; ++i) full2 += e[i] * e[i];
        *y = mu2 * dev + alpha * bulk * tr;
        *scale = mu2 * PN__SQRT(full2) + alpha * bulk * PN__FABS(tr);
        break;
    }
    case PN_PLASTIC_VON_MISES: {
        pn_real tau[3];
        pn__tau_principal(m, h, d, s, tau);
        *scale = pn__vm_tau_y(m, h);
        *y = pn__dev_norm(d, tau) - *scale;
        break;
    }
    case PN_PLASTIC_CAM_CLAY: {
        pn__camclay c;
        pn__camclay_eval(m, d, s, h, &c);
        *y = c.y;
        *scale = c.yscale;
        break;
    }
    case PN_PLASTIC_SNOW_STOMAKHIN: {
        pn_real worst = -(pn_real)1e30;
        for (i = 0; i < d; ++i) {
            worst = PN__MAX(worst, s[i] - (1 + m->theta_s));
            worst = PN__MAX(worst, (1 - m->theta_c) - s[i]);
        }
        *y = worst;
        *scale = 1;
        break;
    }
    default:
        *y = -1;
        *scale = 1;
        break;
    }
}

/* von Mises for any elasticity: the volume-preserving return H = e - dgamma n in Hencky space
   with |dev tau(exp H)| = sqrt(2/3) sigma_Y(a + sqrt(2/3) dgamma), by Newton safeguarded with
   the bracket [0, |e_hat|] (f > 0 at 0 since the trial point is outside, f < 0 at |e_hat|
   where the stress is hydrostatic). */
static pn_result pn__vm_rootfind(const pn_material *m, int d, const pn_real *s, pn_real h,
                                 pn_real *z, pn_real *h_new) {
    pn_real e[3], n[3], tr, r, lo, hi, g, f = 0, fp, tauy0, k23, sq23 = PN__SQRT((pn_real)2 / 3);
    int i, j, it, ok = 0;
    pn__hencky_split(d, s, 0, 0, e, n, &tr, &r);
    for (i = 0; i < d; ++i) n[i] /= r;
    tauy0 = pn__vm_tau_y(m, h);
    k23 = 2 * m->hardening_modulus / 3;
    lo = 0;
    hi = r;
    g = 0;
    for (it = 0; it < 200; ++it) {
        pn_real zz[3], tau[3], dev[3], mean = 0, dn, dtau[3];
        pn__principal pr;
        for (i = 0; i < d; ++i) zz[i] = PN__EXP(e[i] - g * n[i]);
        pn__elastic_principal(m->elastic, m->mu, m->lambda, d, zz, &pr, 1);
        for (i = 0; i < d; ++i) {
            tau[i] = zz[i] * pr.g[i];
            mean += tau[i] / d;
        }
        for (i = 0; i < d; ++i) dev[i] = tau[i] - mean;
        dn = pn__dev_norm(d, tau);
        f = dn - tauy0 - k23 * g;
        if (f > 0) lo = g; else hi = g;
        /* d tau_i / d gamma = -sum_j (d tau_i / d e_j) n_j, d tau_i/d e_j = (delta_ij g_i + z_i H_ij) z_j */
        for (i = 0; i < d; ++i) {
            dtau[i] = 0;
            for (j = 0; j < d; ++j)
                dtau[i] -= ((i == j ? pr.g[i] : 0) + zz[i] * pr.H[i * 3 + j]) * zz[j] * n[j];
        }
        fp = -k23;
        if (dn > 0)
            for (i = 0; i < d; ++i) fp += dev[i] * dtau[i] / dn;
        /* converged when f is down to its own rounding: the terms of tau are of size mu (and
           the pressure), so a yield stress far below mu cannot be met to eps of itself */
        if (PN__FABS(f) <= 8 * PN__EPS * (tauy0 + m->mu + PN__FABS(mean)) || hi - lo <= 4 * PN__EPS * r) {
            ok = 1;
            break;
        }
        {
            pn_real gn = fp < 0 ? g - f / fp : -1;
            if (!(gn > lo && gn < hi)) gn = (lo + hi) / 2;
            g = gn;
        }
    }
    if (!ok) return PN_ERROR_NOT_CONVERGED;
    for (i = 0; i < d; ++i) z[i] = PN__EXP(e[i] - g * n[i]);
    *h_new = h + sq23 * g;
    return PN_OK;
}

/* Exact projection of Cam-Clay's shear case: keep p (so J) and the direction of dev b, scale
   |dev b| onto the surface. b_new = c n + m 1 with det b_new = J^2 solved for m exactly
   (closed form in 2D, monotone Newton from the trial mean in 3D), so p is kept to rounding
   and the result lies on the surface (the usual m = tr b / d changes J slightly). */
static void pn__camclay_shear(int d, const pn_real *s, pn_real J, pn_real c, pn_real *z) {
    pn_real b[3], trb = 0, n[3], nn = 0, mm;
    int i, it;
    for (i = 0; i < d; ++i) {
        b[i] = s[i] * s[i];
        trb += b[i];
    }
    for (i = 0; i < d; ++i) {
        n[i] = b[i] - trb / d;
        nn += n[i] * n[i];
    }
    nn = PN__SQRT(nn);
    for (i = 0; i < d; ++i) n[i] /= nn;
    if (d == 2) {
        mm = PN__SQRT(J * J + c * c * n[0] * n[0]); /* (m + c n0)(m - c n0) = J^2 */
    } else {
        /* f(m) = prod (m + c n_i) - J^2 is increasing and convex where every factor is
           positive. At the trial mean m = tr b / d, f >= 0 (shrinking dev b at fixed mean
           raises the product), so Newton from there decreases monotonically to the root and
           never leaves the domain. */
        mm = trb / d;
        for (it = 0; it < 100; ++it) {
            pn_real a0 = mm + c * n[0], a1 = mm + c * n[1], a2 = mm + c * n[2];
            pn_real f = a0 * a1 * a2 - J * J, fp = a1 * a2 + a0 * a2 + a0 * a1, step = f / fp;
            if (!(step > 2 * PN__EPS * mm)) break; /* converged, or rounding stalls it */
            mm -= step;
        }
    }
    for (i = 0; i < d; ++i) z[i] = PN__SQRT(mm + c * n[i]);
}

/* Principal return mapping. *plastic = 0 means z == s exactly and h unchanged. */
static pn_result pn__return_principal(const pn_material *m, int d, const pn_real *s, pn_real h,
                                      pn_real *z, pn_real *h_new, int *plastic) {
    pn_real e[3], tr, r, ehat[3], dd = (pn_real)d;
    int i;
    *plastic = 0;
    *h_new = h;
    for (i = 0; i < d; ++i) z[i] = s[i];
    switch (m->plastic) {
    case PN_PLASTIC_DRUCKER_PRAGER: {
        /* Klar et al. 2016 in the cohesion-shifted strain e - c; volume correction
           (Tampubolon et al. 2017) adds the stored log-volume gain h to the trace */
        pn_real alpha = pn__dp_alpha(m->sin_phi, d), c = m->cohesion_strain, dg;
        pn_real hv = m->volume_correction ? h : 0;
        pn__hencky_split(d, s, c, hv, e, ehat, &tr, &r);
        if (tr >= 0) { /* expansion: the cone apex, stress free */
            for (i = 0; i < d; ++i) z[i] = PN__EXP(c);
            *h_new = m->volume_correction ? tr : 0;
            *plastic = 1;
            return PN_OK;
        }
        dg = r + (dd * m->lambda + 2 * m->mu) / (2 * m->mu) * tr * alpha;
        if (dg <= 0) { /* inside; a pending volume credit is absorbed into Z */
            if (hv != 0) {
                for (i = 0; i < d; ++i) z[i] = PN__EXP(e[i] + c);
                *h_new = 0;
                *plastic = 1;
            }
            return PN_OK;
        }
        for (i = 0; i < d; ++i) z[i] = PN__EXP(e[i] - dg * ehat[i] / r + c);
        *h_new = 0;
        *plastic = 1;
        return PN_OK;
    }
    case PN_PLASTIC_VON_MISES: {
        pn_real y, scale;
        if (!(h >= 0)) return PN_ERROR_INVALID_ARGUMENT; /* accumulated plastic strain */
        pn__yield_principal(m, d, s, h, &y, &scale);
        if (y <= 0) return PN_OK;
        *plastic = 1;
        if (m->elastic != PN_ELASTIC_STVK_HENCKY) return pn__vm_rootfind(m, d, s, h, z, h_new);
        {
            /* closed form for StVK-Hencky: dev tau = 2 mu e_hat */
            pn_real tauy = pn__vm_tau_y(m, h), dg;
            pn__hencky_split(d, s, 0, 0, e, ehat, &tr, &r);
            dg = (2 * m->mu * r - tauy) / (2 * m->mu + 2 * m->hardening_modulus / 3);
            for (i = 0; i < d; ++i) z[i] = PN__EXP(e[i] - dg * ehat[i] / r);
            *h_new = h + PN__SQRT((pn_real)2 / 3) * dg;
        }
        return PN_OK;
    }
    case PN_PLASTIC_CAM_CLAY: {
        pn__camclay c;
        pn_real beta = m->beta, Jn;
        pn__camclay_eval(m, d, s, h, &c);
        if (c.p > c.p0 || c.p < -beta * c.p0) {
            /* tips: compression p -> p0 or tension p -> -beta p0, no shear */
            Jn = c.p > c.p0 ? PN__SQRT(1 - 2 * c.p0 / c.kappa)
                            : PN__SQRT(1 + 2 * beta * c.p0 / c.kappa);
            for (i = 0; i < d; ++i) z[i] = pn__pow_dim(Jn, 1, d);
            if (m->camclay_hardening) *h_new = h + PN__LOG(c.J / Jn);
            *plastic = 1;
            return PN_OK;
        }
        if (c.y <= 0) return PN_OK;
        *plastic = 1;
        {
            /* shear: q onto the ellipse at fixed p */
            pn_real q2t = -c.M * c.M * (c.p + beta * c.p0) * (c.p - c.p0) / (1 + 2 * beta);
            pn_real shat_t = PN__SQRT(PN__MAX(q2t, 0) / ((6 - dd) / 2));
            pn_real cc = shat_t / (m->mu * pn__pow_dim(c.J, -2, d)); /* |dev b_new| */
            pn__camclay_shear(d, s, c.J, cc, z);
        }
        if (m->camclay_hardening) {
            /* hardening by a "fake" pressure p_x where the line from the trial point to the
               ellipse centre (p_c, 0) crosses the surface: with P = p_c + t (p - p_c),
               Q = t q, y = 0 gives t^2 = M^2 a^2 / ((1 + 2 beta) q^2 + M^2 (p - p_c)^2),
               a = (1 + beta) p0 / 2 the half-width. logJp moves by log(J / J_x). */
            pn_real pc = (1 - beta) * c.p0 / 2, a = (1 + beta) * c.p0 / 2, t, px, jx2;
            t = c.M * a / PN__SQRT((1 + 2 * beta) * c.q2 + c.M * c.M * (c.p - pc) * (c.p - pc));
            px = pc + t * (c.p - pc);
            jx2 = 1 - 2 * px / c.kappa;
            if (jx2 > 0) *h_new = h + (pn_real)0.5 * PN__LOG(c.J * c.J / jx2);
        }
        return PN_OK;
    }
    case PN_PLASTIC_SNOW_STOMAKHIN: {
        /* clamp the stretches to [1 - theta_c, 1 + theta_s]; log Jp += log(J / J_new). The
           clamp also takes an inverted trial state (the smallest stretch signed, J < 0, where
           the fixed corotated energy is still defined) back to a valid one: its volume
           change counts as the compression |J|. Then the optional J_p bounds. */
        pn_real J = 1, Jn = 1;
        for (i = 0; i < d; ++i) {
            z[i] = PN__MIN(PN__MAX(s[i], 1 - m->theta_c), 1 + m->theta_s);
            if (z[i] != s[i]) *plastic = 1;
            J *= s[i];
            Jn *= z[i];
        }
        if (*plastic) {
            pn_real hn = h + PN__LOG(PN__FABS(J) / Jn);
            if (m->snow_h_min < 0 && hn < m->snow_h_min) hn = m->snow_h_min;
            if (m->snow_h_max > 0 && hn > m->snow_h_max) hn = m->snow_h_max;
            *h_new = hn;
        }
        return PN_OK;
    }
    default: return PN_OK;
    }
}

/* The return mapping in principal form, shared by pn_return_map and the explicit MPM step:
   the SVD of a finite F, the projected stretches z, h_new and the principal Kirchhoff
   stresses t_i = tau_i(z) of the result. Plastic flow needs det F > 0, except the Stomakhin
   clamp, whose fixed corotated energy is defined for inverted F and whose clamp restores
   det > 0; purely elastic models need it where their energy does (not fixed corotated). */
static pn_result pn__return_core(const pn_material *m, int d, const pn_real *F, pn_real h, pn_real *U,
                                 pn_real *s, pn_real *V, pn_real *z, pn_real *h_new, int *plastic, pn_real *t) {
    pn_result r;
    int i;
    pn__svd(d, F, U, s, V);
    if (m->plastic == PN_PLASTIC_NONE) {
        if (pn__needs_positive(m->elastic) && !(s[d - 1] > 0)) return PN_ERROR_INVERTED;
        for (i = 0; i < d; ++i) z[i] = s[i];
        *h_new = h;
        *plastic = 0;
    } else {
        if (!(s[d - 1] > 0) && m->plastic != PN_PLASTIC_SNOW_STOMAKHIN) return PN_ERROR_INVERTED;
        r = pn__return_principal(m, d, s, h, z, h_new, plastic);
        if (r != PN_OK) return r;
    }
    pn__tau_principal(m, *h_new, d, z, t);
    return PN_OK;
}

PN__DEF pn_result pn_return_map(const pn_material *m, int d, const pn_real *F, pn_real h,
                                pn_real *Z, pn_real *h_new, pn_real *T) {
    pn_real U[9], s[3], V[9], z[3], hn, zz[9], tt[9], w[3];
    int plastic, i, n = d * d;
    pn_result r;
    PN_ASSERT(m && F);
    r = pn__check_F(d, F);
    if (r != PN_OK) return r;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    r = pn__return_core(m, d, F, h, U, s, V, z, &hn, &plastic, w);
    if (r != PN_OK) return r;
    if (plastic) pn__udvt(d, U, z, V, zz);
    else memcpy(zz, F, sizeof(pn_real) * (size_t)n);
    /* T = tau(Z) F^-T = U diag(tau_i(z) / s_i) V^T; elastic: P(F) = U diag(g_i) V^T, the same
       where s_i != 0 and defined at s_i = 0 as well */
    if (m->plastic == PN_PLASTIC_NONE) {
        pn__principal pr;
        pn_real mu, la;
        pn__lame_at(m, h, &mu, &la);
        pn__elastic_principal(m->elastic, mu, la, d, s, &pr, 0);
        for (i = 0; i < d; ++i) w[i] = pr.g[i];
    } else {
        for (i = 0; i < d; ++i) w[i] /= s[i];
    }
    pn__udvt(d, U, w, V, tt);
    if (!pn__finite(hn) || !pn__all_finite(n, zz) || !pn__all_finite(n, tt))
        return PN_ERROR_OVERFLOW;
    if (Z) memcpy(Z, zz, sizeof(pn_real) * (size_t)n);
    if (h_new) *h_new = hn;
    if (T) memcpy(T, tt, sizeof(pn_real) * (size_t)n);
    return PN_OK;
}

PN__DEF pn_result pn_yield_function(const pn_material *m, int d, const pn_real *F, pn_real h,
                                    pn_real *y, pn_real *scale) {
    pn_real U[9], s[3], V[9], yy, sc;
    pn_result r = pn__check_F(d, F);
    PN_ASSERT(m && F && y);
    if (r != PN_OK) return r;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    pn__svd(d, F, U, s, V);
    if (m->plastic != PN_PLASTIC_NONE && !(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    pn__yield_principal(m, d, s, h, &yy, &sc);
    if (!pn__finite(yy)) return PN_ERROR_OVERFLOW;
    *y = yy;
    if (scale) *scale = sc;
    return PN_OK;
}

/* ======================================================================================
   >>energy-vm: the incremental potential of StVK-Hencky + von Mises with linear hardening.
   With tau_Y = sqrt(2/3) (sigma_Y0 + K h) at the step's start, beta = 2K/3, r = |e_hat| and
   the return's plastic multiplier g (Simo and Hughes 1998, radial return):
       W(r) = min_{g >= 0} mu (r - g)^2 + tau_Y g + beta/2 g^2
            = mu r^2                                        2 mu r <= tau_Y
            = mu (r - g)^2 + tau_Y g + beta/2 g^2,  g = (2 mu r - tau_Y) / (2 mu + beta)
       psi = kappa/2 (tr e)^2 + W(|e_hat|)
   W'(r) = 2 mu (r - g) = tau_Y + beta g is the returned |dev tau| (envelope theorem), so the
   e-gradient is the Kirchhoff stress of pn_return_map's projected strain, hardening included,
   and the F-gradient is tau(Z(F)) F^-T; W'' = 2 mu beta / (2 mu + beta) along the flow. C1:
   the Hessian jumps across 2 mu r = tau_Y. K = 0: the perfectly plastic tau_Y r - tau_Y^2/(4 mu).
   ====================================================================================== */

PN__DEF pn_result pn_von_mises_energy(const pn_material *m, int d, const pn_real *F, pn_real h,
                                      pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags) {
    pn_real U[9], s[3], V[9], e[3], tr, rr, n[3], ge[3], Ae[9], kappa, tauy, c, dd = (pn_real)d;
    pn__principal pr;
    int i, j;
    pn_result res = pn__check_F(d, F);
    PN_ASSERT(m && F);
    if (res != PN_OK) return res;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    if (m->plastic != PN_PLASTIC_VON_MISES || m->elastic != PN_ELASTIC_STVK_HENCKY)
        return PN_ERROR_UNSUPPORTED;
    if (!(h >= 0)) return PN_ERROR_INVALID_ARGUMENT;
    pn__svd(d, F, U, s, V);
    if (!(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    kappa = m->lambda + 2 * m->mu / dd;
    tauy = pn__vm_tau_y(m, h);
    pn__hencky_split(d, s, 0, 0, e, n, &tr, &rr);
    memset(&pr, 0, sizeof pr);
    if (2 * m->mu * rr <= tauy) {
        pr.psi = kappa / 2 * tr * tr + m->mu * rr * rr;
        c = 2 * m->mu;
        for (i = 0; i < d; ++i) ge[i] = kappa * tr + c * n[i];
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) Ae[i * 3 + j] = kappa + c * ((i == j ? 1 : 0) - 1 / dd);
    } else { /* past yield: the radial return's multiplier g, |dev tau| = w1, W'' = w2 */
        pn_real beta = 2 * m->hardening_modulus / 3, g = (2 * m->mu * rr - tauy) / (2 * m->mu + beta);
        pn_real w1 = tauy + beta * g, w2 = 2 * m->mu * beta / (2 * m->mu + beta);
        pr.psi = kappa / 2 * tr * tr + m->mu * (rr - g) * (rr - g) + tauy * g + beta / 2 * g * g;
        c = w1 / rr;
        for (i = 0; i < d; ++i) n[i] /= rr;
        for (i = 0; i < d; ++i) ge[i] = kappa * tr + w1 * n[i];
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j)
                Ae[i * 3 + j] = kappa + c * ((i == j ? 1 : 0) - 1 / dd - n[i] * n[j]) + w2 * n[i] * n[j];
    }
    pn__hencky_to_s(d, s, ge, Ae, c, &pr);
    return pn__energy_out(d, U, V, &pr, psi, P, dPdF, flags);
}

/* >>energy-dp: the frozen-yield Drucker-Prager energy (see the declaration) */

static pn_result pn__dp_check(const pn_material *m, int d, const pn_real *F, pn_real h) {
    pn_result r = pn__check_F(d, F);
    if (r != PN_OK) return r;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    if (m->plastic != PN_PLASTIC_DRUCKER_PRAGER || m->elastic != PN_ELASTIC_STVK_HENCKY)
        return PN_ERROR_UNSUPPORTED;
    return PN_OK;
}

PN__DEF pn_result pn_dp_prepare(const pn_material *m, int d, const pn_real *F0, pn_real h,
                                pn_real *tau_y) {
    pn_real U[9], s[3], V[9], e[3], tr, rr, kappa = m->lambda + 2 * m->mu / (pn_real)d;
    pn_result r;
    PN_ASSERT(m && F0 && tau_y);
    r = pn__dp_check(m, d, F0, h);
    if (r != PN_OK) return r;
    pn__svd(d, F0, U, s, V);
    if (!(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    pn__hencky_split(d, s, m->cohesion_strain, m->volume_correction ? h : 0, e, NULL, &tr, &rr);
    *tau_y = PN__MAX(-(pn_real)d * kappa * pn__dp_alpha(m->sin_phi, d) * tr, 0);
    return PN_OK;
}

PN__DEF pn_result pn_dp_energy(const pn_material *m, int d, const pn_real *F, pn_real h,
                               pn_real tau_y, pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags) {
    pn_real U[9], s[3], V[9], e[3], tr, rr, n[3], ge[3], Ae[9], kappa, trm, kv, c, dd = (pn_real)d;
    pn__principal pr;
    int i, j;
    pn_result res;
    PN_ASSERT(m && F);
    res = pn__dp_check(m, d, F, h);
    if (res != PN_OK) return res;
    if (!pn__finite(tau_y) || !(tau_y >= 0)) return PN_ERROR_INVALID_ARGUMENT;
    pn__svd(d, F, U, s, V);
    if (!(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    kappa = m->lambda + 2 * m->mu / dd;
    pn__hencky_split(d, s, m->cohesion_strain, m->volume_correction ? h : 0, e, n, &tr, &rr);
    /* volumetric part: stress kappa (min(tr, 0) + d c), stiffness kappa on the compressed side */
    trm = PN__MIN(tr, 0);
    kv = tr < 0 ? kappa : 0;
    memset(&pr, 0, sizeof pr);
    pr.psi = kappa / 2 * trm * trm + dd * kappa * m->cohesion_strain * tr;
    if (2 * m->mu * rr <= tau_y) { /* deviatoric part elastic */
        pr.psi += m->mu * rr * rr;
        c = 2 * m->mu;
        for (i = 0; i < d; ++i) ge[i] = kappa * (trm + dd * m->cohesion_strain) + c * n[i];
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) Ae[i * 3 + j] = kv + c * ((i == j ? 1 : 0) - 1 / dd);
    } else { /* on the cylinder: |dev tau| = tau_y, no stiffness along the flow */
        pr.psi += tau_y * rr - tau_y * tau_y / (4 * m->mu);
        c = tau_y / rr;
        for (i = 0; i < d; ++i) n[i] /= rr;
        for (i = 0; i < d; ++i) ge[i] = kappa * (trm + dd * m->cohesion_strain) + tau_y * n[i];
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) Ae[i * 3 + j] = kv + c * ((i == j ? 1 : 0) - 1 / dd - n[i] * n[j]);
    }
    pn__hencky_to_s(d, s, ge, Ae, c, &pr);
    return pn__energy_out(d, U, V, &pr, psi, P, dPdF, flags);
}

/* ======================================================================================
   >>energy-lagged: Psi_lag(F; F0) = psi_el(F G), G = F0^-1 Z(F0) = V diag(z/s) V^T.
   dPsi/dF = P_el(F G) G^T; d2Psi/dF_ij dF_kl = G_jm H_el[im][kb] G_lb.
   ====================================================================================== */

PN__DEF pn_result pn_lagged_prepare(const pn_material *m, int d, const pn_real *F0, pn_real h0,
                                    pn_real *G, pn_real *h_G) {
    pn_real U[9], s[3], V[9], z[3], hn, g[9], w[3];
    int plastic, i;
    pn_result r = pn__check_F(d, F0);
    PN_ASSERT(m && F0 && G && h_G);
    if (r != PN_OK) return r;
    if (!pn__finite(h0)) return PN_ERROR_NONFINITE;
    if (m->plastic == PN_PLASTIC_NONE) {
        pn__identity(d, g);
        hn = h0;
    } else {
        pn__svd(d, F0, U, s, V);
        if (!(s[d - 1] > 0)) return PN_ERROR_INVERTED;
        r = pn__return_principal(m, d, s, h0, z, &hn, &plastic);
        if (r != PN_OK) return r;
        if (plastic) {
            for (i = 0; i < d; ++i) w[i] = z[i] / s[i];
            pn__udvt(d, V, w, V, g);
        } else {
            pn__identity(d, g);
        }
        if (!pn__finite(hn) || !pn__all_finite(d * d, g)) return PN_ERROR_OVERFLOW;
    }
    memcpy(G, g, sizeof(pn_real) * (size_t)(d * d));
    *h_G = hn;
    return PN_OK;
}

PN__DEF pn_result pn_lagged_energy(const pn_material *m, int d, const pn_real *F, const pn_real *G,
                                   pn_real h_G, pn_real *psi, pn_real *P, pn_real *dPdF,
                                   unsigned flags) {
    pn_real A[9], e, pa[9], ha[81], p[9], hh[81];
    int n = d * d, i, j, k, l, a, b, mm;
    pn_result r = pn__check_F(d, F);
    PN_ASSERT(m && F && G);
    if (r != PN_OK) return r;
    if (!pn__all_finite(n, G) || !pn__finite(h_G)) return PN_ERROR_NONFINITE;
    pn_mat_mul(d, F, G, A);
    r = pn_elastic_energy(m, d, A, h_G, &e, pa, dPdF ? ha : NULL, flags);
    if (r != PN_OK) return r;
    for (i = 0; i < d; ++i) /* P = P_el(A) G^T */
        for (j = 0; j < d; ++j) {
            pn_real acc = 0;
            for (mm = 0; mm < d; ++mm) acc += pa[i * d + mm] * G[j * d + mm];
            p[i * d + j] = acc;
        }
    if (dPdF) {
        /* congruence by G keeps a PSD-projected H_el PSD */
        pn_real t[81]; /* t[(i m),(k l)] = sum_b H[(i m),(k b)] G_lb */
        for (i = 0; i < d; ++i)
            for (mm = 0; mm < d; ++mm)
                for (k = 0; k < d; ++k)
                    for (l = 0; l < d; ++l) {
                        pn_real acc = 0;
                        for (b = 0; b < d; ++b) acc += ha[(i * d + mm) * n + k * d + b] * G[l * d + b];
                        t[(i * d + mm) * n + k * d + l] = acc;
                    }
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j)
                for (a = 0; a < n; ++a) {
                    pn_real acc = 0;
                    for (mm = 0; mm < d; ++mm) acc += G[j * d + mm] * t[(i * d + mm) * n + a];
                    hh[(i * d + j) * n + a] = acc;
                }
    }
    if (!pn__all_finite(n, p) || (dPdF && !pn__all_finite(n * n, hh))) return PN_ERROR_OVERFLOW;
    if (psi) *psi = e;
    if (P) memcpy(P, p, sizeof(pn_real) * (size_t)n);
    if (dPdF) memcpy(dPdF, hh, sizeof(pn_real) * (size_t)(n * n));
    return PN_OK;
}

/* ======================================================================================
   >>mlp: value by a forward pass; gradient by a backward (adjoint) pass; the Hessian with
   respect to the first n_diff inputs from the identity for an MLP with affine layers,
       d2 f / dx dx = sum over hidden units u of  (df/da_u) s''(z_u) (dz_u/dx) (dz_u/dx)^T,
   with the tangents dz_u/dx carried forward and the adjoints df/da_u from the backward pass:
   2 + n_diff passes instead of the 1 + n_diff + n_diff(n_diff+1)/2 of forward mode.
   ====================================================================================== */

#define PN__MLP_MAX_HIDDEN ((PN_MLP_MAX_LAYERS - 1) * PN_MLP_MAX_WIDTH)

static pn_real pn__sigmoid(pn_real z) {
    if (z >= 0) return 1 / (1 + PN__EXP(-z));
    {
        pn_real e = PN__EXP(z);
        return e / (1 + e);
    }
}

/* activation value and first two derivatives */
static void pn__activate(pn_activation act, pn_real z, pn_real *a, pn_real *a1, pn_real *a2) {
    switch (act) {
    case PN_ACTIVATION_TANH: {
        pn_real t = (pn_real)tanh((double)z);
        *a = t;
        *a1 = 1 - t * t;
        *a2 = -2 * t * (1 - t * t);
        break;
    }
    case PN_ACTIVATION_SOFTPLUS: {
        pn_real sg = pn__sigmoid(z);
        *a = PN__MAX(z, 0) + PN__LOG1P(PN__EXP(-PN__FABS(z)));
        *a1 = sg;
        *a2 = sg * (1 - sg);
        break;
    }
    default: { /* PN_ACTIVATION_SILU */
        pn_real sg = pn__sigmoid(z);
        *a = z * sg;
        *a1 = sg + z * sg * (1 - sg);
        *a2 = sg * (1 - sg) * (2 + z * (1 - 2 * sg));
        break;
    }
    }
}

/* dot product of float weights (widened) and pn_real inputs: four partial sums, independent
   add chains */
static pn_real pn__dotf(int n, const float *a, const pn_real *b) {
    pn_real s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        s0 += (pn_real)a[i] * b[i];
        s1 += (pn_real)a[i + 1] * b[i + 1];
        s2 += (pn_real)a[i + 2] * b[i + 2];
        s3 += (pn_real)a[i + 3] * b[i + 3];
    }
    for (; i < n; ++i) s0 += (pn_real)a[i] * b[i];
    return (s0 + s1) + (s2 + s3);
}

static int pn__mlp_ok(const pn_mlp *n) {
    int l;
    if (n->n_layers < 1 || n->n_layers > PN_MLP_MAX_LAYERS) return 0;
    if (n->activation < PN_ACTIVATION_SILU || n->activation > PN_ACTIVATION_SOFTPLUS) return 0;
    for (l = 0; l <= n->n_layers; ++l)
        if (n->size[l] < 1 || n->size[l] > PN_MLP_MAX_WIDTH) return 0;
    for (l = 0; l < n->n_layers; ++l) {
        if (!n->weight[l] || !n->bias[l]) return 0;
        /* declared lengths (format 2) must match: otherwise the dots would read past them */
        if ((n->weight_count[l] || n->bias_count[l]) &&
            (n->weight_count[l] != n->size[l] * n->size[l + 1] || n->bias_count[l] != n->size[l + 1]))
            return 0;
    }
    return 1;
}

/* every weight and bias finite (a corrupt or hand-made network is refused before use) */
static int pn__mlp_finite(const pn_mlp *n) {
    int l, i;
    for (l = 0; l < n->n_layers; ++l) {
        for (i = 0; i < n->size[l] * n->size[l + 1]; ++i)
            if (!pn__finite((pn_real)n->weight[l][i])) return 0;
        for (i = 0; i < n->size[l + 1]; ++i)
            if (!pn__finite((pn_real)n->bias[l][i])) return 0;
    }
    return 1;
}

PN__DEF pn_result pn_mlp_eval(const pn_mlp *net, const pn_real *in, int n_diff, pn_real *out,
                              pn_real *grad, pn_real *hess) {
    /* forward: buf[c * width + unit], c = 0 the value, c = 1..nt-1 the tangents dz/dx_k */
    pn_real buf[2][(1 + PN_MLP_MAX_DIFF) * PN_MLP_MAX_WIDTH];
    pn_real d1[PN__MLP_MAX_HIDDEN], d2[PN__MLP_MAX_HIDDEN];      /* s'(z), s''(z) per unit  */
    pn_real tg[PN__MLP_MAX_HIDDEN * PN_MLP_MAX_DIFF];             /* dz/dx per unit          */
    pn_real lam[2][PN_MLP_MAX_WIDTH], H[PN_MLP_MAX_DIFF * PN_MLP_MAX_DIFF];
    pn_real val[PN_MLP_MAX_WIDTH], gout[PN_MLP_MAX_WIDTH * PN_MLP_MAX_DIFF];
    pn_real hout[PN_MLP_MAX_WIDTH * PN_MLP_MAX_DIFF * PN_MLP_MAX_DIFF];
    int off[PN_MLP_MAX_LAYERS], L, l, i, j, c, k, o, cur = 0, nt, n_in, n_out;
    int want_h = hess != NULL && n_diff > 0, want_g = (grad != NULL || want_h) && n_diff > 0;
    PN_ASSERT(net && in && out);
    if (!pn__mlp_ok(net) || n_diff < 0 || n_diff > PN_MLP_MAX_DIFF || n_diff > net->size[0])
        return PN_ERROR_FORMAT;
    L = net->n_layers;
    n_in = net->size[0];
    n_out = net->size[L];
    if (!pn__all_finite(n_in, in)) return PN_ERROR_NONFINITE;
    nt = 1 + (want_h ? n_diff : 0);
    for (i = 0; i < n_in; ++i) {
        buf[0][i] = in[i];
        for (c = 1; c < nt; ++c) buf[0][c * n_in + i] = c - 1 == i ? 1 : 0;
    }
    for (l = 0, k = 0; l < L; ++l) {
        int n0 = net->size[l], n1 = net->size[l + 1];
        const float *W = net->weight[l], *b = net->bias[l];
        pn_real *x = buf[cur], *y = buf[1 - cur];
        for (j = 0; j < n1; ++j) {
            const float *wj = W + (size_t)j * (size_t)n0;
            for (c = 0; c < nt; ++c) /* four partial sums: independent add chains */
                y[c * n1 + j] = pn__dotf(n0, wj, x + c * n0);
            y[j] += (pn_real)b[j];
        }
        if (l < L - 1) { /* hidden layer: keep s', s'' and the tangents of z for the passes back */
            off[l] = k;
            for (j = 0; j < n1; ++j, ++k) {
                pn_real a;
                pn__activate(net->activation, y[j], &a, &d1[k], &d2[k]);
                y[j] = a;
                for (c = 1; c < nt; ++c) {
                    tg[k * PN_MLP_MAX_DIFF + c - 1] = y[c * n1 + j];
                    y[c * n1 + j] *= d1[k];
                }
            }
        }
        cur = 1 - cur;
    }
    memcpy(val, buf[cur], sizeof(pn_real) * (size_t)n_out);
    if (!pn__all_finite(n_out, val)) return PN_ERROR_OVERFLOW;
    /* backward, once per output: lam = df/dz of the current layer's outputs */
    for (o = 0; want_g && o < n_out; ++o) {
        int lc = 0;
        memset(H, 0, sizeof H);
        for (j = 0; j < n_out; ++j) lam[0][j] = j == o ? 1 : 0;
        for (l = L - 1; l >= 0; --l) {
            int n0 = net->size[l], n1 = net->size[l + 1];
            const float *W = net->weight[l];
            pn_real *mu = lam[1 - lc];
            for (i = 0; i < n0; ++i) mu[i] = 0;
            for (j = 0; j < n1; ++j) {
                const float *wj = W + (size_t)j * (size_t)n0;
                pn_real lj = lam[lc][j];
                if (lj == 0) continue;
                for (i = 0; i + 4 <= n0; i += 4) { /* independent lanes: vectorizes at -O2 */
                    mu[i] += (pn_real)wj[i] * lj;
                    mu[i + 1] += (pn_real)wj[i + 1] * lj;
                    mu[i + 2] += (pn_real)wj[i + 2] * lj;
                    mu[i + 3] += (pn_real)wj[i + 3] * lj;
                }
                for (; i < n0; ++i) mu[i] += (pn_real)wj[i] * lj;
            }
            if (l > 0) { /* mu = df/da of hidden layer l-1: its Hessian term, then df/dz */
                int base = off[l - 1];
                for (i = 0; i < n0; ++i) {
                    int u = base + i;
                    if (want_h) {
                        pn_real w2 = mu[i] * d2[u];
                        const pn_real *t = tg + u * PN_MLP_MAX_DIFF;
                        for (j = 0; j < n_diff; ++j)
                            for (c = j; c < n_diff; ++c) H[j * PN_MLP_MAX_DIFF + c] += w2 * t[j] * t[c];
                    }
                    mu[i] *= d1[u];
                }
            }
            lc = 1 - lc;
        }
        for (j = 0; j < n_diff; ++j) gout[o * n_diff + j] = lam[lc][j]; /* df/dx */
        if (!pn__all_finite(n_diff, gout + o * n_diff)) return PN_ERROR_OVERFLOW;
        if (want_h)
            for (j = 0; j < n_diff; ++j)
                for (c = j; c < n_diff; ++c) {
                    pn_real v = H[j * PN_MLP_MAX_DIFF + c];
                    if (!pn__finite(v)) return PN_ERROR_OVERFLOW;
                    hout[(o * n_diff + j) * n_diff + c] = v;
                    hout[(o * n_diff + c) * n_diff + j] = v;
                }
    }
    /* every check passed: now the outputs */
    for (o = 0; o < n_out; ++o) out[o] = val[o];
    if (grad && n_diff > 0) memcpy(grad, gout, sizeof(pn_real) * (size_t)(n_out * n_diff));
    if (want_h) memcpy(hess, hout, sizeof(pn_real) * (size_t)(n_out * n_diff * n_diff));
    return PN_OK;
}

/* ---- MLP inference in lanes: PN_MLP_LANES points at once, in float ---------------------- */

/* A vector of PN_MLP_LANES floats: GCC and Clang vector extensions where the compiler has
   them (SSE, AVX2, AVX-512, NEON: whatever the build targets), a plain struct otherwise.
   Operators only through these helpers, so both spellings share one kernel (e^x alone has a
   spelling of its own for each). */
#if (defined(__GNUC__) || defined(__clang__)) && !defined(PN_NO_VECTOR_EXTENSIONS)
#define PN__VF_VECTOR
#if defined(__AVX__)
#define PN__VW 8 /* lanes per vector: what the target's registers hold (8 x 32 bits without AVX
                    would go through memory: a different calling convention) */
#else
#define PN__VW 4
#endif
typedef float pn__vf __attribute__((vector_size(PN__VW * sizeof(float))));
static pn__vf pn__vf_set1(float x) {
    pn__vf v;
    memset(&v, 0, sizeof v);
    return v + x;
}
static pn__vf pn__vf_add(pn__vf a, pn__vf b) { return a + b; }
static pn__vf pn__vf_sub(pn__vf a, pn__vf b) { return a - b; }
static pn__vf pn__vf_mul(pn__vf a, pn__vf b) { return a * b; }
static pn__vf pn__vf_div(pn__vf a, pn__vf b) { return a / b; }
static pn__vf pn__vf_madd(pn__vf acc, float w, pn__vf x) { return acc + w * x; }
#else
#define PN__VW PN_MLP_LANES
typedef struct pn__vf { float v[PN__VW]; } pn__vf;
#define PN__VF_OP(name, expr)                                                                \
    static pn__vf name(pn__vf a, pn__vf b) {                                                \
        int l;                                                                              \
        for (l = 0; l < PN__VW; ++l) a.v[l] = (expr);                                 \
        return a;                                                                           \
    }
PN__VF_OP(pn__vf_add, a.v[l] + b.v[l])
PN__VF_OP(pn__vf_sub, a.v[l] - b.v[l])
PN__VF_OP(pn__vf_mul, a.v[l] * b.v[l])
PN__VF_OP(pn__vf_div, a.v[l] / b.v[l])
#undef PN__VF_OP
static pn__vf pn__vf_set1(float x) {
    pn__vf r;
    int l;
    for (l = 0; l < PN__VW; ++l) r.v[l] = x;
    return r;
}
static pn__vf pn__vf_madd(pn__vf acc, float w, pn__vf x) {
    int l;
    for (l = 0; l < PN__VW; ++l) acc.v[l] += w * x.v[l];
    return acc;
}
#endif

/* e^x per lane, float, for |x| <= 87 (clamped beyond): x = k ln 2 + r, |r| <= ln 2 / 2,
   e^r by its Taylor polynomial to r^7 (relative error below 1e-8), 2^k from the exponent
   bits. Branch-free over the lanes. k is rounded by adding 1.5 2^23, whose float then holds
   k in its low mantissa bits; a NaN lane stays NaN through r. The vector spelling keeps every
   lane in registers (the plain one goes through memory), and both give the same bits. */
static pn__vf pn__vf_exp_poly(pn__vf r) { /* e^r, |r| <= ln 2 / 2: Horner to r^7 */
    pn__vf p = pn__vf_set1(1.0f / 5040);
    p = pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(1.0f / 720));
    p = pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(1.0f / 120));
    p = pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(1.0f / 24));
    p = pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(1.0f / 6));
    p = pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(0.5f));
    p = pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(1.0f));
    return pn__vf_add(pn__vf_mul(p, r), pn__vf_set1(1.0f));
}
#if defined(PN__VF_VECTOR)
typedef uint32_t pn__vu __attribute__((vector_size(PN__VW * sizeof(uint32_t))));
static pn__vf pn__vf_exp(pn__vf x) {
    const pn__vf lo = pn__vf_set1(-87.0f), hi = pn__vf_set1(87.0f), magic = pn__vf_set1(12582912.0f);
    pn__vu below = (pn__vu)(x < lo), above = (pn__vu)(x > hi), bits;
    pn__vf km, kv, r, p;
    x = (pn__vf)((below & (pn__vu)lo) | (~below & (pn__vu)x));
    x = (pn__vf)((above & (pn__vu)hi) | (~above & (pn__vu)x));
    km = pn__vf_add(pn__vf_mul(x, pn__vf_set1(1.44269504f)), magic); /* the helpers: no contraction */
    kv = pn__vf_sub(km, magic);
    bits = ((pn__vu)km - (pn__vu)magic + 127u) << 23;
    r = pn__vf_sub(pn__vf_sub(x, pn__vf_mul(kv, pn__vf_set1(0.693145752f))), pn__vf_mul(kv, pn__vf_set1(1.42860677e-6f)));
    p = pn__vf_exp_poly(r);
    return pn__vf_mul(p, (pn__vf)bits);
}
#else
static pn__vf pn__vf_exp(pn__vf x) {
    float z[PN__VW], k[PN__VW], two_k[PN__VW];
    int32_t bits[PN__VW];
    pn__vf r, p, kv, tk;
    int l;
    memcpy(z, &x, sizeof z);
    for (l = 0; l < PN__VW; ++l) {
        float t = z[l] < -87.0f ? -87.0f : z[l];
        t = t > 87.0f ? 87.0f : t;
        z[l] = t;
        k[l] = (t * 1.44269504f + 12582912.0f) - 12582912.0f; /* round to nearest */
        bits[l] = ((int32_t)(k[l] == k[l] ? k[l] : 0) + 127) * (1 << 23); /* NaN: through r, not the cast */
    }
    memcpy(two_k, bits, sizeof two_k);
    memcpy(&x, z, sizeof z);
    memcpy(&kv, k, sizeof k);
    memcpy(&tk, two_k, sizeof two_k);
    r = pn__vf_sub(pn__vf_sub(x, pn__vf_mul(kv, pn__vf_set1(0.693145752f))), pn__vf_mul(kv, pn__vf_set1(1.42860677e-6f)));
    p = pn__vf_exp_poly(r);
    return pn__vf_mul(p, tk);
}
#endif

/* activation, s' and s'' per lane (silu and tanh; softplus has no lane path) */
static void pn__vf_activate(pn_activation act, pn__vf z, pn__vf *a, pn__vf *a1, pn__vf *a2) {
    pn__vf one = pn__vf_set1(1.0f), two = pn__vf_set1(2.0f);
    pn__vf e = pn__vf_exp(pn__vf_mul(z, pn__vf_set1(act == PN_ACTIVATION_TANH ? -2.0f : -1.0f)));
    pn__vf sg = pn__vf_div(one, pn__vf_add(one, e)), q = pn__vf_sub(one, sg); /* sigmoid(z) or (2z) */
    if (act == PN_ACTIVATION_TANH) {
        pn__vf t = pn__vf_sub(pn__vf_mul(two, sg), one), u = pn__vf_sub(one, pn__vf_mul(t, t));
        *a = t;
        *a1 = u;
        *a2 = pn__vf_mul(pn__vf_mul(pn__vf_set1(-2.0f), t), u);
    } else {
        pn__vf sq = pn__vf_mul(sg, q);
        *a = pn__vf_mul(z, sg);
        *a1 = pn__vf_add(sg, pn__vf_mul(z, sq));
        *a2 = pn__vf_mul(sq, pn__vf_add(two, pn__vf_mul(z, pn__vf_sub(one, pn__vf_mul(two, sg)))));
    }
}

#if defined(PN__VF_VECTOR)
/* One layer's sums for NT tangents at once (pn__mlp_lanes, GCC and Clang): y[c n1 + j] =
   sum_i W[j][i] x[c n0 + i] (+ b[j] for c = 0), two output units at a time, each weight
   broadcast once for all NT tangents (19 instructions for 6 products where the loop of one
   tangent takes 17 for 4); the same sums in the same order, so the same bits. The loops over
   c unrolled, so the 2 NT sums stay in registers. */
#define PN__MLP_TANGENTS(NT)                                                                       \
    for (j = 0; j < n1; j += 2) {                                                                  \
        const float *w0 = Wl + (size_t)j * (size_t)n0, *w1 = w0 + (j + 1 < n1 ? n0 : 0);          \
        pn__vf s0[NT], s1[NT];                                                                     \
        _Pragma("GCC unroll 4") for (c = 0; c < NT; ++c) s0[c] = s1[c] = pn__vf_set1(0.0f);        \
        for (i = 0; i < n0; ++i) {                                                                 \
            pn__vf u0 = pn__vf_set1(w0[i]), u1 = pn__vf_set1(w1[i]);                               \
            _Pragma("GCC unroll 4") for (c = 0; c < NT; ++c) {                                     \
                s0[c] = pn__vf_add(s0[c], pn__vf_mul(u0, x[c * n0 + i]));                          \
                s1[c] = pn__vf_add(s1[c], pn__vf_mul(u1, x[c * n0 + i]));                          \
            }                                                                                      \
        }                                                                                          \
        _Pragma("GCC unroll 4") for (c = 0; c < NT; ++c) {                                         \
            y[c * n1 + j] = c ? s0[c] : pn__vf_add(s0[c], pn__vf_set1(b[j]));                      \
            if (j + 1 < n1) y[c * n1 + j + 1] = c ? s1[c] : pn__vf_add(s1[c], pn__vf_set1(b[j + 1])); \
        }                                                                                          \
    }
#endif

/* The network at PN__VW points (lanes; inputs and outputs at lane stride PN_MLP_LANES): out, the gradient d out / d in_k for k < n_grad (the pass
   back), and with want_h the Hessian along n_dir directions of the input space, hess[j][c] =
   s_j^T (d2 out / d in2) s_c: seed NULL takes the unit vectors of the first n_dir inputs,
   else seed[(c * n_in + i) * L + lane] is input i of direction c. The directions are what
   the pass forward carries (1 + n_dir vectors per unit, and none without want_h), so a
   Hessian needed only along a few directions (PlasticityNet's scaled encoding: its d
   features, not its 2 d + 1 inputs) costs a few passes, not one per input. */
static void pn__mlp_lanes(const pn_mlp *net, const float *in, const float *seed, int n_grad, int n_dir, int want_h,
                          float *out, float *grad, float *hess) {
    enum { L = PN_MLP_LANES, W = PN_MLP_MAX_WIDTH, D = PN_MLP_MAX_DIFF };
    /* per unit (and tangent c: 0 the value, 1.. d/dx): a lane vector */
    pn__vf buf[2][(1 + D) * W], d1[PN_MLP_LANES_HIDDEN], d2[PN_MLP_LANES_HIDDEN];
    pn__vf tg[PN_MLP_LANES_HIDDEN * D], lam[2][W], H[D * D];
    int off[PN_MLP_MAX_LAYERS], nl = net->n_layers, l, i, j, c, k, lane, cur = 0, nt, n_in = net->size[0];
    int want_g = n_grad > 0 || want_h, n_diff = want_h ? n_dir : 0;
    float tmp[PN__VW];
    nt = 1 + n_diff;
    for (i = 0; i < n_in; ++i) {
        for (lane = 0; lane < PN__VW; ++lane) tmp[lane] = in[i * L + lane];
        memcpy(&buf[0][i], tmp, sizeof tmp);
        for (c = 1; c < nt; ++c) {
            if (seed) {
                for (lane = 0; lane < PN__VW; ++lane) tmp[lane] = seed[((c - 1) * n_in + i) * L + lane];
                memcpy(&buf[0][c * n_in + i], tmp, sizeof tmp);
            } else {
                buf[0][c * n_in + i] = pn__vf_set1(c - 1 == i ? 1.0f : 0.0f);
            }
        }
    }
    for (l = 0, k = 0; l < nl; ++l) {
        int n0 = net->size[l], n1 = net->size[l + 1];
        const float *Wl = net->weight[l], *b = net->bias[l];
        const pn__vf *x = buf[cur];
        pn__vf *y = buf[1 - cur];
#if defined(PN__VF_VECTOR)
        if (nt == 3) { /* the tangents of a 2D Hessian */
            PN__MLP_TANGENTS(3)
        } else if (nt == 4) { /* of a 3D one */
            PN__MLP_TANGENTS(4)
        } else
#endif
        for (c = 0; c < nt; ++c) { /* four output units at a time: four independent sums */
            const pn__vf *xc = x + c * n0;
            for (j = 0; j < n1; j += 4) {
                const float *w0 = Wl + (size_t)j * (size_t)n0, *w1 = w0 + (j + 1 < n1 ? n0 : 0);
                const float *w2 = w0 + (j + 2 < n1 ? 2 * n0 : 0), *w3 = w0 + (j + 3 < n1 ? 3 * n0 : 0);
                pn__vf a0 = pn__vf_set1(0.0f), a1 = a0, a2 = a0, a3 = a0;
                for (i = 0; i < n0; ++i) {
                    a0 = pn__vf_madd(a0, w0[i], xc[i]);
                    a1 = pn__vf_madd(a1, w1[i], xc[i]);
                    a2 = pn__vf_madd(a2, w2[i], xc[i]);
                    a3 = pn__vf_madd(a3, w3[i], xc[i]);
                }
                y[c * n1 + j] = c ? a0 : pn__vf_add(a0, pn__vf_set1(b[j]));
                if (j + 1 < n1) y[c * n1 + j + 1] = c ? a1 : pn__vf_add(a1, pn__vf_set1(b[j + 1]));
                if (j + 2 < n1) y[c * n1 + j + 2] = c ? a2 : pn__vf_add(a2, pn__vf_set1(b[j + 2]));
                if (j + 3 < n1) y[c * n1 + j + 3] = c ? a3 : pn__vf_add(a3, pn__vf_set1(b[j + 3]));
            }
        }
        if (l < nl - 1) { /* hidden: keep s', s'' and the tangents of z for the pass back */
            off[l] = k;
            for (j = 0; j < n1; ++j, ++k) {
                pn__vf_activate(net->activation, y[j], &y[j], &d1[k], &d2[k]);
                for (c = 1; c < nt; ++c) {
                    tg[k * D + c - 1] = y[c * n1 + j];
                    y[c * n1 + j] = pn__vf_mul(y[c * n1 + j], d1[k]);
                }
            }
        }
        cur = 1 - cur;
    }
    memcpy(tmp, &buf[cur][0], sizeof tmp);
    for (lane = 0; lane < PN__VW; ++lane) out[lane] = tmp[lane];
    if (want_g) { /* backward: lam = d out / dz of the current layer's units */
        int lc = 0;
        for (j = 0; j < n_diff * n_diff; ++j) H[j] = pn__vf_set1(0.0f);
        lam[0][0] = pn__vf_set1(1.0f);
        for (l = nl - 1; l >= 0; --l) {
            int n0 = net->size[l], n1 = net->size[l + 1];
            const float *Wl = net->weight[l];
            pn__vf *mu = lam[1 - lc];
            for (i = 0; i < n0; i += 4) { /* mu = W^T lam, four inputs at a time: sums in registers */
                int i1 = i + 1 < n0 ? i + 1 : i, i2 = i + 2 < n0 ? i + 2 : i, i3 = i + 3 < n0 ? i + 3 : i;
                pn__vf a0 = pn__vf_set1(0.0f), a1 = a0, a2 = a0, a3 = a0;
                for (j = 0; j < n1; ++j) {
                    const float *wj = Wl + (size_t)j * (size_t)n0;
                    pn__vf lj = lam[lc][j];
                    a0 = pn__vf_madd(a0, wj[i], lj), a1 = pn__vf_madd(a1, wj[i1], lj);
                    a2 = pn__vf_madd(a2, wj[i2], lj), a3 = pn__vf_madd(a3, wj[i3], lj);
                }
                mu[i] = a0, mu[i1] = a1, mu[i2] = a2, mu[i3] = a3; /* past n0: the same sum again */
            }
            if (l > 0) /* mu = d out / da of hidden layer l - 1: its Hessian term, then d out / dz */
                for (i = 0; i < n0; ++i) {
                    int u = off[l - 1] + i;
                    if (want_h) {
                        pn__vf w2 = pn__vf_mul(mu[i], d2[u]);
                        const pn__vf *t = tg + u * D;
                        for (j = 0; j < n_diff; ++j) {
                            pn__vf wt = pn__vf_mul(w2, t[j]);
                            for (c = j; c < n_diff; ++c) H[j * n_diff + c] = pn__vf_add(H[j * n_diff + c], pn__vf_mul(wt, t[c]));
                        }
                    }
                    mu[i] = pn__vf_mul(mu[i], d1[u]);
                }
            lc = 1 - lc;
        }
        for (j = 0; j < n_grad; ++j) {
            memcpy(tmp, &lam[lc][j], sizeof tmp);
            for (lane = 0; lane < PN__VW; ++lane) grad[j * L + lane] = tmp[lane];
        }
        if (want_h)
            for (j = 0; j < n_diff; ++j)
                for (c = j; c < n_diff; ++c) {
                    memcpy(tmp, &H[j * n_diff + c], sizeof tmp);
                    for (lane = 0; lane < PN__VW; ++lane) hess[(j * n_diff + c) * L + lane] = hess[(c * n_diff + j) * L + lane] = tmp[lane];
                }
    }
}

/* pn_mlp_eval_lanes with the directions of pn__mlp_lanes: the gradient over the first n_grad
   inputs, the Hessian (n_dir x n_dir) along seed's directions (NULL: unit vectors; else
   every one of the PN_MLP_LANES lanes set), for the first n points (lanes past n repeat the
   first); outputs only on success */
static pn_result pn__mlp_eval_lanes_dir(const pn_mlp *net, int n, const float *in, const float *seed, int n_grad,
                                        int n_dir, float *out, float *grad, float *hess) {
    enum { L = PN_MLP_LANES, D = PN_MLP_MAX_DIFF };
    float xin[PN_MLP_MAX_WIDTH * L], o[L], g[PN_MLP_MAX_WIDTH * L];
    float h[D * D * L], worst = 0;
    int l, i, lane, hidden = 0, want_h = hess != NULL && n_dir > 0, n_in = net->size[0];
    if (!pn__mlp_ok(net) || n < 1 || n > L || n_grad < 0 || n_grad > n_in || n_dir < 0 || n_dir > D ||
        (!seed && n_dir > n_in) || net->size[net->n_layers] != 1 || net->activation == PN_ACTIVATION_SOFTPLUS)
        return PN_ERROR_FORMAT;
    for (l = 1; l < net->n_layers; ++l) hidden += net->size[l];
    if (hidden > PN_MLP_LANES_HIDDEN) return PN_ERROR_FORMAT;
    for (i = 0; i < n_in; ++i)
        for (lane = 0; lane < L; ++lane) {
            float v = in[i * L + (lane < n ? lane : 0)];
            if (!(v == v) || v > 3.4e38f || v < -3.4e38f) return PN_ERROR_NONFINITE;
            xin[i * L + lane] = v;
        }
    for (i = 0; seed && want_h && i < n_dir * n_in * L; ++i)
        if (!(seed[i] == seed[i]) || seed[i] > 3.4e38f || seed[i] < -3.4e38f) return PN_ERROR_NONFINITE;
    for (lane = 0; lane < n; lane += PN__VW)
        pn__mlp_lanes(net, xin + lane, seed ? seed + lane : NULL, n_grad, n_dir, want_h, o + lane, g + lane, h + lane);
    /* a result that is not finite is an overflow (as pn_mlp_eval says) */
    for (lane = 0; lane < n; ++lane) {
        worst += o[lane] * 0;
        for (i = 0; i < n_grad; ++i) worst += g[i * L + lane] * 0;
        for (i = 0; want_h && i < n_dir * n_dir; ++i) worst += h[i * L + lane] * 0;
    }
    if (!(worst == 0)) return PN_ERROR_OVERFLOW;
    for (lane = 0; lane < n; ++lane) out[lane] = o[lane];
    for (i = 0; grad && i < n_grad; ++i)
        for (lane = 0; lane < n; ++lane) grad[i * L + lane] = g[i * L + lane];
    for (i = 0; want_h && i < n_dir * n_dir; ++i)
        for (lane = 0; lane < n; ++lane) hess[i * L + lane] = h[i * L + lane];
    return PN_OK;
}

PN__DEF pn_result pn_mlp_eval_lanes(const pn_mlp *net, int n, const float *in, int n_diff, float *out, float *grad,
                                    float *hess) {
    int nd;
    PN_ASSERT(net && in && out);
    if (n_diff < 0 || n_diff > PN_MLP_MAX_DIFF || !pn__mlp_ok(net) || n_diff > net->size[0]) return PN_ERROR_FORMAT;
    nd = (grad != NULL || (hess != NULL && n_diff > 0)) ? n_diff : 0;
    return pn__mlp_eval_lanes_dir(net, n, in, NULL, grad ? nd : 0, hess ? nd : 0, out, grad, hess);
}

/* ======================================================================================
   >>features: rotation invariants of F for the energy networks, smooth wherever J > 0 and
   computed from C = F^T F without an SVD (gen/pn_torch.py, `features`):
     x1 = log J
     2D: x2 = log(I1 / 2) - log J                    (= log cosh(e_1 - e_2))
     3D: a = log(I1 / 3) - 2/3 log J, b = log(II / 3) - 4/3 log J, x2 = (a + b)/2, x3 = a - b
   with I1 = tr C and II = tr cof C. Derivatives (row-major d^2 vectors, d^2 x d^2 Hessians):
     d log J = F^-T, d2 log J[ij][kl] = -Finv_jk Finv_li; dI1 = 2F, d2 I1 = 2 Id;
     dII = 2 (I1 F - F C), d2 II[ij][kl] = 4 F_ij F_kl + 2 I1 d_ik d_jl
                                          - 2 (d_ik C_lj + F_il F_kj + B_ik d_jl), B = F F^T.
   ====================================================================================== */

typedef struct pn__features {
    int nf;
    pn_real x[3];
    pn_real dx[3][9];
    pn_real d2x[3][81];
} pn__features;

/* level 0: values, 1: + gradients, 2: + Hessians. Needs det F > 0. */
static void pn__features_eval(int d, const pn_real *F, int level, pn__features *f) {
    pn_real Fi[9], C[9], B[9], dL[9], dI1[9], dII[9], J, L, I1 = 0, II = 0;
    int n = d * d, i, j, k, l, a;
    J = pn_mat_det(d, F);
    L = PN__LOG(J);
    for (i = 0; i < n; ++i) I1 += F[i] * F[i];
    f->nf = d == 2 ? 2 : 3;
    f->x[0] = L;
    if (d == 3) {
        for (i = 0; i < 3; ++i)
            for (j = 0; j < 3; ++j) {
                pn_real c = 0, bb = 0;
                for (k = 0; k < 3; ++k) {
                    c += F[k * 3 + i] * F[k * 3 + j];
                    bb += F[i * 3 + k] * F[j * 3 + k];
                }
                C[i * 3 + j] = c;
                B[i * 3 + j] = bb;
            }
        /* II as the sum of the principal 2x2 minors of C: no cancellation against I1^2 */
        II = C[0] * C[4] - C[1] * C[3] + C[0] * C[8] - C[2] * C[6] + C[4] * C[8] - C[5] * C[7];
        {
            pn_real av = PN__LOG(I1 / 3) - 2 * L / 3, bv = PN__LOG(II / 3) - 4 * L / 3;
            f->x[1] = (av + bv) / 2;
            f->x[2] = av - bv;
        }
    } else {
        f->x[1] = PN__LOG(I1 / 2) - L;
    }
    if (level < 1) return;
    pn_mat_inverse(d, F, Fi); /* J > 0: cannot fail */
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) {
            dL[i * d + j] = Fi[j * d + i];
            dI1[i * d + j] = 2 * F[i * d + j];
        }
    if (d == 3)
        for (i = 0; i < 3; ++i)
            for (j = 0; j < 3; ++j) {
                pn_real fc = 0;
                for (k = 0; k < 3; ++k) fc += F[i * 3 + k] * C[k * 3 + j];
                dII[i * 3 + j] = 2 * (I1 * F[i * 3 + j] - fc);
            }
    for (a = 0; a < n; ++a) {
        pn_real da = dI1[a] / I1 - (d == 2 ? 1 : (pn_real)2 / 3) * dL[a];
        if (d == 2) {
            f->dx[0][a] = dL[a];
            f->dx[1][a] = da;
        } else {
            pn_real db = dII[a] / II - (pn_real)4 / 3 * dL[a];
            f->dx[0][a] = dL[a];
            f->dx[1][a] = (da + db) / 2;
            f->dx[2][a] = da - db;
        }
    }
    if (level < 2) return;
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j)
            for (k = 0; k < d; ++k)
                for (l = 0; l < d; ++l) {
                    int r = i * d + j, c = k * d + l, id = i == k && j == l;
                    pn_real d2L = -Fi[j * d + k] * Fi[l * d + i];
                    pn_real d2I1 = id ? 2 : 0;
                    pn_real ha = d2I1 / I1 - dI1[r] * dI1[c] / (I1 * I1);
                    f->d2x[0][r * n + c] = d2L;
                    if (d == 2) {
                        f->d2x[1][r * n + c] = ha - d2L;
                    } else {
                        pn_real d2II = 4 * F[r] * F[c] + I1 * d2I1 -
                                       2 * ((i == k ? C[l * 3 + j] : 0) + F[i * 3 + l] * F[k * 3 + j] +
                                            (j == l ? B[i * 3 + k] : 0));
                        pn_real hb = d2II / II - dII[r] * dII[c] / (II * II);
                        ha -= (pn_real)2 / 3 * d2L;
                        hb -= (pn_real)4 / 3 * d2L;
                        f->d2x[1][r * n + c] = (ha + hb) / 2;
                        f->d2x[2][r * n + c] = ha - hb;
                    }
                }
}

/* ======================================================================================
   >>pnet: model checks, material matching, PlasticityNet energy (Li et al. 2022, Eqs. 8, 11)
     N(F, F0, h) = (E / E_train) out_scale mlp(u),
     u = ([x(F) - x(F0), x(F0), clamp(h)] - in_shift) * in_scale
     Psi = N(F, F0, h) - C : F + R(F, F0),  C = grad_F N(F0, F0, h) - T(F0)
     R = reg/2 |F - F0|^2 (Eq. 11) or reg/8 |F^T F - F0^T F0|^2 (pn_pnet_regularizer)
   ====================================================================================== */

static int pn__model_nf(const pn_model *mo) { return mo->dim == 2 ? 2 : 3; }

/* An energy network has 2 nf + 1 inputs (raw encoding) or 2 nf + 2 (scaled encoding: the
   strain scale s is the extra input, see >>pnet), then a conditioned model's n_params. */
static int pn__model_scaled(const pn_model *mo) {
    return mo->kind == PN_MODEL_ENERGY && mo->n_inputs - mo->n_params == 2 * pn__model_nf(mo) + 2;
}

static int pn__model_inputs(const pn_model *mo) {
    return mo->kind == PN_MODEL_ENERGY ? 2 * pn__model_nf(mo) + 1 + pn__model_scaled(mo) + mo->n_params
                                       : (mo->dim == 2 ? 3 : 4);
}

/* the parameter list: each kind known and used once, each range finite and ordered */
static int pn__model_params_ok(const pn_model *mo) {
    int i, j;
    if (mo->n_params < 0 || mo->n_params > PN_MODEL_MAX_PARAMS || (mo->n_params && mo->kind != PN_MODEL_ENERGY)) return 0;
    for (i = 0; i < mo->n_params; ++i) {
        const pn_model_param *q = &mo->param[i];
        if (q->kind < PN_MODEL_PARAM_POISSON || q->kind > PN_MODEL_PARAM_CAMCLAY_XI || !pn__finite((pn_real)q->lo) ||
            !pn__finite((pn_real)q->hi) || !(q->lo <= q->hi))
            return 0;
        for (j = 0; j < i; ++j)
            if (mo->param[j].kind == q->kind) return 0;
    }
    if (mo->base != PN_MODEL_BASE_NONE &&
        (mo->kind != PN_MODEL_ENERGY ||
         !((mo->base == PN_MODEL_BASE_VON_MISES_HENCKY && mo->plastic == PN_PLASTIC_VON_MISES) ||
           (mo->base == PN_MODEL_BASE_DP_FROZEN && mo->plastic == PN_PLASTIC_DRUCKER_PRAGER &&
            mo->elastic == PN_ELASTIC_STVK_HENCKY))))
        return 0;
    return mo->output == PN_MODEL_OUTPUT_LINEAR || mo->output == PN_MODEL_OUTPUT_SOFTPLUS;
}

static int pn__model_normalisation_ok(const pn_model *mo) {
    int i;
    for (i = 0; i < mo->n_inputs && i < 16; ++i)
        if (!pn__finite((pn_real)mo->in_shift[i]) || !pn__finite((pn_real)mo->in_scale[i])) return 0;
    return 1;
}

/* a model (format 2 and up) declares the lengths of every layer's arrays: pn__mlp_ok checks
   only the layers that declare them */
static int pn__mlp_counted(const pn_mlp *n) {
    int l;
    for (l = 0; l < n->n_layers && l < PN_MLP_MAX_LAYERS; ++l)
        if (n->weight_count[l] == 0 || n->bias_count[l] == 0) return 0;
    return 1;
}

static pn_result pn__model_check_why(const pn_model *mo, int dim, const char **why) {
    const char *w = NULL;
    pn_result r = PN_OK;
    PN_ASSERT(mo);
    if (mo->format_version != PN_MODEL_FORMAT_VERSION) {
        w = "model format version differs from PN_MODEL_FORMAT_VERSION: regenerate it (make models; "
            "gen/upgrade_format.py for older formats)";
        r = PN_ERROR_FORMAT;
    } else if (!pn__mlp_counted(&mo->mlp)) {
        w = "model network without its array lengths (pn_mlp.weight_count, bias_count of every layer)";
        r = PN_ERROR_FORMAT;
    } else if (mo->kind != PN_MODEL_ENERGY && mo->kind != PN_MODEL_RETURN_MAP) {
        w = "unknown model kind";
        r = PN_ERROR_FORMAT;
    } else if (!pn__dim_ok(mo->dim)) {
        w = "model dimension is not 2 or 3, or is compiled out (PN_NO_2D / PN_NO_3D)";
        r = PN_ERROR_DIMENSION;
    } else if (dim != 0 && mo->dim != dim) {
        w = "model was trained for another dimension";
        r = PN_ERROR_DIMENSION;
    } else if (!pn__model_params_ok(mo)) {
        w = "model parameter list, output form or base energy is malformed (pn_model.n_params, param, output, base)";
        r = PN_ERROR_FORMAT;
    } else if (!pn__mlp_ok(&mo->mlp) || mo->n_inputs != mo->mlp.size[0] ||
               mo->n_inputs != pn__model_inputs(mo) || mo->mlp.size[mo->mlp.n_layers] != 1) {
        w = "model network layout is malformed (layer sizes, array lengths or input count disagree)";
        r = PN_ERROR_FORMAT;
    } else if (!pn__mlp_finite(&mo->mlp)) {
        w = "model network has a NaN or infinite weight";
        r = PN_ERROR_FORMAT;
    } else if (!(mo->youngs_modulus_train_pa > 0) || !(mo->h_min <= mo->h_max) ||
               !pn__finite((pn_real)mo->out_scale) || !pn__model_normalisation_ok(mo)) {
        w = "model training parameters are malformed";
        r = PN_ERROR_FORMAT;
    }
    if (why && w) *why = w;
    return r;
}

PN__DEF pn_result pn_model_check(const pn_model *model, int dim, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__model_check_why(model, dim, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}

static pn_result pn__model_material_why(const pn_model *mo, pn_real E, pn_material *m, const char **why) {
    pn_material_desc d;
    pn_result r;
    PN_ASSERT(mo && m);
    if ((r = pn__model_check_why(mo, 0, why)) != PN_OK) return r;
    pn_model_material_desc(mo, E, &d);
    return pn__material_init_why(m, &d, why);
}

PN__DEF pn_result pn_model_material(const pn_model *model, pn_real E, pn_material *m, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__model_material_why(model, E, m, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}

PN__DEF void pn_model_material_desc(const pn_model *mo, pn_real E, pn_material_desc *dst) {
    pn_material_desc d;
    PN_ASSERT(mo && dst);
    memset(&d, 0, sizeof d);
    d.elastic = mo->elastic;
    d.plastic = mo->plastic;
    d.youngs_modulus_pa = E;
    d.poisson_ratio = (pn_real)mo->poisson_ratio;
    d.friction_angle_deg = (pn_real)mo->friction_angle_deg;
    d.cohesion_strain = (pn_real)mo->cohesion_strain;
    d.yield_stress_pa = (pn_real)(mo->yield_stress_ratio * E);
    d.hardening_modulus_pa = (pn_real)(mo->hardening_ratio * E);
    d.camclay_beta = (pn_real)mo->camclay_beta;
    d.camclay_xi = (pn_real)mo->camclay_xi;
    *dst = d;
}

PN__DEF void pn_model_param_set(pn_material_desc *d, int kind, double v) {
    PN_ASSERT(d);
    switch (kind) {
    case PN_MODEL_PARAM_POISSON: d->poisson_ratio = (pn_real)v; break;
    case PN_MODEL_PARAM_FRICTION_DEG: d->friction_angle_deg = (pn_real)v; break;
    case PN_MODEL_PARAM_COHESION: d->cohesion_strain = (pn_real)v; break;
    case PN_MODEL_PARAM_YIELD_RATIO: d->yield_stress_pa = (pn_real)(v * (double)d->youngs_modulus_pa); break;
    case PN_MODEL_PARAM_HARDENING_RATIO: d->hardening_modulus_pa = (pn_real)(v * (double)d->youngs_modulus_pa); break;
    case PN_MODEL_PARAM_CAMCLAY_BETA: d->camclay_beta = (pn_real)v; break;
    case PN_MODEL_PARAM_CAMCLAY_XI: d->camclay_xi = (pn_real)v; break;
    default: break;
    }
}

static int pn__close(double a, double b) { return fabs(a - b) <= 1e-6 * (fabs(a) + fabs(b)) + 1e-12; }

/* A material's value of parameter kind k (pn_model_param_kind units), and its name */
static double pn__model_param_value(const pn_material *m, int k) {
    double E = (double)m->E;
    switch (k) {
    case PN_MODEL_PARAM_POISSON: return (double)m->nu;
    case PN_MODEL_PARAM_FRICTION_DEG: return asin((double)m->sin_phi) * 180 / 3.14159265358979323846;
    case PN_MODEL_PARAM_COHESION: return (double)m->cohesion_strain;
    case PN_MODEL_PARAM_YIELD_RATIO: return (double)m->yield_stress / E;
    case PN_MODEL_PARAM_HARDENING_RATIO: return (double)m->hardening_modulus / E;
    case PN_MODEL_PARAM_CAMCLAY_BETA: return (double)m->beta;
    case PN_MODEL_PARAM_CAMCLAY_XI: return (double)m->xi;
    default: return 0;
    }
}

static const char *pn__model_param_name(int k) {
    static const char *names[] = {"?", "poisson_ratio", "friction_angle_deg", "cohesion_strain", "yield_stress_pa / E",
                                  "hardening_modulus_pa / E", "camclay_beta", "camclay_xi"};
    return k >= PN_MODEL_PARAM_POISSON && k <= PN_MODEL_PARAM_CAMCLAY_XI ? names[k] : names[0];
}

/* does the model take parameter kind k as an input? */
static int pn__model_conditions(const pn_model *mo, int k) {
    int i;
    for (i = 0; i < mo->n_params; ++i)
        if (mo->param[i].kind == k) return 1;
    return 0;
}

/* Does material m match the model's training material (up to E, and but for the parameters
   it takes as inputs, checked against their ranges by pn_pnet_init)? */
static pn_result pn__model_matches(const pn_model *mo, const pn_material *m, const char **why) {
    const char *w = NULL;
    double E = (double)m->E;
    int dp = m->plastic == PN_PLASTIC_DRUCKER_PRAGER, cc = m->plastic == PN_PLASTIC_CAM_CLAY, vm = m->plastic == PN_PLASTIC_VON_MISES;
#define PN__FIXED(k, a, b) (!pn__model_conditions(mo, k) && !pn__close(a, b))
    if (m->elastic != mo->elastic) w = "the material's elastic model differs from the model's";
    else if (m->plastic != mo->plastic) w = "the material's plastic model differs from the model's";
    else if (PN__FIXED(PN_MODEL_PARAM_POISSON, (double)m->nu, mo->poisson_ratio))
        w = "the material's poisson_ratio differs from the model's training material";
    else if ((dp || cc) && PN__FIXED(PN_MODEL_PARAM_FRICTION_DEG, (double)m->sin_phi,
                                     sin(mo->friction_angle_deg * 3.14159265358979323846 / 180)))
        w = "the material's friction_angle_deg differs from the model's training material";
    else if (dp && (PN__FIXED(PN_MODEL_PARAM_COHESION, (double)m->cohesion_strain, mo->cohesion_strain) || m->volume_correction))
        w = "the material's cohesion_strain or volume_correction differs from the model's";
    else if (vm && (PN__FIXED(PN_MODEL_PARAM_YIELD_RATIO, (double)m->yield_stress / E, mo->yield_stress_ratio) ||
                    PN__FIXED(PN_MODEL_PARAM_HARDENING_RATIO, (double)m->hardening_modulus / E, mo->hardening_ratio)))
        w = "the material's yield_stress_pa or hardening_modulus_pa relative to E differs from the model's";
    else if (cc && (PN__FIXED(PN_MODEL_PARAM_CAMCLAY_BETA, (double)m->beta, mo->camclay_beta) ||
                    PN__FIXED(PN_MODEL_PARAM_CAMCLAY_XI, (double)m->xi, mo->camclay_xi)))
        w = "the material's camclay_beta or camclay_xi differs from the model's";
#undef PN__FIXED
    if (!w) return PN_OK;
    if (why) *why = w;
    return PN_ERROR_INVALID_PARAMETER;
}

static pn_result pn__pnet_init_why(pn_pnet *net, const pn_pnet_desc *desc, const pn_material *m,
                               int dim, const char **why) {
    const pn_model *e, *rm;
    pn_result r;
    const char *w = NULL;
    pn_real cond[PN_MODEL_MAX_PARAMS];
    int i;
    PN_ASSERT(net && desc && m);
    e = desc->energy;
    rm = desc->return_map;
    if (!e) {
        if (why) *why = "pn_pnet_desc.energy is NULL";
        return PN_ERROR_INVALID_ARGUMENT;
    }
    r = pn__model_check_why(e, dim, why);
    if (r != PN_OK) return r;
    if (e->kind != PN_MODEL_ENERGY) {
        if (why) *why = "pn_pnet_desc.energy is not an energy model";
        return PN_ERROR_INVALID_ARGUMENT;
    }
    r = pn__model_matches(e, m, why);
    if (r != PN_OK) return r;
    if (e->return_map) {
        if (!rm) w = "this energy was trained with a learned return mapping: set pn_pnet_desc.return_map";
        else if (!rm->name || strcmp(rm->name, e->return_map) != 0)
            w = "pn_pnet_desc.return_map is not the return mapping this energy was trained with";
    } else if (rm) {
        w = "this energy was trained with the analytic return mapping: pn_pnet_desc.return_map must be NULL";
    }
    if (w) {
        if (why) *why = w;
        return PN_ERROR_INVALID_ARGUMENT;
    }
    if (rm) {
        r = pn__model_check_why(rm, e->dim, why);
        if (r != PN_OK) return r;
        if (rm->kind != PN_MODEL_RETURN_MAP) {
            if (why) *why = "pn_pnet_desc.return_map is not a return-mapping model";
            return PN_ERROR_INVALID_ARGUMENT;
        }
        r = pn__model_matches(rm, m, why);
        if (r != PN_OK) return r;
    }
    if (!pn__finite(desc->regularizer)) {
        if (why) *why = "pn_pnet_desc.regularizer is not finite";
        return PN_ERROR_NONFINITE;
    }
    for (i = 0; i < e->n_params; ++i) { /* a conditioned model serves its ranges only */
        const pn_model_param *q = &e->param[i];
        /* the ends included, to float precision (a float build stores 0.4 as 0.40000001) */
        double v = pn__model_param_value(m, q->kind), tol = 1e-5 * (fabs(q->lo) + fabs(q->hi)) + 1e-12;
        if (!(v >= q->lo - tol && v <= q->hi + tol)) {
#ifndef PN_NO_STDIO
            snprintf(net->message, sizeof net->message,
                     "the material's %s = %.6g is outside the range this model was trained over, [%.6g, %.6g]",
                     pn__model_param_name(q->kind), v, q->lo, q->hi);
#else /* the name without the numbers */
            strcpy(net->message, "the material's ");
            strcat(net->message, pn__model_param_name(q->kind));
            strcat(net->message, " is outside the range this model was trained over (pn_model.param)");
#endif
            if (why) *why = net->message;
            return PN_ERROR_INVALID_PARAMETER;
        }
        cond[i] = (pn_real)v;
    }
    if (desc->regularizer_form != PN_PNET_REG_DISPLACEMENT && desc->regularizer_form != PN_PNET_REG_STRAIN) {
        if (why) *why = "pn_pnet_desc.regularizer_form is neither PN_PNET_REG_DISPLACEMENT nor PN_PNET_REG_STRAIN";
        return PN_ERROR_INVALID_ARGUMENT;
    }
    net->energy = e;
    net->return_map = rm;
    net->material = *m;
    net->scale = (pn_real)((double)m->E / e->youngs_modulus_train_pa);
    net->reg = desc->regularizer < 0 ? 0 : (desc->regularizer == 0 ? 1 : desc->regularizer) * m->mu;
    net->reg_form = desc->regularizer_form;
    for (i = 0; i < PN_MODEL_MAX_PARAMS; ++i) net->cond[i] = i < e->n_params ? cond[i] : 0;
    net->base = *m;
    net->base.elastic = PN_ELASTIC_STVK_HENCKY; /* same mu, lambda: the base's elasticity */
    return PN_OK;
}

PN__DEF pn_result pn_pnet_init(pn_pnet *net, const pn_pnet_desc *desc, const pn_material *m, int dim, char *why, size_t why_cap) {
    const char *msg = NULL;
    pn_result r = pn__pnet_init_why(net, desc, m, dim, &msg);
    if (r != PN_OK) pn__put(why, why_cap, msg ? msg : pn_result_string(r));
    return r;
}

/* Scaled encoding (gen/pn_torch.py, scaled_raw): with y = x(F), y0 = x(F0),
     q(y) = y1^2 / d + c y2 (c = 1 in 2D, 3/2 in 3D),  S = s^2 = q(y) + q(y0) + eps^2,
     raw = [(y - y0) s^-p, y0 s^-p, s, h],  N = S M(raw),
   p = 1 for log J and 2 for the others: the 3D cubic feature (~|e_hat|^3, the Lode angle) over
   s^2 fades at small strains instead of amplifying its rounding (it is a difference of two
   logarithms, exact to ~1e-16 only); Drucker-Prager and Hencky do not depend on it.
   Cohesionless Drucker-Prager is positively homogeneous in the Hencky strain, so M sees every
   strain scale alike; a network of the raw features is only its linearisation at strains far
   below the training box (a sand column at E = 1e7 Pa strains ~1e-4). Gives N / (E-scale)
   and its y-gradient and y-Hessian (nf x nf), by the chain rule through S and raw(y). */
#define PN__SCALED_EPS 1e-6
/* The network call of a PlasticityNet evaluation, split for pn_pnet_energy_lanes: mode 0
   evaluates it (pn_mlp_eval); mode 1 stops once its inputs u (nu of them, the first nd
   differentiated) are known; mode 2 takes its value, gradient and Hessian from m, gm, hm. */
typedef struct pn__mlp_io {
    int mode, nu, nd, ns; /* inputs, gradient entries, Hessian directions (0: the unit ones) */
    pn_real u[PN_MLP_MAX_WIDTH], m, gm[PN_MLP_MAX_DIFF], hm[PN_MLP_MAX_DIFF * PN_MLP_MAX_DIFF];
    pn_real seed[3 * PN_MLP_MAX_WIDTH]; /* direction c, input i: seed[c nu + i] (ns > 0) */
} pn__mlp_io;

/* The network at u: its value m, gradient over the first nd inputs gm and, with want_h, the
   Hessian hm over them (nd x nd). With lanes (io mode 1: the inputs handed over; mode 2: the
   results handed back) and ns > 0, the Hessian comes back along the ns directions of seed
   instead, hm[j ns + c] = seed_j^T H seed_c (pn__mlp_lanes): what the caller's chain rule
   needs, at a fraction of the cost. A softplus output (PN_MODEL_OUTPUT_SOFTPLUS) is applied
   here: m -> log(1 + e^m), g -> sig g, H -> sig H + sig (1 - sig) g g^T, sig = 1/(1 + e^-m). */
static pn_result pn__mlp_call(const pn_mlp *mlp, int softplus, const pn_real *u, int nu, int nd, int want_h,
                              const pn_real *seed, int ns, pn__mlp_io *io, pn_real *m, pn_real *gm, pn_real *hm) {
    int i, j, dirs = 0;
    pn_real x, sg, gs[3];
    if (!io || io->mode == 0) {
        pn_result r = pn_mlp_eval(mlp, u, nd, m, gm, want_h ? hm : NULL);
        if (r != PN_OK) return r;
    } else if (io->mode == 1) {
        memcpy(io->u, u, sizeof(pn_real) * (size_t)nu);
        io->nu = nu;
        io->nd = nd;
        io->ns = want_h && seed && nu <= PN_MLP_MAX_WIDTH ? ns : 0;
        if (io->ns) memcpy(io->seed, seed, sizeof(pn_real) * (size_t)(ns * nu));
        return PN_OK;
    } else {
        *m = io->m;
        for (i = 0; i < nd; ++i) gm[i] = io->gm[i];
        for (i = 0; want_h && i < (io->ns ? io->ns * io->ns : nd * nd); ++i) hm[i] = io->hm[i];
        dirs = io->ns;
    }
    if (!softplus) return PN_OK;
    x = *m;
    sg = 1 / (1 + PN__EXP(-x));
    *m = x > 0 ? x + PN__LOG1P(PN__EXP(-x)) : PN__LOG1P(PN__EXP(x));
    if (want_h && nd > 0) {
        if (dirs) { /* along the directions: the gradient's component on each */
            for (j = 0; j < dirs; ++j)
                for (gs[j] = 0, i = 0; i < nd; ++i) gs[j] += gm[i] * io->seed[j * io->nu + i];
            for (j = 0; j < dirs; ++j)
                for (i = 0; i < dirs; ++i) hm[j * dirs + i] = sg * hm[j * dirs + i] + sg * (1 - sg) * gs[j] * gs[i];
        } else {
            for (j = 0; j < nd; ++j)
                for (i = 0; i < nd; ++i) hm[j * nd + i] = sg * hm[j * nd + i] + sg * (1 - sg) * gm[j] * gm[i];
        }
    }
    for (i = 0; i < nd; ++i) gm[i] *= sg;
    return PN_OK;
}

static pn_result pn__pnet_scaled(const pn_model *mo, const pn_real *y, const pn_real *y0, pn_real h, const pn_real *cond,
                                 int level, pn_real *N, pn_real *gN, pn_real *HN, pn__mlp_io *io) {
    int nf = pn__model_nf(mo), nr = 2 * nf + 1, nu = nr + 1 + mo->n_params, d = mo->dim, i, j, l, k;
    pn_real c = d == 2 ? 1 : (pn_real)1.5, q0, S, s, qj[3] = {0, 0, 0}, qjl[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    pn_real sj[3], sjl[3][3]; /* qj, qjl zeroed: gcc -O3 cannot see that nf >= 2 fills them */
    pn_real a[3], a1[3], a2[3], raw[8], u[8 + PN_MODEL_MAX_PARAMS], J[7][3], K[7][3][3], m, gm[7], hm[7 * 7];
    pn_real gr[7], Mj[3], Mjl[3][3], seed[3 * (8 + PN_MODEL_MAX_PARAMS)];
    pn_result r;
    q0 = y0[0] * y0[0] / d + c * y0[1];
    S = y[0] * y[0] / d + c * y[1] + q0 + (pn_real)(PN__SCALED_EPS * PN__SCALED_EPS);
    /* q >= 0 exactly (y[1] = log cosh of a stretch difference in 2D, AM-GM sums in 3D), but
       a float y[1] of a near-isotropic F rounds to -1e-7, below the 1e-12 floor: S < 0 and a
       NaN. The floor holds it; in double S dips below it by rounding at most (1e-16). */
    S = PN__MAX(S, (pn_real)(PN__SCALED_EPS * PN__SCALED_EPS));
    s = PN__SQRT(S);
    for (j = 0; j < nf; ++j) {
        qj[j] = j == 0 ? 2 * y[0] / d : (j == 1 ? c : 0);
        for (l = 0; l < nf; ++l) qjl[j][l] = j == 0 && l == 0 ? (pn_real)2 / d : 0;
    }
    for (j = 0; j < nf; ++j) sj[j] = qj[j] / (2 * s);
    for (j = 0; j < nf; ++j)
        for (l = 0; l < nf; ++l) sjl[j][l] = qjl[j][l] / (2 * s) - qj[j] * qj[l] / (4 * S * s);
    for (k = 0; k < nf; ++k) { /* a_k = s^-p and its derivatives in s */
        int p = k == 0 ? 1 : 2;
        /* 1 / s and 1 / S (as gen/pn_torch.py divides), not pow(s, -p): a compiler that peels
           or unrolls this loop sees pow(s, -1.0) and folds it to 1 / s (clang -O2, gcc -O3),
           while a libm call is not always correctly rounded, so the bits would depend on the
           compiler and the optimization level (THREADS AND DETERMINISM). */
        a[k] = p == 1 ? 1 / s : 1 / S;
        a1[k] = -p * a[k] / s;
        a2[k] = p * (p + 1) * a[k] / S;
    }
    for (k = 0; k < nf; ++k) {
        raw[k] = (y[k] - y0[k]) * a[k];
        raw[nf + k] = y0[k] * a[k];
    }
    raw[2 * nf] = s;
    raw[2 * nf + 1] = PN__MIN(PN__MAX(h, (pn_real)mo->h_min), (pn_real)mo->h_max);
    for (i = 0; i < nr + 1; ++i) u[i] = (raw[i] - (pn_real)mo->in_shift[i]) * (pn_real)mo->in_scale[i];
    for (i = nr + 1; i < nu; ++i) u[i] = (cond[i - nr - 1] - (pn_real)mo->in_shift[i]) * (pn_real)mo->in_scale[i];
    /* J = d raw / d y (nr x nf) and K = d2 raw / d y2, known before the network: with lanes,
       its Hessian is taken along J's columns (in u), one direction per feature */
    for (k = 0; k < nf; ++k)
        for (j = 0; j < nf; ++j) {
            J[k][j] = (k == j ? a[k] : 0) + (y[k] - y0[k]) * a1[k] * sj[j];
            J[nf + k][j] = y0[k] * a1[k] * sj[j];
        }
    for (j = 0; j < nf; ++j) J[2 * nf][j] = sj[j];
    for (j = 0; j < nf; ++j) {
        for (i = 0; i < nr; ++i) seed[j * nu + i] = (pn_real)mo->in_scale[i] * J[i][j];
        for (i = nr; i < nu; ++i) seed[j * nu + i] = 0; /* h and the material are not functions of F */
    }
    r = pn__mlp_call(&mo->mlp, mo->output == PN_MODEL_OUTPUT_SOFTPLUS, u, nu, level > 0 ? nr : 0, level > 1, seed, nf, io,
                     &m, gm, hm);
    if (r != PN_OK || (io && io->mode == 1)) return r;
    *N = S * m;
    if (level < 1) return PN_OK;
    for (i = 0; i < nr; ++i) gr[i] = gm[i] * (pn_real)mo->in_scale[i];
    for (j = 0; j < nf; ++j) {
        Mj[j] = 0;
        for (i = 0; i < nr; ++i) Mj[j] += gr[i] * J[i][j];
        gN[j] = qj[j] * m + S * Mj[j];
    }
    if (level < 2) return PN_OK;
    for (k = 0; k < nf; ++k)
        for (j = 0; j < nf; ++j)
            for (l = 0; l < nf; ++l) {
                pn_real da = a2[k] * sj[j] * sj[l] + a1[k] * sjl[j][l];
                K[k][j][l] = (k == j ? a1[k] * sj[l] : 0) + (k == l ? a1[k] * sj[j] : 0) + (y[k] - y0[k]) * da;
                K[nf + k][j][l] = y0[k] * da;
            }
    for (j = 0; j < nf; ++j)
        for (l = 0; l < nf; ++l) K[2 * nf][j][l] = sjl[j][l];
    for (j = 0; j < nf; ++j)
        for (l = 0; l < nf; ++l) {
            pn_real acc = 0;
            for (i = 0; i < nr; ++i) {
                pn_real t = 0;
                if (!(io && io->ns)) /* the full Hessian (double path): J^T H J here */
                    for (k = 0; k < nr; ++k) t += hm[i * nr + k] * (pn_real)mo->in_scale[k] * J[k][l];
                acc += (pn_real)mo->in_scale[i] * J[i][j] * t + gr[i] * K[i][j][l];
            }
            Mjl[j][l] = acc + (io && io->ns ? hm[j * nf + l] : 0);
        }
    for (j = 0; j < nf; ++j)
        for (l = 0; l < nf; ++l) HN[j * nf + l] = qjl[j][l] * m + qj[j] * Mj[l] + qj[l] * Mj[j] + S * Mjl[j][l];
    return PN_OK;
}

/* N and its derivatives with respect to F at F (features f, level as in pn__features_eval). */
static pn_result pn__pnet_network(const pn_pnet *net, const pn_pnet_point *pt, int d,
                                  const pn__features *f, int level, pn_real *N, pn_real *gN,
                                  pn_real *HN, pn__mlp_io *io) {
    const pn_model *mo = net->energy;
    pn_real u[16], out, g[3], H[9], h, s;
    int nf = f->nf, i, k, l, a, b, n = d * d;
    pn_result r;
    h = PN__MIN(PN__MAX(pt->h, (pn_real)mo->h_min), (pn_real)mo->h_max);
    s = net->scale * (pn_real)mo->out_scale;
    if (pn__model_scaled(mo)) {
        r = pn__pnet_scaled(mo, f->x, pt->x0, pt->h, net->cond, level, &out, g, H, io);
        if (r != PN_OK || (io && io->mode == 1)) return r;
        for (k = 0; level > 0 && k < nf; ++k) g[k] *= s; /* only what was asked is set */
        for (k = 0; level > 1 && k < nf * nf; ++k) H[k] *= s;
    } else {
        for (i = 0; i < nf; ++i) {
            u[i] = (f->x[i] - pt->x0[i] - (pn_real)mo->in_shift[i]) * (pn_real)mo->in_scale[i];
            u[nf + i] = (pt->x0[i] - (pn_real)mo->in_shift[nf + i]) * (pn_real)mo->in_scale[nf + i];
        }
        u[2 * nf] = (h - (pn_real)mo->in_shift[2 * nf]) * (pn_real)mo->in_scale[2 * nf];
        for (i = 0; i < mo->n_params; ++i)
            u[2 * nf + 1 + i] = (net->cond[i] - (pn_real)mo->in_shift[2 * nf + 1 + i]) * (pn_real)mo->in_scale[2 * nf + 1 + i];
        r = pn__mlp_call(&mo->mlp, mo->output == PN_MODEL_OUTPUT_SOFTPLUS, u, 2 * nf + 1 + mo->n_params, level > 0 ? nf : 0,
                         level > 1, NULL, 0, io, &out, g, H);
        if (r != PN_OK || (io && io->mode == 1)) return r;
        /* chain rule through u_k = (x_k - x0_k - shift_k) scale_k */
        for (k = 0; level > 0 && k < nf; ++k) g[k] *= s * (pn_real)mo->in_scale[k];
        for (k = 0; level > 1 && k < nf; ++k)
            for (l = 0; l < nf; ++l) H[k * nf + l] *= s * (pn_real)(mo->in_scale[k] * mo->in_scale[l]);
    }
    *N = s * out;
    if (level > 0) {
        for (a = 0; a < n; ++a) {
            pn_real acc = 0;
            for (k = 0; k < nf; ++k) acc += g[k] * f->dx[k][a];
            gN[a] = acc;
        }
    }
    if (level > 1) {
        for (a = 0; a < n; ++a)
            for (b = a; b < n; ++b) {
                pn_real acc = 0;
                for (k = 0; k < nf; ++k) {
                    pn_real hk = 0;
                    for (l = 0; l < nf; ++l) hk += H[k * nf + l] * f->dx[l][b];
                    acc += f->dx[k][a] * hk + g[k] * f->d2x[k][a * n + b];
                }
                HN[a * n + b] = acc;
                HN[b * n + a] = acc;
            }
    }
    return PN_OK;
}

/* The point's frozen yield stress of a PN_MODEL_BASE_DP_FROZEN base (0 for the others) */
static pn_result pn__pnet_base_prepare(const pn_pnet *net, pn_pnet_point *pt) {
    pt->tau_y = 0;
    if (net->energy->base != PN_MODEL_BASE_DP_FROZEN) return PN_OK;
    return pn_dp_prepare(&net->base, net->energy->dim, pt->F0, pt->h, &pt->tau_y);
}

/* Add the model's base energy B(F; F0, h) (pn_model.base) at a point to e, g (level > 0) and
   H (level > 1). */
static pn_result pn__pnet_base(const pn_pnet *net, const pn_pnet_point *pt, const pn_real *F, int level, pn_real *e,
                               pn_real *g, pn_real *H) {
    int d = net->energy->dim, n = d * d, a;
    pn_real b, gb[9], Hb[81];
    pn_result r;
    if (net->energy->base == PN_MODEL_BASE_NONE) return PN_OK;
    if (net->energy->base == PN_MODEL_BASE_DP_FROZEN)
        r = pn_dp_energy(&net->base, d, F, pt->h, pt->tau_y, &b, level > 0 ? gb : NULL, level > 1 ? Hb : NULL, 0);
    else
        r = pn_von_mises_energy(&net->base, d, F, pt->h, &b, level > 0 ? gb : NULL, level > 1 ? Hb : NULL, 0);
    if (r != PN_OK) return r;
    *e += b;
    for (a = 0; level > 0 && a < n; ++a) g[a] += gb[a];
    for (a = 0; level > 1 && a < n * n; ++a) H[a] += Hb[a];
    return PN_OK;
}

PN__DEF pn_result pn_pnet_prepare(const pn_pnet *net, const pn_real *F0, pn_real h,
                                  pn_pnet_point *pt, pn_real *h_new, pn_real *T0) {
    pn_pnet_point p;
    pn__features f;
    pn_real T[9], hn, N, gN[9];
    int d, n, i;
    pn_result r;
    PN_ASSERT(net && net->energy && F0 && pt);
    d = net->energy->dim;
    n = d * d;
    r = pn__check_F(d, F0);
    if (r != PN_OK) return r;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    if (!(pn_mat_det(d, F0) > 0)) return PN_ERROR_INVERTED;
    r = net->return_map ? pn_learned_return_map(net->return_map, &net->material, d, F0, h, NULL, &hn, T)
                        : pn_return_map(&net->material, d, F0, h, NULL, &hn, T);
    if (r != PN_OK) return r;
    memset(&p, 0, sizeof p);
    memcpy(p.F0, F0, sizeof(pn_real) * (size_t)n);
    p.h = h;
    pn__features_eval(d, F0, 1, &f);
    for (i = 0; i < f.nf; ++i) p.x0[i] = f.x[i];
    memset(gN, 0, sizeof gN); /* gcc cannot always see that the network fills the d^2 the base adds to */
    r = pn__pnet_network(net, &p, d, &f, 1, &N, gN, NULL, NULL);
    if (r == PN_OK) r = pn__pnet_base_prepare(net, &p);
    if (r == PN_OK) r = pn__pnet_base(net, &p, F0, 1, &N, gN, NULL);
    if (r != PN_OK) return r;
    for (i = 0; i < n; ++i) p.C[i] = gN[i] - T[i];
    if (!pn__all_finite(n, p.C)) return PN_ERROR_OVERFLOW;
    *pt = p;
    if (h_new) *h_new = hn;
    if (T0) memcpy(T0, T, sizeof(pn_real) * (size_t)n);
    return PN_OK;
}

static pn_result pn__pnet_finish(const pn_pnet *net, const pn_pnet_point *pt, const pn_real *F, int level, pn_real N,
                                 pn_real *gN, pn_real *HN, unsigned flags, pn_real *psi, pn_real *P, pn_real *dPdF);

PN__DEF pn_result pn_pnet_energy(const pn_pnet *net, const pn_pnet_point *pt, const pn_real *F,
                                 pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags) {
    pn__features f;
    pn_real N, gN[9], HN[81];
    int d, level;
    pn_result r;
    PN_ASSERT(net && net->energy && pt && F);
    d = net->energy->dim;
    r = pn__check_F(d, F);
    if (r != PN_OK) return r;
    if (!(pn_mat_det(d, F) > 0)) return PN_ERROR_INVERTED;
    level = dPdF ? 2 : (P ? 1 : 0);
    pn__features_eval(d, F, level, &f);
    r = pn__pnet_network(net, pt, d, &f, level, &N, gN, HN, NULL);
    if (r != PN_OK) return r;
    return pn__pnet_finish(net, pt, F, level, N, gN, HN, flags, psi, P, dPdF);
}

/* The strain regularizer R = w mu/8 |D|^2, D = F^T F - F0^T F0: with k = w mu / 2,
   P_R = k F D and dP_R_ij / dF_lm = k (delta_il D_mj + F_im F_lj + delta_jm (F F^T)_il). */
static void pn__pnet_strain_reg(int d, pn_real k, const pn_real *F, const pn_real *F0, int level, pn_real *e,
                                pn_real *g, pn_real *H) {
    int n = d * d, i, j, l, m;
    pn_real D[9], FF[9];
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) {
            pn_real c = 0, ff = 0;
            for (l = 0; l < d; ++l) {
                c += F[l * d + i] * F[l * d + j] - F0[l * d + i] * F0[l * d + j];
                ff += F[i * d + l] * F[j * d + l];
            }
            D[i * d + j] = c, FF[i * d + j] = ff;
        }
    for (i = 0; i < n; ++i) *e += k / 4 * D[i] * D[i];
    if (level > 0)
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j)
                for (l = 0; l < d; ++l) g[i * d + j] += k * F[i * d + l] * D[l * d + j];
    if (level > 1)
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j)
                for (l = 0; l < d; ++l)
                    for (m = 0; m < d; ++m)
                        H[(i * d + j) * n + l * d + m] +=
                            k * ((i == l ? D[m * d + j] : 0) + F[i * d + m] * F[l * d + j] + (j == m ? FF[i * d + l] : 0));
}

/* pn_pnet_energy after the network: the base energy, the linear correction, the regularizer
   (Eq. 11 or the strain form), the PSD projection, checks */
static pn_result pn__pnet_finish(const pn_pnet *net, const pn_pnet_point *pt, const pn_real *F, int level, pn_real N,
                                 pn_real *gN, pn_real *HN, unsigned flags, pn_real *psi, pn_real *P, pn_real *dPdF) {
    int n = net->energy->dim * net->energy->dim, a, strain = net->reg_form == PN_PNET_REG_STRAIN;
    pn_real e;
    pn_result r;
    e = N;
    r = pn__pnet_base(net, pt, F, level, &e, gN, HN);
    if (r != PN_OK) return r;
    for (a = 0; a < n; ++a) {
        pn_real df = F[a] - pt->F0[a];
        e += -pt->C[a] * F[a];
        if (level > 0) gN[a] += -pt->C[a];
        if (strain) continue;
        e += net->reg / 2 * df * df;
        if (level > 0) gN[a] += net->reg * df;
        if (level > 1) HN[a * n + a] += net->reg;
    }
    if (strain && net->reg > 0) pn__pnet_strain_reg(net->energy->dim, net->reg / 2, F, pt->F0, level, &e, gN, HN);
    if (level > 1 && (flags & PN_EVAL_PROJECT_PSD)) {
        if (!pn__all_finite(n * n, HN)) return PN_ERROR_OVERFLOW;
        r = pn_sym_project_psd(n, HN);
        if (r != PN_OK) return r;
    }
    if (!pn__finite(e) || (level > 0 && !pn__all_finite(n, gN)) || (level > 1 && !pn__all_finite(n * n, HN)))
        return PN_ERROR_OVERFLOW;
    if (psi) *psi = e;
    if (P) memcpy(P, gN, sizeof(pn_real) * (size_t)n);
    if (dPdF) memcpy(dPdF, HN, sizeof(pn_real) * (size_t)(n * n));
    return PN_OK;
}

PN__DEF pn_result pn_pnet_energy_lanes(const pn_pnet *net, int n, const pn_pnet_point *const *pt, const pn_real *F,
                                       pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags, pn_result *status) {
    enum { L = PN_MLP_LANES };
    pn__features f[PN_MLP_LANES];
    pn__mlp_io io[PN_MLP_LANES];
    float xin[PN_MLP_MAX_WIDTH * L], m[L], gm[PN_MLP_MAX_DIFF * L], hm[PN_MLP_MAX_DIFF * PN_MLP_MAX_DIFF * L];
    float seed[3 * PN_MLP_MAX_WIDTH * L];
    int d, dd, level, i, k, first = -1, nu = 0, nd = 0, ns = 0, nh;
    pn_result r, worst = PN_OK;
    PN_ASSERT(net && net->energy && pt && F && status);
    if (n < 1 || n > L) return PN_ERROR_INVALID_ARGUMENT;
    d = net->energy->dim;
    dd = d * d;
    level = dPdF ? 2 : (P ? 1 : 0);
    for (i = 0; i < n; ++i) { /* features and network inputs, in pn_real */
        const pn_real *Fi = F + i * dd;
        pn_real N;
        status[i] = pn__check_F(d, Fi);
        if (status[i] == PN_OK && !(pn_mat_det(d, Fi) > 0)) status[i] = PN_ERROR_INVERTED;
        if (status[i] != PN_OK) continue;
        pn__features_eval(d, Fi, level, &f[i]);
        io[i].mode = 1;
        status[i] = pn__pnet_network(net, pt[i], d, &f[i], level, &N, NULL, NULL, &io[i]);
        if (status[i] != PN_OK) continue;
        if (first < 0) first = i, nu = io[i].nu, nd = io[i].nd, ns = io[i].ns;
    }
    if (first >= 0) { /* the network in float lanes (points that failed repeat the first good one) */
        for (i = 0; i < L; ++i) {
            int src = i < n && status[i] == PN_OK ? i : first;
            for (k = 0; k < nu; ++k) xin[k * L + i] = (float)io[src].u[k];
            for (k = 0; k < ns * nu; ++k) seed[k * L + i] = (float)io[src].seed[k];
        }
        r = pn__mlp_eval_lanes_dir(&net->energy->mlp, L, xin, ns ? seed : NULL, level > 0 ? nd : 0,
                                   level > 1 ? (ns ? ns : nd) : 0, m, gm, level > 1 ? hm : NULL);
        for (i = 0; i < n; ++i) {
            pn_real N, gN[9], HN[81];
            if (status[i] != PN_OK) continue;
            if (r != PN_OK) { /* no lane path for this network, or a lane overflowed: one at a time */
                status[i] = pn_pnet_energy(net, pt[i], F + i * dd, psi ? psi + i : NULL, P ? P + i * dd : NULL,
                                           dPdF ? dPdF + i * dd * dd : NULL, flags);
                continue;
            }
            io[i].mode = 2;
            io[i].m = (pn_real)m[i];
            for (k = 0; k < nd; ++k) io[i].gm[k] = (pn_real)gm[k * L + i];
            nh = ns ? ns * ns : nd * nd;
            for (k = 0; level > 1 && k < nh; ++k) io[i].hm[k] = (pn_real)hm[k * L + i];
            status[i] = pn__pnet_network(net, pt[i], d, &f[i], level, &N, gN, HN, &io[i]);
            if (status[i] == PN_OK)
                status[i] = pn__pnet_finish(net, pt[i], F + i * dd, level, N, gN, HN, flags, psi ? psi + i : NULL,
                                            P ? P + i * dd : NULL, dPdF ? dPdF + i * dd * dd : NULL);
        }
    }
    for (i = 0; i < n; ++i)
        if (worst == PN_OK) worst = status[i];
    return worst;
}

PN__DEF pn_result pn_pnet_prepare_lanes(const pn_pnet *net, int n, const pn_real *F0, const pn_real *h,
                                        pn_pnet_point *pt, pn_result *status) {
    enum { L = PN_MLP_LANES };
    pn__features f[PN_MLP_LANES];
    pn__mlp_io io[PN_MLP_LANES];
    pn_pnet_point q[PN_MLP_LANES]; /* written to pt only where it succeeds */
    pn_real T[PN_MLP_LANES][9];
    float xin[PN_MLP_MAX_WIDTH * L], m[L], gm[PN_MLP_MAX_DIFF * L];
    int d, dd, i, k, first = -1, nu = 0, nd = 0;
    pn_result r, worst = PN_OK;
    PN_ASSERT(net && net->energy && F0 && h && pt && status);
    if (n < 1 || n > L) return PN_ERROR_INVALID_ARGUMENT;
    d = net->energy->dim;
    dd = d * d;
    for (i = 0; i < n; ++i) { /* the return mapping, features and network inputs, in pn_real */
        const pn_real *Fi = F0 + i * dd;
        pn_real N, hn;
        status[i] = pn__check_F(d, Fi);
        if (status[i] == PN_OK && !pn__finite(h[i])) status[i] = PN_ERROR_NONFINITE;
        if (status[i] == PN_OK && !(pn_mat_det(d, Fi) > 0)) status[i] = PN_ERROR_INVERTED;
        if (status[i] == PN_OK)
            status[i] = net->return_map ? pn_learned_return_map(net->return_map, &net->material, d, Fi, h[i], NULL, &hn, T[i])
                                        : pn_return_map(&net->material, d, Fi, h[i], NULL, &hn, T[i]);
        if (status[i] != PN_OK) continue;
        memset(&q[i], 0, sizeof q[i]);
        memcpy(q[i].F0, Fi, sizeof(pn_real) * (size_t)dd);
        q[i].h = h[i];
        pn__features_eval(d, Fi, 1, &f[i]);
        for (k = 0; k < f[i].nf; ++k) q[i].x0[k] = f[i].x[k];
        io[i].mode = 1;
        status[i] = pn__pnet_network(net, &q[i], d, &f[i], 1, &N, NULL, NULL, &io[i]);
        if (status[i] == PN_OK && first < 0) first = i, nu = io[i].nu, nd = io[i].nd;
    }
    if (first >= 0) {
        for (i = 0; i < L; ++i) {
            int src = i < n && status[i] == PN_OK ? i : first;
            for (k = 0; k < nu; ++k) xin[k * L + i] = (float)io[src].u[k];
        }
        r = pn__mlp_eval_lanes_dir(&net->energy->mlp, L, xin, NULL, nd, 0, m, gm, NULL);
        for (i = 0; i < n; ++i) {
            pn_real N, gN[9];
            if (status[i] != PN_OK) continue;
            if (r != PN_OK) { /* no lane path, or a lane overflowed: one at a time */
                status[i] = pn_pnet_prepare(net, F0 + i * dd, h[i], &pt[i], NULL, NULL);
                continue;
            }
            io[i].mode = 2;
            io[i].m = (pn_real)m[i];
            for (k = 0; k < nd; ++k) io[i].gm[k] = (pn_real)gm[k * L + i];
            memset(gN, 0, sizeof gN);
            status[i] = pn__pnet_network(net, &q[i], d, &f[i], 1, &N, gN, NULL, &io[i]);
            if (status[i] == PN_OK) status[i] = pn__pnet_base_prepare(net, &q[i]);
            if (status[i] == PN_OK) status[i] = pn__pnet_base(net, &q[i], q[i].F0, 1, &N, gN, NULL);
            for (k = 0; status[i] == PN_OK && k < dd; ++k) q[i].C[k] = gN[k] - T[i][k];
            if (status[i] == PN_OK && !pn__all_finite(dd, q[i].C)) status[i] = PN_ERROR_OVERFLOW;
            if (status[i] == PN_OK) pt[i] = q[i];
        }
    }
    for (i = 0; i < n; ++i)
        if (worst == PN_OK) worst = status[i];
    return worst;
}

/* ======================================================================================
   >>learned-return: von Mises return mapping with a learned plastic multiplier (Li et al.
   2022, Eqs. 12-13). Outside the analytic yield surface, H = e - dgamma n with
     dgamma = clamp(|e_hat| - r, 0, |e_hat|),  r = r_ref exp(out_scale mlp(u)),
     r_ref = (sqrt(2/3) sigma_Y(h) + 2K/3 |e_hat|) / (2 mu J^(2/d) + 2K/3)  (small-strain radius)
     u = ([tr e, |e_hat|, (3D) sqrt(6) sum n_i^3, clamp(h)] - in_shift) * in_scale
   ====================================================================================== */

PN__DEF pn_result pn_learned_return_map(const pn_model *mo, const pn_material *m, int d,
                                        const pn_real *F, pn_real h, pn_real *Z, pn_real *h_new,
                                        pn_real *T) {
    pn_real U[9], s[3], V[9], z[3] = {1, 1, 1}, e[3], eh[3], tr, rr, y, sc, hn = h, w[3], zz[9], tt[9];
    pn_real raw[4], u[4], out, rad, rref, dg, K, hc;
    int i, nr, n = d * d, plastic = 0;
    pn_result r;
    PN_ASSERT(mo && m && F);
    r = pn__model_check_why(mo, d, NULL);
    if (r != PN_OK) return r;
    if (mo->kind != PN_MODEL_RETURN_MAP) return PN_ERROR_INVALID_ARGUMENT;
    r = pn__model_matches(mo, m, NULL);
    if (r != PN_OK) return r;
    r = pn__check_F(d, F);
    if (r != PN_OK) return r;
    if (!pn__finite(h)) return PN_ERROR_NONFINITE;
    if (!(h >= 0)) return PN_ERROR_INVALID_ARGUMENT;
    pn__svd(d, F, U, s, V);
    if (!(s[d - 1] > 0)) return PN_ERROR_INVERTED;
    for (i = 0; i < d; ++i) z[i] = s[i];
    pn__yield_principal(m, d, s, h, &y, &sc);
    if (y > 0) {
        pn__hencky_split(d, s, 0, 0, e, eh, &tr, &rr);
        K = m->hardening_modulus;
        hc = PN__MIN(PN__MAX(h, (pn_real)mo->h_min), (pn_real)mo->h_max);
        nr = 0;
        raw[nr++] = tr;
        raw[nr++] = rr;
        if (d == 3) {
            pn_real c3 = 0;
            for (i = 0; i < 3; ++i) c3 += (eh[i] / rr) * (eh[i] / rr) * (eh[i] / rr);
            raw[nr++] = PN__SQRT(6) * c3;
        }
        raw[nr++] = hc;
        for (i = 0; i < nr; ++i) u[i] = (raw[i] - (pn_real)mo->in_shift[i]) * (pn_real)mo->in_scale[i];
        r = pn_mlp_eval(&mo->mlp, u, 0, &out, NULL, NULL);
        if (r != PN_OK) return r;
        rref = (pn__vm_tau_y(m, h) + 2 * K / 3 * rr) / (2 * m->mu * PN__EXP(2 * tr / d) + 2 * K / 3);
        rad = rref * PN__EXP((pn_real)mo->out_scale * out);
        dg = PN__MIN(PN__MAX(rr - rad, 0), rr);
        for (i = 0; i < d; ++i) z[i] = PN__EXP(e[i] - dg * eh[i] / rr);
        hn = h + PN__SQRT((pn_real)2 / 3) * dg;
        plastic = 1;
    }
    if (plastic) pn__udvt(d, U, z, V, zz);
    else memcpy(zz, F, sizeof(pn_real) * (size_t)n);
    pn__tau_principal(m, hn, d, z, w);
    for (i = 0; i < d; ++i) w[i] /= s[i];
    pn__udvt(d, U, w, V, tt);
    if (!pn__finite(hn) || !pn__all_finite(n, zz) || !pn__all_finite(n, tt)) return PN_ERROR_OVERFLOW;
    if (Z) memcpy(Z, zz, sizeof(pn_real) * (size_t)n);
    if (h_new) *h_new = hn;
    if (T) memcpy(T, tt, sizeof(pn_real) * (size_t)n);
    return PN_OK;
}

#endif /* PLASTINET_IMPLEMENTATION */

/*
------------------------------------------------------------------------------
This software is available under 2 licenses -- choose whichever you prefer.
------------------------------------------------------------------------------
ALTERNATIVE A - MIT License
Copyright (c) 2026 the plastinet authors
Permission is hereby granted, free of charge, to any person obtaining a copy of
this software and associated documentation files (the "Software"), to deal in
the Software without restriction, including without limitation the rights to
use, copy, modify, merge, publish, distribute, sublicense, and/or sell copies
of the Software, and to permit persons to whom the Software is furnished to do
so, subject to the following conditions:
The above copyright notice and this permission notice shall be included in all
copies or substantial portions of the Software.
THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE
SOFTWARE.
------------------------------------------------------------------------------
ALTERNATIVE B - Public Domain (www.unlicense.org)
This is free and unencumbered software released into the public domain.
Anyone is free to copy, modify, publish, use, compile, sell, or distribute this
software, either in source code form or as a compiled binary, for any purpose,
commercial or non-commercial, and by any means.
In jurisdictions that recognize copyright laws, the author or authors of this
software dedicate any and all copyright interest in the software to the public
domain. We make this dedication in the belief that its use will be of greater
benefit to the public at large and to the detriment of our heirs and
successors. We intend this dedication to be an overt act of relinquishment in
perpetuity of all present and future rights to this software under copyright
law.
------------------------------------------------------------------------------
*/
