"""The path loop of one chunk: every level of P rings through burn-in and measured window.

Private module. One loop serves every step scheme (:mod:`montecarlo.steps`): the scheme's tag
selects its kernels at compile time (:mod:`montecarlo.steps.dispatch`), so numba compiles one
specialised loop per scheme. The levels: fine (``dt/2`` with Richardson coupling, else ``dt``),
coarse (``dt``, on the fine level's noise), coarsest (``2 dt``, optional) and the harmonic twin
(on the fine level's noise, measured with it, :mod:`montecarlo.controls.twin`); the martingale
sums ride on the fine level (:mod:`montecarlo.controls.martingale`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ._kernels import (KIND_LINEAR, N_MOM, ROWS, Scratch, _check_escape, _clamp_start, _kick_force, _live,
                       _measure, _start, new_level)
from ._kink import N_TAYLOR
from .controls.martingale import MG_DIST, mg_measure, n_state
from .controls.twin import measure_twin
from .steps import StepScheme
from .steps.dispatch import advance, compose, noise, step, twin_xi


class Setup(NamedTuple):
    """Everything a chunk's loop reads.

    Attributes
    ----------
    P, N : int
        Paths (rings) of this chunk and units per ring.
    nburn, nrun : int
        Burn-in and measured steps of size ``cf_c[12]`` if ``coupled`` else ``cf_f[12]``.
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
    twin : bool
        A harmonic ring (coefficients ``cf_t`` at the fine step, physical vector ``pp_t``) is
        advanced on the fine level's noise and measured with it.
    kind : int
        On-site treatment (:data:`montecarlo._kernels.KIND_LINEAR`, ``KIND_KICK``, ``KIND_KINK``).
    cf_f, cf_c, cf_cc, cf_t : ndarray
        Step coefficients (:mod:`montecarlo._kernels`) of the fine, coarse, coarsest and twin
        levels.
    pp, pp_t : ndarray
        Physical vectors of the system and of the twin.
    chol : (4N, 4N) or (0, 0) ndarray
        Initial law: every level (and the twin) starts from one draw of ``chol @ z`` per path,
        or from rest with stationary xi when empty.
    n_mart : int
        Martingale control columns (:func:`montecarlo.controls.martingale.basis_names`), 0 for
        none.
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
    n_mart: int


class Sums(NamedTuple):
    """What a chunk's loop accumulates.

    Attributes
    ----------
    sums : (ROWS, N_MOM) ndarray
        Sums over measured unit-steps of the moments :data:`montecarlo._kernels.MOMENTS`: fine
        level, coarse level, fine level over the first half of the measured steps, coarsest.
    counts : (ROWS,) ndarray
        Number of unit-steps summed per row.
    esc_time : (P,) ndarray
        Time at which path p first had some |x_j| > threshold, or -1.
    counters : (5,) int64 ndarray
        Kink statistics (slow-path unit steps, crossings, averaged-map entries, exhausted event
        budgets) and, in slot 4, the number of ring steps taken (all levels).
    mart : (2, n_mart) ndarray
        Martingale control sums of the fine level over the measured window and its first half.
    """

    sums: np.ndarray
    counts: np.ndarray
    esc_time: np.ndarray
    counters: np.ndarray
    mart: np.ndarray

    @staticmethod
    def zeros(P: int, n_mart: int) -> Sums:
        return Sums(np.zeros((ROWS, N_MOM)), np.zeros(ROWS), np.empty(P), np.zeros(5, dtype=np.int64),
                    np.zeros((2, n_mart)))


def run_chunk(gen: np.random.Generator, scheme: StepScheme, s: Setup, out: Sums) -> None:
    """Simulate one chunk of paths with ``scheme`` and add its time averages to ``out``.

    ``gen`` is this chunk's own stream (deterministic for a given seed, whatever the thread
    count)."""
    _run(scheme.tag, gen, s, out)


@njit(cache=True, nogil=True)
def _init_levels(s, f, c, cc, t) -> None:
    """Every level starts where the fine level's start put it (with the same kicked force)."""
    for j in range(s.N):
        for p in range(s.P):
            for lv in (c, cc):
                lv.x[j, p], lv.v[j, p], lv.V[j, p], lv.xi[j, p] = f.x[j, p], f.v[j, p], f.V[j, p], f.xi[j, p]
            t.x[j, p], t.v[j, p], t.V[j, p], t.xi[j, p] = f.x[j, p], f.v[j, p], f.V[j, p], f.xi[j, p]
            if s.kind != KIND_LINEAR:
                f.F[j, p] = _kick_force(f.x[j, p], s.pp)
                c.F[j, p] = f.F[j, p]
                cc.F[j, p] = f.F[j, p]


@njit(cache=True, nogil=True)
def _draw(gen, z1, z2, coupled: bool) -> None:
    """The step's normals, unit by unit: z1 (and z2 for the second fine substep)."""
    nz, N, P = z1.shape
    for j in range(N):
        for p in range(P):
            for r in range(nz):
                z1[r, j, p] = gen.standard_normal()
            if coupled:
                for r in range(nz):
                    z2[r, j, p] = gen.standard_normal()


