/* bench_mpm: speed against accuracy of the MPM integrators of plastinet_mpm.h on the sand column
   and the snow press of docs/validation.md (scenes in examples/common/pn_example.h), or the snowball
   (--snowball: its fracture is chaotic, so its reference is not converged).
   Build: cc -std=c99 -O2 bench/bench_mpm.c -lm -o bench_mpm        (or: make bench-mpm)
   Usage: bench_mpm [--quick] [--only sand|snow] [--dim 2|3] [--duration S] [--res2 N] [--res3 N]
                    [--max-run-seconds S] [--filter S] [--references] [--out DIR] [--snowball]
                    [--dts S,S,..] [--passes N,N,..] [--energies pnet,lagged,dp,stress] [--no-sweep]
                    [--contact-rounds N] [--cg-forcing X] [--no-hardening] [--cost] [--min-wall S]
                    [--sweep-only] [--sweep-dim 2|3] [--sweep-res N] [--sweep-E E,E,..]
                    [--sweep-runs I,I,..] [--sweep-scene sand|snow] [--sweep-tol X] [--cell-relax X]
                    [--energy-rise-tol X] [--anderson on|off] [--materials]
          bench_mpm --scale [--scale-dim 2|3] [--scale-res2 N,N,..] [--scale-res3 N,N,..] [--sweep-E E,E,..]
                    [--duration S] [--max-run-seconds S] [--out DIR] [--scale-count] [--scale-implicit-only]
                    (or: make bench-scale)
   Defaults: both scenes, 2D at res 64 (1 m) for 0.5 s and 3D at res 16 (0.5 m) for 0.3 s
   simulated (the snow press for at most 0.2 s, while its plate goes 0.08 domain_m deep), at
   most 120 wall seconds per run (--max-run-seconds 0: no limit), DIR = build.
   --quick: 2D only (unless --dim), res 32, 2 frames, implicit dt 1e-3 and 1e-2 with 1 and 2
   passes, sweep E 1e6 and 1e7. --filter S: the scenes' transfer filter time
   (pn_mpm_desc.filter_time_s; 0: plain APIC) instead of their default. --references: only
   the fair baseline, the reference and its check (how converged the reference is), no sweep.
   --dts, --passes, --energies: only these implicit steps, fixed-point passes and energies
   (lists of up to 8, comma separated) instead of the full grid; --no-sweep: skip the sweep.
   --contact-rounds N: every implicit run with pn_mpm_implicit_desc.contact_rounds = N (up
   to N solves per fixed-point pass while separating contact changes its set) [1].
   --cg-forcing X: pn_mpm_implicit_desc.cg_forcing_max (the loosest CG residual of the
   Eisenstat-Walker forcing, e.g. 0.5) [0: off]. --no-hardening: the snow's Cam-Clay without
   hardening (pn_ex_scene.no_hardening), to see what its fracture does to the reference.
   --min-wall S: the fair run and the implicit runs of the scenes (not the sweep or --scale)
   that took less than S wall seconds are stepped again, unscored, until S seconds have gone
   by in all (at most 10 runs), and the fastest run's wall and processor seconds are kept: a
   run of a fraction of a second is at the mercy of the machine's clock [2; 0: one run].
   --cost: instead of the runs, DIR/bench_mpm_cost.md: per step, the fair explicit step, the
   least an implicit step at 1e-3 s can cost (one Newton and one CG iteration), each further
   CG iteration, and a real step, against the budget docs/validation.md's time bar leaves a step
   (sand: half the fair explicit time, snow: the same).

   --materials: instead, the 2D sand column at friction angles 20, 30, 45 deg and Poisson
   ratios 0.3, 0.4 (E 1e7 Pa), each against its own explicit reference (the fair step / 4):
   implicit at --dts (default 1e-4 s, 2 fixed-point passes; 1e-3 s, 4) with the conditioned
   model pn_model_sand_any_2d, with the lagged energy, and at 30 deg / 0.3 with the
   single-material sand_2d; mass IoU and the runout (the deposit's half-width at the end,
   against the reference's). DIR/bench_mpm_materials.md.

   --scale: instead, the implicit sand column at user sizes, carried to its deposit (1.5 s
   simulated unless --duration; frames of 1/20 s, SCALE_FPS, so that 1/60 s steps divide them):
   the 3D column at res 49, 78, 122 (24863, 101306, 393588 particles; --scale-res3) and the 2D
   one at res 417, 932 (20000, 99681; --scale-res2), both unless --scale-dim, at E 1e7 and
   1e9 Pa (--sweep-E). Per (dim, res, E), with the sweep's machinery: the fair explicit
   baseline (bench_fair), the explicit reference at half its step (the sweep's rule), and the
   stress formulation (the group's Drucker-Prager) per particle at the advection limit and at
   1/60 s, per cell (stress_unknowns cells) at both, and cells then particles at the
   advection limit. The advection limit: the library has
   no helper that returns it (pn_mpm_advance picks such steps inside), so
   dt = dx / (2 sqrt(2 g H)), H the column height (the free fall from its top at half a cell
   per step), rounded down to whole steps per frame. Per run: particles, dt, dt / dt_CFL
   (dt_CFL: the fair explicit step), sweeps, coarse corrections, Newton and CG iterations per
   step, the share of steps retried as substeps (material moving over a cell), the share of
   each pn_mpm_stats.stage_s stage, mean / min min/max mass IoU against the reference, runout
   and final height (the highest particle above the floor) over the reference's, wall and
   processor (clock()) seconds per simulated second and the processor time over the fair
   run's. Runs at 400k particles take hours, so the mode resumes: each run is appended to
   DIR/bench_scale.csv as it ends, and a start skips the runs already there (key: dim, res, E,
   run, dt; the fair run, whose step is searched, by dim, res, E; one DIR per --duration). The
   fair run is written once the reference exists to score it, and the reference's mass fields
   are kept in DIR/bench_scale_ref_<dim>d_res<res>_E<E>.bin (about 450 MB at res 122; in
   memory the reference's and the fair run's fields, twice that), so that a resumed start does
   not repeat it. --max-run-seconds (none by default here) stops an implicit run, which is then a
   "timeout" row (and is skipped later: delete the row to run it again). --scale-count:
   print the particle count of each size and stop. --scale-implicit-only: the stress
   formulation's runs alone, without the explicit runs or any score (IoU, deposit ratios,
   dt / dt_CFL and CPU x fair are then "-"): the work per step and the cost's slope in
   particles at sizes whose explicit runs take too long (in a DIR of its own). --filter and the solver's flags
   (--sweep-tol, --cell-relax, --anderson on|off, --energy-rise-tol) apply as elsewhere. DIR/bench_scale.md: the
   table of every row of the CSV.

   For each scene and dimension, in one run:
   1. the fair explicit baseline: the largest stable explicit step, searched from the CFL
      estimate dt = 0.5 dx / sqrt(E / rho) times 4 (rounded down to a whole number of steps
      per frame) by halving until the whole run stays finite and bounded: no failed step, no
      particle leaving the domain, max particle speed <= 2 (v0 + sqrt(2 g L)) and kinetic
      energy <= 1.5 (initial kinetic + potential energy above the floor);
   2. the explicit reference at a quarter of that step, and the same at an eighth: how far
      their mean min/max mass IoU is from 1 says how converged the reference is; and the
      reference's step with E larger by 1e-6: how far that is from 1 says how chaotic the
      scene is, a floor under any integrator's distance from the reference;
   3. implicit at dt 1e-4, 1e-3, 1e-2 s with 1, 2 and 4 fixed-point passes, with the
      PlasticityNet energy and with the lagged energy, and for sand also with the frozen-yield
      Drucker-Prager energy (pn_dp_energy); and the stress formulation (one run per dt: it has
      no fixed point).
   Every run is compared with the reference frame by frame (25 fps, so that every dt above
   divides a frame) by the mass IoUs of examples/common/pn_example.h: soft (the formula of
   docs/validation.md; below 1 even for identical fields, so the reference's score against itself
   is its ceiling), min/max (1 for identical fields; the plots use it) and binary occupancy.
   Then a Young's-modulus sweep of the sand column (1e6 to 1e10 Pa; --sweep-E, at --sweep-res
   cells, default the res of --sweep-dim, 2D unless said): at each E the fair explicit baseline
   (searched as above), the reference at half its step, and implicit runs of the lagged and
   frozen-yield DP energies with multigrid and Jacobi CG and of the stress formulation, its
   stresses per particle, per cell, and per cell then per particle (sweep_cfgs, numbered from
   1 for --sweep-runs), IoU against that reference, and the
   crossover (the smallest E where implicit is faster than the fair baseline at mean min/max
   IoU >= 0.90). --sweep-scene snow: the same sweep on the snow press (Neo-Hookean snow with
   Cam-Clay; every run but the DP energy's), its crossover at mean IoU >= 0.85.
   --sweep-only: the sweep alone.
   Wall time: clock_gettime(CLOCK_MONOTONIC) around the steps only (scene setup and the IoU
   rasterization excluded); processor seconds (clock()) go to the CSV beside it, so a run
   slowed by another process shows as wall > cpu.
   Writes DIR/bench_mpm.csv, DIR/bench_mpm_esweep.{csv,md}, DIR/bench_mpm.svg (mean IoU against
   wall seconds per simulated second), DIR/bench_mpm_esweep.svg and DIR/bench_mpm.md (tables
   for the README); progress on stderr. A run that fails (step error, unbounded, over the time
   limit) is a row that says so, with the figures of the frames it completed. */
#define PLASTINET_IMPLEMENTATION
#include "../examples/common/pn_example.h"
#include "../models/pn_model_sand_any_2d.h"

#define BENCH_FPS 25 /* 0.04 s frames: 1e-4, 1e-3 and 1e-2 s all divide them */
#define BENCH_MAX_FRAMES 1000
#define BENCH_MAX_RUNS 64
#define BENCH_PERTURB 1e-6 /* relative change of E for the reference's sensitivity */
#define BENCH_REF_DIV 4 /* the reference runs at the fair step / 4, its check at / 8 */

typedef enum { RUN_OK = 0, RUN_STEP_FAILED, RUN_UNBOUNDED, RUN_TIMEOUT } run_status;

/* one row: what was run and what it gave */
typedef struct bench_run {
    char role[16];        /* reference, ref_check, ref_perturbed, fair, implicit    */
    int implicit, fp;     /* fixed-point passes (implicit)                          */
    pn_energy energy; /* implicit only                                          */
    int stress;           /* implicit in the stress formulation (energy: the group's law) */
    double dt;
    run_status status;
    pn_result error;      /* RUN_STEP_FAILED                                        */
    double fail_t;        /* simulated time the run stopped at, if it did           */
    int frames, frames_done;
    size_t particles;
    double wall, cpu, sim; /* seconds stepping, simulated seconds done              */
    pn_ex_tally tally;
    double iou_mean, iou_min;       /* soft IoU (the formula of docs/validation.md)     */
    double mm_mean, mm_min;         /* min/max IoU (1 for identical fields)        */
    double biou_mean;               /* binary occupancy IoU                        */
    int scored;                     /* compared with a reference                   */
    double runout;                  /* at the end: the largest |x - domain centre| */
    double height;                  /* at the end: the highest particle above the floor */
    double frame_s;                 /* the frames' length [0: 1 / BENCH_FPS]           */
    double fair_wps_beside;         /* the fair run's wall s per simulated s, timed
                                       beside this run (bench_retime; 0: not timed)     */
} bench_run;

typedef struct bench_cfg {
    double duration[4];   /* simulated seconds, by dimension                       */
    int res[4];           /* cells per axis, by dimension                          */
    double max_run_s;     /* stop a run after this many wall seconds (0: never)     */
    double min_wall_s;    /* time short runs again, keep the fastest (bench_retime)  */
    int quick;
    int refs_only;        /* only the fair baseline, the reference and its check     */
    double filter;        /* the scenes' transfer filter time (< 0: their default)  */
    int no_hardening;     /* the snow without Cam-Clay hardening                    */
    int snowball;         /* the snow scene: the snowball instead of the snow press  */
    const double *dts;    /* implicit steps                                        */
    int n_dts;
    const int *fps_iters; /* fixed-point passes                                    */
    int n_fps;
    unsigned energy_mask; /* bit e: run energies_run[e] (bench_one)                 */
    pn_mpm_implicit_desc solver; /* implicit runs: contact_rounds, cg_forcing_max;
                                    fixed_point_iters is set per run              */
    const double *Es;     /* the sweep                                             */
    int n_Es, sweep_res, sweep_dim;
    unsigned sweep_mask;  /* bit c: run sweep_cfgs[c]                              */
    pn_ex_scene_kind sweep_kind; /* the sweep's scene: the sand column or the snow press */
    int scale_res[4][8], scale_n_res[4]; /* --scale: the sizes, by dimension             */
    int scale_implicit_only; /* --scale-implicit-only: no explicit runs, nothing scored    */
    const char *out;
} bench_cfg;

/* the scene of a benchmark kind (0: sand column, 1: snow) */
static pn_ex_scene_kind bench_kind(const bench_cfg *cfg, int kind) {
    return kind == 0 ? PN_EX_SAND_COLUMN : cfg->snowball ? PN_EX_SNOWBALL : PN_EX_SNOW_PRESS;
}

/* frames of 1/BENCH_FPS s a run of scene s lasts: the dimension's duration, and for the snow
   press no longer than the plate takes to go 0.08 domain_m deep (0.2 s) */
static int bench_frames(const bench_cfg *cfg, const pn_ex_scene *s) {
    double t = cfg->duration[s->dim];
    int frames;
    if (s->kind == PN_EX_SNOW_PRESS && t > 0.08 * s->domain_m / s->press_m_s) t = 0.08 * s->domain_m / s->press_m_s;
    frames = (int)floor(t * BENCH_FPS + 0.5);
    return frames < 1 ? 1 : frames > BENCH_MAX_FRAMES ? BENCH_MAX_FRAMES : frames;
}

static const char *energy_name(const bench_run *r) {
    if (!r->implicit) return "return_mapping";
    if (r->stress) return "stress";
    return r->energy == PN_ENERGY_PNET     ? "pnet"
           : r->energy == PN_ENERGY_LAGGED ? "lagged"
           : r->energy == PN_ENERGY_DP     ? "dp"
                                               : "other";
}

static const char *status_name(const bench_run *r) {
    static const char *const names[] = {"yes", "step failed", "unbounded", "timeout"};
    return names[r->status];
}

