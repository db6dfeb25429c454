"""Normalized Hermite algebra of the linear variables (v, V, xi) and the whitening transform.

The density of one harvester is expanded in the linear variables :math:`y = (v, V, \\xi)`
around a Gaussian weight :math:`N(0, \\Sigma)`, :math:`\\Sigma = L L^T` (Cholesky, v first):

.. math::

    p(x, y) = \\sum_{|\\alpha| \\le M} c_\\alpha(x)\\, h_\\alpha(z)\\,\\phi(z), \\qquad
    z = L^{-1} y, \\qquad h_\\alpha(z) = \\prod_i \\frac{He_{\\alpha_i}(z_i)}{\\sqrt{\\alpha_i!}},

so that :math:`c_\\alpha(x) = \\int h_\\alpha(z) p(x, z)\\,dz` and :math:`c_0(x)` is the
x-marginal density. Projecting the Fokker--Planck equation on :math:`h_\\alpha` gives the
hierarchy (weak form, :math:`\\mathcal{A}` the backward generator)

.. math::

    \\partial_t c = -\\partial_x (F c) + (K_0 + u(x) K_1)\\, c, \\qquad u(x) = -U'(x)/m,

with the symmetric flux matrix :math:`F = L_{00} J_0` (:math:`J_0` multiplication by
:math:`z_0`, tridiagonal in :math:`\\alpha_0` because v is first in the Cholesky order),
:math:`K_0` from the linear drift and the noise, :math:`K_1` from the nonlinear force.
Truncation at total degree M drops :math:`c_\\beta` with :math:`|\\beta| = M + 1`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..model import Harvester

__all__ = ["HermiteBasis", "linear_drift", "equivalent_harmonic"]


def linear_drift(h: Harvester) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear part of the (v, V, xi) dynamics.

    Returns ``(B, e, Q)``: :math:`dy = (B y + e\\,u(x))\\,dt + \\text{noise}` with
    :math:`u(x) = -U'(x)/m` entering the v equation only (``e = (1, 0, 0)``) and noise
    covariance rate :math:`Q = \\mathrm{diag}(0, 0, 2D/\\tau^2)`.
    """
    p = h.params
    B = np.array(
        [
            [-p.gamma, -p.Kv / p.m, p.sigma / p.m],
            [p.Kc, -1.0 / p.tau_p, 0.0],
            [0.0, 0.0, -1.0 / p.tau],
        ]
    )
    Q = np.zeros((3, 3))
    Q[2, 2] = 2.0 * p.D / p.tau**2
    return B, np.array([1.0, 0.0, 0.0]), Q


