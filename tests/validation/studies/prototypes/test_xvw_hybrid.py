"""The hybrid of the candidate kink scheme (validation.studies.prototypes.xvw_hybrid): Hermite functions in V
on the bulk's (x, v) elements, the V mesh on the trap's, exact projections between them."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester
from fpe_harvester.fpe.plane import DGLine
from validation.studies.prototypes import xvw_hybrid
from validation.studies.prototypes.xvw import BASE, assemble
from validation.studies.prototypes.xvw_mesh import XVWMesh
from validation.studies.prototypes.xvw_hybrid import VBasis, VRule, assemble_hybrid, element_frames

SCALES = (0.15, 0.078)


def _permutation(X: DGLine, Vv: DGLine, W: DGLine) -> np.ndarray:
    """Index in xvw's ordering (x, v, V) of every unknown of the element-by-element ordering."""
    p1x, p1v = X.p + 1, Vv.p + 1
    ix, iv, i, j, k = np.indices((X.elements, Vv.elements, p1x, p1v, W.size)).reshape(5, -1)
    return ((ix * p1x + i) * Vv.size + iv * p1v + j) * W.size + k


def test_with_no_bulk_element_the_hybrid_is_the_v_variant():
    h = Harvester.build(n=1, a=1)
    ms = XVWMesh(**{**BASE, "p": 1, "K": 3})
    A, B = assemble(h, ms, scales=SCALES), assemble_hybrid(h, ms, scales=SCALES)
    perm = _permutation(*A["lines"])
    for key in ("mass", "mirror"):
        assert abs(A[key][perm][:, perm] - B[key]).max() < 1e-14 * abs(A[key]).max()
    for Ta, Tb in zip(A["T"], B["T"]):
        assert abs(Ta[perm][:, perm] - Tb).max() < 1e-14 * abs(Ta).max()
    for key in ("one", "V2", "vV", "vxi", "v2"):
        assert np.array_equal(A[key][perm], B[key])


def test_hermite_functions_are_biorthogonal_and_their_split_integrals_add_up():
    b = VBasis(None, 0.3, 0.2, 7)
    mesh = VBasis(DGLine(np.array([-1.0, -0.1, 0.0, 0.1, 1.0]), 2))
    rule = VRule(np.unique(np.concatenate([np.linspace(-3.0, 3.0, 121), mesh.line.nodes])))
    assert np.allclose(rule.pair(b, b), np.eye(7), atol=1e-12)
    # the derivative of the test functions: int theta_k' psi_l = -int theta_k psi_l' (no boundary)
    f, df = rule.values(b, True)
    g, dg = rule.values(b)
    assert np.allclose((df * rule.w[:, None]).T @ g, -(f * rule.w[:, None]).T @ dg, atol=1e-12)
    for a, c in ((b, mesh), (mesh, b), (mesh, mesh)):
        t = np.array([-0.55, 0.0, 0.37, 5.0])
        lo0, lo1, tot1 = rule.split(a, c, t)
        assert np.allclose(lo0[-1], rule.pair(a, c), atol=1e-13)
        # int_{V<t} V ... from a direct rule with t as a breakpoint
        direct = VRule(np.unique(np.concatenate([rule.breaks[rule.breaks < 0.37], [0.37]])))
        ref = (direct.values(a, True)[0] * (direct.w * direct.V)[:, None]).T @ direct.values(c)[0]
        assert np.allclose(lo1[2], ref, atol=1e-13)
    # the mesh's own integrals are exact: its mass matrix
    assert np.allclose(rule.pair(mesh, mesh), mesh.line.mass().toarray(), atol=1e-15)


def test_element_frames_are_the_elements_moments_or_the_plane_fit():
    X, Vv = DGLine(np.array([0.0, 1.0, 2.0]), 1), DGLine(np.array([-1.0, 0.0, 1.0]), 1)
    rng = np.random.default_rng(1)
    x, v = rng.uniform(0.0, 2.0, 4000), rng.uniform(-1.0, 1.0, 4000)
    V = 0.5 + 0.2 * x - 0.3 * v + 0.1 * rng.standard_normal(4000)
    c, s = element_frames(Harvester.build(n=1, a=1), X, Vv, np.stack([x, v, V], axis=1), least=500)
    inside = (x > 1.0) & (v < 0.0)
    assert c[1, 0] == pytest.approx(V[inside].mean(), rel=1e-12)
    assert s[1, 0] == pytest.approx(V[inside].std(), rel=1e-9)
    # mirrored states count for x > 0; an element with too few states takes the plane fit
    c2, s2 = element_frames(Harvester.build(n=1, a=1), X, Vv, np.stack([x, v, V], axis=1), least=10**6)
    assert c2[1, 0] == pytest.approx(0.5 + 0.2 * 1.5 + 0.3 * 0.5, abs=0.01)
    assert s2[0, 0] == pytest.approx(0.1, rel=0.05)


