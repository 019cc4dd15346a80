"""Inner kernels (gpquad.engine.numba_config): compiled without the wrappers that let Python
call them, callable from other kernels, and a clear TypeError (not a crash) from Python."""

import ast
import importlib
import pkgutil
from pathlib import Path

import numba
import numpy as np
import pytest

import gpquad
import gpquad.engine.kernels
from gpquad.engine import numba_config
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


def _cache_index(kernel):
    return kernel._cache._cache_file._index_path


def test_python_callable_is_cached_apart_from_the_inner_kernel():
    """Under the inner kernel's own cache file, a Python call could load code compiled
    without an entry for Python: a plain numba.njit of the same function would share it."""
    kernel = kq.euler_from_quat
    copy = python_callable(kernel)
    assert copy.py_func.__code__ is kernel.py_func.__code__
    assert _cache_index(copy) != _cache_index(kernel)
    with numba_config._caching_in(numba_config.CACHE_FOLDER):  # as gpquad's njit caches
        naive = numba.njit(cache=True)(kernel.py_func)
    assert _cache_index(naive) == _cache_index(kernel)  # the case the name guards against


def _jitted(fn) -> bool:
    return any("njit" in ast.unparse(d) for d in fn.decorator_list)


def python_calls_of_inner(sources: dict[str, str]) -> list[str]:
    """Calls, from Python code (outside any njit function), of a function some source
    decorates @njit(inner=True): each would raise at run time."""
    trees = {name: ast.parse(text) for name, text in sources.items()}
    inner = {
        fn.name
        for tree in trees.values()
        for fn in tree.body
        if isinstance(fn, ast.FunctionDef)
        and any("inner=True" in ast.unparse(d) for d in fn.decorator_list)
    }
    found = []

    def visit(node, name, in_kernel):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                visit(child, name, in_kernel or _jitted(child))
                continue
            if isinstance(child, ast.Call) and not in_kernel:
                f = child.func
                called = f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)
                if called in inner:
                    found.append(f"{name}:{child.lineno} {called}")
            visit(child, name, in_kernel)

    for name, tree in trees.items():
        visit(tree, name, False)
    return found


def test_no_python_code_calls_an_inner_kernel():
    root = Path(gpquad.__file__).parent
    sources = {str(p.relative_to(root)): p.read_text() for p in root.rglob("*.py")}
    assert python_calls_of_inner(sources) == []


def test_the_inner_call_check_finds_a_python_caller():
    kernel = "@njit(inner=True)\ndef helper(x):\n    return x\n"
    caller = (
        "from k import helper\n\n@njit\ndef fine(x):\n    return helper(x)\n\n"
        "def wrong(x):\n    return k.helper(x)\n"
    )
    assert python_calls_of_inner({"k.py": kernel, "c.py": caller}) == ["c.py:8 helper"]
