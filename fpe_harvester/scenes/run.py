"""Running a scene: the solver :func:`~fpe_harvester.solve.solve` picks per point, cache/resume,
outputs and figures.

Per point the method is ``scene.method`` or, for ``"auto"``, the first solver that handles the
point (:func:`~fpe_harvester.solve.choose_method`: harmonic -> exact, a single nonlinear unit
-> Fokker--Planck where it can answer, else Monte Carlo). Each solver gets what its declared
capabilities take: ``tol = rtol``, a seed derived from the scene and the point, no progress bar
of its own, its machine-dependent defaults fixed (``portable``), then the scene's
``options[method]``. Every point is checked before the first is computed: a point no solver
(or not the scene's method) handles stops the run with a :class:`ParameterError`. The points of
a solver with ``solve_many`` (exact) are computed together; the rest one by one through
:func:`~fpe_harvester.solve.solve`, which also tries the next solver where the first stops
short of ``rtol`` (``method = "auto"``). Each finished point is appended to ``points.jsonl`` in
the output folder (see :mod:`.cache`), so reruns reuse it and an interrupted run resumes (even
one killed mid-write; two runs may share a folder). Outputs are replaced atomically. A point
whose solver fails is reported with its status and message; the scene goes on. With
``scheduler`` the pointwise points run as tasks on a Dask cluster (:mod:`.cluster`) and give
the same numbers.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import HarvesterError, MethodNotAvailableError, ParameterError, check_int
from ..exact import k_di
from ..model import Harvester
from ..optimum import optimize, refine_grid_maximum
from ..result import QUANTITIES, Stats, Status
from ..solve import choose_method, get_solver, relative_eta_error, solve, solve_many
from ..solvers import METHODS, capabilities
from .cache import PointCache, atomic_path, point_key, point_seed, stats_from_dict, write_text_atomic
from .result import ERROR, NOT_AVAILABLE, SceneResult, SceneRow, write_csv
from .spec import Scene, load_scene

if TYPE_CHECKING:
    from .cluster import Connection

__all__ = ["SCENE_FALLBACK_SECONDS", "run_scene"]

#: Wall-time budget (s) per point of the solver that takes over where the first one stops short
#: of ``rtol`` (``method = "auto"``), unless the scene's options give that solver one.
SCENE_FALLBACK_SECONDS = 600.0
#: Solver details copied onto rows (escapes decide how a metastable point is drawn; ``fallback``
#: keeps the other solver's numbers where a second solver was tried).
_CARRIED_INFO = ("seed", "escape_fraction", "escape_time_median", "fallback")


@dataclass(frozen=True)
class _Failure:
    status: str
    message: str
    method: str


#: A point to compute: its index in the batch, cache key, solver name and per-solver settings.
_Todo = tuple[int, str, str, dict[str, dict[str, Any]]]


class _Runner:
    """Evaluates harvesters for one scene run, through the cache."""

    def __init__(self, scene: Scene, cache: PointCache | None, bar: Any, workers: int = 1,
                 cluster: Connection | None = None) -> None:
        self.scene, self.cache, self.bar, self.workers, self.cluster = scene, cache, bar, workers, cluster
        self.computed = self.reused = 0
        self.needs_solver = any(o in QUANTITIES for o in scene.observables)

    def settings(self, name: str, h: Harvester) -> dict[str, Any]:
        """What solver ``name`` gets for point ``h``: the scene's accuracy, seed and silence where
        its capabilities take them, its machine-dependent defaults fixed, then the scene's options."""
        caps = capabilities(name)
        opts: dict[str, Any] = {}
        if caps.tol is not None:
            opts["tol"] = self.scene.rtol
        if caps.progress is not None:
            opts["progress"] = False  # the scene draws its own bar over points
        if caps.seed:
            opts["seed"] = point_seed(self.scene.name, h)
        opts.update(self.scene.options.get(name, {}))
        if caps.portable is not None:
            # e.g. the Monte Carlo replica batch, which shapes the numbers: fixed here, as in a
            # run in this process, a point gives the same numbers on any Dask worker
            opts.update(caps.portable(opts))
        return opts

    def all_settings(self, h: Harvester) -> dict[str, dict[str, Any]]:
        """:meth:`settings` of every registered solver the scene may use for ``h``."""
        names = METHODS if self.scene.method == "auto" else (self.scene.method,)
        out = {}
        for name in names:
            try:
                out[name] = self.settings(name, h)
            except MethodNotAvailableError:
                continue
        return out

    def solver_of(self, h: Harvester, every: dict[str, dict[str, Any]] | None = None) -> str:
        """The solver that answers for ``h`` (``every``: :meth:`all_settings` of ``h``, if known).

        Raises
        ------
        ParameterError
            No solver (or not the scene's method) handles ``h``; the message names the point.
        """
        every = self.all_settings(h) if every is None else every
        try:
            if self.scene.method == "auto":
                return choose_method(h, solver_options=every)
            name = self.scene.method
            reason = get_solver(name, **every.get(name, {})).unsupported_reason(h)
        except MethodNotAvailableError as exc:
            reason, name = str(exc), self.scene.method
        if reason:
            desc = ", ".join(f"{k} = {v:g}" for k, v in (("a", h.a), ("n", h.n), ("N", h.N), ("k", h.k)))
            raise ParameterError(f"method: {name!r} cannot handle the point ({desc}) of scene "
                                 f"{self.scene.name!r}: {reason}")
        return name

    def key(self, h: Harvester) -> tuple[str, str, dict[str, dict[str, Any]]]:
        """The cache key of ``h``, its solver and the settings of every solver it may use."""
        every = self.all_settings(h)
        name = self.solver_of(h, every)
        rtol = None if capabilities(name).tol is None else self.scene.rtol
        return point_key(h, name, rtol, every[name]), name, every

    def _cached(self, key: str) -> Stats | None:
        stats = self.cache.get(key)
        # caches written before exact batches reported x2 hold stable points without it
        if stats is not None and "x2" in self.scene.observables and stats.x2 is None and stats.ok \
                and stats.status is not Status.MARGINAL:
            return None
        return stats

    def evaluate(self, hs: Sequence[Harvester]) -> list[Stats | _Failure | None]:
        """Results for each harvester (``None`` when no solver is needed)."""
        out: list[Stats | _Failure | None] = [None] * len(hs)
        if not self.needs_solver:
            self.bar.update(len(hs))
            return out
        todo: list[_Todo] = []
        for i, h in enumerate(hs):
            key, name, every = self.key(h)
            hit = self._cached(key)
            if hit is not None:
                out[i] = hit
                self.reused += 1
                self.bar.update(1)
            else:
                todo.append((i, key, name, every))
        rest = self._solve_batched(hs, todo, out)
        if self.cluster is not None and rest:
            self._solve_distributed(hs, rest, out)
        pool = [t for t in rest if capabilities(t[2]).pooled] if self.workers > 1 else []
        # the slowest points first, so that one does not start last and leave the other workers idle
        pool.sort(key=lambda t: _cost_rank(hs[t[0]]))
        if len(pool) > 1:
            self._solve_parallel(hs, pool, out)
        for i, key, name, every in rest:
            if out[i] is None:
                out[i] = self._store(hs[i], key, every[name], _solve_point(hs[i], self.scene.method, name, every))
        return out

    def _solve_batched(self, hs: Sequence[Harvester], todo: list[_Todo],
                       out: list[Stats | _Failure | None]) -> list[_Todo]:
        """The points of solvers with ``solve_many``, one call per solver and settings; returns
        the others."""
        groups: dict[tuple[str, str], list[_Todo]] = {}
        rest = []
        for t in todo:
            if capabilities(t[2]).solve_many:
                groups.setdefault((t[2], json.dumps(t[3][t[2]], sort_keys=True, default=str)), []).append(t)
            else:
                rest.append(t)
        for (name, _), members in groups.items():
            results = solve_many([hs[t[0]] for t in members], name, **members[0][3][name])
            for (i, key, _, every), stats in zip(members, results):
                out[i] = self._store(hs[i], key, every[name], stats)
        return rest

    def _solve_distributed(self, hs: Sequence[Harvester], todo: list[_Todo],
                           out: list[Stats | _Failure | None]) -> None:
        from .cluster import run_tasks

        def on_worker(every: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
            # one task per worker thread: a threaded solver runs single-threaded unless the scene says
            return {name: ({"threads": 1, **opts} if capabilities(name).threads else opts)
                    for name, opts in every.items()}

        args = [(hs[i], self.scene.method, name, on_worker(every)) for i, _, name, every in todo]
        for j, res in run_tasks(self.cluster.client(), _solve_portable, args,
                                lambda j, why: _Failure(ERROR, why, todo[j][2])):
            i, key, name, every = todo[j]
            out[i] = self._store(hs[i], key, every[name], stats_from_dict(res) if isinstance(res, dict) else res)

    def _solve_parallel(self, hs: Sequence[Harvester], todo: list[_Todo],
                        out: list[Stats | _Failure | None]) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        # fork where available: spawn re-runs the caller's __main__ in every worker, which
        # breaks user scripts without an ``if __name__ == "__main__"`` guard. Only pooled
        # (single-threaded) solvers' points go to the pool.
        methods = multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
        with ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx) as ex:
            futures = {ex.submit(_solve_portable, hs[i], self.scene.method, name, every): (i, key, every[name])
                       for i, key, name, every in todo}
            for fut in as_completed(futures):
                i, key, opts = futures[fut]
                res = fut.result()
                out[i] = self._store(hs[i], key, opts, stats_from_dict(res) if isinstance(res, dict) else res)

    def _store(self, h: Harvester, key: str, opts: Mapping[str, Any],
               res: Stats | _Failure) -> Stats | _Failure:
        extra = {"scene": self.scene.name, "seed": opts.get("seed")}
        if isinstance(res, Stats):
            self.cache.put(key, h, res, extra)
            self.computed += 1
        else:
            self.cache.log_failure(key, h, res.status, res.message, {**extra, "method": res.method})
        self.bar.update(1)
        return res


