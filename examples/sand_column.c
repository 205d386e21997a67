/* sand_column: a column of sand (aspect ratio a = H / W) collapsing on a frictional floor,
   simulated by plastinet_mpm.h, implicit or explicit, beside the explicit reference it is
   measured against. The scene is the one of docs/validation.md (examples/pn_example.h).
   Build: cc -std=c99 -O2 examples/sand_column.c -lm -o sand_column
   Usage: sand_column [flags]      (sand_column --help lists them)
   Defaults (`make run`): 2D, implicit at dt 1e-3 s in the stress formulation (Drucker-Prager
   plasticity as the stress's return mapping, exact within the step), particles jittered in
   their lattice cells, 30 frames at 30 fps, a = 2, E = 1e7 Pa, res 64 (2D) / 24 (3D) cells
   over 1 m (2D) / 0.5 m (3D), walls separate with Coulomb friction 0.5, transfer filter time
   2e-3 s (pn_mpm_desc.filter_time_s; 0: APIC). Then the explicit reference (steps of
   pn_mpm_stable_dt) on the same particles to the same time.
   Why these: measured at res 64 on one core, the stress formulation's deposit is within 2%
   of the reference's in runout and height (runout 0.358 m against 0.353 m, height 0.086 m
   against 0.086 m) in about a second of steps. PlasticityNet at dt 1e-3 s stops short
   (runout 0.139 m, 39% of the reference's), at 2.5e-4 s is still 22% short after 14 s of
   steps, and comes within 6% only at 1e-4 s, below the explicit stable step (1.5e-4 s),
   after 21 s: `--energy pnet` runs it (the energy formulation with the embedded model;
   PlasticityNet's regularizer w = 1, --regularizer -1: off). Particles on
   the lattice (--lattice) collapse in vertical strands with every integrator, the
   reference's included (seen at res 64); jittered, none of them does. The old demo:
   --energy pnet --lattice.
   Writes DIR/frame_NNNN.png (--png), DIR/preview.png (--apng, animated), DIR/frame_NNNN.ply
   (--ply, points) and DIR/frame_NNNN.obj (--obj, 3D surfaces); a progress line on stderr; a
   one-line JSON summary on stdout: frames, wall seconds of the steps (monotonic clock),
   iterations per step, runout (how far the front moved past the column's initial edge, the
   farthest particle), final height above the floor (the highest particle), largest
   fixed-point residual; and the reference's runout, height, steps and wall seconds, the
   ratios run / reference, and the min/max mass IoU of the two deposits (pn_example.h). */
#define PLASTINET_IMPLEMENTATION
#include "common/pn_example.h"

