/* cc -std=c99 -O2 examples/material_point.c -lm -o material_point

   material_point - drive one material point of plastinet through a deformation path and print
   one CSV row per step: the tool to calibrate a material with (yield point, hardening slope,
   cyclic loops, compaction curves) before putting it into a simulation.

   The point is stored MPM style: the elastic deformation Fe and the plastic state h. A step
   moves the total deformation F_n -> F_{n+1}; the trial elastic part is
   Fe_tr = (F_{n+1} F_n^-1) Fe_n, and pn_return_map projects it to Fe_{n+1}, h_{n+1}.

   Run `material_point --help` for the flags. Examples:
       material_point --plastic von_mises                     3D tensile test of steel
       material_point --plastic von_mises --path cyclic --cycles 3 --max-strain 0.005
       material_point --plastic drucker_prager --path isotropic --max-strain -0.1
       material_point --dim 2 --plastic cam_clay --path simple_shear --max-strain 0.5
       material_point --plastic von_mises --csv my_F_history.csv --out result.csv

   Exit status: 0 success, 2 bad input (nothing written to the output), 1 a step failed
   (rows up to the failed step were written; stderr names the step).

   Tests include this file with PN_MATERIAL_POINT_NO_MAIN defined (they provide the library
   implementation themselves) and call pn_mp_main with their own argv and FILE pointers. */
#ifndef PN_MATERIAL_POINT_NO_MAIN
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#endif

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PN_MP_PI 3.14159265358979323846
#define PN_MP_MAX_STEPS 10000000
#define PN_MP_MAX_LINE 4096

/* ---- options --------------------------------------------------------------------------- */

typedef struct pn_mp_opts {
    int dim, steps, volume_correction, no_hardening, help;
    double E, nu, friction, cohesion, yield, hardening, beta, xi, theta_c, theta_s, snow_xi;
    double h0, max_strain, cycles;
    const char *elastic, *plastic, *path, *csv, *out;
} pn_mp_opts;

typedef enum { PN_MP_REAL, PN_MP_INT, PN_MP_STRING, PN_MP_FLAG } pn_mp_kind;

typedef struct pn_mp_flag {
    const char *name;
    pn_mp_kind kind;
    size_t offset;   /* of the field in pn_mp_opts */
    const char *help;
} pn_mp_flag;

/* One table drives parsing, defaults and --help, so they cannot drift apart. */
static const pn_mp_flag pn_mp_flags[] = {
    {"--dim", PN_MP_INT, offsetof(pn_mp_opts, dim), "2 or 3 (default 3)"},
    {"--elastic", PN_MP_STRING, offsetof(pn_mp_opts, elastic),
     "default | fixed_corotated | stvk_hencky | neo_hookean | neo_hookean_snow"},
    {"--plastic", PN_MP_STRING, offsetof(pn_mp_opts, plastic),
     "none | drucker_prager | von_mises | cam_clay | snow_stomakhin (default von_mises)"},
    {"--E", PN_MP_REAL, offsetof(pn_mp_opts, E), "Young's modulus, Pa"},
    {"--nu", PN_MP_REAL, offsetof(pn_mp_opts, nu), "Poisson ratio in (-1, 0.5)"},
    {"--friction-deg", PN_MP_REAL, offsetof(pn_mp_opts, friction),
     "friction angle, degrees (drucker_prager, cam_clay)"},
    {"--cohesion", PN_MP_REAL, offsetof(pn_mp_opts, cohesion),
     "cohesion as a log-strain shift of the cone apex (drucker_prager)"},
    {"--volume-correction", PN_MP_FLAG, offsetof(pn_mp_opts, volume_correction),
     "Tampubolon volume correction (drucker_prager); --volume-correction=0 turns it off"},
    {"--yield-stress", PN_MP_REAL, offsetof(pn_mp_opts, yield),
     "uniaxial yield stress sigma_Y0, Pa (von_mises)"},
    {"--hardening", PN_MP_REAL, offsetof(pn_mp_opts, hardening),
     "linear hardening modulus K, Pa (von_mises)"},
    {"--beta", PN_MP_REAL, offsetof(pn_mp_opts, beta), "cohesion ratio (cam_clay)"},
    {"--xi", PN_MP_REAL, offsetof(pn_mp_opts, xi), "hardening factor (cam_clay)"},
    {"--no-hardening", PN_MP_FLAG, offsetof(pn_mp_opts, no_hardening),
     "keep the plastic state fixed (cam_clay)"},
    {"--theta-c", PN_MP_REAL, offsetof(pn_mp_opts, theta_c),
     "critical compression (snow_stomakhin)"},
    {"--theta-s", PN_MP_REAL, offsetof(pn_mp_opts, theta_s), "critical stretch (snow_stomakhin)"},
    {"--snow-xi", PN_MP_REAL, offsetof(pn_mp_opts, snow_xi),
     "hardening coefficient (snow_stomakhin)"},
    {"--h0", PN_MP_REAL, offsetof(pn_mp_opts, h0),
     "initial plastic state (von_mises: plastic strain >= 0; drucker_prager: stored log-volume "
     "gain >= 0; cam_clay, snow_stomakhin: log Jp)"},
    {"--path", PN_MP_STRING, offsetof(pn_mp_opts, path),
     "uniaxial_stress | uniaxial_strain | simple_shear | isotropic | cyclic | csv"},
    {"--steps", PN_MP_INT, offsetof(pn_mp_opts, steps), "number of steps (default 200)"},
    {"--max-strain", PN_MP_REAL, offsetof(pn_mp_opts, max_strain),
     "final axial log strain (uniaxial, cyclic amplitude), shear g (simple_shear), or log "
     "compression per axis (isotropic; negative expands)"},
    {"--cycles", PN_MP_REAL, offsetof(pn_mp_opts, cycles), "cycles of the cyclic path (default 2)"},
    {"--csv", PN_MP_STRING, offsetof(pn_mp_opts, csv),
     "file of the total F per step: dim*dim numbers a line, row-major, ',' or blanks, '#' "
     "comments; step 0 is the undeformed state, line k is F after step k"},
    {"--out", PN_MP_STRING, offsetof(pn_mp_opts, out), "output file (default stdout)"},
    {"--help", PN_MP_FLAG, offsetof(pn_mp_opts, help), "this text"}};

