"""The CLI imports a command's subsystem only when that command runs (issue 12).

Checked on ``sys.modules`` of a fresh interpreter (never on time: the machine is shared).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tether_companion.cli import COMMANDS, build_parser
from tether_companion.commands.bench import BENCHMARKS
from tether_companion.commands.lazy import help_line, selected

HEAVY_FOR_HELP = ("numpy", "scipy", "pymavlink", "rich", "matplotlib")
HEAVY_FOR_RUN = (
    "scipy.linalg",  # the filters' dpotrf/dpotrs come from estimation.lapack
    "scipy.special",  # imported at the first chi-square gate (aid_status.chi2_threshold)
    "scipy._lib._array_api",
    "numpy.f2py",
    "scipy.stats",
    "scipy.signal",
    "scipy.optimize",
    "matplotlib",
    "rich",
    "filterpy",
    "tether_companion.sysid.identify",
    "tether_companion.sim.simulator",
    "tether_companion.emulator.server",
    "tether_companion.bench.speed",
)


def _modules_after(code: str) -> set[str]:
    """The module names loaded by a fresh interpreter after running ``code``."""
    script = f"import sys, json\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def _loaded(modules: set[str], names: tuple[str, ...]) -> list[str]:
    return [name for name in names if name in modules]


def test_help_imports_no_subsystem() -> None:
    code = (
        "import contextlib, io\n"
        "from tether_companion.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    main(['--help'])\n"
    )
    modules = _modules_after(code)
    assert _loaded(modules, HEAVY_FOR_HELP) == []
    assert not any(m.startswith("tether_companion.service") for m in modules)


def test_run_parser_imports_only_the_service() -> None:
    modules = _modules_after("from tether_companion.cli import build_parser\nbuild_parser(['run'])")
    assert "tether_companion.service.app" in modules
    assert _loaded(modules, HEAVY_FOR_RUN) == []


def test_bench_imports_only_the_benchmark_named() -> None:
    modules = _modules_after(
        "from tether_companion.cli import build_parser\nbuild_parser(['bench', 'latency'])"
    )
    assert "tether_companion.bench.latency" in modules
    others = [f"tether_companion.bench.{name}" for name in BENCHMARKS if name != "latency"]
    assert _loaded(modules, tuple(others)) == []


def test_help_lines_read_from_source_equal_the_modules_help() -> None:
    import importlib

    for package, names in (("commands", COMMANDS), ("bench", BENCHMARKS)):
        for name in names:
            module_name = f"tether_companion.{package}.{name}"
            assert help_line(module_name) == importlib.import_module(module_name).HELP


def test_selected_command() -> None:
    assert selected(["--version"], COMMANDS) is None
    assert selected(["replay", "x.tlog"], COMMANDS) == "replay"
    assert selected(["nonesuch", "run"], COMMANDS) is None
    with pytest.raises(LookupError):
        help_line("tether_companion.commands")  # a package without a HELP literal


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_parses_its_help(name: str, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        build_parser([name, "--help"]).parse_args([name, "--help"])
    assert exit_info.value.code == 0
    assert "usage: tether-companion" in capsys.readouterr().out
