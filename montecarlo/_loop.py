"""The path loop of one chunk: every level of P rings through burn-in and measured window.

Private module. One loop serves every stepper (:mod:`montecarlo.steps`): the stepper's tag
selects its kernels at compile time (:mod:`montecarlo.steps.dispatch`), so numba compiles one
specialised loop per stepper. The levels: fine (``dt/2`` with Richardson coupling, else ``dt``),
coarse (``dt``, on the fine level's noise), coarsest (``2 dt``, optional) and the harmonic twin
(on the fine level's noise, measured with it, :mod:`montecarlo.controls.twin`); the martingale
sums ride on the fine level (:mod:`montecarlo.controls.martingale`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ._kernels import _check_escape, _clamp_start, _kick_force, _live, _measure, _start, measure_groups
from ._kink import N_TAYLOR
from .controls.generator import gen_close, gen_measure
from .controls.martingale import mg_measure, mg_measure_groups, n_state
from .controls.twin import measure_twin, measure_twin_groups
from .layout import (C_RING_STEPS, CF_H, CF_XI_DECAY, KIND_LINEAR, N_COUNTERS, N_MOM, P_A, P_KV, P_N, P_SIGMA,
                     P_THRESHOLD, P_XI_VAR, ROWS)
from .steps import Stepper
from .steps.dispatch import advance, compose, noise, normals, step, twin_xi


class Setup(NamedTuple):
    """Everything a chunk's loop reads.

    Attributes
    ----------
    P, N : int
        Paths (rings) of this chunk and units per ring.
    nburn, nrun : int
        Burn-in and measured steps of size ``cf_c[CF_H]`` if ``coupled`` else ``cf_f[CF_H]``.
    stride : int
        Moments are accumulated every ``stride``-th step of the measured part (samples far
        closer than the correlation time add cost, not information).
    coupled : bool
        If True, each coarse step ``cf_c`` is also done as two fine steps ``cf_f`` (h/2) on the
        same noise (exact composition): level 0 = fine, 1 = coarse. If False, only level 0 runs,
        with step ``cf_f``.
    third : bool
        With ``coupled``, every two coarse steps are also done as one step ``cf_cc`` (2h) on
        their combined noise: the coarsest level, row 3 of ``sums`` (measured at its own steps
        in the measured window).
    middle : bool
        With ``third``: whether the coarse level itself is stepped and measured. False composes
        only its noise, for the coarsest level: the levels are then the fine one and one four
        times as coarse (row 1 of ``sums`` stays empty).
    coarse_half : bool
        With ``coupled``: the coarse and coarsest levels stop after the first half of the measured
        window (their rows then hold that half only, to be compared with row 2).
    twin : bool
        A harmonic ring (coefficients ``cf_t`` at the fine step, physical vector ``pp_t``) is
        advanced on the fine level's noise and measured with it.
    kind : int
        On-site treatment (:data:`montecarlo.layout.KIND_LINEAR`, ``KIND_KICK``, ``KIND_KINK``).
    cf_f, cf_c, cf_cc, cf_t : ndarray
        Step coefficients (:mod:`montecarlo._kernels`) of the fine, coarse, coarsest and twin
        levels.
    pp, pp_t : ndarray
        Physical vectors of the system and of the twin.
    chol : (4N, 4N) or (0, 0) ndarray
        Initial law: every level (and the twin) starts from one draw of ``chol @ z`` per path,
        or from rest with stationary xi when empty.
    n_ctl : int
        Columns of the control accumulator ``Sums.ctl`` (the sums of every accumulated control,
        :class:`montecarlo.controls.base.Control`; 0 for none).
    mg_at, n_mg, bd_at, n_bd : int
        The martingale sums' first column in it and their number
        (:func:`montecarlo.controls.martingale.basis_names`; 0 without them), and the same for
        the end-of-window terms (:func:`~montecarlo.controls.martingale.boundary_names`).
    gen_at, n_gen, gen_kink, gen_every : int, int, bool, int
        The generator sums' first column and number, whether they carry the kink's hinge terms,
        and the fine steps between their points (:mod:`montecarlo.controls.generator`).
    groups : int
        Replicas in this chunk: its P paths are ``groups`` replicas of P / groups consecutive
        paths each, every sum kept per replica (P a multiple of it).
    """

    P: int
    N: int
    nburn: int
    nrun: int
    stride: int
    coupled: bool
    third: bool
    twin: bool
    kind: int
    cf_f: np.ndarray
    cf_c: np.ndarray
    cf_cc: np.ndarray
    cf_t: np.ndarray
    pp: np.ndarray
    pp_t: np.ndarray
    chol: np.ndarray
    n_ctl: int = 0
    mg_at: int = 0
    n_mg: int = 0
    bd_at: int = 0
    n_bd: int = 0
    gen_at: int = 0
    n_gen: int = 0
    gen_kink: bool = False
    gen_every: int = 1
    groups: int = 1
    middle: bool = True
    coarse_half: bool = False


class Sums(NamedTuple):
    """What a chunk's loop accumulates.

    Attributes
    ----------
    sums : (G, ROWS, N_MOM) ndarray
        Per replica of the chunk (:attr:`Setup.groups`), sums over measured unit-steps of the
        moments :data:`montecarlo.layout.MOMENTS`: fine level, coarse level, fine level over the
        first half of the measured steps, coarsest.
    counts : (G, ROWS) ndarray
        Number of unit-steps summed per replica and row.
    esc_time : (P,) ndarray
        Time at which path p first had some |x_j| > threshold, or -1.
    counters : (N_COUNTERS,) int64 ndarray
        Kink statistics and the number of ring steps taken, all levels (``C_*`` of
        :mod:`montecarlo.layout`).
    ctl : (G, 2, n_ctl) ndarray
        Per replica, the accumulated controls' sums on the fine level over the measured window and
        its first half (:attr:`Setup.n_ctl`).
    """

    sums: np.ndarray
    counts: np.ndarray
    esc_time: np.ndarray
    counters: np.ndarray
    ctl: np.ndarray

    @staticmethod
    def zeros(P: int, n_ctl: int, groups: int = 1) -> Sums:
        """Empty accumulators for a chunk of P paths in ``groups`` replicas with ``n_ctl`` control
        columns."""
        return Sums(np.zeros((groups, ROWS, N_MOM)), np.zeros((groups, ROWS)), np.empty(P),
                    np.zeros(N_COUNTERS, dtype=np.int64),
                    np.zeros((groups, 2, n_ctl)))


def run_chunk(gen: np.random.Generator, stepper: Stepper, s: Setup, out: Sums) -> None:
    """Simulate one chunk of paths with ``stepper`` and add its time averages to ``out``.

    ``gen`` is this chunk's own stream (deterministic for a given seed, whatever the thread
    count)."""
    _run(stepper.tag, gen, s, out)


@njit(cache=True, nogil=True)
def _init_levels(s, f, c, cc, t) -> None:
    """Every level starts where the fine level's start put it (with the same kicked force);
    levels are tuples (x, v, V, xi, F) of (N, P) arrays."""
    # element loops, not slice copies: those compiled numba's shape-checking copy per
    # dimension (about 2 s of a cold start)
    x, v, V, xi, F = f[0], f[1], f[2], f[3], f[4]
    kicked = s.kind != KIND_LINEAR
    for j in range(s.N):
        for p in range(s.P):
            if kicked:
                F[j, p] = _kick_force(x[j, p], s.pp)
            for lv in (c, cc, t):
                lv[0][j, p], lv[1][j, p], lv[2][j, p], lv[3][j, p] = x[j, p], v[j, p], V[j, p], xi[j, p]
            c[4][j, p], cc[4][j, p] = F[j, p], F[j, p]


@njit(cache=True, nogil=True)
def _copy_noise(src, dst) -> None:
    """``dst[:] = src`` for the (nz, N, P) noise arrays, element by element (a slice copy compiles
    numba's shape-checking copy per dimension)."""
    for r in range(src.shape[0]):
        for j in range(src.shape[1]):
            for p in range(src.shape[2]):
                dst[r, j, p] = src[r, j, p]


@njit(cache=True, nogil=True, inline="always")
def _draw(gen, z1, z2, coupled) -> None:
    """The step's standard normals: per unit and path those of ``z1`` and, with ``coupled``, of
    ``z2`` (the fine level's two half steps), in that order."""
    nz, N, P = z1.shape
    for j in range(N):
        for p in range(P):
            for r in range(nz):
                z1[r, j, p] = gen.standard_normal()
            if coupled:
                for r in range(nz):
                    z2[r, j, p] = gen.standard_normal()


@njit(cache=True, nogil=True, inline="always")
def _measure_replicas(G, x, v, V, xi, stuck, F, w, cf, pp, kind, sums, row, counts, pvx) -> None:
    """The system's moments into ``sums[g, row]`` and ``counts[g, row]`` for each of the chunk's G
    replicas: :func:`montecarlo._kernels._measure` for one, ``measure_groups`` for several (the
    same sums per replica; the single-replica loops run a ring 12 % faster, measured)."""
    if G == 1:
        counts[0, row] += _measure(x, v, V, xi, stuck, F, w, cf, pp, kind, sums[0, row], pvx)
    else:
        measure_groups(x, v, V, xi, stuck, F, w, cf, pp, kind, sums, row, counts, pvx)


@njit(cache=True, nogil=True, inline="always")
def _twin_replicas(G, x, v, V, xi, w, cf, sums, row, nn, pvx) -> None:
    """The twin's moments into ``sums[g, row]`` per replica (as :func:`_measure_replicas`)."""
    if G == 1:
        measure_twin(x, v, V, xi, w, cf, sums[0, row], nn, pvx)
    else:
        measure_twin_groups(x, v, V, xi, w, cf, sums, row, nn, pvx)


@njit(cache=True, nogil=True, inline="always")
def _mg_replicas(G, x, v, V, xi, w, a, n, phi, xi0, acc, bd, first, started, decay, var, g_bd, gprev_bd) -> None:
    """The martingale sums into ``acc[g]`` and the end-of-window terms into ``bd[g]`` per
    replica, with their scratch ``g_bd``, ``gprev_bd`` (G, terms) (as :func:`_measure_replicas`)."""
    if G == 1:
        mg_measure(x, v, V, xi, w, a, n, phi, xi0, acc[0], bd[0], first, started, decay, var, g_bd[0], gprev_bd[0])
    else:
        mg_measure_groups(x, v, V, xi, w, a, n, phi, xi0, acc, bd, first, started, decay, var, g_bd, gprev_bd)


@njit(cache=True, nogil=True)
def _gen_point(s, g_fine, g_upd, gen_points, x, v, V, xi, w, gst, gacc, first, cf, pp):
    """Add a generator point every ``s.gen_every`` fine steps of the measured window; returns the
    points taken and the xi updates since the last point, both after this step."""
    if g_fine % s.gen_every != 0:
        return gen_points, g_upd
    dec = cf[CF_XI_DECAY] ** g_upd
    gen_measure(x, v, V, xi, w, gst, gacc, first, gen_points > 0, dec, pp[P_XI_VAR] * (1.0 - dec * dec), s.gen_kink,
                pp[P_A], pp[P_SIGMA], pp[P_KV])
    return gen_points + 1, 0


@njit(cache=True, nogil=True)
def _run(tag, gen, s, out) -> None:
    """The loop of :func:`run_chunk`, compiled once per stepper ``tag``."""
    # every array is a local of its own: reading them out of tuples inside the loop cost 5-20 %
    # in reference counting at the solver's small chunks
    N, P, G, coupled, twin, kind, stride, nburn = s.N, s.P, s.groups, s.coupled, s.twin, s.kind, s.stride, s.nburn
    third = s.third and coupled
    # the coarse level stepped and measured (else only its noise composed, for the coarsest)
    mid = coupled and (s.middle or not third)
    cf_f, cf_c, cf_cc, cf_t, pp, pp_t = s.cf_f, s.cf_c, s.cf_cc, s.cf_t, s.pp, s.pp_t
    sums, counts, counters, esc = out.sums, out.counts, out.counters, out.esc_time
    mg, bd = out.ctl[:, :, s.mg_at:s.mg_at + s.n_mg], out.ctl[:, :, s.bd_at:s.bd_at + s.n_bd]
    thr = pp[P_THRESHOLD]
    # every level's arrays (x, v, V, xi, F, pvx; stuck) allocated here one by one: returned in
    # tuples by a helper, they made the loop copy about twice the array fields before every
    # kernel call
    xf, vf, Vf, xif, Ff, pf = (np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)),
                               np.zeros((N, P)), np.zeros((N, P)))
    xc, vc, Vc, xic, Fc, pc = (np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)),
                               np.zeros((N, P)), np.zeros((N, P)))
    xcc, vcc, Vcc, xicc, Fcc, pcc = (np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)),
                                     np.zeros((N, P)), np.zeros((N, P)))
    xit = twin_xi(tag, xif)
    xt, vt, Vt, Ft, pt = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    sf, sc = np.zeros((N, P), dtype=np.bool_), np.zeros((N, P), dtype=np.bool_)
    scc, st = np.zeros((N, P), dtype=np.bool_), np.zeros((N, P), dtype=np.bool_)
    xm, fext, rbm, rbx = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    cs = np.zeros((3, N_TAYLOR + 1))
    nz = normals(tag)
    z1, z2 = np.zeros((nz, N, P)), np.zeros((nz, N, P))
    e1, e2, et = np.zeros((nz, N, P)), np.zeros((nz, N, P)), np.zeros((nz, N, P))
    ec, ec0, ecc = np.zeros((nz, N, P)), np.zeros((nz, N, P)), np.zeros((nz, N, P))
    w = np.ones(P)
    esc[:] = -1.0
    use_mg = s.n_mg > 0 or s.n_bd > 0
    phi = np.zeros((n_state(N) if s.n_mg > 0 else 0, N, P))
    g_bd, gprev_bd = np.zeros((G, s.n_bd)), np.zeros((G, s.n_bd))
    xi0 = np.zeros((N, P))
    mg_points = 0  # martingale points taken (an int: a bool flag compiled mg_measure twice)
    n_upd = 0  # xi updates of the fine level since the last martingale point
    use_gen = s.n_gen > 0
    gacc = out.ctl[:, :, s.gen_at:s.gen_at + s.n_gen]
    gst = np.zeros((4, N, P if use_gen else 0))
    # generator points taken, xi updates of the fine level since the last one, fine steps of the
    # measured window so far
    gen_points = g_upd = g_fine = 0
    h = cf_c[CF_H] if coupled else cf_f[CF_H]
    _start(gen, s.chol, math.sqrt(pp[P_XI_VAR]), xf, vf, Vf, xif)
    _clamp_start(xf, kind, pp, h)
    _init_levels(s, (xf, vf, Vf, xif, Ff), (xc, vc, Vc, xic, Fc), (xcc, vcc, Vcc, xicc, Fcc),
                 (xt, vt, Vt, xit, Ft))
    cc_stride = max(1, stride // 2)
    half = nburn + s.nrun // 2
    # the steps after which the coarser levels stop
    c_end = half if s.coarse_half else nburn + s.nrun
    for it in range(nburn + s.nrun):
        live = _live(w)
        if live == 0:
            break
        meas = it >= nburn and (it - nburn) % stride == 0
        first = it < half
        t_end = (it + 1) * h
        mid_now, third_now = mid and it < c_end, third and it < c_end
        counters[C_RING_STEPS] += (3 if mid_now else 2 if coupled else 1) * live
        _draw(gen, z1, z2, coupled)
        for sub in range(2 if coupled else 1):
            zz = z1 if sub == 0 else z2
            ee = e1 if sub == 0 else e2
            noise(tag, cf_f, zz, ee)
            n_upd += 1
            g_upd += 1
            step(tag, xf, vf, Vf, xif, Ff, sf, pf, ee, cf_f, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen)
            if twin:
                noise(tag, cf_t, zz, et)
                step(tag, xt, vt, Vt, xit, Ft, st, pt, et, cf_t, pp_t, KIND_LINEAR, xm, fext,
                     cs, rbm, rbx, w, counters, gen)
            if sub == 1 and (mid_now or third_now):
                compose(tag, cf_f, cf_c, e1, e2, ec)
                if mid_now:
                    step(tag, xc, vc, Vc, xic, Fc, sc, pc, ec, cf_c, pp, kind, xm, fext, cs, rbm, rbx, w, counters,
                         gen)
                    _check_escape(xc, vc, Vc, xic, Fc, sc, w, thr, t_end, esc)
            _check_escape(xf, vf, Vf, xif, Ff, sf, w, thr, t_end - (0.5 * h if coupled and sub == 0 else 0.0), esc)
            if use_gen and it >= nburn:
                gen_points, g_upd = _gen_point(s, g_fine, g_upd, gen_points, xf, vf, Vf, xif, w, gst, gacc, first,
                                               cf_f, pp)
                g_fine += 1
            if meas:
                _measure_replicas(G, xf, vf, Vf, xif, sf, Ff, w, cf_f, pp, kind, sums, 0, counts, pf)
                if use_mg and sub == 0:
                    dec = cf_f[CF_XI_DECAY] ** n_upd
                    _mg_replicas(G, xf, vf, Vf, xif, w, pp[P_A], pp[P_N], phi, xi0, mg, bd, first, mg_points > 0, dec,
                                 pp[P_XI_VAR] * (1.0 - dec * dec), g_bd, gprev_bd)
                    mg_points += 1
                    n_upd = 0
                if twin:
                    _twin_replicas(G, xt, vt, Vt, xit, w, cf_t, sums, 0, pp[P_N], pt)
                if first:
                    _measure_replicas(G, xf, vf, Vf, xif, sf, Ff, w, cf_f, pp, kind, sums, 2, counts, pf)
                    if twin:
                        _twin_replicas(G, xt, vt, Vt, xit, w, cf_t, sums, 2, pp[P_N], pt)
                if mid_now and sub == 1:
                    _measure_replicas(G, xc, vc, Vc, xic, sc, Fc, w, cf_c, pp, kind, sums, 1, counts, pc)
            advance(tag, xif, ee, cf_f)
        if mid_now:
            advance(tag, xic, ec, cf_c)
        if third_now and it % 2 == 1:
            counters[C_RING_STEPS] += live
            compose(tag, cf_c, cf_cc, ec0, ec, ecc)
            step(tag, xcc, vcc, Vcc, xicc, Fcc, scc, pcc, ecc, cf_cc, pp, kind, xm, fext, cs, rbm, rbx, w, counters,
                 gen)
            _check_escape(xcc, vcc, Vcc, xicc, Fcc, scc, w, thr, t_end, esc)
            if it >= nburn and ((it - nburn) // 2) % cc_stride == 0:
                _measure_replicas(G, xcc, vcc, Vcc, xicc, scc, Fcc, w, cf_cc, pp, kind, sums, 3, counts, pcc)
            advance(tag, xicc, ecc, cf_cc)
        elif third_now:
            _copy_noise(ec, ec0)
    if use_gen:
        gen_close(gacc)
