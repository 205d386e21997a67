/* test_pnet_energy.c - plastinet.h's >>features and >>pnet rooms (pnet_*): the PlasticityNet
   energy (pn_pnet_init / pn_pnet_prepare / pn_pnet_energy) against finite differences and
   against a reference written from its definition, for the raw and the scaled encoding,
   conditioned models and a base energy. Helpers: test_pnet_mlp.c. */

/* ================================================================================================
   2. pn_pnet_energy: P against differences of Psi, dP/dF against differences of P, on F near F0,
      F from the sampling box, F = I and F with repeated singular values; the regularizer term.
   ================================================================================================ */

enum { T_PN_K_NEAR, T_PN_K_BOX, T_PN_K_IDENTITY, T_PN_K_REPEATED, T_PN_NK };
static const char *const t_pn_kind_name[T_PN_NK] = {"F near F0", "F from the box", "F = I",
                                                    "repeated singular values"};

/* F0, F, h of one sample of the given kind (i counts the samples of that kind) */
static void t_pn_pair(pn_test_rng *rng, int dim, int kind, int i, double *F0, double *F, double *h) {
    double e[3], R1[9], R2[9], s[3];
    int k;
    *h = i % 5 == 0 ? 0 : pn_test_rng_range(rng, 0, 1.2); /* beyond h_max: the clamp */
    switch (kind) {
    case T_PN_K_NEAR:
        t_pn_box(rng, dim, 1, NULL, NULL, NULL, F0);
        t_pn_near(rng, dim, F0, 0.05, F);
        break;
    case T_PN_K_BOX:
        t_pn_box(rng, dim, 1, e, NULL, NULL, F0);
        t_rand_rot(rng, dim, R1);
        t_rand_rot(rng, dim, R2);
        for (k = 0; k < dim; ++k) s[k] = exp(e[k] + pn_test_rng_range(rng, -0.1, 0.1));
        t_adb(dim, R1, s, R2, F);
        break;
    case T_PN_K_IDENTITY:
        if (i == 0) t_pn_identity(dim, F0);
        else if (i == 1) t_pn_repeated(rng, dim, F0);
        else t_pn_box(rng, dim, 1, NULL, NULL, NULL, F0);
        t_pn_identity(dim, F);
        break;
    default:
        if (i % 2) t_pn_repeated(rng, dim, F0);
        else t_pn_box(rng, dim, 1, NULL, NULL, NULL, F0);
        t_pn_repeated(rng, dim, F);
        if (i == 0) memcpy(F0, F, sizeof(double) * (size_t)(dim * dim));
        break;
    }
}

