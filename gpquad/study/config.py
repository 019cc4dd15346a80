"""Experiment configuration: frozen dataclasses loaded from TOML.

Unknown keys and wrong types are errors that name the file and the field. The engine's
defaults are the best engine measured; `preset = "paper"` gives the paper's method
(gpquad.study.presets). Keys of older versions are migrated (gpquad.study.config_migrate).
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path

from gpquad.engine.variables import DEFAULT_INPUTS, TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.study.config_checks import validate
from gpquad.study.config_evolution import FINISH_STEPS
from gpquad.study.config_migrate import migrate
from gpquad.study.config_tables import build_dataclass, read_toml
from gpquad.study.presets import with_preset

#: The dominant terms of the paper's median model (Table 1), used by the reference simulator.
MEDIAN_MODEL = {
    "a_x": "10.0*theta - 0.6*u",
    "a_y": "-9.2*phi - 0.6*v",
    "a_z": "28.2*u_T(t-5) - w - 9.81",
    "p_dot": "10.3*u_R(t-1) - 4.15*p",
    "q_dot": "-9.8*u_P - 3.3*q",
    "r_dot": "-7.8*u_Y(t-2) - 1.9*r",
}


@dataclass(frozen=True)
class DataConfig:
    """Where the flight data comes from and how it is read."""

    files: tuple[str, ...] = ()  # empty: fly the reference simulator
    format: str = "generic"  # generic | px4-csv | ulog | betaflight | ardupilot | table
    frame: str = "NED/FRD"  # of the file's quaternion, velocities and rates: or "ENU/FLU"
    # input names, or a level for log readers: "rates" | "torque" | "sticks" | "motors"
    # (gpquad.data.levels); the default names take "rates" wherever a log has rate set-points
    inputs: tuple[str, ...] | str = DEFAULT_INPUTS
    columns: dict[str, str] = field(default_factory=dict)  # canonical name -> file column
    trim: str = "none"  # none | mean | given
    trim_values: dict[str, float] = field(default_factory=dict)  # trim = "given": per input
    validation_fraction: float = 2000 / 13800  # paper: 11,800 train + 2,000 validation
    # "fraction" (the last validation_fraction of every flight) or files held out whole
    validation: tuple[str, ...] | str = "fraction"
    # Log pipeline (formats px4-csv, ulog, betaflight, table; see gpquad.data.pipeline).
    log_index: int = 0  # Betaflight: which log of a multi-log file (1-based); 0 = every log
    resample_hz: float = 100.0  # common clock before filtering (paper: 100 Hz)
    max_gap_s: float = 0.2  # a longer gap in any stream splits the flight there
    segment: str = "auto"  # auto (armed and thrust) | armed | thrust | range | none
    thrust_threshold: float = 0.2  # normalised collective thrust above which the craft flies
    time_range: tuple[float, ...] = ()  # segment = "range": (start_s, stop_s) from log start
    min_segment_s: float = 10.0  # shorter in-flight segments are dropped
    filter_taps: int = 200  # zero-phase FIR low-pass length (paper: 200)
    cutoff_hz: float = 5.0  # FIR cutoff (paper: 5 Hz); 0 = no filter
    filter_inputs: bool = True  # filter the inputs too (anti-aliasing before downsampling)
    downsample: int = 4  # paper: 100 Hz -> 25 Hz
    rates_from: str = "quaternion"  # quaternion (exact discrete inverse) | log
    check_steps: int = 750  # integration-check window (paper: 750 steps)
    check_max_rse: float = 0.05  # integration check passes below this RSE (paper: 5 %)
    check_before_run: bool = True  # refuse to start a run on a dataset that fails the check
    # an attitude step this much larger than the gyro explains (deg per clock sample) is an
    # estimator reset: the flight is split there (as at a change of a reset counter)
    max_attitude_step_deg: float = 5.0


@dataclass(frozen=True)
class SimulatorConfig:
    """Reference simulator: a known model flown by a pilot-like closed loop."""

    seed: int = 0
    rate_hz: float = 25.0
    duration_s: float = 552.0  # 13,800 samples at 25 Hz, as in the paper
    equations: dict[str, str] = field(default_factory=lambda: dict(MEDIAN_MODEL))
    trim: dict[str, float] = field(default_factory=lambda: {"u_T": 9.81 / 28.2})
    stick_sd: dict[str, float] = field(
        default_factory=lambda: {"u_P": 0.08, "u_R": 0.08, "u_Y": 0.08, "u_T": 0.03}
    )
    stick_time_constant_s: float = 0.6
    # Pilot feedback: input -> {state: gain}; keeps attitude and speed bounded.
    pilot_gains: dict[str, dict[str, float]] = field(
        default_factory=lambda: {
            "u_R": {"phi": -0.6, "v": 0.05},
            "u_P": {"theta": 0.6, "u": 0.05},
            "u_Y": {"psi": 0.15},
        }
    )
    input_limit: float = 1.0
    # Gaussian measurement noise on the recorded flight (not on the dynamics), SD per signal:
    # "attitude" (rad, a random small rotation), "velocity" (m/s), "rates" (rad/s).
    measurement_noise: dict[str, float] = field(default_factory=dict)
    # How the truth is flown: "rk4" with `substeps` steps per sample (the equations as the
    # continuous-time ODEs they are, as a vehicle flies them) or "euler" (one eq. 2 step per
    # sample: the paper's discrete-time model).
    integrator: str = "rk4"
    substeps: int = 8


#: The value of a per-target field (input_taps, max_depth, max_degree, refine_terms) for a
#: target that its {target: number} table leaves out.
PER_TARGET_FALLBACK = {"input_taps": 1, "max_depth": 5, "max_degree": 0, "refine_terms": 0}
RATE_TARGETS = ("p_dot", "q_dot", "r_dot")


def _per_rate_target(value: int, translational: int | None = None) -> dict[str, int]:
    table = {t: value for t in RATE_TARGETS}
    if translational is not None:
        table.update({t: translational for t in ("a_x", "a_y", "a_z")})
    return table


@dataclass(frozen=True)
class GPConfig:
    """The paper's variation operators (section 2.2): probabilities and constant ranges."""

    p_leaf: float = 0.7  # a new node is a leaf with this probability
    p_constant_leaf: float = 0.25  # share of new leaves that are constants (not in the paper)
    const_low: float = -5.0  # new constants are uniform in [const_low, const_high]
    const_high: float = 5.0  # upper end of the new constants' range
    const_variance: float = 0.1  # a constant mutation adds N(0, const_variance)
    p_const_perturb: float = 0.5  # a constant is perturbed with this probability
    p_delay: float = 0.1  # each input delay is redrawn with this probability


