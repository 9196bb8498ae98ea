/*
 * vstig_xbee: Digi XBee API frames carrying our messages (SPEC.md 6.9). Part of libvstig.
 *
 *   0x7E | length (u16 big-endian) | frame data | checksum (0xFF - sum of the frame data)
 *
 * API mode 2 (AP=2) escapes 0x7E, 0x7D, 0x11 and 0x13 after the 0x7E as 0x7D, byte ^ 0x20.
 * A host sends Transmit Requests (0x10) whose RF data are N messages back to back, as many
 * as the module's maximum payload (NP) holds, and hears Receive Packets (0x90): the 64-bit
 * source address, then RF data of whole messages.
 *
 * The receiver is fed one byte at a time and resynchronises at the next 0x7E after anything
 * that is not a frame, counting one drop per bad unit: noise (a run of bytes outside any frame,
 * once), escape (mode 2: 0x7D before a byte it never escapes, a 0x7E included, or 0x11/0x13 left raw),
 * frame_length (0 or above VSTIG_XBEE_MAX_FRAME_DATA), truncated (mode 2: the next 0x7E came
 * first; either mode: vstig_xbee_flush, the line went quiet) and checksum. In mode 1 a 0x7E
 * may be data, so the bytes of a bad frame are searched again for one: a fed byte can complete
 * more than one frame (vstig_xbee_next gives the others). No 64-bit arithmetic: addresses are
 * 8 bytes, most significant first.
 */
#ifndef VSTIG_XBEE_H
#define VSTIG_XBEE_H

#include "vstig_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

#define VSTIG_XBEE_START 0x7Eu
#define VSTIG_XBEE_TRANSMIT_REQUEST 0x10u
#define VSTIG_XBEE_RECEIVE_PACKET 0x90u
#define VSTIG_XBEE_TX_STATUS 0x8Bu
#define VSTIG_XBEE_MODEM_STATUS 0x8Au
#define VSTIG_XBEE_AT_RESPONSE 0x88u

/* Frame data longer than this is a corrupted length: the largest a swarm radio sends is a
 * Receive Packet with 256 bytes of RF data (268 bytes). */
#define VSTIG_XBEE_MAX_FRAME_DATA 512u
#define VSTIG_XBEE_RX_HEADER 12u /* 0x90, source64, source16, options */
#define VSTIG_XBEE_TX_HEADER 14u /* 0x10, frame id, dest64, dest16, radius, options */
/* Messages one frame carries at most, either way (the RF data of the longest frame). */
#define VSTIG_XBEE_MAX_MESSAGES ((VSTIG_XBEE_MAX_FRAME_DATA - VSTIG_XBEE_TX_HEADER) / VSTIG_MESSAGE_SIZE)
/* The RF payload assumed until the module says its NP: 64 bytes fit every XBee. */
#define VSTIG_XBEE_DEFAULT_MAX_PAYLOAD 64u
/* Bytes one frame takes on the UART at most: escaped, everything doubles after the 0x7E. */
#define VSTIG_XBEE_WIRE_MAX (1u + 2u * (VSTIG_XBEE_MAX_FRAME_DATA + 3u))

/* ---- receiving ----------------------------------------------------------- */
typedef struct {
    uint8_t raw[VSTIG_XBEE_WIRE_MAX]; /* bytes held: the frame arriving at raw[head], then bytes not yet scanned */
    uint8_t data[VSTIG_XBEE_MAX_FRAME_DATA + 3u]; /* the frame arriving, unescaped: length, frame data, checksum */
    uint16_t head, pos, avail; /* raw[head..pos) scanned (the frame so far), raw[pos..avail) still to scan */
    uint16_t got;              /* bytes in data */
    uint16_t wire_at, wire_len; /* the last whole frame as it crossed the UART: raw[wire_at..+wire_len) */
    uint8_t escaped;  /* API mode 2 */
    uint8_t in_frame; /* a 0x7E was seen at raw[head] */
    uint8_t escaping; /* mode 2: the last byte was 0x7D */
    uint8_t counted;  /* the bytes being skipped are already counted (noise, or a bad frame's remains) */
    uint8_t final;    /* vstig_xbee_flush: what is still arriving never will */
    vstig_drops_t drops;
} vstig_xbee_rx_t;

void vstig_xbee_rx_init(vstig_xbee_rx_t *rx, uint8_t escaped);
/* Feed one byte; 1 when a frame is whole: its frame data are vstig_xbee_frame_data(rx), its
 * bytes on the wire vstig_xbee_wire(rx). Then call vstig_xbee_next until it returns 0. */
