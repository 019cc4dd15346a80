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
under test. About 30 minutes on two cores against code that hangs or runs its payloads,
five against code that refuses them. Cases are in hostile_cases.py and hostile_inputs.py.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from hostile_cases import exec_cases, loss_cases, path_cases
from hostile_common import MEMORY_LIMIT, Case, make_fixtures
from hostile_inputs import command_cases, config_cases, model_cases


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
        return [n for n in SIGNALS if n in table and float(table[n].max() - table[n].min()) < 1e-3]
    model = work / "r" / "model.json"
    if model.exists():
        envelope = json.loads(model.read_text()).get("envelope") or {}
        return [n for n in SIGNALS if n in envelope and envelope[n][1] - envelope[n][0] < 1e-3]
    return ["(no flight written)"]


def limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def start(argv, cwd, env):
    return subprocess.Popen(
        [sys.executable, "-m", "gpquad", *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        errors="replace",
        preexec_fn=limit_memory,
        start_new_session=True,
    )


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
    outside = {
        p
        for p in snapshot(cases_root, work) - before
        if p.name != "PWNED" and work not in p.parents
    }
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
            return "ok", (
                "every signal moves" if case.verify else "the command does not read the field"
            )
        return "silent", (lines[0] if lines else "exit 0, nothing said")[:160]
    return "untidy", f"exit {code}, {len(lines)} lines: {first_line}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        default=str(Path(__file__).resolve().parents[1]),
        help="source tree whose gpquad is walked (default: this one)",
    )
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
        outcomes.append(
            {
                "case": case.name,
                "outcome": kind,
                "detail": detail,
                "seconds": round(time.time() - start_s, 1),
            }
        )
        print(f"{kind:15s} {case.name:60s} {detail}", flush=True)
    print(f"\n{len(cases)} cases in {time.time() - t0:.0f} s:")
    for kind in (
        "ok",
        "code execution",
        "file outside",
        "data lost",
        "traceback",
        "hang",
        "silent",
        "untidy",
    ):
        print(f"  {kind:15s} {counts[kind]}")
    if args.json:
        Path(args.json).write_text(json.dumps({"counts": counts, "outcomes": outcomes}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
