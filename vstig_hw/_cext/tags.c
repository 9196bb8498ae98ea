/*
 * The swarm key's part of an Engine: what makes it the twin of vstig_hw.gateway.signing.SignedEngine (the engine
 * with vstig_hw.tagged.TaggedStigmergy beside it), over libvstig's vstig_tagged (writers' prepared keys cached).
 *
 * Reference: vstig_hw/gateway/signing.py vstig_hw/tagged.py (held equal by tests/native; the index of the twins:
 *   vstig_hw/_vstig.pyi).
 *
 * A unit's check by its link's policy happens before the intake and the guard (path.c, or Signing.check on the
 * Python delivery); what passes reaches the engine's receive (vx_tags_receive) with the unit's record, found as
 * SignedEngine finds it in Signing.records: by the message.
 */
#include "tags.h"

#include <string.h>

vx_tags_t *vx_tags_new(vstig_engine_t *engine, PyObject *key, int stigmergy, PyObject *policies,
                       PyObject *record_type) {
    vx_tags_t *tags;
    if (!PyBytes_Check(key) || PyBytes_GET_SIZE(key) != (Py_ssize_t)VSTIG_KEY_SIZE) {
        PyErr_Format(PyExc_ValueError, "a swarm master secret is %u bytes", (unsigned)VSTIG_KEY_SIZE);
        return NULL;
    }
    if (stigmergy < 0 || stigmergy > 0xFFFF) {
        PyErr_Format(PyExc_ValueError, "stigmergy must be an integer in 0..65535, got %d", stigmergy);
        return NULL;
    }
    if (!PyTuple_Check(policies) || PyTuple_GET_SIZE(policies) != 3 || !PyCallable_Check(record_type)) {
        PyErr_SetString(PyExc_TypeError, "policies must be AuthPolicy's three members (require, prefer, off) and "
                                         "record the type of a record (Tagged)");
        return NULL;
    }
    tags = PyMem_Calloc(1, sizeof *tags);
    if (tags == NULL) {
        PyErr_NoMemory();
        return NULL;
    }
    vstig_tagged_init(&tags->tagged, engine, (const uint8_t *)PyBytes_AS_STRING(key), (uint16_t)stigmergy);
    tags->policy = VSTIG_AUTH_OFF;
    tags->policies = Py_NewRef(policies);
    tags->record_type = Py_NewRef(record_type);
    return tags;
}

void vx_tags_clear(vx_tags_t *tags) {
    if (tags == NULL) return;
    Py_CLEAR(tags->records_dict);
    Py_CLEAR(tags->policies);
    Py_CLEAR(tags->record_type);
}

void vx_tags_free(vx_tags_t *tags) {
    vx_tags_clear(tags);
    if (tags != NULL) PyMem_Free(tags->slots);
    PyMem_Free(tags);
}

int vx_tags_traverse(vx_tags_t *tags, visitproc visit, void *arg) {
    if (tags == NULL) return 0;
    Py_VISIT(tags->records_dict);
    Py_VISIT(tags->policies);
    Py_VISIT(tags->record_type);
    return 0;
}

static int same_msg(const vstig_msg_t *a, const vstig_msg_t *b) {
    return a->op == b->op && a->key == b->key && a->value == b->value && a->timestamp == b->timestamp &&
           a->robot == b->robot;
}

#define LINEAR_RECORDS 8u /* a unit of at most this many records is searched in order; a longer one by slot */

static size_t slot_of(const vx_tags_t *tags, const vstig_msg_t *msg) {
    uint32_t h = (uint32_t)msg->key * 2654435761u ^ (uint32_t)msg->timestamp * 40503u ^ msg->robot ^
                 (uint32_t)msg->value << 7 ^ msg->op;
    return (size_t)h & (tags->nslots - 1u);
}

