"""Each validation check fails when it should: fed a wrong answer, a false status, an error bar
too wide to test anything, or a result without numbers, it does not pass."""

from __future__ import annotations

from dataclasses import replace

import pytest


from fpe_harvester import Harvester, Optimum, Stats, Status, solve
from validation.sections import paper
from validation.harness.checks import Outcome, agree
from validation.sections.crosscheck import _compare
from validation.sections.figures import row_checks
from validation.sections.paper import PAPER_ROWS, _row_check, vrms_text
from validation.sections.stress import _judge


def _mc_like(r: Stats, scale: float = 1.0, rel_err: float = 1e-3, status: Status = Status.STABLE) -> Stats:
    return Stats.from_moments(V2=r.V2 * scale, Pin=r.Pin, R=1.0, V2_err=rel_err * r.V2, Pin_err=rel_err * r.Pin,
                              v2=r.v2, v2_err=rel_err * r.v2, vV=r.vV * scale, vV_err=rel_err * r.vV, method="mc",
                              status=status, message="" if status is Status.STABLE else "what happened")


H = Harvester.build(a=0.5, N=3, k=-0.25)


def test_agree_fails_when_the_error_bars_are_too_wide_to_test_anything():
    assert agree("x", "s", 1.0, 0.002, 1.005, 0.0, max_rel_tol=0.03).passed
    wide = agree("x", "s", 1.0, 0.5, 1.005, 0.0, max_rel_tol=0.03)
    assert wide.outcome is Outcome.FAIL and "exceeds the cap" in wide.detail


def test_cross_check_needs_converged_results_and_fails_on_a_wrong_one():
    ex = solve(H)
    assert all(c.passed for c in _compare("ok", _mc_like(ex), ex, quick=True))
    wrong = _compare("wrong", _mc_like(ex, scale=1.02), ex, quick=True)
    assert not wrong[0].passed  # eta off by 2 % with 0.1 % errors
    unconverged = _compare("nc", _mc_like(ex, rel_err=0.5, status=Status.NOT_CONVERGED), ex, quick=True)
    assert not any(c.passed for c in unconverged) and "exceeds the cap" in unconverged[0].detail
    honest = _compare("nc", _mc_like(ex, rel_err=1e-3, status=Status.NOT_CONVERGED), ex, quick=True)
    assert all(c.passed for c in honest)  # a best estimate is tested by its error bar
    none = _compare("unstable", Stats(status=Status.UNSTABLE, method="mc", message="grows"), ex, quick=True)
    assert not any(c.passed for c in none) and "no stationary number" in none[0].detail


def test_paper_row_check_fails_on_a_wrong_number_and_on_a_missing_one():
    row = PAPER_ROWS[-1]  # N = 3 harmonic, k = -0.33, eta = 0.677
    r = solve(Harvester.build(a=row.a, n=row.n, N=row.N, k=-0.33))
    assert _row_check(row, -0.33, r, 0.0005).passed
    assert not _row_check(row, -0.33, replace(r, eta=0.69), 0.0005).passed
    assert not _row_check(row, -0.33, replace(r, eta_err=0.05), 0.0005).passed  # cap: cannot test 3 digits
    nc = Stats(status=Status.NOT_CONVERGED, method="fpe", message="budget")
    assert not _row_check(row, -0.33, nc, 0.0005).passed
    assert not _row_check(row, -0.33, replace(r, status=Status.UNSTABLE), 0.0005).passed


