/* metal_frame: a rectangular steel frame on the ground, crushed by a rigid plate moving down
   at a constant speed; finite elements of plastinet_mpm.h (>>fem) with barrier contact,
   explicit (the reference) or implicit with the exact von Mises energy, PlasticityNet, the
   lagged energy, or their Neo-Hookean metal counterparts.
   Build: cc -std=c99 -O2 examples/metal_frame.c -lm -o metal_frame
   Usage: metal_frame [flags]      (metal_frame --help lists them)
   Defaults: 2D (plane strain), implicit, exact energy, dt 1e-2 s; the frame's bounding box
   0.1 m x 0.18 m, walls 0.01 m thick, squares of 2.5 mm in 2D, each four triangles around
   its centre (crossed: they do not lock under von Mises flow), cubes of 5 mm in 3D (six
   tetrahedra each; extruded 0.03 m); the side walls bowed out 0.5 mm at mid-height;
   steel: E = 200 GPa, nu 0.3, the yield stress 0.003 E and hardening 0.01 E of the single-
   material metal models (--yield, --hardening: others, with exact, lagged, nh or
   pnet_nh_any), density 7850; the plate at 0.5 m/s until it has gone 40% of the frame's
   height down; ground and plate with Coulomb friction 0.3; 25 frames per second.
   Writes DIR/frame_NNNN.png (--png, 2D: elements coloured by equivalent plastic strain, with a
   scale bar), DIR/frame_NNNN.vtu (--vtu: per-element plastic strain and von Mises stress, for
   ParaView), DIR/frame_NNNN.obj (--obj: the surface, for Blender); a progress line on stderr;
   a one-line JSON summary on stdout. */
#define PLASTINET_IMPLEMENTATION
#include "common/pn_example.h"
#include "common/pn_frame.h"

/* order of sorted vertex triples (qsort) */

typedef struct frame_cli {
    int dim, implicit, frames_per_s, png, vtu, obj, pass, alternating;
    const char *energy, *out, *solver;
    double dt, E, speed, wall, h, depth, crush, friction, newton_tol, regularizer, yield, hardening;
} frame_cli;

static void usage(FILE *f) {
    fprintf(f, "usage: metal_frame [flags]   a steel frame crushed by a plate\n"
               "  --dim 2|3                 plane strain or the frame extruded [2]\n"
               "  --integrator explicit|implicit                     [implicit]\n"
               "  --energy exact|pnet|lagged|pnet_nh|nh|pnet_nh_any   implicit steps: exact\n"
               "                            StVK-Hencky + von Mises, PlasticityNet, lagged;\n"
               "                            PlasticityNet Neo-Hookean metal with its learned\n"
               "                            return mapping, Neo-Hookean (lagged) with the\n"
               "                            root-find one, the conditioned PlasticityNet\n"
               "                            Neo-Hookean metal (any --yield, --hardening in its\n"
               "                            ranges) [exact]\n"
               "  --yield R                 yield stress / E [3e-3]\n"
               "  --hardening R             hardening modulus / E [1e-2]\n"
               "  --dt S                    implicit step [1e-2]; explicit: at most S, else\n"
               "                            half of pn_fem_stable_dt\n"
               "  --E PA                    Young's modulus [2e11]\n"
               "  --speed M_S               plate speed [0.5]\n"
               "  --crush F                 stop when the plate has gone F of the height [0.4]\n"
               "  --wall M                  wall thickness [0.01]\n"
               "  --h M                     element size [2.5e-3 in 2D, 5e-3 in 3D]\n"
               "  --depth M                 3D: extrusion depth [0.03]\n"
               "  --friction MU             Coulomb coefficient of ground and plate [0.3]\n"
               "  --passes N                F0 fixed-point passes [1]\n"
               "  --solver default|cholesky|pcg   implicit: the Newton systems' solver; default:\n"
               "                            Cholesky unless its factor is too large [default]\n"
               "  --newton-tol X            pn_fem_implicit_desc.newton_tol [1e-5]\n"
               "  --regularizer W           PlasticityNet's w, strain form (-1: off) [1]\n"
               "  --fps N                   frames per simulated second [25]\n"
               "  --alternating             2D: two triangles per square, not four (crossed)\n"
               "  --png --vtu --obj         outputs (DIR/frame_NNNN.*)\n"
               "  --out DIR                 [build/metal_frame_frames]\n"
               "  --help                    this text\n");
}

