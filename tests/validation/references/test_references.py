"""The independent references the validation relies on: the high-precision Lyapunov solve,
rational arithmetic, the closed-form bound, the benchmark-data parser and the paper row of
the exact solver."""

from __future__ import annotations

from fractions import Fraction

import pytest

from fpe_harvester import Harvester, Params, solve
from fpe_harvester.exact import k_di
from validation.sections.benchmarks import error_time_pairs
from validation.sections.beyond import eta_bound, eta_mode, optimum, plateau
from validation.references import mp_mode_moments, mp_ring_moments, rational_eta


def test_mp_lyapunov_reproduces_the_known_rationals():
    mom = mp_mode_moments(1.0, Params())
    assert float(mom["V2"]) == pytest.approx(20 / 143, rel=1e-14)
    assert float(mom["Pin"]) == pytest.approx(3 / 11, rel=1e-14)


def test_mp_zero_stiffness_limit_has_infinite_x2_and_finite_rest():
    mom = mp_mode_moments(0, Params())
    assert mom["x2"] == float("inf")
    assert float(mom["V2"] / mom["Pin"]) == pytest.approx(20 / 27, rel=1e-14)


def test_mp_ring_matches_exact_solver():
    h = Harvester.build(a=0.5, n=2, N=3, k=-0.33)
    assert float(mp_ring_moments(h)["eta"]) == pytest.approx(0.6773938564, rel=1e-9)


def test_rational_closed_form_matches_exact_solver():
    assert rational_eta([Fraction(1)]) == (Fraction(20, 143), Fraction(20, 39))
    V2, eta = rational_eta([Fraction(1), Fraction(7, 8), Fraction(3, 4), Fraction(7, 8)])
    r = solve(Harvester.build(a=0.5, N=4, k=-1 / 16))
    assert r.eta == pytest.approx(float(eta), rel=1e-14)
    assert r.V2 == pytest.approx(float(V2), rel=1e-14)


def test_bound_and_closed_form():
    p = Params()
    assert eta_bound(p) == pytest.approx(float(Fraction(20, 27)), rel=1e-15)
    assert float(eta_mode(1.0, p)) == pytest.approx(20 / 39, rel=1e-14)
    k_opt, eta, _ = optimum(3, 0.5, p)
    assert k_opt == pytest.approx(k_di(3, 0.5)) and eta < eta_bound(p)
    assert plateau(0.5, p) == pytest.approx(optimum(64, 0.5, p)[1], rel=1e-9)


def test_error_time_pairs_pairs_by_name_prefix():
    data = {"dense_s": 2.0, "dense_eta_err": 1e-12, "fourier_s": 1e-3, "fourier_eta_err": 0.0,
            "rows": [{"dt": 0.1, "wall_time": 3.0, "eta_rel_error": 0.01}], "ignored_target_s": 1.0,
            "curve": [{"wall_s": 0.5, "replicas": 8, "rel_se_eta": 0.02}]}
    pairs = sorted(error_time_pairs(data))
    assert pairs == [("curve[0] rel_se_eta", 0.5, 0.02), ("dense_eta_err", 2.0, 1e-12),
                     ("fourier_eta_err", 1e-3, 0.0), ("rows[0] eta_rel_error", 3.0, 0.01)]


def test_exact_result_used_for_the_paper_row():
    r = solve(Harvester.build(a=0.5, n=2, N=3, k=-0.33), "exact")
    assert abs(r.eta - 0.677) <= 0.0005


def test_doctests_of_the_validation_package():
    import doctest

    import validation.sections.benchmarks
    import validation.harness.checks

    for mod in (validation.harness.checks, validation.sections.benchmarks):
        assert doctest.testmod(mod).failed == 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_closed_form_against_the_lyapunov_solve(seed: int) -> None:
    """The validation's closed form (mpmath) against its independent 40-digit Lyapunov solve,
    on rings with random parameters and coupling inside the stable range: every moment to
    1e-30 relative."""
    import numpy as np

    from fpe_harvester.exact import k_di
    from validation.references import mp_closed_form

    rng = np.random.default_rng(seed)
    params = {n: float(rng.uniform(0.3, 3.0)) for n in ("m", "gamma", "Kv", "Kc", "sigma", "tau", "D", "tau_p")}
    N, a = int(rng.integers(1, 6)), float(rng.uniform(0.1, 2.0))
    h = Harvester.build(a=a, n=2, N=N, **params)
    if N > 1:
        h = h.replace(k=float(rng.uniform(0.9 * k_di(N, a), 1.0)))
    cf, ly = mp_closed_form(h, dps=50), mp_ring_moments(h, dps=50)
    for key in ("V2", "Pin", "v2", "vV", "x2", "eta"):
        assert abs(cf[key] - ly[key]) <= 1e-30 * abs(ly[key]), key
