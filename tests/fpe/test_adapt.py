"""Element-wise refinement of the x mesh: indicator, marking, adapted meshes, the estimate."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester, solve
from fpe_harvester.fpe import XMesh, stationary
from fpe_harvester.fpe.schemes.x import XMeshRule
from fpe_harvester.fpe.schemes.x.adapt import AdaptiveHermiteDG, element_indicators, mark
from fpe_harvester.fpe.schemes.x.discretize import Whitening, solve_level


def _marked(n: float, a: float, M: int) -> tuple[np.ndarray, np.ndarray]:
    """Marks and half nodes (relative to L) of the first mesh at degree M."""
    h = Harvester.build(a=a, n=n)
    w = Whitening.of(h)
    mesh = XMeshRule.of(h).build(h, w, 8)
    return mark(element_indicators(solve_level(h, M, mesh, 3, w))), mesh.half_nodes() / mesh.L


def test_indicator_marks_the_steep_wall() -> None:
    """n = 8, a = 2: the density falls steeply at 0.45-0.7 L (U/T_eff from 0.06 to 1); the
    marked elements are there, not at 0 or at the far edge where the density is gone."""
    marked, nodes = _marked(8.0, 2.0, 8)
    left, right = nodes[:-1][marked], nodes[1:][marked]
    assert marked.sum() <= 3
    assert left.min() >= 0.4 and right.max() <= 0.8, (left, right)


def test_indicator_marks_the_element_at_zero() -> None:
    """n = 1.5, a = 1: the force ~|x|^(1/2) is not smooth at 0; the element touching 0 is
    marked at the first step and again after it was bisected (grading toward 0)."""
    h = Harvester.build(a=1.0, n=1.5)
    w = Whitening.of(h)
    mesh = XMeshRule.of(h).build(h, w, 8)
    first = mesh.half_nodes()[1]
    for _ in range(2):
        marked = mark(element_indicators(solve_level(h, 8, mesh, 3, w)))
        assert marked[0]
        mesh = mesh.refined(marked)
    assert mesh.half_nodes()[1] == pytest.approx(first / 4)
    assert mesh.generation == 2 and mesh.size == 32


def test_indicator_falls_with_the_element_size_where_smooth() -> None:
    """On the harmonic unit (n = 2, exact Gaussian in x) the indicator of the degree-p part
    falls like h^(p + 1/2) per element, so their root sum of squares over the ~1/h elements
    like h^p = h^3 (P3) under uniform refinement: observed order within [2.5, 3.5] (a
    convergence check)."""
    h = Harvester.build(a=1.0, n=2.0)
    w = Whitening.of(h)
    rule = XMeshRule.of(h)
    total = [np.sqrt(np.sum(element_indicators(solve_level(h, 2, rule.build(h, w, nh), 3, w)) ** 2))
             for nh in (8, 16, 32)]
    orders = np.log2(np.array(total[:-1]) / np.array(total[1:]))
    assert np.all((orders > 2.5) & (orders < 3.5)), orders


def test_marking_and_refined_mesh() -> None:
    assert mark(np.array([1.0, 1.0, 1.0, 1.0]), 0.5).sum() == 2
    assert mark(np.array([0.0, 2.0, 0.0]), 1.0).tolist() == [False, True, False]
    m = XMesh(2.0, 4, n=2.0, scale=1.0, domain=1.0, wall=0.0)
    r = m.refined(np.array([True, False, False, True]))
    nodes = r.nodes()
    assert np.allclose(nodes, -nodes[::-1])  # mirror symmetry kept
    assert r.elements == 12 and r.with_elements(4).elements == 8
    with pytest.raises(ValueError, match="share must be in"):
        mark(np.ones(3), 0.0)
    with pytest.raises(ValueError, match="one flag per half element"):
        m.refined(np.array([True]))
    with pytest.raises(ValueError, match="extra nodes must lie"):
        XMesh(2.0, 4, extra=(3.0,))


def test_adaptive_refinement_meets_tol_and_its_error_bounds_a_tighter_run() -> None:
    """n = 8, a = 2 from 4 elements per half: the degree outgrows the mesh, which is then
    bisected everywhere, and the mesh check compares with a mesh refined where marked (not a
    multiple of the uniform sizes); the reported error bounds the difference to a run 10x
    tighter on the uniform refinement (a convergence check of the estimate: same
    discretization family)."""
    h = Harvester.build(a=2.0, n=8.0)
    adapted = stationary(h, tol=1e-2, elements=8, mesh="adaptive", grid=3).stats
    tight = solve(h, "fpe", tol=1e-3, mesh="algebraic")
    assert adapted.status.value == tight.status.value == "stable"
    assert any(lv["elements"] % 8 for lv in adapted.info["history"])
    assert abs(adapted.eta - tight.eta) <= adapted.eta_err + tight.eta_err
    assert adapted.eta_err / adapted.eta <= 1e-2


def test_adapted_mesh_carries_only_what_its_longest_elements_carry() -> None:
    """Marked bisections do not raise the highest Hermite degree; a mesh the degree outgrew
    is bisected everywhere (n = 8, a = 2 on 10 elements per half adapted from 8: M = 14 is
    1.1e-3 off there)."""
    h = Harvester.build(a=2.0, n=8.0)
    w = Whitening.of(h)
    disc = AdaptiveHermiteDG(h, XMeshRule.of(h).build(h, w, 8), 3, w)
    disc.solve(8, 16)  # marks mesh 16 from a level on mesh 8
    assert disc.max_degree(16) == disc.max_degree(8) == 12
    disc.outgrown(16)
    assert disc.max_degree(32) == 24
    assert disc.mesh(32) is not None  # no level needed to bisect everything
    assert disc.summary()["32"]["half_elements"] == 2 * disc.summary()["16"]["half_elements"]


def test_adaptive_discretization_reports_its_meshes() -> None:
    h = Harvester.build(a=1.0, n=6.0)
    w = Whitening.of(h)
    disc = AdaptiveHermiteDG(h, XMeshRule.of(h).build(h, w, 4), 3, w)
    assert disc.mesh(8) is None  # nothing solved on the first mesh to mark it by
    disc.solve(4, 8)  # solves a level on the first mesh to mark the second
    assert disc.summary()["8"]["generation"] == 1
    assert 4 < disc.summary()["8"]["half_elements"] < 8
    assert disc.unknowns(4, 8) < 2 * 8 * 4 * 35
