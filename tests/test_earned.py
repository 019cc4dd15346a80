"""Terms beyond FREE_TERMS must earn their place on the validation flights
(gpquad.models.earned, run inside the "refine" finishing step)."""

import numpy as np
import pytest
import sympy as sp
from conftest import truth_dataset
from test_refine import coefficients, evolution
from test_stability import model_of

from gpquad.models.earned import FREE_TERMS
from gpquad.models.refine import refine_equation, refined_summary
from gpquad.study.config import SimulatorConfig

TRUTH_R = SimulatorConfig().equations["r_dot"]  # -7.8*u_Y(t-2) - 1.9*r
JUNK = ("p", "q", "u", "v", "w", "phi", "theta", "p*q", "q*w", "u*v", "u_P", "u_T")


@pytest.fixture(scope="module")
def dataset():
    return truth_dataset({}, duration_s=120.0, seed=11)


def n_terms(equation) -> int:
    return len(sp.Add.make_args(sp.expand(equation.sympy())))


def test_terms_that_do_not_lower_the_validation_error_are_removed(dataset):
    """The bad case: the truth's two terms plus twelve that the flights do not support
    (14 > FREE_TERMS): the step removes terms until FREE_TERMS are left or the rest earn
    their place, and keeps the truth's terms with their coefficients."""
    text = TRUTH_R + "".join(f" + 0.05*{t}" for t in JUNK)
    found = model_of({"r_dot": text}, dataset).equations["r_dot"]
    assert n_terms(found) == 14 > FREE_TERMS
    refined, report = refine_equation(found, dataset, evolution(n_terms=1), ())
    assert len(report["dropped"]) >= 14 - FREE_TERMS
    assert n_terms(refined) <= FREE_TERMS
    assert report["validation_after"] <= report["validation_before"] * 1.01
    got = coefficients(refined)
    assert got["u_Y(t-2)"] == pytest.approx(-7.8, rel=1e-3)
    assert got["r"] == pytest.approx(-1.9, rel=1e-3)
    assert "unearned" in refined_summary({"r_dot": report})


def test_an_equation_of_at_most_free_terms_keeps_its_terms(dataset):
    """At most FREE_TERMS terms need not earn their place: nothing is removed, even where
    the validation error would allow it."""
    text = TRUTH_R + "".join(f" + 0.05*{t}" for t in JUNK[: FREE_TERMS - 2])
    found = model_of({"r_dot": text}, dataset).equations["r_dot"]
    assert n_terms(found) == FREE_TERMS
    refined, report = refine_equation(found, dataset, evolution(n_terms=1), ())
    assert report["dropped"] == []
    assert np.isfinite(report["validation_before"])
