/* IngestCore's clock gate: fc_time.FcTimeGate's check, on_system_time and reset in C, bit for
 * bit (see ingest_core.c for the object and its tests). */
#include "ingest_core.h"

static int
implausible(Core *c, double fc_s, int has_local, double local_s)
{
    if (!has_local || !c->has_latest_local)
        return 0;
    double elapsed = local_s - c->latest_local_s;
    if (!(elapsed > 0.0))
        elapsed = 0.0;
    return fc_s > c->latest_fc_s + c->max_rate * elapsed + c->future_tolerance_s;
}

void
ingest_gate_reset(Core *c)
{
    c->latest_fc_s = -INFINITY;
    c->has_latest_local = 0;
    c->has_claim = 0;
    c->n_confirm = 0;
    c->confirm_none = c->confirm_timed = 0;
    c->backsteps = 0;
    c->has_first_backstep_local = 0;
    c->n_ahead = 0;
}

/* max(local times) - min(local times) >= confirm_span_s, or True if one was None. */
static int
spans(Core *c, int none, double lo, double hi)
{
    return none || hi - lo >= c->confirm_span_s;
}

static int
jump_confirmed(Core *c, double fc_s, double local_s)
{
    if (c->n_ahead) {
        double elapsed = local_s - c->ahead_local_s;
        int agrees = c->ahead_fc_s - c->backstep_s <= fc_s
                     && fc_s <= c->ahead_fc_s + c->max_rate * elapsed + c->future_tolerance_s;
        if (!agrees)
            c->n_ahead = 0;
    }
    if (c->n_ahead == 0) {
        c->ahead_fc_s = fc_s;
        c->ahead_local_s = c->ahead_min = c->ahead_max = local_s;
    }
    else {
        /* min/max as Python's: the first of equals kept; NaN never here (local times) */
        if (local_s < c->ahead_min)
            c->ahead_min = local_s;
        if (local_s > c->ahead_max)
            c->ahead_max = local_s;
    }
    c->n_ahead++;
    return c->n_ahead >= c->confirmations && spans(c, 0, c->ahead_min, c->ahead_max);
}

static PyObject *
rebooted(Core *c, double fc_s, int has_local, double local_s)
{
    ingest_gate_reset(c);
    c->latest_fc_s = fc_s;
    c->has_latest_local = has_local;
    c->latest_local_s = local_s;
    return v_reboot;
}

static int
agrees_with_claim(Core *c, double fc_s, int has_local, double local_s)
{
    if (fc_s < c->claim_fc_s - c->backstep_s)
        return 0;
    if (!has_local || !c->claim_has_local)
        return 1;
    return fc_s <= c->claim_fc_s + (local_s - c->claim_local_s) + c->future_tolerance_s;
}

static int
fallback_due(Core *c, int has_local, double local_s)
{
    if (!has_local || !c->has_first_backstep_local)
        return c->backsteps >= c->fallback_samples;
    return local_s - c->first_backstep_local_s >= c->fallback_s;
}

static PyObject *
backstep(Core *c, double fc_s, int has_local, double local_s)
{
    if (c->backsteps == 0) {
        c->has_first_backstep_local = has_local;
        c->first_backstep_local_s = local_s;
    }
    c->backsteps++;
    if (c->has_claim && agrees_with_claim(c, fc_s, has_local, local_s)) {
        if (!has_local)
            c->confirm_none = 1;
        else if (!c->confirm_timed) {
            c->confirm_timed = 1;
            c->confirm_min = c->confirm_max = local_s;
        }
        else {
            if (local_s < c->confirm_min)
                c->confirm_min = local_s;
            if (local_s > c->confirm_max)
                c->confirm_max = local_s;
        }
        c->n_confirm++;
        if (c->n_confirm >= c->confirmations
            && spans(c, c->confirm_none, c->confirm_min, c->confirm_max))
            return rebooted(c, fc_s, has_local, local_s);
    }
    else if (fallback_due(c, has_local, local_s))
        return rebooted(c, fc_s, has_local, local_s);
    return v_backstep;
}

/* FcTimeGate.check: the verdict (a borrowed interned string). */
PyObject *
ingest_gate_check(Core *c, double fc_s, int has_local, double local_s)
{
    if (implausible(c, fc_s, has_local, local_s) && !jump_confirmed(c, fc_s, local_s))
        return v_implausible;
    c->n_ahead = 0;
    if (fc_s < c->latest_fc_s - c->backstep_s)
        return backstep(c, fc_s, has_local, local_s);
    c->has_claim = 0;
    c->backsteps = 0;
    c->has_first_backstep_local = 0;
    if (fc_s >= c->latest_fc_s) {
        c->latest_fc_s = fc_s;
        c->has_latest_local = has_local;
        c->latest_local_s = local_s;
    }
    return v_accept;
}


/* FcTimeGate.on_system_time: the verdict on SYSTEM_TIME's stamp (a borrowed interned string). */
PyObject *
ingest_gate_on_system_time(Core *c, double fc_s, int has_local, double local_s)
{
    if (!isfinite(c->latest_fc_s))
        return v_accept;
    if (implausible(c, fc_s, has_local, local_s))
        return v_implausible;
    if (fc_s < c->latest_fc_s - c->backstep_s) {
        c->has_claim = 1;
        c->claim_fc_s = fc_s;
        c->claim_has_local = has_local;
        c->claim_local_s = local_s;
        c->n_confirm = 0;
        c->confirm_none = c->confirm_timed = 0;
        return v_backstep;
    }
    c->has_claim = 0;
    return v_accept;
}
