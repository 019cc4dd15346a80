"""The hill climbers' mutation of a whole population in one kernel.

gpquad.engine.tree.variation.mutate is the reference: the same operators, the same draws in
the same order from the same RandomStream, so the same mutants to the bit
(tests/test_variation_reference.py). Per generation the model phase mutates its 14
climbers here instead of in Python, where the mutation cost about 9 us a tree, two fifths
of the phase (docs/decisions/2026-12-07-rows-and-mutation.md).

Trees are rows of padded arrays (codes, values, sizes, delays), as the fitness kernels take
them. The draws are read from the stream's current blocks (RandomStream.uniforms and
.normals from positions `pos`); a block that runs out stops the kernel at that tree with
its positions as they were before it, so that Python draws the next block at the same point
of the sequence as the reference does and the tree is mutated again
(variation.mutate_population).
A mutant that would not fit its row stops the kernel likewise (OVERFLOW), and that tree is
mutated by the reference.
"""

import numpy as np

from gpquad.engine.numba_config import njit
from gpquad.engine.tree.encoding import node_depth, subtree_end, tree_degree
from gpquad.engine.tree.operators import CONST, N_OPERATORS, VAR_BASE

#: The kernel's status (pos[2]): every tree mutated, a stream ran out, a row overflowed.
DONE, NEED_UNIFORM, NEED_NORMAL, OVERFLOW = 0, 1, 2, 3
#: Indices of the float and integer parameters (`params_f`, `params_i`).
P_LEAF, P_CONSTANT_LEAF, CONST_LOW, CONST_HIGH, CONST_SIGMA, P_CONST_PERTURB, P_DELAY = range(7)
MAX_DEPTH, N_INPUTS, MAX_DELAY, MAX_DEGREE, DEGREE_TRIES = range(5)


@njit(inline="always")
def _next(block, pos, slot, short):
    """The next draw of `block` at position pos[slot]; past the block's end 0.0 and the
    status `short` (the first shortage met is the one reported)."""
    i = pos[slot]
    if i >= block.shape[0]:
        if pos[2] == DONE:
            pos[2] = short
        return 0.0
    pos[slot] = i + 1
    return block[i]


@njit(inline="always")
def _uniform(uniforms, pos):
    """The next U[0, 1) draw (NEED_UNIFORM past the block)."""
    return _next(uniforms, pos, 0, NEED_UNIFORM)


@njit(inline="always")
def _normal(normals, pos):
    """The next N(0, 1) draw (NEED_NORMAL past the block)."""
    return _next(normals, pos, 1, NEED_NORMAL)


@njit(inline="always")
def _below(uniforms, pos, n):
    """RandomStream.below: a uniform integer in 0..n-1."""
    return min(int(_uniform(uniforms, pos) * n), n - 1)


#: encoding's own structural helpers, compiled for the kernel (the same code, not a copy).
_node_depth = njit(inner=True)(node_depth)
_subtree_end = njit(inner=True)(subtree_end)
_tree_degree = njit(inner=True)(tree_degree)


@njit(inner=True)
def _random_subtree(uniforms, pos, params_f, variables, max_depth, codes, values, at, stack):
    """variation.random_subtree written into codes/values from `at`; returns the index after
    it, or -1 when it would not fit (the status OVERFLOW)."""
    p_leaf = params_f[P_LEAF]
    p_constant = params_f[P_CONSTANT_LEAF]
    low = params_f[CONST_LOW]
    span = params_f[CONST_HIGH] - params_f[CONST_LOW]
    n_leaves = variables.shape[0]
    stack[0] = max_depth
    top = 1
    while top > 0:
        if at >= codes.shape[0] or top + 2 > stack.shape[0]:
            pos[2] = OVERFLOW
            return -1
        top -= 1
        depth_left = stack[top]
        if depth_left == 0 or _uniform(uniforms, pos) < p_leaf:
            if _uniform(uniforms, pos) < p_constant:
                codes[at] = CONST
                values[at] = low + span * _uniform(uniforms, pos)
                at += 1
                continue
            k = min(int(_uniform(uniforms, pos) * n_leaves), n_leaves - 1)
            codes[at] = VAR_BASE + variables[k]
        else:
            codes[at] = min(int(_uniform(uniforms, pos) * N_OPERATORS), N_OPERATORS - 1)
            stack[top] = depth_left - 1
            stack[top + 1] = depth_left - 1
            top += 2
        values[at] = 0.0
        at += 1
    return at


@njit(inner=True)
def _copy(src_c, src_v, start, end, dst_c, dst_v, at):
    """dst[at:] = src[start:end]; returns the index after it, or -1 when it does not fit."""
    if at + end - start > dst_c.shape[0]:
        return -1
    for k in range(start, end):
        dst_c[at] = src_c[k]
        dst_v[at] = src_v[k]
        at += 1
    return at


