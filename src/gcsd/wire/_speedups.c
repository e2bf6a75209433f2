/* gcsd.wire._speedups: the compiled form of two hot loops of the packet path.
 *
 * Optional. gcsd/speedups.py holds the pure-Python code these functions replace, with the same
 * signatures and results; it picks this module when it was built (a C compiler at install time)
 * and GCSD_PURE_PYTHON is not set. The unit tests run both (tests/unit/test_speedups.py,
 * tests/unit/test_codec.py).
 *
 *   setup(frame_type, infos)     once, by gcsd.wire.codec: the Frame class (its slots are filled
 *                                directly) and {msgid: (crc_extra, target_system_ofs,
 *                                target_component_ofs)} for every message id of the dialect.
 *   feed(parser, data) -> list   FrameParser.feed: framing, CRC, targets, per-source sequence
 *                                gaps, exactly as speedups.feed (the reference).
 *   recv_batch(sock, n) -> list  up to n datagrams as [(bytes, (host, port)), ...] from one
 *                                recvmmsg(2); [] when none is waiting; an AF_INET socket only.
 *   RecentFrames(window_s, max_frames)   dedup.RecentFramesPython: seen, remember, check, len.
 *   send_batch(sock, items) -> int   sendmmsg(2) of [(bytes, (host, port)), ...] on an AF_INET
 *                                socket; how many were sent (a datagram that meets a full buffer
 *                                or an error is dropped and the rest are tried).
 *
 * Nothing here keeps state between calls but the setup tables and the receive buffers.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <stdint.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/socket.h>

#define STX_V2 0xFD
#define STX_V1 0xFE
#define IFLAG_SIGNED 0x01
#define MAX_SOURCES_TRACKED 256
#define LOSS_WINDOW 256
#define MAX_GAP 128
#define MAX_BATCH 64
#define SLOT_BYTES 65536 /* a whole UDP datagram always fits */

/* ------------------------------------------------------------------------------------------- */
/* setup                                                                                        */

typedef struct {
    uint8_t known;
    uint8_t crc_extra;
    int16_t ts_ofs;
    int16_t tc_ofs;
} MsgInfo;

/* Every message id of ardupilotmega is below 65536. Zero (unknown) until setup; only the pages of
 * the ids the dialect has are ever written, so the table costs the process ~60 kB, not 384. */
static MsgInfo msg_info[1 << 16];
static int msg_info_set = 0;

enum { F_RAW, F_MSGID, F_SYSID, F_COMPID, F_SEQ, F_VERSION, F_KNOWN, F_TS, F_TC, F_MSG, F_COUNT };
static const char *frame_slots[F_COUNT] = {"raw", "msgid", "sysid", "compid", "seq", "version",
                                           "known", "target_system", "target_component", "_msg"};
static Py_ssize_t frame_ofs[F_COUNT];
static PyTypeObject *frame_type = NULL;

static PyObject *s_stats, *s_buf, *s_keep_bad, *s_bad_frames, *s_last_seq;
static PyObject *s_bytes, *s_frames, *s_parse_errors, *s_crc_errors, *s_unknown_ids, *s_seq_gaps;
static PyObject *empty_bytes;

