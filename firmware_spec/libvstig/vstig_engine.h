/*
 * vstig_engine: one robot's view of one virtual stigmergy (SPEC.md sections 4 and 5).
 *
 * Feed it what the radio heard (vstig_engine_receive), call put and get as the robot's
 * program does, and send what vstig_engine_drain hands back. It owns no device, thread
 * or clock: the caller owns the struct (static, VSTIG_KEYS keys) and every call is
 * explicit. The Python engine (vstig_hw/engine.py) is the reference; a differential
 * test keeps the two equal. Part of libvstig.
 */
#ifndef VSTIG_ENGINE_H
#define VSTIG_ENGINE_H

#include "vstig_outqueue.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    uint16_t value;
    uint16_t timestamp;
    uint16_t robot;
} vstig_entry_t;

/* What vstig_engine_receive did with a message: the outcomes of SPEC.md section 4 (the
 * engine counts each), then two results that change nothing. */
typedef enum {
    VSTIG_STORED = 0, /* newer: stored and queued for re-broadcast (rows 3) */
    VSTIG_ANSWERED,   /* a GET older than ours: our entry queued (row 5) */
    VSTIG_STALE,      /* a PUT older than ours: ignored (row 4) */
    VSTIG_SAME,       /* same timestamp and robot: nothing to do (row 6) */
    VSTIG_CONFLICT,   /* same timestamp, another robot: resolved, winner queued (row 7) */
    VSTIG_UNKNOWN,    /* an empty GET for a key we do not hold (row 2) */
    VSTIG_INVALID,    /* a PUT with the reserved timestamp 0 (row 1) */
    VSTIG_FULL,       /* a new key and no room left in the table: not stored (counted) */
    VSTIG_BAD_WINNER, /* the resolver gave no entry, or a merge naming a third robot: nothing changed */
    VSTIG_OUTCOMES = VSTIG_FULL /* the protocol's outcomes; counts[] also has VSTIG_FULL */
} vstig_outcome_t;

/* The conflict rule (SPEC.md section 4, row 7): sets *chosen and returns 1, or returns 0
 * when it has no answer. `ctx` is the one given to vstig_engine_init. */
typedef uint8_t (*vstig_resolver_t)(void *ctx, uint16_t key, const vstig_entry_t *local,
                                    const vstig_entry_t *remote, vstig_entry_t *chosen);
/* Called when the entry we held was our own write and the conflict's winner is not. */
typedef void (*vstig_lost_t)(void *ctx, uint16_t key, const vstig_entry_t *lost);

/* Ready-made rules. The default: the higher robot id wins (Buzz's). */
uint8_t vstig_higher_robot_wins(void *ctx, uint16_t key, const vstig_entry_t *local,
                                const vstig_entry_t *remote, vstig_entry_t *chosen);
/* The paper's Figure 1: the larger value, then the higher robot id. */
uint8_t vstig_larger_value_wins(void *ctx, uint16_t key, const vstig_entry_t *local,
                                const vstig_entry_t *remote, vstig_entry_t *chosen);
/* A merge: the sum of both values mod 65536, named for the higher robot id. */
uint8_t vstig_sum_merge(void *ctx, uint16_t key, const vstig_entry_t *local, const vstig_entry_t *remote,
                        vstig_entry_t *chosen);

typedef struct {
    uint16_t key[VSTIG_KEYS]; /* open addressing; a free place holds 0xFFFF */
    vstig_entry_t entry[VSTIG_KEYS];
    uint16_t size;
    uint16_t robot;
    vstig_resolver_t onconflict;
    vstig_lost_t onconflictlost; /* may be NULL */
    void *ctx;                   /* handed to both callbacks */
    uint32_t counts[VSTIG_OUTCOMES + 1u]; /* per outcome, and VSTIG_FULL (saturating) */
    vstig_outqueue_t out;                 /* out.full counts messages the queue had no room for */
} vstig_engine_t;

/* onconflict NULL: vstig_higher_robot_wins. Returns 0, or VSTIG_ERR_CONFIG when the caller
 * was built with other capacities than the library (vstig_config.h). */
#define vstig_engine_init(e, robot, onconflict, onconflictlost, ctx) \
    vstig_engine_init_sized((e), sizeof *(e), (robot), (onconflict), (onconflictlost), (ctx))
int vstig_engine_init_sized(vstig_engine_t *e, size_t size, uint16_t robot, vstig_resolver_t onconflict,
                            vstig_lost_t onconflictlost, void *ctx);

/* The robot's program. put: write locally (timestamp old + 1, or 1) and queue a PUT; 0, or
 * VSTIG_ERR_ARG (key above 0x7FFF), VSTIG_ERR_FULL (a new key and the table is full). */
int vstig_engine_put(vstig_engine_t *e, uint16_t key, uint16_t value);
/* get: 1 and *value when the key is held, else 0; queues a GET carrying our view either way.
 * VSTIG_ERR_ARG for a key above 0x7FFF. */
int vstig_engine_get(vstig_engine_t *e, uint16_t key, uint16_t *value);
/* The entry held for key, without sending anything: 1 and *entry, or 0. */
uint8_t vstig_engine_entry(const vstig_engine_t *e, uint16_t key, vstig_entry_t *entry);
/* Iterate the table: place 0..VSTIG_KEYS-1 holds an entry when this returns 1. */
uint8_t vstig_engine_at(const vstig_engine_t *e, uint16_t place, uint16_t *key, vstig_entry_t *entry);

/* The radio: apply one message heard from a neighbour, or n of them (outcomes may be NULL). */
vstig_outcome_t vstig_engine_receive(vstig_engine_t *e, const vstig_msg_t *msg);
void vstig_engine_receive_many(vstig_engine_t *e, const vstig_msg_t *msgs, size_t n, uint8_t *outcomes);

/* What to broadcast now: up to `budget` messages into out, PUTs first (one control step). */
size_t vstig_engine_drain(vstig_engine_t *e, vstig_msg_t *out, size_t budget);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_ENGINE_H */
