/*
 * Test driver for libvstig: reads one command per line on stdin, writes one result
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
 *   serial_rx FRAMING MAX CHUNK..     -> msgs=.. drops=..  (vstig_serial_receive, at most MAX per call)
 *   can_rx EXT BASE STIG ID IDE FD RTR DATA   -> sender=N msgs=.. drops=..  (BASE - : the default)
 *   can_tx EXT BASE STIG SENDER FD MSGS       -> ID#DATA or ID##1DATA per frame | refused
 *   engine_case SELF RESOLVER LOCAL BEFORE MSG -> OUTCOME entry=V,T,R|- queued=HEX,..|- lost=V,T,R|-
 *   traffic SEED ROUNDS               -> ok | fail WHAT  (random traffic through every part, invariants)
 *   xbee_rx API CHUNK..               -> SENDER=MSGS;.. drops=..  (each chunk fed byte by byte, then the line
 *                                        goes quiet; one SENDER=MSG,MSG per frame with messages, - if none)
 *   xbee_tx API NP TICKS MSGS..       -> frame hex per batch  (each MSGS one batch, comma-separated; TICKS:
 *                                        1 ticks before every batch, 0 never)
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vstig.h"

#define MAX_BYTES 65536
#define MAX_TOKENS 4096

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

static unsigned long num(const char *text) { return strtoul(text, NULL, 0); }

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

static void print_msgs(const vstig_msg_t *msgs, size_t n) {
    size_t i;
    if (n == 0) fputs("-", stdout);
    for (i = 0; i < n; i++) {
        if (i) fputs(",", stdout);
        print_msg_hex(&msgs[i]);
    }
}

static vstig_msg_t msg_of(const char *hex) {
    uint8_t raw[VSTIG_MESSAGE_SIZE] = {0};
    vstig_msg_t m;
    parse_hex(hex, raw);
    vstig_msg_decode(raw, &m);
    return m;
}

/* Collected results of a receive run, printed as msgs=... drops=... */
typedef struct {
    vstig_msg_t msgs[4096];
    unsigned n;
} results_t;

static results_t res;

static void add(const vstig_msg_t *m) {
    if (res.n < 4096) res.msgs[res.n++] = *m;
}

static void print_results(const vstig_drops_t *drops) {
    unsigned i, first = 1;
    fputs("msgs=", stdout);
    print_msgs(res.msgs, res.n);
    fputs(" drops=", stdout);
    for (i = 0; i < VSTIG_DROP_REASONS; i++) {
        if (!drops->count[i]) continue;
        printf("%s%s:%u", first ? "" : ",", vstig_drop_name((vstig_drop_t)i), drops->count[i]);
        first = 0;
    }
    if (first) fputs("-", stdout);
}

static void print_entry(const char *label, const vstig_entry_t *e) {
    if (e) printf(" %s=%u,%u,%u", label, e->value, e->timestamp, e->robot);
    else printf(" %s=-", label);
}

/* ---- engine_case: one row of vectors/receive.json ------------------------ */

static const char *const outcome_names[] = {"STORED", "ANSWERED", "STALE", "SAME", "CONFLICT",
                                            "UNKNOWN", "INVALID", "FULL", "BAD_WINNER"};

static vstig_resolver_t resolver_named(const char *name) {
    if (strcmp(name, "sum_merge") == 0) return vstig_sum_merge;
    if (strcmp(name, "larger_value") == 0) return vstig_larger_value_wins;
    return vstig_higher_robot_wins;
}

static vstig_entry_t lost_entry;
static uint8_t lost_calls;

static void on_lost(void *ctx, uint16_t key, const vstig_entry_t *lost) {
    (void)ctx;
    (void)key;
    lost_entry = *lost;
    lost_calls++;
}

static void engine_case(char **arg) {
    static vstig_engine_t e;
    static vstig_msg_t drained[VSTIG_QUEUE];
    vstig_msg_t m = msg_of(arg[4]);
    vstig_entry_t entry;
    uint16_t value;
    size_t n;
    vstig_engine_init(&e, (uint16_t)num(arg[0]), resolver_named(arg[1]), on_lost, NULL);
    lost_calls = 0;
    if (strcmp(arg[2], "-") != 0) {
        vstig_msg_t local = msg_of(arg[2]);
        vstig_engine_receive(&e, &local);
        vstig_engine_drain(&e, drained, VSTIG_QUEUE);
    }
    if (strcmp(arg[3], "get") == 0) vstig_engine_get(&e, m.key, &value);
    fputs(outcome_names[vstig_engine_receive(&e, &m)], stdout);
    print_entry("entry", vstig_engine_entry(&e, m.key, &entry) ? &entry : NULL);
    n = vstig_engine_drain(&e, drained, VSTIG_QUEUE);
    fputs(" queued=", stdout);
    print_msgs(drained, n);
    print_entry("lost", lost_calls ? &lost_entry : NULL);
}

