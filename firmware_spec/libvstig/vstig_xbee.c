/* vstig_xbee: XBee API frames. See vstig_xbee.h and SPEC.md 6.9. */
#include "vstig_xbee.h"

#define ESCAPE 0x7Du
#define FLIP 0x20u

static uint8_t special(uint8_t byte) { return (uint8_t)(byte == 0x7Eu || byte == 0x7Du || byte == 0x11u || byte == 0x13u); }

/* ---- receiving ----------------------------------------------------------- */

void vstig_xbee_rx_reset(vstig_xbee_rx_t *rx) {
    rx->head = rx->pos = rx->avail = 0;
    rx->got = 0;
    rx->in_frame = rx->escaping = 0;
    rx->counted = 0;
    rx->final = 0;
}

void vstig_xbee_rx_init(vstig_xbee_rx_t *rx, uint8_t escaped) {
    rx->escaped = (uint8_t)(escaped != 0);
    rx->wire_at = rx->wire_len = 0;
    vstig_xbee_rx_reset(rx);
    vstig_drops_clear(&rx->drops);
}

/* A bad unit: counted, and the search for a frame starts again one byte after its 0x7E (in mode 1
 * its bytes may hold the next frame's 0x7E). */
static void refuse(vstig_xbee_rx_t *rx, vstig_drop_t reason) {
    vstig_drops_count(&rx->drops, reason);
    rx->counted = 1;
    rx->in_frame = 0;
    rx->head = (uint16_t)(rx->head + 1u);
    rx->pos = rx->head;
}

/* One unescaped byte of the frame arriving; 1 when it completed the frame. */
static uint8_t take(vstig_xbee_rx_t *rx, uint8_t byte) {
    uint16_t length, i;
    uint8_t sum = 0;
    rx->data[rx->got++] = byte;
    if (rx->got < 2u) return 0;
    length = (uint16_t)((uint16_t)rx->data[0] << 8 | rx->data[1]);
    if (length == 0 || length > VSTIG_XBEE_MAX_FRAME_DATA) {
        refuse(rx, VSTIG_DROP_FRAME_LENGTH);
        return 0;
    }
    if (rx->got < length + 3u) return 0;
    for (i = 2; i < rx->got; i++) sum = (uint8_t)(sum + rx->data[i]);
    if (sum != 0xFFu) {
        refuse(rx, VSTIG_DROP_CHECKSUM);
        return 0;
    }
    rx->wire_at = rx->head;
    rx->wire_len = (uint16_t)(rx->pos - rx->head);
    rx->head = rx->pos;
    rx->in_frame = 0;
    rx->counted = 0;
    return 1;
}

/* Scan what is held; 1 when a frame is whole. With `final`, a frame still arriving is truncated
 * and, once everything held is scanned, the receiver starts afresh. */
static uint8_t scan(vstig_xbee_rx_t *rx) {
    uint8_t byte;
    for (;;) {
        if (rx->pos == rx->avail) {
            if (!rx->final) return 0;
            if (rx->in_frame) {
                refuse(rx, VSTIG_DROP_TRUNCATED);
                continue;
            }
            vstig_xbee_rx_reset(rx);
            return 0;
        }
        byte = rx->raw[rx->pos++];
        if (!rx->in_frame) {
            if (byte == VSTIG_XBEE_START) {
                rx->head = (uint16_t)(rx->pos - 1u);
                rx->in_frame = 1;
                rx->got = 0;
                rx->escaping = 0;
            } else {
                if (!rx->counted) vstig_drops_count(&rx->drops, VSTIG_DROP_NOISE); /* one drop per run */
                rx->counted = 1;
                rx->head = rx->pos;
            }
            continue;
        }
        if (!rx->escaped) {
            if (take(rx, byte)) return 1;
            continue;
        }
        /* Mode 2: a 0x7E always starts a frame (searched again from it); SPEC.md 6.6's order puts a bad escape
         * (0x7D before a byte it never escapes, 0x7E included; a 0x11 or 0x13 left raw) before `truncated`. */
        if (rx->escaping) {
            rx->escaping = 0;
            if (!special((uint8_t)(byte ^ FLIP))) refuse(rx, VSTIG_DROP_ESCAPE);
            else if (take(rx, (uint8_t)(byte ^ FLIP))) return 1;
        } else if (byte == VSTIG_XBEE_START) {
            refuse(rx, VSTIG_DROP_TRUNCATED);
        } else if (byte == ESCAPE) {
            rx->escaping = 1;
        } else if (byte == 0x11u || byte == 0x13u) {
            refuse(rx, VSTIG_DROP_ESCAPE);
        } else if (take(rx, byte)) {
            return 1;
        }
    }
}

