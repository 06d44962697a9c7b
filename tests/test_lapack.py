"""estimation.lapack's dpotrf/dpotrs are scipy.linalg.lapack's, bit for bit, loaded without
the scipy.linalg package (start-up of ``run``, issue 12)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from tether_companion.estimation import lapack


def _matrices(rng: np.random.Generator, count: int):
    for index in range(count):
        n = 1 + index % 17
        a = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-6, 6, size=n)
        spd = a @ a.T + (1e-9 if index % 5 else 0.0) * np.eye(n)
        if index % 7 == 0:
            spd[0, 0] = -abs(spd[0, 0])  # not positive definite: info > 0
        yield spd


def test_factor_and_solve_bit_equal_to_scipy_linalg() -> None:
    from scipy.linalg import lapack as reference

    rng = np.random.default_rng(19)
    not_pd = 0
    for spd in _matrices(rng, 400):
        for lower in (0, 1):
            mine = lapack.dpotrf(spd, lower=lower, clean=0)
            theirs = reference.dpotrf(spd, lower=lower, clean=0)
            assert mine[1] == theirs[1]
            assert mine[0].tobytes() == theirs[0].tobytes()
            if mine[1] != 0:
                not_pd += 1
                continue
            b = rng.normal(size=(spd.shape[0], 3))
            x_mine, info_mine = lapack.dpotrs(mine[0], b, lower=lower)
            x_theirs, info_theirs = reference.dpotrs(theirs[0], b, lower=lower)
            assert info_mine == info_theirs == 0
            assert x_mine.tobytes() == x_theirs.tobytes()
    assert not_pd > 0


def test_loaded_without_the_scipy_linalg_package_which_later_shares_it() -> None:
    script = (
        "import sys, json\n"
        "from tether_companion.estimation import lapack\n"
        "before = 'scipy.linalg' in sys.modules\n"
        "import numpy as np, scipy.linalg\n"
        "from scipy.linalg import lapack as reference\n"
        "a = np.array([[4.0, 2.0], [2.0, 3.0]])\n"
        "factor = scipy.linalg.cholesky(a, lower=True).tobytes()\n"
        "same = factor == lapack.dpotrf(a, lower=1)[0].tobytes()\n"
        "print(json.dumps([lapack._MODULE.__name__, before,"
        " reference.dpotrf is lapack.dpotrf, reference.dpotrs is lapack.dpotrs, same]))"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True
    )
    name, package_loaded, same_f, same_s, same_factor = json.loads(
        out.stdout.strip().splitlines()[-1]
    )
    assert name == "scipy.linalg._flapack"
    assert package_loaded is False
    assert same_f and same_s and same_factor


@pytest.mark.parametrize("name", ["dpotrf", "dpotrs"])
def test_the_filters_use_these_functions(name: str) -> None:
    from tether_companion.estimation import ekf
    from tether_companion.estimation.dynamic import bank_arrays

    assert getattr(ekf, name) is getattr(lapack, name)
    if name == "dpotrf":
        assert bank_arrays.dpotrf is lapack.dpotrf
