"""Benchmarks: the work-precision diagrams, and each solver's benchmark module in its short version.

The work-precision diagrams (:mod:`validation.studies.work_precision`: every solver's actual
error of eta against its wall time over a range of tolerances, beside the baselines) are read
from the study's recorded full run in ``validation/data`` and drawn here; their checks read that
data only, so they are RECORDED, not passes. The Monte Carlo curves are measured against
references that do not share their errors; the Fokker--Planck curves against Fokker--Planck's own
run at a tighter tolerance (self-convergence: they show convergence, not correctness, which the
cross-checks against Monte Carlo and the exact solver test). The study modules
:mod:`validation.studies.exact.bench`, :mod:`validation.studies.fpe.bench` and
:mod:`validation.studies.mc.bench` (:func:`bench_modules`) each provide ``run(quick, out, **REPORT_KW)
-> dict`` and write their own JSON and PNG (named by their ``STEM``); every error/time pair they
report is tabulated (:func:`error_time_pairs`), and ``report_checks(data)`` says what their short
run compared (nothing, for a module that only times: then no check is counted).

Speed targets (``X_target_s`` next to ``X_s``) are tabulated, not failed: timings belong to
the machine, correctness to the checks.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from types import ModuleType
from typing import Any

from ..harness.checks import CheckResult, Context, expect, recorded
from ..harness.report import Figure, Section, Table

__all__ = ["bench_modules", "error_time_pairs", "run"]

_SECTION = "Benchmarks: error versus wall time"


def bench_modules() -> tuple[ModuleType, ...]:
    """The study modules this section runs, one per solver: exact, Fokker--Planck, Monte Carlo
    (imported when the section runs: importing them loads every solver)."""
    from ..studies.exact import bench as exact
    from ..studies.fpe import bench as fpe
    from ..studies.mc import bench as mc

    return exact, fpe, mc


def _is_time(key: str) -> bool:
    low = key.lower()
    return (low.endswith("_s") or "seconds" in low or "time" in low or low in ("s", "t", "wall")) and \
        "target" not in low and "err" not in low


def _is_error(key: str) -> bool:
    """Error-like keys: ``*err*`` or a standard error ``se`` as a ``_``-separated word."""
    low = key.lower()
    return ("err" in low or "se" in low.split("_")) and "target" not in low and "note" not in low


def _prefix_len(a: str, b: str) -> int:
    n = 0
    for x, y in zip(a.lower().split("_"), b.lower().split("_")):
        if x != y:
            break
        n += 1
    return n


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def error_time_pairs(data: Any, path: str = "") -> Iterator[tuple[str, float, float]]:
    """``(label, seconds, error)`` for every error/time pair found in a benchmark dict.

    Examples
    --------
    >>> list(error_time_pairs({"rows": [{"M": 4, "time_s": 0.1, "eta_rel_error": 1e-3}]}))
    [('rows[0] eta_rel_error', 0.1, 0.001)]
    """
    if isinstance(data, Mapping):
        times = {k: _number(v) for k, v in data.items() if _is_time(str(k)) and _number(v) is not None}
        for key, val in data.items():
            err = _number(val)
            if _is_error(str(key)) and err is not None and err >= 0 and times:
                tkey = max(times, key=lambda t: (_prefix_len(t, str(key)), -len(t)))
                if times[tkey] and times[tkey] > 0:
                    yield (f"{path} {key}".strip(), float(times[tkey]), err)
        for key, val in data.items():
            if isinstance(val, (Mapping, list, tuple)):
                yield from error_time_pairs(val, f"{path}.{key}" if path else str(key))
    elif isinstance(data, (list, tuple)):
        for i, val in enumerate(data):
            yield from error_time_pairs(val, f"{path}[{i}]")


def _targets(data: Any, prefix: str = "") -> Iterator[tuple[str, float, float]]:
    if isinstance(data, Mapping):
        for key, val in data.items():
            k = str(key)
            if k.endswith("_target_s"):
                base = k[: -len("_target_s")] + "_s"
                t, target = _number(data.get(base)), _number(val)
                if t is not None and target is not None:
                    yield (f"{prefix}{base}", t, target)
            elif isinstance(val, Mapping):
                yield from _targets(val, f"{prefix}{k}.")


def _work_precision(ctx: Context, sec: Section) -> list[CheckResult]:
    """The work-precision diagrams recorded by :mod:`validation.studies.work_precision` (its full
    run, committed in ``validation/data``): the figure drawn from the JSON and the table of
    each solver's range; checked (RECORDED: the data's, not this run's) to hold every solver of
    every case over at least two points, each curve spanning two decades of resolved error."""
    from ..studies import work_precision as wp

    source = f"validation/data/{wp.STEM}.json"
    if not wp.RECORDED.exists():
        return [expect("work-precision data", _SECTION, False, f"{source} missing: {wp.COMMAND}")]
    res = json.loads(wp.RECORDED.read_text())
    path = ctx.out / "work_precision.png"
    wp.plot(res, path)
    sec.figures.insert(0, Figure(path, wp.CAPTION + f" Recorded by {wp.COMMAND} ({'quick' if res['quick'] else 'full'} "
                                                     f"run, {res['wall_s']:.0f} s; not this run)."))
    head, rows = wp.summary_rows(res)
    sec.tables.insert(0, Table("Work-precision: each solver's range (recorded)", head, rows,
                               note=f"Data: {source}; regenerate: {wp.COMMAND}. Monte Carlo errors against "
                                    "independent references; Fokker-Planck errors against its own tighter run "
                                    "(self-convergence)."))
    thin = [f"{case['title']}: {c['method']} ({len(c['points'])} points)" for case in res["cases"].values()
            for c in case["curves"] if len(c["points"]) < 2]
    spans = [(case["title"], c["method"], *wp.resolved(c))
             for case in res["cases"].values() for c in case["curves"] if c["method"] in wp.SOLVERS and c["points"]]
    short = [f"{title}: {method} {d:.2g}" for title, method, d, floor in spans if d < wp.DECADES and not floor]
    floored = [f"{title}: {method} {d:.2g}" for title, method, d, floor in spans if d < wp.DECADES and floor]
    return [recorded("work-precision data: every solver of every case is a curve", _SECTION,
                     not thin and not res["quick"],
                     f"{len(res['cases'])} cases from a {'quick' if res['quick'] else 'full'} run; curves with fewer "
                     f"than two points: {'; '.join(thin) or 'none'}", source=source, command=wp.COMMAND),
            recorded(f"work-precision data: each solver's curve spans {wp.DECADES:g} decades of resolved error or "
                     "reaches its reference's own error", _SECTION, not short and not res["quick"],
                     f"smallest span {min(d for _, _, d, _ in spans):.2g} decades over {len(spans)} curves "
                     f"(errors above each reference's own; Fokker-Planck's reference is its own tighter run); "
                     f"shorter, down to the reference's error: {'; '.join(floored) or 'none'}; shorter, above it: "
                     f"{'; '.join(short) or 'none'}", source=source, command=wp.COMMAND)]


def _include(ctx: Context, mod: Any, sec: Section, targets: Table) -> None:
    """The exhaustive run of benchmark ``mod`` found in ``ctx.bench`` (its JSON and figures)."""
    if ctx.bench is None:
        return
    path = ctx.bench / f"{mod.STEM}.json"
    if not path.exists():
        sec.text.append(f"No exhaustive run of {mod.__name__} in {ctx.bench} ({path.name} missing).")
        return
    import datetime

    data = json.loads(path.read_text())
    stamp = datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc)
    when = stamp.strftime("%Y-%m-%d %H:%M UTC")
    origin = f"exhaustive run of python -m {mod.__name__}, written {when} (not this run)"
    for label, t, target in _targets(data):
        targets.rows.append((f"{mod.STEM} ({origin})", label, f"{t:.4g}", f"{target:.4g}",
                             "yes" if t <= target else "NO"))
    for png in sorted(ctx.bench.glob(f"{mod.STEM}*.png")):
        sec.figures.append(Figure(png.resolve(), f"{mod.STEM}: {png.stem}, {origin}"))
    pairs = list(error_time_pairs(data))
    sec.tables.append(Table(f"{mod.STEM}, {origin}: error/time pairs", ("quantity", "wall time [s]", "error"),
                            [(lbl, f"{t:.4g}", f"{e:.3g}") for lbl, t, e in pairs[:80]],
                            note=f"All measurements: {path}."))


def _run_one(ctx: Context, mod: ModuleType, sec: Section, targets: Table) -> list[CheckResult]:
    out = ctx.out / "bench"
    out.mkdir(parents=True, exist_ok=True)
    # a module's REPORT_KW narrows its short run to what this section needs (its own CLI runs all)
    data = mod.run(quick=True, out=out, **mod.REPORT_KW)
    name = mod.STEM
    _include(ctx, mod, sec, targets)
    pairs = list(error_time_pairs(data))
    for label, t, target in _targets(data):
        targets.rows.append((name, label, f"{t:.4g}", f"{target:.4g}", "yes" if t <= target else "NO"))
    for png in sorted(out.glob(f"{name}*.png")):
        sec.figures.append(Figure(png, f"{name}: {png.stem} (written by {mod.__name__})"))
    table = Table(f"{name}: error/time pairs", ("quantity", "wall time [s]", "error"),
                  [(lbl, f"{t:.4g}", f"{e:.3g}") for lbl, t, e in pairs[:60]],
                  note=f"All measurements: bench/{name}.json." if (out / f"{name}.json").exists() else "")
    sec.tables.append(table)
    (out / f"{name}.validation.json").write_text(json.dumps({"pairs": pairs}, indent=1))
    # what the short run compared (a module that only times compares nothing: no check counted)
    return [expect(f"benchmark {name}: {label}", _SECTION, ok, detail)
            for label, ok, detail in mod.report_checks(data)]


def run(ctx: Context) -> Section:
    """The recorded work-precision diagrams, then every benchmark module's short version; include
    the exhaustive runs written by ``python -m validation.studies.* --out DIR`` when the run was
    given ``DIR`` (``harvester validate --bench DIR``)."""
    sec = Section("benchmarks", _SECTION)
    targets = Table("Speed targets (reported, not failed)", ("benchmark", "measurement", "time [s]", "target [s]",
                                                             "met"))
    for mod in bench_modules():
        sec.checks += ctx.check(f"benchmark {mod.__name__}", _SECTION,
                                lambda mod=mod: _run_one(ctx, mod, sec, targets))
    if targets.rows:
        sec.tables.insert(0, targets)
    sec.checks += ctx.check("work-precision diagrams", _SECTION, lambda: _work_precision(ctx, sec))
    sec.text.append(
        "The work-precision figure (first) shows, for the harmonic ring, the exact solver's time against the "
        "ring size beside scipy's dense Lyapunov solve, and for a smooth unit, the kink and a ring, each "
        "solver's actual error of eta against its wall time over a range of tolerances, beside the baselines a "
        "user would otherwise write (plain Monte Carlo, a numpy Euler-Maruyama script). The Monte Carlo and "
        "baseline errors are measured against references that do not share them (Fokker-Planck for single units, "
        "an independent long Monte Carlo run for the ring, the closed form for the harmonic ring); the "
        "Fokker-Planck errors against Fokker-Planck's own run ten times tighter than its tightest point "
        "(self-convergence: a measure of convergence, not of correctness; no independent method reaches its "
        "errors, and the cross-checks test it against Monte Carlo and the exact solver). The figure is recorded "
        "by a full run of the study, not this run, so its checks are RECORDED. "
        "Each benchmark module then measures its own solver and baselines in this run, in its short version "
        "(the exhaustive sweeps are python -m validation.studies.fpe.bench, .mc.bench, .exact.bench; harvester validate "
        "--bench DIR includes their latest output, labelled with its date)."
        + (f" Included: {ctx.bench}." if ctx.bench else " None included in this run.")
        + " Each module's table lists every error/time pair it reports (reported errors included)."
    )
    return sec
