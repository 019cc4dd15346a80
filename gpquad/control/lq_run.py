"""`gpquad control lq PEM_RUN_DIR`: the LQ acceleration tracker designed on the identified
body-centric model, flown on that model's non-linear equations (step and joystick-like
references), plus the tracker of the paper's own Table A1 matrices."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from gpquad.baselines.pem_config import PARAMS
from gpquad.control.config import ControlConfig, LqConfig
from gpquad.control.lq import TABLE_A1, discretise, hover_speed, linearise, lq_tracker
from gpquad.control.lq_kernel import fly_tracker
from gpquad.errors import GpquadError
from gpquad.study.store import write_json

AXES = ("a_x", "a_y", "a_z")


def load_pem_model(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """(theta [I_xx, I_yy, I_zz, J_r, b, d], vehicle [l, m, g, omega_min, omega_max])."""
    path = run_dir / "model.json"
    if not path.is_file():
        raise GpquadError(
            "not a run folder (no model.json); give the folder of `gpquad baseline pem`",
            source=str(run_dir),
        )
    d = json.loads(path.read_text())
    if d.get("method") != "pem" or "parameters" not in d or "vehicle" not in d:
        raise GpquadError(
            "not a PEM body-centric model (model.json needs method = pem, "
            "parameters and vehicle); run `gpquad baseline pem` first",
            source=str(path),
            field="method",
        )
    theta = np.array([float(d["parameters"][p]) for p in PARAMS])
    vehicle = np.array([float(v) for v in d["vehicle"]])
    if not (np.all(np.isfinite(theta)) and theta[4] > 0 and len(vehicle) == 5):
        raise GpquadError(
            "parameters must be finite with b > 0, vehicle 5 values",
            source=str(path),
            field="parameters",
        )
    return theta, vehicle


def step_metrics(t, ref, out, start: int, step: float, band: float) -> dict:
    """Settling time (s after the step until |out - ref| stays within band |step|) and
    steady-state error (mean over the last second, as a fraction of the step)."""
    err = out[start:] - ref[start:]
    outside = np.nonzero(~(np.abs(err) <= band * abs(step)))[0]
    settle = (
        0.0
        if len(outside) == 0
        else (np.inf if outside[-1] == len(err) - 1 else t[start + outside[-1] + 1] - t[start])
    )
    last = max(1, int(round(1.0 / (t[1] - t[0]))))
    return {
        "settling_time_s": float(settle),
        "steady_state_error": float(np.mean(err[-last:]) / step),
    }


def step_tests(theta, vehicle, tracker, cfg: LqConfig) -> tuple[dict, list]:
    """One step of each body acceleration reference (1 s at zero, then step_s at step)."""
    dt, om = cfg.dt, hover_speed(theta, vehicle)
    n0, n1 = int(round(1.0 / dt)), int(round(cfg.step_s / dt))
    t = np.arange(n0 + n1) * dt
    out, traces = {}, []
    for i, axis in enumerate(AXES):
        refs = np.zeros((n0 + n1 + 1, 4))
        refs[n0 + 1 :, 1 + i] = cfg.step_m_s2  # y_r(n + 1) is read at step n
        xs, ys, _ = fly_tracker(theta, vehicle, tracker.K, tracker.F, om, refs, dt)
        m = step_metrics(t, refs[1:, 1 + i], ys[:, 1 + i], n0, cfg.step_m_s2, cfg.settle_band)
        tail = slice(-int(round(1.0 / dt)), None)
        m["steady_attitude_rad_per_m_s2"] = {
            "phi": float(np.mean(xs[tail, 0]) / cfg.step_m_s2),
            "theta": float(np.mean(xs[tail, 1]) / cfg.step_m_s2),
        }
        out[axis] = m
        traces.append((axis, t, refs[1:, 1:], ys[:, 1:], xs[:, :2]))
    return out, traces


def joystick_reference(cfg: LqConfig, rng: np.random.Generator) -> np.ndarray:
    """refs (N + 1, 4): psi_r = 0 and accelerations (a_z at half the SD), clipped: an OU
    process of time constant joystick_tau_s smoothed by a first-order lag of tau / 5 (a
    thumb on a stick cannot move faster)."""
    n = int(round(cfg.joystick_s / cfg.dt)) + 1
    decay = np.exp(-cfg.dt / cfg.joystick_tau_s)
    lag = np.exp(-cfg.dt / (0.2 * cfg.joystick_tau_s))
    sd = cfg.joystick_sd_m_s2 * np.array([1.0, 1.0, 0.5])
    shocks = rng.standard_normal((n, 3)) * sd * np.sqrt(1 - decay**2)
    ou = np.zeros(3)
    a = np.zeros((n, 3))
    for k in range(1, n):
        ou = decay * ou + shocks[k]
        a[k] = lag * a[k - 1] + (1 - lag) * ou
    refs = np.zeros((n, 4))
    refs[:, 1:] = np.clip(a, -cfg.max_ref_m_s2, cfg.max_ref_m_s2)
    return refs


def run_lq(run_dir, cfg: ControlConfig, out_dir, say=print, figures: bool = True) -> dict:
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    started = time.time()
    q = cfg.lq
    theta, vehicle = load_pem_model(run_dir)
    A, B, C, D = linearise(theta, vehicle)
    Phi, Gamma, Cd, Dd = discretise(A, B, C, D, q.dt)
    tracker = lq_tracker(Phi, Gamma, Cd, Dd, np.diag(q.q_y), q.r * np.eye(4))
    say(
        f"gpquad control lq: PEM model {run_dir}; hover {hover_speed(theta, vehicle):.1f} rad/s; "
        f"pitch per unit a_x reference {tracker.Pi[1, 1]:.4f} rad/(m/s^2)"
    )
    steps, traces = step_tests(theta, vehicle, tracker, q)
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 56]))
    refs = joystick_reference(q, rng)
    xs, ys, _ = fly_tracker(
        theta, vehicle, tracker.K, tracker.F, hover_speed(theta, vehicle), refs, q.dt
    )
    joy_rmse = {
        a: float(np.sqrt(np.nanmean((ys[:, 1 + i] - refs[1:, 1 + i]) ** 2)))
        for i, a in enumerate(AXES)
    }
    paper = lq_tracker(
        TABLE_A1["Phi"],
        TABLE_A1["Gamma"],
        TABLE_A1["C"],
        TABLE_A1["D"],
        TABLE_A1["Q_y"],
        TABLE_A1["R"],
    )
    summary = {
        "pitch_per_unit_ax_rad": float(tracker.Pi[1, 1]),
        "roll_per_unit_ay_rad": float(tracker.Pi[0, 2]),
        "step": steps,
        "joystick_rmse_m_s2": joy_rmse,
        "joystick_diverged": bool(np.isnan(ys).any()),
    }
    details = {
        "model_run": str(run_dir),
        "parameters": dict(zip(PARAMS, theta.tolist(), strict=True)),
        "vehicle": vehicle.tolist(),
        "dt": q.dt,
        "Phi": Phi.tolist(),
        "Gamma": Gamma.tolist(),
        "C": Cd.tolist(),
        "D": Dd.tolist(),
        "tracker": tracker.to_dict(),
        "table_a1_tracker": {
            **paper.to_dict(),
            "note": "K, F, Pi from the paper's printed "
            "Phi, Gamma, C, D, Q_y, R (tests/test_control_lq.py compares "
            "them with its printed K and F)",
        },
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "summary.json", {**summary, **details})
    from gpquad.control.pid_run import provenance_with_control

    write_json(
        out_dir / "run.json",
        {
            "command": "control lq",
            "seed": cfg.seed,
            "config": {"seed": cfg.seed, "lq": q.__dict__},
            "model_run": str(run_dir),
            "wall_time_s": time.time() - started,
            **provenance_with_control(),
        },
    )
    np.savetxt(
        out_dir / "joystick.csv",
        np.column_stack([np.arange(len(ys)) * q.dt, refs[1:, 1:], ys[:, 1:]]),
        delimiter=",",
        header="t,a_xr,a_yr,a_zr,a_x,a_y,a_z",
        comments="",
        fmt="%.6g",
    )
    if figures:
        from gpquad.control.figures import tracking_figure

        for axis, t, ref, acc, ang in traces:
            tracking_figure(
                t,
                ref,
                acc,
                out_dir / f"step_{axis}.png",
                title=f"LQ tracker, step in {axis} (PEM model)",
                angles=ang,
            )
        tracking_figure(
            np.arange(len(ys)) * q.dt,
            refs[1:, 1:],
            ys[:, 1:],
            out_dir / "joystick.png",
            title="LQ tracker, joystick-like references (PEM model)",
            angles=xs[:, :2],
        )
    for axis, m in steps.items():
        say(
            f"  step {q.step_m_s2:g} m/s^2 in {axis}: settling {m['settling_time_s']:.3f} s "
            f"({q.settle_band:.0%} band), steady-state error {m['steady_state_error']:+.2%}"
        )
    say("  joystick RMSE (m/s^2): " + ", ".join(f"{a} {v:.3f}" for a, v in joy_rmse.items()))
    return summary
