/* vstig_mavlink: MAVLink 2 TUNNEL frames carrying our messages (SPEC.md 6.10). See vstig_mavlink.h. */
#include "vstig_mavlink.h"

#include <string.h>

#define CRC_EXTRA_TUNNEL 147u
#define CRC_EXTRA_HEARTBEAT 50u
#define TUNNEL_HEAD 5u   /* payload_type, target_system, target_component, payload_length */
#define TUNNEL_SIZE 133u /* the payload before its trailing zeros are cut */

static const char *const mavlink_drop_names[VSTIG_MAVLINK_DROP_REASONS] = {
    "noise", "incompat_flags", "crc", "truncated", "mavlink1", "unsigned", "signature", "replay",
    "other_message", "other_payload_type", "not_for_us", "bad_length",
};

const char *vstig_mavlink_drop_name(vstig_mavlink_drop_t reason) {
    return (unsigned)reason < VSTIG_MAVLINK_DROP_REASONS ? mavlink_drop_names[reason] : "?";
}

/* ---- SHA-256 (FIPS 180-4), 32-bit arithmetic only ------------------------- */
typedef struct {
    uint32_t h[8];
    uint8_t block[64];
    uint8_t used;
    uint16_t total; /* bytes hashed: a key and one frame, far below 65535 */
} sha256_t;

static const uint32_t K[64] = {
    0x428a2f98ul, 0x71374491ul, 0xb5c0fbcful, 0xe9b5dba5ul, 0x3956c25bul, 0x59f111f1ul, 0x923f82a4ul, 0xab1c5ed5ul,
    0xd807aa98ul, 0x12835b01ul, 0x243185beul, 0x550c7dc3ul, 0x72be5d74ul, 0x80deb1feul, 0x9bdc06a7ul, 0xc19bf174ul,
    0xe49b69c1ul, 0xefbe4786ul, 0x0fc19dc6ul, 0x240ca1ccul, 0x2de92c6ful, 0x4a7484aaul, 0x5cb0a9dcul, 0x76f988daul,
    0x983e5152ul, 0xa831c66dul, 0xb00327c8ul, 0xbf597fc7ul, 0xc6e00bf3ul, 0xd5a79147ul, 0x06ca6351ul, 0x14292967ul,
    0x27b70a85ul, 0x2e1b2138ul, 0x4d2c6dfcul, 0x53380d13ul, 0x650a7354ul, 0x766a0abbul, 0x81c2c92eul, 0x92722c85ul,
    0xa2bfe8a1ul, 0xa81a664bul, 0xc24b8b70ul, 0xc76c51a3ul, 0xd192e819ul, 0xd6990624ul, 0xf40e3585ul, 0x106aa070ul,
    0x19a4c116ul, 0x1e376c08ul, 0x2748774cul, 0x34b0bcb5ul, 0x391c0cb3ul, 0x4ed8aa4aul, 0x5b9cca4ful, 0x682e6ff3ul,
    0x748f82eeul, 0x78a5636ful, 0x84c87814ul, 0x8cc70208ul, 0x90befffaul, 0xa4506cebul, 0xbef9a3f7ul, 0xc67178f2ul,
};

static uint32_t rotr(uint32_t x, uint8_t n) { return (x >> n) | (x << (32u - n)); }

static void sha256_block(sha256_t *s) {
    uint32_t w[16], a, b, c, d, e, f, g, h, t1, t2;
    uint8_t i;
    for (i = 0; i < 16u; i++)
        w[i] = (uint32_t)s->block[4u * i] << 24 | (uint32_t)s->block[4u * i + 1u] << 16 |
               (uint32_t)s->block[4u * i + 2u] << 8 | s->block[4u * i + 3u];
    a = s->h[0]; b = s->h[1]; c = s->h[2]; d = s->h[3]; e = s->h[4]; f = s->h[5]; g = s->h[6]; h = s->h[7];
    for (i = 0; i < 64u; i++) {
        uint32_t wi;
        if (i < 16u) {
            wi = w[i];
        } else { /* the schedule in place: w[i mod 16] */
            uint32_t w15 = w[(i + 1u) & 15u], w2 = w[(i + 14u) & 15u];
            wi = w[i & 15u] + (rotr(w15, 7) ^ rotr(w15, 18) ^ (w15 >> 3)) + w[(i + 9u) & 15u] +
                 (rotr(w2, 17) ^ rotr(w2, 19) ^ (w2 >> 10));
            w[i & 15u] = wi;
        }
        t1 = h + (rotr(e, 6) ^ rotr(e, 11) ^ rotr(e, 25)) + ((e & f) ^ (~e & g)) + K[i] + wi;
        t2 = (rotr(a, 2) ^ rotr(a, 13) ^ rotr(a, 22)) + ((a & b) ^ (a & c) ^ (b & c));
        h = g; g = f; f = e; e = d + t1; d = c; c = b; b = a; a = t1 + t2;
    }
    s->h[0] += a; s->h[1] += b; s->h[2] += c; s->h[3] += d; s->h[4] += e; s->h[5] += f; s->h[6] += g; s->h[7] += h;
}

