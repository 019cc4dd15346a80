"""One BLAS code path on every x86-64 machine (gpquad._blas): OpenBLAS's Haswell kernels are
asked for before numpy loads, so that another kind of CPU finds the same equations; where
numpy loaded first, the worker processes compute as the parent does and gpquad.fit says so."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from gpquad import _blas
from gpquad._blas import CORE, VARIABLE, cpu_flags, late, pin

X86 = frozenset({"sse2", "avx", "avx2", "fma", "avx512f"})


@pytest.fixture(autouse=True)
def no_missed_pin(monkeypatch):
    monkeypatch.setattr(_blas, "_missed", {})


def test_pins_the_haswell_kernels_before_numpy_loads():
    environ: dict = {}
    assert pin(environ, modules={}, flags=X86, arch="x86_64")
    assert environ == {VARIABLE: CORE}
    assert late() is None


@pytest.mark.parametrize(
    "flags, arch",
    [
        (X86 - {"avx2"}, "x86_64"),  # the kernels would not run
        (X86 - {"fma"}, "x86_64"),
        (frozenset(), "x86_64"),  # flags unknown (no /proc/cpuinfo)
        (frozenset({"asimd", "fp"}), "aarch64"),
    ],
)
def test_leaves_cpus_that_cannot_run_them(flags, arch):
    environ: dict = {}
    assert not pin(environ, modules={}, flags=flags, arch=arch)
    assert environ == {}


def test_a_users_choice_wins():
    environ = {VARIABLE: "SkylakeX"}
    assert not pin(environ, modules={}, flags=X86, arch="x86_64")
    assert environ == {VARIABLE: "SkylakeX"}


def test_numpy_loaded_first_keeps_the_workers_with_the_parent_and_warns():
    environ: dict = {}
    modules = {"numpy": object()}
    assert not pin(environ, modules, flags=X86, arch="x86_64", loaded_kernels="SkylakeX")
    assert environ == {VARIABLE: "SkylakeX"}  # the processes a run starts compute as this one
    why = late()
    assert why is not None and "SkylakeX" in why and "import gpquad before numpy" in why


def test_numpy_loaded_first_with_the_same_kernels_needs_no_warning():
    environ: dict = {}
    pin(environ, {"numpy": object()}, flags=X86, arch="x86_64", loaded_kernels="Haswell")
    assert environ == {VARIABLE: "Haswell"} and late() is None
    pin({}, {"numpy": object()}, flags=X86 - {"avx2"}, arch="x86_64", loaded_kernels="Sandybridge")
    assert late() is None  # gpquad could not have pinned there either


def test_cpu_flags_read_from_cpuinfo(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nmodel name\t: Some CPU\nflags\t\t: fpu sse2 avx2 fma\n")
    assert cpu_flags(str(info)) == {"fpu", "sse2", "avx2", "fma"}
    assert cpu_flags(str(tmp_path / "missing")) == frozenset()


def _in_a_new_process(code: str) -> str:
    env = {k: v for k, v in os.environ.items() if k != VARIABLE}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


@pytest.mark.skipif(
    not _blas.pinnable(cpu_flags(), __import__("platform").machine()),
    reason="a CPU without AVX2 and FMA keeps its own kernels",
)
def test_importing_gpquad_first_runs_the_haswell_kernels():
    show = "import os; from gpquad._blas import state; print(os.environ['{v}'], state()['kernels'])"
    assert _in_a_new_process("import gpquad, numpy; " + show.format(v=VARIABLE)) == (
        f"{CORE} {CORE}"
    )
    # numpy first: whatever it chose, the variable names it, for the worker processes
    first = _in_a_new_process("import numpy, gpquad; " + show.format(v=VARIABLE))
    variable, kernels = first.split()
    assert variable == kernels


def test_fit_warns_where_numpy_chose_other_kernels(monkeypatch, capsys):
    import gpquad

    monkeypatch.setattr(_blas, "_missed", {"kernels": "SkylakeX"})
    flight = gpquad.reference_flight(seed=0, duration_s=20.0)
    gpquad.fit(flight, seed=1, iterations=1, targets=["p_dot"], jobs=1)
    err = capsys.readouterr().err
    assert "gpquad: warning: numpy was imported before gpquad" in err