uint8_t vstig_xbee_feed(vstig_xbee_rx_t *rx, uint8_t byte);
/* The next frame in the bytes already held (mode 1, after a bad frame); 0 when there is none. */
uint8_t vstig_xbee_next(vstig_xbee_rx_t *rx);
/* The line went quiet: a frame still arriving is `truncated`, and the frames that began in its
 * bytes are read (1: one is whole; vstig_xbee_next for more). Then the receiver starts afresh. */
uint8_t vstig_xbee_flush(vstig_xbee_rx_t *rx);
/* Forget everything held (a reopened port); the drops stay. */
void vstig_xbee_rx_reset(vstig_xbee_rx_t *rx);
/* Something came since the last frame: part of one, or bytes skipped (a run the line going quiet ends). */
#define vstig_xbee_holding(rx) ((rx)->head != (rx)->avail || (rx)->counted)
#define vstig_xbee_frame_data(rx) ((const uint8_t *)(rx)->data + 2)
#define vstig_xbee_frame_len(rx) ((uint16_t)((rx)->got - 3u))
#define vstig_xbee_wire(rx) ((const uint8_t *)(rx)->raw + (rx)->wire_at)

/* What a frame's data are for a link: */
#define VSTIG_XBEE_DROPPED 0u  /* counted in drops: unknown_type, or bad_length */
#define VSTIG_XBEE_MESSAGES 1u /* a Receive Packet (source set) or a Transmit Request (ours, in a capture) */
#define VSTIG_XBEE_REPORT 2u   /* the module's own news (Transmit Status, Modem Status, AT response) */
/* The messages of one frame's data into out (room for VSTIG_XBEE_MAX_MESSAGES), *n of them;
 * a Receive Packet's 64-bit source into source[8] (*has_source 1). RF data that are not whole
 * messages, or a frame too short for its header, are bad_length. */
uint8_t vstig_xbee_messages(const uint8_t *frame_data, uint16_t len, vstig_msg_t *out, uint8_t *n,
                            uint8_t source[8], uint8_t *has_source, vstig_drops_t *drops);

/* ---- sending ------------------------------------------------------------- */
typedef struct {
    uint8_t dest[8];   /* 64-bit destination, most significant first (000000000000FFFF: broadcast) */
    uint8_t escaped;   /* API mode 2 */
    uint8_t per_frame; /* messages a frame carries: NP / 8, at least 1, at most VSTIG_XBEE_MAX_MESSAGES */
    uint8_t frame_id;  /* the last frame id given (1..255, cycling) */
    uint8_t report;    /* the next frame asks the module for a Transmit Status */
} vstig_xbee_tx_t;

/* dest NULL: broadcast. Messages per frame from VSTIG_XBEE_DEFAULT_MAX_PAYLOAD. */
void vstig_xbee_tx_init(vstig_xbee_tx_t *tx, uint8_t escaped, const uint8_t dest[8]);
/* What the module said its NP is: as many messages a frame as it holds (1..VSTIG_XBEE_MAX_MESSAGES). */
void vstig_xbee_max_payload(vstig_xbee_tx_t *tx, uint16_t np);
/* A control period passed: the next frame has a frame id (1..255), so the module reports its
 * delivery; the others carry 0. */
void vstig_xbee_tick(vstig_xbee_tx_t *tx);
/* Bytes of the Transmit Requests that carry n messages, at most (worst case, escaped). */
#define VSTIG_XBEE_TX_BYTES(n) ((size_t)(n) * 2u * VSTIG_MESSAGE_SIZE + \
                                ((size_t)(n) + 1u) * (1u + 2u * (VSTIG_XBEE_TX_HEADER + 3u)))
/* The Transmit Requests for msgs[0..n), in order, each as full as per_frame allows, into out
 * (VSTIG_XBEE_TX_BYTES(n)); returns the bytes written. */
size_t vstig_xbee_encode(vstig_xbee_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out);
/* Bytes of a Transmit Request of len bytes of RF data, at most (escaped). */
#define VSTIG_XBEE_TRANSMIT_BYTES(len) (1u + 2u * (2u + VSTIG_XBEE_TX_HEADER + (size_t)(len) + 1u))
/* One Transmit Request carrying rf[0..len) as its RF data (a tagged batch, SPEC.md 10.5), into out
 * (VSTIG_XBEE_TRANSMIT_BYTES(len)); returns the bytes written. */
size_t vstig_xbee_transmit(vstig_xbee_tx_t *tx, const uint8_t *rf, uint16_t len, uint8_t *out);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_XBEE_H */