static PyObject *
setup(PyObject *self, PyObject *args)
{
    PyObject *type, *infos;
    if (!PyArg_ParseTuple(args, "O!O!", &PyType_Type, &type, &PyDict_Type, &infos))
        return NULL;
    PyObject *tdict = ((PyTypeObject *)type)->tp_dict;
    for (int k = 0; k < F_COUNT; k++) {
        PyObject *d = PyDict_GetItemString(tdict, frame_slots[k]);
        if (d == NULL || !Py_IS_TYPE(d, &PyMemberDescr_Type)) {
            PyErr_Format(PyExc_TypeError, "Frame has no slot %s", frame_slots[k]);
            return NULL;
        }
        PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
        if (m->type != T_OBJECT_EX) {
            PyErr_Format(PyExc_TypeError, "Frame slot %s is not an object slot", frame_slots[k]);
            return NULL;
        }
        frame_ofs[k] = m->offset;
    }
    if (msg_info_set) /* set up again (tests): start from nothing */
        memset(msg_info, 0, sizeof(msg_info));
    msg_info_set = 1;
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (PyDict_Next(infos, &pos, &key, &value)) {
        long msgid = PyLong_AsLong(key);
        int crc_extra, ts, tc;
        if (msgid == -1 && PyErr_Occurred())
            return NULL;
        if (msgid < 0 || msgid >= (1 << 16)) {
            PyErr_Format(PyExc_ValueError, "message id %ld out of range", msgid);
            return NULL;
        }
        if (!PyArg_ParseTuple(value, "iii", &crc_extra, &ts, &tc))
            return NULL;
        msg_info[msgid] = (MsgInfo){1, (uint8_t)crc_extra, (int16_t)ts, (int16_t)tc};
    }
    Py_INCREF(type);
    Py_XSETREF(frame_type, (PyTypeObject *)type);
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------------------------------------- */
/* feed                                                                                         */

static inline uint16_t
crc_accumulate(uint8_t byte, uint16_t crc) /* MAVLink's X.25 (CRC-16/MCRF4XX) step */
{
    uint8_t t = byte ^ (uint8_t)(crc & 0xFF);
    t ^= (uint8_t)(t << 4);
    return (uint16_t)((crc >> 8) ^ ((uint16_t)t << 8) ^ ((uint16_t)t << 3) ^ (t >> 4));
}

static Py_ssize_t
next_stx(const uint8_t *buf, Py_ssize_t start, Py_ssize_t n)
{
    for (Py_ssize_t j = start; j < n; j++)
        if (buf[j] == STX_V2 || buf[j] == STX_V1)
            return j;
    return n;
}

static inline void
set_slot(PyObject *obj, int k, PyObject *value) /* steals value */
{
    *(PyObject **)((char *)obj + frame_ofs[k]) = value;
}

static PyObject *
new_frame(PyObject *raw, long msgid, int sysid, int compid, int seq, int version, int known, int ts,
          int tc)
{
    PyObject *f = frame_type->tp_alloc(frame_type, 0);
    if (f == NULL)
        return NULL;
    Py_INCREF(raw);
    set_slot(f, F_RAW, raw);
    set_slot(f, F_MSGID, PyLong_FromLong(msgid));
    set_slot(f, F_SYSID, PyLong_FromLong(sysid));
    set_slot(f, F_COMPID, PyLong_FromLong(compid));
    set_slot(f, F_SEQ, PyLong_FromLong(seq));
    set_slot(f, F_VERSION, PyLong_FromLong(version));
    set_slot(f, F_KNOWN, Py_NewRef(known ? Py_True : Py_False));
    set_slot(f, F_TS, PyLong_FromLong(ts));
    set_slot(f, F_TC, PyLong_FromLong(tc));
    set_slot(f, F_MSG, Py_NewRef(Py_None));
    for (int k = 0; k < F_COUNT; k++) {
        if (*(PyObject **)((char *)f + frame_ofs[k]) == NULL) { /* an int that failed to allocate */
            Py_DECREF(f);
            return NULL;
        }
    }
    return f;
}

static int
add_to(PyObject *obj, PyObject *name, Py_ssize_t delta)
{
    if (delta == 0)
        return 0;
    PyObject *old = PyObject_GetAttr(obj, name);
    if (old == NULL)
        return -1;
    PyObject *d = PyLong_FromSsize_t(delta);
    PyObject *sum = d ? PyNumber_Add(old, d) : NULL;
    Py_DECREF(old);
    Py_XDECREF(d);
    if (sum == NULL)
        return -1;
    int rc = PyObject_SetAttr(obj, name, sum);
    Py_DECREF(sum);
    return rc;
}

/* per-source sequence tracking: [last seq, frames, frames missing] (codec.ParseStats.last_seq) */
static int
track_seq(PyObject *last_seq, int sysid, int compid, int seq, Py_ssize_t *gaps)
{
    PyObject *a = PyLong_FromLong(sysid), *b = PyLong_FromLong(compid); /* small ints: cached */
    PyObject *key = (a && b) ? PyTuple_Pack(2, a, b) : NULL;
    Py_XDECREF(a);
    Py_XDECREF(b);
    if (key == NULL)
        return -1;
    PyObject *entry = PyDict_GetItemWithError(last_seq, key); /* borrowed */
    int rc = 0;
    if (entry != NULL) {
        if (!PyList_CheckExact(entry) || PyList_GET_SIZE(entry) != 3) {
            PyErr_SetString(PyExc_TypeError, "last_seq entries are [seq, frames, missing]");
            rc = -1;
            goto done;
        }
        long last = PyLong_AsLong(PyList_GET_ITEM(entry, 0));
        long frames = PyLong_AsLong(PyList_GET_ITEM(entry, 1));
        long missing = PyLong_AsLong(PyList_GET_ITEM(entry, 2));
        if (PyErr_Occurred()) {
            rc = -1;
            goto done;
        }
        long gap = (seq - last - 1) & 0xFF;
        *gaps += gap;
        frames += 1;
        if (gap < MAX_GAP)
            missing += gap;
        if (frames >= LOSS_WINDOW) {
            frames >>= 1;
            missing >>= 1;
        }
        PyObject *a = PyLong_FromLong(seq), *b = PyLong_FromLong(frames), *c = PyLong_FromLong(missing);
        if (a == NULL || b == NULL || c == NULL) {
            Py_XDECREF(a);
            Py_XDECREF(b);
            Py_XDECREF(c);
            rc = -1;
            goto done;
        }
        PyList_SetItem(entry, 0, a);
        PyList_SetItem(entry, 1, b);
        PyList_SetItem(entry, 2, c);
    } else if (PyErr_Occurred()) {
        rc = -1;
    } else if (PyDict_GET_SIZE(last_seq) < MAX_SOURCES_TRACKED) {
        PyObject *fresh = Py_BuildValue("[iii]", seq, 1, 0);
        rc = fresh ? PyDict_SetItem(last_seq, key, fresh) : -1;
        Py_XDECREF(fresh);
    }
done:
    Py_DECREF(key);
    return rc;
}

static PyObject *
feed(PyObject *self, PyObject *args)
{
    PyObject *parser, *data;
    if (!PyArg_ParseTuple(args, "OO", &parser, &data))
        return NULL;
    if (frame_type == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "gcsd.wire._speedups.setup() was not called");
        return NULL;
    }
    PyObject *stats = NULL, *pending = NULL, *buf = NULL, *frames = NULL, *last_seq = NULL,
             *bad = NULL, *rest = NULL, *result = NULL;
    Py_buffer view = {0};
    if (PyObject_GetBuffer(data, &view, PyBUF_SIMPLE) < 0)
        return NULL;
    Py_ssize_t data_len = view.len;
    stats = PyObject_GetAttr(parser, s_stats);
    pending = stats ? PyObject_GetAttr(parser, s_buf) : NULL;
    if (pending == NULL)
        goto out;
    if (!PyBytes_Check(pending)) {
        PyErr_SetString(PyExc_TypeError, "FrameParser._buf must be bytes");
        goto out;
    }
    if (PyBytes_GET_SIZE(pending) == 0 && PyBytes_CheckExact(data)) {
        buf = Py_NewRef(data);
    } else {
        Py_ssize_t held = PyBytes_GET_SIZE(pending);
        buf = PyBytes_FromStringAndSize(NULL, held + data_len);
        if (buf == NULL)
            goto out;
        memcpy(PyBytes_AS_STRING(buf), PyBytes_AS_STRING(pending), held);
        memcpy(PyBytes_AS_STRING(buf) + held, view.buf, data_len);
    }
    int keep_bad = 0;
    {
        PyObject *k = PyObject_GetAttr(parser, s_keep_bad);
        if (k == NULL)
            goto out;
        keep_bad = PyObject_IsTrue(k);
        Py_DECREF(k);
        if (keep_bad < 0)
            goto out;
    }
    last_seq = PyObject_GetAttr(stats, s_last_seq);
    if (last_seq == NULL)
        goto out;
    if (!PyDict_Check(last_seq)) {
        PyErr_SetString(PyExc_TypeError, "ParseStats.last_seq must be a dict");
        goto out;
    }
    frames = PyList_New(0);
    if (frames == NULL)
        goto out;

    const uint8_t *b = (const uint8_t *)PyBytes_AS_STRING(buf);
    Py_ssize_t n = PyBytes_GET_SIZE(buf), i = 0;
    Py_ssize_t n_frames = 0, parse_errors = 0, crc_errors = 0, unknown_ids = 0, gaps = 0;
    while (i < n) {
        uint8_t stx = b[i];
        if (stx != STX_V2 && stx != STX_V1) {
            i = next_stx(b, i + 1, n);
            parse_errors++;
            continue;
        }
        Py_ssize_t plen, hlen, total;
        int seq, sysid, compid, version;
        long msgid;
        if (stx == STX_V2) {
            if (n - i < 10)
                break;
            plen = b[i + 1];
            uint8_t flags = b[i + 2];
            if (flags & ~IFLAG_SIGNED) {
                parse_errors++;
                i++;
                continue;
            }
            hlen = 10;
            total = plen + 12 + (flags ? 13 : 0);
            if (n - i < total)
                break;
            seq = b[i + 4];
            sysid = b[i + 5];
            compid = b[i + 6];
            msgid = (long)b[i + 7] | ((long)b[i + 8] << 8) | ((long)b[i + 9] << 16);
            version = 2;
        } else {
            if (n - i < 6)
                break;
            plen = b[i + 1];
            hlen = 6;
            total = plen + 8;
            if (n - i < total)
                break;
            seq = b[i + 2];
            sysid = b[i + 3];
            compid = b[i + 4];
            msgid = b[i + 5];
            version = 1;
        }
        const uint8_t *f = b + i;
        const MsgInfo *info = msgid < (1 << 16) && msg_info[msgid].known ? &msg_info[msgid] : NULL;
        int ts = -1, tc = -1;
        if (info != NULL) {
            Py_ssize_t crc_end = hlen + plen;
            uint16_t crc = 0xFFFF;
            for (Py_ssize_t j = 1; j < crc_end; j++)
                crc = crc_accumulate(f[j], crc);
            crc = crc_accumulate(info->crc_extra, crc);
            if (crc != (uint16_t)(f[crc_end] | (f[crc_end + 1] << 8))) {
                crc_errors++;
                if (keep_bad) {
                    if (bad == NULL && (bad = PyObject_GetAttr(parser, s_bad_frames)) == NULL)
                        goto out;
                    PyObject *raw = PyBytes_FromStringAndSize((const char *)f, total);
                    if (raw == NULL || PyList_Append(bad, raw) < 0) {
                        Py_XDECREF(raw);
                        goto out;
                    }
                    Py_DECREF(raw);
                }
                i++; /* resync: the real frame may start inside this one */
                continue;
            }
            if (info->ts_ofs >= 0)
                ts = info->ts_ofs < plen ? f[hlen + info->ts_ofs] : 0;
            if (info->tc_ofs >= 0)
                tc = info->tc_ofs < plen ? f[hlen + info->tc_ofs] : 0;
        } else {
            unknown_ids++;
        }
        PyObject *raw = (i == 0 && total == n) ? Py_NewRef(buf)
                                               : PyBytes_FromStringAndSize((const char *)f, total);
        if (raw == NULL)
            goto out;
        PyObject *frame = new_frame(raw, msgid, sysid, compid, seq, version, info != NULL, ts, tc);
        Py_DECREF(raw);
        if (frame == NULL)
            goto out;
        int appended = PyList_Append(frames, frame);
        Py_DECREF(frame);
        if (appended < 0)
            goto out;
        n_frames++;
        if (track_seq(last_seq, sysid, compid, seq, &gaps) < 0)
            goto out;
        i += total;
    }
    if (i < n)
        rest = PyBytes_FromStringAndSize((const char *)b + i, n - i);
    else
        rest = Py_NewRef(empty_bytes);
    if (rest == NULL || PyObject_SetAttr(parser, s_buf, rest) < 0)
        goto out;
    if (add_to(stats, s_bytes, data_len) < 0 || add_to(stats, s_frames, n_frames) < 0 ||
        add_to(stats, s_parse_errors, parse_errors) < 0 || add_to(stats, s_crc_errors, crc_errors) < 0 ||
        add_to(stats, s_unknown_ids, unknown_ids) < 0 || add_to(stats, s_seq_gaps, gaps) < 0)
        goto out;
    result = Py_NewRef(frames);
out:
    PyBuffer_Release(&view);
    Py_XDECREF(stats);
    Py_XDECREF(pending);
    Py_XDECREF(buf);
    Py_XDECREF(frames);
    Py_XDECREF(last_seq);
    Py_XDECREF(bad);
    Py_XDECREF(rest);
    return result;
}