PN_TEST(pnet_fd) {
    static const int count[T_PN_NK] = {30, 15, 6, 12};
    double worst_g[T_PN_NK] = {0, 0, 0, 0}, worst_h[T_PN_NK] = {0, 0, 0, 0}, worst_sym = 0, worst_reg = 0;
    double worst_opt = 0, worst_sg = 0, worst_sh = 0, worst_sreg = 0;
    long fails = 0, samples = 0;
    int which, dim, kind, i;
    for (which = T_PN_SAND; which <= T_PN_METAL; ++which)
        for (dim = 2; dim <= 3; ++dim) {
            t_pn_setup s, s_off, s_two;
            pn_pnet str; /* s's model with the strain regularizer, w = 1 */
            pn_pnet_desc sd;
            pn_test_rng rng;
            rng.s = 1000 + 10 * (unsigned long long)which + (unsigned long long)dim;
            /* the same models (same seed) with the regularizer off and at w = 2 */
            if (!t_pn_setup_make(pn__t, &s, which, dim, 1, 0, 77 + (unsigned long long)dim) ||
                !t_pn_setup_make(pn__t, &s_off, which, dim, 1, -1, 77 + (unsigned long long)dim) ||
                !t_pn_setup_make(pn__t, &s_two, which, dim, 1, 2, 77 + (unsigned long long)dim))
                return;
            memset(&sd, 0, sizeof sd);
            sd.energy = s.net.energy, sd.return_map = s.net.return_map, sd.regularizer_form = PN_PNET_REG_STRAIN;
            PN_CHECK(pn_pnet_init(&str, &sd, &s.m, dim, NULL, 0) == PN_OK);
            sd.regularizer_form = (pn_pnet_regularizer)7;
            PN_CHECK(pn_pnet_init(&str, &sd, &s.m, dim, NULL, 0) == PN_ERROR_INVALID_ARGUMENT);
            sd.regularizer_form = PN_PNET_REG_STRAIN;
            PN_CHECK(pn_pnet_init(&str, &sd, &s.m, dim, NULL, 0) == PN_OK);
            for (kind = 0; kind < T_PN_NK; ++kind)
                for (i = 0; i < count[kind]; ++i) {
                    const int n2 = dim * dim, n4 = n2 * n2;
                    double F0[9], F[9], h, psi = 0, P[9], H[81], fd[81], psi_off = 0, psi_two = 0, d2 = 0;
                    double psi1 = 0, P1[9], P2[9], den;
                    pn_pnet_point pt, pt_off, pt_two;
                    int k;
                    t_pn_pair(&rng, dim, kind, i, F0, F, &h);
                    ++samples;
                    if (pn_pnet_prepare(&s.net, F0, h, &pt, NULL, NULL) != PN_OK ||
                        pn_pnet_energy(&s.net, &pt, F, &psi, P, H, 0) != PN_OK) {
                        ++fails;
                        continue;
                    }
                    fails += t_pn_fd(&s.net, &pt, dim, F, 5e-4, 0, fd);
                    t_pn_worst(&worst_g[kind], t_pn_rel(n2, fd, P, 1e-4));
                    fails += t_pn_fd(&s.net, &pt, dim, F, 5e-4, 1, fd);
                    t_pn_worst(&worst_h[kind], t_pn_rel(n4, fd, H, 1e-4));
                    t_pn_worst(&worst_sym, t_asym(n2, H) / (t_norm(n4, H) + 1e-300));
                    /* the optional outputs do not change each other */
                    fails += pn_pnet_energy(&s.net, &pt, F, &psi1, NULL, NULL, 0) != PN_OK;
                    fails += pn_pnet_energy(&s.net, &pt, F, NULL, P1, NULL, 0) != PN_OK;
                    fails += pn_pnet_energy(&s.net, &pt, F, NULL, P2, H, 0) != PN_OK;
                    t_pn_worst(&worst_opt, (fabs(psi1 - psi) + t_dist(n2, P1, P) + t_dist(n2, P2, P)) /
                                               (fabs(psi) + t_norm(n2, P) + t_norm(n2, pt.C) * t_norm(n2, F)));
                    /* Eq. 11: Psi_w - Psi_off = w mu / 2 |F - F0|^2 */
                    fails += pn_pnet_prepare(&s_off.net, F0, h, &pt_off, NULL, NULL) != PN_OK;
                    fails += pn_pnet_prepare(&s_two.net, F0, h, &pt_two, NULL, NULL) != PN_OK;
                    fails += pn_pnet_energy(&s_off.net, &pt_off, F, &psi_off, NULL, NULL, 0) != PN_OK;
                    fails += pn_pnet_energy(&s_two.net, &pt_two, F, &psi_two, NULL, NULL, 0) != PN_OK;
                    for (k = 0; k < n2; ++k) d2 += (F[k] - F0[k]) * (F[k] - F0[k]);
                    /* relative to the terms that cancel in Psi: N, C : F, reg/2 |F - F0|^2 */
                    den = fabs(psi) + fabs(psi_two) + fabs(psi_off) + t_norm(n2, pt.C) * t_norm(n2, F);
                    t_pn_worst(&worst_reg, fabs((psi - psi_off) - s.m.mu / 2 * d2) / den);
                    t_pn_worst(&worst_reg, fabs((psi_two - psi_off) - s.m.mu * d2) / den);
                    { /* the strain form: Psi_s - Psi_off = mu/8 |F^T F - F0^T F0|^2, and its derivatives */
                        double psi_s = 0, Ps[9], Hs[81], dc2 = 0;
                        pn_pnet_point pt_s;
                        int a, b, l;
                        fails += pn_pnet_prepare(&str, F0, h, &pt_s, NULL, NULL) != PN_OK;
                        fails += pn_pnet_energy(&str, &pt_s, F, &psi_s, Ps, Hs, 0) != PN_OK;
                        for (a = 0; a < dim; ++a)
                            for (b = 0; b < dim; ++b) {
                                double c = 0;
                                for (l = 0; l < dim; ++l) c += F[l * dim + a] * F[l * dim + b] - F0[l * dim + a] * F0[l * dim + b];
                                dc2 += c * c;
                            }
                        t_pn_worst(&worst_sreg, fabs((psi_s - psi_off) - s.m.mu / 8 * dc2) / (den + fabs(psi_s)));
                        fails += t_pn_fd(&str, &pt_s, dim, F, 5e-4, 0, fd);
                        t_pn_worst(&worst_sg, t_pn_rel(n2, fd, Ps, 1e-4));
                        fails += t_pn_fd(&str, &pt_s, dim, F, 5e-4, 1, fd);
                        t_pn_worst(&worst_sh, t_pn_rel(n4, fd, Hs, 1e-4));
                    }
                }
        }
    for (kind = 0; kind < T_PN_NK; ++kind)
        PN_REPORT("%-25s FD grad %.2e, FD hess %.2e (relative to the largest entry)", t_pn_kind_name[kind],
                  worst_g[kind], worst_h[kind]);
    PN_REPORT("%ld samples (sand, metal with a learned return map; 2D, 3D): dP/dF asymmetry %.2e, "
              "regularizer w mu/2 |F - F0|^2 %.2e, optional outputs %.2e, failed %ld",
              samples, worst_sym, worst_reg, worst_opt, fails);
    PN_CHECK(fails == 0);
    for (kind = 0; kind < T_PN_NK; ++kind) {
        PN_CHECK_LE(worst_g[kind], T_PN_FD_TOL);
        PN_CHECK_LE(worst_h[kind], T_PN_FD_TOL);
    }
    PN_CHECK_LE(worst_sym, 1e-14);
    PN_REPORT("strain regularizer w mu/8 |F^T F - F0^T F0|^2 %.2e, FD grad %.2e, FD hess %.2e", worst_sreg, worst_sg,
              worst_sh);
    PN_CHECK_LE(worst_reg, 1e-12);
    PN_CHECK_LE(worst_sreg, 1e-12);
    PN_CHECK_LE(worst_sg, T_PN_FD_TOL);
    PN_CHECK_LE(worst_sh, T_PN_FD_TOL);
    PN_CHECK_LE(worst_opt, 1e-14);
}

