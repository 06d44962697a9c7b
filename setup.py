"""The optional C extensions (everything else is in pyproject.toml): the dynamic filter's
generated models, the tension filter's generated predict/update (``tension_core.c``), the
published bound approximation's step (``bound_core.c``), the published covariance's added
terms and the status decision (``status_core.c`` with ``status_decide.c``,
``published_terms.ADDED_POSITION_TERMS``, ``observability.DECIDE``: bit for bit) and the dynamic filter's members'
matrix arithmetic (``member_core.c``: numpy's to 1e-12, not bit for bit;
``imu_batch.MEMBER_CORE``) with the bank's force-balance and scalar fusions over its members in
one call each (``bank_fusion.c``, ``bank_updates.FUSE_FORCE_BALANCE`` / ``FUSE_SCALAR``: bit for bit
the bank's Python on those), and the flight controller's input frames' test and field read
(``service/frame_core.c`` with ``frame_reader.c`` and ``frame_wire.h``,
``ingest_frames.FrameIngest``: its samples bit for bit) with the ingest's clock gate, reorder
buffer and order check (``service/ingest_core.c``, ``Ingest.core``: bit for bit).

``tether_companion/estimation/dynamic/generated_core.c`` is written by the derivation
(``python -m tether_companion.estimation.dynamic.derivation.derive``) next to the Python
``generated.py``, which stays the reference and the fallback: without a C compiler the build
skips the extension (``optional=True``) and the package runs the Python functions. The flags
keep every C function's floats bit for bit the Python function's (derivation/c_core.py): no
fused multiply-add (GCC's default on ARM) and libm's ``pow`` (as CPython's ``**``) kept.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "tether_companion.estimation.dynamic._generated_core",
            ["tether_companion/estimation/dynamic/generated_core.c"],
            extra_compile_args=["-ffp-contract=off", "-fno-builtin-pow"],
            optional=True,
        ),
        Extension(
            "tether_companion.estimation._tension_core",
            ["tether_companion/estimation/tension_core.c"],
            depends=["tether_companion/estimation/exact_floats.h"],
            extra_compile_args=["-ffp-contract=off"],
            optional=True,
        ),
        Extension(
            "tether_companion.estimation.dynamic._bound_core",
            ["tether_companion/estimation/dynamic/bound_core.c"],
            depends=["tether_companion/estimation/dynamic/straight_rows.h"],
            extra_compile_args=["-ffp-contract=off", "-fno-builtin-pow"],
            optional=True,
        ),
        Extension(
            "tether_companion.estimation.dynamic._status_core",
            [
                "tether_companion/estimation/dynamic/status_core.c",
                "tether_companion/estimation/dynamic/status_decide.c",
            ],
            depends=[
                "tether_companion/estimation/dynamic/status_core.h",
                "tether_companion/estimation/dynamic/straight_rows.h",
            ],
            extra_compile_args=["-ffp-contract=off", "-fno-builtin-pow"],
            optional=True,
        ),
        Extension(
            "tether_companion.estimation.dynamic._member_core",
            [
                "tether_companion/estimation/dynamic/member_core.c",
                "tether_companion/estimation/dynamic/bank_fusion.c",
                "tether_companion/estimation/dynamic/bank_health.c",
                "tether_companion/estimation/dynamic/bank_mixture.c",
                "tether_companion/estimation/dynamic/bank_predict.c",
            ],
            depends=[
                "tether_companion/estimation/exact_floats.h",
                "tether_companion/estimation/dynamic/member_core.h",
            ],
            extra_compile_args=["-ffp-contract=off"],
            optional=True,
        ),
        Extension(
            "tether_companion.service._frame_core",
            [
                "tether_companion/service/frame_core.c",
                "tether_companion/service/frame_reader.c",
                "tether_companion/service/ingest_core.c",
                "tether_companion/service/ingest_clock.c",
                "tether_companion/service/ingest_reorder.c",
            ],
            depends=[
                "tether_companion/service/frame_wire.h",
                "tether_companion/service/ingest_core.h",
            ],
            extra_compile_args=["-ffp-contract=off"],
            optional=True,
        ),
    ]
)