/* ------------------------------------------------------------------------------------------- */
/* recv_batch / send_batch                                                                      */

static char *arena = NULL; /* MAX_BATCH slots of SLOT_BYTES; pages are touched only as used */
static struct mmsghdr rx[MAX_BATCH];
static struct iovec rx_iov[MAX_BATCH];
static struct sockaddr_in rx_addr[MAX_BATCH];

static struct {
    uint32_t ip;
    uint16_t port;
    PyObject *tuple;
} last_addr = {0, 0, NULL};

static PyObject *
address_of(const struct sockaddr_in *sa)
{
    if (last_addr.tuple != NULL && last_addr.ip == sa->sin_addr.s_addr && last_addr.port == sa->sin_port)
        return Py_NewRef(last_addr.tuple);
    char host[INET_ADDRSTRLEN];
    if (inet_ntop(AF_INET, &sa->sin_addr, host, sizeof(host)) == NULL)
        return PyErr_SetFromErrno(PyExc_OSError);
    PyObject *t = Py_BuildValue("(si)", host, (int)ntohs(sa->sin_port));
    if (t == NULL)
        return NULL;
    Py_XSETREF(last_addr.tuple, Py_NewRef(t));
    last_addr.ip = sa->sin_addr.s_addr;
    last_addr.port = sa->sin_port;
    return t;
}

