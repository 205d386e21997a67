/* drop_on_sand: a stiff elastic block (FEM, E 1e9 Pa) dropped, tilted, onto a sand bed
   (MPM), the two coupled through a barrier (plastinet_mpm.h >>couple): implicit, one
   Newton over the grid's velocities and the block's positions at dt 1e-3 s (PlasticityNet's
   sand model by default), or explicit (the reference) at the coupled step bound.
   Build: cc -std=c99 -O2 examples/drop_on_sand.c -lm -o drop_on_sand
   Usage: drop_on_sand [flags]      (drop_on_sand --help lists them)
   Writes DIR/frame_NNNN.png (--png, 2D: particles by speed, the block in grey), DIR/preview.png
   (--apng, 2D, animated), DIR/frame_NNNN.ply (--ply, the particles), DIR/frame_NNNN.vtu and
   DIR/block_NNNN.obj (--vtu, --obj: the block's mesh); a progress line on stderr; a one-line
   JSON summary on stdout: steps, wall seconds of the steps, Newton and CG iterations per
   step, the smallest particle-block distance over the run, the block's final centre and
   tilt, the deepest point it reached below the bed's surface. */
#define PLASTINET_IMPLEMENTATION
#include "common/pn_example.h"
#include "common/pn_drop.h"

static void usage(FILE *f) {
    fprintf(f, "usage: drop_on_sand [flags]   a stiff block dropped onto a sand bed (MPM-FEM coupling)\n"
               "  --dim 2|3                 [2]\n"
               "  --integrator implicit|explicit   [implicit]\n"
               "  --energy pnet|dp|lagged   the sand's implicit energy [pnet]\n"
               "  --dt S                    implicit step [1e-3]; explicit: [0.9 x pn_coupled_stable_dt]\n"
               "  --theta T                 implicit: the theta method, 1 backward Euler, 0.5 the\n"
               "                            trapezoidal rule (less damping, for steps near 1e-3) [1]\n"
               "  --frames N --fps F        [15 frames at 60 per second: the impact and the block at rest]\n"
               "  --res N                   grid cells per axis [2D 64, 3D 32]; the defaults before issue 42\n"
               "                            were res 128 and 30 frames (about 95 s on one core)\n"
               "  --E PA                    the block's Young's modulus [1e9]\n"
               "  --speed M_S               its downward speed at release [2]\n"
               "  --tilt DEG                its tilt [20]\n"
               "  --friction MU             block-sand Coulomb coefficient [0.5]\n"
               "  --png --apng --ply --vtu --obj   outputs (DIR/...)\n"
               "  --out DIR                 [build/drop_on_sand_frames]\n"
               "  --help                    this text\n");
}

/* the block's centre (node mean) and its tilt: the angle of its first rest edge's direction
   now, in the xy plane (degrees) */
static void block_pose(const pn_drop *s, double *c, double *tilt) {
    const pn_fem_mesh *m = s->m;
    int d = m->dim, i;
    size_t k, a = 0, b = 1;
    for (i = 0; i < 3; ++i) c[i] = 0;
    for (k = 0; k < m->n_nodes; ++k)
        for (i = 0; i < d; ++i) c[i] += (double)m->x[k * (size_t)d + (size_t)i] / (double)m->n_nodes;
    for (k = 1; k < m->n_nodes; ++k) /* node 0 and the next along x at rest */
        if (s->X[k * (size_t)d + 1] == s->X[1] && (d == 2 || s->X[k * (size_t)d + 2] == s->X[2])) {
            b = k;
            break;
        }
    *tilt = atan2((double)(m->x[b * (size_t)d + 1] - m->x[a * (size_t)d + 1]),
                  (double)(m->x[b * (size_t)d] - m->x[a * (size_t)d])) * 180 / 3.14159265358979;
}

