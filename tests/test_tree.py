"""Tree encoding, variation operators and export."""

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

import naive
from gpquad.engine.tree.encoding import (
    Tree,
    is_valid,
    node_depths,
    stack_rows,
    subtree_end,
    tree_depth,
)
from gpquad.engine.tree.export import from_sympy, parse_equation, to_latex, to_sympy
from gpquad.engine.tree.operators import ADD, CONST, DIV, MUL, SUB, VAR_BASE
from gpquad.engine.tree.variation import (
    VariationParams,
    constant_mutation,
    fold_constants,
    macro_mutation,
    micro_mutation,
    mutate,
    random_tree,
    replace_with_constant,
)
from gpquad.errors import GpquadError

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
PARAMS = VariationParams(n_variables=13, n_inputs=4)


def test_structure_helpers():
    # (p + 2) * u_R
    codes = [MUL, ADD, VAR_BASE + 6, CONST, VAR_BASE + 10]
    assert is_valid(codes)
    assert not is_valid(codes[:-1])
    assert subtree_end(codes, 1) == 4
    assert node_depths(codes) == [0, 1, 2, 2, 1]
    assert tree_depth(codes) == 2


@given(st.integers(0, 2**32 - 1))
def test_mutations_keep_trees_valid_and_shallow(seed):
    rng = np.random.default_rng(seed)
    tree = random_tree(rng, PARAMS)
    for _ in range(20):
        tree = mutate(rng, tree, PARAMS)
        assert is_valid(tree.codes.tolist())
        assert tree.depth <= PARAMS.max_depth
        assert ((tree.delays >= 0) & (tree.delays <= PARAMS.max_delay)).all()
        assert len(tree.values) == tree.size


@given(st.integers(0, 2**32 - 1))
def test_macro_and_micro_change_one_place(seed):
    rng = np.random.default_rng(seed)
    tree = random_tree(rng, PARAMS)
    for op in (macro_mutation, micro_mutation):
        codes, values = op(rng, tree.codes.tolist(), tree.values.tolist(), PARAMS)
        assert is_valid(codes) and len(codes) == len(values)
        assert tree_depth(codes) <= PARAMS.max_depth


def test_random_trees_use_p_leaf():
    """With p_leaf = 0.7 grown subtrees are mostly single leaves: check the leaf rate."""
    rng = np.random.default_rng(0)
    from gpquad.engine.tree.variation import random_subtree

    sizes = [len(random_subtree(rng, PARAMS, 5)[0]) for _ in range(4000)]
    # P(root is a leaf) = 0.7
    assert np.mean(np.array(sizes) == 1) == pytest.approx(0.7, abs=0.03)


def test_delay_mutation_rate():
    rng = np.random.default_rng(1)
    tree = random_tree(rng, PARAMS)
    changed = 0
    for _ in range(3000):
        changed += (mutate(rng, tree, PARAMS).delays != 0).sum()
    # each of 4 delays is redrawn with p = 0.1 and lands on non-zero with p = 5/6
    assert changed / (3000 * 4) == pytest.approx(0.1 * 5 / 6, abs=0.01)


def test_constant_mutation_is_gaussian_with_variance_0_1():
    rng = np.random.default_rng(2)
    tree = Tree.from_lists([ADD, CONST, VAR_BASE], [0.0, 1.0, 0.0], [0, 0, 0, 0])
    steps = [constant_mutation(rng, tree, PARAMS).values[1] - 1.0 for _ in range(5000)]
    assert np.var(steps) == pytest.approx(0.1, rel=0.06)
    assert abs(np.mean(steps)) < 0.015


def test_replace_with_constant_and_fold():
    rng = np.random.default_rng(3)
    tree = Tree.from_lists([MUL, ADD, CONST, CONST, VAR_BASE + 6], [0, 0, 2.0, 3.0, 0], [0] * 4)
    folded = fold_constants(tree)
    assert folded.codes.tolist() == [MUL, CONST, VAR_BASE + 6]
    assert folded.values[1] == 5.0
    simpler = replace_with_constant(rng, tree, lambda a, b: 7.0)
    assert is_valid(simpler.codes.tolist()) and CONST in simpler.codes


@given(st.integers(0, 2**32 - 1))
def test_fold_constants_preserves_values(seed):
    rng = np.random.default_rng(seed)
    params = VariationParams(n_variables=13, n_inputs=4, p_constant_leaf=0.7)
    tree = random_tree(rng, params)
    leaves = rng.normal(size=13)
    before = naive.eval_tree(tree.codes, tree.values, leaves)
    after = naive.eval_tree(*(lambda t: (t.codes, t.values))(fold_constants(tree)), leaves)
    assert after == pytest.approx(before, rel=1e-12, abs=1e-12)


