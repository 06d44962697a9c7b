"""Posterior CRLB (estimation/crlb.py) against closed forms of a static hover."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_companion.estimation.crlb import posterior_crlb

MASS_KG = 1.5
TENSION_N = 4.0
LENGTH_M = 5.0
SIGMA_ACC = 0.1
SIGMA_RANGE = 0.3
P0 = 1.0
RATE_HZ = 200.0


def _hover(ticks: int, alpha_rad: float, euler=(0.0, 0.0, 0.0), range_every: int = 1):
    """A drone held still at ``L (sin a, 0, -cos a)`` with a known tension."""
    position = LENGTH_M * np.array((math.sin(alpha_rad), 0.0, -math.cos(alpha_rad)))
    return dict(
        time_s=np.arange(ticks) / RATE_HZ,
        position_ned_m=np.tile(position, (ticks, 1)),
        tension_n=np.full(ticks, TENSION_N),
        euler_rad=np.tile(np.asarray(euler, dtype=float), (ticks, 1)),
        thrust_n=np.full(ticks, 15.0),
        range_seen=(np.arange(ticks) % range_every) == 0,
    )


def _bound(flight, q_density, known_tension=True, p0=P0):
    n = 3 if known_tension else 4
    return posterior_crlb(
        **flight,
        mass_kg=MASS_KG,
        accel_std_mps2=SIGMA_ACC,
        range_std_m=SIGMA_RANGE,
        q_density=np.eye(n) * q_density,
        p0=np.eye(n) * p0,
        known_tension=known_tension,
    )


@pytest.mark.parametrize("euler", [(0.0, 0.0, 0.0), (0.1, -0.2, 0.7)])
def test_static_hover_known_tension_matches_the_fisher_information_by_hand(euler):
    """Static hover, tension known, no process noise: the bound after N ticks by hand.

    The accelerometer model is ``h(p) = ([0, 0, -T] + R(-f u)) / m`` with ``u = p / |p|``;
    its Jacobian ``H = -(f / (m L)) R (I - u u^T)``. ``R`` is a rotation, so the Fisher
    information of one sample is ``H^T H / s_a^2 = a (I - u u^T)`` with
    ``a = (f / (m L s_a))^2`` whatever the attitude: the accelerometer says nothing about
    the distance along the cable. The rangefinder reads ``d = -p_d / c`` with
    ``c = cos(roll) cos(pitch)``: information ``b = 1 / (c s_r)^2`` on ``p_d``.
    With ``P0 = p0 I`` and no process noise the information adds up over N ticks:
    ``J = I / p0 + N a (I - u u^T) + N b e_d e_d^T``. For ``u = (s, 0, -k)``
    (``s = sin(alpha)``, ``k = cos(alpha)``), east decouples: ``var_e = 1 / (1/p0 + N a)``;
    north-down is the 2x2 block ``[[1/p0 + N a k^2, N a s k], [N a s k, 1/p0 + N a s^2 +
    N b]]``, whose inverse has diagonal ``(J_dd, J_nn) / det``.
    """
    ticks, alpha = 400, 0.6
    bound = _bound(_hover(ticks, alpha, euler), 0.0)
    s, k = math.sin(alpha), math.cos(alpha)
    a = (TENSION_N / (MASS_KG * LENGTH_M * SIGMA_ACC)) ** 2
    c = math.cos(euler[0]) * math.cos(euler[1])
    b = 1.0 / (c * SIGMA_RANGE) ** 2
    j_nn = 1.0 / P0 + ticks * a * k * k
    j_nd = ticks * a * s * k
    j_dd = 1.0 / P0 + ticks * a * s * s + ticks * b
    det = j_nn * j_dd - j_nd * j_nd
    expected = np.array((j_dd / det, 1.0 / (1.0 / P0 + ticks * a), j_nn / det))
    np.testing.assert_allclose(bound[-1], expected, rtol=1e-9)


def test_random_walk_reaches_the_scalar_riccati_fixed_point():
    """With process noise ``q = Q_c dt`` per tick and information ``i = a`` per tick on east,
    the bound's fixed point solves ``P = (P + q) / (1 + i (P + q))``, i.e.
    ``i P^2 + i q P - q = 0``: ``P = (-q + sqrt(q^2 + 4 q / i)) / 2``."""
    q_density = 1.0
    bound = _bound(_hover(3000, 0.6), q_density)
    q = q_density / RATE_HZ
    i = (TENSION_N / (MASS_KG * LENGTH_M * SIGMA_ACC)) ** 2
    expected = 0.5 * (-q + math.sqrt(q * q + 4.0 * q / i))
    assert bound[-1, 1] == pytest.approx(expected, rel=1e-9)
    assert np.all(np.diff(bound[100:, 1]) <= 1e-15)  # settles monotonically


def test_unknown_tension_straight_above_the_anchor_decouples():
    """Drone straight above the anchor (``u = (0, 0, -1)``), level: the tension column of the
    Jacobian ``-R u / m = e_d / m`` sees only the vertical specific force, the position
    columns only north and east. So with no process noise after N ticks:
    ``var_f = 1 / (1/p0 + N / (m s_a)^2)``, ``var_d = 1 / (1/p0 + N / s_r^2)`` (range only),
    north and east as with a known tension."""
    ticks = 300
    bound = _bound(_hover(ticks, 0.0), 0.0, known_tension=False)
    a = (TENSION_N / (MASS_KG * LENGTH_M * SIGMA_ACC)) ** 2
    expected = (
        1.0 / (1.0 / P0 + ticks * a),
        1.0 / (1.0 / P0 + ticks * a),
        1.0 / (1.0 / P0 + ticks / SIGMA_RANGE**2),
        1.0 / (1.0 / P0 + ticks / (MASS_KG * SIGMA_ACC) ** 2),
    )
    np.testing.assert_allclose(bound[-1], expected, rtol=1e-9)


def test_position_bound_does_not_depend_on_knowing_the_tension():
    """The position and tension columns of the straight-cable Jacobian are orthogonal
    (``(I - u u^T) R^T R u = 0``), so a load cell adds no position information: both bounds
    agree at any position and attitude."""
    flight = _hover(500, 0.9, (0.05, 0.1, 1.0), range_every=3)
    known = _bound(flight, 1.0)
    unknown = _bound(flight, 1.0, known_tension=False)
    np.testing.assert_allclose(known, unknown[:, :3], rtol=1e-9)


def test_no_tension_no_horizontal_information():
    """A slack cable (``f = 0``) tells nothing horizontally: north/east grow as ``p0 + Q_c t``."""
    flight = _hover(201, 0.6)
    flight["tension_n"] = np.zeros(201)
    bound = _bound(flight, 0.5)
    assert bound[-1, 1] == pytest.approx(P0 + 0.5 * 1.0, rel=1e-9)


def test_zero_noise_is_refused():
    with pytest.raises(ValueError, match="sigmas must be > 0"):
        posterior_crlb(
            **_hover(3, 0.5),
            mass_kg=MASS_KG,
            accel_std_mps2=0.0,
            range_std_m=SIGMA_RANGE,
            q_density=np.eye(3),
            p0=np.eye(3),
            known_tension=True,
        )
