/* rom_crosscheck.c: every reduced-order model of models/pn_rom_models.h against torch. For each
   model NAME, build/rom_NAME_ref.txt (gen/rom_crosscheck.py: torch float64 autograd on the
   weights parsed back out of the header) holds 64 inputs (X, xhat) and g, dg/dX, dg/dxhat;
   pn_rom_eval (the double path) and the float lanes (pn_rom_map) must agree with them.
   tests/run.sh writes the references and runs this when torch is installed.
   Last line: N passed, N failed. */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../plastinet_rom.h"
#include "../models/pn_rom_models.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv) {
    const char *dir = argc > 1 ? argv[1] : "build";
    int passed = 0, failed = 0, k;
    for (k = 0; pn_rom_models_all[k]; ++k) {
        const pn_rom_model *m = pn_rom_models_all[k]();
        char path[512];
        FILE *f;
        int d, K, cnt, i, j, ok = 1;
        double eg = 0, eF = 0, eG = 0, sg = 0, sF = 0, sG = 0, ef = 0;
        pn_rom_desc desc;
        pn_rom_world *w = NULL;
        snprintf(path, sizeof path, "%s/rom_%s_ref.txt", dir, m->name);
        if (!(f = fopen(path, "r")) || fscanf(f, "%d %d %d", &d, &K, &cnt) != 3 || d != m->dim || K != m->latent) {
            printf("FAIL rom %s: no reference %s of the model's size (gen/rom_crosscheck.py %s)\n", m->name, path, m->name);
            failed++;
            if (f) fclose(f);
            continue;
        }
        memset(&desc, 0, sizeof desc);
        desc.model = m;
        if (pn_rom_create(&desc, &w, NULL, 0) != PN_OK) ok = 0;
        for (i = 0; i < cnt && ok; ++i) {
            double X[3], xh[PN_ROM_MAX_LATENT], g[3], F[9], G[3 * PN_ROM_MAX_LATENT], cg[3], cF[9], cG[3 * PN_ROM_MAX_LATENT];
            float Xf[3], xf[3], Ff[9];
            for (j = 0; j < d; ++j) ok &= fscanf(f, "%lf", &X[j]) == 1;
            for (j = 0; j < K; ++j) ok &= fscanf(f, "%lf", &xh[j]) == 1;
            for (j = 0; j < d; ++j) ok &= fscanf(f, "%lf", &g[j]) == 1;
            for (j = 0; j < d * d; ++j) ok &= fscanf(f, "%lf", &F[j]) == 1;
            for (j = 0; j < d * K; ++j) ok &= fscanf(f, "%lf", &G[j]) == 1;
            if (!ok) break;
            pn_rom_eval(m, xh, 1, X, cg, cF, cG);
            for (j = 0; j < d; ++j) eg = fmax(eg, fabs(cg[j] - g[j])), sg = fmax(sg, fabs(g[j]));
            for (j = 0; j < d * d; ++j) eF = fmax(eF, fabs(cF[j] - F[j])), sF = fmax(sF, fabs(F[j]));
            for (j = 0; j < d * K; ++j) eG = fmax(eG, fabs(cG[j] - G[j])), sG = fmax(sG, fabs(G[j]));
            /* the float lanes at the same latent */
            pn_rom_set_latent(w, xh, NULL);
            for (j = 0; j < d; ++j) Xf[j] = (float)X[j];
            pn_rom_map(w, 1, Xf, xf, Ff);
            for (j = 0; j < d; ++j) ef = fmax(ef, fabs((double)xf[j] - g[j]) / sg);
        }
        fclose(f);
        pn_rom_destroy(w);
        eg /= sg, eF /= sF, eG /= sG;
        ok = ok && eg <= 1e-12 && eF <= 1e-10 && eG <= 1e-10 && ef <= 1e-5;
        printf("%s rom %s: %d inputs; double path vs torch (relative to the largest value): g %.1e, dg/dX %.1e, dg/dxhat "
               "%.1e; float path g %.1e (bars 1e-12, 1e-10, 1e-10, 1e-5)\n",
               ok ? "ok  " : "FAIL", m->name, cnt, eg, eF, eG, ef);
        if (ok) passed++;
        else failed++;
    }
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
