"""numba kernels: one splitting step of the harvester ring and the path loop of one chunk.

Private module. The Python side (:mod:`montecarlo.scheme`) builds the coefficient arrays:

``cf`` (per step size h)
    ``cf[0:9]`` the 3x3 propagator :math:`E = e^{Ah}` of the linear part of (x, v, V),
    row-major; ``cf[9:12]`` its response :math:`g = \\int_0^h e^{As}b\\,ds` to a unit
    constant force; ``cf[12] = h``; ``cf[13] = e^{-h/\\tau}``;
    ``cf[14] = \\sqrt{(D/\\tau)(1 - e^{-2h/\\tau})}``; ``cf[15] = e^{-h/2\\tau}``;
    ``cf[16:25]``, ``cf[25:28]``: E and g of the substep ``h /`` :data:`MAX_SUBSTEPS` (the
    stiff-wall substeps build ``h/K`` from it by squaring, :func:`_substep_path`).
``pp`` (physical)
    ``m, gamma, Kv, Kc, tau_p, sigma, k, a, n, c, threshold, D/tau, rule, a_kink`` where
    ``c`` is the stiffness kept inside the linear flow (``2k``, plus ``2a`` for the harmonic
    potential), ``threshold`` the escape amplitude, ``rule`` the kink's rule for swings
    shorter than the step (:data:`AVERAGE` or :data:`HOLD`) and ``a_kink`` the strength
    :math:`an` of the kink part :math:`-an\\,\\mathrm{sign}(x)` integrated exactly by the kink
    scheme (0 for the others).
``cf_t`` (harmonic twin, optional)
    ``cf`` of the harmonic ring with on-site stiffness ``kappa_t`` and the same ``k``, run on
    the fine level's noise; its moments are control variates (:mod:`montecarlo.twin`).

Two steps exist. The joint step (``cf[CF_JOINT] = 1``, the harmonic and smooth kick schemes
when tau < 10 dt, :func:`montecarlo.scheme.uses_joint_step`) is ``K(h/2) L(h) K(h/2)``: L the
exact Gaussian transition of the linear part of (x, v, V, xi) including the Ornstein--Uhlenbeck
noise (mean map and noise factor from :func:`montecarlo.scheme.joint_chain`, four normals per
unit), K the kicks of -U'(x); the neighbours' force is a constant at their predicted midpoints,
stiff walls split a path's step into joint substeps with fresh normals
(:func:`_d_step_joint`), and v xi is measured by its conditional expectation. The coarse level
of a Richardson pair gets the exact composition of the fine level's two noise increments, and
the twin its own factor applied to the same normals (its xi increment is the system's).

The frozen-xi step is the Strang splitting ``O(h/2) D(h) O(h/2)`` of the generator into the exact
Ornstein--Uhlenbeck flow ``O`` of xi and the deterministic flow ``D`` of (x, v, V) with xi
frozen; consecutive half steps of ``O`` merge, so the loop runs ``D(h) O(h)`` and measures
after ``D`` (xi-dependent observables get the exact half-step factor ``e^{-h/2tau}``).
Inside ``D`` the neighbours' positions enter as a constant force evaluated at the
predicted midpoint; the on-site force is either part of the exact linear flow (n = 2),
a Strang kick around it (smooth n; where a steep wall makes :math:`h^2U''/m` large the
step of that path is split into substeps, :data:`STIFF_LIMIT`), or, for the kink
(1 <= n <= 1 + KINK_WIDTH of
:mod:`montecarlo.scheme`), its part :math:`-an\\,\\mathrm{sign}(x)` is handled by an exact
piecewise-linear flow with located zero crossings and the remainder by Strang kicks. Toward
rest the kink's swings shrink exponentially in time and never stop (docs/model.md §3); once
they are much shorter than the step the scheme advances them by the averaged map of their
amplitude (:data:`AVERAGE`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._force import _onsite_force
from ._martingale import MG_DIST, mg_measure, n_state

KIND_LINEAR = 0
KIND_KICK = 1
KIND_KINK = 2

#: Stiff walls (smooth scheme, n > 2): a path whose stiffest unit has
#: :math:`h^2 U''(x_e)/m > ` STIFF_LIMIT (x_e the farther of x and x + h v at the start of a
#: step) takes that step as K equal
#: substeps (K the smallest power of 2 that brings it below, at most MAX_SUBSTEPS), the
#: neighbours' force held at its value for the whole step. The kick-drift-kick step is
#: unstable for :math:`h^2 U''/m > 4`; with n = 12, 16 the tails of the law (and the first
#: steps from a Gaussian start) reach it at dt = 0.01 and paths blew up (0.5 %, 2.6 %).
STIFF_LIMIT = 1.0
MAX_SUBSTEPS = 1024

#: Joint step (``cf[CF_JOINT] = 1``): from ``o = CF_JOINT + 1``, ``cf[o:o+16]`` the 4x4
#: propagator of (x, v, V, xi), ``[o+16:o+20]`` its response to a unit constant force on v,
#: ``[o+20:o+36]`` the noise factor L (increment = L z, z four standard normals), ``[o+36]``
#: the noise covariance of (v, xi), ``[o+37]`` the regression coefficient of the xi increment
#: on the x increment (:func:`montecarlo.scheme.step_coefficients`).
#: Block ``i = 1 ..`` log2(MAX_SUBSTEPS) after it holds the same entries (from the propagator
#: on) for the substep ``h / 2^i`` of the stiff walls.
CF_JOINT = 28
JOINT_BLOCK = 38
CF_SIZE = CF_JOINT + 1 + JOINT_BLOCK * (1 + 10)

#: Moments accumulated per level, in this order: the system's (``xdU`` is
#: :math:`x\\,U'(x)`, for the statistical linearization) and, prefixed ``t_``, the harmonic
#: twin's (fine level only; zero without a twin).
MOMENTS = ("V2", "vV", "v2", "x2", "vxi", "stuck", "xdU",
           "t_V2", "t_vV", "t_v2", "t_x2", "t_vxi",
           "t_x4", "t_x2V2", "t_x2v2", "t_absxn", "t_V2v2", "t_vxiV2")
N_MOM = len(MOMENTS)
#: Rows of the ``sums`` accumulator: fine level, coarse level, fine level over the first half
#: of the measured window (the burn-in drift check compares it with the whole), and the
#: coarsest level (twice the coarse step, only with ``third``).
ROWS = 4

#: Kink rule for swings shorter than the step (``pp[12]``). The model's swings never stop
#: (docs/model.md §3). AVERAGE (default) advances them with the averaged map of their crossing
#: speed, w -> w exp(-gamma r/3) (:func:`_average_swing`), once AVG_SWINGS full swings fit in
#: the time left of a step; HOLD follows them until MAX_EVENTS crossings in one step and then
#: holds the unit at rest, a time-step artifact (validation/bench/montecarlo.py compares them).
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
    m, gamma, Kv, Kc, tau_p, c = pp[0], pp[1], pp[2], pp[3], pp[4], pp[9]
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
    Kv, tau_p, a = pp[2], pp[4], pp[13]
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
    m, gamma, Kc, tau_p, a = pp[0], pp[1], pp[3], pp[4], pp[13]
    u = _net_exit_time(f, V, rem, pp)
    net = f - pp[2] * V
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
    net = f - pp[2] * V
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
    each side of x = 0 is linear with constant force f - a s (a = ``pp[13]``); zero crossings
    are located on the flow's Taylor series (bracketing + safeguarded Newton). Swings shorter
    than the step never stop (docs/model.md §3): with the rule ``pp[12]`` = :data:`AVERAGE`,
    once AVG_SWINGS full swings fit in the time left, the rest of the step is the averaged
    map :func:`_average_swing`; with :data:`HOLD` they are followed until MAX_EVENTS
    crossings in one step and the unit is then held at x = v = 0 (``stuck``) while the net
    force |f - Kv V| <= a, a time-step artifact kept for comparison.
    """
    m, Kv, a = pp[0], pp[2], pp[13]
    hold = pp[12] == HOLD
    h = cf[12]
    counters[0] += 1
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
        counters[1] += 1
        net = f - Kv * V
        if not hold and AVG_SWINGS * 4.0 * a * m * abs(v) < (h - t) * (a * a - net * net):
            counters[2] += 1
            x, v, V, u = _average_swing(v, V, f, h - t, pp)
            t += u
    # event budget exhausted (long chatter, HOLD only): the unit is at or next to x = 0
    counters[3] += 1
    if hold and abs(f - Kv * V) <= a:
        return 0.0, 0.0, V, True
    return x, v, V, stuck


