"""The kernels' array layouts: every named slot holds what its name says, and no two names share one."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from fpe_harvester import Harvester
from montecarlo import layout
from montecarlo._kernels import MAX_SUBSTEPS
from montecarlo._kink import HOLD
from montecarlo.coefficients import linear_stiffness, physical_vector, step_coefficients
from montecarlo.layout import (CF_E, CF_G, CF_H, CF_PVX, CF_STEP, CF_SUB_E, CF_SUB_G, CF_XI_DECAY,
                               CF_XI_HALF, CF_XI_NOISE, KIND_KINK, MOMENTS, P_A, P_GAMMA, P_K, P_K3, P_K4,
                               P_KC, P_KINK_FORCE, P_KINK_RULE, P_KV, P_M, P_N, P_SIGMA, P_SIZE, P_STIFFNESS,
                               P_TAU_P, P_THRESHOLD, P_XI_VAR)

# every parameter different, so that a swapped slot shows
H = Harvester.build(a=0.7, n=1.02, N=3, k=-0.11, k4=0.013, k3=0.17, m=1.3, gamma=0.9, Kv=1.1, Kc=0.8,
                    sigma=1.2, tau=0.6, D=1.4, tau_p=2.5)


def _names(prefix: str) -> dict[str, int]:
    return {name: getattr(layout, name) for name in layout.__all__ if name.startswith(prefix)}


def test_parameter_slots_are_a_permutation_of_the_array() -> None:
    slots = {k: v for k, v in _names("P_").items() if k != "P_SIZE"}
    assert sorted(slots.values()) == list(range(P_SIZE))


def test_physical_vector_fills_each_named_slot() -> None:
    p = H.params
    pp = physical_vector(H, 123.0, "hold", kind=KIND_KINK)
    assert pp.shape == (P_SIZE,)
    expect = {P_M: p.m, P_GAMMA: p.gamma, P_KV: p.Kv, P_KC: p.Kc, P_TAU_P: p.tau_p, P_SIGMA: p.sigma,
              P_K: H.k, P_A: H.a, P_N: H.n, P_STIFFNESS: linear_stiffness(H), P_THRESHOLD: 123.0,
              P_XI_VAR: p.D / p.tau, P_KINK_RULE: HOLD, P_KINK_FORCE: H.a * H.n, P_K4: H.k4, P_K3: H.k3}
    assert set(expect) == set(range(P_SIZE))
    for slot, value in expect.items():
        assert pp[slot] == pytest.approx(value, rel=1e-15), slot


def test_coefficient_slots_do_not_overlap() -> None:
    widths = {CF_E: 9, CF_G: 3, CF_H: 1, CF_XI_DECAY: 1, CF_XI_NOISE: 1, CF_XI_HALF: 1, CF_SUB_E: 9,
              CF_SUB_G: 3, CF_PVX: 1}
    assert set(widths) == set(v for k, v in _names("CF_").items() if k != "CF_STEP")
    covered = sorted(i for start, width in widths.items() for i in range(start, start + width))
    assert covered == list(range(CF_STEP))


def test_step_coefficients_fill_each_named_slot() -> None:
    dt = 0.03
    p = H.params
    cf = step_coefficients(H, dt)
    c = linear_stiffness(H)
    A = np.array([[0.0, 1.0, 0.0, 0.0], [-c / p.m, -p.gamma, -p.Kv / p.m, 1.0 / p.m],
                  [0.0, p.Kc, -1.0 / p.tau_p, 0.0], [0.0, 0.0, 0.0, 0.0]])
    for h, e0, g0 in ((dt, CF_E, CF_G), (dt / MAX_SUBSTEPS, CF_SUB_E, CF_SUB_G)):
        E = scipy.linalg.expm(A * h)
        np.testing.assert_allclose(cf[e0:e0 + 9].reshape(3, 3), E[:3, :3], rtol=1e-13, atol=1e-16)
        np.testing.assert_allclose(cf[g0:g0 + 3], E[:3, 3], rtol=1e-13, atol=1e-18)
    assert cf[CF_H] == dt
    assert cf[CF_XI_DECAY] == pytest.approx(math.exp(-dt / p.tau), rel=1e-15)
    noise = math.sqrt(p.D / p.tau * (1 - math.exp(-2 * dt / p.tau)))
    assert cf[CF_XI_NOISE] == pytest.approx(noise, rel=1e-14)
    assert cf[CF_XI_HALF] == pytest.approx(math.exp(-dt / (2 * p.tau)), rel=1e-15)
    assert cf[CF_PVX] == 0.0


def test_moment_slots_follow_the_names() -> None:
    for name, slot in _names("M_").items():
        if name == "M_TWIN":
            assert MOMENTS[slot] == "t_V2"
        else:
            assert MOMENTS[slot] == name[2:], name
