"""``tether-companion run`` as a separate process against SITL, as a user runs it."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from tether_companion.resources import CONFIGS_DIR, VEHICLES_DIR

SITL_VEHICLE = VEHICLES_DIR / "ardupilot-sitl-plus.yaml"
"""The profile written from SITL's '+' frame model (configs/vehicles/ardupilot-sitl-plus.yaml)."""
SHIPPED_ESTIMATION_KEYS = ("thrust_dynamics", "estimator", "dynamic_filter")
"""The sections of configs/companion.yaml a SITL run takes as they ship."""
SITL_RANGEFINDER_OFFSET_FRD_M = (0.0, 0.0, 0.09)
"""Where SITL's rangefinder measures from, from the vehicle's reference point (SIM_STATE's
position, where SIM_Tether pulls) in body FRD [m]: SITL reads ``Aircraft::hagl()``, the
reference point's height above the ground less the frame's height (libraries/SITL/
SIM_Aircraft.cpp), so the beam starts at the frame's underside, as a real downward
rangefinder does. Measured on a taut winch + angle flight (sitlcal13): landed, SIM_STATE's
position rests 0.090 m above home (the anchor); in flight DISTANCE_SENSOR read 0.094 m
(+-0.005) less than SIM_STATE's height above home, tilt corrected (0.09 m and its
centimetre truncation). Left at 0 (the service's default), the height the rangefinder gave
and the one the winch's length and the elevation gave differed by 0.09 m, which the
calibration states, learning, took as the winch's offset and the elevation's zero (our
estimate 0.09 m low)."""


def companion_config(
    workdir: Path, home: tuple[float, float, float, float], overrides: dict | None = None
) -> Path:
    """Write the service YAML for a SITL run into ``workdir`` and return its path.

    Starts from configs/companion.yaml's estimator choices (its ``thrust_dynamics``,
    ``estimator`` and ``dynamic_filter`` sections: the shipped default filter) with the
    rangefinder's mounting point on SITL's frame (:data:`SITL_RANGEFINDER_OFFSET_FRD_M`);
    the origin is SITL's home (the tether's anchor); recordings go to ``workdir/rec``.
    """
    shipped = yaml.safe_load((CONFIGS_DIR / "companion.yaml").read_text(encoding="utf-8"))
    config: dict = {
        "vehicle": str(SITL_VEHICLE),
        "link": {"autopilot": "ardupilot", "fc_system_id": 1, "fc_component_id": 1},
        "origin": {"latitude_deg": home[0], "longitude_deg": home[1], "altitude_m": home[2]},
        **{key: shipped[key] for key in SHIPPED_ESTIMATION_KEYS if key in shipped},
        "recording": {"enabled": True, "directory": str(workdir / "rec")},
    }
    estimator = config.setdefault("estimator", {})
    estimator["rangefinder"] = {
        **estimator.get("rangefinder", {}),
        "offset_frd_m": list(SITL_RANGEFINDER_OFFSET_FRD_M),
    }
    for section, values in (overrides or {}).items():
        if isinstance(values, dict):
            config.setdefault(section, {}).update(values)
        else:
            config[section] = values
    path = workdir / "companion.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


class CompanionProcess:
    """``python -m tether_companion.cli run --config C --connect tcp:127.0.0.1:PORT``."""

    def __init__(self, config_path: Path, port: int, log_path: Path) -> None:
        self.command = [
            sys.executable, "-m", "tether_companion.cli", "run",
            "--config", str(config_path), "--connect", f"tcp:127.0.0.1:{port}",
        ]  # fmt: skip
        self.log_path = log_path
        self.process: subprocess.Popen[bytes] | None = None

    def __enter__(self) -> CompanionProcess:
        with open(self.log_path, "wb") as log:
            self.process = subprocess.Popen(
                self.command,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def alive(self) -> bool:
        """True while it runs."""
        return self.process is not None and self.process.poll() is None

    def output(self) -> str:
        """What it printed."""
        return self.log_path.read_text(errors="replace") if self.log_path.is_file() else ""

    def stop(self) -> int | None:
        """SIGTERM (a clean stop), SIGKILL to the group after 10 s; its exit code."""
        proc = self.process
        if proc is None:
            return None
        if proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5.0)
        return proc.returncode


def wait_until(predicate, timeout_s: float, poll_s: float = 0.1) -> bool:  # noqa: ANN001
    """Poll ``predicate()`` until true or ``timeout_s`` [s] pass; whether it came true."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return bool(predicate())
