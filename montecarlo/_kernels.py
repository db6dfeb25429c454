"""numba kernels shared by the steps: kicks, stiff walls, coupling, measurement, escapes.

Private module. The steps (:mod:`montecarlo.steps`) and the path loop (:mod:`montecarlo._loop`)
use these; the arrays they read are laid out in :mod:`montecarlo.layout`. The ring's coupling
force is computed in one place, :func:`_ring_coupling` (:func:`_coupling_force` per unit). It and
:func:`_kick` exist twice, as an ordinary call and inlined (``..._inline``), from one body: the
steps' general kernels call them, their fast kernels inline them
(:class:`montecarlo.steps.base.Stepper`).
"""

from __future__ import annotations


import numpy as np
from numba import njit

from ._force import _onsite_force
from .layout import (CF_PVX, CF_XI_HALF, KIND_KICK, KIND_KINK, M_V2, M_d2, M_stuck, M_v2, M_vV, M_vxi, M_x2,
                     M_xdU, P_A, P_K, P_K3, P_K4, P_KINK_FORCE, P_M, P_N, P_SIGMA)

#: Stiff walls (kick treatment, n > 2): a path whose stiffest unit has
#: :math:`h^2 U''(x_e)/m > ` STIFF_LIMIT (x_e the farther of x and x + h v at the start of a
#: step) takes that step as K equal substeps (K the smallest power of 2 that brings it below, at
#: most MAX_SUBSTEPS), the neighbours' force held at its value for the whole step. The
#: kick-drift-kick step is unstable for :math:`h^2 U''/m > 4`, which the tails of the law of a
#: steep wall (n = 12, 16) and the first steps from a Gaussian start reach at dt = 0.01.
STIFF_LIMIT = 1.0
MAX_SUBSTEPS = 1024



@njit(cache=True, nogil=True, inline="always")
def _kick_force(x: float, pp: np.ndarray) -> float:
    """The on-site force left to the kicks: -U'(x), minus the kink part
    :math:`-an\\,\\mathrm{sign}(x)` that the kink's flow integrates exactly (``pp[P_KINK_FORCE]``,
    0 for the other on-site kinds)."""
    F = _onsite_force(x, pp[P_A], pp[P_N])
    if x > 0.0:
        F += pp[P_KINK_FORCE]
    elif x < 0.0:
        F -= pp[P_KINK_FORCE]
    return F


@njit(cache=True, nogil=True, inline="always")
def _kick_inline(x, v, F, h, pp, update) -> None:
    """Half kick v += (h/2) F/m; with ``update`` first recompute F (:func:`_kick_force`)."""
    N, P = x.shape
    m = pp[P_M]
    hk = 0.5 * h / m
    for j in range(N):
        for p in range(P):
            if update:
                F[j, p] = _kick_force(x[j, p], pp)
            v[j, p] += hk * F[j, p]


#: :func:`_kick_inline` as an ordinary call, for the steps' general kernels (their fast kernels
#: inline it: :class:`~montecarlo.steps.base.Stepper`).
_kick = njit(cache=True, nogil=True)(_kick_inline.py_func)



@njit(cache=True, nogil=True, inline="always")
def _stiff_amplitude(pp: np.ndarray, h: float) -> float:
    """The |x| beyond which a step h sees h^2 U''(x)/m > STIFF_LIMIT (n > 2)."""
    return (STIFF_LIMIT * pp[P_M] / (h * h * pp[P_A] * pp[P_N] * (pp[P_N] - 1.0))) ** (1.0 / (pp[P_N] - 2.0))


@njit(cache=True, nogil=True, inline="always")
def _reach(x: float, v: float, h: float) -> float:
    """How far from 0 a unit at (x, v) gets within a step h, as the stiff walls' tests take it:
    the farther of |x| and |x + h v|."""
    return max(abs(x), abs(x + h * v))


@njit(cache=True, nogil=True, inline="always")
def _near_wall(x, v, h: float, xstar: float, thr: float) -> bool:
    """Whether some unit is beyond ``xstar`` at the step's start or its predicted end, so that
    its path's step needs substeps (:func:`_substeps`); never when ``xstar`` is not below the
    escape amplitude ``thr``."""
    if xstar >= thr:
        return False
    N, P = x.shape
    for p in range(P):
        for j in range(N):
            if _reach(x[j, p], v[j, p], h) > xstar:
                return True
    return False


