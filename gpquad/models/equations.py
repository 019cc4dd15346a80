"""A discovered model: one equation per target, exportable and flyable.

model.json contract:
{"targets": {"p_dot": {"expr": "<sympy string>", "delays": {"u_R": 1, ...}, "error": ...,
             "validation_error": ..., "latex": ..., "digits": ..., "prefix": {...}}, ...},
 "seed": ..., "config": {...}, "input_names": [...], "trim": {...}, "dt": ...}
`expr` is in the model's own variables (trim-subtracted inputs); `expr_raw` writes
the same equation in the log's raw inputs (u = u' + trim). `digits`: significant digits of
every printed form (text, LaTeX), enough for it to stay the model (gpquad.models.precision);
`prefix` holds the full constants. `lag` (s, only when > 0): the equation's first-order lag,
tau d(target)/dt + target = expr (gpquad.engine.lag); `expr` is then the commanded value.
`integrator` and `substeps` (only when the scheme is not "euler"): the scheme the equations
were fitted with, which simulate and fly use (gpquad.engine.kernels.step).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy as sp

from gpquad.data.flight import Flight
from gpquad.engine.kernels.flight_arrays import FlightArrays
from gpquad.engine.kernels.quaternion import quat_from_euler, rotation_matrix
from gpquad.engine.kernels.step import SCHEMES
from gpquad.engine.kernels.tree_eval import check_stack
from gpquad.engine.tree.encoding import stack_rows
from gpquad.engine.variables import TARGET_NAMES, target_index
from gpquad.errors import GpquadError
from gpquad.models.equation import Equation, _shown
from gpquad.models.model_checks import (
    checked_input_names,
    checked_number,
    checked_targets,
    checked_trim,
)
from gpquad.study.store import read_json

#: model.json's layout: 1 = gpquad 0.1 (no "schema" key), 2 = 0.2 (unmeasured, integrator).
#: Older files are read; a newer one is refused in one line.
SCHEMA = 2

#: DiscoveredModel's optional reports: each a model.json entry of the same name when not None.
REPORTS = (
    "joint_fit",
    "stability",
    "envelope",
    "mirror_parity",
    "symmetrized",
    "refined",
    "unmeasured",
)


@dataclass
class DiscoveredModel:
    """The equations of a run, with what is needed to reproduce and fly them."""

    equations: dict[str, Equation]
    input_names: tuple[str, ...]
    trim: dict[str, float]
    dt: float
    seed: int
    config: dict
    interrupted: bool = False
    #: The joint refit's report (gpquad.models.joint_fit), or None when none was made.
    joint_fit: dict | None = None
    #: The full-model stability repair's report (gpquad.models.stability), or None.
    stability: dict | None = None
    #: {signal: [min, max]} over the training samples (gpquad.models.envelope), or None.
    envelope: dict | None = None
    #: Terms of the wrong left-right parity (gpquad.models.symmetry), or None (not checked).
    mirror_parity: dict | None = None
    #: What gpquad.models.symmetrize removed from each equation, or None (not asked).
    symmetrized: dict | None = None
    #: What gpquad.models.refine gave each equation (lag, terms), or None (not asked).
    refined: dict | None = None
    #: {target: note} of equations whose state the data does not measure, or None.
    unmeasured: dict | None = None
    #: The scheme the equations were fitted with and fly with (gpquad.engine.kernels.step);
    #: None: the config's evolution.integrator / substeps, else "euler" / 1.
    integrator: str | None = None
    substeps: int | None = None

    def __post_init__(self):
        evolution = self.config.get("evolution", {}) if isinstance(self.config, dict) else {}
        if self.integrator is None:
            self.integrator = str(evolution.get("integrator", "euler"))
        if self.substeps is None:
            self.substeps = int(evolution.get("substeps", 1))
        if self.integrator not in SCHEMES or self.substeps < 1:  # load() names the file
            raise ValueError(
                f"integrator {self.integrator!r} with {self.substeps} substeps: "
                f"use one of {sorted(SCHEMES)} and substeps >= 1"
            )

    @property
    def n_parameters(self) -> int:
        """Fitted numbers in the printed equations (Equation.n_constants, summed)."""
        return sum(e.n_constants for e in self.equations.values())

    def to_dict(self) -> dict:
        out = {
            "schema": SCHEMA,
            "targets": {
                t: self.equations[t].to_dict() for t in TARGET_NAMES if t in self.equations
            },
            "seed": self.seed,
            "config": self.config,
            "input_names": list(self.input_names),
            "trim": self.trim,
            "dt": self.dt,
        }
        if self.interrupted:
            out["interrupted"] = True
        if self.integrator != "euler":
            out["integrator"] = self.integrator
            out["substeps"] = self.substeps
        out.update(
            {name: getattr(self, name) for name in REPORTS if getattr(self, name) is not None}
        )
        return out

    @classmethod
    def from_dict(cls, d: dict) -> DiscoveredModel:
        """The model of a model.json, every field checked (gpquad.models.model_checks)."""
        if int(d.get("schema", 1)) > SCHEMA:
            raise ValueError(
                f"schema {d['schema']}: written by a newer gpquad (this one reads "
                f"up to {SCHEMA}); upgrade gpquad"
            )
        names = checked_input_names(d["input_names"])
        trim = checked_trim(d.get("trim", {}), names)
        eqs = {
            t: Equation.from_dict(t, e, names, trim)
            for t, e in checked_targets(d["targets"]).items()
        }
        return cls(
            eqs,
            names,
            dict(trim),
            checked_number(d["dt"], "dt", positive=True),
            int(d.get("seed", 0)),
            d.get("config", {}),
            bool(d.get("interrupted", False)),
            **{name: d.get(name) for name in REPORTS},
            integrator=str(d.get("integrator", "euler")),
            substeps=int(d.get("substeps", 1)),
        )

    @classmethod
    def load(cls, path) -> DiscoveredModel:
        path = Path(path)
        if path.is_dir():
            path = path / "model.json"
        d = read_json(path, "gpquad run folder", "give the folder a `gpquad run` wrote")
        try:
            return cls.from_dict(d)
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise GpquadError(
                f"not a gpquad model (bad or missing entry {exc}); give the "
                "model.json a `gpquad run` wrote",
                source=str(path),
            ) from None
        except GpquadError as exc:  # a checked field (model_checks): name the file too
            raise GpquadError(str(exc), source=str(path)) from None

    def to_sympy(self, raw: bool = False) -> dict[str, sp.Eq]:
        """Each equation as a sympy.Eq that is the model: a delayed input is its own symbol
        'u_R(t-1)' (delays in samples of self.dt), a lagged equation (Equation.lag > 0) is
        Eq(tau*Derivative(p_dot(t), t) + p_dot(t), rhs), protected division a Piecewise;
        raw=True: in the untrimmed inputs. gpquad.models.exports.sympy_equations gives the
        symbols, dt, trim and lambdify as well."""
        from gpquad.models.exports.symbolic import sympy_equations

        return sympy_equations(self, raw).equations

    def note(self, target: str) -> str:
        """Why a target's equation is not to be trusted ('' if nothing is known against it)."""
        return (self.unmeasured or {}).get(target, "")

    def latex(self, raw: bool = False) -> str:
        rows = [
            self.equations[t].latex(raw=raw)
            + (f" && \\text{{({self.note(t)})}}" if self.note(t) else "")
            for t in TARGET_NAMES
            if t in self.equations
        ]
        return (
            "\\begin{align}\n"
            + " \\\\\n".join(r.replace(" = ", " &= ", 1) for r in rows)
            + "\n\\end{align}\n"
        )

    def markdown(self) -> str:
        lines = [
            "| target | equation | train error | validation error | note |",
            "|---|---|---|---|---|",
        ]
        for t in TARGET_NAMES:
            if t in self.equations:
                e = self.equations[t]
                lines.append(
                    f"| {t} | ${e.latex()}$ | {_shown(e.error)} | "
                    f"{_shown(e.validation_error)} | {self.note(t)} |"
                )
            elif self.note(t):
                lines.append(f"| {t} | - | - | - | {self.note(t)} |")
        return "\n".join(lines) + "\n"

    def __str__(self) -> str:
        return self.text()

    def text(self, raw: bool = False) -> str:
        """The equations, one per line (raw=True: in the untrimmed inputs)."""
        return "\n".join(
            self.equations[t].text(raw=raw) + (f"   [{self.note(t)}]" if self.note(t) else "")
            if t in self.equations
            else f"{t}: {self.note(t)}"
            for t in TARGET_NAMES
            if t in self.equations or self.note(t)
        )

    def fly_states(self, inputs, initial_state=None, raw_inputs: bool = True) -> np.ndarray:
        """The flown states of `fly`: shape (N, 9), [phi, theta, psi, u, v, w, p, q, r]
        (rad, m/s, rad/s), row k at time k dt; row 0 is the initial state (its Euler angles
        as read back from the attitude quaternion).

        inputs: (N, n_inputs) control inputs, one row per sample of dt = self.dt; raw (the
        trim is subtracted here) unless raw_inputs=False. initial_state: 9 values, default
        all zero. Inputs before the first row are held at the first row; a lagged
        equation starts from zero acceleration. Targets without an equation have zero
        acceleration. This is the reference every export (gpquad.models.exports) flies to.
        """
        return self._flown(inputs, initial_state, raw_inputs, False)[0]

    def _flown(
        self, inputs, initial_state, raw_inputs: bool, keep_pos: bool
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """fly_states, and with keep_pos an RK4 model's world position (N, 3) from x = 0,
        flown as part of the RK4 state; None for eq. 2 (fly sums it from the states)."""
        inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
        n_in = len(self.input_names)
        if inputs.ndim != 2 or inputs.shape[1] != n_in or len(inputs) < 1:
            raise GpquadError(
                f"inputs must have shape (N >= 1, {n_in}) for {self.input_names}", field="inputs"
            )
        state0 = np.zeros(9) if initial_state is None else np.asarray(initial_state, float)
        if state0.shape != (9,) or not np.all(np.isfinite(state0)):
            raise GpquadError(
                "initial_state needs 9 finite values [phi, theta, psi, u, v, w, p, q, r]",
                field="initial_state",
            )
        trim = np.array([self.trim.get(n, 0.0) for n in self.input_names])
        model_inputs = inputs - trim if raw_inputs else inputs
        history = max([int(e.tree.delays.max(initial=0)) for e in self.equations.values()] + [0])
        n = len(inputs)
        rows = history + n
        padded = np.vstack([np.repeat(model_inputs[:1], history, axis=0), model_inputs])
        quat = np.zeros((rows, 4))
        quat[history] = quat_from_euler(*state0[:3])
        states = np.zeros((rows, 9))
        states[history] = state0
        arrays = FlightArrays(
            quat=quat,
            states=states,
            acc=np.zeros((rows, 6)),
            inputs=np.ascontiguousarray(padded),
            rot=np.zeros((rows, 9)),
            dt=float(self.dt),
        )
        pos = np.empty((1, n, 3)) if keep_pos and self.integrator == "rk4" else None
        flown = self._rollout(
            arrays, np.array([history]), n - 1, None, missing_from_data=False, pos=pos
        )
        return flown[0], None if pos is None else pos[0]

    def fly(self, inputs, initial_state=None, raw_inputs: bool = True) -> Flight:
        """Fly the model from an initial state with given inputs (no data needed).

        inputs: (N, n_inputs) control inputs, one row per sample of dt = self.dt; raw (the
        trim is subtracted here) unless raw_inputs=False. initial_state: 9 values
        [phi, theta, psi, u, v, w, p, q, r] (rad, m/s, rad/s), default all zero. Inputs
        before the first row are held at the first row. Targets without an equation have
        zero acceleration. Returns a Flight (NED/FRD) that gpquad.data.flight.write_flight_file
        can save; its states are `fly_states`, its position x_dot = R(q) V from x = 0 flown by
        the model's scheme: eq. 2's x' = x + R(q) V dt, or as part of an RK4 model's state.
        """
        inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
        n_in = len(self.input_names)
        if inputs.shape[1] != n_in or len(inputs) < 2:
            raise GpquadError(
                f"inputs must have shape (N >= 2, {n_in}) for {self.input_names}", field="inputs"
            )
        flown, pos = self._flown(inputs, initial_state, raw_inputs, True)
        n = len(inputs)
        out_quat = np.array([quat_from_euler(*row[:3]) for row in flown])
        if pos is None:  # eq. 2: x' = x + R(q) V dt
            world_vel = np.array([_rotate(q, v) for q, v in zip(out_quat, flown[:, 3:6])])
            pos = np.vstack([np.zeros(3), np.cumsum(world_vel[:-1] * self.dt, axis=0)])
        return Flight(
            name="simulated model",
            t=np.arange(n) * self.dt,
            quat=out_quat,
            vel=flown[:, 3:6].copy(),
            rates=flown[:, 6:9].copy(),
            inputs=inputs,
            input_names=self.input_names,
            pos=pos,
            meta={
                "source": "gpquad.models.equations.DiscoveredModel.fly",
                "equations": {t: e.text() for t, e in self.equations.items()},
            },
        )

    def simulate(self, dataset, starts, n_steps: int, input_noise=None) -> np.ndarray:
        """Fly the model over data windows: states (n_windows, n_steps + 1, 9).

        Targets without an equation use the data's accelerations. input_noise, if given,
        has shape (n_windows, n_steps, n_inputs) and is added to the recorded inputs.
        """
        return self._rollout(dataset.arrays, starts, n_steps, input_noise, missing_from_data=True)

    def kernel_trees(
        self, dt: float, missing_from_data: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The rollout kernels' model arrays (codes, values, sizes, delays, modelled,
        alphas): one tree per target (gpquad.engine.tree.encoding.stack_rows), which
        targets a tree models (else the data's acceleration when missing_from_data, or the
        constant-0 placeholder's zero), each equation's lag factor at sample period dt."""
        from gpquad.engine.lag import lag_alpha

        codes, values, sizes, delays = stack_rows(
            {target_index(t): e.tree for t, e in self.equations.items()}, 6
        )
        check_stack(codes, sizes)
        modelled = np.zeros(6, dtype=np.bool_)
        modelled[[target_index(t) for t in self.equations]] = True
        if not missing_from_data:
            modelled[:] = True  # the constant-0 placeholders give zero acceleration
        alphas = np.ones(6)
        for t, e in self.equations.items():
            alphas[target_index(t)] = lag_alpha(e.lag, dt)
        return codes, values, sizes, delays, modelled, alphas

    def _rollout(
        self,
        arrays: FlightArrays,
        starts,
        n_steps: int,
        input_noise,
        missing_from_data: bool,
        pos=None,
    ) -> np.ndarray:
        """The rollout kernel over `arrays`; targets without an equation take the data's
        acceleration (missing_from_data) or zero. pos: as rollout's (RK4 only)."""
        from gpquad.engine.kernels.rollout import rollout

        trees = self.kernel_trees(arrays.dt, missing_from_data)
        noise = np.zeros((0, 0, 0)) if input_noise is None else np.ascontiguousarray(input_noise)
        return rollout(
            *trees,
            arrays,
            np.ascontiguousarray(starts, dtype=np.int64),
            int(n_steps),
            noise,
            SCHEMES[str(self.integrator)],
            int(self.substeps or 1),
            pos,
        )


def _rotate(quat, body_vector) -> np.ndarray:
    """World vector of a body vector."""
    mat = np.empty((3, 3))
    rotation_matrix(*quat, mat)
    return mat @ body_vector
