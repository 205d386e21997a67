/* fuzz_rom_model_check.c: pn_rom_model_check on hand-built models mutated from the input, then,
   for a model it accepts, the map at a point (pn_rom_eval, pn_rom_inside, pn_rom_lattice) and a
   world of four points drawn through the float path (pn_rom_create, pn_rom_map).

   Every array is allocated at exactly the length the model's count fields declare (the
   contract of format 2), while the sizes those counts must agree with (dim, latent, n_layers,
   width[], cells[]) and the values (weights, latents, normalisation) come from the input: a
   model the check accepts must never be read past, whatever its widths say. Under
   -fsanitize=address any read past an array is a crash.

   clang -g -O1 -fsanitize=fuzzer,address,undefined tests/fuzz/fuzz_rom_model_check.c -lm -o build/fuzz_rom
   build/fuzz_rom -max_total_time=30 tests/fuzz/corpus/rom_model_check
   Also builds with gcc as C99 linked with a main that feeds it files. */
#define PLASTINET_IMPLEMENTATION
#include "../../plastinet.h"
#include "../../plastinet_rom.h"
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct fz_in {
    const uint8_t *p;
    size_t n, at;
} fz_in;

static unsigned fz_byte(fz_in *in) { return in->at < in->n ? in->p[in->at++] : 0u; }

/* a weight-like value: small, sometimes zero, NaN, infinite or huge */
static double fz_value(fz_in *in) {
    unsigned b = fz_byte(in);
    switch (b) {
    case 255: return NAN;
    case 254: return INFINITY;
    case 253: return -1e300;
    default: return ((double)b - 128.0) / 64.0;
    }
}

/* a length near `want`: usually it, sometimes off by a little or anything */
static int fz_count(fz_in *in, int want) {
    unsigned b = fz_byte(in);
    if (b < 192) return want;
    if (b < 224) return want + (int)(b % 5) - 2;
    return (int)(b - 224) * 37;
}