#define PN_MP_NFLAGS ((int)(sizeof pn_mp_flags / sizeof pn_mp_flags[0]))

/* Material defaults by plastic model: steel, sand, snow (Gaume 2018 flavour), snow
   (Stomakhin 2013 values), and a rubbery solid for the purely elastic case. The default path
   of each shows the model doing something: cohesionless sand carries no unconfined load, so it
   gets confined (uniaxial strain) compression; Cam-Clay snow gets isotropic compaction. */
static void pn_mp_model_defaults(int plastic, pn_mp_opts *o) {
    memset(o, 0, sizeof *o);
    o->dim = 3;
    o->steps = 200;
    o->cycles = 2;
    o->elastic = "default";
    o->plastic = "von_mises";
    o->path = "uniaxial_stress";
    o->nu = 0.3;
    switch (plastic) {
    case PN_PLASTIC_NONE:
        o->E = 1e6;
        o->max_strain = 0.1;
        break;
    case PN_PLASTIC_DRUCKER_PRAGER:
        o->E = 1e7;
        o->friction = 30;
        o->path = "uniaxial_strain";
        o->max_strain = -0.01;
        break;
    case PN_PLASTIC_CAM_CLAY:
        o->E = 1e6;
        o->friction = 40;
        o->beta = 0.3;
        o->xi = 3;
        o->h0 = -0.05; /* snow needs a compacted state (log Jp < 0) to have strength */
        o->path = "isotropic";
        o->max_strain = 0.1;
        break;
    case PN_PLASTIC_SNOW_STOMAKHIN:
        o->E = 1.4e5;
        o->nu = 0.2;
        o->theta_c = 2.5e-2;
        o->theta_s = 7.5e-3;
        o->snow_xi = 10;
        o->max_strain = -0.05;
        break;
    default: /* von Mises: structural steel */
        o->E = 200e9;
        o->yield = 250e6;
        o->hardening = 2e9;
        o->max_strain = 0.01;
        break;
    }
}