static void sha256_init(sha256_t *s) {
    static const uint32_t iv[8] = {0x6a09e667ul, 0xbb67ae85ul, 0x3c6ef372ul, 0xa54ff53aul,
                                   0x510e527ful, 0x9b05688cul, 0x1f83d9abul, 0x5be0cd19ul};
    memcpy(s->h, iv, sizeof iv);
    s->used = 0;
    s->total = 0;
}

static void sha256_add(sha256_t *s, const uint8_t *data, uint16_t len) {
    uint16_t i;
    for (i = 0; i < len; i++) {
        s->block[s->used++] = data[i];
        if (s->used == 64u) {
            sha256_block(s);
            s->used = 0;
        }
    }
    s->total = (uint16_t)(s->total + len);
}

static void sha256_first6(sha256_t *s, uint8_t out[6]) {
    uint32_t bits = (uint32_t)s->total << 3;
    uint8_t i;
    s->block[s->used++] = 0x80u;
    if (s->used > 56u) {
        while (s->used < 64u) s->block[s->used++] = 0;
        sha256_block(s);
        s->used = 0;
    }
    while (s->used < 60u) s->block[s->used++] = 0; /* the length's high 32 bits are 0 */
    for (i = 0; i < 4u; i++) s->block[60u + i] = (uint8_t)(bits >> (24u - 8u * i));
    sha256_block(s);
    for (i = 0; i < 6u; i++) out[i] = (uint8_t)(s->h[i >> 2] >> (24u - 8u * (i & 3u)));
}

void vstig_mavlink_sign(const uint8_t key[VSTIG_MAVLINK_KEY_SIZE], const uint8_t *frame, uint16_t len,
                        uint8_t out[6]) {
    sha256_t s;
    sha256_init(&s);
    sha256_add(&s, key, VSTIG_MAVLINK_KEY_SIZE);
    sha256_add(&s, frame, len);
    sha256_first6(&s, out);
}

uint16_t vstig_mavlink_crc(const uint8_t *data, uint16_t len, uint8_t crc_extra) {
    return vstig_crc16_update(vstig_crc16(data, len), crc_extra);
}

static uint8_t crc_extra_of(uint32_t msgid, uint8_t *extra) {
    if (msgid == VSTIG_MAVLINK_TUNNEL) *extra = CRC_EXTRA_TUNNEL;
    else if (msgid == VSTIG_MAVLINK_HEARTBEAT) *extra = CRC_EXTRA_HEARTBEAT;
    else return 0;
    return 1;
}

uint8_t vstig_mavlink_whole(const uint8_t *data, uint16_t len) {
    uint8_t extra;
    uint16_t at;
    if (len <= VSTIG_MAVLINK_HEADER + 2u || data[0] != VSTIG_MAVLINK_STX ||
        (data[2] & (uint8_t)~VSTIG_MAVLINK_SIGNED) ||
        len != VSTIG_MAVLINK_HEADER + data[1] + 2u + ((data[2] & VSTIG_MAVLINK_SIGNED) ? VSTIG_MAVLINK_SIGNATURE : 0u))
        return 0;
    if (!crc_extra_of((uint32_t)data[7] | (uint32_t)data[8] << 8 | (uint32_t)data[9] << 16, &extra)) return 1;
    at = (uint16_t)(VSTIG_MAVLINK_HEADER + data[1]);
    return vstig_mavlink_crc(data + 1, (uint16_t)(at - 1u), extra) == (uint16_t)(data[at] | data[at + 1u] << 8);
}

