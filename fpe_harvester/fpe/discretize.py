"""One discretization level: build the Hermite-DG system, solve it, read off the moments.

A level is fixed by the Hermite degree M, the mesh and the polynomial order p. The
stationary coefficients solve :math:`A c = 0` (see :mod:`.assemble`) with the density's
normalization :math:`\\int c_0\\,dx = 1`. The operator is nonsingular only through the
(exponentially small) outflow at :math:`\\pm L`, so one step of inverse iteration,
:math:`c = A^{-1} b` with :math:`b_{i0} = \\int\\psi_i\\,dx`, gives the null vector up to
that outflow; it is then rescaled to unit mass.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..model import Harvester
from .assemble import XMatrices, assemble_x, dg_operator
from .blocksolve import BlockTridiagonal
from .hermite import HermiteBasis, linear_drift, whitening_covariance
from .mesh import XMesh

__all__ = ["Whitening", "Level", "solve_level", "hierarchy_matrices"]


@dataclass(frozen=True)
class Whitening:
    """Gaussian weight of the Hermite expansion and the derived domain scales.

    Attributes
    ----------
    Sigma : ndarray (3, 3)
        Covariance of (v, V, xi) of the equivalent harmonic unit.
    chol : ndarray (3, 3)
        Its lower Cholesky factor L (v first).
    kappa, x2 : float
        Equivalent stiffness and its :math:`\\langle x^2\\rangle`.
    """

    Sigma: np.ndarray
    chol: np.ndarray
    kappa: float
    x2: float

    @classmethod
    def of(cls, h: Harvester) -> Whitening:
        Sigma, kappa, x2 = whitening_covariance(h)
        return cls(Sigma, np.linalg.cholesky(Sigma), kappa, x2)

    @property
    def temperature(self) -> float:
        """Effective temperature :math:`T_{eff} = \\kappa\\langle x^2\\rangle`."""
        return self.kappa * self.x2

    def domain(self, h: Harvester, theta: float) -> float:
        """Half-width L with :math:`U(L) = \\Theta T_{eff}`."""
        return (theta * self.temperature / h.a) ** (1.0 / h.n)


def hierarchy_matrices(h: Harvester, M: int, w: Whitening) -> tuple[HermiteBasis, np.ndarray, sp.csr_matrix,
                                                                      sp.csr_matrix]:
    """Hermite basis and the matrices ``F, K0, K1`` of the hierarchy at degree M.

    In whitened coordinates :math:`z = L^{-1} y`: :math:`B_z = L^{-1} B L`,
    :math:`Q_z = L^{-1} Q L^{-T}`, the nonlinear force enters along :math:`g = L^{-1} e_v`,
    and :math:`v = L_{00} z_0` gives the flux matrix :math:`F = L_{00} J_0`.
    """
    hb = HermiteBasis(M)
    B, e, Q = linear_drift(h)
    Li = np.linalg.inv(w.chol)
    F = w.chol[0, 0] * hb.multiply(0).toarray()
    K0 = hb.generator(Li @ B @ w.chol, Li @ Q @ Li.T)
    K1 = hb.lowering(Li @ e)
    return hb, F, K0, K1


@dataclass(frozen=True)
class Level:
    """Solution of one discretization level.

    Attributes
    ----------
    M, order : int
        Hermite degree and DG polynomial order.
    mesh : XMesh
        The x mesh.
    coef : ndarray (ndofs_x, n_alpha)
        Coefficients :math:`c_\\alpha` at every x dof (element-major).
    moments : dict
        ``V2, Pin, eta, v2, vV, vxi, x2`` and the identity residuals ``res_V2`` and
        ``res_power`` (relative).
    dofs : int
        Number of unknowns.
    seconds : float
        Wall time of assembly and solve.
    """

    M: int
    order: int
    mesh: XMesh
    coef: np.ndarray
    moments: dict[str, float]
    dofs: int
    seconds: float
    xmat: XMatrices = field(repr=False)
    hermite: HermiteBasis = field(repr=False)
    whitening: Whitening = field(repr=False)

    def summary(self) -> dict[str, Any]:
        """JSON-ready description (for the refinement history)."""
        return {
            "M": self.M, "order": self.order, "elements": self.mesh.elements, "dofs": self.dofs,
            "seconds": round(self.seconds, 4), "eta": self.moments["eta"], "V2": self.moments["V2"],
            "Pin": self.moments["Pin"],
        }


def _moments(h: Harvester, X: XMatrices, hb: HermiteBasis, C: np.ndarray, w: Whitening) -> dict[str, float]:
    p = h.params
    W = hb.second_moment_weights(w.chol)
    Y = np.einsum("ijm,km->ijk", W, C) @ X.integral
    v2, vV, vxi, V2 = Y[0, 0], Y[0, 1], Y[0, 2], Y[1, 1]
    Pin = p.sigma * vxi
    res_V2 = (V2 - p.Kc * p.tau_p * vV) / V2
    res_power = (Pin - p.m * p.gamma * v2 - p.Kv * vV) / Pin
    return {
        "V2": float(V2), "Pin": float(Pin), "eta": float(V2 / (p.R * Pin)), "v2": float(v2),
        "vV": float(vV), "vxi": float(vxi), "x2": float(C[:, 0] @ X.x2),
        "res_V2": float(res_V2), "res_power": float(res_power),
    }


def solve_level(h: Harvester, M: int, mesh: XMesh, order: int, w: Whitening) -> Level:
    """Assemble and solve one level (block-tridiagonal elimination over the elements).

    Parameters
    ----------
    h : Harvester
        A single unit (N = 1).
    M : int
        Hermite total degree, >= 2.
    mesh : XMesh
        The x mesh (a node at 0).
    order : int
        DG polynomial order p.
    w : Whitening
        The Gaussian weight.
    """
    t0 = time.perf_counter()
    hb, F, K0, K1 = hierarchy_matrices(h, M, w)
    m = h.params.m
    pot = h.potential
    X = assemble_x(mesh.nodes(), order, lambda x: -pot.dU(x) / m)
    na = hb.size
    A = dg_operator(X, F, K0, K1).tocsr()
    # One step of inverse iteration: A is nonsingular only through the outflow at +-L, so
    # A^{-1} b is the stationary density up to O(outflow) for any b with a component along
    # the left null vector (the alpha = 0 test of psi = 1). b = (int psi_i dx) on alpha = 0
    # has the component 2L > 0 whatever the shape of the density, unlike pinning one value
    # (ill-conditioned where the true c_0 is small, e.g. quasi-static drives with a density
    # minimum at x = 0).
    rhs = np.zeros((X.integral.size, na))
    rhs[:, 0] = X.integral
    solver = BlockTridiagonal(A, (order + 1) * na)
    C = solver.solve(rhs.ravel()).reshape(-1, na)
    mass = float(C[:, 0] @ X.integral)
    scale = float(np.abs(C[:, 0]) @ np.abs(X.integral))
    if not (math.isfinite(mass) and math.isfinite(scale)) or abs(mass) <= 1e-8 * scale:
        raise FloatingPointError(f"degenerate stationary solution at M = {M} (mass {mass}, "
                                 f"integral of |c_0| {scale})")
    C /= mass
    moments = _moments(h, X, hb, C, w)
    return Level(M, order, mesh, C, moments, A.shape[0], time.perf_counter() - t0, X, hb, w)