def test_a_paper_disagreement_is_a_finding_only_when_a_second_solver_confirms_ours(monkeypatch):
    """The best single unit (n = 1, a = 0.5): the paper prints 0.609, both our solvers give 0.6103.
    The row is a FINDING (not a pass) only while the independent second solver agrees with the
    first and not with the paper; otherwise it fails."""
    from validation.harness.checks import Outcome

    row = PAPER_ROWS[0]
    fpe = Stats(status=Status.STABLE, method="fpe", eta=0.6103035, eta_err=4.3e-5)
    mc = Stats(status=Status.STABLE, method="mc", eta=0.610596, eta_err=1.6e-4, message="long run")
    monkeypatch.setattr(paper, "second_solver", lambda row, r: mc)
    confirmed = _row_check(row, 0.0, fpe, 0.0005)
    assert confirmed.outcome is Outcome.FINDING and not confirmed.passed
    assert confirmed.detail.startswith("THE PAPER'S PRINTED VALUE DISAGREES")
    assert (confirmed.value, confirmed.reference) == (fpe.eta, 0.609)
    monkeypatch.setattr(paper, "second_solver", lambda row, r: replace(mc, eta=0.6092))  # sides with the paper
    assert _row_check(row, 0.0, fpe, 0.0005).outcome is Outcome.FAIL
    monkeypatch.setattr(paper, "second_solver", lambda row, r: replace(mc, eta=0.6130))  # disagrees with fpe
    assert _row_check(row, 0.0, fpe, 0.0005).outcome is Outcome.FAIL
    monkeypatch.setattr(paper, "second_solver", lambda row, r: None)  # no second solver: a plain failure
    assert _row_check(row, 0.0, fpe, 0.0005).outcome is Outcome.FAIL
    # the recorded second solver exists for this row and is the long Monte Carlo run
    monkeypatch.undo()
    second = paper.second_solver(row, fpe)
    assert second is not None and second.method == "mc" and abs(second.eta - 0.6103) < 1e-3


def test_paper_maximum_row_uses_the_optimizer_and_can_fail(monkeypatch, tmp_path):
    """Outside quick mode a "maximum" row reports the optimizer's eta_max and k_opt: a wrong
    eta_max, or one whose error bar cannot test the paper's digits, fails the check."""
    from validation.harness.checks import Context, SolveCache

    row = next(r for r in PAPER_ROWS if r.maximum and r.n == 4)
    found = Optimum("k", "eta", -0.3, 0.01, 0.5081, 0.0005, status=Status.STABLE, method="mc")
    monkeypatch.setattr(paper, "optimize", lambda h, over, **kw: found)
    solved = []
    monkeypatch.setattr(paper, "solve_first", lambda ctx, h, methods: solved.append(h.k) or _mc_like(solve(H)))
    ctx = Context(quick=False, out=tmp_path, cache=SolveCache())
    k, r, opt = paper._row_result(ctx, row)
    assert k == -0.3 and solved == [-0.3] and opt is found and (r.eta, r.eta_err) == (0.5081, 0.0005)
    assert _row_check(row, k, r, 0.0005, opt).passed
    assert "k_opt = -0.3000" in _row_check(row, k, r, 0.0005, opt).detail
    assert not _row_check(row, k, replace(r, eta=0.52), 0.0005, opt).passed
    assert not _row_check(row, k, replace(r, eta_err=0.05), 0.0005, opt).passed
    quick = Context(quick=True, out=tmp_path, cache=SolveCache())
    solved.clear()
    assert paper._row_result(quick, row)[2] is None and solved == list(row.k_quick)


def test_vrms_paragraph_follows_the_numbers():
    constant = vrms_text([("a", 14.1, 10.0), ("b", 14.2, 10.3)], {"a": True, "b": True})
    assert "constant multiple of sqrt(<V^2>) within" in constant and "close to sqrt(200)" in constant
    assert "Every printed eta agrees" in constant
    scattered = vrms_text([("a", 10.0, 10.0), ("b", 14.2, 10.1)], {"a": True, "b": False})
    assert "not a constant multiple" in scattered and "not for: b" in scattered
    assert "Vrms ~ 10 eta" in scattered


def test_stress_judge_fails_false_statuses_refusals_and_wrong_numbers():
    nonlinear = Harvester.build(a=0.5, n=3)
    ex = solve(H)
    good = _judge("ok", "exact", lambda: ex, H, lambda: ex)
    assert all(c.passed for c in good)
    assert not any(c.passed for c in _judge("unstable", "mc", lambda: Stats(status=Status.UNSTABLE, message="m"),
                                            nonlinear))
    assert not any(c.passed for c in _judge("meta", "mc", lambda: Stats(status=Status.METASTABLE, message="m"),
                                            nonlinear))

    def refuse() -> Stats:
        from fpe_harvester import ParameterError

        raise ParameterError("no")

    assert not any(c.passed for c in _judge("refused", "mc", refuse, nonlinear))
    wrong = _judge("wrong", "exact", lambda: _mc_like(ex, scale=1.05), H, lambda: ex)
    assert any(c.outcome is Outcome.FAIL for c in wrong)
    empty = _judge("empty", "fpe", lambda: Stats(status=Status.NOT_CONVERGED, message="budget"), nonlinear)
    assert [c.outcome for c in empty] == [Outcome.SKIP]
    beyond = Harvester.build(a=0.5, N=3, k=-0.4)
    assert _judge("beyond", "exact", lambda: solve(beyond), beyond, expected=Status.UNSTABLE)[0].passed
    assert not _judge("beyond", "exact", lambda: ex, beyond, expected=Status.UNSTABLE)[0].passed


