"""Input taps (evolution.input_taps): one input at several delays in one equation.

The truth used end to end is a lagging roll loop p_dot = -3 p + 20 u_R(t-1) - 12 u_R(t-3):
a one-delay-per-input equation cannot express it, a two-tap equation can, exactly.
"""

import dataclasses

import numpy as np
import pytest
from conftest import truth_dataset

from gpquad.control.pid_kernel import plant_accelerations
from gpquad.control.plant import model_plant
from gpquad.engine.evolve.coevolution import Coevolution
from gpquad.engine.evolve.leaves import measured_variables
from gpquad.engine.evolve.term_search import term_candidates
from gpquad.engine.kernels.tree_eval import STACK_ROWS
from gpquad.engine.taps import (
    base_input,
    initial_delays,
    tap_index,
    tap_names,
    taps_of,
    tile_inputs,
    with_taps,
)
from gpquad.engine.tree.encoding import Tree
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.study.config import (
    Config,
    config_from_dict,
    preset_evolution,
    validate,
)
from gpquad.study.search import identify

INPUTS = ("u_P", "u_R", "u_Y", "u_T")
LAGGING = "-3.0*p + 20.0*u_R(t-1) - 12.0*u_R(t-3)"


def _equation(text: str, target: str = "p_dot") -> Equation:
    expr, delays = parse_equation(text, INPUTS)
    return Equation(target, from_sympy(expr, delays, INPUTS), INPUTS, 0.0, 0.0)


def test_tap_names_and_tiling():
    assert tap_names(("a", "b"), 3) == ("a", "b", "a__tap1", "b__tap1", "a__tap2", "b__tap2")
    assert [base_input(n) for n in tap_names(("u_R",), 3)] == ["u_R"] * 3
    assert [tap_index(n) for n in tap_names(("u_R",), 3)] == [0, 1, 2]
    assert base_input("u__tap") == "u__tap" and tap_index("u_T") == 0
    assert taps_of(12, 4) == 3 and taps_of(4, 4) == 1 and taps_of(0, 0) == 1
    x = np.arange(6.0).reshape(3, 2)
    tiled = tile_inputs(x, 3)
    assert tiled.shape == (3, 6)
    assert all(np.array_equal(tiled[:, 2 * k : 2 * k + 2], x) for k in range(3))
    assert tile_inputs(x, 1) is x
    assert initial_delays(2, 3, 5).tolist() == [0, 0, 1, 1, 2, 2]
    assert initial_delays(1, 3, 1).tolist() == [0, 1, 1]  # clipped at max_delay


def test_an_input_at_several_delays_parses_and_prints_back():
    eq = _equation(LAGGING)
    assert eq.leaf_names == tap_names(INPUTS, 2)
    assert eq.delays["u_R"] == 1 and eq.delays["u_R__tap1"] == 3
    assert eq.text() == "p_dot = -3.0*p + 20.0*u_R(t-1) - 12.0*u_R(t-3)"
    # the printed text parses to the same tree
    again = _equation(eq.text().split(" = ", 1)[1])
    assert np.array_equal(again.tree.codes, eq.tree.codes)
    assert np.array_equal(again.tree.delays, eq.tree.delays)
    assert r"u_{R-3}" in eq.latex()
    # a plain input next to a delayed one is a tap at delay 0
    eq0 = _equation("2.0*u_R - u_R(t-2)")
    assert eq0.text() == "p_dot = 2.0*u_R - 1.0*u_R(t-2)"
    with pytest.raises(GpquadError, match="more than 6 delays"):
        parse_equation("u_R + " + " + ".join(f"u_R(t-{k})" for k in range(1, 7)), INPUTS)


def test_taps_at_the_same_delay_are_one_variable():
    eq = _equation(LAGGING)
    delays = eq.tree.delays.copy()
    delays[len(INPUTS) + 1] = 1  # the tap moves onto the input's own delay
    merged = dataclasses.replace(eq, tree=dataclasses.replace(eq.tree, delays=delays))
    assert merged.text() == "p_dot = -3.0*p + 8.0*u_R(t-1)"


def test_tapped_model_round_trips_through_model_json_and_flies_like_numpy():
    eq = _equation(LAGGING)
    model = DiscoveredModel({"p_dot": eq}, INPUTS, {}, 0.04, 1, {})
    back = DiscoveredModel.from_dict(model.to_dict())
    assert back.text() == model.text()
    assert np.array_equal(back.equations["p_dot"].tree.delays, eq.tree.delays)
    rng = np.random.default_rng(0)
    u = rng.normal(size=(60, 4))
    flown = back.fly(u).rates[:, 0]
    # plain-numpy reference: Euler on p, inputs before the first row held at the first row
    p = np.zeros(60)
    for k in range(59):
        u1, u3 = u[max(k - 1, 0), 1], u[max(k - 3, 0), 1]
        p[k + 1] = p[k] + 0.04 * (-3.0 * p[k] + 20.0 * u1 - 12.0 * u3)
    np.testing.assert_allclose(flown, p, rtol=1e-12, atol=1e-12)


