"""The simulator's raw output on a few scenarios, as recorded in ``data/simulator_reference.json``.

``test_sim_reference.py`` flies the same scenarios and compares. The file was written by the
simulator before its step was generated as straight-line code (main at dc72492, 2026-11-25):
``python tests/simulator_reference.py --write`` writes it again from the code in use.

Each scenario is flown for :data:`SECONDS` with every sensor read at its own rate (as
``run_scenario`` does); every :data:`EVERY`-th sample of each stream is kept, and the truth
(position, velocity, Euler angles, body rates, motor thrusts, tension, specific force) at
the end.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

from tether_companion.sim.scenario import load_scenario
from tether_companion.sim.simulator import Simulator

SCENARIOS = (
    "paper-circle",
    "realistic-circle",
    "realistic-sagging-circle",
    "catenary-hover",
    "elastic-hover",
)
"""The paper's circle; every error source with gusts; a catenary lying on the ground and a
catenary stretched by its tension (the two ways its force is solved); an elastic line."""
SECONDS = 2.0
EVERY = 25
PATH = Path(__file__).parent / "data" / "simulator_reference.json"


def fly(name: str) -> dict[str, list[list[float]]]:
    """The streams of ``name`` flown for :data:`SECONDS` (lists of rows of floats)."""
    scenario = dataclasses.replace(load_scenario(name), duration_s=SECONDS)
    sim = Simulator(scenario)
    sensors = scenario.sensors
    rates = {
        "attitude": sensors.attitude_rate_hz,
        "pwm": sensors.pwm_rate_hz,
        "imu": sensors.imu_rate_hz,
        "range": sensors.range_rate_hz,
    }
    dt = sim.physics_dt_s
    due = sorted(
        (round(k / rate / dt), kind)
        for kind, rate in rates.items()
        for k in range(1, int(SECONDS * rate + 1e-9) + 1)
    )
    streams: dict[str, list[list[float]]] = {kind: [] for kind in rates}
    for step, kind in due:
        sim.advance_to(step * dt)
        if kind == "attitude":
            a = sim.read_attitude()
            row = [a.time_s, a.roll_rad, a.pitch_rad, a.yaw_rad]
        elif kind == "pwm":
            p = sim.read_pwm()
            row = [p.time_s, *p.pwm_us.tolist()]
        elif kind == "range":
            r = sim.read_rangefinder()
            row = [] if r is None else [r.time_s, r.distance_m]
        else:
            i = sim.read_imu()
            row = [
                i.time_s,
                *i.specific_force_body_mps2.tolist(),
                *i.angular_rate_body_rad_s.tolist(),
                *sim.position_ned_m,
                sim.tension_n,
            ]
        streams[kind].append(row)
    kept = {kind: rows[EVERY - 1 :: EVERY] for kind, rows in streams.items()}
    t = sim.truth
    kept["truth"] = [
        [
            t.time_s,
            *t.position_ned_m.tolist(),
            *t.velocity_ned_m_s.tolist(),
            *t.euler_rad.tolist(),
            *t.body_rates_rad_s.tolist(),
            *t.motor_thrust_n.tolist(),
            t.tension_n,
            *t.specific_force_body_mps2.tolist(),
        ]
    ]
    return kept


def main() -> None:
    if sys.argv[1:] != ["--write"]:
        raise SystemExit("usage: python tests/simulator_reference.py --write")
    PATH.write_text(json.dumps({name: fly(name) for name in SCENARIOS}, indent=1) + "\n")


if __name__ == "__main__":
    main()
