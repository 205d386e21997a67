/* bench_rom.c: the reduced-order models of plastinet_rom.h against full-order explicit MPM
   (make bench-rom; docs/rom.md explains the scenes and the measures).

   build/bench_rom [--scenes cylinder,cuboid,poke,tower] [--data data/rom] [--out bench/results]
                   [--samples 10,50,all] [--schemes LN,LL,EN,EL,IM] [--instances N] [--substeps S]
                   [--integrator bdf2|be|mid] [--im-steps S] [--cubature 2,4] [--drive-weight W]
                   [--tower-frames N] [--pic] [--no-speed] [--no-superres] [--no-seq]

   For every scene, on its test instances (never trained on), each scheme runs the reduced
   model from the fitted rest state (Eq. 19) and is measured by the paper's relative L2
   position error sqrt(sum |x_rom - x_full|^2 / sum |x_full|^2) over every point of every frame
   of every test instance, the same with positions taken from the initial centroid, and the
   wall seconds per simulated second of the reduced steps (drawing excluded). Schemes:
     LN LL EN EL  the paper's explicit step (L/E: Lagrangian/Eulerian quadrature, N/L:
                  nonlinear/linear projection) with each projection-point count, at the
                  snapshot interval divided by S (default: the full-order step); on the tower
                  one test instance, its first --tower-frames frames [6], not with all points
     IM<C>        the implicit latent step (--integrator, default BDF2), --im-steps per frame
                  [1], on a cubature of cells C grid cells wide, for each C of --cubature [2,4]
                  (super-resolution and the ten pokes: the first C; the tower's scaling: the last)
   In the same run: the full-order explicit MPM (plastinet_mpm.h, the generator's step) on the
   same scene, its wall seconds per simulated second; zero-shot super-resolution on the cuboid
   (the model run on the points of the 2x finer full-order run, against it); ten pokes in a
   row (poke_seq); the tower at 1x and 3x per axis (1.56 million points): reduced dynamics,
   reconstruction rate and the full-order speed at that size.
   Writes OUT/bench_rom.md, .csv and .svg (error against wall time, with the real-time line).
   Needs the snapshots of make rom-data. */
#define PLASTINET_IMPLEMENTATION
#include "../examples/common/pn_example.h"
#include "../plastinet_rom.h"
#include "../models/pn_rom_models.h"
#include "../examples/common/pn_rom_scenes.h"

#define QUAD(kind) ((kind) == 4 ? 2 : (kind) >= 2) /* rom_run's quad: 0 L, 1 E, 2 the implicit integrator */

typedef struct rrun {
    char scene[24], scheme[24];
    int samples;               /* -1: all                                                    */
    double err, err_c, wall_per_s, quad_mean;
    int ok;
} rrun;

typedef struct cfg {
    const char *data, *out;
    char scenes[256], schemes[64];
    int samples[8], n_samples, instances, substeps, speed, superres, seq, pic, im_steps, integrator;
    double cubature_dx, drive_weight, cubs[4];
    int n_cubs;
    int tower_frames;
} cfg;

static const pn_rom_model *model_of(const char *scene) {
    int i;
    for (i = 0; pn_rom_models_all[i]; ++i)
        if (!strcmp(pn_rom_models_all[i]()->name, scene)) return pn_rom_models_all[i]();
    return NULL;
}

