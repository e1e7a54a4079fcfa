/*
 * ghj_sizes - print the RAM the decoder's two structs take with this build's
 * GHJ_MAX_JOINTS (`make sizes` builds it with 64 and with 25). The sizes
 * depend on the target's alignment rules; tools/avr_ram.sh measures AVR.
 */
#include <stdio.h>

#include "ghjoints.h"

int main(void)
{
    printf("GHJ_MAX_JOINTS=%u: sizeof(ghj_decoder)=%u sizeof(ghj_packet)=%u\n", (unsigned)GHJ_MAX_JOINTS,
           (unsigned)sizeof(ghj_decoder), (unsigned)sizeof(ghj_packet));
    return 0;
}
