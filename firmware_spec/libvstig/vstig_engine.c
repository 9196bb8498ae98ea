/* vstig_engine: the receive rules and local operations of SPEC.md sections 4 and 5. See vstig_engine.h. */
#include "vstig_engine.h"
#include "vstig_keymap.h"

uint8_t vstig_higher_robot_wins(void *ctx, uint16_t key, const vstig_entry_t *local,
                                const vstig_entry_t *remote, vstig_entry_t *chosen) {
    (void)ctx;
    (void)key;
    *chosen = remote->robot > local->robot ? *remote : *local;
    return 1;
}

uint8_t vstig_larger_value_wins(void *ctx, uint16_t key, const vstig_entry_t *local,
                                const vstig_entry_t *remote, vstig_entry_t *chosen) {
    (void)ctx;
    (void)key;
    *chosen = (remote->value > local->value || (remote->value == local->value && remote->robot > local->robot))
                  ? *remote : *local;
    return 1;
}

uint8_t vstig_sum_merge(void *ctx, uint16_t key, const vstig_entry_t *local, const vstig_entry_t *remote,
                        vstig_entry_t *chosen) {
    (void)ctx;
    (void)key;
    chosen->value = (uint16_t)(local->value + remote->value);
    chosen->timestamp = local->timestamp;
    chosen->robot = local->robot > remote->robot ? local->robot : remote->robot;
    return 1;
}

int vstig_engine_init_sized(vstig_engine_t *e, size_t size, uint16_t robot, vstig_resolver_t onconflict,
                            vstig_lost_t onconflictlost, void *ctx) {
    uint16_t i;
    if (size != sizeof *e || vstig_outqueue_init(&e->out) != 0) return VSTIG_ERR_CONFIG;
    for (i = 0; i < VSTIG_KEYS; i++) e->key[i] = VSTIG_NO_KEY;
    for (i = 0; i <= VSTIG_OUTCOMES; i++) e->counts[i] = 0;
    e->size = 0;
    e->robot = robot;
    e->onconflict = onconflict ? onconflict : vstig_higher_robot_wins;
    e->onconflictlost = onconflictlost;
    e->ctx = ctx;
    return 0;
}

static void queue(vstig_engine_t *e, uint8_t op, uint16_t key, const vstig_entry_t *entry) {
    vstig_msg_t msg;
    msg.op = op;
    msg.key = key;
    msg.value = entry->value;
    msg.timestamp = entry->timestamp;
    msg.robot = entry->robot;
    (void)vstig_outqueue_push(&e->out, &msg); /* a full queue counts it in out.full */
}

/* The entry held for key (NULL if none); *place is where it is or would go (VSTIG_KEYS: full). */
static vstig_entry_t *held(vstig_engine_t *e, uint16_t key, uint16_t *place) {
    *place = vstig_keymap_place(e->key, VSTIG_KEYS, key);
    return *place < VSTIG_KEYS && e->key[*place] == key ? &e->entry[*place] : 0;
}

/* Claims the free place found by held() for a new key; NULL when the table is full. */
static vstig_entry_t *claim(vstig_engine_t *e, uint16_t key, uint16_t place) {
    if (place >= VSTIG_KEYS) return 0;
    e->key[place] = key;
    e->size++;
    return &e->entry[place];
}

int vstig_engine_put(vstig_engine_t *e, uint16_t key, uint16_t value) {
    uint16_t place;
    vstig_entry_t *local;
    uint16_t timestamp;
    if (key > VSTIG_KEY_MAX) return VSTIG_ERR_ARG;
    local = held(e, key, &place);
    timestamp = local ? vstig_ts_next(local->timestamp) : 1u;
    if (!local && !(local = claim(e, key, place))) return VSTIG_ERR_FULL;
    local->value = value;
    local->timestamp = timestamp;
    local->robot = e->robot;
    queue(e, VSTIG_PUT, key, local);
    return 0;
}

int vstig_engine_get(vstig_engine_t *e, uint16_t key, uint16_t *value) {
    uint16_t place;
    const vstig_entry_t *local;
    vstig_entry_t none;
    if (key > VSTIG_KEY_MAX) return VSTIG_ERR_ARG;
    local = held(e, key, &place);
    if (!local) {
        none.value = 0;
        none.timestamp = VSTIG_TS_NONE;
        none.robot = e->robot;
        queue(e, VSTIG_GET, key, &none);
        return 0;
    }
    queue(e, VSTIG_GET, key, local);
    *value = local->value;
    return 1;
}

