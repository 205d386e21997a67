/* pn_test.h - the tiny test framework of plastinet's tests (Box2D test_macros.h style).

   A test is a function `static void name(pn_test_ctx *pn__t)`; a file lists its tests in a
   pn_test_case array that tests/test_main.c runs. Checks record failures and keep going, so a
   failing test reports every broken check. The runner prints `N passed, N failed` last. */
#ifndef PN_TEST_H
#define PN_TEST_H

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <stdlib.h>
#include <time.h>

typedef struct pn_test_ctx {
    const char *name;
    int failures;  /* checks that failed in the current test */
    int reported;  /* failures printed (capped so a loop cannot flood the log) */
} pn_test_ctx;

typedef struct pn_test_case {
    const char *name;
    void (*fn)(pn_test_ctx *pn__t);
} pn_test_case;

#define PN_TEST(name) static void name(pn_test_ctx *pn__t)

static void pn_test__fail(pn_test_ctx *t, const char *file, int line, const char *msg) {
    t->failures++;
    if (t->reported++ < 20) fprintf(stderr, "  %s:%d: %s: %s\n", file, line, t->name, msg);
}

/* PN_CHECK(cond): cond must hold. */
#define PN_CHECK(cond)                                                                      \
    do {                                                                                    \
        if (!(cond)) pn_test__fail(pn__t, __FILE__, __LINE__, "check failed: " #cond);      \
    } while (0)

/* PN_CHECK_NEAR(a, b, tol): |a - b| <= tol (NaN fails). */
#define PN_CHECK_NEAR(a, b, tol)                                                            \
    do {                                                                                    \
        double pn__a = (double)(a), pn__b = (double)(b), pn__tol = (double)(tol);           \
        if (!(fabs(pn__a - pn__b) <= pn__tol)) {                                            \
            char pn__m[256];                                                                \
            snprintf(pn__m, sizeof pn__m, "%s = %.17g, %s = %.17g, |diff| %.3g > %.3g", #a, \
                     pn__a, #b, pn__b, fabs(pn__a - pn__b), pn__tol);                       \
            pn_test__fail(pn__t, __FILE__, __LINE__, pn__m);                                \
        }                                                                                   \
    } while (0)

/* PN_CHECK_LE(value, bound): value <= bound (NaN fails); prints both. For error figures. */
#define PN_CHECK_LE(v, bound)                                                               \
    do {                                                                                    \
        double pn__v = (double)(v), pn__bd = (double)(bound);                               \
        if (!(pn__v <= pn__bd)) {                                                           \
            char pn__m[256];                                                                \
            snprintf(pn__m, sizeof pn__m, "%s = %.6g exceeds %s = %.6g", #v, pn__v, #bound, \
                     pn__bd);                                                               \
            pn_test__fail(pn__t, __FILE__, __LINE__, pn__m);                                \
        }                                                                                   \
    } while (0)

/* PN_REPORT: print a measured figure (the closing notes quote these lines). */
#define PN_REPORT(...)                                                                      \
    do {                                                                                    \
        printf("    [%s] ", pn__t->name);                                                   \
        printf(__VA_ARGS__);                                                                \
        printf("\n");                                                                       \
    } while (0)

/* Deterministic random numbers for tests (SplitMix64): no global state. */
typedef struct pn_test_rng { unsigned long long s; } pn_test_rng;
static unsigned long long pn_test_rng_u64(pn_test_rng *r) {
    unsigned long long z = (r->s += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}
/* uniform in [0, 1) */
static double pn_test_rng_uniform(pn_test_rng *r) {
    return (double)(pn_test_rng_u64(r) >> 11) * (1.0 / 9007199254740992.0);
}
static double pn_test_rng_range(pn_test_rng *r, double lo, double hi) {
    return lo + (hi - lo) * pn_test_rng_uniform(r);
}

/* PN_TEST_FULL=1 (make test-all, what CI runs): the tests that sweep many cases run them all;
   otherwise (make test, make test-sanitize) a representative subset named in the test. */
static inline int pn_test_full(void) {
    const char *s = getenv("PN_TEST_FULL");
    return s && *s && strcmp(s, "0") != 0;
}

/* Does a case's name pass filter? NULL: all; "=name": that name exactly; else a substring. */
static int pn_test_match(const char *name, const char *filter) {
    if (!filter) return 1;
    if (filter[0] == '=') return strcmp(name, filter + 1) == 0;
    return strstr(name, filter) != NULL;
}

/* Print the names of the cases that pass filter, one a line (tests/run.sh runs them two at a
   time, each in its own process). */
static inline void pn_test_list(const pn_test_case *cases, int count, const char *filter) {
    int i;
    for (i = 0; i < count; ++i)
        if (pn_test_match(cases[i].name, filter)) printf("%s\n", cases[i].name);
}

/* Run the cases that pass filter (pn_test_match); returns the number that failed. With
   PN_TEST_TIMES set, each test's CPU seconds (every thread's) go to stderr: "cpu 1.23 name". */
static int pn_test_run(const pn_test_case *cases, int count, const char *filter, int *passed,
                       int *failed) {
    int i, bad = 0, times = getenv("PN_TEST_TIMES") != NULL;
    for (i = 0; i < count; ++i) {
        pn_test_ctx t;
        clock_t c0;
        if (!pn_test_match(cases[i].name, filter)) continue;
        t.name = cases[i].name;
        t.failures = 0;
        t.reported = 0;
        c0 = clock();
        cases[i].fn(&t);
        if (times) fprintf(stderr, "cpu %.2f %s\n", (double)(clock() - c0) / CLOCKS_PER_SEC, cases[i].name);
        if (t.failures) {
            printf("FAIL %s (%d failed checks)\n", cases[i].name, t.failures);
            ++*failed;
            ++bad;
        } else {
            printf("ok   %s\n", cases[i].name);
            ++*passed;
        }
        fflush(stdout);
    }
    return bad;
}

#endif
