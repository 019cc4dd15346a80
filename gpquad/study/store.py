"""Run folders: provenance, atomic writes and streamed histories.

A run folder holds run.json (seed, config, package versions, git revision,
timings), config.json, model.json, equations.tex, equations.md and history.csv.
model.json holds no timings, so the same config and seed give the same file.
"""

from __future__ import annotations

import csv
import json
import os
import platform
import subprocess
import tempfile
from importlib import metadata
from pathlib import Path

PACKAGES = ("numpy", "numba", "llvmlite", "sympy", "joblib", "pandas", "scipy", "matplotlib")


def package_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in ("gpquad",) + PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def git_revision() -> str:
    """The source checkout's commit (with '+dirty' when it has changes), or 'unknown'."""
    here = Path(__file__).resolve().parent
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return rev + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def provenance() -> dict:
    """What a result needs to be reproduced: package versions, git revision, platform and
    machine (gpquad._machine.machine: the CPU and the BLAS kernels it ran)."""
    from gpquad._machine import machine

    return {
        "versions": package_versions(),
        "git_revision": git_revision(),
        "platform": platform.platform(),
        "machine": machine(),
    }


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write to a temporary file in the same folder, fsync, then rename over the target."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode())


def read_json(path, what: str = "file", fix: str = "") -> dict:
    """A JSON object from `path`; a missing or damaged file is a GpquadError naming it.

    `what` says what the file is ("run folder's model"), `fix` what the user can do about it.
    """
    from gpquad.errors import GpquadError

    path = Path(path)
    if not path.is_file():
        raise GpquadError(
            f"no {path.name} here: not a {what}" + (f"; {fix}" if fix else ""),
            source=str(path.parent),
        )
    try:
        obj = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise GpquadError(
            f"damaged JSON ({exc}); " + (fix or "restore or delete the file"), source=str(path)
        ) from None
    if not isinstance(obj, dict):
        raise GpquadError(
            "damaged JSON (not an object); " + (fix or "restore or delete it"), source=str(path)
        )
    return obj


#: Longest run name (it becomes part of a folder name).
MAX_NAME_CHARACTERS = 100


def checked_name(name, field: str = "name") -> str:
    """A run name that is a file name, not a path: letters, digits and . _ - + = , @ only,
    not starting with a dot (GpquadError otherwise: name = "../../x" would put the run
    folder outside output.dir)."""
    import re

    from gpquad.errors import GpquadError

    if (
        not isinstance(name, str)
        or len(name) > MAX_NAME_CHARACTERS
        or not re.fullmatch(r"[A-Za-z0-9_+=,@-][A-Za-z0-9._+=,@-]*", name)
    ):
        raise GpquadError(
            f"{str(name)[:40]!r} is not a run name: use up to "
            f"{MAX_NAME_CHARACTERS} letters, digits, '_', '-' or '.', not "
            "starting with '.' (the name becomes a folder name, not a path)",
            field=field,
        )
    return name


def write_json(path, obj) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")


def open_for_append(path: Path):
    """A text file opened to append, never through a symbolic link and only when it is a
    regular file (GpquadError otherwise: a history.csv that links to another file must not
    have that file truncated)."""
    import stat

    from gpquad.errors import GpquadError

    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        mode = None
    if mode is not None and not stat.S_ISREG(mode):
        raise GpquadError(
            "not a regular file (a link, folder or pipe); gpquad writes no file "
            "through a link: delete it or give another folder",
            source=str(path),
        )
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        raise GpquadError(f"cannot write ({exc.strerror})", source=str(path)) from None
    return os.fdopen(fd, "a", newline="")


class HistoryWriter:
    """Appends per-generation rows to a CSV as they come (bounded memory)."""

    FIELDS = (
        "target",
        "iteration",
        "generation",
        "best_suite_error",
        "median_suite_error",
        "best_size",
    )

    def __init__(self, path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists()
        self._fh = open_for_append(self.path)
        self._writer = csv.DictWriter(self._fh, fieldnames=self.FIELDS)
        if new:
            self._writer.writeheader()
            self._fh.flush()

    def write(self, rows) -> None:
        """Append rows and push them to disk (a checkpoint may record the size next)."""
        self._writer.writerows(rows)
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def size(self) -> int:
        """Bytes written so far (header included)."""
        return self._fh.tell()

    def truncate(self, size: int) -> None:
        """Drop everything after `size` bytes (rows of an interrupted iteration); never
        extends the file (ValueError for a size outside 0 .. its length)."""
        self._fh.flush()
        if type(size) is not int or not 0 <= size <= self.size():
            raise ValueError(f"cannot cut {self.path} of {self.size()} bytes to {size!r}")
        self._fh.truncate(size)
        self._fh.seek(size)

    def close(self) -> None:
        self._fh.close()
