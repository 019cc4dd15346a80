"""gpquad.engine.kernels.step's RK4 stage functions over lanes (windows flown side by side):
the same arithmetic per lane, row by row over the lanes so that the loops vectorise
(docs/decisions/2026-11-27-lanes-and-trials.md).

They take the flown rows as a list (`rows`, ascending; fitness_rk4.flown_rows): an angular
equation that reads the attitude but not the velocity flies Q and W and leaves V out, and
the rows not flown are neither stepped nor read.
"""

from gpquad.engine.kernels.quaternion import renormalize
from gpquad.engine.kernels.step import Q, unit_attitude
from gpquad.engine.numba_config import njit


@njit(inner=True)
def lanes_stage_state(y, k, node, h, out, n_lanes, rows):
    """body_stage_state of lanes 0..n_lanes-1 on the flown `rows` (ascending; the attitude
    is normalised when they start at Q), row by row over the lanes, so that the loops over
    lanes vectorise (docs/decisions/2026-11-27-lanes-and-trials.md). The same bits per lane;
    a dead lane is stepped too, to no purpose."""
    if node == 0.0:
        for r in range(rows.shape[0]):
            i = rows[r]
            for lane in range(n_lanes):
                out[i, lane] = y[i, lane]
        return
    step = node * h
    for r in range(rows.shape[0]):
        i = rows[r]
        for lane in range(n_lanes):
            out[i, lane] = y[i, lane] + step * k[i, lane]
    if rows[0] == Q:
        for lane in range(n_lanes):
            unit_attitude(out, lane)


@njit(inner=True)
def lanes_accumulate(total, k, weight, stage, n_lanes, rows):
    """accumulate of lanes 0..n_lanes-1 on the flown `rows`, row by row over the lanes."""
    for r in range(rows.shape[0]):
        i = rows[r]
        if stage == 0:
            for lane in range(n_lanes):
                total[i, lane] = weight * k[i, lane]
        else:
            for lane in range(n_lanes):
                total[i, lane] += weight * k[i, lane]


@njit(inner=True)
def lanes_finish_step(y, total, h, n_lanes, rows):
    """finish_step of lanes 0..n_lanes-1 on the flown `rows`, row by row over the lanes."""
    for r in range(rows.shape[0]):
        i = rows[r]
        for lane in range(n_lanes):
            y[i, lane] += h * total[i, lane]
    if rows[0] == Q:
        for lane in range(n_lanes):
            y[Q, lane], y[Q + 1, lane], y[Q + 2, lane], y[Q + 3, lane] = renormalize(
                y[Q, lane], y[Q + 1, lane], y[Q + 2, lane], y[Q + 3, lane]
            )
