"""scipy's Levenberg-Marquardt remembers earlier calls: a reproduction (not a test).

    python benchmarks/lm_state.py [--call 9000] [--flights results/ab-finish/flights]

Runs the engine's p_dot search on rotorpy-heldout-angle (seed 1, recommended engine) until
its CALL-th residual evaluation inside `gradient_fit.gauss_newton_constants`, then replays
the least-squares problem of that moment (the same residual vector, Jacobian, free
constants and start) through `scipy.optimize.least_squares(method="lm", x_scale="jac")`
three times in the same process, and once more after an unrelated LM fit of another size,
printing a hash of the first trial points of each replay. The replays see bit-identical
inputs; with scipy 1.17.1 (2026-11-25) the first replay, which follows the engine's own LM
calls, and the one after the unrelated fit took other trial points than the two in
between: MINPACK's result depends on what ran before it in the process. This is why the
same seed gave other constants in another process (README, "Reproducibility").
`scipy.optimize.leastsq` with an explicit `diag` (MINPACK mode 2) usually did not show it
in the same replay (once in about twenty runs it did); without `diag` (mode 1) it did. The
engine's constant fit is now gpquad's own LM in numba loops (gpquad.engine.evolve.lm); this
script keeps calling scipy's `least_squares` to show why.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

import gpquad.engine.evolve.gradient_fit as gradient_fit
from gpquad.benchmark.engine import engine_config
from gpquad.benchmark.scenarios import build_scenario
from gpquad.engine.tree.operators import CONST
from gpquad.study.search import identify


class Replayed(Exception):
    """Raised to stop the search once the replays are printed."""


def trial_hashes(res, jac, free, x0) -> list[str]:
    """Hashes of the first three points at which LM evaluates the residuals."""
    points = []

    def fun(x):
        points.append(x.copy())
        return res if np.array_equal(x, x0[free]) else 2.0 * res

    least_squares(fun, x0[free], jac=lambda x: jac[:, free], method="lm", max_nfev=3, x_scale="jac")
    return [hashlib.sha256(p.tobytes()).hexdigest()[:10] for p in points[:3]]


def unrelated_fit() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((1500, 16)), rng.standard_normal(1500)
    least_squares(
        lambda x: a @ x - b, np.zeros(16), jac=lambda x: a, method="lm", max_nfev=5, x_scale="jac"
    )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--call", type=int, default=9000)
    parser.add_argument("--flights", type=Path, default=Path("results/ab-finish/flights"))
    args = parser.parse_args()
    scenario = build_scenario("rotorpy-heldout-angle", args.flights)
    sub = next(iter(scenario.groups.values()))
    cfg = engine_config(1)
    cfg = dataclasses.replace(cfg, evolution=dataclasses.replace(cfg.evolution, targets=["p_dot"]))
    original = gradient_fit.residuals_and_jacobian
    calls = [0]

    def counted(ev, tree, starts, n_steps):
        out = original(ev, tree, starts, n_steps)
        calls[0] += 1
        res, jac, _ = out
        if calls[0] >= args.call and np.all(np.isfinite(jac)) and jac.shape[1] > 1:
            free = gradient_fit.identifiable(jac)
            x0 = tree.values[np.flatnonzero(tree.codes == CONST)]
            print(
                f"call {calls[0]}: residuals {res.shape}, Jacobian {jac.shape}, "
                f"{free.size} free constants"
            )
            for label in ("after the engine's LM calls", "again", "again"):
                print(f"  {label:28s}", trial_hashes(res, jac, free, x0))
            unrelated_fit()
            print(f"  {'after an unrelated LM fit':28s}", trial_hashes(res, jac, free, x0))
            raise Replayed
        return out

    gradient_fit.residuals_and_jacobian = counted
    try:
        identify(sub.fit, "p_dot", cfg)
        print(f"the search ended before call {args.call}; give a smaller --call")
    except Replayed:
        pass


if __name__ == "__main__":
    sys.exit(main())
