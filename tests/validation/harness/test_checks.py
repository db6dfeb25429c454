"""The check/tolerance logic: what must pass passes, what must fail fails, crashes are reported."""

from __future__ import annotations

import math
import time

import pytest

from fpe_harvester import Harvester, MethodNotAvailableError, ParameterError, Stats, solve
from validation.harness.checks import Outcome, SolveCache, agree, expect, guarded


def test_agree_passes_within_the_stated_tolerance():
    r = agree("x", "s", 1.0, 0.1, 1.35, 0.0)
    assert r.outcome is Outcome.PASS
    assert r.tolerance == pytest.approx(0.4)
    assert "tol" in r.detail


def test_agree_fails_outside_the_tolerance():
    r = agree("x", "s", 1.0, 0.01, 1.3, 0.0)
    assert r.outcome is Outcome.FAIL
    assert r.diff == pytest.approx(0.3)


def test_agree_combines_errors_in_quadrature_and_adds_floors():
    assert agree("x", "s", 0.0, 3.0, 20.0, 4.0).outcome is Outcome.PASS  # 4 * 5 = 20
    assert agree("x", "s", 0.0, 3.0, 20.1, 4.0).outcome is Outcome.FAIL
    assert agree("x", "s", 1.0, 0.0, 1.0 + 1e-11, 0.0, rel_floor=1e-10).outcome is Outcome.PASS
    assert agree("x", "s", 1.0, 0.0, 1.0 + 1e-9, 0.0, rel_floor=1e-10).outcome is Outcome.FAIL
    assert agree("x", "s", 1.0, 0.0, 1.04, 0.0, floor=0.05).outcome is Outcome.PASS


@pytest.mark.parametrize("a", [None, math.nan, math.inf])
def test_agree_fails_without_a_finite_value(a):
    assert agree("x", "s", a, 0.1, 1.0, 0.1).outcome is Outcome.FAIL


def test_agree_rejects_bad_settings():
    with pytest.raises(ParameterError, match="n_sigma"):
        agree("x", "s", 1.0, 0.1, 1.0, 0.1, n_sigma=0.0)
    with pytest.raises(ParameterError, match="floor"):
        agree("x", "s", 1.0, 0.1, 1.0, 0.1, floor=-1.0)


def test_missing_error_is_taken_as_zero_and_said():
    r = agree("x", "s", 1.0, None, 1.0, 0.0)
    assert r.outcome is Outcome.PASS and "no error reported" in r.detail


def test_guarded_turns_missing_solver_into_skip_and_crash_into_fail():
    def missing():
        raise MethodNotAvailableError("method 'mc' is not available yet")

    def crash():
        raise ZeroDivisionError("boom")

    (s,) = guarded("c", "s", missing)
    assert s.outcome is Outcome.SKIP and "not available" in s.detail
    (f,) = guarded("c", "s", crash)
    assert f.outcome is Outcome.FAIL and "ZeroDivisionError" in f.detail
    ok = guarded("c", "s", lambda: expect("c", "s", True, "fine"))
    assert ok[0].outcome is Outcome.PASS and ok[0].seconds >= 0


def test_guarded_reports_a_hang():
    def spin():
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 5:
            pass

    (r,) = guarded("c", "s", spin, timeout=0.2)
    assert r.outcome is Outcome.FAIL and "hang" in r.detail


def test_solve_cache_reuses_results_and_drops_unknown_options():
    cache = SolveCache()
    h = Harvester.build(a=0.5, n=2, N=3, k=-0.2)
    r1 = cache.solve(h, "exact", tol=1e-3)
    r2 = cache.solve(h, "exact", tol=1e-3)
    assert r1 is r2
    assert cache.dropped == {"exact": {"tol"}}
    assert len(cache.results()) == 1


def test_context_skips_checks_past_the_quick_budget(tmp_path):
    from validation.harness.checks import Context

    past = Context(quick=True, out=tmp_path, cache=SolveCache(), deadline=time.perf_counter() - 1.0)
    (r,) = past.check("late", "s", lambda: expect("late", "s", True, "ran"))
    assert r.outcome is Outcome.SKIP and "budget" in r.detail

    def spin():
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 5:
            pass

    soon = Context(quick=True, out=tmp_path, cache=SolveCache(), deadline=time.perf_counter() + 0.2)
    (r,) = soon.check("slow", "s", spin, cap=10.0)
    assert r.outcome is Outcome.SKIP  # the run's budget ran out, not the check's own cap
    free = Context(quick=False, out=tmp_path, cache=SolveCache())
    (r,) = free.check("slow", "s", spin, cap=0.2)
    assert r.outcome is Outcome.FAIL and "hang" in r.detail


def test_require_names_the_missing_solver(tmp_path, monkeypatch):
    import validation.harness.checks as checks

    monkeypatch.setattr(checks, "solver_available", lambda m: None if m == "exact" else f"{m} missing")
    ctx = checks.Context(quick=True, out=tmp_path, cache=SolveCache())
    ctx.require("exact")
    with pytest.raises(MethodNotAvailableError, match="mc: mc missing"):
        ctx.require("exact", "mc")


def test_systematic_offset_diagnostic():
    from validation.sections.crosscheck import systematic_offset

    same_sign = [agree("c: eta", "s", 1.0 + 0.001 * i, 0.002, 1.0, 0.002) for i in range(1, 11)]
    assert all(c.outcome is Outcome.PASS for c in same_sign)  # each passes on its own ...
    assert "common offset" in systematic_offset(same_sign)  # ... but together they are one-sided
    mixed = [agree("c: eta", "s", 1.0 + 0.001 * (-1) ** i, 0.002, 1.0, 0.002) for i in range(10)]
    assert "5 of 10" in systematic_offset(mixed) and "common offset" not in systematic_offset(mixed)
    assert systematic_offset(mixed[:2]) == ""


def test_timeout_is_not_swallowed_by_broad_handlers():
    def swallowing():
        try:
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 5:
                pass
        except Exception:  # code under test that records errors and carries on
            return expect("c", "s", True, "swallowed")
        return expect("c", "s", True, "finished")

    (r,) = guarded("c", "s", swallowing, timeout=0.2)
    assert r.outcome is Outcome.FAIL and "hang" in r.detail


def test_solve_cache_background_gives_the_same_result_as_a_solve_here():
    """A solve announced to the worker process returns what the same solve in this process
    returns, and counts as announced and used."""
    from fpe_harvester.model import Harvester
    from validation.harness.checks import SolveCache

    h = Harvester.build(a=0.5, n=3.0)
    here = SolveCache().solve(h, "fpe", tol=1e-2)
    cache = SolveCache(background=True)
    try:
        cache.prefetch(h, "fpe", tol=1e-2)
        cache.prefetch(h, "fpe", tol=1e-2)  # announced once
        cache.prefetch(Harvester.build(a=0.5, n=3.0, N=3, k=-0.1), "fpe", tol=1e-2)  # a ring: the solve raises
        there = cache.solve(h, "fpe", tol=1e-2)
    finally:
        cache.close()
    assert (cache.announced, cache.prefetched) == (2, 1)
    assert there.status is here.status
    for q in ("eta", "V2", "Pin"):
        assert there.value(q) == here.value(q)