static void pn_mp_usage(FILE *f) {
    int i;
    fprintf(f, "usage: material_point [--flag value | --flag=value]...\n"
               "Drives one plastinet material point along a deformation path; prints CSV:\n"
               "step, F (total), Fe (elastic), tau (Kirchhoff), sigma (Cauchy = tau / det F),\n"
               "h (plastic state), yield (pn_yield_function of Fe at h), axial_log_strain,\n"
               "axial_sigma. Defaults depend on --plastic (von_mises: E=200e9 nu=0.3\n"
               "sigma_Y0=250e6 K=2e9, uniaxial_stress to 0.01; drucker_prager: E=1e7 nu=0.3\n"
               "30 deg, uniaxial_strain to -0.01; cam_clay: E=1e6 nu=0.3 40 deg beta=0.3 xi=3\n"
               "h0=-0.05, isotropic 0.1; snow_stomakhin: E=1.4e5 nu=0.2 theta_c=0.025\n"
               "theta_s=0.0075 xi=10, uniaxial_stress to -0.05; none: E=1e6, to 0.1).\n"
               "uniaxial_stress and cyclic solve for the lateral stretch that makes the\n"
               "lateral stress zero. Exit: 0 ok, 2 bad input (no output), 1 a step failed.\n");
    for (i = 0; i < PN_MP_NFLAGS; ++i)
        fprintf(f, "  %-20s %s\n", pn_mp_flags[i].name, pn_mp_flags[i].help);
}

/* strtod/strtol that accept only a whole, finite number. */
static int pn_mp_parse_real(const char *s, double *v) {
    char *end;
    double x;
    errno = 0;
    x = strtod(s, &end);
    if (end == s || *end != 0 || errno == ERANGE || !(x == x) || x - x != 0) return 0;
    *v = x;
    return 1;
}

static int pn_mp_parse_int(const char *s, int *v) {
    char *end;
    long x;
    errno = 0;
    x = strtol(s, &end, 10);
    if (end == s || *end != 0 || errno == ERANGE || x < -1000000000L || x > 1000000000L) return 0;
    *v = (int)x;
    return 1;
}

/* Parse argv into o; given[i] records which flags appeared (defaults fill the rest later).
   Returns 0 and explains on err on failure. */
static int pn_mp_parse_args(int argc, char **argv, pn_mp_opts *o, char *given, FILE *err) {
    int a, i;
    for (a = 1; a < argc; ++a) {
        const char *arg = argv[a], *eq = strchr(arg, '='), *val = NULL;
        size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
        const pn_mp_flag *f = NULL;
        char *field;
        for (i = 0; i < PN_MP_NFLAGS; ++i)
            if (strlen(pn_mp_flags[i].name) == len && !strncmp(arg, pn_mp_flags[i].name, len)) {
                f = &pn_mp_flags[i];
                break;
            }
        if (!f) {
            fprintf(err, "material_point: unknown argument '%s' (try --help)\n", arg);
            return 0;
        }
        given[i] = 1;
        field = (char *)o + f->offset;
        if (f->kind == PN_MP_FLAG) {
            int on = 1;
            if (eq && (!pn_mp_parse_int(eq + 1, &on) || (on != 0 && on != 1))) {
                fprintf(err, "material_point: %s takes =0 or =1, got '%s'\n", f->name, eq + 1);
                return 0;
            }
            memcpy(field, &on, sizeof on);
            continue;
        }
        if (eq) val = eq + 1;
        else if (a + 1 < argc) val = argv[++a];
        else {
            fprintf(err, "material_point: %s needs a value\n", f->name);
            return 0;
        }
        if (f->kind == PN_MP_STRING) {
            memcpy(field, &val, sizeof val);
        } else if (f->kind == PN_MP_INT) {
            int v;
            if (!pn_mp_parse_int(val, &v)) {
                fprintf(err, "material_point: %s: '%s' is not an integer\n", f->name, val);
                return 0;
            }
            memcpy(field, &v, sizeof v);
        } else {
            double v;
            if (!pn_mp_parse_real(val, &v)) {
                fprintf(err, "material_point: %s: '%s' is not a finite number\n", f->name, val);
                return 0;
            }
            memcpy(field, &v, sizeof v);
        }
    }
    return 1;
}

static int pn_mp_flag_index(const char *name) {
    int i;
    for (i = 0; i < PN_MP_NFLAGS; ++i)
        if (!strcmp(pn_mp_flags[i].name, name)) return i;
    return -1;
}

