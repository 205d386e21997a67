/* test_driver.c - the material-point driver (examples/material_point.c) end to end.

   The driver is included with its main() compiled out and run through pn_mp_main with argv
   arrays and tmpfile() streams; its CSV is parsed back and judged against closed-form
   small-strain plasticity, never against earlier output:
   - von Mises, uniaxial stress, linear hardening: elastic line tau = E eps (exact for
     StVK-Hencky in log strain), yield at sigma_Y0, then the slope E K / (E + K), lateral
     stress zero;
   - von Mises, cyclic: stress bounded by the hardened yield stress sigma_Y0 + K a, the
     perfectly plastic loop closes with area 4 sigma_Y (eps_a - sigma_Y / E), and the work
     balances elastic energy plus dissipation;
   - simple shear: tau_12 bounded by sigma_Y / sqrt(3);
   - Drucker-Prager under isotropic expansion: stress free;
   - 2D uniaxial strain, elastic: tau = ((2 mu + lambda) eps, lambda eps);
   - the csv path reproduces a built-in path;
   - bad input: nonzero exit, NOTHING written. */

#define PN_MATERIAL_POINT_NO_MAIN
#include "../examples/material_point.c"

/* ---- running the driver ---------------------------------------------------------------- */

#define PN_TD_MAX_COLS 64

typedef struct pn_td_table {
    int rows, cols;
    char names[PN_TD_MAX_COLS][32];
    double *v; /* rows x cols */
    long bytes;        /* size of the output */
    char err[512];     /* the start of stderr */
} pn_td_table;

static void pn_td_free(pn_td_table *t) {
    free(t->v);
    t->v = NULL;
}

static int pn_td_col(const pn_td_table *t, const char *name) {
    int j;
    for (j = 0; j < t->cols; ++j)
        if (!strcmp(t->names[j], name)) return j;
    return -1;
}

static double pn_td_at(const pn_td_table *t, int row, int col) { return t->v[row * t->cols + col]; }

/* Parse the driver's CSV: '#' lines skipped, one header, then rows of numbers. */
static int pn_td_parse(FILE *f, pn_td_table *t) {
    char line[8192];
    int cap = 0, header = 0;
    while (fgets(line, sizeof line, f)) {
        char *p = line, *tok;
        int j = 0;
        if (line[0] == '#' || line[0] == '\n') continue;
        if (!header) {
            for (tok = strtok(line, ",\n"); tok && j < PN_TD_MAX_COLS; tok = strtok(NULL, ",\n"))
                snprintf(t->names[j++], sizeof t->names[0], "%s", tok);
            t->cols = j;
            header = 1;
            continue;
        }
        if (t->rows == cap) {
            double *g;
            cap = cap ? 2 * cap : 256;
            g = (double *)realloc(t->v, sizeof(double) * (size_t)cap * (size_t)t->cols);
            if (!g) return 0;
            t->v = g;
        }
        for (j = 0; j < t->cols; ++j) {
            char *end;
            t->v[t->rows * t->cols + j] = strtod(p, &end);
            if (end == p) return 0;
            p = end + (*end == ',');
        }
        t->rows++;
    }
    return header;
}

/* Run the driver with args (argv[0] supplied here). Returns its exit status; the output is
   parsed into t (t->bytes is its size, t->err the start of stderr). */
static int pn_td_run(const char *const *args, int nargs, pn_td_table *t) {
    char store[32][128], *argv[33];
    FILE *out = tmpfile(), *err = tmpfile();
    int i, rc;
    memset(t, 0, sizeof *t);
    if (!out || !err || nargs > 31) {
        if (out) fclose(out);
        if (err) fclose(err);
        return -1000;
    }
    snprintf(store[0], sizeof store[0], "material_point");
    argv[0] = store[0];
    for (i = 0; i < nargs; ++i) {
        snprintf(store[i + 1], sizeof store[0], "%s", args[i]);
        argv[i + 1] = store[i + 1];
    }
    argv[nargs + 1] = NULL;
    rc = pn_mp_main(nargs + 1, argv, out, err);
    fflush(out);
    t->bytes = ftell(out);
    rewind(out);
    if (!pn_td_parse(out, t)) t->rows = -1;
    rewind(err);
    t->err[fread(t->err, 1, sizeof t->err - 1, err)] = 0;
    fclose(out);
    fclose(err);
    return rc;
}

/* max(acc, |a|, |b|); NaN sticks */
static double pn_td_max3(double acc, double a, double b) {
    if (!(fabs(a) <= acc)) acc = fabs(a);
    if (!(fabs(b) <= acc)) acc = fabs(b);
    return acc;
}

