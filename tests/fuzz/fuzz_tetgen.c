/* fuzz_tetgen.c - the TetGen loader (pn_fem_parse_tetgen) on arbitrary bytes: the input up to
   its first NUL byte is the .node file, the rest the .ele file (no NUL: all of it is the
   .node file and the .ele file is empty). A mesh that parses goes on to pn_fem_create and one
   explicit step (fuzz_mesh.h). Seeds: corpus/tetgen/. */
#define PLASTINET_IMPLEMENTATION
#include "../../plastinet.h"
#include "../../plastinet_mpm.h"
#include "fuzz_mesh.h"

#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    pn_fem_mesh_data d;
    char why[256];
    const char *text = (const char *)data, *sep;
    size_t node_len = size, ele_len = 0;
    pn_result r;
    if (size > PN_FUZZ_MAX_INPUT) return 0;
    sep = size ? (const char *)memchr(text, 0, size) : NULL;
    if (sep) node_len = (size_t)(sep - text), ele_len = size - node_len - 1;
    r = pn_fem_parse_tetgen(text, node_len, sep ? sep + 1 : NULL, ele_len, NULL, &d, why, sizeof why);
    if (r == PN_OK) {
        pn_fuzz_use_mesh(&d, 3);
        pn_fem_mesh_data_free(&d, NULL);
    } else if (d.nodes || d.elements || d.element_tags || (r == PN_ERROR_FORMAT && !why[0])) {
        abort(); /* a refusal allocates nothing and says why */
    }
    return 0;
}
