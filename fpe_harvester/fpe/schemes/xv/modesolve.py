"""The kink solver's preconditioner: a Gauss--Seidel sweep over the modes, each solved exactly.

In the mode basis of :mod:`.kink` (eigenvectors of the drive's multiplication
:math:`G = R\\Lambda R^T`) the operator of a level is

.. math::

    A = \\sum_i T_i \\otimes e_i e_i^T + S_S \\otimes P + S_0 \\otimes K_0 + S_1 \\otimes K_1
        + S_2 \\otimes K_2 ,

with :math:`T_i` the scalar upwind transport of mode i in the (x, v) plane, P the parity
(which pairs the modes of nodes :math:`\\pm\\lambda` of one chain through the mirror
inflow at x = 0), and :math:`S_k \\otimes K_k` the coupling of the modes by the (V, xi)
dynamics (:math:`S_k` element masses of the plane weighted by 1, v, x). A group is a mode
with its parity partner; :class:`ModePreconditioner` factors each group's block
:math:`D_g` (its modes' transport, parity and own coupling coefficients :math:`(K_k)_{ii}`;
SuperLU) and applies one forward block Gauss--Seidel sweep over the groups:

.. math::

    y_g = D_g^{-1}\\Big(r_g - \\sum_{h < g} A_{gh}\\, y_h\\Big),

i.e. the exact solve of A's block lower triangle, up to the coupling of the two modes of a
group by :math:`K_k`. The groups are swept chain by chain
(:math:`\\beta_2` ascending), and within a chain from the slowest mode (smallest
:math:`|\\lambda|`) outward, the order that measured fewest iterations; one thread is the
default (:data:`~.kink.SWEEP_THREADS`): two halves swept concurrently save wall time per
sweep but cost iterations and CPU time.

Why not sweeps in (x, v) (upwind block Gauss--Seidel over the elements, in place of each
group's LU): on the half plane the transport of one mode is acyclic, so one sweep in flow
order solves it exactly, but the mirror inflow at x = 0 closes the rotation's cycle, and
breaking it (the inflow from the previous sweep) costs far more iterations than the exact
group solves. The measurements: docs/methods.md, Fokker-Planck design notes.
"""

from __future__ import annotations

import functools
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

if TYPE_CHECKING:
    from .hierarchy import KinkHierarchy, KinkPlane

__all__ = ["ModePreconditioner", "mode_groups"]

#: Entries of the parity in the mode basis below this are rounding of R (the parity maps
#: each mode to one other).
PARITY_TOL = 1e-8


@functools.cache
def _helper() -> ThreadPoolExecutor:
    """The thread that sweeps the second segment (made once)."""
    return ThreadPoolExecutor(1, thread_name_prefix="mode-sweep")


def mode_groups(hi: KinkHierarchy) -> list[np.ndarray]:
    """The groups of modes (a mode and its parity partner) in sweep order: by chain
    :math:`\\beta_2` (the Hermite degree in the second variable, which G does not change),
    then by the smallest :math:`|\\lambda|` of the group."""
    n = hi.lam.size
    seen = np.zeros(n, dtype=bool)
    groups = []
    for i in range(n):
        if not seen[i]:
            grp = np.unique(np.concatenate([[i], np.flatnonzero(np.abs(hi.Pm[:, i]) > PARITY_TOL)]))
            seen[grp] = True
            groups.append(grp)
    # R is block diagonal by chain: the chain of a mode is that of its largest component
    chain = np.array([hi.hb.alphas[np.argmax(np.abs(hi.R[:, g[0]])), 1] for g in groups])
    slow = np.array([np.abs(hi.lam[g]).min() for g in groups])
    return [groups[k] for k in np.lexsort((slow, chain))]