/* the CSV's status column: ok, the step error, unbounded or timeout */
static const char *status_detail(const bench_run *r) {
    if (r->status == RUN_OK) return "ok";
    return r->status == RUN_STEP_FAILED ? pn_result_string(r->error) : status_name(r);
}

static double wall_per_sim(const bench_run *r) { return r->sim > 0 ? r->wall / r->sim : 0; }

/* r's wall time over the fair run's: the one timed beside it if there is one, else fair_wps */
static double x_fair(const bench_run *r, double fair_wps) {
    double fw = r->fair_wps_beside > 0 ? r->fair_wps_beside : fair_wps;
    return fw > 0 ? wall_per_sim(r) / fw : 0;
}

/* sum m (|v|^2 / 2) and sum m g (y - floor) over active particles */
static void energies(const pn_mpm_world *w, double floor_y, double *kin, double *pot) {
    size_t p;
    int i;
    *kin = *pot = 0;
    for (p = 0; p < w->n; ++p) {
        double v2 = 0;
        if (!w->active[p]) continue;
        for (i = 0; i < w->dim; ++i) v2 += (double)w->v[p * (size_t)w->dim + (size_t)i] * (double)w->v[p * (size_t)w->dim + (size_t)i];
        *kin += 0.5 * (double)w->mass[p] * v2;
        *pot += (double)w->mass[p] * 9.81 * ((double)w->x[p * (size_t)w->dim + 1] - floor_y);
    }
}

/* Frame f's scores of field a against the reference's b, kept as running sums (frame 0
   starts them); a == NULL turns the sums over `f` frames into means. */
static void bench_score(bench_run *r, int f, const double *a, const double *b, size_t nodes) {
    pn_ex_iou_scores s;
    if (!a) {
        if (f > 0) {
            r->iou_mean /= f;
            r->mm_mean /= f;
            r->biou_mean /= f;
        }
        return;
    }
    if (f == 0) {
        r->iou_mean = r->mm_mean = r->biou_mean = 0;
        r->iou_min = r->mm_min = 1;
    }
    s = pn_ex_iou(a, b, nodes);
    r->scored = 1;
    r->iou_mean += s.soft;
    r->mm_mean += s.minmax;
    r->biou_mean += s.binary;
    if (s.soft < r->iou_min) r->iou_min = s.soft;
    if (s.minmax < r->mm_min) r->mm_min = s.minmax;
}

/* Run scene s as r describes for `frames` frames. fields (frames x nodes, may be NULL) gets
   each frame's normalized mass field; ref (may be NULL) is the reference's, for the IoU. */
static void bench_run_scene(const pn_ex_scene *s0, bench_run *r, int frames, double max_run_s,
                            const pn_mpm_implicit_desc *solver, double *fields, const double *ref) {
    pn_ex_scene s = *s0;
    pn_mpm_world *w;
    pn_mpm_implicit_desc id;
    char why[256] = "";
    double frame_dt = r->frame_s > 0 ? r->frame_s : 1.0 / BENCH_FPS, kin0, pot0, kin, pot, vmax, *field;
    long per_frame = (long)floor(frame_dt / r->dt + 0.5);
    size_t nodes;
    int f;
    r->frames = frames;
    r->frames_done = 0;
    r->status = RUN_OK;
    r->wall = r->cpu = r->sim = 0;
    memset(&r->tally, 0, sizeof r->tally);
    if (r->implicit) s.energy = r->energy;
    if (pn_ex_scene_create(&s, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "bench_mpm: %s\n", why);
        exit(1);
    }
    r->particles = w->n;
    nodes = pn_ex_field_size(w);
    field = (double *)malloc(sizeof(double) * nodes);
    if (!field) exit(1);
    energies(w, pn_ex_scene_floor(&s), &kin0, &pot0);
    vmax = 2 * (s.kind == PN_EX_SNOWBALL ? s.speed_m_s : 0) + 2 * sqrt(2 * 9.81 * s.domain_m);
    memset(&id, 0, sizeof id);
    if (solver) id = *solver;
    id.fixed_point_iters = r->fp;
    if (r->stress) id.formulation = PN_MPM_FORMULATION_STRESS;
    for (f = 0; f < frames; ++f) {
        double t0 = pn_ex_seconds(), c0 = (double)clock() / CLOCKS_PER_SEC;
        pn_result e = pn_ex_steps(w, r->implicit, r->dt, &id, per_frame, &r->tally);
        r->wall += pn_ex_seconds() - t0;
        r->cpu += (double)clock() / CLOCKS_PER_SEC - c0;
        r->sim = (double)w->time_s;
        if (e != PN_OK) {
            r->status = RUN_STEP_FAILED;
            r->error = e;
            break;
        }
        energies(w, pn_ex_scene_floor(&s), &kin, &pot);
        if (w->left_total > 0 || !(r->tally.max_speed_m_s <= vmax) || !(kin <= 1.5 * (kin0 + pot0))) {
            r->status = RUN_UNBOUNDED;
            break;
        }
        pn_ex_mass_field(w, fields ? fields + (size_t)f * nodes : field);
        if (ref) bench_score(r, f, fields ? fields + (size_t)f * nodes : field, ref + (size_t)f * nodes, nodes);
        r->frames_done = f + 1;
        if (max_run_s > 0 && r->wall > max_run_s && f + 1 < frames) {
            r->status = RUN_TIMEOUT;
            break;
        }
    }
    r->fail_t = r->sim;
    if (ref) bench_score(r, r->frames_done, NULL, NULL, nodes);
    { /* the deposit's half-width and height */
        size_t p;
        r->runout = r->height = 0;
        for (p = 0; p < w->n; ++p)
            if (w->active[p]) {
                r->runout = fmax(r->runout, fabs((double)w->x[p * (size_t)w->dim] - 0.5 * s.domain_m));
                r->height = fmax(r->height, (double)w->x[p * (size_t)w->dim + 1] - pn_ex_scene_floor(&s));
            }
    }
    free(field);
    pn_mpm_destroy(w);
}

/* IoU of stored fields against the reference's, over the frames r completed */
static void bench_compare(bench_run *r, const double *fields, const double *ref, size_t nodes) {
    int f;
    for (f = 0; f < r->frames_done; ++f) bench_score(r, f, fields + (size_t)f * nodes, ref + (size_t)f * nodes, nodes);
    bench_score(r, r->frames_done, NULL, NULL, nodes);
}

static void bench_progress(const char *scene, int dim, const bench_run *r) {
    char iou[48] = "", beside[48] = "";
    if (r->scored) snprintf(iou, sizeof iou, "IoU soft %.3f min/max %.3f, ", r->iou_mean, r->mm_mean);
    if (r->fair_wps_beside > 0) snprintf(beside, sizeof beside, " (%.2fx the fair run beside it)", x_fair(r, 0));
    fprintf(stderr, "  %-5s %dD %-9s %-14s dt %-9.3g fp %d: %6.2f wall s/sim s%s, %sNewton %.1f CG %.0f sweeps %.0f per step, %s\n",
            scene, dim, r->role, energy_name(r), r->dt, r->implicit ? r->fp : 0, wall_per_sim(r), beside, iou,
            r->tally.steps ? (double)r->tally.newton / r->tally.steps : 0.0,
            r->tally.steps ? (double)r->tally.cg / r->tally.steps : 0.0,
            r->tally.steps ? (double)r->tally.sweeps / r->tally.steps : 0.0, status_name(r));
}

/* The fair explicit baseline: the largest stable step, in halvings from the CFL estimate, in
   frames of frame_dt s. Its fields (if not NULL) are kept for the IoU. Returns 0 if no step
   was stable. */
static int bench_fair(const pn_ex_scene *s, int frames, double frame_dt, bench_run *r, double *fields) {
    double c = sqrt(s->E_pa / s->density_kg_m3);
    double dt = 0.5 * pn_ex_scene_dx(s) / c * 4;
    long n = (long)ceil(frame_dt / dt - 1e-9); /* whole steps per frame, so halving stays exact */
    int k;
    for (k = 0; k < 16; ++k, n *= 2) {
        memset(r, 0, sizeof *r);
        strcpy(r->role, "fair");
        r->frame_s = frame_dt;
        r->dt = frame_dt / (double)n;
        bench_run_scene(s, r, frames, 0, NULL, fields, NULL);
        fprintf(stderr, "    search dt %.4g: %s\n", r->dt, status_name(r));
        if (r->status == RUN_OK) return 1;
    }
    return 0;
}

/* Timing that the machine's drift does not decide. r, done, is stepped again, unscored, while
   all its runs together took less than min_wall_s wall seconds (at most 10 runs); r keeps
   the fastest run's wall and processor seconds (the steps are the same, so nothing else
   changes). With fair (the fair run's row), the fair run is stepped again beside each of
   r's runs, and r->fair_wps_beside keeps its fastest: a run's x fair is then a ratio of
   times taken minutes, not a whole bench, apart. */
static void bench_retime(const pn_ex_scene *s, bench_run *r, const bench_run *fair, int frames,
                         const pn_mpm_implicit_desc *solver, double min_wall_s) {
    double total = r->wall;
    int k;
    for (k = 0; k < 10 && min_wall_s > 0 && r->status == RUN_OK; ++k) {
        bench_run again;
        if (fair) {
            again = *fair;
            bench_run_scene(s, &again, frames, 0, NULL, NULL, NULL);
            if (again.status == RUN_OK && (r->fair_wps_beside <= 0 || wall_per_sim(&again) < r->fair_wps_beside))
                r->fair_wps_beside = wall_per_sim(&again);
        }
        if (total >= min_wall_s) break;
        again = *r;
        bench_run_scene(s, &again, frames, 0, solver, NULL, NULL);
        total += again.wall;
        if (again.status != RUN_OK) break;
        if (again.wall < r->wall) r->wall = again.wall, r->cpu = again.cpu;
    }
}

/* ---- output ----------------------------------------------------------------------------- */

static void csv_header(FILE *f) {
    fprintf(f, "scene,dim,role,integrator,energy,dt_s,fixed_point_iters,particles,frames,frames_done,"
               "mass_iou_mean,mass_iou_min,minmax_iou_mean,minmax_iou_min,binary_iou_mean,wall_s,cpu_s,simulated_s,"
               "wall_per_sim_s,ratio_to_fair,newton_per_step,cg_per_step,fixed_point_per_step,line_search_failures,"
               "halved_steps,max_fixed_point_residual,dt_over_cfl,cg_capped,finite,status\n");
}

static void csv_row(FILE *f, const char *scene, int dim, const bench_run *r, double fair_wps) {
    double st = r->tally.steps ? (double)r->tally.steps : 1;
    fprintf(f, "%s,%d,%s,%s,%s,%.6g,%d,%lu,%d,%d,%.4f,%.4f,%.4f,%.4f,%.4f,%.3f,%.3f,%.4f,%.4g,%.4g,%.2f,%.1f,%.2f,%ld,%ld,"
               "%.3e,%.3g,%ld,%s,\"%s\"\n", /* quoted: error strings hold commas */
            scene, dim, r->role, r->implicit ? "implicit" : "explicit", energy_name(r), r->dt, r->implicit ? r->fp : 0,
            (unsigned long)r->particles, r->frames, r->frames_done, r->iou_mean, r->iou_min, r->mm_mean, r->mm_min,
            r->biou_mean, r->wall, r->cpu, r->sim, wall_per_sim(r), x_fair(r, fair_wps),
            r->tally.newton / st, r->tally.cg / st, r->tally.fixed_point / st, r->tally.line_search_failures,
            r->tally.halved, r->tally.max_fixed_point_residual, r->tally.max_dt_over_cfl, r->tally.cg_capped,
            r->status == RUN_OK ? "yes" : "no",
            status_detail(r));
}

static void md_row(FILE *f, const char *scene, int dim, const bench_run *r, double fair_wps) {
    double st = r->tally.steps ? (double)r->tally.steps : 1;
    char finite[96], fp[8], res[16];
    if (r->status == RUN_OK) strcpy(finite, "yes");
    else if (r->status == RUN_TIMEOUT) snprintf(finite, sizeof finite, "stopped at t = %.2f s (time limit)", r->fail_t);
    else snprintf(finite, sizeof finite, "**no: %s at t = %.2f s**", r->status == RUN_STEP_FAILED ?
                  pn_result_string(r->error) : status_name(r), r->fail_t);
    if (r->implicit) snprintf(fp, sizeof fp, "%d", r->fp);
    else strcpy(fp, "-");
    /* with one pass the solver has no second F0 to compare with: the residual is not measured */
    if (r->implicit && (r->fp > 1 || r->tally.max_fixed_point_residual > 0))
        snprintf(res, sizeof res, "%.2e", r->tally.max_fixed_point_residual);
    else strcpy(res, "-");
    fprintf(f, "| %s | %d | %s | %s | %s | %.3g | %.3g | %s | %.3f / %.3f | %.3f / %.3f | %.3f | %.3g | %.2f | %.1f / %.0f / %.1f "
               "| %ld / %ld / %ld | %s | %s |\n",
            scene, dim, r->role, r->implicit ? "implicit" : "explicit", energy_name(r), r->dt, r->tally.max_dt_over_cfl, fp,
            r->iou_mean,
            r->iou_min, r->mm_mean, r->mm_min, r->biou_mean, wall_per_sim(r),
            x_fair(r, fair_wps), r->tally.newton / st, r->tally.cg / st,
            r->tally.fixed_point / st, r->tally.line_search_failures, r->tally.halved, r->tally.cg_capped, res, finite);
}

/* ---- a small SVG plot: log-x axis, linear or log y, labelled markers -------------------- */

typedef struct svg_panel {
    double ox, oy, w, h;               /* plot area in pixels                         */
    double x0, x1, y0, y1;             /* data range (log10 for log axes)             */
    int logy;
} svg_panel;

static double svg_px(const svg_panel *p, double x) { return p->ox + (log10(x) - p->x0) / (p->x1 - p->x0) * p->w; }
static double svg_py(const svg_panel *p, double y) {
    double v = p->logy ? log10(y) : y;
    return p->oy + p->h - (v - p->y0) / (p->y1 - p->y0) * p->h;
}

