/* sand_column: a column of sand (aspect ratio a = H / W) collapsing on a frictional floor,
   simulated by plastinet_mpm.h, implicit or explicit, beside the explicit reference it is
   measured against. The scene is the one of docs/validation.md.
   Build: cc -std=c99 -O2 examples/sand_column.c -lm -o sand_column
   Usage: sand_column [flags]      (sand_column --help lists them)

   The simulation itself is column_world() and main(): make a world, add the sand, fill the
   column, bind what implicit steps minimize, step frame by frame, read the deposit, destroy.
   examples/common/pn_example.h does the rest: the shared flags, pictures and point files,
   the mass IoU and the JSON line's tail.

   Defaults (`make run`): 2D, implicit at dt 1e-3 s in the stress formulation (Drucker-Prager
   plasticity as the stress's return mapping, exact within the step), particles jittered in
   their lattice cells, 30 frames at 30 fps, a = 2, E = 1e7 Pa, res 64 (2D) / 24 (3D) cells
   over 1 m (2D) / 0.5 m (3D), walls separate with Coulomb friction 0.5, transfer filter time
   2e-3 s (pn_mpm_desc.filter_time_s; 0: APIC). Then the explicit reference (steps of
   pn_mpm_stable_dt) on the same particles to the same time.
   Why these: measured at res 64 on one core, the stress formulation's deposit is within 2%
   of the reference's in runout and height (runout 0.358 m against 0.353 m, height 0.086 m
   against 0.086 m) in about a second of steps. PlasticityNet at dt 1e-3 s stops short
   (runout 0.205 m, 58% of the reference's; 0.139 m before its first pass left out
   gravity's kick), and at 2.5e-4 s was still 22% short after 14 s of steps; it came within
   6% only at 1e-4 s, below the explicit stable step (1.5e-4 s), after 21 s: `--energy pnet` runs it (the energy formulation with the embedded model;
   PlasticityNet's regularizer w = 1, --regularizer -1: off). Particles on the lattice
   (--lattice) collapse in vertical strands with every integrator, the reference's included
   (seen at res 64); jittered, none of them does. The old demo: --energy pnet --lattice.
   Writes DIR/frame_NNNN.png (--png), DIR/preview.png (--apng, animated), DIR/frame_NNNN.ply
   (--ply, points) and DIR/frame_NNNN.obj (--obj, 3D surfaces); a progress line on stderr; a
   one-line JSON summary on stdout: frames, wall seconds of the steps (monotonic clock),
   iterations per step, runout (how far the front moved past the column's initial edge, the
   farthest particle), final height above the floor (the highest particle), largest
   fixed-point residual; and the reference's runout, height, steps and wall seconds, the
   ratios run / reference, and the min/max mass IoU of the two deposits. */
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* particles only: FEM and coupling left out of the build */
#include "common/pn_example.h" /* plastinet.h, plastinet_mpm.h, the sand models, the plumbing */
#include "../models/pn_models.h" /* every model in models/, for --model */

/* The column's world, with the library's calls: s holds the numbers the flags set (res, E,
   walls, jitter, aspect; pn_ex_scene_default gives the rest), energy what implicit steps
   minimize. NULL after a failure, said on stderr. Made twice: the run and its reference. */
