/* pn_frame.h - the metal-frame scene of examples/metal_frame.c and bench/bench_fem.c: a
   rectangular steel frame on the ground, crushed by a rigid plate moving down at a constant
   speed (FEM, plastinet_mpm.h >>fem). Include after pn_example.h, in the file that defines
   PLASTINET_IMPLEMENTATION.
   Here: the scene's numbers (pn_frame_desc), its nodes and elements (pn_frame_mesh), the
   models of each energy, the whole scene in one call for the benchmarks (pn_frame_create,
   pn_frame_advance), and metal_frame's command line, pictures and VTU files.
   metal_frame.c makes the same mesh step by step with the library's calls; a change to the
   scene goes into both (its outputs are compared bit for bit). */
#ifndef PN_FRAME_H
#define PN_FRAME_H
#include "../../models/pn_model_metal_2d.h"
#include "../../models/pn_model_metal_3d.h"
#include "../../models/pn_model_metal_nh_2d.h"
#include "../../models/pn_model_metal_nh_3d.h"
#include "../../models/pn_model_metal_nh_return_2d.h"
#include "../../models/pn_model_metal_nh_return_3d.h"
#include "../../models/pn_model_metal_nh_any_2d.h"
#include "../../models/pn_model_metal_nh_any_3d.h"

/* the implicit energies: exact StVK-Hencky + von Mises, PlasticityNet, lagged; PlasticityNet
   Neo-Hookean metal with its learned return mapping, Neo-Hookean (lagged energy) with the
   root-find return mapping, and the conditioned Neo-Hookean metal model (any yield and
   hardening in its ranges; the root-find return mapping) */
enum { PN_FRAME_EXACT = 0, PN_FRAME_PNET, PN_FRAME_LAGGED, PN_FRAME_PNET_NH, PN_FRAME_NH, PN_FRAME_PNET_NH_ANY, PN_FRAME_ENERGIES };
static const char *const pn_frame_energy_names[PN_FRAME_ENERGIES] = {"exact", "pnet", "lagged", "pnet_nh", "nh", "pnet_nh_any"};

typedef struct pn_frame_desc {
    int dim, energy;             /* 2 or 3; PN_FRAME_*                                       */
    double width, height, wall;  /* the frame's bounding box and wall thickness (m) [0.1, 0.18, 0.01] */
    double depth;                /* 3D: extrusion [0.03]                                     */
    double h;                    /* element size [2.5e-3 in 2D, 5e-3 in 3D]                  */
    double E, density;           /* [2e11 Pa, 7850 kg/m^3]                                   */
    double yield_ratio, hardening_ratio; /* sigma_Y0 / E and K / E [3e-3, 1e-2: the single-
                                    material metal models'; others need pnet_nh_any or an
                                    analytic energy]                                        */
    double speed, friction;      /* plate speed (m/s) [0.5]; Coulomb coefficient of ground and
                                    plate [0.3]                                            */
    double regularizer;          /* PlasticityNet's w, in the strain form (pn_pnet_desc:
                                    PN_PNET_REG_STRAIN; bending elements turn, and Eq. 11's
                                    form would resist that) [0: 1]                         */
    int alternating;             /* 2D: two triangles per square (the diagonal alternating)
                                    instead of four around a centre node, which lock less
                                    under von Mises flow [0]                               */
    double imperfection;         /* the side walls bow out by this much at mid-height (m): a
                                    perfect frame buckles either way, decided by rounding, so
                                    two integrators could take opposite ways [5e-4]        */
    int order;                   /* 2: quadratic elements (pn_fem_quadratic_mesh of the same
                                    cells: linear tetrahedra two through a wall lock in
                                    bending) [0: linear]                                   */
} pn_frame_desc;

