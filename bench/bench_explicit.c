/* bench_explicit: throughput of plastinet's explicit MPM step, in particle-steps per second.

   The scene is that of the classic 88-line MLS-MPM program (Hu et al. 2018), in its units
   (1 m box, density 1, E 1e4 Pa, nu 0.2, gravity -200 m/s^2): three squares of side 0.16 m
   centred at (0.55, 0.45), (0.45, 0.65), (0.55, 0.85), each with `per_block` particles placed
   uniformly at random (a seeded generator); fixed corotated elasticity with the Stomakhin snow
   clamp (theta_c 2.5e-2, theta_s 7.5e-3, xi 10, J_p in [0.6, 20]), or without it (--jelly);
   walls 0.05 m thick (separating; the program's side walls are sticky, which these blocks
   never reach). In 3D the squares become cubes at z = 0.5, each 0.1 m lower (coarse 3D grids
   have their upper wall below 0.93 m). The step is 1e-4 s at n = 80 (the
   program's) and scales with the cell below that (2e-5 s at n = 256).

   Modes:
     bench_explicit [--n 80] [--per-block 10000] [--steps 1000] [--dt S] [--jelly] [--dim 2]
                    [--threads T] [--perturb X]
         one run; prints particles, steps, wall seconds, particle-steps per second and the
         mean height at the end (to set beside the 88-line program's: same scene, same physics).
         --perturb X: Young's modulus times 1 + X (how far a tiny change moves the result: the
         float build's test in tests/run.sh compares float and double against it).
     bench_explicit --sweep [--max 1000000] [--sweep-dim 2|3] [--csv FILE] [--md FILE]
         2D and 3D, 1e3 .. --max particles at about 8 per occupied cell (the grid refined with
         the count), 1 and 2 threads alternating, the best of three runs of about 3e6
         particle-steps each: particle-steps per second, the log-log slope of the time per
         step against the particle count, the 2-thread speedup, and the machine's memory
         bandwidth and vector arithmetic on 1 and 2 threads (the ceilings of a memory-bound
         and of an arithmetic-bound step's speedup).
   `make bench-explicit` runs both (and the 88-line program beside them when MLS88_DIR names
   a copy of it: bench/mls88_side_by_side.sh). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L
#endif
#define PLASTINET_IMPLEMENTATION
#define PLASTINET_MPM_IMPLEMENTATION
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>
#endif

static double wall_seconds(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* xorshift64*: the positions are the same on every machine */
static double uniform01(unsigned long long *s) {
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    return (double)((*s * 2685821657736338717ULL) >> 11) * (1.0 / 9007199254740992.0);
}

static void set_threads(int t) {
#ifdef _OPENMP
    if (t > 0) omp_set_num_threads(t);
#else
    (void)t;
#endif
}

static int max_threads(void) {
#ifdef _OPENMP
    return omp_get_max_threads();
#else
    return 1;
#endif
}

