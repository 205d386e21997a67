/* rom_data.c: full-order snapshots for the reduced-order models (plastinet_rom.h).

   build/rom_data SCENE [--out data/rom] [--instance K] [--split all|train|test] [--fine F]
                        [--frames N]

   Runs the explicit MPM of plastinet_mpm.h (APIC, fixed corotated) on the instances of a scene
   of examples/common/pn_rom_scenes.h and writes one snapshot file per instance into OUT/SCENE/ (with
   --fine F > 1: the same scene on an F times finer grid and lattice, into OUT/SCENE_fF/), and
   OUT/SCENE/manifest.json listing every instance, its parameters and its split. The format is
   in gen/README.md. A run cut off continues where it stopped: each instance keeps a checkpoint
   of the full state (iNNN.ckpt, replaced atomically after every frame); a finished instance
   (all frames on disk, no checkpoint) is skipped. Instances are independent: spread them over
   machines with --instance (gen/README.md shows GNU parallel and Slurm job arrays).

   Build: cc -std=c99 -O2 -fopenmp gen/rom_data.c -lm -o build/rom_data */
#define _POSIX_C_SOURCE 200809L
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "../examples/common/pn_rom_scenes.h"
#include <errno.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define HEADER_BYTES 256

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void put_i32(unsigned char *b, int v) {
    unsigned u = (unsigned)v;
    int i;
    for (i = 0; i < 4; ++i) b[i] = (unsigned char)(u >> (8 * i));
}

static void put_f64(unsigned char *b, double v) {
    unsigned long long u;
    int i;
    memcpy(&u, &v, 8);
    for (i = 0; i < 8; ++i) b[i] = (unsigned char)(u >> (8 * i));
}

/* little-endian float32 array */
static void put_f32s(FILE *f, const double *a, size_t n) {
    unsigned char buf[4096];
    size_t i, k = 0;
    for (i = 0; i < n; ++i) {
        float x = (float)a[i];
        unsigned u;
        int j;
        memcpy(&u, &x, 4);
        for (j = 0; j < 4; ++j) buf[k++] = (unsigned char)(u >> (8 * j));
        if (k == sizeof buf) fwrite(buf, 1, k, f), k = 0;
    }
    if (k) fwrite(buf, 1, k, f);
}

/* mkdir -p */
static void make_dirs(const char *path) {
    char b[1024];
    size_t i;
    snprintf(b, sizeof b, "%s", path);
    for (i = 1; b[i]; ++i)
        if (b[i] == '/') {
            b[i] = 0;
            mkdir(b, 0777);
            b[i] = '/';
        }
    mkdir(b, 0777);
}

static size_t data_offset(size_t n) { return HEADER_BYTES + 12 * n + ((n + 3) / 4) * 4; }
static size_t frame_bytes(size_t n) { return 4 * n * (3 + 3 + 9); }

static void write_manifest(const char *dir, const pn_rs_scene *s, int fine, int frames, size_t n) {
    char path[1024];
    FILE *f;
    int k, i;
    snprintf(path, sizeof path, "%s/manifest.json", dir);
    f = fopen(path, "w");
    if (!f) return;
    fprintf(f, "{\"scene\": \"%s\", \"dim\": 3, \"n_points\": %lu, \"frame_dt_s\": %.17g, \"frames\": %d,\n", s->name,
            (unsigned long)n, s->frame_dt, frames);
    fprintf(f, " \"spacing_m\": %.17g, \"fine\": %d, \"params\": [", s->dx / s->per_axis, fine);
    for (i = 0; i < s->n_params; ++i) fprintf(f, "%s\"%s\"", i ? ", " : "", s->param_names[i]);
    fprintf(f, "],\n \"youngs_pa\": %.17g, \"poisson\": %.17g, \"density_kg_m3\": %.17g, \"dx_m\": %.17g, \"per_axis\": %d,\n",
            s->youngs_pa, s->poisson, s->density, s->dx, s->per_axis);
    fprintf(f, " \"solver\": \"plastinet_mpm.h explicit, APIC, fixed corotated\",\n \"instances\": [\n");
    for (k = 0; k < s->n_instances; ++k) {
        pn_rs_instance in = pn_rs_instance_of(s, k);
        fprintf(f, "  {\"id\": %d, \"params\": [", k);
        for (i = 0; i < s->n_params; ++i) fprintf(f, "%s%.17g", i ? ", " : "", in.params[i]);
        fprintf(f, "], \"split\": \"%s\", \"file\": \"i%03d.pnrs\"}%s\n", in.test ? "test" : "train", k,
                k + 1 < s->n_instances ? "," : "");
    }
    fprintf(f, " ]}\n");
    fclose(f);
}

