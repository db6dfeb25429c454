"""MonteCarlo solver: agreement with the exact harmonic solver, identities, statuses, seeds."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fpe_harvester import Harvester, Status, solve
from fpe_harvester.errors import ParameterError
from montecarlo import MonteCarlo

FAST = dict(tol=0.02, dt=0.05, paths=128, t_run=50.0, min_replicas=6, progress=False)


@pytest.mark.parametrize(
    ("N", "k", "seed"),
    [(1, 0.0, 1), (2, -0.15, 2), (3, -0.2, 3), (5, -0.15, 4), (5, 0.3, 5)],
)
def test_harmonic_rings_agree_with_exact(N: int, k: float, seed: int) -> None:
    h = Harvester.build(a=0.5, n=2, N=N, k=k)
    ex = solve(h, "exact")
    mc = solve(h, "mc", seed=seed, **FAST)
    assert mc.status is Status.STABLE, mc.message
    for name in ("eta", "V2", "Pin", "v2", "vV"):
        value, err = mc.value(name)
        assert err > 0
        assert abs(value - getattr(ex, name)) < 4 * err, (name, value, err, getattr(ex, name))
    assert mc.eta_err / mc.eta < 0.02


def test_spec_identities_hold_within_error() -> None:
    h = Harvester.build(a=0.5, n=3, N=3, k=-0.3)
    r = solve(h, "mc", seed=7, **FAST)
    p = h.params
    res1, se1 = r.info["identity_V2_minus_KcTaup_vV"]
    res2, se2 = r.info["identity_Pin_minus_mgamma_v2_minus_Kv_vV"]
    assert abs(res1) < 4 * se1 + 1e-3 * r.V2
    assert abs(res2) < 4 * se2 + 1e-3 * r.Pin
    # and from the returned values themselves, within their errors
    assert abs(r.V2 - p.Kc * p.tau_p * r.vV) < 4 * math.hypot(r.V2_err, p.Kc * p.tau_p * r.vV_err)
    lhs, rhs = r.Pin, p.m * p.gamma * r.v2 + p.Kv * r.vV
    assert abs(lhs - rhs) < 4 * math.hypot(r.Pin_err, r.v2_err, r.vV_err)


def test_same_seed_identical_different_seed_different() -> None:
    h = Harvester.build(a=0.5, n=3, N=2, k=-0.2)
    opts = dict(dt=0.05, paths=16, t_run=10.0, t_burn=5.0, min_replicas=2, max_replicas=2,
                progress=False)
    a = solve(h, "mc", seed=11, **opts)
    b = solve(h, "mc", seed=11, **opts)
    c = solve(h, "mc", seed=12, **opts)
    d = solve(h, "mc", seed=11, threads=1, **opts)
    assert (a.V2, a.Pin, a.eta_err) == (b.V2, b.Pin, b.eta_err)
    assert (a.V2, a.Pin) == (d.V2, d.Pin)
    assert a.V2 != c.V2 and a.Pin != c.Pin


def test_results_depend_on_the_batch_not_on_threads() -> None:
    # the adaptive loop sizes its batches by ``batch``: fixed, the thread count is free
    h = Harvester.build(a=0.5, n=3, N=2, k=-0.2)
    opts = {"dt": 0.05, "paths": 8, "t_run": 5.0, "t_burn": 2.0, "min_replicas": 2, "max_replicas": 8,
            "tol": 1e-3, "seed": 5, "batch": 3, "progress": False}
    a = solve(h, "mc", threads=1, **opts)
    b = solve(h, "mc", threads=3, **opts)
    assert a.info["replicas"] > 2 and a.info["batch"] == 3  # more than one batch ran
    assert (a.eta, a.eta_err, a.V2, a.Pin) == (b.eta, b.eta_err, b.V2, b.Pin)


def test_unsupported_reason_is_none_for_every_harvester() -> None:
    for h in (Harvester.build(n=1), Harvester.build(n=1.3, N=4, k=-1.0), Harvester.build(N=2, k=-9.0)):
        assert MonteCarlo().unsupported_reason(h) is None


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"dt": 0.0}, "dt must be in"),
        ({"dt": -0.1}, "dt must be in"),
        ({"paths": 1}, "paths must be an integer"),
        ({"tol": float("nan")}, "tol must be finite"),
        ({"tol": 1.5}, "tol must be in"),
        ({"min_replicas": 1}, "min_replicas"),
        ({"min_replicas": 10, "max_replicas": 5}, "max_replicas"),
        ({"t_run": float("inf")}, "t_run must be finite"),
        ({"max_time": 0}, "max_time"),
        ({"escape": -1.0}, "escape"),
        ({"seed": -3}, "seed"),
        ({"batch": 0}, "batch must be an integer"),
        ({"seed": 1.5}, "seed must be an integer"),
        ({"progress": "yes"}, "progress must be"),
        ({"richardson": 1}, "richardson must be"),
        ({"dt": 5.0, "t_run": 1.0}, "dt must not exceed t_run"),
    ],
)
def test_bad_settings_raise(kwargs: dict, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        MonteCarlo(**kwargs)


def test_bad_problem_and_unknown_option_raise() -> None:
    with pytest.raises(ParameterError, match="tau_p must be finite"):
        Harvester.build(tau_p=float("nan"))
    with pytest.raises(ParameterError, match="h must be a Harvester"):
        MonteCarlo().solve("not a harvester")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="invalid option for method 'mc'"):
        solve(Harvester.build(), "mc", bogus=1)


def test_escape_detected_beyond_k_di() -> None:
    h = Harvester.build(a=0.5, n=2, N=2, k=-0.4)  # k_di = -0.25
    r = solve(h, "mc", seed=3, dt=0.05, paths=32, t_run=100.0, min_replicas=2, progress=False)
    assert r.status is Status.UNSTABLE
    assert r.eta is None and r.V2 is None
    assert r.growth_rate > 0
    assert r.info["escape_fraction"] > 0.9
    assert 0 < r.info["escape_time_median"] < 140
    assert "beyond k_di" in r.message


def test_metastable_ring_is_labelled() -> None:
    h = Harvester.build(a=0.5, n=1.0, N=3, k=-0.01)
    r = solve(h, "mc", seed=5, tol=0.05, dt=0.05, paths=16, t_run=50.0, progress=False)
    assert r.status is Status.METASTABLE, r.message
    assert r.message.startswith("metastable:") and "quasi-stationary" in r.message
    assert 0.0 <= r.info["escape_fraction"] <= 1.0


def test_not_converged_overrides_metastable_and_keeps_the_class_in_the_message() -> None:
    # no path escaped: the quasi-stationary numbers could converge with more replicas
    h = Harvester.build(a=0.5, n=1.5, N=3, k=-0.05)
    r = solve(h, "mc", seed=5, dt=0.05, paths=32, t_run=50.0, min_replicas=2, max_replicas=2,
              progress=False)
    assert r.info["escape_fraction"] == 0.0
    assert r.status is Status.NOT_CONVERGED
    assert r.message.startswith("metastable:") and "NOT CONVERGED" in r.message


def test_metastable_ring_whose_paths_escape_stays_metastable() -> None:
    # no stationary state to converge to: more replicas would not help
    h = Harvester.build(a=0.5, n=1.5, N=3, k=-0.2)
    r = solve(h, "mc", seed=5, dt=0.05, paths=32, t_run=50.0, min_replicas=2, max_replicas=2,
              progress=False)
    assert r.info["escape_fraction"] > 0.5
    assert r.status is Status.METASTABLE
    assert "NOT CONVERGED" in r.message


def test_time_budget_gives_not_converged_with_numbers() -> None:
    h = Harvester.build(a=0.5, n=3)
    r = solve(h, "mc", seed=2, tol=1e-4, dt=0.05, paths=16, t_run=5.0, min_replicas=2,
              max_time=0.01, progress=False)
    assert r.status is Status.NOT_CONVERGED
    assert "NOT CONVERGED" in r.message
    assert r.eta is not None and np.isfinite(r.eta_err)


def test_first_batch_beyond_the_budget_is_not_started() -> None:
    """A slowly relaxing nonlinear unit (m = 1e4) needs a burn-in that a 0.3 s budget
    cannot cover even at the loop's fastest rate: neither the pilot nor a batch runs, the status
    is not converged, no numbers, and the message names max_time and the time it needs."""
    h = Harvester.build(a=0.5, n=4, m=1e4)
    mc = MonteCarlo(seed=1, max_time=0.3, progress=False)
    r = mc.solve(h)
    assert r.status is Status.NOT_CONVERGED and r.eta is None and r.V2 is None
    need = r.info["least_seconds"]
    assert need > 0.3 and f"{need:.3g} s" in r.message and "max_time = 0.3 s" in r.message
    plan = mc.plan(h)
    assert "no pilot run" in plan.notes["twin"]
    assert need == mc.least_seconds(h, plan.dt, plan.paths, mc.min_replicas, plan.t_burn + plan.t_run)
    # the same budget covers a fast-relaxing unit: it runs
    assert MonteCarlo(seed=1, max_time=0.3, progress=False, tol=0.1).solve(Harvester.build(a=0.5)).eta is not None


def test_uncoupled_kink_ring_equals_single_unit() -> None:
    # k = 0: three independent n = 1 units; exercises the ring code path of the kink scheme
    opts = dict(dt=0.04, paths=48, t_run=40.0, t_burn=20.0, min_replicas=6, max_replicas=6,
                progress=False)
    ring = solve(Harvester.build(a=0.5, n=1, N=3, k=0.0), "mc", seed=8, **opts)
    single = solve(Harvester.build(a=0.5, n=1), "mc", seed=9, **opts)
    assert ring.status is Status.STABLE and single.status in (Status.STABLE, Status.NOT_CONVERGED)
    for name in ("eta", "V2", "Pin"):
        (a, da), (b, db) = ring.value(name), single.value(name)
        assert abs(a - b) < 4 * math.hypot(da, db), name
    assert ring.info["kink_crossings"] > 0 and 0.0 <= ring.info["stuck_fraction"] < 0.5


def test_marginal_ring_reports_finite_V2_and_no_x2() -> None:
    h = Harvester.build(a=0.5, N=4, k=-0.25)  # k = k_di: the q = 2 mode has zero stiffness
    ex = solve(h, "exact")
    r = solve(h, "mc", seed=2, dt=0.05, paths=64, t_run=50.0, min_replicas=6, max_replicas=6,
              progress=False)
    assert r.status is Status.MARGINAL and ex.status is Status.MARGINAL
    assert r.x2 is None and r.x2_err is None
    assert r.info["t_burn"] < 100.0
    for name in ("eta", "V2", "Pin"):
        assert abs(r.value(name)[0] - getattr(ex, name)) < 4 * r.value(name)[1], name


def test_marginal_does_not_hide_non_convergence() -> None:
    h = Harvester.build(a=0.5, N=4, k=-0.25)
    r = solve(h, "mc", seed=2, dt=0.05, paths=16, t_run=50.0, min_replicas=6, max_replicas=6,
              tol=1e-3, progress=False)
    assert r.status is Status.NOT_CONVERGED
    assert r.message.startswith("marginal:") and "NOT CONVERGED" in r.message
    assert r.x2 is None


def test_confined_system_blowing_up_is_not_converged() -> None:
    # n = 8 at dt = 0.5: the stiff-wall substeps keep every path (the bias of the frozen-xi
    # step is large, and said)
    h = Harvester.build(a=2.0, n=8)
    r = solve(h, "mc", seed=2, dt=0.5, t_run=50.0, progress=False, step="frozen")
    assert r.info["escaped_paths"] == 0 and r.eta is not None and "lower dt" in r.message
    # every path leaves |x| < 0.3 during burn-in: reported as a blow-up, with no numbers
    r = solve(h, "mc", seed=2, dt=0.5, t_run=50.0, escape=0.3, progress=False, step="frozen")
    assert r.status is Status.NOT_CONVERGED
    assert "blew up" in r.message and "Lower dt" in r.message
    assert r.eta is None


@pytest.mark.parametrize("n", [12.0, 16.0])
def test_steep_walls_keep_every_path(n: float) -> None:
    """n = 12, 16 at the default step: no confined path escapes (the kick-drift-kick step is
    split where h^2 U''/m > 1), and eta agrees with Fokker-Planck within 3 combined errors."""
    h = Harvester.build(a=0.5, n=n)
    r = solve(h, "mc", seed=3, tol=3e-3, progress=False)
    f = solve(h, "fpe", tol=1e-4)
    assert r.info["escaped_paths"] == 0, r.message
    assert abs(r.eta - f.eta) <= 3 * math.hypot(r.eta_err, f.eta_err), (r.eta, r.eta_err, f.eta)


def test_transient_left_by_a_short_burn_in_is_detected() -> None:
    # tau_p = 20: V relaxes over ~10 time units; measuring from rest shows in the first half
    h = Harvester.build(a=0.5, n=3, tau_p=20.0)
    r = solve(h, "mc", seed=2, t_burn=0.0, t_run=40.0, control=False, martingale=False, tol=0.05,
              progress=False)
    assert r.status is Status.NOT_CONVERGED
    assert "TRANSIENT" in r.message and "raise t_burn" in r.message
    drift, drift_se = r.info["burn_in_drift_eta"]
    assert abs(drift) > 3 * drift_se
    # the default t_run without martingale controls (100): with them it is 400, and the rule's
    # burn-in (montecarlo.plan.burn_in) shortens with it
    auto = solve(h, "mc", seed=2, tol=0.05, paths=16, martingale=False, progress=False)
    assert auto.status is Status.STABLE, auto.message
    assert auto.info["t_burn"] > 3 * auto.info["relaxation_time"]


def test_plan_follows_the_slowest_relaxation_time() -> None:
    mc = MonteCarlo(seed=1, tol=1e-2)
    fast = mc.plan(Harvester.build(a=0.5, n=3))
    slow = mc.plan(Harvester.build(a=0.5, n=3, tau_p=200.0))
    assert slow.relaxation_time > 50 * fast.relaxation_time
    assert slow.t_burn > 3 * slow.relaxation_time and slow.t_run >= slow.t_burn
    assert slow.paths < fast.paths
    assert fast.twin is not None and fast.start == "twin"
    lin = mc.plan(Harvester.build(a=0.5, N=3, k=-0.2))
    assert lin.twin is None and lin.start == "twin"
    marginal = mc.plan(Harvester.build(a=0.5, N=4, k=-0.25))
    assert marginal.start == "rest"
    assert MonteCarlo(seed=1, control=False).plan(Harvester.build(a=0.5, n=3)).twin is None


def test_restart_rules() -> None:
    from montecarlo.estimate import Estimate

    h = Harvester.build(a=0.5, n=3)
    mc = MonteCarlo(seed=1, tol=1e-3)
    plan = mc.plan(h)

    def est(bias, bias_se, drift, drift_se):
        base = dict.fromkeys(("V2", "Pin", "eta", "v2", "vV", "x2", "stuck"), 1.0)
        return Estimate(mean=dict(base, eta=0.5), se=dict(base), bias=dict(base, eta=bias),
                        bias_se=dict(base, eta=bias_se), cov_V2_Pin=0.0, replicas=32,
                        identity_V2=(0.0, 1.0), identity_power=(0.0, 1.0),
                        drift=dict(base, eta=drift), drift_se=dict(base, eta=drift_se))

    assert mc._restart_reason(h, plan, est(1e-5, 1e-6, 0.0, 1e-4)) is None
    what, new = mc._restart_reason(h, plan, est(4e-4, 1e-5, 0.0, 1e-4))
    assert what == "dt" and new.dt == plan.dt / 2
    assert mc._restart_reason(h, plan, est(4e-4, 2e-4, 0.0, 1e-4)) is None  # bias not resolved
    # a third of tol x eta is 1.67e-4; from a coarse level at four times the fine step the bias
    # must pass it by one standard error
    assert mc._restart_reason(h, plan, est(2.0e-4, 5e-5, 0.0, 1e-4))[0] == "dt"
    four = dataclasses.replace(plan, coarse_ratio=4)
    assert mc._restart_reason(h, four, est(2.0e-4, 5e-5, 0.0, 1e-4)) is None
    assert mc._restart_reason(h, four, est(2.3e-4, 5e-5, 0.0, 1e-4))[0] == "dt"
    what, new = mc._restart_reason(h, plan, est(0.0, 1e-6, 1e-3, 1e-4))
    assert what == "t_burn" and new.t_burn == 2 * plan.t_burn
    assert MonteCarlo(seed=1, tol=1e-3, dt=0.02)._restart_reason(h, plan, est(4e-4, 1e-5, 0, 1)) is None


def test_stiffness_beyond_the_double_range_is_a_clear_error() -> None:
    # 2a overflows: was a LinAlgError from the relaxation-time eigenvalues
    with pytest.raises(ParameterError, match=r"a = 1e\+308: Monte Carlo needs the unit stiffness 2a"):
        solve(Harvester.build(a=1e308), "mc", seed=0, tol=0.1, progress=False)


def test_escape_threshold_follows_the_natural_amplitude_of_a_confined_system() -> None:
    """Strong noise on the kink (n = 1, D = 100) has sd(x) ~ 94: its ordinary paths must not
    count as blown up at |x| = 100; a weakly driven unit keeps the floor 100."""
    from montecarlo.solver import ESCAPE_AMPLITUDES
    from montecarlo.harmonic import natural_amplitude

    strong = Harvester.build(a=0.5, n=1.0, D=100.0)
    amp = natural_amplitude(strong)
    assert 50.0 < amp < 150.0
    assert MonteCarlo().threshold(strong) == pytest.approx(ESCAPE_AMPLITUDES * amp)
    assert MonteCarlo().threshold(Harvester.build(a=0.5, n=3.0)) == 100.0
    assert MonteCarlo(escape=7.0).threshold(strong) == 7.0
