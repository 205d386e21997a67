/* test_util.h - the reference helpers that more than one test file uses: small dense matrix
   products, norm, determinant, random rotations, a symmetric Jacobi eigen-solver, the
   nearest-PSD rebuild, Lame constants.

   #included once by test_main.c after pn_test.h; the test files (one translation unit) use
   these t_ helpers and keep only those specific to them, under their own prefixes. Everything
   here is double precision and written independently of plastinet.h: it is what the tests
   judge the library against, so it must not call it. Matrices are n x n row-major, n <= 12. */
#ifndef PN_TEST_UTIL_H
#define PN_TEST_UTIL_H

#include <math.h>
#include "pn_test.h"

/* ---- dense helpers -------------------------------------------------------------------------- */

/* Frobenius norm, scaled against overflow and underflow (an inf entry gives inf). */
static double t_norm(int count, const double *a) {
    double m = 0, acc = 0;
    int i;
    for (i = 0; i < count; ++i)
        if (fabs(a[i]) > m) m = fabs(a[i]);
    if (m == 0 || !(m < HUGE_VAL)) return m;
    for (i = 0; i < count; ++i) acc += (a[i] / m) * (a[i] / m);
    return m * sqrt(acc);
}
/* |a - b| (Frobenius), count <= 81 */
static double t_dist(int count, const double *a, const double *b) {
    double d[144];
    int i;
    for (i = 0; i < count; ++i) d[i] = a[i] - b[i];
    return t_norm(count, d);
}
/* C = A B */
static void t_mul(int n, const double *A, const double *B, double *C) {
    int i, j, k;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) {
            double acc = 0;
            for (k = 0; k < n; ++k) acc += A[i * n + k] * B[k * n + j];
            C[i * n + j] = acc;
        }
}
/* C = A^T B */
static void t_mul_tn(int n, const double *A, const double *B, double *C) {
    int i, j, k;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) {
            double acc = 0;
            for (k = 0; k < n; ++k) acc += A[k * n + i] * B[k * n + j];
            C[i * n + j] = acc;
        }
}
/* C = A B^T */
static void t_mul_nt(int n, const double *A, const double *B, double *C) {
    int i, j, k;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) {
            double acc = 0;
            for (k = 0; k < n; ++k) acc += A[i * n + k] * B[j * n + k];
            C[i * n + j] = acc;
        }
}
/* C = A diag(d) B: F = R1 diag(s) R2 from known factors */
static void t_adb(int n, const double *A, const double *d, const double *B, double *C) {
    int i, j, k;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) {
            double acc = 0;
            for (k = 0; k < n; ++k) acc += A[i * n + k] * d[k] * B[k * n + j];
            C[i * n + j] = acc;
        }
}
/* C = A diag(d) B^T: the SVD reconstruction U diag(s) V^T, Q diag(w) Q^T */
static void t_adbt(int n, const double *A, const double *d, const double *B, double *C) {
    int i, j, k;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) {
            double acc = 0;
            for (k = 0; k < n; ++k) acc += A[i * n + k] * d[k] * B[j * n + k];
            C[i * n + j] = acc;
        }
}
/* Determinant by cofactor expansion, dim 2 or 3 (independent of pn_mat_det). */
static double t_det(int dim, const double *A) {
    if (dim == 2) return A[0] * A[3] - A[1] * A[2];
    return A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) +
           A[2] * (A[3] * A[7] - A[4] * A[6]);
}
/* |A - A^T| (Frobenius) */
static double t_asym(int n, const double *A) {
    double m = 0;
    int i, j;
    for (i = 0; i < n; ++i)
        for (j = i + 1; j < n; ++j) {
            double d = A[i * n + j] - A[j * n + i];
            m += 2 * d * d;
        }
    return sqrt(m);
}
/* 1 when every entry is finite */
static int t_finite(int count, const double *a) {
    int i;
    for (i = 0; i < count; ++i)
        if (!(fabs(a[i]) < HUGE_VAL)) return 0;
    return 1;
}

/* ---- random numbers and random rotations ---------------------------------------------------- */

