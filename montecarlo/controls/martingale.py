"""The martingale controls: sums of functions of the state times the noise drawn after it.

In every step of the kernel the only randomness is a fresh Gaussian draw: the
Ornstein--Uhlenbeck normal :math:`Z_j` of each unit (frozen-xi step, xi increment
:math:`s Z_j`, :math:`s = \\sqrt{(D/\\tau)(1 - e^{-2h/\\tau})}`), or the joint step's four normals
(xi's own transition is the same exact OU update). For any function :math:`\\phi` of the state
:math:`Y_{t_m}` at a martingale point, and the innovation :math:`\\eta` of xi until the next,

.. math::

    M_\\phi = \\sum_{m} \\sum_j \\phi_j(Y_{t_m})\\,\\eta_{j,m},\\qquad
    \\eta_{j,m} = \\xi_j(t_{m+1}) - e^{-(t_{m+1} - t_m)/\\tau}\\xi_j(t_m)
    = \\sum_{t_m \\le s < t_{m+1}} e^{-(t_{m+1} - s - h)/\\tau} s Z_{j,s},\\qquad E[M_\\phi] = 0

exactly, for any dt, step, start and coefficient (each normal is independent of everything
before it), so these sums are control variates with known mean 0 whose regression
(:mod:`montecarlo.controls.regression`) adds no bias and leaves the Richardson pair untouched. The
:math:`t_m` are the measured steps (the fine level's first substep with Richardson); the
innovation needs no work per step, and the noise after the last point is left out, so that the
sums telescope with the measured window. The ideal :math:`\\phi` is the gradient in xi of
the solution g of the Poisson equation of the measured observable,
:math:`g(Y) - E[g(Y')|Y] = f(Y) - \\pi(f)`, whose martingale
:math:`\\sum_t g(Y_{t+1}) - E[g(Y_{t+1})|Y_t]` cancels the time average's fluctuation up to the
boundary term :math:`g(Y_{t_0}) - g(Y_{t_1})`; for a harmonic ring g is quadratic, so its
first-order part is linear in the state (the ``lin`` basis) and its second-order part is
:math:`\\sum_d G_d \\sum_j (\\eta_j\\eta_{j+d} - \\delta_{d0}\\,\\mathrm{var})` (the ``he`` sums;
exact with a martingale point at every step, :func:`poisson_controls`).

Basis, per unit j (sums over units; the ring's symmetry makes one coefficient per lag d):

``lin``  (x, v, V, xi) of the unit (d = 0) and the sums over its two neighbours at lag d,
         d = 1 .. D, :math:`D = \\min(\\lfloor N/2\\rfloor,` :data:`MG_DIST`);
``nl``   odd nonlinear terms of the unit: :data:`NL_NAMES` (``dU`` is :math:`-U'(x_j)`, ``r2``
         the neighbours' :math:`x_{j-1}^2 + x_{j+1}^2`; the terms measured against others:
         docs/methods.md, "Why the settings are what they are");
``he``   noise only: :math:`\\sum_j (\\eta_j^2/\\mathrm{var} - 1)` and
         :math:`\\sum_j \\eta_j\\eta_{j+d}/\\mathrm{var}`, d = 1 .. D (var the innovation's variance).

End-of-window terms ``bd``: :math:`G(Y_{t_{last}}) - G(Y_{t_0})` for quadratic G, the symmetrized
products :math:`a_j b_{j+d} + b_j a_{j+d}` of (x, v, V, xi), d = 0 .. D, and the potential
:math:`|x_j|^n`, summed over units (accumulated as the telescoping sum of G's changes between
measured points). They are the Poisson solution's boundary term, which the martingale sums
leave; their mean is 0 only for a stationary window (exactly so for a harmonic ring started
from its own law, up to the burn-in's remaining transient otherwise), so they are a control of
their own, :data:`BOUNDARY` (``simulate(..., controls=("martingale", "boundary"))``), admitted
only where :func:`stationary_window` finds their means consistent with 0. The kernel
(:func:`mg_measure`) accumulates either part alone or both.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from fpe_harvester.model import Harvester

from .._force import _onsite_force
from ..harmonic import step_matrices
from .base import Columns, Control

if TYPE_CHECKING:
    from ..ensemble import Ensemble

__all__ = ["MARTINGALE", "BOUNDARY", "MartingaleControl", "BoundaryControl", "BOUNDARY_TAIL", "MG_DIST",
           "NL_NAMES", "basis_names", "boundary_names", "lags", "n_state", "mg_measure", "mg_measure_groups",
           "stationary_window", "poisson_controls"]

#: Tail probability of the test (Hotelling's T^2 against chi^2) that the end-of-window terms
#: have mean 0; where it fails the candidate sets with them are left out (:func:`stationary_window`).
BOUNDARY_TAIL = 1e-3

#: Largest neighbour lag of the linear basis (the Poisson solution's weight on farther units is
#: small; the count of controls grows with it).
MG_DIST = 4
#: Odd nonlinear terms of the basis, in the kernel's order.
NL_NAMES = ("dU", "x3", "x2v", "x2V", "x2xi", "xv2", "xvV", "xvxi", "xr2", "vr2")
_LIN = ("x", "v", "V", "xi")
#: Quadratic products of the end-of-window terms, as index pairs into (x, v, V, xi).
BD_PAIRS = ((0, 0), (0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3), (2, 2), (2, 3), (3, 3))


def lags(N: int) -> int:
    """Largest neighbour lag D of the basis for a ring of N units."""
    return min(N // 2, MG_DIST)


def basis_names(N: int) -> tuple[str, ...]:
    """Names of the accumulated martingale controls for N units, in the kernel's order:
    ``lin_<var>_<d>``, ``nl_<term>``, ``he_<d>``."""
    D = lags(N)
    lin = tuple(f"lin_{v}_{d}" for d in range(D + 1) for v in _LIN)
    return lin + tuple("nl_" + t for t in NL_NAMES) + tuple(f"he_{d}" for d in range(D + 1))


def boundary_names(N: int) -> tuple[str, ...]:
    """Names of the accumulated end-of-window terms for N units, in the kernel's order:
    ``bd_<ab>_<d>`` and ``bd_U``."""
    return tuple(f"bd_{_LIN[a]}{_LIN[b]}_{d}" for d in range(lags(N) + 1) for a, b in BD_PAIRS) + ("bd_U",)


@njit(cache=True, nogil=True)
def n_state(N: int) -> int:
    """Number of state functions (``lin`` and ``nl``) of the basis for N units."""
    return 4 * (min(N // 2, MG_DIST) + 1) + len(NL_NAMES)


@njit(cache=True, nogil=True)
def _boundary_groups(x, v, V, xi, w, n, g) -> None:
    """g[r, k] = sum over units and live paths of replica r of the k-th end-of-window function at
    this state (``g`` (G, K): G replicas of P / G consecutive paths; one replica is G = 1)."""
    N, P = x.shape
    G = g.shape[0]
    per = P // G
    D = min(N // 2, MG_DIST)
    for r in range(G):
        for k in range(g.shape[1]):
            g[r, k] = 0.0
    for p in range(P):
        if w[p] == 0.0:
            continue
        r = p // per
        for j in range(N):
            a0 = (x[j, p], v[j, p], V[j, p], xi[j, p])
            for d in range(D + 1):
                l = (j + d) % N
                b0 = (x[l, p], v[l, p], V[l, p], xi[l, p])
                for i in range(len(BD_PAIRS)):
                    a, b = BD_PAIRS[i]
                    val = a0[a] * b0[b] + a0[b] * b0[a] if a != b or d > 0 else a0[a] * a0[a]
                    # lag d > 0 visits each unordered pair of units once per j (twice for d = N/2)
                    g[r, 10 * d + i] += 0.5 * val if d > 0 else val
            g[r, 10 * (D + 1)] += abs(x[j, p]) ** n


@njit(cache=True, nogil=True)
def mg_phi(x, v, V, xi, w, a, n, phi) -> None:
    """Evaluate the state basis at the measured state into ``phi`` (K, N, P), K the ``lin``
    and ``nl`` functions; dead paths 0."""
    N, P = x.shape
    D = min(N // 2, MG_DIST)
    o = 4 * (D + 1)
    for p in range(P):
        for j in range(N):
            wp = w[p]
            xx, vv, VV, ss = x[j, p], v[j, p], V[j, p], xi[j, p]
            phi[0, j, p], phi[1, j, p], phi[2, j, p], phi[3, j, p] = wp * xx, wp * vv, wp * VV, wp * ss
            for d in range(1, D + 1):
                jm, jp = (j + N - d) % N, (j + d) % N
                b = 4 * d
                phi[b, j, p] = wp * (x[jm, p] + x[jp, p])
                phi[b + 1, j, p] = wp * (v[jm, p] + v[jp, p])
                phi[b + 2, j, p] = wp * (V[jm, p] + V[jp, p])
                phi[b + 3, j, p] = wp * (xi[jm, p] + xi[jp, p])
            du = -2.0 * a * xx if n == 2.0 else _onsite_force(xx, a, n)
            x2 = xx * xx
            r2 = 0.0
            if N > 1:
                r2 = x[(j + N - 1) % N, p] ** 2 + x[(j + 1) % N, p] ** 2
            phi[o, j, p] = wp * du
            phi[o + 1, j, p] = wp * x2 * xx
            phi[o + 2, j, p] = wp * x2 * vv
            phi[o + 3, j, p] = wp * x2 * VV
            phi[o + 4, j, p] = wp * x2 * ss
            phi[o + 5, j, p] = wp * xx * vv * vv
            phi[o + 6, j, p] = wp * xx * vv * VV
            phi[o + 7, j, p] = wp * xx * vv * ss
            phi[o + 8, j, p] = wp * xx * r2
            phi[o + 9, j, p] = wp * vv * r2


@njit(cache=True, nogil=True, inline="always")
def _state_sums(phi, xi, xi0, w, decay: float, var: float, p0: int, p1: int, acc, first: bool) -> None:
    """The martingale sums of one replica, paths ``p0 .. p1 - 1``, into its ``acc`` (2, K + D + 1)
    (:func:`mg_measure`): acc[0, k] += sum of phi[k] eta, acc[0, K + d] += sum of
    :math:`\\eta_j\\eta_{j+d}/var - \\delta_{d0}` over live paths, the same into acc[1] with
    ``first``. Shared by :func:`mg_measure` (0, P) and :func:`mg_measure_groups` (each replica's
    paths)."""
    K, N, _ = phi.shape
    D = min(N // 2, MG_DIST)
    for k in range(K):
        s = 0.0
        for j in range(N):
            for p in range(p0, p1):
                s += phi[k, j, p] * (xi[j, p] - decay * xi0[j, p])
        acc[0, k] += s
        if first:
            acc[1, k] += s
    for d in range(D + 1):
        s = 0.0
        for p in range(p0, p1):
            if w[p] == 0.0:
                continue
            for j in range(N):
                l = (j + d) % N
                s += (xi[j, p] - decay * xi0[j, p]) * (xi[l, p] - decay * xi0[l, p]) / var
                if d == 0:
                    s -= 1.0
        acc[0, K + d] += s
        if first:
            acc[1, K + d] += s


@njit(cache=True, nogil=True)
def mg_measure(x, v, V, xi, w, a, n, phi, xi0, acc, bd, first: bool, started: bool, decay: float,
               var: float, g: np.ndarray, gprev: np.ndarray) -> None:
    """At a measured step: close the interval since the previous one (unless this is the first)
    and start the next.

    The interval's noise of unit j is the innovation of its xi,
    :math:`\\eta_j = \\xi_j - e^{-\\Delta/\\tau}\\xi_j^{(0)}` (``decay``; ``xi0`` holds xi at the
    previous measured step), the exponentially weighted sum of the normals drawn since, with
    conditional mean 0 and variance ``var`` = :math:`(D/\\tau)(1 - e^{-2\\Delta/\\tau})` whatever
    happened to x, v, V: acc[0, k] += sum over units and paths of phi[k] eta (k < K),
    acc[0, K + d] += sum of :math:`\\eta_j\\eta_{j+d}/var - \\delta_{d0}` over live paths,
    the same into acc[1] while in the first half of the window; the end-of-window functions'
    change since the previous point goes to bd (``g``, ``gprev`` scratch). Then the basis is
    evaluated at the current state (:func:`mg_phi`) and xi is kept in ``xi0``. Either part is
    skipped where its accumulator has no columns (the martingale sums ``acc``, the end-of-window
    terms ``bd``). Nothing is done per step.
    """
    K, N, P = phi.shape
    D = min(N // 2, MG_DIST)
    state = acc.shape[1] > 0
    if g.size > 0:
        # one replica: the replicas' kernel on a (1, K) view (the same sums, the same order)
        _boundary_groups(x, v, V, xi, w, n, g.reshape(1, g.size))
    if started:
        for k in range(g.size):
            bd[0, k] += g[k] - gprev[k]
            if first:
                bd[1, k] += g[k] - gprev[k]
        if state:
            _state_sums(phi, xi, xi0, w, decay, var, 0, P, acc, first)
    # element loops, not slice copies: those compile numba's shape-checked copy per dimension
    for k in range(g.size):
        gprev[k] = g[k]
    if state:
        mg_phi(x, v, V, xi, w, a, n, phi)
        for j in range(N):
            for p in range(P):
                xi0[j, p] = xi[j, p]


@njit(cache=True, nogil=True)
def mg_measure_groups(x, v, V, xi, w, a, n, phi, xi0, acc, bd, first: bool, started: bool, decay: float,
                      var: float, g: np.ndarray, gprev: np.ndarray) -> None:
    """:func:`mg_measure` for G replicas of P / G consecutive paths: ``acc`` (G, 2, K + D + 1) and
    ``bd`` (G, 2, K') hold each replica's sums, ``g`` and ``gprev`` (G, K') its end-of-window
    scratch (acc[r, 0, k] += sum over units and paths of replica r of phi[k] eta, and so on)."""
    K, N, P = phi.shape
    G = acc.shape[0]
    per = P // G
    D = min(N // 2, MG_DIST)
    state = acc.shape[2] > 0
    if g.shape[1] > 0:
        _boundary_groups(x, v, V, xi, w, n, g)
    if started:
        for r in range(G):
            p0, p1 = r * per, (r + 1) * per
            for k in range(g.shape[1]):
                bd[r, 0, k] += g[r, k] - gprev[r, k]
                if first:
                    bd[r, 1, k] += g[r, k] - gprev[r, k]
            if not state:
                continue
            _state_sums(phi, xi, xi0, w, decay, var, p0, p1, acc[r], first)
    # element loops, not slice copies: those compile numba's shape-checked copy per dimension
    for r in range(G):
        for k in range(g.shape[1]):
            gprev[r, k] = g[r, k]
    if state:
        mg_phi(x, v, V, xi, w, a, n, phi)
        for j in range(N):
            for p in range(P):
                xi0[j, p] = xi[j, p]


class MartingaleControl(Control):
    """The martingale sums ``lin``, ``nl`` and ``he`` (mean 0 exactly, any start), accumulated by
    the path loop (:func:`mg_measure`)."""

    name = "martingale"
    accumulated = True

    def sums(self, h: Harvester) -> tuple[str, ...]:
        return basis_names(h.N)

    def loop_fields(self, h: Harvester, offset: int) -> dict[str, int]:
        return {"mg_at": offset, "n_mg": len(basis_names(h.N))}

    def columns(self, e: Ensemble, valid: np.ndarray) -> Columns | None:
        return _own(e, valid, self.name)


class BoundaryControl(Control):
    """The end-of-window terms ``bd_*`` (the change of quadratic functions of the state and of
    :math:`|x|^n` over the measured window, accumulated by the path loop beside the martingale
    sums, :func:`mg_measure`): mean 0 only for a stationary window, so only where
    :func:`stationary_window` admits them."""

    name = "boundary"
    accumulated = True

    def sums(self, h: Harvester) -> tuple[str, ...]:
        return boundary_names(h.N)

    def loop_fields(self, h: Harvester, offset: int) -> dict[str, int]:
        return {"bd_at": offset, "n_bd": len(boundary_names(h.N))}

    def columns(self, e: Ensemble, valid: np.ndarray) -> Columns | None:
        if self.name not in e.ctl_names or not stationary_window(e.control_sums(self.name), valid,
                                                                   e.ctl_names[self.name]):
            return None
        return _own(e, valid, self.name)


def _own(e: Ensemble, valid: np.ndarray, control: str) -> Columns | None:
    """Every column ``control`` accumulated (exact means 0), or None where it was not."""
    if control not in e.ctl_names:
        return None
    whole, first = e.control_sums(control), e.control_sums(control, first_half=True)
    names = e.ctl_names[control]
    return [whole[name][valid] for name in names], [first[name][valid] for name in names], [0.0] * len(names)


#: The martingale control.
MARTINGALE = MartingaleControl()
#: The martingale's end-of-window terms as a control of their own.
BOUNDARY = BoundaryControl()


def stationary_window(mg: dict[str, np.ndarray], valid: np.ndarray, names: tuple[str, ...]) -> bool:
    """Whether the end-of-window terms are usable: present, and their means consistent with 0
    (Hotelling's T^2 below the chi^2 quantile at :data:`BOUNDARY_TAIL`). They have mean 0 only
    for a stationary window; a transient left by the burn-in shows here first
    (tests/montecarlo/test_extrapolate.py)."""
    from scipy.stats import chi2

    cols = [mg[name][valid] for name in names if name.startswith("bd_")]
    n = int(valid.sum())
    if not cols or n < 3:
        return False
    C = np.column_stack(cols)
    sd = C.std(axis=0, ddof=1)
    C = C[:, sd > 0] / sd[sd > 0]
    # Hotelling's T^2 of the means (the terms are strongly correlated), on the resolved rank
    m = C.mean(axis=0)
    Cc = C - m
    _, sv, vt = np.linalg.svd(Cc / math.sqrt(n - 1), full_matrices=False)
    keep = sv > 1e-8 * sv[0] if sv.size else sv > 0
    proj = vt[keep] @ m / sv[keep]
    t2 = n * float(proj @ proj)
    return bool(t2 < chi2.ppf(1.0 - BOUNDARY_TAIL, max(int(keep.sum()), 1)))


def poisson_controls(lin: Harvester, dt: float, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Weights over the martingale sums that make the Poisson-solution controls of V2 and Pin.

    For the harmonic ring ``lin`` at the frozen-xi step dt, the measured state
    :math:`Y_t` (x, v, V after the step's flow, xi before its update, unit by unit) is the linear
    chain :math:`Y_{t+1} = A Y_t + \\sum_j b_j Z_j` with :math:`A = T D_\\xi` (T of
    :func:`montecarlo.harmonic.step_matrices` in unit space, :math:`D_\\xi` the xi decay
    :math:`e^{-h/\\tau}`) and
    :math:`b_j = s\\,T e_{\\xi_j}`. For a quadratic observable :math:`f = Y^TFY` (the ring mean of
    :math:`V^2`, or of :math:`\\sigma e^{-h/2\\tau} v\\xi`) the Poisson equation
    :math:`g - E[g(Y')|Y] = f - \\pi(f)` has the quadratic solution :math:`g = Y^TGY`,
    :math:`G - A^TGA = F` (one discrete Lyapunov solve), and its martingale increment is

    .. math::

        g(Y') - E[g(Y')|Y] = \\sum_j 2\\,e_{\\xi_j}^T T^T G A Y\\; sZ_j
        + s^2 \\sum_{j,l} (T^TGT)_{\\xi_j\\xi_l}(Z_jZ_l - \\delta_{jl}),

    linear in the state times the noise plus Hermite terms: a fixed combination of the ``lin`` and
    ``he`` sums of :mod:`montecarlo.controls.martingale` (the ring's symmetry makes the weights depend on
    the lag only; lags beyond :data:`montecarlo.controls.martingale.MG_DIST` are not in the basis, so the
    weights are exact for N <= 9). With a sample at every step the time average's fluctuation is
    this martingale up to the boundary term :math:`g(Y_{t_0}) - g(Y_{t_1})`.

    Parameters
    ----------
    lin : Harvester
        A stable harmonic ring (the system itself, or a nonlinear system's twin: the weights then
        define a control evaluated on the real state, still of mean 0).
    dt : float
        The fine step of the ensemble, > 0 (frozen-xi step).
    names : tuple of str
        The martingale sums' names, ``ctl_names["martingale"]`` of the ensemble.

    Returns
    -------
    dict
        ``{"V2": w, "Pin": w}, weight vectors over ``names``.
    """
    import scipy.linalg

    M, T, _, _ = step_matrices(lin, dt)
    N = lin.N
    p = lin.params
    lag = np.arange(N)
    cosw = np.cos(2.0 * math.pi * np.outer(lag, np.arange(N)) / N) / N
    Tb = np.einsum("lq,qab->lab", cosw, T)
    Tu = np.zeros((4 * N, 4 * N))
    for j in range(N):
        for l in range(N):
            Tu[4 * j:4 * j + 4, 4 * l:4 * l + 4] = Tb[(j - l) % N]
    Dxi = np.eye(4 * N)
    Dxi[3::4, 3::4] *= math.exp(-dt / p.tau)
    A = Tu @ Dxi
    s = math.sqrt(p.noise_variance * -math.expm1(-2.0 * dt / p.tau))
    half = math.exp(-0.5 * dt / p.tau)
    out = {}
    for key in ("V2", "Pin"):
        F = np.zeros((4 * N, 4 * N))
        for j in range(N):
            if key == "V2":
                F[4 * j + 2, 4 * j + 2] = 1.0 / N
            else:
                F[4 * j + 1, 4 * j + 3] = F[4 * j + 3, 4 * j + 1] = 0.5 * p.sigma * half / N
        G = scipy.linalg.solve_discrete_lyapunov(A.T, F)
        lin_w = 2.0 * Tu[:, 3].T @ G @ A  # unit 0's phi = lin_w . Y
        K = s * s * Tu.T @ G @ Tu
        w = np.zeros(len(names))
        for i, name in enumerate(names):
            kind, *rest = name.split("_")
            if kind == "lin":
                var, d = "x v V xi".split().index(rest[0]), int(rest[1])
                if d == 0:
                    w[i] = lin_w[var]
                else:
                    # the basis holds y_{j-d} + y_{j+d}: equal weights on a reflection-symmetric ring
                    w[i] = lin_w[4 * d + var] if 2 * d != N else 0.5 * lin_w[4 * d + var]
            elif kind == "he":
                d = int(rest[0])
                w[i] = K[3, 3] if d == 0 else (K[3, 4 * d + 3] * (1.0 if 2 * d == N else 2.0))
        out[key] = w
    return out
