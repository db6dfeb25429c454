"""The frozen-xi step: Strang splitting ``O(h/2) D(h) O(h/2)`` (``step="frozen"``).

The generator splits into the exact Ornstein--Uhlenbeck flow ``O`` of xi and the deterministic
flow ``D`` of (x, v, V) with xi frozen; consecutive half steps of ``O`` merge, so the loop runs
``D(h) O(h)`` and measures after ``D`` (xi-dependent observables get the exact half-step factor
``e^{-h/2tau}``, ``cf[CF_XI_HALF]``). Inside ``D`` the neighbours' positions enter as a constant force
evaluated at the predicted midpoint; the on-site force is either part of the exact linear flow
(n = 2), a Strang kick around it (smooth n; where a steep wall makes :math:`h^2U''/m` large the
step of that path is split into substeps, :data:`montecarlo._kernels.STIFF_LIMIT`), or, for the
kink, its part :math:`-an\\,\\mathrm{sign}(x)` is handled by the exact piecewise-linear flow of
:mod:`montecarlo._kink` and the remainder by Strang kicks. One normal per unit and step; the
coarse level of a Richardson pair takes the exact composition of the fine level's two.

This module implements the stepper protocol of :mod:`montecarlo.steps` (``noise``, ``compose``,
``step``, ``advance``, ``twin_xi`` and the stepper :data:`FROZEN`). It serves every on-site
treatment at any tau; ``step="auto"`` takes it where the joint step (smooth forces, short tau) or
the averaged step (the kink, short tau) is not preferred.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from fpe_harvester.model import Harvester, mode_sin2

from .._kernels import (MAX_SUBSTEPS, _kick, _kick_force, _kick_inline, _near_wall, _neighbour_force, _reach,
                        _ring_coupling, _stiff_amplitude, _substeps)
from .._kink import N_TAYLOR, _kink_flow
from ..coefficients import step_coefficients
from ..layout import (CF_E, CF_G, CF_H, CF_SUB_E, CF_SUB_G, CF_XI_DECAY, CF_XI_HALF, CF_XI_NOISE, KIND_KICK,
                      KIND_KINK, P_M, P_N, P_SIGMA, P_THRESHOLD)
from .base import Kernels, Stepper


__all__ = ["FROZEN", "FrozenStep", "d_step", "N_TAYLOR"]


class FrozenTag(NamedTuple):
    """numba tag selecting this module's kernels in the path loop."""

    normals: int


@njit(cache=True, nogil=True, inline="always")
def _linear_flow_inline(x, v, V, f, cf) -> None:
    """Exact linear flow of (x, v, V) over the step with constant force f; arrays (N, P)."""
    N, P = x.shape
    for j in range(N):
        for p in range(P):
            x0, v0, V0, fp = x[j, p], v[j, p], V[j, p], f[j, p]
            x[j, p] = cf[CF_E] * x0 + cf[CF_E + 1] * v0 + cf[CF_E + 2] * V0 + cf[CF_G] * fp
            v[j, p] = cf[CF_E + 3] * x0 + cf[CF_E + 4] * v0 + cf[CF_E + 5] * V0 + cf[CF_G + 1] * fp
            V[j, p] = cf[CF_E + 6] * x0 + cf[CF_E + 7] * v0 + cf[CF_E + 8] * V0 + cf[CF_G + 2] * fp


#: :func:`_linear_flow_inline` as an ordinary call, for :func:`d_step`.
_linear_flow = njit(cache=True, nogil=True)(_linear_flow_inline.py_func)


@njit(cache=True, nogil=True)
def _substep_path(x, v, V, F, fext, p: int, K: int, cf: np.ndarray, pp: np.ndarray) -> None:
    """Kick-drift-kick of path p as K substeps h/K (neighbours' force fext held)."""
    N = x.shape[0]
    E = cf[CF_SUB_E:CF_SUB_E + 9].copy()
    g = cf[CF_SUB_G:CF_SUB_G + 3].copy()
    s = MAX_SUBSTEPS // K
    while s > 1:                      # e^{A 2t} = (e^{At})^2, g_2t = e^{At} g_t + g_t
        E2 = np.empty(9)
        g2 = np.empty(3)
        for r in range(3):
            g2[r] = E[3 * r] * g[0] + E[3 * r + 1] * g[1] + E[3 * r + 2] * g[2] + g[r]
            for c in range(3):
                E2[3 * r + c] = E[3 * r] * E[c] + E[3 * r + 1] * E[3 + c] + E[3 * r + 2] * E[6 + c]
        E, g = E2, g2
        s //= 2
    hk = 0.5 * cf[CF_H] / K / pp[P_M]
    for j in range(N):
        xx, vv, VV, FF, fp = x[j, p], v[j, p], V[j, p], F[j, p], fext[j, p]
        for _ in range(K):
            vv += hk * FF
            x0, v0, V0 = xx, vv, VV
            xx = E[0] * x0 + E[1] * v0 + E[2] * V0 + g[0] * fp
            vv = E[3] * x0 + E[4] * v0 + E[5] * V0 + g[1] * fp
            VV = E[6] * x0 + E[7] * v0 + E[8] * V0 + g[2] * fp
            FF = _kick_force(xx, pp)
            vv += hk * FF
        x[j, p], v[j, p], V[j, p], F[j, p] = xx, vv, VV, FF


