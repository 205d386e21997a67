/* bench_coupling: the MPM-FEM coupling (plastinet_mpm.h >>couple) on the drop scene of
   examples/common/pn_drop.h: a tilted block (E 1e9 Pa) dropped onto a sand bed.
   Build: cc -std=c99 -O2 bench/bench_coupling.c -lm -o bench_coupling   (or: make bench-coupling)
   Usage: bench_coupling [--dim 2|3] [--T S] [--res N] [--tilt DEG] [--friction MU] [--out DIR] [--ref-cache DIR]
                         [--no-check] [--energies pnet,dp,lagged] [--dts 1e-3,1e-2] [--thetas 1,0.6] [--window S]
                         [--contact-stiffness PA] [--contact-distance M] [--passes N]
                         [--forcing ETA] [--regularizer W] [--quick]
   In one run:
   1. the explicit reference: pn_coupled_step_explicit at half the coupled step bound
      (pn_coupled_stable_dt) of each step, to T (0.25 s), recording at every frame (every
      0.025 s) the sand's mass field and the block's node positions; and (unless --no-check)
      the same at the whole bound, scored against it: how far doubling its step moves it
      bounds how converged the reference is;
   2. the fair explicit baseline: the largest multiple of the bound (4, 2, 1) that runs the
      whole run (or its first --window seconds) without failing, timed over it and scaled to a
      simulated second, and scored against the reference as the implicit runs are;
   3. implicit at each step of --dts (up to 8; default 1e-3 and 1e-2 s) with the sand's learned
      energy (pnet) and the analytic alternatives (dp: frozen-yield Drucker-Prager, lagged), each
      to T, with each theta of --thetas (up to 4; default 1, backward Euler; 0.5 is the
      trapezoidal rule, which at 1e-2 s lets the block bounce off the sand: docs/results.md).
      --theta is the same flag.
   --friction MU: the block-sand friction coefficient (the scene's 0.5); --contact-stiffness,
   --contact-distance: pn_coupled_desc's (the library's defaults: 0.1 E of the sand, dx / 4);
   --passes N: the implicit runs' fixed-point passes on F0 (pn_mpm_implicit_desc, default 1);
   --forcing ETA: their Eisenstat-Walker forcing up to ETA (cg_forcing_max; default off);
   --regularizer W: PlasticityNet's regularizer weight (pn_pnet_desc.regularizer; default 1,
   negative: off).
   Scores against the reference, at the frames: the mean and smallest min/max mass IoU of the
   sand (docs/validation.md), the mean error of the block's nodes over its bounding-box
   diagonal, the smallest particle-block distance over the run, wall seconds per simulated
   second (the steps only) and the ratio to the fair baseline.
   Writes DIR/bench_coupling_Nd.csv and .md; progress on stderr. --quick: a smoke test of a
   minute or two: coarse (res 64 in 2D, 16 in 3D, whatever --res says), one frame (T 0.025 s),
   the implicit runs at 1e-2 s only unless --dts is given. --ref-cache DIR: keep the reference's frames in
   DIR and read them on a rerun with the same scene. */
#define PLASTINET_IMPLEMENTATION
#include "../examples/common/pn_example.h"
#include "../examples/common/pn_drop.h"

#define FRAME_DT 0.025
#define MAX_FRAMES 64

typedef struct run {
    const char *role;            /* reference, ref_check, fair_explicit, implicit             */
    int energy, implicit, ok;
    double dt, mult;             /* implicit step, or the explicit step's multiple of the bound */
    double theta;                /* implicit: the theta method's (1: backward Euler)          */
    double iou_mean, iou_min, body_err, dmin, wall, sim, newton, cg;
    long steps;
    char why[160];
} run;

typedef struct cfg {
    int dim, res, quick, no_check, dts_given;
    unsigned energies;
    double T, window, tilt;      /* tilt: the block's (degrees; < -90: the scene's default) */
    double dt[8], theta[4];      /* the implicit runs: every step with every theta          */
    int ndt, ntheta;
    double friction;             /* block-sand Coulomb coefficient (< 0: the scene's 0.5)     */
    double stiffness, dhat;      /* the interface's (0: the library's defaults)               */
    int passes;                  /* the implicit runs' fixed-point passes (0: the default, 1)  */
    double forcing;              /* their cg_forcing_max (0: off, the default)                */
    double regularizer;          /* PlasticityNet's w (0: the default, 1; < 0: off)           */
    const char *out, *ref_cache;
} cfg;

