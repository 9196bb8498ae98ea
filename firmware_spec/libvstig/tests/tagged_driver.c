/*
 * The vstig_tagged test driver: one command per line on stdin, one result per line on stdout.
 *   init ROBOT STIGMERGY MASTER            -> ok
 *   put KEY VALUE                          -> vstig_tagged_put's result
 *   recv POLICY MESSAGE EPOCH TAG          -> vstig_tagged_receive's result (EPOCH and TAG "-" when untagged)
 *   drain                                  -> MESSAGE/EPOCH/TAG or MESSAGE/- for each message, comma-separated
 *   counts                                 -> refused_untagged refused_bad_tag replays
 * Hex without spaces; numbers in decimal; POLICY 0 require, 1 prefer, 2 off.
 */
#include <stdio.h>
#include <string.h>

#include "vstig_engine.h"
#include "vstig_tagged.h"
#include "hex_io.h"

static vstig_engine_t engine;
static vstig_tagged_t tagged;

int main(void) {
    char line[512], cmd[8], a[80], b[80], c[80];
    unsigned long x, y;
    uint8_t bytes[VSTIG_MESSAGE_SIZE], tag[VSTIG_TAG_SIZE], master[VSTIG_KEY_SIZE];
    uint32_t epoch;
    vstig_msg_t msg, out[64];
    size_t n, i;
    while (fgets(line, sizeof line, stdin)) {
        if (sscanf(line, "%7s", cmd) != 1) return 2;
        if (!strcmp(cmd, "init") && sscanf(line, "%*s %lu %lu %79s", &x, &y, a) == 3 &&
            unhex(a, master, sizeof master)) {
            if (vstig_engine_init(&engine, (uint16_t)x, NULL, NULL, NULL) != 0) return 3;
            vstig_tagged_init(&tagged, &engine, master, (uint16_t)y);
            printf("ok\n");
        } else if (!strcmp(cmd, "put") && sscanf(line, "%*s %lu %lu", &x, &y) == 2) {
            printf("%d\n", vstig_tagged_put(&tagged, (uint16_t)x, (uint16_t)y));
        } else if (!strcmp(cmd, "recv") && sscanf(line, "%*s %lu %79s %79s %79s", &x, a, b, c) == 4 &&
                   unhex(a, bytes, sizeof bytes)) {
            vstig_msg_decode(bytes, &msg);
            if (!strcmp(b, "-")) {
                printf("%d\n", vstig_tagged_receive(&tagged, (vstig_auth_policy_t)x, &msg, NULL, NULL));
            } else {
                if (sscanf(b, "%lu", &y) != 1 || !unhex(c, tag, sizeof tag)) return 2;
                epoch = (uint32_t)y;
                printf("%d\n", vstig_tagged_receive(&tagged, (vstig_auth_policy_t)x, &msg, &epoch, tag));
            }
        } else if (!strcmp(cmd, "drain")) {
            n = vstig_engine_drain(&engine, out, 64);
            for (i = 0; i < n; i++) {
                if (i) printf(",");
                vstig_msg_encode(&out[i], bytes);
                print_hex(bytes, sizeof bytes);
                if (vstig_tagged_record(&tagged, &out[i], &epoch, tag)) {
                    printf("/%lu/", (unsigned long)epoch);
                    print_hex(tag, sizeof tag);
                } else {
                    printf("/-");
                }
            }
            printf("\n");
        } else if (!strcmp(cmd, "counts")) {
            printf("%lu %lu %lu\n", (unsigned long)tagged.refused_untagged, (unsigned long)tagged.refused_bad_tag,
                   (unsigned long)tagged.replays);
        } else {
            fprintf(stderr, "bad command: %s", line);
            return 2;
        }
    }
    return 0;
}
