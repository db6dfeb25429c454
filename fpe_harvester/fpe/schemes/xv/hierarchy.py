"""The kink scheme's building blocks: the Gaussian frame of (V, xi), the Hermite hierarchy in
that frame, and the DG matrices of the (x, v) plane.

:class:`KinkFrame` is the weight :math:`N(b v + c x, \\Sigma)`, :class:`KinkHierarchy` the
projected (V, xi) dynamics in its Hermite basis and in the mode basis of the drive, and
:func:`kink_plane` the DG matrices of the plane (:class:`KinkPlane`); :mod:`.kink` assembles
and solves a level from them (its module docstring has the equations) and
:mod:`.modesolve` preconditions it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ....model import Harvester
from ...hermite import HermiteBasis
from ...plane import DGLine, PlaneMesh

__all__ = ["KinkFrame", "KinkHierarchy", "KinkPlane", "kink_plane"]


@dataclass(frozen=True)
class KinkFrame:
    """Gaussian weight :math:`N(b v + c x, \\Sigma)` of (V, xi) and its factor L.

    Attributes
    ----------
    Sigma : ndarray (2, 2)
        Covariance of the weight (V first), positive definite.
    shift : ndarray (2,)
        b: the weight's centre moves with v (zero: not shifted).
    xshift : ndarray (2,)
        c: the weight's centre moves with x (zero: not shifted).
    """

    Sigma: np.ndarray
    shift: np.ndarray = field(default_factory=lambda: np.zeros(2))
    xshift: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        object.__setattr__(self, "Sigma", np.asarray(self.Sigma, dtype=float).reshape(2, 2))
        object.__setattr__(self, "shift", np.asarray(self.shift, dtype=float).reshape(2))
        object.__setattr__(self, "xshift", np.asarray(self.xshift, dtype=float).reshape(2))
        if not np.all(np.linalg.eigvalsh(self.Sigma) > 0.0):
            raise ValueError(f"Sigma must be positive definite, got {self.Sigma.tolist()}")

    @classmethod
    def from_moments(cls, h: Harvester, mo: dict[str, float], shifted: bool = False,
                     xshifted: float = 0.0) -> KinkFrame:
        """The weight from estimates ``mo`` of the stationary moments (V2, Pin, v2, vV; with
        ``xshifted`` also x2, xV, xxi).

        The marginal covariance of (V, xi) follows from V2 and Pin by two exact identities:
        :math:`\\langle\\xi^2\\rangle = D/\\tau` and
        :math:`\\langle V\\xi\\rangle = K_c\\langle v\\xi\\rangle/(1/\\tau_p + 1/\\tau)`
        (:math:`d\\langle V\\xi\\rangle/dt = 0`). ``shifted`` centres it on the regression
        :math:`b = \\langle w v\\rangle/\\langle v^2\\rangle` on v (:math:`\\langle xv\\rangle = 0`);
        ``xshifted`` (a fraction f in [0, 1]) also on x,
        :math:`c = \\langle w x\\rangle/\\langle x^2\\rangle`, and removes the fraction f of
        the variance that the regression on x explains from the covariance.
        """
        p = h.params
        vxi = mo["Pin"] / p.sigma
        cov = p.Kc * vxi / (1.0 / p.tau_p + 1.0 / p.tau)
        Sigma = np.array([[mo["V2"], cov], [cov, p.D / p.tau]])
        b, c = np.zeros(2), np.zeros(2)
        if shifted:
            b = np.array([mo["vV"], vxi]) / mo["v2"]
            Sigma = Sigma - np.outer(b, b) * mo["v2"]
        if xshifted:
            c = np.array([mo["xV"], 0.0]) / mo["x2"]
            Sigma = Sigma - xshifted * np.outer(c, c) * mo["x2"]
        # keep the weight a proper Gaussian when the estimates are rough
        lam, U = np.linalg.eigh(Sigma)
        lam = np.maximum(lam, 1e-3 * lam.max())
        return cls((U * lam) @ U.T, b, c)

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
class KinkHierarchy:
    """Hermite matrices of one degree M in the frame, and G's eigen-decomposition."""

    hb: HermiteBasis
    L: np.ndarray
    lam: np.ndarray          # eigenvalues of G (velocities of the modes, per unit mass)
    R: np.ndarray            # orthogonal eigenvectors, c = d R^T
    K0m: np.ndarray          # K0, K1 and the parity in the mode basis (R^T H R)
    K1m: np.ndarray
    Pm: np.ndarray
    K0: sp.csr_matrix        # K0, K1 and K2 in the Hermite basis
    K1: sp.csr_matrix
    K2: sp.csr_matrix        # multiplies x (the frame's x shift)
    K2m: np.ndarray
    a0: float                # speed of mode i on x > 0: a0 - gamma_e v + kappa x - A x^q + lam_i
    gamma_e: float
    kappa: float
    A: float = 0.0           # force -A x^q of U = a|x|^n with 1 < n < 2 (A = a n/m, q = n - 1)
    q: float = 0.0

    @classmethod
    def of(cls, h: Harvester, M: int, frame: KinkFrame) -> KinkHierarchy:
        p = h.params
        if h.n != 1.0 and np.any(frame.shift != 0.0):
            raise ValueError(f"a frame shifted with v needs the constant kink force (n = 1), got n = {h.n!r}")
        hb = HermiteBasis(M, dim=2)
        L, s = frame.factor(h)
        Li = np.linalg.inv(L)
        b, c = frame.shift, frame.xshift
        g = np.array([-p.Kv, p.sigma])
        gamma_e = p.gamma - float(g @ b) / p.m
        kappa = float(g @ c) / p.m
        Bw = np.diag([-1.0 / p.tau_p, -1.0 / p.tau])
        Qw = np.diag([0.0, 2.0 * p.D / p.tau**2])
        Bz = Li @ Bw @ L - np.outer(Li @ b, g @ L) / p.m
        # w = L z + b v + c x, v' = -a/m - gamma_e v + kappa x + (s/m) z_1 (x > 0):
        # z' = Bz z + Li (Bw b + Kc e_V - c + gamma_e b) v + Li (Bw c - kappa b) x + Li b a/m + noise
        K0 = hb.generator(Bz, Li @ Qw @ Li.T) + hb.lowering(Li @ b * (h.a / p.m))
        K1 = hb.lowering(Li @ (Bw @ b + np.array([p.Kc, 0.0]) - c + gamma_e * b))
        K2 = hb.lowering(Li @ (Bw @ c - kappa * b)).tocsr()
        G = (s / p.m) * hb.multiply(0).toarray()
        lam, R = np.linalg.eigh(G)
        R[np.abs(R) < 1e-15] = 0.0
        par = hb.parity()
        return cls(hb, L, lam, R, R.T @ (K0 @ R), R.T @ (K1 @ R), R.T @ (par[:, None] * R),
                   K0.tocsr(), K1.tocsr(), K2, R.T @ (K2 @ R), -h.a / p.m if h.n == 1.0 else 0.0, gamma_e, kappa,
                   0.0 if h.n == 1.0 else h.a * h.n / p.m, h.n - 1.0)


