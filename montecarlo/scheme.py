"""Coefficients of the splitting integrator (the Python half of :mod:`montecarlo._kernels`).

Two steps: the joint step advances the linear part of (x, v, V, xi), noise included, by its
exact Gaussian transition (:func:`joint_matrices`), valid at any tau relative to the step and
taken when tau < :data:`JOINT_STEPS` dt; the frozen-xi step below holds xi over a step between
exact Ornstein--Uhlenbeck updates and needs dt well below tau (at tau = 1e-2 the solver had to
halve dt to 6e-4). The kink scheme (:func:`scheme_kind`) has only the frozen-xi step.

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

import functools
import math

import numpy as np
import scipy.linalg

from fpe_harvester.model import Harvester

from ._kernels import MAX_SUBSTEPS
from ._kink import AVERAGE, HOLD
from .layout import (CF_E, CF_G, CF_H, CF_PVX, CF_STEP, CF_SUB_E, CF_SUB_G, CF_XI_DECAY, CF_XI_HALF, CF_XI_NOISE,
                     J_BETA, J_COV_VXI, J_G, J_L, J_P, JOINT_BLOCK, KIND_KICK, KIND_KINK, KIND_LINEAR, P_A, P_GAMMA,
                     P_K, P_K3, P_K4, P_KC, P_KINK_FORCE, P_KINK_RULE, P_KV, P_M, P_N, P_SIGMA, P_SIZE,
                     P_STIFFNESS, P_TAU_P, P_THRESHOLD, P_XI_VAR)

#: Length of a coefficient array: the common part and the joint step's blocks (the step and its
#: stiff-wall substeps h/2^i, i = 1 .. log2(MAX_SUBSTEPS)).
CF_SIZE = CF_STEP + JOINT_BLOCK * (1 + 10)

__all__ = ["scheme_kind", "linear_stiffness", "step_coefficients", "physical_vector", "SCHEME_NAMES",
           "KINK_WIDTH", "KINK_RULES", "JOINT_STEPS", "uses_joint_step", "joint_step_refusal",
           "joint_matrices", "joint_chain", "noise_factor"]

SCHEME_NAMES = {
    KIND_LINEAR: "Strang O(h/2) D(h) O(h/2); D exact linear flow (harmonic on-site force)",
    KIND_KICK: "Strang O(h/2) D(h) O(h/2); D = kick(h/2) linear-flow(h) kick(h/2) for -U'(x)",
    KIND_KINK: "Strang O(h/2) D(h) O(h/2); D exact piecewise-linear flow of the kink force "
    "-a n sign(x) with located zero crossings, swings much shorter than the step advanced by the "
    "averaged map of their amplitude (w -> w exp(-gamma t/3)), and (n > 1) Strang kicks of the "
    "remainder -U'(x) + a n sign(x)",
}

#: The joint step (the exact Gaussian transition of (x, v, V, xi) under the linear drift, see
#: :func:`joint_matrices`) replaces the frozen-xi step when the noise's correlation time is
#: shorter than JOINT_STEPS coarse time steps, tau < JOINT_STEPS dt. Freezing xi over a step
#: is wrong once tau is not large against the step (at tau = 1e-4, dt = 0.02, n = 3 eta came
#: out 0.62 +- 0.26 against 0.269); the joint step is exact for the linear flow at any tau and
#: tends to the white-noise model as tau -> 0, but draws four normals per unit-step instead of
#: one, so the slow-noise case keeps the cheaper step.
JOINT_STEPS = 10.0

#: The kink scheme's rules for swings shorter than the step (:data:`montecarlo._kink.AVERAGE`):
#: ``"average"`` (default) advances them by the averaged map of their amplitude; ``"hold"``
#: follows them until 64 crossings in one step and then holds the unit at rest (a time-step
#: artifact, kept to compare with).
KINK_RULES = {"average": AVERAGE, "hold": HOLD}


#: Width of the kink scheme's range of n: 1 <= n <= 1 + KINK_WIDTH (see :func:`scheme_kind`).
KINK_WIDTH = 0.05


def scheme_kind(h: Harvester) -> int:
    """Which D-step the kernel uses: 0 harmonic (exact), 1 smooth kick, 2 kink.

    The kink scheme serves :math:`1 \\le n \\le 1 +` :data:`KINK_WIDTH`: it integrates the
    force :math:`-an\\,\\mathrm{sign}(x)` exactly (zero crossings located, the unit held at
    rest once its swings are shorter than the step) and kicks only the remainder
    :math:`-U'(x) + an\\,\\mathrm{sign}(x)`, which is 0 at n = 1 and small away from
    :math:`|x| \\lesssim 2^{-1/(n-1)}` near it. Just above n = 1 the force jumps from 0 to about
    :math:`an` within an unresolvably small :math:`|x|`, and the smooth kick scheme then
    chatters across x = 0 like a naive scheme across the kink. Measured at a = 2 on the same
    noise (eta ~ 0.12), the kick scheme minus the kink scheme at dt = 0.01, 0.005, 0.0025:
    -4.7, -2.5, -1.2 % for n = 1.0001 and -3.2, -1.5, -0.8 % for n = 1.01 (a first-order
    bias that its order-2 Richardson estimate understates), but within 0.3 % (1-2 standard
    errors) for n = 1.05, 1.1 and 1.2, where the kink scheme's kicked remainder grows
    instead (its bias estimate at n = 1.2 is 3x the kick scheme's).
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


def joint_step_refusal(h: Harvester, kind: int | None = None) -> str | None:
    """Why the joint step cannot serve ``h``, or None if it can.

    Only the harmonic and the smooth kick schemes have it: the kink scheme (n near 1) integrates
    its piecewise flow at a constant force (with xi frozen, or at short tau its step mean,
    :mod:`montecarlo.steps.averaged`).
    """
    kind = scheme_kind(h) if kind is None else kind
    if kind == KIND_KINK:
        return "the kink scheme (n near 1) integrates its piecewise flow with xi frozen"
    return None


def uses_joint_step(h: Harvester, dt: float, kind: int | None = None) -> bool:
    """Whether a run of ``h`` with coarse step ``dt`` takes the joint step by default:
    tau < :data:`JOINT_STEPS` dt, and :func:`joint_step_refusal` has no objection; for the kink
    scheme, whose frozen-xi flow needs dt <= tau, the short-tau step is the averaged-noise step
    (:mod:`montecarlo.steps.averaged`), taken when tau < dt."""
    kind = scheme_kind(h) if kind is None else kind
    if kind == KIND_KINK:
        return bool(h.params.tau < dt)
    return bool(h.params.tau < JOINT_STEPS * dt and joint_step_refusal(h, kind) is None)


def _drift_matrix(h: Harvester) -> np.ndarray:
    """Linear drift of one unit's (x, v, V, xi), with the stiffness :func:`linear_stiffness`."""
    p = h.params
    A = np.zeros((4, 4))
    A[0, 1] = 1.0
    A[1, 0] = -linear_stiffness(h) / p.m
    A[1, 1] = -p.gamma
    A[1, 2] = -p.Kv / p.m
    A[1, 3] = p.sigma / p.m
    A[2, 1] = p.Kc
    A[2, 2] = -1.0 / p.tau_p
    A[3, 3] = -1.0 / p.tau
    return A


def joint_matrices(h: Harvester, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact Gaussian transition of one unit's linear part over a step ``dt``.

    For :math:`y = (x, v, V, \\xi)` with :math:`dy = (Ay + b f)\\,dt + B\\,dW` (A of
    :func:`_drift_matrix`, :math:`b = e_v/m` the response to a constant force f,
    :math:`B = e_\\xi\\sqrt{2D}/\\tau`):

    .. math::

        y(t + h) = e^{Ah} y(t) + g f + \\varepsilon,\\qquad g = \\int_0^h e^{As}b\\,ds,\\qquad
        \\varepsilon \\sim \\mathcal N\\Big(0,\\ Q = \\int_0^h e^{As}BB^Te^{A^Ts}ds\\Big).

    Q is built by doubling, :math:`Q(2t) = Q(t) + e^{At}Q(t)e^{A^Tt}`, from a step so short
    that Van Loan's exponential is exact to round-off (his formula over the whole step
    overflows for tau << h, where :math:`e^{-Ah}` holds :math:`e^{h/\\tau}`).

    Returns
    -------
    P : ndarray (4, 4)
        :math:`e^{Ah}`.
    g : ndarray (4,)
        Response to a unit constant force on v.
    Q : ndarray (4, 4)
        Covariance of the noise increment.
    """
    return joint_chain(h, dt, 1)[0]


@functools.lru_cache(maxsize=64)
def joint_chain(h: Harvester, dt: float, count: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]:
    """:func:`joint_matrices` at the steps ``dt / 2^i``, i = 0 .. count - 1, in one doubling pass.

    From a step t0 with :math:`\\|A\\|t_0 \\le 10^{-3}` (Van Loan's exponential of the
    augmented drift, exact to round-off there), each doubling is
    :math:`P(2t) = P(t)^2`, :math:`g(2t) = P(t)g(t) + g(t)`,
    :math:`Q(2t) = Q(t) + P(t)Q(t)P(t)^T`: scaling and squaring, which keeps every term a sum
    of positive parts (Q) at any tau. Cached (a solve asks for the same steps several times;
    the arrays are read-only).
    """
    p = h.params
    A = _drift_matrix(h)
    norm = float(np.abs(A).sum(axis=1).max())
    levels = max(count - 1, math.ceil(math.log2(max(norm * dt, 1e-300) / 1e-3)))
    t = dt / 2.0**levels
    aug = np.zeros((5, 5))
    aug[:4, :4] = A * t
    aug[1, 4] = t / p.m
    E = scipy.linalg.expm(aug)
    F = scipy.linalg.expm(_van_loan_block(A, 2.0 * p.D / p.tau**2, t))
    P, g = E[:4, :4], E[:4, 4]
    Q = F[4:, 4:].T @ F[:4, 4:]
    out = []
    for i in range(levels, -1, -1):
        if i == 0:
            # the step itself from one exponential: each squaring adds a relative error of
            # order 1e-16 (2^30 of them at tau = 1e-8 made the twin's V2 3e-6 off)
            aug[:4, :4] = A * dt
            aug[1, 4] = dt / p.m
            E = scipy.linalg.expm(aug)
            P, g = E[:4, :4], E[:4, 4]
        if i < count:
            entry = (P.copy(), g.copy(), 0.5 * (Q + Q.T))
            for arr in entry:
                arr.flags.writeable = False
            out.append(entry)
        if i > 0:
            Q = Q + P @ Q @ P.T
            g = P @ g + g
            P = P @ P
    return tuple(out[::-1])


def _van_loan_block(A: np.ndarray, q: float, t: float) -> np.ndarray:
    """Van Loan's 8x8 matrix :math:`[[-A, BB^T], [0, A^T]]\\,t` with :math:`BB^T = q\\,e_\\xi e_\\xi^T`."""
    C = np.zeros((8, 8))
    C[:4, :4] = -A * t
    C[3, 7] = q * t
    C[4:, 4:] = A.T * t
    return C


def noise_factor(Q: np.ndarray) -> np.ndarray:
    """Factor L with :math:`LL^T = Q` whose first column alone drives xi (row 3).

    Column 0 is :math:`Q_{\\cdot\\xi}/\\sqrt{Q_{\\xi\\xi}}`, so the xi increment is the same
    multiple of the first normal for every unit with the same tau and D (the harmonic twin
    shares it); columns 1-3 factor the conditional covariance of (x, v, V) given the xi
    increment by its symmetric square root (it is near-singular at short steps, where a
    Cholesky factorization breaks down; its round-off negative eigenvalues are cut to 0).
    """
    L = np.zeros((4, 4))
    L[:, 0] = Q[:, 3] / math.sqrt(Q[3, 3])
    S = Q[:3, :3] - np.outer(L[:3, 0], L[:3, 0])
    w, U = np.linalg.eigh(0.5 * (S + S.T))
    L[:3, 1:] = U @ np.diag(np.sqrt(np.maximum(w, 0.0))) @ U.T
    return L


def step_coefficients(h: Harvester, dt: float, joint: bool = False) -> np.ndarray:
    """Coefficient array ``cf`` of one step of size ``dt`` (layout in :mod:`montecarlo.layout`).

    Parameters
    ----------
    h : Harvester
        The problem.
    dt : float
        Time step, > 0 (any value relative to tau: the OU update is exact).
    joint : bool
        Also fill the joint step's entries (:func:`joint_matrices`) and select it.

    Examples
    --------
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
    cf = np.zeros(CF_SIZE)
    cf[CF_SUB_E:CF_SUB_E + 9] = Ps[:3, :3].ravel()
    cf[CF_SUB_G:CF_SUB_G + 3] = Ps[:3, 3]
    cf[CF_E:CF_E + 9] = P[:3, :3].ravel()
    cf[CF_G:CF_G + 3] = P[:3, 3]
    cf[CF_H] = dt
    cf[CF_XI_DECAY] = math.exp(-dt / p.tau)
    cf[CF_XI_NOISE] = math.sqrt(p.noise_variance * -math.expm1(-2.0 * dt / p.tau))
    cf[CF_XI_HALF] = math.exp(-0.5 * dt / p.tau)
    if joint:
        cf[CF_PVX] = 1.0
        # block 0: the step; block i: the stiff walls' substep dt/2^i (only the kick scheme
        # with n > 2 takes substeps)
        blocks = 1 + (int(round(math.log2(MAX_SUBSTEPS))) if scheme_kind(h) == KIND_KICK and h.n > 2 else 0)
        for i, (Pj, gj, Q) in enumerate(joint_chain(h, dt, blocks)):
            o = CF_STEP + JOINT_BLOCK * i
            cf[o + J_P:o + J_P + 16] = Pj.ravel()
            cf[o + J_G:o + J_G + 4] = gj
            cf[o + J_L:o + J_L + 16] = noise_factor(Q).ravel()
            cf[o + J_COV_VXI] = Q[1, 3]
            cf[o + J_BETA] = Q[0, 3] / Q[0, 0] if Q[0, 0] > 0.0 else 0.0
        # the measured xi is the one after the step: no half-step factor
        cf[CF_XI_HALF] = 1.0
    return cf


def physical_vector(h: Harvester, threshold: float, rule: str = "average",
                    kind: int | None = None) -> np.ndarray:
    """Parameter array ``pp`` of the kernels (layout in :mod:`montecarlo.layout`).

    ``threshold`` is the escape amplitude, ``rule`` the kink's rule for swings shorter than
    the step (a key of :data:`KINK_RULES`), ``kind`` the scheme (default :func:`scheme_kind`).
    """
    p = h.params
    kind = scheme_kind(h) if kind is None else kind
    pp = np.zeros(P_SIZE)
    pp[P_M], pp[P_GAMMA], pp[P_KV], pp[P_KC], pp[P_TAU_P], pp[P_SIGMA] = p.m, p.gamma, p.Kv, p.Kc, p.tau_p, p.sigma
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
