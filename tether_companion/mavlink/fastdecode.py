"""Fast payload decoding of the hot input streams, straight from intact frame bytes.

pymavlink's ``MAVLink.decode`` re-parses the header, checks the CRC a second time, reorders
the fields with Python loops, builds a header object and calls the generated ``__init__``:
several microseconds a message, and the service receives ~600 input messages a second. For
the messages the estimators live on (:data:`HOT_MESSAGES`) :class:`FastDecoder` instead makes
a :class:`HotRecord`: a tuple of the message's fields (pymavlink's names and values, arrays as
lists) and of the header items a receiver reads (sender ids, sequence, the frame itself),
built by one generated function per message from the dialect's own generated class: its wire-
order ``struct`` format (MAVLink 2 extension fields last), its field order, array lengths and
``crc_extra``. A record answers the part of pymavlink's message interface the receivers use
(``get_type()``, ``get_srcSystem()``, ``get_srcComponent()``, ``get_seq()``,
``get_msgbuf()``, every field by name); :meth:`HotRecord.to_message` makes pymavlink's own
object from the frame for anything else. Everything else still goes through pymavlink.

The caller (:class:`~tether_companion.mavlink.framing.FrameParser`) hands in a frame whose
checksum (with the message's ``crc_extra``) it has already checked and that the link-trust
layer admitted; :meth:`FastDecoder.decode` only unpacks. A MAVLink 2 payload whose trailing
zero bytes were truncated by the sender is zero-padded back to the full length, as pymavlink
does. The property tests in ``tests/test_mavlink_fastdecode.py`` check on recorded and fuzzed
frames that every field of a record is bit for bit pymavlink's, and its header items too.
"""

from __future__ import annotations

import functools
import re
import struct
from collections import namedtuple
from collections.abc import Iterable

from pymavlink.dialects.v20 import ardupilotmega as dialect

__all__ = ["HOT_MESSAGES", "FastDecoder", "HotRecord", "MessageLayout", "record_class"]

HOT_MESSAGES: tuple[str, ...] = (
    "RAW_IMU",
    "HIGHRES_IMU",
    "ATTITUDE",
    "SERVO_OUTPUT_RAW",
    "DISTANCE_SENSOR",
    "WINCH_STATUS",
)
"""Messages decoded by :class:`FastDecoder` (the estimators' input streams; the ground
station's WINCH_STATUS arrives at only ~10 Hz, but takes the same path as the other inputs)."""

_HEADER_LEN_V1 = dialect.HEADER_LEN_V1
_HEADER_LEN_V2 = dialect.HEADER_LEN_V2
_STX_V1 = dialect.PROTOCOL_MARKER_V1
_new_tuple = tuple.__new__
_HEADER_ITEMS = ("src_system", "src_component", "seq", "frame")
"""What a record keeps of the header, after the message's fields."""


class HotRecord(tuple):
    """Base of the generated record classes: one message's fields, then :data:`_HEADER_ITEMS`.

    Subclasses (one per hot message, see :func:`record_class`) name every item; they are
    tuples, so building one is a single C call.
    """

    __slots__ = ()
    msgname = ""
    """pymavlink's message name (``RAW_IMU``...)."""
    msg_id = -1
    """The MAVLink message id."""

    def get_type(self) -> str:
        """The message name, as pymavlink's ``get_type()``."""
        return self.msgname

    def get_msgId(self) -> int:  # noqa: N802 - pymavlink's name
        """The message id."""
        return self.msg_id

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        """The sender's system id."""
        return self[-4]

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        """The sender's component id."""
        return self[-3]

    def get_seq(self) -> int:
        """The frame's sequence number."""
        return self[-2]

    def get_msgbuf(self) -> bytearray:
        """The whole frame as received (signature included), as pymavlink's."""
        return self[-1]

    def to_message(self) -> dialect.MAVLink_message:
        """pymavlink's own message object of the same frame."""
        return dialect.MAVLink(None).decode(self[-1])


def record_class(message_class: type[dialect.MAVLink_message]) -> type[HotRecord]:
    """The :class:`HotRecord` subclass of one message: its fields by pymavlink's names.

    Raises
    ------
    ValueError
        For a message with ``char`` fields (pymavlink strips their NULs; not a hot message),
        or a field named like a header item.
    """
    if any(t == "char" for t in message_class.fieldtypes):
        raise ValueError(f"{message_class.msgname}: char fields are not fast-decoded")
    names = tuple(message_class.fieldnames) + _HEADER_ITEMS
    if len(set(names)) != len(names):
        raise ValueError(f"{message_class.msgname}: a field is named like a header item")
    base = namedtuple(f"{message_class.msgname}_fields", names)  # noqa: PYI024 - generated
    return type(
        f"{message_class.msgname.title().replace('_', '')}Record",
        (base, HotRecord),
        {"__slots__": (), "msgname": message_class.msgname, "msg_id": message_class.id},
    )


