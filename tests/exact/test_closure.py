"""The Gaussian closure (statistical linearization), shared by the Fokker-Planck frame and the Monte Carlo twin."""

import math

import pytest

from fpe_harvester import Harvester
from fpe_harvester.exact.moments import closure_mismatch
from fpe_harvester.fpe.hermite import equivalent_harmonic
from montecarlo import linearized_stiffness


@pytest.mark.parametrize("n, a", [(3.0, 0.5), (1.5, 1.0), (8.0, 2.0)])
def test_frame_and_twin_solve_the_same_closure(n: float, a: float) -> None:
    h = Harvester.build(a=a, n=n)
    k_fp, k_mc = equivalent_harmonic(h)[0], linearized_stiffness(h)
    assert abs(closure_mismatch(h, math.log(k_fp))) < 1e-9
    assert k_mc == pytest.approx(k_fp, rel=1e-9)


def test_closure_is_exact_for_the_harmonic_potential() -> None:
    """n = 2: <x U'> = 2a <x^2>, so the mismatch vanishes at kappa = 2a, for rings too."""
    for h in (Harvester.build(a=0.7, n=2), Harvester.build(a=0.7, n=2, N=4, k=-0.1)):
        assert abs(closure_mismatch(h, math.log(1.4))) < 1e-12
