/*
 * vstig_wire: the 8-byte message, timestamps, CRCs and drop counters (SPEC.md sections 2,
 * 3, 6.0.2 and 6.6). Part of libvstig (vstig.h includes every part).
 *
 * Portable: fixed-width integers only, no malloc, no floating point, no 64-bit
 * arithmetic, no lookup tables. It builds for an 8-bit AVR as well as for a PC.
 */
#ifndef VSTIG_WIRE_H
#define VSTIG_WIRE_H

#include <stddef.h>
#include <stdint.h>

#include "vstig_config.h"

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
/* How many vstig_ts_next steps lead from older (nonzero) to newer, for newer newer than older. */
uint16_t vstig_ts_steps(uint16_t newer, uint16_t older);

/* ---- CRCs ---------------------------------------------------------------- */
/* CRC-16/MCRF4XX, byte-wise without a table (avr-libc's _crc_ccitt_update computes the same). */
#define VSTIG_CRC16_INIT 0xFFFFu
uint16_t vstig_crc16_update(uint16_t crc, uint8_t byte);
uint16_t vstig_crc16(const uint8_t *data, size_t len);
/* CRC-32/ISO-HDLC (zlib's crc32), bit by bit. */
uint32_t vstig_crc32(const uint8_t *data, size_t len);

/* ---- drop counters (SPEC.md 6.6) ----------------------------------------- */
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
    VSTIG_DROP_ERROR_FRAME,  /* CAN: an error frame */
    VSTIG_DROP_UNKNOWN_ID,   /* CAN: an ID outside the scheme */
    VSTIG_DROP_REMOTE_FRAME, /* CAN: RTR on a scheme ID */
    VSTIG_DROP_BAD_DLC,      /* CAN: a data length that is not a whole allowed number of messages */
    VSTIG_DROP_OP_MISMATCH,  /* CAN: a message whose op differs from the ID's (per message) */
    VSTIG_DROP_NOISE,        /* XBee: bytes outside any frame (a run counts once) */
    VSTIG_DROP_ESCAPE,       /* XBee mode 2: a bad escape, or a byte left raw that must be escaped */
    VSTIG_DROP_FRAME_LENGTH, /* XBee: a length of 0 or above VSTIG_XBEE_MAX_FRAME_DATA */
    VSTIG_DROP_TRUNCATED,    /* XBee: a frame cut short (the next 0x7E in mode 2, or the line went quiet) */
    VSTIG_DROP_CHECKSUM,     /* XBee: the checksum does not match */
    VSTIG_DROP_UNKNOWN_TYPE, /* XBee: a frame type a link does not use */
    VSTIG_DROP_REASONS
} vstig_drop_t;

typedef struct {
    uint16_t count[VSTIG_DROP_REASONS]; /* saturating */
} vstig_drops_t;

/* The reason's name as SPEC.md spells it ("crc", "bad_length", ...). */
const char *vstig_drop_name(vstig_drop_t reason);
/* Count one drop (saturating at 65535); `count` of them for vstig_drops_add. */
void vstig_drops_count(vstig_drops_t *drops, vstig_drop_t reason);
void vstig_drops_add(vstig_drops_t *drops, vstig_drop_t reason, uint16_t count);
void vstig_drops_clear(vstig_drops_t *drops);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_WIRE_H */
