"""The dataflash record reader against pymavlink's DFReader, record by record (issue 12)."""

from __future__ import annotations

import contextlib
import io
import struct
from pathlib import Path

import numpy as np
from pymavlink import DFReader

from tether_companion.mavlink.dataflash import DataflashReader

TYPES = {
    # name: (type, format, columns)
    "IMU": (200, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "ATT": (201, "QccccCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw"),
    "RCOU": (202, "QHHHHhb", "TimeUS,C1,C2,C3,C4,C5,C6"),
    "POS": (203, "QLLeEiIdq", "TimeUS,Lat,Lng,Alt,RelAlt,A,B,C,D"),
}


def _fmt_record(msg_type: int, name: str, fmt: str, columns: str) -> bytes:
    length = 3 + struct.calcsize("<" + fmt.translate(str.maketrans("LcCeE", "ihHiI")))
    body = struct.pack(
        "<BB4s16s64s", msg_type, length, name.encode(), fmt.encode(), columns.encode()
    )
    return b"\xa3\x95\x80" + body


def _random_values(fmt: str, rng: np.random.Generator) -> list:
    ranges = {
        "Q": (0, 2**40), "q": (-(2**40), 2**40), "B": (0, 255), "b": (-128, 127),
        "H": (0, 65535), "h": (-32768, 32767), "C": (0, 65535), "c": (-32768, 32767),
        "I": (0, 2**32 - 1), "i": (-(2**31), 2**31 - 1), "E": (0, 2**32 - 1),
        "e": (-(2**31), 2**31 - 1), "L": (-(2**31), 2**31 - 1),
    }  # fmt: skip
    values = []
    for char in fmt:
        if char in ("f", "d"):
            values.append(float(rng.normal(0.0, 100.0)))
        else:
            low, high = ranges[char]
            values.append(int(rng.integers(low, high, endpoint=True)))
    return values


def _write_log(
    path: Path, rng: np.random.Generator, records: int, undeclared: bool = False
) -> Path:
    parts = [_fmt_record(t, name, fmt, cols) for name, (t, fmt, cols) in TYPES.items()]
    names = list(TYPES)
    for k in range(records):
        name = names[int(rng.integers(len(names)))]
        msg_type, fmt, _ = TYPES[name]
        code = "<" + fmt.translate(str.maketrans("LcCeE", "ihHiI"))
        parts.append(bytes((0xA3, 0x95, msg_type)) + struct.pack(code, *_random_values(fmt, rng)))
        if k % 97 == 50:  # garbage (no header byte in it): skipped
            parts.append(bytes(rng.integers(0, 0xA3, 7, dtype=np.uint8)))
            if undeclared:  # a record of an undeclared type: skipped too
                parts.append(b"\xa3\x95\x11" + bytes(5))
    path.write_bytes(b"".join(parts))
    return path


def _dfreader_records(path: Path) -> list[tuple[str, list]]:
    out = []
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        reader = DFReader.DFReader_binary(str(path))
        while (msg := reader.recv_match(type=list(TYPES))) is not None:
            out.append((msg.get_type(), [getattr(msg, c) for c in msg.get_fieldnames()]))
    return out


def test_every_record_equals_dfreaders(tmp_path: Path, rng) -> None:
    path = _write_log(tmp_path / "log.bin", rng, 3000)
    ours = DataflashReader(path.read_bytes())
    got = [(fmt.name, list(values)) for fmt, values in ours.records(set(TYPES))]
    expected = _dfreader_records(path)
    assert len(got) == len(expected) == 3000
    for (name, values), (name_ref, values_ref) in zip(got, expected, strict=True):
        assert name == name_ref
        assert values == values_ref, name  # bit for bit, scaled fields included
        assert [type(v) for v in values] == [type(v) for v in values_ref], name
    assert ours.remaining == 0


def test_truncated_log_leaves_bytes(tmp_path: Path, rng) -> None:
    data = _write_log(tmp_path / "log.bin", rng, 50).read_bytes()
    reader = DataflashReader(data[:-5])
    assert len(list(reader.records(set(TYPES)))) == 49
    assert reader.remaining > 0
    junk = DataflashReader(bytes(range(256)) * 4)
    assert list(junk.records(set(TYPES))) == [] and junk.remaining > 0


def test_records_of_undeclared_types_are_skipped(tmp_path: Path, rng) -> None:
    """(DFReader's index stops at the first one; this reader goes on.)"""
    path = _write_log(tmp_path / "log.bin", rng, 300, undeclared=True)
    reader = DataflashReader(path.read_bytes())
    assert len(list(reader.records(set(TYPES)))) == 300 and reader.remaining == 0
