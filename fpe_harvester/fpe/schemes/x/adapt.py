"""Element-wise refinement of the x mesh: an error indicator per element and the
discretization whose mesh refinement bisects only the marked elements.

*Indicator* (:func:`element_indicators`): the difference of two polynomial degrees per
element. On element K of length :math:`h_K` with Legendre expansion
:math:`c_\\alpha(x) = \\sum_{k \\le p} a_{\\alpha k} P_k(t)` of the DG solution, the part
that degree p adds to degree p - 1 has the norm

.. math::

    \\eta_K^2 = \\sum_\\alpha \\int_K \\big(c_\\alpha - \\Pi_{p-1} c_\\alpha\\big)^2 dx
             = \\frac{h_K}{2p + 1} \\sum_\\alpha a_{\\alpha p}^2 ,

summed over the Hermite modes (orthonormal, so this is the weighted :math:`L^2` norm of the
density's top x-mode). Where the solution is smooth and resolved it falls like
:math:`h_K^{p + 1/2}`; a steep wall or the non-smooth force at x = 0 keeps it large.

*Marking* (:func:`mark`): Dörfler's bulk criterion, the fewest elements that carry the
share :data:`DORFLER` of :math:`\\sum_K \\eta_K^2`.

*Discretization* (:class:`AdaptiveHermiteDG`): the refinement (:mod:`...refine`) asks for
meshes of sizes :math:`N_h 2^g`; here mesh g + 1 is mesh g with its marked elements
bisected, marked by the indicator of the highest Hermite degree solved on mesh g (the
mirror images follow: the half mesh is refined). Meshes coarser than the first are
uniform (the node map with fewer elements), as in the uniform refinement.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from skfem import Basis

from ....model import Harvester
from ...assemble import dg_element
from ...protocol import Discretization
from .discretize import ADVICE, DEGREES_PER_ELEMENT, Level, Whitening, block_size, level_gigabytes, solve_level
from .mesh import XMesh

__all__ = ["element_indicators", "mark", "AdaptiveHermiteDG", "DORFLER"]

#: Share of the summed squared indicators that the marked elements carry.
DORFLER = 0.8


def element_indicators(lv: Level) -> np.ndarray:
    """:math:`\\eta_K` of every element of the half mesh of ``lv`` (left to right): the
    :math:`L^2` norm of the degree-p Legendre part of the solution, summed over the
    Hermite modes (see the module docstring)."""
    if not lv.half:
        raise ValueError("element_indicators needs a level solved on the half mesh")
    p = lv.order
    nodes = lv.mesh.half_nodes()
    h = np.diff(nodes)
    t, wq = np.polynomial.legendre.leggauss(p + 1)
    top = np.polynomial.legendre.Legendre.basis(p)(t)
    pts = 0.5 * (nodes[:-1] + nodes[1:])[:, None] + 0.5 * h[:, None] * t[None, :]
    X = lv.xmat
    # A fresh element: ElementLinePp caches reference values by array shape only.
    basis = Basis(X.basis.mesh, dg_element(p), intorder=2 * p + 2)
    probe = basis.probes(pts.reshape(1, -1))
    u = np.zeros((basis.N, lv.coef.shape[1]))
    u[X.perm] = lv.coef
    vals = (probe @ u).reshape(h.size, p + 1, -1)
    a = 0.5 * (2 * p + 1) * np.einsum("q,eqa->ea", wq * top, vals)
    return np.sqrt(h / (2 * p + 1) * np.sum(a * a, axis=1))


def mark(indicators: np.ndarray, share: float = DORFLER) -> np.ndarray:
    """The fewest elements whose squared indicators sum to ``share`` (in (0, 1]) of the
    total (Dörfler marking); a boolean flag per element.

    Examples
    --------
    >>> mark(np.array([0.1, 3.0, 0.2, 1.0]), 0.8).tolist()
    [False, True, False, False]
    """
    if not 0.0 < share <= 1.0:
        raise ValueError(f"share must be in (0, 1], got {share!r}")
    e2 = np.asarray(indicators, dtype=float) ** 2
    order = np.argsort(-e2, kind="stable")
    cum = np.cumsum(e2[order])
    k = int(np.searchsorted(cum, share * cum[-1] * (1.0 - 1e-12))) + 1
    out = np.zeros(e2.size, dtype=bool)
    out[order[:k]] = True
    return out


class AdaptiveHermiteDG(Discretization):
    """Hermite functions of (v, V, xi) times DG in x, with element-wise mesh refinement
    (:class:`~fpe_harvester.fpe.protocol.Discretization`; ``size`` is the nominal elements per half,
    :attr:`~.mesh.XMesh.size`).

    Parameters
    ----------
    h : Harvester
        A single unit.
    base : XMesh
        The first mesh (its ``half_elements`` is the refinement's starting size).
    order : int
        DG polynomial order p.
    w : Whitening
        The Gaussian weight.
    share : float
        Dörfler share of the marking (:func:`mark`).
    """

    work_exponents: tuple[float, float] = (2.0, 3.0)
    #: Refine as soon as the first mesh check fails (:func:`~fpe_harvester.fpe.refine.refine`): a step
    #: adds only the marked elements, so an early step costs little.
    refine_early: bool = True
    #: Mesh checks at M - 4 but, from M = 10 on, not below M = 8 (the uniform refinement:
    #: not below 6). The marking
    #: follows the highest degree solved, and the mesh error of M = 6 on such a mesh says
    #: little about it: n = 6, a = 1, 10 elements per half adapted once more, at M = 6 the
    #: two meshes differ by 1.3e-4 (relative eta), at M = 8 by 2e-6.
    check_floor: int = 8
    mesh_check_degree: int = 6
    advice: str = ADVICE

    def __init__(self, h: Harvester, base: XMesh, order: int, w: Whitening, share: float = DORFLER) -> None:
        self.h, self.base, self.order, self.w, self.share = h, base, order, w, share
        self._meshes: dict[int, XMesh] = {}
        self._top: dict[int, Level] = {}
        #: Sizes whose mesh bisects every element (the Hermite degree outgrew the coarser one).
        self._uniform: set[int] = set()

    @property
    def algebraic(self) -> bool:
        return self.h.n < 2.0

    def mesh(self, size: int) -> XMesh | None:
        """The mesh of nominal ``size``: the node map for sizes up to the first, else the
        mesh of ``size // 2`` with its marked elements bisected; None while no level on
        that coarser mesh exists to mark it."""
        if size in self._meshes:
            return self._meshes[size]
        nh = self.base.half_elements
        if size <= nh:
            mesh = self.base.with_elements(size)
        else:
            parent = size // 2
            if size in self._uniform:
                coarse = self.mesh(parent)
                mesh = coarse.refined(np.ones(len(coarse.half_nodes()) - 1, dtype=bool))
            elif size % 2 or parent not in self._top:
                return None
            else:
                mesh = self.mesh(parent).refined(mark(element_indicators(self._top[parent]), self.share))
        self._meshes[size] = mesh
        return mesh

    def _half(self, size: int) -> int:
        """Elements per half of mesh ``size`` (twice those of ``size // 2`` if not built yet:
        the uniform refinement, an upper bound)."""
        mesh = self.mesh(size)
        return len(mesh.half_nodes()) - 1 if mesh is not None else size + self.base.layers

    def solve(self, M: int, size: int, lower: Any = None) -> Level:
        mesh = self.mesh(size)
        if mesh is None:
            # no level on the coarser mesh yet: solve one there to mark this one
            self.solve(min(M, self.mesh_check_degree), size // 2)
            mesh = self.mesh(size)
        lv = solve_level(self.h, M, mesh, self.order, self.w)
        if size not in self._top or M >= self._top[size].M:
            self._top[size] = lv
        return lv

    def unknowns(self, M: int, size: int) -> int:
        """Unknowns of the whole mesh (twice those of the half mesh that is solved)."""
        return 2 * self._half(size) * block_size(M, self.order)

    def gigabytes(self, M: int, size: int) -> float:
        return level_gigabytes(M, self._half(size), self.order)

    def max_degree(self, size: int) -> int:
        """What the uniform mesh with this mesh's longest elements carries: the node map's
        elements per half, doubled for every step that bisected all elements. Marked
        bisections do not count: an adapted mesh carries the degree of its longest elements,
        not of its element count (docs/methods.md, Fokker-Planck design notes)."""
        n = min(size, self.base.half_elements) + self.base.layers
        s = self.base.half_elements
        while s < size:
            s *= 2
            if s in self._uniform:
                n *= 2
        return int(DEGREES_PER_ELEMENT * n)

    def outgrown(self, size: int) -> None:
        """The Hermite degree needs more than mesh ``size`` carries: the next mesh bisects
        every element (called by the refinement before it asks for ``2 * size``)."""
        if 2 * size not in self._meshes:
            self._uniform.add(2 * size)

    def work(self, M: int, size: int) -> tuple[float, float]:
        return float(self._half(size)), float(block_size(M, self.order))

    def describe(self, size: int) -> str:
        mesh = self.mesh(size)
        if mesh is None or mesh.generation == 0:
            return f"{2 * self._half(size)} elements"
        return f"{mesh.elements} elements, adapted {mesh.generation}x"

    def summary(self) -> dict[str, Any]:
        """The meshes built so far: nominal size, elements per half, generation."""
        return {str(k): {"half_elements": len(m.half_nodes()) - 1, "generation": m.generation}
                for k, m in sorted(self._meshes.items())}
