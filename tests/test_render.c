/* test_render: examples/common/pn_render.h and pn_png.h - the PNG/APNG encoder (checked by an independent decoder,
   tests/check_png.py: Python's zlib and its own unfiltering), the Huffman code builder, the
   iso-surface mesher (closed, manifold, outward, volumes against closed forms), the mesh
   files and the particle renderer (occlusion, overlays, mask, NaN, bad arguments, speed).
   Build: cc -std=c99 -Wall -Wextra -Werror -pedantic -O2 tests/test_render.c -lm -o build/test_render
   Run from the repository root: build/test_render [name-filter]   last line: N passed, N failed
   (the filter "test_render" runs everything, so that tests/run.sh test_render does)
   Files go to build/test_render_files/ (PNGs, their raw RGB, an OBJ and a PLY). Without python3 the
   decoder checks are reported as skipped and pass. */
#if !defined(_POSIX_C_SOURCE) && !defined(_WIN32)
#define _POSIX_C_SOURCE 200112L /* mkdir, clock_gettime */
#endif
#include "../examples/common/pn_render.h"
#include "pn_test.h"
#include <time.h>
#if !defined(_WIN32)
#include <sys/stat.h>
#include <sys/types.h>
#endif

#define T_DIR "build/test_render_files" /* build/test_render is the binary */
#define PN_COUNT(a) ((int)(sizeof(a) / sizeof((a)[0])))

static double t_seconds(void) {
#if defined(CLOCK_MONOTONIC)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#else
    return (double)clock() / CLOCKS_PER_SEC;
#endif
}

static void t_mkdir(void) {
#if !defined(_WIN32)
    mkdir("build", 0777);
    mkdir(T_DIR, 0777);
#endif
}

static int t_write(const char *path, const void *p, size_t n) {
    FILE *f = fopen(path, "wb");
    int ok;
    if (!f) return 0;
    ok = fwrite(p, 1, n, f) == n;
    return (fclose(f) == 0) && ok;
}

static int t_have_python(void) { return system("python3 -c \"import zlib, struct\" >/dev/null 2>&1") == 0; }

/* tests/check_png.py ARGS: 1 if it passed, -1 if python3 is missing (skipped), 0 if it failed */
static int t_check_png(const char *args) {
    char cmd[1024];
    if (!t_have_python()) return -1;
    snprintf(cmd, sizeof cmd, "python3 tests/check_png.py %s", args);
    fflush(stdout);
    return system(cmd) == 0;
}

/* encode, write NAME.png and NAME.rgb, check with the decoder; returns the PNG size (0: failed) */
static size_t t_png_case(pn_test_ctx *pn__t, const char *name, int w, int h, const unsigned char *rgb,
                         double *ms) {
    char png[256], raw[256], args[600];
    unsigned char *out = NULL;
    size_t n = 0;
    double t0 = t_seconds();
    int ok = pn_png_encode(w, h, rgb, &out, &n), chk;
    *ms = 1e3 * (t_seconds() - t0);
    PN_CHECK(ok);
    if (!ok) return 0;
    snprintf(png, sizeof png, T_DIR "/%s.png", name);
    snprintf(raw, sizeof raw, T_DIR "/%s.rgb", name);
    PN_CHECK(t_write(png, out, n));
    PN_CHECK(t_write(raw, rgb, (size_t)w * (size_t)h * 3));
    free(out);
    snprintf(args, sizeof args, "%s %s", png, raw);
    chk = t_check_png(args);
    if (chk < 0) PN_REPORT("skipped the decoder check of %s (python3 not found)", name);
    PN_CHECK(chk != 0);
    return n;
}

/* a 2D scene like an example's frame: a mound of particles on a floor, speed-coloured */
static size_t t_scene_2d(pn_real *x, pn_real *sp, size_t cap, pn_render_desc *d, double *spacing) {
    double s = 1.0 / 300, fl = 0.05;
    size_t n = 0;
    int i, j;
    for (i = 0; i < 300 && n < cap; ++i)
        for (j = 0; j < 300 && n < cap; ++j) {
            double px = (i + 0.5) * s, py = fl + (j + 0.5) * s, top = 0.35 - 0.9 * fabs(px - 0.5);
            if (py - fl > top) break;
            x[2 * n] = (pn_real)px;
            x[2 * n + 1] = (pn_real)py;
            sp[n] = (pn_real)(py - fl > top - 0.05 ? (px - 0.2) * 2 : 0);
            ++n;
        }
    memset(d, 0, sizeof *d);
    d->width = 960;
    d->height = 540;
    d->dim = 2;
    d->hi[0] = d->hi[1] = 1;
    d->radius_m = 0.6 * s;
    d->has_floor = 1;
    d->floor_m = fl;
    d->field_name = "speed (m/s)";
    d->field_hi = 1;
    d->time_s = 0.5;
    d->scale_bar = 1;
    d->title = "test scene";
    *spacing = s;
    return n;
}

/* ---- PNG ---------------------------------------------------------------------------------- */

