"""GMRES of the level solves (:mod:`fpe_harvester.fpe.krylov`) against scipy's."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from fpe_harvester.fpe.krylov import gmres, restart_length


def _system(N: int = 300, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A nonsymmetric system whose Jacobi-preconditioned GMRES needs 80-115 iterations (more
    with shorter restarts)."""
    rng = np.random.default_rng(seed)
    A = np.diag(rng.uniform(1.0, 5.0, N)) + 2.0 * rng.standard_normal((N, N)) / np.sqrt(N)
    return A, rng.standard_normal(N), np.diag(1.0 / np.diag(A))


@pytest.mark.parametrize("restart", [15, 40, 400])
def test_gmres_is_scipys_method(restart: int) -> None:
    A, b, P = _system()
    x0 = 0.1 * np.ones_like(b)
    x, info, its = gmres(lambda v: A @ v, lambda r: P @ r, b, x0, 1e-10, restart, 2000)
    count = [0]
    y, yinfo = spla.gmres(A, b, x0=x0, M=P, rtol=1e-10, restart=restart, maxiter=2000 // restart,
                          callback=lambda _: count.__setitem__(0, count[0] + 1), callback_type="pr_norm")
    assert info == 0 and yinfo == 0
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)
    assert its == count[0]                       # the same Krylov spaces, the same stopping rule
    assert np.allclose(x, y, rtol=0.0, atol=1e-8 * np.abs(y).max())


def test_gmres_reports_an_exhausted_budget() -> None:
    A, b, P = _system()
    seen: list[float] = []
    x, info, its = gmres(lambda v: A @ v, lambda r: P @ r, b, None, 1e-12, 10, 25, callback=seen.append)
    assert info == its == 25 and len(seen) == 25
    assert np.linalg.norm(A @ x - b) > 1e-12 * np.linalg.norm(b)


def test_restart_length_fits_the_memory() -> None:
    assert restart_length(10**6, 1500, 1.6) == 199          # 200 vectors of 8 MB in 1.6 GB
    assert restart_length(10**6, 150, 1.6) == 150           # never more than the budget
    assert restart_length(10**9, 1500, 1.0) == 20           # at least 20