/* frame, decade ticks on x (and on y when logy), 0.1 ticks on a linear y */
static void svg_axes(FILE *f, const svg_panel *p, const char *title, const char *xlabel, const char *ylabel) {
    double t;
    fprintf(f, "<rect x='%.1f' y='%.1f' width='%.1f' height='%.1f' fill='white' stroke='#444'/>\n", p->ox, p->oy, p->w,
            p->h);
    fprintf(f, "<text x='%.1f' y='%.1f' font-size='13' font-weight='bold'>%s</text>\n", p->ox, p->oy - 8, title);
    fprintf(f, "<text x='%.1f' y='%.1f' font-size='11' text-anchor='middle'>%s</text>\n", p->ox + p->w / 2,
            p->oy + p->h + 32, xlabel);
    fprintf(f, "<text x='%.1f' y='%.1f' font-size='11' text-anchor='middle' transform='rotate(-90 %.1f %.1f)'>%s</text>\n",
            p->ox - 42, p->oy + p->h / 2, p->ox - 42, p->oy + p->h / 2, ylabel);
    for (t = ceil(p->x0 - 1e-9); t <= p->x1 + 1e-9; t += 1) {
        double x = p->ox + (t - p->x0) / (p->x1 - p->x0) * p->w;
        fprintf(f, "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/>\n", x, p->oy, x, p->oy + p->h);
        fprintf(f, "<text x='%.1f' y='%.1f' font-size='10' text-anchor='middle'>1e%d</text>\n", x, p->oy + p->h + 14,
                (int)t);
    }
    for (t = p->y0; t <= p->y1 + 1e-9; t += p->logy ? 1 : 0.1) {
        double y = p->oy + p->h - (t - p->y0) / (p->y1 - p->y0) * p->h;
        fprintf(f, "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#ddd'/>\n", p->ox, y, p->ox + p->w, y);
        if (p->logy) fprintf(f, "<text x='%.1f' y='%.1f' font-size='10' text-anchor='end'>1e%d</text>\n", p->ox - 4, y + 3, (int)floor(t + 0.5));
        else fprintf(f, "<text x='%.1f' y='%.1f' font-size='10' text-anchor='end'>%.1f</text>\n", p->ox - 4, y + 3, t);
    }
}

/* Labels already placed in a panel, so a new one can dodge them (greedy, vertical moves). */
typedef struct svg_labels {
    double x[BENCH_MAX_RUNS], y[BENCH_MAX_RUNS], w[BENCH_MAX_RUNS];
    int n;
} svg_labels;

static void svg_marker(FILE *f, const svg_panel *p, svg_labels *placed, double x, double y, const char *color,
                       int square, const char *label) {
    static const double shift[] = {0, 10, -10, 20, -20, 30, -30};
    double X = svg_px(p, x), Y = svg_py(p, y), w = 5.2 * (double)strlen(label), ty = Y + 3;
    int k, j;
    if (square) fprintf(f, "<rect x='%.1f' y='%.1f' width='8' height='8' fill='%s'/>\n", X - 4, Y - 4, color);
    else fprintf(f, "<circle cx='%.1f' cy='%.1f' r='4' fill='%s'/>\n", X, Y, color);
    for (k = 0; k < 7; ++k) { /* the first vertical offset whose box meets no placed label */
        double cy = Y + 3 + shift[k];
        for (j = 0; j < placed->n; ++j)
            if (X + 6 < placed->x[j] + placed->w[j] && placed->x[j] < X + 6 + w && fabs(cy - placed->y[j]) < 10) break;
        if (j == placed->n) {
            ty = cy;
            break;
        }
    }
    if (placed->n < BENCH_MAX_RUNS) {
        placed->x[placed->n] = X + 6;
        placed->y[placed->n] = ty;
        placed->w[placed->n++] = w;
    }
    if (ty != Y + 3) /* a leader line from the marker to its moved label */
        fprintf(f, "<line x1='%.1f' y1='%.1f' x2='%.1f' y2='%.1f' stroke='#999' stroke-width='0.5'/>\n", X + 3, Y,
                X + 6, ty - 3);
    fprintf(f, "<text x='%.1f' y='%.1f' font-size='9' fill='#333'>%s</text>\n", X + 6, ty, label);
}

/* decades covering [lo, hi] (both > 0) */
static void svg_log_range(double lo, double hi, double *a, double *b) {
    *a = floor(log10(lo));
    *b = ceil(log10(hi));
    if (*b <= *a) *b = *a + 1;
}

/* ---- one scene ---------------------------------------------------------------------------- */

typedef struct bench_scene {
    const char *name;
    int dim;
    bench_run runs[BENCH_MAX_RUNS];
    int n_runs, fair_index;
    double ref_convergence; /* 1 - mean min/max IoU(reference at dt/2, reference)       */
    double ref_sensitivity; /* 1 - mean min/max IoU(reference with E (1 + BENCH_PERTURB)) */
} bench_scene;

static void bench_one(const bench_cfg *cfg, pn_ex_scene_kind kind, int dim, bench_scene *out, FILE *csv) {
    pn_ex_scene s, sp;
    int frames, i, j, e, k;
    size_t nodes;
    double *ref, *tmp, fair_wps;
    pn_mpm_world *w;
    char why[256] = "";
    bench_run *r;
    /* the last is the stress formulation (its law is the group's: the DP energy's entry only
       selects sand's Drucker-Prager groups); fixed-point passes do not apply to it, so it runs
       at the first of them only */
    static const pn_energy energies_run[] = {PN_ENERGY_PNET, PN_ENERGY_LAGGED, PN_ENERGY_DP,
                                                 PN_ENERGY_DP};
    int n_energies = 4;
    pn_ex_scene_default(&s, kind, dim);
    s.res = cfg->res[dim];
    if (cfg->filter >= 0) s.filter_s = cfg->filter;
    s.no_hardening = cfg->no_hardening && kind != PN_EX_SAND_COLUMN;
    frames = bench_frames(cfg, &s);
    memset(out, 0, sizeof *out);
    out->name = kind == PN_EX_SAND_COLUMN ? "sand" : "snow";
    out->dim = dim;
    if (pn_ex_scene_create(&s, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "bench_mpm: %s\n", why);
        exit(1);
    }
    nodes = pn_ex_field_size(w);
    fprintf(stderr, "%s %dD: %lu particles, res %d, %d frames (%.2f s)\n", out->name, dim, (unsigned long)w->n, s.res,
            frames, frames / (double)BENCH_FPS);
    pn_mpm_destroy(w);
    /* zeroed: frames a failed reference never reached compare as empty (IoU 0), never as garbage */
    ref = (double *)calloc(nodes * (size_t)frames, sizeof(double));
    tmp = (double *)calloc(nodes * (size_t)frames, sizeof(double));
    if (!ref || !tmp) exit(1);
    /* 1. fair baseline (fields kept in tmp until the reference exists) */
    r = &out->runs[0];
    if (!bench_fair(&s, frames, 1.0 / BENCH_FPS, r, tmp)) {
        fprintf(stderr, "bench_mpm: %s %dD: no stable explicit step found\n", out->name, dim);
        out->n_runs = 1;
        csv_row(csv, out->name, dim, r, 0);
        free(ref);
        free(tmp);
        return;
    }
    out->fair_index = 0;
    bench_retime(&s, r, NULL, frames, NULL, cfg->min_wall_s);
    /* 2. reference and its check at half the step */
    r = &out->runs[1];
    strcpy(r->role, "reference");
    r->dt = out->runs[0].dt / BENCH_REF_DIV;
    bench_run_scene(&s, r, frames, 0, NULL, ref, NULL);
    if (r->status != RUN_OK) fprintf(stderr, "bench_mpm: the reference failed (%s)\n", status_name(r));
    bench_compare(r, ref, ref, nodes);
    bench_compare(&out->runs[0], tmp, ref, nodes);
    r = &out->runs[2];
    strcpy(r->role, "ref_check");
    r->dt = out->runs[0].dt / (2 * BENCH_REF_DIV);
    bench_run_scene(&s, r, frames, 0, NULL, NULL, ref);
    out->ref_convergence = 1 - r->mm_mean;
    /* the reference's step with E off by BENCH_PERTURB: a chaotic scene (one that fragments)
       loses IoU to a change far below any measurement, and then no integrator can score
       near 1 against it */
    r = &out->runs[3];
    strcpy(r->role, "ref_perturbed");
    r->dt = out->runs[1].dt;
    sp = s;
    sp.E_pa *= 1 + BENCH_PERTURB;
    bench_run_scene(&sp, r, frames, 0, NULL, NULL, ref);
    out->ref_sensitivity = 1 - r->mm_mean;
    out->n_runs = 4;
    for (i = 0; i < 4; ++i) bench_progress(out->name, dim, &out->runs[i]);
    /* 3. implicit */
    for (e = 0; e < n_energies && !cfg->refs_only; ++e)
        for (i = 0; i < cfg->n_dts && (cfg->energy_mask >> e & 1); ++i)
            for (j = 0; j < (e == 3 ? 1 : cfg->n_fps); ++j) {
                if (e == 2 && kind != PN_EX_SAND_COLUMN) break; /* the DP energy is for Drucker-Prager */
                r = &out->runs[out->n_runs++];
                strcpy(r->role, "implicit");
                r->implicit = 1;
                r->stress = e == 3;
                r->energy = e == 3 && kind != PN_EX_SAND_COLUMN ? PN_ENERGY_LAGGED : energies_run[e];
                r->dt = cfg->dts[i];
                r->fp = cfg->fps_iters[j];
                bench_run_scene(&s, r, frames, cfg->max_run_s, &cfg->solver, NULL, ref);
                bench_retime(&s, r, &out->runs[0], frames, &cfg->solver, cfg->min_wall_s);
                bench_progress(out->name, dim, r);
            }
    fair_wps = wall_per_sim(&out->runs[0]);
    for (k = 0; k < out->n_runs; ++k) csv_row(csv, out->name, dim, &out->runs[k], fair_wps);
    fflush(csv);
    free(ref);
    free(tmp);
}

/* ---- what an implicit step costs (--cost) ------------------------------------------------ */

#define COST_REPS 3   /* each timing: the least of this many repeats (the machine is noisy) */
#define COST_STEPS 40 /* steps per timing                                               */

/* wall ms per call of one step of w (explicit, or implicit with id at dt); the least over
   COST_REPS blocks of COST_STEPS; failing implicit steps leave w as it was (measured again) */
static double cost_ms(pn_mpm_world *w, int implicit, double dt, const pn_mpm_implicit_desc *id, pn_ex_tally *t) {
    double best = 1e300;
    int rep, k;
    for (rep = 0; rep < COST_REPS; ++rep) {
        double t0 = pn_ex_seconds();
        for (k = 0; k < COST_STEPS; ++k) {
            pn_mpm_stats st;
            pn_result r = implicit ? pn_mpm_step_implicit(w, (pn_real)dt, id, &st) : pn_mpm_step_explicit(w, (pn_real)dt, &st);
            if (r == PN_OK && t) {
                t->steps++;
                t->newton += st.newton_iters;
                t->cg += st.cg_iters;
            }
        }
        best = fmin(best, (pn_ex_seconds() - t0) * 1e3 / COST_STEPS);
    }
    return best;
}

/* For a scene: the fair explicit step's cost, and for each implicit energy at dt 1e-3 s with
   one pass what a step costs at the least (one Newton iteration with one CG iteration: a
   step that cannot converge, so it fails and leaves the world as it was), what each further
   CG iteration adds, and what a real step costs; against the budget a step has for the
   implicit run to meet the time bar (sand 0.5, snow 1.0 of the fair explicit time). The state: the scene after warm_s of
   explicit stepping (the column collapsing, the plate pressing the snow, or the ball hitting
   the floor), 0.4 of the run. */
static void bench_cost(const bench_cfg *cfg, pn_ex_scene_kind kind, int dim, FILE *md) {
    static const pn_energy en[] = {PN_ENERGY_PNET, PN_ENERGY_LAGGED, PN_ENERGY_DP};
    static const char *const names[] = {"pnet", "lagged", "dp"};
    pn_ex_scene s;
    bench_run fair;
    double warm_s, dt = 1e-3, expl = 0, budget;
    double bar = kind == PN_EX_SAND_COLUMN ? 0.5 : 1.0; /* docs/validation.md: time over fair explicit */
    int frames, e;
    pn_ex_scene_default(&s, kind, dim);
    s.res = cfg->res[dim];
    if (cfg->filter >= 0) s.filter_s = cfg->filter;
    frames = bench_frames(cfg, &s);
    warm_s = 0.4 * frames / (double)BENCH_FPS;
    if (!bench_fair(&s, frames, 1.0 / BENCH_FPS, &fair, NULL)) {
        fprintf(md, "**%s %dD**: no stable explicit step found.\n\n", kind == PN_EX_SAND_COLUMN ? "sand" : "snow", dim);
        return;
    }
    fprintf(md, "**%s %dD**, after %.2f s of explicit steps; fair explicit dt %.3g s. Budget: the wall time an "
                "implicit step of %g s may take for the run to cost %g times the fair explicit one (docs/validation.md), "
                "%g (%g / %.3g) explicit steps.\n\n",
            kind == PN_EX_SAND_COLUMN ? "sand" : "snow", dim, warm_s, fair.dt, dt, bar, bar, dt, fair.dt);
    fprintf(md, "| energy | explicit step (ms) | budget (ms) | 1 Newton + 1 CG (ms) | each more CG (ms) | "
                "real step (ms) | its Newton / CG | real / budget |\n|---|---|---|---|---|---|---|---|\n");
    for (e = 0; e < (kind == PN_EX_SAND_COLUMN ? 3 : 2); ++e) {
        pn_mpm_world *w;
        pn_mpm_implicit_desc id;
        pn_ex_tally t;
        char why[256] = "";
        double one, more, real;
        long k;
        if (!(cfg->energy_mask >> e & 1)) continue;
        s.energy = en[e];
        if (pn_ex_scene_create(&s, &w, why, sizeof why) != PN_OK) {
            fprintf(stderr, "bench_mpm: %s\n", why);
            exit(1);
        }
        for (k = 0; k < (long)floor(warm_s / fair.dt + 0.5); ++k)
            if (pn_mpm_step_explicit(w, (pn_real)fair.dt, NULL) != PN_OK) break;
        memset(&id, 0, sizeof id);
        id.fixed_point_iters = 1;
        id.newton_max = 1;
        id.cg_max = 1;
        id.cg_rel_tol = (pn_real)1e-12; /* CG runs all of cg_max */
        id.max_halvings = -1;
        one = cost_ms(w, 1, dt, &id, NULL);
        id.cg_max = 101; /* 100 more: well above the timing noise of the rest of the step */
        more = (cost_ms(w, 1, dt, &id, NULL) - one) / 100;
        memset(&t, 0, sizeof t);
        id = cfg->solver;
        id.fixed_point_iters = 1;
        real = cost_ms(w, 1, dt, &id, &t);
        expl = cost_ms(w, 0, fair.dt, NULL, NULL); /* now, on the same world */
        budget = bar * dt / fair.dt * expl;
        fprintf(md, "| %s | %.3f | %.3f | %.3f | %.4f | %.3f | %.1f / %.0f | %.1f |\n", names[e], expl, budget, one, more,
                real, t.steps ? (double)t.newton / (double)t.steps : 0, t.steps ? (double)t.cg / (double)t.steps : 0,
                real / budget);
        fflush(md);
        pn_mpm_destroy(w);
    }
    fprintf(md, "\n");
}

