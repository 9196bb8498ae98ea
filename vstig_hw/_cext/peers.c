/*
 * UdpPeers: a udpin link's peers, vstig_hw.transports.mavlink.UdpPeers in C (the addresses heard from within
 * `timeout` seconds, at most `most`, the least recently heard forgotten first).
 *
 * Reference: vstig_hw/transports/mavlink.py (held equal by tests/native; the index of the twins:
 *   vstig_hw/_vstig.pyi).
 *
 * The compiled delivery notes each datagram's source here as it reads it (path.c) and the outlet sends to what is
 * live (outlet.c), with no Python per datagram; the transport's own calls (its HEARTBEATs, a write the writer
 * makes) use the same object through its Python face (`heard`, `live`, `len`), addresses as the socket module
 * gives them: (host, port) for IPv4, (host, port, flowinfo, scope_id) for IPv6.
 */
#include "peers.h"

#include <string.h>
#include <time.h>
#include <structmember.h>
#ifndef _WIN32
#include <arpa/inet.h>
#include <netinet/in.h>
#endif

double vx_monotonic(void) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)now.tv_sec + (double)now.tv_nsec * 1e-9;
}

/* The same address as the socket module's tuples compare: family, host, port (IPv6: and flowinfo, scope). */
static int same_address(const struct sockaddr_storage *a, const struct sockaddr *b) {
    if (a->ss_family != b->sa_family) return 0;
    if (b->sa_family == AF_INET) {
        const struct sockaddr_in *x = (const struct sockaddr_in *)a, *y = (const struct sockaddr_in *)b;
        return x->sin_port == y->sin_port && x->sin_addr.s_addr == y->sin_addr.s_addr;
    }
    if (b->sa_family == AF_INET6) {
        const struct sockaddr_in6 *x = (const struct sockaddr_in6 *)a, *y = (const struct sockaddr_in6 *)b;
        return x->sin6_port == y->sin6_port && x->sin6_flowinfo == y->sin6_flowinfo &&
               x->sin6_scope_id == y->sin6_scope_id && memcmp(&x->sin6_addr, &y->sin6_addr, 16) == 0;
    }
    return 0;
}

static void forget(vx_peers_t *t, Py_ssize_t i) {
    memmove(&t->peer[i], &t->peer[i + 1], (size_t)(t->count - i - 1) * sizeof *t->peer);
    t->count--;
}

void vx_peers_heard(vx_peers_t *t, const struct sockaddr *addr, socklen_t len, double now) {
    Py_ssize_t i;
    vx_peer_t *last;
    if (len > (socklen_t)sizeof last->addr || t->most < 1) return;
    for (i = 0; i < t->count; i++) {
        if (same_address(&t->peer[i].addr, addr)) {
            forget(t, i); /* heard again: it goes last, the order being the order last heard */
            break;
        }
    }
    if (t->count == t->most) forget(t, 0);
    last = &t->peer[t->count++];
    memset(&last->addr, 0, sizeof last->addr);
    memcpy(&last->addr, addr, len);
    last->len = len;
    last->until = now + t->timeout;
}

Py_ssize_t vx_peers_live(vx_peers_t *t, double now) {
    Py_ssize_t i, kept = 0;
    for (i = 0; i < t->count; i++) {
        if (t->peer[i].until >= now) t->peer[kept++] = t->peer[i];
    }
    t->count = kept;
    return kept;
}

/* ---- the Python face ------------------------------------------------------------------ */

/* An address tuple as the socket module gives it, as a sockaddr; 0, or -1 with ValueError naming it. */
static int sockaddr_of(PyObject *address, struct sockaddr_storage *out, socklen_t *len) {
    const char *host;
    int port, v6;
    unsigned int flowinfo = 0, scope_id = 0;
    char bare[INET6_ADDRSTRLEN];
    memset(out, 0, sizeof *out);
    if (!PyTuple_Check(address) ||
        !PyArg_ParseTuple(address, "si|II", &host, &port, &flowinfo, &scope_id) || port < 0 || port > 65535) {
        PyErr_Clear();
        PyErr_Format(PyExc_ValueError, "a UDP peer is (host, port[, flowinfo, scope_id]), got %R", address);
        return -1;
    }
    v6 = strchr(host, ':') != NULL;
    PyOS_snprintf(bare, sizeof bare, "%s", host);
    if (strchr(bare, '%') != NULL) *strchr(bare, '%') = '\0'; /* fe80::1%eth0: the scope is scope_id's */
    if (!v6 && PyTuple_GET_SIZE(address) == 2) {
        struct sockaddr_in *in = (struct sockaddr_in *)out;
        in->sin_family = AF_INET;
        in->sin_port = htons((uint16_t)port);
        if (inet_pton(AF_INET, bare, &in->sin_addr) == 1) {
            *len = sizeof *in;
            return 0;
        }
    } else if (v6) {
        struct sockaddr_in6 *in6 = (struct sockaddr_in6 *)out;
        in6->sin6_family = AF_INET6;
        in6->sin6_port = htons((uint16_t)port);
        in6->sin6_flowinfo = htonl(flowinfo);
        in6->sin6_scope_id = scope_id;
        if (inet_pton(AF_INET6, bare, &in6->sin6_addr) == 1) {
            *len = sizeof *in6;
            return 0;
        }
    }
    PyErr_Format(PyExc_ValueError, "a UDP peer's host is a numeric IPv4 or IPv6 address, got %R", address);
    return -1;
}