/* One reduced run of instance `in` against snapshots `snap`; adds to the error sums. */
static int rom_run(const pn_rom_model *m, const pn_rs_scene *s, const pn_rs_instance *in, const pn_rs_snap *snap, int quad,
                   int proj, int samples, int substeps, int pic, const cfg *cf, unsigned long long seed, double *se, double *sn,
                   double *snc, double *wall, double *sim, double *quad_sum, long *steps) {
    pn_rom_desc d;
    pn_rom_world *w = NULL;
    char why[256];
    double *X = (double *)malloc(sizeof(double) * 3 * (size_t)snap->n), c0[3] = {0, 0, 0}, h = s->dx / s->per_axis;
    float *x = (float *)malloc(sizeof(float) * 3 * (size_t)snap->n);
    int f, k, i, next = 0, ok = 1;
    size_t p;
    for (p = 0; p < 3 * (size_t)snap->n; ++p) X[p] = snap->X[p];
    for (p = 0; p < (size_t)snap->n; ++p)
        for (i = 0; i < 3; ++i) c0[i] += X[3 * p + (size_t)i] / snap->n;
    memset(&d, 0, sizeof d);
    d.model = m, d.points = X, d.n_points = (size_t)snap->n, d.point_volume_m3 = h * h * h, d.dx_m = s->dx;
    d.youngs_pa = s->youngs_pa, d.poisson = s->poisson, d.density_kg_m3 = s->density;
    for (i = 0; i < 3; ++i) d.gravity[i] = in->gravity[i];
    d.samples = samples, d.quadrature = quad ? PN_ROM_EULERIAN : PN_ROM_LAGRANGIAN;
    d.projection = proj ? PN_ROM_LINEAR : PN_ROM_NONLINEAR, d.seed = seed;
    d.transfer = pic ? PN_ROM_PIC : PN_ROM_APIC;
    if (quad == 2) { /* IM: the implicit integrator, im_steps per frame */
        d.integrator = (pn_rom_integrator)cf->integrator, d.cubature_m = cf->cubature_dx * s->dx, d.quadrature = PN_ROM_LAGRANGIAN;
        d.drive_weight = cf->drive_weight;
        substeps = cf->im_steps;
    }
    if (pn_rom_create(&d, &w, why, sizeof why) != PN_OK || !pn_rs_rom_setup(w, in)) {
        fprintf(stderr, "pn_rom_create: %s\n", why);
        free(X), free(x);
        return 0;
    }
    { /* the initial latent: the least-squares fit of the rest state (Eq. 19) */
        double *x0 = (double *)malloc(sizeof(double) * 3 * (size_t)snap->n);
        const float *xf = pn_rs_x(snap, 0);
        for (p = 0; p < 3 * (size_t)snap->n; ++p) x0[p] = xf[p];
        ok = pn_rom_fit(w, x0, NULL, NULL) == PN_OK;
        free(x0);
    }
    /* the tower's explicit schemes (about 150 steps per frame): its first tower_frames frames */
    int nfr = s->id == PN_RS_TOWER && quad < 2 && cf->tower_frames > 0 && cf->tower_frames < snap->frames ? cf->tower_frames + 1
                                                                                                          : snap->frames;
    for (f = 0; f < nfr && ok; ++f) {
        const float *xr = pn_rs_x(snap, f);
        if (f > 0) {
            double t0;
            if (!pn_rs_rom_events(w, in, (f - 1) * s->frame_dt, &next)) ok = 0;
            t0 = pn_ex_seconds();
            for (k = 0; k < substeps && ok; ++k) {
                pn_rom_stats st;
                if (pn_rom_step(w, s->frame_dt / substeps, &st) != PN_OK) {
                    fprintf(stderr, "  %s frame %d: %s\n", s->name, f, pn_rom_error(w));
                    ok = 0;
                }
                *quad_sum += (double)(quad == 2 ? st.cubature_points : st.quad_points);
                ++*steps;
            }
            *wall += pn_ex_seconds() - t0;
            *sim += s->frame_dt;
        }
        pn_rom_positions(w, 0, (size_t)snap->n, x, NULL);
        for (p = 0; p < 3 * (size_t)snap->n; ++p) {
            double e = (double)x[p] - (double)xr[p], r = (double)xr[p];
            *se += e * e, *sn += r * r, *snc += (r - c0[p % 3]) * (r - c0[p % 3]);
        }
    }
    pn_rom_destroy(w);
    free(X), free(x);
    return ok;
}

/* the full-order step count per frame of scene s (gen/rom_data.c's: 0.7 of the stable step at rest) */
static int fom_substeps(const pn_rs_scene *s) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material_desc md;
    pn_material mat;
    pn_real dts = 0;
    int i, n = 1;
    memset(&wd, 0, sizeof wd);
    wd.dim = 3, wd.dx_m = s->dx, wd.max_particles = 1;
    for (i = 0; i < 3; ++i) wd.res[i] = s->res[i];
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED, md.plastic = PN_PLASTIC_NONE;
    md.youngs_modulus_pa = s->youngs_pa, md.poisson_ratio = s->poisson;
    if (pn_mpm_create(&wd, &w, NULL, 0) == PN_OK && pn_material_init(&mat, &md, NULL, 0) == PN_OK &&
        pn_mpm_add_group(w, &mat, s->density) >= 0 && pn_mpm_stable_dt(w, &dts) == PN_OK && dts > 0)
        n = (int)ceil(s->frame_dt / (0.7 * (double)dts));
    pn_mpm_destroy(w);
    return n;
}

/* wall seconds per simulated second of the full-order explicit step on instance `in` of
   scene s (the generator's fixed step), over `frames` frames */
static double fom_speed_steps(const pn_rs_scene *s, const pn_rs_instance *in, int frames, int max_steps, size_t *n_out);
static double fom_speed(const pn_rs_scene *s, const pn_rs_instance *in, int frames) {
    return fom_speed_steps(s, in, frames, 0, NULL);
}

/* wall s per simulated s of full-order explicit MPM on scene s (any refinement): `frames`
   frames, or (max_steps > 0) the first max_steps steps timed at the per-frame step count */
