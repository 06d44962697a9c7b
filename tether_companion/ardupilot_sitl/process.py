"""Start and stop ArduCopter SITL on loopback, in its own temporary directory.

The binary is a test fixture beside the project: ``<repo>/../shared/ardupilot-sitl/arducopter``
(CI checks the repository out beside ``shared/``), or wherever ``TETHER_SITL_DIR`` points.
Every wait is bounded; the process group is always killed on the way out.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from tether_companion.resources import PROJECT_ROOT

SITL_DIR_ENV = "TETHER_SITL_DIR"
"""Environment variable naming the folder that holds ``arducopter`` and its .parm files."""
DEFAULT_SITL_DIR = PROJECT_ROOT.parent / "shared" / "ardupilot-sitl"
OUR_PARAMS = PROJECT_ROOT / "sitl" / "ardupilot" / "tether-companion.parm"
SHIPPED_PARAMS = ("copter.parm", "tether.parm", "extnav.parm")
BASE_TCP_PORT = 5760
"""SERIAL0 of instance 0; SERIAL1 is +2, SERIAL2 +3; instance N moves every port by 10 N."""
BASE_UDP_PORT = 5501
"""The simulator's own UDP input port of instance 0 (bound even for the built-in models)."""
MAX_INSTANCE = 60
HOME = (-35.363261, 149.165230, 584.0, 0.0)
"""Default home and tether anchor (lat [deg], lon [deg], alt AMSL [m], yaw [deg]): ArduPilot's
CMAC test field; the '+' frame's reference altitude (593 m) is close, so its thrust map holds."""


class SitlUnavailable(RuntimeError):
    """SITL cannot be used here (binary or parameter file missing): tests skip with this text."""


class SitlFailed(RuntimeError):
    """SITL was found but did not start or stopped early (its output's tail is in the text)."""


def sitl_dir() -> Path:
    """The folder holding ``arducopter`` (``TETHER_SITL_DIR`` or ``<repo>/../shared/...``)."""
    return Path(os.environ.get(SITL_DIR_ENV) or DEFAULT_SITL_DIR)


def find_sitl() -> tuple[Path, list[Path]]:
    """The binary and the ``--defaults`` files in order; SitlUnavailable says what is missing."""
    folder = sitl_dir()
    binary = folder / "arducopter"
    if not binary.is_file() or not os.access(binary, os.X_OK):
        raise SitlUnavailable(
            f"ArduPilot SITL not found: no executable {binary} (set {SITL_DIR_ENV} to the "
            "folder holding arducopter and its .parm files)"
        )
    params = [folder / name for name in SHIPPED_PARAMS] + [OUR_PARAMS]
    missing = [str(p) for p in params if not p.is_file()]
    if missing:
        raise SitlUnavailable(f"ArduPilot SITL parameter files missing: {', '.join(missing)}")
    return binary, params


def ports_of(instance: int) -> dict[str, int]:
    """The ports instance ``instance`` uses (TCP serial0/1/2, UDP sim input)."""
    shift = 10 * instance
    return {
        "serial0": BASE_TCP_PORT + shift,
        "serial1": BASE_TCP_PORT + 2 + shift,
        "serial2": BASE_TCP_PORT + 3 + shift,
        "sim_udp": BASE_UDP_PORT + shift,
    }


def _port_free(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as sock:
        if kind == socket.SOCK_STREAM:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("0.0.0.0", port))  # SITL binds every interface
        except OSError:
            return False
    return True


def instance_free(instance: int) -> bool:
    """True when none of the instance's ports is bound by anyone."""
    ports = ports_of(instance)
    tcp = all(_port_free(ports[k], socket.SOCK_STREAM) for k in ("serial0", "serial1", "serial2"))
    return tcp and _port_free(ports["sim_udp"], socket.SOCK_DGRAM)


def free_instance(start: int = 1) -> int:
    """The first instance >= ``start`` whose ports are all free (SitlFailed when none is)."""
    for instance in range(start, MAX_INSTANCE + 1):
        if instance_free(instance):
            return instance
    raise SitlFailed(f"no free SITL instance in {start}..{MAX_INSTANCE} (all port ranges in use)")


