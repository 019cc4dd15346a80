"""Stiff closed loops: the growing-horizon fit, the linear seed, and one gain per term.

The truth here is an angle-mode attitude loop like rotorpy's hummingbird (kp_att 544,
kd_att 46.6): p_dot = 544 (u_R - phi) - 46.6 p. Its long-window integrated error has
several basins; Levenberg-Marquardt from small constants stops in a wrong one, which is
what the growing horizon and the linear seed are for.
"""

import dataclasses

import numpy as np
import pytest
from conftest import truth_dataset
from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import continued_constants, gauss_newton_constants
from gpquad.engine.evolve.linear_seed import coefficients_of, linear_tree
from gpquad.engine.evolve.term_search import term_candidates, with_term_coefficients
from gpquad.engine.evolve.windows import spread, tile
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.tree.random_stream import RandomStream
from gpquad.engine.tree.variation import random_tree
from gpquad.errors import GpquadError
from gpquad.study.config import Config, preset_evolution, validate
from naive import evaluate_on_table

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
STIFF = "544.0*(u_R - phi) - 46.6*p"


@pytest.fixture(scope="module")
def stiff_dataset():
    return truth_dataset({"p_dot": STIFF}, duration_s=90.0, seed=3)


def _tree(text):
    expr, delays = parse_equation(text, INPUTS)
    return from_sympy(expr, delays, INPUTS)


def test_growing_horizon_finds_the_stiff_loop_where_a_direct_fit_does_not(stiff_dataset):
    ds = stiff_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    starts, _ = tile(ds.train, 250, 5)

    def error_of(t):
        return float(ev.mean_errors([t], starts)[0])

    start = _tree("0.001*phi + 0.001*p + 0.001*u_R")
    e0 = error_of(start)
    direct, direct_error = gauss_newton_constants(ev, start, e0, starts, 250, error_of, 30)
    short = [(spread(tile(ds.train, h, 5)[0], 4000 // h), h) for h in (2, 10)]
    grown, grown_error = continued_constants(ev, start, e0, starts, 250, error_of, 30, short)
    consts = sorted(grown.values[grown.codes == 4])
    # the loop's constants (-544 phi, -46.6 p, +544 u_R) to 0.1 %, error at round-off
    assert consts == pytest.approx([-544.0, -46.6, 544.0], rel=1e-3)
    assert grown_error < 1e-12 * e0
    # the direct fit from the same start stays in another basin (the reason for the option)
    assert direct_error > 1e3 * grown_error
    # With the exact Jacobian (angle_tangents: phi's leaf carries the attitude's
    # sensitivity, dt x p's integrated) the direct fit from small constants gets there
    # too; from 5 phi - 3 p - 2 u_R it does not: the growing horizon is still needed.
    exact = Evaluator(ds, "p_dot", 250, "mse", angle_tangents=True)
    small_error = gauss_newton_constants(exact, start, e0, starts, 250, error_of, 30)[1]
    assert small_error < 1e-12 * e0
    far = _tree("5.0*phi - 3.0*p - 2.0*u_R")
    far_error = gauss_newton_constants(exact, far, error_of(far), starts, 250, error_of, 30)[1]
    assert far_error > 1e3 * grown_error
    # without short windows the continued fit is the direct fit
    same, same_error = continued_constants(ev, start, e0, starts, 250, error_of, 30, [])
    assert same_error == direct_error and np.array_equal(same.values, direct.values)


def test_linear_seed_starts_a_climber_in_the_loops_basin(stiff_dataset):
    ev_cfg = preset_evolution(
        constant_fit="lm", linear_seed=True, window_s=10.0, n_models=4, exclude_leaves=("psi",)
    )
    co = Coevolution(stiff_dataset, "p_dot", ev_cfg)
    seeded = co.linear_seed()
    assert seeded is not None and seeded.depth <= ev_cfg.max_depth
    names = sorted({int(c) - 5 for c in seeded.codes if c >= 5})
    coefs, constant = coefficients_of(seeded, names)
    by_name = dict(zip(names, coefs, strict=True))
    # phi (0), p (6), u_R (9 + 1): the loop; every other variable's gain is small
    assert by_name[0] == pytest.approx(-544.0, rel=0.01)
    assert by_name[6] == pytest.approx(-46.6, rel=0.01)
    assert by_name[10] == pytest.approx(544.0, rel=0.01)
    assert 2 not in by_name  # psi is excluded
    state = co.init_state(1)
    assert state.models[0].codes.tolist() == seeded.codes.tolist()
    # no random draw: the other climbers are those of a run without the seed
    plain = Coevolution(stiff_dataset, "p_dot", dataclasses.replace(ev_cfg, linear_seed=False))
    other = plain.init_state(1)
    assert [m.codes.tolist() for m in state.models[1:]] == [
        m.codes.tolist() for m in other.models[1:]
    ]


def test_linear_tree_round_trips_its_coefficients():
    tree = linear_tree([0, 6, 10], np.array([1.5, -2.0, 3.25]), 0.5, np.zeros(4, dtype=int))
    coefs, constant = coefficients_of(tree, [0, 6, 10])
    assert coefs.tolist() == [1.5, -2.0, 3.25] and constant == 0.5
    assert coefficients_of(tree, [10, 0])[0].tolist() == [3.25, 1.5]
    # the shallow sum reorders its terms: the constant and the first term come last
    four = linear_tree(
        [0, 6, 10, 12], np.array([1.5, -2.0, 3.25, 7.0]), 0.5, np.zeros(4, dtype=int)
    )
    assert [int(c) - 5 for c in four.codes if c >= 5] == [6, 10, 12, 0]
    coefs, constant = coefficients_of(four, [0, 6, 10, 12])
    assert coefs.tolist() == [1.5, -2.0, 3.25, 7.0] and constant == 0.5
    assert tree.depth == 3  # 4 summands need two levels of + (root depth 0)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_one_gain_per_term_is_the_same_function(seed):
    """with_term_coefficients only regroups and adds unit gains: same values everywhere."""
    rng = np.random.default_rng(seed)
    co_cfg = preset_evolution()
    from gpquad.engine.evolve.coevolution import variation_params

    tree = random_tree(RandomStream(rng), variation_params(co_cfg, 4))
    table = rng.normal(size=(40, 13))
    regrouped = with_term_coefficients(tree)
    a, b = evaluate_on_table(tree, table), evaluate_on_table(regrouped, table)
    finite = np.isfinite(a) & (np.abs(a) < 1e8)
    assert np.allclose(a[finite], b[finite], rtol=1e-9, atol=1e-9)


def test_term_candidates_give_every_term_a_gain():
    model = _tree("p*r - 3.5*q - 8.5*u_P")
    flat = with_term_coefficients(model)
    assert flat.size == model.size + 2  # one gain, for p*r
    candidates = term_candidates(flat, list(range(13)), 5)
    # a candidate adding c q r keeps p*r's own gain, so LM can move each term separately
    assert all(c.depth <= 5 for c in candidates) and len(candidates) > 100


@pytest.mark.parametrize(
    "fields, field",
    [
        ({"linear_seed": True}, "evolution.linear_seed"),  # needs the LM constant fit
        ({"linear_seed": True, "constant_fit": "nelder-mead"}, "evolution.linear_seed"),
    ],
)
def test_bad_stiff_loop_settings_are_refused(fields, field):
    cfg = Config(evolution=dataclasses.replace(preset_evolution(), **fields))
    with pytest.raises(GpquadError, match=field.replace(".", r"\.")):
        validate(cfg, "x.toml")