/* the snapshot of the current state as float32 x, v, F */
static void write_frame(FILE *f, const pn_mpm_world *w, double *tmp) {
    size_t n = w->n, p;
    int i;
    for (p = 0; p < 3 * n; ++p) tmp[p] = (double)w->x[p];
    put_f32s(f, tmp, 3 * n);
    for (p = 0; p < 3 * n; ++p) tmp[p] = (double)w->v[p];
    put_f32s(f, tmp, 3 * n);
    for (p = 0; p < n; ++p)
        for (i = 0; i < 9; ++i) tmp[9 * p + (size_t)i] = (double)w->F[9 * p + (size_t)i];
    put_f32s(f, tmp, 9 * n);
}

/* checkpoint: frame index, time, then x, v, C, F in the solver's precision */
static int save_ckpt(const char *path, const pn_mpm_world *w, int frame) {
    char tmp[1100];
    FILE *f;
    size_t n = w->n;
    double t = (double)w->time_s;
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    f = fopen(tmp, "wb");
    if (!f) return 0;
    fwrite(&frame, sizeof frame, 1, f);
    fwrite(&t, sizeof t, 1, f);
    fwrite(&n, sizeof n, 1, f);
    fwrite(w->x, sizeof(pn_real), 3 * n, f);
    fwrite(w->v, sizeof(pn_real), 3 * n, f);
    fwrite(w->C, sizeof(pn_real), 9 * n, f);
    fwrite(w->F, sizeof(pn_real), 9 * n, f);
    if (fclose(f) != 0) return 0;
    return rename(tmp, path) == 0;
}

static int load_ckpt(const char *path, pn_mpm_world *w, int *frame) {
    FILE *f = fopen(path, "rb");
    size_t n = 0, m = w->n;
    double t = 0;
    pn_real *buf;
    int ok;
    if (!f) return 0;
    buf = (pn_real *)malloc(sizeof(pn_real) * 24 * m);
    ok = fread(frame, sizeof *frame, 1, f) == 1 && fread(&t, sizeof t, 1, f) == 1 && fread(&n, sizeof n, 1, f) == 1 &&
         n == m && fread(buf, sizeof(pn_real), 24 * m, f) == 24 * m;
    fclose(f);
    if (ok) ok = pn_mpm_set_particles(w, 0, m, buf, buf + 3 * m, buf + 6 * m, buf + 15 * m, (pn_real)t) == PN_OK;
    free(buf);
    return ok;
}

