"""The tree's value and gradient by reverse mode (gpquad.engine.kernels.tree_tangent)
against plain-Python references: the operands' positions of a recursive parse, the
recursive value, and the forward-mode gradient with the leaves' tangents."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_kernels import N_VARS, as_tree, prefix_trees

import naive
from gpquad.engine.kernels.tree_tangent import (
    constant_slots,
    eval_with_gradient,
    gradient_work,
    right_children,
)
from gpquad.engine.numba_config import python_callable
from gpquad.engine.tree.operators import CONST, MUL, VAR_BASE

constant_slots = python_callable(constant_slots)
right_children = python_callable(right_children)
gradient_work = python_callable(gradient_work)
eval_with_gradient = python_callable(eval_with_gradient)


def _gradient(tree, leaves, tangents, n_tangent=None):
    n_c = int(np.count_nonzero(tree.codes == CONST))
    grad = np.empty(n_c)
    value = eval_with_gradient(
        tree.codes,
        tree.values,
        tree.size,
        constant_slots(tree.codes, tree.size),
        np.asarray(leaves, dtype=float),
        np.ascontiguousarray(tangents, dtype=float).reshape(len(leaves), n_c),
        gradient_work(tree.codes, tree.size, len(leaves)),
        grad,
        np.arange(len(leaves) if n_tangent is None else n_tangent),
    )
    return value, grad


@given(prefix_trees)
def test_right_operands_are_those_of_a_recursive_parse(nodes):
    tree = as_tree(nodes)
    assert right_children(tree.codes, tree.size).tolist() == naive.right_operands(tree.codes)


@settings(max_examples=60, deadline=None)
@given(
    prefix_trees,
    st.lists(st.floats(-2, 2), min_size=N_VARS, max_size=N_VARS),
    st.integers(0, 2**32 - 1),
)
def test_value_is_the_recursive_one_and_gradient_the_forward_modes(nodes, leaves, seed):
    tree = as_tree(nodes)
    n_c = int(np.count_nonzero(tree.codes == CONST))
    # the states' leaves carry tangents (a flown state depends on the constants), the
    # inputs' do not
    tangents = np.random.default_rng(seed).normal(size=(N_VARS, n_c))
    tangents[9:] = 0.0
    value, grad = _gradient(tree, leaves, tangents)
    assert value == naive.eval_tree(tree.codes, tree.values, leaves)  # the same operations
    ref_value, ref_grad = naive.eval_with_tangent(tree.codes, tree.values, leaves, tangents)
    assert value == ref_value
    scale = 1.0 + np.abs(ref_grad).max(initial=0.0)
    assert np.allclose(grad, ref_grad, rtol=1e-12, atol=1e-12 * scale)


def test_a_leafs_tangent_enters_through_its_adjoint():
    """c0 * p * p + c1 with dp/dc = (t0, t1): d/dc0 = p^2 + 2 c0 p t0, d/dc1 = 1 + 2 c0 p t1.
    A gradient that left out the leaves' tangents (the bad case) would give p^2 and 1."""
    p, c0 = 0.7, 1.5
    nodes = [(0, 0.0), (MUL, 0.0), (CONST, c0), (MUL, 0.0), (VAR_BASE + 6, 0.0)]
    nodes += [(VAR_BASE + 6, 0.0), (CONST, -0.4)]
    tree = as_tree(nodes)
    leaves = np.zeros(N_VARS)
    leaves[6] = p
    tangents = np.zeros((N_VARS, 2))
    tangents[6] = (0.3, -0.2)
    value, grad = _gradient(tree, leaves, tangents)
    assert value == pytest.approx(c0 * p * p - 0.4)
    assert grad == pytest.approx([p * p + 2 * c0 * p * 0.3, 1.0 + 2 * c0 * p * -0.2])
    _, without = _gradient(tree, leaves, np.zeros((N_VARS, 2)))
    assert without == pytest.approx([p * p, 1.0])
    assert not np.allclose(grad, without)


def test_only_the_moving_leaves_tangents_are_read():
    """The kernels name the leaves whose tangents they follow (the states'): an input's row
    is not read. A tangent in an input's row counts when its leaf is named (the bad case
    for a kernel whose inputs had tangents) and not with the nine states."""
    u = VAR_BASE + 9  # the first input
    tree = as_tree([(MUL, 0.0), (CONST, 2.0), (MUL, 0.0), (VAR_BASE + 6, 0.0), (u, 0.0)])
    leaves = np.arange(1.0, N_VARS + 1.0)
    tangents = np.zeros((N_VARS, 1))
    tangents[6, 0] = 1.0  # d p / d c
    tangents[9, 0] = 5.0  # an input's row, not zero
    _, every_row = _gradient(tree, leaves, tangents)
    _, states_only = _gradient(tree, leaves, tangents, 9)
    p, u_value = leaves[6], leaves[9]
    assert states_only[0] == pytest.approx(p * u_value + 2.0 * u_value * 1.0)
    assert every_row[0] == pytest.approx(states_only[0] + 2.0 * p * 5.0)