@njit(cache=True, nogil=True)
def _substeps(x: float, v: float, h: float, xstar: float, pp: np.ndarray) -> int:
    """Substeps a unit at (x, v) needs within a step h: :math:`h^2 U''(x_e)/m` at the farther of
    x and x + h v (U'' = a n (n-1)|x|^(n-2), growing with |x|); 1 below ``xstar``, where it is
    STIFF_LIMIT."""
    xe = _reach(x, v, h)
    if xe <= xstar:
        return 1
    a, n = pp[P_A], pp[P_N]
    stiff = h * h * a * n * (n - 1.0) * xe ** (n - 2.0) / pp[P_M]
    K = 1
    while stiff > STIFF_LIMIT * K * K and K < MAX_SUBSTEPS:
        K *= 2
    return K



@njit(cache=True, nogil=True)
def _measure(x, v, V, xi, stuck, F, w, cf, pp, kind, acc, pvx) -> float:
    """Add the system's moments of the live paths (weight w = 1) to their slots of ``acc``
    (:data:`montecarlo.layout.MOMENTS`; the bonds' d^2: N bonds per ring of N >= 2); return
    unit-steps counted.

    ``F`` holds -U'(x) at the current x for the smooth kind (the last kick computed it).
    After a joint step, v xi is replaced by the estimate ``pvx`` of :func:`_d_step_joint` (and
    after the kink's averaged-noise step by its own, :mod:`montecarlo.steps.averaged`).
    """
    N, P = x.shape
    half = cf[CF_XI_HALF]
    a, n = pp[P_A], pp[P_N]
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
    # the bonds' d^2 in the same pass: a pass of its own cost 15 % of this function at small P
    for j in range(N):
        jp = j + 1 if j < N - 1 else 0
        for p in range(P):
            wp = w[p]
            s0 += wp * V[j, p] * V[j, p]
            s1 += wp * v[j, p] * V[j, p]
            s2 += wp * v[j, p] * v[j, p]
            s3 += wp * x[j, p] * x[j, p]
            s4 += wp * v[j, p] * xi[j, p]
            s5 += wp * stuck[j, p]
            if N > 1:
                d = x[jp, p] - x[j, p]
                s7 += wp * d * d
    if cf[CF_PVX] == 1.0:
        s4 = 0.0
        for j in range(N):
            for p in range(P):
                s4 += w[p] * pvx[j, p]
    if kind == KIND_KICK:
        for j in range(N):
            for p in range(P):
                s6 -= w[p] * x[j, p] * F[j, p]
    elif kind == KIND_KINK:
        for j in range(N):
            for p in range(P):
                ax = abs(x[j, p])
                s6 += w[p] * a * (ax if n == 1.0 else n * ax**n)
    else:
        s6 = 2.0 * a * s3
    acc[M_V2] += s0
    acc[M_vV] += s1
    acc[M_v2] += s2
    acc[M_x2] += s3
    acc[M_vxi] += s4 * half
    acc[M_stuck] += s5
    acc[M_xdU] += s6
    if N > 1:
        acc[M_d2] += s7
    live = 0.0
    for p in range(P):
        live += w[p]
    return live * N




@njit(cache=True, nogil=True)
def measure_groups(x, v, V, xi, stuck, F, w, cf, pp, kind, acc, row, cnt, pvx) -> None:
    """Add the system's moments of the live paths (weight w = 1) to their slots of ``acc[g, row]``
    and the unit-steps counted to ``cnt[g, row]``, g the replica of the path
    (:data:`montecarlo.layout.MOMENTS`; the bonds' d^2: N bonds per ring of N >= 2).

    ``acc`` is (G, rows, moments), ``cnt`` (G, rows): the P paths are G replicas of P / G
    consecutive paths each (:func:`_measure` is the same for one replica, with loops over all
    paths: loops over a range of paths cost a ring's run 12 % when run with one replica).
    ``F`` holds -U'(x) at the current x for the smooth kind (the last kick computed it).
    After a joint step, v xi is replaced by the estimate ``pvx`` of :func:`_d_step_joint` (and
    after the kink's averaged-noise step by its own, :mod:`montecarlo.steps.averaged`).
    """
    N, P = x.shape
    G = acc.shape[0]
    per = P // G
    half = cf[CF_XI_HALF]
    a, n = pp[P_A], pp[P_N]
    for g in range(G):
        p0, p1 = g * per, (g + 1) * per
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        # the bonds' d^2 in the same pass: a pass of its own cost 15 % of this function at small P
        for j in range(N):
            jp = j + 1 if j < N - 1 else 0
            for p in range(p0, p1):
                wp = w[p]
                s0 += wp * V[j, p] * V[j, p]
                s1 += wp * v[j, p] * V[j, p]
                s2 += wp * v[j, p] * v[j, p]
                s3 += wp * x[j, p] * x[j, p]
                s4 += wp * v[j, p] * xi[j, p]
                s5 += wp * stuck[j, p]
                if N > 1:
                    d = x[jp, p] - x[j, p]
                    s7 += wp * d * d
        if cf[CF_PVX] == 1.0:
            s4 = 0.0
            for j in range(N):
                for p in range(p0, p1):
                    s4 += w[p] * pvx[j, p]
        if kind == KIND_KICK:
            for j in range(N):
                for p in range(p0, p1):
                    s6 -= w[p] * x[j, p] * F[j, p]
        elif kind == KIND_KINK:
            for j in range(N):
                for p in range(p0, p1):
                    ax = abs(x[j, p])
                    s6 += w[p] * a * (ax if n == 1.0 else n * ax**n)
        else:
            s6 = 2.0 * a * s3
        out = acc[g, row]
        out[M_V2] += s0
        out[M_vV] += s1
        out[M_v2] += s2
        out[M_x2] += s3
        out[M_vxi] += s4 * half
        out[M_stuck] += s5
        out[M_xdU] += s6
        if N > 1:
            out[M_d2] += s7
        live = 0.0
        for p in range(p0, p1):
            live += w[p]
        cnt[g, row] += live * N




