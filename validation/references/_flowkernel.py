"""Kernels of the exact-flow Monte Carlo (:mod:`validation.references.exactflow`).

Written apart from :mod:`montecarlo` on purpose: the report compares the two, so they share no
integrator code. State of a unit: ``y = (x, v, V, xi)``. Between the events of the on-site force
the drift is linear, :math:`dy = (Ay + b f)\\,dt + g\\,dW`, and one step of length ``h`` is

.. math::

    y(h) = e^{Ah} y(0) + \\int_0^h e^{A(h-u)} b\\, f(u)\\,du + \\eta,
    \\qquad \\eta \\sim N(0, Q(h)),

with the noise term ``eta`` drawn exactly. For n = 1 the force is :math:`-a s` on each side ``s``
of the kink, so the step is exact once the zero crossings of x are known; they are located on the
conditional mean of the path given the step's noise draw (:func:`_advance_kink`). For n > 1 the
force over the step is the discrete gradient :math:`-(U(x_1) - U(x_0))/(x_1 - x_0)`, solved
implicitly (:func:`_advance_dg`).

``pp`` holds ``(m, gamma, Kv, Kc, sigma, tau, D, tau_p, a, n)``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: Counters of events per path: zero crossings, collapses into the trap, releases from it,
#: steps whose crossing search hit :data:`MAX_SWITCHES`, discrete-gradient solves that did not
#: converge, steps searched for crossings.
N_COUNTS = 6
C_CROSS, C_COLLAPSE, C_RELEASE, C_OVERFLOW, C_DG, C_SEARCH = range(N_COUNTS)
#: Observables accumulated per sample: V^2, v xi, v^2, v V.
N_OBS = 4
#: Most force switches (zero crossings) within one step; a step that needs more collapses the
#: unit into the trap and is counted (C_OVERFLOW).
MAX_SWITCHES = 64
#: Grid of the crossing search over the rest of a step.
SCAN = 4


@njit(cache=True)
def _poly(c: np.ndarray, s: float) -> float:
    r = 0.0
    for d in range(c.shape[0] - 1, -1, -1):
        r = r * s + c[d]
    return r


@njit(cache=True)
def _dpoly(c: np.ndarray, s: float) -> float:
    r = 0.0
    for d in range(c.shape[0] - 1, 0, -1):
        r = r * s + d * c[d]
    return r


@njit(cache=True)
def _path(t: float, h: float, cx: np.ndarray) -> tuple[float, float]:
    """(x, v) at time t of the step on the conditional-mean path, ``cx`` its polynomial in t/h
    (free flow, noise, and the response to every force switch so far: :func:`_add_switch`)."""
    return _poly(cx, t / h), _dpoly(cx, t / h) / h


@njit(cache=True)
def _add_switch(cx: np.ndarray, pc: np.ndarray, tk: float, df: float, h: float) -> None:
    """Fold the response to a force step ``df`` at ``tk``, :math:`df\\,P_x(t - t_k)`, into ``cx``
    (a polynomial in t/h): the path is only ever evaluated after the latest switch, where every
    switch acts, so one polynomial carries them all."""
    hp = 1.0
    for e in range(pc.shape[0]):
        acc, binom, mt = 0.0, 1.0, 1.0
        for d in range(e, pc.shape[0]):
            acc += pc[d] * binom * mt
            binom = binom * (d + 1) / (d + 1 - e)
            mt *= -tk
        cx[e] += df * hp * acc
        hp *= h


@njit(cache=True)
def _root(lo: float, hi: float, s: float, h: float, cx: np.ndarray, guess: float) -> float:
    """The crossing in (lo, hi]: ``s x(lo) > 0 >= s x(hi)``; Newton kept inside the bracket, done
    when its step or the bracket is below 1e-14 h (Newton closes in from one side, so the bracket
    alone would not shrink)."""
    t = guess if lo < guess < hi else 0.5 * (lo + hi)
    for _ in range(60):
        x, v = _path(t, h, cx)
        if s * x > 0.0:
            lo = t
        else:
            hi = t
        tn = t - x / v if v != 0.0 else -1.0
        if hi - lo <= 1e-14 * h or abs(tn - t) <= 1e-14 * h:
            return min(max(tn, lo), hi)
        t = tn if lo < tn < hi else 0.5 * (lo + hi)
    return hi


@njit(cache=True)
def _accel(t: float, h: float, cx: np.ndarray) -> float:
    """x'' at t on the conditional-mean path (a switch at t acts from t on)."""
    r = 0.0
    for d in range(cx.shape[0] - 1, 1, -1):
        r = r * (t / h) + d * (d - 1) * cx[d]
    return r / (h * h)


@njit(cache=True)
def _turning(lo: float, hi: float, s: float, h: float, cx: np.ndarray) -> float:
    """Where v = 0 in (lo, hi), given ``s v(lo) < 0 < s v(hi)``: Newton on v kept in the bracket."""
    t = 0.5 * (lo + hi)
    for _ in range(60):
        _, v = _path(t, h, cx)
        if s * v < 0.0:
            lo = t
        else:
            hi = t
        acc = _accel(t, h, cx)
        tn = t - v / acc if acc != 0.0 else -1.0
        if hi - lo <= 1e-14 * h or abs(tn - t) <= 1e-14 * h:
            return min(max(tn, lo), hi)
        t = tn if lo < tn < hi else 0.5 * (lo + hi)
    return t


@njit(cache=True)
def _first_crossing(t0: float, s: float, h: float, cx: np.ndarray, nscan: int = SCAN) -> float:
    """First time in (t0, h] where the path leaves side ``s`` (``s x <= 0``), or -1; -2 for a
    swing too small to resolve (the caller collapses it).

    At a crossing (or from rest) the path is at 0 moving into side s: the swing's return is first
    sought where a parabola with the local acceleration returns, beyond its apex. Otherwise SCAN
    points are scanned; between two of them where the path turns back (v changes sign), its
    turning point is found and a crossing there counts too (a dip across and back)."""
    tl = t0
    xl, vl = _path(t0, h, cx)
    if h - t0 <= 0.0:
        return -1.0
    if s * xl <= 0.0 or t0 > 0.0:
        acc = _accel(t0, h, cx)
        if s * acc < 0.0 and s * vl > 0.0:
            tr = t0 - 2.0 * vl / acc
            if tr < h:
                tb = min(t0 + 1.3 * (tr - t0), h)
                xb, vb = _path(tb, h, cx)
                if s * xb <= 0.0:
                    ta = t0 - vl / acc
                    xa, _ = _path(ta, h, cx)
                    if s * xa <= 0.0:
                        return -2.0
                    return _root(ta, tb, s, h, cx, tr)
                tl, xl, vl = tb, xb, vb
        elif s * vl <= 0.0 and s * acc <= 0.0:
            return -2.0  # on the boundary and not moving into side s: nothing to resolve
    dt = (h - tl) / nscan
    if dt <= 0.0:
        return -1.0
    for i in range(1, nscan + 1):
        tr = tl + i * dt if i < nscan else h
        xr, vr = _path(tr, h, cx)
        tp = tl + (i - 1) * dt
        if s * xr <= 0.0:
            lo = tp
            if s * xl <= 0.0:
                # left end on the boundary: start from the apex of the swing
                a = (vr - vl) / (tr - tp)
                ta = tp - vl / a if a * vl < 0.0 else 0.5 * (tp + tr)
                if not tp < ta < tr:
                    ta = 0.5 * (tp + tr)
                xa, _ = _path(ta, h, cx)
                if s * xa <= 0.0:
                    return -2.0
                lo = ta
            return _root(lo, tr, s, h, cx, tr - xr / vr if vr != 0.0 else -1.0)
        if s * xl > 0.0 and s * vl < 0.0 < s * vr:
            # both ends on side s and the path turns between them: across at its turning point?
            tt = _turning(tp, tr, s, h, cx)
            xt, _ = _path(tt, h, cx)
            if s * xt <= 0.0:
                return _root(tp, tt, s, h, cx, -1.0)
        xl, vl = xr, vr
    return -1.0


@njit(cache=True)
def _end_state(y0: np.ndarray, eta: np.ndarray, E: np.ndarray, pvec: np.ndarray, h: float,
               tsw: np.ndarray, dfs: np.ndarray, nsw: int, out: np.ndarray) -> None:
    """y(h) = E y0 + sum_k P(h - t_k) df_k + eta (P(tau) by its series ``pvec``)."""
    for r in range(4):
        acc = eta[r]
        for c in range(4):
            acc += E[r, c] * y0[c]
        out[r] = acc
    for k in range(nsw):
        tau = h - tsw[k]
        pw = tau
        for d in range(pvec.shape[0]):
            for r in range(3):
                out[r] += dfs[k] * pvec[d, r] * pw
            pw *= tau


@njit(cache=True)
def _kink_crossings(y: np.ndarray, st: np.ndarray, eta: np.ndarray, E: np.ndarray, pvec: np.ndarray, h: float,
                    Ex: np.ndarray, Cx: np.ndarray, pc: np.ndarray, wtrap: float, pp: np.ndarray,
                    counts: np.ndarray, tsw: np.ndarray, dfs: np.ndarray, cx: np.ndarray, y1: np.ndarray,
                    powers: np.ndarray, jumps: np.ndarray, nscan: int = SCAN) -> None:
    """A kink step (n = 1) that may cross x = 0: ``y1`` holds its end without a crossing.

    The crossings are located one after the other on the conditional-mean path
    (:func:`_first_crossing`); the force switches from :math:`-as` to :math:`as` at each. A unit
    whose crossing speed falls below ``wtrap`` while the net drive :math:`|\\sigma\\xi - K_v V| < a`
    holds it is set at rest at the origin (``st[1] = 1``; its swings would shrink like
    :math:`e^{-\\gamma t/3}` with ever more crossings): V decays from there, xi runs exactly. That
    jump of v to 0 changes each monomial of ``powers`` by :math:`f(\\text{after}) - f(\\text{before})`,
    added to ``jumps``: with it, the controls keep their mean 0 for the scheme's own dynamics."""
    sigma, Kv, tau_p, a = pp[4], pp[2], pp[7], pp[8]
    s = st[0]
    tsw[0] = 0.0
    dfs[0] = -a * s
    nsw = 1
    for d in range(cx.shape[0]):
        acc = 0.0
        if d < Ex.shape[1]:
            for c in range(4):
                acc += Ex[c, d] * y[c] + Cx[c, d] * eta[c]
        cx[d] = acc
    _add_switch(cx, pc, 0.0, dfs[0], h)
    t = 0.0
    while True:
        tc = _first_crossing(t, s, h, cx, nscan)
        if tc == -1.0:
            break
        frac = max(tc, t) / h
        F = sigma * ((1 - frac) * y[3] + frac * y1[3]) - Kv * ((1 - frac) * y[2] + frac * y1[2])
        vc = 0.0
        if tc > 0.0:
            _, vc = _path(tc, h, cx)
        if tc == -2.0 or nsw == MAX_SWITCHES or (abs(vc) < wtrap and abs(F) < a):
            tc = max(tc, t)
            if nsw == MAX_SWITCHES:
                counts[C_OVERFLOW] += 1
            counts[C_COLLAPSE] += 1
            frac = tc / h
            Vc = (1 - frac) * y[2] + frac * y1[2]
            xic = (1 - frac) * y[3] + frac * y1[3]
            for q in range(jumps.shape[0]):
                if powers[q, 0] == 0 and powers[q, 1] > 0:  # x = 0 at the crossing: only x-free terms move
                    jumps[q] -= vc ** powers[q, 1] * Vc ** powers[q, 2] * xic ** powers[q, 3]
            y[0] = 0.0
            y[1] = 0.0
            y[2] = Vc * math.exp(-(h - tc) / tau_p)
            y[3] = y1[3]
            st[1] = 1.0
            return
        counts[C_CROSS] += 1
        tsw[nsw] = tc
        dfs[nsw] = 2.0 * a * s
        _add_switch(cx, pc, tc, dfs[nsw], h)
        nsw += 1
        s = -s
        t = tc
    _end_state(y, eta, E, pvec, h, tsw, dfs, nsw, y1)
    y[:] = y1
    st[0] = s


