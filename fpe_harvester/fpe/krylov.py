"""Left-preconditioned GMRES with classical Gram-Schmidt (BLAS), for the large level solves.

:func:`scipy.sparse.linalg.gmres` orthogonalizes by modified Gram-Schmidt, one Python-level
dot product and update per basis vector and iteration: at the kink solver's largest levels
(n = 1, a = 1, M = 20: 5e5 unknowns, 235 iterations) that was 29 s of the 236 s spent in
GMRES. :func:`gmres` is the same method (the same Krylov space, the same restarts, the same
stopping rule on the preconditioned residual, checked against the true residual at the end
of a cycle) with classical Gram-Schmidt (two matrix-vector products with the basis, BLAS),
repeated where cancellation calls for it (as accurate as modified Gram-Schmidt);
:func:`restart_length` bounds the restart length by memory.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.linalg as sla

__all__ = ["gmres", "restart_length", "REORTHOGONALIZE"]

#: A Gram-Schmidt pass is repeated when it shrinks the vector below this fraction of its
#: norm (Daniel, Gragg, Kaufman and Stewart, Math. Comp. 30, 1976: "twice is enough").
#: Each pass reads the whole basis twice: at n = 1, a = 1, M = 20, degree 4 (8.3e5 unknowns,
#: 130 iterations) about 110 GB of memory traffic over the level.
REORTHOGONALIZE = 1.0 / math.sqrt(2.0)


def restart_length(size: int, maxiter: int, gigabytes: float) -> int:
    """Basis vectors (restart length) that fit in ``gigabytes`` of float64 vectors of
    ``size`` entries, at least 20 and at most ``maxiter``."""
    return int(min(maxiter, max(20, gigabytes * 1e9 / (8.0 * size) - 1)))


def gmres(matvec: Callable[[np.ndarray], np.ndarray], psolve: Callable[[np.ndarray], np.ndarray],
          b: np.ndarray, x0: np.ndarray | None, rtol: float, restart: int, maxiter: int,
          callback: Callable[[float], None] | None = None) -> tuple[np.ndarray, int, int]:
    """Solve :math:`A x = b` by GMRES on the left-preconditioned system :math:`P A x = P b`.

    Parameters
    ----------
    matvec, psolve : callable
        :math:`v \\mapsto A v` and :math:`r \\mapsto P r` on vectors of ``b``'s size.
    b : ndarray (N,)
        Right-hand side.
    x0 : ndarray (N,) or None
        Starting guess (zero if None).
    rtol : float
        Stop when the preconditioned residual is below ``rtol`` times :math:`\\|P b\\|` and
        the true residual below ``rtol`` times :math:`\\|b\\|` (the rule of
        :func:`scipy.sparse.linalg.gmres`), > 0.
    restart : int
        Krylov basis vectors kept before a restart (memory: ``restart + 1`` vectors), >= 1.
    maxiter : int
        Iterations (matrix-vector products) allowed in all, >= 1.
    callback : callable or None
        Called after every iteration with the preconditioned residual over :math:`\\|b\\|`
        (it may raise to stop the solve).

    Returns
    -------
    x : ndarray (N,)
        The last iterate.
    info : int
        0 if converged, else the iterations made (the budget ran out).
    iterations : int
        Iterations made.
    """
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    bnorm = float(np.linalg.norm(b))
    if bnorm == 0.0:
        return np.zeros_like(b), 0, 0
    atol = rtol * bnorm
    ptol = rtol * float(np.linalg.norm(psolve(b)))
    V = np.empty((min(restart, maxiter) + 1, b.size))
    its, factor = 0, 1.0
    r = b - matvec(x) if x.any() else b.copy()
    rnorm = float(np.linalg.norm(r))
    while rnorm > atol and its < maxiter:
        y, steps, presid = _cycle(lambda v: psolve(matvec(v)), psolve(r), V, min(V.shape[0] - 1, maxiter - its),
                                  ptol, bnorm, callback)
        its += steps
        x += y @ V[:steps]
        r = b - matvec(x)
        rnorm = float(np.linalg.norm(r))
        # the preconditioned residual met its target but the true one did not: tighten the
        # inner target (the rule of scipy's gmres)
        factor = max(np.finfo(float).eps, 0.25 * factor) if presid <= ptol else min(1.0, 1.5 * factor)
        ptol = presid * min(factor, atol / rnorm)
    return x, (0 if rnorm <= atol else its), its


def _cycle(op: Callable[[np.ndarray], np.ndarray], r: np.ndarray, V: np.ndarray, steps: int, ptol: float,
           bnorm: float, callback: Callable[[float], None] | None) -> tuple[np.ndarray, int, float]:
    """One GMRES cycle of the preconditioned operator ``op`` (:math:`v \\mapsto P A v`) from the
    preconditioned residual ``r``: at most ``steps`` iterations, basis in ``V``. Returns the
    coefficients of the update in the basis, the iterations made and the preconditioned
    residual reached."""
    beta = float(np.linalg.norm(r))
    V[0] = r / beta
    H = np.zeros((steps + 1, steps))
    g = np.zeros(steps + 1)
    g[0] = beta
    cs, sn = np.zeros(steps), np.zeros(steps)
    k = 0
    for k in range(steps):
        w = op(V[k])
        h = np.zeros(k + 2)
        before = float(np.linalg.norm(w))
        for _ in range(2):
            c = V[:k + 1] @ w
            w -= c @ V[:k + 1]
            h[:k + 1] += c
            h[k + 1] = float(np.linalg.norm(w))
            # a second pass only where cancellation lost orthogonality (DGKS criterion)
            if h[k + 1] > REORTHOGONALIZE * before:
                break
            before = h[k + 1]
        if h[k + 1] > 0.0:
            V[k + 1] = w / h[k + 1]
        for j in range(k):
            h[j], h[j + 1] = cs[j] * h[j] + sn[j] * h[j + 1], -sn[j] * h[j] + cs[j] * h[j + 1]
        cs[k], sn[k], h[k] = _rotation(h[k], h[k + 1])
        h[k + 1] = 0.0
        H[:k + 1, k] = h[:k + 1]
        g[k + 1], g[k] = -sn[k] * g[k], cs[k] * g[k]
        if callback is not None:
            callback(abs(g[k + 1]) / bnorm)
        if abs(g[k + 1]) <= ptol or H[k, k] == 0.0:
            break
    n = k + 1
    return sla.solve_triangular(H[:n, :n], g[:n]), n, abs(g[n])


def _rotation(f: float, g: float) -> tuple[float, float, float]:
    """Givens rotation ``(c, s, r)`` with :math:`c f + s g = r`, :math:`-s f + c g = 0`."""
    r = float(np.hypot(f, g))
    if r == 0.0:
        return 1.0, 0.0, 0.0
    return f / r, g / r, r
