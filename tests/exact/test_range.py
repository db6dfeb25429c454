"""The exact solver over the whole double range: true answers, true statuses, clear refusals.

Inputs are drawn log-uniformly over many decades, including the extremes of double precision
(subnormal to 1.8e308), and judged against :func:`validation.references.mp_closed_form`, the
closed form evaluated in mpmath (60 digits, unbounded exponent): the true value of every
moment and the true sign of every mode stiffness, whatever the float range.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from fpe_harvester import Harvester, ParameterError, Params, Status, solve
from fpe_harvester.exact import MARGINAL_RTOL, k_di
from fpe_harvester.result import QUANTITIES
from fpe_harvester.wide import LARGEST, SMALLEST_NORMAL
from validation.references import mp_closed_form

EPS = float(np.finfo(float).eps)
FIELDS = tuple(Params().to_dict())


def log_uniform(lo: int, hi: int) -> st.SearchStrategy[float]:
    """Positive floats m 2^e, m in [1/2, 1), e uniform in [lo, hi] (0 excluded)."""
    return st.builds(lambda m, e: math.ldexp(m, e), st.floats(0.5, 1.0, exclude_max=True),
                     st.integers(lo, hi)).filter(lambda x: x > 0.0)


#: A parameter: its default (None), moderate (2^+-20), or anywhere in the positive doubles.
POSITIVE = st.one_of(st.none(), log_uniform(-20, 20), log_uniform(-1074, 1024))


@st.composite
def harmonic(draw: st.DrawFn) -> Harvester:
    """A harmonic harvester: any N, a, k and parameters, with extra weight near k = k_di."""
    N = draw(st.one_of(st.sampled_from([1, 2, 3, 4, 5, 7]), st.integers(1, 64)))
    a = draw(POSITIVE) or 0.5
    params = {f: v for f in FIELDS if (v := draw(POSITIVE)) is not None}
    if draw(st.booleans()) and draw(st.booleans()):
        params["gamma"] = 0.0
    k = 0.0
    if N > 1:
        kd = k_di(N, a)
        k = draw(st.one_of(
            st.builds(lambda f: f * abs(kd), st.floats(-1.5, 3.0)),
            st.builds(lambda j: kd * (1.0 + j * EPS), st.integers(-300, 300)),
            log_uniform(-1074, 1024),
            log_uniform(-1074, 1024).map(lambda x: -x),
        ))
    return Harvester.build(a=a, n=2, N=N, k=k, **params)


def _normal(x: mpmath.mpf) -> bool:
    """True if |x| is a normal double (margin 1e-9 relative, for values right at the edge)."""
    return SMALLEST_NORMAL * (1 + 1e-9) <= abs(x) <= LARGEST * (1 - 1e-9)


def _edge(x: mpmath.mpf) -> bool:
    return abs(abs(x) / SMALLEST_NORMAL - 1) < 1e-9 or abs(abs(x) / LARGEST - 1) < 1e-9


def true_status(h: Harvester) -> set[Status]:
    """Statuses allowed by the exact mode stiffnesses (either side of the marginal band's edge)."""
    ref = mp_closed_form(h, dps=60)
    ratio = [float(kap / sc) for kap, sc in zip(ref["kappa"], ref["scale"])]
    lo, hi = MARGINAL_RTOL - 8 * EPS, MARGINAL_RTOL + 8 * EPS  # float kappa is within ~3 ulp of scale
    if any(r < -hi for r in ratio):
        return {Status.UNSTABLE}
    if any(abs(r) < lo for r in ratio):
        return {Status.MARGINAL}
    allowed = {Status.STABLE}
    if any(abs(r) <= hi for r in ratio):
        allowed |= {Status.MARGINAL, Status.UNSTABLE}
    return allowed


def check_exact(h: Harvester) -> None:
    """One harvester: the right status, the true numbers within the stated errors, or a clear refusal."""
    allowed = true_status(h)
    try:
        r = solve(h, "exact")
    except ParameterError as exc:
        ref = mp_closed_form(h, marginal=MARGINAL_RTOL)
        msg = str(exc)
        assert "\n" not in msg and "double" in msg
        assert any(f"{name} = " in msg for name in ("a", *FIELDS)), msg
        assert not all(_normal(ref[q]) for q in ("V2", "Pin", "eta")), msg  # refused only if out of range
        return
    assert r.status in allowed, (r.status, allowed, r.message)
    if r.status is Status.UNSTABLE:
        assert r.eta is None and r.V2 is None
        assert r.growth_rate is None or r.growth_rate > 0
        return
    ref = mp_closed_form(h, marginal=MARGINAL_RTOL if r.status is Status.MARGINAL else 0.0)
    assert all(_normal(ref[q]) or _edge(ref[q]) for q in ("V2", "Pin", "eta")), "in range but not refused"
    ref["Vrms"] = mpmath.sqrt(ref["V2"])
    for q in QUANTITIES:
        value, err = r.value(q)
        if value is None:
            assert err is None
            assert q in ("v2", "vV", "x2"), q
            assert not _normal(ref[q]) or _edge(ref[q]) or (q == "x2" and r.status is Status.MARGINAL), (q, ref[q])
            continue
        assert math.isfinite(value) and math.isfinite(err) and 0 <= err < abs(value), (q, value, err)
        diff = abs(mpmath.mpf(value) - ref[q])
        assert diff <= err, f"{q}: |{value!r} - {mpmath.nstr(ref[q], 17)}| = {mpmath.nstr(diff, 3)} > err {err:.3g}"
    assert r.growth_rate is None or r.growth_rate < 0 or r.status is Status.MARGINAL


def fuzz(examples: int, prop, **strategies) -> None:
    """Run ``prop`` under hypothesis: fixed examples in CI, random ones in the long profile."""
    settings(max_examples=examples, deadline=None, derandomize=examples <= 200,
             suppress_health_check=list(__import__("hypothesis").HealthCheck))(given(**strategies)(prop))()


PROFILES = [pytest.param(150, id="ci"), pytest.param(5000, id="long", marks=pytest.mark.slow)]


@pytest.mark.parametrize("examples", PROFILES)
def test_exact_over_the_whole_double_range(examples: int) -> None:
    fuzz(examples, check_exact, h=harmonic())
