"""Experiment configuration: frozen dataclasses loaded from TOML.

Unknown keys and wrong types are errors that name the file and the field.
Defaults are the paper's numbers (coevolutionary-gp-rotorcraft, sections 2.2 and 3.2).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from gpquad.engine.variables import DEFAULT_INPUTS, TARGET_NAMES
from gpquad.errors import GpquadError
from gpquad.study.config_checks import validate
from gpquad.study.config_tables import build_dataclass, read_toml

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
    format: str = "generic"
    frame: str = "NED/FRD"
    # input names, or a level for log readers: "rates" | "torque" | "sticks" | "motors"
    # (gpquad.data.levels); the default names take "rates" wherever a log has rate set-points
    inputs: tuple[str, ...] | str = DEFAULT_INPUTS
    columns: dict[str, str] = field(default_factory=dict)  # canonical name -> file column
    trim: str = "none"  # none | mean | given
    trim_values: dict[str, float] = field(default_factory=dict)
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
        default_factory=lambda: {"u_P": 0.08, "u_R": 0.08, "u_Y": 0.08, "u_T": 0.03})
    stick_time_constant_s: float = 0.6
    # Pilot feedback: input -> {state: gain}; keeps attitude and speed bounded.
    pilot_gains: dict[str, dict[str, float]] = field(default_factory=lambda: {
        "u_R": {"phi": -0.6, "v": 0.05},
        "u_P": {"theta": 0.6, "u": 0.05},
        "u_Y": {"psi": 0.15},
    })
    input_limit: float = 1.0
    # Gaussian measurement noise on the recorded flight (not on the dynamics), SD per signal:
    # "attitude" (rad, a random small rotation), "velocity" (m/s), "rates" (rad/s).
    measurement_noise: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class EvolutionConfig:
    """Coevolution settings; defaults are the paper's."""

    targets: tuple[str, ...] = TARGET_NAMES
    iterations: int = 30
    model_generations: int = 600
    test_generations: int = 80
    n_models: int = 14
    n_tests: int = 5
    suite_size: int = 6
    window_steps: int = 750
    # One number, or a table per target such as {p_dot = 7} (a target left out gets 5).
    max_depth: int | dict[str, int] = 5
    # Not in the paper: the highest polynomial degree of an equation (x y is 2, x y z 3, a
    # quotient counts both sides); 0 = no limit. Mutations above it are drawn again. One
    # number, or a table per target (a target left out gets 0).
    max_degree: int | dict[str, int] = 0
    p_leaf: float = 0.7
    p_constant_leaf: float = 0.25
    const_low: float = -5.0
    const_high: float = 5.0
    const_variance: float = 0.1
    p_const_perturb: float = 0.5
    p_delay: float = 0.1
    max_delay: int = 5
    metric: str = "mae"
    simplify_generations: int = 50
    simplify_tolerance: float = 0.0  # 0: keep a simplification only if better (paper 2.2);
    # > 0 (extension): keep it if error <= (1 + tol) * before
    test_offset_max: int = 375
    # Not in the paper: a local search on every model after the model phase. "none" keeps
    # the paper's method; "delays" tries every single-input delay change; "delays+constants"
    # first runs Nelder-Mead on the constants (at most local_search_evals evaluations),
    # then tries the delay changes, each with its constants re-fitted (evals / 5).
    local_search: str = "none"
    local_search_evals: int = 150
    # Not in the paper: prune the final equation (subtrees -> constants, constants re-fitted)
    # while its training error grows by less than prune_tolerance x the error of the best
    # constant model (a parsimony threshold on the error scale); 0 = off.
    prune_tolerance: float = 0.0
    # Not in the paper: how local search and pruning re-fit constants. "nelder-mead" (at most
    # local_search_evals evaluations) or "gauss-newton": Levenberg-Marquardt on the integrated
    # error with forward-mode sensitivities (at most gradient_steps evaluations).
    constant_fit: str = "nelder-mead"
    gradient_steps: int = 20
    # Not in the paper: a growing horizon for the gauss-newton fit. Each fit also starts at
    # these short horizons (steps, ascending) on windows spread over the training data, each
    # fit starting from the last, and then fits the full windows; the better of that and the
    # direct fit is kept. A stiff loop such as 544 (u_R - phi) - 47 p sits in a narrow basin
    # of the long-window error that short windows lead into. [] = off.
    fit_horizons: tuple[int, ...] = ()
    # Not in the paper: one climber starts from the linear model in every allowed variable,
    # constants fitted through the integrator, cut to the terms that contribute most
    # (gpquad.engine.evolve.linear_seed); needs constant_fit = "gauss-newton".
    linear_seed: bool = False
    # Not in the paper: how the final equation is chosen. "prune" = the best climber, pruned
    # by prune_tolerance if > 0; "bic" = pruned while the training BIC of the integrated
    # state does not grow, then the lowest BIC (training and validation windows) among it and
    # the front's climbers.
    final_selection: str = "prune"
    # Not in the paper: after the local search, try adding c*x_i or c*x_i*x_j to the best
    # climber (constants re-fitted); keep the best if the error drops by > term_min_gain.
    term_search: bool = False
    # Not in the paper: state or input names no equation may read (for example "psi": the
    # heading, which the body-frame dynamics do not depend on and a model can overfit to).
    exclude_leaves: tuple[str, ...] = ()
    # Not in the paper: a name of exclude_leaves stays allowed when an input tracks it (an
    # angle set-point: the input explains >= 30 % of the state's variance, correlation >= 0.6;
    # gpquad.engine.evolve.leaves), e.g. psi when u_Y is a heading set-point.
    keep_tracked: bool = False
    term_min_gain: float = 0.01
    # Not in the paper: after the six equations, refit all their constants jointly on
    # full-model rollouts, kept if the validation error drops significantly
    # (gpquad.models.joint_fit).
    joint_fit: bool = False
    # Not in the paper: when the six equations diverge flown together (validation flights
    # of the joint refit's horizon), swap equations for their front's alternatives until
    # they stop (gpquad.models.stability); runs before the joint refit.
    stability_repair: bool = False
    # Not in the paper: after the stability repair, keep swapping equations for their
    # front's alternatives while the full model's validation flights get significantly
    # better (paired test over the windows; gpquad.models.stability).
    front_selection: bool = False
    # Not in the paper: taps per input: an equation may read each input at up to this many
    # evolvable delays, e.g. 110 u_R(t-1) - 70 u_R(t-3) for a lagging motor
    # (gpquad.engine.taps). 1 = the paper's one delay per input and equation. Either one
    # number for every equation or a table per target, e.g. {a_x = 4, p_dot = 6}
    # (a target the table leaves out gets 1).
    input_taps: int | dict[str, int] = 1
    # Not in the paper: an angular equation's fitness also counts the error of the Euler
    # angle its rate integrates into (p -> phi, q -> theta, r -> psi), this weight times the
    # ratio of the two signals' spreads on the data; 0 = the rate alone (the paper).
    # A roll equation without the attitude feedback of a stiff loop leaks a small rate bias
    # that the angle integrates (gpquad.engine.kernels.fitness).
    attitude_weight: float = 0.0
    # Not in the paper: the gradient fit's Jacobian follows the constants through the Euler
    # angles a tree reads (exact; off, they get zero tangent). Off by default: on angle-mode
    # flights it lets LM fit attitude loops so stiff that they diverge flown together
    # (gpquad.engine.kernels.sensitivity, README "Engine extensions").
    angle_tangents: bool = False
    # Not in the paper: on a left-right symmetric vehicle, the inputs that change sign in
    # the mirror image of a flight (the roll and yaw commands, e.g. ["u_R", "u_Y"]). The
    # stability repair then also flies the mirrored validation flights, and an equation set
    # that diverges there is swapped for front alternatives that do not, where the recorded
    # flights allow (gpquad.data.mirror, gpquad.models.stability); `gpquad run` reports
    # each equation's part of the wrong left-right parity (gpquad.models.symmetry) and
    # `gpquad score` the mirrored windows that diverge. [] = off.
    mirror_inputs: tuple[str, ...] = ()
    # Not in the paper: the equations of a left-right symmetric vehicle. After the searches,
    # each equation loses its terms of the wrong left-right parity (constants excepted) and
    # its constants are refitted (gpquad.models.symmetrize); needs mirror_inputs. Off by
    # default (fifteenth round, README).
    symmetric_equations: bool = False
    # Not in the paper: after the searches (and the symmetric-equations step), each
    # equation may gain up to this many terms: products of two of the states and input taps
    # at every delay 0..max_delay, screened on the one-step residual and fitted through the
    # integrator, each kept while it lowers the training error by term_min_gain; the
    # equation may also get a first-order lag, tau da/dt + a = expr (a motor that lags its
    # command; tau from gpquad.engine.lag.LAG_GRID). The refined equation replaces the found
    # one only if it flies the validation windows better (gpquad.models.refine). One
    # number, or a table per target, e.g. {r_dot = 16}; 0 = off (sixteenth round, README).
    refine_terms: int | dict[str, int] = 0
    # the scheme that flies the windows (gpquad.engine.kernels.step): euler (eq. 2) | rk4
    integrator: str = "euler"
    substeps: int = 1  # rk4 steps per sample (euler: 1)

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
        return self._per_target("refine_terms", target)

    def _per_target(self, name: str, target: str) -> int:
        """Field `name` for `target`: one number for every target, or a {target: number}
        table whose left-out targets get the field's default."""
        value = getattr(self, name)
        if isinstance(value, dict):
            default = next(f.default for f in dataclasses.fields(self) if f.name == name)
            return int(value.get(target, default))
        return int(value)

    def for_target(self, target: str) -> EvolutionConfig:
        """This config with the per-target tables resolved for `target`."""
        return dataclasses.replace(self, input_taps=self.taps_for(target),
                                   max_depth=self.depth_for(target),
                                   max_degree=self.degree_for(target),
                                   refine_terms=self.refine_for(target))


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
    dir: str = "results"
    progress: bool = True


