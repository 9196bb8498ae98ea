/*
 * vstig_mavlink: our messages in MAVLink 2 TUNNEL (#385) messages, optionally signed (SPEC.md 6.10).
 * Part of libvstig.
 *
 *   0xFD | len | incompat | compat | seq | sysid | compid | msgid (u24 LE) | payload | crc (u16 LE)
 *        [| link id | timestamp (u48 LE) | signature (6)]      when incompat has bit 0x01
 *
 * crc: CRC-16/MCRF4XX over len..payload, then the message's CRC_EXTRA (TUNNEL 147, HEARTBEAT 50).
 * TUNNEL's payload: payload_type (u16 LE, ours 46449), target_system, target_component,
 * payload_length, payload[128] = up to 16 messages; trailing zero bytes are not sent. A TUNNEL of
 * payload_type 46450 carries up to 6 authenticated messages instead (20-byte records, SPEC.md 10.5).
 * signature: the first 6 bytes of SHA-256(key | frame through crc | link id | timestamp).
 *
 * The receiver is fed one byte at a time and resynchronises at the byte after a bad frame's start:
 * noise, incompat_flags, crc and (vstig_mavlink_flush: the line went quiet) truncated are counted here;
 * vstig_mavlink_check and vstig_mavlink_messages count what a whole frame gives no message for
 * (mavlink1, unsigned, signature; other_message, other_payload_type, not_for_us, bad_length). The
 * replay check between them (a timestamp per sysid, compid and link id) is the caller's.
 * No 64-bit arithmetic: timestamps are 6 bytes, least significant first.
 */
#ifndef VSTIG_MAVLINK_H
#define VSTIG_MAVLINK_H

#include "vstig_auth.h"
#include "vstig_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

#define VSTIG_MAVLINK_STX 0xFDu
#define VSTIG_MAVLINK_STX_V1 0xFEu
#define VSTIG_MAVLINK_SIGNED 0x01u
#define VSTIG_MAVLINK_HEADER 10u
#define VSTIG_MAVLINK_SIGNATURE 13u
#define VSTIG_MAVLINK_TUNNEL 385u
#define VSTIG_MAVLINK_HEARTBEAT 0u
#define VSTIG_MAVLINK_PAYLOAD_TYPE 46449u /* 0xB571, in MAVLink's range for local use */
#define VSTIG_MAVLINK_PAYLOAD_TYPE_TAGGED 46450u /* 0xB572: records, SPEC.md 10.5 */
#define VSTIG_MAVLINK_MAX_MESSAGES 16u
#define VSTIG_MAVLINK_MAX_RECORDS 6u /* 120 of the 128 bytes */
#define VSTIG_MAVLINK_FRAME_MAX (VSTIG_MAVLINK_HEADER + 255u + 2u + VSTIG_MAVLINK_SIGNATURE)
#define VSTIG_MAVLINK_KEY_SIZE 32u
#define VSTIG_MAVLINK_COMP_ID 191u /* MAV_COMP_ID_ONBOARD_COMPUTER */

typedef enum {
    VSTIG_MAVLINK_DROP_NOISE = 0,
    VSTIG_MAVLINK_DROP_INCOMPAT_FLAGS,
    VSTIG_MAVLINK_DROP_CRC,
    VSTIG_MAVLINK_DROP_TRUNCATED,
    VSTIG_MAVLINK_DROP_MAVLINK1,
    VSTIG_MAVLINK_DROP_UNSIGNED,
    VSTIG_MAVLINK_DROP_SIGNATURE,
    VSTIG_MAVLINK_DROP_REPLAY, /* counted by the caller's replay check */
    VSTIG_MAVLINK_DROP_OTHER_MESSAGE,
    VSTIG_MAVLINK_DROP_OTHER_PAYLOAD_TYPE,
    VSTIG_MAVLINK_DROP_NOT_FOR_US,
    VSTIG_MAVLINK_DROP_BAD_LENGTH,
    VSTIG_MAVLINK_DROP_REASONS
} vstig_mavlink_drop_t;

/* The reason's name as SPEC.md 6.6 spells it. */
const char *vstig_mavlink_drop_name(vstig_mavlink_drop_t reason);

/* ---- the crc and the signature -------------------------------------------- */
/* The crc of a frame whose len..payload are `data` (CRC_EXTRA appended). */
uint16_t vstig_mavlink_crc(const uint8_t *data, uint16_t len, uint8_t crc_extra);
/* The 6 signature bytes of `frame` (0xFD through the link id and timestamp: all but the signature). */
void vstig_mavlink_sign(const uint8_t key[VSTIG_MAVLINK_KEY_SIZE], const uint8_t *frame, uint16_t len,
                        uint8_t out[6]);

/* 1 if `data` is exactly one whole MAVLink 2 frame whose crc holds (where its message's CRC_EXTRA is known): what
 * the receiver would cut from it alone, with nothing counted (a UDP datagram's usual content), so it may be taken
 * as it is, without feeding it byte by byte. */
uint8_t vstig_mavlink_whole(const uint8_t *data, uint16_t len);

