"""When a search stops gaining: the stall rule of the run loop (gpquad.study.loop).

After every iteration the run loop records the best climber's error over the whole
training data (`RunState.best_errors`). The search stops early when `patience`
iterations in a row did not lower the best error recorded so far by at least the
fraction `gain` of it, or at once when the best error is `exact`: below EXACT_RSE of the
target state's spread, the selection's resolution, below which the final selection sees no
error to gain (it still prunes the climber). The generations fly the eq. 2 surrogate, in
which a continuous-time equation that is exact still errs by its discretisation: a best
error below NEAR_EXACT_RSE is therefore also checked in the configured integrator, its
constants fitted there (gpquad.engine.evolve.choice, FinalChoice.exact_in_model_scheme).
The climbers are scored on a co-evolving suite, so the best training error is not
monotone; the rule compares with the lowest error reached, and an iteration that does not
beat it by `gain` counts as stalled. The measurements behind the defaults are in
docs/decisions/2026-11-26-finish-speed.md and docs/decisions/2026-11-28-exact-in-rk4.md.
"""

from __future__ import annotations

import math

from gpquad.engine.evolve.selection import RSE_RESOLUTION

#: A best error below this fraction of the target state's standard deviation is exact:
#: the final selection's resolution (errors below it count as zero there).
EXACT_RSE = RSE_RESOLUTION
#: A best surrogate error below this fraction of the spread may be an exact equation of the
#: configured integrator (its discretisation error stays below it; docs/decisions/
#: 2026-11-28-exact-in-rk4.md), so it is checked there (FinalChoice.exact_in_model_scheme).
NEAR_EXACT_RSE = 20 * EXACT_RSE


def stalled(best_errors: list[float], patience: int, gain: float) -> bool:
    """True when the last `patience` entries of best_errors did not lower the lowest earlier
    one by the fraction `gain`; False for patience 0 (the rule is off) or a short record."""
    if patience <= 0 or len(best_errors) <= patience:
        return False
    lowest = math.inf
    since = 0
    for error in best_errors:
        if not math.isfinite(error):
            since += 1
            continue
        if error < lowest * (1.0 - gain):
            lowest, since = error, 0
        else:
            since += 1
            lowest = min(lowest, error)
    return since >= patience


def best_error(train_errors) -> float:
    """The lowest finite climber error (inf when none is finite)."""
    finite = [float(e) for e in train_errors if math.isfinite(float(e))]
    return min(finite) if finite else math.inf


def exact(error: float, spread: float, squared: bool, rse: float = EXACT_RSE) -> bool:
    """Whether `error` (the engine's metric: mean absolute, or squared if `squared`, state
    error) is below `rse` (default EXACT_RSE) of a state whose standard deviation is
    `spread`."""
    floor = rse * spread
    return math.isfinite(error) and error <= (floor * floor if squared else floor)
