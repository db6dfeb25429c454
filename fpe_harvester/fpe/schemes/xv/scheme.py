"""Scheme ``"xv"``: its default plan and its entry in the scheme registry.

The discretization is DG in (x, v) on a mesh graded toward the trap times Hermite functions
of (V, xi) (:mod:`.kink`), refined in M and in the DG degree (:mod:`.kinkdisc`), for the
kink n = 1 and for 1 < n < 2.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ....model import Harvester
from ...protocol import Discretization, RefinementPlan, Scheme
from .kinkdisc import KinkDG, KinkSettings

if TYPE_CHECKING:
    from ...settings import Settings

__all__ = ["XVScheme", "default_plan", "MAX_DOFS"]

#: Unknowns allowed to a level (GMRES in the mode basis holds about 200 vectors of the half
#: plane's unknowns; the memory bound max_gb applies too).
MAX_DOFS = 6_000_000


def default_plan(h: Harvester, settings: Settings) -> RefinementPlan:
    """The refinement of scheme ``"xv"``: from M = 4 on the base mesh (size 1, the DG degree
    ``order``; the refinement's mesh knob ``size`` raises the degree by log2 of it, at most 8);
    a given ``M`` alone fixes the level."""
    return RefinementPlan(M=4 if settings.M is None else settings.M, size=1,
                fixed=settings.M is not None, max_M=settings.max_M, max_size=8,
                max_dofs=max(settings.max_dofs, MAX_DOFS), max_seconds=settings.max_seconds,
                max_gb=settings.max_gb)


class XVScheme(Scheme):
    """DG in (x, v), Hermite functions of (V, xi): 1 <= n < 2, the choice of
    ``scheme="auto"`` there unless an option of scheme ``"x"`` or its mesh knob is given.

    For 1 < n < 2 it converges in more cases than scheme ``"x"`` and the two agree within
    their error bars where both do (docs/methods.md, Fokker-Planck design notes).
    """

    name = "xv"
    priority = 1
    setup_failure = "the kink solver's pilot level failed"

    def refusal(self, h: Harvester) -> str:
        if 1.0 <= h.n < 2.0:
            return ""
        return (f"scheme='xv' (DG in x and v) is built for the kink n = 1 and for 1 < n < 2, "
                f"got n = {h.n!r}; use scheme='x' or 'auto'")

    def preferred(self, h: Harvester, settings: Settings) -> bool:
        x_settings = any(settings.given(name) for name in ("mesh", "weight", "elements"))
        return h.n == 1.0 or (1.0 < h.n < 2.0 and not x_settings)

    def plan(self, h: Harvester, settings: Settings) -> RefinementPlan:
        return default_plan(h, settings)

    def build(self, h: Harvester, settings: Settings, plan: RefinementPlan, tol: float, deadline: float | None
              ) -> Discretization:
        # 1 < n < 2 has no trap at the origin: one core element per axis (measured at
        # a = 1, tol 1e-4: n = 1.5 eta 0.3878655 in 22 s against 0.3878575 +- 1.4e-5 in
        # 47 s with the kink's four layers; n = 1.25 0.3919145 in 31 s against 0.3919087 in 90 s)
        kink = KinkSettings(order=3 if settings.order is None else settings.order,
                            layers=1 if h.n > 1.0 else KinkSettings.layers)
        return KinkDG.build(h, kink, tol, deadline)
