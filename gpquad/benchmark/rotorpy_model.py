"""rotorpy's multirotor model and controllers as numba kernels (flat arrays in, arrays out).

A line-by-line port of rotorpy 3.0.0 (`rotorpy.vehicles.multirotor.Multirotor` with
`aero=True`: rotor drag `k_d`, induced inflow `k_z`, translational lift `k_h`, flapping
`k_flap`, parasitic drag `c_D`, first-order motor lag `tau_m`, rotor-speed limits; its
low-level `cmd_ctatt` and `cmd_ctbr` laws; and `rotorpy.controllers.quadrotor_control.
SE3Control`). The vehicle parameters are read from rotorpy's own parameter dicts.

Why a port: rotorpy steps with `scipy.integrate.solve_ivp` and scipy `Rotation` objects, about
12 ms per 10 ms step on the development machine, i.e. 45 minutes for the benchmark's flights;
this port takes seconds. `tests/test_rotorpy_flights.py` checks it against rotorpy itself: the
state derivative, the low-level motor commands and the SE3 set-points to round-off, and a
closed-loop flight stepped by rotorpy's `Multirotor.step`.

State s (20,), rotorpy's layout: position (3, m, world z up), velocity (3, m/s, world), attitude
quaternion body to world (4, x y z w), body rates (3, rad/s, FLU), wind (3, zero here), rotor
speeds (4, rad/s).
"""

from __future__ import annotations

import math

import numpy as np

from gpquad.engine.kernels.quaternion import rotation_matrix
from gpquad.engine.numba_config import njit

#: Indices into the scalar parameter array of `vehicle_arrays`.
(
    MASS,
    GRAV,
    K_ETA,
    K_M,
    K_D,
    K_Z,
    K_H,
    K_FLAP,
    C_DX,
    C_DY,
    C_DZ,
    TAU_M,
    W_MIN,
    W_MAX,
    K_W,
    KP_ATT,
    KD_ATT,
) = range(17)
#: Control abstractions (rotorpy names cmd_ctatt, cmd_ctbr).
CTATT, CTBR = 0, 1
#: SE3Control's position gains (rotorpy 3.0.0, fixed in its constructor).
SE3_KP_POS = np.array([6.5, 6.5, 15.0])
SE3_KD_POS = np.array([4.0, 4.0, 9.0])
GRAVITY = 9.81  # rotorpy's g, m/s^2
#: SE3Control's attitude gains when a vehicle's parameters give none (rotorpy 3.0.0).
DEFAULT_KP_ATT, DEFAULT_KD_ATT = 3000.0, 360.0


def vehicle_arrays(params: dict, k_w: float | None = None) -> tuple:
    """The kernels' vehicle tuple from a rotorpy `quad_params` dict.

    Returns (scalars (17,), inertia (3, 3), inverse inertia (3, 3), rotor positions (4, 3) m,
    rotor directions (4,), thrust-and-moment-to-rotor-force matrix (4, 4)); the allocation is
    built exactly as rotorpy builds it. `k_w` overrides the body-rate gain of `cmd_ctbr`.
    """
    p = params
    scal = np.array(
        [
            p["mass"],
            GRAVITY,
            p["k_eta"],
            p["k_m"],
            p.get("k_d", 0.0),
            p.get("k_z", 0.0),
            p.get("k_h", 0.0),
            p.get("k_flap", 0.0),
            p.get("c_Dx", 0.0),
            p.get("c_Dy", 0.0),
            p.get("c_Dz", 0.0),
            p["tau_m"],
            p["rotor_speed_min"],
            p["rotor_speed_max"],
            p.get("k_w", 1.0) if k_w is None else k_w,
            p.get("kp_att", DEFAULT_KP_ATT),
            p.get("kd_att", DEFAULT_KD_ATT),
        ],
        dtype=float,
    )
    inertia = np.array(
        [
            [p["Ixx"], p["Ixy"], p["Ixz"]],
            [p["Ixy"], p["Iyy"], p["Iyz"]],
            [p["Ixz"], p["Iyz"], p["Izz"]],
        ],
        dtype=float,
    )
    geom = np.array([p["rotor_pos"][k] for k in p["rotor_pos"]], dtype=float)
    rotor_dir = np.asarray(p["rotor_directions"], dtype=float)
    if geom.shape != (4, 3):
        raise ValueError("the kernels model quadrotors (4 rotors)")
    e3 = np.array([0.0, 0.0, 1.0])
    f_to_tm = np.vstack(
        (
            np.ones((1, 4)),
            np.hstack([np.cross(r, e3).reshape(-1, 1)[0:2] for r in geom]),
            (p["k_m"] / p["k_eta"] * rotor_dir).reshape(1, -1),
        )
    )
    return (scal, inertia, np.linalg.inv(inertia), geom, rotor_dir, np.linalg.inv(f_to_tm))