def test_untapped_models_keep_the_paper_layout():
    eq = _equation("-4.15*p + 10.3*u_R(t-1)")
    assert eq.leaf_names == INPUTS
    assert eq.to_dict()["delays"] == {"u_P": 0, "u_R": 1, "u_Y": 0, "u_T": 0}


def test_config_bounds_on_input_taps():
    with pytest.raises(GpquadError, match="input_taps"):
        validate(Config(evolution=preset_evolution(input_taps=0)))
    with pytest.raises(GpquadError, match=r"max_delay \+ 1 \(2\)"):
        validate(Config(evolution=preset_evolution(input_taps=3, max_delay=1)))
    validate(Config(evolution=preset_evolution(input_taps=6)))  # every delay 0..max_delay
    with pytest.raises(GpquadError, match="input_taps"):
        validate(Config(evolution=preset_evolution(input_taps=7, max_delay=6)))


def test_input_taps_per_target_table():
    cfg = config_from_dict({"evolution": {"input_taps": {"p_dot": 6, "a_x": 2}}})
    assert [cfg.evolution.taps_for(t) for t in ("p_dot", "a_x", "r_dot")] == [6, 2, 1]
    assert preset_evolution(input_taps=4).taps_for("r_dot") == 4
    with pytest.raises(GpquadError, match=r"input_taps\.x_dot.*unknown target"):
        config_from_dict({"evolution": {"input_taps": {"x_dot": 2}}}, "exp.toml")
    with pytest.raises(GpquadError, match=r"input_taps\.q_dot.*between 1 and 6"):
        config_from_dict({"evolution": {"input_taps": {"p_dot": 2, "q_dot": 7}}}, "exp.toml")
    with pytest.raises(GpquadError, match="input_taps"):
        config_from_dict({"evolution": {"input_taps": {"p_dot": "six"}}}, "exp.toml")


def test_each_target_searches_with_its_own_taps(lagging_dataset):
    ev = preset_evolution(input_taps={"p_dot": 3}, window_s=4.0)
    assert len(Coevolution(lagging_dataset, "p_dot", ev).dataset.input_names) == 3 * 4
    assert Coevolution(lagging_dataset, "a_x", ev).dataset.input_names == INPUTS


def test_a_model_mixing_tap_counts_flies_each_equation_as_alone():
    lag = _equation(LAGGING)  # 2 taps (8 delay slots)
    yaw = _equation("2.0*u_Y(t-2) - 0.5*r", "r_dot")  # 1 tap (4 slots)
    assert (len(lag.tree.delays), len(yaw.tree.delays)) == (8, 4)
    u = np.random.default_rng(3).normal(size=(60, 4))
    mixed = DiscoveredModel({"p_dot": lag, "r_dot": yaw}, INPUTS, {}, 0.04, 1, {}).fly(u).rates
    alone_p = DiscoveredModel({"p_dot": lag}, INPUTS, {}, 0.04, 1, {}).fly(u).rates
    alone_r = DiscoveredModel({"r_dot": yaw}, INPUTS, {}, 0.04, 1, {}).fly(u).rates
    np.testing.assert_array_equal(mixed[:, 0], alone_p[:, 0])
    np.testing.assert_array_equal(mixed[:, 2], alone_r[:, 2])
    assert np.abs(mixed[:, 2]).max() > 0.1


def test_control_plant_reads_every_tap():
    model = DiscoveredModel({"p_dot": _equation(LAGGING)}, INPUTS, {"u_R": 0.5}, 0.04, 1, {})
    for form in ("simplified", "tree"):
        plant = model_plant(model, form)
        assert plant.delays.shape == (6, 8)
        state = np.zeros(9)
        state[6] = 0.2
        # inputs held: 20 u - 12 u = 8 (u_R - trim)
        acc = plant.accelerations(state, np.array([0.0, 1.5, 0.0, 0.0]))
        assert acc[3] == pytest.approx(-3.0 * 0.2 + 8.0 * 1.0, rel=1e-12)
        # a varying history against numpy: -3 p + 20 (u(t-1) - trim) - 12 (u(t-3) - trim)
        history = np.zeros((6, 4))
        history[:, 1] = [0.1, 0.7, -0.4, 0.9, 0.3, -0.2]
        out = np.empty(6)
        plant_accelerations(
            *plant.arrays()[:5],
            state,
            history,
            5,
            out,
            np.empty((17, 1)),
            np.empty((STACK_ROWS, 1)),
            np.empty(1),
        )
        assert out[3] == pytest.approx(-0.6 + 20.0 * (0.3 - 0.5) - 12.0 * (-0.4 - 0.5))


