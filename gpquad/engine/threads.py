"""BLAS on one thread inside the engine: results independent of --jobs.

The engine's kernels are numba loops on one thread; its few LAPACK calls (the pivoted QR of
`gradient_fit.identifiable`, the joint refit's normal equations and Cholesky) are small, and
OpenBLAS may sum in another order on another number of threads. joblib's workers run BLAS on
cpu_count // n_jobs threads, a process with --jobs 1 on all cores: the same seed could give
other bits with another --jobs. On one thread the result is the same either way, and faster
here (the pivoted QR of a 5000 x 10 Jacobian: 2.2 ms on one thread, 9.9 ms on two with the
other core busy, on a 2-core machine).
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from threadpoolctl import threadpool_limits


def one_blas_thread(func):
    """func runs with BLAS (and LAPACK) limited to one thread; the limit is lifted after."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper


def thread_map(func, items, workers: int) -> list:
    """[func(item) for item in items], in up to `workers` threads when there are several
    items (func must be thread-safe and release the GIL for its work, as the numba kernels
    do); in the items' order, so the same for any number of workers."""
    return thread_map_until(func, items, workers, lambda results: False)


def thread_map_until(func, items, workers: int, stop) -> list:
    """[func(item) for item in items] up to and including the first result after which
    stop(results so far) is true. In up to `workers` threads, the items queued in order
    (the threads never wait for each other); past the stop the items not yet started are
    cancelled and the results of those started are dropped, so the same for any number of
    workers."""
    items, results = list(items), []
    if workers <= 1 or len(items) <= 1:
        for item in items:
            results.append(func(item))
            if stop(results):
                break
        return results
    with ThreadPoolExecutor(max_workers=min(workers, len(items))) as pool:
        futures = [pool.submit(func, item) for item in items]
        try:
            for future in futures:
                results.append(future.result())
                if stop(results):
                    break
        finally:  # at the stop, or an error: what has not started does not
            for future in futures:
                future.cancel()
    return results


def chunks(n: int, workers: int) -> list[np.ndarray]:
    """range(n) in at most `workers` contiguous, non-empty index chunks of nearly equal
    size: windows flown side by side in threads (each window's arithmetic is its own)."""
    return [c for c in np.array_split(np.arange(n), max(1, workers)) if len(c)]
