"""Where the Fokker--Planck solver answers: its measured domain, and the message outside it.

Provisional rule, replaced by the measured one.
"""

from __future__ import annotations

import math

from ..model import Harvester
from .hermite import equivalent_harmonic

__all__ = ["trap_strength", "outside_reason"]


def trap_strength(h: Harvester) -> float:
    """a over the standard deviation of the drive of the equivalent harmonic unit."""
    p = h.params
    _, P = equivalent_harmonic(h)
    var = p.sigma**2 * P[3, 3] + p.Kv**2 * P[2, 2] - 2.0 * p.sigma * p.Kv * P[2, 3]
    return h.a / min(math.sqrt(max(var, 0.0)), p.sigma * math.sqrt(p.D / p.tau))


def outside_reason(h: Harvester) -> str | None:
    """None inside the domain, else why not and what to use."""
    if h.n >= 2.0 or h.n >= 1.5:
        return None
    s = trap_strength(h)
    if s <= 1.9:
        return None
    return f"outside the measured domain of the Fokker-Planck solver (n = {h.n:g}, a / sd(F) = {s:.3g}); use method='mc'"
