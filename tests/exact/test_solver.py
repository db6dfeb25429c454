"""Exact harmonic solver: closed form vs Lyapunov, Fourier modes vs dense ring, reference values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fpe_harvester import (
    Exact,
    Harvester,
    MethodNotAvailableError,
    ParameterError,
    Params,
    Status,
    exact_sweep,
    k_di,
    solve,
)
from fpe_harvester.exact import dense_covariance, lyapunov_covariance, mode_moments


def test_single_unit_reference_values():
    r = solve(Harvester.build(a=0.5))
    assert r.method == "exact" and r.status is Status.STABLE
    assert r.V2 == pytest.approx(20 / 143, rel=1e-12)
    assert r.Pin == pytest.approx(3 / 11, rel=1e-12)
    assert r.eta == pytest.approx(20 / 39, rel=1e-12)
    assert r.Vrms == pytest.approx(np.sqrt(20 / 143), rel=1e-12)
    # errors are round-off bounds
    assert 0 < r.eta_err < 1e-14 * r.eta and 0 < r.V2_err < 1e-14 * r.V2


def test_three_unit_ring_reference():
    r = solve(Harvester.build(a=0.5, N=3, k=-0.33))
    assert r.eta == pytest.approx(0.6773938564, abs=1e-9)
    assert r.V2 == pytest.approx(0.2302970396, abs=1e-9)


def test_identities_on_exact_solution(rng):
    for _ in range(20):
        p = Params(*rng.uniform(0.2, 3.0, size=9))
        h = Harvester(N=int(rng.integers(1, 7)), params=p).replace(a=float(rng.uniform(0.05, 2)))
        if h.N > 1:
            h = h.replace(k=float(rng.uniform(0.9 * k_di(h.N, h.a), 1.0)))
        r = solve(h)
        assert r.V2 == pytest.approx(p.Kc * p.tau_p * r.vV, rel=1e-12)
        assert r.Pin == pytest.approx(p.m * p.gamma * r.v2 + p.Kv * r.vV, rel=1e-12)


params_st = st.builds(
    Params,
    m=st.floats(0.2, 5), gamma=st.floats(0.0, 3), Kv=st.floats(0.1, 3), Kc=st.floats(0.1, 3),
    sigma=st.floats(0.1, 3), tau=st.floats(0.05, 5), D=st.floats(0.1, 5), tau_p=st.floats(0.1, 5),
    R=st.floats(0.1, 5),
)


@settings(max_examples=40, deadline=None)
@given(params=params_st, kappa=st.floats(0.01, 20))
def test_closed_form_matches_lyapunov(params, kappa):
    P = lyapunov_covariance(kappa, params)
    mom = mode_moments(kappa, params)
    for key, (i, j) in {"x2": (0, 0), "v2": (1, 1), "vV": (1, 2), "V2": (2, 2), "vxi": (1, 3)}.items():
        assert float(mom[key]) == pytest.approx(P[i, j], rel=1e-8)


@settings(max_examples=30, deadline=None)
@given(
    params=params_st,
    N=st.integers(1, 12),
    a=st.floats(0.05, 3),
    frac=st.floats(-0.95, 2.0),
)
def test_fourier_matches_dense_lyapunov(params, N, a, frac):
    k = 0.0 if N == 1 else frac * abs(k_di(N, a))
    h = Harvester.build(a=a, N=N, k=k).replace(params=params)
    r = solve(h, "exact")
    C = dense_covariance(h)
    diag = np.diag(C)
    assert r.V2 == pytest.approx(diag[2::4].mean(), rel=1e-10)
    assert r.v2 == pytest.approx(diag[1::4].mean(), rel=1e-10)
    assert r.x2 == pytest.approx(diag[0::4].mean(), rel=1e-8)
    assert r.Pin == pytest.approx(params.sigma * np.diag(C, 2)[1::4].mean(), rel=1e-10)


def test_marginal_point_is_finite_limit():
    h = Harvester.build(a=0.5, N=3, k=k_di(3, 0.5))
    r = solve(h)
    assert r.status is Status.MARGINAL and r.x2 is None and "marginal" in r.message
    eps = solve(h.replace(k=k_di(3, 0.5) * (1 - 1e-9)))
    assert eps.status is Status.STABLE
    assert r.eta == pytest.approx(eps.eta, rel=1e-7)
    assert r.V2 == pytest.approx(eps.V2, rel=1e-7)


@pytest.mark.parametrize("N", [2, 4, 10])
def test_even_ring_threshold_is_minus_a_over_2(N):
    r = solve(Harvester.build(a=0.8, N=N, k=-0.4))
    assert r.status is Status.MARGINAL


def test_unstable_reported_not_nan():
    r = solve(Harvester.build(a=0.5, N=3, k=-0.4))
    assert r.status is Status.UNSTABLE and not r.ok
    assert r.eta is None and r.V2 is None and r.growth_rate > 0
    assert "k_di" in r.message
    d = r.to_dict()
    assert d["eta"] is None and d["status"] == "unstable"
    with pytest.raises(RuntimeError, match="beyond k_di"):
        r.raise_for_status()


def test_exact_refuses_nonlinear():
    with pytest.raises(MethodNotAvailableError, match="n = 2"):
        solve(Harvester.build(n=3), "exact")
    with pytest.raises(MethodNotAvailableError, match="n = 2"):
        Exact().solve(Harvester.build(n=1.5))


def test_large_ring_matches_continuum_mean():
    h = Harvester.build(a=0.5, N=100_000, k=-0.2)
    r = solve(h)
    q = np.linspace(0, 1, 200_001)
    kap = 1.0 + 4 * -0.2 * np.sin(np.pi * q) ** 2
    mom = mode_moments(kap, h.params)
    assert r.V2 == pytest.approx(np.trapezoid(mom["V2"], q), rel=1e-8)


def test_sweep_matches_pointwise_and_masks_unstable():
    a = np.array([0.01, 0.5, 1.0, 2.0])[:, None]
    k = np.linspace(-0.7, 0.3, 11)[None, :]
    sw = exact_sweep(a, k, N=3)
    for i in range(a.shape[0]):
        for j in range(k.shape[1]):
            r = solve(Harvester.build(a=float(a[i, 0]), N=3, k=float(k[0, j])))
            if r.ok:
                assert not sw["eta"].mask[i, j]
                assert sw["eta"][i, j] == pytest.approx(r.eta, rel=1e-12)
                assert sw["Vrms"][i, j] == pytest.approx(r.Vrms, rel=1e-12)
            else:
                assert sw["eta"].mask[i, j] and not sw["stable"][i, j]
    assert not np.any(np.isnan(sw["eta"].filled(0.0)))


def test_sweep_bad_input():
    with pytest.raises(ParameterError, match="a must be finite and > 0"):
        exact_sweep([0.5, -1.0], 0.0, N=3)
    with pytest.raises(ParameterError, match="k must be finite"):
        exact_sweep(0.5, [np.nan], N=3)
    with pytest.raises(ParameterError, match="k must be 0 for a single unit"):
        exact_sweep(0.5, [0.1], N=1)


def test_roundoff_error_covers_ill_conditioned_x2_near_threshold():
    from fractions import Fraction

    k = k_di(3, 0.5) * (1 - 1e-12)
    r = solve(Harvester.build(a=0.5, N=3, k=k))
    # sin^2(pi/3) = 3/4 exactly: the critical stiffness in exact rational arithmetic
    kap_c = float(Fraction(1) + 4 * Fraction(k) * Fraction(3, 4))
    x2_ref = float(np.mean(mode_moments(np.array([1.0, kap_c, kap_c]), Params())["x2"]))
    assert abs(r.x2 - x2_ref) > 1e-6 * x2_ref  # double precision really is off here ...
    assert abs(r.x2 - x2_ref) <= r.x2_err < 1e-2 * r.x2  # ... and the stated error covers it
    assert r.eta_err < 1e-14 * r.eta  # eta is insensitive to kappa_min
