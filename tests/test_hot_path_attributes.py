"""The live service's objects keep key-sharing instance dicts (issue 12: CPU per tick).

CPython 3.11+ stores an instance's attributes in the class's shared keys while there are
fewer than 30 of them (``SHARED_KEYS_MAX_SIZE``); from the 30th on, that instance gets a
dict of its own and every attribute read and method call on it leaves the specialised fast
path (a 30-attribute object's method call measured ~30 % slower than a 29-attribute one's).
The estimator holds 29 attributes and the session 28: two more each (31 and 30) cost the live
path 0.8 % of its instructions (callgrind, 8 s of 200 Hz ticks, 1,077.1 M -> 1,085.8 M, wrap21).
This test walks what a flying service holds and names any object past the limit: split it
by job, or hold settings in an object it already has.
"""

from __future__ import annotations

from hot_path_cost import SOURCE, _datagrams  # type: ignore[import-not-found]

from tether_companion.mavlink.endpoints import parse_endpoint
from tether_companion.mavlink.framing import FrameEncoder
from tether_companion.mavlink.trust import LinkTrust
from tether_companion.mavlink.udp_link import UdpLink
from tether_companion.service.app import CompanionService
from tether_companion.service.config import load_service_config, load_vehicle_for

SHARED_KEYS_LIMIT = 30
"""From this many attributes on, an instance's dict stops sharing its class's keys."""


class _SilentLink(UdpLink):
    """A listening UDP link without a socket: datagrams handed in, frames sent dropped."""

    def __init__(self) -> None:
        super().__init__(
            parse_endpoint("udpin:127.0.0.1:0", "listen"),
            FrameEncoder(1, 191),
            64,
            LinkTrust(fc_ids=(1, 1)),
        )

    def _write(self, frame: bytes) -> int:
        return len(self._peers)


def _flown_service() -> CompanionService:
    """A service after 3 s of the bench's streams on the live frame path."""
    overrides = {"recording": {"enabled": False}, "publish": {"on_unhealthy": "inflate"}}
    config = load_service_config(None, overrides)
    service = CompanionService(config, load_vehicle_for(config))
    link = _SilentLink()
    service._send_now_to(link)  # noqa: SLF001 - as _serve wires it

    def receive(items: list) -> None:
        for item in items:
            service._handle_guarded(link, item)  # noqa: SLF001 - _serve's receiver

    link.set_receiver(receive, service.session.frames.take)
    for _, data in _datagrams(200.0, 3.0):
        link._deliver(link._datagram(data, SOURCE))  # noqa: SLF001 - a socket's readiness
    assert service.session.estimator.initialised  # the filter's objects exist
    return service


def _project_objects(root: object) -> dict[str, object]:
    """The project's objects reachable from ``root`` through attributes, lists and dicts,
    by the first path found."""
    found: dict[int, tuple[str, object]] = {}
    stack: list[tuple[str, object]] = [("service", root)]
    while stack:
        path, obj = stack.pop()
        if isinstance(obj, list | tuple):
            stack += [(f"{path}[{i}]", v) for i, v in enumerate(obj[:16])]
            continue
        if isinstance(obj, dict):
            stack += [(f"{path}[{k!r}]", v) for k, v in list(obj.items())[:32]]
            continue
        attributes = getattr(obj, "__dict__", None)
        if not isinstance(attributes, dict) or id(obj) in found:
            continue
        if not type(obj).__module__.startswith("tether_companion"):
            continue
        found[id(obj)] = (path, obj)
        stack += [(f"{path}.{name}", value) for name, value in attributes.items()]
    return dict(found.values())


def test_every_object_of_the_live_path_keeps_a_key_sharing_dict() -> None:
    objects = _project_objects(_flown_service())
    names = {type(obj).__name__ for obj in objects.values()}
    assert {"DynamicTetherEstimator", "EstimationSession", "MemberFilter", "Publisher"} <= names
    too_many = {
        path: f"{type(obj).__name__}: {len(vars(obj))} attributes"
        for path, obj in objects.items()
        if len(vars(obj)) >= SHARED_KEYS_LIMIT
    }
    assert not too_many, too_many