PN_EX_UNUSED static void pn_frame_default(pn_frame_desc *d, int dim) {
    memset(d, 0, sizeof *d);
    d->dim = dim, d->energy = PN_FRAME_EXACT;
    d->width = 0.1, d->height = 0.18, d->wall = 0.01, d->depth = 0.03, d->h = dim == 3 ? 5e-3 : 2.5e-3;
    d->E = 2e11, d->density = 7850, d->speed = 0.5, d->friction = 0.3, d->imperfection = 5e-4;
    d->yield_ratio = 3e-3, d->hardening_ratio = 1e-2;
}

/* the frame starts this far above the ground, the plate twice as far above it: beyond the
   barrier's reach dhat (1e-3 of the bounding-box diagonal, about 2e-4 m): a node starting
   inside it is pushed off at once, and the bottom row was kicked past yield that way */
#define PN_FRAME_GAP 5e-4

/* the plate's height at time t */
PN_EX_UNUSED static double pn_frame_plate(const pn_frame_desc *d, double t) { return 3 * PN_FRAME_GAP + d->height - d->speed * t; }

/* The frame's nodes and elements at rest: a grid of cells of about h (pn_fem_grid_mesh)
   without the frame's hole, the side walls bowed out by d->imperfection; with d->order 2 made
   quadratic (pn_fem_quadratic_mesh). *X (nn x dim coordinates) and *el (ne x the element's
   node count) are malloc'd: the caller frees them. 0 and a message in why on failure
   (nothing to free). */
PN_EX_UNUSED static int pn_frame_mesh(const pn_frame_desc *d, pn_real **X_out, int **el_out, size_t *nn_out, size_t *ne_out,
                                      char *why, size_t cap) {
    pn_fem_grid g;
    pn_real *X;
    int *el, dim = d->dim;
    size_t nn, ne, k;
    *X_out = NULL, *el_out = NULL;
    memset(&g, 0, sizeof g); /* a grid of cells of size about h, without the frame's hole */
    g.dim = dim, g.crossed = !d->alternating;
    g.cells[0] = (int)ceil(d->width / d->h - 1e-9), g.cells[1] = (int)ceil(d->height / d->h - 1e-9);
    g.cells[2] = (int)ceil(d->depth / d->h - 1e-9);
    g.size_m[0] = (pn_real)d->width, g.size_m[1] = (pn_real)d->height, g.size_m[2] = (pn_real)d->depth;
    g.lo_m[1] = (pn_real)PN_FRAME_GAP;
    g.hole_lo_m[0] = (pn_real)d->wall, g.hole_lo_m[1] = (pn_real)(PN_FRAME_GAP + d->wall), g.hole_lo_m[2] = (pn_real)-1;
    g.hole_size_m[0] = (pn_real)(d->width - 2 * d->wall), g.hole_size_m[1] = (pn_real)(d->height - 2 * d->wall);
    g.hole_size_m[2] = (pn_real)(d->depth + 2);
    if (pn_fem_grid_mesh(&g, NULL, NULL, &nn, &ne) != PN_OK) {
        snprintf(why, cap, "the frame's grid is out of range");
        return 0;
    }
    X = (pn_real *)malloc(sizeof(pn_real) * nn * (size_t)dim);
    el = (int *)malloc(sizeof(int) * ne * (size_t)(dim + 1));
    if (!X || !el || pn_fem_grid_mesh(&g, X, el, &nn, &ne) != PN_OK) {
        snprintf(why, cap, "out of memory");
        free(X);
        free(el);
        return 0;
    }
    for (k = 0; k < nn; ++k) { /* the imperfection: x moves out by imperfection sin(pi y / height) */
        pn_real *p = X + k * (size_t)dim;
        double s = sin(3.14159265358979323846 * (p[1] - PN_FRAME_GAP) / d->height);
        p[0] += (pn_real)(d->imperfection * s * (p[0] < d->width / 2 ? -1 : 1));
    }
    if (d->order == 2) { /* a node on each edge's middle */
        size_t n2 = 0;
        pn_real *X2 = NULL;
        int *el2 = NULL;
        if (pn_fem_quadratic_mesh(dim, X, nn, el, ne, NULL, NULL, NULL, &n2) == PN_OK) {
            X2 = (pn_real *)malloc(sizeof(pn_real) * n2 * (size_t)dim);
            el2 = (int *)malloc(sizeof(int) * ne * (size_t)((dim + 1) * (dim + 2) / 2));
        }
        if (!X2 || !el2 || pn_fem_quadratic_mesh(dim, X, nn, el, ne, NULL, X2, el2, &n2) != PN_OK) {
            snprintf(why, cap, "out of memory");
            free(X), free(el), free(X2), free(el2);
            return 0;
        }
        free(X), free(el);
        X = X2, el = el2, nn = n2;
    }
    *X_out = X, *el_out = el, *nn_out = nn, *ne_out = ne;
    return 1;
}

