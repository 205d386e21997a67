/* pn_drop.h - the scene of examples/drop_on_sand.c and bench/bench_coupling.c: a stiff
   elastic block (an FEM mesh, Neo-Hookean) dropped, tilted, onto a sand bed (MPM), the two
   coupled by plastinet_mpm.h >>couple. Include after pn_example.h, in the file that defines
   PLASTINET_IMPLEMENTATION. */
#ifndef PN_DROP_H
#define PN_DROP_H

/* the sand's implicit energy: PlasticityNet's sand model, the frozen-yield Drucker-Prager
   energy, the lagged energy */
enum { PN_DROP_PNET = 0, PN_DROP_DP, PN_DROP_LAGGED, PN_DROP_ENERGIES };
static const char *const pn_drop_energy_names[PN_DROP_ENERGIES] = {"pnet", "dp", "lagged"};

typedef struct pn_drop_desc {
    int dim, res, energy;        /* 2 or 3; grid cells per axis [2D 128, 3D 32]; PN_DROP_*   */
    double domain_m;             /* the cube's edge [2D 1, 3D 0.5]                           */
    double bed_m;                /* the sand's depth [2D 0.25, 3D 0.12]                      */
    double block_m[3];           /* the block's size [2D 0.2 x 0.1, 3D 0.12 x 0.06 x 0.12]   */
    int cells[3];                /* its mesh: cells per axis (2D: 4 triangles each, 3D: 6
                                    tetrahedra each) [2D 16 x 8, 3D 8 x 4 x 8]             */
    double E_block, rho_block;   /* [1e9 Pa, 2500 kg/m^3]                                     */
    double E_sand, rho_sand;     /* [1e7 Pa, 1600 kg/m^3; nu 0.3, friction angle 30 deg]     */
    double tilt_deg;             /* the block turned about z [20]                             */
    double v0[3];                /* its initial velocity [0.5, -2, 0] m/s                      */
    double gap_m;                /* its lowest corner this far above the bed [half a cell]    */
    double friction;             /* Coulomb coefficient of the block on the sand [0.5]        */
    double contact_stiffness;    /* pn_coupled_desc's (Pa) [0: the library's default]        */
    double contact_distance_m;   /* pn_coupled_desc's dhat (m) [0: the library's default]    */
    double pnet_regularizer;     /* PlasticityNet's w (pn_pnet_desc.regularizer) [0: 1; < 0:
                                    off]                                                        */
} pn_drop_desc;

typedef struct pn_drop {
    pn_mpm_world *w;
    pn_fem_mesh *m;
    pn_coupled *c;
    pn_pnet net;
    pn_real *X;
    int *el;
    double diag;                 /* the block's rest bounding-box diagonal (m)               */
} pn_drop;

PN_EX_UNUSED static void pn_drop_default(pn_drop_desc *d, int dim) {
    memset(d, 0, sizeof *d);
    d->dim = dim, d->res = dim == 2 ? 128 : 32, d->energy = PN_DROP_PNET;
    d->domain_m = dim == 2 ? 1 : 0.5, d->bed_m = dim == 2 ? 0.25 : 0.12;
    d->block_m[0] = dim == 2 ? 0.2 : 0.12, d->block_m[1] = dim == 2 ? 0.1 : 0.06, d->block_m[2] = 0.12;
    d->cells[0] = dim == 2 ? 16 : 8, d->cells[1] = dim == 2 ? 8 : 4, d->cells[2] = 8;
    d->E_block = 1e9, d->rho_block = 2500, d->E_sand = 1e7, d->rho_sand = 1600;
    d->tilt_deg = 20, d->v0[0] = 0.5, d->v0[1] = -2, d->friction = 0.5;
}

PN_EX_UNUSED static void pn_drop_free(pn_drop *s) {
    pn_coupled_destroy(s->c);
    pn_fem_destroy(s->m);
    pn_mpm_destroy(s->w);
    free(s->X);
    free(s->el);
    memset(s, 0, sizeof *s);
}

