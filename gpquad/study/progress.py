"""Live progress of a sweep: runs done and running, best error per equation, ETA.

The best error of an equation is the lowest validation error of its finished runs, or,
before any has finished, "(suite x)": the lowest suite error among its running runs.

Workers write ``status.json`` in their run folders after every iteration; a
background thread of the parent polls them, so this works the same for loky and
dask workers (on a shared filesystem). Modes: ``live`` (a refreshed line on a
terminal, a line every `interval_log` seconds otherwise, plus one line per
finished run), ``quiet`` (warnings and the final summary only) and ``jsonl`` (one
JSON object per event on stdout, for batch clusters).
"""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

from gpquad.engine.variables import TARGET_NAMES

MODES = ("live", "quiet", "jsonl")


def _fmt_time(seconds: float | None) -> str:
    if seconds is None or seconds != seconds or seconds == float("inf"):
        return "?"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else f"{m}m{s:02d}s"


class SweepProgress:
    """Polls the run folders of a sweep and reports in one of MODES."""

    def __init__(
        self, mode: str = "live", stream=None, interval: float = 1.0, interval_log: float = 30.0
    ):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}")
        self.mode = mode
        self.stream = (
            stream if stream is not None else (sys.stdout if mode == "jsonl" else sys.stderr)
        )
        self.interval = interval
        self.interval_log = interval_log
        self.tty = mode == "live" and hasattr(self.stream, "isatty") and self.stream.isatty()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._last_log = 0.0

    # ------------------------------------------------------------------ events
    def start(self, out: Path, keys, iterations: int) -> None:
        self.out = Path(out)
        self.keys = list(keys)
        self.iterations = iterations
        self.t0 = time.time()
        self.done_at_start = self.snapshot()["iterations_done"]
        self._emit(
            {"event": "start", "runs": len(self.keys), "folder": str(self.out)},
            f"gpquad sweep: {len(self.keys)} runs x {iterations} iterations in {self.out}",
        )
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def warn(self, message: str) -> None:
        self._emit({"event": "warning", "message": message}, f"warning: {message}", force=True)

    def run_done(self, summary: dict) -> None:
        if summary.get("skipped"):
            text = None
        else:
            text = (
                f"done {summary['target']} rep {summary['repetition']}: validation error "
                f"{summary['validation_error']:.4g} (train {summary['train_error']:.4g})"
            )
        self._emit(
            {
                "event": "run_done",
                **{
                    k: summary[k]
                    for k in ("target", "repetition", "train_error", "validation_error", "skipped")
                },
            },
            text,
        )

    def finished(self, summaries, model_path) -> None:
        snap = self.snapshot()
        self._emit(
            {
                "event": "sweep_done",
                "runs": len(summaries),
                "wall_s": time.time() - self.t0,
                "best_validation_error": snap["best_validation"],
                "model": str(model_path) if model_path else None,
            },
            f"sweep finished: {len(summaries)} runs in {_fmt_time(time.time() - self.t0)}"
            + (f"; best full model {model_path}" if model_path else ""),
            force=True,
        )

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()

    # ----------------------------------------------------------------- polling
    def snapshot(self) -> dict:
        """Counts, per-target best errors and iteration totals read from the run folders."""
        from gpquad.study.sweep_folders import run_dir

        done = running = iters = 0
        best_val: dict[str, float] = {}
        best_run: dict[str, float] = {}
        now = time.time()
        for key in self.keys:
            folder = run_dir(self.out, key)
            result = folder / "result.json"
            if result.exists():
                done += 1
                iters += self.iterations
                try:
                    val = float(json.loads(result.read_text())["validation_error"])
                    if val < best_val.get(key.target, float("inf")):
                        best_val[key.target] = val
                except (ValueError, KeyError, OSError):
                    pass
                continue
            try:
                status = json.loads((folder / "status.json").read_text())
            except (ValueError, OSError):
                continue
            iters += int(status.get("iteration", 0))
            if (
                status.get("state") == "running"
                and status.get("time", 0) >= self.t0 - 1
                and now - status.get("time", 0) < 7 * 24 * 3600
            ):
                running += 1
                err = float(status.get("best_suite_error", float("inf")))
                if err < best_run.get(key.target, float("inf")):
                    best_run[key.target] = err
        return {
            "done": done,
            "running": running,
            "total": len(self.keys),
            "iterations_done": iters,
            "iterations_total": len(self.keys) * self.iterations,
            "best_validation": best_val,
            "best_running": best_run,
        }

    def eta(self, snap: dict) -> float | None:
        gained = snap["iterations_done"] - self.done_at_start
        if gained <= 0:
            return None
        rate = gained / (time.time() - self.t0)
        return (snap["iterations_total"] - snap["iterations_done"]) / rate

    def line(self, snap: dict) -> str:
        parts = []
        for t in TARGET_NAMES:
            if t in snap["best_validation"] or t in snap["best_running"]:
                v = snap["best_validation"].get(t)
                r = snap["best_running"].get(t)
                parts.append(f"{t} {v:.3g}" if v is not None else f"{t} (suite {r:.3g})")
        return (
            f"[{snap['done']}/{snap['total']} done, {snap['running']} running, "
            f"{snap['iterations_done']}/{snap['iterations_total']} iterations, "
            f"elapsed {_fmt_time(time.time() - self.t0)}, ETA {_fmt_time(self.eta(snap))}] "
            f"best validation error: " + (", ".join(parts) if parts else "-")
        )

    def _loop(self) -> None:
        while not self._stop.wait(self.interval):
            snap = self.snapshot()
            if self.mode == "jsonl":
                if time.time() - self._last_log >= self.interval_log:
                    self._last_log = time.time()
                    self._emit({"event": "progress", **snap, "eta_s": self.eta(snap)}, None)
            elif self.mode == "live":
                if self.tty:
                    with self._lock:
                        self.stream.write("\r\033[K" + self.line(snap))
                        self.stream.flush()
                elif time.time() - self._last_log >= self.interval_log:
                    self._last_log = time.time()
                    self._emit({}, self.line(snap))

    def _emit(self, obj: dict, text: str | None, force: bool = False) -> None:
        with self._lock:
            if self.mode == "jsonl":
                if obj:
                    self.stream.write(json.dumps({**obj, "time": time.time()}) + "\n")
            elif text is not None and (self.mode == "live" or force):
                self.stream.write(("\r\033[K" if self.tty else "") + text + "\n")
            self.stream.flush()
