/* vstig_serial: the serial frame and its framings. See vstig_serial.h and SPEC.md 6.0 to 6.4. */
#include "vstig_serial.h"

#include <string.h>

/* ---- serial frame -------------------------------------------------------- */

uint8_t vstig_frame_encode(const uint8_t *payload, uint8_t len, uint8_t *out) {
    /* COBS over payload || crc_lo || crc_hi, written straight into out. With at most
     * 62 bytes to stuff no block reaches 254 bytes, so codes never need splitting. */
    uint16_t crc = vstig_crc16(payload, len);
    uint8_t code_at = 0, w = 1, i, byte;
    for (i = 0; i < (uint8_t)(len + 2u); i++) {
        byte = i < len ? payload[i] : (i == len ? (uint8_t)(crc & 0xFFu) : (uint8_t)(crc >> 8));
        if (byte == 0) {
            out[code_at] = (uint8_t)(w - code_at);
            code_at = w++;
        } else {
            out[w++] = byte;
        }
    }
    out[code_at] = (uint8_t)(w - code_at);
    out[w++] = 0;
    return w;
}

void vstig_deframer_init(vstig_deframer_t *d) {
    d->len = 0;
    d->discarding = 0;
    vstig_drops_clear(&d->drops);
}

/* Decodes COBS in place (output never overtakes input); returns the decoded length or -1. */
static int16_t cobs_decode_in_place(uint8_t *buf, uint8_t len) {
    uint8_t r = 0, w = 0, code, i;
    while (r < len) {
        code = buf[r];
        if (code == 0 || (uint16_t)r + code > len) return -1;
        r++;
        for (i = 1; i < code; i++) buf[w++] = buf[r++];
        if (code != 0xFFu && r < len) buf[w++] = 0;
    }
    return w;
}

uint8_t vstig_deframer_feed(vstig_deframer_t *d, uint8_t byte, uint8_t want) {
    return vstig_deframer_feed_either(d, byte, want, want) != 0;
}

uint8_t vstig_deframer_feed_either(vstig_deframer_t *d, uint8_t byte, uint8_t want, uint8_t also) {
    int16_t n;
    if (byte != 0) {
        if (d->discarding) return 0;
        if (d->len == VSTIG_FRAME_MAX) { /* no delimiter in sight: drop, resync at the next 0x00 */
            vstig_drops_count(&d->drops, VSTIG_DROP_OVERLONG);
            d->discarding = 1;
            d->len = 0;
            return 0;
        }
        d->buf[d->len++] = byte;
        return 0;
    }
    if (d->discarding) { /* the end of an overlong frame, already counted */
        d->discarding = 0;
        return 0;
    }
    if (d->len == 0) return 0; /* idle line */
    n = cobs_decode_in_place(d->buf, d->len);
    d->len = 0;
    if (n < 0) {
        vstig_drops_count(&d->drops, VSTIG_DROP_COBS);
        return 0;
    }
    if (n < 2 || vstig_crc16(d->buf, (size_t)n) != 0) { /* over payload || crc_le the residue is 0 */
        vstig_drops_count(&d->drops, VSTIG_DROP_CRC);
        return 0;
    }
    if (n - 2 != want && n - 2 != also) {
        vstig_drops_count(&d->drops, VSTIG_DROP_BAD_LENGTH);
        return 0;
    }
    return (uint8_t)(n - 2);
}

size_t vstig_deframer_feed_run(vstig_deframer_t *d, const uint8_t *data, size_t len, uint8_t want, uint8_t also,
                               uint8_t *size) {
    const uint8_t *end = (const uint8_t *)memchr(data, 0, len);
    size_t run = end == NULL ? len : (size_t)(end - data); /* the frame's bytes before its 0x00 */
    *size = 0;
    if (!d->discarding) {
        if (run > (size_t)(VSTIG_FRAME_MAX - d->len)) { /* a byte met a full buffer: overlong, as feed_either */
            vstig_drops_count(&d->drops, VSTIG_DROP_OVERLONG);
            d->discarding = 1;
            d->len = 0;
        } else {
            memcpy(d->buf + d->len, data, run);
            d->len = (uint8_t)(d->len + run);
        }
    }
    if (end == NULL) return len;
    *size = vstig_deframer_feed_either(d, 0, want, also);
    return run + 1;
}

