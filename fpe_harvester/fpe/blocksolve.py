"""Block-tridiagonal elimination for the element-major DG system.

With unknowns ordered element by element (x outer, Hermite index inner), the DG
operator is block tridiagonal: element K couples to K - 1 and K + 1 only through the
upwind flux at the shared node. Each off-diagonal block is nonzero in a few rows and
columns and has low rank: the trace values of the two elements times :math:`F^\\pm`,
so its rank is at most :math:`\\mathrm{rank}\\,F^\\pm \\approx \\binom{M+3}{3}/2`. Stored as
:math:`A_{K,K-1} = U_K V_K^T` and :math:`A_{K-1,K} = P_K Q_K^T` (rank-revealing QR of the
block, or, when the caller passes the coupling terms :math:`X_\\pm \\otimes F^\\pm`, Kronecker
products of the factors of the small trace block and of :math:`F^\\pm`), forward
elimination

.. math::

    S_0 = A_{00}, \\qquad
    S_K = A_{KK} - U_K \\big(V_K^T W_{K-1}\\big) Q_K^T, \\qquad W_{K-1} = S_{K-1}^{-1} P_K

needs, per element, one dense LU of :math:`S_K` and one solve with only
:math:`\\mathrm{rank}\\,F^+` right-hand sides; :math:`W_K` is kept, so back substitution
needs no further solves. The elimination runs from both ends toward the middle block
(twisted factorization), the two halves in parallel (:class:`BlockTridiagonal`). This
avoids the fill of a general sparse LU (which grows like the product of all the
bandwidths) and runs in dense LAPACK. Cost per element :math:`\\approx \\tfrac23 n_b^3`,
:math:`n_b = (p+1)\\binom{M+3}{3}`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

__all__ = ["BlockTridiagonal", "blas_controller"]

#: Pivots of the rank-revealing QR below this fraction of the largest are dropped from a
#: coupling block (a relative perturbation of the operator at round-off level).
RANK_TOL = 1e-14


@functools.cache
def blas_controller() -> ThreadpoolController:
    """The thread-pool controller, made once (``threadpool_limits`` rescans the loaded
    libraries on every call: ~2 ms, a few per cent of a low level)."""
    return ThreadpoolController()


class _Coupling:
    """A sparse off-diagonal block as a low-rank product ``left @ right.T``.

    ``left`` lives on the rows ``rows`` of the block, ``right`` on the columns ``cols``.
    """

    def __init__(self, rows: np.ndarray, cols: np.ndarray, left: np.ndarray, right: np.ndarray) -> None:
        self.rows, self.cols, self.left, self.right = rows, cols, left, right

    @classmethod
    def from_entries(cls, r: np.ndarray, c: np.ndarray, v: np.ndarray,
                     known: dict[bytes, tuple[np.ndarray, np.ndarray]]) -> _Coupling:
        """From the nonzero entries ``(r, c, v)`` of the block (block-local indices)."""
        keep = v != 0.0
        r, c, v = r[keep], c[keep], v[keep]
        rows, ri = np.unique(r, return_inverse=True)
        cols, ci = np.unique(c, return_inverse=True)
        dense = np.zeros((len(rows), len(cols)))
        dense[ri, ci] = v
        # The DG couplings of a uniform reference element repeat from element to element:
        # one factorization per distinct block.
        key = np.array(dense.shape).tobytes() + dense.tobytes()
        if key not in known:
            known[key] = _low_rank(dense)
        return cls(rows, cols, *known[key])

    @classmethod
    def from_kron(cls, parts: list[tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]]) -> _Coupling:
        """From Kronecker terms :math:`\\sum_j X_j \\otimes H_j`: ``parts`` holds the small
        dense blocks :math:`X_j` with the low-rank factors of :math:`H_j`.

        The factors are Kronecker products of the factors of :math:`X_j` (an SVD of a
        :math:`(p+1)\\times(p+1)` matrix) and of :math:`H_j`: no factorization of the
        :math:`n_b \\times n_b` block (its pivoted QR was 40 % of a level at M = 14).
        """
        lefts, rights = [], []
        for xb, (hl, hr) in parts:
            u, sv, vt = np.linalg.svd(xb)
            for i in np.flatnonzero(sv > RANK_TOL * max(sv[0], 1e-300)):
                lefts.append(np.kron(u[:, i:i + 1] * sv[i], hl))
                rights.append(np.kron(vt[i][:, None], hr))
        if not lefts:
            none = np.zeros(0, dtype=int)
            return cls(none, none, np.zeros((0, 0)), np.zeros((0, 0)))
        left, right = np.hstack(lefts), np.hstack(rights)
        rows = np.flatnonzero(np.any(left != 0.0, axis=1))
        cols = np.flatnonzero(np.any(right != 0.0, axis=1))
        return cls(rows, cols, np.ascontiguousarray(left[rows]), np.ascontiguousarray(right[cols]))

    @property
    def rank(self) -> int:
        return self.left.shape[1]

    def times(self, x: np.ndarray) -> np.ndarray:
        """The block times ``x`` (a vector of the column block), on the rows ``rows``."""
        return self.left @ (self.right.T @ x[self.cols])


def _low_rank(dense: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(left, right)`` with ``dense = left @ right.T`` up to RANK_TOL (pivoted QR).

    Column-pivoted QR :math:`D \\Pi = Q R` is rank revealing for these blocks (their
    nonzero singular values are O(1), the rest round-off) and 2-3x cheaper than an SVD.
    """
    if dense.size == 0:
        return np.zeros((dense.shape[0], 0)), np.zeros((dense.shape[1], 0))
    Q, R, piv = sl.qr(dense, pivoting=True, mode="economic", check_finite=False)
    d = np.abs(np.diag(R))
    r = int(np.count_nonzero(d > RANK_TOL * d[0])) if d[0] > 0.0 else 0
    right = np.empty((dense.shape[1], r))
    right[piv] = R[:r].T
    return Q[:, :r], right


