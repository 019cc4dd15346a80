"""The benchmark's fidelity column: a cell's printed equations flown by RK4 x 8 against the
method's own scheme (gpquad.benchmark.fidelity, gpquad.benchmark.fidelity_table)."""

import json

import numpy as np
import pytest

from gpquad.benchmark import fidelity, fidelity_table
from gpquad.benchmark.scenarios import Scenario
from gpquad.data.dataset import build_dataset
from gpquad.data.flight import Flight
from gpquad.errors import GpquadError
from gpquad.models.scoring import SCORED_STATES

DT = 0.04
ZERO = {t: f"{t} = 0" for t in ("a_x", "a_y", "a_z", "q_dot", "r_dot")}
PEER_ZERO = {t: "0" for t in ("a_x", "a_y", "a_z", "q_dot", "r_dot")}


def _scenario(p: np.ndarray, u: np.ndarray) -> Scenario:
    """A flight at rest but for its roll rate p (input u_R); only p is scored as changing."""
    n = len(p)
    rates = np.zeros((n, 3))
    rates[:, 0] = p
    flight = Flight(
        "roll",
        np.arange(n) * DT,
        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        np.zeros((n, 3)),
        rates,
        u[:, None],
        ("u_R",),
    )
    test = build_dataset([flight], validation_fraction=1.0)
    return Scenario("roll", test, test, None, {s: True for s in SCORED_STATES}, {})


