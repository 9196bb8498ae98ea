/*
 * vstig_auth: tags that prove who wrote an entry (SPEC.md section 10): BLAKE2s (RFC 7693) with an 8-byte
 * digest and the robot-key derivation; the authenticated message is the 8 bytes, the epoch and the tag.
 * Part of libvstig.
 *
 * Portable: 32-bit arithmetic only (no 64-bit), no malloc; BLAKE2s' constants are its only tables (in flash
 * on an AVR). Cost on an ATmega328P (SPEC.md 10.7): 69k cycles a tag, 1.9 kB of flash, 16 bytes of static RAM,
 * about 320 bytes of stack while tagging.
 */
#ifndef VSTIG_AUTH_H
#define VSTIG_AUTH_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define VSTIG_KEY_SIZE 32u
#define VSTIG_TAG_SIZE 8u
#define VSTIG_RECORD_SIZE 20u /* message (8) || epoch (u32, big-endian) || tag (8) */

/* A key made ready to tag: BLAKE2s' state after the key block, so each tag costs one compression. */
typedef struct {
    uint32_t h[8];
} vstig_tag_key_t;

/* Prepares a robot key for vstig_tag / vstig_tag_ok. One compression. */
void vstig_tag_key_init(vstig_tag_key_t *ready, const uint8_t key[VSTIG_KEY_SIZE]);
/* Prepares the swarm master secret for vstig_robot_key. One compression. */
void vstig_master_init(vstig_tag_key_t *ready, const uint8_t master[VSTIG_KEY_SIZE]);
/* The tag of a message's entry (the op bit is not covered) at `epoch` under a prepared writer key. */
void vstig_tag(const vstig_tag_key_t *writer, uint16_t stigmergy, const uint8_t msg[8], uint32_t epoch,
               uint8_t tag[VSTIG_TAG_SIZE]);
/* 1 when `tag` is the entry's tag under `writer` (compared without an early exit), else 0. */
uint8_t vstig_tag_ok(const vstig_tag_key_t *writer, uint16_t stigmergy, const uint8_t msg[8], uint32_t epoch,
                     const uint8_t tag[VSTIG_TAG_SIZE]);
/* A robot's key from the prepared swarm master secret and its id. One compression. */
void vstig_robot_key(const vstig_tag_key_t *master, uint16_t robot, uint8_t key[VSTIG_KEY_SIZE]);

#ifdef __cplusplus
}
#endif

#endif
