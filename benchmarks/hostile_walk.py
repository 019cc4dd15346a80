"""A walk of hostile and mistaken inputs through the command line, one subprocess each.

Each case builds its bad input in a folder of its own (cases/<name>/work, the working
directory of the command), runs `python -m gpquad ...` with a timeout and a memory limit,
and classifies the outcome:

    ok              exit 2 with one `gpquad: error:` line (or, where the case allows it, a
                    warning and a clean restart)
    code execution  a payload's marker file appeared
    file outside    a file appeared outside the case's work folder
    data lost       a file the user owned changed or vanished
    traceback       a Python traceback on stderr
    hang            the command ran past its timeout
    silent          exit 0 on input that should have been refused (or warned about)
    untidy          any other exit (several lines, exit 1, killed by the memory limit)

Usage: python benchmarks/hostile_walk.py [--root SOURCE_TREE] [--work DIR] [--only WORD]
Prints one line per case and the counts by category; --json writes every outcome.
The fixtures (a six-target run folder and a small sweep folder) are made first by the code
under test. Expect 10 to 20 minutes on two cores.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import resource
import shutil
import struct
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

QUICK = """\
[evolution]
targets = {targets}
iterations = 1
model_generations = 2
test_generations = 2
window_steps = 60
test_offset_max = 30
simplify_generations = 2
stability_repair = true
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
        "globals": ("0*Integer.__new__.__globals__['__builtins__']['__import__']('os')"
                    f".system('touch {m}')"),
        "lambda": f"(lambda: open('{m}', 'w'))()",
        "symbol_attr": (f"p + Symbol('x').__class__.__init__.__globals__['__builtins__']"
                        f"['open']('{m}', 'w').close()"),
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
    for argv in (["run", str(fix / "six.toml"), "--out", str(fix / "run6"), "--quiet"],
                 ["sweep", str(fix / "six.toml"), "--runs", "1", "--out", str(fix / "sweep"),
                  "--quiet", "--no-assemble"]):
        if not Path(argv[argv.index("--out") + 1]).exists():
            proc = subprocess.run([sys.executable, "-m", "gpquad", *argv], env=env,
                                  capture_output=True, text=True, timeout=900)
            if proc.returncode != 0:
                sys.exit(f"fixture {argv[0]} failed:\n{proc.stderr}")
    proc = subprocess.run([sys.executable, "-m", "gpquad", "simulate", str(fix / "six.toml"),
                           "--out", str(fix / "flight.csv")], env=env, capture_output=True,
                          text=True, timeout=300)
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


