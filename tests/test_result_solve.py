"""Result type and the solve() entry point."""

from __future__ import annotations

import json
import math

import pytest

from fpe_harvester import (
    Exact,
    Harvester,
    MethodNotAvailableError,
    ParameterError,
    Stats,
    Status,
    choose_method,
    get_solver,
    solve,
)
from fpe_harvester.errors import check_choice, check_int, check_real


def test_from_moments_propagates_errors():
    r = Stats.from_moments(V2=2.0, Pin=4.0, R=0.5, V2_err=0.02, Pin_err=0.04, method="mc")
    assert r.eta == pytest.approx(1.0)
    assert r.eta_err == pytest.approx(math.sqrt(2) * 0.01)
    assert r.Vrms_err == pytest.approx(0.5 * 0.02 / math.sqrt(2))
    corr = Stats.from_moments(V2=2.0, Pin=4.0, R=0.5, V2_err=0.02, Pin_err=0.04, cov_V2_Pin=0.0008)
    assert corr.eta_err == pytest.approx(0.0, abs=1e-12)


def test_stats_rejects_non_finite():
    with pytest.raises(ValueError, match="eta = nan"):
        Stats(eta=math.nan)
    with pytest.raises(ValueError, match="V2_err = inf"):
        Stats(V2=1.0, V2_err=math.inf)


def test_to_dict_is_json_and_value_lookup():
    r = solve(Harvester.build())
    d = json.loads(json.dumps(r.to_dict()))
    assert d["status"] == "stable" and d["method"] == "exact"
    assert r.value("eta") == (r.eta, r.eta_err)
    with pytest.raises(KeyError, match="unknown observable 'power'"):
        r.value("power")
    assert Stats(status="marginal").status is Status.MARGINAL


def test_choose_method():
    assert choose_method(Harvester.build(n=2, N=5, k=0.1)) == "exact"
    assert choose_method(Harvester.build(n=1)) == "fpe"
    assert choose_method(Harvester.build(n=3, N=3, k=-0.5)) == "mc"


def test_solve_errors():
    with pytest.raises(ParameterError, match="method must be one of 'exact', 'fpe', 'mc', 'auto'"):
        solve(Harvester.build(), "magic")
    with pytest.raises(ParameterError, match="h must be a Harvester"):
        solve({"a": 0.5})  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="cannot be combined with a solver object"):
        get_solver(Exact(), dt=0.1)
    with pytest.raises(ParameterError, match=r"tol must be in \(0, 1\), got 1"):
        get_solver(Exact(), tol=1)
    with pytest.raises(MethodNotAvailableError, match="n = 2"):
        solve(Harvester.build(n=4), Exact())


def test_validators():
    assert check_real("x", 1, low=0.0, high=1.0) == 1.0
    with pytest.raises(ParameterError, match=r"x must be in \[0, 1\), got 1"):
        check_real("x", 1, low=0.0, high=1.0, high_open=True)
    assert check_int("M", 4.0, low=1) == 4
    with pytest.raises(ParameterError, match=r"M must be an integer in \[1, 9\], got 10"):
        check_int("M", 10, low=1, high=9)
    with pytest.raises(ParameterError, match="M must be an integer.*True"):
        check_int("M", True)
    with pytest.raises(ParameterError, match="observable must be one of 'eta', 'V2'; got 'P'"):
        check_choice("observable", "P", ["eta", "V2"])


@pytest.mark.parametrize(("status", "error"), [
    (Status.UNSTABLE, "UnstableSystemError"), (Status.METASTABLE, "UnstableSystemError"),
    (Status.NOT_CONVERGED, "NotConvergedError"),
])
def test_raise_for_status_raises_unless_the_numbers_describe_a_stationary_state(status, error):
    """Its docstring's promise: stable or marginal pass, everything else raises (not_converged did not)."""
    import fpe_harvester

    r = Stats(status=status, message="what happened")
    with pytest.raises(getattr(fpe_harvester, error), match="what happened"):
        r.raise_for_status()
    with pytest.raises(getattr(fpe_harvester, error)):
        Stats(status=status).raise_for_status()  # no message: a default one
    for ok in (Status.STABLE, Status.MARGINAL):
        s = Stats(V2=1.0, status=ok)
        assert s.raise_for_status() is s


def test_from_moments_without_overflow_or_division_by_zero():
    """eta = V2/(R Pin) with R Pin beyond double range, V2 = 0, and the errors of tiny values."""
    r = Stats.from_moments(V2=1e300, Pin=1e300, R=1e300, V2_err=1e284, Pin_err=1e284)
    assert r.eta == pytest.approx(1e-300) and r.eta_err == pytest.approx(math.sqrt(2) * 1e-316)
    tiny = Stats.from_moments(V2=1e-300, Pin=1e-300, R=1.0, V2_err=1e-310, Pin_err=1e-310)
    assert tiny.eta == 1.0 and tiny.eta_err == pytest.approx(math.sqrt(2) * 1e-10)
    zero = Stats.from_moments(V2=0.0, Pin=2.0, R=0.5, V2_err=0.04)
    assert zero.eta == 0.0 and zero.eta_err == pytest.approx(0.04) and zero.Vrms == 0.0
    assert zero.Vrms_err == pytest.approx(0.2)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"V2": 1.0, "Pin": 0.0}, "Pin != 0"),
    ({"V2": -1.0, "Pin": 1.0}, "V2 >= 0"),
    ({"V2": math.nan, "Pin": 1.0}, "finite V2"),
    ({"V2": 1e300, "Pin": 1e-300}, r"eta = V2/\(R Pin\) ~ 10\^600.0 exceeds the largest double"),
    ({"V2": 1.0, "Pin": 1.0, "V2_err": 1e300, "Pin_err": 1e-300, "cov_V2_Pin": 0.0, "R": 1e-300},
     "exceeds the largest double"),
])
def test_from_moments_refuses_clearly(kwargs, match):
    with pytest.raises(ParameterError, match=match):
        Stats.from_moments(**{"R": 1.0, **kwargs})


