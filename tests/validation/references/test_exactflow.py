"""The exact-flow Monte Carlo (validation.references.exactflow): its step against an ODE solve
with events, its noise, its answers against the exact solver and Fokker-Planck, its settings."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fpe_harvester import Harvester, ParameterError
from validation.references import _flowkernel as fk
from validation.references import exactflow as ef
from validation.references.reftable import load

KINK = Harvester.build(a=2.0, n=1)


def _drift(h: Harvester) -> np.ndarray:
    p = h.params
    return np.array([[0, 1, 0, 0], [0, -p.gamma, -p.Kv / p.m, p.sigma / p.m], [0, p.Kc, -1 / p.tau_p, 0],
                     [0, 0, 0, -1 / p.tau]])


def _ode_step(h: Harvester, y0: np.ndarray, s0: float, step: float) -> tuple[np.ndarray, float]:
    """The kink's step without noise (xi then decays freely) by an event-locating ODE solver."""
    A, s, t, y = _drift(h), s0, 0.0, y0.copy()
    for _ in range(200):
        def crossing(t, y):
            return y[0]

        crossing.terminal, crossing.direction = True, -s
        r = solve_ivp(lambda t, y, s=s: A @ y + np.array([0, -h.a * s / h.params.m, 0, 0]), (t, step), y,
                      rtol=1e-13, atol=1e-20, events=crossing, method="DOP853", first_step=1e-9)
        if r.status != 1 or r.t_events[0][0] <= t:
            return r.y[:, -1], s
        t, y, s = r.t_events[0][0], r.y_events[0][0].copy(), -s
        y[0] = 0.0
    raise AssertionError("too many crossings")


@pytest.mark.parametrize("scale", [3e-3, 1e-5])
def test_a_kink_step_without_noise_matches_an_ode_solve_with_events(scale):
    """With the noise draw set to zero the step's path is deterministic: every crossing, the force
    switching there and the end state agree with an ODE solve that locates its events, to 1e-12,
    from states near the kink with about one crossing per step (scale 3e-3) or several swings (1e-5)."""
    step = 0.02
    M = ef.step_matrices(KINK, step)
    pc, Ex, Cx = ef._trimmed(M, [M])
    pp = ef._pp(KINK)
    rng = np.random.default_rng(3)
    crossings = 0
    for _ in range(25):
        y0 = np.array([rng.uniform(-scale, scale), rng.uniform(-3e-3, 3e-3) if scale < 1e-3 else rng.uniform(-0.5, 0.5),
                       0.1 * rng.normal(), 0.8 * rng.normal()])
        s0 = 1.0 if y0[0] > 0 else -1.0
        y, st, eta = y0.copy(), np.array([s0, 0.0]), np.zeros(4)
        counts = np.zeros(fk.N_COUNTS, dtype=np.int64)
        y1 = M.E @ y0 + M.Pv * (-KINK.a * s0)
        fk._kink_crossings(y, st, eta, M.E, M.pvec, step, Ex[0], Cx[0], pc, 0.0, pp, counts,
                           np.zeros(fk.MAX_SWITCHES + 1), np.zeros(fk.MAX_SWITCHES + 1),
                           np.zeros(max(Ex.shape[2], pc.size)), y1, np.zeros((0, 4), dtype=np.int64), np.zeros(0))
        ref, s_ref = _ode_step(KINK, y0, s0, step)
        np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12)
        assert st[0] == s_ref
        crossings += counts[fk.C_CROSS]
    assert crossings >= 10


def test_the_noise_of_two_steps_is_the_noise_of_their_sum():
    """Q(2h) = E(h) Q(h) E(h)^T + Q(h): summing the fine steps' noise as the kernel does gives a
    coarse step's noise exactly (the variants of a coupled run share one Brownian path)."""
    fine, coarse = ef.step_matrices(KINK, 0.01), ef.step_matrices(KINK, 0.02)
    Qf, Qc = fine.L @ fine.L.T, coarse.L @ coarse.L.T
    np.testing.assert_allclose(fine.E @ Qf @ fine.E.T + Qf, Qc, rtol=1e-10, atol=1e-22)
    np.testing.assert_allclose(fine.E @ fine.E, coarse.E, rtol=1e-13, atol=1e-16)


def test_the_harmonic_unit_by_the_discrete_gradient_matches_the_exact_solver():
    """n = 2: eta = 20/39 (docs/model.md) within 4 standard errors."""
    r = ef.solve_flow(Harvester.build(a=0.5, n=2), ef.FlowSettings(step=0.02, paths=16, t_run=1000.0, seed=1))
    assert abs(r.eta - 20 / 39) < 4 * r.eta_err and r.eta_err < 0.01


def test_the_kink_at_a_half_matches_the_fokker_planck_reference():
    """n = 1, a = 0.5: the reference table's Fokker-Planck entry (1e-6), an independent method."""
    ref = load()["fpe n = 1, a = 0.5"]
    r = ef.solve_flow(Harvester.build(a=0.5, n=1), ef.FlowSettings(step=0.01, w_trap=0.003, paths=16, t_run=1500.0,
                                                                   seed=2))
    for q in ("eta", "V2", "Pin"):
        assert abs(r.value(q)[0] - ref[q]) < 4 * r.value(q)[1], q
    assert r.eta_err < 0.01 * r.eta


def test_the_results_do_not_depend_on_the_threads():
    import numba

    settings = ef.FlowSettings(step=0.02, paths=4, t_run=100.0, seed=5)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = ef.solve_flow(KINK, settings)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        two = ef.solve_flow(KINK, settings)
    finally:
        numba.set_num_threads(before)
    assert one.eta == two.eta and one.V2 == two.V2


def test_the_settings_and_the_system_are_checked():
    with pytest.raises(ParameterError, match="step"):
        ef.FlowSettings(step=0.5)
    with pytest.raises(ParameterError, match="w_trap"):
        ef.FlowSettings(w_trap=-1.0)
    with pytest.raises(ParameterError, match="paths"):
        ef.FlowSettings(paths=1)
    with pytest.raises(ParameterError, match="N must be 1"):
        ef.solve_flow(Harvester.build(a=0.5, n=3, N=3, k=-0.1))


def test_the_energy_shells_hold_the_time_spent_in_them():
    edges = np.array([0.0, 0.05, 0.5, 1e6])
    r = ef.solve_flow(Harvester.build(a=0.5, n=1), ef.FlowSettings(paths=4, t_run=200.0, seed=3), edges)
    assert sum(r.info["shells"]) == pytest.approx(1.0, abs=0.02) and len(r.info["shells_err"]) == 3


def test_the_reports_settings_have_a_recorded_bias_bound():
    """The strong-kink rows' exact-flow settings are rows of the bias study, whose bound their errors
    include (validation/data/exactflow_bias.json)."""
    from validation.comparisons.strongkink import FLOW

    for n, s in FLOW.items():
        settings = ef.FlowSettings(step=s["step"], w_trap=s["w_trap"])
        bound = ef.bias_bound(Harvester.build(a=2.0, n=n), settings)
        assert bound is not None and max(bound[q] for q in ("eta", "V2", "Pin")) < 0.01, (n, bound)
    assert ef.bias_bound(Harvester.build(a=0.5, n=1), ef.FlowSettings(step=0.01, w_trap=0.003)) is None