/* Least-squares slope of y against x over rows [a, b]. */
static double pn_td_slope(const pn_td_table *t, int cx, int cy, int a, int b) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0, n = 0;
    int k;
    for (k = a; k <= b; ++k) {
        double x = pn_td_at(t, k, cx), y = pn_td_at(t, k, cy);
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
        n += 1;
    }
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

/* A writable scratch path: $TMPDIR, /tmp, or the current directory. */
static int pn_td_scratch(char *path, size_t cap, const char *name) {
    const char *dirs[3];
    int i;
    dirs[0] = getenv("TMPDIR");
    dirs[1] = "/tmp";
    dirs[2] = ".";
    for (i = 0; i < 3; ++i) {
        FILE *f;
        if (!dirs[i]) continue;
        snprintf(path, cap, "%s/%s", dirs[i], name);
        f = fopen(path, "w");
        if (f) {
            fclose(f);
            return 1;
        }
    }
    return 0;
}

/* ---- von Mises, uniaxial stress --------------------------------------------------------- */

/* Steel: E = 200 GPa, nu = 0.3, sigma_Y0 = 250 MPa, K = 2 GPa; 1000 steps to a log strain of
   0.5% (step 5e-6, so the first plastic step overshoots the yield strain by less than 5e-6,
   a stress error below E_t 5e-6 = 1e4 Pa). */
PN_TEST(driver_von_mises_uniaxial_stress) {
    static const char *const args[] = {"--plastic", "von_mises", "--E", "200e9", "--nu", "0.3",
                                       "--yield-stress", "250e6", "--hardening", "2e9",
                                       "--path", "uniaxial_stress", "--max-strain", "0.005",
                                       "--steps", "1000"};
    const double E = 200e9, K = 2e9, sy = 250e6, Et = E * K / (E + K);
    pn_td_table t;
    int rc = pn_td_run(args, 16, &t), ce, cs, ct, ch, cy, c22, c33, c11, k, ky = -1, j;
    double lat = 0, off = 0, line = 0, ymax = 0, s_el, s_pl, s_y;
    PN_CHECK(rc == 0);
    PN_CHECK(t.rows == 1001 && t.cols == 41);
    if (rc != 0 || t.rows != 1001) {
        pn_td_free(&t);
        return;
    }
    ce = pn_td_col(&t, "axial_log_strain");
    cs = pn_td_col(&t, "axial_sigma");
    ct = pn_td_col(&t, "tau11");
    ch = pn_td_col(&t, "h");
    cy = pn_td_col(&t, "yield");
    c22 = pn_td_col(&t, "sigma22");
    c33 = pn_td_col(&t, "sigma33");
    c11 = pn_td_col(&t, "sigma11");
    PN_CHECK(ce >= 0 && cs >= 0 && ct >= 0 && ch >= 0 && cy >= 0 && c22 >= 0 && c33 >= 0 && c11 >= 0);
    if (ce < 0 || cs < 0 || ct < 0 || ch < 0 || cy < 0 || c22 < 0 || c33 < 0 || c11 < 0) {
        pn_td_free(&t);
        return;
    }
    for (k = 0; k < t.rows; ++k) {
        double eps = pn_td_at(&t, k, ce);
        PN_CHECK_NEAR(eps, 0.005 * k / 1000, 1e-14); /* the prescribed path */
        lat = pn_td_max3(lat, pn_td_at(&t, k, c22), pn_td_at(&t, k, c33));
        for (j = 0; j < 9; ++j) /* sigma off-diagonals */
            if (j % 4 != 0) off = pn_td_max3(off, pn_td_at(&t, k, c11 + j), 0);
        if (ky < 0 && pn_td_at(&t, k, ch) > 0) ky = k;
        if (ky < 0) /* elastic: tau = E eps exactly for StVK-Hencky in uniaxial stress */
            line = pn_td_max3(line, (pn_td_at(&t, k, ct) - E * eps) / sy, 0);
        else /* on the hardened surface */
            ymax = pn_td_max3(ymax, pn_td_at(&t, k, cy) / (sqrt(2.0 / 3) * sy), 0);
    }
    PN_CHECK(ky > 1 && ky < t.rows - 100);
    if (ky <= 1 || ky >= t.rows - 100) {
        pn_td_free(&t);
        return;
    }
    s_y = pn_td_at(&t, ky, cs);
    s_el = pn_td_slope(&t, ce, cs, 1, ky - 1);
    s_pl = pn_td_slope(&t, ce, cs, ky + 5, t.rows - 1);
    PN_REPORT("first plastic step %d at eps %.6g: sigma %.6g Pa (sigma_Y0 %.6g, error %.2e)", ky,
              pn_td_at(&t, ky, ce), s_y, sy, s_y / sy - 1);
    PN_REPORT("elastic slope %.6g (E %.6g, error %.2e), plastic slope %.6g (E K/(E+K) %.6g, "
              "error %.2e)", s_el, E, s_el / E - 1, s_pl, Et, s_pl / Et - 1);
    PN_REPORT("max |lateral sigma| / sigma_Y0 %.2e, max |off-diagonal| %.2e, max |tau - E eps| / "
              "sigma_Y0 before yield %.2e, max |yield| / tau_Y after %.2e", lat / sy, off / sy,
              line, ymax);
    PN_CHECK_LE(fabs(s_y / sy - 1), 0.01);
    PN_CHECK_LE(fabs(s_el / E - 1), 0.01);
    PN_CHECK_LE(fabs(s_pl / Et - 1), 0.01);
    PN_CHECK_LE(lat / sy, 1e-9);
    PN_CHECK_LE(off / sy, 1e-9);
    PN_CHECK_LE(line, 1e-9);
    PN_CHECK_LE(ymax, 1e-9);
    /* Kirchhoff stress: the last elastic step below sigma_Y0, the first plastic one above it
       by at most one step of the hardening slope; yield at the strain sigma_Y0 / E */
    PN_CHECK(pn_td_at(&t, ky - 1, ct) < sy);
    PN_CHECK(pn_td_at(&t, ky, ct) >= sy * (1 - 1e-12));
    PN_CHECK_LE(pn_td_at(&t, ky, ct) - sy, Et * 5e-6 * (1 + 1e-9));
    PN_CHECK_LE(fabs(pn_td_at(&t, ky, ce) - sy / E), 5e-6 * (1 + 1e-9));
    pn_td_free(&t);
}

