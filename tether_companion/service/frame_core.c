/* The flight controller's input frames' test and field read (ingest_frames.py) in C.
 *
 * FrameIngest takes a datagram when it is exactly one intact, unsigned MAVLink 2 frame of an
 * input stream from the flight controller, and reads the fields its sample is made of. Its
 * Python reference (FrameIngest._entry, then the message's wire-order struct, then the fields
 * picked) is a dozen small steps a frame; here it is one call:
 *
 *   take(spec, frame)    -> True / False  (the verdict only, as FrameIngest.take)
 *   fields(spec, frame)  -> None, or (code, value, ...) as the reference gives it
 *
 * `spec` is a bytes object FrameIngest builds from the dialect's own message classes (never
 * written by hand): the flight controller's system and component id, the entry count, then per
 * message: its id (uint32 little-endian), crc_extra, payload size, code, field count, and per
 * field its byte offset in the payload and its struct format character (one of QqIiHhBbfd).
 *
 * The test, as the reference: length > 10, STX 0xFD, no incompatibility flag (unsigned), a
 * message of the table, the flight controller's system and component id, the frame exactly
 * header + payload length + 2 checksum bytes, the payload length at most the message's size,
 * and the MCRF4XX checksum over frame[1:end] then crc_extra equal to the frame's last two bytes.
 * A field's bytes past the payload's (truncated) length read as zero, as pymavlink pads them.
 * Values are the objects struct makes: integers as Python ints, float32 widened to a double as
 * struct's 'f' does (a C float-to-double conversion), doubles as they are.
 * tests/test_frame_core.py compares the two on recorded and fuzzed frames.
 *
 * The wire test and the field bits are frame_wire.h's; the Reader (the frame's checked sample,
 * as Ingest makes it) is frame_reader.c's.
 */
#include "frame_wire.h"

/* Read the spec and the frame's bytes (bytes, bytearray or any buffer); 0 with an error set. */
static int
get_args(PyObject *const *args, Py_ssize_t nargs, Py_buffer *spec, Py_buffer *frame)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "expected (spec, frame)");
        return 0;
    }
    if (PyObject_GetBuffer(args[0], spec, PyBUF_SIMPLE) < 0)
        return 0;
    if (PyObject_GetBuffer(args[1], frame, PyBUF_SIMPLE) < 0) {
        PyBuffer_Release(spec);
        return 0;
    }
    return 1;
}

static PyObject *
frame_take(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer spec, frame;
    if (!get_args(args, nargs, &spec, &frame))
        return NULL;
    int bad = 0;
    const unsigned char *entry =
        taken(spec.buf, spec.len, frame.buf, frame.len, &bad);
    PyBuffer_Release(&frame);
    PyBuffer_Release(&spec);
    if (bad)
        return malformed();
    return PyBool_FromLong(entry != NULL);
}

/* One field of the payload `p` (its first `length` bytes sent, the rest zero) at `offset` of
 * struct format `type`, as struct unpacks it; NULL without an error for an unknown format. */
static PyObject *
field(const unsigned char *p, int length, int offset, int type)
{
    if (type == 0 || strchr("QqIiHhBbfd", type) == NULL)
        return NULL;
    uint64_t u = field_bits(p, length, offset, type);
    switch (type) {
    case 'Q': return PyLong_FromUnsignedLongLong(u);
    case 'q': return PyLong_FromLongLong((long long)u);
    case 'I': return PyLong_FromUnsignedLong((unsigned long)(uint32_t)u);
    case 'i': return PyLong_FromLong((long)(int32_t)(uint32_t)u);
    case 'H': return PyLong_FromLong((long)(uint16_t)u);
    case 'h': return PyLong_FromLong((long)(int16_t)(uint16_t)u);
    case 'B': return PyLong_FromLong((long)(uint8_t)u);
    case 'b': return PyLong_FromLong((long)(int8_t)(uint8_t)u);
    case 'f': {
        uint32_t w = (uint32_t)u;
        float x;
        memcpy(&x, &w, 4);
        return PyFloat_FromDouble((double)x);
    }
    default: { /* 'd' */
        double x;
        memcpy(&x, &u, 8);
        return PyFloat_FromDouble(x);
    }
    }
}

static PyObject *
frame_fields(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer spec, frame;
    if (!get_args(args, nargs, &spec, &frame))
        return NULL;
    int bad = 0;
    const unsigned char *f = frame.buf;
    const unsigned char *entry = taken(spec.buf, spec.len, f, frame.len, &bad);
    PyObject *out = NULL;
    if (bad) {
        malformed();
        goto done;
    }
    if (entry == NULL) {
        out = Py_NewRef(Py_None);
        goto done;
    }
    int count = entry[3];
    out = PyTuple_New(1 + count);
    if (out == NULL)
        goto done;
    PyObject *code = PyLong_FromLong(entry[2]);
    if (code == NULL) {
        Py_CLEAR(out);
        goto done;
    }
    PyTuple_SET_ITEM(out, 0, code);
    for (int i = 0; i < count; i++) {
        PyObject *value = field(f + HEADER_V2, f[1], entry[4 + 2 * i], entry[5 + 2 * i]);
        if (value == NULL) {
            Py_CLEAR(out);
            if (!PyErr_Occurred())
                malformed();
            goto done;
        }
        PyTuple_SET_ITEM(out, 1 + i, value);
    }
done:
    PyBuffer_Release(&frame);
    PyBuffer_Release(&spec);
    return out;
}

static PyMethodDef methods[] = {
    {"take", (PyCFunction)(void (*)(void))frame_take, METH_FASTCALL,
     "take(spec, frame) -> bool: whether frame is one intact unsigned MAVLink 2 frame of the "
     "spec's messages from its system and component."},
    {"fields", (PyCFunction)(void (*)(void))frame_fields, METH_FASTCALL,
     "fields(spec, frame) -> (code, value, ...) of a frame take() accepts, else None."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_frame_core",
    "The flight controller's input frames' test and field read in C (see frame_core.c).", -1,
    methods,
};

PyMODINIT_FUNC
PyInit__frame_core(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (!tether_frame_reader_add(m) || !tether_ingest_core_add(m)) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