/* ---- sending -------------------------------------------------------------- */
void vstig_mavlink_tx_init(vstig_mavlink_tx_t *tx, uint8_t sysid, uint8_t compid, const uint8_t *key) {
    memset(tx, 0, sizeof *tx);
    tx->sysid = sysid;
    tx->compid = compid;
    tx->key = key;
}

static uint16_t frame_out(vstig_mavlink_tx_t *tx, uint16_t msgid, uint8_t crc_extra, const uint8_t *payload,
                          uint8_t size, uint8_t *out) {
    uint8_t len = size, i;
    uint16_t crc, end;
    while (len > 1u && payload[len - 1u] == 0) len--;
    out[0] = VSTIG_MAVLINK_STX;
    out[1] = len;
    out[2] = tx->key ? VSTIG_MAVLINK_SIGNED : 0u;
    out[3] = 0;
    out[4] = tx->seq++;
    out[5] = tx->sysid;
    out[6] = tx->compid;
    out[7] = (uint8_t)msgid;
    out[8] = (uint8_t)(msgid >> 8);
    out[9] = 0;
    memcpy(out + VSTIG_MAVLINK_HEADER, payload, len);
    crc = vstig_mavlink_crc(out + 1, (uint16_t)(VSTIG_MAVLINK_HEADER - 1u + len), crc_extra);
    end = (uint16_t)(VSTIG_MAVLINK_HEADER + len);
    out[end++] = (uint8_t)crc;
    out[end++] = (uint8_t)(crc >> 8);
    if (!tx->key) return end;
    for (i = 0; i < 6u && ++tx->timestamp[i] == 0; i++) { /* one more than the last: never repeats */
    }
    out[end++] = tx->link_id;
    memcpy(out + end, tx->timestamp, 6);
    end = (uint16_t)(end + 6u);
    vstig_mavlink_sign(tx->key, out, end, out + end);
    return (uint16_t)(end + 6u);
}

/* A TUNNEL's payload head: its type, the target and `size` bytes carried; the rest zeros. */
static void tunnel_head(const vstig_mavlink_tx_t *tx, uint16_t type, uint8_t size, uint8_t payload[TUNNEL_SIZE]) {
    memset(payload, 0, TUNNEL_SIZE);
    payload[0] = (uint8_t)(type & 0xFFu);
    payload[1] = (uint8_t)(type >> 8);
    payload[2] = tx->target_system;
    payload[3] = tx->target_component;
    payload[4] = size;
}

uint16_t vstig_mavlink_encode(vstig_mavlink_tx_t *tx, const vstig_msg_t *msgs, uint8_t n, uint8_t *out) {
    uint8_t payload[TUNNEL_SIZE];
    uint8_t i;
    if (n > VSTIG_MAVLINK_MAX_MESSAGES) n = VSTIG_MAVLINK_MAX_MESSAGES;
    tunnel_head(tx, VSTIG_MAVLINK_PAYLOAD_TYPE, (uint8_t)(n * VSTIG_MESSAGE_SIZE), payload);
    for (i = 0; i < n; i++) vstig_msg_encode(&msgs[i], payload + TUNNEL_HEAD + VSTIG_MESSAGE_SIZE * i);
    return frame_out(tx, VSTIG_MAVLINK_TUNNEL, CRC_EXTRA_TUNNEL, payload, TUNNEL_SIZE, out);
}

uint16_t vstig_mavlink_encode_tagged(vstig_mavlink_tx_t *tx, const uint8_t *records, uint8_t n, uint8_t *out) {
    uint8_t payload[TUNNEL_SIZE];
    if (n > VSTIG_MAVLINK_MAX_RECORDS) n = VSTIG_MAVLINK_MAX_RECORDS;
    tunnel_head(tx, VSTIG_MAVLINK_PAYLOAD_TYPE_TAGGED, (uint8_t)(n * VSTIG_RECORD_SIZE), payload);
    memcpy(payload + TUNNEL_HEAD, records, (size_t)n * VSTIG_RECORD_SIZE);
    return frame_out(tx, VSTIG_MAVLINK_TUNNEL, CRC_EXTRA_TUNNEL, payload, TUNNEL_SIZE, out);
}

uint16_t vstig_mavlink_heartbeat(vstig_mavlink_tx_t *tx, uint8_t *out) {
    static const uint8_t beat[9] = {0, 0, 0, 0, 18u, 8u, 0, 4u, 3u};
    return frame_out(tx, VSTIG_MAVLINK_HEARTBEAT, CRC_EXTRA_HEARTBEAT, beat, sizeof beat, out);
}

