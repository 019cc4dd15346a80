"""Config of the prediction-error baseline (`gpquad baseline pem CONFIG.toml`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from gpquad.baselines.geometry import Geometry
from gpquad.baselines.schema import build, read_toml, require

PARAMS = ("I_xx", "I_yy", "I_zz", "J_r", "b", "d")
#: Truth: the paper's refined Pelican values (Table 1).
TRUE_PARAMS = {
    "I_xx": 1.21e-2,
    "I_yy": 1.355e-2,
    "I_zz": 2.179e-2,
    "J_r": 1.143e-4,
    "b": 2.256e-5,
    "d": 3.679e-7,
}
#: The Pelican's LQ state-feedback gain K (appendix, Table A1): rows motors 1..4,
#: columns [phi, theta, psi, p, q, r]; motor speed deviations in rad/s.
PELICAN_GAIN = (
    (0.0, 530.32, -211.61, 0.0, 42.4, -86.12),
    (-529.93, 0.0, 211.61, -40.04, 0.0, 86.12),
    (0.0, -530.32, -211.61, 0.0, -42.4, -86.12),
    (529.93, 0.0, 211.61, 40.04, 0.0, 86.12),
)


@dataclass(frozen=True)
class VehicleConfig:
    """Known vehicle constants (Pelican-like: l from the appendix's Gamma, m from its D)."""

    arm_length: float = 0.2178
    mass: float = 1.583
    gravity: float = 9.805
    omega_min: float = 100.0
    omega_max: float = 900.0


@dataclass(frozen=True)
class ControllerConfig:
    gain: tuple[tuple[float, ...], ...] = PELICAN_GAIN


@dataclass(frozen=True)
class PemSimConfig:
    """Closed-loop truth simulator: OU pilot references, outputs with optional noise."""

    seed: int = 0
    rate_hz: float = 50.0
    substeps: int = 4
    train_s: float = 300.0
    unseen_s: tuple[float, ...] = (120.0, 120.0)
    # references [phi_r, theta_r, psi_r (rad), Omega_T offset from hover (rad/s)]
    ref_sd: tuple[float, ...] = (0.15, 0.15, 0.4, 15.0)
    ref_tau_s: tuple[float, ...] = (0.7, 0.7, 3.0, 1.0)
    # output noise SD for y = [phi, theta, psi, p, q, r, a_x, a_y, a_z]; empty = noise-free
    noise_sd: tuple[float, ...] = ()
    true_params: dict[str, float] = field(default_factory=lambda: dict(TRUE_PARAMS))


@dataclass(frozen=True)
class PemSection:
    method: str = "SLSQP"  # SLSQP or trust-constr (quasi-Newton, constrained)
    bound_factor: float = 10.0  # bounds theta0 / f .. theta0 * f
    constraints: bool = True  # perpendicular-axis inequalities (20)
    max_iter: int = 200
    tolerance: float = 1e-12
    open_loop_windows_s: float = 10.0
    divergence_rad: float = 0.2  # attitude error that counts as a failed prediction


@dataclass(frozen=True)
class PemConfig:
    name: str = "baseline-pem"
    seed: int = 0
    validation_fraction: float = 0.2
    score_horizon_steps: int = 100
    noisy_sd: tuple[float, ...] = (0.005, 0.005, 0.005, 0.02, 0.02, 0.02, 0.1, 0.1, 0.1)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    geometry: Geometry = field(default_factory=Geometry)
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    simulator: PemSimConfig = field(default_factory=PemSimConfig)
    pem: PemSection = field(default_factory=PemSection)


def validate(cfg: PemConfig, source: str) -> PemConfig:
    s, p, g = cfg.simulator, cfg.pem, cfg.geometry
    require(
        len(cfg.controller.gain) == 4 and all(len(r) == 6 for r in cfg.controller.gain),
        "need 4 rows (motors) of 6 gains [phi, theta, psi, p, q, r]",
        source,
        "controller.gain",
    )
    require(
        len(s.ref_sd) == 4 and len(s.ref_tau_s) == 4, "give 4 values", source, "simulator.ref_sd"
    )
    for name, sd in (("simulator.noise_sd", s.noise_sd), ("noisy_sd", cfg.noisy_sd)):
        require(len(sd) in (0, 9), "give 9 SDs (outputs y) or none", source, name)
    require(
        set(s.true_params) == set(PARAMS),
        f"give exactly {list(PARAMS)}",
        source,
        "simulator.true_params",
    )
    require(
        s.rate_hz > 0 and s.train_s > 0 and s.substeps >= 1,
        "rate_hz, train_s > 0 and substeps >= 1",
        source,
        "simulator.rate_hz",
    )
    require(
        len(s.unseen_s) >= 1 and min(s.unseen_s) > p.open_loop_windows_s > 0,
        f"each unseen flight must be longer than pem.open_loop_windows_s = "
        f"{p.open_loop_windows_s:g} s (> 0), which the open-loop test windows span; lengthen "
        "them or shorten the windows",
        source,
        "simulator.unseen_s",
    )
    require(
        p.method in ("SLSQP", "trust-constr"), "choose SLSQP or trust-constr", source, "pem.method"
    )
    require(p.bound_factor > 1.0, "must be > 1", source, "pem.bound_factor")
    require(
        g.lift_method in ("hover", "blade_element"),
        "choose hover or blade_element",
        source,
        "geometry.lift_method",
    )
    require(len(g.box_size) == 3, "give [x, y, z] in m", source, "geometry.box_size")
    require(0.0 < cfg.validation_fraction < 1.0, "must be in (0, 1)", source, "validation_fraction")
    return cfg


def load_pem_config(path) -> PemConfig:
    table, source = read_toml(path)
    return validate(build(PemConfig, table, source), source)
