"""The 1-D mesh in x: symmetric, a node at x = 0, domain sized from the potential.

The domain :math:`[-L, L]` is chosen so that the potential at its edge is ``domain``
effective temperatures above the bottom,

.. math::

    U(L) = a L^n = \\Theta\\,T_{eff}, \\qquad T_{eff} = \\kappa\\langle x^2\\rangle,

with :math:`\\kappa, \\langle x^2\\rangle` from the equivalent harmonic unit (for n = 2,
:math:`T_{eff} = 2a\\langle x^2\\rangle` and the density at L is :math:`e^{-\\Theta}` of its peak).
Nodes :math:`x_i = L\\,g(i/N_h)` on each half with :math:`g(t) = t^\\beta`: :math:`\\beta > 1`
grades elements toward the kink at 0 (force not smooth there for n < 2; the *algebraic*
mesh), and a second, wall-side refinement for steep potentials clusters nodes near the edge.

The *geometric* mesh for 1 < n < 2 keeps :math:`\\beta = 1` and splits the element
:math:`[0, x_1]` next to 0 into ``layers`` elements whose nodes form a geometric sequence,

.. math::

    0,\\; x_1\\sigma^{N_\\ell},\\; x_1\\sigma^{N_\\ell - 1},\\; \\dots,\\; x_1\\sigma,\\; x_1,
    \\qquad \\sigma \\approx 0.15,

so that the element touching 0, where the force :math:`\\propto |x|^{n-1}` is not smooth, is
:math:`\\sigma^{N_\\ell}` times shorter than the bulk elements and the error it carries falls
geometrically with :math:`N_\\ell` (Babuska and Guo's hp grading toward a point singularity).

An *adapted* mesh (:meth:`XMesh.refined`) bisects chosen elements of the half mesh (and so
their mirror images): the inserted nodes are kept in ``extra``, on top of the node map.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from skfem import MeshLine

from ....errors import check_int, check_real

__all__ = ["XMesh"]


@dataclass(frozen=True)
class XMesh:
    """Symmetric graded mesh on :math:`[-L, L]` with a node at 0.

    Nodes equidistribute the monitor :math:`s(x) = x/\\ell + w\\,\\Theta (x/L)^n` (length
    scale :math:`\\ell` of the bulk, plus ``w`` elements per unit of :math:`U/T_{eff}` so that
    steep walls get short elements): :math:`s(x_i) = s(L)\\,(i/N_h)^\\beta`, where
    :math:`\\beta > 1` grades toward the kink at 0.

    Parameters
    ----------
    L : float
        Half-width of the domain, > 0.
    half_elements : int
        Elements on each half, >= 1 (total ``2 * half_elements``).
    n : float
        Potential exponent, >= 1 (shape of the wall term).
    scale : float
        Bulk length scale :math:`\\ell > 0` (e.g. :math:`\\sqrt{\\langle x^2\\rangle}`).
    domain : float
        Domain factor :math:`\\Theta = U(L)/T_{eff} > 0`.
    wall : float
        Weight ``w >= 0`` of the wall term (0: uniform in x apart from the grading).
    grading : float
        :math:`\\beta` in [1, 6].
    layers : int
        Geometric layers :math:`N_\\ell \\ge 0` splitting the first element of each half
        (0: none).
    ratio : float
        Ratio :math:`\\sigma` of successive layers, in (0, 1).
    extra : tuple of float
        Nodes in (0, L) inserted on top of the node map by :meth:`refined` (default none).
    generation : int
        How many times :meth:`refined` made this mesh from the node map (0: not adapted).

    Examples
    --------
    >>> m = XMesh(2.0, 4, n=2.0, scale=1.0, domain=1.0, wall=0.0)
    >>> m.nodes().round(2).tolist()
    [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]
    """

    L: float
    half_elements: int
    n: float = 2.0
    scale: float = 1.0
    domain: float = 30.0
    wall: float = 0.25
    grading: float = 1.0
    layers: int = 0
    ratio: float = 0.15
    extra: tuple[float, ...] = ()
    generation: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "L", check_real("L", self.L, low=0.0, low_open=True))
        object.__setattr__(self, "half_elements", check_int("half_elements", self.half_elements, low=1))
        object.__setattr__(self, "n", check_real("n", self.n, low=1.0))
        object.__setattr__(self, "scale", check_real("scale", self.scale, low=0.0, low_open=True))
        object.__setattr__(self, "domain", check_real("domain", self.domain, low=0.0, low_open=True))
        object.__setattr__(self, "wall", check_real("wall", self.wall, low=0.0))
        object.__setattr__(self, "grading", check_real("grading", self.grading, low=1.0, high=6.0))
        object.__setattr__(self, "layers", check_int("layers", self.layers, low=0, high=60))
        object.__setattr__(self, "ratio", check_real("ratio", self.ratio, low=0.0, high=1.0, low_open=True,
                                                     high_open=True))
        extra = tuple(sorted(float(x) for x in self.extra))
        if extra and not (0.0 < extra[0] and extra[-1] < self.L):
            raise ValueError(f"extra nodes must lie in (0, L = {self.L!r}), got {extra[0]!r} ... {extra[-1]!r}")
        object.__setattr__(self, "extra", extra)
        object.__setattr__(self, "generation", check_int("generation", self.generation, low=0))

    def nodes(self) -> np.ndarray:
        """Sorted node coordinates, including -L, 0 and L."""
        half = self.half_nodes()
        return np.concatenate([-half[:0:-1], half])

    def half_nodes(self) -> np.ndarray:
        """The nodes in :math:`[0, L]` (the mesh is their mirror image and themselves)."""
        xf = np.linspace(0.0, self.L, 4001)
        sf = xf / self.scale + self.wall * self.domain * (xf / self.L) ** self.n
        t = np.linspace(0.0, 1.0, self.half_elements + 1) ** self.grading
        half = np.interp(t * sf[-1], sf, xf)
        half[0], half[-1] = 0.0, self.L
        if self.layers:
            inner = half[1] * self.ratio ** np.arange(self.layers, 0, -1)
            half = np.concatenate([[0.0], inner, half[1:]])
        if self.extra:
            half = np.union1d(half, self.extra)
        return half

    def skfem(self) -> MeshLine:
        """The scikit-fem mesh."""
        return MeshLine(self.nodes())

    @property
    def elements(self) -> int:
        """Total number of elements (the layers and inserted nodes included)."""
        return 2 * (self.half_elements + self.layers + len(self.extra))

    @property
    def geometric(self) -> bool:
        """True if the element next to 0 is split into geometric layers."""
        return self.layers > 0

    def with_elements(self, half_elements: int) -> XMesh:
        """The same node map with another number of (bulk) elements per half; the layers stay,
        inserted nodes (``extra``) go."""
        return dataclasses.replace(self, half_elements=half_elements, extra=(), generation=0)

    @property
    def size(self) -> int:
        """Nominal elements per half, :math:`N_h 2^g` after g adaptive refinements (the
        refinement's mesh knob: one step doubles it, whether all elements were bisected or
        only the marked ones)."""
        return self.half_elements * 2**self.generation

    def refined(self, marked: np.ndarray) -> XMesh:
        """This mesh with the marked elements of the half mesh bisected (the mirror images
        with them: the mesh stays symmetric).

        Parameters
        ----------
        marked : ndarray of bool
            One flag per element of :meth:`half_nodes`, left to right.

        Examples
        --------
        >>> m = XMesh(2.0, 2, n=2.0, scale=1.0, domain=1.0, wall=0.0)
        >>> r = m.refined(np.array([False, True]))
        >>> r.half_nodes().tolist(), r.size
        ([0.0, 1.0, 1.5, 2.0], 4)
        """
        half = self.half_nodes()
        marked = np.asarray(marked, dtype=bool)
        if marked.shape != (half.size - 1,):
            raise ValueError(f"marked needs one flag per half element ({half.size - 1}), got shape {marked.shape}")
        mid = 0.5 * (half[:-1] + half[1:])[marked]
        return dataclasses.replace(self, extra=self.extra + tuple(mid.tolist()), generation=self.generation + 1)