PN_TEST(png_roundtrip) {
    pn_test_rng rng;
    unsigned char *img = (unsigned char *)malloc(960 * 540 * 3), px[3] = {12, 200, 77};
    pn_real *x = (pn_real *)malloc(sizeof(pn_real) * 2 * 60000), *sp = (pn_real *)malloc(sizeof(pn_real) * 60000);
    pn_render_desc d;
    size_t n, np, i;
    double ms, s;
    int a, b;
    rng.s = 7;
    t_mkdir();
    if (!img || !x || !sp) {
        PN_CHECK(0);
        goto done;
    }
    /* noise: incompressible; stored blocks bound the size */
    for (i = 0; i < 64 * 48 * 3; ++i) img[i] = (unsigned char)(pn_test_rng_u64(&rng) >> 56);
    n = t_png_case(pn__t, "noise", 64, 48, img, &ms);
    PN_CHECK_LE(n, 64 * 48 * 3 + 64 * 48 * 3 / 100 + 200);
    PN_REPORT("noise 64x48: %lu bytes (raw %d)", (unsigned long)n, 64 * 48 * 3);
    /* flat 960x540 */
    memset(img, 0, 960 * 540 * 3);
    for (i = 0; i < 960 * 540; ++i) img[3 * i] = 240, img[3 * i + 1] = 242, img[3 * i + 2] = 245;
    n = t_png_case(pn__t, "flat", 960, 540, img, &ms);
    PN_CHECK(n > 0);
    PN_CHECK_LE(n, 0.01 * 960 * 540 * 3);
    PN_REPORT("flat 960x540: %lu bytes (%.3f%% of raw), %.1f ms", (unsigned long)n, 100.0 * n / (960 * 540 * 3), ms);
    /* gradient 256x256: every filter has work to do */
    for (b = 0; b < 256; ++b)
        for (a = 0; a < 256; ++a) {
            unsigned char *p = img + 3 * ((size_t)b * 256 + (size_t)a);
            p[0] = (unsigned char)a, p[1] = (unsigned char)b, p[2] = (unsigned char)((a * b) >> 8);
        }
    n = t_png_case(pn__t, "gradient", 256, 256, img, &ms);
    PN_CHECK(n > 0 && n < 256 * 256 * 3 / 4);
    /* 1x1 and an odd size */
    n = t_png_case(pn__t, "one", 1, 1, px, &ms);
    PN_CHECK(n > 0);
    for (i = 0; i < 7 * 5 * 3; ++i) img[i] = (unsigned char)(i * 37 % 251);
    n = t_png_case(pn__t, "odd", 7, 5, img, &ms);
    PN_CHECK(n > 0);
    /* long runs and long-distance repeats: matches up to 258 bytes and 32 KB back */
    for (b = 0; b < 40; ++b)
        for (a = 0; a < 3000; ++a) {
            unsigned char *p = img + 3 * ((size_t)b * 3000 + (size_t)a);
            unsigned long long r = pn_test_rng_u64(&rng);
            p[0] = (unsigned char)(a < 1500 ? (unsigned long long)(a / 300) * 40 : r >> 56);
            p[1] = (unsigned char)(a < 1500 ? 7 : (r >> 48) & 3);
            p[2] = (unsigned char)(b & 1 ? a : 9);
        }
    n = t_png_case(pn__t, "runs", 3000, 40, img, &ms);
    PN_CHECK(n > 0);
    /* a rendered frame: flat background, floor, a few thousand shaded discs, text */
    np = t_scene_2d(x, sp, 60000, &d, &s);
    PN_CHECK(pn_render_particles(&d, np, x, sp, NULL, img));
    n = t_png_case(pn__t, "scene_2d", 960, 540, img, &ms);
    PN_CHECK(n > 0);
    PN_CHECK_LE(n, 100000);
    PN_REPORT("rendered 2D frame, %lu particles: %lu bytes (%.2f%% of raw), encoded in %.1f ms", (unsigned long)np,
              (unsigned long)n, 100.0 * n / (960 * 540 * 3), ms);
done:
    free(img);
    free(x);
    free(sp);
}

/* the length and distance symbols against RFC 1951's tables (3.2.5) */
PN_TEST(png_deflate_symbols) {
    int len, dist, bad = 0;
    for (len = 3; len <= 258; ++len) {
        int c = pn_png__lcode(len);
        if (c < 0 || c > 28 || len < pn_png__lbase[c] || len - pn_png__lbase[c] >= (1 << pn_png__lext[c]) ||
            (c < 28 && len >= pn_png__lbase[c + 1] && c != 27))
            ++bad;
    }
    PN_CHECK(pn_png__lcode(258) == 28 && pn_png__lcode(257) == 27 && pn_png__lcode(3) == 0);
    for (dist = 1; dist <= 32768; ++dist) {
        int c = pn_png__dcode(dist);
        if (c < 0 || c > 29 || dist < pn_png__dbase[c] || dist - pn_png__dbase[c] >= (1 << pn_png__dext[c])) ++bad;
    }
    PN_CHECK(bad == 0);
}

/* optimal prefix code cost without a length limit, the classic pairing of the two lightest
   (O(n^2), written independently of the package-merge in the header) */
static unsigned long t_huffman_cost(const unsigned long *freq, int n) {
    unsigned long w[300], cost = 0;
    int m = 0, i;
    for (i = 0; i < n; ++i)
        if (freq[i]) w[m++] = freq[i];
    if (m < 2) return m ? freq[0] : 0;
    while (m > 1) {
        int a = 0, b = 1;
        if (w[b] < w[a]) a = 1, b = 0;
        for (i = 2; i < m; ++i) {
            if (w[i] < w[a])
                b = a, a = i;
            else if (w[i] < w[b])
                b = i;
        }
        cost += w[a] + w[b];
        w[a] += w[b];
        w[b] = w[--m];
    }
    return cost;
}

/* the Paeth predictor against the PNG specification's formula (9.4), every a, b, c */
PN_TEST(png_paeth) {
    int a, b, c, bad = 0;
    for (a = 0; a < 256; ++a)
        for (b = 0; b < 256; ++b)
            for (c = 0; c < 256; ++c) {
                int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
                int want = (pa <= pb && pa <= pc) ? a : (pb <= pc) ? b : c;
                bad += pn_png__paeth(a, b, c) != want;
            }
    PN_CHECK(bad == 0);
}

static unsigned long t_cost(const unsigned long *freq, const unsigned char *len, int n) {
    unsigned long c = 0;
    int i;
    for (i = 0; i < n; ++i) c += freq[i] * len[i];
    return c;
}

/* One deflate block of literal tokens only (no LZ77), in a zlib stream: the block coder alone,
   so the test controls its statistics. Adler-32 (RFC 1950) written here. */
static int t_literal_block(const unsigned char *src, size_t n, pn_png__buf *z) {
    unsigned *tok = (unsigned *)malloc((n ? n : 1) * sizeof(unsigned));
    unsigned long a = 1, b = 0;
    unsigned char h[4];
    pn_png__bw w;
    size_t i;
    if (!tok) return 0;
    for (i = 0; i < n; ++i) tok[i] = src[i];
    h[0] = 0x78, h[1] = 0x9C;
    pn_png__put(z, h, 2);
    w.b = z, w.acc = 0, w.nb = 0;
    pn_png__block(&w, tok, n, src, 0, n, 1);
    pn_png__align(&w);
    for (i = 0; i < n; ++i) a = (a + src[i]) % 65521, b = (b + a) % 65521;
    h[0] = (unsigned char)(b >> 8), h[1] = (unsigned char)(b & 255), h[2] = (unsigned char)(a >> 8),
    h[3] = (unsigned char)(a & 255);
    pn_png__put(z, h, 4);
    free(tok);
    return !z->fail;
}

/* bare deflate streams decoded by Python's zlib: runs (distance 1 and 3, 258-byte matches),
   noise, empty input; and single blocks of literals: Fibonacci frequencies (an unlimited
   Huffman code would be ~21 bits deep, so the 15-bit limit must act) and 70000 noise bytes
   (a stored block split at 65535 bytes) */
