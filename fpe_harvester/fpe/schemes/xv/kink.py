"""The kink solver's discretization: DG in (x, v) times Hermite functions in (V, xi).

For :math:`U = a|x|`, the velocity's density concentrates at the trap (x, v) = (0, 0)
like a power of the energy :math:`E = v^2/2 + a|x|` (docs/model.md §3), which a smooth
basis in v cannot follow. This discretization keeps x *and* v on a mesh
(:mod:`...plane`, graded toward the origin) and expands only the linear variables
:math:`w = (V, \\xi)` in Hermite functions around a Gaussian weight :math:`N(b v, \\Sigma)`:

.. math::

    p(x, v, w) = \\sum_{|\\beta| \\le M} c_\\beta(x, v)\\, h_\\beta(z)\\,\\phi(z), \\qquad
    z = L^{-1}(w - b v), \\quad L L^T = \\Sigma .

The columns of L are chosen so that the net drive :math:`F = \\sigma\\xi - K_v V` is
:math:`F = g\\cdot w = s z_1 + (g\\cdot b) v` (first column along :math:`\\Sigma g`). With
:math:`\\gamma_e = \\gamma - g\\cdot b/m` and, on the half plane x > 0,
:math:`a_0(v) = -a/m - \\gamma_e v`, the projected stationary Fokker--Planck equation is the
hierarchy

.. math::

    \\partial_x (v\\, c) + \\partial_v\\big((a_0(v) + G)\\, c\\big) = (K_0 + v K_1)\\, c,
    \\qquad G = \\frac{s}{m} J_1,

with :math:`J_1` the (tridiagonal) multiplication by :math:`z_1`, :math:`K_0` the
generator of the (V, xi) dynamics in z (relaxation, noise, and the kink force's pull on the
shifted frame), :math:`K_1` the V-drive :math:`K_c v` and the frame's shift. G is
diagonalized once, :math:`G = R\\Lambda R^T`: its eigenvalues are Gauss--Hermite nodes of F
(per chain of :math:`\\beta_1`), and in that *mode* basis :math:`d = c R` the transport is
diagonal: mode i moves with velocity :math:`(v, a_0(v) + \\lambda_i)` in the plane. The DG
flux is the exact upwind (characteristic) flux: on a face v = const the velocity of each
mode is constant, so its sign decides; on a face x = const it is v, whose sign is fixed
by the node at v = 0.

On x = 0 the half plane receives, for v > 0, the mirror image of its own outflow:
:math:`c_\\beta(0^-, v) = (-1)^{|\\beta|} c_\\beta(0^+, -v)`; in the mode basis the parity
maps the mode of node :math:`\\lambda` to that of :math:`-\\lambda` with a sign.

For :math:`U = a|x|^n` with 1 < n < 2 the same hierarchy holds with :math:`a_0` replaced
by the force :math:`-(a n/m)\\,x^{n-1}` (the frame then must not shift with v): the speed of
a mode along a face v = const falls monotonically in x, so the upwind split of every face
is still exact (:meth:`~...plane.DGLine.signed_parts`), and the :math:`x^{n-1}` masses use
Gauss--Jacobi on the element at x = 0. There is no trap for n > 1 (the density is bounded),
so the mesh needs no layers toward the origin.

The linear system (the stationary density is its null vector, normalized) is solved by
GMRES in the mode basis, preconditioned by the exact solves of every mode's scalar
transport (with its parity partner), swept mode by mode with the coupling between modes
(noise and relaxation of (V, xi)) in Gauss--Seidel fashion
(:class:`~.modesolve.ModePreconditioner`): the transport around the trap is cyclic (the
flow spirals into the origin), and a solve per mode resolves the cycles exactly on any
mesh, where element-block Gauss--Seidel sweeps cannot follow the rotation
(docs/methods.md, Fokker-Planck design notes).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ....errors import NotConvergedError
from ....model import Harvester
from ...blocksolve import blas_controller
from ...krylov import gmres, restart_length
from ...moments import conditional_fields, harvester_moments
from ...plane import PlaneMesh
from .hierarchy import KinkFrame, KinkHierarchy, KinkPlane, kink_plane
from .modesolve import ModePreconditioner

__all__ = ["KinkLevel", "face_parts", "mode_transport",
           "ModeOperator", "CoarseCorrection", "solve_kink_level", "GMRES_GIGABYTES", "GMRES_RESTART", "SWEEP_THREADS"]

#: Memory (GB) of the GMRES basis and its longest restart length: the restart length is
#: what fits, at most GMRES_RESTART (the levels the refinement takes need fewer iterations
#: than that; docs/methods.md, Fokker-Planck design notes).
GMRES_GIGABYTES, GMRES_RESTART = 1.5, 150

#: Threads of the preconditioner's sweep (:class:`~.modesolve.ModePreconditioner`).
SWEEP_THREADS = 1


def face_parts(pl: KinkPlane, hi: KinkHierarchy) -> tuple[np.ndarray, np.ndarray]:
    """x-matrices of the upwind flux of every mode through every face v = v_j: the element
    masses weighted by the positive and negative part of the mode's speed
    :math:`a_0 - \\gamma_e v_j + \\kappa x + \\lambda_i` (linear in x along the face), shape
    ``(nodes, modes, x elements, p + 1, p + 1)``."""
    speed0 = hi.a0 - hi.gamma_e * pl.Vl.nodes[:, None] + hi.lam[None, :]
    P, N = pl.X.signed_parts(speed0.ravel(), hi.kappa, hi.A, hi.q)
    shape = (*speed0.shape, *P.shape[1:])
    return P.reshape(shape), N.reshape(shape)


def mode_transport(pl: KinkPlane, hi: KinkHierarchy, parts: tuple[np.ndarray, np.ndarray]) -> list[sp.csr_matrix]:
    """The scalar transport matrix of every mode: ``S_I``, :math:`\\lambda_i` times the v
    derivative, and its upwind v-face terms. All modes share one sparsity pattern, so the
    entries are gathered once and summed per mode by one ``bincount``."""
    P, N = parts
    p1, nvd = pl.X.p + 1, pl.Vl.size
    nx_el = pl.X.elements
    S_I = pl.S_I.tocoo()
    S_G = (-sp.kron(pl.Mx, pl.Dv)).tocoo()
    rows, cols = [S_I.row, S_G.row], [S_I.col, S_G.col]
    # face entries: x block (e, k, l) of P[j, i] or N[j, i] times the v entry (r, c) of U_j or D_j
    ex, kk, ll = np.meshgrid(np.arange(nx_el), np.arange(p1), np.arange(p1), indexing="ij")
    xr, xc = (ex * p1 + kk).ravel(), (ex * p1 + ll).ravel()
    face_vals = []
    for j, (_, U, D) in enumerate(pl.faces):
        for V, W in ((U.tocoo(), P[j]), (D.tocoo(), N[j])):
            for r, c, sgn in zip(V.row, V.col, V.data):
                rows.append(xr * nvd + r)
                cols.append(xc * nvd + c)
                face_vals.append(sgn * W.reshape(W.shape[0], -1))        # (modes, entries)
    row, col = np.concatenate(rows), np.concatenate(cols)
    n = pl.S_I.shape[0]
    pattern = sp.csr_matrix((np.ones(row.size), (row, col)), shape=(n, n))
    pattern.sum_duplicates()
    pattern.sort_indices()
    # position of every gathered entry in the pattern's data array
    keys = row.astype(np.int64) * n + col
    uniq, pos = np.unique(keys, return_inverse=True)
    fv = np.concatenate(face_vals, axis=1)                               # (modes, face entries)
    out = []
    for i, li in enumerate(hi.lam):
        vals = np.concatenate([S_I.data, li * S_G.data, fv[i]])
        data = np.bincount(pos, weights=vals, minlength=uniq.size)
        out.append(sp.csr_matrix((data, pattern.indices.copy(), pattern.indptr.copy()), shape=(n, n)))
    return out


class ModeOperator:
    """The operator in the mode basis, applied to all modes at once: the mode-independent
    sparse parts as sparse-times-dense products, the v faces (whose upwind side depends on
    the mode) as one sparse matrix on the flattened unknowns (row-major: (x, v) unknown
    outer, mode inner), the parity (a signed permutation of the modes) as a sparse matrix:
    about half the time of a product with the faces gathered per v node (docs/methods.md, Fokker-Planck design notes)."""

    def __init__(self, pl: KinkPlane, hi: KinkHierarchy, parts: tuple[np.ndarray, np.ndarray]) -> None:
        self.pl, self.hi = pl, hi
        self.S_G = -sp.kron(pl.Mx, pl.Dv).tocsr()
        # entries below 1e-12 are rounding of R (the parity maps each mode to one other)
        self.Pm = sp.csr_matrix(np.where(np.abs(hi.Pm) > 1e-12, hi.Pm, 0.0))
        self.faces = _face_matrix(pl, parts)

    def __call__(self, D: np.ndarray) -> np.ndarray:
        pl, hi = self.pl, self.hi
        out = pl.S_I @ D + (self.S_G @ D) * hi.lam
        out += pl.S_K0 @ (D @ hi.K0m.T) + pl.S_K1 @ (D @ hi.K1m.T) + pl.S_S @ (self.Pm @ D.T).T
        if hi.K2.nnz:
            out += pl.S_K2 @ (D @ hi.K2m.T)
        out += (self.faces @ D.ravel()).reshape(D.shape)
        return out


def _face_matrix(pl: KinkPlane, parts: tuple[np.ndarray, np.ndarray]) -> sp.csr_matrix:
    """The upwind flux of every mode through the faces v = v_j inside the mesh, as a sparse
    matrix on the flattened unknowns (index (x dof * nvd + v dof) * modes + mode).

    On the face at node j, with trace b below (top of the element below) and a above, the
    flux of x element e and mode i is :math:`f_{ek} = \\sum_l P_{j,iekl}\\, c_{(el)b}
    + N_{j,iekl}\\, c_{(el)a}`; it enters the equation of the trace below with + and that of
    the trace above with -."""
    P, N = parts
    p1, nvd = pl.Vl.p + 1, pl.Vl.size
    nh, ne = P.shape[1], P.shape[2]
    i, e, k, l_ = np.meshgrid(np.arange(nh), np.arange(ne), np.arange(p1), np.arange(p1), indexing="ij")
    rows, cols, vals = [], [], []
    for j in range(pl.Vl.nodes.size):
        below = j * p1 - 1 if j > 0 else -1
        above = j * p1 if j < pl.Vl.elements else -1
        for out_dof, sign in ((below, 1.0), (above, -1.0)):
            for in_dof, W in ((below, P[j]), (above, N[j])):
                if out_dof < 0 or in_dof < 0:
                    continue
                rows.append((((e * p1 + k) * nvd + out_dof) * nh + i).ravel())
                cols.append((((e * p1 + l_) * nvd + in_dof) * nh + i).ravel())
                vals.append(sign * W.ravel())
    size = pl.S_I.shape[0] * nh
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size))


class CoarseCorrection:
    """Exact solve of the kink discretization truncated at the low Hermite degree ``Mc``.

    Used after the mode preconditioner (multiplicatively): the modes' solves miss the
    coupling of the modes by the (V, xi) dynamics, whose slowest part lives in the lowest
    Hermite degrees. It depends on the mesh, the DG degree and the frame only, so one
    factorization serves every M of a refinement. Degree 2 (:data:`~.kinkdisc.COARSE_DEGREE`)
    halves the iterations; degree 4 costs more than it saves (docs/methods.md, Fokker-Planck design notes).
    """

    def __init__(self, h: Harvester, mesh: PlaneMesh, order: int, frame: KinkFrame, Mc: int = 2) -> None:
        hi = KinkHierarchy.of(h, Mc, frame)
        pl = kink_plane(h, mesh, order, hi.gamma_e, hi.kappa)
        self.hermite = hi.hb
        nc = hi.hb.size
        T = mode_transport(pl, hi, face_parts(pl, hi))
        # the Mc-truncated operator in the Hermite basis: transport from the mode basis
        blocks = sp.block_diag(T, format="csr")
        perm = np.arange(pl.S_I.shape[0] * nc).reshape(nc, -1).T.ravel()   # (mode, xv) -> (xv, mode)
        Rk = sp.kron(sp.identity(pl.S_I.shape[0]), sp.csr_matrix(hi.R))
        A = Rk @ blocks[perm][:, perm] @ Rk.T
        A = (A + sp.kron(pl.S_K0, hi.K0) + sp.kron(pl.S_K1, hi.K1) + sp.kron(pl.S_K2, hi.K2)
             + sp.kron(pl.S_S, sp.diags(hi.hb.parity())))
        # The border u u^T by Sherman-Morrison (a dense row would fill the factors). A is
        # nearly singular (mass is conserved up to the outflow), so A^{-1} u is large and
        # the formula cancels digits; a preconditioner needs few.
        self.lu = spla.splu(A.tocsc(), permc_spec="MMD_ATA")
        u = np.zeros((pl.S_I.shape[0], nc))
        u[:, 0] = pl.integrals["1"] / np.linalg.norm(pl.integrals["1"])
        self.u = u.ravel()
        self.z = self.lu.solve(self.u)
        self.nc = nc

    def __call__(self, r: np.ndarray, hi: KinkHierarchy) -> np.ndarray:
        """The correction (mode basis of ``hi``) for the residual ``r`` (mode basis of ``hi``)."""
        low = np.array([hi.hb.index[tuple(al)] for al in self.hermite.alphas])
        Rl = hi.R[low]
        x = self.lu.solve(np.ascontiguousarray(r @ Rl.T).ravel())
        x -= self.z * (float(self.u @ x) / (1.0 + float(self.u @ self.z)))
        return x.reshape(-1, self.nc) @ Rl


@dataclass(frozen=True)
class KinkLevel:
    """One solved level of the kink discretization.

    Attributes
    ----------
    M, order : int
        Hermite degree in (V, xi) and DG degree in x and v.
    mesh : PlaneMesh
        The (x, v) mesh of the half plane.
    coef : ndarray (n_xv, n_beta)
        Coefficients :math:`c_\\beta` at every (x, v) unknown (x outer), unit mass on the
        whole plane.
    moments : dict
        ``V2, Pin, eta, v2, vV, vxi, x2`` and the identity residuals ``res_V2``, ``res_power``.
    dofs : int
        Number of unknowns.
    seconds : float
        Wall time (assembly, preconditioner, GMRES).
    iterations : int
        GMRES iterations.
    """

    M: int
    order: int
    mesh: PlaneMesh
    coef: np.ndarray = field(repr=False)
    moments: dict[str, float]
    dofs: int
    seconds: float
    iterations: int
    frame: KinkFrame = field(repr=False)
    hierarchy: KinkHierarchy = field(repr=False)
    plane: KinkPlane = field(repr=False)
    #: The refinement's mesh knob this level was solved at (:class:`~.kinkdisc.KinkDG`).
    size: int = 1
    #: The oscillator's mass m (for energies).
    mass: float = 1.0

    @property
    def elements(self) -> int:
        """Rectangles of the whole plane (twice the half plane's)."""
        return 2 * self.mesh.elements

    @property
    def half_width(self) -> float:
        """Half-width :math:`L_x` of the domain in x."""
        return self.mesh.Lx

    def info(self) -> dict[str, Any]:
        """Discretization details for the result's ``info``."""
        return {"scheme": "xv", "M": self.M, "order": self.order, "elements": self.elements,
                "layers": self.mesh.layers, "subdivisions": self.mesh.subdivisions, "Lx": self.mesh.Lx,
                "Lv": self.mesh.Lv, "dofs": self.dofs, "gmres_iterations": self.iterations,
                "frame_Sigma": self.frame.Sigma.tolist(), "frame_shift": self.frame.shift.tolist(),
                "frame_xshift": self.frame.xshift.tolist()}

    def fields(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """x-marginal density and conditional means :math:`\\langle y|x\\rangle`,
        y = v, V, xi, at points ``x`` (masked where the density is below 1e-9 of its peak)."""
        X, Vl = self.plane.X, self.plane.Vl
        x = np.asarray(x, dtype=float)
        C = self.coef.reshape(X.size, Vl.size, -1)
        w1 = self.hierarchy.hb.first_moment_weights(self.hierarchy.L)     # (2, n_beta)
        c0v = C[:, :, 0] @ Vl.integral()                                  # int c0 dv
        vc0 = C[:, :, 0] @ Vl.integral(1)                                 # int v c0 dv
        wc = np.einsum("xvb,v,ib->xi", C, Vl.integral(), w1)              # int <w'> c0 dv
        ax = np.clip(np.abs(x), 0.0, X.nodes[-1])
        dens = X.evaluate(c0v, ax)
        sign = np.where(x < 0.0, -1.0, 1.0)
        b, c = self.frame.shift, self.frame.xshift
        num = {"v_mean": X.evaluate(vc0, ax),
               "V_mean": X.evaluate(wc[:, 0] + b[0] * vc0, ax) + c[0] * ax * X.evaluate(c0v, ax),
               "xi_mean": X.evaluate(wc[:, 1] + b[1] * vc0, ax) + c[1] * ax * X.evaluate(c0v, ax)}
        dens = np.where(np.abs(x) <= X.nodes[-1], dens, 0.0)
        return conditional_fields(dens, {name: sign * val for name, val in num.items()})

    def summary(self) -> dict[str, Any]:
        """JSON-ready description (for the refinement history)."""
        return {"M": self.M, "order": self.order, "layers": self.mesh.layers, "bulk_x": self.mesh.bulk_x,
                "bulk_v": self.mesh.bulk_v, "elements": self.mesh.elements, "dofs": self.dofs,
                "iterations": self.iterations, "seconds": round(self.seconds, 4), "eta": self.moments["eta"],
                "V2": self.moments["V2"], "Pin": self.moments["Pin"]}

    def marginal(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The (x, v) marginal density :math:`c_0` on the grid ``x`` (rows) by ``v`` (columns);
        x < 0 by the mirror image."""
        X, Vl = self.plane.X, self.plane.Vl
        c0 = self.coef[:, 0].reshape(X.size, Vl.size)
        x, v = np.asarray(x, dtype=float), np.asarray(v, dtype=float)
        ax = np.abs(x)
        rows = X.evaluate(c0, np.clip(ax, 0.0, X.nodes[-1]))          # (nx_pts, nv_dofs)
        sign = np.where(x < 0.0, -1.0, 1.0)
        vv = np.clip(sign[:, None] * v[None, :], -Vl.nodes[-1], Vl.nodes[-1])
        out = np.empty((x.size, v.size))
        for i in range(x.size):
            out[i] = Vl.evaluate(rows[i], vv[i])
        inside = (ax <= X.nodes[-1])[:, None] & (np.abs(v) <= Vl.nodes[-1])[None, :]
        return np.where(inside, out, 0.0)

    def energy_cdf(self, eps: np.ndarray, nodes: int = 24) -> np.ndarray:
        """Probability :math:`P(E < \\varepsilon)` of the mechanical energy
        :math:`E = m v^2/2 + a|x|` below each ``eps`` (> 0) [energy units].

        The region :math:`E < \\varepsilon` of the plane is mapped onto a square,
        :math:`x = \\pm(\\varepsilon/a)(1 - u^2)`, :math:`v = \\sqrt{2\\varepsilon/m}\\,u t`
        (:math:`dx\\,dv = 2(\\varepsilon/a)\\sqrt{2\\varepsilon/m}\\,u^2\\,du\\,dt`), and
        integrated with ``nodes`` x ``nodes`` Gauss--Legendre points; the density is piecewise
        polynomial, so the rule is exact only where the region lies inside one element
        (elsewhere its error is of the order of the density's jump across element edges).
        Near the origin the density vanishes like :math:`E^{\\beta - 3/2}` or diverges like
        it (:math:`P(E < \\varepsilon) \\sim \\varepsilon^\\beta`); below the innermost layer of
        the mesh (:meth:`~...plane.PlaneMesh.x_nodes`) a level can only follow it polynomially.
        """
        if self.hierarchy.A:
            raise ValueError("energy_cdf is the kink's (n = 1: E = m v^2/2 + a|x|); this level has 1 < n < 2")
        eps = np.atleast_1d(np.asarray(eps, dtype=float))
        if np.any(~np.isfinite(eps)) or np.any(eps <= 0.0):
            raise ValueError(f"eps must be positive and finite, got {eps!r}")
        a, m = self.mesh.a, self.mass
        g, wg = np.polynomial.legendre.leggauss(nodes)
        u, wu = 0.5 * (g + 1.0), 0.5 * wg                                  # u in [0, 1]
        X, Vl = self.plane.X, self.plane.Vl
        c0 = self.coef[:, 0].reshape(X.size, Vl.size)
        xs = (eps[:, None] / a) * (1.0 - u[None, :] ** 2)                  # (n_eps, nodes)
        rows = X.evaluate(c0, np.clip(xs.ravel(), 0.0, X.nodes[-1])).reshape(eps.size, nodes, -1)
        out = np.empty(eps.size)
        for i, e in enumerate(eps):
            sv = math.sqrt(2.0 * e / m)
            acc = 0.0
            for k in range(nodes):
                v = np.clip(sv * u[k] * g, -Vl.nodes[-1], Vl.nodes[-1])
                dens = Vl.evaluate(rows[i, k], v) * (xs[i, k] <= X.nodes[-1])
                acc += wu[k] * u[k] ** 2 * float(wg @ dens)
            out[i] = 2.0 * 2.0 * (e / a) * sv * acc                        # both half planes
        return out


def _moments(h: Harvester, pl: KinkPlane, hi: KinkHierarchy, frame: KinkFrame, C: np.ndarray) -> dict[str, float]:
    # The half plane holds half of every (even) integral.
    p = h.params
    I = pl.integrals
    C = C / (2.0 * float(I["1"] @ C[:, 0]))
    v2, x2, xv = (2.0 * float(I[k] @ C[:, 0]) for k in ("v2", "x2", "xv"))
    w1 = hi.hb.first_moment_weights(hi.L)                  # <w' | x, v> c0 = w1 . c
    W2 = hi.hb.second_moment_weights(hi.L)
    vw1 = 2.0 * (w1 @ (C.T @ I["v"]))                      # <v w'>, w' = L z
    xw1 = 2.0 * (w1 @ (C.T @ I["x"]))                      # <x w'>
    ww1 = 2.0 * np.einsum("ijm,m->ij", W2, C.T @ I["1"])   # <w' w'^T>
    b, c = frame.shift, frame.xshift
    # w = w' + b v + c x
    vw = vw1 + b * v2 + c * xv
    xw = xw1 + b * xv + c * x2
    ww = (ww1 + np.outer(b, vw1) + np.outer(vw1, b) + np.outer(c, xw1) + np.outer(xw1, c)
          + np.outer(b, b) * v2 + np.outer(c, c) * x2 + (np.outer(b, c) + np.outer(c, b)) * xv)
    return {**harvester_moments(p, v2, vw[0], vw[1], ww[0, 0], x2),
            "xv": xv, "xV": float(xw[0]), "xxi": float(xw[1])}


def solve_kink_level(h: Harvester, M: int, mesh: PlaneMesh, order: int, frame: KinkFrame,
                     rtol: float = 1e-9, guess: KinkLevel | None = None, maxiter: int = 1500,
                     coarse: CoarseCorrection | None = None, deadline: float | None = None) -> KinkLevel:
    """Assemble and solve one level (GMRES in the mode basis, :class:`~.modesolve.ModePreconditioner`).

    The stationary density is the null vector of the operator A (nonsingular only through
    the outflow at the domain's edge); GMRES solves the bordered system
    :math:`(A + u w^T) c = u` with :math:`w^T c` the mass, whose solution is the null
    vector with unit mass (up to the outflow). ``guess`` (a lower level on the same mesh
    and frame) starts the iteration.
    """
    # single-threaded BLAS: the dense products are small (the modes of one degree), and
    # threads only add overhead and contention
    with blas_controller().limit(limits=1, user_api="blas"):
        return _solve(h, M, mesh, order, frame, rtol, guess, maxiter, coarse, deadline)


def _solve(h: Harvester, M: int, mesh: PlaneMesh, order: int, frame: KinkFrame, rtol: float,
           guess: KinkLevel | None, maxiter: int, coarse: CoarseCorrection | None,
           deadline: float | None) -> KinkLevel:
    t0 = time.perf_counter()
    hi = KinkHierarchy.of(h, M, frame)
    pl = kink_plane(h, mesh, order, hi.gamma_e, hi.kappa)
    parts = face_parts(pl, hi)
    T = mode_transport(pl, hi, parts)
    prec = ModePreconditioner(T, pl, hi, SWEEP_THREADS)
    n, nh = pl.S_I.shape[0], hi.hb.size
    # bordering in the mode basis: u = w = (integral of the test functions) on beta = 0
    U = np.outer(pl.integrals["1"], hi.R[0])
    unorm = U / np.linalg.norm(U)

    apply_A = ModeOperator(pl, hi, parts)

    def matvec(d: np.ndarray) -> np.ndarray:
        D = d.reshape(n, nh)
        out = apply_A(D)
        out += unorm * float(np.vdot(unorm, D))
        return out.ravel()

    x0 = None
    if guess is not None and guess.mesh == mesh and guess.order == order and guess.frame == frame:
        E = _embed(guess, hi)
        x0 = (E / float(np.vdot(unorm, E))).ravel()
    its = [0]

    def count(_: Any) -> None:
        its[0] += 1
        if deadline is not None and time.perf_counter() > deadline:
            raise NotConvergedError(f"the time budget ran out in GMRES iteration {its[0]} (M = {M}, "
                                    f"{mesh.elements} elements)")

    cc = coarse if coarse is not None and coarse.hermite.M < M else None

    def apply(r: np.ndarray) -> np.ndarray:
        R_ = r.reshape(n, nh)
        y = prec(R_)
        if cc is not None:
            y += cc(R_ - matvec(y.ravel()).reshape(n, nh), hi)
        return y.ravel()

    rhs = unorm.ravel()
    restart = restart_length(rhs.size, min(maxiter, GMRES_RESTART), GMRES_GIGABYTES)
    d, info, _ = gmres(matvec, apply, rhs, x0, rtol, restart, maxiter, callback=count)
    if info != 0:
        raise NotConvergedError(f"GMRES did not reach rtol = {rtol:.1e} in {its[0]} iterations "
                                f"(M = {M}, {mesh.elements} elements)")
    C = d.reshape(n, nh) @ hi.R.T
    C = C / (2.0 * float(pl.integrals["1"] @ C[:, 0]))
    mom = _moments(h, pl, hi, frame, C)
    return KinkLevel(M, order, mesh, C, mom, n * nh, time.perf_counter() - t0, its[0], frame, hi, pl,
                     mass=h.params.m)


def _embed(level: KinkLevel, hi: KinkHierarchy) -> np.ndarray:
    """The coefficients of a lower level in the mode basis of ``hi`` (degrees above the
    lower level's are zero)."""
    C = np.zeros((level.coef.shape[0], hi.hb.size))
    for k, al in enumerate(map(tuple, level.hierarchy.hb.alphas)):
        C[:, hi.hb.index[al]] = level.coef[:, k]
    return C @ hi.R