/* Fill every flag not given on the command line from the defaults of the plastic model. */
static void pn_mp_apply_defaults(pn_mp_opts *o, const char *given, int plastic) {
    pn_mp_opts def;
    int i;
    pn_mp_model_defaults(plastic, &def);
    for (i = 0; i < PN_MP_NFLAGS; ++i) {
        const pn_mp_flag *f = &pn_mp_flags[i];
        size_t size = f->kind == PN_MP_REAL ? sizeof(double)
                    : f->kind == PN_MP_STRING ? sizeof(const char *) : sizeof(int);
        if (!given[i]) memcpy((char *)o + f->offset, (const char *)&def + f->offset, size);
    }
    /* a file of F implies the csv path */
    if (o->csv && !given[pn_mp_flag_index("--path")]) o->path = "csv";
}

/* ---- paths ----------------------------------------------------------------------------- */

typedef enum {
    PN_MP_UNIAXIAL_STRESS,
    PN_MP_UNIAXIAL_STRAIN,
    PN_MP_SIMPLE_SHEAR,
    PN_MP_ISOTROPIC,
    PN_MP_CYCLIC,
    PN_MP_CSV,
    PN_MP_PATH_COUNT
} pn_mp_path;

static const char *const pn_mp_path_names[] = {"uniaxial_stress", "uniaxial_strain",
                                               "simple_shear",    "isotropic",
                                               "cyclic",          "csv"};

static int pn_mp_path_from_name(const char *name) {
    int i;
    for (i = 0; i < (int)PN_MP_PATH_COUNT; ++i)
        if (!strcmp(name, pn_mp_path_names[i])) return i;
    return -1;
}

/* Everything a run needs, validated. */
typedef struct pn_mp_run {
    pn_material m;
    int dim, steps, path;
    double h0, max_strain, cycles;
    pn_real *csv_F; /* steps * dim * dim reals for the csv path (owned) */
} pn_mp_run;

static void pn_mp_identity(int d, pn_real *A) {
    int i;
    for (i = 0; i < d * d; ++i) A[i] = 0;
    for (i = 0; i < d; ++i) A[i * d + i] = 1;
}

/* Axial log strain prescribed at step k of the stress-controlled paths. */
static double pn_mp_axial_strain(const pn_mp_run *r, int k) {
    double t = (double)k / r->steps;
    if (r->path == PN_MP_CYCLIC) return r->max_strain * sin(2 * PN_MP_PI * r->cycles * t);
    return r->max_strain * t;
}

/* Total F at step k of the deformation-controlled paths. */
static void pn_mp_prescribed_F(const pn_mp_run *r, int k, pn_real *F) {
    int d = r->dim, i;
    double t = (double)k / r->steps;
    pn_mp_identity(d, F);
    switch (r->path) {
    case PN_MP_UNIAXIAL_STRAIN: F[0] = (pn_real)exp(r->max_strain * t); break;
    case PN_MP_SIMPLE_SHEAR: F[1] = (pn_real)(r->max_strain * t); break;
    case PN_MP_ISOTROPIC:
        for (i = 0; i < d; ++i) F[i * d + i] = (pn_real)exp(-r->max_strain * t);
        break;
    case PN_MP_CSV: memcpy(F, r->csv_F + (size_t)(k - 1) * (size_t)(d * d), sizeof(pn_real) * (size_t)(d * d)); break;
    default: break;
    }
}

/* ---- the csv input: read and validated whole before any output ------------------------- */

/* Parse one line's numbers (',' or blanks separate, '#' starts a comment) into v.
   Returns the count, or -1 with a message on a malformed or non-finite number. */
static int pn_mp_parse_line(char *line, double *v, int cap, const char *file, int lineno,
                            FILE *err) {
    char *p = line, *hash = strchr(line, '#');
    int n = 0;
    if (hash) *hash = 0;
    for (;;) {
        char *end;
        double x;
        while (*p == ',' || *p == ' ' || *p == '\t' || *p == '\r' || *p == '\n') ++p;
        if (!*p) return n;
        errno = 0;
        x = strtod(p, &end);
        if (end == p || (*end && !strchr(", \t\r\n", *end))) {
            fprintf(err, "material_point: %s:%d: not a number: '%.20s'\n", file, lineno, p);
            return -1;
        }
        if (!(x == x) || x - x != 0 || errno == ERANGE) {
            fprintf(err, "material_point: %s:%d: non-finite value '%.*s'\n", file, lineno,
                    (int)(end - p), p);
            return -1;
        }
        if (n >= cap) {
            fprintf(err, "material_point: %s:%d: more than %d numbers\n", file, lineno, cap);
            return -1;
        }
        v[n++] = x;
        p = end;
    }
}

