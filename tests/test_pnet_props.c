/* test_pnet_props.c - plastinet.h's >>pnet room (pnet_*): the PlasticityNet energy's
   invariants (exact at F0, objectivity, isotropy, scaling with E), its PSD projection, and
   bad input to the learned-model API (the right code, every output untouched). Helpers:
   test_pnet_mlp.c. */

/* ================================================================================================
   3. Exactness at F0: P(F0; F0) = T(F0) = T0 of pn_pnet_prepare, which is the return mapping's
      (analytic for sand, learned for metal), for every regularizer.
   ================================================================================================ */

PN_TEST(pnet_exact_at_F0) {
    static const double regs[3] = {0, -1, 5};
    double worst = 0, worst_T0 = 0;
    long fails = 0, samples = 0, plastic = 0;
    int which, dim, ir, i;
    for (which = T_PN_SAND; which <= T_PN_METAL; ++which)
        for (dim = 2; dim <= 3; ++dim)
            for (ir = 0; ir < 3; ++ir) {
                t_pn_setup s;
                pn_test_rng rng;
                rng.s = 3000 + 100 * (unsigned long long)which + 10 * (unsigned long long)dim + (unsigned long long)ir;
                if (!t_pn_setup_make(pn__t, &s, which, dim, 1, regs[ir], 99)) return;
                for (i = 0; i < 100; ++i) {
                    const int n2 = dim * dim;
                    double F0[9], h, T0[9], P[9], H[81], Tr[9], Zr[9], hn = -1, hr = -2, den;
                    pn_pnet_point pt;
                    pn_result r;
                    if (i == 0) t_pn_identity(dim, F0);
                    else if (i < 10) t_pn_repeated(&rng, dim, F0);
                    else t_pn_box(&rng, dim, 1, NULL, NULL, NULL, F0);
                    h = pn_test_rng_range(&rng, 0, 1);
                    ++samples;
                    if (pn_pnet_prepare(&s.net, F0, h, &pt, &hn, T0) != PN_OK ||
                        pn_pnet_energy(&s.net, &pt, F0, NULL, P, i % 2 ? H : NULL, 0) != PN_OK) {
                        ++fails;
                        continue;
                    }
                    /* the scale of the cancellation C = grad N(F0) - T0 */
                    den = t_pn_maxabs(n2, T0) + t_pn_maxabs(n2, pt.C);
                    t_pn_worst(&worst, t_pn_rel(n2, P, T0, den));
                    /* T0 and h_new are the return mapping's */
                    r = which == T_PN_SAND ? pn_return_map(&s.m, dim, F0, h, Zr, &hr, Tr)
                                           : pn_learned_return_map(&s.rmap.model, &s.m, dim, F0, h, Zr, &hr, Tr);
                    fails += r != PN_OK;
                    t_pn_worst(&worst_T0, t_dist(n2, T0, Tr) + fabs(hn - hr));
                    plastic += t_dist(n2, Zr, F0) > 0;
                }
            }
    PN_REPORT("%ld samples (sand, metal with a learned return map; 2D, 3D; w = 1, off, 5; %ld plastic): "
              "|P(F0) - T0| / (|T0| + |C|) %.2e, T0 and h_new vs the return mapping %.2e, failed %ld",
              samples, plastic, worst, worst_T0, fails);
    PN_CHECK(fails == 0);
    PN_CHECK(plastic > samples / 2);
    PN_CHECK_LE(worst, T_PN_EXACT_TOL);
    PN_CHECK(worst_T0 == 0);
}

/* ================================================================================================
   4. Objectivity Psi(QF; QF0) = Psi(F; F0), P -> Q P, dP/dF -> Q Q dP/dF; isotropy
      Psi(FR; F0R) = Psi(F; F0), P -> P R, dP/dF -> dP/dF R R.
   ================================================================================================ */

/* Hr[(ij),(kl)] = sum Q_ia Q_kc H[(aj),(cl)] (left), or sum H[(ia),(kc)] R_aj R_cl (right) */
static void t_pn_rotate_hess(int dim, const double *Q, const double *H, int right, double *Hr) {
    const int n2 = dim * dim;
    int i, j, k, l, a, c;
    for (i = 0; i < dim; ++i)
        for (j = 0; j < dim; ++j)
            for (k = 0; k < dim; ++k)
                for (l = 0; l < dim; ++l) {
                    double acc = 0;
                    for (a = 0; a < dim; ++a)
                        for (c = 0; c < dim; ++c)
                            acc += right ? H[(i * dim + a) * n2 + k * dim + c] * Q[a * dim + j] * Q[c * dim + l]
                                         : Q[i * dim + a] * Q[k * dim + c] * H[(a * dim + j) * n2 + c * dim + l];
                    Hr[(i * dim + j) * n2 + k * dim + l] = acc;
                }
}

