"""A prefix tree's value and its gradient with respect to its constants, by reverse mode
(the sensitivity kernels' inner loop; tests/naive.py holds the forward-mode reference)."""

import numpy as np

from gpquad.engine.kernels.tree_eval import compile_program, run_program
from gpquad.engine.numba_config import njit
from gpquad.engine.tree.operators import ADD, CONST, DIV_EPS, MUL, SUB, VAR_BASE


@njit
def residual_rows(target, att_weight):
    """Residual rows per window step: 2 with an angle row (an angular target whose angle is
    weighted), else 1."""
    return 2 if target >= 3 and att_weight > 0.0 else 1


@njit(inner=True)
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


@njit(inner=True)
def right_children(codes, size):
    """(size,) index of each operator node's right operand in a prefix tree (its left one
    is the next node); -1 for the leaves. The stack walk of the evaluation, right to left:
    an operator's operands are the two subtrees on top."""
    right = np.full(size, -1, dtype=np.int64)
    roots = np.empty(size, dtype=np.int64)  # roots of the subtrees evaluated, a stack
    sp = 0
    for i in range(size - 1, -1, -1):
        if codes[i] < CONST:  # an operator: its left operand on top, its right one below
            right[i] = roots[sp - 2]
            sp -= 2
        roots[sp] = i
        sp += 1
    return right


@njit(inner=True)
def tangent_leaves(linear, axis, angles):
    """The leaves whose tangents a per-equation sensitivity kernel follows: a linear
    target's u, v, w; an angular target's own rate, and the Euler angles when `angles`."""
    if linear:
        return np.array([3, 4, 5], dtype=np.int64)
    if angles:
        return np.array([0, 1, 2, 6 + axis], dtype=np.int64)
    return np.array([6 + axis], dtype=np.int64)


@njit(inner=True)
def gradient_work(codes, size, n_terminals):
    """eval_with_gradient's work for one tree: (its right operands (right_children), node
    values, node adjoints (size,), leaf adjoints (n_terminals,))."""
    return right_children(codes, size), np.empty(size), np.empty(size), np.empty(n_terminals)


@njit(inner=True)
def eval_with_gradient(codes, values, size, slot_of, features, tangents, work, grad, moving):
    """Value of the tree at one sample and its gradient w.r.t. the constants (grad, (n_c,)),
    by reverse mode: O(size + state leaves read x n_c), where forward mode (every node
    carrying n_c derivatives) costs O(size x n_c).

    slot_of (size,): column of each CONST node (-1 otherwise); features (n_terminals,);
    tangents (n_terminals, n_c): d(leaf)/d(constants), of which only the rows `moving`
    (int64 leaf indices) are read: the leaves a flight integrates (an input, or a state
    held from the data, has no tangent; `tangent_leaves` gives them); work:
    gradient_work(codes, size, n_terminals). The value is the stack evaluation's to the bit
    (the same operations in the same order). Returns the value."""
    right, node_value, node_adjoint, leaf_adjoint = work
    for i in range(size - 1, -1, -1):
        c = codes[i]
        if c >= VAR_BASE:
            node_value[i] = features[c - VAR_BASE]
        elif c == CONST:
            node_value[i] = values[i]
        else:
            a = node_value[i + 1]
            b = node_value[right[i]]
            if c == ADD:
                node_value[i] = a + b
            elif c == SUB:
                node_value[i] = a - b
            elif c == MUL:
                node_value[i] = a * b
            elif abs(b) < DIV_EPS:
                node_value[i] = 1.0
            else:
                node_value[i] = a / b
    n_c = grad.shape[0]
    for j in range(n_c):
        grad[j] = 0.0
    for k in range(leaf_adjoint.shape[0]):
        leaf_adjoint[k] = 0.0
    node_adjoint[0] = 1.0
    for i in range(size):
        c = codes[i]
        g = node_adjoint[i]
        if c >= VAR_BASE:
            leaf_adjoint[c - VAR_BASE] += g
        elif c == CONST:
            if slot_of[i] >= 0:
                grad[slot_of[i]] += g
        else:
            left, r = i + 1, right[i]
            if c == ADD:
                node_adjoint[left] = g
                node_adjoint[r] = g
            elif c == SUB:
                node_adjoint[left] = g
                node_adjoint[r] = -g
            elif c == MUL:
                node_adjoint[left] = g * node_value[r]
                node_adjoint[r] = g * node_value[left]
            else:
                b = node_value[r]
                if abs(b) < DIV_EPS:
                    node_adjoint[left] = 0.0
                    node_adjoint[r] = 0.0
                else:
                    node_adjoint[left] = g / b
                    node_adjoint[r] = -g * node_value[i] / b
    for m in range(moving.shape[0]):
        k = moving[m]
        g = leaf_adjoint[k]
        if g != 0.0:
            for j in range(n_c):
                grad[j] += g * tangents[k, j]
    return node_value[0]


