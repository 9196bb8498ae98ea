/*
 * libvstig: the vstig-hw protocol in portable C99, for robot firmware and gateways.
 * Include this one header; compile the vstig_*.c files beside it (README.md).
 *
 *   vstig_wire      the 8-byte message, timestamps (RFC 1982), CRCs, drop counters
 *   vstig_serial    the serial frame and the cobs8, epuck4, kilobot, kilobot-ohc framings
 *   vstig_can       the CAN ID scheme, classic frames and CAN FD batches
 *   vstig_xbee      Digi XBee API frames (modes 1 and 2): Receive Packets in, Transmit Requests out
 *   vstig_outqueue  the outgoing queue: one message per key, newest wins, PUTs first
 *   vstig_engine    put, get, receive, the conflict rule as a callback, drain
 *   vstig_guard     a gateway's jump bound
 *   vstig_auth      tags that prove who wrote an entry: BLAKE2s, robot keys (SPEC.md section 10)
 *   vstig_tagged    an engine with tags beside it, for a node holding the master secret (SPEC.md 10.4, 10.6)
 *
 * No malloc, no I/O, no clock, no global state: every structure is the caller's, passed
 * explicitly, with capacities fixed at compile time (vstig_config.h).
 */
#ifndef VSTIG_H
#define VSTIG_H

#include "vstig_wire.h"
#include "vstig_serial.h"
#include "vstig_can.h"
#include "vstig_xbee.h"
#include "vstig_mavlink.h"
#include "vstig_outqueue.h"
#include "vstig_engine.h"
#include "vstig_guard.h"
#include "vstig_auth.h"
#include "vstig_tagged.h"

#define VSTIG_FORMAT_VERSION 1u /* SPEC.md section 8 */

#endif /* VSTIG_H */
