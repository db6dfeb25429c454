"""Wide arithmetic: float rounding without an exponent limit; Float: the same on plain floats."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import strategies as st

import fpe_harvester.exact.solver as exact_solver
from fpe_harvester import Params
from fpe_harvester.wide import LARGEST, SMALLEST_NORMAL, Float, Wide

NORMAL = st.floats(min_value=-1e300, max_value=1e300, allow_nan=False).filter(
    lambda x: x == 0 or 1e-300 < abs(x))
SCALE = st.integers(-3000, 3000)


def _exact(w: Wide) -> Fraction:
    return Fraction(0) if w.mant == 0 else Fraction(float(w.mant)) * Fraction(2) ** int(w.exp)


def _arith(x: float, y: float, e1: int, e2: int) -> None:
    """Each operation on 2^e-scaled operands is the float result (on the unscaled ones), rescaled."""
    a, b = Wide(x, e1), Wide(y, e2)
    pairs = [(a * b, x * y, e1 + e2), (a + b if e1 == e2 else None, x + y, e1),
             (a - b if e1 == e2 else None, x - y, e1)]
    if y != 0:
        pairs.append((a / b, x / y, e1 - e2))
    if abs(x) < 1e150:
        pairs.append((a**2, x**2, 2 * e1))
        if x >= 0:
            pairs.append((a.sqrt() if e1 % 2 == 0 else None, math.sqrt(x), e1 // 2))
    for w, plain, shift in pairs:
        if w is None or not 1e-300 < abs(plain) < 1e300:  # (a float underflow to 0 is inexact)
            continue
        assert _exact(w) == Fraction(plain) * Fraction(2) ** shift


def test_wide_rounds_like_float_at_any_exponent(fuzz) -> None:
    fuzz(_arith, {"ci": 200, "long": 20000}, x=NORMAL, y=NORMAL, e1=SCALE, e2=SCALE)


def test_mean_is_bit_identical_to_ndarray_mean(rng) -> None:
    x = rng.standard_normal((7, 1001)) * 10.0 ** rng.integers(-5, 5, size=(7, 1001))
    assert np.array_equal(Wide(x).mean().to_float(), x.mean(axis=-1))
    shifted = Wide(x, 5000).mean()
    assert np.array_equal(shifted.mant, Wide(x).mean().mant) and np.all(shifted.exp == Wide(x).mean().exp + 5000)


def test_range_queries() -> None:
    big = Wide(1e300) * Wide(1e300)
    assert big.to_float() == math.inf and not big.representable()
    assert round(float(big.log10()), 9) == 600.0
    tiny = Wide(1e-300) * Wide(1e-300)
    assert not tiny.representable() and tiny.to_float() == 0.0
    assert Wide(SMALLEST_NORMAL).representable() and Wide(LARGEST).representable()
    assert not Wide(SMALLEST_NORMAL / 2).representable()  # subnormal: precision lost
    assert Wide(0.0).representable() and (Wide(0.0) + Wide(5e-324)).to_float() == 5e-324
    with pytest.raises(ZeroDivisionError):
        Wide(1.0) / Wide(0.0)
    with pytest.raises(ValueError, match="powers"):
        Wide(2.0) ** 0.5  # type: ignore[operator]


def test_fast_and_wide_paths_of_the_exact_solver_agree_bit_for_bit(rng) -> None:
    """The exact solver evaluates in plain floats and falls back to Wide on any overflow or
    underflow: wherever the plain evaluation succeeds, both must give the same bits."""
    compared = 0
    for _ in range(300):
        N = int(rng.choice([1, 2, 3, 4, 5, 16]))
        a = 10 ** rng.uniform(-3, 3, size=6)
        k = np.zeros(6) if N == 1 else rng.uniform(-0.6, 2, size=6) * a
        p = Params(*(10 ** rng.uniform(-3, 3, size=9)))
        try:
            with np.errstate(all="raise"):
                fast = exact_solver._sweep_block_in(Float, a, k, N, p)
        except FloatingPointError:
            continue
        wide = exact_solver._sweep_block_in(Wide, a, k, N, p)
        compared += 1
        for key in fast:
            assert np.array_equal(np.asarray(fast[key]), np.asarray(wide[key]), equal_nan=True), key
    assert compared > 100