@njit(cache=True, nogil=True)
def _external_force(xi, xm, f, pp) -> None:
    """f = sigma xi + k (x_{j-1} + x_{j+1}) with neighbours at their predicted midpoints."""
    N, P = xi.shape
    sigma, k = pp[5], pp[6]
    for j in range(N):
        jm = (j + N - 1) % N
        jp = (j + 1) % N
        for p in range(P):
            f[j, p] = sigma * xi[j, p]
            if N > 1:
                f[j, p] += k * (xm[jm, p] + xm[jp, p])


@njit(cache=True, nogil=True)
def _linear_flow(x, v, V, f, cf) -> None:
    N, P = x.shape
    for j in range(N):
        for p in range(P):
            x0, v0, V0, fp = x[j, p], v[j, p], V[j, p], f[j, p]
            x[j, p] = cf[0] * x0 + cf[1] * v0 + cf[2] * V0 + cf[9] * fp
            v[j, p] = cf[3] * x0 + cf[4] * v0 + cf[5] * V0 + cf[10] * fp
            V[j, p] = cf[6] * x0 + cf[7] * v0 + cf[8] * V0 + cf[11] * fp


@njit(cache=True, nogil=True, inline="always")
def _kick_force(x: float, pp: np.ndarray) -> float:
    """The on-site force left to the kicks: -U'(x), minus the kink part -pp[13] sign(x) that
    the kink flow integrates exactly (pp[13] = 0 for the smooth scheme)."""
    F = _onsite_force(x, pp[7], pp[8])
    if x > 0.0:
        F += pp[13]
    elif x < 0.0:
        F -= pp[13]
    return F


@njit(cache=True, nogil=True)
def _kick(x, v, F, h, pp, update) -> None:
    """Half kick v += (h/2) F/m; with ``update`` first recompute F (:func:`_kick_force`)."""
    N, P = x.shape
    m = pp[0]
    hk = 0.5 * h / m
    for j in range(N):
        for p in range(P):
            if update:
                F[j, p] = _kick_force(x[j, p], pp)
            v[j, p] += hk * F[j, p]


@njit(cache=True, nogil=True)
def _kink_flow(x, v, V, stuck, f, w, cf, pp, counters, cs) -> None:
    """D step of the kink potential: one exact affine step away from x = 0, events near it."""
    N, P = x.shape
    m, gamma, Kv, a, c = pp[0], pp[1], pp[2], pp[13], pp[9]
    h = cf[12]
    for j in range(N):
        for p in range(P):
            if w[p] == 0.0:
                continue
            x0, v0, V0 = x[j, p], v[j, p], V[j, p]
            if not stuck[j, p] and x0 != 0.0:
                s = 1.0 if x0 > 0.0 else -1.0
                Fs = f[j, p] - a * s
                xn = cf[0] * x0 + cf[1] * v0 + cf[2] * V0 + cf[9] * Fs
                # no crossing possible within the step: |x| exceeds the distance reachable
                # with the current speed and a generous bound on the acceleration
                acc = (abs(Fs) + abs(c * x0) + m * gamma * abs(v0) + Kv * abs(V0)) / m
                if s * xn > 0.0 and s * x0 > h * (abs(v0) + 2.0 * h * acc):
                    x[j, p] = xn
                    v[j, p] = cf[3] * x0 + cf[4] * v0 + cf[5] * V0 + cf[10] * Fs
                    V[j, p] = cf[6] * x0 + cf[7] * v0 + cf[8] * V0 + cf[11] * Fs
                    continue
            x[j, p], v[j, p], V[j, p], stuck[j, p] = _kink_unit(
                x0, v0, V0, stuck[j, p], f[j, p], cf, pp, counters, cs)


@njit(cache=True, nogil=True, inline="always")
def _stiff_amplitude(pp: np.ndarray, h: float) -> float:
    """The |x| beyond which a step h sees h^2 U''(x)/m > STIFF_LIMIT (n > 2)."""
    return (STIFF_LIMIT * pp[0] / (h * h * pp[7] * pp[8] * (pp[8] - 1.0))) ** (1.0 / (pp[8] - 2.0))


