"""Gradient constants, BIC selection and term insertion: values, determinism, resume, config."""

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_engine import tiny_config

from gpquad.data.dataset import build_dataset
from gpquad.data.io import load_dataset
from gpquad.data.simulator import simulate
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.evaluator import Evaluator
from gpquad.engine.evolve.gradient_fit import gauss_newton_constants
from gpquad.engine.evolve.selection import bic, mse_of, prune_by_bic, select_by_bic
from gpquad.engine.evolve.term_search import improve_terms, regain_candidates, term_candidates
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.tree.operators import CONST, MUL
from gpquad.errors import GpquadError
from gpquad.study import checkpoint
from gpquad.study.config import load_config, override
from gpquad.study.runner import run_experiment

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"
NEW = {"constant_fit": "lm", "selection": "bic", "term_search": True, "linear_seed": True}


@pytest.fixture(scope="module")
def rigid_dataset():
    """80 s of the rigid-body truth (experiments/rigid_body.toml) flown by eq. 2, which the
    evaluators here fly: p_dot has 0.9 q r."""
    sim = load_config(EXPERIMENTS / "rigid_body.toml").simulator
    sim = dataclasses.replace(sim, duration_s=80.0, seed=5, integrator="euler")  # eq. 2 truth
    return build_dataset(
        [simulate(sim, ("u_P", "u_R", "u_Y", "u_T"))], validation_fraction=0.25, trim="none"
    )


def _tree(text, dataset):
    expr, delays = parse_equation(text, dataset.input_names)
    return from_sympy(expr, delays, dataset.input_names)


def _fit(ev):
    def fit(tree, err, starts, n_steps):
        return gauss_newton_constants(
            ev, tree, err, starts, n_steps, lambda t: mse_of(ev, t, starts, n_steps), 20
        )

    return fit


STARTS = np.array([10, 260, 510, 760, 1010, 1260], dtype=np.int64)


def test_bic_prefers_the_exact_model_and_rejects_non_finite():
    assert bic(1e-4, 1000, 5) < bic(1e-4, 1000, 9)  # same error, fewer symbols
    assert bic(1e-6, 1000, 9) < bic(1e-4, 1000, 5)  # 100x smaller error beats 4 symbols
    assert bic(np.inf, 1000, 3) == np.inf and bic(np.nan, 1000, 3) == np.inf


def test_bic_pruning_removes_bloat_and_keeps_a_small_coupling(rigid_dataset):
    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    truth = "9.0*u_R(t-2) - 4.0*p - 0.9*q*r"
    # the truth plus a bloat term that explains nothing (its constant fits to ~0)
    bloated = _tree(truth + " + 0.3*theta*u_Y", ds)

    def const(t, a, b):
        return 0.0

    pruned = prune_by_bic(ev, bloated, STARTS, 250, const, _fit(ev))
    assert sorted(map(str, parse_equation(truth, ds.input_names)[0].free_symbols)) == sorted(
        str(s) for s in _sym(pruned, ds).free_symbols
    )
    assert mse_of(ev, pruned, STARTS, 250) < 1e-10


def _sym(tree, ds):
    from gpquad.models.equations import Equation

    return Equation("p_dot", tree, ds.input_names, 0.0, 0.0, {}).sympy()


def test_select_by_bic_picks_the_lowest_and_the_first_on_ties(rigid_dataset):
    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    exact = _tree("9.0*u_R(t-2) - 4.0*p - 0.9*q*r", ds)
    missing = _tree("9.0*u_R(t-2) - 4.0*p", ds)
    chosen, scores = select_by_bic(ev, [missing, exact, exact], STARTS, 250)
    assert chosen is exact and scores[1] == scores[2] < scores[0]


