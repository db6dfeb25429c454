"""``solve(method="auto")`` and ``harvester stats``: Monte Carlo where Fokker-Planck stops short."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import pytest

from fpe_harvester import Harvester, Stats, Status, solve
from fpe_harvester.cli import main
from fpe_harvester.errors import MethodNotAvailableError, ParameterError
from fpe_harvester.solve import FALLBACK_SECONDS
from fpe_harvester.solvers import METHODS, Capabilities, Tolerance

KINK = Harvester.build(n=1, a=2)
EXACT = solve(Harvester.build(n=2, a=2), "exact")
#: What the stand-ins return; each test sets the outcomes it needs.
FPE_SHORT = replace(EXACT, method="fpe", status=Status.NOT_CONVERGED, eta_err=0.01 * EXACT.eta,
                    message="fpe stopped", harvester=None)
FPE_EMPTY = Stats(status=Status.NOT_CONVERGED, method="fpe", message="no level solved")
MC_OK = replace(EXACT, method="mc", eta_err=0.004 * EXACT.eta, message="mc ok", info={"seed": 7}, harvester=None)


@dataclass(frozen=True)
class _StandIn:
    """A solver that returns ``outcomes[name]`` and records the settings it was built with; it
    declares the capabilities of the solver it stands in for, and declines when ``reasons`` say."""

    name: ClassVar[str] = ""
    outcomes: ClassVar[dict[str, Stats]] = {}
    reasons: ClassVar[dict[str, str]] = {}
    calls: ClassVar[list[tuple[str, dict[str, Any]]]] = []
    tol: float = 1e-4
    progress: Any = None
    extra: dict[str, Any] = field(default_factory=dict)

    def unsupported_reason(self, h: Harvester) -> str | None:
        return self.reasons.get(self.name)

    def solve(self, h: Harvester) -> Stats:
        self.calls.append((self.name, {"tol": self.tol, "progress": self.progress, **self.extra}))
        return self.outcomes[self.name]


@dataclass(frozen=True)
class _FPE(_StandIn):
    name: ClassVar[str] = "fpe"
    capabilities: ClassVar[Capabilities] = Capabilities(title="Fokker-Planck", tol=Tolerance(0.1, 1e-4),
                                                        max_time="max_seconds", progress="lines")
    max_seconds: float | None = None


@dataclass(frozen=True)
class _MC(_StandIn):
    name: ClassVar[str] = "mc"
    capabilities: ClassVar[Capabilities] = Capabilities(title="Monte Carlo", tol=Tolerance(1.0, 1e-2, True),
                                                        seed=True, max_time="max_time", progress="bar",
                                                        common_random_numbers=lambda solver, h, replicas: {})
    seed: int | None = None
    max_time: float = 600.0

    def solve(self, h: Harvester) -> Stats:
        self.calls.append(("mc", {"tol": self.tol, "progress": self.progress, "max_time": self.max_time,
                                  "seed": self.seed}))
        return self.outcomes["mc"]


@pytest.fixture
def stand_ins(monkeypatch):
    """Register the stand-ins as "fpe" and "mc"; returns (outcomes, calls, reasons)."""
    outcomes: dict[str, Stats] = {"fpe": FPE_SHORT, "mc": MC_OK}
    calls: list[tuple[str, dict[str, Any]]] = []
    reasons: dict[str, str] = {}
    monkeypatch.setattr(_StandIn, "outcomes", outcomes)
    monkeypatch.setattr(_StandIn, "calls", calls)
    monkeypatch.setattr(_StandIn, "reasons", reasons)
    monkeypatch.setitem(METHODS, "fpe", _FPE)
    monkeypatch.setitem(METHODS, "mc", _MC)
    return outcomes, calls, reasons


def test_auto_falls_back_within_the_budget_and_says_so(stand_ins):
    outcomes, calls, _ = stand_ins
    res = solve(KINK, "auto", tol=1e-3)
    assert [c[0] for c in calls] == ["fpe", "mc"]
    assert calls[1][1]["max_time"] == FALLBACK_SECONDS == 60.0
    assert calls[1][1]["tol"] == 1e-3  # the tolerance asked of Fokker-Planck
    assert res.method == "mc" and res.status is Status.STABLE and res.eta == MC_OK.eta
    assert "Fokker-Planck did not reach the tolerance" in res.message and "fpe stopped" in res.message
    assert "Monte Carlo used instead" in res.message
    assert res.info["seed"] == 7
    fb = res.info["fallback"]
    assert fb["kept"] == "mc"
    assert {k: fb["other"][k] for k in ("method", "eta", "eta_err", "status", "message")} == {
        "method": "fpe", "eta": FPE_SHORT.eta, "eta_err": FPE_SHORT.eta_err, "status": "not_converged",
        "message": "fpe stopped"}
    assert fb["other"]["V2"] == FPE_SHORT.V2 and fb["other"]["Pin_err"] == FPE_SHORT.Pin_err
    json.dumps(res.to_dict())  # the record of the replaced numbers is JSON-ready


def test_fallback_when_fokker_planck_gives_no_number(stand_ins):
    outcomes, calls, _ = stand_ins
    outcomes["fpe"] = FPE_EMPTY
    # Monte Carlo short of tol too, but it has numbers: they win
    outcomes["mc"] = replace(MC_OK, status=Status.NOT_CONVERGED, eta_err=0.05 * EXACT.eta)
    res = solve(KINK, fallback_time=5.0, progress=False)
    assert calls[1][1]["max_time"] == 5.0 and calls[1][1]["progress"] is False
    assert res.method == "mc" and res.eta is not None and res.status is Status.NOT_CONVERGED
    assert "Fokker-Planck gave no result (no level solved); Monte Carlo used instead" in res.message
    assert res.info["fallback"]["other"]["eta"] is None


def test_the_smaller_relative_error_wins_when_neither_converged(stand_ins):
    outcomes, calls, _ = stand_ins
    outcomes["mc"] = replace(FPE_SHORT, method="mc", eta_err=0.02 * EXACT.eta, message="mc stopped")
    res = solve(KINK)
    assert res.method == "fpe" and res.status is Status.NOT_CONVERGED
    assert "Monte Carlo did no better (mc stopped)" in res.message
    assert res.info["fallback"]["kept"] == "fpe" and res.info["fallback"]["other"]["method"] == "mc"


@pytest.mark.parametrize("method, options", [("fpe", {}), ("auto", {"fallback_time": 0}),
                                             ("auto", {"fallback_time": None})])
def test_no_fallback_for_fpe_or_without_a_budget(stand_ins, method, options):
    outcomes, calls, _ = stand_ins
    res = solve(KINK, method, **options)
    assert (res.method, res.eta, res.status) == ("fpe", FPE_SHORT.eta, Status.NOT_CONVERGED)
    assert [c[0] for c in calls] == ["fpe"] and "fallback" not in res.info


def test_no_fallback_when_fokker_planck_converged(stand_ins):
    outcomes, calls, _ = stand_ins
    outcomes["fpe"] = replace(FPE_SHORT, status=Status.STABLE)
    assert solve(KINK).method == "fpe" and [c[0] for c in calls] == ["fpe"]


def test_fallback_time_is_checked(stand_ins):
    with pytest.raises(ParameterError, match="fallback_time"):
        solve(KINK, fallback_time=-1.0)


def test_cli_stats_prints_the_fallback_numbers_and_their_solver(stand_ins, capsys):
    outcomes, calls, _ = stand_ins
    assert main(["stats", "--n", "1", "--a", "2", "--no-progress", "--fallback-time", "9"]) == 0
    out = capsys.readouterr().out
    assert "method = mc; status = stable" in out and "Monte Carlo used instead" in out
    assert calls[1][1]["max_time"] == 9.0
    eta_row = next(line for line in out.splitlines() if line.split()[:1] == ["eta"])
    assert len(eta_row.split()) == 3  # value and error
    assert main(["stats", "--n", "1", "--a", "2", "--no-progress", "--method", "fpe"]) == 0
    assert "method = fpe; status = not_converged" in capsys.readouterr().out


#: What the Fokker-Planck solver says where it declines the strong kink (its domain rule is its own).
DECLINE = ("outside the measured domain of the Fokker-Planck solver (a = 2, n <= 1.4); use method='mc' "
           "(Monte Carlo)")


def test_auto_goes_straight_to_the_solver_that_can_answer(stand_ins, capsys):
    """Where Fokker-Planck declines at once, auto runs Monte Carlo alone (no attempt known to fail)
    and says which solver answered and why; so does the command line."""
    outcomes, calls, reasons = stand_ins
    reasons["fpe"] = DECLINE
    res = solve(KINK, tol=1e-3, seed=5, progress=False)
    assert [c[0] for c in calls] == ["mc"] and calls[0][1]["tol"] == 1e-3 and calls[0][1]["seed"] == 5
    assert res.method == "mc" and res.eta == MC_OK.eta and "fallback" not in res.info
    assert res.info["auto"]["chosen"] == "mc" and res.info["auto"]["declined"]["fpe"] == DECLINE
    assert "n = 1" in res.info["auto"]["declined"]["exact"]
    assert "method auto chose Monte Carlo; declined: exact (" in res.message
    assert "Fokker-Planck (outside the measured domain of the Fokker-Planck solver (a = 2, n <= 1.4))" in res.message
    assert main(["stats", "--n", "1", "--a", "2", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "method = mc; status = stable" in out and "Fokker-Planck (outside the measured domain" in out
    # asked by name, the declining solver refuses at once
    with pytest.raises(MethodNotAvailableError, match="outside the measured domain"):
        solve(KINK, "fpe")


def test_scene_points_go_straight_to_the_solver_that_can_answer(stand_ins, tmp_path):
    """Fig. 1's strong-kink points: the scene asks the same rule, so the row is Monte Carlo's alone
    (keyed as such in the cache), with the scene's seed and tolerance."""
    from fpe_harvester.scenes import Scene, run_scene
    from fpe_harvester.scenes.cache import point_seed

    outcomes, calls, reasons = stand_ins
    reasons["fpe"] = DECLINE
    scene = Scene("kink", system=KINK, observables=("eta",), rtol=0.01, outputs=())
    row = run_scene(scene, tmp_path, progress=False).rows[0]
    assert [c[0] for c in calls] == ["mc"] and calls[0][1]["seed"] == point_seed("kink", KINK)
    assert row.method == "mc" and row.status == "stable" and "Fokker-Planck (outside the measured" in row.message


