/* pn_example.h: what the examples and the MPM benchmark share, so each stays one .c file and a
   one-line build. Include it once, first, in a file that defines PLASTINET_IMPLEMENTATION:
       #define PLASTINET_IMPLEMENTATION
       #include "pn_example.h"      // plastinet.h, plastinet_mpm.h, the sand and snow models
   Here: a monotonic clock, a PNG writer and a particle renderer, an ASCII PLY writer, the scene
   builders of shared/design/VALIDATION.md (sand column, snowball), a stepping helper that
   tallies solver statistics, and the mass IoU metric. Everything is static; no globals. */
#ifndef PN_EXAMPLE_H
#define PN_EXAMPLE_H
/* clock_gettime under -std=c99; must come before the first system header */
#if !defined(_POSIX_C_SOURCE) && !defined(_WIN32)
#define _POSIX_C_SOURCE 199309L
#endif
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "../models/pn_model_sand_2d.h"
#include "../models/pn_model_sand_3d.h"
#include "../models/pn_model_snow_2d.h"
#include "../models/pn_model_snow_3d.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* each program uses only some of these helpers */
#if defined(__GNUC__)
#define PN_EX_UNUSED __attribute__((unused))
#else
#define PN_EX_UNUSED
#endif

/* Wall-clock seconds from an arbitrary origin: CLOCK_MONOTONIC where POSIX has it (immune to
   clock changes, counts time lost to other processes), else processor time from clock(). */
PN_EX_UNUSED static double pn_ex_seconds(void) {
#if defined(CLOCK_MONOTONIC)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#else
    return (double)clock() / CLOCKS_PER_SEC;
#endif
}

/* ---- PNG: RGB, zlib stored (uncompressed) blocks; no compressor needed ------------------- */

static unsigned long pn_ex__png_crc(unsigned long c, const unsigned char *b, size_t n) {
    size_t i;
    int k;
    for (i = 0; i < n; ++i) {
        c ^= b[i];
        for (k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320UL & (0UL - (c & 1UL)));
    }
    return c;
}

static void pn_ex__png_u32(unsigned char *p, unsigned long v) {
    p[0] = (unsigned char)(v >> 24);
    p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8);
    p[3] = (unsigned char)v;
}

static void pn_ex__png_chunk(FILE *f, const char *type, const unsigned char *data, size_t n) {
    unsigned char h[8];
    unsigned long c;
    pn_ex__png_u32(h, (unsigned long)n);
    memcpy(h + 4, type, 4);
    fwrite(h, 1, 8, f);
    if (n) fwrite(data, 1, n, f);
    c = pn_ex__png_crc(0xFFFFFFFFUL, (const unsigned char *)type, 4);
    c = pn_ex__png_crc(c, data, n) ^ 0xFFFFFFFFUL;
    pn_ex__png_u32(h, c);
    fwrite(h, 1, 4, f);
}

/* Write a w x h RGB image (rows top to bottom); 1 on success. */
PN_EX_UNUSED static int pn_ex_png_write(const char *path, int w, int h, const unsigned char *rgb) {
    size_t row = (size_t)w * 3 + 1, raw_n = row * (size_t)h, blocks = (raw_n + 65534) / 65535;
    size_t z_n = 2 + raw_n + 5 * blocks + 4, i, pos = 0, off = 0;
    unsigned char *raw = (unsigned char *)malloc(raw_n), *z = (unsigned char *)malloc(z_n), hdr[13];
    unsigned long a = 1, b = 0;
    FILE *f;
    int y, ok;
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
    pn_ex__png_u32(z + pos, (b << 16) | a);
    pos += 4;
    fwrite("\x89PNG\r\n\x1a\n", 1, 8, f);
    pn_ex__png_u32(hdr, (unsigned long)w);
    pn_ex__png_u32(hdr + 4, (unsigned long)h);
    hdr[8] = 8; /* bit depth */
    hdr[9] = 2; /* RGB */
    hdr[10] = hdr[11] = hdr[12] = 0;
    pn_ex__png_chunk(f, "IHDR", hdr, 13);
    pn_ex__png_chunk(f, "IDAT", z, pos);
    pn_ex__png_chunk(f, "IEND", NULL, 0);
    ok = ferror(f) == 0;
    ok = (fclose(f) == 0) && ok;
    free(raw);
    free(z);
    return ok;
}

/* The active particles seen from the front (x right, y up; 3D projects along z) as 3x3-pixel
   dots coloured by speed (sand colour at rest, blue at 1 m/s and above); 1 on success. */
