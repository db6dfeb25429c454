"""Closed forms of the n = 1 ring with cubic coupling: single-site buckled states, the fold and
coexistence couplings, and the barriers between the origin and the buckled states.

With one unit displaced by u > 0 and its neighbours held at the cusp x = 0 (N >= 3, k4 = 0),
the two bonds at the displaced unit give

.. math::

    E_1(u) = a u + k u^2 + \\frac{k_3}2 u^4,\\qquad E_1'(u) = 0 \\iff 2k_3u^3 + 2ku + a = 0.

The cubic has two positive roots, the saddle :math:`u_s` (escape from the origin) and the
buckled minimum :math:`u_+ > u_s`, below the fold

.. math::

    k_{sn} = -\\Big(\\frac{27a^2k_3}{16}\\Big)^{1/3},

and the buckled state has the energy of the origin at the coexistence coupling

.. math::

    k_{co} = -\\Big(\\frac{27a^2k_3}{8}\\Big)^{1/3}

(beyond it, :math:`k < k_{co}`, it is the lower). The neighbours stay at the cusp because the
force on each, :math:`|ku + k_3u^3| = a/2`, is inside the subgradient :math:`[-a, a]`. Two
neighbouring buckled states of opposite sign are joined through the hop saddle (u, -u, 0, ...):

.. math::

    E_2(u) = 2au + 3ku^2 + \\frac92 k_3u^4,\\qquad E_2'(u) = 0 \\iff 18k_3u^3 + 6ku + 2a = 0,

at the larger positive root (its third unit is held for any N = 3; for N >= 4 the outer
neighbours feel :math:`|ku + k_3u^3|`, which must be at most a).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import check_real

__all__ = ["Buckling", "buckling", "fold_coupling", "coexistence_coupling"]


def fold_coupling(a: float, k3: float) -> float:
    """:math:`k_{sn} = -(27a^2k_3/16)^{1/3}`: below it the single-site buckled state exists."""
    return -float(np.cbrt(27.0 * a * a * k3 / 16.0))


def coexistence_coupling(a: float, k3: float) -> float:
    """:math:`k_{co} = -(27a^2k_3/8)^{1/3}`: below it the buckled state is below the origin."""
    return -float(np.cbrt(27.0 * a * a * k3 / 8.0))


def _positive_roots(c3: float, c1: float, c0: float) -> list[float]:
    """Positive real roots of :math:`c_3u^3 + c_1u + c_0`, ascending, Newton-polished."""
    roots = []
    for z in np.roots([c3, 0.0, c1, c0]):
        if abs(z.imag) > 1e-7 * max(abs(z), 1.0) or z.real <= 0:
            continue
        u = z.real
        for _ in range(4):
            slope = 3.0 * c3 * u * u + c1
            if slope == 0.0:
                break
            u -= (c3 * u**3 + c1 * u + c0) / slope
        roots.append(float(u))
    return sorted(roots)


@dataclass(frozen=True)
class Buckling:
    """Single-site buckling of an n = 1 ring with cubic coupling (module docstring).

    Attributes
    ----------
    k_sn, k_co : float
        Fold and coexistence couplings.
    u_s, u_plus : float or None
        Saddle and buckled displacements (None above the fold, ``k > k_sn``).
    escape_barrier : float or None
        :math:`E_1(u_s) - E(0) = E_1(u_s)`, out of the origin.
    return_barrier : float or None
        :math:`E_1(u_s) - E_1(u_+)`, from the buckled state back to the origin.
    u_hop : float or None
        Displacement of the hop saddle (u, -u, 0, ...).
    hop_barrier : float or None
        :math:`E_2(u_{hop}) - E_1(u_+)`, between neighbouring buckled states (None where the hop
        saddle's neighbours are not held at the cusp, N >= 4).
    """

    k_sn: float
    k_co: float
    u_s: float | None
    u_plus: float | None
    escape_barrier: float | None
    return_barrier: float | None
    u_hop: float | None
    hop_barrier: float | None

    def to_dict(self) -> dict[str, object]:
        return dict(self.__dict__)


def buckling(a: float, k: float, k3: float, N: int = 3) -> Buckling:
    """Single-site states and barriers of an n = 1 ring (``k4 = 0``, N >= 3) with ``k3 > 0``.

    Examples
    --------
    >>> b = buckling(1.0, -2.0, 1.0)
    >>> round(b.escape_barrier, 6), round(b.return_barrier, 6), round(b.hop_barrier, 6)
    (0.127088, 0.78219, 0.193831)
    """
    a = check_real("a", a, low=0.0, low_open=True)
    k = check_real("k", k)
    k3 = check_real("k3", k3, low=0.0, low_open=True)
    single = _positive_roots(2.0 * k3, 2.0 * k, a)
    if len(single) < 2:
        return Buckling(fold_coupling(a, k3), coexistence_coupling(a, k3), None, None, None, None, None, None)
    u_s, u_plus = single[0], single[-1]

    def e1(u: float) -> float:
        return a * u + k * u * u + 0.5 * k3 * u**4

    hop = _positive_roots(18.0 * k3, 6.0 * k, 2.0 * a)
    u_hop = hop[-1] if hop else None
    hop_barrier = None
    if u_hop is not None and (N == 3 or abs(k * u_hop + k3 * u_hop**3) <= a):
        hop_barrier = 2.0 * a * u_hop + 3.0 * k * u_hop**2 + 4.5 * k3 * u_hop**4 - e1(u_plus)
    return Buckling(fold_coupling(a, k3), coexistence_coupling(a, k3), u_s, u_plus, e1(u_s),
                    e1(u_s) - e1(u_plus), u_hop, hop_barrier)
