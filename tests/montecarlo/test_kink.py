"""The kink scheme (n = 1): exact swings and their crossings, the averaged map, no unit held at
rest, the step's tests that a unit cannot cross, bias order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError
from montecarlo import estimate, simulate
from montecarlo._kink import (AVERAGE, HOLD, N_TAYLOR, _average_swing, _curvature_bound, _degree, _first_crossing,
                              _horner, _kink_flow, _kink_unit, _series, _step_constants)
from montecarlo.coefficients import KINK_RULES, physical_vector, step_coefficients
from montecarlo.layout import C_AVERAGED, C_CROSSINGS, C_SLOW, N_COUNTERS


def _unit(a: float, dt: float, rule: str):
    h = Harvester.build(a=a, n=1)
    return step_coefficients(h, dt), physical_vector(h, 100.0, rule)


def _speed(x: float, v: float, V: float, f: float, a: float) -> float:
    """Crossing speed of the arc through (x, v): its speed at x = 0 (m = Kv = 1)."""
    net = f - V
    return math.sqrt(v * v + 2.0 * (a - math.copysign(1.0, x) * net) * abs(x))


def _follow(x, v, V, f, a, dt, steps, rule="hold"):
    """Exact swing sequence of one unit under a constant external force f."""
    _, pp = _unit(a, dt, rule)
    cs, cnt = np.zeros((3, N_TAYLOR + 1)), np.zeros(N_COUNTERS, dtype=np.int64)
    kc = _step_constants(dt, pp)
    stuck = False
    for _ in range(steps):
        x, v, V, stuck = _kink_unit(x, v, V, stuck, f, pp, cnt, cs, kc, False)
    return x, v, V, stuck, cnt


def test_swings_decay_exponentially_in_time() -> None:
    # docs/model.md §3: dw/dt = -gamma w / 3 whatever F; followed crossing by crossing (the
    # rule "hold" follows up to 64 crossings per step, far from that budget here). A root
    # finder that returned a bracket end instead of its converged root used to stall the
    # decay near w ~ dt/4 (energy gained at one crossing in a few hundred).
    a, f, w0 = 2.0, 0.5, 0.03
    for T in (3.0, 12.0):
        x, v, V, stuck, cnt = _follow(0.0, w0, 0.0, f, a, 0.01, int(round(T / 0.01)))
        w = _speed(x, v, V, f, a)
        assert not stuck and cnt[3] == 0
        assert w == pytest.approx(w0 * math.exp(-T / 3.0), rel=0.03), T


def test_averaged_map_matches_the_exact_swing_sequence() -> None:
    a, f, V0, w0, r = 2.0, 0.5, 0.02, 0.01, 1.0
    _, pp = _unit(a, 0.01, "average")
    kc = _step_constants(0.01, pp)
    x, v, V, u = _average_swing(0.0, w0, V0, f, r, pp, kc)
    assert u == r
    xe, ve, Ve, _, _ = _follow(0.0, w0, V0, f, a, 1e-3, int(round(r / 1e-3)))
    assert _speed(x, v, V, f, a) == pytest.approx(_speed(xe, ve, Ve, f, a), rel=5e-3)
    # V up to Kc x, whose part at the end depends on the phase (pseudo-random in the map)
    assert V - x == pytest.approx(Ve - xe, abs=5e-7)
    # amplitude law alone, and the time at which the relaxing V lets the net force leave (-a, a)
    assert _speed(x, v, V, f, a) == pytest.approx(w0 * math.exp(-r / 3.0), rel=5e-3)
    f, V0 = 2.1, 0.3  # net force 1.8 at first, relaxing toward 2.1 > a
    _, _, V, u = _average_swing(0.0, 1e-3, V0, f, 3.0, pp, kc)
    assert u == pytest.approx(-2.0 * math.log((f - a) / V0), rel=1e-12)
    assert f - V == pytest.approx(a, rel=1e-6)


def test_averaged_rest_is_rest_until_the_net_force_leaves() -> None:
    _, pp = _unit(2.0, 0.01, "average")
    x, v, V, u = _average_swing(0.0, 0.0, 0.1, 0.5, 0.5, pp, _step_constants(0.01, pp))
    assert (x, v, u) == (0.0, 0.0, 0.5) and V == pytest.approx(0.1 * math.exp(-0.25))


def _dense_crossing(cs: np.ndarray, s: float, shift: int, rem: float, K: int) -> float | None:
    """First sign change of s x(t) / t^shift on a grid of 20001 points of (0, rem], refined by
    bisection on the polynomial; -1 for none; None where the arc grazes x = 0 (undecidable)."""
    coef = cs[0, shift:K + 1]
    g = lambda t: s * np.polynomial.polynomial.polyval(t, coef)
    t = np.linspace(0.0, rem, 20001)[1:]
    y = g(t)
    scale = np.abs(coef).max()
    hit = np.flatnonzero(y <= 0.0)
    before = y[:hit[0]] if hit.size else y
    if before.size and before.min() < 1e-9 * scale:
        return None
    if not hit.size:
        return -1.0
    lo, hi = (t[hit[0] - 1] if hit[0] else 0.0), t[hit[0]]
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if g(mid) > 0.0 else (lo, mid)
    return hi


def test_first_crossing_is_the_first_sign_change(rng) -> None:
    # arcs near x = 0 in the trap and outside it, from x != 0 and from x = 0 (shift 1), against a
    # dense scan: the concave/convex shortcuts and the grid fallback find the same first root
    a = 2.0
    _, pp = _unit(a, 0.01, "average")
    cs = np.zeros((3, N_TAYLOR + 1))
    checked = {0: 0, 1: 0}
    for _ in range(400):
        rem = float(rng.choice([0.01, 0.04]))
        K = _step_constants(rem, pp)[1]
        shift = int(rng.integers(0, 2))
        x = 0.0 if shift else float(rng.choice([-1, 1]) * 10 ** rng.uniform(-7, -2))
        v = float(rng.choice([-1, 1]) * 10 ** rng.uniform(-5, -0.5))
        s = math.copysign(1.0, x) if shift == 0 else math.copysign(1.0, v)
        _series(x, v, rng.uniform(-0.3, 0.3), rng.uniform(-3.5, 3.5) - a * s, pp, cs, K)
        ref = _dense_crossing(cs, s, shift, rem, K)
        if ref is None:
            continue
        tc = _first_crossing(cs, s, shift, rem, K, False)
        if ref < 0.0:
            assert tc == -1.0
        else:
            assert tc == pytest.approx(ref, rel=1e-9, abs=1e-13 * rem)
            checked[shift] += 1
            if shift == 0 and 2.0 * s * cs[0, 2] + _curvature_bound(cs, rem, K) < 0.0:
                # the caller's proof that the arc crosses once skips the check, same root
                assert _first_crossing(cs, s, shift, rem, K, True) == tc
    assert min(checked.values()) > 50, checked


def test_series_degree_follows_the_step(rng) -> None:
    _, pp = _unit(2.0, 0.01, "average")
    degrees = []
    for h in (0.005, 0.01, 0.04, 0.16):
        K = _step_constants(h, pp)[1]
        degrees.append(K)
        full, cut = np.zeros((3, N_TAYLOR + 1)), np.zeros((3, N_TAYLOR + 1))
        for _ in range(20):
            y = rng.normal(size=3)
            F = rng.normal()
            _series(*y, F, pp, full, N_TAYLOR)
            _series(*y, F, pp, cut, K)
            for row in range(3):
                assert _horner(cut, row, h, 0, K) == pytest.approx(_horner(full, row, h, 0, N_TAYLOR),
                                                                   rel=1e-15, abs=1e-15 * np.abs(y).max())
    assert degrees == sorted(degrees) and degrees[0] < N_TAYLOR
    assert _degree(10.0, 2.0) == N_TAYLOR  # beyond its range the series keeps every term


def test_affine_step_only_where_no_crossing_is_possible(rng) -> None:
    # units near x = 0 with every kind of motion: wherever the step takes its affine path (the
    # slow-path counter does not move), the flow on that side stays on that side over the step
    a, h = 2.0, 0.01
    cf, pp = _unit(a, h, "average")
    cs, cnt = np.zeros((3, N_TAYLOR + 1)), np.zeros(N_COUNTERS, dtype=np.int64)
    K = _step_constants(h, pp)[1]
    arrays = [np.zeros((1, 1)) for _ in range(4)]
    fast = 0
    for _ in range(3000):
        x0 = float(rng.choice([-1, 1]) * 10 ** rng.uniform(-8, -1))
        v0, V0, f = float(rng.normal() * 10 ** rng.uniform(-4, 0)), rng.uniform(-0.3, 0.3), rng.uniform(-4.0, 4.0)
        x, v, V, fa = arrays
        x[0, 0], v[0, 0], V[0, 0], fa[0, 0] = x0, v0, V0, f
        slow = cnt[C_SLOW]
        _kink_flow(x, v, V, np.zeros((1, 1), dtype=np.bool_), fa, np.ones(1), cf, pp, cnt, cs)
        if cnt[C_SLOW] > slow:
            continue
        fast += 1
        s = math.copysign(1.0, x0)
        _series(x0, v0, V0, f - a * s, pp, cs, K)
        t = np.linspace(0.0, h, 2001)
        assert np.all(s * np.polynomial.polynomial.polyval(t, cs[0, :K + 1]) > 0.0)
        assert x[0, 0] == pytest.approx(_horner(cs, 0, h, 0, K), rel=1e-12, abs=1e-18)
    assert fast > 1000


def test_averaged_map_from_the_middle_of_an_arc() -> None:
    # the swing read off a point of its arc (energy and time since the crossing), averaged,
    # against the exact swing sequence from that point
    a, f, V0, w0, r = 2.0, 0.5, 0.02, 0.01, 1.0
    x1, v1, V1, _, _ = _follow(0.0, w0, V0, f, a, 1e-4, 3)  # a third of the way along the first arc
    assert x1 > 0.0 and v1 > 0.0
    _, pp = _unit(a, 0.01, "average")
    x, v, V, u = _average_swing(x1, v1, V1, f, r, pp, _step_constants(0.01, pp))
    xe, ve, Ve, _, _ = _follow(x1, v1, V1, f, a, 1e-3, int(round(r / 1e-3)))
    assert u == r
    assert _speed(x, v, V, f, a) == pytest.approx(_speed(xe, ve, Ve, f, a), rel=5e-3)
    assert V - x == pytest.approx(Ve - xe, abs=5e-7)


def test_swings_shorter_than_the_rule_are_averaged() -> None:
    # the rule is the number of full swings that must fit in the time left (HOLD: never)
    assert KINK_RULES == {"average": AVERAGE, "hold": HOLD} and HOLD == 0.0 < AVERAGE
    a, f, h = 2.0, 0.5, 0.01
    _, pp = _unit(a, h, "average")
    kc = _step_constants(h, pp)
    period_per_w = 4.0 * a / (a * a - f * f)  # m = 1, V = 0
    for factor, averaged in ((0.9, 1), (1.1, 0)):
        w = factor * h / AVERAGE / period_per_w
        cnt = np.zeros(N_COUNTERS, dtype=np.int64)
        x, v, _, _ = _kink_unit(0.0, w, 0.0, False, f, pp, cnt, np.zeros((3, N_TAYLOR + 1)), kc, False)
        assert cnt[C_AVERAGED] == averaged, factor
        if averaged:  # averaged from the start of the step: no crossing located
            assert cnt[C_CROSSINGS] == 0
        elif AVERAGE < 1.0:  # followed: still on its first arc (longer than the step), decelerating
            assert cnt[C_CROSSINGS] == 0 and x > 0.0 and 0.0 < v < w
        else:  # followed: its crossings located (about AVERAGE of them fit in the step)
            assert 0 < cnt[C_CROSSINGS] <= 2 * AVERAGE + 1


def test_default_rule_holds_no_unit_at_rest() -> None:
    h = Harvester.build(a=2.0, n=1)
    kw = dict(dt=0.02, paths=32, replicas=2, t_burn=10.0, t_run=40.0, seed=5)
    avg, hold = simulate(h, **kw), simulate(h, kink_rule="hold", **kw)
    assert np.all(avg.moments(0)["stuck"] == 0.0)
    _, crossings, averaged, exhausted = avg.kink_counters
    assert averaged > 0 and exhausted == 0 and crossings > 0
    # the old rule holds units at rest once 64 crossings fit in a step: ~6e-3 of the time here
    assert hold.moments(0)["stuck"].mean() > 1e-3 and hold.kink_counters[3] > 0
    with pytest.raises(ParameterError, match="kink_rule must be one of"):
        simulate(h, kink_rule="snap", **kw)


def test_kink_bias_is_second_order() -> None:
    # a = 0.5: coupled eta(dt) - eta(dt/2) at dt = 0.08 and 0.04 (measured ratio 4.0, order 2.0)
    h = Harvester.build(a=0.5, n=1)
    diff, err = [], []
    for dt in (0.08, 0.04):
        e = simulate(h, dt=dt, paths=64, replicas=32, t_burn=20.0, t_run=100.0, seed=8, twin=0.37,
                     start="twin", richardson=True)
        est = estimate(e, h, order=1.0)  # order 1: bias = coarse - fine, the raw difference
        diff.append(est.bias["eta"])
        err.append(est.bias_se["eta"])
    assert all(abs(d) > 4 * s for d, s in zip(diff, err)), (diff, err)
    ratio = diff[0] / diff[1]
    assert 2.8 < ratio < 5.7, (ratio, diff, err)