/* ================================================================================================
   2b. Psi against a reference written from the definition (plastinet.h >>pnet and
      gen/pn_torch.py): the invariant features from singular values known by construction, the
      network inputs (shift, scale, the h clamp), the naive forward pass, E / E_train, out_scale,
      the linear correction C of the prepared point and the regularizer.
   ================================================================================================ */

/* features of F = R1 diag(s) R2 (gen/pn_torch.py `features`) */
static void t_pn_features(int dim, const double *s, double *x) {
    double logJ = 0, b[3];
    int i;
    for (i = 0; i < dim; ++i) {
        logJ += log(s[i]);
        b[i] = s[i] * s[i];
    }
    x[0] = logJ;
    if (dim == 2) {
        x[1] = log((b[0] + b[1]) / 2) - logJ;
    } else {
        double a = log((b[0] + b[1] + b[2]) / 3) - 2.0 / 3.0 * logJ;
        double c = log((b[0] * b[1] + b[0] * b[2] + b[1] * b[2]) / 3) - 4.0 / 3.0 * logJ;
        x[1] = (a + c) / 2;
        x[2] = a - c;
    }
}

PN_TEST(pnet_energy_reference) {
    double worst_psi = 0, worst_x0 = 0;
    long fails = 0, samples = 0, clamped = 0, bad_point = 0;
    int which, dim, i;
    for (which = T_PN_SAND; which <= T_PN_METAL; ++which)
        for (dim = 2; dim <= 3; ++dim) {
            const double E = which == T_PN_SAND ? 1e6 : 2e3, w = which == T_PN_SAND ? 0 : 3;
            t_pn_setup s;
            const pn_model *mo;
            pn_test_rng rng;
            rng.s = 2500 + 10 * (unsigned long long)which + (unsigned long long)dim;
            if (!t_pn_setup_make(pn__t, &s, which, dim, E, w, 4242)) return;
            mo = &s.energy.model;
            for (i = 0; i < 100; ++i) {
                const int nf = dim == 2 ? 2 : 3, n2 = dim * dim;
                double R[4][9], e0[3], s0[3], sv[3], F0[9], F[9], x0[3], x[3], u[7], out, h, hc, psi = 0, ref;
                double cf = 0, d2 = 0, reg = (w == 0 ? 1 : w) * s.m.mu;
                pn_pnet_point pt;
                int k;
                for (k = 0; k < 4; ++k) t_rand_rot(&rng, dim, R[k]);
                for (k = 0; k < dim; ++k) {
                    e0[k] = pn_test_rng_range(&rng, -1, 1);
                    s0[k] = exp(e0[k]);
                    sv[k] = exp(e0[k] + pn_test_rng_range(&rng, -0.3, 0.3));
                }
                if (i % 10 == 0) sv[1] = sv[0]; /* repeated singular values */
                t_adb(dim, R[0], s0, R[1], F0);
                if (i % 3 == 0) t_adb(dim, R[0], sv, R[1], F); /* same singular vectors */
                else t_adb(dim, R[2], sv, R[3], F);
                /* h inside and on both sides of [h_min, h_max] (the learned return map needs h >= 0) */
                h = pn_test_rng_range(&rng, which == T_PN_SAND ? -0.3 : 0, 1.3);
                hc = h < mo->h_min ? mo->h_min : h > mo->h_max ? mo->h_max : h;
                clamped += hc != h;
                ++samples;
                if (pn_pnet_prepare(&s.net, F0, h, &pt, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&s.net, &pt, F, &psi, NULL, NULL, 0) != PN_OK) {
                    ++fails;
                    continue;
                }
                t_pn_features(dim, s0, x0);
                t_pn_features(dim, sv, x);
                for (k = 0; k < nf; ++k) {
                    u[k] = (x[k] - x0[k] - mo->in_shift[k]) * mo->in_scale[k];
                    u[nf + k] = (x0[k] - mo->in_shift[nf + k]) * mo->in_scale[nf + k];
                    t_pn_worst(&worst_x0, fabs(pt.x0[k] - x0[k]));
                }
                u[2 * nf] = (hc - mo->in_shift[2 * nf]) * mo->in_scale[2 * nf];
                t_pn_forward(&mo->mlp, u, &out);
                for (k = 0; k < n2; ++k) {
                    cf += pt.C[k] * F[k];
                    d2 += (F[k] - F0[k]) * (F[k] - F0[k]);
                }
                /* the documented point: F0 as given */
                bad_point += memcmp(pt.F0, F0, sizeof(double) * (size_t)n2) != 0;
                ref = E / mo->youngs_modulus_train_pa * mo->out_scale * out - cf + reg / 2 * d2;
                t_pn_worst(&worst_psi, fabs(psi - ref) / (fabs(ref) + fabs(cf) + E * 1e-6));
            }
        }
    PN_REPORT("%ld samples (sand at E = 1e6, w = 1; metal at E = 2e3, w = 3; 2D, 3D; %ld with h "
              "clamped): psi vs reference %.2e, x(F0) %.2e, pt.F0 other than F0 %ld; failed %ld",
              samples, clamped, worst_psi, worst_x0, bad_point, fails);
    PN_CHECK(fails == 0);
    PN_CHECK(clamped > 10);
    PN_CHECK(bad_point == 0);
    PN_CHECK_LE(worst_psi, 1e-12);
    PN_CHECK_LE(worst_x0, 1e-13);
}