@given(st.integers(0, 2**32 - 1))
def test_sympy_round_trip(seed):
    """to_sympy then from_sympy gives a tree with the same values (away from protected division)."""
    rng = np.random.default_rng(seed)
    tree = random_tree(rng, PARAMS)
    expr = to_sympy(tree, INPUTS)
    back = from_sympy(expr, {}, INPUTS)
    leaves = rng.normal(size=13)
    a = naive.eval_tree(tree.codes, tree.values, leaves)
    b = naive.eval_tree(back.codes, back.values, leaves)
    if np.isfinite(a) and abs(a) < 1e6 and DIV not in tree.codes:
        assert b == pytest.approx(a, rel=1e-9, abs=1e-9)


def test_parse_equation_with_delays():
    expr, delays = parse_equation("28.2*u_T(t-5) - w - 9.81", INPUTS)
    assert delays == {"u_T": 5}
    assert expr == sp.sympify(
        "28.2*u_T - w - 9.81", locals={n: sp.Symbol(n, real=True) for n in ("u_T", "w")}
    )
    tree = from_sympy(expr, delays, INPUTS)
    assert tree.delays.tolist() == [0, 0, 0, 5]


@pytest.mark.parametrize(
    "text, message",
    [
        # several delays of one input are taps (tests/test_taps.py), up to MAX_TAPS of them
        (
            "u_R + u_R(t-1) + u_R(t-2) + u_R(t-3) + u_R(t-4) + u_R(t-5) + u_R(t-6)",
            "more than 6 delays",
        ),
        ("10*p(t-1)", "only inputs"),
        ("10*zeta", "unknown names"),
        ("10*(p", "cannot parse"),
    ],
)
def test_parse_equation_errors(text, message):
    with pytest.raises(GpquadError, match=message):
        parse_equation(text, INPUTS)


def test_latex_writes_delays():
    expr, delays = parse_equation("28.2*u_T(t-5) - w - 9.81 + theta", INPUTS)
    latex = to_latex(expr, delays, INPUTS)
    assert "u_{T-5}" in latex and r"\theta" in latex


def test_sub_and_div_operand_order():
    tree = Tree.from_lists(
        [SUB, VAR_BASE + 6, DIV, CONST, VAR_BASE + 7], [0, 0, 0, 2.0, 0], [0] * 4
    )
    assert str(to_sympy(tree, INPUTS)) == "p - 2.0/q"


def test_division_by_an_identically_zero_subtree_exports_like_the_kernel():
    # p / (q - q): the kernel's protected division gives 1; sympy alone would give zoo
    tree = Tree.from_lists([DIV, VAR_BASE + 6, SUB, VAR_BASE + 7, VAR_BASE + 7], [0.0] * 5, [0] * 4)
    assert to_sympy(tree, INPUTS) == 1
    assert naive.eval_tree(tree.codes, tree.values, np.arange(13.0)) == 1.0


def test_stack_rows_pads_trees_and_fills_empty_rows_with_zero():
    a = Tree.from_lists([ADD, VAR_BASE, CONST], [0.0, 0.0, 2.0], [1, 2])
    b = Tree.from_lists([VAR_BASE + 9], [0.0], [0, 3, 1, 4])  # a tree with 2 taps of 2 inputs
    codes, values, sizes, delays = stack_rows({0: a, 2: b}, 4, min_slots=2)
    assert codes.shape == values.shape == (4, 3) and delays.shape == (4, 4)
    assert codes[0].tolist() == [ADD, VAR_BASE, CONST] and values[0, 2] == 2.0
    assert codes[2, 0] == VAR_BASE + 9 and sizes.tolist() == [3, 1, 1, 1]
    assert codes[1, 0] == CONST and values[1, 0] == 0.0  # no tree: the constant 0
    assert delays[0].tolist() == [1, 2, 0, 0] and delays[2].tolist() == [0, 3, 1, 4]
    assert delays[1].tolist() == [0, 0, 0, 0]
    assert stack_rows({}, 6, min_slots=4)[3].shape == (6, 4)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 4), min_size=1, max_size=20))
def test_shallow_sum_is_the_sum_of_least_depth(term_depths):
    """Every term once, and the least depth any sum of them can have: the smallest D with
    sum 2**d_i <= 2**D (Kraft's inequality: a term of depth d sits at most D - d deep).
    A balanced sum fails it: a product first and four constants make depth 5, not 3."""
    from gpquad.engine.evolve.term_search import additive_terms
    from gpquad.engine.tree.encoding import shallow_sum

    def chain(depth, k):  # a term of the given depth: x_k * (x_k * (... * c))
        return [(MUL, 0.0)] * depth + [(VAR_BASE + k, 0.0)] * depth + [(CONST, float(k))]

    terms = [chain(d, k) for k, d in enumerate(term_depths)]
    prefix = shallow_sum(terms)
    codes = [c for c, _ in prefix]
    assert is_valid(codes)
    least = next(d for d in range(40) if sum(2**t for t in term_depths) <= 2**d)
    assert tree_depth(codes) == least
    found = sorted(
        tuple(c) for _, c, _ in additive_terms(np.array(codes), np.array([v for _, v in prefix]))
    )
    assert found == sorted(tuple(c for c, _ in t) for t in terms)
