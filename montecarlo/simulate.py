"""Ensembles of independent replicas: the lower-level entry point of the Monte Carlo engine.

A *replica* is ``paths`` independent rings started at rest (x = v = V = 0, xi drawn from
its stationary law), run for ``t_burn`` without measuring and then for ``t_run`` while the
moments are averaged over time, units and paths. Replicas are statistically independent,
so their spread gives honest standard errors (the samples inside one path are correlated).

Random numbers: every chunk of paths owns a :class:`numpy.random.Generator` (PCG64) seeded by
``SeedSequence(seed, spawn_key=(replica, chunk))`` and drawn from inside the numba kernel
(measured fastest, see ``validation/studies/mc/bench.py``). Chunks run on a thread pool with
the GIL released, so results depend on the seed only, not on the number of threads.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from fpe_harvester.errors import ParameterError, check_int, check_real
from fpe_harvester.model import Harvester
from fpe_harvester.parallel import default_threads

from ._loop import Setup, Sums, run_chunk
from .coefficients import KINK_RULES, onsite_kind, physical_vector
from .controls.sets import CONTROLS
from .ensemble import Ensemble
from .harmonic import initial_cholesky, twin_expectations, twin_harvester, twin_is_stable
from .layout import (C_AVERAGED, C_CROSSINGS, C_EXHAUSTED, C_RING_STEPS, C_SLOW, KIND_KICK, KIND_KINK,
                     N_COUNTERS, N_MOM)
from .steps import STEPPERS, Stepper, resolve_step

__all__ = ["Ensemble", "simulate"]


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
    step: str = "auto",
    controls: tuple[str, ...] = (),
    third_level: bool = False,
    generator_every: float = 0.0,
    group: int = 1,
    coarse_ratio: int = 2,
    coarse_half: bool = False,
) -> Ensemble:
    """Simulate independent replicas of ``h`` and return their raw moment sums.

    Parameters
    ----------
    h : Harvester
        Any potential (n >= 1), ring size and coupling.
    dt : float
        Time step, > 0. With ``richardson=True`` the ensemble runs at ``dt/2`` (level 0)
        and at ``dt`` (level 1, or ``2 dt`` with ``coarse_ratio=4``) on the same Brownian paths.
    paths : int
        Paths (rings) per replica, >= 1.
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
        Paths per random stream / task, >= 1 (a replica of more paths is split into chunks).
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
        fine level's noise and measured with it (:mod:`montecarlo.harmonic`); its modes
        :math:`\\kappa + 4k\\sin^2(\\pi q/N)` must all be positive. None: no twin.
    start : {"rest", "twin"}
        Initial state of every path: rest (x = v = V = 0, xi stationary), or a draw from the
        twin's stationary law at the fine step (needs ``twin``, or a harmonic ``h``, which is
        then its own twin). The twin always starts from its own law when ``start="twin"``;
        with ``start="rest"`` a twin starts at rest too, and its expectations are then not
        those of :attr:`Ensemble.twin_mean` during the transient.
    kink_rule : {"average", "hold"}
        Kink treatment only: swings shorter than a few steps are advanced by the averaged map
        of their amplitude (``"average"``), or followed until 64 crossings in one step and the
        unit then held at rest (``"hold"``, a time-step artifact kept to compare with;
        :data:`montecarlo.coefficients.KINK_RULES`).
    kind : int or None
        On-site treatment (:data:`montecarlo.layout.KIND_KICK` or ``KIND_KINK``; default
        :func:`montecarlo.coefficients.onsite_kind`), for comparing the treatments near n = 1.
    step : str
        The stepper (:data:`montecarlo.steps.STEP_NAMES`): ``"frozen"`` (xi held over each step),
        ``"joint"`` ((x, v, V, xi) together by the exact Gaussian transition of the linear drift;
        not the kink), ``"averaged"`` (the kink at tau <= 1e-4, without a twin), or ``"auto"``
        (default): the one :func:`montecarlo.steps.resolve_step` picks at ``dt`` (joint where
        tau < 10 dt, averaged for the kink where tau < dt, else frozen). Raises where the named
        stepper refuses ``h``, or ``"auto"`` finds none (the kink between tau = 1e-4 and dt).
    controls : tuple of str
        Controls whose sums the path loop accumulates on level 0 (names of
        :data:`montecarlo.controls.CONTROLS` that are ``accumulated``; :attr:`Ensemble.ctl`), e.g.
        ``("martingale", "boundary")``: sums of basis functions of the state times the noise drawn
        after it, with mean exactly 0, and the end-of-window terms, with mean 0 for a stationary
        window (:mod:`montecarlo.controls.martingale`). The simulated paths are the same with or
        without them. The twin is asked for by ``twin``.
    generator_every : float
        Time between the points of the generator control (``"generator"`` in ``controls``,
        :mod:`montecarlo.controls.generator`), >= 0, rounded to whole steps of level 0 (at least
        one); the default 0 takes every step. Longer intervals cost less per step and remove
        less variance (docs/methods.md, "Generator controls").
    third_level : bool
        With ``richardson``, also run level 2 at ``2 dt`` on the same noise (two coarse
        increments composed exactly), so that two Richardson extrapolations, from
        ``(dt, dt/2)`` and from ``(2 dt, dt)``, can be compared (:func:`montecarlo.estimate`);
        it adds a quarter of level 0's steps. Ignored without ``richardson``.
    coarse_ratio : {2, 4}
        With ``richardson``: the coarse level's step over the fine one's. 4 runs level 1 at ``2 dt``
        (four fine increments composed exactly) instead of ``dt``, at about half the coarse level's
        cost; for a weak order p its difference from the fine level is ``4^p - 1`` times the fine
        level's bias instead of ``2^p - 1`` times, while its noise grows less (at the strong kink,
        n = 1, a = 2, the bias estimate's standard error fell 5x: docs/methods.md, "Generator
        controls"). Not with ``third_level``.
    coarse_half : bool
        With ``richardson``: the coarse level runs through the burn-in and the first half of the
        measured window only (:attr:`Ensemble.coarse_half`), at about half its cost; its
        difference from the fine level over that half estimates the same bias, from half the
        path time. Pays where that estimate's noise takes little of the error budget (the strong
        kink with ``coarse_ratio=4``: docs/methods.md, "Generator controls"). Not with
        ``third_level``.
    group : int
        Replicas per task, >= 1. With more than one, a task runs ``group`` whole replicas
        (``group * paths`` paths, ``paths <= chunk``) on one random stream, seeded by its first
        replica: a kernel call then steps more paths (cheaper per path-step at small ``paths``),
        while every replica keeps sums of its own (more, smaller replicas for the cross-fitted
        controls). The default 1 gives each replica its own streams; results depend on ``group``.

    Returns
    -------
    Ensemble

    Examples
    --------
    >>> e = simulate(Harvester.build(a=0.5), dt=0.05, paths=4, replicas=2, t_burn=1.0,
    ...              t_run=2.0, seed=3)
    >>> e.sums.shape, float(e.counts[0, 0])
    ((2, 2, 19), 160.0)
    """
    c = _check(h, dt=dt, paths=paths, replicas=replicas, t_burn=t_burn, t_run=t_run, seed=seed,
               richardson=richardson, threshold=threshold, chunk=chunk, threads=threads,
               first_replica=first_replica, sample_every=sample_every, twin=twin, start=start,
               kink_rule=kink_rule, kind=kind, step=step, controls=controls, third_level=third_level,
               generator_every=generator_every, group=group, coarse_ratio=coarse_ratio,
               coarse_half=coarse_half)
    stepper, setup, twin_mean = _coefficients(h, c)
    ss = np.random.SeedSequence(c.seed)
    tasks = _tasks(c)
    t0 = time.perf_counter()
    results = _run_tasks(stepper, setup, ss, c.first_replica, tasks, c.threads)
    wall = time.perf_counter() - t0
    sums, counts, esc_times, counters, ctl = _merge(results, tasks, c)
    dt = c.dt
    return Ensemble(
        sums=sums,
        counts=counts,
        escape_times=esc_times,
        dts=tuple(0.5 * dt * 2.0**k for k in _level_exponents(c)) if c.richardson else (dt,),
        paths=c.paths,
        t_burn=setup.nburn * dt,
        t_run=setup.nrun * dt,
        threshold=c.threshold,
        path_steps=int(counters[C_RING_STEPS]),
        wall_time=wall,
        kink_counters=tuple(int(counters[i]) for i in (C_SLOW, C_CROSSINGS, C_AVERAGED, C_EXHAUSTED)),
        seed_entropy=int(ss.entropy) if c.seed is None else c.seed,
        first_replica=c.first_replica,
        notes={"threads": c.threads, "chunk": c.chunk, "onsite_kind": setup.kind,
               "sample_stride": setup.stride, "kink_rule": c.kink_rule, "step": stepper.name,
               **({"replicas_per_task": c.group} if c.group > 1 else {}),
               **({"generator_stride": setup.gen_every} if setup.n_gen else {})},
        twin_kappa=c.twin,
        twin_mean=twin_mean,
        start=c.start,
        ctl=ctl if c.controls else None,
        ctl_names={name: CONTROLS[name].sums(h) for name in c.controls},
        coarse_half=c.coarse_half,
    )


class _Checked(NamedTuple):
    """The arguments of :func:`simulate`, checked (``third_level`` only with ``richardson``,
    ``kind`` and ``step`` resolved)."""

    dt: float
    paths: int
    replicas: int
    t_burn: float
    t_run: float
    seed: int | None
    richardson: bool
    threshold: float
    chunk: int
    threads: int
    first_replica: int
    sample_every: float
    twin: float | None
    start: str
    kink_rule: str
    kind: int
    step: str
    controls: tuple[str, ...]
    third_level: bool
    generator_every: float
    group: int
    coarse_ratio: int
    coarse_half: bool


def _level_exponents(c: _Checked) -> tuple[int, ...]:
    """Each level's step in fine steps, as powers of 2: (0,), (0, 1), (0, 2) or (0, 1, 2)."""
    if not c.richardson:
        return (0,)
    return (0, 1, 2) if c.third_level else (0, c.coarse_ratio.bit_length() - 1)