@dataclass(frozen=True)
class HermiteBasis:
    """Total-degree-M index set of normalized Hermite functions in ``dim`` variables.

    Parameters
    ----------
    M : int
        Total degree, >= 2 (second moments must be resolved).
    dim : int
        Number of variables: 3 for (v, V, xi) of the 1-D solver, 2 for (V, xi) of the
        kink solver (:mod:`.schemes.xv.kink`).

    Examples
    --------
    >>> HermiteBasis(2).size
    10
    >>> HermiteBasis(2).index[(0, 0, 2)]
    9
    >>> HermiteBasis(2, dim=2).size
    6
    """

    M: int
    dim: int = 3

    def __post_init__(self) -> None:
        alphas = [a for deg in range(self.M + 1) for a in _compositions(deg, self.dim)]
        object.__setattr__(self, "alphas", np.array(alphas, dtype=int).reshape(-1, self.dim))
        object.__setattr__(self, "index", {a: i for i, a in enumerate(alphas)})

    @property
    def size(self) -> int:
        """Number of coefficients, :math:`\\binom{M+d}{d}`."""
        return len(self.alphas)

    def degree(self) -> np.ndarray:
        """Total degree of each index."""
        return self.alphas.sum(axis=1)

    def parity(self) -> np.ndarray:
        """:math:`(-1)^{|\\alpha|}` of each index: the sign of :math:`h_\\alpha(-z)/h_\\alpha(z)`."""
        return 1.0 - 2.0 * (self.degree() % 2)

    def _shift(self, alpha: tuple[int, ...], i: int, d: int) -> int | None:
        b = list(alpha)
        b[i] += d
        if b[i] < 0:
            return None
        return self.index.get(tuple(b))

    def multiply(self, i: int) -> sp.csr_matrix:
        """Matrix of :math:`c \\mapsto \\int z_i h_\\alpha p` (symmetric, truncated).

        :math:`z_i h_\\alpha = \\sqrt{\\alpha_i+1}\\,h_{\\alpha+e_i} + \\sqrt{\\alpha_i}\\,h_{\\alpha-e_i}`.
        """
        rows, cols, vals = [], [], []
        for r, al in enumerate(map(tuple, self.alphas)):
            for d, coef in ((1, math.sqrt(al[i] + 1)), (-1, math.sqrt(al[i]))):
                c = self._shift(al, i, d)
                if c is not None and coef != 0.0:
                    rows.append(r)
                    cols.append(c)
                    vals.append(coef)
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.size, self.size))

    def generator(self, Bz: np.ndarray, Qz: np.ndarray) -> sp.csr_matrix:
        """Matrix :math:`K_0` of the x-independent part of the generator.

        Row :math:`\\alpha` holds the coefficients of :math:`\\mathcal{A}_0 h_\\alpha` with
        :math:`\\mathcal{A}_0 = (B_z z)\\cdot\\nabla + \\tfrac12 Q_z : \\nabla\\nabla`, so that
        :math:`\\partial_t c_\\alpha \\ni \\sum_\\beta (K_0)_{\\alpha\\beta} c_\\beta`.
        """
        entries: dict[tuple[int, int], float] = {}

        def add(r: int, c: int | None, v: float) -> None:
            if c is not None and v != 0.0:
                entries[(r, c)] = entries.get((r, c), 0.0) + v

        for r, al in enumerate(map(tuple, self.alphas)):
            for i in range(self.dim):
                if al[i] == 0:
                    continue
                be = list(al)
                be[i] -= 1
                si = math.sqrt(al[i])
                for j in range(self.dim):
                    bij = Bz[i, j]
                    if bij != 0.0:
                        up = list(be)
                        up[j] += 1
                        add(r, self.index.get(tuple(up)), bij * si * math.sqrt(be[j] + 1))
                        if be[j] > 0:
                            dn = list(be)
                            dn[j] -= 1
                            add(r, self.index.get(tuple(dn)), bij * si * math.sqrt(be[j]))
                    qij = Qz[i, j]
                    if qij != 0.0 and be[j] > 0:
                        dn = list(be)
                        dn[j] -= 1
                        add(r, self.index.get(tuple(dn)), 0.5 * qij * si * math.sqrt(be[j]))
        if not entries:
            return sp.csr_matrix((self.size, self.size))
        keys = np.array(list(entries.keys()))
        return sp.csr_matrix(
            (np.array(list(entries.values())), (keys[:, 0], keys[:, 1])), shape=(self.size, self.size)
        )

    def lowering(self, g: np.ndarray) -> sp.csr_matrix:
        """Matrix :math:`K_1` of :math:`g\\cdot\\nabla_z h_\\alpha = \\sum_i g_i\\sqrt{\\alpha_i} h_{\\alpha-e_i}`."""
        rows, cols, vals = [], [], []
        for r, al in enumerate(map(tuple, self.alphas)):
            for i in range(self.dim):
                if al[i] > 0 and g[i] != 0.0:
                    rows.append(r)
                    cols.append(self._shift(al, i, -1))
                    vals.append(g[i] * math.sqrt(al[i]))
        return sp.csr_matrix((vals, (rows, cols)), shape=(self.size, self.size))

    def second_moment_weights(self, Lchol: np.ndarray) -> np.ndarray:
        """Weights ``W[i, j, :]`` with :math:`\\langle y_i y_j | x\\rangle = W_{ij}\\cdot c(x)/c_0(x)`.

        Uses :math:`z_k z_l = h_{e_k+e_l}` (k != l), :math:`z_k^2 = \\sqrt2 h_{2e_k} + 1` and
        :math:`y = L z`.
        """
        d = self.dim
        Wz = np.zeros((d, d, self.size))
        for k in range(d):
            for l in range(d):
                a = [0] * d
                a[k] += 1
                a[l] += 1
                if k == l:
                    Wz[k, k, self.index[tuple(a)]] = math.sqrt(2.0)
                    Wz[k, k, 0] = 1.0
                else:
                    Wz[k, l, self.index[tuple(a)]] = 1.0
        return np.einsum("ik,jl,klm->ijm", Lchol, Lchol, Wz)

    def first_moment_weights(self, Lchol: np.ndarray) -> np.ndarray:
        """Weights ``w[i, :]`` with :math:`\\langle y_i | x\\rangle = w_i\\cdot c(x)/c_0(x)`."""
        wz = np.zeros((self.dim, self.size))
        for k in range(self.dim):
            a = [0] * self.dim
            a[k] = 1
            wz[k, self.index[tuple(a)]] = 1.0
        return Lchol @ wz


def _compositions(total: int, parts: int) -> list[tuple[int, ...]]:
    """Tuples of ``parts`` non-negative integers summing to ``total``, first entry descending."""
    if parts == 1:
        return [(total,)]
    return [(first, *rest) for first in range(total, -1, -1) for rest in _compositions(total - first, parts - 1)]


