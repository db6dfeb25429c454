"""sweep(): parameter grids in one call, a table with the parameters beside the results."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fpe_harvester import Harvester, ParameterError, exact_sweep, k_di, solve, sweep
from fpe_harvester.exact import Exact


def test_outer_product_with_the_parameters_beside_the_results(monkeypatch) -> None:
    sizes: list[int] = []
    real = Exact.solve_many
    monkeypatch.setattr(Exact, "solve_many", lambda self, hs: sizes.append(len(hs)) or real(self, hs))
    ks = [-0.4, -0.3, 0.0]
    s = sweep(Harvester.build(a=0.5, n=2, N=3), {"a": [0.5, 1.0], "k": ks}, tol=1e-3)
    assert sizes == [6]  # the exact points in one vectorized call
    assert s.axes == ("a", "k") and len(s) == 6
    assert [dict(p) for p in s.points] == [{"a": a, "k": k} for a in (0.5, 1.0) for k in ks]
    ref = exact_sweep(a=[[0.5], [1.0]], k=ks, N=3)
    assert np.ma.allequal(s.column("eta").reshape(2, 3), ref["eta"])
    assert s.column("eta").mask.tolist() == [True, False, False, False, False, False]  # k = -0.4 < k_di(a = 0.5)
    assert s.results[0].status.value == "unstable" and s.results[0].info["ignored"] == ["tol"]
    rec = s.records()[4]
    assert list(rec)[:2] == ["a", "k"] and (rec["a"], rec["k"], rec["N"], rec["tau_p"]) == (1.0, -0.3, 3, 2.0)
    assert rec["eta"] == solve(Harvester.build(a=1.0, n=2, N=3, k=-0.3)).eta
    d = json.loads(json.dumps(s.to_dict()))
    assert d["axes"] == ["a", "k"] and d["rows"][0]["status"] == "unstable" and d["rows"][0]["eta"] is None
    assert "eta" in s.table().splitlines()[0] and "unstable" in s.table()


def test_into_pandas_in_one_call() -> None:
    pd = pytest.importorskip("pandas")
    frame = sweep(Harvester.build(a=0.5, n=2, N=3), {"k": np.linspace(k_di(3, 0.5), 0.0, 5)}).to_frame()
    assert isinstance(frame, pd.DataFrame) and frame.shape[0] == 5
    assert list(frame.columns[:2]) == ["k", "a"] and {"eta", "eta_err", "status", "method", "tau_p"} <= set(frame)
    assert frame["status"].tolist()[0] == "marginal" and frame["x2"].isna().tolist()[0]
    assert frame["eta"].is_monotonic_decreasing


def test_a_sweep_over_solvers() -> None:
    s = sweep(Harvester.build(a=0.5), {"n": [2, 3]}, tol=1e-3, progress=False)
    assert [r.method for r in s.results] == ["exact", "fpe"]
    assert s.results[1].eta_err <= 1e-3 * s.results[1].eta and s.records()[1]["n"] == 3


@pytest.mark.parametrize(("grid", "match"), [
    ({"z": [1]}, "grid: 'z' is not a parameter"),
    ({}, "grid must map parameter names"),
    ({"k": []}, r"grid\['k'\] must be a non-empty list"),
    ({"a": [0.5, -1.0]}, r"sweep point \(a = -1.0\): a must be in \(0, inf\)"),
])
def test_bad_grids_are_refused_before_any_point(grid: dict, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        sweep(Harvester.build(), grid)
    with pytest.raises(ParameterError, match="column must be a parameter or a quantity"):
        sweep(Harvester.build(), {"a": [1.0]}).column("power")


@pytest.mark.slow
def test_a_loop_over_n_with_one_tolerance() -> None:
    """The first hour's loop: one tolerance for every n, whichever solver answers."""
    methods = [solve(Harvester.build(a=0.5, n=n), tol=1e-3).method for n in (1, 1.5, 2, 3)]
    assert methods == ["fpe", "fpe", "exact", "fpe"]
