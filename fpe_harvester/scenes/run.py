"""Running a scene: cheapest adequate solver per point, cache/resume, outputs and figures.

Per point the method is ``scene.method`` or, for ``"auto"``, :func:`~fpe_harvester.solve.choose_method`
(harmonic -> exact, single nonlinear unit -> Fokker--Planck with ``tol = rtol``, coupled
nonlinear ring -> Monte Carlo with ``tol = rtol`` and a seed derived from the scene and the
point). Harmonic points are computed together with :func:`~fpe_harvester.exact.exact_stats` (one
vectorized call per ring size and parameter set); the rest one by one. Each finished point
is appended to ``points.jsonl`` in the output folder (see :mod:`.cache`), so reruns
reuse it and an interrupted run resumes (even one killed mid-write; two runs may share a
folder). Outputs are replaced atomically. A point whose solver fails or is not available is
reported with its status and message; the scene goes on. With ``scheduler`` the pointwise
points run as tasks on a Dask cluster (:mod:`.cluster`) and give the same numbers.
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
from ..exact import Exact, exact_stats, k_di
from ..model import Harvester
from ..optimum import optimize, refine_grid_maximum
from ..result import QUANTITIES, Stats, Status
from ..solve import choose_method, fallback_result, relative_eta_error, solve
from .cache import PointCache, atomic_path, point_key, point_seed, stats_from_dict, write_text_atomic
from .result import ERROR, NOT_AVAILABLE, SceneResult, SceneRow, write_csv
from .spec import Scene, load_scene

if TYPE_CHECKING:
    from .cluster import Connection

__all__ = ["run_scene"]

#: Methods worth a process pool: single-threaded and slow (Monte Carlo runs its own threads,
#: exact points cost microseconds).
_POOLED: tuple[str, ...] = ("fpe",)
#: Solver details copied onto rows (escapes decide how a metastable point is drawn; ``fallback``
#: keeps the other solver's numbers where Monte Carlo was tried after Fokker--Planck).
_CARRIED_INFO = ("seed", "escape_fraction", "escape_time_median", "fallback")


@dataclass(frozen=True)
class _Failure:
    status: str
    message: str
    method: str


class _Runner:
    """Evaluates harvesters for one scene run, through the cache."""

    def __init__(self, scene: Scene, cache: PointCache, bar: Any, workers: int = 1,
                 cluster: Connection | None = None) -> None:
        self.scene, self.cache, self.bar, self.workers, self.cluster = scene, cache, bar, workers, cluster
        self.computed = self.reused = 0
        self.needs_solver = any(o in QUANTITIES for o in scene.observables)

    def method_of(self, h: Harvester, method: str | None = None) -> tuple[str, dict[str, Any]]:
        if method is None:
            method = choose_method(h) if self.scene.method == "auto" else self.scene.method
        opts: dict[str, Any] = {}
        if method in ("fpe", "mc"):
            # the scene draws its own progress bar over points
            opts.update(tol=self.scene.rtol, progress=False)
        if method == "mc":
            from fpe_harvester.parallel import default_threads

            # the replica batch (by default the thread count) shapes the numbers: fixed here,
            # as in a run in this process, a point gives the same numbers on any Dask worker
            batch = self.scene.options.get("mc", {}).get("threads") or default_threads()
            opts.update(seed=point_seed(self.scene.name, h), batch=batch)
        opts.update(self.scene.options.get(method, {}))
        return method, opts

    def key(self, h: Harvester) -> tuple[str, str, dict[str, Any]]:
        method, opts = self.method_of(h)
        rtol = None if method == "exact" else self.scene.rtol
        return point_key(h, method, rtol, opts), method, opts

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
        todo: list[tuple[int, str, str, dict[str, Any]]] = []
        for i, h in enumerate(hs):
            key, method, opts = self.key(h)
            hit = self._cached(key)
            if hit is not None:
                out[i] = hit
                self.reused += 1
                self.bar.update(1)
            else:
                todo.append((i, key, method, opts))
        batch = [t for t in todo if t[2] == "exact" and hs[t[0]].is_linear]
        if batch:
            for (i, key, _, opts), stats in zip(batch, exact_stats([hs[t[0]] for t in batch])):
                out[i] = self._store(hs[i], key, opts, stats)
        in_batch = {t[0] for t in batch}
        rest = [t for t in todo if t[0] not in in_batch]
        if self.cluster is not None and rest:
            self._solve_distributed(hs, rest, out)
        pool = [t for t in rest if t[2] in _POOLED] if self.workers > 1 else []
        # the slowest points first, so that one does not start last and leave the other workers idle
        pool.sort(key=lambda t: _fpe_cost_rank(hs[t[0]]))
        if len(pool) > 1:
            self._solve_parallel(hs, pool, out)
        for i, key, method, opts in rest:
            if out[i] is None:
                res = _solve_point(hs[i], method, opts, self.fallback(hs[i], method))
                out[i] = self._store(hs[i], key, opts, res)
        return out

    def fallback(self, h: Harvester, method: str) -> tuple[str, dict[str, Any]] | None:
        """Method and settings to try when ``method`` gives no numbers (see :func:`_solve_point`)."""
        return self.method_of(h, "mc") if self.scene.method == "auto" and method == "fpe" else None

    def _solve_distributed(self, hs: Sequence[Harvester], todo: list[tuple[int, str, str, dict[str, Any]]],
                           out: list[Stats | _Failure | None]) -> None:
        from .cluster import run_tasks

        def on_worker(method: str, opts: dict[str, Any]) -> dict[str, Any]:
            # one task per worker thread: Monte Carlo runs single-threaded unless the scene says
            return {"threads": 1, **opts} if method == "mc" else opts

        fallbacks = [self.fallback(hs[i], method) for i, _, method, _ in todo]
        args = [(hs[i], method, on_worker(method, opts), None if fb is None else (fb[0], on_worker(*fb)))
                for (i, _, method, opts), fb in zip(todo, fallbacks)]
        for j, res in run_tasks(self.cluster.client(), _solve_portable, args,
                                lambda j, why: _Failure(ERROR, why, todo[j][2])):
            i, key, _, opts = todo[j]
            out[i] = self._store(hs[i], key, opts, stats_from_dict(res) if isinstance(res, dict) else res)

    def _solve_parallel(self, hs: Sequence[Harvester], todo: list[tuple[int, str, str, dict[str, Any]]],
                        out: list[Stats | _Failure | None]) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        # fork where available: spawn re-runs the caller's __main__ in every worker, which
        # breaks user scripts without an ``if __name__ == "__main__"`` guard. Only
        # Fokker--Planck points go to the pool; they use no numba threads.
        methods = multiprocessing.get_all_start_methods()
        ctx = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
        with ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx) as ex:
            futures = {ex.submit(_solve_portable, hs[i], method, opts, self.fallback(hs[i], method)):
                       (i, key, opts) for i, key, method, opts in todo}
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


def _fpe_cost_rank(h: Harvester) -> tuple[bool, float, float]:
    """Sort key putting the dearest Fokker--Planck points first: 1 <= n < 2 (the 2-D scheme in
    (x, v), seconds to a minute) before n >= 2 (the expansion in x, about a second), then strong
    walls a first, then n nearest the kink. Measured on the paper's Fig. 1 grid (39 points, tol
    5e-3): the ten dearest points all have n < 2, and at a given n the cost grows with a (n = 1:
    5, 12, ~80 s at a = 0.5, 1, 2, the last including the Monte Carlo fallback)."""
    return (not 1.0 <= h.n < 2.0, -h.a, h.n)


def _attempt(h: Harvester, method: str, opts: dict[str, Any]) -> Stats | _Failure:
    """Solve one point; a failure becomes a :class:`_Failure` carrying the reason."""
    try:
        return solve(h, method, **opts)
    except MethodNotAvailableError as exc:
        return _Failure(NOT_AVAILABLE, str(exc), method)
    except HarvesterError as exc:
        return _Failure(ERROR, f"method {method!r} failed: {type(exc).__name__}: {exc}", method)
    except Exception as exc:  # noqa: BLE001
        # A solver bug (or a warning turned into an error) must not sink a long sweep:
        # report it on the point and go on. KeyboardInterrupt still stops the run.
        return _Failure(ERROR, f"method {method!r} raised {type(exc).__name__}: {exc}", method)


def _solve_point(h: Harvester, method: str, opts: dict[str, Any],
                 fallback: tuple[str, dict[str, Any]] | None) -> Stats | _Failure:
    """Solve one point; a point that did not reach its tolerance (Fokker--Planck density not
    resolved: no numbers, or numbers whose error exceeds the tolerance) is tried again with
    ``fallback`` (method, settings) if given, and :func:`~fpe_harvester.solve.fallback_result`
    decides which numbers to keep and says so in the message."""
    res = _attempt(h, method, opts)
    if not (fallback is not None and isinstance(res, Stats) and res.status is Status.NOT_CONVERGED):
        return res
    second = _attempt(h, *fallback)
    return fallback_result(res, second) if isinstance(second, Stats) else res


def _solve_portable(h: Harvester, method: str, opts: dict[str, Any],
                    fallback: tuple[str, dict[str, Any]] | None) -> dict[str, Any] | _Failure:
    """:func:`_solve_point` for a worker process: Stats travel as dicts (their info is read-only)."""
    res = _solve_point(h, method, opts, fallback)
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
        if hi > lo and runner.method_of(h0.replace(**{opt.over: 0.5 * (lo + hi)}))[0] == "mc":
            rows.append(_noisy_optimum_row(scene, runner, index, p, h0, lo, hi))
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
        exact = isinstance(res[best], Stats) and res[best].method == "exact"
        if at_bound is None and len(grid) > 1 and exact:
            def value(x: float) -> float:
                v = Exact().solve(h0.replace(**{opt.over: x})).value(opt.maximize)[0]
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
                       lo: float, hi: float) -> SceneRow:
    """A Monte Carlo optimum: :func:`~fpe_harvester.optimum.optimize` (common random numbers,
    quadratic fit, jackknife errors); the maximized observable is the fit's value at the vertex,
    the others come from one more solve there."""
    opt = scene.optimize
    assert opt is not None
    found = optimize(h0, opt.over, (lo, hi), opt.maximize, method="mc", seed=point_seed(scene.name, h0),
                     mc_tol=scene.rtol, progress=False)
    info: dict[str, Any] = {"optimize": {"maximize": opt.maximize, "over": opt.over, "interval": [lo, hi],
                                         **{k: v for k, v in found.to_dict().items() if k != "info"},
                                         "window": found.info.get("window"),
                                         "batches": found.info.get("batches")}}
    runner.bar.update(opt.points)
    if found.x_opt is None:
        return _row(scene, index, {**p, opt.over: None}, h0,  # type: ignore[dict-item]
                    _Failure(Status.NOT_CONVERGED.value, found.message, "mc"), info)
    final = runner.evaluate([h0.replace(**{opt.over: found.x_opt})])[0]
    row = _row(scene, index, {**p, opt.over: found.x_opt}, h0, final, info)
    values = {**row.values, opt.maximize: found.value, opt.maximize + "_err": found.value_err}
    status = row.status if found.status is Status.STABLE else found.status.value
    return SceneRow(row.index, row.point, status, "mc", f"{found.message}; {row.message}", values, row.info)


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
        A point is not a valid harvester, ``figures`` names an unknown figure, or the Dask
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