# ---------------------------------------------------------------------------- cases
def exec_cases(work_of, fix: Path) -> list[Case]:
    """Payloads in every field that holds an expression, under every command that reads it."""
    out = []
    for pname in payloads(Path("/x")):
        # [simulator] equations in a TOML config
        for command in ("simulate", "run", "sweep"):
            name = f"exec/toml-equation/{command}/{pname}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            text = quick_config() + f'[simulator.equations]\np_dot = "{payloads(marker)[pname]}"\n'
            cfg = write(work / "c.toml", text)
            argv = {"simulate": gp("simulate", cfg, "--out", work / "f.csv"),
                    "run": gp("run", cfg, "--out", work / "r", "--quiet"),
                    "sweep": gp("sweep", cfg, "--runs", "1", "--out", work / "s", "--quiet")
                    }[command]
            out.append(Case(name, argv))
        # config.json / run.json of a run folder a user was sent
        for where, command in (("config.json", "compare"), ("config.json", "control-pid"),
                               ("config.json", "report"), ("run.json", "compare"),
                               ("config.json", "run-resume")):
            name = f"exec/{where}-equation/{command}/{pname}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            run = copy_run(fix, work)
            payload = payloads(marker)[pname]

            def put(obj, payload=payload, where=where):
                table = obj["config"] if where == "run.json" else obj
                table["simulator"]["equations"]["p_dot"] = payload

            edit_json(run / where, put)
            argv = {"compare": gp("compare", run, "--out", work / "cmp"),
                    "control-pid": gp("control", "pid", run, "--out", work / "pid", "--json",
                                      "--no-figures"),
                    "report": gp("report", run, "--format", "png"),
                    "run-resume": gp("run", fix / "six.toml", "--out", run, "--quiet")}[command]
            unread = where == "config.json" and command == "compare"  # compare reads run.json
            out.append(Case(name, argv, expect="safe" if unread else "refuse"))
        # candidates[].expr reached by the stability repair (a diverging equation)
        for where in ("run-checkpoint-record", "sweep-result", "report-reassemble"):
            name = f"exec/candidates/{where}/{pname}"
            work = work_of(name)
            payload = payloads(work.parent / "PWNED")[pname]

            def poison(eq, payload=payload):
                eq["prefix"] = {"codes": [2, 4, 11], "values": [0.0, 60.0, 0.0]}  # 60*p
                eq["candidates"] = [{"expr": payload, "delays": {}, "error": 0.1, "size": 3}]

            if where == "run-checkpoint-record":
                run = copy_run(fix, work)
                edit_json(run / "checkpoints" / "p_dot.json", lambda o: poison(o["equation"]))
                argv = gp("run", fix / "six.toml", "--out", run, "--quiet")
            else:
                sweep = copy_sweep(fix, work)
                edit_json(sweep / "runs" / "p_dot" / "rep000" / "result.json",
                          lambda o: poison(o["equation"]))
                argv = (gp("sweep", fix / "six.toml", "--runs", "1", "--out", sweep, "--quiet")
                        if where == "sweep-result" else
                        gp("report", sweep, "--reassemble", "--format", "png"))
            out.append(Case(name, argv, expect="warn"))
        # model.json's expr beside its prefix, under the readers of a model
        for command in ("export", "fly", "score"):
            name = f"exec/model-expr/{command}/{pname}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            run = copy_run(fix, work)
            payload = payloads(marker)[pname]
            edit_json(run / "model.json",
                      lambda o, p=payload: o["targets"]["p_dot"].update(expr=p))
            argv = {"export": gp("export", run, "--format", "sympy"),
                    "fly": gp("fly", run, "--inputs", inputs_csv(work / "in.csv"), "--out",
                              work / "o.csv"),
                    "score": gp("score", run, "--data", fix / "flight.csv")}[command]
            out.append(Case(name, argv, expect="warn"))
    # forged pickled checkpoints
    for kind in ("run", "sweep"):
        for variant in ("system", "open"):
            name = f"exec/pickle-checkpoint/{kind}/{variant}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            call = ((os.system, (f"touch {marker}",)) if variant == "system"
                    else (open, (str(marker), "w")))

            class Evil:
                def __reduce__(self, call=call):
                    return call

            payload = pickle.dumps({"state": Evil(), "meta": {}})
            import hashlib

            blob = struct.pack("<8sQ32s", b"GPQCKPT1", len(payload),
                               hashlib.sha256(payload).digest()) + payload
            if kind == "run":
                run = copy_run(fix, work)
                (run / "checkpoints" / "p_dot.json").unlink()
                write(run / "checkpoints" / "p_dot.ckpt", blob)
                argv = gp("run", fix / "six.toml", "--out", run, "--quiet")
            else:
                sweep = copy_sweep(fix, work)
                rep = sweep / "runs" / "p_dot" / "rep000"
                (rep / "result.json").unlink()
                write(rep / "checkpoint.bin", blob)
                argv = gp("sweep", fix / "six.toml", "--runs", "1", "--out", sweep, "--quiet",
                          "--no-assemble")
            out.append(Case(name, argv, expect="warn", timeout=300))
    return out


