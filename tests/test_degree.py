"""The degree limit (`max_degree`): tree_degree against sympy, and mutation, new trees,
term insertion and the config respecting it."""

import dataclasses

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.engine.evolve.term_search import term_candidates
from gpquad.engine.tree.encoding import tree_degree
from gpquad.engine.tree.export import from_sympy, parse_equation, to_sympy
from gpquad.engine.tree.operators import DIV
from gpquad.engine.tree.variation import VariationParams, mutate, random_tree
from gpquad.engine.variables import terminal_names
from gpquad.errors import GpquadError
from gpquad.study.config import Config, EvolutionConfig, validate

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
PARAMS = VariationParams(n_variables=13, n_inputs=4, max_depth=6)


def _tree(text):
    expr, delays = parse_equation(text, INPUTS)
    return from_sympy(expr, delays, INPUTS)


@pytest.mark.parametrize("text, degree", [
    ("1.5", 0), ("p", 1), ("0.9*q*r", 2), ("9*u_R(t-2) - 4*p - 0.9*q*r", 2),
    ("phi*theta*u_R*u_T", 4), ("p/(q + r)", 2), ("2*(p + q)*(r - u)", 2)])
def test_degree_of_written_equations(text, degree):
    assert tree_degree(_tree(text).codes) == degree


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_degree_bounds_the_sympy_degree_of_division_free_trees(seed):
    """An upper bound (x y - x y counts 2), equal to sympy's total degree of the tree
    multiplied out whenever nothing cancels."""
    rng = np.random.default_rng(seed)
    tree = random_tree(rng, PARAMS)
    if DIV in tree.codes.tolist():
        return
    names = terminal_names(INPUTS)
    expr = sp.expand(to_sympy(tree, names))
    symbols = sorted(expr.free_symbols, key=str)
    true_degree = sp.Poly(expr, *symbols).total_degree() if symbols else 0
    assert true_degree <= tree_degree(tree.codes)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_mutation_and_new_trees_stay_within_the_degree_limit(seed):
    rng = np.random.default_rng(seed)
    limited = dataclasses.replace(PARAMS, max_degree=2)
    tree = random_tree(rng, limited)
    assert tree_degree(tree.codes) <= 2
    for _ in range(30):
        tree = mutate(rng, tree, limited)
        assert tree_degree(tree.codes) <= 2


def test_without_the_limit_mutation_goes_above_degree_2():
    """The check above can fail: the same operators without a limit make degree-3 trees."""
    rng = np.random.default_rng(0)
    tree, seen = random_tree(rng, PARAMS), 0
    for _ in range(400):
        tree = mutate(rng, tree, PARAMS)
        seen = max(seen, tree_degree(tree.codes))
    assert seen > 2


def test_term_insertion_offers_products_only_within_the_limit():
    model = _tree("-4.0*p + 9.0*u_R")
    limited = dataclasses.replace(PARAMS, max_degree=1)
    kept = [t for t in term_candidates(model, 13, 6) if limited.allows(t.codes)]
    every = term_candidates(model, 13, 6)
    assert max(tree_degree(t.codes) for t in every) == 2
    assert kept and max(tree_degree(t.codes) for t in kept) == 1


@pytest.mark.parametrize("value", [-1, 17])
def test_config_refuses_a_degree_out_of_range(value):
    cfg = Config(evolution=dataclasses.replace(EvolutionConfig(), max_degree=value))
    with pytest.raises(GpquadError, match="evolution.max_degree"):
        validate(cfg, "x.toml")
