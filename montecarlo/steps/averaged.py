"""The kink's averaged-noise step: the frozen-xi flow driven by the step's mean of xi.

The kink treatment (n near 1, :mod:`montecarlo._kink`) integrates the piecewise-linear flow of
(x, v, V) under a force that is constant over the step, locating the zero crossings. Holding xi
at its start value is right only for tau >> dt; for tau << dt the force noise is nearly white
and xi decorrelates within the step. This step drives the same flow with the step's mean
:math:`\\bar\\xi = I/h` of the Ornstein--Uhlenbeck path, :math:`I = \\int_t^{t+h}\\xi\\,ds`, drawn
exactly together with the end value :math:`\\xi(t+h)` given :math:`\\xi(t)`:

.. math::

    \\xi(t+h) = e\\,\\xi(t) + \\eta_\\xi,\\qquad I = \\tau(1 - e)\\,\\xi(t) + \\eta_I,\\qquad e = e^{-h/\\tau},

    \\mathrm{Var}\\,\\eta_\\xi = s^2(1 - e^2),\\quad \\mathrm{Cov} = s^2\\tau(1 - e)^2,\\quad
    \\mathrm{Var}\\,\\eta_I = s^2\\tau^2(2h/\\tau - 3 + 4e - e^2),

:math:`s^2 = D/\\tau`. The velocity's impulse :math:`\\sigma I/m` over the step is then exact in law
at every h/tau (white noise for tau << h: variance :math:`2\\sigma^2Dh/m^2`); only its spread
within the step is approximated (a time-step error, estimated by the Richardson levels, whose
coarse noise is the exact composition of two fine steps'). xi is measured at the end of the
step, and ``v xi`` is measured by its conditional expectation given the step's draws that move
v, :math:`v\\,E[\\xi(t+h)\\,|\\,\\xi(t), \\eta_I] = v\\,(e\\,\\xi(t) + (\\mathrm{Cov}/\\mathrm{Var}\\,\\eta_I)\\,\\eta_I)`
(``pvx``, ``cf[CF_PVX] = 1``): the same mean, without the variance :math:`s^2 = D/\\tau` of xi
itself, which at short tau swamps the plain product's. Spreading the impulse over the step moves v
by :math:`g_v/h` per unit force instead of the :math:`1/m` of the noise at the step's end, with
which xi(t+h) is correlated: the constant :math:`\\sigma\\,\\mathrm{Cov}\\,(1/m - g_v/h)` restores the
continuous-time correlation for tau << h (without it Pin comes out low while
:math:`m\\gamma\\langle v^2\\rangle` is right; docs/methods.md, "The kink"). The harmonic twin's
exact means are those of the frozen and joint steps, so this step runs without a twin.

It is measured correct for tau <= :data:`AVERAGED_MAX_TAU` and refuses longer tau; between that
and the frozen step's range (dt <= tau) ``step="auto"`` finds no step and says so.

``cf`` is the common part (:func:`montecarlo.coefficients.step_coefficients`) with, from
:data:`~montecarlo.layout.CF_STEP`: ``e`` (:data:`A_DECAY`), ``tau (1 - e)`` (:data:`A_MEAN`), the
factor ``L11, L21, L22`` of :math:`(\\eta_\\xi, \\eta_I)` (:data:`A_L11`, :data:`A_L21`, :data:`A_L22`),
``Cov / Var eta_I`` (:data:`A_REG`) and the constant of ``pvx`` (:data:`A_PVX`); ``cf[CF_PVX] = 1``
(``v xi`` from ``pvx``) and ``cf[CF_XI_HALF] = 1`` (xi measured at the end of the step).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from fpe_harvester.model import Harvester

from ..coefficients import step_coefficients
from ..layout import CF_G, CF_H, CF_PVX, CF_STEP, CF_XI_HALF, KIND_KINK
from .base import Kernels, Stepper
from .frozen import d_step
# like the joint step, this one moves xi itself: nothing to advance after the measurement, and
# a twin (never run with this step) would need its own xi
from .joint import advance, twin_xi

#: Largest tau at which this step is measured correct (the white-noise Boltzmann bond law of
#: n = 1 rings of two at K_v = 0, tests/montecarlo/test_coupling.py); it refuses longer tau.
AVERAGED_MAX_TAU = 1e-4

# the step's own entries, from CF_STEP (module docstring)
A_DECAY = 0
A_MEAN = 1
A_L11 = 2
A_L21 = 3
A_L22 = 4
A_REG = 5
A_PVX = 6
A_SIZE = 7


class AveragedTag(NamedTuple):
    """numba tag selecting this module's kernels in the path loop."""

    normals: int


