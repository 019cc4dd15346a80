"""Benchmark scenarios: training flights, held-out test flights, and the truth where known.

Each scenario is a `Scenario`: `fit` is a Dataset of the training flights (its `train`
ranges are fitted, its `validation` ranges serve model selection: SINDy's threshold,
gpquad's reported validation error), `test` a Dataset whose `validation` ranges are the
held-out flights that every method is scored on (same trim as `fit`).

- median, median-noisy: the bundled reference simulator (paper's median model), training
  flight of simulator seed 0, test flights of seeds 1001 and 1002 (180 s each);
- rigid-body, rigid-body-noisy: the same with `experiments/rigid_body.toml`'s [simulator];
  noisy: simulator.measurement_noise = NOISE on every flight (training and test);
- median-noisy2x, median-noisy4x: median-noisy's flights with 2 and 4 times NOISE (the
  noise family; rigid-body, the same simulator with other equations, has none);
- rotorpy-angle, rotorpy-angle-noisy, rotorpy-rate, rotorpy-rate-noisy: flights made by
  `gpquad.benchmark.rotorpy_flights.ensure_flights` (cached), skipped when it or rotorpy
  is missing. Two vehicles whose attitude loops differ (crazyflie: kp_att 310, kd_att 57;
  hummingbird: 544, 46.6), so no one lumped model describes both: each method is fitted
  per vehicle (`groups`) and each vehicle's model flies that vehicle's test flight; the
  scenario's RSE is taken over the windows of both;
- rotorpy-heldout-angle, rotorpy-heldout-angle-noisy, rotorpy-heldout-rate,
  rotorpy-heldout-rate-noisy: the same flights of rotorpy's brushless crazyflie, a vehicle
  that no engine setting was chosen on (`rotorpy_flights.FLEETS`): how the recommended
  engine does on a vehicle it was not tuned to;
- rotorpy-px4sih-angle, rotorpy-px4sih-rate and their -noisy variants: a third vehicle,
  rotorpy's parameters of PX4's SIH quad X (1 kg) with an attitude loop tuned like the two
  tuned vehicles' (`rotorpy_flights.GAINS`);
- the noise family, rotorpy-{angle,rate}-noisy{2x,4x} and rotorpy-px4sih-{angle,rate}-
  noisy{2x,4x}: the noisy variants' flights with 2 and 4 times their sensor noise (every SD,
  the gyro bias's too: `rotorpy_flights.noise_sd`); the held-out fleet has none (it asks
  how the engine does on an untuned vehicle at the benchmark's noise);
- px4-s250, px4-aquaquad: the real logs of `experiments/px4_*.toml`, first 70 % of the
  flight time trains, the last 30 % tests; only measured states are scored;
- betaflight-gecko: `experiments/betaflight_gecko.toml`, a 5" quad's Betaflight blackbox
  log trains, another flight of the same quad (its `data.validation` file) tests; only p,
  q, r are measured and scored;
- betaflight-gecko-motors: the same flights with the four motor outputs as the inputs
  (`experiments/betaflight_gecko_motors.toml`): the rate equations must read the motors;
- a user's TOML: the files of its data.validation list test and the others train; without
  such a list its training part trains and its held-out part (data.validation_fraction of
  each flight) tests.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gpquad.data.dataset import Dataset, build_dataset
from gpquad.data.flight import Flight
from gpquad.errors import GpquadError
from gpquad.models.scoring import SCORED_STATES
from gpquad.study.config import Config, load_config

NOISE = {"attitude": 0.005, "velocity": 0.02, "rates": 0.01}
TEST_SEEDS = (1001, 1002)
TEST_DURATION_S = 180.0
TRAIN_FRACTION = 0.7
#: Noise of a scenario name's suffix, as a multiple of the benchmark's (0: clean).
NOISE_SUFFIX = {"": 0, "-noisy": 1, "-noisy2x": 2, "-noisy4x": 4}
#: The simulator scenarios: name -> (experiment config, noise multiple).
SIMULATED = {
    **{f"median{k}": ("quickstart.toml", v) for k, v in NOISE_SUFFIX.items()},
    **{f"rigid-body{k}": ("rigid_body.toml", NOISE_SUFFIX[k]) for k in ("", "-noisy")},
}
#: rotorpy scenario -> (mode, noise multiple, fleet of gpquad.benchmark.rotorpy_flights.FLEETS).
ROTORPY = {
    f"rotorpy-{prefix}{mode}{suffix}": (mode, NOISE_SUFFIX[suffix], fleet)
    for prefix, fleet, suffixes in (
        ("", "tuned", tuple(NOISE_SUFFIX)),
        ("heldout-", "heldout", ("", "-noisy")),
        ("px4sih-", "px4sih", tuple(NOISE_SUFFIX)),
    )
    for mode in ("angle", "rate")
    for suffix in suffixes
}
#: Real logs: name -> experiment config.
LOGS = {
    "px4-s250": "px4_s250.toml",
    "px4-aquaquad": "px4_aquaquad.toml",
    "betaflight-gecko": "betaflight_gecko.toml",
    "betaflight-gecko-motors": "betaflight_gecko_motors.toml",
}
SCENARIOS = (*SIMULATED, *ROTORPY, *LOGS)


class Skipped(Exception):
    """A scenario that cannot run here (a missing optional package); the message says why."""


@dataclass
class Scenario:
    name: str
    fit: Dataset
    test: Dataset
    truth: dict[str, str] | None  # known equations (raw inputs), or None
    measured: dict[str, bool]  # u..r: scored only when measured
    source: dict  # what the flights are (recorded with results)
    #: Sub-scenarios fitted separately (one per vehicle), or empty. When given, `test` is
    #: their test flights concatenated in this order and `fit` their training flights
    #: (for summaries only: every method is fitted per group).
    groups: dict[str, Scenario] = dataclasses.field(default_factory=dict)

    def group_offsets(self) -> dict[str, tuple[int, int]]:
        """Sample range [a, b) of each group's test flights in `test`."""
        out, a = {}, 0
        for name, g in self.groups.items():
            out[name] = (a, a + g.test.n_samples)
            a += g.test.n_samples
        if a != self.test.n_samples:
            raise GpquadError(
                f"scenario {self.name}: the groups' test flights ({a} samples) "
                f"are not the scenario's ({self.test.n_samples})"
            )
        return out