def _cost_rank(h: Harvester) -> tuple[bool, float, float]:
    """Sort key putting the dearest single-unit points first: 1 <= n < 2 (for Fokker--Planck the
    2-D scheme in (x, v), seconds to a minute) before n >= 2 (about a second), then strong walls a
    first, then n nearest the kink. Measured on the paper's Fig. 1 grid (39 points, tol 5e-3): the
    ten dearest points all have n < 2, and at a given n the cost grows with a (n = 1: 5, 12 s at
    a = 0.5, 1)."""
    return (not 1.0 <= h.n < 2.0, -h.a, h.n)


def _solve_point(h: Harvester, method: str, name: str, every: dict[str, dict[str, Any]]) -> Stats | _Failure:
    """Solve one point by :func:`~fpe_harvester.solve.solve` (``method``: the scene's, so that
    ``"auto"`` falls back where its first solver stops short); a failure becomes a
    :class:`_Failure` carrying the reason, labelled with the solver ``name`` that was to answer."""
    try:
        return solve(h, method, fallback_time=SCENE_FALLBACK_SECONDS, solver_options=every)
    except MethodNotAvailableError as exc:
        return _Failure(NOT_AVAILABLE, str(exc), name)
    except HarvesterError as exc:
        return _Failure(ERROR, f"method {name!r} failed: {type(exc).__name__}: {exc}", name)
    except Exception as exc:  # noqa: BLE001
        # A solver bug (or a warning turned into an error) must not sink a long sweep:
        # report it on the point and go on. KeyboardInterrupt still stops the run.
        return _Failure(ERROR, f"method {name!r} raised {type(exc).__name__}: {exc}", name)


