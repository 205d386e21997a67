/* test_pnet_lanes.c - the float lanes of plastinet.h's >>mlp and >>pnet rooms (pnet_lanes*):
   pn_mlp_eval_lanes and pn_pnet_energy_lanes against the double reference. tests/run.sh also
   runs these in their other spellings (-march=native, -DPN_NO_VECTOR_EXTENSIONS) by the
   filter pnet_lanes. Helpers: test_pnet_mlp.c. */

/* ================================================================================================
   The float lanes (pn_mlp_eval_lanes, pn_pnet_energy_lanes) against the double reference
   (pn_mlp_eval, pn_pnet_energy): test models with the raw and the scaled encoding, silu and
   tanh, 2D and 3D, blocks of 1 to 8 points with an inverted F among them (its status, the
   others' values), and the shipped sand models when present. Errors are relative to the
   largest entry of each quantity over a block (float rounds each product to 6e-8 of itself;
   sums of a few dozen terms of mixed sign land near 1e-6 of the largest).
   ================================================================================================ */

static double t_lanes_rel(int n, const double *ref, const double *got) {
    double top = 0, err = 0;
    int i;
    for (i = 0; i < n; ++i) top = fmax(top, fabs(ref[i]));
    for (i = 0; i < n; ++i) err = fmax(err, fabs(ref[i] - got[i]));
    return top > 0 ? err / top : err;
}

static void t_lanes_block(pn_test_ctx *pn__t, const pn_pnet *net, int dim, int n, pn_test_rng *rng, double r,
                          int bad, double *worst) {
    int dd = dim * dim, i, k;
    pn_pnet_point pt[PN_MLP_LANES];
    const pn_pnet_point *ptp[PN_MLP_LANES];
    double F[PN_MLP_LANES * 9], psi[PN_MLP_LANES], P[PN_MLP_LANES * 9], H[PN_MLP_LANES * 81];
    double rpsi[PN_MLP_LANES], rP[PN_MLP_LANES * 9], rH[PN_MLP_LANES * 81];
    pn_result st[PN_MLP_LANES], rst[PN_MLP_LANES];
    memset(F, 0, sizeof F); /* gcc -O1 cannot see that n >= 1 fills what the call reads */
    for (i = 0; i < PN_MLP_LANES; ++i) ptp[i] = &pt[i];
    for (i = 0; i < n; ++i) {
        double R[4][9], s0[3], sv[3], F0[9];
        for (k = 0; k < 4; ++k) t_rand_rot(rng, dim, R[k]);
        for (k = 0; k < dim; ++k) {
            double e0 = pn_test_rng_range(rng, -r, r);
            s0[k] = exp(e0);
            sv[k] = exp(e0 + pn_test_rng_range(rng, -r, r));
        }
        t_adb(dim, R[0], s0, R[1], F0);
        t_adb(dim, R[2], sv, R[3], F + i * dd);
        if (i == bad) F[i * dd] = -F[i * dd] - 3; /* det F < 0 (a flipped column, near enough) */
        PN_CHECK(pn_pnet_prepare(net, F0, 0.1, &pt[i], NULL, NULL) == PN_OK);
        ptp[i] = &pt[i];
        rst[i] = pn_pnet_energy(net, &pt[i], F + i * dd, &rpsi[i], rP + i * dd, rH + i * dd * dd, PN_EVAL_PROJECT_PSD);
    }
    pn_pnet_energy_lanes(net, n, ptp, F, psi, P, H, PN_EVAL_PROJECT_PSD, st);
    for (i = 0; i < n; ++i) {
        PN_CHECK(st[i] == rst[i]);
        if (st[i] != PN_OK || rst[i] != PN_OK) continue;
        worst[0] = fmax(worst[0], fabs(psi[i] - rpsi[i]) / (fabs(rpsi[i]) + t_lanes_rel(dd, rP + i * dd, rP + i * dd) + 1e-300));
        worst[1] = fmax(worst[1], t_lanes_rel(dd, rP + i * dd, P + i * dd));
        worst[2] = fmax(worst[2], t_lanes_rel(dd * dd, rH + i * dd * dd, H + i * dd * dd));
    }
}

/* pn_pnet_prepare_lanes against pn_pnet_prepare at n random F0 (lane bad, if >= 0, inverted):
   F0, h and the features exactly, C to float precision of the network's gradient (relative
   to |C| + |T(F0)|, T the return mapping's stress, which C subtracts); the inverted lane
   refused alone and its point left as it was. Returns the worst relative error of C. */
