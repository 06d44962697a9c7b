"""Fast MAVLink 2 framing of outgoing messages: the same bytes as pymavlink's ``pack``.

pymavlink's ``MAVLink_message.pack`` builds a header object, copies the frame several times
and runs its checksum through a Python object: 12-19 us a message here, and the service sends
~80 a second (VISION_POSITION_ESTIMATE at 30 Hz, the tension filter's NAMED_VALUE_FLOATs).
:class:`FastEncoder` packs the payload with the message class's own ``struct`` (fields in wire
order, arrays item by item, ``char`` fields from pymavlink's raw bytes, as the generated
``pack`` methods do), strips the trailing zero bytes as MAVLink 2 allows (keeping one), and
checksums header and payload with fastcrc's C CRC-16/MCRF4XX and the message's ``crc_extra``.
The packers are generated from each dialect class on first use, never written by hand;
``tests/test_mavlink_fastencode.py`` compares the bytes with pymavlink's for every message of
the dialect on random field values.
"""

from __future__ import annotations

from collections.abc import Callable

from fastcrc.crc16 import mcrf4xx
from pymavlink.dialects.v20 import ardupilotmega as dialect

__all__ = ["FastEncoder", "payload_packer"]

_STX_V2 = dialect.PROTOCOL_MARKER_V2


def payload_packer(message_class: type[dialect.MAVLink_message]) -> Callable[..., bytes]:
    """``pack(msg) -> bytes``: the whole payload of a ``message_class`` message, generated from
    the class's field names, types and array lengths in wire order."""
    names = message_class.fieldnames
    items = []
    for name, length in zip(
        message_class.ordered_fieldnames, message_class.array_lengths, strict=True
    ):
        if message_class.fieldtypes[names.index(name)] == "char":
            items.append(f"msg._{name}_raw")  # pymavlink keeps the bytes as given
        elif length:
            items += [f"msg.{name}[{i}]" for i in range(length)]
        else:
            items.append(f"msg.{name}")
    source = f"def pack(msg):\n    return struct_pack({', '.join(items)})\n"
    namespace = {"struct_pack": message_class.unpacker.pack}
    exec(compile(source, f"<fastencode {message_class.msgname}>", "exec"), namespace)  # noqa: S102
    return namespace["pack"]


class FastEncoder:
    """Unsigned MAVLink 2 frames of pymavlink message objects (packers made per class on first
    use)."""

    def __init__(self) -> None:
        self._packers: dict[type, tuple[Callable[..., bytes], bytes]] = {}

    def frame(
        self, msg: dialect.MAVLink_message, seq: int, system_id: int, component_id: int
    ) -> bytes:
        """The frame pymavlink's ``msg.pack`` makes with that sequence number and sender.

        Raises
        ------
        struct.error
            When a field does not fit its wire type (as pymavlink's).
        """
        cls = type(msg)
        known = self._packers.get(cls)
        if known is None:
            known = self._packers[cls] = (payload_packer(cls), bytes((cls.crc_extra,)))
        pack, crc_extra = known
        payload = pack(msg)
        payload = payload.rstrip(b"\x00") or payload[:1]
        msg_id = cls.id
        frame = bytearray(
            (
                _STX_V2,
                len(payload),
                0,
                0,
                seq,
                system_id,
                component_id,
                msg_id & 0xFF,
                (msg_id >> 8) & 0xFF,
                msg_id >> 16,
            )
        )
        frame += payload
        frame += mcrf4xx(crc_extra, mcrf4xx(frame[1:], 0xFFFF)).to_bytes(2, "little")
        return bytes(frame)
