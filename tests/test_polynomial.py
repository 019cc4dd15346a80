"""A tree multiplied out into monomials (gpquad.engine.tree.polynomial): the same function,
like terms merged, protected division as the kernels evaluate it, and no expansion where
the tree divides by a variable."""

import numpy as np
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.engine.evolve.coevolution import variation_params
from gpquad.engine.tree.encoding import Tree, shallow_sum
from gpquad.engine.tree.export import from_sympy, parse_equation, to_sympy
from gpquad.engine.tree.operators import DIV, VAR_BASE
from gpquad.engine.tree.polynomial import MAX_MONOMIALS, expand, monomial_terms
from gpquad.engine.tree.random_stream import RandomStream
from gpquad.engine.tree.variation import random_tree
from gpquad.engine.variables import terminal_names
from gpquad.study.config import preset_evolution
from naive import evaluate_on_table

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


def _tree(text):
    expr, delays = parse_equation(text, INPUTS)
    return from_sympy(expr, delays, INPUTS)


def _as_tree(poly, delays):
    prefix = shallow_sum(monomial_terms(poly))
    return Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], delays)


def test_a_product_of_sums_becomes_its_monomials():
    poly = expand(*_tree_arrays("(2*u_T + 3*w)*(1 + 0.5*phi)"))
    assert _named(poly) == {("u_T",): 2.0, ("w",): 3.0, ("phi", "u_T"): 1.0, ("phi", "w"): 1.5}


def _tree_arrays(text):
    t = _tree(text)
    return t.codes, t.values


def _named(poly):
    names = terminal_names(INPUTS)
    return {tuple(sorted(names[v - VAR_BASE] for v in m)): c for m, c in poly.items()}


def test_like_terms_merge_and_cancel():
    assert expand(*_tree_arrays("p*q - q*p + 2")) == {(): 2.0}
    assert _named(expand(*_tree_arrays("p*(q + 1) + (q - 1)*p"))) == {("p", "q"): 2.0}
    assert expand(*_tree_arrays("p - p")) == {(): 0.0}


def test_division_by_a_constant_scales_and_by_a_variable_is_not_expanded():
    assert expand(*_tree_arrays("(4*p + 2)/2")) is not None
    assert sorted(expand(*_tree_arrays("(4*p + 2)/2")).values()) == [1.0, 2.0]
    assert expand(*_tree_arrays("p/q")) is None
    # protected division by a constant below DIV_EPS gives 1, as the kernels evaluate it
    tree = Tree.from_lists([DIV, 5 + 6, 4], [0.0, 0.0, 1e-9], np.zeros(4, dtype=np.int64))
    assert expand(tree.codes, tree.values) == {(): 1.0}


def test_too_many_monomials_are_not_expanded():
    text = "*".join(
        f"({a} + {b})"
        for a, b in [
            ("p", "q"),
            ("r", "u"),
            ("v", "w"),
            ("phi", "theta"),
            ("u_R", "u_P"),
            ("u_T", "u_Y"),
        ]
    )
    assert 2**6 > MAX_MONOMIALS and expand(*_tree_arrays(text)) is None


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_expansion_is_the_same_function(seed):
    rng = np.random.default_rng(seed)
    tree = random_tree(RandomStream(rng), variation_params(preset_evolution(), 4))
    poly = expand(tree.codes, tree.values)
    if poly is None:  # only a division by a variable, or too many monomials
        expr = sp.expand(to_sympy(tree, INPUTS))
        assert DIV in tree.codes.tolist() or len(sp.Add.make_args(expr)) > MAX_MONOMIALS
        return
    table = rng.normal(size=(40, 13))
    a, b = evaluate_on_table(tree, table), evaluate_on_table(_as_tree(poly, tree.delays), table)
    scale = np.maximum(np.abs(a), 1.0)
    assert np.all(np.abs(a - b) <= 1e-9 * scale * max(1.0, max(map(abs, poly.values()))))
