/* test_pnet_mlp.c - plastinet.h's >>mlp room (mlp_eval: pn_mlp_eval against a naive forward
   pass and central differences), and the helpers every test_pnet_*.c file shares: random
   networks, the naive forward pass, test models built at run time (random float weights, the
   material of a pn_material_init, so no trained file is needed), deformations, finite
   differences of the PlasticityNet energy.

   The test_pnet_*.c files cover plastinet.h's learned-model API: >>mlp (here), >>features and
   >>pnet (test_pnet_energy.c, test_pnet_props.c), >>learned-return and the shipped models of
   models/ when tests/run.sh finds models/pn_models.h (test_pnet_return.c), the float lanes
   (test_pnet_lanes.c). #included by test_main.c after plastinet.h (with
   PLASTINET_IMPLEMENTATION), pn_test.h and test_util.h, in that order. Expected values come
   from independent sources: a naive forward pass, central differences with Richardson
   extrapolation, invariants (exactness at F0, objectivity, isotropy, scaling with E, volume
   preservation), test_util.h's Jacobi eigen-solver, and an implementation of the learned
   return mapping's documented formula (Li et al. 2022, Eqs. 12-13). Helpers carry the t_pn_
   prefix (one translation unit is shared with the other test files). */

#include <stdlib.h> /* malloc for the widest test network */

#ifdef PN_TEST_HAVE_MODELS
#include "../models/pn_models.h"
#endif

#define T_PN_FD_TOL 1e-6       /* finite differences, relative to the largest entry          */
#define T_PN_EXACT_TOL 1e-10   /* P(F0) = T(F0), relative                                    */
#define T_PN_INV_TOL 1e-10     /* objectivity and isotropy, relative                         */
#define T_PN_SCALE_TOL 1e-12   /* rescaling with E, relative                                 */
#define T_PN_BUF 1024          /* floats of one test model's weights                         */

/* ---- small helpers -------------------------------------------------------------------------- */

static double t_pn_maxabs(int n, const double *a) {
    double m = 0;
    int i;
    for (i = 0; i < n; ++i)
        if (!(fabs(a[i]) <= m)) m = fabs(a[i]); /* a NaN sticks */
    return m;
}
/* max |a - b| / max(max |b|, floor) */
static double t_pn_rel(int n, const double *a, const double *b, double floor) {
    double m = 0, den = t_pn_maxabs(n, b);
    int i;
    for (i = 0; i < n; ++i)
        if (!(fabs(a[i] - b[i]) <= m)) m = fabs(a[i] - b[i]);
    return m / (den > floor ? den : floor);
}
static void t_pn_worst(double *worst, double v) {
    if (!(v <= *worst) && *worst == *worst) *worst = v; /* a NaN sticks */
}
static void t_pn_identity(int dim, double *A) {
    int i;
    for (i = 0; i < dim * dim; ++i) A[i] = 0;
    for (i = 0; i < dim; ++i) A[i * dim + i] = 1;
}
/* inverse by cofactors (independent of pn_mat_inverse) */
static void t_pn_inverse(int dim, const double *A, double *Ai) {
    double det = t_det(dim, A);
    if (dim == 2) {
        Ai[0] = A[3] / det; Ai[1] = -A[1] / det;
        Ai[2] = -A[2] / det; Ai[3] = A[0] / det;
        return;
    }
    Ai[0] = (A[4] * A[8] - A[5] * A[7]) / det;
    Ai[1] = (A[2] * A[7] - A[1] * A[8]) / det;
    Ai[2] = (A[1] * A[5] - A[2] * A[4]) / det;
    Ai[3] = (A[5] * A[6] - A[3] * A[8]) / det;
    Ai[4] = (A[0] * A[8] - A[2] * A[6]) / det;
    Ai[5] = (A[2] * A[3] - A[0] * A[5]) / det;
    Ai[6] = (A[3] * A[7] - A[4] * A[6]) / det;
    Ai[7] = (A[1] * A[6] - A[0] * A[7]) / det;
    Ai[8] = (A[0] * A[4] - A[1] * A[3]) / det;
}
static void t_pn_transpose(int dim, const double *A, double *At) {
    int i, j;
    for (i = 0; i < dim; ++i)
        for (j = 0; j < dim; ++j) At[j * dim + i] = A[i * dim + j];
}
static const double t_pn_sq23 = 0.81649658092772603; /* sqrt(2/3) */