@dataclass(frozen=True)
class Config:
    """A whole experiment."""

    seed: int = 0
    name: str = "experiment"
    data: DataConfig = field(default_factory=DataConfig)
    simulator: SimulatorConfig = field(default_factory=SimulatorConfig)
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


def config_from_dict(table: dict, source: str = "config", base_dir: str = ".") -> Config:
    cfg = build_dataclass(Config, table, source)
    cfg = dataclasses.replace(cfg, base_dir=str(base_dir))
    return validate(cfg, source)


def load_config(path) -> Config:
    """Read and validate a TOML experiment file."""
    path = Path(path)
    table, _ = read_toml(path)
    data = table.get("data")
    if isinstance(data, dict) and data.get("files") == []:
        raise GpquadError("files = [] lists no flight; list flight files, or remove the key to "
                          "fly the reference simulator", source=str(path), field="data.files")
    return config_from_dict(table, str(path), str(path.parent.resolve()))


def override(cfg: Config, *, files=None, targets=None, iterations=None, seed=None,
             out=None) -> Config:
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
    new = dataclasses.replace(cfg, data=data, evolution=ev, output=output, base_dir=base_dir,
                              seed=cfg.seed if seed is None else int(seed))
    return validate(new, "command line")


def folder_config_dict(cfg: Config) -> dict:
    """What a run or sweep folder stores as config.json (with the data files' base folder)."""
    return {**cfg.to_dict(), "base_dir": cfg.base_dir}


def load_folder_config(folder) -> Config:
    """The config a run or sweep folder was made with (its config.json)."""
    from gpquad.study.store import read_json

    path = Path(folder) / "config.json"
    table = read_json(path, "gpquad run or sweep folder",
                      "give a folder written by `gpquad run` or `gpquad sweep`")
    base = table.pop("base_dir", ".")
    return config_from_dict(table, str(path), base)
