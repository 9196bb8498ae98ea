/*
 * Hex in and out for the test drivers (auth_driver.c, tagged_driver.c): exactly n bytes from 2n hex digits,
 * and bytes as hex with no newline. Static inline so a driver that uses only one builds clean under -Werror.
 */
#ifndef VSTIG_TESTS_HEX_IO_H
#define VSTIG_TESTS_HEX_IO_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

/* 1 when text is exactly 2n hex digits, written to out; 0 otherwise. */
static inline int unhex(const char *text, uint8_t *out, size_t n) {
    size_t i;
    unsigned byte;
    if (strlen(text) != 2 * n) return 0;
    for (i = 0; i < n; i++) {
        if (sscanf(text + 2 * i, "%2x", &byte) != 1) return 0;
        out[i] = (uint8_t)byte;
    }
    return 1;
}

static inline void print_hex(const uint8_t *data, size_t n) {
    size_t i;
    for (i = 0; i < n; i++) printf("%02x", data[i]);
}

#endif