/* the element's equivalent plastic strain: h for von Mises */
static double plastic_strain(const pn_fem_mesh *m, size_t e) { return (double)m->h[e]; }

/* von Mises stress of the element's Kirchhoff stress (Pa) */
static double mises(const pn_fem_mesh *m, size_t e) {
    int d = m->dim, dd = d * d, i, j, a;
    const int *el = m->elem + e * (size_t)(d + 1);
    pn_real Ds[9], F[9], Fe[9], tau[9];
    double tr = 0, s2 = 0;
    for (a = 1; a <= d; ++a)
        for (i = 0; i < d; ++i) Ds[i * d + a - 1] = m->x[(size_t)el[a] * (size_t)d + (size_t)i] - m->x[(size_t)el[0] * (size_t)d + (size_t)i];
    pn_mat_mul(d, Ds, m->Dm_inv + e * (size_t)dd, F);
    pn_mat_mul(d, F, m->Fp_inv + e * (size_t)dd, Fe);
    if (pn_kirchhoff_stress(&m->groups[m->egroup[e]].material, d, Fe, m->h[e], tau) != PN_OK) return 0;
    for (i = 0; i < d; ++i) tr += tau[i * d + i];
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) {
            double s = tau[i * d + j] - (i == j ? tr / d : 0);
            s2 += s * s;
        }
    return sqrt(1.5 * s2);
}

/* VTU with the elements' plastic strain and von Mises stress */
static int write_frame_vtu(const char *path, const pn_fem_mesh *m) {
    double *f = (double *)malloc(sizeof(double) * 2 * (m->n_elems ? m->n_elems : 1));
    const char *names[2] = {"plastic_strain", "von_mises_stress_pa"};
    const double *fields[2];
    size_t e;
    int ok;
    if (!f) return 0;
    for (e = 0; e < m->n_elems; ++e) f[e] = plastic_strain(m, e), f[m->n_elems + e] = mises(m, e);
    fields[0] = f, fields[1] = f + m->n_elems;
    ok = pn_ex_write_vtu(path, m, 2, names, fields);
    free(f);
    return ok;
}

/* 2D picture: the elements coloured by plastic strain (0 .. 0.2), ground, plate, a 2 cm bar */
static int write_png(const char *path, const pn_fem_mesh *m, double plate_y, double t) {
    pn_canvas c;
    int W = 640, H = 720, ok;
    double k = 2600, ox = W / 2.0 - 0.05 * k, oy = H - 60.0, strain_max = 0.2;
    size_t e;
    char label[128];
    if (!pn_canvas_create(&c, W, H)) return 0;
    pn_canvas_fill(&c, 246, 244, 238);
    pn_canvas_rect(&c, 0, (int)oy, W, H - (int)oy, 120, 116, 110, 1);                     /* ground */
    pn_canvas_rect(&c, 0, 0, W, (int)(oy - plate_y * k), 120, 116, 110, 1);               /* plate  */
    for (e = 0; e < m->n_elems; ++e) {
        double x[3], y[3];
        unsigned char rgb[3];
        int a;
        for (a = 0; a < 3; ++a) {
            x[a] = ox + k * m->x[2 * (size_t)m->elem[3 * e + (size_t)a]];
            y[a] = oy - k * m->x[2 * (size_t)m->elem[3 * e + (size_t)a] + 1];
        }
        pn_render_colormap(plastic_strain(m, e) / strain_max, rgb);
        pn_canvas_triangle(&c, x, y, rgb[0], rgb[1], rgb[2], 1);
    }
    pn_canvas_rect(&c, 20, H - 40, (int)(0.02 * k), 6, 30, 30, 30, 1); /* scale bar: 2 cm */
    pn_canvas_text(&c, 20, H - 28, 2, 255, 255, 255, "2 cm");
    { /* colour bar: plastic strain 0 .. strain_max */
        int i;
        for (i = 0; i < 200; ++i) {
            unsigned char rgb[3];
            pn_render_colormap(i / 199.0, rgb);
            pn_canvas_rect(&c, W - 230 + i, H - 40, 1, 10, rgb[0], rgb[1], rgb[2], 1);
        }
        snprintf(label, sizeof label, "plastic strain 0 .. %.1f", strain_max);
        pn_canvas_text(&c, W - 230, H - 26, 2, 255, 255, 255, label);
    }
    snprintf(label, sizeof label, "t = %.3f s", t);
    pn_canvas_text(&c, 20, (int)(oy - plate_y * k) + 10 > 20 ? 12 : 12, 2, 255, 255, 255, label);
    ok = pn_png_write(path, W, H, c.rgb);
    pn_canvas_free(&c);
    return ok;
}

