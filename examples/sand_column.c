/* sand_column: a column of sand (aspect ratio a = H / W) collapsing on the floor, simulated by
   plastinet_mpm.h, explicit (the reference) or implicit with the PlasticityNet sand model.
   Build: cc -std=c99 -O2 examples/sand_column.c -lm -o sand_column
   Usage: sand_column [--dim 2|3] [--integrator implicit|explicit] [--energy pnet|lagged|elastic]
                      [--dt S] [--fixed-point N] [--frames N] [--fps N] [--aspect A] [--E PA]
                      [--res N] [--out DIR] [--png] [--ply] [--quiet]
   Writes DIR/frame_NNNN.png (--png) and DIR/frame_NNNN.ply (--ply, ASCII point clouds that
   Houdini, Blender and ParaView read); a progress line on stderr; a one-line JSON summary on
   stdout (frames, wall seconds, iterations, runout, final height, largest fixed-point residual).
   The domain walls are sticky (the floor holds the sand; both integrators treat it alike). */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "../models/pn_model_sand_2d.h"
#include "../models/pn_model_sand_3d.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---- a small PNG writer: RGB, zlib stored (uncompressed) blocks ------------------------- */

static unsigned long png_crc(unsigned long c, const unsigned char *b, size_t n) {
    size_t i;
    int k;
    for (i = 0; i < n; ++i) {
        c ^= b[i];
        for (k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320UL & (0UL - (c & 1UL)));
    }
    return c;
}

static void png_u32(unsigned char *p, unsigned long v) {
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

static void png_chunk(FILE *f, const char *type, const unsigned char *data, size_t n) {
    unsigned char h[8];
    unsigned long c;
    png_u32(h, (unsigned long)n);
    memcpy(h + 4, type, 4);
    fwrite(h, 1, 8, f);
    if (n) fwrite(data, 1, n, f);
    c = png_crc(0xFFFFFFFFUL, (const unsigned char *)type, 4);
    c = png_crc(c, data, n) ^ 0xFFFFFFFFUL;
    png_u32(h, c);
    fwrite(h, 1, 4, f);
}

static int png_write(const char *path, int w, int h, const unsigned char *rgb) {
    size_t row = (size_t)w * 3 + 1, raw_n = row * (size_t)h, blocks = (raw_n + 65534) / 65535;
    size_t z_n = 2 + raw_n + 5 * blocks + 4, i, pos = 0, off = 0;
    unsigned char *raw = (unsigned char *)malloc(raw_n), *z = (unsigned char *)malloc(z_n), hdr[13];
    unsigned long a = 1, b = 0;
    FILE *f;
    int y;
    if (!raw || !z || !(f = fopen(path, "wb"))) {
        free(raw);
        free(z);
        return 0;
    }
    for (y = 0; y < h; ++y) {
        raw[(size_t)y * row] = 0; /* filter: none */
        memcpy(raw + (size_t)y * row + 1, rgb + (size_t)y * (size_t)w * 3, (size_t)w * 3);
    }
    z[pos++] = 0x78;
    z[pos++] = 0x01;
    while (off < raw_n) {
        size_t n = raw_n - off > 65535 ? 65535 : raw_n - off;
        z[pos++] = off + n == raw_n ? 1 : 0;
        z[pos++] = (unsigned char)(n & 255);
        z[pos++] = (unsigned char)(n >> 8);
        z[pos++] = (unsigned char)(~n & 255);
        z[pos++] = (unsigned char)((~n >> 8) & 255);
        memcpy(z + pos, raw + off, n);
        pos += n;
        off += n;
    }
    for (i = 0; i < raw_n; ++i) { /* adler32 */
        a = (a + raw[i]) % 65521UL;
        b = (b + a) % 65521UL;
    }
    png_u32(z + pos, (b << 16) | a);
    pos += 4;
    fwrite("\x89PNG\r\n\x1a\n", 1, 8, f);
    png_u32(hdr, (unsigned long)w);
    png_u32(hdr + 4, (unsigned long)h);
    hdr[8] = 8;  /* bit depth */
    hdr[9] = 2;  /* RGB */
    hdr[10] = hdr[11] = hdr[12] = 0;
    png_chunk(f, "IHDR", hdr, 13);
    png_chunk(f, "IDAT", z, pos);
    png_chunk(f, "IEND", NULL, 0);
    fclose(f);
    free(raw);
    free(z);
    return 1;
}

/* particles seen from the front (x right, y up), coloured by speed */
static int render_png(const char *path, const pn_mpm_world *w, int px) {
    unsigned char *img = (unsigned char *)malloc((size_t)px * (size_t)px * 3);
    double L = w->desc.res[0] * w->desc.dx_m;
    size_t p;
    int ok, i;
    if (!img) return 0;
    for (i = 0; i < px * px * 3; ++i) img[i] = 245;
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim, *v = w->v + p * (size_t)w->dim;
        double sp = 0;
        int cx = (int)(x[0] / L * px), cy = px - 1 - (int)(x[1] / L * px), dx, dy;
        if (!w->active[p]) continue;
        for (i = 0; i < w->dim; ++i) sp += (double)v[i] * (double)v[i];
        sp = sqrt(sp);
        for (dy = -1; dy <= 1; ++dy)
            for (dx = -1; dx <= 1; ++dx) {
                int X = cx + dx, Y = cy + dy;
                unsigned char *c;
                if (X < 0 || Y < 0 || X >= px || Y >= px) continue;
                c = img + ((size_t)Y * (size_t)px + (size_t)X) * 3;
                c[0] = (unsigned char)(200 - 120 * (sp > 1 ? 1 : sp));
                c[1] = (unsigned char)(160 - 60 * (sp > 1 ? 1 : sp));
                c[2] = (unsigned char)(90 + 150 * (sp > 1 ? 1 : sp));
            }
    }
    ok = png_write(path, px, px, img);
    free(img);
    return ok;
}

