"""The figure check's count of the points solved twice and its cross-check of the two solvers."""

from __future__ import annotations

from types import SimpleNamespace

from fpe_harvester.scenes.result import SceneRow
from validation.sections.figures import fallback_check

SCENE = SimpleNamespace(observables=("eta", "V2"))


def _row(i: int, eta: float, err: float, other: dict | None) -> SceneRow:
    info = {} if other is None else {"fallback": {"kept": "mc", "other": {"method": "fpe", "status": "not_converged",
                                                                          **other}}}
    return SceneRow(i, {"n": 1.0 + i}, "stable", "mc", "", {"eta": eta, "eta_err": err, "V2": 1.0, "V2_err": 0.01},
                    info)


def test_no_check_without_points_solved_twice():
    assert fallback_check("fig", SCENE, [_row(0, 0.5, 0.001, None)]) == []


def test_points_solved_twice_are_counted_and_must_agree_within_three_combined_bars():
    agreeing = {"eta": 0.504, "eta_err": 0.001, "V2": 1.0, "V2_err": 0.02}
    rows = [_row(0, 0.5, 0.001, None), _row(1, 0.5, 0.001, {**agreeing, "eta": 0.5045})]
    (check,) = fallback_check("fig", SCENE, rows)
    assert not check.passed and "1 of 2 points" in check.detail and "eta" in check.detail
    rows[1] = _row(1, 0.5, 0.001, {**agreeing, "eta": 0.5040})  # 4.0e-3 < 3 * 1.41e-3 = 4.24e-3 < 4.5e-3
    (check,) = fallback_check("fig", SCENE, rows)
    assert check.passed and "2 values given by both solvers compared" in check.detail
    assert "1 kept Monte Carlo's numbers" in check.detail


def test_points_solved_twice_without_a_value_from_both_compare_nothing_and_are_a_skip():
    rows = [_row(0, 0.5, 0.001, {"eta": None, "eta_err": None, "V2": None, "V2_err": None})]
    (check,) = fallback_check("fig", SCENE, rows)
    assert check.outcome.value == "SKIP" and "1 of 1 points" in check.detail and "nothing compared" in check.detail
