/* The library built with PN_REAL=float: SVD invariants over every kind of matrix and return
   mappings landing on their yield surfaces, with bounds a few hundred float ulps wide (the
   double-precision figures are in test_main.c). tests/run.sh builds and runs it.
   Build: cc -std=c99 -O2 -DPN_REAL=float tests/test_float.c -lm -o build/test_float */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../models/pn_model_sand_2d.h"
#include "../models/pn_model_sand_3d.h"
#include "pn_test.h"

typedef char t_fl_requires_float[sizeof(pn_real) == sizeof(float) ? 1 : -1];

static void t_fl_rotation(pn_test_rng *r, int d, pn_real *R) {
    pn_real A[9], s[3], V[9];
    int i;
    for (i = 0; i < d * d; ++i) A[i] = (pn_real)pn_test_rng_range(r, -1, 1);
    pn_svd(d, A, R, s, V);
}

/* F = R1 diag(s) R2 */
static void t_fl_compose(int d, const pn_real *R1, const double *s, const pn_real *R2, pn_real *F) {
    pn_real S[9], T[9];
    int i;
    for (i = 0; i < d * d; ++i) S[i] = 0;
    for (i = 0; i < d; ++i) S[i * d + i] = (pn_real)s[i];
    pn_mat_mul(d, R1, S, T);
    pn_mat_mul(d, T, R2, F);
}

PN_TEST(float_svd) {
    static const char *const kinds[] = {"generic", "tiny 1e-8", "huge 1e8", "zero", "inverted"};
    pn_test_rng rng;
    int d, kind, t, i, j, k;
    rng.s = 71;
    for (d = 2; d <= 3; ++d)
        for (kind = 0; kind < 5; ++kind) {
            double recon = 0, orth = 0, det = 0;
            for (t = 0; t < 20000; ++t) {
                pn_real R1[9], R2[9], F[9], U[9], s[3], V[9];
                double sv[3], e = 0, n = 0;
                t_fl_rotation(&rng, d, R1);
                t_fl_rotation(&rng, d, R2);
                for (i = 0; i < d; ++i) sv[i] = exp(pn_test_rng_range(&rng, -1, 1));
                if (kind == 1) sv[d - 1] = 1e-8;
                if (kind == 2) sv[0] = 1e8;
                if (kind == 3) sv[d - 1] = 0;
                if (kind == 4) sv[d - 1] = -sv[d - 1];
                t_fl_compose(d, R1, sv, R2, F);
                PN_CHECK(pn_svd(d, F, U, s, V) == PN_OK);
                for (i = 0; i < d; ++i)
                    for (j = 0; j < d; ++j) {
                        double a = 0, uu = 0, vv = 0;
                        for (k = 0; k < d; ++k) {
                            a += (double)U[i * d + k] * s[k] * V[j * d + k];
                            uu += (double)U[k * d + i] * U[k * d + j];
                            vv += (double)V[k * d + i] * V[k * d + j];
                        }
                        e += (a - F[i * d + j]) * (a - F[i * d + j]);
                        n += (double)F[i * d + j] * F[i * d + j];
                        orth = fmax(orth, fmax(fabs(uu - (i == j)), fabs(vv - (i == j))));
                    }
                recon = fmax(recon, sqrt(e / n));
                det = fmax(det, fmax(fabs(pn_mat_det(d, U) - 1.0), fabs(pn_mat_det(d, V) - 1.0)));
            }
            PN_REPORT("dim %d %-9s: reconstruction %.2e, orthogonality %.2e, |det - 1| %.2e", d,
                      kinds[kind], recon, orth, det);
            PN_CHECK_LE(recon, 1e-5);
            PN_CHECK_LE(orth, 1e-5);
            PN_CHECK_LE(det, 1e-5);
        }
}