@njit(cache=True, nogil=True)
def _check_escape(x, v, V, xi, F, stuck, w, thr, t, esc_time) -> None:
    """Retire paths with some |x_j| > thr (or non-finite): record the time, zero their state."""
    N, P = x.shape
    # branch-free scan first: escapes are rare, the scan vectorizes, NaN counts as escaped
    n_bad = 0
    for j in range(N):
        for p in range(P):
            n_bad += 0 if abs(x[j, p]) <= thr else 1
    if n_bad == 0:
        return
    for p in range(P):
        if w[p] == 0.0:
            continue
        out = False
        for j in range(N):
            if not abs(x[j, p]) <= thr:
                out = True
        if out:
            w[p] = 0.0
            esc_time[p] = t
            for j in range(N):
                x[j, p] = 0.0
                v[j, p] = 0.0
                V[j, p] = 0.0
                xi[j, p] = 0.0
                F[j, p] = 0.0
                stuck[j, p] = False


@njit(cache=True, nogil=True)
def _start(gen, chol, sd, x, v, V, xi) -> None:
    """Initial state: rest with stationary xi, or a draw ``chol @ z`` of the 4N-vector
    (x_j, v_j, V_j, xi_j) per path when ``chol`` (lower triangular, 4N x 4N) is given."""
    N, P = x.shape
    if chol.shape[0] == 0:
        for j in range(N):
            for p in range(P):
                xi[j, p] = sd * gen.standard_normal()
        return
    z = np.empty(4 * N)
    for p in range(P):
        for i in range(4 * N):
            z[i] = gen.standard_normal()
        for i in range(4 * N):
            s = 0.0
            for l in range(i + 1):
                s += chol[i, l] * z[l]
            j, c = divmod(i, 4)
            if c == 0:
                x[j, p] = s
            elif c == 1:
                v[j, p] = s
            elif c == 2:
                V[j, p] = s
            else:
                xi[j, p] = s


@njit(cache=True, nogil=True)
def _clamp_start(x: np.ndarray, kind: int, pp: np.ndarray, h: float) -> None:
    """A Gaussian start can land deep in a steep wall, where even MAX_SUBSTEPS substeps of a
    step h are unstable: such draws start at the deepest resolvable |x| (the burn-in forgets it)."""
    if kind == KIND_KICK and pp[P_N] > 2.0:
        xcap = _stiff_amplitude(pp, h / MAX_SUBSTEPS)
        for j in range(x.shape[0]):
            for p in range(x.shape[1]):
                x[j, p] = min(max(x[j, p], -xcap), xcap)


@njit(cache=True, nogil=True)
def _live(w: np.ndarray) -> int:
    """Paths still running (weight > 0; an escaped path has weight 0)."""
    n = 0
    for p in range(w.size):
        if w[p] > 0.0:
            n += 1
    return n