/* The models of energy d->energy: *model the energy's (and the material's defaults), *ret the
   learned return mapping (NULL: the analytic one). */
PN_EX_UNUSED static void pn_frame_models(const pn_frame_desc *d, const pn_model **model, const pn_model **ret) {
    int dim = d->dim, nh = d->energy == PN_FRAME_PNET_NH || d->energy == PN_FRAME_NH || d->energy == PN_FRAME_PNET_NH_ANY;
    *ret = NULL;
    *model = nh ? (dim == 2 ? pn_model_metal_nh_2d() : pn_model_metal_nh_3d()) : (dim == 2 ? pn_model_metal_2d() : pn_model_metal_3d());
    if (d->energy == PN_FRAME_PNET_NH) *ret = dim == 2 ? pn_model_metal_nh_return_2d() : pn_model_metal_nh_return_3d();
    if (d->energy == PN_FRAME_PNET_NH_ANY) *model = dim == 2 ? pn_model_metal_nh_any_2d() : pn_model_metal_nh_any_3d();
}

/* Build the scene: *out the mesh with its material, energy and the two obstacles; *net the
   PlasticityNet binding (kept by the caller while the mesh lives). 0 and a message in why on
   failure. */
PN_EX_UNUSED static int pn_frame_create(const pn_frame_desc *d, pn_fem_mesh **out, pn_pnet *net, char *why, size_t cap) {
    pn_group grp;
    pn_fem_desc fd;
    pn_collider c;
    pn_real *X;
    int *el, ok = 0;
    size_t nn, ne;
    const pn_model *model, *ret;
    int dim = d->dim;
    pn_material_desc md;
    *out = NULL;
    if (!pn_frame_mesh(d, &X, &el, &nn, &ne, why, cap)) return 0;
    pn_frame_models(d, &model, &ret);
    memset(&grp, 0, sizeof grp);
    pn_model_material_desc(model, (pn_real)d->E, &md); /* the model's material at this yield and hardening */
    md.yield_stress_pa = (pn_real)(d->yield_ratio * d->E);
    md.hardening_modulus_pa = (pn_real)(d->hardening_ratio * d->E);
    if (pn_material_init(&grp.material, &md, NULL, 0) != PN_OK) {
        snprintf(why, cap, "E %g Pa, yield ratio %g or hardening ratio %g is out of range", d->E, d->yield_ratio, d->hardening_ratio);
        goto done;
    }
    grp.density_kg_m3 = (pn_real)d->density;
    memset(&fd, 0, sizeof fd);
    fd.dim = dim, fd.n_nodes = nn, fd.n_elements = ne, fd.rest_m = X, fd.elements = el, fd.groups = &grp, fd.n_groups = 1;
    fd.gravity[1] = (pn_real)-9.81, fd.order = d->order;
    if (pn_fem_create(&fd, out, why, cap) != PN_OK) goto done;
    if (d->energy == PN_FRAME_PNET || d->energy == PN_FRAME_PNET_NH || d->energy == PN_FRAME_PNET_NH_ANY) {
        pn_pnet_desc pd;
        char w2[256] = "";
        memset(&pd, 0, sizeof pd);
        pd.energy = model, pd.return_map = ret, pd.regularizer = (pn_real)d->regularizer;
        pd.regularizer_form = PN_PNET_REG_STRAIN;
        if (pn_pnet_init(net, &pd, &grp.material, dim, w2, sizeof w2) != PN_OK) {
            snprintf(why, cap, "%s", w2);
            goto done;
        }
        if (pn_fem_group_set_energy(*out, 0, PN_ENERGY_PNET, net) != PN_OK) goto fem_error;
    } else if (pn_fem_group_set_energy(*out, 0, d->energy == PN_FRAME_EXACT ? PN_ENERGY_EXACT_VM : PN_ENERGY_LAGGED,
                                       NULL) != PN_OK)
        goto fem_error;
    memset(&c, 0, sizeof c); /* the ground */
    c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1, c.friction = (pn_real)d->friction;
    if (pn_fem_add_obstacle(*out, &c, NULL) != PN_OK) goto fem_error;
    c.normal[1] = -1, c.center_m[1] = (pn_real)pn_frame_plate(d, 0), c.velocity_m_s[1] = (pn_real)-d->speed; /* the plate */
    if (pn_fem_add_obstacle(*out, &c, NULL) != PN_OK) goto fem_error;
    ok = 1;
    goto done;
fem_error:
    snprintf(why, cap, "%s", pn_fem_error(*out));
done:
    if (!ok && *out) pn_fem_destroy(*out), *out = NULL;
    free(X);
    free(el);
    return ok;
}

