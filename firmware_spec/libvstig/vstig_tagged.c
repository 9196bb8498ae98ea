/* vstig_tagged: see vstig_tagged.h. Each step names the line of vstig_hw/tagged.py it mirrors. */
#include "vstig_tagged.h"

#include <string.h>

#define FREE 0xFFFFu

static uint8_t same_entry(const vstig_entry_t *a, const vstig_entry_t *b) {
    return a->value == b->value && a->timestamp == b->timestamp && a->robot == b->robot;
}

/* The place of key's proof: where it is, or the first free place on its probe path (vstig_keymap_place's rule).
 * A key keeps its place once given (its proof may be VSTIG_PROOF_NONE), and proofs are kept only for keys the
 * engine holds, at most VSTIG_KEYS: a place is always found. */
static vstig_proof_t *place(const vstig_tagged_t *t, uint16_t key) {
    uint16_t p = (uint16_t)(key & (VSTIG_KEYS - 1u)), n;
    for (n = 0; n < VSTIG_KEYS; n++, p = (uint16_t)((p + 1u) & (VSTIG_KEYS - 1u))) {
        if (t->proofs[p].key == key || t->proofs[p].key == FREE) return (vstig_proof_t *)&t->proofs[p];
    }
    return NULL;
}

static vstig_proof_t *find(const vstig_tagged_t *t, uint16_t key) {
    vstig_proof_t *proof = place(t, key);
    return proof && proof->key == key && proof->kind != VSTIG_PROOF_NONE ? proof : NULL;
}

/* The writer's prepared key: from the cache (VSTIG_WRITER_KEYS), or derived from the master (two compressions). */
static const vstig_tag_key_t *writer_key(vstig_tagged_t *t, uint16_t robot, vstig_tag_key_t *scratch) {
    uint8_t robot_key[VSTIG_KEY_SIZE];
#if VSTIG_WRITER_KEYS
    vstig_writer_key_t *cached = &t->writers[robot & (VSTIG_WRITER_KEYS - 1u)];
    if (cached->ready && cached->robot == robot) return &cached->key;
    scratch = &cached->key;
    cached->robot = robot;
    cached->ready = 1;
#endif
    vstig_robot_key(&t->master, robot, robot_key);
    vstig_tag_key_init(scratch, robot_key);
    return scratch;
}

/* (epoch, entry) held for key: the proof's epoch when it belongs to the entry, else 0 (`_epoch_entry`). */
static uint32_t held(vstig_tagged_t *t, uint16_t key, vstig_entry_t *local, uint8_t *has) {
    vstig_proof_t *proof = find(t, key);
    *has = vstig_engine_entry(t->engine, key, local);
    return (*has && proof && same_entry(&proof->entry, local)) ? proof->epoch : 0u;
}

/* The tag the writer of (key, entry) makes at epoch: its key from the master, then the tag. */
static void writer_tag(vstig_tagged_t *t, uint16_t key, const vstig_entry_t *entry, uint32_t epoch,
                       uint8_t tag[VSTIG_TAG_SIZE]) {
    uint8_t bytes[VSTIG_MESSAGE_SIZE];
    vstig_tag_key_t scratch;
    vstig_msg_t msg;
    msg.op = VSTIG_PUT;
    msg.key = key;
    msg.value = entry->value;
    msg.timestamp = entry->timestamp;
    msg.robot = entry->robot;
    vstig_msg_encode(&msg, bytes);
    vstig_tag(writer_key(t, entry->robot, &scratch), t->stigmergy, bytes, epoch, tag);
}

static void keep(vstig_tagged_t *t, uint16_t key, const vstig_entry_t *entry, uint32_t epoch, const uint8_t *tag) {
    vstig_proof_t *proof = place(t, key);
    if (!proof) return;
    proof->key = key;
    proof->entry = *entry;
    proof->epoch = epoch;
    proof->kind = tag != NULL ? VSTIG_PROOF_TAGGED : VSTIG_PROOF_UNTAGGED;
    if (tag) memcpy(proof->tag, tag, VSTIG_TAG_SIZE);
}

/* `_tag_own`: our write after an entry at (old_epoch, old). */
static void tag_own(vstig_tagged_t *t, uint16_t key, uint32_t old_epoch, const vstig_entry_t *old, uint8_t had) {
    vstig_entry_t now;
    uint8_t tag[VSTIG_TAG_SIZE];
    uint32_t epoch = old_epoch;
    if (!vstig_engine_entry(t->engine, key, &now)) return;
    if (had && old->timestamp != VSTIG_TS_NONE && now.timestamp < old->timestamp) epoch++; /* next_epoch */
    writer_tag(t, key, &now, epoch, tag);
    keep(t, key, &now, epoch, tag);
}

void vstig_tagged_init(vstig_tagged_t *t, vstig_engine_t *engine, const uint8_t master[VSTIG_KEY_SIZE],
                       uint16_t stigmergy) {
    uint16_t i;
    memset(t, 0, sizeof *t);
    t->engine = engine;
    t->stigmergy = stigmergy;
    vstig_master_init(&t->master, master);
    for (i = 0; i < VSTIG_KEYS; i++) t->proofs[i].key = FREE;
}

int vstig_tagged_put(vstig_tagged_t *t, uint16_t key, uint16_t value) {
    vstig_entry_t old;
    uint8_t had;
    uint32_t epoch = held(t, key, &old, &had);
    int result = vstig_engine_put(t->engine, key, value);
    if (result == 0) tag_own(t, key, epoch, &old, had);
    return result;
}