/* ---- von Mises, cyclic ------------------------------------------------------------------ */

/* Perfect plasticity (K = 0), amplitude 0.5% = 4 yield strains, 2 cycles of 2000 steps. */
PN_TEST(driver_von_mises_cyclic_loop_closes) {
    static const char *const args[] = {"--plastic", "von_mises", "--hardening", "0",
                                       "--path", "cyclic", "--max-strain", "0.005",
                                       "--cycles", "2", "--steps", "4000"};
    const double E = 200e9, sy = 250e6, ea = 0.005;
    pn_td_table t;
    int rc = pn_td_run(args, 12, &t), ce, ct, cf, k;
    double peak = 0, area = 0, expect = 4 * sy * (ea - sy / E), closure;
    PN_CHECK(rc == 0 && t.rows == 4001);
    if (rc != 0 || t.rows != 4001) {
        pn_td_free(&t);
        return;
    }
    ce = pn_td_col(&t, "axial_log_strain");
    ct = pn_td_col(&t, "tau11");
    cf = pn_td_col(&t, "Fe11");
    PN_CHECK(ce >= 0 && ct >= 0 && cf >= 0);
    if (ce < 0 || ct < 0 || cf < 0) {
        pn_td_free(&t);
        return;
    }
    for (k = 0; k < t.rows; ++k) peak = pn_td_max3(peak, pn_td_at(&t, k, ct), 0);
    /* the second cycle (steps 2000..4000): trapezoid rule for the loop integral of tau d eps */
    for (k = 2001; k <= 4000; ++k)
        area += 0.5 * (pn_td_at(&t, k, ct) + pn_td_at(&t, k - 1, ct)) *
                (pn_td_at(&t, k, ce) - pn_td_at(&t, k - 1, ce));
    /* after the first quarter cycle the loop is stable: cycle 1 and 2 end in the same state */
    closure = pn_td_max3(pn_td_at(&t, 4000, ct) - pn_td_at(&t, 2000, ct), 0, 0) / sy;
    closure = pn_td_max3(closure, (pn_td_at(&t, 4000, cf) - pn_td_at(&t, 2000, cf)) * E / sy, 0);
    PN_REPORT("peak |tau11| / sigma_Y %.12f, loop area %.6g J/m^3 (4 sigma_Y (eps_a - eps_y) = "
              "%.6g, error %.2e), closure %.2e", peak / sy, area, expect, area / expect - 1,
              closure);
    PN_CHECK_LE(peak / sy, 1 + 1e-9);
    PN_CHECK(peak / sy >= 1 - 1e-9); /* it did yield */
    PN_CHECK_LE(fabs(area / expect - 1), 0.01);
    PN_CHECK_LE(closure, 1e-6);
    pn_td_free(&t);
}

