"""Replay a flight log through the same :class:`EstimationSession` as the live service.

Sources:

* a MAVLink telemetry log (``.tlog``, e.g. the service's own recording): every frame goes
  through the same framing, ingest, estimator and publisher as live, so a recording replays
  to the estimates the live run sent;
* an ArduPilot dataflash log (``.bin``): IMU (m/s^2, rad/s), ATT (degrees), RCOU (us) and
  RFND (m) are turned into samples directly (they are already in SI units or close) and fed to
  the same session.

Replay runs as fast as the CPU allows and writes one CSV row per published estimate (see
:class:`~tether_companion.service.publish.Publication`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from tether_companion.errors import InputError
from tether_companion.frames import wrap_pi
from tether_companion.mavlink.dataflash import DataflashReader, RecordFormat
from tether_companion.mavlink.framing import FrameParser
from tether_companion.physics.vehicle import VehicleProfile
from tether_companion.samples import AttitudeSample, ImuSample, PwmSample, RangeSample
from tether_companion.service.config import ServiceConfig
from tether_companion.service.health import OK, health_text
from tether_companion.service.ingest import ATTITUDE, IMU, PWM, Sample
from tether_companion.service.ingest_frames import FrameIngest
from tether_companion.service.publish import Publication
from tether_companion.service.recording import read_tlog
from tether_companion.service.session import EstimationSession, Step

DATAFLASH_DOWNWARD = 25
"""RFND ``Orient`` of a downward rangefinder (ROTATION_PITCH_270)."""
_REQUIRED = (IMU, ATTITUDE, PWM)
_MAVLINK_NAMES = {"ardupilot": {IMU: "RAW_IMU"}, "px4": {IMU: "HIGHRES_IMU"}}
_COMMON_NAMES = {ATTITUDE: "ATTITUDE", PWM: "SERVO_OUTPUT_RAW"}
_DATAFLASH_NAMES = {IMU: "IMU", ATTITUDE: "ATT", PWM: "RCOU"}


@dataclass(frozen=True)
class ReplaySummary:
    """What a replay did.

    ``estimates`` counts the estimator's outputs (IMU ticks), ``not_ok`` those whose health
    was not ``ok``, by health state: the reasons positions were withheld (or inflated).
    """

    source: str
    inputs: dict[str, int]
    published: int
    fc_time_span_s: float
    ingest_dropped: int
    estimates: int = 0
    not_ok: dict[str, int] = field(default_factory=dict)

    def reasons_text(self) -> str:
        """Why positions were not published as healthy, most frequent first ("" if always ok).

        With no estimate at all, says so and why (no IMU tick reached the estimator)."""
        if self.estimates == 0:
            return (
                "no estimate: no IMU sample reached the estimator "
                f"(inputs accepted: {_counts(self.inputs)}; {self.ingest_dropped} dropped)"
            )
        if not self.not_ok:
            return ""
        parts = [
            f"{name} {count / self.estimates:.0%} ({health_text(name)})"
            for name, count in sorted(self.not_ok.items(), key=lambda kv: -kv[1])
        ]
        return "not ok for " + ", ".join(parts)


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in counts.items()) or "none"


def replay_log(
    path: str | Path,
    config: ServiceConfig,
    vehicle: VehicleProfile,
    out: TextIO,
    *,
    allow_truncated: bool = False,
) -> ReplaySummary:
    """Run the pipeline on a .tlog or .bin log and write the estimates CSV to ``out``.

    Raises
    ------
    InputError
        When the log is missing, truncated, of an unknown kind, or lacks IMU, attitude or
        motor-output messages from the configured flight controller (the message names them).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such log file")
    session = EstimationSession(config, vehicle, messages=False)  # only the CSV is read
    out.write(Publication.CSV_HEADER + "\n")
    suffix = path.suffix.lower()
    if suffix == ".tlog":
        # as live: each message at the time it was received (the clock checks), and samples
        # still in the reorder buffer at the end (only if the log shows reordering) are not
        # processed
        steps = _tlog_steps(session, path, allow_truncated)
    elif suffix in (".bin", ".log"):
        dataflash = DataflashSource(path, vehicle.n_motors, allow_truncated=allow_truncated)
        steps = (session.on_sample(sample) for sample in dataflash)
    else:
        raise InputError(
            f"{path}: unknown log kind {suffix!r}; "
            "expected a .tlog (MAVLink) or .bin (ArduPilot dataflash)"
        )
    first_s = last_s = math.nan
    published = 0
    for step in steps:
        if step.publication is not None:
            out.write(step.publication.csv_row() + "\n")
            published += 1
            last_s = step.publication.time_usec * 1e-6
            first_s = last_s if math.isnan(first_s) else first_s
    accepted = (
        dict(session.ingest.counters.accepted) if suffix == ".tlog" else dict(dataflash.counts)
    )
    _check_inputs(path, config, accepted, suffix)
    counters = session.publisher.counters
    return ReplaySummary(
        source=str(path),
        inputs=accepted,
        published=published,
        fc_time_span_s=(last_s - first_s) if published else 0.0,
        ingest_dropped=session.ingest.counters.dropped,
        estimates=counters.estimates,
        not_ok={k: v for k, v in counters.by_health.items() if k != OK and v > 0},
    )