def test_select_by_bic_counts_a_polynomial_multiplied_out(rigid_dataset):
    """BIC counts nodes: the truth grown as a product of a sum (15 nodes) is scored, and
    returned, multiplied out (13 nodes), as the truth written plainly is; a rational stays
    as it is."""
    from gpquad.engine.evolve.selection import fewest_nodes

    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    exact = _tree("9.0*u_R(t-2) - 4.0*p - 0.9*q*r", ds)
    grown = Tree.from_lists(  # 3 * (3 u_R(t-2) - 4/3 p - 0.3 q r), the same function
        [MUL, CONST] + exact.codes.tolist(),
        [0.0, 3.0] + (exact.values / 3.0).tolist(),
        exact.delays,
    )
    assert grown.size == exact.size + 2
    chosen, scores = select_by_bic(ev, [grown], STARTS, 250)
    assert chosen.size == exact.size
    assert np.isclose(scores[0], select_by_bic(ev, [exact], STARTS, 250)[1][0], rtol=1e-9)
    assert fewest_nodes(exact) is exact
    rational = _tree("9.0*u_R(t-2)/(1 + p*p) - 4.0*p", ds)
    assert fewest_nodes(rational) is rational


def test_term_insertion_finds_the_gyroscopic_term(rigid_dataset):
    ds = rigid_dataset
    ev = Evaluator(ds, "p_dot", 250, "mse")
    model = _tree("8.0*u_R(t-2) - 3.0*p", ds)
    assert len(term_candidates(model, 13, 5)) == 13 + 91 + 78
    assert len(regain_candidates(model, 5)) == 1  # c * model; its terms have gains already
    assert term_candidates(model, 13, 2) == []  # no room under the depth limit
    err = ev.mean_errors([model], STARTS)[0]
    found, found_err = improve_terms(ev, model, err, STARTS, _fit(ev), 13, 5, 0.01)
    assert found_err < 1e-8 * err
    assert {"q", "r", "p", "u_R"} <= {str(s) for s in _sym(found, ds).free_symbols}
    # A required gain it cannot reach keeps the model.
    exact = _tree("9.0*u_R(t-2) - 4.0*p - 0.9*q*r", ds)
    kept, kept_err = improve_terms(ev, exact, 0.0, STARTS, _fit(ev), 13, 5, 0.01)
    assert kept is exact and kept_err == 0.0


def test_a_full_tree_exchanges_a_substitute_for_the_coupling(rigid_dataset, monkeypatch):
    """Seen on the benchmark (rigid-body, seed 1): p_dot with q*u_Y(t-5) and r*u_P(t-5)
    standing in for -0.9 q r, in a tree at the depth limit. Adding c q r needs a level more,
    even packed as the shallowest sum, so term insertion must drop the least contributing
    terms to make room."""
    from gpquad.engine.evolve import term_search
    from gpquad.engine.evolve.term_search import gained_terms, term_contributions
    from gpquad.engine.tree.encoding import Tree, shallow_sum, tree_depth
    from gpquad.engine.tree.operators import CONST, MUL, VAR_BASE

    ds = rigid_dataset
    names = ("phi", "theta", "psi", "u", "v", "w", "p", "q", "r") + ds.input_names
    var = {n: VAR_BASE + i for i, n in enumerate(names)}

    def term(c, *xs):
        body = (
            [(var[xs[0]], 0.0)]
            if len(xs) == 1
            else [(MUL, 0.0), (var[xs[0]], 0.0), (var[xs[1]], 0.0)]
        )
        return [(MUL, 0.0), (CONST, c)] + body

    # six products and four linear terms fill a depth-5 sum exactly (Kraft: 6/8 + 4/16 = 1)
    prefix = shallow_sum(
        [
            term(0.454, "q", "u_Y"),
            term(1.42, "r", "u_P"),
            term(-4.0, "p"),
            term(0.01, "phi", "theta"),
            term(8.97, "u_R"),
            term(-0.005, "v", "w"),
            term(0.002, "u", "phi"),
            term(0.003, "theta", "w"),
            term(-0.047, "phi"),
            term(0.01, "theta"),
        ]
    )
    model = Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], [5, 2, 5, 0])
    with_coupling = shallow_sum(gained_terms(model) + [term(1.0, "q", "r")])
    assert tree_depth([c for c, _ in with_coupling]) == 6
    assert model.depth == 5
    ev = Evaluator(ds, "p_dot", 250, "mse")
    err = ev.mean_errors([model], STARTS)[0]
    found, found_err = improve_terms(ev, model, err, STARTS, _fit(ev), 13, 5, 0.01)
    assert found_err < 1e-8 * err
    assert "q*r" in str(_sym(found, ds))
    assert len(term_contributions(ev, model, STARTS)) == 10
    # without making room (no contributions), the same search cannot reach the truth
    monkeypatch.setattr(term_search, "term_contributions", lambda *a: None)
    _, stuck_err = improve_terms(ev, model, err, STARTS, _fit(ev), 13, 5, 0.01)
    assert stuck_err > 1e3 * found_err


