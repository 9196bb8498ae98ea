/*
 * vstig_wire: reference C99 codec for vstig-hw robot firmware (firmware_spec/SPEC.md).
 *
 * Portable: fixed-width integers only, no malloc, no floating point, no 64-bit
 * arithmetic, no lookup tables. It builds for an 8-bit AVR as well as for a PC.
 * Every decoder is a small struct the caller owns (static or on the stack) and
 * feeds one byte or one word at a time; drops are counted in it by reason.
 */
#ifndef VSTIG_WIRE_H
#define VSTIG_WIRE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- the 8-byte message (SPEC.md section 2) ------------------------------ */
#define VSTIG_MESSAGE_SIZE 8u
#define VSTIG_PUT 0u
#define VSTIG_GET 1u
#define VSTIG_KEY_MAX 0x7FFFu
#define VSTIG_TS_NONE 0u /* reserved: "no entry" */

typedef struct {
    uint8_t op;         /* VSTIG_PUT or VSTIG_GET */
    uint16_t key;       /* 0..0x7FFF */
    uint16_t value;
    uint16_t timestamp; /* 0 is reserved */
    uint16_t robot;     /* the robot that wrote the value */
} vstig_msg_t;

/* Writes the 8 wire bytes. Out-of-range fields are masked (op to 1 bit, key to 15). */
void vstig_msg_encode(const vstig_msg_t *msg, uint8_t out[VSTIG_MESSAGE_SIZE]);
/* Any 8 bytes are a message. */
void vstig_msg_decode(const uint8_t in[VSTIG_MESSAGE_SIZE], vstig_msg_t *msg);

/* ---- timestamps (SPEC.md section 3) -------------------------------------- */
/* 1 when timestamp a is strictly newer than b (serial-number arithmetic, 0 reserved). */
uint8_t vstig_ts_newer(uint16_t a, uint16_t b);
/* The timestamp a local put gives after ts: ts + 1, skipping 0 (65535 -> 1). */
uint16_t vstig_ts_next(uint16_t ts);

/* ---- CRCs ---------------------------------------------------------------- */
/* CRC-16/MCRF4XX, byte-wise without a table (avr-libc's _crc_ccitt_update computes the same). */
#define VSTIG_CRC16_INIT 0xFFFFu
uint16_t vstig_crc16_update(uint16_t crc, uint8_t byte);
uint16_t vstig_crc16(const uint8_t *data, size_t len);
/* CRC-32/ISO-HDLC (zlib's crc32), bit by bit. */
uint32_t vstig_crc32(const uint8_t *data, size_t len);

/* ---- drop counters ------------------------------------------------------- */
typedef enum {
    VSTIG_DROP_COBS = 0,   /* undecodable COBS */
    VSTIG_DROP_CRC,        /* CRC mismatch */
    VSTIG_DROP_BAD_LENGTH, /* payload length not this framing's */
    VSTIG_DROP_OVERLONG,   /* no delimiter within VSTIG_FRAME_MAX bytes */
    VSTIG_DROP_BAD_INDEX,  /* epuck4: index 3 */
    VSTIG_DROP_COLLISION,  /* epuck4: a fragment clashed with a stored one (older ones evicted) */
    VSTIG_DROP_CHECK,      /* epuck4: complete set failed the CRC-32 check */
    VSTIG_DROP_STALE,      /* epuck4: fragments expired */
    VSTIG_DROP_DUPLICATE,  /* epuck4: identical fragment already held */
    VSTIG_DROP_FOREIGN_TYPE, /* kilobot: another message type (other Kilobot traffic) */
    VSTIG_DROP_BAD_VERSION,  /* kilobot: data[8] is not format version 1 */
    VSTIG_DROP_REASONS
} vstig_drop_t;

typedef struct {
    uint16_t count[VSTIG_DROP_REASONS]; /* saturating */
} vstig_drops_t;

/* The reason's name as SPEC.md spells it ("crc", "bad_length", ...). */
const char *vstig_drop_name(vstig_drop_t reason);

/* ---- the serial frame (SPEC.md section 6): COBS(payload || crc16_le) || 0x00 */
#define VSTIG_FRAME_MAX 64u /* longest run of non-zero bytes a receiver buffers */
/* Bytes a frame of a len-byte payload takes on the wire (len <= 60). */
#define VSTIG_FRAME_SIZE(len) ((len) + 4u)

/* Writes the frame for payload[0..len) into out (VSTIG_FRAME_SIZE(len) bytes); returns its size.
 * len must be at most 60 (every vstig payload is 4, 8 or 10 bytes). */
uint8_t vstig_frame_encode(const uint8_t *payload, uint8_t len, uint8_t *out);

