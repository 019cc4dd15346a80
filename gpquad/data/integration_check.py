"""The integration check (paper section 2.1): do the computed accelerations reproduce the flight?

For every flight the accelerations are computed exactly as the engine will see them
(`build_dataset` -> `body_accelerations`), then integrated forward with the engine's integrator
over consecutive windows of `check_steps` steps (paper: 750 steps = 30 s at 25 Hz), each window
starting from the data's state at its first sample.

What is compared, and what RSE means here
-----------------------------------------
The integrated states are compared with the **unfiltered measurements** of the log put on the
same clock (`Flight.meta["reference"]`): attitude from the log's quaternion, body velocity from
the log's velocity rotated by the log's attitude, body rates from the log's gyro. Against the
processed data itself the error is round-off by construction (the accelerations are the
integrator's exact inverse); that number is reported too ("round trip") as a self-test. So the
RSE measures what filtering, downsampling and deriving rates from the pose lose or distort.

    RSE = sum over windows and steps of (x_integrated - x_measured)^2
          / sum over windows and steps of (x_measured - window mean of x_measured)^2

pooled over all windows of all flights (a single window in a hover has almost no variance, so
per-window ratios are unstable; the worst window is shown for information). Angles are
compared modulo 2 pi. A state whose signal the log does not measure (for example u and v of a
PX4 flight without horizontal velocity) is reported as "not measured" and is neither a pass
nor a failure; the dataset passes when every measured one of u, v, w, p, q, r is below
`check_max_rse`. Flights without a reference (generic files) are compared with themselves,
and then roll and pitch integrated from the file's rates are judged against the file's
quaternion: a flipped or mis-scaled gyro axis, or a mis-ordered quaternion, fails there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpquad.data.flight import Flight
from gpquad.data.pipeline import is_measured
from gpquad.engine.kernels.integrator import body_accelerations, integrate
from gpquad.engine.kernels.quaternion import euler_array
from gpquad.engine.variables import STATE_NAMES
from gpquad.errors import GpquadError

#: The states the paper's check is about (the integrated ones).
CHECKED = ("u", "v", "w", "p", "q", "r")
ANGLES = ("phi", "theta", "psi")
#: Where a flight has no measurement reference of its own (generic files), u..r round-trip by
#: construction; the check then judges the attitude integrated from the file's rates against
#: the file's quaternion instead (roll and pitch; yaw often hardly varies).
JUDGED_ANGLES = ("phi", "theta")


@dataclass
class CheckRow:
    """One state variable's result. rse/worst are fractions (0.05 = 5 %)."""

    name: str
    rse: float
    worst: float
    rse_raw: float
    round_trip: float
    measured: str
    status: str  # "pass", "FAIL", "not measured", "info"


@dataclass
class CheckResult:
    rows: list[CheckRow]
    window_steps: int
    n_windows: int
    threshold: float
    notes: list[str] = field(default_factory=list)
    diagnosis: str = ""  # why the failing rates fail, when the log tells

    @property
    def passed(self) -> bool:
        return not any(r.status == "FAIL" for r in self.rows)

    def row(self, name: str) -> CheckRow:
        return next(r for r in self.rows if r.name == name)

    def table(self) -> str:
        """The result as a fixed-width text table."""
        lines = [
            f"Integration check: {self.n_windows} window(s) of {self.window_steps} steps; "
            f"pass when RSE < {self.threshold:.0%} for every measured u, v, w, p, q, r",
            f"{'state':<6} {'RSE':>9} {'worst win':>10} {'vs raw':>9} {'round trip':>11}  "
            f"{'status':<13} signal",
        ]
        for r in self.rows:
            lines.append(
                f"{r.name:<6} {r.rse:>9.3%} {r.worst:>10.3%} {r.rse_raw:>9.3%} "
                f"{r.round_trip:>11.2e}  "
                f"{r.status:<13} {r.measured}"
            )
        lines.append(
            "RSE: integrated states vs the log's measurements after the same low-pass "
            "(rates as means over each step), pooled over windows; vs raw: vs the "
            "unfiltered measurements (includes what the filter removes); round trip: "
            "max |error| vs the processed data (self-test)"
        )
        lines.append(f"verdict: {'PASS' if self.passed else 'FAIL'}")
        lines.extend(self.notes)
        return "\n".join(lines)

    def failure(self) -> str:
        bad = [f"{r.name} {r.rse:.1%}" for r in self.rows if r.status == "FAIL"]
        return (
            f"integration check failed: RSE over {self.window_steps}-step windows "
            f"{', '.join(bad)} (limit {self.threshold:.0%})"
            + (f"; {self.diagnosis}" if self.diagnosis else "")
        )

    def to_dict(self) -> dict:
        return {
            "window_steps": self.window_steps,
            "n_windows": self.n_windows,
            "threshold": self.threshold,
            "passed": self.passed,
            "rows": [r.__dict__ for r in self.rows],
        }