def _solve_portable(h: Harvester, method: str, name: str,
                    every: dict[str, dict[str, Any]]) -> dict[str, Any] | _Failure:
    """:func:`_solve_point` for a worker process: Stats travel as dicts (their info is read-only)."""
    res = _solve_point(h, method, name, every)
    return res.to_dict() if isinstance(res, Stats) else res


def _row(scene: Scene, index: int, point: Mapping[str, float], h: Harvester,
         res: Stats | _Failure | None, info: Mapping[str, Any]) -> SceneRow:
    values: dict[str, float | None] = {}
    for obs in scene.observables:
        if obs == "k_di":
            values["k_di"] = k_di(h.N, h.a, h.k4)
        elif isinstance(res, Stats):
            values[obs], values[obs + "_err"] = res.value(obs)
        else:
            values[obs] = values[obs + "_err"] = None
    if res is None:
        msg = "closed form" if values.get("k_di") is not None else "N = 1: no coupling threshold"
        return SceneRow(index, dict(point), Status.STABLE.value, "", msg, values, info)
    if isinstance(res, _Failure):
        return SceneRow(index, dict(point), res.status, res.method, res.message, values, info)
    status, message = res.status.value, res.message
    # whatever the solver said (a cached point, a tol overridden in the scene's options), a row
    # that misses the scene's accuracy on eta is not converged; the message keeps the solver's
    if res.ok and res.eta is not None and not (res.eta_err is not None
                                               and res.eta_err <= scene.rtol * abs(res.eta)):
        rel_err = relative_eta_error(res)
        rel = "unknown" if math.isinf(rel_err) else f"{rel_err:.2g}"
        status = Status.NOT_CONVERGED.value
        message += (f"; accuracy not met: eta_err/eta = {rel} > rtol = {scene.rtol:g} "
                    f"(the numbers are the best estimate; tighten the solver settings or loosen rtol)")
    carried = {key: res.info[key] for key in _CARRIED_INFO if key in res.info}
    return SceneRow(index, dict(point), status, res.method, message, values, {**info, **carried})


