"""The kink solver's discretization: DG in (x, v) times Hermite functions in (V, xi).

For :math:`U = a|x|`, the velocity's density concentrates at the trap (x, v) = (0, 0)
like a power of the energy :math:`E = v^2/2 + a|x|` (docs/model.md §3), which a smooth
basis in v cannot follow. This discretization keeps x *and* v on a mesh
(:mod:`.plane`, graded toward the origin) and expands only the linear variables
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

The linear system (the stationary density is its null vector, normalized) is solved by
GMRES in the mode basis, preconditioned by the exact solves of every mode's scalar
transport with the diagonal of the mode coupling (:class:`ModePreconditioner`): the
transport around the trap is cyclic (the flow spirals into the origin), and a solve per
mode resolves the cycles exactly on any mesh, while GMRES handles the coupling between
modes (noise and relaxation of (V, xi)). Measured on a = 2 with four layers at M = 6:
164 iterations in 11 s, against 566 iterations in 205 s with element-block symmetric
Gauss--Seidel, whose sweeps cannot follow the rotation.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import NotConvergedError
from ..model import Harvester
from .hermite import HermiteBasis
from .plane import DGLine, PlaneMesh

__all__ = ["KinkFrame", "KinkLevel", "solve_kink_level", "ModePreconditioner"]


@dataclass(frozen=True)
class KinkFrame:
    """Gaussian weight :math:`N(b v, \\Sigma)` of (V, xi) and its factor L.

    Attributes
    ----------
    Sigma : ndarray (2, 2)
        Covariance of the weight (V first), positive definite.
    shift : ndarray (2,)
        Regression b of (V, xi) on v: the weight is centred on b v (zero: not shifted).
    """

    Sigma: np.ndarray
    shift: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        object.__setattr__(self, "Sigma", np.asarray(self.Sigma, dtype=float).reshape(2, 2))
        object.__setattr__(self, "shift", np.asarray(self.shift, dtype=float).reshape(2))
        if not np.all(np.linalg.eigvalsh(self.Sigma) > 0.0):
            raise ValueError(f"Sigma must be positive definite, got {self.Sigma.tolist()}")

    @classmethod
    def from_moments(cls, h: Harvester, V2: float, Pin: float, v2: float, vV: float,
                     shifted: bool = False, widen: float = 1.0) -> KinkFrame:
        """The weight from estimates of the stationary moments.

        The marginal covariance of (V, xi) follows from V2 and Pin by two exact identities:
        :math:`\\langle\\xi^2\\rangle = D/\\tau` and
        :math:`\\langle V\\xi\\rangle = K_c\\langle v\\xi\\rangle/(1/\\tau_p + 1/\\tau)`
        (:math:`d\\langle V\\xi\\rangle/dt = 0`). ``shifted`` centres it on the regression
        :math:`b = (\\langle vV\\rangle, \\langle v\\xi\\rangle)/\\langle v^2\\rangle` and
        keeps the conditional covariance; ``widen`` multiplies the covariance.
        """
        p = h.params
        vxi = Pin / p.sigma
        cov = p.Kc * vxi / (1.0 / p.tau_p + 1.0 / p.tau)
        Sigma = np.array([[V2, cov], [cov, p.D / p.tau]])
        b = np.zeros(2)
        if shifted:
            b = np.array([vV, vxi]) / v2
            Sigma = Sigma - np.outer(b, b) * v2
        # keep the weight a proper Gaussian when the estimates are rough
        lam, U = np.linalg.eigh(Sigma)
        lam = np.maximum(lam, 1e-3 * lam.max())
        return cls((U * lam) @ U.T * widen, b)

    def factor(self, h: Harvester) -> tuple[np.ndarray, float]:
        """``(L, s)``: :math:`L L^T = \\Sigma` with :math:`g^T L = (s, 0)`,
        :math:`g = (-K_v, \\sigma)`, i.e. :math:`z_1 = (F - g\\cdot b\\,v)/s`."""
        p = h.params
        g = np.array([-p.Kv, p.sigma])
        s = math.sqrt(float(g @ self.Sigma @ g))
        l1 = self.Sigma @ g / s
        rest = self.Sigma - np.outer(l1, l1)
        lam, U = np.linalg.eigh(rest)
        l2 = math.sqrt(max(lam[-1], 0.0)) * U[:, -1]
        return np.column_stack([l1, l2]), s


@dataclass(frozen=True)
class _Hierarchy:
    """Hermite matrices of one degree M in the frame, and G's eigen-decomposition."""

    hb: HermiteBasis
    L: np.ndarray
    lam: np.ndarray          # eigenvalues of G (velocities of the modes, per unit mass)
    R: np.ndarray            # orthogonal eigenvectors, c = d R^T
    K0m: np.ndarray          # K0, K1 and the parity in the mode basis (R^T H R)
    K1m: np.ndarray
    Pm: np.ndarray
    a0: float                # a0(v) = a0 - gamma_e v on x > 0
    gamma_e: float

    @classmethod
    def of(cls, h: Harvester, M: int, frame: KinkFrame) -> _Hierarchy:
        p = h.params
        hb = HermiteBasis(M, dim=2)
        L, s = frame.factor(h)
        Li = np.linalg.inv(L)
        b = frame.shift
        g = np.array([-p.Kv, p.sigma])
        gamma_e = p.gamma - float(g @ b) / p.m
        Bw = np.diag([-1.0 / p.tau_p, -1.0 / p.tau])
        Qw = np.diag([0.0, 2.0 * p.D / p.tau**2])
        Bz = Li @ Bw @ L - np.outer(Li @ b, g @ L) / p.m
        # z' = Bz z + Li (Bw b + Kc e_V + gamma_e b) v + Li b a/m (x > 0) + noise
        K0 = hb.generator(Bz, Li @ Qw @ Li.T) + hb.lowering(Li @ b * (h.a / p.m))
        K1 = hb.lowering(Li @ (Bw @ b + np.array([p.Kc, 0.0]) + gamma_e * b))
        G = (s / p.m) * hb.multiply(0).toarray()
        lam, R = np.linalg.eigh(G)
        R[np.abs(R) < 1e-15] = 0.0
        par = hb.parity()
        return cls(hb, L, lam, R, R.T @ (K0 @ R), R.T @ (K1 @ R), R.T @ (par[:, None] * R),
                   -h.a / p.m, gamma_e)