PN_EX_UNUSED static int pn_ex_render_png(const char *path, const pn_mpm_world *w, int px) {
    unsigned char *img = (unsigned char *)malloc((size_t)px * (size_t)px * 3);
    double L = w->desc.res[0] * (double)w->desc.dx_m;
    size_t p;
    int ok, i;
    if (!img) return 0;
    memset(img, 245, (size_t)px * (size_t)px * 3);
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim, *v = w->v + p * (size_t)w->dim;
        double sp = 0;
        int cx = (int)(x[0] / L * px), cy = px - 1 - (int)(x[1] / L * px), dx, dy;
        if (!w->active[p]) continue;
        for (i = 0; i < w->dim; ++i) sp += (double)v[i] * (double)v[i];
        sp = sqrt(sp);
        if (sp > 1) sp = 1;
        for (dy = -1; dy <= 1; ++dy)
            for (dx = -1; dx <= 1; ++dx) {
                int X = cx + dx, Y = cy + dy;
                unsigned char *c;
                if (X < 0 || Y < 0 || X >= px || Y >= px) continue;
                c = img + ((size_t)Y * (size_t)px + (size_t)X) * 3;
                c[0] = (unsigned char)(200 - 120 * sp);
                c[1] = (unsigned char)(160 - 60 * sp);
                c[2] = (unsigned char)(90 + 150 * sp);
            }
    }
    ok = pn_ex_png_write(path, px, px, img);
    free(img);
    return ok;
}

/* ASCII PLY point cloud of the active particles, "x y z vx vy vz" per vertex (z = vz = 0 in
   2D); Houdini, Blender and ParaView read it. 1 on success. */
PN_EX_UNUSED static int pn_ex_write_ply(const char *path, const pn_mpm_world *w) {
    FILE *f = fopen(path, "w");
    size_t p, n = 0;
    int ok;
    if (!f) return 0;
    for (p = 0; p < w->n; ++p) n += w->active[p];
    fprintf(f, "ply\nformat ascii 1.0\nelement vertex %lu\nproperty float x\nproperty float y\n"
               "property float z\nproperty float vx\nproperty float vy\nproperty float vz\nend_header\n",
            (unsigned long)n);
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim, *v = w->v + p * (size_t)w->dim;
        if (!w->active[p]) continue;
        fprintf(f, "%g %g %g %g %g %g\n", (double)x[0], (double)x[1], w->dim == 3 ? (double)x[2] : 0.0,
                (double)v[0], (double)v[1], w->dim == 3 ? (double)v[2] : 0.0);
    }
    ok = ferror(f) == 0;
    return (fclose(f) == 0) && ok;
}

/* ---- scenes (shared/design/VALIDATION.md) ------------------------------------------------

   Both live in a cube of side domain_m (1 m in 2D, 0.5 m in 3D) cut into res cells per axis,
   with walls 3 cells thick (so the floor is at y = 3 dx), gravity 9.81 m/s^2 along -y, and
   2 x 2 (x 2) particles per cell placed on a regular lattice. The material is the one the
   embedded PlasticityNet model was trained for, at Young's modulus E_pa.
   - sand column: StVK-Hencky + Drucker-Prager (nu 0.3, friction angle 30 deg), E 1e7 Pa,
     1600 kg/m^3; a column of width W = 0.12 m (a square prism in 3D) and height a W, a = 2,
     standing on the floor at the centre of the domain, at rest.
   - snowball: Neo-Hookean snow + Cam-Clay with hardening (nu 0.3, 45 deg, beta 0.3, xi 3),
     E 1e6 Pa, 400 kg/m^3; a disk (2D, radius 0.1 m) or ball (3D, radius 0.08 m, mid-depth)
     that starts 0.05 domain_m from the left wall and 0.1 domain_m above the floor, thrown at
     3 m/s, 45 deg below the horizontal, towards +x. Its initial h = log J_p = -0.01 sits
     inside the model's trained range [-0.15, 0]; it sets the consolidation pressure
     p0 = kappa sinh(-xi h) (25-29 kPa at E = 1e6), which gives the snow cohesion but is
     exceeded by the impact (about rho c v = 60 kPa, c = sqrt(E / rho)), so the ball breaks
     (at h0 = -0.03 it bounces off whole).
   Walls: SEPARATE with Coulomb friction 0.5 (the frictional floor); STICKY or SLIP on request. */

typedef enum pn_ex_scene_kind { PN_EX_SAND_COLUMN = 0, PN_EX_SNOWBALL } pn_ex_scene_kind;