/* Linear hardening: |tau11| <= sigma_Y0 + K a at every step and reaches it while flowing;
   the work of tau on the log strain equals the elastic energy tau^2 / (2E) plus the
   dissipation, the integral of sigma_Y(a) da (for associative von Mises the plastic work is
   sigma_Y da). */
PN_TEST(driver_von_mises_cyclic_hardening) {
    static const char *const args[] = {"--plastic", "von_mises", "--hardening", "20e9",
                                       "--path", "cyclic", "--max-strain", "0.004",
                                       "--cycles", "3", "--steps", "6000"};
    const double E = 200e9, K = 20e9, sy = 250e6;
    pn_td_table t;
    int rc = pn_td_run(args, 12, &t), ce, ct, ch, k;
    double over = -1, reached = 0, work = 0, diss = 0, psi, hys = 0;
    PN_CHECK(rc == 0 && t.rows == 6001);
    if (rc != 0 || t.rows != 6001) {
        pn_td_free(&t);
        return;
    }
    ce = pn_td_col(&t, "axial_log_strain");
    ct = pn_td_col(&t, "tau11");
    ch = pn_td_col(&t, "h");
    PN_CHECK(ce >= 0 && ct >= 0 && ch >= 0);
    if (ce < 0 || ct < 0 || ch < 0) {
        pn_td_free(&t);
        return;
    }
    for (k = 1; k < t.rows; ++k) {
        double tau = pn_td_at(&t, k, ct), h = pn_td_at(&t, k, ch), h0 = pn_td_at(&t, k - 1, ch);
        double ratio = fabs(tau) / (sy + K * h);
        over = ratio > over ? ratio : over;
        if (h > h0) reached = ratio > reached ? ratio : reached;
        PN_CHECK(h >= h0); /* hardening is monotone */
        work += 0.5 * (tau + pn_td_at(&t, k - 1, ct)) * (pn_td_at(&t, k, ce) - pn_td_at(&t, k - 1, ce));
        diss += (sy + K * 0.5 * (h + h0)) * (h - h0);
    }
    psi = pn_td_at(&t, 6000, ct) * pn_td_at(&t, 6000, ct) / (2 * E);
    /* each cycle dissipates: the loop integral over the last cycle is positive */
    for (k = 4001; k <= 6000; ++k)
        hys += 0.5 * (pn_td_at(&t, k, ct) + pn_td_at(&t, k - 1, ct)) *
               (pn_td_at(&t, k, ce) - pn_td_at(&t, k - 1, ce));
    PN_REPORT("max |tau11| / (sigma_Y0 + K a) %.12f (while flowing >= %.12f); final a %.6g; "
              "work %.6g = psi %.6g + dissipation %.6g (error %.2e); last loop %.6g J/m^3",
              over, reached, pn_td_at(&t, 6000, ch), work, psi, diss, work / (psi + diss) - 1, hys);
    PN_CHECK_LE(over, 1 + 1e-9);
    PN_CHECK(reached >= 1 - 1e-9);
    PN_CHECK(pn_td_at(&t, 6000, ch) > 0.01); /* six plastic passes of a few 1e-3 each */
    PN_CHECK_LE(fabs(work / (psi + diss) - 1), 0.01);
    PN_CHECK(hys > 0);
    pn_td_free(&t);
}

/* Simple shear: |dev tau| <= sqrt(2/3) sigma_Y and |dev tau| >= sqrt(2) |tau_12| bound the
   shear stress by sigma_Y / sqrt(3) (K = 0); at small strain the flow stress reaches it. */
