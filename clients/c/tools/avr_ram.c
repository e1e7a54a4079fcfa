/*
 * avr_ram - the smallest firmware that decodes the stream on an ATmega328P
 * (Arduino Uno/Nano): read UDR0, feed the decoder, write to a port. It owns no
 * variables besides the decoder and one packet, so the linked program's
 * .data + .bss is exactly the decoder's static RAM. Built by tools/avr_ram.sh;
 * never run. -DWITH_NAMES also links ghj_result_name().
 */
#include <avr/io.h>

#include "ghjoints.h"

static ghj_decoder dec;
static ghj_packet pkt;

int main(void)
{
    ghj_init(&dec);
    for (;;) {
        ghj_result r;
        while (!(UCSR0A & (1u << RXC0))) {
        }
        r = ghj_feed_byte(&dec, UDR0, &pkt);
        if (r == GHJ_PACKET) PORTB = (uint8_t)pkt.u.joints.joints[0].x;
#ifdef WITH_NAMES
        PORTC = (uint8_t)ghj_result_name(r)[0];
#endif
    }
}
