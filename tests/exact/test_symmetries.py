"""Exact scaling symmetries of the model as oracles for the exact solver.

Derivation (docs/model.md §1 and §5). One unit of a ring obeys

.. math::

    dx = v\\,dt,\\quad m\\,dv = [-U'(x) - m\\gamma v - K_v V + \\sigma\\xi + k\\Delta x]\\,dt,\\quad
    dV = (K_c v - V/\\tau_p)\\,dt,\\quad \\tau\\,d\\xi = -\\xi\\,dt + \\sqrt{2D}\\,dW,

with :math:`U = a|x|^n` (here ``n = 2``). Five changes of variables map one parameter set onto
another:

S1 (noise amplitude) :math:`\\xi = \\lambda\\tilde\\xi`: the OU equation keeps its form with
   :math:`D \\to D/\\lambda^2` and the force :math:`\\sigma\\xi = (\\sigma\\lambda)\\tilde\\xi`. So
   :math:`(\\sigma, D) \\to (\\lambda\\sigma, D/\\lambda^2)` leaves x, v, V unchanged, and
   :math:`P_{in} = \\sigma\\langle v\\xi\\rangle` too: every observable is invariant.
S2 (voltage amplitude) :math:`V = \\mu\\tilde V`: :math:`d\\tilde V = (K_c/\\mu\\, v - \\tilde V/\\tau_p)dt`
   and :math:`K_v V = (K_v\\mu)\\tilde V`. So :math:`(K_c, K_v) \\to (K_c/\\mu, \\mu K_v)` gives
   :math:`V^2 \\to V^2/\\mu^2`, :math:`vV \\to vV/\\mu`, :math:`\\eta \\to \\eta/\\mu^2`; x, v, Pin unchanged.
S3 (mass) dividing the v equation by :math:`\\lambda`: :math:`(m, a, k, K_v, \\sigma) \\to
   \\lambda(m, a, k, K_v, \\sigma)` leaves the process (x, v, V, xi) unchanged; only
   :math:`P_{in} = \\sigma\\langle v\\xi\\rangle \\to \\lambda P_{in}` and :math:`\\eta \\to \\eta/\\lambda`.
S4 (amplitude of everything) :math:`(x, v, V, \\xi) = s(\\tilde x, \\tilde v, \\tilde V, \\tilde\\xi)`:
   the equations keep their form with :math:`a \\to a s^{n-2}` and :math:`D \\to D/s^2`; for
   ``n = 2``, :math:`D \\to s^2 D` multiplies every second moment by :math:`s^2`, eta unchanged.
S5 (time) :math:`t = c\\tilde t`, :math:`\\tilde v = c v`: :math:`(m/c^2)\\,d\\tilde v/d\\tilde t =
   -U' - (m/c^2)(c\\gamma)\\tilde v - K_v V + \\sigma\\xi + k\\Delta x`, :math:`dV/d\\tilde t = K_c\\tilde v
   - V/(\\tau_p/c)`, and with :math:`dW(t) = \\sqrt c\\,d\\tilde W(\\tilde t)`, :math:`(\\tau/c)\\,d\\xi =
   -\\xi\\,d\\tilde t + \\sqrt{2D/c}\\,d\\tilde W`. So :math:`(m, \\gamma, \\tau_p, \\tau, D) \\to (m/c^2,
   c\\gamma, \\tau_p/c, \\tau/c, D/c)` gives :math:`P_{in} \\to cP_{in}`, :math:`v^2 \\to c^2v^2`,
   :math:`vV \\to c\\,vV`, :math:`\\eta \\to \\eta/c`, growth rates :math:`\\times c`; V2, x2 unchanged.

With every factor a power of 2 the new parameters are exact, and every term of the closed
form scales by the same power of 2, so the exact solver (whose arithmetic never overflows)
must return the transformed numbers and errors bit for bit, and the same status. With general
factors they agree to round-off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume
from hypothesis import strategies as st

from fpe_harvester import Harvester, ParameterError, Params, solve
from fpe_harvester.exact import k_di
from fpe_harvester.result import QUANTITIES

EPS = float(np.finfo(float).eps)

#: Each symmetry: (parameter exponents of the factor, observable exponents of the factor).
SYMMETRIES = {
    "S1 noise amplitude": ({"sigma": 1, "D": -2}, {}),
    "S2 voltage amplitude": ({"Kc": -1, "Kv": 1}, {"V2": -2, "vV": -1, "eta": -2, "Vrms": -1}),
    "S3 mass": ({"m": 1, "a": 1, "k": 1, "Kv": 1, "sigma": 1}, {"Pin": 1, "eta": -1}),
    "S4 amplitude": ({"D": 2}, {"V2": 2, "Pin": 2, "v2": 2, "vV": 2, "x2": 2, "d2": 2, "Vrms": 1}),
    "S5 time": ({"m": -2, "gamma": 1, "tau_p": -1, "tau": -1, "D": -1},
                {"Pin": 1, "v2": 2, "vV": 1, "eta": -1, "growth_rate": 1}),
}


def moderate(lo: int = -10, hi: int = 10) -> st.SearchStrategy[float]:
    return st.builds(lambda m, e: math.ldexp(m, e), st.floats(0.5, 1.0, exclude_max=True), st.integers(lo, hi))


@st.composite
def base(draw: st.DrawFn) -> Harvester:
    N = draw(st.integers(1, 6))
    a = draw(moderate())
    params = {f: draw(moderate()) for f in Params().to_dict()}
    k = 0.0 if N == 1 else draw(st.one_of(st.floats(-0.999, 2.0).map(lambda f: f * abs(k_di(N, a))),
                                          st.just(k_di(N, a)), st.just(1.5 * k_di(N, a))))
    return Harvester.build(a=a, N=N, k=k, **params)


def transform(h: Harvester, factors: dict[str, float]) -> tuple[Harvester, dict[str, float]]:
    """Apply the symmetries with the given factors; return the new harvester and observable factors."""
    values = {"a": h.a, "k": h.k, **h.params.to_dict()}
    obs: dict[str, float] = {}
    for name, f in factors.items():
        param_exp, obs_exp = SYMMETRIES[name]
        for p, e in param_exp.items():
            values[p] *= f**e
        for q, e in obs_exp.items():
            obs[q] = obs.get(q, 1.0) * f**e
    a, k = values.pop("a"), values.pop("k")
    return Harvester.build(a=a, N=h.N, k=k, **values), obs


def _solve(h: Harvester):
    try:
        return solve(h, "exact")
    except ParameterError:
        return None


def transform_exactly(h: Harvester, exps: list[int]) -> tuple[Harvester, dict[str, int]] | None:
    """The symmetries with factors 2^e: each parameter rescaled once, exactly (None if not normal)."""
    values = {"a": h.a, "k": h.k, **h.params.to_dict()}
    param_shift: dict[str, int] = {}
    obs_shift: dict[str, int] = {}
    for (param_exp, obs_exp), e in zip(SYMMETRIES.values(), exps):
        for p, power in param_exp.items():
            param_shift[p] = param_shift.get(p, 0) + power * e
        for q, power in obs_exp.items():
            obs_shift[q] = obs_shift.get(q, 0) + power * e
    for p, shift in param_shift.items():
        if values[p]:
            if not -1021 <= math.frexp(values[p])[1] + shift <= 1024:
                return None  # the new value is not a normal double: the map would not be exact
            values[p] = math.ldexp(values[p], shift)
    a, k = values.pop("a"), values.pop("k")
    return Harvester.build(a=a, N=h.N, k=k, **values), obs_shift


def check_powers_of_two(h: Harvester, exps: list[int]) -> None:
    moved = transform_exactly(h, exps)
    assume(moved is not None)
    h2, shift = moved
    r1, r2 = _solve(h), _solve(h2)
    assume(r1 is not None and r2 is not None)
    assert r2.status is r1.status, (r1.message, r2.message)
    # an error below the normal range is inexact, and so are the errors derived from it
    normal_errors = all(not e or abs(e) > 2.3e-308 for r in (r1, r2) for e in (r.value(q)[1] for q in QUANTITIES))
    for q in QUANTITIES:
        for key in (q, q + "_err") if normal_errors else (q,):
            v1, v2 = getattr(r1, key), getattr(r2, key)
            if v1 is None or v2 is None:
                # only a secondary moment that leaves the double range may vanish on one side
                assert v1 is v2 is None or q in ("v2", "vV", "x2", "d2"), key
                continue
            assert v2 == math.ldexp(v1, shift.get(q, 0)), f"{key}: {v2!r} != {v1!r} * 2^{shift.get(q, 0)}"
    g1, g2 = r1.growth_rate, r2.growth_rate
    if g1 is not None and g2 is not None:
        # numpy.roots: absolute accuracy ~eps times the largest root; roots below 1e-8 of it are polished
        assert g2 == pytest.approx(math.ldexp(g1, shift.get("growth_rate", 0)), rel=1e-7, abs=0)


def check_general_factors(h: Harvester, factors: list[float]) -> None:
    h2, obs = transform(h, dict(zip(SYMMETRIES, factors)))
    r1, r2 = _solve(h), _solve(h2)
    assume(r1 is not None and r2 is not None)
    assert r2.status is r1.status, (r1.message, r2.message)
    assume(r1.ok)
    for q in ("eta", "V2", "Pin", "Vrms", "v2", "vV"):
        f = obs.get(q, 1.0)
        (v1, e1), (v2, e2) = r1.value(q), r2.value(q)
        if v1 is None or v2 is None:
            continue
        # the factors' own rounding moves the inputs by a few ulps: allow ~50 ulp on top of the errors
        assert abs(v2 - v1 * f) <= e2 + e1 * f + 50 * EPS * abs(v2), (q, v1 * f, v2, e1 * f, e2)


def test_power_of_two_symmetries_are_exact(fuzz) -> None:
    fuzz(check_powers_of_two, {"ci": 50, "long": 4000}, h=base(),
         exps=st.lists(st.integers(-300, 300), min_size=5, max_size=5))


def test_general_symmetries_hold_to_round_off(fuzz) -> None:
    fuzz(check_general_factors, {"ci": 40, "long": 4000}, h=base(),
         factors=st.lists(moderate(-60, 60), min_size=5, max_size=5))


@pytest.mark.parametrize("name", list(SYMMETRIES))
def test_each_symmetry_on_the_paper_ring(name: str) -> None:
    """N = 3, a = 0.5, k = -0.33 (eta = 0.6774), factor 3: each symmetry on its own."""
    h = Harvester.build(a=0.5, N=3, k=-0.33)
    h2, obs = transform(h, {name: 3.0})
    r1, r2 = solve(h), solve(h2)
    for q in ("eta", "V2", "Pin", "v2", "vV", "x2", "d2"):
        assert getattr(r2, q) == pytest.approx(getattr(r1, q) * obs.get(q, 1.0), rel=1e-13), q
