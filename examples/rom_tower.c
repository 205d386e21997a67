/* rom_tower.c: a reduced-order elastic tower (plastinet_rom.h) pressed and sheared from the top
   while its base is held, stepped as fast as the reduced model goes, drawn at any resolution.

   build/rom_tower [--refine R] [--frames N] [--substeps S] [--scheme IM|LN|LL|EN|EL] [--samples M]
                   [--cubature C] [--speed CM_S] [--theta RAD] [--phi RAD] [--exact] [--png]
                   [--all-frames] [--ply] [--out DIR] [--quiet] [--help]

   The model (models/rom_tower.h) was trained on 16 full-order runs of 57,840 points. The
   dynamics by default (scheme IM) take one implicit step (BDF2) per frame of 1/24 s on a
   cubature of cells C x the grid spacing [4]; the paper's explicit schemes need about 150
   substeps per frame (the explicit step is refused above pn_rom_stable_dt). Either way a step
   costs the same whatever is drawn. --refine R draws the tower's reference domain sampled R
   times finer per axis (R = 3: 1.56 million points), each point placed by the learned map from
   the current latent: zero-shot super-resolution. Prints wall seconds per simulated second of
   the dynamics (<= 1: real time) and the cost of reconstructing the drawn points. --help lists
   every flag. Build: cc -O2 examples/rom_tower.c -lm */
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* particles only: FEM and coupling left out of the build */
#include "common/pn_example.h"
#include "../plastinet_rom.h"
#include "../models/rom_tower.h"
#include "common/pn_rom_scenes.h"

/* binary little-endian PLY of n points (float x y z) */
static int write_ply(const char *path, size_t n, const float *x) {
    FILE *f = fopen(path, "wb");
    size_t p;
    if (!f) return 0;
    fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment plastinet_rom.h tower\nelement vertex %lu\n"
               "property float x\nproperty float y\nproperty float z\nend_header\n", (unsigned long)n);
    for (p = 0; p < 3 * n; ++p) {
        unsigned char b[4];
        unsigned u;
        memcpy(&u, &x[p], 4);
        b[0] = (unsigned char)u, b[1] = (unsigned char)(u >> 8), b[2] = (unsigned char)(u >> 16), b[3] = (unsigned char)(u >> 24);
        fwrite(b, 1, 4, f);
    }
    return fclose(f) == 0;
}

static void usage(FILE *f, const char *prog) {
    fprintf(f,
            "usage: %s [--refine R] [--frames N] [--substeps S] [--scheme IM|LN|LL|EN|EL] [--samples M] [--cubature C]\n"
            "       [--speed CM_S] [--theta RAD] [--phi RAD] [--exact] [--png] [--all-frames] [--ply] [--out DIR] [--quiet] [--help]\n"
            "A reduced-order elastic tower (models/rom_tower.h), its base held and its top moved at a constant\n"
            "velocity, stepped as fast as the reduced model goes and drawn at any resolution.\n"
            "  --refine R      draw the tower at R times the training resolution per axis, 1 .. 64 (3: 1.56 million\n"
            "                  points) [1]; the dynamics do not depend on it\n"
            "  --frames N      frames of 1/24 s [80]\n"
            "  --substeps S    steps per frame [1]; the explicit schemes need about 150 (a step above 1.5x\n"
            "                  pn_rom_stable_dt is refused)\n"
            "  --scheme XY     how the reduced model steps [IM]:\n"
            "                    IM  implicit (BDF2): the latent minimizes the incremental potential summed over\n"
            "                        a fixed cubature of the body, by Newton; one step per frame\n"
            "                    the paper's explicit step (an MPM step around a few sampled points, projected\n"
            "                    back onto the latent); first letter, the quadrature:\n"
            PN_RS_SCHEME_HELP
            "  --samples M     explicit schemes: projection points per step [50]\n"
            "  --cubature C    IM: cubature cells of C grid spacings (coarser is faster) [4]\n"
            "  --speed CM_S    the top's speed in cm/s [test instance 19's]\n"
            "  --theta RAD     its direction's azimuth [instance 19's]\n"
            "  --phi RAD       its elevation [instance 19's]\n"
            "  --exact         reconstruct every drawn point by the map itself, not by the embedding (a Taylor\n"
            "                  step from a lattice of the grid spacing, a few micrometres off)\n"
            "  --png           pictures into DIR: preview.png, an animated PNG of the run (every second frame,\n"
            "                  12 per second, in real time), and frame_NNNN.png stills of the middle and last frames\n"
            "  --all-frames    with --png, every frame as DIR/frame_0001.png ...\n"
            "  --ply           every frame's points as DIR/frame_0001.ply ... (binary PLY, x y z float)\n"
            "  --out DIR       where files go [build/rom_tower]\n"
            "  --quiet         only the summary lines\n"
            "  --help          this help\n",
            prog);
}

