"""A synthetic hover flown to the service beside CPU hogs (not collected: no ``test_`` prefix).

Shared by the estimate-age test (``test_service_load.py``) and its breakdown tool
(``age_breakdown.py``): the fake flight controller listens on UDP on 127.0.0.1, the service
(its own process and session, the shipped configuration pointed at that port) is started from
``service_cmd`` followed by ``run --config FILE``, and ``hogs`` busy loops run at ordinary
priority each in a session of its own, for ``flight_s`` seconds of flight.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import yaml

from tether_companion.mavlink.endpoints import open_link, parse_endpoint
from tether_companion.resources import CONFIGS_DIR
from tether_companion.service.config import load_service_config, load_vehicle_for
from tether_companion.service.synthetic import FakeFlightController, HoverStreams

HOVER_POSITION_NED_M = np.array([2.0, 1.0, -3.0])
"""Where the synthetic drone hovers, NED from the anchor [m]; 4 N of tension."""


async def fly_hover_beside_hogs(
    workdir: Path,
    service_cmd: Sequence[str],
    hogs: int,
    flight_s: float,
    service_preexec: Callable[[], None] | None,
) -> FakeFlightController:
    """Fly the hover for ``flight_s`` [s] with the service and ``hogs`` CPU hogs running;
    always stops them. Returns the fake flight controller with its log."""
    fc_link = await open_link(
        parse_endpoint("udpin:127.0.0.1:0", "listen"), system_id=1, component_id=1
    )
    data = yaml.safe_load((CONFIGS_DIR / "companion.yaml").read_text())
    data.setdefault("link", {})["connect"] = f"udpout:127.0.0.1:{fc_link.local_address[1]}"
    data.setdefault("recording", {})["directory"] = str(workdir / "rec")
    config_path = workdir / "companion.yaml"
    config_path.write_text(yaml.safe_dump(data))
    config = load_service_config(config_path)
    fc = FakeFlightController(
        fc_link,
        HoverStreams(
            load_vehicle_for(config), HOVER_POSITION_NED_M, 4.0, rng=np.random.default_rng(9)
        ),
    )
    service = await asyncio.create_subprocess_exec(
        *service_cmd,
        "run",
        "--config",
        str(config_path),
        start_new_session=True,
        preexec_fn=service_preexec,
    )
    hog_procs = [
        subprocess.Popen(
            [sys.executable, "-c", "while True: pass"],
            preexec_fn=lambda: os.setpriority(os.PRIO_PROCESS, 0, 0),
            start_new_session=True,
        )
        for _ in range(hogs)
    ]
    try:
        await fc.run(flight_s)
    finally:
        for hog in hog_procs:
            hog.kill()
            hog.wait()
        service.terminate()
        await asyncio.wait_for(service.wait(), 20.0)
        await fc_link.close()
    return fc
