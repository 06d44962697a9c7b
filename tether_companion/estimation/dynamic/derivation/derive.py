"""Derive the dynamic tether filter's models and Jacobians with sympy; generate scalar Python.

Run ``python -m tether_companion.estimation.dynamic.derivation.derive`` to rewrite
``tether_companion/estimation/dynamic/generated.py`` (marked do-not-edit); a test regenerates
it and compares (PX4 EKF2's way). Only this script needs sympy (the ``test`` extra has it);
the filter imports the generated module.

The model (SI units, NED world, FRD body, ``R = R_v^b`` maps NED to body; state in
:mod:`..state`):

* Cable force on the drone, NED. Horizontal: ``-T_ch p_ne/|p|`` (toward the anchor; the
  catenary's horizontal tension is ``H = T_ch a/|p|`` with the span ``a = |p_ne|``, so ``T_ch``,
  state ``tension``, is the chord tension of the taut limit). Vertical (down), the exact
  catenary through the anchor and the drone with parameter ``c = H/w`` (``w`` weight per
  length), written with ``z = a/(2c) = w|p|/(2 T_ch)`` and the drone's height above the anchor
  ``b = -p_d`` so that nothing divides by the span (the drone may be right above the anchor):
  ``F_d = (T_ch/|p|) (sinh z sqrt(a^2 + (b z/sinh z)^2) + b z cosh z/sinh z)``; as ``w -> 0`` it
  tends to the straight line's ``T_ch b/|p|``. From the catenary ``y = c cosh((x - x0)/c)``
  through both ends: ``sinh((a - 2 x0)/(2c)) = b/(2c sinh z)`` gives ``x0``, and the vertical
  force at the drone is ``H sinh((a - x0)/c)``. Variants: ``*_straight`` (``w = 0``,
  the taut line) and ``*_catenary`` (``w > 0``); neither needs the cable's length: the two
  ends, the weight and the tension fix the curve. ``*_grounded``: where that free catenary
  would dip below the anchor's level (its lowest point between anchor and drone), a cable
  resting on that level (a winch on the ground) lies on it from the anchor to a touchdown
  point ``x_t = a - c acosh(1 + b/c)`` and rises from there as a catenary whose lowest point
  is the touchdown point: the force at the drone is ``H`` horizontally and the weight of the
  rising part, ``w sqrt(b^2 + 2 b c)``, down; the arc length is ``x_t + sqrt(b^2 + 2 b c)``;
  the cable leaves the anchor flat. Which one holds is a property of the state (``x_t > 0``:
  grounded), chosen in ``models.py``; at ``x_t = 0`` the two coincide.
* Rotor drag, body horizontal (ArduPilot's EK3_DRAG_MCOEF "momentum drag"):
  ``a_drag = -mu (R (v - w))_{x,y}`` with ``w = (w_n, w_e, 0)`` the wind, ``mu`` [1/s].
* Thrust ``s T`` along body ``-z`` (``T`` from the PWM through the thrust map, ``s`` state).
* Specific force, body: ``f = (0, 0, -s T/m) + a_drag + R F_c / m``; the accelerometer reads
  ``f + b`` (``b`` state, body).
* Formulation (a), force balance as the process: ``p' = v``,
  ``v' = R^T f + g e_d`` (``m a = T + F_c + F_drag + m g``); accelerometer as a measurement.
* Formulation (b), accelerometer as the input: ``p' = v``, ``v' = R^T (f_meas - b) + g e_d``;
  the force balance ``f_meas = f + b`` as the measurement (same function as (a)'s).
* Rangefinder: height above the ground ``-p_d + h_anchor``.
* Load cell at the drone: ``|F_c|``.
* The winch's load cell at the anchor: ``|F_c| - w b``. A catenary's tension is ``w`` times
  the height above its directrix, so it grows by ``w b`` from the anchor to the drone, and on
  the grounded cable ``|F_c| = H + w b`` exactly (``H^2 + w^2 (b^2 + 2 b c) = (H + w b)^2``)
  with ``H`` what the cable on the ground carries to the winch. (A drone below the anchor's
  level, ``b < 0``, takes the same expression: the models there are the straight chord's.)
* Winch paid-out length: the encoder reads ``offset + (1 + scale) L`` with ``L`` the
  catenary's arc length ``sqrt(b^2 + a^2 (sinh z / z)^2)`` (``|p|`` for the straight line) and
  the calibration states ``winch_offset``, ``winch_scale``.
* Ground-station cable angle: the cable leaves the anchor along
  ``t_a = (T_ch p_n/|p|, T_ch p_e/|p|, w L - F_d)`` (NED; ``L`` the arc length, the straight
  line's ``T_ch p/|p|`` at ``w = 0``): elevation ``atan2(-t_a_d, |t_a_ne|)`` [rad, up positive]
  and azimuth ``atan2(t_a_e, t_a_n)`` [rad from north], each read plus its zero error
  (the calibration states ``elevation_zero``, ``azimuth_zero``).

All other states are random walks or constants (derivative 0 here), but the wind: a
first-order Gauss-Markov process about calm, ``w' = -w / tau`` plus white noise
(``noise.wind_decay_per_s``). Its rate is linear with a constant coefficient and enters no
measurement model, so the predictions apply it (the inertial batch's transition
``exp(-T / tau)``, the force-balance member's Euler step) and the generated functions leave it
out (their Jacobians are those of the models above).
"""

