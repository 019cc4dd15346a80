"""Peer identification methods, each fitted as its users fit it.

Every peer is a one-step regression of the data's forward-difference accelerations
(`gpquad.engine.kernels.integrator.body_accelerations`, the integrator's exact inverse) on the
recorded state [phi, theta, psi, u, v, w, p, q, r] and on every input lagged 0..MAX_LAG
samples; none of them can evolve delays. A fitted peer is a `FittedPeer` whose `predict`
flies through `gpquad.benchmark.rollout.fly`.

- zero: every acceleration is 0 (the floor every model must beat);
- ols: ordinary least squares with intercept on the lagged features (numpy lstsq);
- sindy: PySINDy SINDYc (x = [u, v, w, p, q, r], control = the attitude and the lagged
  inputs), degree-2 polynomial library, STLSQ; the threshold is picked from THRESHOLDS by
  the 7 s integrated-state RSE on the validation part of the training flights;
- operon: pyoperon SymbolicRegressor per acceleration, functions + - * / only, max depth 5,
  Levenberg-Marquardt constants, a fixed seed and generation budget (OPERON_SETTINGS).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from importlib import metadata

import numpy as np

from gpquad.benchmark.peer_predictor import PolynomialPredictor
from gpquad.benchmark.rollout import MAX_LAG, fly, lagged_inputs, lagged_names
from gpquad.engine.evolve.windows import tile
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES

PEERS = ("zero", "ols", "sindy", "operon")
#: The Python package each optional peer needs (pip install -e ".[peers]").
PEER_PACKAGES = {"sindy": "pysindy", "operon": "pyoperon"}
THRESHOLDS = (0.01, 0.1, 0.3, 1.0)
SINDY_SETTINGS = {
    "library": "PolynomialLibrary(degree=2)",
    "optimizer": "STLSQ",
    "alpha": 0.05,
    "max_iter": 20,
    "thresholds": list(THRESHOLDS),
    "threshold_selection": "mean RSE of u..r over 7 s validation windows",
}
OPERON_SETTINGS = {
    "allowed_symbols": "add,sub,mul,div,constant,variable",
    "max_depth": 5,
    "max_length": 30,
    "population_size": 100,
    "generations": 25,
    "max_evaluations": 1_000_000,
    "optimizer": "lm",
    "optimizer_iterations": 5,
    "n_threads": 1,
    "model_selection_criterion": "minimum_description_length",
}
#: Every setting a peer's result depends on (recorded with its cells; a change recomputes them).
PEER_SETTINGS = {
    "zero": {},
    "ols": {"features": "state + inputs lagged 0..MAX_LAG"},
    "sindy": SINDY_SETTINGS,
    "operon": OPERON_SETTINGS,
}


@dataclasses.dataclass
class FittedPeer:
    """A fitted peer: predict(features (W, F), idx (W,)) -> (W, 6) and what describes it."""

    predict: Callable
    equations: dict[str, str]  # target -> expression in feature names (lags as u_R_l2)
    n_parameters: int
    settings: dict


def feature_names(input_names) -> list[str]:
    return list(STATE_NAMES) + lagged_names(input_names)


def training_rows(ranges) -> np.ndarray:
    """Sample indices i whose features (i - MAX_LAG .. i) and acceleration (i -> i + 1) lie
    inside one range [a, b)."""
    rows = [np.arange(a + MAX_LAG, b - 1) for a, b in ranges if b - 1 > a + MAX_LAG]
    return np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)


def regression_data(dataset, ranges) -> tuple[np.ndarray, np.ndarray]:
    """Features (n, 9 + n_inputs * 6) and forward-difference accelerations (n, 6)."""
    rows = training_rows(ranges)
    arrays = dataset.arrays
    x = np.hstack([arrays.states[rows], lagged_inputs(arrays.inputs, rows)])
    return x, arrays.acc[rows]


def package_version(peer: str) -> str | None:
    """Installed version of a peer's package, None if it is missing (zero, ols: numpy)."""
    try:
        return metadata.version(PEER_PACKAGES.get(peer, "numpy"))
    except metadata.PackageNotFoundError:
        return None


def _linear_text(coef: np.ndarray, names: list[str], digits: int = 6) -> str:
    terms = [
        f"{c:.{digits}g}*{n}" if n != "1" else f"{c:.{digits}g}"
        for c, n in zip(coef, names)
        if c != 0.0
    ]
    return " + ".join(terms) if terms else "0"


def fit_zero(dataset, seed: int) -> FittedPeer:
    return FittedPeer(lambda f, idx: np.zeros((len(idx), 6)), {t: "0" for t in TARGET_NAMES}, 0, {})


def fit_ols(dataset, seed: int) -> FittedPeer:
    x, y = regression_data(dataset, dataset.train)
    design = np.hstack([np.ones((len(x), 1)), x])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)  # (1 + F, 6)
    names = ["1"] + feature_names(dataset.input_names)
    eqs = {t: _linear_text(coef[:, k], names) for k, t in enumerate(TARGET_NAMES)}
    return FittedPeer(
        lambda f, idx: coef[0] + f @ coef[1:],
        eqs,
        int(coef.size),
        {"solver": "numpy.linalg.lstsq", "intercept": True},
    )