@dataclass(frozen=True)
class KinkPlane:
    """Scalar DG matrices of the (x, v) mesh (x outer, v inner): see :func:`kink_plane`."""

    X: DGLine
    Vl: DGLine
    S_I: sp.csr_matrix       # x transport, the a0 part of v transport (mode independent)
    S_S: sp.csr_matrix       # mirror inflow at x = 0 (times the parity)
    S_K0: sp.csr_matrix      # -mass
    S_K1: sp.csr_matrix      # -mass * v
    S_K2: sp.csr_matrix      # -mass * x
    Mx: sp.csr_matrix
    Dv: sp.csr_matrix
    faces: list[tuple[float, sp.csr_matrix, sp.csr_matrix]]   # (v_j, up, down) per v node
    integrals: dict[str, np.ndarray]


def kink_plane(h: Harvester, mesh: PlaneMesh, p: int, gamma_e: float, kappa: float) -> KinkPlane:
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
    # the force -U'(x)/m on x > 0: -a/m at the kink, -(a n/m) x^(n-1) for 1 < n < 2
    Mf = (-h.a / m) * Mx if h.n == 1.0 else (-h.a * h.n / m) * X.power_mass(h.n - 1.0)
    S_I = (-sp.kron(Dx, Mvv) - sp.kron(Mf, Dv) + gamma_e * sp.kron(Mx, Dvv) - kappa * sp.kron(X.mass(power=1), Dv)
           + sp.kron(Xpos, Mv_up) + sp.kron(Xneg, Mv_dn))
    flip = sp.csr_matrix(np.fliplr(np.eye(Vl.size)))
    S_S = -sp.kron(lft, Mv_up @ flip)
    faces = []
    for j, vj in enumerate(Vl.nodes):
        tb, ta = Vl.left_of(j), Vl.right_of(j)
        faces.append((float(vj), sp.csr_matrix(np.outer(tb - ta, tb)), sp.csr_matrix(np.outer(tb - ta, ta))))
    Ix, Iv = X.integral(), Vl.integral()
    integrals = {"1": np.kron(Ix, Iv), "v": np.kron(Ix, Vl.integral(1)), "v2": np.kron(Ix, Vl.integral(2)),
                 "x2": np.kron(X.integral(2), Iv), "x": np.kron(X.integral(1), Iv),
                 "xv": np.kron(X.integral(1), Vl.integral(1))}
    return KinkPlane(X, Vl, S_I.tocsr(), S_S.tocsr(), -sp.kron(Mx, Mv).tocsr(), -sp.kron(Mx, Mvv).tocsr(),
                  -sp.kron(X.mass(power=1), Mv).tocsr(), Mx, Dv, faces, integrals)
