"""Potentials 1 < n < 2 (force not smooth at x = 0): geometric mesh, scheme boundaries."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fpe_harvester import Harvester, ParameterError, solve
from fpe_harvester.fpe import stationary
from fpe_harvester.fpe.discretize import Whitening, solve_level
from fpe_harvester.fpe.stationary import default_plan


def test_mesh_error_falls_geometrically_with_layers() -> None:
    """n = 1.5, a = 1, M = 6 on 8 bulk elements per half: the error of eta against 12 layers
    falls by a factor of about 0.45 per layer (convergence in the layers, not correctness)."""
    h = Harvester.build(a=1.0, n=1.5)
    w = Whitening.of(h)
    plan = default_plan(h, mesh="geometric")

    def eta(layers: int) -> float:
        mesh = dataclasses.replace(plan, layers=layers).mesh(h, w, 8)
        return solve_level(h, 6, mesh, plan.order, w).moments["eta"]

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
    """n = 1.02, 1.05, 1.1 at a = 0.5 converge (tol 3e-3) and lie on a line within their
    error bars. At tol = 1e-3 these n do not converge in 60 s: the Hermite expansion in v
    converges algebraically there, as at the kink."""
    ns = (1.02, 1.05, 1.1)
    res = {n: solve(Harvester.build(a=0.5, n=n), "fpe", tol=3e-3) for n in ns}
    assert all(r.status.value == "stable" for r in res.values())
    # linear extrapolation from 1.05 and 1.1 to 1.02: weights 1.6 and -0.6
    line = 1.6 * res[1.05].eta - 0.6 * res[1.1].eta
    bound = res[1.02].eta_err + 1.6 * res[1.05].eta_err + 0.6 * res[1.1].eta_err
    assert abs(res[1.02].eta - line) <= bound


@pytest.mark.slow
def test_eta_near_1_meets_the_kink() -> None:
    """n = 1.02 (scheme 'x') against the kink n = 1 (scheme 'xv'): the difference is the
    slope of eta(n) over 0.02 (measured -0.15 per unit n from 1.05 to 1.1) within the
    error bars."""
    kink = solve(Harvester.build(a=0.5, n=1.0), "fpe", tol=1e-2)
    near = {n: solve(Harvester.build(a=0.5, n=n), "fpe", tol=3e-3) for n in (1.02, 1.1)}
    slope = (near[1.1].eta - near[1.02].eta) / 0.08
    predicted = near[1.02].eta - 0.02 * slope
    assert abs(kink.eta - predicted) <= kink.eta_err + 1.25 * near[1.02].eta_err + 0.25 * near[1.1].eta_err
