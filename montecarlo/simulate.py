"""Ensembles of independent replicas: the lower-level entry point of the Monte Carlo engine.

A *replica* is ``paths`` independent rings started at rest (x = v = V = 0, xi drawn from
its stationary law), run for ``t_burn`` without measuring and then for ``t_run`` while the
moments are averaged over time, units and paths. Replicas are statistically independent,
so their spread gives honest standard errors (the samples inside one path are correlated).

Random numbers: every chunk of paths owns a :class:`numpy.random.Generator` (PCG64) seeded by
``SeedSequence(seed, spawn_key=(replica, chunk))`` and drawn from inside the numba kernel
(measured fastest, see ``validation/bench/montecarlo.py``). Chunks run on a thread pool with
the GIL released, so results depend on the seed only, not on the number of threads.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from fpe_harvester.errors import ParameterError, check_int, check_real
from fpe_harvester.model import Harvester

from ._kernels import KIND_KICK, KIND_KINK, MOMENTS, N_MOM, ROWS, run_chunk
from ._martingale import basis_names
from .scheme import (KINK_RULES, joint_step_refusal, physical_vector, scheme_kind, step_coefficients,
                     uses_joint_step)
from .twin import initial_cholesky, twin_expectations, twin_harvester, twin_is_stable

__all__ = ["Ensemble", "simulate", "default_threads"]


def default_threads() -> int:
    """Number of worker threads: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


@dataclass(frozen=True)
class Ensemble:
    """Raw result of :func:`simulate`: per-replica sums, counts and escape times.

    Attributes
    ----------
    sums : ndarray, shape (replicas, levels + 1, len(MOMENTS))
        Sums over measured unit-steps of the moments :data:`montecarlo._kernels.MOMENTS`
        (``v xi`` already at the Strang point, or after a joint step its conditional expectation
        given the state before the step and the x reached; the twin's ``t_*`` at level 0 only),
        per level;
        the last row is level 0 over the first half of the measured window.
    counts : ndarray, shape (replicas, levels + 1)
        Number of unit-steps summed (fewer than ``paths * N * t_run/dt`` when paths escaped).
    escape_times : ndarray, shape (replicas, paths)
        Time of the first ``|x_j| > threshold`` of each path (burn-in included), ``inf`` if none.
    dts : tuple of float
        Time step of each level: ``(dt,)``, or ``(dt/2, dt)`` with Richardson coupling, or
        ``(dt/2, dt, 2 dt)`` with its third level.
    twin_kappa : float or None
        On-site stiffness of the harmonic twin run on level 0's noise (None: no twin).
    twin_mean : dict of float
        Exact expectations of the twin's moments at level 0's step
        (:func:`montecarlo.twin.twin_expectations`); empty without a twin.
    start : str
        ``"rest"`` or ``"twin"`` (the paths start from the twin's stationary law).
    kink_counters : tuple of int
        Kink scheme: unit-steps on the slow path (near x = 0), located zero crossings, entries
        into the averaged swing map, steps that exhausted the event budget (all levels).
    mart : ndarray, shape (replicas, 2, len(mart_names))
        Martingale control sums of level 0 (:mod:`montecarlo._martingale`) over the measured
        window and over its first half; no columns without ``martingale``.
    mart_names : tuple of str
        Their names (:func:`montecarlo._martingale.basis_names`).
    """

    sums: np.ndarray
    counts: np.ndarray
    escape_times: np.ndarray
    dts: tuple[float, ...]
    paths: int
    t_burn: float
    t_run: float
    threshold: float
    path_steps: int
    wall_time: float
    kink_counters: tuple[int, int, int, int] = (0, 0, 0, 0)
    seed_entropy: int | None = None
    first_replica: int = 0
    notes: dict[str, object] = field(default_factory=dict)
    twin_kappa: float | None = None
    twin_mean: dict[str, float] = field(default_factory=dict)
    start: str = "rest"
    mart: np.ndarray | None = None
    mart_names: tuple[str, ...] = ()

    @property
    def replicas(self) -> int:
        return int(self.sums.shape[0])

    @property
    def levels(self) -> int:
        """Number of time-step levels (1, or 2 or 3 with Richardson coupling)."""
        return len(self.dts)

    def moments(self, level: int = 0) -> dict[str, np.ndarray]:
        """Per-replica averages ``{name: array(replicas)}`` of one level (NaN where nothing counted).

        ``level = -1`` gives level 0 over the first half of the measured window.
        """
        cnt = self.counts[:, level]
        safe = np.where(cnt > 0, cnt, 1.0)
        out = {name: np.where(cnt > 0, self.sums[:, level, i] / safe, np.nan) for i, name in enumerate(MOMENTS)}
        return out

    def martingale(self, first_half: bool = False) -> dict[str, np.ndarray]:
        """Per-replica martingale controls ``{name: array(replicas)}``, each sum divided by the
        unit-steps counted in its window (NaN where nothing counted); every one has mean 0
        exactly when no path escaped. Empty without ``martingale``."""
        if self.mart is None or not self.mart_names:
            return {}
        cnt = self.counts[:, -1 if first_half else 0]
        safe = np.where(cnt > 0, cnt, 1.0)
        row = self.mart[:, 1 if first_half else 0]
        return {name: np.where(cnt > 0, row[:, i] / safe, np.nan) for i, name in enumerate(self.mart_names)}

    def escaped_fraction(self) -> float:
        """Fraction of all paths that crossed the escape threshold."""
        return float(np.isfinite(self.escape_times).mean())

    def merge(self, other: Ensemble) -> Ensemble:
        """Concatenate the replicas of two runs with identical settings."""
        if (other.dts, other.paths, other.t_run, other.t_burn, other.twin_kappa, other.start,
                other.mart_names) != (self.dts, self.paths, self.t_run, self.t_burn, self.twin_kappa,
                                      self.start, self.mart_names):
            raise ParameterError("can only merge ensembles with the same dt, paths, t_run, t_burn, "
                                 "twin, start and martingale controls")
        return Ensemble(
            sums=np.concatenate([self.sums, other.sums]),
            counts=np.concatenate([self.counts, other.counts]),
            escape_times=np.concatenate([self.escape_times, other.escape_times]),
            dts=self.dts, paths=self.paths, t_burn=self.t_burn, t_run=self.t_run,
            threshold=self.threshold,
            path_steps=self.path_steps + other.path_steps,
            wall_time=self.wall_time + other.wall_time,
            kink_counters=tuple(a + b for a, b in zip(self.kink_counters, other.kink_counters)),
            seed_entropy=self.seed_entropy,
            first_replica=min(self.first_replica, other.first_replica),
            notes=dict(self.notes),
            twin_kappa=self.twin_kappa,
            twin_mean=dict(self.twin_mean),
            start=self.start,
            mart=None if self.mart is None else np.concatenate([self.mart, other.mart]),
            mart_names=self.mart_names,
        )


