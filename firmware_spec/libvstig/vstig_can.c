/* vstig_can: the CAN ID scheme and payloads of SPEC.md 6.5. See vstig_can.h. */
#include "vstig_can.h"

#define BASE_MASK_29BIT 0x1E000000ul

int vstig_can_init(vstig_can_t *c, uint8_t extended, uint32_t base, uint8_t stigmergy, uint16_t sender,
                   uint8_t fd, uint8_t brs) {
    if (extended) {
        if (base == VSTIG_CAN_DEFAULT_BASE) base = 0x18000000ul;
        if (base & ~BASE_MASK_29BIT) return VSTIG_ERR_ARG;
        c->match_mask = 0x1FFE0000ul;
        c->match_value = base | (uint32_t)stigmergy << 17;
        c->op_shift = 16;
        c->sender_mask = 0xFFFFu;
    } else {
        if (base == VSTIG_CAN_DEFAULT_BASE) base = 0x600u;
        if ((base & ~0x600ul) || stigmergy) return VSTIG_ERR_ARG;
        c->match_mask = 0x600u;
        c->match_value = base;
        c->op_shift = 8;
        c->sender_mask = 0xFFu;
    }
    c->extended = (uint8_t)(extended != 0);
    c->fd = (uint8_t)(fd != 0);
    c->brs = (uint8_t)(brs && fd);
    vstig_drops_clear(&c->drops);
    if (!vstig_can_id(c, VSTIG_PUT, sender, &c->ids[0]) || !vstig_can_id(c, VSTIG_GET, sender, &c->ids[1]))
        return VSTIG_ERR_ARG;
    return 0;
}

uint8_t vstig_can_id(const vstig_can_t *c, uint8_t op, uint16_t sender, uint32_t *id) {
    if (sender > c->sender_mask) return 0;
    *id = c->match_value | (uint32_t)(op & 1u) << c->op_shift | sender;
    return 1;
}

/* The FD data lengths that are whole messages: 1, 2, 3, 4, 6 or 8 of them. */
static uint8_t fd_batch(uint8_t messages) { return messages <= 4u || messages == 6u || messages == 8u; }

size_t vstig_can_receive(vstig_can_t *c, const vstig_can_frame_t *frame, vstig_msg_t out[8], uint16_t *sender) {
    uint8_t op, i, n = 0;
    if (frame->error) {
        vstig_drops_count(&c->drops, VSTIG_DROP_ERROR_FRAME);
        return 0;
    }
    if ((frame->extended != 0) != c->extended || (frame->id & c->match_mask) != c->match_value) {
        vstig_drops_count(&c->drops, VSTIG_DROP_UNKNOWN_ID);
        return 0;
    }
    if (frame->rtr) {
        vstig_drops_count(&c->drops, VSTIG_DROP_REMOTE_FRAME);
        return 0;
    }
    if (frame->fd ? (frame->len == 0 || frame->len > VSTIG_CAN_FD_MAX || frame->len % VSTIG_MESSAGE_SIZE ||
                     !fd_batch((uint8_t)(frame->len / VSTIG_MESSAGE_SIZE)))
                  : frame->len != VSTIG_MESSAGE_SIZE) {
        vstig_drops_count(&c->drops, VSTIG_DROP_BAD_DLC);
        return 0;
    }
    op = (uint8_t)(frame->id >> c->op_shift & 1u);
    *sender = (uint16_t)(frame->id & c->sender_mask);
    for (i = 0; i < frame->len; i = (uint8_t)(i + VSTIG_MESSAGE_SIZE)) {
        vstig_msg_decode(&frame->data[i], &out[n]);
        if (out[n].op == op) n++;
        else vstig_drops_count(&c->drops, VSTIG_DROP_OP_MISMATCH); /* the ID's op decides its priority */
    }
    return n;
}

static void frame_head(const vstig_can_t *c, uint8_t op, vstig_can_frame_t *f) {
    f->id = c->ids[op];
    f->extended = c->extended;
    f->fd = c->fd;
    f->brs = c->brs;
    f->rtr = 0;
    f->error = 0;
    f->len = 0;
}

size_t vstig_can_encode(const vstig_can_t *c, const vstig_msg_t *msgs, size_t n, vstig_can_frame_t *frames) {
    size_t i, count = 0, left;
    uint8_t op, size;
    if (!c->fd) {
        for (i = 0; i < n; i++, count++) {
            frame_head(c, (uint8_t)(msgs[i].op & 1u), &frames[count]);
            vstig_msg_encode(&msgs[i], frames[count].data);
            frames[count].len = VSTIG_MESSAGE_SIZE;
        }
        return count;
    }
    for (op = 0; op < 2; op++) { /* a frame's ID carries one op: PUT frames, then GET frames */
        for (left = 0, i = 0; i < n; i++) left += (msgs[i].op & 1u) == op;
        for (i = 0; left; left -= size, count++) {
            size = (uint8_t)(left >= 8u ? 8u : left >= 6u ? 6u : left == 5u ? 4u : left); /* greedy: 7 = 6 + 1 */
            frame_head(c, op, &frames[count]);
            while (frames[count].len < size * VSTIG_MESSAGE_SIZE) {
                if ((msgs[i].op & 1u) == op) {
                    vstig_msg_encode(&msgs[i], &frames[count].data[frames[count].len]);
                    frames[count].len = (uint8_t)(frames[count].len + VSTIG_MESSAGE_SIZE);
                }
                i++;
            }
        }
    }
    return count;
}
