"""Linear algebra of the Levenberg-Marquardt step, in loops of fixed order (no BLAS).

The constant fits call these for every step (gpquad.engine.evolve.lm). BLAS and LAPACK
may sum in another order for another thread count or memory alignment, and scipy 1.17's
MINPACK took other trial points for bit-identical inputs after other fits in the process
(benchmarks/lm_state.py); with plain loops the result is a function of the inputs alone,
whatever ran before and however many threads or jobs.

Flat arrays in, flat arrays out:
- `triangularize(jac, scale, res, r, qtr)`: for J = jac (m, n) with its columns divided
  by scale, an upper triangular R (r, (n, n)) and qtr (n,) with R^T R = J^T J and
  R^T qtr = J^T res, what the LM step reads: the Cholesky factor of the normal equations,
  summed four rows at a time in one pass over jac (cost m n^2 / 2, no dependency chain);
  where that factor is close to singular (its diagonal spans more than
  NORMAL_PIVOT_RATIO), the Householder QR (`householder_triangularize`: R and the first
  n entries of Q^T res, cost 2 m n^2 in dependent sums).
- `damped_step(r, qtr, mu, h)`: the step h minimising |jac h + res|^2 + mu |h|^2, from R and
  Q^T res alone (QR of [R; sqrt(mu) I], n^3), and what Newton's correction of mu needs.
- `predicted_drop`, `gradient_norm`, `sum_squares`, `squares_finite`, `column_norms`: the
  reductions around them.
"""

import numpy as np

from gpquad.engine.numba_config import njit

#: The normal equations' Cholesky factor is replaced by the QR when its smallest diagonal
#: entry is at most this fraction of its largest (a condition of J above about 1e6, where
#: the factor loses more than about 1e-4 of its digits).
NORMAL_PIVOT_RATIO = 1e-6


@njit(inner=True)
def _householder(at, b, n_rows, n_cols):
    """In place: at (n_cols, n_rows), the matrix transposed (its columns contiguous) -> R^T
    in its lower triangle, b (n_rows,) -> Q^T b."""
    for k in range(n_cols):
        v = at[k]
        norm = 0.0
        for i in range(k, n_rows):
            norm += v[i] * v[i]
        norm = np.sqrt(norm)
        if norm == 0.0:
            continue
        alpha = -norm if v[k] >= 0.0 else norm
        # v = a[k:, k] - alpha e_k, kept in a[k:, k]; H = I - 2 v v^T / (v^T v)
        v[k] -= alpha
        vtv = 0.0
        for i in range(k, n_rows):
            vtv += v[i] * v[i]
        if vtv == 0.0:
            v[k] = alpha
            continue
        for j in range(k + 1, n_cols):
            column = at[j]
            dot = 0.0
            for i in range(k, n_rows):
                dot += v[i] * column[i]
            scale = 2.0 * dot / vtv
            for i in range(k, n_rows):
                column[i] -= scale * v[i]
        dot = 0.0
        for i in range(k, n_rows):
            dot += v[i] * b[i]
        scale = 2.0 * dot / vtv
        for i in range(k, n_rows):
            b[i] -= scale * v[i]
        v[k] = alpha


@njit
def triangularize(jac, scale, res, r, qtr):
    """R (upper triangle of r, zeros below) and qtr with R^T R = J^T J and R^T qtr = J^T res
    for J = jac / scale (each column j divided by scale[j]): the normal equations' Cholesky
    factor, or householder_triangularize's QR where that factor is close to singular
    (module notes). jac and res are left as they are; the result is a function of them."""
    m, n = jac.shape
    gram = np.zeros((n, n))  # upper triangle of J^T J
    jtr = np.zeros(n)
    inverse = 1.0 / scale
    block = np.empty((4, n))
    whole = m - m % 4
    for i in range(0, whole, 4):
        for k in range(4):
            for a in range(n):
                block[k, a] = jac[i + k, a] * inverse[a]
        f0, f1, f2, f3 = res[i], res[i + 1], res[i + 2], res[i + 3]
        for a in range(n):
            x0, x1, x2, x3 = block[0, a], block[1, a], block[2, a], block[3, a]
            jtr[a] += (x0 * f0 + x1 * f1) + (x2 * f2 + x3 * f3)
            for b in range(a, n):
                gram[a, b] += (x0 * block[0, b] + x1 * block[1, b]) + (
                    x2 * block[2, b] + x3 * block[3, b]
                )
    for i in range(whole, m):
        for a in range(n):
            xa = jac[i, a] * inverse[a]
            jtr[a] += xa * res[i]
            for b in range(a, n):
                gram[a, b] += xa * (jac[i, b] * inverse[b])
    largest = 0.0
    for k in range(n):  # gram = R^T R, R upper triangular
        d = gram[k, k]
        for p in range(k):
            d -= r[p, k] * r[p, k]
        if not d > 0.0:  # singular (or not finite)
            householder_triangularize(jac, scale, res, r, qtr)
            return
        d = np.sqrt(d)
        largest = max(largest, d)
        r[k, k] = d
        for j in range(k):
            r[k, j] = 0.0
        for j in range(k + 1, n):
            s = gram[k, j]
            for p in range(k):
                s -= r[p, k] * r[p, j]
            r[k, j] = s / d
    for k in range(n):
        if not r[k, k] > NORMAL_PIVOT_RATIO * largest:
            householder_triangularize(jac, scale, res, r, qtr)
            return
    for k in range(n):  # R^T qtr = J^T res
        s = jtr[k]
        for p in range(k):
            s -= r[p, k] * qtr[p]
        qtr[k] = s / r[k, k]


