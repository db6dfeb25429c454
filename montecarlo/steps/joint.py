"""The joint step: ``K(h/2) L(h) K(h/2)`` (``step="joint"``; the harmonic and kick treatments).

L is the exact Gaussian transition of the linear part of (x, v, V, xi) including the
Ornstein--Uhlenbeck noise (mean map and noise factor from :func:`joint_chain`, four normals per
unit), K the kicks of -U'(x); the neighbours' force is a constant at their predicted midpoints,
stiff walls split a path's step into joint substeps with fresh normals (:func:`_joint_substeps`),
and v xi is measured by a conditional expectation (:func:`_d_step_joint`). The coarse level of a
Richardson pair gets the exact composition of the fine level's two noise increments, and the twin
its own factor applied to the same normals (its xi increment is the system's).

Valid at any tau relative to the step and tending to the white-noise model as tau -> 0, but it
draws four normals per unit-step instead of the frozen step's one: ``step="auto"`` takes it where
tau < :data:`JOINT_STEPS` dt, where freezing xi over a step is wrong.

Coefficients, from :data:`~montecarlo.layout.CF_STEP`: a block of :data:`JOINT_BLOCK` entries for
the step (``J_*`` offsets: the 4x4 propagator of (x, v, V, xi), row-major; its response to a unit
constant force on v; the noise factor L, increment = L z, row-major; the noise covariance of
(v, xi)), then one block per stiff-wall substep h/2^i, i = 1 .. log2(MAX_SUBSTEPS).

This module implements the stepper protocol of :mod:`montecarlo.steps` (``noise``, ``compose``,
``step``, ``advance``, ``twin_xi`` and the stepper :data:`JOINT`).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
import scipy.linalg
from numba import njit

from fpe_harvester.model import Harvester, mode_sin2

from .._kernels import MAX_SUBSTEPS, _kick, _kick_force, _reach, _ring_coupling, _stiff_amplitude, _substeps
from ..coefficients import linear_stiffness, onsite_kind, step_coefficients
from ..layout import CF_H, CF_PVX, CF_STEP, CF_XI_HALF, KIND_KICK, KIND_KINK, P_M, P_N, P_THRESHOLD
from .base import Kernels, Stepper

#: ``step="auto"`` takes the joint step where tau < JOINT_STEPS dt (dt the coarse step).
JOINT_STEPS = 10.0

# the entries of one block (module docstring)
J_P = 0
J_G = 16
J_L = 20
J_COV_VXI = 36
JOINT_BLOCK = 37
#: Blocks: the step and its stiff-wall substeps.
J_BLOCKS = 1 + int(round(math.log2(MAX_SUBSTEPS)))


class JointTag(NamedTuple):
    """numba tag selecting this module's kernels in the path loop."""

    normals: int


@njit(cache=True, nogil=True)
def _noise(cf, z, eps) -> None:
    """Joint step's noise increments eps = L z per unit; z, eps (4, N, P)."""
    _, N, P = z.shape
    o = CF_STEP + J_L
    for r in range(4):
        l0, l1, l2, l3 = cf[o + 4 * r], cf[o + 4 * r + 1], cf[o + 4 * r + 2], cf[o + 4 * r + 3]
        for j in range(N):
            for p in range(P):
                eps[r, j, p] = l0 * z[0, j, p] + l1 * z[1, j, p] + l2 * z[2, j, p] + l3 * z[3, j, p]


@njit(cache=True, nogil=True)
def _compose(cf, e1, e2, out) -> None:
    """Noise increment of two joint steps ``cf`` in a row, out = P e1 + e2: the coarse level's
    increment from the fine level's two (exact for the linear flow)."""
    _, N, P = e1.shape
    o = CF_STEP + J_P
    for r in range(4):
        p0, p1, p2, p3 = cf[o + 4 * r], cf[o + 4 * r + 1], cf[o + 4 * r + 2], cf[o + 4 * r + 3]
        for j in range(N):
            for p in range(P):
                out[r, j, p] = p0 * e1[0, j, p] + p1 * e1[1, j, p] + p2 * e1[2, j, p] + p3 * e1[3, j, p] \
                    + e2[r, j, p]


@njit(cache=True, nogil=True, inline="always")
def _joint_unit(y0, y1, y2, y3, fp, e0, e1, e2, e3, c: np.ndarray, o: int) -> tuple:
    """One unit through the joint transition whose block starts at ``c[o]`` (layout of
    :data:`montecarlo.layout.JOINT_BLOCK`): returns x, v, V, xi, the conditional mean of v xi given the
    state before (mean v times mean xi plus their noise covariance) and the mean of xi."""
    ip, ig = o + J_P, o + J_G
    mx = c[ip] * y0 + c[ip + 1] * y1 + c[ip + 2] * y2 + c[ip + 3] * y3 + c[ig] * fp
    mv = c[ip + 4] * y0 + c[ip + 5] * y1 + c[ip + 6] * y2 + c[ip + 7] * y3 + c[ig + 1] * fp
    mV = c[ip + 8] * y0 + c[ip + 9] * y1 + c[ip + 10] * y2 + c[ip + 11] * y3 + c[ig + 2] * fp
    ms = c[ip + 15] * y3
    return (mx + e0, mv + e1, mV + e2, ms + e3, mv * ms + c[o + J_COV_VXI], ms)