def _sweep_rows(scene: Scene, runner: _Runner, points: list[dict[str, float]]) -> list[SceneRow]:
    hs = [scene.harvester(p) for p in points]
    results = runner.evaluate(hs)
    return [_row(scene, i, p, h, r, {}) for i, (p, h, r) in enumerate(zip(points, hs, results))]


def _objective(res: Stats | _Failure | None, name: str) -> float | None:
    if isinstance(res, Stats) and res.ok:
        return res.value(name)[0]
    return None


def _optimize_rows(scene: Scene, runner: _Runner, points: list[dict[str, float]]) -> list[SceneRow]:
    opt = scene.optimize
    assert opt is not None
    rows = []
    for index, p in enumerate(points):
        h0 = scene.harvester(p)
        lo, hi = opt.interval(h0)
        name = runner.solver_of(h0.replace(**{opt.over: 0.5 * (lo + hi)}))
        if hi > lo and capabilities(name).seed:
            # a random solver: the noisy optimizer, with common random numbers across the interval
            rows.append(_noisy_optimum_row(scene, runner, index, p, h0, lo, hi, name))
            continue
        grid = np.linspace(lo, hi, opt.points) if hi > lo else np.array([lo])
        hs = [h0.replace(**{opt.over: float(x)}) for x in grid]
        res = runner.evaluate(hs)
        vals = [_objective(r, opt.maximize) for r in res]
        good = [i for i, v in enumerate(vals) if v is not None]
        info: dict[str, Any] = {"optimize": {"maximize": opt.maximize, "over": opt.over,
                                             "interval": [lo, hi], "grid_points": len(grid)}}
        if not good:
            first = next((r for r in res if isinstance(r, _Failure)), None)
            rows.append(_row(scene, index, {**p, opt.over: None}, h0,  # type: ignore[dict-item]
                             first or _Failure(ERROR, "no stationary point in the search interval", ""),
                             info))
            runner.bar.update(1)
            continue
        best = max(good, key=lambda i: vals[i])
        x_opt = float(grid[best])
        bracket = [float(grid[max(best - 1, 0)]), float(grid[min(best + 1, len(grid) - 1)])]
        at_bound = "low" if best == 0 and len(grid) > 1 else "high" if best == len(grid) - 1 > 0 else None
        best_by = res[best].method if isinstance(res[best], Stats) else ""
        if at_bound is None and len(grid) > 1 and best_by in METHODS and capabilities(best_by).tol is None:
            # exact to round-off: the best grid cell is refined by a bounded scalar search
            def value(x: float) -> float:
                v = solve(h0.replace(**{opt.over: x}), best_by).value(opt.maximize)[0]
                return -np.inf if v is None else v

            grid_vals = np.array([-np.inf if v is None else v for v in vals])
            x_opt = refine_grid_maximum(value, grid, grid_vals)[0]
            bracket = [x_opt, x_opt]
        info["optimize"].update(at_bound=at_bound, bracket=bracket)
        final = runner.evaluate([h0.replace(**{opt.over: x_opt})])[0]
        row = _row(scene, index, {**p, opt.over: x_opt}, h0, final, info)
        if at_bound:
            row = SceneRow(row.index, row.point, row.status, row.method,
                           row.message + f"; the largest {opt.maximize} on the grid is at the {at_bound} "
                           f"end of the search interval {opt.over} in [{lo:.6g}, {hi:.6g}]",
                           row.values, row.info)
        rows.append(row)
    return rows


