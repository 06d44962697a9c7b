"""A fused winch length on a sagging cable: the published covariance along the range covers
the range's change over the tensions the filter cannot rule out, or the estimate is withheld
(issue 10: never published beyond 3 sigma of its own covariance)."""

from __future__ import annotations

import math

import numpy as np
from status_settings import NO_DRAG_RULE as SETTINGS

from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.mixture import MixtureValues, ProcessNoise
from tether_companion.estimation.dynamic.models import CATENARY, ModelConstants, rests_on_ground
from tether_companion.estimation.dynamic.observability import OK
from tether_companion.estimation.dynamic.published import TickSource
from tether_companion.estimation.dynamic.sag_range import (
    arc_length_m,
    mixture_sag,
    span_at_length_m,
)
from tether_companion.physics.cable_winch import winch_catenary

WEIGHT_N_PER_M = 0.0167 * 9.81
"""ArduPilot's SIM_TETH_DENSITY default's weight [N/m] (realistic-sagging-hover)."""
LENGTH_M = 7.0
HEIGHT_M = 3.0


def _chord_tension(span_m: float, horizontal_n: float) -> float:
    return horizontal_n * math.hypot(span_m, HEIGHT_M) / span_m


def _closed_form_arc_length_m(span: float, height: float, horizontal: float, weight: float):
    """The arc length of the catenary derivation's closed form (the reference sag_range.py
    wrote out itself before it called the generated model): free, ``sqrt(h^2 + (2 c
    sinh(a / 2c))^2)``; resting on the ground, ``a - c acosh(1 + h/c) + sqrt(h (h + 2c))``
    (``c = H/w``)."""
    c = horizontal / weight
    rise = c * math.acosh(1.0 + height / c)
    if span > rise:
        return span - rise + math.sqrt(height * (height + 2.0 * c))
    if span / (2.0 * c) > 350.0:
        return math.inf
    return math.hypot(height, 2.0 * c * math.sinh(span / (2.0 * c)))


def test_the_arc_length_equals_the_closed_form_on_random_cables() -> None:
    """sag_range's arc length is the generated winch-length model; on 20,000 random cables
    (free and resting on the ground, light and heavy, taut and slack) it equals the
    derivation's closed form to 1e-9 relative, and is inf where that overflows."""
    rng = np.random.default_rng(7)
    grounded = free = 0
    for _ in range(20_000):
        span = float(rng.uniform(0.05, 30.0))
        height = float(rng.uniform(0.05, 20.0))
        weight = float(rng.choice([0.0167, 0.1, 1.0])) * 9.81
        horizontal = float(np.exp(rng.uniform(math.log(0.01), math.log(50.0))))
        expected = _closed_form_arc_length_m(span, height, horizontal, weight)
        got = arc_length_m(span, height, horizontal, weight)
        if math.isinf(expected):
            assert math.isinf(got)
            continue
        assert math.isclose(got, expected, rel_tol=1e-9), (span, height, horizontal, weight)
        c = horizontal / weight
        if span > c * math.acosh(1.0 + height / c):
            grounded += 1
        else:
            free += 1
    assert grounded > 1000 and free > 1000


def test_the_arc_length_is_the_generated_models_on_both_sides_of_the_touchdown() -> None:
    constants = (1.5, 0.3, WEIGHT_N_PER_M)
    for span, horizontal in ((5.0, 0.1), (5.0, 0.7), (4.0, 3.0), (6.0, 0.3)):
        x = [span, 0.0, -HEIGHT_M] + [0.0] * (state.N_STATES - 3)
        x[state.TENSION] = _chord_tension(span, horizontal)
        (expected,), _ = CATENARY.winch_length(x, (), constants)
        assert math.isclose(arc_length_m(span, HEIGHT_M, horizontal, WEIGHT_N_PER_M), expected)
    # the inverse, and the span at a length grows with the tension
    spans = [span_at_length_m(LENGTH_M, HEIGHT_M, h, WEIGHT_N_PER_M) for h in (0.05, 0.1, 0.7)]
    assert spans == sorted(spans)
    assert math.isclose(
        arc_length_m(spans[1], HEIGHT_M, 0.1, WEIGHT_N_PER_M), LENGTH_M, abs_tol=1e-3
    )