static pn_mpm_world *column_world(const char *prog, const pn_ex_scene *s, pn_energy energy) {
    const pn_model *model = s->model ? s->model : s->dim == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
    double dx = s->domain_m / s->res, sp = dx / 2, floor_m = PN_EX_WALL_CELLS * dx;
    int across = (int)(s->width_m / sp), up = (int)(s->aspect * s->width_m / sp), d = s->dim, i, g;
    double left = floor((s->domain_m / 2 - across * sp / 2) / sp + 0.5) * sp; /* on a lattice line */
    char why[256] = "";
    pn_material_desc md;
    pn_material sand;
    pn_mpm_desc wd;
    pn_mpm_fill_desc fill;
    pn_mpm_world *w = NULL;
    size_t n = 0;
    pn_result r;
    /* the sand the embedded PlasticityNet model was trained on (StVK-Hencky, Drucker-Prager), at E */
    pn_model_material_desc(model, (pn_real)s->E_pa, &md);
    if ((r = pn_material_init(&sand, &md, why, sizeof why)) != PN_OK) goto failed;
    /* the world: res cells per axis, walls PN_EX_WALL_CELLS thick (the floor is their top), gravity */
    memset(&wd, 0, sizeof wd);
    wd.dim = d;
    for (i = 0; i < d; ++i) wd.res[i] = s->res;
    wd.dx_m = (pn_real)dx;
    wd.gravity[1] = (pn_real)-9.81;
    wd.boundary = s->boundary;
    wd.friction = (pn_real)s->friction;
    wd.filter_time_s = (pn_real)s->filter_s;
    wd.wall_cells = PN_EX_WALL_CELLS;
    /* the particles: 2 per cell per axis in a box W wide (a square prism in 3D), a W tall, on the floor */
    memset(&fill, 0, sizeof fill);
    fill.shape = PN_MPM_FILL_BOX;
    fill.per_axis = 2;
    fill.jitter = s->jitter;
    fill.seed = 1;
    for (i = 0; i < d; ++i) {
        fill.center_m[i] = (pn_real)(left + across * sp / 2);
        fill.half_extent_m[i] = (pn_real)(across * sp / 2);
    }
    fill.center_m[1] = (pn_real)(floor_m + up * sp / 2);
    fill.half_extent_m[1] = (pn_real)(up * sp / 2);
    if ((r = pn_mpm_fill_count(&wd, &fill, &n, why, sizeof why)) != PN_OK) goto failed;
    if (n == 0) {
        fprintf(stderr, "%s: the column has no particles (narrower than half a cell)\n", prog);
        return NULL;
    }
    wd.max_particles = n;
    if ((r = pn_mpm_create(&wd, &w, why, sizeof why)) != PN_OK) goto failed;
    if ((g = pn_mpm_add_group(w, &sand, (pn_real)s->density_kg_m3)) < 0) r = PN_ERROR_INVALID_ARGUMENT;
    else {
        fill.group = g;
        r = pn_mpm_fill(w, &fill, NULL);
    }
    if (r == PN_OK && energy == PN_ENERGY_PNET) { /* the network: the world keeps its own copy */
        pn_pnet net;
        pn_pnet_desc nd;
        memset(&nd, 0, sizeof nd);
        nd.energy = model;
        nd.regularizer = (pn_real)s->regularizer;
        if ((r = pn_pnet_init(&net, &nd, &sand, d, why, sizeof why)) != PN_OK) goto failed;
        r = pn_mpm_group_set_energy(w, g, PN_ENERGY_PNET, &net);
    } else if (r == PN_OK) r = pn_mpm_group_set_energy(w, g, energy, NULL);
    if (r == PN_OK) return w;
    snprintf(why, sizeof why, "%s", pn_mpm_error(w));
failed:
    fprintf(stderr, "%s: %s (%s)\n", prog, why, pn_result_string(r));
    pn_mpm_destroy(w);
    return NULL;
}

/* the deposit: how far the front moved past the column's initial edge (either side, along
   the horizontal axes), and the height of the highest particle above the floor */
static void deposit(const pn_mpm_world *w, const pn_ex_scene *s, const double *lo0, const double *hi0, double *runout,
                    double *height) {
    double lo[3], hi[3];
    int i;
    *runout = *height = 0;
    if (!pn_ex_bounds(w, lo, hi)) return;
    for (i = 0; i < w->dim; ++i)
        if (i != 1) *runout = fmax(*runout, fmax(hi[i] - hi0[i], lo0[i] - lo[i]));
    *height = hi[1] - pn_ex_scene_floor(s);
}

