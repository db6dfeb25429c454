"""The landscape of the coupled potential: energy vs force, equilibria, buckling closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester, ParameterError
from fpe_harvester.exact import ring_drift_matrix, threshold
from fpe_harvester.landscape import (
    RingEnergy,
    bounded_below,
    buckling,
    coexistence_coupling,
    find_equilibria,
    fold_coupling,
    landscape,
)


@pytest.mark.parametrize("N", [2, 3, 5])
@pytest.mark.parametrize(("n", "k", "k4", "k3"), [(3.0, -0.4, 0.3, 0.7), (1.5, 0.2, -0.1, 0.0), (2.0, -0.3, 0.5, 1.2)])
def test_force_is_minus_the_energy_gradient(N, n, k, k4, k3, rng):
    """Central differences of E against the force: fixes the k4 energy's normalisation (k4/2) sum (Lx)^2."""
    e = RingEnergy(n=n, a=0.6, N=N, k=k, k4=k4, k3=k3)
    x = rng.uniform(0.3, 1.5, N) * rng.choice([-1.0, 1.0], N)
    h = 1e-6
    grad = np.array([(e.energy(x + h * np.eye(N)[j]) - e.energy(x - h * np.eye(N)[j])) / (2 * h) for j in range(N)])
    assert np.allclose(-grad, e.force(x), rtol=1e-7, atol=1e-8)
    hess = np.array([(e.force(x - h * np.eye(N)[j]) - e.force(x + h * np.eye(N)[j])) / (2 * h) for j in range(N)])
    assert np.allclose(hess, e.hessian(x), rtol=1e-6, atol=1e-6)


def test_coupling_force_matches_the_exact_solvers_drift():
    """The linear part of the coupling force is the dense drift's (kL - k4 L^2)/m block."""
    h = Harvester.build(a=0.5, N=5, k=-0.3, k4=0.2, m=2.0)
    e = RingEnergy.of(h)
    x = np.linspace(-1.0, 1.3, 5)
    block = ring_drift_matrix(h)[1::4, 0::4] * h.params.m + 2.0 * h.a * np.eye(5)
    assert np.allclose(e.coupling_force(x), block @ x, rtol=1e-13, atol=1e-14)


def test_fold_and_coexistence_couplings():
    assert fold_coupling(1.0, 1.0) == pytest.approx(-(27 / 16) ** (1 / 3), abs=1e-12)
    assert coexistence_coupling(1.0, 1.0) == pytest.approx(-1.5, abs=1e-12)
    a, k3 = 0.7, 0.3
    k_sn, k_co = fold_coupling(a, k3), coexistence_coupling(a, k3)
    below, above = buckling(a, k_sn * (1 + 1e-6), k3), buckling(a, k_sn * (1 - 1e-6), k3)
    assert above.u_plus is None
    assert below.u_plus - below.u_s == pytest.approx(0.0, abs=1e-2) and below.u_plus > below.u_s
    # at k_co the buckled state has the origin's energy
    b = buckling(a, k_co, k3)
    assert a * b.u_plus + k_co * b.u_plus**2 + 0.5 * k3 * b.u_plus**4 == pytest.approx(0.0, abs=1e-8)


def test_barriers_of_the_issue_example():
    b = buckling(1.0, -2.0, 1.0)
    assert b.escape_barrier == pytest.approx(0.127088, abs=5e-7)
    assert b.return_barrier == pytest.approx(0.782190, abs=5e-7)
    assert b.hop_barrier == pytest.approx(0.193831, abs=5e-7)


def test_reduction_against_the_full_three_unit_search():
    """Every state of the closed forms is an equilibrium of the whole ring, with the right index."""
    ls = landscape(RingEnergy(n=1, a=1.0, N=3, k=-2.0, k3=1.0))
    b = ls.buckling
    by_energy = {}
    for q in ls.equilibria:
        by_energy.setdefault(round(q.energy, 9), []).append(q)
    e_plus = 1.0 * b.u_plus - 2.0 * b.u_plus**2 + 0.5 * b.u_plus**4
    minima = [q for q in ls.equilibria if abs(q.energy - e_plus) < 1e-10]
    assert len(minima) == 6 and all(q.index == 0 and not q.degenerate for q in minima)
    assert ls.global_minimum.energy == pytest.approx(e_plus, abs=1e-12)
    escape = [q for q in ls.equilibria if abs(q.energy - b.escape_barrier) < 1e-10]
    assert len(escape) == 6 and all(q.index == 1 and len(q.pinned) == 2 for q in escape)
    hop = [q for q in ls.equilibria if abs(q.energy - (e_plus + b.hop_barrier)) < 1e-10]
    assert len(hop) == 6 and all(q.index == 1 and len(q.pinned) == 1 for q in hop)
    assert sorted(np.abs(hop[0].x))[-1] == pytest.approx(b.u_hop, rel=1e-10)
    origin = [q for q in ls.equilibria if not any(q.x)]
    assert len(origin) == 1 and origin[0].index == 0 and not origin[0].degenerate


@pytest.mark.parametrize("N", [4, pytest.param(5, marks=pytest.mark.slow)])
def test_single_site_states_in_larger_rings(N):
    e = RingEnergy(n=1, a=1.0, N=N, k=-2.0, k3=1.0)
    b = buckling(1.0, -2.0, 1.0, N)
    states = find_equilibria(e)
    for u, index in ((b.u_plus, 0), (b.u_s, 1)):
        x = np.zeros(N)
        x[0] = u
        match = [q for q in states if np.allclose(q.x, x, atol=1e-9)]
        assert len(match) == 1 and match[0].index == index


def test_unbounded_without_cubic_coupling():
    ls = landscape(Harvester.build(a=1.0, n=1, N=3, k=-0.5))
    assert not ls.bounded and ls.global_minimum is None and "no global minimum" in ls.message
    assert ls.to_dict()["global_minimum"] is None
    assert bounded_below(RingEnergy(n=1, a=1.0, N=3, k=-0.5, k3=0.01))[0]
    assert bounded_below(RingEnergy(n=3, a=1.0, N=3, k=-5.0))[0]


@pytest.mark.parametrize("k4", [0.1, 0.5, -0.05])
def test_harmonic_boundedness_is_the_threshold(k4):
    kd = threshold(4, 1.0, k4).k_di
    assert bounded_below(RingEnergy(n=2, a=1.0, N=4, k=kd + 1e-6, k4=k4))[0]
    assert not bounded_below(RingEnergy(n=2, a=1.0, N=4, k=kd - 1e-6, k4=k4))[0]


def test_search_refuses_large_rings():
    with pytest.raises(ParameterError, match=r"N must be in \[1, 6\] for the equilibrium search"):
        find_equilibria(RingEnergy(n=1, a=1.0, N=7, k=-1.0, k3=1.0))
    with pytest.raises(ParameterError, match=r"k3 must be in \[0, inf\)"):
        RingEnergy(n=1, a=1.0, N=3, k3=-1.0)
