"""The landscape of a ring: its equilibria, whether it is bounded below, and (n = 1 with cubic
coupling) the fold, coexistence and barriers of single-site buckling."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Harvester
from .energy import RingEnergy
from .reduction import Buckling, buckling
from .search import Equilibrium, find_equilibria

__all__ = ["Landscape", "landscape", "bounded_below"]


def bounded_below(e: RingEnergy) -> tuple[bool, str]:
    """Whether :math:`E` is bounded below, and why.

    ``k3 > 0`` bounds every ring (the quartic bonds outgrow any quadratic coupling, and the
    on-site term holds the uniform mode). Without it, the coupling adds
    :math:`c_q = k\\mu_q + k_4\\mu_q^2` to mode q's energy :math:`\\frac12(\\cdot)|\\hat x_q|^2`: if some
    :math:`c_q < 0` (q >= 1), :math:`a|x|^n` cannot hold that mode for n < 2, can for n > 2, and
    for n = 2 holds it iff :math:`2a + c_q > 0`.
    """
    if e.N == 1:
        return True, "a single unit: a|x|^n alone, bounded below by 0"
    if e.k3 > 0:
        return True, "k3 > 0: the quartic bond energy outgrows every quadratic term, the ring is confined"
    mu = 4.0 * np.sin(np.pi * np.arange(1, e.N // 2 + 1) / e.N) ** 2
    c = e.k * mu + e.k4 * mu**2
    if c.min() >= 0:
        return True, "the coupling adds no negative stiffness to any mode: bounded below"
    if e.n > 2:
        return True, f"n = {e.n:g} > 2: a|x|^n outgrows the coupling's negative quadratic energy"
    if e.n == 2:
        ok = bool(2.0 * e.a + c.min() >= 0)
        return ok, ("harmonic ring with every mode stiffness >= 0" if ok else
                    "harmonic ring with a negative mode stiffness (k < k_di): unbounded below")
    return False, (f"n = {e.n:g} < 2 with a negative coupling stiffness and k3 = 0: E -> -inf along the "
                   "softened mode (no global minimum; the ring is at best metastable)")


@dataclass(frozen=True)
class Landscape:
    """Equilibria of a ring's potential :math:`E(x)` (:class:`~.energy.RingEnergy`).

    Attributes
    ----------
    energy : RingEnergy
        The landscape's parameters (n, a, N, k, k4, k3).
    equilibria : tuple of Equilibrium
        Every equilibrium found, by increasing energy.
    bounded : bool
        Whether E is bounded below; if not there is no global minimum.
    message : str
        Why it is (or is not) bounded.
    buckling : Buckling or None
        Fold, coexistence and barriers of single-site buckling (n = 1, k3 > 0, k4 = 0, N >= 3).
    """

    energy: RingEnergy
    equilibria: tuple[Equilibrium, ...]
    bounded: bool
    message: str
    buckling: Buckling | None

    @property
    def minima(self) -> tuple[Equilibrium, ...]:
        """The local minima (index 0, not degenerate)."""
        return tuple(q for q in self.equilibria if q.index == 0 and not q.degenerate)

    @property
    def global_minimum(self) -> Equilibrium | None:
        """The lowest equilibrium if E is bounded below (then it is a minimum), else None."""
        return self.equilibria[0] if self.bounded and self.equilibria else None

    def to_dict(self) -> dict[str, object]:
        e = self.energy
        gmin = self.global_minimum
        return {"n": e.n, "a": e.a, "N": e.N, "k": e.k, "k4": e.k4, "k3": e.k3, "bounded": self.bounded,
                "message": self.message, "global_minimum": None if gmin is None else list(gmin.x),
                "buckling": None if self.buckling is None else self.buckling.to_dict(),
                "equilibria": [q.to_dict() for q in self.equilibria]}


def landscape(system: Harvester | RingEnergy) -> Landscape:
    """Equilibria, boundedness and (n = 1 with k3 > 0) buckling of a ring's potential.

    Parameters
    ----------
    system : Harvester or RingEnergy
        The ring (a harvester's physical parameters do not enter). N in [1, 6].

    Examples
    --------
    >>> ls = landscape(RingEnergy(n=1, a=1.0, N=3, k=-2.0, k3=1.0))
    >>> ls.bounded, round(ls.buckling.k_sn, 6), len(ls.minima)
    (True, -1.190551, 7)
    """
    e = system if isinstance(system, RingEnergy) else RingEnergy.of(system)
    bounded, message = bounded_below(e)
    reduction = buckling(e.a, e.k, e.k3, e.N) if e.n == 1 and e.k3 > 0 and e.k4 == 0 and e.N >= 3 else None
    return Landscape(e, find_equilibria(e), bounded, message, reduction)
