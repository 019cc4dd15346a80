"""The training envelope of a model (gpquad.models.envelope) and its report in `gpquad score`."""

import dataclasses

import numpy as np
import pytest

from gpquad.data.io import load_dataset
from gpquad.data.score import format_score
from gpquad.models.envelope import REPORT_FRACTION, outside_envelope, training_envelope
from gpquad.models.equations import DiscoveredModel
from gpquad.study.config import Config, SimulatorConfig


@pytest.fixture(scope="module")
def dataset():
    return load_dataset(dataclasses.replace(Config(), simulator=SimulatorConfig(duration_s=60.0)))


def test_envelope_covers_the_training_samples_only(dataset):
    env = training_envelope(dataset)
    rows = np.concatenate([np.arange(a, b) for a, b in dataset.train])
    p = dataset.arrays.states[rows, 6]
    assert env["p"] == [float(p.min()), float(p.max())]
    u_r = dataset.arrays.inputs[rows, list(dataset.input_names).index("u_R")]
    assert env["u_R"] == [float(u_r.min()), float(u_r.max())]
    assert outside_envelope(env, dataset, rows) == []  # the training samples are inside


def test_a_shifted_signal_is_reported_with_its_ranges(dataset):
    env = training_envelope(dataset)
    rows = np.arange(dataset.n_samples)
    states = dataset.arrays.states.copy()
    states[:, 8] = states[:, 8] * 3.0  # r three times larger: beyond the range on many samples
    shifted = dataclasses.replace(dataset, arrays=dataset.arrays._replace(states=states))
    report = outside_envelope(env, shifted, rows)
    assert report and report[0]["signal"] == "r"
    assert report[0]["fraction"] > REPORT_FRACTION
    assert report[0]["training"] == env["r"]
    assert report[0]["seen"][1] == pytest.approx(states[:, 8].max())
    line = format_score(
        {
            "run": "RUN",
            "data": "LOG",
            "part": "all",
            "segments": ["a"],
            "input_names": ["u_R"],
            "windows": 1,
            "steps": 2,
            "horizon_s": 0.08,
            "diverged": 0,
            "rse": {"p": 0.1},
            "dropped": [],
            "outside_training": report,
        }
    )
    assert "note: r leaves the training range on" in line
    flagged = format_score(
        {
            "run": "RUN",
            "data": "LOG",
            "part": "all",
            "segments": ["a"],
            "input_names": ["u_R"],
            "windows": 1,
            "steps": 2,
            "horizon_s": 0.08,
            "diverged": 0,
            "rse": {"u": float("nan"), "p": 1.7, "q": 0.2},
            "dropped": [],
            "outside_training": [],
            "baselines": {"zero": {"u": float("nan"), "p": 2.0, "q": 0.9}},
        }
    )
    model_row = next(r for r in flagged.splitlines() if r.startswith("model"))
    zero_row = next(r for r in flagged.splitlines() if r.startswith("zero"))
    assert "1.7!" in model_row and "0.2 " in model_row and "nan" not in flagged.lower()
    assert "2!" in zero_row and "0.9 " in zero_row


def test_model_json_keeps_the_envelope_and_reads_old_files(dataset):
    env = training_envelope(dataset)
    model = DiscoveredModel({}, dataset.input_names, dataset.trim, dataset.dt, 1, {}, envelope=env)
    assert DiscoveredModel.from_dict(model.to_dict()).envelope == env
    old = model.to_dict()
    del old["envelope"]
    assert DiscoveredModel.from_dict(old).envelope is None
