/* Compile-configuration check: built by tests/run.sh as C99 and C++11 under gcc and clang
   with -Wall -Wextra -Werror -pedantic, with PLASTINET_STATIC, PN_REAL=float, PN_NO_STDIO,
   PN_NO_2D and PN_NO_3D. It touches every public function once and checks loose sanity
   (loose so that the float build passes too); the real tests are in test_main.c.
   compile_check_tu2.c includes the header without the implementation and links with this
   file (except under PLASTINET_STATIC), which checks the extern declarations. */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../models/pn_models.h" /* every generated header, in every configuration */
#include "../plastinet_mpm.h"
#include "../plastinet_rom.h"
#include <math.h>
#include <stdio.h>
#include <string.h>

int pn_check_second_tu(void); /* compile_check_tu2.c */

static int failures = 0;
#define CHECK(c)                                                                            \
    do {                                                                                    \
        if (!(c)) {                                                                         \
            printf("compile_check: %s:%d: %s\n", __FILE__, __LINE__, #c);                   \
            failures++;                                                                     \
        }                                                                                   \
    } while (0)

static void smoke(int d) {
    pn_material_desc desc;
    pn_material m;
    char why[256] = "";
    pn_real F[9], U[9] = {0}, s[3] = {0}, V[9], R[9], S[9] = {0}, E[9], Z[9], T[9] = {0}, G[9] = {0};
    pn_real P[9] = {0}, H[81], psi = 0, h = 0, hg = 0, y = 0, sc = 1;
    pn_real Fi[9] = {0}, I[9];
    int i, j;
    for (i = 0; i < d; ++i)
        for (j = 0; j < d; ++j) F[i * d + j] = (pn_real)((i == j ? 1.1 : 0.0) + 0.05 * (i + 2 * j));
    CHECK(pn_svd(d, F, U, s, V) == PN_OK);
    CHECK(s[0] >= s[d - 1] && s[d - 1] > 0);
    CHECK(fabs((double)(pn_mat_det(d, U) - 1)) < 1e-5);
    CHECK(pn_polar(d, F, R, S) == PN_OK);
    CHECK(pn_hencky_strain(d, F, E) == PN_OK);
    CHECK(pn_mat_inverse(d, F, Fi) == PN_OK);
    pn_mat_mul(d, F, Fi, I);
    CHECK(fabs((double)(I[0] - 1)) < 1e-5);
    CHECK(pn_sym_eigen(d, S, U, s) == PN_OK);
    CHECK(pn_sym_project_psd(d, S) == PN_OK);
    memset(&desc, 0, sizeof desc);
    desc.plastic = PN_PLASTIC_VON_MISES;
    desc.youngs_modulus_pa = 1000;
    desc.poisson_ratio = (pn_real)0.3;
    desc.yield_stress_pa = 10;
    CHECK(pn_material_init(&m, &desc, why, sizeof why) == PN_OK);
    CHECK(pn_elastic_energy(&m, d, F, 0, &psi, P, H, PN_EVAL_PROJECT_PSD) == PN_OK && psi > 0);
    CHECK(pn_kirchhoff_stress(&m, d, F, 0, S) == PN_OK);
    CHECK(pn_return_map(&m, d, F, 0, Z, &h, T) == PN_OK && h > 0);
    CHECK(pn_yield_function(&m, d, Z, h, &y, &sc) == PN_OK && fabs((double)(y / sc)) < 1e-4);
    CHECK(pn_von_mises_energy(&m, d, F, 0, &psi, P, H, 0) == PN_OK);
    CHECK(pn_lagged_prepare(&m, d, F, 0, G, &hg) == PN_OK);
    CHECK(pn_lagged_energy(&m, d, F, G, hg, &psi, P, H, 0) == PN_OK);
    for (i = 0; i < d * d; ++i) CHECK(fabs((double)(P[i] - T[i])) <= 1e-4 * fabs((double)T[0]) + 1e-3);
    desc.youngs_modulus_pa = -1;
    CHECK(pn_material_init(&m, &desc, why, sizeof why) == PN_ERROR_INVALID_PARAMETER && why[0] != 0);
    F[0] = (pn_real)NAN;
    CHECK(pn_svd(d, F, U, s, V) == PN_ERROR_NONFINITE);
}

/* Every shipped model: checked, bound to its material and evaluated once (or refused with
   PN_ERROR_DIMENSION when its dimension is compiled out). */
static void smoke_models(void) {
    int k, i;
    for (k = 0; pn_models_all[k]; ++k) {
        const pn_model *mo = pn_models_all[k]();
        pn_material m;
        pn_real F[9] = {0}, T[9] = {0}, P[9] = {0}, H[81], psi = 0, hn = 0;
        char why[256] = "";
        int d = mo->dim, ok_dim;
#if defined(PN_NO_2D)
        ok_dim = d != 2;
#elif defined(PN_NO_3D)
        ok_dim = d != 3;
#else
        ok_dim = 1;
#endif
        CHECK(pn_model_check(mo, 0, why, sizeof why) == (ok_dim ? PN_OK : PN_ERROR_DIMENSION));
        if (!ok_dim) continue;
        CHECK(pn_model_material(mo, 1e6, &m, NULL, 0) == PN_OK);
        if (mo->n_params) { /* a conditioned model: another material inside its ranges */
            pn_material_desc md;
            pn_model_material_desc(mo, 1e6, &md);
            for (i = 0; i < mo->n_params; ++i) pn_model_param_set(&md, mo->param[i].kind, mo->param[i].hi);
            CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
        }
        for (i = 0; i < d; ++i) F[i * d + i] = (pn_real)(1 + 0.05 * i);
        F[1] = (pn_real)0.02;
        if (mo->kind == PN_MODEL_RETURN_MAP) {
            CHECK(pn_learned_return_map(mo, &m, d, F, 0, NULL, &hn, T) == PN_OK && hn >= 0);
        } else {
            pn_pnet net;
            pn_pnet_desc nd;
            pn_pnet_point pt;
            int j;
            memset(&nd, 0, sizeof nd);
            memset(&net, 0, sizeof net);
            memset(&pt, 0, sizeof pt);
            nd.energy = mo;
            for (j = 0; mo->return_map && pn_models_all[j]; ++j)
                if (!strcmp(pn_models_all[j]()->name, mo->return_map)) nd.return_map = pn_models_all[j]();
            CHECK(pn_pnet_init(&net, &nd, &m, d, why, sizeof why) == PN_OK);
            CHECK(pn_pnet_prepare(&net, F, (pn_real)mo->h_min, &pt, &hn, T) == PN_OK);
            CHECK(pn_pnet_energy(&net, &pt, F, &psi, P, H, PN_EVAL_PROJECT_PSD) == PN_OK);
            for (i = 0; i < d * d; ++i) /* exact at F0 (Eq. 8) */
                CHECK(fabs((double)(P[i] - T[i])) <= 1e-3 * (1 + fabs((double)T[i])) * 1e6);
            { /* the same point in lanes */
                const pn_pnet_point *pp = &pt;
                pn_pnet_point pl;
                pn_real hh = (pn_real)mo->h_min, P2[9];
                pn_result st;
                CHECK(pn_pnet_prepare_lanes(&net, 1, F, &hh, &pl, &st) == PN_OK);
                CHECK(pn_pnet_energy_lanes(&net, 1, &pp, F, &psi, P2, NULL, 0, &st) == PN_OK);
                for (i = 0; i < d * d; ++i) CHECK(fabs((double)(P2[i] - P[i])) <= 1e-3 * (1 + fabs((double)P[i])) * 1e6);
            }
        }
    }
    {
        pn_real in[PN_MLP_MAX_WIDTH] = {0}, out = 0, g[2], h[4]; /* as many inputs as any network has */
        float inl[PN_MLP_MAX_WIDTH * PN_MLP_LANES] = {0}, outl[PN_MLP_LANES];
        CHECK(pn_mlp_eval(&pn_models_all[0]()->mlp, in, 0, &out, g, h) != PN_ERROR_NONFINITE);
        CHECK(pn_mlp_eval_lanes(&pn_models_all[0]()->mlp, 1, inl, 0, outl, NULL, NULL) != PN_ERROR_NONFINITE);
    }
}

/* The MPM solver: a few explicit steps of a small sand block. */
static void smoke_mpm(int d) {
    pn_mpm_desc wd;
    pn_mpm_world *w = NULL;
    pn_material_desc md;
    pn_material m;
    pn_mpm_stats st;
    pn_real x[3] = {(pn_real)0.5, (pn_real)0.5, (pn_real)0.5}, mass = 0, mom[3];
    int g, k;
    memset(&wd, 0, sizeof wd);
    wd.dim = d;
    wd.res[0] = wd.res[1] = wd.res[2] = 16;
    wd.dx_m = (pn_real)(1.0 / 16);
    wd.gravity[1] = (pn_real)-9.81;
    wd.max_particles = 4;
    CHECK(pn_mpm_create(&wd, &w, NULL, 0) == PN_OK);
    if (!w) return;
    memset(&md, 0, sizeof md);
    md.plastic = PN_PLASTIC_DRUCKER_PRAGER;
    md.youngs_modulus_pa = 1e4;
    md.poisson_ratio = (pn_real)0.3;
    md.friction_angle_deg = 30;
    CHECK(pn_material_init(&m, &md, NULL, 0) == PN_OK);
    g = pn_mpm_add_group(w, &m, 1000);
    CHECK(pn_mpm_add_particles(w, g, 1, x, NULL, (pn_real)1e-4) == PN_OK);
    {
        pn_real h0 = 0;
        pn_collider c;
        memset(&c, 0, sizeof c);
        c.shape = PN_SHAPE_HALF_SPACE;
        c.boundary = PN_BOUNDARY_SEPARATE;
        c.center_m[1] = (pn_real)0.25;
        c.normal[1] = 1;
        CHECK(pn_mpm_set_state(w, 0, 1, &h0) == PN_OK);
        CHECK(pn_mpm_add_collider(w, &c, NULL) == PN_OK);
    }
    for (k = 0; k < 3; ++k) CHECK(pn_mpm_step_explicit(w, (pn_real)1e-3, &st) == PN_OK);
    { /* the scene helpers and the frame stepper */
        pn_mpm_fill_desc f;
        pn_real dt = 0, at[3] = {(pn_real)0.3, (pn_real)0.3, (pn_real)0.3};
        size_t n = 0;
        char why[256] = "";
        memset(&f, 0, sizeof f);
        f.shape = PN_MPM_FILL_SPHERE;
        f.center_m[0] = f.center_m[1] = f.center_m[2] = (pn_real)0.5;
        f.radius_m = (pn_real)0.01;
        f.group = g;
        CHECK(pn_mpm_fill_count(&w->desc, &f, &n, why, sizeof why) == PN_OK && n == 0);
        CHECK(pn_mpm_fill(w, &f, &n) == PN_OK && n == 0);
        CHECK(pn_mpm_stable_dt(w, &dt) == PN_OK && dt > 0);
        CHECK(pn_mpm_advance(w, (pn_real)1e-3, NULL, &st) == PN_OK && pn_mpm_error(w)[0] == 0);
        CHECK(pn_mpm_move_collider(w, 0, at, NULL) == PN_OK);
        CHECK(pn_material_check(&m, why, sizeof why) == PN_OK);
    }
    CHECK(pn_mpm_group_set_energy(w, g, PN_ENERGY_LAGGED, NULL) == PN_OK);
    CHECK(pn_mpm_step_implicit(w, (pn_real)1e-3, NULL, &st) == PN_OK);
    pn_mpm_totals(w, &mass, mom);
    CHECK(mass > 0 && mom[1] < 0);
    { /* driven particles and loads */
        pn_real lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1}, f[3] = {0, 1, 0}, v[3] = {0, 0, 0};
        size_t sel[4], cnt = 0;
        int di = -1, li = -1;
        CHECK(pn_mpm_select_box(w, lo, hi, sel, 4, &cnt) == PN_OK && cnt == 1);
        CHECK(pn_mpm_set_particles(w, 0, 1, NULL, v, NULL, NULL, -1) == PN_OK);
        CHECK(pn_mpm_add_load(w, cnt, sel, f, (pn_real)1e-3, &li) == PN_OK);
        CHECK(pn_mpm_drive_particles(w, cnt, sel, v, NULL, NULL, &di) == PN_OK);
        CHECK(pn_mpm_step_explicit(w, (pn_real)1e-3, &st) == PN_OK);
        CHECK(pn_mpm_release_drive(w, di) == PN_OK && pn_mpm_remove_load(w, li) == PN_OK);
    }
    pn_mpm_destroy(w);
}

