/* The IngestCore object's state and the functions its three files share (part of the
 * _frame_core extension): ingest_clock.c (the clock gate, fc_time.FcTimeGate), ingest_reorder.c
 * (the reorder buffer, reorder.ReorderBuffer) and ingest_core.c (the ingest's counts and order,
 * the Python type; its header comment says what the object is and how it is checked).
 */
#ifndef TETHER_INGEST_CORE_H
#define TETHER_INGEST_CORE_H

#include "frame_wire.h"
#include <math.h>
#include <stddef.h>

typedef struct {
    double t;
    long long seq;
    PyObject *kind, *sample;
} Held;

typedef struct {
    PyObject_HEAD
    /* the clock gate's parameters and state (fc_time.FcTimeGate) */
    double backstep_s, future_tolerance_s, max_rate, confirm_span_s, fallback_s;
    long long confirmations, fallback_samples;
    double latest_fc_s;
    int has_latest_local;
    double latest_local_s;
    int has_claim, claim_has_local;
    double claim_fc_s, claim_local_s;
    long long n_confirm;
    int confirm_none, confirm_timed; /* a None among them; a local time among them */
    double confirm_min, confirm_max;
    long long backsteps;
    int has_first_backstep_local;
    double first_backstep_local_s;
    long long n_ahead;
    double ahead_fc_s, ahead_local_s, ahead_min, ahead_max;
    /* the reorder buffer's (reorder.ReorderBuffer) */
    double max_window_s, window_s, largest_lateness_s, newest_s, period_end_s, lateness_s,
        previous_lateness_s;
    long long reordered, widened, narrowed, next_seq;
    Held *heap;
    Py_ssize_t held, capacity;
    PyObject *newest_by_kind;
    /* the ingest's (Ingest): its per-kind newest stamps, counters, itself, the frame reader */
    PyObject *latest_by_kind, *counters, *ingest, *reader;
    /* the buffer's counts as last written to the counters (mirrored: written at least once) */
    int mirrored;
    long long mirror_reordered, mirror_widened;
    double mirror_window_s;
} Core;

/* The gate's verdicts, interned by ingest_core.c's module set-up. */
extern PyObject *v_accept, *v_implausible, *v_backstep, *v_reboot;

/* FcTimeGate.check / on_system_time: the verdict (borrowed); reset: the gate's state cleared. */
PyObject *ingest_gate_check(Core *c, double fc_s, int has_local, double local_s);
PyObject *ingest_gate_on_system_time(Core *c, double fc_s, int has_local, double local_s);
void ingest_gate_reset(Core *c);

/* ReorderBuffer.push: a new list of (kind, sample) due, oldest first (NULL with an error set);
 * clear: every held item dropped (1, or 0 with an error set). */
PyObject *ingest_buffer_push(Core *c, PyObject *kind, double time_s, PyObject *sample);
int ingest_buffer_clear(Core *c);

#endif
