"""Python side of the fitness kernel: pads trees into population arrays and calls it."""

from __future__ import annotations

import numpy as np

from gpquad.data.dataset import Dataset
from gpquad.engine.kernels.fitness import population_window_errors
from gpquad.engine.kernels.tree_eval import STACK_ROWS, check_stack
from gpquad.engine.tree.encoding import Tree, max_nodes
from gpquad.engine.variables import target_index


class Evaluator:
    """Integrated-state errors of trees for one target on one dataset."""

    def __init__(self, dataset: Dataset, target: str, n_steps: int, metric: str = "mae",
                 max_depth: int = 5):
        self.arrays = dataset.arrays
        self.target = target_index(target)
        self.n_steps = int(n_steps)
        self.squared = metric == "mse"
        self.capacity = max_nodes(max_depth)
        self.n_inputs = dataset.arrays.inputs.shape[1]
        self.evaluations = 0  # window evaluations, for throughput reports

    def pack(self, trees: list[Tree]):
        """Population arrays (codes, values, sizes, delays) for the kernel."""
        capacity = max(self.capacity, max(t.size for t in trees))
        codes = np.zeros((len(trees), capacity), dtype=np.int64)
        values = np.zeros((len(trees), capacity))
        sizes = np.empty(len(trees), dtype=np.int64)
        delays = np.empty((len(trees), self.n_inputs), dtype=np.int64)
        for i, t in enumerate(trees):
            codes[i, : t.size] = t.codes
            values[i, : t.size] = t.values
            sizes[i] = t.size
            delays[i] = t.delays
        if (capacity + 1) // 2 > STACK_ROWS:  # n nodes hold <= (n + 1) // 2 leaves >= height
            check_stack(codes, sizes)
        return codes, values, sizes, delays

    def window_errors(self, trees: list[Tree], starts, bounds=None, n_steps=None) -> np.ndarray:
        """Per-window mean error, shape (len(trees), len(starts)); inf = diverged/abandoned."""
        starts = np.ascontiguousarray(starts, dtype=np.int64)
        n_steps = self.n_steps if n_steps is None else int(n_steps)
        if bounds is None:
            bounds = np.full(len(trees), np.inf)
        out = np.empty((len(trees), len(starts)))
        codes, values, sizes, delays = self.pack(trees)
        population_window_errors(codes, values, sizes, delays, self.target, self.arrays, starts,
                                 n_steps, self.squared, np.asarray(bounds, dtype=float), out)
        self.evaluations += len(trees) * len(starts)
        return out

    def mean_errors(self, trees: list[Tree], starts, bounds=None) -> np.ndarray:
        """Fitness of each tree: mean over windows of the per-window error."""
        return self.window_errors(trees, starts, bounds).mean(axis=1)