/* ---- random networks and the naive forward pass ------------------------------------------- */

static int t_pn_mlp_floats(int n_layers, const int *size) {
    int l, n = 0;
    for (l = 0; l < n_layers; ++l) n += size[l] * size[l + 1] + size[l + 1];
    return n;
}
/* An MLP with the given layer sizes, weights and biases N(0, sigma^2) stored in buf. */
static void t_pn_mlp_random(pn_mlp *mlp, float *buf, int n_layers, const int *size,
                            pn_activation act, double sigma, pn_test_rng *rng) {
    int l, i, k = 0;
    memset(mlp, 0, sizeof *mlp);
    mlp->n_layers = n_layers;
    mlp->activation = act;
    for (l = 0; l <= n_layers; ++l) mlp->size[l] = size[l];
    for (l = 0; l < n_layers; ++l) {
        mlp->weight[l] = buf + k;
        for (i = 0; i < size[l] * size[l + 1]; ++i) buf[k++] = (float)(sigma * t_gauss(rng));
        mlp->bias[l] = buf + k;
        for (i = 0; i < size[l + 1]; ++i) buf[k++] = (float)(sigma * t_gauss(rng));
        mlp->weight_count[l] = size[l] * size[l + 1]; /* the lengths format 2 declares */
        mlp->bias_count[l] = size[l + 1];
    }
}
static double t_pn_act(pn_activation a, double z) {
    switch (a) {
    case PN_ACTIVATION_TANH: return tanh(z);
    case PN_ACTIVATION_SOFTPLUS: return z > 0 ? z + log1p(exp(-z)) : log1p(exp(z));
    default: return z / (1 + exp(-z));
    }
}
/* out = mlp(in), written from the layout documented in plastinet.h */
static void t_pn_forward(const pn_mlp *mlp, const double *in, double *out) {
    double x[PN_MLP_MAX_WIDTH], y[PN_MLP_MAX_WIDTH];
    int l, i, j;
    for (i = 0; i < mlp->size[0]; ++i) x[i] = in[i];
    for (l = 0; l < mlp->n_layers; ++l) {
        int n0 = mlp->size[l], n1 = mlp->size[l + 1];
        for (j = 0; j < n1; ++j) {
            double acc = (double)mlp->bias[l][j];
            for (i = 0; i < n0; ++i) acc += (double)mlp->weight[l][j * n0 + i] * x[i];
            y[j] = l + 1 < mlp->n_layers ? t_pn_act(mlp->activation, acc) : acc;
        }
        for (j = 0; j < n1; ++j) x[j] = y[j];
    }
    for (j = 0; j < mlp->size[mlp->n_layers]; ++j) out[j] = x[j];
}

/* ---- test models ------------------------------------------------------------------------------ */

typedef struct t_pn_model {
    pn_model model; /* points into buf: never copy a t_pn_model */
    float buf[T_PN_BUF];
} t_pn_model;

/* dst = a copy of src with its own weights (rebased), one of them set to value: weight 5 of
   layer 1 (which = 1) or bias 3 of layer 1 (which = 0) */
