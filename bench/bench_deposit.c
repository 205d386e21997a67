/* bench_deposit: is the explicit reference converged? (docs/results.md, "The explicit reference")

   1. The 2D sand column of docs/validation.md (examples/common/pn_example.h), on a rough floor
      (--friction), collapses for --end seconds [1]; then its deposit is measured by its
      thickness profile: mass per unit length over the initial density (what the deposit
      would be at the packing it started with; a particle's height would move by the
      particle spacing with dx), smoothed by a 3 cm tent. Its front: how far from the centre
      the thickness is still at least 1 cm (and 2 cm), the mean of both sides; its summit:
      the largest thickness; its core: the mean thickness over the column's footprint (the
      mass left there over rho W). The thin sheared tail ahead of the front lengthens as dx
      shrinks; these measures need not. Runs: res 64, 128, 256 at the stable step (courant
      1), and res 128 at courant 1/2 and 1/4 (dt halvings). Each halving's relative change
      is reported.
   2. The settled pile: core and summit at 1 s and at --settle seconds [3] (res 64 and 128,
      courant 1 and 1/2): how much a pile at rest still sinks.
   3. The snow press (pn_example.h): a plate pressed 0.08 m into a snow layer at 0.4 m/s,
      res 64, courant 1, 1/2, 1/4: the min/max mass IoU (docs/validation.md) of each run
      against the next at every 25 fps frame, mean and worst, and against the run at 1/4; and
      the run at 1/2 against itself with E larger by --perturb [1e-6] (how chaotic the scene
      is: a floor under any step's distance). The deepest compaction (min log J_p) is printed beside.
   Usage: bench_deposit [--quick] [--end S] [--settle S] [--filter S] [--friction F]
                        [--perturb X] [--only column|settle|press] [--md FILE]
   --filter S: the transfer filter time (pn_mpm_desc.filter_time_s) instead of the scenes'
   2e-3 s; 0 is plain APIC. --friction F: the column's wall Coulomb coefficient [1: a rough
   floor, above the sand's tan 30 deg = 0.58, as laboratory column collapses use, so the
   deposit is the sand's and not a basal slip layer's, which the grid resolves only to a
   cell; the scene's own 0.5 lets the sand slide on the floor]. --only: one part.
   --quick: res 32, 64, 128 and shorter runs (a smoke test). */
#define PLASTINET_IMPLEMENTATION
#define PLASTINET_MPM_IMPLEMENTATION
#include "../examples/common/pn_example.h"

typedef struct deposit {
    double front1, front2, summit, core; /* m */
    double seconds;
} deposit;

/* The thickness profile: mass per unit length over the initial density, smoothed by a tent
   of half-width 3 cm (several particle spacings at every res here, so the lattice does not
   alias into it), sampled every mm; its summit and its front at 1 and 2 cm. */
static deposit measure(const pn_mpm_world *w, const pn_ex_scene *s) {
    enum { NS = 1001 };
    static double th[NS];
    double a = 0.03, hs = s->domain_m / (NS - 1), c = s->domain_m / 2, rho = s->density_kg_m3;
    int k, side, t;
    size_t p;
    deposit r;
    memset(th, 0, sizeof th);
    for (p = 0; p < w->n; ++p) {
        double xp = (double)w->x[p * 2], m = (double)w->mass[p] / rho;
        int lo = (int)ceil((xp - a) / hs), hi = (int)floor((xp + a) / hs);
        if (!w->active[p]) continue;
        for (k = lo < 0 ? 0 : lo; k <= hi && k < NS; ++k) th[k] += m * (a - fabs(k * hs - xp)) / (a * a);
    }
    r.summit = 0;
    for (k = 0; k < NS; ++k) r.summit = th[k] > r.summit ? th[k] : r.summit;
    r.core = 0; /* the mean thickness over the column's footprint (unsmoothed: mass over rho W) */
    for (p = 0; p < w->n; ++p)
        if (w->active[p] && fabs((double)w->x[p * 2] - c) < s->width_m / 2) r.core += (double)w->mass[p] / (rho * s->width_m);
    for (t = 1; t <= 2; ++t) {
        double thr = 0.01 * t, sum = 0;
        for (side = -1; side <= 1; side += 2) { /* the last sample out from the centre above thr */
            double front = 0;
            for (k = 0; k < NS; ++k) {
                double dist = (k * hs - c) * side;
                int nx = k + side;
                if (dist < 0 || th[k] < thr) continue;
                front = dist;
                if (nx >= 0 && nx < NS && th[nx] < thr) front += hs * (th[k] - thr) / (th[k] - th[nx]);
            }
            sum += front;
        }
        if (t == 1) r.front1 = sum / 2;
        else r.front2 = sum / 2;
    }
    return r;
}

