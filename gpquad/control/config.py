"""Config of `gpquad control pid` and `gpquad control lq` (TOML sections [pid] and [lq]).

Every field has a default, so both commands run without a file; a TOML file
(experiments/control_*.toml) changes them. Unknown keys and wrong types are one-line
GpquadErrors naming the file and the field, as everywhere in gpquad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from gpquad.baselines.schema import build, read_toml, require

#: Names of the evolved PID gains, in the kernel's order (see gpquad.control.pid_kernel).
GAIN_NAMES = (
    "kp_roll",
    "kd_roll",
    "kp_pitch",
    "kd_pitch",
    "kp_yaw",
    "kd_yaw",
    "kp_x",
    "kd_x",
    "kp_y",
    "kd_y",
    "kp_z",
    "ki_z",
    "kd_z",
)


@dataclass(frozen=True)
class CourseConfig:
    """Random waypoint courses: legs of random length and turn from the origin, heading north."""

    legs: int = 5
    leg_min_m: float = 4.0
    leg_max_m: float = 10.0
    max_turn_deg: float = 120.0
    climb_max_m: float = 1.0  # altitude change per leg, uniform in +-climb_max_m
    speed_m_s: float = 1.0  # allotted time = course length / speed
    waypoint_radius_m: float = 0.5  # a waypoint is reached within this distance


@dataclass(frozen=True)
class PidConfig:
    """Nested PID loops (paper section 3.3) and the evolution of their gains."""

    input_level: str = "rate"  # rate: inputs command rates/torques | angle: they command angles
    model_form: str = "simplified"  # fly the simplified equations | "tree": the raw trees
    max_angle_rad: float = 0.35  # outer loops' pitch and roll set-points are clipped to this
    input_noise: float = 0.10  # input noise SD as a fraction of each input's maximum (paper)
    input_margin: float = 0.25  # inputs clipped to the training range widened by this x span
    integral_limit: float = 5.0  # |altitude error integral| limit, m s
    command_limit: float = 0.0  # > 0: |roll, pitch, yaw input - hover| limit (input units)
    # Nominal gains: CMA-ES searches log10(gain / nominal) in [-span, +span].
    nominal_gains: tuple[float, ...] = (
        30.0,
        8.0,
        30.0,
        8.0,
        10.0,
        4.0,
        0.5,
        1.0,
        0.5,
        1.0,
        2.0,
        0.2,
        2.0,
    )
    log10_span: float = 2.0
    sigma0: float = 0.5  # CMA-ES initial step, in decades
    popsize: int = 12
    generations: int = 40
    courses_per_generation: int = 3  # common random courses for the whole population
    deviation_scale_m: float = 1.0  # d0 of the fitness (progress / (1 + rmse / d0))
    repetitions: int = 3  # flights per test course on each plant, with different noise (Fig. 3)
    course: CourseConfig = field(default_factory=CourseConfig)


@dataclass(frozen=True)
class LqConfig:
    """LQ acceleration tracker (body-centric paper, section 6) on the PEM model."""

    dt: float = 0.001  # control and discretisation period, s (paper: 1 kHz)
    q_y: tuple[float, ...] = (180e3, 5e3, 5e3, 5e3)  # Q_y diagonal, outputs [psi, a_x, a_y, a_z]
    r: float = 1.0  # R = r I_4
    step_m_s2: float = 1.0  # size of the step references
    step_s: float = 6.0  # length of each step test
    settle_band: float = 0.05  # settling: |a - a_r| stays within this fraction of the step
    joystick_s: float = 30.0  # length of the joystick-like reference
    joystick_sd_m_s2: float = 0.8  # its SD (a_x, a_y; a_z half of it)
    joystick_tau_s: float = 1.0  # its time constant
    max_ref_m_s2: float = 2.0  # |reference| limit (section 6.2: limits the attitude)


@dataclass(frozen=True)
class ControlConfig:
    seed: int = 1
    pid: PidConfig = field(default_factory=PidConfig)
    lq: LqConfig = field(default_factory=LqConfig)


def validate(cfg: ControlConfig, source: str) -> ControlConfig:
    p, c, q = cfg.pid, cfg.pid.course, cfg.lq
    require(p.input_level in ("rate", "angle"), "choose rate or angle", source, "pid.input_level")
    require(
        p.model_form in ("simplified", "tree"),
        "choose simplified or tree",
        source,
        "pid.model_form",
    )
    require(
        len(p.nominal_gains) == len(GAIN_NAMES) and all(g > 0 for g in p.nominal_gains),
        f"give {len(GAIN_NAMES)} positive gains {list(GAIN_NAMES)}",
        source,
        "pid.nominal_gains",
    )
    require(
        0.0 < p.max_angle_rad < math.pi / 2, "must be in (0, pi/2)", source, "pid.max_angle_rad"
    )
    require(0.0 <= p.input_noise < 1.0, "must be in [0, 1)", source, "pid.input_noise")
    require(p.input_margin >= 0.0, "must be >= 0", source, "pid.input_margin")
    require(p.log10_span > 0 and p.sigma0 > 0, "must be > 0", source, "pid.sigma0")
    require(
        p.popsize >= 2
        and p.generations >= 1
        and p.courses_per_generation >= 1
        and p.repetitions >= 1,
        "popsize >= 2, generations, courses and repetitions >= 1",
        source,
        "pid.popsize",
    )
    require(p.command_limit >= 0, "must be >= 0 (0: no limit)", source, "pid.command_limit")
    require(
        p.deviation_scale_m > 0 and p.integral_limit >= 0,
        "must be > 0",
        source,
        "pid.deviation_scale_m",
    )
    require(c.legs >= 1, "must be >= 1", source, "pid.course.legs")
    require(
        0 < c.leg_min_m <= c.leg_max_m,
        "need 0 < leg_min_m <= leg_max_m",
        source,
        "pid.course.leg_min_m",
    )
    require(
        c.speed_m_s > 0 and c.waypoint_radius_m > 0 and c.climb_max_m >= 0,
        "speed and radius must be > 0",
        source,
        "pid.course.speed_m_s",
    )
    require(0 <= c.max_turn_deg <= 180, "must be in [0, 180]", source, "pid.course.max_turn_deg")
    require(q.dt > 0 and q.r > 0, "must be > 0", source, "lq.dt")
    require(
        len(q.q_y) == 4 and all(v >= 0 for v in q.q_y),
        "give 4 non-negative weights [psi, a_x, a_y, a_z]",
        source,
        "lq.q_y",
    )
    require(
        q.step_s > 0 and q.joystick_s > 0 and q.joystick_tau_s > 0,
        "must be > 0",
        source,
        "lq.step_s",
    )
    require(0 < q.settle_band < 1, "must be in (0, 1)", source, "lq.settle_band")
    require(
        q.max_ref_m_s2 > 0 and q.joystick_sd_m_s2 >= 0, "must be > 0", source, "lq.max_ref_m_s2"
    )
    return cfg


def load_control_config(path=None) -> ControlConfig:
    """The defaults, or a TOML file's values."""
    if path is None:
        return ControlConfig()
    table, source = read_toml(path)
    return validate(build(ControlConfig, table, source), source)
