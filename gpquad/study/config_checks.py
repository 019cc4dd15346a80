"""Semantic checks of an experiment config, the ones types alone cannot express.

Every failure is a GpquadError naming the file and the field, raised before any long work.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.study.config_evolution import validate_evolution
from gpquad.study.config_names import validate_names

if TYPE_CHECKING:
    from gpquad.study.config import Config, DataConfig, SweepConfig

FRAMES = ("NED/FRD", "ENU/FLU")
METRICS = ("mae", "mse")


def _check_probability(value: float, source: str, where: str):
    if not 0.0 <= value <= 1.0:
        raise GpquadError(
            f"must be a probability in [0, 1], got {value}", source=source, field=where
        )


def validate(cfg: Config, source: str = "config") -> Config:
    """Semantic checks that types alone cannot express."""
    validate_evolution(cfg, source)
    d = cfg.data
    if d.frame not in FRAMES:
        raise GpquadError(f"choose one of {list(FRAMES)}", source=source, field="data.frame")
    if d.trim not in ("none", "mean", "given"):
        raise GpquadError("choose none, mean or given", source=source, field="data.trim")
    if not 0.0 <= d.validation_fraction < 1.0:
        raise GpquadError("must be in [0, 1)", source=source, field="data.validation_fraction")
    validate_pipeline(d, source)
    validate_inputs(d, source)
    s = cfg.simulator
    unknown_eq = set(s.equations) - set(TARGET_NAMES)
    if unknown_eq:
        raise GpquadError(
            f"unknown targets {sorted(unknown_eq)}", source=source, field="simulator.equations"
        )
    bad_noise = set(s.measurement_noise) - {"attitude", "velocity", "rates"}
    if bad_noise or any(v < 0 for v in s.measurement_noise.values()):
        raise GpquadError(
            "keys attitude, velocity, rates with SD >= 0",
            source=source,
            field="simulator.measurement_noise",
        )
    if not (s.rate_hz > 0 and s.duration_s > 0 and s.rate_hz * s.duration_s < float("inf")):
        raise GpquadError(
            "rate_hz and duration_s must be finite and > 0",
            source=source,
            field="simulator.rate_hz",
        )
    if round(s.rate_hz * s.duration_s) < 2:
        raise GpquadError(
            f"{s.duration_s} s at {s.rate_hz} Hz is less than two samples; fly for longer",
            source=source,
            field="simulator.duration_s",
        )
    validate_sweep(cfg.sweep, source)
    validate_names(cfg, source)
    return cfg


def validate_sweep(sw: SweepConfig, source: str = "config") -> None:
    """Checks of the [sweep] section."""
    for name in ("runs", "full_models"):
        if getattr(sw, name) < 1:
            raise GpquadError("must be >= 1", source=source, field=f"sweep.{name}")
    if sw.selection not in ("validation", "train"):
        raise GpquadError("choose validation or train", source=source, field="sweep.selection")
    if sw.assembly not in ("bootstrap", "repetition"):
        raise GpquadError("choose bootstrap or repetition", source=source, field="sweep.assembly")
    if sw.assembly == "repetition" and sw.full_models > sw.runs:
        raise GpquadError(
            f"assembly = 'repetition' needs full_models <= runs ({sw.runs}); "
            "lower full_models or use assembly = 'bootstrap'",
            source=source,
            field="sweep.full_models",
        )
    if sw.input_noise < 0 or sw.window_s <= 0 or sw.divergence_factor <= 0:
        raise GpquadError(
            "input_noise must be >= 0, window_s and divergence_factor > 0",
            source=source,
            field="sweep.input_noise",
        )
    if not sw.horizons_s or min(sw.horizons_s) <= 0:
        raise GpquadError("need positive horizons in s", source=source, field="sweep.horizons_s")
    _check_probability(sw.shared_fraction, source, "sweep.shared_fraction")


SEGMENT_MODES = ("auto", "armed", "thrust", "range", "none")


def validate_pipeline(d: DataConfig, source: str = "config") -> None:
    """Checks of the log-pipeline fields of [data]."""
    from gpquad.data.formats import FORMATS

    if d.format not in FORMATS:
        raise GpquadError(
            f"unknown format '{d.format}'; choose one of {sorted(FORMATS)}",
            source=source,
            field="data.format",
        )
    if d.segment not in SEGMENT_MODES:
        raise GpquadError(
            f"choose one of {list(SEGMENT_MODES)}", source=source, field="data.segment"
        )
    if d.segment == "range" and (len(d.time_range) != 2 or d.time_range[0] >= d.time_range[1]):
        raise GpquadError(
            "segment = 'range' needs time_range = [start_s, stop_s], start < stop",
            source=source,
            field="data.time_range",
        )
    for name in ("resample_hz", "max_gap_s", "check_max_rse"):
        if getattr(d, name) <= 0:
            raise GpquadError("must be > 0", source=source, field=f"data.{name}")
    if d.cutoff_hz < 0 or d.cutoff_hz >= d.resample_hz / 2:
        raise GpquadError(
            f"must be in [0, resample_hz / 2 = {d.resample_hz / 2}) (0 = no filter)",
            source=source,
            field="data.cutoff_hz",
        )
    for name in ("filter_taps", "downsample", "check_steps"):
        if getattr(d, name) < 1:
            raise GpquadError("must be >= 1", source=source, field=f"data.{name}")
    if d.min_segment_s < 0 or d.log_index < 0:
        raise GpquadError("must be >= 0", source=source, field="data.min_segment_s")
    if d.rates_from not in ("quaternion", "log"):
        raise GpquadError("choose quaternion or log", source=source, field="data.rates_from")


def validate_inputs(d: DataConfig, source: str = "config") -> None:
    """data.inputs: distinct names, or a level that a log reader resolves; data.validation."""
    from gpquad.data.levels import LEVELS

    if isinstance(d.inputs, str):
        if d.inputs not in LEVELS:
            raise GpquadError(
                f"choose a level {list(LEVELS)} or a list of input names",
                source=source,
                field="data.inputs",
            )
        if d.format in ("generic", "table") or not d.files:
            raise GpquadError(
                f"input level '{d.inputs}' is chosen by a log reader (px4-csv, "
                "ulog, betaflight, ardupilot); the simulator, generic files and "
                "tables need a list of input names",
                source=source,
                field="data.inputs",
            )
    else:
        if not d.inputs or len(set(d.inputs)) != len(d.inputs):
            raise GpquadError("need distinct input names", source=source, field="data.inputs")
        clash = set(d.inputs) & set(STATE_NAMES)
        if clash:
            raise GpquadError(
                f"input names {sorted(clash)} clash with state names",
                source=source,
                field="data.inputs",
            )
    if isinstance(d.validation, str) and d.validation != "fraction":
        raise GpquadError(
            'choose "fraction" or a list of flight files held out whole',
            source=source,
            field="data.validation",
        )
    if d.max_attitude_step_deg <= 0:
        raise GpquadError("must be > 0", source=source, field="data.max_attitude_step_deg")