static double fom_speed_steps(const pn_rs_scene *s, const pn_rs_instance *in, int frames, int max_steps, size_t *n_out) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material_desc md;
    pn_material mat;
    size_t cap = pn_rs_points(s, 1, NULL, 0);
    double *X = (double *)malloc(sizeof(double) * 3 * cap), t0, wall;
    pn_real dts;
    int g, i, f, j, nsub, next = 0, done = 0;
    memset(&wd, 0, sizeof wd);
    wd.dim = 3, wd.dx_m = s->dx, wd.boundary = PN_BOUNDARY_STICKY, wd.max_particles = cap;
    for (i = 0; i < 3; ++i) wd.res[i] = s->res[i], wd.gravity[i] = in->gravity[i];
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED, md.plastic = PN_PLASTIC_NONE;
    md.youngs_modulus_pa = s->youngs_pa, md.poisson_ratio = s->poisson;
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK || pn_material_init(&mat, &md, NULL, 0) != PN_OK) return -1;
    g = pn_mpm_add_group(w, &mat, s->density);
    if (!pn_rs_setup(w, g, s, in, 1, NULL, X, cap)) return -1;
    pn_mpm_stable_dt(w, &dts);
    nsub = (int)ceil(s->frame_dt / (0.7 * (double)dts));
    if (n_out) *n_out = w->n;
    t0 = pn_ex_seconds();
    for (f = 0; f < frames && !(max_steps > 0 && done >= max_steps); ++f) {
        pn_rs_events(w, in, X, w->n, f * s->frame_dt, &next);
        for (j = 0; j < nsub && !(max_steps > 0 && done >= max_steps); ++j, ++done)
            if (pn_mpm_step_explicit(w, s->frame_dt / nsub, NULL) != PN_OK) break;
    }
    wall = pn_ex_seconds() - t0;
    pn_mpm_destroy(w);
    free(X);
    return wall / (done * (s->frame_dt / nsub));
}

/* The tower at the training resolution and three times finer per axis (1.56 million
   points, zero-shot): the implicit reduced dynamics (one step per frame) in wall s per
   simulated s, the reconstruction rate of every point (pn_rom_positions), and the
   full-order explicit MPM at the fine resolution, timed over its first steps. */
typedef struct tscale {
    int refine;
    size_t n;
    double rom_wall_per_s, recon_pts_per_s, fom_wall_per_s, max_pts_30fps;
    double emb_spacing[2], emb_rate[2], emb_err_rms[2], emb_err_max[2], emb_30fps[2]; /* pn_rom_embed at dx and 2 dx */
} tscale;

