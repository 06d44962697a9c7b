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
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>
#include <math.h>

#define HEADER_V2 10
#define STX_V2 0xFD
#define MAX_PAYLOAD 255

/* The spec's entry of `msg_id` (a pointer to its crc_extra byte) or NULL; checks the spec's
 * bounds as it walks it (a malformed spec is a ValueError: *bad = 1). */
static const unsigned char *
find_entry(const unsigned char *spec, Py_ssize_t spec_len, uint32_t msg_id, int *bad)
{
    Py_ssize_t pos = 3;
    int entries = spec[2];
    for (int e = 0; e < entries; e++) {
        if (pos + 8 > spec_len) {
            *bad = 1;
            return NULL;
        }
        const unsigned char *p = spec + pos;
        uint32_t id = (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16)
                      | ((uint32_t)p[3] << 24);
        Py_ssize_t next = pos + 8 + 2 * (Py_ssize_t)p[7];
        if (next > spec_len) {
            *bad = 1;
            return NULL;
        }
        if (id == msg_id)
            return p + 4;
        pos = next;
    }
    return NULL;
}

/* MAVLink's X.25 checksum (MCRF4XX) of `n` bytes, continuing `crc`. */
static uint16_t
crc_accumulate(const unsigned char *data, Py_ssize_t n, uint16_t crc)
{
    for (Py_ssize_t i = 0; i < n; i++) {
        uint8_t tmp = data[i] ^ (uint8_t)(crc & 0xFF);
        tmp ^= (uint8_t)(tmp << 4);
        crc = (uint16_t)((crc >> 8) ^ ((uint16_t)tmp << 8) ^ ((uint16_t)tmp << 3) ^ (tmp >> 4));
    }
    return crc;
}

/* The entry (from its crc_extra byte: crc_extra, size, code, field count, fields) when `f`
 * (`n` bytes) is a frame the table takes, else NULL; *bad = 1 for a malformed spec. */
