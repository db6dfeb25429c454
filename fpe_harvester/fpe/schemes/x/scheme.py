"""Scheme ``"x"``: its default plan, its x mesh and its entry in the scheme registry.

The discretization is DG in x times Hermite functions of (v, V, xi)
(:mod:`.discretize`); the x mesh refines uniformly or element by element (:mod:`.adapt`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ....errors import ParameterError
from ....model import Harvester
from ...protocol import Discretization, RefinementPlan, Scheme
from .adapt import AdaptiveHermiteDG
from .discretize import HermiteDG, Whitening
from .mesh import XMesh

if TYPE_CHECKING:
    from ...settings import Settings

__all__ = ["XScheme", "XMeshRule", "default_plan", "resolve_mesh", "MESHES", "ORDER", "GEOMETRIC_LAYERS",
           "GEOMETRIC_RATIO"]

#: The x meshes (see :func:`resolve_mesh`).
MESHES = ("auto", "algebraic", "geometric", "adaptive")

#: DG order unless given (P2 and P4 measured no robust gain: docs/methods.md, Fokker-Planck design notes).
ORDER = 3

#: Geometric layers toward x = 0 of the ``"geometric"`` mesh and their ratio. Measured for
#: n = 1.5, a = 1 at M = 8 on 8 bulk elements per half: 2 layers are within 3e-8 (relative
#: eta) of 10 layers; 4 keep a margin for higher M.
GEOMETRIC_LAYERS = 4
GEOMETRIC_RATIO = 0.15


def resolve_mesh(h: Harvester, mesh: str) -> str:
    """The x mesh ``"algebraic"``, ``"geometric"`` or ``"adaptive"`` that ``mesh`` means for ``h``.

    ``"auto"`` is ``"algebraic"``: for 1 < n < 2 it measured at least as accurate per
    unknown as the geometric one (see :class:`XMeshRule`), and the element-wise
    refinement (``"adaptive"``, any n) did not measure faster overall (see
    :mod:`validation.studies.fpe.bench`). For n >= 2 the mesh is graded toward the walls only and
    ``"algebraic"`` names that mesh; ``"geometric"`` is refused.
    """
    _check_mesh_name(mesh)
    if mesh == "adaptive":
        return mesh
    if mesh == "geometric" and h.n >= 2.0:
        raise ParameterError(f"mesh='geometric' grades toward the non-smooth force at x = 0 of n < 2, "
                             f"got n = {h.n!r}; use mesh='auto'")
    return "algebraic" if mesh == "auto" else mesh


def _check_mesh_name(mesh: str) -> None:
    if mesh not in MESHES:
        raise ParameterError(f"mesh must be one of {', '.join(map(repr, MESHES))}, got {mesh!r} "
                             f"(type {type(mesh).__name__})")


@dataclass(frozen=True)
class XMeshRule:
    """How scheme ``"x"`` builds its x mesh (:class:`~.mesh.XMesh`) for a harvester.

    Attributes
    ----------
    domain : float
        Domain factor :math:`\\Theta = U(L)/T_{eff}`.
    grading : float
        Mesh grading toward x = 0.
    wall : float
        Wall weight of the mesh monitor.
    layers : int
        Geometric layers toward x = 0 splitting the first element of each half (0: none).
    ratio : float
        Ratio of successive geometric layers, in (0, 1).
    """

    domain: float = 30.0
    grading: float = 1.0
    wall: float = 0.1
    layers: int = 0
    ratio: float = GEOMETRIC_RATIO

    @classmethod
    def of(cls, h: Harvester, mesh: str = "auto", domain: float = 30.0) -> XMeshRule:
        """Smooth potentials (n >= 2) on a mesh graded toward the walls, n < 2 (kink or
        non-smooth force at 0) graded toward 0.

        ``mesh`` (n < 2 only, :func:`resolve_mesh`): ``"algebraic"`` grades the nodes like
        :math:`t^{2.5}` toward 0; ``"geometric"`` keeps the bulk uniform (:math:`\\beta = 1`)
        and splits the element at 0 into :data:`GEOMETRIC_LAYERS` layers of ratio
        :data:`GEOMETRIC_RATIO`, with Gauss--Jacobi quadrature of the force there. For
        1 < n < 2 what limits the accuracy is the Hermite expansion in (v, V, xi), not the mesh
        (docs/methods.md, Fokker-Planck design notes).
        """
        geometric = resolve_mesh(h, mesh) == "geometric"
        return cls(domain=domain, grading=2.5 if h.n < 2.0 and not geometric else 1.0, wall=0.1,
                   layers=GEOMETRIC_LAYERS if geometric else 0, ratio=GEOMETRIC_RATIO)

    def build(self, h: Harvester, w: Whitening, half_elements: int) -> XMesh:
        """The mesh for ``h``: domain :math:`U(L) = \\Theta T_{eff}` of the weight ``w``,
        ``half_elements`` elements per half."""
        return XMesh(w.half_width(h, self.domain), half_elements, n=h.n, scale=math.sqrt(w.x2), domain=self.domain,
                     wall=self.wall, grading=self.grading, layers=self.layers, ratio=self.ratio)


def default_plan(h: Harvester, settings: Settings) -> RefinementPlan:
    """The refinement of scheme ``"x"``: from M = 4 on 16 elements, 8 per half (or the given
    ``M`` or ``elements``; fixed when both are given). Its mesh knob ``size`` is the
    elements per half."""
    resolve_mesh(h, settings.mesh)
    size = None if settings.elements is None else settings.elements // 2
    return RefinementPlan(M=4 if settings.M is None else settings.M, size=8 if size is None else size,
                fixed=settings.M is not None and size is not None, max_M=settings.max_M,
                max_dofs=settings.max_dofs, max_seconds=settings.max_seconds, max_gb=settings.max_gb)


class XScheme(Scheme):
    """DG in x, Hermite functions of (v, V, xi): any n, the fallback of ``scheme="auto"``."""

    name = "x"
    priority = 0
    setup_failure = "the Gaussian weight of the Hermite expansion could not be built"
    options = {"weight": "the Gaussian weight", "mesh": "the x mesh"}

    def preferred(self, h: Harvester, settings: Settings) -> bool:
        return True

    def check(self, settings: Settings) -> None:
        _check_mesh_name(settings.mesh)
        if settings.weight is not None and not isinstance(settings.weight, Whitening):
            raise ParameterError(f"weight must be a Whitening or None, got {type(settings.weight).__name__}")

    def plan(self, h: Harvester, settings: Settings) -> RefinementPlan:
        return default_plan(h, settings)

    def build(self, h: Harvester, settings: Settings, plan: RefinementPlan, tol: float, deadline: float | None
              ) -> Discretization:
        w = Whitening.of(h) if settings.weight is None else settings.weight
        base = XMeshRule.of(h, settings.mesh, settings.domain).build(h, w, plan.size)
        order = ORDER if settings.order is None else settings.order
        if resolve_mesh(h, settings.mesh) == "adaptive":
            return AdaptiveHermiteDG(h, base, order, w)
        return HermiteDG(h, base, order, w)