static void usage(FILE *f, const pn_ex_cli *d) {
    fprintf(f, "usage: sand_column [flags]   a sand column collapsing on a frictional floor, and its explicit reference\n"
               "  defaults: implicit at 1e-3 s in the stress formulation (Drucker-Prager as a return mapping\n"
               "  of the stress: no energy), jittered particles, res 64; its deposit is within 2%% of the\n"
               "  explicit reference's. PlasticityNet (the energy formulation with the embedded model) is\n"
               "  one flag away, --energy pnet, but at 1e-3 s its deposit stops short (runout 0.14 m against\n"
               "  the reference's 0.35 m); it comes within 10%% only at --dt 1e-4, below the explicit stable\n"
               "  step, more than 20 times slower. Particles on the lattice (--lattice) collapse in vertical strands.\n"
               "  The old demo: --energy pnet --lattice.\n"
               "  --energy pnet|lagged|dp|elastic   what implicit steps minimize; selects the energy\n"
               "                             formulation unless --formulation is given [none: stress]\n"
               "  --aspect A                 column height / width [2]\n"
               "  --reference  --no-reference   run the explicit reference after the run and compare\n"
               "                             [on; off when the run is explicit at the stable step]\n");
    pn_ex_cli_usage(f, d);
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

int main(int argc, char **argv) {
    static const char *const energies[] = {"pnet", "lagged", "dp", "elastic"};
    static const pn_mpm_energy energy_of[] = {PN_MPM_ENERGY_PNET, PN_MPM_ENERGY_LAGGED, PN_MPM_ENERGY_DP,
                                              PN_MPM_ENERGY_ELASTIC};
    const char *prog = "sand_column";
    int energy, k, energy_given = 0, formulation_given = 0, reference = -1, stress;
    double aspect = 2, runout = 0, height = 0, ref_runout = 0, ref_height = 0, ref_wall = 0;
    pn_ex_cli c, d;
    pn_ex_scene sc;
    pn_ex_outcome o;
    pn_ex_tally ref_tally;
    pn_mpm_world *ref = NULL;
    pn_ex_iou_scores iou = {0, 0, 0};
    pn_ex_cli_default(&c, "build/sand_column_frames");
    c.solver.formulation = PN_MPM_FORMULATION_STRESS;
    c.jitter = 1;
    d = c;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        int used;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout, &d);
            return 0;
        }
        energy_given |= !strcmp(a, "--energy");
        formulation_given |= !strcmp(a, "--formulation");
        used = pn_ex_cli_flag(prog, &c, a, v);
        if (used < 0) return 2;
        if (used == 0 && !strcmp(a, "--aspect")) used = pn_ex_number(prog, a, v, &aspect) ? 2 : -1;
        if (used == 0 && !strcmp(a, "--reference")) used = 1, reference = 1;
        if (used == 0 && !strcmp(a, "--no-reference")) used = 1, reference = 0;
        if (used < 0) return 2;
        if (used == 0) {
            fprintf(stderr, "%s: unknown flag '%s' (--help lists them)\n", prog, a);
            return 2;
        }
        k += used - 1;
    }
    if ((energy = pn_ex_choice(prog, "--energy", c.energy, energies, 4)) < 0) return 2;
    if (energy_given && !formulation_given) c.solver.formulation = PN_MPM_FORMULATION_ENERGY;
    stress = c.implicit && c.solver.formulation == PN_MPM_FORMULATION_STRESS;
    if (reference < 0) reference = c.implicit || c.dt > 0;
    pn_ex_scene_default(&sc, PN_EX_SAND_COLUMN, c.dim == 3 ? 3 : 2);
    if (!pn_ex_cli_apply(prog, &c, &sc)) return 2;
    if (!(aspect > 0)) {
        fprintf(stderr, "%s: --aspect must be > 0\n", prog);
        return 2;
    }
    sc.aspect = aspect;
    /* the stress formulation has no energy: bind one that needs no network */
    sc.energy = stress ? PN_MPM_ENERGY_DP : energy_of[energy];
    if (!pn_ex_simulate(prog, &c, &sc, &o)) return 1;
    deposit(o.w, &sc, o.lo0, o.hi0, &runout, &height);
    if (reference) {
        double *fa, *fb;
        size_t nodes = pn_ex_field_size(o.w);
        if (!c.quiet) fprintf(stderr, "the explicit reference to t = %.3f s ...", (double)o.w->time_s);
        if (!pn_ex_reference(prog, &sc, (double)o.w->time_s, c.frames, &ref, &ref_tally, &ref_wall)) {
            pn_mpm_destroy(o.w);
            return 1;
        }
        if (!c.quiet) fprintf(stderr, " %ld steps, %.1f s\n", ref_tally.steps, ref_wall);
        deposit(ref, &sc, o.lo0, o.hi0, &ref_runout, &ref_height);
        fa = (double *)malloc(sizeof(double) * nodes);
        fb = (double *)malloc(sizeof(double) * nodes);
        if (!fa || !fb) {
            fprintf(stderr, "%s: out of memory\n", prog);
            return 1;
        }
        pn_ex_mass_field(o.w, fa);
        pn_ex_mass_field(ref, fb);
        iou = pn_ex_iou(fa, fb, nodes);
        free(fa);
        free(fb);
    }
    printf("{\"scene\": \"sand_column\", \"dim\": %d, \"integrator\": \"%s\", \"formulation\": \"%s\", \"energy\": \"%s\", "
           "\"dt\": %g, \"dt_rule\": \"%s\", \"jitter\": %s, "
           "\"fixed_point_iters\": %d, \"contact_rounds\": %d, \"E\": %g, \"aspect\": %g, \"boundary\": \"%s\", \"friction\": %g, "
           "\"res\": %d, \"particles\": %lu, \"frames\": %d, \"simulated_s\": %.4f, \"wall_s\": %.3f, \"steps\": %ld, "
           "\"newton_per_step\": %.2f, \"cg_per_step\": %.1f, \"fixed_point_per_step\": %.2f, \"sweeps_per_step\": %.1f, "
           "\"line_search_failures\": %ld, \"runout_m\": %.4f, "
           "\"final_height_m\": %.4f, \"max_fixed_point_residual\": %.3e, \"left_domain\": %lu",
           c.dim, c.implicit ? "implicit" : "explicit", !c.implicit ? "explicit" : stress ? "stress" : "energy",
           !c.implicit || stress ? "return_mapping" : energies[energy],
           o.tally.steps ? (double)o.w->time_s / (double)o.tally.steps : 0.0, c.dt > 0 ? "fixed" : c.implicit ? "default" : "stable",
           c.jitter ? "true" : "false", c.solver.fixed_point_iters, c.solver.contact_rounds,
           sc.E_pa, aspect, pn_ex_walls[c.boundary], c.friction, sc.res, (unsigned long)o.w->n, c.frames,
           (double)o.w->time_s, o.wall_s, o.tally.steps, (double)o.tally.newton / (double)o.tally.steps,
           (double)o.tally.cg / (double)o.tally.steps, (double)o.tally.fixed_point / (double)o.tally.steps,
           (double)o.tally.sweeps / (double)o.tally.steps,
           o.tally.line_search_failures, runout, height, o.tally.max_fixed_point_residual,
           (unsigned long)o.w->left_total);
    if (reference)
        printf(", \"reference_integrator\": \"explicit at pn_mpm_stable_dt\", \"reference_steps\": %ld, "
               "\"reference_wall_s\": %.3f, \"reference_runout_m\": %.4f, \"reference_final_height_m\": %.4f, "
               "\"runout_ratio\": %.3f, \"height_ratio\": %.3f, \"mass_iou_minmax\": %.3f, \"mass_iou_binary\": %.3f",
               ref_tally.steps, ref_wall, ref_runout, ref_height, ref_runout > 0 ? runout / ref_runout : 0.0,
               ref_height > 0 ? height / ref_height : 0.0, iou.minmax, iou.binary);
    pn_ex_json_end(&o.tally, c.solver.measure_force_error && c.implicit);
    pn_mpm_destroy(ref);
    pn_mpm_destroy(o.w);
    return 0;
}
