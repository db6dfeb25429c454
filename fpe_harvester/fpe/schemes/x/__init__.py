"""Scheme ``"x"``: DG in x, Hermite functions of (v, V, xi) (:mod:`.discretize` the level
and the refinement family, :mod:`.adapt` the element-wise one, :mod:`.mesh` the x mesh,
:mod:`.scheme` the plan, the mesh rule and the registry entry)."""

from __future__ import annotations

from .adapt import AdaptiveHermiteDG
from .discretize import HermiteDG, Level, Whitening, level_gigabytes, solve_level
from .mesh import XMesh
from .scheme import MESHES, ORDER, XMeshRule, XScheme, default_plan, resolve_mesh

__all__ = ["HermiteDG", "AdaptiveHermiteDG", "Level", "Whitening", "solve_level", "level_gigabytes", "XMesh",
           "XMeshRule", "XScheme", "default_plan", "resolve_mesh", "MESHES", "ORDER"]
