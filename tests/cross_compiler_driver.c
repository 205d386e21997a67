/* cross_compiler_driver: steps the sand column of examples/common/pn_example.h a few steps with each
   integrator and energy (2D, and 3D implicit PlasticityNet), the snowball (Neo-Hookean snow,
   Cam-Clay) and the column made of metal (von Mises: the exact energy, the metal network) and
   prints one line per combination: its name and a 64-bit FNV-1a hash of the particle state's
   bytes (x, v, C, F, h).
   tests/cross_compiler.sh builds it with every compiler found and compares the lines: the
   same bits are the claim of plastinet.h's THREADS AND DETERMINISM section.
   Usage: cross_compiler_driver [name-filter]   (a name: dim2_implicit_pnet, ...)
   Build: cc -std=c99 -O2 -ffp-contract=off tests/cross_compiler_driver.c -lm   (also as C++) */
#define PLASTINET_IMPLEMENTATION
#include "../examples/common/pn_example.h"
#include "../models/pn_model_metal_2d.h"
#include "../models/pn_model_metal_nh_2d.h"
#include "../models/pn_model_metal_nh_return_2d.h"

/* -DCC_STEP_SCALE=10: ten times the steps, for a longer look by hand */
#ifndef CC_STEP_SCALE
#define CC_STEP_SCALE 1
#endif

typedef struct cc_combo {
    const char *name;
    pn_ex_scene_kind scene;
    int metal; /* 0: the scene's material; 1: metal_2d (StVK-Hencky), 2: metal_nh_2d
                  (Neo-Hookean, learned return mapping) */
    int dim, implicit;
    pn_energy energy;
    double dt;
    long steps;
} cc_combo;

/* Implicit at the examples' dt 1e-3 s, explicit at 1e-4 s (CFL); enough steps for every
   material to yield somewhere, so the return mappings and plastic energies run. The 3D worlds
   are the examples' on a coarser grid (16 cells) to keep the run short. */
static const cc_combo combos[] = {
    {"sand_dim2_implicit_pnet", PN_EX_SAND_COLUMN, 0, 2, 1, PN_ENERGY_PNET, 1e-3, 8},
    {"sand_dim2_implicit_lagged", PN_EX_SAND_COLUMN, 0, 2, 1, PN_ENERGY_LAGGED, 1e-3, 8},
    {"sand_dim2_implicit_dp", PN_EX_SAND_COLUMN, 0, 2, 1, PN_ENERGY_DP, 1e-3, 8},
    {"sand_dim2_implicit_elastic", PN_EX_SAND_COLUMN, 0, 2, 1, PN_ENERGY_ELASTIC, 1e-3, 4},
    {"sand_dim2_explicit", PN_EX_SAND_COLUMN, 0, 2, 0, PN_ENERGY_PNET, 1e-4, 40},
    {"sand_dim3_implicit_pnet", PN_EX_SAND_COLUMN, 0, 3, 1, PN_ENERGY_PNET, 1e-3, 3},
    {"sand_dim3_explicit", PN_EX_SAND_COLUMN, 0, 3, 0, PN_ENERGY_PNET, 1e-4, 10},
    {"snow_dim2_implicit_pnet", PN_EX_SNOWBALL, 0, 2, 1, PN_ENERGY_PNET, 1e-3, 60},
    {"snow_dim2_implicit_lagged", PN_EX_SNOWBALL, 0, 2, 1, PN_ENERGY_LAGGED, 1e-3, 60},
    {"snow_dim2_explicit", PN_EX_SNOWBALL, 0, 2, 0, PN_ENERGY_PNET, 2e-4, 300},
    {"snow_dim3_implicit_pnet", PN_EX_SNOWBALL, 0, 3, 1, PN_ENERGY_PNET, 1e-3, 40},
    {"metal_dim2_implicit_exact_vm", PN_EX_SAND_COLUMN, 1, 2, 1, PN_ENERGY_EXACT_VM, 1e-3, 30},
    {"metal_dim2_implicit_pnet", PN_EX_SAND_COLUMN, 1, 2, 1, PN_ENERGY_PNET, 1e-3, 30},
    {"metal_dim2_explicit", PN_EX_SAND_COLUMN, 1, 2, 0, PN_ENERGY_DEFAULT, 1e-4, 150},
    {"metal_nh_dim2_implicit_pnet", PN_EX_SAND_COLUMN, 2, 2, 1, PN_ENERGY_PNET, 1e-3, 30},
    {"metal_nh_dim2_explicit", PN_EX_SAND_COLUMN, 2, 2, 0, PN_ENERGY_DEFAULT, 1e-4, 150},
};

