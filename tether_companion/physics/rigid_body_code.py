"""The rigid body's equations of motion (eqs. 3-6) as generated straight-line Python.

:data:`_DERIVATIVE` writes the derivative of the 12 rigid-body states once, as text, in the
layout of :mod:`tether_companion.physics.rigid_body`; :func:`generated` compiles it into the
``derivative`` the body's outputs use and into one RK4 step with the four stages inlined
(each stage's inputs and outputs renamed in the text, so no call, tuple or copy between
stages). Both do :data:`_DERIVATIVE`'s operations in its order: the same floats as RK4 built
from ``derivative`` stage by stage.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable

from tether_companion.physics.aerodynamics import drag_accel_body_mps2

_STATE = ("pn", "pe", "pd", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r")
"""Names of the 12 rigid-body states in the generated code, in
:mod:`tether_companion.physics.rigid_body`'s layout."""
_N = len(_STATE)
_COEFFICIENTS = "bn, be, bd, c, im, wn, we, wd, gx, gy, gz, ix, iy, iz, rotor, ballistic"
"""What the derivative reads besides the state and the wrench (``RigidBody._coefficients``)."""
_DERIVATIVE = """\
cr = cos(phi)
sr = sin(phi)
cp = cos(theta)
sp = sin(theta)
cy = cos(psi)
sy = sin(psi)
# rows of R_v^b (eq. 2)
srsp = sr * sp
crsp = cr * sp
r00 = cp * cy
r01 = cp * sy
r10 = srsp * cy - cr * sy
r11 = srsp * sy + cr * cy
r12 = sr * cp
r20 = crsp * cy + sr * sy
r21 = crsp * sy - sr * cy
r22 = cr * cp
# eq. 3: NED velocity = R^T (u, v, w)
vn = r00 * u + r10 * v + r20 * w
ve = r01 * u + r11 * v + r21 * w
vd = -sp * u + r12 * v + r22 * w
fn, fe, fd = external_force(pn, pe, pd, vn, ve, vd)
fn += bn - c * vn
fe += be - c * ve
fd += bd - c * vd
ax = (r00 * fn + r01 * fe - sp * fd) * im
ay = (r10 * fn + r11 * fe + r12 * fd) * im
{drag}az = (r20 * fn + r21 * fe + r22 * fd - thrust_n) * im
# eq. 4
du = r * v - q * w + ax
dv = p * w - r * u + ay
dw = q * u - p * v + az
# eq. 5
s = sr * q + cr * r
dphi = p + s * sp / cp
dtheta = cr * q - sr * r
dpsi = s / cp
# eq. 6
dp = gx * q * r + tau_l * ix
dq = gy * p * r + tau_m * iy
dr = gz * p * q + tau_n * iz
"""
"""Eqs. 3-6 at the state named by :data:`_STATE` for the wrench ``thrust_n, tau_l, tau_m,
tau_n``, as straight-line code: written once, used by :meth:`RigidBody.derivative` and inlined
four times into the RK4 step (no call, no tuple per stage)."""
_DRAG = """\
dax, day = drag_accel_body_mps2(
    u - (r00 * wn + r01 * we - sp * wd), v - (r10 * wn + r11 * we + r12 * wd), rotor, ballistic
)
ax += dax
ay += day
"""
_OUTPUTS = "vn, ve, vd, du, dv, dw, dphi, dtheta, dpsi, dp, dq, dr"
NO_SLOPE: tuple[float, ...] = ()
"""The empty slope: :func:`generated`'s ``derivative`` at the state itself."""


def _indent(code: str) -> str:
    return "".join(f"    {line}\n" for line in code.splitlines())


def _renamed(code: str, names: dict[str, str]) -> str:
    """``code`` with every whole-word occurrence of a key of ``names`` replaced by its value;
    comment lines dropped."""
    pattern = re.compile(r"\b(" + "|".join(map(re.escape, names)) + r")\b")
    lines = (line for line in code.splitlines() if not line.lstrip().startswith("#"))
    return "\n".join(pattern.sub(lambda m: names[m.group(1)], line) for line in lines) + "\n"