def _inputs(n: int) -> np.ndarray:
    """Set-points held 0.4 s each (band-limited), from a fixed generator."""
    rng = np.random.default_rng(7)
    return np.repeat(rng.normal(0.0, 0.5, n // 10 + 1), 10)[:n]


def _rk4_factor(rate: float, substeps: int) -> float:
    """RK4's amplification of x' = rate x over one sample of `substeps` steps."""
    z = rate * DT / substeps
    return (1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24) ** substeps


@pytest.fixture(scope="module")
def continuous():
    """p_dot = -4 (p - u_R) flown exactly with u_R held over each sample (zero-order hold)."""
    u = _inputs(1500)
    p = np.zeros(len(u))
    decay = np.exp(-4 * DT)
    for k in range(len(u) - 1):
        p[k + 1] = decay * p[k] + (1 - decay) * u[k]
    return _scenario(p, u), u


@pytest.mark.parametrize(
    "method, p_dot",
    [("gpquad", "p_dot = -4*p + 4*u_R"), ("ols", "-4*p + 4*u_R_l0")],
)
def test_rk4_flight_of_a_linear_equation_is_the_analytic_rk4_map(continuous, method, p_dot):
    scenario, u = continuous
    others = ZERO if method == "gpquad" else PEER_ZERO
    equations = {**others, "p_dot": p_dot}
    simulate = fidelity.text_simulator(method, equations, scenario.test, "rk4", 8)
    start, steps = 300, 175
    flown = simulate(np.array([start]), steps)[0, :, 6]
    # x - u decays by RK4's factor over each sample, with u held
    g = _rk4_factor(-4.0, 8)
    expected = [scenario.test.arrays.states[start, 6]]
    for k in range(steps):
        expected.append(g * expected[-1] + (1 - g) * u[start + k])
    assert flown == pytest.approx(np.array(expected), abs=1e-12)
    # and the fine RK4 flies the continuous data to round-off, where one Euler step is off
    cell = {"method": method, "equations": equations, "metrics": {}}
    result = fidelity.cell_fidelity(cell, scenario, (7.0,))
    assert result["rk4"]["7s"]["rse"]["p"] < 1e-9
    assert result["own"]["7s"]["rse"]["p"] > 1e-4
    # p: RK4 much better than its own scheme; q, r stay zero in both (ratio 1 at the floor)
    assert fidelity.ratio(result["rk4"]["7s"]["rse"]["p"], result["own"]["7s"]["rse"]["p"]) < 0.01
    assert result["ratio"] == 1.0
    assert result["own_scheme"] == {"integrator": "euler", "substeps": 1}


def test_equations_fitted_to_one_euler_step_fail_the_fidelity_check():
    """A stiff loop as one explicit step flies it (k dt = 1.6): exact in its own scheme,
    another system in continuous time."""
    u = _inputs(1500)
    p = np.zeros(len(u))
    for k in range(len(u) - 1):
        p[k + 1] = p[k] + DT * (-40 * p[k] + 40 * u[k])
    scenario = _scenario(p, u)
    cell = {
        "scenario": "roll",
        "method": "ols",
        "seed": 0,
        "equations": {**PEER_ZERO, "p_dot": "-40*p + 40*u_R_l0"},
        "metrics": {},
    }
    result = fidelity.cell_fidelity(cell, scenario, (1.0, 7.0))
    assert result["own"]["7s"]["rse"]["p"] < 1e-20  # the data's own map
    assert result["rk4"]["7s"]["rse"]["p"] > 0.01
    assert result["ratio"] > 100
    record = {"scenario": "roll", "method": "ols", "seed": 0, **result}
    agg = fidelity_table.aggregate([record])
    assert agg["roll"]["ols"]["passes"] is False
    assert agg["roll"]["ols"]["ratio_worst"] == result["ratio"]
    text = fidelity_table.markdown(agg)
    assert "### roll" in text and "| ols (euler) |" in text and "| no |" in text
    # the same equations scored as their own reference pass
    good = {**record, "rk4": record["own"], "ratio": 1.0}
    assert fidelity_table.aggregate([good])["roll"]["ols"]["passes"] is True


def test_ratio_is_one_at_round_off_and_counts_a_diverged_flight():
    assert fidelity.ratio(3e-30, 1e-32) == 1.0
    assert fidelity.ratio(2e-3, 1e-3) == pytest.approx(2.0)
    assert fidelity.ratio(2e-3, 1e-31) == pytest.approx(2e3)
    assert fidelity.ratio(None, 1e-3) == float("inf")  # every RK4 window diverged
    assert fidelity.ratio(None, None) is None  # not measured
    own = {"windows": 3, "rse": {"p": 1e-3, "q": 1e-3, "r": None}}
    rk4 = {"windows": 3, "rse": {"p": 1.2e-3, "q": 3e-3, "r": None}}
    assert fidelity.cell_ratio(own, rk4) == pytest.approx(3.0)


def test_a_printed_lag_is_read_and_a_foreign_line_refused():
    assert fidelity.parse_line("p_dot + 0.05 d(p_dot)/dt = -4*p", "p_dot") == ("-4*p", 0.05)
    assert fidelity.parse_line("p_dot = -4*p", "p_dot") == ("-4*p", 0.0)
    model = fidelity.model_from_text(
        {"p_dot": "p_dot + 0.05 d(p_dot)/dt = -4*p"}, ("u_R",), DT, "rk4", 8
    )
    assert model.equations["p_dot"].lag == 0.05 and model.substeps == 8
    with pytest.raises(GpquadError):
        fidelity.parse_line("q_dot = -4*q", "p_dot")


def test_own_scheme_is_the_cells_integrator():
    cell = {"method": "gpquad", "settings": {"evolution": {"integrator": "rk4", "substeps": 4}}}
    assert fidelity.own_scheme(cell) == ("rk4", 4)
    assert fidelity.own_scheme({"method": "gpquad", "settings": {"evolution": {}}}) == (
        "euler",
        1,
    )
    assert fidelity.own_scheme({"method": "sindy"}) == ("euler", 1)
    # the finished model's scheme wins: a stiff loop raised its steps per sample
    cell["scheme"] = {"integrator": "rk4", "substeps": 8}
    assert fidelity.own_scheme(cell) == ("rk4", 8)
    # a cell fitted per vehicle records each group's model's scheme
    cell["scheme"] = {"a": {"integrator": "rk4", "substeps": 2}, "b": cell["scheme"]}
    assert fidelity.own_scheme(cell, "a") == ("rk4", 2)
    assert fidelity.own_scheme(cell, "b") == ("rk4", 8)


def test_update_caches_and_recomputes_a_changed_cell(continuous, tmp_path, monkeypatch):
    scenario, _ = continuous
    cell = {
        "scenario": "roll",
        "method": "gpquad",
        "seed": 1,
        "fingerprint": "f",
        "equations": {**ZERO, "p_dot": "p_dot = -4*p + 4*u_R"},
        "metrics": {},
    }
    first = fidelity.update(tmp_path, [cell], {"roll": scenario}, (7.0,), log=lambda s: None)
    assert (tmp_path / "fidelity" / "roll" / "gpquad" / "seed1.json").is_file()
    assert fidelity.load(tmp_path, [cell]) == first

    def refuse(*args):
        raise AssertionError("recomputed a cached cell")

    monkeypatch.setattr(fidelity, "cell_fidelity", refuse)
    assert fidelity.update(tmp_path, [cell], {"roll": scenario}, (7.0,), log=print) == first
    changed = {**cell, "equations": {**cell["equations"], "p_dot": "p_dot = -3*p + 3*u_R"}}
    assert fidelity.load(tmp_path, [changed]) == []  # stale: not reported
    with pytest.raises(AssertionError, match="recomputed"):
        fidelity.update(tmp_path, [changed], {"roll": scenario}, (7.0,), log=print)


def test_text_that_differs_from_the_stored_score_is_flagged():
    own = {"7s": {"windows": 2, "diverged": 0, "rse": {"p": 0.010, "q": None}}}
    same = {"7s": {"diverged": 0, "rse": {"p": 0.0101, "q": None}}}
    assert fidelity.matches_stored(own, same)
    assert not fidelity.matches_stored(own, {"7s": {"diverged": 0, "rse": {"p": 0.02}}})
    assert not fidelity.matches_stored(own, {"7s": {"diverged": 1, "rse": {"p": 0.01}}})
    tiny = {"7s": {"windows": 2, "diverged": 0, "rse": {"p": 1e-11}}}
    assert fidelity.matches_stored(tiny, {"7s": {"diverged": 0, "rse": {"p": 1e-30}}})


def test_report_of_a_folder_without_a_benchmark_is_one_line(tmp_path, capsys):
    from gpquad.cli.commands import main

    assert main(["benchmark", "--report", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "benchmark.json" in err[0]
    (tmp_path / "benchmark.json").write_text(
        json.dumps({"scenarios": {"median": {}}, "settings": {"horizons_s": [7.0]}})
    )
    assert main(["benchmark", "--report", "--out", str(tmp_path), "rigid-body"]) == 2
    assert "not in this benchmark" in capsys.readouterr().err


def test_a_cell_whose_text_does_not_parse_is_skipped_with_a_warning(continuous, tmp_path):
    scenario, _ = continuous
    cell = {
        "scenario": "roll",
        "method": "operon",
        "seed": 1,
        "equations": {**PEER_ZERO, "p_dot": "sin(p)"},
        "metrics": {},
    }
    said = []
    assert fidelity.update(tmp_path, [cell], {"roll": scenario}, (7.0,), log=said.append) == []
    assert len(said) == 1 and "no fidelity for roll/operon/seed1" in said[0]