@njit(cache=True)
def _dg(x0: float, x1: float, a: float, n: float) -> tuple[float, float]:
    """Discrete gradient (U(x1) - U(x0))/(x1 - x0) of U = a|x|^n and its derivative in x1."""
    d = x1 - x0
    if abs(d) < 1e-9 * (abs(x0) + abs(x1)) or d == 0.0:
        xm = 0.5 * (x0 + x1)
        g = a * n * abs(xm) ** (n - 1.0) * (1.0 if xm > 0 else -1.0 if xm < 0 else 0.0)
        return g, 0.5 * a * n * (n - 1.0) * abs(xm) ** (n - 2.0) if xm != 0.0 else 0.0
    u0, u1 = a * abs(x0) ** n, a * abs(x1) ** n
    g = (u1 - u0) / d
    du1 = a * n * abs(x1) ** (n - 1.0) * (1.0 if x1 > 0 else -1.0 if x1 < 0 else 0.0)
    return g, (du1 - g) / d


@njit(cache=True)
def _dg_force(x0: float, xl: float, c: float, a: float, n: float) -> tuple[float, bool]:
    """The force f over a step for n > 1: f = -DG(x0, xl + c f), minus the discrete gradient between
    the step's ends (exact for a path linear in time; continuous across x = 0). ``xl`` is the end
    without force, ``c`` the x response to a unit force. Newton kept in a bracket (the equation is
    monotone: U is convex); returns (f, converged)."""
    bound = a * n * (max(abs(x0), abs(xl)) + 1.0) ** (n - 1.0) + 1.0
    lo, hi = -bound, bound
    f = -a * n * abs(x0) ** (n - 1.0) * (1.0 if x0 > 0 else -1.0 if x0 < 0 else 0.0)
    for _ in range(60):
        g, dg = _dg(x0, xl + c * f, a, n)
        r = f + g
        if r > 0.0:
            hi = f
        else:
            lo = f
        if abs(r) <= 1e-15 * (abs(f) + abs(g)) + 1e-300 or hi - lo <= 1e-15 * bound:
            return f, True
        fn = f - r / (1.0 + c * dg)
        f = fn if lo < fn < hi else 0.5 * (lo + hi)
    return f, False