@dataclass(frozen=True)
class VehicleConfig:
    """What the engine may assume about the vehicle."""

    # Left-right symmetric (a quadrotor, not a tricopter or a payload off to one side): the
    # equations keep the parity of a left-right mirror ("symmetrize"), the stability repair
    # also flies the mirrored validation flights, and `run` reports terms of the wrong parity.
    symmetric: bool = True
    # The inputs that change sign in the mirror image of a flight (roll and yaw commands).
    mirror_inputs: tuple[str, ...] = ("u_R", "u_Y")

    def flipped(self, input_names) -> tuple[str, ...]:
        """The mirrored inputs when the vehicle is symmetric and the data has all of them."""
        names = tuple(self.mirror_inputs)
        if not self.symmetric or not names:
            return ()
        return names if all(n in input_names for n in names) else ()


@dataclass(frozen=True)
class EvolutionConfig:
    """How each equation is searched and finished. The defaults are the best engine measured
    (docs/decisions); `preset = "paper"` is the paper's method (gpquad.study.presets)."""

    # The accelerations to identify, each alone; a target whose state the log does not
    # measure is left out (docs/guide.md).
    targets: tuple[str, ...] = TARGET_NAMES
    iterations: int = 12  # coevolution iterations (paper: 30)
    # Stop a search early when `stall_iterations` iterations in a row (0 = never) did not
    # lower its best training error by `stall_gain` of it (docs/decisions).
    stall_iterations: int = 3
    stall_gain: float = 0.01
    model_generations: int = 600  # model hill-climber generations per iteration
    test_generations: int = 80  # test hill-climber generations per iteration
    n_models: int = 14  # model hill climbers
    n_tests: int = 5  # test hill climbers
    suite_size: int = 6  # tests in the suite the models are scored on
    window_s: float = 10.0  # length of a test window, s (paper: 30); tests move by half of it
    # Largest tree depth: one number, or a table per target (a target left out gets 5).
    max_depth: int | dict[str, int] = field(default_factory=lambda: _per_rate_target(7))
    # Largest polynomial degree (x y is 2; a quotient counts both sides); 0 = no limit.
    # One number, or a table per target (a target left out gets 0).
    max_degree: int | dict[str, int] = field(default_factory=lambda: _per_rate_target(2))
    max_delay: int = 5  # input delays 0..max_delay samples
    # Each input may appear at up to this many evolvable delays (taps) per equation: one
    # number, or a table per target (a target left out gets 1, the paper's one delay).
    input_taps: int | dict[str, int] = field(default_factory=lambda: _per_rate_target(6, 4))
    metric: str = "mae"  # fitness: mean absolute ("mae") or squared ("mse") state error
    simplify_generations: int = 50  # re-convergence generations of a bloat simplification
    # Keep a simplification whose error is at most (1 + tolerance) x before (0: only better).
    simplify_tolerance: float = 0.01
    # Constants after every model phase: "lm" (Levenberg-Marquardt through the integrator,
    # forward-mode sensitivities), "nelder-mead", or "none" (mutation only, the paper);
    # "lm" and "nelder-mead" also search single-input delay changes.
    constant_fit: str = "lm"
    nelder_mead_evals: int = 150  # evaluations of one Nelder-Mead fit
    gradient_steps: int = 20  # evaluations of one Levenberg-Marquardt fit
    # The reported equation: "bic" (pruned while the BIC of the integrated state does not
    # grow, then the lowest BIC among it and the Pareto front) or "prune" (the best climber,
    # pruned within prune_tolerance x the error of the best constant model; 0 = not pruned).
    selection: str = "bic"
    prune_tolerance: float = 0.0  # selection = "prune": the allowed error growth (0 = off)
    linear_seed: bool = True  # one climber starts from the linear model, fitted by LM
    term_search: bool = True  # try best + c x and best + c x y after every model phase
    term_min_gain: float = 0.01  # a term (search or refinement) must lower the error by this
    # State or input names no equation may read: psi, the heading, does not act on the
    # body-frame dynamics and does not carry over between flights.
    exclude_leaves: tuple[str, ...] = ("psi",)
    # An excluded name stays allowed when an input tracks it (an angle set-point: the input
    # explains >= 30 % of its variance, correlation >= 0.6), e.g. psi under a heading set-point.
    keep_tracked: bool = True
    # The steps that make six searched equations one model, in order: "symmetrize" (drop
    # terms of the wrong left-right parity, [vehicle]), "refine" (a first-order lag and up to
    # refine_terms product terms per equation, kept by validation), "repair" (swap in front
    # alternatives while the six diverge together), "joint_fit" (refit every constant on
    # full-model flights, kept if validation improves). [] = the searched equations as found.
    finish: tuple[str, ...] = FINISH_STEPS
    # Terms the refinement may add: one number, or a table per target (left out: 0).
    refine_terms: int | dict[str, int] = field(default_factory=lambda: _per_rate_target(20))
    # How the reported equations are fitted, chosen and scored: "rk4" (the printed ODEs in
    # continuous time, inputs held over a sample; gpquad.engine.kernels.step) with
    # `substeps` RK4 steps per sample, or "euler" (eq. 2, one step per sample, the paper).
    # The generations always fly eq. 2, the cheap surrogate.
    integrator: str = "rk4"
    substeps: int = 1  # rk4 steps per sample (euler: 1)
    gp: GPConfig = field(default_factory=GPConfig)

    def window_steps(self, dt: float) -> int:
        """Samples in a test window at sample period dt (s)."""
        return max(1, int(round(self.window_s / dt)))

    def taps_for(self, target: str) -> int:
        """Taps per input of `target`'s equation."""
        return self._per_target("input_taps", target)

    def depth_for(self, target: str) -> int:
        """Largest tree depth of `target`'s equation."""
        return self._per_target("max_depth", target)

    def degree_for(self, target: str) -> int:
        """Largest polynomial degree of `target`'s equation (0: no limit)."""
        return self._per_target("max_degree", target)

    def refine_for(self, target: str) -> int:
        """Terms the refinement may add to `target`'s equation (0: none)."""
        if "refine" not in self.finish:
            return 0
        return self._per_target("refine_terms", target)

    def _per_target(self, name: str, target: str) -> int:
        """Field `name` for `target`: one number for every target, or a {target: number}
        table whose left-out targets get PER_TARGET_FALLBACK[name]."""
        value = getattr(self, name)
        if isinstance(value, dict):
            return int(value.get(target, PER_TARGET_FALLBACK[name]))
        return int(value)

    def for_target(self, target: str) -> EvolutionConfig:
        """This config with the per-target tables resolved for `target`."""
        return dataclasses.replace(
            self,
            input_taps=self.taps_for(target),
            max_depth=self.depth_for(target),
            max_degree=self.degree_for(target),
            refine_terms=self.refine_for(target),
        )