/* ---- receiving ------------------------------------------------------------ */
void vstig_mavlink_rx_init(vstig_mavlink_rx_t *rx) { memset(rx, 0, sizeof *rx); }

void vstig_mavlink_count(vstig_mavlink_rx_t *rx, vstig_mavlink_drop_t reason) {
    if (rx->drops[reason] != 0xFFFFu) rx->drops[reason]++;
}

/* A bad frame: counted; its bytes after the start byte are scanned again, ahead of any held. */
static void refuse(vstig_mavlink_rx_t *rx, vstig_mavlink_drop_t reason) {
    uint16_t again = (uint16_t)(rx->len - 1u);
    vstig_mavlink_count(rx, reason);
    rx->counted = 1;
    if (rx->held_at < again) { /* make room at the front */
        memmove(rx->held + again, rx->held + rx->held_at, rx->held_len);
        rx->held_at = again;
    }
    rx->held_at = (uint16_t)(rx->held_at - again);
    memcpy(rx->held + rx->held_at, rx->frame + 1, again);
    rx->held_len = (uint16_t)(rx->held_len + again);
    rx->len = 0;
}

/* One byte into the frame arriving; 1 when it is whole. */
static uint8_t step(vstig_mavlink_rx_t *rx, uint8_t byte) {
    uint16_t need;
    uint8_t extra;
    if (rx->len == 0) {
        if (byte != VSTIG_MAVLINK_STX && byte != VSTIG_MAVLINK_STX_V1) {
            if (!rx->counted) vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_NOISE);
            rx->counted = 1;
            return 0;
        }
    }
    rx->frame[rx->len++] = byte;
    if (rx->len < 2u) return 0;
    if (rx->frame[0] == VSTIG_MAVLINK_STX_V1) {
        need = (uint16_t)(rx->frame[1] + 8u);
    } else {
        if (rx->len < 3u) return 0;
        if (rx->frame[2] & (uint8_t)~VSTIG_MAVLINK_SIGNED) {
            refuse(rx, VSTIG_MAVLINK_DROP_INCOMPAT_FLAGS);
            return 0;
        }
        need = (uint16_t)(VSTIG_MAVLINK_HEADER + rx->frame[1] + 2u +
                          ((rx->frame[2] & VSTIG_MAVLINK_SIGNED) ? VSTIG_MAVLINK_SIGNATURE : 0u));
    }
    if (rx->len < need) return 0;
    if (rx->frame[0] == VSTIG_MAVLINK_STX &&
        crc_extra_of((uint32_t)rx->frame[7] | (uint32_t)rx->frame[8] << 8 | (uint32_t)rx->frame[9] << 16, &extra)) {
        uint16_t at = (uint16_t)(VSTIG_MAVLINK_HEADER + rx->frame[1]);
        uint16_t crc = vstig_mavlink_crc(rx->frame + 1, (uint16_t)(at - 1u), extra);
        if (crc != (uint16_t)(rx->frame[at] | rx->frame[at + 1u] << 8)) {
            refuse(rx, VSTIG_MAVLINK_DROP_CRC);
            return 0;
        }
    }
    rx->whole = rx->len;
    rx->len = 0;
    rx->counted = 0;
    return 1;
}

uint8_t vstig_mavlink_next(vstig_mavlink_rx_t *rx) {
    rx->whole = 0;
    for (;;) {
        while (rx->held_len) {
            uint8_t byte = rx->held[rx->held_at++];
            rx->held_len--;
            if (step(rx, byte)) return 1;
        }
        if (!rx->final || rx->len == 0) break;
        refuse(rx, VSTIG_MAVLINK_DROP_TRUNCATED);
    }
    if (rx->final) {
        rx->final = 0;
        rx->counted = 0;
    }
    rx->held_at = 0;
    return 0;
}

uint8_t vstig_mavlink_feed(vstig_mavlink_rx_t *rx, uint8_t byte) {
    rx->whole = 0;
    if (!rx->held_len) {
        rx->held_at = 0;
        return step(rx, byte);
    }
    if (rx->held_at + rx->held_len >= (uint16_t)sizeof rx->held) { /* keep the bytes at the front */
        memmove(rx->held, rx->held + rx->held_at, rx->held_len);
        rx->held_at = 0;
    }
    rx->held[rx->held_at + rx->held_len] = byte;
    rx->held_len++;
    return vstig_mavlink_next(rx);
}