@njit(cache=True)
def _generator(y: np.ndarray, side: float, resting: bool, pp: np.ndarray, powers: np.ndarray, tab: np.ndarray,
               out: np.ndarray) -> None:
    """Add :math:`\\mathcal{L}f` at the state ``y`` to ``out`` for each monomial
    :math:`f = x^i v^j V^k \\xi^l` of ``powers``, with the generator of the scheme's own dynamics:

    .. math::

        \\mathcal{L}f = \\dot x f_x + \\dot v f_v + (K_c v - V/\\tau_p) f_V - \\frac{\\xi}{\\tau} f_\\xi
        + \\frac{D}{\\tau^2} f_{\\xi\\xi},\\qquad
        \\dot x = v,\\ \\dot v = (F - m\\gamma v - K_v V + \\sigma\\xi)/m,

    F the on-site force (n = 1: :math:`-a s` on the unit's side s), and :math:`\\dot x = \\dot v = 0`
    for a unit held at rest. Its stationary mean is 0, so its time average is a control variate."""
    m, gamma, Kv, Kc, sigma, tau, D, tau_p, a, n = pp[0], pp[1], pp[2], pp[3], pp[4], pp[5], pp[6], pp[7], pp[8], pp[9]
    x, v, V, xi = y[0], y[1], y[2], y[3]
    for c in range(4):
        tab[c, 0] = 0.0  # x^-1 etc.: the derivative's factor i makes them vanish
        tab[c, 1] = 1.0
        for d in range(2, 6):
            tab[c, d] = tab[c, d - 1] * y[c]
    if resting:
        dx, dv = 0.0, 0.0
    else:
        force = -a * side if n == 1.0 else -a * n * abs(x) ** (n - 1.0) * (1.0 if x > 0 else -1.0 if x < 0 else 0.0)
        dx, dv = v, (force - m * gamma * v - Kv * V + sigma * xi) / m
    dV = Kc * v - V / tau_p
    for q in range(powers.shape[0]):
        i, j, k, l = powers[q, 0], powers[q, 1], powers[q, 2], powers[q, 3]
        px, pv, pV, pxi = tab[0, i + 1], tab[1, j + 1], tab[2, k + 1], tab[3, l + 1]
        r = 0.0
        if i > 0:
            r += i * tab[0, i] * pv * pV * pxi * dx
        if j > 0:
            r += j * px * tab[1, j] * pV * pxi * dv
        if k > 0:
            r += k * px * pv * tab[2, k] * pxi * dV
        if l > 0:
            r -= l * px * pv * pV * tab[3, l + 1] / tau
        if l > 1:
            r += l * (l - 1) * px * pv * pV * tab[3, l - 1] * D / (tau * tau)
        out[q] += r