static const unsigned char *
taken(const unsigned char *spec, Py_ssize_t spec_len, const unsigned char *f, Py_ssize_t n,
      int *bad)
{
    if (spec_len < 3) {
        *bad = 1;
        return NULL;
    }
    if (n <= HEADER_V2 || f[0] != STX_V2 || f[2] != 0)
        return NULL;
    uint32_t msg_id = (uint32_t)f[7] | ((uint32_t)f[8] << 8) | ((uint32_t)f[9] << 16);
    const unsigned char *entry = find_entry(spec, spec_len, msg_id, bad);
    if (entry == NULL || f[5] != spec[0] || f[6] != spec[1])
        return NULL;
    Py_ssize_t end = n - 2;
    if (end != HEADER_V2 + (Py_ssize_t)f[1] || f[1] > entry[1])
        return NULL;
    uint16_t crc = crc_accumulate(f + 1, end - 1, 0xFFFF);
    crc = crc_accumulate(entry, 1, crc);
    if (crc != ((uint16_t)f[end] | ((uint16_t)f[end + 1] << 8)))
        return NULL;
    return entry;
}

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
malformed(void)
{
    PyErr_SetString(PyExc_ValueError, "malformed frame spec");
    return NULL;
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
 * struct format `type`, as struct unpacks it. */
static PyObject *
field(const unsigned char *p, int length, int offset, int type)
{
    int size;
    switch (type) {
    case 'Q': case 'q': case 'd': size = 8; break;
    case 'I': case 'i': case 'f': size = 4; break;
    case 'H': case 'h': size = 2; break;
    case 'B': case 'b': size = 1; break;
    default: return NULL;
    }
    unsigned char bytes[8] = {0};
    for (int i = 0; i < size; i++)
        bytes[i] = offset + i < length ? p[offset + i] : 0;
    uint64_t u = 0;
    for (int i = size - 1; i >= 0; i--)
        u = (u << 8) | bytes[i];
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

/* ---------------------------------------------------------------- the samples, as Ingest's
 * checks make them
 *
 * Reader(spec, conversions, kinds, limits, clock, types, array).read(frame) does what
 * FrameIngest's reference does for a frame take() accepts before the ingest's clock, reorder
 * and order steps: the message's convert (units) and Ingest's check of it (imu_sample,
 * attitude_sample, pwm_sample, range_sample), the same IEEE double operations in the same
 * order (-ffp-contract=off: no fused multiply-add), and the sample object those make.
 *
 *   conversions  bytes, per code: 0 RAW_IMU, 1 HIGHRES_IMU, 2 ATTITUDE, 3 SERVO_OUTPUT_RAW,
 *                4 DISTANCE_SENSOR (the spec's fields in the order the reference's convert
 *                takes them)
 *   kinds        tuple of the input kinds' names per code
 *   limits       (milli-g to m/s^2, milli-rad to rad, max squared specific force, max rate,
 *                lowest and highest motor output, shortest and longest range [m], n_motors,
 *                downward orientation)
 *   clock        the ingest's FcTimeGate (its latest_fc_s unwraps SERVO_OUTPUT_RAW's time)
 *   types        (ImuSample, AttitudeSample, PwmSample, RangeSample): frozen slotted
 *                dataclasses without __post_init__, filled as their __init__ fills them
 *                (object.__setattr__ per field, in field order)
 *   array        numpy.array
 *
 * read(frame) -> None (not taken), or (kind, sample, None), or (kind, None, reason) with the
 * reason the reference counts (not_input, nonfinite, absurd, out_of_range).
 */
enum { RAW_IMU, HIGHRES_IMU, ATTITUDE, SERVO_OUTPUT_RAW, DISTANCE_SENSOR, CONVERSIONS };
#define MAX_CODES 8
#define MAX_MOTORS 16

typedef struct {
    PyObject_HEAD
    PyObject *spec;
    unsigned char conversion[MAX_CODES];
    PyObject *kinds;
    double milli_g, milli_rad, max_force_sq, max_rate, out_low, out_high, range_min, range_max;
    int n_motors, downward;
    PyObject *clock, *imu_type, *attitude_type, *pwm_type, *range_type, *array, *dtype_float;
} Reader;

static PyObject *s_not_input, *s_nonfinite, *s_absurd, *s_out_of_range, *s_latest_fc_s;
static PyObject *s_time_s, *s_force, *s_rate, *s_roll, *s_pitch, *s_yaw, *s_pwm_us,
    *s_distance_m;

/* The unsigned bits of the field at `offset` (struct format `type`) of the payload `p` whose
 * first `length` bytes were sent; its size in *size (0: an unknown format). */
static uint64_t
field_bits(const unsigned char *p, int length, int offset, int type)
{
    int size = (type == 'Q' || type == 'q' || type == 'd') ? 8
               : (type == 'I' || type == 'i' || type == 'f') ? 4
               : (type == 'H' || type == 'h') ? 2 : 1;
    uint64_t u = 0;
    for (int i = size - 1; i >= 0; i--)
        u = (u << 8) | (offset + i < length ? p[offset + i] : 0);
    return u;
}

/* The field's value as the double Python makes of struct's item (float(int), a float32
 * widened, a double). */
static double
field_double(const unsigned char *p, int length, const unsigned char *where)
{
    uint64_t u = field_bits(p, length, where[0], where[1]);
    switch (where[1]) {
    case 'Q': return (double)u;
    case 'q': return (double)(int64_t)u;
    case 'I': return (double)(uint32_t)u;
    case 'i': return (double)(int32_t)(uint32_t)u;
    case 'H': return (double)(uint16_t)u;
    case 'h': return (double)(int16_t)(uint16_t)u;
    case 'B': return (double)(uint8_t)u;
    case 'b': return (double)(int8_t)(uint8_t)u;
    case 'f': {
        uint32_t w = (uint32_t)u;
        float x;
        memcpy(&x, &w, 4);
        return (double)x;
    }
    default: {
        double x;
        memcpy(&x, &u, 8);
        return x;
    }
    }
}

/* An integer field's value (the formats of ids, ports, channels, stamps: never 'Q' > 2^63). */
static int64_t
field_int(const unsigned char *p, int length, const unsigned char *where)
{
    uint64_t u = field_bits(p, length, where[0], where[1]);
    switch (where[1]) {
    case 'q': return (int64_t)u;
    case 'i': return (int32_t)(uint32_t)u;
    case 'h': return (int16_t)(uint16_t)u;
    case 'b': return (int8_t)(uint8_t)u;
    default: return (int64_t)u;
    }
}

/* A new instance of the frozen slotted dataclass `type` with `count` fields set as its
 * __init__ sets them (object.__setattr__); steals the values' references. */
static PyObject *
make(PyObject *type, int count, PyObject **names, PyObject **values)
{
    PyObject *out = NULL;
    for (int i = 0; i < count; i++)
        if (values[i] == NULL)
            goto done;
    out = ((PyTypeObject *)type)->tp_alloc((PyTypeObject *)type, 0);
    if (out == NULL)
        goto done;
    for (int i = 0; i < count; i++) {
        if (PyObject_GenericSetAttr(out, names[i], values[i]) < 0) {
            Py_CLEAR(out);
            goto done;
        }
    }
done:
    for (int i = 0; i < count; i++)
        Py_XDECREF(values[i]);
    return out;
}

/* numpy.array of the `n` doubles (as np.array(tuple of floats) makes it). */
static PyObject *
array_of(Reader *r, const double *v, int n)
{
    PyObject *items = PyTuple_New(n);
    if (items == NULL)
        return NULL;
    for (int i = 0; i < n; i++) {
        PyObject *f = PyFloat_FromDouble(v[i]);
        if (f == NULL) {
            Py_DECREF(items);
            return NULL;
        }
        PyTuple_SET_ITEM(items, i, f);
    }
    PyObject *out = PyObject_CallOneArg(r->array, items);
    Py_DECREF(items);
    return out;
}

static PyObject *
result(Reader *r, int code, PyObject *sample, PyObject *reason)
{
    if (sample == NULL && reason == NULL)
        return NULL;
    PyObject *kind = PyTuple_GET_ITEM(r->kinds, code);
    PyObject *out = PyTuple_Pack(3, kind, sample ? sample : Py_None, reason ? reason : Py_None);
    Py_XDECREF(sample);
    return out;
}

static PyObject *
imu(Reader *r, int code, int conversion, const unsigned char *p, int length,
    const unsigned char *w)
{
    double t = field_double(p, length, w) * 1e-6;
    double v[6];
    for (int i = 0; i < 6; i++)
        v[i] = field_double(p, length, w + 2 * (1 + i));
    if (conversion == RAW_IMU) {
        for (int i = 0; i < 3; i++)
            v[i] = v[i] * r->milli_g;
        for (int i = 3; i < 6; i++)
            v[i] = v[i] * r->milli_rad;
    }
    if (field_int(p, length, w + 14) != 0)
        return result(r, code, NULL, s_not_input);
    if (!isfinite(v[0] + v[1] + v[2] + v[3] + v[4] + v[5]))
        return result(r, code, NULL, s_nonfinite);
    if (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > r->max_force_sq || fabs(v[3]) > r->max_rate
        || fabs(v[4]) > r->max_rate || fabs(v[5]) > r->max_rate)
        return result(r, code, NULL, s_absurd);
    PyObject *names[3] = {s_time_s, s_force, s_rate};
    PyObject *values[3] = {PyFloat_FromDouble(t), array_of(r, v, 3), array_of(r, v + 3, 3)};
    return result(r, code, make(r->imu_type, 3, names, values), NULL);
}

static PyObject *
attitude(Reader *r, int code, const unsigned char *p, int length, const unsigned char *w)
{
    double t = field_double(p, length, w) * 1e-3;
    double roll = field_double(p, length, w + 2), pitch = field_double(p, length, w + 4),
           yaw = field_double(p, length, w + 6);
    if (!(isfinite(roll) && isfinite(pitch) && isfinite(yaw)))
        return result(r, code, NULL, s_nonfinite);
    if (fabs(roll) > M_PI + 1e-3 || fabs(pitch) > 0.5 * M_PI + 1e-3 || fabs(yaw) > 2.0 * M_PI)
        return result(r, code, NULL, s_absurd);
    PyObject *names[4] = {s_time_s, s_roll, s_pitch, s_yaw};
    PyObject *values[4] = {PyFloat_FromDouble(t), PyFloat_FromDouble(roll),
                           PyFloat_FromDouble(pitch), PyFloat_FromDouble(yaw)};
    return result(r, code, make(r->attitude_type, 4, names, values), NULL);
}

/* Ingest._unwrap_uint32_us: uint32 microseconds to seconds near the latest stamp. The sum
 * time_usec + wraps 2^32 is exact in Python's integers and then rounded once to a double; here
 * both terms are exact doubles and one addition rounds their exact sum the same way. */
static int
unwrap(Reader *r, int64_t time_usec, double *out)
{
    PyObject *latest = PyObject_GetAttr(r->clock, s_latest_fc_s);
    if (latest == NULL)
        return 0;
    double latest_s = PyFloat_AsDouble(latest);
    Py_DECREF(latest);
    if (latest_s == -1.0 && PyErr_Occurred())
        return 0;
    if (!isfinite(latest_s)) {
        *out = (double)time_usec * 1e-6;
        return 1;
    }
    double wraps = nearbyint((latest_s * 1e6 - (double)time_usec) / 4294967296.0);
    if (!(wraps > 0.0))
        wraps = 0.0;
    *out = ((double)time_usec + wraps * 4294967296.0) * 1e-6;
    return 1;
}

static PyObject *
pwm(Reader *r, int code, const unsigned char *p, int length, const unsigned char *w)
{
    if (field_int(p, length, w) != 0)
        return result(r, code, NULL, s_not_input);
    double out[MAX_MOTORS];
    double low = INFINITY, high = -INFINITY;
    for (int i = 0; i < r->n_motors; i++) {
        out[i] = (double)field_int(p, length, w + 2 * (2 + i));
        low = out[i] < low ? out[i] : low;
        high = out[i] > high ? out[i] : high;
    }
    if (low < r->out_low || high > r->out_high)
        return result(r, code, NULL, s_absurd);
    double time_s;
    if (!unwrap(r, field_int(p, length, w + 2), &time_s))
        return NULL;
    PyObject *items = PyTuple_New(r->n_motors);
    if (items == NULL)
        return NULL;
    for (int i = 0; i < r->n_motors; i++) {
        PyObject *o = PyLong_FromLongLong((long long)out[i]);
        if (o == NULL) {
            Py_DECREF(items);
            return NULL;
        }
        PyTuple_SET_ITEM(items, i, o);
    }
    PyObject *args = PyTuple_Pack(1, items);
    Py_DECREF(items);
    if (args == NULL)
        return NULL;
    PyObject *array = PyObject_Call(r->array, args, r->dtype_float);
    Py_DECREF(args);
    PyObject *names[2] = {s_time_s, s_pwm_us};
    PyObject *values[2] = {PyFloat_FromDouble(time_s), array};
    return result(r, code, make(r->pwm_type, 2, names, values), NULL);
}

static PyObject *
range(Reader *r, int code, const unsigned char *p, int length, const unsigned char *w)
{
    if (field_int(p, length, w) != r->downward)
        return result(r, code, NULL, s_not_input);
    int64_t current = field_int(p, length, w + 4), low = field_int(p, length, w + 6),
            high = field_int(p, length, w + 8);
    double distance_m = (double)current * 0.01;
    if (!(low <= current && current <= high)
        || !(r->range_min <= distance_m && distance_m <= r->range_max))
        return result(r, code, NULL, s_out_of_range);
    PyObject *names[2] = {s_time_s, s_distance_m};
    PyObject *values[2] = {PyFloat_FromDouble(field_double(p, length, w + 2) * 1e-3),
                           PyFloat_FromDouble(distance_m)};
    return result(r, code, make(r->range_type, 2, names, values), NULL);
}

static PyObject *
reader_read(Reader *r, PyObject *arg)
{
    Py_buffer frame;
    if (PyObject_GetBuffer(arg, &frame, PyBUF_SIMPLE) < 0)
        return NULL;
    const unsigned char *f = frame.buf;
    int bad = 0;
    const unsigned char *entry = taken((const unsigned char *)PyBytes_AS_STRING(r->spec),
                                       PyBytes_GET_SIZE(r->spec), f, frame.len, &bad);
    PyObject *out;
    if (bad)
        out = malformed();
    else if (entry == NULL)
        out = Py_NewRef(Py_None);
    else {
        int code = entry[2];
        const unsigned char *p = f + HEADER_V2, *w = entry + 4;
        int length = f[1];
        switch (r->conversion[code]) {
        case RAW_IMU: case HIGHRES_IMU:
            out = imu(r, code, r->conversion[code], p, length, w);
            break;
        case ATTITUDE: out = attitude(r, code, p, length, w); break;
        case SERVO_OUTPUT_RAW: out = pwm(r, code, p, length, w); break;
        default: out = range(r, code, p, length, w); break;
        }
    }
    PyBuffer_Release(&frame);
    return out;
}

/* The fields each conversion reads (as the reference's converts take them). */
static const int conversion_fields[CONVERSIONS] = {8, 8, 4, -1, 5};

static int
reader_init(Reader *r, PyObject *args, PyObject *kwds)
{
    PyObject *spec, *conversions, *kinds, *limits, *clock, *types, *array;
    if (!PyArg_ParseTuple(args, "SSO!O!OO!O", &spec, &conversions, &PyTuple_Type, &kinds,
                          &PyTuple_Type, &limits, &clock, &PyTuple_Type, &types, &array))
        return -1;
    Py_ssize_t codes = PyBytes_GET_SIZE(conversions);
    if (codes > MAX_CODES || PyTuple_GET_SIZE(kinds) != codes || PyTuple_GET_SIZE(types) != 4
        || !PyArg_ParseTuple(limits, "ddddddddii", &r->milli_g, &r->milli_rad,
                             &r->max_force_sq, &r->max_rate, &r->out_low, &r->out_high,
                             &r->range_min, &r->range_max, &r->n_motors, &r->downward)
        || r->n_motors < 1 || r->n_motors > MAX_MOTORS) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "bad Reader arguments");
        return -1;
    }
    /* every code's entry in the spec must hold the fields its conversion reads */
    const unsigned char *s = (const unsigned char *)PyBytes_AS_STRING(spec);
    Py_ssize_t n = PyBytes_GET_SIZE(spec), pos = 3;
    if (n < 3 || s[2] != codes) {
        PyErr_SetString(PyExc_ValueError, "malformed frame spec");
        return -1;
    }
    for (Py_ssize_t e = 0; e < codes; e++) {
        if (pos + 8 > n || pos + 8 + 2 * s[pos + 7] > n || s[pos + 6] != e) {
            PyErr_SetString(PyExc_ValueError, "malformed frame spec");
            return -1;
        }
        int conversion = ((unsigned char *)PyBytes_AS_STRING(conversions))[e];
        int wanted = conversion < CONVERSIONS ? conversion_fields[conversion] : 0;
        if (conversion == SERVO_OUTPUT_RAW)
            wanted = 2 + r->n_motors;
        if (conversion >= CONVERSIONS || s[pos + 7] != wanted) {
            PyErr_SetString(PyExc_ValueError, "a conversion does not match its fields");
            return -1;
        }
        for (int i = 0; i < wanted; i++)
            if (strchr("QqIiHhBbfd", s[pos + 9 + 2 * i]) == NULL || s[pos + 9 + 2 * i] == 0) {
                PyErr_SetString(PyExc_ValueError, "malformed frame spec");
                return -1;
            }
        r->conversion[e] = (unsigned char)conversion;
        pos += 8 + 2 * s[pos + 7];
    }
    PyObject *dtype = PyDict_New();
    if (dtype == NULL || PyDict_SetItemString(dtype, "dtype", (PyObject *)&PyFloat_Type) < 0) {
        Py_XDECREF(dtype);
        return -1;
    }
    Py_XSETREF(r->dtype_float, dtype);
    Py_XSETREF(r->spec, Py_NewRef(spec));
    Py_XSETREF(r->kinds, Py_NewRef(kinds));
    Py_XSETREF(r->clock, Py_NewRef(clock));
    Py_XSETREF(r->imu_type, Py_NewRef(PyTuple_GET_ITEM(types, 0)));
    Py_XSETREF(r->attitude_type, Py_NewRef(PyTuple_GET_ITEM(types, 1)));
    Py_XSETREF(r->pwm_type, Py_NewRef(PyTuple_GET_ITEM(types, 2)));
    Py_XSETREF(r->range_type, Py_NewRef(PyTuple_GET_ITEM(types, 3)));
    Py_XSETREF(r->array, Py_NewRef(array));
    for (int i = 0; i < 4; i++)
        if (!PyType_Check(PyTuple_GET_ITEM(types, i))) {
            PyErr_SetString(PyExc_TypeError, "types must be classes");
            return -1;
        }
    return 0;
}