PN_TEST(pnet_objectivity_isotropy) {
    double worst[2][3] = {{0, 0, 0}, {0, 0, 0}}; /* [left, right][psi, P, dP/dF] */
    long fails = 0, samples = 0;
    int which, dim, i, side;
    for (which = T_PN_SAND; which <= T_PN_METAL; ++which)
        for (dim = 2; dim <= 3; ++dim) {
            t_pn_setup s;
            pn_test_rng rng;
            rng.s = 4000 + 10 * (unsigned long long)which + (unsigned long long)dim;
            if (!t_pn_setup_make(pn__t, &s, which, dim, 1, 0, 123)) return;
            for (i = 0; i < 40; ++i) {
                const int n2 = dim * dim, n4 = n2 * n2;
                double F0[9], F[9], h, psi = 0, P[9], H[81], Q[9];
                pn_pnet_point pt;
                t_pn_pair(&rng, dim, i % 2 ? T_PN_K_BOX : T_PN_K_NEAR, i, F0, F, &h);
                ++samples;
                if (pn_pnet_prepare(&s.net, F0, h, &pt, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&s.net, &pt, F, &psi, P, H, 0) != PN_OK) {
                    ++fails;
                    continue;
                }
                for (side = 0; side < 2; ++side) {
                    double QF0[9], QF[9], psiq = 0, Pq[9], Hq[81], Pref[9], Href[81], den;
                    pn_pnet_point ptq;
                    t_rand_rot(&rng, dim, Q);
                    if (side == 0) {
                        t_mul(dim, Q, F0, QF0);
                        t_mul(dim, Q, F, QF);
                        t_mul(dim, Q, P, Pref);
                    } else {
                        t_mul(dim, F0, Q, QF0);
                        t_mul(dim, F, Q, QF);
                        t_mul(dim, P, Q, Pref);
                    }
                    t_pn_rotate_hess(dim, Q, H, side, Href);
                    if (pn_pnet_prepare(&s.net, QF0, h, &ptq, NULL, NULL) != PN_OK ||
                        pn_pnet_energy(&s.net, &ptq, QF, &psiq, Pq, Hq, 0) != PN_OK) {
                        ++fails;
                        continue;
                    }
                    /* the scale of the terms that cancel in Psi and P: N, C : F */
                    den = fabs(psi) + t_norm(n2, pt.C) * t_norm(n2, F);
                    t_pn_worst(&worst[side][0], fabs(psiq - psi) / den);
                    t_pn_worst(&worst[side][1], t_pn_rel(n2, Pq, Pref, t_pn_maxabs(n2, pt.C)));
                    t_pn_worst(&worst[side][2], t_pn_rel(n4, Hq, Href, 1e-4));
                }
            }
        }
    PN_REPORT("%ld samples: left rotation Q F, Q F0: psi %.2e, P %.2e, dP/dF %.2e", samples, worst[0][0],
              worst[0][1], worst[0][2]);
    PN_REPORT("right rotation F R, F0 R: psi %.2e, P %.2e, dP/dF %.2e; failed %ld", worst[1][0], worst[1][1],
              worst[1][2], fails);
    PN_CHECK(fails == 0);
    for (side = 0; side < 2; ++side) {
        PN_CHECK_LE(worst[side][0], T_PN_INV_TOL);
        PN_CHECK_LE(worst[side][1], T_PN_INV_TOL);
        PN_CHECK_LE(worst[side][2], T_PN_INV_TOL);
    }
}

/* ================================================================================================
   5. Young's modulus: a net bound to the material at E = 1e7 gives 1e7 times psi, P, dP/dF and
      T0 of the one at E = 1 (the regularizer scales with mu).
   ================================================================================================ */