/* Advance to time t: implicit steps of at most dt (id: NULL for the defaults), or explicit
   ones of min(dt, courant pn_fem_stable_dt). Totals into *steps, *newton and *cg (optional:
   conjugate-gradient iterations), the smallest contact distance into *dmin. 0 on a failed
   step (the message in pn_fem_error). */
PN_EX_UNUSED static int pn_frame_advance(pn_fem_mesh *m, double t, int implicit, double dt, double courant, const pn_fem_implicit_desc *id,
                            long *steps, long *newton, long *cg, double *dmin) {
    while (m->time_s < t - 1e-12) {
        pn_fem_stats st;
        pn_result r;
        double h = fmin(dt, t - m->time_s);
        if (implicit) r = pn_fem_step_implicit(m, (pn_real)h, id, &st);
        else {
            pn_real sdt;
            pn_fem_stable_dt(m, &sdt);
            r = pn_fem_step_explicit(m, (pn_real)fmin(h, courant * sdt), &st);
        }
        if (r != PN_OK) return 0;
        ++*steps;
        *newton += st.newton_iters;
        if (cg) *cg += st.cg_iters;
        if (st.min_distance_m < *dmin) *dmin = st.min_distance_m;
    }
    return 1;
}

/* ---- metal_frame's command line, pictures and VTU files ---- */

/* metal_frame's command line */
typedef struct pn_frame_cli {
    int dim, implicit, frames_per_s, png, vtu, obj, pass, alternating, order;
    const char *energy, *out, *solver;
    int energy_id, solver_id; /* PN_FRAME_*; pn_fem_linear_solver */
    double dt, E, speed, wall, h, depth, crush, friction, newton_tol, regularizer, yield, hardening;
} pn_frame_cli;

PN_EX_UNUSED static void pn_frame_usage(FILE *f) {
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
               "  --order 1|2               linear or quadratic elements [1]\n"
               "  --png --vtu --obj         outputs (DIR/frame_NNNN.*)\n"
               "  --out DIR                 [build/metal_frame_frames]\n"
               "  --help                    this text\n");
}

/* metal_frame's flags into *o and the scene *fd they describe. Returns -1 to go on, else the
   exit code (0 after --help, 2 for a bad flag, said on stderr). */
