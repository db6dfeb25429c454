"""Shell densities of the kink figure (validation.kinkdensity)."""

import math

import numpy as np
import pytest
import scipy.integrate

from fpe_harvester import Harvester
from validation.kinkdensity import shell_area, shell_density_mc


@pytest.mark.parametrize("a, m", [(0.5, 1.0), (2.0, 3.0)])
def test_shell_area_is_the_area_of_the_energy_region(a: float, m: float) -> None:
    eps = 0.7
    half, _ = scipy.integrate.quad(lambda x: 2.0 * math.sqrt(2.0 * (eps - a * x) / m), 0.0, eps / a)
    assert shell_area(eps, a, m) == pytest.approx(2.0 * half, rel=1e-10)


def test_monte_carlo_shell_densities_hold_the_mass() -> None:
    """Summed over shells that cover the law, density x area is the probability mass 1."""
    h = Harvester.build(a=0.5, n=1)
    edges = np.array([1e-6, 0.01, 0.1, 1.0, 100.0])
    sd = shell_density_mc(h, edges, samples=20, paths=64)
    mass = float(np.sum(sd.density * np.diff(shell_area(edges, h.a))))
    assert mass == pytest.approx(1.0, abs=1e-12)
    assert np.all(sd.error >= 0) and sd.centres.shape == (4,)
