"""Shared fixtures: simulated flights of the paper's median model (known truth)."""

import dataclasses
import os

import pytest
from hypothesis import settings

from gpquad.data.dataset import build_dataset
from gpquad.data.simulator import simulate
from gpquad.study.config import Config, DataConfig, SimulatorConfig

INPUTS = ("u_P", "u_R", "u_Y", "u_T")

# Numba compiles on first call: no per-example deadline. CI replays a fixed example set.
settings.register_profile("dev", deadline=None)
settings.register_profile("ci", deadline=None, derandomize=True, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture(scope="session")
def median_flight():
    """The reference simulator's default flight (552 s at 25 Hz, median model)."""
    return simulate(SimulatorConfig(), INPUTS)


#: The paper's discrete-time truth (eq. 2 per sample): the kernel and engine-mechanism tests
#: check exact invariants of the eq. 2 kernels (the true equations score zero, ...) on it.
EQ2_TRUTH = dataclasses.replace(SimulatorConfig(), integrator="euler")


@pytest.fixture(scope="session")
def short_flight():
    """A 60 s flight of the eq. 2 truth with livelier sticks, for kernel tests."""
    cfg = dataclasses.replace(
        EQ2_TRUTH,
        duration_s=60.0,
        seed=7,
        stick_sd={"u_P": 0.2, "u_R": 0.2, "u_Y": 0.2, "u_T": 0.05},
    )
    return simulate(cfg, INPUTS)


@pytest.fixture(scope="session")
def short_dataset(short_flight):
    return build_dataset([short_flight], validation_fraction=0.2, trim="mean")


@pytest.fixture(scope="session")
def median_dataset(median_flight):
    cfg = Config(data=DataConfig(trim="mean"))
    return build_dataset(
        [median_flight], validation_fraction=cfg.data.validation_fraction, trim="mean"
    )


def truth_dataset(equations: dict[str, str], duration_s: float, seed: int):
    """A dataset of the reference simulator's eq. 2 truth with some of its equations
    replaced (raw inputs, no trim, the last 20 % for validation)."""
    sim = dataclasses.replace(EQ2_TRUTH, duration_s=duration_s, seed=seed)
    sim = dataclasses.replace(sim, equations={**sim.equations, **equations})
    return build_dataset([simulate(sim, INPUTS)], validation_fraction=0.2, trim="none")
