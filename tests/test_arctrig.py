"""gpquad.engine.kernels.arctrig's atan2 and asin (the Euler angles of every kernel) are
within 1 ulp of the exact values (mpmath at 120 bits), agree with libm on special inputs,
and their lane loops give the bits of the scalar functions."""

import math

import mpmath
import numpy as np
import pytest

from gpquad.engine.kernels.arctrig import asin, atan2, atan2_lanes
from gpquad.engine.kernels.quaternion import euler_angle, euler_angle_lanes
from gpquad.engine.numba_config import njit, python_callable

euler_angle = python_callable(euler_angle)
euler_angle_lanes = python_callable(euler_angle_lanes)
atan2_lanes = python_callable(atan2_lanes)


@njit(cache=False)
def _atan2_each(y, x, out):
    for i in range(y.shape[0]):
        out[i] = atan2(y[i], x[i])


@njit(cache=False)
def _asin_each(x, out):
    for i in range(x.shape[0]):
        out[i] = asin(x[i])


def _ulps(got, exact) -> float:
    exact_f = float(exact)
    unit = math.ulp(exact_f) if exact_f != 0.0 else 5e-324
    return abs(float((mpmath.mpf(got) - exact) / unit))


def _atan2_inputs(rng, n):
    angle = rng.uniform(-np.pi, np.pi, n)
    radius = np.exp(rng.uniform(-5, 5, n))
    near = rng.choice([0.4375, 0.6875, 1.0, 1 / 0.6875, 1 / 0.4375], n)  # interval edges
    x = rng.standard_normal(n)
    ys = [radius * np.sin(angle), x * near * (1 + rng.normal(0, 1e-6, n)) * rng.choice([-1, 1], n)]
    xs = [radius * np.cos(angle), x]
    ys.append(rng.standard_normal(n) * 10.0 ** rng.uniform(-40, 0, n))  # near the x axis
    xs.append(rng.standard_normal(n))
    return np.concatenate(ys), np.concatenate(xs)


def test_atan2_within_one_ulp():
    rng = np.random.default_rng(1)
    y, x = _atan2_inputs(rng, 2000)
    out = np.empty_like(y)
    _atan2_each(y, x, out)
    mpmath.mp.prec = 120
    worst = max(_ulps(o, mpmath.atan2(mpmath.mpf(a), mpmath.mpf(b))) for o, a, b in zip(out, y, x))
    assert worst < 0.75


def test_asin_within_one_ulp():
    rng = np.random.default_rng(2)
    n = 3000
    x = np.concatenate(
        [
            rng.uniform(-1, 1, n),
            1 - 10.0 ** rng.uniform(-16, 0, n),
            0.5 + rng.normal(0, 1e-6, n),
            rng.standard_normal(n) * 10.0 ** rng.uniform(-30, 0, n),
        ]
    )
    x = x[np.abs(x) <= 1.0]
    out = np.empty_like(x)
    _asin_each(x, out)
    mpmath.mp.prec = 120
    worst = max(_ulps(o, mpmath.asin(mpmath.mpf(a))) for o, a in zip(out, x))
    assert worst < 0.75


@pytest.mark.parametrize(
    "y, x",
    [(0.0, 0.0), (-0.0, 0.0), (0.0, -0.0), (-0.0, -0.0), (1.0, -0.0), (-1.0, 0.0), (0.0, -2.0)]
    + [(-0.0, -2.0), (math.inf, 1.0), (1.0, math.inf), (math.inf, -math.inf), (1e-310, 1.0)]
    + [(1e300, 1e-300), (1e-300, -1e300), (2.0, 1e-200)],
)
def test_atan2_special_inputs_as_libm(y, x):
    want = math.atan2(y, x)
    out = np.empty(1)
    _atan2_each(np.array([y]), np.array([x]), out)
    assert out[0] == want and math.copysign(1.0, out[0]) == math.copysign(1.0, want)
    atan2_lanes(np.array([y]), np.array([x]), out, 1)
    assert out[0] == want and math.copysign(1.0, out[0]) == math.copysign(1.0, want)


def test_asin_special_inputs_as_libm():
    x = np.array([0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 1e-310, 2**-28])
    out = np.empty_like(x)
    _asin_each(x, out)
    for got, a in zip(out, x):
        assert got == math.asin(a) and math.copysign(1.0, got) == math.copysign(1.0, a)
    _asin_each(np.array([1.5, math.nan]), out[:2])
    assert np.isnan(out[:2]).all()


def test_euler_angle_lanes_within_one_ulp_of_libm_angles():
    """The fitness kernel's vectorised Euler angles against euler_angle (libm's)."""
    rng = np.random.default_rng(3)
    n = 3001
    quat = rng.standard_normal((4, n))
    quat /= np.linalg.norm(quat, axis=0)
    quat[:, :20] = [[1.0], [0.0], [0.0], [0.0]]  # zero angles
    quat[:, 20:25] = [[0.5**0.5], [0.0], [0.5**0.5], [0.0]]  # theta = pi/2 (clamped)
    quat[:, 25] = np.nan  # roll and yaw NaN (theta's clamp is not defined for NaN)
    out, y, x = np.empty(n), np.empty(n), np.empty(n)
    for axis in range(3):
        euler_angle_lanes(axis, quat, 0, out, n, y, x)
        want = np.array([euler_angle(axis, *quat[:, i]) for i in range(n)])
        assert axis == 1 or (np.isnan(out[25]) and np.isnan(want[25]))
        ok = np.arange(n) != 25
        assert np.all(np.abs(out[ok] - want[ok]) <= np.spacing(np.abs(want[ok])))
        assert np.mean(out[ok] == want[ok]) > 0.95
        # the same attitudes as rows 3-6 of a stage state (the RK4 kernels' layout)
        ys = np.full((9, n), 7.0)
        ys[3:7] = quat
        at_row = np.empty(n)
        euler_angle_lanes(axis, ys, 3, at_row, n, y, x)
        assert np.array_equal(at_row, out, equal_nan=True)
