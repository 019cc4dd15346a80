"""The one place where numba flags are set (STUMPY's habit); the CPU numba compiles for is
recorded by gpquad._machine.

fastmath stays off: kernels rely on NaN/inf checks to flag diverging trajectories.

A kernel that only other kernels call is compiled `inner`: without the wrappers that let
Python (and C callbacks) call it. Nothing calls those wrappers, and a cold start would
build them for every kernel (docs/decisions/2026-11-28-inner-kernels.md).

The compiled kernels are cached in a folder named by a digest of every kernel source
(`KERNEL_SOURCES`, `cache_folder`). numba keys a cached kernel on its own file only, so a
kernel that inlines a helper from another file would otherwise keep the helper's old code
after that file changed (an edit, a `git pull` into an editable install).
"""

import contextlib
import functools
import hashlib
import os
import shutil
import time
import types
from pathlib import Path

import numba
from numba.core import config
from numba.core.registry import CPUDispatcher

NJIT = {"cache": True, "nogil": True, "fastmath": False, "error_model": "numpy"}

#: The target options of an inner kernel beyond NJIT's.
INNER = {"nopython": True, "no_cpython_wrapper": True, "no_cfunc_wrapper": True}


#: Every source file whose code or constants a kernel compiles in, relative to the package:
#: the files that define kernels and the gpquad modules they import
#: (tests/test_kernel_cache.py checks that the list is whole).
KERNEL_SOURCES = (
    "engine/kernels/*.py",
    "engine/numba_config.py",
    "engine/tree/encoding.py",
    "engine/tree/mutation_kernel.py",
    "engine/tree/operators.py",
    "baselines/body_kernels.py",
    "baselines/quad12_kernels.py",
    "benchmark/rollout.py",
    "benchmark/rotorpy_model.py",
    "control/lq_kernel.py",
    "control/pid_kernel.py",
)
PACKAGE = Path(__file__).resolve().parent.parent


def kernel_files(root: Path = PACKAGE, patterns=KERNEL_SOURCES) -> list[Path]:
    """The files of `patterns` under root, sorted."""
    return sorted({f for pattern in patterns for f in root.glob(pattern)})


def sources_digest(files, root: Path = PACKAGE) -> str:
    """A digest of the files' paths (relative to root) and contents."""
    h = hashlib.sha256()
    for f in files:
        h.update(Path(f).relative_to(root).as_posix().encode() + b"\0")
        h.update(Path(f).read_bytes() + b"\0")
    return h.hexdigest()[:16]


#: A cache folder of other kernel sources (an older gpquad) not used for this many days is
#: deleted when gpquad starts.
STALE_DAYS = 30


def cache_folder(digest: str) -> Path:
    """Where the kernels of sources with `digest` are cached: under NUMBA_CACHE_DIR when it
    is set, else under the user's cache folder (XDG_CACHE_HOME, default ~/.cache), else,
    when that cannot be made, in the package's __pycache__. The user cache folder's time
    is set to now (its last use) and its stale siblings are deleted (`prune_stale`)."""
    name = f"kernels-{digest}"
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"]) / name
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gpquad" / name
    try:
        user.mkdir(parents=True, exist_ok=True)
        os.utime(user)
    except OSError:
        return PACKAGE / "__pycache__" / name
    prune_stale(user.parent, user)
    return user


def prune_stale(parent: Path, keep: Path, days: float = STALE_DAYS) -> list[Path]:
    """Delete the kernels-* folders of `parent` other than `keep` last used (their time)
    more than `days` ago; returns them."""
    now = time.time()
    gone = []
    for folder in parent.glob("kernels-*"):
        try:
            stale = folder != keep and now - folder.stat().st_mtime > days * 86400
        except OSError:
            continue
        if stale and folder.is_dir():
            shutil.rmtree(folder, ignore_errors=True)
            gone.append(folder)
    return gone


CACHE_FOLDER = cache_folder(sources_digest(kernel_files()))


@contextlib.contextmanager
def _caching_in(folder: Path):
    """numba's cache folder set to `folder` while a kernel is created (its cache locator
    reads it then), and given back afterwards: other packages' numba caches do not move."""
    previous = config.CACHE_DIR
    config.CACHE_DIR = str(folder)
    try:
        yield
    finally:
        config.CACHE_DIR = previous


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
            with _caching_in(CACHE_FOLDER):
                return numba.njit(**flags)(f)
        options = {k: v for k, v in flags.items() if k != "cache"}
        kernel = InnerDispatcher(py_func=f, locals={}, targetoptions={**options, **INNER})
        if flags["cache"]:
            with _caching_in(CACHE_FOLDER):
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
