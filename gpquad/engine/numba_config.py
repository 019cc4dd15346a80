"""The one place where numba flags are set (STUMPY's habit); the CPU numba compiles for is
recorded by gpquad._machine.

fastmath stays off: kernels rely on NaN/inf checks to flag diverging trajectories.
"""

import numba

NJIT = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}


def njit(func=None, **overrides):
    """numba.njit with the project's flags."""
    flags = {**NJIT, **overrides}
    if func is None:
        return lambda f: numba.njit(**flags)(f)
    return numba.njit(**flags)(func)