PN_TEST(png_deflate_stream) {
    static const char *const names[] = {"zeros", "abc", "noise", "empty", "fib_block", "stored_block"};
    size_t cap = 140000, n, i;
    unsigned char *src = (unsigned char *)malloc(cap);
    pn_test_rng rng;
    int k, chk;
    rng.s = 99;
    t_mkdir();
    if (!src) {
        PN_CHECK(0);
        return;
    }
    for (k = 0; k < 6; ++k) {
        pn_png__buf z;
        char zp[128], rp[128], args[300];
        memset(&z, 0, sizeof z);
        n = 0;
        if (k == 0) {
            n = 100000;
            memset(src, 0, n);
        } else if (k == 1) {
            for (n = 0; n < 50000; ++n) src[n] = (unsigned char)("abc"[n % 3]);
        } else if (k == 2 || k == 5) {
            for (n = 0; n < 70000; ++n) src[n] = (unsigned char)(pn_test_rng_u64(&rng) >> 56);
        } else if (k == 4) { /* symbol s appears Fibonacci(s) times */
            unsigned long f0 = 1, f1 = 1;
            int sym;
            for (sym = 0; sym < 24 && n + f1 <= cap; ++sym) {
                for (i = 0; i < f1; ++i) src[n++] = (unsigned char)(sym * 11);
                f1 += f0;
                f0 = f1 - f0;
            }
        }
        if (k < 4) {
            PN_CHECK(pn_png__zlib(src, n, &z));
        } else {
            unsigned long freq[288];
            unsigned char len[288];
            int depth = 0;
            PN_CHECK(t_literal_block(src, n, &z));
            if (k == 4) { /* the limit binds: the limited code costs more than the optimal one */
                memset(freq, 0, sizeof freq);
                for (i = 0; i < n; ++i) freq[src[i]]++;
                freq[256] = 1;
                pn_png__huff_lengths(freq, 286, 15, len);
                for (i = 0; i < 286; ++i)
                    if (len[i] > depth) depth = len[i];
                PN_CHECK(depth == 15);
                PN_CHECK(t_huffman_cost(freq, 286) < t_cost(freq, len, 286));
            }
        }
        if (k == 2 || k == 5) PN_CHECK_LE(z.n, n + n / 1000 + 64); /* stored: 5 bytes per 64 KB */
        if (k == 0 || k == 1) PN_CHECK_LE(z.n, n / 100);
        snprintf(zp, sizeof zp, T_DIR "/%s.z", names[k]);
        snprintf(rp, sizeof rp, T_DIR "/%s.raw", names[k]);
        PN_CHECK(t_write(zp, z.p, z.n));
        PN_CHECK(t_write(rp, src, n));
        free(z.p);
        snprintf(args, sizeof args, "--zlib %s %s", zp, rp);
        chk = t_check_png(args);
        if (chk < 0) PN_REPORT("skipped the decoder check of %s (python3 not found)", names[k]);
        PN_CHECK(chk != 0);
    }
    free(src);
}

PN_TEST(png_huffman_lengths) {
    pn_test_rng rng;
    unsigned long freq[288];
    unsigned char len[288];
    int trial, i, limit_cases = 0;
    rng.s = 11;
    for (trial = 0; trial < 200; ++trial) {
        int n = trial % 3 == 0 ? 19 : trial % 3 == 1 ? 30 : 286, maxbits = n == 19 ? 7 : 15, used = 0, over = 0;
        double kraft = 0;
        unsigned long cost = 0, opt;
        for (i = 0; i < n; ++i) {
            unsigned long r = (unsigned long)(pn_test_rng_u64(&rng) >> 40);
            /* sparse, skewed and Fibonacci-like weights: the last force codes beyond 15 bits */
            freq[i] = trial % 5 == 0 ? (i < 30 ? (unsigned long)(1.0 * pow(1.618, i)) + 1 : 0)
                                     : (r % 3 == 0 ? 0 : 1 + r % (trial % 2 ? 1000000 : 20));
        }
        pn_png__huff_lengths(freq, n, maxbits, len);
        for (i = 0; i < n; ++i) {
            if (len[i]) kraft += pow(2, -len[i]), ++used;
            if (len[i] > maxbits || (freq[i] && !len[i])) ++over;
            cost += freq[i] * len[i];
        }
        PN_CHECK(over == 0);
        PN_CHECK_NEAR(kraft, 1, 1e-12); /* complete: what zlib's inflate requires */
        opt = t_huffman_cost(freq, n);
        PN_CHECK(cost >= opt);
        if (cost > opt) ++limit_cases;
        /* without a binding limit package-merge is optimal */
        {
            int maxlen = 0;
            for (i = 0; i < n; ++i)
                if (len[i] > maxlen) maxlen = len[i];
            if (maxlen < maxbits) PN_CHECK(cost == opt);
        }
    }
    PN_REPORT("%d of 200 codes were shortened by the length limit", limit_cases);
    PN_CHECK(limit_cases > 0);
    /* one used symbol still gets a complete two-code tree */
    memset(freq, 0, sizeof freq);
    freq[5] = 9;
    pn_png__huff_lengths(freq, 19, 7, len);
    PN_CHECK(len[5] == 1 && len[0] == 1);
    memset(freq, 0, sizeof freq);
    pn_png__huff_lengths(freq, 30, 15, len);
    PN_CHECK(len[0] == 1 && len[1] == 1);
}

