"""Which identified model is written: admitted only when stable and at the static fit's
steady-state thrust at the operating point; chosen by the steady and transient error of the
thrust simulated from PWM alone (not k-step-ahead Fit%)."""

from __future__ import annotations

import numpy as np
import pytest
from sysid_synthetic import motor_flight, split

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sysid.identify import DYNAMIC_STRUCTURES, StructureResult, identify
from tether_companion.sysid.selection import DC_TOLERANCE_PCT, select, steady_state_thrust_n

PWM_RANGE = (1000.0, 2000.0)


class Scaled:
    """A model that follows the measured thrust's shape but with a wrong steady-state gain:
    the true thrust (known here) times ``gain``, delayed by nothing; transients look perfect."""

    orders = "fake"

    def __init__(self, reference, gain: float) -> None:
        self.reference, self.gain = reference, gain

    def simulate(self, data):
        return self.gain * self.reference.simulate(data)


class Diverging:
    """Exact at a constant input, blowing up after any change (an unstable pole)."""

    orders = "fake"

    def __init__(self, reference) -> None:
        self.reference = reference

    def simulate(self, data):
        out = self.reference.simulate(data)
        change = np.abs(np.diff(data.pwm_us.mean(axis=1), prepend=data.pwm_us[0, 0]))
        with np.errstate(over="ignore"):
            return out + 1e-3 * np.exp(np.cumsum(np.cumsum(change)) * 0.01)


@pytest.fixture(scope="module")
def flight():
    vehicle = load_vehicle("default-quad")
    data = motor_flight(vehicle, np.random.default_rng(5), duration_s=40.0, noise_mps2=0.1)
    estimation, validation = split(data)
    structures = ("static", "process", "arx")  # the quick ones: subspace and PEM take minutes
    return (
        vehicle,
        estimation,
        validation,
        identify([estimation], [validation], PWM_RANGE, structures),
    )


def test_chosen_model_is_dynamic_and_right_at_steady_state(flight) -> None:
    vehicle, _, validation, results = flight
    chosen, scores = select(results, [validation], PWM_RANGE)
    assert chosen.structure in DYNAMIC_STRUCTURES
    weight = vehicle.mass_kg * GRAVITY_MPS2
    hover = float(vehicle.thrust_curve.pwm_for_thrust(weight / 4))
    thrust, settled = steady_state_thrust_n(chosen.model, validation, hover, PWM_RANGE)
    assert settled and thrust == pytest.approx(weight, rel=0.005)
    static = scores["static"]
    assert scores[chosen.structure].score_n < static.score_n
    assert static.dc_error_pct == 0.0 and static.admitted()


def test_a_model_off_at_steady_state_is_not_written_however_it_fits(flight) -> None:
    _, _, validation, results = flight
    by_name = {r.structure: r for r in results}
    best_real = by_name["process"]
    off = StructureResult("arx", Scaled(best_real.model, 1.08), best_real.metrics)
    near = StructureResult(
        "oe", Scaled(best_real.model, 1.0 + 0.5 * DC_TOLERANCE_PCT / 100), best_real.metrics
    )
    candidates = [by_name["static"], off, near]
    chosen, scores = select(candidates, [validation], PWM_RANGE)
    assert scores["arx"].dc_error_pct == pytest.approx(8.0, abs=0.5)
    assert not scores["arx"].admitted() and scores["oe"].admitted()
    assert chosen.structure == "oe"


def test_an_unstable_model_is_not_written(flight) -> None:
    _, _, validation, results = flight
    by_name = {r.structure: r for r in results}
    unstable = StructureResult("ss", Diverging(by_name["process"].model), by_name["arx"].metrics)
    chosen, scores = select([by_name["static"], unstable], [validation], PWM_RANGE)
    assert not scores["ss"].stable and not scores["ss"].admitted()
    assert chosen.structure == "static"


def test_without_a_static_fit_nothing_is_chosen(flight) -> None:
    _, _, validation, results = flight
    dynamic = [r for r in results if r.structure != "static"]
    assert select(dynamic, [validation], PWM_RANGE) == (None, {})
