/* bench_coarse: the stress formulation's coarse correction (pn_mpm_implicit_desc.coarse_every)
   against the Gauss-Seidel sweeps alone, as the grid grows (docs/results.md, "The coarse
   correction").

   Scene: an elastic StVK-Hencky block (E --E [1e7] Pa, nu 0.3, 1500 kg/m^3) 0.2 x 0.4 x 0.2
   m, 2 particles per cell per axis, dropped from rest on the floor of a 1 m box (walls
   SEPARATE, Coulomb 0.5), one step per 1/60 s frame, --steps [10] steps; at res 32, 48 and
   64 (--res to pick). Each size runs three times in one process: the sweeps alone at the
   library's tolerance, the same with the coarse correction, and (--reference) the sweeps
   alone at a 100 times tighter tolerance as the answer both are measured against (the
   largest particle gap in cells after the last step). Columns: sweeps, corrections and CG
   iterations per step, CPU seconds per step, the gap. A Drucker-Prager block (sand) shows
   that the correction is not taken on plastic material (0 corrections).
   Usage: bench_coarse [--res N]... [--steps N] [--E PA] [--reference] [--md FILE] */
#define PLASTINET_IMPLEMENTATION
#define PLASTINET_MPM_IMPLEMENTATION
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "bench_util.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct run {
    double sweeps, corrections, cg, cpu_s; /* per step */
    int ok;
} run;

static pn_mpm_world *block(int res, double E, pn_plastic_model pl) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material_desc md;
    pn_material m;
    double dx, lo[3], sz[3] = {0.2, 0.4, 0.2};
    int c[3], i, a, b, e, g;
    size_t n = 0;
    pn_real *x;
    memset(&wd, 0, sizeof wd);
    wd.dim = 3;
    wd.res[0] = wd.res[1] = wd.res[2] = res;
    wd.dx_m = 1.0 / res;
    wd.gravity[1] = -9.81;
    wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = 0.5;
    dx = wd.dx_m / 2;
    for (i = 0; i < 3; ++i) c[i] = (int)(sz[i] / dx + 0.5);
    wd.max_particles = (size_t)c[0] * (size_t)c[1] * (size_t)c[2];
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK) return NULL;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_STVK_HENCKY;
    md.plastic = pl;
    md.youngs_modulus_pa = E;
    md.poisson_ratio = 0.3;
    md.friction_angle_deg = 30;
    if (pn_material_init(&m, &md, NULL, 0) != PN_OK || (g = pn_mpm_add_group(w, &m, 1500)) < 0) {
        pn_mpm_destroy(w);
        return NULL;
    }
    lo[0] = lo[2] = 0.4, lo[1] = w->s.wall_lo[1];
    x = (pn_real *)malloc(sizeof(pn_real) * 3 * wd.max_particles);
    if (!x) {
        pn_mpm_destroy(w);
        return NULL;
    }
    for (a = 0; a < c[0]; ++a)
        for (b = 0; b < c[1]; ++b)
            for (e = 0; e < c[2]; ++e, ++n) {
                x[3 * n] = (pn_real)(lo[0] + (a + 0.5) * dx);
                x[3 * n + 1] = (pn_real)(lo[1] + (b + 0.5) * dx);
                x[3 * n + 2] = (pn_real)(lo[2] + (e + 0.5) * dx);
            }
    if (pn_mpm_add_particles(w, g, n, x, NULL, (pn_real)(dx * dx * dx)) != PN_OK) {
        pn_mpm_destroy(w);
        w = NULL;
    }
    free(x);
    return w;
}

/* steps of 1/60 s; coarse: coarse_every (-1 never); tol_scale: sweep_tol over the default */
static run go(pn_mpm_world *w, int steps, int coarse, double tol_scale) {
    pn_mpm_implicit_desc id;
    pn_mpm_stats st;
    run r;
    double t0 = bench_seconds();
    int s;
    memset(&r, 0, sizeof r);
    memset(&id, 0, sizeof id);
    id.formulation = PN_MPM_FORMULATION_STRESS;
    id.coarse_every = coarse;
    id.sweep_tol = (pn_real)(1e-4 * tol_scale);
    if (tol_scale < 1) id.sweeps_max = 1000000;
    r.ok = 1;
    for (s = 0; s < steps && r.ok; ++s) {
        r.ok = pn_mpm_step_implicit(w, 1.0 / 60, &id, &st) == PN_OK;
        if (!r.ok) fprintf(stderr, "bench_coarse: %s\n", pn_mpm_error(w));
        r.sweeps += st.sweeps, r.corrections += st.coarse_corrections, r.cg += st.cg_iters;
    }
    r.cpu_s = (bench_seconds() - t0) / steps;
    r.sweeps /= steps, r.corrections /= steps, r.cg /= steps;
    return r;
}

