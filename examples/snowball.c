/* snowball: a ball of snow (Neo-Hookean + Cam-Clay with hardening) thrown at a frictional
   floor at an angle; it breaks and spreads. Simulated by plastinet_mpm.h, explicit (the
   reference) or implicit with the PlasticityNet snow model or the lagged energy (Cam-Clay has
   no exact energy). The scene is the one of docs/validation.md (examples/common/pn_example.h).
   Build: cc -std=c99 -O2 examples/snowball.c -lm -o snowball
   Usage: snowball [flags]      (snowball --help lists them)
   Defaults: 2D, implicit, pnet, dt 1e-3 s, 1 fixed-point pass, 30 frames at 30 fps,
   E = 1e6 Pa, res 64 (2D) / 24 (3D) cells over 1 m (2D) / 0.5 m (3D), radius 0.1 m (2D) /
   0.08 m (3D), 3 m/s at 45 degrees below the horizontal, initial log J_p = -0.01 (inside the
   model's trained range [-0.15, 0]), walls separate with Coulomb friction 0.5, transfer
   filter time 2e-3 s (pn_mpm_desc.filter_time_s; 0: APIC), PlasticityNet regularizer w = 1
   (Eq. 11; --regularizer -1: off). --no-hardening: Cam-Clay with log J_p held (the hardening
   that makes the snow fracture, and its mass field chaotic, is off). --press: the snow press of
   the benchmarks instead (a layer of the same snow pressed by a plate; res 64 / 24 as above).
   Writes DIR/frame_NNNN.png (--png), DIR/preview.png (--apng, animated), DIR/frame_NNNN.ply
   (--ply) and DIR/frame_NNNN.obj (--obj, 3D); a progress line on stderr; a one-line JSON
   summary on stdout: frames, wall seconds of the steps (monotonic clock),
   iterations per step, spread (extent of the snow along the throw), runout (how far its front
   moved), final height above the floor, largest fixed-point residual. */
#define PLASTINET_IMPLEMENTATION
#define PN_NO_FEM /* particles only: FEM and coupling left out of the build */
#include "common/pn_example.h"

static void usage(FILE *f, const pn_ex_cli *d) {
    fprintf(f, "usage: snowball [flags]   a snowball thrown at a frictional floor\n"
               "  --energy pnet|lagged       what implicit steps minimize [pnet]\n"
               "  --speed M_S  --angle DEG   the throw: speed and angle below the horizontal [3, 45]\n"
               "  --h0 LOGJP                 initial consolidation log J_p <= 0 [-0.01]\n"
               "  --no-hardening             Cam-Clay with the state held\n"
               "  --press                    the snow press of the benchmarks instead of the ball\n");
    pn_ex_cli_usage(f, d);
}

int main(int argc, char **argv) {
    static const char *const energies[] = {"pnet", "lagged"};
    const char *prog = "snowball";
    int lagged, k;
    double speed = 3, angle = 45, h0 = -0.01;
    int no_hardening = 0, press = 0;
    pn_ex_cli c, d;
    pn_ex_scene sc;
    pn_ex_outcome o;
    pn_ex_cli_default(&c, "build/snowball_frames");
    d = c;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        int used;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout, &d);
            return 0;
        }
        used = pn_ex_cli_flag(prog, &c, a, v);
        if (used == 0) {
            if (!strcmp(a, "--no-hardening")) used = no_hardening = 1;
            else if (!strcmp(a, "--press")) used = press = 1;
            else if (!strcmp(a, "--speed")) used = pn_ex_number(prog, a, v, &speed) ? 2 : -1;
            else if (!strcmp(a, "--angle")) used = pn_ex_number(prog, a, v, &angle) ? 2 : -1;
            else if (!strcmp(a, "--h0")) used = pn_ex_number(prog, a, v, &h0) ? 2 : -1;
            else {
                fprintf(stderr, "%s: unknown flag '%s' (--help lists them)\n", prog, a);
                return 2;
            }
        }
        if (used < 0) return 2;
        k += used - 1;
    }
    if ((lagged = pn_ex_choice(prog, "--energy", c.energy, energies, 2)) < 0) return 2;
    pn_ex_scene_default(&sc, press ? PN_EX_SNOW_PRESS : PN_EX_SNOWBALL, c.dim == 3 ? 3 : 2);
    if (!pn_ex_cli_apply(prog, &c, &sc)) return 2;
    if (!(speed >= 0) || !(angle >= -90 && angle <= 90) || !(h0 <= 0)) {
        fprintf(stderr, "%s: --speed must be >= 0, --angle in [-90, 90], --h0 <= 0\n", prog);
        return 2;
    }
    sc.speed_m_s = speed;
    sc.angle_deg = angle;
    sc.h0 = h0;
    sc.no_hardening = no_hardening;
    sc.energy = lagged ? PN_ENERGY_LAGGED : PN_ENERGY_PNET;
    if (!pn_ex_simulate("snowball", &c, &sc, &o)) return 1;
    printf("{\"scene\": \"%s\", \"dim\": %d, \"integrator\": \"%s\", \"energy\": \"%s\", \"dt\": %g, "
           "\"fixed_point_iters\": %d, \"contact_rounds\": %d, \"E\": %g, \"speed\": %g, \"angle\": %g, \"h0\": %g, \"hardening\": %s, \"boundary\": \"%s\", "
           "\"friction\": %g, \"res\": %d, \"particles\": %lu, \"frames\": %d, \"simulated_s\": %.4f, \"wall_s\": %.3f, "
           "\"steps\": %ld, \"newton_per_step\": %.2f, \"cg_per_step\": %.1f, \"fixed_point_per_step\": %.2f, "
           "\"line_search_failures\": %ld, \"spread_m\": %.4f, \"runout_m\": %.4f, \"final_height_m\": %.4f, "
           "\"max_fixed_point_residual\": %.3e, \"left_domain\": %lu",
           press ? "snow_press" : "snowball", c.dim, c.implicit ? "implicit" : "explicit", !c.implicit ? "return_mapping" : lagged ? "lagged" : "pnet",
           o.tally.steps ? (double)o.w->time_s / (double)o.tally.steps : 0.0,
           c.solver.fixed_point_iters, c.solver.contact_rounds, sc.E_pa, speed, angle, h0, no_hardening ? "false" : "true", pn_ex_walls[c.boundary], c.friction, sc.res, (unsigned long)o.w->n, c.frames,
           (double)o.w->time_s, o.wall_s, o.tally.steps, (double)o.tally.newton / (double)o.tally.steps,
           (double)o.tally.cg / (double)o.tally.steps, (double)o.tally.fixed_point / (double)o.tally.steps,
           o.tally.line_search_failures, o.hi[0] - o.lo[0],
           o.hi[0] - o.hi0[0], o.hi[1] - pn_ex_scene_floor(&sc), o.tally.max_fixed_point_residual,
           (unsigned long)o.w->left_total);
    pn_ex_json_end(&o.tally, c.solver.measure_force_error && c.implicit);
    pn_mpm_destroy(o.w);
    return 0;
}
