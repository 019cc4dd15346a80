"""`gpquad.Model`: a fitted model as a user holds it (gpquad.fit, gpquad.load).

It wraps the engine's DiscoveredModel (gpquad.models.equations) with DataFrame in, DataFrame
out methods: predict (one-step accelerations), simulate (flown windows of a flight), score
(RSE beside the zero model), fly (from inputs alone) and export.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import sympy as sp

from gpquad.data.flight import DT_TOLERANCE, Flight, flights_of
from gpquad.engine.variables import STATE_NAMES, TARGET_NAMES, target_index
from gpquad.errors import GpquadError
from gpquad.models.equations import DiscoveredModel


@dataclasses.dataclass(frozen=True)
class EquationForms:
    """One equation in every printed form.

    Attributes
    ----------
    target : str
        The acceleration it gives ("p_dot").
    text : str
        One line, delayed inputs written ``u_R(t-1)`` (delays in samples of dt).
    latex : str
        LaTeX of the same equation.
    sympy : sympy.Eq
        The equation: each delayed input is its own symbol named ``u_R(t-k)``, a lagged
        equation reads ``Eq(tau*Derivative(p_dot(t), t) + p_dot(t), rhs)``, and protected
        division is a ``Piecewise`` (``sympy.lambdify`` of ``.rhs`` gives the model's value).
    lag : float
        Time constant (s) of the first-order lag: ``lag * d(target)/dt + target = sympy``
        (0: none, ``target = sympy``).
    delays : dict
        Delay (samples) of every input the equation reads.
    """

    target: str
    text: str
    latex: str
    sympy: sp.Expr
    lag: float
    delays: dict


class Model:
    """Six (or fewer) discovered equations with what is needed to fly them.

    Parameters
    ----------
    discovered : DiscoveredModel
        The engine's model (model.json).
    config : Config, optional
        The config it was fitted with (recorded in the model too).
    profile : dict, optional
        Where the fit's time went, in seconds: ``{"search": {target: s}, "finish":
        {step: s}}`` (`fit` sets it; a loaded model has none).
    """

    def __init__(self, discovered: DiscoveredModel, config=None, profile: dict | None = None):
        self.discovered = discovered
        self.config = config
        self.profile = profile

    # ------------------------------------------------------------------ description
    @property
    def dt(self) -> float:
        """Sample period (s); equation delays are whole samples of it."""
        return float(self.discovered.dt)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.discovered.input_names)

    @property
    def trim(self) -> dict[str, float]:
        """Subtracted from the raw inputs before the equations read them."""
        return dict(self.discovered.trim)

    @property
    def targets(self) -> tuple[str, ...]:
        return tuple(t for t in TARGET_NAMES if t in self.discovered.equations)

    @property
    def equations(self) -> dict[str, EquationForms]:
        """{target: EquationForms} in the order a_x, a_y, a_z, p_dot, q_dot, r_dot."""
        from gpquad.models.exports import sympy_equations

        exact = sympy_equations(self.discovered).equations
        out = {}
        for t in self.targets:
            e = self.discovered.equations[t]
            out[t] = EquationForms(t, e.text(), e.latex(), exact[t], float(e.lag), e.used_delays())
        return out

    def __str__(self) -> str:
        head = f"dt = {self.dt:g} s (delays u(t-k) in samples)"
        if any(self.trim.values()):
            trims = ", ".join(f"{n} {v:.6g}" for n, v in self.trim.items() if v)
            head += f"; inputs trim-subtracted ({trims})"
        return head + "\n" + self.discovered.text()

    def __repr__(self) -> str:
        flag = ", interrupted" if self.discovered.interrupted else ""
        return (
            f"<gpquad.Model {len(self.targets)} equations ({', '.join(self.targets)}), "
            f"dt={self.dt:g} s, {self.discovered.n_parameters} constants{flag}>"
        )

    # ------------------------------------------------------------------ data
    def _dataset(self, data, trimmed: bool = True):
        """The data as a dataset whose every sample is scored, inputs in the model's view
        (trim subtracted) unless `trimmed` is False."""
        from gpquad.data.dataset import build_dataset
        from gpquad.models.scoring import model_view

        flights = self._flights(data)
        dataset = build_dataset(flights, validation_fraction=0.0, held_out=[True] * len(flights))
        if abs(dataset.dt - self.dt) > DT_TOLERANCE * self.dt:
            raise GpquadError(
                f"the data's sample period is {dataset.dt:.6g} s but the model's "
                f"delays are samples of {self.dt:.6g} s; resample the data",
                field="t",
            )
        return model_view(dataset, self.trim) if trimmed else dataset

    def _flights(self, data) -> list[Flight]:
        from gpquad.data.io import read_log_file
        from gpquad.study.config import DataConfig

        def read(path) -> list[Flight]:
            data = DataConfig() if self.config is None else self.config.data
            data = dataclasses.replace(data, inputs=self.input_names, files=(str(path),))
            return read_log_file(path, data)

        items = list(data) if isinstance(data, (list, tuple)) else [data]
        flights = flights_of(items, self.input_names, read=read)
        for f in flights:
            if tuple(f.input_names) != self.input_names:
                raise GpquadError(
                    f"the model reads inputs {list(self.input_names)} but the "
                    f"data gives {list(f.input_names)}",
                    source=f.name,
                    field="inputs",
                )
        return flights

    # ------------------------------------------------------------------ use
    def predict(self, data) -> pd.DataFrame:
        """One-step accelerations of every equation on the data's states and inputs.

        Returns
        -------
        DataFrame
            Index: sample of the concatenated flights (those with a full input history);
            columns ``t`` (s, within its flight), ``flight`` and one per target (m/s^2,
            rad/s^2). A lagged equation's value is its applied acceleration after one
            step of its lag from the data's acceleration.
        """
        from gpquad.engine.kernels.tree_eval import eval_on_samples
        from gpquad.engine.lag import lag_alpha
        from gpquad.engine.taps import with_taps

        dataset = self._dataset(data)
        history = self._history()
        rows = np.concatenate([np.arange(a + history, b) for a, b in dataset.segments])
        flight = np.concatenate(
            [np.full(b - a - history, k) for k, (a, b) in enumerate(dataset.segments)]
        )
        starts = np.array([a for a, _ in dataset.segments])
        out = {"t": (rows - starts[flight]) * dataset.dt, "flight": flight}
        arrays = dataset.arrays
        for t in self.targets:
            tree, lag = self.discovered.equations[t].tree, self.discovered.equations[t].lag
            taps = len(tree.delays) // len(self.input_names)
            inputs = with_taps(dataset, taps).arrays.inputs
            pred = eval_on_samples(
                tree.codes, tree.values, tree.size, tree.delays, arrays.states, inputs, rows
            )
            alpha = lag_alpha(lag, self.dt)
            if alpha < 1.0:
                before = arrays.acc[rows - 1, target_index(t)]
                pred = before + alpha * (pred - before)
            out[t] = pred
        return pd.DataFrame(out, index=rows)

    def _history(self) -> int:
        return max(
            [int(np.max(e.tree.delays, initial=0)) for e in self.discovered.equations.values()]
            + [1]
        )

    def _windows(self, dataset, horizon_s: float):
        from gpquad.models.scoring import validation_windows

        if not np.isfinite(horizon_s) or horizon_s <= 0:
            raise GpquadError(
                f"horizon_s must be a positive number of seconds, got {horizon_s}",
                field="horizon_s",
            )
        steps = max(1, int(round(horizon_s / dataset.dt)))
        return validation_windows(dataset, steps, self._history())

    def simulate(self, data, horizon_s: float = 7.0) -> pd.DataFrame:
        """Fly the equations over consecutive windows of the data, each from the data's
        state at its start, driven by the recorded inputs.

        Returns
        -------
        DataFrame
            Columns ``window``, ``t`` (s from the window's start), the nine flown states
            ``phi theta psi u v w p q r`` and the data's, suffixed ``_data``.
        """
        dataset = self._dataset(data)
        starts, steps = self._windows(dataset, horizon_s)
        with np.errstate(all="ignore"):
            flown = self.discovered.simulate(dataset, starts, steps)
        truth = dataset.arrays.states[starts[:, None] + np.arange(steps + 1)[None, :]]
        n = len(starts)
        frame = {
            "window": np.repeat(np.arange(n), steps + 1),
            "t": np.tile(np.arange(steps + 1) * dataset.dt, n),
        }
        frame.update({s: flown[:, :, i].ravel() for i, s in enumerate(STATE_NAMES)})
        frame.update({f"{s}_data": truth[:, :, i].ravel() for i, s in enumerate(STATE_NAMES)})
        return pd.DataFrame(frame)

    def score(self, data, horizon_s: float = 7.0) -> pd.DataFrame:
        """RSE of the integrated states over consecutive windows of `horizon_s`, beside the
        zero model (every acceleration zero), flown the same way.

        RSE = sum of squared errors / sum of squared deviations of the data from its mean,
        per state over the windows; 1 is no better than the data's mean; a diverged window
        (non-finite, or beyond 10x the largest |state| of the windows) is left out and
        counted. On rate set-point inputs the set-point model (each rate follows its
        set-point) is scored too.

        Returns
        -------
        DataFrame
            Rows ``model``, ``zero`` (and ``set-point``); columns u, v, w, p, q, r,
            ``diverged``, ``windows`` and ``horizon_s``.
        """
        from gpquad.models.reference_models import reference_models
        from gpquad.models.scoring import flown_score, windows_bound

        dataset = self._dataset(data)
        raw = self._dataset(data, trimmed=False)
        starts, steps = self._windows(dataset, horizon_s)
        bound = windows_bound(dataset, starts, steps)

        flown = {"model": flown_score(self.discovered, dataset, starts, steps, bound)}
        for name, reference in reference_models(self.input_names, self.dt, raw.flight_info).items():
            flown[name] = flown_score(reference, raw, starts, steps, bound)
        rows = {
            name: {**row, "windows": int(len(starts)), "horizon_s": float(steps * dataset.dt)}
            for name, row in flown.items()
        }
        return pd.DataFrame.from_dict(rows, orient="index")

    def fly(self, inputs: pd.DataFrame, x0=None) -> pd.DataFrame:
        """Fly the model from an initial state, driven by raw inputs alone (no data).

        Parameters
        ----------
        inputs : DataFrame
            One column per model input (by name; other columns are ignored), one row per
            sample of dt; an optional ``t`` column (s) must step by the model's dt. Rows
            before the first are held at the first.
        x0 : sequence of 9 floats or dict, optional
            Initial ``phi theta psi`` (rad), ``u v w`` (m/s), ``p q r`` (rad/s); a dict may
            name some of them; default all zero.

        Returns
        -------
        DataFrame
            ``t`` and the nine flown states, one row per input row.
        """
        if not isinstance(inputs, pd.DataFrame):
            raise GpquadError(
                f"inputs must be a DataFrame with the columns "
                f"{list(self.input_names)} (named, not by position)",
                field="inputs",
            )
        missing = [n for n in self.input_names if n not in inputs.columns]
        if missing:
            raise GpquadError(
                f"inputs lack the columns {missing}; the model reads {list(self.input_names)}",
                field="inputs",
            )
        if "t" in inputs.columns and len(inputs) > 1:
            steps = np.diff(inputs["t"].to_numpy(dtype=float))
            if not np.all(np.abs(steps - self.dt) <= DT_TOLERANCE * self.dt):
                raise GpquadError(
                    f"column t steps by {np.median(steps):.6g} s but the model's "
                    f"dt is {self.dt:.6g} s; resample the inputs",
                    field="t",
                )
        state0 = np.zeros(9)
        if isinstance(x0, dict):
            unknown = [k for k in x0 if k not in STATE_NAMES]
            if unknown:
                raise GpquadError(
                    f"unknown states {unknown}; name some of {list(STATE_NAMES)}", field="x0"
                )
            for k, v in x0.items():
                state0[STATE_NAMES.index(k)] = float(v)
        elif x0 is not None:
            state0 = np.asarray(x0, dtype=float)
        values = inputs[list(self.input_names)].to_numpy(dtype=float)
        flight = self.discovered.fly(values, state0)
        from gpquad.engine.kernels.quaternion import euler_array

        angles = euler_array(np.ascontiguousarray(flight.quat))
        frame = {"t": flight.t}
        frame.update({s: angles[:, i] for i, s in enumerate(STATE_NAMES[:3])})
        frame.update({s: flight.vel[:, i] for i, s in enumerate(STATE_NAMES[3:6])})
        frame.update({s: flight.rates[:, i] for i, s in enumerate(STATE_NAMES[6:9])})
        return pd.DataFrame(frame)

    def export(self, fmt: str, path=None, raw: bool = False):
        """The model in another form, every one stating dt, the delays, the lags and the trim.

        Parameters
        ----------
        fmt : str
            "text", "latex", "markdown", "json" (model.json), "sympy" (a script of sympy
            equations), "python" (a numpy module: ``fly`` flies the model as gpquad does,
            ``rhs`` is the continuous-time right-hand side), "c" (a C99 source and header
            with ``gpquad_fly`` and ``gpquad_rhs``) or "casadi" (a casadi Function, needs
            the ``casadi`` extra).
        path : str or Path, optional
            Write there ("c": ``model.c`` writes model.c and model.h) and return the paths;
            default: return the text ({file name: text} for "c").
        raw : bool
            text, latex, sympy: write the equations in the raw (untrimmed) inputs.
        """
        from gpquad.models.exports import export, write_export

        if path is None:
            return export(self.discovered, fmt, **({"raw": True} if raw else {}))
        return write_export(self.discovered, fmt, path, raw)

    def save(self, path) -> Path:
        """Write model.json to `path` (a folder or a .json file); gpquad.load reads it."""
        from gpquad.study.store import write_json

        path = Path(path)
        target = path if path.suffix == ".json" else path / "model.json"
        write_json(target, self.discovered.to_dict())
        return target
