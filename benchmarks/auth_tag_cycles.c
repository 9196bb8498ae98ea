/* The firmware bench_auth.py runs on a simulated ATmega328P: RUNS tags (WHAT=1), RUNS tag checks (WHAT=2) or,
 * as the anchor, RUNS cobs8 frames (WHAT=0) of one message, then it sleeps with interrupts off (simavr stops). */
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <stdint.h>

#include "vstig.h"

volatile uint8_t sink;

int main(void) {
    static const uint8_t key[VSTIG_KEY_SIZE] = {1, 2, 3};
    static uint8_t msg[8] = {0x01, 0x02, 0xAB, 0xCD, 0x80, 0x00, 0x00, 0x2A}, tag[VSTIG_TAG_SIZE];
    static uint8_t frame[VSTIG_COBS8_FRAME_SIZE];
    static vstig_tag_key_t ready;
    vstig_msg_t decoded;
    uint16_t n;
    vstig_tag_key_init(&ready, key);
    vstig_msg_decode(msg, &decoded);
    for (n = 0; n < RUNS; n++) {
#if WHAT == 1
        vstig_tag(&ready, 0, msg, n, tag);
#elif WHAT == 2
        sink ^= vstig_tag_ok(&ready, 0, msg, n, tag);
#else
        decoded.timestamp = (uint16_t)(n + 1);
        sink ^= vstig_cobs8_encode(&decoded, frame);
#endif
        sink ^= tag[0] ^ frame[0];
    }
    cli();
    sleep_cpu();
    return 0;
}
