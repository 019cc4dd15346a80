"""The joint refit's Jacobian from one sensitivity flight of the full model
(gpquad.engine.kernels.rollout_sensitivity), for a continuous-time (RK4) model: the exact
derivative of the residuals that gpquad.models.joint_fit.FullModelError gives, where
forward differences fly one rollout per constant."""

from __future__ import annotations

import numpy as np

from gpquad.engine.evolve.lm import remember_last
from gpquad.engine.kernels.rollout_sensitivity import rk4_rollout_sensitivities
from gpquad.engine.kernels.step import RK4, SCHEMES
from gpquad.engine.threads import chunks, thread_map
from gpquad.engine.tree.operators import CONST
from gpquad.engine.variables import target_index


def has_sensitivities(model) -> bool:
    """Whether the model's scheme has the sensitivity flight (RK4; eq. 2 has none)."""
    return SCHEMES[str(model.integrator)] == RK4


def column_slots(model, slots, capacity: int) -> np.ndarray:
    """(6, capacity): the Jacobian column of each constant node that the joint refit fits,
    `slots` = [(target, indices of its CONST nodes)] in the order of its constants vector;
    -1 elsewhere."""
    out = np.full((6, capacity), -1, dtype=np.int64)
    at = 0
    for target, idx in slots:
        assert np.all(model.equations[target].tree.codes[idx] == CONST)
        out[target_index(target), idx] = np.arange(at, at + len(idx))
        at += len(idx)
    return out


def flown_with_sensitivities(model, dataset, slots, starts, n_steps: int, workers: int = 1):
    """(states (W, n_steps + 1, 9), sensitivities (W, n_steps + 1, 6, n_constants)) of the
    model flown over the windows, the sensitivities those of u, v, w, p, q, r to the
    constants of `slots`. Targets without an equation take the data's accelerations, as
    DiscoveredModel.simulate. The windows are split among `workers` threads; each window's
    arithmetic is its own, so the result is the same for any number."""
    trees = model.kernel_trees(dataset.dt)
    columns = column_slots(model, slots, trees[0].shape[1])
    n_c = sum(len(idx) for _, idx in slots)
    starts = np.ascontiguousarray(starts, dtype=np.int64)

    def fly(chunk):
        out = np.empty((len(chunk), n_steps + 1, 9))
        sens = np.empty((len(chunk), n_steps + 1, 6, n_c))
        rk4_rollout_sensitivities(
            *trees,
            columns,
            dataset.arrays,
            starts[chunk],
            int(n_steps),
            int(model.substeps or 1),
            out,
            sens,
        )
        return out, sens

    parts = thread_map(fly, chunks(len(starts), workers), workers)
    if not parts:
        return np.empty((0, n_steps + 1, 9)), np.empty((0, n_steps + 1, 6, n_c))
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def sensitivity_jacobian(residuals, model_at, slots, dataset, objectives, workers, counter):
    """(value, jac) for the joint refit's LM, as lm.forward_difference's: value(x) is
    residuals(x) remembered at the last point asked, jac(x) the Jacobian of the
    `objectives`' (joint_fit.FullModelError) residuals, concatenated, at the model
    model_at(x), from one sensitivity flight of each objective's windows; `counter` is
    advanced once per Jacobian."""
    value = remember_last(lambda v: np.asarray(residuals(v), dtype=float))

    def jacobian(x):
        next(counter)
        model = model_at(np.array(x, dtype=float))
        blocks = []
        for o in objectives:
            states, sens = flown_with_sensitivities(
                model, dataset, slots, o.starts, o.steps, workers
            )
            blocks.append(o.jacobian_of(states, sens))
        return np.concatenate(blocks)

    return value, jacobian