/* the reference's frames: mass fields and node positions */
typedef struct frames {
    int n;
    size_t nf, nx;
    double *field, *x;
} frames;

static void scene(const cfg *c, int energy, pn_drop_desc *d) {
    pn_drop_default(d, c->dim);
    d->energy = energy;
    if (c->res) d->res = c->res;
    if (c->tilt >= -90) d->tilt_deg = c->tilt;
    if (c->friction >= 0) d->friction = c->friction;
    d->contact_stiffness = c->stiffness, d->contact_distance_m = c->dhat;
    d->pnet_regularizer = c->regularizer;
}

/* one run to time `until` (the frames at every FRAME_DT recorded into rec, or scored against
   ref) */
static void run_one(const cfg *c, run *r, frames *rec, const frames *ref, double until) {
    pn_drop_desc dd;
    pn_drop s;
    char why[256];
    int f, nframes = (int)floor(until / FRAME_DT + 1e-9);
    double *field = NULL;
    r->ok = 1, r->iou_mean = r->body_err = r->wall = r->sim = r->newton = r->cg = 0, r->iou_min = 1, r->dmin = 1e30;
    r->steps = 0, r->why[0] = 0;
    scene(c, r->implicit ? r->energy : PN_DROP_LAGGED, &dd);
    if (!pn_drop_create(&dd, &s, why, sizeof why)) {
        fprintf(stderr, "bench_coupling: %s\n", why);
        exit(1);
    }
    field = (double *)malloc(sizeof(double) * pn_ex_field_size(s.w));
    if (rec) {
        rec->n = 0, rec->nf = pn_ex_field_size(s.w), rec->nx = s.m->n_nodes * (size_t)c->dim;
        rec->field = (double *)malloc(sizeof(double) * rec->nf * MAX_FRAMES);
        rec->x = (double *)malloc(sizeof(double) * rec->nx * MAX_FRAMES);
    }
    if (!field || (rec && (!rec->field || !rec->x))) {
        fprintf(stderr, "bench_coupling: out of memory\n");
        exit(1);
    }
    for (f = 1; f <= (until > 0 ? (nframes > 0 ? nframes : 1) : 0) && r->ok; ++f) {
        double t_end = nframes > 0 ? f * FRAME_DT : until;
        size_t k;
        while ((double)s.w->time_s < t_end - 1e-12) {
            pn_coupled_stats st;
            pn_result e;
            double h = r->dt, t0;
            if (!r->implicit) {
                pn_real sdt;
                if (pn_coupled_stable_dt(s.c, &sdt) != PN_OK) sdt = (pn_real)1e-7;
                h = r->mult * (double)sdt;
            }
            if (h > t_end - (double)s.w->time_s) h = t_end - (double)s.w->time_s;
            t0 = pn_ex_seconds();
            if (r->implicit) {
                pn_coupled_implicit_desc id;
                memset(&id, 0, sizeof id);
                id.theta = (pn_real)r->theta, id.mpm.fixed_point_iters = c->passes;
                id.mpm.cg_forcing_max = (pn_real)c->forcing;
                e = pn_coupled_step_implicit(s.c, (pn_real)h, &id, &st);
            } else e = pn_coupled_step_explicit(s.c, (pn_real)h, &st);
            r->wall += pn_ex_seconds() - t0;
            if (e != PN_OK) {
                r->ok = 0;
                snprintf(r->why, sizeof r->why, "t = %.4f s: %.120s", (double)s.w->time_s, pn_coupled_error(s.c));
                break;
            }
            r->steps++, r->newton += st.newton_iters, r->cg += st.cg_iters;
            if (st.min_distance_m < r->dmin) r->dmin = (double)st.min_distance_m;
        }
        r->sim = (double)s.w->time_s;
        if (!r->ok || nframes <= 0) break;
        pn_ex_mass_field(s.w, field);
        if (rec && rec->n < MAX_FRAMES) {
            memcpy(rec->field + rec->nf * (size_t)rec->n, field, sizeof(double) * rec->nf);
            for (k = 0; k < rec->nx; ++k) rec->x[rec->nx * (size_t)rec->n + k] = (double)s.m->x[k];
            rec->n++;
        }
        if (ref && f <= ref->n) {
            pn_ex_iou_scores sc = pn_ex_iou(field, ref->field + ref->nf * (size_t)(f - 1), ref->nf);
            double e = 0;
            for (k = 0; k < s.m->n_nodes; ++k) {
                double d2 = 0;
                int i;
                for (i = 0; i < c->dim; ++i) {
                    double u = (double)s.m->x[k * (size_t)c->dim + (size_t)i] - ref->x[ref->nx * (size_t)(f - 1) + k * (size_t)c->dim + (size_t)i];
                    d2 += u * u;
                }
                e += sqrt(d2);
            }
            r->iou_mean += sc.minmax / ref->n;
            if (sc.minmax < r->iou_min) r->iou_min = sc.minmax;
            r->body_err += e / (double)s.m->n_nodes / s.diag / ref->n;
        }
        fprintf(stderr, "\r  %s %s dt %.3g: t = %.3f s, %ld steps, %.1f s   ", r->role,
                r->implicit ? pn_drop_energy_names[r->energy] : "explicit", r->implicit ? r->dt : r->mult, (double)s.w->time_s,
                r->steps, r->wall);
    }
    fprintf(stderr, "\n");
    free(field);
    pn_drop_free(&s);
}

