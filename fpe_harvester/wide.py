"""Real numbers with double-precision rounding and an unbounded exponent range.

A :class:`Wide` number is :math:`m\\,2^e` with a float mantissa :math:`1/2 \\le |m| < 1` (or 0)
and an integer exponent. Products, quotients, sums and square roots round the mantissas
exactly as float arithmetic rounds the numbers themselves (scaling by a power of 2 is exact),
so a formula evaluated on :class:`Wide` operands in the same order gives bit-for-bit the float
result whenever the float evaluation stays inside the normal range, and the correctly scaled
result where it would have overflowed or underflowed. The exact solver evaluates its closed
forms this way, so that no intermediate product decides whether an answer is representable:
only the answer itself does (:meth:`Wide.representable`).

Examples
--------
>>> big = Wide.of(1e300)
>>> float(((big * big) / big).to_float())
1e+300
>>> round(float((big * big).log10()), 9)
600.0
"""

from __future__ import annotations

import math
from typing import Any, Union

import numpy as np

__all__ = ["Wide", "Float", "SMALLEST_NORMAL", "LARGEST"]

#: Smallest positive normal double; below it a float loses relative precision.
SMALLEST_NORMAL = float(np.finfo(float).tiny)
#: Largest finite double.
LARGEST = float(np.finfo(float).max)

# Exponent given to zero: far below any real exponent, so that zero never sets the alignment
# exponent of a sum (an exponent difference below -_SHIFT_CAP makes a term exactly 0 anyway).
_ZERO_EXP = -(2**40)
_SHIFT_CAP = 1100

Operand = Union["Wide", float, int, np.ndarray]


