"""Generate every rotorpy flight of the benchmark (every fleet, angle and rate mode, clean,
noisy and the noise family).

    python benchmarks/make_rotorpy_flights.py [--out results/benchmark_data/rotorpy]

Seeds are fixed (gpquad.benchmark.rotorpy_flights.flight_plan); flights already cached with
the same settings are kept. Prints the time each scenario took and where its files are.
"""

from __future__ import annotations

import argparse
import time

from gpquad.benchmark.rotorpy_flights import ensure_flights
from gpquad.benchmark.scenarios import ROTORPY

DEFAULT_OUT = "results/benchmark_data/rotorpy"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=DEFAULT_OUT, help=f"cache folder (default {DEFAULT_OUT})")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    for name, (mode, noise, fleet) in ROTORPY.items():
        t0 = time.perf_counter()
        res = ensure_flights(
            mode,
            noise > 0,
            args.out,
            fleet=fleet,
            noise_scale=max(noise, 1),
            progress=lambda m: print(" ", m, flush=True),
        )
        n = sum(len(res[r]) for r in ("train", "validation", "test"))
        print(
            f"{name}: {n} flights, seeds {res['seeds']}, {time.perf_counter() - t0:.1f} s -> "
            f"{res['train'][0].rsplit('/', 1)[0]}",
            flush=True,
        )
    print(f"total {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