@njit(cache=True, nogil=True)
def d_step(x, v, V, xi, F, stuck, xm, fext, w, cf, pp, kind, counters, cs) -> None:
    """Deterministic flow D(h) of P rings of N units with xi frozen; arrays (N, P), in place.

    x, v, V, xi the state; F the kicked on-site force at x (:func:`montecarlo._kernels._kick_force`
    at the start); ``stuck`` the kink's held units (HOLD rule); ``xm``, ``fext`` scratch; ``w`` the
    live paths (1) and escaped ones (0); ``cf``, ``pp`` the coefficient and parameter arrays
    (:mod:`montecarlo.layout`) with ``cf[CF_H]`` the step h; ``kind`` the on-site treatment;
    ``counters`` (:data:`~montecarlo.layout.N_COUNTERS`,) int64 the kink's statistics; ``cs``
    scratch of shape (3, N_TAYLOR + 1).

    Paths are the inner loops: one path's steps form a serial dependency chain, so only
    independent paths side by side keep the floating-point pipelines busy. ``kind`` is
    tested once per call, outside the loops (inside them it cost a factor ten).
    """
    N, P = x.shape
    h = cf[CF_H]
    # the kink treatment kicks only the smooth remainder of a near-kink potential (n > 1)
    kicks = kind == KIND_KICK or (kind == KIND_KINK and pp[P_N] != 1.0)
    # stiff walls: paths to redo as substeps, with their state at the start of the step
    n_stiff = 0
    xstar = math.inf
    if kind == KIND_KICK and pp[P_N] > 2.0:
        xstar = _stiff_amplitude(pp, h)
    if xstar < pp[P_THRESHOLD]:  # stiffness reachable before the escape amplitude: scan the paths
        for p in range(P):
            for j in range(N):
                if _reach(x[j, p], v[j, p], h) > xstar:
                    n_stiff += 1
                    break
    if n_stiff > 0:
        sp = np.empty(n_stiff, dtype=np.int64)
        sk = np.empty(n_stiff, dtype=np.int64)
        s0 = np.empty((4, N, n_stiff))
        i = 0
        for p in range(P):
            K = 1
            for j in range(N):
                K = max(K, _substeps(x[j, p], v[j, p], h, xstar, pp))
            if K > 1:
                sp[i], sk[i] = p, K
                for j in range(N):
                    s0[0, j, i], s0[1, j, i], s0[2, j, i], s0[3, j, i] = x[j, p], v[j, p], V[j, p], F[j, p]
                i += 1
    # the kicks' update flags are runtime bools: literal True and False compiled _kick twice
    if kicks:
        _kick(x, v, F, h, pp, not kicks)
    # the external force sigma xi plus the coupling at the predicted midpoints, called directly:
    # a wrapper around _ring_coupling cost a third of the force's time at two paths per chunk
    _neighbour_force(x, v, xi, xm, fext, pp, h)
    if kind == KIND_KINK:
        _kink_flow(x, v, V, stuck, fext, w, cf, pp, counters, cs)
    else:
        _linear_flow(x, v, V, fext, cf)
    if kicks:
        _kick(x, v, F, h, pp, kicks)
    for i in range(n_stiff):
        p = sp[i]
        for j in range(N):
            x[j, p], v[j, p], V[j, p], F[j, p] = s0[0, j, i], s0[1, j, i], s0[2, j, i], s0[3, j, i]
        if N > 1:  # neighbours at their midpoints predicted from the start of the step
            for j in range(N):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
            _ring_coupling(xm, fext, pp, p, p + 1, xi, pp[P_SIGMA])
        _substep_path(x, v, V, F, fext, p, sk[i], cf, pp)


# error_model numpy: no zero test on the kicks' division by m (> 0, checked by the model)
@njit(cache=True, nogil=True, error_model="numpy")
def _d_step_fast(x, v, V, xi, F, xm, fext, cf, pp, kind) -> bool:
    """:func:`d_step` where the on-site force is smooth (not the kink) and no path is near a
    stiff wall: the same operations in the same order (bit-identical results), in a kernel of
    its own with the coupling, the kicks and the linear flow inlined.

    Returns False, with nothing changed, when :func:`d_step` must take the step. It exists
    because the general kernel's calls of the coupling and the flow, each with 7-9 arrays, and
    its stiff and kink branches cost a harmonic ring's loop about a fifth at the solver's small
    chunks (docs/methods.md, "Monte Carlo kernels").
    """
    N, P = x.shape
    h = cf[CF_H]
    kicks = kind == KIND_KICK
    fast = kind != KIND_KINK and not (kicks and pp[P_N] > 2.0 and _near_wall(x, v, h, _stiff_amplitude(pp, h),
                                                                            pp[P_THRESHOLD]))
    if fast:
        if kicks:
            _kick_inline(x, v, F, h, pp, not kicks)
        _neighbour_force(x, v, xi, xm, fext, pp, h)
        _linear_flow_inline(x, v, V, fext, cf)
        if kicks:
            _kick_inline(x, v, F, h, pp, kicks)
    return fast