uint8_t vstig_xbee_feed(vstig_xbee_rx_t *rx, uint8_t byte) {
    if (rx->head == rx->avail) {
        rx->head = rx->pos = rx->avail = 0;
    } else if (rx->avail == sizeof rx->raw) { /* make room: what lies before the frame arriving is done with */
        uint16_t i, keep = (uint16_t)(rx->avail - rx->head);
        for (i = 0; i < keep; i++) rx->raw[i] = rx->raw[rx->head + i];
        rx->pos = (uint16_t)(rx->pos - rx->head);
        rx->avail = keep;
        rx->head = 0;
    }
    rx->raw[rx->avail++] = byte;
    return scan(rx);
}

uint8_t vstig_xbee_next(vstig_xbee_rx_t *rx) { return scan(rx); }

uint8_t vstig_xbee_flush(vstig_xbee_rx_t *rx) {
    rx->final = 1;
    return scan(rx);
}

uint8_t vstig_xbee_messages(const uint8_t *frame_data, uint16_t len, vstig_msg_t *out, uint8_t *n,
                            uint8_t source[8], uint8_t *has_source, vstig_drops_t *drops) {
    uint8_t kind = frame_data[0], i;
    uint16_t header, rf;
    *n = 0;
    *has_source = 0;
    if (kind == VSTIG_XBEE_TX_STATUS || kind == VSTIG_XBEE_MODEM_STATUS || kind == VSTIG_XBEE_AT_RESPONSE)
        return VSTIG_XBEE_REPORT;
    if (kind != VSTIG_XBEE_RECEIVE_PACKET && kind != VSTIG_XBEE_TRANSMIT_REQUEST) {
        vstig_drops_count(drops, VSTIG_DROP_UNKNOWN_TYPE);
        return VSTIG_XBEE_DROPPED;
    }
    header = kind == VSTIG_XBEE_RECEIVE_PACKET ? VSTIG_XBEE_RX_HEADER : VSTIG_XBEE_TX_HEADER;
    rf = (uint16_t)(len - header);
    if (len < header || rf == 0 || rf % VSTIG_MESSAGE_SIZE != 0 || rf / VSTIG_MESSAGE_SIZE > VSTIG_XBEE_MAX_MESSAGES) {
        vstig_drops_count(drops, VSTIG_DROP_BAD_LENGTH);
        return VSTIG_XBEE_DROPPED;
    }
    if (kind == VSTIG_XBEE_RECEIVE_PACKET) {
        for (i = 0; i < 8u; i++) source[i] = frame_data[1 + i];
        *has_source = 1;
    }
    *n = (uint8_t)(rf / VSTIG_MESSAGE_SIZE);
    for (i = 0; i < *n; i++) vstig_msg_decode(frame_data + header + (uint16_t)i * VSTIG_MESSAGE_SIZE, &out[i]);
    return VSTIG_XBEE_MESSAGES;
}

/* ---- sending ------------------------------------------------------------- */

void vstig_xbee_tx_init(vstig_xbee_tx_t *tx, uint8_t escaped, const uint8_t dest[8]) {
    uint8_t i;
    for (i = 0; i < 8u; i++) tx->dest[i] = dest ? dest[i] : (uint8_t)(i == 6u || i == 7u ? 0xFFu : 0u);
    tx->escaped = (uint8_t)(escaped != 0);
    tx->frame_id = 0;
    tx->report = 1;
    vstig_xbee_max_payload(tx, VSTIG_XBEE_DEFAULT_MAX_PAYLOAD);
}

