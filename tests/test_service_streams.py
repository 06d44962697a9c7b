"""The stream requests' fallback to REQUEST_DATA_STREAM asks each group at its fastest input."""

from __future__ import annotations

from tether_companion.mavlink.framing import dialect
from tether_companion.service.config import load_service_config
from tether_companion.service.streams import StreamRequests


def test_a_shared_group_is_asked_at_its_fastest_inputs_rate() -> None:
    config = load_service_config(None, {"streams": {"rangefinder_hz": 20.0}})
    streams = StreamRequests(config.link, config.streams)
    silent = {kind: 0 for kind in streams.table}
    now = 0.0
    requests = []
    for _ in range(4):  # every input stays silent: the intervals are retried, then the groups
        requests += streams.due(now, silent)
        now += config.link.stream_request_interval_s + 0.6
    extra3 = [
        m.req_message_rate
        for m in requests
        if m.get_type() == "REQUEST_DATA_STREAM"
        and m.req_stream_id == dialect.MAV_DATA_STREAM_EXTRA3
    ]
    assert extra3 and set(extra3) == {20}  # the rangefinder's, not SYSTEM_TIME's 5 Hz