/* A sockaddr as the socket module's tuple (new reference). */
static PyObject *address_of(const vx_peer_t *peer) {
    char host[INET6_ADDRSTRLEN];
    if (peer->addr.ss_family == AF_INET) {
        const struct sockaddr_in *in = (const struct sockaddr_in *)&peer->addr;
        inet_ntop(AF_INET, &in->sin_addr, host, sizeof host);
        return Py_BuildValue("(si)", host, (int)ntohs(in->sin_port));
    }
    {
        const struct sockaddr_in6 *in6 = (const struct sockaddr_in6 *)&peer->addr;
        inet_ntop(AF_INET6, &in6->sin6_addr, host, sizeof host);
        return Py_BuildValue("(siII)", host, (int)ntohs(in6->sin6_port), (unsigned int)ntohl(in6->sin6_flowinfo),
                             (unsigned int)in6->sin6_scope_id);
    }
}

static PyObject *UdpPeers_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"most", "timeout", NULL};
    Py_ssize_t most = 8;
    double timeout = 10.0;
    vx_peers_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|nd", kwlist, &most, &timeout)) return NULL;
    if (most < 1 || most > 4096) {
        PyErr_Format(PyExc_ValueError, "a udpin link keeps 1..4096 peers, got %zd", most);
        return NULL;
    }
    self = (vx_peers_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->most = most;
    self->timeout = timeout;
    self->peer = PyMem_Calloc((size_t)most, sizeof *self->peer);
    if (self->peer == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    return (PyObject *)self;
}

static void UdpPeers_dealloc(vx_peers_t *self) {
    PyMem_Free(self->peer);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *UdpPeers_heard(vx_peers_t *self, PyObject *args) {
    PyObject *address;
    double now;
    struct sockaddr_storage addr;
    socklen_t len;
    if (!PyArg_ParseTuple(args, "Od:heard", &address, &now) || sockaddr_of(address, &addr, &len) < 0) return NULL;
    vx_peers_heard(self, (const struct sockaddr *)&addr, len, now);
    Py_RETURN_NONE;
}

static PyObject *UdpPeers_live(vx_peers_t *self, PyObject *now_obj) {
    double now = PyFloat_AsDouble(now_obj);
    Py_ssize_t n, i;
    PyObject *list;
    if (now == -1.0 && PyErr_Occurred()) return NULL;
    n = vx_peers_live(self, now);
    if ((list = PyList_New(n)) == NULL) return NULL;
    for (i = 0; i < n; i++) {
        PyObject *address = address_of(&self->peer[i]);
        if (address == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, address);
    }
    return list;
}

static Py_ssize_t UdpPeers_len(vx_peers_t *self) { return self->count; }

static PyMethodDef UdpPeers_methods[] = {
    {"heard", (PyCFunction)UdpPeers_heard, METH_VARARGS, "heard(address, now): a datagram came from `address`."},
    {"live", (PyCFunction)UdpPeers_live, METH_O, "live(now): the addresses heard within `timeout`, oldest first."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef UdpPeers_members[] = {
    {"most", T_PYSSIZET, offsetof(vx_peers_t, most), READONLY, "Addresses kept at most."},
    {"timeout", T_DOUBLE, offsetof(vx_peers_t, timeout), READONLY, "Seconds an address is kept after it spoke."},
    {NULL, 0, 0, 0, NULL},
};

static PySequenceMethods UdpPeers_as_sequence = {.sq_length = (lenfunc)UdpPeers_len};

PyTypeObject vx_UdpPeersType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.UdpPeers",
    .tp_doc = "UdpPeers(most=8, timeout=10.0): a udpin link's peers, UdpPeers in C.",
    .tp_basicsize = sizeof(vx_peers_t),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = UdpPeers_new,
    .tp_dealloc = (destructor)UdpPeers_dealloc,
    .tp_methods = UdpPeers_methods,
    .tp_members = UdpPeers_members,
    .tp_as_sequence = &UdpPeers_as_sequence,
};