void vstig_xbee_max_payload(vstig_xbee_tx_t *tx, uint16_t np) {
    uint16_t per = np / VSTIG_MESSAGE_SIZE;
    tx->per_frame = (uint8_t)(per < 1u ? 1u : (per > VSTIG_XBEE_MAX_MESSAGES ? VSTIG_XBEE_MAX_MESSAGES : per));
}

void vstig_xbee_tick(vstig_xbee_tx_t *tx) { tx->report = 1; }

/* One byte after the 0x7E, escaped in mode 2; returns the next write position. */
static size_t put(const vstig_xbee_tx_t *tx, uint8_t *out, size_t w, uint8_t byte) {
    if (tx->escaped && special(byte)) {
        out[w++] = ESCAPE;
        byte = (uint8_t)(byte ^ FLIP);
    }
    out[w++] = byte;
    return w;
}

/* The 0x7E, the length and the Transmit Request's header of a frame of rf_len bytes of RF data, at out; the header's
 * bytes added to *sum (the checksum's); returns the next write position. */
static size_t transmit_head(vstig_xbee_tx_t *tx, uint16_t rf_len, uint8_t *out, uint8_t *sum) {
    uint8_t head[VSTIG_XBEE_TX_HEADER], i;
    uint16_t length = (uint16_t)(VSTIG_XBEE_TX_HEADER + rf_len);
    size_t w = 0;
    head[0] = VSTIG_XBEE_TRANSMIT_REQUEST;
    head[1] = 0;
    if (tx->report) { /* the first frame of a control period asks for a Transmit Status */
        tx->report = 0;
        tx->frame_id = (uint8_t)(tx->frame_id % 255u + 1u);
        head[1] = tx->frame_id;
    }
    for (i = 0; i < 8u; i++) head[2 + i] = tx->dest[i];
    head[10] = 0xFFu; /* 16-bit address unknown: the module finds its way by the 64-bit one */
    head[11] = 0xFEu;
    head[12] = 0;     /* radius: the maximum */
    head[13] = 0;     /* options */
    out[w++] = VSTIG_XBEE_START;
    w = put(tx, out, w, (uint8_t)(length >> 8));
    w = put(tx, out, w, (uint8_t)length);
    for (i = 0; i < VSTIG_XBEE_TX_HEADER; i++) {
        *sum = (uint8_t)(*sum + head[i]);
        w = put(tx, out, w, head[i]);
    }
    return w;
}

/* One Transmit Request carrying msgs[0..n) at out; its size. */
static size_t transmit(vstig_xbee_tx_t *tx, const vstig_msg_t *msgs, uint8_t n, uint8_t *out) {
    uint8_t raw[VSTIG_MESSAGE_SIZE], sum = 0, i, k;
    size_t w = transmit_head(tx, (uint16_t)((uint16_t)n * VSTIG_MESSAGE_SIZE), out, &sum);
    for (k = 0; k < n; k++) {
        vstig_msg_encode(&msgs[k], raw);
        for (i = 0; i < VSTIG_MESSAGE_SIZE; i++) {
            sum = (uint8_t)(sum + raw[i]);
            w = put(tx, out, w, raw[i]);
        }
    }
    return put(tx, out, w, (uint8_t)(0xFFu - sum));
}

size_t vstig_xbee_transmit(vstig_xbee_tx_t *tx, const uint8_t *rf, uint16_t len, uint8_t *out) {
    uint8_t sum = 0;
    uint16_t i;
    size_t w = transmit_head(tx, len, out, &sum);
    for (i = 0; i < len; i++) {
        sum = (uint8_t)(sum + rf[i]);
        w = put(tx, out, w, rf[i]);
    }
    return put(tx, out, w, (uint8_t)(0xFFu - sum));
}

size_t vstig_xbee_encode(vstig_xbee_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out) {
    size_t at = 0, w = 0;
    uint8_t step;
    while (at < n) {
        step = (uint8_t)(n - at < tx->per_frame ? n - at : tx->per_frame);
        w += transmit(tx, msgs + at, step, out + w);
        at += step;
    }
    return w;
}