/* Read every F of the file into r->csv_F and set r->steps. Each F must be finite, complete and
   have det > 0 (a total deformation that inverts or flattens the point is not a path). */
static int pn_mp_read_csv(const char *file, pn_mp_run *r, FILE *err) {
    FILE *f = fopen(file, "r");
    char line[PN_MP_MAX_LINE];
    int d = r->dim, n = d * d, lineno = 0, count = 0, cap = 0, i;
    pn_real *data = NULL;
    if (!f) {
        fprintf(err, "material_point: cannot open --csv file '%s'\n", file);
        return 0;
    }
    while (fgets(line, sizeof line, f)) {
        double v[9];
        pn_real F[9];
        int got;
        ++lineno;
        if (!strchr(line, '\n') && !feof(f)) {
            fprintf(err, "material_point: %s:%d: line longer than %d characters\n", file,
                    lineno, PN_MP_MAX_LINE - 2);
            goto fail;
        }
        got = pn_mp_parse_line(line, v, n, file, lineno, err);
        if (got < 0) goto fail;
        if (got == 0) continue;
        if (got != n) {
            fprintf(err, "material_point: %s:%d: %d numbers, expected dim*dim = %d\n", file,
                    lineno, got, n);
            goto fail;
        }
        for (i = 0; i < n; ++i) F[i] = (pn_real)v[i];
        if (!(pn_mat_det(d, F) > 0)) {
            fprintf(err, "material_point: %s:%d: det F = %g <= 0 (inverted or singular)\n",
                    file, lineno, (double)pn_mat_det(d, F));
            goto fail;
        }
        if (count == cap) {
            pn_real *grown;
            cap = cap ? 2 * cap : 64;
            if (cap > PN_MP_MAX_STEPS) {
                fprintf(err, "material_point: %s: more than %d steps\n", file, PN_MP_MAX_STEPS);
                goto fail;
            }
            grown = (pn_real *)realloc(data, sizeof(pn_real) * (size_t)n * (size_t)cap);
            if (!grown) {
                fprintf(err, "material_point: out of memory reading '%s'\n", file);
                goto fail;
            }
            data = grown;
        }
        memcpy(data + (size_t)count * (size_t)n, F, sizeof(pn_real) * (size_t)n);
        ++count;
    }
    if (ferror(f)) {
        fprintf(err, "material_point: error reading '%s'\n", file);
        goto fail;
    }
    if (count == 0) {
        fprintf(err, "material_point: %s: no deformation gradients found\n", file);
        goto fail;
    }
    fclose(f);
    r->csv_F = data;
    r->steps = count;
    return 1;
fail:
    fclose(f);
    free(data);
    return 0;
}

/* ---- setup: turn options into a validated run ------------------------------------------ */