PN_TEST(png_apng) {
    enum { W = 40, H = 30, NF = 6 };
    unsigned char *frames = (unsigned char *)malloc((size_t)W * H * 3 * NF);
    pn_apng *a;
    int f, i, j, ok = 1, chk;
    char args[256];
    FILE *probe;
    t_mkdir();
    if (!frames) {
        PN_CHECK(0);
        return;
    }
    a = pn_apng_open(T_DIR "/anim.png", W, H, 10);
    PN_CHECK(a != NULL);
    for (f = 0; f < NF; ++f) { /* a dot moving over a gradient; frame 3 repeats frame 2 */
        unsigned char *img = frames + (size_t)f * W * H * 3;
        int fx = f == 3 ? 2 : f;
        for (j = 0; j < H; ++j)
            for (i = 0; i < W; ++i) {
                int in = (i - 5 - 6 * fx) * (i - 5 - 6 * fx) + (j - 15) * (j - 15) < 16;
                img[3 * (j * W + i)] = (unsigned char)(in ? 200 : 4 * i);
                img[3 * (j * W + i) + 1] = (unsigned char)(in ? 40 : 8 * j);
                img[3 * (j * W + i) + 2] = (unsigned char)(in ? 90 : 128);
            }
        if (a) ok &= pn_apng_add(a, img);
    }
    PN_CHECK(ok);
    PN_CHECK(pn_apng_close(a) == 1);
    PN_CHECK(t_write(T_DIR "/anim.rgb", frames, (size_t)W * H * 3 * NF));
    snprintf(args, sizeof args, "--apng " T_DIR "/anim.png " T_DIR "/anim.rgb %d", NF);
    chk = t_check_png(args);
    if (chk < 0) PN_REPORT("skipped the decoder check (python3 not found)");
    PN_CHECK(chk != 0);
    /* no frames: not a valid PNG, so the file is removed and close says so */
    a = pn_apng_open(T_DIR "/empty_anim.png", W, H, 10);
    PN_CHECK(a != NULL);
    PN_CHECK(pn_apng_close(a) == 0);
    probe = fopen(T_DIR "/empty_anim.png", "rb");
    PN_CHECK(probe == NULL);
    if (probe) fclose(probe);
    PN_CHECK(pn_apng_open(T_DIR "/bad.png", 0, 10, 10) == NULL);
    PN_CHECK(pn_apng_open(T_DIR "/bad.png", 10, 10, 0) == NULL);
    PN_CHECK(pn_apng_add(NULL, frames) == 0);
    PN_CHECK(pn_apng_close(NULL) == 0);
    free(frames);
}

/* ---- canvas and font ----------------------------------------------------------------------- */

PN_TEST(canvas_text) {
    static const char need[] = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz.,:;-+=/()[]%_^*";
    pn_canvas c;
    const char *s = "t = 0.500 s";
    int i, j, scale, missing = 0;
    for (i = 0; need[i]; ++i) {
        const pn_canvas__glyph *g = pn_canvas__find((unsigned char)need[i]);
        if (!g || g->ch != (unsigned char)need[i]) ++missing;
    }
    PN_CHECK(missing == 0);
    PN_CHECK(pn_canvas__find(0xB0) && pn_canvas__find(0xB0)->ch == 0xB0);
    /* digits are all 5 wide: "0.5" = 5 + 1 + 1 + 1 + 5 columns */
    PN_CHECK(pn_canvas_text_width(1, "0.5") == 13);
    PN_CHECK(pn_canvas_text_width(2, "0.5") == 26);
    PN_CHECK(pn_canvas_text_width(1, "ab\nabc") == pn_canvas_text_width(1, "abc"));
    PN_CHECK(pn_canvas_text_width(1, "") == 0);
    PN_CHECK(pn_canvas_create(&c, 200, 60));
    if (!c.rgb) return;
    for (scale = 1; scale <= 3; ++scale) {
        int w = pn_canvas_text_width(scale, s), inside = 0, outside = 0, x0 = 10, y0 = 5;
        pn_canvas_fill(&c, 255, 255, 255);
        pn_canvas_text(&c, x0, y0, scale, 0, 0, 0, s);
        for (j = 0; j < c.h; ++j)
            for (i = 0; i < c.w; ++i) {
                int inked = c.rgb[3 * (j * c.w + i)] < 255;
                /* the box of the text, widened by the smoothing (at most a font pixel) */
                int in = i >= x0 - scale && i < x0 + w + scale && j >= y0 - scale && j < y0 + 9 * scale + scale;
                if (inked && in) ++inside;
                if (inked && !in) ++outside;
            }
        PN_CHECK(outside == 0);
        PN_CHECK(inside > 20 * scale * scale);
    }
    /* shapes stay inside the canvas and blend */
    pn_canvas_fill(&c, 0, 0, 0);
    pn_canvas_rect(&c, -5, -5, 20, 20, 255, 0, 0, 1);
    pn_canvas_disc(&c, 100, 30, 10, 0, 255, 0, 0.5);
    pn_canvas_line(&c, -50, -50, 300, 300, 3, 0, 0, 255, 1);
    PN_CHECK(c.rgb[3 * (14 * 200)] == 255 && c.rgb[3 * (12 * 200 + 2)] == 255 && c.rgb[3 * (15 * 200 + 15)] == 0);
    PN_CHECK(c.rgb[3 * (14 * 200 + 14) + 2] == 255 && c.rgb[3 * (40 * 200 + 40) + 2] == 255); /* the line */
    PN_CHECK(c.rgb[3 * (30 * 200 + 100) + 1] == 128);
    PN_CHECK(c.rgb[3 * (30 * 200 + 150)] == 0 && c.rgb[3 * (30 * 200 + 150) + 1] == 0);
    pn_canvas_free(&c);
}

/* ---- iso-surfaces ------------------------------------------------------------------------- */

static unsigned long long t_key(unsigned a, unsigned b) { return (unsigned long long)a << 32 | b; }
static int t_cmp_key(const void *a, const void *b) {
    unsigned long long x = *(const unsigned long long *)a, y = *(const unsigned long long *)b;
    return x < y ? -1 : x > y;
}

/* closed and manifold with consistent orientation: every directed edge occurs once and its
   reverse occurs too, so each undirected edge has exactly two triangles, one each way */
static int t_closed_manifold(const pn_mesh *m) {
    size_t ne = m->nt * 3, i;
    unsigned long long *e;
    int ok = 1;
    if (!m->nt) return 0;
    e = (unsigned long long *)malloc(ne * sizeof *e);
    if (!e) return 0;
    for (i = 0; i < m->nt; ++i) {
        const unsigned *t = m->t + 3 * i;
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || t[0] >= m->nv || t[1] >= m->nv || t[2] >= m->nv) ok = 0;
        e[3 * i] = t_key(t[0], t[1]);
        e[3 * i + 1] = t_key(t[1], t[2]);
        e[3 * i + 2] = t_key(t[2], t[0]);
    }
    qsort(e, ne, sizeof *e, t_cmp_key);
    for (i = 0; i < ne && ok; ++i) {
        unsigned long long rev = t_key((unsigned)(e[i] & 0xFFFFFFFFu), (unsigned)(e[i] >> 32));
        if (i + 1 < ne && e[i + 1] == e[i]) ok = 0;
        if (!bsearch(&rev, e, ne, sizeof *e, t_cmp_key)) ok = 0;
    }
    free(e);
    return ok;
}

