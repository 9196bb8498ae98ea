/*
 * Test driver for vstig_wire: reads one command per line on stdin, writes one result
 * line per command on stdout. The test harness (tests/spec/) turns the JSON vectors
 * into these commands, so this file needs no JSON parser. Hex "-" is empty input.
 *
 *   encode OP KEY VALUE TS ROBOT      -> 16 hex digits
 *   decode HEX                        -> OP KEY VALUE TS ROBOT | drop bad_length
 *   newer A B / next TS               -> 1|0 / the next timestamp
 *   crc16 HEX / crc32 HEX / kilocrc HEX
 *   frame HEX / cobs8 MSG             -> serial frame hex
 *   cobs8_rx STREAM                   -> msgs=HEX,.. drops=name:n,..
 *   epuck4 MSG                        -> W0 W1 W2 F0 F1 F2 (words, then their UART frames)
 *   epuck4_rx EXPIRY EVENT..          -> msgs=.. drops=..  (EVENT: w:XXXXXXXX or t)
 *   epuck4_uart_rx STREAM             -> msgs=.. drops=..  (expiry 3)
 *   kilobot MSG TYPE                  -> message_t hex, then the UART frame hex
 *   kilobot_rx TYPE STREAM            -> msgs=.. drops=..
 *   ohc MSG PACKET_TYPE TYPE          -> 132-byte packet hex
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vstig_wire.h"

#define MAX_BYTES 65536

static size_t parse_hex(const char *text, uint8_t *out) {
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    while (text[0] && text[1] && n < MAX_BYTES) {
        char pair[3] = {text[0], text[1], 0};
        out[n++] = (uint8_t)strtoul(pair, NULL, 16);
        text += 2;
    }
    return n;
}

static void print_hex(const uint8_t *data, size_t len) {
    size_t i;
    if (len == 0) fputs("-", stdout);
    for (i = 0; i < len; i++) printf("%02x", data[i]);
}

static const char *const ops[2] = {"PUT", "GET"};

static void print_msg_hex(const vstig_msg_t *m) {
    uint8_t raw[VSTIG_MESSAGE_SIZE];
    vstig_msg_encode(m, raw);
    print_hex(raw, sizeof raw);
}

/* Collected results of a receive run, printed as msgs=... drops=... */
typedef struct {
    vstig_msg_t msgs[4096];
    unsigned n;
} results_t;

static void add(results_t *r, const vstig_msg_t *m) {
    if (r->n < 4096) r->msgs[r->n++] = *m;
}

static void print_results(const results_t *r, const vstig_drops_t *drops) {
    unsigned i, first = 1;
    fputs("msgs=", stdout);
    if (r->n == 0) fputs("-", stdout);
    for (i = 0; i < r->n; i++) {
        if (i) fputs(",", stdout);
        print_msg_hex(&r->msgs[i]);
    }
    fputs(" drops=", stdout);
    for (i = 0; i < VSTIG_DROP_REASONS; i++) {
        if (!drops->count[i]) continue;
        printf("%s%s:%u", first ? "" : ",", vstig_drop_name((vstig_drop_t)i), drops->count[i]);
        first = 0;
    }
    if (first) fputs("-", stdout);
}

