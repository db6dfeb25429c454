"""Hermite algebra, mesh, DG assembly and the block solver, checked in isolation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fpe_harvester import Harvester, ParameterError
from fpe_harvester.fpe import HermiteBasis, XMesh
from fpe_harvester.fpe.assemble import assemble_x, jacobi_rule, split_flux
from fpe_harvester.fpe.blocksolve import BlockTridiagonal
from fpe_harvester.fpe.hermite import equivalent_harmonic


def test_hermite_index_set_size_and_symmetry() -> None:
    for M in (2, 5, 9):
        hb = HermiteBasis(M)
        assert hb.size == math.comb(M + 3, 3)
        J = hb.multiply(0)
        assert abs(J - J.T).max() == 0.0
        assert hb.degree().max() == M


def test_flux_matrix_eigenvalues_are_hermite_roots() -> None:
    """Each v-chain of the truncated multiplication matrix has the roots of He_k as eigenvalues."""
    hb = HermiteBasis(4)
    lam = np.sort(np.linalg.eigvalsh(hb.multiply(0).toarray()))
    expected = []
    for s in range(5):  # degree of (alpha1, alpha2)
        k = 4 - s + 1
        roots = np.polynomial.hermite_e.hermeroots([0] * k + [1])
        expected.extend(list(roots) * (s + 1))
    assert np.allclose(lam, np.sort(expected), atol=1e-12)


def test_generator_reproduces_gaussian_stationary_moments() -> None:
    """For a linear (v, V, xi) system whitened by its own stationary covariance, the
    generator annihilates the degree-2 equations at c = e_0 (the weight is stationary)."""
    B = np.array([[-1.0, -1.0, 1.0], [1.0, -0.5, 0.0], [0.0, 0.0, -1.0]])
    Q = np.diag([0.0, 0.0, 2.0])
    import scipy.linalg as sl

    S = sl.solve_continuous_lyapunov(B, -Q)
    L = np.linalg.cholesky(S)
    Li = np.linalg.inv(L)
    K0 = HermiteBasis(3).generator(Li @ B @ L, Li @ Q @ Li.T)
    c = np.zeros(K0.shape[0])
    c[0] = 1.0
    assert np.abs(K0 @ c).max() < 1e-12


@pytest.mark.parametrize("params", [{}, {"m": 1.7, "gamma": 0.3, "Kv": 2.5, "Kc": 0.4, "sigma": 1.3,
                                     "tau": 0.6, "D": 2.2, "tau_p": 5.0}])
def test_whitening_of_a_harmonic_unit_is_its_stationary_covariance(params) -> None:
    """n = 2: the equivalent stiffness is 2a and the weight is the unit's stationary covariance,
    checked against a 40-digit Lyapunov solve (independent of the scipy solve the code uses) and
    the exact facts <x v> = 0 (d<x^2>/dt = 0) and <xi^2> = D/tau."""
    from validation.references import mp_mode_moments

    h = Harvester.build(a=0.7, n=2, **params)
    kappa, P = equivalent_harmonic(h)
    assert kappa == 1.4
    ref = {key: float(val) for key, val in mp_mode_moments(1.4, h.params).items()}
    p = h.params
    expected = {(0, 0): ref["x2"], (1, 1): ref["v2"], (2, 2): ref["V2"], (1, 2): ref["vV"],
                (1, 3): ref["Pin"] / p.sigma, (0, 1): 0.0, (3, 3): p.D / p.tau}
    for (i, j), value in expected.items():
        assert P[i, j] == pytest.approx(value, rel=1e-10, abs=1e-14), (i, j)
        assert P[j, i] == pytest.approx(value, rel=1e-10, abs=1e-14), (j, i)
    assert np.linalg.eigvalsh(P).min() > 0


def test_mesh_has_node_at_zero_and_is_symmetric() -> None:
    nodes = XMesh(3.0, 7, n=1.0, scale=0.5, domain=30.0, grading=2.5).nodes()
    assert 0.0 in nodes
    assert np.allclose(nodes, -nodes[::-1])
    assert np.all(np.diff(nodes) > 0)
    h = np.diff(nodes)
    assert h[7] < h[0]  # graded toward the kink


def test_geometric_layers_split_the_element_at_zero() -> None:
    base = XMesh(2.0, 4, n=1.5, scale=1.0, domain=1.0, wall=0.0)
    mesh = XMesh(2.0, 4, n=1.5, scale=1.0, domain=1.0, wall=0.0, layers=3, ratio=0.15)
    half, x1 = mesh.half_nodes(), base.half_nodes()[1]
    assert np.allclose(half, [0.0, x1 * 0.15**3, x1 * 0.15**2, x1 * 0.15, *base.half_nodes()[1:]])
    assert mesh.elements == 2 * (4 + 3) and mesh.geometric and not base.geometric
    nodes = mesh.nodes()
    assert 0.0 in nodes and np.allclose(nodes, -nodes[::-1])
    assert mesh.with_elements(8).layers == 3


@pytest.mark.parametrize("s", [0.02, 0.25, 0.5, 0.75, 0.98])
@pytest.mark.parametrize("h", [1.0, 0.37])
def test_gauss_jacobi_rule_is_exact_for_power_times_polynomial(s: float, h: float) -> None:
    """int_0^h x^s x^k dx = h^(s+k+1)/(s+k+1) for k <= 2 * points - 1."""
    x, w = jacobi_rule(5, s, h)
    assert np.all((x > 0.0) & (x < h))
    for k in range(10):
        assert w @ x**k == pytest.approx(h ** (s + k + 1) / (s + k + 1), rel=1e-13), k


def test_singular_assembly_is_exact_for_the_force_at_zero() -> None:
    """M_u with Gauss-Jacobi on the elements touching 0: for the projections c_k of x^k
    (exact in P3), c_k^T M_u c_l = int u x^(k+l) dx, in closed form for u = -n|x|^(n-1) sign x
    on [-1, 1]; Gauss-Legendre with as many points misses it by far more."""
    n = 1.5
    u = lambda x: -n * np.abs(x) ** (n - 1.0) * np.sign(x)  # noqa: E731
    nodes = np.array([-1.0, -0.2, 0.0, 0.2, 1.0])
    errors = {}
    for singular in (n - 1.0, None):
        X = assemble_x(nodes, 3, u, intorder=40, singular=singular)
        c = [X.basis.project(lambda x, k=k: x[0] ** k)[X.perm] for k in range(4)]
        err = 0.0
        for k in range(4):
            for l in range(4):
                m = k + l
                exact = -2.0 * n / (n + m) if m % 2 else 0.0
                err = max(err, abs(c[k] @ X.mass_u @ c[l] - exact))
        errors[singular] = err
    assert errors[n - 1.0] < 1e-12
    assert errors[None] > 1e3 * errors[n - 1.0]


def test_singular_assembly_needs_a_node_at_zero() -> None:
    with pytest.raises(ValueError, match="node at x = 0"):
        assemble_x(np.array([-1.0, -0.3, 0.4, 1.0]), 3, lambda x: x, singular=0.5)
    with pytest.raises(ValueError, match="exponent > -1"):
        assemble_x(np.array([-1.0, 0.0, 1.0]), 3, lambda x: x, singular=-1.5)


def test_mesh_rejects_bad_input() -> None:
    with pytest.raises(ParameterError, match="half_elements"):
        XMesh(1.0, 0)
    with pytest.raises(ParameterError, match="L must be"):
        XMesh(-1.0, 3)


@pytest.mark.parametrize("order", [2, 3, 4])
def test_dg_upwind_scalar_advection_is_exact_for_polynomials(order: int) -> None:
    """d/dx c = s(x) with inflow 0 at -1: DG upwind reproduces a polynomial solution."""
    nodes = np.linspace(-1.0, 1.0, 5)
    X = assemble_x(nodes, order, lambda x: 0.0 * x)
    # weak form: xplus c - deriv c = mass s, for F = 1 (F^+ = 1, F^- = 0)
    A = (X.xplus - X.deriv).tocsc()
    exact = lambda x: (x + 1.0) ** 2  # noqa: E731
    from skfem import LinearForm, asm

    s = asm(LinearForm(lambda v, w: 2.0 * (w.x[0] + 1.0) * v), X.basis)[X.perm]
    c = spla.spsolve(A, s)
    assert abs(c @ X.integral - 8.0 / 3.0) < 1e-12
    assert np.isclose(c @ X.x2, np.trapezoid(np.linspace(-1, 1, 20001) ** 2 * exact(np.linspace(-1, 1, 20001)),
                                             np.linspace(-1, 1, 20001)), rtol=1e-6)


def test_split_flux() -> None:
    F = HermiteBasis(3).multiply(0).toarray()
    Fp, Fm = split_flux(F)
    assert np.allclose(Fp + Fm, F)
    assert np.linalg.eigvalsh(Fp).min() > -1e-12
    assert np.linalg.eigvalsh(Fm).max() < 1e-12


def test_block_tridiagonal_matches_sparse_lu(rng: np.random.Generator) -> None:
    nb, b = 5, 6
    A = sp.lil_matrix((nb * b, nb * b))
    for k in range(nb):
        A[k * b:(k + 1) * b, k * b:(k + 1) * b] = rng.normal(size=(b, b)) + 8 * np.eye(b)
        if k:
            A[k * b, (k - 1) * b + 2] = rng.normal()
            A[(k - 1) * b + 3, k * b + 1] = rng.normal()
    A = A.tocsr()
    r = rng.normal(size=nb * b)
    assert np.allclose(BlockTridiagonal(A, b).solve(r), spla.spsolve(A.tocsc(), r), atol=1e-12)


@pytest.mark.parametrize("nblocks", [1, 2, 3, 6, 7])
@pytest.mark.parametrize("threads", [1, 2])
def test_block_tridiagonal_low_rank_couplings(rng: np.random.Generator, nblocks: int, threads: int) -> None:
    # Couplings of rank 2 on a few rows and columns (like the DG traces times F+-), some
    # repeated from block to block (the factorization shares their low-rank factors).
    b = 8
    A = sp.lil_matrix((nblocks * b, nblocks * b))
    same = rng.normal(size=(3, 2)) @ rng.normal(size=(2, 4))
    for k in range(nblocks):
        A[k * b:(k + 1) * b, k * b:(k + 1) * b] = rng.normal(size=(b, b)) + 6 * np.eye(b)
        if k:
            A[k * b:k * b + 3, (k - 1) * b + 4:k * b] = same
            A[(k - 1) * b + 5:k * b, k * b:k * b + 4] = rng.normal(size=(3, 2)) @ rng.normal(size=(2, 4))
    A = A.tocsr()
    r = rng.normal(size=nblocks * b)
    x = BlockTridiagonal(A, b, threads=threads).solve(r)
    assert np.allclose(x, spla.spsolve(A.tocsc(), r), rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("nblocks", [1, 2, 5])
def test_block_tridiagonal_kronecker_couplings(rng: np.random.Generator, nblocks: int) -> None:
    # A = sum_j X_j (x) H_j with X_j block tridiagonal in 2 x 2 element blocks (rank-1
    # off-diagonal blocks, like DG traces) and low-rank H_j: the couplings factored term by
    # term must give the same solution as those factored from A's entries.
    nx, nh = 2, 5
    Xs, Hs = [], []
    for _ in range(2):
        X = sp.lil_matrix((nblocks * nx, nblocks * nx))
        for k in range(nblocks):
            X[k * nx:(k + 1) * nx, k * nx:(k + 1) * nx] = rng.normal(size=(nx, nx))
            if k:
                X[k * nx:(k + 1) * nx, (k - 1) * nx:k * nx] = np.outer(rng.normal(size=nx), rng.normal(size=nx))
                X[(k - 1) * nx:k * nx, k * nx:(k + 1) * nx] = np.outer(rng.normal(size=nx), rng.normal(size=nx))
        Xs.append(X.tocsr())
        Hs.append(rng.normal(size=(nh, 2)) @ rng.normal(size=(2, nh)))
    A = sum(sp.kron(X, H) for X, H in zip(Xs, Hs)) + 10.0 * sp.eye(nblocks * nx * nh)
    A = sp.csr_matrix(A)
    r = rng.normal(size=A.shape[0])
    x = BlockTridiagonal(A, nx * nh, kron=list(zip(Xs, Hs))).solve(r)
    assert np.allclose(x, BlockTridiagonal(A, nx * nh).solve(r), rtol=1e-11, atol=1e-12)
    assert np.allclose(A @ x, r, atol=1e-10)
    with pytest.raises(ValueError, match="does not fit"):
        BlockTridiagonal(A, nx * nh, kron=[(Xs[0], np.eye(3))])


def test_block_tridiagonal_rejects_bad_input() -> None:
    A = sp.eye(6, format="lil")
    A[0, 5] = 1.0
    with pytest.raises(ValueError, match="outside the block tridiagonal"):
        BlockTridiagonal(A.tocsr(), 2)
    with pytest.raises(ValueError, match="multiple of the block size"):
        BlockTridiagonal(sp.eye(7, format="csr"), 2)
    with pytest.raises(ValueError, match="threads"):
        BlockTridiagonal(sp.eye(6, format="csr"), 2, threads=3)


def test_mirror_needs_a_half_mesh() -> None:
    with pytest.raises(ValueError, match="half mesh"):
        assemble_x(np.linspace(-1.0, 1.0, 5), 3, lambda x: 0.0 * x, reflect=True)
    X = assemble_x(np.linspace(0.0, 1.0, 3), 3, lambda x: 0.0 * x, reflect=True)
    # -psi_i(0) phi_j(0): nonzero only on the first element, rank one.
    dense = X.xreflect.toarray()
    assert np.all(dense[4:] == 0.0) and np.all(dense[:, 4:] == 0.0)
    assert np.linalg.matrix_rank(dense) == 1 and dense.trace() < 0.0