PN_TEST(driver_von_mises_simple_shear) {
    static const char *const args[] = {"--plastic", "von_mises", "--hardening", "0", "--path",
                                       "simple_shear", "--max-strain", "0.01", "--steps", "200"};
    const double sy = 250e6;
    pn_td_table t;
    int rc = pn_td_run(args, 10, &t), c12, cdet[9], k, i;
    double peak = 0, last, detdev = 0;
    PN_CHECK(rc == 0 && t.rows == 201);
    if (rc != 0 || t.rows != 201) {
        pn_td_free(&t);
        return;
    }
    c12 = pn_td_col(&t, "tau12");
    for (i = 0; i < 9; ++i) {
        char name[32];
        snprintf(name, sizeof name, "F%d%d", i / 3 + 1, i % 3 + 1);
        cdet[i] = pn_td_col(&t, name);
        if (cdet[i] < 0) c12 = -1;
    }
    PN_CHECK(c12 >= 0);
    if (c12 < 0) {
        pn_td_free(&t);
        return;
    }
    for (k = 0; k < t.rows; ++k) {
        double F[9];
        for (i = 0; i < 9; ++i) F[i] = pn_td_at(&t, k, cdet[i]);
        detdev = pn_td_max3(detdev, t_det(3, F) - 1, 0);
        PN_CHECK_NEAR(F[1], 0.01 * k / 200, 1e-15);
        peak = pn_td_max3(peak, pn_td_at(&t, k, c12), 0);
    }
    last = pn_td_at(&t, 200, c12);
    PN_REPORT("max tau12 / (sigma_Y / sqrt 3) %.9f, final %.6f, max |det F - 1| %.2e",
              peak * sqrt(3.0) / sy, last * sqrt(3.0) / sy, detdev);
    PN_CHECK_LE(peak * sqrt(3.0) / sy, 1 + 1e-9);
    PN_CHECK(last * sqrt(3.0) / sy >= 0.99);
    PN_CHECK_LE(detdev, 1e-15);
    pn_td_free(&t);
}

/* ---- Drucker-Prager, isotropic expansion ------------------------------------------------ */

PN_TEST(driver_drucker_prager_expansion_stress_free) {
    static const char *const args3[] = {"--plastic", "drucker_prager", "--path", "isotropic",
                                        "--max-strain", "-0.1", "--steps", "50"};
    static const char *const args2[] = {"--plastic", "drucker_prager", "--path", "isotropic",
                                        "--max-strain", "-0.1", "--steps", "50", "--dim", "2",
                                        "--friction-deg", "40"};
    int pass;
    for (pass = 0; pass < 2; ++pass) {
        pn_td_table t;
        int d = pass ? 2 : 3, n = d * d, rc = pass ? pn_td_run(args2, 12, &t) : pn_td_run(args3, 8, &t);
        int k, j, cF = pn_td_col(&t, "F11"), cFe = pn_td_col(&t, "Fe11"), ctau = pn_td_col(&t, "tau11");
        double stress = 0, fe = 0, fdev = 0;
        PN_CHECK(rc == 0 && t.rows == 51 && t.cols == 1 + 4 * n + 4);
        if (rc != 0 || t.rows != 51 || cF < 0 || cFe < 0 || ctau < 0) {
            pn_td_free(&t);
            continue;
        }
        for (k = 0; k < t.rows; ++k)
            for (j = 0; j < n; ++j) {
                double id = j % (d + 1) == 0;
                stress = pn_td_max3(stress, pn_td_at(&t, k, ctau + j), pn_td_at(&t, k, ctau + n + j));
                fe = pn_td_max3(fe, pn_td_at(&t, k, cFe + j) - id, 0);
                fdev = pn_td_max3(fdev, pn_td_at(&t, k, cF + j) - id * exp(0.1 * k / 50), 0);
            }
        PN_REPORT("dim %d: expansion to F = %.6f I: max |tau|, |sigma| %.3g Pa, max |Fe - I| %.2e",
                  d, pn_td_at(&t, 50, cF), stress, fe);
        PN_CHECK_LE(fdev, 1e-14);
        PN_CHECK_LE(stress, 1e-9); /* E = 1e7 Pa: zero to rounding */
        PN_CHECK_LE(fe, 1e-14);
        pn_td_free(&t);
    }
}

/* ---- 2D elastic uniaxial strain: tau = ((2 mu + lambda) eps, lambda eps) -------------------- */