static int write_ply(const char *path, const pn_mpm_world *w) {
    FILE *f = fopen(path, "w");
    size_t p, n = 0;
    if (!f) return 0;
    for (p = 0; p < w->n; ++p) n += w->active[p];
    fprintf(f, "ply\nformat ascii 1.0\nelement vertex %zu\nproperty float x\nproperty float y\n"
               "property float z\nproperty float vx\nproperty float vy\nproperty float vz\nend_header\n", n);
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim, *v = w->v + p * (size_t)w->dim;
        if (!w->active[p]) continue;
        fprintf(f, "%g %g %g %g %g %g\n", (double)x[0], (double)x[1], w->dim == 3 ? (double)x[2] : 0.0,
                (double)v[0], (double)v[1], w->dim == 3 ? (double)v[2] : 0.0);
    }
    fclose(f);
    return 1;
}

static void usage(void) {
    fprintf(stderr, "usage: sand_column [--dim 2|3] [--integrator implicit|explicit] [--energy pnet|lagged|elastic]\n"
                    "       [--dt S] [--fixed-point N] [--frames N] [--fps N] [--aspect A] [--E PA] [--res N]\n"
                    "       [--out DIR] [--png] [--ply] [--quiet]\n");
}

int main(int argc, char **argv) {
    int dim = 2, implicit = 1, fp = 1, frames = 30, fps = 30, res = 64, png = 0, ply = 0, quiet = 0;
    int k, i, frame, g, steps_per_frame;
    double dt = 1e-3, aspect = 2, E = 1e7, rho = 1600, W = 0.12, t0, wall = 0, fp_worst = 0;
    const char *energy = "pnet", *out = "build/sand_column_frames";
    long newton = 0, cg = 0, steps = 0, ls_fail = 0;
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material m;
    pn_pnet net;
    pn_pnet_desc nd;
    pn_mpm_implicit_desc id;
    const char *why = "";
    const pn_model *model;
    pn_real *xs;
    size_t n = 0, cap;
    double cell, x0, spacing;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        if (!strcmp(a, "--png")) png = 1;
        else if (!strcmp(a, "--ply")) ply = 1;
        else if (!strcmp(a, "--quiet")) quiet = 1;
        else if (!v) { usage(); return 2; }
        else if (!strcmp(a, "--dim")) dim = atoi(v), ++k;
        else if (!strcmp(a, "--integrator")) implicit = !strcmp(v, "implicit") ? 1 : (!strcmp(v, "explicit") ? 0 : -1), ++k;
        else if (!strcmp(a, "--energy")) energy = v, ++k;
        else if (!strcmp(a, "--dt")) dt = atof(v), ++k;
        else if (!strcmp(a, "--fixed-point")) fp = atoi(v), ++k;
        else if (!strcmp(a, "--frames")) frames = atoi(v), ++k;
        else if (!strcmp(a, "--fps")) fps = atoi(v), ++k;
        else if (!strcmp(a, "--aspect")) aspect = atof(v), ++k;
        else if (!strcmp(a, "--E")) E = atof(v), ++k;
        else if (!strcmp(a, "--res")) res = atoi(v), ++k;
        else if (!strcmp(a, "--out")) out = v, ++k;
        else { usage(); return 2; }
    }
    if ((dim != 2 && dim != 3) || implicit < 0 || !(dt > 0) || fp < 1 || frames < 1 || fps < 1 || !(aspect > 0) ||
        !(E > 0) || res < 16 || res > 1024 ||
        (strcmp(energy, "pnet") && strcmp(energy, "lagged") && strcmp(energy, "elastic"))) {
        usage();
        return 2;
    }
    model = dim == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
    if (pn_model_material(model, E, &m) != PN_OK) {
        fprintf(stderr, "sand_column: bad Young's modulus\n");
        return 2;
    }
    /* domain 1 m (2D) or 0.5 m (3D) wide; the column stands at the left wall's centre line */
    cell = (dim == 2 ? 1.0 : 0.5) / res;
    memset(&wd, 0, sizeof wd);
    wd.dim = dim;
    for (i = 0; i < dim; ++i) wd.res[i] = res;
    wd.dx_m = cell;
    wd.gravity[1] = -9.81;
    wd.boundary = PN_MPM_BOUNDARY_STICKY;
    spacing = cell / 2; /* 2 particles per cell per axis */
    cap = (size_t)(W / spacing + 1) * (size_t)(aspect * W / spacing + 1) * (dim == 3 ? (size_t)(W / spacing + 1) : 1);
    wd.max_particles = cap;
    if (pn_mpm_create(&wd, &w) != PN_OK) {
        fprintf(stderr, "sand_column: cannot create the world\n");
        return 1;
    }
    g = pn_mpm_add_group(w, &m, rho);
    xs = (pn_real *)malloc(sizeof(pn_real) * cap * (size_t)dim);
    x0 = (res / 2) * cell - W / 2;
    {
        int a, b, c, na = (int)(W / spacing), nb = (int)(aspect * W / spacing), nc = dim == 3 ? na : 1;
        for (a = 0; a < na; ++a)
            for (b = 0; b < nb; ++b)
                for (c = 0; c < nc; ++c) {
                    xs[n * dim] = x0 + (a + 0.5) * spacing;
                    xs[n * dim + 1] = 3 * cell + (b + 0.5) * spacing;
                    if (dim == 3) xs[n * dim + 2] = x0 + (c + 0.5) * spacing;
                    ++n;
                }
    }
    if (pn_mpm_add_particles(w, g, n, xs, NULL, pow(spacing, dim)) != PN_OK) {
        fprintf(stderr, "sand_column: the column does not fit the domain (lower --aspect or raise --res)\n");
        return 1;
    }
    free(xs);
    if (implicit) {
        if (!strcmp(energy, "pnet")) {
            memset(&nd, 0, sizeof nd);
            nd.energy = model;
            if (pn_pnet_init(&net, &nd, &m, dim, &why) != PN_OK ||
                pn_mpm_group_set_energy(w, g, PN_MPM_ENERGY_PNET, &net) != PN_OK) {
                fprintf(stderr, "sand_column: %s\n", why);
                return 1;
            }
        } else {
            pn_mpm_group_set_energy(w, g, !strcmp(energy, "lagged") ? PN_MPM_ENERGY_LAGGED : PN_MPM_ENERGY_ELASTIC, NULL);
        }
    }
    memset(&id, 0, sizeof id);
    id.fixed_point_iters = fp;
    steps_per_frame = (int)(1.0 / fps / dt + 0.5);
    if (steps_per_frame < 1) steps_per_frame = 1;
    t0 = (double)clock() / CLOCKS_PER_SEC;
    for (frame = 1; frame <= frames; ++frame) {
        char path[1024];
        for (k = 0; k < steps_per_frame; ++k) {
            pn_mpm_stats st;
            pn_result r = implicit ? pn_mpm_step_implicit(w, dt, &id, &st) : pn_mpm_step_explicit(w, dt, &st);
            if (r != PN_OK) {
                fprintf(stderr, "\nsand_column: step %ld failed at particle %zu: %s\n", steps, w->error_particle,
                        pn_result_string(r));
                return 1;
            }
            ++steps;
            newton += st.newton_iters;
            cg += st.cg_iters;
            ls_fail += st.line_search_failures;
            if (st.fixed_point_residual > fp_worst) fp_worst = st.fixed_point_residual;
        }
        if (png) {
            snprintf(path, sizeof path, "%s/frame_%04d.png", out, frame);
            if (!render_png(path, w, 400)) {
                fprintf(stderr, "\nsand_column: cannot write %s (does the folder exist?)\n", path);
                return 1;
            }
        }
        if (ply) {
            snprintf(path, sizeof path, "%s/frame_%04d.ply", out, frame);
            if (!write_ply(path, w)) {
                fprintf(stderr, "\nsand_column: cannot write %s (does the folder exist?)\n", path);
                return 1;
            }
        }
        wall = (double)clock() / CLOCKS_PER_SEC - t0;
        if (!quiet)
            fprintf(stderr, "\rframe %d/%d  t = %.3f s  wall %.1f s  Newton/step %.1f  CG/step %.0f   ", frame, frames,
                    (double)w->time_s, wall, (double)newton / (double)steps, (double)cg / (double)steps);
    }
    if (!quiet) fprintf(stderr, "\n");
    {
        double right = 0, top = 0;
        size_t p;
        for (p = 0; p < w->n; ++p) {
            if (!w->active[p]) continue;
            if (w->x[p * dim] - (x0 + W / 2) > right) right = w->x[p * dim] - (x0 + W / 2);
            if (w->x[p * dim + 1] - 3 * cell > top) top = w->x[p * dim + 1] - 3 * cell;
        }
        printf("{\"scene\": \"sand_column\", \"dim\": %d, \"integrator\": \"%s\", \"energy\": \"%s\", \"dt\": %g, "
               "\"fixed_point_iters\": %d, \"E\": %g, \"aspect\": %g, \"particles\": %zu, \"frames\": %d, "
               "\"simulated_s\": %.4f, \"wall_s\": %.3f, \"steps\": %ld, \"newton_per_step\": %.2f, "
               "\"cg_per_step\": %.1f, \"line_search_failures\": %ld, \"runout_m\": %.4f, \"final_height_m\": %.4f, "
               "\"max_fixed_point_residual\": %.3e, \"left_domain\": %zu}\n",
               dim, implicit ? "implicit" : "explicit", implicit ? energy : "return_mapping", dt, fp, E, aspect, n,
               frames, (double)w->time_s, wall, steps, steps ? (double)newton / (double)steps : 0.0,
               steps ? (double)cg / (double)steps : 0.0, ls_fail, right, top, fp_worst, (size_t)w->left_total);
    }
    pn_mpm_destroy(w);
    return 0;
}