PN_TEST(pnet_E_scaling) {
    const double E = 1e7;
    double worst[4] = {0, 0, 0, 0};
    long fails = 0, samples = 0;
    int which, dim, i;
    for (which = T_PN_SAND; which <= T_PN_METAL; ++which)
        for (dim = 2; dim <= 3; ++dim) {
            t_pn_setup s1, sE;
            pn_test_rng rng;
            rng.s = 5000 + 10 * (unsigned long long)which + (unsigned long long)dim;
            if (!t_pn_setup_make(pn__t, &s1, which, dim, 1, 0, 321) ||
                !t_pn_setup_make(pn__t, &sE, which, dim, E, 0, 321))
                return;
            for (i = 0; i < 40; ++i) {
                const int n2 = dim * dim, n4 = n2 * n2;
                double F0[9], F[9], h, psi1 = 0, P1[9], H1[81], T1[9], psiE = 0, PE[9], HE[81], TE[9];
                int k;
                pn_pnet_point p1, pE;
                t_pn_pair(&rng, dim, i % 4, i, F0, F, &h);
                ++samples;
                if (pn_pnet_prepare(&s1.net, F0, h, &p1, NULL, T1) != PN_OK ||
                    pn_pnet_prepare(&sE.net, F0, h, &pE, NULL, TE) != PN_OK ||
                    pn_pnet_energy(&s1.net, &p1, F, &psi1, P1, H1, 0) != PN_OK ||
                    pn_pnet_energy(&sE.net, &pE, F, &psiE, PE, HE, 0) != PN_OK) {
                    ++fails;
                    continue;
                }
                for (k = 0; k < n2; ++k) {
                    P1[k] *= E;
                    T1[k] *= E;
                }
                for (k = 0; k < n4; ++k) H1[k] *= E;
                psi1 *= E;
                t_pn_worst(&worst[0], fabs(psiE - psi1) / (fabs(psi1) + E * t_norm(n2, p1.C) * t_norm(n2, F)));
                t_pn_worst(&worst[1], t_pn_rel(n2, PE, P1, E * t_pn_maxabs(n2, p1.C)));
                t_pn_worst(&worst[2], t_pn_rel(n4, HE, H1, E * 1e-4));
                t_pn_worst(&worst[3], t_pn_rel(n2, TE, T1, E * 1e-4));
            }
        }
    PN_REPORT("%ld samples, E = 1e7 vs E = 1 x 1e7: psi %.2e, P %.2e, dP/dF %.2e, T0 %.2e; failed %ld",
              samples, worst[0], worst[1], worst[2], worst[3], fails);
    PN_CHECK(fails == 0);
    for (i = 0; i < 4; ++i) PN_CHECK_LE(worst[i], T_PN_SCALE_TOL);
}

/* ================================================================================================
   6. PN_EVAL_PROJECT_PSD: no negative eigenvalue (pn_sym_eigen), the nearest PSD matrix of dP/dF
      (test_util.h's Jacobi solver), and dP/dF itself when that is PSD already (w = 1e4).
   ================================================================================================ */

PN_TEST(pnet_project_psd) {
    double worst_neg = 0, worst_near = 0, worst_same = 0, worst_premise = -HUGE_VAL;
    long fails = 0, samples = 0, indefinite = 0, psd_samples = 0, psd_w1 = 0;
    int dim, i, big;
    for (dim = 2; dim <= 3; ++dim)
        for (big = 0; big < 2; ++big) {
            t_pn_setup s;
            pn_test_rng rng;
            rng.s = 6000 + 10 * (unsigned long long)dim + (unsigned long long)big;
            if (!t_pn_setup_make(pn__t, &s, T_PN_SAND, dim, 1, big ? 1e4 : 0, 555)) return;
            for (i = 0; i < 60; ++i) {
                const int n2 = dim * dim, n4 = n2 * n2;
                double F0[9], F[9], h, H[81], Hp[81], Q[81], w[9], ref[81], mn, scale;
                pn_real Qe[81], we[9];
                pn_pnet_point pt;
                int k;
                t_pn_pair(&rng, dim, i % 4, i, F0, F, &h);
                ++samples;
                if (pn_pnet_prepare(&s.net, F0, h, &pt, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&s.net, &pt, F, NULL, NULL, H, 0) != PN_OK ||
                    pn_pnet_energy(&s.net, &pt, F, NULL, NULL, Hp, PN_EVAL_PROJECT_PSD) != PN_OK ||
                    pn_sym_eigen(n2, Hp, Qe, we) != PN_OK) {
                    ++fails;
                    continue;
                }
                scale = t_norm(n4, H);
                for (k = 0; k < n2; ++k) t_pn_worst(&worst_neg, -we[k] / scale);
                t_jacobi(n2, H, Q, w);
                mn = t_psd_rebuild(n2, Q, w, ref);
                if (big) {
                    /* w mu = 3.8e3: dP/dF is PSD and must come back unchanged */
                    ++psd_samples;
                    t_pn_worst(&worst_premise, -mn / scale);
                    t_pn_worst(&worst_same, t_dist(n4, Hp, H) / scale);
                } else {
                    indefinite += mn < -1e-8 * scale;
                    t_pn_worst(&worst_near, t_dist(n4, Hp, ref) / scale);
                    if (mn > 1e-8 * scale) { /* PSD already at w = 1 */
                        ++psd_w1;
                        t_pn_worst(&worst_same, t_dist(n4, Hp, H) / scale);
                    }
                }
            }
        }
    PN_REPORT("%ld samples (%ld indefinite, %ld PSD dP/dF at w = 1): smallest eigenvalue of the "
              "projection %.2e |dP/dF|, vs the nearest PSD matrix %.2e; PSD ones (and all at w = 1e4, "
              "smallest eigenvalue >= %.2e |dP/dF|) changed by %.2e; failed %ld",
              samples, indefinite, psd_w1, -worst_neg, worst_near, -worst_premise, worst_same, fails);
    PN_CHECK(fails == 0);
    PN_CHECK(indefinite > 0 && psd_w1 > 0);
    PN_CHECK(psd_samples > 0 && worst_premise < 0);
    PN_CHECK_LE(worst_neg, 1e-10);
    PN_CHECK_LE(worst_near, 1e-10);
    PN_CHECK_LE(worst_same, 1e-12);
}