def _check(h: Harvester, *, dt: float, paths: int, replicas: int, t_burn: float, t_run: float,
           seed: int | None, richardson: bool, threshold: float, chunk: int, threads: int | None,
           first_replica: int, sample_every: float, twin: float | None, start: str, kink_rule: str,
           kind: int | None, step: str, controls: tuple[str, ...], third_level: bool,
           generator_every: float, group: int, coarse_ratio: int, coarse_half: bool) -> _Checked:
    """Validate :func:`simulate`'s arguments (raises :class:`ParameterError`)."""
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    dt = check_real("dt", dt, low=0.0, low_open=True)
    paths = check_int("paths", paths, low=1)
    replicas = check_int("replicas", replicas, low=1)
    t_burn = check_real("t_burn", t_burn, low=0.0)
    t_run = check_real("t_run", t_run, low=0.0, low_open=True)
    threshold = check_real("threshold", threshold, low=0.0, low_open=True)
    chunk = check_int("chunk", chunk, low=1)
    group = check_int("group", group, low=1)
    if group > 1 and paths > chunk:
        raise ParameterError(f"group > 1 needs whole replicas per task: paths ({paths}) <= chunk ({chunk}), "
                             f"got group = {group}")
    threads = default_threads() if threads is None else check_int("threads", threads, low=1)
    first_replica = check_int("first_replica", first_replica, low=0)
    if seed is not None:
        seed = check_int("seed", seed, low=0)
    sample_every = check_real("sample_every", sample_every, low=0.0)
    generator_every = check_real("generator_every", generator_every, low=0.0)
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
    if not isinstance(third_level, bool):
        raise ParameterError(f"third_level must be True or False, got {third_level!r} "
                             f"(type {type(third_level).__name__})")
    if isinstance(coarse_ratio, bool) or coarse_ratio not in (2, 4):
        raise ParameterError(f"coarse_ratio must be 2 or 4, got {coarse_ratio!r} (type {type(coarse_ratio).__name__})")
    if coarse_ratio == 4 and third_level and richardson:
        raise ParameterError("coarse_ratio=4 runs the coarse level at 2 dt itself: not with third_level=True")
    if not isinstance(coarse_half, bool):
        raise ParameterError(f"coarse_half must be True or False, got {coarse_half!r} "
                             f"(type {type(coarse_half).__name__})")
    if coarse_half and third_level and richardson:
        raise ParameterError("coarse_half=True leaves the coarser levels half the window: not with third_level=True")
    loop_controls = tuple(name for name, control in CONTROLS.items() if control.accumulated)
    if isinstance(controls, str) or not all(name in loop_controls for name in controls) \
            or len(set(controls)) != len(controls):
        raise ParameterError(f"controls must be a tuple of distinct names among {loop_controls}, got "
                             f"{controls!r} (type {type(controls).__name__})")
    if start == "twin" and twin is None:
        if not h.is_linear:
            raise ParameterError("start='twin' needs a twin stiffness for a nonlinear potential")
    if kind is not None and (h.is_linear or kind not in (KIND_KICK, KIND_KINK)):
        raise ParameterError(f"kind must be None, or {KIND_KICK} (kick) or {KIND_KINK} (kink) for a "
                             f"nonlinear potential, got {kind!r} with n = {h.n:g}")
    kind = onsite_kind(h) if kind is None else kind
    # every level takes the same stepper, chosen at the coarse step
    stepper, _ = resolve_step(h, step, dt, kind)
    if twin is not None and not stepper.twin:
        raise ParameterError(f"twin: the {stepper.name} step has no harmonic twin; use twin=None")
    return _Checked(dt, paths, replicas, t_burn, t_run, seed, bool(richardson), threshold, chunk, threads,
                    first_replica, sample_every, twin, start, kink_rule, kind, stepper.name, tuple(controls),
                    third_level and bool(richardson), generator_every, group, int(coarse_ratio),
                    coarse_half and bool(richardson))