/* `_older`: the message loses to the entry held before the engine sees it. */
static uint8_t older(vstig_tagged_t *t, uint16_t key, uint32_t epoch, const vstig_msg_t *msg, uint32_t held_epoch,
                     const vstig_entry_t *local, uint8_t proven) {
    vstig_proof_t *proof;
    if (held_epoch != epoch) return held_epoch > epoch;
    if (local->timestamp != msg->timestamp) return local->timestamp > msg->timestamp;
    proof = find(t, key);
    return !proven && proof && proof->kind == VSTIG_PROOF_TAGGED && same_entry(&proof->entry, local) &&
           msg->robot != local->robot;
}

int vstig_tagged_check(vstig_tagged_t *t, vstig_auth_policy_t policy, const vstig_msg_t *msg, const uint32_t *epoch,
                       const uint8_t *tag) {
    vstig_entry_t heard;
    const vstig_proof_t *held;
    uint8_t expected[VSTIG_TAG_SIZE], diff = 0, i;
    if (msg->timestamp == VSTIG_TS_NONE) return 0; /* an empty GET shows no entry: nothing to prove */
    if (tag != NULL && epoch != NULL && policy != VSTIG_AUTH_OFF) {
        heard.value = msg->value;
        heard.timestamp = msg->timestamp;
        heard.robot = msg->robot;
        held = find(t, msg->key);
        if (held && held->kind == VSTIG_PROOF_TAGGED && held->epoch == *epoch && same_entry(&held->entry, &heard))
            memcpy(expected, held->tag, VSTIG_TAG_SIZE); /* a re-broadcast of the entry held: its tag, checked then */
        else
            writer_tag(t, msg->key, &heard, *epoch, expected);
        for (i = 0; i < VSTIG_TAG_SIZE; i++) diff |= (uint8_t)(expected[i] ^ tag[i]);
        if (diff) {
            t->refused_bad_tag++;
            return VSTIG_REFUSED_BAD_TAG;
        }
    } else if (policy == VSTIG_AUTH_REQUIRE) {
        t->refused_untagged++;
        return VSTIG_REFUSED_UNTAGGED;
    }
    return 0;
}

int vstig_tagged_receive(vstig_tagged_t *t, vstig_auth_policy_t policy, const vstig_msg_t *msg,
                         const uint32_t *epoch, const uint8_t *tag) {
    int refused = vstig_tagged_check(t, policy, msg, epoch, tag);
    return refused ? refused : vstig_tagged_apply(t, policy, msg, epoch, tag);
}

int vstig_tagged_apply(vstig_tagged_t *t, vstig_auth_policy_t policy, const vstig_msg_t *msg, const uint32_t *epoch,
                       const uint8_t *tag) {
    vstig_entry_t local, now, heard;
    uint8_t has, proven;
    uint32_t held_epoch, msg_epoch;
    int outcome;
    if (msg->timestamp == VSTIG_TS_NONE) return (int)vstig_engine_receive(t->engine, msg);
    proven = tag != NULL && epoch != NULL && policy != VSTIG_AUTH_OFF;
    heard.value = msg->value;
    heard.timestamp = msg->timestamp;
    heard.robot = msg->robot;
    held_epoch = held(t, msg->key, &local, &has);
    msg_epoch = proven ? *epoch
                       : held_epoch + (has && vstig_ts_newer(msg->timestamp, local.timestamp) &&
                                       msg->timestamp < local.timestamp);
    if (has && older(t, msg->key, msg_epoch, msg, held_epoch, &local, proven)) {
        vstig_msg_t empty;
        if (proven) t->replays++;
        if (msg->op != VSTIG_GET) return VSTIG_STALE;
        empty.op = VSTIG_GET; /* answer it with our entry, as row 5 does */
        empty.key = msg->key;
        empty.value = 0;
        empty.timestamp = VSTIG_TS_NONE;
        empty.robot = msg->robot;
        return (int)vstig_engine_receive(t->engine, &empty);
    }
    outcome = (int)vstig_engine_receive(t->engine, msg);
    /* `_note`: keep the proof of whatever the engine now holds */
    if (!vstig_engine_entry(t->engine, msg->key, &now) || (has && same_entry(&now, &local))) return outcome;
    if (same_entry(&now, &heard)) {
        keep(t, msg->key, &now, msg_epoch, proven ? tag : NULL);
    } else if (now.robot == t->engine->robot) {
        tag_own(t, msg->key, held_epoch, &local, has);
    } else {
        vstig_proof_t *proof = find(t, msg->key);
        if (proof && !same_entry(&proof->entry, &now)) proof->kind = VSTIG_PROOF_NONE;
    }
    return outcome;
}

uint8_t vstig_tagged_record(const vstig_tagged_t *t, const vstig_msg_t *msg, uint32_t *epoch,
                            uint8_t tag[VSTIG_TAG_SIZE]) {
    const vstig_proof_t *proof;
    if (msg->timestamp == VSTIG_TS_NONE) {
        *epoch = 0;
        memset(tag, 0, VSTIG_TAG_SIZE);
        return 1;
    }
    proof = find(t, msg->key);
    if (proof == NULL || proof->kind != VSTIG_PROOF_TAGGED || proof->entry.value != msg->value ||
        proof->entry.timestamp != msg->timestamp || proof->entry.robot != msg->robot)
        return 0;
    *epoch = proof->epoch;
    memcpy(tag, proof->tag, VSTIG_TAG_SIZE);
    return 1;
}
