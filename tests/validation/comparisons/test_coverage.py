"""Coverage of the Monte Carlo error bars: fractions within 1, 2, 3 errors of another solver."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester, solve
from validation.comparisons.coverage import (NORMAL_COVERAGE, QUICK_CASES, CoverageCase, binomial_limits, coverage_checks,
                                          detection, mc_coverage, min_results)


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


def _typical(count: int, scale: float) -> list[float]:
    """``count`` z at the normal quantiles (i + 1/2)/count, times ``scale``: the typical sample
    of results whose reported errors are off by 1/scale."""
    import scipy.stats

    return list(scale * scipy.stats.norm.ppf((np.arange(count) + 0.5) / count))


@pytest.mark.parametrize("run", ["quick", "full"])
def test_checks_fail_when_the_bars_are_too_small_or_too_large(run) -> None:
    """Honest bars pass; the typical results of bars 1.5x too small, or 2x too large, fail, at
    the number of results per quantity of the quick run (60) and of the full grid (104)."""
    from validation.comparisons.coverage import FULL_CASES, FULL_RUNS
    from validation.sections.errorbars import _QUICK_MC_RUNS

    count = len(QUICK_CASES) * _QUICK_MC_RUNS if run == "quick" else sum(c.runs or FULL_RUNS for c in FULL_CASES)
    assert count >= min_results(0.5 if run == "quick" else 0.9)
    rng = np.random.default_rng(5)
    assert all(ok for _, ok, _ in coverage_checks({q: list(rng.standard_normal(count)) for q in ("eta", "V2")}))
    assert all(ok for _, ok, _ in coverage_checks({"eta": _typical(count, 1.0)}))
    shrunk = [detail for _, ok, detail in coverage_checks({"eta": _typical(count, 1.5)}) if not ok]
    assert shrunk and all("too narrow" in d for d in shrunk)                 # reported errors / 1.5
    wide = [(label, d) for label, ok, d in coverage_checks({"eta": _typical(count, 0.5)}) if not ok]
    assert any("within 1 " in label and "too wide" in d for label, d in wide)  # reported errors x 2
    assert NORMAL_COVERAGE[0] == pytest.approx(0.6827, abs=1e-4)


def test_detection_probability_of_misscaled_bars() -> None:
    """The power the runs are sized by, checked by simulation: 300 synthetic quantities of 48
    results with bars 1.5x too small fail at the predicted rate (a lower bound) or more."""
    rng = np.random.default_rng(7)
    predicted = detection(48, 1.5)
    failed = np.mean([not all(ok for _, ok, _ in coverage_checks({"q": list(1.5 * rng.standard_normal(48))}))
                      for _ in range(300)])
    assert 0.5 <= predicted <= failed + 0.1
    assert detection(60, 0.5) > 0.99 and detection(104, 1.5) > 0.9
    assert min_results(0.5) == 48 and min_results(0.9) == 95
    honest = np.mean([all(ok for _, ok, _ in coverage_checks({"q": list(rng.standard_normal(48))}))
                      for _ in range(300)])
    assert honest > 0.98


def test_coverage_fails_for_a_wrong_reference() -> None:
    # the check can fail: a reference off by a few error bars is caught
    h = Harvester.build(a=0.5)
    wrong = CoverageCase("harmonic, wrong reference", h,
                         {"tol": 0.05, "paths": 8, "t_run": 50.0, "progress": False},
                         reference=solve(h.replace(a=0.55), "exact"))
    res = mc_coverage(cases=(wrong,), runs=4)
    assert res["fractions"]["eta"][2] < 0.5


def test_coverage_rejects_too_few_runs() -> None:
    with pytest.raises(ValueError, match="runs must be an integer in"):
        mc_coverage(runs=1)


@pytest.mark.slow
def test_full_coverage() -> None:
    res = mc_coverage(quick=False)
    z = {q: [v for c in res["cases"] for v in c["z"][q]] for q in res["fractions"]}
    failed = [(label, detail) for label, ok, detail in coverage_checks(z) if not ok]
    assert not failed, failed


def test_a_reference_short_of_its_tolerance_serves_only_when_precise_enough() -> None:
    from fpe_harvester import Stats, Status
    from validation.comparisons.coverage import REF_MAX_SHARE, usable_reference

    def ref(rel: float, status: Status = Status.NOT_CONVERGED) -> Stats:
        return Stats(V2=1.0, V2_err=rel, Pin=2.0, Pin_err=2.0 * rel, eta=0.5, eta_err=0.5 * rel, status=status,
                     method="mc", message="budget ran out")

    assert usable_reference(ref(0.9 * REF_MAX_SHARE * 1e-2), 1e-2) is None
    assert "budget ran out" in usable_reference(ref(1.1 * REF_MAX_SHARE * 1e-2), 1e-2)
    assert usable_reference(ref(0.5, Status.STABLE), 1e-2) is None
    assert usable_reference(ref(1e-4, Status.UNSTABLE), 1e-2) is not None


def test_an_unusable_reference_is_reported_and_the_other_cases_run() -> None:
    from fpe_harvester import Stats, Status

    h = Harvester.build(a=0.5)
    bad = CoverageCase("no reference", h, {"tol": 0.05, "paths": 8, "t_run": 50.0, "progress": False},
                       reference=Stats(status=Status.NOT_CONVERGED, method="mc", message="no numbers"))
    good = CoverageCase("harmonic", h, {"tol": 0.05, "paths": 8, "t_run": 50.0, "progress": False})
    res = mc_coverage(cases=(bad, good), runs=3)
    assert res["cases"][0]["unusable_reference"].startswith("not_converged")
    assert res["count"] == 3 and len(res["cases"][1]["z"]["eta"]) == 3


def test_the_full_grid_takes_its_monte_carlo_references_from_the_table() -> None:
    from validation.comparisons.coverage import FULL_CASES, _table_reference

    for case in FULL_CASES:
        if case.method == "mc":
            r = _table_reference(case)
            assert r is not None and r.eta_err is not None and "reference table" in r.message, case.label