def _windows(n: int, steps: int) -> list[tuple[int, int]]:
    """Consecutive (start, n_steps) windows of a flight of n samples; a short flight is one."""
    if n < 2:
        return []
    if n <= steps:
        return [(0, n - 1)]
    return [(s, steps) for s in range(0, n - steps, steps)]


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else (0.0 if a == 0 else float("inf"))


def _diff(a: np.ndarray, b: np.ndarray, angle: bool) -> np.ndarray:
    d = a - b
    return (d + np.pi) % (2 * np.pi) - np.pi if angle else d


def integration_check(
    flights: list[Flight], window_steps: int = 750, threshold: float = 0.05
) -> CheckResult:
    """Integrate each flight's accelerations over windows; RSE per state (see module doc)."""
    if not flights:
        raise GpquadError("no flight to check", field="data.files")
    sse = np.zeros(9)
    sst = np.zeros(9)
    sse_raw = np.zeros(9)
    sst_raw = np.zeros(9)
    worst = np.zeros(9)
    trip = np.zeros(9)
    n_windows = 0
    notes = []
    measured = {}
    self_referenced = False
    for f in flights:
        dt = f.dt
        quat = np.ascontiguousarray(f.quat, dtype=float)
        vel = np.ascontiguousarray(f.vel, dtype=float)
        rates = np.ascontiguousarray(f.rates, dtype=float)
        acc = body_accelerations(vel, rates, dt)
        data_states = np.hstack([euler_array(quat), vel, rates])
        ref = f.meta.get("reference")
        raw = f.meta.get("reference_raw")
        if ref is None:
            ref = data_states
            self_referenced = True
            notes.append(
                f"{f.name}: no separate measurement reference (a generic file): u..r "
                "are compared with the file itself, and the attitude integrated from "
                "its rates with its quaternion (phi and theta judged)"
            )
        if raw is None:
            raw = ref
        for name, text in f.meta.get("measured", {}).items():
            if not is_measured(text) or name not in measured:
                measured[name] = text
        for start, steps in _windows(len(f), window_steps):
            q, v, w, _ = integrate(
                quat[start], vel[start], rates[start], np.zeros(3), acc[start : start + steps], dt
            )
            sim = np.hstack([euler_array(np.ascontiguousarray(q)), v, w])
            n_windows += 1
            for j, name in enumerate(STATE_NAMES):
                angle = name in ANGLES
                x_ref = ref[start : start + steps + 1, j]
                e = _diff(sim[:, j], x_ref, angle)
                centred = (
                    _diff(x_ref, np.angle(np.mean(np.exp(1j * x_ref))), True)
                    if angle
                    else x_ref - x_ref.mean()
                )
                a, b = float(e @ e), float(centred @ centred)
                sse[j] += a
                sst[j] += b
                x_raw = raw[start : start + steps + 1, j]
                e_raw = _diff(sim[:, j], x_raw, angle)
                c_raw = (
                    _diff(x_raw, np.angle(np.mean(np.exp(1j * x_raw))), True)
                    if angle
                    else x_raw - x_raw.mean()
                )
                sse_raw[j] += float(e_raw @ e_raw)
                sst_raw[j] += float(c_raw @ c_raw)
                worst[j] = max(worst[j], a / b if b > 0 else (0.0 if a == 0 else np.inf))
                rt = _diff(sim[:, j], data_states[start : start + steps + 1, j], angle)
                trip[j] = max(trip[j], float(np.abs(rt).max()))
    rows = []
    for j, name in enumerate(STATE_NAMES):
        rse = _ratio(sse[j], sst[j])
        rse_raw = _ratio(sse_raw[j], sst_raw[j])
        text = measured.get(name, "measured")
        if name not in CHECKED and not (self_referenced and name in JUDGED_ANGLES):
            status = "info"
        elif not is_measured(text):
            status = "not measured"
        else:
            status = "pass" if rse < threshold else "FAIL"
        rows.append(
            CheckRow(
                name, float(rse), float(worst[j]), float(rse_raw), float(trip[j]), text, status
            )
        )
    if n_windows == 0:
        raise GpquadError("flights too short for the integration check", field="data.files")
    failing = [j for j, r in enumerate(rows) if r.status == "FAIL" and r.name in "pqr"]
    return CheckResult(
        rows, window_steps, n_windows, threshold, notes, diagnose_rates(flights, failing)
    )