def path_cases(work_of, fix: Path) -> list[Case]:
    out = []
    for label, run_name in (("dotdot3", "../../.."), ("dotdot", ".."), ("nested", "a/../../b"),
                            ("absolute", "/tmp/gpquad-walk-absolute-name"),
                            ("slash", "x/y"), ("empty", ""), ("nul", "a\\u0000b"),
                            ("long", "n" * 300)):
        for command in ("run", "sweep"):
            name = f"path/name/{label}/{command}"
            work = work_of(name)
            cfg = write(work / "c.toml", f'name = "{run_name}"\n' + quick_config())
            argv = gp(command, cfg, "--quiet") if command == "run" else \
                gp(command, cfg, "--runs", "1", "--quiet")
            out.append(Case(name, argv))
    # a history.csv that is a symlink to a user's file, on resume
    for label in ("history", "model", "config"):
        name = f"path/symlink/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        victim = write(work.parent / "victim.txt", "the user's precious file\n")
        target = {"history": "history.csv", "model": "checkpoints/p_dot.ckpt",
                  "config": "equations.tex"}[label]
        (run / target).unlink(missing_ok=True)
        (run / "checkpoints" / "p_dot.json").unlink()
        (run / target).symlink_to(victim)
        out.append(Case(name, gp("run", fix / "six.toml", "--out", run, "--quiet"),
                        expect="warn", protected={victim: victim.read_bytes()}, timeout=300))
    # run.json scoring_data.files outside the folder
    for label, files in (("dotdot", ["../secret.csv"]), ("absolute", None)):
        for command in ("compare", "score"):
            name = f"path/scoring-data/{label}/{command}"
            work = work_of(name)
            run = copy_run(fix, work)
            secret = shutil.copy(fix / "flight.csv", work.parent / "secret.csv")
            listed = files or [str(Path(secret).resolve())]
            edit_json(run / "run.json", lambda o, f=listed: o.update(scoring_data={
                "files": f, "inputs": ["u_P", "u_R", "u_Y", "u_T"], "validation_fraction": 0.5}))
            argv = gp("compare", run, "--out", work / "cmp") if command == "compare" else \
                gp("score", run, "--data", fix / "flight.csv")
            # score re-reads the run's config.json, never run.json's scoring_data
            out.append(Case(name, argv, expect="refuse" if command == "compare" else "safe"))
    return out


def loss_cases(work_of, fix: Path) -> list[Case]:
    out = []
    name = "loss/concurrent-runs"
    work = work_of(name)
    cfg = write(work / "c.toml", quick_config('["p_dot", "q_dot"]').replace(
        "iterations = 1", "iterations = 3"))
    argv = gp("run", cfg, "--out", work / "r", "--quiet")
    out.append(Case(name, argv, concurrent=argv, timeout=400))
    name = "loss/out-with-user-files"
    work = work_of(name)
    user = work / "mine"
    model = write(user / "model.json", '{"mine": true}\n')
    tex = write(user / "equations.tex", "my thesis\n")
    out.append(Case(name, gp("run", write(work / "c.toml", quick_config()), "--out", user,
                             "--quiet"),
                    protected={model: model.read_bytes(), tex: tex.read_bytes()}))
    name = "loss/out-is-a-sweep-folder"
    work = work_of(name)
    sweep = copy_sweep(fix, work)
    (sweep / "model.json").write_text('{"the sweep best": 1}\n')
    out.append(Case(name, gp("run", fix / "six.toml", "--out", sweep, "--quiet"),
                    protected={sweep / "model.json": (sweep / "model.json").read_bytes()}))
    for label, value in (("huge", 100_000_000), ("negative", -5), ("string", '"x"'),
                         ("float", 1.5), ("past-end", 10_000)):
        name = f"loss/history-bytes/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        before = (run / "history.csv").stat().st_size
        record = run / "checkpoints" / "p_dot.json"
        edit_json(record, lambda o, v=value: o.update(history_bytes=json.loads(str(v))))
        case = Case(name, gp("run", fix / "six.toml", "--out", run, "--quiet"), expect="warn",
                    timeout=300)
        case.history_limit = before + 100_000  # type: ignore[attr-defined]
        out.append(case)
    return out