from __future__ import annotations

import sys
from pathlib import Path

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import state
from tether_companion.estimation.dynamic.derivation import c_core

OUTPUT = Path(__file__).resolve().parent.parent / "generated.py"
OUTPUT_C = OUTPUT.with_name("generated_core.c")

X = sp.Matrix(sp.symbols(state.NAMES, real=True))
P = X[0:3, 0]
V = X[3:6, 0]
TCH = X[state.TENSION]
SCALE = X[state.SCALE]
B = X[state.BIAS, 0]
WIND = sp.Matrix([X[state.WIND.start], X[state.WIND.start + 1], 0])
WINCH_OFFSET, WINCH_SCALE = X[state.WINCH_OFFSET], X[state.WINCH_SCALE]
ELEVATION_ZERO, AZIMUTH_ZERO = X[state.ELEVATION_ZERO], X[state.AZIMUTH_ZERO]
N = state.N_STATES
N_CONSTANT = N - 6
"""States after position and velocity: zero derivative."""
R = sp.Matrix(3, 3, sp.symbols("r00 r01 r02 r10 r11 r12 r20 r21 r22", real=True))
THRUST = sp.Symbol("thrust_n", real=True)
F_MEAS = sp.Matrix(sp.symbols("f_x f_y f_z", real=True))
MASS, DRAG, WPL, ANCHOR_H = sp.symbols(
    "mass_kg drag_per_s weight_n_per_m anchor_height_m", real=True
)
G = sp.Float(GRAVITY_MPS2)
E_D = sp.Matrix([0, 0, 1])

CONSTANT_NAMES = ("mass_kg", "drag_per_s", "weight_n_per_m")
"""Order of the constants tuple ``c`` every generated model takes."""


def _norm(v: sp.Matrix) -> sp.Expr:
    return sp.sqrt(sum(e**2 for e in v))


NORM = _norm(P)
SPAN_SQ = P[0] ** 2 + P[1] ** 2
HEIGHT = -P[2]
Z = WPL * NORM / (2 * TCH)
"""Half the span over the catenary parameter, ``a / (2c)`` [1]."""


def _catenary_down_n() -> sp.Expr:
    """Down component of the catenary's force on the drone [N] (module docstring)."""
    shape = HEIGHT * Z / sp.sinh(Z)
    return TCH / NORM * (sp.sinh(Z) * sp.sqrt(SPAN_SQ + shape**2) + shape * sp.cosh(Z))


CATENARY_LENGTH = sp.sqrt(HEIGHT**2 + SPAN_SQ * (sp.sinh(Z) / Z) ** 2)
"""Arc length of the catenary between anchor and drone [m]."""

STRAIGHT, CATENARY, GROUNDED = "straight", "catenary", "grounded"
CABLES = (STRAIGHT, CATENARY, GROUNDED)
"""The cable variants (module docstring)."""

GROUNDED_PARAMETER = TCH * sp.sqrt(SPAN_SQ) / (NORM * WPL)
"""Catenary parameter ``c = H/w`` of the cable resting on the anchor's level [m]."""
GROUNDED_RISE = sp.sqrt(HEIGHT**2 + 2 * HEIGHT * GROUNDED_PARAMETER)
"""Arc length of the grounded cable's rising part, touchdown to drone [m]."""
GROUNDED_LENGTH = (
    sp.sqrt(SPAN_SQ)
    - GROUNDED_PARAMETER * sp.acosh(1 + HEIGHT / GROUNDED_PARAMETER)
    + GROUNDED_RISE
)
"""Arc length of the grounded cable, anchor to drone (the part on the ground included) [m]."""


def cable_force_ned(cable: str) -> sp.Matrix:
    """Force of the cable on the drone, NED [N], for one of :data:`CABLES`."""
    straight = -TCH * P / NORM
    if cable == STRAIGHT:
        return straight
    down = _catenary_down_n() if cable == CATENARY else WPL * GROUNDED_RISE
    return sp.Matrix([straight[0], straight[1], down])


def rotor_specific_force_body() -> sp.Matrix:
    """Thrust and rotor drag per unit mass, FRD body [m/s^2]."""
    air = R * (V - WIND)
    return sp.Matrix([-DRAG * air[0], -DRAG * air[1], -SCALE * THRUST / MASS])