static void run(char *line) {
    static uint8_t buf[MAX_BYTES];
    static uint8_t out[MAX_BYTES];
    char *cmd = strtok(line, " \t\r\n");
    char *arg[4] = {0, 0, 0, 0};
    size_t n, i;
    vstig_msg_t m;
    static results_t res;
    res.n = 0;
    if (!cmd) return;
    for (i = 0; i < 4; i++) arg[i] = strtok(NULL, " \t\r\n");

    if (strcmp(cmd, "encode") == 0) {
        m.op = (uint8_t)(strcmp(arg[0], "GET") == 0);
        m.key = (uint16_t)strtoul(arg[1], NULL, 0);
        m.value = (uint16_t)strtoul(arg[2], NULL, 0);
        m.timestamp = (uint16_t)strtoul(arg[3], NULL, 0);
        m.robot = (uint16_t)strtoul(strtok(NULL, " \t\r\n"), NULL, 0);
        print_msg_hex(&m);
    } else if (strcmp(cmd, "decode") == 0) {
        n = parse_hex(arg[0], buf);
        if (n != VSTIG_MESSAGE_SIZE) {
            fputs("drop bad_length", stdout);
        } else {
            vstig_msg_decode(buf, &m);
            printf("%s %u %u %u %u", ops[m.op], m.key, m.value, m.timestamp, m.robot);
        }
    } else if (strcmp(cmd, "newer") == 0) {
        printf("%u", vstig_ts_newer((uint16_t)strtoul(arg[0], NULL, 0), (uint16_t)strtoul(arg[1], NULL, 0)));
    } else if (strcmp(cmd, "next") == 0) {
        printf("%u", vstig_ts_next((uint16_t)strtoul(arg[0], NULL, 0)));
    } else if (strcmp(cmd, "crc16") == 0) {
        n = parse_hex(arg[0], buf);
        printf("%04x", vstig_crc16(buf, n));
    } else if (strcmp(cmd, "kilocrc") == 0) {
        parse_hex(arg[0], buf);
        printf("%04x", vstig_kilobot_crc(buf));
    } else if (strcmp(cmd, "crc32") == 0) {
        n = parse_hex(arg[0], buf);
        printf("%08lx", (unsigned long)vstig_crc32(buf, n));
    } else if (strcmp(cmd, "frame") == 0) {
        n = parse_hex(arg[0], buf);
        print_hex(out, vstig_frame_encode(buf, (uint8_t)n, out));
    } else if (strcmp(cmd, "cobs8") == 0) {
        parse_hex(arg[0], buf);
        vstig_msg_decode(buf, &m);
        print_hex(out, vstig_cobs8_encode(&m, out));
    } else if (strcmp(cmd, "cobs8_rx") == 0) {
        vstig_deframer_t d;
        vstig_deframer_init(&d);
        n = parse_hex(arg[0], buf);
        for (i = 0; i < n; i++)
            if (vstig_cobs8_feed(&d, buf[i], &m)) add(&res, &m);
        print_results(&res, &d.drops);
    } else if (strcmp(cmd, "epuck4") == 0) {
        uint32_t words[3];
        parse_hex(arg[0], buf);
        vstig_msg_decode(buf, &m);
        vstig_epuck4_encode(&m, words);
        printf("%08lx %08lx %08lx", (unsigned long)words[0], (unsigned long)words[1], (unsigned long)words[2]);
        for (i = 0; i < 3; i++) {
            fputs(" ", stdout);
            print_hex(out, vstig_epuck4_word_frame(words[i], out));
        }
    } else if (strcmp(cmd, "epuck4_rx") == 0) {
        static vstig_epuck4_reassembler_t r;
        char *event = arg[1];
        vstig_epuck4_init(&r, (uint8_t)strtoul(arg[0], NULL, 0));
        /* arg[1..3] were already split off; continue with strtok for the rest */
        for (i = 1; event; i++) {
            if (event[0] == 't') {
                vstig_epuck4_tick(&r);
            } else if (vstig_epuck4_feed(&r, (uint32_t)strtoul(event + 2, NULL, 16), &m)) {
                add(&res, &m);
            }
            event = i < 3 ? arg[i + 1] : strtok(NULL, " \t\r\n");
        }
        print_results(&res, &r.drops);
    } else if (strcmp(cmd, "epuck4_uart_rx") == 0) {
        static vstig_epuck4_reassembler_t r;
        vstig_deframer_t d;
        uint32_t word;
        vstig_deframer_init(&d);
        vstig_epuck4_init(&r, 3);
        n = parse_hex(arg[0], buf);
        for (i = 0; i < n; i++)
            if (vstig_epuck4_uart_feed(&d, buf[i], &word) && vstig_epuck4_feed(&r, word, &m)) add(&res, &m);
        for (i = 0; i < VSTIG_DROP_REASONS; i++) r.drops.count[i] = (uint16_t)(r.drops.count[i] + d.drops.count[i]);
        print_results(&res, &r.drops);
    } else if (strcmp(cmd, "kilobot") == 0) {
        parse_hex(arg[0], buf);
        vstig_msg_decode(buf, &m);
        vstig_kilobot_encode(&m, (uint8_t)strtoul(arg[1], NULL, 0), out);
        print_hex(out, 12);
        fputs(" ", stdout);
        print_hex(out, vstig_kilobot_frame(&m, (uint8_t)strtoul(arg[1], NULL, 0), out));
    } else if (strcmp(cmd, "kilobot_rx") == 0) {
        vstig_deframer_t d;
        uint8_t type = (uint8_t)strtoul(arg[0], NULL, 0);
        vstig_deframer_init(&d);
        n = parse_hex(arg[1], buf);
        for (i = 0; i < n; i++)
            if (vstig_kilobot_uart_feed(&d, buf[i], type, &m)) add(&res, &m);
        print_results(&res, &d.drops);
    } else if (strcmp(cmd, "ohc") == 0) {
        parse_hex(arg[0], buf);
        vstig_msg_decode(buf, &m);
        vstig_ohc_packet(&m, (uint8_t)strtoul(arg[1], NULL, 0), (uint8_t)strtoul(arg[2], NULL, 0), out);
        print_hex(out, VSTIG_OHC_PACKET_SIZE);
    } else {
        printf("error unknown command %s", cmd);
    }
}

int main(void) {
    static char line[2 * MAX_BYTES + 256];
    while (fgets(line, sizeof line, stdin)) {
        run(line);
        fputs("\n", stdout);
    }
    return 0;
}
