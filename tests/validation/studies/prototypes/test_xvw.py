"""The candidate kink discretization of validation.studies.prototypes.xvw: its xi-mode algebra and one level."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fpe_harvester import Harvester
from validation.studies.prototypes.xvw import BASE, assemble, solve_xvw
from validation.studies.prototypes.xvw_mesh import XVWMesh, xi_modes


def test_xi_modes_are_gauss_hermite_nodes_with_the_ou_generator_and_parity():
    h = Harvester.build(n=1, a=2).replace(params=Harvester.build(n=1, a=2).params.replace(D=2.0, tau=0.5))
    lam, R, gen, parity = xi_modes(h, 5)
    s = math.sqrt(2.0 / 0.5)
    nodes = np.polynomial.hermite_e.hermegauss(5)[0]
    assert np.allclose(np.sort(lam), s * nodes)
    assert np.allclose(np.sort(np.linalg.eigvalsh(0.5 * (gen + gen.T))), -np.arange(5)[::-1] / 0.5)
    # the parity maps the node lambda to -lambda (a signed permutation)
    assert np.allclose(np.abs(parity) @ lam, -lam)
    assert np.allclose(parity @ parity, np.eye(5))


def test_the_transport_of_a_constant_is_its_outflow():
    # test function 1 summed: the volume terms cancel the interior faces; what is left is the flux
    # through the outer boundary and x = 0 (here without the mirror's inflow)
    h = Harvester.build(n=1, a=1)
    ms = XVWMesh(**{**BASE, "p": 1, "K": 3})
    asm = assemble(h, ms, scales=(0.15, 0.078))
    X, Vv, W = asm["lines"]
    ones = np.ones(asm["mass"].shape[0])
    flux = ones @ (asm["T"][1] @ ones)
    Lx, Lv, LV = X.nodes[-1], Vv.nodes[-1], W.nodes[-1]
    p = h.params
    # x = Lx: int v+ ; x = 0: - int v- (outflow where v < 0), over v and V
    expected = (Lv**2 / 2) * 2 * LV + (Lv**2 / 2) * 2 * LV
    # v = +-Lv: speed (-a + sigma lambda_1 - gamma m v - Kv V) / m with lambda_1 = 0 (middle node)
    for v in (-Lv, Lv):
        speed = lambda V: (-h.a - p.gamma * p.m * v - p.Kv * V) / p.m  # noqa: E731
        Vs = np.linspace(-LV, LV, 20001)
        u = speed(Vs)
        part = np.maximum(u, 0.0) if v > 0 else -np.minimum(u, 0.0)
        expected += Lx * np.trapezoid(part, Vs)
    # V = +-LV: speed Kc v - V / tau_p
    for V in (-LV, LV):
        vs = np.linspace(-Lv, Lv, 20001)
        u = p.Kc * vs - V / p.tau_p
        part = np.maximum(u, 0.0) if V > 0 else -np.minimum(u, 0.0)
        expected += Lx * np.trapezoid(part, vs)
    assert flux == pytest.approx(expected, rel=1e-6)


@pytest.mark.slow
def test_one_level_at_a_half_is_near_scheme_xv():
    res = solve_xvw(Harvester.build(n=1, a=0.5), XVWMesh(**{**BASE, "p": 2, "K": 5}))
    # scheme xv: 0.6103035 +- 4e-5; this coarse level (43200 unknowns) measured 0.5932
    assert abs(res.eta - 0.6103) < 0.03 and abs(res.residuals["V2"]) < 0.01


def test_the_w_variant_is_the_v_variant_without_the_charging_coupling():
    # W = V - Kc x: with Kc -> 0 the two discretizations are the same matrices
    h = Harvester.build(n=1, a=1)
    h = h.replace(params=h.params.replace(Kc=1e-12))
    ms = XVWMesh(**{**BASE, "p": 1, "K": 3})
    A = assemble(h, ms, scales=(0.15, 0.078))
    B = assemble(h, dataclasses.replace(ms, variant="W"), scales=(0.15, 0.078))
    for Ta, Tb in zip(A["T"], B["T"]):
        assert abs(Ta - Tb).max() < 1e-9 * abs(Ta).max()


def test_the_w_variant_transports_a_constant_to_its_outflow():
    # v faces: speed (-a - gamma m v - Kv (W + Kc x)) / m, W faces: -(W + Kc x) / tau_p
    h = Harvester.build(n=1, a=1)
    p = h.params
    asm = assemble(h, XVWMesh(**{**BASE, "p": 1, "K": 3, "variant": "W"}), scales=(0.15, 0.078))
    X, Vv, W = asm["lines"]
    ones = np.ones(asm["mass"].shape[0])
    Lx, Lv, LW = X.nodes[-1], Vv.nodes[-1], W.nodes[-1]
    expected = Lv**2 * 2 * LW
    xs, ws, vs = np.linspace(0, Lx, 2001), np.linspace(-LW, LW, 2001), np.linspace(-Lv, Lv, 2001)
    XX, WW = np.meshgrid(xs, ws, indexing="ij")
    for v in (-Lv, Lv):
        u = (-h.a - p.gamma * p.m * v - p.Kv * (WW + p.Kc * XX)) / p.m
        part = np.maximum(u, 0.0) if v > 0 else -np.minimum(u, 0.0)
        expected += np.trapezoid(np.trapezoid(part, ws, axis=1), xs)
    XX, VV = np.meshgrid(xs, vs, indexing="ij")
    for w in (-LW, LW):
        u = -(w + p.Kc * XX) / p.tau_p + 0.0 * VV
        part = np.maximum(u, 0.0) if w > 0 else -np.minimum(u, 0.0)
        expected += np.trapezoid(np.trapezoid(part, vs, axis=1), xs)
    assert ones @ (asm["T"][1] @ ones) == pytest.approx(expected, rel=1e-5)
