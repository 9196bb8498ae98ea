/*
 * Test driver for libvstig's MAVLink part (SPEC.md 6.10): one command per line on stdin, one result
 * line per command on stdout (tests/spec/test_spec_c_mavlink.py turns mavlink.json into these).
 *
 *   tx SYSID COMPID KEY LINK_ID STAMP MSGS  -> the TUNNEL's hex  (KEY hex or -; STAMP: the last timestamp signed
 *                                              with, 12 hex digits least significant first; MSGS comma-separated)
 *   txt SYSID COMPID KEY LINK_ID STAMP RECORDS  -> a tagged TUNNEL's hex (RECORDS: 20-byte records back to back)
 *   hb SYSID COMPID                         -> the HEARTBEAT's hex
 *   rx SYSID COMPID KEY CHUNK..             -> SENDER=MSGS;.. drops=name:n,..  (each chunk fed byte by byte, then
 *                                              the line goes quiet; SENDER sysid/compid; - if no frame; a tagged
 *                                              TUNNEL's messages are shown as MSG/RECORD)
 * With a key, rx keeps the last timestamp per (sysid, compid, link id) as SPEC.md 6.10.3 rule 6 says.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vstig.h"

#define MAX_BYTES 8192
#define STREAMS 16

static size_t parse_hex(const char *text, uint8_t *out, size_t cap) {
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    while (text[0] && text[1] && n < cap) {
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

/* ---- the caller's replay check ---------------------------------------------------- */
static struct {
    uint8_t sysid, compid, link_id, stamp[6];
} streams[STREAMS];
static unsigned n_streams;
static uint8_t newest[6];

/* a - b compared as 48-bit little-endian numbers: -1, 0, 1 */
static int compare(const uint8_t a[6], const uint8_t b[6]) {
    int i;
    for (i = 5; i >= 0; i--)
        if (a[i] != b[i]) return a[i] < b[i] ? -1 : 1;
    return 0;
}

/* 1 when the frame's timestamp is new for its stream (and remembered); 0: a replay. */
static uint8_t fresh(const uint8_t *frame, uint16_t len) {
    uint8_t link_id, stamp[6], floor[6];
    unsigned i;
    uint32_t borrow = 6000000ul; /* 60 s in 10 us units: a new stream may start this far behind the newest */
    if (!vstig_mavlink_timestamp(frame, len, &link_id, stamp)) return 0;
    for (i = 0; i < n_streams; i++)
        if (streams[i].sysid == frame[5] && streams[i].compid == frame[6] && streams[i].link_id == link_id) break;
    if (i < n_streams) {
        if (compare(stamp, streams[i].stamp) <= 0) return 0;
    } else {
        int j;
        for (j = 0; j < 6; j++) { /* floor = newest - 60 s, clamped at 0 */
            uint32_t d = (uint32_t)newest[j] - (borrow & 0xFFu);
            floor[j] = (uint8_t)d;
            borrow = (borrow >> 8) + ((d >> 8) ? 1u : 0u);
        }
        if ((!borrow && compare(stamp, floor) <= 0) || n_streams == STREAMS) return 0; /* borrow: floor < 0 */
        i = n_streams++;
        streams[i].sysid = frame[5];
        streams[i].compid = frame[6];
        streams[i].link_id = link_id;
    }
    memcpy(streams[i].stamp, stamp, 6);
    if (compare(stamp, newest) > 0) memcpy(newest, stamp, 6);
    return 1;
}

static unsigned frames_shown;

static void take(vstig_mavlink_rx_t *rx, uint8_t sysid, uint8_t compid, const uint8_t *key) {
    vstig_msg_t msgs[VSTIG_MAVLINK_MAX_MESSAGES];
    uint8_t records[VSTIG_MAVLINK_MAX_RECORDS * VSTIG_RECORD_SIZE];
    uint8_t from_sysid, from_compid, n, i, tagged;
    if (!vstig_mavlink_check(rx, vstig_mavlink_frame(rx), vstig_mavlink_frame_len(rx), key)) return;
    if (key && !fresh(vstig_mavlink_frame(rx), vstig_mavlink_frame_len(rx))) {
        vstig_mavlink_count(rx, VSTIG_MAVLINK_DROP_REPLAY);
        return;
    }
    n = vstig_mavlink_records(rx, vstig_mavlink_frame(rx), sysid, compid, msgs, records, &tagged, &from_sysid,
                              &from_compid);
    if (!n) return;
    printf("%s%u/%u=", frames_shown++ ? ";" : "", from_sysid, from_compid);
    for (i = 0; i < n; i++) {
        uint8_t raw[VSTIG_MESSAGE_SIZE];
        vstig_msg_encode(&msgs[i], raw);
        fputs(i ? "," : "", stdout);
        print_hex(raw, sizeof raw);
        if (tagged) {
            fputs("/", stdout);
            print_hex(records + VSTIG_RECORD_SIZE * i, VSTIG_RECORD_SIZE);
        }
    }
}