class MessageLayout:
    """How one message id's payload maps to its :class:`HotRecord`.

    Built from the dialect's generated class, never written by hand: ``unpacker`` is the
    class's wire-order ``struct`` (extensions last), ``make`` puts the unpacked items in the
    class's field order, arrays grouped into lists.

    Raises
    ------
    ValueError
        As :func:`record_class`.
    """

    def __init__(self, message_class: type[dialect.MAVLink_message]) -> None:
        self.record = record_class(message_class)
        self.msg_id: int = message_class.id
        self.crc_extra: int = message_class.crc_extra
        self.unpacker: struct.Struct = message_class.unpacker
        self.size: int = message_class.unpacker.size
        self.padding = bytes(self.size)
        self.wire_index: dict[str, int] = _wire_index(message_class)
        """Each field's index among the unpacked struct items (wire order; an array's first)."""
        self.wire_offsets, self.wire_formats = _wire_items(self.unpacker.format)
        """Each unpacked struct item's byte offset in the payload and its ``struct`` format
        character (what ``frame_core.c`` reads a field at)."""
        self.make = _record_builder(message_class, self.record)
        """``make(flat, src_system, src_component, seq, frame) -> record`` from the unpacked
        struct items ``flat`` (wire order)."""

    def flat_of(self, frame: bytes | bytearray, header_len: int, end: int) -> tuple:
        """The unpacked struct items (wire order) of the payload ``frame[header_len:end]`` of
        a checked frame of this message; a MAVLink 2 payload whose trailing zeros the sender
        truncated is zero-padded back to the full length, as pymavlink does."""
        if end - header_len >= self.size:
            return self.unpacker.unpack_from(frame, header_len)
        return self.unpacker.unpack(frame[header_len:end] + self.padding[end - header_len :])

    def record_of(
        self,
        frame: bytearray,
        header_len: int,
        end: int,
        src_system: int,
        src_component: int,
        seq: int,
    ) -> HotRecord:
        """The record of a checked ``frame`` of this message whose payload is
        ``frame[header_len:end]``; the header items as given."""
        flat = self.flat_of(frame, header_len, end)
        return self.make(flat, src_system, src_component, seq, frame)


def _wire_index(message_class: type[dialect.MAVLink_message]) -> dict[str, int]:
    """Each field's index among the message's unpacked wire-order struct items (an array's
    first element's)."""
    index, flat = {}, 0
    for name, length in zip(message_class.ordered_fieldnames, message_class.lengths, strict=True):
        index[name] = flat
        flat += length
    return index


def _wire_items(fmt: str) -> tuple[tuple[int, ...], str]:
    """Each item a little-endian ``struct`` format without alignment (``<``) of numbers (no
    ``char`` fields: :func:`record_class` refuses them) unpacks: its byte offset and its format
    character (a count repeats its code: an array's elements)."""
    offsets: list[int] = []
    codes = []
    at = 0
    for count, code in re.findall(r"(\d*)([a-zA-Z])", fmt.lstrip("<")):
        n, size = int(count or 1), struct.calcsize("<" + code)
        offsets.extend(range(at, at + n * size, size))
        codes.append(code * n)
        at += n * size
    return tuple(offsets), "".join(codes)


def _record_builder(message_class: type[dialect.MAVLink_message], record: type[HotRecord]):
    """A function building one message's record, generated from its layout.

    One tuple display in the record's order, from constant indices into the wire-order items
    (the source is generated here from the dialect's field names and array lengths; nothing is
    written by hand per message).
    """
    index = _wire_index(message_class)
    where = {}
    for name, length in zip(message_class.ordered_fieldnames, message_class.lengths, strict=True):
        i = index[name]
        where[name] = f"flat[{i}]" if length == 1 else f"list(flat[{i}:{i + length}])"
    items = [where[name] for name in message_class.fieldnames] + list(_HEADER_ITEMS)
    source = (
        f"def make(flat, {', '.join(_HEADER_ITEMS)}):\n"
        f"    return new(record, ({', '.join(items)},))\n"
    )
    namespace = {"new": _new_tuple, "record": record}
    exec(compile(source, f"<fastdecode {message_class.msgname}>", "exec"), namespace)  # noqa: S102
    return namespace["make"]


@functools.cache
def layout_of(name: str) -> MessageLayout:
    """The :class:`MessageLayout` of the dialect's message ``name``, generated once per
    process (its record class and builder are immutable and shared by every decoder: a parser
    per link or per datagram costs no code generation)."""
    return MessageLayout(dialect.mavlink_map[getattr(dialect, f"MAVLINK_MSG_ID_{name}")])


class FastDecoder:
    """Decodes intact frames of the hot messages into :class:`HotRecord` s.

    Parameters
    ----------
    names
        Message names to fast-decode (default :data:`HOT_MESSAGES`).
    """

    def __init__(self, names: Iterable[str] = HOT_MESSAGES) -> None:
        self.layouts: dict[int, MessageLayout] = {
            getattr(dialect, f"MAVLINK_MSG_ID_{name}"): layout_of(name) for name in names
        }

    def handles(self, msg_id: int) -> bool:
        """Whether frames of ``msg_id`` are decoded here."""
        return msg_id in self.layouts

    def decode(self, frame: bytearray, signature_len: int) -> HotRecord:
        """The record of one whole, checksum-verified frame of a handled id.

        ``frame`` (MAVLink 1 or 2, with its ``signature_len`` signature bytes, 13 or 0) becomes
        the record's ``frame``; do not reuse it.
        """
        if frame[0] == _STX_V1:
            header_len = _HEADER_LEN_V1
            seq, src_system, src_component, msg_id = frame[2], frame[3], frame[4], frame[5]
        else:
            header_len = _HEADER_LEN_V2
            seq, src_system, src_component = frame[4], frame[5], frame[6]
            msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
        end = len(frame) - 2 - signature_len
        return self.layouts[msg_id].record_of(
            frame, header_len, end, src_system, src_component, seq
        )