typedef struct pn_ex_scene {
    pn_ex_scene_kind kind;
    int dim;                     /* 2 or 3                                                 */
    int res;                     /* grid cells per axis [64 in 2D, 24 in 3D]               */
    double domain_m;             /* side of the cubic domain [1 in 2D, 0.5 in 3D]           */
    double E_pa;                 /* Young's modulus [sand 1e7, snow 1e6]                    */
    double density_kg_m3;        /* [sand 1600, snow 400]                                   */
    pn_mpm_boundary boundary;    /* domain walls [SEPARATE]                                 */
    double friction;             /* Coulomb coefficient of SEPARATE walls [0.5]             */
    double filter_s;             /* transfer filter time (pn_mpm_desc.filter_time_s) [2e-3]  */
    double regularizer;          /* PlasticityNet's w (pn_pnet_desc.regularizer) [0: 1]     */
    pn_mpm_energy energy;        /* what implicit steps minimize [PNET]; ignored by explicit */
    double width_m, aspect;      /* sand column: W [0.12], a = H / W [2]                    */
    double radius_m;             /* snowball: [0.1 in 2D, 0.08 in 3D]                       */
    double speed_m_s, angle_deg; /* snowball: throw speed [3] and angle below horizontal [45] */
    double h0;                   /* snowball: initial log J_p [-0.01]                       */
    int no_hardening;            /* snowball: Cam-Clay with h held (no hardening) [0]        */
} pn_ex_scene;

/* Fill s with the defaults above for a scene kind and dimension. */
PN_EX_UNUSED static void pn_ex_scene_default(pn_ex_scene *s, pn_ex_scene_kind kind, int dim) {
    int sand = kind == PN_EX_SAND_COLUMN;
    memset(s, 0, sizeof *s);
    s->kind = kind;
    s->dim = dim;
    s->res = dim == 2 ? 64 : 24;
    s->domain_m = dim == 2 ? 1.0 : 0.5;
    s->E_pa = sand ? 1e7 : 1e6;
    s->density_kg_m3 = sand ? 1600 : 400;
    s->boundary = PN_MPM_BOUNDARY_SEPARATE;
    s->friction = 0.5;
    s->filter_s = 2e-3;
    s->energy = PN_MPM_ENERGY_PNET;
    s->width_m = 0.12;
    s->aspect = 2;
    s->radius_m = dim == 2 ? 0.1 : 0.08;
    s->speed_m_s = 3;
    s->angle_deg = 45;
    s->h0 = -0.01;
}

#define PN_EX_WALL_CELLS 3

PN_EX_UNUSED static double pn_ex_scene_dx(const pn_ex_scene *s) { return s->domain_m / s->res; }
/* height of the floor (m): the top of the bottom wall */
PN_EX_UNUSED static double pn_ex_scene_floor(const pn_ex_scene *s) { return PN_EX_WALL_CELLS * pn_ex_scene_dx(s); }

PN_EX_UNUSED static const pn_model *pn_ex_scene_model(const pn_ex_scene *s) {
    if (s->kind == PN_EX_SAND_COLUMN) return s->dim == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
    return s->dim == 2 ? pn_model_snow_2d() : pn_model_snow_3d();
}

/* Where the snowball's centre starts (m). */
static void pn_ex__ball_centre(const pn_ex_scene *s, double *c) {
    c[0] = pn_ex_scene_floor(s) + 0.05 * s->domain_m + s->radius_m; /* the walls are alike */
    c[1] = pn_ex_scene_floor(s) + 0.1 * s->domain_m + s->radius_m;
    c[2] = 0.5 * s->domain_m;
}

/* Lattice of the scene's particles: writes up to cap positions to x (NULL: count only) and
   returns how many there are. Spacing dx/2, points at the centres of the lattice cells. */
