/*
 * vstig_serial: the serial frame of every UART link and the framings on it: cobs8,
 * epuck4, kilobot and kilobot-ohc (SPEC.md 6.0 to 6.4). Part of libvstig.
 *
 * Every decoder is a small struct the caller owns (static or on the stack) and feeds
 * one byte or one word at a time, or a whole buffer (vstig_serial_receive); drops are
 * counted in it by reason.
 */
#ifndef VSTIG_SERIAL_H
#define VSTIG_SERIAL_H

#include "vstig_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- the serial frame (SPEC.md 6.0): COBS(payload || crc16_le) || 0x00 --- */
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
/* The same for a receiver of two payload sizes (cobs8 with authenticated messages, SPEC.md 10.5): the size of
 * the payload accepted (`want` or `also`), or 0. */
uint8_t vstig_deframer_feed_either(vstig_deframer_t *d, uint8_t byte, uint8_t want, uint8_t also);
/* vstig_deframer_feed_either over data[0..len) up to and including its first 0x00 (the end of a frame), as that
 * many calls of it would do, without a call per byte: returns how many bytes it took, and in *size what the
 * call for the last of them would have returned (0 when no frame ended there, or the frame was dropped). */
size_t vstig_deframer_feed_run(vstig_deframer_t *d, const uint8_t *data, size_t len, uint8_t want, uint8_t also,
                               uint8_t *size);

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

typedef struct {
    uint32_t chunk[3];
    uint16_t order[3]; /* arrival number of each held fragment (compared modulo 2^16) */
    uint8_t born[3];   /* tick count when each fragment arrived (compared modulo 2^8) */
    uint8_t held;      /* bit i: chunk[i] holds a fragment; 0: the slot is free */
    uint8_t group;
} vstig_epuck4_partial_t;

typedef struct {
    vstig_epuck4_partial_t slot[VSTIG_EPUCK4_SLOTS]; /* with fewer than 16, busy slots go oldest first */
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

/* ---- a serial link's receiver over buffers --------------------------------- */
#define VSTIG_COBS8 0u
#define VSTIG_EPUCK4 1u
#define VSTIG_KILOBOT 2u

typedef struct {
    vstig_deframer_t deframer;
    uint8_t framing;      /* VSTIG_COBS8, VSTIG_EPUCK4 or VSTIG_KILOBOT */
    uint8_t kilobot_type; /* kilobot: the message type of the swarm (VSTIG_KILOBOT_TYPE) */
    vstig_epuck4_reassembler_t *epuck4; /* epuck4: the caller's reassembler (it counts the epuck4 drops) */
} vstig_serial_rx_t;

/* 0, or VSTIG_ERR_ARG for an unknown framing, a kilobot type of 0x80 or more, or an epuck4
 * receiver without a reassembler. */
int vstig_serial_rx_init(vstig_serial_rx_t *rx, uint8_t framing, uint8_t kilobot_type,
                         vstig_epuck4_reassembler_t *epuck4);
/* Feed len received bytes; every message they complete is written to out, at most max of them.
 * Returns how many were written; *used is how many bytes were taken, len unless out filled up
 * first (call again with the rest). Bad frames are counted in rx->deframer.drops. */
size_t vstig_serial_receive(vstig_serial_rx_t *rx, const uint8_t *data, size_t len, size_t *used,
                            vstig_msg_t *out, size_t max);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_SERIAL_H */