/* ---- cobs8 --------------------------------------------------------------- */

uint8_t vstig_cobs8_encode(const vstig_msg_t *msg, uint8_t out[VSTIG_COBS8_FRAME_SIZE]) {
    uint8_t raw[VSTIG_MESSAGE_SIZE];
    vstig_msg_encode(msg, raw);
    return vstig_frame_encode(raw, VSTIG_MESSAGE_SIZE, out);
}

uint8_t vstig_cobs8_feed(vstig_deframer_t *d, uint8_t byte, vstig_msg_t *out) {
    if (!vstig_deframer_feed(d, byte, VSTIG_MESSAGE_SIZE)) return 0;
    vstig_msg_decode(d->buf, out);
    return 1;
}

/* ---- epuck4 -------------------------------------------------------------- */
/* P = message (64 bits) || check (14 bits) is cut into three 26-bit chunks from the top.
 * Done byte by byte so that no 64-bit arithmetic is needed on small targets. */

#define CHUNK_MASK 0x03FFFFFFul
#define CHECK_MASK 0x3FFFu

void vstig_epuck4_encode(const vstig_msg_t *msg, uint32_t words[3]) {
    uint8_t m[VSTIG_MESSAGE_SIZE];
    uint32_t c, group;
    uint16_t check;
    vstig_msg_encode(msg, m);
    c = vstig_crc32(m, VSTIG_MESSAGE_SIZE);
    group = (c >> 28) << 26;
    check = (uint16_t)((c >> 14) & CHECK_MASK);
    words[0] = group | ((uint32_t)m[0] << 18) | ((uint32_t)m[1] << 10) | ((uint32_t)m[2] << 2) | (m[3] >> 6);
    words[1] = (1ul << 30) | group | ((uint32_t)(m[3] & 0x3Fu) << 20) | ((uint32_t)m[4] << 12) |
               ((uint32_t)m[5] << 4) | (m[6] >> 4);
    words[2] = (2ul << 30) | group | ((uint32_t)(m[6] & 0x0Fu) << 22) | ((uint32_t)m[7] << 14) | check;
}

uint8_t vstig_epuck4_word_frame(uint32_t word, uint8_t out[VSTIG_EPUCK4_FRAME_SIZE]) {
    uint8_t w[4];
    w[0] = (uint8_t)(word >> 24);
    w[1] = (uint8_t)(word >> 16);
    w[2] = (uint8_t)(word >> 8);
    w[3] = (uint8_t)word;
    return vstig_frame_encode(w, 4, out);
}

uint8_t vstig_epuck4_uart_feed(vstig_deframer_t *d, uint8_t byte, uint32_t *word) {
    if (!vstig_deframer_feed(d, byte, 4)) return 0;
    *word = ((uint32_t)d->buf[0] << 24) | ((uint32_t)d->buf[1] << 16) | ((uint32_t)d->buf[2] << 8) | d->buf[3];
    return 1;
}

void vstig_epuck4_init(vstig_epuck4_reassembler_t *r, uint8_t expiry_ticks) {
    uint8_t i;
    for (i = 0; i < VSTIG_EPUCK4_SLOTS; i++) r->slot[i].held = 0;
    vstig_drops_clear(&r->drops);
    r->arrivals = 0;
    r->now = 0;
    r->expiry_ticks = expiry_ticks;
}

/* a arrived before (or is) b, with arrival numbers compared modulo 2^16 */
static uint8_t arrived_no_later(uint16_t a, uint16_t b) { return (uint8_t)((uint16_t)(b - a) < 0x8000u); }

static uint8_t oldest_index(const vstig_epuck4_partial_t *p) {
    uint8_t i, best = 3;
    for (i = 0; i < 3; i++)
        if ((p->held & (1u << i)) && (best == 3 || !arrived_no_later(p->order[best], p->order[i]))) best = i;
    return best;
}

