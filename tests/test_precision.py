"""Printed equations keep enough significant digits to stay the model
(gpquad.models.precision): a lag filter whose taps nearly cancel needs more than three."""

import dataclasses

import numpy as np
import pytest
from conftest import INPUTS

from gpquad.data.dataset import build_dataset
from gpquad.data.simulator import simulate
from gpquad.engine.kernels.tree_eval import eval_on_samples
from gpquad.engine.taps import taps_of, tile_inputs
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.precision import (
    MIN_DIGITS,
    TOLERANCE,
    _columns,
    _values,
    faithful,
    printed_digits,
    sample_rows,
    with_printed_digits,
)
from gpquad.study.config import SimulatorConfig

#: A six-tap roll filter like the rotorpy-angle models' (its coefficients sum to 3.5).
FILTER = (
    "-47.31*p + 1313.7*u_R - 2761.4*u_R(t-1) + 3421.9*u_R(t-2) - 3063.3*u_R(t-3)"
    " + 1512.6*u_R(t-4) - 424.0*u_R(t-5)"
)


@pytest.fixture(scope="module")
def dataset():
    flight = simulate(SimulatorConfig(duration_s=30.0, seed=4), INPUTS)
    return build_dataset([flight], validation_fraction=0.2, trim="mean")


def _equation(text, ds):
    expr, delays = parse_equation(text, ds.input_names)
    return Equation(
        "p_dot", from_sympy(expr, delays, ds.input_names), ds.input_names, 0.0, 0.0, dict(ds.trim)
    )


def _tree_values(eq, ds, rows):
    """The kernel's values of the equation's tree (inputs tiled once per tap)."""
    t = eq.tree
    n_in = len(ds.input_names)
    inputs = tile_inputs(ds.arrays.inputs, taps_of(len(t.delays), n_in))
    return eval_on_samples(t.codes, t.values, t.size, t.delays, ds.arrays.states, inputs, rows)


def test_a_cancelling_filter_gets_the_digits_it_needs_and_its_text_is_the_model(dataset):
    ds = dataset
    eq = _equation(FILTER, ds)
    rows = sample_rows(ds.train, 5)
    digits = printed_digits(eq, ds.arrays, rows)
    assert digits > MIN_DIGITS
    columns = _columns(eq, ds.arrays, rows, raw=False)
    own = _values(eq.sympy(), columns, len(rows))
    assert faithful(eq.sympy(), own, columns, digits)
    assert not faithful(eq.sympy(), own, columns, digits - 1)  # the check can fail
    # the printed line, parsed back, evaluates like the model (and the 3-digit one does not)
    exact = _tree_values(eq, ds, rows)
    scale = np.sqrt(np.mean(exact**2))
    shown = dataclasses.replace(eq, digits=digits)
    again = _equation(shown.text().split(" = ", 1)[1], ds)
    assert np.max(np.abs(_tree_values(again, ds, rows) - exact)) <= TOLERANCE * scale
    three = _equation(eq.text(digits=3).split(" = ", 1)[1], ds)
    assert np.max(np.abs(_tree_values(three, ds, rows) - exact)) > TOLERANCE * scale


def test_plain_equations_keep_three_digits_and_model_json_keeps_the_digits(dataset):
    ds = dataset
    model = DiscoveredModel(
        {
            "p_dot": _equation(FILTER, ds),
            "a_x": Equation(
                "a_x",
                _equation("-9.81*theta - 0.35*u", ds).tree,
                ds.input_names,
                0.0,
                0.0,
                dict(ds.trim),
            ),
        },
        ds.input_names,
        dict(ds.trim),
        ds.dt,
        0,
        {},
    )
    done = with_printed_digits(model, ds)
    assert done.equations["a_x"].digits == MIN_DIGITS
    assert done.equations["p_dot"].digits > MIN_DIGITS
    again = DiscoveredModel.from_dict(done.to_dict())
    assert {t: e.digits for t, e in again.equations.items()} == {
        t: e.digits for t, e in done.equations.items()
    }
    assert again.text() == done.text() and again.text(raw=True) == done.text(raw=True)
