"""ArduPilot dataflash (.bin) records read straight from the bytes, for replay at speed.

A dataflash log is a sequence of records ``0xA3 0x95 <type> <payload>``; the layout of each
type is declared in the log itself by ``FMT`` records (type 128: type, total length, name,
format characters, comma-separated column names). Format characters map to little-endian
``struct`` codes; ``c``, ``C``, ``e``, ``E`` hold hundredths and ``L`` 1e-7 degrees, and are
scaled here.

Numeric values equal those of pymavlink's ``DFReader`` (same codes, same scaling: a value is
divided by ``1 / multiplier`` as it does, so they are bit for bit the same; the tests compare
the two on every record; text fields stay bytes here), without building a message object per
record, which costs most of ``DFReader``'s time. Bytes that do not start a record of a
declared type are skipped, as ``DFReader`` does (whose index, though, ends at the first
record of an undeclared type; this reader goes on past it); what is left at the end that
does not hold a whole record is counted in :attr:`DataflashReader.remaining`. Pure: bytes in,
records out.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass

HEAD = b"\xa3\x95"
FMT_TYPE = 0x80

_CODES = {
    "a": ("64s", None),
    "b": ("b", None),
    "B": ("B", None),
    "g": ("e", None),
    "h": ("h", None),
    "H": ("H", None),
    "i": ("i", None),
    "I": ("I", None),
    "f": ("f", None),
    "n": ("4s", None),
    "N": ("16s", None),
    "Z": ("64s", None),
    "c": ("h", 0.01),
    "C": ("H", 0.01),
    "e": ("i", 0.01),
    "E": ("I", 0.01),
    "L": ("i", 1e-07),
    "d": ("d", None),
    "M": ("b", None),
    "q": ("q", None),
    "Q": ("Q", None),
}
"""Format character -> (struct code, multiplier or None)."""

_FMT = struct.Struct("<BB4s16s64s")


@dataclass(frozen=True, eq=False)
class RecordFormat:
    """The layout of one record type, as declared by its FMT record.

    Attributes
    ----------
    type
        Record type byte.
    name
        Record name (``IMU``, ``ATT``, ...).
    length
        Whole record length in bytes, header included.
    columns
        Column name -> index in the values.
    """

    type: int
    name: str
    length: int
    columns: dict[str, int]
    _unpack: struct.Struct
    _divisors: tuple[tuple[int, float], ...]

    def values(self, data: bytes, offset: int) -> tuple:
        """The record's values from its payload at ``data[offset:]``, scaled."""
        values = self._unpack.unpack_from(data, offset)
        if not self._divisors:
            return values
        scaled = list(values)
        for index, divisor in self._divisors:
            scaled[index] = float(scaled[index]) / divisor
        return tuple(scaled)


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", "replace")


def _record_format(payload: tuple) -> RecordFormat | None:
    """The format a FMT record declares, or None when it is unusable (unknown format
    character, or a length that does not match the format)."""
    type_, length, name, fmt, columns = payload
    codes = ["<"]
    divisors = []
    chars = _text(fmt)
    for index, char in enumerate(chars):
        code = _CODES.get(char)
        if code is None:
            return None
        codes.append(code[0])
        if code[1] is not None:
            divisors.append((index, 1 / code[1]))  # DFReader divides by 1/multiplier
    unpack = struct.Struct("".join(codes))
    if unpack.size + 3 != length:
        return None
    names = [c for c in _text(columns).split(",") if c]
    return RecordFormat(
        type_, _text(name), length, {c: i for i, c in enumerate(names)}, unpack, tuple(divisors)
    )


class DataflashReader:
    """Records of a dataflash log held in memory.

    Parameters
    ----------
    data
        The whole log.

    Attributes
    ----------
    remaining
        Bytes at the end that do not hold a whole record (after :meth:`records` ran to the
        end): non-zero for a truncated log.
    records_read
        Records of declared types read (FMT records included).
    """

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.formats: dict[int, RecordFormat] = {}
        self.remaining = len(data)
        self.records_read = 0

    def records(self, names: set[str]) -> Iterator[tuple[RecordFormat, tuple]]:
        """``(format, values)`` of every record whose name is in ``names``, in log order."""
        data = self.data
        size = len(data)
        formats = self.formats
        head1, head2 = HEAD
        pos = 0
        while size - pos >= 3:
            fmt = formats.get(data[pos + 2]) if data[pos + 2] != FMT_TYPE else None
            if (
                data[pos] != head1
                or data[pos + 1] != head2
                or (fmt is None and data[pos + 2] != FMT_TYPE)
            ):
                found = data.find(HEAD, pos + 1)
                pos = found if found >= 0 else max(pos + 1, size - 2)
                continue
            if fmt is None:  # a FMT record
                end = pos + 3 + _FMT.size
                if end > size:
                    break
                declared = _record_format(_FMT.unpack_from(data, pos + 3))
                if declared is not None:
                    formats[declared.type] = declared
                pos = end
                self.records_read += 1
                continue
            end = pos + fmt.length
            if end > size:
                break
            self.records_read += 1
            if fmt.name in names:
                yield fmt, fmt.values(data, pos + 3)
            pos = end
        self.remaining = size - pos
