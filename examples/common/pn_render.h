/* pn_render.h: pictures and meshes for the plastinet examples, with no dependency beyond libc
   and libm. It takes plain arrays (positions, one field value per particle), so FEM or ROM code
   can use it too. Include it after pn_example.h when both are used (that one must define
   _POSIX_C_SOURCE before the first system header). A 2D frame to a PNG in 10 lines:

       pn_render_desc d;
       unsigned char *rgb = malloc(960 * 540 * 3);
       memset(&d, 0, sizeof d);
       d.width = 960; d.height = 540; d.dim = 2;      // dim 3: also yaw_deg 30, pitch_deg 20
       d.hi[0] = d.hi[1] = 1;                         // world box [0, 1]^2 (m)
       d.radius_m = 0.6 * spacing;                    // splat radius
       d.has_floor = 1; d.floor_m = 0.05; d.time_s = t; d.scale_bar = 1;
       d.field_name = "speed (m/s)"; d.field_hi = 1;  // field: one speed per particle
       pn_render_particles(&d, n, x, speed, NULL, rgb);
       pn_png_write("frame.png", 960, 540, rgb);      // or pn_apng_add(anim, rgb)

   Contents
   - pn_png.h (included here): the PNG and animated PNG writers, with their own deflate.
   - pn_canvas: RGB + depth, anti-aliased rectangles, lines, discs and a 5x7 bitmap font.
   - pn_render_particles: 2D discs or 3D shaded spheres (depth buffer, shadow map, perspective
     orbit camera), floor, colliders, colour legend, time stamp, scale bar; 2x2 supersampled.
   - Iso-surfaces by marching tetrahedra (watertight, indexed), particle splatting, OBJ and
     binary PLY writers for Blender.
   Every function is static; there is no mutable global state. */
#ifndef PN_RENDER_H
#define PN_RENDER_H

#include "../../plastinet.h"
#include "pn_png.h"
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* each program uses only some of these functions */
#if defined(__GNUC__)
#define PN_RENDER_UNUSED __attribute__((unused))
#else
#define PN_RENDER_UNUSED
#endif

PN_RENDER_UNUSED static int pn_render__finite(double v) { return v == v && v <= DBL_MAX && v >= -DBL_MAX; }
PN_RENDER_UNUSED static double pn_render__clamp(double v, double lo, double hi) {
    return v < lo ? lo : v > hi ? hi : v;
}

/* =========================================================================================
   Canvas, drawing primitives and a bitmap font
   ========================================================================================= */

typedef struct pn_canvas {
    int w, h;
    unsigned char *rgb; /* w * h * 3, rows top to bottom                             */
    float *depth;       /* w * h, camera depth (m) of what is drawn; NULL: none         */
} pn_canvas;

/* Allocate a w x h canvas (black, depth at FLT_MAX); 1 on success. */
PN_RENDER_UNUSED static int pn_canvas_create(pn_canvas *c, int w, int h) {
    size_t n = (size_t)w * (size_t)h, i;
    memset(c, 0, sizeof *c);
    if (w <= 0 || h <= 0 || (double)w * (double)h > 1e9) return 0;
    c->rgb = (unsigned char *)calloc(n * 3, 1);
    c->depth = (float *)malloc(n * sizeof(float));
    if (!c->rgb || !c->depth) {
        free(c->rgb);
        free(c->depth);
        memset(c, 0, sizeof *c);
        return 0;
    }
    for (i = 0; i < n; ++i) c->depth[i] = FLT_MAX;
    c->w = w;
    c->h = h;
    return 1;
}

PN_RENDER_UNUSED static void pn_canvas_free(pn_canvas *c) {
    free(c->rgb);
    free(c->depth);
    memset(c, 0, sizeof *c);
}

PN_RENDER_UNUSED static void pn_canvas_fill(pn_canvas *c, int r, int g, int b) {
    size_t i, n = (size_t)c->w * (size_t)c->h;
    for (i = 0; i < n; ++i) {
        c->rgb[3 * i] = (unsigned char)r;
        c->rgb[3 * i + 1] = (unsigned char)g;
        c->rgb[3 * i + 2] = (unsigned char)b;
    }
}

/* blend colour (r, g, b) over pixel (x, y) with opacity a in [0, 1] */
PN_RENDER_UNUSED static void pn_canvas__blend(pn_canvas *c, int x, int y, int r, int g, int b, double a) {
    unsigned char *p;
    if (x < 0 || y < 0 || x >= c->w || y >= c->h || !(a > 0)) return;
    p = c->rgb + ((size_t)y * (size_t)c->w + (size_t)x) * 3;
    if (a >= 1) {
        p[0] = (unsigned char)r;
        p[1] = (unsigned char)g;
        p[2] = (unsigned char)b;
        return;
    }
    p[0] = (unsigned char)(p[0] + (r - p[0]) * a + 0.5);
    p[1] = (unsigned char)(p[1] + (g - p[1]) * a + 0.5);
    p[2] = (unsigned char)(p[2] + (b - p[2]) * a + 0.5);
}

/* Filled rectangle of pixels [x, x + w) x [y, y + h), opacity alpha (1: opaque). */
PN_RENDER_UNUSED static void pn_canvas_rect(pn_canvas *c, int x, int y, int w, int h, int r, int g, int b,
                                            double alpha) {
    int i, j, x0 = x < 0 ? 0 : x, y0 = y < 0 ? 0 : y;
    int x1 = x + w > c->w ? c->w : x + w, y1 = y + h > c->h ? c->h : y + h;
    for (j = y0; j < y1; ++j)
        for (i = x0; i < x1; ++i) pn_canvas__blend(c, i, j, r, g, b, alpha);
}

/* Anti-aliased disc centred at (cx, cy) (pixel centres are at +0.5). */
PN_RENDER_UNUSED static void pn_canvas_disc(pn_canvas *c, double cx, double cy, double radius, int r,
                                            int g, int b, double alpha) {
    int i, j, x0, x1, y0, y1;
    if (!pn_render__finite(cx) || !pn_render__finite(cy) || !(radius > 0) || radius > 1e6) return;
    x0 = (int)floor(cx - radius - 1), x1 = (int)ceil(cx + radius + 1);
    y0 = (int)floor(cy - radius - 1), y1 = (int)ceil(cy + radius + 1);
    if (x0 < 0) x0 = 0;
    if (y0 < 0) y0 = 0;
    if (x1 > c->w) x1 = c->w;
    if (y1 > c->h) y1 = c->h;
    for (j = y0; j < y1; ++j)
        for (i = x0; i < x1; ++i) {
            double dx = i + 0.5 - cx, dy = j + 0.5 - cy;
            double cov = pn_render__clamp(radius + 0.5 - sqrt(dx * dx + dy * dy), 0, 1);
            if (cov > 0) pn_canvas__blend(c, i, j, r, g, b, alpha * cov);
        }
}

/* Anti-aliased segment of the given width with round caps. With zbuf (the canvas depth) and
   camera depths z0, z1 of the ends, it is hidden where the depth buffer is nearer; the depth
   along the segment is interpolated in 1/z (perspective-correct). */
PN_RENDER_UNUSED static void pn_canvas__line(pn_canvas *c, double x0, double y0, double z0, double x1,
                                             double y1, double z1, double width, int r, int g, int b,
                                             double alpha, int depth_test) {
    double dx = x1 - x0, dy = y1 - y0, l2 = dx * dx + dy * dy, hw = 0.5 * width, pad = hw + 1;
    int steep = fabs(dy) > fabs(dx), u, v, u0, u1;
    if (!pn_render__finite(x0 + y0 + x1 + y1) || !(width > 0) || l2 > 1e14) return;
    u0 = (int)floor((steep ? (y0 < y1 ? y0 : y1) : (x0 < x1 ? x0 : x1)) - pad);
    u1 = (int)ceil((steep ? (y0 > y1 ? y0 : y1) : (x0 > x1 ? x0 : x1)) + pad);
    if (u0 < 0) u0 = 0;
    if (u1 > (steep ? c->h : c->w)) u1 = steep ? c->h : c->w;
    for (u = u0; u < u1; ++u) {
        /* the band of the minor axis the segment covers at this major coordinate */
        double du = steep ? dy : dx, dv = steep ? dx : dy, a0 = steep ? y0 : x0, b0 = steep ? x0 : y0;
        double t = du != 0 ? pn_render__clamp((u + 0.5 - a0) / du, 0, 1) : 0;
        double vc = b0 + t * dv, half = pad * (du != 0 ? sqrt(1 + (dv / du) * (dv / du)) : 1) + 1;
        int v0 = (int)floor(vc - half), v1 = (int)ceil(vc + half);
        if (du != 0 && fabs(dv / du) > 1) half = pad + 1;
        for (v = v0; v < v1; ++v) {
            int px = steep ? v : u, py = steep ? u : v;
            double qx = px + 0.5 - x0, qy = py + 0.5 - y0, s = l2 > 0 ? (qx * dx + qy * dy) / l2 : 0, ex, ey, cov;
            if (px < 0 || py < 0 || px >= c->w || py >= c->h) continue;
            s = pn_render__clamp(s, 0, 1);
            ex = qx - s * dx;
            ey = qy - s * dy;
            cov = pn_render__clamp(hw + 0.5 - sqrt(ex * ex + ey * ey), 0, 1);
            if (!(cov > 0)) continue;
            if (depth_test && c->depth) {
                double z = 1 / ((1 - s) / z0 + s / z1);
                if (z > c->depth[(size_t)py * (size_t)c->w + (size_t)px] * 1.0005) continue;
            }
            pn_canvas__blend(c, px, py, r, g, b, alpha * cov);
        }
    }
}

/* Anti-aliased line from (x0, y0) to (x1, y1), width in pixels, round caps. */
PN_RENDER_UNUSED static void pn_canvas_line(pn_canvas *c, double x0, double y0, double x1, double y1,
                                            double width, int r, int g, int b, double alpha) {
    pn_canvas__line(c, x0, y0, 1, x1, y1, 1, width, r, g, b, alpha, 0);
}

/* Filled triangle with corners (x_i, y_i) in pixels, opacity alpha: the pixels whose centres
   it covers, 4 x 4 samples per pixel for the edges' coverage. */
PN_RENDER_UNUSED static void pn_canvas_triangle(pn_canvas *c, const double *x, const double *y, int r, int g, int b,
                                                double alpha) {
    double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]), lo[2], hi[2];
    int px, py, k;
    if (!(area != 0) || !pn_render__finite(area)) return;
    lo[0] = hi[0] = x[0], lo[1] = hi[1] = y[0];
    for (k = 1; k < 3; ++k) {
        lo[0] = x[k] < lo[0] ? x[k] : lo[0], hi[0] = x[k] > hi[0] ? x[k] : hi[0];
        lo[1] = y[k] < lo[1] ? y[k] : lo[1], hi[1] = y[k] > hi[1] ? y[k] : hi[1];
    }
    if (lo[0] < 0) lo[0] = 0;
    if (lo[1] < 0) lo[1] = 0;
    if (hi[0] > c->w - 1) hi[0] = c->w - 1;
    if (hi[1] > c->h - 1) hi[1] = c->h - 1;
    for (py = (int)lo[1]; py <= (int)hi[1]; ++py)
        for (px = (int)lo[0]; px <= (int)hi[0]; ++px) {
            int in = 0, sx, sy;
            for (sy = 0; sy < 4; ++sy)
                for (sx = 0; sx < 4; ++sx) {
                    double qx = px + (sx + 0.5) / 4, qy = py + (sy + 0.5) / 4, w0, w1, w2;
                    w0 = ((x[1] - qx) * (y[2] - qy) - (x[2] - qx) * (y[1] - qy)) / area;
                    w1 = ((x[2] - qx) * (y[0] - qy) - (x[0] - qx) * (y[2] - qy)) / area;
                    w2 = 1 - w0 - w1;
                    in += w0 >= 0 && w1 >= 0 && w2 >= 0;
                }
            if (in) pn_canvas__blend(c, px, py, r, g, b, alpha * in / 16.0);
        }
}

/* The font: 5 columns by 9 rows (7 above the baseline, 2 for descenders), drawn for this
   file. '#' is ink. Glyphs are proportional (their inked columns plus one of space), except
   digits, which are all 5 wide so that numbers line up. 0xB0 is the degree sign (UTF-8 "\xc2\xb0"). */
typedef struct pn_canvas__glyph {
    unsigned char ch;
    const char *bits; /* up to 9 rows of 5; missing rows are blank */
} pn_canvas__glyph;

