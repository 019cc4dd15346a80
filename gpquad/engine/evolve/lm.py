"""Least-squares fits whose result is a function of their inputs: gpquad's own
Levenberg-Marquardt, for the search's constant fits and the joint refit.

scipy 1.17.1's `least_squares(method="lm")` and `leastsq` (MINPACK) take other trial points
for bit-identical inputs depending on which least-squares fits ran before in the process
(`benchmarks/lm_state.py` reproduces it on one of the engine's problems; with fixed
scaling, MINPACK mode 2, about one replay in twenty, once in CI); the search amplifies that
into other equations for the same seed in another process. `levenberg_marquardt` is
therefore gpquad's own: MINPACK's algorithm in mode 2 (Moré's trust-region LM, variables
scaled, fixed, by the first Jacobian's column norms), rewritten with every reduction,
factorisation and solve in numba loops of fixed order (gpquad.engine.kernels.least_squares;
each Jacobian's R from the normal equations, the QR where they are ill-conditioned): no
BLAS, whose summation order may change with the thread count or memory alignment.

The joint refit (up to 80 constants, 10^5 residuals) forms its normal equations in BLAS
on one thread, as every finish runs (`normal_triangularize`).
Its Jacobian is a sensitivity flight for a continuous-time model
(gpquad.models.joint_jacobian); otherwise `forward_difference` gives one (scipy's
'2-point' step) whose result is also a function of the inputs alone. `broyden_jacobian`
asks for it at every few points only and updates it by Broyden's secant update in between.
"""

from __future__ import annotations

import numpy as np

from gpquad.engine.kernels import least_squares as kernels
from gpquad.engine.threads import thread_map

#: Relative step of the forward differences: sqrt(machine epsilon), scipy's '2-point' step.
FD_STEP = float(np.sqrt(np.finfo(float).eps))
#: Stopping tolerances of the LM: MINPACK's defaults in scipy's leastsq (sqrt(eps)).
FTOL = XTOL = 1.49012e-8
#: MINPACK's trust-region settings: first radius factor, acceptance ratio, Newton
#: corrections of the damping per step.
RADIUS_FACTOR = 100.0
ACCEPT_RATIO = 1e-4
MU_ITERATIONS = 10
#: The stall rule (steps, relative drop) of the search's final selection by BIC (the
#: default; the paper preset's pruning keeps its fits as they were): a fit stops once that
#: many taken steps together lowered the sum by at most that fraction of it
#: (docs/decisions/2026-11-27-jacobians.md). The refinement has its own,
#: gpquad.models.refine_problem.STALL.
STALL = (2, 1e-3)


def column_norms(j: np.ndarray) -> np.ndarray:
    """The fixed variable scaling of both fits: the column norms of the first Jacobian j, 1
    where a column is zero or not finite."""
    out = np.empty(j.shape[1])
    kernels.column_norms(np.ascontiguousarray(j, dtype=float), out)
    return out


def _norm(v: np.ndarray) -> float:
    return float(np.sqrt(kernels.sum_squares(np.ascontiguousarray(v))))


def _damping_for_radius(r, qtr, radius: float, mu: float, h: np.ndarray) -> float:
    """Moré's (1978) choice of the damping mu: the Gauss-Newton step (mu = 0) when it lies
    within 1.1 radius, else mu with |h(mu)| within 10 % of the radius (at most
    MU_ITERATIONS Newton corrections, safeguarded by bounds). Writes the step into h."""
    z2 = kernels.damped_step(r, qtr, 0.0, h)
    step = _norm(h) if z2 >= 0.0 else np.inf
    if step <= 1.1 * radius:
        return 0.0
    lower = (step - radius) / radius * step * step / z2 if z2 > 0.0 and np.isfinite(step) else 0.0
    upper = kernels.gradient_norm(r, qtr) / radius
    if upper <= 0.0:
        upper = np.finfo(float).tiny / min(radius, 0.1)
    mu = min(max(mu, lower), upper)
    if mu == 0.0:
        mu = upper * 1e-3
    for _ in range(MU_ITERATIONS):
        z2 = kernels.damped_step(r, qtr, mu, h)
        step = _norm(h)
        excess = step - radius
        if abs(excess) <= 0.1 * radius or z2 <= 0.0:
            break
        if excess > 0.0:
            lower = max(lower, mu)
        else:
            upper = min(upper, mu)
        mu = max(lower, mu + step * step / z2 * excess / radius)
    return mu