static size_t pn_ex__lattice(const pn_ex_scene *s, pn_real *x, size_t cap) {
    int d = s->dim, i, a, b, c, na, nb, nc;
    double sp = pn_ex_scene_dx(s) / 2, lo[3], p[3], ctr[3] = {0, 0, 0};
    size_t n = 0;
    if (s->kind == PN_EX_SAND_COLUMN) {
        na = (int)(s->width_m / sp);
        nb = (int)(s->aspect * s->width_m / sp);
        lo[0] = lo[2] = s->domain_m / 2 - na * sp / 2;
        lo[1] = pn_ex_scene_floor(s);
    } else {
        pn_ex__ball_centre(s, ctr);
        na = nb = 2 * (int)ceil(s->radius_m / sp) + 2; /* a spare row each side for the snap */
        for (i = 0; i < 3; ++i) lo[i] = ctr[i] - na * sp / 2;
    }
    /* snap the lattice to the grid so every particle sits at a quarter of a cell, as in the
       usual 2-per-cell seeding (the ball keeps its exact centre: points are chosen by radius) */
    for (i = 0; i < 3; ++i) lo[i] = floor(lo[i] / sp + 0.5) * sp;
    nc = d == 3 ? na : 1;
    for (a = 0; a < na; ++a)
        for (b = 0; b < nb; ++b)
            for (c = 0; c < nc; ++c) {
                double r2 = 0;
                p[0] = lo[0] + (a + 0.5) * sp;
                p[1] = lo[1] + (b + 0.5) * sp;
                p[2] = lo[2] + (c + 0.5) * sp;
                if (s->kind == PN_EX_SNOWBALL) {
                    for (i = 0; i < d; ++i) r2 += (p[i] - ctr[i]) * (p[i] - ctr[i]);
                    if (r2 > s->radius_m * s->radius_m) continue;
                }
                if (x && n < cap)
                    for (i = 0; i < d; ++i) x[n * (size_t)d + (size_t)i] = (pn_real)p[i];
                ++n;
            }
    return n;
}

/* Create the world of scene s in *out, filled and ready to step, with the energy s->energy
   bound for implicit steps. On failure *out is NULL, *why says what went wrong. */
PN_EX_UNUSED static pn_result pn_ex_scene_create(const pn_ex_scene *s, pn_mpm_world **out, const char **why) {
    const pn_model *model;
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material m;
    pn_real *x, *v = NULL;
    size_t n, p;
    int g, i, d = s->dim;
    double sp = pn_ex_scene_dx(s) / 2;
    pn_result r;
    *out = NULL;
    *why = "";
    if ((d != 2 && d != 3) || s->res < 16 || s->res > 1024 || !(s->domain_m > 0)) {
        *why = "dim must be 2 or 3, res in [16, 1024], domain_m > 0";
        return PN_ERROR_INVALID_ARGUMENT;
    }
    model = pn_ex_scene_model(s);
    if ((r = pn_model_material(model, (pn_real)s->E_pa, &m, NULL)) != PN_OK) {
        *why = "bad Young's modulus";
        return r;
    }
    if (s->no_hardening) m.camclay_hardening = 0;
    n = pn_ex__lattice(s, NULL, 0);
    if (n == 0) {
        *why = "the scene has no particles (size below half a cell)";
        return PN_ERROR_INVALID_ARGUMENT;
    }
    memset(&wd, 0, sizeof wd);
    wd.dim = d;
    for (i = 0; i < d; ++i) wd.res[i] = s->res;
    wd.dx_m = (pn_real)pn_ex_scene_dx(s);
    wd.gravity[1] = (pn_real)-9.81;
    wd.boundary = s->boundary;
    wd.friction = (pn_real)s->friction;
    wd.filter_time_s = (pn_real)s->filter_s;
    wd.wall_cells = PN_EX_WALL_CELLS;
    wd.max_particles = n;
    if ((r = pn_mpm_create(&wd, &w)) != PN_OK) {
        *why = "cannot create the world (bad friction, or out of memory)";
        return r;
    }
    g = pn_mpm_add_group(w, &m, (pn_real)s->density_kg_m3);
    x = (pn_real *)malloc(sizeof(pn_real) * n * (size_t)d);
    if (s->kind == PN_EX_SNOWBALL) v = (pn_real *)malloc(sizeof(pn_real) * n * (size_t)d);
    if (g < 0 || !x || (s->kind == PN_EX_SNOWBALL && !v)) {
        *why = g < 0 ? "density must be positive" : "out of memory";
        r = g < 0 ? PN_ERROR_INVALID_ARGUMENT : PN_ERROR_OUT_OF_MEMORY;
        goto fail;
    }
    pn_ex__lattice(s, x, n);
    if (v) {
        double a = s->angle_deg * 3.14159265358979 / 180;
        for (p = 0; p < n; ++p) {
            for (i = 0; i < d; ++i) v[p * (size_t)d + (size_t)i] = 0;
            v[p * (size_t)d] = (pn_real)(s->speed_m_s * cos(a));
            v[p * (size_t)d + 1] = (pn_real)(-s->speed_m_s * sin(a));
        }
    }
    if ((r = pn_mpm_add_particles(w, g, n, x, v, (pn_real)pow(sp, d))) != PN_OK) {
        *why = "the scene does not fit inside the walls (smaller size, or higher res)";
        goto fail;
    }
    if (s->kind == PN_EX_SNOWBALL) { /* the snow's initial consolidation: h = log J_p = h0 */
        for (p = 0; p < n; ++p) x[p] = (pn_real)s->h0;
        if ((r = pn_mpm_set_state(w, 0, n, x)) != PN_OK) {
            *why = "bad initial log J_p";
            goto fail;
        }
    }
    if (s->energy == PN_MPM_ENERGY_PNET) {
        pn_pnet net;
        pn_pnet_desc nd;
        memset(&nd, 0, sizeof nd);
        nd.energy = model;
        nd.regularizer = (pn_real)s->regularizer;
        if ((r = pn_pnet_init(&net, &nd, &m, d, why)) != PN_OK) goto fail;
        r = pn_mpm_group_set_energy(w, g, PN_MPM_ENERGY_PNET, &net);
    } else {
        r = pn_mpm_group_set_energy(w, g, s->energy, NULL);
    }
    if (r != PN_OK) {
        *why = "this energy does not serve this material";
        goto fail;
    }
    free(x);
    free(v);
    *out = w;
    return PN_OK;
fail:
    free(x);
    free(v);
    pn_mpm_destroy(w);
    return r;
}

