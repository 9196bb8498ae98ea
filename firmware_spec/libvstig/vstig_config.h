/*
 * libvstig capacities, fixed at compile time (no malloc anywhere).
 *
 * Override any of them with -D on EVERY file that includes a libvstig header (the
 * library's own sources and yours): the structures' sizes depend on them. The init
 * functions check that the library and the caller were built with the same values
 * (they return VSTIG_ERR_CONFIG otherwise), so a mismatch fails at start, not later.
 */
#ifndef VSTIG_CONFIG_H
#define VSTIG_CONFIG_H

/* Keys an engine's table holds: a power of two, 2..32768. 32768 holds every key, so the
 * table is never full (a gateway); a small robot holds the keys its program uses. */
#ifndef VSTIG_KEYS
#define VSTIG_KEYS 32u
#endif

/* Messages an outgoing queue holds (one per key): a power of two, 2..32768. An engine's
 * queue needs one per key it holds, plus one per unknown key its program reads. */
#ifndef VSTIG_QUEUE
#define VSTIG_QUEUE VSTIG_KEYS
#endif

/* Keys a jump guard tracks (gateways: 32768, every key): a power of two, 2..32768. */
#ifndef VSTIG_GUARD_KEYS
#define VSTIG_GUARD_KEYS VSTIG_KEYS
#endif

/* Partial messages an epuck4 reassembler keeps: 16 is one per group (SPEC.md 6.2.3). */
#ifndef VSTIG_EPUCK4_SLOTS
#define VSTIG_EPUCK4_SLOTS 16u
#endif

#define VSTIG_ERR_CONFIG (-1) /* built with other capacities than the library */
#define VSTIG_ERR_ARG (-2)    /* an argument out of range */
#define VSTIG_ERR_FULL (-3)   /* no room left for a new key */

/* C99 compile-time check: a negative array size when `cond` is false. */
#define VSTIG_STATIC_ASSERT(cond, name) typedef char vstig_static_assert_##name[(cond) ? 1 : -1]

#define VSTIG_IS_POW2(n) ((n) >= 2u && (n) <= 32768u && ((n) & ((n) - 1u)) == 0u)
VSTIG_STATIC_ASSERT(VSTIG_IS_POW2(VSTIG_KEYS), keys_is_a_power_of_two_up_to_32768);
VSTIG_STATIC_ASSERT(VSTIG_IS_POW2(VSTIG_QUEUE), queue_is_a_power_of_two_up_to_32768);
VSTIG_STATIC_ASSERT(VSTIG_IS_POW2(VSTIG_GUARD_KEYS), guard_keys_is_a_power_of_two_up_to_32768);

#endif /* VSTIG_CONFIG_H */
