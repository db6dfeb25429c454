"""The bi-Laplacian coupling k4 in the exact solver: thresholds, shifts, dense cross-check."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester, MethodNotAvailableError, solve
from fpe_harvester.exact import dense_covariance, exact_sweep, threshold
from fpe_harvester.exact.stability import growth_rate


@pytest.mark.parametrize(("N", "k4", "k_di", "modes"), [
    (4, 0.1, -0.9, (2,)),
    (4, 0.5, -2.0, (1, 3)),
    (6, 0.5, -13.0 / 6.0, (2, 4)),
    (64, 0.5, -2.0, (16, 48)),
])
def test_threshold_with_k4_closed_form(N, k4, k_di, modes):
    th = threshold(N, 1.0, k4)
    assert th.k_di == pytest.approx(k_di, abs=1e-12)
    assert th.critical_mode == modes


def test_threshold_brute_force_over_k_both_signs_of_k4():
    """k_di separates stable from unstable rings, checked on the mode stiffnesses themselves."""
    for N in (2, 3, 5, 8, 13):
        for k4 in (-0.4, -0.05, 0.02, 0.3, 2.0):
            kd = threshold(N, 0.7, k4).k_di
            assert np.isfinite(kd)
            above = Harvester.build(a=0.7, N=N, k=kd + 1e-9, k4=k4).mode_stiffness()
            below = Harvester.build(a=0.7, N=N, k=kd - 1e-9, k4=k4).mode_stiffness()
            assert above.min() > 0 > below.min()


@pytest.mark.parametrize(("N", "shift"), [(3, 3.0), (2, 4.0)])
def test_k4_is_a_shift_of_k_for_small_rings(N, shift):
    """L^2 = -3L at N = 3 and -4L at N = 2: eta(k, k4) = eta(k + shift k4, 0)."""
    k, k4 = np.linspace(-0.3, 0.5, 9), 0.07
    with_k4 = exact_sweep(0.5, k, N, k4=k4)
    shifted = exact_sweep(0.5, k + shift * k4, N)
    for key in ("eta", "V2", "Pin", "x2"):
        assert np.allclose(with_k4[key], shifted[key], rtol=1e-12, atol=0)
    assert threshold(N, 0.5, k4).k_di == pytest.approx(threshold(N, 0.5).k_di - shift * k4, abs=1e-12)


@pytest.mark.parametrize(("N", "k", "k4"), [(4, -0.3, 0.1), (6, -0.5, 0.2), (5, 0.1, -0.02)])
def test_k4_against_dense_lyapunov(N, k, k4):
    h = Harvester.build(a=0.5, N=N, k=k, k4=k4, tau_p=1.5)
    r = solve(h, "exact")
    P = dense_covariance(h)
    assert r.V2 == pytest.approx(np.mean(np.diag(P)[2::4]), rel=1e-10)
    assert r.x2 == pytest.approx(np.mean(np.diag(P)[0::4]), rel=1e-10)
    assert r.Pin == pytest.approx(h.params.sigma * np.mean(np.diag(P, 2)[1::4]), rel=1e-10)


def test_marginal_at_threshold_and_unstable_beyond():
    kd = threshold(6, 1.0, 0.5).k_di
    h = Harvester.build(a=1.0, N=6, k=kd, k4=0.5)
    r = solve(h, "exact")
    assert r.status.value == "marginal" and r.x2 is None and np.isfinite(r.eta)
    beyond = solve(h.replace(k=kd - 0.1), "exact")
    assert beyond.status.value == "unstable" and beyond.eta is None
    assert beyond.growth_rate > 0 and "mode q = 2" in beyond.message
    assert beyond.growth_rate == pytest.approx(growth_rate(h.replace(k=kd - 0.1)), rel=1e-14)
    eig = np.linalg.eigvals(__import__("fpe_harvester.exact", fromlist=["x"]).ring_drift_matrix(
        h.replace(k=kd - 0.1)))
    assert beyond.growth_rate == pytest.approx(eig.real.max(), rel=1e-9)


def test_negative_k4_destabilises_short_waves():
    """k4 < 0 lowers the threshold's magnitude (it can make even k > 0 unstable): never NaN."""
    th = threshold(4, 0.5, -0.2)
    assert th.k_di == pytest.approx(-(1.0 / 4.0 - 0.2 * 4.0), abs=1e-15) and th.critical_mode == (2,)
    r = solve(Harvester.build(a=0.5, N=4, k=0.5, k4=-0.2), "exact")
    assert r.status.value == "unstable" and r.growth_rate > 0


def test_exact_refuses_cubic_coupling():
    with pytest.raises(MethodNotAvailableError, match=r"k3 = 0.1 \(cubic coupling\) is nonlinear"):
        solve(Harvester.build(N=3, k=-0.1, k3=0.1), "exact")