PN_TEST(driver_2d_uniaxial_strain_elastic) {
    static const char *const args[] = {"--dim", "2", "--plastic", "none", "--elastic",
                                       "stvk_hencky", "--E", "1e6", "--nu", "0.25", "--path",
                                       "uniaxial_strain", "--max-strain", "0.2", "--steps", "20"};
    const double E = 1e6, nu = 0.25, mu = t_mu(E, nu), la = t_lambda(E, nu);
    pn_td_table t;
    int rc = pn_td_run(args, 16, &t), k, c11, c22, c12, cs11, cF11, cF22;
    double err = 0;
    PN_CHECK(rc == 0 && t.rows == 21 && t.cols == 1 + 16 + 4);
    c11 = pn_td_col(&t, "tau11");
    c22 = pn_td_col(&t, "tau22");
    c12 = pn_td_col(&t, "tau12");
    cs11 = pn_td_col(&t, "sigma11");
    cF11 = pn_td_col(&t, "F11");
    cF22 = pn_td_col(&t, "F22");
    if (rc != 0 || t.rows != 21 || c11 < 0 || c22 < 0 || c12 < 0 || cs11 < 0 || cF11 < 0 || cF22 < 0) {
        pn_td_free(&t);
        return;
    }
    for (k = 0; k < t.rows; ++k) {
        double eps = 0.2 * k / 20, J = pn_td_at(&t, k, cF11) * pn_td_at(&t, k, cF22);
        err = pn_td_max3(err, pn_td_at(&t, k, c11) - (2 * mu + la) * eps,
                             pn_td_at(&t, k, c22) - la * eps);
        err = pn_td_max3(err, pn_td_at(&t, k, c12), pn_td_at(&t, k, cs11) - pn_td_at(&t, k, c11) / J);
        PN_CHECK_NEAR(pn_td_at(&t, k, cF11), exp(eps), 1e-15);
    }
    PN_REPORT("max stress error %.3g Pa (stresses up to %.3g Pa)", err, (2 * mu + la) * 0.2);
    PN_CHECK_LE(err, 1e-9 * E);
    pn_td_free(&t);
}

/* ---- the csv path --------------------------------------------------------------------- */

/* The F history of a built-in path written to a file (with comments, commas and blanks)
   gives the same rows. */
PN_TEST(driver_csv_matches_builtin_path) {
    static const char *const builtin[] = {"--plastic", "von_mises", "--path", "uniaxial_strain",
                                          "--max-strain", "0.004", "--steps", "40"};
    const char *args[6];
    char path[512];
    pn_td_table a, b;
    int rc, k, j;
    double diff = 0;
    FILE *f;
    if (!pn_td_scratch(path, sizeof path, "pn_test_driver_history.csv")) {
        pn_test__fail(pn__t, __FILE__, __LINE__, "no writable scratch directory");
        return;
    }
    f = fopen(path, "w");
    PN_CHECK(f != NULL);
    if (!f) return;
    fprintf(f, "# total F per step\n\n");
    for (k = 1; k <= 40; ++k) /* computed the way the driver documents its path */
        fprintf(f, "%.17g, 0, 0,  0 1 0 ,0,0,1   # step %d\n", exp(0.004 * k / 40), k);
    fclose(f);
    rc = pn_td_run(builtin, 8, &a);
    PN_CHECK(rc == 0);
    args[0] = "--plastic";
    args[1] = "von_mises";
    args[2] = "--csv";
    args[3] = path;
    rc = pn_td_run(args, 4, &b);
    PN_CHECK(rc == 0);
    PN_CHECK(a.rows == 41 && b.rows == 41 && a.cols == b.cols);
    if (a.rows == 41 && b.rows == 41 && a.cols == b.cols)
        for (k = 0; k < 41; ++k)
            for (j = 0; j < a.cols; ++j)
                diff = pn_td_max3(diff, (pn_td_at(&a, k, j) - pn_td_at(&b, k, j)) /
                                                 (fabs(pn_td_at(&a, k, j)) + 1), 0);
    PN_REPORT("max relative difference csv vs built-in path: %.2e", diff);
    PN_CHECK_LE(diff, 1e-15);
    pn_td_free(&a);
    pn_td_free(&b);
    remove(path);
}

/* ---- bad input: nonzero exit, nothing written, a message on stderr ---------------------- */

static void pn_td_expect_reject(pn_test_ctx *pn__t, const char *const *args, int n,
                                const char *what, const char *expect_in_err) {
    pn_td_table t;
    int rc = pn_td_run(args, n, &t);
    if (rc == 0 || t.bytes != 0 || !t.err[0] || (expect_in_err && !strstr(t.err, expect_in_err))) {
        char msg[400];
        snprintf(msg, sizeof msg, "%s: exit %d, %ld bytes written, stderr '%.150s'", what, rc,
                 t.bytes, t.err);
        pn_test__fail(pn__t, __FILE__, __LINE__, msg);
    }
    pn_td_free(&t);
}