def repo_root() -> Path:
    return Path(__file__).resolve().parents[2]


def _trim_values(flights: list[Flight], mode: str, given: dict) -> tuple[str, dict]:
    """Trim from the training flights only: mode for build_dataset and its values."""
    if mode == "mean":
        stacked = np.vstack([f.inputs for f in flights])
        return "given", {
            n: float(stacked[:, j].mean()) for j, n in enumerate(flights[0].input_names)
        }
    return mode, dict(given)


def make_scenario(
    name: str,
    train: list[Flight],
    test: list[Flight],
    *,
    trim: str,
    trim_values: dict | None = None,
    validation: list[Flight] | None = None,
    validation_fraction: float = 2000 / 13800,
    truth=None,
    source=None,
) -> Scenario:
    """Scenario from flight lists; `validation` flights (if given) replace the held-out
    fraction of the training flights for model selection."""
    if not train or not test:
        raise GpquadError(f"scenario {name}: needs training and test flights", field="data.files")
    mode, values = _trim_values(train, trim, trim_values or {})
    if validation:
        fit = build_dataset(
            train + validation, validation_fraction=0.0, trim=mode, trim_values=values
        )
        n = len(train)
        fit = dataclasses.replace(fit, train=fit.segments[:n], validation=fit.segments[n:])
    else:
        fit = build_dataset(
            train, validation_fraction=validation_fraction, trim=mode, trim_values=values
        )
    test_ds = build_dataset(test, validation_fraction=1.0, trim="given", trim_values=fit.trim)
    measured = {s: not (fit.unmeasured(s) or test_ds.unmeasured(s)) for s in SCORED_STATES}
    return Scenario(name, fit, test_ds, truth, measured, source or {})