static const pn_canvas__glyph pn_canvas__font[] = {
    {'0', ".###." "#...#" "#..##" "#.#.#" "##..#" "#...#" ".###."},
    {'1', "..#.." ".##.." "..#.." "..#.." "..#.." "..#.." ".###."},
    {'2', ".###." "#...#" "....#" "...#." "..#.." ".#..." "#####"},
    {'3', ".###." "#...#" "....#" "..##." "....#" "#...#" ".###."},
    {'4', "...#." "..##." ".#.#." "#..#." "#####" "...#." "...#."},
    {'5', "#####" "#...." "####." "....#" "....#" "#...#" ".###."},
    {'6', "..##." ".#..." "#...." "####." "#...#" "#...#" ".###."},
    {'7', "#####" "....#" "...#." "..#.." ".#..." ".#..." ".#..."},
    {'8', ".###." "#...#" "#...#" ".###." "#...#" "#...#" ".###."},
    {'9', ".###." "#...#" "#...#" ".####" "....#" "...#." ".##.."},
    {'A', ".###." "#...#" "#...#" "#####" "#...#" "#...#" "#...#"},
    {'B', "####." "#...#" "#...#" "####." "#...#" "#...#" "####."},
    {'C', ".###." "#...#" "#...." "#...." "#...." "#...#" ".###."},
    {'D', "####." "#...#" "#...#" "#...#" "#...#" "#...#" "####."},
    {'E', "#####" "#...." "#...." "####." "#...." "#...." "#####"},
    {'F', "#####" "#...." "#...." "####." "#...." "#...." "#...."},
    {'G', ".###." "#...#" "#...." "#.###" "#...#" "#...#" ".####"},
    {'H', "#...#" "#...#" "#...#" "#####" "#...#" "#...#" "#...#"},
    {'I', "###.." ".#..." ".#..." ".#..." ".#..." ".#..." "###.."},
    {'J', "..###" "...#." "...#." "...#." "...#." "#..#." ".##.."},
    {'K', "#...#" "#..#." "#.#.." "##..." "#.#.." "#..#." "#...#"},
    {'L', "#...." "#...." "#...." "#...." "#...." "#...." "#####"},
    {'M', "#...#" "##.##" "#.#.#" "#.#.#" "#...#" "#...#" "#...#"},
    {'N', "#...#" "#...#" "##..#" "#.#.#" "#..##" "#...#" "#...#"},
    {'O', ".###." "#...#" "#...#" "#...#" "#...#" "#...#" ".###."},
    {'P', "####." "#...#" "#...#" "####." "#...." "#...." "#...."},
    {'Q', ".###." "#...#" "#...#" "#...#" "#.#.#" "#..#." ".##.#"},
    {'R', "####." "#...#" "#...#" "####." "#.#.." "#..#." "#...#"},
    {'S', ".####" "#...." "#...." ".###." "....#" "....#" "####."},
    {'T', "#####" "..#.." "..#.." "..#.." "..#.." "..#.." "..#.."},
    {'U', "#...#" "#...#" "#...#" "#...#" "#...#" "#...#" ".###."},
    {'V', "#...#" "#...#" "#...#" "#...#" "#...#" ".#.#." "..#.."},
    {'W', "#...#" "#...#" "#...#" "#.#.#" "#.#.#" "#.#.#" ".#.#."},
    {'X', "#...#" "#...#" ".#.#." "..#.." ".#.#." "#...#" "#...#"},
    {'Y', "#...#" "#...#" ".#.#." "..#.." "..#.." "..#.." "..#.."},
    {'Z', "#####" "....#" "...#." "..#.." ".#..." "#...." "#####"},
    {'a', "....." "....." ".###." "....#" ".####" "#...#" ".####"},
    {'b', "#...." "#...." "####." "#...#" "#...#" "#...#" "####."},
    {'c', "....." "....." ".###." "#...." "#...." "#...." ".###."},
    {'d', "....#" "....#" ".####" "#...#" "#...#" "#...#" ".####"},
    {'e', "....." "....." ".###." "#...#" "#####" "#...." ".###."},
    {'f', "..##." ".#..." "####." ".#..." ".#..." ".#..." ".#..."},
    {'g', "....." "....." ".####" "#...#" "#...#" "#...#" ".####" "....#" ".###."},
    {'h', "#...." "#...." "####." "#...#" "#...#" "#...#" "#...#"},
    {'i', ".#..." "....." "##..." ".#..." ".#..." ".#..." "###.."},
    {'j', "...#." "....." "..##." "...#." "...#." "...#." "...#." "#..#." ".##.."},
    {'k', "#...." "#...." "#..#." "#.#.." "##..." "#.#.." "#..#."},
    {'l', "##..." ".#..." ".#..." ".#..." ".#..." ".#..." "###.."},
    {'m', "....." "....." "##.#." "#.#.#" "#.#.#" "#.#.#" "#.#.#"},
    {'n', "....." "....." "####." "#...#" "#...#" "#...#" "#...#"},
    {'o', "....." "....." ".###." "#...#" "#...#" "#...#" ".###."},
    {'p', "....." "....." "####." "#...#" "#...#" "#...#" "####." "#...." "#...."},
    {'q', "....." "....." ".####" "#...#" "#...#" "#...#" ".####" "....#" "....#"},
    {'r', "....." "....." "#.##." "##..#" "#...." "#...." "#...."},
    {'s', "....." "....." ".####" "#...." ".###." "....#" "####."},
    {'t', ".#..." ".#..." "####." ".#..." ".#..." ".#..#" "..##."},
    {'u', "....." "....." "#...#" "#...#" "#...#" "#...#" ".####"},
    {'v', "....." "....." "#...#" "#...#" "#...#" ".#.#." "..#.."},
    {'w', "....." "....." "#...#" "#...#" "#.#.#" "#.#.#" ".#.#."},
    {'x', "....." "....." "#...#" ".#.#." "..#.." ".#.#." "#...#"},
    {'y', "....." "....." "#...#" "#...#" "#...#" "#...#" ".####" "....#" ".###."},
    {'z', "....." "....." "#####" "...#." "..#.." ".#..." "#####"},
    {'.', "....." "....." "....." "....." "....." "....." "#...."},
    {',', "....." "....." "....." "....." "....." ".#..." ".#..." "#...."},
    {':', "....." "....." "#...." "....." "....." "....." "#...."},
    {';', "....." "....." ".#..." "....." "....." "....." ".#..." "#...."},
    {'-', "....." "....." "....." "####." "....." "....." "....."},
    {'+', "....." "..#.." "..#.." "#####" "..#.." "..#.." "....."},
    {'=', "....." "....." "#####" "....." "#####" "....." "....."},
    {'/', "....#" "....#" "...#." "..#.." ".#..." "#...." "#...."},
    {'(', "..#.." ".#..." "#...." "#...." "#...." ".#..." "..#.."},
    {')', "#...." ".#..." "..#.." "..#.." "..#.." ".#..." "#...."},
    {'[', "###.." "#...." "#...." "#...." "#...." "#...." "###.."},
    {']', "###.." "..#.." "..#.." "..#.." "..#.." "..#.." "###.."},
    {'%', "##..#" "##..#" "...#." "..#.." ".#..." "#..##" "#..##"},
    {'_', "....." "....." "....." "....." "....." "....." "....." "#####"},
    {'^', "..#.." ".#.#." "#...#" "....." "....." "....." "....."},
    {'*', "....." "..#.." "#.#.#" ".###." "#.#.#" "..#.." "....."},
    {'!', "#...." "#...." "#...." "#...." "#...." "....." "#...."},
    {'?', ".###." "#...#" "....#" "...#." "..#.." "....." "..#.."},
    {'\'', "#...." "#...." "....."},
    {'<', "....." "...#." "..#.." ".#..." "..#.." "...#." "....."},
    {'>', "....." ".#..." "..#.." "...#." "..#.." ".#..." "....."},
    {0xB0, ".##.." "#..#." "#..#." ".##.." "....."},
};

/* glyph of byte ch (NULL: space); unknown bytes draw as '?' */
PN_RENDER_UNUSED static const pn_canvas__glyph *pn_canvas__find(unsigned char ch) {
    size_t i, n = sizeof pn_canvas__font / sizeof pn_canvas__font[0];
    if (ch == ' ') return NULL;
    for (i = 0; i < n; ++i)
        if (pn_canvas__font[i].ch == ch) return &pn_canvas__font[i];
    return pn_canvas__find('?');
}

PN_RENDER_UNUSED static int pn_canvas__ink(const pn_canvas__glyph *g, int col, int row) {
    size_t k = (size_t)row * 5 + (size_t)col;
    if (col < 0 || col > 4 || row < 0 || row > 8 || k >= strlen(g->bits)) return 0;
    return g->bits[k] == '#';
}

/* first inked column and width in font units (digits: 0 and 5) */
PN_RENDER_UNUSED static void pn_canvas__extent(const pn_canvas__glyph *g, int *c0, int *cw) {
    int lo = 5, hi = -1, col, row;
    if (g->ch >= '0' && g->ch <= '9') {
        *c0 = 0;
        *cw = 5;
        return;
    }
    for (col = 0; col < 5; ++col)
        for (row = 0; row < 9; ++row)
            if (pn_canvas__ink(g, col, row)) {
                if (col < lo) lo = col;
                if (col > hi) hi = col;
            }
    *c0 = hi < 0 ? 0 : lo;
    *cw = hi < 0 ? 3 : hi - lo + 1;
}

/* skip the UTF-8 lead byte of the degree sign */
PN_RENDER_UNUSED static int pn_canvas__skip(const unsigned char *s) { return s[0] == 0xC2 && s[1] == 0xB0; }

/* Width in pixels of the widest line of s at this scale (a line is 7 * scale tall above the
   baseline, 9 * scale with descenders; lines are 11 * scale apart). */
PN_RENDER_UNUSED static int pn_canvas_text_width(int scale, const char *s) {
    const unsigned char *p = (const unsigned char *)s;
    int wmax = 0, w = 0;
    if (!s || scale < 1) return 0;
    for (; *p; ++p) {
        const pn_canvas__glyph *g;
        int c0, cw;
        if (*p == '\n') {
            w = 0;
            continue;
        }
        if (pn_canvas__skip(p)) continue;
        g = pn_canvas__find(*p);
        if (g)
            pn_canvas__extent(g, &c0, &cw);
        else
            cw = 3;
        w += (w ? 1 : 0) + cw;
        if (w > wmax) wmax = w;
    }
    return wmax * scale;
}

/* Text with its top-left corner at (x, y). Scale 1 draws the bitmap as is; larger scales
   smooth it (the bitmap bilinearly interpolated and cut at one half, anti-aliased), which
   turns the staircases of diagonals into straight edges. '\n' starts a new line. */
PN_RENDER_UNUSED static void pn_canvas_text(pn_canvas *c, int x, int y, int scale, int r, int g, int b,
                                            const char *s) {
    const unsigned char *p = (const unsigned char *)s;
    int pen = x, line = y;
    if (!s || scale < 1) return;
    for (; *p; ++p) {
        const pn_canvas__glyph *gl;
        int c0, cw, i, j;
        if (*p == '\n') {
            pen = x;
            line += 11 * scale;
            continue;
        }
        if (pn_canvas__skip(p)) continue;
        gl = pn_canvas__find(*p);
        if (pen != x) pen += scale;
        if (!gl) {
            pen += 3 * scale;
            continue;
        }
        pn_canvas__extent(gl, &c0, &cw);
        if (scale == 1) {
            for (j = 0; j < 9; ++j)
                for (i = 0; i < cw; ++i)
                    if (pn_canvas__ink(gl, c0 + i, j)) pn_canvas__blend(c, pen + i, line + j, r, g, b, 1);
        } else {
            for (j = -scale; j < 9 * scale + scale; ++j)
                for (i = -scale; i < cw * scale + scale; ++i) {
                    double fx = (i + 0.5) / scale - 0.5, fy = (j + 0.5) / scale - 0.5;
                    int ix = (int)floor(fx), iy = (int)floor(fy);
                    double tx = fx - ix, ty = fy - iy, v, cov;
                    v = (1 - ty) * ((1 - tx) * pn_canvas__ink(gl, c0 + ix, iy) + tx * pn_canvas__ink(gl, c0 + ix + 1, iy)) +
                        ty * ((1 - tx) * pn_canvas__ink(gl, c0 + ix, iy + 1) + tx * pn_canvas__ink(gl, c0 + ix + 1, iy + 1));
                    /* cut a little below one half so diagonal joints keep their weight */
                    cov = pn_render__clamp((v - 0.42) * scale * 1.6 + 0.5, 0, 1);
                    if (cov > 0) pn_canvas__blend(c, pen + i, line + j, r, g, b, cov);
                }
        }
        pen += cw * scale;
    }
}