def config_cases(work_of, fix: Path) -> list[Case]:
    out = []
    texts = {
        "latin1": quick_config().replace("[simulator]", "# caf\xe9\n[simulator]").encode(
            "latin-1"),
        "utf16": quick_config().encode("utf-16"),
        "binary": bytes(range(256)) * 4,
        "empty-bytes-nul": b"\x00" * 10,
    }
    for label, blob in texts.items():
        for command in ("run", "simulate", "sweep", "data-check"):
            name = f"config/encoding/{label}/{command}"
            work = work_of(name)
            cfg = write(work / "c.toml", blob)
            argv = {"run": gp("run", cfg, "--out", work / "r", "--quiet"),
                    "simulate": gp("simulate", cfg, "--out", work / "f.csv"),
                    "sweep": gp("sweep", cfg, "--runs", "1", "--out", work / "s", "--quiet"),
                    "data-check": gp("data", "check", fix / "flight.csv", "--config", cfg,
                                     "--plot", work / "p.png")}[command]
            out.append(Case(name, argv))
    bad_sim = {
        "duration-huge": "duration_s = 1e12", "rate-huge": "rate_hz = 1e9",
        "duration-nan": "duration_s = nan", "duration-inf": "duration_s = inf",
        "duration-negative": "duration_s = -5.0", "rate-zero": "rate_hz = 0.0",
        "stick-negative": 'stick_sd = {u_P = -0.1, u_R = 0.08, u_Y = 0.08, u_T = 0.03}',
        "noise-huge": "measurement_noise = {attitude = 1e6}",
        "input-limit-zero": "input_limit = 0.0",
        "stick-partial": "stick_sd = {u_P = 0.08}",
        "equations-partial": 'equations = {p_dot = "10.3*u_R(t-1) - 4.15*p"}',
        "equation-unknown-name": 'equations = {p_dot = "10.3*u_Q - p"}',
        "equation-huge-power": 'equations = {p_dot = "p**100000"}',
        "equation-deep-parens": 'equations = {p_dot = "' + "(" * 500 + "p" + ")" * 500 + '"}',
        "equation-long": 'equations = {p_dot = "' + "+".join(["p"] * 20000) + '"}',
        "equation-delay-huge": 'equations = {p_dot = "u_R(t-100000000)"}',
        "equation-future": 'equations = {p_dot = "u_R(t+3)"}',
        "equation-empty": 'equations = {p_dot = ""}',
    }
    for label, line in bad_sim.items():
        for command in ("simulate", "run"):
            name = f"config/simulator/{label}/{command}"
            work = work_of(name)
            text = quick_config().replace("duration_s = 40.0", "")
            if "duration" not in label:
                text += "duration_s = 40.0\n"
            cfg = write(work / "c.toml", text + line + "\n")
            argv = gp("simulate", cfg, "--out", work / "f.csv") if command == "simulate" else \
                gp("run", cfg, "--out", work / "r", "--quiet")
            # a table that names one entry changes that one (merged over the defaults): the
            # flight must still move every state and input
            merged = label in ("stick-partial", "equations-partial")
            out.append(Case(name, argv, expect="safe" if merged else "refuse", timeout=90,
                            verify="moves" if merged else ""))
    bad_ev = {
        "const-variance-inf": "const_variance = inf", "model-generations-0":
        "model_generations = 0", "exclude-all": 'exclude_leaves = ["phi", "theta", "psi", '
        '"u", "v", "w", "p", "q", "r", "u_P", "u_R", "u_Y", "u_T"]',
    }
    for label, line in bad_ev.items():
        name = f"config/evolution/{label}/run"
        work = work_of(name)
        text = quick_config().replace("[simulator]", line + "\n[simulator]")
        if label == "model-generations-0":
            key = line.split(" =")[0]
            text = "\n".join(r for r in text.splitlines() if not r.startswith(key + " ")) \
                .replace("[simulator]", line + "\n[simulator]")
        cfg = write(work / "c.toml", text)
        out.append(Case(name, gp("run", cfg, "--out", work / "r", "--quiet"), timeout=90))
    for label, line in (("format-bogus", 'format = "bogus"'),
                        ("validation-zero", "validation_fraction = 0.0")):
        name = f"config/data/{label}/run"
        work = work_of(name)
        text = quick_config().replace("stability_repair = true", "stability_repair = true") + \
            f"[data]\n{line}\n"
        cfg = write(work / "c.toml", text)
        out.append(Case(name, gp("run", cfg, "--out", work / "r", "--quiet"), timeout=90))
    return out