def _coefficients(h: Harvester, c: _Checked) -> tuple[Stepper, Setup, dict[str, float]]:
    """The stepper, the kernels' setup (all but the chunk's path count) and the twin's
    exact expectations (empty without a twin)."""
    stepper = STEPPERS[c.step]
    dt_f = 0.5 * c.dt if c.richardson else c.dt
    pp = physical_vector(h, c.threshold, c.kink_rule, c.kind)
    cf_f = stepper.coefficients(h, dt_f)
    cf_c = stepper.coefficients(h, c.dt)
    # the coarse level at 2 dt (coarse_ratio 4) is the loop's coarsest, without its middle level
    ratio4 = c.richardson and c.coarse_ratio == 4
    cf_cc = stepper.coefficients(h, 2.0 * c.dt) if c.third_level or ratio4 else cf_c
    lin = twin_harvester(h, c.twin) if c.twin is not None else (h if h.is_linear else None)
    if c.twin is not None:
        cf_t, pp_t = stepper.coefficients(lin, dt_f), physical_vector(lin, c.threshold)
        twin_mean = twin_expectations(lin, dt_f, h.n, c.step)
    else:
        cf_t, pp_t, twin_mean = cf_f, pp, {}
    chol = initial_cholesky(lin, dt_f, c.step) if c.start == "twin" else np.zeros((0, 0))
    setup = Setup(P=0, N=h.N, nburn=int(round(c.t_burn / c.dt)), nrun=max(1, int(round(c.t_run / c.dt))),
                  stride=max(1, int(round(c.sample_every / c.dt))), coupled=c.richardson,
                  third=c.third_level or ratio4, middle=not ratio4, coarse_half=c.coarse_half,
                  twin=c.twin is not None, kind=c.kind, cf_f=cf_f, cf_c=cf_c, cf_cc=cf_cc,
                  cf_t=cf_t, pp=pp, pp_t=pp_t, chol=chol)
    # each accumulated control's sums at its columns of the loop's control accumulator
    n_ctl = 0
    for name in c.controls:
        setup = setup._replace(**CONTROLS[name].loop_fields(h, n_ctl))
        n_ctl += len(CONTROLS[name].sums(h))
    setup = setup._replace(n_ctl=n_ctl, gen_every=max(1, int(round(c.generator_every / dt_f))))
    return stepper, setup, twin_mean