static int pn_mp_setup(int argc, char **argv, pn_mp_opts *o, pn_mp_run *r, FILE *err) {
    char given[PN_MP_NFLAGS];
    pn_material_desc desc;
    char why[256] = "";
    int plastic = PN_PLASTIC_VON_MISES, elastic;
    pn_result res;
    memset(given, 0, sizeof given);
    memset(o, 0, sizeof *o);
    memset(r, 0, sizeof *r);
    if (!pn_mp_parse_args(argc, argv, o, given, err)) return 0;
    if (o->help) return 1;
    if (given[pn_mp_flag_index("--plastic")]) { /* the plastic model decides the defaults */
        plastic = pn_plastic_model_from_name(o->plastic);
        if (plastic < 0) {
            fprintf(err, "material_point: unknown plastic model '%s' (none, drucker_prager, "
                         "von_mises, cam_clay, snow_stomakhin)\n", o->plastic);
            return 0;
        }
    }
    pn_mp_apply_defaults(o, given, plastic);
    elastic = pn_elastic_model_from_name(o->elastic);
    if (elastic < 0) {
        fprintf(err, "material_point: unknown elastic model '%s' (default, fixed_corotated, "
                     "stvk_hencky, neo_hookean, neo_hookean_snow)\n", o->elastic);
        return 0;
    }
    if (o->dim != 2 && o->dim != 3) {
        fprintf(err, "material_point: --dim must be 2 or 3, got %d\n", o->dim);
        return 0;
    }
    r->path = pn_mp_path_from_name(o->path);
    if (r->path < 0) {
        fprintf(err, "material_point: unknown path '%s' (uniaxial_stress, uniaxial_strain, "
                     "simple_shear, isotropic, cyclic, csv)\n", o->path);
        return 0;
    }
    if (o->steps < 1 || o->steps > PN_MP_MAX_STEPS) {
        fprintf(err, "material_point: --steps must be in [1, %d], got %d\n", PN_MP_MAX_STEPS,
                o->steps);
        return 0;
    }
    if (!(fabs(o->max_strain) <= 10)) { /* exp() of more is not a deformation, it is overflow */
        fprintf(err, "material_point: --max-strain must be in [-10, 10], got %g\n", o->max_strain);
        return 0;
    }
    if (!(o->cycles > 0)) {
        fprintf(err, "material_point: --cycles must be > 0, got %g\n", o->cycles);
        return 0;
    }
    memset(&desc, 0, sizeof desc);
    desc.elastic = (pn_elastic_model)elastic;
    desc.plastic = (pn_plastic_model)plastic;
    desc.youngs_modulus_pa = (pn_real)o->E;
    desc.poisson_ratio = (pn_real)o->nu;
    desc.friction_angle_deg = (pn_real)o->friction;
    desc.cohesion_strain = (pn_real)o->cohesion;
    desc.volume_correction = o->volume_correction;
    desc.yield_stress_pa = (pn_real)o->yield;
    desc.hardening_modulus_pa = (pn_real)o->hardening;
    desc.camclay_beta = (pn_real)o->beta;
    desc.camclay_xi = (pn_real)o->xi;
    desc.camclay_no_hardening = o->no_hardening;
    desc.snow_theta_c = (pn_real)o->theta_c;
    desc.snow_theta_s = (pn_real)o->theta_s;
    desc.snow_xi = (pn_real)o->snow_xi;
    res = pn_material_init(&r->m, &desc, why, sizeof why);
    if (res != PN_OK) {
        fprintf(err, "material_point: bad material: %s (%s)\n", why,
                pn_result_string(res));
        return 0;
    }
    r->dim = o->dim;
    r->steps = o->steps;
    r->h0 = o->h0;
    r->max_strain = o->max_strain;
    r->cycles = o->cycles;
    if (r->path == PN_MP_CSV) {
        if (!o->csv) {
            fprintf(err, "material_point: --path csv needs --csv FILE\n");
            return 0;
        }
        if (!pn_mp_read_csv(o->csv, r, err)) return 0;
    } else if (o->csv) {
        fprintf(err, "material_point: --csv given but --path is %s\n", o->path);
        return 0;
    }
    {
        /* the initial state must be one the model accepts (e.g. von Mises needs h0 >= 0) */
        pn_real I[9], Z[9], hn;
        pn_mp_identity(r->dim, I);
        res = pn_return_map(&r->m, r->dim, I, (pn_real)r->h0, Z, &hn, NULL);
        if (res != PN_OK) {
            fprintf(err, "material_point: --h0 %g rejected: %s\n", r->h0, pn_result_string(res));
            free(r->csv_F);
            r->csv_F = NULL;
            return 0;
        }
    }
    return 1;
}

/* ---- stepping -------------------------------------------------------------------------- */

typedef struct pn_mp_point {
    pn_real F[9], Fe[9], tau[9], h;
} pn_mp_point;

/* One step MPM style: Fe_tr = (F_next F^-1) Fe, projected by the return mapping; tau at the
   new state. `next` is written only on success. */
static pn_result pn_mp_advance(const pn_material *m, int d, const pn_mp_point *p,
                               const pn_real *F_next, pn_mp_point *next) {
    pn_real Finv[9], inc[9], Fe_tr[9];
    pn_mp_point q;
    pn_result res = pn_mat_inverse(d, p->F, Finv);
    if (res != PN_OK) return res;
    pn_mat_mul(d, F_next, Finv, inc);
    pn_mat_mul(d, inc, p->Fe, Fe_tr);
    res = pn_return_map(m, d, Fe_tr, p->h, q.Fe, &q.h, NULL);
    if (res != PN_OK) return res;
    res = pn_kirchhoff_stress(m, d, q.Fe, q.h, q.tau);
    if (res != PN_OK) return res;
    memcpy(q.F, F_next, sizeof q.F);
    *next = q;
    return PN_OK;
}

