"""BLAS runs on one thread inside the engine (gpquad.engine.threads), whatever --jobs."""

import dataclasses

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from gpquad.engine.threads import one_blas_thread


@dataclasses.dataclass
class Unfinished:
    """A model as finish_model reads it before its first step."""

    equations: dict


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
    monkeypatch.setattr(
        finish, "finish_equation", lambda e, *a: finish.EquationFinish(e, (e,), (), 0.0)
    )
    with threadpool_limits(limits=2, user_api="blas"):
        if 2 not in blas_threads():
            pytest.skip("no BLAS here runs on two threads")
        with pytest.raises(Stop):
            search.identify(None, "p_dot", type("C", (), {"evolution": None})())
        model = Unfinished(dict.fromkeys(finish.TARGET_NAMES))
        evolution = type(
            "E", (), {"finish": ("repair",), "refine_for": staticmethod(lambda target: 0)}
        )()
        with pytest.raises(Stop):
            finish.finish_model(model, None, evolution)
    assert seen == [{1}, {1}]


@needs_blas
def test_the_fits_early_finishing_runs_on_one_thread(monkeypatch):
    """Each equation's own finishing steps, made in threads while the other searches go on
    (gpquad.study.fit.EarlyFinish), run under the fit's one-thread limit: a limit entered
    and left by each thread would lift it under the others. Bad case: the same threads
    started outside the fit run on the process's two."""
    from gpquad.models.finish import EquationFinish
    from gpquad.study import fit

    seen = []

    def record(equation, *args):
        seen.append(blas_threads())
        return EquationFinish(equation, (), (), 0.0)

    def search(dataset, cfg, report, run_dir, resuming, jobs, on_found):
        for target in ("p_dot", "q_dot"):
            on_found(type("Q", (), {"target": target})())
        return {}, {}

    monkeypatch.setattr(fit, "finish_equation", record)
    monkeypatch.setattr(fit, "search_equations", search)
    monkeypatch.setattr(fit, "new_model", lambda *a: None)
    monkeypatch.setattr(fit, "finish", lambda model, *a, early, **k: sorted(early))
    cfg = type("C", (), {"evolution": type("E", (), {"finish": ("refine",)}), "vehicle": None})
    with threadpool_limits(limits=2, user_api="blas"):
        if 2 not in blas_threads():
            pytest.skip("no BLAS here runs on two threads")
        assert fit.fit_dataset(None, cfg, report=object(), jobs=2) == ["p_dot", "q_dot"]
        assert seen == [{1}, {1}]
        outside = fit.EarlyFinish(None, cfg, 2)
        outside.start(type("Q", (), {"target": "r_dot"})())
        outside.results()
    assert seen[2] == {2}
