"""Thrust and drag identification on ground-truth flights (thesis IV.B-C), as plain results.

Each flight gets its own generator, SeedSequence([seed, flight number]), so the noise of a
flight does not depend on which other flights a command uses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpquad.physics.aero import THRUST_MODELS, drag_regressors, thrust_regressors
from gpquad.physics.config import PhysicsConfig
from gpquad.physics.regression import fit, predict
from gpquad.physics.sensors import measure
from gpquad.physics.sync import causal_moving_average
from gpquad.physics.truth import MANOEUVRES, cached_flight, true_coefficients, vehicle_params


def flight_number(manoeuvre: str, yaw: bool) -> int:
    return 2 * MANOEUVRES.index(manoeuvre) + int(yaw)


def load_flight(cfg: PhysicsConfig, manoeuvre: str, yaw: bool = False) -> dict:
    """A rotorpy flight (cached) as the sensors measure it, smoothed as configured."""
    tc = cfg.truth
    cache = None
    if tc.cache:
        cache = Path(tc.cache)
        cache = cache if cache.is_absolute() else Path.cwd() / cache
    spec = {
        "manoeuvre": manoeuvre,
        "side": tc.side,
        "speed": tc.speed,
        "yaw": yaw,
        "vehicle": tc.vehicle,
        "dt": tc.dt,
    }
    flight = cached_flight(spec, cache)
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, flight_number(manoeuvre, yaw)]))
    meas = measure(flight, cfg.noise, rng)
    if cfg.regression.smoothing_window > 1:
        meas["force"] = causal_moving_average(meas["force"], cfg.regression.smoothing_window)
    meas["name"] = f"{manoeuvre}{'-yaw' if yaw else ''}"
    return meas


def split(n: int, fraction: float) -> tuple[slice, slice]:
    cut = int(round(n * (1.0 - fraction)))
    return slice(0, cut), slice(cut, n)


def _fit_thrust(meas: dict, model: str, cfg: PhysicsConfig, mass: float) -> dict:
    X = thrust_regressors(model, meas["rotor"], meas["vel_body"])
    y = mass * meas["force"][:, 2]
    tr, va = split(len(y), cfg.regression.validation_fraction)
    res = fit(
        X[tr],
        y[tr],
        THRUST_MODELS[model],
        cfg.regression.method,
        X_val=X[va],
        y_val=y[va],
        window=cfg.regression.wls_window,
    )
    res["flight"] = meas["name"]
    return res


def _rel(value: float, truth: float) -> float | None:
    return None if truth == 0 else float(value / truth - 1.0)


def identify_thrust(cfg: PhysicsConfig) -> dict:
    """Standard thrust from hover (eq. 5); standard and refined (eq. 19) from forward flight."""
    params = vehicle_params(cfg.truth.vehicle)
    truth = true_coefficients(params)
    mass = truth["mass"]
    hover = load_flight(cfg, cfg.thrust.hover)
    forward = load_flight(cfg, cfg.thrust.forward)
    out = {"truth": {k: truth[k] for k in ("mass", "k_t", "k_z", "k_h")}, "fits": {}}
    out["fits"]["standard_hover"] = _fit_thrust(hover, "standard", cfg, mass)
    out["fits"]["standard_forward"] = _fit_thrust(forward, "standard", cfg, mass)
    out["fits"]["refined_forward"] = _fit_thrust(forward, "refined", cfg, mass)
    # the hover fit applied to forward flight (the base model's situation in section V)
    Xf = thrust_regressors("standard", forward["rotor"], forward["vel_body"])
    yf = mass * forward["force"][:, 2]
    _, va = split(len(yf), cfg.regression.validation_fraction)
    pf = predict(out["fits"]["standard_hover"], Xf)
    from gpquad.physics.regression import r_squared

    out["hover_fit_on_forward_validation"] = {
        "r2": r_squared(yf[va], pf[va]),
        "rmse": float(np.sqrt(np.mean((yf[va] - pf[va]) ** 2))),
    }
    for res in out["fits"].values():
        res["relative_error"] = {n: _rel(c, truth[n]) for n, c in zip(res["names"], res["coef"])}
    ref, std = out["fits"]["refined_forward"], out["fits"]["standard_forward"]
    out["refined_beats_standard"] = bool(ref["rmse_val"] < std["rmse_val"])
    out["_series"] = {"hover": hover, "forward": forward, "mass": mass}
    return out


def identify_drag(cfg: PhysicsConfig) -> dict:
    """k_dx, k_dy of eq. (18) pooled over the drag flights, with and without parasitic drag."""
    truth = true_coefficients(vehicle_params(cfg.truth.vehicle))
    flights = [load_flight(cfg, name) for name in cfg.drag.flights]
    out = {
        "truth": {k: truth[k] for k in ("k_dx", "k_dy", "c_dx", "c_dy")},
        "fits": {},
        "flights": [f["name"] for f in flights],
    }
    variants = [False, True] if cfg.regression.parasitic_drag else [False]
    for axis in (0, 1):
        for parasitic in variants:
            Xs, ys, Xv, yv = [], [], [], []
            for f in flights:
                X, names = drag_regressors(axis, f["rotor"], f["vel_body"], parasitic)
                if cfg.regression.drag_intercept:
                    X = np.column_stack([X, np.ones(len(X))])
                    names = names + [f"bias_{'xy'[axis]}"]
                y = f["force"][:, axis]
                tr, va = split(len(y), cfg.regression.validation_fraction)
                Xs.append(X[tr])
                ys.append(y[tr])
                Xv.append(X[va])
                yv.append(y[va])
            res = fit(
                np.vstack(Xs),
                np.concatenate(ys),
                names,
                cfg.regression.method,
                X_val=np.vstack(Xv),
                y_val=np.concatenate(yv),
                window=cfg.regression.wls_window,
            )
            res["relative_error"] = {
                n: _rel(c, truth[n]) for n, c in zip(names, res["coef"]) if n in truth
            }
            key = f"{'xy'[axis]}{'_parasitic' if parasitic else ''}"
            out["fits"][key] = res
            if res["coef"][0] >= 0:
                out.setdefault("warnings", []).append(
                    f"{key}: {names[0]} = {res['coef'][0]:.3g} is not negative (drag must "
                    f"oppose the velocity); the flights {out['flights']} barely move along "
                    f"{'xy'[axis]}"
                )
    out["_series"] = {"flights": flights}
    return out


def coefficients(thrust: dict, drag: dict, parasitic: bool) -> dict:
    """Named coefficients for dead reckoning from the identification results."""

    def named(res):
        return dict(zip(res["names"], res["coef"]))

    fits = drag["fits"]
    use = "_parasitic" if parasitic and "x_parasitic" in fits else ""
    return {
        "standard": named(thrust["fits"]["standard_hover"]),
        "refined": named(thrust["fits"]["refined_forward"]),
        "drag": {**named(fits[f"x{use}"]), **named(fits[f"y{use}"])},
    }