def _chunks(paths: int, chunk: int) -> list[int]:
    full, rest = divmod(paths, chunk)
    return [chunk] * full + ([rest] if rest else [])


def simulate(
    h: Harvester,
    *,
    dt: float = 0.02,
    paths: int = 256,
    replicas: int = 8,
    t_burn: float = 20.0,
    t_run: float = 100.0,
    seed: int | None = None,
    richardson: bool = False,
    threshold: float = 100.0,
    chunk: int = 256,
    threads: int | None = None,
    first_replica: int = 0,
    sample_every: float = 0.05,
    twin: float | None = None,
    start: str = "rest",
    kink_rule: str = "average",
    kind: int | None = None,
    joint: bool | None = None,
    martingale: bool = False,
    third_level: bool = False,
) -> Ensemble:
    """Simulate independent replicas of ``h`` and return their raw moment sums.

    Parameters
    ----------
    h : Harvester
        Any potential (n >= 1), ring size and coupling.
    dt : float
        Time step, > 0. With ``richardson=True`` the ensemble runs at ``dt/2`` (level 0)
        and at ``dt`` (level 1) on the same Brownian paths.
    paths : int
        Paths (rings) per replica, >= 2.
    replicas : int
        Number of independent replicas, >= 1.
    t_burn, t_run : float
        Burn-in (>= 0) and measuring time (> 0) per path, in model time units.
    seed : int or None
        Root of the :class:`numpy.random.SeedSequence`; None draws fresh entropy (recorded in
        ``seed_entropy`` so that the run can be repeated).
    richardson : bool
        Run the coupled coarse level too (bias estimate at 1.5x the cost of level 0).
    threshold : float
        Escape amplitude, > 0: a path stops at its first ``|x_j| > threshold``.
    chunk : int
        Paths per random stream / task, >= 1.
    threads : int or None
        Worker threads (default: the usable CPUs). Results do not depend on it.
    first_replica : int
        Index of the first replica in the seed tree (continuing a run draws new streams).
    sample_every : float
        Time between accumulated samples, >= 0 (rounded to whole steps of ``dt``; 0 = every
        step). The default 0.05 is far below the correlation times (~1), so the standard
        error is unchanged while the accumulation cost drops.
    twin : float or None
        On-site stiffness :math:`\\kappa > 0` of a harmonic twin ring (same k) advanced on the
        fine level's noise and measured with it (:mod:`montecarlo.twin`); its modes
        :math:`\\kappa + 4k\\sin^2(\\pi q/N)` must all be positive. None: no twin.
    start : {"rest", "twin"}
        Initial state of every path: rest (x = v = V = 0, xi stationary), or a draw from the
        twin's stationary law at the fine step (needs ``twin``, or a harmonic ``h``, which is
        then its own twin). The twin always starts from its own law when ``start="twin"``;
        with ``start="rest"`` a twin starts at rest too, and its expectations are then not
        those of :attr:`Ensemble.twin_mean` during the transient.
    kink_rule : {"average", "hold"}
        Kink scheme only: swings much shorter than the step are advanced by the averaged map
        of their amplitude (``"average"``), or followed until 64 crossings in one step and the
        unit then held at rest (``"hold"``, a time-step artifact kept to compare with;
        :data:`montecarlo.scheme.KINK_RULES`).
    kind : int or None
        Scheme (:data:`montecarlo._kernels.KIND_KICK` or ``KIND_KINK``; default
        :func:`montecarlo.scheme.scheme_kind`), for comparing the schemes near n = 1.
    joint : bool or None
        Advance (x, v, V, xi) together by the exact Gaussian transition of the linear drift
        (True) or with xi frozen over each step (False). None (default): joint when
        tau < :data:`montecarlo.scheme.JOINT_STEPS` dt, where freezing xi is wrong
        (:func:`montecarlo.scheme.uses_joint_step`). True raises where the scheme has no joint
        step (:func:`montecarlo.scheme.joint_step_refusal`).
    martingale : bool
        Also accumulate level 0's martingale control sums (:mod:`montecarlo._martingale`,
        :attr:`Ensemble.mart`): sums of basis functions of the state times the noise drawn
        after it, with mean exactly 0. The simulated paths are the same with or without them.
    third_level : bool
        With ``richardson``, also run level 2 at ``2 dt`` on the same noise (two coarse
        increments composed exactly), so that two Richardson extrapolations, from
        ``(dt, dt/2)`` and from ``(2 dt, dt)``, can be compared (:func:`montecarlo.estimate`);
        it adds a quarter of level 0's steps (measured on the ring n = 3, N = 3, k = -0.5 with
        twin and martingale sums, one thread, median of 3: 1.24x and 1.31x the CPU of level 0
        alone for two and three levels). Ignored without ``richardson``.

    Returns
    -------
    Ensemble

    Examples
    --------
    >>> e = simulate(Harvester.build(a=0.5), dt=0.05, paths=4, replicas=2, t_burn=1.0,
    ...              t_run=2.0, seed=3)
    >>> e.sums.shape, float(e.counts[0, 0])
    ((2, 2, 18), 160.0)
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    dt = check_real("dt", dt, low=0.0, low_open=True)
    paths = check_int("paths", paths, low=2)
    replicas = check_int("replicas", replicas, low=1)
    t_burn = check_real("t_burn", t_burn, low=0.0)
    t_run = check_real("t_run", t_run, low=0.0, low_open=True)
    threshold = check_real("threshold", threshold, low=0.0, low_open=True)
    chunk = check_int("chunk", chunk, low=1)
    threads = default_threads() if threads is None else check_int("threads", threads, low=1)
    first_replica = check_int("first_replica", first_replica, low=0)
    if seed is not None:
        seed = check_int("seed", seed, low=0)
    sample_every = check_real("sample_every", sample_every, low=0.0)
    if kink_rule not in KINK_RULES:
        raise ParameterError(f"kink_rule must be one of {sorted(KINK_RULES)}, got {kink_rule!r} "
                             f"(type {type(kink_rule).__name__})")
    if start not in ("rest", "twin"):
        raise ParameterError(f"start must be 'rest' or 'twin', got {start!r} (type {type(start).__name__})")
    if twin is not None:
        twin = check_real("twin", twin, low=0.0, low_open=True)
        if not twin_is_stable(h, twin):
            raise ParameterError(
                f"twin must give every twin mode a positive stiffness twin + 4k sin^2(pi q/N) "
                f"(k = {h.k:g}, N = {h.N}), got {twin!r}")
    for flag, value in (("martingale", martingale), ("third_level", third_level)):
        if not isinstance(value, bool):
            raise ParameterError(f"{flag} must be True or False, got {value!r} "
                                 f"(type {type(value).__name__})")
    if start == "twin" and twin is None:
        if not h.is_linear:
            raise ParameterError("start='twin' needs a twin stiffness for a nonlinear potential")
    stride = max(1, int(round(sample_every / dt)))
    nrun = max(1, int(round(t_run / dt)))
    nburn = int(round(t_burn / dt))
    ss = np.random.SeedSequence(seed)
    third_level = third_level and richardson
    levels = 3 if third_level else 2 if richardson else 1
    dt_f = 0.5 * dt if richardson else dt
    if kind is not None and (h.is_linear or kind not in (KIND_KICK, KIND_KINK)):
        raise ParameterError(f"kind must be None, or {KIND_KICK} (kick) or {KIND_KINK} (kink) for a "
                             f"nonlinear potential, got {kind!r} with n = {h.n:g}")
    kind = scheme_kind(h) if kind is None else kind
    pp = physical_vector(h, threshold, kink_rule, kind)
    # both levels take the same step, chosen at the coarse one
    if joint is None:
        joint = uses_joint_step(h, dt, kind)
    elif joint:
        why = joint_step_refusal(h, kind)
        if why is not None:
            raise ParameterError(f"joint=True is not available here: {why}")
    joint = bool(joint)
    cf_f = step_coefficients(h, dt_f, joint)
    cf_c = step_coefficients(h, dt, joint)
    cf_cc = step_coefficients(h, 2.0 * dt, joint) if third_level else cf_c
    lin = twin_harvester(h, twin) if twin is not None else (h if h.is_linear else None)
    if twin is not None:
        cf_t, pp_t = step_coefficients(lin, dt_f, joint), physical_vector(lin, threshold)
        twin_mean = twin_expectations(lin, dt_f, h.n, joint)
    else:
        cf_t, pp_t, twin_mean = cf_f, pp, {}
    chol = initial_cholesky(lin, dt_f, joint) if start == "twin" else np.zeros((0, 0))
    sizes = _chunks(paths, chunk)
    tasks = [(r, c) for r in range(replicas) for c in range(len(sizes))]

    names = basis_names(h.N) if martingale else ()

    def work(task: tuple[int, int]) -> tuple[np.ndarray, ...]:
        r, c = task
        child = np.random.SeedSequence(ss.entropy, spawn_key=(first_replica + r, c))
        gen = np.random.Generator(np.random.PCG64(child))
        sums = np.zeros((ROWS, N_MOM))
        counts = np.zeros(ROWS)
        esc = np.empty(sizes[c])
        counters = np.zeros(5, dtype=np.int64)
        mg = np.zeros((2, len(names)))
        run_chunk(gen, sizes[c], h.N, nburn, nrun, stride, cf_f, cf_c, pp, kind, richardson, cf_t,
                  pp_t, twin is not None, chol, sums, counts, esc, counters, mg, cf_cc, third_level)
        return sums, counts, esc, counters, mg

    t0 = time.perf_counter()
    if threads == 1 or len(tasks) == 1:
        results = [work(t) for t in tasks]
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            results = list(pool.map(work, tasks))
    wall = time.perf_counter() - t0
    rows = [0, 1, 3][:levels] + [2]
    sums = np.zeros((replicas, levels + 1, N_MOM))
    counts = np.zeros((replicas, levels + 1))
    esc_times = np.full((replicas, paths), np.inf)
    counters = np.zeros(5, dtype=np.int64)
    mart = np.zeros((replicas, 2, len(names)))
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    for (r, c), (s, n, e, k, mg) in zip(tasks, results):
        mart[r] += mg
        sums[r] += s[rows]
        counts[r] += n[rows]
        esc_times[r, offsets[c]:offsets[c + 1]] = np.where(e >= 0.0, e, np.inf)
        counters += k
    return Ensemble(
        sums=sums,
        counts=counts,
        escape_times=esc_times,
        dts=(0.5 * dt, dt, 2.0 * dt)[:levels] if richardson else (dt,),
        paths=paths,
        t_burn=nburn * dt,
        t_run=nrun * dt,
        threshold=threshold,
        path_steps=int(counters[4]),
        wall_time=wall,
        kink_counters=tuple(int(v) for v in counters[:4]),
        seed_entropy=int(ss.entropy) if seed is None else seed,
        first_replica=first_replica,
        notes={"threads": threads, "chunk": chunk, "scheme_kind": kind, "sample_stride": stride,
               "kink_rule": kink_rule, "joint_step": joint},
        twin_kappa=twin,
        twin_mean=twin_mean,
        start=start,
        mart=mart if martingale else None,
        mart_names=names,
    )

