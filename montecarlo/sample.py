"""Samples of the stationary state (x, v, V, xi) from the Monte Carlo integrator.

The estimators of :mod:`montecarlo.simulate` keep only time averages of moments; densities
(histograms of the state, its law near the kink's trap at (x, v) = (0, 0)) need the states
themselves. :func:`sample_states` runs the same splitting step as the solver (the same
kernel, :func:`montecarlo.steps.frozen.d_step`, and the exact Ornstein--Uhlenbeck update of xi)
and records every unit's state at a fixed interval after a burn-in.

Samples along one path are correlated (correlation time ~ max(1/gamma, tau, tau_p)); use
``every`` of that order, or count independent samples as ``paths * t_run / correlation time``.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from fpe_harvester.errors import ParameterError, check_int, check_real
from fpe_harvester.model import Harvester

from ._kernels import _kick_force
from ._kink import N_TAYLOR
from .coefficients import onsite_kind, physical_vector, step_coefficients
from .layout import CF_XI_DECAY, CF_XI_NOISE, KIND_LINEAR, N_COUNTERS, P_XI_VAR
from .steps.frozen import d_step

__all__ = ["sample_states"]

#: Paths per chunk (one random stream each: the samples do not depend on the thread count).
_CHUNK = 128

#: Escape amplitude of the sampler's paths (no path of a confined system comes near it).
_THRESHOLD = 1e6


@njit(cache=True, nogil=True)
def _sample(gen, P: int, N: int, nburn: int, nsamp: int, stride: int, cf: np.ndarray,
            pp: np.ndarray, kind: int, out: np.ndarray) -> None:
    """Run P rings of N units from rest (xi stationary); out[s, p, j] = (x, v, V, xi) after
    ``nburn + (s + 1) * stride`` steps."""
    x, v, V = np.zeros((N, P)), np.zeros((N, P)), np.zeros((N, P))
    xi, F = np.zeros((N, P)), np.zeros((N, P))
    stuck = np.zeros((N, P), dtype=np.bool_)
    xm, fext = np.zeros((N, P)), np.zeros((N, P))
    w = np.ones(P)
    cs = np.zeros((3, N_TAYLOR + 1))
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    sd = math.sqrt(pp[P_XI_VAR])
    for j in range(N):
        for p in range(P):
            xi[j, p] = sd * gen.standard_normal()
            if kind != KIND_LINEAR:
                F[j, p] = _kick_force(x[j, p], pp)
    s = 0
    for step in range(nburn + nsamp * stride):
        d_step(x, v, V, xi, F, stuck, xm, fext, w, cf, pp, kind, counters, cs)
        for j in range(N):
            for p in range(P):
                xi[j, p] = cf[CF_XI_DECAY] * xi[j, p] + cf[CF_XI_NOISE] * gen.standard_normal()
        if step >= nburn and (step + 1 - nburn) % stride == 0:
            for p in range(P):
                for j in range(N):
                    out[s, p, j, 0] = x[j, p]
                    out[s, p, j, 1] = v[j, p]
                    out[s, p, j, 2] = V[j, p]
                    out[s, p, j, 3] = xi[j, p]
            s += 1


def sample_states(h: Harvester, *, samples: int = 1000, paths: int = 1000, every: float = 1.0,
                  t_burn: float = 50.0, dt: float = 0.01, seed: int = 0,
                  threads: int | None = None) -> np.ndarray:
    """States of ``paths`` independent rings sampled every ``every`` time units.

    Parameters
    ----------
    h : Harvester
        The problem (any n, any ring size; an unstable ring's samples grow without bound).
    samples : int
        Samples per path, >= 1.
    paths : int
        Independent paths, >= 1.
    every : float
        Time between samples [time units], >= dt (rounded to a whole number of steps).
    t_burn : float
        Time from rest (xi drawn from its stationary law) to the first sample, >= 0.
    dt : float
        Time step, > 0. The integrator's bias is O(dt^2) on smooth observables (measured order 2
        at the kink too); densities on scales below the distance travelled in a step are not
        resolved.
    seed : int
        Seed of the ``SeedSequence``; one stream per chunk of paths.
    threads : int, optional
        Worker threads (default: the number of CPUs); the samples do not depend on it.

    Returns
    -------
    ndarray, shape (samples, paths, N, 4)
        ``[..., 0:4] = (x, v, V, xi)``; ``xi`` is the noise at the end of the step, the others
        after the step's deterministic flow (the state the estimators measure).

    Examples
    --------
    >>> s = sample_states(Harvester.build(a=0.5, n=2), samples=10, paths=50, every=1.0)
    >>> s.shape
    (10, 50, 1, 4)
    """
    samples = check_int("samples", samples, low=1)
    paths = check_int("paths", paths, low=1)
    dt = check_real("dt", dt, low=0.0, low_open=True)
    every = check_real("every", every, low=dt)
    t_burn = check_real("t_burn", t_burn, low=0.0)
    seed = check_int("seed", seed, low=0)
    if samples * paths * h.N > 50_000_000:
        raise ParameterError(f"samples * paths * N must be <= 5e7 (400 MB per state component), got "
                             f"{samples} * {paths} * {h.N}")
    threads = max(1, threads or len(os.sched_getaffinity(0)))
    cf = step_coefficients(h, dt)
    kind = onsite_kind(h)
    pp = physical_vector(h, _THRESHOLD, kind=kind)
    stride = max(1, int(round(every / dt)))
    nburn = int(round(t_burn / dt))
    n_chunks = -(-paths // _CHUNK)
    sizes = [paths // n_chunks + (1 if c < paths % n_chunks else 0) for c in range(n_chunks)]
    out = np.empty((samples, paths, h.N, 4))
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    ss = np.random.SeedSequence(seed)

    def work(c: int) -> None:
        gen = np.random.Generator(np.random.PCG64(np.random.SeedSequence(ss.entropy, spawn_key=(c,))))
        block = np.empty((samples, sizes[c], h.N, 4))
        _sample(gen, sizes[c], h.N, nburn, samples, stride, cf, pp, kind, block)
        out[:, offsets[c]:offsets[c + 1]] = block

    if threads == 1:
        for c in range(n_chunks):
            work(c)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(work, range(n_chunks)))
    if not np.all(np.isfinite(out)):
        raise FloatingPointError("sampled states are not finite: the system is unstable or dt too large")
    return out