@njit(cache=True, nogil=True, inline="always")
def _coupling_force(x2m: float, xm: float, x: float, xp: float, x2p: float, k: float, k4: float,
                    k3: float) -> float:
    """Force on a unit at ``x`` from its ring neighbours at ``xm``, ``xp`` (and theirs, ``x2m``,
    ``x2p``, for ``k4``), all at their predicted midpoints: the one place the step kernels
    compute the coupling (indices from :func:`_ring_neighbours`).

    The force is :math:`-\\partial E/\\partial x_j` of :math:`E = (k/2)\\sum d^2 +
    (k_4/2)\\sum (Lx)^2 + (k_3/4)\\sum d^4` (bonds :math:`d = x_{j+1} - x_j`) minus the part
    :math:`-(2k + 6k_4)x_j` kept in the exact linear flow (:func:`montecarlo.coefficients.linear_stiffness`):
    :math:`k(x_{j-1} + x_{j+1}) + k_4[4(x_{j-1} + x_{j+1}) - x_{j-2} - x_{j+2}]
    + k_3[(x_{j+1} - x_j)^3 - (x_j - x_{j-1})^3]`, indices modulo N (so that N = 2 is a ring
    of two bonds). ``k4`` and ``k3`` are tested for 0 so that a ring without them computes
    exactly the diffusive force, bit for bit. Scalars, not the array: an array argument of
    an inlined function is reference-counted at every call, which with these branches made
    the whole step 25 % slower at the solver's small chunks.
    """
    F = k * (xm + xp)
    if k4 != 0.0:
        F += k4 * (4.0 * (xm + xp) - x2m - x2p)
    if k3 != 0.0:
        dp = xp - x
        dm = x - xm
        F += k3 * (dp * dp * dp - dm * dm * dm)
    return F


@njit(cache=True, nogil=True, inline="always")
def _ring_coupling_inline(xm: np.ndarray, f: np.ndarray, pp: np.ndarray, p0: int, p1: int, base: np.ndarray,
                   scale: float) -> None:
    """f[:, p0:p1] = scale * base + the coupling force (:func:`_coupling_force`) on each unit of
    paths p0 to p1 - 1, from their midpoints ``xm`` (N, P). The frozen step adds its noise force
    (base xi, scale sigma) in the same pass: a second pass over f made a harmonic ring's step
    slower; the joint step passes scale 0."""
    N = xm.shape[0]
    k, k4, k3 = pp[P_K], pp[P_K4], pp[P_K3]
    # the diffusive coupling alone reads two neighbours, not four: at two paths per chunk the
    # general force's loads and tests cost 10-20 % of a harmonic ring's step
    plain = k4 == 0.0 and k3 == 0.0
    for j in range(N):
        jmm, jm, jp, jpp = _ring_neighbours(j, N)
        for p in range(p0, p1):
            f[j, p] = scale * base[j, p]
            if plain:
                f[j, p] += k * (xm[jm, p] + xm[jp, p])
            else:
                f[j, p] += _coupling_force(xm[jmm, p], xm[jm, p], xm[j, p], xm[jp, p], xm[jpp, p], k, k4, k3)


#: :func:`_ring_coupling_inline` as an ordinary call, for the steps' general kernels.
_ring_coupling = njit(cache=True, nogil=True)(_ring_coupling_inline.py_func)


@njit(cache=True, nogil=True, inline="always")
def _neighbour_force(x, v, xi, xm, fext, pp, h: float) -> None:
    """The frozen step's external force: ``fext`` = sigma xi plus the ring's coupling force
    (:func:`_ring_coupling`) at the units' predicted midpoints ``xm`` = x + (h/2) v; inlined
    into both frozen kernels. The joint step keeps its own loop, which measured faster there
    (docs/methods.md, "Monte Carlo kernels")."""
    N, P = x.shape
    if N > 1:
        for j in range(N):
            for p in range(P):
                xm[j, p] = x[j, p] + 0.5 * h * v[j, p]
        _ring_coupling_inline(xm, fext, pp, 0, P, xi, pp[P_SIGMA])
    else:
        for p in range(P):
            fext[0, p] = pp[P_SIGMA] * xi[0, p]


@njit(cache=True, nogil=True, inline="always")
def _ring_neighbours(j: int, N: int) -> tuple[int, int, int, int]:
    """Indices of units j - 2, j - 1, j + 1, j + 2 on a ring of N (modulo N). Compares, not
    ``%``: an integer division per index was a fifth of the coupling's cost at two paths per chunk."""
    jm = j - 1 if j > 0 else N - 1
    jp = j + 1 if j < N - 1 else 0
    return (jm - 1 if jm > 0 else N - 1), jm, jp, (jp + 1 if jp < N - 1 else 0)
