"""Analytic initial guesses of the body-centric model's parameters (section 3 of the paper).

Lift factor b: blade-element theory, eq. (13), or the hover balance, eq. (14).
Drag factor d: blade-element theory, eq. (16).
Inertia: the frame as two rods, the electronics (and battery) as a box, the motors as
cylinders and the propellers as flat discs at the arm tips; J_r is a propeller (flat
disc of variable density: factor * m_p R_p^2) plus the motor bell (thin ring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Geometry:
    """Vehicle geometry (SI units: m, kg, rad, kg/m^3)."""

    rho: float = 1.225
    n_blades: int = 2
    chord: float = 0.025
    prop_radius: float = 0.127
    theta_tw0: float = 0.30  # blade twist at the hub, eq. (12)
    theta_twf: float = 0.15  # twist slope along the radius, eq. (12)
    inflow_ratio: float = 0.05  # lambda
    drag_coefficient: float = 0.01
    lift_method: str = "hover"  # hover (eq. 14) or blade_element (eq. 13)
    hover_speed: float = 405.0  # measured hover motor speed, rad/s
    rod_mass: float = 0.1  # each of the two arms, tip to tip 2 l
    box_mass: float = 0.9
    box_size: tuple[float, ...] = (0.12, 0.12, 0.08)
    motor_mass: float = 0.1
    motor_radius: float = 0.014
    motor_height: float = 0.03
    prop_mass: float = 0.01
    prop_inertia_factor: float = 1.0 / 3.0
    rotor_mass: float = 0.02  # spinning motor bell


def blade_element_factor(g: Geometry) -> float:
    """The bracket [theta_tw0/6 - theta_twf/8 - lambda/4] of eqs. (11)-(16)."""
    return g.theta_tw0 / 6.0 - g.theta_twf / 8.0 - g.inflow_ratio / 4.0


def lift_factor(g: Geometry, mass: float, gravity: float) -> float:
    """b (N s^2): eq. (14) from the hover speed, or eq. (13) from blade elements."""
    if g.lift_method == "hover":
        return mass * gravity / (4.0 * g.hover_speed**2)
    return 2 * math.pi * g.rho * g.n_blades * g.chord * g.prop_radius**3 * blade_element_factor(g)


def drag_factor(g: Geometry) -> float:
    """d (N m s^2), eq. (16)."""
    return (
        2
        * math.pi
        * g.rho
        * g.n_blades
        * g.chord
        * g.prop_radius**4
        * (g.drag_coefficient / (16 * math.pi) + g.inflow_ratio * blade_element_factor(g))
    )


def inertia(g: Geometry, arm: float) -> tuple[float, float, float, float]:
    """(I_xx, I_yy, I_zz, J_r) kg m^2 from simple shapes; arm = motor distance l (m)."""
    rod = g.rod_mass * (2 * arm) ** 2 / 12.0  # each rod, about its transverse axes
    a, b, c = g.box_size
    box = (
        g.box_mass * (b * b + c * c) / 12.0,
        g.box_mass * (a * a + c * c) / 12.0,
        g.box_mass * (a * a + b * b) / 12.0,
    )
    mr, mh = g.motor_radius, g.motor_height
    motor_axial = g.motor_mass * mr * mr / 2.0
    motor_trans = g.motor_mass * (3 * mr * mr + mh * mh) / 12.0
    tip = (g.motor_mass + g.prop_mass) * arm * arm  # point masses at the arm tips
    prop_axial = g.prop_inertia_factor * g.prop_mass * g.prop_radius**2
    prop_trans = prop_axial / 2.0  # flat disc: transverse = axial / 2
    # arms on x (motors 1, 3) and y (motors 2, 4): each pair adds 2 tip masses to the two
    # axes perpendicular to its arm.
    ixx = rod + box[0] + 2 * tip + 4 * (motor_trans + prop_trans)
    iyy = rod + box[1] + 2 * tip + 4 * (motor_trans + prop_trans)
    izz = 2 * rod + box[2] + 4 * tip + 4 * (motor_axial + prop_axial)
    jr = prop_axial + g.rotor_mass * mr * mr
    return ixx, iyy, izz, jr


def initial_guess(g: Geometry, arm: float, mass: float, gravity: float) -> dict[str, float]:
    """Theta_0 = {I_xx, I_yy, I_zz, J_r, b, d} of the analytic approximations."""
    ixx, iyy, izz, jr = inertia(g, arm)
    return {
        "I_xx": ixx,
        "I_yy": iyy,
        "I_zz": izz,
        "J_r": jr,
        "b": lift_factor(g, mass, gravity),
        "d": drag_factor(g),
    }