class BlockTridiagonal:
    """Twisted factorization of a block-tridiagonal sparse matrix with equal square blocks.

    Elimination runs from both ends toward the middle block m (blocks 0..m-1 from the
    left, N-1..m+1 from the right); the two sweeps are independent and run in two threads,
    each with single-threaded BLAS. On the 2-core reference machine this is 2-3x faster than
    one sweep with two BLAS threads: LAPACK's threaded LU is inefficient below a few
    thousand unknowns, the block sizes here.

    Parameters
    ----------
    A : sparse matrix
        Square, of size ``nblocks * block``, zero outside the block tridiagonal.
    block : int
        Size of one diagonal block (all equal).
    threads : int
        1 (one sweep after the other) or 2 (concurrent sweeps). Default 2.
    kron : sequence of (sparse matrix, ndarray), optional
        The terms :math:`X_j \\otimes H_j` of A that couple neighbouring blocks (all other
        terms block diagonal), with ``block`` a multiple of the size of :math:`H_j`. The
        off-diagonal blocks are then factored term by term (small :math:`X_j` blocks times
        one factorization per :math:`H_j`) instead of from A's entries; A's off-diagonal
        entries must equal those of the terms (the caller's contract).

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> A = sp.diags([[-1.0] * 5, [4.0] * 6, [-1.0] * 5], [-1, 0, 1]).tocsr()
    >>> x = BlockTridiagonal(A, 2).solve(np.ones(6))
    >>> bool(np.allclose(A @ x, 1.0))
    True
    """

    def __init__(self, A: sp.spmatrix, block: int, threads: int = 2,
                 kron: Sequence[tuple[sp.spmatrix, np.ndarray]] | None = None) -> None:
        with blas_controller().limit(limits=1, user_api="blas"):
            self._factor(A, block, threads, kron)

    def _factor(self, A: sp.spmatrix, block: int, threads: int,
                kron: Sequence[tuple[sp.spmatrix, np.ndarray]] | None) -> None:
        A = sp.csr_matrix(A)
        n = A.shape[0]
        if n % block:
            raise ValueError(f"matrix size {n} is not a multiple of the block size {block}")
        if threads not in (1, 2):
            raise ValueError(f"threads must be 1 or 2, got {threads}")
        self.block = block
        self.nblocks = N = n // block
        self.mid = m = N // 2
        b = block
        # Split the entries by block row and column once (scipy's 2-D slicing is slow here).
        Ac = A.tocoo()
        Ac.sum_duplicates()  # new arrays: the caller's matrix is left alone
        br, bc = Ac.row // b, Ac.col // b
        if np.any(np.abs(br - bc) > 1):
            raise ValueError("matrix has entries outside the block tridiagonal")
        order = np.lexsort((bc, br))
        keys = (br * 3 + (bc - br + 1))[order]
        cuts = np.searchsorted(keys, np.arange(3 * N + 1))
        R, C, V = Ac.row[order] % b, Ac.col[order] % b, Ac.data[order]

        def part(k: int, d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            i = 3 * k + d + 1
            sl_ = slice(cuts[i], cuts[i + 1])
            return R[sl_], C[sl_], V[sl_]

        #: lower[k - 1] = A_{k,k-1}, upper[k] = A_{k,k+1}
        if kron is None:
            known: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
            self.lower = [_Coupling.from_entries(*part(k, -1), known) for k in range(1, N)]
            self.upper = [_Coupling.from_entries(*part(k, 1), known) for k in range(N - 1)]
        else:
            self.lower, self.upper = _kron_couplings(kron, N, b)
        self.lu: list[Any] = [None] * N
        # W[k] = S_k^{-1} (left factor of A_{k,k+1}) for k < m (left sweep),
        # W[k] = T_k^{-1} (left factor of A_{k,k-1}) for k > m (right sweep).
        self.W: list[Any] = [None] * N

        def diag(k: int) -> np.ndarray:
            r, c, v = part(k, 0)
            out = np.zeros((b, b), order="F")
            out[r, c] = v
            return out

        def placed(c: _Coupling) -> np.ndarray:
            out = np.zeros((b, c.rank))
            out[c.rows] = c.left
            return out

        def from_left(S: np.ndarray, k: int) -> None:
            # S_k -= A_{k,k-1} S_{k-1}^{-1} A_{k-1,k}
            lo, up = self.lower[k - 1], self.upper[k - 1]
            S[np.ix_(lo.rows, up.cols)] -= lo.left @ (lo.right.T @ self.W[k - 1][lo.cols]) @ up.right.T

        def from_right(T: np.ndarray, k: int) -> None:
            # T_k -= A_{k,k+1} T_{k+1}^{-1} A_{k+1,k}
            up, lo = self.upper[k], self.lower[k]
            T[np.ix_(up.rows, lo.cols)] -= up.left @ (up.right.T @ self.W[k + 1][up.cols]) @ lo.right.T

        def left_sweep() -> None:
            for k in range(m):
                S = diag(k)
                if k > 0:
                    from_left(S, k)
                self.lu[k] = sl.lu_factor(S, check_finite=False, overwrite_a=True)
                self.W[k] = sl.lu_solve(self.lu[k], placed(self.upper[k]), check_finite=False)

        def right_sweep() -> None:
            for k in range(N - 1, m, -1):
                T = diag(k)
                if k < N - 1:
                    from_right(T, k)
                self.lu[k] = sl.lu_factor(T, check_finite=False, overwrite_a=True)
                self.W[k] = sl.lu_solve(self.lu[k], placed(self.lower[k - 1]), check_finite=False)

        if threads == 2 and N > 2:
            with ThreadPoolExecutor(2) as pool:
                jobs = [pool.submit(left_sweep), pool.submit(right_sweep)]
                for job in jobs:
                    job.result()
        else:
            left_sweep()
            right_sweep()
        Z = diag(m)
        if m > 0:
            from_left(Z, m)
        if m < N - 1:
            from_right(Z, m)
        # Both sweeps are done: the middle block may use both cores (LAPACK's threaded LU
        # is 1.2-1.6x faster than one thread at these sizes, measured n_b = 660-2720).
        with blas_controller().limit(limits=threads, user_api="blas"):
            self.lu[m] = sl.lu_factor(Z, check_finite=False, overwrite_a=True)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve :math:`A x = r` with the stored factorization."""
        N, m = self.nblocks, self.mid
        r = np.array(rhs, dtype=float).reshape(N, self.block)
        y = np.empty_like(r)
        for k in range(m):
            rk = r[k].copy()
            if k > 0:
                rk[self.lower[k - 1].rows] -= self.lower[k - 1].times(y[k - 1])
            y[k] = sl.lu_solve(self.lu[k], rk, check_finite=False)
        for k in range(N - 1, m, -1):
            rk = r[k].copy()
            if k < N - 1:
                rk[self.upper[k].rows] -= self.upper[k].times(y[k + 1])
            y[k] = sl.lu_solve(self.lu[k], rk, check_finite=False)
        x = np.empty_like(y)
        rm = r[m].copy()
        if m > 0:
            rm[self.lower[m - 1].rows] -= self.lower[m - 1].times(y[m - 1])
        if m < N - 1:
            rm[self.upper[m].rows] -= self.upper[m].times(y[m + 1])
        x[m] = sl.lu_solve(self.lu[m], rm, check_finite=False)
        for k in range(m - 1, -1, -1):
            up = self.upper[k]
            x[k] = y[k] - self.W[k] @ (up.right.T @ x[k + 1][up.cols])
        for k in range(m + 1, N):
            lo = self.lower[k - 1]
            x[k] = y[k] - self.W[k] @ (lo.right.T @ x[k - 1][lo.cols])
        return x.ravel()


def _kron_couplings(kron: Sequence[tuple[sp.spmatrix, np.ndarray]], N: int, block: int
                    ) -> tuple[list[_Coupling], list[_Coupling]]:
    """The couplings A_{k,k-1} (lower) and A_{k,k+1} (upper) from Kronecker terms X_j (x) H_j."""
    terms = []
    for X, H in kron:
        H = np.asarray(H.toarray() if sp.issparse(H) else H, dtype=float)
        nx = block // H.shape[0]
        if nx * H.shape[0] != block or X.shape[0] != N * nx:
            raise ValueError(f"Kronecker term of shape {X.shape} x {H.shape} does not fit {N} blocks of {block}")
        terms.append((sp.csr_matrix(X), _low_rank(H), nx))

    def coupling(k: int, j: int) -> _Coupling:
        parts = []
        for X, hf, nx in terms:
            xb = X[k * nx:(k + 1) * nx, j * nx:(j + 1) * nx].toarray()
            if np.any(xb != 0.0):
                parts.append((xb, hf))
        return _Coupling.from_kron(parts)

    return [coupling(k, k - 1) for k in range(1, N)], [coupling(k, k + 1) for k in range(N - 1)]
