"""Coverage of the Monte Carlo error bars: fractions within 1, 2, 3 errors of another solver."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester, solve
from validation.coverage import (NORMAL_COVERAGE, QUICK_CASES, CoverageCase, binomial_limits, coverage_checks,
                                 mc_coverage)


def test_quick_cases_use_other_solvers_and_the_kink() -> None:
    methods = {c.label: c.method for c in QUICK_CASES}
    assert methods == {"harmonic N = 1, a = 0.5": "exact", "n = 3, a = 0.5": "fpe", "n = 1, a = 0.5": "fpe"}


def test_quick_coverage_against_other_solvers() -> None:
    res = mc_coverage(quick=True, runs=6)
    assert res["count"] == 18
    assert [c["reference_method"] for c in res["cases"]] == ["exact", "fpe", "fpe"]
    z = {q: [v for c in res["cases"] for v in c["z"][q]] for q in res["fractions"]}
    failed = [(label, detail) for label, ok, detail in coverage_checks(z) if not ok]
    assert not failed, failed


def test_binomial_limits() -> None:
    lo, hi = binomial_limits(100, 0.6827)
    assert 0.5 < lo < 0.6 and 0.78 < hi < 0.85
    assert binomial_limits(100, 0.9973)[0] > 0.96


def test_checks_fail_when_the_bars_are_too_small_or_too_large() -> None:
    """Honest bars pass; the same z with bars 1.5x too small, or 2x too large, fail (200 results
    per quantity, the full grid's order)."""
    rng = np.random.default_rng(5)
    z = {q: list(rng.standard_normal(200)) for q in ("eta", "V2", "Pin")}
    assert all(ok for _, ok, _ in coverage_checks(z))
    shrunk = {q: [1.5 * v for v in zq] for q, zq in z.items()}        # reported errors / 1.5
    assert not any(ok for label, ok, _ in coverage_checks(shrunk) if "within 2" in label)
    widened = {q: [0.5 * v for v in zq] for q, zq in z.items()}
    assert not any(ok for label, ok, _ in coverage_checks(widened) if "within 1 " in label)
    assert NORMAL_COVERAGE[0] == pytest.approx(0.6827, abs=1e-4)


def test_coverage_fails_for_a_wrong_reference() -> None:
    # the check can fail: a reference off by a few error bars is caught
    h = Harvester.build(a=0.5)
    wrong = CoverageCase("harmonic, wrong reference", h,
                         {"tol": 0.05, "paths": 8, "t_run": 50.0, "progress": False},
                         reference=solve(h.replace(a=0.55), "exact"))
    res = mc_coverage(cases=(wrong,), runs=4)
    assert res["fractions"]["eta"][2] < 0.5


def test_coverage_rejects_too_few_runs() -> None:
    with pytest.raises(ValueError, match="runs must be an integer >= 2"):
        mc_coverage(runs=1)


@pytest.mark.slow
def test_full_coverage() -> None:
    res = mc_coverage(quick=False)
    z = {q: [v for c in res["cases"] for v in c["z"][q]] for q in res["fractions"]}
    failed = [(label, detail) for label, ok, detail in coverage_checks(z) if not ok]
    assert not failed, failed