def diagnose_rates(flights: list[Flight], failing: list[int]) -> str:
    """Why body rates fail the check: the gyro's peak and its agreement with the estimator's
    attitude (the rates the quaternion implies), from the unfiltered reference of a log."""
    raws = [f.meta.get("reference_raw") for f in flights]
    if not failing or any(r is None for r in raws):
        return ""
    gyro = np.vstack([r[:-1, 6:9] for r in raws])
    implied = np.vstack([f.rates[:-1] for f in flights])  # from the quaternion
    n = min(len(gyro), len(implied))
    gyro, implied = gyro[:n], implied[:n]
    corr = [float(np.corrcoef(gyro[:, j - 6], implied[:, j - 6])[0, 1]) for j in failing]
    names = [STATE_NAMES[j] for j in failing]
    peak = float(np.abs(gyro).max())
    text = (
        f"the estimator's attitude and the gyro disagree on {', '.join(names)} "
        f"(correlation of the quaternion's rates with the gyro "
        f"{', '.join(f'{c:.2f}' for c in corr)})"
    )
    if peak > 10.0:
        text += f"; the gyro reaches {peak:.1f} rad/s (flips?)"
    return text


def screen_segments(
    flights: list[Flight],
    window_steps: int = 750,
    threshold: float = 0.05,
    source: str = "",
    field: str = "data.check_max_rse",
    skip_hint: str = "set data.check_before_run = false",
) -> tuple[list[Flight], list[str], CheckResult]:
    """Check every segment on its own; drop those that fail, keep the rest.

    Returns (kept flights, one warning per dropped segment naming its time span and the
    failing states, the pooled check of the kept ones). Raises GpquadError (naming `field`)
    when no segment passes, with the reason of the longest one and `skip_hint` (how the
    calling command skips the check).
    """
    kept, dropped, results = [], [], []
    for f in flights:
        result = integration_check([f], window_steps, threshold)
        results.append((len(f), f, result))
        if result.passed:
            kept.append(f)
        else:
            dropped.append(
                f"dropped segment {f.name} ({f.t[0]:.2f}..{f.t[-1]:.2f} s): {result.failure()}"
            )
    if not kept:
        _, worst, result = max(results, key=lambda r: r[0])
        where = f" (every segment fails; longest {worst.name})" if len(flights) > 1 else ""
        raise GpquadError(
            f"{result.failure()}{where}; run `gpquad data check` for the table, or {skip_hint}",
            source=source,
            field=field,
        )
    check = integration_check(kept, window_steps, threshold)
    check.notes.extend(dropped)
    return kept, dropped, check