def innovation_covariance(h: float, tau: float, D: float) -> tuple[float, float, float]:
    """``(Var eta_xi, Cov, Var eta_I)`` of one step h (module docstring), without cancellation at
    h << tau (series of :math:`2x - 3 + 4e^{-x} - e^{-2x} = 2x^3/3 - x^4/2 + 7x^5/30 - \\dots`)."""
    x = h / tau
    s2 = D / tau
    em1 = math.expm1(-x)
    f = 2.0 * x + 4.0 * em1 - math.expm1(-2.0 * x) if x > 1e-2 else x**3 * (2.0 / 3.0 - x / 2.0 + 7.0 * x * x / 30.0)
    return -s2 * math.expm1(-2.0 * x), s2 * tau * em1 * em1, s2 * tau * tau * f


@njit(cache=True, nogil=True, inline="always")
def noise(cf: np.ndarray, z: np.ndarray, buf: np.ndarray) -> None:
    """The innovations (eta_xi, eta_I) of one step from two normals per unit."""
    _, N, P = z.shape
    for j in range(N):
        for p in range(P):
            buf[0, j, p] = cf[CF_STEP + A_L11] * z[0, j, p]
            buf[1, j, p] = cf[CF_STEP + A_L21] * z[0, j, p] + cf[CF_STEP + A_L22] * z[1, j, p]


@njit(cache=True, nogil=True, inline="always")
def compose(cf_a: np.ndarray, cf_b: np.ndarray, e1: np.ndarray, e2: np.ndarray, out: np.ndarray) -> None:
    """Innovations of one step 2h from two steps h in a row, exact: the end value's
    :math:`e\\,\\eta_{\\xi,1} + \\eta_{\\xi,2}` and the integral's
    :math:`\\eta_{I,1} + \\tau(1 - e)\\eta_{\\xi,1} + \\eta_{I,2}`."""
    e, b = cf_a[CF_STEP + A_DECAY], cf_a[CF_STEP + A_MEAN]
    _, N, P = e1.shape
    for j in range(N):
        for p in range(P):
            out[0, j, p] = e * e1[0, j, p] + e2[0, j, p]
            out[1, j, p] = e1[1, j, p] + b * e1[0, j, p] + e2[1, j, p]


@njit(cache=True, nogil=True)
def step(x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters) -> None:
    """The frozen step's flow at the step's mean of xi (held in the scratch ``rbm``), then xi
    moved to its end value and ``pvx`` set to v times its conditional mean (module docstring)."""
    N, P = x.shape
    e, b, h, r = cf[CF_STEP + A_DECAY], cf[CF_STEP + A_MEAN], cf[CF_H], cf[CF_STEP + A_REG]
    for j in range(N):
        for p in range(P):
            rbm[j, p] = (b * xi[j, p] + eps[1, j, p]) / h
            rbx[j, p] = e * xi[j, p] + r * eps[1, j, p]
    d_step(x, v, V, rbm, F, stuck, xm, fext, w, cf, pp, kind, counters, cs)
    for j in range(N):
        for p in range(P):
            xi[j, p] = e * xi[j, p] + eps[0, j, p]
            pvx[j, p] = v[j, p] * rbx[j, p] + cf[CF_STEP + A_PVX]


class AveragedStep(Stepper):
    """The kink's averaged-noise step (Python side)."""

    name = "averaged"
    priority = 10
    description = ("the kink's piecewise flow driven by the step's exact mean of xi, drawn with xi's end "
                   "value")
    preference = "tau < dt"
    dt_start = 0.04
    twin = False
    tag = AveragedTag(2)
    kernels = Kernels(2, noise, compose, step, advance, twin_xi)

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        cf = np.concatenate([step_coefficients(h, dt), np.zeros(A_SIZE)])
        p = h.params
        var_xi, cov, var_i = innovation_covariance(dt, p.tau, p.D)
        l11 = math.sqrt(var_xi)
        own = np.zeros(A_SIZE)
        own[A_DECAY] = math.exp(-dt / p.tau)
        own[A_MEAN] = -p.tau * math.expm1(-dt / p.tau)
        own[A_L11], own[A_L21] = l11, cov / l11
        own[A_L22] = math.sqrt(max(var_i - cov * cov / var_xi, 0.0))
        own[A_REG] = cov / var_i
        # the velocity's response to a constant force over the step is g_v = cf[CF_G + 1]
        own[A_PVX] = p.sigma * cov * (1.0 / p.m - cf[CF_G + 1] / dt)
        cf[CF_STEP:CF_STEP + A_SIZE] = own
        cf[CF_PVX] = 1.0
        cf[CF_XI_HALF] = 1.0
        return cf

    def refusal(self, h: Harvester, kind: int) -> str | None:
        if kind != KIND_KINK:
            return "the averaged-noise step serves the kink treatment (n near 1) only"
        if h.params.tau > AVERAGED_MAX_TAU:
            return (f"the averaged-noise step is measured only for tau <= {AVERAGED_MAX_TAU:g} (the "
                    f"white-noise Boltzmann law of kink rings at K_v = 0), got tau = {h.params.tau:g}; the "
                    f"frozen step serves the kink with dt <= tau")
        return None

    def preferred(self, h: Harvester, kind: int, dt: float) -> bool:
        return h.params.tau < dt


#: The kink's averaged-noise stepper.
AVERAGED = AveragedStep()