/* standard normal (Box-Muller; two uniforms per call) */
static double t_gauss(pn_test_rng *r) {
    double u1 = pn_test_rng_uniform(r), u2 = pn_test_rng_uniform(r);
    if (u1 < 1e-300) u1 = 1e-300;
    return sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
}
/* log-uniform in [lo, hi) */
static double t_logu(pn_test_rng *r, double lo, double hi) {
    return exp(pn_test_rng_range(r, log(lo), log(hi)));
}
/* uniform integer in [0, n) */
static int t_randint(pn_test_rng *r, int n) { return (int)(pn_test_rng_u64(r) % (unsigned)n); }
/* Uniformly distributed rotation: an angle in 2D, a unit quaternion from four Gaussians in 3D. */
static void t_rand_rot(pn_test_rng *r, int dim, double *R) {
    if (dim == 2) {
        double a = pn_test_rng_range(r, 0, 6.283185307179586);
        R[0] = cos(a); R[1] = -sin(a);
        R[2] = sin(a); R[3] = cos(a);
    } else {
        double w = t_gauss(r), x = t_gauss(r), y = t_gauss(r), z = t_gauss(r);
        double n = sqrt(w * w + x * x + y * y + z * z);
        w /= n; x /= n; y /= n; z /= n;
        R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - w * z);     R[2] = 2 * (x * z + w * y);
        R[3] = 2 * (x * y + w * z);     R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - w * x);
        R[6] = 2 * (x * z - w * y);     R[7] = 2 * (y * z + w * x);     R[8] = 1 - 2 * (x * x + y * y);
    }
}

/* ---- reference symmetric eigen-solver and PSD rebuild (not pn_sym_eigen) -------------------- */

/* Cyclic Jacobi: A (n x n, n <= 12, symmetrised on entry) = Q diag(w) Q^T, Q columns
   eigenvectors, w unsorted. */
static void t_jacobi(int n, const double *A_in, double *Q, double *w) {
    double A[144];
    int i, j, p, q, sweep;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j) A[i * n + j] = 0.5 * (A_in[i * n + j] + A_in[j * n + i]);
    for (i = 0; i < n * n; ++i) Q[i] = 0;
    for (i = 0; i < n; ++i) Q[i * n + i] = 1;
    for (sweep = 0; sweep < 100; ++sweep) {
        int rotated = 0;
        for (p = 0; p < n; ++p)
            for (q = p + 1; q < n; ++q) {
                double apq = A[p * n + q], app = A[p * n + p], aqq = A[q * n + q], theta, t, c, s;
                int k;
                if (apq == 0) continue;
                /* once negligible against both diagonal entries, drop it (Numerical Recipes) */
                if (sweep > 3 && fabs(app) + 1e3 * fabs(apq) == fabs(app) &&
                    fabs(aqq) + 1e3 * fabs(apq) == fabs(aqq)) {
                    A[p * n + q] = A[q * n + p] = 0;
                    continue;
                }
                rotated = 1;
                theta = (aqq - app) / (2.0 * apq);
                t = fabs(theta) > 1e150 ? 0.5 / theta
                                        : (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                c = 1.0 / sqrt(t * t + 1.0);
                s = t * c;
                for (k = 0; k < n; ++k) { /* A <- A J */
                    double akp = A[k * n + p], akq = A[k * n + q];
                    A[k * n + p] = c * akp - s * akq;
                    A[k * n + q] = s * akp + c * akq;
                }
                for (k = 0; k < n; ++k) { /* A <- J^T A */
                    double apk = A[p * n + k], aqk = A[q * n + k];
                    A[p * n + k] = c * apk - s * aqk;
                    A[q * n + k] = s * apk + c * aqk;
                }
                A[p * n + q] = A[q * n + p] = 0;
                for (k = 0; k < n; ++k) { /* Q <- Q J */
                    double qkp = Q[k * n + p], qkq = Q[k * n + q];
                    Q[k * n + p] = c * qkp - s * qkq;
                    Q[k * n + q] = s * qkp + c * qkq;
                }
            }
        if (!rotated) break;
    }
    for (i = 0; i < n; ++i) w[i] = A[i * n + i];
}
/* The nearest PSD matrix from an eigen-decomposition: out = Q diag(max(w, 0)) Q^T. Clamps w
   in place; returns the smallest eigenvalue before clamping. */
static double t_psd_rebuild(int n, const double *Q, double *w, double *out) {
    double mn = HUGE_VAL;
    int i;
    for (i = 0; i < n; ++i) {
        if (w[i] < mn) mn = w[i];
        if (w[i] < 0) w[i] = 0;
    }
    t_adbt(n, Q, w, Q, out);
    return mn;
}

/* ---- Lame constants from Young's modulus and Poisson's ratio -------------------------------- */

static double t_mu(double E, double nu) { return E / (2 * (1 + nu)); }
static double t_lambda(double E, double nu) { return E * nu / ((1 + nu) * (1 - 2 * nu)); }

#endif
