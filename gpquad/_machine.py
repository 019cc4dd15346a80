"""The machine a result was computed on, for its provenance (run.json, benchmark.json,
sweeps, `gpquad bench`): the CPU, the CPU numba compiles the kernels for, the cores and
the BLAS kernels (gpquad._blas). Standard library only at import: gpquad._blas reads the
CPU's flags from here before numpy loads.

The same seed gives the same bits on one machine for any --jobs. Across machines, numba's
target did not change a result where it was compared, and OpenBLAS's kernels did until
gpquad pinned them (docs/decisions/2026-11-28-blas-kernels.md).
"""

from __future__ import annotations

import os
import platform

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


def machine() -> dict:
    """{"cpu", "compiled_for", "cores", "blas"}: the CPU's model, the CPU numba compiles
    the kernels for (LLVM's name of the host, or NUMBA_CPU_NAME), the cores, and the BLAS
    libraries with their kernels (gpquad._blas.state)."""
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