class _Task(NamedTuple):
    """One task of :func:`simulate`: replicas ``r0 .. r0 + groups - 1`` (their paths
    ``p0 .. p0 + P - 1`` when one replica is split into chunks, ``chunk`` the chunk's index)."""

    r0: int
    chunk: int
    groups: int
    p0: int
    P: int


def _tasks(c: _Checked) -> list[_Task]:
    """Every replica split into chunks of ``c.chunk`` paths, or ``c.group`` whole replicas per task."""
    if c.group > 1:
        return [_Task(r0, 0, min(c.group, c.replicas - r0), 0, min(c.group, c.replicas - r0) * c.paths)
                for r0 in range(0, c.replicas, c.group)]
    full, rest = divmod(c.paths, c.chunk)
    sizes = [c.chunk] * full + ([rest] if rest else [])
    starts = np.concatenate([[0], np.cumsum(sizes)])
    return [_Task(r, k, 1, int(starts[k]), size) for r in range(c.replicas) for k, size in enumerate(sizes)]


def _run_tasks(stepper: Stepper, setup: Setup, ss: np.random.SeedSequence, first_replica: int,
               tasks: list[_Task], threads: int) -> list[Sums]:
    """Run every task on a thread pool, each on its own random stream
    ``SeedSequence(seed, spawn_key=(first replica, chunk))``."""

    def work(task: _Task) -> Sums:
        child = np.random.SeedSequence(ss.entropy, spawn_key=(first_replica + task.r0, task.chunk))
        gen = np.random.Generator(np.random.PCG64(child))
        out = Sums.zeros(task.P, setup.n_ctl, task.groups)
        run_chunk(gen, stepper, setup._replace(P=task.P, groups=task.groups), out)
        return out

    if threads == 1 or len(tasks) == 1:
        return [work(t) for t in tasks]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(work, tasks))


def _merge(results: list[Sums], tasks: list[_Task], c: _Checked) -> tuple[np.ndarray, ...]:
    """Per-replica sums, counts, escape times (inf: none), summed counters and control sums
    from the chunks' outputs (rows of the levels in :attr:`Ensemble.sums`'s order)."""
    # the loop's rows: fine, coarse, first half, coarsest
    rows = [(0, 1, 3)[k] for k in _level_exponents(c)] + [2]
    levels = len(rows) - 1
    sums = np.zeros((c.replicas, levels + 1, N_MOM))
    counts = np.zeros((c.replicas, levels + 1))
    esc_times = np.full((c.replicas, c.paths), np.inf)
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    ctl = np.zeros((c.replicas, 2, results[0].ctl.shape[2]))
    for t, out in zip(tasks, results):
        r = slice(t.r0, t.r0 + t.groups)
        ctl[r] += out.ctl
        sums[r] += out.sums[:, rows]
        counts[r] += out.counts[:, rows]
        esc = np.where(out.esc_time >= 0.0, out.esc_time, np.inf)
        esc_times[r, t.p0:t.p0 + t.P // t.groups] = esc.reshape(t.groups, t.P // t.groups)
        counters += out.counters
    return sums, counts, esc_times, counters, ctl
