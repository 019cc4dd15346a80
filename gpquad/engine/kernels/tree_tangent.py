"""A prefix tree's value and its gradient with respect to its constants (forward mode)."""

import numpy as np

from gpquad.engine.numba_config import njit
from gpquad.engine.tree.operators import ADD, CONST, DIV, DIV_EPS, MUL, SUB, VAR_BASE


@njit
def residual_rows(target, att_weight):
    """Residual rows per window step: 2 with an angle row (an angular target whose angle is
    weighted), else 1."""
    return 2 if target >= 3 and att_weight > 0.0 else 1


@njit
def constant_slots(codes, size):
    """(size,) column of each CONST node of a prefix tree in the constants' order, -1 for
    the other nodes."""
    slot_of = np.full(size, -1, dtype=np.int64)
    j = 0
    for i in range(size):
        if codes[i] == CONST:
            slot_of[i] = j
            j += 1
    return slot_of


@njit
def eval_with_tangent(codes, values, size, slot_of, features, tangents, stack, dstack, grad):
    """Value of the tree at one sample and its gradient w.r.t. the constants (grad, (n_c,)).

    slot_of (size,): column of each CONST node (-1 otherwise); features (n_terminals,);
    tangents (n_terminals, n_c): d(leaf)/d(constants); stack (STACK_ROWS,), dstack
    (STACK_ROWS, n_c) are work buffers. Returns the value.
    """
    n_c = grad.shape[0]
    sp = 0
    for i in range(size - 1, -1, -1):
        c = codes[i]
        if c >= VAR_BASE:
            k = c - VAR_BASE
            stack[sp] = features[k]
            for j in range(n_c):
                dstack[sp, j] = tangents[k, j]
            sp += 1
        elif c == CONST:
            stack[sp] = values[i]
            for j in range(n_c):
                dstack[sp, j] = 0.0
            if slot_of[i] >= 0:
                dstack[sp, slot_of[i]] = 1.0
            sp += 1
        else:
            top = sp - 1  # left operand
            res = sp - 2  # right operand, overwritten by the result
            a = stack[top]
            b = stack[res]
            if c == ADD:
                stack[res] = a + b
                for j in range(n_c):
                    dstack[res, j] = dstack[top, j] + dstack[res, j]
            elif c == SUB:
                stack[res] = a - b
                for j in range(n_c):
                    dstack[res, j] = dstack[top, j] - dstack[res, j]
            elif c == MUL:
                stack[res] = a * b
                for j in range(n_c):
                    dstack[res, j] = dstack[top, j] * b + a * dstack[res, j]
            elif c == DIV:
                if abs(b) < DIV_EPS:
                    stack[res] = 1.0
                    for j in range(n_c):
                        dstack[res, j] = 0.0
                else:
                    q = a / b
                    stack[res] = q
                    for j in range(n_c):
                        dstack[res, j] = (dstack[top, j] - q * dstack[res, j]) / b
            sp -= 1
    for j in range(n_c):
        grad[j] = dstack[0, j]
    return stack[0]
