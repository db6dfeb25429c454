"""Run the whole validation and write the report (``harvester validate``, ``python -m validation``).

The steps are the report's sections, each a module with ``run(ctx) -> Section``, read in the
order of :data:`validation.sections.SECTIONS`: the cross-checks, the error bars, the paper
comparison, beyond the paper, the stress tests, the paper's figures (scenes), the benchmarks, and
last the stationary identities on every result computed in the run. The same table says the
order they run in, in a quick and in a full run. A step that crashes becomes a failed check;
the run always ends with a report.
"""

from __future__ import annotations

import importlib
import os
import platform
import resource
import sys
import time
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from pathlib import Path

from fpe_harvester.errors import ParameterError, check_int

from ..sections import SECTIONS, Step
from .checks import Context, SolveCache, guarded
from .report import Report, Section, summary_text, write_html, write_markdown

__all__ = ["SECTIONS", "Step", "QUICK_BUDGET", "QUICK_MIN_RAN", "validate", "exit_code", "run_cli"]

#: Wall-time budget [s] of the checks in quick mode; checks that would start later are skipped
#: (and listed as such), so that CI always gets its report within 3 minutes.
QUICK_BUDGET = 165.0


def cpu_time(cache: SolveCache | None = None) -> float:
    """Processor time [s] used so far by this process (all threads), its finished children and
    the live worker process of ``cache`` (a :class:`~.checks.SolveCache`, if given)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    worker = cache.worker_cpu() if cache is not None else 0.0
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime + worker


def _announce(ctx: Context, modules: Sequence[str | Callable[[Context], Section]]) -> list[str]:
    """Call each step module's ``prefetch(ctx)``, if it has one, in run order: the solves it
    announces start in the background (:meth:`SolveCache.prefetch`; full run only). Returns
    what went wrong (a step then solves in this process what it could not announce)."""
    problems: list[str] = []
    if not ctx.cache.background:
        return problems
    seen = set()
    for module in modules:
        if not isinstance(module, str):
            continue
        name = module.partition(":")[0]
        if name in seen:
            continue
        seen.add(name)
        try:
            hook = getattr(importlib.import_module(name), "prefetch", None)
        except Exception:  # noqa: BLE001 - the step reports its own import failure
            continue
        if hook is not None:
            problems += [f"{name}: {c.detail}" for c in guarded(f"prefetch {name}", name, lambda: hook(ctx) or [])
                         if not c.passed]
    return problems


def _run_steps(ctx: Context, plan: list[Step], order: list[int], done: dict[int, Section],
               progress: Callable[[str], None] | None, finished: Callable[[Section], None] | None) -> None:
    """Run ``plan[i]`` for each ``i`` of ``order`` into ``done[i]``, each section stamped with its wall
    and processor time (:func:`cpu_time`: the worker process's time counts in the section it was
    used in) and handed to ``finished``."""
    for i in order:
        target, title = plan[i].target, plan[i].title
        if progress:
            progress(title)
        t0, c0 = time.perf_counter(), cpu_time(ctx.cache)
        holder: list[Section] = []

        def step(target: str | Callable[[Context], Section] = target) -> list:
            if isinstance(target, str):
                name, _, func = target.partition(":")
                fn = getattr(importlib.import_module(name), func or "run")
            else:
                fn = target
            holder.append(fn(ctx))
            return []

        crash = guarded(title, title, step)
        sec = holder[0] if holder else Section(str(target).rsplit(".", 1)[-1], title)
        sec.title = title
        sec.checks += crash
        sec.seconds = time.perf_counter() - t0
        sec.cpu_seconds = cpu_time(ctx.cache) - c0
        if finished:
            finished(sec)
        done[i] = sec


def validate(
    quick: bool = False,
    out: Path | str = "validation_report",
    seed: int = 2017,
    steps: Sequence[Step | tuple] | None = None,
    progress: Callable[[str], None] | None = None,
    bench: Path | str | None = None,
    finished: Callable[[Section], None] | None = None,
) -> Report:
    """Run the validation steps and write ``report.md`` and ``report.html`` into ``out``.

    Parameters
    ----------
    quick : bool
        CI mode (subsets, short budgets; < 3 minutes on 2 cores).
    out : path
        Output folder, created if needed.
    seed : int
        Base seed of the Monte Carlo runs, >= 0.
    steps : sequence of :class:`~validation.sections.Step`, optional
        The steps to run, in the report's order (default :data:`~validation.sections.SECTIONS`); a
        plain ``(target, title)`` runs in that order too.
    progress : callable, optional
        Called with the title of each step before it starts.
    bench : path, optional
        Folder written by ``python -m validation.studies.fpe.bench --out DIR`` (and the other
        benchmark modules): their exhaustive results are included in the report. The
        report's own benchmark section always runs the short benchmarks.
    finished : callable, optional
        Called with each section (its ``seconds`` and checks filled in) as soon as it is done.

    Returns
    -------
    Report
        All sections and checks; ``report.failed`` says whether any check failed.
    """
    seed = check_int("seed", seed, low=0)
    if bench is not None and not Path(bench).is_dir():
        raise ParameterError(f"bench must be a folder written by python -m validation.studies.*, got {str(bench)!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    # full run: Fokker-Planck solves in a second process beside the Monte Carlo ones (SolveCache)
    ctx = Context(quick=quick, out=out.resolve(), cache=SolveCache(background=not quick), seed=seed,
                  deadline=t_start + QUICK_BUDGET if quick else None,
                  bench=None if bench is None else Path(bench).resolve())
    report = Report("fpe-harvester validation report" + (" (quick)" if quick else ""))
    report.meta.update({
        "date (UTC)": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S"),
        "mode": "quick (CI subset)" if quick else "full",
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "Monte Carlo seed": str(seed),
    })
    plan = [Step(*s) for s in (SECTIONS if steps is None else steps)]
    order = sorted(range(len(plan)), key=lambda i: (plan[i].quick if quick else plan[i].full, i))
    c_start = cpu_time(ctx.cache)
    problems = _announce(ctx, [plan[i].target for i in order])
    if problems:
        report.meta["announcing solves failed (the steps solved them themselves)"] = "; ".join(problems)
    done: dict[int, Section] = {}
    try:
        _run_steps(ctx, plan, order, done, progress, finished)
    finally:
        ctx.cache.close()
    if ctx.cache.background:
        report.meta["Fokker-Planck solves in a second process"] = (
            f"{ctx.cache.announced} announced, {ctx.cache.prefetched} used; this process waited for them "
            f"{ctx.cache.waited:.1f} s in all")
    report.sections += [done[i] for i in range(len(plan))]
    if ctx.cache.dropped:
        report.meta["solver options not supported (dropped)"] = "; ".join(
            f"{m}: {', '.join(sorted(o))}" for m, o in ctx.cache.dropped.items())
    report.meta["total wall time"] = f"{time.perf_counter() - t_start:.1f} s"
    report.meta["total CPU time"] = f"{cpu_time() - c_start:.1f} s (all threads and processes)"
    write_markdown(report, out / "report.md")
    write_html(report, out / "report.html")
    return report


#: Least fraction of a quick run's checks that must have run (not skipped) for it to pass.
QUICK_MIN_RAN = 0.9


def exit_code(report: Report, quick: bool) -> int:
    """1 if a check failed, if a full run skipped any check (nothing may go unchecked there),
    or if a quick run skipped more than 1 - :data:`QUICK_MIN_RAN` of its checks (a quick run
    may skip a few for its time budget, and says how many and which); else 0. Recorded checks
    and findings do not fail a run: the summary counts them apart from the passes."""
    if report.failed:
        return 1
    n_skip, n_all = len(report.skipped), len(report.checks)
    if quick:
        return 1 if n_all == 0 or n_all - n_skip < QUICK_MIN_RAN * n_all else 0
    return 1 if n_skip else 0


def run_cli(quick: bool = False, out: Path | str = "validation_report", seed: int = 2017,
            progress: bool = True, bench: Path | str | None = None) -> int:
    """Run :func:`validate` over :data:`~validation.sections.SECTIONS`, print the pass/fail summary.

    Returns the exit code (:func:`exit_code`): 1 if any check failed or, in a full run, was
    skipped; else 0.
    """
    steps = SECTIONS
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(steps), desc="validate", unit="step", file=sys.stderr,
                   disable=None)  # drawn only on a terminal, as the solvers' bars
    started: list[str] = []

    def tick(title: str) -> None:
        if bar is not None:
            if started:
                bar.update(1)
            bar.set_postfix_str(title)
        started.append(title)

    def step_done(sec: Section) -> None:
        failed = sum(c.outcome.value == "FAIL" for c in sec.checks)
        found = sum(c.outcome.value == "FINDING" for c in sec.checks)
        kept = sum(c.outcome.value == "RECORDED" for c in sec.checks)
        line = (f"{time.perf_counter() - t0:7.1f} s  {sec.title}: {sec.seconds:.1f} s ({sec.cpu_seconds:.0f} CPU-s), "
                f"{len(sec.checks)} checks"
                + (f", {kept} recorded" if kept else "")
                + (f", {found} finding{'' if found == 1 else 's'}" if found else "")
                + (f", {failed} FAILED" if failed else ""))
        if bar is not None:
            bar.write(line, file=sys.stderr)
        else:
            print(line, file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    report = validate(quick=quick, out=out, seed=seed, steps=steps, progress=tick, bench=bench,
                      finished=step_done)
    if bar is not None:
        bar.update(bar.total - bar.n)
        bar.close()
    print(summary_text(report))
    skips = report.skipped
    if skips:
        ran = 1.0 - len(skips) / max(len(report.checks), 1)
        print(f"{len(skips)} check(s) SKIPPED (listed above): "
              + (f"{ran:.0%} of the checks ran; a quick run fails below {QUICK_MIN_RAN:.0%}, the full run "
                 "on any skip." if quick else "the full run fails: every check must run."))
    elif quick and not report.checks:
        print("no check ran: the quick run fails.")
    print(f"report: {Path(out) / 'report.md'} and {Path(out) / 'report.html'} "
          f"({time.perf_counter() - t0:.1f} s)")
    return exit_code(report, quick)