/* Lateral Kirchhoff stress tau_22 after a step to F = diag(l, t, t) with x = log t. */
static pn_result pn_mp_lateral(const pn_material *m, int d, const pn_mp_point *p, double l,
                               double x, pn_mp_point *next, double *g) {
    pn_real F[9];
    int i;
    pn_result res;
    pn_mp_identity(d, F);
    F[0] = (pn_real)l;
    for (i = 1; i < d; ++i) F[i * d + i] = (pn_real)exp(x);
    res = pn_mp_advance(m, d, p, F, next);
    if (res == PN_OK) *g = (double)next->tau[d + 1];
    return res;
}

/* Uniaxial stress: find the lateral stretch t (one for both lateral axes, by isotropy) with
   zero lateral stress. tau_22 grows with t, so bracket the root in x = log t by expanding
   from the previous stretch, then Illinois regula falsi: it keeps the bracket, so it cannot
   wander off like Newton through a kink of the return mapping. */
static pn_result pn_mp_uniaxial_stress_step(const pn_material *m, int d, const pn_mp_point *p,
                                            double axial, pn_mp_point *next) {
    double l = exp(axial), x0 = log((double)p->F[d + 1]), step = 1e-4, lo, hi, glo, ghi, g;
    int it, side = 0;
    pn_mp_point q;
    pn_result res = pn_mp_lateral(m, d, p, l, x0, &q, &g);
    if (res != PN_OK) return res;
    if (g == 0) {
        *next = q;
        return PN_OK;
    }
    {
        /* walk away from x0 (down when the lateral stress is tensile), doubling the step,
           until the sign flips */
        double x = x0, gx = g, prev, gprev, dir = g > 0 ? -1 : 1;
        do {
            if (step > 40) return PN_ERROR_NOT_CONVERGED; /* stretch beyond exp(40): no root */
            prev = x;
            gprev = gx;
            x = prev + dir * step;
            step *= 2;
            res = pn_mp_lateral(m, d, p, l, x, &q, &gx);
            if (res != PN_OK) return res;
            if (gx == 0) {
                *next = q;
                return PN_OK;
            }
        } while ((gx > 0) == (gprev > 0));
        lo = gx < 0 ? x : prev;
        glo = gx < 0 ? gx : gprev;
        hi = gx < 0 ? prev : x;
        ghi = gx < 0 ? gprev : gx;
    }
    if (!(glo < 0 && ghi > 0)) return PN_ERROR_NOT_CONVERGED;
    for (it = 0;; ++it) {
        double x = (lo * ghi - hi * glo) / (ghi - glo);
        if (it == 300) return PN_ERROR_NOT_CONVERGED;
        if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
        res = pn_mp_lateral(m, d, p, l, x, &q, &g);
        if (res != PN_OK) return res;
        if (g == 0 || hi - lo <= 4e-16 * (1 + fabs(x))) break;
        if (g < 0) {
            lo = x;
            glo = g;
            if (side == -1) ghi *= 0.5; /* Illinois: the stale end loses weight */
            side = -1;
        } else {
            hi = x;
            ghi = g;
            if (side == 1) glo *= 0.5;
            side = 1;
        }
        if (fabs(g) <= 1e-14 * fabs((double)q.tau[0])) break;
    }
    *next = q;
    return PN_OK;
}

/* ---- output ---------------------------------------------------------------------------- */

static void pn_mp_header(FILE *out, int d) {
    static const char *const groups[] = {"F", "Fe", "tau", "sigma"};
    int g, i, j;
    fprintf(out, "step");
    for (g = 0; g < 4; ++g)
        for (i = 0; i < d; ++i)
            for (j = 0; j < d; ++j) fprintf(out, ",%s%d%d", groups[g], i + 1, j + 1);
    fprintf(out, ",h,yield,axial_log_strain,axial_sigma\n");
}

/* One complete row; sigma = tau / det F (Cauchy from Kirchhoff with the total volume change).
   axial_log_strain is the log stretch of the material fiber along x, 1/2 log (F^T F)_11. */