@njit(cache=True, nogil=True, inline="always")
def noise(cf: np.ndarray, z: np.ndarray, buf: np.ndarray) -> None:
    """The level's noise for one step: the OU update's own normals ``z`` (1, N, P), copied."""
    _, N, P = z.shape
    for j in range(N):
        for p in range(P):
            buf[0, j, p] = z[0, j, p]


@njit(cache=True, nogil=True, inline="always")
def compose(cf_a: np.ndarray, cf_b: np.ndarray, e1: np.ndarray, e2: np.ndarray, out: np.ndarray) -> None:
    """Normal of one step ``cf_b`` (= 2 h) from those of two steps ``cf_a`` (h) in a row, exact:
    out = w1 e1 + w2 e2 with the OU update's weights."""
    w1 = cf_a[CF_XI_DECAY] * cf_a[CF_XI_NOISE] / cf_b[CF_XI_NOISE]
    w2 = cf_a[CF_XI_NOISE] / cf_b[CF_XI_NOISE]
    _, N, P = e1.shape
    for j in range(N):
        for p in range(P):
            out[0, j, p] = w1 * e1[0, j, p] + w2 * e2[0, j, p]


@njit(cache=True, nogil=True, inline="always")
def advance(xi: np.ndarray, eps: np.ndarray, cf: np.ndarray) -> None:
    """O(h) after the measurement: the exact OU update of the level's xi with normals ``eps``."""
    N, P = xi.shape
    for j in range(N):
        for p in range(P):
            xi[j, p] = cf[CF_XI_DECAY] * xi[j, p] + cf[CF_XI_NOISE] * eps[0, j, p]


@njit(cache=True, nogil=True, inline="always")
def twin_xi(xi: np.ndarray) -> np.ndarray:
    """The twin runs at the fine level's xi itself (D does not change xi)."""
    return xi


class FrozenStep(Stepper):
    """The frozen-xi step (Python side): every on-site treatment; the kink's piecewise flow needs
    the force held over the step, so there it is preferred only for dt <= tau."""

    name = "frozen"
    priority = 0
    description = ("Strang splitting O(h/2) D(h) O(h/2): exact Ornstein-Uhlenbeck update O of xi, "
                   "D the flow of (x, v, V) with xi frozen")
    preference = "xi held over the step: any tau, but for the kink only dt <= tau"
    dt_start = 0.02
    tag = FrozenTag(1)
    kernels = Kernels(1, noise, compose, d_step, advance, twin_xi, _d_step_fast, KIND_KINK)

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        return step_coefficients(h, dt)

    def preferred(self, h: Harvester, kind: int, dt: float) -> bool:
        return kind != KIND_KINK or h.params.tau >= dt

    def extrapolates(self, h: Harvester, kind: int) -> bool:
        """Smooth on-site forces only: at the kink the bias in dt is not yet asymptotic at the
        extrapolation's coarser steps (docs/methods.md, "Error estimate")."""
        return kind != KIND_KINK

    def start_dt(self, h: Harvester, kind: int, scale: float) -> float:
        """``scale`` times :attr:`dt_start`, and for the kink at most tau."""
        dt = scale * self.dt_start
        return min(dt, h.params.tau) if kind == KIND_KINK else dt

    def twin_matrices(self, lin: Harvester, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Mode q of the harmonic ring (:math:`s_q = \\sin^2(\\pi q/N)`) advances as
        :math:`y' = E y + g(\\sigma\\xi + k(2 - 4s_q)(x + \\tfrac h2 v))`, measured there, then
        :math:`\\xi' = e^{-h/\\tau}\\xi + \\sqrt{(D/\\tau)(1 - e^{-2h/\\tau})}\\,Z` (T maps to y after
        the flow with xi before its update; the noise acts on xi only)."""
        k = lin.k if lin.N > 1 else 0.0
        cq = 2.0 - 4.0 * mode_sin2(lin.N)
        cf = step_coefficients(lin, dt)
        E = cf[CF_E:CF_E + 9].reshape(3, 3)
        g = cf[CF_G:CF_G + 3]
        T = np.zeros((lin.N, 4, 4))
        T[:, :3, :3] = E
        T[:, :3, 0] += (k * cq)[:, None] * g
        T[:, :3, 1] += (0.5 * dt * k * cq)[:, None] * g
        T[:, :3, 3] = lin.params.sigma * g
        T[:, 3, 3] = 1.0
        M = T.copy()
        M[:, 3, 3] = cf[CF_XI_DECAY]
        Q = np.zeros((4, 4))
        Q[3, 3] = cf[CF_XI_NOISE] ** 2
        return M, T, Q, float(cf[CF_XI_HALF])


#: The frozen-xi stepper.
FROZEN = FrozenStep()
