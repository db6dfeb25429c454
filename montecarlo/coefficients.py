"""What the kernels read of a problem: the on-site kind, the parameter array and the common coefficients.

The path loop advances a unit's linear part exactly and treats the on-site force -U'(x) in one of
three ways (:func:`onsite_kind`). The linear part of one unit's (x, v, V) dynamics with a force f
held over the step is

.. math::

    \\frac{d}{dt}\\begin{pmatrix}x\\\\ v\\\\ V\\end{pmatrix} =
    \\underbrace{\\begin{pmatrix}0 & 1 & 0\\\\ -c/m & -\\gamma & -K_v/m\\\\
    0 & K_c & -1/\\tau_p\\end{pmatrix}}_{A}\\begin{pmatrix}x\\\\ v\\\\ V\\end{pmatrix}
    + \\begin{pmatrix}0\\\\ 1/m\\\\ 0\\end{pmatrix} f,

with c the stiffness kept in the linear part (:func:`linear_stiffness`) and
:math:`f = \\sigma\\xi + k(x_{j-1} + x_{j+1})` (plus the k4 and k3 couplings). Its exact flow over a
step h is :math:`E = e^{Ah}` and :math:`g = \\int_0^h e^{As} b\\,ds`, both read off one 4x4 matrix
exponential (:func:`step_coefficients`). The steps (:mod:`montecarlo.steps`) append their own
coefficients; the layouts are in :mod:`montecarlo.layout`.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg

from fpe_harvester.model import Harvester

from ._kernels import MAX_SUBSTEPS
from ._kink import AVERAGE, HOLD
from .layout import (CF_E, CF_G, CF_H, CF_STEP, CF_SUB_E, CF_SUB_G, CF_XI_DECAY, CF_XI_HALF, CF_XI_NOISE,
                     KIND_KICK, KIND_KINK, KIND_LINEAR, P_A, P_GAMMA, P_K, P_K3, P_K4, P_KC, P_KINK_FORCE,
                     P_KINK_RULE, P_KV, P_M, P_N, P_SIGMA, P_SIZE, P_STIFFNESS, P_TAU_P, P_THRESHOLD,
                     P_XI_VAR)

__all__ = ["onsite_kind", "ONSITE_NAMES", "KINK_WIDTH", "KINK_RULES", "linear_stiffness", "step_coefficients",
           "physical_vector"]

#: The on-site treatments (:func:`onsite_kind`), as the solver's ``info["integrator"]`` names them.
ONSITE_NAMES = {
    KIND_LINEAR: "harmonic on-site force inside the exact linear flow",
    KIND_KICK: "Strang kicks kick(h/2) linear-flow(h) kick(h/2) of -U'(x)",
    KIND_KINK: "exact piecewise-linear flow of the kink force -a n sign(x) with located zero crossings, "
    "swings once four fit in the time left of a step advanced by the averaged map of their amplitude "
    "(w -> w exp(-gamma t/3)), and (n > 1) Strang kicks of the remainder -U'(x) + a n sign(x)",
}

#: The kink's rules for swings shorter than the step, by the value the kernels read
#: (``pp[P_KINK_RULE]``, :data:`montecarlo._kink.AVERAGE`): the number of full swings that must fit in
#: the time left of a step before their averaged map takes over. ``"average"`` (default) averages
#: swings once four full swings fit in the time left; ``"hold"`` (0) never averages: it follows them until
#: 64 crossings in one step and then holds the unit at rest (a time-step artifact, kept to compare with).
KINK_RULES = {"average": AVERAGE, "hold": HOLD}

#: Width of the kink treatment's range of n: 1 <= n <= 1 + KINK_WIDTH (see :func:`onsite_kind`).
KINK_WIDTH = 0.05


def onsite_kind(h: Harvester) -> int:
    """How the kernels treat the on-site force -U'(x) of ``h`` (:mod:`montecarlo.layout`):
    :data:`~montecarlo.layout.KIND_LINEAR` (harmonic, inside the exact linear flow),
    ``KIND_KICK`` (smooth n, Strang kicks) or ``KIND_KINK``.

    The kink treatment serves :math:`1 \\le n \\le 1 +` :data:`KINK_WIDTH`: it integrates the
    force :math:`-an\\,\\mathrm{sign}(x)` exactly (zero crossings located, swings shorter than
    the step advanced by their averaged map) and kicks only the remainder
    :math:`-U'(x) + an\\,\\mathrm{sign}(x)`, which is 0 at n = 1 and small away from
    :math:`|x| \\lesssim 2^{-1/(n-1)}` near it. Just above n = 1 the force jumps from 0 to about
    :math:`an` within an unresolvably small :math:`|x|`, and the smooth kicks would chatter
    across x = 0 like a naive scheme across the kink; beyond 1 + KINK_WIDTH the kicked remainder
    grows instead (the comparison that set the width: docs/methods.md, "The kink").
    """
    if h.is_linear:
        return KIND_LINEAR
    if h.n <= 1.0 + KINK_WIDTH:
        return KIND_KINK
    return KIND_KICK


def linear_stiffness(h: Harvester) -> float:
    """Stiffness :math:`c` kept in the exactly integrated linear part: the coupling's own-unit
    part :math:`2k + 6k_4` (of :math:`k(Lx)_j - k_4(L^2x)_j`) and, for the harmonic potential, 2a."""
    c = (2.0 * h.k + 6.0 * h.k4 if h.k4 != 0.0 else 2.0 * h.k) if h.N > 1 else 0.0
    if h.is_linear:
        c += 2.0 * h.a
    return c


def step_coefficients(h: Harvester, dt: float) -> np.ndarray:
    """The common part of the coefficient array ``cf`` of one step of size ``dt`` (length
    :data:`~montecarlo.layout.CF_STEP`, layout in :mod:`montecarlo.layout`): the exact flow of the
    linear part over the step and over the stiff walls' substep, the Ornstein--Uhlenbeck update of
    xi over the step, and xi measured half a step before its update (the frozen step's
    convention; a step that measures otherwise sets its own).

    Parameters
    ----------
    h : Harvester
        The problem.
    dt : float
        Time step, > 0 (any value relative to tau: the OU update is exact).

    Examples
    --------
    >>> from montecarlo.layout import CF_XI_DECAY
    >>> cf = step_coefficients(Harvester.build(a=0.5), 0.01)
    >>> bool(abs(cf[CF_XI_DECAY] - math.exp(-0.01)) < 1e-15)
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
    Ps = scipy.linalg.expm(M * (dt / MAX_SUBSTEPS))
    cf = np.zeros(CF_STEP)
    cf[CF_SUB_E:CF_SUB_E + 9] = Ps[:3, :3].ravel()
    cf[CF_SUB_G:CF_SUB_G + 3] = Ps[:3, 3]
    cf[CF_E:CF_E + 9] = P[:3, :3].ravel()
    cf[CF_G:CF_G + 3] = P[:3, 3]
    cf[CF_H] = dt
    cf[CF_XI_DECAY] = math.exp(-dt / p.tau)
    cf[CF_XI_NOISE] = math.sqrt(p.noise_variance * -math.expm1(-2.0 * dt / p.tau))
    cf[CF_XI_HALF] = math.exp(-0.5 * dt / p.tau)
    return cf


def physical_vector(h: Harvester, threshold: float, rule: str = "average",
                    kind: int | None = None) -> np.ndarray:
    """Parameter array ``pp`` of the kernels (layout in :mod:`montecarlo.layout`).

    ``threshold`` is the escape amplitude, ``rule`` the kink's rule for swings shorter than
    the step (a key of :data:`KINK_RULES`), ``kind`` the on-site treatment (default
    :func:`onsite_kind`).
    """
    p = h.params
    kind = onsite_kind(h) if kind is None else kind
    pp = np.zeros(P_SIZE)
    pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KC] = p.m, p.gamma, p.Kv, p.Kc
    pp[P_TAU_P], pp[P_SIGMA] = p.tau_p, p.sigma
    pp[P_A], pp[P_N] = h.a, h.n
    if h.N > 1:
        pp[P_K], pp[P_K4], pp[P_K3] = h.k, h.k4, h.k3
    pp[P_STIFFNESS] = linear_stiffness(h)
    pp[P_THRESHOLD] = threshold
    pp[P_XI_VAR] = p.noise_variance
    pp[P_KINK_RULE] = KINK_RULES[rule]
    if kind == KIND_KINK:
        pp[P_KINK_FORCE] = h.a * h.n
    return pp