/* ================================================================================================
   7. Bad input: the right code, every output untouched (the pn_pnet and pn_pnet_point structs
      compared byte for byte), a reason for pn_pnet_init failures.
   ================================================================================================ */

typedef struct t_pn_bad {
    pn_test_ctx *t;
    int calls, wrong;
} t_pn_bad;

static void t_pn_bad_report(t_pn_bad *b, const char *what, int r, int want, const char *extra) {
    b->calls++;
    if (r == want && !extra) return;
    b->wrong++;
    if (b->wrong <= 20)
        fprintf(stderr, "      %s: result %d (want %d)%s%s\n", what, r, want, extra ? ", " : "",
                extra ? extra : "");
}

/* pn_pnet_init must fail with want, name a reason (containing why_has if not NULL) and leave
   the net untouched: once filled with a byte pattern, once holding a valid binding. */
static void t_pn_expect_init(t_pn_bad *b, const char *what, const pn_pnet_desc *desc,
                             const pn_material *m, int dim, pn_result want, const char *why_has,
                             const pn_pnet *valid) {
    int pass;
    for (pass = 0; pass < 2; ++pass) {
        pn_pnet net, keep;
        char why[256] = "";
        pn_result r;
        if (pass == 0) memset(&net, 0x5A, sizeof net);
        else memcpy(&net, valid, sizeof net);
        memcpy(&keep, &net, sizeof net);
        r = pn_pnet_init(&net, desc, m, dim, why, sizeof why);
        if (memcmp(&net, &keep, sizeof net) != 0) t_pn_bad_report(b, what, (int)r, (int)want, "net modified");
        else if (!why[0]) t_pn_bad_report(b, what, (int)r, (int)want, "no reason");
        else if (why_has && !strstr(why, why_has)) t_pn_bad_report(b, what, (int)r, (int)want, why);
        else t_pn_bad_report(b, what, (int)r, (int)want, NULL);
    }
    /* a NULL why is accepted */
    {
        pn_pnet net;
        t_pn_bad_report(b, what, (int)pn_pnet_init(&net, desc, m, dim, NULL, 0), (int)want, NULL);
    }
}

/* pn_pnet_prepare must fail with want and leave pt, h_new, T0 untouched */
static void t_pn_expect_prepare(t_pn_bad *b, const char *what, const pn_pnet *net, const double *F0,
                                double h, pn_result want) {
    pn_pnet_point pt, keep;
    pn_pnet net_keep;
    double hn = -7.25, T0[9];
    int k, touched = 0;
    pn_result r;
    for (k = 0; k < 9; ++k) T0[k] = -7.25;
    memset(&pt, 0xA5, sizeof pt);
    memcpy(&keep, &pt, sizeof pt);
    memcpy(&net_keep, net, sizeof net_keep);
    r = pn_pnet_prepare(net, F0, h, &pt, &hn, T0);
    touched = memcmp(&pt, &keep, sizeof pt) != 0 || hn != -7.25 || memcmp(&net_keep, net, sizeof net_keep) != 0;
    for (k = 0; k < 9; ++k) touched |= T0[k] != -7.25;
    t_pn_bad_report(b, what, (int)r, (int)want, touched ? "outputs modified" : NULL);
}

/* pn_pnet_energy must fail with want and leave psi, P, dP/dF (and the point) untouched */
static void t_pn_expect_energy(t_pn_bad *b, const char *what, const pn_pnet *net,
                               const pn_pnet_point *pt, const double *F, pn_result want) {
    pn_pnet_point keep;
    double psi = -7.25, P[9], H[81];
    int k, touched = 0;
    pn_result r;
    for (k = 0; k < 81; ++k) H[k] = -7.25;
    for (k = 0; k < 9; ++k) P[k] = -7.25;
    memcpy(&keep, pt, sizeof keep);
    r = pn_pnet_energy(net, pt, F, &psi, P, H, PN_EVAL_PROJECT_PSD);
    touched = psi != -7.25 || memcmp(&keep, pt, sizeof keep) != 0;
    for (k = 0; k < 81; ++k) touched |= H[k] != -7.25;
    for (k = 0; k < 9; ++k) touched |= P[k] != -7.25;
    t_pn_bad_report(b, what, (int)r, (int)want, touched ? "outputs modified" : NULL);
}

/* pn_learned_return_map must fail with want and leave Z, h_new, T untouched */
static void t_pn_expect_lrm(t_pn_bad *b, const char *what, const pn_model *mo, const pn_material *m,
                            int dim, const double *F, double h, pn_result want) {
    double Z[9], T[9], hn = -7.25;
    int k, touched = 0;
    pn_result r;
    for (k = 0; k < 9; ++k) Z[k] = T[k] = -7.25;
    r = pn_learned_return_map(mo, m, dim, F, h, Z, &hn, T);
    touched = hn != -7.25;
    for (k = 0; k < 9; ++k) touched |= Z[k] != -7.25 || T[k] != -7.25;
    t_pn_bad_report(b, what, (int)r, (int)want, touched ? "outputs modified" : NULL);
}

