"""atan2 without a libm call, so that a loop over lanes of it vectorises.

glibc's atan2 costs about 20 ns a call on the machines this ran on, and the fitness kernel
calls it for roll and yaw at every step of every lane of an angular target that reads them.
`atan2` here is fdlibm's atan (its polynomial, its intervals of |y/x| and their atan(c) hi /
lo parts) reorganised so that every path is the same arithmetic:

- a, b = min(|x|, |y|), max(|x|, |y|) and t = a / b in [0, 1] falls in [0, 7/16), [7/16,
  11/16) or [11/16, 1]; the reduced argument is a / b, (2a - b) / (2b + a) or (a - b) /
  (b + a). Each numerator is exact (Sterbenz), and the division's error is carried as a low
  part (an FMA gives the residual exactly), so unlike atan(y / x) no rounding of t reaches
  the result;
- atan2 = H + atan(X) with H one of twelve constants (0, atan(1/2), pi/4, atan(2), pi/2,
  pi - those) by interval, by |y| > |x| (then atan(a / b) is subtracted from pi/2) and by
  x < 0 (subtracted from pi); H + X is summed exactly (head and tail), and the tail, H's low
  part, X's and X's polynomial term are added to it in one last rounding;
- the sign of y is copied onto the result.

Accuracy: within 1 ulp of the exact atan2 (the rounding of the final sum, about 0.5 ulp, plus
the polynomial's and the low parts' errors; tests/test_atan2.py measures it against mpmath).
It is not glibc's atan2 bit for bit: glibc rounds differently on a few results in a
thousand (also within 1 ulp), so changing from one to the other changes those bits.

Outside 2^-500 <= max(|x|, |y|) <= 2^500 (and min(|x|, |y|) zero or at least 2^-500), i.e.
for zeros, infinities, NaN and extreme ratios, `atan2_fast` reports that it did not apply
and `atan2` calls math.atan2 (a lane loop redoes those lanes after the vectorised pass).
"""

import math

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from gpquad.engine.numba_config import njit