def _noisy_optimum_row(scene: Scene, runner: _Runner, index: int, p: Mapping[str, float], h0: Harvester,
                       lo: float, hi: float, name: str) -> SceneRow:
    """An optimum by a random solver ``name``: :func:`~fpe_harvester.optimum.optimize` (common
    random numbers, quadratic fit, jackknife errors); the maximized observable is the fit's value
    at the vertex, the others come from one more solve there."""
    opt = scene.optimize
    assert opt is not None
    found = optimize(h0, opt.over, (lo, hi), opt.maximize, method=name, seed=point_seed(scene.name, h0),
                     mc_tol=scene.rtol, progress=False)
    info: dict[str, Any] = {"optimize": {"maximize": opt.maximize, "over": opt.over, "interval": [lo, hi],
                                         **{k: v for k, v in found.to_dict().items() if k != "info"},
                                         "window": found.info.get("window"),
                                         "batches": found.info.get("batches")}}
    runner.bar.update(opt.points)
    if found.x_opt is None:
        return _row(scene, index, {**p, opt.over: None}, h0,  # type: ignore[dict-item]
                    _Failure(Status.NOT_CONVERGED.value, found.message, name), info)
    final = runner.evaluate([h0.replace(**{opt.over: found.x_opt})])[0]
    row = _row(scene, index, {**p, opt.over: found.x_opt}, h0, final, info)
    values = {**row.values, opt.maximize: found.value, opt.maximize + "_err": found.value_err}
    status = row.status if found.status is Status.STABLE else found.status.value
    return SceneRow(row.index, row.point, status, found.method, f"{found.message}; {row.message}", values,
                    row.info)


def _check_solvers(sc: Scene, hs: Sequence[Harvester]) -> None:
    """Every point has a solver that handles it (for an optimum: the middle of its interval),
    before the first point is computed.

    Raises
    ------
    ParameterError
        Naming the first point no solver (or not the scene's method) handles, and why.
    """
    probe = _Runner(sc, None, bar=None)
    if not probe.needs_solver:
        return
    for h in hs:
        if sc.optimize is not None:
            lo, hi = sc.optimize.interval(h)
            h = h.replace(**{sc.optimize.over: 0.5 * (lo + hi)}) if hi > lo else h
        probe.solver_of(h)