@dataclass
class SitlOptions:
    """How to start SITL."""

    speedup: float = 1.0
    """SIM_SPEEDUP: the flight code's clock runs this many times faster than the wall clock."""
    model: str = "+"
    home: tuple[float, float, float, float] = HOME
    extra_params: dict[str, float] = field(default_factory=dict)
    """Written to a last ``--defaults`` file (e.g. {"GPS1_TYPE": 0})."""
    instance: int | None = None
    """-I N; None: the first free one."""
    start_timeout_s: float = 20.0
    keep_dir: bool = False


class SitlProcess:
    """One running ArduCopter SITL (use as a context manager; it is always stopped).

    ``ports["serial0"]`` waits for the first TCP client before the flight code starts; the
    ground-station client connects there, the companion on ``ports["serial1"]``.
    """

    def __init__(self, options: SitlOptions | None = None) -> None:
        self.options = options or SitlOptions()
        self.binary, self.param_files = find_sitl()
        self.instance = -1
        self.ports: dict[str, int] = {}
        self.workdir: Path | None = None
        self.process: subprocess.Popen[bytes] | None = None
        self._log_path: Path | None = None

    def __enter__(self) -> SitlProcess:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def start(self) -> None:
        """Start the process and wait (bounded) until SERIAL0 listens."""
        opts = self.options
        if opts.instance is None:
            self.instance = free_instance()
        else:
            if not instance_free(opts.instance):
                raise SitlFailed(
                    f"SITL instance {opts.instance}: a port of {ports_of(opts.instance)} is in use"
                )
            self.instance = opts.instance
        self.ports = ports_of(self.instance)
        self.workdir = Path(tempfile.mkdtemp(prefix=f"sitl-I{self.instance}-"))
        defaults = list(self.param_files)
        if opts.extra_params:
            extra = self.workdir / "extra.parm"
            extra.write_text("".join(f"{k} {float(v)!r}\n" for k, v in opts.extra_params.items()))
            defaults.append(extra)
        home = ",".join(repr(float(v)) for v in opts.home)
        command = [
            str(self.binary),
            "--model", opts.model,
            "--speedup", f"{opts.speedup:g}",
            f"-I{self.instance}",
            "-w",
            "--home", home,
            "--defaults", ",".join(str(p) for p in defaults),
        ]  # fmt: skip
        self._log_path = self.workdir / "sitl.out"
        with open(self._log_path, "wb") as log:
            self.process = subprocess.Popen(
                command,
                cwd=self.workdir,
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # its own process group: killed as one
            )
        self._wait_listening(opts.start_timeout_s)

    def _wait_listening(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        port = self.ports["serial0"]
        while time.monotonic() < deadline:
            if self.process is not None and self.process.poll() is not None:
                raise SitlFailed(
                    f"SITL exited with code {self.process.returncode} before listening on "
                    f"tcp {port}: {self.output_tail()}"
                )
            if f"SERIAL0 on TCP port {port}" in self.output():
                return
            time.sleep(0.05)
        raise SitlFailed(
            f"SITL did not listen on tcp {port} within {timeout_s:g} s: {self.output_tail()}"
        )

    def output(self) -> str:
        """Everything SITL printed so far."""
        if self._log_path is None or not self._log_path.is_file():
            return ""
        return self._log_path.read_text(errors="replace")

    def output_tail(self, lines: int = 8) -> str:
        """The last lines SITL printed, on one line."""
        return " | ".join(self.output().strip().splitlines()[-lines:]) or "(no output)"

    def alive(self) -> bool:
        """True while the process runs."""
        return self.process is not None and self.process.poll() is None

    def stop(self) -> None:
        """SIGTERM then SIGKILL to the whole process group (bounded), and remove the folder."""
        proc = self.process
        if proc is not None and proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5.0)
        if self.workdir is not None and not self.options.keep_dir:
            shutil.rmtree(self.workdir, ignore_errors=True)
