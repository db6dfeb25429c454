"""Potentials 1 < n < 2 (force not smooth at x = 0): geometric mesh, scheme boundaries."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fpe_harvester import Harvester, ParameterError, solve
from fpe_harvester.fpe import stationary
from fpe_harvester.fpe.schemes.x import XMeshRule
from fpe_harvester.fpe.schemes.x.discretize import Whitening, solve_level


def test_mesh_error_falls_geometrically_with_layers() -> None:
    """n = 1.5, a = 1, M = 6 on 8 bulk elements per half: the error of eta against 12 layers
    falls by a factor of about 0.45 per layer (convergence in the layers, not correctness)."""
    h = Harvester.build(a=1.0, n=1.5)
    w = Whitening.of(h)
    rule = XMeshRule.of(h, mesh="geometric")

    def eta(layers: int) -> float:
        mesh = dataclasses.replace(rule, layers=layers).build(h, w, 8)
        return solve_level(h, 6, mesh, 3, w).moments["eta"]

    ref = eta(12)
    errors = np.array([abs(eta(k) - ref) for k in range(5)])
    assert np.all(errors[2:] < 0.7 * errors[1:-1]), errors
    rate = np.exp(np.polyfit(np.arange(1, 5), np.log(errors[1:]), 1)[0])
    assert rate < 0.6, rate
    assert errors[4] < 1e-2 * errors[0], errors


def test_geometric_and_algebraic_meshes_agree() -> None:
    h = Harvester.build(a=0.5, n=1.5)
    alg = solve(h, "fpe", tol=1e-3, mesh="algebraic")
    geo = solve(h, "fpe", tol=1e-3, mesh="geometric")
    assert alg.status.value == geo.status.value == "stable"
    assert geo.info["elements"] > alg.info["elements"]  # the layers
    assert abs(alg.eta - geo.eta) <= alg.eta_err + geo.eta_err


def test_geometric_mesh_is_refused_where_it_does_not_apply() -> None:
    with pytest.raises(ParameterError, match="mesh='geometric'"):
        stationary(Harvester.build(a=1.0, n=3.0), mesh="geometric")
    with pytest.raises(ParameterError, match="mesh must be one of"):
        solve(Harvester.build(a=1.0, n=1.5), "fpe", mesh="hp")
    with pytest.raises(ParameterError, match="scheme 'x'"):
        stationary(Harvester.build(a=1.0, n=1.0), mesh="algebraic")


def test_eta_is_continuous_across_n_equals_2() -> None:
    """n = 1.98 (marginal weight, mesh graded toward 0) and n = 2.02 (conditional weight,
    wall-graded mesh) bracket the exact n = 2: their mean is eta(2) within the error bars
    (the curvature of eta(n) over 0.02 is ~4e-6, ten times smaller)."""
    res = {n: solve(Harvester.build(a=1.0, n=n), "fpe", tol=1e-3) for n in (1.98, 2.0, 2.02)}
    assert all(r.status.value == "stable" for r in res.values())
    mean = 0.5 * (res[1.98].eta + res[2.02].eta)
    bound = res[1.98].eta_err + res[2.02].eta_err + 2.0 * res[2.0].eta_err
    assert abs(mean - res[2.0].eta) <= bound
    assert res[1.98].eta < res[2.0].eta < res[2.02].eta


def test_eta_is_smooth_toward_n_equals_1() -> None:
    """n = 1.02, 1.05, 1.1 at a = 0.5 converge (tol 3e-3, the default scheme: DG in (x, v))
    and lie on a line within their error bars."""
    ns = (1.02, 1.05, 1.1)
    res = {n: solve(Harvester.build(a=0.5, n=n), "fpe", tol=3e-3) for n in ns}
    assert all(r.status.value == "stable" for r in res.values())
    # linear extrapolation from 1.05 and 1.1 to 1.02: weights 1.6 and -0.6
    line = 1.6 * res[1.05].eta - 0.6 * res[1.1].eta
    bound = res[1.02].eta_err + 1.6 * res[1.05].eta_err + 0.6 * res[1.1].eta_err
    assert abs(res[1.02].eta - line) <= bound


@pytest.mark.slow
def test_eta_near_1_meets_the_kink() -> None:
    """n = 1.02 (one core element toward the origin) against the kink n = 1 (four layers
    toward the trap), both by DG in (x, v): the difference is the
    slope of eta(n) over 0.02 (measured -0.15 per unit n from 1.05 to 1.1) within the
    error bars."""
    kink = solve(Harvester.build(a=0.5, n=1.0), "fpe", tol=1e-2)
    near = {n: solve(Harvester.build(a=0.5, n=n), "fpe", tol=3e-3) for n in (1.02, 1.1)}
    slope = (near[1.1].eta - near[1.02].eta) / 0.08
    predicted = near[1.02].eta - 0.02 * slope
    assert abs(kink.eta - predicted) <= kink.eta_err + 1.25 * near[1.02].eta_err + 0.25 * near[1.1].eta_err


def test_power_mass_is_exact_on_the_element_at_zero() -> None:
    """int x^q psi_i psi_j against closed forms: the Lagrange basis sums to 1 and
    interpolates x, so 1^T M 1 = L^(q+1)/(q+1) and 1^T M x = L^(q+2)/(q+2) (exact
    quadrature: Gauss-Jacobi on the element at 0)."""
    from fpe_harvester.fpe.plane import DGLine

    X = DGLine(np.array([0.0, 0.3, 0.7, 2.0]), 3)
    for q in (0.25, 0.5, 0.75):
        M = X.power_mass(q)
        one, x = np.ones(X.size), X.points()
        assert one @ M @ one == pytest.approx(2.0 ** (q + 1) / (q + 1), rel=1e-12)
        assert one @ M @ x == pytest.approx(2.0 ** (q + 2) / (q + 2), rel=1e-12)
    assert np.allclose(X.power_mass(1.0).toarray(), X.mass(power=1).toarray(), atol=1e-14)


def test_signed_parts_of_a_power_law_speed() -> None:
    """u(x) = s0 - A x^q split at its root x* = (s0/A)^(1/q): the positive part integrates
    to s0 x* - A x*^(q+1)/(q+1) (closed form, root inside the element at 0), the two parts
    add up to the whole, and a negative s0 has no positive part."""
    from fpe_harvester.fpe.plane import DGLine

    X = DGLine(np.array([0.0, 0.5, 1.0]), 3)
    A, q = 1.5, 0.5
    s0 = np.array([0.6, -0.2])
    P, N = X.signed_parts(s0, 0.0, A, q)
    r = (0.6 / A) ** (1.0 / q)
    assert P[0, 0].sum() == pytest.approx(0.6 * r - A * r ** (q + 1) / (q + 1), rel=1e-12)
    whole = (s0[:, None, None] * X.mass().toarray()[None] - A * X.power_mass(q).toarray()[None])
    blocks = np.stack([np.block([[P[k, 0] + N[k, 0], np.zeros((4, 4))], [np.zeros((4, 4)), P[k, 1] + N[k, 1]]])
                       for k in range(2)])
    assert np.allclose(blocks, whole, atol=1e-14)
    assert np.all(P[1] == 0.0)


def test_kink_scheme_takes_sub_quadratic_n() -> None:
    """n = 1.5, a = 0.5 by DG in (x, v) with Hermite in (V, xi) (scheme 'xv') against DG in x
    with Hermite in (v, V, xi) (scheme 'x'): two discretizations that share no error, equal
    within their error bars (a correctness check)."""
    h = Harvester.build(a=0.5, n=1.5)
    xv = solve(h, "fpe", tol=3e-3, scheme="xv")
    x = solve(h, "fpe", tol=3e-3, scheme="x")
    assert xv.status.value == x.status.value == "stable"
    assert xv.info["scheme"] == "xv"
    assert abs(xv.eta - x.eta) <= xv.eta_err + x.eta_err


def test_auto_scheme_for_sub_quadratic_n() -> None:
    """1 < n < 2 is solved by DG in (x, v) unless an x-only setting is given; the kink's
    energy distribution is refused there (its energy is a|x| + m v^2/2)."""
    from fpe_harvester.fpe.schemes import resolve_scheme
    from fpe_harvester.fpe.settings import Settings

    h = Harvester.build(a=1.0, n=1.5)
    assert resolve_scheme(h, Settings()).name == "xv"
    assert resolve_scheme(h, Settings(mesh="algebraic")).name == "x"
    assert resolve_scheme(h, Settings(elements=16)).name == "x"
    assert resolve_scheme(Harvester.build(a=1.0, n=1.0), Settings(elements=16)).name == "xv"
    assert resolve_scheme(Harvester.build(a=1.0, n=2.0), Settings()).name == "x"
    sol = stationary(h, tol=1e-2, M=4)
    assert sol.stats.info["scheme"] == "xv"
    with pytest.raises(ValueError, match="energy_cdf is the kink's"):
        sol.level.energy_cdf(np.array([0.1]))
