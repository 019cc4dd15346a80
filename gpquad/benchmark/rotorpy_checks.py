"""Bounds of a generated rotorpy flight (gpquad.benchmark.rotorpy_flights): a flight that
crashes, diverges, tilts or spins too far, or saturates its rotors is refused."""

from __future__ import annotations

import numpy as np

from gpquad.errors import GpquadError

#: A flight fails (GpquadError) when it leaves these bounds.
LIMITS = {
    "min_altitude_m": 0.5,
    "max_tracking_m": 3.0,
    "max_tilt_deg": 60.0,
    "max_rate": 15.0,
    "max_saturation_fraction": 0.01,
}


def check_flight(spec, t, states, ref, flown: int, rotor_limits) -> dict:
    """Bounds of a flight (dict) of a rotorpy_flights.FlightSpec; GpquadError naming the
    flight if it crashed or diverged."""

    def fail(what: str, k: int | None = None):
        at = "" if k is None else f" at t = {t[k]:.2f} s"
        raise GpquadError(
            f"flight {spec.mode}/{spec.name} (seed {spec.seed}) {what}{at}; lower the excitation",
            field="EXCITATION",
        )

    finite = np.isfinite(states[:flown]).all(axis=1)
    if flown < len(t) or not finite.all():
        fail("diverged (non-finite state)", int(np.argmin(finite)) if not finite.all() else flown)
    tilt = np.degrees(
        np.arccos(np.clip(1.0 - 2.0 * (states[:, 6] ** 2 + states[:, 7] ** 2), -1.0, 1.0))
    )
    tracking = np.linalg.norm(states[:, 0:3] - ref[:, 0:3], axis=1)
    rates = np.abs(states[:, 10:13]).max(axis=1)
    for value, limit, what, below in (
        (states[:, 2], LIMITS["min_altitude_m"], "hit the ground (altitude < limit)", True),
        (tracking, LIMITS["max_tracking_m"], "left the reference (> limit m)", False),
        (tilt, LIMITS["max_tilt_deg"], "tilted beyond the limit", False),
        (rates, LIMITS["max_rate"], "spun beyond the rate limit", False),
    ):
        bad = np.flatnonzero(value < limit if below else value > limit)
        if bad.size:
            fail(what, int(bad[0]))
    saturated = (
        (states[:, 16:] <= rotor_limits[0] + 1e-9) | (states[:, 16:] >= rotor_limits[1] - 1e-9)
    ).mean()
    if saturated > LIMITS["max_saturation_fraction"]:
        fail(f"saturated its rotors {100 * saturated:.1f} % of the time")
    return {
        "min_altitude_m": float(states[:, 2].min()),
        "max_tilt_deg": float(tilt.max()),
        "max_tracking_m": float(tracking.max()),
        "max_rate": float(rates.max()),
        "rotor_saturation_fraction": float(saturated),
    }
