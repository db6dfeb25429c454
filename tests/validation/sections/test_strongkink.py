"""Where Fokker-Planck declines (the strong kink), the report compares two Monte Carlo
constructions instead: the cross-check rows, the kink density, the stress cases.

Fokker-Planck's domain rule is the contract ``FokkerPlanck().unsupported_reason(h)``, returning a
message for the strong kink (a = 2, n below about 1.4); the tests pin it either way by monkeypatching,
so that they hold whatever bands the measured rule draws.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from fpe_harvester import Harvester, MethodNotAvailableError, Stats, Status
from fpe_harvester.fpe import FokkerPlanck
from validation.harness.checks import Outcome, expect
from validation.comparisons import kinkdensity, strongkink
from validation.sections import crosscheck, stress

REASON = "outside the measured domain of Fokker-Planck (a = 2, n < 1.4): use solve(h, 'mc')"


@pytest.fixture
def fpe_declines(monkeypatch):
    """Fokker-Planck declines the strong kink, as its domain rule will."""
    def reason(self, h):
        return REASON if h.N == 1 and h.a >= 2.0 and h.n < 1.4 else None

    monkeypatch.setattr(FokkerPlanck, "unsupported_reason", reason)


@pytest.fixture
def fpe_accepts(monkeypatch):
    """Fokker-Planck takes every single unit (as before it knew its domain, or with force=True)."""
    def reason(self, h):
        return None if h.N == 1 else "a ring"

    monkeypatch.setattr(FokkerPlanck, "unsupported_reason", reason)


def _stats(eta: float, rel: float, method: str) -> Stats:
    V2, Pin = 0.0024 * eta / 0.125, 0.0192
    return Stats.from_moments(V2=V2, Pin=Pin, R=1.0, V2_err=rel * V2, Pin_err=rel * Pin, eta_err=rel * eta,
                              status=Status.STABLE, method=method, message="",
                              info={"settings": {"step": 0.01, "w_trap": 0.003, "paths": 64}, "t_run": 100.0,
                                    "seconds": 1.0, "bias_bound": None})


def _ctx(mc: Stats, flow: Stats, quick: bool = False) -> SimpleNamespace:
    return SimpleNamespace(quick=quick, seed=1, require=lambda *m: None, solve=lambda h, m, **o: mc,
                           mc_options={"max_time": 90.0},
                           cache=SimpleNamespace(reference=lambda h, name, fn, **s: flow))


def test_declines_reads_the_solvers_domain_rule(fpe_declines):
    assert strongkink.declines(Harvester.build(a=2.0, n=1.0)) == REASON
    assert strongkink.declines(Harvester.build(a=2.0, n=1.5)) is None
    assert strongkink.declines(Harvester.build(a=0.5, n=1.0)) is None


def test_two_monte_carlo_constructions_agree_within_their_errors_and_can_fail():
    rows = strongkink.mc_vs_flow(_ctx(_stats(0.1240, 0.005, "mc"), _stats(0.1250, 0.005, "exactflow")),
                                 1.0, 2.0, "S")
    assert [c.name.rsplit(": ", 1)[1] for c in rows] == ["eta", "V2", "Pin"] and all(c.passed for c in rows)
    assert "exact-flow Monte Carlo: h = 0.01" in rows[0].detail
    off = strongkink.mc_vs_flow(_ctx(_stats(0.1240 * 1.06, 0.005, "mc"), _stats(0.1240, 0.005, "exactflow")),
                                1.0, 2.0, "S")
    assert not off[0].passed  # 6 % apart with 0.5 % errors
    wide = strongkink.mc_vs_flow(_ctx(_stats(0.1240, 0.02, "mc"), _stats(0.1240, 0.02, "exactflow")), 1.0, 2.0, "S")
    assert not wide[0].passed and "cap" in wide[0].detail  # 4 x 2.8 % > the 5 % cap: cannot tell


def _planned(ctx_quick: bool) -> list[str]:
    names = []

    def check(name, section, fn, cap=None):
        names.append(name)
        return [expect(name, section, True, "not run here")]

    crosscheck.run(SimpleNamespace(quick=ctx_quick, seed=1, mc_options={}, fpe_options={}, check=check))
    return names


def test_the_cross_checks_compare_two_monte_carlo_constructions_where_fokker_planck_declines(fpe_declines):
    names = _planned(False)
    assert "fpe vs mc: n = 1, a = 2" not in names and "fpe vs mc: n = 1, a = 0.5" in names
    assert "mc vs exact-flow mc: n = 1, a = 2" in names and "mc vs exact-flow mc: n = 1.25, a = 2" in names
    assert names.count("mc vs exact-flow mc: n = 1, a = 2") == 1


def test_the_strong_kink_rows_run_whether_or_not_fokker_planck_declines(fpe_accepts):
    names = _planned(False)
    assert "fpe vs mc: n = 1, a = 2" in names and "mc vs exact-flow mc: n = 1.25, a = 2" in names
    assert not any(n.startswith("mc vs exact-flow") for n in _planned(True))


def test_no_fokker_planck_solve_is_announced_where_it_declines(fpe_declines):
    announced = []
    ctx = SimpleNamespace(quick=False, prefetch=lambda h, m, **o: announced.append((h.n, h.a)))
    crosscheck.prefetch(ctx)
    stress.prefetch(ctx)
    assert (1.0, 2.0) not in announced and (1.0, 0.5) in announced


def test_the_kink_density_uses_the_second_construction_where_fokker_planck_declines(tmp_path, monkeypatch):
    """Where ``second`` gives shells, Fokker-Planck is not asked; the check passes when the two
    Monte Carlo constructions agree within 4 combined errors on every shell and fails otherwise."""
    edges = kinkdensity.EDGES
    dens = np.linspace(1.0, 2.0, edges.size - 1)
    mc = kinkdensity.ShellDensity(edges, dens, 0.01 * dens, "product")
    monkeypatch.setattr(kinkdensity, "shell_density_mc", lambda *a, **k: mc)
    asked = []

    def solved(h):
        asked.append(h)
        raise AssertionError("Fokker-Planck must not be asked where it declines")

    same = lambda h: kinkdensity.ShellDensity(edges, dens * 1.01, 0.01 * dens, "second")  # noqa: E731
    _, ((label, ok, detail),) = kinkdensity.kink_density_figure(tmp_path, True, (2.0,), solved, same)
    assert ok and "mc vs exact-flow mc" in label and not asked
    off = lambda h: kinkdensity.ShellDensity(edges, dens * 1.2, 0.01 * dens, "second")  # noqa: E731
    _, ((_, ok, detail),) = kinkdensity.kink_density_figure(tmp_path, True, (2.0,), solved, off)
    assert not ok and "combined error" in detail


def test_fokker_planck_must_decline_at_once_naming_monte_carlo(monkeypatch):
    import fpe_harvester

    h = Harvester.build(a=2.0, n=1.0)

    def declining(h, method, **o):
        raise MethodNotAvailableError(REASON)

    monkeypatch.setattr(fpe_harvester, "solve", declining)
    (ok,) = stress._declines("n = 1 kink, a = 2", h)
    assert ok.passed and "declined in" in ok.detail
    monkeypatch.setattr(fpe_harvester, "solve", lambda h, m, **o: (_ for _ in ()).throw(
        MethodNotAvailableError("no")))
    assert not stress._declines("x", h)[0].passed  # does not name Monte Carlo
    monkeypatch.setattr(fpe_harvester, "solve", lambda h, m, **o: Stats(status=Status.NOT_CONVERGED, method="fpe"))
    assert stress._declines("x", h)[0].outcome is Outcome.FAIL  # answered instead of declining