static void tower_scale(const pn_rs_scene *s, const pn_rom_model *m, const cfg *cf, tscale *out, int *n_out) {
    pn_rs_instance in = pn_rs_instance_of(s, s->n_instances - 1);
    int r, f, k = 0;
    for (r = 1; r <= 3; r += 2) {
        pn_rom_desc d;
        pn_rom_world *w = NULL;
        tscale *t = &out[k];
        char why[256];
        float *x;
        double t0, wall = 0;
        memset(&d, 0, sizeof d);
        memset(t, 0, sizeof *t);
        d.model = m, d.refine = r, d.dx_m = s->dx, d.youngs_pa = s->youngs_pa, d.poisson = s->poisson;
        d.density_kg_m3 = s->density, d.integrator = (pn_rom_integrator)cf->integrator, d.cubature_m = cf->cubs[cf->n_cubs - 1] * s->dx;
        d.drive_weight = cf->drive_weight;
        if (pn_rom_create(&d, &w, why, sizeof why) != PN_OK || !pn_rs_rom_setup(w, &in)) {
            fprintf(stderr, "tower x%d: %s\n", r, why);
            return;
        }
        t->refine = r, t->n = w->n;
        for (f = 0; f < 24; ++f) {
            t0 = pn_ex_seconds();
            if (pn_rom_step(w, s->frame_dt, NULL) != PN_OK) fprintf(stderr, "tower x%d: %s\n", r, pn_rom_error(w));
            wall += pn_ex_seconds() - t0;
        }
        t->rom_wall_per_s = wall / (24 * s->frame_dt);
        x = (float *)malloc(sizeof(float) * 3 * w->n);
        t0 = pn_ex_seconds();
        for (f = 0; f < 3; ++f) pn_rom_positions(w, 0, w->n, x, NULL);
        t->recon_pts_per_s = 3.0 * (double)w->n / (pn_ex_seconds() - t0);
        /* a 30 fps display in real time: per frame 1/30 s of dynamics, the rest of the 1/30 s
           for reconstruction */
        t->max_pts_30fps = t->rom_wall_per_s < 1 ? t->recon_pts_per_s * (1 - t->rom_wall_per_s) / 30 : 0;
        { /* the render embedding: a lattice of dx or 2 dx, each point a Taylor step from its node */
            float *Xf = (float *)malloc(sizeof(float) * 3 * w->n), *xe = (float *)malloc(sizeof(float) * 3 * w->n);
            size_t p;
            int e;
            for (p = 0; p < 3 * w->n; ++p) Xf[p] = (float)w->X[p];
            for (e = 0; e < 2; ++e) {
                pn_rom_embedding *em = NULL;
                double s2 = 0, mx = 0;
                t->emb_spacing[e] = (e + 1) * s->dx;
                if (pn_rom_embed(w, w->n, Xf, t->emb_spacing[e], &em) != PN_OK) continue;
                t0 = pn_ex_seconds();
                for (f = 0; f < 3; ++f) pn_rom_embed_positions(w, em, xe);
                t->emb_rate[e] = 3.0 * (double)w->n / (pn_ex_seconds() - t0);
                for (p = 0; p < w->n; ++p) {
                    double q = 0;
                    int i;
                    for (i = 0; i < 3; ++i) q += ((double)xe[3 * p + i] - x[3 * p + i]) * ((double)xe[3 * p + i] - x[3 * p + i]);
                    s2 += q, mx = q > mx ? q : mx;
                }
                t->emb_err_rms[e] = sqrt(s2 / (double)w->n), t->emb_err_max[e] = sqrt(mx);
                t->emb_30fps[e] = t->rom_wall_per_s < 1 ? t->emb_rate[e] * (1 - t->rom_wall_per_s) / 30 : 0;
                fprintf(stderr, "tower x%d: embedding at %.0f mm (%lu nodes): %.3g points/s, off the exact map by %.2g um RMS "
                                "(%.2g um max)\n", r, 1e3 * t->emb_spacing[e], (unsigned long)em->n_nodes, t->emb_rate[e],
                        1e6 * t->emb_err_rms[e], 1e6 * t->emb_err_max[e]);
                pn_rom_embed_destroy(em);
            }
            free(Xf), free(xe);
        }
        free(x);
        pn_rom_destroy(w);
        if (r == 3) {
            pn_rs_scene fine = pn_rs_get(PN_RS_TOWER, 3);
            size_t nf = 0;
            fine.frames = 1;
            t->fom_wall_per_s = fom_speed_steps(&fine, &in, 1, 6, &nf);
        }
        fprintf(stderr, "tower x%d: %lu points; reduced dynamics %.3g wall s per simulated s; reconstruction %.3g points/s "
                        "(30 fps in real time: %.3g points)%s",
                r, (unsigned long)t->n, t->rom_wall_per_s, t->recon_pts_per_s, t->max_pts_30fps, r == 3 ? "" : "\n");
        if (r == 3) fprintf(stderr, "; full order at this resolution %.4g wall s per simulated s\n", t->fom_wall_per_s);
        k++;
    }
    *n_out = k;
}

static int listed(const char *list, const char *name) {
    char b[256], *t, *save = NULL;
    snprintf(b, sizeof b, "%s", list);
    for (t = strtok_r(b, ",", &save); t; t = strtok_r(NULL, ",", &save))
        if (!strcmp(t, name)) return 1;
    return 0;
}