/* the scene on an n^dim grid; NULL on failure (the reason printed) */
static pn_mpm_world *scene(int dim, int n, long per_block, int jelly, double perturb) {
    static const double centers[2][3][3] = {{{0.55, 0.45, 0}, {0.45, 0.65, 0}, {0.55, 0.85, 0}},
                                            {{0.55, 0.35, 0.5}, {0.45, 0.55, 0.5}, {0.55, 0.75, 0.5}}};
    pn_mpm_desc d;
    pn_material_desc md;
    pn_material mat;
    pn_mpm_world *w = NULL;
    pn_real *x;
    unsigned long long seed = 88;
    char why[256] = "";
    size_t p, np = (size_t)(3 * per_block);
    int g, b, i;
    memset(&d, 0, sizeof d);
    d.dim = dim;
    d.res[0] = d.res[1] = d.res[2] = n;
    d.dx_m = (pn_real)(1.0 / n);
    d.gravity[1] = -200;
    d.boundary = PN_BOUNDARY_SEPARATE;
    d.wall_cells = (int)(0.05 * n + 0.999) - 1; /* the program holds nodes below 0.05: rows 0..wall */
    d.max_particles = np;
    d.parallel_min_particles = 1;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED;
    md.plastic = jelly ? PN_PLASTIC_NONE : PN_PLASTIC_SNOW_STOMAKHIN;
    md.youngs_modulus_pa = (pn_real)(1e4 * (1 + perturb));
    md.poisson_ratio = (pn_real)0.2;
    md.snow_theta_c = (pn_real)2.5e-2;
    md.snow_theta_s = (pn_real)7.5e-3;
    md.snow_xi = 10;
    md.snow_jp_min = (pn_real)0.6; /* the program clamps J_p to [0.6, 20] */
    md.snow_jp_max = 20;
    if (pn_material_init(&mat, &md, why, sizeof why) != PN_OK || pn_mpm_create(&d, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "bench_explicit: %s\n", why);
        return NULL;
    }
    g = pn_mpm_add_group(w, &mat, 1);
    x = (pn_real *)malloc(sizeof(pn_real) * (size_t)dim * np);
    if (g < 0 || !x) {
        pn_mpm_destroy(w);
        free(x);
        return NULL;
    }
    for (b = 0, p = 0; b < 3; ++b) {
        long k;
        for (k = 0; k < per_block; ++k, ++p)
            for (i = 0; i < dim; ++i) x[(size_t)dim * p + (size_t)i] = (pn_real)(centers[dim - 2][b][i] + (uniform01(&seed) * 2 - 1) * 0.08);
    }
    /* the program gives every particle volume 1 and mass 1: only their ratio (density 1)
       matters to the motion, so the particles here share the blocks' volume */
    if (pn_mpm_add_particles(w, g, np, x, NULL, (pn_real)(3 * pow(0.16, dim) / (double)np)) != PN_OK) {
        fprintf(stderr, "bench_explicit: %s\n", pn_mpm_error(w));
        pn_mpm_destroy(w);
        w = NULL;
    }
    free(x);
    return w;
}

/* steps at dt after `warm` untimed ones: wall seconds, or -1 when a step fails */
static double run(pn_mpm_world *w, int warm, int steps, double dt, double *plastic) {
    double t0 = wall_seconds();
    int i;
    if (plastic) *plastic = 0;
    for (i = 0; i < warm + steps; ++i) {
        pn_result r;
        pn_mpm_stats st;
        if (i == warm) t0 = wall_seconds();
        r = pn_mpm_step_explicit(w, (pn_real)dt, &st);
        if (plastic && i >= warm) *plastic += (double)st.plastic / (double)st.particles / steps;
        if (r != PN_OK) {
            fprintf(stderr, "bench_explicit: step %d failed: %s (%s)\n", i, pn_result_string(r), pn_mpm_error(w));
            return -1;
        }
    }
    return wall_seconds() - t0;
}

static double step_for(int n) { return n <= 80 ? 1e-4 : 1e-4 * 80.0 / n * 0.64; }

/* The machine's memory bandwidth on t threads, GB/s: a STREAM-style triad a = b + s c over
   three arrays of 64 MB (past any cache), the best of five. A step of a big scene streams
   every particle's state through memory, so where two threads get no more bandwidth than one,
   no memory-bound step can go twice as fast on two: the sweep prints this beside its
   speedups. */
static double triad_gb_s(int t) {
    size_t n = (size_t)8 << 20, i;
    double *a = (double *)malloc(sizeof(double) * n * 3), best = 0;
    int rep;
    if (!a) return 0;
    set_threads(t);
    for (i = 0; i < 3 * n; ++i) a[i] = (double)(i % 7); /* first touch on one thread */
    for (rep = 0; rep < 5; ++rep) {
        double t0 = wall_seconds(), s;
        long li;
#ifdef _OPENMP
#pragma omp parallel for schedule(static)
#endif
        for (li = 0; li < (long)n; ++li) a[li] = a[n + (size_t)li] + 1.5 * a[2 * n + (size_t)li];
        s = wall_seconds() - t0;
        if (3.0 * 8 * (double)n / s / 1e9 > best) best = 3.0 * 8 * (double)n / s / 1e9;
    }
    free(a);
    return best;
}

/* The machine's vector arithmetic on t threads, 1e9 multiply-adds per second: 64 independent
   float chains per thread (the compiler vectorizes them), the same work on every thread, the
   best of three. Where two threads get less than twice one's (two virtual cores on one
   physical core, or a neighbour's load), no arithmetic-bound step can reach 2x either. */
