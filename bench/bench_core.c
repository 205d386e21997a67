/* bench_core: nanoseconds per call of the constitutive core, 2D and 3D, and per particle of
   the PlasticityNet energy with P and its PSD dP/dF (what an implicit Newton iteration asks
   of every particle), one particle at a time in double (pn_pnet_energy) against blocks of
   PN_MLP_LANES in float lanes (pn_pnet_energy_lanes), beside the analytic lagged energy.
   Build: cc -std=c99 -O2 bench/bench_core.c -lm -o bench_core
   Usage: bench_core [--csv FILE] [--reps N]
   Inputs are random F = R1 diag(exp(e)) R2 with e in [-0.3, 0.3]^d, so return mappings see a
   mix of elastic and plastic points. CPU time by clock(); results are per machine and never
   asserted anywhere. */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../models/pn_models.h"
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "bench_util.h"

#define NF 1024

static void bench_inputs(int d, pn_real *Fs) {
    bench_rng r;
    int k, i;
    r.s = 12345u + (unsigned)d;
    for (k = 0; k < NF; ++k) {
        pn_real R1[9], R2[9];
        double e[3];
        bench_rotation(&r, d, R1);
        bench_rotation(&r, d, R2);
        for (i = 0; i < d; ++i) e[i] = 0.6 * bench_uniform(&r) - 0.3;
        bench_compose(d, R1, e, R2, Fs + 9 * k);
    }
}

enum { OP_SVD, OP_ENERGY, OP_ENERGY_PSD, OP_RETURN, OP_VM_ENERGY, OP_LAGGED };

static double bench_op(int op, const pn_material *m, int d, const pn_real *Fs, long reps,
                       double *sink) {
    pn_real U[9], s[3], V[9], P[9], H[81], psi = 0, Z[9], T[9], G[9], hg = 0, h = 0;
    long it;
    clock_t t0;
    if (op == OP_LAGGED) pn_lagged_prepare(m, d, Fs, 0, G, &hg);
    t0 = clock();
    for (it = 0; it < reps; ++it) {
        const pn_real *F = Fs + 9 * (it % NF);
        switch (op) {
        case OP_SVD: pn_svd(d, F, U, s, V); *sink += s[0]; break;
        case OP_ENERGY: pn_elastic_energy(m, d, F, 0, &psi, P, H, 0); *sink += H[0]; break;
        case OP_ENERGY_PSD: pn_elastic_energy(m, d, F, 0, &psi, P, H, PN_EVAL_PROJECT_PSD); *sink += H[0]; break;
        case OP_RETURN: pn_return_map(m, d, F, 0, Z, &h, T); *sink += T[0]; break;
        case OP_VM_ENERGY: pn_von_mises_energy(m, d, F, 0, &psi, P, H, 0); *sink += H[0]; break;
        case OP_LAGGED: pn_lagged_energy(m, d, F, G, hg, &psi, P, H, 0); *sink += H[0]; break;
        }
    }
    return (double)(clock() - t0) / CLOCKS_PER_SEC * 1e9 / (double)reps;
}