uint8_t vstig_engine_entry(const vstig_engine_t *e, uint16_t key, vstig_entry_t *entry) {
    uint16_t place = vstig_keymap_place(e->key, VSTIG_KEYS, key);
    if (place >= VSTIG_KEYS || e->key[place] != key) return 0;
    *entry = e->entry[place];
    return 1;
}

uint8_t vstig_engine_at(const vstig_engine_t *e, uint16_t place, uint16_t *key, vstig_entry_t *entry) {
    if (place >= VSTIG_KEYS || e->key[place] == VSTIG_NO_KEY) return 0;
    *key = e->key[place];
    *entry = e->entry[place];
    return 1;
}

/* The entry to store for a conflict's chosen entry, which may be neither of the two (a merge):
 * a merge is a new write of the robot it names (SPEC.md section 4, row 7). 0: a merge naming
 * a third robot, which nobody could publish as its own write. */
static uint8_t winner_of(const vstig_engine_t *e, const vstig_entry_t *local, const vstig_entry_t *remote,
                         const vstig_entry_t *chosen, vstig_entry_t *winner) {
    winner->value = chosen->value;
    winner->timestamp = local->timestamp;
    winner->robot = chosen->robot;
    if ((chosen->value == local->value && chosen->robot == local->robot) ||
        (chosen->value == remote->value && chosen->robot == remote->robot))
        return 1;
    if (chosen->robot == e->robot) {
        winner->timestamp = vstig_ts_next(local->timestamp);
        return 1;
    }
    if (chosen->robot == local->robot || chosen->robot == remote->robot) {
        winner->value = chosen->robot == local->robot ? local->value : remote->value;
        return 1;
    }
    return 0;
}

static vstig_outcome_t resolve(vstig_engine_t *e, uint16_t key, vstig_entry_t *slot, const vstig_msg_t *msg) {
    vstig_entry_t local = *slot, remote, chosen, winner;
    remote.value = msg->value;
    remote.timestamp = msg->timestamp;
    remote.robot = msg->robot;
    if (!e->onconflict(e->ctx, key, &local, &remote, &chosen) || !winner_of(e, &local, &remote, &chosen, &winner))
        return VSTIG_BAD_WINNER;
    *slot = winner;
    queue(e, VSTIG_PUT, key, &winner);
    /* Only the entry we held can be our lost write: the echo of a write that already lost
     * comes back as the remote, and must not be reported again. */
    if (e->onconflictlost && local.robot == e->robot && winner.robot != e->robot) e->onconflictlost(e->ctx, key, &local);
    return VSTIG_CONFLICT;
}

static vstig_outcome_t apply(vstig_engine_t *e, const vstig_msg_t *msg) {
    uint16_t place, key = (uint16_t)(msg->key & VSTIG_KEY_MAX);
    uint8_t is_get = (uint8_t)(msg->op & 1u);
    vstig_entry_t *local = held(e, key, &place);
    if (msg->timestamp == VSTIG_TS_NONE) {
        if (!is_get) return VSTIG_INVALID;
        if (!local) return VSTIG_UNKNOWN;
    }
    if (!local || vstig_ts_newer(msg->timestamp, local->timestamp)) {
        if (!local && !(local = claim(e, key, place))) return VSTIG_FULL;
        local->value = msg->value;
        local->timestamp = msg->timestamp;
        local->robot = msg->robot;
        queue(e, VSTIG_PUT, key, local);
        return VSTIG_STORED;
    }
    if (msg->timestamp != local->timestamp) {
        if (!is_get) return VSTIG_STALE;
        queue(e, VSTIG_PUT, key, local);
        return VSTIG_ANSWERED;
    }
    if (msg->robot == local->robot) return VSTIG_SAME;
    return resolve(e, key, local, msg);
}

vstig_outcome_t vstig_engine_receive(vstig_engine_t *e, const vstig_msg_t *msg) {
    vstig_outcome_t outcome = apply(e, msg);
    if (outcome <= VSTIG_FULL && e->counts[outcome] != 0xFFFFFFFFul) e->counts[outcome]++;
    return outcome;
}

void vstig_engine_receive_many(vstig_engine_t *e, const vstig_msg_t *msgs, size_t n, uint8_t *outcomes) {
    size_t i;
    for (i = 0; i < n; i++) {
        vstig_outcome_t outcome = vstig_engine_receive(e, &msgs[i]);
        if (outcomes) outcomes[i] = (uint8_t)outcome;
    }
}

size_t vstig_engine_drain(vstig_engine_t *e, vstig_msg_t *out, size_t budget) {
    return vstig_outqueue_drain(&e->out, out, budget);
}
