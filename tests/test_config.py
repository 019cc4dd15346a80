"""Config loading: defaults are the paper's; bad keys, types and values are one-line errors."""

import pytest

from gpquad.errors import GpquadError
from gpquad.study.config import Config, config_from_dict, load_config, override


def test_defaults_are_the_papers():
    ev = Config().evolution
    assert (ev.n_models, ev.n_tests, ev.suite_size) == (14, 5, 6)
    assert (ev.model_generations, ev.test_generations, ev.iterations) == (600, 80, 30)
    assert (ev.window_steps, ev.max_depth, ev.max_delay) == (750, 5, 5)
    assert (ev.p_leaf, ev.p_delay, ev.const_variance, ev.p_const_perturb) == (0.7, 0.1, 0.1, 0.5)
    assert (ev.const_low, ev.const_high) == (-5.0, 5.0)
    assert ev.local_search == "none"  # the paper's method unless asked for


def test_load_toml(tmp_path):
    path = tmp_path / "exp.toml"
    path.write_text('seed = 4\n[data]\nfiles = ["flight.csv"]\n[evolution]\n'
                    'targets = ["p_dot"]\nwindow_steps = 100\n')
    cfg = load_config(path)
    assert cfg.seed == 4 and cfg.evolution.targets == ("p_dot",)
    assert cfg.data_paths() == [(tmp_path / "flight.csv").resolve()]


@pytest.mark.parametrize("table, field, message", [
    ({"evolution": {"iteratons": 3}}, "evolution.iteratons", "unknown key"),
    ({"evolution": {"iterations": "3"}}, "evolution.iterations", "expected int"),
    ({"evolution": {"p_leaf": 1.5}}, "evolution.p_leaf", "probability"),
    ({"evolution": {"targets": ["a_w"]}}, "evolution.targets[0]", "unknown target"),
    ({"evolution": {"metric": "rmse"}}, "evolution.metric", "choose one of"),
    ({"data": {"frame": "NWU"}}, "data.frame", "choose one of"),
    ({"data": {"inputs": ["u", "u_T"]}}, "data.inputs", "clash"),
    ({"seed": 1.5}, "seed", "expected int"),
    ({"evolution": 3}, "evolution", "section"),
    ({"colour": "red"}, "colour", "unknown key"),
])
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
