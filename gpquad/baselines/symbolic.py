"""A parametric model dX/dt = f(X, U; theta) in sympy, its cost and its analytic gradient.

The cost is the paper's equation-error criterion

    I(theta) = 1/2 sum_k || D(k) - f(X(k), U(k); theta) ||^2,

with D(k) a finite-difference estimate of dX/dt. Its gradient is derived symbolically,

    dI/dtheta_j = - sum_k sum_r (D_r(k) - f_r(k)) * df_r/dtheta_j(k),

and both are lambdified to numpy so that a whole population (P, n_params) is evaluated
in one broadcast call over the samples (P, N).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp

from gpquad.errors import GpquadError


@dataclass
class ParametricModel:
    """Right-hand sides of a state-space model, symbolic in states, inputs and parameters.

    state_names : names of X (n_x,); input_names : names of U (n_u,)
    param_names : names of theta (n_p,); rhs : {state name: sympy expression of dX/dt}
    Only the states listed in `rhs` enter the cost (e.g. the rows of one loop).
    """

    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    param_names: tuple[str, ...]
    rhs: dict[str, sp.Expr]

    def __post_init__(self):
        self.symbols = {
            n: sp.Symbol(n, real=True)
            for n in self.state_names + self.input_names + self.param_names
        }
        known = set(self.symbols)
        for name, expr in self.rhs.items():
            if name not in self.state_names:
                raise GpquadError(f"rhs for unknown state '{name}'", field="model")
            extra = {str(s) for s in expr.free_symbols} - known
            if extra:
                raise GpquadError(f"d{name}/dt uses unknown names {sorted(extra)}", field="model")
        args = [self.symbols[n] for n in self.state_names + self.input_names + self.param_names]
        self.rows = tuple(self.rhs)
        self._f = [sp.lambdify(args, self.rhs[r], "numpy") for r in self.rows]
        self.jacobian = {
            (r, p): sp.diff(self.rhs[r], self.symbols[p])
            for r in self.rows
            for p in self.param_names
        }
        self._df = {k: sp.lambdify(args, e, "numpy") for k, e in self.jacobian.items()}

    @classmethod
    def from_function(
        cls,
        func: Callable,
        state_names: Sequence[str],
        input_names: Sequence[str],
        param_names: Sequence[str],
        rows: Sequence[str] | None = None,
    ) -> ParametricModel:
        """Build from a Python function f(X, U, theta) -> sequence of dX/dt (one per state).

        The function is called once with sympy symbols to obtain its symbolic form (so it
        must use only arithmetic and sympy-compatible functions, e.g. `sympy.sin`);
        `rows` selects the states whose equations enter the cost (default: all that
        depend on a parameter).
        """
        xs = [sp.Symbol(n, real=True) for n in state_names]
        us = [sp.Symbol(n, real=True) for n in input_names]
        ps = [sp.Symbol(n, real=True) for n in param_names]
        out = [sp.sympify(e, strict=True) for e in func(xs, us, ps)]  # no strings
        if len(out) != len(state_names):
            raise GpquadError(
                f"f returned {len(out)} rates for {len(state_names)} states", field="model"
            )
        rows = rows or [
            n for n, e in zip(state_names, out, strict=True) if e.free_symbols & set(ps)
        ]
        rhs = {n: e for n, e in zip(state_names, out, strict=True) if n in rows}
        return cls(tuple(state_names), tuple(input_names), tuple(param_names), rhs)

    def _args(self, X: np.ndarray, U: np.ndarray, theta: np.ndarray) -> list:
        """Broadcastable arguments: samples along the last axis, individuals along the first."""
        theta = np.atleast_2d(theta)
        return (
            [X[:, i][None, :] for i in range(X.shape[1])]
            + [U[:, i][None, :] for i in range(U.shape[1])]
            + [theta[:, j][:, None] for j in range(theta.shape[1])]
        )

    def predict(self, X: np.ndarray, U: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """dX/dt of the cost rows: (P, n_rows, N) for theta (P, n_p), X (N, n_x), U (N, n_u)."""
        args = self._args(X, U, theta)
        shape = (np.atleast_2d(theta).shape[0], X.shape[0])
        return np.stack([np.broadcast_to(f(*args), shape) for f in self._f], axis=1)

    def residuals(self, X, U, D, theta) -> np.ndarray:
        """D - f: (P, n_rows, N); D is (N, n_rows) in the order of `rows`."""
        return D.T[None, :, :] - self.predict(X, U, theta)

    def cost(self, X, U, D, theta) -> np.ndarray:
        """I(theta) for each individual: (P,)."""
        res = self.residuals(X, U, D, theta)
        return 0.5 * np.einsum("prn,prn->p", res, res)

    def gradient(self, X, U, D, theta) -> tuple[np.ndarray, np.ndarray]:
        """(I (P,), dI/dtheta (P, n_p)) from the symbolic Jacobian of f."""
        theta = np.atleast_2d(theta)
        args = self._args(X, U, theta)
        res = self.residuals(X, U, D, theta)
        shape = (theta.shape[0], X.shape[0])
        grad = np.zeros(theta.shape)
        for j, p in enumerate(self.param_names):
            for r_i, r in enumerate(self.rows):
                if self.jacobian[(r, p)] == 0:
                    continue
                df = np.broadcast_to(self._df[(r, p)](*args), shape)
                grad[:, j] -= np.einsum("pn,pn->p", res[:, r_i], df)
        return 0.5 * np.einsum("prn,prn->p", res, res), grad

    def equations(
        self, theta: np.ndarray | None = None, digits: int | None = None
    ) -> dict[str, str]:
        """Sympy-parsable strings of the cost rows, with parameter values substituted if given."""
        out = {}
        for r in self.rows:
            expr = self.rhs[r]
            if theta is not None:
                expr = expr.xreplace(
                    {
                        self.symbols[p]: sp.Float(float(v))
                        for p, v in zip(self.param_names, theta, strict=True)
                    }
                )
            out[r] = sp.sstr(expr if digits is None else expr.evalf(digits), full_prec=True)
        return out


def finite_difference(X: np.ndarray, dt: float, scheme: str = "forward") -> np.ndarray:
    """Estimate dX/dt at samples 0..N-2 ('forward') from X (N, n), dt s: (N-1, n).

    'central' uses (X[k+1] - X[k-1]) / 2dt inside and forward at k = 0.
    """
    if scheme == "forward":
        return np.diff(X, axis=0) / dt
    if scheme == "central":
        out = np.empty((X.shape[0] - 1, X.shape[1]))
        out[0] = (X[1] - X[0]) / dt
        out[1:] = (X[2:] - X[:-2]) / (2 * dt)
        return out
    raise GpquadError(
        f"unknown difference scheme '{scheme}'; choose forward or central", field="ga.difference"
    )