/* ---- CAN ------------------------------------------------------------------ */

static int can_setup(vstig_can_t *c, char **arg, uint16_t sender, uint8_t fd) {
    uint32_t base = strcmp(arg[1], "-") == 0 ? VSTIG_CAN_DEFAULT_BASE : (uint32_t)num(arg[1]);
    return vstig_can_init(c, (uint8_t)num(arg[0]), base, (uint8_t)num(arg[2]), sender, fd, fd);
}

static void can_rx(char **arg) {
    vstig_can_t c;
    vstig_can_frame_t f;
    vstig_msg_t out[8];
    uint16_t sender = 0;
    size_t n, i;
    if (can_setup(&c, arg, 0, 0) != 0) {
        fputs("refused", stdout);
        return;
    }
    f.id = (uint32_t)num(arg[3]);
    f.extended = (uint8_t)num(arg[4]);
    f.fd = (uint8_t)num(arg[5]);
    f.rtr = (uint8_t)num(arg[6]);
    f.error = 0;
    f.brs = f.fd;
    f.len = (uint8_t)parse_hex(arg[7], f.data);
    n = vstig_can_receive(&c, &f, out, &sender);
    for (i = 0; i < n; i++) add(&out[i]);
    printf("sender=%u ", n ? sender : 0u);
    print_results(&c.drops);
}

static void can_tx(char **arg) {
    static vstig_can_frame_t frames[512];
    static vstig_msg_t msgs[512];
    static uint8_t raw[MAX_BYTES];
    vstig_can_t c;
    size_t n = parse_hex(arg[5], raw) / VSTIG_MESSAGE_SIZE, i, k;
    if (n > 512 || can_setup(&c, arg, (uint16_t)num(arg[3]), (uint8_t)num(arg[4])) != 0) {
        fputs("refused", stdout);
        return;
    }
    for (i = 0; i < n; i++) vstig_msg_decode(&raw[i * VSTIG_MESSAGE_SIZE], &msgs[i]);
    n = vstig_can_encode(&c, msgs, n, frames);
    for (i = 0; i < n; i++) {
        printf(i ? " %0*lX#%s" : "%0*lX#%s", frames[i].extended ? 8 : 3, (unsigned long)frames[i].id,
               frames[i].fd ? (frames[i].brs ? "#1" : "#0") : "");
        for (k = 0; k < frames[i].len; k++) printf("%02X", frames[i].data[k]); /* as can-utils writes it */
    }
    if (n == 0) fputs("-", stdout);
}

/* ---- traffic: random input through every part, checking what must always hold ---------- */

static uint32_t rng_state;

