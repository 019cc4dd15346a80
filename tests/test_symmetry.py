"""Left-right parity of equations (gpquad.models.symmetry) on the median model, whose six
equations have a symmetric vehicle's parity with u_R and u_Y flipped."""

import numpy as np
import pytest
from test_stability import model_of

from gpquad.data.dataset import build_dataset
from gpquad.models.analysis import term_contributions
from gpquad.models.equations import DiscoveredModel
from gpquad.models.symmetry import mirror_odd_terms, parity_summary, term_parity
from gpquad.study.config import SimulatorConfig, preset_evolution

TRUTH = dict(SimulatorConfig().equations)
FLIP = ("u_R", "u_Y")


@pytest.fixture(scope="module")
def dataset(short_flight):
    return build_dataset([short_flight], validation_fraction=0.25, trim="none")


@pytest.mark.parametrize(
    "term, parity",
    [
        ("r", -1),
        ("q", 1),
        ("1", 1),
        ("r**2", 1),
        ("phi*u_R", 1),
        ("u_R*u_Y", 1),
        ("u_Y__tap2", -1),
        ("p*q*r", 1),
        ("v*w", -1),
        ("theta*u_P", 1),
        ("psi*u_T", -1),
    ],
)
def test_term_parity(term, parity):
    assert term_parity(term, FLIP) == parity


def test_the_truth_has_a_symmetric_vehicles_parity(dataset):
    model = model_of(TRUTH, dataset)
    assert mirror_odd_terms(model, dataset, FLIP) == {}
    assert "no equation" in parity_summary({}, FLIP)
    # the bad case: with the pitch command flipped too, q_dot's -9.8 u_P is odd
    wrong = mirror_odd_terms(model, dataset, ("u_R", "u_P", "u_Y"))
    assert list(wrong) == ["q_dot"] and wrong["q_dot"]["share"] > 0.5


def test_terms_of_the_wrong_parity_are_found_with_their_share(dataset):
    model = model_of(
        dict(TRUTH, a_z=TRUTH["a_z"] + " + 2.0*r", p_dot=TRUTH["p_dot"] + " + 3.0*q"), dataset
    )
    found = mirror_odd_terms(model, dataset, FLIP)
    assert set(found) == {"a_z", "p_dot"}
    rows = {
        r["term"]: r["share"]
        for r in term_contributions(model.equations["a_z"], dataset, raw=False)
    }
    assert found["a_z"]["share"] == pytest.approx(rows["r"], rel=1e-12)
    assert found["a_z"]["text"] == "2.0*r"
    assert [t["term"] for t in found["p_dot"]["terms"]] == ["q"]
    line = parity_summary(found, FLIP)
    assert "a_z" in line and "p_dot" in line and "2.0*r" in line
    # below the share threshold: not listed
    small = model_of(dict(TRUTH, a_z=TRUTH["a_z"] + " + 0.001*r"), dataset)
    assert mirror_odd_terms(small, dataset, FLIP) == {}


def test_model_json_keeps_the_parity_report(dataset):
    model = model_of(dict(TRUTH, a_z=TRUTH["a_z"] + " + 2.0*r"), dataset)
    found = mirror_odd_terms(model, dataset, FLIP)
    model.mirror_parity = found
    again = DiscoveredModel.from_dict(model.to_dict())
    assert again.mirror_parity == found
    assert np.isclose(again.mirror_parity["a_z"]["share"], found["a_z"]["share"])


def test_symmetrize_drops_the_wrong_parity_and_refits(dataset):
    """a_z with a yaw-rate term and wrong constants: the term goes, the refit finds the
    truth's constants; constants themselves are kept (p_dot's offset), and an equation with
    the right parity is left as it is."""
    import dataclasses

    from gpquad.models.symmetrize import symmetrize, without_wrong_parity

    model = model_of(
        dict(TRUTH, a_z="25.0*u_T(t-5) - 0.8*w - 9.0 + 2.0*r", p_dot=TRUTH["p_dot"] + " + 0.3"),
        dataset,
    )
    assert without_wrong_parity(model.equations["p_dot"], FLIP) is None
    assert without_wrong_parity(model.equations["q_dot"], FLIP) is None
    evolution = preset_evolution(window_s=10.0, max_delay=5)
    fixed, report = symmetrize(model, dataset, evolution, FLIP)
    assert list(report) == ["a_z"] and report["a_z"]["dropped"] == ["2.0*r"]
    assert fixed.equations["p_dot"] is model.equations["p_dot"]
    got = {
        str(k): float(v) for k, v in fixed.equations["a_z"].sympy().as_coefficients_dict().items()
    }
    want = {"u_T": 28.2, "w": -1.0, "1": -9.81}
    assert set(got) == set(want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-3), k
    assert fixed.equations["a_z"].delays["u_T"] == 5
    from gpquad.models.symmetrize import symmetrized_summary

    assert symmetrized_summary(report) == (
        "symmetric equations (terms of the wrong left-right parity removed): a_z without 2.0*r"
    )
    assert "no equation" in symmetrized_summary({})
    again = DiscoveredModel.from_dict(dataclasses.replace(fixed, symmetrized=report).to_dict())
    assert again.symmetrized == report


def test_symmetric_equations_need_the_mirrored_inputs():
    from gpquad.errors import GpquadError
    from gpquad.study.config import config_from_dict

    with pytest.raises(GpquadError, match="vehicle.mirror_inputs"):
        config_from_dict({"vehicle": {"mirror_inputs": []}})
    # an asymmetric vehicle needs none; an old config's switches become the finish list
    assert config_from_dict({"vehicle": {"symmetric": False, "mirror_inputs": []}})
    notes = []
    ok = config_from_dict(
        {
            "evolution": {
                "symmetric_equations": True,
                "stability_repair": True,
                "mirror_inputs": list(FLIP),
            }
        },
        notes=notes,
    )
    assert ok.evolution.finish == ("symmetrize", "repair") and len(notes) == 2
