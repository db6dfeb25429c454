"""Fokker--Planck solver for a single nonlinear harvester: Hermite functions in (v, V, xi),
upwind discontinuous Galerkin in x (scikit-fem), tolerance-driven refinement. For the kink
n = 1 and 1 < n < 2 (default there): discontinuous Galerkin in (x, v) on a mesh
graded geometrically toward the trap at (0, 0), Hermite functions in (V, xi) only
(:mod:`.schemes.xv`), behind the same refinement and error estimate. The x mesh of scheme
``"x"`` (:mod:`.schemes.x`) refines uniformly or element by element. Each scheme follows
the protocol of :mod:`.protocol` and is found through the registry of :mod:`.schemes`.
Where the solver answers is measured and declared in :mod:`.domain`: outside (the strong
kink) :class:`FokkerPlanck` declines at once and names Monte Carlo.

Public API: the solver object :class:`FokkerPlanck` (``method="fpe"``), the richer
:func:`stationary` returning an :class:`FPESolution` (density, conditional means,
identity residuals), time-dependent runs through py-pde (:func:`transient`, with the exact
harmonic reference :func:`lyapunov_transient`), and the building blocks
:class:`HermiteBasis` and :class:`XMesh`.
"""

from __future__ import annotations

from .hermite import HermiteBasis
from .schemes.x import XMesh
from .solver import FokkerPlanck
from .stationary import FPESolution, stationary
from .transient import TransientSolution, lyapunov_transient, transient

__all__ = [
    "FokkerPlanck",
    "stationary",
    "FPESolution",
    "transient",
    "TransientSolution",
    "lyapunov_transient",
    "HermiteBasis",
    "XMesh",
]
