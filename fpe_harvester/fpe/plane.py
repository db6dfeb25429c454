"""The (x, v) plane of the kink solver: 1-D DG spaces and the tensor mesh graded toward the trap.

The kink solver (:mod:`.schemes.xv.kink`) discretizes the position x and the velocity v by
discontinuous Galerkin on a tensor mesh of rectangles. Every 2-D matrix it needs is a
Kronecker product of two 1-D matrices (x outer, v inner), so this module only builds 1-D
DG spaces (:class:`DGLine`) and the node sets of the two axes (:class:`PlaneMesh`).

The 1-D basis is nodal: Lagrange polynomials of degree p on the Gauss--Lobatto points of
each element, so the trace of a function at an element end is one coefficient (faces
couple only end values) and every end value is a single unknown. Integrals use
Gauss--Legendre quadrature with p + 4 points (exact for the polynomial weights 1, v, v^2
used here).

The mesh covers the half plane :math:`x \\ge 0` (the stationary density is symmetric under
:math:`(x, v, V, \\xi) \\to -(x, v, V, \\xi)`), :math:`0 \\le x \\le L_x`,
:math:`|v| \\le L_v`, with nodes on x = 0 and v = 0 (the force :math:`-a\\,\\mathrm{sign}\\,x`
and the direction of transport in x are constant on every element). Near the trap at the
origin the density concentrates like a power of the energy :math:`E = v^2/2 + a|x|`, so
the nodes are graded geometrically toward the origin with the trap's parabolic scaling:
layer k ends at :math:`x_k = x_c q^{2k}`, :math:`v_k = v_c q^k`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.polynomial import legendre as npleg

from ..errors import check_int, check_real

__all__ = ["DGLine", "PlaneMesh", "lobatto_points"]


@functools.cache
def lobatto_points(p: int) -> np.ndarray:
    """The p + 1 Gauss--Lobatto points of [-1, 1] (ends included), ascending, p >= 1.

    >>> lobatto_points(2).tolist()
    [-1.0, 0.0, 1.0]
    """
    coef = np.zeros(p + 1)
    coef[-1] = 1.0
    inner = np.sort(npleg.legroots(npleg.legder(coef))) if p > 1 else np.zeros(0)
    return np.concatenate([[-1.0], inner, [1.0]]) + 0.0  # no -0.0


@functools.cache
def _reference(p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Quadrature points and weights on [-1, 1] and the nodal basis and its derivative there."""
    qx, qw = npleg.leggauss(p + 4)
    vinv = np.linalg.inv(npleg.legvander(lobatto_points(p), p))
    basis = npleg.legvander(qx, p) @ vinv
    dleg = np.stack([npleg.legval(qx, npleg.legder(np.eye(p + 1)[j])) for j in range(p + 1)], axis=1)
    return qx, qw, basis, dleg @ vinv