/* ---- sending -------------------------------------------------------------- */
typedef struct {
    uint8_t sysid, compid, target_system, target_component;
    uint8_t seq;
    const uint8_t *key; /* NULL: unsigned; else 32 bytes, kept by the caller */
    uint8_t link_id;
    uint8_t timestamp[6]; /* the last timestamp signed with; the caller may move it forward (its clock) */
} vstig_mavlink_tx_t;

void vstig_mavlink_tx_init(vstig_mavlink_tx_t *tx, uint8_t sysid, uint8_t compid, const uint8_t *key);
/* One TUNNEL carrying n (1..16) messages into out (VSTIG_MAVLINK_FRAME_MAX bytes); its length.
 * A signed frame takes the timestamp one more than the last. */
uint16_t vstig_mavlink_encode(vstig_mavlink_tx_t *tx, const vstig_msg_t *msgs, uint8_t n, uint8_t *out);
/* One tagged TUNNEL (payload_type 46450) carrying n (1..6) records, VSTIG_RECORD_SIZE bytes each back to back
 * (message || epoch || tag: vstig_tag makes the tag, vstig_tagged_record gives a relayed entry's). */
uint16_t vstig_mavlink_encode_tagged(vstig_mavlink_tx_t *tx, const uint8_t *records, uint8_t n, uint8_t *out);
/* The HEARTBEAT of an onboard controller (type 18, autopilot 8, active), once a second. */
uint16_t vstig_mavlink_heartbeat(vstig_mavlink_tx_t *tx, uint8_t *out);

/* ---- receiving ------------------------------------------------------------ */
typedef struct {
    uint8_t frame[VSTIG_MAVLINK_FRAME_MAX]; /* the frame arriving, from its start byte */
    uint8_t held[VSTIG_MAVLINK_FRAME_MAX + 1u]; /* bytes to scan again (after a bad frame) */
    uint16_t len;           /* bytes in frame */
    uint16_t held_at, held_len;
    uint16_t whole;         /* the length of the whole frame in `frame`, 0 if none */
    uint8_t counted;        /* the bytes being skipped are already counted */
    uint8_t final;          /* flushing: what is still arriving never will */
    uint16_t drops[VSTIG_MAVLINK_DROP_REASONS]; /* saturating */
} vstig_mavlink_rx_t;

void vstig_mavlink_rx_init(vstig_mavlink_rx_t *rx);
/* Feed one byte; 1 when a frame is whole: vstig_mavlink_frame(rx), vstig_mavlink_frame_len(rx).
 * Then call vstig_mavlink_next until it returns 0 (a bad frame's bytes may hold more). */
uint8_t vstig_mavlink_feed(vstig_mavlink_rx_t *rx, uint8_t byte);
uint8_t vstig_mavlink_next(vstig_mavlink_rx_t *rx);
/* The line went quiet: a frame still arriving is `truncated`, its bytes scanned again (1: a frame is whole;
 * vstig_mavlink_next for more). Then the receiver starts afresh. */
uint8_t vstig_mavlink_flush(vstig_mavlink_rx_t *rx);
#define vstig_mavlink_frame(rx) ((const uint8_t *)(rx)->frame)
#define vstig_mavlink_frame_len(rx) ((rx)->whole)
void vstig_mavlink_count(vstig_mavlink_rx_t *rx, vstig_mavlink_drop_t reason);

/* A whole frame's first checks (SPEC.md 6.10.3 rules 5 and 6): 0 for a MAVLink 1 frame and, with `key`, for
 * an unsigned or wrongly signed one, the reason counted in rx. The replay check comes next, the caller's
 * (vstig_mavlink_timestamp reads a frame's link id and timestamp; count VSTIG_MAVLINK_DROP_REPLAY). */
uint8_t vstig_mavlink_check(vstig_mavlink_rx_t *rx, const uint8_t *frame, uint16_t len, const uint8_t *key);
/* Then the messages of a checked frame for receiver (sysid, compid) (rules 7 to 11): their number (0: none,
 * the reason counted in rx) and the sender's sysid and compid. */
uint8_t vstig_mavlink_messages(vstig_mavlink_rx_t *rx, const uint8_t *frame, uint8_t sysid, uint8_t compid,
                               vstig_msg_t out[VSTIG_MAVLINK_MAX_MESSAGES], uint8_t *from_sysid,
                               uint8_t *from_compid);
/* vstig_mavlink_messages for a node that reads tags: the same messages and drops, and *tagged 1 when they came
 * as records (a TUNNEL of payload_type 46450), record i at records + VSTIG_RECORD_SIZE * i; 0 for untagged ones.
 * vstig_mavlink_messages gives a tagged TUNNEL's messages without their tags (a link with auth off). */
uint8_t vstig_mavlink_records(vstig_mavlink_rx_t *rx, const uint8_t *frame, uint8_t sysid, uint8_t compid,
                              vstig_msg_t out[VSTIG_MAVLINK_MAX_MESSAGES],
                              uint8_t records[VSTIG_MAVLINK_MAX_RECORDS * VSTIG_RECORD_SIZE], uint8_t *tagged,
                              uint8_t *from_sysid, uint8_t *from_compid);
/* A signed frame's link id and timestamp (6 bytes, least significant first); 0 if it is not signed. */
uint8_t vstig_mavlink_timestamp(const uint8_t *frame, uint16_t len, uint8_t *link_id, uint8_t stamp[6]);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_MAVLINK_H */