def levenberg_marquardt(
    fun,
    x0: np.ndarray,
    jac,
    max_nfev: int,
    ftol: float = FTOL,
    xtol: float = XTOL,
    stall: tuple[int, float] | None = None,
    triangularize=None,
) -> np.ndarray:
    """Minimise sum(fun(x)^2) from x0 with the analytic Jacobian jac(x) (rows = residuals),
    at most max_nfev evaluations of fun after the one at x0; jac is asked only at x0 and at
    accepted points, after fun there (a caller that computes both at once pays nothing).

    MINPACK's lmder in mode 2 (Moré 1978; one deviation: when the damping is 0 and the
    Gauss-Newton step is too long, the Newton iteration starts from 1e-3 of its upper bound
    where lmpar starts from |gradient| / |Gauss-Newton step|): a trust region in the
    variables scaled by the
    first Jacobian's column norms, RADIUS_FACTOR x the scaled |x0| at first; the step is
    the Gauss-Newton step when it fits, else the damped step of the radius's length; taken
    when the actual drop of the sum is at least ACCEPT_RATIO of the predicted one; the
    radius halves (or shrinks to a tenth after a blow-up) when that ratio is below 1/4 and
    doubles the step when it is above 3/4. Stops when the actual and predicted relative
    drops are at most ftol, or the radius is at most xtol of the scaled |x|, or, with
    `stall` = (k, drop), when the last k steps taken lowered the sum by at most that
    fraction of it (rejected trials do not count: a fit that shrinks its radius from a
    plateau is not stopped). `triangularize` (default kernels.triangularize, loops of fixed
    order) gives R and Q^T f of each Jacobian: normal_triangularize for tall ones. Returns
    x; its sum is never above x0's."""
    triangularize = kernels.triangularize if triangularize is None else triangularize
    x = np.array(x0, dtype=float)
    f = np.ascontiguousarray(fun(x), dtype=float)
    cost = kernels.sum_squares(f)
    n = x.size
    if not np.isfinite(cost) or cost == 0.0 or n == 0:
        return x
    j = np.ascontiguousarray(jac(x), dtype=float)
    if not kernels.squares_finite(j.ravel()):
        return x
    scale = column_norms(j)
    r, qtr, h = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    triangularize(j, scale, f, r, qtr)
    radius = RADIUS_FACTOR * (_norm(x * scale) or 1.0)
    mu = 0.0
    costs = [cost]  # the sum after each step taken
    for evaluation in range(int(max_nfev)):
        mu = _damping_for_radius(r, qtr, radius, mu, h)
        step = _norm(h)
        if evaluation == 0:
            radius = min(radius, step)
        with np.errstate(over="ignore", invalid="ignore"):  # a huge step: inf, rejected
            trial = x + h / scale
        f_trial = np.ascontiguousarray(fun(trial), dtype=float)
        cost_trial = kernels.sum_squares(f_trial)
        blown = not (np.isfinite(cost_trial) and cost_trial < 100.0 * cost)
        actual = -1.0 if blown else 1.0 - cost_trial / cost
        drop, jh2 = kernels.predicted_drop(r, qtr, h)
        predicted = drop / cost
        ratio = actual / predicted if predicted > 0.0 else 0.0
        if ratio <= 0.25:
            slope = -(jh2 + mu * step * step) / cost
            shrink = 0.5 if actual >= 0.0 else 0.5 * slope / (slope + 0.5 * actual)
            shrink = 0.1 if blown or shrink < 0.1 else min(shrink, 0.5)
            radius = shrink * min(radius, step / 0.1)
            mu /= shrink
        elif mu == 0.0 or ratio >= 0.75:
            radius = step / 0.5
            mu *= 0.5
        if ratio >= ACCEPT_RATIO:
            x, f, cost = trial, f_trial, cost_trial
            costs.append(cost)
            if cost == 0.0 or (
                stall is not None
                and len(costs) > stall[0]
                and costs[-1 - stall[0]] - cost <= stall[1] * costs[-1 - stall[0]]
            ):
                break
            j = np.ascontiguousarray(jac(x), dtype=float)
            if not kernels.squares_finite(j.ravel()):
                break
            triangularize(j, scale, f, r, qtr)
        if (abs(actual) <= ftol and predicted <= ftol and ratio <= 2.0) or radius <= xtol * _norm(
            x * scale
        ):
            break
    return x


