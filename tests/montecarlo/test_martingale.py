"""Martingale control variates: mean exactly 0, the Poisson solution of a harmonic ring, honest errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from fpe_harvester import Harvester, solve
from fpe_harvester.errors import ParameterError
from montecarlo import estimate, simulate
from montecarlo.controls.regression import enough_dof, regression_estimate
from montecarlo.controls.martingale import poisson_controls
from montecarlo.harmonic import twin_expectations


@pytest.mark.parametrize("step", ["frozen", "joint"])
def test_martingale_sums_have_mean_zero_and_leave_the_paths_unchanged(step: str) -> None:
    # a nonlinear ring at a coarse step: every martingale control's mean must be 0 whatever the
    # bias of the scheme (chi^2 of the z-scores of all controls against its 0.1 % tail); the
    # end-of-window terms bd_* are not martingales (mean 0 only for a stationary window) and are
    # left out
    h = Harvester.build(a=0.5, n=3, N=3, k=-0.5)
    kw = dict(dt=0.1, paths=4, replicas=200, t_burn=5.0, t_run=40.0, seed=8, step=step, richardson=True)
    e = simulate(h, controls=("martingale", "boundary"), **kw)
    off = simulate(h, **kw)
    assert np.array_equal(e.sums, off.sums) and np.array_equal(e.counts, off.counts)
    assert e.ctl_names["martingale"] and off.ctl is None and not off.ctl_names
    for half in (False, True):
        mg = e.control_sums("martingale", first_half=half)
        names = [n for n in e.ctl_names["martingale"] if not n.startswith("bd_")]
        z = np.array([mg[n].mean() / (mg[n].std(ddof=1) / math.sqrt(e.replicas)) for n in names])
        assert np.all(np.isfinite(z))
        assert float(z @ z) < chi2.ppf(0.999, z.size), dict(zip(names, z.round(2)))


def test_poisson_control_of_a_harmonic_ring_removes_all_but_the_boundary_term() -> None:
    # N = 2 (harmonic): the Poisson solution is quadratic, its martingale is a fixed combination
    # of the linear and Hermite sums, and with a sample at every step the time average's
    # fluctuation is that martingale times N (the ring mean over N units) up to the boundary
    # term g(Y_0) - g(Y_T), whose share falls like 1/T: reduction > 1e3 at T = 2000
    h = Harvester.build(a=0.5, N=2, k=-0.1)
    dt = 0.04
    e = simulate(h, dt=dt, paths=2, replicas=40, t_burn=0.0, t_run=2000.0, seed=3, sample_every=0.0,
                 start="twin", controls=("martingale", "boundary"))
    names = e.ctl_names["martingale"]
    w = poisson_controls(h, dt, names)
    C = np.column_stack([e.control_sums("martingale")[n] for n in names])
    m = e.moments(0)
    exact = twin_expectations(h, dt)
    for key, y, mu in (("V2", m["V2"], exact["V2"]), ("Pin", m["vxi"], exact["vxi"])):
        r = regression_estimate(y[:, None], (C @ w[key])[:, None], np.zeros(1))
        assert r.reduction[0] > 1e3, (key, r.reduction[0])
        assert r.coef[0, 0] == pytest.approx(h.N, rel=0.05)
        assert abs(r.mean[0] - mu) < 4 * math.sqrt(r.cov[0, 0]), key


def test_martingale_estimate_is_unbiased_at_a_coarse_step() -> None:
    # harmonic ring at dt = 0.2 (fine level 0.1): the scheme's own expectation is known exactly
    # (discrete Lyapunov), so a bias of the controls would show at the regression's precision;
    # the Richardson extrapolation must then meet the exact solver's continuous-time value
    h = Harvester.build(a=0.5, N=3, k=-0.2)
    dt = 0.2
    e = simulate(h, dt=dt, paths=4, replicas=64, t_burn=30.0, t_run=400.0, seed=12, controls=("martingale", "boundary"),
                 richardson=True, step="frozen")
    est = estimate(e, h, controls="martingale")
    disc = twin_expectations(h, dt / 2)
    assert est.controls == "martingale" and est.reduction["eta"] > 5.0
    assert abs(est.mean["V2"] - disc["V2"]) < 4 * est.se["V2"]
    assert abs(est.mean["Pin"] - disc["vxi"]) < 4 * est.se["Pin"]
    exact = solve(h, "exact")
    # the fine level alone is off by its time-step bias, the extrapolation is not
    assert abs(est.mean["eta"] - exact.eta) > 4 * est.se["eta"]
    extrapolated = est.mean["eta"] - est.bias["eta"]
    assert abs(extrapolated - exact.eta) < 4 * math.hypot(est.se["eta"], est.bias_se["eta"])


def test_martingale_error_bars_cover_the_exact_solution_over_seeds() -> None:
    # smoke test of the coverage study (validation.studies.mc.martingale, martingale_coverage): 32
    # seeds of a harmonic pair (20 controls, 48 replicas), errors against the exact discrete value;
    # binomial 0.1 % tails of 68.3 % and 95.4 % of 32 (measured over 100 other seeds: 66 % and 93 %)
    h = Harvester.build(a=0.5, N=2, k=-0.2)
    dt = 0.1
    exact = twin_expectations(h, dt)
    eta = exact["V2"] / exact["vxi"]
    z = []
    for seed in range(32):
        e = simulate(h, dt=dt, paths=2, replicas=48, t_burn=20.0, t_run=60.0, seed=100 + seed, start="twin",
                     controls=("martingale", "boundary"))
        est = estimate(e, h, controls="martingale")
        z.append(abs(est.mean["eta"] - eta) / est.se["eta"])
    z = np.array(z)
    assert 14 <= (z < 1).sum() <= 29, z.round(2)
    assert (z < 2).sum() >= 27, z.round(2)


def test_estimate_controls_argument() -> None:
    h = Harvester.build(a=0.5, n=3)
    e = simulate(h, dt=0.05, paths=4, replicas=4, t_burn=1.0, t_run=2.0, seed=1, controls=("martingale", "boundary"))
    with pytest.raises(ParameterError, match="controls must be None or one of"):
        estimate(e, h, controls="poisson")
    with pytest.raises(ParameterError, match="needs an ensemble with control variates"):
        estimate(e, h, controls="martingale")  # 4 replicas are too few for 15 controls
    with pytest.raises(ParameterError, match=r"controls must be a tuple of distinct names among \('martin"):
        simulate(h, dt=0.05, paths=4, replicas=1, t_run=2.0, controls="martingale")
    with pytest.raises(ParameterError, match="controls must be a tuple"):
        simulate(h, dt=0.05, paths=4, replicas=1, t_run=2.0, controls=("twin",))
    assert enough_dof(24, 11) and not enough_dof(23, 11)
    assert enough_dof(41, 20) and not enough_dof(40, 20)


def test_the_end_of_window_terms_accumulate_with_or_without_the_martingale_sums() -> None:
    # boundary is a control of its own: alone it gives the very sums it gives beside the
    # martingale's, and the martingale's are the same without it
    h = Harvester.build(a=0.5, n=3, N=3, k=-0.5)
    kw = dict(dt=0.05, paths=4, replicas=6, t_burn=2.0, t_run=10.0, seed=5)
    both = simulate(h, controls=("martingale", "boundary"), **kw)
    alone = simulate(h, controls=("boundary",), **kw)
    mg = simulate(h, controls=("martingale",), **kw)
    assert alone.ctl_names == {"boundary": both.ctl_names["boundary"]}
    assert all(name.startswith("bd_") for name in alone.ctl_names["boundary"])
    for half in (False, True):
        for control, e in (("boundary", alone), ("martingale", mg)):
            ref, got = both.control_sums(control, first_half=half), e.control_sums(control, first_half=half)
            assert ref.keys() == got.keys() and all(np.array_equal(ref[k], got[k]) for k in ref)