def specific_force_body(cable: str) -> sp.Matrix:
    """Modelled specific force (no bias), FRD body [m/s^2]."""
    return rotor_specific_force_body() + R * cable_force_ned(cable) / MASS


def anchor_tangent_ned(cable: str) -> sp.Matrix:
    """Direction (unnormalised) in which the cable leaves the anchor, NED [N]."""
    force = cable_force_ned(cable)
    if cable == STRAIGHT:
        return -force
    if cable == GROUNDED:  # flat on the anchor's level, toward the drone
        return sp.Matrix([-force[0], -force[1], 0])
    return sp.Matrix([-force[0], -force[1], WPL * CATENARY_LENGTH - force[2]])


ARC_LENGTH = {STRAIGHT: NORM, CATENARY: CATENARY_LENGTH, GROUNDED: GROUNDED_LENGTH}


def models() -> list[tuple[str, str, list[sp.Symbol], list[sp.Expr], sp.Matrix | None, str]]:
    """``(name, doc, inputs, values, jacobian_wrt, returns)`` for each generated function."""
    out = []
    for suffix in CABLES:
        f_body = specific_force_body(suffix)
        # R^T R = I written out: m v' = R^T (thrust + drag) + F_c + m g
        vdot = R.T * rotor_specific_force_body() + cable_force_ned(suffix) / MASS + G * E_D
        out.append(
            (
                f"force_balance_{suffix}",
                "Formulation (a): ``x' = f(x, u)`` with ``u = (R_v^b row-major, thrust_n)``;"
                f" returns ``(x' ({N},), dv'/dx (3x{N} row-major))``.",
                [*R, THRUST],
                list(V) + list(vdot) + [0] * N_CONSTANT,
                vdot,
                "process",
            )
        )
        h = f_body + B
        out.append(
            (
                f"accel_{suffix}",
                "Accelerometer force balance ``h = f + b`` [m/s^2], FRD body, with"
                " ``u = (R_v^b row-major, thrust_n)``;"
                f" returns ``(h (3,), H (3x{N} row-major))``.",
                [*R, THRUST],
                list(h),
                h,
                "measurement",
            )
        )
        force = cable_force_ned(suffix)
        tension = _norm(force)
        out.append(
            (
                f"tension_{suffix}",
                f"Load cell at the drone: ``|F_c|`` [N]; returns ``(h (1,), H (1x{N}))``.",
                [],
                [tension],
                sp.Matrix([tension]),
                "measurement",
            )
        )
        at_anchor = tension - WPL * HEIGHT
        out.append(
            (
                f"anchor_tension_{suffix}",
                "Winch's load cell at the anchor: ``|F_c| - w b`` [N]; returns"
                f" ``(h (1,), H (1x{N}))``.",
                [],
                [at_anchor],
                sp.Matrix([at_anchor]),
                "measurement",
            )
        )
        tangent = anchor_tangent_ned(suffix)
        angles = sp.Matrix(
            [
                sp.atan2(-tangent[2], sp.sqrt(tangent[0] ** 2 + tangent[1] ** 2)) + ELEVATION_ZERO,
                sp.atan2(tangent[1], tangent[0]) + AZIMUTH_ZERO,
            ]
        )
        out.append(
            (
                f"cable_angle_{suffix}",
                "Ground-station cable angle as read: (elevation up, azimuth from north) plus"
                f" their zero errors [rad]; returns ``(h (2,), H (2x{N}))``.",
                [],
                list(angles),
                angles,
                "measurement",
            )
        )
    ins_vdot = R.T * (F_MEAS - B) + G * E_D
    out.append(
        (
            "inertial",
            "Formulation (b): ``x' = f(x, u)`` with ``u = (R_v^b row-major, f_x, f_y, f_z)``"
            f" (accelerometer as the input); returns ``(x' ({N},), dv'/dx (3x{N}))``.",
            [*R, *F_MEAS],
            list(V) + list(ins_vdot) + [0] * N_CONSTANT,
            ins_vdot,
            "process",
        )
    )
    for suffix, arc in ARC_LENGTH.items():
        reading = WINCH_OFFSET + (1 + WINCH_SCALE) * arc
        out.append(
            (
                f"winch_length_{suffix}",
                "Winch paid-out length as read: ``offset + (1 + scale)`` times the cable's"
                f" arc length [m]; returns ``(h (1,), H (1x{N}))``.",
                [],
                [reading],
                sp.Matrix([reading]),
                "measurement",
            )
        )
    height = -P[2] + ANCHOR_H
    out.append(
        (
            "height_above_ground",
            "Rangefinder: height above the ground ``-p_d + anchor_height_m`` [m] with"
            f" ``u = (anchor_height_m,)``; returns ``(h (1,), H (1x{N}))``.",
            [ANCHOR_H],
            [height],
            sp.Matrix([height]),
            "measurement",
        )
    )
    return out