/* ---- the Young's-modulus sweep (2D sand) ----------------------------------------------------- */

/* the sweep's implicit runs at every E: energy, step, passes, linear solver */
typedef struct sweep_cfg {
    const char *name;
    pn_energy energy;
    double dt;
    int fp;
    pn_mpm_linear_solver linear;
    pn_mpm_formulation formulation;
    pn_mpm_stress_unknowns where; /* stress: pn_mpm_implicit_desc.stress_unknowns */
} sweep_cfg;
static const sweep_cfg sweep_cfgs[] = {
    {"lagged, dt 1e-3, multigrid", PN_ENERGY_LAGGED, 1e-3, 1, PN_MPM_LINEAR_MULTIGRID, PN_MPM_FORMULATION_ENERGY, PN_MPM_STRESS_PARTICLES},
    {"lagged, dt 1e-3, Jacobi", PN_ENERGY_LAGGED, 1e-3, 1, PN_MPM_LINEAR_JACOBI, PN_MPM_FORMULATION_ENERGY, PN_MPM_STRESS_PARTICLES},
    {"lagged, dt 4e-3, multigrid", PN_ENERGY_LAGGED, 4e-3, 1, PN_MPM_LINEAR_MULTIGRID, PN_MPM_FORMULATION_ENERGY, PN_MPM_STRESS_PARTICLES},
    {"lagged 4 passes, dt 1e-3, multigrid", PN_ENERGY_LAGGED, 1e-3, 4, PN_MPM_LINEAR_MULTIGRID, PN_MPM_FORMULATION_ENERGY, PN_MPM_STRESS_PARTICLES},
    {"DP 4 passes, dt 1e-3, multigrid", PN_ENERGY_DP, 1e-3, 4, PN_MPM_LINEAR_MULTIGRID, PN_MPM_FORMULATION_ENERGY, PN_MPM_STRESS_PARTICLES},
    /* the stress formulation (Gauss-Seidel; no linear solver); 2e-2 s: one step per frame
       of these 25 fps frames' half (1/60 s does not divide them) */
    {"stress, dt 1e-3", PN_ENERGY_DP, 1e-3, 1, PN_MPM_LINEAR_DEFAULT, PN_MPM_FORMULATION_STRESS, PN_MPM_STRESS_PARTICLES},
    {"stress, dt 4e-3", PN_ENERGY_DP, 4e-3, 1, PN_MPM_LINEAR_DEFAULT, PN_MPM_FORMULATION_STRESS, PN_MPM_STRESS_PARTICLES},
    {"stress, dt 2e-2", PN_ENERGY_DP, 2e-2, 1, PN_MPM_LINEAR_DEFAULT, PN_MPM_FORMULATION_STRESS, PN_MPM_STRESS_PARTICLES},
    {"stress by cell, dt 1e-3", PN_ENERGY_DP, 1e-3, 1, PN_MPM_LINEAR_DEFAULT, PN_MPM_FORMULATION_STRESS,
     PN_MPM_STRESS_CELLS},
    {"stress by cell, dt 4e-3", PN_ENERGY_DP, 4e-3, 1, PN_MPM_LINEAR_DEFAULT, PN_MPM_FORMULATION_STRESS,
     PN_MPM_STRESS_CELLS},
    {"stress, cells then particles, dt 1e-3", PN_ENERGY_DP, 1e-3, 1, PN_MPM_LINEAR_DEFAULT,
     PN_MPM_FORMULATION_STRESS, PN_MPM_STRESS_CELLS_THEN_PARTICLES},
    {"stress, cells then particles, dt 4e-3", PN_ENERGY_DP, 4e-3, 1, PN_MPM_LINEAR_DEFAULT,
     PN_MPM_FORMULATION_STRESS, PN_MPM_STRESS_CELLS_THEN_PARTICLES},
    {"stress, dt 5e-4", PN_ENERGY_DP, 5e-4, 1, PN_MPM_LINEAR_DEFAULT, PN_MPM_FORMULATION_STRESS,
     PN_MPM_STRESS_PARTICLES},
    {"stress, cells then particles, dt 5e-4", PN_ENERGY_DP, 5e-4, 1, PN_MPM_LINEAR_DEFAULT,
     PN_MPM_FORMULATION_STRESS, PN_MPM_STRESS_CELLS_THEN_PARTICLES},
};
#define SWEEP_RUNS ((int)(sizeof sweep_cfgs / sizeof sweep_cfgs[0]))

/* run c of the sweep on its scene: the frozen-yield DP energy is for Drucker-Prager sand */
static int sweep_applies(const bench_cfg *cfg, int c) {
    return cfg->sweep_kind == PN_EX_SAND_COLUMN || sweep_cfgs[c].formulation == PN_MPM_FORMULATION_STRESS ||
           sweep_cfgs[c].energy != PN_ENERGY_DP;
}

/* the IoU an implicit run must reach for the crossover: docs/validation.md's bars */
static double sweep_bar(const bench_cfg *cfg) { return cfg->sweep_kind == PN_EX_SAND_COLUMN ? 0.90 : 0.85; }

typedef struct sweep_row {
    double E;
    bench_run fair, ref, imp[SWEEP_RUNS];
    int found;
} sweep_row;

/* At each E: the fair explicit baseline (searched), the reference at half its step (the IoU of
   every run is against it; the fair run's own IoU says how converged the reference is), and
   the implicit runs of sweep_cfgs (each capped at max_run_s). */
static void bench_sweep(const bench_cfg *cfg, sweep_row *rows, FILE *csv) {
    int i, c, dim = cfg->sweep_dim, frames;
    pn_ex_scene s;
    size_t nodes;
    double *fair, *ref;
    const char *name = cfg->sweep_kind == PN_EX_SAND_COLUMN ? "sand" : "snow";
    pn_ex_scene_default(&s, cfg->sweep_kind, cfg->sweep_dim);
    s.res = cfg->sweep_res;
    frames = bench_frames(cfg, &s);
    nodes = (size_t)(s.res + 1) * (size_t)(s.res + 1) * (cfg->sweep_dim == 3 ? (size_t)(s.res + 1) : 1);
    if (!(fair = (double *)malloc(sizeof(double) * nodes * (size_t)frames))) exit(1);
    if (!(ref = (double *)malloc(sizeof(double) * nodes * (size_t)frames))) exit(1);
    fprintf(csv, "E_pa,particles,run,dt_s,fixed_point_iters,linear_solver,wall_per_sim_s,over_fair,"
                 "minmax_iou_mean_vs_ref,minmax_iou_min_vs_ref,dt_over_cfl,newton_per_step,cg_per_step,"
                 "halved_steps,cg_capped,status,sweeps_per_step,setup_s,energy_s,linear_s,sweeps_s,g2p_s\n");
    for (i = 0; i < cfg->n_Es; ++i) {
        sweep_row *w = &rows[i];
        double fw;
        pn_ex_scene_default(&s, cfg->sweep_kind, dim);
        s.res = cfg->sweep_res;
        if (cfg->filter >= 0) s.filter_s = cfg->filter;
        s.E_pa = cfg->Es[i];
        w->E = s.E_pa;
        fprintf(stderr, "E sweep, %s %dD, E = %.0e Pa, res %d\n", name, dim, w->E, s.res);
        w->found = bench_fair(&s, frames, 1.0 / BENCH_FPS, &w->fair, fair);
        memset(&w->ref, 0, sizeof w->ref);
        strcpy(w->ref.role, "reference");
        w->ref.dt = w->found ? w->fair.dt / 2 : 0;
        if (w->found) {
            bench_run_scene(&s, &w->ref, frames, 0, NULL, ref, NULL);
            bench_compare(&w->fair, fair, ref, nodes);
            bench_progress(name, dim, &w->fair);
        }
        fw = w->found ? wall_per_sim(&w->fair) : 0;
        fprintf(csv, "%g,%lu,explicit fair,%.6g,0,,%.4g,1,%.4f,%.4f,%.3g,0,0,0,0,\"%s\",0,0,0,0,0,0\n", w->E,
                (unsigned long)w->fair.particles, w->fair.dt, fw, w->fair.mm_mean, w->fair.mm_min,
                w->fair.tally.max_dt_over_cfl, w->found ? "ok" : "no stable step");
        for (c = 0; c < SWEEP_RUNS; ++c) {
            bench_run *r = &w->imp[c];
            pn_mpm_implicit_desc id = cfg->solver;
            double st;
            memset(r, 0, sizeof *r);
            if (!(cfg->sweep_mask >> c & 1) || !sweep_applies(cfg, c)) continue;
            strcpy(r->role, "implicit");
            r->implicit = 1;
            r->stress = sweep_cfgs[c].formulation == PN_MPM_FORMULATION_STRESS; /* (its progress line's label) */
            r->energy = sweep_cfgs[c].energy;
            if (cfg->sweep_kind != PN_EX_SAND_COLUMN && r->energy == PN_ENERGY_DP)
                r->energy = PN_ENERGY_LAGGED; /* the stress runs use none; DP is sand's */
            r->dt = sweep_cfgs[c].dt;
            r->fp = sweep_cfgs[c].fp;
            id.linear_solver = sweep_cfgs[c].linear;
            id.formulation = sweep_cfgs[c].formulation;
            id.stress_unknowns = sweep_cfgs[c].where;
            bench_run_scene(&s, r, frames, cfg->max_run_s, &id, NULL, w->found ? ref : NULL);
            bench_progress(name, dim, r);
            st = r->tally.steps ? (double)r->tally.steps : 1;
            fprintf(csv, "%g,%lu,\"%s\",%g,%d,%s,%.4g,%.4g,%.4f,%.4f,%.3g,%.2f,%.1f,%ld,%ld,\"%s\",%.1f,%.4g,%.4g,%.4g,"
                         "%.4g,%.4g\n", w->E,
                    (unsigned long)r->particles, sweep_cfgs[c].name, r->dt, r->fp,
                    sweep_cfgs[c].formulation == PN_MPM_FORMULATION_STRESS ? "gauss-seidel"
                    : sweep_cfgs[c].linear == PN_MPM_LINEAR_JACOBI        ? "jacobi"
                                                                         : "multigrid", wall_per_sim(r),
                    fw > 0 ? wall_per_sim(r) / fw : 0, r->mm_mean, r->mm_min, r->tally.max_dt_over_cfl,
                    r->tally.newton / st, r->tally.cg / st, r->tally.halved, r->tally.cg_capped, status_detail(r),
                    r->tally.sweeps / st, r->tally.stage_s[PN_MPM_STAGE_SETUP], r->tally.stage_s[PN_MPM_STAGE_ENERGY],
                    r->tally.stage_s[PN_MPM_STAGE_LINEAR], r->tally.stage_s[PN_MPM_STAGE_SWEEPS],
                    r->tally.stage_s[PN_MPM_STAGE_G2P]);
            fflush(csv);
        }
    }
    free(fair);
    free(ref);
}

/* The sweep's table, and the crossover: the smallest E where an implicit run is faster than
   the fair explicit baseline at mean min/max IoU >= sweep_bar (sand 0.90, snow 0.85) against
   the reference. */
static void write_sweep_md(const char *path, const bench_cfg *cfg, const sweep_row *rows, int n) {
    FILE *f = fopen(path, "w");
    int i, c, cross = -1;
    double bar = sweep_bar(cfg);
    pn_ex_scene sc;
    pn_ex_scene_default(&sc, cfg->sweep_kind, cfg->sweep_dim);
    if (!f) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return;
    }
    fprintf(f, "<!-- written by bench/bench_mpm.c (make bench-mpm) -->\n**Young's modulus sweep**, %s %dD, "
               "res %d (%lu particles), %.2f s simulated: at each E the fair explicit baseline (largest stable step, "
               "searched), the reference (explicit at half that step; every IoU is the mean / min min/max mass IoU "
               "against it), and the implicit runs (1 fixed-point pass unless said; each capped at %.0f wall s). "
               "*x fair*: wall time over the fair baseline's, in the same run. The stress-formulation runs "
               "give Gauss-Seidel sweeps per step in the Newton column.\n\n",
            cfg->sweep_kind == PN_EX_SAND_COLUMN ? "sand column" : "snow press", cfg->sweep_dim, cfg->sweep_res, n ? (unsigned long)rows[0].fair.particles : 0ul, (double)bench_frames(cfg, &sc) / BENCH_FPS, cfg->max_run_s);
    fprintf(f, "| E (Pa) | run | dt (s) | dt / dt_CFL | wall s / sim s | x fair | min/max IoU mean / min | "
               "Newton / CG per step | time: setup / energy / linear / sweeps / g2p (%%) | status |\n"
               "|---|---|---|---|---|---|---|---|---|---|\n");
    for (i = 0; i < n; ++i) {
        const sweep_row *w = &rows[i];
        double fw = w->found ? wall_per_sim(&w->fair) : 0;
        if (!w->found) fprintf(f, "| %.0e | explicit fair | none stable | | | | | | | |\n", w->E);
        else
            fprintf(f, "| %.0e | explicit fair | %.3g | %.2f | %.3g | 1 | %.3f / %.3f | | | ok |\n", w->E, w->fair.dt,
                    w->fair.tally.max_dt_over_cfl, fw, w->fair.mm_mean, w->fair.mm_min);
        for (c = 0; c < SWEEP_RUNS; ++c) {
            const bench_run *r = &w->imp[c];
            double st = r->tally.steps ? (double)r->tally.steps : 1, x = fw > 0 ? wall_per_sim(r) / fw : 0;
            if (!(cfg->sweep_mask >> c & 1) || !sweep_applies(cfg, c)) continue;
            double sum = 0, sh[PN_MPM_STAGES];
            int g;
            for (g = 0; g < PN_MPM_STAGES; ++g) sum += r->tally.stage_s[g];
            for (g = 0; g < PN_MPM_STAGES; ++g) sh[g] = sum > 0 ? 100 * r->tally.stage_s[g] / sum : 0;
            fprintf(f, "| %.0e | %s | %.3g | %.0f | %.3g | %.3g | %.3f / %.3f | %.1f / %.1f | %.0f / %.0f / %.0f / %.0f / %.0f | %s |\n",
                    w->E, sweep_cfgs[c].name, r->dt, r->tally.max_dt_over_cfl, wall_per_sim(r), x, r->mm_mean, r->mm_min,
                    sweep_cfgs[c].formulation == PN_MPM_FORMULATION_STRESS ? r->tally.sweeps / st : r->tally.newton / st,
                    r->tally.cg / st, sh[0], sh[1], sh[2], sh[3], sh[4], status_detail(r));
            if (cross < 0 && r->status == RUN_OK && fw > 0 && x < 1 && r->mm_mean >= bar) cross = i;
        }
    }
    if (cross >= 0) fprintf(f, "\n**Crossover**: E = %.0e Pa is the smallest E of the sweep where an implicit run is "
                               "faster than the fair explicit baseline at mean min/max IoU >= %.2f.\n", rows[cross].E, bar);
    else fprintf(f, "\n**Crossover**: none in this sweep (no implicit run faster than the fair explicit baseline at "
                    "mean min/max IoU >= %.2f).\n", bar);
    fclose(f);
}

