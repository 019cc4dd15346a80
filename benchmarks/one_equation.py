"""One equation flown alone: where does a full model's short-horizon error come from (not a test).

    python benchmarks/one_equation.py rotorpy-angle --group hummingbird --target r_dot \\
        --flights results/ab/flights --model results/ab/raw/rotorpy-angle/hummingbird/seed1.json \\
        --sindy results/benchmark/cells/rotorpy-angle/sindy/seed0.json \\
        --library "1,psi,r,u_Y0,u_Y1,u_Y2,u_Y3,u_Y4,u_Y5,theta*u_R0,phi*u_P0,phi*theta,u_P0*u_R0"

Flies one acceleration equation on the scenario's held-out test flight with every other
state taken from the data (and, for a_x, a_y, a_z, the data's rotation between samples, as
the integrator's V_{t+1} = R (V_t + a dt)): only the equation's own state is integrated, from
the recorded value at each window start (every STRIDE samples), over `--horizon` seconds.
Error: RSE of that state (gpquad.models.scoring.rse's definition: squared error over the
windows / squared deviation of the recorded values from their mean). This separates an
equation's own error from what the other five add in the full model, and compares
equations of different origin on the same footing:
- `--model`: the target's equation of gpquad model.json files (or ab_finish raw records);
- `--sindy`: the target's equation in a benchmark SINDy cell (its lagged inputs u_X_lK);
- `--library`: least squares of the data's forward-difference accelerations on the given
  monomials (states by name, inputs as <name><lag>, products with *), on the training
  flights: an oracle of what a structure can give when fitted one step at a time.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import sympy as sp

from gpquad.benchmark.scenarios import build_scenario
from gpquad.engine.taps import base_input
from gpquad.engine.tree.arithmetic import parse_in_symbols
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES, TARGET_STATE
from gpquad.models.equations import DiscoveredModel

STRIDE = 10
MAX_LAG = 5


def columns(ds, lags: dict[str, int] | None = None) -> dict[str, np.ndarray]:
    """Every state by name and every input at lags 0..MAX_LAG as <name><lag> and <name>_l<lag>
    (SINDy's spelling), over the dataset's rows (earlier rows wrap; windows start later)."""
    s, u = ds.arrays.states, ds.arrays.inputs
    out = {n: s[:, k] for k, n in enumerate(STATE_NAMES)}
    out["1"] = np.ones(len(s))
    for j, name in enumerate(ds.input_names):
        for k in range(MAX_LAG + 1):
            out[f"{name}{k}"] = out[f"{name}_l{k}"] = np.roll(u[:, j], k)
    return out


def rollout_rse(ds, target: str, rhs, seconds: float) -> float:
    """RSE of the target's state flown alone; rhs(cols, rows) -> acceleration at rows."""
    state = STATE_NAMES.index(TARGET_STATE[target])
    cols = columns(ds)
    steps = max(1, int(round(seconds / ds.dt)))
    starts = np.concatenate(
        [np.arange(a + MAX_LAG + 1, b - steps - 1, STRIDE) for a, b in ds.validation]
    )
    x = ds.arrays.states[starts, state].copy()
    err = np.zeros(len(starts))
    recorded = []
    translational = TARGET_NAMES.index(target) < 3
    for k in range(steps):
        rows = starts + k
        view = dict(cols)
        view[STATE_NAMES[state]] = np.zeros(len(cols["1"]))
        view[STATE_NAMES[state]][rows] = x
        x = x + ds.dt * rhs(view, rows)
        if translational:  # the integrator's V_{t+1} = R (V_t + a_t dt), R = rot of the data
            rot = ds.arrays.rot[rows].reshape(-1, 3, 3)
            # V_t + a_t dt of the data is R^T V_{t+1}; the equation's own component replaces
            # its part
            before = np.einsum("wji,wj->wi", rot, ds.arrays.states[rows + 1, 3:6])
            before[:, state - 3] = x
            x = np.einsum("wj,wj->w", rot[:, state - 3], before)
        truth = ds.arrays.states[rows + 1, state]
        err += (x - truth) ** 2
        recorded.append(truth)
    recorded = np.concatenate(recorded)
    return float(err.sum() / ((recorded - recorded.mean()) ** 2).sum())


def sympy_rhs(expr: sp.Expr, rename: dict[str, str]):
    symbols = sorted(expr.free_symbols, key=lambda s: s.name)
    func = sp.lambdify(symbols, expr, "numpy")

    def rhs(view, rows):
        args = [view[rename.get(s.name, s.name)][rows] for s in symbols]
        return np.broadcast_to(np.asarray(func(*args), dtype=float), (len(rows),))

    return rhs, len(expr.as_ordered_terms())


def gpquad_rhs(path: Path, target: str):
    model = DiscoveredModel.from_dict(json.loads(path.read_text()))
    eq = model.equations[target]
    rename = {n: f"{base_input(n)}{d}" for n, d in eq.delays.items()}
    return sympy_rhs(eq.sympy(), rename)


def sindy_rhs(path: Path, group: str, target: str):
    cell = json.loads(path.read_text())
    text = (
        cell["equations"][group][target]
        if group in cell["equations"]
        else cell["equations"][target]
    )
    return sympy_rhs(parse_in_symbols(text, None, caret_power=True), {})


def library_rhs(ds_fit, target: str, library: str):
    names = [n.strip() for n in library.split(",") if n.strip()]
    cols = columns(ds_fit)
    rows = np.concatenate([np.arange(a + MAX_LAG + 1, b - 1) for a, b in ds_fit.train])

    def monomial(view, name, at):
        out = np.ones(len(at))
        for part in name.split("*"):
            out = out * view[part][at]
        return out

    x = np.column_stack([monomial(cols, n, rows) for n in names])
    coef, *_ = np.linalg.lstsq(x, ds_fit.arrays.acc[rows, TARGET_NAMES.index(target)], rcond=None)

    def rhs(view, at):
        return np.column_stack([monomial(view, n, at) for n in names]) @ coef

    return rhs, len(names)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("scenario")
    parser.add_argument("--group", help="vehicle of a per-vehicle (rotorpy) scenario")
    parser.add_argument("--target", default="r_dot", choices=TARGET_NAMES)
    parser.add_argument("--flights", type=Path, default=Path("results/ab-finish/flights"))
    parser.add_argument("--model", type=Path, nargs="*", default=[])
    parser.add_argument("--sindy", type=Path)
    parser.add_argument("--library", action="append", default=[])
    parser.add_argument("--horizon", type=float, default=1.0, help="seconds")
    args = parser.parse_args()
    scenario = build_scenario(args.scenario, args.flights)
    sub = scenario.groups[args.group] if args.group else scenario
    print(f"| equation | terms | {TARGET_STATE[args.target]} alone, RSE at {args.horizon:g} s |")
    print("|---|---|---|")
    sources = [(f"gpquad {p}", lambda p=p: gpquad_rhs(p, args.target)) for p in args.model]
    if args.sindy:
        sources.append(("sindy", lambda: sindy_rhs(args.sindy, args.group, args.target)))
    sources += [
        (f"least squares [{lib}]", lambda lib=lib: library_rhs(sub.fit, args.target, lib))
        for lib in args.library
    ]
    for label, make in sources:
        rhs, terms = make()
        with np.errstate(all="ignore"):
            rse = rollout_rse(sub.test, args.target, rhs, args.horizon)
        print(
            f"| {label} | {terms} | {rse:.3g} |"
            if np.isfinite(rse)
            else f"| {label} | {terms} | diverged |"
        )


if __name__ == "__main__":
    sys.exit(main())