uint8_t vstig_mavlink_flush(vstig_mavlink_rx_t *rx) {
    rx->final = 1;
    return vstig_mavlink_next(rx);
}

uint8_t vstig_mavlink_timestamp(const uint8_t *frame, uint16_t len, uint8_t *link_id, uint8_t stamp[6]) {
    if (len < VSTIG_MAVLINK_HEADER + 2u + VSTIG_MAVLINK_SIGNATURE || frame[0] != VSTIG_MAVLINK_STX ||
        !(frame[2] & VSTIG_MAVLINK_SIGNED))
        return 0;
    *link_id = frame[len - 13u];
    memcpy(stamp, frame + len - 12u, 6);
    return 1;
}

uint8_t vstig_mavlink_check(vstig_mavlink_rx_t *rx, const uint8_t *frame, uint16_t len, const uint8_t *key) {
    uint8_t signature[6];
    if (frame[0] == VSTIG_MAVLINK_STX_V1) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_MAVLINK1);
        return 0;
    }
    if (!key) return 1;
    if (!(frame[2] & VSTIG_MAVLINK_SIGNED)) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_UNSIGNED);
        return 0;
    }
    vstig_mavlink_sign(key, frame, (uint16_t)(len - 6u), signature);
    if (memcmp(signature, frame + len - 6u, 6) != 0) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_SIGNATURE);
        return 0;
    }
    return 1;
}

uint8_t vstig_mavlink_messages(vstig_mavlink_rx_t *rx, const uint8_t *frame, uint8_t sysid, uint8_t compid,
                               vstig_msg_t out[VSTIG_MAVLINK_MAX_MESSAGES], uint8_t *from_sysid,
                               uint8_t *from_compid) {
    uint8_t tagged;
    return vstig_mavlink_records(rx, frame, sysid, compid, out, NULL, &tagged, from_sysid, from_compid);
}

uint8_t vstig_mavlink_records(vstig_mavlink_rx_t *rx, const uint8_t *frame, uint8_t sysid, uint8_t compid,
                              vstig_msg_t out[VSTIG_MAVLINK_MAX_MESSAGES],
                              uint8_t records[VSTIG_MAVLINK_MAX_RECORDS * VSTIG_RECORD_SIZE], uint8_t *tagged,
                              uint8_t *from_sysid, uint8_t *from_compid) {
    uint8_t payload[TUNNEL_SIZE];
    uint8_t carried, i, n, size, most;
    uint16_t type;
    *tagged = 0;
    if ((frame[7] | frame[8] << 8 | (uint32_t)frame[9] << 16) != VSTIG_MAVLINK_TUNNEL) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_OTHER_MESSAGE);
        return 0;
    }
    memset(payload, 0, sizeof payload);
    memcpy(payload, frame + VSTIG_MAVLINK_HEADER, frame[1] < TUNNEL_SIZE ? frame[1] : TUNNEL_SIZE);
    type = (uint16_t)(payload[0] | payload[1] << 8);
    if (type != VSTIG_MAVLINK_PAYLOAD_TYPE && type != VSTIG_MAVLINK_PAYLOAD_TYPE_TAGGED) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_OTHER_PAYLOAD_TYPE);
        return 0;
    }
    if ((payload[2] != 0 && payload[2] != sysid) || (payload[3] != 0 && payload[3] != compid)) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_NOT_FOR_US);
        return 0;
    }
    carried = payload[4];
    size = type == VSTIG_MAVLINK_PAYLOAD_TYPE_TAGGED ? VSTIG_RECORD_SIZE : VSTIG_MESSAGE_SIZE;
    most = size == VSTIG_RECORD_SIZE ? VSTIG_MAVLINK_MAX_RECORDS : VSTIG_MAVLINK_MAX_MESSAGES;
    if (carried == 0 || carried % size || carried > most * size) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_BAD_LENGTH);
        return 0;
    }
    n = (uint8_t)(carried / size);
    for (i = 0; i < n; i++) vstig_msg_decode(payload + TUNNEL_HEAD + (uint8_t)(size * i), &out[i]);
    if (size == VSTIG_RECORD_SIZE && records) {
        memcpy(records, payload + TUNNEL_HEAD, carried);
        *tagged = 1;
    }
    *from_sysid = frame[5];
    *from_compid = frame[6];
    return n;
}
