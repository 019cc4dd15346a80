"""Config of `gpquad physics thrust|drag|deadreckon` (TOML; unknown keys are errors).

Two sources of flights:
- a log: `[data]` as in `gpquad run` (files, format, frame, columns, segmentation), plus
  `[vehicle]` (mass in kg; motor pole pairs where the log gives eRPM). Motor speeds and the
  accelerometer are read by gpquad.data.motors.
- simulated truth (no `[data]` files): rotorpy flights (`truth.py`), an identification set
  (hover, forward, lateral) and the thesis's validation manoeuvres (L, U, square, each with
  and without yaw), with the vehicle's known coefficients.
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
    side: float = 4.0  # leg of the L/U/square paths, m
    speed: float = 3.0  # rotorpy MinSnap average speed, m/s
    cache: str = "results/physics_flights"  # "" for no cache


@dataclass(frozen=True)
class RegressionConfig:
    method: str = "ols"
    smoothing_window: int = 1  # causal moving average on the accelerometer, samples
    validation_fraction: float = 0.3  # last part of each identification flight
    parasitic_drag: bool = True
    drag_intercept: bool = False  # also fit a constant per axis (residual accelerometer bias)
    wls_window: int = 25


@dataclass(frozen=True)
class ThrustConfig:
    hover: str = "hover"  # simulated truth: the manoeuvres flown
    forward: str = "forward"
    hover_max_speed: float = 0.5  # log: hover samples are slower than this (m/s) ...
    hover_max_rate: float = 1.0  # ... and turn slower than this (rad/s)
    min_height: float = 0.0  # log with position: fit only this high above the
    #                                   segment's lowest point (m; drops ground contact)


@dataclass(frozen=True)
class VehicleConfig:
    mass: float = 0.0  # kg; required for a log
    motor_pole_pairs: int = 0  # eRPM -> RPM; 0: from the log header (Betaflight)


@dataclass(frozen=True)
class DragConfig:
    flights: tuple = ("forward", "lateral")


@dataclass(frozen=True)
class DeadReckonConfig:
    manoeuvres: tuple = ("L", "U", "square")
    yaw: tuple = (True, False)
    window_s: float = 0.0  # log: dead-reckon windows of this length (0: whole segments)


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
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    data: dict = field(default_factory=dict)  # the [data] table as written
    base_dir: str = "."

    @property
    def source(self) -> str:
        """ "log" when [data] lists files, else "truth" (rotorpy)."""
        return "log" if self.data.get("files") else "truth"

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out.pop("base_dir")
        if self.source == "truth":  # the simulated-truth record as it always was
            out.pop("vehicle")
            out.pop("data")
        return out

    def data_config(self, source: str = "physics config"):
        """[data] as gpquad run reads it (validated), relative paths from the config's folder."""
        from gpquad.study.config import config_from_dict

        return config_from_dict({"data": dict(self.data)}, source, self.base_dir).data

    def data_paths(self) -> list[Path]:
        return [(Path(self.base_dir) / f).resolve() for f in self.data.get("files", ())]


SECTIONS = {
    "truth": TruthConfig,
    "noise": SensorNoise,
    "regression": RegressionConfig,
    "thrust": ThrustConfig,
    "drag": DragConfig,
    "deadreckon": DeadReckonConfig,
    "vehicle": VehicleConfig,
}


def _section(cls, raw: dict, name: str, source: str):
    names = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in raw.items():
        if key not in names:
            raise GpquadError(
                f"unknown key; known: {sorted(names)}", source=source, field=f"{name}.{key}"
            )
        default = getattr(cls(), key)
        if isinstance(default, tuple):
            if not isinstance(value, list):
                raise GpquadError("must be a list", source=source, field=f"{name}.{key}")
            value = tuple(value)
        elif isinstance(default, bool):
            if not isinstance(value, bool):
                raise GpquadError("must be true or false", source=source, field=f"{name}.{key}")
        elif isinstance(default, (int, float)) and not isinstance(value, (int, float)):
            raise GpquadError(
                f"must be a number, not {value!r}", source=source, field=f"{name}.{key}"
            )
        kwargs[key] = value
    return cls(**kwargs)