/* the world (a bed over the whole floor), the block's mesh and their coupling; 0 and why on
   failure (nothing left allocated) */
PN_EX_UNUSED static int pn_drop_create(const pn_drop_desc *d, pn_drop *s, char *why, size_t cap) {
    int dim = d->dim, i;
    double dx = d->domain_m / d->res, fl = PN_EX_WALL_CELLS * dx, a = d->tilt_deg * 3.14159265358979 / 180, lowest = 1e30;
    double ctr[3], gap = d->gap_m > 0 ? d->gap_m : dx / 2;
    const pn_model *model = dim == 2 ? pn_model_sand_2d() : pn_model_sand_3d();
    char w_why[256] = "";
    pn_mpm_desc wd;
    pn_mpm_fill_desc f;
    pn_material_desc md;
    pn_material sand;
    pn_fem_grid g;
    pn_group fg;
    pn_fem_desc fd;
    pn_coupled_desc cd;
    size_t n = 0, nn, ne, k;
    int grp;
    memset(s, 0, sizeof *s);
    memset(&wd, 0, sizeof wd);
    wd.dim = dim;
    for (i = 0; i < dim; ++i) wd.res[i] = d->res;
    wd.dx_m = (pn_real)dx, wd.gravity[1] = (pn_real)-9.81, wd.boundary = PN_BOUNDARY_SEPARATE;
    wd.friction = (pn_real)0.5, wd.wall_cells = PN_EX_WALL_CELLS, wd.clock_s = pn_ex__clock;
    memset(&f, 0, sizeof f);
    f.shape = PN_MPM_FILL_BOX, f.per_axis = 2;
    for (i = 0; i < dim; ++i) f.center_m[i] = (pn_real)(d->domain_m / 2), f.half_extent_m[i] = (pn_real)(d->domain_m / 2 - fl);
    f.center_m[1] = (pn_real)(fl + d->bed_m / 2), f.half_extent_m[1] = (pn_real)(d->bed_m / 2);
    if (pn_mpm_fill_count(&wd, &f, &n, w_why, sizeof w_why) != PN_OK || !n) {
        snprintf(why, cap, "the sand bed: %.200s", w_why);
        return 0;
    }
    wd.max_particles = n;
    if (pn_mpm_create(&wd, &s->w, w_why, sizeof w_why) != PN_OK) {
        snprintf(why, cap, "the world: %.200s", w_why);
        return 0;
    }
    pn_model_material_desc(model, (pn_real)d->E_sand, &md);
    if (pn_material_init(&sand, &md, w_why, sizeof w_why) != PN_OK) {
        snprintf(why, cap, "the sand: %.200s", w_why);
        pn_drop_free(s);
        return 0;
    }
    grp = pn_mpm_add_group(s->w, &sand, (pn_real)d->rho_sand);
    f.group = grp;
    if (grp < 0 || pn_mpm_fill(s->w, &f, NULL) != PN_OK) {
        snprintf(why, cap, "the sand bed: %.200s", pn_mpm_error(s->w));
        pn_drop_free(s);
        return 0;
    }
    if (d->energy == PN_DROP_PNET) {
        pn_pnet_desc nd;
        memset(&nd, 0, sizeof nd);
        nd.energy = model;
        nd.regularizer = (pn_real)d->pnet_regularizer;
        if (pn_pnet_init(&s->net, &nd, &sand, dim, w_why, sizeof w_why) != PN_OK ||
            pn_mpm_group_set_energy(s->w, grp, PN_ENERGY_PNET, &s->net) != PN_OK) {
            snprintf(why, cap, "the sand model: %.100s%.100s", w_why, pn_mpm_error(s->w));
            pn_drop_free(s);
            return 0;
        }
    } else if (pn_mpm_group_set_energy(s->w, grp, d->energy == PN_DROP_DP ? PN_ENERGY_DP : PN_ENERGY_LAGGED, NULL) !=
               PN_OK) {
        snprintf(why, cap, "the sand's energy: %.200s", pn_mpm_error(s->w));
        pn_drop_free(s);
        return 0;
    }
    /* the block: a grid mesh turned by tilt about its centre, its lowest node gap above the bed */
    memset(&g, 0, sizeof g);
    g.dim = dim, g.crossed = 1;
    for (i = 0; i < dim; ++i) g.cells[i] = d->cells[i], g.size_m[i] = (pn_real)d->block_m[i], ctr[i] = d->block_m[i] / 2;
    if (pn_fem_grid_mesh(&g, NULL, NULL, &nn, &ne) != PN_OK || !(s->X = (pn_real *)malloc(sizeof(pn_real) * nn * (size_t)dim)) ||
        !(s->el = (int *)malloc(sizeof(int) * ne * (size_t)(dim + 1))) || pn_fem_grid_mesh(&g, s->X, s->el, &nn, &ne) != PN_OK) {
        snprintf(why, cap, "the block's mesh");
        pn_drop_free(s);
        return 0;
    }
    for (k = 0; k < nn; ++k) {
        pn_real *p = s->X + k * (size_t)dim;
        double x = p[0] - ctr[0], y = p[1] - ctr[1];
        p[0] = (pn_real)(d->domain_m / 2 + cos(a) * x - sin(a) * y);
        p[1] = (pn_real)(sin(a) * x + cos(a) * y);
        if (dim == 3) p[2] = (pn_real)(d->domain_m / 2 + p[2] - ctr[2]);
        if (p[1] < lowest) lowest = p[1];
    }
    for (k = 0; k < nn; ++k) s->X[k * (size_t)dim + 1] += (pn_real)(fl + d->bed_m - dx / 4 + gap - lowest);
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_NEO_HOOKEAN, md.youngs_modulus_pa = (pn_real)d->E_block, md.poisson_ratio = (pn_real)0.3;
    memset(&fg, 0, sizeof fg);
    if (pn_material_init(&fg.material, &md, w_why, sizeof w_why) != PN_OK) {
        snprintf(why, cap, "the block's material: %.200s", w_why);
        pn_drop_free(s);
        return 0;
    }
    fg.density_kg_m3 = (pn_real)d->rho_block;
    memset(&fd, 0, sizeof fd);
    fd.dim = dim, fd.n_nodes = nn, fd.n_elements = ne, fd.rest_m = s->X, fd.elements = s->el;
    fd.groups = &fg, fd.n_groups = 1, fd.gravity[1] = (pn_real)-9.81;
    if (pn_fem_create(&fd, &s->m, why, cap) != PN_OK) {
        pn_drop_free(s);
        return 0;
    }
    for (k = 0; k < nn; ++k)
        for (i = 0; i < dim; ++i) s->m->v[k * (size_t)dim + (size_t)i] = (pn_real)d->v0[i];
    s->diag = 0;
    for (i = 0; i < dim; ++i) s->diag += d->block_m[i] * d->block_m[i];
    s->diag = sqrt(s->diag);
    memset(&cd, 0, sizeof cd);
    cd.friction = (pn_real)d->friction, cd.contact_stiffness = (pn_real)d->contact_stiffness;
    cd.contact_distance_m = (pn_real)d->contact_distance_m;
    if (pn_coupled_create(s->w, s->m, &cd, &s->c, why, cap) != PN_OK) {
        pn_drop_free(s);
        return 0;
    }
    return 1;
}

/* the 2D picture's triangles: the mesh at its positions, 6 reals each, into tri (room for
   n_elems) */
PN_EX_UNUSED static void pn_drop_triangles(const pn_fem_mesh *m, double *tri) {
    size_t e;
    int a;
    for (e = 0; e < m->n_elems; ++e)
        for (a = 0; a < 3; ++a) {
            tri[6 * e + 2 * (size_t)a] = (double)m->x[2 * (size_t)m->elem[3 * e + (size_t)a]];
            tri[6 * e + 2 * (size_t)a + 1] = (double)m->x[2 * (size_t)m->elem[3 * e + (size_t)a] + 1];
        }
}

#endif /* PN_DROP_H */
