"""Multicopter motor layouts as the autopilots number their outputs.

Each layout lists the rotors in output-channel order (motor ``i`` is SERVO_OUTPUT_RAW
``servo{i}_raw``), with the arm direction from the nose (positive toward the right wing), the
propeller's rotation seen from above and the arm length relative to the longest arm.

Source: ArduPilot ``libraries/AP_Motors/AP_MotorsMatrix.cpp``, ``setup_motors()`` (read at
commit 0001fe62): ``add_motor(motor, angle_deg, yaw_factor, order)`` puts a rotor on the arm
at ``angle_deg``; ``add_motor_raw(motor, roll, pitch, yaw, order)`` gives its roll and pitch
factors, which are ``-y`` and ``x`` of its position; a yaw factor > 0 is a counter-clockwise
propeller (``AP_MOTORS_MATRIX_YAW_FACTOR_CCW = 1`` in ``AP_MotorsMatrix.h``). PX4's default
airframes for quad X and hexa X use the same numbering; other PX4 geometries are read from
their ``CA_ROTORn_PX/PY/KM`` parameters (:mod:`tether_companion.vehicle_params`).

``FRAME_CLASS`` / ``FRAME_TYPE`` values are ArduPilot's ``motor_frame_class`` /
``motor_frame_type`` enums (``AP_Motors_Class.h``).
"""

from __future__ import annotations

import math

from tether_companion.physics.motor_layout import Motor


def _ring(*entries: tuple[float, str]) -> tuple[Motor, ...]:
    """Rotors on equal arms: ``(angle_deg, spin)`` per output channel."""
    return tuple(Motor(angle, spin) for angle, spin in entries)


def _raw(*entries: tuple[float, float, str]) -> tuple[Motor, ...]:
    """Rotors from ArduPilot's raw ``(roll, pitch)`` factors: position ``x = pitch, y = -roll``."""
    radii = [math.hypot(roll, pitch) for roll, pitch, _ in entries]
    longest = max(radii)
    return tuple(
        Motor(math.degrees(math.atan2(-roll, pitch)), spin, radius / longest)
        for (roll, pitch, spin), radius in zip(entries, radii, strict=True)
    )


FRAMES: dict[str, tuple[Motor, ...]] = {
    "quad-x": _ring((45, "ccw"), (-135, "ccw"), (-45, "cw"), (135, "cw")),
    "quad-plus": _ring((90, "ccw"), (-90, "ccw"), (0, "cw"), (180, "cw")),
    "quad-v": _ring((45, "ccw"), (-135, "ccw"), (-45, "cw"), (135, "cw")),
    "quad-h": _ring((45, "cw"), (-135, "cw"), (-45, "ccw"), (135, "ccw")),
    "hexa-plus": _ring(
        (0, "cw"), (180, "ccw"), (-120, "cw"), (60, "ccw"), (-60, "ccw"), (120, "cw")
    ),
    "hexa-x": _ring((90, "cw"), (-90, "ccw"), (-30, "cw"), (150, "ccw"), (30, "ccw"), (-150, "cw")),
    "octa-plus": _ring(
        (0, "cw"),
        (180, "cw"),
        (45, "ccw"),
        (135, "ccw"),
        (-45, "ccw"),
        (-135, "ccw"),
        (-90, "cw"),
        (90, "cw"),
    ),
    "octa-x": _ring(
        (22.5, "cw"),
        (-157.5, "cw"),
        (67.5, "ccw"),
        (157.5, "ccw"),
        (-22.5, "ccw"),
        (-112.5, "ccw"),
        (-67.5, "cw"),
        (112.5, "cw"),
    ),
    "octaquad-plus": _ring(
        (0, "ccw"),
        (-90, "cw"),
        (180, "ccw"),
        (90, "cw"),
        (-90, "ccw"),
        (0, "cw"),
        (90, "ccw"),
        (180, "cw"),
    ),
    "octaquad-x": _ring(
        (45, "ccw"),
        (-45, "cw"),
        (-135, "ccw"),
        (135, "cw"),
        (-45, "ccw"),
        (45, "cw"),
        (135, "ccw"),
        (-135, "cw"),
    ),
    "y6": _raw(
        (-1.0, 0.666, "ccw"),
        (1.0, 0.666, "cw"),
        (1.0, 0.666, "ccw"),
        (0.0, -1.333, "cw"),
        (-1.0, 0.666, "cw"),
        (0.0, -1.333, "ccw"),
    ),
}
"""Layouts by name; ``octaquad-*`` are the coaxial octocopters (four arms, two rotors each)."""

FRAME_NAMES: tuple[str, ...] = tuple(FRAMES)

ARDUPILOT_FRAMES: dict[tuple[int, int], str] = {
    (1, 0): "quad-plus",
    (1, 1): "quad-x",
    (1, 2): "quad-v",
    (1, 3): "quad-h",
    (2, 0): "hexa-plus",
    (2, 1): "hexa-x",
    (3, 0): "octa-plus",
    (3, 1): "octa-x",
    (4, 0): "octaquad-plus",
    (4, 1): "octaquad-x",
}
"""(FRAME_CLASS, FRAME_TYPE) to layout; Y6 (class 5) is ``y6`` for every FRAME_TYPE but 10
(Y6B) and 11 (Y6F), whose other motor orders are not supported."""

ARDUPILOT_Y6_CLASS = 5
ARDUPILOT_Y6_OTHER_TYPES = (10, 11)


def ardupilot_frame(frame_class: int, frame_type: int) -> str | None:
    """Layout name for ArduPilot's ``FRAME_CLASS`` and ``FRAME_TYPE``, or None if unsupported."""
    if frame_class == ARDUPILOT_Y6_CLASS:
        return None if frame_type in ARDUPILOT_Y6_OTHER_TYPES else "y6"
    return ARDUPILOT_FRAMES.get((frame_class, frame_type))


def ardupilot_frame_ids(name: str) -> tuple[int, int]:
    """``(FRAME_CLASS, FRAME_TYPE)`` of a layout name (inverse of :func:`ardupilot_frame`)."""
    if name == "y6":
        return ARDUPILOT_Y6_CLASS, 0
    for ids, frame in ARDUPILOT_FRAMES.items():
        if frame == name:
            return ids
    raise KeyError(name)