@dataclass(frozen=True)
class DGLine:
    """Discontinuous piecewise polynomials of degree p on a 1-D mesh, nodal on Lobatto points.

    Unknowns are ordered element by element (element e owns ``e*(p+1) ... e*(p+1)+p``),
    the first and last of each element being its values at the left and right end.

    Parameters
    ----------
    nodes : ndarray
        Strictly increasing mesh nodes (at least two).
    p : int
        Polynomial degree, 1..8.

    Examples
    --------
    >>> line = DGLine(np.array([0.0, 1.0, 3.0]), 2)
    >>> round(float(line.integral() @ np.ones(line.size)), 12)
    3.0
    """

    nodes: np.ndarray
    p: int

    def __post_init__(self) -> None:
        nodes = np.asarray(self.nodes, dtype=float)
        if nodes.ndim != 1 or nodes.size < 2 or not np.all(np.diff(nodes) > 0.0):
            raise ValueError(f"nodes must be a strictly increasing 1-D array of >= 2 points, got {nodes!r}")
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "p", check_int("p", self.p, low=1, high=8))

    @property
    def elements(self) -> int:
        return self.nodes.size - 1

    @property
    def size(self) -> int:
        """Number of unknowns, ``elements * (p + 1)``."""
        return self.elements * (self.p + 1)

    def points(self) -> np.ndarray:
        """Coordinates of the unknowns (the Lobatto points of every element)."""
        lo, h = self.nodes[:-1], np.diff(self.nodes)
        return (lo[:, None] + 0.5 * h[:, None] * (lobatto_points(self.p) + 1.0)).ravel()

    def _quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        qx, qw, _, _ = _reference(self.p)
        lo, h = self.nodes[:-1], np.diff(self.nodes)
        return lo[:, None] + 0.5 * h[:, None] * (qx + 1.0), 0.5 * h[:, None] * qw

    def _blocks(self, test: np.ndarray, trial: np.ndarray, weight: np.ndarray) -> sp.csr_matrix:
        blocks = np.einsum("qi,eq,qj->eij", test, weight, trial)
        return sp.block_diag(list(blocks), format="csr")

    def mass(self, f: np.ndarray | None = None, power: int = 0) -> sp.csr_matrix:
        """:math:`\\int s^{power} f\\,\\psi_i\\phi_j\\,ds` (s the coordinate; ``f`` per element, constant)."""
        _, _, basis, _ = _reference(self.p)
        s, w = self._quadrature()
        weight = w * s**power * (1.0 if f is None else np.asarray(f, dtype=float)[:, None])
        return self._blocks(basis, basis, weight)

    def power_mass(self, q: float) -> sp.csr_matrix:
        """:math:`\\int s^q\\,\\psi_i\\phi_j\\,ds` for a real :math:`q > -1` on a line with
        :math:`s \\ge 0` (:meth:`_from_left` over whole elements)."""
        return sp.block_diag(list(self._from_left(q, self.nodes[1:])), format="csr")

    def _from_left(self, q: float, b: np.ndarray) -> np.ndarray:
        """:math:`\\int_{s_e}^{b_e} s^q\\,\\psi_i\\phi_j\\,ds` from the left end :math:`s_e`
        of every element e to :math:`b_e` (``b``: shape ``(..., E)``, inside the elements);
        shape ``(..., E, p + 1, p + 1)``. Gauss--Jacobi of the weight :math:`s^q` where
        :math:`s_e = 0` (exact), Gauss--Legendre with 2p + 8 points elsewhere (:math:`s^q`
        smooth there)."""
        from .assemble import jacobi_rule

        lo, hi = self.nodes[:-1], self.nodes[1:]
        if lo[0] < 0.0 or not q > -1.0:
            raise ValueError(f"s^q needs s >= 0 and q > -1, got s from {lo[0]!r}, q = {q!r}")
        b = np.asarray(b, dtype=float)
        n = 2 * self.p + 8
        tj, wj = jacobi_rule(n, q)
        tg, wg = npleg.leggauss(n)
        at0 = (lo <= 0.0)[:, None]
        span = (b - lo)[..., None]
        pts = np.where(at0, b[..., None] * tj, lo[:, None] + 0.5 * span * (tg + 1.0))
        w = np.where(at0, np.maximum(b, 0.0)[..., None] ** (q + 1.0) * wj,
                     0.5 * span * wg * np.maximum(pts, 0.0) ** q)
        vinv = np.linalg.inv(npleg.legvander(lobatto_points(self.p), self.p))
        basis = npleg.legvander(2.0 * (pts - lo[:, None]) / (hi - lo)[:, None] - 1.0, self.p) @ vinv
        return np.einsum("...qi,...q,...qj->...ij", basis, w, basis)

    def derivative(self, power: int = 0) -> sp.csr_matrix:
        """:math:`\\int s^{power}\\,\\psi_i'\\phi_j\\,ds` (derivative on the test function)."""
        _, qw, basis, dbasis = _reference(self.p)
        s, _ = self._quadrature()
        return self._blocks(dbasis, basis, s**power * qw[None, :])

    def signed_parts(self, s0: np.ndarray, kappa: float, A: float = 0.0, q: float = 0.0
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Element mass matrices weighted by the positive and the negative part of the
        speed :math:`u(s) = s_0 + \\kappa s - A s^q`:
        :math:`\\int_e u^\\pm\\psi_i\\phi_j\\,ds`, each element split at the root of u: exact
        for A = 0 (u linear); for A > 0 (with ``kappa = 0`` and :math:`s \\ge 0`: u falls
        monotonically, one root) by :meth:`_from_left`, exact on the element at 0.

        Returns two arrays of shape ``(len(s0), elements, p + 1, p + 1)``.
        """
        s0 = np.atleast_1d(np.asarray(s0, dtype=float))
        qx, qw, _, _ = _reference(self.p)
        vinv = np.linalg.inv(npleg.legvander(lobatto_points(self.p), self.p))
        lo, hi = self.nodes[:-1], self.nodes[1:]
        if A:
            if kappa != 0.0 or q <= 0.0 or lo[0] < 0.0:
                raise ValueError(f"a power-law speed needs kappa = 0, q > 0 and s >= 0, got {kappa!r}, {q!r}")
            # u falls monotonically: positive left of its root, negative right of it
            root = np.where(s0 > 0.0, (np.maximum(s0, 0.0) / A) ** (1.0 / q), 0.0)
            cut = np.clip(root[:, None], lo, hi)                     # (n, E)
            left = s0[:, None, None, None] * self._from_left(0.0, cut) - A * self._from_left(q, cut)
            whole = s0[:, None, None, None] * self._from_left(0.0, hi) - A * self._from_left(q, hi)
            return left, whole - left
        if kappa == 0.0:
            root = np.where(s0 > 0.0, -np.inf, np.inf)[:, None] * np.ones(lo.size)
        else:
            root = (-s0 / kappa)[:, None] * np.ones(lo.size)
        cut = np.clip(root, lo, hi)                                  # (n, E)
        out = []
        for a, b in ((lo + 0.0 * cut, cut), (cut, hi + 0.0 * cut)):
            pts = a[..., None] + 0.5 * (b - a)[..., None] * (qx + 1.0)  # (n, E, q)
            w = 0.5 * (b - a)[..., None] * qw
            ref = 2.0 * (pts - lo[None, :, None]) / (hi - lo)[None, :, None] - 1.0
            basis = npleg.legvander(ref, self.p) @ vinv               # (n, E, q, p+1)
            u = s0[:, None, None] + kappa * pts
            out.append((basis, w, u))
        pos = np.zeros((s0.size, lo.size, self.p + 1, self.p + 1))
        neg = np.zeros_like(pos)
        for basis, w, u in out:
            pos += np.einsum("neqi,neq,neqj->neij", basis, w * np.maximum(u, 0.0), basis)
            neg += np.einsum("neqi,neq,neqj->neij", basis, w * np.minimum(u, 0.0), basis)
        return pos, neg

    def integral(self, power: int = 0) -> np.ndarray:
        """:math:`\\int s^{power}\\phi_j\\,ds` for every unknown."""
        _, _, basis, _ = _reference(self.p)
        s, w = self._quadrature()
        return np.einsum("eq,qj->ej", w * s**power, basis).ravel()

    def left_of(self, node: int) -> np.ndarray:
        """Unit vector of the value at mesh node ``node`` from the element on its left
        (zero vector at the first node)."""
        e = np.zeros(self.size)
        if node > 0:
            e[node * (self.p + 1) - 1] = 1.0
        return e

    def right_of(self, node: int) -> np.ndarray:
        """Unit vector of the value at mesh node ``node`` from the element on its right
        (zero vector at the last node)."""
        e = np.zeros(self.size)
        if node < self.elements:
            e[node * (self.p + 1)] = 1.0
        return e

    def evaluate(self, coef: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Values at points ``s`` (inside the mesh) of the functions with coefficients
        ``coef`` (rows: unknowns, any trailing shape)."""
        s = np.asarray(s, dtype=float)
        e = np.clip(np.searchsorted(self.nodes, s, side="right") - 1, 0, self.elements - 1)
        lo, h = self.nodes[e], self.nodes[e + 1] - self.nodes[e]
        r = np.clip(2.0 * (s - lo) / h - 1.0, -1.0, 1.0)
        vinv = np.linalg.inv(npleg.legvander(lobatto_points(self.p), self.p))
        basis = npleg.legvander(r, self.p) @ vinv
        idx = e[:, None] * (self.p + 1) + np.arange(self.p + 1)
        return np.einsum("sj,sj...->s...", basis, coef[idx])


@dataclass(frozen=True)
class PlaneMesh:
    """Tensor mesh of the half plane :math:`0 \\le x \\le L_x`, :math:`|v| \\le L_v`.

    Nodes on each axis: the origin, ``layers`` geometric layers toward it
    (:math:`x_k = x_c q^{2k}`, :math:`v_k = v_c q^k`, k = 0 .. layers - 1, with
    :math:`x_c = E_c/a` and :math:`v_c = \\sqrt{2E_c}`: the box of the energy :math:`E_c`),
    then ``bulk_x`` and ``bulk_v`` elements out to the edge, spaced like
    :math:`t^{g}` (t uniform, g = ``grading``). The v nodes are symmetric about 0.

    Parameters
    ----------
    Lx, Lv : float
        Half-widths of the domain, > 0.
    Ec : float
        Energy of the core box, > 0 (:math:`x_c < L_x`, :math:`v_c < L_v`).
    a : float
        Strength of the kink force (sets :math:`x_c = E_c/a`).
    layers : int
        Geometric layers toward the origin, >= 1 (1: one core element per axis).
    ratio : float
        Layer ratio q in v (:math:`q^2` in x), in (0, 1).
    bulk_x, bulk_v : int
        Elements outside the core on each axis (v: on each side of 0), >= 1.
    grading : float
        Exponent g >= 1 of the bulk spacing (short elements next to the core).
    subdivisions : int
        Every rectangle of the mesh so defined is cut into s x s equal ones (the
        refinement's mesh knob), >= 1.

    Examples
    --------
    >>> m = PlaneMesh(Lx=4.0, Lv=2.0, Ec=0.5, a=1.0, layers=2, ratio=0.5, bulk_x=2, bulk_v=2)
    >>> m.x_nodes().round(3).tolist()
    [0.0, 0.125, 0.5, 1.375, 4.0]
    >>> m.elements
    32
    """

    Lx: float
    Lv: float
    Ec: float
    a: float
    layers: int = 3
    ratio: float = 0.3
    bulk_x: int = 6
    bulk_v: int = 5
    grading: float = 2.0
    subdivisions: int = 1

    def __post_init__(self) -> None:
        for name in ("Lx", "Lv", "Ec", "a"):
            object.__setattr__(self, name, check_real(name, getattr(self, name), low=0.0, low_open=True))
        object.__setattr__(self, "layers", check_int("layers", self.layers, low=1, high=40))
        object.__setattr__(self, "ratio", check_real("ratio", self.ratio, low=0.0, high=1.0,
                                                     low_open=True, high_open=True))
        object.__setattr__(self, "bulk_x", check_int("bulk_x", self.bulk_x, low=1))
        object.__setattr__(self, "bulk_v", check_int("bulk_v", self.bulk_v, low=1))
        object.__setattr__(self, "grading", check_real("grading", self.grading, low=1.0, high=6.0))
        if self.Ec / self.a >= self.Lx or math.sqrt(2.0 * self.Ec) >= self.Lv:
            raise ValueError(f"the core box (x_c = {self.Ec / self.a:.3g}, v_c = {math.sqrt(2 * self.Ec):.3g}) "
                             f"must lie inside the domain (Lx = {self.Lx:.3g}, Lv = {self.Lv:.3g})")

    def _axis(self, core: float, power: float, edge: float, bulk: int) -> np.ndarray:
        k = np.arange(self.layers - 1, -1, -1)
        inner = core * self.ratio ** (power * k)
        outer = core + (edge - core) * np.linspace(0.0, 1.0, bulk + 1)[1:] ** self.grading
        nodes = np.concatenate([[0.0], inner, outer])
        s = self.subdivisions
        cut = nodes[:-1, None] + np.diff(nodes)[:, None] * (np.arange(s) / s)
        return np.concatenate([cut.ravel(), nodes[-1:]])

    def x_nodes(self) -> np.ndarray:
        """Nodes of the x axis, from 0 to Lx."""
        return self._axis(self.Ec / self.a, 2.0, self.Lx, self.bulk_x)

    def v_nodes(self) -> np.ndarray:
        """Nodes of the v axis, from -Lv to Lv, symmetric, with a node at 0."""
        half = self._axis(math.sqrt(2.0 * self.Ec), 1.0, self.Lv, self.bulk_v)
        return np.concatenate([-half[:0:-1], half])

    @property
    def elements(self) -> int:
        """Number of rectangles of the half plane."""
        return (self.layers + self.bulk_x) * 2 * (self.layers + self.bulk_v) * self.subdivisions**2

    def subdivided(self, s: int) -> PlaneMesh:
        """The mesh with every rectangle cut into s x s equal ones (s = 1: itself)."""
        return dataclasses.replace(self, subdivisions=check_int("s", s, low=1, high=64))
