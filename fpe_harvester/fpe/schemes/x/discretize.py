"""One discretization level: build the Hermite-DG system, solve it, read off the moments.

A level is fixed by the Hermite degree M, the mesh and the polynomial order p. The
stationary coefficients solve :math:`A c = 0` (see :mod:`...assemble`) with the density's
normalization :math:`\\int c_0\\,dx = 1`. The operator is nonsingular only through the
(exponentially small) outflow at :math:`\\pm L`, so two steps of inverse iteration from
:math:`b_{i0} = \\int\\psi_i\\,dx` give the null vector up to that outflow; it is then
rescaled to unit mass.

The problem is mirror-symmetric: the force :math:`-U'(x)` is odd and everything else is
linear, so the stationary density is invariant under :math:`(x, y) \\to (-x, -y)`, and with
a weight centred on :math:`b x` the coefficients obey
:math:`c_\\alpha(-x) = (-1)^{|\\alpha|} c_\\alpha(x)`. The stationary levels are solved on
the half mesh :math:`[0, L]` with that reflection as the inflow condition at 0
(:func:`~...assemble.dg_operator`): half the unknowns, and on a mirror-symmetric mesh the
same discrete solution as the full mesh (the full discrete problem has the same symmetry
and a unique solution). The second moments are even, so their half-domain integrals
normalized by the half-domain mass are the full-domain values.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
from skfem import Basis

from ....model import Harvester, Potential
from ...assemble import XMatrices, assemble_x, dg_element, dg_operator, upwind_parts
from ...blocksolve import BlockTridiagonal
from ...hermite import HermiteBasis, equivalent_harmonic, linear_drift
from ...moments import conditional_fields, harvester_moments
from ...protocol import Discretization
from .mesh import XMesh

__all__ = ["Whitening", "Level", "solve_level", "assemble_level", "hierarchy_matrices", "x_matrices",
           "level_moments", "HermiteDG", "level_gigabytes", "block_size", "clear_x_cache",
           "DEGREES_PER_ELEMENT"]

#: Noise correlation time from which the weight's centre of xi follows the force
#: (:meth:`Whitening.of`, ``curved``; n > 2; the measurements are in its docstring).
CURVED_TAU = 10.0

#: Highest Hermite degree per element of the half mesh. Beyond it the levels are not
#: resolved and may be wrong while looking physical (docs/methods.md, Fokker-Planck design notes).
DEGREES_PER_ELEMENT = 1.5

#: What a user can do when no level of scheme x gives an error estimate.
ADVICE = ("the Hermite expansion around the equivalent harmonic unit does not resolve this "
          "density; use method='mc', or fix M and elements to inspect the levels")


@dataclass(frozen=True)
class Whitening:
    """Gaussian weight of the Hermite expansion and the derived domain scales.

    Attributes
    ----------
    Sigma : ndarray (3, 3)
        Covariance of the Gaussian weight in (v, V, xi): the conditional covariance given x
        of the equivalent harmonic unit (or its marginal covariance if not conditional).
    chol : ndarray (3, 3)
        Its lower Cholesky factor L (v first).
    kappa, x2 : float
        Equivalent stiffness and its :math:`\\langle x^2\\rangle`.
    shift : ndarray (3,)
        Regression of (v, V, xi) on x, :math:`b = \\langle x y\\rangle / \\langle x^2\\rangle`
        (:math:`b_v = 0`: :math:`\\langle x v\\rangle = 0` in a stationary state). The weight
        is centred on :math:`b x`, the conditional mean of the equivalent harmonic unit.
    curve : ndarray (3,)
        c: the weight's centre follows the force, :math:`b x + c\\,\\psi(x)` with
        :math:`\\psi(x) = U'(x)/\\kappa - x` (zero for n = 2; default c = 0: centred on b x).
        With :math:`c = b_\\xi e_\\xi` the centre of xi is :math:`b_\\xi U'(x)/\\kappa`, which for
        slow noise (:math:`\\tau \\gg 1/\\gamma`) is the quasi-static force balance
        :math:`\\sigma\\xi \\approx U'(x)`, where a centre linear in x is off by many
        conditional standard deviations at the walls.
    potential : Potential or None
        The potential of a curved centre (None when ``curve`` is zero).

    Notes
    -----
    Centring the weight on the conditional mean is what makes the Hermite expansion short:
    for n = 2 the stationary density is exactly :math:`c_0(x)\\,\\phi(z)` (all other
    coefficients vanish), and for a nonlinear unit the conditional law of (v, V, xi) given x
    stays close to it. With the marginal weight (``shift = 0``) the coefficients of a
    density whose conditional mean moves with x decay only like :math:`\\mu^k/\\sqrt{k!}`,
    :math:`\\mu \\propto x`, slowly in the tails.
    """

    Sigma: np.ndarray
    chol: np.ndarray
    kappa: float
    x2: float
    shift: np.ndarray = field(default_factory=lambda: np.zeros(3))
    curve: np.ndarray = field(default_factory=lambda: np.zeros(3))
    potential: Potential | None = None

    @classmethod
    def of(cls, h: Harvester, conditional: bool | None = None, curved: bool | None = None) -> Whitening:
        """Weight of harvester ``h``: conditional on x or marginal.

        ``conditional=None`` picks the measured better choice: conditional for
        :math:`2 \\le n \\le 4`, marginal otherwise (a mean linear in x is a poor guess at
        steep walls and at a strong kink).

        ``curved`` centres xi on :math:`b_\\xi U'(x)/\\kappa` instead of :math:`b_\\xi x`
        (``curve``; n > 2 only, and then the weight is conditional unless ``conditional=False``).
        ``None`` picks it for slow noise, :math:`\\tau \\ge` :data:`CURVED_TAU`, where xi is
        quasi-static and follows the force; at tau = 1 both centres give the same eta and the
        linear one stays the default (docs/methods.md, Fokker-Planck design notes).
        """
        kappa, P = equivalent_harmonic(h)
        x2 = float(P[0, 0])
        if curved is None:
            curved = h.params.tau >= CURVED_TAU
        curved = curved and h.n > 2.0
        if conditional is None:
            conditional = 2.0 <= h.n <= 4.0 or curved
        if not conditional:
            Sigma = P[1:, 1:].copy()
            return cls(Sigma, np.linalg.cholesky(Sigma), kappa, x2)
        b = P[1:, 0] / x2
        # <x v> = 0 exactly in a stationary state; drop its round-off so v = L_00 z_0 stays
        # the transport variable (F tridiagonal in the v index).
        b[0] = 0.0
        cond = P[1:, 1:] - np.outer(b, b) * x2
        c = np.array([0.0, 0.0, b[2]]) if curved else np.zeros(3)
        return cls(cond, np.linalg.cholesky(cond), kappa, x2, b, c, h.potential if np.any(c) else None)

    def __post_init__(self) -> None:
        object.__setattr__(self, "shift", np.asarray(self.shift, dtype=float))
        object.__setattr__(self, "curve", np.asarray(self.curve, dtype=float))
        if np.any(self.curve != 0.0) and self.potential is None:
            raise ValueError("a curved centre (curve != 0) needs the potential")

    @property
    def curved(self) -> bool:
        """True if the centre follows the force (``curve`` not zero)."""
        return bool(np.any(self.curve != 0.0))

    def psi(self, x: np.ndarray) -> np.ndarray:
        """:math:`\\psi(x) = U'(x)/\\kappa - x`, the part of the centre not linear in x (zero
        where the centre is not curved)."""
        x = np.asarray(x, dtype=float)
        if self.potential is None:
            return np.zeros_like(x)
        return self.potential.dU(x) / self.kappa - x

    @property
    def temperature(self) -> float:
        """Effective temperature :math:`T_{eff} = \\kappa\\langle x^2\\rangle`."""
        return self.kappa * self.x2

    def half_width(self, h: Harvester, domain: float) -> float:
        """Half-width L of the x domain with :math:`U(L) = \\Theta T_{eff}`, :math:`\\Theta` = ``domain``."""
        return (domain * self.temperature / h.a) ** (1.0 / h.n)


def hierarchy_matrices(h: Harvester, M: int, w: Whitening) -> tuple[HermiteBasis, np.ndarray, sp.csr_matrix,
                                                                      sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
    """Hermite basis and the matrices ``F, K0, K1, K2, K3`` of the hierarchy at degree M.

    The expansion variable is :math:`z = L^{-1}(y - b x - c\\,\\psi(x))` (``w.shift`` = b,
    ``w.curve`` = c, :math:`b_v = c_v = 0`, :math:`\\psi = U'/\\kappa - x = -m u/\\kappa - x`).
    From :math:`\\dot y = B y + e\\,u(x)` + noise and :math:`\\dot x = v = e_v^T y`,

    .. math::

        \\dot z = L^{-1}(B - b e_v^T) L\\, z + L^{-1}(e - \\tfrac{m}{\\kappa} B c)\\, u(x)
        + L^{-1} B (b - c)\\, x - \\psi'(x)\\, L^{-1} c\\, e_v^T L\\, z + \\text{noise},

    so :math:`B_z = L^{-1}(B - b e_v^T) L`, :math:`Q_z = L^{-1} Q L^{-T}`, the nonlinear
    force enters along :math:`L^{-1}(e - \\tfrac{m}{\\kappa} B c)` (``K1``, multiplied by u(x)),
    the shift along :math:`L^{-1} B (b - c)` (``K2``, multiplied by x), the curved centre as
    the linear drift :math:`-L^{-1} c\\, e_v^T L` (``K3``, multiplied by
    :math:`\\psi'(x) = -\\tfrac{m}{\\kappa} u'(x) - 1`), and :math:`v = L_{00} z_0` gives the
    flux matrix :math:`F = L_{00} J_0`. With ``b = c = 0``, ``K2`` and ``K3`` are zero.
    """
    hb = HermiteBasis(M)
    B, e, Q = linear_drift(h)
    Li = np.linalg.inv(w.chol)
    b, c = w.shift, w.curve
    ev = np.array([1.0, 0.0, 0.0])
    r = h.params.m / w.kappa
    F = w.chol[0, 0] * hb.multiply(0).toarray()
    K0 = hb.generator(Li @ (B - np.outer(b, ev)) @ w.chol, Li @ Q @ Li.T)
    K1 = hb.lowering(Li @ (e - r * B @ c))
    K2 = hb.lowering(Li @ B @ (b - c))
    K3 = hb.generator(-Li @ np.outer(c, ev) @ w.chol, np.zeros((3, 3))) if w.curved else sp.csr_matrix((hb.size,) * 2)
    return hb, F, K0, K1, K2, K3


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

    @property
    def half(self) -> bool:
        """True if ``coef`` and ``xmat`` live on the half mesh :math:`[0, L]`; the solution
        on :math:`x < 0` is then the mirror image :math:`c_\\alpha(-x) = (-1)^{|\\alpha|}c_\\alpha(x)`."""
        return self.xmat.xreflect is not None

    @property
    def size(self) -> int:
        """The refinement's mesh knob: elements per half (nominal on an adapted mesh,
        :attr:`~.mesh.XMesh.size`)."""
        return self.mesh.size

    @property
    def elements(self) -> int:
        return self.mesh.elements

    @property
    def half_width(self) -> float:
        """Half-width L of the domain."""
        return self.mesh.L

    def fields(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """x-marginal density :math:`c_0(x)` and conditional means
        :math:`\\langle y|x\\rangle = \\sum_\\alpha w_{y\\alpha} c_\\alpha(x)/c_0(x)` plus the
        weight's centre :math:`b x + c\\,\\psi(x)`, y = v, V, xi, at points ``x`` (clipped to [-L, L])."""
        X = self.xmat
        x = np.clip(np.asarray(x, dtype=float), -self.mesh.L, self.mesh.L)
        # A fresh element: ElementLinePp caches reference values by array shape only.
        basis = Basis(X.basis.mesh, dg_element(self.order), intorder=2 * self.order + 6)
        probe = basis.probes(np.atleast_2d(np.abs(x) if self.half else x))
        u = np.zeros((basis.N, self.coef.shape[1]))
        u[X.perm] = self.coef
        vals = probe @ u
        if self.half:
            # Mirror image on x < 0: c_alpha(-x) = (-1)^|alpha| c_alpha(x).
            vals = np.where((x < 0.0)[:, None], vals * self.hermite.parity(), vals)
        num = vals @ self.hermite.first_moment_weights(self.whitening.chol).T
        w = self.whitening
        centre = np.multiply.outer(x, w.shift) + np.multiply.outer(w.psi(x), w.curve)
        names = ("v_mean", "V_mean", "xi_mean")
        return conditional_fields(vals[:, 0], {k: num[:, i] for i, k in enumerate(names)},
                                  {k: centre[:, i] for i, k in enumerate(names)})

    def info(self) -> dict[str, Any]:
        """Discretization details for the result's ``info``."""
        return {"scheme": "x", "M": self.M, "order": self.order, "elements": self.mesh.elements,
                "L": self.mesh.L, "dofs": self.dofs, "kappa_eq": self.whitening.kappa}

    def summary(self) -> dict[str, Any]:
        """JSON-ready description (for the refinement history)."""
        return {
            "M": self.M, "order": self.order, "elements": self.mesh.elements, "dofs": self.dofs,
            "seconds": round(self.seconds, 4), "eta": self.moments["eta"], "V2": self.moments["V2"],
            "Pin": self.moments["Pin"],
        }


