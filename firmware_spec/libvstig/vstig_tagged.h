/*
 * vstig_tagged: an engine with tags beside it (SPEC.md 10.4 and 10.6), for a node that holds the swarm's
 * master secret (a gateway, or a trusted robot). The C twin of vstig_hw/tagged.py (TaggedStigmergy), held
 * equal by tests/spec/test_spec_c_tagged.py. The engine itself is unchanged: this checks each message's tag,
 * refuses what the link's policy refuses, refuses by (epoch, timestamp) what is older before the engine's
 * 16-bit compare sees it, and keeps each entry's epoch and tag for every re-broadcast.
 *
 * RAM: 21 bytes per key on an AVR beside the engine's table (vstig_proof_t), and 32 for the prepared master.
 * Each message checked costs three BLAKE2s compressions (the writer's key, its key block, the tag), or one for a
 * writer whose prepared key is cached (VSTIG_WRITER_KEYS places, 0 by default; a gateway keeps 1024), and none for
 * a re-broadcast of the entry held (the same entry, epoch and tag as its proof: checked when it was kept). Proofs
 * are found as the engine finds its entries (open addressing: with 32768 places, one comparison).
 */
#ifndef VSTIG_TAGGED_H
#define VSTIG_TAGGED_H

#include <stdint.h>

#include "vstig_auth.h"
#include "vstig_engine.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Writers whose prepared keys a node keeps (direct-mapped by robot id): a power of two, or 0 for none. */
#ifndef VSTIG_WRITER_KEYS
#define VSTIG_WRITER_KEYS 0u
#endif

typedef enum { VSTIG_AUTH_REQUIRE = 0, VSTIG_AUTH_PREFER, VSTIG_AUTH_OFF } vstig_auth_policy_t;

/* vstig_tagged_receive's results beside the engine's outcomes: refused before the engine saw the message. */
#define VSTIG_REFUSED_UNTAGGED 16
#define VSTIG_REFUSED_BAD_TAG 17

/* vstig_proof_t.kind: what the proof of a key's entry is */
#define VSTIG_PROOF_NONE 0u     /* none (the place stays the key's, as the engine's table keeps its keys) */
#define VSTIG_PROOF_UNTAGGED 1u /* the entry was kept untagged */
#define VSTIG_PROOF_TAGGED 2u   /* `tag` is the writer's, checked */

typedef struct {
    uint16_t key;        /* 0xFFFF: a free place */
    uint8_t kind;        /* VSTIG_PROOF_* */
    vstig_entry_t entry; /* the entry the proof belongs to: the engine may move on without it */
    uint32_t epoch;
    uint8_t tag[VSTIG_TAG_SIZE];
} vstig_proof_t;

typedef struct {
    uint16_t robot;
    uint8_t ready; /* 1: `key` is robot's prepared key */
    vstig_tag_key_t key;
} vstig_writer_key_t;

typedef struct {
    vstig_engine_t *engine;
    vstig_tag_key_t master;
    uint16_t stigmergy;
    vstig_proof_t proofs[VSTIG_KEYS];
    uint32_t refused_untagged, refused_bad_tag, replays;
#if VSTIG_WRITER_KEYS
    vstig_writer_key_t writers[VSTIG_WRITER_KEYS];
#endif
} vstig_tagged_t;

void vstig_tagged_init(vstig_tagged_t *t, vstig_engine_t *engine, const uint8_t master[VSTIG_KEY_SIZE],
                       uint16_t stigmergy);
/* A write of this node, tagged with its own key: vstig_engine_put's result. */
int vstig_tagged_put(vstig_tagged_t *t, uint16_t key, uint16_t value);
/* A message heard on a link with `policy`; `epoch` and `tag` are its record's, or NULL when it came untagged.
 * Returns a vstig_outcome_t, or VSTIG_REFUSED_UNTAGGED / VSTIG_REFUSED_BAD_TAG (counted). */
int vstig_tagged_receive(vstig_tagged_t *t, vstig_auth_policy_t policy, const vstig_msg_t *msg,
                         const uint32_t *epoch, const uint8_t *tag);
/* vstig_tagged_receive in two steps, for a node that refuses before its guard and intake: the check by policy
 * and tag (0 when the message passes, else the refusal, counted), then the receive of a message that passed (its
 * record is kept as a checked proof: never apply one that was not checked). */
int vstig_tagged_check(vstig_tagged_t *t, vstig_auth_policy_t policy, const vstig_msg_t *msg, const uint32_t *epoch,
                       const uint8_t *tag);
int vstig_tagged_apply(vstig_tagged_t *t, vstig_auth_policy_t policy, const vstig_msg_t *msg, const uint32_t *epoch,
                       const uint8_t *tag);
/* The record of a drained message: 1 and its entry's epoch and writer's tag (zeros for an empty GET), or 0
 * when no checked proof is held, and a link that requires tags must not carry it. */
uint8_t vstig_tagged_record(const vstig_tagged_t *t, const vstig_msg_t *msg, uint32_t *epoch,
                            uint8_t tag[VSTIG_TAG_SIZE]);

#ifdef __cplusplus
}
#endif

#endif
