"""Block-tridiagonal elimination for the element-major DG system.

With unknowns ordered element by element (x outer, Hermite index inner), the DG
operator is block tridiagonal: element K couples to K - 1 and K + 1 only through the
upwind flux at the shared node, so the off-diagonal blocks are nonzero in a few rows
and columns (the trace dofs times the rank of :math:`F^\\pm`). Forward elimination

.. math::

    S_0 = A_{00}, \\qquad S_K = A_{KK} - A_{K,K-1} S_{K-1}^{-1} A_{K-1,K}

needs, per element, one dense LU of :math:`S_K` and solves with as many right-hand sides
as the coupling has columns; the update touches only the trace block. This avoids the
fill of a general sparse LU (which grows like the product of all the bandwidths) and runs
in dense LAPACK. Cost per element :math:`\\approx \\tfrac23 n_b^3`, :math:`n_b = (p+1)\\binom{M+3}{3}`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp

__all__ = ["BlockTridiagonal"]


class _Coupling:
    """A sparse off-diagonal block stored as (rows, cols, dense values)."""

    def __init__(self, block: sp.csr_matrix) -> None:
        block = sp.csr_matrix(block)
        block.eliminate_zeros()
        self.rows = np.unique(block.nonzero()[0])
        self.cols = np.unique(block.nonzero()[1])
        self.values = block[self.rows][:, self.cols].toarray()


class BlockTridiagonal:
    """Factorization of a block-tridiagonal sparse matrix with equal square blocks.

    Parameters
    ----------
    A : sparse matrix
        Square, of size ``nblocks * block``, zero outside the block tridiagonal.
    block : int
        Size of one diagonal block (all equal).

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> A = sp.diags([[-1.0] * 5, [4.0] * 6, [-1.0] * 5], [-1, 0, 1]).tocsr()
    >>> x = BlockTridiagonal(A, 2).solve(np.ones(6))
    >>> bool(np.allclose(A @ x, 1.0))
    True
    """

    def __init__(self, A: sp.spmatrix, block: int) -> None:
        A = sp.csr_matrix(A)
        n = A.shape[0]
        if n % block:
            raise ValueError(f"matrix size {n} is not a multiple of the block size {block}")
        self.block = block
        self.nblocks = n // block
        b = block
        sl_ = [slice(k * b, (k + 1) * b) for k in range(self.nblocks)]
        self.lower = [_Coupling(A[sl_[k], sl_[k - 1]]) for k in range(1, self.nblocks)]
        self.upper = [_Coupling(A[sl_[k], sl_[k + 1]]) for k in range(self.nblocks - 1)]
        self.lu: list[tuple[np.ndarray, np.ndarray]] = []
        for k in range(self.nblocks):
            S = A[sl_[k], sl_[k]].toarray()
            if k > 0:
                lo, up = self.lower[k - 1], self.upper[k - 1]
                # S_{k-1}^{-1} restricted to the coupling: rows lo.cols, columns up.rows.
                rhs = np.zeros((b, len(up.rows)))
                rhs[up.rows, np.arange(len(up.rows))] = 1.0
                Z = sl.lu_solve(self.lu[k - 1], rhs, check_finite=False)[lo.cols]
                S[np.ix_(lo.rows, up.cols)] -= lo.values @ Z @ up.values
            self.lu.append(sl.lu_factor(S, check_finite=False, overwrite_a=True))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve :math:`A x = r` with the stored factorization."""
        b = self.block
        r = np.array(rhs, dtype=float).reshape(self.nblocks, b)
        y = np.empty_like(r)
        for k in range(self.nblocks):
            rk = r[k].copy()
            if k > 0:
                lo = self.lower[k - 1]
                rk[lo.rows] -= lo.values @ y[k - 1][lo.cols]
            y[k] = sl.lu_solve(self.lu[k], rk, check_finite=False)
        x = np.empty_like(y)
        x[-1] = y[-1]
        for k in range(self.nblocks - 2, -1, -1):
            up = self.upper[k]
            t = np.zeros(b)
            t[up.rows] = up.values @ x[k + 1][up.cols]
            x[k] = y[k] - sl.lu_solve(self.lu[k], t, check_finite=False)
        return x.ravel()