def model_cases(work_of, fix: Path) -> list[Case]:
    """Hand-edited model.json under export, fly and score."""
    def setter(key, value):
        return lambda o: o["targets"]["p_dot"].__setitem__(key, value)

    def prefix(codes, values):
        return lambda o: o["targets"]["p_dot"].__setitem__(
            "prefix", {"codes": codes, "values": values})

    edits = {
        "bad-codes": prefix([99, 4, 4], [0, 1, 2]),
        "negative-code": prefix([-1], [0.0]),
        "short-values": prefix([2, 4, 10], [1.0]),
        "incomplete-tree": prefix([2, 4], [1.0, 2.0]),
        "empty-prefix": prefix([], []),
        "huge-tree": prefix([0] * 5000 + [4] * 5001, [1.0] * 10001),
        "nan-constant": prefix([2, 4, 10], [float("nan"), 0, 0]),
        "huge-constant": prefix([2, 4, 10], [1e308, 0, 0]),
        "string-codes": prefix("abc", [1.0]),
        "huge-delay": setter("delays", {"u_R": 10 ** 9}),
        "negative-delay": setter("delays", {"u_R": -3}),
        "delay-of-unknown": setter("delays", {"u_Q": 2}),
        "expr-disagrees": setter("expr", "42*q"),
        "empty-inputs": lambda o: o.__setitem__("input_names", []),
        "payload-input-name": lambda o: o.__setitem__(
            "input_names", ["__import__('os').system('touch /tmp/gpquad-walk-name')", "u_R",
                            "u_Y", "u_T"]),
        "renamed-target": lambda o: o["targets"].__setitem__("x_dot", o["targets"].pop("p_dot")),
        "dt-zero": lambda o: o.__setitem__("dt", 0.0),
        "dt-nan": lambda o: o.__setitem__("dt", float("nan")),
        "targets-list": lambda o: o.__setitem__("targets", []),
        "interrupted": lambda o: o.__setitem__("interrupted", True),
    }
    out = []
    for label, change in edits.items():
        for command in ("export", "fly", "score"):
            name = f"model/{label}/{command}"
            work = work_of(name)
            run = copy_run(fix, work)
            edit_json(run / "model.json", change)
            argv = {"export": gp("export", run, "--format", "json"),
                    "fly": gp("fly", run, "--inputs", inputs_csv(work / "in.csv"), "--out",
                              work / "o.csv"),
                    "score": gp("score", run, "--data", fix / "flight.csv")}[command]
            out.append(Case(name, argv, expect="warn" if label == "interrupted" else "refuse",
                            timeout=90))
    return out