static double filter_s = -1; /* --filter: the scenes' transfer filter time (-1: their default, 2e-3 s) */
static double perturb = 1e-6; /* --perturb: the relative change of E of the chaos run */
static double friction = 1; /* --friction: the column's wall Coulomb coefficient [1: a rough floor] */

static int column(int res, double courant, double end, double settle, deposit *at_end, deposit *settled) {
    pn_ex_scene s;
    pn_mpm_world *w = NULL;
    pn_mpm_advance_desc a;
    char why[256] = "";
    double t = 0, t0 = pn_ex_seconds();
    pn_ex_scene_default(&s, PN_EX_SAND_COLUMN, 2);
    s.res = res;
    s.energy = PN_ENERGY_LAGGED; /* explicit runs ignore it; no network to set up */
    if (filter_s >= 0) s.filter_s = filter_s;
    s.friction = friction;
    if (pn_ex_scene_create(&s, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "bench_deposit: %s\n", why);
        return 0;
    }
    memset(&a, 0, sizeof a);
    a.integrator = PN_MPM_EXPLICIT;
    a.courant = (pn_real)courant;
    while (t < (settle > end ? settle : end) - 1e-9) {
        if (pn_mpm_advance(w, (pn_real)0.04, &a, NULL) != PN_OK) {
            fprintf(stderr, "bench_deposit: res %d courant %g: %s\n", res, courant, pn_mpm_error(w));
            pn_mpm_destroy(w);
            return 0;
        }
        t += 0.04;
        if (fabs(t - end) < 1e-6) {
            *at_end = measure(w, &s);
            at_end->seconds = pn_ex_seconds() - t0;
        }
    }
    if (settled) *settled = measure(w, &s);
    pn_mpm_destroy(w);
    return 1;
}

/* --only: run one part (column, settle, press), or all when empty */
static int want(const char *only, const char *part) { return !*only || !strcmp(only, part); }

static double rel(double a, double b) { return fabs(a - b) / fabs(b); }

/* the snow press at res, courant: the normalized mass field at each frame into f (frames x
   nodes), and the deepest compaction (min h) */
static int press(int res, double courant, double perturb, int frames, double *f, size_t nodes, double *hmin,
                 double *seconds) {
    pn_ex_scene s;
    pn_mpm_world *w = NULL;
    pn_mpm_advance_desc a;
    char why[256] = "";
    double t0 = pn_ex_seconds();
    size_t p;
    int k;
    pn_ex_scene_default(&s, PN_EX_SNOW_PRESS, 2);
    s.res = res;
    if (filter_s >= 0) s.filter_s = filter_s;
    s.E_pa *= 1 + perturb;
    s.energy = PN_ENERGY_LAGGED;
    if (pn_ex_scene_create(&s, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "bench_deposit: %s\n", why);
        return 0;
    }
    if (pn_ex_field_size(w) != nodes) return 0;
    memset(&a, 0, sizeof a);
    a.integrator = PN_MPM_EXPLICIT;
    a.courant = (pn_real)courant;
    for (k = 0; k < frames; ++k) {
        if (pn_mpm_advance(w, (pn_real)0.04, &a, NULL) != PN_OK) {
            fprintf(stderr, "bench_deposit: snow press res %d courant %g: %s\n", res, courant, pn_mpm_error(w));
            pn_mpm_destroy(w);
            return 0;
        }
        pn_ex_mass_field(w, f + (size_t)k * nodes);
    }
    *hmin = 0;
    for (p = 0; p < w->n; ++p) *hmin = (double)w->h[p] < *hmin ? (double)w->h[p] : *hmin;
    *seconds = pn_ex_seconds() - t0;
    pn_mpm_destroy(w);
    return 1;
}

