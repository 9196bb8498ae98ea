/* vstig_wire: the message, timestamps, CRCs and drop counters. See vstig_wire.h and SPEC.md. */
#include "vstig_wire.h"

/* ---- message ------------------------------------------------------------- */

static void put16(uint8_t *out, uint16_t v) {
    out[0] = (uint8_t)(v >> 8);
    out[1] = (uint8_t)(v & 0xFFu);
}

static uint16_t get16(const uint8_t *in) { return (uint16_t)(((uint16_t)in[0] << 8) | in[1]); }

void vstig_msg_encode(const vstig_msg_t *msg, uint8_t out[VSTIG_MESSAGE_SIZE]) {
    put16(out, (uint16_t)(((uint16_t)(msg->op & 1u) << 15) | (msg->key & VSTIG_KEY_MAX)));
    put16(out + 2, msg->value);
    put16(out + 4, msg->timestamp);
    put16(out + 6, msg->robot);
}

void vstig_msg_decode(const uint8_t in[VSTIG_MESSAGE_SIZE], vstig_msg_t *msg) {
    msg->op = (uint8_t)(in[0] >> 7);
    msg->key = (uint16_t)(get16(in) & VSTIG_KEY_MAX);
    msg->value = get16(in + 2);
    msg->timestamp = get16(in + 4);
    msg->robot = get16(in + 6);
}

/* ---- timestamps ---------------------------------------------------------- */

uint8_t vstig_ts_newer(uint16_t a, uint16_t b) {
    uint16_t distance;
    if (b == VSTIG_TS_NONE) return (uint8_t)(a != VSTIG_TS_NONE);
    if (a == VSTIG_TS_NONE) return 0;
    distance = (uint16_t)(a - b); /* modulo 2^16 */
    if (distance == 0x8000u) return (uint8_t)(a > b); /* half-way: the larger number is newer */
    return (uint8_t)(distance != 0 && distance < 0x8000u);
}

uint16_t vstig_ts_next(uint16_t ts) { return ts == 0xFFFFu ? 1u : (uint16_t)(ts + 1u); }

uint16_t vstig_ts_steps(uint16_t newer, uint16_t older) {
    uint16_t distance = (uint16_t)(newer - older); /* modulo 2^16 */
    return newer < older ? (uint16_t)(distance - 1u) : distance; /* the path skipped 0 once */
}

/* ---- CRCs ---------------------------------------------------------------- */

/* Static, so vstig_crc16's loop inlines it: a shared library's exported function is called per byte. */
static uint16_t crc16_step(uint16_t crc, uint8_t byte) {
    /* Reflected poly 0x8408 processed a byte at a time: the same shift/xor identity
     * avr-libc documents for _crc_ccitt_update. */
    uint8_t x = (uint8_t)(byte ^ (uint8_t)(crc & 0xFFu));
    x = (uint8_t)(x ^ (uint8_t)(x << 4));
    return (uint16_t)((((uint16_t)x << 8) | (crc >> 8)) ^ (uint8_t)(x >> 4) ^ ((uint16_t)x << 3));
}

uint16_t vstig_crc16_update(uint16_t crc, uint8_t byte) { return crc16_step(crc, byte); }

uint16_t vstig_crc16(const uint8_t *data, size_t len) {
    uint16_t crc = VSTIG_CRC16_INIT;
    while (len--) crc = crc16_step(crc, *data++);
    return crc;
}

uint32_t vstig_crc32(const uint8_t *data, size_t len) {
    uint32_t crc = 0xFFFFFFFFul;
    uint8_t bit;
    while (len--) {
        crc ^= *data++;
        for (bit = 0; bit < 8; bit++) crc = (crc & 1u) ? (crc >> 1) ^ 0xEDB88320ul : crc >> 1;
    }
    return crc ^ 0xFFFFFFFFul;
}

/* ---- drops --------------------------------------------------------------- */

static const char *const drop_names[VSTIG_DROP_REASONS] = {
    "cobs", "crc", "bad_length", "overlong", "bad_index", "collision", "check", "stale", "duplicate",
    "foreign_type", "bad_version", "error_frame", "unknown_id", "remote_frame", "bad_dlc", "op_mismatch",
    "noise", "escape", "frame_length", "truncated", "checksum", "unknown_type",
};

const char *vstig_drop_name(vstig_drop_t reason) {
    return (unsigned)reason < VSTIG_DROP_REASONS ? drop_names[reason] : "?";
}

void vstig_drops_add(vstig_drops_t *drops, vstig_drop_t reason, uint16_t count) {
    uint16_t *n = &drops->count[reason];
    *n = (uint16_t)(*n > 0xFFFFu - count ? 0xFFFFu : *n + count);
}

void vstig_drops_count(vstig_drops_t *drops, vstig_drop_t reason) { vstig_drops_add(drops, reason, 1u); }

void vstig_drops_clear(vstig_drops_t *drops) {
    uint8_t i;
    for (i = 0; i < VSTIG_DROP_REASONS; i++) drops->count[i] = 0;
}
