/* fuzz_gmsh.c - the Gmsh .msh loader (pn_fem_parse_msh: ASCII 2.2 and 4.1) on arbitrary
   bytes, read as a 2D file (triangles) and as a 3D file (tetrahedra); a mesh that parses goes
   on to pn_fem_create and one explicit step (fuzz_mesh.h). Seeds: corpus/gmsh/. */
#define PLASTINET_IMPLEMENTATION
#include "../../plastinet.h"
#include "../../plastinet_mpm.h"
#include "fuzz_mesh.h"

#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    int dim;
    if (size > PN_FUZZ_MAX_INPUT) return 0;
    for (dim = 2; dim <= 3; ++dim) {
        pn_fem_mesh_data d;
        char why[256];
        pn_result r = pn_fem_parse_msh((const char *)data, size, dim, NULL, &d, why, sizeof why);
        if (r == PN_OK) {
            pn_fuzz_use_mesh(&d, dim);
            pn_fem_mesh_data_free(&d, NULL);
        } else if (d.nodes || d.elements || d.element_tags || (r == PN_ERROR_FORMAT && !why[0])) {
            abort(); /* a refusal allocates nothing and says why */
        }
    }
    return 0;
}
