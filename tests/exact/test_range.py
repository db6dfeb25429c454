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
    # d2 (the bond statistic) has no multiple-precision reference here: it is checked against the
    # Boltzmann bond law in tests/montecarlo/test_coupling.py
    for q in (q for q in QUANTITIES if q != "d2"):
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


def test_exact_over_the_whole_double_range(fuzz) -> None:
    fuzz(check_exact, {"ci": 60, "long": 5000}, h=harmonic())


@pytest.mark.parametrize(("N", "a", "k"), [(3, 0.5, 1e14), (2, 0.5, 1e50), (5, 0.5, 1e300)])
def test_huge_positive_coupling_is_stable_with_the_single_unit_limit(N: int, a: float, k: float) -> None:
    """Every mode but q = 0 is infinitely stiff and silent: eta -> 20/39 (it was "marginal", 0.7407)."""
    r = solve(Harvester.build(a=a, N=N, k=k))
    assert r.status is Status.STABLE and "marginal" not in r.message
    assert r.eta == pytest.approx(20 / 39, rel=1e-12)
    assert r.eta_err < 1e-14
    assert r.V2 == pytest.approx(20 / 143 / N, rel=1e-12)


def test_tiny_a_with_unit_coupling_is_stable_and_keeps_x2() -> None:
    """a = 1e-14, k = 1, N = 3: the q = 0 mode has stiffness 2e-14 exactly, so x2 ~ 5.6e12 (was dropped)."""
    h = Harvester.build(a=1e-14, N=3, k=1.0)
    r = solve(h)
    ref = mp_closed_form(h)
    assert r.status is Status.STABLE
    assert r.x2 == pytest.approx(float(ref["x2"]), rel=1e-12) and 5e12 < r.x2 < 6e12
    assert r.eta == pytest.approx(float(ref["eta"]), rel=1e-14)


@pytest.mark.parametrize(("changes", "name", "side"), [
    ({"a": 1e308}, "a", "<="), ({"a": 1e300}, "a", "<="), ({"m": 1e300}, "m", "<="),
    ({"tau": 1e300}, "tau", "<="), ({"D": 1e-320}, "D", ">="), ({"sigma": 1e-200}, "sigma", ">="),
])
def test_out_of_range_is_refused_naming_the_parameter_and_its_range(changes, name, side) -> None:
    h = Harvester.build(a=changes.pop("a", 0.5), **changes)
    with pytest.raises(ParameterError, match=rf"^{name} = \S+ is out of range .*double.* {name} {side} \S+ keeps") as exc:
        solve(h)
    bound = float(str(exc.value).split(f"{name} {side} ")[1].split()[0])
    assert solve(h.replace(**{name: bound})).ok  # the stated bound is inside the range


@pytest.mark.parametrize("changes", [{"tau": 1e100}, {"D": 1e-300}, {"m": 1e-300}, {"Kc": 1e200},
                                     {"tau_p": 1e-100}, {"a": 1e150}])
def test_extreme_but_representable_parameters_are_solved(changes) -> None:
    """Answers within double range are computed, whatever the intermediate products (were tracebacks)."""
    h = Harvester.build(a=changes.pop("a", 0.5), **changes)
    r = solve(h)
    ref = mp_closed_form(h)
    assert r.status is Status.STABLE
    for q in ("eta", "V2", "Pin"):
        assert abs(r.value(q)[0] - ref[q]) <= r.value(q)[1] > 0 or r.value(q)[0] == float(ref[q])


def test_vrms_error_covers_the_square_root_rounding() -> None:
    """Found by the long fuzz profile: Vrms was off by 1.8e-15 with a stated error of 1.6e-15
    (only V2's error was propagated, not the rounding of the square root)."""
    h = Harvester.build(a=0.5, N=46, k=0.25, m=0.5, gamma=6.875, Kv=0.94921875, Kc=1152.0, tau=0.15625,
                        tau_p=369.2989518558326)
    check_exact(h)


@pytest.mark.parametrize("kappa", [1e-8, 1.0, 2e8, 1e12])
def test_numerical_lyapunov_covariance_matches_the_closed_form_for_stiff_and_soft_units(kappa):
    import warnings

    from fpe_harvester.exact.moments import lyapunov_covariance, mode_moments
    from fpe_harvester.model import Params

    p = Params()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # scipy warns (and perturbs A) on an unbalanced stiff unit
        X = lyapunov_covariance(kappa, p)
    m = mode_moments(kappa, p)
    assert X[0, 0] == pytest.approx(float(m["x2"]), rel=1e-12)
    assert X[2, 2] == pytest.approx(float(m["V2"]), rel=1e-12)
