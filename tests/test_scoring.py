"""Common scoring: RSE maths, GP and baseline run folders, `gpquad compare`."""

import json

import numpy as np
import pytest
import sympy as sp

from gpquad.baselines import pem_sim as ps
from gpquad.baselines import quad12
from gpquad.baselines.flyable import BodyModel, Quad12Model
from gpquad.baselines.ga_config import GAConfig, Quad12SimConfig, theta_of
from gpquad.baselines.ga_identify import simulate as simulate_quad12
from gpquad.baselines.pem_config import TRUE_PARAMS, PemConfig, PemSimConfig
from gpquad.baselines.runfolder import write_flights, write_run
from gpquad.cli.commands import main
from gpquad.data.dataset import build_dataset
from gpquad.engine.tree.export import from_sympy, parse_equation, symbols_for
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel, Equation
from gpquad.models.scoring import compare, format_table, load_run, rse, run_dataset, score_model
from gpquad.study.config import MEDIAN_MODEL, Config, SimulatorConfig
from gpquad.study.runner import write_model
from gpquad.study.store import write_json

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


def test_rse_values():
    rng = np.random.default_rng(0)
    data = rng.normal(size=(4, 11, 9))
    np.testing.assert_allclose(rse(data, data), 0.0)
    mean = data.copy()
    mean[:, 1:, 3:] = data[:, 1:, 3:].reshape(-1, 6).mean(axis=0)
    np.testing.assert_allclose(rse(mean, data), 1.0)
    diverged = data.copy()
    diverged[0, 5, 6] = np.nan
    assert np.isinf(rse(diverged, data)[3]) and np.isfinite(rse(diverged, data)[:3]).all()


@pytest.fixture(scope="module")
def gp_run(tmp_path_factory):
    """A GP run folder holding the median model's true equations, in trimmed inputs."""
    run = tmp_path_factory.mktemp("gp")
    cfg = Config(simulator=SimulatorConfig(duration_s=60.0, seed=3))
    trim = {"u_T": 0.35, "u_P": 0.0, "u_R": 0.0, "u_Y": 0.0}
    syms = symbols_for(INPUTS)
    eqs = {}
    for target, text in MEDIAN_MODEL.items():
        expr, delays = parse_equation(text, INPUTS)
        expr = sp.expand(expr.xreplace({syms["u_T"]: syms["u_T"] + trim["u_T"]}))
        full = {n: delays.get(n, 0) for n in INPUTS}
        eqs[target] = Equation(target, from_sympy(expr, full, INPUTS), INPUTS, 0.0, 0.0, trim)
    write_model(run, DiscoveredModel(eqs, INPUTS, trim, 0.04, 0, cfg.to_dict()))
    write_json(run / "run.json", {"config": cfg.to_dict(), "wall_time_s": 12.5})
    return run


def test_gp_run_with_true_equations_scores_zero(gp_run):
    info = load_run(gp_run)
    assert info.kind == "gp" and info.fit_time_s == 12.5 and info.max_delay == 5
    # fitted numbers of the printed equations: two each, and a_z = 28.2 u_T(t-5) - 1.0 w
    # + 0.06 in the trimmed u_T (28.2 x 0.35 - 9.81) has three
    assert info.n_parameters == 13
    assert {t: e.n_constants for t, e in info.model.equations.items()}["a_z"] == 3
    dataset = run_dataset(gp_run)
    assert dataset.trim == {n: 0.0 for n in INPUTS}
    score = score_model(info.model, dataset, 50, info.trim, info.max_delay)
    # the model flies RK4 x1 (the default), the simulator's truth RK4 x8
    assert score.n_windows == 4 and max(score.rse.values()) < 1e-9
    # without the trim shift the model is wrong: the scorer must apply it
    wrong = score_model(info.model, dataset, 50, {}, info.max_delay)
    assert wrong.rse["w"] > 1e-3


@pytest.fixture(scope="module")
def quad12_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("ga")
    cfg = GAConfig(simulator=Quad12SimConfig(duration_s=20.0))
    truth, _ = simulate_quad12(cfg)
    model = Quad12Model(theta_of(cfg.simulator.true_params, quad12.PARAMS), 5.0, 10)
    scoring = write_flights(run, [quad12.to_flight(truth, "truth")], 0.25)
    write_run(
        run,
        {
            "method": "ga-gradient",
            "model": "quad12",
            "parameters": cfg.simulator.true_params,
            "v_hover": 5.0,
            "substeps": 10,
            "equations": model.equations(),
        },
        {"seed": 0},
        {"scoring_data": scoring, "fit_time_s": 3.0},
        0.0,
    )
    return run


def test_quad12_truth_scores_zero_and_perturbed_does_not(quad12_run):
    info = load_run(quad12_run)
    dataset = run_dataset(quad12_run)
    assert info.n_parameters == 14
    assert max(score_model(info.model, dataset, 100).rse.values()) < 1e-10
    theta = info.model.theta.copy()
    theta[quad12.PARAMS.index("a_7")] *= 1.05
    off = score_model(Quad12Model(theta, 5.0, 10), dataset, 100)
    assert off.rse["p"] > 1e-4 and off.rse["q"] < 0.1 * off.rse["p"]  # roll effectiveness
    eqs = json.loads((quad12_run / "model.json").read_text())["equations"]
    expr = sp.sympify(eqs["d(phi_dot)/dt"])
    assert float(expr.coeff(sp.Symbol("u_2"))) == pytest.approx(2.34)


def test_body_model_truth_scores_zero():
    cfg = PemConfig(simulator=PemSimConfig(train_s=20.0))
    rec = ps.simulate(cfg, 20.0, 0)
    dataset = build_dataset([ps.to_flight(rec, "body")], validation_fraction=0.3)
    truth = ps.theta_array(TRUE_PARAMS)
    model = BodyModel(truth, ps.vehicle_array(cfg), np.array(cfg.controller.gain), 4)
    assert max(score_model(model, dataset, 50).rse.values()) < 1e-8
    wrong = BodyModel(truth * np.array([1.3, 1, 1, 1, 1, 1]), model.vehicle, model.gain, 4)
    assert score_model(wrong, dataset, 50).rse["p"] > 1e-4


def test_compare_table_and_cli(quad12_run, gp_run, tmp_path, capsys):
    rows = compare([quad12_run, gp_run], 100)
    assert rows[0]["mean_rse"] < 1e-10 and rows[0]["n_parameters"] == 14
    assert np.isnan(rows[1]["mean_rse"]) and "inputs" in rows[1]["note"]
    assert "| ga-gradient |" in format_table(rows)
    out = tmp_path / "cmp"
    # The GP run cannot fly the baseline's flight (other inputs): the table is still written,
    # and the command exits 2 saying which run and why, instead of a NaN row and exit 0.
    assert (
        main(["compare", str(gp_run), str(quad12_run), "--horizon", "50", "--out", str(out)]) == 2
    )
    captured = capsys.readouterr()
    assert "| gp |" in captured.out and (tmp_path / "cmp.csv").is_file()
    assert (tmp_path / "cmp.md").read_text().count("\n|") >= 3
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "could not be scored on common data" in err[0]
    # Runs on the same flight compare cleanly: exit 0.
    assert (
        main(["compare", str(quad12_run), str(quad12_run), "--horizon", "50", "--out", str(out)])
        == 0
    )


def test_scoring_errors_are_one_line(tmp_path):
    with pytest.raises(GpquadError, match="model.json"):
        load_run(tmp_path)