static int t_pn_model_poison(t_pn_model *dst, const t_pn_model *src, int which, double value) {
    int l;
    dst->model = src->model;
    memcpy(dst->buf, src->buf, sizeof dst->buf);
    for (l = 0; l < src->model.mlp.n_layers; ++l) {
        dst->model.mlp.weight[l] = dst->buf + (src->model.mlp.weight[l] - src->buf);
        dst->model.mlp.bias[l] = dst->buf + (src->model.mlp.bias[l] - src->buf);
    }
    if (which) dst->buf[dst->model.mlp.weight[1] - dst->buf + 5] = (float)value;
    else dst->buf[dst->model.mlp.bias[1] - dst->buf + 3] = (float)value;
    return 0;
}

/* The materials: Drucker-Prager sand and von Mises metal with Neo-Hookean elasticity. */
enum { T_PN_SAND, T_PN_METAL };
static void t_pn_desc(pn_material_desc *d, int which, double E) {
    memset(d, 0, sizeof *d);
    d->youngs_modulus_pa = E;
    d->poisson_ratio = 0.3;
    if (which == T_PN_SAND) {
        d->plastic = PN_PLASTIC_DRUCKER_PRAGER;
        d->friction_angle_deg = 30;
    } else {
        d->elastic = PN_ELASTIC_NEO_HOOKEAN;
        d->plastic = PN_PLASTIC_VON_MISES;
        d->yield_stress_pa = 3e-3 * E;
        d->hardening_modulus_pa = 1e-2 * E;
    }
}

/* A model of `kind` for the material (desc, m) at E_train = 1, hidden 8-8, random weights
   N(0, 0.5^2), input shifts N(0, 0.2^2), scales in [0.5, 1.5]. */
static void t_pn_model_make_enc(t_pn_model *tm, pn_model_kind kind, int dim, const pn_material_desc *d,
                                const pn_material *m, const char *name, const char *return_map,
                                pn_activation act, pn_test_rng *rng, int scaled) {
    pn_model *mo = &tm->model;
    int nf = dim == 2 ? 2 : 3, size[4], i;
    memset(mo, 0, sizeof *mo);
    mo->format_version = PN_MODEL_FORMAT_VERSION;
    mo->name = name;
    mo->kind = kind;
    mo->dim = dim;
    mo->elastic = m->elastic;
    mo->plastic = m->plastic;
    mo->youngs_modulus_train_pa = 1;
    mo->poisson_ratio = d->poisson_ratio;
    mo->friction_angle_deg = d->friction_angle_deg;
    mo->cohesion_strain = d->cohesion_strain;
    mo->yield_stress_ratio = d->yield_stress_pa / d->youngs_modulus_pa;
    mo->hardening_ratio = d->hardening_modulus_pa / d->youngs_modulus_pa;
    mo->h_min = 0;
    mo->h_max = 1;
    mo->e_box = 1;
    mo->de_box = 0.1;
    mo->return_map = return_map;
    mo->n_inputs = kind == PN_MODEL_ENERGY ? 2 * nf + 1 + (scaled != 0) : (dim == 2 ? 3 : 4);
    for (i = 0; i < mo->n_inputs; ++i) {
        mo->in_shift[i] = 0.2 * t_gauss(rng);
        mo->in_scale[i] = pn_test_rng_range(rng, 0.5, 1.5);
    }
    mo->out_scale = kind == PN_MODEL_ENERGY ? 0.3 : 0.5;
    size[0] = mo->n_inputs;
    size[1] = size[2] = 8;
    size[3] = 1;
    t_pn_mlp_random(&mo->mlp, tm->buf, 3, size, act, 0.5, rng);
    mo->summary = "test model";
}

/* the raw encoding (2 nf + 1 inputs) */
static void t_pn_model_make(t_pn_model *tm, pn_model_kind kind, int dim, const pn_material_desc *d,
                            const pn_material *m, const char *name, const char *return_map,
                            pn_activation act, pn_test_rng *rng) {
    t_pn_model_make_enc(tm, kind, dim, d, m, name, return_map, act, rng, 0);
}

