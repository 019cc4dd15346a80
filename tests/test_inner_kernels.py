"""Inner kernels (gpquad.engine.numba_config): compiled without the wrappers that let Python
call them, callable from other kernels, and a clear TypeError (not a crash) from Python."""

import importlib
import pkgutil

import numpy as np
import pytest

import gpquad.engine.kernels
from gpquad.engine.kernels import quaternion as kq
from gpquad.engine.numba_config import InnerDispatcher, njit, python_callable


def inner_kernels():
    found = []
    for info in pkgutil.iter_modules(gpquad.engine.kernels.__path__):
        module = importlib.import_module(f"gpquad.engine.kernels.{info.name}")
        for name, value in vars(module).items():
            if isinstance(value, InnerDispatcher) and value.py_func.__module__ == module.__name__:
                found.append(pytest.param(value, id=f"{info.name}.{name}"))
    return found


@njit(cache=False)
def _euler_in_a_kernel(q0, q1, q2, q3):
    return kq.euler_from_quat(q0, q1, q2, q3)


def test_the_kernels_have_inner_helpers():
    assert len(inner_kernels()) >= 30


@pytest.mark.parametrize("kernel", inner_kernels())
def test_an_inner_kernel_refuses_a_python_call(kernel):
    """Its compiled code has no entry for Python: the call must stop before it, naming
    the way round. (Without the guard this call crashes the interpreter.)"""
    assert kernel.targetoptions["no_cpython_wrapper"] is True
    assert kernel.targetoptions["no_cfunc_wrapper"] is True
    with pytest.raises(TypeError, match="python_callable"):
        kernel()


def test_an_inner_kernel_runs_in_a_kernel_and_through_python_callable():
    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    in_kernel = _euler_in_a_kernel(*q)
    from_python = python_callable(kq.euler_from_quat)(*q)
    assert in_kernel == from_python
    assert not isinstance(python_callable(kq.euler_from_quat), InnerDispatcher)
    assert python_callable(kq.euler_from_quat) is python_callable(kq.euler_from_quat)
    assert python_callable(kq.quat_mul) is kq.quat_mul  # not inner: itself


def test_python_callable_is_cached_apart_from_the_inner_kernel():
    """Under the inner kernel's own cache name, a Python call could load code compiled
    without an entry for Python."""
    copy = python_callable(kq.euler_from_quat)
    assert copy.py_func.__qualname__ != kq.euler_from_quat.py_func.__qualname__
    assert copy.py_func.__code__ is kq.euler_from_quat.py_func.__code__
