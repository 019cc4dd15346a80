"""Shared pieces of the hostile walk (benchmarks/hostile_walk.py): the case record, the
payloads, small file helpers and the fixtures (a finished six-target run, a sweep)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

QUICK = """\
preset = "paper"
[evolution]
targets = {targets}
iterations = 1
model_generations = 2
test_generations = 2
window_s = 2.4
simplify_generations = 2
finish = ["repair"]
[simulator]
duration_s = 40.0
"""
SIX = '["a_x", "a_y", "a_z", "p_dot", "q_dot", "r_dot"]'
MEMORY_LIMIT = 3 << 30  # bytes of address space per command


def payloads(marker: Path) -> dict[str, str]:
    """Expressions that create `marker` when evaluated as Python (or through sympy)."""
    m = str(marker)
    return {
        "import": f"__import__('os').system('touch {m}')",
        "globals": (
            f"0*Integer.__new__.__globals__['__builtins__']['__import__']('os').system('touch {m}')"
        ),
        "lambda": f"(lambda: open('{m}', 'w'))()",
        "symbol_attr": (
            f"p + Symbol('x').__class__.__init__.__globals__['__builtins__']"
            f"['open']('{m}', 'w').close()"
        ),
    }


@dataclass
class Case:
    name: str
    argv: list[str]
    #: "refuse": exit 2 with one line; "warn": exit 0 with a warning line is also fine;
    #: "safe": the command does not read the bad field, so a clean exit 0 is fine too
    expect: str = "refuse"
    timeout: float = 120.0
    #: files the user owns: they must keep their bytes
    protected: dict[Path, bytes] = field(default_factory=dict)
    #: a second command started at the same time (concurrent runs)
    concurrent: list[str] | None = None
    #: "moves": on exit 0, every state and input of the flight written (simulate's f.csv,
    #: or run's model.json envelope) must vary; a still signal is a silent wrong result
    verify: str = ""


def write(path: Path, text, mode: str = "w") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def quick_config(targets: str = '["p_dot"]', extra: str = "") -> str:
    return QUICK.format(targets=targets) + extra


# ---------------------------------------------------------------------------- fixtures
def make_fixtures(fix: Path, env: dict) -> None:
    """A finished six-target run folder and a one-repetition sweep folder (no assembly)."""
    fix.mkdir(parents=True, exist_ok=True)
    write(fix / "six.toml", quick_config(SIX))
    for argv in (
        ["run", str(fix / "six.toml"), "--out", str(fix / "run6"), "--quiet"],
        [
            "sweep",
            str(fix / "six.toml"),
            "--runs",
            "1",
            "--out",
            str(fix / "sweep"),
            "--quiet",
            "--no-assemble",
        ],
    ):
        if not Path(argv[argv.index("--out") + 1]).exists():
            proc = subprocess.run(
                [sys.executable, "-m", "gpquad", *argv],
                env=env,
                capture_output=True,
                text=True,
                timeout=900,
            )
            if proc.returncode != 0:
                sys.exit(f"fixture {argv[0]} failed:\n{proc.stderr}")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "gpquad",
            "simulate",
            str(fix / "six.toml"),
            "--out",
            str(fix / "flight.csv"),
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    if proc.returncode != 0:
        sys.exit(f"fixture simulate failed:\n{proc.stderr}")


def copy_run(fix: Path, work: Path, name: str = "run") -> Path:
    dst = work / name
    shutil.copytree(fix / "run6", dst)
    return dst


def copy_sweep(fix: Path, work: Path) -> Path:
    dst = work / "sweep"
    shutil.copytree(fix / "sweep", dst)
    return dst


def edit_json(path: Path, change) -> None:
    obj = json.loads(path.read_text())
    change(obj)
    path.write_text(json.dumps(obj, indent=2))


def inputs_csv(path: Path, dt: float = 0.04, n: int = 60) -> Path:
    rows = ["t,u_P,u_R,u_Y,u_T"] + [f"{k * dt:.6f},0.01,0,0,0.35" for k in range(n)]
    return write(path, "\n".join(rows) + "\n")


def gp(*argv) -> list[str]:
    return [str(a) for a in argv]