static int
reader_traverse(Reader *r, visitproc visit, void *arg)
{
    Py_VISIT(r->spec);
    Py_VISIT(r->kinds);
    Py_VISIT(r->clock);
    Py_VISIT(r->imu_type);
    Py_VISIT(r->attitude_type);
    Py_VISIT(r->pwm_type);
    Py_VISIT(r->range_type);
    Py_VISIT(r->array);
    Py_VISIT(r->dtype_float);
    return 0;
}

static int
reader_clear(Reader *r)
{
    Py_CLEAR(r->spec);
    Py_CLEAR(r->kinds);
    Py_CLEAR(r->clock);
    Py_CLEAR(r->imu_type);
    Py_CLEAR(r->attitude_type);
    Py_CLEAR(r->pwm_type);
    Py_CLEAR(r->range_type);
    Py_CLEAR(r->array);
    Py_CLEAR(r->dtype_float);
    return 0;
}

static void
reader_dealloc(Reader *r)
{
    PyObject_GC_UnTrack(r);
    reader_clear(r);
    Py_TYPE(r)->tp_free((PyObject *)r);
}

static PyObject *
reader_call_read(Reader *r, PyObject *arg)
{
    if (r->spec == NULL) {
        PyErr_SetString(PyExc_ValueError, "Reader not initialised");
        return NULL;
    }
    return reader_read(r, arg);
}