@njit(cache=True, nogil=True)
def _joint_flow(x, v, V, xi, f, eps, cf, rbm, rbx) -> None:
    """Exact Gaussian transition of (x, v, V, xi) under the linear drift, constant force f;
    ``rbm``, ``rbx`` as returned by :func:`_joint_unit`."""
    N, P = x.shape
    o = CF_STEP
    for j in range(N):
        for p in range(P):
            x[j, p], v[j, p], V[j, p], xi[j, p], rbm[j, p], rbx[j, p] = _joint_unit(
                x[j, p], v[j, p], V[j, p], xi[j, p], f[j, p], eps[0, j, p], eps[1, j, p], eps[2, j, p],
                eps[3, j, p], cf, o)


@njit(cache=True, nogil=True)
def _joint_substeps(x, v, V, xi, F, fext, pvx, p: int, K: int, cf: np.ndarray, pp: np.ndarray,
                    gen) -> None:
    """Path p's step as K joint substeps h/K (kick-flow-kick, neighbours' force fext held),
    with fresh normals: the step's own increment is not split, so this path leaves the common
    noise of the other level and of the twin for this step (their laws stay exact)."""
    N = x.shape[0]
    o = CF_STEP + JOINT_BLOCK * int(round(math.log2(K)))
    hk = 0.5 * cf[CF_H] / K / pp[P_M]
    e = np.empty(4)
    for j in range(N):
        xx, vv, VV, ss, FF, fp = x[j, p], v[j, p], V[j, p], xi[j, p], F[j, p], fext[j, p]
        rm = rx = 0.0
        for _ in range(K):
            z0, z1, z2, z3 = gen.standard_normal(), gen.standard_normal(), gen.standard_normal(), \
                gen.standard_normal()
            for r in range(4):
                lo = o + J_L + 4 * r
                e[r] = cf[lo] * z0 + cf[lo + 1] * z1 + cf[lo + 2] * z2 + cf[lo + 3] * z3
            vv += hk * FF
            xx, vv, VV, ss, rm, rx = _joint_unit(xx, vv, VV, ss, fp, e[0], e[1], e[2], e[3], cf, o)
            FF = _kick_force(xx, pp)
            vv += hk * FF
        x[j, p], v[j, p], V[j, p], xi[j, p], F[j, p] = xx, vv, VV, ss, FF
        pvx[j, p] = rm + hk * FF * rx


@njit(cache=True, nogil=True)
def _d_step_joint(x, v, V, xi, F, xm, fext, eps, cf, pp, kind, rbm, rbx, pvx, w, gen) -> None:
    """One whole joint step: kick(h/2), exact linear flow of (x, v, V, xi) with
    noise increment ``eps``, kick(h/2); the neighbours' force enters as a constant at their
    predicted midpoints, and stiff walls split a path's step, as in :func:`montecarlo.steps.frozen.d_step`.

    ``pvx`` receives each unit's estimate of v xi for the measurement, without the variance
    D/tau of xi itself (which made the plain product useless for tau << 1): the conditional
    mean of v xi given the state before the flow, plus the closing half kick
    :math:`(h/2m)F(x_{end})` times the conditional mean :math:`e^{-h/\\tau}\\xi` of xi given that
    state. Conditioning xi on the x reached as well would count the half kick's correlation
    with the noise of the step's last tau, :math:`-(h/2)\\tau\\sigma^2D\\langle U''\\rangle/m^2`
    in Pin, which the continuous model has at order :math:`\\tau^2` only: a bias linear in h
    for tau << h (Pin 1.9e-6 low at n = 3, tau = 1e-4, h = 0.02, where its standard error is
    5e-7), which the order-2 Richardson estimate takes for a third of itself.
    """
    N, P = x.shape
    h = cf[CF_H]
    kicks = kind == KIND_KICK
    n_stiff = 0
    xstar = math.inf
    if kicks and pp[P_N] > 2.0:
        xstar = _stiff_amplitude(pp, h)
    if xstar < pp[P_THRESHOLD]:
        for p in range(P):
            for j in range(N):
                if w[p] > 0.0 and _reach(x[j, p], v[j, p], h) > xstar:
                    n_stiff += 1
                    break
    if n_stiff > 0:
        sp = np.empty(n_stiff, dtype=np.int64)
        sk = np.empty(n_stiff, dtype=np.int64)
        s0 = np.empty((5, N, n_stiff))
        i = 0
        for p in range(P):
            if w[p] == 0.0:
                continue
            K = 1
            for j in range(N):
                K = max(K, _substeps(x[j, p], v[j, p], h, xstar, pp))
            if K > 1:
                sp[i], sk[i] = p, K
                for j in range(N):
                    s0[0, j, i], s0[1, j, i], s0[2, j, i] = x[j, p], v[j, p], V[j, p]
                    s0[3, j, i], s0[4, j, i] = xi[j, p], F[j, p]
                i += 1
        n_stiff = i
    # the kicks' update flags are runtime bools: literal True and False compiled _kick twice
    if kicks:
        _kick(x, v, F, h, pp, not kicks)
    if N > 1:
        for j in range(N):
            for p in range(P):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
        _ring_coupling(xm, fext, pp, 0, P, xi, 0.0)
    else:
        for p in range(P):
            fext[0, p] = 0.0
    _joint_flow(x, v, V, xi, fext, eps, cf, rbm, rbx)
    if kicks:
        _kick(x, v, F, h, pp, kicks)
        hk = 0.5 * h / pp[P_M]
        for j in range(N):
            for p in range(P):
                pvx[j, p] = rbm[j, p] + hk * F[j, p] * rbx[j, p]
    else:
        for j in range(N):
            for p in range(P):
                pvx[j, p] = rbm[j, p]
    for i in range(n_stiff):
        p = sp[i]
        for j in range(N):
            x[j, p], v[j, p], V[j, p] = s0[0, j, i], s0[1, j, i], s0[2, j, i]
            xi[j, p], F[j, p] = s0[3, j, i], s0[4, j, i]
        if N > 1:
            for j in range(N):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
            _ring_coupling(xm, fext, pp, p, p + 1, xi, 0.0)
        _joint_substeps(x, v, V, xi, F, fext, pvx, p, sk[i], cf, pp, gen)



