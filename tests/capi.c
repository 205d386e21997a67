/* capi.c: a C entry point into plastinet.h and the shipped models for gen/crosscheck.py
   (ctypes), which compares them with the torch formulas. Built by crosscheck.py:
       cc -std=c99 -O2 -shared -fPIC tests/capi.c -lm -o build/libpn_capi.so
   Every function works on n row-major d x d matrices and returns the number of failures. */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../models/pn_models.h"
#include <string.h>

int capi_model_count(void) { return PN_MODEL_COUNT; }

const char *capi_model_name(int i) { return pn_models_all[i]()->name; }

/* ints: kind, dim, n_layers, activation, size[0..8], return-map index or -1;
   dbl: in_shift[16], in_scale[16], out_scale, E_train, h_min, h_max, e_box, de_box */
void capi_model_info(int i, int *ints, double *dbl) {
    const pn_model *m = pn_models_all[i]();
    int k;
    ints[0] = (int)m->kind;
    ints[1] = m->dim;
    ints[2] = m->mlp.n_layers;
    ints[3] = (int)m->mlp.activation;
    for (k = 0; k < 9; ++k) ints[4 + k] = m->mlp.size[k];
    ints[13] = -1;
    for (k = 0; m->return_map && pn_models_all[k]; ++k)
        if (!strcmp(pn_models_all[k]()->name, m->return_map)) ints[13] = k;
    ints[14] = m->n_params; /* a conditioned model: its parameters (kind, range) and output */
    ints[15] = m->output;
    ints[20] = m->base;
    for (k = 0; k < PN_MODEL_MAX_PARAMS; ++k) {
        ints[16 + k] = k < m->n_params ? m->param[k].kind : 0;
        dbl[38 + 2 * k] = k < m->n_params ? m->param[k].lo : 0;
        dbl[39 + 2 * k] = k < m->n_params ? m->param[k].hi : 0;
    }
    for (k = 0; k < 16; ++k) {
        dbl[k] = m->in_shift[k];
        dbl[16 + k] = m->in_scale[k];
    }
    dbl[32] = m->out_scale;
    dbl[33] = m->youngs_modulus_train_pa;
    dbl[34] = m->h_min;
    dbl[35] = m->h_max;
    dbl[36] = m->e_box;
    dbl[37] = m->de_box;
}

void capi_model_layer(int i, int layer, float *W, float *b) {
    const pn_mlp *n = &pn_models_all[i]()->mlp;
    int rows = n->size[layer + 1], cols = n->size[layer];
    memcpy(W, n->weight[layer], sizeof(float) * (size_t)(rows * cols));
    memcpy(b, n->bias[layer], sizeof(float) * (size_t)rows);
}

/* T(F) = tau(Z(F)) F^-T of a material given by its parameters (pn_material_desc fields) */
int capi_T(int elastic, int plastic, const double *par, int d, int n, const double *F,
           const double *h, double *T) {
    pn_material_desc desc;
    pn_material m;
    int k, fails = 0;
    memset(&desc, 0, sizeof desc);
    desc.elastic = (pn_elastic_model)elastic;
    desc.plastic = (pn_plastic_model)plastic;
    desc.youngs_modulus_pa = par[0];
    desc.poisson_ratio = par[1];
    desc.friction_angle_deg = par[2];
    desc.cohesion_strain = par[3];
    desc.yield_stress_pa = par[4];
    desc.hardening_modulus_pa = par[5];
    desc.camclay_beta = par[6];
    desc.camclay_xi = par[7];
    if (pn_material_init(&m, &desc, NULL, 0) != PN_OK) return n;
    for (k = 0; k < n; ++k)
        if (pn_return_map(&m, d, F + k * d * d, h[k], NULL, NULL, T + k * d * d) != PN_OK) fails++;
    return fails;
}

/* Psi(F; F0, h) and its gradient with model i at E_train, regularizer off (Eq. 8); a
   conditioned model at its parameter values `values` (pn_model_param units, one per input) */
int capi_energy(int i, const double *values, int n, const double *F0, const double *F, const double *h, double *psi,
                double *P) {
    const pn_model *mo = pn_models_all[i]();
    pn_pnet_desc desc;
    pn_material_desc md;
    pn_material m;
    pn_pnet net;
    int k, j, d = mo->dim, fails = 0;
    memset(&desc, 0, sizeof desc);
    desc.energy = mo;
    desc.regularizer = -1;
    for (j = 0; mo->return_map && pn_models_all[j]; ++j)
        if (!strcmp(pn_models_all[j]()->name, mo->return_map)) desc.return_map = pn_models_all[j]();
    pn_model_material_desc(mo, (pn_real)mo->youngs_modulus_train_pa, &md);
    for (k = 0; k < mo->n_params; ++k) pn_model_param_set(&md, mo->param[k].kind, values[k]);
    if (pn_material_init(&m, &md, NULL, 0) != PN_OK || pn_pnet_init(&net, &desc, &m, d, NULL, 0) != PN_OK) return n;
    for (k = 0; k < n; ++k) {
        pn_pnet_point pt;
        if (pn_pnet_prepare(&net, F0 + k * d * d, h[k], &pt, NULL, NULL) != PN_OK ||
            pn_pnet_energy(&net, &pt, F + k * d * d, psi + k, P + k * d * d, NULL, 0) != PN_OK)
            fails++;
    }
    return fails;
}

/* T(F) by the learned return mapping model i */
int capi_learned_T(int i, int n, const double *F, const double *h, double *T) {
    const pn_model *mo = pn_models_all[i]();
    pn_material m;
    int k, d = mo->dim, fails = 0;
    if (pn_model_material(mo, (pn_real)mo->youngs_modulus_train_pa, &m, NULL, 0) != PN_OK) return n;
    for (k = 0; k < n; ++k)
        if (pn_learned_return_map(mo, &m, d, F + k * d * d, h[k], NULL, NULL, T + k * d * d) != PN_OK) fails++;
    return fails;
}
