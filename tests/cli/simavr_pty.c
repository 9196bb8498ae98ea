/*
 * A simulated robot board: an AVR firmware (ELF) in libsimavr, its UART0 on a fresh pty.
 *
 *   simavr_pty FIRMWARE.elf ROBOT_ID [MCU [HZ]]
 *
 * Prints the pty's path on the first line of stdout, then runs until SIGTERM or SIGINT
 * (or its parent's death). ROBOT_ID is written to EEPROM 0xB0-0xB1, where kilolib keeps a
 * Kilobot's id. simavr's own uart_pty part is not used: it also makes /tmp/simavr-uart*
 * symlinks (files nobody named, shared by every simulator on the machine).
 *
 * Bytes cross in both directions without loss while the firmware keeps up: the UART's
 * receive FIFO says when it has room (XON/XOFF), and what the pty cannot take yet waits.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <termios.h>
#include <unistd.h>

#include <simavr/avr_eeprom.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_time.h>

#define BUFFER 65536

typedef struct {
    avr_t *avr;
    avr_irq_t *to_avr;
    int master;
    int xon;
    unsigned char in[BUFFER], out[BUFFER];
    size_t in_len, in_done, out_len;
} board_t;

static volatile sig_atomic_t stopping;

static void on_signal(int sig) {
    (void)sig;
    stopping = 1;
}

static void byte_from_avr(avr_irq_t *irq, uint32_t value, void *param) {
    board_t *b = param;
    (void)irq;
    if (b->out_len < BUFFER) b->out[b->out_len++] = (unsigned char)value;
}

static void xon(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    ((board_t *)param)->xon = 1;
}

static void xoff(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    ((board_t *)param)->xon = 0;
}

/* Every simulated millisecond: bytes the pty brought go to the UART while it has room, and
 * what the firmware sent goes to the pty. */
static avr_cycle_count_t pump(avr_t *avr, avr_cycle_count_t when, void *param) {
    board_t *b = param;
    ssize_t n;
    if (b->in_done == b->in_len) {
        n = read(b->master, b->in, BUFFER);
        b->in_len = n > 0 ? (size_t)n : 0;
        b->in_done = 0;
    }
    while (b->xon && b->in_done < b->in_len) avr_raise_irq(b->to_avr, b->in[b->in_done++]);
    if (b->out_len) {
        n = write(b->master, b->out, b->out_len);
        if (n > 0) {
            memmove(b->out, b->out + n, b->out_len - (size_t)n);
            b->out_len -= (size_t)n;
        }
    }
    return when + avr_usec_to_cycles(avr, 1000);
}

static int open_pty(char *path, size_t size, int *slave) {
    struct termios raw;
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) || unlockpt(master) || ptsname_r(master, path, size)) return -1;
    /* the slave stays open here, raw, so nothing is echoed or translated before the peer opens it */
    *slave = open(path, O_RDWR | O_NOCTTY);
    if (*slave < 0 || tcgetattr(*slave, &raw)) return -1;
    cfmakeraw(&raw);
    if (tcsetattr(*slave, TCSANOW, &raw) || fcntl(master, F_SETFL, O_NONBLOCK)) return -1;
    return master;
}

int main(int argc, char **argv) {
    static board_t board;
    elf_firmware_t firmware;
    avr_eeprom_desc_t eeprom;
    uint8_t uid[2];
    uint32_t flags = 0;
    char path[256];
    int slave, state;
    unsigned long robot;
    if (argc < 3) {
        fprintf(stderr, "usage: %s FIRMWARE.elf ROBOT_ID [MCU [HZ]]\n", argv[0]);
        return 2;
    }
    robot = strtoul(argv[2], NULL, 0);
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    memset(&firmware, 0, sizeof firmware);
    if (elf_read_firmware(argv[1], &firmware) != 0) {
        fprintf(stderr, "%s: cannot read %s\n", argv[0], argv[1]);
        return 1;
    }
    snprintf(firmware.mmcu, sizeof firmware.mmcu, "%s", argc > 3 ? argv[3] : "atmega328p");
    firmware.frequency = argc > 4 ? (uint32_t)strtoul(argv[4], NULL, 0) : 8000000u;
    board.avr = avr_make_mcu_by_name(firmware.mmcu);
    if (!board.avr || avr_init(board.avr) != 0) {
        fprintf(stderr, "%s: no AVR core %s\n", argv[0], firmware.mmcu);
        return 1;
    }
    avr_load_firmware(board.avr, &firmware);
    board.avr->log = LOG_ERROR;
    uid[0] = (uint8_t)robot;
    uid[1] = (uint8_t)(robot >> 8);
    eeprom.ee = uid;
    eeprom.offset = 0xB0;
    eeprom.size = 2;
    avr_ioctl(board.avr, AVR_IOCTL_EEPROM_SET, &eeprom);

    board.master = open_pty(path, sizeof path, &slave);
    if (board.master < 0) {
        fprintf(stderr, "%s: cannot make a pty: %s\n", argv[0], strerror(errno));
        return 1;
    }
    avr_ioctl(board.avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(uint32_t)AVR_UART_FLAG_STDIO; /* binary, not lines for the console */
    avr_ioctl(board.avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    board.to_avr = avr_io_getirq(board.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(board.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), byte_from_avr,
                            &board);
    avr_irq_register_notify(avr_io_getirq(board.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), xon, &board);
    avr_irq_register_notify(avr_io_getirq(board.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), xoff, &board);
    avr_cycle_timer_register_usec(board.avr, 1000, pump, &board);

    printf("%s\n", path);
    fflush(stdout);
    do {
        state = avr_run(board.avr);
    } while (!stopping && state != cpu_Done && state != cpu_Crashed);
    if (state == cpu_Crashed) fprintf(stderr, "%s: the firmware crashed\n", argv[0]);
    close(board.master);
    close(slave);
    return state == cpu_Crashed ? 1 : 0;
}
