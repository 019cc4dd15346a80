"""Physically sensible equations fitted by least squares on the rotorpy flights (25 Hz).

    python benchmarks/rotorpy_flight_fits.py [--data results/benchmark_data/rotorpy]

Reads each scenario's training flights per vehicle through gpquad's own pipeline (the config
that `ensure_flights` returns) and fits, on the pipeline's accelerations:
angle mode  p_dot = k (u_R(t-d) - phi) - c p   (likewise q_dot with u_P, theta; r_dot with
            u_Y, psi), best input delay d in 0..5 samples;
rate mode   p_dot = k (u_R(t-d) - p) - c p     (likewise q, r);
both        a_z = k_T u_T(t-d) + b, a_y = g_y phi, a_x = g_x theta (frame signs: in NED/FRD
            a_y ~ +g phi, a_x ~ -g theta, k_T ~ -g).
Prints one line per fit with the one-step R^2. The attitude and rate laws are also fitted
in continuous time on the 100 Hz files themselves (logged rates, central differences, input
delay 0..20 samples of 10 ms): the physical gains, which the 25 Hz one-step fit cannot give
when the loop is stiff (omega_n dt near 1) and the forward-difference acceleration leads the
state by a sample.
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

from gpquad.benchmark.rotorpy_flights import VEHICLES, ensure_flights
from gpquad.data.dataset import build_dataset
from gpquad.data.io import load_flights
from gpquad.engine.kernels.quaternion import euler_array
from gpquad.study.config import config_from_dict

STATE = {"phi": 0, "theta": 1, "psi": 2, "u": 3, "v": 4, "w": 5, "p": 6, "q": 7, "r": 8}
TARGET = {"a_x": 0, "a_y": 1, "a_z": 2, "p_dot": 3, "q_dot": 4, "r_dot": 5}


def vehicle_data(paths, config):
    cfg = config_from_dict({"data": {**config, "files": list(paths)}})
    ds = build_dataset(load_flights(cfg), validation_fraction=0.0)
    return ds


def lagged(ds, col, d):
    """Input column delayed by d samples within each flight; rows with no history dropped."""
    keep, values = [], []
    x = ds.arrays.inputs[:, col]
    for a, b in ds.segments:
        idx = np.arange(a + d, b - 1)  # last row has no acceleration
        keep.append(idx)
        values.append(x[idx - d])
    return np.concatenate(keep), np.concatenate(values)


def fit(ds, target, columns):
    """Least squares of acc[target] on columns(idx, d) -> (coef, R^2, d) with the best d."""
    best = None
    for d in range(6):
        idx, _ = lagged(ds, 0, d)
        feats = np.column_stack(columns(idx, d))
        y = ds.arrays.acc[idx, TARGET[target]]
        coef, *_ = np.linalg.lstsq(feats, y, rcond=None)
        r2 = 1.0 - np.mean((y - feats @ coef) ** 2) / np.var(y)
        if best is None or r2 > best[1]:
            best = (coef, r2, d)
    return best


def continuous_fit(paths, inp, ang, rate, mode):
    """k, c, delay (samples at 100 Hz), R^2 of rate_dot = k (inp(t-d) - ref) - c rate."""
    frames = [pd.read_parquet(p) for p in paths]
    best = None
    for d in range(21):
        ys, feats = [], []
        for f in frames:
            dt = float(f["t"].iloc[1] - f["t"].iloc[0])
            euler = euler_array(np.ascontiguousarray(f[["qw", "qx", "qy", "qz"]].to_numpy()))
            ref = euler[:, STATE[ang]] if mode == "angle" else f[rate].to_numpy()
            w = f[rate].to_numpy()
            u = f[inp].to_numpy()
            sl = slice(300 + d, len(f) - 1)  # skip the excitation's fade-in
            ys.append(np.gradient(w, dt)[sl])
            feats.append(np.column_stack([u[300 : len(f) - 1 - d] - ref[sl], -w[sl]]))
        y, x = np.concatenate(ys), np.vstack(feats)
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        r2 = 1.0 - np.mean((y - x @ coef) ** 2) / np.var(y)
        if best is None or r2 > best[3]:
            best = (coef[0], coef[1], d, r2)
    return best


def report_vehicle(name: str, vehicle: str, paths: list[str], config: dict, mode: str) -> None:
    """Print the fits of one vehicle's training flights."""
    ds = vehicle_data(paths, config)
    s = ds.arrays.states
    names = list(ds.input_names)

    def feedback(col, ref, rate):
        def cols(idx, d):
            _, u = lagged(ds, col, d)
            return (u - s[idx, ref], -s[idx, STATE[rate]])

        return cols

    for tgt, inp, ang, rate in (
        ("p_dot", "u_R", "phi", "p"),
        ("q_dot", "u_P", "theta", "q"),
        ("r_dot", "u_Y", "psi", "r"),
    ):
        ref = STATE[ang] if mode == "angle" else STATE[rate]
        (k, c), r2, d = fit(ds, tgt, feedback(names.index(inp), ref, rate))
        kc, cc, dc, r2c = continuous_fit(paths, inp, ang, rate, mode)
        law = f"k ({inp}(t-{d}) - {ang if mode == 'angle' else rate}) - c {rate}"
        print(
            f"{name:20s} {vehicle:12s} {tgt} = {law}: k = {k:.1f}, c = {c:.1f}, "
            f"one-step R^2 = {r2:.3f} | 100 Hz continuous: k = {kc:.1f}, c = {cc:.1f}, "
            f"delay {10 * dc} ms, R^2 = {r2c:.3f}"
        )
    col = names.index("u_T")
    (kt, b), r2, d = fit(ds, "a_z", lambda idx, d: (lagged(ds, col, d)[1], np.ones(len(idx))))
    print(
        f"{name:20s} {vehicle:12s} a_z = k_T u_T(t-{d}) + b: k_T = {kt:.2f}, b = {b:.2f}, "
        f"one-step R^2 = {r2:.3f}"
    )
    for tgt, ang in (("a_y", "phi"), ("a_x", "theta")):
        j = STATE[ang]
        (g,), r2, _ = fit(ds, tgt, lambda idx, d, j=j: (s[idx, j],))
        print(f"{name:20s} {vehicle:12s} {tgt} = g {ang}: g = {g:.2f}, one-step R^2 = {r2:.3f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default="results/benchmark_data/rotorpy")
    args = parser.parse_args(argv)
    for mode in ("angle", "rate"):
        for noisy in (False, True):
            res = ensure_flights(mode, noisy, args.data)
            name = f"rotorpy-{mode}{'-noisy' if noisy else ''}"
            for vehicle in VEHICLES:
                paths = [p for p in res["train"] if f"/{vehicle}_" in p]
                report_vehicle(name, vehicle, paths, res["config"], mode)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
