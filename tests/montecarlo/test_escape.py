"""Escape detection: harmonic rings beyond k_di and metastable n < 2 rings with k < 0."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError
from montecarlo import MonteCarlo, escape_study


def test_escape_curve_of_a_metastable_ring() -> None:
    h = Harvester.build(a=0.5, n=1.5, N=3, k=-0.3)
    c = escape_study(h, t_max=40.0, paths=32, dt=0.05, seed=2, points=9)
    assert np.all(np.diff(c.fraction) >= 0)
    assert c.fraction[0] == 0.0
    assert 0.0 < c.fraction[-1] <= 1.0
    assert c.rate is not None and c.rate > 0
    assert c.escape_time == pytest.approx(1.0 / c.rate, rel=1e-12) and c.escape_time_lower is None
    assert c.escape_time_err == pytest.approx(c.escape_time / np.sqrt(c.escape_times.size))
    assert np.all((c.escape_times > 0) & (c.escape_times <= c.t_max))
    assert np.all(c.fraction_err <= 0.5 / np.sqrt(c.paths) + 1e-12)
    assert c.to_dict()["paths"] == 32


def test_stable_ring_does_not_escape() -> None:
    c = escape_study(Harvester.build(a=0.5, n=2, N=3, k=-0.2), t_max=20.0, paths=16, seed=1)
    assert c.fraction[-1] == 0.0 and c.rate is None and c.mean_escape_time is None
    assert c.escape_time is None and c.escape_time_err is None
    assert c.exposure == pytest.approx(16 * c.t_max) and c.escape_time_lower == pytest.approx(c.exposure / 3)


def test_growth_beyond_k_di_escapes_at_the_predicted_pace() -> None:
    # far beyond k_di the critical mode grows like exp(lambda t): escape takes ~ log(threshold)/lambda
    from fpe_harvester.exact import growth_rate

    h = Harvester.build(a=0.5, n=2, N=2, k=-1.0)
    lam = growth_rate(h)
    c = escape_study(h, t_max=60.0, paths=16, seed=4, threshold=1e3)
    assert c.fraction[-1] == 1.0
    assert np.median(c.escape_times) < 3.0 * np.log(1e3 / 0.1) / lam


def test_threshold_defaults() -> None:
    mc = MonteCarlo()
    assert mc.threshold(Harvester.build(a=0.5, n=3, N=3, k=-0.5)) == 100.0
    weak = Harvester.build(a=0.5, n=1, N=3, k=-0.001)  # barrier at x* = a / (4|k| 3/4) ~ 167
    assert mc.threshold(weak) == pytest.approx(4 * 0.5 / (4 * 0.001 * 0.75))
    assert MonteCarlo(escape=7.0).threshold(weak) == 7.0


def test_escape_study_bad_input() -> None:
    h = Harvester.build(a=0.5)
    with pytest.raises(ParameterError, match="t_max must be"):
        escape_study(h, t_max=0.0)
    with pytest.raises(ParameterError, match="points must be an integer"):
        escape_study(h, t_max=1.0, points=1)
    with pytest.raises(ParameterError, match="threshold must be"):
        escape_study(h, t_max=1.0, threshold=-1.0)


def test_everything_escaping_in_burn_in_gives_no_numbers() -> None:
    from fpe_harvester import Status, solve

    h = Harvester.build(a=0.5, n=1.5, N=3, k=-1.0)
    r = solve(h, "mc", seed=1, dt=0.05, paths=16, t_burn=60.0, t_run=10.0, min_replicas=2,
              progress=False)
    assert r.status is Status.METASTABLE
    assert r.eta is None and r.V2 is None and r.eta_err is None
    assert r.info["escape_fraction"] == 1.0
    assert "No statistics" in r.message
