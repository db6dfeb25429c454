"""DG assembly in x with scikit-fem: scalar matrices and the upwind-flux operator.

The truncated hierarchy :math:`\\partial_x(F c) = (K_0 + u(x) K_1 + x K_2) c` is a first-order
hyperbolic system with a symmetric, singular flux matrix F. Its discontinuous-Galerkin
weak form on every element K, with the upwind (characteristic) numerical flux
:math:`\\hat F = F^+ c^- + F^- c^+` (:math:`F^\\pm = R\\Lambda^\\pm R^T`, the positive and
negative parts of F; :math:`c^\\mp` the traces left and right of a node), reads

.. math::

    \\sum_K \\Big( [\\psi \\hat F]_{\\partial K} - \\int_K F c\\,\\psi' \\,dx
    - \\int_K \\psi (K_0 + u K_1 + x K_2) c\\,dx \\Big) = 0,

with zero inflow at :math:`\\pm L`. Every term is a Kronecker product of an x-matrix
(assembled here by scikit-fem) and an :math:`\\alpha`-matrix (from :mod:`.hermite`):

.. math::

    A = X_+ \\otimes F^+ + X_- \\otimes F^- - D \\otimes F - M \\otimes K_0
        - M_u \\otimes K_1 - M_x \\otimes K_2 .

Unknowns are ordered element by element, x outer and :math:`\\alpha` inner.

For :math:`U = a|x|^n` with non-integer n the force :math:`u \\propto |x|^{n-1}\\mathrm{sign}\\,x`
is not a polynomial on an element touching x = 0, and Gauss--Legendre quadrature converges
slowly there. With ``singular = n - 1`` the term :math:`M_u` on those elements uses the
Gauss--Jacobi rule of the weight :math:`|x|^{n-1}` (:func:`jacobi_rule`), exact for
:math:`|x|^{n-1}` times a polynomial.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from skfem import (
    Basis,
    BilinearForm,
    ElementDG,
    ElementLineP1,
    ElementLineP2,
    ElementLinePp,
    FacetBasis,
    InteriorFacetBasis,
    LinearForm,
    asm,
)

__all__ = ["XMatrices", "assemble_x", "dg_element", "jacobi_rule", "split_flux", "upwind_parts", "dg_operator"]


@dataclass(frozen=True)
class XMatrices:
    """Scalar DG matrices of one mesh and polynomial order (rows: test, columns: trial).

    Attributes
    ----------
    mass, mass_u, mass_x, deriv : sparse
        :math:`\\int\\psi_i\\phi_j`, :math:`\\int u\\,\\psi_i\\phi_j`, :math:`\\int x\\,\\psi_i\\phi_j`,
        :math:`\\int\\psi_i'\\phi_j`.
    mass_du : sparse
        :math:`\\int u'\\,\\psi_i\\phi_j` (a weight centred on a mean that follows the force,
        :func:`dg_operator`'s ``K3``).
    xplus, xminus : sparse
        Face matrices multiplying :math:`F^+` and :math:`F^-` in the upwind flux.
    xreflect : sparse or None
        On a half mesh :math:`[0, L]` with a mirror at x = 0 (``reflect=True``), the point
        matrix :math:`-\\psi_i(0)\\phi_j(0)` multiplying :math:`F^+ S` (inflow at 0 from the
        mirror image, see :func:`dg_operator`); None on a full mesh.
    integral, x2, x1 : ndarray
        :math:`\\int\\phi_j`, :math:`\\int x^2\\phi_j`, :math:`\\int x\\phi_j`.
    u1, u2, xu : ndarray
        :math:`\\int u\\,\\phi_j`, :math:`\\int u^2\\phi_j`, :math:`\\int x u\\,\\phi_j` (moments of
        a weight whose mean follows the force).
    basis : skfem.Basis
        The DG basis (for evaluating fields on a grid).
    order : int
        Polynomial order p.
    perm : ndarray
        Element-major ordering: ``perm[i]`` is the scikit-fem dof of the i-th unknown.
    """

    mass: sp.csr_matrix
    mass_u: sp.csr_matrix
    mass_x: sp.csr_matrix
    deriv: sp.csr_matrix
    xplus: sp.csr_matrix
    xminus: sp.csr_matrix
    integral: np.ndarray
    x2: np.ndarray
    x1: np.ndarray
    basis: Basis
    order: int
    perm: np.ndarray
    xreflect: sp.csr_matrix | None = None
    mass_du: sp.csr_matrix | None = None
    u1: np.ndarray | None = None
    u2: np.ndarray | None = None
    xu: np.ndarray | None = None

    @property
    def copies(self) -> float:
        """How often the mesh's integrals count: 2 on a half mesh with a mirror (the image
        on x < 0 adds the same integral of an even integrand), else 1."""
        return 1.0 if self.xreflect is None else 2.0


def dg_element(order: int) -> ElementDG:
    """The discontinuous Lagrange element of degree ``order`` on a line (a fresh one:
    scikit-fem's ElementLinePp caches reference values by array shape only)."""
    if order == 1:
        return ElementDG(ElementLineP1())
    if order == 2:
        return ElementDG(ElementLineP2())
    return ElementDG(ElementLinePp(order))


def _element_major(basis: Basis) -> np.ndarray:
    """Permutation putting the dofs of each element together, elements left to right."""
    order = np.argsort(basis.mesh.p[0, basis.mesh.t[0]])
    return basis.element_dofs[:, order].T.ravel()


def jacobi_rule(points: int, exponent: float, h: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Gauss--Jacobi rule of the weight :math:`x^s` on :math:`[0, h]`.

    .. math::

        \\int_0^h x^s f(x)\\,dx = \\sum_i w_i f(x_i)

    exactly for polynomials f of degree up to ``2 * points - 1``.

    Parameters
    ----------
    points : int
        Number of nodes, >= 1.
    exponent : float
        :math:`s > -1`.
    h : float
        Length of the interval, > 0.

    Returns
    -------
    x, w : ndarray
        Nodes in (0, h) and weights.

    Examples
    --------
    >>> x, w = jacobi_rule(2, 0.5)
    >>> round(float(w @ x**2), 12) == round(1 / 3.5, 12)
    True
    """
    from scipy.special import roots_jacobi

    t, w = roots_jacobi(points, 0.0, exponent)  # weight (1 + t)^s on [-1, 1]
    scale = (0.5 * h) ** (exponent + 1.0)
    return 0.5 * h * (1.0 + t), w * scale


def _singular_mass(mesh, order: int, u: Callable[[np.ndarray], np.ndarray], singular: float) -> sp.spmatrix:
    """:math:`\\int u\\,\\psi_i\\phi_j` on the elements with a node at x = 0 by Gauss--Jacobi
    with the weight :math:`|x|^s`: nodes and weights of :func:`jacobi_rule` on the reference
    interval, the weights divided by :math:`t^s`, so that scikit-fem's sum of
    :math:`w_i |J| u(x_i)` is the rule for :math:`|x|^s \\cdot (u/|x|^s)`."""
    t, w = jacobi_rule(order + 4, singular)
    p, cells = mesh.p[0], mesh.t
    out = None
    for end in (0, 1):  # the reference point t = 0 (left node) or t = 1 (right node) sits at x = 0
        elems = np.flatnonzero(np.abs(p[cells[end]]) <= 1e-14 * np.abs(p).max())
        if elems.size == 0:
            continue
        pts = t if end == 0 else 1.0 - t
        basis = Basis(mesh, dg_element(order), quadrature=(pts[None, :], w / t**singular), elements=elems)
        part = asm(BilinearForm(lambda a, b, w_: u(w_.x[0]) * a * b), basis)
        out = part if out is None else out + part
    return out


def assemble_x(mesh_nodes: np.ndarray, order: int, u: Callable[[np.ndarray], np.ndarray],
               intorder: int | None = None, reflect: bool = False, singular: float | None = None,
               du: Callable[[np.ndarray], np.ndarray] | None = None) -> XMatrices:
    """Assemble the scalar DG matrices on a 1-D mesh.

    Parameters
    ----------
    mesh_nodes : ndarray
        Sorted node coordinates (a node at every point where ``u`` is not smooth).
    order : int
        Polynomial order p in 1..8.
    u : callable
        The nonlinear force per unit mass :math:`u(x) = -U'(x)/m`.
    intorder : int, optional
        Quadrature order (default ``2 p + 6``, enough for smooth u on graded elements).
    reflect : bool
        The nodes cover the half :math:`[0, L]` of a mirror-symmetric problem: the left
        boundary x = 0 gets inflow from the mirror image (``xreflect``) instead of none.
    singular : float, optional
        Exponent :math:`s > -1` of a factor :math:`|x|^s` of u at x = 0 (``n - 1`` for
        :math:`U = a|x|^n`): the elements touching 0 (0 must be a node) integrate
        :math:`M_u` by Gauss--Jacobi, exact when :math:`u/|x|^s` is a polynomial there.
    du : callable, optional
        Its derivative :math:`u'(x)`: also assemble ``mass_du``, ``u1``, ``u2`` and ``xu``.
    """
    from skfem import MeshLine

    mesh = MeshLine(np.asarray(mesh_nodes, dtype=float))
    e = dg_element(order)
    q = intorder or 2 * order + 6
    basis = Basis(mesh, e, intorder=q)
    perm = _element_major(basis)

    mass = asm(BilinearForm(lambda a, b, w: a * b), basis)
    if singular is None:
        mass_u = asm(BilinearForm(lambda a, b, w: u(w.x[0]) * a * b), basis)
    else:
        if not singular > -1.0:
            raise ValueError(f"singular must be an exponent > -1, got {singular!r}")
        at0 = np.abs(mesh.p[0, mesh.t]).min(axis=0) <= 1e-14 * np.abs(mesh.p).max()
        if not at0.any():
            raise ValueError("singular needs a node at x = 0")
        mass_u = _singular_mass(mesh, order, u, singular)
        if not at0.all():
            rest = Basis(mesh, dg_element(order), intorder=q, elements=np.flatnonzero(~at0))
            mass_u = mass_u + asm(BilinearForm(lambda a, b, w: u(w.x[0]) * a * b), rest)
    mass_x = asm(BilinearForm(lambda a, b, w: w.x[0] * a * b), basis)
    deriv = asm(BilinearForm(lambda a, b, w: a * b.grad[0]), basis)
    integral = asm(LinearForm(lambda b, w: b), basis)
    x2 = asm(LinearForm(lambda b, w: w.x[0] ** 2 * b), basis)
    x1 = asm(LinearForm(lambda b, w: w.x[0] * b), basis)
    curved = {}
    if du is not None:
        curved = {"u1": asm(LinearForm(lambda b, w: u(w.x[0]) * b), basis),
                  "u2": asm(LinearForm(lambda b, w: u(w.x[0]) ** 2 * b), basis),
                  "xu": asm(LinearForm(lambda b, w: w.x[0] * u(w.x[0]) * b), basis)}
        mass_du = asm(BilinearForm(lambda a, b, w: du(w.x[0]) * a * b), basis)

    # Interior nodes: side 0 is the element whose outward normal is n. The upwind flux in
    # direction n is (nF)^+ c_0 + (nF)^- c_1, added to side 0 and subtracted from side 1;
    # (nF)^+ = F^+ for n = +1 and -F^- for n = -1.
    # A fresh element per facet basis: ElementLinePp caches its reference values by array
    # shape only, so two bases evaluated at different single points must not share one.
    pos = BilinearForm(lambda a, b, w: (w.n[0] > 0) * a * b)
    neg = BilinearForm(lambda a, b, w: (w.n[0] < 0) * a * b)
    if mesh.t.shape[1] > 1:
        sides = [InteriorFacetBasis(mesh, dg_element(order), side=s) for s in (0, 1)]
        P = {(s, t): (asm(pos, sides[t], sides[s]), asm(neg, sides[t], sides[s]))
             for s in (0, 1) for t in (0, 1)}
        xplus = P[0, 0][0] - P[1, 0][0] - P[0, 1][1] + P[1, 1][1]
        xminus = P[0, 1][0] - P[1, 1][0] - P[0, 0][1] + P[1, 0][1]
    else:  # one element (the coarsest half mesh): no interior node
        xplus = xminus = sp.csr_matrix(mass.shape)
    # Boundary: outflow only, (nF)^+ c; inflow from outside the domain is zero, except at a
    # mirror (x = 0 of a half mesh), where it comes from the reflected trace.
    xreflect = None
    if reflect and abs(mesh_nodes[0]) > 1e-12 * abs(mesh_nodes[-1]):
        raise ValueError(f"reflect=True needs a half mesh starting at x = 0, got {mesh_nodes[0]!r}")
    for facet in mesh.boundary_facets():
        fb = FacetBasis(mesh, dg_element(order), facets=np.array([facet]))
        xplus = xplus + asm(pos, fb)
        xminus = xminus - asm(neg, fb)
        if reflect and mesh.p[0, facet] < 0.5 * mesh_nodes[-1]:
            xreflect = -asm(neg, fb)

    def p2(A: sp.spmatrix, clean: bool = False) -> sp.csr_matrix:
        A = sp.csr_matrix(A)
        if clean:
            # Face matrices are products of basis values at nodes, O(1) or exactly zero (the
            # bubbles vanish at the ends); drop the round-off (1e-16) of the latter, which
            # would double the rows of every element coupling.
            A.data[np.abs(A.data) < 1e-12 * max(np.abs(A.data).max(initial=0.0), 1.0)] = 0.0
        A.eliminate_zeros()
        return A[perm][:, perm].tocsr()

    return XMatrices(
        mass=p2(mass), mass_u=p2(mass_u), mass_x=p2(mass_x), deriv=p2(deriv), xplus=p2(xplus, True),
        xminus=p2(xminus, True),
        integral=integral[perm], x2=x2[perm], x1=x1[perm], basis=basis, order=order, perm=perm,
        xreflect=None if xreflect is None else p2(xreflect, True),
        mass_du=p2(mass_du) if du is not None else None, **{k: v[perm] for k, v in curved.items()},
    )


def split_flux(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positive and negative parts :math:`F^\\pm = R\\Lambda^\\pm R^T` of a symmetric matrix.

    F is decomposed into its irreducible diagonal blocks (for the Hermite flux matrix these
    are the :math:`\\alpha_0`-chains, Jacobi matrices that depend only on their length),
    and each distinct block is diagonalized once: O(M^2) small eigenproblems instead of
    one of size :math:`\\binom{M+3}{3}`.
    """
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(F, dtype=float)
    ncomp, label = connected_components(sp.csr_matrix(F != 0.0), directed=False)
    Fp, Fm = np.zeros_like(F), np.zeros_like(F)
    parts: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    for comp in range(ncomp):
        idx = np.flatnonzero(label == comp)
        block = F[np.ix_(idx, idx)]
        key = np.array(block.shape).tobytes() + block.tobytes()
        if key not in parts:
            lam, R = np.linalg.eigh(block)
            parts[key] = ((R * np.maximum(lam, 0.0)) @ R.T, (R * np.minimum(lam, 0.0)) @ R.T)
        Fp[np.ix_(idx, idx)], Fm[np.ix_(idx, idx)] = parts[key]
    return Fp, Fm


def upwind_parts(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`split_flux` with round-off entries (below 1e-14 of max |F|) set to zero: the
    :math:`F^\\pm` that :func:`dg_operator` multiplies by ``xplus`` and ``xminus``."""
    Fp, Fm = split_flux(F)
    tol = 1e-14 * max(1.0, np.abs(F).max())
    Fp[np.abs(Fp) < tol] = 0.0
    Fm[np.abs(Fm) < tol] = 0.0
    return Fp, Fm


def dg_operator(X: XMatrices, F: np.ndarray, K0: sp.spmatrix, K1: sp.spmatrix,
                K2: sp.spmatrix | None = None, parity: np.ndarray | None = None,
                upwind: tuple[np.ndarray, np.ndarray] | None = None,
                K3: tuple[float, sp.spmatrix] | None = None) -> sp.csr_matrix:
    """The global DG operator :math:`A` (see module docstring), x outer, alpha inner.

    ``K2`` (optional) multiplies x, from a weight centred on a conditional mean linear in x
    (:func:`fpe_harvester.fpe.schemes.x.discretize.hierarchy_matrices`): adds :math:`-M_x \\otimes K_2`.

    On a half mesh (``X.xreflect`` set) the solution is continued to x < 0 by the mirror
    symmetry :math:`c_\\alpha(-x) = (-1)^{|\\alpha|} c_\\alpha(x)` (``parity`` =
    :math:`(-1)^{|\\alpha|}`, S = diag(parity)): the upwind flux at 0 is
    :math:`F^+ c(0^-) + F^- c(0^+) = (F^+ S + F^-)\\,c(0^+)`, which adds
    :math:`X_{reflect} \\otimes F^+ S`.

    ``upwind`` is :func:`upwind_parts` of F if the caller has it already.

    ``K3 = (r, K)`` (optional) is a drift that a weight centred on a mean following the force
    adds in proportion to :math:`\\psi'(x) = r\\,u'(x) - 1`: :math:`-(r M_{u'} - M) \\otimes K`
    (needs ``X.mass_du``).
    """
    Fp, Fm = upwind_parts(F) if upwind is None else upwind
    A = (
        sp.kron(X.xplus, sp.csr_matrix(Fp))
        + sp.kron(X.xminus, sp.csr_matrix(Fm))
        - sp.kron(X.deriv, sp.csr_matrix(F))
        - sp.kron(X.mass, K0)
        - sp.kron(X.mass_u, K1)
    )
    if K2 is not None and K2.nnz:
        A = A - sp.kron(X.mass_x, K2)
    if K3 is not None and K3[1].nnz:
        if X.mass_du is None:
            raise ValueError("a weight whose mean follows the force needs X.mass_du (assemble_x(..., du=...))")
        A = A - sp.kron(K3[0] * X.mass_du - X.mass, K3[1])
    if X.xreflect is not None:
        if parity is None:
            raise ValueError("a half mesh (X.xreflect) needs the parity (-1)^|alpha| of the Hermite indices")
        A = A + sp.kron(X.xreflect, sp.csr_matrix(Fp * np.asarray(parity, dtype=float)[None, :]))
    return A.tocsr()
