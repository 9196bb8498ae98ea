/* Internal to libvstig: the open-addressed key tables of the engine and the guard.
 * Keys are 15 bits, so 0xFFFF marks a free place; a table never deletes a key. */
#ifndef VSTIG_KEYMAP_H
#define VSTIG_KEYMAP_H

#include <stdint.h>

#define VSTIG_NO_KEY 0xFFFFu

/* The place of key among cap places (a power of two): where it is, or the first free place
 * on its probe path (linear, from key & (cap - 1)); cap when neither (the table is full). With
 * a table of 32768 places every key sits at its own place: a lookup is one comparison. */
static uint16_t vstig_keymap_place(const uint16_t *keys, uint16_t cap, uint16_t key) {
    uint16_t p = (uint16_t)(key & (cap - 1u)), n;
    for (n = 0; n < cap; n++, p = (uint16_t)((p + 1u) & (cap - 1u))) {
        if (keys[p] == key || keys[p] == VSTIG_NO_KEY) return p;
    }
    return cap;
}

#endif /* VSTIG_KEYMAP_H */