def run_scene(
    scene: Scene | str | Path,
    out_dir: str | Path,
    quick: bool = False,
    progress: bool | None = None,
    figures: Sequence[str] | None = None,
    workers: int | None = None,
    scheduler: Any = None,
) -> SceneResult:
    """Run a scene: compute its points, write the outputs it asks for, draw its figures.

    Parameters
    ----------
    scene : Scene, str or Path
        The study, or a shipped scene name or TOML path (see :func:`.spec.load_scene`).
    out_dir : str or Path
        Output folder (created). Holds ``points.jsonl`` (cache and run log; reruns reuse it),
        ``<name>.csv``, ``<name>.json``, ``<name>.txt`` and ``<name>_<figure>.png``.
    quick : bool
        Run the scene's reduced variant (fewer points, looser rtol) if it declares one.
    progress : bool or None
        Progress bar over points; ``None`` shows it only on a terminal.
    figures : sequence of str, optional
        Draw only these of the scene's figures (default: all declared; ``[]``: none).
    workers : int or None
        Without ``scheduler``: processes for single-threaded pointwise solvers
        (Fokker--Planck), >= 1 (default 1: everything in this process); Monte Carlo points run
        in this process (the simulator is multi-threaded itself). With ``scheduler="local"``:
        the LocalCluster's worker processes (default: one per usable CPU). Harmonic points are
        always vectorized in this process.
    scheduler : str, distributed.Client or None
        Run the Fokker--Planck and Monte Carlo points as tasks on a Dask cluster (needs the
        ``dask`` extra): ``"local"`` starts a LocalCluster on this machine, an address such as
        ``"tcp://10.0.0.5:8786"`` connects to a running scheduler, a Client is used as is.
        Results reach the cache as they finish; the numbers are those of a run in this process
        (same seeds and Monte Carlo settings); a lost worker costs only its points, which
        another worker computes. ``None`` (default): no Dask (the environment variable
        ``DASK_SCHEDULER_ADDRESS`` is read by the command line only).

    Returns
    -------
    SceneResult
        Rows, output paths, counts of computed/reused points and of unusable cache lines.
        A stable or marginal row that misses ``rtol`` on eta has status ``not_converged``.

    Raises
    ------
    ParameterError
        Before any point is computed: a point is not a valid harvester, no solver (or not the
        scene's ``method``) handles a point, ``figures`` names an unknown figure, or the Dask
        scheduler is unusable (see :class:`.cluster.Connection`). Solver failures do not
        raise: they are reported on their points.
    """
    from tqdm.auto import tqdm

    if isinstance(scene, (str, Path)):
        scene = load_scene(scene)
    if not isinstance(scene, Scene):
        raise ParameterError(f"scene must be a Scene, got {scene!r} (type {type(scene).__name__})")
    if workers is not None:
        workers = check_int("workers", workers, low=1)
    sc = scene.variant(quick)
    names = [f.name for f in sc.figures]
    wanted = names if figures is None else list(figures)
    for name in wanted:
        if name not in names:
            raise ParameterError(f"figure {name!r} is not in scene {sc.name!r}; its figures: {names}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    points = list(sc.points())
    hs0 = [sc.harvester(p) for p in points]  # validates every point before any work
    _check_solvers(sc, hs0)
    total = len(points)
    if sc.optimize is not None:
        total = sum(1 + (sc.optimize.points if np.ptp(sc.optimize.interval(h)) > 0 else 1) for h in hs0)
    cache = PointCache(out)
    with ExitStack() as stack:
        cluster = None
        if scheduler is not None:
            from .cluster import Connection

            cluster = stack.enter_context(Connection(scheduler, workers))
        bar = stack.enter_context(tqdm(total=total, desc=sc.name, unit="pt", leave=False,
                                       disable=None if progress is None else not progress))
        runner = _Runner(sc, cache, bar, 1 if cluster is not None else workers or 1, cluster)
        rows = _optimize_rows(sc, runner, points) if sc.optimize else _sweep_rows(sc, runner, points)
    result = SceneResult(sc, tuple(rows), out, MappingProxyType({}), None, None, None,
                         runner.computed, runner.reused, 0.0, cache_skipped=cache.skipped_lines)
    if "csv" in sc.outputs:
        result = replace(result, csv_path=write_csv(result, out / f"{sc.name}.csv"))
    if "table" in sc.outputs:
        table_path = write_text_atomic(out / f"{sc.name}.txt", result.table() + "\n")
        result = replace(result, table_path=table_path)
    drawn: dict[str, Path] = {}
    if wanted:
        from .plotting import draw_figure

        for spec in sc.figures:
            if spec.name in wanted:
                drawn[spec.name] = path = out / f"{sc.name}_{spec.name}.png"
                with atomic_path(path) as tmp:
                    draw_figure(sc, spec, rows, tmp)
    result = replace(result, figures=MappingProxyType(drawn), elapsed=time.perf_counter() - t0)
    if "json" in sc.outputs:
        result = replace(result, json_path=out / f"{sc.name}.json")
        write_text_atomic(result.json_path, json.dumps({**result.to_dict(), "quick": quick}, indent=1,
                                                       default=str))
    return result