def _sindy_parts(features: np.ndarray) -> np.ndarray:
    """SINDYc order of a feature matrix: x = [u, v, w, p, q, r], then the control
    [phi, theta, psi, lagged inputs] (SINDy applies its library to [x, u])."""
    return np.hstack([features[:, 3:9], features[:, :3], features[:, 9:]])


def _validation_rse(predict, dataset, horizon_steps: int) -> float:
    """Mean RSE of u..r over non-overlapping windows of the validation ranges (inf if any
    window diverges); the training ranges if there is no validation part."""
    from gpquad.models.scoring import rse

    ranges = dataset.validation or dataset.train
    starts, steps = tile(ranges, horizon_steps, MAX_LAG)
    if len(starts) == 0:
        return np.inf
    pred = fly(predict, dataset.arrays, starts, steps)
    data = dataset.arrays.states[starts[:, None] + np.arange(steps + 1)[None, :]]
    if not np.isfinite(pred).all():
        return np.inf
    return float(np.mean(rse(pred, data)))


def polynomial_predictor(powers: np.ndarray, coef: np.ndarray, reorder):
    """predict(features, idx) of a polynomial library with coefficients (6, T): powers
    (T, F) are the library's exponents (PolynomialLibrary.powers_) in the features that
    `reorder` makes; only the terms some equation uses are computed, each as the product
    of its factors (gpquad.benchmark.peer_predictor), much faster per step than the
    library's own transform."""
    keep = np.flatnonzero(np.any(coef != 0.0, axis=0))
    poly = PolynomialPredictor(powers[keep], coef[:, keep].T)

    def predict(features, idx):
        return poly(reorder(features))

    return predict


def fit_sindy(dataset, seed: int) -> FittedPeer:
    """SINDYc: PySINDy's PolynomialLibrary(degree=2) on [x, u] and its STLSQ optimizer (what
    ps.SINDy(...).fit(x, x_dot=..., u=...) runs), the library evaluated once for all
    thresholds."""
    import warnings

    import pysindy as ps

    x, y = regression_data(dataset, dataset.train)
    names = feature_names(dataset.input_names)
    sindy_names = names[3:9] + names[:3] + names[9:]
    library = ps.PolynomialLibrary(degree=2)
    theta = library.fit_transform(_sindy_parts(x))
    theta = np.asarray(theta)
    horizon = int(round(7.0 / dataset.dt))
    best = None
    for threshold in THRESHOLDS:
        opt = ps.STLSQ(threshold=threshold, alpha=0.05, max_iter=20)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            opt.fit(theta, y)
        coef = np.asarray(opt.coef_).reshape(6, -1)
        predict = polynomial_predictor(library.powers_, coef, _sindy_parts)
        score = _validation_rse(predict, dataset, horizon)
        if best is None or score < best[0]:
            best = (score, threshold, coef, predict)
    score, threshold, coef, predict = best
    terms = [t.replace(" ", "*") for t in library.get_feature_names(sindy_names)]
    eqs = {t: _linear_text(coef[k], terms) for k, t in enumerate(TARGET_NAMES)}
    return FittedPeer(
        predict,
        eqs,
        int(np.count_nonzero(coef)),
        {**SINDY_SETTINGS, "threshold": threshold, "validation_rse_7s": score},
    )


def fit_operon(dataset, seed: int) -> FittedPeer:
    from pyoperon.sklearn import SymbolicRegressor

    x, y = regression_data(dataset, dataset.train)
    names = feature_names(dataset.input_names)
    regressors, eqs, n_params = [], {}, 0
    for k, target in enumerate(TARGET_NAMES):
        reg = SymbolicRegressor(**OPERON_SETTINGS, random_state=int(seed) * 16 + k)
        reg.fit(x, y[:, k])
        regressors.append(reg)
        eqs[target] = reg.get_model_string(reg.model_, 6, names)
        n_params += int(sum(1 for node in reg.model_.Nodes if node.IsConstant))

    def predict(f, idx):
        return np.column_stack([reg.predict(f) for reg in regressors])

    return FittedPeer(
        predict, eqs, n_params, {**OPERON_SETTINGS, "random_state": "seed * 16 + target index"}
    )


FITTERS = {"zero": fit_zero, "ols": fit_ols, "sindy": fit_sindy, "operon": fit_operon}


def fit_peer(name: str, dataset, seed: int) -> tuple[FittedPeer, float]:
    """Fit a peer on the training ranges of `dataset`; returns it and the fit time (s)."""
    t0 = time.perf_counter()
    peer = FITTERS[name](dataset, seed)
    return peer, time.perf_counter() - t0


#: Peers whose fit does not depend on the seed (fitted once, reported with seed 0).
DETERMINISTIC = ("zero", "ols", "sindy")


def recovery(peer: FittedPeer, scenario) -> dict[str, bool]:
    """Exact-structure recovery of each known equation (gpquad.benchmark.recovery)."""
    from gpquad.benchmark.recovery import recovered

    return {
        t: recovered(peer.equations[t], scenario.truth[t], t, scenario.fit)
        for t in TARGET_NAMES
        if t in scenario.truth
    }
