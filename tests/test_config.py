"""Config loading: the defaults are the recommended engine, `preset = "paper"` the paper's;
old keys migrate with a note or fail in one line; bad keys, types and values are one-line
errors."""

import pytest

from gpquad.errors import GpquadError
from gpquad.study.config import Config, config_from_dict, load_config, override


def test_defaults_are_the_recommended_engine():
    ev = Config().evolution
    assert (ev.n_models, ev.n_tests, ev.suite_size) == (14, 5, 6)
    assert (ev.model_generations, ev.test_generations, ev.iterations) == (600, 80, 12)
    assert ev.window_steps(0.04) == 250 and ev.max_delay == 5
    assert (ev.constant_fit, ev.selection, ev.linear_seed, ev.term_search) == (
        "lm",
        "bic",
        True,
        True,
    )
    assert ev.finish == ("symmetrize", "refine", "repair", "joint_fit")
    assert (ev.taps_for("a_x"), ev.taps_for("p_dot")) == (4, 6)
    assert (ev.depth_for("a_z"), ev.depth_for("r_dot")) == (5, 7)
    assert (ev.refine_for("a_y"), ev.refine_for("q_dot")) == (0, 20)
    assert Config().vehicle.flipped(("u_P", "u_R", "u_Y", "u_T")) == ("u_R", "u_Y")


def test_paper_preset_is_section_2_2():
    cfg = config_from_dict({"preset": "paper"})
    ev = cfg.evolution
    assert (ev.iterations, ev.window_steps(0.04), ev.max_delay) == (30, 750, 5)
    assert (ev.depth_for("p_dot"), ev.taps_for("p_dot"), ev.degree_for("r_dot")) == (5, 1, 0)
    gp = ev.gp
    assert (gp.p_leaf, gp.p_delay, gp.const_variance, gp.p_const_perturb) == (0.7, 0.1, 0.1, 0.5)
    assert (gp.const_low, gp.const_high) == (-5.0, 5.0)
    assert (ev.constant_fit, ev.selection, ev.finish, ev.linear_seed) == (
        "none",
        "prune",
        (),
        False,
    )
    assert ev.exclude_leaves == () and not cfg.vehicle.symmetric
    # a preset is laid under the file's own keys
    assert (
        config_from_dict({"preset": "paper", "evolution": {"iterations": 2}}).evolution.iterations
        == 2
    )
    with pytest.raises(GpquadError, match="unknown preset"):
        config_from_dict({"preset": "fast"})


def test_old_keys_migrate_with_a_note():
    notes = []
    cfg = config_from_dict(
        {
            "evolution": {
                "final_selection": "prune",
                "p_leaf": 0.6,
                "local_search": "delays+constants",
                "constant_fit": "gauss-newton",
                "front_selection": False,
                "stability_repair": True,
                "joint_fit": True,
                "refine_terms": 0,
                "test_offset_max": 125,
            }
        },
        "old.toml",
        notes=notes,
    )
    ev = cfg.evolution
    assert (ev.selection, ev.gp.p_leaf, ev.constant_fit) == ("prune", 0.6, "lm")
    assert ev.finish == ("repair", "joint_fit")
    assert all(n.startswith("old.toml: ") for n in notes) and len(notes) == 6
    # a run folder's config (its dt known) converts its window in steps
    assert config_from_dict(
        {"evolution": {"window_steps": 100}}, dt=0.04
    ).evolution.window_s == pytest.approx(4.0)


