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
    with pytest.raises(ParameterError, match="invalid option for method 'exact'"):
        solve(Harvester.build(), "exact", tol=1e-3)
    with pytest.raises(ParameterError, match="cannot be combined with a solver object"):
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
