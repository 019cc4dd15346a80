"""The PID waypoint controller as a record, and one closed-loop flight of it on a plant."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gpquad.control.config import GAIN_NAMES, PidConfig
from gpquad.control.courses import PathScore, allotted_steps, score_path
from gpquad.control.pid_kernel import fly_course
from gpquad.control.plant import DesignPoint, Plant
from gpquad.engine.kernels.step import scheme_code


@dataclass
class Controller:
    """Gains (13,) in GAIN_NAMES order, the design point and the input limits (raw units)."""

    gains: np.ndarray
    design: DesignPoint
    lo: np.ndarray
    hi: np.ndarray
    max_angle: float
    level: float  # 1: rate-level inputs (inner loop on the angle error), 0: angle-level
    waypoint_radius: float
    integral_limit: float
    command_limit: float = 0.0

    def ctrl(self) -> np.ndarray:
        return np.array(
            [
                self.design.g_x,
                self.design.g_y,
                self.max_angle,
                self.level,
                self.waypoint_radius,
                self.integral_limit,
                self.command_limit,
                0.0,
                0.0,
            ]
        )

    def with_gains(self, gains) -> Controller:
        return Controller(
            np.asarray(gains, float),
            self.design,
            self.lo,
            self.hi,
            self.max_angle,
            self.level,
            self.waypoint_radius,
            self.integral_limit,
            self.command_limit,
        )

    def gains_dict(self) -> dict[str, float]:
        return dict(zip(GAIN_NAMES, self.gains.tolist(), strict=True))


def make_controller(gains, design: DesignPoint, lo, hi, cfg: PidConfig) -> Controller:
    return Controller(
        np.asarray(gains, float),
        design,
        np.asarray(lo, float),
        np.asarray(hi, float),
        cfg.max_angle_rad,
        1.0 if cfg.input_level == "rate" else 0.0,
        cfg.course.waypoint_radius_m,
        cfg.integral_limit,
        cfg.command_limit,
    )


@dataclass
class Flight:
    pos: np.ndarray  # (N + 1, 3) NED m
    states: np.ndarray  # (N + 1, 9)
    inputs: np.ndarray  # (N, n_in) raw, before noise
    target: np.ndarray  # (N + 1,) waypoint index
    flown: int
    score: PathScore


def fly(plant: Plant, controller: Controller, waypoints: np.ndarray, noise: np.ndarray) -> Flight:
    """Fly the course for len(noise) steps (the allotted time) and score the path."""
    n = len(noise)
    d = controller.design
    with np.errstate(all="ignore"):
        pos, states, inputs, target, flown = fly_course(
            plant.codes,
            plant.values,
            plant.sizes,
            plant.delays,
            plant.alphas,
            plant.trim,
            plant.dt,
            controller.gains,
            controller.ctrl(),
            d.chan,
            d.scale,
            d.hover,
            controller.lo,
            controller.hi,
            np.ascontiguousarray(waypoints, float),
            np.ascontiguousarray(noise),
            n,
            scheme_code(plant.integrator),
            plant.substeps,
        )
    return Flight(
        pos, states, inputs, target, int(flown), score_path(pos, target, waypoints, int(flown), n)
    )


def input_noise(
    rng: np.random.Generator, waypoints, cfg: PidConfig, dt: float, sd: np.ndarray
) -> np.ndarray:
    """Gaussian input noise (allotted steps, n_in) of SD `sd` per input."""
    n = allotted_steps(waypoints, cfg.course, dt)
    return rng.standard_normal((n, len(sd))) * sd