PN_TEST(driver_bad_input_writes_nothing) {
    static const char *const e0[] = {"--plastic", "von_mises", "--E", "0"};
    static const char *const eneg[] = {"--plastic", "drucker_prager", "--E", "-1e7"};
    static const char *const nu05[] = {"--plastic", "von_mises", "--nu", "0.5"};
    static const char *const nu06[] = {"--plastic", "cam_clay", "--nu", "0.6"};
    static const char *const num1[] = {"--plastic", "von_mises", "--nu", "-1"};
    static const char *const num2[] = {"--plastic", "snow_stomakhin", "--nu", "-1.5"};
    static const char *const fric[] = {"--plastic", "drucker_prager", "--friction-deg", "-5"};
    static const char *const fric2[] = {"--plastic", "cam_clay", "--friction-deg", "-30"};
    static const char *const ys[] = {"--plastic", "von_mises", "--yield-stress", "0"};
    static const char *const umodel[] = {"--plastic", "mohr_coulomb"};
    static const char *const uel[] = {"--elastic", "hookean"};
    static const char *const uflag[] = {"--plastic", "von_mises", "--young", "1e9"};
    static const char *const upath[] = {"--path", "triaxial"};
    static const char *const nan_e[] = {"--E", "nan"};
    static const char *const inf_e[] = {"--E", "inf"};
    static const char *const junk[] = {"--E", "1e9x"};
    static const char *const dim4[] = {"--dim", "4"};
    static const char *const steps0[] = {"--steps", "0"};
    static const char *const noval[] = {"--plastic"};
    static const char *const combo[] = {"--plastic", "cam_clay", "--elastic", "stvk_hencky"};
    static const char *const combo2[] = {"--plastic", "drucker_prager", "--elastic", "neo_hookean"};
    static const char *const h0[] = {"--plastic", "von_mises", "--h0", "-0.1"};
    static const char *const nocsv[] = {"--path", "csv"};
    static const char *const missing[] = {"--csv", "/nonexistent/dir/pn_no_such_file.csv"};
    pn_td_expect_reject(pn__t, e0, 4, "E = 0", "youngs_modulus");
    pn_td_expect_reject(pn__t, eneg, 4, "E < 0", "youngs_modulus");
    pn_td_expect_reject(pn__t, nu05, 4, "nu = 0.5", "poisson");
    pn_td_expect_reject(pn__t, nu06, 4, "nu = 0.6", "poisson");
    pn_td_expect_reject(pn__t, num1, 4, "nu = -1", "poisson");
    pn_td_expect_reject(pn__t, num2, 4, "nu = -1.5", "poisson");
    pn_td_expect_reject(pn__t, fric, 4, "negative friction (DP)", "friction");
    pn_td_expect_reject(pn__t, fric2, 4, "negative friction (Cam-Clay)", "friction");
    pn_td_expect_reject(pn__t, ys, 4, "yield stress 0", "yield_stress");
    pn_td_expect_reject(pn__t, umodel, 2, "unknown plastic model", "mohr_coulomb");
    pn_td_expect_reject(pn__t, uel, 2, "unknown elastic model", "hookean");
    pn_td_expect_reject(pn__t, uflag, 4, "unknown flag", "--young");
    pn_td_expect_reject(pn__t, upath, 2, "unknown path", "triaxial");
    pn_td_expect_reject(pn__t, nan_e, 2, "--E nan", NULL);
    pn_td_expect_reject(pn__t, inf_e, 2, "--E inf", NULL);
    pn_td_expect_reject(pn__t, junk, 2, "--E 1e9x", NULL);
    pn_td_expect_reject(pn__t, dim4, 2, "--dim 4", NULL);
    pn_td_expect_reject(pn__t, steps0, 2, "--steps 0", NULL);
    pn_td_expect_reject(pn__t, noval, 1, "flag without value", NULL);
    pn_td_expect_reject(pn__t, combo, 4, "cam_clay + stvk_hencky", NULL);
    pn_td_expect_reject(pn__t, combo2, 4, "drucker_prager + neo_hookean", NULL);
    pn_td_expect_reject(pn__t, h0, 4, "von Mises h0 < 0", NULL);
    pn_td_expect_reject(pn__t, nocsv, 2, "--path csv without --csv", NULL);
    pn_td_expect_reject(pn__t, missing, 2, "missing csv file", NULL);
}

/* A CSV of F with one bad entry anywhere (even on the last line) is rejected before any row
   is written: NaN, inf, a short line, a word, det F <= 0. */