@njit(cache=True, nogil=True)
def _substeps(x: float, v: float, h: float, xstar: float, pp: np.ndarray) -> int:
    """Substeps a unit at (x, v) needs within a step h: :math:`h^2 U''(x_e)/m` at the farther of
    x and x + h v (U'' = a n (n-1)|x|^(n-2), growing with |x|); 1 below ``xstar``, where it is
    STIFF_LIMIT."""
    xe = max(abs(x), abs(x + h * v))
    if xe <= xstar:
        return 1
    a, n = pp[7], pp[8]
    stiff = h * h * a * n * (n - 1.0) * xe ** (n - 2.0) / pp[0]
    K = 1
    while stiff > STIFF_LIMIT * K * K and K < MAX_SUBSTEPS:
        K *= 2
    return K


@njit(cache=True, nogil=True)
def _substep_path(x, v, V, F, fext, p: int, K: int, cf: np.ndarray, pp: np.ndarray) -> None:
    """Kick-drift-kick of path p as K substeps h/K (neighbours' force fext held)."""
    N = x.shape[0]
    E = cf[16:25].copy()
    g = cf[25:28].copy()
    s = MAX_SUBSTEPS // K
    while s > 1:                      # e^{A 2t} = (e^{At})^2, g_2t = e^{At} g_t + g_t
        E2 = np.empty(9)
        g2 = np.empty(3)
        for r in range(3):
            g2[r] = E[3 * r] * g[0] + E[3 * r + 1] * g[1] + E[3 * r + 2] * g[2] + g[r]
            for c in range(3):
                E2[3 * r + c] = E[3 * r] * E[c] + E[3 * r + 1] * E[3 + c] + E[3 * r + 2] * E[6 + c]
        E, g = E2, g2
        s //= 2
    hk = 0.5 * cf[12] / K / pp[0]
    for j in range(N):
        xx, vv, VV, FF, fp = x[j, p], v[j, p], V[j, p], F[j, p], fext[j, p]
        for _ in range(K):
            vv += hk * FF
            x0, v0, V0 = xx, vv, VV
            xx = E[0] * x0 + E[1] * v0 + E[2] * V0 + g[0] * fp
            vv = E[3] * x0 + E[4] * v0 + E[5] * V0 + g[1] * fp
            VV = E[6] * x0 + E[7] * v0 + E[8] * V0 + g[2] * fp
            FF = _kick_force(xx, pp)
            vv += hk * FF
        x[j, p], v[j, p], V[j, p], F[j, p] = xx, vv, VV, FF


@njit(cache=True, nogil=True)
def _d_step(x, v, V, xi, F, stuck, xm, fext, w, cf, pp, kind, counters, cs) -> None:
    """Deterministic flow D(h) of P rings of N units with xi frozen; arrays (N, P), in place.

    Paths are the inner loops: one path's steps form a serial dependency chain, so only
    independent paths side by side keep the floating-point pipelines busy. ``kind`` is
    tested once per call, outside the loops (inside them it cost a factor ten).
    """
    N, P = x.shape
    h = cf[12]
    # the kink scheme kicks only the smooth remainder of a near-kink potential (n > 1)
    kicks = kind == KIND_KICK or (kind == KIND_KINK and pp[8] != 1.0)
    # stiff walls: paths to redo as substeps, with their state at the start of the step
    n_stiff = 0
    xstar = math.inf
    if kind == KIND_KICK and pp[8] > 2.0:
        xstar = _stiff_amplitude(pp, h)
    if xstar < pp[10]:  # stiffness reachable before the escape amplitude: scan the paths
        for p in range(P):
            for j in range(N):
                if max(abs(x[j, p]), abs(x[j, p] + h * v[j, p])) > xstar:
                    n_stiff += 1
                    break
    if n_stiff > 0:
        sp = np.empty(n_stiff, dtype=np.int64)
        sk = np.empty(n_stiff, dtype=np.int64)
        s0 = np.empty((4, N, n_stiff))
        i = 0
        for p in range(P):
            K = 1
            for j in range(N):
                K = max(K, _substeps(x[j, p], v[j, p], h, xstar, pp))
            if K > 1:
                sp[i], sk[i] = p, K
                for j in range(N):
                    s0[0, j, i], s0[1, j, i], s0[2, j, i], s0[3, j, i] = x[j, p], v[j, p], V[j, p], F[j, p]
                i += 1
    if kicks:
        _kick(x, v, F, h, pp, False)
    if N > 1:
        for j in range(N):
            for p in range(P):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
    _external_force(xi, xm, fext, pp)
    if kind == KIND_KINK:
        _kink_flow(x, v, V, stuck, fext, w, cf, pp, counters, cs)
    else:
        _linear_flow(x, v, V, fext, cf)
    if kicks:
        _kick(x, v, F, h, pp, True)
    for i in range(n_stiff):
        p = sp[i]
        for j in range(N):
            x[j, p], v[j, p], V[j, p], F[j, p] = s0[0, j, i], s0[1, j, i], s0[2, j, i], s0[3, j, i]
        if N > 1:  # neighbours at their midpoints predicted from the start of the step
            for j in range(N):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
            sigma, k = pp[5], pp[6]
            for j in range(N):
                fext[j, p] = sigma * xi[j, p] + k * (xm[(j + N - 1) % N, p] + xm[(j + 1) % N, p])
        _substep_path(x, v, V, F, fext, p, sk[i], cf, pp)


@njit(cache=True, nogil=True)
def _noise(cf, z, eps) -> None:
    """Joint step's noise increments eps = L z per unit; z, eps (4, N, P)."""
    _, N, P = z.shape
    o = CF_JOINT + 21
    for r in range(4):
        l0, l1, l2, l3 = cf[o + 4 * r], cf[o + 4 * r + 1], cf[o + 4 * r + 2], cf[o + 4 * r + 3]
        for j in range(N):
            for p in range(P):
                eps[r, j, p] = l0 * z[0, j, p] + l1 * z[1, j, p] + l2 * z[2, j, p] + l3 * z[3, j, p]


