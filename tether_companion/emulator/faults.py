"""Link faults on what the emulator sends: drop, duplicate, corrupt, delay (pure, seeded).

Flight-controller faults (stream outages, reboots, rangefinder out of range) are time windows
of :class:`~tether_companion.emulator.config.FaultConfig` handled by the flight controller
itself; this module only decides what happens to each outgoing frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class LinkFaultSettings:
    """Current link-fault levels (changeable at run time through EMU_* parameters)."""

    drop_probability: float = 0.0
    duplicate_probability: float = 0.0
    corrupt_probability: float = 0.0
    delay_s: float = 0.0
    delay_jitter_s: float = 0.0

    @property
    def active(self) -> bool:
        """True when any fault is switched on."""
        return bool(
            self.drop_probability
            or self.duplicate_probability
            or self.corrupt_probability
            or self.delay_s
            or self.delay_jitter_s
        )


@dataclass
class LinkFaultCounters:
    """Frames the fault injector dropped, duplicated, corrupted or delayed."""

    dropped: int = 0
    duplicated: int = 0
    corrupted: int = 0
    delayed: int = 0


class LinkFaults:
    """Decides the fate of each outgoing frame.

    Parameters
    ----------
    settings
        Fault levels; read on every frame, so changing them takes effect at once.
    rng
        Source of all randomness (the same seed gives the same faults).
    """

    def __init__(self, settings: LinkFaultSettings, rng: np.random.Generator) -> None:
        self.settings = settings
        self.counters = LinkFaultCounters()
        self._rng = rng

    def apply(self, frame: bytes) -> list[tuple[float, bytes]]:
        """The copies of ``frame`` to send, each as (delay [s, emulator time], bytes).

        An empty list means the frame is dropped. A corrupted copy has one byte after the
        start marker XOR-ed with a random non-zero value, so it fails its checksum (or its
        framing) at the receiver.
        """
        s = self.settings
        if not s.active:
            return [(0.0, frame)]
        rng = self._rng
        if s.drop_probability and rng.random() < s.drop_probability:
            self.counters.dropped += 1
            return []
        copies = 2 if s.duplicate_probability and rng.random() < s.duplicate_probability else 1
        if copies == 2:
            self.counters.duplicated += 1
        out = []
        for _ in range(copies):
            data = frame
            if s.corrupt_probability and rng.random() < s.corrupt_probability:
                broken = bytearray(frame)
                broken[int(rng.integers(1, len(frame)))] ^= int(rng.integers(1, 256))
                data = bytes(broken)
                self.counters.corrupted += 1
            delay = s.delay_s + (s.delay_jitter_s * rng.random() if s.delay_jitter_s else 0.0)
            if delay > 0.0:
                self.counters.delayed += 1
            out.append((delay, data))
        return out