@njit(inner=True)
def _structure(uniforms, pos, params_f, params_i, variables, codes, values, size, out_c, out_v):
    """One macro or micro mutation (variation.mutate's draw) of codes[:size] into out;
    returns the mutant's size, or -1 when it does not fit (the status OVERFLOW)."""
    max_depth = params_i[MAX_DEPTH]
    stack = np.empty(2 * max_depth + 64, dtype=np.int64)
    if _uniform(uniforms, pos) < 0.5:  # macro_mutation
        i = _below(uniforms, pos, size)
        depth = _node_depth(codes, i)
        was_op = codes[i] < N_OPERATORS
        if depth < max_depth and _uniform(uniforms, pos) >= params_f[P_LEAF]:
            new_op = _below(uniforms, pos, N_OPERATORS)
            if was_op:
                at = _copy(codes, values, 0, size, out_c, out_v, 0)
                if at < 0:
                    pos[2] = OVERFLOW
                    return -1
                out_c[i] = new_op
                out_v[i] = 0.0
                return size
            at = _copy(codes, values, 0, i, out_c, out_v, 0)
            if at < 0 or at >= out_c.shape[0]:
                pos[2] = OVERFLOW
                return -1
            out_c[at] = new_op
            out_v[at] = 0.0
            at += 1
            for _ in range(2):  # the left subtree, then the right
                at = _random_subtree(
                    uniforms,
                    pos,
                    params_f,
                    variables,
                    max_depth - depth - 1,
                    out_c,
                    out_v,
                    at,
                    stack,
                )
                if at < 0:
                    return -1
            at = _copy(codes, values, i + 1, size, out_c, out_v, at)
        else:
            end = _subtree_end(codes, i)
            at = _copy(codes, values, 0, i, out_c, out_v, 0)
            if at < 0 or at >= out_c.shape[0]:
                pos[2] = OVERFLOW
                return -1
            if _uniform(uniforms, pos) < params_f[P_CONSTANT_LEAF]:  # random_leaf
                out_c[at] = CONST
                low, high = params_f[CONST_LOW], params_f[CONST_HIGH]
                out_v[at] = low + (high - low) * _uniform(uniforms, pos)
            else:
                out_c[at] = VAR_BASE + variables[_below(uniforms, pos, variables.shape[0])]
                out_v[at] = 0.0
            at = _copy(codes, values, end, size, out_c, out_v, at + 1)
    else:  # micro_mutation
        i = _below(uniforms, pos, size)
        depth = _node_depth(codes, i)
        end = _subtree_end(codes, i)
        at = _copy(codes, values, 0, i, out_c, out_v, 0)
        if at >= 0:
            at = _random_subtree(
                uniforms, pos, params_f, variables, max_depth - depth, out_c, out_v, at, stack
            )
        if at >= 0:
            at = _copy(codes, values, end, size, out_c, out_v, at)
    if at < 0:
        pos[2] = OVERFLOW
    return at


@njit(nogil=True)
def mutate_rows(
    codes,
    values,
    sizes,
    delays,
    first,
    uniforms,
    normals,
    pos,
    params_f,
    params_i,
    variables,
    out_codes,
    out_values,
    out_sizes,
    out_delays,
):
    """variation.mutate of rows first.. of (codes, values, sizes, delays) into the out rows
    (their tails past each size zeroed, as Evaluator.pack pads). pos: the uniform and
    normal positions in their blocks and the status (DONE ...). Returns the row it stopped
    at (the number of rows when every one is done), its positions as before that row."""
    n_rows = codes.shape[0]
    max_degree = params_i[MAX_DEGREE]
    for t in range(first, n_rows):
        u0, n0 = pos[0], pos[1]
        size = sizes[t]
        out_c, out_v = out_codes[t], out_values[t]
        n = -1
        for _ in range(params_i[DEGREE_TRIES]):
            n = _structure(
                uniforms,
                pos,
                params_f,
                params_i,
                variables,
                codes[t],
                values[t],
                size,
                out_c,
                out_v,
            )
            if n < 0 or max_degree <= 0 or _tree_degree(out_c[:n]) <= max_degree:
                break
            n = -1
        if pos[2] == DONE and n < 0:  # the degree limit refused every draw: the parent's
            n = _copy(codes[t], values[t], 0, size, out_c, out_v, 0)
            if n < 0:
                pos[2] = OVERFLOW
        if pos[2] == DONE and _uniform(uniforms, pos) < params_f[P_CONST_PERTURB]:
            n_const = 0
            for k in range(n):
                if out_c[k] == CONST:
                    n_const += 1
            if n_const > 0:  # variation.perturb_constant
                pick = _below(uniforms, pos, n_const)
                for k in range(n):
                    if out_c[k] == CONST:
                        if pick == 0:
                            out_v[k] += params_f[CONST_SIGMA] * _normal(normals, pos)
                            break
                        pick -= 1
        for j in range(delays.shape[1]):
            out_delays[t, j] = delays[t, j]
        for j in range(params_i[N_INPUTS]):
            if _uniform(uniforms, pos) < params_f[P_DELAY]:
                out_delays[t, j] = _below(uniforms, pos, params_i[MAX_DELAY] + 1)
        if pos[2] != DONE:
            pos[0], pos[1] = u0, n0
            return t
        out_sizes[t] = n
        for k in range(n, out_codes.shape[1]):
            out_c[k] = 0
            out_v[k] = 0.0
    return n_rows