int main(int argc, char **argv) {
    int quick = 0, i, k, res[3] = {64, 128, 256};
    double end = 1, settle = 3, courants[3] = {1, 0.5, 0.25};
    const char *mdp = "build/bench_deposit.md", *only = "";
    deposit dx_runs[3], dt_runs[3], set_at1[4], set_end[4];
    FILE *md;
    for (i = 1; i < argc; ++i) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--quick")) quick = 1;
        else if (v && !strcmp(a, "--end")) end = atof(v), ++i;
        else if (v && !strcmp(a, "--settle")) settle = atof(v), ++i;
        else if (v && !strcmp(a, "--md")) mdp = v, ++i;
        else if (v && !strcmp(a, "--filter")) filter_s = atof(v), ++i;
        else if (v && !strcmp(a, "--friction")) friction = atof(v), ++i;
        else if (v && !strcmp(a, "--perturb")) perturb = atof(v), ++i;
        else if (v && !strcmp(a, "--only")) only = v, ++i;
        else {
            fprintf(stderr, "usage: %s [--quick] [--end S] [--settle S] [--filter S] [--friction F] [--perturb X]\n"
                            "       [--only column|settle|press] [--md FILE]\n", argv[0]);
            return 2;
        }
    }
    if (quick) {
        res[0] = 32, res[1] = 64, res[2] = 128;
        end = 0.6, settle = 1.2;
    }
    if (!(md = fopen(mdp, "w"))) {
        fprintf(stderr, "bench_deposit: cannot write %s\n", mdp);
        return 1;
    }
    /* 1. dx and dt halvings */
    for (k = 0; k < 3 && want(only, "column"); ++k) {
        if (!column(res[k], 1, end, 0, &dx_runs[k], NULL)) return 1;
        printf("column res %d courant 1: front(1 cm) %.4f m, front(2 cm) %.4f m, summit %.4f m, core %.4f m (%.1f s)\n",
               res[k], dx_runs[k].front1, dx_runs[k].front2, dx_runs[k].summit, dx_runs[k].core, dx_runs[k].seconds);
        fflush(stdout);
    }
    dt_runs[0] = dx_runs[1];
    for (k = 1; k < 3 && want(only, "column"); ++k) {
        if (!column(res[1], courants[k], end, 0, &dt_runs[k], NULL)) return 1;
        printf("column res %d courant %g: front(1 cm) %.4f m, front(2 cm) %.4f m, summit %.4f m, core %.4f m (%.1f s)\n",
               res[1], courants[k], dt_runs[k].front1, dt_runs[k].front2, dt_runs[k].summit, dt_runs[k].core,
               dt_runs[k].seconds);
        fflush(stdout);
    }
    if (want(only, "column")) {
    fprintf(md, "## Sand column deposit at %.2g s (2D, explicit)\n\n", end);
    fprintf(md, "| run | front, thickness >= 1 cm (m) | front, >= 2 cm (m) | summit (m) | core (m) | wall s |\n"
                "|---|---|---|---|---|---|\n");
    for (k = 0; k < 3; ++k)
        fprintf(md, "| res %d, stable step | %.4f | %.4f | %.4f | %.4f | %.1f |\n", res[k], dx_runs[k].front1,
                dx_runs[k].front2, dx_runs[k].summit, dx_runs[k].core, dx_runs[k].seconds);
    for (k = 1; k < 3; ++k)
        fprintf(md, "| res %d, step x %g | %.4f | %.4f | %.4f | %.4f | %.1f |\n", res[1], courants[k], dt_runs[k].front1,
                dt_runs[k].front2, dt_runs[k].summit, dt_runs[k].core, dt_runs[k].seconds);
    fprintf(md, "\n| halving | front 1 cm | front 2 cm | summit | core |\n|---|---|---|---|---|\n");
    for (k = 1; k < 3; ++k)
        fprintf(md, "| dx: res %d -> %d | %.1f%% | %.1f%% | %.1f%% | %.1f%% |\n", res[k - 1], res[k],
                100 * rel(dx_runs[k].front1, dx_runs[k - 1].front1), 100 * rel(dx_runs[k].front2, dx_runs[k - 1].front2),
                100 * rel(dx_runs[k].summit, dx_runs[k - 1].summit), 100 * rel(dx_runs[k].core, dx_runs[k - 1].core));
    for (k = 1; k < 3; ++k)
        fprintf(md, "| dt: x %g -> x %g (res %d) | %.1f%% | %.1f%% | %.1f%% | %.1f%% |\n", courants[k - 1], courants[k],
                res[1], 100 * rel(dt_runs[k].front1, dt_runs[k - 1].front1),
                100 * rel(dt_runs[k].front2, dt_runs[k - 1].front2), 100 * rel(dt_runs[k].summit, dt_runs[k - 1].summit),
                100 * rel(dt_runs[k].core, dt_runs[k - 1].core));
    }
    fflush(md);
    /* 2. the settled pile */
    if (want(only, "settle")) fprintf(md, "\n## Settled pile: core and summit at 1 s and at %.2g s\n\n| run | core at 1 s (m) | at %.2g s (m) | sank | "
                "summit at 1 s (m) | at %.2g s (m) |\n|---|---|---|---|---|---|\n", settle, settle, settle);
    for (k = 0; k < 4 && want(only, "settle"); ++k) {
        int r = res[k / 2];
        double c = courants[k % 2];
        if (!column(r, c, quick ? 0.6 : 1.0, settle, &set_at1[k], &set_end[k])) return 1;
        printf("settled res %d courant %g: core %.4f m -> %.4f m, summit %.4f m -> %.4f m\n", r, c, set_at1[k].core,
               set_end[k].core, set_at1[k].summit, set_end[k].summit);
        fprintf(md, "| res %d, step x %g | %.4f | %.4f | %.2f%% | %.4f | %.4f |\n", r, c, set_at1[k].core, set_end[k].core,
                100 * (set_at1[k].core - set_end[k].core) / set_at1[k].core, set_at1[k].summit, set_end[k].summit);
        fflush(stdout);
    }
    /* 3. the snow press: frames of 0.04 s while the plate goes 0.08 m down */
    if (want(only, "press")) {
        int frames = 5, r = quick ? 32 : 64, j;
        size_t nodes = (size_t)(r + 1) * (size_t)(r + 1);
        double *f[4], hmin[4], sec[4];
        for (k = 0; k < 4; ++k) { /* the fourth: step x 1/2 with E x (1 + perturb), how chaotic it is */
            f[k] = (double *)malloc(sizeof(double) * nodes * (size_t)frames);
            if (!f[k] || !press(r, courants[k < 3 ? k : 1], k < 3 ? 0 : perturb, frames, f[k], nodes, &hmin[k], &sec[k]))
                return 1;
        }
        fprintf(md, "\n## Snow press (2D, res %d, explicit): min/max mass IoU between step halvings (perturb: %g)\n\n"
                    "| runs | mean over %d frames | worst frame | deepest log J_p |\n|---|---|---|---|\n", r, perturb, frames);
        for (k = 0; k < 4; ++k) {
            int a = k < 2 ? k : k == 2 ? 0 : 1, b = k < 2 ? k + 1 : k == 2 ? 2 : 3;
            double mean = 0, worst = 1;
            for (j = 0; j < frames; ++j) {
                pn_ex_iou_scores sc = pn_ex_iou(f[a] + (size_t)j * nodes, f[b] + (size_t)j * nodes, nodes);
                mean += sc.minmax / frames;
                worst = sc.minmax < worst ? sc.minmax : worst;
            }
            printf("snow press: step x %g vs x %g%s: min/max IoU mean %.4f, worst %.4f\n", courants[a], courants[b < 3 ? b : 1],
                   b == 3 ? " with E x (1 + perturb)" : "", mean, worst);
            fprintf(md, "| step x %g vs x %g%s | %.4f | %.4f | %.4f vs %.4f |\n", courants[a], courants[b < 3 ? b : 1],
                    b == 3 ? " with E x (1 + perturb)" : "", mean, worst, hmin[a], hmin[b]);
        }
        for (k = 0; k < 4; ++k) free(f[k]);
    }
    fclose(md);
    printf("written: %s\n", mdp);
    return 0;
}
