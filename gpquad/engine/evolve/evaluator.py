"""Python side of the fitness kernel: pads trees into population arrays and calls it."""

from __future__ import annotations

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.engine.kernels.fitness import population_window_errors
from gpquad.engine.kernels.step import scheme_code
from gpquad.engine.kernels.tree_eval import STACK_ROWS, check_stack
from gpquad.engine.lag import lag_alpha
from gpquad.engine.tree.encoding import Tree, max_nodes
from gpquad.engine.variables import STATE_NAMES, target_index


def attitude_weight(dataset: Dataset, target: str, weight: float) -> float:
    """The kernels' att_weight for `target`: `weight` x (RMS deviation of the target's rate) /
    (RMS deviation of the Euler angle it integrates into), both on `dataset`, so that with
    weight 1 the rate and the angle count alike whatever the units and the flight's range.
    0 for linear targets, for weight 0, and where the angle is not measured in every flight.
    """
    k = target_index(target)
    if weight <= 0.0 or k < 3:
        return 0.0
    angle = STATE_NAMES[k - 3]
    if dataset.unmeasured(angle):
        return 0.0
    states = dataset.arrays.states
    rate_spread = float(np.std(states[:, 3 + k]))
    angle_spread = float(np.std(states[:, k - 3]))
    if not (rate_spread > 0.0 and angle_spread > 0.0):
        return 0.0
    return float(weight * rate_spread / angle_spread)


class Evaluator:
    """Integrated-state errors of trees for one target on one dataset.

    attitude: the weight of the angle an angular target's rate integrates into
    (gpquad.engine.kernels.fitness; scaled by `attitude_weight`); 0 = the paper's fitness.
    angle_tangents: the constants' Jacobian follows them through the Euler angles the tree
    reads (gpquad.engine.kernels.sensitivity; used by the gradient fit only).
    lag: the equation's time constant, s (gpquad.engine.lag; 0 = none); `set_lag` changes it.
    integrator, substeps: the scheme that flies the windows (gpquad.engine.kernels.step:
    "euler", one eq. 2 step per sample, or "rk4" with `substeps` steps per sample).
    """

    def __init__(
        self,
        dataset: Dataset,
        target: str,
        n_steps: int,
        metric: str = "mae",
        max_depth: int = 5,
        attitude: float = 0.0,
        angle_tangents: bool = False,
        lag: float = 0.0,
        integrator: str = "euler",
        substeps: int = 1,
    ):
        self.arrays = dataset.scheme_arrays(integrator, substeps)
        self.integrator = integrator
        self.scheme = scheme_code(integrator)
        self.substeps = int(substeps)
        self.set_lag(lag)
        self.target = target_index(target)
        self.att_weight = attitude_weight(dataset, target, attitude)
        self.angle_tangents = bool(angle_tangents)
        self.n_steps = int(n_steps)
        self.squared = metric == "mse"
        self.capacity = max_nodes(max_depth)
        self.n_inputs = dataset.arrays.inputs.shape[1]
        self.evaluations = 0  # window evaluations, for throughput reports

    def set_lag(self, tau: float) -> None:
        """Evaluate every tree with time constant tau (s) from now on."""
        self.lag = float(tau)
        self.alpha = lag_alpha(self.lag, self.arrays.dt)

    def pack(self, trees: list[Tree]):
        """Population arrays (codes, values, sizes, delays) for the kernel."""
        lengths = [len(t.codes) for t in trees]
        capacity = max(self.capacity, max(lengths))
        codes = np.zeros((len(trees), capacity), dtype=np.int64)
        values = np.zeros((len(trees), capacity))
        delays = np.empty((len(trees), self.n_inputs), dtype=np.int64)
        for i, t in enumerate(trees):
            n = lengths[i]
            codes[i, :n] = t.codes
            values[i, :n] = t.values
            delays[i] = t.delays
        sizes = np.array(lengths, dtype=np.int64)
        return codes, values, sizes, delays

    def window_errors(self, trees: list[Tree], starts, bounds=None, n_steps=None) -> np.ndarray:
        """Per-window mean error, shape (len(trees), len(starts)); inf = diverged/abandoned."""
        return self.packed_window_errors(self.pack(trees), starts, bounds, n_steps)

    def packed_window_errors(self, packed, starts, bounds=None, n_steps=None) -> np.ndarray:
        """window_errors of a population already packed as `pack` packs it (codes, values,
        sizes, delays; each row's codes past its size are not read)."""
        codes, values, sizes, delays = packed
        # n nodes hold <= (n + 1) // 2 leaves >= the height
        if sizes.size and (int(sizes.max()) + 1) // 2 > STACK_ROWS:
            check_stack(codes, sizes)
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        n_steps = self.n_steps if n_steps is None else int(n_steps)
        n_trees = codes.shape[0]
        if bounds is None:
            bounds = np.full(n_trees, np.inf)
        out = np.empty((n_trees, len(starts)))
        population_window_errors(
            codes,
            values,
            sizes,
            delays,
            self.target,
            self.arrays,
            starts,
            n_steps,
            self.squared,
            self.att_weight,
            self.alpha,
            np.asarray(bounds, dtype=float),
            out,
            self.scheme,
            self.substeps,
        )
        self.evaluations += n_trees * len(starts)
        return out

    def mean_errors(self, trees: list[Tree], starts, bounds=None) -> np.ndarray:
        """Fitness of each tree: mean over windows of the per-window error."""
        return self.window_errors(trees, starts, bounds).mean(axis=1)

    def packed_mean_errors(self, packed, starts, bounds=None) -> np.ndarray:
        """mean_errors of a packed population (packed_window_errors)."""
        return self.packed_window_errors(packed, starts, bounds).mean(axis=1)