/* ---- stepping --------------------------------------------------------------------------- */

/* Solver statistics summed over steps. */
typedef struct pn_ex_tally {
    long steps, newton, cg, fixed_point, line_search_failures;
    long halved;                     /* implicit steps retried as substeps (the fallback)    */
    double max_fixed_point_residual; /* max_q |F0_new - F0| at the end of a step, worst step  */
    double max_speed_m_s;            /* fastest particle after any step                      */
    /* pn_mpm_implicit_desc.measure_force_error: per-step values summed (mean = sum / steps) */
    double force_error, force_error_regularizer, apex_fraction;
} pn_ex_tally;

/* n steps of dt_s seconds, implicit (with id, which may be NULL for its defaults) or explicit;
   adds to *t. Stops at the first failed step and returns its code (w->error_particle names
   the culprit; the world stays as before that step). */
PN_EX_UNUSED static pn_result pn_ex_steps(pn_mpm_world *w, int implicit, double dt_s,
                                          const pn_mpm_implicit_desc *id, long n, pn_ex_tally *t) {
    long k;
    for (k = 0; k < n; ++k) {
        pn_mpm_stats st;
        pn_result r = implicit ? pn_mpm_step_implicit(w, (pn_real)dt_s, id, &st)
                               : pn_mpm_step_explicit(w, (pn_real)dt_s, &st);
        if (r != PN_OK) return r;
        t->steps++;
        t->newton += st.newton_iters;
        t->cg += st.cg_iters;
        t->fixed_point += st.fixed_point_iters;
        t->line_search_failures += st.line_search_failures;
        t->halved += implicit && st.substeps > 1;
        if ((double)st.fixed_point_residual > t->max_fixed_point_residual)
            t->max_fixed_point_residual = (double)st.fixed_point_residual;
        if ((double)st.max_speed_m_s > t->max_speed_m_s) t->max_speed_m_s = (double)st.max_speed_m_s;
        t->force_error += (double)st.force_error;
        t->force_error_regularizer += (double)st.force_error_regularizer;
        t->apex_fraction += (double)st.apex_fraction;
    }
    return PN_OK;
}

/* Ends an example's JSON line: the means over the steps of the force-error statistics when they
   were measured (--force-error, implicit), then the closing brace. */
PN_EX_UNUSED static void pn_ex_json_end(const pn_ex_tally *t, int measured) {
    if (measured && t->steps > 0)
        printf(", \"force_error\": %.4f, \"force_error_regularizer\": %.4f, \"apex_fraction\": %.3f",
               t->force_error / (double)t->steps, t->force_error_regularizer / (double)t->steps,
               t->apex_fraction / (double)t->steps);
    printf("}\n");
}

/* One frame of an example: the steps, then DIR/frame_NNNN.png and .ply when asked. Says what
   failed on stderr (prog: the program's name) and returns 0 then. */
PN_EX_UNUSED static int pn_ex_frame(const char *prog, pn_mpm_world *w, int implicit, double dt_s,
                                    const pn_mpm_implicit_desc *id, long steps, pn_ex_tally *t,
                                    const char *out, int frame, int png, int ply) {
    char path[1024];
    pn_result r = pn_ex_steps(w, implicit, dt_s, id, steps, t);
    if (r != PN_OK) {
        fprintf(stderr, "\n%s: step %ld failed at particle %lu: %s\n", prog, t->steps,
                (unsigned long)w->error_particle, pn_result_string(r));
        return 0;
    }
    snprintf(path, sizeof path, "%s/frame_%04d.png", out, frame);
    if (png && !pn_ex_render_png(path, w, 400)) {
        fprintf(stderr, "\n%s: cannot write %s (does the folder exist?)\n", prog, path);
        return 0;
    }
    snprintf(path, sizeof path, "%s/frame_%04d.ply", out, frame);
    if (ply && !pn_ex_write_ply(path, w)) {
        fprintf(stderr, "\n%s: cannot write %s (does the folder exist?)\n", prog, path);
        return 0;
    }
    return 1;
}