def test_optimizer_uses_the_same_rule(stand_ins):
    from fpe_harvester.optimum import _objective_solver

    _, _, reasons = stand_ins
    ring = Harvester.build(n=3, N=3)
    assert _objective_solver(ring, "auto") == "mc"
    assert _objective_solver(Harvester.build(n=2, N=3), "auto") == "exact"
    with pytest.raises(ParameterError, match="method 'fpe' cannot be optimized over: .* Fokker-Planck gives neither"):
        _objective_solver(ring, "fpe")


@pytest.mark.slow
def test_real_kink_at_a_2_gets_monte_carlo_numbers():
    # n = 1, a = 2: Fokker-Planck declines or stops short (here within 5 s); Monte Carlo gives the numbers
    res = solve(KINK, tol=1e-2, max_seconds=5.0, fallback_time=60.0, progress=False)
    assert res.method == "mc"
    assert "fpe" in res.info["auto"]["declined"] or res.info["fallback"]["other"]["method"] == "fpe"
    # the validation's long Monte Carlo reference (validation/references/data/reference_values.json,
    # "mc n = 1, a = 2", 900 s, seed 101): eta = 0.12288 +- 0.00020
    assert res.eta_err is not None and 0 < res.eta_err < 0.02 * res.eta
    assert abs(res.eta - 0.12288) < 3 * math.hypot(res.eta_err, 0.0002)