@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c with one rounding (LLVM's llvm.fma: an FMA instruction where there is one)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


# H (hi, lo): atan of the interval's centre (0, atan(1/2), pi/4), pi/2 minus it (|y| > |x|),
# pi minus it (x < 0), pi/2 plus it (both). Picked by selects, not by a table index: a
# gather of a table stops the lane loop's booleans from staying in vector registers.
_ATAN_HALF = (0.4636476090008061, 2.2698777452961687e-17)
_ATAN_TWO = (1.1071487177940904, 9.40447137356638e-17)
_PI_4 = (0.7853981633974483, 3.061616997868383e-17)
_PI_2 = (1.5707963267948966, 6.123233995736766e-17)
_PI_2_PLUS = (2.0344439357957027, 2.841996617907152e-17)
_PI_3_4 = (2.356194490192345, 9.184850993605148e-17)
_PI_MINUS = (2.677945044588987, 1.5527705369303147e-16)
_PI = (3.141592653589793, 1.2246467991473532e-16)
# fdlibm s_atan.c: atan(x) = x - x (s1 + s2) for |x| <= 7/16.
_AT0 = 3.33333333333329318027e-01
_AT1 = -1.99999999998764832476e-01
_AT2 = 1.42857142725034663711e-01
_AT3 = -1.11111104054623557880e-01
_AT4 = 9.09088713343650656196e-02
_AT5 = -7.69187620504482999495e-02
_AT6 = 6.66107313738753120669e-02
_AT7 = -5.83357013379057348645e-02
_AT8 = 4.97687799461593236017e-02
_AT9 = -3.65315727442169155270e-02
_AT10 = 1.62858201153657823623e-02
_TINY = 2.0**-500
_HUGE = 2.0**500


@njit(inline="always")
def _pick(top, mid, centre, half, quarter):
    """The (hi, lo) of the interval: `quarter` when top, `half` when mid, else `centre`."""
    hi = quarter[0] if top else (half[0] if mid else centre[0])
    lo = quarter[1] if top else (half[1] if mid else centre[1])
    return hi, lo


@njit(inline="always")
def _offset(neg, swap, top, mid):
    """H (hi, lo) of atan2_fast (module notes), by selects."""
    if neg:
        if swap:
            return _pick(top, mid, _PI_2, _PI_2_PLUS, _PI_3_4)
        return _pick(top, mid, _PI, _PI_MINUS, _PI_3_4)
    if swap:
        return _pick(top, mid, _PI_2, _ATAN_TWO, _PI_4)
    return _pick(top, mid, (0.0, 0.0), _ATAN_HALF, _PI_4)


@njit(inline="always")
def atan2_fast(y, x):
    """(atan2(y, x), applies): the value is right only where applies (module notes)."""
    ax = abs(x)
    ay = abs(y)
    swap = ay > ax
    a = ax if swap else ay
    b = ay if swap else ax
    top = a >= 0.6875 * b
    mid = a >= 0.4375 * b
    c = 1.0 if top else (2.0 if mid else 1.0)
    d = 1.0 if mid else 0.0
    cb = c * b
    num = c * a - d * b  # exact
    den = cb + d * a
    e = d * a - (den - cb)  # den + e = cb + d a exactly
    den = den if den > 0.0 else 1.0  # x = y = 0 or NaN: does not apply
    x0 = num / den
    x_lo = (fma(-x0, den, num) - x0 * e) / den  # num / (den + e) - x0, to first order
    neg = x < 0.0
    s = 1.0 if swap == neg else -1.0
    hi, lo = _offset(neg, swap, top, mid)
    xr = s * x0
    z = xr * xr
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    head = hi + xr  # exact with tail: |hi| >= |xr| or hi = 0
    tail = xr - (head - hi)
    v = head + (((lo + s * x_lo) - xr * (s1 + s2)) + tail)
    applies = (b >= _TINY) and (b <= _HUGE) and ((a >= _TINY) or (a == 0.0))
    return math.copysign(v, y), applies


@njit(inline="always")
def atan2(y, x):
    """atan2(y, x) within 1 ulp (module notes)."""
    v, applies = atan2_fast(y, x)
    return v if applies else math.atan2(y, x)


@njit(inner=True)
def atan2_lanes(y, x, out, n):
    """out[:n] = atan2(y[:n], x[:n]): a vectorised pass, then math.atan2 where it did not
    apply (the same bits as atan2 lane by lane)."""
    missed = 0
    for lane in range(n):
        v, applies = atan2_fast(y[lane], x[lane])
        out[lane] = v
        missed += not applies
    if missed > 0:
        for lane in range(n):
            if not atan2_fast(y[lane], x[lane])[1]:
                out[lane] = math.atan2(y[lane], x[lane])


# fdlibm e_asin.c: asin(x) = x + x R(x^2), R = p / q, for x^2 <= 1/4.
_PS0 = 1.66666666666666657415e-01
_PS1 = -3.25565818622400915405e-01
_PS2 = 2.01212532134862925881e-01
_PS3 = -4.00555345006794114027e-02
_PS4 = 7.91534994289814532176e-04
_PS5 = 3.47933107596021167570e-05
_QS1 = -2.40339491173441421878e00
_QS2 = 2.02094576023350569471e00
_QS3 = -6.88283971605453293030e-01
_QS4 = 7.70381505559019352791e-02
_PIO2_HI = 1.57079632679489655800e00
_PIO2_LO = 6.12323399573676603587e-17


@njit(inline="always")
def asin(x):
    """asin(x) within 1 ulp, without a libm call or a branch (a lane loop vectorises).

    fdlibm's rational R, on x itself for |x| < 1/2, else asin |x| = pi/2 - 2 asin(s) with
    s = sqrt(z), z = (1 - |x|) / 2 (exact), sqrt's error carried as a low part (FMA residual)
    and pi/2 - 2 s summed exactly (head and tail) before the small terms. NaN for |x| > 1
    or NaN."""
    ax = abs(x)
    big = ax >= 0.5
    z = 0.5 * (1.0 - ax) if big else x * x
    p = z * (_PS0 + z * (_PS1 + z * (_PS2 + z * (_PS3 + z * (_PS4 + z * _PS5)))))
    q = 1.0 + z * (_QS1 + z * (_QS2 + z * (_QS3 + z * _QS4)))
    r = p / q
    s = math.sqrt(z)
    s_lo = fma(-s, s, z) / (s + s) if s > 0.0 else 0.0
    two_s = s + s
    head = _PIO2_HI - two_s  # exact with tail: pi/2 > 2 s
    tail = (_PIO2_HI - head) - two_s
    far = head + ((tail + _PIO2_LO) - (2.0 * s_lo + two_s * r))
    near = ax + ax * r
    return math.copysign(far if big else near, x)