/* The material a model was trained for, at Young's modulus E (pn_model_material, spelt out
   with pn_material_init so this driver does not follow that function's signature). */
static pn_result cc_model_material(const pn_model *mo, double E, pn_material *m) {
    pn_material_desc d;
    memset(&d, 0, sizeof d);
    d.elastic = mo->elastic;
    d.plastic = mo->plastic;
    d.youngs_modulus_pa = (pn_real)E;
    d.poisson_ratio = (pn_real)mo->poisson_ratio;
    d.yield_stress_pa = (pn_real)(mo->yield_stress_ratio * E);
    d.hardening_modulus_pa = (pn_real)(mo->hardening_ratio * E);
    return pn_material_init(m, &d, NULL, 0);
}

static unsigned long long cc_hash(unsigned long long h, const void *p, size_t n) {
    const unsigned char *b = (const unsigned char *)p;
    size_t i;
    for (i = 0; i < n; ++i) {
        h ^= b[i];
        h *= 1099511628211ULL;
    }
    return h;
}

int main(int argc, char **argv) {
    size_t k;
    int failed = 0;
    for (k = 0; k < sizeof combos / sizeof combos[0]; ++k) {
        const cc_combo *c = &combos[k];
        pn_ex_scene sc;
        pn_mpm_world *w = NULL;
        pn_mpm_implicit_desc id;
        pn_ex_tally t;
        char why[256] = "";
        unsigned long long h = 14695981039346656037ULL;
        size_t n, d;
        pn_result r;
        if (argc > 1 && !strstr(c->name, argv[1])) continue;
        pn_ex_scene_default(&sc, c->scene, c->dim);
        if (c->dim == 3) sc.res = 16;
        sc.energy = c->metal ? PN_ENERGY_DEFAULT : c->energy;
        memset(&id, 0, sizeof id);
        memset(&t, 0, sizeof t);
        id.fixed_point_iters = 1;
        id.contact_rounds = 1;
        r = pn_ex_scene_create(&sc, &w, why, sizeof why);
        if (r == PN_OK && c->metal) {
            /* the column's geometry, a metal soft enough (E = 1e5 Pa, yield stress 300 Pa) to
               yield under its weight: group 0's material swapped before the first step */
            const pn_model *mo = c->metal == 1 ? pn_model_metal_2d() : pn_model_metal_nh_2d();
            pn_material m;
            r = cc_model_material(mo, 1e5, &m);
            if (r == PN_OK) w->groups[0].material = m;
            if (r == PN_OK && c->energy == PN_ENERGY_PNET) {
                pn_pnet net;
                pn_pnet_desc nd;
                memset(&nd, 0, sizeof nd);
                nd.energy = mo;
                if (c->metal == 2) nd.return_map = pn_model_metal_nh_return_2d(); /* learned return */
                r = pn_pnet_init(&net, &nd, &m, c->dim, why, sizeof why);
                if (r == PN_OK) r = pn_mpm_group_set_energy(w, 0, PN_ENERGY_PNET, &net);
            } else if (r == PN_OK) {
                r = pn_mpm_group_set_energy(w, 0, c->energy, NULL);
            }
        }
        if (r == PN_OK) r = pn_ex_steps(w, c->implicit, c->dt, &id, c->steps * CC_STEP_SCALE, &t);
        if (r != PN_OK) {
            printf("%s error %s %s\n", c->name, pn_result_string(r), why);
            failed = 1;
            pn_mpm_destroy(w);
            continue;
        }
        n = w->n;
        d = (size_t)w->dim;
        h = cc_hash(h, w->x, sizeof(pn_real) * n * d);
        h = cc_hash(h, w->v, sizeof(pn_real) * n * d);
        h = cc_hash(h, w->C, sizeof(pn_real) * n * d * d);
        h = cc_hash(h, w->F, sizeof(pn_real) * n * d * d);
        h = cc_hash(h, w->h, sizeof(pn_real) * n);
        /* x[0] as a hex float: a readable witness of how far two builds drifted apart */
        printf("%s %016llx steps %ld newton %ld cg %ld x0 %a\n", c->name, h, t.steps, t.newton, t.cg,
               (double)w->x[0]);
        pn_mpm_destroy(w);
    }
    return failed;
}