def assemble_level(h: Harvester, M: int, mesh: XMesh, order: int, w: Whitening, half: bool = False
                   ) -> tuple[HermiteBasis, np.ndarray, XMatrices, sp.csr_matrix, tuple[np.ndarray, np.ndarray]]:
    """Hermite basis, flux matrix F, scalar x-matrices, the global DG operator A and the
    upwind parts :math:`(F^+, F^-)` of one level, on the whole mesh or (``half``) on
    :math:`[0, L]` with the mirror condition at 0."""
    hb, F, K0, K1, K2, K3 = hierarchy_matrices(h, M, w)
    X = x_matrices(h, mesh, order, half, curved=w.curved)
    parity = hb.parity() if half else None
    upwind = upwind_parts(F)
    curve = (-h.params.m / w.kappa, K3) if w.curved else None
    return hb, F, X, dg_operator(X, F, K0, K1, K2, parity, upwind, K3=curve), upwind


#: Scalar DG matrices of recently used (mesh, order, potential): the refinement solves
#: several Hermite degrees on one mesh. Small and first-in first-out.
_X_CACHE: dict[tuple[Any, ...], XMatrices] = {}
_X_CACHE_SIZE = 16
_X_LOCK = threading.Lock()  # scenes may solve points in threads


def x_matrices(h: Harvester, mesh: XMesh, order: int, half: bool = False, curved: bool = False) -> XMatrices:
    """:func:`~...assemble.assemble_x` for the force :math:`-U'(x)/m` of ``h``, cached (read-only);
    on the half mesh :math:`[0, L]` with a mirror at 0 if ``half``; with the matrices of a
    weight whose centre follows the force if ``curved`` (:math:`u' = -U''/m`, n > 2)."""
    nodes = mesh.half_nodes() if half else mesh.nodes()
    key = (nodes.tobytes(), order, h.potential, h.params.m, half, mesh.geometric, curved)
    with _X_LOCK:
        X = _X_CACHE.get(key)
    if X is None:
        m, pot = h.params.m, h.potential
        # On geometric layers the force |x|^(n-1) is integrated by Gauss-Jacobi on the
        # element at 0 and by a longer Gauss-Legendre rule on the layers, whose ends are
        # 1/ratio apart (x^(n-1) is far from a polynomial there).
        singular = h.n - 1.0 if mesh.geometric and h.n != round(h.n) else None
        a, n = pot.a, pot.n
        du = (lambda x: -a * n * (n - 1.0) * np.abs(x) ** (n - 2.0) / m) if curved else None
        X = assemble_x(nodes, order, lambda x: -pot.dU(x) / m, reflect=half, singular=singular,
                       intorder=2 * order + 16 if mesh.geometric else None, du=du)
        with _X_LOCK:
            while len(_X_CACHE) >= _X_CACHE_SIZE:
                _X_CACHE.pop(next(iter(_X_CACHE)))
            _X_CACHE[key] = X
    return X