@njit(cache=True, nogil=True)
def _run(tag, gen, s, out) -> None:
    N, P = s.N, s.P
    third = s.third and s.coupled
    cf_f, cf_c, cf_cc, pp, kind = s.cf_f, s.cf_c, s.cf_cc, s.pp, s.kind
    sums, counts, counters, mg = out.sums, out.counts, out.counters, out.mart
    thr = pp[10]
    f = new_level(N, P, np.zeros((N, P)))
    c = new_level(N, P, np.zeros((N, P)))
    cc = new_level(N, P, np.zeros((N, P)))
    t = new_level(N, P, twin_xi(tag, f.xi))
    scr = Scratch(np.zeros((N, P)), np.zeros((N, P)), np.zeros((3, N_TAYLOR + 1)), np.zeros((N, P)),
                  np.zeros((N, P)))
    nz = tag.normals
    z1, z2 = np.zeros((nz, N, P)), np.zeros((nz, N, P))
    e1, e2, et = np.zeros((nz, N, P)), np.zeros((nz, N, P)), np.zeros((nz, N, P))
    ec, ec0, ecc = np.zeros((nz, N, P)), np.zeros((nz, N, P)), np.zeros((nz, N, P))
    w = np.ones(P)
    out.esc_time[:] = -1.0
    use_mg = s.n_mart > 0
    phi = np.zeros((n_state(N) if use_mg else 0, N, P))
    n_bd = s.n_mart - n_state(N) - min(N // 2, MG_DIST) - 1 if use_mg else 0
    g_bd, gprev_bd = np.zeros(max(n_bd, 0)), np.zeros(max(n_bd, 0))
    xi0 = np.zeros((N, P))
    mg_started = False
    n_upd = 0  # xi updates of the fine level since the last martingale point
    h = cf_c[12] if s.coupled else cf_f[12]
    _start(gen, s.chol, math.sqrt(pp[11]), f.x, f.v, f.V, f.xi)
    _clamp_start(f.x, kind, pp, h)
    _init_levels(s, f, c, cc, t)
    cc_stride = max(1, s.stride // 2)
    half = s.nburn + s.nrun // 2
    for it in range(s.nburn + s.nrun):
        live = _live(w)
        if live == 0:
            break
        meas = it >= s.nburn and (it - s.nburn) % s.stride == 0
        first = it < half
        t_end = (it + 1) * h
        counters[4] += (3 if s.coupled else 1) * live
        _draw(gen, z1, z2, s.coupled)
        ea, eb = e1, e2  # the fine substeps' noise, as the scheme's noise() returns it
        for sub in range(2 if s.coupled else 1):
            ee = noise(tag, cf_f, z1 if sub == 0 else z2, e1 if sub == 0 else e2)
            if sub == 0:
                ea = ee
            else:
                eb = ee
            n_upd += 1
            step(tag, f, ee, cf_f, pp, kind, scr, w, counters, gen)
            if s.twin:
                step(tag, t, noise(tag, s.cf_t, z1 if sub == 0 else z2, et), s.cf_t, s.pp_t, KIND_LINEAR, scr,
                     w, counters, gen)
            if s.coupled and sub == 1:
                compose(tag, cf_f, cf_c, ea, eb, ec)
                step(tag, c, ec, cf_c, pp, kind, scr, w, counters, gen)
                _check_escape(c.x, c.v, c.V, c.xi, c.F, c.stuck, w, thr, t_end, out.esc_time)
            _check_escape(f.x, f.v, f.V, f.xi, f.F, f.stuck, w, thr,
                          t_end - (0.5 * h if s.coupled and sub == 0 else 0.0), out.esc_time)
            if meas:
                counts[0] += _measure(f.x, f.v, f.V, f.xi, f.stuck, f.F, w, cf_f, pp, kind, sums[0], f.pvx)
                if use_mg and sub == 0:
                    dec = cf_f[13] ** n_upd
                    mg_measure(f.x, f.v, f.V, f.xi, w, pp[7], pp[8], phi, xi0, mg, first, mg_started, dec,
                               pp[11] * (1.0 - dec * dec), g_bd, gprev_bd)
                    mg_started = True
                    n_upd = 0
                if s.twin:
                    measure_twin(t.x, t.v, t.V, t.xi, w, s.cf_t, sums[0], pp[8], t.pvx)
                if first:
                    counts[2] += _measure(f.x, f.v, f.V, f.xi, f.stuck, f.F, w, cf_f, pp, kind, sums[2], f.pvx)
                    if s.twin:
                        measure_twin(t.x, t.v, t.V, t.xi, w, s.cf_t, sums[2], pp[8], t.pvx)
                if s.coupled and sub == 1:
                    counts[1] += _measure(c.x, c.v, c.V, c.xi, c.stuck, c.F, w, cf_c, pp, kind, sums[1], c.pvx)
            advance(tag, f, ee, cf_f)
        if s.coupled:
            advance(tag, c, ec, cf_c)
        if third and it % 2 == 1:
            counters[4] += live
            compose(tag, cf_c, cf_cc, ec0, ec, ecc)
            step(tag, cc, ecc, cf_cc, pp, kind, scr, w, counters, gen)
            _check_escape(cc.x, cc.v, cc.V, cc.xi, cc.F, cc.stuck, w, thr, t_end, out.esc_time)
            if it >= s.nburn and ((it - s.nburn) // 2) % cc_stride == 0:
                counts[3] += _measure(cc.x, cc.v, cc.V, cc.xi, cc.stuck, cc.F, w, cf_cc, pp, kind, sums[3],
                                      cc.pvx)
            advance(tag, cc, ecc, cf_cc)
        elif third:
            ec0[:] = ec
