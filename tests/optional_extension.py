"""The project's optional C extensions in tests: import one, fail where it should be there.

Each extension is optional (``setup.py``: ``optional=True``; without a compiler the pure-Python
reference runs). A test file of an extension imports it through :func:`import_extension`: its
absence fails the file where it could have been built (a C compiler and the Python headers
here: ``pip install -e .`` builds it, as CI's install does) or with ``TETHER_REQUIRE_CORE=1``,
so a broken build cannot pass silently; the file is skipped, with the reason, only where the
extension could not be built.
"""

from __future__ import annotations

import functools
import importlib
import os
import shutil
import struct
import sysconfig
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType

import pytest


def could_build() -> bool:
    """Whether this interpreter's C compiler and headers are here (then the install builds
    the extensions)."""
    compiler = (sysconfig.get_config_var("CC") or "").split()
    headers = Path(sysconfig.get_paths()["include"], "Python.h")
    return bool(compiler) and shutil.which(compiler[0]) is not None and headers.is_file()


def import_extension(module: str) -> tuple[ModuleType | None, pytest.MarkDecorator]:
    """The extension ``module`` (dotted name) or ``None``, and the calling file's
    ``pytestmark`` (skip with the reason when it is ``None``); fails the calling file's
    collection when the extension is missing but could have been built."""
    name = module.rsplit(".", 1)[-1]
    try:
        core: ModuleType | None = importlib.import_module(module)
    except ImportError:  # depends on the install
        core = None
    if core is None and (os.environ.get("TETHER_REQUIRE_CORE") == "1" or could_build()):
        pytest.fail(
            f"the C extension {name} is not built although a C compiler and the Python "
            "headers are here: `python3 -m pip install -e .` builds it",
            pytrace=False,
        )
    return core, pytest.mark.skipif(
        core is None, reason=f"the C extension {name} is not built (no C compiler here)"
    )


@contextmanager
def recording_c_calls(
    owner: ModuleType,
    name: str,
    c_function: Callable,
    python_function: Callable,
    bound: tuple = (),
) -> Iterator[tuple[list[tuple], list[tuple]]]:
    """For the block, ``owner.<name>`` (the package's ``functools.partial(c_function,
    python_function, *bound)``: C with its Python fallback and the objects it is bound to)
    records every call's arguments and every fallback the C took to Python; yields ``(calls,
    fallbacks)``. Checks afterwards that the
    name was bound to ``c_function`` (so the flight ran C, not Python alone); skips where
    ``TETHER_PURE_PYTHON`` is set (the package then runs the Python alone, by request)."""
    if os.environ.get("TETHER_PURE_PYTHON"):
        pytest.skip("TETHER_PURE_PYTHON is set: the package runs the Python alone")
    calls: list[tuple] = []
    fallbacks: list[tuple] = []

    def fallback(*args: object) -> object:
        fallbacks.append(args)
        return python_function(*args)

    def recorded(*args: object) -> object:
        calls.append(args)
        return c_function(fallback, *bound, *args)

    saved = getattr(owner, name)
    setattr(owner, name, recorded)
    try:
        yield calls, fallbacks
    finally:
        setattr(owner, name, saved)
    assert isinstance(saved, functools.partial) and saved.func is c_function


def float_bits(values: object) -> object:
    """Nested lists/tuples of floats by their bit patterns (-0.0 != 0.0, NaNs compare), and
    the containers' types: what a C twin's result must equal its Python reference's in."""
    if isinstance(values, (list, tuple)):
        return [type(values).__name__, [float_bits(v) for v in values]]
    if isinstance(values, float):
        return struct.pack("<d", values)
    return (type(values).__name__, values)
