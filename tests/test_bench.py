"""The benchmark command (deselected by default: run with -m bench)."""

import json

import pytest

from gpquad.cli.commands import main


@pytest.mark.bench
def test_bench_json(capsys):
    assert main(["bench", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["window_steps_per_s"] > 1e6
    assert result["constant_fit_ms"] > 0 and result["constant_fit_window_steps_per_s"] > 1e5
    assert result["paper_run_s"] > 0 and set(result["paths"]) == {
        "rates_and_inputs",
        "attitude_and_velocity",
        "linear_target",
    }
    assert set(result["paths_rk4"]) == {f"{p} rk4x{m}" for p in result["paths"] for m in (1, 4)}
    assert all(rate > 1e4 for rate in result["paths_rk4"].values())
