"""One BLAS code path on every x86-64 machine, so that a seed gives the same equations there.

numpy's and scipy's OpenBLAS choose their kernels by CPU when they load: the SkylakeX kernels
on a CPU with AVX-512, the Haswell ones (AVX2 and FMA) on one without, such as an AMD EPYC.
The two sum a product in another order, and a search amplifies such last bits into other
equations: the same config and seed found other equations on the two kinds of machine
(docs/decisions/2026-11-28-blas-kernels.md).

`pin` asks OpenBLAS for its Haswell kernels wherever the CPU has AVX2 and FMA, before numpy
loads (gpquad's package import calls it first). The processes a run starts inherit the
variable. It leaves the choice alone where a user set OPENBLAS_CORETYPE, where numpy or scipy
is loaded already (their BLAS has chosen), off x86-64, and where the CPU's flags cannot be
read (/proc/cpuinfo: Linux) or lack AVX2 or FMA (Haswell kernels would not run there).
`state` says which kernels this process runs, for a result's provenance.
"""

from __future__ import annotations

import os
import platform
import sys

#: The environment variable OpenBLAS reads when it loads, and the kernels gpquad asks for.
VARIABLE = "OPENBLAS_CORETYPE"
CORE = "Haswell"
#: The CPU flags (as /proc/cpuinfo names them) that the Haswell kernels need.
NEEDS = ("avx2", "fma")
#: Modules that load an OpenBLAS: once one is loaded, setting the variable changes nothing.
LOADERS = ("numpy", "scipy")
#: Why this process could not pin (numpy loaded first on a CPU that runs CORE), for `late`.
_missed: dict[str, str] = {}


def cpu_flags(path: str = "/proc/cpuinfo") -> frozenset[str]:
    """The first processor's flags (empty where they cannot be read)."""
    try:
        with open(path) as fh:
            for line in fh:
                if line.startswith("flags"):
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return frozenset()


def pinnable(flags: frozenset[str], arch: str) -> bool:
    """Whether the Haswell kernels run on a CPU of architecture `arch` with `flags`."""
    return arch.lower() in ("x86_64", "amd64") and all(f in flags for f in NEEDS)


def pin(environ=None, modules=None, flags=None, arch=None, loaded_kernels=None) -> bool:
    """Set VARIABLE to CORE in `environ` (os.environ) if no BLAS is loaded yet and the user
    chose none, on a CPU that runs those kernels; returns whether it did. Where a BLAS is
    loaded already, VARIABLE is set to the kernels it chose, so that the worker processes a
    run starts compute as this one does (the same equations for any number of them). The
    arguments stand in for the process's environment, modules, CPU flags, architecture and
    loaded kernels (tests)."""
    environ = os.environ if environ is None else environ
    modules = sys.modules if modules is None else modules
    if VARIABLE in environ:
        return False
    flags = cpu_flags() if flags is None else flags
    can = pinnable(flags, platform.machine() if arch is None else arch)
    if any(name in modules for name in LOADERS):
        kernels = state()["kernels"] if loaded_kernels is None else loaded_kernels
        if kernels != "unknown":
            environ[VARIABLE] = kernels
        if can and kernels.lower() != CORE.lower():
            _missed["kernels"] = kernels
        return False
    if not can:
        return False
    environ[VARIABLE] = CORE
    return True


def late() -> str | None:
    """A warning where numpy was loaded before gpquad on a CPU where gpquad would have
    pinned other BLAS kernels than numpy chose (None otherwise): a notebook's order of
    imports, which the command line does not have."""
    kernels = _missed.get("kernels")
    if kernels is None:
        return None
    return (
        f"numpy was imported before gpquad, so its BLAS runs this CPU's {kernels} kernels, "
        f"not the {CORE} ones gpquad uses everywhere else: the equations may differ from "
        "those of `gpquad run` or of another machine for the same seed; import gpquad "
        f"before numpy (or set {VARIABLE}={CORE})"
    )


def state() -> dict:
    """The BLAS this process runs: {"library", "kernels", "same_everywhere"}; the last says
    whether they are the kernels gpquad pins (the same bits as other x86-64 machines)."""
    import numpy  # noqa: F401  (its BLAS, loaded)
    from threadpoolctl import threadpool_info

    blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    if not blas:
        return {"library": "unknown", "kernels": "unknown", "same_everywhere": False}
    info = blas[0]
    kernels = str(info.get("architecture", "unknown"))
    return {
        "library": f"{info.get('internal_api', 'unknown')} {info.get('version', '')}".strip(),
        "kernels": kernels,
        "same_everywhere": kernels.lower() == CORE.lower(),
    }
