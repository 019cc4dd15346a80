"""Hostile cases of the walk: code from files, paths and links, data that can be lost."""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
import struct
from pathlib import Path

from hostile_common import (
    Case,
    copy_run,
    copy_sweep,
    edit_json,
    gp,
    inputs_csv,
    payloads,
    quick_config,
    write,
)


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
            argv = {
                "simulate": gp("simulate", cfg, "--out", work / "f.csv"),
                "run": gp("run", cfg, "--out", work / "r", "--quiet"),
                "sweep": gp("sweep", cfg, "--runs", "1", "--out", work / "s", "--quiet"),
            }[command]
            out.append(Case(name, argv))
        # config.json / run.json of a run folder a user was sent
        for where, command in (
            ("config.json", "compare"),
            ("config.json", "control-pid"),
            ("config.json", "report"),
            ("run.json", "compare"),
            ("config.json", "run-resume"),
        ):
            name = f"exec/{where}-equation/{command}/{pname}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            run = copy_run(fix, work)
            payload = payloads(marker)[pname]

            def put(obj, payload=payload, where=where):
                table = obj["config"] if where == "run.json" else obj
                table["simulator"]["equations"]["p_dot"] = payload

            edit_json(run / where, put)
            argv = {
                "compare": gp("compare", run, "--out", work / "cmp"),
                "control-pid": gp(
                    "control", "pid", run, "--out", work / "pid", "--json", "--no-figures"
                ),
                "report": gp("report", run, "--format", "png"),
                "run-resume": gp("run", fix / "six.toml", "--out", run, "--quiet"),
            }[command]
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
                edit_json(
                    sweep / "runs" / "p_dot" / "rep000" / "result.json",
                    lambda o: poison(o["equation"]),
                )
                argv = (
                    gp("sweep", fix / "six.toml", "--runs", "1", "--out", sweep, "--quiet")
                    if where == "sweep-result"
                    else gp("report", sweep, "--reassemble", "--format", "png")
                )
            out.append(Case(name, argv, expect="warn"))
        # model.json's expr beside its prefix, under the readers of a model
        for command in ("export", "fly", "score"):
            name = f"exec/model-expr/{command}/{pname}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            run = copy_run(fix, work)
            payload = payloads(marker)[pname]
            edit_json(run / "model.json", lambda o, p=payload: o["targets"]["p_dot"].update(expr=p))
            argv = {
                "export": gp("export", run, "--format", "sympy"),
                "fly": gp(
                    "fly", run, "--inputs", inputs_csv(work / "in.csv"), "--out", work / "o.csv"
                ),
                "score": gp("score", run, "--data", fix / "flight.csv"),
            }[command]
            out.append(Case(name, argv, expect="warn"))
    # forged pickled checkpoints
    for kind in ("run", "sweep"):
        for variant in ("system", "open"):
            name = f"exec/pickle-checkpoint/{kind}/{variant}"
            work = work_of(name)
            marker = work.parent / "PWNED"
            call = (
                (os.system, (f"touch {marker}",))
                if variant == "system"
                else (open, (str(marker), "w"))
            )

            class Evil:
                def __reduce__(self, call=call):
                    return call

            payload = pickle.dumps({"state": Evil(), "meta": {}})

            blob = (
                struct.pack("<8sQ32s", b"GPQCKPT1", len(payload), hashlib.sha256(payload).digest())
                + payload
            )
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
                argv = gp(
                    "sweep",
                    fix / "six.toml",
                    "--runs",
                    "1",
                    "--out",
                    sweep,
                    "--quiet",
                    "--no-assemble",
                )
            out.append(Case(name, argv, expect="warn", timeout=300))
    return out


