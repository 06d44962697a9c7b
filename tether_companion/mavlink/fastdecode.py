"""Fast payload decoding of the hot input streams, straight from intact frame bytes.

pymavlink's ``MAVLink.decode`` re-parses the header, checks the CRC a second time, reorders
the fields with Python loops and calls the generated ``__init__``: about 40 us a message on
a small board, and the service receives ~600 input messages a second. For the messages the
estimators live on (:data:`HOT_MESSAGES`) :class:`FastDecoder` builds the *same* pymavlink
message object (same class, same attributes, so ``get_type()``, ``get_srcSystem()``,
``get_msgbuf()`` and every field read exactly as before) from a layout precompiled out of the
dialect's own generated class: its ``struct`` format (wire order, MAVLink 2 extension fields
last), its field order, array lengths and ``crc_extra``. Everything else still goes through
pymavlink.

The caller (:class:`~tether_companion.mavlink.framing.FrameParser`) hands in a frame whose
checksum (with the message's ``crc_extra``) it has already checked and that the link-trust
layer admitted; :meth:`FastDecoder.decode` only unpacks. A MAVLink 2 payload whose trailing
zero bytes were truncated by the sender is zero-padded back to the full length, as pymavlink
does. The ``_payload`` attribute copies pymavlink's (``msgbuf[6:-2]`` whatever the header
length) so that the two decoders' objects are equal attribute for attribute; the property
tests in ``tests/test_mavlink_fastdecode.py`` check exactly that on recorded and fuzzed frames.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

from pymavlink.dialects.v20 import ardupilotmega as dialect

__all__ = ["HOT_MESSAGES", "FastDecoder", "MessageLayout"]

HOT_MESSAGES: tuple[str, ...] = (
    "RAW_IMU",
    "HIGHRES_IMU",
    "ATTITUDE",
    "SERVO_OUTPUT_RAW",
    "DISTANCE_SENSOR",
)
"""Messages decoded by :class:`FastDecoder` (the estimators' input streams)."""

_HEADER_LEN_V1 = dialect.HEADER_LEN_V1
_HEADER_LEN_V2 = dialect.HEADER_LEN_V2
_STX_V1 = dialect.PROTOCOL_MARKER_V1
_Header = dialect.MAVLink_header
_CRC = struct.Struct("<H")
_new_object = object.__new__


class MessageLayout:
    """How one message id's payload maps to its pymavlink message's attributes.

    Built from the dialect's generated class, never written by hand: ``unpacker`` is the
    class's wire-order ``struct`` (extensions last), ``orders`` says which wire field each
    constructor argument is, ``lengths`` groups array fields.

    Raises
    ------
    ValueError
        For a message with ``char`` fields (pymavlink strips their NULs; not a hot message).
    """

    def __init__(self, message_class: type[dialect.MAVLink_message]) -> None:
        if any(t == "char" for t in message_class.fieldtypes):
            raise ValueError(f"{message_class.msgname}: char fields are not fast-decoded")
        self.message_class = message_class
        self.msg_id: int = message_class.id
        self.crc_extra: int = message_class.crc_extra
        self.unpacker: struct.Struct = message_class.unpacker
        self.size: int = message_class.unpacker.size
        self.padding = bytes(self.size)
        self.attributes = _attribute_builder(message_class)
        """``attributes(flat, header, frame, payload, crc) -> dict``: the instance attributes
        pymavlink's decoder sets, from the unpacked struct items ``flat`` (wire order)."""


def _attribute_builder(message_class: type[dialect.MAVLink_message]):
    """A function building one message's attribute dict, generated from its layout.

    A dict display with constant keys is several times cheaper in CPython than filling a dict
    from ``zip(names, values)``; the source is generated here from the dialect's field names
    and array lengths (nothing is written by hand per message).
    """
    items = []
    flat_index = 0
    for name, length in zip(message_class.ordered_fieldnames, message_class.lengths, strict=True):
        if length == 1:
            items.append(f"{name!r}: flat[{flat_index}]")
        else:
            items.append(f"{name!r}: list(flat[{flat_index}:{flat_index + length}])")
        flat_index += length
    constants = {
        "_fieldnames": message_class.fieldnames,
        "_type": message_class.msgname,
        "_signed": False,
        "_link_id": None,
        "_instances": None,
        "_instance_field": message_class.instance_field,
        "_instance_offset": message_class.instance_offset,
    }
    namespace = {f"c{i}": value for i, value in enumerate(constants.values())}
    items += [f"{key!r}: c{i}" for i, key in enumerate(constants)]
    items += ["'_header': header", "'_msgbuf': frame", "'_payload': payload", "'_crc': crc"]
    body = ", ".join(items)
    source = f"def attributes(flat, header, frame, payload, crc):\n    return {{{body}}}\n"
    exec(compile(source, f"<fastdecode {message_class.msgname}>", "exec"), namespace)  # noqa: S102
    return namespace["attributes"]


class FastDecoder:
    """Decodes intact frames of the hot messages into pymavlink message objects.

    Parameters
    ----------
    names
        Message names to fast-decode (default :data:`HOT_MESSAGES`).
    """

    def __init__(self, names: Iterable[str] = HOT_MESSAGES) -> None:
        self.layouts: dict[int, MessageLayout] = {}
        for name in names:
            msg_id = getattr(dialect, f"MAVLINK_MSG_ID_{name}")
            self.layouts[msg_id] = MessageLayout(dialect.mavlink_map[msg_id])

    def handles(self, msg_id: int) -> bool:
        """Whether frames of ``msg_id`` are decoded here."""
        return msg_id in self.layouts

    def decode(self, frame: bytearray, signature_len: int) -> dialect.MAVLink_message:
        """The message of one whole, checksum-verified frame of a handled id.

        ``frame`` (MAVLink 1 or 2, with its ``signature_len`` signature bytes, 13 or 0) becomes
        the message's ``_msgbuf``, as in pymavlink; do not reuse it.
        """
        if frame[0] == _STX_V1:
            header_len = _HEADER_LEN_V1
            _, mlen, seq, src_system, src_component, msg_id = frame[:_HEADER_LEN_V1]
            incompat = compat = 0
        else:
            header_len = _HEADER_LEN_V2
            _, mlen, incompat, compat, seq, src_system, src_component = frame[:7]
            msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
        layout = self.layouts[msg_id]
        end = len(frame) - 2 - signature_len
        payload = frame[header_len:end]
        if len(payload) < layout.size:  # MAVLink 2 trailing zeros truncated by the sender
            payload += layout.padding[len(payload) :]
        header = _new_object(_Header)
        header.__dict__ = {
            "mlen": mlen,
            "seq": seq,
            "srcSystem": src_system,
            "srcComponent": src_component,
            "msgId": msg_id,
            "incompat_flags": incompat,
            "compat_flags": compat,
        }
        msg = _new_object(layout.message_class)
        msg.__dict__ = layout.attributes(
            layout.unpacker.unpack(payload),
            header,
            frame,
            frame[6:end],
            _CRC.unpack_from(frame, end)[0],
        )
        return msg
