/* rom_poke.c: a reduced-order jelly cylinder (plastinet_rom.h) standing on a held base, poked
   at its top rim again and again from random directions, each poke released before the next
   (the model was trained on single pokes only).

   build/rom_poke [--pokes N] [--seed S] [--scheme IM|LN|LL|EN|EL] [--samples M] [--substeps S]
                  [--refine R] [--png] [--all-frames] [--out DIR] [--quiet] [--help]

   Each poke pushes 0.06 N for 0.25 s; one poke every 3 s of simulated time, stepped at the
   snapshot interval 1/144 s divided by S. Scheme IM (the default): the implicit step (BDF2),
   S = 1; the paper's explicit schemes need S = 12 (the explicit step is refused above
   pn_rom_stable_dt) and are about 30 times slower. Prints the largest displacement after each
   poke, wall milliseconds per step and wall seconds per simulated second. --help lists every
   flag. Build: cc -O2 examples/rom_poke.c -lm */
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* particles only: FEM and coupling left out of the build */
#include "common/pn_example.h"
#include "../plastinet_rom.h"
#include "../models/rom_poke.h"
#include "common/pn_rom_scenes.h"

static void usage(FILE *f, const char *prog) {
    fprintf(f,
            "usage: %s [--pokes N] [--seed S] [--scheme IM|LN|LL|EN|EL] [--samples M] [--substeps S] [--refine R]\n"
            "       [--png] [--all-frames] [--out DIR] [--quiet] [--help]\n"
            "A reduced-order jelly cylinder (models/rom_poke.h) on a held base, poked at its top rim from random\n"
            "directions, one poke (0.06 N for 0.25 s) every 3 s of simulated time.\n"
            "  --pokes N       how many pokes, 1 .. %d [5]; the run lasts 3 N simulated seconds\n"
            "  --seed S        seed of the poke directions [7]\n"
            "  --scheme XY     how the reduced model steps [IM]:\n"
            "                    IM  implicit (BDF2): the latent minimizes the incremental potential summed over\n"
            "                        a fixed cubature of the body, by Newton; one step per 1/144 s snapshot interval\n"
            "                    the paper's explicit step (an MPM step around a few sampled points, projected\n"
            "                    back onto the latent), 12 substeps by default; first letter, the quadrature:\n"
            PN_RS_SCHEME_HELP
            "  --samples M     explicit schemes: projection points per step [50]\n"
            "  --substeps S    steps per 1/144 s [IM 1, explicit 12]; an explicit step above 1.5x\n"
            "                  pn_rom_stable_dt is refused\n"
            "  --refine R      pictures: draw the body at R times the training resolution per axis, 1 .. 64 [1]\n"
            "  --png           pictures into DIR: preview.png, an animated PNG of the first poke (3 s at 12\n"
            "                  frames per second, in real time), and poke_01.png ... one still per poke as its push ends\n"
            "  --all-frames    with --png, also every 1/24 s as DIR/frame_0001.png ... (360 for 5 pokes)\n"
            "  --out DIR       where pictures go [build/rom_poke]\n"
            "  --quiet         only the summary line\n"
            "  --help          this help\n",
            prog, PN_RS_MAX_LOADS);
}

