/* LinkTrust.admit's usual frame in C (trust.py; its Python, LinkTrust.admit_reference, stays
 * the reference and the fallback).
 *
 *   admit(trust, frame, source) -> bool   (bound as LinkTrust.admit: an instance method)
 *
 * Taken here, with signing "off": a frame whose system is not one of `command_sources` (or whose
 * source is None), and that is either not from the flight controller's (system, component), or
 * from them at the pinned address with no candidate address counting HEARTBEATs. Then, as the
 * reference: the flight controller's frame sets `_fc_heard_s` to `_monotonic_s()`, and
 * `counters.admitted` grows by one. Every other frame (signing on, a ground station's, the flight
 * controller unpinned, from another address or with a candidate, a frame too short or not bytes)
 * calls `trust.admit_reference(frame, source)` before anything is changed, so the Python decides
 * and counts (and raises) as it always did. tests/test_trust_core.py compares the two.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#define STX_V1 0xFE
#define IDS_END_V2 11 /* bytes 5-10 hold a MAVLink 2 frame's system, component and message id */
#define IDS_END_V1 6

static PyObject *s_signing, *s_off, *s_fc_ids, *s_command_sources, *s_fc_source,
    *s_candidate_heartbeats, *s_monotonic_s, *s_fc_heard_s, *s_counters, *s_admitted,
    *s_admit_reference, *s_one;

static PyObject *
reference(PyObject *trust, PyObject *frame, PyObject *source)
{
    PyObject *args[3] = {trust, frame, source};
    return PyObject_VectorcallMethod(s_admit_reference, args,
                                     3 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
}

/* 1 when `trust`'s attribute `name` is a true value, 0 when false, -1 with an error set. */
static int
attribute_true(PyObject *trust, PyObject *name)
{
    PyObject *value = PyObject_GetAttr(trust, name);
    if (value == NULL)
        return -1;
    int truth = PyObject_IsTrue(value);
    Py_DECREF(value);
    return truth;
}

/* 1 when `a == b` is true (Python's `==`, then its truth), 0 when not, -1 with an error set. */
static int
equal(PyObject *a, PyObject *b)
{
    PyObject *result = PyObject_RichCompare(a, b, Py_EQ);
    if (result == NULL)
        return -1;
    int truth = PyObject_IsTrue(result);
    Py_DECREF(result);
    return truth;
}

/* 1 when the frame is the usual one (see the top), 0 when the reference must decide, -1 with an
 * error set. Reads only: nothing is changed. *from_fc tells whether it is the flight
 * controller's. */
static int
usual(PyObject *trust, PyObject *frame, PyObject *source, int *from_fc)
{
    PyObject *signing = PyObject_GetAttr(trust, s_signing);
    if (signing == NULL)
        return -1;
    int off = PyUnicode_CheckExact(signing) && PyUnicode_Compare(signing, s_off) == 0;
    Py_DECREF(signing);
    if (!off || !PyBytes_CheckExact(frame) || PyBytes_GET_SIZE(frame) < 1)
        return 0;
    const unsigned char *f = (const unsigned char *)PyBytes_AS_STRING(frame);
    Py_ssize_t size = PyBytes_GET_SIZE(frame);
    if (size < (f[0] == STX_V1 ? IDS_END_V1 : IDS_END_V2))
        return 0; /* the reference raises (IndexError or struct.error) */
    int v1 = f[0] == STX_V1;
    long system = v1 ? f[3] : f[5], component = v1 ? f[4] : f[6];
    PyObject *sources = PyObject_GetAttr(trust, s_command_sources);
    if (sources == NULL)
        return -1;
    int commanding = 0;
    if (PyFrozenSet_CheckExact(sources)) {
        PyObject *key = PyLong_FromLong(system);
        commanding = key == NULL ? -1 : PySet_Contains(sources, key);
        Py_XDECREF(key);
    } else {
        commanding = 1; /* not the frozenset __init__ makes: the reference decides */
    }
    Py_DECREF(sources);
    if (commanding < 0)
        return -1;
    if (commanding && source != Py_None)
        return 0;
    PyObject *ids = PyObject_GetAttr(trust, s_fc_ids);
    if (ids == NULL)
        return -1;
    int exact = PyTuple_CheckExact(ids) && PyTuple_GET_SIZE(ids) == 2 &&
                PyLong_CheckExact(PyTuple_GET_ITEM(ids, 0)) &&
                PyLong_CheckExact(PyTuple_GET_ITEM(ids, 1));
    long fc_system = exact ? PyLong_AsLong(PyTuple_GET_ITEM(ids, 0)) : -1;
    long fc_component = exact ? PyLong_AsLong(PyTuple_GET_ITEM(ids, 1)) : -1;
    Py_DECREF(ids);
    if (!exact || PyErr_Occurred()) {
        PyErr_Clear();
        return 0;
    }
    *from_fc = system == fc_system && component == fc_component;
    if (!*from_fc)
        return 1;
    PyObject *fc_source = PyObject_GetAttr(trust, s_fc_source);
    if (fc_source == NULL)
        return -1;
    int pinned = fc_source == Py_None ? 0 : equal(source, fc_source);
    Py_DECREF(fc_source);
    if (pinned <= 0)
        return pinned;
    int counting = attribute_true(trust, s_candidate_heartbeats);
    return counting < 0 ? -1 : !counting;
}

static PyObject *
trust_admit(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3)
        return PyErr_Format(PyExc_TypeError, "admit takes (trust, frame, source)");
    PyObject *trust = args[0], *frame = args[1], *source = args[2];
    int from_fc = 0;
    int taken = usual(trust, frame, source, &from_fc);
    if (taken < 0)
        return NULL;
    if (!taken)
        return reference(trust, frame, source);
    if (from_fc) {
        PyObject *now = PyObject_CallMethodNoArgs(trust, s_monotonic_s);
        if (now == NULL)
            return NULL;
        int failed = PyObject_SetAttr(trust, s_fc_heard_s, now);
        Py_DECREF(now);
        if (failed)
            return NULL;
    }
    PyObject *counters = PyObject_GetAttr(trust, s_counters);
    if (counters == NULL)
        return NULL;
    PyObject *admitted = PyObject_GetAttr(counters, s_admitted);
    PyObject *more = admitted == NULL ? NULL : PyNumber_Add(admitted, s_one);
    Py_XDECREF(admitted);
    int failed = more == NULL || PyObject_SetAttr(counters, s_admitted, more);
    Py_XDECREF(more);
    Py_DECREF(counters);
    if (failed)
        return NULL;
    Py_RETURN_TRUE;
}

