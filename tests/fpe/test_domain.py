"""The Fokker--Planck solver's measured domain: the rule on both sides of its boundary, the
decline (at once, naming Monte Carlo) and the forced attempt."""

from __future__ import annotations

import math

import pytest
from scipy.optimize import brentq

from fpe_harvester import Harvester, MethodNotAvailableError, ParameterError, Status, solve
from fpe_harvester.fpe import FokkerPlanck, solver
from fpe_harvester.fpe.domain import (
    A_OFF_DEFAULTS, CHECKED, DOMAIN, at_defaults, outside_reason, strength_limit, trap_strength,
)
from fpe_harvester.result import Stats


def _at_strength(s: float, n: float, **params: float) -> Harvester:
    """The unit of exponent n (``params`` changed) whose trap strength is s (s is nearly
    proportional to a: the root is bracketed around the proportional guess)."""
    strength = lambda a: trap_strength(Harvester.build(a=a, n=n, **params))  # noqa: E731
    guess = s / strength(1.0)
    a = brentq(lambda a: strength(a) - s, 0.7 * guess, 1.4 * guess, xtol=1e-9)
    return Harvester.build(a=a, n=n, **params)


@pytest.mark.parametrize(("tol", "row"), [(t, row) for t, rows in DOMAIN.items() for row in range(len(rows))])
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
        assert outside_reason(Harvester.build(a=0.99 * a_max, n=n, R=3.0, Kc=2.0, Kv=0.5), tol) is None
        assert outside_reason(Harvester.build(a=1.01 * a_max, n=n, R=3.0, Kc=2.0, Kv=0.5), tol) is not None


def test_rule_off_the_defaults() -> None:
    """A quantity that shapes the trap off its default (gamma, tau, tau_p, m, K_c K_v, and for
    n != 1 sigma^2 D) gets the limit of a = 0.5 at the defaults, on both sides of it, within the
    checked ranges; outside them the unit is declined at any strength. The exact invariances
    (R, K_c K_v, and for n = 1 sigma sqrt(D) with a) keep the measured bands."""
    tol = 1e-4
    assert strength_limit(1.0, 1e-3, defaults=False) == strength_limit(1.0, tol, defaults=False)
    assert at_defaults(Harvester.build(a=2.0, n=1.0, sigma=2.0, D=0.5, R=3.0, Kc=2.0, Kv=0.5))
    assert at_defaults(Harvester.build(a=2.0, n=1.5, sigma=2.0, D=0.25))
    for change in ({"gamma": 0.5}, {"tau": 2.0}, {"tau_p": 4.0}, {"m": 2.0}, {"Kv": 2.0}):
        assert not at_defaults(Harvester.build(a=1.0, n=1.0, **change))
    assert not at_defaults(Harvester.build(a=1.0, n=1.5, sigma=2.0))
    for n, change in ((1.0, {"tau": 2.0}), (1.0, {"tau_p": 4.0}), (1.5, {"sigma": 2.0})):
        limit = strength_limit(n, tol, defaults=False)
        assert limit == pytest.approx(trap_strength(Harvester.build(a=A_OFF_DEFAULTS, n=n)), rel=1e-12)
        assert outside_reason(_at_strength(0.99 * limit, n, **change), tol) is None
        message = outside_reason(_at_strength(1.01 * limit, n, **change), tol)
        assert message is not None and "the limit off the default parameters" in message
    # sigma = 2 at n = 1 is the default unit with a / 2: the bands hold
    assert outside_reason(Harvester.build(a=2.0, n=1.0, sigma=2.0), tol) is None


def test_rule_outside_the_checked_ranges() -> None:
    """Weak damping and a stronger circuit feedback failed even at the weakest strength: such
    units are declined however weak the trap, with the quantity and its checked range named."""
    for change, quantity in (({"gamma": 0.5}, "gamma = 0.5"), ({"Kv": 4.0}, "Kc Kv = 4"),
                             ({"tau": 8.0}, "tau = 8")):
        lo, hi = CHECKED[quantity.split(" = ")[0]]
        message = outside_reason(Harvester.build(a=0.05, n=1.0, **change))
        assert message is not None and f"{quantity} (checked {lo:g} to {hi:g})" in message
    for change in ({"gamma": CHECKED["gamma"][0]}, {"tau": CHECKED["tau"][1]}, {"m": CHECKED["m"][0]}):
        assert outside_reason(Harvester.build(a=0.1, n=1.0, **change)) is None


def test_strength_is_relative_to_the_drive() -> None:
    """For n = 1 (a, sigma) -> (c a, c sigma) is an exact change of scale: s does not move; a
    stronger noise makes the same a weaker; K_c and K_v act only through their product."""
    s = trap_strength(Harvester.build(a=1.0, n=1.0))
    assert trap_strength(Harvester.build(a=2.0, n=1.0, sigma=2.0)) == pytest.approx(s, rel=1e-9)
    assert trap_strength(Harvester.build(a=1.0, n=1.0, D=4.0)) < s
    assert trap_strength(Harvester.build(a=1.0, n=1.0, Kc=2.0, Kv=0.5)) == pytest.approx(s, rel=1e-9)


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
