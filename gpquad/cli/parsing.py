"""The command line's parser pieces: argparse with "did you mean", --version, the examples
every --help ends with (gpquad.cli.examples), and Python warnings as grouped gpquad lines."""

from __future__ import annotations

import argparse
import sys


class Parser(argparse.ArgumentParser):
    """argparse with a "did you mean" for a mistyped command or choice."""

    def error(self, message: str):
        import difflib
        import re

        found = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if found:
            choices = re.findall(r"'([^']*)'", found.group(2))
            close = difflib.get_close_matches(found.group(1), choices, n=1)
            if close:
                message += f"; did you mean '{close[0]}'?"
        super().error(message)


class Version(argparse.Action):
    """--version: the version and the source's git revision."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="print the version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from gpquad._version import __version__
        from gpquad.study.store import git_revision

        print(f"gpquad {__version__} (git {git_revision()})")
        parser.exit()


EXAMPLES = """examples:
  gpquad run experiments/quickstart.toml          identify the reference flight's equations
  gpquad run my.toml --data flight.ulg            the same engine on your log
  gpquad score results/RUN --data other.ulg       RSE on another flight, beside the zero model
  gpquad export results/RUN --format c --out m.c  C99 code that flies the model
  gpquad data check flight.ulg                    is the log fit for identification?
  gpquad sweep experiments/paper.toml --jobs 2    the paper's full study
"""


def add_examples(parser: argparse.ArgumentParser, path: list[str]) -> None:
    """Every (sub)command's --help ends with its examples (gpquad.cli.examples)."""
    from gpquad.cli.examples import EXAMPLES

    for action in parser._actions:
        if not isinstance(action, argparse._SubParsersAction):
            continue
        for name, child in action.choices.items():
            key = " ".join(path + [name])
            if not child.epilog and key in EXAMPLES:
                child.epilog = "examples:\n" + "\n".join(f"  {e}" for e in EXAMPLES[key])
                child.formatter_class = argparse.RawDescriptionHelpFormatter
            add_examples(child, path + [name])


class WarningLines:
    """Python warnings as gpquad lines: the first of each kind (the message with its numbers
    blanked) printed when it happens, one line at the end for the rest of that kind; no
    source paths."""

    def __init__(self, stream=None):
        self.stream = stream
        self.kinds: dict[tuple[str, str], list] = {}

    def show(self, message, category, filename, lineno, file=None, line=None):
        import re

        text = " ".join(str(message).split())
        key = (category.__name__, re.sub(r"\d+(\.\d+)?(e-?\d+)?", "#", text))
        seen = self.kinds.setdefault(key, [text, 0])
        seen[1] += 1
        if seen[1] == 1:
            print(f"gpquad: warning: {text}", file=self.stream or sys.stderr, flush=True)

    def summary(self) -> None:
        for first, count in self.kinds.values():
            if count > 1:
                print(
                    f'gpquad: warning: {count - 1} more warning(s) like "{first}"',
                    file=self.stream or sys.stderr,
                )
