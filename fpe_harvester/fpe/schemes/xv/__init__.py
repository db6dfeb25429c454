"""Scheme ``"xv"``: DG in (x, v) graded toward the trap, Hermite functions of (V, xi)
(:mod:`.hierarchy` the frame, the Hermite hierarchy and the plane's matrices, :mod:`.kink` the
level, :mod:`.modesolve` its preconditioner, :mod:`.kinkdisc` the refinement family,
:mod:`.scheme` the plan and the registry entry)."""

from __future__ import annotations

from .hierarchy import KinkFrame
from .kink import KinkLevel, solve_kink_level
from .kinkdisc import KinkDG, KinkSettings, kink_domain
from .scheme import XVScheme

__all__ = ["KinkDG", "KinkSettings", "KinkLevel", "KinkFrame", "solve_kink_level", "kink_domain", "XVScheme"]
