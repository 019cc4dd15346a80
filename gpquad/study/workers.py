"""The worker processes of the equations' searches (a loky process pool of their own, apart
from the one joblib shares between a benchmark's or a sweep's cells).

A run may start them before it loads its data (`start`), so that their start-up and the
kernels' compilation (gpquad.study.warmup: one group per worker) overlap the loading;
`submit_all` waits for the warm-up before it hands out the searches. `release` lets them
exit once the searches are done. A fit inside a worker process (a benchmark's cells run in
parallel, say) searches in its own process: `inside_worker`.

On Linux, from a process that runs no other Python thread (the `gpquad run` command, a
script), the workers are forked from this process once it has imported the search and
loaded numba's compiler (`fork_context`, `gpquad.study.warmup.load`): they start with
both, where a fresh interpreter takes about two seconds of CPU for them. Elsewhere (a
notebook, whose kernel runs threads; macOS; Windows) they are fresh interpreters (loky).
The workers ignore Ctrl-C: this process stops them. They exit by themselves once it is
gone (killed outright, it could not stop them).

A fit's `jobs` are the cores it may use: at most one worker process per equation, and a
search whose pool has cores left idle (the last one running, say) takes them as threads
for its final choice, told by `CoreShare`. The equations are the same for any number.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
import tempfile
import threading
import time
from concurrent.futures import FIRST_EXCEPTION, Future, as_completed, wait

from gpquad.study.warmup import GROUPS, load, warm

#: The executor of the last start() and its warm-up futures.
_pool: dict = {}
#: Seconds the last submit_all waited for the warm-up (`warm_up_wait`).
_waited: dict = {}


def warm_up_wait() -> float:
    """Seconds the searches waited for the workers' warm-up since the last call (0 if none
    did): with a cold kernel cache, the compilation that the loading did not hide."""
    return _waited.pop("s", 0.0)


def default_jobs() -> int:
    """The cores a fit uses by default: every core this process may run on (joblib's count,
    which honours CPU affinity and a container's CPU quota)."""
    from joblib import cpu_count

    return max(1, cpu_count())


def processes(jobs: int, n_targets: int) -> int:
    """Worker processes for `n_targets` searches on `jobs` cores: one per core, at most one
    per target."""
    return max(1, min(jobs, n_targets))


class CoreShare:
    """The number of a pool's searches not yet finished, in a small file that the searches
    read (`threads_of`): while fewer are left than the fit's `jobs`, each may use
    jobs // left threads. Where the file cannot be made or replaced, the searches keep the
    count they last read (one thread when none), which gives the same equations."""

    def __init__(self, left: int):
        try:
            fd, self.path = tempfile.mkstemp(prefix="gpquad-searches-")
            os.close(fd)
        except OSError:  # no writable temporary directory: one thread per search
            self.path = os.devnull
            return
        self.set(left)

    def set(self, left: int) -> None:
        """Record `left` searches not yet finished (replaced atomically; skipped where the
        file is held open by a reader and cannot be replaced, as on Windows)."""
        if self.path == os.devnull:
            return
        tmp = f"{self.path}.tmp"
        try:
            with open(tmp, "w") as fh:
                fh.write(str(left))
            os.replace(tmp, self.path)
        except OSError:
            pass

    def close(self) -> None:
        if self.path == os.devnull:
            return
        for path in (self.path, f"{self.path}.tmp"):
            try:
                os.unlink(path)
            except FileNotFoundError:
                pass

    def __enter__(self) -> CoreShare:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def threads_of(path: str, jobs: int):
    """A search's threads() for a pool's CoreShare file: jobs // (searches left), at least 1
    (1 when the file cannot be read)."""

    def threads() -> int:
        try:
            with open(path) as fh:
                left = int(fh.read())
        except (OSError, ValueError):
            return 1
        return max(1, jobs // max(1, left))

    return threads


def inside_worker() -> bool:
    """Whether this process is a worker of another (its fits search in-process)."""
    import multiprocessing

    return multiprocessing.parent_process() is not None


def fork_context():
    """multiprocessing's fork context where a fork is safe and available: Linux, and no
    Python thread in this process but the main one (a thread holding a lock at the fork
    would leave it held in the child); None elsewhere."""
    import multiprocessing

    if not sys.platform.startswith("linux") or threading.active_count() > 1:
        return None
    if "fork" not in multiprocessing.get_all_start_methods():  # pragma: no cover
        return None
    return multiprocessing.get_context("fork")


#: Seconds between a worker's looks at its parent (`_exit_when_orphaned`).
PARENT_POLL_S = 0.5


def _initialize_worker(parent: int) -> None:
    """A worker's initializer. Ctrl-C in a terminal reaches every process of its group;
    this process stops the workers (`completed`), which would otherwise die mid-message:
    they ignore it. And a worker exits once this process (`parent`) is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if os.name == "posix":
        threading.Thread(target=_exit_when_orphaned, args=(parent,), daemon=True).start()


def _exit_when_orphaned(parent: int) -> None:
    """Exit this process, whatever it is doing, once `parent` is no longer its parent. A
    parent killed outright (SIGKILL, the out-of-memory killer, a job's time limit) cannot
    stop its workers, which would otherwise finish their search and wait for the next one
    forever."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def start(jobs: int) -> None:
    """Start `jobs` worker processes and their warm-up (returns at once); a pool of another
    size is shut down first."""
    if _pool.get("jobs") == jobs:
        return
    release()
    context = fork_context()
    if context is not None:
        from concurrent.futures import ProcessPoolExecutor

        load()  # the forked workers inherit it
        executor = ProcessPoolExecutor(
            max_workers=jobs,
            mp_context=context,
            initializer=_initialize_worker,
            initargs=(os.getpid(),),
        )
    else:
        from joblib.externals.loky import ProcessPoolExecutor as LokyExecutor

        executor = LokyExecutor(
            max_workers=jobs, initializer=_initialize_worker, initargs=(os.getpid(),)
        )
    with _born_ignoring_interrupts():  # the processes start at the first submit
        futures = [executor.submit(warm, g) for g in GROUPS]
    _pool.update(jobs=jobs, executor=executor, warm=futures)


@contextlib.contextmanager
def _born_ignoring_interrupts():
    """SIGINT ignored in this process (from its main thread only) while it starts worker
    processes: they inherit that, through a fork and through exec, so a fresh interpreter
    ignores Ctrl-C while it imports, before its initializer runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def submit_all(jobs: int, func, arguments: list[tuple]) -> list[Future]:
    """func(*args) for each of `arguments` in the warmed workers (started now if they were
    not); the futures, in the order of `arguments`."""
    start(jobs)
    t0 = time.perf_counter()
    done, _ = wait(_pool["warm"], return_when=FIRST_EXCEPTION)
    try:
        for future in done:
            future.result()  # a failed warm-up raises here, before any search
    except BaseException:
        release(kill=True)  # a pool that failed is not kept for the next fit
        raise
    _waited["s"] = time.perf_counter() - t0
    executor = _pool["executor"]
    return [executor.submit(func, *args) for args in arguments]


def completed(futures: list[Future]):
    """The futures' results as they finish; on an interruption or an error the rest are
    cancelled and the workers stopped."""
    try:
        for future in as_completed(futures):
            yield future.result()
    except BaseException:
        for future in futures:
            future.cancel()
        release(kill=True)
        raise


def release(wait: bool = False, kill: bool = False) -> None:
    """Shut the worker processes down (in the background unless `wait`): a run's finishing
    steps need none, and the next search starts new ones."""
    executor = _pool.pop("executor", None)
    _pool.clear()
    if executor is None:
        return
    from concurrent.futures import ProcessPoolExecutor

    if not isinstance(executor, ProcessPoolExecutor):  # loky's
        executor.shutdown(wait=wait, kill_workers=kill)
        return
    processes = list((executor._processes or {}).values())  # Python < 3.14: no kill_workers
    manager = getattr(executor, "_executor_manager_thread", None)
    executor.shutdown(wait=False, cancel_futures=kill)
    if kill:
        for process in processes:
            process.kill()
        if manager is not None:
            # Held here, the executor lets its manager thread close the call queue. Dropped,
            # the thread set an error on a cancelled future (InvalidStateError in Python
            # 3.11's terminate_broken), died, and left the queue's feeder thread blocked
            # on a full pipe, which the interpreter then waited for at exit.
            manager.join(timeout=60)
    if wait:
        for process in processes:
            process.join()


# a pool still open at exit (gpquad.fit's, kept for the next fit) is shut down while the
# modules its shutdown needs are still there
atexit.register(release, wait=True)