static PyObject *
recv_batch(PyObject *self, PyObject *args)
{
    PyObject *sock;
    int want;
    if (!PyArg_ParseTuple(args, "Oi", &sock, &want))
        return NULL;
    int fd = PyObject_AsFileDescriptor(sock);
    if (fd < 0)
        return NULL;
    if (want < 1)
        return PyList_New(0);
    if (want > MAX_BATCH)
        want = MAX_BATCH;
    if (arena == NULL) {
        void *m = mmap(NULL, (size_t)MAX_BATCH * SLOT_BYTES, PROT_READ | PROT_WRITE,
                       MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (m == MAP_FAILED)
            return PyErr_SetFromErrno(PyExc_OSError);
        arena = m;
    }
    for (int k = 0; k < want; k++) {
        rx_iov[k].iov_base = arena + (size_t)k * SLOT_BYTES;
        rx_iov[k].iov_len = SLOT_BYTES;
        memset(&rx[k].msg_hdr, 0, sizeof(rx[k].msg_hdr));
        rx[k].msg_hdr.msg_iov = &rx_iov[k];
        rx[k].msg_hdr.msg_iovlen = 1;
        rx[k].msg_hdr.msg_name = &rx_addr[k];
        rx[k].msg_hdr.msg_namelen = sizeof(rx_addr[k]);
    }
    int got = recvmmsg(fd, rx, (unsigned)want, MSG_DONTWAIT, NULL);
    if (got < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)
            return PyList_New(0);
        return PyErr_SetFromErrno(PyExc_OSError);
    }
    PyObject *out = PyList_New(got);
    if (out == NULL)
        return NULL;
    for (int k = 0; k < got; k++) {
        PyObject *addr;
        if (rx[k].msg_hdr.msg_namelen >= sizeof(struct sockaddr_in) && rx_addr[k].sin_family == AF_INET) {
            addr = address_of(&rx_addr[k]);
        } else {
            addr = Py_NewRef(Py_None);
        }
        PyObject *payload = addr ? PyBytes_FromStringAndSize(rx_iov[k].iov_base, rx[k].msg_len) : NULL;
        PyObject *item = payload ? PyTuple_Pack(2, payload, addr) : NULL;
        Py_XDECREF(payload);
        Py_XDECREF(addr);
        if (item == NULL) {
            Py_DECREF(out);
            return NULL;
        }
        PyList_SET_ITEM(out, k, item);
    }
    return out;
}

