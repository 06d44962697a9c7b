"""The unit of work sent to a Dask worker: one scenario, one seed, every kind, scored.

Only plain data crosses the wire: the task names its kinds (looked up in the worker's own
registry) and carries the scenario; the result carries sums, per-tick NEES and short series.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from tether_companion.bench.estimators.flight import fly
from tether_companion.bench.estimators.registry import KNOWN_TENSION, FlightContext, kinds
from tether_companion.bench.estimators.scores import KindRunScore, score_kind
from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.config import load_estimator_config
from tether_companion.estimation.crlb import posterior_crlb
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.sim.scenario import Scenario


@dataclass(frozen=True)
class FlightTask:
    """One flight to score.

    Attributes
    ----------
    scenario_name
        The name the tables use.
    scenario
        The scenario with its seed set.
    kind_names
        Registered kinds to ride along.
    settle_s, converged_m
        Start of the scored window [s]; convergence threshold [m].
    simulator
        ``ours`` or ``rotorpy`` (:data:`~tether_companion.bench.estimators.SIMULATORS`).
    """

    scenario_name: str
    scenario: Scenario
    kind_names: tuple[str, ...]
    settle_s: float
    converged_m: float
    simulator: str = "ours"

    @property
    def seed(self) -> int:
        """The simulator's seed."""
        return self.scenario.seed


@dataclass(frozen=True)
class FlightScore:
    """The scores of every kind on one flight."""

    scenario_name: str
    seed: int
    kinds: dict[str, KindRunScore]


def crlb_for(record, scenario: Scenario, crlb_model: str):
    """Diagonal of the posterior CRLB along ``record``'s truth, shape (N, 3 or 4)."""
    known = crlb_model == KNOWN_TENSION
    config = dataclasses.replace(
        load_estimator_config(), kind="three_state" if known else "four_state"
    )
    return posterior_crlb(
        record.time_s,
        record.position_ned_m,
        record.tension_n,
        record.euler_rad,
        record.thrust_n,
        record.range_seen,
        mass_kg=load_vehicle(scenario.vehicle).mass_kg,
        accel_std_mps2=scenario.sensors.accel_noise_std_mps2,
        range_std_m=scenario.sensors.range_noise_std_m,
        q_density=config.q_density(),
        p0=config.p0(),
        known_tension=known,
        min_cable_length_m=config.min_cable_length_m,
    )


def score_flight(task: FlightTask) -> FlightScore:
    """Fly ``task`` and score every kind (runs on a worker)."""
    registry = kinds()
    selected = [registry[name] for name in task.kind_names]
    record = fly(task.scenario, selected, task.simulator)
    context = FlightContext(task.scenario, load_vehicle(task.scenario.vehicle), GRAVITY_MPS2)
    bounds = {
        model: crlb_for(record, task.scenario, model)
        for model in {kind.crlb_model for kind in selected}
    }
    return FlightScore(
        scenario_name=task.scenario_name,
        seed=task.seed,
        kinds={
            kind.name: score_kind(
                record,
                record.traces[kind.name],
                bounds[kind.crlb_model],
                task.settle_s,
                task.converged_m,
                kind.own_bound(context, record) if kind.own_bound is not None else None,
            )
            for kind in selected
        },
    )