def _check(cfg: PhysicsConfig, source: str) -> None:
    def bad(fieldname, msg):
        raise GpquadError(msg, source=source, field=fieldname)

    if cfg.regression.method not in METHODS:
        bad("regression.method", f"use one of {METHODS}")
    if not 0 < cfg.regression.validation_fraction < 0.9:
        bad("regression.validation_fraction", "must be in (0, 0.9)")
    if cfg.regression.smoothing_window < 1:
        bad("regression.smoothing_window", "must be >= 1 sample")
    if not cfg.drag.flights:
        bad("drag.flights", "needs at least one flight")
    if cfg.source == "log":
        _check_log(cfg, source)
        return
    if cfg.truth.vehicle not in PARAM_SETS:
        bad("truth.vehicle", f"unknown vehicle; use one of {PARAM_SETS}")
    if not 0 < cfg.truth.dt <= 0.05:
        bad("truth.dt", "must be in (0, 0.05] s")
    if cfg.truth.side <= 0 or cfg.truth.speed <= 0:
        bad("truth.side", "path side and speed must be positive")
    for key, value in dataclasses.asdict(cfg.noise).items():
        if value < 0:
            bad(f"noise.{key}", "must be >= 0")
    for fl in (cfg.thrust.hover, cfg.thrust.forward, *cfg.drag.flights, *cfg.deadreckon.manoeuvres):
        if fl not in MANOEUVRES:
            bad("deadreckon.manoeuvres", f"unknown manoeuvre '{fl}'; use {MANOEUVRES}")
    if not all(isinstance(y, bool) for y in cfg.deadreckon.yaw):
        bad("deadreckon.yaw", "a list of true/false")


def _check_log(cfg: PhysicsConfig, source: str) -> None:
    """Checks of a config that reads a log: [vehicle], the log-only fields and [data]."""
    from gpquad.data.motors import FORMATS

    v = cfg.vehicle
    if not v.mass > 0:
        raise GpquadError(
            "the vehicle's mass in kg is needed to turn specific force into "
            "thrust (m f_z = k_t sum w^2); set [vehicle] mass = ...",
            source=source,
            field="vehicle.mass",
        )
    if not isinstance(v.motor_pole_pairs, int) or v.motor_pole_pairs < 0:
        raise GpquadError(
            "an integer >= 0 (0: from the log header)",
            source=source,
            field="vehicle.motor_pole_pairs",
        )
    for name in ("hover_max_speed", "hover_max_rate"):
        if not getattr(cfg.thrust, name) > 0:
            raise GpquadError("must be > 0", source=source, field=f"thrust.{name}")
    if cfg.thrust.min_height < 0:
        raise GpquadError(
            "must be >= 0 m (0: keep every in-flight sample)",
            source=source,
            field="thrust.min_height",
        )
    if cfg.deadreckon.window_s < 0:
        raise GpquadError(
            "must be >= 0 (0: whole segments)", source=source, field="deadreckon.window_s"
        )
    data = cfg.data_config(source)
    if data.format not in FORMATS:
        raise GpquadError(
            f"no motor-speed reader for format '{data.format}'; use one of {list(FORMATS)}",
            source=source,
            field="data.format",
        )


def load_physics_config(path) -> PhysicsConfig:
    path = Path(path)
    raw, _ = read_toml(path)
    top = {}
    for key, value in raw.items():
        if key == "data":
            if not isinstance(value, dict):
                raise GpquadError("must be a table", source=str(path), field=key)
            top["data"] = dict(value)
        elif key in SECTIONS:
            if not isinstance(value, dict):
                raise GpquadError("must be a table", source=str(path), field=key)
            top[key] = _section(SECTIONS[key], value, key, str(path))
        elif key in ("name", "seed"):
            top[key] = value
        else:
            raise GpquadError(
                f"unknown key; known: name, seed, data, {sorted(SECTIONS)}",
                source=str(path),
                field=key,
            )
    if not isinstance(top.get("seed", 1), int):
        raise GpquadError("must be an integer", source=str(path), field="seed")
    if top.get("data", {}).get("files") and "truth" in top:
        raise GpquadError(
            "[data] files and [truth] name two sources of flights; keep one",
            source=str(path),
            field="truth",
        )
    if "vehicle" in top and not top.get("data", {}).get("files"):
        raise GpquadError(
            "[vehicle] describes a logged vehicle but [data] lists no files; "
            "the simulated truth takes its vehicle from [truth] vehicle",
            source=str(path),
            field="vehicle",
        )
    cfg = PhysicsConfig(**top, base_dir=str(path.resolve().parent))
    _check(cfg, str(path))
    return cfg
