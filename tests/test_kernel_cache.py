"""The kernels' cache folder is named by a digest of every kernel source
(gpquad.engine.numba_config): a kernel that inlines a helper from another file is compiled
again when that file changes, which numba's own cache key (the kernel's file) misses."""

import ast
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numba.core.config
import pytest

from gpquad.engine import numba_config
from gpquad.engine.numba_config import (
    CACHE_FOLDER,
    KERNEL_SOURCES,
    PACKAGE,
    cache_folder,
    kernel_files,
    prune_stale,
    sources_digest,
)


def _defines_kernel(path: Path) -> bool:
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for dec in node.decorator_list:
                target = dec.func if isinstance(dec, ast.Call) else dec
                if isinstance(target, ast.Name) and target.id == "njit":
                    return True
                if isinstance(target, ast.Attribute) and target.attr == "njit":
                    return True
    return False


def _gpquad_imports(path: Path) -> set[Path]:
    """The files of the gpquad modules `path` imports (anywhere in it)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            if name == "gpquad" or not name.startswith("gpquad."):
                continue
            rel = Path(*name.split(".")[1:])
            for candidate in (PACKAGE / rel.with_suffix(".py"), PACKAGE / rel / "__init__.py"):
                if candidate.exists():
                    found.add(candidate)
    return found


def uncovered(patterns) -> list[str]:
    """Files that a kernel compiles in and `patterns` leave out."""
    covered = set(kernel_files(PACKAGE, patterns))
    kernels = {
        p
        for p in PACKAGE.rglob("*.py")
        if "__pycache__" not in p.parts and p != PACKAGE / "engine/numba_config.py"
        if _defines_kernel(p)
    }
    needed = set(kernels)
    for f in kernels:
        needed |= _gpquad_imports(f)
    return sorted(str(p.relative_to(PACKAGE)) for p in needed - covered)


def test_the_sources_cover_every_kernel_and_what_it_imports():
    assert uncovered(KERNEL_SOURCES) == []


def test_the_coverage_check_finds_a_missing_file():
    fewer = tuple(p for p in KERNEL_SOURCES if p != "engine/tree/operators.py")
    assert uncovered(fewer) == ["engine/tree/operators.py"]
    fewer = tuple(p for p in KERNEL_SOURCES if p != "control/pid_kernel.py")
    assert uncovered(fewer) == ["control/pid_kernel.py"]


def test_the_digest_follows_every_file(tmp_path):
    (tmp_path / "a.py").write_text("X = 1\n")
    (tmp_path / "b.py").write_text("Y = 2\n")
    files = kernel_files(tmp_path, ("*.py",))
    first = sources_digest(files, tmp_path)
    assert sources_digest(files, tmp_path) == first
    (tmp_path / "b.py").write_text("Y = 3\n")
    assert sources_digest(files, tmp_path) != first
    (tmp_path / "b.py").write_text("Y = 2\n")
    assert sources_digest(files, tmp_path) == first
    (tmp_path / "b.py").rename(tmp_path / "c.py")
    assert sources_digest(kernel_files(tmp_path, ("*.py",)), tmp_path) != first


def test_the_folder_is_under_numba_cache_dir_or_the_user_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    assert cache_folder("abc") == tmp_path / "numba" / "kernels-abc"
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_folder("abc") == tmp_path / "xdg" / "gpquad" / "kernels-abc"
    assert (tmp_path / "xdg" / "gpquad" / "kernels-abc").is_dir()
    (tmp_path / "a-file").write_text("")  # a cache home that cannot hold a folder
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "a-file"))
    assert cache_folder("abc") == PACKAGE / "__pycache__" / "kernels-abc"


def test_stale_folders_of_other_sources_are_deleted(monkeypatch, tmp_path):
    day = 86400.0
    parent = tmp_path / "xdg" / "gpquad"
    for name, age_days in (("kernels-old", 40), ("kernels-recent", 5), ("kernels-mine", 90)):
        (parent / name / "sub").mkdir(parents=True)
        (parent / name / "sub" / "k.nbi").write_text("")
        then = os.stat(parent / name).st_mtime - age_days * day
        os.utime(parent / name, (then, then))
    (parent / "other-old").mkdir()  # not a kernel folder: left alone
    then = os.stat(parent / "other-old").st_mtime - 90 * day
    os.utime(parent / "other-old", (then, then))
    assert prune_stale(parent, parent / "kernels-mine") == [parent / "kernels-old"]
    assert sorted(p.name for p in parent.iterdir()) == [
        "kernels-mine",
        "kernels-recent",
        "other-old",
    ]
    # cache_folder marks its own folder as used now and prunes the rest
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    then = os.stat(parent / "kernels-recent").st_mtime - 30 * day
    os.utime(parent / "kernels-recent", (then, then))
    assert cache_folder("mine") == parent / "kernels-mine"
    assert sorted(p.name for p in parent.iterdir()) == ["kernels-mine", "other-old"]


def test_kernels_cache_there_and_numba_setting_is_given_back():
    from gpquad.engine.kernels.fitness import euler_population_window_errors
    from gpquad.engine.kernels.tree_eval import run_program

    for kernel in (euler_population_window_errors, run_program):
        assert Path(kernel._cache._cache_path).is_relative_to(CACHE_FOLDER)
    assert numba.core.config.CACHE_DIR != str(CACHE_FOLDER)
    assert numba_config.CACHE_FOLDER.name.startswith("kernels-")


@pytest.mark.skipif(numba.core.config.DISABLE_JIT, reason="no compiled kernels")
def test_a_changed_helper_in_another_file_is_compiled_again(tmp_path):
    """euler_angle_lanes (quaternion.py) inlines arctrig.py's asin. A copy of the package
    flies it, arctrig.py's first asin coefficient is changed, and it flies again: the
    result must change, although quaternion.py did not."""
    copy = tmp_path / "pkg" / "gpquad"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    script = textwrap.dedent(
        """
        import numpy as np
        from gpquad.engine.kernels.quaternion import euler_angle_lanes
        from gpquad.engine.numba_config import python_callable
        quat = np.array([[0.9], [0.1], [0.3], [0.2]])
        quat /= np.sqrt((quat ** 2).sum())
        out = np.empty(1)
        python_callable(euler_angle_lanes)(1, quat, 0, out, 1, np.empty(1), np.empty(1))
        print(repr(float(out[0])))
        """
    )
    env = dict(os.environ, PYTHONPATH=str(copy.parent), NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def fly() -> str:
        done = subprocess.run(
            [sys.executable, "-c", script],
            env=env,
            cwd=tmp_path,  # not the checkout's folder, whose gpquad would come first
            capture_output=True,
            text=True,
            check=True,
        )
        return done.stdout.strip()

    before = fly()
    assert fly() == before  # from the cache
    assert len(list((tmp_path / "cache").iterdir())) == 1
    arctrig = copy / "engine" / "kernels" / "arctrig.py"
    text = arctrig.read_text()
    assert "_PS0 = 1.66666666666666657415e-01" in text
    arctrig.write_text(text.replace("_PS0 = 1.66666666666666657415e-01", "_PS0 = 0.2"))
    assert fly() != before
    assert len(list((tmp_path / "cache").iterdir())) == 2
