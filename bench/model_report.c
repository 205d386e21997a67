/* model_report: the measured quality and cost of every shipped model (models/REPORT.md).
   Build: cc -std=c99 -O2 bench/model_report.c -lm -o model_report   (needs models/pn_models.h)
   Usage: model_report [--out models/REPORT.md] [--samples N] [--model NAME --banner]
     --banner   print the quality lines gen/export.py puts into NAME's header (no timings,
                so headers stay reproducible)

   Energy models, on N fresh samples from the training box (PlasticityNet Section 5.1:
   F0 = R1 diag(exp(e)) R2, F = R3 diag(exp(e + de)) R4, Haar rotations, h uniform), with the
   regularizer off (Eq. 8 as trained):
     exact at F0    max |grad Psi(F0; F0) - T(F0)| / max(|T(F0)|, 1e-6 mean |T|)
     approximation  mean and 95th percentile of |grad Psi(F; F0) - T(F)| / mean |T|, next to the
                    lagged energy psi_el(F G) of plastinet.h and the constant T(F0); also for
                    "aligned" samples (R3 = R1, R4 = R2: only the stretches differ, as in a time
                    step). T is always the analytic return mapping (root find for metal_nh).
     objectivity    max relative change of Psi and grad Psi under a random rotation of F and F0
     Hessian        max |dP/dF - central FD of P| / max |dP/dF| (step 1e-6), 1000 samples
     least energy   min over samples of Psi(F; F0) - Psi(F0; F0), regularizer on (as simulated),
                    per unit E: F0 in the box, F within de_box (the box) and with log stretches
                    anywhere in [-10, 3] (far beyond it, crushed: a Newton step's trial states)
   Conditioned models (material parameters as inputs) are measured the same way at every
   point of a grid over their ranges (corners, edge midpoints, centre) and at the points of
   the single-material models of their family, next to those models.
     cost           ns per prepare (once per F0), per energy + gradient + Hessian, and with the
                    PSD projection
   Return-map models: |log z - log z_ref| against the root find of plastinet.h (mean, max),
   relative |T - T_ref| (mean, max), the yield residual |y(Z)| / tau_Y (max) and the cost of
   both. Rates are per machine; nothing here is asserted (tests/test_pnet_return.c asserts accuracy). */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../models/pn_models.h"
#include "bench_util.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct energy_figures {
    double exact_max, net_mean, net_p95, lag_mean, lag_p95, const_mean, const_p95;
    double net_aligned, lag_aligned, objectivity_psi, objectivity_P, hess_fd;
    double ns_prepare, ns_energy, ns_energy_psd;
    double small_ratio;          /* ratio to lagged at |e0| <= 1e-3, |de| <= 1e-2 */
    double solver_ratio;         /* ratio to lagged on the pairs a solve visits            */
    double least_box, least_far; /* min Psi(F) - Psi(F0) / E: F in the box, far beyond */
    int failures;
} energy_figures;

typedef struct return_figures {
    double logz_mean, logz_max, T_mean, T_max, yield_max, ns_learned, ns_rootfind;
    int failures;
} return_figures;

static double nrm(int n, const pn_real *a) {
    double s = 0;
    int i;
    for (i = 0; i < n; ++i) s += (double)a[i] * (double)a[i];
    return sqrt(s);
}