/* ================================================================================================
   2c. The scaled encoding (2 nf + 2 inputs, plastinet.h >>pnet): Psi against its definition
      written here (s^2 = q(x) + q(x0) + 1e-12, raw = [(x - x0) / s^p, x0 / s^p, s, h],
      N = s^2 M; p = 1, 2, 2), and its gradient and Hessian against central differences at strain scales
      1, 1e-2 and 1e-4 (steps scaled with the strain), where the chain rule through s matters.
   ================================================================================================ */

PN_TEST(pnet_scaled_encoding) {
    static const double scales[3] = {1, 1e-2, 1e-4};
    double worst_psi = 0, worst_g[3] = {0, 0, 0}, worst_h[3] = {0, 0, 0};
    long fails = 0, samples = 0;
    int dim, is, i, k;
    for (dim = 2; dim <= 3; ++dim) {
        const int nf = dim == 2 ? 2 : 3, n2 = dim * dim, n4 = n2 * n2;
        pn_material_desc d1;
        pn_material m1;
        t_pn_model tm;
        pn_pnet net;
        pn_pnet_desc pd;
        pn_test_rng rng;
        char why[256] = "";
        rng.s = 3100 + (unsigned long long)dim;
        if (!t_pn_material(pn__t, &m1, &d1, T_PN_SAND, 1)) return;
        t_pn_model_make_enc(&tm, PN_MODEL_ENERGY, dim, &d1, &m1, "t_sand_scaled", NULL, PN_ACTIVATION_SILU, &rng, 1);
        memset(&pd, 0, sizeof pd);
        pd.energy = &tm.model;
        pd.regularizer = -1;
        if (pn_pnet_init(&net, &pd, &m1, dim, why, sizeof why) != PN_OK) {
            PN_CHECK(!"pn_pnet_init of a scaled model");
            return;
        }
        for (is = 0; is < 3; ++is)
            for (i = 0; i < 20; ++i) {
                const double r = scales[is], c = dim == 2 ? 1 : 1.5;
                double R[4][9], s0[3], sv[3], F0[9], F[9], x0[3], x[3], S, sq, pw[3], u[8], out, psi = 0, P[9];
                double H[81], fd[81], cf = 0, ref;
                pn_pnet_point pt;
                for (k = 0; k < 4; ++k) t_rand_rot(&rng, dim, R[k]);
                for (k = 0; k < dim; ++k) {
                    double e0 = pn_test_rng_range(&rng, -r, r);
                    s0[k] = exp(e0);
                    sv[k] = exp(e0 + pn_test_rng_range(&rng, -r, r) * (i % 4 == 0 && r < 1 ? 10 : 1));
                }
                t_adb(dim, R[0], s0, R[1], F0);
                if (i % 3 == 0) t_adb(dim, R[0], sv, R[1], F); /* same singular vectors */
                else t_adb(dim, R[2], sv, R[3], F);
                ++samples;
                if (pn_pnet_prepare(&net, F0, 0, &pt, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&net, &pt, F, &psi, P, H, 0) != PN_OK) {
                    ++fails;
                    continue;
                }
                t_pn_features(dim, s0, x0);
                t_pn_features(dim, sv, x);
                S = x[0] * x[0] / dim + c * x[1] + x0[0] * x0[0] / dim + c * x0[1] + 1e-12;
                sq = sqrt(S);
                pw[0] = sq;
                pw[1] = S;
                pw[2] = S; /* the cubic feature also over s^2 (plastinet.h >>pnet) */
                for (k = 0; k < nf; ++k) {
                    u[k] = ((x[k] - x0[k]) / pw[k] - tm.model.in_shift[k]) * tm.model.in_scale[k];
                    u[nf + k] = (x0[k] / pw[k] - tm.model.in_shift[nf + k]) * tm.model.in_scale[nf + k];
                }
                u[2 * nf] = (sq - tm.model.in_shift[2 * nf]) * tm.model.in_scale[2 * nf];
                u[2 * nf + 1] = (0 - tm.model.in_shift[2 * nf + 1]) * tm.model.in_scale[2 * nf + 1];
                t_pn_forward(&tm.model.mlp, u, &out);
                for (k = 0; k < n2; ++k) cf += pt.C[k] * F[k];
                ref = tm.model.out_scale * S * out - cf;
                /* the features of F and of its singular values round differently, by ~1e-16
                   absolutely, which the inputs divide by s^2 ~ r^2 */
                t_pn_worst(&worst_psi, fabs(psi - ref) / (fabs(ref) + fabs(cf) + 1e-300) * (r * r));
                fails += t_pn_fd(&net, &pt, dim, F, r < 1 ? 1e-2 * r : 5e-4, 0, fd);
                t_pn_worst(&worst_g[is], t_pn_rel(n2, fd, P, 0));
                fails += t_pn_fd(&net, &pt, dim, F, r < 1 ? 1e-2 * r : 5e-4, 1, fd);
                t_pn_worst(&worst_h[is], t_pn_rel(n4, fd, H, 0));
            }
    }
    for (is = 0; is < 3; ++is)
        PN_REPORT("strain scale %.0e: FD grad %.2e, FD hess %.2e (relative to the largest entry)", scales[is],
                  worst_g[is], worst_h[is]);
    PN_REPORT("%ld samples (2D, 3D): psi vs its definition %.2e (relative, times r^2); failed %ld", samples,
              worst_psi, fails);
    PN_CHECK(fails == 0);
    PN_CHECK_LE(worst_psi, 1e-13);
    /* at 1e-4 the differences see the rounding of the features (~1e-16 over s^2 ~ 1e-8 in the
       inputs) divided by the step: 1e-4 there */
    for (is = 0; is < 3; ++is) {
        PN_CHECK_LE(worst_g[is], is < 2 ? T_PN_FD_TOL : 1e-4);
        PN_CHECK_LE(worst_h[is], is < 2 ? T_PN_FD_TOL : 1e-4);
    }
}


