"""The command line's help: every command shows examples, and every example parses (so a
hint never names an option a command does not have)."""

import argparse
import shlex

import pytest

from gpquad.cli.commands import EXAMPLES as TOP_EXAMPLES
from gpquad.cli.commands import build_parser, main
from gpquad.cli.examples import EXAMPLES


def _commands(parser, path=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield " ".join((*path, name)), child
                yield from _commands(child, (*path, name))


def test_every_command_has_examples():
    missing = [
        name
        for name, child in _commands(build_parser())
        if not (child.epilog or "").startswith("examples:")
    ]
    assert missing == []


def _all_examples():
    lines = [line.strip().split("  ")[0] for line in TOP_EXAMPLES.splitlines()[1:] if line.strip()]
    lines += [e for examples in EXAMPLES.values() for e in examples]
    return [line.strip() for line in lines]


@pytest.mark.parametrize("example", _all_examples())
def test_every_example_parses(example):
    argv = shlex.split(example)
    assert argv[0] == "gpquad"
    build_parser().parse_args(argv[1:])  # SystemExit (exit 2) on an unknown option


def test_a_mistyped_command_gets_a_suggestion(capsys):
    with pytest.raises(SystemExit) as info:
        main(["sweeep", "x.toml"])
    assert info.value.code == 2 and "did you mean 'sweep'?" in capsys.readouterr().err


def test_version_and_bare_command(capsys):
    with pytest.raises(SystemExit):
        main(["--version"])
    out = capsys.readouterr().out
    assert out.startswith("gpquad ") and "(git " in out
    assert main([]) == 0 and "examples:" in capsys.readouterr().out


def test_hints_name_what_the_command_has(tmp_path):
    """A missing PX4 folder is said to be missing; score's failed-check hint names its own
    --no-check (not a config key it cannot take)."""
    from gpquad.data.integration_check import screen_segments
    from gpquad.data.px4 import read_px4_folder
    from gpquad.errors import GpquadError

    with pytest.raises(GpquadError, match="no such file or folder"):
        read_px4_folder(tmp_path / "S250_missing")
    (tmp_path / "file.txt").write_text("x")
    with pytest.raises(GpquadError, match="not a folder of ulog2csv"):
        read_px4_folder(tmp_path / "file.txt")
    import inspect

    assert (
        inspect.signature(screen_segments).parameters["skip_hint"].default
        == "set data.check_before_run = false"
    )
    score_args = build_parser().parse_args(["score", "RUN", "--data", "x.ulg", "--no-check"])
    assert score_args.no_check
