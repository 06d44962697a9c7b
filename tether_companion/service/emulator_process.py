"""``tether-companion emulate`` as a child process on a free loopback UDP port.

The demo and the end-to-end tests run the emulator in its own process, as a flight controller
is its own computer: it paces itself in real time (or ``--speed`` times faster) without sharing
an event loop or a core with the service under test.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import sys
from pathlib import Path

from tether_companion.resources import PROJECT_ROOT

_BOUND = re.compile(r"\(bound ([0-9.]+):(\d+)\)")
START_TIMEOUT_S = 30.0


class EmulatorProcess:
    """Start the emulator listening on ``udp:127.0.0.1:0`` and learn its port.

    Parameters
    ----------
    scenario
        Built-in scenario name or YAML path.
    duration_s
        Emulator seconds to run before it exits by itself and writes its score.
    score_path
        Where the emulator writes its score (JSON).
    speed
        Emulator seconds per wall second.
    extra_args
        More ``emulate`` flags (``--seed``, ``--nav vision``, faults, ...).

    Use as ``async with EmulatorProcess(...) as emu: ... await emu.wait()``; leaving the block
    stops a still-running emulator (SIGTERM, then SIGKILL).
    """

    def __init__(
        self,
        scenario: str,
        *,
        duration_s: float,
        score_path: Path,
        speed: float = 1.0,
        extra_args: tuple[str, ...] = (),
    ) -> None:
        self.args = [
            sys.executable, "-m", "tether_companion.cli", "emulate", scenario,
            "--listen", "udp:127.0.0.1:0", "--speed", repr(speed), "--duration", repr(duration_s),
            "--score-out", str(score_path), "--quiet", *extra_args,
        ]  # fmt: skip
        self.score_path = score_path
        self.port: int | None = None
        """The first endpoint's port (the ``--listen udp:127.0.0.1:0`` this class adds)."""
        self.ports: list[int] = []
        """Every endpoint's port, in the order given (more ``--listen`` in ``extra_args``)."""
        self.output: list[str] = []
        self._process: asyncio.subprocess.Process | None = None
        self._reader: asyncio.Task[None] | None = None

    async def __aenter__(self) -> EmulatorProcess:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            filter(None, (str(PROJECT_ROOT), env.get("PYTHONPATH")))
        )
        self._process = await asyncio.create_subprocess_exec(
            *self.args, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.STDOUT, env=env
        )
        try:
            await asyncio.wait_for(self._read_until_bound(), timeout=START_TIMEOUT_S)
        except BaseException:
            await self.stop()
            raise
        self._reader = asyncio.create_task(self._read_rest(), name="emulator-output")
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.stop()

    async def _read_until_bound(self) -> None:
        assert self._process is not None and self._process.stdout is not None
        while True:
            line = await self._process.stdout.readline()
            if not line:
                raise RuntimeError("the emulator exited before listening:\n" + "".join(self.output))
            text = line.decode(errors="replace")
            self.output.append(text)
            match = _BOUND.search(text)
            if match:
                self.ports.append(int(match.group(2)))
                self.port = self.ports[0]
            elif self.ports:  # the line after the endpoints': all of them are bound
                return

    async def _read_rest(self) -> None:
        assert self._process is not None and self._process.stdout is not None
        while line := await self._process.stdout.readline():
            self.output.append(line.decode(errors="replace"))

    async def wait(self) -> int:
        """Wait for the emulator to finish its duration; returns its exit code."""
        assert self._process is not None
        code = await self._process.wait()
        if self._reader is not None:
            await self._reader
        return code

    def score(self) -> dict:
        """The score the emulator wrote (after :meth:`wait`)."""
        return json.loads(self.score_path.read_text(encoding="utf-8"))

    async def stop(self) -> None:
        """Terminate the emulator if it still runs; idempotent."""
        process = self._process
        if process is not None and process.returncode is None:
            process.terminate()
            try:
                await asyncio.wait_for(process.wait(), timeout=5.0)
            except asyncio.TimeoutError:
                process.kill()
                await process.wait()
        if self._reader is not None:
            self._reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._reader
