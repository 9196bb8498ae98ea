/* vstig_auth: see vstig_auth.h. BLAKE2s as RFC 7693 section 3 writes it, for inputs of one block. */
#include "vstig_auth.h"

#include <string.h>

/* BLAKE2s' constants stay in flash on an AVR (144 bytes of its 2 kB of RAM otherwise). */
#ifdef __AVR__
#include <avr/pgmspace.h>
#define ROM PROGMEM
#define ROM_BYTE(p) pgm_read_byte(p)
#define ROM_WORD(p) pgm_read_dword(p)
#else
#define ROM
#define ROM_BYTE(p) (*(p))
#define ROM_WORD(p) (*(p))
#endif

static const uint32_t IV[8] ROM = {0x6A09E667ul, 0xBB67AE85ul, 0x3C6EF372ul, 0xA54FF53Aul,
                               0x510E527Ful, 0x9B05688Cul, 0x1F83D9ABul, 0x5BE0CD19ul};
/* SIGMA's rows, two indexes per byte, to halve the table (80 bytes). */
static const uint8_t SIGMA[10][8] ROM = {
    {0x01, 0x23, 0x45, 0x67, 0x89, 0xAB, 0xCD, 0xEF}, {0xEA, 0x48, 0x9F, 0xD6, 0x1C, 0x02, 0xB7, 0x53},
    {0xB8, 0xC0, 0x52, 0xFD, 0xAE, 0x36, 0x71, 0x94}, {0x79, 0x31, 0xDC, 0xBE, 0x26, 0x5A, 0x40, 0xF8},
    {0x90, 0x57, 0x24, 0xAF, 0xE1, 0xBC, 0x68, 0x3D}, {0x2C, 0x6A, 0x0B, 0x83, 0x4D, 0x75, 0xFE, 0x19},
    {0xC5, 0x1F, 0xED, 0x4A, 0x07, 0x63, 0x92, 0x8B}, {0xDB, 0x7E, 0xC1, 0x39, 0x50, 0xF4, 0x86, 0x2A},
    {0x6F, 0xE9, 0xB3, 0x08, 0xC2, 0xD7, 0x14, 0xA5}, {0xA2, 0x84, 0x76, 0x15, 0xFB, 0x9E, 0x3C, 0xD0}};

/* Rotations by constants, so a compiler for an 8-bit core moves bytes for 16 and 8 instead of looping. */
#define ROTR(x, n) (((x) >> (n)) | ((x) << (32u - (n))))

static void g(uint32_t *v, uint8_t a, uint8_t b, uint8_t c, uint8_t d, uint32_t x, uint32_t y) {
    uint32_t va = v[a], vb = v[b], vc = v[c], vd = v[d];
    va += vb + x;
    vd = ROTR(vd ^ va, 16);
    vc += vd;
    vb = ROTR(vb ^ vc, 12);
    va += vb + y;
    vd = ROTR(vd ^ va, 8);
    vc += vd;
    vb = ROTR(vb ^ vc, 7);
    v[a] = va;
    v[b] = vb;
    v[c] = vc;
    v[d] = vd;
}

/* One compression of a 64-byte block; `count` is the bytes hashed so far (< 2^32 here). */
static void compress(uint32_t h[8], const uint8_t block[64], uint32_t count, uint8_t last) {
    static const uint8_t LANES[8][4] ROM = {{0, 4, 8, 12}, {1, 5, 9, 13}, {2, 6, 10, 14}, {3, 7, 11, 15},
                                        {0, 5, 10, 15}, {1, 6, 11, 12}, {2, 7, 8, 13}, {3, 4, 9, 14}};
    uint32_t m[16], v[16];
    uint8_t i, r;
    for (i = 0; i < 16; i++)
        m[i] = (uint32_t)block[4 * i] | (uint32_t)block[4 * i + 1] << 8 | (uint32_t)block[4 * i + 2] << 16 |
               (uint32_t)block[4 * i + 3] << 24;
    for (i = 0; i < 8; i++) {
        v[i] = h[i];
        v[i + 8] = ROM_WORD(&IV[i]);
    }
    v[12] ^= count;
    if (last) v[14] = ~v[14];
    for (r = 0; r < 10; r++)
        for (i = 0; i < 8; i++) {
            uint8_t s = ROM_BYTE(&SIGMA[r][i]);
            g(v, ROM_BYTE(&LANES[i][0]), ROM_BYTE(&LANES[i][1]), ROM_BYTE(&LANES[i][2]), ROM_BYTE(&LANES[i][3]),
              m[s >> 4], m[s & 15u]);
        }
    for (i = 0; i < 8; i++) h[i] ^= v[i] ^ v[i + 8];
}

