"""Time-dependent runs through py-pde: exact Lyapunov dynamics (n = 2), relaxation to the stationary state."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
import pytest

from fpe_harvester import Harvester, MethodNotAvailableError, NotConvergedError, ParameterError
from fpe_harvester.fpe.schemes.x import XMeshRule
from fpe_harvester.fpe.schemes.x.discretize import Whitening, solve_level
from fpe_harvester.fpe.transient import lyapunov_transient, transient


def test_harmonic_transient_matches_lyapunov_ode() -> None:
    h = Harvester.build(a=0.5, n=2)
    tr = transient(h, 6.0, M=4, elements=16, interval=1.0, grid=51)
    w = Whitening.of(h)
    s = 0.3 * math.sqrt(w.x2)
    P = lyapunov_transient(h, np.diag([s**2, s**2, s**2, 1.0]), tr.t)
    assert tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(6.0)
    # Limited by the transient domain (density e^-12 at +-L) and the narrow start.
    assert np.abs(tr.V2 - P[:, 2, 2]).max() < 1e-4 * P[-1, 2, 2]
    assert np.abs(tr.Pin - P[:, 1, 3]).max() < 1e-4 * P[-1, 1, 3]
    assert np.abs(tr.x2 - P[:, 0, 0]).max() < 1e-4 * P[-1, 0, 0]
    assert abs(tr.mass[0] - 1.0) < 1e-5  # quadrature of the narrow initial Gaussian
    assert np.abs(tr.mass - tr.mass[0]).max() < 1e-4  # only the outflow at +-L (density e^-12 there)
    assert tr.eta.mask[0] and not tr.eta.mask[-1]  # Pin = 0 at the start: eta undefined
    assert tr.density.shape == (len(tr.t), 51)


@pytest.fixture(scope="module")
def stationary_n3() -> tuple[Harvester, Mapping[str, float]]:
    """n = 3, a = 0.5 and the stationary moments of the discretization ``transient`` uses
    (M = 4, 8 half elements, order 3), read-only so the tests sharing it cannot alter it."""
    h = Harvester.build(a=0.5, n=3)
    # A module fixture is set up before the autouse strict-floats fixture of each test.
    with np.errstate(all="raise", under="ignore"):
        w = Whitening.of(h)
        mesh = XMeshRule.of(h, domain=12.0).build(h, w, 8)
        st = solve_level(h, 4, mesh, 3, w).moments
    return h, MappingProxyType(dict(st))


def test_relaxes_to_stationary_solution(stationary_n3: tuple[Harvester, Mapping[str, float]]) -> None:
    """n = 3: the transient approaches the stationary solution of the same discretization."""
    h, st = stationary_n3
    tr = transient(h, 24.0, M=4, elements=16, interval=4.0, grid=21)
    gap = np.abs(tr.V2 - st["V2"]) / st["V2"]
    assert np.all(np.diff(gap[2:]) < 0)  # monotone approach after the initial swing
    assert gap[-1] < 2e-3
    assert abs(tr.eta[-1] - st["eta"]) < 5e-3 * st["eta"]


def test_steep_wall_relaxes_with_default_mesh() -> None:
    """n = 8: the default 16 elements per half resolve the wall (8 gave a growing mode);
    the run approaches the stationary solution of the same discretization."""
    h = Harvester.build(a=0.5, n=8)
    w = Whitening.of(h)
    st = solve_level(h, 4, XMeshRule.of(h, domain=12.0).build(h, w, 16), 3, w).moments
    tr = transient(h, 12.0, M=4, interval=4.0, grid=5)
    assert tr.info["elements"] == 32
    gap = np.abs(tr.V2 - st["V2"]) / st["V2"]
    assert np.all(np.diff(gap) < 0)
    assert gap[-1] < 3e-3


def test_unstable_discretization_is_reported() -> None:
    with pytest.raises(NotConvergedError, match="spurious growing mode"):
        transient(Harvester.build(a=0.5, n=8), 5.0, M=4, elements=8, interval=0.5, grid=5)


def test_transient_bad_input() -> None:
    h = Harvester.build(a=0.5, n=3)
    with pytest.raises(ParameterError, match="t_end"):
        transient(h, -1.0)
    with pytest.raises(ParameterError, match="P0"):
        transient(h, 1.0, P0=np.eye(3))
    with pytest.raises(ParameterError, match="elements must be even"):
        transient(h, 1.0, elements=7)
    with pytest.raises(ParameterError, match="domain"):
        transient(h, 1.0, domain=1.0)
    with pytest.raises(MethodNotAvailableError, match="N = 3"):
        transient(Harvester.build(a=0.5, n=3, N=3, k=0.1), 1.0)
    with pytest.raises(MethodNotAvailableError, match="harmonic"):
        lyapunov_transient(h, np.eye(4), np.array([0.0, 1.0]))


@pytest.mark.slow
def test_relaxation_reaches_stationary_to_1e6(stationary_n3: tuple[Harvester, Mapping[str, float]]) -> None:
    h, st = stationary_n3
    tr = transient(h, 80.0, M=4, elements=16, interval=10.0, grid=11)
    assert abs(tr.V2[-1] - st["V2"]) < 1e-6 * st["V2"]
