"""Semantic checks of an experiment config, the ones types alone cannot express.

Every failure is a GpquadError naming the file and the field, raised before any long work.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gpquad.engine.taps import MAX_TAPS
from gpquad.engine.variables import DEFAULT_INPUTS, STATE_NAMES, TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.study.config_names import validate_names

if TYPE_CHECKING:
    from gpquad.study.config import Config, DataConfig, SweepConfig

FRAMES = ("NED/FRD", "ENU/FLU")
METRICS = ("mae", "mse")
LOCAL_SEARCHES = ("none", "delays", "delays+constants")
CONSTANT_FITS = ("nelder-mead", "gauss-newton")
FINAL_SELECTIONS = ("prune", "bic")


def _check_probability(value: float, source: str, where: str):
    if not 0.0 <= value <= 1.0:
        raise GpquadError(f"must be a probability in [0, 1], got {value}", source=source,
                          field=where)


def validate(cfg: Config, source: str = "config") -> Config:
    """Semantic checks that types alone cannot express."""
    ev = cfg.evolution
    for i, t in enumerate(ev.targets):
        if t not in TARGET_NAMES:
            raise GpquadError(f"unknown target '{t}'; choose from {list(TARGET_NAMES)}",
                              source=source, field=f"evolution.targets[{i}]")
    if not ev.targets:
        raise GpquadError("at least one target is needed", source=source, field="evolution.targets")
    for name in ("p_leaf", "p_constant_leaf", "p_const_perturb", "p_delay"):
        _check_probability(getattr(ev, name), source, f"evolution.{name}")
    positive = ("iterations", "n_models", "n_tests", "suite_size", "window_steps")
    for name in positive:
        if getattr(ev, name) < 1:
            raise GpquadError("must be >= 1", source=source, field=f"evolution.{name}")
    for name in ("model_generations", "test_generations", "simplify_generations", "max_delay",
                 "test_offset_max"):
        if getattr(ev, name) < 0:
            raise GpquadError("must be >= 0", source=source, field=f"evolution.{name}")
    _check_table(ev.max_depth, "max_depth", 1, 8, "must be between 1 and 8", source)
    _check_table(ev.max_degree, "max_degree", 0, 16, "must be between 0 (no limit) and 16",
                 source)
    if ev.n_models < 2:
        raise GpquadError("tests are scored by the variance of the models' errors: need >= 2",
                          source=source, field="evolution.n_models")
    if ev.local_search not in LOCAL_SEARCHES:
        raise GpquadError(f"choose one of {list(LOCAL_SEARCHES)}", source=source,
                          field="evolution.local_search")
    if ev.constant_fit not in CONSTANT_FITS:
        raise GpquadError(f"choose one of {list(CONSTANT_FITS)}", source=source,
                          field="evolution.constant_fit")
    if ev.final_selection not in FINAL_SELECTIONS:
        raise GpquadError(f"choose one of {list(FINAL_SELECTIONS)}", source=source,
                          field="evolution.final_selection")
    known = set(STATE_NAMES) | set(cfg.data.inputs if not isinstance(cfg.data.inputs, str)
                                   else DEFAULT_INPUTS)
    for i, name in enumerate(ev.exclude_leaves):
        if name not in known:
            raise GpquadError(f"unknown variable '{name}'; choose from the states "
                              f"{list(STATE_NAMES)} or the inputs", source=source,
                              field=f"evolution.exclude_leaves[{i}]")
    inputs = set(cfg.data.inputs if not isinstance(cfg.data.inputs, str) else DEFAULT_INPUTS)
    for i, name in enumerate(ev.mirror_inputs):
        if name not in inputs:
            raise GpquadError(f"unknown input '{name}'; list the inputs that change sign in a "
                              f"left-right mirror (roll and yaw commands) among "
                              f"{sorted(inputs)}", source=source,
                              field=f"evolution.mirror_inputs[{i}]")
    if ev.symmetric_equations and not ev.mirror_inputs:
        raise GpquadError("the symmetric equations keep the parity of the mirror that flips "
                          'mirror_inputs: name them (e.g. ["u_R", "u_Y"])', source=source,
                          field="evolution.symmetric_equations")
    if not 0.0 <= ev.attitude_weight <= 100.0:
        raise GpquadError("must be in [0, 100] (1 counts the angle like the rate; 0 = off)",
                          source=source, field="evolution.attitude_weight")
    if not 0.0 <= ev.term_min_gain < 1.0:
        raise GpquadError("must be in [0, 1)", source=source, field="evolution.term_min_gain")
    _check_table(ev.input_taps, "input_taps", 1, min(MAX_TAPS, ev.max_delay + 1),
                 f"must be between 1 and {MAX_TAPS}, and at most max_delay + 1 "
                 f"({ev.max_delay + 1}): each tap needs its own delay", source)
    if ev.gradient_steps < 0:
        raise GpquadError("must be >= 0", source=source, field="evolution.gradient_steps")
    if ev.linear_seed and ev.constant_fit != "gauss-newton":
        raise GpquadError('the linear seed is fitted by Levenberg-Marquardt: set constant_fit = '
                          '"gauss-newton"', source=source, field="evolution.linear_seed")
    _check_table(ev.refine_terms, "refine_terms", 0, 64, "must be between 0 (off) and 64",
                 source)
    if any(ev.refine_for(t) for t in TARGET_NAMES) and ev.constant_fit != "gauss-newton":
        raise GpquadError('the refined equations are fitted by Levenberg-Marquardt: set '
                          'constant_fit = "gauss-newton"', source=source,
                          field="evolution.refine_terms")
    if any(not 1 <= h < ev.window_steps for h in ev.fit_horizons) or \
            list(ev.fit_horizons) != sorted(set(ev.fit_horizons)):
        raise GpquadError(f"give ascending step counts between 1 and window_steps - 1 "
                          f"({ev.window_steps - 1})", source=source, field="evolution.fit_horizons")
    if ev.simplify_tolerance < 0 or ev.local_search_evals < 0 or ev.prune_tolerance < 0:
        raise GpquadError("must be >= 0", source=source, field="evolution.simplify_tolerance")
    if ev.metric not in METRICS:
        raise GpquadError(f"choose one of {list(METRICS)}", source=source, field="evolution.metric")
    if ev.const_low >= ev.const_high or ev.const_variance < 0:
        raise GpquadError("need const_low < const_high and const_variance >= 0", source=source,
                          field="evolution.const_low")
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
        raise GpquadError(f"unknown targets {sorted(unknown_eq)}", source=source,
                          field="simulator.equations")
    bad_noise = set(s.measurement_noise) - {"attitude", "velocity", "rates"}
    if bad_noise or any(v < 0 for v in s.measurement_noise.values()):
        raise GpquadError("keys attitude, velocity, rates with SD >= 0", source=source,
                          field="simulator.measurement_noise")
    if not (s.rate_hz > 0 and s.duration_s > 0 and s.rate_hz * s.duration_s < float("inf")):
        raise GpquadError("rate_hz and duration_s must be finite and > 0", source=source,
                          field="simulator.rate_hz")
    if round(s.rate_hz * s.duration_s) < 2:
        raise GpquadError(f"{s.duration_s} s at {s.rate_hz} Hz is less than two samples; fly "
                          "for longer", source=source, field="simulator.duration_s")
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
        raise GpquadError(f"assembly = 'repetition' needs full_models <= runs ({sw.runs}); "
                          "lower full_models or use assembly = 'bootstrap'", source=source,
                          field="sweep.full_models")
    if sw.input_noise < 0 or sw.window_s <= 0 or sw.divergence_factor <= 0:
        raise GpquadError("input_noise must be >= 0, window_s and divergence_factor > 0",
                          source=source, field="sweep.input_noise")
    if not sw.horizons_s or min(sw.horizons_s) <= 0:
        raise GpquadError("need positive horizons in s", source=source, field="sweep.horizons_s")
    _check_probability(sw.shared_fraction, source, "sweep.shared_fraction")


SEGMENT_MODES = ("auto", "armed", "thrust", "range", "none")


def validate_pipeline(d: DataConfig, source: str = "config") -> None:
    """Checks of the log-pipeline fields of [data]."""
    if d.segment not in SEGMENT_MODES:
        raise GpquadError(f"choose one of {list(SEGMENT_MODES)}", source=source,
                          field="data.segment")
    if d.segment == "range" and (len(d.time_range) != 2 or d.time_range[0] >= d.time_range[1]):
        raise GpquadError("segment = 'range' needs time_range = [start_s, stop_s], start < stop",
                          source=source, field="data.time_range")
    for name in ("resample_hz", "max_gap_s", "check_max_rse"):
        if getattr(d, name) <= 0:
            raise GpquadError("must be > 0", source=source, field=f"data.{name}")
    if d.cutoff_hz < 0 or d.cutoff_hz >= d.resample_hz / 2:
        raise GpquadError(f"must be in [0, resample_hz / 2 = {d.resample_hz / 2}) (0 = no filter)",
                          source=source, field="data.cutoff_hz")
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
            raise GpquadError(f"choose a level {list(LEVELS)} or a list of input names",
                              source=source, field="data.inputs")
        if d.format in ("generic", "table") or not d.files:
            raise GpquadError(f"input level '{d.inputs}' is chosen by a log reader (px4-csv, "
                              "ulog, betaflight, ardupilot); the simulator, generic files and "
                              "tables need a list of input names",
                              source=source, field="data.inputs")
    else:
        if not d.inputs or len(set(d.inputs)) != len(d.inputs):
            raise GpquadError("need distinct input names", source=source, field="data.inputs")
        clash = set(d.inputs) & set(STATE_NAMES)
        if clash:
            raise GpquadError(f"input names {sorted(clash)} clash with state names",
                              source=source, field="data.inputs")
    if isinstance(d.validation, str) and d.validation != "fraction":
        raise GpquadError("choose \"fraction\" or a list of flight files held out whole",
                          source=source, field="data.validation")
    if d.max_attitude_step_deg <= 0:
        raise GpquadError("must be > 0", source=source, field="data.max_attitude_step_deg")


def _check_table(value, name: str, low: int, high: int, message: str, source) -> None:
    """One number in [low, high], or a {target: number} table of them (per-target fields:
    input_taps, max_depth, max_degree); the error names the key."""
    table = value if isinstance(value, dict) else {"": value}
    for target, k in table.items():
        where = f"evolution.{name}" + (f".{target}" if target else "")
        if target and target not in TARGET_NAMES:
            raise GpquadError(f"unknown target; the table's keys are targets {list(TARGET_NAMES)}",
                              source=source, field=where)
        if isinstance(k, bool) or not isinstance(k, int) or not low <= k <= high:
            raise GpquadError(message, source=source, field=where)
