"""The project's optional C extensions in tests: import one, fail where it should be there.

Each extension is optional (``setup.py``: ``optional=True``; without a compiler the pure-Python
reference runs). A test file of an extension imports it through :func:`import_extension`: its
absence fails the file where it could have been built (a C compiler and the Python headers
here: ``pip install -e .`` builds it, as CI's install does) or with ``TETHER_REQUIRE_CORE=1``,
so a broken build cannot pass silently; the file is skipped, with the reason, only where the
extension could not be built.
"""

from __future__ import annotations

import importlib
import os
import shutil
import sysconfig
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