int main(int argc, char **argv) {
    const pn_rom_model *m = pn_rom_model_poke();
    pn_rs_scene s = pn_rs_get(PN_RS_POKE, 1);
    pn_rs_instance in = pn_rs_instance_of(&s, 0);
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    const char *out = "build/rom_poke", *scheme = "IM";
    char why[256], path[1200];
    int pokes = 5, samples = 50, refine = 1, png = 0, all = 0, quiet = 0, substeps = 0, a, step, steps, next = 0, frame = 0;
    int per_frame, per_poke, still = 0;
    pn_apng *anim = NULL;
    unsigned char *rgb = NULL;
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
        else if (!strcmp(argv[a], "--all-frames")) all = 1;
        else if (!strcmp(argv[a], "--quiet")) quiet = 1;
        else if (!strcmp(argv[a], "--help") || !strcmp(argv[a], "-h")) {
            usage(stdout, argv[0]);
            return 0;
        } else {
            fprintf(stderr, "%s: unknown or incomplete flag %s\n", argv[0], argv[a]);
            usage(stderr, argv[0]);
            return 2;
        }
    }
    if (substeps == 0) substeps = strcmp(scheme, "IM") ? 12 : 1;
    if (pokes < 1 || pokes > PN_RS_MAX_LOADS || refine < 1 || refine > PN_ROM_MAX_REFINE || substeps < 1 ||
        (strcmp(scheme, "IM") && (strlen(scheme) != 2 || !strchr("LE", scheme[0]) || !strchr("NL", scheme[1])))) {
        fprintf(stderr, "--pokes 1 .. %d, --refine 1 .. %d, --substeps >= 1, --scheme IM, LN, LL, EN or EL (--help)\n",
                PN_RS_MAX_LOADS, PN_ROM_MAX_REFINE);
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
    if (!Xd || !Xf || !x) {
        fprintf(stderr, "out of memory for %lu points\n", (unsigned long)n);
        return 1;
    }
    if (png) {
        if (!pn_ex_mkdirs(out)) {
            fprintf(stderr, "cannot create %s\n", out);
            return 1;
        }
        snprintf(path, sizeof path, "%s/preview.png", out);
        rgb = (unsigned char *)malloc(PN_RS_DRAW_W * PN_RS_DRAW_H * 3);
        if (!rgb || !(anim = pn_apng_open(path, PN_RS_DRAW_W, PN_RS_DRAW_H, 12))) {
            fprintf(stderr, "cannot start %s\n", path);
            return 1;
        }
    }
    per_frame = 6 * substeps, per_poke = 432 * substeps; /* 1/24 s and 3 s in steps */
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
        {
            int on_frame = (step + 1) % per_frame == 0, in_preview = on_frame && step < per_poke && frame % 2 == 0;
            int push_end = (step + 1) % per_poke == 36 * substeps; /* 0.25 s into a poke: the push ends */
            if (on_frame) frame++;
            if ((png && ((all && on_frame) || in_preview || push_end)) || (step + 1) % per_poke == 0) /* draw only what is shown */
                pn_rom_map(w, n, Xf, x, NULL);
            if (png && ((all && on_frame) || in_preview || push_end)) {
                const char *title = "reduced-order cylinder, poked (plastinet_rom.h)";
                int ok = pn_rs_render(rgb, n, x, Xd, m->cell_m / refine, w->time_s, lo, hi, 0.012, "displacement (mm)", 1000, 8, title);
                if (ok && in_preview) ok = pn_apng_add(anim, rgb);
                if (ok && push_end) snprintf(path, sizeof path, "%s/poke_%02d.png", out, ++still), ok = pn_png_write(path, PN_RS_DRAW_W, PN_RS_DRAW_H, rgb);
                if (ok && all && on_frame) snprintf(path, sizeof path, "%s/frame_%04d.png", out, frame), ok = pn_png_write(path, PN_RS_DRAW_W, PN_RS_DRAW_H, rgb);
                if (!ok) {
                    fprintf(stderr, "cannot write the pictures in %s\n", out);
                    return 1;
                }
            }
        }
        if (!quiet && (step + 1) % per_poke == 0) {
            double dmax = 0;
            for (p = 0; p < n; ++p) {
                double e0 = x[3 * p] - Xd[3 * p], e1 = x[3 * p + 1] - Xd[3 * p + 1], e2 = x[3 * p + 2] - Xd[3 * p + 2];
                dmax = fmax(dmax, sqrt(e0 * e0 + e1 * e1 + e2 * e2));
            }
            printf("  t = %4.1f s: poke %d done, largest displacement now %.2f mm\n", w->time_s, (step + 1) / per_poke,
                   1e3 * dmax);
        }
    }
    printf("%d pokes, %d steps: %.3f ms per step, %.3f wall s per simulated s\n", pokes, steps, 1e3 * wall / steps,
           wall / (steps * s.frame_dt));
    if (anim && !pn_apng_close(anim)) {
        fprintf(stderr, "cannot finish %s/preview.png\n", out);
        return 1;
    }
    if (png) printf("pictures: %s/preview.png (first poke, animated) and %d stills%s\n", out, still, all ? ", every frame" : "");
    pn_rom_destroy(w);
    free(Xd), free(Xf), free(x), free(rgb);
    return 0;
}