def test_a_product_of_sums_is_multiplied_out_to_make_room(rigid_dataset, monkeypatch):
    """Seen on the benchmark (rotorpy-angle crazyflie a_z, seed 2): a climber written as a
    product of sums at the depth limit is one additive term, so no term could be added or
    exchanged. Multiplied out (gpquad.engine.tree.polynomial) it is 18 monomials, of which
    the least contributing make room for the missing c q r."""
    from gpquad.engine.evolve import term_search
    from gpquad.engine.tree.encoding import Tree, shallow_sum
    from gpquad.engine.tree.operators import CONST, MUL, VAR_BASE

    ds = rigid_dataset
    names = ("phi", "theta", "psi", "u", "v", "w", "p", "q", "r") + ds.input_names

    def term(c, x):
        return [(MUL, 0.0), (CONST, c), (VAR_BASE + names.index(x), 0.0)]

    # (9 u_R(t-2) - 4 p + 0.001 (phi + theta + r + u)) * (1 + 0.001 (v + w))
    first = shallow_sum(
        [
            term(9.0, "u_R"),
            term(-4.0, "p"),
            term(0.001, "phi"),
            term(0.001, "theta"),
            term(0.001, "r"),
            term(0.001, "u"),
        ]
    )
    second = shallow_sum([[(CONST, 1.0)], term(0.001, "v"), term(0.001, "w")])
    prefix = [(MUL, 0.0)] + first + second
    model = Tree.from_lists([c for c, _ in prefix], [v for _, v in prefix], [5, 2, 5, 0])
    assert model.depth == 5
    ev = Evaluator(ds, "p_dot", 250, "mse")
    err = ev.mean_errors([model], STARTS)[0]
    assert len(term_search.model_terms(model)) == 18
    found, found_err = improve_terms(ev, model, err, STARTS, _fit(ev), 13, 5, 0.01)
    assert found_err < 1e-8 * err
    assert "q*r" in str(_sym(found, ds))
    # kept as one product, the same search finds nothing to add
    monkeypatch.setattr(term_search, "expand", lambda *a: None)
    stuck, stuck_err = improve_terms(ev, model, err, STARTS, _fit(ev), 13, 5, 0.01)
    assert stuck is model and stuck_err == err