static int
parse_inet(PyObject *addr, struct sockaddr_in *sa)
{
    const char *host;
    int port;
    if (!PyTuple_Check(addr) || !PyArg_ParseTuple(addr, "si", &host, &port)) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "an address is a (host, port) tuple");
        return -1;
    }
    if (port < 0 || port > 65535) {
        PyErr_SetString(PyExc_OverflowError, "port must be 0-65535");
        return -1;
    }
    memset(sa, 0, sizeof(*sa));
    sa->sin_family = AF_INET;
    sa->sin_port = htons((uint16_t)port);
    if (inet_pton(AF_INET, host, &sa->sin_addr) != 1) {
        PyErr_Format(PyExc_OSError, "not an IPv4 address: %s", host);
        return -1;
    }
    return 0;
}

static PyObject *
send_batch(PyObject *self, PyObject *args)
{
    PyObject *sock, *items;
    if (!PyArg_ParseTuple(args, "OO!", &sock, &PyList_Type, &items))
        return NULL;
    int fd = PyObject_AsFileDescriptor(sock);
    if (fd < 0)
        return NULL;
    Py_ssize_t total = PyList_GET_SIZE(items), done = 0, ok = 0;
    struct mmsghdr tx[MAX_BATCH];
    struct iovec iov[MAX_BATCH];
    struct sockaddr_in to[MAX_BATCH];
    while (done < total) {
        int k = 0;
        for (; k < MAX_BATCH && done + k < total; k++) {
            PyObject *item = PyList_GET_ITEM(items, done + k);
            if (!PyTuple_Check(item) || PyTuple_GET_SIZE(item) != 2 || !PyBytes_Check(PyTuple_GET_ITEM(item, 0))) {
                PyErr_SetString(PyExc_TypeError, "send_batch takes [(bytes, (host, port)), ...]");
                return NULL;
            }
            if (parse_inet(PyTuple_GET_ITEM(item, 1), &to[k]) < 0)
                return NULL;
            PyObject *payload = PyTuple_GET_ITEM(item, 0);
            iov[k].iov_base = PyBytes_AS_STRING(payload);
            iov[k].iov_len = (size_t)PyBytes_GET_SIZE(payload);
            memset(&tx[k].msg_hdr, 0, sizeof(tx[k].msg_hdr));
            tx[k].msg_hdr.msg_iov = &iov[k];
            tx[k].msg_hdr.msg_iovlen = 1;
            tx[k].msg_hdr.msg_name = &to[k];
            tx[k].msg_hdr.msg_namelen = sizeof(to[k]);
        }
        int sent = sendmmsg(fd, tx, (unsigned)k, MSG_DONTWAIT);
        if (sent > 0) {
            done += sent;
            ok += sent;
        } else if (errno != EINTR) {
            done += 1; /* a full buffer or an error on this datagram: it is dropped, the rest go on */
        }
    }
    return PyLong_FromSsize_t(ok);
}


