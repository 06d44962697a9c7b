"""vehicle: from_autopilot end to end over UDP: the service reads PX4's parameters from the
emulator's PX4 flavour (integers bytewise) and estimates; ``tether-companion run`` against an
emulator answering a bad parameter stops with exit code 2 and one line naming it, or, with
``autopilot_vehicle.fallback``, flies on the fallback and says why in a STATUSTEXT."""

from __future__ import annotations

import asyncio
import math
import os
import sys

import pytest
import yaml
from paper_filter import PAPER_FILTER, with_paper_filter
from test_service_emulator import _fly as fly_service

from tether_companion.mavlink.framing import FrameParser
from tether_companion.physics.vehicle import load_vehicle
from tether_companion.resources import PROJECT_ROOT
from tether_companion.service.emulator_process import EmulatorProcess
from tether_companion.service.recording import read_tlog

pytestmark = pytest.mark.integration

MASS_KG = 1.5  # the hover scenario's default-quad
BAD = ("MOT_SPIN_MIN", 0.5)
"""Outside ArduPilot's documented [0, 0.3]."""


def test_service_reads_px4_parameters_over_udp_and_estimates(tmp_path) -> None:
    emulator = EmulatorProcess(
        "hover",
        duration_s=12.0,
        score_path=tmp_path / "s.json",
        speed=2.0,
        extra_args=("--autopilot", "px4"),
    )
    overrides = {
        "link": {"autopilot": "px4"},
        "vehicle": "from_autopilot",
        "autopilot_vehicle": {"mass_kg": MASS_KG},
        "recording": {"enabled": False},
    }
    service = asyncio.run(fly_service(emulator, with_paper_filter(overrides)))
    score = emulator.score()
    truth = load_vehicle("default-quad").thrust_curve
    assert service.vehicle.name == "from-px4-4-rotors", service.state.last_error
    assert service.state.fc_autopilot == 12  # MAV_AUTOPILOT_PX4
    for pwm in (1100.0, 1500.0, 1668.0, 1900.0):
        assert float(service.vehicle.thrust_curve.thrust_n(pwm)) == pytest.approx(
            float(truth.thrust_n(pwm)), rel=1e-5
        )
    # the rotor count first, then its 6 per-rotor names for 4 rotors and the other 3
    assert service.state.sent_by_type.get("PARAM_REQUEST_READ", 0) >= 4 + 6 * 4
    assert service.session.ingest.counters.accepted["imu"] > 0  # HIGHRES_IMU, PX4's
    print(f"PX4 flavour: {score['scored']} estimates scored, 3-D RMSE {score['rmse_m']['3d']} m")
    assert score["scored"] > 100 and math.isfinite(score["rmse_m"]["3d"])
    assert score["rmse_m"]["3d"] < 0.5


def _config(tmp_path, **vehicle_settings) -> str:
    path = tmp_path / "companion.yaml"
    config = {
        "vehicle": "from_autopilot",
        "autopilot_vehicle": {"mass_kg": MASS_KG, "attempts": 1, **vehicle_settings},
        "recording": {"enabled": True, "directory": str(tmp_path / "rec")},
        "estimator": PAPER_FILTER,  # the hover withholds the default's position
    }
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return str(path)


async def _run(config: str, duration_s: float, tmp_path) -> tuple[int | None, str, dict]:
    """``tether-companion run`` against an emulator answering the bad parameter; the service's
    exit code (None: still running when the emulator finished, then stopped), its stderr and
    the emulator's score (None when the service stopped first)."""
    name, value = BAD
    emulator = EmulatorProcess(
        "hover",
        duration_s=duration_s,
        score_path=tmp_path / "s.json",
        speed=2.0,
        extra_args=("--param", f"{name}={value}"),
    )
    env = {**os.environ, "PYTHONPATH": str(PROJECT_ROOT)}
    async with emulator:
        service = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "tether_companion.cli", "run", "--config", config,
            "--connect", f"udpout:127.0.0.1:{emulator.port}",
            stdout=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE, env=env,
        )  # fmt: skip
        code: int | None = None
        try:
            waiter = asyncio.ensure_future(service.wait())
            finished = asyncio.ensure_future(emulator.wait())
            done, _ = await asyncio.wait(
                [waiter, finished], timeout=60.0, return_when=asyncio.FIRST_COMPLETED
            )
            if waiter in done:  # the service stopped: the emulator is stopped on the way out
                code = waiter.result()
            else:
                await asyncio.wait_for(finished, timeout=60.0)
        finally:
            if service.returncode is None:
                service.terminate()
            await asyncio.wait_for(service.wait(), timeout=10.0)
        assert service.stderr is not None
        err = (await service.stderr.read()).decode(errors="replace")
    return code, err, emulator.score() if code is None else {}


def test_run_stops_with_exit_2_naming_the_bad_parameter(tmp_path) -> None:
    code, err, _ = asyncio.run(_run(_config(tmp_path), 30.0, tmp_path))
    name, value = BAD
    assert code == 2, err
    errors = [line for line in err.splitlines() if "error" in line]
    assert errors == [err.strip().splitlines()[-1]], err  # one line, the last, no traceback
    assert "Traceback" not in err
    assert f"{name} = {value}: outside its documented range" in errors[0], errors


def test_run_with_a_fallback_flies_on_it_and_says_why(tmp_path) -> None:
    config = _config(tmp_path, fallback="default-quad")
    # 12 s of wall time: the service process took over 8 s to start and fetch the parameters
    # once at load 8-14 (0 estimates in a 16 s flight at speed 2)
    code, err, score = asyncio.run(_run(config, 24.0, tmp_path))
    assert code is None, err  # still running when the emulator finished
    assert "Traceback" not in err
    print(f"fallback run: {score['scored']} estimates scored, 3-D RMSE {score['rmse_m']['3d']} m")
    # the service process takes seconds to start on a loaded machine: at least 1 s of estimates
    assert score["scored"] >= 30 and score["rmse_m"]["3d"] < 1.0
    parser = FrameParser()
    (recording,) = (tmp_path / "rec").glob("*.tlog")
    texts = [
        m.text
        for _, frame in read_tlog(recording)
        for m in parser.feed(frame)
        if m.get_type() == "STATUSTEXT" and m.get_srcComponent() == 191
    ]
    name, value = BAD
    assert f"{name}={value} bad: vehicle default-quad" in texts, texts