def command_cases(work_of, fix: Path) -> list[Case]:
    out = []
    for label, value in (("zero", "0"), ("negative", "-5"), ("huge", "1000000000")):
        name = f"command/compare-horizon/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        out.append(Case(name, gp("compare", run, "--horizon", value, "--out", work / "c"),
                        timeout=60))
    for label, value in (("inf", "inf"), ("nan", "nan"), ("negative", "-1"), ("zero", "0")):
        name = f"command/score-horizon/{label}"
        work = work_of(name)
        out.append(Case(name, gp("score", copy_run(fix, work), "--data", fix / "flight.csv",
                                 "--horizon-s", value), timeout=60))
    for label, dt in (("model-50hz", 0.02), ("model-12.5hz", 0.08)):
        name = f"command/score-other-rate/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        edit_json(run / "model.json", lambda o, dt=dt: o.__setitem__("dt", dt))
        out.append(Case(name, gp("score", run, "--data", fix / "flight.csv"), timeout=60))
    fly_inputs = {"empty": b"", "garbage": b"\x00\xff garbage \x01\n1,2\n",
                  "utf16": "t,u_P,u_R,u_Y,u_T\n0,0,0,0,0\n0.04,0,0,0,0\n".encode("utf-16"),
                  "header-only": b"t,u_P,u_R,u_Y,u_T\n",
                  "nan": b"t,u_P,u_R,u_Y,u_T\n0,nan,0,0,0\n0.04,0,0,0,0\n0.08,0,0,0,0\n",
                  "missing-column": b"t,u_P,u_R\n0,0,0\n0.04,0,0\n"}
    for label, blob in fly_inputs.items():
        name = f"command/fly-inputs/{label}"
        work = work_of(name)
        out.append(Case(name, gp("fly", copy_run(fix, work), "--inputs",
                                 write(work / "in.csv", blob), "--out", work / "o.csv"),
                        timeout=60))
    name = "command/data-check-fifo"
    work = work_of(name)
    os.mkfifo(work / "pipe.csv")
    out.append(Case(name, gp("data", "check", work / "pipe.csv", "--plot", work / "p.png"),
                    timeout=30))
    for label, target in (("history", "history.csv"), ("sweep-json", "sweep.json"),
                          ("result-json", "runs/p_dot/rep000/result.json")):
        for blob_label, blob in (("garbage", b"\x00\xffnot it"), ("empty", b"")):
            name = f"command/report-damaged/{label}/{blob_label}"
            work = work_of(name)
            sweep = copy_sweep(fix, work)
            write(sweep / target, blob)
            out.append(Case(name, gp("report", sweep, "--format", "png"), timeout=180))
    return out


# ---------------------------------------------------------------------------- running
def snapshot(folder: Path, skip: Path) -> set[Path]:
    found = set()
    for dirpath, dirnames, filenames in os.walk(folder):
        if Path(dirpath) == skip or skip in Path(dirpath).parents:
            dirnames[:] = []
            continue
        for f in filenames + dirnames:
            found.add(Path(dirpath) / f)
    return found


SIGNALS = ("u", "v", "w", "p", "q", "r", "u_P", "u_R", "u_Y", "u_T")


def still_signals(work: Path) -> list[str]:
    """The states and inputs that never change in the flight a command wrote: simulate's
    f.csv, or the training envelope of run's model.json."""
    if (work / "f.csv").exists():
        import pandas as pd

        table = pd.read_csv(work / "f.csv")
        return [n for n in SIGNALS if n in table and float(table[n].max() - table[n].min())
                < 1e-3]
    model = work / "r" / "model.json"
    if model.exists():
        envelope = json.loads(model.read_text()).get("envelope") or {}
        return [n for n in SIGNALS if n in envelope and envelope[n][1] - envelope[n][0] < 1e-3]
    return ["(no flight written)"]


def limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def start(argv, cwd, env):
    return subprocess.Popen([sys.executable, "-m", "gpquad", *argv], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            errors="replace", preexec_fn=limit_memory, start_new_session=True)


def finish(proc, timeout):
    try:
        out, err = proc.communicate(timeout=timeout)
        return proc.returncode, out, err, False
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        out, err = proc.communicate()
        return None, out, err, True


