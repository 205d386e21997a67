/* fuzz_mesh.h - what the loader targets (fuzz_gmsh.c, fuzz_tetgen.c) do with a mesh that
   parsed: the loader's promises checked (indices in range, tags and arrays present), then
   pn_fem_create on it and, for a small mesh it takes, its energy, stable step and one
   explicit step. A broken promise aborts, so the fuzzer reports it. Include after the
   plastinet headers. */
#ifndef PN_FUZZ_MESH_H
#define PN_FUZZ_MESH_H

#include <stdlib.h>

#define PN_FUZZ_MAX_INPUT 16384 /* bytes: longer inputs are skipped (bounded cost per input) */
#define PN_FUZZ_STEP_MAX_ELEMENTS 256 /* step only meshes this small                       */

static void pn_fuzz_use_mesh(const pn_fem_mesh_data *d, int dim) {
    pn_fem_desc fd;
    pn_group grp;
    pn_material_desc md;
    pn_fem_mesh *m = NULL;
    char why[256];
    size_t k;
    if (d->dim != dim || !d->n_nodes || !d->n_elements || !d->nodes || !d->elements || !d->element_tags) abort();
    if (d->order != 1 && d->order != 2) abort();
    for (k = 0; k < d->n_elements * (size_t)(d->order == 2 ? (dim + 1) * (dim + 2) / 2 : dim + 1); ++k)
        if (d->elements[k] < 0 || (size_t)d->elements[k] >= d->n_nodes) abort();
    memset(&md, 0, sizeof md);
    md.elastic = PN_ELASTIC_NEO_HOOKEAN, md.youngs_modulus_pa = 1e6, md.poisson_ratio = (pn_real)0.3;
    memset(&grp, 0, sizeof grp);
    if (pn_material_init(&grp.material, &md, NULL, 0) != PN_OK) abort();
    grp.density_kg_m3 = 1000;
    memset(&fd, 0, sizeof fd);
    fd.dim = dim, fd.n_nodes = d->n_nodes, fd.n_elements = d->n_elements, fd.rest_m = d->nodes, fd.elements = d->elements;
    fd.groups = &grp, fd.n_groups = 1, fd.gravity[1] = (pn_real)-9.81, fd.order = d->order;
    why[0] = 0;
    if (pn_fem_create(&fd, &m, why, sizeof why) != PN_OK) {
        if (m) abort(); /* all or nothing */
        return;
    }
    if (d->n_elements <= PN_FUZZ_STEP_MAX_ELEMENTS) {
        pn_real el = 0, kin = 0, dt = 0;
        pn_fem_stats st;
        (void)pn_fem_energy(m, &el, &kin);
        if (pn_fem_stable_dt(m, &dt) == PN_OK && dt > 0) (void)pn_fem_step_explicit(m, dt / 2, &st);
    }
    pn_fem_destroy(m);
}

#endif
