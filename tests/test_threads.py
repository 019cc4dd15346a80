"""BLAS runs on one thread inside the engine (gpquad.engine.threads), whatever --jobs."""

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from gpquad.engine.threads import one_blas_thread


def blas_threads() -> set[int]:
    return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}


needs_blas = pytest.mark.skipif(not blas_threads(), reason="no BLAS that threadpoolctl sees")


def blas_state() -> list[tuple[str, int]]:
    return sorted(
        (i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"
    )


@needs_blas
def test_wrapped_function_runs_on_one_thread_and_the_limit_is_lifted_after():
    with threadpool_limits(limits=2, user_api="blas"):
        outside = blas_state()
        if 2 not in {n for _, n in outside}:
            pytest.skip("no BLAS here runs on two threads")  # the bad case cannot be made
        inside = one_blas_thread(blas_threads)()
        assert inside == {1}
        assert blas_state() == outside


@needs_blas
def test_identify_and_finish_model_run_on_one_thread(monkeypatch):
    from gpquad.engine.variables import TARGET_NAMES
    from gpquad.models import finish
    from gpquad.study import search

    seen = []

    class Stop(Exception):
        pass

    def record(*args, **kwargs):
        seen.append(blas_threads())
        raise Stop

    monkeypatch.setattr(search, "Coevolution", record)
    monkeypatch.setattr(finish, "repair_stability", record)
    monkeypatch.setattr(finish, "without_negligible", lambda model, dataset: model)
    with threadpool_limits(limits=2, user_api="blas"):
        if 2 not in blas_threads():
            pytest.skip("no BLAS here runs on two threads")
        with pytest.raises(Stop):
            search.identify(None, "p_dot", type("C", (), {"evolution": None})())
        model = type("M", (), {"equations": dict.fromkeys(TARGET_NAMES)})()
        evolution = type(
            "E", (), {"finish": ("repair",), "refine_for": staticmethod(lambda target: 0)}
        )()
        with pytest.raises(Stop):
            finish.finish_model(model, None, evolution)
    assert seen == [{1}, {1}]
