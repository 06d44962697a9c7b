"""The ``--status`` live view: rates, staleness, estimate, covariance, drops, health (rich)."""

from __future__ import annotations

import asyncio
import contextlib
import math

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from tether_companion.service.app import CompanionService
from tether_companion.service.health import OK, health_text
from tether_companion.service.ingest import INPUT_KINDS

_HEALTH_STYLE = {
    OK: "bold green",
    "converging": "yellow",
    "stale": "bold red",
    "diverged": "bold red",
}


def render(service: CompanionService) -> Group:
    """One frame of the live view for the service's current state."""
    state = service.state
    session = service.session
    publisher = session.publisher
    health_style = _HEALTH_STYLE.get(publisher.health, "bold yellow")
    head = Text.assemble(
        ("tether-companion  ", "bold"),
        (state.link_text, "green" if state.link_up else "red"),
        "  health: ",
        (publisher.health, health_style),
        ("" if publisher.health == OK else f" ({health_text(publisher.health)})", health_style),
        f"  reset_counter {publisher.reset_counter}",
        _clock_text(service),
    )

    inputs = Table(title="inputs", expand=False)
    for column in ("input", "rate [Hz]", "age [s]", "accepted"):
        inputs.add_column(column, justify="right")
    accepted = session.ingest.counters.accepted
    for kind in INPUT_KINDS:
        age = state.ages_s.get(kind, math.inf)
        inputs.add_row(
            kind,
            f"{state.rates_hz.get(kind, 0.0):.1f}",
            "-" if math.isinf(age) else f"{age:.2f}",
            str(accepted[kind]),
        )
    inputs.add_row(
        "published",
        f"{state.rates_hz.get('published', 0.0):.1f}",
        "",
        str(publisher.counters.published),
    )

    counters = session.ingest.counters
    link = service.link
    framing = link.framing.as_dict() if link is not None else {}
    drops = Table(title="dropped and counted", expand=False)
    drops.add_column("why")
    drops.add_column("count", justify="right")
    for name in (
        "wrong_system",
        "nonfinite",
        "absurd",
        "out_of_range",
        "duplicate",
        "out_of_order",
        "implausible",
        "no_fc_time",
        "reboots",
    ):
        drops.add_row(name.replace("_", " "), str(getattr(counters, name)))
    drops.add_row(
        f"reordered by the link (window now {1e3 * counters.reorder_window_s:.0f} ms)",
        str(counters.reordered),
    )
    for name in ("garbage_bytes", "bad_crc", "unknown_id", "truncated"):
        drops.add_row(name.replace("_", " "), str(framing.get(name, 0)))
    trust = getattr(link, "trust", None)
    if trust is not None:  # signing and address checks (docs/security.md), by reason
        for name, count in trust.counters.as_dict().items():
            if name not in ("admitted", "repins") and count:
                drops.add_row(name.replace("_", " "), str(count))
    winch = session.ingest.winch
    if winch is not None:  # the winch's WINCH_STATUS drops, by reason
        for name, count in winch.counters.as_dict().items():
            if name != "accepted" and count:
                drops.add_row(f"winch: {name.replace('_', ' ')}", str(count))
        if session.winch.timeouts:
            drops.add_row("winch: timed out (stale)", str(session.winch.timeouts))
        if session.winch.near_vertical:
            drops.add_row("winch: near vertical, not fused", str(session.winch.near_vertical))
    angle = session.ingest.cable_angle
    if angle is not None:  # the cable-angle sensor's DEBUG_VECT drops, by reason
        for name, count in angle.counters.as_dict().items():
            if name != "accepted" and count:
                drops.add_row(f"cable angle: {name.replace('_', ' ')}", str(count))
        feed = session.cable_angle
        for label, count in (
            ("timed out (stale)", feed.timeouts),
            ("stale for the filter, not fused", feed.stale_readings),
            ("near vertical, not fused", feed.near_vertical),
        ):
            if count:
                drops.add_row(f"cable angle: {label}", str(count))
    for reason, count in sorted(session.commands_refused.items()):
        drops.add_row(f"commands denied: {reason.replace('_', ' ')}", str(count))
    drops.add_row("withheld estimates", str(publisher.counters.withheld))
    drops.add_row("handler errors", str(state.handler_errors))

    estimate = Table(title="estimate (NED from the anchor)", expand=False)
    for column in ("", "north", "east", "down", "tension"):
        estimate.add_column(column, justify="right")
    last = session.last_estimate
    if last is not None:
        variance = np.diag(last.covariance)
        sigma = np.sqrt(np.clip(variance, 0.0, None))
        estimate.add_row(
            escape("EKF [m, N]"),
            *(f"{v:+.2f}" for v in last.position_ned_m),
            f"{last.tension_n:.2f}",
        )
        tension_sigma = f"{sigma[3]:.3f}" if sigma.shape[0] > 3 else "known"
        estimate.add_row("EKF 1-sigma", *(f"{s:.3f}" for s in sigma[:3]), tension_sigma)
        velocity = getattr(last, "velocity_ned_mps", None)  # the dynamic filter has one
        if velocity is not None:
            estimate.add_row(escape("velocity [m/s]"), *(f"{v:+.2f}" for v in velocity), "")
        reason = getattr(last, "reason", "")
        if reason:  # the dynamic filter's own words for why its position is not observable
            estimate.add_row("filter says", escape(reason), "", "", "")
        estimate.add_row(escape("FC time [s]"), f"{last.time_s:.3f}", "", "", "")
    else:
        estimate.add_row("no estimate yet", "", "", "", "")
    tension = session.modes.tension
    if tension is not None and tension.valid:
        estimate.add_row(
            escape("tension filter [N]"),
            *(f"{v:+.2f}" for v in tension.tension_ned_n),
            f"{tension.magnitude_n:.2f}",
        )
    if winch is not None:
        reading = session.winch.last
        if reading is None:
            estimate.add_row("winch", "stale" if session.winch.stale else "nothing yet", "", "", "")
        else:
            tension = "" if math.isnan(reading.tension_n) else f"{reading.tension_n:.2f}"
            estimate.add_row(
                escape("winch line [m], tension at winch [N]"),
                f"{reading.length_m:.2f}",
                "",
                "",
                tension,
            )
    if angle is not None:
        reading = session.cable_angle.last
        if reading is None:
            state_text = "stale" if session.cable_angle.stale else "nothing yet"
            estimate.add_row("cable angle", state_text, "", "", "")
        else:
            estimate.add_row(
                escape("cable angle at anchor: azimuth, elevation [deg]"),
                f"{math.degrees(reading.azimuth_rad):+.1f}",
                f"{math.degrees(reading.elevation_rad):+.1f}",
                "",
                "",
            )
    catenary = session.last_catenary
    if catenary is not None:
        source = " (published)" if session.catenary_source else ""
        if catenary.valid:
            values = [f"{v:+.2f}" for v in catenary.position_ned_m]
        else:
            values = [catenary.status, "", ""]
        estimate.add_row(escape(f"catenary [m]{source}"), *values, "")
    sent = ", ".join(f"{k} {v}" for k, v in sorted(state.sent_by_type.items()))
    return Group(head, inputs, estimate, drops, Text(f"sent: {sent}"))


def _clock_text(service: CompanionService) -> str:
    clock = service.clock
    offset = clock.offset_s(service.monotonic_s())
    if offset is None:
        return "  FC clock: not synchronised"
    rtt = clock.timesync_rtt_s
    rtt_text = "no TIMESYNC" if rtt is None else f"TIMESYNC rtt {rtt * 1e3:.1f} ms"
    return f"  FC time {service.monotonic_s() + offset:.2f} s ({rtt_text})"


async def live_status(
    service: CompanionService, stop: asyncio.Event, refresh_hz: float = 4.0
) -> None:
    """Redraw the view ``refresh_hz`` times a second until ``stop`` is set."""
    console = Console()
    with Live(
        render(service), console=console, refresh_per_second=refresh_hz, transient=False
    ) as live:
        while not stop.is_set():
            live.update(render(service))
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(stop.wait(), timeout=1.0 / refresh_hz)
        live.update(render(service))
