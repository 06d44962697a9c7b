"""Derive the dynamic tether filter's models and Jacobians with sympy; generate scalar Python.

Run ``python -m tether_companion.estimation.dynamic.derivation.derive`` to rewrite
``tether_companion/estimation/dynamic/generated.py`` (marked do-not-edit); a test regenerates
it and compares (PX4 EKF2's way). Only this script needs sympy (the ``test`` extra has it);
the filter imports the generated module.

The model (SI units, NED world, FRD body, ``R = R_v^b`` maps NED to body; state in
:mod:`..state`):

* Cable force on the drone, NED: ``F_c = -T_ch p/|p| + (w L / 2) e_d``. The chord term
  ``T_ch`` (state ``tension``) pulls toward the anchor; a cable of weight ``w`` per length and
  length ``L`` hanging between anchor and drone adds half its weight at the drone (moment
  balance about the anchor with the cable's centre of mass half-way along the span, exact for
  the parabola and the small-sag catenary, the straight line at ``w = 0``: the taut limit).
  ``L`` is the winch's paid-out length when one is reported (``*_known_length`` functions, an
  input), otherwise the chord ``|p|`` (``*_chord_length``, differentiated through ``p``).
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
* Winch paid-out length: the arc length, to first order in the sag,
  ``|p| + w^2 (p_n^2 + p_e^2) |p| / (24 T_ch^2)`` (parabola; ``|p|`` at ``w = 0``).
* Ground-station cable angle: the cable leaves the anchor along
  ``t_a = T_ch p/|p| + (w L / 2) e_d``: elevation ``atan2(-t_a_d, |t_a_ne|)`` [rad, up
  positive] and azimuth ``atan2(t_a_e, t_a_n)`` [rad from north].

All other states are random walks (derivative 0).
"""

from __future__ import annotations

import sys
from pathlib import Path

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from tether_companion.constants import GRAVITY_MPS2
from tether_companion.estimation.dynamic import state

OUTPUT = Path(__file__).resolve().parent.parent / "generated.py"

X = sp.Matrix(sp.symbols(state.NAMES, real=True))
P = X[0:3, 0]
V = X[3:6, 0]
TCH = X[state.TENSION]
SCALE = X[state.SCALE]
B = X[8:11, 0]
WIND = sp.Matrix([X[11], X[12], 0])
R = sp.Matrix(3, 3, sp.symbols("r00 r01 r02 r10 r11 r12 r20 r21 r22", real=True))
THRUST = sp.Symbol("thrust_n", real=True)
F_MEAS = sp.Matrix(sp.symbols("f_x f_y f_z", real=True))
MASS, DRAG, WPL, LENGTH, ANCHOR_H = sp.symbols(
    "mass_kg drag_per_s weight_n_per_m length_m anchor_height_m", real=True
)
G = sp.Float(GRAVITY_MPS2)
E_D = sp.Matrix([0, 0, 1])

CONSTANT_NAMES = ("mass_kg", "drag_per_s", "weight_n_per_m", "length_m")
"""Order of the constants tuple ``c`` every generated model takes."""


def _norm(v: sp.Matrix) -> sp.Expr:
    return sp.sqrt(sum(e**2 for e in v))


def cable_force_ned(length: sp.Expr) -> sp.Matrix:
    """Force of the cable on the drone, NED [N], for a cable of length ``length``."""
    return -TCH * P / _norm(P) + (WPL * length / 2) * E_D


def rotor_specific_force_body() -> sp.Matrix:
    """Thrust and rotor drag per unit mass, FRD body [m/s^2]."""
    air = R * (V - WIND)
    return sp.Matrix([-DRAG * air[0], -DRAG * air[1], -SCALE * THRUST / MASS])


def specific_force_body(length: sp.Expr) -> sp.Matrix:
    """Modelled specific force (no bias), FRD body [m/s^2]."""
    return rotor_specific_force_body() + R * cable_force_ned(length) / MASS


def anchor_tangent_ned(length: sp.Expr) -> sp.Matrix:
    """Direction (unnormalised) in which the cable leaves the anchor, NED [N]."""
    return TCH * P / _norm(P) + (WPL * length / 2) * E_D


LENGTHS = {"known_length": LENGTH, "chord_length": _norm(P)}


