/*
 * vstig_guard: a gateway's jump bound (SPEC.md 3.1), the check vstig-hw gateways make
 * before a message reaches their engine (vstig_hw/gateway/guard.py, `max_jump` and
 * `learn`; the guard's other policies stay in Python).
 *
 * A PUT or GET newer than the newest entry let through for its key by more than
 * max_jump timestamps is refused; so is one whose skipped timestamps (its steps beyond
 * the first) overspend the key's budget of max_jump, refilled at max_jump a second. A
 * refused message moves nothing. A key never seen passes at any timestamp unless `learn`
 * time has passed since the first message: then it must start within max_jump of 0.
 *
 * No clock: every check is handed `now`, in units of the caller's choice
 * (units_per_second of them a second), wrapping modulo 2^32; two times compared are less
 * than 2^31 units apart. Robots do not need it. Part of libvstig.
 */
#ifndef VSTIG_GUARD_H
#define VSTIG_GUARD_H

#include "vstig_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

#define VSTIG_GUARD_PASS 0u /* let through (and, if newer, the key's new reference) */
#define VSTIG_GUARD_JUMP 1u /* refused: counted by the caller as drop_jump */
#define VSTIG_GUARD_FULL 2u /* refused: a new key and no room to track it (counted in `full`) */
#define VSTIG_GUARD_NEVER_LEARNT 0xFFFFFFFFul /* learn: keys never seen pass at any timestamp */

typedef struct {
    uint16_t timestamp, robot, value; /* the newest entry let through; timestamp 0: none yet */
    uint8_t has_budget;
    uint32_t budget; /* skipped steps the key may still spend, times units_per_second */
    uint32_t spent;  /* when the budget was last looked at */
} vstig_guard_key_t;

typedef struct {
    uint16_t key[VSTIG_GUARD_KEYS]; /* open addressing; a free place holds 0xFFFF */
    vstig_guard_key_t at[VSTIG_GUARD_KEYS];
    uint16_t max_jump;         /* 1..32767 */
    uint16_t units_per_second; /* 1..65535 */
    uint32_t learn;            /* units after the first message, or VSTIG_GUARD_NEVER_LEARNT */
    uint32_t started;          /* when the first message was checked */
    uint8_t has_started;
    uint32_t full; /* messages refused for want of room (saturating) */
} vstig_guard_t;

/* 0, VSTIG_ERR_ARG (max_jump not 1..32767, units_per_second 0, learn of 2^31 units or more
 * other than VSTIG_GUARD_NEVER_LEARNT) or VSTIG_ERR_CONFIG (built with other capacities). */
#define vstig_guard_init(g, max_jump, units_per_second, learn) \
    vstig_guard_init_sized((g), sizeof *(g), (max_jump), (units_per_second), (learn))
int vstig_guard_init_sized(vstig_guard_t *g, size_t size, uint16_t max_jump, uint16_t units_per_second,
                           uint32_t learn);
/* VSTIG_GUARD_PASS, VSTIG_GUARD_JUMP or VSTIG_GUARD_FULL for msg heard at `now`. */
uint8_t vstig_guard_check(vstig_guard_t *g, const vstig_msg_t *msg, uint32_t now);
/* The newest entry let through for key: 1 and its fields, or 0. */
uint8_t vstig_guard_view(const vstig_guard_t *g, uint16_t key, uint16_t *timestamp, uint16_t *robot,
                         uint16_t *value);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_GUARD_H */
