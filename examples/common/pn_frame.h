/* pn_frame.h - the metal-frame scene of examples/metal_frame.c and bench/bench_fem.c: a
   rectangular steel frame on the ground, crushed by a rigid plate moving down at a constant
   speed (FEM, plastinet_mpm.h >>fem). Include after pn_example.h, in the file that defines
   PLASTINET_IMPLEMENTATION. */
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
} pn_frame_desc;

static void pn_frame_default(pn_frame_desc *d, int dim) {
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
static double pn_frame_plate(const pn_frame_desc *d, double t) { return 3 * PN_FRAME_GAP + d->height - d->speed * t; }

/* Build the scene: *out the mesh with its material, energy and the two obstacles; *net the
   PlasticityNet binding (kept by the caller while the mesh lives). 0 and a message in why on
   failure. */
static int pn_frame_create(const pn_frame_desc *d, pn_fem_mesh **out, pn_pnet *net, char *why, size_t cap) {
    pn_fem_grid g;
    pn_fem_group grp;
    pn_fem_desc fd;
    pn_mpm_collider c;
    pn_real *X;
    int *el, ok = 0;
    size_t nn, ne, k;
    const pn_model *model, *ret = NULL;
    int dim = d->dim, nh = d->energy == PN_FRAME_PNET_NH || d->energy == PN_FRAME_NH || d->energy == PN_FRAME_PNET_NH_ANY;
    pn_material_desc md;
    *out = NULL;
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
        goto done;
    }
    for (k = 0; k < nn; ++k) { /* the imperfection: x moves out by imperfection sin(pi y / height) */
        pn_real *p = X + k * (size_t)dim;
        double s = sin(3.14159265358979323846 * (p[1] - PN_FRAME_GAP) / d->height);
        p[0] += (pn_real)(d->imperfection * s * (p[0] < d->width / 2 ? -1 : 1));
    }
    model = nh ? (dim == 2 ? pn_model_metal_nh_2d() : pn_model_metal_nh_3d()) : (dim == 2 ? pn_model_metal_2d() : pn_model_metal_3d());
    if (d->energy == PN_FRAME_PNET_NH) ret = dim == 2 ? pn_model_metal_nh_return_2d() : pn_model_metal_nh_return_3d();
    if (d->energy == PN_FRAME_PNET_NH_ANY) model = dim == 2 ? pn_model_metal_nh_any_2d() : pn_model_metal_nh_any_3d();
    memset(&grp, 0, sizeof grp);
    pn_model_material_desc(model, (pn_real)d->E, &md); /* the model's material at this yield and hardening */
    md.yield_stress_pa = (pn_real)(d->yield_ratio * d->E);
    md.hardening_modulus_pa = (pn_real)(d->hardening_ratio * d->E);
    if (pn_material_init(&grp.material, &md, NULL) != PN_OK) {
        snprintf(why, cap, "E %g Pa, yield ratio %g or hardening ratio %g is out of range", d->E, d->yield_ratio, d->hardening_ratio);
        goto done;
    }
    grp.density_kg_m3 = (pn_real)d->density;
    memset(&fd, 0, sizeof fd);
    fd.dim = dim, fd.n_nodes = nn, fd.n_elements = ne, fd.rest_m = X, fd.elements = el, fd.groups = &grp, fd.n_groups = 1;
    fd.gravity[1] = (pn_real)-9.81;
    if (pn_fem_create(&fd, out, why, cap) != PN_OK) goto done;
    if (d->energy == PN_FRAME_PNET || d->energy == PN_FRAME_PNET_NH || d->energy == PN_FRAME_PNET_NH_ANY) {
        pn_pnet_desc pd;
        const char *w2 = NULL;
        memset(&pd, 0, sizeof pd);
        pd.energy = model, pd.return_map = ret, pd.regularizer = (pn_real)d->regularizer;
        pd.regularizer_form = PN_PNET_REG_STRAIN;
        if (pn_pnet_init(net, &pd, &grp.material, dim, &w2) != PN_OK) {
            snprintf(why, cap, "%s", w2 ? w2 : "pn_pnet_init failed");
            goto done;
        }
        if (pn_fem_group_set_energy(*out, 0, PN_MPM_ENERGY_PNET, net) != PN_OK) goto fem_error;
    } else if (pn_fem_group_set_energy(*out, 0, d->energy == PN_FRAME_EXACT ? PN_MPM_ENERGY_EXACT_VM : PN_MPM_ENERGY_LAGGED,
                                       NULL) != PN_OK)
        goto fem_error;
    memset(&c, 0, sizeof c); /* the ground */
    c.shape = PN_MPM_SHAPE_HALF_SPACE, c.normal[1] = 1, c.friction = (pn_real)d->friction;
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
static int pn_frame_advance(pn_fem_mesh *m, double t, int implicit, double dt, double courant, const pn_fem_implicit_desc *id,
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
#endif
