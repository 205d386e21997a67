/* bench_util.h: what the benchmark programs share: a seeded RNG (splitmix64), Haar-random
   rotations, samples from a PlasticityNet training box, and a CPU-seconds clock. */
#ifndef PN_BENCH_UTIL_H
#define PN_BENCH_UTIL_H
#include <math.h>
#include <time.h>

/* each program uses only some of these helpers */
#if defined(__GNUC__)
#define BENCH_UNUSED __attribute__((unused))
#else
#define BENCH_UNUSED
#endif

typedef struct bench_rng { unsigned long long s; } bench_rng;

/* uniform in [0, 1) */
BENCH_UNUSED static double bench_uniform(bench_rng *r) {
    unsigned long long z = (r->s += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return (double)((z ^ (z >> 31)) >> 11) * (1.0 / 9007199254740992.0);
}

BENCH_UNUSED static double bench_gauss(bench_rng *r) {
    double u = bench_uniform(r), v = bench_uniform(r);
    return sqrt(-2 * log(1 - u)) * cos(6.283185307179586 * v);
}

/* Haar-random rotation: a uniform angle in 2D, a normalized Gaussian quaternion in 3D. */
BENCH_UNUSED static void bench_rotation(bench_rng *r, int d, pn_real *R) {
    if (d == 2) {
        double a = 6.283185307179586 * bench_uniform(r);
        R[0] = (pn_real)cos(a); R[1] = (pn_real)-sin(a);
        R[2] = (pn_real)sin(a); R[3] = (pn_real)cos(a);
    } else {
        double w = bench_gauss(r), x = bench_gauss(r), y = bench_gauss(r), z = bench_gauss(r);
        double n = sqrt(w * w + x * x + y * y + z * z);
        w /= n; x /= n; y /= n; z /= n;
        R[0] = (pn_real)(1 - 2 * (y * y + z * z)); R[1] = (pn_real)(2 * (x * y - w * z)); R[2] = (pn_real)(2 * (x * z + w * y));
        R[3] = (pn_real)(2 * (x * y + w * z)); R[4] = (pn_real)(1 - 2 * (x * x + z * z)); R[5] = (pn_real)(2 * (y * z - w * x));
        R[6] = (pn_real)(2 * (x * z - w * y)); R[7] = (pn_real)(2 * (y * z + w * x)); R[8] = (pn_real)(1 - 2 * (x * x + y * y));
    }
}

/* out = R1 diag(exp(e)) R2 */
BENCH_UNUSED static void bench_compose(int d, const pn_real *R1, const double *e, const pn_real *R2, pn_real *out) {
    pn_real S[9] = {0}, T[9];
    int i;
    for (i = 0; i < d; ++i) S[i * d + i] = (pn_real)exp(e[i]);
    pn_mat_mul(d, R1, S, T);
    pn_mat_mul(d, T, R2, out);
}

/* PlasticityNet Section 5.1: F0 = R1 diag(exp(e)) R2, e uniform in [-e_box, e_box]^d;
   F = R3 diag(exp(e + de)) R4, de uniform in [-de_box, de_box]^d, all R Haar; Fa the same
   stretches as F with the rotations of F0 ("aligned"). */
BENCH_UNUSED static void bench_box_sample(bench_rng *r, int d, double e_box, double de_box, pn_real *F0,
                             pn_real *F, pn_real *Fa) {
    pn_real R1[9], R2[9], R3[9], R4[9];
    double e[3], e2[3];
    int i;
    for (i = 0; i < d; ++i) e[i] = (2 * bench_uniform(r) - 1) * e_box;
    for (i = 0; i < d; ++i) e2[i] = e[i] + (2 * bench_uniform(r) - 1) * de_box;
    bench_rotation(r, d, R1);
    bench_rotation(r, d, R2);
    bench_rotation(r, d, R3);
    bench_rotation(r, d, R4);
    bench_compose(d, R1, e, R2, F0);
    bench_compose(d, R3, e2, R4, F);
    bench_compose(d, R1, e2, R2, Fa);
}

/* A pair as an implicit solve visits it (gen/train.py sample_solver): F0 = R1 diag(exp(e0)) R2
   with e0 = tr/d + dev, |tr| uniform below r0 (r0 log-uniform over 4 decades below e_box), |dev|
   / r0 log-uniform in [0.03, 100] (at most e_box): trial states far outside a yield surface;
   F = R1 (I + D) diag(exp(e0)) R2, D Gaussian of norm |e0| 10^U[-3, 0] (at most de_box). */
BENCH_UNUSED static void bench_solver_sample(bench_rng *r, int d, double e_box, double de_box, pn_real *F0,
                                             pn_real *F) {
    pn_real R1[9], R2[9], S[9] = {0}, T[9], D[9];
    double e[3], v[3], m = 0, nv = 0, ne = 0, nd = 0, r0, tr, dev, size;
    int i, j;
    r0 = e_box * pow(10, -4 * bench_uniform(r));
    tr = (2 * bench_uniform(r) - 1) * r0;
    for (i = 0; i < d; ++i) m += (v[i] = bench_gauss(r)) / d;
    for (i = 0; i < d; ++i) nv += (v[i] - m) * (v[i] - m);
    dev = fmin(r0 * pow(10, -1.5 + 3.5 * bench_uniform(r)), e_box);
    for (i = 0; i < d; ++i) {
        e[i] = tr / d + (v[i] - m) / sqrt(nv) * dev;
        ne += e[i] * e[i];
    }
    for (i = 0; i < d * d; ++i) {
        D[i] = (pn_real)bench_gauss(r);
        nd += D[i] * D[i];
    }
    size = fmin(sqrt(ne) * pow(10, -3 * bench_uniform(r)), de_box);
    bench_rotation(r, d, R1);
    bench_rotation(r, d, R2);
    bench_compose(d, R1, e, R2, F0);
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) S[i * d + j] = (pn_real)((i == j) + D[i * d + j] * size / sqrt(nd)) * (pn_real)exp(e[j]);
    pn_mat_mul(d, R1, S, T);
    pn_mat_mul(d, T, R2, F);
}

BENCH_UNUSED static double bench_seconds(void) { return (double)clock() / CLOCKS_PER_SEC; }

#endif
