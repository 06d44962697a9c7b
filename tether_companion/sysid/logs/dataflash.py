"""ArduPilot dataflash logs (.bin) read with pymavlink's ``DFReader``.

Messages used (fields as ArduPilot writes them):

- ``IMU`` (``TimeUS``, ``AccX/Y/Z`` [m/s^2], instance ``I`` 0 when present);
- ``ATT`` (``TimeUS``, ``Roll``, ``Pitch``, ``Yaw`` [deg]);
- ``RCOU`` (``TimeUS``, ``C1`` .. ``C4`` [us]);
- height, optional: ``RFND`` (``Dist`` [m], instance 0) or else ``BARO`` (``Alt`` [m]);
- battery voltage, optional: ``BAT`` (``Volt`` [V], instance 0) or else ``CURR`` (older
  logs' ``Volt`` [V]); readings <= 0 (no monitor) are skipped.
"""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path
from typing import Any

from pymavlink import DFReader

from tether_companion.errors import InputError
from tether_companion.sysid.logs.flightlog import N_MOTORS, FlightLog, make_series

WANTED = ("IMU", "ATT", "RCOU", "RFND", "BARO", "BAT", "CURR")


def _instance(msg: Any) -> int:
    for name in ("I", "Instance", "Inst"):
        value = getattr(msg, name, None)
        if value is not None:
            return int(value)
    return 0


def _read_messages(path: Path) -> dict[str, list[Any]]:
    source = str(path)
    if not path.is_file():
        raise InputError(f"{source}: no such file")
    if path.stat().st_size == 0:
        raise InputError(f"{source}: empty file")
    messages: dict[str, list[Any]] = {name: [] for name in WANTED}
    # DFReader prints complaints about garbage to stderr; they are summarised in our error.
    with contextlib.redirect_stderr(io.StringIO()):
        try:
            reader = DFReader.DFReader_binary(source)
        except Exception as exc:  # noqa: BLE001 - DFReader raises many kinds on bad bytes
            raise InputError(f"{source}: not a readable dataflash log ({exc})") from None
        try:
            while True:
                try:
                    msg = reader.recv_match(type=list(WANTED))
                except Exception as exc:  # noqa: BLE001 - as above
                    raise InputError(
                        f"{source}: corrupt or truncated dataflash record ({exc})"
                    ) from None
                if msg is None:
                    break
                if _instance(msg) == 0:
                    messages[msg.get_type()].append(msg)
        finally:
            reader.filehandle.close()
    return messages


def load_dataflash(path: Path) -> FlightLog:
    """Read an ArduPilot .bin log into a :class:`FlightLog` (see module docstring).

    Raises
    ------
    InputError
        When the file is unreadable or lacks IMU, ATT or RCOU messages.
    """
    source = str(path)
    messages = _read_messages(path)
    for name in ("IMU", "ATT", "RCOU"):
        if not messages[name]:
            raise InputError(
                f"{source}: no {name} message in the log "
                "(not an ArduPilot dataflash log, or truncated)"
            )
    imu, att, rcou = messages["IMU"], messages["ATT"], messages["RCOU"]
    height = None
    for name, field in (("RFND", "Dist"), ("BARO", "Alt")):
        usable = [m for m in messages[name] if getattr(m, field, None) is not None]
        if len(usable) >= 2:
            height = make_series(
                source,
                name,
                [m.TimeUS * 1e-6 for m in usable],
                [getattr(m, field) for m in usable],
                1,
            )
            break
    voltage = None
    for name in ("BAT", "CURR"):
        usable = [m for m in messages[name] if (getattr(m, "Volt", None) or 0.0) > 0.0]
        if len(usable) >= 2:
            voltage = make_series(
                source, name, [m.TimeUS * 1e-6 for m in usable], [m.Volt for m in usable], 1
            )
            break
    deg = math.pi / 180.0
    return FlightLog(
        source=source,
        pwm_us=make_series(
            source,
            "RCOU",
            [m.TimeUS * 1e-6 for m in rcou],
            [[getattr(m, f"C{i + 1}") for i in range(N_MOTORS)] for m in rcou],
            N_MOTORS,
        ),
        specific_force_body_mps2=make_series(
            source,
            "IMU",
            [m.TimeUS * 1e-6 for m in imu],
            [[m.AccX, m.AccY, m.AccZ] for m in imu],
            3,
        ),
        euler_rad=make_series(
            source,
            "ATT",
            [m.TimeUS * 1e-6 for m in att],
            [[m.Roll * deg, m.Pitch * deg, m.Yaw * deg] for m in att],
            3,
        ),
        height_m=height,
        battery_voltage_v=voltage,
    )
