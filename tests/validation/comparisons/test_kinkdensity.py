"""Shell densities of the kink figure (validation.comparisons.kinkdensity)."""

import math

import numpy as np
import pytest
import scipy.integrate

from fpe_harvester import Harvester
from validation.comparisons.kinkdensity import shell_area, shell_density_mc, v_concentration


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


def test_v_concentration_tells_a_smooth_law_from_the_kinks_spike() -> None:
    """A harmonic unit's V is Gaussian: P(|V| < delta sd) ~ 2 delta phi(0), exponent 1. At the
    strong kink (a = 2) trapped units pile up at V = 0: exponent well below 1."""
    smooth = v_concentration(Harvester.build(a=0.5, n=2), (1e-2, 1e-1), samples=100, paths=128)
    assert smooth["fraction"][1] == pytest.approx(math.erf(0.1 / math.sqrt(2.0)), abs=4 * smooth["fraction_err"][1])
    assert smooth["exponent"][0] == pytest.approx(1.0, abs=0.15)
    spike = v_concentration(Harvester.build(a=2.0, n=1), (1e-2, 1e-1), samples=100, paths=128)
    assert spike["exponent"][0] < 0.6
    assert spike["fraction"][0] > 10 * smooth["fraction"][0]