/* The state after the key block, for digests of `outlen` bytes (the length is in the parameter block). */
static void prepare(vstig_tag_key_t *ready, const uint8_t key[VSTIG_KEY_SIZE], uint8_t outlen) {
    uint8_t block[64], i;
    for (i = 0; i < 8; i++) ready->h[i] = ROM_WORD(&IV[i]);
    ready->h[0] ^= 0x01010000ul ^ ((uint32_t)VSTIG_KEY_SIZE << 8) ^ outlen; /* fanout, depth 1; key length */
    memcpy(block, key, VSTIG_KEY_SIZE);
    memset(block + VSTIG_KEY_SIZE, 0, sizeof block - VSTIG_KEY_SIZE);
    compress(ready->h, block, 64u, 0u);
}

/* The digest of `len` (<= 64) bytes after the prepared key block: one compression. */
static void finish(const vstig_tag_key_t *ready, const uint8_t *data, uint8_t len, uint8_t *out, uint8_t outlen) {
    uint8_t block[64];
    uint32_t h[8];
    uint8_t i;
    memcpy(h, ready->h, sizeof h);
    memcpy(block, data, len);
    memset(block + len, 0, sizeof block - len);
    compress(h, block, 64u + len, 1u);
    for (i = 0; i < outlen; i++) out[i] = (uint8_t)(h[i >> 2] >> (8u * (i & 3u)));
}

void vstig_tag_key_init(vstig_tag_key_t *ready, const uint8_t key[VSTIG_KEY_SIZE]) {
    prepare(ready, key, VSTIG_TAG_SIZE);
}

void vstig_master_init(vstig_tag_key_t *ready, const uint8_t master[VSTIG_KEY_SIZE]) {
    prepare(ready, master, VSTIG_KEY_SIZE);
}

void vstig_robot_key(const vstig_tag_key_t *master, uint16_t robot, uint8_t key[VSTIG_KEY_SIZE]) {
    static const char LABEL[] = "vstig robot key";
    uint8_t data[sizeof LABEL + 1];
    memcpy(data, LABEL, sizeof LABEL - 1);
    data[sizeof LABEL - 1] = (uint8_t)(robot >> 8);
    data[sizeof LABEL] = (uint8_t)robot;
    finish(master, data, (uint8_t)sizeof data, key, VSTIG_KEY_SIZE);
}

void vstig_tag(const vstig_tag_key_t *writer, uint16_t stigmergy, const uint8_t msg[8], uint32_t epoch,
               uint8_t tag[VSTIG_TAG_SIZE]) {
    uint8_t data[14];
    data[0] = (uint8_t)(epoch >> 24);
    data[1] = (uint8_t)(epoch >> 16);
    data[2] = (uint8_t)(epoch >> 8);
    data[3] = (uint8_t)epoch;
    data[4] = (uint8_t)(stigmergy >> 8);
    data[5] = (uint8_t)stigmergy;
    memcpy(data + 6, msg, 8);
    data[6] &= 0x7Fu; /* the entry, not the op: a GET showing it carries the same tag */
    finish(writer, data, (uint8_t)sizeof data, tag, VSTIG_TAG_SIZE);
}

uint8_t vstig_tag_ok(const vstig_tag_key_t *writer, uint16_t stigmergy, const uint8_t msg[8], uint32_t epoch,
                     const uint8_t tag[VSTIG_TAG_SIZE]) {
    uint8_t expected[VSTIG_TAG_SIZE], diff = 0, i;
    vstig_tag(writer, stigmergy, msg, epoch, expected);
    for (i = 0; i < VSTIG_TAG_SIZE; i++) diff |= (uint8_t)(expected[i] ^ tag[i]);
    return diff == 0;
}
