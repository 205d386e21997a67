/* plastinet.h - v0.1 - elastoplastic constitutive core for sand, snow, metal and rubber.
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
       memset(&d, 0, sizeof d);                       // zeroed fields mean defaults
       d.plastic = PN_PLASTIC_DRUCKER_PRAGER;         // elastic defaults to StVK-Hencky
       d.youngs_modulus_pa = 1e7; d.poisson_ratio = 0.3; d.friction_angle_deg = 30;
       if (pn_material_init(&sand, &d, &why) != PN_OK) puts(why);

       pn_real F[9] = {...}, Z[9], T[9], h = 0, h_new;   // 3x3 row-major
       pn_return_map(&sand, 3, F, h, Z, &h_new, T);      // project F onto the yield surface;
                                                        // T = tau(Z(F)) F^-T, the force density

   Matrices are row-major arrays of dim*dim reals (F[i*dim+j] = F_ij), dim = 2 or 3.
   A pn_real[9] serves both dimensions. Fourth-order tensors (dP/dF) are dim^2 x dim^2
   row-major: dPdF[(i*dim+j)*dim*dim + k*dim+l] = dP_ij / dF_kl.

   What is here (greppable banners in the implementation: // >>name):
     >>matrix   small dense 2D/3D matrix helpers
     >>svd      SVD with rotation-valued U and V (det +1), the sign of an inverted F carried
                by the smallest singular value; polar decomposition; Hencky strain
     >>eigen    symmetric eigen-decomposition (Jacobi) and PSD projection, n <= 9
     >>material parameter validation, Lame constants
     >>elastic  fixed corotated, StVK-Hencky, Neo-Hookean, and the Neo-Hookean variant used by
                Cam-Clay snow: energy, P, dP/dF, PSD-projected dP/dF
     >>return-mapping  Drucker-Prager (sand), von Mises (metal, closed form for StVK-Hencky,
                safeguarded root find otherwise), non-associative Cam-Clay (snow), and the
                singular-value clamp snow of Stomakhin et al. 2013
     >>energy-vm      exact StVK-Hencky + von Mises elastoplastic energy (frozen yield stress)
     >>energy-lagged  lagged-plasticity energy Psi_el(F G), G = F0^-1 Z(F0)

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

   ======================================================================================
   MEMORY
   ======================================================================================
   The core allocates nothing: every function works on caller-provided arrays. Solvers built
   on it take a pn_allocator (both callbacks or neither, with a user pointer) and store it with
   the object they allocate.

   ======================================================================================
   ERRORS
   ======================================================================================
   Every fallible call returns a pn_result; pn_result_string() explains it. Bad data (NaN or
   inf, impossible parameters, a deformation where the model is undefined) never crashes and
   never writes a partial result: on any error every output is left exactly as it was.
   pn_material_init additionally names the offending parameter. NULL required pointers and
   similar programming errors trip PN_ASSERT.

   Inverted deformations: the Hencky-strain models (StVK-Hencky, Drucker-Prager, von Mises,
   exact von Mises energy) and the Neo-Hookean models are undefined for det F <= 0 and return
   PN_ERROR_INVERTED. Fixed corotated is defined for every F (singular at s_i + s_j = 0 only in
   its Hessian, where the rotation is undefined).

   ======================================================================================
   THREADS AND DETERMINISM
   ======================================================================================
   No global state: every function is reentrant and may run on any number of threads at once.
   Results depend only on the inputs (no randomness, no thread-count dependence). For bitwise
   identical results across compilers compile without -ffast-math and with -ffp-contract=off.

   ======================================================================================
   VERSION HISTORY
   ======================================================================================
     0.1  constitutive core: deformation math, elastic energies, return mappings,
          exact von Mises and lagged-plasticity energies.
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
#define PN_VERSION_MINOR 1

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
    PN_ERROR_FORMAT,            /* a model of an unknown format version                    */
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

/* Symmetric eigen-decomposition A = Q diag(w) Q^T (cyclic Jacobi), n <= 9, Q row-major with
   eigenvectors as columns, w ascending. A must be symmetric (only the upper part is read). */
PN_API pn_result pn_sym_eigen(int n, const pn_real *A, pn_real *Q, pn_real *w);
/* Replace symmetric A (n x n, n <= 9) with its nearest positive semi-definite matrix. */
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
} pn_material;

/* Validate desc and fill m. On failure m is untouched, and *why (if why is not NULL) points to
   a static sentence naming the offending parameter. */
PN_API pn_result pn_material_init(pn_material *m, const pn_material_desc *desc, const char **why);

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
enum { PN_EVAL_PROJECT_PSD = 1 }; /* dP/dF replaced by its nearest PSD matrix (for Newton) */

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
   Z = F and h_new = h (except that a Drucker-Prager volume correction is absorbed into Z). */
PN_API pn_result pn_return_map(const pn_material *m, int dim, const pn_real *F, pn_real h,
                               pn_real *Z, pn_real *h_new, pn_real *T);

/* Yield function at an elastic F and state h: <= 0 inside, 0 on the surface. Units:
   Drucker-Prager and von Mises Pa (|dev tau| + alpha tr tau resp. |dev tau| - sqrt(2/3)
   sigma_Y), Cam-Clay Pa^2 ((1 + 2 beta) q^2 + M^2 (p + beta p0)(p - p0)), Stomakhin
   dimensionless (distance of the singular values outside [1 - theta_c, 1 + theta_s]),
   NONE: -1. A scale (same units) for relative residuals goes to *scale if not NULL. */
PN_API pn_result pn_yield_function(const pn_material *m, int dim, const pn_real *F, pn_real h,
                                   pn_real *y, pn_real *scale);

/* ---- elastoplastic energies -------------------------------------------------------------- */

/* Exact StVK-Hencky + von Mises energy with the yield stress frozen at sigma_Y0 + K h
   (perfect plasticity within one minimization): its gradient is tau(Z(F)) F^-T of the
   return mapping with that yield stress. C1 across the yield surface. Needs a von Mises
   material with StVK-Hencky elasticity (PN_ERROR_UNSUPPORTED otherwise). */
PN_API pn_result pn_von_mises_energy(const pn_material *m, int dim, const pn_real *F, pn_real h,
                                     pn_real *psi, pn_real *P, pn_real *dPdF, unsigned flags);

/* Lagged-plasticity energy Psi_lag(F; F0) = psi_el(F G, h_G), G = F0^-1 Z(F0, h0): the
   no-network baseline whose gradient at F = F0 is exactly T(F0). Prepare G and h_G once per
   F0, then evaluate at any F. */
PN_API pn_result pn_lagged_prepare(const pn_material *m, int dim, const pn_real *F0, pn_real h0,
                                   pn_real *G, pn_real *h_G);
PN_API pn_result pn_lagged_energy(const pn_material *m, int dim, const pn_real *F,
                                  const pn_real *G, pn_real h_G, pn_real *psi, pn_real *P,
                                  pn_real *dPdF, unsigned flags);

#ifdef __cplusplus
}
#endif
#endif /* PLASTINET_H */
