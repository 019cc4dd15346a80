"""The final selection does not choose a quotient whose denominator crosses zero where the
data went (gpquad.engine.evolve.poles)."""

import numpy as np

from gpquad.engine.evolve.poles import crosses_pole, denominators, without_poles
from gpquad.engine.taps import tile_inputs
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.tree.operators import DIV, SUB, VAR_BASE

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


def _tree(text, taps=2):
    """The tree of `text`, with one delay per input column of _data(taps=taps)."""
    expr, delays = parse_equation(text, INPUTS)
    tree = from_sympy(expr, delays, INPUTS)
    tiled = np.zeros(len(INPUTS) * taps, dtype=tree.delays.dtype)
    tiled[: len(tree.delays)] = tree.delays
    return Tree(tree.codes, tree.values, tiled)


def _data(n=400, seed=0, taps=2):
    """States, and the inputs tiled once per tap (as the search's data are)."""
    rng = np.random.default_rng(seed)
    states = rng.normal(size=(n, 9))
    inputs = np.column_stack([rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)])
    throttle = 0.55 + 0.05 * np.sin(np.linspace(0, 20, n))  # 0.50 .. 0.60
    return states, tile_inputs(np.column_stack([inputs, throttle]), taps)


def test_a_denominator_that_changes_sign_over_the_data_is_a_pole():
    states, inputs = _data()
    samples = np.arange(10, 400)
    # px4-s250's a_z: its denominator is zero at u_T = 0.489; here u_T spans 0.50-0.60
    crossing = _tree("57.2*u_T*w/(99.0*u_T*u_T(t-5) - 54.5*u_T(t-5))")  # zero at u_T = 0.55
    clear = _tree("57.2*u_T*w/(99.0*u_T*u_T(t-5) - 48.4*u_T(t-5))")  # zero at 0.489: outside
    assert len(denominators(crossing)) == 1
    assert crosses_pole(crossing, states, inputs, samples)
    assert not crosses_pole(clear, states, inputs, samples)  # the check can pass
    # a denominator that only comes near zero (|b| < DIV_EPS) counts too
    w, u_t = VAR_BASE + 5, VAR_BASE + 9 + 3
    zero = Tree.from_lists([DIV, w, SUB, u_t, u_t], [0.0] * 5, [0] * 8)  # w / (u_T - u_T)
    assert crosses_pole(zero, states, inputs, samples)
    assert not crosses_pole(_tree("-2.0*w + u_T"), states, inputs, samples)  # no quotient


def test_the_selection_keeps_the_flyable_and_falls_back_to_all():
    states, inputs = _data()
    samples = np.arange(10, 400)
    crossing = _tree("w/(u_T - 0.55)")
    plain = _tree("-0.6*w + 2.0*u_T")
    assert without_poles([crossing, plain], states, inputs, samples) == [plain]
    assert without_poles([crossing], states, inputs, samples) == [crossing]


def test_a_tree_without_a_delay_for_every_input_column_is_refused():
    """The kernel (tree_eval.eval_on_samples) reads one delay per input column: a tree with
    fewer (the bad case, which read past its delays) is an error, not a read of whatever
    memory follows."""
    import pytest

    states, inputs = _data(taps=2)
    expr, delays = parse_equation("w/(u_T - 0.55)", INPUTS)
    short = from_sympy(expr, delays, INPUTS)  # 4 delays for 8 input columns
    with pytest.raises(ValueError, match="one delay per input column"):
        crosses_pole(short, states, inputs, np.arange(10, 400))