static uint32_t rnd(void) { /* xorshift32 */
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

static vstig_msg_t random_msg(uint16_t keys) {
    vstig_msg_t m;
    m.op = (uint8_t)(rnd() & 1u);
    m.key = (uint16_t)(rnd() % keys);
    m.value = (uint16_t)rnd();
    m.timestamp = (uint16_t)(rnd() & 3u ? rnd() % 8u : rnd());
    m.robot = (uint16_t)(rnd() % 4u);
    return m;
}

static const char *check_drained(const vstig_msg_t *out, size_t n) {
    static uint8_t seen[VSTIG_KEY_MAX + 1u];
    size_t i;
    memset(seen, 0, sizeof seen);
    for (i = 0; i < n; i++) {
        if (seen[out[i].key]++) return "two messages for one key";
        if (i && out[i - 1].op > out[i].op) return "a PUT after a GET";
    }
    return NULL;
}

static const char *traffic_round(void) {
    static vstig_engine_t e;
    static vstig_outqueue_t q;
    static vstig_guard_t g;
    static vstig_epuck4_reassembler_t r;
    static vstig_msg_t out[VSTIG_QUEUE + 64u];
    static vstig_can_frame_t frames[64];
    static uint8_t bytes[512];
    static vstig_msg_t sent[64];
    const vstig_resolver_t rules[3] = {vstig_higher_robot_wins, vstig_larger_value_wins, vstig_sum_merge};
    vstig_serial_rx_t rx;
    vstig_can_t c;
    vstig_entry_t entry;
    uint16_t keys = (uint16_t)(rnd() & 1u ? 8u : 4u * VSTIG_KEYS), i, value, sender, place, size = 0;
    size_t n, used, got, k, len;
    const char *why;
    vstig_engine_init(&e, (uint16_t)(rnd() % 4u), rules[rnd() % 3u], on_lost, NULL);
    vstig_outqueue_init(&q);
    vstig_guard_init(&g, (uint16_t)(1u + rnd() % 300u), 1024u, rnd() & 1u ? VSTIG_GUARD_NEVER_LEARNT : rnd() % 4096u);
    for (i = 0; i < 400; i++) {
        vstig_msg_t m = random_msg(keys);
        switch (rnd() % 4u) {
        case 0: vstig_engine_put(&e, m.key, m.value); break;
        case 1: vstig_engine_get(&e, m.key, &value); break;
        default:
            if (vstig_guard_check(&g, &m, (uint32_t)i * 100u) == VSTIG_GUARD_PASS) vstig_engine_receive(&e, &m);
        }
        vstig_outqueue_push(&q, &m);
        if (e.out.len > VSTIG_QUEUE || q.len > VSTIG_QUEUE || e.size > VSTIG_KEYS) return "over capacity";
        if (rnd() % 16u == 0) {
            n = vstig_engine_drain(&e, out, rnd() % 8u);
            if ((why = check_drained(out, n)) != NULL) return why;
        }
    }
    for (place = 0; place < VSTIG_KEYS; place++) {
        uint16_t key;
        vstig_entry_t found;
        if (!vstig_engine_at(&e, place, &key, &entry)) continue;
        size++;
        if (!vstig_engine_entry(&e, key, &found) || found.timestamp != entry.timestamp) return "an entry not found";
    }
    if (size != e.size) return "size differs from the entries";
    n = vstig_engine_drain(&e, out, VSTIG_QUEUE + 64u);
    if (n > VSTIG_QUEUE || e.out.len != 0 || (why = check_drained(out, n)) != NULL) return why ? why : "drain all";
    n = vstig_outqueue_drain(&q, out, VSTIG_QUEUE);
    if (q.len != 0 || (why = check_drained(out, n)) != NULL) return why ? why : "queue drain all";
    /* serial receivers over random bytes, a few at a time */
    vstig_epuck4_init(&r, (uint8_t)(1u + rnd() % 5u));
    vstig_serial_rx_init(&rx, (uint8_t)(rnd() % 3u), VSTIG_KILOBOT_TYPE, &r);
    len = 1u + rnd() % sizeof bytes;
    for (k = 0; k < len; k++) bytes[k] = (uint8_t)(rnd() % 4u ? rnd() : 0u);
    for (k = 0; k < len; k += used) {
        got = vstig_serial_receive(&rx, &bytes[k], len - k, &used, out, 1u + rnd() % 2u);
        if (got > 2 || (used == 0 && k < len)) return "serial receive";
    }
    /* CAN: random frames in, and every batch sent comes back whole */
    if (vstig_can_init(&c, (uint8_t)(rnd() & 1u), VSTIG_CAN_DEFAULT_BASE, 0, (uint16_t)(rnd() % 256u),
                       (uint8_t)(rnd() & 1u), 1) != 0)
        return "can init";
    n = rnd() % 64u;
    for (k = 0; k < n; k++) sent[k] = random_msg(keys);
    got = vstig_can_encode(&c, sent, n, frames);
    for (len = 0, k = 0; k < got; k++) {
        len += vstig_can_receive(&c, &frames[k], &out[len], &sender);
        frames[k].len = (uint8_t)(rnd() % 65u); /* then mangled */
        frames[k].rtr = (uint8_t)(rnd() % 8u == 0);
        frames[k].id ^= rnd() % 4u == 0 ? (uint32_t)1u << (rnd() % 29u) : 0u;
        vstig_can_receive(&c, &frames[k], &out[VSTIG_QUEUE], &sender);
    }
    if (len != n || got > n) return "a CAN batch came back changed";
    return NULL;
}

static void traffic(char **arg) {
    unsigned long rounds = num(arg[1]), i;
    const char *why;
    rng_state = (uint32_t)num(arg[0]) | 1u;
    for (i = 0; i < rounds; i++) {
        if ((why = traffic_round()) != NULL) {
            printf("fail round %lu: %s", i, why);
            return;
        }
    }
    fputs("ok", stdout);
}

/* ---- the codec and serial framings ---------------------------------------- */

/* The frames a receiver completed: SENDER=MSG,MSG per frame that carried messages. */
static unsigned xbee_frames;

static void xbee_frame(vstig_xbee_rx_t *rx, vstig_drops_t *drops) {
    vstig_msg_t got[VSTIG_XBEE_MAX_MESSAGES];
    uint8_t source[8], has_source, n;
    if (vstig_xbee_messages(vstig_xbee_frame_data(rx), vstig_xbee_frame_len(rx), got, &n, source, &has_source,
                            drops) != VSTIG_XBEE_MESSAGES)
        return;
    fputs(xbee_frames++ ? ";" : "", stdout);
    if (has_source) print_hex(source, 8);
    else fputs("-", stdout);
    fputs("=", stdout);
    print_msgs(got, n);
}

static void xbee_rx(char **arg, int argc) {
    static vstig_xbee_rx_t rx;
    static uint8_t bytes[MAX_BYTES];
    vstig_drops_t drops;
    size_t n, k;
    int i;
    vstig_xbee_rx_init(&rx, (uint8_t)(num(arg[0]) == 2));
    vstig_drops_clear(&drops);
    xbee_frames = 0;
    for (i = 1; i < argc; i++) {
        n = parse_hex(arg[i], bytes);
        for (k = 0; k < n; k++) {
            if (!vstig_xbee_feed(&rx, bytes[k])) continue;
            do xbee_frame(&rx, &drops);
            while (vstig_xbee_next(&rx));
        }
    }
    if (vstig_xbee_flush(&rx)) {
        do xbee_frame(&rx, &drops);
        while (vstig_xbee_next(&rx));
    }
    if (!xbee_frames) fputs("-", stdout);
    for (i = 0; i < VSTIG_DROP_REASONS; i++) vstig_drops_add(&drops, (vstig_drop_t)i, rx.drops.count[i]);
    res.n = 0;
    fputs(" ", stdout);
    print_results(&drops);
}

static void xbee_tx(char **arg, int argc) {
    static vstig_msg_t msgs[256];
    static uint8_t out[VSTIG_XBEE_TX_BYTES(256)];
    vstig_xbee_tx_t tx;
    int i;
    vstig_xbee_tx_init(&tx, (uint8_t)(num(arg[0]) == 2), NULL);
    vstig_xbee_max_payload(&tx, (uint16_t)num(arg[1]));
    for (i = 3; i < argc; i++) {
        size_t n = 0;
        char *m = strtok(arg[i], ",");
        for (; m != NULL && n < 256; m = strtok(NULL, ",")) msgs[n++] = msg_of(m);
        if (num(arg[2])) vstig_xbee_tick(&tx);
        if (i > 3) fputs(" ", stdout);
        print_hex(out, vstig_xbee_encode(&tx, msgs, n, out));
    }
}

static void run(char *line) {
    static uint8_t buf[MAX_BYTES];
    static uint8_t out[MAX_BYTES];
    static char *arg[MAX_TOKENS];
    char *cmd = strtok(line, " \t\r\n");
    size_t n, i, argc = 0;
    vstig_msg_t m;
    res.n = 0;
    if (!cmd) return;
    while (argc < MAX_TOKENS - 1 && (arg[argc] = strtok(NULL, " \t\r\n")) != NULL) argc++;
    arg[argc] = NULL;

    if (strcmp(cmd, "encode") == 0) {
        m.op = (uint8_t)(strcmp(arg[0], "GET") == 0);
        m.key = (uint16_t)num(arg[1]);
        m.value = (uint16_t)num(arg[2]);
        m.timestamp = (uint16_t)num(arg[3]);
        m.robot = (uint16_t)num(arg[4]);
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
        printf("%u", vstig_ts_newer((uint16_t)num(arg[0]), (uint16_t)num(arg[1])));
    } else if (strcmp(cmd, "next") == 0) {
        printf("%u", vstig_ts_next((uint16_t)num(arg[0])));
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
        m = msg_of(arg[0]);
        print_hex(out, vstig_cobs8_encode(&m, out));
    } else if (strcmp(cmd, "cobs8_rx") == 0) {
        vstig_deframer_t d;
        vstig_deframer_init(&d);
        n = parse_hex(arg[0], buf);
        for (i = 0; i < n; i++)
            if (vstig_cobs8_feed(&d, buf[i], &m)) add(&m);
        print_results(&d.drops);
    } else if (strcmp(cmd, "epuck4") == 0) {
        uint32_t words[3];
        m = msg_of(arg[0]);
        vstig_epuck4_encode(&m, words);
        printf("%08lx %08lx %08lx", (unsigned long)words[0], (unsigned long)words[1], (unsigned long)words[2]);
        for (i = 0; i < 3; i++) {
            fputs(" ", stdout);
            print_hex(out, vstig_epuck4_word_frame(words[i], out));
        }
    } else if (strcmp(cmd, "epuck4_rx") == 0) {
        static vstig_epuck4_reassembler_t r;
        vstig_epuck4_init(&r, (uint8_t)num(arg[0]));
        for (i = 1; i < argc; i++) {
            if (arg[i][0] == 't') vstig_epuck4_tick(&r);
            else if (vstig_epuck4_feed(&r, (uint32_t)strtoul(arg[i] + 2, NULL, 16), &m)) add(&m);
        }
        print_results(&r.drops);
    } else if (strcmp(cmd, "epuck4_uart_rx") == 0) {
        static vstig_epuck4_reassembler_t r;
        vstig_deframer_t d;
        uint32_t word;
        vstig_deframer_init(&d);
        vstig_epuck4_init(&r, 3);
        n = parse_hex(arg[0], buf);
        for (i = 0; i < n; i++)
            if (vstig_epuck4_uart_feed(&d, buf[i], &word) && vstig_epuck4_feed(&r, word, &m)) add(&m);
        for (i = 0; i < VSTIG_DROP_REASONS; i++) vstig_drops_add(&r.drops, (vstig_drop_t)i, d.drops.count[i]);
        print_results(&r.drops);
    } else if (strcmp(cmd, "kilobot") == 0) {
        m = msg_of(arg[0]);
        vstig_kilobot_encode(&m, (uint8_t)num(arg[1]), out);
        print_hex(out, 12);
        fputs(" ", stdout);
        print_hex(out, vstig_kilobot_frame(&m, (uint8_t)num(arg[1]), out));
    } else if (strcmp(cmd, "kilobot_rx") == 0) {
        vstig_deframer_t d;
        uint8_t type = (uint8_t)num(arg[0]);
        vstig_deframer_init(&d);
        n = parse_hex(arg[1], buf);
        for (i = 0; i < n; i++)
            if (vstig_kilobot_uart_feed(&d, buf[i], type, &m)) add(&m);
        print_results(&d.drops);
    } else if (strcmp(cmd, "ohc") == 0) {
        m = msg_of(arg[0]);
        vstig_ohc_packet(&m, (uint8_t)num(arg[1]), (uint8_t)num(arg[2]), out);
        print_hex(out, VSTIG_OHC_PACKET_SIZE);
    } else if (strcmp(cmd, "serial_rx") == 0) {
        static vstig_epuck4_reassembler_t r;
        static vstig_msg_t got[64];
        vstig_serial_rx_t rx;
        size_t max = num(arg[1]), used, k, j;
        vstig_epuck4_init(&r, 3);
        if (max > 64 || vstig_serial_rx_init(&rx, (uint8_t)num(arg[0]), VSTIG_KILOBOT_TYPE, &r) != 0) {
            fputs("refused", stdout);
            return;
        }
        for (i = 2; i < argc; i++) {
            n = parse_hex(arg[i], buf);
            for (k = 0; k < n; k += used) {
                size_t count = vstig_serial_receive(&rx, &buf[k], n - k, &used, got, max);
                for (j = 0; j < count; j++) add(&got[j]);
            }
        }
        for (i = 0; i < VSTIG_DROP_REASONS; i++) vstig_drops_add(&r.drops, (vstig_drop_t)i, rx.deframer.drops.count[i]);
        print_results(&r.drops);
    } else if (strcmp(cmd, "can_rx") == 0) {
        can_rx(arg);
    } else if (strcmp(cmd, "can_tx") == 0) {
        can_tx(arg);
    } else if (strcmp(cmd, "engine_case") == 0) {
        engine_case(arg);
    } else if (strcmp(cmd, "traffic") == 0) {
        traffic(arg);
    } else if (strcmp(cmd, "xbee_rx") == 0) {
        xbee_rx(arg, (int)argc);
    } else if (strcmp(cmd, "xbee_tx") == 0) {
        xbee_tx(arg, (int)argc);
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
