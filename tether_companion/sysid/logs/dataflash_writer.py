"""Write ArduPilot-style dataflash (.bin) logs: FMT records followed by message records.

Used to record simulated identification flights in the format ArduPilot writes, and by the
tests. Each record is ``0xA3 0x95 <type id>`` and the little-endian packed fields; a message
type is declared once by an ``FMT`` record (type 128) giving its length, name, field format
characters and column names (pymavlink ``DFReader`` conventions: ``Q`` uint64, ``f`` float,
``H`` uint16, ``B`` uint8, ``N`` char[16]).
"""

from __future__ import annotations

import struct
from typing import BinaryIO

HEADER = b"\xa3\x95"
FMT_TYPE = 128
_FMT_STRUCT = struct.Struct("<BB4s16s64s")
_CHAR_TO_STRUCT = {
    "Q": "Q",
    "q": "q",
    "f": "f",
    "d": "d",
    "H": "H",
    "h": "h",
    "B": "B",
    "b": "b",
    "I": "I",
    "i": "i",
    "N": "16s",
}


class DataflashWriter:
    """Write a dataflash log to a binary stream.

    Parameters
    ----------
    stream
        An open binary file; the caller closes it.
    """

    def __init__(self, stream: BinaryIO) -> None:
        self._stream = stream
        self._types: dict[str, tuple[int, struct.Struct]] = {}
        self._write_format(
            FMT_TYPE, "FMT", 3 + _FMT_STRUCT.size, "BBnNZ", "Type,Length,Name,Format,Columns"
        )

    def _write_format(self, type_id: int, name: str, length: int, fmt: str, columns: str) -> None:
        body = _FMT_STRUCT.pack(type_id, length, name.encode(), fmt.encode(), columns.encode())
        self._stream.write(HEADER + bytes([FMT_TYPE]) + body)

    def declare(self, name: str, fmt: str, columns: tuple[str, ...]) -> None:
        """Declare message ``name`` with one format character per column (e.g. ``"Qfff"``)."""
        if len(fmt) != len(columns):
            raise ValueError(f"{name}: {len(fmt)} format characters for {len(columns)} columns")
        packer = struct.Struct("<" + "".join(_CHAR_TO_STRUCT[c] for c in fmt))
        type_id = 129 + len(self._types)
        self._types[name] = (type_id, packer)
        self._write_format(type_id, name, 3 + packer.size, fmt, ",".join(columns))

    def write(self, name: str, *values: float) -> None:
        """Append one ``name`` record with the declared columns' values."""
        type_id, packer = self._types[name]
        self._stream.write(HEADER + bytes([type_id]) + packer.pack(*values))


def declare_identification_messages(writer: DataflashWriter) -> None:
    """Declare IMU, ATT, RCOU, RFND and BAT as ArduPilot names them (the fields the loader
    reads)."""
    writer.declare(
        "IMU", "QBffffff", ("TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ")
    )
    writer.declare("ATT", "Qfff", ("TimeUS", "Roll", "Pitch", "Yaw"))
    writer.declare("RCOU", "QHHHH", ("TimeUS", "C1", "C2", "C3", "C4"))
    writer.declare("RFND", "QBf", ("TimeUS", "Instance", "Dist"))
    writer.declare("BAT", "QBf", ("TimeUS", "Inst", "Volt"))