/* The reduced-order world on the affine map: a few points, a drive, a load, both
   quadratures, the implicit step, and the reconstruction (also by an embedding). */
static void smoke_rom(int d) {
    pn_rom_model am;
    pn_rom_desc desc;
    pn_rom_world *w = NULL;
    pn_rom_region r;
    pn_rom_stats st;
    double X[8 * 3], x[8 * 3], lat[12] = {0}, f[3] = {0, 0, 0};
    float Xf[3] = {0.5f, 0.5f, 0.5f}, xf[3 * 8];
    char why[128];
    int i, q;
    for (i = 0; i < 8 * d; ++i) X[i] = 0.45 + 0.05 * ((i / d) >> (i % d) & 1);
    pn_rom_affine_model(d, &am);
    CHECK(pn_rom_model_check(&am, why, sizeof why) == PN_OK);
    CHECK(pn_rom_inside(&am, X) == 1 && pn_rom_lattice(&am, 1, NULL, 0) == 0);
    CHECK(pn_rom_eval(&am, lat, 8, X, x, NULL, NULL) == PN_OK && fabs(x[0] - X[0]) < 1e-12);
    memset(&desc, 0, sizeof desc);
    desc.model = &am, desc.points = X, desc.n_points = 8, desc.point_volume_m3 = 1e-4, desc.dx_m = 0.1, desc.samples = -1;
    for (q = 0; q < 3; ++q) {
        pn_rom_embedding *e = NULL;
        desc.quadrature = q ? PN_ROM_LAGRANGIAN : PN_ROM_EULERIAN;
        desc.integrator = q == 2 ? PN_ROM_BDF2 : PN_ROM_EXPLICIT;
        CHECK(pn_rom_create(&desc, &w, why, sizeof why) == PN_OK);
        if (!w) return;
        memset(&r, 0, sizeof r);
        r.lo[0] = r.lo[1] = r.lo[2] = 0, r.hi[0] = r.hi[1] = r.hi[2] = 0.46;
        CHECK(pn_rom_drive(w, &r, NULL, NULL, NULL, &i) == PN_OK && pn_rom_release_drive(w, i) == PN_OK);
        CHECK(pn_rom_add_load(w, &r, f, 0, &i) == PN_OK && pn_rom_remove_load(w, i) == PN_OK);
        CHECK(pn_rom_set_latent(w, lat, NULL) == PN_OK && pn_rom_fit(w, X, NULL, NULL) == PN_OK);
        CHECK(pn_rom_step(w, 1e-4, &st) == PN_OK && pn_rom_error(w)[0] == 0);
        CHECK(pn_rom_positions(w, 0, 8, xf, NULL) == PN_OK && pn_rom_map(w, 1, Xf, xf, NULL) == PN_OK);
        CHECK(pn_rom_embed(w, 1, Xf, 0.1, &e) == PN_OK && pn_rom_embed_positions(w, e, xf) == PN_OK);
        pn_rom_embed_destroy(e);
        pn_rom_destroy(w);
        w = NULL;
    }
}

