"""Generator controls: mean exactly 0 for any force, cross-fitting unbiased, exact values met, the
solver's choice."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import binom, chi2, norm

from fpe_harvester import Harvester, solve
from montecarlo import MonteCarlo, estimate, simulate
from montecarlo.controls.generator import GENERATOR, basis_names
from montecarlo.controls.regression import FOLDS, crossfit_estimate, regression_estimate
from montecarlo.controls.sets import control_columns
from montecarlo.harmonic import twin_expectations


@pytest.mark.parametrize("system, step", [
    ({"a": 2.0, "n": 1.0}, "frozen"),
    ({"a": 0.5, "n": 4.0, "N": 3, "k": -0.2, "k3": 0.5, "k4": 0.02}, "frozen"),
    ({"a": 0.5, "n": 3.0, "tau": 1e-4}, "joint"),
])
def test_generator_sums_have_mean_zero_and_leave_the_paths_unchanged(system: dict, step: str) -> None:
    # the kink, a ring with cubic and bi-Laplacian coupling, the joint step: the force never
    # enters the martingale form, so every sum has mean 0 at any step. The sums are strongly
    # correlated (neighbouring hinge knots, monomials sharing factors), so the sum of their squared
    # z-scores is not chi^2-distributed: each z-score, whole window and first half, against the
    # 0.1 % family-wise (Bonferroni) bound, on 800 one-path replicas in tasks of 24 (also several
    # replicas per task), each long enough (t_run = 60) for its sums to be near normal
    h = Harvester.build(**system)
    dt = 0.02 if step == "joint" else 0.05
    kw = dict(dt=dt, paths=1, replicas=800, group=24, t_burn=20.0, t_run=60.0, seed=9, step=step, richardson=True)
    e = simulate(h, controls=("martingale", "boundary", "generator"), **kw)
    off = simulate(h, controls=("martingale", "boundary"), **kw)
    assert np.array_equal(e.sums, off.sums) and np.array_equal(e.counts, off.counts)
    names = e.ctl_names["generator"]
    assert names == GENERATOR.sums(h)
    bound = norm.isf(0.001 / (2 * 2 * len(names)))
    for half in (False, True):
        g = e.control_sums("generator", first_half=half)
        z = np.array([g[n].mean() / (g[n].std(ddof=1) / math.sqrt(e.replicas)) for n in names])
        assert np.all(np.isfinite(z))
        assert np.abs(z).max() < bound, dict(zip(names, z.round(2)))


def test_the_kink_gets_the_hinge_terms() -> None:
    assert len(basis_names(kink=False)) == 65 and len(basis_names(kink=True)) == 110
    assert GENERATOR.sums(Harvester.build(a=2.0, n=1.0)) == basis_names(kink=True)
    assert GENERATOR.sums(Harvester.build(a=2.0, n=1.25)) == basis_names(kink=False)


def test_crossfitted_error_bars_cover_where_the_in_sample_fit_is_biased(rng) -> None:
    # a response nonlinear in 40 controls, 96 replicas: the in-sample regression's intercept
    # picks up the fitted noise (biased towards the sample mean); every cross-fitted value has
    # the exact mean, and its error bar covers 68 % / 95 % within binomial limits over 400 draws
    p, R, draws = 40, 96, 400
    z = []
    for _ in range(draws):
        C = rng.standard_normal((R, p))
        Y = 1.0 + C[:, :1] + 0.5 * (C[:, 1:2] ** 2 - 1.0) + 0.3 * rng.standard_normal((R, 1))
        r = crossfit_estimate(Y, C, np.zeros(p))
        z.append((r.mean[0] - 1.0) / math.sqrt(r.cov[0, 0]))
    z = np.abs(np.array(z))
    for k, nominal in ((1.0, 0.6827), (2.0, 0.9545)):
        lo, hi = binom.ppf([0.001, 0.999], draws, nominal) / draws
        assert lo <= (z < k).mean() <= hi, (k, (z < k).mean())


def test_crossfitting_is_the_least_squares_fit_of_each_fold(rng) -> None:
    # the folds' fits from the whole Gram matrix equal a direct fit on each fold's complement
    R, p = 160, 7
    C = rng.standard_normal((R, p)) + 3.0
    Y = np.column_stack([C @ rng.standard_normal(p), C[:, 0] ** 2]) + rng.standard_normal((R, 2))
    r = crossfit_estimate(Y, C, np.full(p, 3.0))
    fold = np.arange(R) % FOLDS
    Z = np.empty_like(Y)
    for k in range(FOLDS):
        fit = fold != k
        B = regression_estimate(Y[fit], C[fit], np.full(p, 3.0)).coef
        Z[~fit] = Y[~fit] - (C[~fit] - 3.0) @ B.T
    np.testing.assert_allclose(r.mean, Z.mean(axis=0), rtol=1e-12)
    assert r.dof == R - 1


@pytest.mark.parametrize("N, k", [(1, 0.0), (3, -0.2)])
def test_generator_estimate_meets_the_exact_harmonic_values(N: int, k: float) -> None:
    # harmonic unit and ring at a coarse step: the scheme's own expectation is known exactly
    # (discrete Lyapunov), so a bias of the cross-fitted generator set would show
    h = Harvester.build(a=0.5, N=N, k=k)
    dt = 0.2
    e = simulate(h, dt=dt, paths=2, replicas=320, t_burn=30.0, t_run=100.0, seed=21, start="twin",
                 controls=("martingale", "boundary", "generator"), step="frozen")
    est = estimate(e, h, controls="martingale+boundary+generator")
    # the harmonic ring's Poisson solution is in the martingale basis already: the estimate's own
    # choice keeps the in-sample set, whose variance is smaller
    assert estimate(e, h).controls == "martingale+boundary"
    disc = twin_expectations(h, dt)
    assert abs(est.mean["V2"] - disc["V2"]) < 4 * est.se["V2"]
    assert abs(est.mean["Pin"] - disc["vxi"]) < 4 * est.se["Pin"]
    assert abs(est.mean["eta"] - disc["V2"] / disc["vxi"]) < 4 * est.se["eta"]


def test_generator_set_needs_replicas_for_every_fold() -> None:
    # 125 controls (martingale and generator sums of the kink): every fold's fit of 15/16 of the
    # replicas must leave max(12, p) residual degrees of freedom, so 268 replicas at least
    h = Harvester.build(a=2.0, n=1.0)
    e = simulate(h, dt=0.05, paths=2, replicas=268, t_burn=2.0, t_run=5.0, seed=4,
                 controls=("martingale", "boundary", "generator"))
    valid = np.ones(e.replicas, dtype=bool)
    assert len(e.ctl_names["generator"]) + len(e.ctl_names["martingale"]) == 125
    assert control_columns(e, valid, "martingale+generator", 268).C.shape == (268, 125)
    assert control_columns(e, valid, "martingale+generator", 267) is None
    assert control_columns(e, valid, "martingale+generator", 268).crossfit
    assert not control_columns(e, valid, "martingale", 268).crossfit


def test_solver_adds_the_generator_where_it_pays() -> None:
    # the strong kink: eta is noisy per unit path time (plain relative variance ~50), so a run
    # long enough for the fit restarts with the generator controls (whether the estimate then
    # keeps them is its own choice: at t_run = 20 the replicas are too heavy-tailed for their fit);
    # n = 3 (~0.5) keeps today's set
    opts = dict(seed=3, t_run=20.0, t_burn=5.0, min_replicas=32, progress=False)
    kink = solve(Harvester.build(a=2.0, n=1.0), "mc", tol=3e-3, paths=2, max_replicas=320, **opts)
    assert kink.info["plan_notes"]["generator"].startswith("used")
    assert kink.info["plan_notes"]["restarts"][0] == "generator"
    assert kink.info["paths"] == 2 and kink.info["replicas"] == 320
    smooth = solve(Harvester.build(a=0.5, n=3.0), "mc", tol=1e-3, max_replicas=64, **opts)
    assert smooth.info["plan_notes"]["generator"].startswith("not used: plain relative variance")
    assert "generator" not in smooth.info["control_set"]
    off = solve(Harvester.build(a=2.0, n=1.0), "mc", tol=3e-3, paths=2, max_replicas=64, generator=False, **opts)
    assert "generator" not in off.info["plan_notes"] and "generator" not in off.info["control_set"]


def test_the_strong_kink_restarts_with_the_generator_at_half_the_step_only_at_tight_tol() -> None:
    # its bias at the starting step is ~0.06 % of eta: at tol < 1.8e-3 the restart for the
    # generator controls also halves dt (the halving rule would restart there anyway, later);
    # at a looser tol, or with an explicit dt, the step stays
    h = Harvester.build(a=2.0, n=1.0)
    e = simulate(h, dt=0.02, paths=4, replicas=32, t_burn=5.0, t_run=40.0, seed=5, richardson=True,
                 controls=("martingale", "boundary"))
    est = estimate(e, h)

    def replanned(**options) -> tuple:
        mc = MonteCarlo(progress=False, **options)
        plan = dataclasses.replace(mc.plan(h), t_run=400.0)
        new, first = mc._generator_plan(h, plan, e, est)
        return plan.dt, new, first

    dt, new, first = replanned(tol=1e-3)
    assert first > 0 and new.generator and new.dt == dt / 2, new.notes["generator"]
    assert "dt halved" in new.notes["generator"]
    # with its bias estimated from a coarse level at four times the fine step
    assert new.coarse_ratio == 4 and new.coarse_half and "coarse level at 2 dt" in new.notes["generator"]
    dt, new, first = replanned(tol=2e-3)
    assert first > 0 and new.generator and new.dt == dt and new.coarse_ratio == 2 and not new.coarse_half
    dt, new, first = replanned(tol=1e-3, dt=0.02)
    assert new.generator and new.dt == 0.02 and new.coarse_ratio == 2 and not new.coarse_half


def test_generator_batches_run_in_whole_rounds_of_equal_tasks() -> None:
    # a last round with one thread idle costs a whole task's time: the batch is cut into an even
    # number of equal tasks (two threads), of at most the plan's replicas per task, and loses less
    # than one replica per task
    mc = MonteCarlo(threads=2, progress=False)
    assert mc._tasks(101, 1) == (101, 1)
    for asked in (2, 3, 32, 383, 384, 385, 2613, 5000):
        replicas, per_task = mc._tasks(asked, 192)
        tasks = replicas // per_task
        assert replicas == tasks * per_task and tasks % 2 == 0 and 1 <= per_task <= 192, asked
        assert asked - tasks < replicas <= asked, asked


def test_the_strong_kink_measures_its_variance_on_one_path_replicas() -> None:
    # where the generator's restart is likely (the kink at tight tol, automatic paths) the first
    # batch only measures eta's variance and is discarded: 128 one-path replicas; elsewhere the
    # plan's own
    kink = Harvester.build(a=2.0, n=1.0)
    mc = MonteCarlo(tol=1e-3, threads=2, progress=False)
    plan = dataclasses.replace(mc.plan(kink), paths=21)
    pilot, replicas = mc._first_batch(kink, plan)
    assert (pilot.paths, pilot.group, replicas) == (1, 64, 128) and not pilot.generator
    for other in (MonteCarlo(tol=2e-3), MonteCarlo(tol=1e-3, paths=21), MonteCarlo(tol=1e-3, generator=False),
                  MonteCarlo(tol=1e-3, martingale=False)):
        assert other._first_batch(kink, plan) == (plan, 32)
    smooth = Harvester.build(a=0.5, n=3.0)
    assert mc._first_batch(smooth, plan) == (plan, 32)


def test_a_pilot_without_the_generator_after_it_restarts_with_the_plan() -> None:
    # the kink at a = 0.5 and tight tol: the one-path pilot finds eta's variance too small for the
    # generator, and the run restarts in the plan's own layout
    h = Harvester.build(a=0.5, n=1.0)
    r = solve(h, "mc", tol=1e-3, seed=3, t_run=20.0, t_burn=5.0, min_replicas=32, max_replicas=64,
              progress=False)
    assert r.info["plan_notes"]["generator"].startswith("not used"), r.info["plan_notes"]["generator"]
    assert r.info["plan_notes"]["restarts"][0] == "pilot"
    assert r.info["paths"] > 1 and "generator" not in r.info["control_set"]