/* ---- plots and the markdown report ------------------------------------------------------------ */

static void write_svg(const char *path, const bench_scene *sc, int n_sc) {
    FILE *f = fopen(path, "w");
    int i, k, cols = n_sc > 1 ? 2 : 1, rows = (n_sc + cols - 1) / cols;
    double pw = 520, ph = 330, mx = 70, my = 50;
    if (!f) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return;
    }
    fprintf(f, "<svg xmlns='http://www.w3.org/2000/svg' width='%.0f' height='%.0f' font-family='sans-serif'>\n",
            cols * (pw + mx + 20) + 10, rows * (ph + my + 40) + 60);
    fprintf(f, "<rect width='100%%' height='100%%' fill='#fafafa'/>\n");
    fprintf(f, "<text x='10' y='16' font-size='11'>Mean min/max mass IoU against the explicit reference, against "
               "wall seconds per simulated second (log).</text>\n<text x='10' y='30' font-size='11'>Black: explicit "
               "(square: fair baseline); blue: implicit PlasticityNet; orange: implicit lagged; green: implicit frozen-yield DP.</text>\n"
               "<text x='10' y='44' font-size='11'>Labels: dt x fixed-point passes; grey (!): failed or stopped "
               "(figures of the frames it completed).</text>\n");
    for (i = 0; i < n_sc; ++i) {
        svg_panel p;
        svg_labels placed;
        double lo = 1e300, hi = 0, ymin = 1;
        char title[64];
        const bench_scene *s = &sc[i];
        placed.n = 0;
        for (k = 0; k < s->n_runs; ++k) {
            double x = wall_per_sim(&s->runs[k]);
            if (x <= 0 || !s->runs[k].frames_done) continue;
            if (x < lo) lo = x;
            if (x > hi) hi = x;
            if (s->runs[k].mm_mean < ymin) ymin = s->runs[k].mm_mean;
        }
        if (hi <= 0) lo = hi = 1;
        p.ox = 10 + mx + (i % cols) * (pw + mx + 20);
        p.oy = 60 + my + (i / cols) * (ph + my + 40);
        p.w = pw;
        p.h = ph;
        svg_log_range(lo, hi, &p.x0, &p.x1);
        p.y0 = floor(ymin * 10) / 10;
        if (p.y0 > 0.9) p.y0 = 0.9;
        if (p.y0 < 0) p.y0 = 0;
        p.y1 = 1;
        p.logy = 0;
        snprintf(title, sizeof title, "%s %dD", s->name, s->dim);
        svg_axes(f, &p, title, "wall seconds per simulated second", "mean min/max mass IoU");
        for (k = 0; k < s->n_runs; ++k) {
            const bench_run *r = &s->runs[k];
            char label[64];
            const char *color = !r->implicit                       ? "#111"
                                : r->stress                       ? "#b0249a"
                                : r->energy == PN_ENERGY_PNET ? "#1f5fbf"
                                : r->energy == PN_ENERGY_DP   ? "#2a9d3a"
                                                                  : "#e07b00";
            if (wall_per_sim(r) <= 0 || !r->frames_done) continue;
            if (r->implicit) snprintf(label, sizeof label, "%g x%d%s", r->dt, r->fp, r->status == RUN_OK ? "" : " (!)");
            else snprintf(label, sizeof label, "%s %.2g", r->role, r->dt);
            if (r->status != RUN_OK) color = "#bbb";
            svg_marker(f, &p, &placed, wall_per_sim(r), r->mm_mean < p.y0 ? p.y0 : r->mm_mean, color,
                       !r->implicit && !strcmp(r->role, "fair"), label);
        }
    }
    fprintf(f, "</svg>\n");
    fclose(f);
}

static void write_sweep_svg(const char *path, const sweep_row *rows, int n) {
    FILE *f = fopen(path, "w");
    svg_panel p;
    svg_labels placed;
    double lo = 1e300, hi = 0;
    int i, s;
    placed.n = 0;
    if (!f) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return;
    }
    for (i = 0; i < n; ++i) {
        double v[2];
        v[0] = rows[i].found ? wall_per_sim(&rows[i].fair) : 0;
        v[1] = wall_per_sim(&rows[i].imp[0]);
        for (s = 0; s < 2; ++s)
            if (v[s] > 0) {
                if (v[s] < lo) lo = v[s];
                if (v[s] > hi) hi = v[s];
            }
    }
    if (hi <= 0) lo = hi = 1;
    p.ox = 80;
    p.oy = 60;
    p.w = 520;
    p.h = 330;
    p.x0 = log10(rows[0].E) - 0.3; /* room for the labels right of the last point */
    p.x1 = log10(rows[n - 1].E) + 0.7;
    svg_log_range(lo, hi, &p.y0, &p.y1);
    p.logy = 1;
    fprintf(f, "<svg xmlns='http://www.w3.org/2000/svg' width='700' height='480' font-family='sans-serif'>\n");
    fprintf(f, "<rect width='100%%' height='100%%' fill='#fafafa'/>\n");
    svg_axes(f, &p, "sand 2D: wall seconds per simulated second against Young's modulus", "Young's modulus E (Pa)",
             "wall s / simulated s");
    for (s = 0; s < 2; ++s) { /* 0: explicit at its fair step, 1: implicit dt 1e-3 */
        const char *color = s ? "#1f5fbf" : "#111";
        int first = 1;
        fprintf(f, "<polyline fill='none' stroke='%s' points='", color);
        for (i = 0; i < n; ++i) {
            const bench_run *r = s ? &rows[i].imp[0] : &rows[i].fair;
            if ((!s && !rows[i].found) || wall_per_sim(r) <= 0) continue;
            fprintf(f, "%s%.1f,%.1f", first ? "" : " ", svg_px(&p, rows[i].E), svg_py(&p, wall_per_sim(r)));
            first = 0;
        }
        fprintf(f, "'/>\n");
        for (i = 0; i < n; ++i) {
            const bench_run *r = s ? &rows[i].imp[0] : &rows[i].fair;
            char label[64];
            if ((!s && !rows[i].found) || wall_per_sim(r) <= 0) continue;
            if (s && rows[i].found)
                snprintf(label, sizeof label, "%.3g x explicit, IoU %.2f%s",
                         wall_per_sim(r) / wall_per_sim(&rows[i].fair), r->mm_mean, r->status == RUN_OK ? "" : " (!)");
            else snprintf(label, sizeof label, "dt %.2g", r->dt);
            svg_marker(f, &p, &placed, rows[i].E, wall_per_sim(r), r->status == RUN_OK ? color : "#bbb", !s, label);
        }
    }
    fprintf(f, "<text x='20' y='446' font-size='11'>Black squares: explicit at its largest stable step (dt shown). "
               "Blue: implicit lagged, dt 1e-3 s, multigrid,</text>\n<text x='20' y='462' font-size='11'>1 fixed-point "
               "pass (time over explicit; min/max mass IoU against the reference). Grey (!): failed or "
               "stopped.</text>\n</svg>\n");
    fclose(f);
}

static void write_md(const char *path, const bench_cfg *cfg, const bench_scene *sc, int n_sc) {
    FILE *f = fopen(path, "w");
    int i, k;
    if (!f) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return;
    }
    fprintf(f, "<!-- written by bench/bench_mpm.c (make bench-mpm)%s -->\n", cfg->quick ? ", --quick" : "");
    fprintf(f, "Scenes of docs/validation.md (examples/common/pn_example.h): the sand column and the %s; 2D res %d over 1 m, "
               "3D res %d over 0.5 m; %.2f s (2D) and %.2f s (3D) simulated (the snow press at most 0.2 s), compared at %d "
               "frames per second. Mass IoU against the "
               "explicit reference, mean / min over frames: *soft* is sum(ab) / sum(a + b - ab) of the max-normalized "
               "mass fields (docs/validation.md), below 1 even for identical fields (the reference row shows its ceiling); "
               "*min/max* is sum(min(a, b)) / sum(max(a, b)), 1 for identical fields; *binary*: occupancy above "
               "%.0f%% of the maximum. *x fair*: wall time per simulated second over the explicit run at its largest "
               "stable step (for an implicit run, the fair run stepped again beside it; the fastest of runs repeated to "
               "--min-wall seconds). *dt / dt_CFL*: the step over the explicit bound pn_mpm_stable_dt (largest over the "
               "run; for explicit runs at each frame's start). *it/step*: Newton / CG / fixed-point passes per step. "
               "*LS fails / halved / CG capped*: Newton steps whose line search failed / implicit steps retried as "
               "substeps / Newton steps whose linear solve stopped at cg_max. *max FP residual*: largest "
               "max_q |F0_new - F0| (not measured with one pass). Wall time from CLOCK_MONOTONIC.\n\n",
            cfg->snowball ? "snowball" : "snow press", cfg->res[2], cfg->res[3], cfg->duration[2], cfg->duration[3],
            BENCH_FPS, 100 * PN_EX_OCCUPIED);
    if (cfg->solver.contact_rounds != 1)
        fprintf(f, "Implicit runs with up to %d contact solves per fixed-point pass (--contact-rounds).\n\n",
                cfg->solver.contact_rounds);
    if (cfg->no_hardening) fprintf(f, "Snow without Cam-Clay hardening (--no-hardening).\n\n");
    if (cfg->solver.cg_forcing_max != 0)
        fprintf(f, "Implicit runs with pn_mpm_implicit_desc.cg_forcing_max = %g (--cg-forcing).\n\n",
                (double)cfg->solver.cg_forcing_max);
    for (i = 0; i < n_sc; ++i) {
        const bench_scene *s = &sc[i];
        double fair_wps = wall_per_sim(&s->runs[s->fair_index]);
        if (s->n_runs < 3) {
            fprintf(f, "**%s %dD**: no stable explicit step found; nothing measured.\n\n", s->name, s->dim);
            continue;
        }
        fprintf(f, "**%s %dD** (%lu particles): reference = explicit at dt %.3g s (fair step / %d); halving it "
                   "moves the mean min/max IoU %.4f from 1 (soft: %.3f against the reference's own %.3f); E off by "
                   "%g at the same step moves it %.4f. Fair explicit baseline: dt %.3g s.%s\n\n",
                s->name, s->dim, (unsigned long)s->runs[0].particles, s->runs[1].dt, BENCH_REF_DIV, s->ref_convergence,
                s->runs[2].iou_mean, s->runs[1].iou_mean, BENCH_PERTURB, s->ref_sensitivity, s->runs[0].dt,
                s->runs[1].status == RUN_OK ? "" : " **The reference itself failed: the IoUs are meaningless.**");
        fprintf(f, "| scene | dim | role | integrator | energy | dt (s) | dt / dt_CFL | FP iters | soft IoU mean / min | "
                   "min/max IoU mean / min | binary IoU | wall s / sim s | x fair | it/step N / CG / FP | "
                   "LS fails / halved / CG capped | max FP residual | finite |\n");
        fprintf(f, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for (k = 0; k < s->n_runs; ++k) md_row(f, s->name, s->dim, &s->runs[k], fair_wps);
        fprintf(f, "\n");
    }
    fclose(f);
}

/* ---- materials: one conditioned model across friction angles and Poisson ratios ------------- */

static void bench_materials(const bench_cfg *cfg, int n_dts, const double *dts, const int *fps) {
    static const double phis[3] = {20, 30, 45}, nus[2] = {0.3, 0.4};
    char path[1024];
    FILE *md;
    int a, b, k, frames;
    snprintf(path, sizeof path, "%s/bench_mpm_materials.md", cfg->out);
    if (!(md = fopen(path, "w"))) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        exit(1);
    }
    fprintf(md, "<!-- written by bench/bench_mpm.c --materials -->\n");
    fprintf(md, "The 2D sand column (res %d over 1 m, E 1e7 Pa, %.2f s) at three friction angles and two Poisson ratios, "
                "each against its own explicit reference (the fair step / %d). One conditioned model, "
                "`pn_model_sand_any_2d`, serves all six; `sand_2d` is trained at 30 deg, 0.3 only. IoU: min/max "
                "mass IoU mean over frames (soft in brackets); runout: the deposit's half-width at the end over the "
                "reference's.\n\n", cfg->res[2], cfg->duration[2], BENCH_REF_DIV);
    fprintf(md, "| friction | nu | energy | dt (s) | FP | min/max IoU (soft) | runout / reference | wall s / sim s | status |\n");
    fprintf(md, "|---|---|---|---|---|---|---|---|---|\n");
    for (b = 0; b < 2; ++b)
        for (a = 0; a < 3; ++a) {
            pn_ex_scene s;
            bench_run fair, ref;
            double *fields, ref_run;
            size_t nodes;
            pn_mpm_world *w;
            char why[256] = "";
            pn_ex_scene_default(&s, PN_EX_SAND_COLUMN, 2);
            s.res = cfg->res[2];
            s.model = pn_model_sand_any_2d();
            s.nu = nus[b], s.friction_deg = phis[a];
            frames = bench_frames(cfg, &s);
            if (pn_ex_scene_create(&s, &w, why, sizeof why) != PN_OK) {
                fprintf(stderr, "bench_mpm: %s\n", why);
                exit(1);
            }
            nodes = pn_ex_field_size(w);
            pn_mpm_destroy(w);
            fields = (double *)malloc(sizeof(double) * nodes * (size_t)frames);
            if (!fields || !bench_fair(&s, frames, 1.0 / BENCH_FPS, &fair, NULL)) {
                fprintf(stderr, "bench_mpm: no stable explicit step at %g deg, nu %g\n", phis[a], nus[b]);
                exit(1);
            }
            memset(&ref, 0, sizeof ref);
            strcpy(ref.role, "reference");
            ref.dt = fair.dt / BENCH_REF_DIV;
            bench_run_scene(&s, &ref, frames, 0, NULL, fields, NULL);
            ref_run = ref.runout;
            fprintf(stderr, "  %g deg, nu %g: reference dt %.3g, runout %.4f m\n", phis[a], nus[b], ref.dt, ref_run);
            fprintf(md, "| %g | %g | explicit (fair) | %.3g | - | - | - | %.3g | |\n", phis[a], nus[b], fair.dt, wall_per_sim(&fair));
            for (k = 0; k < 3 * n_dts; ++k) {
                pn_ex_scene sk = s;
                bench_run r;
                double ro;
                int which = k % 3; /* 0 conditioned, 1 lagged, 2 single-material */
                if (which == 2 && !(phis[a] == 30 && nus[b] == 0.3)) continue;
                memset(&r, 0, sizeof r);
                strcpy(r.role, "implicit");
                r.implicit = 1, r.dt = dts[k / 3], r.fp = fps[k / 3];
                r.energy = which == 1 ? PN_ENERGY_LAGGED : PN_ENERGY_PNET;
                if (which == 2) sk.model = pn_model_sand_2d(), sk.nu = sk.friction_deg = 0;
                bench_run_scene(&sk, &r, frames, 0, NULL, NULL, fields);
                ro = r.status == RUN_OK ? r.runout : 0;
                bench_progress("sand", 2, &r);
                fprintf(md, "| %g | %g | %s | %.3g | %d | %.3f (%.3f) | %.3f | %.3g | %s |\n", phis[a], nus[b],
                        which == 0 ? "PlasticityNet, sand_any_2d" : which == 1 ? "lagged" : "PlasticityNet, sand_2d",
                        r.dt, r.fp, r.mm_mean, r.iou_mean, ref_run > 0 ? ro / ref_run : 0, wall_per_sim(&r), status_name(&r));
                fflush(md);
            }
            free(fields);
        }
    fclose(md);
    fprintf(stderr, "wrote %s\n", path);
}

