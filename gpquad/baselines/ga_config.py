"""Config of the GA baselines (`gpquad baseline ga-gradient|ga CONFIG.toml`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpquad.baselines import quad12
from gpquad.baselines.schema import build, read_toml, require

#: Feasible box per parameter ("physical specs"); the truth is inside but off-centre.
DEFAULT_BOUNDS = {
    "a_1": (-1.0, 0.0),
    "a_2": (0.0, 1.0),
    "a_3": (-1.0, 0.0),
    "a_4": (0.0, 1.0),
    "a_5": (-1.0, 0.0),
    "a_6": (-0.05, 0.05),
    "a_7": (0.5, 5.0),
    "a_8": (-0.05, 0.05),
    "a_9": (0.5, 5.0),
    "a_10": (-0.05, 0.05),
    "a_11": (0.5, 5.0),
    "b_1": (0.0, 1.0),
    "b_2": (0.0, 1.0),
    "b_3": (-1.0, 0.0),
}


@dataclass(frozen=True)
class Quad12SimConfig:
    """Truth simulator of the 12-state model (pilot PD + OU excitation)."""

    seed: int = 0
    duration_s: float = 60.0
    rate_hz: float = 100.0
    substeps: int = 10
    excitation_sd: tuple[float, ...] = (2.0, 1.0, 1.0, 1.0)  # V, on u_1..u_4
    excitation_tau_s: float = 0.5
    # [k_zdot, k_phi, k_phidot, k_theta, k_thetadot, k_psi, k_psidot]
    pilot_gains: tuple[float, ...] = (2.0, 2.0, 1.0, 2.0, 1.0, 2.0, 1.0)
    v_hover: float = 5.0
    # measurement noise SD on the 12 states (m, m/s, rad, rad/s), empty = noise-free
    noise_sd: tuple[float, ...] = ()
    true_params: dict[str, float] = field(default_factory=lambda: dict(quad12.TRUE_PARAMS))


@dataclass(frozen=True)
class GASection:
    population: int = 40
    generations: int = 200
    elite: int = 2
    crossover_prob: float = 0.8
    mutation_prob: float = 0.1
    mutation_shape: float = 2.0
    max_backtracks: int = 40
    difference: str = "forward"
    loops: tuple[str, ...] = tuple(quad12.LOOPS)
    bounds: dict[str, tuple[float, ...]] = field(default_factory=lambda: dict(DEFAULT_BOUNDS))


@dataclass(frozen=True)
class StudySection:
    """Convergence comparison: gradient vs traditional GA from the same populations."""

    seeds: int = 20
    fraction: float = 0.05
    noise_sd: tuple[float, ...] = (
        0.0,
        0.002,
        0.0,
        0.002,
        0.0,
        0.002,
        0.0005,
        0.001,
        0.0005,
        0.001,
        0.0005,
        0.001,
    )


@dataclass(frozen=True)
class GAConfig:
    name: str = "baseline-ga"
    seed: int = 0
    validation_fraction: float = 0.2
    score_horizon_steps: int = 100
    simulator: Quad12SimConfig = field(default_factory=Quad12SimConfig)
    ga: GASection = field(default_factory=GASection)
    study: StudySection = field(default_factory=StudySection)


def validate(cfg: GAConfig, source: str) -> GAConfig:
    s, g = cfg.simulator, cfg.ga
    require(
        len(s.excitation_sd) == 4, "give 4 values (u_1..u_4)", source, "simulator.excitation_sd"
    )
    require(len(s.pilot_gains) == 7, "give 7 gains", source, "simulator.pilot_gains")
    for name, sd in (("simulator.noise_sd", s.noise_sd), ("study.noise_sd", cfg.study.noise_sd)):
        require(len(sd) in (0, 12), "give 12 SDs (one per state) or none", source, name)
    require(
        set(s.true_params) == set(quad12.PARAMS),
        f"give exactly the parameters {list(quad12.PARAMS)}",
        source,
        "simulator.true_params",
    )
    require(
        s.rate_hz > 0 and s.duration_s > 0 and s.substeps >= 1,
        "rate_hz, duration_s > 0 and substeps >= 1",
        source,
        "simulator.rate_hz",
    )
    for loop in g.loops:
        require(
            loop in quad12.LOOPS,
            f"unknown loop '{loop}'; choose from {list(quad12.LOOPS)}",
            source,
            "ga.loops",
        )
    for p in quad12.PARAMS:
        b = g.bounds.get(p)
        require(
            b is not None and len(b) == 2 and b[0] < b[1],
            "need [low, high] with low < high for every parameter",
            source,
            f"ga.bounds.{p}",
        )
    require(set(g.bounds) <= set(quad12.PARAMS), "unknown parameter", source, "ga.bounds")
    require(
        g.difference in ("forward", "central"), "choose forward or central", source, "ga.difference"
    )
    require(
        g.population >= 4 and 0 <= g.elite < g.population,
        "need population >= 4 and 0 <= elite < population",
        source,
        "ga.population",
    )
    require(g.generations >= 1, "must be >= 1", source, "ga.generations")
    for name in ("crossover_prob", "mutation_prob"):
        v = getattr(g, name)
        require(0.0 <= v <= 1.0, "must be in [0, 1]", source, f"ga.{name}")
    require(
        cfg.study.seeds >= 1 and 0 < cfg.study.fraction < 1,
        "need seeds >= 1 and 0 < fraction < 1",
        source,
        "study.fraction",
    )
    require(0.0 < cfg.validation_fraction < 1.0, "must be in (0, 1)", source, "validation_fraction")
    require(cfg.score_horizon_steps >= 1, "must be >= 1", source, "score_horizon_steps")
    return cfg


def load_ga_config(path) -> GAConfig:
    table, source = read_toml(path)
    return validate(build(GAConfig, table, source), source)


def theta_of(params: dict[str, float], names) -> np.ndarray:
    return np.array([params[n] for n in names], dtype=float)