static int run_instance(const char *dir, const pn_rs_scene *s, int k, int frames) {
    char path[1024], ck[1100];
    pn_rs_instance in = pn_rs_instance_of(s, k);
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material_desc md;
    pn_material mat;
    size_t cap = pn_rs_points(s, 1, NULL, 0), n, p;
    double *X = (double *)malloc(sizeof(double) * 3 * cap), *tmp = (double *)malloc(sizeof(double) * 9 * cap), t0 = now_s();
    unsigned char *flags = (unsigned char *)malloc(cap + 4);
    pn_real dts;
    int frame = 0, nsub, next_load = 0, g, i, ok = 0;
    struct stat st;
    FILE *f = NULL;
    snprintf(path, sizeof path, "%s/i%03d.pnrs", dir, k);
    snprintf(ck, sizeof ck, "%s/i%03d.ckpt", dir, k);
    memset(&wd, 0, sizeof wd);
    wd.dim = 3;
    for (i = 0; i < 3; ++i) wd.res[i] = s->res[i], wd.gravity[i] = (pn_real)in.gravity[i];
    wd.dx_m = (pn_real)s->dx;
    wd.boundary = PN_BOUNDARY_STICKY;
    wd.max_particles = cap;
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_FIXED_COROTATED;
    md.plastic = PN_PLASTIC_NONE;
    md.youngs_modulus_pa = s->youngs_pa;
    md.poisson_ratio = s->poisson;
    if (pn_mpm_create(&wd, &w, NULL, 0) != PN_OK || pn_material_init(&mat, &md, NULL, 0) != PN_OK ||
        (g = pn_mpm_add_group(w, &mat, (pn_real)s->density)) < 0) {
        fprintf(stderr, "%s %d: cannot create the world\n", s->name, k);
        goto done;
    }
    n = pn_rs_setup(w, g, s, &in, 1, flags, X, cap);
    if (!n) goto done;
    if (stat(path, &st) == 0 && stat(ck, &st) != 0) { /* finished before (no checkpoint left) */
        size_t have = ((size_t)st.st_size - data_offset(n)) / frame_bytes(n);
        if ((size_t)st.st_size >= data_offset(n) && have >= (size_t)frames) {
            printf("%s %d: done before (%lu frames)\n", s->name, k, (unsigned long)have);
            ok = 1;
            goto done;
        }
    }
    if (load_ckpt(ck, w, &frame)) { /* resume: drop what was written after the checkpoint */
        if (truncate(path, (off_t)(data_offset(n) + (size_t)(frame + 1) * frame_bytes(n))) != 0 ||
            !(f = fopen(path, "r+b"))) {
            fprintf(stderr, "%s %d: cannot reopen %s\n", s->name, k, path);
            goto done;
        }
        fseek(f, 0, SEEK_END);
        printf("%s %d: resuming after frame %d\n", s->name, k, frame);
    } else {
        unsigned char h[HEADER_BYTES];
        memset(h, 0, sizeof h);
        memcpy(h, "PNROMS1\n", 8);
        put_i32(h + 8, 1), put_i32(h + 12, 3), put_i32(h + 16, (int)n), put_i32(h + 20, s->n_params);
        put_f64(h + 24, s->frame_dt);
        for (i = 0; i < s->n_params; ++i) put_f64(h + 32 + 8 * i, in.params[i]);
        put_i32(h + 96, k);
        if (!(f = fopen(path, "wb"))) {
            fprintf(stderr, "%s %d: cannot write %s: %s\n", s->name, k, path, strerror(errno));
            goto done;
        }
        fwrite(h, 1, sizeof h, f);
        put_f32s(f, X, 3 * n);
        fwrite(flags, 1, (n + 3) / 4 * 4, f);
        write_frame(f, w, tmp);
        fflush(f);
        frame = 0;
        if (!save_ckpt(ck, w, 0)) goto done;
    }
    /* a fixed step per scene: the stable step at rest with a margin for compression */
    if (pn_mpm_stable_dt(w, &dts) != PN_OK) goto done;
    nsub = (int)ceil(s->frame_dt / (0.7 * (double)dts));
    while (frame + 1 < frames) {
        int j;
        if (!pn_rs_events(w, &in, X, n, frame * s->frame_dt, &next_load)) goto done;
        for (j = 0; j < nsub; ++j) {
            pn_result r = pn_mpm_step_explicit(w, (pn_real)(s->frame_dt / nsub), NULL);
            if (r != PN_OK) {
                fprintf(stderr, "%s %d: frame %d step %d: %s\n", s->name, k, frame + 1, j, pn_mpm_error(w));
                goto done;
            }
        }
        frame++;
        write_frame(f, w, tmp);
        fflush(f);
        if (!save_ckpt(ck, w, frame)) {
            fprintf(stderr, "%s %d: cannot write the checkpoint\n", s->name, k);
            goto done;
        }
    }
    fclose(f);
    f = NULL;
    remove(ck);
    for (p = 0, i = 0; p < n; ++p) i += flags[p] != 0;
    printf("%s %d: %lu points (%d driven or loaded), %d frames, %d steps of %.3g s per frame, %.1f s\n", s->name, k,
           (unsigned long)n, i, frames, nsub, s->frame_dt / nsub, now_s() - t0);
    fflush(stdout);
    ok = 1;
done:
    if (f) fclose(f);
    pn_mpm_destroy(w);
    free(X), free(tmp), free(flags);
    return ok;
}

int main(int argc, char **argv) {
    const char *out = "data/rom", *split = "all";
    char dir[900];
    int id, a, only = -1, fine = 1, frames = 0, k, fails = 0;
    pn_rs_scene s;
    if (argc < 2 || (id = pn_rs_find(argv[1])) < 0) {
        fprintf(stderr, "usage: %s cylinder|cuboid|poke|poke_seq|tower [--out DIR] [--instance K] [--split all|train|test] "
                        "[--fine F] [--frames N]\n", argv[0]);
        return 2;
    }
    for (a = 2; a < argc; ++a) {
        if (!strcmp(argv[a], "--out") && a + 1 < argc) out = argv[++a];
        else if (!strcmp(argv[a], "--instance") && a + 1 < argc) only = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--split") && a + 1 < argc) split = argv[++a];
        else if (!strcmp(argv[a], "--fine") && a + 1 < argc) fine = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--frames") && a + 1 < argc) frames = atoi(argv[++a]);
        else {
            fprintf(stderr, "unknown argument %s\n", argv[a]);
            return 2;
        }
    }
    if (fine < 1) fine = 1;
    s = pn_rs_get(id, fine);
    if (frames <= 0 || frames > s.frames) frames = s.frames;
    if (fine > 1) snprintf(dir, sizeof dir, "%s/%s_f%d", out, s.name, fine);
    else snprintf(dir, sizeof dir, "%s/%s", out, s.name);
    make_dirs(dir);
    write_manifest(dir, &s, fine, frames, pn_rs_points(&s, 1, NULL, 0));
    for (k = 0; k < s.n_instances; ++k) {
        pn_rs_instance in = pn_rs_instance_of(&s, k);
        if (only >= 0 && k != only) continue;
        if ((!strcmp(split, "train") && in.test) || (!strcmp(split, "test") && !in.test)) continue;
        fails += !run_instance(dir, &s, k, frames);
    }
    return fails ? 1 : 0;
}