static PyMethodDef admit_def = {
    "admit", (PyCFunction)(void (*)(void))trust_admit, METH_FASTCALL,
    "admit(trust, frame, source) -> bool: LinkTrust.admit_reference's decision, its usual "
    "frame in C (trust_core.c)."};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_trust_core",
    "LinkTrust.admit's usual frame in C (see trust_core.c).", -1, NULL,
};

static int
intern_names(void)
{
    return (s_signing = PyUnicode_InternFromString("signing")) &&
           (s_off = PyUnicode_InternFromString("off")) &&
           (s_fc_ids = PyUnicode_InternFromString("fc_ids")) &&
           (s_command_sources = PyUnicode_InternFromString("command_sources")) &&
           (s_fc_source = PyUnicode_InternFromString("fc_source")) &&
           (s_candidate_heartbeats = PyUnicode_InternFromString("_candidate_heartbeats")) &&
           (s_monotonic_s = PyUnicode_InternFromString("_monotonic_s")) &&
           (s_fc_heard_s = PyUnicode_InternFromString("_fc_heard_s")) &&
           (s_counters = PyUnicode_InternFromString("counters")) &&
           (s_admitted = PyUnicode_InternFromString("admitted")) &&
           (s_admit_reference = PyUnicode_InternFromString("admit_reference")) &&
           (s_one = PyLong_FromLong(1));
}

PyMODINIT_FUNC
PyInit__trust_core(void)
{
    if (!intern_names())
        return NULL;
    PyObject *m = PyModule_Create(&module_def);
    if (m == NULL)
        return NULL;
    /* an instance method: LinkTrust.admit = this binds the trust as the first argument */
    PyObject *function = PyCFunction_New(&admit_def, NULL);
    PyObject *method = function == NULL ? NULL : PyInstanceMethod_New(function);
    Py_XDECREF(function);
    if (method == NULL || PyModule_AddObject(m, "admit", method) < 0) {
        Py_XDECREF(method);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
