"""The one table of state variables, targets and default inputs.

The state passed to every model is x = [phi, theta, psi, u, v, w, p, q, r]
(Euler angles in rad from the body-to-world quaternion, body velocity in m/s,
body rates in rad/s), as in the paper's eq. (1). Everything else (kernel
terminal indices, export names, units) is derived from this module.
"""

STATE_NAMES: tuple[str, ...] = ("phi", "theta", "psi", "u", "v", "w", "p", "q", "r")
STATE_UNITS: tuple[str, ...] = ("rad", "rad", "rad", "m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s")
STATE_LATEX: tuple[str, ...] = (r"\phi", r"\theta", r"\psi", "u", "v", "w", "p", "q", "r")
N_STATE = len(STATE_NAMES)

TARGET_NAMES: tuple[str, ...] = ("a_x", "a_y", "a_z", "p_dot", "q_dot", "r_dot")
TARGET_UNITS: tuple[str, ...] = ("m/s^2",) * 3 + ("rad/s^2",) * 3
TARGET_LATEX: tuple[str, ...] = ("a_x", "a_y", "a_z", r"\dot{p}", r"\dot{q}", r"\dot{r}")
#: The state variable that each target's acceleration integrates into.
TARGET_STATE: dict[str, str] = {
    "a_x": "u",
    "a_y": "v",
    "a_z": "w",
    "p_dot": "p",
    "q_dot": "q",
    "r_dot": "r",
}

DEFAULT_INPUTS: tuple[str, ...] = ("u_P", "u_R", "u_Y", "u_T")
MAX_INPUTS = 8

#: Generic flight-file columns (see gpquad.data.flight).
QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
BODY_VEL_COLUMNS = ("u", "v", "w")
WORLD_VEL_COLUMNS = ("vx", "vy", "vz")
RATE_COLUMNS = ("p", "q", "r")
POSITION_COLUMNS = ("x", "y", "z")


def target_index(name: str) -> int:
    """Index 0..5 of a target name (a_x ... r_dot)."""
    return TARGET_NAMES.index(name)


def terminal_names(input_names) -> tuple[str, ...]:
    """Names of the tree leaves that are variables: the 9 states, then the inputs."""
    return STATE_NAMES + tuple(input_names)


def input_latex(name: str, delay: int) -> str:
    """LaTeX of a (possibly delayed) input: u_T with delay 5 -> u_{T-5}."""
    base, _, sub = name.partition("_")
    if not sub:
        return f"{name}(t-{delay})" if delay else name
    return f"{base}_{{{sub}-{delay}}}" if delay else f"{base}_{{{sub}}}"