def classify(case: Case, work: Path, cases_root: Path, before: set[Path], env) -> tuple[str, str]:
    proc = start(case.argv, work, env)
    second = start(case.concurrent, work, env) if case.concurrent else None
    results = [finish(proc, case.timeout)]
    if second is not None:
        results.append(finish(second, case.timeout))
    results = [(c, e, h) for c, _, e, h in results]
    code, err, _ = results[0]
    marker = work.parent / "PWNED"
    outside = {p for p in snapshot(cases_root, work) - before
               if p.name != "PWNED" and work not in p.parents}
    for extra in (Path("/tmp/gpquad-walk-absolute-name"), Path("/tmp/gpquad-walk-name")):
        if extra.exists():
            outside.add(extra)
            shutil.rmtree(extra, ignore_errors=True) if extra.is_dir() else extra.unlink()
    first_line = next((line for line in err.splitlines() if line.strip()), "")[:160]
    if marker.exists():
        return "code execution", first_line
    if outside:
        return "file outside", ", ".join(sorted(str(p) for p in outside))[:160]
    for path, blob in case.protected.items():
        if not path.exists() or path.read_bytes() != blob:
            return "data lost", f"{path.name} changed"
    limit = getattr(case, "history_limit", None)
    hist = work / "run" / "history.csv"
    if limit is not None and hist.exists() and hist.stat().st_size > limit:
        return "data lost", f"history.csv grew to {hist.stat().st_size} bytes"
    if any(h for _, _, h in results):
        return "hang", f"over {case.timeout:.0f} s"
    if any("Traceback" in e for _, e, _ in results):
        tail = [line for line in err.splitlines() if line.strip()]
        return "traceback", (tail[-1] if tail else first_line)[:160]
    if second is not None:
        codes = sorted(c for c, _, _ in results)
        refused = [e for c, e, _ in results if c == 2]
        if codes == [0, 2] and len(refused[0].strip().splitlines()) == 1:
            return "ok", refused[0].strip()[:160]
        hist = work / "r" / "history.csv"
        damaged = hist.exists() and b"\x00" in hist.read_bytes()
        return ("data lost" if damaged else "silent"), f"exit codes {codes}"
    lines = [line for line in err.strip().splitlines() if line.strip()]
    if code == 2 and len(lines) == 1 and lines[0].startswith("gpquad: error:"):
        return "ok", lines[0][:160]
    if code == 0:
        warned = any("warning" in line for line in lines)
        if case.expect == "warn" and warned:
            return "ok", next(line for line in lines if "warning" in line)[:160]
        still = still_signals(work) if case.verify == "moves" else []
        if still:
            return "silent", f"exit 0 but {', '.join(still)} never change"
        if case.expect == "safe":
            return "ok", ("every signal moves" if case.verify else
                          "the command does not read the field")
        return "silent", (lines[0] if lines else "exit 0, nothing said")[:160]
    return "untidy", f"exit {code}, {len(lines)} lines: {first_line}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=str(Path(__file__).resolve().parents[1]),
                        help="source tree whose gpquad is walked (default: this one)")
    parser.add_argument("--work", default="/tmp/gpquad-hostile-walk")
    parser.add_argument("--only", default="", help="run the cases whose name holds this")
    parser.add_argument("--json", default="", help="write every outcome to this file")
    args = parser.parse_args(argv)
    root = Path(args.root).resolve()
    work_root = Path(args.work).resolve()
    env = {**os.environ, "PYTHONPATH": str(root), "MPLBACKEND": "Agg"}
    cases_root = work_root / "cases"
    if cases_root.exists():
        shutil.rmtree(cases_root)
    cases_root.mkdir(parents=True)
    fix = work_root / "fixtures"
    make_fixtures(fix, env)

    def work_of(name: str) -> Path:
        folder = cases_root / name.replace("/", "__") / "work"
        folder.mkdir(parents=True)
        return folder

    groups = (exec_cases, path_cases, loss_cases, config_cases, model_cases, command_cases)
    cases = [c for g in groups for c in g(work_of, fix) if args.only in c.name]
    counts: Counter = Counter()
    outcomes = []
    t0 = time.time()
    for case in cases:
        work = cases_root / case.name.replace("/", "__") / "work"
        before = snapshot(cases_root, work)
        start_s = time.time()
        kind, detail = classify(case, work, cases_root, before, env)
        counts[kind] += 1
        outcomes.append({"case": case.name, "outcome": kind, "detail": detail,
                         "seconds": round(time.time() - start_s, 1)})
        print(f"{kind:15s} {case.name:60s} {detail}", flush=True)
    print(f"\n{len(cases)} cases in {time.time() - t0:.0f} s:")
    for kind in ("ok", "code execution", "file outside", "data lost", "traceback", "hang",
                 "silent", "untidy"):
        print(f"  {kind:15s} {counts[kind]}")
    if args.json:
        Path(args.json).write_text(json.dumps({"counts": counts, "outcomes": outcomes},
                                              indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
