"""One BLAS code path on every Linux x86-64 machine (gpquad._machine): OpenBLAS's Haswell kernels
are asked for before numpy loads, so that another kind of CPU finds the same equations;
where numpy loaded first, the processes a fit starts compute as the parent does, and both
gpquad.fit and the command line say so."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pandas as pd
import pytest

from gpquad import _machine
from gpquad._machine import (
    CORE,
    FOLLOWS,
    VARIABLE,
    blas_state,
    cpu_flags,
    cpuinfo,
    late,
    pin,
    pinnable,
)
from gpquad.errors import GpquadError

X86 = frozenset({"sse2", "avx", "avx2", "fma", "avx512f"})


@pytest.fixture(autouse=True)
def no_missed_pin(monkeypatch):
    monkeypatch.setattr(_machine, "_missed", {})


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


def test_a_users_choice_wins_and_an_empty_one_is_none():
    environ = {VARIABLE: "SkylakeX"}
    assert not pin(environ, modules={}, flags=X86, arch="x86_64")
    assert environ == {VARIABLE: "SkylakeX"} and late() is None
    environ = {VARIABLE: " "}  # OpenBLAS ignores it: gpquad pins
    assert pin(environ, modules={}, flags=X86, arch="x86_64")
    assert environ == {VARIABLE: CORE}


def test_numpy_loaded_first_keeps_the_workers_with_the_parent_and_warns():
    environ: dict = {}
    modules = {"numpy": object()}
    assert not pin(environ, modules, flags=X86, arch="x86_64", loaded_kernels="SkylakeX")
    # the processes a run starts compute as this one, and know why
    assert environ == {VARIABLE: "SkylakeX", FOLLOWS: "SkylakeX"}
    why = late()
    assert why is not None and "SkylakeX" in why and "import gpquad before numpy" in why


def test_a_process_started_by_such_a_parent_follows_it_and_warns_too():
    environ = {VARIABLE: "SkylakeX", FOLLOWS: "SkylakeX"}
    assert not pin(environ, modules={}, flags=X86, arch="x86_64")
    assert environ == {VARIABLE: "SkylakeX", FOLLOWS: "SkylakeX"}
    assert late() is not None and "SkylakeX" in late()


def test_no_warning_where_nothing_differs_or_nothing_is_known():
    pin({}, {"numpy": object()}, flags=X86, arch="x86_64", loaded_kernels="Haswell")
    pin({}, {"numpy": object()}, flags=X86 - {"avx2"}, arch="x86_64", loaded_kernels="Sandybridge")
    environ: dict = {}  # another BLAS (MKL, Accelerate): no OpenBLAS kernels to follow
    pin(environ, {"numpy": object()}, flags=X86, arch="x86_64", loaded_kernels="")
    assert late() is None and environ == {}


def test_cpuinfo_fields_are_read(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nmodel name\t: Some CPU\nflags\t\t: fpu sse2 avx2 fma\n")
    assert cpu_flags(str(info)) == {"fpu", "sse2", "avx2", "fma"}
    assert cpuinfo("model name", str(info)) == "Some CPU"
    assert cpu_flags(str(tmp_path / "missing")) == frozenset()


def test_state_names_every_blas_and_whether_all_are_pinned(monkeypatch):
    found = blas_state()
    assert found["libraries"], "numpy's BLAS is listed"
    for lib in found["libraries"]:
        assert set(lib) == {"library", "file", "kernels"}

    def entries(*kernels):
        return lambda: [{"library": "openblas", "file": "x.so", "kernels": k} for k in kernels]

    for kernels, pinned in [
        (("Haswell", "haswell"), True),
        (("Haswell", "SkylakeX"), False),  # scipy's BLAS not pinned: not the same everywhere
        (("unknown",), False),
        ((), False),  # no BLAS that threadpoolctl sees
    ]:
        monkeypatch.setattr(_machine, "_blas_info", entries(*kernels))
        assert blas_state()["pinned"] is pinned, kernels


def _in_a_new_process(code: str, **env) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k not in (VARIABLE, FOLLOWS)}
    return subprocess.run(
        [sys.executable, "-c", code], env={**clean, **env}, capture_output=True, text=True
    )


LOADED = "import sys; print(sorted(m for m in ('numpy', 'scipy') if m in sys.modules))"
#: This process's variable, whether every BLAS runs CORE, and the kernels numpy loaded.
SHOW = (
    "import os; from gpquad._machine import _loaded_kernels, blas_state; "
    f"print(os.environ.get('{VARIABLE}'), blas_state()['pinned'], _loaded_kernels())"
)


def test_importing_gpquad_loads_no_blas_before_it_pins():
    out = _in_a_new_process("import gpquad; " + LOADED)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stderr


PINNABLE = pinnable(cpu_flags(), platform.machine())


@pytest.mark.skipif(not PINNABLE, reason="a CPU without AVX2 and FMA keeps its own kernels")
def test_importing_gpquad_first_runs_the_haswell_kernels():
    variable, _, kernels = _in_a_new_process("import numpy; " + SHOW).stdout.split()
    if kernels == "None":
        pytest.skip("numpy's BLAS is not an OpenBLAS that names its kernels")
    out = _in_a_new_process("import gpquad, numpy; " + SHOW)
    assert out.stdout.split() == [CORE, "True", CORE], out.stderr
    # numpy first: whatever it chose, the variable names it, for the processes a fit starts
    variable, _, kernels = _in_a_new_process("import numpy, gpquad; " + SHOW).stdout.split()
    assert variable == kernels


@pytest.mark.skipif(not PINNABLE, reason="a CPU without AVX2 and FMA keeps its own kernels")
def test_the_command_line_says_it_follows_a_parent_that_loaded_numpy_first():
    out = subprocess.run(
        [sys.executable, "-m", "gpquad", "export", "no-such-run-folder", "--format", "c"],
        env={**os.environ, VARIABLE: "SkylakeX", FOLLOWS: "SkylakeX"},
        capture_output=True,
        text=True,
    )
    assert "gpquad: warning: numpy was imported before gpquad" in out.stderr
    assert out.returncode == 2  # and the command's own error after it


def test_fit_warns_where_numpy_chose_other_kernels(monkeypatch, capsys):
    import gpquad

    monkeypatch.setattr(_machine, "_missed", {"kernels": "SkylakeX"})
    with pytest.raises(GpquadError):  # the warning comes before the data is read
        gpquad.fit(pd.DataFrame({"t": [0.0, 0.04]}))
    assert "gpquad: warning: numpy was imported before gpquad" in capsys.readouterr().err