def _rk4_source(body: str, first_stage: bool) -> str:
    """One RK4 step's function (see :func:`generated`): ``rk4`` evaluating all four stages, or
    ``rk4_after`` given the first stage's derivative ``k1`` (12 values) in place of
    ``w_start``."""
    x_names = [f"x{i}" for i in range(_N)]
    if first_stage:
        lines = ["def rk4(x, w_start, w_half, w_full, h, coefficients, external_force):"]
    else:
        lines = ["def rk4_after(x, k1, w_half, w_full, h, coefficients, external_force):"]
    lines += [
        f"    {_COEFFICIENTS} = coefficients",
        f"    {', '.join(x_names)} = x",
        "    hh = 0.5 * h",
    ]
    if not first_stage:
        lines.append(f"    {', '.join(f'k1_{i}' for i in range(_N))} = k1")
    outputs = _OUTPUTS.split(", ")
    stages = (
        ("w_start", None, ""),
        ("w_half", "k1", "hh"),
        (None, "k2", "hh"),  # the same wrench as the second stage's
        ("w_full", "k3", "h"),
    )
    for k, (wrench, previous, step) in enumerate(stages, start=1):
        if previous is None and not first_stage:
            continue
        if wrench is not None:
            lines.append(f"    thrust_n, tau_l, tau_m, tau_n = {wrench}")
        names = {out: f"k{k}_{i}" for i, out in enumerate(outputs)}
        for i, name in enumerate(_STATE):
            if previous is None:
                names[name] = f"x{i}"
            else:
                names[name] = f"y{k}_{i}"
                lines.append(f"    y{k}_{i} = x{i} + {step} * {previous}_{i}")
        lines.append(_indent(_renamed(body, names)).rstrip("\n"))
    lines.append("    h6 = h / 6.0")
    lines.append(
        "    return ["
        + ", ".join(f"x{i} + h6 * (k1_{i} + k4_{i} + 2.0 * (k2_{i} + k3_{i}))" for i in range(_N))
        + "]"
    )
    return "\n".join(lines) + "\n"


@functools.cache
def generated(
    aero_drag: bool,
) -> tuple[Callable[..., tuple], Callable[..., list], Callable[..., list]]:
    """``(derivative, rk4, rk4_after)`` compiled from :data:`_DERIVATIVE`, with the
    body-horizontal drag of :mod:`~tether_companion.physics.aerodynamics` or without it.

    ``derivative(x, wrench, slope, h, coefficients, external_force)`` is eqs. 3-6 at ``x``
    (``x + h * slope`` unless ``slope`` is empty); ``rk4(x, w_start, w_half, w_full, h,
    coefficients, external_force)`` returns the new state of one classical RK4 step with the
    wrench at the stage times; ``rk4_after(x, k1, w_half, w_full, h, coefficients,
    external_force)`` the same step given its first stage ``k1 = derivative(x, w_start, (),
    0.0, coefficients, external_force)`` (evaluated already, for the accelerometer). In the
    step, stage ``k`` is :data:`_DERIVATIVE` with its outputs renamed ``k{k}_{i}`` and its
    state inputs ``y{k}_{i}`` (the first stage reads the state's own ``x{i}``): the same
    operations in the same order, so all give the same floats as evaluating the stages one by
    one.
    """
    body = _DERIVATIVE.format(drag=_DRAG if aero_drag else "")
    stage_in = ", ".join(_STATE)
    x_names = [f"x{i}" for i in range(_N)]
    derivative = (
        "def derivative(x, wrench, slope, h, coefficients, external_force):\n"
        f"    {_COEFFICIENTS} = coefficients\n"
        "    thrust_n, tau_l, tau_m, tau_n = wrench\n"
        "    if slope:\n"
        f"        {', '.join(x_names)} = x\n"
        f"        {', '.join(f's{i}' for i in range(_N))} = slope\n"
        + "".join(f"        {name} = x{i} + h * s{i}\n" for i, name in enumerate(_STATE))
        + "    else:\n"
        f"        {stage_in} = x\n" + _indent(body) + f"    return ({_OUTPUTS})\n"
    )
    namespace = {"cos": math.cos, "sin": math.sin, "drag_accel_body_mps2": drag_accel_body_mps2}
    source = derivative + _rk4_source(body, True) + _rk4_source(body, False)
    exec(compile(source, f"<generated rigid body, drag {aero_drag}>", "exec"), namespace)  # noqa: S102
    return namespace["derivative"], namespace["rk4"], namespace["rk4_after"]
