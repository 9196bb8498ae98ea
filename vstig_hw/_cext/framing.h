/* A link's framing in C: what libvstig receives and encodes for it (framing.c), for the data path. */
#ifndef VSTIG_EXT_FRAMING_H
#define VSTIG_EXT_FRAMING_H

#include "ext.h"
#include "mavlink.h"
#include "tags.h"

#define VX_COBS8 0u   /* = VSTIG_COBS8 */
#define VX_EPUCK4 1u  /* = VSTIG_EPUCK4 */
#define VX_KILOBOT 2u /* = VSTIG_KILOBOT */
#define VX_CAN 3u
#define VX_XBEE 4u
#define VX_MAVLINK 5u
#define VX_FRAMINGS 6u

/* The wire bytes of one message in each serial framing (cobs8 12, epuck4 3 x 8, kilobot 14). */
#define VX_SERIAL_MAX_BYTES 24u

typedef struct {
    uint8_t kind;
    vstig_serial_rx_t serial;
    vstig_epuck4_reassembler_t epuck4;
    vstig_can_t can;
    vstig_xbee_rx_t xbee;
    vx_mav_rx_t mav;
    uint8_t has_sender;         /* XBee, MAVLink: the last unit's messages named their sender, `sender` */
    unsigned long long sender;  /* an XBee module's 64-bit source; MAVLink's sysid << 8 | compid */
    PyObject *drops; /* the Python framing's drop Counters: what libvstig counts is added there */
    PyObject *on_tick; /* called at each tick, or None (XBee: the framing's tick, for what it sends) */
    /* a link that checks tags (SPEC.md 10.6; cobs8 and CAN FD carry records, 10.5): its policy, the records of the
     * unit being decoded (each at its message's place: `emitted` so far), and its Signing.refuse (or None) */
    vstig_auth_policy_t policy;
    vx_records_t records;
    size_t emitted;
    PyObject *refuse;
} vx_rx_t;

typedef struct {
    uint8_t kind;
    uint8_t kilobot_type;
    vstig_can_t can;
    vstig_xbee_tx_t xbee; /* its frame ids and NP: the link's XBeeFraming sends with the same (`share`) */
    uint8_t records_per_frame; /* XBee: records a tagged batch carries ((the module's NP - 1) / 20) */
    vx_mav_tx_t mav;      /* its sequence and signing timestamps: the link's MavlinkFraming sends through it */
    PyObject *frame_type; /* CAN: can.Message, for the units handed to Python */
    PyObject *unit_template;   /* CAN: a frame_type() made once, copied per unit (NULL: frame_type is called) */
    Py_ssize_t unit_slots[6];  /* where the template's class keeps the fields a frame sets (framing.c UNIT_FIELDS) */
    /* a link that sends tags (cobs8, CAN FD, XBee: `send_tags`): the engine whose proofs go with each message,
     * whether the link requires them (one without a proof is then held back, counted in `tag_counters`'
     * held_unverified) */
    PyObject *tag_engine, *tag_counters;
    uint8_t tag_require;
} vx_tx_t;

typedef struct {
    PyObject_HEAD
    vx_rx_t rx;
} vx_receiver_t;

typedef struct {
    PyObject_HEAD
    vx_tx_t tx;
} vx_encoder_t;

/* Messages completed by len bytes of a serial stream, into out (room for max); *used: bytes taken. */
size_t vx_rx_bytes(vx_rx_t *rx, const uint8_t *data, size_t len, size_t *used, vstig_msg_t *out, size_t max);
/* XBee: the messages of one unit (whole frames, as the transport cuts them), into out (room for len / 8 + 1);
 * rx->has_sender and rx->sender: the source of the first Receive Packet that carried any. */
size_t vx_rx_xbee(vx_rx_t *rx, const uint8_t *data, size_t len, vstig_msg_t *out);
/* XBee or MAVLink: the messages of one unit (whole frames, as the transport cuts them), into out (room for
 * len / 8 + 1); rx->has_sender and rx->sender: the sender of the first frame that carried any. */
size_t vx_rx_whole(vx_rx_t *rx, const uint8_t *data, size_t len, vstig_msg_t *out);
/* The messages of one CAN frame, into out (room for 8); *sender: the node its ID names. A CAN FD frame of one
 * record (20 bytes) gives its message, and the record where the link checks tags. */
size_t vx_rx_frame(vx_rx_t *rx, const vstig_can_frame_t *frame, vstig_msg_t out[8], uint16_t *sender);
/* The unit's records were taken (or none were wanted): the next unit starts afresh. */
void vx_rx_unit_done(vx_rx_t *rx);
/* The python-can Message attributes the compiled path reads (declared slots of can.Message). */
typedef enum {
    VX_CAN_ID, VX_CAN_EXTENDED, VX_CAN_FD, VX_CAN_REMOTE, VX_CAN_ERROR, VX_CAN_DATA, VX_CAN_TIMESTAMP, VX_CAN_FIELDS
} vx_can_field_t;
/* A python-can Message's attribute (new reference), or NULL with an exception. */
PyObject *vx_can_field(PyObject *unit, vx_can_field_t field);
/* A python-can Message's fields as a libvstig frame; -1 with an exception if it has none of them. */
int vx_frame_of(PyObject *unit, vstig_can_frame_t *frame);
/* Adds what libvstig counted to the Python framing's drops; -1 on failure. */
int vx_rx_harvest(vx_rx_t *rx);

/* Bytes the wire form of n messages may take at most. */
size_t vx_tx_room(const vx_tx_t *tx, size_t n);
/* The wire bytes of n messages in a serial framing, into out (room for vx_tx_room(tx, n)). */
size_t vx_tx_bytes(vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out);
/* The CAN frames of n messages into frames (room for n); how many. */
size_t vx_tx_frames(const vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, vstig_can_frame_t *frames);
/* XBee: the most records a tagged batch carries (SPEC.md 10.5: a marker and records within the frame data). */
#define VX_XBEE_MAX_RECORDS ((VSTIG_XBEE_MAX_FRAME_DATA - VSTIG_XBEE_TX_HEADER - 1u) / VSTIG_RECORD_SIZE)

/* The wire form of n messages as the link's writer gets it (Link.units_of): serial bytes into out (room for
 * vx_tx_room(tx, n)), or CAN frames into frames (room for n); how many bytes or frames. A link that sends tags
 * (`send_tags`) sends each message with its entry's record, and holds back, counted, what it may not send (so
 * fewer, or none); -1 with an exception. */
Py_ssize_t vx_tx_wire(vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out, vstig_can_frame_t *frames);
/* A frame as a can.Message, for Python's writer (new reference). */
PyObject *vx_frame_unit(const vx_tx_t *tx, const vstig_can_frame_t *frame);

#endif /* VSTIG_EXT_FRAMING_H */