def slice_flight(flight: Flight, a: int, b: int, suffix: str) -> Flight:
    """Samples a..b-1 of a flight as a flight of its own."""
    pos = None if flight.pos is None else flight.pos[a:b]
    return Flight(
        f"{flight.name}{suffix}",
        flight.t[a:b],
        flight.quat[a:b],
        flight.vel[a:b],
        flight.rates[a:b],
        flight.inputs[a:b],
        flight.input_names,
        pos,
        dict(flight.meta),
    )


def time_split(flights: list[Flight], fraction: float) -> tuple[list[Flight], list[Flight]]:
    """The first `fraction` of all samples (flights in log order) and the rest."""
    total = sum(len(f) for f in flights)
    cut = int(round(fraction * total))
    train, test, seen = [], [], 0
    for f in flights:
        if seen + len(f) <= cut:
            train.append(f)
        elif seen >= cut:
            test.append(f)
        else:
            k = cut - seen
            train.append(slice_flight(f, 0, k, "[train]"))
            test.append(slice_flight(f, k, len(f), "[test]"))
        seen += len(f)
    return train, test


def _simulated(name: str, cfg: Config, noise: float) -> Scenario:
    """The simulator's flights of cfg; with `noise` > 0, NOISE times `noise` on each."""
    from gpquad.data.simulator import completed, simulate

    sim = completed(cfg.simulator)
    if noise:
        sim = dataclasses.replace(sim, measurement_noise={k: noise * v for k, v in NOISE.items()})
    train = [simulate(sim, cfg.data.inputs)]
    duration = min(TEST_DURATION_S, sim.duration_s)
    test = [
        simulate(dataclasses.replace(sim, seed=s, duration_s=duration), cfg.data.inputs)
        for s in TEST_SEEDS
    ]
    return make_scenario(
        name,
        train,
        test,
        trim=cfg.data.trim,
        trim_values=cfg.data.trim_values,
        validation_fraction=cfg.data.validation_fraction,
        truth=dict(sim.equations),
        source={
            "kind": "simulator",
            "train_seed": sim.seed,
            "test_seeds": list(TEST_SEEDS),
            "test_duration_s": duration,
            "measurement_noise": dict(sim.measurement_noise),
            "equations": dict(sim.equations),
        },
    )


def _from_log(name: str, path: Path, named: bool = True) -> Scenario:
    """A real log's config: the files of `data.validation` (a list) are the test flights;
    without one, the first TRAIN_FRACTION of the samples train and the rest tests. A named
    scenario whose logs are not on this machine (../shared/data) is skipped."""
    from gpquad.data.io import held_out_paths, load_flights

    cfg = load_config(path)
    missing = [p for p in cfg.data_paths() + held_out_paths(cfg) if not Path(p).exists()]
    if named and missing:
        raise Skipped(
            f"{name}: its log {missing[0]} is not on this machine (the public logs "
            "of ../shared/data)"
        )
    flights = load_flights(cfg)
    held = {str(p) for p in held_out_paths(cfg)}
    if held:
        train = [f for f in flights if f.meta.get("file") not in held]
        test = [f for f in flights if f.meta.get("file") in held]
        if not train or not test:
            raise GpquadError(
                f"no usable flight in the {'test' if train else 'training'} "
                "files (data.validation lists the test files)",
                source=str(path),
                field="data.validation",
            )
        split = f"{', '.join(cfg.data.files)} train; {', '.join(cfg.data.validation)} test"
    else:
        train, test = time_split(flights, TRAIN_FRACTION)
        split = f"first {TRAIN_FRACTION:.0%} of the samples train"
    return make_scenario(
        name,
        train,
        test,
        trim=cfg.data.trim,
        trim_values=cfg.data.trim_values,
        validation_fraction=cfg.data.validation_fraction,
        source={
            "kind": "log",
            "config": str(path),
            "config_text": Path(path).read_text(),
            "files": list(cfg.data.files),
            "split": split,
        },
    )