@njit(cache=True, nogil=True)
def _compose(cf, e1, e2, out) -> None:
    """Noise increment of two joint steps ``cf`` in a row, out = P e1 + e2: the coarse level's
    increment from the fine level's two (exact for the linear flow)."""
    _, N, P = e1.shape
    o = CF_JOINT + 1
    for r in range(4):
        p0, p1, p2, p3 = cf[o + 4 * r], cf[o + 4 * r + 1], cf[o + 4 * r + 2], cf[o + 4 * r + 3]
        for j in range(N):
            for p in range(P):
                out[r, j, p] = p0 * e1[0, j, p] + p1 * e1[1, j, p] + p2 * e1[2, j, p] + p3 * e1[3, j, p] \
                    + e2[r, j, p]


@njit(cache=True, nogil=True, inline="always")
def _joint_unit(y0, y1, y2, y3, fp, e0, e1, e2, e3, c: np.ndarray, o: int) -> tuple:
    """One unit through the joint transition whose propagator starts at ``c[o]`` (layout of
    :data:`CF_JOINT`'s entries): returns x, v, V, xi, the conditional mean of v xi given the
    state before (mean v times mean xi plus their noise covariance) and the mean of xi minus
    the regression coefficient times the mean of x."""
    mx = c[o] * y0 + c[o + 1] * y1 + c[o + 2] * y2 + c[o + 3] * y3 + c[o + 16] * fp
    mv = c[o + 4] * y0 + c[o + 5] * y1 + c[o + 6] * y2 + c[o + 7] * y3 + c[o + 17] * fp
    mV = c[o + 8] * y0 + c[o + 9] * y1 + c[o + 10] * y2 + c[o + 11] * y3 + c[o + 18] * fp
    ms = c[o + 15] * y3
    return (mx + e0, mv + e1, mV + e2, ms + e3, mv * ms + c[o + 36], ms - c[o + 37] * mx)


@njit(cache=True, nogil=True)
def _joint_flow(x, v, V, xi, f, eps, cf, rbm, rbx) -> None:
    """Exact Gaussian transition of (x, v, V, xi) under the linear drift, constant force f;
    ``rbm``, ``rbx`` as returned by :func:`_joint_unit`."""
    N, P = x.shape
    o = CF_JOINT + 1
    for j in range(N):
        for p in range(P):
            x[j, p], v[j, p], V[j, p], xi[j, p], rbm[j, p], rbx[j, p] = _joint_unit(
                x[j, p], v[j, p], V[j, p], xi[j, p], f[j, p], eps[0, j, p], eps[1, j, p], eps[2, j, p],
                eps[3, j, p], cf, o)


@njit(cache=True, nogil=True)
def _joint_substeps(x, v, V, xi, F, fext, pvx, p: int, K: int, cf: np.ndarray, pp: np.ndarray,
                    gen) -> None:
    """Path p's step as K joint substeps h/K (kick-flow-kick, neighbours' force fext held),
    with fresh normals: the step's own increment is not split, so this path leaves the common
    noise of the other level and of the twin for this step (their laws stay exact)."""
    N = x.shape[0]
    o = CF_JOINT + 1 + JOINT_BLOCK * int(round(math.log2(K)))
    hk = 0.5 * cf[12] / K / pp[0]
    beta = cf[o + 37]
    e = np.empty(4)
    for j in range(N):
        xx, vv, VV, ss, FF, fp = x[j, p], v[j, p], V[j, p], xi[j, p], F[j, p], fext[j, p]
        rm = rx = 0.0
        for _ in range(K):
            z0, z1, z2, z3 = gen.standard_normal(), gen.standard_normal(), gen.standard_normal(), \
                gen.standard_normal()
            for r in range(4):
                lo = o + 20 + 4 * r
                e[r] = cf[lo] * z0 + cf[lo + 1] * z1 + cf[lo + 2] * z2 + cf[lo + 3] * z3
            vv += hk * FF
            xx, vv, VV, ss, rm, rx = _joint_unit(xx, vv, VV, ss, fp, e[0], e[1], e[2], e[3], cf, o)
            FF = _kick_force(xx, pp)
            vv += hk * FF
        x[j, p], v[j, p], V[j, p], xi[j, p], F[j, p] = xx, vv, VV, ss, FF
        pvx[j, p] = rm + hk * FF * (rx + beta * xx)


@njit(cache=True, nogil=True)
def _d_step_joint(x, v, V, xi, F, xm, fext, eps, cf, pp, kind, rbm, rbx, pvx, w, gen) -> None:
    """One whole step of the joint scheme: kick(h/2), exact linear flow of (x, v, V, xi) with
    noise increment ``eps``, kick(h/2); the neighbours' force enters as a constant at their
    predicted midpoints, and stiff walls split a path's step, as in :func:`_d_step`.

    ``pvx`` receives each unit's estimate of v xi for the measurement: its conditional
    expectation given the state before the flow and the x reached (the same mean as v xi,
    without the variance D/tau of xi itself, which made the plain product useless for
    tau << 1).
    """
    N, P = x.shape
    h = cf[12]
    kicks = kind == KIND_KICK
    n_stiff = 0
    xstar = math.inf
    if kicks and pp[8] > 2.0:
        xstar = _stiff_amplitude(pp, h)
    if xstar < pp[10]:
        for p in range(P):
            for j in range(N):
                if w[p] > 0.0 and max(abs(x[j, p]), abs(x[j, p] + h * v[j, p])) > xstar:
                    n_stiff += 1
                    break
    if n_stiff > 0:
        sp = np.empty(n_stiff, dtype=np.int64)
        sk = np.empty(n_stiff, dtype=np.int64)
        s0 = np.empty((5, N, n_stiff))
        i = 0
        for p in range(P):
            if w[p] == 0.0:
                continue
            K = 1
            for j in range(N):
                K = max(K, _substeps(x[j, p], v[j, p], h, xstar, pp))
            if K > 1:
                sp[i], sk[i] = p, K
                for j in range(N):
                    s0[0, j, i], s0[1, j, i], s0[2, j, i] = x[j, p], v[j, p], V[j, p]
                    s0[3, j, i], s0[4, j, i] = xi[j, p], F[j, p]
                i += 1
        n_stiff = i
    if kicks:
        _kick(x, v, F, h, pp, False)
    k = pp[6]
    for j in range(N):
        for p in range(P):
            fext[j, p] = 0.0
    if N > 1:
        for j in range(N):
            for p in range(P):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
        for j in range(N):
            jm = (j + N - 1) % N
            jp = (j + 1) % N
            for p in range(P):
                fext[j, p] = k * (xm[jm, p] + xm[jp, p])
    _joint_flow(x, v, V, xi, fext, eps, cf, rbm, rbx)
    if kicks:
        _kick(x, v, F, h, pp, True)
        hk = 0.5 * h / pp[0]
        beta = cf[CF_JOINT + 38]
        for j in range(N):
            for p in range(P):
                pvx[j, p] = rbm[j, p] + hk * F[j, p] * (rbx[j, p] + beta * x[j, p])
    else:
        for j in range(N):
            for p in range(P):
                pvx[j, p] = rbm[j, p]
    for i in range(n_stiff):
        p = sp[i]
        for j in range(N):
            x[j, p], v[j, p], V[j, p] = s0[0, j, i], s0[1, j, i], s0[2, j, i]
            xi[j, p], F[j, p] = s0[3, j, i], s0[4, j, i]
        if N > 1:
            for j in range(N):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
            for j in range(N):
                fext[j, p] = k * (xm[(j + N - 1) % N, p] + xm[(j + 1) % N, p])
        _joint_substeps(x, v, V, xi, F, fext, pvx, p, sk[i], cf, pp, gen)