/* enclosed volume by the divergence theorem: sum of signed tetrahedra from the origin */
static double t_volume(const pn_mesh *m) {
    double v = 0;
    size_t i;
    for (i = 0; i < m->nt; ++i) {
        const float *a = m->v + 3 * (size_t)m->t[3 * i], *b = m->v + 3 * (size_t)m->t[3 * i + 1],
                    *c = m->v + 3 * (size_t)m->t[3 * i + 2];
        v += (double)a[0] * ((double)b[1] * c[2] - (double)b[2] * c[1]) -
             (double)a[1] * ((double)b[0] * c[2] - (double)b[2] * c[0]) +
             (double)a[2] * ((double)b[0] * c[1] - (double)b[1] * c[0]);
    }
    return v / 6;
}

/* sphere of radius r as the signed field r - |x - c| on a grid of cell h (2r + 4 cells wide) */
static int t_sphere_mesh(double r, double h, pn_mesh *m) {
    int n = (int)ceil(2 * r / h) + 5, i, j, k, ok;
    double org[3], c = 0.01; /* centre off the grid's symmetry */
    float *f = (float *)malloc(sizeof(float) * (size_t)n * n * n);
    if (!f) return 0;
    for (i = 0; i < 3; ++i) org[i] = c - 0.5 * (n - 1) * h;
    for (i = 0; i < n; ++i)
        for (j = 0; j < n; ++j)
            for (k = 0; k < n; ++k) {
                double x = org[0] + i * h - c, y = org[1] + j * h - c, z = org[2] + k * h - c;
                f[((size_t)i * n + j) * n + k] = (float)(r - sqrt(x * x + y * y + z * z));
            }
    ok = pn_iso_mesh(f, n, n, n, org, h, 0, m);
    free(f);
    return ok;
}

PN_TEST(iso_sphere) {
    double r = 0.5, exact = 4.0 / 3.0 * 3.14159265358979323846 * r * r * r, err[2];
    int level;
    for (level = 0; level < 2; ++level) {
        pn_mesh m;
        double h = level ? 0.025 : 0.05, vol;
        PN_CHECK(t_sphere_mesh(r, h, &m));
        PN_CHECK(t_closed_manifold(&m));
        vol = t_volume(&m);
        err[level] = fabs(vol - exact) / exact;
        PN_CHECK(vol > 0);
        PN_CHECK_LE(err[level], 0.02);
        PN_REPORT("sphere r %.2f, cell %.3f: %lu vertices, %lu triangles, volume error %.3f%%", r, h, (unsigned long)m.nv,
                  (unsigned long)m.nt, 100 * err[level]);
        /* vertices on the sphere to a fraction of a cell */
        {
            size_t i;
            double worst = 0;
            for (i = 0; i < m.nv; ++i) {
                double x = m.v[3 * i] - 0.01, y = m.v[3 * i + 1] - 0.01, z = m.v[3 * i + 2] - 0.01;
                double e = fabs(sqrt(x * x + y * y + z * z) - r);
                if (e > worst) worst = e;
            }
            PN_CHECK_LE(worst, 0.1 * h);
        }
        pn_mesh_free(&m);
    }
    PN_CHECK_LE(err[1], 0.5 * err[0]); /* second order: about a quarter */
}

/* inside everywhere: the padding layer closes the mesh, with faces half a cell out. The cubes'
   cut turns half of the box's edges into chamfers (legs of half a cell), so the volume lies
   between the n-cell box less all 12 edges chamfered and the full n-cell box. */
PN_TEST(iso_grid_boundary) {
    float f[4 * 3 * 5];
    double org[3] = {1, 2, 3}, vol, cell = 0.5, lo[3] = {1e9, 1e9, 1e9}, hi[3] = {-1e9, -1e9, -1e9};
    pn_mesh m;
    size_t q;
    int i;
    for (i = 0; i < 4 * 3 * 5; ++i) f[i] = 1;
    PN_CHECK(pn_iso_mesh(f, 4, 3, 5, org, cell, 0.5, &m));
    PN_CHECK(t_closed_manifold(&m));
    vol = t_volume(&m) / (cell * cell * cell); /* in cells */
    PN_CHECK_LE(vol, 4 * 3 * 5);
    PN_CHECK_LE(4 * 3 * 5 - 4 * (4 + 3 + 5) * 0.125, vol);
    PN_REPORT("all inside 4x3x5: %.3f cells^3 (box 60)", vol);
    for (q = 0; q < m.nv; ++q)
        for (i = 0; i < 3; ++i) {
            if (m.v[3 * q + (size_t)i] < lo[i]) lo[i] = m.v[3 * q + (size_t)i];
            if (m.v[3 * q + (size_t)i] > hi[i]) hi[i] = m.v[3 * q + (size_t)i];
        }
    PN_CHECK_NEAR(lo[0], 1 - 0.25, 1e-6);
    PN_CHECK_NEAR(hi[0], 1 + 3.5 * 0.5, 1e-6);
    PN_CHECK_NEAR(lo[2], 3 - 0.25, 1e-6);
    PN_CHECK_NEAR(hi[2], 3 + 4.5 * 0.5, 1e-6);
    pn_mesh_free(&m);
    /* nothing inside: an empty mesh; NaN counts as outside */
    for (i = 0; i < 4 * 3 * 5; ++i) f[i] = 0;
    f[7] = (float)(1e300 * 1e300 - 1e300 * 1e300); /* NaN */
    PN_CHECK(pn_iso_mesh(f, 4, 3, 5, org, 0.5, 0.5, &m));
    PN_CHECK(m.nv == 0 && m.nt == 0);
    pn_mesh_free(&m);
    PN_CHECK(!pn_iso_mesh(f, 0, 3, 5, org, 0.5, 0.5, &m));
    PN_CHECK(!pn_iso_mesh(f, 4, 3, 5, org, 0, 0.5, &m));
}

/* a box of particles on a lattice of spacing s: the B-spline density is 1/2 exactly on the
   lattice's faces, so the mesh encloses the box but for its rounded edges and corners */
