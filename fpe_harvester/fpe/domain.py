"""Where the Fokker--Planck solver answers: its measured domain, and what to use outside it.

For :math:`1 \\le n < 2` the density of a strong potential concentrates at x = 0 (for the
kink n = 1 a power law at the trap (x, v) = (0, 0), docs/model.md §3), and beyond a
strength that grows with n the refinement of either scheme stops without reaching its
tolerance: it fails, after seconds to minutes, with no number or a poor one. This module
holds the measured boundary and the rule that :meth:`~.solver.FokkerPlanck.unsupported_reason`
consults before any work, so that a solve outside declines at once and names Monte Carlo.

**The measure of strength.** The unit is trapped near x = 0 while the net drive
:math:`F = \\sigma\\xi - K_v V` stays inside :math:`(-a, a)` (exactly so for n = 1), so the
strength of the potential is taken relative to the drive,

.. math::

    s = \\frac{a}{\\min(s_F, \\sigma\\sqrt{D/\\tau})},

with :math:`s_F` the standard deviation of F in the equivalent harmonic unit
(:func:`~.hermite.equivalent_harmonic`, a 4 x 4 Lyapunov solve: a few milliseconds) and
:math:`\\sigma\\sqrt{D/\\tau}` that of the noise force alone. At the defaults :math:`s_F` is
0.88-0.99 of the latter, so s is a / 0.88 at a = 0.5 and a / 0.99 at a = 3. For n = 1 a
change of scale maps (a, sigma) to (c a, c sigma) exactly, and s is invariant under it.

**The rule** (:data:`DOMAIN`, measured by ``python -m validation.studies.fpe.domain``, the table
in docs/methods.md). Per tolerance class and band of n, the largest a (every other parameter
at its default) at which the solver converged at every measured n of the band; a unit is
inside when its s is at most that of the default unit with that a at its own n (at the
defaults: a <= a_max). The margin: the boundary is the last strength that converged, not a
point between it and the first that failed, and a band of n takes the boundary of its
lowest n (the potential gets harder as n falls). n >= 2 is always inside (no trap, smooth density;
the benchmark of :mod:`validation.studies.fpe.bench` covers n = 2-8); so are strengths below the
measured ones (nothing there is known to fail; a failure there ends as ``not_converged``
with its reason). Tolerances at or above 1e-3 use the 1e-3 boundary, tighter ones the 1e-4
boundary (tighter than 1e-4 was not mapped: a stop there costs time, not a wrong number).

**Off the defaults.** The model depends on some parameters only through combinations:
R enters only eta, K_c and K_v only through :math:`K_c K_v` (write :math:`W = K_v V`), sigma
and D only through :math:`\\sigma\\sqrt D`, and for n = 1 a change of scale maps
(a, :math:`\\sigma\\sqrt D`) to (c a, c :math:`\\sigma\\sqrt D`) exactly, leaving s and the
solver's work unchanged. A unit whose m, gamma, tau, tau_p and :math:`K_c K_v` (and for n != 1
also :math:`\\sigma\\sqrt D`) are the defaults is *at the defaults* (:func:`at_defaults`) and
gets the measured bands. s does not follow how long a trapped spell lasts against the
unit's damping: on the boundary of the hardest band (n = 1, s = 1.12, tol 1e-3) gamma = 0.5,
K_v = 2 and tau_p = 4 fail where tau = 0.5 or 2, tau_p = 1, gamma = 2 and m = 2 converge (the
study's spot checks). So any other unit gets the weakest measured strength as its limit,
that of a = :data:`A_OFF_DEFAULTS` at the defaults at its n, whatever the band, and only
within the ranges of :data:`CHECKED`, where units on that limit converged with one quantity
changed at a time (combinations were not checked). Beyond them a researcher can attempt the
solve with ``FokkerPlanck(force=True)``.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..model import Harvester, Params
from .hermite import equivalent_harmonic

__all__ = ["DOMAIN", "A_OFF_DEFAULTS", "CHECKED", "trap_strength", "at_defaults", "strength_limit",
           "outside_reason"]

#: The measured domain for 1 <= n < 2: per tolerance class (the tightest tol of the class),
#: rows (n_low, a_max): for n_low <= n < the next row's n_low, the largest a of the map
#: (a in {0.5, 1, 1.5, 2, 3}, defaults otherwise) at which the solver converged at every n
#: of the map in the band. The map (``python -m validation.studies.fpe.domain``): at 1e-3
#: n = 1-1.25 converge up to a = 1 and fail from 1.5, n = 1.5 up to 2 (fails at 3), n = 1.75
#: up to 3; at 1e-4 n = 1-1.5 up to a = 1 (n = 1.5 fails from 1.5), n = 1.75 up to 2 (fails at 3).
DOMAIN: dict[float, tuple[tuple[float, float], ...]] = {
    1e-3: ((1.0, 1.0), (1.5, 2.0), (1.75, 3.0)),
    1e-4: ((1.0, 1.0), (1.75, 2.0)),
}


#: Off the defaults (:func:`at_defaults` False) the limit is the strength of this a at the
#: defaults: the weakest point of the map, converged at every n and both tolerances in 1-23 s.
A_OFF_DEFAULTS = 0.5

#: Off the defaults, the range of each quantity that shapes the trap within which units on
#: the limit of :data:`A_OFF_DEFAULTS` converged, one quantity changed at a time (the study's
#: spot checks at tol 1e-4, n = 1 and 1.5). Outside a range the solver declines at any
#: strength: gamma = 0.25 and 0.5 and K_c K_v = 4 failed there (GMRES stalls: weakly damped
#: swings and a stronger circuit feedback make the cycles of the (x, v) transport harder).
CHECKED = {"m": (0.5, 2.0), "gamma": (0.75, 4.0), "tau": (0.25, 4.0), "tau_p": (0.5, 8.0),
           "Kc Kv": (0.5, 2.0), "sigma^2 D": (0.25, 4.0)}


def _shape(h: Harvester) -> dict[str, float]:
    """The quantities that shape the trap (:data:`CHECKED`): :math:`K_c K_v` together (only
    their product enters the dynamics of :math:`W = K_v V`), and :math:`\\sigma^2 D` (only
    :math:`\\sigma\\sqrt D` enters) except for n = 1, where s absorbs it exactly."""
    p = h.params
    q = {"m": p.m, "gamma": p.gamma, "tau": p.tau, "tau_p": p.tau_p, "Kc Kv": p.Kc * p.Kv}
    if h.n != 1.0:
        q["sigma^2 D"] = p.sigma**2 * p.D
    return q


def at_defaults(h: Harvester) -> bool:
    """True if every quantity that shapes the trap is at the paper's default, up to the
    model's exact invariances (R; :math:`K_c K_v` together; :math:`\\sigma\\sqrt D` together,
    and for n = 1 not at all, since s absorbs it)."""
    d = _shape(Harvester.build(a=h.a, n=h.n))
    return all(math.isclose(v, d[k], rel_tol=1e-12) for k, v in _shape(h).items())


def trap_strength(h: Harvester) -> float:
    """Strength of the potential relative to the drive, :math:`s = a/\\min(s_F, \\sigma\\sqrt{D/\\tau})`.

    :math:`s_F^2 = \\sigma^2 P_{\\xi\\xi} + K_v^2 P_{VV} - 2\\sigma K_v P_{V\\xi}` from the
    covariance P of the equivalent harmonic unit (dimensionless; a few milliseconds).

    Examples
    --------
    >>> round(trap_strength(Harvester.build(a=1.0, n=1.0)), 2)
    1.12
    """
    p = h.params
    _, P = equivalent_harmonic(h)
    var = p.sigma**2 * P[3, 3] + p.Kv**2 * P[2, 2] - 2.0 * p.sigma * p.Kv * P[2, 3]
    return h.a / min(math.sqrt(max(var, 0.0)), p.sigma * math.sqrt(p.noise_variance))


def _tol_class(tol: float) -> float:
    return 1e-3 if tol >= 1e-3 else 1e-4


def _row(n: float, tol: float) -> tuple[float, float]:
    rows = DOMAIN[_tol_class(tol)]
    return [r for r in rows if r[0] <= n][-1]


@functools.cache
def _limit_at(n: float, a_max: float) -> float:
    return trap_strength(Harvester.build(a=a_max, n=n))


def strength_limit(n: float, tol: float = 1e-4, defaults: bool = True) -> float:
    """The largest trap strength s inside the domain at exponent n and tolerance ``tol``:
    that of the default unit at this n with the band's ``a_max`` (so that at the defaults
    the rule is a <= a_max), or off the defaults (``defaults=False``) with
    :data:`A_OFF_DEFAULTS`; infinite for n >= 2."""
    if n >= 2.0:
        return math.inf
    return _limit_at(n, _row(n, tol)[1] if defaults else A_OFF_DEFAULTS)


def outside_reason(h: Harvester, tol: float = 1e-4) -> str | None:
    """None if the single unit ``h`` is inside the measured domain at ``tol``, else why not
    and what to use (Monte Carlo, or ``force=True`` to attempt it anyway)."""
    if h.N != 1 or h.n >= 2.0:
        return None
    defaults = at_defaults(h)
    unchecked = [] if defaults else [f"{k} = {v:g} (checked {CHECKED[k][0]:g} to {CHECKED[k][1]:g})"
                                     for k, v in _shape(h).items() if not CHECKED[k][0] <= v <= CHECKED[k][1]]
    try:
        s = trap_strength(h)
    except np.linalg.LinAlgError:
        # no equivalent harmonic unit at these scales (a = 1e-8: the variances span too many
        # decades): no measured boundary applies; the solver meets the same failure and says so
        return None
    limit = strength_limit(h.n, tol, defaults)
    if not unchecked and s <= limit * (1.0 + 1e-9):
        return None
    params = {k: v for k, v in h.params.to_dict().items() if v != getattr(Params(), k)}
    if unchecked:
        why = (f"off the default parameters it was checked within ranges, one quantity at a time, and "
               f"{', '.join(unchecked)} is outside them")
    elif defaults:
        n_low, a_max = _row(h.n, tol)
        nexts = [r[0] for r in DOMAIN[_tol_class(tol)] if r[0] > n_low]
        why = (f"its trap strength a / sd(drive) = {s:.3g} exceeds {limit:.3g}, the strength at which it "
               f"last converged for {n_low:g} <= n < {nexts[0] if nexts else 2:g} (a = {a_max:g} at the "
               f"default parameters; at stronger traps the density concentrates at x = 0 and the refinement "
               f"stops without an answer)")
    else:
        why = (f"its trap strength a / sd(drive) = {s:.3g} exceeds {limit:.3g}, the limit off the default "
               f"parameters, that of a = {A_OFF_DEFAULTS:g} at the defaults")
    extra = "".join(f" --param {k}={v:g}" for k, v in params.items())
    return (f"n = {h.n:g}, a = {h.a:g} is outside the measured domain of the Fokker-Planck solver at tol "
            f"{tol:.2g}: {why}. Use Monte Carlo: solve(h, 'mc') or harvester stats --n {h.n:g} --a {h.a:g}"
            f"{extra} --method mc; FokkerPlanck(force=True) attempts it anyway")
