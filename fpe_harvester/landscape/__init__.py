"""The coupled potential of a ring and its equilibria.

:mod:`.energy` holds the energy :math:`E(x)` of a ring with the couplings k, k4 and k3, its
force and Hessian; :mod:`.search` finds every equilibrium with its Morse index by a
deterministic search over sign patterns (treating the cusp of n = 1 at x = 0 as such);
:mod:`.reduction` has the closed forms of single-site buckling for n = 1 with cubic
coupling (fold ``k_sn``, coexistence ``k_co``, barriers); :mod:`.survey` puts them together
in :func:`landscape`, the call behind ``harvester landscape``.
"""

from __future__ import annotations

from .energy import RingEnergy
from .reduction import Buckling, buckling, coexistence_coupling, fold_coupling
from .search import MAX_SEARCH_N, Equilibrium, find_equilibria
from .survey import Landscape, bounded_below, landscape

__all__ = [
    "MAX_SEARCH_N",
    "Buckling",
    "Equilibrium",
    "Landscape",
    "RingEnergy",
    "bounded_below",
    "buckling",
    "coexistence_coupling",
    "find_equilibria",
    "fold_coupling",
    "landscape",
]