/* ---- the command line every example shares --------------------------------------------- */

static const char *const pn_ex_walls[] = {"sticky", "slip", "separate"};

typedef struct pn_ex_cli {
    int dim, implicit, frames, fps, res, png, ply, quiet, boundary;
    pn_mpm_implicit_desc solver; /* --fixed-point, --contact-rounds, --newton-tol, --cg-tol,
                                    --cg-forcing, --force-error                            */
    double dt, E, friction, filter;  /* filter < 0: the scene's default                  */
    double regularizer;          /* PlasticityNet's w (0: 1, < 0: off)                     */
    const char *energy, *out;    /* the energy's name as given; the example maps it        */
} pn_ex_cli;

/* defaults: 2D, implicit, pnet, dt 1e-3 s, 1 pass, 30 frames at 30 fps, the scene's res and
   E (0: the scene's default), separate walls with friction 0.5, frames into out */
PN_EX_UNUSED static void pn_ex_cli_default(pn_ex_cli *c, const char *out) {
    memset(c, 0, sizeof *c);
    c->dim = 2;
    c->implicit = 1;
    c->solver.fixed_point_iters = 1;
    c->solver.contact_rounds = 1;
    c->frames = c->fps = 30;
    c->boundary = PN_MPM_BOUNDARY_SEPARATE;
    c->dt = 1e-3;
    c->friction = 0.5;
    c->filter = -1;
    c->energy = "pnet";
    c->out = out;
}

/* If flag a (with its value v, NULL at the end) is a shared one, take it: returns how many
   arguments it used (1 or 2); 0 for a flag the example must handle, -1 for a missing value. */
PN_EX_UNUSED static int pn_ex_cli_flag(pn_ex_cli *c, const char *a, const char *v) {
    if (!strcmp(a, "--png")) return c->png = 1;
    if (!strcmp(a, "--ply")) return c->ply = 1;
    if (!strcmp(a, "--quiet")) return c->quiet = 1;
    if (!strcmp(a, "--force-error")) return c->solver.measure_force_error = 1;
    if (strncmp(a, "--", 2) || !strstr("|--dim|--integrator|--energy|--boundary|--friction|--filter|--regularizer|"
                                       "--dt|--fixed-point|--contact-rounds|--newton-tol|--cg-tol|--cg-forcing|"
                                       "--frames|--fps|--E|--res|--out|", a))
        return 0;
    if (!v) return -1;
    if (!strcmp(a, "--dim")) c->dim = atoi(v);
    else if (!strcmp(a, "--integrator")) c->implicit = !strcmp(v, "implicit") ? 1 : !strcmp(v, "explicit") ? 0 : -1;
    else if (!strcmp(a, "--energy")) c->energy = v;
    else if (!strcmp(a, "--boundary"))
        for (c->boundary = 0; c->boundary < 3 && strcmp(v, pn_ex_walls[c->boundary]); ++c->boundary) {}
    else if (!strcmp(a, "--friction")) c->friction = atof(v);
    else if (!strcmp(a, "--filter")) c->filter = atof(v);
    else if (!strcmp(a, "--regularizer")) c->regularizer = atof(v);
    else if (!strcmp(a, "--dt")) c->dt = atof(v);
    else if (!strcmp(a, "--fixed-point")) c->solver.fixed_point_iters = atoi(v);
    else if (!strcmp(a, "--contact-rounds")) c->solver.contact_rounds = atoi(v);
    else if (!strcmp(a, "--newton-tol")) c->solver.newton_tol = (pn_real)atof(v);
    else if (!strcmp(a, "--cg-tol")) c->solver.cg_rel_tol = (pn_real)atof(v);
    else if (!strcmp(a, "--cg-forcing")) c->solver.cg_forcing_max = (pn_real)atof(v);
    else if (!strcmp(a, "--frames")) c->frames = atoi(v);
    else if (!strcmp(a, "--fps")) c->fps = atoi(v);
    else if (!strcmp(a, "--E")) c->E = atof(v);
    else if (!strcmp(a, "--res")) c->res = atoi(v);
    else c->out = v;
    return 2;
}

/* The shared flags in range, and scene s (made with pn_ex_scene_default for c->dim) set
   from them. Returns 0 when a value is out of range. */