/* ================================================================================================
   2d. Conditioned models (material parameters as network inputs, softplus output): Psi against
      its definition written here (the parameters after h, normalized like every input; N =
      out_scale softplus(M) (times s^2, scaled)), gradient and Hessian against central
      differences, the float lanes against the double path, a parameter outside its range
      refused with its name and range, the parameters wired (another nu, another Psi), and the
      energy above its analytic lower bound -C:F0 - |C|^2 / (2 w mu) at F far outside the box.
   ================================================================================================ */

static void t_lanes_block(pn_test_ctx *pn__t, const pn_pnet *net, int dim, int n, pn_test_rng *rng, double r, int bad,
                          double *worst); /* section 10 */
static double t_prepare_lanes(pn_test_ctx *pn__t, const pn_pnet *net, int dim, int n, int bad,
                              pn_test_rng *rng); /* the same */

/* a sand test model taking nu in [0.2, 0.4] and the friction angle in [20, 45] deg */
static void t_pn_cond_model(t_pn_model *tm, int dim, int scaled, pn_test_rng *rng) {
    pn_material_desc d1;
    pn_material m1;
    pn_model *mo = &tm->model;
    int size[4], i;
    t_pn_desc(&d1, T_PN_SAND, 1);
    pn_material_init(&m1, &d1, NULL, 0);
    t_pn_model_make_enc(tm, PN_MODEL_ENERGY, dim, &d1, &m1, "t_sand_any", NULL, PN_ACTIVATION_SILU, rng, scaled);
    mo->n_params = 2;
    mo->param[0].kind = PN_MODEL_PARAM_POISSON, mo->param[0].lo = 0.2, mo->param[0].hi = 0.4;
    mo->param[1].kind = PN_MODEL_PARAM_FRICTION_DEG, mo->param[1].lo = 20, mo->param[1].hi = 45;
    mo->output = PN_MODEL_OUTPUT_SOFTPLUS;
    for (i = mo->n_inputs; i < mo->n_inputs + 2; ++i) mo->in_shift[i] = i == mo->n_inputs ? 0.3 : 32.5;
    mo->in_scale[mo->n_inputs] = 10, mo->in_scale[mo->n_inputs + 1] = 0.08;
    mo->n_inputs += 2;
    size[0] = mo->n_inputs, size[1] = size[2] = 8, size[3] = 1;
    t_pn_mlp_random(&mo->mlp, tm->buf, 3, size, PN_ACTIVATION_SILU, 0.5, rng);
}

/* F0 = R0 diag(s0) R1 and F = R2 diag(sv) R3 with log s0 uniform in [-r, r] and log sv within
   r of them, the four rotations random (kept in R) */
static void t_pn_near_pair(pn_test_rng *rng, int dim, double r, double R[4][9], double *s0, double *sv, double *F0,
                           double *F) {
    int k;
    for (k = 0; k < 4; ++k) t_rand_rot(rng, dim, R[k]);
    for (k = 0; k < dim; ++k) {
        double e0 = pn_test_rng_range(rng, -r, r);
        s0[k] = exp(e0);
        sv[k] = exp(e0 + pn_test_rng_range(rng, -r, r));
    }
    t_adb(dim, R[0], s0, R[1], F0);
    t_adb(dim, R[2], sv, R[3], F);
}

