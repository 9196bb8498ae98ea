/* A udpin link's peers in C (peers.c): the addresses its sends go to, for the delivery (path.c) and the outlets. */
#ifndef VSTIG_EXT_PEERS_H
#define VSTIG_EXT_PEERS_H

#include "ext.h"

#ifdef _WIN32
#include <winsock2.h>
#include <ws2tcpip.h>
#else
#include <sys/socket.h>
#endif

typedef struct {
    struct sockaddr_storage addr;
    socklen_t len;
    double until; /* monotonic seconds: let go after this */
} vx_peer_t;

typedef struct {
    PyObject_HEAD
    vx_peer_t *peer;  /* in the order last heard, the least recent first */
    Py_ssize_t count, most;
    double timeout;
} vx_peers_t;

/* UdpPeers.heard: `addr` spoke at `now` (monotonic seconds). */
void vx_peers_heard(vx_peers_t *t, const struct sockaddr *addr, socklen_t len, double now);
/* UdpPeers.live: those past their time let go; how many are left (t->peer[0..count)). */
Py_ssize_t vx_peers_live(vx_peers_t *t, double now);

/* CLOCK_MONOTONIC in seconds: Python's time.monotonic. */
double vx_monotonic(void);

extern PyTypeObject vx_UdpPeersType;

#endif /* VSTIG_EXT_PEERS_H */
