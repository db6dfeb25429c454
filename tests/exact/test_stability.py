"""Thresholds: closed form vs eigenvalues of the dense ring drift."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester, ParameterError, Params, critical_mode, growth_rate, k_di, threshold
from fpe_harvester.exact import classify, ring_drift_matrix, ring_spectrum


def test_known_thresholds():
    assert k_di(3, 0.5) == pytest.approx(-1 / 3, rel=1e-14)
    for N in (2, 4, 6, 100):
        assert k_di(N, 0.7) == pytest.approx(-0.35, rel=1e-14)
    assert k_di(1, 0.5) is None
    assert critical_mode(3) == (1, 2) and critical_mode(4) == (2,) and critical_mode(1) == (0,)


@pytest.mark.parametrize("N", range(2, 51))
def test_threshold_matches_dense_eigenvalues(N):
    a = 0.5
    kd = k_di(N, a)
    params = Params(m=1.3, gamma=0.4, tau_p=2.5)
    inside = Harvester.build(a=a, N=N, k=kd * (1 - 1e-3)).replace(params=params)
    beyond = inside.replace(k=kd * (1 + 1e-3))
    ev_in = np.linalg.eigvals(ring_drift_matrix(inside))
    ev_out = np.linalg.eigvals(ring_drift_matrix(beyond))
    assert ev_in.real.max() < 0
    assert ev_out.real.max() > 0
    assert growth_rate(beyond) == pytest.approx(ev_out.real.max(), rel=1e-6)
    # the critical mode is the one that went soft
    kap = beyond.mode_stiffness()
    assert set(np.flatnonzero(kap < 0)) == set(critical_mode(N))


def test_spectrum_is_union_of_modes():
    h = Harvester.build(a=0.5, N=5, k=-0.2)
    modes = ring_spectrum(h).ravel()
    dense = np.linalg.eigvals(ring_drift_matrix(h))
    assert modes.shape == dense.shape == (20,)
    dist = np.abs(modes[:, None] - dense[None, :])
    assert dist.min(axis=0).max() < 1e-7 and dist.min(axis=1).max() < 1e-7


def test_classify():
    assert classify(Harvester.build(N=3, k=-0.2))[0] == "stable"
    assert classify(Harvester.build(N=3, k=k_di(3, 0.5)))[0] == "marginal"
    assert classify(Harvester.build(N=3, k=-0.34))[0] == "unstable"
    assert classify(Harvester.build(N=3, k=k_di(3, 0.5) * (1 - 1e-12)))[0] == "stable"
    # each mode judged on its own round-off: q = 0 has stiffness exactly 2a, however large k
    # or small a (these three were "marginal" when the tolerance was relative to 2a + 4|k|)
    assert classify(Harvester.build(N=3, k=1e14)) == ("stable", 1.0)
    assert classify(Harvester.build(N=2, k=1e50)) == ("stable", 1.0)
    assert classify(Harvester.build(a=1e-14, N=3, k=1.0)) == ("stable", 2e-14)
    assert classify(Harvester.build(a=1e308, N=4, k=-1e308))[0] == "unstable"
    assert classify(Harvester.build(a=1e308, N=4, k=k_di(4, 1e308)))[0] == "marginal"


def test_growth_rates_of_stiff_and_weakly_damped_modes_are_resolved():
    """numpy.roots alone returned 0.0 for these stable modes (slow root -4e-22 next to roots of
    size 3e10; a real part -9e-17 next to an imaginary part 1): the sign must be right."""
    from fpe_harvester.exact import mode_growth_rate

    assert mode_growth_rate(1.0, Params(Kc=2.0**70)) == pytest.approx(-0.5 / 2.0**70, rel=1e-12)
    assert -1e-16 < mode_growth_rate(1.0, Params(Kc=2.0**-51, gamma=0.0)) < 0
    assert mode_growth_rate(1.0, Params(tau_p=2.0**-205)) == pytest.approx(-0.5, rel=1e-12)
    assert mode_growth_rate(-1.0, Params()) > 0 and mode_growth_rate(0.0, Params()) == 0.0


def test_threshold_object():
    th = threshold(3, 0.5)
    d = th.to_dict()
    assert d["critical_mode"] == [1, 2] and d["k_di"] == pytest.approx(-1 / 3)
    assert "marginal" in th.explanation
    assert threshold(1, 0.5).k_di is None and "single unit" in threshold(1, 0.5).explanation
    with pytest.raises(ParameterError, match="N must be an integer"):
        threshold(0, 0.5)
    with pytest.raises(ParameterError, match=r"a must be in \(0, inf\)"):
        threshold(3, -1.0)
