"""The kink scheme: DG in (x, v) times Hermite functions of (V, xi), for n = 1."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp

from fpe_harvester import Harvester, ParameterError, Status, solve
from fpe_harvester.fpe import HermiteBasis, stationary
from fpe_harvester.fpe.plane import DGLine, PlaneMesh, lobatto_points
from fpe_harvester.fpe.schemes.xv import hierarchy, kink
from fpe_harvester.fpe.schemes.xv.kinkdisc import KinkDG, KinkSettings, kink_domain
from fpe_harvester.fpe.schemes.xv.modesolve import ModePreconditioner


def test_lobatto_points_are_the_extrema_of_legendre() -> None:
    for p in (1, 2, 3, 5):
        pts = lobatto_points(p)
        assert pts[0] == -1.0 and pts[-1] == 1.0 and np.all(np.diff(pts) > 0)
        # the interior points are the roots of P_p'
        c = np.zeros(p + 1)
        c[-1] = 1.0
        assert np.allclose(np.polynomial.legendre.legval(pts[1:-1], np.polynomial.legendre.legder(c)), 0.0,
                           atol=1e-12)


def test_dg_line_integrates_polynomials_exactly() -> None:
    line = DGLine(np.array([-1.0, 0.0, 0.5, 2.0]), 3)
    s = line.points()
    f = s**3 - 2 * s                                         # in the space: interpolation is exact
    assert float(line.integral() @ f) == pytest.approx((2.0**4 - 1) / 4 - (4.0 - 1.0), rel=1e-13)
    assert float(line.integral(power=2) @ np.ones(line.size)) == pytest.approx((8.0 + 1.0) / 3, rel=1e-13)
    # int psi' phi summed over the test functions is zero inside, the jumps at the ends
    D = line.derivative().toarray()
    assert np.allclose(D.sum(axis=0), 0.0, atol=1e-12)
    # mass matrix against the integral of products of interpolants
    M = line.mass().toarray()
    assert float(f @ M @ np.ones(line.size)) == pytest.approx(float(line.integral() @ f), rel=1e-13)


def test_signed_parts_split_the_weighted_mass_exactly() -> None:
    line = DGLine(np.array([0.0, 1.0, 3.0]), 2)
    s0 = np.array([-1.5, 2.0, -10.0])
    P, N = line.signed_parts(s0, 1.0)
    Mw = lambda c: (line.mass(power=1) + c * line.mass()).toarray()  # noqa: E731
    full = lambda A: sp.block_diag(list(A)).toarray()  # noqa: E731
    for k, c in enumerate(s0):
        assert np.allclose(full(P[k]) + full(N[k]), Mw(c), atol=1e-13)
    assert np.all(N[1] == 0.0) and np.all(P[2] == 0.0)
    # int_1^3 (x - 1.5)^+ dx = 1.125: the sum of the positive part's entries
    assert P[0, 1].sum() == pytest.approx(1.125, rel=1e-13)
    assert N[0, 0].sum() + N[0, 1].sum() == pytest.approx(-(1.5**2) / 2, rel=1e-13)


def test_plane_mesh_layers_and_symmetry() -> None:
    m = PlaneMesh(Lx=5.0, Lv=3.0, Ec=0.1, a=0.5, layers=3, ratio=0.3, bulk_x=4, bulk_v=3)
    x, v = m.x_nodes(), m.v_nodes()
    assert x[0] == 0.0 and x[-1] == 5.0 and np.all(np.diff(x) > 0)
    assert np.allclose(v, -v[::-1]) and 0.0 in v
    xc, vc = 0.1 / 0.5, math.sqrt(0.2)
    assert np.allclose(x[1:4], xc * 0.3 ** np.array([4, 2, 0]))            # ratio q^2 in x
    assert np.allclose(v[v > 0][:3], vc * 0.3 ** np.array([2, 1, 0]))      # ratio q in v
    assert m.elements == (x.size - 1) * (v.size - 1)
    assert m.subdivided(2).elements == 4 * m.elements
    with pytest.raises(ValueError, match="core box"):
        PlaneMesh(Lx=0.1, Lv=3.0, Ec=0.1, a=0.5)
    with pytest.raises(ParameterError, match="ratio"):
        PlaneMesh(Lx=5.0, Lv=3.0, Ec=0.1, a=0.5, ratio=1.0)


def test_two_variable_hermite_basis() -> None:
    hb = HermiteBasis(4, dim=2)
    assert hb.size == math.comb(6, 2) and hb.alphas.shape == (15, 2)
    assert hb.index[(0, 4)] == 14 and hb.parity()[hb.index[(1, 2)]] == -1.0


def test_frame_factor_puts_the_drive_on_the_first_variable() -> None:
    h = Harvester.build(a=1.0, n=1, Kv=2.0, sigma=1.5)
    mo = {"V2": 0.05, "Pin": 0.2, "v2": 0.15, "vV": 0.02}
    fr = hierarchy.KinkFrame.from_moments(h, mo)
    L, s = fr.factor(h)
    assert np.allclose(L @ L.T, fr.Sigma)
    g = np.array([-2.0, 1.5])
    assert np.allclose(g @ L, [s, 0.0])
    # <V xi> from the identity d<V xi>/dt = 0, <xi^2> = D/tau
    assert fr.Sigma[0, 1] == pytest.approx(h.params.Kc * 0.2 / 1.5 / (1 / h.params.tau_p + 1 / h.params.tau))
    with pytest.raises(ValueError, match="positive definite"):
        hierarchy.KinkFrame(np.array([[1.0, 2.0], [2.0, 1.0]]))


@pytest.fixture(scope="module")
def small() -> tuple[Harvester, KinkDG]:
    h = Harvester.build(a=0.5, n=1)
    return h, KinkDG.build(h, KinkSettings(layers=2, bulk_x=4, bulk_v=3, order=3), tol=1e-3)


def test_mode_operator_matches_the_assembled_hierarchy(small: tuple[Harvester, KinkDG]) -> None:
    """The matrix-free operator in the mode basis equals the sparse operator of the
    hierarchy in the Hermite basis (assembled term by term), with a shifted frame."""
    h, disc = small
    fr = hierarchy.KinkFrame(disc.frame.Sigma, np.array([0.1, 0.4]), np.array([0.3, 0.0]))
    hi = hierarchy.KinkHierarchy.of(h, 3, fr)
    pl = hierarchy.kink_plane(h, disc.base, 3, hi.gamma_e, hi.kappa)
    parts = kink.face_parts(pl, hi)
    T = kink.mode_transport(pl, hi, parts)
    op = kink.ModeOperator(pl, hi, parts)
    rng = np.random.default_rng(1)
    D = rng.standard_normal((pl.S_I.shape[0], hi.hb.size))
    blocks = sp.block_diag(T, format="csr")
    n, nh = D.shape
    transport = (blocks @ D.T.ravel()).reshape(nh, n).T
    direct = (transport + pl.S_K0 @ D @ hi.K0m.T + pl.S_K1 @ D @ hi.K1m.T + pl.S_K2 @ D @ hi.K2m.T
              + pl.S_S @ D @ hi.Pm.T)
    assert np.allclose(op(D), direct, atol=1e-12 * np.abs(direct).max())
    # mass conservation: the beta = 0 row of the Hermite-basis operator sums to the outflow
    # only (no interior source): the test function 1 sees no K0/K1/K2 term
    assert np.allclose((hi.R @ hi.K0m @ hi.R.T)[0], 0.0, atol=1e-12)


@pytest.mark.parametrize("threads", [1, 2])
def test_mode_sweep_solves_the_block_lower_triangle(small: tuple[Harvester, KinkDG], threads: int) -> None:
    """The preconditioner's sweep solves A's block lower triangle over the mode groups in
    sweep order (each group's block without the coupling of its two modes by K0, K1, K2;
    with two threads, each segment's), checked against the matrix-free operator, with a
    shifted frame (K2 != 0)."""
    h, disc = small
    fr = hierarchy.KinkFrame(disc.frame.Sigma, np.array([0.1, 0.4]), np.array([0.3, 0.0]))
    hi = hierarchy.KinkHierarchy.of(h, 4, fr)
    pl = hierarchy.kink_plane(h, disc.base, 2, hi.gamma_e, hi.kappa)
    parts = kink.face_parts(pl, hi)
    prec = ModePreconditioner(kink.mode_transport(pl, hi, parts), pl, hi, threads)
    op = kink.ModeOperator(pl, hi, parts)
    assert sorted(np.concatenate(prec.groups).tolist()) == list(range(hi.hb.size))
    assert any(g.size == 2 for g in prec.groups)
    r = np.random.default_rng(2).standard_normal((pl.S_I.shape[0], hi.hb.size))
    y = prec(r)
    done = np.zeros(hi.hb.size, dtype=bool)
    for k, g in enumerate(prec.groups):
        if k == prec.segments[-1][0]:
            done[:] = False
        done[g] = True
        lower = op(np.where(done, y, 0.0))[:, g]
        for Km, S in ((hi.K0m, pl.S_K0), (hi.K1m, pl.S_K1), (hi.K2m, pl.S_K2)):
            own = Km[np.ix_(g, g)] - np.diag(np.diag(Km[np.ix_(g, g)]))
            lower -= S @ y[:, g] @ own.T
        assert np.allclose(lower, r[:, g], atol=1e-10 * np.abs(r).max())
    assert len(prec.segments) == threads
    with pytest.raises(ValueError, match="threads must be 1 or 2"):
        ModePreconditioner([], pl, hi, 3)


def test_level_is_a_density_with_the_stationary_identities(small: tuple[Harvester, KinkDG]) -> None:
    h, disc = small
    lv = disc.solve(4, 1)
    mo = lv.moments
    assert abs(mo["res_V2"]) < 1e-5 and abs(mo["res_power"]) < 1e-5
    assert abs(mo["xv"]) < 1e-3 * math.sqrt(mo["x2"] * mo["v2"])   # <x v> = 0 in a stationary state
    x = np.linspace(-lv.mesh.Lx, lv.mesh.Lx, 2000)  # no point at x = 0, where DG has one-sided values
    f = lv.fields(x)
    assert np.trapezoid(f["density"], x) == pytest.approx(1.0, abs=2e-3)
    assert np.allclose(f["density"], f["density"][::-1], atol=1e-12)      # mirror symmetry
    assert np.allclose(f["V_mean"], -f["V_mean"][::-1], atol=1e-12)
    # the (x, v) marginal is nonnegative where it carries mass and peaks near the trap
    p = lv.marginal(np.array([0.0, 0.5, 1.0]), np.array([-0.2, 0.0, 0.2]))
    assert p.shape == (3, 3) and p.min() > 0.0


def test_hermite_degree_converges(small: tuple[Harvester, KinkDG]) -> None:
    """Convergence in M (a = 0.5): the steps between M = 2, 4, 6 contract (a check of
    convergence, not of correctness: see the cross-solver tests)."""
    h, disc = small
    eta = [disc.solve(M, 1).moments["eta"] for M in (2, 4, 6)]
    assert abs(eta[2] - eta[1]) < 0.2 * abs(eta[1] - eta[0])


def test_kink_result_agrees_with_the_one_dimensional_scheme() -> None:
    """Two discretizations that share no mesh and no weight: DG in (x, v) x Hermite (V, xi)
    against DG in x x Hermite (v, V, xi), each within its own error bar (a = 0.5)."""
    h = Harvester.build(a=0.5, n=1)
    new = solve(h, "fpe", tol=1e-3)
    old = solve(h, "fpe", tol=3e-3, scheme="x")
    assert new.status is Status.STABLE and new.info["scheme"] == "xv"
    assert old.info["scheme"] == "x"
    assert abs(new.eta - old.eta) <= 3.0 * math.hypot(new.eta_err, old.eta_err)
    assert new.eta_err / new.eta <= 1e-3


def test_scheme_errors() -> None:
    with pytest.raises(ParameterError, match="scheme must be one of"):
        solve(Harvester.build(a=0.5, n=1), "fpe", scheme="2d")
    with pytest.raises(ParameterError, match="scheme='xv'.*n = 1"):
        stationary(Harvester.build(a=0.5, n=3), scheme="xv")


def test_domain_grows_with_the_drive() -> None:
    h = Harvester.build(a=2.0, n=1)
    Lx, Lv = kink_domain(h, v2=0.018, sF=1.0)
    assert Lv == pytest.approx(4.5) and Lx == pytest.approx(4.5**2 / 4)
    Lx2, Lv2 = kink_domain(h.replace(sigma=2.0), v2=0.018, sF=2.0)
    assert Lv2 > Lv and Lx2 > Lx


def test_energy_cdf_integrates_the_marginal(small: tuple[Harvester, KinkDG]) -> None:
    """P(E < eps) by the mapped Gauss rule against a brute-force grid sum of the (x, v)
    marginal over the region m v^2/2 + a|x| < eps; and P -> 1 once the region holds the mass."""
    h, disc = small
    lv = disc.solve(4, 1)
    eps = 0.3
    xs = np.linspace(-eps / h.a, eps / h.a, 801)
    vs = np.linspace(-math.sqrt(2 * eps), math.sqrt(2 * eps), 801)
    p = lv.marginal(xs, vs)
    inside = 0.5 * vs[None, :] ** 2 + h.a * np.abs(xs[:, None]) < eps
    brute = float(np.sum(p * inside)) * (xs[1] - xs[0]) * (vs[1] - vs[0])
    P = lv.energy_cdf(np.array([1e-3, 0.03, eps, 3.0]), nodes=48)
    assert P[2] == pytest.approx(brute, rel=5e-3)
    assert np.all(np.diff(P) > 0) and P[-1] == pytest.approx(1.0, abs=2e-3)
    with pytest.raises(ValueError, match="eps must be positive"):
        lv.energy_cdf(np.array([0.0]))


def test_weight_belongs_to_the_one_dimensional_scheme() -> None:
    from fpe_harvester.fpe import stationary
    from fpe_harvester.fpe.schemes.x.discretize import Whitening

    h = Harvester.build(a=0.5, n=1)
    with pytest.raises(ParameterError, match="weight is the Gaussian weight of scheme 'x'"):
        stationary(h, weight=Whitening.of(h))
    with pytest.raises(ParameterError, match="weight must be a Whitening"):
        stationary(Harvester.build(a=0.5, n=3), weight="wide")