PN_EX_UNUSED static int pn_frame_cli_parse(int argc, char **argv, pn_frame_cli *o, pn_frame_desc *fd) {
    static const char *const solvers[3] = {"default", "cholesky", "pcg"};
    int k;
    memset(o, 0, sizeof *o);
    o->dim = 2, o->implicit = 1, o->energy = "exact", o->solver = "default", o->out = "build/metal_frame_frames", o->dt = 1e-2, o->E = 2e11;
    o->speed = 0.5, o->wall = 0.01, o->h = 0, o->depth = 0.03, o->crush = 0.4, o->friction = 0.3, o->frames_per_s = 25, o->pass = 1;
    o->yield = 3e-3, o->hardening = 1e-2;
    for (k = 1; k < argc; ++k) {
        const char *a = argv[k], *v = k + 1 < argc ? argv[k + 1] : NULL;
        double x;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            pn_frame_usage(stdout);
            return 0;
        }
        if (!strcmp(a, "--png")) o->png = 1;
        else if (!strcmp(a, "--vtu")) o->vtu = 1;
        else if (!strcmp(a, "--obj")) o->obj = 1;
        else if (!strcmp(a, "--alternating")) o->alternating = 1;
        else if (!v) {
            fprintf(stderr, "metal_frame: unknown flag or missing value '%s' (--help lists them)\n", a);
            return 2;
        } else if (!strcmp(a, "--integrator")) {
            if (strcmp(v, "explicit") && strcmp(v, "implicit")) {
                fprintf(stderr, "metal_frame: --integrator explicit|implicit\n");
                return 2;
            }
            o->implicit = !strcmp(v, "implicit"), ++k;
        } else if (!strcmp(a, "--energy")) o->energy = v, ++k;
        else if (!strcmp(a, "--out")) o->out = v, ++k;
        else if (!strcmp(a, "--solver")) o->solver = v, ++k;
        else {
            if (!pn_ex_number("metal_frame", a, v, &x)) return 2;
            ++k;
            if (!strcmp(a, "--dim")) o->dim = (int)x;
            else if (!strcmp(a, "--dt")) o->dt = x;
            else if (!strcmp(a, "--E")) o->E = x;
            else if (!strcmp(a, "--speed")) o->speed = x;
            else if (!strcmp(a, "--crush")) o->crush = x;
            else if (!strcmp(a, "--wall")) o->wall = x;
            else if (!strcmp(a, "--h")) o->h = x;
            else if (!strcmp(a, "--depth")) o->depth = x;
            else if (!strcmp(a, "--friction")) o->friction = x;
            else if (!strcmp(a, "--passes")) o->pass = (int)x;
            else if (!strcmp(a, "--newton-tol")) o->newton_tol = x;
            else if (!strcmp(a, "--regularizer")) o->regularizer = x;
            else if (!strcmp(a, "--yield")) o->yield = x;
            else if (!strcmp(a, "--hardening")) o->hardening = x;
            else if (!strcmp(a, "--fps")) o->frames_per_s = (int)x;
            else if (!strcmp(a, "--order")) o->order = (int)x;
            else {
                fprintf(stderr, "metal_frame: unknown flag '%s' (--help lists them)\n", a);
                return 2;
            }
        }
    }
    if ((o->energy_id = pn_ex_choice("metal_frame", "--energy", o->energy, pn_frame_energy_names, PN_FRAME_ENERGIES)) < 0) return 2;
    if ((o->solver_id = pn_ex_choice("metal_frame", "--solver", o->solver, solvers, 3)) < 0) return 2;
    pn_frame_default(fd, o->dim);
    if (!o->h) o->h = fd->h;
    if ((o->dim != 2 && o->dim != 3) || !(o->dt > 0) || !(o->E > 0) || !(o->speed > 0) || !(o->crush > 0 && o->crush < 0.9) ||
        !(o->wall > 0 && 2 * o->wall < fd->width) || !(o->h > 0 && o->h <= o->wall) || !(o->depth > 0) || !(o->friction >= 0) ||
        o->frames_per_s < 1 || o->pass < 1 || !(o->yield > 0) || !(o->hardening >= 0) || o->order < 0 || o->order > 2) {
        fprintf(stderr, "metal_frame: a flag is out of range (--help)\n");
        return 2;
    }
    fd->energy = o->energy_id, fd->E = o->E, fd->speed = o->speed, fd->wall = o->wall, fd->h = o->h, fd->depth = o->depth, fd->friction = o->friction;
    fd->regularizer = o->regularizer, fd->alternating = o->alternating, fd->order = o->order;
    fd->yield_ratio = o->yield, fd->hardening_ratio = o->hardening;
    return -1;
}

