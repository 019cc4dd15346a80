"""Every result records the machine it was computed on (gpquad._machine.machine):
the same seed gives the same bits on one machine, and may round otherwise on another kind of
CPU, so a reader needs to know which."""

from __future__ import annotations

import llvmlite.binding as ll
from numba.core import config

from gpquad import _machine
from gpquad.engine.bench import format_report
from gpquad.study.store import provenance


def test_machine_names_the_cpu_and_the_compile_target(monkeypatch):
    found = _machine.machine()
    assert set(found) == {"cpu", "compiled_for", "cores", "blas"}
    assert found["cpu"] and found["cores"] >= 1
    monkeypatch.setattr(config, "CPU_NAME", None)
    assert _machine.machine()["compiled_for"] == ll.get_host_cpu_name()
    # NUMBA_CPU_NAME makes numba compile for another CPU: that one is recorded
    monkeypatch.setattr(config, "CPU_NAME", "haswell")
    assert _machine.machine()["compiled_for"] == "haswell"


def test_cpu_model_without_proc_cpuinfo(monkeypatch):
    def no_file(*args, **kwargs):
        raise OSError("no /proc here")

    monkeypatch.setattr("builtins.open", no_file)
    assert _machine.cpu_model()  # the platform's word, never empty


def test_provenance_and_bench_report_carry_the_machine():
    assert provenance()["machine"] == _machine.machine()
    result = {
        "window_steps_per_s": 3.3e7,
        "paths": {"rates_and_inputs": 9.8e7},
        "paths_rk4": {},
        "generation_window_steps_per_s": 1.8e7,
        "constant_fit_ms": 3.1,
        "constant_fit_window_steps_per_s": 1.0e7,
        "paper_iteration_s": 1.1,
        "paper_run_s": 33.0,
        "paper_run_measured": False,
        "iterations": 30,
        "machine": {
            "cpu": "Some CPU",
            "compiled_for": "znver3",
            "cores": 2,
            "blas": {
                "libraries": [
                    {"library": "openblas 0.3.31", "file": "a.so", "kernels": "Haswell"},
                    {"library": "openblas 0.3.30", "file": "b.so", "kernels": "Haswell"},
                ],
                "pinned": True,
            },
        },
    }
    first = format_report(result).splitlines()[0]
    assert first == (
        "machine: Some CPU, 2 cores, kernels compiled for znver3; "
        "BLAS openblas 0.3.31 (Haswell), openblas 0.3.30 (Haswell)"
    )
