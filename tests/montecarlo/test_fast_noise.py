"""The joint step: exact linear transition of (x, v, V, xi), from slow noise to the white-noise limit."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from fpe_harvester import Harvester, Status, solve
from fpe_harvester.errors import MethodNotAvailableError, ParameterError
from fpe_harvester.exact import mode_moments
from montecarlo import MonteCarlo, simulate
from montecarlo.controls.twin import TWIN_MOMENTS
from montecarlo.harmonic import twin_expectations
from montecarlo.steps import resolve_step
from montecarlo.steps.joint import joint_matrices, noise_factor

FAST = dict(tol=0.01, paths=64, t_run=50.0, min_replicas=8, progress=False)


def _van_loan(h: Harvester, dt: float) -> np.ndarray:
    """Noise covariance of the linear step by Van Loan's formula over the whole step."""
    p = h.params
    A = np.zeros((4, 4))
    A[0, 1], A[1, 0], A[1, 1], A[1, 2], A[1, 3] = 1.0, -2 * h.a / p.m, -p.gamma, -p.Kv / p.m, p.sigma / p.m
    A[2, 1], A[2, 2], A[3, 3] = p.Kc, -1.0 / p.tau_p, -1.0 / p.tau
    C = np.zeros((8, 8))
    C[:4, :4] = -A * dt
    C[3, 7] = 2.0 * p.D / p.tau**2 * dt
    C[4:, 4:] = A.T * dt
    F = scipy.linalg.expm(C)
    return F[4:, 4:].T @ F[:4, 4:]


@pytest.mark.parametrize("tau", [0.3, 1.0, 5.0])
def test_noise_covariance_matches_van_loan_where_it_is_well_conditioned(tau: float) -> None:
    h = Harvester.build(a=0.7, tau=tau, D=2.0)
    P, _, Q = joint_matrices(h, 0.05)
    ref = _van_loan(h, 0.05)
    assert np.abs(Q - ref).max() < 1e-12 * np.abs(ref).max()
    L = noise_factor(Q)
    assert np.abs(L @ L.T - Q).max() < 1e-13 * np.abs(Q).max()
    assert np.all(L[3, 1:] == 0.0)


@pytest.mark.parametrize("tau", [1e-8, 1e-4, 1e-2, 1.0, 100.0])
def test_joint_twin_of_a_unit_has_the_exact_moments(tau: float) -> None:
    # the joint step is the exact transition of a harmonic unit: its stationary moments are
    # the continuous-time ones at any step, whatever tau is against it (to round-off, which
    # grows like the xi variance D/tau against the others: 2e-7 at tau = 1e-8, where Q is
    # doubled 30 times from a step of 1e-3 / |A|)
    lin = Harvester.build(a=0.5, tau=tau)
    exact = {key: float(val[0]) for key, val in mode_moments(lin.mode_stiffness(), lin.params).items()}
    t = twin_expectations(lin, 0.05, step="joint")
    for name in ("V2", "vV", "v2", "x2", "vxi"):
        assert t[name] == pytest.approx(exact[name], rel=1e-9 if tau >= 1e-4 else 1e-6), name


def test_white_noise_limit_is_continuous() -> None:
    # tau -> 0 at fixed D: the step's matrices converge like tau/dt, to the white-noise step
    # (intensity 2D on v: the v increment's variance is 2 D sigma^2 dt/m^2 less the damping)
    mats = [joint_matrices(Harvester.build(a=0.5, tau=tau), 0.02) for tau in (1e-4, 1e-6, 1e-8)]
    d = [np.abs(Q1[:3, :3] - Q2[:3, :3]).max() + np.abs(P1[:3, :3] - P2[:3, :3]).max()
         for (P1, _, Q1), (P2, _, Q2) in zip(mats, mats[1:])]
    assert d[0] < 0.02 * mats[-1][2][1, 1]
    assert d[1] < 0.02 * d[0]
    assert mats[-1][2][1, 1] == pytest.approx(2.0 * 0.02, rel=0.05)


@pytest.mark.parametrize(("system", "dt", "step"), [
    (dict(n=3, tau=1e-4), 0.02, "joint"),       # tau < 10 dt
    (dict(n=3, tau=0.3), 0.02, "frozen"),
    (dict(n=2, tau=0.1), 0.02, "joint"),
    (dict(n=1, tau=1e-4), 0.02, "averaged"),    # the kink's short-tau step, tau < dt
    (dict(n=1, tau=0.05), 0.02, "frozen"),
    (dict(n=1, tau=1e-4), 1e-4, "frozen"),      # dt <= tau
])
def test_auto_step_at_a_given_dt(system: dict, dt: float, step: str) -> None:
    assert resolve_step(Harvester.build(a=0.5, **system), "auto", dt)[0].name == step


@pytest.mark.parametrize(("system", "step", "dt"), [
    (dict(n=3, tau=1e-4), "joint", 0.04),
    (dict(n=3, tau=1.0), "frozen", 0.02),
    (dict(n=1, tau=1e-4), "averaged", 0.04),
    (dict(n=1, tau=1.0), "frozen", 0.02),
    (dict(n=1, tau=0.01), "frozen", 0.01),      # the kink's frozen step starts at dt = tau
])
def test_auto_step_and_its_starting_dt(system: dict, step: str, dt: float) -> None:
    stepper, start = resolve_step(Harvester.build(a=0.5, **system))
    assert (stepper.name, start) == (step, dt)