PN_EX_UNUSED static int pn_ex_cli_apply(const pn_ex_cli *c, pn_ex_scene *s) {
    if ((c->dim != 2 && c->dim != 3) || c->implicit < 0 || c->boundary > 2 || !(c->friction >= 0) ||
        !(c->dt > 0) || c->solver.fixed_point_iters < 1 || c->solver.contact_rounds < 1 || !(c->solver.newton_tol >= 0) ||
        !(c->solver.cg_rel_tol >= 0 && c->solver.cg_rel_tol < 1) || !(c->solver.cg_forcing_max >= 0 && c->solver.cg_forcing_max < 1) || c->frames < 1 ||
        c->fps < 1 || !(c->E >= 0) ||
        (c->res && (c->res < 16 || c->res > 1024)) || !(c->filter >= 0 || c->filter == -1))
        return 0;
    if (c->filter >= 0) s->filter_s = c->filter;
    s->regularizer = c->regularizer;
    if (c->res) s->res = c->res;
    if (c->E > 0) s->E_pa = c->E;
    s->boundary = (pn_mpm_boundary)c->boundary;
    s->friction = c->friction;
    return 1;
}

/* An example's whole run: frames of 1/fps s at dt_s (implicit steps with the settings id),
   the outputs of pn_ex_frame, a progress line on stderr unless quiet; *wall_s gets the wall
   seconds. Returns 0 after a failure (said on stderr). */
PN_EX_UNUSED static int pn_ex_run(const char *prog, pn_mpm_world *w, int implicit, double dt_s,
                                  const pn_mpm_implicit_desc *id, int frames, int fps, const char *out, int png,
                                  int ply, int quiet, pn_ex_tally *tally, double *wall_s) {
    long steps_per_frame = (long)(1.0 / fps / dt_s + 0.5);
    double t0 = pn_ex_seconds();
    int frame;
    memset(tally, 0, sizeof *tally);
    if (steps_per_frame < 1) steps_per_frame = 1;
    for (frame = 1; frame <= frames; ++frame) {
        if (!pn_ex_frame(prog, w, implicit, dt_s, id, steps_per_frame, tally, out, frame, png, ply)) return 0;
        *wall_s = pn_ex_seconds() - t0;
        if (!quiet)
            fprintf(stderr, "\rframe %d/%d  t = %.3f s  wall %.1f s  Newton/step %.1f  CG/step %.0f   ", frame, frames,
                    (double)w->time_s, *wall_s, (double)tally->newton / (double)tally->steps,
                    (double)tally->cg / (double)tally->steps);
    }
    if (!quiet) fprintf(stderr, "\n");
    return 1;
}

/* Bounding box of the active particles (lo, hi: dim values); 0 when none is active. */
PN_EX_UNUSED static int pn_ex_bounds(const pn_mpm_world *w, double *lo, double *hi) {
    size_t p;
    int i, any = 0;
    for (p = 0; p < w->n; ++p) {
        const pn_real *x = w->x + p * (size_t)w->dim;
        if (!w->active[p]) continue;
        for (i = 0; i < w->dim; ++i) {
            if (!any || x[i] < lo[i]) lo[i] = (double)x[i];
            if (!any || x[i] > hi[i]) hi[i] = (double)x[i];
        }
        any = 1;
    }
    return any;
}

/* An example's simulation: the scene's world, run as the command line says (pn_ex_run), with
   the particles' bounding box before and after. */
typedef struct pn_ex_outcome {
    pn_mpm_world *w;             /* the caller destroys it                                  */
    pn_ex_tally tally;
    double wall_s, lo0[3], hi0[3], lo[3], hi[3];
} pn_ex_outcome;

/* Returns 0 after a failure (said on stderr; nothing left to destroy). */
PN_EX_UNUSED static int pn_ex_simulate(const char *prog, const pn_ex_cli *c, const pn_ex_scene *sc,
                                       pn_ex_outcome *o) {
    const char *why = "";
    pn_result r;
    memset(o, 0, sizeof *o);
    if ((r = pn_ex_scene_create(sc, &o->w, &why)) != PN_OK) {
        fprintf(stderr, "%s: %s (%s)\n", prog, why, pn_result_string(r));
        return 0;
    }
    pn_ex_bounds(o->w, o->lo0, o->hi0);
    if (!pn_ex_run(prog, o->w, c->implicit, c->dt, &c->solver, c->frames, c->fps, c->out, c->png, c->ply, c->quiet,
                   &o->tally, &o->wall_s)) {
        pn_mpm_destroy(o->w);
        o->w = NULL;
        return 0;
    }
    pn_ex_bounds(o->w, o->lo, o->hi);
    return 1;
}

