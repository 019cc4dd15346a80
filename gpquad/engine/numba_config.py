"""The one place where numba flags are set (STUMPY's habit), and what numba compiles for.

fastmath stays off: kernels rely on NaN/inf checks to flag diverging trajectories.
"""

import os
import platform

import numba

NJIT = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}


def njit(func=None, **overrides):
    """numba.njit with the project's flags."""
    flags = {**NJIT, **overrides}
    if func is None:
        return lambda f: numba.njit(**flags)(f)
    return numba.njit(**flags)(func)


def cpu_model() -> str:
    """The processor's model name (/proc/cpuinfo on Linux, else the platform's word)."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine() -> dict:
    """The machine a result was computed on: the CPU's model, the CPU numba compiles the
    kernels for (LLVM's name of the host, or NUMBA_CPU_NAME), the cores, and the BLAS
    kernels numpy runs (gpquad._blas.state: the same on every x86-64 machine with AVX2 and
    FMA when gpquad loaded before numpy). The same seed gives the same bits on one machine
    for any --jobs; on another kind of CPU, the same wherever "blas" says
    "same_everywhere" on both (docs/decisions/2026-11-28-blas-kernels.md)."""
    from numba.core import config

    from gpquad._blas import state

    target = config.CPU_NAME
    if not target:
        import llvmlite.binding as ll

        target = ll.get_host_cpu_name()
    return {
        "cpu": cpu_model(),
        "compiled_for": str(target),
        "cores": os.cpu_count(),
        "blas": state(),
    }