static int t_pn_material(pn_test_ctx *pn__t, pn_material *m, pn_material_desc *desc, int which, double E) {
    char why[256] = "";
    t_pn_desc(desc, which, E);
    if (pn_material_init(m, desc, why, sizeof why) != PN_OK) {
        char msg[512];
        snprintf(msg, sizeof msg, "pn_material_init: %s", why);
        pn_test__fail(pn__t, __FILE__, __LINE__, msg);
        return 0;
    }
    return 1;
}

/* A bound PlasticityNet: the sand energy, or the metal energy with its learned return map. */
typedef struct t_pn_setup {
    pn_material_desc desc;
    pn_material m;
    t_pn_model energy, rmap;
    pn_pnet net;
    int which, dim;
} t_pn_setup;

static int t_pn_setup_make(pn_test_ctx *pn__t, t_pn_setup *s, int which, int dim, double E,
                           double regularizer, unsigned long long seed) {
    pn_test_rng rng;
    pn_pnet_desc pd;
    pn_material m1;
    pn_material_desc d1;
    char why[256] = "";
    pn_result r;
    rng.s = seed;
    s->which = which;
    s->dim = dim;
    /* the models describe the E = 1 material; the net binds the material at E */
    if (!t_pn_material(pn__t, &m1, &d1, which, 1) || !t_pn_material(pn__t, &s->m, &s->desc, which, E))
        return 0;
    t_pn_model_make(&s->energy, PN_MODEL_ENERGY, dim, &d1, &m1, which == T_PN_SAND ? "t_sand" : "t_metal",
                    which == T_PN_SAND ? NULL : "t_metal_return", PN_ACTIVATION_SILU, &rng);
    if (which == T_PN_METAL)
        t_pn_model_make(&s->rmap, PN_MODEL_RETURN_MAP, dim, &d1, &m1, "t_metal_return", NULL,
                        PN_ACTIVATION_SILU, &rng);
    memset(&pd, 0, sizeof pd);
    pd.energy = &s->energy.model;
    pd.return_map = which == T_PN_SAND ? NULL : &s->rmap.model;
    pd.regularizer = regularizer;
    r = pn_pnet_init(&s->net, &pd, &s->m, dim, why, sizeof why);
    if (r != PN_OK) {
        char msg[512];
        snprintf(msg, sizeof msg, "pn_pnet_init: %d (%s)", (int)r, why);
        pn_test__fail(pn__t, __FILE__, __LINE__, msg);
        return 0;
    }
    return 1;
}

/* ---- deformations ---------------------------------------------------------------------------- */

/* F = R1 diag(exp(e)) R2, e uniform in [-box, box]^dim (e and the rotations returned if asked) */
static void t_pn_box(pn_test_rng *rng, int dim, double box, double *e, double *R1, double *R2, double *F) {
    double s[3], ee[3], A[9], B[9];
    int i;
    t_rand_rot(rng, dim, A);
    t_rand_rot(rng, dim, B);
    for (i = 0; i < dim; ++i) {
        ee[i] = pn_test_rng_range(rng, -box, box);
        s[i] = exp(ee[i]);
    }
    t_adb(dim, A, s, B, F);
    if (e) memcpy(e, ee, sizeof(double) * (size_t)dim);
    if (R1) memcpy(R1, A, sizeof(double) * (size_t)(dim * dim));
    if (R2) memcpy(R2, B, sizeof(double) * (size_t)(dim * dim));
}
/* F = (I + eps X) F0, X Gaussian, det(I + eps X) >= 1/2 */
static void t_pn_near(pn_test_rng *rng, int dim, const double *F0, double eps, double *F) {
    double X[9];
    int i;
    do {
        t_pn_identity(dim, X);
        for (i = 0; i < dim * dim; ++i) X[i] += eps * t_gauss(rng);
    } while (!(t_det(dim, X) >= 0.5));
    t_mul(dim, X, F0, F);
}
/* F with repeated singular values: 2D s R; 3D two equal (or, one time in three, all equal) */
static void t_pn_repeated(pn_test_rng *rng, int dim, double *F) {
    double R1[9], R2[9], s[3];
    t_rand_rot(rng, dim, R1);
    t_rand_rot(rng, dim, R2);
    s[0] = s[1] = exp(pn_test_rng_range(rng, -1, 1));
    s[2] = t_randint(rng, 3) == 0 ? s[0] : exp(pn_test_rng_range(rng, -1, 1));
    t_adb(dim, R1, s, R2, F);
}