/* ------------------------------------------------------------------------------------------- */
/* RecentFrames: dedup.RecentFramesPython in C, the same states, sweep and bounds (its docstring) */

#define SWEEP_FRACTION 0.125

typedef struct {
    double t;
    PyObject *key;
} Remembered;

typedef struct {
    PyObject_HEAD
    PyObject *at;         /* {key: time remembered} */
    Remembered *ring;     /* FIFO of (time, key), oldest at head */
    Py_ssize_t head, count, cap;
    double window_s, sweep_at;
    Py_ssize_t max_frames, evicted;
} RecentFramesObject;

static void
rf_dealloc(RecentFramesObject *self)
{
    for (Py_ssize_t k = 0; k < self->count; k++)
        Py_DECREF(self->ring[(self->head + k) % self->cap].key);
    PyMem_Free(self->ring);
    Py_XDECREF(self->at);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int
rf_init(RecentFramesObject *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"window_s", "max_frames", NULL};
    double window_s;
    Py_ssize_t max_frames = 65536;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "d|n", kwlist, &window_s, &max_frames))
        return -1;
    if (!(window_s > 0 && window_s < Py_HUGE_VAL) || max_frames < 1) { /* NaN fails too */
        PyErr_SetString(PyExc_ValueError, "window_s must be > 0 and finite, and max_frames >= 1");
        return -1;
    }
    if (self->at != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "RecentFrames is initialised once");
        return -1;
    }
    self->at = PyDict_New();
    if (self->at == NULL)
        return -1;
    self->window_s = window_s;
    self->max_frames = max_frames;
    self->sweep_at = -Py_HUGE_VAL;
    return 0;
}