def _source(
    span_m: float,
    chord_n: float,
    tension_sd_n: float,
    north_sd_m: float,
    winch: bool = True,
    weight_n_per_m: float = WEIGHT_N_PER_M,
) -> TickSource:
    """A tick of a filter on the sagging hover's cable at ``span_m`` north, 3 m up, with a
    chord tension ``chord_n`` +- ``tension_sd_n`` and its own north sd ``north_sd_m``, with
    the winch's length fused or not."""
    x = np.zeros(state.N_STATES)
    x[:3] = (span_m, 0.0, -HEIGHT_M)
    x[state.TENSION] = chord_n
    x[state.SCALE] = 1.0
    p = np.eye(state.N_STATES) * 1e-4
    p[0, 0] = north_sd_m**2
    p[1, 1] = 0.1**2
    p[state.TENSION, state.TENSION] = tension_sd_n**2
    mixture = MixtureValues(x, p)
    constants = ModelConstants(1.5, 0.3, weight_n_per_m, LENGTH_M if winch else math.nan)
    noise = ProcessNoise(np.eye(state.N_STATES) * 1e-6)
    return TickSource(mixture, None, noise, constants, SETTINGS, 0.0, winch, 0.0, None, 1,
                      None, None, False, False,
                      *mixture_sag(mixture, constants, winch))  # fmt: skip


def test_a_grounded_cable_read_as_free_is_withheld_or_covered() -> None:
    # the drone 5 m out: the cable's horizontal tension 0.1 N, 2 m of it on the ground; the
    # filter reads 0.7 N +- 0.3 (realistic-sagging-hover seed 9): a free catenary whose span
    # at the winch's length is ~1 m too long, with its own (linearised) north sd 0.25 m
    truth_span = span_at_length_m(LENGTH_M, HEIGHT_M, 0.1, WEIGHT_N_PER_M)
    assert abs(truth_span - 5.0) < 0.1
    truth = [truth_span, 0.0, -HEIGHT_M] + [0.0] * 10
    truth[state.TENSION] = _chord_tension(truth_span, 0.1)
    assert rests_on_ground(truth, (1.5, 0.3, WEIGHT_N_PER_M))
    span = span_at_length_m(LENGTH_M, HEIGHT_M, 0.7, WEIGHT_N_PER_M)
    error = span - truth_span
    assert error > 0.9
    estimate = _source(span, _chord_tension(span, 0.7), 0.3, 0.25).values()
    north_sd = math.sqrt(estimate.covariance[0, 0])
    assert estimate.status != OK or error <= 3.0 * north_sd
    assert estimate.status != OK  # here: beyond the 0.5 m bound, withheld, and says why
    assert "rest on the ground" in (_source(span, _chord_tension(span, 0.7), 0.3, 0.25).reason())


def test_a_taut_cable_keeps_its_covariance() -> None:
    # the same cable pulled at 8 N: the span at the length barely moves with the tension
    span = span_at_length_m(LENGTH_M, HEIGHT_M, 8.0, WEIGHT_N_PER_M)
    source = _source(span, _chord_tension(span, 8.0), 0.3, 0.05)
    assert source.sag_std_m < 0.01
    assert source.sag_m2 == 0.0  # the filter's own claims more along the range already
    estimate = source.values()
    assert estimate.status == OK
    assert math.sqrt(estimate.covariance[0, 0]) < 0.07


def test_without_a_length_a_cable_that_may_rest_on_the_ground_is_withheld() -> None:
    # a 0.1 kg/m power tether, the drone 5 m out 3 m up pulled at 0.67 N horizontally
    # (realistic-heavy-sagging-hover): 3.4 m of it on the ground. Neither the pull at the drone
    # nor the anchor's angle depends on the range then; a filter whose own covariance claims
    # 0.2 m (its start's) is withheld, and says why
    heavy = 0.1 * 9.81
    chord = _chord_tension(3.2, 0.67)
    source = _source(3.2, chord, 0.6, 0.2, winch=False, weight_n_per_m=heavy)
    assert source.sag_std_m == math.inf
    assert source.status() != OK
    assert "range is unknown" in source.reason()
    assert source.values().status == source.status()
    # the same cable pulled at 8 N leaves the anchor upward: published
    taut = _source(4.5, _chord_tension(4.5, 8.0), 0.3, 0.2, winch=False, weight_n_per_m=heavy)
    assert taut.sag_std_m == 0.0
    assert taut.status() == OK