/* ---- finite differences of the PlasticityNet energy ---------------------------------------- */

/* Central differences of the energy (t_en_fd of test_energy.c) */
static int t_pn_fd(const pn_pnet *net, const pn_pnet_point *pt, int dim, const double *F, double h,
                   int what, double *out) {
    t_en_fn f;
    memset(&f, 0, sizeof f);
    f.kind = T_EN_PNET;
    f.net = net;
    f.pt = pt;
    return t_en_fd(&f, dim, F, h, what, out);
}

/* ================================================================================================
   1. pn_mlp_eval: value against the naive forward pass, gradient and Hessian against central
      differences, every activation, 1..4 differentiated inputs, several outputs.
   ================================================================================================ */

typedef struct t_pn_arch {
    int n_layers;
    int size[PN_MLP_MAX_LAYERS + 1];
} t_pn_arch;

PN_TEST(mlp_eval) {
    static const t_pn_arch archs[] = {
        {3, {4, 8, 8, 3}},                  /* the energy models' shape, three outputs   */
        {2, {5, 16, 2}},                    /* one hidden layer                          */
        {4, {2, 8, 8, 8, 1}},               /* fewer inputs than PN_MLP_MAX_DIFF         */
        {1, {4, 2}},                        /* linear: the Hessian vanishes              */
        {8, {3, 4, 4, 4, 4, 4, 4, 4, 1}},   /* PN_MLP_MAX_LAYERS                         */
        {3, {4, PN_MLP_MAX_WIDTH, PN_MLP_MAX_WIDTH, 1}}, /* PN_MLP_MAX_WIDTH             */
    };
    static const pn_activation acts[3] = {PN_ACTIVATION_SILU, PN_ACTIVATION_TANH, PN_ACTIVATION_SOFTPLUS};
    static const char *const act_name[3] = {"silu", "tanh", "softplus"};
    const int n_arch = (int)(sizeof archs / sizeof archs[0]), n_pts = 8;
    const double h = 1e-3;
    pn_test_rng rng;
    int a, ia;
    long evals = 0, fails = 0, changed = 0;
    double worst_val = 0, worst_g[3] = {0, 0, 0}, worst_h[3] = {0, 0, 0}, worst_sym = 0;
    rng.s = 0x6d6c70ULL;
    for (ia = 0; ia < 3; ++ia)
        for (a = 0; a < n_arch; ++a) {
            const t_pn_arch *ar = &archs[a];
            int n_in = ar->size[0], n_out = ar->size[ar->n_layers], p, nd, o, k, l, half;
            float *buf = (float *)malloc(sizeof(float) * (size_t)t_pn_mlp_floats(ar->n_layers, ar->size));
            pn_mlp mlp;
            if (!buf) {
                PN_CHECK(buf != NULL);
                return;
            }
            t_pn_mlp_random(&mlp, buf, ar->n_layers, ar->size, acts[ia], 0.5, &rng);
            for (p = 0; p < n_pts; ++p) {
                double u[8], ref[4], out0[4];
                for (k = 0; k < n_in; ++k) u[k] = t_gauss(&rng);
                t_pn_forward(&mlp, u, ref);
                fails += pn_mlp_eval(&mlp, u, 0, out0, NULL, NULL) != PN_OK;
                ++evals;
                t_pn_worst(&worst_val, t_pn_rel(n_out, out0, ref, 1));
                for (nd = 1; nd <= n_in && nd <= PN_MLP_MAX_DIFF; ++nd) {
                    double out[4], g[16], H[64], Honly[64], gfd[16], Hfd[64], out2[4];
                    fails += pn_mlp_eval(&mlp, u, nd, out, g, H) != PN_OK;
                    fails += pn_mlp_eval(&mlp, u, nd, out2, NULL, Honly) != PN_OK;
                    evals += 2;
                    /* the value is the same whatever else is asked; H does not need grad */
                    changed += memcmp(out, out0, sizeof(double) * (size_t)n_out) != 0;
                    changed += memcmp(out2, out0, sizeof(double) * (size_t)n_out) != 0;
                    changed += memcmp(H, Honly, sizeof(double) * (size_t)(n_out * nd * nd)) != 0;
                    for (k = 0; k < nd; ++k) {
                        double D[2][4], DG[2][16];
                        for (half = 0; half < 2; ++half) {
                            double up[8], um[8], op[4], om[4], gp[16], gm[16], step = half ? 0.5 * h : h;
                            memcpy(up, u, sizeof up);
                            memcpy(um, u, sizeof um);
                            up[k] += step;
                            um[k] -= step;
                            step = 0.5 * (up[k] - um[k]);
                            t_pn_forward(&mlp, up, op); /* gradient: differences of the naive pass */
                            t_pn_forward(&mlp, um, om);
                            for (o = 0; o < n_out; ++o) D[half][o] = (op[o] - om[o]) / (2 * step);
                            /* Hessian: differences of the (checked) gradient */
                            fails += pn_mlp_eval(&mlp, up, nd, op, gp, NULL) != PN_OK;
                            fails += pn_mlp_eval(&mlp, um, nd, om, gm, NULL) != PN_OK;
                            evals += 2;
                            for (o = 0; o < n_out * nd; ++o) DG[half][o] = (gp[o] - gm[o]) / (2 * step);
                        }
                        for (o = 0; o < n_out; ++o) {
                            gfd[o * nd + k] = (4 * D[1][o] - D[0][o]) / 3;
                            for (l = 0; l < nd; ++l)
                                Hfd[(o * nd + l) * nd + k] = (4 * DG[1][o * nd + l] - DG[0][o * nd + l]) / 3;
                        }
                    }
                    for (o = 0; o < n_out; ++o) {
                        /* per output: relative to its largest derivative (floor 1e-3) */
                        t_pn_worst(&worst_g[ia], t_pn_rel(nd, gfd + o * nd, g + o * nd, 1e-3));
                        t_pn_worst(&worst_h[ia], t_pn_rel(nd * nd, Hfd + o * nd * nd, H + o * nd * nd, 1e-3));
                        t_pn_worst(&worst_sym, t_asym(nd, H + o * nd * nd) /
                                                   (t_norm(nd * nd, H + o * nd * nd) + 1e-300));
                    }
                }
            }
            free(buf);
        }
    for (ia = 0; ia < 3; ++ia)
        PN_REPORT("%-8s gradient vs FD of the naive pass %.2e, Hessian vs FD of the gradient %.2e",
                  act_name[ia], worst_g[ia], worst_h[ia]);
    PN_REPORT("%ld evaluations (%d architectures x 3 activations x %d points, n_diff 1..4): value vs "
              "naive forward pass %.2e, Hessian asymmetry %.2e, failed %ld, outputs depending on the "
              "request %ld",
              evals, n_arch, n_pts, worst_val, worst_sym, fails, changed);
    PN_CHECK(fails == 0);
    PN_CHECK(changed == 0);
    PN_CHECK_LE(worst_val, 1e-12);
    PN_CHECK_LE(worst_sym, 1e-14);
    for (ia = 0; ia < 3; ++ia) {
        PN_CHECK_LE(worst_g[ia], T_PN_FD_TOL);
        PN_CHECK_LE(worst_h[ia], T_PN_FD_TOL);
    }
}

static const pn_test_case pn_tests_pnet_mlp[] = {
    {"mlp_eval", mlp_eval},
};
