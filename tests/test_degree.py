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
from gpquad.study.config import Config, preset_evolution, validate

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
PARAMS = VariationParams(n_variables=13, n_inputs=4, max_depth=6)


def _tree(text):
    expr, delays = parse_equation(text, INPUTS)
    return from_sympy(expr, delays, INPUTS)


@pytest.mark.parametrize(
    "text, degree",
    [
        ("1.5", 0),
        ("p", 1),
        ("0.9*q*r", 2),
        ("9*u_R(t-2) - 4*p - 0.9*q*r", 2),
        ("phi*theta*u_R*u_T", 4),
        ("p/(q + r)", 2),
        ("2*(p + q)*(r - u)", 2),
    ],
)
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
    cfg = Config(evolution=dataclasses.replace(preset_evolution(), max_degree=value))
    with pytest.raises(GpquadError, match="evolution.max_degree"):
        validate(cfg, "x.toml")


def test_depth_and_degree_tables_per_target():
    from gpquad.study.config import config_from_dict

    ev = config_from_dict(
        {"evolution": {"max_depth": {"p_dot": 7}, "max_degree": {"p_dot": 2}}}, "x.toml"
    ).evolution
    assert (ev.depth_for("p_dot"), ev.depth_for("a_x")) == (7, 5)  # left out: the paper's 5
    assert (ev.degree_for("p_dot"), ev.degree_for("a_x")) == (2, 0)  # left out: no limit
    resolved = ev.for_target("p_dot")
    assert (resolved.max_depth, resolved.max_degree, resolved.input_taps) == (7, 2, 6)


@pytest.mark.parametrize(
    "table, field",
    [
        ({"max_depth": {"p_dt": 7}}, "evolution.max_depth.p_dt"),
        ({"max_depth": {"a_x": 9}}, "evolution.max_depth.a_x"),
        ({"max_degree": {"r_dot": -1}}, "evolution.max_degree.r_dot"),
        ({"max_depth": True}, "evolution.max_depth"),
    ],
)
def test_tables_name_the_bad_key(table, field):
    from gpquad.study.config import config_from_dict

    with pytest.raises(GpquadError, match=field.replace(".", r"\.")):
        config_from_dict({"evolution": table}, "x.toml")
