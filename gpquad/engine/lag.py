"""An equation's first-order lag (not in the paper; chosen by gpquad.models.refine).

A multirotor's moments follow its motor speeds, and the motors lag their commands (rotorpy's
crazyflie: 72 ms, at 25 Hz almost two samples). An equation of the current state and
inputs then cannot hold the applied moment; a few input taps (gpquad.engine.taps) filter
the input part of it but not the feedback of the states. With a lag the equation's tree
gives the commanded acceleration f and the applied one follows it,

    tau da/dt + a = f,   discretely  a_k = a_{k-1} + alpha (f_k - a_{k-1}),
    alpha = 1 - exp(-dt / tau)     (exact for f held over a step),

starting from the data's acceleration of the step before a window. tau = 0 is no lag
(alpha = 1, and the kernels skip the filter).
"""

from __future__ import annotations

import math

#: Time constants (s) the refinement tries (0: none); the one whose refit of the equation's
#: own terms flies the training windows best is kept (gpquad.models.refine.choose_lag).
LAG_GRID = (0.0, 0.01, 0.02, 0.035, 0.05, 0.07, 0.1, 0.14, 0.2)


def lag_alpha(tau: float, dt: float) -> float:
    """The kernels' lag factor of time constant tau (s) at sample period dt (s)."""
    if not tau > 0.0:
        return 1.0
    return float(-math.expm1(-dt / tau))