@dataclass(frozen=True)
class _Plane:
    """Scalar DG matrices of the (x, v) mesh (x outer, v inner): see :func:`_plane`."""

    X: DGLine
    Vl: DGLine
    S_I: sp.csr_matrix       # x transport, the a0 part of v transport (mode independent)
    S_S: sp.csr_matrix       # mirror inflow at x = 0 (times the parity)
    S_K0: sp.csr_matrix      # -mass
    S_K1: sp.csr_matrix      # -mass * v
    Mx: sp.csr_matrix
    Dv: sp.csr_matrix
    faces: list[tuple[float, sp.csr_matrix, sp.csr_matrix]]   # (v_j, up, down) per v node
    integrals: dict[str, np.ndarray]


def _plane(h: Harvester, mesh: PlaneMesh, p: int, gamma_e: float) -> _Plane:
    """Assemble the scalar matrices of the upwind DG weak form on the half plane x > 0.

    Per element K and test function :math:`\\psi`, for every mode (velocity
    :math:`(v, a_0(v) + \\lambda)`):

    .. math::

        \\oint_{\\partial K}\\psi\\,\\widehat{(u\\cdot n)\\,c} - \\int_K (\\psi_x v
        + \\psi_v (a_0 + \\lambda))\\, c - \\int_K \\psi (k_0 + v k_1) c = 0 .

    Faces x = const: flux v c from the side it leaves (outflow only at x = Lx; at x = 0,
    inflow for v > 0 from the mirror image, ``S_S``). Faces v = v_j: per mode the flux
    :math:`(a_0(v_j) + \\lambda)^{\\pm} c` from below/above, ``faces`` holds
    :math:`(v_j, U_j, D_j)` with :math:`U_j` (for the positive part) and :math:`D_j`
    (negative part) the v-matrices; no inflow at :math:`|v| = L_v`.
    """
    m = h.params.m
    X, Vl = DGLine(mesh.x_nodes(), p), DGLine(mesh.v_nodes(), p)
    Mx, Dx, Mv, Mvv = X.mass(), X.derivative(), Vl.mass(), Vl.mass(power=1)
    Dv, Dvv = Vl.derivative(), Vl.derivative(power=1)
    # v elements above / below 0 (the mesh has a node at 0)
    mid = 0.5 * (Vl.nodes[:-1] + Vl.nodes[1:])
    up = np.repeat(mid > 0.0, p + 1).astype(float)
    Mv_up, Mv_dn = Mvv @ sp.diags(up), Mvv @ sp.diags(1.0 - up)
    nx = X.elements
    right = sp.csr_matrix(np.outer(X.left_of(nx), X.left_of(nx)))
    lft = sp.csr_matrix(np.outer(X.right_of(0), X.right_of(0)))
    Xpos, Xneg = right.copy(), -lft
    for node in range(1, nx):
        tl, tr = X.left_of(node), X.right_of(node)
        Xpos = Xpos + sp.csr_matrix(np.outer(tl - tr, tl))
        Xneg = Xneg + sp.csr_matrix(np.outer(tl - tr, tr))
    S_I = (-sp.kron(Dx, Mvv) - sp.kron(Mx, (-h.a / m) * Dv - gamma_e * Dvv)
           + sp.kron(Xpos, Mv_up) + sp.kron(Xneg, Mv_dn))
    flip = sp.csr_matrix(np.fliplr(np.eye(Vl.size)))
    S_S = -sp.kron(lft, Mv_up @ flip)
    faces = []
    for j, vj in enumerate(Vl.nodes):
        tb, ta = Vl.left_of(j), Vl.right_of(j)
        faces.append((float(vj), sp.csr_matrix(np.outer(tb - ta, tb)), sp.csr_matrix(np.outer(tb - ta, ta))))
    Ix, Iv = X.integral(), Vl.integral()
    integrals = {"1": np.kron(Ix, Iv), "v": np.kron(Ix, Vl.integral(1)), "v2": np.kron(Ix, Vl.integral(2)),
                 "x2": np.kron(X.integral(2), Iv)}
    return _Plane(X, Vl, S_I.tocsr(), S_S.tocsr(), -sp.kron(Mx, Mv).tocsr(), -sp.kron(Mx, Mvv).tocsr(),
                  Mx, Dv, faces, integrals)


