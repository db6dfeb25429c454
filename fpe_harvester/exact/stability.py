"""Stability of harmonic rings: the diffusive-instability threshold k_di and growth rates.

Mode ``q`` of a harmonic ring is a single unit with stiffness
:math:`\\kappa_q = 2a + k\\mu_q + k_4\\mu_q^2`, :math:`\\mu_q = 4\\sin^2(\\pi q/N)`. A unit is
stable iff its stiffness is positive (Routh--Hurwitz on the cubic of the (x, v, V) block, for
any positive parameters), so the ring loses its stationary state when some
:math:`\\kappa_q < 0`. Since :math:`\\mu_q > 0` for q >= 1, that happens for k below

.. math::

    k_{di}(k_4) = -\\min_{q \\ge 1}\\Big(\\frac{2a}{\\mu_q} + k_4\\mu_q\\Big),\\qquad
    k_{di}(0) = -\\frac{2a}{4\\max_q \\sin^2(\\pi q/N)} =
    \\begin{cases} -a/2 & N \\text{ even} \\\\ -a/(2\\cos^2(\\pi/2N)) & N \\text{ odd} \\end{cases}

Without ``k4`` (and for ``k4 < 0``, which softens short wavelengths further) the critical
mode is :math:`q^* = \\lfloor N/2 \\rfloor` (with its mirror image :math:`N - q^*` for odd N);
``k4 > 0`` moves it to the mode whose :math:`\\mu_q` is nearest :math:`\\sqrt{2a/k_4}` from
either side. At :math:`k = k_{di}` its x diffuses (zero stiffness) while V stays finite;
beyond, it grows as :math:`e^{\\lambda t}` with :math:`\\lambda` the largest real root of the
characteristic polynomial.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import check_int, check_real
from ..model import Harvester, Params, mode_sin2
from ..wide import Float, Wide

__all__ = [
    "Threshold",
    "k_di",
    "threshold",
    "critical_mode",
    "max_sin2",
    "mode_eigenvalues",
    "growth_rate",
    "mode_growth_rate",
    "classify",
    "classify_modes",
    "kappa_min",
    "softest_mode",
    "ring_spectrum",
    "wide_mode_stiffness",
    "wide_growth_rate",
    "MARGINAL_RTOL",
]

#: Relative tolerance on the smallest mode stiffness below which a ring counts as marginal.
MARGINAL_RTOL = 64 * np.finfo(float).eps


def max_sin2(N: int) -> float:
    """:math:`\\max_q \\sin^2(\\pi q/N)`: 0 for N = 1, 1 for even N, cos^2(pi/2N) for odd N."""
    N = check_int("N", N, low=1)
    if N == 1:
        return 0.0
    if N % 2 == 0:
        return 1.0
    return math.cos(math.pi / (2 * N)) ** 2


def _softening(N: int, a: float, k4: float) -> np.ndarray:
    """:math:`2a/\\mu_q + k_4\\mu_q` for q = 1..N//2 (the coupling k that zeroes mode q is minus it)."""
    mu = 4.0 * mode_sin2(N)[1:N // 2 + 1]
    return 2.0 * a / mu + k4 * mu


def k_di(N: int, a: float, k4: float = 0.0) -> float | None:
    """Diffusive-instability threshold of a harmonic ring (``None`` for N = 1).

    .. math::

        k_{di} = -\\min_{q \\ge 1}\\Big(\\frac{2a}{\\mu_q} + k_4\\mu_q\\Big),\\qquad
        \\mu_q = 4\\sin^2(\\pi q/N)

    Parameters
    ----------
    N : int
        Number of units, >= 1.
    a : float
        Potential strength, > 0 (unit stiffness 2a).
    k4 : float
        Bi-Laplacian coupling, any finite real (default 0). Every k above the returned value
        is stable, every k below it unstable, for either sign of ``k4``.

    Examples
    --------
    >>> round(k_di(3, 0.5), 12)
    -0.333333333333
    >>> k_di(4, 0.5)
    -0.25
    >>> round(k_di(6, 1.0, k4=0.5), 12)
    -2.166666666667
    """
    a = check_real("a", a, low=0.0, low_open=True)
    k4 = check_real("k4", k4)
    s2 = max_sin2(N)
    if s2 == 0.0:
        return None
    if k4 == 0.0:
        return float((-2.0 * Wide.of(a) / (4.0 * s2)).to_float())
    return -float(_softening(N, a, k4).min())


def critical_mode(N: int, a: float = 1.0, k4: float = 0.0) -> tuple[int, ...]:
    """Index (or mirror pair, or tied set) of the mode(s) that go soft first as k decreases.

    ``a`` matters only with ``k4 != 0``; modes whose softening coupling ties the least to
    round-off (1e-12 relative) are all returned, each with its mirror image ``N - q``.
    """
    N = check_int("N", N, low=1)
    if N == 1:
        return (0,)
    if k4 == 0.0:
        q = N // 2
        return (q,) if N % 2 == 0 else (q, N - q)
    f = _softening(N, check_real("a", a, low=0.0, low_open=True), check_real("k4", k4))
    lowest = 1 + np.flatnonzero(f <= f.min() + 1e-12 * np.abs(f).max())
    return tuple(sorted({int(q) for q in lowest} | {int(N - q) for q in lowest}))


def wide_mode_stiffness(a: np.ndarray | float, k: np.ndarray | float, N: int,
                        num: type = Wide, k4: float = 0.0) -> tuple[Wide, Wide]:
    """Mode stiffnesses :math:`\\kappa_q = 2a + 4k s_q + 16k_4 s_q^2`, :math:`s_q = \\sin^2(\\pi q/N)`,
    and their round-off scales.

    Parameters
    ----------
    a, k : array_like
        Potential strengths and couplings (broadcast); the modes go along a new last axis.
    N : int
        Ring size, >= 1.
    num : type
        :class:`~fpe_harvester.wide.Wide` (default) or :class:`~fpe_harvester.wide.Float` (fast path).
    k4 : float
        Bi-Laplacian coupling, shared by all points (default 0: the term is not evaluated).

    Returns
    -------
    kappa, scale : Wide
        :math:`\\kappa_q` rounded as float arithmetic rounds it (never overflowing), and
        :math:`2a + 4|k|s_q + 16|k_4|s_q^2`, the size of the terms whose cancellation can leave
        round-off in :math:`\\kappa_q` (at most a few ulps of it).
    """
    a_w = num.of(np.asarray(a, dtype=float)[..., None])
    k_arr = np.asarray(k, dtype=float)[..., None]
    s2 = num.of(mode_sin2(N))
    kappa, scale = 2.0 * a_w + 4.0 * num.of(k_arr) * s2, 2.0 * a_w + 4.0 * num.of(np.abs(k_arr)) * s2
    if k4 != 0.0:
        quartic = 16.0 * s2 * s2
        kappa, scale = kappa + num.of(k4) * quartic, scale + num.of(abs(k4)) * quartic
    return kappa, scale


def classify_modes(kappa: Wide | Float, scale: Wide | Float) -> tuple[np.ndarray, np.ndarray]:
    """Per mode: ``(marginal, unstable)`` boolean arrays.

    A mode is marginal when :math:`|\\kappa_q| \\le` :data:`MARGINAL_RTOL` times its own round-off
    scale :math:`2a + 4|k|\\sin^2(\\pi q/N)`, so that ``k = k_di`` typed in floating point lands there
    while a mode whose stiffness is an exact ``2a`` (``q = 0``, or any mode for ``k >= 0``) never
    does, however small ``a`` or large ``k``; it is unstable when :math:`\\kappa_q < 0` beyond that.
    """
    marginal = (abs(kappa) / scale).to_float() <= MARGINAL_RTOL
    return marginal, (kappa.sign() < 0) & ~marginal


def _cubic(kappa: Wide, p: Params) -> tuple[Wide, Wide, Wide]:
    """Coefficients :math:`(b_2, b_1, b_0)` of the monic (x, v, V) cubic of a mode."""
    m, g, tp = Wide.of(p.m), Wide.of(p.gamma), Wide.of(p.tau_p)
    return g + 1.0 / tp, kappa / m + g / tp + Wide.of(p.Kv) * Wide.of(p.Kc) / m, kappa / (m * tp)


def _numpy_roots(c: tuple[Wide, Wide, Wide]) -> tuple[np.ndarray, int]:
    """``numpy.roots`` of :math:`s^3 + c_2 s^2 + c_1 s + c_0` as ``(lam, j)``, roots ``lam * 2**j``.

    ``j = 0`` when every coefficient is a normal float in [2^-300, 2^300]; otherwise ``j`` makes
    the coefficients of :math:`\\lambda = s/2^j` at most 1 in size. Roots at 0 (a zero
    coefficient, or one below the scaled range) are kept, so there are always three.
    """
    coeffs = [float(x.to_float()) for x in c]
    j = 0
    if not all(x == 0.0 or 2.0**-300 <= abs(x) <= 2.0**300 for x in coeffs):
        j = max(int(math.ceil(int(x.exp) / power)) for x, power in zip(c, (1, 2, 3)) if x.mant != 0)
        coeffs = [float((x / Wide(1.0, j * power)).to_float()) for x, power in zip(c, (1, 2, 3))]
    lam = np.roots([1.0, *coeffs]).astype(complex)
    return np.append(lam, np.zeros(3 - lam.size, dtype=complex)), j


def _roots(kappa: Wide, p: Params) -> tuple[np.ndarray, int, list | None]:
    """Roots of a mode's (x, v, V) cubic: ``(lam, j, precise)``.

    ``lam * 2**j`` are the ``numpy.roots`` values (:func:`_numpy_roots`). Those are known only
    to about :math:`\\epsilon` times the largest root: not enough for a root far smaller than the
    others (the slow decay of a stiff unit, e.g. -4e-22 next to roots of size 3e10) nor for a
    real part far smaller than its root (a unit damped only by a weak electrical coupling).
    When some root is below 1e-8 of the largest, or has such a real part, ``precise`` holds the
    three roots as mpmath numbers: the largest from ``numpy.roots``, the smallest from the
    reversed cubic (whose largest roots they are), the third from :math:`s_1 s_2 s_3 = -b_0`,
    all polished by Newton's method on the exact coefficients at 40, then 160, then 640 digits
    until their real parts are resolved (a real part still below that precision is NaN).
    Otherwise ``precise`` is None.
    """
    import mpmath

    b = _cubic(kappa, p)
    lam, j = _numpy_roots(b)
    big = float(np.abs(lam).max())
    unresolved = (np.abs(lam) < 1e-8 * big) | (np.abs(lam.real) < 1e-8 * big)
    if b[2].mant == 0 or not unresolved.any():
        return lam, j, None
    b2, b1, b0 = b
    mu, jr = _numpy_roots((b1 / b0, b2 / b0, 1.0 / b0))
    with mpmath.workdps(40):
        large = sorted((_mpc(z, j) for z in lam), key=lambda z: -abs(z))
        small = sorted((1 / _mpc(z, jr) for z in mu if z != 0), key=abs)
        c0 = _mp(b0)
        if large[0].imag != 0:
            guess = [large[0], large[1], -c0 / (large[0] * large[1])]
        elif len(small) > 1 and small[0].imag != 0:
            guess = [large[0], small[0], small[1]]
        else:
            guess = [large[0], small[0], -c0 / (large[0] * small[0])]
    return lam, j, _polish(guess, _mp(kappa), p)


def _mp(x: Wide) -> Any:
    """A (0-d) :class:`Wide` as an mpmath number, exactly."""
    import mpmath

    return mpmath.ldexp(mpmath.mpf(float(x.mant)), int(x.exp))


def _mpc(z: complex, j: int) -> Any:
    """``z * 2**j`` as an mpmath complex, exactly."""
    import mpmath

    return mpmath.mpc(mpmath.ldexp(z.real, j), mpmath.ldexp(z.imag, j))


def _polish(guess: list, kappa: Any, p: Params) -> list:
    """Newton's method on a mode's cubic from ``guess``, its coefficients exact at each precision.

    The coefficients are formed in mpmath from the exact binary parameters (a float
    :math:`\\kappa/m + K_vK_c/m` would drop the weak coupling that decides the damping).
    """
    import mpmath

    for dps in (40, 160, 640):
        with mpmath.workdps(dps):
            m, g, tp, Kv, Kc = (mpmath.mpf(x) for x in (p.m, p.gamma, p.tau_p, p.Kv, p.Kc))
            c2, c1, c0 = g + 1 / tp, kappa / m + g / tp + Kv * Kc / m, kappa / (m * tp)
            zs = []
            for z in guess:
                z = mpmath.mpc(z)
                for _ in range(8 + dps // 20):
                    slope = (3 * z + 2 * c2) * z + c1
                    if slope == 0:
                        break
                    z = z - (((z + c2) * z + c1) * z + c0) / slope
                zs.append(z)
            resolved = [abs(z.real) > mpmath.mpf(10) ** (10 - dps) * abs(z) for z in zs]
            if all(resolved):
                return zs
    return [z if ok else mpmath.mpc(mpmath.nan, z.imag) for z, ok in zip(zs, resolved)]


def mode_eigenvalues(kappa: float, params: Params) -> np.ndarray:
    """The four eigenvalues of one mode's drift: -1/tau and the roots of the (x, v, V) cubic.

    .. math::

        s^3 + (\\gamma + 1/\\tau_p) s^2 + (\\kappa/m + \\gamma/\\tau_p + K_vK_c/m) s
        + \\kappa/(m\\tau_p) = 0

    Eigenvalues beyond the double range come back as complex infinities (or 0 below it), a
    real part that cannot be resolved as NaN; :func:`wide_growth_rate` gives the largest real
    part without the range limitation.
    """
    lam, j, precise = _roots(Wide.of(kappa), params)
    if precise is not None:
        roots = np.array([complex(z) for z in precise])
    else:
        with np.errstate(over="ignore", under="ignore", invalid="ignore"):
            roots = np.ldexp(lam.real, j) + 1j * np.ldexp(lam.imag, j)
    return np.concatenate([roots, [-(Wide.of(1.0) / Wide.of(params.tau)).to_float()]])


def wide_growth_rate(kappa: float | Wide, params: Params) -> Wide | None:
    """Largest real part of the spectrum of a mode of stiffness ``kappa``, as a :class:`Wide`.

    ``None`` when it is not resolved even at 640 digits (a real part below 1e-630 of its root).
    """
    import mpmath

    lam, j, precise = _roots(Wide.of(kappa), params)
    if precise is None:
        rate = Wide(float(lam.real.max()), j)
    else:
        known = [z.real for z in precise if not mpmath.isnan(z.real)]
        if len(known) < len(precise) and not (known and max(known) > 0):
            return None
        mant, exp = mpmath.frexp(max(known))
        rate = Wide(float(mant), int(exp))
    decay = -(Wide.of(1.0) / Wide.of(params.tau))
    return rate if (rate - decay).sign() >= 0 else decay


def ring_spectrum(h: Harvester) -> np.ndarray:
    """All 4N eigenvalues of the ring's drift, mode by mode (shape (N, 4))."""
    kappa, _ = wide_mode_stiffness(h.a, h.k, h.N, k4=h.k4)
    return np.array([mode_eigenvalues(kappa[q], h.params) for q in range(h.N)])


def mode_growth_rate(kappa: float, params: Params) -> float:
    """Largest real part of the spectrum of one mode of stiffness ``kappa`` (> 0: it grows).

    ``inf`` (or a value below the normal range) when the rate itself is beyond the double range,
    NaN when it is not resolved (:func:`wide_growth_rate`).
    """
    rate = wide_growth_rate(kappa, params)
    return math.nan if rate is None else float(rate.to_float())


def softest_mode(h: Harvester) -> int:
    """Mode of least stiffness: without ``k4``, 0 for ``k >= 0`` and ``N // 2`` for ``k < 0``;
    with ``k4``, the least of :math:`\\kappa_q` over q = 0..N//2."""
    if h.k4 == 0.0:
        return h.N // 2 if h.k < 0 else 0
    return int(np.argmin(h.mode_stiffness()[:h.N // 2 + 1]))


def kappa_min(h: Harvester) -> Wide:
    """Smallest mode stiffness, that of :func:`softest_mode`.

    Computed for that mode alone, with the same operations as :func:`wide_mode_stiffness`.
    """
    if h.k4 != 0.0:
        kappa, _ = wide_mode_stiffness(h.a, h.k, h.N, k4=h.k4)
        return kappa[softest_mode(h)]
    q = np.array([softest_mode(h)])
    s2 = np.sin(math.pi * np.minimum(q, h.N - q) / h.N) ** 2  # as in mode_sin2
    return (2.0 * Wide.of(h.a) + 4.0 * Wide.of(h.k) * Wide.of(s2))[0]


def growth_rate(h: Harvester) -> float:
    """Largest real part of the ring's drift spectrum (> 0 means unstable; see :func:`mode_growth_rate`)."""
    rate = wide_growth_rate(kappa_min(h), h.params)
    return math.nan if rate is None else float(rate.to_float())


def classify(h: Harvester) -> tuple[str, float]:
    """``("stable" | "marginal" | "unstable", smallest mode stiffness)`` of a harmonic ring.

    Each mode is judged against its own round-off scale (:func:`classify_modes`), so that
    ``k = k_di`` typed in floating point is marginal while e.g. ``k = 1e14`` or ``a = 1e-14`` with
    ``k = 1`` stays stable. The stiffness is returned as a float (``inf`` past the double range).
    """
    kappa, scale = wide_mode_stiffness(h.a, h.k, h.N, k4=h.k4)
    marginal, unstable = classify_modes(kappa, scale)
    kmin = float(kappa_min(h).to_float())
    if unstable.any():
        return "unstable", kmin
    return ("marginal" if marginal.any() else "stable"), kmin


@dataclass(frozen=True)
class Threshold:
    """Stability threshold of a harmonic ring.

    Attributes
    ----------
    N, a : int, float
        Ring size and potential strength.
    k_di : float or None
        Coupling below which the ring has no stationary state (``None`` for N = 1: always stable).
    critical_mode : tuple of int
        Mode index (or mirror pair) whose stiffness vanishes at ``k_di``.
    k4 : float
        Bi-Laplacian coupling the threshold is for (default 0).
    """

    N: int
    a: float
    k_di: float | None
    critical_mode: tuple[int, ...]
    k4: float = 0.0

    @property
    def explanation(self) -> str:
        """One line saying what the threshold means."""
        if self.k_di is None:
            return "a single unit (N = 1) has no coupling and is stable for every a > 0"
        q = " and ".join(f"q = {c}" for c in self.critical_mode)
        stiffness = "2a + 4k sin^2(pi q/N)" if self.k4 == 0.0 else "2a + k mu_q + k4 mu_q^2 (mu_q = 4 sin^2(pi q/N))"
        return (
            f"for k < {self.k_di:.10g} mode {q} has negative stiffness {stiffness} and "
            f"grows without bound; at k = k_di it is marginal (x diffuses, V stays finite); "
            f"every k > k_di is stable"
        )

    def to_dict(self) -> dict[str, object]:
        return {
            "N": self.N,
            "a": self.a,
            "k4": self.k4,
            "k_di": self.k_di,
            "critical_mode": list(self.critical_mode),
            "explanation": self.explanation,
        }


def threshold(N: int, a: float, k4: float = 0.0) -> Threshold:
    """Closed-form threshold of a harmonic ring of ``N`` units with strength ``a`` (and ``k4``).

    Examples
    --------
    >>> th = threshold(4, 1.0, k4=0.1)
    >>> round(th.k_di, 12), th.critical_mode
    (-0.9, (2,))
    """
    N = check_int("N", N, low=1)
    a = check_real("a", a, low=0.0, low_open=True)
    k4 = check_real("k4", k4)
    return Threshold(N, a, k_di(N, a, k4), critical_mode(N, a, k4), k4)