@dataclass(frozen=True)
class SweepConfig:
    """Repeated runs and full-model assembly (`gpquad sweep`); defaults are the paper's
    (section 3.2: 30 repetitions per equation, 30 full models, input noise SD = 10 %)."""

    runs: int = 30  # repetitions of each equation's identification
    full_models: int = 30  # full six-equation models assembled from the runs
    selection: str = "validation"  # error that picks the best run: validation | train
    assembly: str = "bootstrap"  # full model k: best of a resample of the runs | repetition k
    input_noise: float = 0.1  # Gaussian input noise SD as a fraction of max |input|; 0 = off
    window_s: float = 7.0  # prediction window of the figure (paper Figure 2), s
    horizons_s: tuple[float, ...] = (1.0, 7.0, 30.0)  # RSE horizons of the metrics table, s
    shared_fraction: float = 0.5  # a term is "shared" when more than this fraction of runs has it
    divergence_factor: float = 10.0  # diverged: non-finite or |state| > factor * max |data|


@dataclass(frozen=True)
class OutputConfig:
    """Where run folders go and what is printed."""

    dir: str = "results"  # run folders are written under this folder
    progress: bool = True  # a progress line per iteration and finishing step


@dataclass(frozen=True)
class Config:
    """A whole experiment."""

    seed: int = 0  # master seed: every random draw of the run derives from it
    name: str = "experiment"  # the run folder is <output.dir>/<name>-seed<seed>-<time>
    # The engine preset laid under this config: "recommended" (the defaults) or "paper".
    preset: str = "recommended"
    data: DataConfig = field(default_factory=DataConfig)
    simulator: SimulatorConfig = field(default_factory=SimulatorConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    evolution: EvolutionConfig = field(default_factory=EvolutionConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)
    # Folder that relative data paths are read from (set by load_config, not a TOML key).
    base_dir: str = field(default=".", metadata={"toml": False})

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out.pop("base_dir")
        return out

    def data_paths(self) -> list[Path]:
        return [(Path(self.base_dir) / f).resolve() for f in self.data.files]


def config_from_dict(
    table: dict,
    source: str = "config",
    base_dir: str = ".",
    dt: float | None = None,
    notes: list[str] | None = None,
) -> Config:
    """A validated Config from a TOML-like table: older keys migrated (their notes appended
    to `notes`), the preset laid underneath. `dt`: the data's sample period, when known."""
    table, found = migrate(table, source, dt)
    if notes is not None:
        notes.extend(found)
    cfg = build_dataclass(Config, with_preset(table, source), source)
    cfg = dataclasses.replace(cfg, base_dir=str(base_dir))
    return validate(cfg, source)


def load_config(path, quiet: bool = False) -> Config:
    """Read and validate a TOML experiment file; notes on migrated keys go to stderr."""
    path = Path(path)
    table, _ = read_toml(path)
    data = table.get("data")
    if isinstance(data, dict) and data.get("files") == []:
        raise GpquadError(
            "files = [] lists no flight; list flight files, or remove the key to "
            "fly the reference simulator",
            source=str(path),
            field="data.files",
        )
    notes: list[str] = []
    cfg = config_from_dict(table, str(path), str(path.parent.resolve()), notes=notes)
    if not quiet:
        for line in notes:
            print(f"gpquad: note: {line}", file=sys.stderr)
    return cfg


def override(
    cfg: Config, *, files=None, targets=None, iterations=None, seed=None, out=None
) -> Config:
    """Apply command-line overrides; file paths are taken relative to the current folder."""
    data, ev, output = cfg.data, cfg.evolution, cfg.output
    base_dir = cfg.base_dir
    if files:
        data = dataclasses.replace(data, files=tuple(str(Path(f).resolve()) for f in files))
    if targets:
        ev = dataclasses.replace(ev, targets=tuple(targets))
    if iterations is not None:
        ev = dataclasses.replace(ev, iterations=int(iterations))
    if out is not None:
        output = dataclasses.replace(output, dir=str(Path(out).resolve()))
    new = dataclasses.replace(
        cfg,
        data=data,
        evolution=ev,
        output=output,
        base_dir=base_dir,
        seed=cfg.seed if seed is None else int(seed),
    )
    return validate(new, "command line")


def folder_config_dict(cfg: Config) -> dict:
    """What a run or sweep folder stores as config.json (with the data files' base folder)."""
    return {**cfg.to_dict(), "base_dir": cfg.base_dir}


def _folder_dt(folder: Path) -> float | None:
    """The sample period a run or sweep folder's data had (model.json), if it says."""
    import json

    try:
        return float(json.loads((folder / "model.json").read_text())["dt"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def load_folder_config(folder) -> Config:
    """The config a run or sweep folder was made with (its config.json; one written by an
    older gpquad is migrated to today's keys)."""
    from gpquad.study.store import read_json

    path = Path(folder) / "config.json"
    table = read_json(
        path,
        "gpquad run or sweep folder",
        "give a folder written by `gpquad run` or `gpquad sweep`",
    )
    base = table.pop("base_dir", ".")
    return config_from_dict(table, str(path), base, dt=_folder_dt(Path(folder)))


def preset_evolution(name: str = "paper", **fields) -> EvolutionConfig:
    """The [evolution] of preset `name` with `fields` replaced (validated as a config is)."""
    table = {
        "preset": name,
        "evolution": {k: list(v) if isinstance(v, tuple) else v for k, v in fields.items()},
    }
    return config_from_dict(table, f"preset {name}").evolution
