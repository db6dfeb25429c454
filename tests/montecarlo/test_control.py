"""Harmonic twin and control variates: exact discrete moments, unbiased estimates, honest errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fpe_harvester import Harvester, Status, solve
from fpe_harvester.errors import ParameterError
from fpe_harvester.exact import dense_covariance, mode_moments
from montecarlo import estimate, simulate
from montecarlo.controls import sets
from montecarlo.controls.base import Control
from montecarlo.controls.regression import regression_estimate
from montecarlo.controls.twin import TWIN_MOMENTS
from montecarlo.harmonic import initial_cholesky, linearized_stiffness, twin_expectations, twin_harvester


def test_twin_expectations_tend_to_the_closed_form_as_dt_shrinks() -> None:
    lin = Harvester.build(a=0.6, N=3, k=-0.25)
    exact = {key: float(np.mean(val)) for key, val in
             mode_moments(lin.mode_stiffness(), lin.params).items()}
    errs = []
    for dt in (0.04, 0.02, 0.01):
        t = twin_expectations(lin, dt)
        errs.append(abs(t["V2"] / exact["V2"] - 1) + abs(t["vxi"] / exact["vxi"] - 1))
        assert t["x4"] == pytest.approx(3 * t["x2"] ** 2, rel=1e-12)
    order = np.polyfit(np.log([0.04, 0.02, 0.01]), np.log(errs), 1)[0]
    assert 1.9 < order < 2.1, order
    assert errs[-1] < 1e-4


def test_initial_law_is_the_ring_covariance() -> None:
    lin = Harvester.build(a=0.5, N=4, k=0.3)
    L = initial_cholesky(lin, 1e-4)
    C = L @ L.T
    dense = dense_covariance(lin)
    assert np.allclose(C, dense, rtol=2e-3, atol=2e-4 * np.abs(dense).max())


@pytest.mark.parametrize("step", ["frozen", "joint"])
def test_simulated_twin_matches_its_discrete_expectations_not_the_continuous_ones(step: str) -> None:
    # dt = 0.4: the scheme's bias (~5 %) is far larger than the standard errors
    h = Harvester.build(a=0.5, n=3, N=3, k=-0.2)
    kappa = 1.3
    e = simulate(h, dt=0.4, paths=64, replicas=24, t_burn=0.0, t_run=200.0, seed=6, twin=kappa,
                 start="twin", sample_every=0.0, step=step)
    m = e.moments(0)
    lin = twin_harvester(h, kappa)
    cont = {key: float(np.mean(val)) for key, val in mode_moments(lin.mode_stiffness(), lin.params).items()}
    for name in TWIN_MOMENTS:
        x = m["t_" + name]
        se = x.std(ddof=1) / math.sqrt(x.size)
        assert abs(x.mean() - e.twin_mean[name]) < 4 * se, name
    se = m["t_vxi"].std(ddof=1) / math.sqrt(24)
    if step == "joint":
        # the joint step's only bias in a harmonic ring is the neighbours' force held at its
        # predicted midpoint: far smaller, within the standard error here
        assert abs(e.twin_mean["vxi"] - cont["vxi"]) < 1e-3 * cont["vxi"]
    else:
        assert abs(m["t_vxi"].mean() - cont["vxi"]) > 10 * se


@pytest.mark.parametrize("step", ["frozen", "joint"])
def test_control_variates_are_unbiased_on_a_harmonic_system(step: str) -> None:
    # the system is harmonic, so its discrete-time expectation is known exactly; a twin of
    # another stiffness must not bias the estimate, and must reduce its variance
    h = Harvester.build(a=0.5, N=3, k=-0.2)
    dt = 0.4
    e = simulate(h, dt=dt, paths=32, replicas=48, t_burn=40.0, t_run=100.0, seed=9, twin=1.4,
                 start="twin", step=step)
    est = estimate(e, h, control=True)
    ref = twin_expectations(h, dt, step=step)
    assert est.control and est.reduction["eta"] > 2.0
    assert abs(est.mean["V2"] - ref["V2"]) < 4 * est.se["V2"]
    assert abs(est.mean["Pin"] - ref["vxi"]) < 4 * est.se["Pin"]
    plain = estimate(e, h, control=False)
    assert est.se["eta"] < plain.se["eta"]


def test_regression_estimate_recovers_a_linear_model_with_honest_errors(rng) -> None:
    R, p = 60, 3
    z = []
    for _ in range(300):
        C = rng.normal(size=(R, p))
        y = 1.0 + C @ np.array([2.0, -1.0, 0.5]) + 0.3 * rng.normal(size=R)
        r = regression_estimate(y[:, None], C, np.zeros(p))
        z.append((r.mean[0] - 1.0) / math.sqrt(r.cov[0, 0]))
    z = np.abs(np.array(z))
    # t with 56 degrees of freedom: 68.0 % within 1, 95.0 % within 2 standard errors
    assert 0.62 < (z < 1).mean() < 0.74
    assert 0.92 < (z < 2).mean() < 0.98


def test_regression_estimate_bad_input() -> None:
    with pytest.raises(ParameterError, match="shapes must be"):
        regression_estimate(np.zeros(5), np.zeros((5, 1)), np.zeros(1))
    with pytest.raises(ParameterError, match="more replicas than controls"):
        regression_estimate(np.zeros((3, 1)), np.zeros((3, 2)), np.zeros(2))


def test_estimate_control_true_refuses_an_ensemble_without_twin() -> None:
    h = Harvester.build(a=0.5, n=3)
    e = simulate(h, dt=0.05, paths=4, replicas=4, t_burn=1.0, t_run=2.0, seed=1)
    with pytest.raises(ParameterError, match="control=True needs"):
        estimate(e, h, control=True)


def test_linearized_stiffness() -> None:
    assert linearized_stiffness(Harvester.build(a=0.7, N=3, k=-0.1)) == pytest.approx(1.4)
    h = Harvester.build(a=0.5, n=3)
    kappa = linearized_stiffness(h)
    s2 = float(mode_moments(kappa, h.params)["x2"])
    c3 = 0.5 * 3 * 2**1.5 * math.gamma(2.0) / math.sqrt(math.pi)
    assert kappa == pytest.approx(c3 * s2**0.5, rel=1e-10)
    assert linearized_stiffness(h, xdU=2.0, x2=4.0) == 0.5
    # a twin whose anti-phase mode would have negative stiffness is refused
    assert linearized_stiffness(Harvester.build(a=0.5, n=3, N=3, k=-0.5), xdU=1.0, x2=1.0) is None
    with pytest.raises(ParameterError, match="both xdU and x2"):
        linearized_stiffness(h, xdU=1.0)


def test_simulate_twin_argument_errors() -> None:
    h = Harvester.build(a=0.5, n=3, N=3, k=-0.5)
    with pytest.raises(ParameterError, match="twin must give every twin mode"):
        simulate(h, dt=0.05, paths=2, replicas=1, t_run=1.0, twin=1.0)
    with pytest.raises(ParameterError, match="start must be"):
        simulate(h, dt=0.05, paths=2, replicas=1, t_run=1.0, start="cold")
    with pytest.raises(ParameterError, match="needs a twin stiffness"):
        simulate(h, dt=0.05, paths=2, replicas=1, t_run=1.0, start="twin")


def test_solver_uses_the_twin_and_agrees_with_plain_runs() -> None:
    h = Harvester.build(a=0.5, n=3)
    opts = dict(tol=1e-2, paths=32, progress=False)
    cv = solve(h, "mc", seed=3, **opts)
    plain = solve(h, "mc", seed=4, control=False, martingale=False, **opts)
    assert cv.status is Status.STABLE and plain.status is Status.STABLE
    assert cv.info["control_variates"] and cv.info["start"] == "twin"
    assert cv.info["variance_reduction"] > 3.0
    assert not plain.info["control_variates"] and plain.info["variance_reduction"] is None
    assert abs(cv.eta - plain.eta) < 4 * math.hypot(cv.eta_err, plain.eta_err)
    assert cv.info["eta_standard_error"] < plain.info["eta_standard_error"]


def test_regression_leaves_out_a_control_constant_to_round_off(rng) -> None:
    # a control whose spread is round-off (the twin's v xi estimate at tau << dt) and whose
    # mean is off mu by round-off must not inflate the error through the lever term
    c = rng.normal(size=(64, 1))
    y = 1.0 + 2.0 * c + 0.1 * rng.normal(size=(64, 1))
    flat = 0.5 + 1e-16 * rng.normal(size=(64, 1))
    ref = regression_estimate(y, c, np.zeros(1))
    r = regression_estimate(y, np.hstack([c, flat]), np.array([0.0, 0.5 + 1e-14]))
    assert r.mean[0] == pytest.approx(ref.mean[0], rel=1e-12)
    assert r.cov[0, 0] == pytest.approx(ref.cov[0, 0] * (64 - 2) / (64 - 3), rel=1e-9)


class _NoiseOnly(Control):
    """The martingale's noise-only sums (``he_*``, mean 0 exactly) as a control of their own."""

    name = "noise"

    def columns(self, e, valid):
        names = [n for n in e.ctl_names.get("martingale", ()) if n.startswith("he_")]
        if not names:
            return None
        mg, first = e.control_sums("martingale"), e.control_sums("martingale", first_half=True)
        return [mg[n][valid] for n in names], [first[n][valid] for n in names], [0.0] * len(names)


def test_a_registered_control_reaches_the_estimate(monkeypatch) -> None:
    # a new control is its object in CONTROLS and a set that names it: nothing else changes
    monkeypatch.setitem(sets.CONTROLS, "noise", _NoiseOnly())
    monkeypatch.setitem(sets.CONTROL_SETS, "noise", ("noise",))
    h = Harvester.build(a=0.5, n=3)
    e = simulate(h, dt=0.05, paths=4, replicas=40, t_burn=5.0, t_run=20.0, seed=2, controls=("martingale", "boundary"))
    est = estimate(e, h, controls="noise")
    assert est.control and est.controls == "noise"
    with pytest.raises(ParameterError, match="needs an ensemble with control variates"):
        estimate(simulate(h, dt=0.05, paths=4, replicas=40, t_burn=5.0, t_run=20.0, seed=2), h, controls="noise")
