/* The swarm key's part of an Engine (tags.c): libvstig's vstig_tagged beside the engine, for the deliveries. */
#ifndef VSTIG_EXT_TAGS_H
#define VSTIG_EXT_TAGS_H

#include "ext.h"

#define VX_BATCH_MARKER 161u /* 0xA1, the first byte of N records where untagged messages would be 8*N bytes (XBee) */

/* One authenticated message as a unit carried it (vstig_hw.auth.Tagged), and its message's place in the unit. */
typedef struct {
    vstig_msg_t msg;
    uint32_t epoch;
    uint8_t tag[VSTIG_TAG_SIZE];
    size_t place;
} vx_record_t;

/* The records of one unit, in the order its messages came (a Receiver's, for its link's check). */
typedef struct {
    vx_record_t *at;
    size_t n, cap;
    uint8_t lost; /* no memory for one: raised when the unit's drops are harvested */
} vx_records_t;

/* Keeps one more record (its message at `place`); on no memory, notes it in `lost`. */
void vx_records_add(vx_records_t *records, const vstig_msg_t *msg, const uint8_t *epoch_and_tag, size_t place);

typedef struct {
    vstig_tagged_t tagged;
    vstig_auth_policy_t policy;  /* of the link the unit being received came on (SignedEngine.policy) */
    const vx_record_t *records;  /* the compiled delivery's unit: its records, or NULL */
    size_t nrecords;
    uint32_t *slots;             /* records of a long unit by message (record index + 1; 0 free), nslots of them */
    size_t nslots;
    PyObject *records_dict;      /* the Python delivery's: Signing.records (Message -> Tagged), or NULL */
    PyObject *policies;          /* vstig_hw.tagged.AuthPolicy's members in libvstig's order */
    PyObject *record_type;       /* vstig_hw.auth.Tagged */
} vx_tags_t;

/* Tags for `engine` under the 32-byte master secret `key` (bytes); NULL with an exception. */
vx_tags_t *vx_tags_new(vstig_engine_t *engine, PyObject *key, int stigmergy, PyObject *policies,
                       PyObject *record_type);
void vx_tags_free(vx_tags_t *tags);
int vx_tags_traverse(vx_tags_t *tags, visitproc visit, void *arg);
void vx_tags_clear(vx_tags_t *tags);

/* Signing.check for one unit the compiled delivery decoded on a link with `policy` (its Receiver's): each message
 * its policy refuses is taken out of msgs[0..*n), counted and told by `refuse` (the link's Signing.refuse, called
 * with the message, the counter's name, t, the sender or None, and `listeners`); the records of those that pass
 * are the engine's until vx_tags_unit_done. 0, or -1 with an exception. */
int vx_tags_check_unit(vx_tags_t *tags, vstig_auth_policy_t policy, vx_records_t *records, PyObject *refuse,
                       double t, vstig_msg_t *msgs, size_t *n, int named, unsigned long long sender,
                       PyObject *listeners);
void vx_tags_unit_done(vx_tags_t *tags, vx_records_t *records);

/* The engine's receive of a message that passed its link's check (SignedEngine.receive): under the unit's policy,
 * with its record if the unit carried one. A vstig_outcome_t, or -1 with an exception (a record lookup failed). */
int vx_tags_receive(vx_tags_t *tags, const vstig_msg_t *msg);
/* The record of the unit's message `msg`, if it came with one: 1 and *record set, 0 when untagged, -1 error. */
int vx_tags_record_in_unit(vx_tags_t *tags, const vstig_msg_t *msg, vx_record_t *record);

/* Engine's Python face with a swarm key: record_of(msg), policy, records. */
PyObject *vx_tags_record_of(vx_tags_t *tags, PyObject *msg_obj);
PyObject *vx_tags_get_policy(vx_tags_t *tags);
int vx_tags_set_policy(vx_tags_t *tags, PyObject *value);
PyObject *vx_tags_get_records(vx_tags_t *tags);
int vx_tags_set_records(vx_tags_t *tags, PyObject *value);

#endif /* VSTIG_EXT_TAGS_H */
