"""Flight-log loaders: one typed :class:`FlightLog` from .tlog, .bin, .ulg or .csv files."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from tether_companion.errors import InputError
from tether_companion.sysid.logs.csvlog import load_csv
from tether_companion.sysid.logs.dataflash import load_dataflash
from tether_companion.sysid.logs.flightlog import FlightLog, Series
from tether_companion.sysid.logs.tlog import load_tlog
from tether_companion.sysid.logs.ulog import load_ulog

LOADERS: dict[str, Callable[[Path], FlightLog]] = {
    ".tlog": load_tlog,
    ".bin": load_dataflash,
    ".ulg": load_ulog,
    ".csv": load_csv,
}
"""Loader by file extension (lower case)."""

__all__ = ["FlightLog", "LOADERS", "Series", "load_flight_log"]


def load_flight_log(path: str | Path) -> FlightLog:
    """Load a flight log, choosing the reader by extension (.tlog, .bin, .ulg, .csv).

    Raises
    ------
    InputError
        When the file is missing, of an unknown kind, truncated or lacks a needed signal.
    """
    path = Path(path)
    loader = LOADERS.get(path.suffix.lower())
    if loader is None:
        raise InputError(
            f"{path}: unknown log type {path.suffix!r}; expected one of {', '.join(LOADERS)}"
        )
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    return loader(path)
