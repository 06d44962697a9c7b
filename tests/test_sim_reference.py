"""The simulator's output equals the recorded reference (tests/simulator_reference.py).

The reference was written before the simulator's step became generated straight-line code
(and its sensors, controller and ground were rewritten in scalars): the rewrite keeps every
floating-point operation and the noise stream's order, so on the machine that recorded it the
streams are bit-identical. Another platform's libm may round a sine differently in the last
bit, so the comparison allows 1e-12 relative (1e-12 absolute below 1).
"""

from __future__ import annotations

import json
import math

import pytest
from simulator_reference import PATH, SCENARIOS, fly

REFERENCE = json.loads(PATH.read_text())


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_simulator_flies_as_recorded(name):
    got, want = fly(name), REFERENCE[name]
    assert got.keys() == want.keys()
    for stream, rows in want.items():
        assert len(got[stream]) == len(rows), stream
        for row_got, row_want in zip(got[stream], rows, strict=True):
            assert len(row_got) == len(row_want), stream
            for a, b in zip(row_got, row_want, strict=True):
                assert math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12), (stream, row_want[0], a, b)


def test_the_comparison_sees_a_change_in_the_last_digits(monkeypatch):
    """The check can fail: a thrust 1e-9 N off changes the recorded streams beyond 1e-12."""
    from tether_companion.physics import rigid_body

    original = rigid_body.RigidBody.wrench

    def nudged(self, motor_thrusts_n):
        thrust, *torques = original(self, motor_thrusts_n)
        return (thrust + 1e-9, *torques)

    monkeypatch.setattr(rigid_body.RigidBody, "wrench", nudged)
    got, want = fly("paper-circle"), REFERENCE["paper-circle"]
    differ = any(
        not math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12)
        for stream in want
        for row_got, row_want in zip(got[stream], want[stream], strict=True)
        for a, b in zip(row_got, row_want, strict=True)
    )
    assert differ
