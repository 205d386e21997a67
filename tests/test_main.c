/* The one test binary: every unit, property and driver test of plastinet.
   Build: cc -std=c99 -O2 -Wall -Wextra -pedantic tests/test_main.c -lm -o build/test_main
          (add -DPN_TEST_HAVE_MODELS to test the models of models/pn_models.h, as tests/run.sh does)
   Run:   build/test_main [name-filter]          last line: N passed, N failed
          build/test_main =NAME                  that test alone
          build/test_main --list [name-filter]   the names, one a line (tests/run.sh runs them
                                                 two at a time, each in its own process)
          PN_TEST_FULL=1 build/test_main         every case of the sweeps (make test-all, CI)
          PN_TEST_TIMES=1 build/test_main        each test's CPU seconds on stderr */
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
#include <omp.h> /* the thread tests compare 1 and 2 threads */
#endif
#include "test_util.h" /* the reference helpers the test files share */

#include "test_linalg.c"  /* pn_tests_linalg: SVD, polar, Hencky, eigen, PSD projection  */
#include "test_energy.c"  /* pn_tests_energy: finite differences of every energy        */
#include "test_return.c"  /* pn_tests_return: return-mapping invariants, bad input      */
#include "test_driver.c"  /* pn_tests_driver: the material-point driver end to end      */
/* plastinet.h's learned models, by room (the helpers in test_pnet_mlp.c) */
#include "test_pnet_mlp.c"      /* >>mlp: pn_mlp_eval                                     */
#include "test_pnet_energy.c"   /* >>features, >>pnet: the energy and its derivatives     */
#include "test_pnet_props.c"    /* >>pnet: invariants, PSD projection, bad input          */
#include "test_pnet_return.c"   /* >>learned-return, the shipped models                   */
#include "test_pnet_lanes.c"    /* the float lanes of >>mlp and >>pnet                    */
/* plastinet_mpm.h's MPM, by room (the helpers in test_mpm_world.c) */
#include "test_mpm_world.c"     /* >>world, >>drive                                       */
#include "test_mpm_explicit.c"  /* >>explicit                                             */
#include "test_mpm_transfer.c"  /* >>bin, >>transfer, 1 and 2 threads                     */
#include "test_mpm_contact.c"   /* >>contact, >>friction                                  */
#include "test_mpm_implicit.c"  /* >>implicit: energies, PlasticityNet, the energy guard  */
#include "test_mpm_newton.c"    /* >>newton, >>implicit-step: the solve, the fallback     */
#include "test_mpm_multigrid.c" /* >>multigrid                                            */
#include "test_mpm_stress.c"    /* >>stress                                               */
#include "test_scene.c"   /* pn_tests_scene: fill helpers, stable dt, large steps, errors */
#include "test_fem.c"     /* pn_tests_fem: FEM meshes, energies, contact, Newton        */
#include "test_rom.c"     /* pn_tests_rom: reduced-order MPM (maps, projections, the step) */
#include "test_couple.c"  /* pn_tests_couple: MPM-FEM coupling (momentum, rest, threads)  */

#define PN_COUNT(a) ((int)(sizeof(a) / sizeof((a)[0])))

static const struct {
    const pn_test_case *cases;
    int count;
} pn_suites[] = {
    {pn_tests_linalg, PN_COUNT(pn_tests_linalg)},
    {pn_tests_energy, PN_COUNT(pn_tests_energy)},
    {pn_tests_return, PN_COUNT(pn_tests_return)},
    {pn_tests_driver, PN_COUNT(pn_tests_driver)},
    {pn_tests_pnet_mlp, PN_COUNT(pn_tests_pnet_mlp)},
    {pn_tests_pnet_energy, PN_COUNT(pn_tests_pnet_energy)},
    {pn_tests_pnet_props, PN_COUNT(pn_tests_pnet_props)},
    {pn_tests_pnet_return, PN_COUNT(pn_tests_pnet_return)},
    {pn_tests_pnet_lanes, PN_COUNT(pn_tests_pnet_lanes)},
    {pn_tests_mpm_world, PN_COUNT(pn_tests_mpm_world)},
    {pn_tests_mpm_explicit, PN_COUNT(pn_tests_mpm_explicit)},
    {pn_tests_mpm_transfer, PN_COUNT(pn_tests_mpm_transfer)},
    {pn_tests_mpm_contact, PN_COUNT(pn_tests_mpm_contact)},
    {pn_tests_mpm_implicit, PN_COUNT(pn_tests_mpm_implicit)},
    {pn_tests_mpm_newton, PN_COUNT(pn_tests_mpm_newton)},
    {pn_tests_mpm_multigrid, PN_COUNT(pn_tests_mpm_multigrid)},
    {pn_tests_mpm_stress, PN_COUNT(pn_tests_mpm_stress)},
    {pn_tests_scene, PN_COUNT(pn_tests_scene)},
    {pn_tests_fem, PN_COUNT(pn_tests_fem)},
    {pn_tests_rom, PN_COUNT(pn_tests_rom)},
    {pn_tests_couple, PN_COUNT(pn_tests_couple)},
};

int main(int argc, char **argv) {
    int list = argc > 1 && !strcmp(argv[1], "--list"), s, passed = 0, failed = 0;
    const char *filter = argc > 1 + list ? argv[1 + list] : NULL;
    for (s = 0; s < PN_COUNT(pn_suites); ++s) {
        if (list) pn_test_list(pn_suites[s].cases, pn_suites[s].count, filter);
        else pn_test_run(pn_suites[s].cases, pn_suites[s].count, filter, &passed, &failed);
    }
    if (list) return 0;
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