/* ---- mass IoU (PlasticityNet Fig. 5a-b; VALIDATION.md) -----------------------------------

   Each run's particle mass is spread onto the simulation grid's nodes with the quadratic
   B-spline weights of the MPM transfers (so the field is what the solver itself sees) and
   divided by its maximum, giving a and b in [0, 1]. Three scores per pair of fields:
   - soft: sum(a b) / sum(a + b - a b), the formula of VALIDATION.md. It is below 1 even for
     identical fields wherever a is fractional (edges, thin layers, a denser node setting the
     maximum): compare runs with the reference's score against itself, its ceiling.
   - minmax: sum(min(a, b)) / sum(max(a, b)) (weighted Jaccard): the same as soft on 0/1
     fields, exactly 1 for identical fields, so its deficit from 1 is all disagreement.
   - binary: |A & B| / |A | B| of the nodes above PN_EX_OCCUPIED of the maximum. */

#define PN_EX_OCCUPIED 0.1

/* Number of grid nodes, the length of a mass field. */
PN_EX_UNUSED static size_t pn_ex_field_size(const pn_mpm_world *w) {
    size_t n = 1;
    int i;
    for (i = 0; i < w->dim; ++i) n *= (size_t)(w->desc.res[i] + 1);
    return n;
}

/* The normalized mass field of the active particles (pn_ex_field_size values). */
PN_EX_UNUSED static void pn_ex_mass_field(const pn_mpm_world *w, double *field) {
    size_t nodes = pn_ex_field_size(w), p, k;
    int d = w->dim, i, a, b, c;
    double inv_dx = 1 / (double)w->desc.dx_m, mx = 0;
    memset(field, 0, sizeof(double) * nodes);
    for (p = 0; p < w->n; ++p) {
        double wt[3][3] = {{1, 0, 0}, {1, 0, 0}, {1, 0, 0}};
        int base[3] = {0, 0, 0}, nc = d == 3 ? 3 : 1;
        if (!w->active[p]) continue;
        for (i = 0; i < d; ++i) {
            double xc = (double)w->x[p * (size_t)d + (size_t)i] * inv_dx, f;
            base[i] = (int)floor(xc - 0.5);
            if (base[i] < 0) base[i] = 0; /* active particles stay a cell inside; be safe */
            if (base[i] > w->desc.res[i] - 2) base[i] = w->desc.res[i] - 2;
            f = xc - base[i];
            wt[i][0] = 0.5 * (1.5 - f) * (1.5 - f);
            wt[i][1] = 0.75 - (f - 1) * (f - 1);
            wt[i][2] = 0.5 * (f - 0.5) * (f - 0.5);
        }
        for (a = 0; a < 3; ++a)
            for (b = 0; b < 3; ++b)
                for (c = 0; c < nc; ++c) {
                    k = (size_t)(base[0] + a) * (size_t)(w->desc.res[1] + 1) + (size_t)(base[1] + b);
                    if (d == 3) k = k * (size_t)(w->desc.res[2] + 1) + (size_t)(base[2] + c);
                    field[k] += (double)w->mass[p] * wt[0][a] * wt[1][b] * wt[2][c];
                }
    }
    for (k = 0; k < nodes; ++k)
        if (field[k] > mx) mx = field[k];
    if (mx > 0)
        for (k = 0; k < nodes; ++k) field[k] /= mx;
}

typedef struct pn_ex_iou_scores {
    double soft, minmax, binary;
} pn_ex_iou_scores;

/* The three scores of two normalized fields of n nodes; two empty fields agree (1). */
PN_EX_UNUSED static pn_ex_iou_scores pn_ex_iou(const double *a, const double *b, size_t n) {
    double prod = 0, uni = 0, lo = 0, hi = 0;
    size_t k, bi = 0, bu = 0;
    pn_ex_iou_scores r;
    for (k = 0; k < n; ++k) {
        int oa = a[k] > PN_EX_OCCUPIED, ob = b[k] > PN_EX_OCCUPIED;
        prod += a[k] * b[k];
        uni += a[k] + b[k] - a[k] * b[k];
        lo += a[k] < b[k] ? a[k] : b[k];
        hi += a[k] < b[k] ? b[k] : a[k];
        bi += (size_t)(oa && ob);
        bu += (size_t)(oa || ob);
    }
    r.soft = uni > 0 ? prod / uni : 1.0;
    r.minmax = hi > 0 ? lo / hi : 1.0;
    r.binary = bu ? (double)bi / (double)bu : 1.0;
    return r;
}

#endif /* PN_EXAMPLE_H */
