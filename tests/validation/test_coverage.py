"""Coverage of the Monte Carlo error bars: fractions within 1, 2, 3 errors of a reference."""

from __future__ import annotations

import pytest

from fpe_harvester import Harvester, solve
from validation.coverage import COVERAGE_LIMITS, CoverageCase, mc_coverage


def test_quick_coverage_is_close_to_normal() -> None:
    res = mc_coverage(quick=True, runs=6)
    assert res["count"] == 18
    f1, f2, f3 = res["fractions_all"]
    # 54 correlated z values: errors underestimated twofold would give ~0.38 / 0.68 / 0.87,
    # overestimated threefold ~0.99 / 1.0 / 1.0
    lo1, hi1, lo2, lo3 = COVERAGE_LIMITS[True]  # 0.45 < f1 < 0.95, f2 > 0.80, f3 > 0.93
    assert lo1 < f1 < hi1, res["fractions"]
    assert f2 > lo2 and f3 > lo3, res["fractions"]


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
    f1, f2, f3 = res["fractions_all"]
    lo1, hi1, lo2, lo3 = COVERAGE_LIMITS[False]  # 0.55 < f1 < 0.92, f2 > 0.88, f3 > 0.97
    assert lo1 < f1 < hi1, res["fractions"]
    assert f2 > lo2 and f3 > lo3, res["fractions"]