/* ---- --scale: the implicit sand column at user sizes, resumable ----------------------------- */

#define SCALE_FPS 20 /* 0.05 s frames: a 1/60 s step is 3 of a frame */

/* the runs of each (dim, res, E), in this order; the CSV's run and step columns */
enum { SCALE_FAIR = 0, SCALE_REF, SCALE_ADVECTION, SCALE_FRAME, SCALE_CELLS_ADVECTION, SCALE_CELLS, SCALE_CASCADE, SCALE_RUNS };
static const char *const scale_kinds[SCALE_RUNS] = {"explicit_fair", "explicit_reference", "stress_particles",
                                                    "stress_particles", "stress_cells", "stress_cells",
                                                    "stress_cells_particles"};
static const char *const scale_steps[SCALE_RUNS] = {"fair", "fair/2", "advection", "1/60", "advection", "1/60",
                                                    "advection"};

/* one row of DIR/bench_scale.csv: written as each run ends, read back on start (resume) */
typedef struct scale_row {
    int dim, res;
    double E;
    char run[24], step[16];
    unsigned long particles;
    double dt, dt_over_fair;             /* the step, and over the fair explicit step (dt_CFL) */
    double sweeps, coarse, newton, cg;   /* per step                                          */
    double halved;                       /* the share of the steps retried as substeps        */
    double share[5];                     /* % of the step in each pn_mpm_stage (implicit)     */
    double mm_mean, mm_min;              /* min/max mass IoU against the reference            */
    double runout, height, runout_ratio, height_ratio; /* the deposit, and over the reference's */
    double wall_ps, cpu_ps, cpu_over_fair, sim, wall, cpu;
    char status[96];
} scale_row;

static const char scale_header[] =
    "dim,res,E_pa,run,step,particles,dt_s,dt_over_fair,sweeps_per_step,coarse_per_step,newton_per_step,"
    "cg_per_step,substepped_share,setup_pct,energy_pct,linear_pct,sweeps_pct,g2p_pct,minmax_iou_mean,minmax_iou_min,runout_m,"
    "height_m,runout_over_ref,height_over_ref,wall_per_sim_s,cpu_per_sim_s,cpu_over_fair,simulated_s,wall_s,cpu_s,"
    "status";
#define SCALE_COLUMNS 31

typedef struct scale_csv {
    scale_row *rows;
    int n, cap;
    FILE *f; /* appended to */
} scale_csv;

static void scale_write(FILE *f, const scale_row *o) {
    fprintf(f, "%d,%d,%g,%s,%s,%lu,%.10g,%.4g,%.2f,%.3f,%.2f,%.1f,%.4f,%.1f,%.1f,%.1f,%.1f,%.1f,%.4f,%.4f,%.5f,%.5f,%.4f,%.4f,"
               "%.5g,%.5g,%.4g,%.4f,%.3f,%.3f,\"%s\"\n",
            o->dim, o->res, o->E, o->run, o->step, o->particles, o->dt, o->dt_over_fair, o->sweeps, o->coarse,
            o->newton, o->cg, o->halved, o->share[0], o->share[1], o->share[2], o->share[3], o->share[4], o->mm_mean, o->mm_min,
            o->runout, o->height, o->runout_ratio, o->height_ratio, o->wall_ps, o->cpu_ps, o->cpu_over_fair, o->sim,
            o->wall, o->cpu, o->status);
}

/* a line scale_write wrote into *o; 0 if it is not one */
static int scale_parse(char *line, scale_row *o) {
    char *c[SCALE_COLUMNS], *p = line;
    int n = 0;
    size_t len;
    while (n < SCALE_COLUMNS - 1) { /* the last column, the quoted status, may hold commas */
        c[n++] = p;
        if (!(p = strchr(p, ','))) return 0;
        *p++ = 0;
    }
    c[n] = p;
    memset(o, 0, sizeof *o);
    o->dim = atoi(c[0]), o->res = atoi(c[1]), o->E = atof(c[2]);
    snprintf(o->run, sizeof o->run, "%s", c[3]);
    snprintf(o->step, sizeof o->step, "%s", c[4]);
    o->particles = strtoul(c[5], NULL, 10);
    o->dt = atof(c[6]), o->dt_over_fair = atof(c[7]), o->sweeps = atof(c[8]), o->coarse = atof(c[9]);
    o->newton = atof(c[10]), o->cg = atof(c[11]), o->halved = atof(c[12]);
    for (n = 0; n < 5; ++n) o->share[n] = atof(c[13 + n]);
    o->mm_mean = atof(c[18]), o->mm_min = atof(c[19]), o->runout = atof(c[20]), o->height = atof(c[21]);
    o->runout_ratio = atof(c[22]), o->height_ratio = atof(c[23]), o->wall_ps = atof(c[24]), o->cpu_ps = atof(c[25]);
    o->cpu_over_fair = atof(c[26]), o->sim = atof(c[27]), o->wall = atof(c[28]), o->cpu = atof(c[29]);
    p = c[30] + (c[30][0] == '"');
    len = strcspn(p, "\"\r\n");
    p[len] = 0;
    snprintf(o->status, sizeof o->status, "%s", p);
    return (o->dim == 2 || o->dim == 3) && o->res > 0 && o->E > 0;
}

static void scale_add(scale_csv *t, const scale_row *o) {
    if (t->n == t->cap) {
        t->cap = t->cap ? 2 * t->cap : 64;
        if (!(t->rows = (scale_row *)realloc(t->rows, sizeof(scale_row) * (size_t)t->cap))) exit(1);
    }
    t->rows[t->n++] = *o;
}

/* a finished run: to the CSV at once (a later start skips it) and to the table */
static void scale_append(scale_csv *t, const scale_row *o) {
    scale_write(t->f, o);
    fflush(t->f);
    scale_add(t, o);
}

/* the row of run k of (dim, res, E) at step dt (dt <= 0: at any step), -1 if none */
static int scale_find(const scale_csv *t, int dim, int res, double E, int k, double dt) {
    int i;
    for (i = 0; i < t->n; ++i) {
        const scale_row *o = &t->rows[i];
        if (o->dim == dim && o->res == res && fabs(o->E - E) <= 1e-9 * E && !strcmp(o->run, scale_kinds[k]) &&
            (dt <= 0 || fabs(o->dt - dt) <= 1e-6 * dt))
            return i;
    }
    return -1;
}

/* Row k of a run r; fair_dt, fair_cpu_ps: the fair explicit run's step and processor seconds per
   simulated second; ref_runout, ref_height: the reference's deposit. */
static void scale_row_of(scale_row *o, const pn_ex_scene *s, int k, const bench_run *r, double fair_dt,
                         double fair_cpu_ps, double ref_runout, double ref_height) {
    double st = r->tally.steps ? (double)r->tally.steps : 1, sum = 0;
    int g;
    memset(o, 0, sizeof *o);
    o->dim = s->dim, o->res = s->res, o->E = s->E_pa;
    snprintf(o->run, sizeof o->run, "%s", scale_kinds[k]);
    snprintf(o->step, sizeof o->step, "%s", scale_steps[k]);
    o->particles = (unsigned long)r->particles;
    o->dt = r->dt;
    o->dt_over_fair = fair_dt > 0 ? r->dt / fair_dt : 0;
    o->sweeps = r->tally.sweeps / st, o->coarse = r->tally.coarse / st;
    o->newton = r->tally.newton / st, o->cg = r->tally.cg / st, o->halved = r->tally.halved / st;
    for (g = 0; g < PN_MPM_STAGES; ++g) sum += r->tally.stage_s[g];
    for (g = 0; g < PN_MPM_STAGES && g < 5; ++g) o->share[g] = sum > 0 ? 100 * r->tally.stage_s[g] / sum : 0;
    o->mm_mean = r->mm_mean, o->mm_min = r->mm_min;
    o->runout = r->runout, o->height = r->height;
    o->runout_ratio = ref_runout > 0 ? r->runout / ref_runout : 0;
    o->height_ratio = ref_height > 0 ? r->height / ref_height : 0;
    o->wall_ps = wall_per_sim(r);
    o->cpu_ps = r->sim > 0 ? r->cpu / r->sim : 0;
    o->cpu_over_fair = fair_cpu_ps > 0 ? o->cpu_ps / fair_cpu_ps : 0;
    o->sim = r->sim, o->wall = r->wall, o->cpu = r->cpu;
    snprintf(o->status, sizeof o->status, "%s", status_detail(r));
}

/* The sand column at res cells and E: its scene, its particle count and its field's size. */
static size_t scale_scene(const bench_cfg *cfg, int dim, int res, double E, pn_ex_scene *s, size_t *nodes) {
    pn_mpm_world *w;
    char why[256] = "";
    size_t n;
    pn_ex_scene_default(s, PN_EX_SAND_COLUMN, dim);
    s->res = res;
    s->E_pa = E;
    if (cfg->filter >= 0) s->filter_s = cfg->filter;
    if (pn_ex_scene_create(s, &w, why, sizeof why) != PN_OK) {
        fprintf(stderr, "bench_mpm: %s\n", why);
        exit(1);
    }
    n = w->n;
    if (nodes) *nodes = pn_ex_field_size(w);
    pn_mpm_destroy(w);
    return n;
}

/* The implicit step at the advection limit. The library has no helper that returns it
   (pn_mpm_advance picks such steps inside, one by one, from the fastest particle), so: the
   fastest a particle of the column gets is its free fall from the top, sqrt(2 g H) with H the
   column height (aspect x width), and dt = dx / (2 sqrt(2 g H)) keeps it half a cell per step
   (under one, with room for the spread of the collapse); rounded down to whole steps per frame. */
static double scale_advection_dt(const pn_ex_scene *s, double frame_s) {
    double dt = pn_ex_scene_dx(s) / (2 * sqrt(2 * 9.81 * s->aspect * s->width_m));
    return frame_s / ceil(frame_s / dt - 1e-9);
}

/* the reference's mass fields on disk, so that a resumed run need not repeat it */
#define SCALE_CACHE_TAG 0x504e5331ul /* "PNS1" */

static void scale_cache_path(const bench_cfg *cfg, const pn_ex_scene *s, char *path, size_t cap) {
    snprintf(path, cap, "%s/bench_scale_ref_%dd_res%d_E%g.bin", cfg->out, s->dim, s->res, s->E_pa);
}

static int scale_cache_read(const char *path, double *fields, size_t nodes, int frames, double dt) {
    FILE *f = fopen(path, "rb");
    unsigned long tag = 0;
    size_t nn = 0;
    int nf = 0, ok;
    double d = 0;
    if (!f) return 0;
    ok = fread(&tag, sizeof tag, 1, f) == 1 && tag == SCALE_CACHE_TAG && fread(&nn, sizeof nn, 1, f) == 1 &&
         nn == nodes && fread(&nf, sizeof nf, 1, f) == 1 && nf == frames && fread(&d, sizeof d, 1, f) == 1 &&
         fabs(d - dt) <= 1e-9 * dt && fread(fields, sizeof(double) * nodes, (size_t)frames, f) == (size_t)frames;
    fclose(f);
    return ok;
}

static void scale_cache_write(const char *path, const double *fields, size_t nodes, int frames, double dt) {
    FILE *f = fopen(path, "wb");
    unsigned long tag = SCALE_CACHE_TAG;
    int ok;
    if (!f) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return;
    }
    ok = fwrite(&tag, sizeof tag, 1, f) == 1 && fwrite(&nodes, sizeof nodes, 1, f) == 1 &&
         fwrite(&frames, sizeof frames, 1, f) == 1 && fwrite(&dt, sizeof dt, 1, f) == 1 &&
         fwrite(fields, sizeof(double) * nodes, (size_t)frames, f) == (size_t)frames;
    if (fclose(f) != 0 || !ok) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        remove(path);
    }
}

/* The runs of one (dim, res, E) that the CSV does not have yet: the fair explicit baseline
   (searched as bench_fair does; it is kept only once the reference exists to score it), the
   reference at half its step (the sweep's rule; its fields cached), then the stress
   formulation per particle at the advection limit and at 1/60 s, per cell at both, and cells
   then particles at the advection limit. */