@pytest.mark.parametrize(
    "evolution, field, message",
    [
        ({"window_steps": 250}, "evolution.window_steps", "window_s = 10"),
        ({"front_selection": True}, "evolution.front_selection", "not adopted"),
        ({"attitude_weight": 0.5}, "evolution.attitude_weight", "not adopted"),
        ({"fit_horizons": [2, 10]}, "evolution.fit_horizons", "not adopted"),
        ({"local_search": "delays"}, "evolution.local_search", 'constant_fit = "lm"'),
        (
            {"local_search": "none", "constant_fit": "gauss-newton"},
            "evolution.local_search",
            "no longer offered",
        ),
    ],
)
def test_removed_options_that_change_the_result_fail_in_one_line(evolution, field, message):
    with pytest.raises(GpquadError, match=message) as info:
        config_from_dict({"evolution": evolution}, "old.toml")
    assert f"field '{field}'" in str(info.value) and "\n" not in str(info.value)


def test_load_toml(tmp_path):
    path = tmp_path / "exp.toml"
    path.write_text(
        'seed = 4\n[data]\nfiles = ["flight.csv"]\n[evolution]\n'
        'targets = ["p_dot"]\nwindow_s = 4.0\n'
    )
    cfg = load_config(path)
    assert cfg.seed == 4 and cfg.evolution.targets == ("p_dot",)
    assert cfg.data_paths() == [(tmp_path / "flight.csv").resolve()]


@pytest.mark.parametrize(
    "table, field, message",
    [
        ({"evolution": {"iteratons": 3}}, "evolution.iteratons", "unknown key"),
        ({"evolution": {"iterations": "3"}}, "evolution.iterations", "expected int"),
        ({"evolution": {"gp": {"p_leaf": 1.5}}}, "evolution.gp.p_leaf", "probability"),
        ({"evolution": {"iteratons": 3}}, "evolution.iteratons", "did you mean 'iterations'"),
        ({"evolution": {"finish": ["repair", "polish"]}}, "evolution.finish[1]", "choose one of"),
        (
            {
                "evolution": {
                    "constant_fit": "gauss-newton",
                    "local_search": "delays+constants",
                    "selection": "aic",
                }
            },
            "evolution.selection",
            "choose one of",
        ),
        (
            {"evolution": {"linear_seed": True, "constant_fit": "none", "term_search": False}},
            "evolution.linear_seed",
            "Levenberg",
        ),
        ({"evolution": {"window_s": 0.0}}, "evolution.window_s", "seconds"),
        ({"evolution": {"model_generations": 0}}, "evolution.model_generations", ">= 1"),
        ({"data": {"format": "bogus"}}, "data.format", "unknown format 'bogus'"),
        ({"data": {"validation_fraction": 0.0}}, "data.validation_fraction", "finish = \\[\\]"),
        ({"evolution": {"targets": ["a_w"]}}, "evolution.targets[0]", "unknown target"),
        ({"evolution": {"metric": "rmse"}}, "evolution.metric", "choose one of"),
        ({"data": {"frame": "NWU"}}, "data.frame", "choose one of"),
        ({"data": {"inputs": ["u", "u_T"]}}, "data.inputs", "clash"),
        ({"seed": 1.5}, "seed", "expected int"),
        ({"evolution": 3}, "evolution", "section"),
        ({"colour": "red"}, "colour", "unknown key"),
    ],
)
def test_bad_config_names_the_field(table, field, message):
    with pytest.raises(GpquadError, match=message) as info:
        config_from_dict(table, "exp.toml")
    assert f"field '{field}'" in str(info.value)
    assert str(info.value).startswith("exp.toml")
    assert "\n" not in str(info.value)


def test_bad_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("seed = = 3\n")
    with pytest.raises(GpquadError, match="not valid TOML"):
        load_config(bad)
    with pytest.raises(GpquadError, match="not found"):
        load_config(tmp_path / "missing.toml")


def test_overrides(tmp_path):
    cfg = override(Config(), files=["a.csv"], targets=["a_z"], iterations=2, seed=9)
    assert cfg.evolution.targets == ("a_z",) and cfg.evolution.iterations == 2
    assert cfg.seed == 9 and cfg.data.files[0].endswith("a.csv")
    with pytest.raises(GpquadError, match="unknown target"):
        override(Config(), targets=["yaw"])
