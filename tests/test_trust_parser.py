"""The equations' own parser (gpquad.engine.tree.arithmetic): what it refuses, what it
reads, and that every written tree reads back."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from hypothesis import given
from hypothesis import strategies as st
from test_hostile_inputs import INPUTS, write_run

from gpquad.engine.tree.arithmetic import MAX_POWER, parse_in_symbols
from gpquad.engine.tree.export import expr_string, from_sympy, parse_equation, to_sympy
from gpquad.engine.tree.variation import VariationParams, random_tree
from gpquad.engine.variables import terminal_names
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel

SYMBOLS = {n: sp.Symbol(n, real=True) for n in terminal_names(INPUTS)}


@pytest.mark.parametrize(
    "text",
    [
        "__import__('os')",
        "p.__class__",
        "p[0]",
        "lambda: 1",
        "p; q",
        "p if q else r",
        "exec",
        "[p]",
        "{p}",
        "p @ q",
        "p % q",
        "p // q",
        "'p'",
        "p == q",
        "p**q",
        "p**2.5",
        f"p**{MAX_POWER + 1}",
        "9**9**9",
        "(((p**256)**256)**256)**256",  # sympy merges them: p**4294967296
        "(p**200*q)**2",
        "((9**256)**256)**256",  # a number of 53 M bits
        "(p + q + r + v + w)**256",  # 1.9e8 terms once expanded
        "1/(p + q + r + v + w)**200",  # expand expands the denominator too
        "(p + q + r + v)**9 * (u + w + q)**9 * (p + r)**9",
        "sin(p)",
        "p(t-1)",
        "u_R(t+1)",
        "u_R(t-1.5)",
        "",
        "(" * 200 + "p" + ")" * 200,
        "1e999",
        "p +",
        "* p",
        "p q",
    ],
)
def test_parser_refuses(text):
    with pytest.raises(GpquadError):
        parse_equation(text, INPUTS, source="test")


@pytest.mark.parametrize(
    "text,expected",
    [
        ("10.3*u_R(t-1) - 4.15*p", "-4.15*p + 10.3*u_R"),
        ("-p**2", "-p**2"),
        ("(p + q)/2", "p/2 + q/2"),
        ("p**(-2)", "p**(-2)"),
        ("1.5e-3*q - -r", "0.0015*q + r"),
        ("2*3", "6"),
        ("+p", "p"),
    ],
)
def test_parser_reads_the_grammar(text, expected):
    expr, _ = parse_equation(text, INPUTS)
    assert sp.simplify(expr - parse_in_symbols(expected, SYMBOLS)) == 0


@given(st.data())
def test_written_trees_parse_back_to_the_same_tree(data):
    """Every tree's expr_string parses back (our parser) to an equal expression."""
    seed = data.draw(st.integers(0, 2**32 - 1))
    params = VariationParams(n_variables=13, n_inputs=4, max_depth=4)
    tree = random_tree(np.random.default_rng(seed), params)
    expr = to_sympy(tree, INPUTS)
    back = parse_in_symbols(expr_string(expr), SYMBOLS)
    point = {s: sp.Float(v) for s, v in zip(SYMBOLS.values(), np.linspace(0.3, 1.7, 13))}

    def value(e):
        return e.xreplace(point).evalf()

    # a point where a denominator vanishes gives sympy's complex infinity: not finite
    a, b = (float(v) if v.is_real and v.is_finite else np.nan for v in (value(expr), value(back)))
    assert a == pytest.approx(b, rel=1e-9, abs=1e-9) or not (np.isfinite(a) or np.isfinite(b))
    assert from_sympy(back, {}, INPUTS).size >= 1


def test_a_model_written_by_gpquad_loads(tmp_path):
    """The checks accept what to_dict writes (expr agrees with prefix)."""
    run = write_run(tmp_path / "run")
    model = DiscoveredModel.load(run)
    assert set(model.equations) == {"a_x", "a_y", "a_z", "p_dot", "q_dot", "r_dot"}


def test_a_long_sum_reads_as_the_terms_added_left_to_right():
    """A sum is built as one Add of its terms; it must be the expression that adding them
    one at a time gives, like terms merged and subtraction kept."""
    rng = np.random.default_rng(3)
    names = ["p", "q", "r", "u_R", "u_T"]
    parts, reference = [], sp.Integer(0)
    for k in range(300):
        a, b = rng.choice(names, 2)
        c = round(float(rng.normal(0, 5)), 4)
        sign = "-" if k and rng.random() < 0.5 else "+"
        term = sp.Float(str(c)) * SYMBOLS[a] * SYMBOLS[b]
        reference = reference - term if sign == "-" else reference + term
        parts.append(f"{sign} {c}*{a}*{b}" if k else f"{c}*{a}*{b}")
    text = " ".join(parts) + " - 2.5"
    assert parse_in_symbols(text, SYMBOLS) == reference - sp.Float("2.5")


def test_every_power_a_tree_can_hold_reads_back():
    """A tree of the deepest depth a configuration allows holds a name up to as many times
    as it has leaves, and sympy may print such a tree as one power: a rotorpy fit wrote
    1/(-28.5*u_Y**10 + 177.6*u_Y**9 - ...), which the parser refused at powers above 8, so
    that the run's own parity check (and loading its model.json) failed."""
    from gpquad.engine.tree.encoding import MAX_TREE_DEPTH, max_nodes
    from gpquad.models.symmetry import term_parity

    assert MAX_POWER >= (max_nodes(MAX_TREE_DEPTH) + 1) // 2
    u = SYMBOLS["u_Y"]
    expr = 1 / (3 * u**10 - 2 * u**9 + 1)
    assert parse_in_symbols(expr_string(expr), SYMBOLS) == expr
    assert parse_in_symbols(f"p**{MAX_POWER}", SYMBOLS) == SYMBOLS["p"] ** MAX_POWER
    assert term_parity(str(u**10), {"u_Y"}) == 1
    assert term_parity(str(u**11), {"u_Y"}) == -1


@pytest.mark.parametrize(
    "text",
    [
        "(p + q)**3",
        "(p + q)*(r - u)*(v + 2)",
        "1/(p + q)**2 + r",
        "(p + q + r)**4 - p*q",
        "p",
        "(p + q*r + u)/(v + w**2)",
    ],
)
def test_expanded_terms_bounds_what_sympy_expands_to(text):
    from gpquad.engine.tree.arithmetic import expanded_terms

    expr = parse_in_symbols(text, SYMBOLS)
    n = len(sp.Add.make_args(sp.expand(expr)))
    assert n <= expanded_terms(expr) <= 4 * n


def test_a_written_quotient_of_long_sums_reads_back():
    """gpquad writes a quotient as expanded numerator / expanded denominator: 150 terms over
    150 terms is 150 terms once expanded, not 22,500."""
    names = ["p", "q", "r", "u", "v", "w"]
    pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1 :]]
    monomials = [f"{a}**{i}*{b}**{j}" for a, b in pairs for i in range(1, 6) for j in range(1, 6)]
    monomials = monomials[:150]  # distinct: 150 terms above and below
    num = " + ".join(f"{k + 1}*{m}" for k, m in enumerate(monomials))
    den = " + ".join(f"{k + 2}*{m}" for k, m in enumerate(monomials))
    expr = parse_in_symbols(f"({num})/({den})", SYMBOLS)
    numerator, denominator = sp.fraction(expr)
    assert len(sp.Add.make_args(numerator)) == len(sp.Add.make_args(denominator)) == 150
    assert len(sp.Add.make_args(sp.expand(expr))) == 150