#define CACHE_TAG (0x504e4300ul + (unsigned long)sizeof(run)) /* "PNC" and the record's size */

static int cache_path(const cfg *c, char *path, size_t cap) {
    char mu[96] = "";
    if (c->friction >= 0) snprintf(mu, sizeof mu, "_mu%g", c->friction);
    if (c->stiffness > 0) snprintf(mu + strlen(mu), sizeof mu - strlen(mu), "_k%g", c->stiffness);
    if (c->dhat > 0) snprintf(mu + strlen(mu), sizeof mu - strlen(mu), "_dhat%g", c->dhat);
    return snprintf(path, cap, "%s/coupling_ref_%dd_res%d_T%g_tilt%g%s.bin", c->ref_cache, c->dim,
                    c->res ? c->res : (c->dim == 2 ? 128 : 32), c->T, c->tilt >= -90 ? c->tilt : 20, mu) < (int)cap;
}

static int cache_read(const cfg *c, frames *fr, run *r) {
    char path[1024];
    FILE *f;
    int ok;
    unsigned long tag = 0;
    if (!c->ref_cache || !cache_path(c, path, sizeof path) || !(f = fopen(path, "rb"))) return 0;
    /* the run record is this program's struct: a file from a build with another one is
       recomputed */
    ok = fread(&tag, sizeof tag, 1, f) == 1 && tag == CACHE_TAG && fread(&fr->n, sizeof fr->n, 1, f) == 1 && fread(&fr->nf, sizeof fr->nf, 1, f) == 1 &&
         fread(&fr->nx, sizeof fr->nx, 1, f) == 1 && fread(r, sizeof *r, 1, f) == 1 && fr->n > 0 && fr->n <= MAX_FRAMES;
    if (ok) {
        fr->field = (double *)malloc(sizeof(double) * fr->nf * (size_t)fr->n);
        fr->x = (double *)malloc(sizeof(double) * fr->nx * (size_t)fr->n);
        ok = fr->field && fr->x && fread(fr->field, sizeof(double) * fr->nf, (size_t)fr->n, f) == (size_t)fr->n &&
             fread(fr->x, sizeof(double) * fr->nx, (size_t)fr->n, f) == (size_t)fr->n;
    }
    fclose(f);
    r->role = "reference";
    if (ok) fprintf(stderr, "  reference read from %s\n", path);
    return ok;
}

