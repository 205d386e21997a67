/* fuzz_model_check.c - pn_model_check on hand-built PlasticityNet models mutated by the
   input, then, for a model it accepts, everything that reads the model: the material, an
   energy network bound to it (pn_pnet_init, prepare and energy, one point and lanes), or the
   learned return mapping, and the network itself (pn_mlp_eval, pn_mlp_eval_lanes).

   The input: byte 0 picks the template (dimension, material, kind, input encoding,
   conditioning, base energy); then each operation is a byte naming a field and the bytes of
   its new value (fuzz_int, fuzz_real below). Weight and bias arrays are allocated with the
   lengths the model declares (pn_mlp.weight_count, bias_count; 1 when it declares none), so a
   read past what a model declares is caught by AddressSanitizer. Seeds: corpus/model_check/. */
#define PLASTINET_IMPLEMENTATION
#include "../../plastinet.h"

#include <limits.h>
#include <stdint.h>
#include <stdlib.h>

#define FZ_MAX_OPS 256
#define FZ_MAX_COUNT (PN_MLP_MAX_WIDTH * PN_MLP_MAX_WIDTH)

typedef struct fuzz_in {
    const uint8_t *p;
    size_t n;
} fuzz_in;

static int fuzz_byte(fuzz_in *in) {
    if (!in->n) return 0;
    in->n--;
    return *in->p++;
}

/* small integers (-16 .. 223) and edge values */
static int fuzz_int(fuzz_in *in) {
    static const int edge[16] = {INT_MAX, INT_MIN, -1000000, 1000000, 64, 65, 128, 4095,
                                 4096, 4097, 1 << 20, -2, 9, 17, 32, 63};
    int b = fuzz_byte(in);
    return b < 0xf0 ? b - 16 : edge[b - 0xf0];
}