def test_new_features_are_deterministic_and_resume_exactly(tmp_path):
    cfg = tiny_config(**NEW)
    # Two invocations (fresh processes, as `gpquad run` is used) give the same bytes.
    script = (
        "import sys; sys.path.insert(0, sys.argv[1]); from test_engine import tiny_config; "
        "from gpquad.study.runner import run_experiment; "
        f"run_experiment(tiny_config(**{NEW!r}), sys.argv[2], progress=False)"
    )
    for name in ("a", "b"):
        subprocess.run(
            [sys.executable, "-c", script, str(Path(__file__).parent), str(tmp_path / name)],
            check=True,
            capture_output=True,
        )
    assert (tmp_path / "a" / "model.json").read_bytes() == (
        tmp_path / "b" / "model.json"
    ).read_bytes()
    # Within one long-lived process (after whatever tests ran before) the bytes are the same
    # too. They were not while LM could drift along constants that only act together
    # (gradient_fit.identifiable): round-off decided where they ended.
    run_experiment(cfg, tmp_path / "c", progress=False)
    assert (tmp_path / "c" / "model.json").read_bytes() == (
        tmp_path / "a" / "model.json"
    ).read_bytes()
    dataset = load_dataset(cfg)
    engine = Coevolution(dataset, "p_dot", cfg.evolution)
    state = engine.init_state(np.random.SeedSequence(3))
    engine.iterate(state)
    checkpoint.save(tmp_path / "c.bin", state, {"history_bytes": 0})
    loaded, _ = checkpoint.load(tmp_path / "c.bin")
    engine.iterate(state)
    engine.iterate(loaded)
    for x, y in zip(state.models, loaded.models, strict=True):
        assert np.array_equal(x.values, y.values) and np.array_equal(x.codes, y.codes)
    assert np.array_equal(state.model_errors, loaded.model_errors)


def test_paper_config_leaves_the_new_features_off():
    ev = load_config(EXPERIMENTS / "paper.toml").evolution
    assert (ev.constant_fit, ev.selection, ev.term_search, ev.finish) == (
        "none",
        "prune",
        False,
        (),
    )


@pytest.mark.parametrize(
    "field, value",
    [
        ("constant_fit", "newton"),
        ("selection", "aic"),
        ("term_min_gain", 1.5),
        ("gradient_steps", -1),
        ("finish", ("repair", "repair")),
    ],
)
def test_bad_engine_settings_name_their_field(field, value):
    cfg = tiny_config()
    bad = dataclasses.replace(cfg, evolution=dataclasses.replace(cfg.evolution, **{field: value}))
    with pytest.raises(GpquadError) as err:
        override(bad)
    assert err.value.field == f"evolution.{field}"


def test_constants_that_only_act_together_are_held_fixed():
    """c1 + (c2 + x) and c1 * (c2 * x): equal or proportional Jacobian columns. The fit frees
    one constant of each such group (LM would drift along the line by round-off); the check
    can fail: independent columns are all kept."""
    from gpquad.engine.evolve.gradient_fit import identifiable

    rng = np.random.default_rng(0)
    x = rng.standard_normal((50, 3))
    jac = np.column_stack([np.ones(50), np.ones(50), x[:, 0], 2.0 * x[:, 0], x[:, 1]])
    free = identifiable(jac)
    assert len(free) == 3 and 4 in free
    assert {0, 1} & set(free.tolist()) and not {0, 1} <= set(free.tolist())
    assert {2, 3} & set(free.tolist()) and not {2, 3} <= set(free.tolist())
    assert identifiable(x).tolist() == [0, 1, 2]
    assert identifiable(np.column_stack([np.zeros(50), x[:, 0]])).tolist() == [1]


@settings(max_examples=60)
@given(st.integers(0, 2**31 - 1), st.integers(1, 9), st.floats(-16, 0))
def test_identifiable_shortcut_gives_the_pivoted_qr_answer(seed, n, log_gap):
    """The Gram-matrix shortcut of `identifiable` (well-conditioned: every column) against
    the pivoted QR alone, on random Jacobians with a column made nearly dependent by
    10**log_gap (from exact copies to independent)."""
    from scipy.linalg import qr

    from gpquad.engine.evolve.gradient_fit import IDENTIFIABLE_RTOL, identifiable

    rng = np.random.default_rng(seed)
    jac = rng.standard_normal((200, n)) * rng.uniform(0.1, 10.0, n)
    if n > 1:
        jac[:, -1] = jac[:, 0] * 3.0 + 10.0**log_gap * rng.standard_normal(200)
    unit = jac / np.sqrt((jac * jac).sum(axis=0))
    _, r, piv = qr(unit, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    reference = np.sort(piv[: int(np.count_nonzero(diag > IDENTIFIABLE_RTOL * diag[0]))])
    assert identifiable(jac).tolist() == reference.tolist()