static void usage(FILE *f, const pn_ex_cli *d) {
    fprintf(f, "usage: sand_column [flags]   a sand column collapsing on a frictional floor, and its explicit reference\n"
               "  defaults: implicit at 1e-3 s in the stress formulation (Drucker-Prager as a return mapping\n"
               "  of the stress: no energy), jittered particles, res 64; its deposit is within 2%% of the\n"
               "  explicit reference's. PlasticityNet (the energy formulation with the embedded model) is\n"
               "  one flag away, --energy pnet, but at 1e-3 s its deposit stops short (runout 0.20 m against\n"
               "  the reference's 0.35 m); it comes within 10%% only at --dt 1e-4, below the explicit stable\n"
               "  step, more than 20 times slower. Particles on the lattice (--lattice) collapse in vertical strands.\n"
               "  The old demo: --energy pnet --lattice.\n"
               "  --energy pnet|lagged|dp|elastic   what implicit steps minimize; selects the energy\n"
               "                             formulation unless --formulation is given [none: stress]\n"
               "  --aspect A                 column height / width [2]\n"
               "  --width M  --domain M      column width and domain size (m) [0.12; 1 in 2D, 0.5 in 3D]\n"
               "  --model NAME               the PlasticityNet sand model, any in models/ [sand_2d, sand_3d]\n"
               "  --reference  --no-reference   run the explicit reference after the run and compare\n"
               "                             [on; off when the run is explicit at the stable step]\n");
    pn_ex_cli_usage(f, d);
}

/* The command line into c, col (aspect, width, domain; 0: the scene's), *reference (-1: not
   given) and *energy_given. Returns -1 to go on, else the exit code (0 after --help, 2 for a
   bad flag, said on stderr). */
static int flags(int argc, char **argv, pn_ex_cli *c, double col[3], const char **model, int *reference,
                 int *energy_given) {
    const char *prog = "sand_column";
    pn_ex_cli d;
    int k, formulation_given = 0;
    pn_ex_cli_default(c, "build/sand_column_frames");
    c->solver.formulation = PN_MPM_FORMULATION_STRESS;
    c->jitter = 1;
    d = *c;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        int used;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout, &d);
            return 0;
        }
        *energy_given |= !strcmp(a, "--energy");
        formulation_given |= !strcmp(a, "--formulation");
        used = pn_ex_cli_flag(prog, c, a, v);
        if (used < 0) return 2;
        if (used == 0 && !strcmp(a, "--aspect")) used = pn_ex_number(prog, a, v, &col[0]) ? 2 : -1;
        if (used == 0 && !strcmp(a, "--width")) used = pn_ex_number(prog, a, v, &col[1]) ? 2 : -1;
        if (used == 0 && !strcmp(a, "--domain")) used = pn_ex_number(prog, a, v, &col[2]) ? 2 : -1;
        if (used == 0 && !strcmp(a, "--model")) {
            if (!v) {
                fprintf(stderr, "%s: --model needs a model's name\n", prog);
                return 2;
            }
            *model = v, used = 2;
        }
        if (used == 0 && !strcmp(a, "--reference")) used = 1, *reference = 1;
        if (used == 0 && !strcmp(a, "--no-reference")) used = 1, *reference = 0;
        if (used < 0) return 2;
        if (used == 0) {
            fprintf(stderr, "%s: unknown flag '%s' (--help lists them)\n", prog, a);
            return 2;
        }
        k += used - 1;
    }
    if (*energy_given && !formulation_given) c->solver.formulation = PN_MPM_FORMULATION_ENERGY;
    return -1;
}

