/*
 * The vstig_auth test driver: one command per line on stdin, one result per line on stdout.
 *   key MASTER ROBOT                  -> the robot's key (hex)
 *   tag KEY STIGMERGY MESSAGE EPOCH   -> the entry's tag (hex)
 *   ok KEY STIGMERGY MESSAGE EPOCH TAG -> 1 when the tag checks out, else 0
 * Hex strings without spaces; numbers in decimal.
 */
#include <stdio.h>
#include <string.h>

#include "vstig_auth.h"
#include "hex_io.h"

int main(void) {
    char line[512], cmd[8], a[80], c[80], d[80];
    unsigned long robot, stigmergy, epoch;
    uint8_t key[VSTIG_KEY_SIZE], msg[8], tag[VSTIG_TAG_SIZE];
    vstig_tag_key_t ready;
    while (fgets(line, sizeof line, stdin)) {
        if (sscanf(line, "%7s", cmd) != 1) return 2;
        if (!strcmp(cmd, "key") && sscanf(line, "%*s %79s %lu", a, &robot) == 2 && unhex(a, key, sizeof key)) {
            vstig_master_init(&ready, key);
            vstig_robot_key(&ready, (uint16_t)robot, key);
            print_hex(key, sizeof key);
            printf("\n");
        } else if (!strcmp(cmd, "tag") && sscanf(line, "%*s %79s %lu %79s %lu", a, &stigmergy, c, &epoch) == 4 &&
                   unhex(a, key, sizeof key) && unhex(c, msg, sizeof msg)) {
            vstig_tag_key_init(&ready, key);
            vstig_tag(&ready, (uint16_t)stigmergy, msg, (uint32_t)epoch, tag);
            print_hex(tag, sizeof tag);
            printf("\n");
        } else if (!strcmp(cmd, "ok") &&
                   sscanf(line, "%*s %79s %lu %79s %lu %79s", a, &stigmergy, c, &epoch, d) == 5 &&
                   unhex(a, key, sizeof key) && unhex(c, msg, sizeof msg) && unhex(d, tag, sizeof tag)) {
            vstig_tag_key_init(&ready, key);
            printf("%u\n", (unsigned)vstig_tag_ok(&ready, (uint16_t)stigmergy, msg, (uint32_t)epoch, tag));
        } else {
            fprintf(stderr, "bad command: %s", line);
            return 2;
        }
    }
    return 0;
}
