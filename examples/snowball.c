/* snowball: a ball of snow (Neo-Hookean + Cam-Clay with hardening) thrown at a frictional
   floor at an angle; it breaks and spreads. Simulated by plastinet_mpm.h, explicit (the
   reference) or implicit with the PlasticityNet snow model or the lagged energy (Cam-Clay has
   no exact energy). The scene is the one of shared/design/VALIDATION.md (examples/pn_example.h).
   Build: cc -std=c99 -O2 examples/snowball.c -lm -o snowball
   Usage: snowball [--dim 2|3] [--integrator implicit|explicit] [--energy pnet|lagged] [--dt S]
                   [--fixed-point N] [--contact-rounds N] [--frames N] [--fps N] [--E PA] [--res N] [--speed M_S]
                   [--angle DEG] [--h0 LOGJP] [--no-hardening] [--boundary sticky|slip|separate] [--friction MU]
                   [--filter S] [--regularizer W] [--force-error] [--out DIR] [--png] [--ply] [--quiet]
                   [--newton-tol X] [--cg-tol X] [--cg-forcing X] (pn_mpm_implicit_desc)
   Defaults: 2D, implicit, pnet, dt 1e-3 s, 1 fixed-point pass, 30 frames at 30 fps,
   E = 1e6 Pa, res 64 (2D) / 24 (3D) cells over 1 m (2D) / 0.5 m (3D), radius 0.1 m (2D) /
   0.08 m (3D), 3 m/s at 45 degrees below the horizontal, initial log J_p = -0.01 (inside the
   model's trained range [-0.15, 0]), walls separate with Coulomb friction 0.5, transfer
   filter time 2e-3 s (pn_mpm_desc.filter_time_s; 0: APIC), PlasticityNet regularizer w = 1
   (Eq. 11; --regularizer -1: off). --no-hardening: Cam-Clay with log J_p held (the hardening
   that makes the snow fracture, and its mass field chaotic, is off).
   Writes DIR/frame_NNNN.png (--png) and DIR/frame_NNNN.ply (--ply); a progress line on
   stderr; a one-line JSON summary on stdout: frames, wall seconds (monotonic clock),
   iterations per step, spread (extent of the snow along the throw), runout (how far its front
   moved), final height above the floor, largest fixed-point residual. */
#define PLASTINET_IMPLEMENTATION
#include "pn_example.h"

static void usage(void) {
    fprintf(stderr, "usage: snowball [--dim 2|3] [--integrator implicit|explicit] [--energy pnet|lagged] [--dt S]\n"
                    "       [--fixed-point N] [--contact-rounds N] [--frames N] [--fps N] [--E PA] [--res N] [--speed M_S] [--angle DEG]\n"
                    "       [--h0 LOGJP] [--no-hardening] [--boundary sticky|slip|separate] [--friction MU] [--filter S] [--regularizer W]\n"
                    "       [--force-error] [--out DIR] [--png] [--ply] [--quiet]\n"
                    "       [--newton-tol X] [--cg-tol X] [--cg-forcing X] (pn_mpm_implicit_desc; 0: its default)\n");
}

int main(int argc, char **argv) {
    int lagged, k;
    double speed = 3, angle = 45, h0 = -0.01;
    int no_hardening = 0;
    pn_ex_cli c;
    pn_ex_scene sc;
    pn_ex_outcome o;
    pn_ex_cli_default(&c, "build/snowball_frames");
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        int used = pn_ex_cli_flag(&c, a, v);
        if (used > 0) k += used - 1;
        else if (used == 0 && !strcmp(a, "--no-hardening")) no_hardening = 1;
        else if (used < 0 || !v) { usage(); return 2; }
        else if (!strcmp(a, "--speed")) speed = atof(v), ++k;
        else if (!strcmp(a, "--angle")) angle = atof(v), ++k;
        else if (!strcmp(a, "--h0")) h0 = atof(v), ++k;
        else { usage(); return 2; }
    }
    lagged = !strcmp(c.energy, "lagged") ? 1 : !strcmp(c.energy, "pnet") ? 0 : -1;
    pn_ex_scene_default(&sc, PN_EX_SNOWBALL, c.dim);
    if (!pn_ex_cli_apply(&c, &sc) || lagged < 0 || !(speed >= 0) || !(angle >= -90 && angle <= 90) || !(h0 <= 0)) {
        usage();
        return 2;
    }
    sc.speed_m_s = speed;
    sc.angle_deg = angle;
    sc.h0 = h0;
    sc.no_hardening = no_hardening;
    sc.energy = lagged ? PN_MPM_ENERGY_LAGGED : PN_MPM_ENERGY_PNET;
    if (!pn_ex_simulate("snowball", &c, &sc, &o)) return 1;
    printf("{\"scene\": \"snowball\", \"dim\": %d, \"integrator\": \"%s\", \"energy\": \"%s\", \"dt\": %g, "
           "\"fixed_point_iters\": %d, \"contact_rounds\": %d, \"E\": %g, \"speed\": %g, \"angle\": %g, \"h0\": %g, \"hardening\": %s, \"boundary\": \"%s\", "
           "\"friction\": %g, \"res\": %d, \"particles\": %lu, \"frames\": %d, \"simulated_s\": %.4f, \"wall_s\": %.3f, "
           "\"steps\": %ld, \"newton_per_step\": %.2f, \"cg_per_step\": %.1f, \"fixed_point_per_step\": %.2f, "
           "\"line_search_failures\": %ld, \"spread_m\": %.4f, \"runout_m\": %.4f, \"final_height_m\": %.4f, "
           "\"max_fixed_point_residual\": %.3e, \"left_domain\": %lu",
           c.dim, c.implicit ? "implicit" : "explicit", !c.implicit ? "return_mapping" : lagged ? "lagged" : "pnet", c.dt,
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