int main(int argc, char **argv) {
    const char *prog = "drop_on_sand", *out = "build/drop_on_sand_frames", *energy = "pnet";
    int dim = 2, implicit = 1, frames = 15, fps = 60, png = 0, apng = 0, ply = 0, vtu = 0, obj = 0, k, f, e;
    double dt = 0, res = 0, E = 0, speed = 2, tilt = 20, friction = 0.5, theta = 1, wall_s = 0, dmin = 1e300, deepest = 0, c[3], ang, surf;
    long steps = 0, newton = 0, cg = 0, substeps = 0;
    pn_drop_desc dd;
    pn_drop s;
    pn_ex_view view;
    pn_apng *anim = NULL;
    unsigned char *rgb = NULL;
    double *tri = NULL;
    char why[256], path[1024];
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        double x;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        }
        if (!strcmp(a, "--png")) png = 1;
        else if (!strcmp(a, "--apng")) apng = 1;
        else if (!strcmp(a, "--ply")) ply = 1;
        else if (!strcmp(a, "--vtu")) vtu = 1;
        else if (!strcmp(a, "--obj")) obj = 1;
        else if (!v) {
            fprintf(stderr, "%s: unknown flag or missing value '%s' (--help lists them)\n", prog, a);
            return 2;
        } else if (!strcmp(a, "--integrator")) {
            if (strcmp(v, "explicit") && strcmp(v, "implicit")) {
                fprintf(stderr, "%s: --integrator implicit|explicit\n", prog);
                return 2;
            }
            implicit = !strcmp(v, "implicit"), ++k;
        } else if (!strcmp(a, "--energy")) energy = v, ++k;
        else if (!strcmp(a, "--out")) out = v, ++k;
        else {
            if (!pn_ex_number(prog, a, v, &x)) return 2;
            ++k;
            if (!strcmp(a, "--dim")) dim = (int)x;
            else if (!strcmp(a, "--dt")) dt = x;
            else if (!strcmp(a, "--frames")) frames = (int)x;
            else if (!strcmp(a, "--fps")) fps = (int)x;
            else if (!strcmp(a, "--res")) res = x;
            else if (!strcmp(a, "--E")) E = x;
            else if (!strcmp(a, "--speed")) speed = x;
            else if (!strcmp(a, "--tilt")) tilt = x;
            else if (!strcmp(a, "--friction")) friction = x;
            else if (!strcmp(a, "--theta")) theta = x;
            else {
                fprintf(stderr, "%s: unknown flag '%s' (--help lists them)\n", prog, a);
                return 2;
            }
        }
    }
    if ((e = pn_ex_choice(prog, "--energy", energy, pn_drop_energy_names, PN_DROP_ENERGIES)) < 0) return 2;
    if ((dim != 2 && dim != 3) || dt < 0 || frames < 1 || fps < 1 || (res != 0 && (res < 16 || res > 1024)) || E < 0 ||
        !(speed >= 0) || !(friction >= 0) || !(fabs(tilt) <= 90) || !(theta >= 0.5 && theta <= 1)) {
        fprintf(stderr, "%s: a flag is out of range (--help)\n", prog);
        return 2;
    }
    pn_drop_default(&dd, dim);
    dd.energy = e, dd.v0[1] = -speed, dd.tilt_deg = tilt, dd.friction = friction;
    if (res > 0) dd.res = (int)res;
    else if (dim == 2) dd.res = 64; /* 4 times fewer particles than pn_drop_default's 128 (the benchmark's) */
    if (E > 0) dd.E_block = E;
    if (implicit && dt == 0) dt = 1e-3;
    if (!pn_drop_create(&dd, &s, why, sizeof why)) {
        fprintf(stderr, "%s: %s\n", prog, why);
        return 1;
    }
    surf = PN_EX_WALL_CELLS * dd.domain_m / dd.res + dd.bed_m;
    if ((png || apng || ply || vtu || obj) && !pn_ex_mkdirs(out)) {
        fprintf(stderr, "%s: cannot create %s\n", prog, out);
        return 1;
    }
    memset(&view, 0, sizeof view);
    view.width = 960, view.height = 540, view.field_hi = 1.0, view.title = "block on sand (MPM-FEM, one implicit solve)";
    view.lo[0] = 0, view.lo[1] = PN_EX_WALL_CELLS * dd.domain_m / dd.res, view.hi[0] = dd.domain_m, view.hi[1] = 0.6 * dd.domain_m;
    view.lo[2] = 0, view.hi[2] = dd.domain_m, view.floor_m = view.lo[1];
    if ((png || apng) && dim == 2) {
        rgb = (unsigned char *)malloc((size_t)view.width * (size_t)view.height * 3);
        tri = (double *)malloc(sizeof(double) * 6 * s.m->n_elems);
        if (apng) {
            snprintf(path, sizeof path, "%s/preview.png", out);
            anim = pn_apng_open(path, view.width, view.height, fps > 30 ? 30 : fps);
        }
        if (!rgb || !tri || (apng && !anim)) {
            fprintf(stderr, "%s: out of memory or cannot write %s\n", prog, path);
            return 1;
        }
    }
    for (f = 1; f <= frames; ++f) {
        double t_end = (double)f / fps;
        while ((double)s.w->time_s < t_end - 1e-9) {
            pn_coupled_stats st;
            pn_result r;
            double h = dt, t0 = pn_ex_seconds();
            if (!implicit && h == 0) {
                pn_real sdt;
                if (pn_coupled_stable_dt(s.c, &sdt) != PN_OK) sdt = (pn_real)1e-6;
                h = 0.9 * (double)sdt;
            }
            if (h > t_end - (double)s.w->time_s) h = t_end - (double)s.w->time_s;
            if (implicit) {
                pn_coupled_implicit_desc id;
                memset(&id, 0, sizeof id);
                id.theta = (pn_real)theta;
                r = pn_coupled_step_implicit(s.c, (pn_real)h, &id, &st);
            } else r = pn_coupled_step_explicit(s.c, (pn_real)h, &st);
            wall_s += pn_ex_seconds() - t0;
            if (r != PN_OK) {
                fprintf(stderr, "\n%s: step %ld at t = %g s: %s\n", prog, steps, (double)s.w->time_s, pn_coupled_error(s.c));
                return 1;
            }
            steps++, newton += st.newton_iters, cg += st.cg_iters, substeps += st.substeps > 1;
            if (st.min_distance_m < dmin) dmin = (double)st.min_distance_m;
        }
        {
            size_t q;
            for (q = 0; q < s.m->n_nodes; ++q) {
                double depth = surf - (double)s.m->x[q * (size_t)dim + 1];
                if (depth > deepest) deepest = depth;
            }
        }
        fprintf(stderr, "\r%s: frame %d/%d, t = %.3f s, %ld steps, %.1f s", prog, f, frames, (double)s.w->time_s, steps, wall_s);
        if (rgb) {
            pn_render_desc rd;
            memset(&rd, 0, sizeof rd);
            pn_drop_triangles(s.m, tri);
            /* pn_ex_render draws the particles; the block goes over them with the same view */
            {
                pn_real *speed_f = (pn_real *)malloc(sizeof(pn_real) * s.w->n);
                size_t p;
                int i;
                if (!speed_f) return 1;
                for (p = 0; p < s.w->n; ++p) {
                    double s2 = 0;
                    for (i = 0; i < dim; ++i) s2 += (double)s.w->v[p * (size_t)dim + (size_t)i] * (double)s.w->v[p * (size_t)dim + (size_t)i];
                    speed_f[p] = (pn_real)sqrt(s2);
                }
                rd.width = view.width, rd.height = view.height, rd.dim = 2;
                for (i = 0; i < 3; ++i) rd.lo[i] = view.lo[i], rd.hi[i] = view.hi[i];
                rd.radius_m = 0.3 * (double)s.w->desc.dx_m, rd.has_floor = 1, rd.floor_m = view.floor_m;
                rd.field_name = "speed (m/s)", rd.field_hi = view.field_hi, rd.time_s = (double)s.w->time_s, rd.scale_bar = 1;
                rd.title = view.title, rd.tri_xy = tri, rd.n_tris = s.m->n_elems;
                rd.tri_rgb[0] = 120, rd.tri_rgb[1] = 128, rd.tri_rgb[2] = 142;
                if (!pn_render_particles(&rd, s.w->n, s.w->x, speed_f, s.w->active, rgb)) fprintf(stderr, "\n%s: render failed\n", prog);
                free(speed_f);
            }
            if (png) {
                snprintf(path, sizeof path, "%s/frame_%04d.png", out, f);
                if (!pn_png_write(path, view.width, view.height, rgb)) fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
            }
            if (anim) pn_apng_add(anim, rgb);
        }
        if (ply) {
            snprintf(path, sizeof path, "%s/frame_%04d.ply", out, f);
            if (!pn_ex_write_ply(path, s.w)) fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
        }
        if (vtu) {
            snprintf(path, sizeof path, "%s/frame_%04d.vtu", out, f);
            if (!pn_ex_write_vtu(path, s.m, 0, NULL, NULL)) fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
        }
        if (obj) {
            snprintf(path, sizeof path, "%s/block_%04d.obj", out, f);
            if (!pn_ex_write_mesh_obj(path, s.m)) fprintf(stderr, "\n%s: cannot write %s\n", prog, path);
        }
    }
    fprintf(stderr, "\n");
    if (anim) pn_apng_close(anim);
    block_pose(&s, c, &ang);
    printf("{\"example\": \"drop_on_sand\", \"dim\": %d, \"integrator\": \"%s\", \"energy\": \"%s\", \"particles\": %lu, "
           "\"block_nodes\": %lu, \"block_elements\": %lu, \"E_block_pa\": %g, \"frames\": %d, \"t_s\": %.4f, \"steps\": %ld, "
           "\"wall_s\": %.3f, \"newton_per_step\": %.2f, \"cg_per_step\": %.1f, \"steps_halved\": %ld, "
           "\"min_distance_m\": %.4g, \"dhat_m\": %.4g, \"block_center_m\": [%.5f, %.5f, %.5f], \"block_tilt_deg\": %.2f, "
           "\"deepest_below_surface_m\": %.5f}\n",
           dim, implicit ? "implicit" : "explicit", implicit ? pn_drop_energy_names[e] : "none", (unsigned long)s.w->n,
           (unsigned long)s.m->n_nodes, (unsigned long)s.m->n_elems, dd.E_block, frames, (double)s.w->time_s, steps, wall_s,
           steps ? (double)newton / steps : 0.0, steps ? (double)cg / steps : 0.0, substeps, dmin, (double)s.c->dhat, c[0], c[1], c[2],
           ang, deepest);
    free(rgb);
    free(tri);
    pn_drop_free(&s);
    return 0;
}
