"""Stability of harmonic rings: the diffusive-instability threshold k_di and growth rates.

Mode ``q`` of a harmonic ring is a single unit with stiffness
:math:`\\kappa_q = 2a + 4k\\sin^2(\\pi q/N)`. A unit is stable iff its stiffness is
positive (Routh--Hurwitz on the cubic of the (x, v, V) block, for any positive
parameters), so the ring loses its stationary state when some :math:`\\kappa_q < 0`:

.. math::

    k_{di} = -\\frac{2a}{4\\max_q \\sin^2(\\pi q/N)} =
    \\begin{cases} -a/2 & N \\text{ even} \\\\ -a/(2\\cos^2(\\pi/2N)) & N \\text{ odd} \\end{cases}

The critical mode is :math:`q^* = \\lfloor N/2 \\rfloor` (with its mirror image
:math:`N - q^*` for odd N). At :math:`k = k_{di}` its x diffuses (zero stiffness) while
V stays finite; beyond, it grows as :math:`e^{\\lambda t}` with :math:`\\lambda` the largest
real root of the characteristic polynomial.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import check_int, check_real
from ..model import Harvester, Params

__all__ = [
    "Threshold",
    "k_di",
    "threshold",
    "critical_mode",
    "max_sin2",
    "mode_eigenvalues",
    "ring_spectrum",
    "growth_rate",
    "mode_growth_rate",
    "classify",
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


def k_di(N: int, a: float) -> float | None:
    """Diffusive-instability threshold of a harmonic ring (``None`` for N = 1).

    Parameters
    ----------
    N : int
        Number of units, >= 1.
    a : float
        Potential strength, > 0 (unit stiffness 2a).

    Examples
    --------
    >>> round(k_di(3, 0.5), 12)
    -0.333333333333
    >>> k_di(4, 0.5)
    -0.25
    """
    a = check_real("a", a, low=0.0, low_open=True)
    s2 = max_sin2(N)
    if s2 == 0.0:
        return None
    return -2.0 * a / (4.0 * s2)


def critical_mode(N: int) -> tuple[int, ...]:
    """Index (or mirror pair of indices) of the mode that goes soft first for k < 0."""
    N = check_int("N", N, low=1)
    if N == 1:
        return (0,)
    q = N // 2
    return (q,) if N % 2 == 0 else (q, N - q)


def mode_eigenvalues(kappa: float, params: Params) -> np.ndarray:
    """The four eigenvalues of one mode's drift: -1/tau and the roots of the (x, v, V) cubic.

    .. math::

        s^3 + (\\gamma + 1/\\tau_p) s^2 + (\\kappa/m + \\gamma/\\tau_p + K_vK_c/m) s
        + \\kappa/(m\\tau_p) = 0
    """
    p = params
    cubic = [1.0, p.gamma + 1.0 / p.tau_p, kappa / p.m + p.gamma / p.tau_p + p.Kv * p.Kc / p.m,
             kappa / (p.m * p.tau_p)]
    roots = np.roots(cubic)
    return np.concatenate([roots, [-1.0 / p.tau]])


def ring_spectrum(h: Harvester) -> np.ndarray:
    """All 4N eigenvalues of the ring's drift, mode by mode (shape (N, 4))."""
    return np.array([mode_eigenvalues(kap, h.params) for kap in h.mode_stiffness()])


def mode_growth_rate(kappa: float, params: Params) -> float:
    """Largest real part of the spectrum of one mode of stiffness ``kappa`` (> 0: it grows)."""
    return float(mode_eigenvalues(kappa, params).real.max())


def growth_rate(h: Harvester) -> float:
    """Largest real part of the ring's drift spectrum (> 0 means unstable)."""
    return mode_growth_rate(float(h.mode_stiffness().min()), h.params)


def classify(h: Harvester) -> tuple[str, float]:
    """``("stable" | "marginal" | "unstable", smallest mode stiffness)`` of a harmonic ring.

    A ring whose smallest stiffness is within :data:`MARGINAL_RTOL` of zero (relative to
    ``2a + 4|k|``) counts as marginal, so that ``k = k_di`` typed in floating point lands there.
    """
    kmin = float(h.mode_stiffness().min())
    scale = 2.0 * h.a + 4.0 * abs(h.k)
    if abs(kmin) <= MARGINAL_RTOL * scale:
        return "marginal", kmin
    return ("stable" if kmin > 0 else "unstable"), kmin


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
    """

    N: int
    a: float
    k_di: float | None
    critical_mode: tuple[int, ...]

    @property
    def explanation(self) -> str:
        """One line saying what the threshold means."""
        if self.k_di is None:
            return "a single unit (N = 1) has no coupling and is stable for every a > 0"
        q = " and ".join(f"q = {c}" for c in self.critical_mode)
        return (
            f"for k < {self.k_di:.10g} mode {q} has negative stiffness 2a + 4k sin^2(pi q/N) and "
            f"grows without bound; at k = k_di it is marginal (x diffuses, V stays finite); "
            f"every k > k_di is stable"
        )

    def to_dict(self) -> dict[str, object]:
        return {
            "N": self.N,
            "a": self.a,
            "k_di": self.k_di,
            "critical_mode": list(self.critical_mode),
            "explanation": self.explanation,
        }


def threshold(N: int, a: float) -> Threshold:
    """Closed-form threshold of a harmonic ring of ``N`` units with strength ``a``."""
    N = check_int("N", N, low=1)
    return Threshold(N, check_real("a", a, low=0.0, low_open=True), k_di(N, a), critical_mode(N))