def test_growth_rate_must_be_finite():
    with pytest.raises(ValueError, match="growth_rate = inf"):
        Stats(status=Status.UNSTABLE, growth_rate=math.inf, method="exact")


def test_unknown_solver_options_list_the_valid_ones():
    with pytest.raises(ParameterError, match="invalid option for method 'exact': no option 'M'; valid options: none"):
        solve(Harvester.build(), "exact", M=8)
    with pytest.raises(ParameterError, match="invalid option for method 'fpe': no option 'dt'; valid options: tol, M,"):
        get_solver("fpe", dt=0.1)


def test_common_settings_for_every_method_and_what_was_ignored():
    """tol, seed, max_time (or max_seconds) and progress are accepted whatever the method: each solver
    uses those it has; info["ignored"] lists the rest (a loop over n does not break at n = 2)."""
    r = solve(Harvester.build(a=0.5, n=2), tol=1e-3, seed=1, max_seconds=5.0, progress=False)
    assert r.method == "exact" and r.eta == pytest.approx(20 / 39, rel=1e-14)
    assert r.info["ignored"] == ["max_time", "seed", "tol"]  # progress changes no number: not listed
    fpe = get_solver("fpe", tol=1e-3, seed=1, max_seconds=7.0, progress=False)
    assert (fpe.tol, fpe.max_seconds, fpe.progress) == (1e-3, 7.0, False)
    mc = get_solver("mc", tol=0.05, seed=3, max_seconds=9.0, progress=False)
    assert (mc.tol, mc.seed, mc.max_time, mc.progress) == (0.05, 3, 9.0, False)
    assert get_solver("mc", max_time=4.0).max_time == 4.0
    assert get_solver("fpe", max_time=1.0, max_seconds=1.0).max_seconds == 1.0  # the same setting twice
    with pytest.raises(ParameterError, match="max_time and max_seconds name one setting"):
        solve(Harvester.build(), max_time=1.0, max_seconds=2.0)
    for bad, match in (({"tol": 0}, r"tol must be in \(0, 1\)"), ({"seed": -1}, "seed must be an integer"),
                       ({"max_time": 0}, r"max_time must be in \(0, inf\)"), ({"progress": "yes"}, "progress must be")):
        with pytest.raises(ParameterError, match=match):
            solve(Harvester.build(), **bad)
    # each solver checks its own range
    with pytest.raises(ParameterError, match=r"tol must be in \(0, 0.1\]"):
        solve(Harvester.build(n=3), "fpe", tol=0.5)


def test_stats_carry_their_system_and_go_into_pandas():
    h = Harvester.build(a=0.5, n=2, N=3, k=-0.33, tau_p=3.0)
    r = solve(h)
    d = json.loads(json.dumps(r.to_dict()))
    assert r.harvester == h and d["harvester"] == h.to_dict() and d["harvester"]["params"]["tau_p"] == 3.0
    rec = r.to_record()
    assert (rec["a"], rec["N"], rec["k"], rec["tau_p"]) == (0.5, 3, -0.33, 3.0)
    assert rec["eta"] == r.eta and rec["x2_err"] == r.x2_err and rec["status"] == "stable"
    pd = pytest.importorskip("pandas")
    frame = r.to_frame()
    assert isinstance(frame, pd.DataFrame) and frame.shape[0] == 1
    assert frame.loc[0, "eta"] == r.eta and frame.loc[0, "k"] == -0.33
    assert math.isnan(frame.loc[0, "d2_err"]) is False  # a ring has d2
    assert Stats(eta=1.0).to_record()["status"] == "stable"  # no system: only the results
    from fpe_harvester.scenes.cache import stats_from_dict

    back = stats_from_dict(d)  # a result through JSON (the scene cache, a Dask worker) keeps its system
    assert back.harvester == h and back.to_dict() == r.to_dict()
    with pytest.raises(ParameterError, match="harvester must be a Harvester"):
        Stats(harvester={"a": 0.5})


def test_auto_asks_the_solvers_in_order_and_says_why():
    ring = Harvester.build(a=0.5, n=3, N=3, k=-0.5)
    assert choose_method(ring) == "mc"
    assert choose_method(Harvester.build(a=0.5, n=3, N=3, k=-0.5).replace(n=2.0)) == "exact"
    # a harmonic ring with cubic coupling: exact declines (nonlinear), Fokker-Planck too (a ring)
    assert choose_method(Harvester.build(n=2, N=3, k3=0.1)) == "mc"
    r = solve(Harvester.build(a=0.5, n=2, N=3, k=-0.2))
    assert r.info["auto"] == {"chosen": "exact", "declined": {}} and "declined" not in r.message