@njit(cache=True, nogil=True)
def _measure(x, v, V, xi, stuck, F, w, cf, pp, kind, acc, pvx) -> float:
    """Add the moments of the live paths (weight w = 1) to acc[0:7]; return unit-steps counted.

    ``F`` holds -U'(x) at the current x for the smooth kind (the last kick computed it).
    After a joint step, v xi is replaced by the estimate ``pvx`` of :func:`_d_step_joint`.
    """
    N, P = x.shape
    half = cf[15]
    a, n = pp[7], pp[8]
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = 0.0
    for j in range(N):
        for p in range(P):
            wp = w[p]
            s0 += wp * V[j, p] * V[j, p]
            s1 += wp * v[j, p] * V[j, p]
            s2 += wp * v[j, p] * v[j, p]
            s3 += wp * x[j, p] * x[j, p]
            s4 += wp * v[j, p] * xi[j, p]
            s5 += wp * stuck[j, p]
    if cf[CF_JOINT] == 1.0:
        s4 = 0.0
        for j in range(N):
            for p in range(P):
                s4 += w[p] * pvx[j, p]
    if kind == KIND_KICK:
        for j in range(N):
            for p in range(P):
                s6 -= w[p] * x[j, p] * F[j, p]
    elif kind == KIND_KINK:
        for j in range(N):
            for p in range(P):
                ax = abs(x[j, p])
                s6 += w[p] * a * (ax if n == 1.0 else n * ax**n)
    else:
        s6 = 2.0 * a * s3
    acc[0] += s0
    acc[1] += s1
    acc[2] += s2
    acc[3] += s3
    acc[4] += s4 * half
    acc[5] += s5
    acc[6] += s6
    live = 0.0
    for p in range(P):
        live += w[p]
    return live * N


@njit(cache=True, nogil=True)
def _measure_twin(x, v, V, xi, w, cf, acc, nn, pvx) -> None:
    """Add the twin's moments (``t_*`` of :data:`MOMENTS`, ``nn`` the system's n) to acc[7:18].

    Second moments and a few fourth moments and :math:`|x|^n`: the twin is Gaussian, so
    each has an exactly known mean (:func:`montecarlo.twin.twin_expectations`), and the
    higher ones follow the nonlinear system's amplitude-dependent response better.
    """
    N, P = x.shape
    half = cf[15]
    s = np.zeros(11)
    for j in range(N):
        for p in range(P):
            wp = w[p]
            xx, vv, VV = x[j, p] * x[j, p], v[j, p] * v[j, p], V[j, p] * V[j, p]
            vxi = v[j, p] * xi[j, p]
            ax = abs(x[j, p])
            s[0] += wp * VV
            s[1] += wp * v[j, p] * V[j, p]
            s[2] += wp * vv
            s[3] += wp * xx
            s[4] += wp * vxi
            s[5] += wp * xx * xx
            s[6] += wp * xx * VV
            s[7] += wp * xx * vv
            s[8] += wp * (ax if nn == 1.0 else ax**nn)
            s[9] += wp * VV * vv
            s[10] += wp * VV * vxi
    if cf[CF_JOINT] == 1.0:
        s[4] = 0.0
        for j in range(N):
            for p in range(P):
                s[4] += w[p] * pvx[j, p]
    s[4] *= half
    s[10] *= half
    for i in range(11):
        acc[7 + i] += s[i]


@njit(cache=True, nogil=True)
def _check_escape(x, v, V, xi, F, stuck, w, thr, t, esc_time) -> None:
    """Retire paths with some |x_j| > thr (or non-finite): record the time, zero their state."""
    N, P = x.shape
    # branch-free scan first: escapes are rare, the scan vectorizes, NaN counts as escaped
    n_bad = 0
    for j in range(N):
        for p in range(P):
            n_bad += 0 if abs(x[j, p]) <= thr else 1
    if n_bad == 0:
        return
    for p in range(P):
        if w[p] == 0.0:
            continue
        out = False
        for j in range(N):
            if not abs(x[j, p]) <= thr:
                out = True
        if out:
            w[p] = 0.0
            esc_time[p] = t
            for j in range(N):
                x[j, p] = 0.0
                v[j, p] = 0.0
                V[j, p] = 0.0
                xi[j, p] = 0.0
                F[j, p] = 0.0
                stuck[j, p] = False


@njit(cache=True, nogil=True)
def _start(gen, chol, sd, x, v, V, xi) -> None:
    """Initial state: rest with stationary xi, or a draw ``chol @ z`` of the 4N-vector
    (x_j, v_j, V_j, xi_j) per path when ``chol`` (lower triangular, 4N x 4N) is given."""
    N, P = x.shape
    if chol.shape[0] == 0:
        for j in range(N):
            for p in range(P):
                xi[j, p] = sd * gen.standard_normal()
        return
    z = np.empty(4 * N)
    for p in range(P):
        for i in range(4 * N):
            z[i] = gen.standard_normal()
        for i in range(4 * N):
            s = 0.0
            for l in range(i + 1):
                s += chol[i, l] * z[l]
            j, c = divmod(i, 4)
            if c == 0:
                x[j, p] = s
            elif c == 1:
                v[j, p] = s
            elif c == 2:
                V[j, p] = s
            else:
                xi[j, p] = s


