"""Autopilot parameter sets from logs and parameter files.

* MAVLink ``.tlog``: the PARAM_VALUE messages of the flight controller (the system that sent
  the most); PX4 sends integer parameters bytewise (the int32's bytes in the float field,
  ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``), ArduPilot as a float value
  (``PARAM_ENCODE_C_CAST``): the HEARTBEAT's autopilot field says which.
* ArduPilot dataflash ``.bin``: ``PARM`` records (``Name``, ``Value``); the last value wins.
* PX4 ``.ulg``: the log's initial parameters (pyulog ``initial_parameters``).
* Parameter files (``.parm``, ``.param``, ``.params``): ``NAME VALUE`` or ``NAME,VALUE`` per
  line (ArduPilot, Mission Planner) or QGroundControl's tab-separated
  ``sys comp NAME VALUE type`` lines; ``#`` starts a comment.
"""

from __future__ import annotations

import contextlib
import io
import math
import struct
from collections import Counter, defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tether_companion.errors import InputError

MAV_AUTOPILOT_PX4 = 12
INTEGER_PARAM_TYPES = frozenset({1, 2, 3, 4, 5, 6})
"""MAV_PARAM_TYPE UINT8 .. INT32: the ones PX4 encodes bytewise."""
_INT_FORMATS = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}


def param_value(value: float, param_type: int, bytewise: bool) -> float:
    """The parameter's value from PARAM_VALUE's ``param_value`` float.

    With ``bytewise`` (PX4) an integer parameter's bytes are the float's bytes: they are
    reinterpreted as the integer type ``param_type`` names.
    """
    if not bytewise or param_type not in INTEGER_PARAM_TYPES:
        return float(value)
    raw = struct.pack("<f", value)
    fmt = _INT_FORMATS[param_type]
    return float(struct.unpack(fmt, raw[: struct.calcsize(fmt)])[0])


def param_name(param_id: Any) -> str:
    """PARAM_VALUE's ``param_id`` (bytes or str, NUL-padded to 16) as a name."""
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", errors="replace")
    return str(param_id).split("\x00", 1)[0].strip()


def read_parameters(path: str | Path) -> dict[str, float]:
    """The parameter set a log or parameter file holds (see module docstring).

    Raises
    ------
    InputError
        When the file is missing, unreadable, of an unknown kind, or holds no parameters.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".tlog":
        params = _from_tlog(path)
    elif suffix in (".bin", ".log"):
        params = _from_dataflash(path)
    elif suffix == ".ulg":
        params = _from_ulog(path)
    elif suffix in (".parm", ".param", ".params", ".txt"):
        params = _from_text(path)
    else:
        raise InputError(
            f"{path}: unknown kind {suffix!r}; expected .tlog, .bin, .ulg or a parameter file "
            "(.parm, .param, .params)"
        )
    if not params:
        raise InputError(f"{path}: no parameters found")
    return params


def _from_tlog(path: Path) -> dict[str, float]:
    from pymavlink import mavutil

    try:
        link = mavutil.mavlogfile(str(path), robust_parsing=True)
    except OSError as exc:
        raise InputError(f"{path}: cannot open ({exc.strerror})") from None
    values: dict[int, dict[str, tuple[float, int]]] = defaultdict(dict)
    autopilots: dict[int, int] = {}
    try:
        while True:
            try:
                msg = link.recv_match(type=["PARAM_VALUE", "HEARTBEAT"])
            except Exception as exc:  # noqa: BLE001 - pymavlink raises many kinds on bad bytes
                raise InputError(f"{path}: unreadable MAVLink data ({exc})") from None
            if msg is None:
                break
            system = msg.get_srcSystem()
            if msg.get_type() == "HEARTBEAT":
                autopilots.setdefault(system, msg.autopilot)
            else:
                values[system][param_name(msg.param_id)] = (msg.param_value, msg.param_type)
    finally:
        link.close()
    if not values:
        return {}
    system, _ = Counter({s: len(v) for s, v in values.items()}).most_common(1)[0]
    bytewise = autopilots.get(system) == MAV_AUTOPILOT_PX4
    return {
        name: param_value(value, param_type, bytewise)
        for name, (value, param_type) in values[system].items()
    }


def _from_dataflash(path: Path) -> dict[str, float]:
    from pymavlink import DFReader

    params: dict[str, float] = {}
    with contextlib.redirect_stderr(io.StringIO()):
        try:
            reader = DFReader.DFReader_binary(str(path))
        except Exception as exc:  # noqa: BLE001 - DFReader raises many kinds on bad bytes
            raise InputError(f"{path}: not a readable dataflash log ({exc})") from None
        try:
            while True:
                try:
                    msg = reader.recv_match(type="PARM")
                except Exception as exc:  # noqa: BLE001 - as above
                    raise InputError(f"{path}: corrupt dataflash record ({exc})") from None
                if msg is None:
                    break
                params[param_name(msg.Name)] = float(msg.Value)
        finally:
            reader.filehandle.close()
    return params


def _from_ulog(path: Path) -> dict[str, float]:
    try:
        from pyulog import ULog
    except ImportError:
        raise InputError(
            f"{path}: reading PX4 .ulg logs needs pyulog: pip install 'tether-companion[ulog]'"
        ) from None
    try:
        log = ULog(str(path), message_name_filter_list=[])
    except Exception as exc:  # noqa: BLE001 - pyulog raises many kinds on bad bytes
        raise InputError(f"{path}: not a readable ULog ({exc})") from None
    return {str(k): float(v) for k, v in log.initial_parameters.items()}


def _from_text(path: Path) -> dict[str, float]:
    params: dict[str, float] = {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read ({exc})") from None
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        fields = body.replace(",", " ").split()
        if len(fields) == 5 and fields[0].isdigit() and fields[1].isdigit():  # QGC
            fields = fields[2:4]
        if len(fields) != 2:
            raise InputError(f"{path}:{number}: expected 'NAME VALUE', got {line.strip()!r}")
        try:
            value = float(fields[1])
        except ValueError:
            raise InputError(
                f"{path}:{number}: {fields[0]} = {fields[1]!r} is not a number"
            ) from None
        if not math.isfinite(value):
            raise InputError(f"{path}:{number}: {fields[0]} = {fields[1]!r} is not finite")
        params[fields[0]] = value
    return params


def merge(*sets: Mapping[str, float]) -> dict[str, float]:
    """Parameter sets merged left to right (later files override earlier ones)."""
    merged: dict[str, float] = {}
    for params in sets:
        merged.update(params)
    return merged
