"""What every window kernel counts as a diverged state, and which leaves a tree reads."""

import numpy as np

from gpquad.engine.numba_config import njit
from gpquad.engine.tree.operators import VAR_BASE

DIVERGED = np.inf
#: A state whose magnitude exceeds this (or is NaN) marks the window as diverged.
STATE_LIMIT = 1e6
#: Residual given to every remaining step of a window whose state diverged (sensitivity).
DIVERGED_RESIDUAL = STATE_LIMIT


@njit(inner=True)
def uses_leaves(codes, size, first, last):
    """True if the tree reads a variable leaf first .. last (terminal indices)."""
    for i in range(size):
        c = codes[i] - VAR_BASE
        if first <= c <= last:
            return True
    return False


@njit(inner=True)
def read_leaves(codes, size, n_terminals):
    """(n_terminals,) bool: the variable leaves the tree reads."""
    used = np.zeros(n_terminals, dtype=np.bool_)
    for i in range(size):
        if codes[i] >= VAR_BASE:
            used[codes[i] - VAR_BASE] = True
    return used


@njit(inline="always")
def diverged_rows(res, row, n_rows):
    """A diverged window's residual rows at `row` (the sensitivity kernels' rule)."""
    for extra in range(n_rows):
        res[row + extra] = DIVERGED_RESIDUAL


@njit(inline="always")
def diverged_jacobian_rows(res, jac, row, n_rows):
    """diverged_rows, and their Jacobian rows zero."""
    diverged_rows(res, row, n_rows)
    for extra in range(n_rows):
        jac[row + extra, :] = 0.0
