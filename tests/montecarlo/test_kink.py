"""The kink scheme (n = 1): exact swings, their averaged map, no unit held at rest, bias order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError
from montecarlo import estimate, simulate
from montecarlo._kink import N_TAYLOR, _average_swing, _kink_unit
from montecarlo.coefficients import physical_vector, step_coefficients


def _unit(a: float, dt: float, rule: str):
    h = Harvester.build(a=a, n=1)
    return step_coefficients(h, dt), physical_vector(h, 100.0, rule)


def _speed(x: float, v: float, V: float, f: float, a: float) -> float:
    """Crossing speed of the arc through (x, v): its speed at x = 0 (m = Kv = 1)."""
    net = f - V
    return math.sqrt(v * v + 2.0 * (a - math.copysign(1.0, x) * net) * abs(x))


def _follow(x, v, V, f, a, dt, steps, rule="hold"):
    """Exact swing sequence of one unit under a constant external force f."""
    cf, pp = _unit(a, dt, rule)
    cs, cnt = np.zeros((3, N_TAYLOR + 1)), np.zeros(5, dtype=np.int64)
    stuck = False
    for _ in range(steps):
        x, v, V, stuck = _kink_unit(x, v, V, stuck, f, cf, pp, cnt, cs)
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
    x, v, V, u = _average_swing(w0, V0, f, r, pp)
    assert u == r
    xe, ve, Ve, _, _ = _follow(0.0, w0, V0, f, a, 1e-3, int(round(r / 1e-3)))
    assert _speed(x, v, V, f, a) == pytest.approx(_speed(xe, ve, Ve, f, a), rel=5e-3)
    # V up to Kc x, whose part at the end depends on the phase (pseudo-random in the map)
    assert V - x == pytest.approx(Ve - xe, abs=5e-7)
    # amplitude law alone, and the time at which the relaxing V lets the net force leave (-a, a)
    assert _speed(x, v, V, f, a) == pytest.approx(w0 * math.exp(-r / 3.0), rel=5e-3)
    f, V0 = 2.1, 0.3  # net force 1.8 at first, relaxing toward 2.1 > a
    _, _, V, u = _average_swing(1e-3, V0, f, 3.0, pp)
    assert u == pytest.approx(-2.0 * math.log((f - a) / V0), rel=1e-12)
    assert f - V == pytest.approx(a, rel=1e-6)


def test_averaged_rest_is_rest_until_the_net_force_leaves() -> None:
    _, pp = _unit(2.0, 0.01, "average")
    x, v, V, u = _average_swing(0.0, 0.1, 0.5, 0.5, pp)
    assert (x, v, u) == (0.0, 0.0, 0.5) and V == pytest.approx(0.1 * math.exp(-0.25))


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