int main(int argc, char **argv) {
    static const char *const energies[] = {"pnet", "lagged", "dp", "elastic"};
    static const pn_energy energy_of[] = {PN_ENERGY_PNET, PN_ENERGY_LAGGED, PN_ENERGY_DP,
                                              PN_ENERGY_ELASTIC};
    const char *prog = "sand_column";
    int energy, energy_given = 0, reference = -1, stress, stable, frame, ok = 1, exit_code;
    long k, per_frame;
    const char *model_name = NULL;
    double col[3] = {2, 0, 0}, aspect, dt, wall_s = 0, lo0[3], hi0[3], runout, height, ref_runout = 0, ref_height = 0, ref_wall = 0;
    pn_ex_cli c;
    pn_ex_scene sc;
    pn_ex_view view;
    pn_ex_output out;
    pn_ex_tally tally, ref_tally;
    pn_ex_iou_scores iou = {0, 0, 0};
    pn_mpm_world *w, *ref = NULL;
    if ((exit_code = flags(argc, argv, &c, col, &model_name, &reference, &energy_given)) >= 0) return exit_code;
    aspect = col[0];
    if ((energy = pn_ex_choice(prog, "--energy", c.energy, energies, 4)) < 0) return 2;
    stress = c.implicit && c.solver.formulation == PN_MPM_FORMULATION_STRESS;
    if (reference < 0) reference = c.implicit || c.dt > 0;
    pn_ex_scene_default(&sc, PN_EX_SAND_COLUMN, c.dim == 3 ? 3 : 2);
    if (!pn_ex_cli_apply(prog, &c, &sc)) return 2;
    if (!(aspect > 0) || !(col[1] >= 0) || !(col[2] >= 0)) {
        fprintf(stderr, "%s: --aspect, --width and --domain must be > 0\n", prog);
        return 2;
    }
    sc.aspect = aspect;
    if (model_name) { /* a sand energy model of the run's dimension */
        int k;
        for (k = 0; pn_models_all[k]; ++k) {
            const pn_model *mo = pn_models_all[k]();
            if (!strcmp(mo->name, model_name) && mo->kind == PN_MODEL_ENERGY && mo->dim == sc.dim &&
                mo->plastic == PN_PLASTIC_DRUCKER_PRAGER && mo->n_params == 0)
                sc.model = mo;
        }
        if (!sc.model) {
            fprintf(stderr, "%s: --model %s: no %dD single-material sand energy of that name in models/\n", prog,
                    model_name, sc.dim);
            return 2;
        }
    }
    if (col[1] > 0) sc.width_m = col[1];
    if (col[2] > 0) sc.domain_m = col[2];
    if ((aspect + 0.5) * sc.width_m + 2 * PN_EX_WALL_CELLS * pn_ex_scene_dx(&sc) > sc.domain_m) {
        fprintf(stderr, "%s: a column %g m tall does not fit a domain of %g m (--domain)\n", prog, aspect * sc.width_m,
                sc.domain_m);
        return 2;
    }
    pn_ex_scene_view(&sc, &view);
    if (!pn_ex_output_open(prog, &c, &view, &out)) return 1;
    /* the stress formulation has no energy: bind one that needs no network */
    if (!(w = column_world(prog, &sc, stress ? PN_ENERGY_DP : energy_of[energy]))) {
        pn_ex_output_close(prog, &out, 0);
        return 1;
    }
    pn_ex_bounds(w, lo0, hi0);

    /* frames of 1/fps s: steps of dt (implicit: 1e-3 s unless --dt), or explicit ones of
       pn_mpm_stable_dt each (pn_mpm_advance) when no --dt is given */
    stable = !c.implicit && !(c.dt > 0);
    dt = c.implicit && !(c.dt > 0) ? 1e-3 : c.dt;
    per_frame = stable ? 1 : (long)(1.0 / c.fps / dt + 0.5);
    if (per_frame < 1) per_frame = 1;
    memset(&tally, 0, sizeof tally);
    for (frame = 1; frame <= c.frames && ok; ++frame) {
        double t0 = pn_ex_seconds();
        pn_mpm_stats st;
        pn_result r = PN_OK;
        if (stable) {
            pn_mpm_advance_desc adv;
            memset(&adv, 0, sizeof adv);
            adv.integrator = PN_MPM_EXPLICIT;
            if ((r = pn_mpm_advance(w, (pn_real)(1.0 / c.fps), &adv, &st)) == PN_OK) tally.steps += st.substeps;
        } else
            for (k = 0; k < per_frame && r == PN_OK; ++k) {
                r = c.implicit ? pn_mpm_step_implicit(w, (pn_real)dt, &c.solver, &st) : pn_mpm_step_explicit(w, (pn_real)dt, &st);
                if (r == PN_OK) pn_ex_tally_step(&tally, &st, c.implicit);
            }
        wall_s += pn_ex_seconds() - t0;
        if (r != PN_OK) {
            fprintf(stderr, "\n%s: step %ld failed: %s (%s)\n", prog, tally.steps + 1, pn_mpm_error(w), pn_result_string(r));
            ok = 0;
        } else if (!pn_ex_outputs(prog, w, &out, frame))
            ok = 0;
        else if (!c.quiet)
            fprintf(stderr, "\rframe %d/%d  t = %.3f s  wall %.1f s  Newton/step %.1f  CG/step %.0f   ", frame, c.frames,
                    (double)w->time_s, wall_s, c.implicit ? (double)tally.newton / (double)tally.steps : 0.0,
                    c.implicit ? (double)tally.cg / (double)tally.steps : 0.0);
    }
    if (ok && !c.quiet) fprintf(stderr, "\n");
    if (!pn_ex_output_close(prog, &out, ok)) {
        pn_mpm_destroy(w);
        return 1;
    }
    deposit(w, &sc, lo0, hi0, &runout, &height);

    /* the reference: the same particles, explicit at the stable step, to the same time */
    if (reference) {
        if (!c.quiet) fprintf(stderr, "the explicit reference to t = %.3f s ...", (double)w->time_s);
        /* explicit steps use no energy: the lagged one needs no network */
        ref = column_world(prog, &sc, PN_ENERGY_LAGGED);
        if (!ref || !pn_ex_reference(prog, ref, (double)w->time_s, c.frames, &ref_tally, &ref_wall)) {
            pn_mpm_destroy(ref);
            pn_mpm_destroy(w);
            return 1;
        }
        if (!c.quiet) fprintf(stderr, " %ld steps, %.1f s\n", ref_tally.steps, ref_wall);
        deposit(ref, &sc, lo0, hi0, &ref_runout, &ref_height);
        if (!pn_ex_iou_worlds(w, ref, &iou)) {
            fprintf(stderr, "%s: out of memory\n", prog);
            pn_mpm_destroy(ref);
            pn_mpm_destroy(w);
            return 1;
        }
    }
    printf("{\"scene\": \"sand_column\", \"dim\": %d, \"integrator\": \"%s\", \"formulation\": \"%s\", \"energy\": \"%s\", "
           "\"dt\": %g, \"dt_rule\": \"%s\", \"jitter\": %s, "
           "\"fixed_point_iters\": %d, \"contact_rounds\": %d, \"E\": %g, \"aspect\": %g, \"boundary\": \"%s\", \"friction\": %g, "
           "\"res\": %d, \"particles\": %lu, \"frames\": %d, \"simulated_s\": %.4f, \"wall_s\": %.3f, \"steps\": %ld, "
           "\"newton_per_step\": %.2f, \"cg_per_step\": %.1f, \"fixed_point_per_step\": %.2f, \"sweeps_per_step\": %.1f, "
           "\"coarse_per_step\": %.2f, \"coarse_rejected\": %ld, \"line_search_failures\": %ld, \"runout_m\": %.4f, "
           "\"final_height_m\": %.4f, \"max_fixed_point_residual\": %.3e, \"left_domain\": %lu",
           c.dim, c.implicit ? "implicit" : "explicit", !c.implicit ? "explicit" : stress ? "stress" : "energy",
           !c.implicit || stress ? "return_mapping" : energies[energy],
           tally.steps ? (double)w->time_s / (double)tally.steps : 0.0, c.dt > 0 ? "fixed" : c.implicit ? "default" : "stable",
           c.jitter ? "true" : "false", c.solver.fixed_point_iters, c.solver.contact_rounds,
           sc.E_pa, aspect, pn_ex_walls[c.boundary], c.friction, sc.res, (unsigned long)w->n, c.frames,
           (double)w->time_s, wall_s, tally.steps, (double)tally.newton / (double)tally.steps,
           (double)tally.cg / (double)tally.steps, (double)tally.fixed_point / (double)tally.steps,
           (double)tally.sweeps / (double)tally.steps, (double)tally.coarse / (double)tally.steps,
           tally.coarse_rejected, tally.line_search_failures, runout, height, tally.max_fixed_point_residual, (unsigned long)w->left_total);
    if (reference)
        printf(", \"reference_integrator\": \"explicit at pn_mpm_stable_dt\", \"reference_steps\": %ld, "
               "\"reference_wall_s\": %.3f, \"reference_runout_m\": %.4f, \"reference_final_height_m\": %.4f, "
               "\"runout_ratio\": %.3f, \"height_ratio\": %.3f, \"mass_iou_minmax\": %.3f, \"mass_iou_binary\": %.3f",
               ref_tally.steps, ref_wall, ref_runout, ref_height, ref_runout > 0 ? runout / ref_runout : 0.0,
               ref_height > 0 ? height / ref_height : 0.0, iou.minmax, iou.binary);
    pn_ex_json_end(&tally, c.solver.measure_force_error && c.implicit);
    pn_mpm_destroy(ref);
    pn_mpm_destroy(w);
    return 0;
}