@pytest.fixture(scope="module")
def lagging_dataset():
    return truth_dataset({"p_dot": LAGGING}, duration_s=120.0, seed=4)


def test_excluded_inputs_stay_out_with_every_tap(lagging_dataset):
    tapped = with_taps(lagging_dataset, 2)
    allowed = measured_variables(tapped, ("u_T",))
    names = ("phi", "theta", "psi", "u", "v", "w", "p", "q", "r") + tapped.input_names
    assert {names[i] for i in allowed} >= {"u_R", "u_R__tap1"}
    assert not {"u_T", "u_T__tap1"} & {names[i] for i in allowed}


def _identify(dataset, taps: int) -> Equation:
    ev = preset_evolution(
        targets=("p_dot",),
        iterations=2,
        n_models=4,
        n_tests=4,
        suite_size=4,
        window_s=4.0,
        constant_fit="lm",
        linear_seed=True,
        selection="bic",
        input_taps=taps,
        exclude_leaves=("psi",),
    )
    return identify(dataset, "p_dot", Config(seed=2, evolution=ev))[0]


def test_two_taps_recover_a_lagging_loop_that_one_delay_cannot(lagging_dataset):
    one = _identify(lagging_dataset, 1)
    two = _identify(lagging_dataset, 2)
    used = two.used_delays()
    assert sorted(d for n, d in used.items() if base_input(n) == "u_R") == [1, 3]
    terms = {str(k): float(v) for k, v in two.sympy().as_coefficients_dict().items()}
    r1 = next(n for n, d in used.items() if d == 1)
    r3 = next(n for n, d in used.items() if d == 3)
    assert terms[r1] == pytest.approx(20.0, rel=1e-3)
    assert terms[r3] == pytest.approx(-12.0, rel=1e-3)
    assert terms["p"] == pytest.approx(-3.0, rel=1e-3)
    # one delay per input cannot fly the lag: its validation error is far larger
    assert one.validation_error > 1e3 * two.validation_error


def test_every_delay_as_a_tap_runs_the_linear_seed(lagging_dataset):
    """Six taps of four inputs make the linear seed a sum of 33 products (67 leaves): it
    must evaluate (the stack holds 8 rows of it) and still find the lagging loop."""
    six = _identify(lagging_dataset, 6)
    assert six.validation_error < 1e-6
    assert {d for n, d in six.used_delays().items() if base_input(n) == "u_R"} >= {1, 3}


def test_an_equation_reading_one_tap_takes_the_papers_layout():
    # r_dot = 2 u_Y(t-2) read through tap 2 of u_Y (the others unread, at other delays)
    codes = [2, 4, 5 + 9 + 2 * 4 + 2]  # MUL CONST u_Y__tap2
    tree = Tree.from_lists(codes, [0.0, 2.0, 0.0], [0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2])
    eq = Equation("r_dot", tree, INPUTS, 0.0, 0.0)
    assert eq.text() == "r_dot = 2.0*u_Y(t-2)"
    assert eq.used_delays() == {"u_Y": 2}
    assert eq.tree.codes.tolist() == [2, 4, 5 + 9 + 2]
    # the same function: the relabelled tree flies as the original
    rng = np.random.default_rng(1)
    u = rng.normal(size=(40, 4))
    raw = DiscoveredModel({"r_dot": eq}, INPUTS, {}, 0.04, 1, {})
    ref = _equation("2.0*u_Y(t-2)", "r_dot")
    np.testing.assert_array_equal(
        raw.fly(u).rates, DiscoveredModel({"r_dot": ref}, INPUTS, {}, 0.04, 1, {}).fly(u).rates
    )


def test_taps_enter_term_insertion_alone_or_beside_their_own_input():
    n_in, taps = 4, 4
    variables = [0, 1, 3, 4, 5, 6, 7, 8] + list(range(9, 9 + n_in * taps))
    extra = {9 + k * n_in + j: 9 + j for k in range(1, taps) for j in range(n_in)}
    model = Tree.from_lists([4], [0.0], np.zeros(n_in * taps, dtype=np.int64))
    restricted = term_candidates(model, variables, 5, None, extra)
    assert len(restricted) == 192 and len(term_candidates(model, variables, 5)) == 600
    for cand in restricted:
        leaves = [int(c) - 5 for c in cand.codes if c >= 5]
        tapped = [v for v in leaves if v in extra]
        if len(leaves) == 2 and tapped:  # a product or a pair with a tap
            a, b = leaves
            assert cand.codes.tolist().count(2) == 2  # two terms, not one product
            assert extra.get(a, a) == extra.get(b, b)
