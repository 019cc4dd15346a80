"""sin and cos without a libm call, for the rate increments of fast-spinning lanes.

rate_increment's exp(omega dt / 2) takes sin(h) and cos(h) from libm when h = |omega| dt / 2
is beyond its series (SERIES_LIMIT): a tree that drives a rate far from the data spins its
lanes, and the fitness kernel then spent a fifth of its time in glibc's sincos, one call per
lane. `sincos` here is fdlibm's: the argument reduced by n pi/2 in three 33-bit parts and a tail
(its __rem_pio2 medium path, with every subtraction's error kept), its __kernel_sin and
__kernel_cos on the remainder (head and tail), the quadrant picked by selects, so that a
loop over lanes vectorises. Within 1 ulp of the exact values (tests/test_fast_trig.py measures
it against mpmath), not glibc's bits; for h beyond H_MAX or NaN it does not apply and the
caller uses libm.
"""

import math

from gpquad.engine.numba_config import njit

#: Largest argument sincos takes (n = round(h 2 / pi) < 2^20 keeps n pi/2's parts exact).
H_MAX = 2.0**19

_INVPIO2 = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
_PIO2_3T = 8.47842766036889956997e-32
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11


@njit(inline="always")
def sincos(h):
    """(sin h, cos h) for 0 <= h <= H_MAX, within 1 ulp (module notes)."""
    fn = math.floor(h * _INVPIO2 + 0.5)
    m = int(fn) & 3
    r1 = h - fn * _PIO2_1  # exact (Sterbenz), as fn * _PIO2_1, _PIO2_2 and _PIO2_3 are
    w2 = fn * _PIO2_2
    r2 = r1 - w2
    b2 = r2 - r1
    e2 = (r1 - (r2 - b2)) - (w2 + b2)  # r2's rounding error (two-sum)
    w3 = fn * _PIO2_3
    r3 = r2 - w3
    b3 = r3 - r2
    e3 = (r2 - (r3 - b3)) - (w3 + b3)
    tail = (e2 + e3) - fn * _PIO2_3T
    x = r3 + tail  # the remainder in [-pi/4, pi/4], head x and tail y
    y = (r3 - x) + tail
    z = x * x
    v = z * x
    rs = _S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))
    ks = x - ((z * (0.5 * y - v * rs) - y) - v * _S1)
    zz = z * z
    rc = z * (_C1 + z * (_C2 + z * _C3)) + zz * zz * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    one_hz = 1.0 - hz
    kc = one_hz + (((1.0 - one_hz) - hz) + (z * rc - x * y))
    odd = (m & 1) == 1
    sn = kc if odd else ks
    cs = ks if odd else kc
    sn = -sn if m >= 2 else sn
    cs = -cs if m == 1 or m == 2 else cs
    return sn, cs