/* =========================================================================================
   Particle renderer
   ========================================================================================= */

typedef enum pn_render_shape_kind { PN_RENDER_HALF_SPACE = 0, PN_RENDER_BOX, PN_RENDER_SPHERE } pn_render_shape_kind;

/* A collider to draw. HALF_SPACE: the solid side {p : (p - center) . normal < 0} (normal
   need not be unit), drawn semi-transparent, clipped to the world box. BOX: axis-aligned,
   center +- half_extent. SPHERE: center, radius. Boxes and spheres are opaque grey in 3D,
   semi-transparent with an outline in 2D. 2D uses x and y only. */
typedef struct pn_render_shape {
    pn_render_shape_kind kind;
    double center[3], normal[3], half_extent[3], radius;
} pn_render_shape;

typedef struct pn_render_desc {
    int width, height;             /* pixels, e.g. 960 x 540                                  */
    int dim;                       /* 2 or 3                                                  */
    double lo[3], hi[3];           /* world box (m) to frame; the picture keeps aspect ratio  */
    double radius_m;               /* particle splat radius (m), e.g. 0.6 x particle spacing   */
    int has_floor;                 /* a ground at y = floor_m: a band in 2D, a slab with a     */
    double floor_m;                /*   grid and the particles' shadow in 3D                  */
    double yaw_deg, pitch_deg;     /* 3D camera orbit around the box centre; 0,0: front view   */
    const char *field_name;        /* colour legend title, e.g. "speed (m/s)"; NULL: no legend */
    double field_lo, field_hi;     /* the colour scale's range                                 */
    double time_s;                 /* time stamp "t = 0.500 s"; < 0: none                     */
    int scale_bar;                 /* nonzero: a scale bar with a round length ("10 cm")        */
    const char *title;             /* optional caption top-left, NULL: none                    */
    const pn_render_shape *shapes; /* colliders to draw, n_shapes of them                      */
    int n_shapes;
    const double *tri_xy;          /* 2D: solid triangles drawn over the particles (an FEM body),
                                      x0 y0 x1 y1 x2 y2 each, in tri_rgb with their edges      */
    size_t n_tris;
    unsigned char tri_rgb[3];
} pn_render_desc;

/* The colour map of the field, t in [0, 1]: sand beige at rest through ochre and brick red to
   violet and deep blue at 1, with lightness falling monotonically (it reads in greyscale too).
   NaN gives grey. */
PN_RENDER_UNUSED static void pn_render_colormap(double t, unsigned char rgb[3]) {
    static const unsigned char k[6][3] = {{226, 206, 164}, {225, 167, 104}, {206, 108, 78},
                                          {160, 62, 112},  {96, 52, 150},   {32, 48, 122}};
    double s;
    int i, c;
    if (t != t) {
        rgb[0] = rgb[1] = rgb[2] = 150;
        return;
    }
    s = pn_render__clamp(t, 0, 1) * 5;
    i = s >= 5 ? 4 : (int)s;
    s -= i;
    for (c = 0; c < 3; ++c) rgb[c] = (unsigned char)(k[i][c] + (k[i + 1][c] - k[i][c]) * s + 0.5);
}

/* camera: 2D sx = ox + k x, sy = oy - k y; 3D perspective from eye along -b (right r, up u),
   focal length f and centre (cx, cy) in supersampled pixels */
typedef struct pn_render__view {
    int dim;
    double k, ox, oy;
    double eye[3], r[3], u[3], b[3], f, cx, cy;
} pn_render__view;