def _check_inputs(path: Path, config: ServiceConfig, accepted: dict[str, int], suffix: str) -> None:
    missing = [kind for kind in _REQUIRED if accepted.get(kind, 0) == 0]
    if not missing:
        return
    if suffix == ".tlog":
        names = {**_COMMON_NAMES, **_MAVLINK_NAMES[config.link.autopilot]}
        who = f" from system {config.link.fc_system_id} component {config.link.fc_component_id}"
    else:
        names, who = _DATAFLASH_NAMES, ""
    found = ", ".join(f"{names[k]} x{accepted[k]}" for k in _REQUIRED if accepted.get(k, 0))
    raise InputError(
        f"{path}: lacks {', '.join(names[k] for k in missing)} messages{who} "
        f"(found: {found or 'none of the inputs'}); "
        "the estimator needs IMU, attitude and motor outputs"
    )


def _tlog_steps(session: EstimationSession, path: Path, allow_truncated: bool) -> Iterator[Step]:
    """The session's step for every message of a .tlog, each at the Unix time [s] it was
    recorded at (received, for what the service received): the flight controller's input
    streams straight from their frames
    (:class:`~tether_companion.service.ingest_frames.FrameIngest`), everything else through
    the frame parser and :meth:`EstimationSession.on_message`."""
    parser = FrameParser()
    frames = FrameIngest(session.ingest, parser)
    receive, on_received, on_message = frames.receive, session.on_received, session.on_message
    for stamp_us, frame in read_tlog(path, allow_truncated=allow_truncated):
        received_s = stamp_us * 1e-6
        samples = receive(frame, received_s)
        if samples is not None:
            yield on_received(samples)
            continue
        for msg in parser.feed(frame):
            yield on_message(msg, received_s)
        parser.end_datagram()


class DataflashSource:
    """Samples from an ArduPilot dataflash log: first IMU instance, ATT, RCOU, downward RFND.

    Parameters
    ----------
    path
        The ``.bin`` file.
    n_motors
        RCOU channels C1..Cn that are motors (vehicle profile).
    allow_truncated
        Replay a log whose last message is cut off instead of refusing it.

    Attributes
    ----------
    counts
        Samples read per input kind (filled while iterating).
    """

    def __init__(self, path: Path, n_motors: int, *, allow_truncated: bool = False) -> None:
        self.path = path
        self.n_motors = n_motors
        self.allow_truncated = allow_truncated
        self.counts = dict.fromkeys(_REQUIRED, 0)

    def __iter__(self) -> Iterator[Sample]:
        path = self.path
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise InputError(f"{path}: cannot read log file ({exc.strerror})") from None
        if not data:
            raise InputError(f"{path}: not a readable ArduPilot dataflash log (empty file)")
        reader = DataflashReader(data)
        counts = self.counts
        plans: dict[RecordFormat, tuple] = {}
        for fmt, values in reader.records({"IMU", "ATT", "RCOU", "RFND"}):
            plan = plans.get(fmt)
            if plan is None:
                plan = plans[fmt] = self._plan(fmt)
            kind, time_index, indexes, extra = plan
            time_s = values[time_index] * 1e-6
            if kind == "IMU":
                if extra is not None and values[extra] != 0:  # not the first IMU
                    continue
                gx, gy, gz, ax, ay, az = (values[i] for i in indexes)
                counts[IMU] += 1
                yield ImuSample(
                    time_s=time_s,
                    specific_force_body_mps2=np.array((ax, ay, az), dtype=float),
                    angular_rate_body_rad_s=np.array((gx, gy, gz), dtype=float),
                )
            elif kind == "ATT":
                roll, pitch, yaw = (values[i] for i in indexes)
                counts[ATTITUDE] += 1
                yield AttitudeSample(
                    time_s=time_s,
                    roll_rad=math.radians(roll),
                    pitch_rad=math.radians(pitch),
                    yaw_rad=wrap_pi(math.radians(yaw)),
                )
            elif kind == "RCOU":
                counts[PWM] += 1
                yield PwmSample(
                    time_s=time_s, pwm_us=np.array([values[i] for i in indexes], dtype=float)
                )
            elif extra is None or values[extra] == DATAFLASH_DOWNWARD:  # RFND
                yield RangeSample(time_s=time_s, distance_m=float(values[indexes[0]]))
        if sum(counts.values()) == 0 and reader.remaining > 0:
            raise InputError(
                f"{path}: not an ArduPilot dataflash log (no IMU, ATT or RCOU message "
                f"could be read from its {len(data)} bytes)"
            )
        if reader.remaining > 0 and not self.allow_truncated:
            raise InputError(
                f"{path}: truncated: the last {reader.remaining} bytes "
                "do not hold a complete message "
                "(use --allow-truncated to replay what is complete)"
            )

    def _plan(self, fmt: RecordFormat) -> tuple[str, int, list[int], int | None]:
        """(name, index of TimeUS, indexes of the values used, index of the instance or
        orientation column or None) of a record format.

        Raises
        ------
        InputError
            When a column the replay needs is missing.
        """
        wanted = {
            "IMU": ["GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"],
            "ATT": ["Roll", "Pitch", "Yaw"],
            "RCOU": [f"C{i + 1}" for i in range(self.n_motors)],
            "RFND": ["Dist"],
        }[fmt.name]
        missing = [c for c in ["TimeUS", *wanted] if c not in fmt.columns]
        if missing:
            if fmt.name == "RCOU":
                raise InputError(f"{self.path}: RCOU has fewer than {self.n_motors} channels")
            raise InputError(f"{self.path}: {fmt.name} lacks {', '.join(missing)}")
        extra = {"IMU": "I", "RFND": "Orient"}.get(fmt.name)
        return (
            fmt.name,
            fmt.columns["TimeUS"],
            [fmt.columns[c] for c in wanted],
            fmt.columns.get(extra) if extra is not None else None,
        )
