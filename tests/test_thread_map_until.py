"""thread_map_until (gpquad.engine.threads): the results up to the stop, the same for any
number of threads as one by one."""

import time

from hypothesis import given, settings
from hypothesis import strategies as st

from gpquad.engine.threads import thread_map_until


def one_by_one(func, items, stop):
    results = []
    for item in items:
        results.append(func(item))
        if stop(results):
            break
    return results


@settings(max_examples=40, deadline=None)
@given(
    items=st.lists(st.integers(0, 20), max_size=12),
    limit=st.integers(0, 80),
    workers=st.integers(1, 5),
)
def test_the_results_up_to_the_stop_are_those_one_by_one(items, limit, workers):
    def square(x):
        time.sleep(0.0002 * (x % 3))  # the threads finish out of order
        return x * x

    def stop(results):
        return sum(results) > limit

    assert thread_map_until(square, items, workers, stop) == one_by_one(square, items, stop)


def test_a_stop_leaves_the_rest_out():
    """The bad case for the saving: without the stop every item would be mapped. Items
    past the first three hold their thread for 0.2 s, so at the stop at most one per
    thread has started; the rest are cancelled, not run."""
    seen = []
    workers = 2

    def record(x):
        seen.append(x)
        if x >= 3:
            time.sleep(0.2)
        return x

    results = thread_map_until(record, range(100), workers, lambda r: len(r) == 3)
    assert results == [0, 1, 2]
    assert len(seen) <= 3 + workers