/* A Tagged's epoch and tag (its fields 1 and 2); 0, or -1 with TypeError. */
static int record_fields(PyObject *found, vx_record_t *record) {
    PyObject *tag;
    unsigned long epoch;
    if (!PyTuple_Check(found) || PyTuple_GET_SIZE(found) != 3) goto bad;
    epoch = PyLong_AsUnsignedLong(PyTuple_GET_ITEM(found, 1));
    if (PyErr_Occurred() || epoch > 0xFFFFFFFFul) goto bad;
    tag = PyTuple_GET_ITEM(found, 2);
    if (!PyBytes_Check(tag) || PyBytes_GET_SIZE(tag) != (Py_ssize_t)VSTIG_TAG_SIZE) goto bad;
    record->epoch = (uint32_t)epoch;
    memcpy(record->tag, PyBytes_AS_STRING(tag), VSTIG_TAG_SIZE);
    return 0;
bad:
    PyErr_Clear();
    PyErr_Format(PyExc_TypeError, "a record is a Tagged(message, epoch, tag of %u bytes), got %R",
                 (unsigned)VSTIG_TAG_SIZE, found);
    return -1;
}

int vx_tags_record_in_unit(vx_tags_t *tags, const vstig_msg_t *msg, vx_record_t *record) {
    PyObject *key, *found;
    size_t i;
    if (tags->nrecords > LINEAR_RECORDS) {
        for (i = slot_of(tags, msg); tags->slots[i]; i = (i + 1u) & (tags->nslots - 1u)) {
            if (same_msg(&tags->records[tags->slots[i] - 1u].msg, msg)) {
                *record = tags->records[tags->slots[i] - 1u];
                return 1;
            }
        }
        return 0;
    }
    for (i = tags->nrecords; i-- > 0;) { /* the last of equal messages, as Signing.records keeps it */
        if (same_msg(&tags->records[i].msg, msg)) {
            *record = tags->records[i];
            return 1;
        }
    }
    if (tags->records_dict == NULL || PyDict_GET_SIZE(tags->records_dict) == 0) return 0;
    if ((key = vx_message(msg)) == NULL) return -1;
    found = PyDict_GetItemWithError(tags->records_dict, key);
    Py_DECREF(key);
    if (found == NULL) return PyErr_Occurred() ? -1 : 0;
    record->msg = *msg;
    return record_fields(found, record) < 0 ? -1 : 1;
}

int vx_tags_receive(vx_tags_t *tags, const vstig_msg_t *msg) {
    vx_record_t record;
    int has = vx_tags_record_in_unit(tags, msg, &record);
    if (has < 0) return -1;
    /* checked before the guard (SignedEngine.receive's checked=True): applied, never refused here */
    return vstig_tagged_apply(&tags->tagged, tags->policy, msg, has ? &record.epoch : NULL, has ? record.tag : NULL);
}

PyObject *vx_tags_record_of(vx_tags_t *tags, PyObject *msg_obj) {
    vstig_msg_t msg;
    uint32_t epoch;
    uint8_t tag[VSTIG_TAG_SIZE];
    if (vx_msg_of(msg_obj, &msg) < 0) return NULL;
    if (!vstig_tagged_record(&tags->tagged, &msg, &epoch, tag)) Py_RETURN_NONE;
    return PyObject_CallFunction(tags->record_type, "Oky#", msg_obj, (unsigned long)epoch, (const char *)tag,
                                 (Py_ssize_t)VSTIG_TAG_SIZE);
}

PyObject *vx_tags_get_policy(vx_tags_t *tags) {
    return Py_NewRef(PyTuple_GET_ITEM(tags->policies, (Py_ssize_t)tags->policy));
}

int vx_tags_set_policy(vx_tags_t *tags, PyObject *value) {
    Py_ssize_t i;
    for (i = 0; value != NULL && i < PyTuple_GET_SIZE(tags->policies); i++) {
        if (PyTuple_GET_ITEM(tags->policies, i) == value) {
            tags->policy = (vstig_auth_policy_t)i;
            return 0;
        }
    }
    PyErr_Format(PyExc_TypeError, "policy must be one of %R, got %R", tags->policies, value);
    return -1;
}

PyObject *vx_tags_get_records(vx_tags_t *tags) {
    return tags->records_dict == NULL ? Py_NewRef(Py_None) : Py_NewRef(tags->records_dict);
}

int vx_tags_set_records(vx_tags_t *tags, PyObject *value) {
    if (value != NULL && value != Py_None && !PyDict_Check(value)) {
        PyErr_SetString(PyExc_TypeError, "records must be a dict (Message -> Tagged) or None");
        return -1;
    }
    Py_XSETREF(tags->records_dict, value == NULL || value == Py_None ? NULL : Py_NewRef(value));
    return 0;
}