@njit(cache=True, nogil=True)
def _clamp_start(x: np.ndarray, kind: int, pp: np.ndarray, h: float) -> None:
    """A Gaussian start can land deep in a steep wall, where even MAX_SUBSTEPS substeps of a
    step h are unstable: such draws start at the deepest resolvable |x| (the burn-in forgets it)."""
    if kind == KIND_KICK and pp[8] > 2.0:
        xcap = _stiff_amplitude(pp, h / MAX_SUBSTEPS)
        for j in range(x.shape[0]):
            for p in range(x.shape[1]):
                x[j, p] = min(max(x[j, p], -xcap), xcap)


@njit(cache=True, nogil=True)
def _live(w: np.ndarray) -> int:
    """Paths still running (weight > 0; an escaped path has weight 0)."""
    n = 0
    for p in range(w.size):
        if w[p] > 0.0:
            n += 1
    return n


@njit(cache=True, nogil=True)
def _run_frozen(gen, P: int, N: int, nburn: int, nrun: int, stride: int, cf_f: np.ndarray,
         cf_c: np.ndarray, pp: np.ndarray, kind: int, coupled: bool, cf_t: np.ndarray,
         pp_t: np.ndarray, twin: bool, chol: np.ndarray, sums: np.ndarray, counts: np.ndarray,
         esc_time: np.ndarray, counters: np.ndarray, mg: np.ndarray, cf_cc: np.ndarray,
         third: bool) -> None:
    """Simulate P independent rings of N units with the frozen-xi step and accumulate their
    time averages (:func:`_run_joint` has the same arguments and outputs for the joint step).

    Parameters
    ----------
    gen : numpy.random.Generator
        This chunk's own stream (deterministic for a given seed, whatever the thread count).
    stride : int
        Moments are accumulated every ``stride``-th step of the measured part (samples far
        closer than the correlation time add cost, not information).
    nburn, nrun : int
        Burn-in and measured steps of size ``cf_c[12]`` if ``coupled`` else ``cf_f[12]``.
    coupled : bool
        If True, each coarse step ``cf_c`` is also done as two fine steps ``cf_f`` (h/2) driven
        by the same Brownian increments (exact OU composition): level 0 = fine, 1 = coarse.
        If False, only level 0 is run, with step ``cf_f``.
    cf_cc, third : array, bool
        With ``third`` (and ``coupled``), every two coarse steps are also done as one step
        ``cf_cc`` (2h) on their combined increments: the coarsest level, row 3 of ``sums``
        (measured at its own steps in the measured window).
    cf_t, pp_t, twin : array, array, bool
        With ``twin``, a harmonic ring (coefficients ``cf_t`` at the fine step, physical
        vector ``pp_t``) is advanced on the fine level's xi and measured with it.
    chol : (4N, 4N) or (0, 0) array
        Initial law: every level (and the twin) starts from one draw of ``chol @ z`` per path,
        or from rest with stationary xi when empty.
    sums : (ROWS, N_MOM) array
        Sums over measured unit-steps of the moments :data:`MOMENTS`: fine level, coarse
        level, fine level over the first half of the measured steps (accumulated).
    counts : (ROWS,) array
        Number of unit-steps summed per row (accumulated).
    esc_time : (P,) array
        Time at which path p first had some |x_j| > threshold, or -1.
    counters : (5,) int64 array
        Kink statistics (slow-path unit steps, crossings, averaged-map entries, exhausted
        event budgets) and, in slot 4, the number of ring steps taken (all levels).
    mg : (2, len(basis_names(N))) or (2, 0) array
        Martingale control sums of the fine level (:mod:`montecarlo._martingale`) over the
        measured window and its first half (accumulated); zero columns switch them off.
    """
    third = third and coupled
    thr = pp[10]
    sd = math.sqrt(pp[11])
    xf, vf, Vf = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xif, Ff = np.zeros((N, P)), np.zeros((N, P))
    xc, vc, Vc = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xic, Fc = np.zeros((N, P)), np.zeros((N, P))
    xcc, vcc, Vcc = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xicc, Fcc = np.zeros((N, P)), np.zeros((N, P))
    scc = np.zeros((N, P), dtype=np.bool_)
    xt, vt, Vt, Ft = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    sf = np.zeros((N, P), dtype=np.bool_)
    sc = np.zeros((N, P), dtype=np.bool_)
    st = np.zeros((N, P), dtype=np.bool_)
    xm = np.zeros((N, P))
    z1 = np.zeros((N, P))
    z2 = np.zeros((N, P))
    w = np.ones(P)
    cs = np.zeros((3, N_TAYLOR + 1))
    fext = np.zeros((N, P))
    esc_time[:] = -1.0
    use_mg = mg.shape[1] > 0
    phi = np.zeros((n_state(N) if use_mg else 0, N, P))
    n_bd = mg.shape[1] - n_state(N) - min(N // 2, MG_DIST) - 1 if use_mg else 0
    g_bd, gprev_bd = np.zeros(max(n_bd, 0)), np.zeros(max(n_bd, 0))
    xi0 = np.zeros((N, P))
    mg_started = False
    n_upd = 0  # xi updates of the fine level since the last martingale point
    _start(gen, chol, sd, xf, vf, Vf, xif)
    _clamp_start(xf, kind, pp, cf_c[12] if coupled else cf_f[12])
    for j in range(N):
        for p in range(P):
            xc[j, p], vc[j, p], Vc[j, p], xic[j, p] = xf[j, p], vf[j, p], Vf[j, p], xif[j, p]
            xcc[j, p], vcc[j, p], Vcc[j, p], xicc[j, p] = xf[j, p], vf[j, p], Vf[j, p], xif[j, p]
            xt[j, p], vt[j, p], Vt[j, p] = xf[j, p], vf[j, p], Vf[j, p]
            if kind != KIND_LINEAR:
                Ff[j, p] = _kick_force(xf[j, p], pp)
                Fc[j, p] = Ff[j, p]
                Fcc[j, p] = Ff[j, p]
    h = cf_c[12] if coupled else cf_f[12]
    # the two fine half-step normals combine into the coarse normal exactly
    w1 = cf_f[13] * cf_f[14] / cf_c[14]
    w2 = cf_f[14] / cf_c[14]
    # and two coarse normals into the coarsest one
    u1 = cf_c[13] * cf_c[14] / cf_cc[14]
    u2 = cf_c[14] / cf_cc[14]
    zc = np.zeros((N, P))
    cc_stride = max(1, stride // 2)
    half = nburn + nrun // 2
    for step in range(nburn + nrun):
        live = _live(w)
        if live == 0:
            break
        meas = step >= nburn and (step - nburn) % stride == 0
        first = step < half
        t_end = (step + 1) * h
        if coupled:
            counters[4] += 3 * live
            for j in range(N):
                for p in range(P):
                    z1[j, p] = gen.standard_normal()
                    z2[j, p] = gen.standard_normal()
        else:
            counters[4] += live
            for j in range(N):
                for p in range(P):
                    z1[j, p] = gen.standard_normal()
        for sub in range(2 if coupled else 1):
            _d_step(xf, vf, Vf, xif, Ff, sf, xm, fext, w, cf_f, pp, kind, counters, cs)
            if twin:
                _d_step(xt, vt, Vt, xif, Ft, st, xm, fext, w, cf_t, pp_t, KIND_LINEAR, counters, cs)
            if coupled and sub == 1:
                _d_step(xc, vc, Vc, xic, Fc, sc, xm, fext, w, cf_c, pp, kind, counters, cs)
                _check_escape(xc, vc, Vc, xic, Fc, sc, w, thr, t_end, esc_time)
            _check_escape(xf, vf, Vf, xif, Ff, sf, w, thr, t_end - (0.5 * h if coupled and sub == 0 else 0.0),
                          esc_time)
            if meas:
                n0 = _measure(xf, vf, Vf, xif, sf, Ff, w, cf_f, pp, kind, sums[0], xm)
                counts[0] += n0
                if use_mg and sub == 0:
                    dec = cf_f[13] ** n_upd
                    mg_measure(xf, vf, Vf, xif, w, pp[7], pp[8], phi, xi0, mg, first, mg_started, dec,
                               pp[11] * (1.0 - dec * dec), g_bd, gprev_bd)
                    mg_started = True
                    n_upd = 0
                if twin:
                    _measure_twin(xt, vt, Vt, xif, w, cf_f, sums[0], pp[8], xm)
                if first:
                    counts[2] += _measure(xf, vf, Vf, xif, sf, Ff, w, cf_f, pp, kind, sums[2], xm)
                    if twin:
                        _measure_twin(xt, vt, Vt, xif, w, cf_f, sums[2], pp[8], xm)
                if coupled and sub == 1:
                    counts[1] += _measure(xc, vc, Vc, xic, sc, Fc, w, cf_c, pp, kind, sums[1], xm)
            zz = z1 if sub == 0 else z2
            for j in range(N):
                for p in range(P):
                    xif[j, p] = cf_f[13] * xif[j, p] + cf_f[14] * zz[j, p]
            n_upd += 1
        if coupled:
            for j in range(N):
                for p in range(P):
                    xic[j, p] = cf_c[13] * xic[j, p] + cf_c[14] * (w1 * z1[j, p] + w2 * z2[j, p])
        if third and step % 2 == 1:
            counters[4] += live
            _d_step(xcc, vcc, Vcc, xicc, Fcc, scc, xm, fext, w, cf_cc, pp, kind, counters, cs)
            _check_escape(xcc, vcc, Vcc, xicc, Fcc, scc, w, thr, t_end, esc_time)
            if step >= nburn and ((step - nburn) // 2) % cc_stride == 0:
                counts[3] += _measure(xcc, vcc, Vcc, xicc, scc, Fcc, w, cf_cc, pp, kind, sums[3], xm)
            for j in range(N):
                for p in range(P):
                    xicc[j, p] = cf_cc[13] * xicc[j, p] + cf_cc[14] * (
                        u1 * zc[j, p] + u2 * (w1 * z1[j, p] + w2 * z2[j, p]))
        elif third:
            for j in range(N):
                for p in range(P):
                    zc[j, p] = w1 * z1[j, p] + w2 * z2[j, p]


@njit(cache=True, nogil=True)
def _run_joint(gen, P: int, N: int, nburn: int, nrun: int, stride: int, cf_f: np.ndarray,
               cf_c: np.ndarray, pp: np.ndarray, kind: int, coupled: bool, cf_t: np.ndarray,
               pp_t: np.ndarray, twin: bool, chol: np.ndarray, sums: np.ndarray, counts: np.ndarray,
               esc_time: np.ndarray, counters: np.ndarray, mg: np.ndarray, cf_cc: np.ndarray,
               third: bool) -> None:
    """:func:`_run_frozen` (same arguments and outputs) with the joint step.

    Four normals per unit and fine step; the coarse level takes the exact composition of the
    fine level's two increments (:func:`_compose`), the twin its own noise factor applied to the
    same normals, with its own xi (the same process as the system's: the factors share the xi
    row); the coarsest level the composition of two coarse increments.
    """
    third = third and coupled
    thr = pp[10]
    sd = math.sqrt(pp[11])
    xf, vf, Vf = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xif, Ff = np.zeros((N, P)), np.zeros((N, P))
    xc, vc, Vc = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xic, Fc = np.zeros((N, P)), np.zeros((N, P))
    xcc, vcc, Vcc = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xicc, Fcc = np.zeros((N, P)), np.zeros((N, P))
    scc = np.zeros((N, P), dtype=np.bool_)
    xt, vt, Vt, Ft = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xit = np.zeros((N, P))
    sf = np.zeros((N, P), dtype=np.bool_)
    sc = np.zeros((N, P), dtype=np.bool_)
    xm = np.zeros((N, P))
    z1, z2 = np.zeros((4, N, P)), np.zeros((4, N, P))
    eps1, eps2 = np.zeros((4, N, P)), np.zeros((4, N, P))
    epsc, epst = np.zeros((4, N, P)), np.zeros((4, N, P))
    epsc0, epscc = np.zeros((4, N, P)), np.zeros((4, N, P))
    pvx_cc = np.zeros((N, P))
    cc_stride = max(1, stride // 2)
    rbm, rbx = np.zeros((N, P)), np.zeros((N, P))
    pvx_f, pvx_c, pvx_t = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    w = np.ones(P)
    fext = np.zeros((N, P))
    esc_time[:] = -1.0
    use_mg = mg.shape[1] > 0
    phi = np.zeros((n_state(N) if use_mg else 0, N, P))
    n_bd = mg.shape[1] - n_state(N) - min(N // 2, MG_DIST) - 1 if use_mg else 0
    g_bd, gprev_bd = np.zeros(max(n_bd, 0)), np.zeros(max(n_bd, 0))
    xi0 = np.zeros((N, P))
    mg_started = False
    n_upd = 0  # xi updates of the fine level since the last martingale point
    _start(gen, chol, sd, xf, vf, Vf, xif)
    _clamp_start(xf, kind, pp, cf_c[12] if coupled else cf_f[12])
    for j in range(N):
        for p in range(P):
            xc[j, p], vc[j, p], Vc[j, p], xic[j, p] = xf[j, p], vf[j, p], Vf[j, p], xif[j, p]
            xcc[j, p], vcc[j, p], Vcc[j, p], xicc[j, p] = xf[j, p], vf[j, p], Vf[j, p], xif[j, p]
            xt[j, p], vt[j, p], Vt[j, p], xit[j, p] = xf[j, p], vf[j, p], Vf[j, p], xif[j, p]
            if kind != KIND_LINEAR:
                Ff[j, p] = _kick_force(xf[j, p], pp)
                Fc[j, p] = Ff[j, p]
                Fcc[j, p] = Ff[j, p]
    h = cf_c[12] if coupled else cf_f[12]
    half = nburn + nrun // 2
    for step in range(nburn + nrun):
        live = _live(w)
        if live == 0:
            break
        meas = step >= nburn and (step - nburn) % stride == 0
        first = step < half
        t_end = (step + 1) * h
        counters[4] += (3 if coupled else 1) * live
        for j in range(N):
            for p in range(P):
                for r in range(4):
                    z1[r, j, p] = gen.standard_normal()
                if coupled:
                    for r in range(4):
                        z2[r, j, p] = gen.standard_normal()
        for sub in range(2 if coupled else 1):
            zz = z1 if sub == 0 else z2
            ee = eps1 if sub == 0 else eps2
            _noise(cf_f, zz, ee)
            n_upd += 1
            _d_step_joint(xf, vf, Vf, xif, Ff, xm, fext, ee, cf_f, pp, kind, rbm, rbx, pvx_f, w, gen)
            if twin:
                _noise(cf_t, zz, epst)
                _d_step_joint(xt, vt, Vt, xit, Ft, xm, fext, epst, cf_t, pp_t, KIND_LINEAR, rbm, rbx, pvx_t,
                              w, gen)
            if coupled and sub == 1:
                _compose(cf_f, eps1, eps2, epsc)
                _d_step_joint(xc, vc, Vc, xic, Fc, xm, fext, epsc, cf_c, pp, kind, rbm, rbx, pvx_c, w, gen)
                _check_escape(xc, vc, Vc, xic, Fc, sc, w, thr, t_end, esc_time)
            _check_escape(xf, vf, Vf, xif, Ff, sf, w, thr, t_end - (0.5 * h if coupled and sub == 0 else 0.0),
                          esc_time)
            if meas:
                counts[0] += _measure(xf, vf, Vf, xif, sf, Ff, w, cf_f, pp, kind, sums[0], pvx_f)
                if use_mg and sub == 0:
                    dec = cf_f[13] ** n_upd
                    mg_measure(xf, vf, Vf, xif, w, pp[7], pp[8], phi, xi0, mg, first, mg_started, dec,
                               pp[11] * (1.0 - dec * dec), g_bd, gprev_bd)
                    mg_started = True
                    n_upd = 0
                if twin:
                    _measure_twin(xt, vt, Vt, xit, w, cf_t, sums[0], pp[8], pvx_t)
                if first:
                    counts[2] += _measure(xf, vf, Vf, xif, sf, Ff, w, cf_f, pp, kind, sums[2], pvx_f)
                    if twin:
                        _measure_twin(xt, vt, Vt, xit, w, cf_t, sums[2], pp[8], pvx_t)
                if coupled and sub == 1:
                    counts[1] += _measure(xc, vc, Vc, xic, sc, Fc, w, cf_c, pp, kind, sums[1], pvx_c)
        if third and step % 2 == 1:
            counters[4] += live
            _compose(cf_c, epsc0, epsc, epscc)
            _d_step_joint(xcc, vcc, Vcc, xicc, Fcc, xm, fext, epscc, cf_cc, pp, kind, rbm, rbx, pvx_cc, w,
                          gen)
            _check_escape(xcc, vcc, Vcc, xicc, Fcc, scc, w, thr, t_end, esc_time)
            if step >= nburn and ((step - nburn) // 2) % cc_stride == 0:
                counts[3] += _measure(xcc, vcc, Vcc, xicc, scc, Fcc, w, cf_cc, pp, kind, sums[3], pvx_cc)
        elif third:
            epsc0[:] = epsc


def run_chunk(gen, P: int, N: int, nburn: int, nrun: int, stride: int, cf_f: np.ndarray,
              cf_c: np.ndarray, pp: np.ndarray, kind: int, coupled: bool, cf_t: np.ndarray,
              pp_t: np.ndarray, twin: bool, chol: np.ndarray, sums: np.ndarray,
              counts: np.ndarray, esc_time: np.ndarray, counters: np.ndarray, mg: np.ndarray,
              cf_cc: np.ndarray, third: bool) -> None:
    """Run :func:`_run_frozen` or :func:`_run_joint` (arguments as there; ``cf_f`` says which)
    on a scratch block sized for this chunk."""
    run = _run_joint if cf_f[CF_JOINT] == 1.0 else _run_frozen
    run(gen, P, N, nburn, nrun, stride, cf_f, cf_c, pp, kind, coupled, cf_t, pp_t, twin, chol,
        sums, counts, esc_time, counters, mg, cf_cc, third)
