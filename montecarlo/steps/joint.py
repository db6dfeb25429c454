"""The joint step: ``K(h/2) L(h) K(h/2)`` (the default when tau < 10 dt; harmonic and kick schemes).

L is the exact Gaussian transition of the linear part of (x, v, V, xi) including the
Ornstein--Uhlenbeck noise (mean map and noise factor from :func:`montecarlo.scheme.joint_chain`,
four normals per unit), K the kicks of -U'(x); the neighbours' force is a constant at their
predicted midpoints, stiff walls split a path's step into joint substeps with fresh normals
(:func:`_joint_substeps`), and v xi is measured by its conditional expectation. The coarse level
of a Richardson pair gets the exact composition of the fine level's two noise increments, and
the twin its own factor applied to the same normals (its xi increment is the system's).

This module implements the step protocol of :mod:`montecarlo.steps` (``noise``, ``compose``,
``step``, ``advance``, ``twin_xi`` and the scheme object :data:`JOINT`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from fpe_harvester.model import Harvester

from .._kernels import _kick, _kick_force, _reach, _ring_coupling, _stiff_amplitude, _substeps
from ..layout import (CF_H, CF_STEP, J_BETA, J_COV_VXI, J_G, J_L, J_P, JOINT_BLOCK, KIND_KICK, P_M, P_N,
                      P_THRESHOLD)
from ..scheme import joint_step_refusal, step_coefficients
from .base import Kernels, StepScheme


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
    state before (mean v times mean xi plus their noise covariance) and the mean of xi minus
    the regression coefficient times the mean of x."""
    ip, ig = o + J_P, o + J_G
    mx = c[ip] * y0 + c[ip + 1] * y1 + c[ip + 2] * y2 + c[ip + 3] * y3 + c[ig] * fp
    mv = c[ip + 4] * y0 + c[ip + 5] * y1 + c[ip + 6] * y2 + c[ip + 7] * y3 + c[ig + 1] * fp
    mV = c[ip + 8] * y0 + c[ip + 9] * y1 + c[ip + 10] * y2 + c[ip + 11] * y3 + c[ig + 2] * fp
    ms = c[ip + 15] * y3
    return (mx + e0, mv + e1, mV + e2, ms + e3, mv * ms + c[o + J_COV_VXI], ms - c[o + J_BETA] * mx)


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
    beta = cf[o + J_BETA]
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
        pvx[j, p] = rm + hk * FF * (rx + beta * xx)


@njit(cache=True, nogil=True)
def _d_step_joint(x, v, V, xi, F, xm, fext, eps, cf, pp, kind, rbm, rbx, pvx, w, gen) -> None:
    """One whole step of the joint scheme: kick(h/2), exact linear flow of (x, v, V, xi) with
    noise increment ``eps``, kick(h/2); the neighbours' force enters as a constant at their
    predicted midpoints, and stiff walls split a path's step, as in :func:`montecarlo.steps.frozen._d_step`.

    ``pvx`` receives each unit's estimate of v xi for the measurement: its conditional
    expectation given the state before the flow and the x reached (the same mean as v xi,
    without the variance D/tau of xi itself, which made the plain product useless for
    tau << 1).
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
        beta = cf[CF_STEP + J_BETA]
        for j in range(N):
            for p in range(P):
                pvx[j, p] = rbm[j, p] + hk * F[j, p] * (rbx[j, p] + beta * x[j, p])
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


class JointStep(StepScheme):
    """The joint step (Python side)."""

    name = "joint"
    tag = JointTag(4)
    kernels = Kernels(4, noise, compose, _d_step_joint, advance, twin_xi)

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        return step_coefficients(h, dt, joint=True)

    def refusal(self, h: Harvester, kind: int) -> str | None:
        return joint_step_refusal(h, kind)


#: The joint step scheme.
JOINT = JointStep()
