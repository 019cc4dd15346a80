"""Config of `gpquad physics thrust|drag|deadreckon` (TOML; unknown keys are errors).

The flights come from rotorpy (`truth.py`): an identification set (hover, forward, lateral)
and the thesis's validation manoeuvres (L, U, square, each with and without yaw).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from gpquad.errors import GpquadError
from gpquad.physics.regression import METHODS
from gpquad.physics.sensors import SensorNoise
from gpquad.physics.truth import MANOEUVRES, PARAM_SETS
from gpquad.study.config_tables import read_toml


@dataclass(frozen=True)
class TruthConfig:
    vehicle: str = "hummingbird"
    dt: float = 0.01
    side: float = 4.0          # leg of the L/U/square paths, m
    speed: float = 3.0         # rotorpy MinSnap average speed, m/s
    cache: str = "results/physics_flights"   # "" for no cache


@dataclass(frozen=True)
class RegressionConfig:
    method: str = "ols"
    smoothing_window: int = 1        # causal moving average on the accelerometer, samples
    validation_fraction: float = 0.3  # last part of each identification flight
    parasitic_drag: bool = True
    drag_intercept: bool = False     # also fit a constant per axis (residual accelerometer bias)
    wls_window: int = 25


@dataclass(frozen=True)
class ThrustConfig:
    hover: str = "hover"
    forward: str = "forward"


@dataclass(frozen=True)
class DragConfig:
    flights: tuple = ("forward", "lateral")


@dataclass(frozen=True)
class DeadReckonConfig:
    manoeuvres: tuple = ("L", "U", "square")
    yaw: tuple = (True, False)


@dataclass(frozen=True)
class PhysicsConfig:
    name: str = "physics"
    seed: int = 1
    truth: TruthConfig = field(default_factory=TruthConfig)
    noise: SensorNoise = field(default_factory=SensorNoise)
    regression: RegressionConfig = field(default_factory=RegressionConfig)
    thrust: ThrustConfig = field(default_factory=ThrustConfig)
    drag: DragConfig = field(default_factory=DragConfig)
    deadreckon: DeadReckonConfig = field(default_factory=DeadReckonConfig)
    base_dir: str = "."

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out.pop("base_dir")
        return out


SECTIONS = {"truth": TruthConfig, "noise": SensorNoise, "regression": RegressionConfig,
            "thrust": ThrustConfig, "drag": DragConfig, "deadreckon": DeadReckonConfig}


def _section(cls, raw: dict, name: str, source: str):
    names = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in raw.items():
        if key not in names:
            raise GpquadError(f"unknown key; known: {sorted(names)}", source=source,
                              field=f"{name}.{key}")
        default = getattr(cls(), key)
        if isinstance(default, tuple):
            if not isinstance(value, list):
                raise GpquadError("must be a list", source=source, field=f"{name}.{key}")
            value = tuple(value)
        elif isinstance(default, bool):
            if not isinstance(value, bool):
                raise GpquadError("must be true or false", source=source, field=f"{name}.{key}")
        elif isinstance(default, (int, float)) and not isinstance(value, (int, float)):
            raise GpquadError(f"must be a number, not {value!r}", source=source,
                              field=f"{name}.{key}")
        kwargs[key] = value
    return cls(**kwargs)


def _check(cfg: PhysicsConfig, source: str) -> None:
    def bad(fieldname, msg):
        raise GpquadError(msg, source=source, field=fieldname)

    if cfg.truth.vehicle not in PARAM_SETS:
        bad("truth.vehicle", f"unknown vehicle; use one of {PARAM_SETS}")
    if not 0 < cfg.truth.dt <= 0.05:
        bad("truth.dt", "must be in (0, 0.05] s")
    if cfg.truth.side <= 0 or cfg.truth.speed <= 0:
        bad("truth.side", "path side and speed must be positive")
    if cfg.regression.method not in METHODS:
        bad("regression.method", f"use one of {METHODS}")
    if not 0 < cfg.regression.validation_fraction < 0.9:
        bad("regression.validation_fraction", "must be in (0, 0.9)")
    if cfg.regression.smoothing_window < 1:
        bad("regression.smoothing_window", "must be >= 1 sample")
    for key, value in dataclasses.asdict(cfg.noise).items():
        if value < 0:
            bad(f"noise.{key}", "must be >= 0")
    for fl in (cfg.thrust.hover, cfg.thrust.forward, *cfg.drag.flights,
               *cfg.deadreckon.manoeuvres):
        if fl not in MANOEUVRES:
            bad("deadreckon.manoeuvres", f"unknown manoeuvre '{fl}'; use {MANOEUVRES}")
    if not cfg.drag.flights:
        bad("drag.flights", "needs at least one flight")
    if not all(isinstance(y, bool) for y in cfg.deadreckon.yaw):
        bad("deadreckon.yaw", "a list of true/false")


def load_physics_config(path) -> PhysicsConfig:
    path = Path(path)
    raw, _ = read_toml(path)
    top = {}
    for key, value in raw.items():
        if key in SECTIONS:
            if not isinstance(value, dict):
                raise GpquadError("must be a table", source=str(path), field=key)
            top[key] = _section(SECTIONS[key], value, key, str(path))
        elif key in ("name", "seed"):
            top[key] = value
        else:
            raise GpquadError(f"unknown key; known: name, seed, {sorted(SECTIONS)}",
                              source=str(path), field=key)
    if not isinstance(top.get("seed", 1), int):
        raise GpquadError("must be an integer", source=str(path), field="seed")
    cfg = PhysicsConfig(**top, base_dir=str(path.resolve().parent))
    _check(cfg, str(path))
    return cfg