@njit
def householder_triangularize(jac, scale, res, r, qtr):
    """R (upper triangle of r) and the first n entries of Q^T res for jac / scale = Q R
    (each column j divided by scale[j]); jac and res are left as they are."""
    m, n = jac.shape
    at = np.empty((n, m))
    for i in range(m):
        for j in range(n):
            at[j, i] = jac[i, j] / scale[j]
    b = res.copy()
    _householder(at, b, m, n)
    for i in range(n):
        qtr[i] = b[i]
        for j in range(n):
            r[i, j] = at[j, i] if j >= i else 0.0


@njit
def damped_step(r, qtr, mu, h):
    """h = argmin |R h + qtr|^2 + mu |h|^2 (then |jac h + res|^2 differs by a constant).
    Returns h^T (R^T R + mu I)^-1 h (>= 0: Newton's correction of mu in the trust-region
    iteration), or -1 (h untouched) when the damped system is singular (mu = 0, R singular).
    """
    n = r.shape[0]
    at = np.zeros((n, 2 * n))  # [R; sqrt(mu) I], transposed
    b = np.zeros(2 * n)
    root = np.sqrt(mu)
    for i in range(n):
        b[i] = -qtr[i]
        at[i, n + i] = root
        for j in range(i, n):
            at[j, i] = r[i, j]
    _householder(at, b, 2 * n, n)
    for i in range(n):
        if at[i, i] == 0.0:
            return -1.0
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, n):
            acc -= at[j, i] * h[j]
        h[i] = acc / at[i, i]
    # z = S^-T h with S^T S = R^T R + mu I (S: the upper triangle, at's lower one)
    z = np.zeros(n)
    total = 0.0
    for i in range(n):
        acc = h[i]
        for j in range(i):
            acc -= at[i, j] * z[j]
        z[i] = acc / at[i, i]
        total += z[i] * z[i]
    return total


@njit
def predicted_drop(r, qtr, h):
    """(|res|^2 - |res + jac h|^2 as the linear model predicts it, |jac h|^2), from R and
    Q^T res: (-2 (R h).qtr - |R h|^2, |R h|^2)."""
    n = r.shape[0]
    drop = 0.0
    norm2 = 0.0
    for i in range(n):
        rh = 0.0
        for j in range(i, n):
            rh += r[i, j] * h[j]
        drop -= 2.0 * rh * qtr[i] + rh * rh
        norm2 += rh * rh
    return drop, norm2


@njit
def gradient_norm(r, qtr):
    """|R^T qtr| = |jac^T res|."""
    n = r.shape[0]
    total = 0.0
    for j in range(n):
        g = 0.0
        for i in range(j + 1):
            g += r[i, j] * qtr[i]
        total += g * g
    return np.sqrt(total)


@njit
def sum_squares(v):
    """sum(v^2) in index order (inf or nan when v holds one)."""
    total = 0.0
    for i in range(v.size):
        total += v[i] * v[i]
    return total


@njit
def squares_finite(v):
    """Whether sum(v^2) is finite: summed in four independent parts (only its finiteness is
    read, so their order need not be sum_squares's; the sums differ only within rounding of
    the largest float)."""
    parts = np.zeros(4)
    whole = v.size - v.size % 4
    for i in range(0, whole, 4):
        for k in range(4):
            parts[k] += v[i + k] * v[i + k]
    total = (parts[0] + parts[1]) + (parts[2] + parts[3])
    for i in range(whole, v.size):
        total += v[i] * v[i]
    return np.isfinite(total)


@njit
def column_norms(jac, out):
    """out[j] = |jac[:, j]|, 1 where a column is zero or not finite."""
    m, n = jac.shape
    for j in range(n):
        total = 0.0
        for i in range(m):
            total += jac[i, j] * jac[i, j]
        norm = np.sqrt(total)
        out[j] = norm if (norm > 0.0 and np.isfinite(norm)) else 1.0
