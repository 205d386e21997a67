/* rom_poke.c: a reduced-order jelly cylinder (plastinet_rom.h) standing on a held base, poked
   at its top rim again and again from random directions, each poke released before the next
   (the model was trained on single pokes only).

   build/rom_poke [--pokes N] [--seed S] [--scheme IM|LN|LL|EN|EL] [--samples M] [--substeps S]
                  [--refine R] [--png] [--out DIR] [--quiet]

   Each poke pushes 0.06 N for 0.25 s; one poke every 3 s of simulated time, stepped at the
   snapshot interval 1/144 s divided by S. Scheme IM (the default): the implicit step (BDF2),
   S = 1; the paper's explicit schemes (L/E quadrature, N/L projection, M projection points)
   need S = 12, the full-order step (they are stable up to about three times that,
   docs/rom.md), and are about 30 times slower. Prints the largest displacement
   after each poke, wall milliseconds per step and wall seconds per simulated second;
   --png writes one picture per 1/24 s (DIR/frame_0001.png ...) of the points drawn at
   --refine R times the training resolution. Build: cc -O2 examples/rom_poke.c -lm */
#define PLASTINET_IMPLEMENTATION
#include "pn_example.h"
#include "../plastinet_rom.h"
#include "../models/rom_poke.h"
#include "pn_rom_scenes.h"

int main(int argc, char **argv) {
    const pn_rom_model *m = pn_rom_model_poke();
    pn_rs_scene s = pn_rs_get(PN_RS_POKE, 1);
    pn_rs_instance in = pn_rs_instance_of(&s, 0);
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    const char *out = "build/rom_poke", *scheme = "IM";
    char why[256], path[1200];
    int pokes = 10, samples = 50, refine = 1, png = 0, quiet = 0, substeps = 0, a, step, steps, next = 0, frame = 0;
    unsigned long long seed = 7;
    double wall = 0, *Xd, lo[3] = {0.02, 0.02, 0.0}, hi[3] = {0.06, 0.06, 0.065};
    float *Xf, *x;
    size_t n, p;
    for (a = 1; a < argc; ++a) {
        if (!strcmp(argv[a], "--pokes") && a + 1 < argc) pokes = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--seed") && a + 1 < argc) seed = strtoull(argv[++a], NULL, 10);
        else if (!strcmp(argv[a], "--samples") && a + 1 < argc) samples = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--scheme") && a + 1 < argc) scheme = argv[++a];
        else if (!strcmp(argv[a], "--refine") && a + 1 < argc) refine = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--substeps") && a + 1 < argc) substeps = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--out") && a + 1 < argc) out = argv[++a];
        else if (!strcmp(argv[a], "--png")) png = 1;
        else if (!strcmp(argv[a], "--quiet")) quiet = 1;
        else {
            fprintf(stderr, "usage: %s [--pokes N] [--seed S] [--samples M] [--scheme IM|LN|LL|EN|EL] [--substeps S] [--refine R] "
                            "[--png] [--out DIR] [--quiet]\n", argv[0]);
            return 2;
        }
    }
    if (substeps == 0) substeps = strcmp(scheme, "IM") ? 12 : 1;
    if (pokes < 1 || pokes > PN_RS_MAX_LOADS || refine < 1 || substeps < 1 || strlen(scheme) != 2) {
        fprintf(stderr, "--pokes 1 .. %d, --refine and --substeps >= 1, --scheme two letters\n", PN_RS_MAX_LOADS);
        return 2;
    }
    in.n_loads = pokes;
    for (a = 0; a < pokes; ++a) pn_rs_poke(&in.load[a], 2 * PN_RS_PI * pn_rs_rand(&seed), 3.0 * a);
    memset(&desc, 0, sizeof desc);
    desc.model = m, desc.samples = samples;
    desc.quadrature = scheme[0] == 'L' ? PN_ROM_LAGRANGIAN : PN_ROM_EULERIAN;
    desc.projection = scheme[1] == 'N' ? PN_ROM_NONLINEAR : PN_ROM_LINEAR;
    if (!strcmp(scheme, "IM")) desc.integrator = PN_ROM_BDF2;
    if (pn_rom_create(&desc, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "pn_rom_create: %s\n", why);
        return 1;
    }
    if (!pn_rs_rom_setup(w, &in)) return 1;
    n = pn_rom_lattice(m, refine, NULL, 0);
    Xd = (double *)malloc(sizeof(double) * 3 * n), Xf = (float *)malloc(sizeof(float) * 3 * n);
    x = (float *)malloc(sizeof(float) * 3 * n);
    pn_rom_lattice(m, refine, Xd, n);
    for (p = 0; p < 3 * n; ++p) Xf[p] = (float)Xd[p];
    if (png && !pn_ex_mkdirs(out)) return 1;
    steps = (int)(3.0 * pokes * 144 + 0.5) * substeps;
    for (step = 0; step < steps; ++step) {
        double t0, dt = s.frame_dt / substeps;
        if (!pn_rs_rom_events(w, &in, step * dt, &next)) return 1;
        t0 = pn_ex_seconds();
        if (pn_rom_step(w, dt, NULL) != PN_OK) {
            fprintf(stderr, "step %d: %s\n", step, pn_rom_error(w));
            return 1;
        }
        wall += pn_ex_seconds() - t0;
        if ((png && (step + 1) % (6 * substeps) == 0) || (step + 1) % (432 * substeps) == 0) /* draw only what is shown */
            pn_rom_map(w, n, Xf, x, NULL);
        if (png && (step + 1) % (6 * substeps) == 0) {
            snprintf(path, sizeof path, "%s/frame_%04d.png", out, ++frame);
            pn_rs_draw(path, n, x, Xd, m->cell_m / refine, w->time_s, lo, hi, 0.012, "displacement (mm)", 1000, 8,
                       "reduced-order cylinder, poked (plastinet_rom.h)");
        }
        if (!quiet && (step + 1) % (432 * substeps) == 0) {
            double dmax = 0;
            for (p = 0; p < n; ++p) {
                double e0 = x[3 * p] - Xd[3 * p], e1 = x[3 * p + 1] - Xd[3 * p + 1], e2 = x[3 * p + 2] - Xd[3 * p + 2];
                dmax = fmax(dmax, sqrt(e0 * e0 + e1 * e1 + e2 * e2));
            }
            printf("  t = %4.1f s: poke %d done, largest displacement now %.2f mm\n", w->time_s, (step + 1) / (432 * substeps),
                   1e3 * dmax);
        }
    }
    printf("%d pokes, %d steps: %.3f ms per step, %.3f wall s per simulated s\n", pokes, steps, 1e3 * wall / steps,
           wall / (steps * s.frame_dt));
    pn_rom_destroy(w);
    free(Xd), free(Xf), free(x);
    return 0;
}