static double t_prepare_lanes(pn_test_ctx *pn__t, const pn_pnet *net, int dim, int n, int bad, pn_test_rng *rng) {
    pn_real F0[PN_MLP_LANES * 9], h[PN_MLP_LANES], T[9];
    pn_pnet_point pt[PN_MLP_LANES], ref, keep;
    pn_result st[PN_MLP_LANES];
    int dd = dim * dim, i, k, same = 1;
    double worst = 0;
    memset(F0, 0, sizeof F0), memset(h, 0, sizeof h); /* gcc -O1 cannot see that n >= 1 fills what the call reads */
    for (i = 0; i < n; ++i) {
        for (k = 0; k < dd; ++k) F0[i * dd + k] = (pn_real)((k % (dim + 1) == 0 ? 1 : 0) + pn_test_rng_range(rng, -0.05, 0.05));
        if (i == bad) for (k = 0; k < dim; ++k) F0[i * dd + k] = -F0[i * dd + k]; /* a row negated: det < 0 */
        h[i] = 0;
    }
    memset(&keep, 0x5a, sizeof keep);
    for (i = 0; i < n; ++i) pt[i] = keep;
    PN_CHECK((pn_pnet_prepare_lanes(net, n, F0, h, pt, st) == PN_OK) == (bad < 0 || bad >= n));
    for (i = 0; i < n; ++i) {
        double num = 0, den = 0;
        if (i == bad) {
            PN_CHECK(st[i] == PN_ERROR_INVERTED && memcmp(&pt[i], &keep, sizeof keep) == 0);
            continue;
        }
        PN_CHECK(st[i] == PN_OK && pn_pnet_prepare(net, F0 + i * dd, h[i], &ref, NULL, T) == PN_OK);
        same &= memcmp(ref.F0, pt[i].F0, sizeof ref.F0) == 0 && ref.h == pt[i].h &&
                memcmp(ref.x0, pt[i].x0, sizeof(pn_real) * (size_t)(dim == 2 ? 2 : 3)) == 0;
        for (k = 0; k < dd; ++k) num += fabs((double)(ref.C[k] - pt[i].C[k])), den += fabs((double)ref.C[k]) + fabs((double)T[k]);
        worst = fmax(worst, num / (den + 1e-300));
    }
    PN_CHECK(same);
    return worst;
}

/* The lane path on a network whose float pre-activation is inf - inf = NaN (finite weights
   near FLT_MAX, which pn_model_check accepts): PN_ERROR_OVERFLOW and the output untouched.
   Its exponential cast that NaN to an integer (undefined behaviour: UBSan, make
   test-sanitize; tests/fuzz/corpus/model_check/lanes_nan_preactivation). */
PN_TEST(pnet_lanes_nan_preactivation) {
    static const float w0[4] = {3e38f, -3e38f, 3e38f, -3e38f}, b0[2] = {0, 0}, w1[2] = {1, 1}, b1[1] = {0};
    float in[2 * PN_MLP_LANES], out[PN_MLP_LANES], grad[2 * PN_MLP_LANES];
    pn_mlp mlp;
    int i, act;
    memset(&mlp, 0, sizeof mlp);
    mlp.n_layers = 2;
    mlp.size[0] = 2, mlp.size[1] = 2, mlp.size[2] = 1;
    mlp.weight[0] = w0, mlp.bias[0] = b0, mlp.weight[1] = w1, mlp.bias[1] = b1;
    mlp.weight_count[0] = 4, mlp.bias_count[0] = 2, mlp.weight_count[1] = 2, mlp.bias_count[1] = 1;
    for (i = 0; i < 2 * PN_MLP_LANES; ++i) in[i] = 10;
    for (act = PN_ACTIVATION_SILU; act <= PN_ACTIVATION_TANH; ++act) {
        mlp.activation = (pn_activation)act;
        out[0] = -7;
        PN_CHECK(pn_mlp_eval_lanes(&mlp, 3, in, 2, out, grad, NULL) == PN_ERROR_OVERFLOW);
        PN_CHECK(out[0] == -7);
    }
}

/* The lanes' exponential over its whole range and past its clamp (|z| > 87): a network of
   one input and two hidden units whose pre-activations are +-z, z from -120 to 120, against
   the double path (libm's exp), silu and tanh, value, gradient and Hessian. */
