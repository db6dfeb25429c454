"""The work-precision study: its ladder of tolerances, its references, its table and figure."""

from __future__ import annotations

import math

import pytest

from validation.studies import work_precision as wp


def _fake(errors: dict[float, float], status: str = "stable"):
    calls = []

    def run_one(tol: float, seed: int):
        calls.append((tol, seed))
        return 2.0 * tol ** -0.5 * 1e-2, 1.0 + errors[tol] * (1 if seed % 2 else -1), 0.5 * tol, status

    return run_one, calls


def test_ladder_records_rms_actual_error_over_seeds_and_stops_before_the_budget():
    run_one, calls = _fake({1e-2: 0.01, 1e-3: 0.001, 1e-4: 1e-4})
    pts = wp.ladder(run_one, (1e-2, 1e-3, 1e-4), seeds=3, ref_eta=1.0, budget_s=3.0)
    # 3 seeds at 1e-2 cost 0.6 s, at 1e-3 1.9 s: 1e-4, predicted at 1.9 s more, would pass 3 s
    assert [p["tol"] for p in pts] == [1e-2, 1e-3]
    assert len(calls) == 6 and len({s for _, s in calls}) == 3
    assert pts[0]["error"] == pytest.approx(0.01) and pts[1]["error"] == pytest.approx(0.001)
    assert pts[0]["reported"] == pytest.approx(0.5e-2 / 1.0, rel=0.02) and pts[0]["runs"] == 3


def test_ladder_predicts_monte_carlo_costs_from_the_reported_error():
    run_one, calls = _fake({1e-2: 0.01, 1e-3: 0.001})
    # reported 5e-3 at 1e-2: 1e-3 predicted to cost (5e-3 / 1e-3)^2 = 25 times the 0.6 s spent
    assert [p["tol"] for p in wp.ladder(run_one, (1e-2, 1e-3), 3, 1.0, 15.0, order=2.0)] == [1e-2]
    assert [p["tol"] for p in wp.ladder(run_one, (1e-2, 1e-3), 3, 1.0, 16.0, order=2.0)] == [1e-2, 1e-3]
    assert [p["tol"] for p in wp.ladder(run_one, (1e-2, 1e-3), 3, 1.0, 1.0)] == [1e-2]


def test_span_counts_decades_above_the_reference_error():
    pts = [{"error": e} for e in (3e-2, 1e-3, 2e-5)]
    assert wp.span(pts, 1e-6) == pytest.approx(math.log10(3e-2 / 2e-5))
    assert wp.span(pts, 3e-4) == pytest.approx(2.0)


def test_ladder_stops_after_a_run_that_did_not_converge_and_skips_runs_without_numbers():
    run_one, _ = _fake({1e-2: 0.01, 1e-3: 0.001}, status="not_converged")
    assert [p["tol"] for p in wp.ladder(run_one, (1e-2, 1e-3), 2, 1.0, 100.0)] == [1e-2]
    assert wp.ladder(lambda tol, seed: (0.0, None, None, "over budget"), (1e-2,), 2, 1.0, 100.0) == []


def test_references_do_not_share_the_errors_of_the_solver_measured():
    """Units: the Fokker-Planck table entry, whose tolerance is ten times below the curve's
    tightest point; the ring: its long Monte Carlo run."""
    for key in ("unit_n3", "kink_a0.5", "kink_a1"):
        ref = wp.reference(key)
        assert "fpe n = " in ref["source"] and ref["tol"] <= 1e-5
        tols = wp.fpe_tols((1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7), ref)
        assert tols[0] == 1e-2 and min(tols) >= 10 * ref["tol"] and len(tols) >= 3, key
    assert wp.reference("unit_n3")["rel_err"] < 1e-7
    ring = wp.reference("ring_n3")
    assert "'mc n = 3, N = 3, a = 0.5, k = -0.5'" in ring["source"] and ring["rel_err"] < 5e-4 and ring["tol"] == 0
    assert wp.fpe_tols((1e-2, 1e-7), {"tol": 1e-8}) == (1e-2, 1e-7)
    assert wp.fpe_tols((1e-2, 1e-7), {"tol": 1e-6}) == (1e-2,)


@pytest.mark.parametrize("a", [0.5, 1.0])
def test_the_kinks_fokker_planck_references_agree_with_the_long_monte_carlo_runs(a):
    """The independent check of the Fokker-Planck kink curves' references: the long Monte
    Carlo runs (about 3e-4) agree within 3 combined standard errors."""
    agree = wp.kink_agreement(a)
    assert agree["sigma"] < 3.0 and abs(agree["diff"]) < 1e-3, agree


def test_euler_maruyama_runs_predicted_past_the_budget_are_not_started():
    from fpe_harvester import Harvester

    pilot = {"replicas": 4, "rel_se": 1e-2, "seconds": 1.0}
    assert wp._em_run(Harvester.build(a=0.5, n=3.0), 1e-4, 1, pilot, run_s=10.0)[1] is None