class ModePreconditioner:
    """One forward block Gauss--Seidel sweep over the mode groups, each group's block
    solved by sparse LU (see the module docstring).

    Parameters
    ----------
    T : list of sparse matrices
        Scalar transport of every mode (:func:`~.kink.mode_transport`).
    pl : KinkPlane
        The plane's matrices.
    hi : KinkHierarchy
        The Hermite degree's matrices in the mode basis.
    """

    def __init__(self, T: list[sp.csr_matrix], pl: KinkPlane, hi: KinkHierarchy, threads: int = 1) -> None:
        if threads not in (1, 2):
            raise ValueError(f"threads must be 1 or 2, got {threads!r}")
        self.groups = mode_groups(hi)
        self.order = np.concatenate(self.groups)
        self.bounds = np.cumsum([0] + [g.size for g in self.groups])
        couplings = [hi.K0m, hi.K1m] + ([hi.K2m] if hi.K2.nnz else [])
        self.lus = [self._factor(grp, T, pl, hi) for grp in self.groups]
        # the coupling of every mode to the modes before it in sweep order, the diagonal
        # (in the factors) removed
        C = [np.tril(Km[np.ix_(self.order, self.order)], -1) for Km in couplings]
        self.C = np.concatenate(C, axis=0)                      # (terms * modes, modes)
        # S_k = -(x mass) kron (v mass), applied as small dense products: Mx (W_0 Mv + W_1 Mv1) + Mx1 W_2 Mv
        X, Vl = pl.X, pl.Vl
        self.shape = (X.size, Vl.size)
        self.Mx, self.Mx1 = X.mass().toarray(), X.mass(power=1).toarray()
        self.Mv, self.Mv1 = Vl.mass().toarray(), Vl.mass(power=1).toarray()
        # threads = 2: two segments of about half the modes each, swept concurrently
        # (SuperLU's solve and BLAS release the GIL); the second does without the coupling to the first
        cut = int(np.searchsorted(self.bounds, self.bounds[-1] / 2)) if threads == 2 else len(self.groups)
        self.segments = [(0, cut)] + ([(cut, len(self.groups))] if cut < len(self.groups) else [])

    @staticmethod
    def _factor(grp: np.ndarray, T: list[sp.csr_matrix], pl: KinkPlane, hi: KinkHierarchy) -> Any:
        """SuperLU of the group's block: the modes' transport and their own coupling
        coefficients, and the parity between them. The coupling of the two modes by
        :math:`K_k` is left to the sweep's residual: factoring it into the block doubles the
        factors for a few per cent fewer iterations (docs/methods.md, Fokker-Planck design notes)."""
        blocks: list[list[Any]] = [[hi.Pm[r, c] * pl.S_S for c in grp] for r in grp]
        for k, r in enumerate(grp):
            blocks[k][k] = (blocks[k][k] + T[r] + hi.K0m[r, r] * pl.S_K0 + hi.K1m[r, r] * pl.S_K1
                            + hi.K2m[r, r] * pl.S_K2)
        # MMD on A^T A: a third of COLAMD's fill, half its solve time (a = 1, M = 8)
        return spla.splu(sp.bmat(blocks, format="csc"), permc_spec="MMD_ATA")

    def __call__(self, r: np.ndarray) -> np.ndarray:
        """The sweep for the residual ``r`` ((x, v) unknowns by modes)."""
        R = np.ascontiguousarray(r[:, self.order].T)            # (modes, unknowns), sweep order
        Y = np.empty_like(R)
        if len(self.segments) == 1:
            self._sweep(R, Y, *self.segments[0])
        else:
            job = _helper().submit(self._sweep, R, Y, *self.segments[1])
            self._sweep(R, Y, *self.segments[0])
            job.result()
        out = np.empty_like(r)
        out[:, self.order] = Y.T
        return out

    def _sweep(self, R: np.ndarray, Y: np.ndarray, first: int, last: int) -> None:
        """Solve the groups ``first`` to ``last - 1`` in turn into ``Y`` (sweep order), each
        with the coupling to the groups of the segment solved before it."""
        nh, terms = self.order.size, self.C.shape[0] // self.order.size
        s0 = self.bounds[first]
        for lu, s, e in zip(self.lus[first:last], self.bounds[first:last], self.bounds[first + 1:last + 1]):
            rhs = R[s:e]
            if s > s0:
                rows = (np.arange(s, e)[None, :] + nh * np.arange(terms)[:, None]).ravel()
                W = (self.C[rows, s0:s] @ Y[s0:s]).reshape(terms, e - s, *self.shape)
                # r_g - sum_k S_k W_k, with S_k = -(Mx_k kron Mv_k)
                Z = self.Mx @ (W[0] @ self.Mv + W[1] @ self.Mv1)
                if terms == 3:
                    Z += self.Mx1 @ (W[2] @ self.Mv)
                rhs = rhs + Z.reshape(e - s, -1)
            Y[s:e] = lu.solve(np.ascontiguousarray(rhs).ravel()).reshape(e - s, -1)