def clear_x_cache() -> None:
    """Empty the cache of :func:`x_matrices` (benchmarks time the assembly too)."""
    with _X_LOCK:
        _X_CACHE.clear()


def level_moments(h: Harvester, X: XMatrices, hb: HermiteBasis, C: np.ndarray, w: Whitening) -> dict[str, float]:
    """The moments of coefficients ``C`` (unit mass; :func:`~...moments.harvester_moments`).

    On a half mesh the (even) integrands count once more from the mirror image.
    """
    p = h.params
    C = X.copies * C
    # y = y' + b x + c psi(x) with y' = L z and psi = -r u - x (r = m / kappa):
    # <y y^T> = <y' y'^T> + (s y'^T + y' s^T) + <s s^T>, s = (b - c) x - r c u.
    W = hb.second_moment_weights(w.chol)
    Y = np.einsum("ijm,km->ijk", W, C) @ X.integral
    w1 = hb.first_moment_weights(w.chol)
    b = w.shift - w.curve
    xy = w1 @ (C.T @ X.x1)
    Y = Y + np.outer(b, xy) + np.outer(xy, b) + np.outer(b, b) * float(C[:, 0] @ X.x2)
    if w.curved:
        r = p.m / w.kappa
        cu = -r * w.curve
        uy = w1 @ (C.T @ X.u1)
        Y = (Y + np.outer(cu, uy) + np.outer(uy, cu) + np.outer(cu, cu) * float(C[:, 0] @ X.u2)
             + (np.outer(b, cu) + np.outer(cu, b)) * float(C[:, 0] @ X.xu))
    return harvester_moments(p, Y[0, 0], Y[0, 1], Y[0, 2], Y[1, 1], float(C[:, 0] @ X.x2))