static int
rf_push(RecentFramesObject *self, double t, PyObject *key)
{
    if (self->count == self->cap) {
        Py_ssize_t cap = self->cap ? self->cap * 2 : 64;
        Remembered *ring = PyMem_New(Remembered, cap);
        if (ring == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        for (Py_ssize_t k = 0; k < self->count; k++)
            ring[k] = self->ring[(self->head + k) % self->cap];
        PyMem_Free(self->ring);
        self->ring = ring;
        self->cap = cap;
        self->head = 0;
    }
    Py_INCREF(key);
    self->ring[(self->head + self->count) % self->cap] = (Remembered){t, key};
    self->count++;
    return 0;
}

static int
rf_expire(RecentFramesObject *self, double now)
{
    double horizon = now - self->window_s;
    self->sweep_at = now + self->window_s * SWEEP_FRACTION;
    while (self->count > 0) {
        Remembered *front = &self->ring[self->head];
        if (!(front->t <= horizon || PyDict_GET_SIZE(self->at) > self->max_frames))
            break;
        Remembered r = *front;
        self->head = (self->head + 1) % self->cap;
        self->count--;
        PyObject *cur = PyDict_GetItemWithError(self->at, r.key);
        int rc = 0;
        if (cur != NULL && PyFloat_AS_DOUBLE(cur) == r.t) {
            rc = PyDict_DelItem(self->at, r.key);
            if (r.t > horizon)
                self->evicted++;
        } else if (cur == NULL && PyErr_Occurred()) {
            rc = -1;
        }
        Py_DECREF(r.key);
        if (rc < 0)
            return -1;
    }
    return 0;
}

static int
rf_seen(RecentFramesObject *self, PyObject *raw, double now)
{
    PyObject *at = PyDict_GetItemWithError(self->at, raw);
    if (at == NULL)
        return PyErr_Occurred() ? -1 : 0;
    return now - PyFloat_AS_DOUBLE(at) < self->window_s;
}

static int
rf_remember(RecentFramesObject *self, PyObject *raw, double now)
{
    PyObject *t = PyFloat_FromDouble(now);
    if (t == NULL)
        return -1;
    int rc = PyDict_SetItem(self->at, raw, t);
    Py_DECREF(t);
    if (rc < 0 || rf_push(self, now, raw) < 0)
        return -1;
    if (now >= self->sweep_at || PyDict_GET_SIZE(self->at) > self->max_frames)
        return rf_expire(self, now);
    return 0;
}

static int
rf_args(RecentFramesObject *self, PyObject *const *args, Py_ssize_t nargs, double *now)
{
    if (self->at == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "RecentFrames.__init__ was not called");
        return -1;
    }
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "expected (raw, now)");
        return -1;
    }
    *now = PyFloat_AsDouble(args[1]);
    return (*now == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static PyObject *
rf_seen_m(RecentFramesObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double now;
    if (rf_args(self, args, nargs, &now) < 0)
        return NULL;
    int r = rf_seen(self, args[0], now);
    return r < 0 ? NULL : PyBool_FromLong(r);
}

static PyObject *
rf_remember_m(RecentFramesObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double now;
    if (rf_args(self, args, nargs, &now) < 0 || rf_remember(self, args[0], now) < 0)
        return NULL;
    Py_RETURN_NONE;
}

static PyObject *
rf_check_m(RecentFramesObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double now;
    if (rf_args(self, args, nargs, &now) < 0)
        return NULL;
    int r = rf_seen(self, args[0], now);
    if (r < 0)
        return NULL;
    if (r)
        Py_RETURN_TRUE;
    if (rf_remember(self, args[0], now) < 0)
        return NULL;
    Py_RETURN_FALSE;
}

static Py_ssize_t
rf_len(RecentFramesObject *self)
{
    return self->at ? PyDict_GET_SIZE(self->at) : 0;
}

static PyMethodDef rf_methods[] = {
    {"seen", (PyCFunction)(void (*)(void))rf_seen_m, METH_FASTCALL, "seen(raw, now) -> bool"},
    {"remember", (PyCFunction)(void (*)(void))rf_remember_m, METH_FASTCALL, "remember(raw, now)"},
    {"check", (PyCFunction)(void (*)(void))rf_check_m, METH_FASTCALL, "check(raw, now) -> bool (a duplicate)"},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef rf_members[] = {
    {"window_s", T_DOUBLE, offsetof(RecentFramesObject, window_s), READONLY, NULL},
    {"max_frames", T_PYSSIZET, offsetof(RecentFramesObject, max_frames), READONLY, NULL},
    {"evicted", T_PYSSIZET, offsetof(RecentFramesObject, evicted), 0, NULL},
    {NULL, 0, 0, 0, NULL},
};

static PySequenceMethods rf_as_sequence = {.sq_length = (lenfunc)rf_len};

static PyTypeObject RecentFramesType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "gcsd.wire._speedups.RecentFrames",
    .tp_basicsize = sizeof(RecentFramesObject),
    .tp_dealloc = (destructor)rf_dealloc,
    .tp_as_sequence = &rf_as_sequence,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "dedup.RecentFramesPython in C",
    .tp_methods = rf_methods,
    .tp_members = rf_members,
    .tp_init = (initproc)rf_init,
    .tp_new = PyType_GenericNew,
};

/* ------------------------------------------------------------------------------------------- */

static PyMethodDef methods[] = {
    {"setup", setup, METH_VARARGS, "setup(frame_type, infos): the Frame class and the dialect's message table"},
    {"feed", feed, METH_VARARGS, "feed(parser, data) -> frames (FrameParser.feed)"},
    {"recv_batch", recv_batch, METH_VARARGS, "recv_batch(sock, n) -> [(bytes, (host, port)), ...]"},
    {"send_batch", send_batch, METH_VARARGS, "send_batch(sock, [(bytes, (host, port)), ...]) -> sent"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "gcsd.wire._speedups", NULL, -1, methods};

PyMODINIT_FUNC
PyInit__speedups(void)
{
#define INTERN(var, text) if ((var = PyUnicode_InternFromString(text)) == NULL) return NULL
    INTERN(s_stats, "stats");
    INTERN(s_buf, "_buf");
    INTERN(s_keep_bad, "_keep_bad_crc");
    INTERN(s_bad_frames, "bad_crc_frames");
    INTERN(s_last_seq, "last_seq");
    INTERN(s_bytes, "bytes");
    INTERN(s_frames, "frames");
    INTERN(s_parse_errors, "parse_errors");
    INTERN(s_crc_errors, "crc_errors");
    INTERN(s_unknown_ids, "unknown_ids");
    INTERN(s_seq_gaps, "seq_gaps");
#undef INTERN
    empty_bytes = PyBytes_FromStringAndSize(NULL, 0);
    if (empty_bytes == NULL || PyType_Ready(&RecentFramesType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&RecentFramesType);
    if (PyModule_AddObject(m, "RecentFrames", (PyObject *)&RecentFramesType) < 0) {
        Py_DECREF(&RecentFramesType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