/* the element's equivalent plastic strain: h for von Mises (quadratic elements: the mean
   over their integration points) */
PN_EX_UNUSED static double pn_frame_plastic_strain(const pn_fem_mesh *m, size_t e) {
    double h = 0;
    int q;
    for (q = 0; q < m->points_per_element; ++q) h += (double)m->h[e * (size_t)m->points_per_element + (size_t)q];
    return h / m->points_per_element;
}

/* von Mises stress of the element's Kirchhoff stress (Pa; linear elements: F = Ds Dm^-1;
   quadratic ones: at their corners' mean, their first point's plastic state) */
PN_EX_UNUSED static double pn_frame_mises(const pn_fem_mesh *m, size_t e) {
    int d = m->dim, dd = d * d, i, j, a;
    size_t p = e * (size_t)m->points_per_element;
    const int *el = m->elem + e * (size_t)m->nodes_per_element;
    pn_real Ds[9], Di[9], F[9], Fe[9], tau[9], X0[9];
    double tr = 0, s2 = 0;
    for (a = 1; a <= d; ++a) /* F of the corners' simplex, from rest and current edges */
        for (i = 0; i < d; ++i) {
            Ds[i * d + a - 1] = m->x[(size_t)el[a] * (size_t)d + (size_t)i] - m->x[(size_t)el[0] * (size_t)d + (size_t)i];
            X0[i * d + a - 1] = m->X[(size_t)el[a] * (size_t)d + (size_t)i] - m->X[(size_t)el[0] * (size_t)d + (size_t)i];
        }
    if (pn_mat_inverse(d, X0, Di) != PN_OK) return 0;
    pn_mat_mul(d, Ds, Di, F);
    pn_mat_mul(d, F, m->Fp_inv + p * (size_t)dd, Fe);
    if (pn_kirchhoff_stress(&m->groups[m->egroup[e]].material, d, Fe, m->h[p], tau) != PN_OK) return 0;
    for (i = 0; i < d; ++i) tr += tau[i * d + i];
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) {
            double s = tau[i * d + j] - (i == j ? tr / d : 0);
            s2 += s * s;
        }
    return sqrt(1.5 * s2);
}

/* VTU with the elements' plastic strain and von Mises stress */
PN_EX_UNUSED static int pn_frame_write_vtu(const char *path, const pn_fem_mesh *m) {
    double *f = (double *)malloc(sizeof(double) * 2 * (m->n_elems ? m->n_elems : 1));
    const char *names[2] = {"plastic_strain", "von_mises_stress_pa"};
    const double *fields[2];
    size_t e;
    int ok;
    if (!f) return 0;
    for (e = 0; e < m->n_elems; ++e) f[e] = pn_frame_plastic_strain(m, e), f[m->n_elems + e] = pn_frame_mises(m, e);
    fields[0] = f, fields[1] = f + m->n_elems;
    ok = pn_ex_write_vtu(path, m, 2, names, fields);
    free(f);
    return ok;
}

/* 2D picture: the elements coloured by plastic strain (0 .. 0.2), ground, plate, a 2 cm bar */
PN_EX_UNUSED static int pn_frame_write_png(const char *path, const pn_fem_mesh *m, double plate_y, double t) {
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
            x[a] = ox + k * m->x[2 * (size_t)m->elem[(size_t)m->nodes_per_element * e + (size_t)a]];
            y[a] = oy - k * m->x[2 * (size_t)m->elem[(size_t)m->nodes_per_element * e + (size_t)a] + 1];
        }
        pn_render_colormap(pn_frame_plastic_strain(m, e) / strain_max, rgb);
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

#endif