static double *fz_doubles(fz_in *in, int count) {
    double *a = (double *)malloc(sizeof(double) * (size_t)(count > 0 ? count : 1));
    int i;
    if (a)
        for (i = 0; i < count; ++i) a[i] = fz_value(in);
    return a;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fz_in in;
    pn_rom_model m;
    int *width = NULL, l, i, d, K, L, wn, fail = 0;
    double *wt[PN_ROM_MAX_LAYERS], *bs[PN_ROM_MAX_LAYERS], *rest = NULL, *sd = NULL;
    const double **wp = NULL, **bp = NULL;
    unsigned char *occ = NULL;
    unsigned flags;
    char why[256];
    in.p = data, in.n = size, in.at = 0;
    memset(wt, 0, sizeof wt), memset(bs, 0, sizeof bs);
    memset(&m, 0, sizeof m);
    flags = fz_byte(&in);
    d = 2 + (int)(fz_byte(&in) % 2);
    K = 1 + (int)(fz_byte(&in) % 36);           /* up to PN_ROM_MAX_LATENT + 4 */
    L = (int)(fz_byte(&in) % 11);               /* 0 .. PN_ROM_MAX_LAYERS + 2 */
    m.format_version = (flags & 0x80) && fz_byte(&in) < 16 ? 1 : PN_ROM_FORMAT_VERSION;
    m.name = "fuzz";
    m.dim = (flags & 0x40) && fz_byte(&in) < 8 ? (int)fz_byte(&in) : d;
    m.latent = K, m.n_layers = L;
    m.activation = (flags & 0x20) ? (int)(fz_byte(&in) % 3) : PN_ROM_ELU;
    /* widths: d + K, hidden widths from the input (some beyond PN_ROM_MAX_WIDTH), d */
    wn = fz_count(&in, L + 1);
    width = (int *)malloc(sizeof(int) * (size_t)(wn > 0 ? wn : 1));
    if (!width) return 0;
    for (l = 0; l < wn; ++l) {
        unsigned b = fz_byte(&in);
        width[l] = l == 0 && b < 200 ? d + K : l == L && b < 200 ? d : (int)(b % 72) - 2;
    }
    m.width = width, m.width_count = wn;
    if (L > 0 && L <= PN_ROM_MAX_LAYERS) { /* the pointer arrays hold n_layers entries */
        wp = (const double **)malloc(sizeof(double *) * (size_t)L);
        bp = (const double **)malloc(sizeof(double *) * (size_t)L);
        if (!wp || !bp) fail = 1;
        for (l = 0; l < L && !fail; ++l) {
            int ww = l + 1 < wn ? width[l] * width[l + 1] : 0, bw = l + 1 < wn ? width[l + 1] : 0;
            int wc = fz_count(&in, ww > 0 && ww <= 64 * 64 ? ww : 4), bc = fz_count(&in, bw > 0 && bw <= 64 ? bw : 2);
            if (wc < 0) wc = 0;
            if (bc < 0) bc = 0;
            wt[l] = fz_doubles(&in, wc), bs[l] = fz_doubles(&in, bc);
            wp[l] = wt[l], bp[l] = bs[l];
            m.weight_count[l] = wc, m.bias_count[l] = bc;
        }
        m.weight = wp, m.bias = bp;
    }
    if (!fail && (flags & 0x10) && fz_byte(&in) < 64) m.weight_count[L < PN_ROM_MAX_LAYERS ? L : 0] = (int)fz_byte(&in);
    if (flags & 0x01) {
        m.latent_rest_count = fz_count(&in, K);
        rest = fz_doubles(&in, m.latent_rest_count > 0 ? m.latent_rest_count : 0);
        m.latent_rest = rest;
    }
    if (flags & 0x02) {
        m.latent_std_count = fz_count(&in, K);
        sd = fz_doubles(&in, m.latent_std_count > 0 ? m.latent_std_count : 0);
        m.latent_std = sd;
    }
    for (i = 0; i < 3; ++i) {
        m.in_lo[i] = 0.02, m.in_hi[i] = 0.06, m.out_mean[i] = 0.04, m.out_std[i] = 0.02;
        if ((flags & 0x08) && fz_byte(&in) > 240) m.in_hi[i] = fz_value(&in), m.out_std[i] = fz_value(&in);
    }
    m.youngs_pa = 1e4, m.poisson = 0.3, m.density_kg_m3 = 1000, m.dx_m = 0.004, m.per_axis = 2, m.frame_dt_s = 1.0 / 144;
    if (flags & 0x04) { /* an occupancy grid: small and truthful, or sizes from the input */
        size_t cells = 1, have;
        for (i = 0; i < 3; ++i) {
            unsigned b = fz_byte(&in);
            m.cells[i] = b < 200 ? (i < d ? 1 + (int)(b % 6) : 1) : b < 250 ? (int)(b - 225) : 1 << (b - 236);
            cells *= m.cells[i] > 0 && m.cells[i] <= 64 ? (size_t)m.cells[i] : 1;
        }
        i = fz_count(&in, (int)cells);
        have = i > 0 ? (size_t)i : 0;
        occ = (unsigned char *)malloc(have ? have : 1);
        if (occ)
            for (i = 0; i < (int)have; ++i) occ[i] = (unsigned char)(fz_byte(&in) & 1);
        m.occupied = occ, m.occupied_count = have;
        m.cell_m = (flags & 0x08) && fz_byte(&in) > 250 ? fz_value(&in) : 0.01;
        for (i = 0; i < 3; ++i) m.origin_m[i] = 0.02;
    }
    if (!fail && pn_rom_model_check(&m, why, sizeof why) == PN_OK) {
        double X[3], xhat[PN_ROM_MAX_LATENT + 4], x[3], F[9], G[3 * (PN_ROM_MAX_LATENT + 4)], lat[3 * 64];
        pn_rom_desc desc;
        pn_rom_world *w = NULL;
        for (i = 0; i < 3; ++i) X[i] = 0.02 + 0.01 * (fz_byte(&in) % 5);
        for (i = 0; i < PN_ROM_MAX_LATENT + 4; ++i) xhat[i] = fz_value(&in) * 0.1;
        for (i = 0; i < m.latent; ++i)
            if (!(xhat[i] == xhat[i]) || xhat[i] - xhat[i] != 0) xhat[i] = 0;
        pn_rom_eval(&m, xhat, 1, X, x, F, G);
        (void)pn_rom_inside(&m, X);
        if (m.cells[0] > 0) (void)pn_rom_lattice(&m, 1 + (int)(fz_byte(&in) % 3), lat, 64);
        memset(&desc, 0, sizeof desc);
        {
            double P[3 * 4];
            for (i = 0; i < 3 * 4; ++i) P[i] = 0.02 + 0.01 * (i % 4);
            desc.model = &m, desc.points = P, desc.n_points = 4, desc.point_volume_m3 = 1e-6;
            if (pn_rom_create(&desc, &w, why, sizeof why) == PN_OK) {
                float Xf[3 * 4], xf[3 * 4], Ff[9 * 4];
                for (i = 0; i < 3 * 4; ++i) Xf[i] = (float)P[i];
                (void)pn_rom_map(w, 4, Xf, xf, Ff);
                (void)pn_rom_positions(w, 0, 4, xf, NULL);
                pn_rom_destroy(w);
            }
        }
    }
    for (l = 0; l < PN_ROM_MAX_LAYERS; ++l) free(wt[l]), free(bs[l]);
    free((void *)wp), free((void *)bp), free(width), free(rest), free(sd), free(occ);
    return 0;
}