class Wide:
    """An array of reals :math:`m\\,2^e`, float mantissa, int64 exponent (see the module docstring).

    Parameters
    ----------
    mant : array_like
        Mantissas; normalized on construction.
    exp : array_like of int
        Exponents, broadcast against ``mant``.
    """

    __slots__ = ("mant", "exp")
    __array_priority__ = 100.0  # ndarray op Wide defers to Wide's reflected operators

    def __init__(self, mant: Any, exp: Any = 0) -> None:
        m, de = np.frexp(np.asarray(mant, dtype=float))
        e = np.asarray(exp, dtype=np.int64) + de.astype(np.int64)
        self.mant = m
        self.exp = np.where(m == 0, _ZERO_EXP, e)

    @classmethod
    def of(cls, x: Operand) -> Wide:
        """``x`` as a :class:`Wide` (exactly; subnormal floats included)."""
        return x if isinstance(x, Wide) else cls(x)

    # -- arithmetic --------------------------------------------------------------------------

    def __neg__(self) -> Wide:
        return Wide(-self.mant, self.exp)

    def __abs__(self) -> Wide:
        return Wide(np.abs(self.mant), self.exp)

    def __add__(self, other: Operand) -> Wide:
        o = Wide.of(other)
        e = np.maximum(self.exp, o.exp)
        with np.errstate(under="ignore"):
            s = (np.ldexp(self.mant, np.clip(self.exp - e, -_SHIFT_CAP, 0))
                 + np.ldexp(o.mant, np.clip(o.exp - e, -_SHIFT_CAP, 0)))
        return Wide(s, e)

    __radd__ = __add__

    def __sub__(self, other: Operand) -> Wide:
        return self + (-Wide.of(other))

    def __rsub__(self, other: Operand) -> Wide:
        return Wide.of(other) + (-self)

    def __mul__(self, other: Operand) -> Wide:
        o = Wide.of(other)
        return Wide(self.mant * o.mant, self.exp + o.exp)

    __rmul__ = __mul__

    def __truediv__(self, other: Operand) -> Wide:
        o = Wide.of(other)
        if np.any(o.mant == 0):
            raise ZeroDivisionError("Wide division by zero")
        return Wide(self.mant / o.mant, self.exp - o.exp)

    def __rtruediv__(self, other: Operand) -> Wide:
        return Wide.of(other) / self

    def __pow__(self, power: int) -> Wide:
        """Small positive integer powers, rounded once like the float power ``x ** power``."""
        if isinstance(power, bool) or not isinstance(power, int) or not 1 <= power <= 8:
            raise ValueError(f"Wide supports integer powers 1 to 8, got {power!r}")
        # a float scalar's ** is C pow(), which is not correctly rounded: pow(m, p) 2^(e p) can
        # differ in the last bit from pow(m 2^e, p). Use the float power itself wherever it and its
        # operand are normal doubles, so that the result is bit-for-bit the float one.
        if self.mant.ndim == 0 and self.representable():
            try:
                value = float(self.to_float()) ** power
            except OverflowError:
                value = math.inf
            if (value == 0.0 and self.mant == 0) or SMALLEST_NORMAL <= abs(value) < math.inf:
                return Wide(value)
        mant = float(self.mant) ** power if self.mant.ndim == 0 else np.power(self.mant, power)
        return Wide(mant, self.exp * power)

    def sqrt(self) -> Wide:
        """Square root of a non-negative :class:`Wide` (correctly rounded, like ``math.sqrt``)."""
        if np.any(self.mant < 0):
            raise ValueError("Wide.sqrt of a negative number")
        odd = (self.exp % 2) != 0
        m = np.where(odd, 2.0 * self.mant, self.mant)
        e = np.where(odd, self.exp - 1, self.exp)
        return Wide(np.sqrt(m), np.where(self.mant == 0, 0, e // 2))

    # -- selection and reduction ------------------------------------------------------------------

    @staticmethod
    def where(cond: Any, x: Operand, y: Operand) -> Wide:
        """Elementwise ``x if cond else y``."""
        a, b = Wide.of(x), Wide.of(y)
        return Wide(np.where(cond, a.mant, b.mant), np.where(cond, a.exp, b.exp))

    def __getitem__(self, index: Any) -> Wide:
        shape = np.broadcast_shapes(self.mant.shape, self.exp.shape)
        return Wide(np.broadcast_to(self.mant, shape)[index], np.broadcast_to(self.exp, shape)[index])

    def mean(self, axis: int = -1) -> Wide:
        """Mean along ``axis``; the same rounding as ``ndarray.mean`` of the float values."""
        shape = np.broadcast_shapes(self.mant.shape, self.exp.shape)
        mant, exp = np.broadcast_to(self.mant, shape), np.broadcast_to(self.exp, shape)
        top = exp.max(axis=axis, keepdims=True)
        with np.errstate(under="ignore"):
            total = np.ldexp(mant, np.clip(exp - top, -_SHIFT_CAP, 0)).sum(axis=axis)
        return Wide(total, np.squeeze(top, axis=axis)) / shape[axis]

    # -- conversion -----------------------------------------------------------------------------

    def to_float(self) -> np.ndarray:
        """Float values: ``inf`` past the largest double, 0 or subnormal below the normal range."""
        with np.errstate(over="ignore", under="ignore"):
            return np.ldexp(self.mant, np.clip(self.exp, -_SHIFT_CAP - 1100, _SHIFT_CAP))

    def representable(self) -> np.ndarray:
        """True where the value is 0 or a normal finite double (no precision lost in the float)."""
        return (self.mant == 0) | ((self.exp >= -1021) & (self.exp <= 1024))

    def log10(self) -> np.ndarray:
        """:math:`\\log_{10}|x|` as float (``-inf`` for 0), accurate for any exponent."""
        with np.errstate(divide="ignore"):
            return np.log10(np.abs(self.mant)) + self.exp * math.log10(2.0)

    def sign(self) -> np.ndarray:
        """-1, 0 or +1 elementwise."""
        return np.sign(self.mant)

    def __repr__(self) -> str:
        return f"Wide(log10|x| = {self.log10()!r}, sign = {self.sign()!r})"


class Float:
    """The :class:`Wide` interface on plain float arrays: the exact solver's fast path.

    Operations round exactly as :class:`Wide` does (same operations, same powers), so within the
    normal range the two give bit-identical results. Evaluated under
    ``numpy.errstate(all="raise")``, any overflow, underflow or invalid operation raises
    :class:`FloatingPointError`, and the caller repeats the evaluation with :class:`Wide`.
    """

    __slots__ = ("mant",)
    __array_priority__ = 100.0

    def __init__(self, value: Any) -> None:
        self.mant = np.asarray(value, dtype=float)

    @classmethod
    def of(cls, x: Any) -> Float:
        return x if isinstance(x, Float) else cls(x)

    def __neg__(self) -> Float:
        return Float(-self.mant)

    def __abs__(self) -> Float:
        return Float(np.abs(self.mant))

    def __add__(self, other: Any) -> Float:
        return Float(self.mant + Float.of(other).mant)

    __radd__ = __add__

    def __sub__(self, other: Any) -> Float:
        return Float(self.mant - Float.of(other).mant)

    def __rsub__(self, other: Any) -> Float:
        return Float(Float.of(other).mant - self.mant)

    def __mul__(self, other: Any) -> Float:
        return Float(self.mant * Float.of(other).mant)

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> Float:
        return Float(self.mant / Float.of(other).mant)

    def __rtruediv__(self, other: Any) -> Float:
        return Float(Float.of(other).mant / self.mant)

    def __pow__(self, power: int) -> Float:
        if self.mant.ndim:
            return Float(np.power(self.mant, power))
        # C pow() on a Python float, as Wide does; its range errors do not go through numpy's
        # error state, so they are raised here
        base = float(self.mant)
        try:
            value = base ** power
        except OverflowError:
            raise FloatingPointError(f"overflow in {base!r} ** {power}") from None
        if base != 0.0 and abs(value) < SMALLEST_NORMAL:
            raise FloatingPointError(f"underflow in {base!r} ** {power}")
        return Float(value)

    def sqrt(self) -> Float:
        return Float(np.sqrt(self.mant))

    @staticmethod
    def where(cond: Any, x: Any, y: Any) -> Float:
        return Float(np.where(cond, Float.of(x).mant, Float.of(y).mant))

    def __getitem__(self, index: Any) -> Float:
        return Float(self.mant[index])

    def mean(self, axis: int = -1) -> Float:
        return Float(self.mant.mean(axis=axis))

    def to_float(self) -> np.ndarray:
        return self.mant

    def representable(self) -> np.ndarray:
        return (self.mant == 0) | ((np.abs(self.mant) >= SMALLEST_NORMAL) & np.isfinite(self.mant))

    def log10(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.log10(np.abs(self.mant))

    def sign(self) -> np.ndarray:
        return np.sign(self.mant)
