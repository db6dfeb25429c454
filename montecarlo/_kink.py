"""numba kernels of the kink: the exact piecewise-linear flow of :math:`-an\\,\\mathrm{sign}(x)`.

Private module of the frozen-xi step (:mod:`montecarlo.steps.frozen`). For the kink
(1 <= n <= 1 + KINK_WIDTH of :mod:`montecarlo.coefficients`) the part :math:`-an\\,\\mathrm{sign}(x)`
of the on-site force is integrated by an exact piecewise-linear flow with located zero
crossings (the remainder by Strang kicks). Toward rest the kink's swings shrink exponentially
in time and never stop (docs/model.md §3); once they are much shorter than the step the flow
advances them by the averaged map of their amplitude (:data:`AVERAGE`). ``pp[P_KINK_FORCE]`` is
the strength :math:`an` of the kink part and ``pp[P_KINK_RULE]`` its rule (:data:`AVERAGE` or
:data:`HOLD`); :mod:`montecarlo.layout` has the layout of ``cf`` and ``pp``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .layout import (C_AVERAGED, C_CROSSINGS, C_EXHAUSTED, C_SLOW, CF_E, CF_G, CF_H, P_GAMMA, P_KC,
                     P_KINK_FORCE, P_KINK_RULE, P_KV, P_M, P_STIFFNESS, P_TAU_P)

#: Kink rule for swings shorter than the step (``pp[P_KINK_RULE]``). The model's swings never stop
#: (docs/model.md §3). AVERAGE (default) advances them with the averaged map of their crossing
#: speed, w -> w exp(-gamma r/3) (:func:`_average_swing`), once AVG_SWINGS full swings fit in
#: the time left of a step; HOLD follows them until MAX_EVENTS crossings in one step and then
#: holds the unit at rest, a time-step artifact (validation/studies/montecarlo.py compares them).
AVERAGE = 0.0
HOLD = 1.0
AVG_SWINGS = 4.0
MAX_EVENTS = 64
N_SAMPLE = 8
N_TAYLOR = 11


@njit(cache=True, nogil=True)
def _series(x: float, v: float, V: float, F: float, pp: np.ndarray, cs: np.ndarray) -> None:
    """Taylor coefficients ``cs[i, k] = y_i^(k)(0)/k!`` of the linear flow with constant force F.

    Within one step (|A| h << 1) degree N_TAYLOR leaves a relative error below 1e-13.
    """
    m, gamma, Kv, Kc, tau_p, c = pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KC], pp[P_TAU_P], pp[P_STIFFNESS]
    cs[0, 0], cs[1, 0], cs[2, 0] = x, v, V
    # the first derivative carries the constant force; later ones are powers of A
    dx, dv, dV = v, (F - c * x - Kv * V) / m - gamma * v, Kc * v - V / tau_p
    fac = 1.0
    for kk in range(1, N_TAYLOR + 1):
        fac = fac / kk
        cs[0, kk], cs[1, kk], cs[2, kk] = dx * fac, dv * fac, dV * fac
        dx, dv, dV = dv, (-c * dx - Kv * dV) / m - gamma * dv, Kc * dv - dV / tau_p


@njit(cache=True, nogil=True, inline="always")
def _horner(cs: np.ndarray, row: int, t: float, shift: int) -> float:
    """sum_k cs[row, k] t^(k - shift) over k >= shift."""
    r = cs[row, N_TAYLOR]
    for kk in range(N_TAYLOR - 1, shift - 1, -1):
        r = r * t + cs[row, kk]
    return r


@njit(cache=True, nogil=True, inline="always")
def _dhorner(cs: np.ndarray, row: int, t: float, shift: int) -> float:
    """Derivative in t of :func:`_horner`."""
    r = 0.0
    for kk in range(N_TAYLOR, shift, -1):
        r = r * t + (kk - shift) * cs[row, kk]
    return r


@njit(cache=True, nogil=True)
def _first_crossing(cs: np.ndarray, s: float, shift: int, rem: float) -> float:
    """First t in (0, rem] where s x(t) <= 0, or -1. ``shift`` deflates a root at t = 0.

    x(t) = t^shift g(t) with s g(0) > 0; the grid brackets the first sign change of g and
    safeguarded Newton polishes it to round-off. A converged Newton iterate is the root
    whichever side of it round-off leaves it on (the caller sets x = 0 there and continues
    on the side v points to); only a bracket that collapses without Newton converging returns
    its far end.
    """
    lo = 0.0
    hi = -1.0
    for i in range(1, N_SAMPLE + 1):
        ti = rem * i / N_SAMPLE
        if s * _horner(cs, 0, ti, shift) <= 0.0:
            hi = ti
            break
        lo = ti
    if hi < 0.0:
        return -1.0
    t = 0.5 * (lo + hi)
    for _ in range(60):
        g = _horner(cs, 0, t, shift)
        if s * g > 0.0:
            lo = t
        else:
            hi = t
        if hi - lo <= 1e-15 * rem:
            break
        dg = _dhorner(cs, 0, t, shift)
        tn = t - g / dg if dg != 0.0 else 0.5 * (lo + hi)
        if not (lo < tn < hi):
            tn = 0.5 * (lo + hi)
        elif abs(tn - t) <= 1e-15 * rem:
            return tn
        t = tn
    return hi


@njit(cache=True, nogil=True)
def _net_exit_time(f: float, V: float, rem: float, pp: np.ndarray) -> float:
    """Time within ``rem`` at which the net force f - Kv V(t) leaves [-a, a] as V decays
    (V(t) = V e^(-t/tau_p); the net force relaxes monotonically toward f), or ``rem``
    (0 if it is outside already)."""
    Kv, tau_p, a = pp[P_KV], pp[P_TAU_P], pp[P_KINK_FORCE]
    if abs(f - Kv * V) > a:
        return 0.0
    net_end = f - Kv * V * math.exp(-rem / tau_p)
    if abs(net_end) <= a:
        return rem
    s = 1.0 if net_end > 0.0 else -1.0
    u = -tau_p * math.log((f - s * a) / (Kv * V))
    return min(max(u, 0.0), rem)


@njit(cache=True, nogil=True)
def _average_swing(v: float, V: float, f: float, rem: float, pp: np.ndarray) -> tuple:
    """Swings from x = 0 at speed v, too short to follow, over ``rem`` or until the net force
    leaves (-a, a): returns x, v, V and the time u advanced.

    Averaged map (docs/model.md §3): each half-swing on side s lasts 2 m w/(a - s F) and
    loses a part of the crossing speed w proportional to that time, so w decays as
    exp(-gamma u/3) whatever F is; V relaxes, driven only by the swing's mean position (its
    mean v is 0). The unit is placed on its arc at the phase of the swing count elapsed,
    integrated with that law: deterministic, and uniform in time over the arcs like the exact
    sequence, whose phase is as sensitive to its inputs. w = 0 is rest, its fixed point.
    Neglected: the damping within one swing and the swing's feedback through Kv V, relative
    O(gamma P) and O(Kv Kc P^2) for a swing period P below a quarter of the step.
    """
    m, gamma, Kc, tau_p, a = pp[P_M], pp[P_GAMMA], pp[P_KC], pp[P_TAU_P], pp[P_KINK_FORCE]
    u = _net_exit_time(f, V, rem, pp)
    net = f - pp[P_KV] * V
    V = V * math.exp(-u / tau_p)
    w = abs(v)
    if w == 0.0:
        return 0.0, 0.0, V, u
    # V = V0 e^(-u/tau_p) + Kc x(u) - (Kc/tau_p) int e^(-(u-t)/tau_p) x(t) dt, with x(t)
    # replaced by its mean over a swing, 2 m net w(t)^2 / (3 (a^2 - net^2))
    lam = 1.0 / tau_p - 2.0 * gamma / 3.0
    decay = math.expm1(lam * u) / lam if lam != 0.0 else u
    V -= Kc / tau_p * 2.0 * m * net * w * w / (3.0 * (a * a - net * net)) * math.exp(-u / tau_p) * decay
    s = 1.0 if v > 0.0 else -1.0
    # swings elapsed: integral of dt / period(w(t)), period(w) = 4 a m w / (a^2 - net^2)
    grow = math.expm1(gamma * u / 3.0) * 3.0 / gamma if gamma > 0.0 else u
    cycles = (a * a - net * net) / (4.0 * a * m * w) * grow
    # beyond 2^52 (or overflowed) the count has no fractional digits left: phase 0
    phase = cycles - math.floor(cycles) if cycles < 4.5e15 else 0.0
    w *= math.exp(-gamma * u / 3.0)
    net = f - pp[P_KV] * V
    k1, k2 = (a - s * net) / m, (a + s * net) / m
    if u < rem or k1 <= 0.0 or k2 <= 0.0:
        # the net force has reached +-a: one arc is unbounded, so the unit is left at the
        # crossing, moving into the side it is about to leave toward
        return 0.0, w if net > 0.0 else -w, V, u
    t1 = 2.0 * w / k1
    tau = phase * (t1 + 2.0 * w / k2)
    if tau < t1:
        x, v = s * tau * (w - 0.5 * k1 * tau), s * (w - k1 * tau)
    else:
        tau -= t1
        x, v = -s * tau * (w - 0.5 * k2 * tau), -s * (w - k2 * tau)
    return x, v, V + Kc * x, u


@njit(cache=True, nogil=True)
def _kink_unit(x: float, v: float, V: float, stuck: bool, f: float, cf: np.ndarray,
               pp: np.ndarray, counters: np.ndarray, cs: np.ndarray) -> tuple:
    """Advance one unit of the n = 1 potential over one D step with external force f.

    The slow path of :func:`_kink_flow`, for units at or near x = 0. Exact piecewise flow:
    each side of x = 0 is linear with constant force f - a s (a = ``pp[P_KINK_FORCE]``); zero crossings
    are located on the flow's Taylor series (bracketing + safeguarded Newton). Swings shorter
    than the step never stop (docs/model.md §3): with the rule ``pp[P_KINK_RULE]`` = :data:`AVERAGE`,
    once AVG_SWINGS full swings fit in the time left, the rest of the step is the averaged
    map :func:`_average_swing`; with :data:`HOLD` they are followed until MAX_EVENTS
    crossings in one step and the unit is then held at x = v = 0 (``stuck``) while the net
    force |f - Kv V| <= a, a time-step artifact kept for comparison.
    """
    m, Kv, a = pp[P_M], pp[P_KV], pp[P_KINK_FORCE]
    hold = pp[P_KINK_RULE] == HOLD
    h = cf[CF_H]
    counters[C_SLOW] += 1
    t = 0.0
    for _ in range(MAX_EVENTS):
        rem = h - t
        if rem <= 0.0:
            return x, v, V, stuck
        if x != 0.0:
            s = 1.0 if x > 0.0 else -1.0
            shift = 0
        elif v != 0.0:
            s = 1.0 if v > 0.0 else -1.0
            shift = 1
        else:
            if stuck or abs(f - Kv * V) <= a:
                # at rest: nothing moves until the net force, relaxing with V, reaches +-a;
                # then the unit leaves at once (|net| = a up to round-off must not re-enter)
                x, v, V, u = _average_swing(0.0, V, f, rem, pp)
                if u >= rem:
                    return x, v, V, stuck
                t += u
                rem = h - t
                stuck = False
            s = 1.0 if f - Kv * V > 0.0 else -1.0
            shift = 2
        _series(x, v, V, f - a * s, pp, cs)
        tc = _first_crossing(cs, s, shift, rem)
        if tc < 0.0:
            return _horner(cs, 0, rem, 0), _horner(cs, 1, rem, 0), _horner(cs, 2, rem, 0), False
        v, V = _horner(cs, 1, tc, 0), _horner(cs, 2, tc, 0)
        x = 0.0
        t += tc
        counters[C_CROSSINGS] += 1
        net = f - Kv * V
        if not hold and AVG_SWINGS * 4.0 * a * m * abs(v) < (h - t) * (a * a - net * net):
            counters[C_AVERAGED] += 1
            x, v, V, u = _average_swing(v, V, f, h - t, pp)
            t += u
    # event budget exhausted (long chatter, HOLD only): the unit is at or next to x = 0
    counters[C_EXHAUSTED] += 1
    if hold and abs(f - Kv * V) <= a:
        return 0.0, 0.0, V, True
    return x, v, V, stuck



@njit(cache=True, nogil=True)
def _kink_flow(x, v, V, stuck, f, w, cf, pp, counters, cs) -> None:
    """D step of the kink potential: one exact affine step away from x = 0, events near it."""
    N, P = x.shape
    m, gamma, Kv, a, c = pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KINK_FORCE], pp[P_STIFFNESS]
    h = cf[CF_H]
    for j in range(N):
        for p in range(P):
            if w[p] == 0.0:
                continue
            x0, v0, V0 = x[j, p], v[j, p], V[j, p]
            if not stuck[j, p] and x0 != 0.0:
                s = 1.0 if x0 > 0.0 else -1.0
                Fs = f[j, p] - a * s
                xn = cf[CF_E] * x0 + cf[CF_E + 1] * v0 + cf[CF_E + 2] * V0 + cf[CF_G] * Fs
                # no crossing possible within the step: |x| exceeds the distance reachable
                # with the current speed and a generous bound on the acceleration
                acc = (abs(Fs) + abs(c * x0) + m * gamma * abs(v0) + Kv * abs(V0)) / m
                if s * xn > 0.0 and s * x0 > h * (abs(v0) + 2.0 * h * acc):
                    x[j, p] = xn
                    v[j, p] = cf[CF_E + 3] * x0 + cf[CF_E + 4] * v0 + cf[CF_E + 5] * V0 + cf[CF_G + 1] * Fs
                    V[j, p] = cf[CF_E + 6] * x0 + cf[CF_E + 7] * v0 + cf[CF_E + 8] * V0 + cf[CF_G + 2] * Fs
                    continue
            x[j, p], v[j, p], V[j, p], stuck[j, p] = _kink_unit(
                x0, v0, V0, stuck[j, p], f[j, p], cf, pp, counters, cs)

