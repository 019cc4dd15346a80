"""From a DataFrame to C code that flies the identified model: a notebook's workflow.

    python examples/notebook_workflow.py            # about a minute on one core

1. a flight as a pandas DataFrame (here gpquad's reference simulator; your own log's columns
   are the same: t, qw..qz, u v w, p q r and the inputs),
2. fit the six equations,
3. score them on another flight, beside the zero model,
4. fly them over that flight's windows,
5. export C, compile it, and fly it from the inputs alone: it matches `model.fly`.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import gpquad


def main(out_dir: Path) -> float:
    """Runs the workflow; returns the largest relative difference between the compiled C
    model's flight and `model.fly` (nan when no C compiler is found)."""
    # 1-2. fit: a DataFrame in, a Model out (small budget: 3 iterations, one delay per input)
    flight = gpquad.reference_flight(seed=0, duration_s=300.0)
    model = gpquad.fit(flight, seed=1, iterations=3, input_taps=1)
    print(model)

    # 3. score on a flight the fit never saw: RSE of the integrated states at 7 s
    other = gpquad.reference_flight(seed=7, duration_s=60.0)
    print(model.score(other, horizon_s=7.0).round(6))

    # 4. simulate: the equations flown over 7 s windows of the other flight
    flown = model.simulate(other, horizon_s=7.0)
    print(
        f"flown {flown['window'].nunique()} windows; largest |p error| "
        f"{np.abs(flown['p'] - flown['p_data']).max():.3g} rad/s"
    )

    # 5. export C, compile, fly from the inputs alone, compare with model.fly
    paths = model.export("c", out_dir / "quad_model.c")
    print("wrote", ", ".join(str(p) for p in paths))
    inputs = other[["t", *model.input_names]]
    x0 = {"phi": 0.05, "p": 0.1}
    reference = model.fly(inputs, x0)
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        print("no C compiler found: skipped compiling the export")
        return float("nan")
    library = out_dir / "libquad_model.so"
    subprocess.run(
        [
            compiler,
            "-std=c99",
            "-O2",
            "-shared",
            "-fPIC",
            "-o",
            str(library),
            str(out_dir / "quad_model.c"),
            "-lm",
        ],
        check=True,
    )
    lib = ctypes.CDLL(str(library))
    double_p = ctypes.POINTER(ctypes.c_double)
    lib.gpquad_fly.argtypes = [double_p, ctypes.c_int, double_p, double_p]
    lib.gpquad_fly.restype = ctypes.c_int
    raw = np.ascontiguousarray(inputs[list(model.input_names)].to_numpy(dtype=float))
    state0 = np.zeros(9)
    for name, value in x0.items():
        state0["phi theta psi u v w p q r".split().index(name)] = value
    states = np.zeros((len(raw), 9))
    code = lib.gpquad_fly(
        raw.ctypes.data_as(double_p),
        len(raw),
        state0.ctypes.data_as(double_p),
        states.ctypes.data_as(double_p),
    )
    assert code == 0, f"gpquad_fly returned {code}"
    expected = reference[["phi", "theta", "psi", "u", "v", "w", "p", "q", "r"]].to_numpy()
    scale = np.maximum(np.abs(expected), 1.0)
    difference = float(np.max(np.abs(states - expected) / scale))
    print(
        f"compiled C model flies {len(raw)} samples; largest relative difference from "
        f"model.fly: {difference:.3g}"
    )
    return difference


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
    folder.mkdir(parents=True, exist_ok=True)
    main(folder)