static void scale_group(const bench_cfg *cfg, scale_csv *t, int dim, int res, double E, int frames) {
    double frame_s = 1.0 / SCALE_FPS, dts[SCALE_RUNS], fair_dt, fair_cpu, ref_runout, ref_height, *ref, *fair_f = NULL;
    int have[SCALE_RUNS], k, todo = 0;
    pn_ex_scene s;
    size_t nodes;
    bench_run fair, r;
    scale_row o;
    char path[1024];
    unsigned long n = (unsigned long)scale_scene(cfg, dim, res, E, &s, &nodes);
    dts[SCALE_FAIR] = dts[SCALE_REF] = 0;
    dts[SCALE_ADVECTION] = dts[SCALE_CELLS_ADVECTION] = dts[SCALE_CASCADE] = scale_advection_dt(&s, frame_s);
    dts[SCALE_FRAME] = dts[SCALE_CELLS] = 1.0 / 60;
    have[SCALE_FAIR] = scale_find(t, dim, res, E, SCALE_FAIR, 0);
    fair_dt = have[SCALE_FAIR] >= 0 ? t->rows[have[SCALE_FAIR]].dt : 0;
    if (fair_dt > 0) fair_dt = frame_s / floor(frame_s / fair_dt + 0.5); /* exactly the searched step */
    dts[SCALE_REF] = fair_dt / 2;
    have[SCALE_REF] = fair_dt > 0 ? scale_find(t, dim, res, E, SCALE_REF, dts[SCALE_REF]) : -1;
    for (k = SCALE_ADVECTION; k < SCALE_RUNS; ++k) have[k] = scale_find(t, dim, res, E, k, dts[k]);
    for (k = cfg->scale_implicit_only ? SCALE_ADVECTION : 0; k < SCALE_RUNS; ++k) todo += have[k] < 0;
    fprintf(stderr, "scale: sand %dD res %d (%lu particles), E %g Pa, %d frames (%.2f s): %d of %d runs to do\n", dim,
            res, n, E, frames, frames * frame_s, todo, cfg->scale_implicit_only ? SCALE_RUNS - SCALE_ADVECTION : SCALE_RUNS);
    if (!todo) return;
    if (have[SCALE_FAIR] >= 0 && strcmp(t->rows[have[SCALE_FAIR]].status, "ok")) {
        fprintf(stderr, "  the fair explicit run is %s: nothing to compare with\n", t->rows[have[SCALE_FAIR]].status);
        return;
    }
    if (!(ref = (double *)calloc(nodes * (size_t)frames, sizeof(double)))) exit(1);
    if (cfg->scale_implicit_only) { /* nothing to score against */
        fair_dt = fair_cpu = ref_runout = ref_height = 0;
        goto implicit;
    }
    if (have[SCALE_FAIR] < 0) { /* 1. the fair explicit baseline (fields kept until the reference exists) */
        if (!(fair_f = (double *)calloc(nodes * (size_t)frames, sizeof(double)))) exit(1);
        if (!bench_fair(&s, frames, frame_s, &fair, fair_f)) {
            fprintf(stderr, "bench_mpm: sand %dD res %d E %g: no stable explicit step found\n", dim, res, E);
            scale_row_of(&o, &s, SCALE_FAIR, &fair, 0, 0, 0, 0);
            snprintf(o.status, sizeof o.status, "no stable step");
            scale_append(t, &o);
            free(fair_f);
            free(ref);
            return;
        }
        fair_dt = fair.dt;
        dts[SCALE_REF] = fair_dt / 2;
        have[SCALE_REF] = scale_find(t, dim, res, E, SCALE_REF, dts[SCALE_REF]);
        fair_cpu = fair.sim > 0 ? fair.cpu / fair.sim : 0;
    } else fair_cpu = t->rows[have[SCALE_FAIR]].cpu_ps;
    /* 2. the reference: from its cache when its row is in the CSV */
    scale_cache_path(cfg, &s, path, sizeof path);
    if (have[SCALE_REF] >= 0 && scale_cache_read(path, ref, nodes, frames, dts[SCALE_REF])) {
        ref_runout = t->rows[have[SCALE_REF]].runout;
        ref_height = t->rows[have[SCALE_REF]].height;
        fprintf(stderr, "  reference read from %s\n", path);
    } else {
        memset(&r, 0, sizeof r);
        strcpy(r.role, "reference");
        r.frame_s = frame_s;
        r.dt = dts[SCALE_REF];
        if (have[SCALE_REF] >= 0) fprintf(stderr, "  %s is missing or another run's: the reference again\n", path);
        bench_run_scene(&s, &r, frames, 0, NULL, ref, NULL);
        if (r.status != RUN_OK) fprintf(stderr, "bench_mpm: the reference failed (%s)\n", status_name(&r));
        bench_compare(&r, ref, ref, nodes);
        bench_progress("sand", dim, &r);
        scale_cache_write(path, ref, nodes, frames, r.dt);
        ref_runout = r.runout;
        ref_height = r.height;
        if (have[SCALE_REF] < 0) {
            scale_row_of(&o, &s, SCALE_REF, &r, fair_dt, fair_cpu, ref_runout, ref_height);
            scale_append(t, &o);
        }
    }
    if (fair_f) { /* the fair run, now that it can be scored */
        bench_compare(&fair, fair_f, ref, nodes);
        bench_progress("sand", dim, &fair);
        scale_row_of(&o, &s, SCALE_FAIR, &fair, fair_dt, fair_cpu, ref_runout, ref_height);
        scale_append(t, &o);
        free(fair_f);
    }
implicit: /* 3. the stress formulation (its law: the group's Drucker-Prager, as in the sweep) */
    for (k = SCALE_ADVECTION; k < SCALE_RUNS; ++k) {
        pn_mpm_implicit_desc id = cfg->solver;
        if (have[k] >= 0) continue;
        memset(&r, 0, sizeof r);
        strcpy(r.role, "implicit");
        r.implicit = r.stress = 1;
        r.energy = PN_ENERGY_DP;
        r.fp = 1;
        r.frame_s = frame_s;
        r.dt = dts[k];
        id.stress_unknowns = k == SCALE_CELLS || k == SCALE_CELLS_ADVECTION ? PN_MPM_STRESS_CELLS
                             : k == SCALE_CASCADE                            ? PN_MPM_STRESS_CELLS_THEN_PARTICLES
                                                                             : PN_MPM_STRESS_PARTICLES;
        bench_run_scene(&s, &r, frames, cfg->max_run_s, &id, NULL, cfg->scale_implicit_only ? NULL : ref);
        bench_progress("sand", dim, &r);
        scale_row_of(&o, &s, k, &r, fair_dt, fair_cpu, ref_runout, ref_height);
        scale_append(t, &o);
    }
    free(ref);
}

/* the table's order: dimension, res, E, then the runs in scale_kinds' order by step */
static int scale_rank(const scale_row *o) {
    int k;
    for (k = 0; k < SCALE_RUNS; ++k)
        if (!strcmp(o->run, scale_kinds[k])) return k;
    return SCALE_RUNS;
}

static int scale_cmp(const void *pa, const void *pb) {
    const scale_row *a = (const scale_row *)pa, *b = (const scale_row *)pb;
    if (a->dim != b->dim) return a->dim - b->dim;
    if (a->res != b->res) return a->res - b->res;
    if (a->E != b->E) return a->E < b->E ? -1 : 1;
    if (scale_rank(a) != scale_rank(b)) return scale_rank(a) - scale_rank(b);
    return a->dt < b->dt ? -1 : a->dt > b->dt;
}

/* DIR/bench_scale.md: every row of the CSV, this start's and earlier ones' */
static void scale_md(const char *path, const scale_csv *t) {
    FILE *f = fopen(path, "w");
    scale_row *rows;
    int i;
    if (!f) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return;
    }
    if (!(rows = (scale_row *)malloc(sizeof(scale_row) * (size_t)(t->n ? t->n : 1)))) exit(1);
    if (t->n) memcpy(rows, t->rows, sizeof(scale_row) * (size_t)t->n);
    qsort(rows, (size_t)t->n, sizeof(scale_row), scale_cmp);
    fprintf(f, "<!-- written by bench/bench_mpm.c --scale (make bench-scale) from bench_scale.csv -->\n"
               "**The sand column at user sizes** (examples/common/pn_example.h: StVK-Hencky + Drucker-Prager, a "
               "0.12 m column of aspect 2; 2D over 1 m, 3D over 0.5 m), to the deposit. Per (dim, res, E): the fair "
               "explicit baseline (largest stable step, searched), the explicit reference at half its step (every IoU "
               "is the mean / min min/max mass IoU against it, at %d frames per second), and the stress formulation "
               "(`PN_MPM_FORMULATION_STRESS`, the group's Drucker-Prager) with its stresses per particle at the "
               "advection limit (dx / (2 sqrt(2 g H)), H the column height, in whole steps per frame) and at "
               "1/60 s, per cell at both, and cells then particles (`stress_cells_particles`) at the advection "
               "limit. *dt / dt_CFL*: the step over the fair explicit step. *per step*: "
               "Gauss-Seidel sweeps, coarse corrections (`pn_mpm_stats.coarse_corrections`), Newton and CG "
               "iterations (of a step retried as substeps, for all of them), and *substepped*: the share of the "
               "steps that were (one that would move material more than a cell is). *stage %%*: the share of the step's time in setup / energy / linear / sweeps / g2p "
               "(`pn_mpm_stats.stage_s`). *runout, height*: the deposit's half-width and top above the floor at the "
               "end, over the reference's. Time per simulated second: wall (CLOCK_MONOTONIC) and processor "
               "(`clock()`) seconds; *CPU x fair*: processor time over the fair explicit run's.\n\n",
            SCALE_FPS);
    fprintf(f, "| dim | res | particles | E (Pa) | run | step | dt (s) | dt / dt_CFL | sweeps / coarse per step | "
               "Newton / CG per step | substepped | stage %% setup / energy / linear / sweeps / g2p | min/max IoU mean / min | "
               "runout / ref | height / ref | wall s / sim s | CPU s / sim s | CPU x fair | status |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (i = 0; i < t->n; ++i) {
        const scale_row *o = &rows[i];
        char stage[64] = "-", status[128], ratio[4][32];
        int scored = o->mm_mean > 0 || o->runout_ratio > 0; /* (--scale-implicit-only: not) */
        if (o->share[0] + o->share[1] + o->share[2] + o->share[3] + o->share[4] > 0)
            snprintf(stage, sizeof stage, "%.0f / %.0f / %.0f / %.0f / %.0f", o->share[0], o->share[1], o->share[2],
                     o->share[3], o->share[4]);
        if (strcmp(o->status, "ok")) snprintf(status, sizeof status, "%s at t = %.2f s", o->status, o->sim);
        else strcpy(status, "ok");
        strcpy(ratio[0], "-"), strcpy(ratio[1], "-"), strcpy(ratio[2], "-"), strcpy(ratio[3], "-");
        if (o->dt_over_fair > 0) snprintf(ratio[0], sizeof ratio[0], "%.3g", o->dt_over_fair);
        if (scored) {
            snprintf(ratio[1], sizeof ratio[1], "%.3f / %.3f", o->mm_mean, o->mm_min);
            snprintf(ratio[2], sizeof ratio[2], "%.3f | %.3f", o->runout_ratio, o->height_ratio);
        } else strcpy(ratio[2], "- | -");
        if (o->cpu_over_fair > 0) snprintf(ratio[3], sizeof ratio[3], "%.3g", o->cpu_over_fair);
        fprintf(f, "| %d | %d | %lu | %.0e | %s | %s | %.3g | %s | %.1f / %.2f | %.1f / %.1f | %.2f | %s | %s | "
                   "%s | %.3g | %.3g | %s | %s |\n",
                o->dim, o->res, o->particles, o->E, o->run, o->step, o->dt, ratio[0], o->sweeps, o->coarse,
                o->newton, o->cg, o->halved, stage, ratio[1], ratio[2], o->wall_ps, o->cpu_ps, ratio[3], status);
    }
    free(rows);
    fclose(f);
}

/* --scale: the particle counts of the chosen sizes, then (unless count_only) every run of every
   (dim, res, E) that DIR/bench_scale.csv does not have, each appended as it ends; then
   DIR/bench_scale.md from the whole CSV. Returns the exit status. */
static int bench_scale(const bench_cfg *cfg, const int *dims, int count_only) {
    scale_csv t;
    char path[1024], line[2048];
    FILE *in;
    int d, i, e, whole = 1, frames = (int)floor(cfg->duration[2] * SCALE_FPS + 0.5);
    if (frames < 1) frames = 1;
    for (d = 2; d <= 3; ++d)
        for (i = 0; dims[d] && i < cfg->scale_n_res[d]; ++i) {
            pn_ex_scene s;
            size_t nodes;
            unsigned long n = (unsigned long)scale_scene(cfg, d, cfg->scale_res[d][i], 1e7, &s, &nodes);
            printf("sand column %dD res %d: %lu particles, %lu grid nodes\n", d, cfg->scale_res[d][i], n,
                   (unsigned long)nodes);
        }
    fflush(stdout);
    if (count_only) return 0;
    memset(&t, 0, sizeof t);
    snprintf(path, sizeof path, "%s/bench_scale.csv", cfg->out);
    if ((in = fopen(path, "r"))) { /* resume: the runs already there are skipped */
        int ln = 0;
        while (fgets(line, sizeof line, in)) {
            scale_row o;
            whole = strchr(line, '\n') != NULL;
            if (ln++ == 0) {
                if (strncmp(line, scale_header, strlen(scale_header))) {
                    fprintf(stderr, "bench_mpm: %s has another header (an older bench_mpm's): move it away\n", path);
                    fclose(in);
                    return 1;
                }
                continue;
            }
            if (scale_parse(line, &o)) scale_add(&t, &o);
        }
        fclose(in);
        fprintf(stderr, "scale: %d runs already in %s\n", t.n, path);
    }
    if (!(t.f = fopen(path, "a"))) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return 1;
    }
    if (fseek(t.f, 0, SEEK_END) == 0 && ftell(t.f) == 0) fprintf(t.f, "%s\n", scale_header);
    else if (!whole) fprintf(t.f, "\n"); /* a line cut short by a kill: left unparsed, ended here */
    for (d = 2; d <= 3; ++d)
        for (i = 0; dims[d] && i < cfg->scale_n_res[d]; ++i)
            for (e = 0; e < cfg->n_Es; ++e) scale_group(cfg, &t, d, cfg->scale_res[d][i], cfg->Es[e], frames);
    fclose(t.f);
    snprintf(path, sizeof path, "%s/bench_scale.md", cfg->out);
    scale_md(path, &t);
    fprintf(stderr, "wrote %s/bench_scale.{csv,md}\n", cfg->out);
    free(t.rows);
    return 0;
}

