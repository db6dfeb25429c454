"""numba kernels of the kink: the exact piecewise-linear flow of :math:`-an\\,\\mathrm{sign}(x)`.

Private module of the frozen-xi step (:mod:`montecarlo.steps.frozen`). For the kink
(1 <= n <= 1 + KINK_WIDTH of :mod:`montecarlo.coefficients`) the part :math:`-an\\,\\mathrm{sign}(x)`
of the on-site force is integrated by an exact piecewise-linear flow with located zero
crossings (the remainder by Strang kicks). Toward rest the kink's swings shrink exponentially
in time and never stop (docs/model.md §3); once they are short against the step the flow
advances them by the averaged map of their amplitude (:data:`AVERAGE`). ``pp[P_KINK_FORCE]`` is
the strength :math:`an` of the kink part and ``pp[P_KINK_RULE]`` its rule (:data:`AVERAGE` or
:data:`HOLD`); :mod:`montecarlo.layout` has the layout of ``cf`` and ``pp``.

Where the time goes and what each part of the step costs: docs/methods.md, "The kink's step".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .layout import (C_AVERAGED, C_CROSSINGS, C_EXHAUSTED, C_SLOW, CF_E, CF_G, CF_H, P_GAMMA, P_KC,
                     P_KINK_FORCE, P_KINK_RULE, P_KV, P_M, P_STIFFNESS, P_TAU_P)

#: Kink rules for swings shorter than the step: ``pp[P_KINK_RULE]`` is the number of full swings
#: that must fit in the time left of a step before the averaged map of their crossing speed,
#: w -> w exp(-gamma r/3) (:func:`_average_swing`), advances them from wherever the unit is on its
#: arc; the model's swings never stop (docs/model.md §3). AVERAGE (default) averages swings
#: once four full swings fit in the time left (a looser threshold, a quarter swing, put 5 % too
#: much density on the innermost energy shell at a = 2: docs/methods.md); HOLD (0) never averages: it follows them until MAX_EVENTS
#: crossings in one step and then holds the unit at rest, a time-step artifact kept to compare with.
AVERAGE = 4.0
HOLD = 0.0
MAX_EVENTS = 64
N_SAMPLE = 8
#: Largest degree of the flow's Taylor series (:func:`_degree` takes less where the step allows).
N_TAYLOR = 11
#: 1/k!, k <= N_TAYLOR (a constant of the compiled kernels: no division per coefficient)
_INV_FACTORIAL = np.array([1.0 / math.factorial(k) for k in range(N_TAYLOR + 1)])


@njit(cache=True, nogil=True)
def _degree(h: float, rho: float) -> int:
    """Smallest degree K <= N_TAYLOR whose Taylor remainder of :math:`e^{At}`, t <= h, is below
    the unit round-off: :math:`(\\rho h)^{K+1} e^{\\rho h}/(K+1)! \\le 2^{-53}`, :math:`\\rho \\ge \\|A\\|`."""
    term = math.exp(rho * h)
    for kk in range(1, N_TAYLOR + 1):
        term *= rho * h / (kk + 1)
        if term <= 1.1102230246251565e-16:
            return kk
    return N_TAYLOR


@njit(cache=True, nogil=True)
def _decays(u: float, pp: np.ndarray) -> tuple:
    """The averaged map's factors over a time u: :math:`e^{-u/\\tau_p}`, :math:`e^{-\\gamma u/3}`,
    :math:`\\int_0^u e^{\\lambda t}dt` with :math:`\\lambda = 1/\\tau_p - 2\\gamma/3`, and
    :math:`\\int_0^u e^{\\gamma t/3}dt`."""
    gamma, tau_p = pp[P_GAMMA], pp[P_TAU_P]
    lam = 1.0 / tau_p - 2.0 * gamma / 3.0
    decay = math.expm1(lam * u) / lam if lam != 0.0 else u
    grow = math.expm1(gamma * u / 3.0) * 3.0 / gamma if gamma > 0.0 else u
    return math.exp(-u / tau_p), math.exp(-gamma * u / 3.0), decay, grow


@njit(cache=True, nogil=True)
def _step_constants(h: float, pp: np.ndarray) -> tuple:
    """What every unit's step of size h shares, computed once per step: h, the Taylor degree
    (:func:`_degree`, with :math:`\\rho = \\|A\\|_\\infty`) and :func:`_decays` of h."""
    m, gamma, Kv, Kc, tau_p, c = pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KC], pp[P_TAU_P], pp[P_STIFFNESS]
    rho = max(1.0, (abs(c) + abs(Kv)) / m + gamma, abs(Kc) + 1.0 / tau_p)
    return (h, _degree(h, rho)) + _decays(h, pp)


@njit(cache=True, nogil=True, inline="always")
def _series(x: float, v: float, V: float, F: float, pp: np.ndarray, cs: np.ndarray, K: int) -> None:
    """Taylor coefficients ``cs[i, k] = y_i^(k)(0)/k!``, k <= K, of the linear flow with constant force F."""
    m, gamma, Kv, Kc, tau_p, c = pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KC], pp[P_TAU_P], pp[P_STIFFNESS]
    cs[0, 0], cs[1, 0], cs[2, 0] = x, v, V
    # the first derivative carries the constant force; later ones are powers of A
    dx, dv, dV = v, (F - c * x - Kv * V) / m - gamma * v, Kc * v - V / tau_p
    for kk in range(1, K + 1):
        fac = _INV_FACTORIAL[kk]
        cs[0, kk], cs[1, kk], cs[2, kk] = dx * fac, dv * fac, dV * fac
        dx, dv, dV = dv, (-c * dx - Kv * dV) / m - gamma * dv, Kc * dv - dV / tau_p


@njit(cache=True, nogil=True, inline="always")
def _horner(cs: np.ndarray, row: int, t: float, shift: int, K: int) -> float:
    """sum_k cs[row, k] t^(k - shift) over shift <= k <= K."""
    r = cs[row, K]
    for kk in range(K - 1, shift - 1, -1):
        r = r * t + cs[row, kk]
    return r


@njit(cache=True, nogil=True, inline="always")
def _dhorner(cs: np.ndarray, row: int, t: float, shift: int, K: int) -> float:
    """Derivative in t of :func:`_horner`."""
    r = 0.0
    for kk in range(K, shift, -1):
        r = r * t + (kk - shift) * cs[row, kk]
    return r


@njit(cache=True, nogil=True, inline="always")
def _curvature_bound(cs: np.ndarray, rem: float, K: int) -> float:
    """Bound on |x''(t) - x''(0)| over [0, rem]: sum over k >= 3 of k (k - 1) |cs[0, k]| rem^(k-2)."""
    r = 0.0
    for kk in range(K, 2, -1):
        r = r * rem + kk * (kk - 1) * abs(cs[0, kk])
    return r * rem


@njit(cache=True, nogil=True, inline="always")
def _model_root(q0: float, q1: float, q2: float) -> float:
    """Smallest positive root of q0 + q1 t + q2 t^2 (q0 > 0) in its cancellation-free form, or -1."""
    disc = q1 * q1 - 4.0 * q0 * q2
    if disc < 0.0:
        return -1.0
    d = math.sqrt(disc) - q1
    return 2.0 * q0 / d if d > 0.0 else -1.0


@njit(cache=True, nogil=True, inline="always")
def _polish(cs: np.ndarray, s: float, shift: int, lo: float, hi: float, t: float, rem: float, K: int) -> float:
    """The root of s g in the bracket (lo, hi) (s g(lo) > 0 >= s g(hi), x(t) = t^shift g(t)) by
    safeguarded Newton from t; a converged iterate is the root whichever side of it round-off
    leaves it on (the caller sets x = 0 there and continues on the side v points to); only a
    bracket that collapses without Newton converging returns its far end."""
    if not (lo < t < hi):
        t = 0.5 * (lo + hi)
    g = 1.0
    for _ in range(60):
        g = _horner(cs, 0, t, shift, K)
        if s * g > 0.0:
            lo = t
        else:
            hi = t
        if hi - lo <= 1e-15 * rem or g == 0.0:
            break
        dg = _dhorner(cs, 0, t, shift, K)
        tn = t - g / dg if dg != 0.0 else 0.5 * (lo + hi)
        # converged before the bracket test: a last step that lands on the bracket's end
        # (the root to round-off) is no reason to bisect. Newton's next error is about
        # step^2 g''/2g' ~ step^2/2t here (arcs are near-parabolas over t), so after a step of
        # 1e-6 t the root is within 1e-12 t (x within ~1e-12 of its scale: x = 0 set there)
        # without another evaluation.
        if abs(tn - t) <= max(1e-6 * t, 1e-15 * rem):
            return tn
        if not (lo < tn < hi):
            tn = 0.5 * (lo + hi)
        t = tn
    return t if g == 0.0 else hi


@njit(cache=True, nogil=True, inline="always")
def _first_crossing(cs: np.ndarray, s: float, shift: int, rem: float, K: int, crosses: bool) -> float:
    """First t in (0, rem] where s x(t) <= 0, or -1. ``shift`` deflates a root at t = 0.

    x(t) = t^shift g(t) with s g(0) > 0. Where the series bounds the sign of x'' over the whole
    interval the answer needs no search: s x concave (a swing's arc toward x = 0) is positive on
    an interval [0, t*), so it crosses iff s x(rem) <= 0, once; s x convex and not falling at
    t = 0 (an arc leaving x = 0) never crosses. The crossing is then polished from the root of
    the series' quadratic model. ``crosses``: the caller has proven that (concave, s x(rem) <= 0).
    Otherwise (arcs near the trap's edge |F - K_v V| ~ a, or returning against a force that
    pushes away) a grid of N_SAMPLE points brackets the first sign change of g.
    """
    curv = 2.0 * s * cs[0, 2]
    bound = 0.0 if crosses else _curvature_bound(cs, rem, K)
    if shift < 2 and curv + bound < 0.0:
        if not crosses and s * _horner(cs, 0, rem, shift, K) > 0.0:
            return -1.0
        q0, q1, q2, q3 = s * cs[0, shift], s * cs[0, shift + 1], s * cs[0, shift + 2], s * cs[0, shift + 3]
        t0 = _model_root(q0, q1, q2)
        # one Newton step on the cubic model first: the polish then converges in one or two
        t0 -= (q0 + t0 * (q1 + t0 * (q2 + t0 * q3))) / (q1 + t0 * (2.0 * q2 + 3.0 * t0 * q3))
        return _polish(cs, s, shift, 0.0, rem, t0, rem, K)
    if shift > 0 and curv - bound >= 0.0:
        return -1.0
    lo = 0.0
    for i in range(1, N_SAMPLE + 1):
        ti = rem * i / N_SAMPLE
        if s * _horner(cs, 0, ti, shift, K) <= 0.0:
            return _polish(cs, s, shift, lo, ti, 0.5 * (lo + ti), rem, K)
        lo = ti
    return -1.0


@njit(cache=True, nogil=True)
def _net_exit_time(f: float, V: float, rem: float, pp: np.ndarray, e_rem: float) -> float:
    """Time within ``rem`` at which the net force f - Kv V(t) leaves [-a, a] as V decays
    (V(t) = V e^(-t/tau_p), ``e_rem`` = e^(-rem/tau_p); the net force relaxes monotonically
    toward f), or ``rem`` (0 if it is outside already)."""
    Kv, tau_p, a = pp[P_KV], pp[P_TAU_P], pp[P_KINK_FORCE]
    if abs(f - Kv * V) > a:
        return 0.0
    net_end = f - Kv * V * e_rem
    if abs(net_end) <= a:
        return rem
    s = 1.0 if net_end > 0.0 else -1.0
    u = -tau_p * math.log((f - s * a) / (Kv * V))
    return min(max(u, 0.0), rem)


@njit(cache=True, nogil=True, inline="always")
def _short_swing(x: float, v: float, net: float, s: float, rem: float, pp: np.ndarray) -> bool:
    """Whether ``pp[P_KINK_RULE]`` full swings of the arc through (x, v) on side s fit in ``rem``:
    the period 4 a m w / (a^2 - net^2), w the crossing speed (w^2 = v^2 + 2 (a - s net)|x|/m),
    compared squared, without a division or a root (|net| < a, else never)."""
    m, a = pp[P_M], pp[P_KINK_FORCE]
    d = a * a - net * net
    if not (d > 0.0):
        return False
    c = 4.0 * pp[P_KINK_RULE] * a
    return c * c * m * (m * v * v + 2.0 * (a - s * net) * abs(x)) < (rem * d) * (rem * d)


@njit(cache=True, nogil=True, inline="always")
def _average_swing(x: float, v: float, V: float, f: float, rem: float, pp: np.ndarray, kc: tuple) -> tuple:
    """Swings through (x, v), too short to follow, over ``rem`` or until the net force leaves
    (-a, a): returns x, v, V and the time u advanced. ``kc``: :func:`_step_constants`.

    Averaged map (docs/model.md §3): each half-swing on side s lasts 2 m w/(a - s F) and
    loses a part of the crossing speed w proportional to that time, so w decays as
    exp(-gamma u/3) whatever F is; V relaxes, driven only by the swing's mean position (its
    mean v is 0). The swing's w and phase are read off the arc through (x, v) (its energy and
    the time since it left x = 0); the unit is placed on its arc at the phase of the swing count
    elapsed, integrated with that law: deterministic, and uniform in time over the arcs like the
    exact sequence, whose phase is as sensitive to its inputs. w = 0 is rest, its fixed point.
    Neglected: the damping within one swing and the swing's feedback through Kv V, relative
    O(gamma P) and O(Kv Kc P^2) for a swing period P.
    """
    m, Kc, tau_p, a = pp[P_M], pp[P_KC], pp[P_TAU_P], pp[P_KINK_FORCE]
    h = kc[0]
    u = _net_exit_time(f, V, rem, pp, kc[2] if rem == h else math.exp(-rem / tau_p))
    net = f - pp[P_KV] * V
    e_p, e_w, decay, grow = (kc[2], kc[3], kc[4], kc[5]) if u == h else _decays(u, pp)
    V = V * e_p
    if x == 0.0 and v == 0.0:
        return 0.0, 0.0, V, u
    s = (1.0 if x > 0.0 else -1.0) if x != 0.0 else (1.0 if v > 0.0 else -1.0)
    # with d = a^2 - net^2 the arcs on sides s and -s last 2 m w (a +- s net)/d, the period is
    # 4 a m w/d, and the arc through (x, v) left x = 0 a time m (w - s v)(a + s net)/d ago
    d = a * a - net * net
    w = math.sqrt(v * v + 2.0 * (a - s * net) * abs(x) / m)
    # V = V0 e^(-u/tau_p) + Kc (x(u) - x(0) e^(-u/tau_p)) - (Kc/tau_p) int e^(-(u-t)/tau_p) x(t) dt,
    # with x(t) replaced by its mean over a swing, 2 m net w(t)^2 / (3 d)
    V -= Kc * e_p * (x + 2.0 * m * net * w * w * decay / (3.0 * tau_p * d))
    # swings elapsed: the phase of the arc through (x, v), plus the integral of dt / period(w(t))
    cycles = ((w - s * v) * (a + s * net) * m + grow * d) / (4.0 * a * m * w)
    # beyond 2^52 (or overflowed) the count has no fractional digits left: phase 0
    phase = cycles - math.floor(cycles) if cycles < 4.5e15 else 0.0
    w *= e_w
    net = f - pp[P_KV] * V
    d = a * a - net * net
    if u < rem or not (d > 0.0):
        # the net force has reached +-a: one arc is unbounded, so the unit is left at the
        # crossing, moving into the side it is about to leave toward
        return 0.0, w if net > 0.0 else -w, V, u
    # the arc on side s, then on -s: durations t1, t2 and decelerations k1, k2 (k t = 2 w)
    g = 2.0 * m * w / d
    t1, t2 = g * (a + s * net), g * (a - s * net)
    tau = phase * (t1 + t2)
    if tau < t1:
        x, v = s * tau * w * (1.0 - tau / t1), s * w * (1.0 - 2.0 * tau / t1)
    else:
        tau -= t1
        x, v = -s * tau * w * (1.0 - tau / t2), -s * w * (1.0 - 2.0 * tau / t2)
    return x, v, V + Kc * x, u


@njit(cache=True, nogil=True, inline="always")
def _kink_unit(x: float, v: float, V: float, stuck: bool, f: float, pp: np.ndarray,
               counters: np.ndarray, cs: np.ndarray, kc: tuple, crosses: bool) -> tuple:
    """Advance one unit of the n = 1 potential over one D step with external force f.

    The slow path of :func:`_kink_flow`, for units that may cross x = 0 within the step; ``kc``
    is :func:`_step_constants` of the step; ``crosses``: the unit's arc is proven to cross once
    within the step (:func:`_first_crossing`). Exact piecewise flow: each side of x = 0 is linear
    with constant force f - a s (a = ``pp[P_KINK_FORCE]``); zero crossings are located on the
    flow's Taylor series (:func:`_first_crossing`). Swings shorter than the step never stop
    (docs/model.md §3): once ``pp[P_KINK_RULE]`` (:data:`AVERAGE` by default) full swings fit in
    the time left, the rest of the step is the averaged map :func:`_average_swing`, from
    wherever the unit is on its arc; with :data:`HOLD` they are
    followed until MAX_EVENTS crossings in one step and the unit is then held at x = v = 0
    (``stuck``) while the net force |f - Kv V| <= a, a time-step artifact kept for comparison.
    """
    Kv, a = pp[P_KV], pp[P_KINK_FORCE]
    hold = pp[P_KINK_RULE] == HOLD
    h, K = kc[0], kc[1]
    counters[C_SLOW] += 1
    t = 0.0
    for _ in range(MAX_EVENTS):
        rem = h - t
        if rem <= 0.0:
            return x, v, V, stuck
        if x != 0.0 or v != 0.0:
            s = (1.0 if x > 0.0 else -1.0) if x != 0.0 else (1.0 if v > 0.0 else -1.0)
            shift = 0 if x != 0.0 else 1
            if not hold and _short_swing(x, v, f - Kv * V, s, rem, pp):
                counters[C_AVERAGED] += 1
                x, v, V, u = _average_swing(x, v, V, f, rem, pp, kc)
                t += u
                continue
        else:
            if stuck or abs(f - Kv * V) <= a:
                # at rest: nothing moves until the net force, relaxing with V, reaches +-a;
                # then the unit leaves at once (|net| = a up to round-off must not re-enter)
                x, v, V, u = _average_swing(0.0, 0.0, V, f, rem, pp, kc)
                if u >= rem:
                    return x, v, V, stuck
                t += u
                rem = h - t
                stuck = False
            s = 1.0 if f - Kv * V > 0.0 else -1.0
            shift = 2
        _series(x, v, V, f - a * s, pp, cs, K)
        tc = _first_crossing(cs, s, shift, rem, K, crosses and t == 0.0)
        if tc < 0.0:
            return _horner(cs, 0, rem, 0, K), _horner(cs, 1, rem, 0, K), _horner(cs, 2, rem, 0, K), False
        v, V = _horner(cs, 1, tc, 0, K), _horner(cs, 2, tc, 0, K)
        x = 0.0
        t += tc
        counters[C_CROSSINGS] += 1
    # event budget exhausted (long chatter, HOLD only): the unit is at or next to x = 0
    counters[C_EXHAUSTED] += 1
    if hold and abs(f - Kv * V) <= a:
        return 0.0, 0.0, V, True
    return x, v, V, stuck


@njit(cache=True, nogil=True)
def _kink_flow(x, v, V, stuck, f, w, cf, pp, counters, cs) -> None:
    """D step of the kink potential: one exact affine step where the unit cannot cross x = 0
    within it, events (:func:`_kink_unit`) where it may.

    Two tests prove that it cannot: |x| beyond the distance reachable with the current speed
    and a generous bound on the acceleration; or x on the same side s at both ends of the affine
    step and s x'' negative at both ends by more than its curvature can bridge, which makes s x
    concave over the step (an arc toward x = 0 that turns back, or ends, before reaching it).
    With z = (v, x'', V') the flow has z' = A z, so
    :math:`|x''''| \\le \\rho^2 e^{\\rho h} \\|z(0)\\|_\\infty` with :math:`\\rho = \\|A\\|_\\infty`,
    and x'' departs from its chord over the step by at most :math:`h^2/8` times that.
    """
    N, P = x.shape
    m, gamma, Kv, Kc, a, c = pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KC], pp[P_KINK_FORCE], pp[P_STIFFNESS]
    tau_p, h = pp[P_TAU_P], cf[CF_H]
    # the concavity test's margin, with e^(rho h) <= 1/(1 - rho h) (no test beyond rho h = 1/2)
    rho = max(1.0, (abs(c) + abs(Kv)) / m + gamma, abs(Kc) + 1.0 / tau_p)
    margin = 0.125 * h * h * rho * rho / (1.0 - rho * h) if rho * h < 0.5 else math.inf
    # the step's other constants only once some unit needs them (none do, mostly, at small a):
    # with a few paths per call their exponentials would cost more than the steps themselves
    kc = (h, 0, 0.0, 0.0, 0.0, 0.0)
    averaging = pp[P_KINK_RULE] != HOLD
    for j in range(N):
        for p in range(P):
            x0, v0, V0 = x[j, p], v[j, p], V[j, p]
            s = 1.0 if x0 > 0.0 else -1.0
            Fs = f[j, p] - a * s
            xn = cf[CF_E] * x0 + cf[CF_E + 1] * v0 + cf[CF_E + 2] * V0 + cf[CF_G] * Fs
            vn = cf[CF_E + 3] * x0 + cf[CF_E + 4] * v0 + cf[CF_E + 5] * V0 + cf[CF_G + 1] * Fs
            Vn = cf[CF_E + 6] * x0 + cf[CF_E + 7] * v0 + cf[CF_E + 8] * V0 + cf[CF_G + 2] * Fs
            bound = (abs(Fs) + abs(c * x0) + m * gamma * abs(v0) + Kv * abs(V0)) / m
            acc0 = (Fs - c * x0 - Kv * V0) / m - gamma * v0
            accn = (Fs - c * xn - Kv * Vn) / m - gamma * vn
            z0 = max(abs(v0), abs(acc0), abs(Kc * v0 - V0 / tau_p))
            # both tests and their conditions combined without branches: at large a a unit's
            # outcome changes from step to step, and each mispredicted branch costs more than
            # the arithmetic
            side = (s * xn > 0.0) & (x0 != 0.0) & (w[p] != 0.0) & ~stuck[j, p]
            side_crossed = (s * xn <= 0.0) & (x0 != 0.0) & ~stuck[j, p]
            reach = s * x0 > h * (abs(v0) + 2.0 * h * bound)
            concave = max(s * acc0, s * accn) + margin * z0 < 0.0
            if side & (reach | concave):
                x[j, p], v[j, p], V[j, p] = xn, vn, Vn
                continue
            if w[p] == 0.0:
                continue
            if averaging and x0 != 0.0 and not stuck[j, p] and _short_swing(x0, v0, f[j, p] - Kv * V0, s, h, pp):
                # the trap's short swings, averaged over the whole step (the common slow
                # case at large a, here without the event loop's call)
                if kc[1] == 0:
                    kc = _step_constants(h, pp)
                x1, v1, V1, u = _average_swing(x0, v0, V0, f[j, p], h, pp, kc)
                if u == h:
                    counters[C_SLOW] += 1
                    counters[C_AVERAGED] += 1
                    x[j, p], v[j, p], V[j, p] = x1, v1, V1
                    continue
            if kc[1] == 0:
                kc = _step_constants(h, pp)
            x[j, p], v[j, p], V[j, p], stuck[j, p] = _kink_unit(
                x0, v0, V0, stuck[j, p], f[j, p], pp, counters, cs, kc, side_crossed & concave)