def _mode_transport(pl: _Plane, a0: float, gamma_e: float, lam: np.ndarray) -> list[sp.csr_matrix]:
    """The scalar transport matrix of every mode: ``S_I`` plus its v-flux terms."""
    out = []
    for li in lam:
        vmat = -li * pl.Dv
        for vj, U, D in pl.faces:
            speed = a0 - gamma_e * vj + li
            vmat = vmat + (U * speed if speed > 0.0 else D * speed)
        out.append((pl.S_I + sp.kron(pl.Mx, vmat)).tocsr())
    return out


class ModePreconditioner:
    """Exact solve of each mode's transport with the diagonal of the mode coupling.

    Modes that the mirror condition couples (nodes :math:`\\pm\\lambda` of one chain) are
    solved together. Sparse LU (SuperLU) of systems of the size of the scalar (x, v) space.
    """

    def __init__(self, T: list[sp.csr_matrix], pl: _Plane, hi: _Hierarchy) -> None:
        n = len(T)
        self.groups: list[tuple[np.ndarray, Any]] = []
        seen = np.zeros(n, dtype=bool)
        for i in range(n):
            if seen[i]:
                continue
            grp = np.unique(np.concatenate([[i], np.flatnonzero(np.abs(hi.Pm[:, i]) > 1e-8)]))
            seen[grp] = True
            blocks = [[hi.Pm[r, c] * pl.S_S for c in grp] for r in grp]
            for k, r in enumerate(grp):
                blocks[k][k] = blocks[k][k] + T[r] + hi.K0m[r, r] * pl.S_K0 + hi.K1m[r, r] * pl.S_K1
            self.groups.append((grp, spla.splu(sp.bmat(blocks, format="csc"))))

    def __call__(self, r: np.ndarray) -> np.ndarray:
        out = np.empty_like(r)
        for grp, lu in self.groups:
            out[:, grp] = lu.solve(np.ascontiguousarray(r[:, grp].T).ravel()).reshape(len(grp), -1).T
        return out


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
    hierarchy: _Hierarchy = field(repr=False)
    plane: _Plane = field(repr=False)

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


