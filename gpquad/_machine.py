"""The machine a result is computed on: its CPU, and one BLAS code path on every Linux
x86-64 machine, so that a seed gives the same equations there.

numpy's and scipy's OpenBLAS (the pip wheels) choose their kernels by CPU when they load:
the SkylakeX kernels on a CPU with AVX-512, the Haswell ones (AVX2 and FMA) on one without,
such as an AMD EPYC. The two sum a product in another order, and a search amplifies such
last bits into other equations: the same config and seed found other equations on the two
kinds of machine (docs/decisions/2026-11-28-blas-kernels.md).

`pin` asks OpenBLAS for its Haswell kernels wherever the CPU has AVX2 and FMA, before numpy
loads (gpquad's package import calls it first; this module imports only the standard
library). It sets OPENBLAS_CORETYPE for the whole process, and the processes it starts
inherit it. It leaves the choice alone where a user set OPENBLAS_CORETYPE (to their CPU's
own kernels, say), off x86-64, where the CPU's flags cannot be read (/proc/cpuinfo: Linux)
or lack AVX2 or FMA (the kernels would not run), and where numpy or scipy is loaded
already: their BLAS has chosen. There the variable is set to the kernels numpy chose,
marked as followed (FOLLOWS), so that the processes a fit starts compute as this one does;
`late` then words a warning, here and in those processes.

`machine` is what a result's provenance records (run.json, benchmark.json, sweeps,
`gpquad bench`): the CPU's model, the CPU numba compiles the kernels for, the cores and
every BLAS library with its kernels (`blas_state`). The same seed gives the same bits on
one machine for any --jobs.
"""

from __future__ import annotations

import os
import platform
import sys

CPUINFO = "/proc/cpuinfo"


def cpuinfo(field: str, path: str = CPUINFO) -> str | None:
    """The first processor's `field` in /proc/cpuinfo (None where it cannot be read)."""
    try:
        with open(path) as fh:
            for line in fh:
                name, sep, value = line.partition(":")
                if sep and name.strip() == field:
                    return value.strip()
    except OSError:
        pass
    return None


def cpu_model() -> str:
    """The processor's model name (/proc/cpuinfo on Linux, else the platform's word)."""
    return cpuinfo("model name") or platform.processor() or platform.machine() or "unknown"


def cpu_flags(path: str = CPUINFO) -> frozenset[str]:
    """The first processor's flags (empty where they cannot be read)."""
    return frozenset((cpuinfo("flags", path) or "").split())


#: The environment variable OpenBLAS reads when it loads, and the kernels gpquad asks for.
VARIABLE = "OPENBLAS_CORETYPE"
CORE = "Haswell"
#: Set beside VARIABLE where gpquad followed a BLAS loaded before it (not a user's choice).
FOLLOWS = "GPQUAD_BLAS_FOLLOWS"
#: The CPU flags (as /proc/cpuinfo names them) that the Haswell kernels need.
NEEDS = ("avx2", "fma")
#: Modules that load an OpenBLAS: once one is loaded, setting the variable changes nothing.
LOADERS = ("numpy", "scipy")
#: The kernels this process follows instead of CORE (a BLAS loaded first), for `late`.
_missed: dict[str, str] = {}


def pinnable(flags: frozenset[str], arch: str) -> bool:
    """Whether the Haswell kernels run on a CPU of architecture `arch` with `flags`."""
    return arch.lower() in ("x86_64", "amd64") and all(f in flags for f in NEEDS)


def _is_core(kernels: str) -> bool:
    return kernels.strip().lower() == CORE.lower()


