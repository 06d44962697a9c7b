"""LAPACK's Cholesky factorisation and solve (``dpotrf``, ``dpotrs``) for the filters, without
importing the ``scipy.linalg`` package.

The functions ARE scipy's: the same f2py wrappers of the same LAPACK build, taken from
``scipy.linalg._flapack`` (what ``scipy.linalg.lapack.dpotrf`` is), so every factor and solve is
bit for bit what ``from scipy.linalg.lapack import dpotrf`` gives. Importing the package
``scipy.linalg`` costs ~0.17 s of ``run``'s start-up on an idle 2-core machine (its
``_cythonized_array_utils`` pulls scipy's array-API layer, which loads ``numpy.f2py``,
``numpy.testing``, ``numpy.random`` ...); loading the one extension module file costs ~0.02 s.
numpy's own Cholesky is a different build and differs in the last bit on ~13 % of matrices, so
it is not a substitute.

When ``scipy.linalg`` is already imported, or the module file cannot be loaded on its own (a
scipy laid out differently), the package's functions are used.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from types import ModuleType


def _flapack() -> ModuleType:
    """``scipy.linalg._flapack``, loaded from its file without running ``scipy.linalg``'s
    ``__init__`` (CPython registers the extension under its full name, so a later
    ``import scipy.linalg`` finds it in ``sys.modules`` and uses the same functions)."""
    name = "scipy.linalg._flapack"
    loaded = sys.modules.get(name)
    if loaded is not None:
        return loaded
    try:
        package = importlib.util.find_spec("scipy.linalg")  # imports only the light ``scipy``
        locations = package.submodule_search_locations if package is not None else None
        for directory in locations or ():
            finder = importlib.machinery.FileFinder(
                directory,
                (importlib.machinery.ExtensionFileLoader, importlib.machinery.EXTENSION_SUFFIXES),
            )
            spec = finder.find_spec(name)
            if spec is not None and spec.loader is not None:
                module = importlib.util.module_from_spec(spec)
                spec.loader.exec_module(module)
                return module
    except ImportError:
        pass
    from scipy.linalg import _flapack  # the package after all

    return _flapack


_MODULE = _flapack()
dpotrf = _MODULE.dpotrf
"""LAPACK ``dpotrf`` (f2py): ``dpotrf(a, lower=0, clean=1) -> (c, info)``."""
dpotrs = _MODULE.dpotrs
"""LAPACK ``dpotrs`` (f2py): ``dpotrs(c, b, lower=0) -> (x, info)``."""
