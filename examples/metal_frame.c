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
   a one-line JSON summary on stdout.
   The simulation is main(): the mesh's nodes and elements, the steel, the mesh, the energy,
   the ground and the plate, the step loop, the results, destroy. examples/common/pn_frame.h
   has the frame's shape, the flags, the pictures and the VTU files. */
#define PLASTINET_IMPLEMENTATION
#include "common/pn_example.h" /* plastinet.h, plastinet_mpm.h, the clock, folders, OBJ and VTU */
#include "common/pn_frame.h"   /* the frame's shape and models, the flags, the pictures */

int main(int argc, char **argv) {
    pn_frame_cli o;
    pn_frame_desc fd;
    pn_fem_desc md;
    pn_group steel;
    pn_material_desc sd;
    pn_collider ground, plate;
    pn_fem_implicit_desc id;
    pn_fem_mesh *m = NULL;
    pn_pnet net; /* the mesh keeps a pointer to it: it lives as long as the mesh */
    const pn_model *model, *ret;
    pn_real *X;
    int *el, exit_code, frames, f, fails = 0;
    size_t n_nodes, n_elems, e, i;
    long steps = 0, newton = 0, cg = 0;
    char why[256], path[1024];
    double t_end, wall_s = 0, dmin = 1e300, hmax = 0, top = 0;
    if ((exit_code = pn_frame_cli_parse(argc, argv, &o, &fd)) >= 0) return exit_code;

    /* the nodes and elements at rest (any mesher's arrays would do; this one is a grid with
       a hole) and the steel: the model's material at the flags' yield stress and hardening */
    if (!pn_frame_mesh(&fd, &X, &el, &n_nodes, &n_elems, why, sizeof why)) {
        fprintf(stderr, "metal_frame: %s\n", why);
        return 1;
    }
    pn_frame_models(&fd, &model, &ret);
    pn_model_material_desc(model, (pn_real)fd.E, &sd);
    sd.yield_stress_pa = (pn_real)(fd.yield_ratio * fd.E);
    sd.hardening_modulus_pa = (pn_real)(fd.hardening_ratio * fd.E);
    memset(&steel, 0, sizeof steel);
    steel.density_kg_m3 = (pn_real)fd.density;
    if (pn_material_init(&steel.material, &sd, NULL, 0) != PN_OK) {
        fprintf(stderr, "metal_frame: E %g Pa, yield ratio %g or hardening ratio %g is out of range\n", fd.E, fd.yield_ratio,
                fd.hardening_ratio);
        free(X), free(el);
        return 1;
    }
    /* the mesh (it copies the arrays), then what implicit steps minimize for its one group */
    memset(&md, 0, sizeof md);
    md.dim = o.dim, md.n_nodes = n_nodes, md.n_elements = n_elems, md.rest_m = X, md.elements = el;
    md.groups = &steel, md.n_groups = 1, md.order = fd.order;
    md.gravity[1] = (pn_real)-9.81;
    if (pn_fem_create(&md, &m, why, sizeof why) == PN_OK) {
        if (fd.energy == PN_FRAME_PNET || fd.energy == PN_FRAME_PNET_NH || fd.energy == PN_FRAME_PNET_NH_ANY) {
            pn_pnet_desc pd;
            char w2[256] = "";
            memset(&pd, 0, sizeof pd);
            pd.energy = model, pd.return_map = ret, pd.regularizer = (pn_real)fd.regularizer;
            pd.regularizer_form = PN_PNET_REG_STRAIN; /* bending turns elements: Eq. 11's form would resist it */
            if (pn_pnet_init(&net, &pd, &steel.material, o.dim, w2, sizeof w2) != PN_OK) {
                snprintf(why, sizeof why, "%s", w2);
                fails = 1;
            } else if (pn_fem_group_set_energy(m, 0, PN_ENERGY_PNET, &net) != PN_OK)
                fails = 2;
        } else if (pn_fem_group_set_energy(m, 0, fd.energy == PN_FRAME_EXACT ? PN_ENERGY_EXACT_VM : PN_ENERGY_LAGGED,
                                           NULL) != PN_OK)
            fails = 2;
        /* the ground, and the plate above the frame coming down at the flags' speed */
        memset(&ground, 0, sizeof ground);
        ground.shape = PN_SHAPE_HALF_SPACE, ground.normal[1] = 1, ground.friction = (pn_real)fd.friction;
        plate = ground;
        plate.normal[1] = -1, plate.center_m[1] = (pn_real)pn_frame_plate(&fd, 0), plate.velocity_m_s[1] = (pn_real)-fd.speed;
        if (!fails && (pn_fem_add_obstacle(m, &ground, NULL) != PN_OK || pn_fem_add_obstacle(m, &plate, NULL) != PN_OK))
            fails = 2;
        if (fails == 2) snprintf(why, sizeof why, "%s", pn_fem_error(m));
    } else
        fails = 1;
    free(X), free(el);
    if (fails) {
        fprintf(stderr, "metal_frame: %s\n", why);
        pn_fem_destroy(m);
        return 1;
    }

    t_end = o.crush * fd.height / o.speed;
    frames = (int)ceil(t_end * o.frames_per_s - 1e-9);
    if ((o.png || o.vtu || o.obj) && !pn_ex_mkdirs(o.out)) {
        fprintf(stderr, "metal_frame: cannot create %s\n", o.out);
        pn_fem_destroy(m);
        return 1;
    }
    fprintf(stderr, "metal_frame: %dD, %lu nodes, %lu elements, %s %s, dt %g s, E %g Pa, plate %g m/s, %d frames\n", o.dim,
            (unsigned long)m->n_nodes, (unsigned long)m->n_elems, o.implicit ? "implicit" : "explicit",
            o.implicit ? o.energy : "(return mapping)", o.dt, o.E, o.speed, frames);
    memset(&id, 0, sizeof id); /* zeros: the library's defaults */
    id.fixed_point_iters = o.pass, id.newton_tol = (pn_real)o.newton_tol, id.linear_solver = (pn_fem_linear_solver)o.solver_id;
    /* the step loop: to each frame's time in implicit steps of dt, or explicit ones of at most
       half the stable step */
    for (f = 0; f <= frames && !fails; ++f) {
        double t = f == 0 ? 0 : fmin(t_end, (double)f / o.frames_per_s), t0 = pn_ex_seconds();
        while (m->time_s < t - 1e-12) {
            pn_fem_stats st;
            pn_result r;
            double h = fmin(o.dt, t - m->time_s);
            if (o.implicit) r = pn_fem_step_implicit(m, (pn_real)h, &id, &st);
            else {
                pn_real stable;
                pn_fem_stable_dt(m, &stable);
                r = pn_fem_step_explicit(m, (pn_real)fmin(h, 0.5 * stable), &st);
            }
            if (r != PN_OK) {
                fprintf(stderr, "\nmetal_frame: a step at t = %g s failed: %s\n", (double)m->time_s, pn_fem_error(m));
                fails = 1;
                break;
            }
            ++steps, newton += st.newton_iters, cg += st.cg_iters;
            if (st.min_distance_m < dmin) dmin = st.min_distance_m;
        }
        wall_s += pn_ex_seconds() - t0;
        if (fails) break;
        /* results: the elements' equivalent plastic strain (m->h), the nodes (m->x) */
        for (e = 0; e < m->n_points; ++e) hmax = fmax(hmax, (double)m->h[e]);
        fprintf(stderr, "\r  frame %d/%d  t %.3f s  steps %ld  wall %.1f s  max plastic strain %.3f", f, frames, (double)m->time_s,
                steps, wall_s, hmax);
        if (o.png && o.dim == 2) {
            snprintf(path, sizeof path, "%s/frame_%04d.png", o.out, f);
            if (!pn_frame_write_png(path, m, pn_frame_plate(&fd, m->time_s), m->time_s))
                fprintf(stderr, "\nmetal_frame: cannot write %s\n", path);
        }
        if (o.vtu) {
            snprintf(path, sizeof path, "%s/frame_%04d.vtu", o.out, f);
            if (!pn_frame_write_vtu(path, m)) fprintf(stderr, "\nmetal_frame: cannot write %s\n", path);
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