static void svg(const char *path, const rrun *r, int n, const double *fom, char (*fom_scene)[24], int nf) {
    static const char *cols[] = {"#1f5fbf", "#e07b00", "#2a9d3a", "#b0249a", "#111111"};
    FILE *f = fopen(path, "w");
    double x0 = 1e300, x1 = 0, y0 = 1e300, y1 = 0;
    int k, W = 700, H = 440;
    if (!f) return;
    for (k = 0; k < n; ++k)
        if (r[k].ok && r[k].err > 0 && r[k].wall_per_s > 0)
            x0 = fmin(x0, r[k].wall_per_s), x1 = fmax(x1, r[k].wall_per_s), y0 = fmin(y0, r[k].err), y1 = fmax(y1, r[k].err);
    for (k = 0; k < nf; ++k)
        if (fom[k] > 0) x1 = fmax(x1, fom[k]), x0 = fmin(x0, fom[k]);
    x0 = fmin(x0, 0.5), x1 = fmax(x1, 2);
    if (!(y1 > 0)) y0 = 1e-3, y1 = 1e-1;
    x0 = pow(10, floor(log10(x0))), x1 = pow(10, ceil(log10(x1))), y0 = pow(10, floor(log10(y0))), y1 = pow(10, ceil(log10(y1)));
    if (y1 <= y0) y1 = 10 * y0;
#define PX(v) (80 + (W - 110) * (log10(v) - log10(x0)) / (log10(x1) - log10(x0)))
#define PY(v) (20 + (H - 80) * (1 - (log10(v) - log10(y0)) / (log10(y1) - log10(y0))))
    fprintf(f, "<svg xmlns='http://www.w3.org/2000/svg' width='%d' height='%d' font-family='sans-serif' font-size='12'>\n"
               "<rect width='100%%' height='100%%' fill='white'/>\n<rect x='80' y='20' width='%d' height='%d' fill='none' stroke='#444'/>\n",
            W, H, W - 110, H - 80);
    fprintf(f, "<text x='%d' y='%d' text-anchor='middle'>wall seconds per simulated second (log)</text>\n", W / 2, H - 20);
    fprintf(f, "<text x='16' y='%d' transform='rotate(-90 16 %d)' text-anchor='middle'>relative L2 position error (log)</text>\n",
            H / 2, H / 2);
    fprintf(f, "<text x='80' y='%d'>%g</text><text x='%d' y='%d' text-anchor='end'>%g</text>\n", H - 45, x0, W - 30, H - 45, x1);
    fprintf(f, "<text x='76' y='%d' text-anchor='end'>%g</text><text x='76' y='28' text-anchor='end'>%g</text>\n", H - 60, y0, y1);
    fprintf(f, "<line x1='%.1f' x2='%.1f' y1='20' y2='%d' stroke='#2a9d3a' stroke-dasharray='5 3'/><text x='%.1f' y='34' "
               "fill='#2a9d3a'>real time</text>\n", PX(1.0), PX(1.0), H - 60, PX(1.0) + 4);
    for (k = 0; k < nf; ++k)
        if (fom[k] > 0)
            fprintf(f, "<line x1='%.1f' x2='%.1f' y1='20' y2='%d' stroke='#c00' stroke-dasharray='2 3'/><text x='%.1f' y='%d' "
                       "fill='#c00' font-size='10' transform='rotate(-90 %.1f %d)'>full order: %s</text>\n",
                    PX(fom[k]), PX(fom[k]), H - 60, PX(fom[k]) - 3, H - 64, PX(fom[k]) - 3, H - 64, fom_scene[k]);
    for (k = 0; k < n; ++k) {
        int c = !strcmp(r[k].scheme, "LN") ? 0 : !strcmp(r[k].scheme, "LL") ? 1 : !strcmp(r[k].scheme, "EN") ? 2 : r[k].scheme[0] == 'I' ? 4 : 3;
        if (!r[k].ok || !(r[k].err > 0) || !(r[k].wall_per_s > 0)) continue;
        fprintf(f, "<circle cx='%.1f' cy='%.1f' r='4' fill='%s'/><text x='%.1f' y='%.1f' font-size='9'>%s %s %s</text>\n",
                PX(r[k].wall_per_s), PY(r[k].err), cols[c], PX(r[k].wall_per_s) + 6, PY(r[k].err) + 3, r[k].scene, r[k].scheme,
                r[k].scheme[0] == 'I' ? "" : r[k].samples < 0 ? "all" : (r[k].samples == 10 ? "10" : r[k].samples == 50 ? "50" : "n"));
    }
#undef PX
#undef PY
    fprintf(f, "<text x='90' y='%d' font-size='10'>LN LL EN EL: Lagrangian / Eulerian quadrature, nonlinear / linear projection, "
               "label: projection points; IM: implicit latent step</text>\n</svg>\n", H - 66);
    fclose(f);
}