PN_TEST(float_return_mappings) {
    static const char *const names[] = {"drucker_prager", "von_mises", "von_mises_neo_hookean",
                                        "cam_clay"};
    pn_test_rng rng;
    int d, pm, t;
    rng.s = 72;
    for (d = 2; d <= 3; ++d)
        for (pm = 0; pm < 4; ++pm) {
            pn_material_desc ds;
            pn_material m;
            double worst = 0, spread = pm == 3 ? 0.1 : 0.3, hmin = pm == 3 ? -0.3 : 0;
            int errors = 0, plastic = 0;
            memset(&ds, 0, sizeof ds);
            ds.youngs_modulus_pa = 1e6f;
            ds.poisson_ratio = 0.3f;
            ds.friction_angle_deg = pm == 3 ? 35 : 30;
            ds.yield_stress_pa = 1e4f;
            ds.hardening_modulus_pa = 1e5f;
            ds.camclay_beta = 0.3f;
            ds.camclay_xi = 3;
            ds.plastic = pm == 0 ? PN_PLASTIC_DRUCKER_PRAGER : pm == 3 ? PN_PLASTIC_CAM_CLAY : PN_PLASTIC_VON_MISES;
            if (pm == 2) ds.elastic = PN_ELASTIC_NEO_HOOKEAN;
            PN_CHECK(pn_material_init(&m, &ds, NULL, 0) == PN_OK);
            for (t = 0; t < 10000; ++t) {
                pn_real R1[9], R2[9], F[9], Z[9], T[9], hn = 0, y = 0, ys = 1, y0 = 0, ys0 = 1;
                pn_real h = (pn_real)pn_test_rng_range(&rng, hmin, 0);
                double sv[3];
                int i;
                t_fl_rotation(&rng, d, R1);
                t_fl_rotation(&rng, d, R2);
                for (i = 0; i < d; ++i) sv[i] = exp(pn_test_rng_range(&rng, -spread, spread));
                t_fl_compose(d, R1, sv, R2, F);
                if (pn_return_map(&m, d, F, h, Z, &hn, T) != PN_OK ||
                    pn_yield_function(&m, d, F, h, &y0, &ys0) != PN_OK) {
                    errors++;
                    continue;
                }
                if (!(y0 > 0)) continue;
                plastic++;
                /* the projection lands on the surface of the state it used (Cam-Clay: the old
                   one); relative to the larger of the two scales (apex and tips, plastinet.h) */
                if (pn_yield_function(&m, d, Z, pm == 3 ? h : hn, &y, &ys) != PN_OK) errors++;
                worst = fmax(worst, fabs(y) / fmax(ys, ys0));
            }
            PN_REPORT("dim %d %-21s: %d plastic of 10000, worst relative yield residual %.2e",
                      d, names[pm], plastic, worst);
            PN_CHECK(errors == 0);
            PN_CHECK(plastic > 500);
            PN_CHECK_LE(worst, 1e-2);
        }
}

/* PlasticityNet sand (the scaled encoding) in float at F0 of every kind that a pile holds,
   near-isotropic ones included, where a float feature log(I1/2) - log J rounds below zero:
   prepare and evaluate (one point, and in lanes) without a failure or a non-finite value. */
PN_TEST(float_pnet_sand) {
    int d, k, errors = 0, n = 0;
    pn_test_rng rng;
    rng.s = 31;
    for (d = 2; d <= 3; ++d) {
        const pn_model *mo = d == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
        pn_material m;
        pn_pnet net;
        pn_pnet_desc nd;
        memset(&nd, 0, sizeof nd);
        nd.energy = mo;
        if (pn_model_material(mo, 1e7, &m, NULL, 0) != PN_OK || pn_pnet_init(&net, &nd, &m, d, NULL, 0) != PN_OK) {
            PN_CHECK(!"PlasticityNet sand in float");
            return;
        }
        for (k = 0; k < 4000; ++k) {
            pn_real R1[9], R2[9], F0[9], F[9], psi, P[9], H[81], h = 0, psil, Pl[9];
            double sv[3], spread = k % 4 == 0 ? 0 : k % 4 == 1 ? 1e-6 : k % 4 == 2 ? 1e-3 : 0.05, J = exp(pn_test_rng_range(&rng, -0.05, 0.02));
            pn_pnet_point pt, ptl;
            const pn_pnet_point *pp = &ptl;
            pn_result st;
            int i;
            t_fl_rotation(&rng, d, R1);
            t_fl_rotation(&rng, d, R2);
            for (i = 0; i < d; ++i) sv[i] = pow(J, 1.0 / d) * exp(pn_test_rng_range(&rng, -spread, spread));
            t_fl_compose(d, R1, sv, R2, F0);
            if (pn_mat_det(d, F0) <= 0) continue; /* the two rotations' signs */
            for (i = 0; i < d * d; ++i) F[i] = F0[i] + (pn_real)pn_test_rng_range(&rng, -1e-4, 1e-4);
            n++;
            if (pn_pnet_prepare(&net, F0, h, &pt, NULL, NULL) != PN_OK ||
                pn_pnet_energy(&net, &pt, F, &psi, P, H, PN_EVAL_PROJECT_PSD) != PN_OK ||
                pn_pnet_prepare_lanes(&net, 1, F0, &h, &ptl, &st) != PN_OK ||
                pn_pnet_energy_lanes(&net, 1, &pp, F, &psil, Pl, NULL, 0, &st) != PN_OK)
                errors++;
        }
    }
    PN_REPORT("%d pairs (F0 isotropic to 5%% anisotropic, J in [0.95, 1.02], 2D and 3D): %d failed", n, errors);
    PN_CHECK(n > 2000 && errors == 0);
}

static const pn_test_case pn_tests_float[] = {
    {"float_svd", float_svd},
    {"float_return_mappings", float_return_mappings},
    {"float_pnet_sand", float_pnet_sand},
};

int main(int argc, char **argv) {
    int passed = 0, failed = 0;
    pn_test_run(pn_tests_float, (int)(sizeof pn_tests_float / sizeof pn_tests_float[0]),
                argc > 1 ? argv[1] : NULL, &passed, &failed);
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