static double gap(const pn_mpm_world *a, const pn_mpm_world *b) {
    double g = 0;
    size_t i;
    for (i = 0; i < a->n * 3; ++i) g = fmax(g, fabs((double)a->x[i] - (double)b->x[i]) / a->desc.dx_m);
    return g;
}

int main(int argc, char **argv) {
    int res[8] = {32, 48, 64}, nres = 3, user_res = 0, steps = 10, reference = 0, i, k;
    double E = 1e7;
    const char *md = NULL;
    FILE *out;
    for (i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--res") && i + 1 < argc && user_res < 8) res[user_res++] = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--steps") && i + 1 < argc) steps = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--E") && i + 1 < argc) E = atof(argv[++i]);
        else if (!strcmp(argv[i], "--reference")) reference = 1;
        else if (!strcmp(argv[i], "--md") && i + 1 < argc) md = argv[++i];
        else {
            fprintf(stderr, "usage: bench_coarse [--res N]... [--steps N] [--E PA] [--reference] [--md FILE]\n");
            return !!strcmp(argv[i], "--help");
        }
    }
    if (user_res) nres = user_res;
    if (steps < 1 || E <= 0) return 1;
    out = md ? fopen(md, "w") : stdout;
    if (!out) return 1;
    fprintf(out, "Elastic block (E %g Pa) dropped on the floor, 3D, %d steps of 1/60 s (the sweeps' tolerance the "
                 "library's; the gap: the largest particle distance from the 100x tighter sweeps, in cells)\n\n",
            E, steps);
    fprintf(out, "| res | particles | solve | sweeps / step | corrections / step | CG / step | CPU s / step | gap (dx) |\n");
    fprintf(out, "|---|---|---|---|---|---|---|---|\n");
    for (k = 0; k < nres; ++k) {
        pn_mpm_world *w[3] = {block(res[k], E, PN_PLASTIC_NONE), block(res[k], E, PN_PLASTIC_NONE),
                              reference ? block(res[k], E, PN_PLASTIC_NONE) : NULL};
        run r[3];
        static const char *const names[3] = {"sweeps alone", "with the coarse correction", "sweeps, tolerance / 100"};
        if (!w[0] || !w[1] || (reference && !w[2])) return 1;
        r[0] = go(w[0], steps, -1, 1);
        r[1] = go(w[1], steps, 0, 1);
        if (reference) r[2] = go(w[2], steps, -1, 0.01);
        for (i = 0; i < (reference ? 3 : 2); ++i) {
            char g[32] = "";
            if (reference && i < 2) snprintf(g, sizeof g, "%.1e", gap(w[i], w[2]));
            fprintf(out, "| %d | %lu | %s%s | %.1f | %.1f | %.1f | %.3f | %s |\n", res[k], (unsigned long)w[i]->n, names[i],
                    r[i].ok ? "" : " (failed)", r[i].sweeps, r[i].corrections, r[i].cg, r[i].cpu_s, g);
            fflush(out);
        }
        for (i = 0; i < 3; ++i) pn_mpm_destroy(w[i]);
    }
    { /* plastic material: the correction is not taken */
        pn_mpm_world *s = block(res[0], E, PN_PLASTIC_DRUCKER_PRAGER);
        run r;
        if (!s) return 1;
        r = go(s, 2, 4, 1);
        fprintf(out, "\nDrucker-Prager block (sand), res %d, coarse_every 4: %.1f corrections per step (not taken on "
                     "plastic material), %.1f sweeps per step\n", res[0], r.corrections, r.sweeps);
        pn_mpm_destroy(s);
    }
    if (md) fclose(out);
    return 0;
}
