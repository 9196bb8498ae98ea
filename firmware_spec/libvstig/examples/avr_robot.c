/*
 * A robot on an ATmega328P (the Kilobot's MCU) whose radio is its UART, speaking cobs8:
 * libvstig's engine driven by a sleeping main loop. It runs the paper's program: every
 * robot writes its id under key 1 and the larger value wins, so the swarm agrees on the
 * highest id; each control step the robot reads key 1 and reports what it holds under
 * key 0x100 + its id, so a PC sees this robot's own view converge.
 *
 * Its robot id is read from EEPROM bytes 0xB0-0xB1, where kilolib keeps a Kilobot's.
 *
 * Built with -DVSTIG_ROBOT_KEY='"robot_key.h"' (`vstig keys --swarm-key FILE ID --format c`, for this robot's id:
 * `make robot ROBOT_KEY=robot_key.h`), it is a robot of a swarm that checks tags (SPEC.md section 10), on a
 * gateway link with auth=require: it sends each entry it wrote as a record tagged with its own key, refuses an
 * entry claiming its id under a tag its key does not give, and takes only records. It holds no other robot's
 * key, so it keeps others' entries untagged and relays them so (a gateway that requires tags refuses those: it
 * holds them already). Its writes stay at epoch 0: this program never takes a key round the 16-bit wrap.
 * Build (the tests do it, and run it in simavr with its UART on a pty):
 *   avr-gcc -mmcu=atmega328p -DF_CPU=8000000UL -Os -DVSTIG_KEYS=16u -I.. avr_robot.c ../vstig_*.c
 */
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>

#include "vstig.h"

#ifdef VSTIG_ROBOT_KEY
#include VSTIG_ROBOT_KEY /* static const uint8_t vstig_own_key[VSTIG_KEY_SIZE] */
#define RX_PAYLOAD VSTIG_RECORD_SIZE /* an auth=require link: every frame a record (SPEC.md 10.5) */
static vstig_tag_key_t own_key;
#else
#define RX_PAYLOAD VSTIG_MESSAGE_SIZE /* cobs8: one message a frame */
#endif

#define BAUD_DIVISOR ((F_CPU / 8UL / 115200UL) - 1UL) /* 115200 8N1 (SPEC.md 6.0.1), double speed */
#define STEP_TICKS ((F_CPU / 64UL / 20UL) - 1UL)      /* a control step every 50 ms (Timer1, clk/64) */
#define UID_ADDRESS ((const uint8_t *)0xB0)           /* kilolib's EEPROM_UID */
#define KEY_LEADER 1u
#define KEY_REPORT 0x100u
#define BUDGET 4u    /* messages sent per control step: the radio's bandwidth */
#define RX_RING 128u /* bytes the UART interrupt can hold between two passes of the main loop */

static volatile uint8_t ring[RX_RING];
static volatile uint8_t ring_head, ring_tail, ring_lost; /* ring_lost: bytes the ring had no room for */
static volatile uint8_t step_due;

ISR(USART_RX_vect) {
    uint8_t byte = UDR0, next = (uint8_t)((ring_head + 1u) % RX_RING);
    if (next == ring_tail) {
        ring_lost++;
        return;
    }
    ring[ring_head] = byte;
    ring_head = next;
}

ISR(TIMER1_COMPA_vect) { step_due = 1; }

static void uart_send(const uint8_t *data, uint8_t len) {
    while (len--) {
        while (!(UCSR0A & _BV(UDRE0))) {
        }
        UDR0 = *data++;
    }
}

static void send_queue(vstig_engine_t *engine) {
    vstig_msg_t out[BUDGET];
    uint8_t payload[RX_PAYLOAD], frame[VSTIG_FRAME_SIZE(RX_PAYLOAD)];
    size_t i, n = vstig_engine_drain(engine, out, BUDGET);
    for (i = 0; i < n; i++) {
        uint8_t len = VSTIG_MESSAGE_SIZE;
        vstig_msg_encode(&out[i], payload);
#ifdef VSTIG_ROBOT_KEY
        if (out[i].robot == engine->robot && out[i].timestamp != 0) { /* its own entry: the record */
            uint8_t b;
            for (b = VSTIG_MESSAGE_SIZE; b < VSTIG_MESSAGE_SIZE + 4u; b++) payload[b] = 0; /* epoch 0 */
            vstig_tag(&own_key, 0, payload, 0, payload + VSTIG_MESSAGE_SIZE + 4u);
            len = VSTIG_RECORD_SIZE;
        }
#endif
        uart_send(frame, vstig_frame_encode(payload, len, frame));
    }
}

/* Whether a received payload may reach the engine: with a key, an entry claiming this robot's id must carry
 * the tag its key gives. */
static uint8_t acceptable(const uint8_t *payload, const vstig_msg_t *heard, uint16_t uid) {
#ifdef VSTIG_ROBOT_KEY
    uint32_t epoch = (uint32_t)payload[8] << 24 | (uint32_t)payload[9] << 16 | (uint16_t)payload[10] << 8 | payload[11];
    if (heard->robot == uid && heard->timestamp != 0)
        return vstig_tag_ok(&own_key, 0, payload, epoch, payload + VSTIG_MESSAGE_SIZE + 4u);
#else
    (void)payload, (void)heard, (void)uid;
#endif
    return 1;
}

/* Everything the UART brought since the last pass, through the framing into the engine. */
static void take_in(vstig_engine_t *engine, vstig_deframer_t *deframer) {
    vstig_msg_t heard;
    while (ring_tail != ring_head) {
        uint8_t byte = ring[ring_tail];
        ring_tail = (uint8_t)((ring_tail + 1u) % RX_RING);
        if (vstig_deframer_feed(deframer, byte, RX_PAYLOAD)) {
            vstig_msg_decode(deframer->buf, &heard);
            if (acceptable(deframer->buf, &heard, engine->robot)) vstig_engine_receive(engine, &heard);
        }
    }
}

int main(void) {
    static vstig_engine_t engine; /* the whole stigmergy: table and outgoing queue */
    static vstig_deframer_t deframer; /* the cobs8 receiver; deframer.drops counts what it drops */
    uint16_t uid = (uint16_t)(eeprom_read_byte(UID_ADDRESS) | (uint16_t)eeprom_read_byte(UID_ADDRESS + 1) << 8);
    uint16_t leader = 0, reported = 0;
    const uint8_t idle = 0; /* SPEC.md 6.0.3: a 0x00 first, so the far end drops any partial frame */

    vstig_engine_init(&engine, uid, vstig_larger_value_wins, 0, 0);
#ifdef VSTIG_ROBOT_KEY
    vstig_tag_key_init(&own_key, vstig_own_key);
#endif
    vstig_deframer_init(&deframer);
    UBRR0 = BAUD_DIVISOR;
    UCSR0A = _BV(U2X0);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    OCR1A = STEP_TICKS;
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10);
    TIMSK1 = _BV(OCIE1A);
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();
    uart_send(&idle, 1);
    vstig_engine_put(&engine, KEY_LEADER, uid);

    for (;;) {
        take_in(&engine, &deframer);
        if (step_due) {
            step_due = 0;
            if (vstig_engine_get(&engine, KEY_LEADER, &leader) == 1 && leader != reported) {
                vstig_engine_put(&engine, (uint16_t)(KEY_REPORT + uid), leader);
                reported = leader;
            }
            send_queue(&engine);
        }
        cli();
        if (ring_tail == ring_head && !step_due) { /* nothing to do: sleep until an interrupt */
            sleep_enable();
            sei();
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
