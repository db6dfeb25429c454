"""The Fokker--Planck solver's measured domain: the rule on both sides of its boundary, the
decline (at once, naming Monte Carlo) and the forced attempt."""

from __future__ import annotations

import math

import pytest
from scipy.optimize import brentq

from fpe_harvester import Harvester, MethodNotAvailableError, ParameterError, Status, solve
from fpe_harvester.fpe import FokkerPlanck, solver
from fpe_harvester.fpe.domain import DOMAIN, outside_reason, strength_limit, trap_strength
from fpe_harvester.result import Stats


def _at_strength(s: float, n: float, **params: float) -> Harvester:
    """The unit of exponent n (``params`` changed) whose trap strength is s (s is close to
    proportional to a / sigma: the root is bracketed within a factor 1.6 of a = s sigma)."""
    guess = s * params.get("sigma", 1.0)
    a = brentq(lambda a: trap_strength(Harvester.build(a=a, n=n, **params)) - s, 0.7 * guess, 1.1 * guess,
               xtol=1e-9)
    return Harvester.build(a=a, n=n, **params)


@pytest.mark.parametrize(("tol", "row"), [(tol, row) for tol, rows in DOMAIN.items() for row in range(len(rows))])
def test_rule_on_both_sides_of_each_measured_boundary(tol: float, row: int) -> None:
    """At the defaults the rule is a <= a_max across each band (its lowest n and the top of
    it); off the defaults (a stronger noise) the boundary moves with the trap strength s."""
    rows = DOMAIN[tol]
    n_low, a_max = rows[row]
    n_top = rows[row + 1][0] - 1e-3 if row + 1 < len(rows) else 1.999
    for n in (n_low, n_top):
        assert outside_reason(Harvester.build(a=a_max, n=n), tol) is None
        assert outside_reason(Harvester.build(a=1.01 * a_max, n=n), tol) is not None
        limit = strength_limit(n, tol)
        assert trap_strength(Harvester.build(a=a_max, n=n)) == pytest.approx(limit, rel=1e-12)
        assert outside_reason(_at_strength(0.99 * limit, n, sigma=1.5), tol) is None
        assert outside_reason(_at_strength(1.01 * limit, n, sigma=1.5), tol) is not None


def test_tolerance_classes() -> None:
    """tol >= 1e-3 takes the 1e-3 map's boundary, tighter ones the 1e-4 map's."""
    for n in (1.0, 1.3, 1.6, 1.9):
        assert strength_limit(n, 1e-2) == strength_limit(n, 1e-3)
        assert strength_limit(n, 1e-6) == strength_limit(n, 1e-4) <= strength_limit(n, 1e-3)
    assert outside_reason(Harvester.build(a=2.0, n=1.5), 1e-3) is None
    assert outside_reason(Harvester.build(a=2.0, n=1.5), 1e-4) is not None


def test_rule_known_points() -> None:
    """The strong kink is outside at every tolerance; the paper's best case and every n >= 2 inside."""
    for tol in (1e-2, 1e-3, 1e-4, 1e-6):
        assert outside_reason(Harvester.build(a=2.0, n=1.0), tol) is not None
        assert outside_reason(Harvester.build(a=0.5, n=1.0), tol) is None
        assert outside_reason(Harvester.build(a=50.0, n=2.0), tol) is None
        assert outside_reason(Harvester.build(a=5.0, n=3.0), tol) is None
    assert math.isinf(strength_limit(2.0))


def test_strength_is_relative_to_the_drive() -> None:
    """For n = 1 (a, sigma) -> (c a, c sigma) is an exact change of scale: s does not move, nor
    does the verdict; a stronger noise makes the same a weaker."""
    s = trap_strength(Harvester.build(a=1.0, n=1.0))
    assert trap_strength(Harvester.build(a=2.0, n=1.0, sigma=2.0)) == pytest.approx(s, rel=1e-9)
    assert outside_reason(Harvester.build(a=2.0, n=1.0, sigma=2.0)) is None
    assert trap_strength(Harvester.build(a=1.0, n=1.0, D=4.0)) < s


def test_decline_names_monte_carlo_and_solves_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    """Outside, solve(h, "fpe") raises before any level is built, naming the domain, Monte
    Carlo (the call and the command line) and force=True."""

    def no_solve(*args: object, **kwargs: object) -> None:
        raise AssertionError("the Fokker-Planck solve was attempted outside its domain")

    monkeypatch.setattr(solver, "solve_settings", no_solve)
    h = Harvester.build(a=2.0, n=1.0, tau_p=3.0)
    with pytest.raises(MethodNotAvailableError, match="outside the measured domain") as err:
        solve(h, "fpe")
    message = str(err.value)
    assert "solve(h, 'mc')" in message
    assert "harvester stats --n 1 --a 2 --param tau_p=3 --method mc" in message
    assert "force=True" in message
    with pytest.raises(MethodNotAvailableError, match="Monte Carlo"):
        FokkerPlanck().solve(h)
    assert FokkerPlanck().unsupported_reason(h) == message


def test_force_attempts_outside(monkeypatch: pytest.MonkeyPatch) -> None:
    """force=True takes the unit to the solver (here a stand-in that records the call)."""
    calls = []

    class _Solution:
        stats = Stats(status=Status.NOT_CONVERGED, message="stand-in", method="fpe")

    def record(h: Harvester, settings: object, grid: int, progress: object) -> _Solution:
        calls.append(h)
        return _Solution()

    monkeypatch.setattr(solver, "solve_settings", record)
    h = Harvester.build(a=2.0, n=1.0)
    assert FokkerPlanck(force=True).unsupported_reason(h) is None
    assert solve(h, "fpe", force=True).message == "stand-in"
    assert calls == [h]


def test_ring_reason_comes_first_and_force_is_checked() -> None:
    ring = Harvester.build(a=2.0, n=1.0, N=3, k=-0.1)
    assert "single oscillator" in FokkerPlanck(force=True).unsupported_reason(ring)
    with pytest.raises(ParameterError, match="force must be True or False"):
        FokkerPlanck(force="yes")  # type: ignore[arg-type]
