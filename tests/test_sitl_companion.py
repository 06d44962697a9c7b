"""The service configuration a SITL flight runs the companion with (ardupilot_sitl/
companion.py): the shipped estimator, and the rangefinder where SITL's is. No SITL needed."""

from __future__ import annotations

import numpy as np
import pytest

from tether_companion.ardupilot_sitl.companion import (
    SITL_RANGEFINDER_OFFSET_FRD_M,
    companion_config,
)
from tether_companion.estimation.altimeter_geometry import height_above_anchor_m
from tether_companion.service.config import load_service_config

HOME = (-35.363261, 149.16523, 584.0, 0.0)


def test_the_rangefinder_measures_from_sitls_frame_underside(tmp_path) -> None:
    """SITL's rangefinder reads the reference point's height less the frame's 0.09 m
    (``Aircraft::hagl``): with the written config the service turns such a reading back
    into the height of the point the tether pulls, level, and tilted for a beam from the
    underside (SITL takes the frame's height off vertically: 0.09 (1 - cos) apart, 2 mm at
    0.2 rad); a flight's estimator override keeps the mounting point."""
    path = companion_config(
        tmp_path, HOME, {"estimator": {"kind": "four_state"}, "dynamic_filter": {}}
    )
    config = load_service_config(path)
    assert config.estimator.kind == "four_state"
    offset = config.estimator.rangefinder.offset_frd_m
    assert offset == pytest.approx(SITL_RANGEFINDER_OFFSET_FRD_M) == (0.0, 0.0, 0.09)
    height_m = 4.1  # SIM_STATE's height above home (the anchor)
    level = np.eye(3)
    assert height_above_anchor_m(height_m - 0.09, level, offset, 0.0) == pytest.approx(height_m)
    roll = 0.2
    c, s = np.cos(roll), np.sin(roll)
    ned_to_body = np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])
    reading_m = (height_m - 0.09 * c) / c
    assert height_above_anchor_m(reading_m, ned_to_body, offset, 0.0) == pytest.approx(height_m)