int main(int argc, char **argv) {
    frame_cli o;
    pn_frame_desc fd;
    pn_fem_mesh *m = NULL;
    pn_pnet net;
    pn_fem_implicit_desc id;
    int k, energy, frames, f, fails = 0;
    long steps = 0, newton = 0, cg = 0;
    static const char *const solvers[3] = {"default", "cholesky", "pcg"};
    int solver;
    size_t e, i;
    char why[256], path[1024];
    double t_end, wall_s = 0, dmin = 1e300, hmax = 0, top = 0;
    memset(&o, 0, sizeof o);
    o.dim = 2, o.implicit = 1, o.energy = "exact", o.solver = "default", o.out = "build/metal_frame_frames", o.dt = 1e-2, o.E = 2e11;
    o.speed = 0.5, o.wall = 0.01, o.h = 0, o.depth = 0.03, o.crush = 0.4, o.friction = 0.3, o.frames_per_s = 25, o.pass = 1;
    o.yield = 3e-3, o.hardening = 1e-2;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        double x;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        }
        if (!strcmp(a, "--png")) o.png = 1;
        else if (!strcmp(a, "--vtu")) o.vtu = 1;
        else if (!strcmp(a, "--obj")) o.obj = 1;
        else if (!strcmp(a, "--alternating")) o.alternating = 1;
        else if (!v) {
            fprintf(stderr, "metal_frame: unknown flag or missing value '%s' (--help lists them)\n", a);
            return 2;
        } else if (!strcmp(a, "--integrator")) {
            if (strcmp(v, "explicit") && strcmp(v, "implicit")) {
                fprintf(stderr, "metal_frame: --integrator explicit|implicit\n");
                return 2;
            }
            o.implicit = !strcmp(v, "implicit"), ++k;
        } else if (!strcmp(a, "--energy")) o.energy = v, ++k;
        else if (!strcmp(a, "--out")) o.out = v, ++k;
        else if (!strcmp(a, "--solver")) o.solver = v, ++k;
        else {
            if (!pn_ex_number("metal_frame", a, v, &x)) return 2;
            ++k;
            if (!strcmp(a, "--dim")) o.dim = (int)x;
            else if (!strcmp(a, "--dt")) o.dt = x;
            else if (!strcmp(a, "--E")) o.E = x;
            else if (!strcmp(a, "--speed")) o.speed = x;
            else if (!strcmp(a, "--crush")) o.crush = x;
            else if (!strcmp(a, "--wall")) o.wall = x;
            else if (!strcmp(a, "--h")) o.h = x;
            else if (!strcmp(a, "--depth")) o.depth = x;
            else if (!strcmp(a, "--friction")) o.friction = x;
            else if (!strcmp(a, "--passes")) o.pass = (int)x;
            else if (!strcmp(a, "--newton-tol")) o.newton_tol = x;
            else if (!strcmp(a, "--regularizer")) o.regularizer = x;
            else if (!strcmp(a, "--yield")) o.yield = x;
            else if (!strcmp(a, "--hardening")) o.hardening = x;
            else if (!strcmp(a, "--fps")) o.frames_per_s = (int)x;
            else {
                fprintf(stderr, "metal_frame: unknown flag '%s' (--help lists them)\n", a);
                return 2;
            }
        }
    }
    if ((energy = pn_ex_choice("metal_frame", "--energy", o.energy, pn_frame_energy_names, PN_FRAME_ENERGIES)) < 0) return 2;
    if ((solver = pn_ex_choice("metal_frame", "--solver", o.solver, solvers, 3)) < 0) return 2;
    pn_frame_default(&fd, o.dim);
    if (!o.h) o.h = fd.h;
    if ((o.dim != 2 && o.dim != 3) || !(o.dt > 0) || !(o.E > 0) || !(o.speed > 0) || !(o.crush > 0 && o.crush < 0.9) ||
        !(o.wall > 0 && 2 * o.wall < fd.width) || !(o.h > 0 && o.h <= o.wall) || !(o.depth > 0) || !(o.friction >= 0) ||
        o.frames_per_s < 1 || o.pass < 1 || !(o.yield > 0) || !(o.hardening >= 0)) {
        fprintf(stderr, "metal_frame: a flag is out of range (--help)\n");
        return 2;
    }
    fd.energy = energy, fd.E = o.E, fd.speed = o.speed, fd.wall = o.wall, fd.h = o.h, fd.depth = o.depth, fd.friction = o.friction;
    fd.regularizer = o.regularizer, fd.alternating = o.alternating;
    fd.yield_ratio = o.yield, fd.hardening_ratio = o.hardening;
    if (!pn_frame_create(&fd, &m, &net, why, sizeof why)) {
        fprintf(stderr, "metal_frame: %s\n", why);
        return 1;
    }
    t_end = o.crush * fd.height / o.speed;
    frames = (int)ceil(t_end * o.frames_per_s - 1e-9);
    if ((o.png || o.vtu || o.obj) && !pn_ex_mkdirs(o.out)) {
        fprintf(stderr, "metal_frame: cannot create %s\n", o.out);
        return 1;
    }
    fprintf(stderr, "metal_frame: %dD, %lu nodes, %lu elements, %s %s, dt %g s, E %g Pa, plate %g m/s, %d frames\n", o.dim,
            (unsigned long)m->n_nodes, (unsigned long)m->n_elems, o.implicit ? "implicit" : "explicit",
            o.implicit ? o.energy : "(return mapping)", o.dt, o.E, o.speed, frames);
    memset(&id, 0, sizeof id);
    id.fixed_point_iters = o.pass, id.newton_tol = (pn_real)o.newton_tol, id.linear_solver = (pn_fem_linear_solver)solver;
    for (f = 0; f <= frames; ++f) {
        double t0 = pn_ex_seconds();
        int ok = pn_frame_advance(m, f == 0 ? 0 : fmin(t_end, (double)f / o.frames_per_s), o.implicit, o.dt, 0.5, &id, &steps,
                                  &newton, &cg, &dmin);
        wall_s += pn_ex_seconds() - t0;
        if (!ok) {
            fprintf(stderr, "\nmetal_frame: a step at t = %g s failed: %s\n", (double)m->time_s, pn_fem_error(m));
            fails = 1;
            break;
        }
        for (e = 0; e < m->n_elems; ++e) hmax = fmax(hmax, plastic_strain(m, e));
        fprintf(stderr, "\r  frame %d/%d  t %.3f s  steps %ld  wall %.1f s  max plastic strain %.3f", f, frames, (double)m->time_s,
                steps, wall_s, hmax);
        if (o.png && o.dim == 2) {
            snprintf(path, sizeof path, "%s/frame_%04d.png", o.out, f);
            if (!write_png(path, m, pn_frame_plate(&fd, m->time_s), m->time_s)) fprintf(stderr, "\nmetal_frame: cannot write %s\n", path);
        }
        if (o.vtu) {
            snprintf(path, sizeof path, "%s/frame_%04d.vtu", o.out, f);
            if (!write_frame_vtu(path, m)) fprintf(stderr, "\nmetal_frame: cannot write %s\n", path);
        }
        if (o.obj) {
            snprintf(path, sizeof path, "%s/frame_%04d.obj", o.out, f);
            if (!pn_ex_write_mesh_obj(path, m)) fprintf(stderr, "\nmetal_frame: cannot write %s\n", path);
        }
    }
    fprintf(stderr, "\n");
    for (i = 0; i < m->n_nodes; ++i) top = fmax(top, m->x[i * (size_t)o.dim + 1]);
    printf("{\"dim\": %d, \"nodes\": %lu, \"elements\": %lu, \"integrator\": \"%s\", \"energy\": \"%s\", \"dt\": %g, "
           "\"E\": %g, \"steps\": %ld, \"sim_s\": %.6g, \"wall_s\": %.4g, \"wall_per_sim_s\": %.4g, \"newton_per_step\": %.2f, "
           "\"cg_per_newton\": %.1f, \"min_distance_m\": %.4g, \"max_plastic_strain\": %.4g, \"top_drop_m\": %.5g, \"ok\": %s}\n",
           o.dim, (unsigned long)m->n_nodes, (unsigned long)m->n_elems, o.implicit ? "implicit" : "explicit",
           o.implicit ? o.energy : "return_mapping", o.dt, o.E, steps, (double)m->time_s, wall_s,
           m->time_s > 0 ? wall_s / m->time_s : 0, steps ? (double)newton / steps : 0, newton ? (double)cg / newton : 0, dmin, hmax,
           PN_FRAME_GAP + fd.height - top, fails ? "false" : "true");
    pn_fem_destroy(m);
    return fails;
}