PN_TEST(pnet_lanes_exp_range) {
    static const float w0[2] = {1, -1}, b0[2] = {0, 0}, w1[2] = {0.75f, -0.5f}, b1[1] = {0.25f};
    float in[PN_MLP_LANES], o[PN_MLP_LANES], g[PN_MLP_LANES], h[PN_MLP_LANES];
    double worst = 0;
    pn_mlp mlp;
    int act, k, i;
    memset(&mlp, 0, sizeof mlp);
    mlp.n_layers = 2;
    mlp.size[0] = 1, mlp.size[1] = 2, mlp.size[2] = 1;
    mlp.weight[0] = w0, mlp.bias[0] = b0, mlp.weight[1] = w1, mlp.bias[1] = b1;
    mlp.weight_count[0] = 2, mlp.bias_count[0] = 2, mlp.weight_count[1] = 2, mlp.bias_count[1] = 1;
    for (act = PN_ACTIVATION_SILU; act <= PN_ACTIVATION_TANH; ++act) {
        mlp.activation = (pn_activation)act;
        for (k = 0; k < 30; ++k) {
            for (i = 0; i < PN_MLP_LANES; ++i) in[i] = -120.0f + 240.0f * (float)(k * PN_MLP_LANES + i) / (30 * PN_MLP_LANES - 1);
            PN_CHECK(pn_mlp_eval_lanes(&mlp, PN_MLP_LANES, in, 1, o, g, h) == PN_OK);
            for (i = 0; i < PN_MLP_LANES; ++i) {
                double x = in[i], ro, rg, rh;
                PN_CHECK(pn_mlp_eval(&mlp, &x, 1, &ro, &rg, &rh) == PN_OK);
                worst = fmax(worst, fabs(ro - o[i]) / (fabs(ro) + 1));
                worst = fmax(worst, fabs(rg - g[i]) / (fabs(rg) + 1));
                worst = fmax(worst, fabs(rh - h[i]) / (fabs(rh) + 1));
            }
        }
    }
    PN_REPORT("pre-activations over [-120, 120]: worst relative error %.2e (value, gradient, Hessian)", worst);
    PN_CHECK_LE(worst, 1e-5);
}