@njit(inner=True)
def lanes_gradient_program(codes, values, size, n_terminals, n_lanes):
    """lanes_eval_with_gradient's program and work for up to n_lanes lanes: (regs
    (n_terminals + size, n_lanes), whose first n_terminals rows are the leaves the caller
    writes; prog, n_ops, root: the tree as a register program over regs
    (tree_eval.compile_program, its constants' rows filled once); row_of (size,): the regs
    row holding each node's value; node adjoints (size, n_lanes); leaf adjoints
    (n_terminals, n_lanes))."""
    regs = np.zeros((n_terminals + size, n_lanes))
    prog = np.empty((size, 4), dtype=np.int64)
    n_ops, root = compile_program(codes, values, size, n_terminals, regs, prog)
    row_of = np.empty(size, dtype=np.int64)
    for i in range(size):
        row_of[i] = codes[i] - VAR_BASE if codes[i] >= VAR_BASE else n_terminals + i
    node_adjoint = np.empty((size, n_lanes))
    leaf_adjoint = np.empty((n_terminals, n_lanes))
    return regs, prog, n_ops, root, row_of, node_adjoint, leaf_adjoint


@njit(inner=True)
def lanes_eval_with_gradient(codes, size, slot_of, right, program, grad, pred, n):
    """eval_with_gradient for lanes 0..n-1 at once, the tree walked once for all of them
    (program: lanes_gradient_program's, its leaf rows holding one column per lane), before
    the leaves' tangents: pred (L,) gets the values, grad (n_c, L) the gradients through the
    constants' own nodes, and the program's leaf adjoints each leaf's adjoint, whose product
    with the leaf's tangents the caller adds in eval_with_gradient's order (`moving` first
    to last). The values come from the register program (no copies of the leaves); each
    lane's arithmetic is eval_with_gradient's, in its order: the same bits.
    right: right_children(codes, size)."""
    regs, prog, n_ops, root, row_of, node_adjoint, leaf_adjoint = program
    run_program(prog, n_ops, regs, n)
    grad[:, :n] = 0.0
    leaf_adjoint[:, :n] = 0.0
    node_adjoint[0, :n] = 1.0
    for i in range(size):
        c = codes[i]
        if c >= VAR_BASE:
            for lane in range(n):
                leaf_adjoint[c - VAR_BASE, lane] += node_adjoint[i, lane]
        elif c == CONST:
            if slot_of[i] >= 0:
                for lane in range(n):
                    grad[slot_of[i], lane] += node_adjoint[i, lane]
        else:
            left, r = i + 1, right[i]
            if c == ADD:
                for lane in range(n):
                    node_adjoint[left, lane] = node_adjoint[i, lane]
                    node_adjoint[r, lane] = node_adjoint[i, lane]
            elif c == SUB:
                for lane in range(n):
                    node_adjoint[left, lane] = node_adjoint[i, lane]
                    node_adjoint[r, lane] = -node_adjoint[i, lane]
            elif c == MUL:
                a, b = row_of[left], row_of[r]
                for lane in range(n):
                    g = node_adjoint[i, lane]
                    node_adjoint[left, lane] = g * regs[b, lane]
                    node_adjoint[r, lane] = g * regs[a, lane]
            else:
                b, own = row_of[r], row_of[i]
                for lane in range(n):
                    g, den = node_adjoint[i, lane], regs[b, lane]
                    if abs(den) < DIV_EPS:
                        node_adjoint[left, lane] = 0.0
                        node_adjoint[r, lane] = 0.0
                    else:
                        node_adjoint[left, lane] = g / den
                        node_adjoint[r, lane] = -g * regs[own, lane] / den
    for lane in range(n):
        pred[lane] = regs[root, lane]