def _rotorpy(name: str, cache_dir: Path) -> Scenario:
    mode, noise, fleet = ROTORPY[name]
    noisy = noise > 0
    try:
        rotorpy_flights = importlib.import_module("gpquad.benchmark.rotorpy_flights")
    except ImportError as exc:
        raise Skipped(f"{name}: gpquad.benchmark.rotorpy_flights unavailable ({exc})") from None
    scale = {} if noise <= 1 else {"noise_scale": noise}
    try:
        made = rotorpy_flights.ensure_flights(mode, noisy, cache_dir, fleet=fleet, **scale)
    except ImportError as exc:
        raise Skipped(f"{name}: rotorpy is not installed ({exc})") from None
    from gpquad.data.io import load_flights
    from gpquad.study.config import config_from_dict

    def read(paths):
        flights = []
        for p in paths:
            table = {"data": {**made["config"], "files": [str(Path(p).resolve())]}}
            flights.extend(load_flights(config_from_dict(table, f"{name} flights")))
        return flights

    data = made["config"]
    trim = dict(trim=data.get("trim", "none"), trim_values=data.get("trim_values"))
    groups, roles = {}, {"train": [], "test": [], "validation": []}
    for vehicle in made["vehicles"]:
        paths = {
            role: [
                f["path"] for f in made["flights"] if f["vehicle"] == vehicle and f["role"] == role
            ]
            for role in roles
        }
        flights = {role: read(ps) for role, ps in paths.items()}
        for role in roles:
            roles[role] += flights[role]
        groups[vehicle] = make_scenario(
            f"{name}/{vehicle}",
            flights["train"],
            flights["test"],
            validation=flights["validation"],
            **trim,
        )
    source = {
        "kind": "rotorpy",
        "mode": mode,
        "noisy": noisy,
        **scale,
        **({} if fleet == "tuned" else {"fleet": fleet}),  # the tuned cells' fingerprint
        "vehicles": made.get("vehicles"),
        "seeds": made.get("seeds"),
        "config": data,
        "fitted": "per vehicle",
    }
    pooled = make_scenario(
        name, roles["train"], roles["test"], validation=roles["validation"], source=source, **trim
    )
    pooled = dataclasses.replace(pooled, groups=groups)
    pooled.group_offsets()  # the test flights are the groups' in order
    return pooled


def user_scenario(path: Path) -> Scenario:
    """A user's experiment config: the files of `data.validation` (a list) are the test
    flights; without one, each flight's held-out part (data.validation_fraction) is."""
    from gpquad.data.io import held_out_paths, load_flights

    cfg = load_config(path)
    if not cfg.data.files:
        return _simulated(path.stem, cfg, noise=0)
    if held_out_paths(cfg):
        return _from_log(path.stem, path, named=False)
    if cfg.data.validation_fraction <= 0:
        raise GpquadError(
            "the benchmark tests on the held-out part of each flight; set "
            "data.validation_fraction > 0",
            source=str(path),
            field="data.validation_fraction",
        )
    train, test = [], []
    for f in load_flights(cfg):
        cut = len(f) - int(round(cfg.data.validation_fraction * len(f)))
        if cut > 0:
            train.append(slice_flight(f, 0, cut, "[train]"))
        if cut < len(f):
            test.append(slice_flight(f, cut, len(f), "[test]"))
    return make_scenario(
        path.stem,
        train,
        test,
        trim=cfg.data.trim,
        trim_values=cfg.data.trim_values,
        validation_fraction=cfg.data.validation_fraction,
        source={"kind": "user config", "config": str(path)},
    )


def build_scenario(name: str, cache_dir: Path) -> Scenario:
    """Build a named scenario (or a user's TOML path); raises Skipped when it cannot run."""
    root = repo_root()
    if name.endswith(".toml"):
        return user_scenario(Path(name))
    if name in SIMULATED:
        config, noise = SIMULATED[name]
        cfg = load_config(root / "experiments" / config)
        if name.startswith("median"):  # the paper's median model, not the quickstart's
            cfg = dataclasses.replace(cfg, simulator=Config().simulator)
        return _simulated(name, cfg, noise)
    if name in ROTORPY:
        return _rotorpy(name, cache_dir)
    if name in LOGS:
        return _from_log(name, root / "experiments" / LOGS[name])
    raise GpquadError(
        f"unknown scenario '{name}'; choose from {list(SCENARIOS)} or give a config .toml",
        field="scenario",
    )