PN_TEST(pnet_bad_input) {
    const double nan = HUGE_VAL - HUGE_VAL, inf = HUGE_VAL;
    t_pn_setup sand2, sand3, metal2, metal3;
    t_pn_model bad; /* a model copied from sand2.energy, then broken (its mlp still points
                       into sand2.energy.buf) */
    pn_pnet_desc desc;
    pn_material m;
    pn_material_desc md;
    t_pn_bad b;
    double F[9], Fbad[9];
    pn_pnet_point pt;
    int dim, k;
    b.t = pn__t;
    b.calls = b.wrong = 0;
    if (!t_pn_setup_make(pn__t, &sand2, T_PN_SAND, 2, 1, 0, 1) ||
        !t_pn_setup_make(pn__t, &sand3, T_PN_SAND, 3, 1, 0, 2) ||
        !t_pn_setup_make(pn__t, &metal2, T_PN_METAL, 2, 1, 0, 3) ||
        !t_pn_setup_make(pn__t, &metal3, T_PN_METAL, 3, 1, 0, 4))
        return;

    /* ---- pn_pnet_init / pn_model_check ---- */
    memset(&desc, 0, sizeof desc);
    desc.energy = &sand3.energy.model;
    t_pn_expect_init(&b, "3D model, dim 2", &desc, &sand2.m, 2, PN_ERROR_DIMENSION, NULL, &sand2.net);
    desc.energy = &sand2.energy.model;
    t_pn_expect_init(&b, "2D model, dim 3", &desc, &sand2.m, 3, PN_ERROR_DIMENSION, NULL, &sand2.net);
#define T_PN_BROKEN(what, stmt, want)                                                               \
    do {                                                                                            \
        char why_[256] = "";                                                                    \
        pn_result r_;                                                                               \
        bad.model = sand2.energy.model;                                                             \
        stmt;                                                                                       \
        desc.energy = &bad.model;                                                                   \
        t_pn_expect_init(&b, what, &desc, &sand2.m, 2, want, NULL, &sand2.net);                     \
        r_ = pn_model_check(&bad.model, 0, why_, sizeof why_);                                                  \
        t_pn_bad_report(&b, what " (pn_model_check)", (int)r_, (int)want, why_[0] ? NULL : "no reason"); \
    } while (0)
    T_PN_BROKEN("format_version + 1", bad.model.format_version++, PN_ERROR_FORMAT);
    T_PN_BROKEN("format_version 0", bad.model.format_version = 0, PN_ERROR_FORMAT);
    T_PN_BROKEN("unknown kind", bad.model.kind = (pn_model_kind)7, PN_ERROR_FORMAT);
    T_PN_BROKEN("model dim 4", bad.model.dim = 4, PN_ERROR_DIMENSION);
    T_PN_BROKEN("mlp n_layers 0", bad.model.mlp.n_layers = 0, PN_ERROR_FORMAT);
    T_PN_BROKEN("mlp n_layers 9", bad.model.mlp.n_layers = PN_MLP_MAX_LAYERS + 1, PN_ERROR_FORMAT);
    T_PN_BROKEN("mlp width 0", bad.model.mlp.size[1] = 0, PN_ERROR_FORMAT);
    T_PN_BROKEN("mlp width > PN_MLP_MAX_WIDTH", bad.model.mlp.size[2] = PN_MLP_MAX_WIDTH + 1, PN_ERROR_FORMAT);
    T_PN_BROKEN("mlp weight NULL", bad.model.mlp.weight[1] = NULL, PN_ERROR_FORMAT);
    T_PN_BROKEN("mlp bias NULL", bad.model.mlp.bias[2] = NULL, PN_ERROR_FORMAT);
    T_PN_BROKEN("activation 0", bad.model.mlp.activation = (pn_activation)0, PN_ERROR_FORMAT);
    T_PN_BROKEN("activation 4", bad.model.mlp.activation = (pn_activation)4, PN_ERROR_FORMAT);
    T_PN_BROKEN("n_inputs != size[0]", bad.model.n_inputs = 4, PN_ERROR_FORMAT);
    T_PN_BROKEN("inputs not 2 nf + 1", (bad.model.n_inputs = 4, bad.model.mlp.size[0] = 4), PN_ERROR_FORMAT);
    T_PN_BROKEN("two outputs", bad.model.mlp.size[3] = 2, PN_ERROR_FORMAT);
    T_PN_BROKEN("E_train 0", bad.model.youngs_modulus_train_pa = 0, PN_ERROR_FORMAT);
    T_PN_BROKEN("E_train NaN", bad.model.youngs_modulus_train_pa = nan, PN_ERROR_FORMAT);
    T_PN_BROKEN("h_min > h_max", bad.model.h_min = 2, PN_ERROR_FORMAT);
    /* layer sizes that disagree with the arrays: pn_mlp_eval would read past them (ASan) */
    T_PN_BROKEN("hidden size 9, arrays of 8", bad.model.mlp.size[1] = 9, PN_ERROR_FORMAT);
    T_PN_BROKEN("weight_count short", bad.model.mlp.weight_count[2] -= 1, PN_ERROR_FORMAT);
    T_PN_BROKEN("format 2 without lengths", (bad.model.mlp.weight_count[0] = 0, bad.model.mlp.bias_count[0] = 0),
                PN_ERROR_FORMAT);
    /* only layer 0 was required to declare its lengths: a later layer without them (its
       sizes then unchecked) was read past by pn_model_check itself (tests/fuzz/corpus/
       model_check/layer1_no_lengths) */
    T_PN_BROKEN("a hidden layer without its lengths", (bad.model.mlp.weight_count[1] = 0, bad.model.mlp.bias_count[1] = 0),
                PN_ERROR_FORMAT);
    T_PN_BROKEN("NaN weight", t_pn_model_poison(&bad, &sand2.energy, 1, nan), PN_ERROR_FORMAT);
    T_PN_BROKEN("inf bias", t_pn_model_poison(&bad, &sand2.energy, 0, inf), PN_ERROR_FORMAT);
#undef T_PN_BROKEN
    desc.energy = NULL;
    t_pn_expect_init(&b, "energy NULL", &desc, &sand2.m, 2, PN_ERROR_INVALID_ARGUMENT, NULL, &sand2.net);
    desc.energy = &metal2.rmap.model;
    t_pn_expect_init(&b, "a return map as the energy", &desc, &metal2.m, 2, PN_ERROR_INVALID_ARGUMENT, NULL,
                     &sand2.net);
    /* materials that differ from the training material */
    desc.energy = &sand2.energy.model;
    t_pn_desc(&md, T_PN_SAND, 1e7);
    md.poisson_ratio = 0.25;
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    t_pn_expect_init(&b, "poisson_ratio 0.25", &desc, &m, 2, PN_ERROR_INVALID_PARAMETER, "poisson_ratio", &sand2.net);
    t_pn_desc(&md, T_PN_SAND, 1e7);
    md.friction_angle_deg = 35;
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    t_pn_expect_init(&b, "friction 35", &desc, &m, 2, PN_ERROR_INVALID_PARAMETER, "friction_angle_deg", &sand2.net);
    t_pn_desc(&md, T_PN_SAND, 1e7);
    md.volume_correction = 1;
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    t_pn_expect_init(&b, "volume correction", &desc, &m, 2, PN_ERROR_INVALID_PARAMETER, "volume_correction", &sand2.net);
    t_pn_desc(&md, T_PN_METAL, 1e7);
    md.elastic = PN_ELASTIC_STVK_HENCKY; /* the sand model's elasticity */
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    t_pn_expect_init(&b, "metal material, sand model", &desc, &m, 2, PN_ERROR_INVALID_PARAMETER, "plastic",
                     &sand2.net);
    desc.energy = &metal2.energy.model;
    desc.return_map = &metal2.rmap.model;
    t_pn_desc(&md, T_PN_METAL, 1e7);
    md.elastic = PN_ELASTIC_STVK_HENCKY;
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    t_pn_expect_init(&b, "StVK metal, Neo-Hookean model", &desc, &m, 2, PN_ERROR_INVALID_PARAMETER, "elastic", &metal2.net);
    t_pn_desc(&md, T_PN_METAL, 1e7);
    md.yield_stress_pa = 4e-3 * 1e7;
    PN_CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    t_pn_expect_init(&b, "yield stress", &desc, &m, 2, PN_ERROR_INVALID_PARAMETER, "yield_stress_pa", &metal2.net);
    /* the return mapping the energy names */
    desc.return_map = NULL;
    t_pn_expect_init(&b, "energy names a return map, desc.return_map NULL", &desc, &metal2.m, 2,
                     PN_ERROR_INVALID_ARGUMENT, "return_map", &metal2.net);
    desc.energy = &metal3.energy.model;
    desc.return_map = &metal2.rmap.model; /* right name, wrong dimension */
    t_pn_expect_init(&b, "2D return map for a 3D energy", &desc, &metal3.m, 3, PN_ERROR_DIMENSION, NULL, &metal3.net);
    bad.model = metal2.rmap.model;
    bad.model.name = "another_return";
    desc.energy = &metal2.energy.model;
    desc.return_map = &bad.model;
    t_pn_expect_init(&b, "return map of another name", &desc, &metal2.m, 2, PN_ERROR_INVALID_ARGUMENT, "return_map",
                     &metal2.net);
    desc.energy = &sand2.energy.model;
    desc.return_map = &metal2.rmap.model;
    t_pn_expect_init(&b, "a return map for an analytic energy", &desc, &sand2.m, 2, PN_ERROR_INVALID_ARGUMENT,
                     "return_map", &sand2.net);
    desc.return_map = NULL;
    desc.regularizer = nan;
    t_pn_expect_init(&b, "regularizer NaN", &desc, &sand2.m, 2, PN_ERROR_NONFINITE, "regularizer", &sand2.net);
    desc.regularizer = inf;
    t_pn_expect_init(&b, "regularizer inf", &desc, &sand2.m, 2, PN_ERROR_NONFINITE, "regularizer", &sand2.net);

    /* ---- pn_pnet_prepare, pn_pnet_energy ---- */
    for (dim = 2; dim <= 3; ++dim) {
        const t_pn_setup *s = dim == 2 ? &sand2 : &sand3, *mt = dim == 2 ? &metal2 : &metal3;
        const int n2 = dim * dim;
        pn_test_rng rng;
        rng.s = 7000 + (unsigned long long)dim;
        t_pn_box(&rng, dim, 0.5, NULL, NULL, NULL, F);
        PN_CHECK(pn_pnet_prepare(&s->net, F, 0.1, &pt, NULL, NULL) == PN_OK);
        for (k = 0; k < n2; ++k) {
            memcpy(Fbad, F, sizeof Fbad);
            Fbad[k] = k % 2 ? nan : -inf;
            t_pn_expect_prepare(&b, "prepare, NaN/inf in F0", &s->net, Fbad, 0.1, PN_ERROR_NONFINITE);
            t_pn_expect_energy(&b, "energy, NaN/inf in F", &s->net, &pt, Fbad, PN_ERROR_NONFINITE);
        }
        t_pn_expect_prepare(&b, "prepare, NaN h", &s->net, F, nan, PN_ERROR_NONFINITE);
        t_pn_expect_prepare(&b, "prepare, inf h", &s->net, F, inf, PN_ERROR_NONFINITE);
        t_pn_expect_prepare(&b, "prepare (learned return map), NaN h", &mt->net, F, nan, PN_ERROR_NONFINITE);
        t_pn_expect_prepare(&b, "prepare (learned return map), h < 0", &mt->net, F, -0.1, PN_ERROR_INVALID_ARGUMENT);
        /* det F < 0 (a reflection) and det F = 0 (a zero row) */
        memcpy(Fbad, F, sizeof Fbad);
        for (k = 0; k < dim; ++k) Fbad[k] = -Fbad[k];
        t_pn_expect_prepare(&b, "prepare, det F0 < 0", &s->net, Fbad, 0.1, PN_ERROR_INVERTED);
        t_pn_expect_energy(&b, "energy, det F < 0", &s->net, &pt, Fbad, PN_ERROR_INVERTED);
        t_pn_expect_energy(&b, "energy (learned return map), det F < 0", &mt->net, &pt, Fbad, PN_ERROR_INVERTED);
        for (k = 0; k < dim; ++k) Fbad[k] = 0;
        t_pn_expect_prepare(&b, "prepare, det F0 = 0", &s->net, Fbad, 0.1, PN_ERROR_INVERTED);
        t_pn_expect_energy(&b, "energy, det F = 0", &s->net, &pt, Fbad, PN_ERROR_INVERTED);

        /* ---- pn_learned_return_map ---- */
        {
            const pn_model *rm = &mt->rmap.model;
            double Fp[9], s3[3] = {1.3, 0.8, 1}, R[9];
            t_rand_rot(&rng, dim, R);
            t_adb(dim, R, s3, R, Fp); /* plastic: |e_hat| ~ 0.35 */
            memcpy(Fbad, Fp, sizeof Fbad);
            Fbad[1] = nan;
            t_pn_expect_lrm(&b, "learned return map, NaN in F", rm, &mt->m, dim, Fbad, 0.1, PN_ERROR_NONFINITE);
            t_pn_expect_lrm(&b, "learned return map, NaN h", rm, &mt->m, dim, Fp, nan, PN_ERROR_NONFINITE);
            t_pn_expect_lrm(&b, "learned return map, inf h", rm, &mt->m, dim, Fp, inf, PN_ERROR_NONFINITE);
            t_pn_expect_lrm(&b, "learned return map, h < 0", rm, &mt->m, dim, Fp, -1e-3, PN_ERROR_INVALID_ARGUMENT);
            memcpy(Fbad, Fp, sizeof Fbad);
            for (k = 0; k < dim; ++k) Fbad[k] = -Fbad[k];
            t_pn_expect_lrm(&b, "learned return map, det F < 0", rm, &mt->m, dim, Fbad, 0.1, PN_ERROR_INVERTED);
            t_pn_expect_lrm(&b, "learned return map, an energy model", &mt->energy.model, &mt->m, dim, Fp, 0.1,
                            PN_ERROR_INVALID_ARGUMENT);
            t_pn_expect_lrm(&b, "learned return map, sand material", rm, &s->m, dim, Fp, 0.1,
                            PN_ERROR_INVALID_PARAMETER);
            t_pn_expect_lrm(&b, "learned return map, other dim", dim == 2 ? &metal3.rmap.model : &metal2.rmap.model,
                            &mt->m, dim, Fp, 0.1, PN_ERROR_DIMENSION);
            bad.model = *rm;
            bad.model.format_version = PN_MODEL_FORMAT_VERSION + 1;
            t_pn_expect_lrm(&b, "learned return map, format version", &bad.model, &mt->m, dim, Fp, 0.1,
                            PN_ERROR_FORMAT);
        }
    }

    /* ---- pn_mlp_eval ---- */
    {
        pn_mlp mlp = sand2.energy.model.mlp, big;
        double u[5] = {0.1, -0.2, 0.3, 0.4, -0.5}, out = -7.25, g[20], H[80];
        static const float w_huge[1] = {1e38f}, b_zero[1] = {0};
        pn_result r;
        int touched;
#define T_PN_MLP(what, mlp_, in_, nd, want)                                                          \
    do {                                                                                             \
        for (k = 0; k < 20; ++k) g[k] = -7.25;                                                       \
        for (k = 0; k < 80; ++k) H[k] = -7.25;                                                       \
        out = -7.25;                                                                                 \
        r = pn_mlp_eval(mlp_, in_, nd, &out, g, H);                                                  \
        touched = out != -7.25;                                                                      \
        for (k = 0; k < 20; ++k) touched |= g[k] != -7.25;                                           \
        for (k = 0; k < 80; ++k) touched |= H[k] != -7.25;                                           \
        t_pn_bad_report(&b, what, (int)r, (int)want, touched ? "outputs modified" : NULL);          \
    } while (0)
        T_PN_MLP("mlp, n_diff 5", &mlp, u, PN_MLP_MAX_DIFF + 1, PN_ERROR_FORMAT);
        T_PN_MLP("mlp, n_diff -1", &mlp, u, -1, PN_ERROR_FORMAT);
        mlp.size[0] = 3;
        mlp.size[1] = 8;
        T_PN_MLP("mlp, n_diff > inputs", &mlp, u, 4, PN_ERROR_FORMAT);
        mlp = sand2.energy.model.mlp;
        mlp.n_layers = 0;
        T_PN_MLP("mlp, no layer", &mlp, u, 1, PN_ERROR_FORMAT);
        mlp = sand2.energy.model.mlp;
        u[2] = nan;
        T_PN_MLP("mlp, NaN input", &mlp, u, 2, PN_ERROR_NONFINITE);
        u[2] = 0.3;
        /* 1e38 x 1e300 overflows */
        memset(&big, 0, sizeof big);
        big.n_layers = 1;
        big.size[0] = big.size[1] = 1;
        big.activation = PN_ACTIVATION_TANH;
        big.weight[0] = w_huge;
        big.bias[0] = b_zero;
        u[0] = 1e300;
        T_PN_MLP("mlp, overflow", &big, u, 1, PN_ERROR_OVERFLOW);
        /* finite value and first output, second output's Hessian overflows: silu at z = 0
           (s' = s'' = 1/2) through four hidden layers of weight 1e38, x = 0, so the tangent of
           the last hidden unit is 1.25e151; output 0 reads it with weight 1 (Hessian 7.8e301),
           output 1 with weight FLT_MAX (inf). Nothing may be written. */
        {
            static const float w1e38[1] = {1e38f}, w_out[2] = {1, 3.4e38f}, b_out[2] = {0, 0};
            int l;
            memset(&big, 0, sizeof big);
            big.n_layers = 5;
            big.activation = PN_ACTIVATION_SILU;
            for (l = 0; l < 5; ++l) {
                big.size[l] = 1;
                big.weight[l] = l < 4 ? w1e38 : w_out;
                big.bias[l] = l < 4 ? b_zero : b_out;
            }
            big.size[5] = 2;
            u[0] = 0;
            T_PN_MLP("mlp, Hessian of the second output overflows", &big, u, 1, PN_ERROR_OVERFLOW);
        }
#undef T_PN_MLP
    }
    PN_REPORT("%d bad calls (pn_pnet_init, pn_model_check, pn_pnet_prepare, pn_pnet_energy, "
              "pn_learned_return_map, pn_mlp_eval): %d wrong code, reason or modified output",
              b.calls, b.wrong);
    PN_CHECK(b.calls > 100);
    PN_CHECK(b.wrong == 0);
}

static const pn_test_case pn_tests_pnet_props[] = {
    {"pnet_exact_at_F0", pnet_exact_at_F0},
    {"pnet_objectivity_isotropy", pnet_objectivity_isotropy},
    {"pnet_E_scaling", pnet_E_scaling},
    {"pnet_project_psd", pnet_project_psd},
    {"pnet_bad_input", pnet_bad_input},
};