def solve_level(h: Harvester, M: int, mesh: XMesh, order: int, w: Whitening, half: bool = True) -> Level:
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
    half : bool
        Solve on the half mesh with the mirror condition at 0 (default; the same numbers as
        the whole mesh, see the module docstring, at half the cost).
    """
    t0 = time.perf_counter()
    hb, F, X, A, (Fp, Fm) = assemble_level(h, M, mesh, order, w, half)
    na = hb.size
    # Inverse iteration for the generalized problem A c = lambda (M_x (x) I) c: A is
    # nonsingular only through the outflow at +-L, whose eigenvalue lambda_0 is exponentially
    # small, and the stationary density is its eigenvector (the quasi-stationary density of
    # the truncated domain). The start b = (int psi_i dx) on alpha = 0 (the mass matrix times
    # c_0 = 1) has a component along the left null vector (the alpha = 0 test of psi = 1)
    # whatever the shape of the density, unlike pinning one value (ill-conditioned where the
    # true c_0 is small, e.g. quasi-static drives with a density minimum at x = 0). Each step
    # damps the other modes by lambda_0/lambda_1; the second costs one more solve with the
    # same factorization (it matters only for small domains: at Theta = 12 the first step
    # leaves 1e-6 in V2).
    rhs = np.zeros((X.integral.size, na))
    rhs[:, 0] = X.integral
    # Neighbouring elements couple only through the face terms X_+ (x) F^+ and X_- (x) F^-.
    solver = BlockTridiagonal(A, (order + 1) * na, kron=[(X.xplus, Fp), (X.xminus, Fm)])
    C = solver.solve(rhs.ravel()).reshape(-1, na)
    C /= max(float(np.abs(C).max()), 1e-300)
    C = solver.solve((X.mass @ C).ravel()).reshape(-1, na)
    mass = float(C[:, 0] @ X.integral)
    scale = float(np.abs(C[:, 0]) @ np.abs(X.integral))
    if not (math.isfinite(mass) and math.isfinite(scale)) or abs(mass) <= 1e-8 * scale:
        raise FloatingPointError(f"degenerate stationary solution at M = {M} (mass {mass}, "
                                 f"integral of |c_0| {scale})")
    # Unit mass on the whole domain (a half mesh holds half of it).
    C /= X.copies * mass
    moments = level_moments(h, X, hb, C, w)
    return Level(M, order, mesh, C, moments, A.shape[0], time.perf_counter() - t0, X, hb, w)


def block_size(M: int, order: int) -> int:
    """Unknowns per element, :math:`n_b = (p + 1)\\binom{M+3}{3}`."""
    return (order + 1) * math.comb(M + 3, 3)


def level_gigabytes(M: int, half_elements: int, order: int) -> float:
    """Memory (GB) of one level's factorization: the dense LU of every element block of the
    half mesh (:math:`N_h n_b^2` doubles) plus half as much again for the coupling solves,
    the sparse operator and temporaries, plus 0.2 GB (measured peaks: 0.45 GB at M = 12 and
    1.58 GB at M = 16 with 8 elements per half, predicted 0.62 and 1.64)."""
    nb = block_size(M, order)
    return 1.5 * half_elements * nb * nb * 8 / 1e9 + 0.2


@dataclass(frozen=True)
class HermiteDG(Discretization):
    """The 1-D discretization as seen by the refinement (:class:`~fpe_harvester.fpe.protocol.Discretization`):
    Hermite functions of (v, V, xi) times DG in x on ``base`` with ``size`` elements per half."""

    h: Harvester
    base: XMesh
    order: int
    w: Whitening
    work_exponents: tuple[float, float] = (2.0, 3.0)
    mesh_check_degree: int = 6
    advice: str = ADVICE

    @property
    def algebraic(self) -> bool:
        return self.h.n < 2.0

    def solve(self, M: int, size: int, lower: Any = None) -> Level:
        return solve_level(self.h, M, self.base.with_elements(size), self.order, self.w)

    def unknowns(self, M: int, size: int) -> int:
        """Unknowns of the whole mesh (twice those of the half mesh that is solved)."""
        return 2 * (size + self.base.layers) * block_size(M, self.order)

    def gigabytes(self, M: int, size: int) -> float:
        return level_gigabytes(M, size + self.base.layers, self.order)

    def max_degree(self, size: int) -> int:
        return int(DEGREES_PER_ELEMENT * size)

    def work(self, M: int, size: int) -> tuple[float, float]:
        return float(size + self.base.layers), float(block_size(M, self.order))

    def describe(self, size: int) -> str:
        return f"{2 * (size + self.base.layers)} elements"