static void cache_write(const cfg *c, const frames *fr, const run *r) {
    char path[1024];
    FILE *f;
    unsigned long tag = CACHE_TAG;
    if (!c->ref_cache || !pn_ex_mkdirs(c->ref_cache) || !cache_path(c, path, sizeof path) || !(f = fopen(path, "wb"))) return;
    fwrite(&tag, sizeof tag, 1, f);
    fwrite(&fr->n, sizeof fr->n, 1, f), fwrite(&fr->nf, sizeof fr->nf, 1, f), fwrite(&fr->nx, sizeof fr->nx, 1, f);
    fwrite(r, sizeof *r, 1, f);
    fwrite(fr->field, sizeof(double) * fr->nf, (size_t)fr->n, f);
    fwrite(fr->x, sizeof(double) * fr->nx, (size_t)fr->n, f);
    fclose(f);
}

static unsigned parse_list(const char *v, const char *const *names, int n) {
    unsigned bits = 0;
    char buf[256], *tok;
    int i;
    snprintf(buf, sizeof buf, "%s", v);
    for (tok = strtok(buf, ","); tok; tok = strtok(NULL, ","))
        for (i = 0; i < n; ++i)
            if (!strcmp(tok, names[i])) bits |= 1u << i;
    return bits;
}

/* a comma list of up to max numbers into x; the count, or -1 if one is not a positive number */
static int parse_numbers(const char *v, double *x, int max) {
    char buf[256], *tok, *end;
    int n = 0;
    snprintf(buf, sizeof buf, "%s", v);
    for (tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
        if (n == max || !((x[n] = strtod(tok, &end)) > 0) || *end) return -1;
        n++;
    }
    return n;
}

