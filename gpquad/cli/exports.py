"""The commands that take a run's equations away: `gpquad export` (text, code for a
simulator) and `gpquad fly` (the equations flown on new inputs)."""

from __future__ import annotations

import sys
from pathlib import Path

from gpquad.errors import GpquadError


def cmd_export(args) -> int:
    from gpquad.models.equations import DiscoveredModel
    from gpquad.models.exports import export, write_export

    model = DiscoveredModel.load(args.run)
    warn_interrupted(model, args.run)
    if args.out:
        for path in write_export(model, args.format, args.out, raw=args.raw_inputs):
            print(f"wrote {path}")
        return 0
    result = export(model, args.format, **({"raw": True} if args.raw_inputs else {}))
    if isinstance(result, dict):  # c: the header, then the source
        result = "".join(
            f"/* ---- {name} ---- */\n{text}\n"
            for name, text in sorted(result.items(), key=lambda kv: kv[0][-1])
        )
    print(result, end="" if result.endswith("\n") else "\n")
    return 0


def warn_interrupted(model, run) -> None:
    """One warning line when the model is that of an interrupted run."""
    if model.interrupted:
        print(
            f"gpquad: warning: {run}: the run was interrupted; these are the equations found "
            "so far (the same `gpquad run` command resumes it)",
            file=sys.stderr,
        )


def cmd_fly(args) -> int:
    import numpy as np
    import pandas as pd

    from gpquad.data.flight import write_flight_file
    from gpquad.engine.variables import TARGET_NAMES
    from gpquad.models.equations import DiscoveredModel

    model = DiscoveredModel.load(args.run)
    path = Path(args.inputs)
    if not path.is_file():
        raise GpquadError("file not found", source=str(path))
    warn_interrupted(model, args.run)
    if path.suffix.lower() in (".parquet", ".pq"):
        from gpquad.extras import require

        require("pyarrow", "reading Parquet files")
    try:
        table = (
            pd.read_parquet(path)
            if path.suffix.lower() in (".parquet", ".pq")
            else pd.read_csv(path)
        )
    except (
        ValueError,
        OSError,
        UnicodeDecodeError,
        pd.errors.ParserError,
        pd.errors.EmptyDataError,
    ) as exc:
        raise GpquadError(
            f"not a readable table ({type(exc).__name__}); give a UTF-8 CSV or a "
            "Parquet file with a column per input",
            source=str(path),
        ) from None
    missing = [n for n in model.input_names if n not in table.columns]
    if missing:
        raise GpquadError(f"missing input columns {missing}", source=str(path), field=missing[0])
    absent = [t for t in TARGET_NAMES if t not in model.equations]
    if absent and not args.zero_missing:
        raise GpquadError(
            f"the run has no equation for {absent}; identify all six targets, or "
            "give --zero-missing to fly them as zero acceleration",
            source=str(args.run),
            field="targets",
        )
    try:
        clock = table["t"].to_numpy(dtype=float) if "t" in table.columns else None
        inputs = table[list(model.input_names)].to_numpy(dtype=float)
    except (ValueError, TypeError):
        raise GpquadError(
            "the time and input columns must hold numbers",
            source=str(path),
            field=model.input_names[0],
        ) from None
    if len(inputs) < 2:
        raise GpquadError(
            f"{len(inputs)} rows; give at least 2 samples of the inputs",
            source=str(path),
            field=model.input_names[0],
        )
    if clock is not None:
        check_input_clock(clock, model.dt, str(path))
    if not np.all(np.isfinite(inputs)):
        raise GpquadError("inputs contain NaN", source=str(path), field=model.input_names[0])
    initial = None
    if args.initial:
        try:
            initial = [float(x) for x in args.initial.split(",")]
        except ValueError:
            raise GpquadError(
                "--initial takes 9 numbers: phi,theta,psi,u,v,w,p,q,r", field="--initial"
            ) from None
    flight = model.fly(inputs, initial, raw_inputs=not args.trimmed)
    out = write_flight_file(flight, args.out)
    print(
        f"flew {len(flight)} samples ({len(flight) * model.dt:.1f} s) with the equations of "
        f"{args.run}; wrote {out}"
    )
    return 0


def check_input_clock(t, dt: float, source: str) -> None:
    """The inputs' time column must tick at the model's sample time (inputs are not resampled)."""
    import numpy as np

    steps = np.diff(t)
    if len(steps) and (
        not np.all(np.isfinite(steps))
        or np.max(np.abs(steps - dt)) > 1e-6 * max(dt, 1.0) + 1e-9 * abs(t).max()
    ):
        raise GpquadError(
            f"the inputs are not sampled every {dt:g} s, the model's sample time "
            f"(steps {np.min(steps):.6g} to {np.max(steps):.6g} s); resample them "
            "to the model's rate",
            source=source,
            field="t",
        )