static double dist(int n, const pn_real *a, const pn_real *b) {
    double s = 0;
    int i;
    for (i = 0; i < n; ++i) s += ((double)a[i] - (double)b[i]) * ((double)a[i] - (double)b[i]);
    return sqrt(s);
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double p95(double *v, int n) {
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    return v[(int)(0.95 * (n - 1))];
}

static double mean(const double *v, int n) {
    double s = 0;
    int i;
    for (i = 0; i < n; ++i) s += v[i];
    return s / n;
}

/* sum |grad Psi - T| / sum |grad Psi_lagged - T| over n pairs: small strains (|e0| <= 1e-3,
   |de| <= 1e-2) or, with solver, the pairs an implicit solve visits */
static double ratio_to_lagged(const pn_model *mo, const pn_material *m, const pn_pnet *net, bench_rng *rng, int n,
                              int solver, int *failures) {
    int d = mo->dim, dd = d * d, k;
    double sn = 0, sl = 0;
    for (k = 0; k < n; ++k) {
        pn_real F0[9], F[9], Fa[9], h, T[9], P[9], G[9], hG, psi;
        pn_pnet_point pt;
        if (solver)
            bench_solver_sample(rng, d, mo->e_box, mo->de_box, F0, F);
        else
            bench_box_sample(rng, d, 1e-3, 1e-2, F0, F, Fa);
        h = (pn_real)(mo->h_min + (mo->h_max - mo->h_min) * bench_uniform(rng));
        if (pn_pnet_prepare(net, F0, h, &pt, NULL, NULL) != PN_OK || pn_return_map(m, d, F, h, NULL, NULL, T) != PN_OK ||
            pn_lagged_prepare(m, d, F0, h, G, &hG) != PN_OK || pn_pnet_energy(net, &pt, F, &psi, P, NULL, 0) != PN_OK) {
            (*failures)++;
            continue;
        }
        sn += dist(dd, P, T);
        if (pn_lagged_energy(m, d, F, G, hG, &psi, P, NULL, 0) != PN_OK) (*failures)++;
        sl += dist(dd, P, T);
    }
    return sn / sl;
}

static void energy_report(const pn_model *mo, const pn_material *mat, int n, int timing, energy_figures *fg) {
    int d = mo->dim, dd = d * d, k, i, j;
    pn_material m = *mat;
    pn_pnet net, net_reg;
    pn_pnet_desc desc;
    bench_rng rng;
    double *err = (double *)malloc(sizeof(double) * (size_t)n);
    double *lag = (double *)malloc(sizeof(double) * (size_t)n);
    double *cst = (double *)malloc(sizeof(double) * (size_t)n);
    double tsum = 0, al_net = 0, al_lag = 0, ex_rel = 0, ex_abs = 0;
    memset(fg, 0, sizeof *fg);
    memset(&desc, 0, sizeof desc);
    desc.energy = mo;
    desc.return_map = NULL;
    if (mo->return_map)
        for (k = 0; pn_models_all[k]; ++k)
            if (!strcmp(pn_models_all[k]()->name, mo->return_map)) desc.return_map = pn_models_all[k]();
    desc.regularizer = -1;
    if (pn_pnet_init(&net, &desc, &m, d, NULL, 0) != PN_OK) {
        fg->failures = n;
        return;
    }
    desc.regularizer = 0;
    pn_pnet_init(&net_reg, &desc, &m, d, NULL, 0);
    rng.s = 20261122u + (unsigned)d;
    for (k = 0; k < n; ++k) {
        pn_real F0[9], F[9], Fa[9], h, T0[9], T[9], Ta[9], P[9], G[9], hG, hn, psi;
        pn_pnet_point pt;
        bench_box_sample(&rng, d, mo->e_box, mo->de_box, F0, F, Fa);
        h = (pn_real)(mo->h_min + (mo->h_max - mo->h_min) * bench_uniform(&rng));
        if (pn_pnet_prepare(&net, F0, h, &pt, &hn, T0) != PN_OK ||
            pn_return_map(&m, d, F, h, NULL, NULL, T) != PN_OK ||
            pn_return_map(&m, d, Fa, h, NULL, NULL, Ta) != PN_OK ||
            pn_lagged_prepare(&m, d, F0, h, G, &hG) != PN_OK) {
            fg->failures++;
            err[k] = lag[k] = cst[k] = 0;
            continue;
        }
        tsum += nrm(dd, T);
        /* exactness at F0: relative where T(F0) != 0, absolute where it vanishes (sand in
           tension); the absolute ones are scaled by 1e-6 mean |T| once that is known */
        pn_pnet_energy(&net, &pt, F0, &psi, P, NULL, 0);
        if (nrm(dd, T0) > 0) ex_rel = fmax(ex_rel, dist(dd, P, T0) / nrm(dd, T0));
        else ex_abs = fmax(ex_abs, dist(dd, P, T0));
        if (pn_pnet_energy(&net, &pt, F, &psi, P, NULL, 0) != PN_OK) fg->failures++;
        err[k] = dist(dd, P, T);
        if (pn_lagged_energy(&m, d, F, G, hG, &psi, P, NULL, 0) != PN_OK) fg->failures++;
        lag[k] = dist(dd, P, T);
        cst[k] = dist(dd, T0, T);
        if (pn_pnet_energy(&net, &pt, Fa, &psi, P, NULL, 0) == PN_OK) al_net += dist(dd, P, Ta);
        if (pn_lagged_energy(&m, d, Fa, G, hG, &psi, P, NULL, 0) == PN_OK) al_lag += dist(dd, P, Ta);
    }
    tsum /= n;
    /* far below the box, where a simulation at a realistic E lives (a sand column at 1e7 Pa
       strains ~1e-4 and steps ~1e-3), and the pairs an implicit solve visits
       (bench_solver_sample: F0 a trial state, often far outside the yield surface, and F near
       it, where the error is the Hessian's): the ratio to the lagged energy there */
    fg->small_ratio = ratio_to_lagged(mo, &m, &net, &rng, n / 10, 0, &fg->failures);
    fg->solver_ratio = ratio_to_lagged(mo, &m, &net, &rng, n / 10, 1, &fg->failures);
    fg->exact_max = fmax(ex_rel, ex_abs / (1e-6 * tsum));
    fg->net_mean = mean(err, n) / tsum;
    fg->lag_mean = mean(lag, n) / tsum;
    fg->const_mean = mean(cst, n) / tsum;
    fg->net_p95 = p95(err, n) / tsum;
    fg->lag_p95 = p95(lag, n) / tsum;
    fg->const_p95 = p95(cst, n) / tsum;
    fg->net_aligned = al_net / n / tsum;
    fg->lag_aligned = al_lag / n / tsum;
    { /* the least energy, regularizer on: F within the box's step, and anywhere in [-3, 3] */
        fg->least_box = fg->least_far = HUGE_VAL;
        for (k = 0; k < n / 10; ++k) {
            pn_real F0[9], F[9], Fa[9], h, psi0, psi;
            pn_pnet_point pt;
            int far;
            bench_box_sample(&rng, d, mo->e_box, mo->de_box, F0, F, Fa);
            h = (pn_real)(mo->h_min + (mo->h_max - mo->h_min) * bench_uniform(&rng));
            if (pn_pnet_prepare(&net_reg, F0, h, &pt, NULL, NULL) != PN_OK ||
                pn_pnet_energy(&net_reg, &pt, F0, &psi0, NULL, NULL, 0) != PN_OK) {
                fg->failures++;
                continue;
            }
            for (far = 0; far <= 1; ++far) {
                if (far) { /* a fresh F, log stretches in [-10, 3]: crushed far beyond the box */
                    pn_real R1[9], R2[9];
                    double e[3];
                    for (i = 0; i < d; ++i) e[i] = -10 + 13 * bench_uniform(&rng);
                    bench_rotation(&rng, d, R1);
                    bench_rotation(&rng, d, R2);
                    bench_compose(d, R1, e, R2, F);
                }
                if (pn_pnet_energy(&net_reg, &pt, F, &psi, NULL, NULL, 0) != PN_OK) continue; /* overflow: +inf */
                psi = (psi - psi0) / m.E;
                if (far) fg->least_far = fmin(fg->least_far, (double)psi);
                else fg->least_box = fmin(fg->least_box, (double)psi);
            }
        }
    }
    /* objectivity and the Hessian, with the regularizer on (as simulated) */
    for (k = 0; k < 1000; ++k) {
        pn_real F0[9], F[9], Fa[9], Q[9], QF0[9], QF[9], h, psi1, psi2, P1[9], P2[9], QP1[9];
        pn_real H[81], Hfd[81], Fp[9], Pp[9], Pm[9];
        pn_pnet_point pt, pq;
        double hmax = 0, emax = 0, step = 1e-6;
        bench_box_sample(&rng, d, mo->e_box, mo->de_box, F0, F, Fa);
        h = (pn_real)(mo->h_min + (mo->h_max - mo->h_min) * bench_uniform(&rng));
        bench_rotation(&rng, d, Q);
        pn_mat_mul(d, Q, F0, QF0);
        pn_mat_mul(d, Q, F, QF);
        if (pn_pnet_prepare(&net_reg, F0, h, &pt, NULL, NULL) != PN_OK ||
            pn_pnet_prepare(&net_reg, QF0, h, &pq, NULL, NULL) != PN_OK ||
            pn_pnet_energy(&net_reg, &pt, F, &psi1, P1, H, 0) != PN_OK ||
            pn_pnet_energy(&net_reg, &pq, QF, &psi2, P2, NULL, 0) != PN_OK) {
            fg->failures++;
            continue;
        }
        pn_mat_mul(d, Q, P1, QP1);
        {
            double op = fabs((double)(psi2 - psi1)) / (fabs((double)psi1) + 1e-300);
            double oP = dist(dd, QP1, P2) / (nrm(dd, P1) + 1e-300);
            if (op > fg->objectivity_psi) fg->objectivity_psi = op;
            if (oP > fg->objectivity_P) fg->objectivity_P = oP;
        }
        for (j = 0; j < dd; ++j) {
            memcpy(Fp, F, sizeof Fp);
            Fp[j] += (pn_real)step;
            pn_pnet_energy(&net_reg, &pt, Fp, NULL, Pp, NULL, 0);
            Fp[j] -= (pn_real)(2 * step);
            pn_pnet_energy(&net_reg, &pt, Fp, NULL, Pm, NULL, 0);
            for (i = 0; i < dd; ++i) Hfd[i * dd + j] = (Pp[i] - Pm[i]) / (pn_real)(2 * step);
        }
        for (i = 0; i < dd * dd; ++i) {
            double a = fabs((double)H[i]), e = fabs((double)(H[i] - Hfd[i]));
            hmax = a > hmax ? a : hmax;
            emax = e > emax ? e : emax;
        }
        if (emax / hmax > fg->hess_fd) fg->hess_fd = emax / hmax;
    }
    if (timing) {
        enum { NT = 256 };
        static pn_real Fs0[NT][9], Fs[NT][9];
        static pn_pnet_point pts[NT];
        pn_real P[9], H[81], psi, sink = 0;
        long reps = 200000, r;
        double t;
        for (k = 0; k < NT; ++k) {
            pn_real Fa[9];
            bench_box_sample(&rng, d, mo->e_box, mo->de_box, Fs0[k], Fs[k], Fa);
            pn_pnet_prepare(&net_reg, Fs0[k], (pn_real)mo->h_min, &pts[k], NULL, NULL);
        }
        t = bench_seconds();
        for (r = 0; r < reps / 4; ++r) sink += pn_pnet_prepare(&net_reg, Fs0[r % NT], (pn_real)mo->h_min, &pts[r % NT], NULL, NULL);
        fg->ns_prepare = (bench_seconds() - t) * 1e9 / (double)(reps / 4);
        t = bench_seconds();
        for (r = 0; r < reps; ++r) {
            pn_pnet_energy(&net_reg, &pts[r % NT], Fs[r % NT], &psi, P, H, 0);
            sink += H[0];
        }
        fg->ns_energy = (bench_seconds() - t) * 1e9 / (double)reps;
        t = bench_seconds();
        for (r = 0; r < reps / 4; ++r) {
            pn_pnet_energy(&net_reg, &pts[r % NT], Fs[r % NT], &psi, P, H, PN_EVAL_PROJECT_PSD);
            sink += H[0];
        }
        fg->ns_energy_psd = (bench_seconds() - t) * 1e9 / (double)(reps / 4);
        if (sink == 12345.678) printf(" ");
    }
    free(err);
    free(lag);
    free(cst);
}

static void return_report(const pn_model *mo, int n, int timing, return_figures *fg) {
    int d = mo->dim, dd = d * d, k, i;
    pn_material m;
    bench_rng rng;
    double sl = 0, st = 0;
    memset(fg, 0, sizeof *fg);
    pn_model_material(mo, (pn_real)mo->youngs_modulus_train_pa, &m, NULL, 0);
    rng.s = 777u + (unsigned)d;
    for (k = 0; k < n; ++k) {
        pn_real F0[9], F[9], Fa[9], h, Z[9], Zr[9], T[9], Tr[9], hn, hr, U[9], s[3], V[9], sr[3];
        pn_real y, sc;
        double dl = 0, dt;
        bench_box_sample(&rng, d, mo->e_box, mo->de_box, F0, F, Fa);
        h = (pn_real)(mo->h_min + (mo->h_max - mo->h_min) * bench_uniform(&rng));
        if (pn_learned_return_map(mo, &m, d, F0, h, Z, &hn, T) != PN_OK ||
            pn_return_map(&m, d, F0, h, Zr, &hr, Tr) != PN_OK) {
            fg->failures++;
            continue;
        }
        pn_svd(d, Z, U, s, V);
        pn_svd(d, Zr, U, sr, V);
        for (i = 0; i < d; ++i) dl += ((double)log(s[i] / sr[i])) * ((double)log(s[i] / sr[i]));
        dl = sqrt(dl);
        dt = dist(dd, T, Tr) / (nrm(dd, Tr) + 1e-300);
        sl += dl;
        st += dt;
        if (dl > fg->logz_max) fg->logz_max = dl;
        if (dt > fg->T_max) fg->T_max = dt;
        /* the learned Z must lie on the surface of the updated state */
        if (hn != h && pn_yield_function(&m, d, Z, hn, &y, &sc) == PN_OK) {
            double ry = fabs((double)y) / (double)sc;
            if (ry > fg->yield_max) fg->yield_max = ry;
        }
    }
    fg->logz_mean = sl / n;
    fg->T_mean = st / n;
    if (timing) {
        enum { NT = 256 };
        static pn_real Fs[NT][9];
        pn_real Z[9], T[9], hn, sink = 0;
        long reps = 100000, r;
        double t;
        for (k = 0; k < NT; ++k) {
            pn_real F0[9], Fa[9];
            bench_box_sample(&rng, d, mo->e_box, mo->de_box, F0, Fs[k], Fa);
        }
        t = bench_seconds();
        for (r = 0; r < reps; ++r) {
            pn_learned_return_map(mo, &m, d, Fs[r % NT], (pn_real)0.1, Z, &hn, T);
            sink += T[0];
        }
        fg->ns_learned = (bench_seconds() - t) * 1e9 / (double)reps;
        t = bench_seconds();
        for (r = 0; r < reps; ++r) {
            pn_return_map(&m, d, Fs[r % NT], (pn_real)0.1, Z, &hn, T);
            sink += T[0];
        }
        fg->ns_rootfind = (bench_seconds() - t) * 1e9 / (double)reps;
        if (sink == 12345.678) printf(" ");
    }
    (void)dd;
}

static int params_of(const pn_model *mo) {
    int l, c = 0;
    for (l = 0; l < mo->mlp.n_layers; ++l) c += mo->mlp.size[l + 1] * (mo->mlp.size[l] + 1);
    return c;
}

static void hidden_of(const pn_model *mo, char *buf, size_t cap) {
    int l;
    size_t len = 0;
    buf[0] = 0;
    for (l = 1; l < mo->mlp.n_layers && len + 8 < cap; ++l)
        len += (size_t)sprintf(buf + len, l == 1 ? "%d" : "-%d", mo->mlp.size[l]);
}

/* the material of model mo with its conditioned parameters set to v (pn_model_param units) */
static int material_at(const pn_model *mo, const double *v, pn_material *m) {
    pn_material_desc d;
    int i;
    pn_model_material_desc(mo, (pn_real)mo->youngs_modulus_train_pa, &d);
    for (i = 0; i < mo->n_params; ++i) pn_model_param_set(&d, mo->param[i].kind, v[i]);
    return pn_material_init(m, &d, NULL, 0) == PN_OK;
}

/* a single-material model's value of parameter kind k (pn_model_param units) */
static double model_value(const pn_model *s, int k) {
    return k == PN_MODEL_PARAM_POISSON ? s->poisson_ratio
         : k == PN_MODEL_PARAM_FRICTION_DEG ? s->friction_angle_deg
         : k == PN_MODEL_PARAM_COHESION ? s->cohesion_strain
         : k == PN_MODEL_PARAM_YIELD_RATIO ? s->yield_stress_ratio
         : k == PN_MODEL_PARAM_HARDENING_RATIO ? s->hardening_ratio
         : k == PN_MODEL_PARAM_CAMCLAY_BETA ? s->camclay_beta : s->camclay_xi;
}

/* a single-material model of mo's family and dimension trained at parameter values v, or NULL */
static const pn_model *single_at(const pn_model *mo, const double *v) {
    int k;
    for (k = 0; pn_models_all[k]; ++k) {
        const pn_model *s = pn_models_all[k]();
        pn_material a;
        pn_pnet net;
        pn_pnet_desc nd;
        int j;
        if (s->n_params || s->kind != PN_MODEL_ENERGY || s->dim != mo->dim || s->elastic != mo->elastic ||
            s->plastic != mo->plastic || !material_at(mo, v, &a))
            continue;
        memset(&nd, 0, sizeof nd);
        nd.energy = s; /* with its learned return mapping, if it has one (the errors are against pn_return_map) */
        for (j = 0; s->return_map && pn_models_all[j]; ++j)
            if (!strcmp(pn_models_all[j]()->name, s->return_map)) nd.return_map = pn_models_all[j]();
        if (pn_pnet_init(&net, &nd, &a, mo->dim, NULL, 0) == PN_OK) return s; /* it serves a: the same material */
    }
    return NULL;
}

/* Conditioned models: the figures at every grid point of their ranges (3 values per parameter,
   the ends and the middle; with 4 parameters the corners and the centre) and at the points of
   the single-material models of their family. */
static int conditioned_report(FILE *f, const char *only, int n, int banner) {
    int k, fails = 0, header = 0;
    for (k = 0; pn_models_all[k]; ++k) {
        const pn_model *mo = pn_models_all[k]();
        double pts[96][PN_MODEL_MAX_PARAMS];
        int np = mo->n_params, npts = 1, g, i, j, q, per = np <= 3 ? 3 : 2;
        if (!np || mo->kind != PN_MODEL_ENERGY || (only && strcmp(only, mo->name))) continue;
        /* up to 3 parameters: ends and middles (3^k points); more: the 2^k corners and the centre */
        for (i = 0; i < np; ++i) npts *= per;
        for (g = 0; g < npts; ++g)
            for (q = g, i = 0; i < np; ++i, q /= per)
                pts[g][i] = mo->param[i].lo + (q % per) / (per - 1.0) * (mo->param[i].hi - mo->param[i].lo);
        if (per == 2) {
            for (i = 0; i < np; ++i) pts[npts][i] = 0.5 * (mo->param[i].lo + mo->param[i].hi);
            ++npts;
        }
        for (j = 0; pn_models_all[j] && npts < 96; ++j) { /* the single-material models' points, once each */
            const pn_model *s = pn_models_all[j]();
            pn_material sm;
            if (s->n_params || s->kind != PN_MODEL_ENERGY || s->dim != mo->dim || s->plastic != mo->plastic ||
                s->elastic != mo->elastic || pn_model_material(s, 1, &sm, NULL, 0) != PN_OK)
                continue;
            for (i = 0; i < np; ++i) pts[npts][i] = model_value(s, mo->param[i].kind);
            for (g = 0; g < npts; ++g) {
                for (i = 0; i < np && fabs(pts[g][i] - pts[npts][i]) <= 1e-9 * (fabs(pts[npts][i]) + 1); ++i) {}
                if (i == np) break;
            }
            if (g == npts) ++npts;
        }
        if (!banner && !header) {
            fprintf(f, "\n## Conditioned energies over their parameter ranges\n\n");
            fprintf(f, "Each row: the conditioned model at one material (the ends and middle of every range; with four\n");
            fprintf(f, "parameters the corners and the centre; and the single-material models' points), measured as above;\n");
            fprintf(f, "\"single\" is the single-material model trained at that material where one ships, and the\n");
            fprintf(f, "conditioned / single ratio of the means.\n\n");
            fprintf(f, "| model | material | exact at F0 | mean | p95 | lagged mean | ratio | small strains | objectivity Psi / P | Hessian vs FD | least energy: box / far | single: model, mean | conditioned / single | ns E+P+H |\n");
            fprintf(f, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
            header = 1;
        }
        for (g = 0; g < npts; ++g) {
            energy_figures e, es;
            pn_material m;
            const pn_model *s;
            char mat[128];
            size_t len = 0;
            if (!material_at(mo, pts[g], &m)) {
                fails++;
                continue;
            }
            for (i = 0; i < np; ++i)
            {
                static const char *const label[] = {"?", "nu", "phi", "c", "sY/E", "K/E", "beta", "xi"};
                int kd = mo->param[i].kind;
                len += (size_t)snprintf(mat + len, sizeof mat - len, "%s%s %.3g", i ? ", " : "",
                                        label[kd >= 1 && kd <= 7 ? kd : 0], pts[g][i]);
            }
            energy_report(mo, &m, n, !banner && g == 0, &e);
            fails += e.failures;
            s = single_at(mo, pts[g]);
            if (s) energy_report(s, &m, n, 0, &es);
            if (banner) {
                fprintf(f, "at %s: mean %.4f, p95 %.4f, ratio to lagged %.3f, small strains %.3f, least energy %.3g / %.3g",
                        mat, e.net_mean, e.net_p95, e.net_mean / e.lag_mean, e.small_ratio, e.least_box, e.least_far);
                if (s) fprintf(f, "; %s %.4f", s->name, es.net_mean);
                fprintf(f, "\n");
                continue;
            }
            fprintf(f, "| %s | %s | %.1e | %.4f | %.4f | %.4f | **%.3f** | %.3f | %.0e / %.0e | %.1e | %.3g / %.3g | ", mo->name,
                    mat, e.exact_max, e.net_mean, e.net_p95, e.lag_mean, e.net_mean / e.lag_mean, e.small_ratio,
                    e.objectivity_psi, e.objectivity_P, e.hess_fd, e.least_box, e.least_far);
            if (s) fprintf(f, "%s, %.4f | %.2f | ", s->name, es.net_mean, e.net_mean / es.net_mean);
            else fprintf(f, "- | - | ");
            if (g == 0) fprintf(f, "%.0f |\n", e.ns_energy);
            else fprintf(f, "|\n");
            fflush(f);
        }
    }
    return fails;
}

int main(int argc, char **argv) {
    const char *out = NULL, *only = NULL;
    int n = 100000, banner = 0, k, fails = 0;
    FILE *f = stdout;
    for (k = 1; k < argc; ++k) {
        if (!strcmp(argv[k], "--out") && k + 1 < argc) out = argv[++k];
        else if (!strcmp(argv[k], "--samples") && k + 1 < argc) n = atoi(argv[++k]);
        else if (!strcmp(argv[k], "--model") && k + 1 < argc) only = argv[++k];
        else if (!strcmp(argv[k], "--banner")) banner = 1;
        else {
            fprintf(stderr, "usage: model_report [--out FILE] [--samples N] [--model NAME [--banner]]\n");
            return 2;
        }
    }
    if (n < 100) n = 100;
    if (out && !(f = fopen(out, "w"))) {
        fprintf(stderr, "model_report: cannot write %s\n", out);
        return 1;
    }
    if (!banner) {
        fprintf(f, "# Shipped models: measured quality and cost\n\n");
        fprintf(f, "Written by `make model-report` (bench/model_report.c); %d fresh samples per model from\n", n);
        fprintf(f, "its training box. Errors are |grad Psi(F; F0) - T(F)| / mean |T| with T the analytic\n");
        fprintf(f, "return mapping; \"lagged\" is the no-network energy psi_el(F G) of plastinet.h, \"T(F0)\"\n");
        fprintf(f, "the constant force. \"aligned\" samples share the rotations of F0 (only the stretches\n");
        fprintf(f, "differ, as within a time step). Ratio = network mean / lagged mean (target <= 0.25).\n");
        fprintf(f, "Exact at F0: max |grad Psi(F0) - T(F0)| / max(|T(F0)|, 1e-6 mean |T|) (target <= 1e-5).\n");
        fprintf(f, "Objectivity: max relative change of Psi / grad Psi under a rotation of F and F0.\n");
        fprintf(f, "Hessian: max |dP/dF - FD| / max |dP/dF| (target <= 1e-4). Costs in ns on this machine.\n");
        fprintf(f, "Small strains: the ratio to lagged with |e0| <= 1e-3 and |de| <= 1e-2, far below the box,\n");
        fprintf(f, "where a simulation at a realistic E lives (a sand column at 1e7 Pa strains ~1e-4). A metal\n");
        fprintf(f, "with a high yield stress stays nearly elastic there, where the lagged energy is exact: the\n");
        fprintf(f, "ratio is then large and says how few pairs yield (tests/test_pnet_return.c holds the network's error\n");
        fprintf(f, "to 1%% of |T| where the lagged energy's is below that).\n");
        fprintf(f, "Solver pairs: the ratio to lagged on pairs as an implicit solve visits them: F0 a step's trial\n");
        fprintf(f, "state (its deviatoric strain up to 100x its volumetric one, far outside the yield surface)\n");
        fprintf(f, "and F within 1e-3..1 |e0| of it, where what counts is the network's Hessian.\n\n");
        fprintf(f, "## Energies\n\n");
        fprintf(f, "Least energy: min of Psi(F) - Psi(F0) per unit E with the regularizer on, F near F0 (the box)\n");
        fprintf(f, "and with log stretches anywhere in [-10, 3] (crushed far beyond the box); bounded models\n");
        fprintf(f, "(softplus output) stay above -C:F0 - |C|^2 / (2 mu).\n\n");
        fprintf(f, "| model | hidden | params | exact at F0 | mean | p95 | lagged mean | lagged p95 | T(F0) mean | ratio | small strains | solver pairs | aligned: net / lagged | objectivity Psi / P | Hessian vs FD | least energy: box / far | ns prepare | ns E+P+H | ns +PSD |\n");
        fprintf(f, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    }
    for (k = 0; pn_models_all[k]; ++k) {
        const pn_model *mo = pn_models_all[k]();
        energy_figures e;
        pn_material m;
        char hid[64];
        if (mo->kind != PN_MODEL_ENERGY || mo->n_params || (only && strcmp(only, mo->name))) continue;
        pn_model_material(mo, (pn_real)mo->youngs_modulus_train_pa, &m, NULL, 0);
        energy_report(mo, &m, n, !banner, &e);
        fails += e.failures;
        hidden_of(mo, hid, sizeof hid);
        if (banner) {
            fprintf(f, "exact at F0: max relative error %.2g (%d samples)\n", e.exact_max, n);
            fprintf(f, "|grad Psi - T| / mean |T|: mean %.4f, p95 %.4f; lagged energy %.4f, %.4f;\n", e.net_mean,
                    e.net_p95, e.lag_mean, e.lag_p95);
            fprintf(f, "  constant T(F0) %.4f, %.4f; ratio to lagged %.3f (target <= 0.25)\n", e.const_mean,
                    e.const_p95, e.net_mean / e.lag_mean);
            fprintf(f, "aligned rotations: mean %.4f, lagged %.4f\n", e.net_aligned, e.lag_aligned);
            fprintf(f, "small strains (|e0| <= 1e-3, |de| <= 1e-2): ratio to lagged %.3f\n", e.small_ratio);
            fprintf(f, "solver pairs (F0 a trial state, F near it): ratio to lagged %.3f\n", e.solver_ratio);
            fprintf(f, "objectivity: Psi %.1e, grad %.1e; Hessian vs FD of gradient %.1e\n", e.objectivity_psi,
                    e.objectivity_P, e.hess_fd);
        } else {
            fprintf(f, "| %s | %s | %d | %.1e | %.4f | %.4f | %.4f | %.4f | %.4f | **%.3f** | %.3f | %.3f | %.4f / %.4f | %.0e / %.0e | %.1e | %.3g / %.3g | %.0f | %.0f | %.0f |\n",
                    mo->name, hid, params_of(mo), e.exact_max, e.net_mean, e.net_p95, e.lag_mean, e.lag_p95,
                    e.const_mean, e.net_mean / e.lag_mean, e.small_ratio, e.solver_ratio, e.net_aligned, e.lag_aligned, e.objectivity_psi,
                    e.objectivity_P, e.hess_fd, e.least_box, e.least_far, e.ns_prepare, e.ns_energy, e.ns_energy_psd);
            fflush(f);
        }
    }
    fails += conditioned_report(f, only, n, banner);
    if (!banner) {
        fprintf(f, "\n## Learned return mappings (against the root find of plastinet.h)\n\n");
        fprintf(f, "| model | hidden | params | log z error mean | max | T rel. error mean | max | yield residual max | ns learned | ns root find |\n");
        fprintf(f, "|---|---|---|---|---|---|---|---|---|---|\n");
    }
    for (k = 0; pn_models_all[k]; ++k) {
        const pn_model *mo = pn_models_all[k]();
        return_figures r;
        char hid[64];
        if (mo->kind != PN_MODEL_RETURN_MAP || (only && strcmp(only, mo->name))) continue;
        return_report(mo, n, !banner, &r);
        fails += r.failures;
        hidden_of(mo, hid, sizeof hid);
        if (banner) {
            fprintf(f, "against the root find (%d samples): |log z - log z_ref| mean %.2g, max %.2g;\n", n,
                    r.logz_mean, r.logz_max);
            fprintf(f, "  |T - T_ref| / |T_ref| mean %.2g, max %.2g; yield residual max %.2g\n", r.T_mean, r.T_max,
                    r.yield_max);
        } else {
            fprintf(f, "| %s | %s | %d | %.2e | %.2e | %.2e | %.2e | %.2e | %.0f | %.0f |\n", mo->name, hid,
                    params_of(mo), r.logz_mean, r.logz_max, r.T_mean, r.T_max, r.yield_max, r.ns_learned,
                    r.ns_rootfind);
        }
    }
    if (fails) fprintf(stderr, "model_report: %d evaluations failed\n", fails);
    if (out) fclose(f);
    return fails ? 1 : 0;
}