/* edge values (NaN, infinities, zeros, extremes), small multiples of 1/16, or 8 raw bytes */
static double fuzz_real(fuzz_in *in) {
    const double inf = HUGE_VAL;
    int b = fuzz_byte(in);
    if (b < 16) {
        const double edge[16] = {inf - inf, inf, -inf, 0.0, -0.0, 1, -1, 1e-300, 1e300, 1.7976931348623157e308,
                                 0.5, 1e7, 2, -1e-3, 4.9e-324, 3.4e38};
        return edge[b];
    }
    if (b < 128) return (b - 72) / 16.0;
    {
        unsigned char raw[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        double x;
        int i;
        for (i = 0; i < 8; ++i) raw[i] = (unsigned char)fuzz_byte(in);
        memcpy(&x, raw, sizeof x);
        return x;
    }
}

typedef struct fuzz_edit {
    int bias, layer, index;
    float value;
} fuzz_edit;

typedef struct fuzz_case {
    pn_model mo;
    float *w[PN_MLP_MAX_LAYERS], *b[PN_MLP_MAX_LAYERS];
    int null_w[PN_MLP_MAX_LAYERS], null_b[PN_MLP_MAX_LAYERS];
    fuzz_edit edit[FZ_MAX_OPS];
    int n_edits;
    pn_real F0[9], F[9], h, E, reg;
    int reg_form, n_diff;
} fuzz_case;

/* consistent layer sizes and declared lengths: in -> hidden... -> out */
static void fuzz_shape(pn_mlp *mlp, int n_layers, int hidden, int out) {
    int l;
    mlp->n_layers = n_layers;
    for (l = 1; l < n_layers; ++l) mlp->size[l] = hidden;
    mlp->size[n_layers] = out;
    for (l = 0; l < PN_MLP_MAX_LAYERS; ++l) {
        mlp->weight_count[l] = l < n_layers ? mlp->size[l] * mlp->size[l + 1] : 0;
        mlp->bias_count[l] = l < n_layers ? mlp->size[l + 1] : 0;
    }
}

static void fuzz_template(fuzz_case *c, int pick) {
    pn_model *mo = &c->mo;
    int dim = pick & 1 ? 3 : 2, nf = dim == 2 ? 2 : 3, metal = (pick >> 1) & 1, rmap = metal && ((pick >> 2) & 1);
    int scaled = !rmap && ((pick >> 3) & 1), cond = !rmap && ((pick >> 4) & 1), i;
    memset(c, 0, sizeof *c);
    mo->format_version = PN_MODEL_FORMAT_VERSION;
    mo->name = "fuzz";
    mo->kind = rmap ? PN_MODEL_RETURN_MAP : PN_MODEL_ENERGY;
    mo->dim = dim;
    mo->elastic = metal ? ((pick >> 5) & 1 ? PN_ELASTIC_STVK_HENCKY : PN_ELASTIC_NEO_HOOKEAN) : PN_ELASTIC_STVK_HENCKY;
    mo->plastic = metal ? PN_PLASTIC_VON_MISES : PN_PLASTIC_DRUCKER_PRAGER;
    mo->youngs_modulus_train_pa = 1;
    mo->poisson_ratio = 0.3;
    mo->friction_angle_deg = metal ? 0 : 30;
    mo->yield_stress_ratio = metal ? 3e-3 : 0;
    mo->hardening_ratio = metal ? 1e-2 : 0;
    mo->h_max = 1;
    mo->e_box = 1, mo->de_box = 0.1;
    mo->out_scale = rmap ? 0.5 : 0.3;
    if (cond) {
        mo->n_params = 1;
        mo->param[0].kind = PN_MODEL_PARAM_POISSON;
        mo->param[0].lo = 0.2, mo->param[0].hi = 0.4;
    }
    mo->output = (pick >> 6) & 1 ? PN_MODEL_OUTPUT_SOFTPLUS : PN_MODEL_OUTPUT_LINEAR;
    mo->base = metal && !rmap && ((pick >> 7) & 1) ? PN_MODEL_BASE_VON_MISES_HENCKY : PN_MODEL_BASE_NONE;
    mo->n_inputs = rmap ? (dim == 2 ? 3 : 4) : 2 * nf + 1 + scaled + mo->n_params;
    for (i = 0; i < mo->n_inputs; ++i) mo->in_shift[i] = 0.01 * i, mo->in_scale[i] = 1 + 0.1 * i;
    mo->mlp.size[0] = mo->n_inputs;
    mo->mlp.activation = PN_ACTIVATION_SILU;
    fuzz_shape(&mo->mlp, 3, 6, 1);
    mo->summary = "fuzz template";
    for (i = 0; i < 9; ++i) c->F0[i] = c->F[i] = (i % (dim + 1) == 0 && i < dim * dim) ? 1 : 0;
    c->F0[0] = (pn_real)1.01, c->F[0] = (pn_real)1.02, c->F[1] = (pn_real)0.01;
    c->h = (pn_real)0.1, c->E = (pn_real)1e7;
    c->n_diff = 2;
}

/* one operation; 0 when the input is used up */
static int fuzz_op(fuzz_case *c, fuzz_in *in) {
    pn_model *mo = &c->mo;
    pn_mlp *mlp = &mo->mlp;
    int op, l;
    if (!in->n) return 0;
    op = fuzz_byte(in);
    l = fuzz_byte(in) % (PN_MLP_MAX_LAYERS + 1); /* a layer (or size index) for the ops that take one */
    switch (op % 40) {
    case 0: mo->format_version = fuzz_int(in); break;
    case 1: mo->kind = (pn_model_kind)fuzz_int(in); break;
    case 2: mo->dim = fuzz_int(in); break;
    case 3: mlp->n_layers = fuzz_int(in); break;
    case 4: mlp->size[l] = fuzz_int(in); break;
    case 5: mlp->activation = (pn_activation)fuzz_int(in); break;
    case 6: if (l < PN_MLP_MAX_LAYERS) mlp->weight_count[l] = fuzz_int(in); break;
    case 7: if (l < PN_MLP_MAX_LAYERS) mlp->bias_count[l] = fuzz_int(in); break;
    case 8: if (l < PN_MLP_MAX_LAYERS) c->null_w[l] = 1; break;
    case 9: if (l < PN_MLP_MAX_LAYERS) c->null_b[l] = 1; break;
    case 10:
    case 11:
        if (c->n_edits < FZ_MAX_OPS && l < PN_MLP_MAX_LAYERS) {
            fuzz_edit *e = &c->edit[c->n_edits++];
            e->bias = op % 40 == 11, e->layer = l, e->index = fuzz_byte(in) * 16 + fuzz_byte(in) % 16;
            e->value = (float)fuzz_real(in);
        }
        break;
    case 12: { /* a consistent reshape: 1 .. 8 layers, hidden width 1 .. 64 */
        int n = 1 + fuzz_byte(in) % PN_MLP_MAX_LAYERS, hidden = 1 + fuzz_byte(in) % PN_MLP_MAX_WIDTH;
        fuzz_shape(mlp, n, hidden, 1);
        break;
    }
    case 13: mo->n_inputs = fuzz_int(in); break;
    case 14: mo->in_shift[fuzz_byte(in) % 16] = fuzz_real(in); break;
    case 15: mo->in_scale[fuzz_byte(in) % 16] = fuzz_real(in); break;
    case 16: mo->out_scale = fuzz_real(in); break;
    case 17: mo->youngs_modulus_train_pa = fuzz_real(in); break;
    case 18: mo->h_min = fuzz_real(in); break;
    case 19: mo->h_max = fuzz_real(in); break;
    case 20: mo->e_box = fuzz_real(in), mo->de_box = fuzz_real(in); break;
    case 21: mo->n_params = fuzz_int(in); break;
    case 22: mo->param[l % PN_MODEL_MAX_PARAMS].kind = fuzz_int(in); break;
    case 23: mo->param[l % PN_MODEL_MAX_PARAMS].lo = fuzz_real(in); break;
    case 24: mo->param[l % PN_MODEL_MAX_PARAMS].hi = fuzz_real(in); break;
    case 25: mo->output = fuzz_int(in); break;
    case 26: mo->base = fuzz_int(in); break;
    case 27: mo->elastic = (pn_elastic_model)fuzz_int(in); break;
    case 28: mo->plastic = (pn_plastic_model)fuzz_int(in); break;
    case 29: mo->poisson_ratio = fuzz_real(in); break;
    case 30: mo->friction_angle_deg = fuzz_real(in), mo->cohesion_strain = fuzz_real(in); break;
    case 31: mo->yield_stress_ratio = fuzz_real(in), mo->hardening_ratio = fuzz_real(in); break;
    case 32: mo->camclay_beta = fuzz_real(in), mo->camclay_xi = fuzz_real(in); break;
    case 33: mo->return_map = fuzz_byte(in) & 1 ? "fuzz" : NULL; break;
    case 34: c->F0[l] = (pn_real)fuzz_real(in); break;
    case 35: c->F[l] = (pn_real)fuzz_real(in); break;
    case 36: c->h = (pn_real)fuzz_real(in); break;
    case 37: c->E = (pn_real)fuzz_real(in); break;
    case 38: c->reg = (pn_real)fuzz_real(in), c->reg_form = fuzz_byte(in) & 1; break;
    default: c->n_diff = fuzz_int(in); break;
    }
    return 1;
}

/* the arrays, as long as the model declares (at least one entry), smooth small values */
static int fuzz_arrays(fuzz_case *c) {
    pn_mlp *mlp = &c->mo.mlp;
    int l, i, k;
    for (l = 0; l < PN_MLP_MAX_LAYERS; ++l) {
        int nw = mlp->weight_count[l] >= 1 && mlp->weight_count[l] <= FZ_MAX_COUNT ? mlp->weight_count[l] : 1;
        int nb = mlp->bias_count[l] >= 1 && mlp->bias_count[l] <= FZ_MAX_COUNT ? mlp->bias_count[l] : 1;
        c->w[l] = (float *)malloc(sizeof(float) * (size_t)nw);
        c->b[l] = (float *)malloc(sizeof(float) * (size_t)nb);
        if (!c->w[l] || !c->b[l]) return 0;
        for (i = 0; i < nw; ++i) c->w[l][i] = (float)(0.3 * sin(1.7 * i + l));
        for (i = 0; i < nb; ++i) c->b[l][i] = (float)(0.1 * cos(0.9 * i + l));
        for (k = 0; k < c->n_edits; ++k) {
            const fuzz_edit *e = &c->edit[k];
            if (e->layer == l && e->index < (e->bias ? nb : nw)) (e->bias ? c->b[l] : c->w[l])[e->index] = e->value;
        }
        mlp->weight[l] = c->null_w[l] ? NULL : c->w[l];
        mlp->bias[l] = c->null_b[l] ? NULL : c->b[l];
    }
    return 1;
}

/* what reads an accepted model */
static void fuzz_use(fuzz_case *c) {
    const pn_model *mo = &c->mo;
    char why[256] = "";
    pn_material m;
    int dim = mo->dim, i, nd;
    pn_real in[PN_MLP_MAX_WIDTH], out[PN_MLP_MAX_WIDTH], grad[PN_MLP_MAX_WIDTH * PN_MLP_MAX_DIFF];
    pn_real hess[PN_MLP_MAX_WIDTH * PN_MLP_MAX_DIFF * PN_MLP_MAX_DIFF];
    float lin[PN_MLP_MAX_WIDTH * PN_MLP_LANES], lout[PN_MLP_LANES], lgrad[PN_MLP_MAX_DIFF * PN_MLP_LANES];
    float lhess[PN_MLP_MAX_DIFF * PN_MLP_MAX_DIFF * PN_MLP_LANES];
    for (i = 0; i < PN_MLP_MAX_WIDTH; ++i) in[i] = (pn_real)(0.1 * i - 0.5);
    for (i = 0; i < PN_MLP_MAX_WIDTH * PN_MLP_LANES; ++i) lin[i] = (float)(0.05 * (i % 17) - 0.4);
    nd = c->n_diff;
    (void)pn_mlp_eval(&mo->mlp, in, nd, out, grad, hess);
    (void)pn_mlp_eval_lanes(&mo->mlp, 3, lin, nd, lout, lgrad, lhess);
    if (pn_model_material(mo, c->E, &m, why, sizeof why) != PN_OK) return;
    if (mo->kind == PN_MODEL_RETURN_MAP) {
        pn_real Z[9], T[9], hn;
        (void)pn_learned_return_map(mo, &m, dim, c->F, c->h, Z, &hn, T);
    } else {
        pn_pnet_desc desc;
        pn_pnet net;
        pn_pnet_point pt[2];
        const pn_pnet_point *ptp[2];
        pn_real T0[9], hn, psi[2], P[18], dPdF[162], F0s[18], hs[2] = {0, 0}, Fs[18];
        pn_result st[2];
        memset(&desc, 0, sizeof desc);
        desc.energy = mo, desc.regularizer = c->reg, desc.regularizer_form = (pn_pnet_regularizer)c->reg_form;
        if (pn_pnet_init(&net, &desc, &m, 0, why, sizeof why) != PN_OK) return;
        if (pn_pnet_prepare(&net, c->F0, c->h, &pt[0], &hn, T0) == PN_OK) {
            (void)pn_pnet_energy(&net, &pt[0], c->F, &psi[0], P, dPdF, 0);
            (void)pn_pnet_energy(&net, &pt[0], c->F, &psi[0], P, dPdF, PN_EVAL_PROJECT_PSD);
        }
        hs[0] = c->h, hs[1] = (pn_real)0.05;
        for (i = 0; i < dim * dim; ++i) {
            F0s[i] = c->F0[i], F0s[dim * dim + i] = i % (dim + 1) == 0 ? 1 : 0;
            Fs[i] = c->F[i], Fs[dim * dim + i] = (i % (dim + 1) == 0 ? 1 : 0) + (pn_real)0.01 * (pn_real)i;
        }
        if (pn_pnet_prepare_lanes(&net, 2, F0s, hs, pt, st) == PN_OK) {
            ptp[0] = &pt[0], ptp[1] = &pt[1];
            (void)pn_pnet_energy_lanes(&net, 2, ptp, Fs, psi, P, dPdF, PN_EVAL_PROJECT_PSD, st);
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fuzz_case *c = (fuzz_case *)malloc(sizeof *c);
    fuzz_in in;
    char why[256] = "";
    int ops = 0, l;
    pn_result r;
    if (!c) return 0;
    in.p = data, in.n = size;
    fuzz_template(c, fuzz_byte(&in));
    while (ops++ < FZ_MAX_OPS && fuzz_op(c, &in)) {
    }
    if (fuzz_arrays(c)) {
        r = pn_model_check(&c->mo, 0, why, sizeof why);
        if (r != PN_OK && !why[0]) abort(); /* a refusal names its reason */
        if (r == PN_OK) fuzz_use(c);
    }
    for (l = 0; l < PN_MLP_MAX_LAYERS; ++l) free(c->w[l]), free(c->b[l]);
    free(c);
    return 0;
}