def _moments(h: Harvester, pl: _Plane, hi: _Hierarchy, frame: KinkFrame, C: np.ndarray) -> dict[str, float]:
    # The half plane holds half of every (even) integral.
    p = h.params
    I = pl.integrals
    mass = 2.0 * float(I["1"] @ C[:, 0])
    C = C / mass
    v2 = 2.0 * float(I["v2"] @ C[:, 0])
    x2 = 2.0 * float(I["x2"] @ C[:, 0])
    w1 = hi.hb.first_moment_weights(hi.L)                  # <w' | x, v> c0 = w1 . c
    W2 = hi.hb.second_moment_weights(hi.L)
    vw1 = 2.0 * (w1 @ (C.T @ I["v"]))                      # <v w'>, w' = L z
    ww1 = 2.0 * np.einsum("ijm,m->ij", W2, C.T @ I["1"])   # <w' w'^T>
    b = frame.shift
    # w = w' + b v
    vw = vw1 + b * v2
    ww = ww1 + np.outer(b, vw1) + np.outer(vw1, b) + np.outer(b, b) * v2
    vV, vxi, V2 = vw[0], vw[1], ww[0, 0]
    Pin = p.sigma * vxi
    return {
        "V2": float(V2), "Pin": float(Pin), "eta": float(V2 / (p.R * Pin)), "v2": v2, "vV": float(vV),
        "vxi": float(vxi), "x2": x2,
        "res_V2": float((V2 - p.Kc * p.tau_p * vV) / V2),
        "res_power": float((Pin - p.m * p.gamma * v2 - p.Kv * vV) / Pin),
    }


def solve_kink_level(h: Harvester, M: int, mesh: PlaneMesh, order: int, frame: KinkFrame,
                     rtol: float = 1e-9, guess: KinkLevel | None = None, maxiter: int = 3000) -> KinkLevel:
    """Assemble and solve one level (GMRES in the mode basis, :class:`ModePreconditioner`).

    The stationary density is the null vector of the operator A (nonsingular only through
    the outflow at the domain's edge); GMRES solves the bordered system
    :math:`(A + u w^T) c = u` with :math:`w^T c` the mass, whose solution is the null
    vector with unit mass (up to the outflow). ``guess`` (a lower level on the same mesh
    and frame) starts the iteration.
    """
    t0 = time.perf_counter()
    hi = _Hierarchy.of(h, M, frame)
    pl = _plane(h, mesh, order, hi.gamma_e)
    T = _mode_transport(pl, hi.a0, hi.gamma_e, hi.lam)
    prec = ModePreconditioner(T, pl, hi)
    n, nh = pl.S_I.shape[0], hi.hb.size
    # bordering in the mode basis: u = w = (integral of the test functions) on beta = 0
    U = np.outer(pl.integrals["1"], hi.R[0])
    unorm = U / np.linalg.norm(U)

    def matvec(d: np.ndarray) -> np.ndarray:
        D = d.reshape(n, nh)
        out = np.empty_like(D)
        for i, Ti in enumerate(T):
            out[:, i] = Ti @ D[:, i]
        out += pl.S_K0 @ (D @ hi.K0m.T) + pl.S_K1 @ (D @ hi.K1m.T) + pl.S_S @ (D @ hi.Pm.T)
        out += unorm * float(np.vdot(unorm, D))
        return out.ravel()

    x0 = None
    if guess is not None and guess.mesh == mesh and guess.order == order and guess.frame == frame:
        E = _embed(guess, hi)
        x0 = (E / float(np.vdot(unorm, E))).ravel()
    its = [0]

    def count(_: Any) -> None:
        its[0] += 1

    A = spla.LinearOperator((n * nh, n * nh), matvec=matvec, dtype=float)
    P = spla.LinearOperator((n * nh, n * nh), matvec=lambda r: prec(r.reshape(n, nh)).ravel(), dtype=float)
    rhs = unorm.ravel()
    d, info = spla.gmres(A, rhs, x0=x0, M=P, rtol=rtol, restart=min(200, maxiter), maxiter=maxiter,
                         callback=count, callback_type="pr_norm")
    if info != 0:
        raise NotConvergedError(f"GMRES did not reach rtol = {rtol:.1e} in {its[0]} iterations "
                                f"(M = {M}, {mesh.elements} elements)")
    C = d.reshape(n, nh) @ hi.R.T
    mom = _moments(h, pl, hi, frame, C)
    C = C / (2.0 * float(pl.integrals["1"] @ C[:, 0]))
    return KinkLevel(M, order, mesh, C, mom, n * nh, time.perf_counter() - t0, its[0], frame, hi, pl)


def _embed(level: KinkLevel, hi: _Hierarchy) -> np.ndarray:
    """The coefficients of a lower level in the mode basis of ``hi`` (degrees above the
    lower level's are zero)."""
    C = np.zeros((level.coef.shape[0], hi.hb.size))
    for k, al in enumerate(map(tuple, level.hierarchy.hb.alphas)):
        C[:, hi.hb.index[al]] = level.coef[:, k]
    return C @ hi.R
