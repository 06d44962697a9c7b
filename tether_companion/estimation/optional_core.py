"""The project's optional C extensions, loaded in one place.

Each extension (``setup.py``, ``optional=True``) is a faster twin of pure-Python code that stays
the reference and the fallback: built where a C compiler is, absent elsewhere, and not used when
the environment sets ``TETHER_PURE_PYTHON`` (to run or measure the reference).
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType


def load(module: str) -> ModuleType | None:
    """The extension ``module`` (dotted name), or ``None`` where it is not built or
    ``TETHER_PURE_PYTHON`` is set."""
    if os.environ.get("TETHER_PURE_PYTHON"):
        return None
    try:
        return importlib.import_module(module)
    except ImportError:  # not built here (no compiler at install time)
        return None
