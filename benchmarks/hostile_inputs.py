"""Hostile cases of the walk: configs, hand-edited models, command arguments."""

from __future__ import annotations

import os
from pathlib import Path

from hostile_common import (
    Case,
    copy_run,
    copy_sweep,
    edit_json,
    gp,
    inputs_csv,
    quick_config,
    write,
)


def config_cases(work_of, fix: Path) -> list[Case]:
    out = []
    texts = {
        "latin1": quick_config().replace("[simulator]", "# caf\xe9\n[simulator]").encode("latin-1"),
        "utf16": quick_config().encode("utf-16"),
        "binary": bytes(range(256)) * 4,
        "empty-bytes-nul": b"\x00" * 10,
    }
    for label, blob in texts.items():
        for command in ("run", "simulate", "sweep", "data-check"):
            name = f"config/encoding/{label}/{command}"
            work = work_of(name)
            cfg = write(work / "c.toml", blob)
            argv = {
                "run": gp("run", cfg, "--out", work / "r", "--quiet"),
                "simulate": gp("simulate", cfg, "--out", work / "f.csv"),
                "sweep": gp("sweep", cfg, "--runs", "1", "--out", work / "s", "--quiet"),
                "data-check": gp(
                    "data", "check", fix / "flight.csv", "--config", cfg, "--plot", work / "p.png"
                ),
            }[command]
            out.append(Case(name, argv))
    bad_sim = {
        "duration-huge": "duration_s = 1e12",
        "rate-huge": "rate_hz = 1e9",
        "duration-nan": "duration_s = nan",
        "duration-inf": "duration_s = inf",
        "duration-negative": "duration_s = -5.0",
        "rate-zero": "rate_hz = 0.0",
        "stick-negative": "stick_sd = {u_P = -0.1, u_R = 0.08, u_Y = 0.08, u_T = 0.03}",
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
            argv = (
                gp("simulate", cfg, "--out", work / "f.csv")
                if command == "simulate"
                else gp("run", cfg, "--out", work / "r", "--quiet")
            )
            # a table that names one entry changes that one (merged over the defaults): the
            # flight must still move every state and input
            merged = label in ("stick-partial", "equations-partial")
            out.append(
                Case(
                    name,
                    argv,
                    expect="safe" if merged else "refuse",
                    timeout=90,
                    verify="moves" if merged else "",
                )
            )
    bad_ev = {
        "const-variance-inf": "const_variance = inf",
        "model-generations-0": "model_generations = 0",
        "exclude-all": 'exclude_leaves = ["phi", "theta", "psi", '
        '"u", "v", "w", "p", "q", "r", "u_P", "u_R", "u_Y", "u_T"]',
    }
    for label, line in bad_ev.items():
        name = f"config/evolution/{label}/run"
        work = work_of(name)
        text = quick_config().replace("[simulator]", line + "\n[simulator]")
        if label == "model-generations-0":
            key = line.split(" =")[0]
            text = "\n".join(r for r in text.splitlines() if not r.startswith(key + " ")).replace(
                "[simulator]", line + "\n[simulator]"
            )
        cfg = write(work / "c.toml", text)
        out.append(Case(name, gp("run", cfg, "--out", work / "r", "--quiet"), timeout=90))
    for label, line in (
        ("format-bogus", 'format = "bogus"'),
        ("validation-zero", "validation_fraction = 0.0"),
    ):
        name = f"config/data/{label}/run"
        work = work_of(name)
        text = quick_config() + f"[data]\n{line}\n"
        cfg = write(work / "c.toml", text)
        out.append(Case(name, gp("run", cfg, "--out", work / "r", "--quiet"), timeout=90))
    return out


def model_cases(work_of, fix: Path) -> list[Case]:
    """Hand-edited model.json under export, fly and score."""

    def setter(key, value):
        return lambda o: o["targets"]["p_dot"].__setitem__(key, value)

    def prefix(codes, values):
        return lambda o: o["targets"]["p_dot"].__setitem__(
            "prefix", {"codes": codes, "values": values}
        )

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
        "huge-delay": setter("delays", {"u_R": 10**9}),
        "negative-delay": setter("delays", {"u_R": -3}),
        "delay-of-unknown": setter("delays", {"u_Q": 2}),
        "expr-disagrees": setter("expr", "42*q"),
        "empty-inputs": lambda o: o.__setitem__("input_names", []),
        "payload-input-name": lambda o: o.__setitem__(
            "input_names",
            ["__import__('os').system('touch /tmp/gpquad-walk-name')", "u_R", "u_Y", "u_T"],
        ),
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
            argv = {
                "export": gp("export", run, "--format", "json"),
                "fly": gp(
                    "fly", run, "--inputs", inputs_csv(work / "in.csv"), "--out", work / "o.csv"
                ),
                "score": gp("score", run, "--data", fix / "flight.csv"),
            }[command]
            out.append(
                Case(name, argv, expect="warn" if label == "interrupted" else "refuse", timeout=90)
            )
    return out


def command_cases(work_of, fix: Path) -> list[Case]:
    out = []
    for label, value in (("zero", "0"), ("negative", "-5"), ("huge", "1000000000")):
        name = f"command/compare-horizon/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        out.append(
            Case(name, gp("compare", run, "--horizon", value, "--out", work / "c"), timeout=60)
        )
    for label, value in (("inf", "inf"), ("nan", "nan"), ("negative", "-1"), ("zero", "0")):
        name = f"command/score-horizon/{label}"
        work = work_of(name)
        out.append(
            Case(
                name,
                gp(
                    "score", copy_run(fix, work), "--data", fix / "flight.csv", "--horizon-s", value
                ),
                timeout=60,
            )
        )
    for label, dt in (("model-50hz", 0.02), ("model-12.5hz", 0.08)):
        name = f"command/score-other-rate/{label}"
        work = work_of(name)
        run = copy_run(fix, work)
        edit_json(run / "model.json", lambda o, dt=dt: o.__setitem__("dt", dt))
        out.append(Case(name, gp("score", run, "--data", fix / "flight.csv"), timeout=60))
    fly_inputs = {
        "empty": b"",
        "garbage": b"\x00\xff garbage \x01\n1,2\n",
        "utf16": "t,u_P,u_R,u_Y,u_T\n0,0,0,0,0\n0.04,0,0,0,0\n".encode("utf-16"),
        "header-only": b"t,u_P,u_R,u_Y,u_T\n",
        "nan": b"t,u_P,u_R,u_Y,u_T\n0,nan,0,0,0\n0.04,0,0,0,0\n0.08,0,0,0,0\n",
        "missing-column": b"t,u_P,u_R\n0,0,0\n0.04,0,0\n",
    }
    for label, blob in fly_inputs.items():
        name = f"command/fly-inputs/{label}"
        work = work_of(name)
        out.append(
            Case(
                name,
                gp(
                    "fly",
                    copy_run(fix, work),
                    "--inputs",
                    write(work / "in.csv", blob),
                    "--out",
                    work / "o.csv",
                ),
                timeout=60,
            )
        )
    name = "command/data-check-fifo"
    work = work_of(name)
    os.mkfifo(work / "pipe.csv")
    out.append(
        Case(name, gp("data", "check", work / "pipe.csv", "--plot", work / "p.png"), timeout=30)
    )
    for label, target in (
        ("history", "runs/p_dot/rep000/history.csv"),
        ("sweep-json", "sweep.json"),
        ("result-json", "runs/p_dot/rep000/result.json"),
    ):
        for blob_label, blob in (("garbage", b"\x00\xffnot it"), ("empty", b"")):
            name = f"command/report-damaged/{label}/{blob_label}"
            work = work_of(name)
            sweep = copy_sweep(fix, work)
            write(sweep / target, blob)
            out.append(Case(name, gp("report", sweep, "--format", "png"), timeout=180))
    return out