def path_cases(work_of, fix: Path) -> list[Case]:
    out = []
    for label, run_name in (
        ("dotdot3", "../../.."),
        ("dotdot", ".."),
        ("nested", "a/../../b"),
        ("absolute", "/tmp/gpquad-walk-absolute-name"),
        ("slash", "x/y"),
        ("empty", ""),
        ("nul", "a\\u0000b"),
        ("long", "n" * 300),
    ):
        for command in ("run", "sweep"):
            name = f"path/name/{label}/{command}"
            work = work_of(name)
            cfg = write(work / "c.toml", f'name = "{run_name}"\n' + quick_config())
            argv = (
                gp(command, cfg, "--quiet")
                if command == "run"
                else gp(command, cfg, "--runs", "1", "--quiet")
            )
            out.append(Case(name, argv))
    # a history.csv that is a symlink to a user's file, on resume
    for label in ("history", "model", "config"):
        name = f"path/symlink/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        victim = write(work.parent / "victim.txt", "the user's precious file\n")
        target = {
            "history": "history.csv",
            "model": "checkpoints/p_dot.ckpt",
            "config": "equations.tex",
        }[label]
        (run / target).unlink(missing_ok=True)
        (run / "checkpoints" / "p_dot.json").unlink()
        (run / target).symlink_to(victim)
        out.append(
            Case(
                name,
                gp("run", fix / "six.toml", "--out", run, "--quiet"),
                expect="warn",
                protected={victim: victim.read_bytes()},
                timeout=300,
            )
        )
    # run.json scoring_data.files outside the folder
    for label, files in (("dotdot", ["../secret.csv"]), ("absolute", None)):
        for command in ("compare", "score"):
            name = f"path/scoring-data/{label}/{command}"
            work = work_of(name)
            run = copy_run(fix, work)
            secret = shutil.copy(fix / "flight.csv", work.parent / "secret.csv")
            listed = files or [str(Path(secret).resolve())]
            edit_json(
                run / "run.json",
                lambda o, f=listed: o.update(
                    scoring_data={
                        "files": f,
                        "inputs": ["u_P", "u_R", "u_Y", "u_T"],
                        "validation_fraction": 0.5,
                    }
                ),
            )
            argv = (
                gp("compare", run, "--out", work / "cmp")
                if command == "compare"
                else gp("score", run, "--data", fix / "flight.csv")
            )
            # score re-reads the run's config.json, never run.json's scoring_data
            out.append(Case(name, argv, expect="refuse" if command == "compare" else "safe"))
    return out


def loss_cases(work_of, fix: Path) -> list[Case]:
    out = []
    name = "loss/concurrent-runs"
    work = work_of(name)
    cfg = write(
        work / "c.toml",
        quick_config('["p_dot", "q_dot"]').replace("iterations = 1", "iterations = 3"),
    )
    argv = gp("run", cfg, "--out", work / "r", "--quiet")
    out.append(Case(name, argv, concurrent=argv, timeout=400))
    name = "loss/out-with-user-files"
    work = work_of(name)
    user = work / "mine"
    model = write(user / "model.json", '{"mine": true}\n')
    tex = write(user / "equations.tex", "my thesis\n")
    out.append(
        Case(
            name,
            gp("run", write(work / "c.toml", quick_config()), "--out", user, "--quiet"),
            protected={model: model.read_bytes(), tex: tex.read_bytes()},
        )
    )
    name = "loss/out-is-a-sweep-folder"
    work = work_of(name)
    sweep = copy_sweep(fix, work)
    (sweep / "model.json").write_text('{"the sweep best": 1}\n')
    out.append(
        Case(
            name,
            gp("run", fix / "six.toml", "--out", sweep, "--quiet"),
            protected={sweep / "model.json": (sweep / "model.json").read_bytes()},
        )
    )
    for label, value in (
        ("huge", 100_000_000),
        ("negative", -5),
        ("string", '"x"'),
        ("float", 1.5),
        ("past-end", 10_000),
    ):
        name = f"loss/history-bytes/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        before = (run / "history.csv").stat().st_size
        record = run / "checkpoints" / "p_dot.json"
        edit_json(record, lambda o, v=value: o.update(history_bytes=json.loads(str(v))))
        case = Case(
            name, gp("run", fix / "six.toml", "--out", run, "--quiet"), expect="warn", timeout=300
        )
        case.history_limit = before + 100_000  # type: ignore[attr-defined]
        out.append(case)
    return out
