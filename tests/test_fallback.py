"""``solve(method="auto")`` and ``harvester stats``: Monte Carlo where Fokker-Planck stops short."""

from __future__ import annotations

import importlib
import json
import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import pytest

from fpe_harvester import Harvester, Stats, Status, solve
from fpe_harvester.cli import main
from fpe_harvester.errors import ParameterError

# the module, not the function of the same name that the package exports
solve_module = importlib.import_module("fpe_harvester.solve")

KINK = Harvester.build(n=1, a=2)
EXACT = solve(Harvester.build(n=2, a=2), "exact")
#: What the stand-ins return; each test sets the outcomes it needs.
FPE_SHORT = replace(EXACT, method="fpe", status=Status.NOT_CONVERGED, eta_err=0.01 * EXACT.eta,
                    message="fpe stopped")
FPE_EMPTY = Stats(status=Status.NOT_CONVERGED, method="fpe", message="no level solved")
MC_OK = replace(EXACT, method="mc", eta_err=0.004 * EXACT.eta, message="mc ok", info={"seed": 7})


@dataclass(frozen=True)
class _StandIn:
    """A solver that returns ``outcomes[name]`` and records the settings it was built with."""

    name: ClassVar[str] = ""
    outcomes: ClassVar[dict[str, Stats]] = {}
    calls: ClassVar[list[tuple[str, dict[str, Any]]]] = []
    tol: float = 1e-4
    progress: Any = None
    extra: dict[str, Any] = field(default_factory=dict)

    def unsupported_reason(self, h: Harvester) -> str | None:
        return None

    def solve(self, h: Harvester) -> Stats:
        self.calls.append((self.name, {"tol": self.tol, "progress": self.progress, **self.extra}))
        return self.outcomes[self.name]


@dataclass(frozen=True)
class _FPE(_StandIn):
    name: ClassVar[str] = "fpe"


@dataclass(frozen=True)
class _MC(_StandIn):
    name: ClassVar[str] = "mc"
    max_time: float = 600.0

    def solve(self, h: Harvester) -> Stats:
        self.calls.append(("mc", {"tol": self.tol, "progress": self.progress, "max_time": self.max_time}))
        return self.outcomes["mc"]


@pytest.fixture
def stand_ins(monkeypatch):
    """Route "fpe" and "mc" to the stand-ins; returns (outcomes, calls)."""
    outcomes: dict[str, Stats] = {"fpe": FPE_SHORT, "mc": MC_OK}
    calls: list[tuple[str, dict[str, Any]]] = []
    monkeypatch.setattr(_StandIn, "outcomes", outcomes)
    monkeypatch.setattr(_StandIn, "calls", calls)
    monkeypatch.setattr(solve_module, "_solver_class", {"fpe": _FPE, "mc": _MC}.__getitem__)
    return outcomes, calls


def test_auto_falls_back_within_the_budget_and_says_so(stand_ins):
    outcomes, calls = stand_ins
    res = solve(KINK, "auto", tol=1e-3)
    assert [c[0] for c in calls] == ["fpe", "mc"]
    assert calls[1][1]["max_time"] == solve_module.FALLBACK_SECONDS == 60.0
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
    outcomes, calls = stand_ins
    outcomes["fpe"] = FPE_EMPTY
    # Monte Carlo short of tol too, but it has numbers: they win
    outcomes["mc"] = replace(MC_OK, status=Status.NOT_CONVERGED, eta_err=0.05 * EXACT.eta)
    res = solve(KINK, fallback_time=5.0, progress=False)
    assert calls[1][1]["max_time"] == 5.0 and calls[1][1]["progress"] is False
    assert res.method == "mc" and res.eta is not None and res.status is Status.NOT_CONVERGED
    assert "Fokker-Planck gave no result (no level solved); Monte Carlo used instead" in res.message
    assert res.info["fallback"]["other"]["eta"] is None


def test_the_smaller_relative_error_wins_when_neither_converged(stand_ins):
    outcomes, calls = stand_ins
    outcomes["mc"] = replace(FPE_SHORT, method="mc", eta_err=0.02 * EXACT.eta, message="mc stopped")
    res = solve(KINK)
    assert res.method == "fpe" and res.status is Status.NOT_CONVERGED
    assert "Monte Carlo did no better (mc stopped)" in res.message
    assert res.info["fallback"]["kept"] == "fpe" and res.info["fallback"]["other"]["method"] == "mc"


@pytest.mark.parametrize("method, options", [("fpe", {}), ("auto", {"fallback_time": 0}),
                                             ("auto", {"fallback_time": None})])
def test_no_fallback_for_fpe_or_without_a_budget(stand_ins, method, options):
    outcomes, calls = stand_ins
    res = solve(KINK, method, **options)
    assert res is FPE_SHORT and [c[0] for c in calls] == ["fpe"]


def test_no_fallback_when_fokker_planck_converged(stand_ins):
    outcomes, calls = stand_ins
    outcomes["fpe"] = replace(FPE_SHORT, status=Status.STABLE)
    assert solve(KINK).method == "fpe" and [c[0] for c in calls] == ["fpe"]


def test_fallback_time_is_checked(stand_ins):
    with pytest.raises(ParameterError, match="fallback_time"):
        solve(KINK, fallback_time=-1.0)


def test_cli_stats_prints_the_fallback_numbers_and_their_solver(stand_ins, capsys):
    outcomes, calls = stand_ins
    assert main(["stats", "--n", "1", "--a", "2", "--no-progress", "--fallback-time", "9"]) == 0
    out = capsys.readouterr().out
    assert "method = mc; status = stable" in out and "Monte Carlo used instead" in out
    assert calls[1][1]["max_time"] == 9.0
    eta_row = next(line for line in out.splitlines() if line.split()[:1] == ["eta"])
    assert len(eta_row.split()) == 3  # value and error
    assert main(["stats", "--n", "1", "--a", "2", "--no-progress", "--method", "fpe"]) == 0
    assert "method = fpe; status = not_converged" in capsys.readouterr().out


@pytest.mark.slow
def test_real_kink_at_a_2_gets_monte_carlo_numbers():
    # n = 1, a = 2: Fokker-Planck stops short (here within 5 s); Monte Carlo gives the numbers
    res = solve(KINK, tol=1e-2, max_seconds=5.0, fallback_time=60.0, progress=False)
    assert res.method == "mc" and res.info["fallback"]["other"]["method"] == "fpe"
    assert "Monte Carlo used instead" in res.message
    # the validation's long Monte Carlo reference (validation/references/data/reference_values.json,
    # "mc n = 1, a = 2", 900 s, seed 101): eta = 0.12288 +- 0.00020
    assert res.eta_err is not None and 0 < res.eta_err < 0.02 * res.eta
    assert abs(res.eta - 0.12288) < 3 * math.hypot(res.eta_err, 0.0002)
