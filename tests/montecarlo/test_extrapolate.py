"""The Richardson-extrapolation policy: the third coupled level, the extrapolated value and its
error bar, checked against exact values that share none of the Monte Carlo's errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fpe_harvester import Harvester, solve
from fpe_harvester.errors import ParameterError
from montecarlo import MonteCarlo, estimate, simulate
from montecarlo.estimate import RESIDUAL_RULE
from montecarlo.twin import twin_expectations


def _discrete_eta(h: Harvester, dt: float, joint: bool) -> float:
    m = twin_expectations(h, dt, 2.0, joint)
    return m["V2"] / (h.params.R * h.params.sigma * m["vxi"])


@pytest.mark.parametrize("joint", [False, True])
@pytest.mark.parametrize("dt", [0.04, 0.16, 0.32])
@pytest.mark.parametrize("k", [0.0, -0.2, -0.3])
def test_residual_rule_bounds_the_extrapolation_error_of_harmonic_schemes(k: float, dt: float,
                                                                          joint: bool) -> None:
    # exact stationary values of the discrete schemes (discrete Lyapunov) against the exact
    # solver: no sampling noise. The rule's D / (2^q - 1) must cover the extrapolation's error
    # (measured ratio 0.40-0.47 for the frozen step, whose next term is dt^4, and 0.87-0.99
    # for the joint ring, dt^3); the joint step is exact for a single unit (both ~1e-16)
    h = Harvester.build(a=0.5, N=1 if k == 0.0 else 3, k=k)
    exact = solve(h, "exact").eta
    eta = {d: _discrete_eta(h, d, joint) for d in (dt / 2, dt, 2 * dt)}
    scale = 1.0 / 3.0
    r_fine = eta[dt / 2] + scale * (eta[dt / 2] - eta[dt])
    r_coarse = eta[dt] + scale * (eta[dt] - eta[2 * dt])
    bound = abs(r_coarse - r_fine) / (2.0 ** RESIDUAL_RULE[0] - 1.0)
    assert abs(r_fine - exact) <= bound + 1e-12
    assert abs(r_fine - exact) <= abs(eta[dt / 2] - exact) + 1e-12


def test_coarsest_level_has_the_law_of_its_own_step() -> None:
    # frozen step on a harmonic ring at coarse steps, where the three levels' exact discrete
    # values differ by many standard errors: each level must match the value at its own step
    h = Harvester.build(a=0.5, N=3, k=-0.2)
    e = simulate(h, dt=0.16, paths=32, replicas=16, t_burn=20.0, t_run=100.0, seed=3, richardson=True,
                 third_level=True, start="twin", joint=False)
    assert e.dts == (0.08, 0.16, 0.32)
    for level, d in enumerate(e.dts):
        ex = twin_expectations(h, d, 2.0, False)
        m = e.moments(level)
        for name in ("V2", "x2"):
            se = m[name].std(ddof=1) / math.sqrt(m[name].size)
            assert abs(m[name].mean() - ex[name]) < 4 * se, (level, name)
    # the levels are distinguishable: the coarsest level's exact V2 is off the fine one's by
    # far more than the test's resolution
    ex0, ex2 = twin_expectations(h, 0.08, 2.0, False), twin_expectations(h, 0.32, 2.0, False)
    v = e.moments(2)["V2"]
    assert abs(ex2["V2"] - ex0["V2"]) > 8 * v.std(ddof=1) / math.sqrt(v.size)


def test_extrapolated_solve_is_unbiased_where_the_fine_level_is_not() -> None:
    # harmonic ring at a coarse explicit step: the fine level's bias is many of the extrapolated
    # value's error bars, the extrapolated value lies within its error bar of the exact solver
    h = Harvester.build(a=0.5, N=3, k=-0.2)
    exact = solve(h, "exact").eta
    r = solve(h, MonteCarlo(seed=5, dt=0.16, tol=2e-4, progress=False, joint=False))
    assert r.info["extrapolated"] and r.info["dt_coarsest"] == 0.32
    fine_bias = _discrete_eta(h, 0.08, False) - exact
    assert abs(fine_bias) > 5 * r.eta_err
    assert abs(r.eta - exact) < 3 * r.eta_err, (r.eta, exact, r.eta_err)


def test_old_policy_is_selectable_and_reports_the_fine_level() -> None:
    h = Harvester.build(a=0.5, N=3, k=-0.2)
    new = MonteCarlo(seed=1, tol=1e-2, progress=False).plan(h)
    old = MonteCarlo(seed=1, tol=1e-2, progress=False, extrapolate=False).plan(h)
    assert new.dt == 2 * old.dt
    r = solve(h, MonteCarlo(seed=1, tol=1e-2, progress=False, extrapolate=False, t_run=20.0))
    assert not r.info["extrapolated"] and r.info["dt_coarsest"] is None
    assert r.eta_err == pytest.approx(math.hypot(r.info["eta_standard_error"], r.info["bias_eta"]))


def test_extrapolate_errors() -> None:
    h = Harvester.build(a=0.5)
    e = simulate(h, dt=0.1, paths=4, replicas=4, t_burn=1.0, t_run=5.0, seed=1, richardson=True)
    with pytest.raises(ParameterError, match="extrapolate=True needs three levels"):
        estimate(e, h, extrapolate=True)
    with pytest.raises(ParameterError, match="third_level must be True or False, got 1"):
        simulate(h, dt=0.1, paths=4, replicas=1, t_run=1.0, richardson=True, third_level=1)
    with pytest.raises(ParameterError, match="extrapolate must be True or False"):
        MonteCarlo(extrapolate="yes")
    # without Richardson there is no third level
    e1 = simulate(h, dt=0.1, paths=4, replicas=2, t_burn=1.0, t_run=5.0, seed=1, third_level=True)
    assert e1.dts == (0.1,)
    assert np.all(np.isfinite(e1.sums))
