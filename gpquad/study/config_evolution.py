"""Semantic checks of [evolution], [evolution.gp] and [vehicle]: one line naming the file
and the field, raised before any long work."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gpquad.engine.kernels.step import SCHEMES
from gpquad.engine.taps import MAX_TAPS
from gpquad.engine.tree.encoding import MAX_TREE_DEPTH
from gpquad.engine.variables import DEFAULT_INPUTS, STATE_NAMES, TARGET_NAMES
from gpquad.errors import GpquadError

if TYPE_CHECKING:
    from gpquad.study.config import Config

METRICS = ("mae", "mse")
CONSTANT_FITS = ("lm", "nelder-mead", "none")
SELECTIONS = ("bic", "prune")
#: The finishing steps after the six searches, in the order gpquad runs them by default
#: (gpquad.models.finish).
FINISH_STEPS = ("symmetrize", "refine", "repair", "joint_fit")


def check_probability(value: float, source: str, where: str) -> None:
    if not 0.0 <= value <= 1.0:
        raise GpquadError(
            f"must be a probability in [0, 1], got {value}", source=source, field=where
        )


def _choice(value: str, choices, source: str, where: str) -> None:
    if value not in choices:
        raise GpquadError(
            f"choose one of {list(choices)}, got '{value}'", source=source, field=where
        )


def _input_names(cfg: Config) -> set[str]:
    return set(cfg.data.inputs if not isinstance(cfg.data.inputs, str) else DEFAULT_INPUTS)


def validate_evolution(cfg: Config, source: str) -> None:
    """Checks of [evolution], [evolution.gp] and [vehicle]."""
    ev = cfg.evolution
    for i, t in enumerate(ev.targets):
        if t not in TARGET_NAMES:
            raise GpquadError(
                f"unknown target '{t}'; choose from {list(TARGET_NAMES)}",
                source=source,
                field=f"evolution.targets[{i}]",
            )
    if not ev.targets:
        raise GpquadError("at least one target is needed", source=source, field="evolution.targets")
    for name in ("iterations", "n_models", "n_tests", "suite_size", "model_generations"):
        if getattr(ev, name) < 1:
            raise GpquadError("must be >= 1", source=source, field=f"evolution.{name}")
    if not 0.0 <= ev.stall_gain < 1.0:
        raise GpquadError(
            "must be a fraction, at least 0 and below 1",
            source=source,
            field="evolution.stall_gain",
        )
    for name in (
        "stall_iterations",
        "test_generations",
        "simplify_generations",
        "max_delay",
        "gradient_steps",
        "nelder_mead_evals",
    ):
        if getattr(ev, name) < 0:
            raise GpquadError("must be >= 0", source=source, field=f"evolution.{name}")
    if not 0.0 < ev.window_s < 3600.0:
        raise GpquadError(
            "must be a window length in seconds, above 0 and below 3600",
            source=source,
            field="evolution.window_s",
        )
    if ev.n_models < 2:
        raise GpquadError(
            "tests are scored by the variance of the models' errors: need >= 2",
            source=source,
            field="evolution.n_models",
        )
    check_table(
        ev.max_depth,
        "max_depth",
        1,
        MAX_TREE_DEPTH,
        f"must be between 1 and {MAX_TREE_DEPTH}",
        source,
    )
    check_table(ev.max_degree, "max_degree", 0, 16, "must be between 0 (no limit) and 16", source)
    check_table(
        ev.input_taps,
        "input_taps",
        1,
        min(MAX_TAPS, ev.max_delay + 1),
        f"must be between 1 and {MAX_TAPS}, and at most max_delay + 1 "
        f"({ev.max_delay + 1}): each tap needs its own delay",
        source,
    )
    check_table(ev.refine_terms, "refine_terms", 0, 64, "must be between 0 (off) and 64", source)
    _choice(ev.metric, METRICS, source, "evolution.metric")
    _choice(ev.constant_fit, CONSTANT_FITS, source, "evolution.constant_fit")
    _choice(ev.selection, SELECTIONS, source, "evolution.selection")
    _choice(ev.integrator, SCHEMES, source, "evolution.integrator")
    if not 1 <= ev.substeps <= (1 if ev.integrator == "euler" else 64):
        raise GpquadError(
            "must be 1 for euler, 1 to 64 for rk4", source=source, field="evolution.substeps"
        )
    for i, step in enumerate(ev.finish):
        _choice(step, FINISH_STEPS, source, f"evolution.finish[{i}]")
    judged = [step for step in ev.finish if step in ("refine", "repair", "joint_fit")]
    d = cfg.data
    if judged and d.validation == "fraction" and not d.validation_fraction > 0:
        raise GpquadError(
            f"validation_fraction = 0 leaves the finishing steps {judged} no "
            "validation data to judge on: give a fraction > 0, hold out files "
            "in data.validation, or set evolution.finish = []",
            source=source,
            field="data.validation_fraction",
        )
    if len(set(ev.finish)) != len(ev.finish):
        raise GpquadError(
            "a finishing step is listed twice; give each once",
            source=source,
            field="evolution.finish",
        )
    needs_lm = [
        ("linear_seed", ev.linear_seed),
        ("refine_terms", any(ev.refine_for(t) for t in TARGET_NAMES)),
    ]
    for name, used in needs_lm:
        if used and ev.constant_fit != "lm":
            raise GpquadError(
                f'{name} is fitted by Levenberg-Marquardt: set constant_fit = "lm"',
                source=source,
                field=f"evolution.{name}",
            )
    if ev.term_search and ev.constant_fit == "none":
        raise GpquadError(
            'term search runs in the local search: set constant_fit = "lm" or '
            '"nelder-mead", or term_search = false',
            source=source,
            field="evolution.term_search",
        )
    if not 0.0 <= ev.term_min_gain < 1.0:
        raise GpquadError("must be in [0, 1)", source=source, field="evolution.term_min_gain")
    if ev.simplify_tolerance < 0 or ev.prune_tolerance < 0:
        raise GpquadError("must be >= 0", source=source, field="evolution.simplify_tolerance")
    known = set(STATE_NAMES) | _input_names(cfg)
    for i, name in enumerate(ev.exclude_leaves):
        if name not in known:
            raise GpquadError(
                f"unknown variable '{name}'; choose from the states "
                f"{list(STATE_NAMES)} or the inputs",
                source=source,
                field=f"evolution.exclude_leaves[{i}]",
            )
    _validate_gp(cfg, source)
    _validate_vehicle(cfg, source)


def _validate_gp(cfg: Config, source: str) -> None:
    gp = cfg.evolution.gp
    for name in ("p_leaf", "p_constant_leaf", "p_const_perturb", "p_delay"):
        check_probability(getattr(gp, name), source, f"evolution.gp.{name}")
    for name in ("const_low", "const_high", "const_variance"):
        if not math.isfinite(getattr(gp, name)):
            raise GpquadError(
                f"{getattr(gp, name)} is not a finite number",
                source=source,
                field=f"evolution.gp.{name}",
            )
    if gp.const_low >= gp.const_high or not gp.const_variance >= 0:
        raise GpquadError(
            "need const_low < const_high and const_variance >= 0",
            source=source,
            field="evolution.gp.const_low",
        )


def _validate_vehicle(cfg: Config, source: str) -> None:
    """mirror_inputs that name some of the inputs must name only inputs (a typo); ones that
    name none of them leave the mirror off for these inputs (VehicleConfig.flipped), as the
    default roll and yaw names do for motor-level inputs."""
    vehicle = cfg.vehicle
    inputs = _input_names(cfg)
    if isinstance(cfg.data.inputs, str):  # a level: names are known once the log is read
        return
    named = [n in inputs for n in vehicle.mirror_inputs]
    for i, name in enumerate(vehicle.mirror_inputs):
        if any(named) and name not in inputs:
            raise GpquadError(
                f"unknown input '{name}'; list the inputs that change sign in a "
                f"left-right mirror (roll and yaw commands) among "
                f"{sorted(inputs)}",
                source=source,
                field=f"vehicle.mirror_inputs[{i}]",
            )
    if vehicle.symmetric and "symmetrize" in cfg.evolution.finish and not vehicle.mirror_inputs:
        raise GpquadError(
            'a symmetric vehicle needs the inputs its mirror flips (e.g. ["u_R", '
            '"u_Y"]), or symmetric = false',
            source=source,
            field="vehicle.mirror_inputs",
        )


def check_table(value, name: str, low: int, high: int, message: str, source) -> None:
    """One number in [low, high], or a {target: number} table of them (per-target fields:
    input_taps, max_depth, max_degree, refine_terms); the error names the key."""
    table = value if isinstance(value, dict) else {"": value}
    for target, k in table.items():
        where = f"evolution.{name}" + (f".{target}" if target else "")
        if target and target not in TARGET_NAMES:
            raise GpquadError(
                f"unknown target; the table's keys are targets {list(TARGET_NAMES)}",
                source=source,
                field=where,
            )
        if isinstance(k, bool) or not isinstance(k, int) or not low <= k <= high:
            raise GpquadError(message, source=source, field=where)