typedef struct {
    uint8_t buf[VSTIG_FRAME_MAX]; /* after a frame is accepted: its payload */
    uint8_t len;
    uint8_t discarding; /* after overlong: skip to the next 0x00 */
    vstig_drops_t drops;
} vstig_deframer_t;

void vstig_deframer_init(vstig_deframer_t *d);
/* Feed one received byte. Returns 1 when a frame whose payload is exactly `want` bytes
 * and whose CRC checks has ended with this byte: the payload is d->buf[0..want). */
uint8_t vstig_deframer_feed(vstig_deframer_t *d, uint8_t byte, uint8_t want);

/* ---- cobs8: one message per serial frame (SPEC.md section 6.1) ----------- */
#define VSTIG_COBS8_FRAME_SIZE 12u
uint8_t vstig_cobs8_encode(const vstig_msg_t *msg, uint8_t out[VSTIG_COBS8_FRAME_SIZE]);
uint8_t vstig_cobs8_feed(vstig_deframer_t *d, uint8_t byte, vstig_msg_t *out);

/* ---- epuck4: three 32-bit radio words (SPEC.md section 6.2) -------------- */
void vstig_epuck4_encode(const vstig_msg_t *msg, uint32_t words[3]);
/* A word as its 8-byte UART frame (payload = the word, big-endian). */
#define VSTIG_EPUCK4_FRAME_SIZE 8u
uint8_t vstig_epuck4_word_frame(uint32_t word, uint8_t out[VSTIG_EPUCK4_FRAME_SIZE]);
/* Feed one UART byte; returns 1 when a whole word arrived in *word. */
uint8_t vstig_epuck4_uart_feed(vstig_deframer_t *d, uint8_t byte, uint32_t *word);

#ifndef VSTIG_EPUCK4_SLOTS
#define VSTIG_EPUCK4_SLOTS 16u /* one per group: with fewer, busy slots are evicted oldest first */
#endif

typedef struct {
    uint32_t chunk[3];
    uint16_t order[3]; /* arrival number of each held fragment (compared modulo 2^16) */
    uint8_t born[3];   /* tick count when each fragment arrived (compared modulo 2^8) */
    uint8_t held;      /* bit i: chunk[i] holds a fragment; 0: the slot is free */
    uint8_t group;
} vstig_epuck4_partial_t;

typedef struct {
    vstig_epuck4_partial_t slot[VSTIG_EPUCK4_SLOTS];
    uint16_t arrivals;
    uint8_t now;
    uint8_t expiry_ticks; /* 1..254 */
    vstig_drops_t drops;
} vstig_epuck4_reassembler_t;

void vstig_epuck4_init(vstig_epuck4_reassembler_t *r, uint8_t expiry_ticks); /* SPEC default: 3 */
/* Feed one radio word; returns 1 when it completed a message (in *out). */
uint8_t vstig_epuck4_feed(vstig_epuck4_reassembler_t *r, uint32_t word, vstig_msg_t *out);
/* One control period passed: expires old partials. */
void vstig_epuck4_tick(vstig_epuck4_reassembler_t *r);

/* ---- kilobot: kilolib message_t (SPEC.md section 6.3) -------------------- */
#define VSTIG_KILOBOT_VERSION 0x01u
#define VSTIG_KILOBOT_TYPE 0x56u /* default message type; any value < 0x80 may be configured */
/* kilolib's message CRC over data[9] + type (10 bytes). */
uint16_t vstig_kilobot_crc(const uint8_t head[10]);
/* The whole 12-byte message_t: data[9], type, crc (little-endian, as the AVR stores it). */
void vstig_kilobot_encode(const vstig_msg_t *msg, uint8_t type, uint8_t out[12]);
/* A received message_t's first 10 bytes (the radio checked its CRC): 1 if it is ours. */
uint8_t vstig_kilobot_accept(const uint8_t head[10], uint8_t type, vstig_msg_t *out, vstig_drops_t *drops);
/* The UART form: a serial frame of the 10-byte head. */
#define VSTIG_KILOBOT_FRAME_SIZE 14u
uint8_t vstig_kilobot_frame(const vstig_msg_t *msg, uint8_t type, uint8_t out[VSTIG_KILOBOT_FRAME_SIZE]);
uint8_t vstig_kilobot_uart_feed(vstig_deframer_t *d, uint8_t byte, uint8_t type, vstig_msg_t *out);

/* ---- kilobot-ohc: PC -> overhead controller packets (SPEC.md section 6.4) */
#define VSTIG_OHC_PACKET_SIZE 132u
#define VSTIG_OHC_FORWARDMSG 2u       /* repeated until the next packet */
#define VSTIG_OHC_FORWARDMSGSINGLE 6u /* sent once */
void vstig_ohc_packet(const vstig_msg_t *msg, uint8_t packet_type, uint8_t type, uint8_t out[VSTIG_OHC_PACKET_SIZE]);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_WIRE_H */
