"""Model objects: defaults, validation, conversions."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fpe_harvester import Harvester, ParameterError, Params, Potential

POSITIVE = ["m", "Kc", "sigma", "tau", "D", "tau_p", "R"]


def test_paper_defaults():
    p = Params()
    assert (p.m, p.gamma, p.Kv, p.Kc, p.sigma, p.tau, p.D, p.tau_p, p.R) == (1, 1, 1, 1, 1, 1, 1, 2, 1)
    assert p.noise_variance == 1.0


@pytest.mark.parametrize("name", POSITIVE)
@pytest.mark.parametrize("bad", [0, -1.5])
def test_nonpositive_parameters_rejected(name, bad):
    with pytest.raises(ParameterError, match=rf"{name} must be in \(0, inf\), got {bad!r}"):
        Params(**{name: bad})


def test_gamma_may_be_zero_but_not_negative():
    assert Params(gamma=0).gamma == 0.0
    with pytest.raises(ParameterError, match=r"gamma must be in \[0, inf\)"):
        Params(gamma=-0.1)


def test_kv_may_be_zero_but_not_with_gamma_zero():
    assert Params(Kv=0).Kv == 0.0
    with pytest.raises(ParameterError, match=r"Kv must be in \[0, inf\), got -1"):
        Params(Kv=-1)
    with pytest.raises(ParameterError, match="gamma = 0 and Kv = 0 leave the oscillator undamped"):
        Params(Kv=0, gamma=0)


def test_higher_couplings_default_zero_and_validated():
    h = Harvester.build(N=3, k=-0.1)
    assert (h.k4, h.k3) == (0.0, 0.0)
    assert "k4" not in h.to_dict() and "k3" not in h.to_dict()
    h = Harvester.build(N=3, k=-0.1, k4=0.2, k3=0.5)
    assert (h.to_dict()["k4"], h.to_dict()["k3"]) == (0.2, 0.5)
    assert h.replace(k4=0.0).k4 == 0.0 and h.replace(k3=1).k3 == 1.0
    with pytest.raises(ParameterError, match=r"k3 must be in \[0, inf\), got -0.1"):
        Harvester.build(N=3, k3=-0.1)
    with pytest.raises(ParameterError, match="k4 must be finite"):
        Harvester.build(N=3, k4=math.inf)
    for name in ("k", "k4", "k3"):
        with pytest.raises(ParameterError, match=rf"{name} must be 0 for a single unit \(N = 1: no neighbours"):
            Harvester.build(N=1, **{name: 0.1})


def test_k4_mode_stiffness_and_confinement():
    h = Harvester.build(a=1.0, n=2, N=4, k=-0.5, k4=0.1)
    mu = 4 * np.sin(np.pi * np.arange(4) / 4) ** 2
    assert np.allclose(h.mode_stiffness(), 2 + -0.5 * mu + 0.1 * mu**2, rtol=0, atol=1e-15)
    assert h.is_linear and not h.replace(k3=0.1).is_linear
    kink = Harvester.build(a=1.0, n=1, N=3, k=-0.5)
    assert kink.confinement == "metastable"
    assert kink.replace(k3=0.1).confinement == "confined"
    # k4 > 0 can hold the softening of every mode: k mu + k4 mu^2 >= 0 for mu in {3} (N = 3)
    assert kink.replace(k4=0.2).confinement == "confined"
    assert kink.replace(k4=0.1).confinement == "metastable"


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_rejected(bad):
    with pytest.raises(ParameterError, match="D must be finite"):
        Params(D=bad)


@pytest.mark.parametrize("bad", ["1", None, True, 1j])
def test_wrong_type_rejected(bad):
    with pytest.raises(ParameterError, match=r"tau must be a real number .*type"):
        Params(tau=bad)


def test_params_frozen_and_replace():
    p = Params()
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.m = 2.0  # type: ignore[misc]
    assert p.replace(tau_p=3).tau_p == 3.0
    with pytest.raises(ParameterError, match="unknown parameter"):
        p.replace(foo=1)
    with pytest.raises(ParameterError, match="R must be in"):
        p.replace(R=0)


def test_potential_validation():
    with pytest.raises(ParameterError, match=r"n must be in \[1, 64\], got 0.5"):
        Potential(0.5, 0.5)
    with pytest.raises(ParameterError, match=r"n must be in \[1, 64\], got 1000000.0"):
        Potential(0.5, 1e6)
    with pytest.raises(ParameterError, match="beyond double precision"):
        Potential.from_U0_x0(U0=1.0, x0=1e-300, n=4)
    with pytest.raises(ParameterError, match="beyond double precision"):
        Potential(1e300, 64).U0_x0(1e10)
    with pytest.raises(ParameterError, match=r"a must be in \(0, inf\), got 0"):
        Potential(0, 2)
    with pytest.raises(ParameterError, match="a must be finite"):
        Potential(math.nan, 2)


def test_potential_force_and_conversion():
    pot = Potential(0.5, 2)
    x = np.linspace(-2, 2, 9)
    np.testing.assert_allclose(pot.force(x), -x)
    np.testing.assert_allclose(pot.U(x), 0.5 * x**2)
    kink = Potential(2.0, 1)
    np.testing.assert_allclose(kink.dU(np.array([-1.0, 0.0, 3.0])), [-2.0, 0.0, 2.0])
    p = Potential.from_U0_x0(U0=3.0, x0=-2.0, n=3)
    assert p.a == pytest.approx(3.0 / 8.0)
    assert p.U0_x0(x0=2.0) == pytest.approx((3.0, 2.0))
    with pytest.raises(ParameterError, match="x0 must be a nonzero"):
        Potential.from_U0_x0(U0=1.0, x0=0.0, n=2)


def test_harvester_validation():
    with pytest.raises(ParameterError, match=r"N must be an integer in \[1, inf\], got 0"):
        Harvester(N=0)
    with pytest.raises(ParameterError, match="N must be an integer.*2.5"):
        Harvester(N=2.5)
    with pytest.raises(ParameterError, match="k must be 0 for a single unit"):
        Harvester(k=-0.1)
    with pytest.raises(ParameterError, match="k must be finite"):
        Harvester(N=3, k=math.inf)
    with pytest.raises(ParameterError, match="potential must be a Potential"):
        Harvester(potential=2.0)  # type: ignore[arg-type]
    assert Harvester(N=np.int64(4)).N == 4


def test_harvester_build_replace_confinement():
    h = Harvester.build(a=0.5, n=1, N=3, k=-0.01, tau_p=3)
    assert h.params.tau_p == 3.0 and h.confinement == "metastable"
    assert h.replace(n=3).confinement == "confined"
    assert h.replace(n=2).confinement == "linear"
    assert h.replace(k=0.1).confinement == "confined"
    h2 = h.replace(a=2, D=5, N=4)
    assert (h2.a, h2.params.D, h2.N, h2.params.tau_p) == (2.0, 5.0, 4, 3.0)


def test_mode_stiffness_n2_convention():
    # N = 2: the antisymmetric mode sees 2a + 4k (force 2k(x_other - x_j) on each unit)
    h = Harvester.build(a=0.5, N=2, k=-0.1)
    np.testing.assert_allclose(h.mode_stiffness(), [1.0, 1.0 - 0.4])
