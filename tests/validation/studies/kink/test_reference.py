"""The kink reference (validation.studies.kink.reference): its root finder, and agreement with the scheme."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError
from validation.studies.kink.reference import _eigen_data, _first_root, reference_run, summarize


def test_conservative_advancement_finds_a_grazing_crossing() -> None:
    # x dips below 0 for ~2e-5 of a 1e-3 interval and comes back: a sampling grid misses it
    ed = _eigen_data(Harvester.build(a=1.0, n=1))
    ed = ed[:4] + (np.zeros(3, dtype=np.complex128), np.zeros(3, dtype=np.complex128))
    y0, y = np.array([1e-8, -2.1e-4, 0.0]), np.zeros(3)
    c0 = 2.0  # outward force on the + side: x(t) ~ 1e-8 - 2.1e-4 t + t^2
    t = _first_root(y0, 1.0, c0, 0.0, 1e-3, False, 10.0, ed, y)
    roots = np.sort(np.roots([0.5 * c0, -2.1e-4, 1e-8]).real)
    assert t == pytest.approx(roots[0], rel=1e-3)
    assert abs(y[0]) < 1e-14


@pytest.mark.slow  # ~15 s of compilation: the driver is not cached (it calls the production kernels)
def test_reference_agrees_with_the_scheme_on_common_noise() -> None:
    run = reference_run(0.5, delta=2e-3, schemes=((10, "average"),), paths=32, replicas=4, t_burn=10.0,
                        t_run=30.0, seed=4)
    lev = summarize(run)["levels"]
    d = lev["scheme dt=0.02 average"]
    for q in ("eta", "V2", "Pin"):
        assert abs(d[f"minus_ref_{q}"]) < 4 * d[f"minus_ref_{q}_se"] + 1e-3 * abs(d[q]), q
    # common noise: the difference is far more precise than either value
    assert d["minus_ref_eta_se"] < 0.3 * lev["reference"]["eta_se"]
    with pytest.raises(ParameterError, match="even integer >= 2, got 5"):
        reference_run(0.5, schemes=((5, "average"),))