@njit(cache=True, nogil=True, inline="always")
def noise(cf: np.ndarray, z: np.ndarray, buf: np.ndarray) -> None:
    """The level's increment for one step, L z (z four normals per unit), written to ``buf``."""
    _noise(cf, z, buf)


@njit(cache=True, nogil=True, inline="always")
def compose(cf_a: np.ndarray, cf_b: np.ndarray, e1: np.ndarray, e2: np.ndarray, out: np.ndarray) -> None:
    """Increment of one step ``cf_b`` from two steps ``cf_a`` in a row (:func:`_compose`)."""
    _compose(cf_a, e1, e2, out)


@njit(cache=True, nogil=True, inline="always")
def advance(xi: np.ndarray, eps: np.ndarray, cf: np.ndarray) -> None:
    """Nothing: the step already moved xi."""


@njit(cache=True, nogil=True, inline="always")
def twin_xi(xi: np.ndarray) -> np.ndarray:
    """The twin has its own xi (its transition moves xi with its own factor)."""
    return np.zeros_like(xi)


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


class JointStep(Stepper):
    """The joint step (Python side)."""

    name = "joint"
    priority = 10
    description = "(x, v, V, xi) by the exact Gaussian transition of the linear drift, kicks around it"
    preference = f"tau < {JOINT_STEPS:g} dt"
    dt_start = 0.04
    tag = JointTag(4)
    kernels = Kernels(4, noise, compose, _d_step_joint, advance, twin_xi)

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        """The common part (:func:`montecarlo.coefficients.step_coefficients`), ``v xi`` from the
        step's conditional expectation, xi measured after the step, and the step's blocks."""
        cf = np.concatenate([step_coefficients(h, dt), np.zeros(JOINT_BLOCK * J_BLOCKS)])
        cf[CF_PVX] = 1.0
        # block 0: the step; block i: the stiff walls' substep dt/2^i (only the kick treatment
        # with n > 2 takes substeps)
        blocks = J_BLOCKS if onsite_kind(h) == KIND_KICK and h.n > 2 else 1
        for i, (Pj, gj, Q) in enumerate(joint_chain(h, dt, blocks)):
            o = CF_STEP + JOINT_BLOCK * i
            cf[o + J_P:o + J_P + 16] = Pj.ravel()
            cf[o + J_G:o + J_G + 4] = gj
            cf[o + J_L:o + J_L + 16] = noise_factor(Q).ravel()
            cf[o + J_COV_VXI] = Q[1, 3]
        cf[CF_XI_HALF] = 1.0
        return cf

    def refusal(self, h: Harvester, kind: int) -> str | None:
        if kind == KIND_KINK:
            return ("the kink treatment (n near 1) needs the force held over the step, which this step's "
                    "Gaussian transition does not; the kink's short-tau step is 'averaged'")
        return None

    def preferred(self, h: Harvester, kind: int, dt: float) -> bool:
        return h.params.tau < JOINT_STEPS * dt

    def twin_matrices(self, lin: Harvester, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(x, v, V, xi) advance together: M is the propagator plus the neighbours' force at the
        predicted midpoint, Q the full noise covariance, and the state is measured after the step
        (T = I, no half-step factor)."""
        k = lin.k if lin.N > 1 else 0.0
        cq = 2.0 - 4.0 * mode_sin2(lin.N)
        P, g, Q = joint_matrices(lin, dt)
        M = np.repeat(P[None], lin.N, axis=0)
        M[:, :, 0] += (k * cq)[:, None] * g
        M[:, :, 1] += (0.5 * dt * k * cq)[:, None] * g
        return M, np.repeat(np.eye(4)[None], lin.N, axis=0), Q, 1.0


#: The joint stepper.
JOINT = JointStep()