static pn_result pn_mp_row(FILE *out, const pn_material *m, int d, int step, const pn_mp_point *p) {
    pn_real y = 0;
    double J = (double)pn_mat_det(d, p->F), c11 = 0;
    int i;
    pn_result res = pn_yield_function(m, d, p->Fe, p->h, &y, NULL);
    if (res != PN_OK) return res;
    for (i = 0; i < d; ++i) c11 += (double)p->F[i * d] * (double)p->F[i * d];
    fprintf(out, "%d", step);
    for (i = 0; i < d * d; ++i) fprintf(out, ",%.17g", (double)p->F[i]);
    for (i = 0; i < d * d; ++i) fprintf(out, ",%.17g", (double)p->Fe[i]);
    for (i = 0; i < d * d; ++i) fprintf(out, ",%.17g", (double)p->tau[i]);
    for (i = 0; i < d * d; ++i) fprintf(out, ",%.17g", (double)p->tau[i] / J);
    fprintf(out, ",%.17g,%.17g,%.17g,%.17g\n", (double)p->h, (double)y, 0.5 * log(c11),
            (double)p->tau[0] / J);
    return PN_OK;
}

/* Run every step, writing rows as they complete. Returns 0, or 1 after a failed step. */
static int pn_mp_simulate(const pn_mp_run *r, FILE *out, FILE *err) {
    int d = r->dim, k = 0, warned = 0;
    pn_mp_point p, next;
    pn_result res;
    char desc[512];
    memset(&p, 0, sizeof p);
    pn_mp_identity(d, p.F);
    pn_mp_identity(d, p.Fe);
    p.h = (pn_real)r->h0;
    res = pn_kirchhoff_stress(&r->m, d, p.Fe, p.h, p.tau);
    pn_material_describe(&r->m, desc, sizeof desc);
    fprintf(out, "# plastinet material_point: dim=%d path=%s steps=%d max_strain=%g h0=%g | %s\n",
            d, pn_mp_path_names[r->path], r->steps, r->max_strain, r->h0, desc);
    pn_mp_header(out, d);
    if (res == PN_OK) res = pn_mp_row(out, &r->m, d, 0, &p);
    while (res == PN_OK && k < r->steps) {
        ++k;
        if (r->path == PN_MP_UNIAXIAL_STRESS || r->path == PN_MP_CYCLIC) {
            res = pn_mp_uniaxial_stress_step(&r->m, d, &p, pn_mp_axial_strain(r, k), &next);
            /* by isotropy tau_33 = tau_22 = 0; say so if the material breaks the symmetry */
            if (res == PN_OK && d == 3 && !warned &&
                !(fabs((double)next.tau[8]) <= 1e-8 * (fabs((double)next.tau[0]) + 1e-300))) {
                fprintf(err, "material_point: warning: step %d: tau_33 = %g is not zero "
                             "(tau_11 = %g)\n", k, (double)next.tau[8], (double)next.tau[0]);
                warned = 1;
            }
        } else {
            pn_real F[9];
            pn_mp_prescribed_F(r, k, F);
            res = pn_mp_advance(&r->m, d, &p, F, &next);
        }
        if (res == PN_OK) res = pn_mp_row(out, &r->m, d, k, &next);
        if (res == PN_OK) p = next;
    }
    if (res != PN_OK) {
        if (k == 0)
            fprintf(err, "material_point: the initial state failed: %s\n", pn_result_string(res));
        else
            fprintf(err, "material_point: step %d failed: %s; the output stops after step %d\n",
                    k, pn_result_string(res), k - 1);
        return 1;
    }
    if (fflush(out) != 0 || ferror(out)) {
        fprintf(err, "material_point: error writing the output\n");
        return 1;
    }
    return 0;
}

/* The whole program; argv[0] is ignored. Returns the exit status. */
static int pn_mp_main(int argc, char **argv, FILE *out, FILE *err) {
    pn_mp_opts o;
    pn_mp_run r;
    FILE *dest = out;
    int status;
    if (!pn_mp_setup(argc, argv, &o, &r, err)) return 2;
    if (o.help) {
        pn_mp_usage(out);
        return 0;
    }
    /* opened only now, so bad input never creates or truncates the output file */
    if (o.out && strcmp(o.out, "-") != 0) {
        dest = fopen(o.out, "w");
        if (!dest) {
            fprintf(err, "material_point: cannot open --out file '%s'\n", o.out);
            free(r.csv_F);
            return 2;
        }
    }
    status = pn_mp_simulate(&r, dest, err);
    if (dest != out && fclose(dest) != 0 && status == 0) {
        fprintf(err, "material_point: error closing '%s'\n", o.out);
        status = 1;
    }
    free(r.csv_F);
    return status;
}

#ifndef PN_MATERIAL_POINT_NO_MAIN
int main(int argc, char **argv) { return pn_mp_main(argc, argv, stdout, stderr); }
#endif