static void usage(void) {
    fprintf(stderr, "usage: bench_mpm [--quick] [--only sand|snow] [--dim 2|3] [--duration S] [--res2 N] [--res3 N]\n"
                    "       [--max-run-seconds S] [--filter S] [--references] [--out DIR] [--snowball]\n"
                    "       [--dts S,S,..] [--passes N,N,..] [--energies pnet,lagged,dp,stress] [--no-sweep]\n"
                    "       [--contact-rounds N] [--cg-forcing X] [--no-hardening] [--cost] [--min-wall S]\n"
                    "       [--sweep-only] [--sweep-dim 2|3] [--sweep-res N] [--sweep-E E,E,..] [--sweep-runs I,I,..]\n"
                    "       [--sweep-scene sand|snow] [--sweep-tol X] [--cell-relax X] [--energy-rise-tol X]\n"
                    "       [--materials]\n"
                    "       bench_mpm --scale [--scale-dim 2|3] [--scale-res2 N,N,..] [--scale-res3 N,N,..]\n"
                    "       [--sweep-E E,E,..] [--duration S] [--max-run-seconds S] [--out DIR] [--scale-count]\n"
                    "       [--scale-implicit-only]\n");
}

/* a comma-separated list of up to 8 positive numbers; its length, 0 if malformed */
static int parse_list(const char *v, double *out) {
    int n = 0;
    char *end;
    while (n < 8) {
        out[n] = strtod(v, &end);
        if (end == v || !(out[n] > 0)) return 0;
        ++n;
        if (*end == 0) return n;
        if (*end != ',') return 0;
        v = end + 1;
    }
    return 0;
}

/* energies by name into a mask over bench_one's energies_run (pnet, lagged, dp, stress); 0 if
   unknown */
static unsigned parse_energies(const char *v) {
    static const char *names[] = {"pnet", "lagged", "dp", "stress"};
    unsigned mask = 0;
    while (*v) {
        size_t len = strcspn(v, ",");
        int e, hit = 0;
        for (e = 0; e < 4; ++e)
            if (strlen(names[e]) == len && !strncmp(v, names[e], len)) mask |= 1u << e, hit = 1;
        if (!hit) return 0;
        v += len;
        if (*v == ',') ++v;
    }
    return mask;
}

int main(int argc, char **argv) {
    static const double dts_full[] = {1e-4, 1e-3, 1e-2}, dts_quick[] = {1e-3, 1e-2};
    static const int fp_full[] = {1, 2, 4}, fp_quick[] = {1, 2};
    static const double Es_full[] = {1e6, 1e7, 1e8, 1e9, 1e10}, Es_quick[] = {1e6, 1e7};
    static double Es_arg[8];
    static const double Es_scale[] = {1e7, 1e9};
    static const int res_scale[4][3] = {{0, 0, 0}, {0, 0, 0}, {417, 932, 0}, {49, 78, 122}};
    int n_Es_arg = 0, sweep_only = 0, materials = 0, scale = 0, scale_count = 0, scale_dim = 0, max_run_set = 0;
    double scale_res_arg[4][8];
    bench_cfg cfg;
    int only = -1, dim_only = 0, k, d, kind, n_sc = 0, n_rows = 0, n_dts = 0, n_passes = 0, sweep = 1, bad = 0, cost = 0;
    static double dts_arg[8], passes_arg[8];
    static int passes_int[8];
    unsigned mask = 15;
    double duration = 0;
    char path[1024];
    FILE *csv, *esw;
    static bench_scene scenes[4]; /* large: kept off the stack */
    static sweep_row rows[8];
    memset(&cfg, 0, sizeof cfg);
    cfg.out = "build";
    cfg.res[2] = 64;
    cfg.res[3] = 16;
    cfg.duration[2] = 0.5;
    cfg.duration[3] = 0.3;
    cfg.max_run_s = 120;
    cfg.min_wall_s = 2;
    cfg.filter = -1;
    cfg.solver.contact_rounds = 1;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        if (!strcmp(a, "--quick")) cfg.quick = 1;
        else if (!strcmp(a, "--references")) cfg.refs_only = 1;
        else if (!strcmp(a, "--no-sweep")) sweep = 0;
        else if (!strcmp(a, "--sweep-only")) sweep_only = 1;
        else if (!strcmp(a, "--no-hardening")) cfg.no_hardening = 1;
        else if (!strcmp(a, "--snowball")) cfg.snowball = 1;
        else if (!strcmp(a, "--cost")) cost = 1;
        else if (!strcmp(a, "--materials")) materials = 1;
        else if (!strcmp(a, "--scale")) scale = 1;
        else if (!strcmp(a, "--scale-count")) scale = scale_count = 1;
        else if (!strcmp(a, "--scale-implicit-only")) scale = cfg.scale_implicit_only = 1;
        else if (!v) { usage(); return 2; }
        else if (!strcmp(a, "--only")) only = !strcmp(v, "sand") ? 0 : !strcmp(v, "snow") ? 1 : 2, ++k;
        else if (!strcmp(a, "--dim")) dim_only = atoi(v), ++k;
        else if (!strcmp(a, "--duration")) duration = atof(v), ++k;
        else if (!strcmp(a, "--res2")) cfg.res[2] = atoi(v), ++k;
        else if (!strcmp(a, "--res3")) cfg.res[3] = atoi(v), ++k;
        else if (!strcmp(a, "--sweep-res")) cfg.sweep_res = atoi(v), ++k;
        else if (!strcmp(a, "--sweep-dim")) cfg.sweep_dim = atoi(v), ++k;
        else if (!strcmp(a, "--sweep-scene")) {
            cfg.sweep_kind = !strcmp(v, "snow") ? PN_EX_SNOW_PRESS : PN_EX_SAND_COLUMN;
            bad |= strcmp(v, "snow") && strcmp(v, "sand");
            ++k;
        }
        else if (!strcmp(a, "--sweep-E")) bad |= !(n_Es_arg = parse_list(v, Es_arg)), ++k;
        else if (!strcmp(a, "--sweep-runs")) {
            double idx[8];
            int m = parse_list(v, idx), q;
            bad |= !m;
            for (cfg.sweep_mask = 0, q = 0; q < m; ++q) bad |= idx[q] > SWEEP_RUNS, cfg.sweep_mask |= 1u << ((int)idx[q] - 1);
            ++k;
        }
        else if (!strcmp(a, "--max-run-seconds")) cfg.max_run_s = atof(v), max_run_set = 1, ++k;
        else if (!strcmp(a, "--min-wall")) cfg.min_wall_s = atof(v), ++k;
        else if (!strcmp(a, "--scale-dim")) bad |= (scale_dim = atoi(v)) != 2 && scale_dim != 3, ++k;
        else if (!strcmp(a, "--scale-res2") || !strcmp(a, "--scale-res3")) {
            int dd = a[11] - '0', q;
            bad |= !(cfg.scale_n_res[dd] = parse_list(v, scale_res_arg[dd]));
            for (q = 0; q < cfg.scale_n_res[dd]; ++q)
                bad |= (cfg.scale_res[dd][q] = (int)scale_res_arg[dd][q]) < 16 || cfg.scale_res[dd][q] > 1024;
            ++k;
        }
        else if (!strcmp(a, "--out")) cfg.out = v, ++k;
        else if (!strcmp(a, "--filter")) cfg.filter = atof(v), ++k;
        else if (!strcmp(a, "--dts")) bad |= !(n_dts = parse_list(v, dts_arg)), ++k;
        else if (!strcmp(a, "--passes")) bad |= !(n_passes = parse_list(v, passes_arg)), ++k;
        else if (!strcmp(a, "--energies")) bad |= !(mask = parse_energies(v)), ++k;
        else if (!strcmp(a, "--sweep-tol")) bad |= !((cfg.solver.sweep_tol = (pn_real)atof(v)) > 0), ++k;
        else if (!strcmp(a, "--cell-relax")) bad |= !((cfg.solver.cell_relax = (pn_real)atof(v)) >= 1), ++k;
        else if (!strcmp(a, "--anderson")) bad |= strcmp(v, "on") && strcmp(v, "off"), cfg.solver.anderson = strcmp(v, "off") ? 0 : -1, ++k;
        else if (!strcmp(a, "--energy-rise-tol")) cfg.solver.energy_rise_tol = (pn_real)atof(v), ++k;
        else if (!strcmp(a, "--contact-rounds")) bad |= (cfg.solver.contact_rounds = atoi(v)) < 1, ++k;
        else if (!strcmp(a, "--cg-forcing")) bad |= !((cfg.solver.cg_forcing_max = (pn_real)atof(v)) >= 0 && cfg.solver.cg_forcing_max < 1), ++k;
        else { usage(); return 2; }
    }
    if (bad || only == 2 || (dim_only && dim_only != 2 && dim_only != 3) || duration < 0 || !(cfg.filter >= 0 || cfg.filter == -1) || cfg.res[2] < 16 || cfg.res[3] < 16 ||
        (cfg.sweep_res && cfg.sweep_res < 16) || (cfg.sweep_dim && cfg.sweep_dim != 2 && cfg.sweep_dim != 3)) {
        usage();
        return 2;
    }
    if (cfg.quick) { /* smoke test: coarse, 2 frames, 2D unless asked, fewer combinations */
        if (cfg.res[2] == 64) cfg.res[2] = 32;
        cfg.duration[2] = cfg.duration[3] = 2.0 / BENCH_FPS;
        if (!dim_only) dim_only = 2;
    }
    if (duration > 0) cfg.duration[2] = cfg.duration[3] = duration;
    cfg.dts = cfg.quick ? dts_quick : dts_full;
    cfg.n_dts = cfg.quick ? 2 : 3;
    cfg.fps_iters = cfg.quick ? fp_quick : fp_full;
    cfg.n_fps = cfg.quick ? 2 : 3;
    if (n_dts) cfg.dts = dts_arg, cfg.n_dts = n_dts;
    for (k = 0; k < n_passes; ++k) passes_int[k] = (int)passes_arg[k];
    if (n_passes) cfg.fps_iters = passes_int, cfg.n_fps = n_passes;
    cfg.energy_mask = mask;
    cfg.Es = cfg.quick ? Es_quick : Es_full;
    cfg.n_Es = cfg.quick ? 2 : 5;
    if (n_Es_arg) cfg.Es = Es_arg, cfg.n_Es = n_Es_arg;
    if (!cfg.sweep_dim) cfg.sweep_dim = 2;
    if (!cfg.sweep_res) cfg.sweep_res = cfg.res[cfg.sweep_dim];
    if (!cfg.sweep_mask) cfg.sweep_mask = (1u << SWEEP_RUNS) - 1;
    if (!pn_ex_mkdirs(cfg.out)) {
        fprintf(stderr, "bench_mpm: cannot create the folder %s\n", cfg.out);
        return 1;
    }
    if (scale) { /* the sizes table only: 1.5 s, E 1e7 and 1e9 Pa, no time limit unless said */
        int dims[4] = {0, 0, 1, 1};
        if (scale_dim) dims[5 - scale_dim] = 0;
        for (d = 2; d <= 3; ++d)
            if (!cfg.scale_n_res[d])
                for (k = 0; k < 3 && res_scale[d][k]; ++k) cfg.scale_res[d][cfg.scale_n_res[d]++] = res_scale[d][k];
        cfg.duration[2] = cfg.duration[3] = duration > 0 ? duration : 1.5;
        if (!n_Es_arg) cfg.Es = Es_scale, cfg.n_Es = 2;
        if (!max_run_set) cfg.max_run_s = 0;
        return bench_scale(&cfg, dims, scale_count);
    }
    if (materials) { /* the material table only */
        static const double m_dts[] = {1e-4, 1e-3};
        static const int m_fps[] = {2, 4};
        int q, m_fp[8];
        for (q = 0; q < n_dts; ++q) m_fp[q] = n_passes > q ? (int)passes_arg[q] : 2;
        bench_materials(&cfg, n_dts ? n_dts : 2, n_dts ? dts_arg : m_dts, n_dts ? m_fp : m_fps);
        return 0;
    }
    if (cost) { /* the cost table only */
        snprintf(path, sizeof path, "%s/bench_mpm_cost.md", cfg.out);
        if (!(csv = fopen(path, "w"))) {
            fprintf(stderr, "bench_mpm: cannot write %s\n", path);
            return 1;
        }
        fprintf(csv, "<!-- written by bench/bench_mpm.c --cost -->\nWall milliseconds per step, the least of %d "
                     "blocks of %d steps.\n\n", COST_REPS, COST_STEPS);
        for (kind = 0; kind < 2; ++kind)
            for (d = 2; d <= 3; ++d)
                if ((only < 0 || only == kind) && (!dim_only || dim_only == d))
                    bench_cost(&cfg, bench_kind(&cfg, kind), d, csv);
        fclose(csv);
        fprintf(stderr, "wrote %s\n", path);
        return 0;
    }
    snprintf(path, sizeof path, "%s/bench_mpm.csv", cfg.out);
    if (!(csv = fopen(path, "w"))) {
        fprintf(stderr, "bench_mpm: cannot write %s\n", path);
        return 1;
    }
    csv_header(csv);
    for (kind = 0; kind < 2 && !sweep_only; ++kind)
        for (d = 2; d <= 3; ++d) {
            if ((only >= 0 && only != kind) || (dim_only && dim_only != d)) continue;
            bench_one(&cfg, bench_kind(&cfg, kind), d, &scenes[n_sc++], csv);
        }
    fclose(csv);
    snprintf(path, sizeof path, "%s/bench_mpm_esweep.csv", cfg.out);
    if ((only < 0 || only == 0 || sweep_only) && (!dim_only || dim_only == 2) && !cfg.refs_only && sweep) {
        if (!(esw = fopen(path, "w"))) {
            fprintf(stderr, "bench_mpm: cannot write %s\n", path);
            return 1;
        }
        bench_sweep(&cfg, rows, esw);
        n_rows = cfg.n_Es;
        fclose(esw);
        snprintf(path, sizeof path, "%s/bench_mpm_esweep.svg", cfg.out);
        write_sweep_svg(path, rows, n_rows);
        snprintf(path, sizeof path, "%s/bench_mpm_esweep.md", cfg.out);
        write_sweep_md(path, &cfg, rows, n_rows);
    }
    if (n_sc) {
        snprintf(path, sizeof path, "%s/bench_mpm.svg", cfg.out);
        write_svg(path, scenes, n_sc);
        snprintf(path, sizeof path, "%s/bench_mpm.md", cfg.out);
        write_md(path, &cfg, scenes, n_sc);
    }
    fprintf(stderr, "wrote %s/bench_mpm.{csv,svg,md}%s\n", cfg.out, n_rows ? " and bench_mpm_esweep.{csv,svg,md}" : "");
    return 0;
}