PN_TEST(iso_particles_box) {
    int nx = 20, ny = 12, nz = 16, i, j, k;
    double s = 0.01, box, vol;
    size_t n = 0;
    pn_real *x = (pn_real *)malloc(sizeof(pn_real) * 3 * (size_t)(nx * ny * nz + 1));
    unsigned char *mask = (unsigned char *)malloc((size_t)(nx * ny * nz + 1));
    pn_mesh m;
    if (!x || !mask) {
        PN_CHECK(0);
        free(x);
        free(mask);
        return;
    }
    for (i = 0; i < nx; ++i)
        for (j = 0; j < ny; ++j)
            for (k = 0; k < nz; ++k) {
                x[3 * n] = (pn_real)(0.3 + (i + 0.5) * s);
                x[3 * n + 1] = (pn_real)(-0.1 + (j + 0.5) * s);
                x[3 * n + 2] = (pn_real)(0.05 + (k + 0.5) * s);
                mask[n++] = 1;
            }
    /* one masked-out particle far away must not count */
    x[3 * n] = 5, x[3 * n + 1] = 5, x[3 * n + 2] = 5;
    mask[n++] = 0;
    box = nx * ny * nz * s * s * s;
    PN_CHECK(pn_iso_from_particles(n, x, mask, 0.5 * s, 0.25 * s, &m));
    PN_CHECK(t_closed_manifold(&m));
    vol = t_volume(&m);
    /* the edge rounding: the iso-line of g(u) g(v) = 1/2 cuts about 0.1 s^2 from each unit of
       edge length (g: the 1D face profile), 4 (nx + ny + nz) s of edges: about 1.2% here */
    PN_REPORT("box %.3g m^3, mesh %.3g m^3 (%.2f%% less), %lu triangles", box, vol, 100 * (1 - vol / box),
              (unsigned long)m.nt);
    PN_CHECK(vol < box);
    PN_CHECK_LE(fabs(vol - box) / box, 0.03);
    {
        size_t q;
        float lo = 1e9f, hi = -1e9f;
        for (q = 0; q < m.nv; ++q) {
            if (m.v[3 * q] < lo) lo = m.v[3 * q];
            if (m.v[3 * q] > hi) hi = m.v[3 * q];
        }
        PN_CHECK_NEAR(lo, 0.3, 0.1 * s); /* faces where the lattice ends, not a radius out */
        PN_CHECK_NEAR(hi, 0.3 + nx * s, 0.1 * s);
    }
    pn_mesh_free(&m);
    PN_CHECK(pn_iso_from_particles(0, x, NULL, 0.005, 0.002, &m) && m.nt == 0);
    PN_CHECK(!pn_iso_from_particles(n, x, NULL, 0, 0.002, &m));
    free(x);
    free(mask);
}

PN_TEST(mesh_files) {
    pn_mesh m;
    FILE *f;
    char line[256];
    unsigned long nv = 0, nt = 0, lines_v = 0, lines_vn = 0, lines_f = 0;
    long size, header = 0;
    t_mkdir();
    PN_CHECK(t_sphere_mesh(0.5, 0.1, &m));
    PN_CHECK(pn_mesh_write_obj(T_DIR "/sphere.obj", &m));
    PN_CHECK(pn_mesh_write_ply(T_DIR "/sphere.ply", &m));
    f = fopen(T_DIR "/sphere.obj", "r");
    PN_CHECK(f != NULL);
    if (f) {
        while (fgets(line, sizeof line, f)) {
            if (!strncmp(line, "v ", 2)) ++lines_v;
            if (!strncmp(line, "vn ", 3)) ++lines_vn;
            if (!strncmp(line, "f ", 2)) ++lines_f;
        }
        fclose(f);
    }
    PN_CHECK(lines_v == m.nv && lines_vn == m.nv && lines_f == m.nt);
    f = fopen(T_DIR "/sphere.ply", "rb");
    PN_CHECK(f != NULL);
    if (f) {
        while (fgets(line, sizeof line, f)) {
            header += (long)strlen(line);
            sscanf(line, "element vertex %lu", &nv);
            sscanf(line, "element face %lu", &nt);
            if (!strcmp(line, "end_header\n")) break;
        }
        fseek(f, 0, SEEK_END);
        size = ftell(f);
        PN_CHECK(nv == m.nv && nt == m.nt);
        PN_CHECK(size == header + (long)(12 * m.nv + 13 * m.nt));
        /* the first vertex, little-endian IEEE floats */
        {
            unsigned char b[4];
            unsigned long u;
            unsigned int bits;
            float v;
            fseek(f, header, SEEK_SET);
            PN_CHECK(fread(b, 1, 4, f) == 4);
            u = b[0] | (unsigned long)b[1] << 8 | (unsigned long)b[2] << 16 | (unsigned long)b[3] << 24;
            bits = (unsigned int)u;
            memcpy(&v, &bits, 4);
            PN_CHECK(v == m.v[0]);
        }
        fclose(f);
    }
    pn_mesh_free(&m);
}

/* ---- renderer ----------------------------------------------------------------------------- */

static void t_desc3(pn_render_desc *d, int w, int h) {
    memset(d, 0, sizeof *d);
    d->width = w;
    d->height = h;
    d->dim = 3;
    d->hi[0] = d->hi[1] = d->hi[2] = 1;
    d->radius_m = 0.05;
    d->time_s = -1;
}

/* a 960 x 540 frame of the unit box with everything drawn: floor at 0.1, camera 30/20, a
   speed legend up to 1 m/s, a scale bar, a time stamp */
static void t_desc3_full(pn_render_desc *d, double radius_m, double time_s) {
    t_desc3(d, 960, 540);
    d->radius_m = radius_m;
    d->has_floor = 1;
    d->floor_m = 0.1;
    d->yaw_deg = 30;
    d->pitch_deg = 20;
    d->field_name = "speed (m/s)";
    d->field_hi = 1;
    d->time_s = time_s;
    d->scale_bar = 1;
}

static long t_diff(const unsigned char *a, const unsigned char *b, int w, int x0, int y0, int x1, int y1) {
    long n = 0;
    int i, j;
    for (j = y0; j < y1; ++j)
        for (i = x0; i < x1; ++i) {
            size_t q = 3 * ((size_t)j * (size_t)w + (size_t)i);
            n += a[q] != b[q] || a[q + 1] != b[q + 1] || a[q + 2] != b[q + 2];
        }
    return n;
}

/* pixels in [x0, x1) x [y0, y1) within 12 per channel of the colour map at t */
static long t_count_near(const unsigned char *img, int w, int h, int x0, int y0, int x1, int y1, double t) {
    unsigned char c[3];
    long n = 0;
    int i, j;
    pn_render_colormap(t, c);
    (void)h;
    for (j = y0; j < y1; ++j)
        for (i = x0; i < x1; ++i) {
            const unsigned char *p = img + 3 * ((size_t)j * (size_t)w + (size_t)i);
            n += abs(p[0] - c[0]) <= 12 && abs(p[1] - c[1]) <= 12 && abs(p[2] - c[2]) <= 12;
        }
    return n;
}

