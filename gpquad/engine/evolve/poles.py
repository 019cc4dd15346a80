"""Quotients whose denominator crosses zero where the data went (the final selection's
guard; not in the paper).

The tree language divides, protected only at |b| < DIV_EPS. A climber can fit its windows
with a quotient whose denominator changes sign inside the training data, a pole that the
windows step over. Measured on px4-s250 (seed 2): a_z = 57.2 u_T w / (99.0 u_T u_T(t-5) -
48.4 u_T(t-5)) won the selection, its denominator zero at u_T = 0.489, passed by 0.2 % of
the training samples; on the held-out flight 7 of 12 windows of 7 s diverged. Such an
equation is singular inside its own flight envelope, and no reader's simulator flies it.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.tree.encoding import Tree, subtree_end
from gpquad.engine.tree.operators import DIV, DIV_EPS


def denominators(tree: Tree) -> list[tuple[int, int]]:
    """The node range [start, end) of every DIV node's right operand."""
    codes = tree.codes
    out = []
    for i in range(tree.size):
        if codes[i] == DIV:
            start = subtree_end(codes, i + 1)
            out.append((start, subtree_end(codes, start)))
    return out


def crosses_pole(tree: Tree, states: np.ndarray, inputs: np.ndarray, samples) -> bool:
    """Whether a denominator of `tree` takes both signs, or comes within DIV_EPS of zero,
    at the data `samples` (one-step values; inputs at the tree's delays)."""
    samples = np.ascontiguousarray(samples, dtype=np.int64)
    for start, end in denominators(tree):
        codes = np.ascontiguousarray(tree.codes[start:end])
        values = np.ascontiguousarray(tree.values[start:end])
        den = eval_on_samples(codes, values, end - start, tree.delays, states, inputs, samples)
        den = den[np.isfinite(den)]
        if den.size and (den.min() < 0.0 < den.max() or np.abs(den).min() < DIV_EPS):
            return True
    return False


def without_poles(trees: list[Tree], states, inputs, samples) -> list[Tree]:
    """The trees that do not cross a pole at `samples` (crosses_pole); all of them when
    every one does (the selection still needs a choice)."""
    kept = [t for t in trees if not crosses_pole(t, states, inputs, samples)]
    return kept or list(trees)
