/* Second translation unit: the header without the implementation must declare everything. */
#include "../plastinet.h"
#include "../plastinet_mpm.h"
#include "../plastinet_rom.h"
int pn_check_second_tu(void);
int pn_check_second_tu(void) {
    pn_mpm_destroy(0); /* declared by plastinet_mpm.h; a no-op on NULL */
    pn_rom_destroy(0); /* and by plastinet_rom.h */
    return pn_result_string(PN_OK)[0] == 'o' && pn_plastic_model_from_name("von_mises") == (int)PN_PLASTIC_VON_MISES;
}
