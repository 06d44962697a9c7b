/* The input frame's checked sample (ingest_frames.FrameIngest's Reader) in C: part of the
 * _frame_core extension (frame_core.c holds the module, frame_wire.h the wire test).
 *
 * Reader(spec, conversions, kinds, limits, clock, types, empty).read(frame) does what
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
 *   empty        numpy.empty: an array is empty(n) filled through its buffer, the array
 *                numpy.array(the n floats) makes (float64, C order, writeable, owning its
 *                data) without the tuple of floats and numpy's inference from it (the
 *                module's READER_FILLS says a build does this)
 *
 * read(frame) -> None (not taken), or (kind, sample, None), or (kind, None, reason) with the
 * reason the reference counts (not_input, nonfinite, absurd, out_of_range).
 */
#include "frame_wire.h"
#include <math.h>

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
    PyObject *clock, *imu_type, *attitude_type, *pwm_type, *range_type, *empty;
} Reader;

static PyObject *s_not_input, *s_nonfinite, *s_absurd, *s_out_of_range, *s_latest_fc_s;
static PyObject *s_time_s, *s_force, *s_rate, *s_roll, *s_pitch, *s_yaw, *s_pwm_us,
    *s_distance_m;


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

/* A float64 numpy array of the `n` doubles, as np.array(tuple of floats) makes it:
 * numpy.empty(n) with the doubles' bits copied in through its buffer. */
static PyObject *
array_of(Reader *r, const double *v, int n)
{
    PyObject *size = PyLong_FromLong(n);
    if (size == NULL)
        return NULL;
    PyObject *out = PyObject_CallOneArg(r->empty, size);
    Py_DECREF(size);
    if (out == NULL)
        return NULL;
    Py_buffer view;
    if (PyObject_GetBuffer(out, &view, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) {
        Py_DECREF(out);
        return NULL;
    }
    int fits = view.len == (Py_ssize_t)(n * sizeof(double));
    if (fits)
        memcpy(view.buf, v, n * sizeof(double));
    PyBuffer_Release(&view);
    if (!fits) {
        Py_DECREF(out);
        PyErr_SetString(PyExc_TypeError, "empty(n) is not n doubles");
        return NULL;
    }
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
    /* np.array(the outputs as Python ints, dtype=float): each an integer below 2^16, exact */
    PyObject *names[2] = {s_time_s, s_pwm_us};
    PyObject *values[2] = {PyFloat_FromDouble(time_s), array_of(r, out, r->n_motors)};
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
    PyObject *spec, *conversions, *kinds, *limits, *clock, *types, *empty;
    if (!PyArg_ParseTuple(args, "SSO!O!OO!O", &spec, &conversions, &PyTuple_Type, &kinds,
                          &PyTuple_Type, &limits, &clock, &PyTuple_Type, &types, &empty))
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
    Py_XSETREF(r->spec, Py_NewRef(spec));
    Py_XSETREF(r->kinds, Py_NewRef(kinds));
    Py_XSETREF(r->clock, Py_NewRef(clock));
    Py_XSETREF(r->imu_type, Py_NewRef(PyTuple_GET_ITEM(types, 0)));
    Py_XSETREF(r->attitude_type, Py_NewRef(PyTuple_GET_ITEM(types, 1)));
    Py_XSETREF(r->pwm_type, Py_NewRef(PyTuple_GET_ITEM(types, 2)));
    Py_XSETREF(r->range_type, Py_NewRef(PyTuple_GET_ITEM(types, 3)));
    Py_XSETREF(r->empty, Py_NewRef(empty));
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
    Py_VISIT(r->empty);
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
    Py_CLEAR(r->empty);
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

int
tether_is_reader(PyObject *o)
{
    return PyObject_TypeCheck(o, &ReaderType);
}

PyObject *
tether_reader_read(PyObject *reader, PyObject *frame)
{
    return reader_call_read((Reader *)reader, frame);
}

static int
intern(PyObject **where, const char *text)
{
    *where = PyUnicode_InternFromString(text);
    return *where != NULL;
}

int
tether_frame_reader_add(PyObject *m)
{
    if (!(intern(&s_not_input, "not_input") && intern(&s_nonfinite, "nonfinite")
          && intern(&s_absurd, "absurd") && intern(&s_out_of_range, "out_of_range")
          && intern(&s_latest_fc_s, "latest_fc_s") && intern(&s_time_s, "time_s")
          && intern(&s_force, "specific_force_body_mps2")
          && intern(&s_rate, "angular_rate_body_rad_s") && intern(&s_roll, "roll_rad")
          && intern(&s_pitch, "pitch_rad") && intern(&s_yaw, "yaw_rad")
          && intern(&s_pwm_us, "pwm_us") && intern(&s_distance_m, "distance_m")))
        return 0;
    if (PyType_Ready(&ReaderType) < 0)
        return 0;
    return PyModule_AddObjectRef(m, "Reader", (PyObject *)&ReaderType) == 0
           && PyModule_AddIntConstant(m, "READER_FILLS", 1) == 0;
}