static void rx_command(char **arg, int argc) {
    static vstig_mavlink_rx_t rx;
    static uint8_t bytes[MAX_BYTES];
    uint8_t key[VSTIG_MAVLINK_KEY_SIZE];
    uint8_t sysid = (uint8_t)strtoul(arg[0], NULL, 0), compid = (uint8_t)strtoul(arg[1], NULL, 0);
    const uint8_t *with = parse_hex(arg[2], key, sizeof key) == sizeof key ? key : NULL;
    unsigned shown = 0, reason;
    int a;
    vstig_mavlink_rx_init(&rx);
    n_streams = 0;
    memset(newest, 0, sizeof newest);
    frames_shown = 0;
    for (a = 3; a < argc; a++) {
        size_t n = parse_hex(arg[a], bytes, sizeof bytes), k;
        for (k = 0; k < n; k++) {
            if (!vstig_mavlink_feed(&rx, bytes[k])) continue;
            do take(&rx, sysid, compid, with);
            while (vstig_mavlink_next(&rx));
        }
    }
    if (vstig_mavlink_flush(&rx)) {
        do take(&rx, sysid, compid, with);
        while (vstig_mavlink_next(&rx));
    }
    if (!frames_shown) fputs("-", stdout);
    fputs(" drops=", stdout);
    for (reason = 0; reason < VSTIG_MAVLINK_DROP_REASONS; reason++) {
        if (!rx.drops[reason]) continue;
        printf("%s%s:%u", shown++ ? "," : "", vstig_mavlink_drop_name((vstig_mavlink_drop_t)reason),
               rx.drops[reason]);
    }
    if (!shown) fputs("-", stdout);
}

/* tx (tagged 0) or txt (tagged 1) */
static void tx_command(char **arg, int tagged) {
    static uint8_t key[VSTIG_MAVLINK_KEY_SIZE];
    vstig_mavlink_tx_t tx;
    vstig_msg_t msgs[VSTIG_MAVLINK_MAX_MESSAGES];
    uint8_t out[VSTIG_MAVLINK_FRAME_MAX], raw[VSTIG_MESSAGE_SIZE];
    uint8_t records[VSTIG_MAVLINK_MAX_RECORDS * VSTIG_RECORD_SIZE];
    const char *m = arg[5];
    uint8_t n = 0;
    int signed_ = parse_hex(arg[2], key, sizeof key) == sizeof key;
    vstig_mavlink_tx_init(&tx, (uint8_t)strtoul(arg[0], NULL, 0), (uint8_t)strtoul(arg[1], NULL, 0),
                          signed_ ? key : NULL);
    tx.link_id = (uint8_t)strtoul(arg[3], NULL, 0);
    parse_hex(arg[4], tx.timestamp, sizeof tx.timestamp);
    if (tagged) {
        n = (uint8_t)(parse_hex(m, records, sizeof records) / VSTIG_RECORD_SIZE);
        print_hex(out, vstig_mavlink_encode_tagged(&tx, records, n, out));
        return;
    }
    while (*m && n < VSTIG_MAVLINK_MAX_MESSAGES) {
        char hex[17];
        memcpy(hex, m, 16);
        hex[16] = 0;
        parse_hex(hex, raw, sizeof raw);
        vstig_msg_decode(raw, &msgs[n++]);
        m += 16;
        if (*m == ',') m++;
    }
    print_hex(out, vstig_mavlink_encode(&tx, msgs, n, out));
}

int main(void) {
    static char line[65536];
    while (fgets(line, sizeof line, stdin)) {
        char *arg[1024];
        int argc = 0;
        char *tok = strtok(line, " \n");
        while (tok && argc < 1024) {
            arg[argc++] = tok;
            tok = strtok(NULL, " \n");
        }
        if (argc == 0) {
            puts("?");
            continue;
        }
        if ((strcmp(arg[0], "tx") == 0 || strcmp(arg[0], "txt") == 0) && argc == 7) {
            tx_command(arg + 1, arg[0][2] == 't');
        } else if (strcmp(arg[0], "hb") == 0 && argc == 3) {
            vstig_mavlink_tx_t tx;
            uint8_t out[VSTIG_MAVLINK_FRAME_MAX];
            vstig_mavlink_tx_init(&tx, (uint8_t)strtoul(arg[1], NULL, 0), (uint8_t)strtoul(arg[2], NULL, 0), NULL);
            print_hex(out, vstig_mavlink_heartbeat(&tx, out));
        } else if (strcmp(arg[0], "rx") == 0 && argc >= 4) {
            rx_command(arg + 1, argc - 1);
        } else {
            fputs("?", stdout);
        }
        putchar('\n');
    }
    return 0;
}
