"""`gpquad report`: figures, median-model table with shared structures, metrics."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_sweep import tiny_config

from gpquad.cli.commands import main
from gpquad.engine.tree.export import from_sympy, parse_equation
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES, TARGET_STATE
from gpquad.models.equations import Equation
from gpquad.report.builder import median_tables, structure_shares, terms
from gpquad.study.assemble import SCORED, diverged, rse
from gpquad.study.sweep import run_sweep

INPUTS = ("u_P", "u_R", "u_Y", "u_T")


def eq(text: str, target: str = "p_dot") -> Equation:
    expr, delays = parse_equation(text, INPUTS)
    tree = from_sympy(expr, delays, INPUTS)
    return Equation(target, tree, INPUTS, 0.1, 0.2)


def test_terms_key_on_structure_and_delay():
    keys = [k for k, _ in terms(eq("10.3*u_R(t-1) - 4.15*p + 0.5"))]
    assert sorted(keys) == ["1", "p", "u_R(t-1)"]
    # the same structure with other constants, and a different delay
    shares = structure_shares(
        [eq("10.3*u_R(t-1) - 4.15*p"), eq("9.1*u_R(t-1) - 3*p + q"), eq("9.1*u_R(t-2) - 3*p")]
    )
    assert shares["p"] == 1.0
    assert shares["u_R(t-1)"] == pytest.approx(2 / 3)
    assert shares["u_R(t-2)"] == pytest.approx(1 / 3) and shares["q"] == pytest.approx(1 / 3)


def test_median_table_marks_shared_terms_only():
    from gpquad.models.equations import DiscoveredModel

    median = eq("10.3*u_R(t-1) - 4.15*p + 2*q")
    runs = {"p_dot": [median, eq("9*u_R(t-1) - 4*p"), eq("8*u_R(t-2) - 4*p")]}
    model = DiscoveredModel({"p_dot": median}, INPUTS, {}, 0.04, 0, {})
    tex, md = median_tables(model, runs, 0.5)
    assert r"\boldsymbol{4.15 p}" in tex and r"\boldsymbol{10.3 u_{R-1}}" in tex
    assert r"\boldsymbol{2.0 q}" not in tex and "2.0 q" in tex
    assert "| p_dot |" in md and "`p` 100%" in md and "3 runs" in md
    assert r"\frac{d}{dt}" not in tex
    # an equation with a lag shows it: the right-hand side alone would be another model
    lagged = dataclasses.replace(median, lag=0.05)
    tex, md = median_tables(dataclasses.replace(model, equations={"p_dot": lagged}), runs, 0.5)
    assert r"\left(1 + 0.05\,\frac{d}{dt}\right) \dot{p}" in tex
    assert r"\left(1 + 0.05\,\frac{d}{dt}\right)" in md


def test_rse_and_divergence():
    assert [STATE_NAMES[i] for i in SCORED] == [TARGET_STATE[t] for t in TARGET_NAMES]
    rng = np.random.default_rng(0)
    data = rng.standard_normal((3, 11, 9))
    assert np.allclose(rse(data, data, np.ones(3, bool)), 0.0)
    mean_pred = np.broadcast_to(data[:, 1:].reshape(-1, 9).mean(axis=0), data.shape).copy()
    mean_pred[:, 0] = data[:, 0]
    assert np.allclose(rse(mean_pred, data, np.ones(3, bool)), 1.0)  # the mean scores RSE 1
    bad = data.copy()
    bad[1, 5, SCORED[2]] = np.inf
    bad[2, 3, SCORED[0]] = 100.0
    assert diverged(bad, np.full(6, 50.0)).tolist() == [False, True, True]
    assert np.allclose(rse(bad, data, np.array([True, False, False])), 0.0)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    run_sweep(tiny_config(), out, jobs=1)
    return out


def test_report_writes_every_figure_and_table(sweep, capsys):
    assert main(["report", str(sweep)]) == 0
    rep = sweep / "report"
    for stem in ("prediction", "convergence"):
        png = (rep / f"{stem}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        width, height = np.frombuffer(png[16:24], dtype=">u4")
        assert 1000 <= width <= 2000 and 400 <= height <= 1600  # 7 in wide at 200 dpi
        assert (rep / f"{stem}.pdf").read_bytes()[:5] == b"%PDF-"
    assembly = json.loads((sweep / "assembly.json").read_text())
    metrics = (rep / "metrics.md").read_text()
    rows = [
        line for line in metrics.splitlines() if line.startswith("| 1s") or line.startswith("| 3s")
    ]
    assert len(rows) == 2 * 3  # two horizons x (best, median, all full models)
    best_1s = assembly["best"]["metrics"]["1s"]
    best_row = next(r for r in rows if r.startswith("| 1s | best"))
    assert f"{best_1s['rse']['p']:.3g}" in best_row
    assert f"{best_1s['diverged']} / {best_1s['windows']}" in best_row
    assert "\\begin{tabular}" in (rep / "metrics.tex").read_text()
    median = json.loads((sweep / "models" / "median" / "model.json").read_text())
    table = (rep / "median_model.md").read_text()
    for t in ("a_z", "p_dot"):
        assert f"{median['targets'][t]['validation_error']:.4g}" in table
    assert "\\begin{tabular}" in (rep / "median_model.tex").read_text()
    assert str(rep / "prediction.png") in capsys.readouterr().out


def test_prediction_file_holds_data_best_and_every_full_model(sweep):
    d = np.load(sweep / "predictions.npz")
    n_steps = int(round(tiny_config().sweep.window_s / float(d["dt"])))
    assert d["data"].shape == d["best"].shape == (n_steps + 1, 9)
    assert d["full"].shape == (3, n_steps + 1, 9)
    # every model starts from the recorded state
    assert np.allclose(d["best"][0, 3:], d["data"][0, 3:])
    assert np.allclose(d["full"][:, 0, 3:], d["data"][0, 3:])


def test_report_on_a_non_sweep_folder_is_a_one_line_error(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "not a sweep folder" in capsys.readouterr().err
