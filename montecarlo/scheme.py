"""Coefficients of the splitting integrator (the Python half of :mod:`montecarlo._kernels`).

The linear part of one unit's (x, v, V) dynamics with xi frozen is

.. math::

    \\frac{d}{dt}\\begin{pmatrix}x\\\\ v\\\\ V\\end{pmatrix} =
    \\underbrace{\\begin{pmatrix}0 & 1 & 0\\\\ -c/m & -\\gamma & -K_v/m\\\\
    0 & K_c & -1/\\tau_p\\end{pmatrix}}_{A}\\begin{pmatrix}x\\\\ v\\\\ V\\end{pmatrix}
    + \\begin{pmatrix}0\\\\ 1/m\\\\ 0\\end{pmatrix} f,

with :math:`c = 2k` (the coupling's on-site part, N > 1) plus :math:`2a` when the potential
is harmonic, and :math:`f = \\sigma\\xi + k(x_{j-1} + x_{j+1})` held constant over the step.
Its exact flow over a step h is :math:`E = e^{Ah}` and
:math:`g = \\int_0^h e^{As} b\\,ds`, both read off one 4x4 matrix exponential.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from fpe_harvester.model import Harvester

from ._kernels import KIND_KICK, KIND_KINK, KIND_LINEAR, SNAP

__all__ = ["scheme_kind", "linear_stiffness", "step_coefficients", "physical_vector", "SCHEME_NAMES"]

SCHEME_NAMES = {
    KIND_LINEAR: "Strang O(h/2) D(h) O(h/2); D exact linear flow (harmonic on-site force)",
    KIND_KICK: "Strang O(h/2) D(h) O(h/2); D = kick(h/2) linear-flow(h) kick(h/2) for -U'(x)",
    KIND_KINK: "Strang O(h/2) D(h) O(h/2); D exact piecewise-linear flow with located zero "
    "crossings and Filippov sticking (n = 1)",
}


def scheme_kind(h: Harvester) -> int:
    """Which D-step the kernel uses: 0 harmonic (exact), 1 smooth kick, 2 kink (n = 1)."""
    if h.is_linear:
        return KIND_LINEAR
    if h.n == 1.0:
        return KIND_KINK
    return KIND_KICK


def linear_stiffness(h: Harvester) -> float:
    """Stiffness :math:`c` kept in the exactly integrated linear part."""
    c = 2.0 * h.k if h.N > 1 else 0.0
    if h.is_linear:
        c += 2.0 * h.a
    return c


def step_coefficients(h: Harvester, dt: float) -> np.ndarray:
    """Coefficient array ``cf`` of one step of size ``dt`` (layout in :mod:`montecarlo._kernels`).

    Parameters
    ----------
    h : Harvester
        The problem.
    dt : float
        Time step, > 0 (any value relative to tau: the OU update is exact).

    Examples
    --------
    >>> cf = step_coefficients(Harvester.build(a=0.5), 0.01)
    >>> bool(abs(cf[13] - math.exp(-0.01)) < 1e-15)
    True
    """
    p = h.params
    c = linear_stiffness(h)
    M = np.zeros((4, 4))
    M[0, 1] = 1.0
    M[1, 0] = -c / p.m
    M[1, 1] = -p.gamma
    M[1, 2] = -p.Kv / p.m
    M[2, 1] = p.Kc
    M[2, 2] = -1.0 / p.tau_p
    M[1, 3] = 1.0 / p.m
    P = scipy.linalg.expm(M * dt)
    cf = np.zeros(16)
    cf[0:9] = P[:3, :3].ravel()
    cf[9:12] = P[:3, 3]
    cf[12] = dt
    cf[13] = math.exp(-dt / p.tau)
    cf[14] = math.sqrt(p.noise_variance * -math.expm1(-2.0 * dt / p.tau))
    cf[15] = math.exp(-0.5 * dt / p.tau)
    return cf


def physical_vector(h: Harvester, threshold: float, snap: float = SNAP) -> np.ndarray:
    """Parameter array ``pp`` of the kernels; ``threshold`` is the escape amplitude, ``snap``
    the kink's sticking rule (:data:`montecarlo._kernels.SNAP`)."""
    p = h.params
    return np.array(
        [p.m, p.gamma, p.Kv, p.Kc, p.tau_p, p.sigma, h.k if h.N > 1 else 0.0, h.a, h.n,
         linear_stiffness(h), threshold, p.noise_variance, snap],
        dtype=float,
    )
