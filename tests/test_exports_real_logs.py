"""The python and C exports of real-log models fly held-out inputs of their logs as
DiscoveredModel.fly_states does, to 1e-12, by the model's eq. 2 and by RK4 (2 substeps).

tests/fixtures/px4_s250_model.json and betaflight_gecko_model.json are `gpquad run` results
of experiments/px4_s250.toml and experiments/betaflight_gecko.toml (seed 1, --iterations 2;
tests/fixtures/LICENSE.md). The held-out inputs are read from ../shared/data (not bundled:
the PX4 log is GPL-3.0), or from GPQUAD_SHARED_DATA when set; without either the tests skip.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from export_models import assert_flies_like, fixture_model, fly_c, in_scheme, python_and_c

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("GPQUAD_SHARED_DATA") or REPO.parent / "shared" / "data")

#: (model fixture, log, config, segment, first row of the held-out part or None for all):
#: px4-s250 holds out the last 30 % of each segment; betaflight-gecko another flight.
CASES = {
    "px4_s250": ("px4_s250_model.json", "px4/S250AQ_2016-12-13", "px4_s250.toml", 0, 0.7),
    "betaflight_gecko": (
        "betaflight_gecko_model.json",
        "betaflight/btfl_all.bbl",
        "betaflight_gecko.toml",
        2,
        None,
    ),
}


def _held_out(case: str):
    """(inputs, initial state) of the held-out part of one segment of the log."""
    from gpquad.data.export import export_flights
    from gpquad.engine.kernels.quaternion import euler_array

    model_file, log, config, segment, start_fraction = CASES[case]
    if not (SHARED / log).exists():
        pytest.skip(
            f"{SHARED / log} is not present (set GPQUAD_SHARED_DATA to the shared data folder)"
        )
    with warnings.catch_warnings():  # the betaflight reader's notes on undecodable logs
        warnings.simplefilter("ignore", UserWarning)
        flights, _ = export_flights(SHARED / log, None, REPO / "experiments" / config)
    flight = flights[segment]
    first = int(start_fraction * len(flight)) if start_fraction else 0
    euler = euler_array(np.ascontiguousarray(flight.quat[first : first + 1]))[0]
    x0 = np.concatenate([euler, flight.vel[first], flight.rates[first]])
    return fixture_model(model_file), flight.inputs[first:], x0, flight.dt


@pytest.mark.parametrize("scheme", [("euler", 1), ("rk4", 2)])
@pytest.mark.parametrize("case", list(CASES))
def test_real_log_exports_fly_held_out_inputs(case, scheme, tmp_path):
    model, inputs, x0, dt = _held_out(case)
    assert abs(dt - model.dt) < 1e-9 and len(inputs) > 300
    model = in_scheme(model, *scheme)
    reference = model.fly_states(inputs, x0)
    module, lib = python_and_c(model, tmp_path, name=f"{case}_{scheme[0]}")
    assert_flies_like(module.fly(inputs, x0), reference)
    code, states = fly_c(lib, inputs, x0)
    assert code == 0
    assert_flies_like(states, reference)