def _synthetic() -> dict:
    curve = lambda m, errs: {"method": m, "reference": {"eta": 0.5, "rel_err": 1e-5, "source": "table"},  # noqa: E731
                             "points": [{"tol": t, "seconds": 1 / t ** 0.5, "error": e, "reported": t, "runs": 2,
                                         "statuses": ["stable"]} for t, e in errs]}
    cases = {key: {"title": title, "system": system,
                   "curves": [curve(m, [(1e-2, 5e-3), (1e-3, 6e-4), (1e-4, 0.0)]) for m in wp.METHODS]}
             for key, (title, system) in wp.CASES.items()}
    rows = [{"method": m, "N": N, "seconds": 1e-3 * N, "eta": 0.5, "error": 1e-16 if N < 100 else None}
            for m in ("exact", "scipy dense Lyapunov") for N in (3, 10, 1000)]
    return {"quick": False, "wall_s": 1.0, "harmonic": {"title": "harmonic", "reference": "60 digits", "rows": rows},
            "cases": cases}


def test_summary_rows_and_figure(tmp_path):
    res = _synthetic()
    head, rows = wp.summary_rows(res)
    assert len(rows) == len(wp.CASES) * len(wp.METHODS) + 2 and all(len(r) == len(head) for r in rows)
    assert rows[0][2] == "0.01 ... 0.0001" and rows[0][3] == "0"
    assert math.isinf(float(rows[0][5]))  # an exact hit: the reported error is infinitely larger
    wp.plot(res, tmp_path / "wp.png")
    assert (tmp_path / "wp.png").stat().st_size > 10_000


def test_the_report_draws_the_recorded_diagrams_and_fails_thin_or_quick_data(tmp_path, monkeypatch):
    import json

    from validation.harness.checks import Context, Outcome, SolveCache
    from validation.harness.report import Section
    from validation.sections import benchmarks

    res = _synthetic()
    recorded = tmp_path / "work_precision.json"
    recorded.write_text(json.dumps(res))
    monkeypatch.setattr(wp, "RECORDED", recorded)
    ctx = Context(quick=True, out=tmp_path, cache=SolveCache())
    sec = Section("b", "B")
    thin, spans = benchmarks._work_precision(ctx, sec)
    # committed data, not this run: RECORDED (never PASS), naming the file and its command
    assert thin.outcome is Outcome.RECORDED and spans.outcome is Outcome.RECORDED and sec.figures[0].path.exists()
    assert thin.source == "validation/data/work_precision.json" and thin.command == wp.COMMAND
    assert "self-convergence" in sec.tables[0].note
    assert sec.tables[0].title.startswith("Work-precision") and "smallest span 2.7 decades" in spans.detail
    # a solver's curve over less than two decades of resolved error fails the second check only,
    # unless it reaches its reference's own error (it then shows all the reference resolves)
    res["cases"]["kink_a1"]["curves"][0]["reference"]["rel_err"] = 1e-4
    recorded.write_text(json.dumps(res))
    thin, spans = benchmarks._work_precision(ctx, Section("b", "B"))
    assert thin.outcome is spans.outcome is Outcome.RECORDED and "reference's error: kink n = 1, a = 1: fpe 1.7;" in spans.detail
    res["cases"]["kink_a1"]["curves"][0]["points"][-1]["error"] = 2e-4
    recorded.write_text(json.dumps(res))
    thin, spans = benchmarks._work_precision(ctx, Section("b", "B"))
    assert thin.outcome is Outcome.RECORDED and spans.outcome is Outcome.FAIL and "above it: kink n = 1, a = 1: fpe 1.4" in spans.detail
    res["cases"]["ring_n3"]["curves"][0]["points"] = res["cases"]["ring_n3"]["curves"][0]["points"][:1]
    recorded.write_text(json.dumps(res))
    thin, _ = benchmarks._work_precision(ctx, Section("b", "B"))
    assert thin.outcome is Outcome.FAIL and "(1 points)" in thin.detail
    recorded.unlink()
    assert not benchmarks._work_precision(ctx, Section("b", "B"))[0].passed


def test_the_recorded_full_run_has_every_solver_as_a_curve():
    """The committed data (validation/data/work_precision.json) is a full run in which every
    solver of every case reached at least two tolerances."""
    import json

    res = json.loads(wp.RECORDED.read_text())
    assert not res["quick"] and set(res["cases"]) == set(wp.CASES)
    for case in res["cases"].values():
        assert {c["method"] for c in case["curves"]} >= set(wp.METHODS) - {"fpe"}
        assert all(len(c["points"]) >= 2 for c in case["curves"]), case["title"]
        # each solver's curve covers two decades of resolved error, or reaches its reference's error
        for c in case["curves"]:
            if c["method"] in wp.SOLVERS:
                decades, floored = wp.resolved(c)
                assert decades >= wp.DECADES or floored, (case["title"], c["method"])