def models() -> list[tuple[str, str, list[sp.Symbol], list[sp.Expr], sp.Matrix | None, str]]:
    """``(name, doc, inputs, values, jacobian_wrt, returns)`` for each generated function."""
    out = []
    for suffix, length in LENGTHS.items():
        f_body = specific_force_body(length)
        # R^T R = I written out: m v' = R^T (thrust + drag) + F_c + m g
        vdot = R.T * rotor_specific_force_body() + cable_force_ned(length) / MASS + G * E_D
        out.append(
            (
                f"force_balance_{suffix}",
                "Formulation (a): ``x' = f(x, u)`` with ``u = (R_v^b row-major, thrust_n)``;"
                " returns ``(x' (13,), dv'/dx (3x13 row-major))``.",
                [*R, THRUST],
                list(V) + list(vdot) + [0] * 7,
                vdot,
                "process",
            )
        )
        h = f_body + B
        out.append(
            (
                f"accel_{suffix}",
                "Accelerometer force balance ``h = f + b`` [m/s^2], FRD body, with"
                " ``u = (R_v^b row-major, thrust_n)``; returns ``(h (3,), H (3x13 row-major))``.",
                [*R, THRUST],
                list(h),
                h,
                "measurement",
            )
        )
        force = cable_force_ned(length)
        tension = _norm(force)
        out.append(
            (
                f"tension_{suffix}",
                "Load cell at the drone: ``|F_c|`` [N]; returns ``(h (1,), H (1x13))``.",
                [],
                [tension],
                sp.Matrix([tension]),
                "measurement",
            )
        )
        tangent = anchor_tangent_ned(length)
        angles = sp.Matrix(
            [
                sp.atan2(-tangent[2], sp.sqrt(tangent[0] ** 2 + tangent[1] ** 2)),
                sp.atan2(tangent[1], tangent[0]),
            ]
        )
        out.append(
            (
                f"cable_angle_{suffix}",
                "Ground-station cable angle: (elevation up, azimuth from north) [rad];"
                " returns ``(h (2,), H (2x13))``.",
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
            " (accelerometer as the input); returns ``(x' (13,), dv'/dx (3x13))``.",
            [*R, *F_MEAS],
            list(V) + list(ins_vdot) + [0] * 7,
            ins_vdot,
            "process",
        )
    )
    arc = _norm(P) + WPL**2 * (P[0] ** 2 + P[1] ** 2) * _norm(P) / (24 * TCH**2)
    out.append(
        (
            "winch_length",
            "Winch paid-out length: the arc length to first order in the sag [m];"
            " returns ``(h (1,), H (1x13))``.",
            [],
            [arc],
            sp.Matrix([arc]),
            "measurement",
        )
    )
    height = -P[2] + ANCHOR_H
    out.append(
        (
            "height_above_ground",
            "Rangefinder: height above the ground ``-p_d + anchor_height_m`` [m] with"
            " ``u = (anchor_height_m,)``; returns ``(h (1,), H (1x13))``.",
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


def _function_source(name, doc, inputs, values, jac_of, kind) -> str:
    printer = _Printer()
    jac = jac_of.jacobian(X) if jac_of is not None else sp.Matrix([])
    flat = [sp.sympify(e) for e in list(values) + list(jac)]
    replacements, reduced = sp.cse(flat, symbols=sp.numbered_symbols("t"), optimizations="basic")
    n_values = len(values)
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
    vals = ", ".join(printer.doprint(sp.sympify(e)) for e in reduced[:n_values])
    jacs = ", ".join(printer.doprint(sp.sympify(e)) for e in reduced[n_values:])
    lines.append(f"    return ({vals},), ({jacs},)")
    return "\n".join(lines)


HEADER = '''"""GENERATED by tether_companion/estimation/dynamic/derivation/derive.py -- DO NOT EDIT.

Regenerate with ``python -m tether_companion.estimation.dynamic.derivation.derive``; the
models and their meaning are documented there. sympy {version}.

Every function takes the state ``x`` (13 floats, layout in ``state.py``), the inputs ``u``
and the constants ``c = (mass_kg, drag_per_s, weight_n_per_m, length_m)`` and returns the
values and the Jacobian with respect to ``x`` (row-major, 13 columns).
"""

# ruff: noqa
from __future__ import annotations

import math
from collections.abc import Sequence
'''


def generate_source() -> str:
    """The text of ``generated.py``."""
    parts = [HEADER.format(version=sp.__version__)]
    for model in models():
        parts.append("\n\n" + _function_source(*model) + "\n")
    return "".join(parts)


def main() -> int:
    """Write ``generated.py``."""
    OUTPUT.write_text(generate_source())
    print(f"wrote {OUTPUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