@njit(cache=True, nogil=True)
def run_paths(first: int, last: int, seeds: np.ndarray, n_burn: int, n_run: int, every: int, Lf: np.ndarray,
              Ef: np.ndarray,
              mult: np.ndarray, E: np.ndarray, Pv: np.ndarray, pvec: np.ndarray, hs: np.ndarray,
              Ex: np.ndarray, Cx: np.ndarray, pc: np.ndarray, wtrap: np.ndarray, pp: np.ndarray,
              kink: bool, edges: np.ndarray, means: np.ndarray, counts: np.ndarray, shells: np.ndarray,
              powers: np.ndarray, cv_every: int, bobs: np.ndarray, bcv: np.ndarray, bjump: np.ndarray) -> None:
    """Run paths ``first`` to ``last - 1`` (of ``seeds.size``) of every variant on one noise per path.

    The fine step's noise ``Lf z`` is drawn once; variant ``j`` steps every ``mult[j]`` fine steps
    with the noise of its own step, :math:`\\eta \\leftarrow E_f\\eta + \\eta_f` summed exactly over
    the fine steps (so the variants' paths are driven by the same Brownian path: their differences
    have small variances). Each path starts at rest at the origin, xi stationary. After ``n_burn``
    fine steps, the state of every variant is sampled every ``every`` fine steps (a multiple of
    every ``mult``) into ``means[path, variant, :]`` (V^2, v xi, v^2, v V averaged) and, for variant
    0 and ``edges`` not empty, the fraction of samples with ``edges[i] < m v^2/2 + a|x| <=
    edges[i + 1]`` into ``shells[path, i]``. With ``powers`` not empty, every variant's observables
    are also averaged over each of ``bobs.shape[2]`` consecutive batches of the samples into
    ``bobs[path, variant, batch, :]``, and the generator applied to each monomial
    ``x^i v^j V^k xi^l`` (a row ``(i, j, k, l)`` of ``powers``) every ``cv_every`` samples into
    ``bcv[path, variant, batch, :]`` (:func:`_generator`: stationary mean 0, the control variates),
    and the monomials' jumps at the trap's collapses (sums) into ``bjump[path, variant, batch, :]``.
    Each path seeds its own generator, so the results do not depend on how the paths are shared
    between threads (the caller runs chunks in threads: the kernel releases the GIL)."""
    nv = mult.size
    m, Kv, sigma, tau_p, a, n = pp[0], pp[2], pp[4], pp[7], pp[8], pp[9]
    nsh = max(edges.size - 1, 0)
    for p in range(first, last):
        np.random.seed(seeds[p])
        y = np.zeros((nv, 4))
        st = np.zeros((nv, 2))
        acc = np.zeros((nv, 4))
        left = mult.copy()
        decay = np.exp(-hs / tau_p)
        eta, y1 = np.zeros(4), np.zeros(4)
        tsw, dfs = np.zeros(MAX_SWITCHES + 1), np.zeros(MAX_SWITCHES + 1)
        cx = np.zeros(max(Ex.shape[2], pc.size))
        sums = np.zeros((nv, N_OBS))
        cnt = np.zeros((nv, N_COUNTS), dtype=np.int64)
        xi0 = math.sqrt(pp[6] / pp[5]) * np.random.standard_normal()
        for j in range(nv):
            y[j, 3] = xi0
            st[j, 0] = 1.0
            st[j, 1] = 1.0 if kink else 0.0
        nsamp = 0
        sample_in = n_burn + every
        ncv, nb = powers.shape[0], bobs.shape[2]
        per_path = n_run // every
        nojump = np.zeros(0)
        bn, bc = np.zeros(nb), np.zeros(nb)
        tab = np.zeros((4, 6))
        for i in range(n_burn + n_run):
            z0, z1 = np.random.standard_normal(), np.random.standard_normal()
            z2, z3 = np.random.standard_normal(), np.random.standard_normal()
            f0 = Lf[0, 0] * z0
            f1 = Lf[1, 0] * z0 + Lf[1, 1] * z1
            f2 = Lf[2, 0] * z0 + Lf[2, 1] * z1 + Lf[2, 2] * z2
            f3 = Lf[3, 0] * z0 + Lf[3, 1] * z1 + Lf[3, 2] * z2 + Lf[3, 3] * z3
            for j in range(nv):
                if mult[j] == 1:
                    eta[0], eta[1], eta[2], eta[3] = f0, f1, f2, f3
                else:
                    for r in range(4):
                        eta[r] = (Ef[r, 0] * acc[j, 0] + Ef[r, 1] * acc[j, 1] + Ef[r, 2] * acc[j, 2]
                                  + Ef[r, 3] * acc[j, 3])
                    acc[j, 0] = eta[0] + f0
                    acc[j, 1] = eta[1] + f1
                    acc[j, 2] = eta[2] + f2
                    acc[j, 3] = eta[3] + f3
                    left[j] -= 1
                    if left[j] > 0:
                        continue
                    left[j] = mult[j]
                    for r in range(4):
                        eta[r] = acc[j, r]
                        acc[j, r] = 0.0
                if kink and st[j, 1] != 0.0:
                    # at rest in the trap: V decays, xi runs; released when the drive exceeds a
                    y[j, 2] *= decay[j]
                    y[j, 3] = E[j, 3, 3] * y[j, 3] + eta[3]
                    F = sigma * y[j, 3] - Kv * y[j, 2]
                    if abs(F) >= a:
                        st[j, 1] = 0.0
                        st[j, 0] = 1.0 if F > 0.0 else -1.0
                        cnt[j, C_RELEASE] += 1
                    continue
                if kink:
                    force = -a * st[j, 0]
                else:
                    xl = eta[0]
                    for c in range(4):
                        xl += E[j, 0, c] * y[j, c]
                    force, ok = _dg_force(y[j, 0], xl, Pv[j, 0], a, n)
                    if not ok:
                        cnt[j, C_DG] += 1
                for r in range(4):
                    y1[r] = eta[r] + Pv[j, r] * force + E[j, r, 0] * y[j, 0] + E[j, r, 1] * y[j, 1] \
                        + E[j, r, 2] * y[j, 2] + E[j, r, 3] * y[j, 3]
                if kink:
                    s = st[j, 0]
                    x0, x1 = s * y[j, 0], s * y1[0]
                    # no crossing possible: the path stays within amax h^2/8 of its chord (amax bounds |x''|)
                    amax = (a + sigma * (max(abs(y[j, 3]), abs(y1[3])) + 0.5) + Kv * max(abs(y[j, 2]), abs(y1[2]))
                            + m * pp[1] * (max(abs(y[j, 1]), abs(y1[1])) + 0.1)) / m
                    if not (x0 > 0.0 and x1 > 0.0 and min(x0, x1) > 0.25 * amax * hs[j] * hs[j]):
                        cnt[j, C_SEARCH] += 1
                        # a collapse counts toward the batch of the next sample (none in the burn-in)
                        bt = min(nsamp * nb // max(per_path, 1), nb - 1) if ncv > 0 else 0
                        _kink_crossings(y[j], st[j], eta, E[j], pvec, hs[j], Ex[j], Cx[j], pc, wtrap[j], pp,
                                        cnt[j], tsw, dfs, cx, y1, powers,
                                        bjump[p, j, bt] if ncv > 0 and i >= n_burn else nojump)
                        continue
                for r in range(4):
                    y[j, r] = y1[r]
            if i + 1 == sample_in:
                sample_in += every
                nsamp += 1
                for j in range(nv):
                    vj, Vj = y[j, 1], y[j, 2]
                    sums[j, 0] += Vj * Vj
                    sums[j, 1] += vj * y[j, 3]
                    sums[j, 2] += vj * vj
                    sums[j, 3] += vj * Vj
                if nsh > 0:
                    en = 0.5 * m * y[0, 1] ** 2 + a * abs(y[0, 0])
                    for b in range(nsh):
                        if edges[b] < en <= edges[b + 1]:
                            shells[p, b] += 1.0
                            break
                if ncv > 0:
                    bt = min((nsamp - 1) * nb // per_path, nb - 1)
                    bn[bt] += 1.0
                    for j in range(nv):
                        vj, Vj = y[j, 1], y[j, 2]
                        bobs[p, j, bt, 0] += Vj * Vj
                        bobs[p, j, bt, 1] += vj * y[j, 3]
                        bobs[p, j, bt, 2] += vj * vj
                        bobs[p, j, bt, 3] += vj * Vj
                    if nsamp % cv_every == 0:
                        bc[bt] += 1.0
                        for j in range(nv):
                            _generator(y[j], st[j, 0], kink and st[j, 1] != 0.0, pp, powers, tab, bcv[p, j, bt])
        for j in range(bobs.shape[1]):
            for bt in range(nb):
                for q in range(N_OBS):
                    bobs[p, j, bt, q] /= max(bn[bt], 1.0)
                for q in range(ncv):
                    bcv[p, j, bt, q] /= max(bc[bt], 1.0)
        for j in range(nv):
            for q in range(N_OBS):
                means[p, j, q] = sums[j, q] / max(nsamp, 1)
            for q in range(N_COUNTS):
                counts[p, j, q] = cnt[j, q]
        for b in range(nsh):
            shells[p, b] /= max(nsamp, 1)