#ifndef PN_NO_FEM
/* FEM: a square of two triangles (or a cube of six tetrahedra) on a floor, explicit and
   implicit steps. */
static void smoke_fem(int d) {
    pn_fem_grid g;
    pn_group grp;
    pn_fem_desc fd;
    pn_fem_mesh *m = NULL;
    pn_material_desc md;
    pn_collider c;
    pn_fem_stats st;
    pn_real X[8 * 3], dt = 0, el_j = 0, kin_j = 0;
    int el[6 * 4], fix = 0;
    size_t nn = 0, ne = 0;
    char why[128];
    memset(&g, 0, sizeof g);
    g.dim = d, g.cells[0] = g.cells[1] = g.cells[2] = 1;
    g.lo_m[1] = (pn_real)0.01, g.size_m[0] = g.size_m[1] = g.size_m[2] = (pn_real)0.1;
    CHECK(pn_fem_grid_mesh(&g, X, el, &nn, &ne) == PN_OK && nn == (size_t)(1 << d));
    memset(&md, 0, sizeof md);
    md.youngs_modulus_pa = 1e5;
    md.poisson_ratio = (pn_real)0.3;
    memset(&grp, 0, sizeof grp);
    CHECK(pn_material_init(&grp.material, &md, NULL, 0) == PN_OK);
    grp.density_kg_m3 = 1000;
    memset(&fd, 0, sizeof fd);
    fd.dim = d, fd.n_nodes = nn, fd.n_elements = ne, fd.rest_m = X, fd.elements = el, fd.groups = &grp, fd.n_groups = 1;
    fd.gravity[1] = (pn_real)-9.81;
    CHECK(pn_fem_create(&fd, &m, why, sizeof why) == PN_OK);
    if (!m) return;
    memset(&c, 0, sizeof c);
    c.shape = PN_SHAPE_HALF_SPACE, c.normal[1] = 1;
    CHECK(pn_fem_add_obstacle(m, &c, NULL) == PN_OK);
    CHECK(pn_fem_group_set_energy(m, 0, PN_ENERGY_ELASTIC, NULL) == PN_OK);
    CHECK(pn_fem_stable_dt(m, &dt) == PN_OK && dt > 0);
    CHECK(pn_fem_step_explicit(m, dt / 2, &st) == PN_OK);
    CHECK(pn_fem_step_implicit(m, (pn_real)1e-3, NULL, &st) == PN_OK && pn_fem_error(m)[0] == 0);
    CHECK(pn_fem_fix_nodes(m, 1, &fix, NULL) == PN_OK);
    {
        static const pn_real centre[3] = {0, 0, 0}, spin[3] = {0, 0, 1};
        CHECK(pn_fem_spin_nodes(m, 1, &fix, centre, spin) == PN_OK && pn_fem_release_nodes(m, 1, &fix) == PN_OK);
    }
    CHECK(pn_fem_energy(m, &el_j, &kin_j) == PN_OK && kin_j > 0);
    { /* coupled to a world of sand below it */
        pn_mpm_desc wd;
        pn_mpm_world *w = NULL;
        pn_mpm_fill_desc f;
        pn_material sand;
        pn_coupled *cp = NULL;
        pn_coupled_stats cs;
        pn_real cdt = 0, dist = 0;
        int i;
        memset(&wd, 0, sizeof wd);
        wd.dim = d, wd.dx_m = (pn_real)0.02, wd.max_particles = 4096, wd.gravity[1] = (pn_real)-9.81;
        for (i = 0; i < d; ++i) wd.res[i] = 20, wd.origin_m[i] = (pn_real)-0.2; /* the mesh within the walls */
        CHECK(pn_mpm_create(&wd, &w, NULL, 0) == PN_OK);
        md.plastic = PN_PLASTIC_DRUCKER_PRAGER, md.elastic = PN_ELASTIC_STVK_HENCKY;
        CHECK(pn_material_init(&sand, &md, NULL, 0) == PN_OK);
        memset(&f, 0, sizeof f);
        f.shape = PN_MPM_FILL_BOX, f.group = pn_mpm_add_group(w, &sand, 1600);
        for (i = 0; i < d; ++i) f.center_m[i] = (pn_real)0.05, f.half_extent_m[i] = (pn_real)0.05;
        f.center_m[1] = (pn_real)-0.05, f.half_extent_m[1] = (pn_real)0.04;
        CHECK(w && pn_mpm_fill(w, &f, NULL) == PN_OK);
        CHECK(pn_coupled_create(w, m, NULL, &cp, why, sizeof why) == PN_OK);
        CHECK(pn_coupled_stable_dt(cp, &cdt) == PN_OK && cdt > 0);
        CHECK(pn_coupled_step_explicit(cp, cdt / 2, &cs) == PN_OK);
        CHECK(pn_coupled_step_implicit(cp, (pn_real)1e-3, NULL, &cs) == PN_OK && pn_coupled_error(cp)[0] == 0);
        CHECK(pn_coupled_min_distance(cp, &dist) == PN_OK && dist > 0);
        pn_coupled_destroy(cp);
        pn_mpm_destroy(w);
    }
    pn_fem_destroy(m);
    { /* the loaders */
        static const char msh[] = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n"
                                  "$Elements\n1\n1 4 0 1 2 3 4\n$EndElements\n";
        static const char node[] = "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n", ele[] = "1 4 0\n1 1 2 3 4\n";
        pn_fem_mesh_data md2;
        CHECK(pn_fem_parse_msh(msh, sizeof msh - 1, d, NULL, &md2, why, sizeof why) == (d == 3 ? PN_OK : PN_ERROR_FORMAT));
        pn_fem_mesh_data_free(&md2, NULL);
        if (d == 3) {
            CHECK(pn_fem_parse_tetgen(node, sizeof node - 1, ele, sizeof ele - 1, NULL, &md2, why, sizeof why) == PN_OK);
            pn_fem_mesh_data_free(&md2, NULL);
        }
    }
}
#else /* PN_NO_FEM: FEM and coupling are left out; only the MPM and ROM parts build */
static void smoke_fem(int d) { (void)d; }
#endif