static vstig_epuck4_partial_t *partial_for(vstig_epuck4_reassembler_t *r, uint8_t group) {
    vstig_epuck4_partial_t *free_slot = 0, *victim = 0;
    uint8_t i;
    for (i = 0; i < VSTIG_EPUCK4_SLOTS; i++) {
        vstig_epuck4_partial_t *p = &r->slot[i];
        if (!p->held) {
            if (!free_slot) free_slot = p;
        } else if (p->group == group) {
            return p;
        } else if (!victim || !arrived_no_later(victim->order[oldest_index(victim)], p->order[oldest_index(p)])) {
            victim = p;
        }
    }
    if (!free_slot) { /* fewer slots than groups, all busy: the oldest partial makes room */
        vstig_drops_count(&r->drops, VSTIG_DROP_STALE);
        victim->held = 0;
        free_slot = victim;
    }
    free_slot->group = group;
    return free_slot;
}

uint8_t vstig_epuck4_feed(vstig_epuck4_reassembler_t *r, uint32_t word, vstig_msg_t *out) {
    uint8_t index = (uint8_t)(word >> 30), group = (uint8_t)((word >> 26) & 0x0Fu), i;
    uint32_t chunk = word & CHUNK_MASK, c;
    uint8_t m[VSTIG_MESSAGE_SIZE];
    vstig_epuck4_partial_t *p;
    if (index == 3) {
        vstig_drops_count(&r->drops, VSTIG_DROP_BAD_INDEX);
        return 0;
    }
    p = partial_for(r, group);
    if (p->held & (1u << index)) {
        uint16_t cut = p->order[index];
        if (p->chunk[index] == chunk) {
            vstig_drops_count(&r->drops, VSTIG_DROP_DUPLICATE);
            return 0;
        }
        /* the clashing fragment and everything older belong to an earlier, lost message */
        vstig_drops_count(&r->drops, VSTIG_DROP_COLLISION);
        for (i = 0; i < 3; i++)
            if ((p->held & (1u << i)) && arrived_no_later(p->order[i], cut)) p->held &= (uint8_t)~(1u << i);
    }
    p->chunk[index] = chunk;
    p->order[index] = ++r->arrivals;
    p->born[index] = r->now;
    p->held |= (uint8_t)(1u << index);
    if (p->held != 7u) return 0;
    m[0] = (uint8_t)(p->chunk[0] >> 18);
    m[1] = (uint8_t)(p->chunk[0] >> 10);
    m[2] = (uint8_t)(p->chunk[0] >> 2);
    m[3] = (uint8_t)(((p->chunk[0] & 3u) << 6) | (p->chunk[1] >> 20));
    m[4] = (uint8_t)(p->chunk[1] >> 12);
    m[5] = (uint8_t)(p->chunk[1] >> 4);
    m[6] = (uint8_t)(((p->chunk[1] & 0x0Fu) << 4) | (p->chunk[2] >> 22));
    m[7] = (uint8_t)(p->chunk[2] >> 14);
    c = vstig_crc32(m, VSTIG_MESSAGE_SIZE);
    if ((uint8_t)(c >> 28) != group || (uint16_t)((c >> 14) & CHECK_MASK) != (uint16_t)(p->chunk[2] & CHECK_MASK)) {
        vstig_drops_count(&r->drops, VSTIG_DROP_CHECK);
        p->held &= (uint8_t)~(1u << oldest_index(p)); /* most likely the leftover of a lost message */
        return 0;
    }
    p->held = 0;
    vstig_msg_decode(m, out);
    return 1;
}

void vstig_epuck4_tick(vstig_epuck4_reassembler_t *r) {
    uint8_t i, j, stale;
    r->now++;
    for (i = 0; i < VSTIG_EPUCK4_SLOTS; i++) {
        vstig_epuck4_partial_t *p = &r->slot[i];
        stale = 0;
        for (j = 0; j < 3; j++) {
            if ((p->held & (1u << j)) && (uint8_t)(r->now - p->born[j]) > r->expiry_ticks) {
                p->held &= (uint8_t)~(1u << j);
                stale = 1;
            }
        }
        if (stale) vstig_drops_count(&r->drops, VSTIG_DROP_STALE);
    }
}