PN_TEST(pnet_lanes) {
    double worst[3] = {0, 0, 0}, mlp_worst = 0, prep_worst = 0;
    int dim, scaled, act, n, rep, k, format_refused;
    pn_test_rng rng = {4242}, rng2 = {77};
    for (dim = 2; dim <= 3; ++dim)
        for (scaled = 0; scaled <= 1; ++scaled)
            for (act = 0; act < 2; ++act) {
                pn_material_desc d1;
                pn_material m1;
                t_pn_model tm;
                pn_pnet net;
                pn_pnet_desc pd;
                char why[256] = "";
                if (!t_pn_material(pn__t, &m1, &d1, T_PN_SAND, 1)) return;
                t_pn_model_make_enc(&tm, PN_MODEL_ENERGY, dim, &d1, &m1, "t_sand_lanes", NULL,
                                    act ? PN_ACTIVATION_TANH : PN_ACTIVATION_SILU, &rng, scaled);
                memset(&pd, 0, sizeof pd);
                pd.energy = &tm.model;
                if (pn_pnet_init(&net, &pd, &m1, dim, why, sizeof why) != PN_OK) {
                    PN_CHECK(!"pn_pnet_init");
                    return;
                }
                for (n = 1; n <= PN_MLP_LANES; ++n)
                    for (rep = 0; rep < 4; ++rep)
                        t_lanes_block(pn__t, &net, dim, n, &rng, rep % 2 ? 1e-2 : 0.3, rep == 3 ? n / 2 : -1, worst);
                for (n = 1; n <= PN_MLP_LANES; ++n)
                    prep_worst = fmax(prep_worst, t_prepare_lanes(pn__t, &net, dim, n, n % 3 == 0 ? n / 2 : -1, &rng2));
                { /* the network alone, every lane count and n_diff */
                    const pn_mlp *mlp = &tm.model.mlp;
                    int nin = mlp->size[0], nd, i;
                    for (nd = 0; nd <= nin; ++nd) {
                        float in[PN_MLP_MAX_WIDTH * PN_MLP_LANES], o[PN_MLP_LANES], g[8 * PN_MLP_LANES];
                        float h[64 * PN_MLP_LANES];
                        for (k = 0; k < nin * PN_MLP_LANES; ++k) in[k] = (float)pn_test_rng_range(&rng, -2, 2);
                        PN_CHECK(pn_mlp_eval_lanes(mlp, 5, in, nd, o, g, h) == PN_OK);
                        for (i = 0; i < 5; ++i) {
                            double x[PN_MLP_MAX_WIDTH], ro, rg[8], rh[64], go[8], ho[64];
                            for (k = 0; k < nin; ++k) x[k] = in[k * PN_MLP_LANES + i];
                            PN_CHECK(pn_mlp_eval(mlp, x, nd, &ro, rg, rh) == PN_OK);
                            for (k = 0; k < nd; ++k) go[k] = g[k * PN_MLP_LANES + i];
                            for (k = 0; k < nd * nd; ++k) ho[k] = h[k * PN_MLP_LANES + i];
                            mlp_worst = fmax(mlp_worst, fabs(ro - o[i]) / (fabs(ro) + 1));
                            if (nd) mlp_worst = fmax(mlp_worst, t_lanes_rel(nd, rg, go));
                            if (nd) mlp_worst = fmax(mlp_worst, t_lanes_rel(nd * nd, rh, ho));
                        }
                    }
                }
            }
    { /* what the lanes refuse: softplus, more hidden units than PN_MLP_LANES_HIDDEN, NaN */
        pn_mlp m;
        float w[PN_MLP_MAX_WIDTH * PN_MLP_MAX_WIDTH], b[PN_MLP_MAX_WIDTH], in[PN_MLP_LANES * 4], o[PN_MLP_LANES];
        int size[4] = {4, 64, 64, 1};
        memset(w, 0, sizeof w), memset(b, 0, sizeof b), memset(in, 0, sizeof in);
        memset(&m, 0, sizeof m);
        m.n_layers = 3;
        m.activation = PN_ACTIVATION_SILU;
        for (k = 0; k <= 3; ++k) m.size[k] = size[k];
        for (k = 0; k < 3; ++k) m.weight[k] = w, m.bias[k] = b;
        format_refused = pn_mlp_eval_lanes(&m, 8, in, 0, o, NULL, NULL) == PN_ERROR_FORMAT; /* 128 hidden: fits */
        m.size[1] = m.size[2] = 33; /* 66 hidden: fits too; then softplus */
        format_refused = !format_refused && pn_mlp_eval_lanes(&m, 8, in, 0, o, NULL, NULL) == PN_OK;
        m.activation = PN_ACTIVATION_SOFTPLUS;
        format_refused = format_refused && pn_mlp_eval_lanes(&m, 8, in, 0, o, NULL, NULL) == PN_ERROR_FORMAT;
        m.activation = PN_ACTIVATION_SILU;
        m.n_layers = 4, m.size[3] = 64, m.size[4] = 1, m.weight[3] = w, m.bias[3] = b; /* 130 hidden */
        m.size[1] = 33;
        format_refused = format_refused && pn_mlp_eval_lanes(&m, 8, in, 0, o, NULL, NULL) == PN_ERROR_FORMAT;
        m.n_layers = 3, m.size[3] = 1;
        in[5] = (float)NAN;
        format_refused = format_refused && pn_mlp_eval_lanes(&m, 8, in, 0, o, NULL, NULL) == PN_ERROR_NONFINITE;
        PN_CHECK(format_refused);
    }
    PN_REPORT("network alone: worst relative error %.2e (value, gradient, Hessian)", mlp_worst);
    PN_REPORT("PlasticityNet energy, 2D and 3D, raw and scaled, silu and tanh: psi %.2e, P %.2e, dP/dF %.2e",
              worst[0], worst[1], worst[2]);
    PN_REPORT("pn_pnet_prepare_lanes: F0, h, features exact; C against pn_pnet_prepare %.2e relative", prep_worst);
    PN_CHECK_LE(prep_worst, 1e-4);
    PN_CHECK_LE(mlp_worst, 1e-5);
    PN_CHECK_LE(worst[0], 5e-5);
    PN_CHECK_LE(worst[1], 1e-4);
    PN_CHECK_LE(worst[2], 1e-4);
}

static const pn_test_case pn_tests_pnet_lanes[] = {
    {"pnet_lanes", pnet_lanes},
    {"pnet_lanes_exp_range", pnet_lanes_exp_range},
    {"pnet_lanes_nan_preactivation", pnet_lanes_nan_preactivation},
};