def pin(environ=None, modules=None, flags=None, arch=None, loaded_kernels=None) -> bool:
    """Set VARIABLE to CORE in `environ` (os.environ) if no BLAS is loaded yet and the user
    chose none, on a CPU that runs those kernels; returns whether it did (module notes).
    The arguments stand in for the process's environment, modules, CPU flags, architecture
    and the loaded BLAS's kernels (tests)."""
    environ = os.environ if environ is None else environ
    modules = sys.modules if modules is None else modules
    flags = cpu_flags() if flags is None else flags
    can = pinnable(flags, platform.machine() if arch is None else arch)
    chosen = environ.get(VARIABLE, "").strip()
    if chosen:  # the user's, or followed by a parent process (then said again here)
        if can and environ.get(FOLLOWS) == chosen and not _is_core(chosen):
            _missed["kernels"] = chosen
        return False
    if any(name in modules for name in LOADERS):
        kernels = _loaded_kernels() if loaded_kernels is None else loaded_kernels
        if kernels:  # "" from a test: another BLAS
            environ[VARIABLE] = environ[FOLLOWS] = kernels
            if can and not _is_core(kernels):
                _missed["kernels"] = kernels
        return False
    if not can:
        return False
    environ[VARIABLE] = CORE
    return True


def late() -> str | None:
    """A warning where this process runs other OpenBLAS kernels than CORE because numpy was
    loaded before gpquad (here or in the process that started this one), on a CPU where
    gpquad would have pinned CORE; None otherwise."""
    kernels = _missed.get("kernels")
    if kernels is None:
        return None
    return (
        f"numpy was imported before gpquad, so its BLAS runs this CPU's {kernels} kernels, "
        f"not the {CORE} ones gpquad pins on other Linux x86-64 machines: the equations may "
        "differ from theirs for the same seed; import gpquad before numpy, or start Python "
        f"with {VARIABLE}={CORE}"
    )


def warn_if_late() -> None:
    """Print `late`'s warning, if any, as one line on standard error (the command line and
    gpquad.fit, before any work)."""
    if (why := late()) is not None:
        print(f"gpquad: warning: {why}", file=sys.stderr)


def _blas_info() -> list[dict]:
    """[{"library", "file", "kernels"}]: threadpoolctl's BLAS entries of this process ([] if
    it cannot tell)."""
    try:
        from threadpoolctl import threadpool_info

        found = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    except Exception:  # noqa: BLE001  (a provenance or an import must not fail on it)
        return []
    return [
        {
            "library": f"{i.get('internal_api', 'unknown')} {i.get('version') or ''}".strip(),
            "file": os.path.basename(str(i.get("filepath", ""))),
            "kernels": str(i.get("architecture") or "unknown"),
        }
        for i in found
    ]


def _loaded_kernels() -> str | None:
    """The OpenBLAS kernels numpy loaded (None for another BLAS, or if unknown)."""
    for entry in _blas_info():
        if entry["library"].startswith("openblas") and entry["kernels"] != "unknown":
            return entry["kernels"]
    return None


def blas_state() -> dict:
    """{"libraries": [{"library", "file", "kernels"}], "pinned"}: every BLAS this process
    runs (numpy's and scipy's are loaded first), and whether all run CORE's kernels."""
    try:
        import numpy  # noqa: F401
        import scipy.linalg  # noqa: F401  (its own OpenBLAS, which the LM's QR runs)
    except ImportError:
        pass
    libraries = _blas_info()
    pinned = bool(libraries) and all(_is_core(lib["kernels"]) for lib in libraries)
    return {"libraries": libraries, "pinned": pinned}


def machine() -> dict:
    """{"cpu", "compiled_for", "cores", "blas"}: the CPU's model, the CPU numba compiles
    the kernels for (LLVM's name of the host, or NUMBA_CPU_NAME), the cores, and the BLAS
    libraries with their kernels (`blas_state`)."""
    from numba.core import config

    target = config.CPU_NAME
    if not target:
        import llvmlite.binding as ll

        target = ll.get_host_cpu_name()
    return {
        "cpu": cpu_model(),
        "compiled_for": str(target),
        "cores": os.cpu_count(),
        "blas": blas_state(),
    }