class _Printer(PythonCodePrinter):
    def __init__(self) -> None:
        super().__init__({"standard": "python3", "fully_qualified_modules": True})


def _reduced(values, jac_of) -> tuple[list, list, int]:
    """The common subexpressions of the values and the Jacobian with respect to the state,
    the reduced values and Jacobian (one list), and the number of values."""
    jac = jac_of.jacobian(X) if jac_of is not None else sp.Matrix([])
    flat = [sp.sympify(e) for e in list(values) + list(jac)]
    replacements, reduced = sp.cse(flat, symbols=sp.numbered_symbols("t"), optimizations="basic")
    return replacements, [sp.sympify(e) for e in reduced], len(values)


def _function_source(name, doc, inputs, values, jac_of, kind) -> str:
    printer = _Printer()
    replacements, reduced, n_values = _reduced(values, jac_of)
    lines = [
        f"def {name}(x: Sequence[float], u: Sequence[float], c: Sequence[float])"
        " -> tuple[tuple[float, ...], tuple[float, ...]]:",
        f'    """{doc}"""',
        f"    {', '.join(state.NAMES)} = x",
    ]
    if inputs:
        names = ", ".join(str(s) for s in inputs)
        lines.append(f"    {names}{',' if len(inputs) == 1 else ''} = u")
    lines.append(f"    {', '.join(CONSTANT_NAMES)} = c")
    for sym, expr in replacements:
        lines.append(f"    {sym} = {printer.doprint(expr)}")
    vals = ", ".join(printer.doprint(e) for e in reduced[:n_values])
    jacs = ", ".join(printer.doprint(e) for e in reduced[n_values:])
    lines.append(f"    return ({vals},), ({jacs},)")
    return "\n".join(lines)


def _c_function_source(index, name, doc, inputs, values, jac_of, kind) -> str:
    replacements, reduced, n_values = _reduced(values, jac_of)
    arguments = [list(X), list(inputs), list(sp.symbols(CONSTANT_NAMES, real=True))]
    return c_core.function_source(
        index,
        name,
        arguments,
        replacements,
        reduced[:n_values],
        reduced[n_values:],
        c_core.CPrinter(_Printer()),
    )


HEADER = '''"""GENERATED by tether_companion/estimation/dynamic/derivation/derive.py -- DO NOT EDIT.

Regenerate with ``python -m tether_companion.estimation.dynamic.derivation.derive``; the
models and their meaning are documented there. sympy {version}.

Every function takes the state ``x`` ({n} floats, layout in ``state.py``), the inputs ``u``
and the constants ``c = (mass_kg, drag_per_s, weight_n_per_m)`` and returns the
values and the Jacobian with respect to ``x`` (row-major, {n} columns).
"""

# ruff: noqa
from __future__ import annotations

import math
from collections.abc import Sequence

from tether_companion.estimation import optional_core
'''

FOOTER = '''

PYTHON = (
    {names},
)
"""The functions above in Python: the reference, and what the C twins call where they could
differ (derivation/c_core.py)."""

CORE = None
"""The C extension when it runs (its ``batch_sums`` is ``imu_batch.batch_sums``'s twin)."""

COMPILED = False
"""Whether the names above are the C extension's twins (``{module}``, built by setup.py
where a compiler is; ``TETHER_PURE_PYTHON=1`` keeps the Python functions)."""

_core = optional_core.load("tether_companion.estimation.dynamic.{module}")
if _core is not None:
    _core.set_fallbacks(PYTHON)
    globals().update({{name: getattr(_core, name) for name in _core.NAMES}})
    COMPILED = True
    CORE = _core
'''


def generate_source() -> str:
    """The text of ``generated.py``."""
    parts = [HEADER.format(version=sp.__version__, n=N)]
    names = []
    for model in models():
        parts.append("\n\n" + _function_source(*model) + "\n")
        names.append(model[0])
    parts.append(FOOTER.format(module=c_core.CORE_MODULE, names=",\n    ".join(names)))
    return "".join(parts)


def generate_c_source() -> str:
    """The text of ``generated_core.c`` (the same models for the C extension)."""
    all_models = models()
    functions = [_c_function_source(i, *model) for i, model in enumerate(all_models)]
    inertial = next(m for m in all_models if m[0] == "inertial")
    batch = c_core.batch_source(N, state.BIAS.start, len(inertial[2]), len(CONSTANT_NAMES))
    return c_core.module_source(functions, [m[0] for m in all_models], sp.__version__, batch)


def main() -> int:
    """Write ``generated.py`` and ``generated_core.c``."""
    OUTPUT.write_text(generate_source())
    print(f"wrote {OUTPUT}")
    OUTPUT_C.write_text(generate_c_source())
    print(f"wrote {OUTPUT_C}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
