"""The one place where numba flags are set (STUMPY's habit); the CPU numba compiles for is
recorded by gpquad._machine.

fastmath stays off: kernels rely on NaN/inf checks to flag diverging trajectories.

A kernel that only other kernels call is compiled `inner`: without the wrappers that let
Python (and C callbacks) call it. Nothing calls those wrappers, and a cold start would
build them for every kernel (docs/decisions/2026-11-28-inner-kernels.md).
"""

import functools
import types

import numba
from numba.core import config
from numba.core.registry import CPUDispatcher

NJIT = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}

#: The target options of an inner kernel beyond NJIT's.
INNER = {"nopython": True, "no_cpython_wrapper": True, "no_cfunc_wrapper": True}


class InnerDispatcher(CPUDispatcher):
    """A kernel compiled for calls from other kernels only. Its compiled code has no entry
    for Python, so a call from Python raises TypeError instead of reaching it."""

    def __call__(self, *args, **kwargs):
        name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
        raise TypeError(
            f"{name} is compiled for calls from other kernels only: call it from a kernel, "
            "or from Python through gpquad.engine.numba_config.python_callable"
        )


def njit(func=None, *, inner=False, **overrides):
    """numba.njit with the project's flags; inner=True compiles an InnerDispatcher."""
    flags = {**NJIT, **overrides}

    def decorate(f):
        if not inner or config.DISABLE_JIT:
            return numba.njit(**flags)(f)
        options = {k: v for k, v in flags.items() if k != "cache"}
        kernel = InnerDispatcher(py_func=f, locals={}, targetoptions={**options, **INNER})
        if flags["cache"]:
            kernel.enable_caching()
        return kernel

    return decorate if func is None else decorate(func)


@functools.cache
def python_callable(kernel):
    """An inner kernel's function compiled with its wrappers, for a call from Python (the
    tests). It is cached under a name of its own: under the inner kernel's it would load
    code without an entry for Python."""
    if not isinstance(kernel, InnerDispatcher):
        return kernel
    f = kernel.py_func
    copy = types.FunctionType(f.__code__, f.__globals__, f.__name__, f.__defaults__, f.__closure__)
    copy.__qualname__ = f"{f.__qualname__}__from_python"
    copy.__module__ = f.__module__
    return njit(copy)
