/* vstig_guard: the jump bound of SPEC.md 3.1, as vstig_hw/gateway/guard.py applies it. See vstig_guard.h. */
#include "vstig_guard.h"
#include "vstig_keymap.h"

int vstig_guard_init_sized(vstig_guard_t *g, size_t size, uint16_t max_jump, uint16_t units_per_second,
                           uint32_t learn) {
    uint16_t i;
    if (size != sizeof *g) return VSTIG_ERR_CONFIG;
    if (max_jump < 1u || max_jump > 0x7FFFu || units_per_second == 0 ||
        (learn >= 0x80000000ul && learn != VSTIG_GUARD_NEVER_LEARNT))
        return VSTIG_ERR_ARG;
    for (i = 0; i < VSTIG_GUARD_KEYS; i++) g->key[i] = VSTIG_NO_KEY;
    g->max_jump = max_jump;
    g->units_per_second = units_per_second;
    g->learn = learn;
    g->has_started = 0;
    g->started = 0;
    g->full = 0;
    return 0;
}

/* now - then in units, 0 when the clock stepped back (a step back refills nothing). */
static uint32_t since(uint32_t now, uint32_t then) {
    uint32_t d = now - then; /* modulo 2^32 */
    return d >= 0x80000000ul ? 0u : d;
}

/* Whether ts is a jump for the key whose state is k (view and budget); spends its skips if not. */
static uint8_t jumps(const vstig_guard_t *g, vstig_guard_key_t *k, uint16_t ts, uint32_t now) {
    uint32_t scale = g->units_per_second, cap = (uint32_t)g->max_jump * scale, left, elapsed, skipped;
    uint16_t steps;
    uint32_t learning = now - g->started; /* negative (a clock stepped back): still learning */
    if (k->timestamp == VSTIG_TS_NONE &&
        (g->learn == VSTIG_GUARD_NEVER_LEARNT || learning >= 0x80000000ul || learning < g->learn))
        return 0; /* a key never seen, and not learnt yet: any timestamp */
    if (!vstig_ts_newer(ts, k->timestamp)) return 0;
    steps = k->timestamp == VSTIG_TS_NONE ? ts : vstig_ts_steps(ts, k->timestamp);
    if (steps > g->max_jump) return 1;
    if (!k->has_budget) {
        k->has_budget = 1;
        k->budget = cap;
        k->spent = now;
    }
    elapsed = since(now, k->spent);
    if (elapsed > scale) elapsed = scale; /* a whole second refills the budget */
    left = k->budget + elapsed * g->max_jump;
    if (left > cap) left = cap;
    k->spent = now;
    skipped = (uint32_t)(steps - 1u) * scale;
    if (skipped > left) {
        k->budget = left;
        return 1;
    }
    k->budget = left - skipped;
    return 0;
}

uint8_t vstig_guard_check(vstig_guard_t *g, const vstig_msg_t *msg, uint32_t now) {
    uint16_t key = (uint16_t)(msg->key & VSTIG_KEY_MAX), place;
    vstig_guard_key_t fresh, *k;
    uint8_t jump;
    if (!g->has_started) {
        g->has_started = 1;
        g->started = now;
    }
    if (msg->timestamp == VSTIG_TS_NONE) return VSTIG_GUARD_PASS; /* an empty GET says nothing of the entry */
    place = vstig_keymap_place(g->key, VSTIG_GUARD_KEYS, key);
    if (place >= VSTIG_GUARD_KEYS) {
        if (g->full != 0xFFFFFFFFul) g->full++;
        return VSTIG_GUARD_FULL;
    }
    if (g->key[place] == key) {
        k = &g->at[place];
    } else { /* tracked from here on only if it passes or spends a budget */
        fresh.timestamp = fresh.robot = fresh.value = VSTIG_TS_NONE;
        fresh.has_budget = 0;
        fresh.budget = fresh.spent = 0;
        k = &fresh;
    }
    jump = jumps(g, k, msg->timestamp, now);
    if (!jump && (k->timestamp == VSTIG_TS_NONE || vstig_ts_newer(msg->timestamp, k->timestamp))) {
        k->timestamp = msg->timestamp;
        k->robot = msg->robot;
        k->value = msg->value;
    }
    if (k == &fresh && (k->timestamp != VSTIG_TS_NONE || k->has_budget)) {
        g->key[place] = key;
        g->at[place] = fresh;
    }
    return jump ? VSTIG_GUARD_JUMP : VSTIG_GUARD_PASS;
}

uint8_t vstig_guard_view(const vstig_guard_t *g, uint16_t key, uint16_t *timestamp, uint16_t *robot,
                         uint16_t *value) {
    uint16_t place = vstig_keymap_place(g->key, VSTIG_GUARD_KEYS, key);
    if (place >= VSTIG_GUARD_KEYS || g->key[place] != key || g->at[place].timestamp == VSTIG_TS_NONE) return 0;
    *timestamp = g->at[place].timestamp;
    *robot = g->at[place].robot;
    *value = g->at[place].value;
    return 1;
}