int main(void) {
    char buf[256];
    pn_material m;
    pn_material_desc desc;
    memset(&desc, 0, sizeof desc);
    desc.youngs_modulus_pa = 1;
    CHECK(pn_material_init(&m, &desc, NULL, 0) == PN_OK);
#ifndef PN_NO_STDIO
    CHECK(pn_material_describe(&m, buf, sizeof buf) > 0);
#else
    buf[0] = 0;
    (void)buf;
#endif
    CHECK(strlen(pn_result_string(PN_ERROR_INVERTED)) > 0);
    CHECK(pn_elastic_model_from_name(pn_elastic_model_name(PN_ELASTIC_STVK_HENCKY)) ==
          (int)PN_ELASTIC_STVK_HENCKY);
    CHECK(pn_plastic_model_from_name("cam_clay") == (int)PN_PLASTIC_CAM_CLAY);
    {
        void *p = pn_alloc(NULL, 16);
        CHECK(p != NULL);
        pn_free(NULL, p);
    }
#ifndef PN_NO_2D
    smoke_mpm(2);
    smoke_fem(2);
#else
    smoke_mpm(3);
#endif
#ifndef PN_NO_3D
    smoke_rom(3);
#else
    smoke_rom(2);
#endif
#ifndef PN_NO_3D
    smoke_fem(3);
#endif
#ifndef PN_NO_2D
    smoke(2);
#else
    {
        pn_real F[4] = {1, 0, 0, 1}, U[4], s[2], V[4];
        CHECK(pn_svd(2, F, U, s, V) == PN_ERROR_DIMENSION);
    }
#endif
#ifndef PN_NO_3D
    smoke(3);
#else
    {
        pn_real F[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, U[9], s[3], V[9];
        CHECK(pn_svd(3, F, U, s, V) == PN_ERROR_DIMENSION);
    }
#endif
    smoke_models();
#ifndef PLASTINET_STATIC
    CHECK(pn_check_second_tu() == 1);
#endif
    printf("compile_check: %s\n", failures ? "FAILED" : "ok");
    return failures ? 1 : 0;
}
