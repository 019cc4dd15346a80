"""Physics-based identification after the racing-drone thesis
(`../shared/seeds/racing-drone-betaflight-thrust-drag-thesis.txt`).

- `mixer`: Betaflight's rate loop to motor commands (thesis IV.A, eqs. 13-17).
- `bflog`, `mixer_check`: PID sums, throttle and motors from blackbox logs; validation.
- `regression`, `aero`: thrust (eqs. 5, 19) and drag (eq. 18) regressions.
- `deadreckon`: position by dead reckoning with four acceleration models (section V).
- `sync`: log synchronisation (eq. 12, cross-correlation) and causal smoothing (III.B-C).
- `truth`: rotorpy flights with known coefficients (L, U and square paths).

Frames in this package follow rotorpy: world z up, body z along the thrust.
"""
