"""Printed equations keep enough significant digits to stay the model
(gpquad.models.precision): a lag filter whose taps nearly cancel needs more than three."""

import dataclasses

import numpy as np
import pytest
import sympy as sp
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
    expression_values,
    faithful,
    printed_digits,
    sample_columns,
    sample_rows,
    with_exact_raw_constant,
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
    columns = sample_columns(eq, ds.arrays, rows, raw=False)
    own = expression_values(eq.sympy(), columns, len(rows))
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


def test_terms_a_fit_drove_to_round_off_are_dropped_and_real_ones_kept(dataset):
    """-4.15 p + 10.3 u_R(t-1) + 1e-6 q r - 2e-6 theta: the two round-off terms go (the tree
    and the text lose them; the value moves by < TOLERANCE / 2 of its RMS); a coupling of
    0.05 q r, above the tolerance, stays; the cancelling filter keeps every tap."""
    from gpquad.models.precision import without_negligible_terms

    rows = sample_rows(dataset.train, 5)
    noisy = _equation("-4.15*p + 10.3*u_R(t-1) + 1e-6*q*r - 2e-6*theta", dataset)
    clean = without_negligible_terms(noisy, dataset.arrays, rows)
    assert {s.name for s in clean.sympy().free_symbols} == {"p", "u_R"}
    before, after = _tree_values(noisy, dataset, rows), _tree_values(clean, dataset, rows)
    rms = np.sqrt(np.mean(before**2))
    assert 0 < np.abs(after - before).max() <= TOLERANCE / 2 * rms
    real = _equation("-4.15*p + 10.3*u_R(t-1) + 0.05*q*r", dataset)
    assert without_negligible_terms(real, dataset.arrays, rows) is real
    lag_filter = _equation(FILTER, dataset)
    assert without_negligible_terms(lag_filter, dataset.arrays, rows) is lag_filter
    model = DiscoveredModel({"p_dot": noisy}, INPUTS, dict(dataset.trim), dataset.dt, 0, {})
    assert "q" not in with_printed_digits(model, dataset).equations["p_dot"].text()


def test_an_equation_whose_expanded_form_is_too_large_is_kept_as_found(dataset):
    """A product of sums expands to thousands of terms, some negligible: the equation is
    kept as it is instead of failing the fit (a refined Betaflight equation did; the check
    can fail: the expanded form itself exceeds from_sympy's limit)."""
    from gpquad.engine.tree.export import TreeTooLarge
    from gpquad.models.precision import without_negligible_terms

    big = _equation("(p + q + r + phi + theta + u_R + u_P + 1e-9)**6 - 4.15*p", dataset)
    rows = sample_rows(dataset.train, 5)
    with pytest.raises(TreeTooLarge):
        from_sympy(sp.expand(big.sympy()), big.delays, big.input_names)
    assert without_negligible_terms(big, dataset.arrays, rows) is big
    model = DiscoveredModel({"p_dot": big}, INPUTS, dict(dataset.trim), dataset.dt, 0, {})
    with_printed_digits(model, dataset)  # the last finishing step: no error


def test_the_finishing_steps_fit_the_printed_terms(dataset, monkeypatch):
    """finish_model hands its steps the equations without their round-off terms, so that
    the joint refit fits the constants that will be printed; without steps it changes
    nothing but the digits."""
    from gpquad.models import finish

    noisy = _equation("-4.15*p + 10.3*u_R(t-1) + 1e-6*q*r - 2e-6*theta", dataset)
    model = DiscoveredModel({"p_dot": noisy}, INPUTS, dict(dataset.trim), dataset.dt, 0, {})
    seen = []

    def step(model, dataset, evolution, flipped, workers, each):
        seen.append(model.equations["p_dot"].sympy().free_symbols)
        return model

    monkeypatch.setitem(finish.STEPS, "repair", step)
    evolution = type("E", (), {"finish": ("repair",)})()
    finish.finish_model(model, dataset, evolution)
    assert {s.name for s in seen[0]} == {"p", "u_R"}
    unfinished = finish.finish_model(model, dataset, type("E", (), {"finish": ()})())
    assert unfinished.equations["p_dot"].tree.size < noisy.tree.size  # the printing drops it


def test_a_rounded_constant_is_bounded_on_average_too(dataset, monkeypatch):
    """A bias is what a weakly damped state integrates over a long flight: 9.7326 printed
    as 9.73 moves every value by 2.7e-4 of the RMS, within the one-step TOLERANCE but not
    within BIAS_TOLERANCE, so 4 digits are printed. Bad case: without the bias bound, 3."""
    from gpquad.models import precision

    ds = dataset
    eq = _equation("0.5*u_R + 9.7326", ds)
    rows = sample_rows(ds.train, 5)
    columns = sample_columns(eq, ds.arrays, rows, raw=False)
    own = expression_values(eq.sympy(), columns, len(rows))
    assert printed_digits(eq, ds.arrays, rows) == 4
    assert not faithful(eq.sympy(), own, columns, 3)
    monkeypatch.setattr(precision, "BIAS_TOLERANCE", 1.0)
    assert printed_digits(eq, ds.arrays, rows) == 3


def _trimmed_roll(ds, residue: float) -> Equation:
    """p_dot = -4.15 p + 10.3 (u_R(t-1) - trim) + c with c such that the raw form's constant
    is `residue`."""
    trim = ds.trim["u_R"]
    return _equation(f"-4.15*p + 10.3*u_R(t-1) + {10.3 * trim + residue!r}", ds)


def test_a_raw_constant_the_data_cannot_see_is_not_printed(dataset):
    ds = dataset
    assert ds.trim["u_R"] != 0.0
    rows = sample_rows(ds.train, 5)
    found = _trimmed_roll(ds, 2.6e-8)  # as a fit leaves it: the trimmed constant to 1e-6
    assert "e-8" in found.text(raw=True)  # a real number is not taken for round-off
    exact = with_exact_raw_constant(found, ds.arrays, rows)
    assert exact.text(raw=True) == "p_dot = -4.15*p + 10.3*u_R(t-1)"
    assert exact.text() == found.text()  # the trimmed form keeps its constant
    moved = _tree_values(exact, ds, rows) - _tree_values(found, ds, rows)
    assert np.max(np.abs(moved)) < 1e-7
    # a constant the data see is kept (the bad case): 1 % of the equation's RMS
    rms = float(np.sqrt(np.mean(_tree_values(found, ds, rows) ** 2)))
    real = _trimmed_roll(ds, 0.01 * rms)
    kept = with_exact_raw_constant(real, ds.arrays, rows)
    assert kept.text(raw=True) == real.text(raw=True)
    assert kept.text(raw=True).endswith(f"{0.01 * rms:.3g}")
    # and with_printed_digits applies it to a model's equations
    model = DiscoveredModel({"p_dot": found}, ds.input_names, dict(ds.trim), ds.dt, 0, {})
    assert with_printed_digits(model, ds).equations["p_dot"].text(raw=True).endswith("u_R(t-1)")
