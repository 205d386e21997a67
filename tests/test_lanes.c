/* The float lanes of plastinet.h's learned models (test_pnet_lanes.c) alone: tests/run.sh
   builds this with -march=native (8-lane vectors on AVX and up) and with
   -DPN_NO_VECTOR_EXTENSIONS (the plain-struct path of compilers without vector types); the
   4-lane default is in test_main. Only plastinet.h (not plastinet_mpm.h): a small build.
   Run: build/test_lanes_native [name-filter]     last line: N passed, N failed */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "pn_test.h"
#include "test_util.h"

/* the t_pn_ helpers and what they use; of these files' tests only the lanes run here */
#include "test_energy.c"
#include "test_pnet_mlp.c"
#include "test_pnet_energy.c"
#include "test_pnet_props.c"
#include "test_pnet_return.c"
#include "test_pnet_lanes.c" /* pn_tests_pnet_lanes */

int main(int argc, char **argv) {
    int passed = 0, failed = 0;
    pn_test_run(pn_tests_pnet_lanes, (int)(sizeof pn_tests_pnet_lanes / sizeof pn_tests_pnet_lanes[0]),
                argc > 1 ? argv[1] : NULL, &passed, &failed);
    (void)pn_tests_energy, (void)pn_tests_pnet_mlp, (void)pn_tests_pnet_energy;
    (void)pn_tests_pnet_props, (void)pn_tests_pnet_return;
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
