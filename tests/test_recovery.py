"""End to end: recover the median model's six equations from noise-free simulated data.

Budget: experiments/quickstart.toml (3 iterations of 600 + 80 generations, 250-step
windows, local search on). benchmarks/recovery.py measures the pass rate over seeds.
"""

from pathlib import Path

import pytest

from gpquad.models.analysis import compare_to_truth
from gpquad.study.config import MEDIAN_MODEL, load_config, override
from gpquad.study.search import identify

QUICKSTART = Path(__file__).resolve().parents[1] / "experiments" / "quickstart.toml"


@pytest.mark.parametrize("target", ["p_dot", "a_z", "a_x", "a_y", "q_dot", "r_dot"])
def test_recovers_median_model_equation(median_dataset, target):
    cfg = override(load_config(QUICKSTART), targets=[target], seed=1)
    eq, _ = identify(median_dataset, target, cfg)
    report = compare_to_truth(eq, MEDIAN_MODEL[target], median_dataset, rel_tol=0.05)
    assert report["same_structure"], report
    assert report["delays"] == report["expected_delays"], report
    assert max(report["relative_errors"].values()) <= 0.05, report
    assert eq.validation_error < 0.01  # integrated-state MAE on unseen data
