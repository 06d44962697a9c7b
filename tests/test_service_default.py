"""The service as shipped (configs/companion.yaml: the dynamic filter) starting up on the
paper's circle in lock-step with the emulator: while the filter initialises and learns the
thrust scale it sends no position, says why in STATUSTEXT and ``--status``, and sends nothing
non-finite."""

from __future__ import annotations

import dataclasses
import io
import math

import numpy as np
import pytest
from lockstep_service import LockstepService, published_errors
from rich.console import Console

from tether_companion.emulator.autopilot import FlightController
from tether_companion.emulator.config import load_emulator_scenario
from tether_companion.estimation.dynamic.estimator import DynamicTetherEstimator
from tether_companion.service.health import LEARNING
from tether_companion.service.status import render

pytestmark = pytest.mark.integration


def _finite_fields(msg) -> bool:
    """Every number the message carries (lists included) is finite."""
    for name in msg.get_fieldnames():
        value = getattr(msg, name)
        values = value if isinstance(value, (list, tuple)) else [value]
        if any(isinstance(v, float) and not math.isfinite(v) for v in values):
            return False
    return True


def test_start_up_withholds_while_learning_the_thrust_scale_and_says_so() -> None:
    scenario, emulator_config = load_emulator_scenario("paper-circle")
    scenario = dataclasses.replace(scenario, duration_s=6.0)
    controller = FlightController(scenario, emulator_config)
    lockstep = LockstepService(controller, {}, record=True)
    session = lockstep.service.session
    assert isinstance(session.estimator, DynamicTetherEstimator)  # the shipped default
    while controller.time_s < scenario.duration_s:
        lockstep.advance()
        lockstep.serve()
    sent = lockstep.link.sent
    assert sent and all(_finite_fields(m) for m in sent)
    # the first 6 s: initialisation (1 s) and the thrust-scale bank (6 s) leave the position
    # unknown along the cable by about a metre: nothing sent
    assert not [m for m in sent if m.get_type() == "VISION_POSITION_ESTIMATE"]
    assert published_errors(lockstep)["time_s"].size == 0
    texts = [m.text for m in sent if m.get_type() == "STATUSTEXT"]
    assert any("learning thrust & wind" in text for text in texts), texts
    assert session.publisher.health == LEARNING
    view = io.StringIO()
    Console(file=view, width=200).print(render(lockstep.service))
    assert "learning the thrust scale and the wind" in view.getvalue()
    last = session.last_estimate
    assert last is not None and np.all(np.isfinite(last.position_ned_m))
