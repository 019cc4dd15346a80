"""Evaluate a flat prefix tree over a batch of lanes (windows or samples).

codes (M,) int64 and values (M,) float64 hold the tree (gpquad.engine.tree.operators),
`size` the number of used nodes. features (n_terminals, n_lanes) holds the
leaf values for every lane; the result goes to out (n_lanes,).
"""

import numpy as np

from gpquad.engine.kernels.divergence import read_leaves
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


@njit(inner=True)
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


@njit(inner=True)
def compile_program(codes, values, size, n_features, regs, prog):
    """The prefix tree as a register program over regs (n_features + size, n_lanes), whose
    first n_features rows are the leaves: node i's value goes to row n_features + i, and a
    constant's row is filled here, once. prog (size, 4) gets one row (op, out, left, right)
    per binary node, in the order of eval_lanes' right-to-left evaluation (the same
    operations on the same values: the same bits). Returns (n_ops, row of the root)."""
    rows = np.empty(size, dtype=np.int64)  # the row of each evaluated subtree, a stack
    sp = 0
    n_ops = 0
    for i in range(size - 1, -1, -1):
        c = codes[i]
        if c >= VAR_BASE:
            rows[sp] = c - VAR_BASE
            sp += 1
        elif c == CONST:
            regs[n_features + i, :] = values[i]
            rows[sp] = n_features + i
            sp += 1
        else:
            prog[n_ops, 0] = c
            prog[n_ops, 1] = n_features + i
            prog[n_ops, 2] = rows[sp - 1]  # left operand
            prog[n_ops, 3] = rows[sp - 2]
            n_ops += 1
            sp -= 1
            rows[sp - 1] = n_features + i
    return n_ops, rows[0]


@njit(inner=True)
def run_program(prog, n_ops, regs, n_lanes):
    """Evaluate a compile_program program on the current leaves (rows of regs)."""
    for j in range(n_ops):
        c = prog[j, 0]
        out = regs[prog[j, 1]]
        left = regs[prog[j, 2]]
        right = regs[prog[j, 3]]
        if c == ADD:
            for lane in range(n_lanes):
                out[lane] = left[lane] + right[lane]
        elif c == SUB:
            for lane in range(n_lanes):
                out[lane] = left[lane] - right[lane]
        elif c == MUL:
            for lane in range(n_lanes):
                out[lane] = left[lane] * right[lane]
        else:
            for lane in range(n_lanes):
                den = right[lane]
                out[lane] = 1.0 if abs(den) < DIV_EPS else left[lane] / den


@njit
def eval_on_samples(codes, values, size, delays, states, inputs, indices):
    """One-step tree values at data samples `indices` (no integration), shape (len(indices),).
    `delays` holds one delay per input column (ValueError otherwise: it would be read past
    its end)."""
    n = indices.shape[0]
    n_state = states.shape[1]
    n_in = inputs.shape[1]
    if delays.shape[0] != n_in:
        raise ValueError("eval_on_samples: the tree needs one delay per input column")
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


@njit(inner=True)
def model_programs(codes, values, sizes, modelled, n_leaves, n_lanes):
    """The register programs of a full model's trees (one per target, compile_program), for
    the rollouts: (regs (6, n_leaves + M, n_lanes), prog (6, M, 4), n_ops (6,), root (6,),
    used (6, n_leaves) the leaves each tree reads); a target not modelled has none."""
    regs = np.zeros((6, n_leaves + codes.shape[1], n_lanes))
    prog = np.empty((6, codes.shape[1], 4), dtype=np.int64)
    n_ops = np.zeros(6, dtype=np.int64)
    root = np.zeros(6, dtype=np.int64)
    used = np.zeros((6, n_leaves), dtype=np.bool_)
    for t in range(6):
        if modelled[t]:
            n_ops[t], root[t] = compile_program(
                codes[t], values[t], sizes[t], n_leaves, regs[t], prog[t]
            )
            leaves = read_leaves(codes[t], sizes[t], n_leaves)
            for i in range(n_leaves):  # a row assignment compiles numba's shape errors
                used[t, i] = leaves[i]
    return regs, prog, n_ops, root, used


@njit(inner=True)
def hold_inputs(regs, used, modelled, delays, inputs, input_noise, starts, k, n_state):
    """Write each modelled tree's input slots (rows n_state + j of regs[t]) for sample k of
    every window (lane): input j % n_inputs at the slot's delay, plus the window's
    input_noise when it has any (shape (0, 0, 0): none)."""
    n_in = inputs.shape[1]
    noisy = input_noise.shape[0] > 0
    for t in range(6):
        if modelled[t]:
            for j in range(delays.shape[1]):
                if not used[t, n_state + j]:
                    continue
                c = j % n_in
                d = delays[t, j]
                for lane in range(starts.shape[0]):
                    u = inputs[starts[lane] + k - d, c]
                    if noisy and k - d >= 0:
                        u += input_noise[lane, k - d, c]
                    regs[t, n_state + j, lane] = u


@njit(inner=True)
def run_model_tree(regs, prog, n_ops, used, t, features, n_lanes):
    """Evaluate tree t of model_programs over the lanes at the state leaves `features`
    (9, n_lanes) (its input slots written by hold_inputs); its value is
    regs[t, root[t]]."""
    tree = regs[t]
    for i in range(features.shape[0]):
        if used[t, i]:
            for lane in range(n_lanes):
                tree[i, lane] = features[i, lane]
    run_program(prog[t], n_ops[t], tree, n_lanes)