PN_TEST(render_depth_order) {
    /* front view (camera on +z): the particle at larger z is in front. Front one at field_lo
       (sand beige, red > blue), back one at field_hi (deep blue): the centre must be beige,
       whichever is drawn first. */
    enum { W = 160, H = 120 };
    unsigned char img[W * H * 3], bg[W * H * 3];
    pn_real x[6] = {0.5, 0.5, 0.7, 0.5, 0.5, 0.3}, f[2] = {0, 1};
    pn_render_desc d;
    int order;
    t_desc3(&d, W, H);
    d.field_name = NULL;
    d.field_lo = 0;
    d.field_hi = 1;
    PN_CHECK(pn_render_particles(&d, 0, x, f, NULL, bg));
    for (order = 0; order < 2; ++order) {
        const unsigned char *p = img + 3 * ((H / 2) * W + W / 2);
        if (order) { /* swap: the back particle first in the arrays */
            pn_real t;
            int k;
            for (k = 0; k < 3; ++k) t = x[k], x[k] = x[3 + k], x[3 + k] = t;
            t = f[0], f[0] = f[1], f[1] = t;
        }
        PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, img));
        PN_CHECK(p[0] > p[2] + 20); /* beige, not blue */
        PN_CHECK(t_diff(img, bg, W, W / 2, H / 2, W / 2 + 1, H / 2 + 1) == 1); /* not background */
    }
    /* seen from behind (yaw 180) the other one is in front */
    d.yaw_deg = 180;
    PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, img));
    PN_CHECK(img[3 * ((H / 2) * W + W / 2) + 2] > img[3 * ((H / 2) * W + W / 2)] + 20);
}

PN_TEST(render_overlays_mask_nan) {
    enum { W = 480, H = 270 };
    unsigned char *a = (unsigned char *)malloc(W * H * 3), *b = (unsigned char *)malloc(W * H * 3),
                  *c = (unsigned char *)malloc(W * H * 3);
    pn_real x[9] = {0.5, 0.5, 0.5, 0.2, 0.3, 0.4, 0, 0, 0}, f[3] = {0.1, 0.9, 0.5};
    unsigned char none[3] = {0, 0, 0};
    pn_render_desc d;
    int dim;
    if (!a || !b || !c) {
        PN_CHECK(0);
        goto done;
    }
    x[6] = x[7] = x[8] = (pn_real)(1e300 * 1e300 - 1e300 * 1e300); /* NaN */
    for (dim = 2; dim <= 3; ++dim) {
        t_desc3(&d, W, H);
        d.dim = dim;
        d.has_floor = 1;
        d.floor_m = 0.1;
        /* the legend: its bar shows the top colour of the map (deep blue) at the right edge,
           which the picture without it has nowhere there */
        PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, a));
        d.field_name = "plastic strain";
        PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, b));
        PN_CHECK(t_count_near(a, W, H, W - 80, 0, W, H, 1.0) == 0);
        PN_CHECK(t_count_near(b, W, H, W - 80, 0, W, H, 1.0) > 10);
        PN_CHECK(t_count_near(b, W, H, W - 80, 0, W, H, 0.0) > 10);
        /* time stamp, title and scale bar change pixels where they go (same framing) */
        d.time_s = 0.5;
        d.title = "title";
        d.scale_bar = 1;
        PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, a));
        PN_CHECK(t_diff(a, b, W, 0, 0, W / 4, H / 6) > 50);     /* title and time */
        PN_CHECK(t_diff(a, b, W, 0, 5 * H / 6, W / 3, H) > 30); /* scale bar */
        PN_CHECK(t_diff(a, b, W, W / 3, H / 6, 2 * W / 3, 5 * H / 6) == 0); /* nothing else */
        /* a mask of zeros, or only NaN positions, draw what no particles draw */
        d.field_name = NULL;
        d.time_s = -1;
        d.scale_bar = 0;
        d.title = NULL;
        PN_CHECK(pn_render_particles(&d, 0, x, f, NULL, a));
        PN_CHECK(pn_render_particles(&d, 2, x, f, none, b));
        PN_CHECK(t_diff(a, b, W, 0, 0, W, H) == 0);
        PN_CHECK(pn_render_particles(&d, 1, x + (dim == 3 ? 6 : 4), f, NULL, c));
        if (dim == 3) PN_CHECK(t_diff(a, c, W, 0, 0, W, H) == 0);
        PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, c));
        PN_CHECK(t_diff(a, c, W, 0, 0, W, H) > 50); /* and without the mask they show */
        /* a NaN field value draws grey, not garbage */
        f[0] = x[8];
        PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, c));
        f[0] = 0.1;
    }
    /* 2D: a NaN particle among good ones draws nothing */
    t_desc3(&d, W, H);
    d.dim = 2;
    {
        pn_real y3[6] = {0.5, 0.5, 0, 0, 0.5, 0.6}, y2[4] = {0.5, 0.5, 0.5, 0.6};
        y3[2] = x[8];
        PN_CHECK(pn_render_particles(&d, 3, y3, NULL, NULL, a));
        PN_CHECK(pn_render_particles(&d, 2, y2, NULL, NULL, b));
        PN_CHECK(t_diff(a, b, W, 0, 0, W, H) == 0);
        PN_CHECK(pn_render_particles(&d, 0, y2, NULL, NULL, c));
        PN_CHECK(t_diff(a, c, W, 0, 0, W, H) > 10);
    }
    /* bad arguments */
    t_desc3(&d, W, H);
    d.dim = 4;
    PN_CHECK(!pn_render_particles(&d, 1, x, f, NULL, a));
    t_desc3(&d, W, H);
    d.hi[1] = 0;
    PN_CHECK(!pn_render_particles(&d, 1, x, f, NULL, a));
    t_desc3(&d, 0, H);
    PN_CHECK(!pn_render_particles(&d, 1, x, f, NULL, a));
    t_desc3(&d, W, H);
    d.yaw_deg = x[8];
    PN_CHECK(!pn_render_particles(&d, 1, x, f, NULL, a));
    t_desc3(&d, W, H);
    PN_CHECK(!pn_render_particles(&d, 1, x, f, NULL, NULL));
    /* tiny pictures, a NaN floor, odd field ranges: drawn without complaint */
    for (dim = 2; dim <= 3; ++dim) {
        int wh[3][2] = {{1, 1}, {7, 3}, {40, 300}}, q;
        for (q = 0; q < 3; ++q) {
            t_desc3(&d, wh[q][0], wh[q][1]);
            d.dim = dim;
            d.field_name = "f";
            d.time_s = 1;
            d.scale_bar = 1;
            d.title = "a title longer than the picture";
            d.has_floor = 1;
            d.floor_m = q == 1 ? x[8] : 0.2;
            d.field_lo = q == 2 ? 1 : 0;
            d.field_hi = q == 2 ? 1 : 1e-12;
            PN_CHECK(pn_render_particles(&d, 2, x, f, NULL, a));
        }
    }
    d.radius_m = 0;
    PN_CHECK(!pn_render_particles(&d, 1, x, f, NULL, a));