int main(int argc, char **argv) {
    cfg c;
    run runs[3 + 8 * 4 * PN_DROP_ENERGIES], ref; /* reference, check, fair; every implicit run */
    frames fr;
    int nr = 0, k, i, j;
    double fair = 0;
    char path[1024];
    FILE *csv, *md;
    memset(&c, 0, sizeof c);
    memset(&fr, 0, sizeof fr);
    c.dim = 2, c.T = 0.25, c.window = 0, c.out = "build", c.energies = 7, c.tilt = -1000, c.friction = -1;
    c.dt[0] = 1e-3, c.dt[1] = 1e-2, c.ndt = 2, c.theta[0] = 1, c.ntheta = 1;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        if (!strcmp(a, "--quick")) c.quick = 1;
        else if (!strcmp(a, "--no-check")) c.no_check = 1;
        else if (!v) {
            fprintf(stderr, "bench_coupling: unknown flag or missing value '%s'\n", a);
            return 2;
        } else if (!strcmp(a, "--dim")) c.dim = atoi(v), ++k;
        else if (!strcmp(a, "--T")) c.T = atof(v), ++k;
        else if (!strcmp(a, "--res")) c.res = atoi(v), ++k;
        else if (!strcmp(a, "--window")) c.window = atof(v), ++k;
        else if (!strcmp(a, "--tilt")) c.tilt = atof(v), ++k;
        else if (!strcmp(a, "--theta") || !strcmp(a, "--thetas")) c.ntheta = parse_numbers(v, c.theta, 4), ++k;
        else if (!strcmp(a, "--friction")) c.friction = atof(v), ++k;
        else if (!strcmp(a, "--contact-stiffness")) c.stiffness = atof(v), ++k;
        else if (!strcmp(a, "--contact-distance")) c.dhat = atof(v), ++k;
        else if (!strcmp(a, "--passes")) c.passes = atoi(v), ++k;
        else if (!strcmp(a, "--forcing")) c.forcing = atof(v), ++k;
        else if (!strcmp(a, "--regularizer")) c.regularizer = atof(v), ++k;
        else if (!strcmp(a, "--out")) c.out = v, ++k;
        else if (!strcmp(a, "--ref-cache")) c.ref_cache = v, ++k;
        else if (!strcmp(a, "--energies")) c.energies = parse_list(v, pn_drop_energy_names, PN_DROP_ENERGIES), ++k;
        else if (!strcmp(a, "--dts")) c.ndt = parse_numbers(v, c.dt, 8), c.dts_given = 1, ++k;
        else {
            fprintf(stderr, "bench_coupling: unknown flag '%s'\n", a);
            return 2;
        }
    }
    if (c.quick) /* a smoke test: every role and energy once, one frame, coarse, the larger step only */
        c.T = FRAME_DT, c.window = 0.01, c.res = c.dim == 2 ? 64 : 16, c.dt[0] = c.dts_given ? c.dt[0] : 1e-2,
        c.ndt = c.dts_given ? c.ndt : 1;
    for (k = 0; k < c.ntheta; ++k)
        if (!(c.theta[k] >= 0.5 && c.theta[k] <= 1)) c.ntheta = -1;
    if (!(c.window > 0) || c.window > c.T) c.window = c.T;
    if ((c.dim != 2 && c.dim != 3) || !(c.T >= FRAME_DT) || c.T > FRAME_DT * MAX_FRAMES || !(c.window > 0) || c.ndt < 1 ||
        c.ntheta < 1) {
        fprintf(stderr, "bench_coupling: --dim 2|3, FRAME_DT <= --T <= %g, --dts: up to 8 steps > 0, "
                        "--thetas: up to 4 in [0.5, 1]\n", FRAME_DT * MAX_FRAMES);
        return 2;
    }
    /* 1. the reference, and its check at twice its step */
    memset(&ref, 0, sizeof ref);
    if (!cache_read(&c, &fr, &ref)) {
        ref.role = "reference", ref.mult = 0.5;
        run_one(&c, &ref, &fr, NULL, c.T);
        if (!ref.ok) {
            fprintf(stderr, "bench_coupling: the reference failed: %s\n", ref.why);
            return 1;
        }
        cache_write(&c, &fr, &ref);
    }
    runs[nr++] = ref;
    runs[0].iou_mean = runs[0].iou_min = 1;
    if (!c.no_check) {
        run *r = &runs[nr++];
        memset(r, 0, sizeof *r);
        r->role = "ref_check", r->mult = 1;
        run_one(&c, r, NULL, &fr, c.T);
    }
    /* 2. the fair explicit baseline over the window (the whole run unless --window) */
    for (k = 0; k < 3; ++k) {
        static const double mults[3] = {4, 2, 1};
        run *r = &runs[nr];
        memset(r, 0, sizeof *r);
        r->role = "fair_explicit", r->mult = mults[k];
        run_one(&c, r, NULL, c.window >= c.T ? &fr : NULL, c.window);
        if (r->ok) {
            fair = r->wall / r->sim;
            nr++;
            break;
        }
        fprintf(stderr, "  %g x the bound fails: %s\n", mults[k], r->why);
    }
    /* 3. implicit: every theta at every step, for each energy */
    for (k = 0; k < c.ntheta; ++k)
        for (i = 0; i < c.ndt; ++i)
            for (j = 0; j < PN_DROP_ENERGIES; ++j) {
                run *r;
                if (!(c.energies >> j & 1)) continue;
                r = &runs[nr++];
                memset(r, 0, sizeof *r);
                r->role = "implicit", r->implicit = 1, r->energy = j, r->dt = c.dt[i], r->theta = c.theta[k];
                run_one(&c, r, NULL, &fr, c.T);
            }
    /* tables */
    if (!pn_ex_mkdirs(c.out)) return 1;
    snprintf(path, sizeof path, "%s/bench_coupling_%dd.csv", c.out, c.dim);
    csv = fopen(path, "w");
    snprintf(path, sizeof path, "%s/bench_coupling_%dd.md", c.out, c.dim);
    md = fopen(path, "w");
    if (!csv || !md) return 1;
    {
        pn_drop_desc dd;
        pn_drop s;
        char why[256];
        scene(&c, PN_DROP_LAGGED, &dd);
        if (!pn_drop_create(&dd, &s, why, sizeof why)) return 1;
        char flags[192] = "";
        if (c.res) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --res %d", c.res);
        if (c.T != 0.25) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --T %g", c.T);
        if (c.tilt >= -90) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --tilt %g", c.tilt);
        if (c.friction >= 0) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --friction %g", c.friction);
        if (c.stiffness > 0) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --contact-stiffness %g", c.stiffness);
        if (c.dhat > 0) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --contact-distance %g", c.dhat);
        if (c.passes > 0) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --passes %d", c.passes);
        if (c.forcing > 0) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --forcing %g", c.forcing);
        if (c.regularizer != 0) snprintf(flags + strlen(flags), sizeof flags - strlen(flags), " --regularizer %g", c.regularizer);
        fprintf(md, "### Block on sand, %dD (`build/bench_coupling --dim %d%s`)\n\n", c.dim, c.dim, c.quick ? " --quick" : flags);
        fprintf(md, "%lu particles (res %d), the block %lu nodes / %lu elements, E %.3g Pa; %.3g s simulated, frames every "
                    "%.3g s; dhat %.3g m. Scores against the explicit reference at half the coupled step bound. Fair baseline: "
                    "explicit at %g x the bound over %.3g s.\n\n",
                (unsigned long)s.w->n, dd.res, (unsigned long)s.m->n_nodes, (unsigned long)s.m->n_elems, dd.E_block, c.T,
                FRAME_DT, (double)s.c->dhat, nr > 1 ? runs[c.no_check ? 1 : 2].mult : 0, c.window);
        pn_drop_free(&s);
    }
    fprintf(csv, "role,integrator,energy,dt_or_bound_multiple,theta,ok,iou_mean,iou_min,body_error,min_distance_m,wall_s,simulated_s,"
                 "wall_per_simulated_s,ratio_to_fair,steps,newton_per_step,cg_per_step,note\n");
    fprintf(md, "| run | step | sand IoU mean (min) | block error | smallest distance (m) | wall s / sim. s | x fair explicit | "
                "Newton / CG per step |\n|---|---|---|---|---|---|---|---|\n");
    for (k = 0; k < nr; ++k) {
        const run *r = &runs[k];
        double per = r->sim > 0 ? r->wall / r->sim : 0;
        char step[64];
        if (r->implicit && r->theta < 1) snprintf(step, sizeof step, "dt %g s, theta %g", r->dt, r->theta);
        else if (r->implicit) snprintf(step, sizeof step, "dt %g s", r->dt);
        else snprintf(step, sizeof step, "%g x bound", r->mult);
        fprintf(csv, "%s,%s,%s,%g,%g,%d,%.4f,%.4f,%.5f,%.4g,%.3f,%.4f,%.3f,%.4f,%ld,%.2f,%.1f,\"%s\"\n", r->role,
                r->implicit ? "implicit" : "explicit", r->implicit ? pn_drop_energy_names[r->energy] : "", r->implicit ? r->dt : r->mult,
                r->implicit ? r->theta : 0, r->ok, r->iou_mean, r->iou_min, r->body_err, r->dmin, r->wall, r->sim, per, fair > 0 ? per / fair : 0, r->steps,
                r->steps ? r->newton / r->steps : 0, r->steps ? r->cg / r->steps : 0, r->why);
        if (!r->ok) {
            fprintf(md, "| %s %s | %s | failed: %s | | | | | |\n", r->role, r->implicit ? pn_drop_energy_names[r->energy] : "", step, r->why);
            continue;
        }
        {
            char iou[64], err[64];
            int scored = k > 0 && (strcmp(r->role, "fair_explicit") || c.window >= c.T);
            if (scored) snprintf(iou, sizeof iou, "%.3f (%.3f)", r->iou_mean, r->iou_min), snprintf(err, sizeof err, "%.2f %%", 100 * r->body_err);
            else snprintf(iou, sizeof iou, "%s", k == 0 ? "(itself)" : "(window only)"), snprintf(err, sizeof err, "-");
            fprintf(md, "| %s%s%s | %s | %s | %s | %.3g | %.1f | %.3g | %.1f / %.0f |\n", r->role, r->implicit ? " " : "",
                    r->implicit ? pn_drop_energy_names[r->energy] : "", step, iou, err, r->dmin, per, fair > 0 ? per / fair : 0,
                    r->steps ? r->newton / r->steps : 0, r->steps ? r->cg / r->steps : 0);
        }
    }
    fclose(csv);
    fclose(md);
    return 0;
}