def hover_rotor_speed(params: dict) -> float:
    """Rotor speed (rad/s) at which four rotors carry the vehicle's weight."""
    return math.sqrt(params["mass"] * GRAVITY / (4.0 * params["k_eta"]))


@njit(inner=True)
def quat_matrix(q, out):
    """Rotation matrix of quaternion q (x, y, z, w), normalised first (as scipy does)."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    rotation_matrix(q[3] / n, q[0] / n, q[1] / n, q[2] / n, out)


@njit(inner=True)
def matrix_quat(m, out):
    """Quaternion (x, y, z, w), w >= 0, of a rotation matrix (Shepperd's method)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(1.0 + tr)
        out[3], out[0] = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        out[1], out[2] = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        out[3], out[0] = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        out[1], out[2] = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        out[3], out[0] = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        out[1], out[2] = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        out[3], out[0] = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        out[1], out[2] = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    if out[3] < 0.0:
        for i in range(4):
            out[i] = -out[i]


@njit(inner=True)
def attitude_error(r, r_des, out):
    """rotorpy's vee(0.5 (R_des^T R - R^T R_des)), rad."""
    s = 0.5 * (r_des.T @ r - r.T @ r_des)
    out[0], out[1], out[2] = -s[1, 2], s[0, 2], -s[0, 1]


@njit
def state_derivative(s, cmd_speeds, veh, out):
    """Multirotor._s_dot_fn with aero on: out (20,) = ds/dt for constant rotor commands."""
    scal, inertia, inv_inertia, geom, rotor_dir, _ = veh
    r = np.empty((3, 3))
    quat_matrix(s[6:10], r)
    w = s[10:13]
    q0, q1, q2, q3 = s[6], s[7], s[8], s[9]
    out[0:3] = s[3:6]
    out[6] = 0.5 * (q3 * w[0] - q2 * w[1] + q1 * w[2])
    out[7] = 0.5 * (q2 * w[0] + q3 * w[1] - q0 * w[2])
    out[8] = 0.5 * (-q1 * w[0] + q0 * w[1] + q3 * w[2])
    out[9] = 0.5 * (-q0 * w[0] - q1 * w[1] - q2 * w[2])
    va = r.T @ (s[3:6] - s[13:16])  # body airspeed
    speed = math.sqrt(va[0] ** 2 + va[1] ** 2 + va[2] ** 2)
    force = np.array(
        [-speed * scal[C_DX] * va[0], -speed * scal[C_DY] * va[1], -speed * scal[C_DZ] * va[2]]
    )
    moment = np.zeros(3)
    for k in range(4):
        rk = geom[k]
        om = s[16 + k]
        loc = va + np.cross(w, rk)
        f = np.array(
            [
                -om * scal[K_D] * loc[0],
                -om * scal[K_D] * loc[1],
                scal[K_ETA] * om * om
                + scal[K_H] * (loc[0] ** 2 + loc[1] ** 2)
                - om * scal[K_Z] * loc[2],
            ]
        )
        force += f
        moment += np.cross(rk, f)
        moment[0] += -scal[K_FLAP] * om * loc[1]
        moment[1] += scal[K_FLAP] * om * loc[0]
        moment[2] += rotor_dir[k] * scal[K_M] * om * om
    fw = r @ force
    m = scal[MASS]
    out[3] = fw[0] / m
    out[4] = fw[1] / m
    out[5] = (-m * scal[GRAV] + fw[2]) / m
    out[10:13] = inv_inertia @ (moment - np.cross(w, inertia @ w))
    out[13:16] = 0.0
    for k in range(4):
        out[16 + k] = (cmd_speeds[k] - s[16 + k]) / scal[TAU_M]


@njit
def motor_commands(s, thrust, command, mode, veh, out):
    """Multirotor.get_cmd_motor_speeds, clipped as Multirotor.step clips them.

    mode CTATT: command = attitude set-point quaternion (x, y, z, w); CTBR: command[:3] = body
    rate set-points (rad/s). thrust: collective thrust set-point, N.
    """
    scal, inertia, _, _, _, tm_to_f = veh
    w = s[10:13]
    if mode == CTATT:
        r = np.empty((3, 3))
        r_des = np.empty((3, 3))
        quat_matrix(s[6:10], r)
        quat_matrix(command, r_des)
        err = np.empty(3)
        attitude_error(r, r_des, err)
        mom = inertia @ (-scal[KP_ATT] * err - scal[KD_ATT] * w) + np.cross(w, inertia @ w)
    else:
        mom = inertia @ (-scal[K_W] * (w - command[:3]))
    tm = np.array([thrust, mom[0], mom[1], mom[2]])
    f = tm_to_f @ tm
    for k in range(4):
        v = f[k] / scal[K_ETA]
        sp = math.copysign(math.sqrt(abs(v)), v) if v != 0.0 else 0.0
        out[k] = min(max(sp, scal[W_MIN]), scal[W_MAX])


@njit
def vehicle_step(s, cmd_speeds, veh, dt, out):
    """One Multirotor.step with classic RK4 in place of solve_ivp; renormalises the attitude
    and clips the rotor speeds as rotorpy does."""
    k1, k2, k3, k4 = np.empty(20), np.empty(20), np.empty(20), np.empty(20)
    state_derivative(s, cmd_speeds, veh, k1)
    state_derivative(s + 0.5 * dt * k1, cmd_speeds, veh, k2)
    state_derivative(s + 0.5 * dt * k2, cmd_speeds, veh, k3)
    state_derivative(s + dt * k3, cmd_speeds, veh, k4)
    out[:] = s + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    out[6:10] /= math.sqrt(out[6] ** 2 + out[7] ** 2 + out[8] ** 2 + out[9] ** 2)
    for k in range(4):
        out[16 + k] = min(max(out[16 + k], veh[0][W_MIN]), veh[0][W_MAX])


@njit
def se3_setpoint(s, ref, mass, r_des):
    """SE3Control.update's thrust (N, returned) and attitude set-point (r_des, 3 x 3).

    ref (10,): position, velocity, acceleration (world, m, m/s, m/s^2) and yaw (rad).
    """
    f_des = mass * (
        -SE3_KP_POS * (s[0:3] - ref[0:3])
        - SE3_KD_POS * (s[3:6] - ref[3:6])
        + ref[6:9]
        + np.array([0.0, 0.0, GRAVITY])
    )
    r = np.empty((3, 3))
    quat_matrix(s[6:10], r)
    u1 = f_des[0] * r[0, 2] + f_des[1] * r[1, 2] + f_des[2] * r[2, 2]
    b3 = f_des / math.sqrt(f_des @ f_des)
    c1 = np.array([math.cos(ref[9]), math.sin(ref[9]), 0.0])
    b2 = np.cross(b3, c1)
    b2 /= math.sqrt(b2 @ b2)
    b1 = np.cross(b2, b3)
    for i in range(3):
        r_des[i, 0], r_des[i, 1], r_des[i, 2] = b1[i], b2[i], b3[i]
    return u1


@njit(inner=True)
def euler_zyx(m):
    """(roll, pitch, yaw) of R = Rz(yaw) Ry(pitch) Rx(roll), rad."""
    return (
        math.atan2(m[2, 1], m[2, 2]),
        math.asin(min(1.0, max(-1.0, -m[2, 0]))),
        math.atan2(m[1, 0], m[0, 0]),
    )


@njit(inner=True)
def zyx_matrix(roll, pitch, yaw, out):
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    out[0, 0], out[0, 1], out[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    out[1, 0], out[1, 1], out[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    out[2, 0], out[2, 1], out[2, 2] = -sp, cp * sr, cp * cr


@njit
def fly(s0, veh, mode, ref, excitation, rate_gain, sub_steps, dt, states, commands):
    """Fly rotorpy's vehicle under the SE3 controller plus set-point excitation.

    Per outer tick k (ref (N, 10), excitation (N, 4): roll, pitch, yaw, thrust/weight):
    states[k] (20,) is logged, then SE3Control gives thrust and attitude set-points.
    CTATT: roll/pitch/yaw of the set-point get excitation[k, :3] (rad); CTBR: body rates
    -rate_gain * attitude error + excitation[k, :3] (rad/s). Thrust gets
    excitation[k, 3] * weight. commands[k] = (thrust N, quaternion x y z w | rates p q r, 0).
    The vehicle then takes sub_steps steps of dt, its low-level law recomputed each step.
    Returns the number of ticks flown (< N if the state became non-finite).
    """
    n = ref.shape[0]
    mass = veh[0][MASS]
    weight = mass * veh[0][GRAV]
    s = s0.copy()
    nxt = np.empty(20)
    r = np.empty((3, 3))
    r_des = np.empty((3, 3))
    r_cmd = np.empty((3, 3))
    err = np.empty(3)
    cmd = np.zeros(4)
    speeds = np.empty(4)
    for k in range(n):
        if not np.all(np.isfinite(s)):
            return k
        states[k] = s
        u1 = se3_setpoint(s, ref[k], mass, r_des)
        thrust = u1 + excitation[k, 3] * weight
        if mode == CTATT:
            roll, pitch, yaw = euler_zyx(r_des)
            zyx_matrix(
                roll + excitation[k, 0], pitch + excitation[k, 1], yaw + excitation[k, 2], r_cmd
            )
            matrix_quat(r_cmd, cmd)
        else:
            quat_matrix(s[6:10], r)
            attitude_error(r, r_des, err)
            for i in range(3):
                cmd[i] = -rate_gain * err[i] + excitation[k, i]
            cmd[3] = 0.0
        commands[k, 0] = thrust
        commands[k, 1:] = cmd
        for _ in range(sub_steps):
            motor_commands(s, thrust, cmd, mode, veh, speeds)
            vehicle_step(s, speeds, veh, dt, nxt)
            s[:] = nxt
    return n