PN_TEST(pnet_conditioned) {
    double worst_psi = 0, worst_g = 0, worst_h = 0, worst_lanes[3] = {0, 0, 0}, worst_bound = HUGE_VAL, wired = 0;
    long fails = 0, samples = 0, refused = 0;
    int dim, scaled, i, k;
    for (dim = 2; dim <= 3; ++dim)
        for (scaled = 0; scaled <= 1; ++scaled) {
            const int nf = dim == 2 ? 2 : 3, n2 = dim * dim, n4 = n2 * n2;
            const double E = 1e5, c = dim == 2 ? 1 : 1.5;
            t_pn_model tm;
            pn_material_desc md;
            pn_material m, m2;
            pn_pnet net, net2;
            pn_pnet_desc pd;
            pn_test_rng rng;
            char why[256] = "";
            rng.s = 3300 + 10 * (unsigned long long)dim + (unsigned long long)scaled;
            t_pn_cond_model(&tm, dim, scaled, &rng);
            memset(&pd, 0, sizeof pd);
            pd.energy = &tm.model;
            /* outside the ranges: refused, naming the parameter and the range */
            t_pn_desc(&md, T_PN_SAND, E);
            md.poisson_ratio = 0.45;
            pn_material_init(&m, &md, NULL, 0);
            if (pn_pnet_init(&net, &pd, &m, dim, why, sizeof why) == PN_ERROR_INVALID_PARAMETER && why[0] &&
                strstr(why, "poisson_ratio = 0.45") && strstr(why, "[0.2, 0.4]"))
                ++refused;
            md.poisson_ratio = 0.3, md.friction_angle_deg = 50;
            pn_material_init(&m, &md, NULL, 0);
            if (pn_pnet_init(&net, &pd, &m, dim, why, sizeof why) == PN_ERROR_INVALID_PARAMETER && why[0] &&
                strstr(why, "friction_angle_deg = 50") && strstr(why, "[20, 45]"))
                ++refused;
            md.cohesion_strain = 1e-3, md.friction_angle_deg = 30; /* not an input: must be the model's */
            pn_material_init(&m, &md, NULL, 0);
            refused += pn_pnet_init(&net, &pd, &m, dim, why, sizeof why) == PN_ERROR_INVALID_PARAMETER;
            /* inside (the ends included) */
            md.cohesion_strain = 0, md.poisson_ratio = 0.4, md.friction_angle_deg = 20;
            pn_material_init(&m2, &md, NULL, 0);
            fails += pn_pnet_init(&net2, &pd, &m2, dim, NULL, 0) != PN_OK;
            md.poisson_ratio = 0.25, md.friction_angle_deg = 40;
            pn_material_init(&m, &md, NULL, 0);
            fails += pn_pnet_init(&net, &pd, &m, dim, NULL, 0) != PN_OK;
            for (i = 0; i < 40; ++i) {
                const double r = i % 4 == 3 ? 1e-2 : 0.5;
                double R[4][9], s0[3], sv[3], F0[9], F[9], x0[3], x[3], S = 1, sq = 1, pw[3] = {1, 1, 1}, u[12], out;
                double psi = 0, psi2 = 0, P[9], H[81], fd[81], cf = 0, cc = 0, ref, h = 0;
                pn_pnet_point pt, pt2;
                t_pn_near_pair(&rng, dim, r, R, s0, sv, F0, F);
                ++samples;
                if (pn_pnet_prepare(&net, F0, h, &pt, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&net, &pt, F, &psi, P, H, 0) != PN_OK ||
                    pn_pnet_prepare(&net2, F0, h, &pt2, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&net2, &pt2, F, &psi2, NULL, NULL, 0) != PN_OK) {
                    ++fails;
                    continue;
                }
                t_pn_features(dim, s0, x0);
                t_pn_features(dim, sv, x);
                if (scaled) {
                    S = x[0] * x[0] / dim + c * x[1] + x0[0] * x0[0] / dim + c * x0[1] + 1e-12;
                    sq = sqrt(S), pw[0] = sq, pw[1] = pw[2] = S;
                }
                for (k = 0; k < nf; ++k) {
                    u[k] = ((x[k] - x0[k]) / pw[k] - tm.model.in_shift[k]) * tm.model.in_scale[k];
                    u[nf + k] = (x0[k] / pw[k] - tm.model.in_shift[nf + k]) * tm.model.in_scale[nf + k];
                }
                k = 2 * nf;
                if (scaled) u[k] = (sq - tm.model.in_shift[k]) * tm.model.in_scale[k], ++k;
                u[k] = (h - tm.model.in_shift[k]) * tm.model.in_scale[k], ++k;
                u[k] = (0.25 - tm.model.in_shift[k]) * tm.model.in_scale[k], ++k;
                u[k] = (40 - tm.model.in_shift[k]) * tm.model.in_scale[k];
                t_pn_forward(&tm.model.mlp, u, &out);
                out = out > 0 ? out + log1p(exp(-out)) : log1p(exp(out));
                for (k = 0; k < n2; ++k) cf += pt.C[k] * F[k], cc += pt.C[k] * pt.C[k];
                { /* the regularizer (w = 1): Eq. 11 */
                    double d2 = 0;
                    for (k = 0; k < n2; ++k) d2 += (F[k] - F0[k]) * (F[k] - F0[k]);
                    ref = E * tm.model.out_scale * S * out - cf + m.mu / 2 * d2;
                }
                t_pn_worst(&worst_psi, fabs(psi - ref) / (fabs(ref) + fabs(cf) + 1e-300) * (scaled ? r * r : 1));
                wired = fmax(wired, fabs(psi2 - psi) / (fabs(psi) + 1e-300));
                fails += t_pn_fd(&net, &pt, dim, F, r < 1 ? 1e-2 * r : 5e-4, 0, fd);
                t_pn_worst(&worst_g, t_pn_rel(n2, fd, P, 0));
                fails += t_pn_fd(&net, &pt, dim, F, r < 1 ? 1e-2 * r : 5e-4, 1, fd);
                t_pn_worst(&worst_h, t_pn_rel(n4, fd, H, 0));
                { /* far beyond the box: Psi >= -C:F0 - |C|^2 / (2 mu) (N >= 0, w = 1) */
                    double Ff[9], sf[3], psif = 0, cf0 = 0;
                    for (k = 0; k < dim; ++k) sf[k] = exp(pn_test_rng_range(&rng, -3, 3));
                    t_adb(dim, R[2], sf, R[3], Ff);
                    for (k = 0; k < n2; ++k) cf0 += pt.C[k] * F0[k];
                    if (pn_pnet_energy(&net, &pt, Ff, &psif, NULL, NULL, 0) == PN_OK)
                        worst_bound = fmin(worst_bound, (psif - (-cf0 - cc / (2 * m.mu))) / (fabs(cf0) + cc / m.mu + E * 1e-12));
                }
            }
            for (i = 0; i < 4; ++i) t_lanes_block(pn__t, &net, dim, PN_MLP_LANES, &rng, i % 2 ? 1e-2 : 0.5, -1, worst_lanes);
        }
    PN_REPORT("%ld samples (2D, 3D; raw, scaled): psi vs its definition %.2e, FD grad %.2e, FD hess %.2e; lanes psi "
              "%.1e, P %.1e, dP/dF %.1e; another material changes psi by up to %.2f; least (Psi - bound) / scale "
              "%.2e (>= 0); %ld of 12 bad materials refused; failed %ld",
              samples, worst_psi, worst_g, worst_h, worst_lanes[0], worst_lanes[1], worst_lanes[2], wired, worst_bound,
              refused, fails);
    PN_CHECK(fails == 0);
    PN_CHECK(refused == 12);
    PN_CHECK_LE(worst_psi, 1e-12);
    PN_CHECK_LE(worst_g, 1e-5);
    PN_CHECK_LE(worst_h, 1e-5);
    PN_CHECK_LE(worst_lanes[1], 1e-4);
    PN_CHECK_LE(worst_lanes[2], 1e-4);
    PN_CHECK(wired > 1e-3);
    PN_CHECK(worst_bound >= -1e-12);
}