/* ---- a unit's check, for the compiled delivery (path.c) ------------------------------------------------------ */

void vx_records_add(vx_records_t *records, const vstig_msg_t *msg, const uint8_t *epoch_and_tag, size_t place) {
    vx_record_t *record;
    if (records->n == records->cap) {
        size_t cap = records->cap ? 2u * records->cap : 16u;
        vx_record_t *grown = PyMem_Realloc(records->at, cap * sizeof *grown);
        if (grown == NULL) {
            records->lost = 1;
            return;
        }
        records->at = grown;
        records->cap = cap;
    }
    record = &records->at[records->n++];
    record->msg = *msg;
    record->epoch = (uint32_t)epoch_and_tag[0] << 24 | (uint32_t)epoch_and_tag[1] << 16 |
                    (uint32_t)epoch_and_tag[2] << 8 | epoch_and_tag[3];
    memcpy(record->tag, epoch_and_tag + 4, VSTIG_TAG_SIZE);
    record->place = place;
}

/* The slots of the unit's records by message, the last of equal messages kept (a dict's rule); 0 or -1. */
static int index_records(vx_tags_t *tags) {
    size_t i, want = 16u;
    while (want < 2u * tags->nrecords) want *= 2u;
    if (want > tags->nslots) {
        uint32_t *grown = PyMem_Realloc(tags->slots, want * sizeof *grown);
        if (grown == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        tags->slots = grown;
        tags->nslots = want;
    }
    memset(tags->slots, 0, tags->nslots * sizeof *tags->slots);
    for (i = 0; i < tags->nrecords; i++) {
        size_t s = slot_of(tags, &tags->records[i].msg);
        while (tags->slots[s] && !same_msg(&tags->records[tags->slots[s] - 1u].msg, &tags->records[i].msg))
            s = (s + 1u) & (tags->nslots - 1u);
        tags->slots[s] = (uint32_t)(i + 1u);
    }
    return 0;
}

static int refuse_one(PyObject *refuse, const vstig_msg_t *msg, int reason, double t, int named,
                      unsigned long long sender, PyObject *listeners) {
    PyObject *m = vx_message(msg), *who = named ? PyLong_FromUnsignedLongLong(sender) : Py_NewRef(Py_None), *done;
    PyObject *name = vx_name(reason == VSTIG_REFUSED_UNTAGGED ? "drop_untagged" : "drop_bad_tag");
    done = m == NULL || who == NULL || name == NULL ? NULL
                                                     : PyObject_CallFunction(refuse, "OOdOO", m, name, t, who, listeners);
    Py_XDECREF(m);
    Py_XDECREF(who);
    Py_XDECREF(done);
    return done == NULL ? -1 : 0;
}

int vx_tags_check_unit(vx_tags_t *tags, vstig_auth_policy_t policy, vx_records_t *records, PyObject *refuse,
                       double t, vstig_msg_t *msgs, size_t *n, int named, unsigned long long sender,
                       PyObject *listeners) {
    size_t i, kept = 0, r = 0, passed = 0;
    tags->policy = policy; /* the engine receives under it (Signing.check sets engine.policy) */
    if (policy == VSTIG_AUTH_OFF) { /* tags ignored: kept untagged */
        records->n = 0;
        return 0;
    }
    for (i = 0; i < *n; i++) {
        const vx_record_t *record = r < records->n && records->at[r].place == i ? &records->at[r++] : NULL;
        int refused = vstig_tagged_check(&tags->tagged, policy, &msgs[i], record ? &record->epoch : NULL,
                                         record ? record->tag : NULL);
        if (refused) {
            if (refuse_one(refuse, &msgs[i], refused, t, named, sender, listeners) < 0) return -1;
            continue;
        }
        if (record != NULL) records->at[passed++] = *record; /* passed < r: never one not yet read */
        msgs[kept++] = msgs[i];
    }
    records->n = passed;
    *n = kept;
    tags->records = records->at;
    tags->nrecords = passed;
    return passed > LINEAR_RECORDS ? index_records(tags) : 0;
}

void vx_tags_unit_done(vx_tags_t *tags, vx_records_t *records) {
    tags->records = NULL;
    tags->nrecords = 0;
    records->n = 0;
}
