/* The one test binary: every unit, property and driver test of plastinet.
   Build: cc -std=c99 -O2 -Wall -Wextra -pedantic tests/test_main.c -lm -o build/test_main
          (add -DPN_TEST_HAVE_MODELS to test the models of models/pn_models.h, as tests/run.sh does)
   Run:   build/test_main [name-filter]          last line: N passed, N failed */
#define PLASTINET_IMPLEMENTATION
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "../plastinet_rom.h"
#ifdef PN_TEST_HAVE_ROM_MODELS
#include "../models/pn_rom_models.h" /* the shipped reduced-order models */
#include "../examples/common/pn_rom_scenes.h" /* their scenes */
#endif
#include "pn_test.h"
#ifdef _OPENMP
#include <omp.h> /* test_mpm.c compares 1 and 2 threads */
#endif
#include "test_util.h" /* the reference helpers the test files share */

#include "test_linalg.c"  /* pn_tests_linalg: SVD, polar, Hencky, eigen, PSD projection  */
#include "test_energy.c"  /* pn_tests_energy: finite differences of every energy        */
#include "test_return.c"  /* pn_tests_return: return-mapping invariants, bad input      */
#include "test_driver.c"  /* pn_tests_driver: the material-point driver end to end      */
#include "test_pnet.c"    /* pn_tests_pnet: MLP, PlasticityNet energy, learned return map */
#include "test_mpm.c"     /* pn_tests_mpm: explicit MPM on small scenes                 */
#include "test_scene.c"   /* pn_tests_scene: fill helpers, stable dt, large steps, errors */
#include "test_fem.c"     /* pn_tests_fem: FEM meshes, energies, contact, Newton        */
#include "test_rom.c"     /* pn_tests_rom: reduced-order MPM (maps, projections, the step) */
#include "test_couple.c"  /* pn_tests_couple: MPM-FEM coupling (momentum, rest, threads)  */

#define PN_COUNT(a) ((int)(sizeof(a) / sizeof((a)[0])))

int main(int argc, char **argv) {
    const char *filter = argc > 1 ? argv[1] : NULL;
    int passed = 0, failed = 0;
    pn_test_run(pn_tests_linalg, PN_COUNT(pn_tests_linalg), filter, &passed, &failed);
    pn_test_run(pn_tests_energy, PN_COUNT(pn_tests_energy), filter, &passed, &failed);
    pn_test_run(pn_tests_return, PN_COUNT(pn_tests_return), filter, &passed, &failed);
    pn_test_run(pn_tests_driver, PN_COUNT(pn_tests_driver), filter, &passed, &failed);
    pn_test_run(pn_tests_pnet, PN_COUNT(pn_tests_pnet), filter, &passed, &failed);
    pn_test_run(pn_tests_mpm, PN_COUNT(pn_tests_mpm), filter, &passed, &failed);
    pn_test_run(pn_tests_scene, PN_COUNT(pn_tests_scene), filter, &passed, &failed);
    pn_test_run(pn_tests_fem, PN_COUNT(pn_tests_fem), filter, &passed, &failed);
    pn_test_run(pn_tests_rom, PN_COUNT(pn_tests_rom), filter, &passed, &failed);
    pn_test_run(pn_tests_couple, PN_COUNT(pn_tests_couple), filter, &passed, &failed);
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