static PyMethodDef reader_methods[] = {
    {"read", (PyCFunction)reader_call_read, METH_O,
     "read(frame) -> None | (kind, sample, None) | (kind, None, reason)"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject ReaderType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "tether_companion.service._frame_core.Reader",
    .tp_basicsize = sizeof(Reader),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "The input frames' samples as Ingest's checks make them (see frame_core.c).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)reader_init,
    .tp_traverse = (traverseproc)reader_traverse,
    .tp_clear = (inquiry)reader_clear,
    .tp_dealloc = (destructor)reader_dealloc,
    .tp_methods = reader_methods,
};

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

static int
intern(PyObject **where, const char *text)
{
    *where = PyUnicode_InternFromString(text);
    return *where != NULL;
}

PyMODINIT_FUNC
PyInit__frame_core(void)
{
    if (!(intern(&s_not_input, "not_input") && intern(&s_nonfinite, "nonfinite")
          && intern(&s_absurd, "absurd") && intern(&s_out_of_range, "out_of_range")
          && intern(&s_latest_fc_s, "latest_fc_s") && intern(&s_time_s, "time_s")
          && intern(&s_force, "specific_force_body_mps2")
          && intern(&s_rate, "angular_rate_body_rad_s") && intern(&s_roll, "roll_rad")
          && intern(&s_pitch, "pitch_rad") && intern(&s_yaw, "yaw_rad")
          && intern(&s_pwm_us, "pwm_us") && intern(&s_distance_m, "distance_m")))
        return NULL;
    if (PyType_Ready(&ReaderType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    if (PyModule_AddObjectRef(m, "Reader", (PyObject *)&ReaderType) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