PN_TEST(driver_bad_csv_writes_nothing) {
    static const char *const bad_lines[] = {
        "1.01 0 0 0 1 0 0 0 nan", "1.01 0 0 0 inf 0 0 0 1", "1.01,0,0,0,1,0,0,0,-inf",
        "1.01 0 0 0 1 0 0 0", "1.01 0 0 0 1 0 0 0 1 0", "1.01 0 0 0 one 0 0 0 1",
        "-1.01 0 0 0 1 0 0 0 1", "1 0 0 1 0 0 0 0 1"};
    char path[512], outpath[560];
    const char *args[4];
    int i, k;
    if (!pn_td_scratch(path, sizeof path, "pn_test_driver_bad.csv")) {
        pn_test__fail(pn__t, __FILE__, __LINE__, "no writable scratch directory");
        return;
    }
    snprintf(outpath, sizeof outpath, "%s.out", path);
    for (i = 0; i < (int)(sizeof bad_lines / sizeof bad_lines[0]); ++i) {
        FILE *f = fopen(path, "w");
        PN_CHECK(f != NULL);
        if (!f) return;
        for (k = 1; k <= 50; ++k) fprintf(f, "%.17g 0 0 0 1 0 0 0 1\n", 1 + 1e-4 * k);
        fprintf(f, "%s\n", bad_lines[i]); /* the last line is the bad one */
        fclose(f);
        args[0] = "--csv";
        args[1] = path;
        pn_td_expect_reject(pn__t, args, 2, bad_lines[i], path);
        /* with --out, the output file is not even created */
        remove(outpath);
        args[2] = "--out";
        args[3] = outpath;
        pn_td_expect_reject(pn__t, args, 4, bad_lines[i], path);
        f = fopen(outpath, "r");
        PN_CHECK(f == NULL);
        if (f) fclose(f);
    }
    remove(path);
}

/* A step that fails mid-run (here: an inverting F, which the csv validation would reject,
   fed straight to the stepping loop) stops with exit 1, names the step on stderr and keeps
   the complete rows before it. */
PN_TEST(driver_step_failure_reported) {
    pn_mp_run r;
    pn_material_desc desc;
    pn_real hist[27];
    FILE *out = tmpfile(), *err = tmpfile();
    char text[4096];
    size_t n;
    int rc, i, rows = 0, header = 0;
    PN_CHECK(out && err);
    if (!out || !err) return;
    memset(&r, 0, sizeof r);
    memset(&desc, 0, sizeof desc);
    desc.plastic = PN_PLASTIC_VON_MISES;
    desc.youngs_modulus_pa = 200e9;
    desc.poisson_ratio = 0.3;
    desc.yield_stress_pa = 250e6;
    PN_CHECK(pn_material_init(&r.m, &desc, NULL, 0) == PN_OK);
    for (i = 0; i < 27; ++i) hist[i] = (pn_real)(i % 9 % 4 == 0 ? 1 : 0);
    hist[0] = (pn_real)1.001;
    hist[9] = (pn_real)1.002;
    hist[18] = (pn_real)-1.0; /* step 3 reflects the point */
    r.dim = 3;
    r.steps = 3;
    r.path = PN_MP_CSV;
    r.csv_F = hist;
    rc = pn_mp_simulate(&r, out, err);
    rewind(out);
    n = fread(text, 1, sizeof text - 1, out);
    text[n] = 0;
    for (i = 0; i < (int)n; ++i)
        if (text[i] == '\n') ++rows;
    header = strstr(text, "step,F11") != NULL;
    rewind(err);
    n = fread(text, 1, sizeof text - 1, err);
    text[n] = 0;
    if (n > 0 && text[n - 1] == '\n') text[n - 1] = 0;
    PN_REPORT("exit %d, %d lines written, stderr: %s", rc, rows, text);
    PN_CHECK(rc == 1);
    PN_CHECK(header);
    PN_CHECK(rows == 2 + 3); /* comment, header, steps 0..2 */
    PN_CHECK(strstr(text, "step 3") != NULL);
    fclose(out);
    fclose(err);
}

static const pn_test_case pn_tests_driver[] = {
    {"driver_von_mises_uniaxial_stress", driver_von_mises_uniaxial_stress},
    {"driver_von_mises_cyclic_loop_closes", driver_von_mises_cyclic_loop_closes},
    {"driver_von_mises_cyclic_hardening", driver_von_mises_cyclic_hardening},
    {"driver_von_mises_simple_shear", driver_von_mises_simple_shear},
    {"driver_drucker_prager_expansion_stress_free", driver_drucker_prager_expansion_stress_free},
    {"driver_2d_uniaxial_strain_elastic", driver_2d_uniaxial_strain_elastic},
    {"driver_csv_matches_builtin_path", driver_csv_matches_builtin_path},
    {"driver_bad_input_writes_nothing", driver_bad_input_writes_nothing},
    {"driver_bad_csv_writes_nothing", driver_bad_csv_writes_nothing},
    {"driver_step_failure_reported", driver_step_failure_reported},
};