def test_scene_rows_are_checked_for_status_accuracy_and_exact_values(tmp_path):
    from fpe_harvester.scenes import load_scene, run_scene

    res = run_scene(load_scene("fig4_eta_vs_k_harmonic"), tmp_path, quick=True, progress=False)
    assert all(c.passed for c in row_checks("fig4", res.scene, res.rows))
    row = res.rows[0]
    lying = [replace(row, status="unstable")] + list(res.rows[1:])
    assert not row_checks("fig4", res.scene, lying)[0].passed
    sloppy = [replace(row, values={**row.values, "eta_err": 0.5 * row.values["eta"]})] + list(res.rows[1:])
    assert not row_checks("fig4", res.scene, sloppy)[1].passed
    off = [replace(row, values={**row.values, "eta": row.values["eta"] * (1 + 1e-9)})] + list(res.rows[1:])
    assert not row_checks("fig4", res.scene, off)[2].passed


def test_error_bar_checks_fail_when_the_promise_breaks(tmp_path, monkeypatch):
    from validation.harness.checks import Context, SolveCache
    from validation.sections.errorbars import Bound, FpeCase, _fpe_checks
    from validation.harness.report import Section

    assert Bound("x", 1e-3, reported=1e-4, actual=1e-5, ref_err=1e-7, status="stable", seconds=0.0).holds
    assert not Bound("x", 1e-3, reported=1e-5, actual=1e-4, ref_err=1e-7, status="stable", seconds=0.0).holds
    # a stable result must have met its tol; only stable and not-converged results carry a bound
    assert not Bound("x", 1e-3, reported=2e-3, actual=1e-5, ref_err=1e-7, status="stable", seconds=0.0).holds
    assert Bound("x", 1e-3, reported=2e-3, actual=1e-5, ref_err=1e-7, status="not_converged", seconds=0.0).holds
    assert not Bound("x", 1e-3, reported=1e-4, actual=1e-5, ref_err=1e-7, status="unstable", seconds=0.0).holds
    # a statistical reference counts REF_SIGMAS of its standard errors
    assert Bound("x", 1e-3, reported=1e-4, actual=3e-4, ref_err=1e-4, status="stable", seconds=0.0,
                 ref_sigmas=3.0).holds
    # a reference that is wrong by far more than the errors: every bound check fails
    h = Harvester.build(a=0.5, n=3.0)
    wrong_ref = solve(h.replace(a=0.55), "fpe", tol=1e-3)

    ctx = Context(quick=True, out=tmp_path, cache=SolveCache())
    import validation.sections.errorbars as eb
    monkeypatch.setattr(eb, "_fpe_reference", lambda ctx, case: wrong_ref)
    monkeypatch.setattr(eb, "QUICK_FPE", (FpeCase(3.0, 0.5, (1e-2,), 1e-5),))
    checks = _fpe_checks(ctx, Section("e", "E"))
    assert len(checks) == 3 and not any(c.passed for c in checks)  # eta, V2 and Pin
    # a wrong independent Monte Carlo reference fails it too
    monkeypatch.setattr(eb, "_mc_reference", lambda n, a: replace(wrong_ref, method="mc"))
    monkeypatch.setattr(eb, "QUICK_FPE", (FpeCase(3.0, 0.5, (1e-2,), None, reference="mc"),))
    assert not any(c.passed for c in _fpe_checks(ctx, Section("e", "E")))


