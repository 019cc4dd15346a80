"""euler_lanes_step (the fitness kernel's vectorised eq. 2 step of all lanes) gives the bits
of euler_step lane by lane, on both branches of the rate increment (series and sin/cos)."""

import numpy as np
import pytest

from gpquad.engine.kernels.quaternion import SERIES_LIMIT
from gpquad.engine.kernels.step import euler_lanes_step, euler_step
from gpquad.engine.numba_config import python_callable

euler_lanes_step = python_callable(euler_lanes_step)


@pytest.mark.parametrize("move_vel, move_att", [(True, True), (False, True), (True, False)])
def test_lanes_step_equals_euler_step_lane_by_lane(move_vel, move_att):
    rng = np.random.default_rng(3)
    n, dt, axis = 9, 0.04, 1
    quat = rng.standard_normal((4, n))
    quat /= np.linalg.norm(quat, axis=0)
    vel = rng.standard_normal((3, n))
    rates = rng.standard_normal((3, n))
    rates[:, 2] *= 40.0  # |omega| dt / 2 above SERIES_LIMIT: the sin/cos branch
    rates[:, 5] *= 60.0
    assert 0.25 * np.sum(rates[:, 2] ** 2) * dt * dt > SERIES_LIMIT**2
    acc = rng.standard_normal((30, 6))
    starts = rng.integers(0, 20, n).astype(np.int64)
    pred = rng.standard_normal(n)
    alive = np.ones(n, dtype=np.bool_)
    k = 4
    want = []
    for lane in range(n):
        a = acc[starts[lane] + k].copy()
        a[3 + axis] = pred[lane]
        want.append(
            euler_step(*quat[:, lane], *vel[:, lane], *rates[:, lane], *a, dt, move_vel, move_att)
        )
    want = np.array(want).T
    euler_lanes_step(
        quat,
        vel,
        rates,
        acc,
        starts,
        k,
        axis,
        pred,
        alive,
        dt,
        move_vel,
        move_att,
        np.empty((5, n)),
    )
    assert np.array_equal(quat, want[:4])
    assert np.array_equal(vel, want[4:7])
    assert np.array_equal(rates, want[7:])