static double madd_rate(int t) {
    double best = 0;
    int rep;
    set_threads(t);
    for (rep = 0; rep < 3; ++rep) {
        double t0 = wall_seconds(), s;
        int nt = 0;
        float sink = 0;
#ifdef _OPENMP
#pragma omp parallel reduction(+ : sink, nt)
#endif
        {
            float a[64];
            int i;
            long it;
            for (i = 0; i < 64; ++i) a[i] = (float)i;
            for (it = 0; it < 10000000L; ++it)
                for (i = 0; i < 64; ++i) a[i] = a[i] * 0.999999f + 1e-7f;
            for (i = 0; i < 64; ++i) sink += a[i];
            nt += 1;
        }
        s = wall_seconds() - t0;
        if (sink == 1234.5f) printf(" "); /* keeps the chains */
        if (nt * 64 * 1e7 / s / 1e9 > best) best = nt * 64 * 1e7 / s / 1e9;
    }
    return best;
}

static int sweep(long max_n, int dims, const char *csv, const char *md) {
    static const long counts[] = {1000, 3000, 10000, 30000, 100000, 300000, 1000000, 3000000};
    FILE *fc = csv ? fopen(csv, "w") : NULL, *fm = md ? fopen(md, "w") : NULL;
    int dim, k, t, tmax = max_threads() >= 2 ? 2 : 1;
    if (fc) fprintf(fc, "dim,particles,grid,threads,steps,seconds,psteps_per_s\n");
    if (fm)
        fprintf(fm, "| dim | particles | grid | particle-steps/s, 1 thread | 2 threads | speedup |\n"
                    "|---|---|---|---|---|---|\n");
    for (dim = 2; dim <= 3; ++dim) {
        double sx = 0, sy = 0, sxx = 0, sxy = 0;
        if (!(dims >> dim & 1)) continue;
        int m = 0;
        for (k = 0; k < (int)(sizeof counts / sizeof counts[0]) && counts[k] <= max_n; ++k) {
            long np = counts[k];
            /* about 8 particles per cell of the blocks: 3 x 0.16^dim m^dim of material */
            int n = (int)(pow((double)np / 8 / (3 * pow(0.16, dim)), 1.0 / dim) + 0.5), steps;
            double rate[2] = {0, 0};
            if (n < 24) n = 24;
            pn_mpm_world *w[2] = {NULL, NULL};
            double s[2] = {1e30, 1e30};
            int rep;
            steps = (int)(3e6 / (double)np);
            if (steps < 3) steps = 3;
            for (t = 1; t <= tmax; ++t)
                if (!(w[t - 1] = scene(dim, n, np / 3, 0, 0))) return 1;
            /* the best of three, 1 and 2 threads alternating (a shared machine only slows runs
               down, and its speed drifts): each thread count steps its own copy of the scene */
            for (rep = 0; rep < 3; ++rep)
                for (t = 1; t <= tmax; ++t) {
                    double r;
                    set_threads(t);
                    r = run(w[t - 1], rep == 0 ? 3 : 0, steps, step_for(n) * (dim == 3 ? 0.5 : 1), NULL);
                    if (r < 0) {
                        pn_mpm_destroy(w[0]), pn_mpm_destroy(w[1]);
                        return 1;
                    }
                    s[t - 1] = r < s[t - 1] ? r : s[t - 1];
                }
            for (t = 1; t <= tmax; ++t) {
                pn_mpm_destroy(w[t - 1]);
                rate[t - 1] = (double)(np / 3 * 3) * steps / s[t - 1];
                if (fc) fprintf(fc, "%d,%ld,%d,%d,%d,%.4f,%.5g\n", dim, np / 3 * 3, n, t, steps, s[t - 1], rate[t - 1]);
                printf("dim %d  particles %8ld  grid %4d  threads %d  %.3g particle-steps/s\n", dim, np / 3 * 3, n, t,
                       rate[t - 1]);
                fflush(stdout);
            }
            /* fit log(seconds per step) = a + slope log(particles) */
            sx += log((double)np);
            sy += log((double)np / rate[0]);
            sxx += log((double)np) * log((double)np);
            sxy += log((double)np) * log((double)np / rate[0]);
            m++;
            if (fm)
                fprintf(fm, "| %d | %ld | %d^%d | %.3g | %.3g | %.2f |\n", dim, np / 3 * 3, n, dim, rate[0],
                        rate[1], rate[1] > 0 ? rate[1] / rate[0] : 0);
        }
        if (m > 1) {
            double slope = (m * sxy - sx * sy) / (m * sxx - sx * sx);
            printf("dim %d: cost per step ~ particles^%.3f (log-log fit, 1 thread)\n", dim, slope);
            if (fm) fprintf(fm, "| %d | slope of log(time per step) on log(particles), 1 thread: **%.3f** | | | | |\n", dim, slope);
        }
    }
    if (tmax > 1) { /* the ceilings of the speedup: memory (triad_gb_s) and arithmetic (madd_rate) */
        double b1 = triad_gb_s(1), b2 = triad_gb_s(2), a1 = madd_rate(1), a2 = madd_rate(2);
        printf("memory bandwidth (triad over 3 x 64 MB): 1 thread %.1f GB/s, 2 threads %.1f GB/s (%.2fx)\n", b1, b2,
               b2 / b1);
        printf("vector arithmetic (independent float multiply-adds): 1 thread %.1fe9/s, 2 threads %.1fe9/s (%.2fx)\n", a1,
               a2, a2 / a1);
        if (fm)
            fprintf(fm,
                    "| | memory bandwidth, triad over 3 x 64 MB | | %.1f GB/s | %.1f GB/s | %.2f |\n"
                    "| | vector arithmetic, independent float multiply-adds | | %.1fe9/s | %.1fe9/s | %.2f |\n",
                    b1, b2, b2 / b1, a1, a2, a2 / a1);
    }
    if (fc) fclose(fc);
    if (fm) fclose(fm);
    return 0;
}