/* ---- kilobot ------------------------------------------------------------- */

static void kilobot_head(const vstig_msg_t *msg, uint8_t type, uint8_t head[10]) {
    vstig_msg_encode(msg, head);
    head[8] = VSTIG_KILOBOT_VERSION;
    head[9] = type;
}

uint16_t vstig_kilobot_crc(const uint8_t head[10]) { return vstig_crc16(head, 10); }

void vstig_kilobot_encode(const vstig_msg_t *msg, uint8_t type, uint8_t out[12]) {
    uint16_t crc;
    kilobot_head(msg, type, out);
    crc = vstig_kilobot_crc(out);
    out[10] = (uint8_t)(crc & 0xFFu);
    out[11] = (uint8_t)(crc >> 8);
}

uint8_t vstig_kilobot_accept(const uint8_t head[10], uint8_t type, vstig_msg_t *out, vstig_drops_t *drops) {
    if (head[9] != type) {
        vstig_drops_count(drops, VSTIG_DROP_FOREIGN_TYPE);
        return 0;
    }
    if (head[8] != VSTIG_KILOBOT_VERSION) {
        vstig_drops_count(drops, VSTIG_DROP_BAD_VERSION);
        return 0;
    }
    vstig_msg_decode(head, out);
    return 1;
}

uint8_t vstig_kilobot_frame(const vstig_msg_t *msg, uint8_t type, uint8_t out[VSTIG_KILOBOT_FRAME_SIZE]) {
    uint8_t head[10];
    kilobot_head(msg, type, head);
    return vstig_frame_encode(head, 10, out);
}

uint8_t vstig_kilobot_uart_feed(vstig_deframer_t *d, uint8_t byte, uint8_t type, vstig_msg_t *out) {
    if (!vstig_deframer_feed(d, byte, 10)) return 0;
    return vstig_kilobot_accept(d->buf, type, out, &d->drops);
}

/* ---- kilobot-ohc --------------------------------------------------------- */

void vstig_ohc_packet(const vstig_msg_t *msg, uint8_t packet_type, uint8_t type, uint8_t out[VSTIG_OHC_PACKET_SIZE]) {
    uint8_t i, x = 0;
    for (i = 0; i < VSTIG_OHC_PACKET_SIZE; i++) out[i] = 0;
    out[0] = 0x55u;
    out[1] = packet_type;
    kilobot_head(msg, type, out + 2);
    for (i = 0; i < VSTIG_OHC_PACKET_SIZE - 1u; i++) x ^= out[i];
    out[VSTIG_OHC_PACKET_SIZE - 1u] = x;
}

/* ---- a serial link's receiver over buffers --------------------------------- */

int vstig_serial_rx_init(vstig_serial_rx_t *rx, uint8_t framing, uint8_t kilobot_type,
                         vstig_epuck4_reassembler_t *epuck4) {
    if (framing > VSTIG_KILOBOT || kilobot_type >= 0x80u || (framing == VSTIG_EPUCK4 && !epuck4)) return VSTIG_ERR_ARG;
    vstig_deframer_init(&rx->deframer);
    rx->framing = framing;
    rx->kilobot_type = kilobot_type;
    rx->epuck4 = epuck4;
    return 0;
}

static uint8_t serial_feed(vstig_serial_rx_t *rx, uint8_t byte, vstig_msg_t *out) {
    uint32_t word;
    switch (rx->framing) {
    case VSTIG_COBS8: return vstig_cobs8_feed(&rx->deframer, byte, out);
    case VSTIG_KILOBOT: return vstig_kilobot_uart_feed(&rx->deframer, byte, rx->kilobot_type, out);
    default: return vstig_epuck4_uart_feed(&rx->deframer, byte, &word) && vstig_epuck4_feed(rx->epuck4, word, out);
    }
}

size_t vstig_serial_receive(vstig_serial_rx_t *rx, const uint8_t *data, size_t len, size_t *used,
                            vstig_msg_t *out, size_t max) {
    size_t i = 0, n = 0;
    while (i < len && n < max) n += serial_feed(rx, data[i++], &out[n]);
    *used = i;
    return n;
}