def equivalent_harmonic(h: Harvester) -> tuple[float, np.ndarray]:
    """Stiffness and stationary covariance of the equivalent harmonic unit (statistical linearization).

    The stiffness :math:`\\kappa` of an equivalent harmonic unit is the root of the mismatch

    .. math::

        \\mu(\\kappa) = \\ln\\frac{\\langle x U'(x)\\rangle}{\\kappa\\langle x^2\\rangle}
        = \\ln c_n + (\\tfrac n2 - 1)\\ln s^2(\\kappa) - \\ln\\kappa,

    with x Gaussian of the harmonic variance :math:`s^2 = \\langle x^2\\rangle(\\kappa)`; for
    :math:`U = a|x|^n`, :math:`\\langle xU'\\rangle = c_n s^n`,
    :math:`c_n = a n\\,2^{n/2}\\Gamma(\\tfrac{n+1}{2})/\\sqrt\\pi`. :math:`\\mu` decreases
    monotonically and tends to :math:`+\\infty` as :math:`\\kappa \\to 0`. As
    :math:`\\kappa \\to \\infty` the harmonic unit becomes quasi-static,
    :math:`s \\approx F_{rms}/\\kappa` (F the drive), so :math:`\\mu \\sim (1 - n)\\ln\\kappa`
    and a root exists for n > 1. For n = 1 the limit is the constant
    :math:`\\ln(a\\sqrt{2/\\pi}/F_{rms})`, positive when the constant restoring force exceeds
    the rms drive (the mass mostly sits at the kink): there is no root, and the
    statistical linearization only says "stiffer than any finite kappa".

    In that case :math:`\\kappa` minimizes :math:`\\mu` on a bounded interval: the smallest
    stiffness at which :math:`\\mu` is within 0.01 of its infimum, i.e. beyond which any
    further stiffening changes the matched moment ratio by less than 1 %. Every larger
    :math:`\\kappa` is equally (in)consistent, and the smallest keeps the widest Gaussian
    weight in (v, V), the safe side for the Hermite expansion. The choice only sets the
    weight and the domain; the refinement measures the resulting accuracy.

    Returns
    -------
    kappa : float
        Equivalent stiffness (``2a`` for n = 2), > 0 and finite for every a > 0, n >= 1.
    P : ndarray (4, 4)
        Stationary covariance of (x, v, V, xi) of the harmonic unit with that stiffness.
    """
    from scipy.optimize import brentq

    from ..exact import lyapunov_covariance
    from ..exact.moments import closure_mismatch

    a, n = h.a, h.n

    def mismatch(log_kappa: float) -> float:
        return closure_mismatch(h, log_kappa)

    if n == 2.0:
        kappa = 2.0 * a
    else:
        kappa = math.exp(_equivalent_log_stiffness(mismatch, math.log(2.0 * a), brentq))
    return kappa, lyapunov_covariance(kappa, h.params)


#: Search window in ln(kappa) around ln(2a), and the flatness criteria of the fallback.
_SEARCH_DECADES = 40.0
_FLAT_STEP = 1e-4
_FLAT_GAP = 0.01
#: ln of the largest stiffness the search tries (below the largest double, ~709.8).
_LOG_MAX = 700.0


def _equivalent_log_stiffness(mismatch: Callable[[float], float], start: float,
                              brentq: Callable[..., float]) -> float:
    """Root of the decreasing ``mismatch`` in ln(kappa), or the bounded minimizer if none.

    The search stays within ``start +- _SEARCH_DECADES`` e-folds (the closed-form moments
    stay finite there); see :func:`equivalent_harmonic` for the fallback.
    """
    # Infimum of mu: reached (to _FLAT_STEP) at the far end of the window only when n = 1.
    far = min(start + _SEARCH_DECADES, _LOG_MAX)
    m_far = mismatch(far)
    flat = abs(mismatch(far - 2.0) - m_far) < _FLAT_STEP
    # Stop at the root, or where mu comes within _FLAT_GAP of a flat infimum if that is
    # reached first (continuous in a across the threshold of the no-root case).
    target = max(m_far + _FLAT_GAP, 0.0) if flat else 0.0
    lo, hi = start - 1.0, start + 1.0
    while mismatch(lo) < target and lo > start - _SEARCH_DECADES:
        lo -= 2.0
    while mismatch(hi) > target and hi < far:
        hi += 2.0
    if mismatch(lo) <= target:
        return lo
    if mismatch(hi) >= target:
        return hi
    return brentq(lambda t: mismatch(t) - target, lo, hi, xtol=1e-12)