def test_refusals_name_the_step_and_the_reason() -> None:
    kink = Harvester.build(a=0.5, n=1)
    with pytest.raises(ParameterError, match="step = 'joint' cannot serve.*kink"):
        resolve_step(kink, "joint", 0.02)
    # the averaged step is measured only for tau <= 1e-4: asked for at tau = 1 it refuses
    with pytest.raises(ParameterError, match=r"'averaged' cannot serve.*measured only for tau <= 0.0001"):
        resolve_step(kink, "averaged", 0.02)
    with pytest.raises(ParameterError, match="averaged-noise step serves the kink"):
        resolve_step(Harvester.build(a=0.5, n=3, tau=1e-4), "averaged", 0.02)
    with pytest.raises(ParameterError, match="step must be one of"):
        resolve_step(kink, "leapfrog", 0.02)
    with pytest.raises(ParameterError, match="step must be one of"):
        MonteCarlo(step="leapfrog")
    assert "kink" in MonteCarlo(step="joint").unsupported_reason(kink)
    assert "measured only" in MonteCarlo(step="averaged").unsupported_reason(kink)
    with pytest.raises(MethodNotAvailableError, match="step = 'joint' cannot serve"):
        solve(kink, "mc", step="joint", progress=False)
    e = simulate(Harvester.build(a=0.5, n=1, tau=1e-4), dt=0.02, paths=2, replicas=1, t_run=1.0, seed=1)
    assert e.notes["step"] == "averaged"
    with pytest.raises(ParameterError, match="averaged step has no harmonic twin"):
        simulate(Harvester.build(a=0.5, n=1, tau=1e-4), dt=0.02, paths=2, replicas=1, t_run=1.0, twin=1.0)


def test_twin_at_fast_noise_matches_its_expectations() -> None:
    h = Harvester.build(a=0.5, n=3, tau=1e-4)
    e = simulate(h, dt=0.02, paths=64, replicas=16, t_burn=0.0, t_run=50.0, seed=8, twin=1.2, start="twin")
    assert e.notes["step"] == "joint"
    m = e.moments(0)
    for name in TWIN_MOMENTS:
        x = m["t_" + name]
        se = x.std(ddof=1) / math.sqrt(x.size)
        # at tau << dt the estimate of v xi is all but deterministic: round-off allowed
        assert abs(x.mean() - e.twin_mean[name]) < 4 * se + 1e-12 * abs(x.mean()), name


@pytest.mark.parametrize(("N", "k"), [(1, 0.0), (3, -0.2)])
def test_fast_noise_harmonic_unit_matches_exact(N: int, k: float) -> None:
    h = Harvester.build(a=0.5, n=2, N=N, k=k, tau=1e-4)
    ex = solve(h, "exact")
    mc = solve(h, "mc", seed=3, **FAST)
    assert mc.status is Status.STABLE, mc.message
    assert mc.info["step"] == "joint"
    for name in ("eta", "V2", "Pin", "v2", "vV"):
        value, err = mc.value(name)
        ref = getattr(ex, name)
        assert abs(value - ref) < 4 * err + 1e-12 * abs(value), (name, value, err, ref)


def test_fast_noise_cubic_unit_agrees_with_fokker_planck() -> None:
    h = Harvester.build(a=0.5, n=3, tau=1e-4)
    fp = solve(h, "fpe", tol=1e-5)
    mc = solve(h, "mc", seed=5, **FAST)
    assert mc.status is Status.STABLE, mc.message
    assert mc.info["step"] == "joint"
    assert abs(mc.eta - fp.eta) < 4 * math.hypot(mc.eta_err, fp.eta_err), (mc.eta, mc.eta_err, fp.eta)


def test_kink_refuses_a_tau_shorter_than_its_step() -> None:
    # the kink's frozen step needs dt <= tau, its averaged-noise step serves tau <= 1e-4
    # (tests/montecarlo/test_coupling.py): between the two it says why
    h = Harvester.build(a=0.5, n=1, tau=1e-3)
    with pytest.raises(MethodNotAvailableError, match="tau = 0.001 is too short for the automatic time step"):
        solve(h, "mc", progress=False)
    with pytest.raises(MethodNotAvailableError, match="no Monte Carlo step serves n = 1, tau = 0.001 at dt"):
        solve(h, "mc", dt=1e-2, progress=False)
    with pytest.raises(ParameterError, match="no Monte Carlo step serves"):
        simulate(h, dt=1e-2, paths=2, replicas=1, t_run=1.0)
    # an explicit dt <= tau is served by the frozen step
    assert MonteCarlo(dt=1e-3).unsupported_reason(h) is None


@pytest.mark.parametrize("kw", [dict(n=3, N=1), dict(n=3, N=2, k=-0.3, k3=0.1)])
def test_white_noise_pin_has_no_first_order_bias(kw: dict) -> None:
    """K_v = 0, tau = 1e-4: Pin = sigma^2 D/(m (1 + gamma tau)) up to tau^2 <U''> (~2e-8). The
    closing half kick's correlation with xi's last tau gave -(h/2) tau <U''> (1.9e-6 at the fine
    step 0.02, 2-3 of its standard errors, linear in h); the error bar covers what remains."""
    s = solve(Harvester.build(a=0.5, Kv=0.0, tau=1e-4, **kw), MonteCarlo(seed=3, tol=1e-2, dt=0.04, progress=False))
    dev = abs(s.Pin - 1.0 / (1.0 + 1e-4))
    assert dev < 5e-8
    assert dev < s.Pin_err < 1e-7