int main(int argc, char **argv) {
    const pn_rom_model *m = pn_rom_model_tower();
    pn_rs_scene s = pn_rs_get(PN_RS_TOWER, 1);
    pn_rs_instance in = pn_rs_instance_of(&s, 19); /* a test instance (never trained on) */
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    const char *out = "build/rom_tower", *scheme = "IM";
    char why[256], path[1200];
    int refine = 1, frames = 80, substeps = 1, samples = 50, png = 0, all = 0, ply = 0, quiet = 0, exact = 0, a, f, k;
    pn_apng *anim = NULL;
    int drawn = 0;
    unsigned char *rgb = NULL;
    pn_rom_embedding *emb = NULL;
    double cubature = 4;
    double *Xd, wall = 0, draw_s = 0, spacing, lo[3] = {0.02, 0.02, 0.0}, hi[3] = {0.14, 0.14, 0.19};
    float *Xf, *x;
    size_t n, p;
    for (a = 1; a < argc; ++a) {
        if (!strcmp(argv[a], "--refine") && a + 1 < argc) refine = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--frames") && a + 1 < argc) frames = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--substeps") && a + 1 < argc) substeps = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--samples") && a + 1 < argc) samples = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--scheme") && a + 1 < argc) scheme = argv[++a];
        else if (!strcmp(argv[a], "--cubature") && a + 1 < argc) cubature = atof(argv[++a]);
        else if (!strcmp(argv[a], "--speed") && a + 1 < argc) in.params[0] = atof(argv[++a]);
        else if (!strcmp(argv[a], "--theta") && a + 1 < argc) in.params[1] = atof(argv[++a]);
        else if (!strcmp(argv[a], "--phi") && a + 1 < argc) in.params[2] = atof(argv[++a]);
        else if (!strcmp(argv[a], "--out") && a + 1 < argc) out = argv[++a];
        else if (!strcmp(argv[a], "--png")) png = 1;
        else if (!strcmp(argv[a], "--exact")) exact = 1;
        else if (!strcmp(argv[a], "--ply")) ply = 1;
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
    if (refine < 1 || refine > PN_ROM_MAX_REFINE || frames < 1 || substeps < 1 || !(cubature > 0) ||
        (strcmp(scheme, "IM") && (strlen(scheme) != 2 || !strchr("LE", scheme[0]) || !strchr("NL", scheme[1])))) {
        fprintf(stderr, "--refine 1 .. %d, --frames and --substeps >= 1, --cubature > 0, --scheme IM, LN, LL, EN or EL (--help)\n",
                PN_ROM_MAX_REFINE);
        return 2;
    }
    /* the top's velocity from (speed, theta, phi), as the scene's instances */
    in.drive[1].velocity[0] = 0.01 * in.params[0] * cos(in.params[2]) * cos(in.params[1]);
    in.drive[1].velocity[1] = 0.01 * in.params[0] * cos(in.params[2]) * sin(in.params[1]);
    in.drive[1].velocity[2] = 0.01 * in.params[0] * sin(in.params[2]);
    memset(&desc, 0, sizeof desc);
    desc.model = m; /* the model's own lattice for the dynamics */
    desc.samples = samples;
    desc.quadrature = scheme[0] == 'L' ? PN_ROM_LAGRANGIAN : PN_ROM_EULERIAN;
    desc.projection = scheme[1] == 'N' ? PN_ROM_NONLINEAR : PN_ROM_LINEAR;
    if (!strcmp(scheme, "IM")) desc.integrator = PN_ROM_BDF2, desc.cubature_m = cubature * s.dx;
    if (pn_rom_create(&desc, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "pn_rom_create: %s\n", why);
        return 1;
    }
    if (!pn_rs_rom_setup(w, &in)) return 1;
    n = pn_rom_lattice(m, refine, NULL, 0); /* the points drawn */
    Xd = (double *)malloc(sizeof(double) * 3 * n), Xf = (float *)malloc(sizeof(float) * 3 * n);
    x = (float *)malloc(sizeof(float) * 3 * n);
    if (!Xd || !Xf || !x) {
        fprintf(stderr, "out of memory for %lu points\n", (unsigned long)n);
        return 1;
    }
    pn_rom_lattice(m, refine, Xd, n);
    for (p = 0; p < 3 * n; ++p) Xf[p] = (float)Xd[p];
    if (!exact && pn_rom_embed(w, n, Xf, s.dx, &emb) != PN_OK) {
        fprintf(stderr, "pn_rom_embed: %s\n", pn_rom_error(w));
        return 1;
    }
    spacing = m->cell_m / refine;
    if ((png || ply) && !pn_ex_mkdirs(out)) {
        fprintf(stderr, "cannot create %s\n", out);
        return 1;
    }
    if (png) {
        snprintf(path, sizeof path, "%s/preview.png", out);
        rgb = (unsigned char *)malloc(PN_RS_DRAW_W * PN_RS_DRAW_H * 3);
        if (!rgb || !(anim = pn_apng_open(path, PN_RS_DRAW_W, PN_RS_DRAW_H, 12))) {
            fprintf(stderr, "cannot start %s\n", path);
            return 1;
        }
    }
    printf("tower: %lu points drawn (refine %d), dynamics on %lu points, %d samples, scheme %s, top at %.2f cm/s\n",
           (unsigned long)n, refine, (unsigned long)w->n, samples, scheme, in.params[0]);
    for (f = 1; f <= frames; ++f) {
        double t0 = pn_ex_seconds(), t1;
        for (k = 0; k < substeps; ++k)
            if (pn_rom_step(w, s.frame_dt / substeps, NULL) != PN_OK) {
                fprintf(stderr, "frame %d: %s\n", f, pn_rom_error(w));
                return 1;
            }
        t1 = pn_ex_seconds();
        wall += t1 - t0;
        int shown = png && (all || f % 2 == 0 || f == frames / 2 || f == frames);
        if (shown || ply || f == frames) { /* reconstruct only what is drawn */
            if (exact) pn_rom_map(w, n, Xf, x, NULL);
            else pn_rom_embed_positions(w, emb, x);
            draw_s += pn_ex_seconds() - t1;
            drawn++;
        }
        if (shown) {
            int ok = pn_rs_render(rgb, n, x, Xd, spacing, w->time_s, lo, hi, 0.012, "displacement (cm)", 100, 3,
                                  "reduced-order tower (plastinet_rom.h)");
            if (ok && (f % 2 == 0 || frames == 1)) ok = pn_apng_add(anim, rgb);
            if (ok && (all || f == frames / 2 || f == frames))
                snprintf(path, sizeof path, "%s/frame_%04d.png", out, f), ok = pn_png_write(path, PN_RS_DRAW_W, PN_RS_DRAW_H, rgb);
            if (!ok) {
                fprintf(stderr, "cannot write the pictures in %s\n", out);
                return 1;
            }
        }
        if (ply) {
            snprintf(path, sizeof path, "%s/frame_%04d.ply", out, f);
            write_ply(path, n, x);
        }
        if (!quiet && (f % 10 == 0 || f == frames))
            printf("  t = %.3f s: top at z = %.4f m\n", w->time_s, 0.172 + in.drive[1].velocity[2] * w->time_s);
    }
    printf("dynamics: %.3f wall s per simulated s (%s real time); reconstruction of %lu points: %.1f ms per frame "
           "(%.0f frames per second)\n",
           wall / (frames * s.frame_dt), wall / (frames * s.frame_dt) <= 1 ? "faster than" : "slower than", (unsigned long)n,
           1e3 * draw_s / drawn, drawn / (draw_s > 0 ? draw_s : 1e-9));
    if (png) printf("pictures: %s/preview.png (animated) and %s\n", out, all ? "every frame" : "the middle and last frames");
    if (anim && !pn_apng_close(anim)) {
        fprintf(stderr, "cannot finish %s/preview.png\n", out);
        return 1;
    }
    pn_rom_embed_destroy(emb);
    pn_rom_destroy(w);
    free(Xd), free(Xf), free(x), free(rgb);
    return 0;
}