def test_the_span_at_a_length_solves_it_on_random_cables() -> None:
    """Newton on the generated model's slope (bracketed): the span found gives the length to
    within the tolerance's worth of arc (the arc grows at most ~1-2 m per metre of span here),
    free and resting on the ground."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        height = float(rng.uniform(0.5, 10.0))
        length = height + float(rng.uniform(0.5, 20.0))
        weight = float(rng.choice([0.0167, 0.1])) * 9.81
        horizontal = float(np.exp(rng.uniform(math.log(0.02), math.log(30.0))))
        span = span_at_length_m(length, height, horizontal, weight)
        assert 0.0 < span <= math.sqrt(length**2 - height**2)
        assert math.isclose(arc_length_m(span, height, horizontal, weight), length, abs_tol=5e-4), (
            length,
            height,
            horizontal,
            weight,
        )


def test_the_arc_lengths_slope_along_the_span_is_the_finite_difference() -> None:
    from tether_companion.estimation.dynamic.sag_range import _arc_length_and_slope

    for span, horizontal in ((5.0, 0.1), (5.0, 0.7), (4.0, 3.0), (6.0, 0.3), (2.0, 20.0)):
        _, slope = _arc_length_and_slope(span, HEIGHT_M, horizontal, WEIGHT_N_PER_M)
        step = 1e-6
        difference = (
            arc_length_m(span + step, HEIGHT_M, horizontal, WEIGHT_N_PER_M)
            - arc_length_m(span - step, HEIGHT_M, horizontal, WEIGHT_N_PER_M)
        ) / (2 * step)
        assert math.isclose(slope, difference, rel_tol=1e-5), (span, horizontal)


def test_a_measured_tension_bounds_the_range_near_the_touchdown() -> None:
    """A constant-tension winch holding 5 N on a 0.1 kg/m cable, the drone 5 m out, 3 m up
    (realistic-winch-heavy-hover-5n): free, 0.36 m short of the touchdown. At 0.2 N of chord
    tension sd the cable rests on the ground 3 sigma below: read from the pull alone the range
    is taken as unsure down to a cable lying flat (0.6 m sd, withheld); with a measured tension
    fused it is the range at T - 3 sigma (1.5 cm)."""
    heavy = 0.1 * 9.80665
    cable = winch_catenary(5.0, HEIGHT_M, 5.0, heavy)
    x = np.zeros(state.N_STATES)
    x[:3] = (5.0, 0.0, -HEIGHT_M)
    x[state.TENSION] = cable.pull_n * math.hypot(5.0, HEIGHT_M) / 5.0
    x[state.SCALE] = 1.0
    p = np.eye(state.N_STATES) * 1e-4
    p[0, 0] = p[1, 1] = 0.1**2
    p[state.TENSION, state.TENSION] = 0.2**2
    mixture = MixtureValues(x, p)
    read = mixture_sag(mixture, ModelConstants(1.5, 0.3, heavy, cable.paid_out_m), True)
    measured = mixture_sag(
        mixture, ModelConstants(1.5, 0.3, heavy, cable.paid_out_m, tension_measured=True), True
    )
    assert read[0] > 0.5 > 0.02 > measured[0] > 0.0
    assert measured[1] == 0.0  # the filter's own 0.1 m along the range covers it


def test_a_span_off_the_length_is_covered_from_the_estimate() -> None:
    """The range a tension within 3 sigma allows at the fused length is measured from the
    estimate's own span: a taut 8 N cable 7 m long 3 m up spans 6.3 m at any plausible
    tension; a filter whose state sits 0.5 m inside that (its own north sd 0.05 m, e.g. the
    length's readings gated or bounding a cable it took for slack) is withheld or published
    with the truth within 3 sigma (from the span its tension gives at the length the sag
    rule claimed under 1 cm: 10 sigma)."""
    length_span = span_at_length_m(LENGTH_M, HEIGHT_M, 8.0, WEIGHT_N_PER_M)
    span = length_span - 0.5
    source = _source(span, _chord_tension(length_span, 8.0), 0.3, 0.05)
    assert source.sag_std_m > 0.5 / 3.0
    estimate = source.values()
    north_sd = math.sqrt(estimate.covariance[0, 0])
    assert estimate.status != OK or 0.5 <= 3.0 * north_sd
    # on the length's curve the taut cable keeps its own covariance (the test above)
    assert _source(length_span, _chord_tension(length_span, 8.0), 0.3, 0.05).sag_m2 == 0.0