int main(int argc, char **argv) {
    static pn_real Fs[2][9 * NF];
    const char *csv = NULL;
    long reps = 200000;
    double sink = 0;
    FILE *out = NULL;
    int i, d;
    struct { const char *name; pn_elastic_model e; pn_plastic_model p; } mats[] = {
        {"fixed_corotated", PN_ELASTIC_FIXED_COROTATED, PN_PLASTIC_NONE},
        {"stvk_hencky", PN_ELASTIC_STVK_HENCKY, PN_PLASTIC_NONE},
        {"neo_hookean", PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_NONE},
        {"sand_drucker_prager", PN_ELASTIC_DEFAULT, PN_PLASTIC_DRUCKER_PRAGER},
        {"metal_von_mises", PN_ELASTIC_DEFAULT, PN_PLASTIC_VON_MISES},
        {"metal_von_mises_nh", PN_ELASTIC_NEO_HOOKEAN, PN_PLASTIC_VON_MISES},
        {"snow_cam_clay", PN_ELASTIC_DEFAULT, PN_PLASTIC_CAM_CLAY},
        {"snow_stomakhin", PN_ELASTIC_DEFAULT, PN_PLASTIC_SNOW_STOMAKHIN},
    };
    for (i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--csv") && i + 1 < argc) csv = argv[++i];
        else if (!strcmp(argv[i], "--reps") && i + 1 < argc) reps = atol(argv[++i]);
        else {
            fprintf(stderr, "usage: bench_core [--csv FILE] [--reps N]\n");
            return 2;
        }
    }
    if (reps < NF) reps = NF;
    if (csv && !(out = fopen(csv, "w"))) {
        fprintf(stderr, "bench_core: cannot write %s\n", csv);
        return 1;
    }
    bench_inputs(2, Fs[0]);
    bench_inputs(3, Fs[1]);
    if (out) fprintf(out, "dim,material,operation,ns_per_call\n");
    printf("%-22s %-4s %10s %12s %12s %12s %12s %12s\n", "material", "dim", "svd", "energy+P+H",
           "+psd", "return_map", "vm_energy", "lagged");
    for (i = 0; i < (int)(sizeof mats / sizeof mats[0]); ++i)
        for (d = 2; d <= 3; ++d) {
            pn_material_desc desc;
            pn_material m;
            double ns[6];
            int op;
            memset(&desc, 0, sizeof desc);
            desc.elastic = mats[i].e;
            desc.plastic = mats[i].p;
            desc.youngs_modulus_pa = 1e7;
            desc.poisson_ratio = 0.3;
            desc.friction_angle_deg = 30;
            desc.yield_stress_pa = 1e5;
            desc.camclay_beta = 0.3;
            desc.camclay_xi = 0.5;
            desc.snow_theta_c = 0.025;
            desc.snow_theta_s = 0.0075;
            desc.snow_xi = 10;
            if (pn_material_init(&m, &desc, NULL, 0) != PN_OK) return 1;
            for (op = 0; op < 6; ++op) {
                int vm = m.plastic == PN_PLASTIC_VON_MISES && m.elastic == PN_ELASTIC_STVK_HENCKY;
                ns[op] = (op == OP_VM_ENERGY && !vm) ? -1 : bench_op(op, &m, d, Fs[d - 2], reps, &sink);
                if (out && ns[op] >= 0) {
                    static const char *names[] = {"svd", "energy_P_H", "energy_P_H_psd", "return_map",
                                                  "vm_energy_P_H", "lagged_energy_P_H"};
                    fprintf(out, "%d,%s,%s,%.1f\n", d, mats[i].name, names[op], ns[op]);
                }
            }
            printf("%-22s %-4d %10.0f %12.0f %12.0f %12.0f ", mats[i].name, d, ns[0], ns[1], ns[2], ns[3]);
            if (ns[4] >= 0) printf("%12.0f ", ns[4]); else printf("%12s ", "-");
            printf("%12.0f\n", ns[5]);
        }
    /* PlasticityNet: every shipped energy model at its training material, E = 1e7 Pa, at pairs
       (F0, F) with F0 from the inputs and F a step of up to 1e-2 from it */
    printf("\n%-22s %-4s %14s %14s %8s %16s\n", "PlasticityNet model", "dim", "double ns", "lanes ns", "speedup",
           "lagged+psd ns");
    for (i = 0; pn_models_all[i]; ++i) {
        const pn_model *mo = pn_models_all[i]();
        pn_material m;
        pn_pnet net;
        pn_pnet_desc pd;
        static pn_pnet_point pts[NF];
        static pn_real F1[9 * NF], P[9 * PN_MLP_LANES], H[81 * PN_MLP_LANES], psi[PN_MLP_LANES];
        const pn_pnet_point *pp[PN_MLP_LANES];
        pn_result st[PN_MLP_LANES];
        double ns[3];
        long it, n;
        int k, a;
        clock_t t0;
        if (mo->kind != PN_MODEL_ENERGY || pn_model_material(mo, 1e7, &m, NULL, 0) != PN_OK) continue;
        d = mo->dim;
        memset(&pd, 0, sizeof pd);
        pd.energy = mo;
        if (pn_pnet_init(&net, &pd, &m, d, NULL, 0) != PN_OK) continue;
        for (k = 0; k < NF; ++k) {
            const pn_real *F0 = Fs[d - 2] + 9 * k;
            pn_pnet_prepare(&net, F0, 0, &pts[k], NULL, NULL);
            for (a = 0; a < d * d; ++a) F1[9 * k + a] = F0[a] + (pn_real)(1e-2 * (((k * 7 + a * 3) % 11) / 5.0 - 1));
        }
        n = reps / 8;
        t0 = clock();
        for (it = 0; it < n; ++it) {
            k = (int)(it % NF);
            pn_pnet_energy(&net, &pts[k], F1 + 9 * k, psi, P, H, PN_EVAL_PROJECT_PSD);
            sink += H[0];
        }
        ns[0] = (double)(clock() - t0) / CLOCKS_PER_SEC * 1e9 / (double)n;
        t0 = clock();
        for (it = 0; it < n; it += PN_MLP_LANES) {
            pn_real Fb[9 * PN_MLP_LANES];
            for (k = 0; k < PN_MLP_LANES; ++k) {
                int q = (int)((it + k) % NF);
                pp[k] = &pts[q];
                memcpy(Fb + k * d * d, F1 + 9 * q, sizeof(pn_real) * (size_t)(d * d));
            }
            pn_pnet_energy_lanes(&net, PN_MLP_LANES, pp, Fb, psi, P, H, PN_EVAL_PROJECT_PSD, st);
            sink += H[0];
        }
        ns[1] = (double)(clock() - t0) / CLOCKS_PER_SEC * 1e9 / (double)n;
        ns[2] = bench_op(OP_LAGGED, &m, d, Fs[d - 2], reps, &sink); /* + PSD below */
        {
            pn_real G[9], hg = 0, hh[81], pp2[9], ps2;
            pn_lagged_prepare(&m, d, Fs[d - 2], 0, G, &hg);
            t0 = clock();
            for (it = 0; it < reps; ++it) {
                pn_lagged_energy(&m, d, Fs[d - 2] + 9 * (it % NF), G, hg, &ps2, pp2, hh, PN_EVAL_PROJECT_PSD);
                sink += hh[0];
            }
            ns[2] = (double)(clock() - t0) / CLOCKS_PER_SEC * 1e9 / (double)reps;
        }
        printf("%-22s %-4d %14.0f %14.0f %7.1fx %16.0f\n", mo->name, d, ns[0], ns[1], ns[0] / ns[1], ns[2]);
        if (out) fprintf(out, "%d,%s,pnet_energy_P_H_psd_double,%.1f\n%d,%s,pnet_energy_P_H_psd_lanes,%.1f\n", d,
                         mo->name, ns[0], d, mo->name, ns[1]);
    }
    if (out) fclose(out);
    fprintf(stderr, "(ns per call; checksum %g)\n", sink);
    return 0;
}
