r"""The W variant of the candidate kink scheme (:mod:`.xvw`): the third coordinate is
:math:`W = V - K_c x` instead of V.

In (x, v, W) the transport velocity of xi-mode i is

.. math::

    \bigl(v,\ f_i - \gamma v - (K_v/m)(W + K_c x),\ -(W + K_c x)/\tau_p\bigr),
    \qquad f_i = (-a + \sigma\lambda_i)/m,

so W's speed no longer depends on v (it is linear in x), and v's speed is linear in x and W
together. The upwind fluxes on the W faces are exact (each x element split at the root of
the speed); on the v faces the speed's root is a line across each (x, W) rectangle: the
integral over W is exact (split at the root) and the one over x uses Gauss--Legendre with
``2p + 10`` points. Deep in the trap x is negligible next to V (x ~ E, V ~ E^(3/4)) and W is
V; in the bulk W is narrower than V (measured with the event-driven simulator). The
mirror at x = 0 is the same as V's (W = V there).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.polynomial import legendre as npleg

from fpe_harvester.fpe.plane import DGLine, lobatto_points
from fpe_harvester.model import Harvester

__all__ = ["transport_w", "moments_w", "kron_middle", "kron3"]


def kron3(a: sp.spmatrix, b: sp.spmatrix, c: sp.spmatrix) -> sp.csr_matrix:
    """Kronecker product of three sparse matrices (a outer, c inner)."""
    return sp.kron(a, sp.kron(b, c, format="csr"), format="csr")


def kron_middle(B: sp.spmatrix, F: sp.spmatrix, n_inner: int) -> sp.csr_matrix:
    """The matrix with entries ``B[(ix, iW), (jx, jW)] * F[iv, jv]`` in the ordering
    (x outer, v middle, W inner): ``B`` acts on (x, W) (W inner, ``n_inner`` unknowns), ``F`` on v."""
    B, F = B.tocoo(), F.tocoo()
    nv = F.shape[0]
    bx, bw = np.divmod(B.row, n_inner)
    cx, cw = np.divmod(B.col, n_inner)
    rows = ((bx[:, None] * nv + F.row[None, :]) * n_inner + bw[:, None]).ravel()
    cols = ((cx[:, None] * nv + F.col[None, :]) * n_inner + cw[:, None]).ravel()
    vals = (B.data[:, None] * F.data[None, :]).ravel()
    n = B.shape[0] // n_inner * nv * n_inner
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _xw_signed(X: DGLine, W: DGLine, s0: float, kx: float, kw: float) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    r""":math:`\iint u^\pm\,\phi_i\phi_j\,\psi_k\psi_l\,dx\,dW` for :math:`u = s_0 + k_x x + k_w W`
    over the (x, W) rectangles, as two matrices in the ordering (x outer, W inner)."""
    n = 2 * X.p + 10
    qx, qw = npleg.leggauss(n)
    lo, hi = X.nodes[:-1], X.nodes[1:]
    pts = lo[:, None] + 0.5 * (hi - lo)[:, None] * (qx + 1.0)            # (Ex, q)
    wts = 0.5 * (hi - lo)[:, None] * qw
    basis = npleg.legvander(qx, X.p) @ np.linalg.inv(npleg.legvander(lobatto_points(X.p), X.p))
    pos, neg = W.signed_parts(s0 + kx * pts.ravel(), kw)                 # (Ex q, EW, pw, pw)
    out = []
    for part in (pos, neg):
        part = part.reshape(X.elements, n, W.elements, W.p + 1, W.p + 1)
        blocks = np.einsum("qi,eq,qj,eqfkl->efikjl", basis, wts, basis, part)
        out.append(_xw_matrix(X, W, blocks))
    return out[0], out[1]


def _xw_matrix(X: DGLine, W: DGLine, blocks: np.ndarray) -> sp.csr_matrix:
    """Sparse (x outer, W inner) matrix of per-rectangle blocks ``[ex, ew, i, k, j, l]``."""
    px, pw = X.p + 1, W.p + 1
    ex, ew, i, k, j, l = np.indices(blocks.shape)
    rows = (ex * px + i) * W.size + ew * pw + k
    cols = (ex * px + j) * W.size + ew * pw + l
    n = X.size * W.size
    return sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))


def transport_w(h: Harvester, X: DGLine, Vv: DGLine, W: DGLine, lam: np.ndarray,
                xface: sp.csr_matrix, vol_f: sp.csr_matrix) -> list[sp.csr_matrix]:
    """Transport matrix of every xi-mode (nodes ``lam``) in (x, v, W), with the x faces
    ``xface`` and the volume term ``vol_f`` of the mode's constant force shared with the V variant."""
    p = h.params
    Mx, Mv, MW = X.mass(), Vv.mass(), W.mass()
    Mx1, Mv1, MW1 = X.mass(power=1), Vv.mass(power=1), W.mass(power=1)
    Dx, Dv, Dv1, DW, DW1 = X.derivative(), Vv.derivative(), Vv.derivative(1), W.derivative(), W.derivative(1)
    kv = p.Kv / p.m
    common = (-kron3(Dx, Mv1, MW) + p.gamma * kron3(Mx, Dv1, MW) + kv * kron3(Mx, Dv, MW1)
              + kv * p.Kc * kron3(Mx1, Dv, MW) + (1.0 / p.tau_p) * kron3(Mx, Mv, DW1)
              + (p.Kc / p.tau_p) * kron3(Mx1, Mv, DW))
    # W faces: speed -(W_f + Kc x) / tau_p, linear in x; v enters through its mass only
    xpos, xneg = X.signed_parts(-W.nodes / p.tau_p, -p.Kc / p.tau_p)
    wface = None
    for f in range(W.elements + 1):
        lf, rf = W.left_of(f), W.right_of(f)
        jump = sp.csr_matrix(lf - rf).T
        for vec, part in ((lf, xpos[f]), (rf, xneg[f])):
            if vec.any():
                term = kron3(sp.block_diag(list(part), format="csr"), Mv, jump @ sp.csr_matrix(vec))
                wface = term if wface is None else wface + term
    T = []
    for li in lam:
        f0 = (-h.a + p.sigma * li) / p.m
        vface = None
        for g in range(Vv.elements + 1):
            lg, rg = Vv.left_of(g), Vv.right_of(g)
            jump = sp.csr_matrix(lg - rg).T
            pos, neg = _xw_signed(X, W, f0 - p.gamma * Vv.nodes[g], -kv * p.Kc, -kv)
            for vec, B in ((lg, pos), (rg, neg)):
                if vec.any():
                    term = kron_middle(B, jump @ sp.csr_matrix(vec), W.size)
                    vface = term if vface is None else vface + term
        T.append((common + f0 * vol_f + xface + wface + vface).tocsr())
    return T


def moments_w(h: Harvester, X: DGLine, Vv: DGLine, W: DGLine) -> dict[str, Any]:
    r"""Moment vectors of V = W + K_c x: :math:`\langle V^2\rangle` and :math:`\langle vV\rangle`."""
    Kc = h.params.Kc
    ix, iv, iW = X.integral(), Vv.integral(), W.integral()
    k3 = lambda a, b, c: np.kron(a, np.kron(b, c))  # noqa: E731
    V2 = (k3(ix, iv, W.integral(2)) + 2.0 * Kc * k3(X.integral(1), iv, W.integral(1))
          + Kc**2 * k3(X.integral(2), iv, iW))
    vV = k3(ix, Vv.integral(1), W.integral(1)) + Kc * k3(X.integral(1), Vv.integral(1), iW)
    return {"V2": V2, "vV": vV}