done:
    free(a);
    free(b);
    free(c);
}

/* every collider kind in both dimensions, written for a look (and the decoder) */
PN_TEST(render_scenes) {
    pn_render_shape sh[3];
    pn_render_desc d;
    unsigned char *img = (unsigned char *)malloc(960 * 540 * 3);
    pn_real *x = (pn_real *)malloc(sizeof(pn_real) * 3 * 40000), *sp = (pn_real *)malloc(sizeof(pn_real) * 40000);
    pn_test_rng rng;
    size_t n = 0, np;
    double s, ms;
    rng.s = 3;
    t_mkdir();
    if (!img || !x || !sp) {
        PN_CHECK(0);
        goto done;
    }
    memset(sh, 0, sizeof sh);
    sh[0].kind = PN_RENDER_SPHERE;
    sh[0].center[0] = 0.8, sh[0].center[1] = 0.3, sh[0].center[2] = 0.5, sh[0].radius = 0.08;
    sh[1].kind = PN_RENDER_BOX;
    sh[1].center[0] = 0.15, sh[1].center[1] = 0.2, sh[1].center[2] = 0.5;
    sh[1].half_extent[0] = 0.04, sh[1].half_extent[1] = 0.15, sh[1].half_extent[2] = 0.3;
    sh[2].kind = PN_RENDER_HALF_SPACE;
    sh[2].center[0] = 0.95, sh[2].normal[0] = -1, sh[2].normal[1] = 0.3;
    np = t_scene_2d(x, sp, 40000, &d, &s);
    d.shapes = sh;
    d.n_shapes = 3;
    PN_CHECK(pn_render_particles(&d, np, x, sp, NULL, img));
    n = t_png_case(pn__t, "colliders_2d", 960, 540, img, &ms);
    PN_CHECK(n > 0);
    /* 3D: a heap of particles */
    for (n = 0; n < 40000; ++n) {
        double r = 0.25 * sqrt(pn_test_rng_uniform(&rng)), a = pn_test_rng_range(&rng, 0, 6.2831853);
        double hgt = 0.3 * (1 - r / 0.25) * pn_test_rng_uniform(&rng);
        x[3 * n] = (pn_real)(0.5 + r * cos(a));
        x[3 * n + 1] = (pn_real)(0.1 + hgt);
        x[3 * n + 2] = (pn_real)(0.5 + r * sin(a));
        sp[n] = (pn_real)(hgt * 4);
    }
    t_desc3_full(&d, 0.006, 1.25);
    d.title = "colliders 3D";
    d.shapes = sh;
    d.n_shapes = 3;
    PN_CHECK(pn_render_particles(&d, 40000, x, sp, NULL, img));
    n = t_png_case(pn__t, "colliders_3d", 960, 540, img, &ms);
    PN_CHECK(n > 0);
    PN_CHECK_LE(n, 150000);
    PN_REPORT("3D frame, 40000 particles and 3 colliders: %lu bytes", (unsigned long)n);
done:
    free(img);
    free(x);
    free(sp);
}

PN_TEST(render_speed) {
    size_t n = 100000, p;
    pn_real *x = (pn_real *)malloc(sizeof(pn_real) * 3 * n), *sp = (pn_real *)malloc(sizeof(pn_real) * n);
    unsigned char *img = (unsigned char *)malloc(960 * 540 * 3);
    pn_render_desc d;
    pn_test_rng rng;
    double t0, t3, t2;
    int side = 47, i, j, k;
    rng.s = 5;
    if (!x || !sp || !img) {
        PN_CHECK(0);
        goto done;
    }
    /* a 47^3 lattice block (103823 clipped to 100000) resting on the floor */
    p = 0;
    for (i = 0; i < side && p < n; ++i)
        for (j = 0; j < side && p < n; ++j)
            for (k = 0; k < side && p < n; ++k, ++p) {
                x[3 * p] = (pn_real)(0.3 + i * 0.008);
                x[3 * p + 1] = (pn_real)(0.1 + j * 0.008);
                x[3 * p + 2] = (pn_real)(0.3 + k * 0.008);
                sp[p] = (pn_real)pn_test_rng_uniform(&rng);
            }
    t_desc3_full(&d, 0.0048, 0);
    t0 = t_seconds();
    PN_CHECK(pn_render_particles(&d, n, x, sp, NULL, img));
    t3 = t_seconds() - t0;
    d.dim = 2;
    for (p = 0; p < n; ++p) x[2 * p] = x[3 * p], x[2 * p + 1] = x[3 * p + 1] + (pn_real)(0.002 * (p % 3));
    t0 = t_seconds();
    PN_CHECK(pn_render_particles(&d, n, x, sp, NULL, img));
    t2 = t_seconds() - t0;
    /* measured, never asserted: tests do not bound wall time */
    PN_REPORT("100000 particles at 960x540: 3D %.0f ms, 2D %.0f ms", 1e3 * t3, 1e3 * t2);
done:
    free(x);
    free(sp);
    free(img);
}

static const pn_test_case pn_tests_render[] = {
    {"png_roundtrip", png_roundtrip},
    {"png_deflate_symbols", png_deflate_symbols},
    {"png_paeth", png_paeth},
    {"png_deflate_stream", png_deflate_stream},
    {"png_huffman_lengths", png_huffman_lengths},
    {"png_apng", png_apng},
    {"canvas_text", canvas_text},
    {"iso_sphere", iso_sphere},
    {"iso_grid_boundary", iso_grid_boundary},
    {"iso_particles_box", iso_particles_box},
    {"mesh_files", mesh_files},
    {"render_depth_order", render_depth_order},
    {"render_overlays_mask_nan", render_overlays_mask_nan},
    {"render_scenes", render_scenes},
    {"render_speed", render_speed},
};

int main(int argc, char **argv) {
    const char *filter = argc > 1 ? argv[1] : NULL;
    int passed = 0, failed = 0;
    if (filter && !strcmp(filter, "test_render")) filter = NULL; /* tests/run.sh test_render: all */
    pn_test_run(pn_tests_render, PN_COUNT(pn_tests_render), filter, &passed, &failed);
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