int main(int argc, char **argv) {
    int n = 80, steps = 1000, jelly = 0, threads = 0, dim = 2, do_sweep = 0, dims = 12, i;
    long per_block = 10000, max_n = 1000000;
    double dt = 0, s, mean_y = 0, perturb = 0, plastic = 0;
    const char *csv = NULL, *md = NULL;
    pn_mpm_world *w;
    size_t p;
    for (i = 1; i < argc; ++i) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--jelly")) jelly = 1;
        else if (!strcmp(a, "--sweep")) do_sweep = 1;
        else if (v && !strcmp(a, "--n")) n = atoi(v), ++i;
        else if (v && !strcmp(a, "--dim")) dim = atoi(v), ++i;
        else if (v && !strcmp(a, "--per-block")) per_block = atol(v), ++i;
        else if (v && !strcmp(a, "--steps")) steps = atoi(v), ++i;
        else if (v && !strcmp(a, "--dt")) dt = atof(v), ++i;
        else if (v && !strcmp(a, "--perturb")) perturb = atof(v), ++i;
        else if (v && !strcmp(a, "--threads")) threads = atoi(v), ++i;
        else if (v && !strcmp(a, "--max")) max_n = atol(v), ++i;
        else if (v && !strcmp(a, "--sweep-dim")) dims = 1 << atoi(v), ++i;
        else if (v && !strcmp(a, "--csv")) csv = v, ++i;
        else if (v && !strcmp(a, "--md")) md = v, ++i;
        else {
            fprintf(stderr, "usage: %s [--n 80] [--per-block 10000] [--steps 1000] [--dt S] [--jelly] [--dim 2] "
                            "[--threads T] [--perturb X] | --sweep [--max 1000000] [--csv FILE] [--md FILE]\n", argv[0]);
            return 2;
        }
    }
    if (do_sweep) return sweep(max_n, dims, csv, md);
    if (n < 16 || per_block < 1 || steps < 1 || (dim != 2 && dim != 3)) {
        fprintf(stderr, "bench_explicit: --n >= 16, --per-block >= 1, --steps >= 1, --dim 2 or 3\n");
        return 2;
    }
    if (!(dt > 0)) dt = step_for(n);
    set_threads(threads);
    if (!(w = scene(dim, n, per_block, jelly, perturb))) return 1;
    s = run(w, 10, steps, dt, &plastic); /* as the side-by-side harness: 10 untimed steps */
    if (s < 0) return 1;
    for (p = 0; p < w->n; ++p) mean_y += (double)w->x[p * (size_t)dim + 1];
    mean_y /= (double)w->n;
    printf("bench_explicit %s real=%s dim=%d n=%d particles=%lu threads=%d steps=%d dt=%g seconds=%.3f "
           "psteps_per_s=%.4g mean_y=%.6f plastic_share=%.3f\n",
           jelly ? "jelly" : "snow", sizeof(pn_real) == 4 ? "float" : "double", dim, n, (unsigned long)w->n,
           max_threads(), steps, dt, s, (double)w->n * steps / s, mean_y, plastic);
    pn_mpm_destroy(w);
    return 0;
}
