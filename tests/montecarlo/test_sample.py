"""State sampler (montecarlo.sample): shape, the stationary law of a harmonic unit, errors."""

import numpy as np
import pytest

from fpe_harvester import Harvester, solve
from fpe_harvester.errors import ParameterError
from montecarlo.sample import sample_states


def test_harmonic_samples_have_the_exact_moments() -> None:
    """n = 2: the sampled V2 and v2 match the exact stationary values within 4 standard
    errors of the per-path means (paths independent; the scheme is exact for n = 2)."""
    h = Harvester.build(a=0.5, n=2)
    s = sample_states(h, samples=200, paths=400, every=2.0, t_burn=40.0, dt=0.05, seed=3)
    assert s.shape == (200, 400, 1, 4)
    ex = solve(h, "exact")
    for col, q in ((2, "V2"), (1, "v2")):
        per_path = np.mean(s[:, :, 0, col] ** 2, axis=0)
        err = per_path.std(ddof=1) / np.sqrt(per_path.size)
        assert abs(per_path.mean() - getattr(ex, q)) < 4 * err


def test_same_seed_same_samples_and_bad_input() -> None:
    h = Harvester.build(a=0.5, n=1)
    a = sample_states(h, samples=5, paths=6, every=0.5, seed=1, threads=2)
    b = sample_states(h, samples=5, paths=6, every=0.5, seed=1, threads=1)
    assert np.array_equal(a, b)
    with pytest.raises(ParameterError, match="every"):
        sample_states(h, every=0.001, dt=0.01)
    with pytest.raises(ParameterError, match="samples"):
        sample_states(h, samples=0)
