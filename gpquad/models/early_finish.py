"""The finishing steps' per-equation work, begun on a core that the searches leave idle.

Searches run in worker processes, one per core; once fewer are left than cores, a core
waits for the last search. The finish (gpquad.models.finish) then refines each equation
flown alone, which needs no other equation: symmetrize and refine are per equation, and
only their model-level parts (keep_what_flies, the repair, the joint refit) need all six.
`EarlyFinish` runs that per-equation work for the equations already found, in one thread
of this process at the lowest priority (`yield_cores`: it takes only what the searches and
the finish's own threads leave idle), while the last searches go on.

Nothing is guessed into the model. The early work computes what the finish would compute
if its inputs turn out as expected, and keeps each result under the exact content of its
input equation (`content_key`); the finish asks for every per-equation result through
the same table (`EarlyFinish.__call__`), which returns a kept result only for an equal
input and otherwise computes it as it always did. The one input the early work has to
expect is the rows on which negligible terms are judged (gpquad.models.precision:
model_rows, from the largest delay of all six equations): it takes those of the
equations found so far; where the finish's rows drop other terms, the key differs and
the finish computes that equation itself. Every per-equation step gives the same result
for any number of threads, so a kept result is the one the finish would have made.

BLAS stays on one thread from `start` to `close` (gpquad.engine.threads): threadpoolctl's
limit is the process's, and a limit lifted by one thread would reach the other.
"""

from __future__ import annotations

import os
import pickle
import sys
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import fields

from threadpoolctl import threadpool_limits

from gpquad.models.precision import sample_rows, without_negligible_terms
from gpquad.models.refine import refine_equation
from gpquad.models.symmetrize import symmetrize_equation

#: The finishing steps whose work is per equation, in the order evolution.finish may list
#: them before any model-level step.
PER_EQUATION = ("symmetrize", "refine")


def content_key(equation) -> bytes:
    """The bytes of every declared field of an equation (dataclass): equal for equal
    content (the same tree, constants, delays, lag, errors, candidates...), different
    otherwise."""
    return pickle.dumps([getattr(equation, f.name) for f in fields(equation)], protocol=5)


#: The niceness of the early work's threads (Linux: the lowest priority).
NICE = 19


def yield_cores() -> None:
    """This thread, and the threads it starts (they inherit it), at the lowest priority
    where the system has per-thread priorities (Linux): the searches and the finish's own
    threads take the cores first, the early work takes what they leave idle. Elsewhere,
    or where it is refused, nothing changes."""
    if not sys.platform.startswith("linux"):
        return
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICE)
    except (AttributeError, OSError):
        pass


class EarlyFinish:
    """Per-equation finishing work started while searches are still running (module notes).

    `found(equation)` as each search ends; `start()` once a core is idle (work already
    found is queued then, later equations as they come); the finish calls the object
    itself for each per-equation result (`__call__`), then `close()`.
    """

    def __init__(self, dataset, evolution, flipped=(), workers: int = 1):
        self.dataset, self.evolution, self.flipped = dataset, evolution, tuple(flipped)
        self.workers = workers  # threads of a refinement's candidates (refine_equation)
        steps = []
        for name in evolution.finish:
            if name not in PER_EQUATION:
                break
            steps.append(name)
        self.steps = tuple(steps)
        self._results: dict[bytes, Future] = {}
        self._lock = threading.Lock()
        self._found: list = []
        self._pool: ThreadPoolExecutor | None = None
        self._limits = None
        self._closed = False
        #: Seconds the early thread spent working, and the results the finish took from it.
        self.busy_s = 0.0
        self.used = 0

    @property
    def useful(self) -> bool:
        """Whether any equation has per-equation work to begin early."""
        return "refine" in self.steps or ("symmetrize" in self.steps and bool(self.flipped))

    def found(self, equation) -> None:
        """An equation whose search has ended; queued at once when started."""
        with self._lock:
            self._found.append(equation)
            if self._pool is not None and not self._closed:
                self._pool.submit(self._prepare, equation)

    def start(self) -> None:
        """Begin the early work (one thread) on the equations found so far."""
        with self._lock:
            if self._pool is not None or self._closed or not self.useful:
                return
            self._limits = threadpool_limits(limits=1, user_api="blas")
            self._pool = ThreadPoolExecutor(
                max_workers=1, thread_name_prefix="gpquad-early", initializer=yield_cores
            )
            for equation in self._found:
                self._pool.submit(self._prepare, equation)

    def drain(self) -> None:
        """The searches have ended: what has not begun never does (the finish, on every
        core, does it), what has goes on."""
        with self._lock:
            self._closed = True
            pool = self._pool
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)

    def close(self) -> None:
        """drain(), then wait for the work begun."""
        self.drain()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
        if self._limits is not None:
            self._limits.restore_original_limits()
            self._limits = None

    def __enter__(self) -> EarlyFinish:
        return self

    def abandon(self) -> None:
        """drain() without waiting for the work begun (an error or Ctrl-C: nothing will
        take it)."""
        self.drain()
        if self._limits is not None:
            self._limits.restore_original_limits()
            self._limits = None

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abandon()

    def __call__(self, kind: str, equation, compute):
        """compute(equation) for the finish step `kind`, or the result the early work made
        for an equal input (waiting for it while it is being made)."""
        key = kind.encode() + b"\0" + content_key(equation)
        with self._lock:
            future = self._results.get(key)
            if future is None:
                future = self._results[key] = Future()
                mine = True
            else:
                mine = False
        if not mine:
            result = future.result()
            if threading.current_thread().name.startswith("gpquad-early"):
                return result
            with self._lock:
                self.used += 1
            return result
        try:
            result = compute(equation)
        except BaseException as exc:
            future.set_exception(exc)
            raise
        future.set_result(result)
        return result

    def _rows(self):
        """The rows the finish would judge negligible terms on, were the equations found so
        far all of them (precision.model_rows)."""
        with self._lock:
            found = list(self._found)
        max_delay = max((d for e in found for d in e.delays.values()), default=0)
        return sample_rows(self.dataset.train or self.dataset.validation, max_delay)

    def _prepare(self, equation) -> None:
        """The per-equation steps of one found equation, as the finish would take them."""
        if self._closed:
            return
        t0 = time.perf_counter()
        try:
            rows = self._rows()
            if len(rows):
                equation = without_negligible_terms(equation, self.dataset.arrays, rows)
            for step in self.steps:
                if self._closed:
                    return
                if step == "symmetrize" and self.flipped:
                    done = self("symmetrize", equation, self._symmetrized)
                    if done is not None:
                        equation = done[0]
                elif step == "refine" and self.evolution.refine_for(equation.target) > 0:
                    self("refine", equation, self._refined)
        except Exception:  # the finish computes it again and reports what it raises
            pass
        finally:
            self.busy_s += time.perf_counter() - t0

    def _symmetrized(self, equation):
        return symmetrize_equation(equation, self.dataset, self.evolution, self.flipped)

    def _refined(self, equation):
        return refine_equation(
            equation, self.dataset, self.evolution, self.flipped, workers=self.workers
        )