PN_RENDER_UNUSED static double pn_render__dot(const double *a, const double *b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

PN_RENDER_UNUSED static void pn_render__normalize(double *a) {
    double l = sqrt(pn_render__dot(a, a));
    if (l > 0) a[0] /= l, a[1] /= l, a[2] /= l;
}

/* project p; 0 if behind the camera. *z: camera depth (3D), 0 in 2D */
PN_RENDER_UNUSED static int pn_render__proj(const pn_render__view *v, const double *p, double *sx, double *sy,
                                            double *z) {
    double q[3], zc;
    if (v->dim == 2) {
        *sx = v->ox + v->k * p[0];
        *sy = v->oy - v->k * p[1];
        *z = 0;
        return 1;
    }
    q[0] = p[0] - v->eye[0];
    q[1] = p[1] - v->eye[1];
    q[2] = p[2] - v->eye[2];
    zc = -pn_render__dot(q, v->b);
    if (!(zc > 1e-9)) return 0;
    *sx = v->cx + v->f * pn_render__dot(q, v->r) / zc;
    *sy = v->cy - v->f * pn_render__dot(q, v->u) / zc;
    *z = zc;
    return 1;
}

/* the ray through pixel point (sx, sy): eye + t dir with t = camera depth */
PN_RENDER_UNUSED static void pn_render__ray(const pn_render__view *v, double sx, double sy, double *dir) {
    double a = (sx - v->cx) / v->f, c = -(sy - v->cy) / v->f;
    int i;
    for (i = 0; i < 3; ++i) dir[i] = a * v->r[i] + c * v->u[i] - v->b[i];
}

/* ray against the box [lo, hi]: entry depth and the entry face (axis * 2 + (1 if the hi face)) */
PN_RENDER_UNUSED static int pn_render__ray_box(const double *o, const double *d, const double *lo,
                                               const double *hi, double *t, int *face) {
    double tn = -DBL_MAX, tf = DBL_MAX;
    int i, fn = 0;
    for (i = 0; i < 3; ++i) {
        if (d[i] == 0) {
            if (o[i] < lo[i] || o[i] > hi[i]) return 0;
            continue;
        } else {
            double a = (lo[i] - o[i]) / d[i], b = (hi[i] - o[i]) / d[i];
            int f = 2 * i + (a > b);
            if (a > b) {
                double s = a;
                a = b;
                b = s;
            }
            if (a > tn) tn = a, fn = f;
            if (b < tf) tf = b;
        }
    }
    if (tn > tf || tn <= 0) return 0;
    *t = tn;
    *face = fn;
    return 1;
}

/* light-space height map of the particles (an orthographic shadow map along the light) */
typedef struct pn_render__smap {
    int nu, nv;
    double u0, v0, cell;
    double lr[3], lu[3], ld[3]; /* light right, up, and direction towards the light */
    float *h;                   /* highest particle surface along ld per cell          */
} pn_render__smap;

/* fraction of the 3x3 cells around p that hold a surface above p (+ bias) towards the light */
PN_RENDER_UNUSED static double pn_render__shadow(const pn_render__smap *s, const double *p, double bias) {
    double u, v, hq, fu, fv, occ = 0, wsum = 0;
    int i, j, iu, iv;
    if (!s->h) return 0;
    u = (pn_render__dot(p, s->lr) - s->u0) / s->cell - 0.5;
    v = (pn_render__dot(p, s->lu) - s->v0) / s->cell - 0.5;
    hq = pn_render__dot(p, s->ld) + bias;
    if (!(u > -2 && v > -2 && u < s->nu + 1 && v < s->nv + 1)) return 0;
    iu = (int)floor(u);
    iv = (int)floor(v);
    fu = u - iu;
    fv = v - iv;
    /* a tent filter over 3x3 cells (a soft-edged percentage-closer filter) */
    for (j = -1; j <= 2; ++j)
        for (i = -1; i <= 2; ++i) {
            int a = iu + i, b = iv + j;
            double wx = i == -1 ? 1 - fu : i == 2 ? fu : 1, wy = j == -1 ? 1 - fv : j == 2 ? fv : 1;
            double wgt = wx * wy;
            wsum += wgt;
            if (a < 0 || b < 0 || a >= s->nu || b >= s->nv) continue;
            if (s->h[(size_t)b * (size_t)s->nu + (size_t)a] > hq) occ += wgt;
        }
    return occ / wsum;
}

/* Build the shadow map for light direction ld (unit, towards the light) over the box (down
   to y_bottom): every particle is a disc of radius rad across the light, at the height of its
   top towards the light. On allocation failure s->h stays NULL (no shadows). */
PN_RENDER_UNUSED static void pn_render__smap_build(pn_render__smap *sm, const double *ld, const double *lo,
                                                   const double *hi, double y_bottom, double rad, size_t n,
                                                   const pn_real *x, const unsigned char *mask) {
    double umin = DBL_MAX, umax = -DBL_MAX, wmin = DBL_MAX, wmax = -DBL_MAX, ref[3] = {0, 0, 1}, rc;
    size_t p;
    int corner, k;
    for (k = 0; k < 3; ++k) sm->ld[k] = ld[k];
    /* lr = ref x ld, lu = ld x lr */
    sm->lr[0] = ref[1] * ld[2] - ref[2] * ld[1];
    sm->lr[1] = ref[2] * ld[0] - ref[0] * ld[2];
    sm->lr[2] = ref[0] * ld[1] - ref[1] * ld[0];
    pn_render__normalize(sm->lr);
    sm->lu[0] = ld[1] * sm->lr[2] - ld[2] * sm->lr[1];
    sm->lu[1] = ld[2] * sm->lr[0] - ld[0] * sm->lr[2];
    sm->lu[2] = ld[0] * sm->lr[1] - ld[1] * sm->lr[0];
    for (corner = 0; corner < 8; ++corner) {
        double q[3], a, b;
        q[0] = corner & 1 ? hi[0] : lo[0];
        q[1] = corner & 2 ? hi[1] : y_bottom;
        q[2] = corner & 4 ? hi[2] : lo[2];
        a = pn_render__dot(q, sm->lr);
        b = pn_render__dot(q, sm->lu);
        if (a < umin) umin = a;
        if (a > umax) umax = a;
        if (b < wmin) wmin = b;
        if (b > wmax) wmax = b;
    }
    sm->cell = 0.7 * rad;
    if ((umax - umin) / sm->cell > 2048) sm->cell = (umax - umin) / 2048;
    if ((wmax - wmin) / sm->cell > 2048) sm->cell = (wmax - wmin) / 2048;
    sm->u0 = umin - 2 * rad;
    sm->v0 = wmin - 2 * rad;
    sm->nu = (int)ceil((umax - umin + 4 * rad) / sm->cell) + 1;
    sm->nv = (int)ceil((wmax - wmin + 4 * rad) / sm->cell) + 1;
    sm->h = (float *)malloc(sizeof(float) * (size_t)sm->nu * (size_t)sm->nv);
    if (!sm->h) return;
    for (p = 0; p < (size_t)sm->nu * (size_t)sm->nv; ++p) sm->h[p] = -FLT_MAX;
    rc = rad / sm->cell;
    for (p = 0; p < n; ++p) {
        double q[3], cu, cw, hh;
        int a0, a1, b0, b1, a, b;
        if (mask && !mask[p]) continue;
        for (k = 0; k < 3; ++k) q[k] = (double)x[p * 3 + (size_t)k];
        if (!pn_render__finite(q[0] + q[1] + q[2])) continue;
        cu = (pn_render__dot(q, sm->lr) - sm->u0) / sm->cell;
        cw = (pn_render__dot(q, sm->lu) - sm->v0) / sm->cell;
        hh = pn_render__dot(q, sm->ld);
        if (!(cu > 0 && cw > 0 && cu < sm->nu && cw < sm->nv)) continue;
        a0 = (int)floor(cu - rc), a1 = (int)ceil(cu + rc), b0 = (int)floor(cw - rc), b1 = (int)ceil(cw + rc);
        if (a0 < 0) a0 = 0;
        if (b0 < 0) b0 = 0;
        if (a1 >= sm->nu) a1 = sm->nu - 1;
        if (b1 >= sm->nv) b1 = sm->nv - 1;
        for (b = b0; b <= b1; ++b)
            for (a = a0; a <= a1; ++a) {
                double du = a + 0.5 - cu, dw = b + 0.5 - cw, e = rc * rc - du * du - dw * dw;
                float *hp = sm->h + (size_t)b * (size_t)sm->nu + (size_t)a;
                double top = hh + (e > 0 ? sqrt(e) * sm->cell : 0);
                if (e > -0.5 * rc && top > *hp) *hp = (float)top;
            }
    }
}

/* contact map: how much of the floor near a point is covered by particles resting on it
   (within 6 radii above it), blurred over a few radii; darkens the floor round a pile's foot */
typedef struct pn_render__contact_map {
    int nx, nz;
    double x0, z0, cell;
    float *occ;
} pn_render__contact_map;

PN_RENDER_UNUSED static void pn_render__contact_build(pn_render__contact_map *c, const double *lo, const double *hi,
                                                      double floor_m, double rad, size_t n, const pn_real *x,
                                                      const unsigned char *mask) {
    float *tmp;
    size_t p, N;
    int i, j, pass, r = 2;
    c->cell = 1.5 * rad;
    if ((hi[0] - lo[0]) / c->cell > 1024) c->cell = (hi[0] - lo[0]) / 1024;
    if ((hi[2] - lo[2]) / c->cell > 1024) c->cell = (hi[2] - lo[2]) / 1024;
    c->x0 = lo[0] - 8 * c->cell;
    c->z0 = lo[2] - 8 * c->cell;
    c->nx = (int)ceil((hi[0] - lo[0]) / c->cell) + 16;
    c->nz = (int)ceil((hi[2] - lo[2]) / c->cell) + 16;
    N = (size_t)c->nx * (size_t)c->nz;
    c->occ = (float *)calloc(N, sizeof(float));
    tmp = (float *)malloc(N * sizeof(float));
    if (!c->occ || !tmp) {
        free(c->occ);
        free(tmp);
        c->occ = NULL;
        return;
    }
    for (p = 0; p < n; ++p) {
        double px, py, pz, w;
        if (mask && !mask[p]) continue;
        px = (double)x[3 * p], py = (double)x[3 * p + 1], pz = (double)x[3 * p + 2];
        if (!pn_render__finite(px + py + pz)) continue;
        w = 1 - (py - floor_m - rad) / (6 * rad);
        if (!(w > 0)) continue;
        i = (int)floor((px - c->x0) / c->cell);
        j = (int)floor((pz - c->z0) / c->cell);
        if (i < 0 || j < 0 || i >= c->nx || j >= c->nz) continue;
        if (w > 1) w = 1;
        if (w > c->occ[(size_t)j * (size_t)c->nx + (size_t)i]) c->occ[(size_t)j * (size_t)c->nx + (size_t)i] = (float)w;
    }
    /* a separable box blur of radius r cells, twice: near-Gaussian */
    for (pass = 0; pass < 4; ++pass) {
        int horiz = !(pass & 1), len = horiz ? c->nx : c->nz, lines = horiz ? c->nz : c->nx;
        float *src = pass & 1 ? tmp : c->occ, *dst = pass & 1 ? c->occ : tmp;
        for (j = 0; j < lines; ++j)
            for (i = 0; i < len; ++i) {
                double sum = 0;
                int k;
                for (k = -r; k <= r; ++k) {
                    int m = i + k;
                    if (m < 0 || m >= len) continue;
                    sum += horiz ? src[(size_t)j * (size_t)c->nx + (size_t)m] : src[(size_t)m * (size_t)c->nx + (size_t)j];
                }
                if (horiz)
                    dst[(size_t)j * (size_t)c->nx + (size_t)i] = (float)(sum / (2 * r + 1));
                else
                    dst[(size_t)i * (size_t)c->nx + (size_t)j] = (float)(sum / (2 * r + 1));
            }
    }
    free(tmp);
}

PN_RENDER_UNUSED static double pn_render__contact(const pn_render__contact_map *c, const double *p) {
    int i, j;
    if (!c->occ) return 0;
    i = (int)floor((p[0] - c->x0) / c->cell);
    j = (int)floor((p[2] - c->z0) / c->cell);
    if (i < 0 || j < 0 || i >= c->nx || j >= c->nz) return 0;
    return pn_render__clamp(1.6 * c->occ[(size_t)j * (size_t)c->nx + (size_t)i], 0, 1);
}

/* screen bounding box (clamped to the canvas) of the box [lo, hi]; all of it if a corner is
   behind the camera */
PN_RENDER_UNUSED static void pn_render__screen_box(const pn_render__view *v, const double *lo, const double *hi,
                                                   int W, int H, int *x0, int *x1, int *y0, int *y1) {
    double sx0 = DBL_MAX, sx1 = -DBL_MAX, sy0 = DBL_MAX, sy1 = -DBL_MAX;
    int corner;
    for (corner = 0; corner < 8; ++corner) {
        double q[3], sx, sy, z;
        q[0] = corner & 1 ? hi[0] : lo[0];
        q[1] = corner & 2 ? hi[1] : lo[1];
        q[2] = corner & 4 ? hi[2] : lo[2];
        if (!pn_render__proj(v, q, &sx, &sy, &z)) {
            sx0 = sy0 = 0, sx1 = W, sy1 = H;
            break;
        }
        if (sx < sx0) sx0 = sx;
        if (sx > sx1) sx1 = sx;
        if (sy < sy0) sy0 = sy;
        if (sy > sy1) sy1 = sy;
    }
    *x0 = sx0 < 0 ? 0 : sx0 >= W ? W : (int)sx0;
    *y0 = sy0 < 0 ? 0 : sy0 >= H ? H : (int)sy0;
    *x1 = sx1 >= W - 1 ? W - 1 : sx1 < 0 ? -1 : (int)sx1 + 1;
    *y1 = sy1 >= H - 1 ? H - 1 : sy1 < 0 ? -1 : (int)sy1 + 1;
}

/* Indices of the drawable particles (then the others) ordered front to back by camera depth,
   by a counting sort into 4096 depth buckets over [zmin, zmax] (clamped): order only matters
   for speed. NULL when out of memory (then any order is drawn). */
PN_RENDER_UNUSED static size_t *pn_render__depth_order(const pn_render__view *v, size_t n, const pn_real *x,
                                                       const unsigned char *mask, double zmin, double zmax) {
    enum { NB = 4096 };
    size_t *order = (size_t *)malloc((n ? n : 1) * sizeof(size_t)), *start = (size_t *)calloc(NB + 1, sizeof(size_t));
    unsigned short *key = (unsigned short *)malloc((n ? n : 1) * sizeof(unsigned short));
    double scale = zmax > zmin ? (NB - 1) / (zmax - zmin) : 0;
    size_t p;
    int b;
    if (!order || !start || !key) {
        free(order);
        free(start);
        free(key);
        return NULL;
    }
    for (p = 0; p < n; ++p) {
        double q[3], z;
        int k;
        for (k = 0; k < 3; ++k) q[k] = (double)x[3 * p + (size_t)k] - v->eye[k];
        z = -pn_render__dot(q, v->b);
        b = NB - 1;
        if ((!mask || mask[p]) && z == z) b = (int)pn_render__clamp((z - zmin) * scale, 0, NB - 1);
        key[p] = (unsigned short)b;
        start[b + 1]++;
    }
    for (b = 0; b < NB; ++b) start[b + 1] += start[b];
    for (p = 0; p < n; ++p) order[start[key[p]]++] = p;
    free(start);
    free(key);
    return order;
}

PN_RENDER_UNUSED static void pn_render__bg(int y, int H, double *c) {
    double t = (double)y / (H > 1 ? H - 1 : 1);
    c[0] = 251 - 22 * t;
    c[1] = 252 - 19 * t;
    c[2] = 253 - 14 * t;
}

/* nice step (1, 2 or 5 times a power of ten) near range / n */
PN_RENDER_UNUSED static double pn_render__nice(double range, double n) {
    double raw = range / n, mag = pow(10, floor(log10(raw))), m = raw / mag;
    return (m < 1.5 ? 1 : m < 3.5 ? 2 : m < 7.5 ? 5 : 10) * mag;
}

/* the largest 1-2-5 length at most lmax */
PN_RENDER_UNUSED static double pn_render__nice_floor(double lmax) {
    double mag = pow(10, floor(log10(lmax))), m = lmax / mag;
    return (m >= 5 ? 5 : m >= 2 ? 2 : 1) * mag;
}

/* shade a surface point: base colour, camera-space normal n; lighting constants in L */
typedef struct pn_render__light {
    double l[3], hv[3], up[3]; /* light, half vector and world up, in camera coordinates */
} pn_render__light;

PN_RENDER_UNUSED static void pn_render__shade(const pn_render__light *L, const double *base, const double *n,
                                              double vis, double spec_k, double *out) {
    double lam = pn_render__dot(n, L->l), sp = pn_render__dot(n, L->hv), sky = pn_render__dot(n, L->up), amb, k;
    int c;
    if (lam < 0) lam = 0;
    sp = sp > 0 ? sp * sp : 0;
    sp *= sp;
    sp *= sp;
    sp *= sp; /* ^16 */
    /* sky ambient, a key light that shadows dim, and a weak fill from the camera so that
       faces turned from the key keep their shape */
    amb = 0.30 + 0.12 * sky;
    k = amb + 0.60 * lam * vis + 0.22 * (n[2] > 0 ? n[2] : 0);
    for (c = 0; c < 3; ++c) out[c] = base[c] * k + 255 * spec_k * sp * vis;
}

PN_RENDER_UNUSED static void pn_render__put(pn_canvas *c, size_t i, const double *col) {
    int k;
    for (k = 0; k < 3; ++k) c->rgb[3 * i + (size_t)k] = (unsigned char)pn_render__clamp(col[k] + 0.5, 0, 255);
}

/* overlay text with a one-pixel halo of the background colour there, legible over particles */
PN_RENDER_UNUSED static void pn_render__label(pn_canvas *c, int x, int y, int scale, int r, int g, int b,
                                              const char *s) {
    double bg[3];
    int dx, dy;
    pn_render__bg(y + 4 * scale, c->h, bg);
    for (dy = -1; dy <= 1; ++dy)
        for (dx = -1; dx <= 1; ++dx)
            if (dx || dy) pn_canvas_text(c, x + dx, y + dy, scale, (int)bg[0], (int)bg[1], (int)bg[2], s);
    pn_canvas_text(c, x, y, scale, r, g, b, s);
}

/* Render n particles (positions x, dim per particle; field: one value per particle, NULL: a
   uniform sand colour; mask: nonzero = draw, NULL: all) into rgb (width * height * 3, rows
   top to bottom). Particles with a non-finite position are skipped. 1 on success, 0 on bad
   arguments or out of memory. 2D looks along -z at the x-y plane (only x, y used); 3D orbits
   a perspective camera around the box centre, yaw about +y, pitch upwards (30, 20 frames a
   pile nicely), with a fixed light from the upper left that casts shadows. */
PN_RENDER_UNUSED static int pn_render_particles(const pn_render_desc *d, size_t n, const pn_real *x,
                                                const pn_real *field, const unsigned char *mask,
                                                unsigned char *rgb) {
    pn_canvas cv, out;
    pn_render__view v;
    pn_render__smap sm;
    pn_render__contact_map ct;
    pn_render__light L;
    int ss, W, H, dim, i, j, ui, legend_w, pad, k, sk, floor_ok;
    double lo[3], hi[3], vx0, vx1, vy0, vy1, flo = 0, fhi = 1, rad, zmin = DBL_MAX, zmax = 0;
    double slab_lo[3], slab_hi[3], lw[3];
    size_t p, op, *order;
    static const double sand[3] = {212, 184, 136};
    if (!d || !rgb || (n && !x) || (d->dim != 2 && d->dim != 3) || !pn_png_size_ok(d->width, d->height) ||
        !(d->radius_m > 0) || !pn_render__finite(d->radius_m) || d->n_shapes < 0 || (d->n_shapes && !d->shapes) ||
        (d->dim == 3 && !pn_render__finite(d->yaw_deg + d->pitch_deg)))
        return 0;
    dim = d->dim;
    for (i = 0; i < 3; ++i) {
        lo[i] = i < dim ? d->lo[i] : 0;
        hi[i] = i < dim ? d->hi[i] : 0;
        if (i < dim && !(hi[i] > lo[i] && pn_render__finite(hi[i] - lo[i]))) return 0;
    }
    /* 2x2 supersampling smooths every edge; big pictures render at 1x */
    ss = (double)d->width * d->height <= 4.2e6 ? 2 : 1;
    W = d->width * ss;
    H = d->height * ss;
    if (!pn_canvas_create(&cv, W, H)) return 0;
    memset(&sm, 0, sizeof sm);
    memset(&ct, 0, sizeof ct);
    memset(&v, 0, sizeof v);
    memset(&L, 0, sizeof L);
    v.dim = dim;
    ui = d->height >= 400 ? 2 : 1; /* overlay text scale */
    pad = 10 * ui;
    if (pad > d->width / 8) pad = d->width / 8;
    if (pad > d->height / 8) pad = d->height / 8;
    legend_w = d->field_name ? 74 * ui : 0;
    if (legend_w > d->width / 3) legend_w = 0; /* too narrow: the legend goes over the scene */
    floor_ok = d->has_floor && pn_render__finite(d->floor_m);
    vx0 = pad * ss;
    vx1 = (d->width - pad - legend_w) * ss;
    vy0 = pad * ss;
    vy1 = (d->height - pad) * ss;
    if (d->field_lo < d->field_hi && pn_render__finite(d->field_hi - d->field_lo)) {
        flo = d->field_lo;
        fhi = d->field_hi;
    } else if (pn_render__finite(d->field_lo)) {
        flo = d->field_lo;
        fhi = d->field_lo + 1;
    }
    rad = d->radius_m;
    /* the floor slab (3D): under the box, down to the box bottom, at least 3% of the box thick */
    for (i = 0; i < 3; ++i) {
        slab_lo[i] = lo[i];
        slab_hi[i] = hi[i];
    }
    if (floor_ok) {
        double ext = hi[1] - lo[1];
        slab_hi[1] = d->floor_m;
        slab_lo[1] = d->floor_m - 0.03 * ext < lo[1] ? d->floor_m - 0.03 * ext : lo[1];
    }
    if (dim == 2) {
        double kx = (vx1 - vx0) / (hi[0] - lo[0]), ky = (vy1 - vy0) / (hi[1] - lo[1]);
        v.k = kx < ky ? kx : ky;
        v.ox = 0.5 * (vx0 + vx1) - v.k * 0.5 * (lo[0] + hi[0]);
        v.oy = 0.5 * (vy0 + vy1) + v.k * 0.5 * (lo[1] + hi[1]);
    } else {
        double yaw = d->yaw_deg * 3.14159265358979 / 180, pit = d->pitch_deg * 3.14159265358979 / 180;
        double C[3], R = 0, amin = DBL_MAX, amax = -DBL_MAX, cmin = DBL_MAX, cmax = -DBL_MAX, lwn[3];
        int corner;
        v.b[0] = cos(pit) * sin(yaw), v.b[1] = sin(pit), v.b[2] = cos(pit) * cos(yaw);
        v.r[0] = cos(yaw), v.r[1] = 0, v.r[2] = -sin(yaw);
        v.u[0] = -sin(pit) * sin(yaw), v.u[1] = cos(pit), v.u[2] = -sin(pit) * cos(yaw);
        for (i = 0; i < 3; ++i) {
            C[i] = 0.5 * (lo[i] + hi[i]);
            R += 0.25 * (hi[i] - lo[i]) * (hi[i] - lo[i]);
        }
        R = sqrt(R);
        /* a 3.2 box-radii distance: mild perspective (about 36 degrees across the box) */
        for (i = 0; i < 3; ++i) v.eye[i] = C[i] + 3.2 * R * v.b[i];
        v.f = 1;
        v.cx = v.cy = 0;
        for (corner = 0; corner < 16; ++corner) { /* the box and the floor slab */
            const double *a = corner < 8 ? lo : slab_lo, *b = corner < 8 ? hi : slab_hi;
            double q[3], sx, sy, z;
            q[0] = corner & 1 ? b[0] : a[0];
            q[1] = corner & 2 ? b[1] : a[1];
            q[2] = corner & 4 ? b[2] : a[2];
            if (!pn_render__proj(&v, q, &sx, &sy, &z)) continue;
            if (sx < amin) amin = sx;
            if (sx > amax) amax = sx;
            if (sy < cmin) cmin = sy;
            if (sy > cmax) cmax = sy;
            if (z < zmin) zmin = z;
            if (z > zmax) zmax = z;
        }
        v.f = (vx1 - vx0) / (amax - amin) < (vy1 - vy0) / (cmax - cmin) ? (vx1 - vx0) / (amax - amin)
                                                                         : (vy1 - vy0) / (cmax - cmin);
        v.cx = 0.5 * (vx0 + vx1) - v.f * 0.5 * (amin + amax);
        v.cy = 0.5 * (vy0 + vy1) - v.f * 0.5 * (cmin + cmax);
        /* the light: from the upper left and a little in front, fixed in the world */
        lwn[0] = -0.6, lwn[1] = 0.75, lwn[2] = 0.45; /* about 43 degrees high */
        pn_render__normalize(lwn);
        for (i = 0; i < 3; ++i) lw[i] = lwn[i];
        L.l[0] = pn_render__dot(lw, v.r), L.l[1] = pn_render__dot(lw, v.u), L.l[2] = pn_render__dot(lw, v.b);
        L.hv[0] = L.l[0], L.hv[1] = L.l[1], L.hv[2] = L.l[2] + 1;
        pn_render__normalize(L.hv);
        L.up[0] = 0, L.up[1] = v.u[1], L.up[2] = v.b[1];
    }
    /* ---- background ---- */
    for (j = 0; j < H; ++j) {
        double c[3];
        unsigned char *row = cv.rgb + (size_t)j * (size_t)W * 3;
        pn_render__bg(j, H, c);
        pn_render__put(&cv, (size_t)j * (size_t)W, c);
        for (i = 1; i < W; ++i) memcpy(row + 3 * (size_t)i, row, 3);
    }
    if (dim == 2) {
        /* ---- 2D: the domain outline and the ground band ---- */
        double x0 = v.ox + v.k * lo[0], x1 = v.ox + v.k * hi[0], y0 = v.oy - v.k * lo[1], y1 = v.oy - v.k * hi[1];
        pn_canvas_line(&cv, x0, y0, x0, y1, 1.0 * ss, 196, 200, 208, 1);
        pn_canvas_line(&cv, x1, y0, x1, y1, 1.0 * ss, 196, 200, 208, 1);
        pn_canvas_line(&cv, x0, y1, x1, y1, 1.0 * ss, 196, 200, 208, 1);
        pn_canvas_line(&cv, x0, y0, x1, y0, 1.0 * ss, 196, 200, 208, 1);
        if (floor_ok) {
            double fy = v.oy - v.k * d->floor_m;
            int jf = (int)floor(fy);
            for (j = jf < 0 ? 0 : jf; j < H; ++j) {
                double c[3], tt = pn_render__clamp((j - fy) / (0.25 * H), 0, 1), cov = pn_render__clamp(j + 1 - fy, 0, 1);
                c[0] = 205 - 18 * tt, c[1] = 200 - 17 * tt, c[2] = 190 - 14 * tt;
                for (i = 0; i < W; ++i) {
                    size_t q = (size_t)j * (size_t)W + (size_t)i;
                    double e[3];
                    for (k = 0; k < 3; ++k) e[k] = cv.rgb[3 * q + (size_t)k] * (1 - cov) + c[k] * cov;
                    pn_render__put(&cv, q, e);
                }
            }
            pn_canvas_line(&cv, 0, fy, W, fy, 1.5 * ss, 150, 143, 130, 1);
        }
    } else {
        /* ---- 3D: shadow map, contact map ---- */
        pn_render__smap_build(&sm, lw, lo, hi, slab_lo[1], rad, n, x, mask);
        if (floor_ok)
            pn_render__contact_build(&ct, lo, hi, d->floor_m, rad, n, x, mask);
        /* ---- 3D: the floor slab, with a grid on top and the particles' shadow ---- */
        if (floor_ok) {
            double grid = pn_render__nice(hi[0] - lo[0] > hi[2] - lo[2] ? hi[0] - lo[0] : hi[2] - lo[2], 8);
            int bx0, bx1, by0, by1;
            pn_render__screen_box(&v, slab_lo, slab_hi, W, H, &bx0, &bx1, &by0, &by1);
            for (j = by0; j <= by1; ++j)
                for (i = bx0; i <= bx1; ++i) {
                    double dir[3], t, hit[3], base[3], nrm[3], nc[3], col[3], bg[3], vis = 1, fog;
                    int face;
                    size_t q = (size_t)j * (size_t)W + (size_t)i;
                    pn_render__ray(&v, i + 0.5, j + 0.5, dir);
                    if (!pn_render__ray_box(v.eye, dir, slab_lo, slab_hi, &t, &face)) continue;
                    for (k = 0; k < 3; ++k) {
                        hit[k] = v.eye[k] + t * dir[k];
                        nrm[k] = 0;
                    }
                    nrm[face / 2] = face & 1 ? 1 : -1;
                    base[0] = 232, base[1] = 232, base[2] = 236;
                    if (face == 3) { /* top: grid lines, anti-aliased by the pixel footprint */
                        double foot = t / v.f * 1.2, g = 0, ao;
                        for (k = 0; k < 3; k += 2) {
                            double fr = hit[k] / grid - floor(hit[k] / grid + 0.5), dist = fabs(fr) * grid;
                            double line = pn_render__clamp(1 - dist / foot, 0, 1);
                            if (line > g) g = line;
                        }
                        ao = pn_render__contact(&ct, hit);
                        for (k = 0; k < 3; ++k) base[k] = (base[k] - 24 * g) * (1 - 0.2 * ao);
                        vis = 1 - 0.8 * pn_render__shadow(&sm, hit, 0.3 * rad);
                    } else {
                        for (k = 0; k < 3; ++k) base[k] *= 0.97;
                    }
                    nc[0] = pn_render__dot(nrm, v.r), nc[1] = pn_render__dot(nrm, v.u), nc[2] = pn_render__dot(nrm, v.b);
                    pn_render__shade(&L, base, nc, vis, 0, col);
                    fog = 0.22 * pn_render__clamp((t - zmin) / (zmax - zmin), 0, 1);
                    pn_render__bg(j, H, bg);
                    for (k = 0; k < 3; ++k) col[k] = col[k] * (1 - fog) + bg[k] * fog;
                    pn_render__put(&cv, q, col);
                    cv.depth[q] = (float)t;
                }
        }
        /* ---- 3D: the box edges behind the scene (those on a face turned away) ---- */
        for (k = 0; k < 12; ++k) {
            int axis = k / 4, o1 = (axis + 1) % 3, o2 = (axis + 2) % 3, s1 = k & 1, s2 = (k >> 1) & 1;
            double a[3], b[3], sa[3], sb[3], toward1, toward2;
            a[axis] = lo[axis], b[axis] = hi[axis];
            a[o1] = b[o1] = s1 ? hi[o1] : lo[o1];
            a[o2] = b[o2] = s2 ? hi[o2] : lo[o2];
            /* the two faces of this edge are turned away when the eye is on their inner side */
            toward1 = s1 ? v.eye[o1] - hi[o1] : lo[o1] - v.eye[o1];
            toward2 = s2 ? v.eye[o2] - hi[o2] : lo[o2] - v.eye[o2];
            if (toward1 > 0 && toward2 > 0) continue;
            if (!pn_render__proj(&v, a, &sa[0], &sa[1], &sa[2]) || !pn_render__proj(&v, b, &sb[0], &sb[1], &sb[2]))
                continue;
            pn_canvas__line(&cv, sa[0], sa[1], sa[2], sb[0], sb[1], sb[2], 1.1 * ss, 170, 176, 188, 1, 1);
        }
    }
    /* ---- opaque colliders (3D) ---- */
    if (dim == 3)
        for (sk = 0; sk < d->n_shapes; ++sk) {
            const pn_render_shape *sh = &d->shapes[sk];
            double blo[3], bhi[3];
            int x0, x1, y0, y1;
            if (sh->kind == PN_RENDER_HALF_SPACE) continue;
            for (i = 0; i < 3; ++i) {
                double e = sh->kind == PN_RENDER_BOX ? fabs(sh->half_extent[i]) : fabs(sh->radius);
                blo[i] = sh->center[i] - e;
                bhi[i] = sh->center[i] + e;
            }
            if (!pn_render__finite(blo[0] + blo[1] + blo[2] + bhi[0] + bhi[1] + bhi[2])) continue;
            pn_render__screen_box(&v, blo, bhi, W, H, &x0, &x1, &y0, &y1);
            for (j = y0; j <= y1; ++j)
                for (i = x0; i <= x1; ++i) {
                    double dir[3], t = 0, nrm[3] = {0, 0, 0}, nc[3], col[3], base[3] = {168, 176, 190};
                    size_t q = (size_t)j * (size_t)W + (size_t)i;
                    int face;
                    pn_render__ray(&v, i + 0.5, j + 0.5, dir);
                    if (sh->kind == PN_RENDER_BOX) {
                        if (!pn_render__ray_box(v.eye, dir, blo, bhi, &t, &face)) continue;
                        nrm[face / 2] = face & 1 ? 1 : -1;
                    } else {
                        double oc[3], a, b, c, disc;
                        for (k = 0; k < 3; ++k) oc[k] = v.eye[k] - sh->center[k];
                        a = pn_render__dot(dir, dir);
                        b = pn_render__dot(oc, dir);
                        c = pn_render__dot(oc, oc) - sh->radius * sh->radius;
                        disc = b * b - a * c;
                        if (disc < 0) continue;
                        t = (-b - sqrt(disc)) / a;
                        if (t <= 0) continue;
                        for (k = 0; k < 3; ++k) nrm[k] = oc[k] + t * dir[k];
                        pn_render__normalize(nrm);
                    }
                    if (t >= cv.depth[q]) continue;
                    nc[0] = pn_render__dot(nrm, v.r), nc[1] = pn_render__dot(nrm, v.u), nc[2] = pn_render__dot(nrm, v.b);
                    pn_render__shade(&L, base, nc, 1, 0.25, col);
                    pn_render__put(&cv, q, col);
                    cv.depth[q] = (float)t;
                }
        }
    /* ---- particles (3D: front to back, so hidden ones fail the depth test early) ---- */
    order = dim == 3 ? pn_render__depth_order(&v, n, x, mask, zmin, zmax) : NULL;
    /* 2D draws every disc twice: first 25% larger, flat and darker, behind everything (the
       holes of a packing fill with material colour, a lone grain gets a rim), then shaded */
    for (op = 0; op < (dim == 2 ? 2 * n : n); ++op) {
        double q[3] = {0, 0, 0}, sx, sy, z, R, base[3], rr2, pz;
        int x0, x1, y0, y1, under = dim == 2 && op < n;
        p = order ? order[op] : op % (n ? n : 1);
        if (mask && !mask[p]) continue;
        for (k = 0; k < dim; ++k) q[k] = (double)x[p * (size_t)dim + (size_t)k];
        if (!pn_render__finite(q[0] + q[1] + q[2]) || !pn_render__proj(&v, q, &sx, &sy, &z)) continue;
        R = rad * (dim == 2 ? v.k : v.f / z);
        if (R < 1.5 * ss) R = 1.5 * ss;
        if (sx + R < 0 || sy + R < 0 || sx - R > W || sy - R > H || R > 0.5 * (W + H)) continue;
        if (field) {
            unsigned char cm[3];
            double fv = (double)field[p];
            if (fv == fv)
                pn_render_colormap((fv - flo) / (fhi - flo), cm);
            else
                pn_render_colormap(fv, cm);
            for (k = 0; k < 3; ++k) base[k] = cm[k];
        } else {
            for (k = 0; k < 3; ++k) base[k] = sand[k];
        }
        if (under) R *= 1.25;
        x0 = (int)floor(sx - R), x1 = (int)ceil(sx + R), y0 = (int)floor(sy - R), y1 = (int)ceil(sy + R);
        if (x0 < 0) x0 = 0;
        if (y0 < 0) y0 = 0;
        if (x1 > W) x1 = W;
        if (y1 > H) y1 = H;
        rr2 = 1 / (R * R);
        if (under) {
            for (k = 0; k < 3; ++k) base[k] *= 0.76;
            for (j = y0; j < y1; ++j)
                for (i = x0; i < x1; ++i) {
                    double dx = i + 0.5 - sx, dy = j + 0.5 - sy;
                    size_t qi = (size_t)j * (size_t)W + (size_t)i;
                    if ((dx * dx + dy * dy) * rr2 >= 1 || cv.depth[qi] <= 1) continue;
                    cv.depth[qi] = 1;
                    pn_render__put(&cv, qi, base);
                }
        } else if (dim == 2) {
            for (j = y0; j < y1; ++j)
                for (i = x0; i < x1; ++i) {
                    double dx = i + 0.5 - sx, dy = j + 0.5 - sy, e = (dx * dx + dy * dy) * rr2, nz, col[3], sh;
                    size_t qi = (size_t)j * (size_t)W + (size_t)i;
                    if (e >= 1) continue;
                    nz = sqrt(1 - e);
                    pz = -nz * rad;
                    if (pz >= cv.depth[qi]) continue;
                    cv.depth[qi] = (float)pz;
                    /* flat, with a soft rim and a faint highlight towards the upper left, so
                       touching discs read as one granular material */
                    sh = 0.80 + 0.20 * nz + 0.10 * (-dx - dy) / R * 0.7071 * (1 - nz);
                    for (k = 0; k < 3; ++k) col[k] = base[k] * sh;
                    pn_render__put(&cv, qi, col);
                }
        } else {
            double vis, top[3], fog;
            for (k = 0; k < 3; ++k) top[k] = q[k] + rad * lw[k];
            vis = 1 - 0.8 * pn_render__shadow(&sm, top, 1.2 * rad);
            fog = 0.22 * pn_render__clamp((z - zmin) / (zmax - zmin), 0, 1);
            for (j = y0; j < y1; ++j)
                for (i = x0; i < x1; ++i) {
                    double dx = i + 0.5 - sx, dy = j + 0.5 - sy, e = (dx * dx + dy * dy) * rr2, nrm[3], col[3], bg[3];
                    size_t qi = (size_t)j * (size_t)W + (size_t)i;
                    if (e >= 1) continue;
                    if (z - rad >= cv.depth[qi]) continue; /* even its nearest point is hidden */
                    nrm[2] = sqrt(1 - e);
                    pz = z - nrm[2] * rad;
                    if (pz >= cv.depth[qi]) continue;
                    cv.depth[qi] = (float)pz;
                    nrm[0] = dx / R;
                    nrm[1] = -dy / R;
                    pn_render__shade(&L, base, nrm, vis, 0.18, col);
                    pn_render__bg(j, H, bg);
                    for (k = 0; k < 3; ++k) col[k] = col[k] * (1 - fog) + bg[k] * fog;
                    pn_render__put(&cv, qi, col);
                }
        }
    }
    /* ---- transparent colliders: half-spaces (both), boxes and spheres in 2D ---- */
    for (k = 0; k < d->n_shapes; ++k) {
        const pn_render_shape *sh = &d->shapes[k];
        double nn[3];
        for (i = 0; i < 3; ++i) nn[i] = i < dim ? sh->normal[i] : 0;
        if (dim == 3 && sh->kind != PN_RENDER_HALF_SPACE) continue;
        if (dim == 2) {
            double cx = v.ox + v.k * sh->center[0], cy = v.oy - v.k * sh->center[1];
            if (sh->kind == PN_RENDER_SPHERE) {
                pn_canvas_disc(&cv, cx, cy, v.k * fabs(sh->radius), 150, 158, 172, 0.55);
                pn_canvas_disc(&cv, cx, cy, v.k * fabs(sh->radius) - 0.7 * ss, 188, 194, 204, 0.6);
            } else if (sh->kind == PN_RENDER_BOX) {
                double hx = v.k * fabs(sh->half_extent[0]), hy = v.k * fabs(sh->half_extent[1]);
                if (!pn_render__finite(cx + cy + hx + hy) || hx > 4 * W || hy > 4 * H) continue;
                pn_canvas_rect(&cv, (int)floor(cx - hx + 0.5), (int)floor(cy - hy + 0.5), (int)floor(2 * hx + 0.5),
                               (int)floor(2 * hy + 0.5), 160, 168, 182, 0.55);
                pn_canvas_line(&cv, cx - hx, cy - hy, cx + hx, cy - hy, 1.2 * ss, 110, 118, 132, 1);
                pn_canvas_line(&cv, cx + hx, cy - hy, cx + hx, cy + hy, 1.2 * ss, 110, 118, 132, 1);
                pn_canvas_line(&cv, cx + hx, cy + hy, cx - hx, cy + hy, 1.2 * ss, 110, 118, 132, 1);
                pn_canvas_line(&cv, cx - hx, cy + hy, cx - hx, cy - hy, 1.2 * ss, 110, 118, 132, 1);
            } else {
                /* the solid side inside the framed box, per pixel */
                double nl = sqrt(nn[0] * nn[0] + nn[1] * nn[1]);
                if (!(nl > 0) || !pn_render__finite(nl)) continue;
                for (j = 0; j < H; ++j)
                    for (i = 0; i < W; ++i) {
                        double wx = (i + 0.5 - v.ox) / v.k, wy = (v.oy - j - 0.5) / v.k;
                        double sd = ((wx - sh->center[0]) * nn[0] + (wy - sh->center[1]) * nn[1]) / nl * v.k;
                        double a;
                        if (wx < lo[0] || wx > hi[0] || wy < lo[1] || wy > hi[1]) continue;
                        /* fill, plus a darker anti-aliased edge line */
                        a = 0.35 * pn_render__clamp(0.5 - sd, 0, 1);
                        if (a > 0) pn_canvas__blend(&cv, i, j, 150, 158, 172, a);
                        a = pn_render__clamp(1.2 * ss - fabs(sd), 0, 1);
                        if (a > 0) pn_canvas__blend(&cv, i, j, 100, 108, 122, a);
                    }
            }
        } else {
            /* 3D half-space: its boundary plane inside the box, semi-transparent */
            double nl = sqrt(pn_render__dot(nn, nn));
            if (!(nl > 0) || !pn_render__finite(nl)) continue;
            for (j = 0; j < H; ++j)
                for (i = 0; i < W; ++i) {
                    double dir[3], den, t, hit[3], nc[3], col[3], base[3] = {160, 168, 182};
                    size_t q = (size_t)j * (size_t)W + (size_t)i;
                    int inside = 1, c;
                    pn_render__ray(&v, i + 0.5, j + 0.5, dir);
                    den = pn_render__dot(dir, nn);
                    if (den == 0) continue;
                    t = ((sh->center[0] - v.eye[0]) * nn[0] + (sh->center[1] - v.eye[1]) * nn[1] +
                         (sh->center[2] - v.eye[2]) * nn[2]) / den;
                    if (!(t > 0) || t >= cv.depth[q]) continue;
                    for (c = 0; c < 3; ++c) {
                        hit[c] = v.eye[c] + t * dir[c];
                        if (hit[c] < lo[c] || hit[c] > hi[c]) inside = 0;
                    }
                    if (!inside) continue;
                    for (c = 0; c < 3; ++c) nc[c] = nn[c] / nl;
                    {
                        double cn[3];
                        cn[0] = pn_render__dot(nc, v.r), cn[1] = pn_render__dot(nc, v.u), cn[2] = pn_render__dot(nc, v.b);
                        if (cn[2] < 0) cn[0] = -cn[0], cn[1] = -cn[1], cn[2] = -cn[2];
                        pn_render__shade(&L, base, cn, 1, 0, col);
                    }
                    for (c = 0; c < 3; ++c) cv.rgb[3 * q + (size_t)c] = (unsigned char)pn_render__clamp(
                                                 cv.rgb[3 * q + (size_t)c] * 0.7 + col[c] * 0.3 + 0.5, 0, 255);
                }
        }
    }
    /* ---- 2D: solid triangles (a body's mesh), then their edges ---- */
    for (p = 0; dim == 2 && d->tri_xy && p < d->n_tris; ++p) {
        const double *t = d->tri_xy + 6 * p;
        double tx[3], ty[3];
        for (k = 0; k < 3; ++k) tx[k] = v.ox + v.k * t[2 * k], ty[k] = v.oy - v.k * t[2 * k + 1];
        if (!pn_render__finite(tx[0] + tx[1] + tx[2] + ty[0] + ty[1] + ty[2])) continue;
        pn_canvas_triangle(&cv, tx, ty, d->tri_rgb[0], d->tri_rgb[1], d->tri_rgb[2], 1);
    }
    for (p = 0; dim == 2 && d->tri_xy && p < d->n_tris; ++p) {
        const double *t = d->tri_xy + 6 * p;
        for (k = 0; k < 3; ++k) {
            int e = (k + 1) % 3;
            double xa = v.ox + v.k * t[2 * k], ya = v.oy - v.k * t[2 * k + 1], xb = v.ox + v.k * t[2 * e], yb = v.oy - v.k * t[2 * e + 1];
            if (pn_render__finite(xa + ya + xb + yb))
                pn_canvas_line(&cv, xa, ya, xb, yb, 0.6 * ss, d->tri_rgb[0] * 3 / 4, d->tri_rgb[1] * 3 / 4, d->tri_rgb[2] * 3 / 4, 0.6);
        }
    }
    /* ---- down-sample into rgb ---- */
    for (j = 0; j < d->height; ++j)
        for (i = 0; i < d->width; ++i) {
            size_t o = ((size_t)j * (size_t)d->width + (size_t)i) * 3;
            int a, b;
            for (k = 0; k < 3; ++k) {
                unsigned s = 0;
                for (b = 0; b < ss; ++b)
                    for (a = 0; a < ss; ++a)
                        s += cv.rgb[(((size_t)j * ss + (size_t)b) * (size_t)W + (size_t)i * ss + (size_t)a) * 3 + (size_t)k];
                rgb[o + (size_t)k] = (unsigned char)((s + (unsigned)(ss * ss) / 2) / (unsigned)(ss * ss));
            }
        }
    free(order);
    free(sm.h);
    free(ct.occ);
    pn_canvas_free(&cv);
    /* ---- overlays at the final resolution ---- */
    out.w = d->width;
    out.h = d->height;
    out.rgb = rgb;
    out.depth = NULL;
    {
        int ty = pad;
        if (d->title) {
            pn_render__label(&out, pad, ty, ui, 40, 44, 54, d->title);
            ty += 12 * ui;
        }
        if (d->time_s >= 0 && pn_render__finite(d->time_s)) {
            char s[64];
            snprintf(s, sizeof s, "t = %.3f s", d->time_s);
            pn_render__label(&out, pad, ty, ui, 70, 76, 88, s);
        }
    }
    if (d->scale_bar) {
        double ppm = dim == 2 ? v.k / ss : 0, len, px;
        if (dim == 3) { /* at the depth of the box centre */
            double C[3], sx, sy, z;
            for (k = 0; k < 3; ++k) C[k] = 0.5 * (lo[k] + hi[k]);
            if (pn_render__proj(&v, C, &sx, &sy, &z)) ppm = v.f / z / ss;
        }
        if (ppm > 0 && pn_render__finite(ppm)) {
            char s[32];
            int bx = pad + 2 * ui, by = d->height - pad - 2 * ui;
            len = pn_render__nice_floor(0.16 * d->width / ppm);
            px = len * ppm;
            if (len >= 1)
                snprintf(s, sizeof s, "%g m", len);
            else if (len >= 0.01)
                snprintf(s, sizeof s, "%g cm", floor(len * 100 + 0.5));
            else
                snprintf(s, sizeof s, "%g mm", floor(len * 1e4 + 0.5) / 10);
            pn_canvas_rect(&out, bx, by - 2 * ui, (int)(px + 0.5), 2 * ui, 45, 50, 60, 1);
            pn_canvas_rect(&out, bx, by - 5 * ui, ui, 5 * ui, 45, 50, 60, 1);
            pn_canvas_rect(&out, bx + (int)(px + 0.5) - ui, by - 5 * ui, ui, 5 * ui, 45, 50, 60, 1);
            pn_render__label(&out, bx + (int)(px / 2) - pn_canvas_text_width(ui, s) / 2, by - 16 * ui, ui, 45, 50, 60, s);
        }
    }
    if (d->field_name) {
        int bw = 9 * ui, bh = (int)(0.42 * d->height), bx = d->width - 74 * ui + 6 * ui, by = (d->height - bh) / 2;
        int tw = pn_canvas_text_width(ui, d->field_name), tx = bx;
        double step = pn_render__nice(fhi - flo, 5), tv;
        int dec = step >= 1 ? 0 : (int)ceil(-log10(step) - 1e-9);
        int nt = 0;
        if (tx + tw > d->width - pad) tx = d->width - pad - tw;
        /* a veil of background behind the legend, for particles that stray under it */
        for (j = by - 19 * ui; j < by + bh + 6 * ui; ++j) {
            double bg[3];
            pn_render__bg(j, d->height, bg);
            pn_canvas_rect(&out, tx - 5 * ui, j, d->width - tx + 5 * ui, 1, (int)bg[0], (int)bg[1], (int)bg[2], 0.8);
        }
        pn_canvas_text(&out, tx, by - 15 * ui, ui, 40, 44, 54, d->field_name);
        for (j = 0; j < bh; ++j) {
            unsigned char cm[3];
            pn_render_colormap(1 - (double)j / (bh > 1 ? bh - 1 : 1), cm);
            pn_canvas_rect(&out, bx, by + j, bw, 1, cm[0], cm[1], cm[2], 1);
        }
        pn_canvas_rect(&out, bx - 1, by - 1, bw + 2, 1, 120, 124, 134, 1);
        pn_canvas_rect(&out, bx - 1, by + bh, bw + 2, 1, 120, 124, 134, 1);
        pn_canvas_rect(&out, bx - 1, by, 1, bh, 120, 124, 134, 1);
        pn_canvas_rect(&out, bx + bw, by, 1, bh, 120, 124, 134, 1);
        if (dec > 6) dec = 6;
        for (tv = ceil(flo / step - 1e-9) * step; tv <= fhi + 1e-9 * step && nt < 50; tv += step, ++nt) {
            char s[48];
            int ty = by + (int)floor((1 - (tv - flo) / (fhi - flo)) * (bh - 1) + 0.5);
            snprintf(s, sizeof s, "%.*f", dec, fabs(tv) < 1e-9 * step ? 0.0 : tv);
            pn_canvas_rect(&out, bx + bw, ty - ui / 2, 4 * ui, ui, 120, 124, 134, 1);
            pn_canvas_text(&out, bx + bw + 7 * ui, ty - (7 * ui) / 2, ui, 60, 64, 74, s);
        }
    }
    return 1;
}

/* =========================================================================================
   Iso-surfaces (marching tetrahedra) and mesh files
   ========================================================================================= */

/* v: 3 floats per vertex; t: 3 vertex indices per triangle, counter-clockwise seen from outside */
typedef struct pn_mesh {
    size_t nv, nt;
    float *v;
    unsigned *t;
} pn_mesh;

PN_RENDER_UNUSED static void pn_mesh_free(pn_mesh *m) {
    if (!m) return;
    free(m->v);
    free(m->t);
    memset(m, 0, sizeof *m);
}

typedef struct pn_iso__b {
    pn_mesh *m;
    size_t capv, capt;
    int fail;
} pn_iso__b;

PN_RENDER_UNUSED static long pn_iso__vertex(pn_iso__b *b, double x, double y, double z) {
    pn_mesh *m = b->m;
    if (b->fail) return -1;
    if (m->nv == b->capv) {
        size_t c = b->capv ? 2 * b->capv : 1024;
        float *q = c < 0xFFFFFFFFUL ? (float *)realloc(m->v, c * 3 * sizeof(float)) : NULL;
        if (!q) {
            b->fail = 1;
            return -1;
        }
        m->v = q;
        b->capv = c;
    }
    m->v[3 * m->nv] = (float)x;
    m->v[3 * m->nv + 1] = (float)y;
    m->v[3 * m->nv + 2] = (float)z;
    return (long)m->nv++;
}

PN_RENDER_UNUSED static void pn_iso__tri(pn_iso__b *b, long a, long c, long d) {
    pn_mesh *m = b->m;
    if (b->fail || a < 0 || c < 0 || d < 0) {
        b->fail = 1;
        return;
    }
    if (m->nt == b->capt) {
        size_t cap = b->capt ? 2 * b->capt : 2048;
        unsigned *q = (unsigned *)realloc(m->t, cap * 3 * sizeof(unsigned));
        if (!q) {
            b->fail = 1;
            return;
        }
        m->t = q;
        b->capt = cap;
    }
    m->t[3 * m->nt] = (unsigned)a;
    m->t[3 * m->nt + 1] = (unsigned)c;
    m->t[3 * m->nt + 2] = (unsigned)d;
    m->nt++;
}

/* The iso-surface of a sampled field by marching tetrahedra: each grid cube is cut into six
   tetrahedra around its main diagonal (the same cut in every cube, so neighbours agree on the
   faces they share and no case is ambiguous), the surface crosses each tetrahedron edge where
   the linear interpolant equals iso, and crossings are shared through a table indexed by grid
   edge, so the mesh is indexed, closed and manifold. field[(i * ny + j) * nz + k] is the value
   at origin + (i, j, k) * cell; inside is field > iso and triangles face outwards (towards
   lower values). The grid is surrounded by a layer of outside values (crossings half a cell
   out), so the mesh is closed even where the inside reaches the grid boundary. NaN counts as
   outside. *out is replaced (free it with pn_mesh_free); 1 on success. */
PN_RENDER_UNUSED static int pn_iso_mesh(const float *field, int nx, int ny, int nz, const double origin[3],
                                        double cell, double iso, pn_mesh *out) {
    static const int tets[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
    pn_iso__b b;
    long *lay[2], *tmp;
    size_t plane;
    int NX = nx + 2, NY = ny + 2, NZ = nz + 2, I, J, K, t, c;
    memset(out, 0, sizeof *out);
    if (!field || nx < 1 || ny < 1 || nz < 1 || !(cell > 0) || (double)NY * NZ * 7 > 1e9) return 0;
    b.m = out;
    b.capv = b.capt = 0;
    b.fail = 0;
    /* crossings on the grid edges leaving the vertices of two x-planes of vertices: 7 per
       vertex, one for each direction (1 = +x, 2 = +y, 4 = +z and their sums) minus one */
    plane = (size_t)NY * (size_t)NZ * 7;
    lay[0] = (long *)malloc(plane * sizeof(long));
    lay[1] = (long *)malloc(plane * sizeof(long));
    if (!lay[0] || !lay[1]) {
        free(lay[0]);
        free(lay[1]);
        return 0;
    }
    for (c = 0; c < 2; ++c)
        for (plane = 0; plane < (size_t)NY * (size_t)NZ * 7; ++plane) lay[c][plane] = -1;
    plane = (size_t)NY * (size_t)NZ * 7;
    for (I = 0; I + 1 < NX && !b.fail; ++I) {
        if (I > 0) { /* slide: the old upper plane becomes the lower one */
            tmp = lay[0];
            lay[0] = lay[1];
            lay[1] = tmp;
            for (t = 0; t < (int)plane; ++t) lay[1][t] = -1;
        }
        for (J = 0; J + 1 < NY; ++J)
            for (K = 0; K + 1 < NZ; ++K) {
                double f[8];
                int ok[8], in[8], nin = 0;
                for (c = 0; c < 8; ++c) {
                    int i = I + (c & 1) - 1, j = J + (c >> 1 & 1) - 1, k = K + (c >> 2 & 1) - 1;
                    ok[c] = i >= 0 && j >= 0 && k >= 0 && i < nx && j < ny && k < nz;
                    f[c] = ok[c] ? (double)field[((size_t)i * (size_t)ny + (size_t)j) * (size_t)nz + (size_t)k] : 0;
                    in[c] = ok[c] && f[c] > iso;
                    nin += in[c];
                }
                if (nin == 0 || nin == 8) continue;
                for (t = 0; t < 6; ++t) {
                    const int *tv = tets[t];
                    int ia[4], oa[4], ni = 0, no = 0, q;
                    long e[4];
                    for (q = 0; q < 4; ++q) {
                        if (in[tv[q]])
                            ia[ni++] = tv[q];
                        else
                            oa[no++] = tv[q];
                    }
                    if (ni == 0 || ni == 4) continue;
                    /* the crossing on the edge between local corners u and w (one contains the
                       other as a bit set: the tetrahedra are monotone paths from 0 to 7) */
#define PN_ISO__EDGE(u, w, res)                                                                          \
    do {                                                                                                 \
        int lo_ = (u) < (w) ? (u) : (w), hi_ = (u) < (w) ? (w) : (u), dir_ = (lo_ ^ hi_) - 1;            \
        int gj_ = J + (lo_ >> 1 & 1), gk_ = K + (lo_ >> 2 & 1);                                          \
        long *slot_ = &lay[lo_ & 1][((size_t)gj_ * (size_t)NZ + (size_t)gk_) * 7 + (size_t)dir_];        \
        if (*slot_ < 0) {                                                                                \
            double fa_ = f[lo_], fb_ = f[hi_], s_ = 0.5;                                                 \
            if (ok[lo_] && ok[hi_]) s_ = (iso - fa_) / (fb_ - fa_);                                      \
            if (!(s_ >= 0 && s_ <= 1)) s_ = 0.5;                                                         \
            *slot_ = pn_iso__vertex(&b, origin[0] + (I + (lo_ & 1) - 1 + s_ * ((lo_ ^ hi_) & 1)) * cell, \
                                    origin[1] + (gj_ - 1 + s_ * ((lo_ ^ hi_) >> 1 & 1)) * cell,          \
                                    origin[2] + (gk_ - 1 + s_ * ((lo_ ^ hi_) >> 2 & 1)) * cell);         \
        }                                                                                                \
        (res) = *slot_;                                                                                  \
    } while (0)
                    if (ni == 1 || ni == 3) {
                        /* one corner a apart from b, c, d: a triangle around a; it faces away
                           from a when a is inside. Seen from a, the order of (b, c, d) is the
                           sign of det(b - a, c - a, d - a) (exact: corners are 0/1 points). */
                        int a = ni == 1 ? ia[0] : oa[0], o[3], s, det, ax, ay, az;
                        int bx, by, bz, cx, cy, cz, dx, dy, dz;
                        for (q = 0, s = 0; q < 4; ++q)
                            if (tv[q] != a) o[s++] = tv[q];
                        ax = a & 1, ay = a >> 1 & 1, az = a >> 2 & 1;
                        bx = (o[0] & 1) - ax, by = (o[0] >> 1 & 1) - ay, bz = (o[0] >> 2 & 1) - az;
                        cx = (o[1] & 1) - ax, cy = (o[1] >> 1 & 1) - ay, cz = (o[1] >> 2 & 1) - az;
                        dx = (o[2] & 1) - ax, dy = (o[2] >> 1 & 1) - ay, dz = (o[2] >> 2 & 1) - az;
                        det = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
                        PN_ISO__EDGE(a, o[0], e[0]);
                        PN_ISO__EDGE(a, o[1], e[1]);
                        PN_ISO__EDGE(a, o[2], e[2]);
                        if ((det > 0) == (ni == 1))
                            pn_iso__tri(&b, e[0], e[1], e[2]);
                        else
                            pn_iso__tri(&b, e[0], e[2], e[1]);
                    } else {
                        /* inside a, b and outside c, d: the quad ac, ad, bd, bc, facing c, d */
                        int a = ia[0], bb = ia[1], cc = oa[0], dd = oa[1], det;
                        int ax = a & 1, ay = a >> 1 & 1, az = a >> 2 & 1;
                        int bx = (bb & 1) - ax, by = (bb >> 1 & 1) - ay, bz = (bb >> 2 & 1) - az;
                        int cx = (cc & 1) - ax, cy = (cc >> 1 & 1) - ay, cz = (cc >> 2 & 1) - az;
                        int dx = (dd & 1) - ax, dy = (dd >> 1 & 1) - ay, dz = (dd >> 2 & 1) - az;
                        det = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
                        PN_ISO__EDGE(a, cc, e[0]);
                        PN_ISO__EDGE(a, dd, e[1]);
                        PN_ISO__EDGE(bb, dd, e[2]);
                        PN_ISO__EDGE(bb, cc, e[3]);
                        if (det > 0) {
                            pn_iso__tri(&b, e[0], e[1], e[2]);
                            pn_iso__tri(&b, e[0], e[2], e[3]);
                        } else {
                            pn_iso__tri(&b, e[0], e[2], e[1]);
                            pn_iso__tri(&b, e[0], e[3], e[2]);
                        }
                    }
#undef PN_ISO__EDGE
                }
            }
    }
    free(lay[0]);
    free(lay[1]);
    if (b.fail) {
        pn_mesh_free(out);
        return 0;
    }
    return 1;
}

/* quadratic B-spline, support (-1.5, 1.5), integral 1: a lattice of them sums to exactly 1 */
PN_RENDER_UNUSED static double pn_iso__bspline(double u) {
    u = fabs(u);
    return u < 0.5 ? 0.75 - u * u : u < 1.5 ? 0.5 * (1.5 - u) * (1.5 - u) : 0;
}

/* 3D particles (x: 3 per particle; mask: nonzero = use, NULL: all; non-finite skipped) to a
   closed mesh of the region they fill. Each particle stands for a cube of side
   s = 2 radius_m (radius_m: half the particle spacing) and spreads unit volume with the
   tensor-product quadratic B-spline of width s (support 1.5 s = 3 radius_m each way), so the
   density is 1 inside a filled lattice and 1/2 on its faces; the surface is its 1/2 level
   sampled on a grid of cell_m (e.g. radius_m / 2), meshed by pn_iso_mesh. */
PN_RENDER_UNUSED static int pn_iso_from_particles(size_t n, const pn_real *x, const unsigned char *mask,
                                                  double radius_m, double cell_m, pn_mesh *out) {
    double blo[3] = {DBL_MAX, DBL_MAX, DBL_MAX}, bhi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX}, org[3], s, sup;
    int dims[3], c, ok;
    size_t p, total;
    float *f;
    memset(out, 0, sizeof *out);
    if ((n && !x) || !(radius_m > 0) || !(cell_m > 0) || !pn_render__finite(radius_m / cell_m)) return 0;
    s = 2 * radius_m;
    sup = 1.5 * s;
    for (p = 0; p < n; ++p) {
        const pn_real *q = x + 3 * p;
        if ((mask && !mask[p]) || !pn_render__finite((double)q[0] + (double)q[1] + (double)q[2])) continue;
        for (c = 0; c < 3; ++c) {
            if (q[c] < blo[c]) blo[c] = q[c];
            if (q[c] > bhi[c]) bhi[c] = q[c];
        }
    }
    if (blo[0] > bhi[0]) return 1; /* nothing to mesh: an empty mesh */
    total = 1;
    for (c = 0; c < 3; ++c) {
        double span = bhi[c] - blo[c] + 2 * (sup + cell_m);
        org[c] = blo[c] - sup - cell_m;
        if (!(span / cell_m < 1e5)) return 0;
        dims[c] = (int)ceil(span / cell_m) + 1;
        total *= (size_t)dims[c];
    }
    if ((double)dims[0] * dims[1] * dims[2] > 4e8) return 0;
    f = (float *)calloc(total, sizeof(float));
    if (!f) return 0;
    for (p = 0; p < n; ++p) {
        const pn_real *q = x + 3 * p;
        double wgt[3][64];
        int i0[3], cnt[3], a, b, e;
        if ((mask && !mask[p]) || !pn_render__finite((double)q[0] + (double)q[1] + (double)q[2])) continue;
        for (c = 0; c < 3; ++c) {
            double g = ((double)q[c] - org[c]) / cell_m;
            int lo = (int)ceil(g - sup / cell_m), hi = (int)floor(g + sup / cell_m);
            if (lo < 0) lo = 0;
            if (hi > dims[c] - 1) hi = dims[c] - 1;
            if (hi - lo + 1 > 64) lo = hi - 63; /* cell_m far below radius_m: coarser support */
            i0[c] = lo;
            cnt[c] = hi - lo + 1;
            for (a = 0; a < cnt[c]; ++a) wgt[c][a] = pn_iso__bspline(((lo + a) - g) * cell_m / s);
        }
        for (a = 0; a < cnt[0]; ++a)
            for (b = 0; b < cnt[1]; ++b) {
                double wab = wgt[0][a] * wgt[1][b];
                float *row = f + ((size_t)(i0[0] + a) * (size_t)dims[1] + (size_t)(i0[1] + b)) * (size_t)dims[2] + (size_t)i0[2];
                if (wab == 0) continue;
                for (e = 0; e < cnt[2]; ++e) row[e] += (float)(wab * wgt[2][e]);
            }
    }
    ok = pn_iso_mesh(f, dims[0], dims[1], dims[2], org, cell_m, 0.5, out);
    free(f);
    return ok;
}

/* Wavefront OBJ (text): vertices, area-weighted vertex normals, 1-based faces. 1 on success. */
PN_RENDER_UNUSED static int pn_mesh_write_obj(const char *path, const pn_mesh *m) {
    FILE *f;
    float *nrm;
    size_t i;
    int ok;
    if (!m || (m->nv && !m->v) || (m->nt && !m->t)) return 0;
    nrm = (float *)calloc(m->nv ? m->nv * 3 : 1, sizeof(float));
    if (!nrm) return 0;
    for (i = 0; i < m->nt; ++i) { /* the cross product's length is twice the area: a weight */
        const unsigned *t = m->t + 3 * i;
        const float *a = m->v + 3 * (size_t)t[0], *b = m->v + 3 * (size_t)t[1], *c = m->v + 3 * (size_t)t[2];
        float u[3], w[3], n[3];
        int k;
        if (t[0] >= m->nv || t[1] >= m->nv || t[2] >= m->nv) {
            free(nrm);
            return 0;
        }
        for (k = 0; k < 3; ++k) u[k] = b[k] - a[k], w[k] = c[k] - a[k];
        n[0] = u[1] * w[2] - u[2] * w[1];
        n[1] = u[2] * w[0] - u[0] * w[2];
        n[2] = u[0] * w[1] - u[1] * w[0];
        for (k = 0; k < 3; ++k) {
            nrm[3 * (size_t)t[0] + (size_t)k] += n[k];
            nrm[3 * (size_t)t[1] + (size_t)k] += n[k];
            nrm[3 * (size_t)t[2] + (size_t)k] += n[k];
        }
    }
    f = fopen(path, "w");
    if (!f) {
        free(nrm);
        return 0;
    }
    fprintf(f, "# plastinet iso-surface: %lu vertices, %lu triangles\n", (unsigned long)m->nv, (unsigned long)m->nt);
    for (i = 0; i < m->nv; ++i)
        fprintf(f, "v %.7g %.7g %.7g\n", (double)m->v[3 * i], (double)m->v[3 * i + 1], (double)m->v[3 * i + 2]);
    for (i = 0; i < m->nv; ++i) {
        double a = nrm[3 * i], b = nrm[3 * i + 1], c = nrm[3 * i + 2], l = sqrt(a * a + b * b + c * c);
        if (l > 0) a /= l, b /= l, c /= l;
        fprintf(f, "vn %.5f %.5f %.5f\n", a, b, c);
    }
    for (i = 0; i < m->nt; ++i) {
        unsigned long a = m->t[3 * i] + 1UL, b = m->t[3 * i + 1] + 1UL, c = m->t[3 * i + 2] + 1UL;
        fprintf(f, "f %lu//%lu %lu//%lu %lu//%lu\n", a, a, b, b, c, c);
    }
    free(nrm);
    ok = ferror(f) == 0;
    return (fclose(f) == 0) && ok;
}

PN_RENDER_UNUSED static void pn_mesh__le32(unsigned char *p, unsigned long v) {
    p[0] = (unsigned char)(v & 255);
    p[1] = (unsigned char)(v >> 8 & 255);
    p[2] = (unsigned char)(v >> 16 & 255);
    p[3] = (unsigned char)(v >> 24 & 255);
}

/* Binary little-endian PLY: float x, y, z per vertex; faces as "list uchar int". Written
   byte by byte, so the file is the same on any host. 1 on success. */
PN_RENDER_UNUSED static int pn_mesh_write_ply(const char *path, const pn_mesh *m) {
    FILE *f;
    size_t i;
    int ok, k;
    if (!m || (m->nv && !m->v) || (m->nt && !m->t) || m->nv > 0x7FFFFFFFUL) return 0;
    f = fopen(path, "wb");
    if (!f) return 0;
    fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment plastinet iso-surface\nelement vertex %lu\n"
               "property float x\nproperty float y\nproperty float z\nelement face %lu\n"
               "property list uchar int vertex_indices\nend_header\n",
            (unsigned long)m->nv, (unsigned long)m->nt);
    for (i = 0; i < m->nv; ++i) {
        unsigned char b[12];
        for (k = 0; k < 3; ++k) {
            float fv = m->v[3 * i + (size_t)k];
            unsigned int bits; /* IEEE-754 single precision, as PLY's float */
            memcpy(&bits, &fv, 4);
            pn_mesh__le32(b + 4 * k, bits);
        }
        fwrite(b, 1, 12, f);
    }
    for (i = 0; i < m->nt; ++i) {
        unsigned char b[13];
        b[0] = 3;
        for (k = 0; k < 3; ++k) pn_mesh__le32(b + 1 + 4 * k, m->t[3 * i + (size_t)k]);
        fwrite(b, 1, 13, f);
    }
    ok = ferror(f) == 0;
    return (fclose(f) == 0) && ok;
}

#endif /* PN_RENDER_H */