def normal_triangularize(jac, scale, res, r, qtr) -> None:
    """kernels.triangularize's R and qtr for a tall, wide Jacobian (the joint refit's:
    108,000 x 43), its normal equations formed by BLAS: R = the Cholesky factor of
    (jac / scale)^T (jac / scale), qtr = R^-T (jac / scale)^T res. The LM step reads only
    R^T R and R^T qtr, which equal jac's own. Under gpquad.engine.threads.one_blas_thread,
    as every finish runs, the result is a function of the inputs. Where the scaled normal
    matrix is close to singular (the factor's diagonal spans more than the kernels'
    NORMAL_PIVOT_RATIO, a condition above about 1e12), kernels.householder_triangularize's
    QR is taken."""
    from scipy.linalg import cho_factor, solve_triangular

    scaled = np.asarray(jac, dtype=float) / scale
    normal = scaled.T @ scaled
    try:
        upper = np.triu(cho_factor(normal, lower=False, check_finite=True)[0])
    except (np.linalg.LinAlgError, ValueError):
        upper = None
    diagonal = np.abs(np.diag(upper)) if upper is not None else np.zeros(1)
    if upper is None or not diagonal.min() > kernels.NORMAL_PIVOT_RATIO * diagonal.max():
        kernels.householder_triangularize(
            np.ascontiguousarray(jac, dtype=float), scale, res, r, qtr
        )
        return
    r[:, :] = upper
    qtr[:] = solve_triangular(upper, scaled.T @ res, trans="T", lower=False)


def remember_last(compute):
    """f(x) = compute(x) (x as a float array), remembered at the last point asked: an LM
    asks for the residuals or the Jacobian at one point several times."""
    memo: dict[str, tuple[bytes, object]] = {}

    def remembered(x):
        key = np.asarray(x, dtype=float).tobytes()
        if "last" not in memo or memo["last"][0] != key:
            memo["last"] = (key, compute(np.array(x, dtype=float)))
        return memo["last"][1]

    return remembered


def forward_difference(fun, workers: int = 1):
    """(value, jac) for a residual function without an analytic Jacobian: value(x) is fun(x)
    remembered at the last point asked, jac(x) the forward-difference Jacobian there with
    step FD_STEP * max(1, |x_j|) (signed like x_j, as scipy's '2-point'), also remembered,
    so that LM's repeated requests at one point cost one evaluation each.

    workers > 1: the columns are computed in that many threads (`fun` must be thread-safe
    and release the GIL for its work, as the numba kernels do); each column is the same
    function of x, so the Jacobian is the same for any number of workers."""
    value = remember_last(lambda v: np.asarray(fun(v), dtype=float))

    def jacobian(x):
        f0 = value(x)
        h = FD_STEP * np.where(x >= 0.0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))

        def column(j: int) -> np.ndarray:
            shifted = x.copy()
            shifted[j] += h[j]
            return (np.asarray(fun(shifted), dtype=float) - f0) / (shifted[j] - x[j])

        return np.column_stack(thread_map(column, range(x.size), workers))

    return value, remember_last(jacobian)


def broyden_jacobian(value, jacobian, refresh: int):
    """jac(x) for levenberg_marquardt that asks `jacobian` (say forward_difference's, one rollout
    per constant) at the first point and at every `refresh`-th new point after it, and in
    between updates the last matrix by Broyden's rank-one secant update,
    J + (f(x) - f(x_last) - J dx) dx^T / (dx^T dx) with dx = x - x_last, x_last the last
    point asked: the updated J maps dx to the change of the residuals exactly, leaves J
    unchanged across dx, and costs no evaluation beyond value(x), which the fit has made
    already. The same point asked again in a row gets the same matrix; an update that is not
    finite is replaced by `jacobian`'s. The result is a function of the sequence of points
    asked."""
    if refresh < 1:
        raise ValueError("refresh must be at least 1")
    last: dict = {}

    def jac(x):
        x = np.array(x, dtype=float)
        if "x" in last and np.array_equal(last["x"], x):
            return last["j"]
        f = np.array(value(x), dtype=float)
        j = None
        if "x" in last and last["age"] + 1 < refresh:
            dx = x - last["x"]
            step = float(dx @ dx)
            if step > 0.0:
                j = last["j"] + np.outer(f - last["f"] - last["j"] @ dx, dx / step)
                if not np.all(np.isfinite(j)):
                    j = None
        if j is None:
            j, age = np.array(jacobian(x), dtype=float), 0
        else:
            age = last["age"] + 1
        last.update(x=x, f=f, j=j, age=age)
        return j

    return jac
