"""Fokker--Planck solver for a single nonlinear harvester: Hermite functions in (v, V, xi),
upwind discontinuous Galerkin in x (scikit-fem), tolerance-driven refinement.

Public API: the solver object :class:`FokkerPlanck` (``method="fpe"``), the richer
:func:`stationary` returning an :class:`FPESolution` (density, conditional means,
identity residuals), and the building blocks :class:`HermiteBasis` and :class:`XMesh`.
"""

from __future__ import annotations

from .hermite import HermiteBasis
from .mesh import XMesh
from .solver import FokkerPlanck
from .stationary import FPESolution, stationary

__all__ = ["FokkerPlanck", "stationary", "FPESolution", "HermiteBasis", "XMesh"]
