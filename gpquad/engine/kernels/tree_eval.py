"""Evaluate a flat prefix tree over a batch of lanes (windows or samples).

codes (M,) int64 and values (M,) float64 hold the tree (gpquad.engine.tree.operators),
`size` the number of used nodes. features (n_terminals, n_lanes) holds the
leaf values for every lane; the result goes to out (n_lanes,).
"""

import numpy as np

from gpquad.engine.numba_config import njit
from gpquad.engine.tree.operators import ADD, CONST, DIV, DIV_EPS, MUL, SUB, VAR_BASE

#: Rows of the evaluation stack of every kernel (no bounds check in numba). A right-to-left
#: evaluation of "op left right" holds right's value while it evaluates left, so the height
#: grows with the depth of left operands, not with the leaves: a depth-d tree needs at most
#: d + 1 rows, a shallow sum of 33 products (67 leaves) 8. Only a left comb of more than
#: 64 leaves needs more, and `check_stack` refuses it before any kernel runs.
STACK_ROWS = 64


@njit
def stack_height(codes, size):
    """Rows the right-to-left evaluation of a prefix tree of `size` nodes needs."""
    sp = 0
    height = 0
    for i in range(size - 1, -1, -1):
        if codes[i] >= VAR_BASE or codes[i] == CONST:
            sp += 1
            if sp > height:
                height = sp
        else:
            sp -= 1
    return height


@njit
def population_stack_height(codes, sizes):
    """Largest stack_height over the rows of a packed population codes (P, M), sizes (P,)."""
    height = 0
    for i in range(codes.shape[0]):
        height = max(height, stack_height(codes[i], sizes[i]))
    return height


def check_stack(codes, sizes) -> None:
    """Raise ValueError if a tree of the packed population needs more than STACK_ROWS rows
    (a numba kernel would write past its stack)."""
    codes = np.atleast_2d(np.asarray(codes, dtype=np.int64))
    sizes = np.atleast_1d(np.asarray(sizes, dtype=np.int64))
    height = population_stack_height(codes, sizes)
    if height > STACK_ROWS:
        raise ValueError(
            f"a tree needs an evaluation stack of {height} rows; the kernels have {STACK_ROWS}"
        )


@njit
def eval_lanes(codes, values, size, features, stack, out, n_lanes):
    """Stack evaluation of the prefix tree, right to left, vectorised over lanes."""
    sp = 0
    for i in range(size - 1, -1, -1):
        c = codes[i]
        if c >= VAR_BASE:
            k = c - VAR_BASE
            for lane in range(n_lanes):
                stack[sp, lane] = features[k, lane]
            sp += 1
        elif c == CONST:
            v = values[i]
            for lane in range(n_lanes):
                stack[sp, lane] = v
            sp += 1
        else:
            top = sp - 1  # left operand
            res = sp - 2  # right operand, overwritten by the result
            if c == ADD:
                for lane in range(n_lanes):
                    stack[res, lane] = stack[top, lane] + stack[res, lane]
            elif c == SUB:
                for lane in range(n_lanes):
                    stack[res, lane] = stack[top, lane] - stack[res, lane]
            elif c == MUL:
                for lane in range(n_lanes):
                    stack[res, lane] = stack[top, lane] * stack[res, lane]
            elif c == DIV:
                for lane in range(n_lanes):
                    den = stack[res, lane]
                    if abs(den) < DIV_EPS:
                        stack[res, lane] = 1.0
                    else:
                        stack[res, lane] = stack[top, lane] / den
            sp -= 1
    for lane in range(n_lanes):
        out[lane] = stack[0, lane]


@njit
def eval_on_samples(codes, values, size, delays, states, inputs, indices):
    """One-step tree values at data samples `indices` (no integration), shape (len(indices),)."""
    n = indices.shape[0]
    n_state = states.shape[1]
    n_in = inputs.shape[1]
    features = np.empty((n_state + n_in, n))
    for lane in range(n):
        idx = indices[lane]
        for k in range(n_state):
            features[k, lane] = states[idx, k]
        for j in range(n_in):
            features[n_state + j, lane] = inputs[max(idx - delays[j], 0), j]
    stack = np.empty((STACK_ROWS, n))
    out = np.empty(n)
    eval_lanes(codes, values, size, features, stack, out, n)
    return out