int main(int argc, char **argv) {
    static rrun runs[512];
    static const char *schemes[5] = {"LN", "LL", "EN", "EL", "IM"};
    double fom[8];
    char fom_scene[8][24], path[1024];
    int nr = 0, nf = 0, a, sc, nts = 0;
    tscale ts[2];
    cfg c;
    FILE *md, *csv;
    memset(&c, 0, sizeof c);
    c.data = "data/rom", c.out = "bench/results";
    snprintf(c.scenes, sizeof c.scenes, "cylinder,cuboid,poke,tower");
    snprintf(c.schemes, sizeof c.schemes, "LN,LL,EN,EL,IM");
    c.im_steps = 1, c.integrator = PN_ROM_BDF2, c.tower_frames = 6;
    c.cubs[0] = 2, c.cubs[1] = 4, c.n_cubs = 2, c.cubature_dx = 2;
    c.samples[0] = 10, c.samples[1] = 50, c.samples[2] = -1, c.n_samples = 3;
    c.substeps = 0, c.speed = 1, c.superres = 1, c.seq = 1;
    for (a = 1; a < argc; ++a) {
        if (!strcmp(argv[a], "--scenes") && a + 1 < argc) snprintf(c.scenes, sizeof c.scenes, "%s", argv[++a]);
        else if (!strcmp(argv[a], "--schemes") && a + 1 < argc) snprintf(c.schemes, sizeof c.schemes, "%s", argv[++a]);
        else if (!strcmp(argv[a], "--data") && a + 1 < argc) c.data = argv[++a];
        else if (!strcmp(argv[a], "--out") && a + 1 < argc) c.out = argv[++a];
        else if (!strcmp(argv[a], "--instances") && a + 1 < argc) c.instances = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--substeps") && a + 1 < argc) c.substeps = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--im-steps") && a + 1 < argc) c.im_steps = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--cubature") && a + 1 < argc) {
            char b[128], *t, *save = NULL;
            snprintf(b, sizeof b, "%s", argv[++a]);
            c.n_cubs = 0;
            for (t = strtok_r(b, ",", &save); t && c.n_cubs < 4; t = strtok_r(NULL, ",", &save)) c.cubs[c.n_cubs++] = atof(t);
            c.cubature_dx = c.cubs[0];
        }
        else if (!strcmp(argv[a], "--drive-weight") && a + 1 < argc) c.drive_weight = atof(argv[++a]);
        else if (!strcmp(argv[a], "--tower-frames") && a + 1 < argc) c.tower_frames = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--integrator") && a + 1 < argc) {
            ++a;
            c.integrator = !strcmp(argv[a], "be") ? PN_ROM_IMPLICIT : !strcmp(argv[a], "mid") ? PN_ROM_MIDPOINT : PN_ROM_BDF2;
        }
        else if (!strcmp(argv[a], "--no-speed")) c.speed = 0;
        else if (!strcmp(argv[a], "--no-superres")) c.superres = 0;
        else if (!strcmp(argv[a], "--no-seq")) c.seq = 0;
        else if (!strcmp(argv[a], "--pic")) c.pic = 1;
        else if (!strcmp(argv[a], "--samples") && a + 1 < argc) {
            char b[128], *t, *save = NULL;
            snprintf(b, sizeof b, "%s", argv[++a]);
            c.n_samples = 0;
            for (t = strtok_r(b, ",", &save); t && c.n_samples < 8; t = strtok_r(NULL, ",", &save))
                c.samples[c.n_samples++] = !strcmp(t, "all") ? -1 : atoi(t);
        } else {
            fprintf(stderr, "usage: %s [--scenes a,b] [--schemes LN,LL,EN,EL] [--samples 10,50,all] [--data DIR] [--out DIR] "
                            "[--instances N] [--substeps S] [--pic] [--no-speed] [--no-superres] [--no-seq]\n", argv[0]);
            return 2;
        }
    }
    for (sc = 0; sc < PN_RS_COUNT; ++sc) {
        pn_rs_scene s = pn_rs_get(sc, 1);
        const pn_rom_model *m;
        int kind, sm, k, used = 0, sub;
        if (sc == PN_RS_POKE_SEQ || !listed(c.scenes, s.name)) continue;
        if (!(m = model_of(s.name))) {
            fprintf(stderr, "no model for %s in models/pn_rom_models.h (make models MODEL=rom_%s)\n", s.name, s.name);
            continue;
        }
        sub = c.substeps > 0 ? c.substeps : fom_substeps(&s); /* default: the full-order step */
        fprintf(stderr, "%s: %d reduced steps per frame of %.4g s\n", s.name, sub, s.frame_dt);
        for (kind = 0; kind < 5; ++kind) {
            if (!listed(c.schemes, schemes[kind])) continue;
            for (sm = 0; sm < (kind == 4 ? c.n_cubs : c.n_samples); ++sm) { /* IM: each cubature */
                rrun *r = &runs[nr];
                cfg cc = c;
                double se = 0, sn = 0, snc = 0, wall = 0, sim = 0, qs = 0;
                long steps = 0;
                memset(r, 0, sizeof *r);
                snprintf(r->scene, sizeof r->scene, "%s", s.name);
                snprintf(r->scheme, sizeof r->scheme, "%s", schemes[kind]);
                r->samples = kind == 4 ? 0 : c.samples[sm];
                if (kind == 4) cc.cubature_dx = c.cubs[sm], snprintf(r->scheme, sizeof r->scheme, "IM%g", c.cubs[sm]);
                r->ok = 1, used = 0;
                if (sc == PN_RS_TOWER && kind < 4 && c.samples[sm] < 0) continue; /* all 57,840 points: hours */
                for (k = 0; k < s.n_instances && r->ok; ++k) {
                    pn_rs_instance in = pn_rs_instance_of(&s, k);
                    pn_rs_snap snap;
                    if (!in.test || (c.instances > 0 && used >= c.instances)) continue;
                    if (sc == PN_RS_TOWER && kind < 4 && used >= 1) continue; /* explicit: one test instance */
                    snprintf(path, sizeof path, "%s/%s/i%03d.pnrs", c.data, s.name, k);
                    if (!pn_rs_read(path, s.frames, &snap)) return 1;
                    r->ok = rom_run(m, &s, &in, &snap, QUAD(kind), kind % 2, r->samples, sub, c.pic, &cc, 1000 + (unsigned)k,
                                    &se, &sn, &snc, &wall, &sim, &qs, &steps);
                    pn_rs_free(&snap);
                    used++;
                }
                r->err = sqrt(se / sn), r->err_c = sqrt(se / snc), r->wall_per_s = wall / sim, r->quad_mean = qs / (steps ? steps : 1);
                fprintf(stderr, "%-9s %s %4s points: error %.3f%% (from the centroid %.3f%%), %.3g wall s per simulated s, "
                                "%.0f quadrature or cubature points per step%s\n",
                        r->scene, r->scheme, r->samples < 0 ? "all" : kind == 4 ? "-" : (snprintf(path, 16, "%d", r->samples), path), 100 * r->err,
                        100 * r->err_c, r->wall_per_s, r->quad_mean, r->ok ? "" : " (FAILED)");
                nr++;
            }
        }
        if (c.superres && sc == PN_RS_CUBOID) { /* zero-shot super-resolution: the points and grid of the 2x run */
            pn_rs_scene fine = pn_rs_get(sc, 2);
            for (kind = 0; kind < 5; ++kind) {
                rrun *r = &runs[nr];
                double se = 0, sn = 0, snc = 0, wall = 0, sim = 0, qs = 0;
                long steps = 0;
                if (!listed(c.schemes, schemes[kind])) continue;
                memset(r, 0, sizeof *r);
                snprintf(r->scene, sizeof r->scene, "%s_x2", s.name);
                snprintf(r->scheme, sizeof r->scheme, "%s", schemes[kind]);
                if (kind == 4) snprintf(r->scheme, sizeof r->scheme, "IM%g", c.cubature_dx);
                r->samples = -1, r->ok = 1, used = 0;
                for (k = 0; k < s.n_instances && r->ok; ++k) {
                    pn_rs_instance in = pn_rs_instance_of(&s, k);
                    pn_rs_snap snap;
                    if (!in.test || (c.instances > 0 && used >= c.instances)) continue;
                    snprintf(path, sizeof path, "%s/%s_f2/i%03d.pnrs", c.data, s.name, k);
                    if (!pn_rs_read(path, s.frames, &snap)) return 1;
                    r->ok = rom_run(m, &fine, &in, &snap, QUAD(kind), kind % 2, -1, 2 * sub, c.pic, &c, 1000 + (unsigned)k,
                                    &se, &sn, &snc, &wall, &sim, &qs, &steps);
                    pn_rs_free(&snap);
                    used++;
                }
                r->err = sqrt(se / sn), r->err_c = sqrt(se / snc), r->wall_per_s = wall / sim, r->quad_mean = qs / (steps ? steps : 1);
                fprintf(stderr, "%-9s %s  all points (super-resolution, trained at 1x): error %.3f%% (from the centroid %.3f%%)%s\n",
                        r->scene, r->scheme, 100 * r->err, 100 * r->err_c, r->ok ? "" : " (FAILED)");
                nr++;
            }
        }
        if (c.seq && sc == PN_RS_POKE) { /* continual manipulation: ten pokes in a row (poke_seq) */
            pn_rs_scene q = pn_rs_get(PN_RS_POKE_SEQ, 1);
            pn_rs_instance in = pn_rs_instance_of(&q, 0);
            pn_rs_snap snap;
            snprintf(path, sizeof path, "%s/%s/i%03d.pnrs", c.data, q.name, 0);
            if (!pn_rs_read(path, q.frames, &snap)) return 1;
            for (kind = 0; kind < 5; ++kind)
                for (sm = 0; sm < c.n_samples; ++sm) {
                    rrun *r = &runs[nr];
                    double se = 0, sn = 0, snc = 0, wall = 0, sim = 0, qs = 0;
                    long steps = 0;
                    if (!listed(c.schemes, schemes[kind]) || (kind == 4 ? sm > 0 : c.samples[sm] == 10)) continue;
                    memset(r, 0, sizeof *r);
                    snprintf(r->scene, sizeof r->scene, "%s", q.name);
                    snprintf(r->scheme, sizeof r->scheme, "%s", schemes[kind]);
                    if (kind == 4) snprintf(r->scheme, sizeof r->scheme, "IM%g", c.cubature_dx);
                    r->samples = kind == 4 ? 0 : c.samples[sm];
                    r->ok = rom_run(m, &q, &in, &snap, QUAD(kind), kind % 2, c.samples[sm], sub, c.pic, &c, 77, &se, &sn, &snc,
                                    &wall, &sim, &qs, &steps);
                    r->err = sqrt(se / sn), r->err_c = sqrt(se / snc), r->wall_per_s = wall / sim, r->quad_mean = qs / (steps ? steps : 1);
                    fprintf(stderr, "%-9s %s %4s points: error %.3f%% (from the centroid %.3f%%)%s\n", r->scene, r->scheme,
                            kind == 4 ? "-" : r->samples < 0 ? "all" : "50", 100 * r->err, 100 * r->err_c, r->ok ? "" : " (FAILED)");
                    nr++;
                }
            pn_rs_free(&snap);
        }
        if (c.speed && sc == PN_RS_TOWER) tower_scale(&s, m, &c, ts, &nts);
        if (c.speed && nf < 8) {
            pn_rs_instance in = pn_rs_instance_of(&s, s.n_instances - 1);
            fom[nf] = fom_speed(&s, &in, sc == PN_RS_TOWER ? 4 : 30);
            snprintf(fom_scene[nf], sizeof fom_scene[nf], "%s", s.name);
            fprintf(stderr, "%-9s full order explicit: %.3g wall s per simulated s\n", s.name, fom[nf]);
            nf++;
        }
    }
    snprintf(path, sizeof path, "%s/bench_rom.csv", c.out);
    csv = fopen(path, "w");
    snprintf(path, sizeof path, "%s/bench_rom.md", c.out);
    md = fopen(path, "w");
    if (!csv || !md) return 1;
    fprintf(csv, "scene,scheme,samples,error,error_centroid,wall_per_sim_s,quad_points,ok\n");
    fprintf(md, "| scene | scheme | projection points | error | error from centroid | wall s / simulated s | quadrature points |\n"
                "|---|---|---|---|---|---|---|\n");
    for (a = 0; a < nr; ++a) {
        fprintf(csv, "%s,%s,%d,%.6g,%.6g,%.6g,%.1f,%d\n", runs[a].scene, runs[a].scheme, runs[a].samples, runs[a].err, runs[a].err_c,
                runs[a].wall_per_s, runs[a].quad_mean, runs[a].ok);
        fprintf(md, "| %s | %s | %s | %.3f%% | %.3f%% | %.3g | %.0f |%s\n", runs[a].scene, runs[a].scheme,
                runs[a].scheme[0] == 'I' ? "-" : runs[a].samples < 0 ? "all" : (snprintf(path, 16, "%d", runs[a].samples), path), 100 * runs[a].err,
                100 * runs[a].err_c, runs[a].wall_per_s, runs[a].quad_mean, runs[a].ok ? "" : " failed");
    }
    for (a = 0; a < nf; ++a) {
        fprintf(csv, "%s,full,-1,0,0,%.6g,0,1\n", fom_scene[a], fom[a]);
        fprintf(md, "| %s | full-order explicit | - | - | - | %.3g | - |\n", fom_scene[a], fom[a]);
    }
    for (a = 0; a < nts; ++a) {
        if (!a)
            fprintf(md, "\n| tower | points | reduced dynamics, wall s / simulated s | exact reconstruction, points / s (at 30 fps) "
                        "| embedding at dx: points / s (at 30 fps), error RMS / max | at 2 dx | full order at this resolution, "
                        "wall s / simulated s |\n|---|---|---|---|---|---|---|\n");
        fprintf(md, "| x%d | %lu | %.3g | %.3g (%.3g) | %.3g (%.3g), %.2g / %.2g um | %.3g (%.3g), %.2g / %.2g um | %s |\n",
                ts[a].refine, (unsigned long)ts[a].n, ts[a].rom_wall_per_s, ts[a].recon_pts_per_s, ts[a].max_pts_30fps,
                ts[a].emb_rate[0], ts[a].emb_30fps[0], 1e6 * ts[a].emb_err_rms[0], 1e6 * ts[a].emb_err_max[0], ts[a].emb_rate[1],
                ts[a].emb_30fps[1], 1e6 * ts[a].emb_err_rms[1], 1e6 * ts[a].emb_err_max[1],
                ts[a].fom_wall_per_s > 0 ? (snprintf(path, 32, "%.4g", ts[a].fom_wall_per_s), path) : "(table above)");
        fprintf(csv, "tower_x%d,IM_scale,%lu,0,0,%.6g,0,1\n", ts[a].refine, (unsigned long)ts[a].n, ts[a].rom_wall_per_s);
        if (ts[a].fom_wall_per_s > 0) fprintf(csv, "tower_x%d,full,-1,0,0,%.6g,0,1\n", ts[a].refine, ts[a].fom_wall_per_s);
    }
    fclose(csv), fclose(md);
    snprintf(path, sizeof path, "%s/bench_rom.svg", c.out);
    svg(path, runs, nr, fom, fom_scene, nf);
    fprintf(stderr, "wrote %s/bench_rom.{md,csv,svg}\n", c.out);
    return 0;
}