@pytest.fixture
def fake_samples(monkeypatch):
    """Stationary-like states without a simulation (the frames only need their moments)."""
    rng = np.random.default_rng(2)
    x, v = rng.normal(0.0, 0.4, 20000), rng.normal(0.0, 0.4, 20000)
    states = np.stack([x, v, 0.5 * v + 0.05 * rng.standard_normal(20000)], axis=1)
    monkeypatch.setattr(xvw_hybrid, "_samples", lambda h: states)


@pytest.mark.parametrize("frame", ["sign", "element"])
def test_the_hybrid_conserves_mass_away_from_the_edges(fake_samples, frame):
    # the test function 1 (ones on the mesh, the first Hermite polynomial on the bulk) against
    # the transport of any function of an element that touches no edge: the fluxes cancel
    h = Harvester.build(n=1, a=1)
    ms = XVWMesh(**{**BASE, "p": 2, "K": 3, "e_split": 0.05, "kv": 5, "frame": frame})
    asm = assemble_hybrid(h, ms, scales=SCALES)
    X, Vv, _ = asm["lines"]
    bases = asm["bases"]
    assert any(b.k for b in bases) and any(not b.k for b in bases)
    off = xvw_hybrid.element_order(X, Vv, np.array([b.size for b in bases]))
    interior = [e for e in range(len(bases)) if 0 < e // Vv.elements < X.elements - 1
                and 0 < e % Vv.elements < Vv.elements - 1]
    for T in asm["T"]:
        for e in interior:
            cols = T[:, off[e]:off[e + 1]]
            flux = asm["unit"] @ cols
            assert abs(flux).max() < 1e-9 * abs(cols).max(), (e, bases[e].k)


def test_the_power_law_force_transports_a_constant_to_its_outflow():
    # n = 1.5: v faces carry the speed (-a n x^(n-1) - gamma m v - Kv V) / m; the volume terms
    # and interior faces cancel against the test function 1
    h = Harvester.build(n=1.5, a=1)
    p = h.params
    asm = assemble_hybrid(h, XVWMesh(**{**BASE, "p": 1, "K": 3}), scales=SCALES)
    X, Vv, W = asm["lines"]
    ones = np.ones(asm["mass"].shape[0])
    Lx, Lv, LV = X.nodes[-1], Vv.nodes[-1], W.nodes[-1]
    expected = (Lv**2 / 2) * 2 * LV * 2
    # x = t^2 (the force's sqrt(x) is smooth in t); in V the parts of a linear speed exactly
    t = np.linspace(0.0, np.sqrt(Lx), 20001)
    for v in (-Lv, Lv):
        A = (-h.a * h.n * t - p.gamma * p.m * v) / p.m          # speed A - B V at x = t^2
        B = p.Kv / p.m
        cut = np.clip(A / B, -LV, LV)
        below = A * (cut + LV) - B * (cut**2 - LV**2) / 2.0     # int of the speed where it is > 0
        above = B * (LV**2 - cut**2) / 2.0 - A * (LV - cut)     # minus its int where it is < 0
        expected += np.trapezoid((below if v > 0 else above) * 2.0 * t, t)
    for V in (-LV, LV):
        vs = np.linspace(-Lv, Lv, 20001)
        u = p.Kc * vs - V / p.tau_p
        expected += Lx * np.trapezoid(np.maximum(u, 0.0) if V > 0 else -np.minimum(u, 0.0), vs)
    assert ones @ (asm["T"][1] @ ones) == pytest.approx(expected, rel=1e-5)


def test_the_force_enters_the_hybrid_through_n():
    # n = 1 through the power-law path (the hybrid's Gauss points in x) equals the constant force
    h = Harvester.build(n=1, a=1)
    ms = XVWMesh(**{**BASE, "p": 1, "K": 3})
    A = assemble_hybrid(h, ms, scales=SCALES)
    B = assemble_hybrid(h.replace(n=1.0 + 1e-12), ms, scales=SCALES)
    for Ta, Tb in zip(A["T"], B["T"]):
        assert abs(Ta - Tb).max() < 1e-9 * abs(Ta).max()
