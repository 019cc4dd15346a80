"""The kernels' evaluation stack (gpquad.engine.kernels.tree_eval): its exact height, the
wide but shallow trees it evaluates, and the deep ones it refuses before a kernel writes
past its STACK_ROWS rows (numba has no bounds check)."""

import numpy as np
import pytest
from conftest import truth_dataset
from hypothesis import given, settings
from hypothesis import strategies as st

import naive
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import residuals_and_jacobian
from gpquad.engine.kernels.tree_eval import STACK_ROWS, check_stack, eval_lanes, stack_height
from gpquad.engine.numba_config import python_callable
from gpquad.engine.tree.encoding import Tree, shallow_sum, tree_depth
from gpquad.engine.tree.operators import ADD, CONST, MUL, VAR_BASE
from gpquad.models.equations import DiscoveredModel, Equation

eval_lanes = python_callable(eval_lanes)

N_VARS = 13


def _tree(prefix) -> Tree:
    return Tree.from_lists(
        [c for c, _ in prefix], [v for _, v in prefix], np.zeros(4, dtype=np.int64)
    )


def _products(n_terms):
    """[c_k * x_(k mod 13)] as prefix lists."""
    return [
        [(MUL, 0.0), (CONST, 0.001 * (k + 1)), (VAR_BASE + k % N_VARS, 0.0)] for k in range(n_terms)
    ]


def _left_comb(n_leaves) -> Tree:
    """(((x0 + x1) + x2) + ...): every left operand is the deepest, the worst case."""
    prefix = [(ADD, 0.0)] * (n_leaves - 1) + [(VAR_BASE + k % N_VARS, 0.0) for k in range(n_leaves)]
    return _tree(prefix)


def _height_reference(codes) -> int:
    """h(leaf) = 1, h(op left right) = max(h(right), 1 + h(left)): right's value waits on
    the stack while left is evaluated."""
    pos = 0

    def rec():
        nonlocal pos
        c = int(codes[pos])
        pos += 1
        if c == CONST or c >= VAR_BASE:
            return 1
        left = rec()
        right = rec()
        return max(right, 1 + left)

    return rec()


leaf = st.one_of(
    st.just([(CONST, 1.5)]), st.integers(0, N_VARS - 1).map(lambda k: [(VAR_BASE + k, 0.0)])
)
trees = st.recursive(
    leaf,
    lambda sub: st.tuples(st.integers(0, 3), sub, sub).map(lambda t: [(t[0], 0.0)] + t[1] + t[2]),
    max_leaves=40,
)


@settings(max_examples=80, deadline=None)
@given(trees)
def test_stack_height_is_exact_and_bounded_by_depth(prefix):
    tree = _tree(prefix)
    height = stack_height(tree.codes, tree.size)
    assert height == _height_reference(tree.codes)
    assert height <= tree_depth(tree.codes) + 1


def test_shallow_sum_of_many_products_is_evaluated():
    """The linear seed of 9 states and 4 inputs x 6 taps is a sum of 33 products and a
    constant (67 leaves): more leaves than stack rows, but 8 rows high."""
    tree = _tree(shallow_sum(_products(33) + [[(CONST, 0.25)]]))
    assert (tree.size + 1) // 2 > STACK_ROWS
    assert stack_height(tree.codes, tree.size) <= 8
    rng = np.random.default_rng(3)
    lanes = rng.normal(size=(5, N_VARS))
    ds = truth_dataset({"p_dot": "-4.0*p + 9.0*u_R"}, duration_s=20.0, seed=1)
    ev = Evaluator(ds, "p_dot", 50, "mse")
    starts = np.array([10, 100], dtype=np.int64)
    assert np.all(np.isfinite(ev.window_errors([tree], starts)))
    res, jac, _ = residuals_and_jacobian(ev, tree, starts, 50)
    assert jac.shape == (100, 34) and np.all(np.isfinite(jac))

    out = np.empty(len(lanes))
    eval_lanes(
        tree.codes,
        tree.values,
        tree.size,
        np.ascontiguousarray(lanes.T),
        np.empty((STACK_ROWS, len(lanes))),
        out,
        len(lanes),
    )
    ref = [naive.eval_tree(tree.codes, tree.values, lane) for lane in lanes]
    np.testing.assert_allclose(out, ref, rtol=1e-12)


def test_a_tree_deeper_than_the_stack_is_refused_everywhere():
    at_limit, beyond = _left_comb(STACK_ROWS), _left_comb(STACK_ROWS + 1)
    assert stack_height(beyond.codes, beyond.size) == STACK_ROWS + 1
    check_stack(at_limit.codes, at_limit.size)
    with pytest.raises(ValueError, match="stack"):
        check_stack(beyond.codes, beyond.size)
    ds = truth_dataset({"p_dot": "-4.0*p + 9.0*u_R"}, duration_s=20.0, seed=1)
    ev = Evaluator(ds, "p_dot", 50, "mse")
    starts = np.array([10, 100], dtype=np.int64)
    assert np.all(np.isfinite(ev.window_errors([at_limit], starts)))
    with pytest.raises(ValueError, match="stack"):
        ev.window_errors([at_limit, beyond], starts)  # one bad tree in a population
    with pytest.raises(ValueError, match="stack"):
        residuals_and_jacobian(ev, beyond, starts, 50)
    equation = Equation("p_dot", beyond, ds.input_names, 0.0, 0.0)
    model = DiscoveredModel({"p_dot": equation}, ds.input_names, ds.trim, ds.dt, 0, {})
    with pytest.raises(ValueError, match="stack"):
        model.simulate(ds, starts, 10)