/* ================================================================================================
   A base energy (pn_model.base): a network that is a correction to an analytic energy B.
   PN_MODEL_BASE_VON_MISES_HENCKY: a Neo-Hookean von Mises model on the exact StVK-Hencky von
   Mises potential; PN_MODEL_BASE_DP_FROZEN: a Drucker-Prager sand on the frozen-yield energy,
   its yield stress taken at F0. Against the same network without the base, Psi changes by
   exactly B(F; F0, h) - grad B(F0; F0, h) : F (pn_von_mises_energy of an independently described
   StVK-Hencky material; pn_dp_energy with pn_dp_prepare's yield at F0), P by grad B(F) -
   grad B(F0) and dP/dF by the Hessian of B (B is only C1 across the yield surface, so finite
   differences of the sum are not a fair check there); exact at F0; the float lanes against the
   double path; a base on a material it does not describe is refused.
   ================================================================================================ */

PN_TEST(pnet_base_energy) {
    double worst_diff = 0, worst_exact = 0, worst_g = 0, worst_h = 0, worst_lanes[3] = {0, 0, 0}, prep = 0, moved = 0;
    long fails = 0, samples = 0, refused = 0;
    int dim, scaled, dp, i, k;
    for (dp = 0; dp <= 1; ++dp)
    for (dim = 2; dim <= 3; ++dim)
        for (scaled = 0; scaled <= 1; ++scaled) {
            const int n2 = dim * dim, n4 = n2 * n2;
            const double E = 2e5;
            t_pn_model tm, plain;
            pn_material_desc md, hd;
            pn_material m, mh;
            pn_pnet net, net0;
            pn_pnet_desc pd;
            pn_test_rng rng;
            char why[256] = "";
            rng.s = 4400 + 100 * (unsigned long long)dp + 10 * (unsigned long long)dim + (unsigned long long)scaled;
            t_pn_desc(&md, dp ? T_PN_SAND : T_PN_METAL, E); /* StVK-Hencky + DP, or Neo-Hookean + von Mises */
            hd = md;
            hd.elastic = PN_ELASTIC_STVK_HENCKY;
            if (pn_material_init(&m, &md, NULL, 0) != PN_OK || pn_material_init(&mh, &hd, NULL, 0) != PN_OK) {
                PN_CHECK(!"pn_material_init");
                continue;
            }
            t_pn_model_make_enc(&tm, PN_MODEL_ENERGY, dim, &md, &m, "t_base", NULL, PN_ACTIVATION_SILU, &rng, scaled);
            tm.model.e_box = 0.05;
            tm.model.out_scale = 1e-3; /* a correction: small against B */
            plain = tm; /* the same network: its weights stay in tm.buf */
            tm.model.base = dp ? PN_MODEL_BASE_DP_FROZEN : PN_MODEL_BASE_VON_MISES_HENCKY;
            memset(&pd, 0, sizeof pd);
            pd.energy = &tm.model;
            pd.regularizer = -1;
            if (pn_pnet_init(&net, &pd, &m, dim, why, sizeof why) != PN_OK) {
                PN_CHECK(!"pn_pnet_init with a base");
                continue;
            }
            pd.energy = &plain.model;
            plain.model.base = PN_MODEL_BASE_NONE;
            if (pn_pnet_init(&net0, &pd, &m, dim, why, sizeof why) != PN_OK) {
                PN_CHECK(!"pn_pnet_init without the base");
                continue;
            }
            for (i = 0; i < 40; ++i) {
                const double r = i % 4 == 3 ? 1e-3 : 0.03;
                double R[4][9], s0[3], sv[3], F0[9], F[9], h = pn_test_rng_range(&rng, 0, 1), T0[9];
                double psi, psi0, P[9], H[81], P0[9], H0[9 * 9], B, gB[9], HB[81], B0, gB0[9], ref, cf = 0, dP[9], dH[81];
                pn_real ty = 0;
                pn_pnet_point pt, pt0;
                t_pn_near_pair(&rng, dim, r, R, s0, sv, F0, F);
                if (dp) h = 0;
                ++samples;
                if (pn_pnet_prepare(&net, F0, h, &pt, NULL, T0) != PN_OK || pn_pnet_prepare(&net0, F0, h, &pt0, NULL, NULL) != PN_OK ||
                    pn_pnet_energy(&net, &pt, F, &psi, P, H, 0) != PN_OK ||
                    pn_pnet_energy(&net0, &pt0, F, &psi0, P0, H0, 0) != PN_OK ||
                    (dp && pn_dp_prepare(&mh, dim, F0, h, &ty) != PN_OK) ||
                    (dp ? pn_dp_energy(&mh, dim, F, h, ty, &B, gB, HB, 0) : pn_von_mises_energy(&mh, dim, F, h, &B, gB, HB, 0)) != PN_OK ||
                    (dp ? pn_dp_energy(&mh, dim, F0, h, ty, &B0, gB0, NULL, 0) : pn_von_mises_energy(&mh, dim, F0, h, &B0, gB0, NULL, 0)) != PN_OK) {
                    ++fails;
                    continue;
                }
                for (k = 0; k < n2; ++k) cf += gB0[k] * F[k];
                ref = B - cf;
                t_pn_worst(&worst_diff, fabs((psi - psi0) - ref) / (fabs(B) + fabs(cf) + 1e-300));
                moved = fmax(moved, fabs(psi - psi0) / (fabs(psi0) + 1e-300));
                for (k = 0; k < n2; ++k) dP[k] = P[k] - P0[k], gB[k] -= gB0[k];
                for (k = 0; k < n4; ++k) dH[k] = H[k] - H0[k];
                /* floors at 1e-6 E: a sand point in tension has B = 0 about it */
                t_pn_worst(&worst_g, t_pn_rel(n2, dP, gB, fmax(t_pn_maxabs(n2, gB0), 1e-6 * E)));
                t_pn_worst(&worst_h, t_pn_rel(n4, dH, HB, 1e-6 * E));
                if (pn_pnet_energy(&net, &pt, F0, NULL, P, NULL, 0) != PN_OK) ++fails;
                t_pn_worst(&worst_exact, t_pn_rel(n2, P, T0, t_pn_maxabs(n2, T0) + t_pn_maxabs(n2, pt.C)));
            }
            for (i = 0; i < 4; ++i) t_lanes_block(pn__t, &net, dim, PN_MLP_LANES, &rng, i % 2 ? 1e-3 : 0.03, -1, worst_lanes);
            for (i = 1; i <= PN_MLP_LANES; ++i) prep = fmax(prep, t_prepare_lanes(pn__t, &net, dim, i, -1, &rng));
            { /* each base needs its own plasticity (DP: and StVK-Hencky); an unknown base is malformed */
                t_pn_model bad = tm;
                bad.model.plastic = dp ? PN_PLASTIC_VON_MISES : PN_PLASTIC_DRUCKER_PRAGER;
                refused += pn_model_check(&bad.model, 0, why, sizeof why) == PN_ERROR_FORMAT && why[0] && strstr(why, "base");
                bad.model.plastic = tm.model.plastic;
                bad.model.base = 7;
                refused += pn_model_check(&bad.model, 0, why, sizeof why) == PN_ERROR_FORMAT;
                if (dp) {
                    bad.model.base = PN_MODEL_BASE_DP_FROZEN;
                    bad.model.elastic = PN_ELASTIC_NEO_HOOKEAN;
                    refused += pn_model_check(&bad.model, 0, why, sizeof why) == PN_ERROR_FORMAT;
                }
            }
        }
    PN_REPORT("%ld samples (2D, 3D; raw, scaled): Psi - Psi without the base vs B(F) - grad B(F0):F %.2e (the base "
              "moves Psi by up to %.2f); exact at F0 %.2e; P %.2e, dP/dF %.2e; lanes psi %.1e, P %.1e, "
              "dP/dF %.1e, prepare %.1e; %ld of 20 malformed bases refused; failed %ld (von Mises and DP bases)",
              samples, worst_diff, moved, worst_exact, worst_g, worst_h, worst_lanes[0], worst_lanes[1], worst_lanes[2],
              prep, refused, fails);
    PN_CHECK(fails == 0);
    PN_CHECK(refused == 20);
    PN_CHECK(moved > 1e-2);
    PN_CHECK_LE(worst_diff, 1e-9);
    PN_CHECK_LE(worst_exact, T_PN_EXACT_TOL);
    PN_CHECK_LE(worst_g, 1e-12);
    PN_CHECK_LE(worst_h, 1e-12);
    PN_CHECK_LE(worst_lanes[1], 1e-4);
    PN_CHECK_LE(worst_lanes[2], 1e-4);
    PN_CHECK_LE(prep, 1e-4);
}

static const pn_test_case pn_tests_pnet_energy[] = {
    {"pnet_fd", pnet_fd},
    {"pnet_energy_reference", pnet_energy_reference},
    {"pnet_scaled_encoding", pnet_scaled_encoding},
    {"pnet_conditioned", pnet_conditioned},
    {"pnet_base_energy", pnet_base_energy},
};
