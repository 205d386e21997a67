/* sand_column: a column of sand (aspect ratio a = H / W) collapsing on a frictional floor,
   simulated by plastinet_mpm.h, explicit (the reference) or implicit with the PlasticityNet
   sand model, the lagged energy or the frozen-yield Drucker-Prager energy (dp). The scene is
   the one of docs/validation.md (examples/pn_example.h).
   Build: cc -std=c99 -O2 examples/sand_column.c -lm -o sand_column
   Usage: sand_column [flags]      (sand_column --help lists them)
   Defaults: 2D, implicit, pnet, dt 1e-3 s, 1 fixed-point pass, 30 frames at 30 fps, a = 2,
   E = 1e7 Pa, res 64 (2D) / 24 (3D) cells over 1 m (2D) / 0.5 m (3D), walls separate with
   Coulomb friction 0.5, transfer filter time 2e-3 s (pn_mpm_desc.filter_time_s; 0: APIC),
   PlasticityNet regularizer w = 1 (Eq. 11; --regularizer -1: off).
   Writes DIR/frame_NNNN.png (--png), DIR/preview.png (--apng, animated), DIR/frame_NNNN.ply
   (--ply, points) and DIR/frame_NNNN.obj (--obj, 3D surfaces); a progress line on stderr; a
   one-line JSON summary on stdout: frames, wall seconds of the steps (monotonic clock),
   iterations per step, runout (how far the front moved past the column's initial edge), final
   height above the floor, largest fixed-point residual. */
#define PLASTINET_IMPLEMENTATION
#include "pn_example.h"

static void usage(FILE *f) {
    fprintf(f, "usage: sand_column [flags]   a sand column collapsing on a frictional floor\n"
               "  --energy pnet|lagged|dp|elastic   what implicit steps minimize [pnet]\n"
               "  --aspect A                 column height / width [2]\n");
    pn_ex_cli_usage(f);
}

int main(int argc, char **argv) {
    static const char *const energies[] = {"pnet", "lagged", "dp", "elastic"};
    static const pn_mpm_energy energy_of[] = {PN_MPM_ENERGY_PNET, PN_MPM_ENERGY_LAGGED, PN_MPM_ENERGY_DP,
                                              PN_MPM_ENERGY_ELASTIC};
    const char *prog = "sand_column";
    int energy, k, i;
    double aspect = 2, runout = 0;
    pn_ex_cli c;
    pn_ex_scene sc;
    pn_ex_outcome o;
    pn_ex_cli_default(&c, "build/sand_column_frames");
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        int used;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        }
        used = pn_ex_cli_flag(prog, &c, a, v);
        if (used < 0) return 2;
        if (used == 0 && !strcmp(a, "--aspect")) used = pn_ex_number(prog, a, v, &aspect) ? 2 : -1;
        if (used < 0) return 2;
        if (used == 0) {
            fprintf(stderr, "%s: unknown flag '%s' (--help lists them)\n", prog, a);
            return 2;
        }
        k += used - 1;
    }
    if ((energy = pn_ex_choice(prog, "--energy", c.energy, energies, 4)) < 0) return 2;
    pn_ex_scene_default(&sc, PN_EX_SAND_COLUMN, c.dim == 3 ? 3 : 2);
    if (!pn_ex_cli_apply(prog, &c, &sc)) return 2;
    if (!(aspect > 0)) {
        fprintf(stderr, "%s: --aspect must be > 0\n", prog);
        return 2;
    }
    sc.aspect = aspect;
    sc.energy = energy_of[energy];
    if (!pn_ex_simulate(prog, &c, &sc, &o)) return 1;
    for (i = 0; i < c.dim; ++i) /* front travel along the horizontal axes, either side */
        if (i != 1) runout = fmax(runout, fmax(o.hi[i] - o.hi0[i], o.lo0[i] - o.lo[i]));
    printf("{\"scene\": \"sand_column\", \"dim\": %d, \"integrator\": \"%s\", \"energy\": \"%s\", \"dt\": %g, "
           "\"fixed_point_iters\": %d, \"contact_rounds\": %d, \"E\": %g, \"aspect\": %g, \"boundary\": \"%s\", \"friction\": %g, "
           "\"res\": %d, \"particles\": %lu, \"frames\": %d, \"simulated_s\": %.4f, \"wall_s\": %.3f, \"steps\": %ld, "
           "\"newton_per_step\": %.2f, \"cg_per_step\": %.1f, \"fixed_point_per_step\": %.2f, \"sweeps_per_step\": %.1f, "
           "\"line_search_failures\": %ld, \"runout_m\": %.4f, "
           "\"final_height_m\": %.4f, \"max_fixed_point_residual\": %.3e, \"left_domain\": %lu",
           c.dim, c.implicit ? "implicit" : "explicit", c.implicit ? energies[energy] : "return_mapping", c.dt, c.solver.fixed_point_iters, c.solver.contact_rounds,
           sc.E_pa, aspect, pn_ex_walls[c.boundary], c.friction, sc.res, (unsigned long)o.w->n, c.frames,
           (double)o.w->time_s, o.wall_s, o.tally.steps, (double)o.tally.newton / (double)o.tally.steps,
           (double)o.tally.cg / (double)o.tally.steps, (double)o.tally.fixed_point / (double)o.tally.steps,
           (double)o.tally.sweeps / (double)o.tally.steps,
           o.tally.line_search_failures, runout, o.hi[1] - pn_ex_scene_floor(&sc), o.tally.max_fixed_point_residual,
           (unsigned long)o.w->left_total);
    pn_ex_json_end(&o.tally, c.solver.measure_force_error && c.implicit);
    pn_mpm_destroy(o.w);
    return 0;
}