def test_a_monte_carlo_run_too_wide_for_the_cap_is_solved_again_tighter(tmp_path):
    """Results and references alike: when 4 errors of V2 (or Pin) exceed the cap's share, the run
    is repeated with tol scaled down by the excess (at most 4x, 4x the time); a narrow run is kept."""
    from validation.harness.checks import Context, SolveCache
    from validation.sections.crosscheck import CAP_SHARE, MAX_REL_TOL, mc_within_cap

    ex = solve(H)
    calls = []

    class Fake(Context):
        def solve(self, h, method, **overrides):
            calls.append(overrides)
            rel = 0.0083 if not overrides else 1e-3  # V2 error 0.83 % (tau = 100), then tighter
            return replace(_mc_like(ex), V2_err=rel * ex.V2)

    ctx = Fake(quick=False, out=tmp_path, cache=SolveCache())
    r = mc_within_cap(ctx, H)
    assert len(calls) == 2 and r.V2_err == pytest.approx(1e-3 * ex.V2)
    tol = calls[1]["tol"]
    full = ctx.mc_options
    assert tol == pytest.approx(full["tol"] * CAP_SHARE * MAX_REL_TOL[False] / (4 * 0.0083))
    assert calls[1]["max_time"] == 4 * full["max_time"]
    calls.clear()
    assert mc_within_cap(Fake(quick=True, out=tmp_path, cache=SolveCache()), H) is not None and len(calls) == 1


def test_benchmark_checks_say_what_their_short_run_compared():
    """A benchmark module counts a check only for what it compared: the exact solver's errors
    against its references, Fokker-Planck's error bars against its own tighter runs; the Monte
    Carlo benchmark compares nothing (timings) and counts none."""
    from validation.studies.exact import bench as exact
    from validation.studies.fpe import bench as fpe
    from validation.studies.mc import bench as montecarlo

    good = {"single_call_eta_rel_error": 2e-16, "rational_check": {"eta_rel_error": 0.0},
            "fourier_vs_dense": [{"fourier_eta_rel_error": 4e-16}]}
    assert [ok for _, ok, _ in exact.report_checks(good)] == [True, True, True]
    bad = {**good, "fourier_vs_dense": [{"fourier_eta_rel_error": 1e-9}]}
    assert [ok for _, ok, _ in exact.report_checks(bad)] == [True, True, False]
    runs = {"cases": {"n=3": {"runs": {"1e-3": {"bounds_actual": True}, "1e-5": {}}},
                      "n=8": {"runs": {"1e-3": {"bounds_actual": False}}}}}
    ((label, ok, detail),) = fpe.report_checks(runs)
    assert not ok and "1 of 2" in detail and "n=8 tol 1e-3" in detail and "convergence" in label
    assert montecarlo.report_checks({}) == []


def test_the_live_best_ring_check_uses_a_tolerance_well_below_its_effect():
    """The best ring's recorded gain over the single unit is the effect: the live check (ring and
    unit both solved in the run) passes only when the live gain exceeds 4 combined errors and that
    tolerance is at most a quarter of the effect; a ring no better than the unit fails."""
    from types import SimpleNamespace

    from validation.sections import beyond

    best = {"k_opt": -0.136, "k3": 0.003, "eta_max": 0.6753, "eta_max_err": 0.0007}
    res = {"a": 0.5, "N": 3, "unit_eta": 0.6103}
    gain = 0.065
    asked = {}

    def solve(h, method, **opts):
        if h.N == 1:
            if method == "fpe":  # a Fokker-Planck run short of its tolerance: Monte Carlo answers instead
                return Stats(eta=0.61, eta_err=0.05 if fpe_fails else 6e-4, method="fpe",
                             status=Status.NOT_CONVERGED if fpe_fails else Status.STABLE)
            return Stats(eta=0.6106, eta_err=opts["tol"] * 0.6106, status=Status.STABLE, method="mc")
        asked.update(opts)
        eta = ring
        return Stats(eta=eta, eta_err=opts["tol"] * eta, status=Status.STABLE, method="mc")

    ctx = SimpleNamespace(mc_options={"tol": 0.02, "max_time": 4.0}, solve=solve)
    ring, fpe_fails = 0.667, False
    (ok,) = beyond._best_ring_live(ctx, res, best, gain)
    assert ok.passed and asked["tol"] < 0.02 and "recorded gain 0.065" in ok.detail and "(fpe)" in ok.detail
    fpe_fails = True
    (ok,) = beyond._best_ring_live(ctx, res, best, gain)
    assert ok.passed and "(mc)" in ok.detail
    ring = 0.6106
    (off,) = beyond._best_ring_live(ctx, res, best, gain)
    assert off.outcome is Outcome.FAIL
