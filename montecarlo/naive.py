"""Reference: the plain vectorized numpy Euler--Maruyama scheme (for validation and speed).

.. math::

    x' = x + v\\,h,\\quad
    v' = v + \\frac{h}{m}\\left[-U'(x) - m\\gamma v - K_vV + \\sigma\\xi + k\\,\\Delta x\\right],\\quad
    V' = V + h(K_cv - V/\\tau_p),\\quad
    \\xi' = \\xi - \\frac{h}{\\tau}\\xi + \\frac{\\sqrt{2Dh}}{\\tau}Z

with :math:`-U'(x) = -a n |x|^{n-1}\\mathrm{sign}(x)` (so ``-a sign(x)`` at n = 1, no
crossing location, no sticking). Weak order 1, and lower at the kink: this is the scheme
the engine is measured against, not one to use.
"""

from __future__ import annotations

import time

import numpy as np

from fpe_harvester.errors import ParameterError, check_int, check_real
from fpe_harvester.model import Harvester

from .ensemble import Ensemble
from .layout import N_MOM

__all__ = ["simulate_naive"]


def simulate_naive(
    h: Harvester,
    *,
    dt: float = 0.01,
    paths: int = 256,
    replicas: int = 8,
    t_burn: float = 20.0,
    t_run: float = 100.0,
    seed: int | None = None,
) -> Ensemble:
    """Euler--Maruyama ensemble with all replicas' paths advanced together by numpy.

    Parameters are as in :func:`montecarlo.simulate` (no escape detection, no Richardson).

    Examples
    --------
    >>> e = simulate_naive(Harvester.build(a=0.5), dt=0.05, paths=4, replicas=2, t_burn=1.0,
    ...                    t_run=2.0, seed=3)
    >>> e.counts[:, 0].tolist()
    [160.0, 160.0]
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    dt = check_real("dt", dt, low=0.0, low_open=True)
    paths = check_int("paths", paths, low=2)
    replicas = check_int("replicas", replicas, low=1)
    t_burn = check_real("t_burn", t_burn, low=0.0)
    t_run = check_real("t_run", t_run, low=0.0, low_open=True)
    p = h.params
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    shape = (replicas, paths, h.N)
    x, v, V = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    xi = rng.standard_normal(shape) * np.sqrt(p.noise_variance)
    nburn, nrun = int(round(t_burn / dt)), max(1, int(round(t_run / dt)))
    amp = np.sqrt(2.0 * p.D * dt) / p.tau
    sums = np.zeros((replicas, 2, N_MOM))  # level 0, and level 0 over the first half
    half = nburn + nrun // 2
    t0 = time.perf_counter()
    for step in range(nburn + nrun):
        force = h.potential.force(x) - p.m * p.gamma * v - p.Kv * V + p.sigma * xi
        if h.N > 1:
            force += h.k * (np.roll(x, 1, axis=2) - 2.0 * x + np.roll(x, -1, axis=2))
        x, v, V, xi = (
            x + dt * v,
            v + (dt / p.m) * force,
            V + dt * (p.Kc * v - V / p.tau_p),
            xi - (dt / p.tau) * xi + amp * rng.standard_normal(shape),
        )
        if step >= nburn:
            for row in (0, 1) if step < half else (0,):
                sums[:, row, 0] += (V * V).sum(axis=(1, 2))
                sums[:, row, 1] += (v * V).sum(axis=(1, 2))
                sums[:, row, 2] += (v * v).sum(axis=(1, 2))
                sums[:, row, 3] += (x * x).sum(axis=(1, 2))
                sums[:, row, 4] += (v * xi).sum(axis=(1, 2))
                sums[:, row, 6] -= (x * h.potential.force(x)).sum(axis=(1, 2))
    wall = time.perf_counter() - t0
    return Ensemble(
        sums=sums,
        counts=np.tile([float(nrun * paths * h.N), float((nrun // 2) * paths * h.N)], (replicas, 1)),
        escape_times=np.full((replicas, paths), np.inf),
        dts=(dt,),
        paths=paths,
        t_burn=nburn * dt,
        t_run=nrun * dt,
        threshold=np.inf,
        path_steps=replicas * paths * (nburn + nrun),
        wall_time=wall,
        seed_entropy=seed,
        notes={"integrator": "numpy Euler-Maruyama"},
    )
