"""Benchmarks: run each solver's benchmark module and combine their error-versus-wall-time curves.

The study modules :mod:`validation.studies.exact`, :mod:`validation.studies.fpe` and
:mod:`validation.studies.montecarlo` (:func:`bench_modules`) each provide ``run(quick, out) -> dict`` and write their own
JSON and PNG (named by their ``STEM``). Each may also return ``"series"``: a list of curves

``{"problem": key of PROBLEMS, "method": str, "points": [{"seconds": float, "error": float}
or {"seconds": float, "eta": float}, ...], "reference": str, "reference_eta": float (optional),
"reference_err": float (optional, relative)}``,

where ``error`` is the *actual* relative error of eta against the best reference (not a
reported one). Points given as ``eta`` get their error against the problem's reference: the
``reference_eta`` with the smallest ``reference_err`` among the series of that problem. The
combined figure has one panel per problem of :data:`PROBLEMS`, wall time on x, actual error on
y, one line per method; a problem whose reference has an uncertainty shows it as a dotted line
(errors below it are not resolved).

Speed targets (``X_target_s`` next to ``X_s``) are tabulated, not failed: timings belong to
the machine, correctness to the checks.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Mapping
from types import ModuleType
from typing import Any

from ..harness.checks import CheckResult, Context, expect
from ..harness.report import Figure, Section, Table, new_figure, save_figure

__all__ = ["bench_modules", "PROBLEMS", "error_time_pairs", "resolve_series", "run"]

_SECTION = "Benchmarks: error versus wall time"
def bench_modules() -> tuple[ModuleType, ...]:
    """The study modules this section runs, one per solver: exact, Fokker--Planck, Monte Carlo
    (imported when the section runs: importing them loads every solver)."""
    from ..studies import exact, fpe, montecarlo

    return exact, fpe, montecarlo


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


#: The problems of the combined figure, one panel each: key -> title.
PROBLEMS = {
    "harmonic_ring": "harmonic ring: N = 3, a = 0.5, k = -0.33",
    "n3_single": "single unit: n = 3, a = 0.5",
    "n1_single": "single unit: n = 1 (kink), a = 0.5",
    "n3_ring": "ring: n = 3, N = 3, a = 0.5, k = -0.5",
}

#: Line style per method (anything else: grey).
METHOD_STYLE = {
    "exact": ("tab:blue", "o", "-"),
    "Fokker-Planck": ("tab:green", "s", "-"),
    "Fokker-Planck (previous design)": ("tab:olive", "D", ":"),
    "Monte Carlo": ("tab:red", "^", "-"),
    "Monte Carlo + control variates": ("tab:purple", "v", "-"),
    "numpy Euler-Maruyama": ("black", "x", "--"),
}


def resolve_series(series: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """Group curves by problem and give every point its actual error.

    Returns ``{problem: [curve, ...]}`` with each point carrying ``error``; the curves of a
    problem get ``reference_used`` (eta, relative uncertainty, source). Points given as eta
    on a problem without a reference are dropped.

    Examples
    --------
    >>> out = resolve_series([
    ...     {"problem": "p", "method": "exact", "points": [{"seconds": 1e-4, "error": 0.0}],
    ...      "reference": "closed form", "reference_eta": 0.5, "reference_err": 0.0},
    ...     {"problem": "p", "method": "Monte Carlo", "points": [{"seconds": 2.0, "eta": 0.501}]}])
    >>> round(out["p"][1]["points"][0]["error"], 6)
    0.002
    """
    by: dict[str, list[dict[str, Any]]] = {}
    for cur in series:
        by.setdefault(cur["problem"], []).append(dict(cur, points=[dict(p) for p in cur["points"]]))
    for curves in by.values():
        refs = [c for c in curves if _number(c.get("reference_eta")) is not None]
        ref = min(refs, key=lambda c: _number(c.get("reference_err")) or 0.0) if refs else None
        for c in curves:
            if ref is not None:
                c["reference_used"] = (ref["reference_eta"], _number(ref.get("reference_err")) or 0.0,
                                       ref.get("reference", ref["method"]))
            kept = []
            for p in c["points"]:
                if _number(p.get("error")) is None and ref is not None and _number(p.get("eta")) is not None:
                    p["error"] = abs(p["eta"] - ref["reference_eta"]) / abs(ref["reference_eta"])
                if _number(p.get("error")) is not None and _number(p.get("seconds")):
                    kept.append(p)
            c["points"] = kept
    return by


def _plot(ctx: Context, series: list[dict[str, Any]]) -> Figure:
    by = resolve_series(series)
    fig, axes = new_figure((10, 7.5), ncols=2, nrows=2)
    for ax, (key, title) in zip(axes.ravel(), PROBLEMS.items()):
        curves = by.get(key, [])
        for c in curves:
            pts = sorted((p["seconds"], p["error"]) for p in c["points"])
            if not pts:
                continue
            color, marker, ls = METHOD_STYLE.get(c["method"], ("0.5", ".", "-"))
            # an error of exactly 0 (agreement to the last bit) is drawn at 1e-17
            ax.loglog([t for t, _ in pts], [max(e, 1e-17) for _, e in pts], color=color, marker=marker,
                      ls=ls if len(pts) > 1 else "none", lw=1, ms=5, label=c["method"])
        ref = next((c["reference_used"] for c in curves if "reference_used" in c), None)
        if ref is not None and ref[1] > 0:
            ax.axhline(ref[1], color="0.5", ls=":", lw=0.8)
        ax.set_title(title + ("" if curves else " (no data in this run)"), fontsize=9)
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel("actual relative error of eta")
        ax.grid(True, which="both", alpha=0.3)
        if curves:
            ax.legend(fontsize=7, loc="best")
    refs = "; ".join(f"{PROBLEMS[k]}: {next((c['reference_used'][2] for c in v if 'reference_used' in c), 'none')}"
                     for k, v in by.items() if k in PROBLEMS)
    return save_figure(fig, ctx.out / "bench_error_vs_time.png",
                       "Actual relative error of eta versus wall time, measured in this run, one panel per "
                       "problem and one line per method (dotted: the uncertainty of the reference; an error of "
                       f"exactly 0 is drawn at 1e-17). References: {refs}.")


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


def _run_one(ctx: Context, mod: ModuleType, sec: Section, curves: list[dict[str, Any]],
             targets: Table) -> list[CheckResult]:
    out = ctx.out / "bench"
    out.mkdir(parents=True, exist_ok=True)
    # a module's REPORT_KW narrows its short run to what this section needs (its own CLI runs all)
    data = mod.run(quick=True, out=out, **getattr(mod, "REPORT_KW", {}))
    name = mod.STEM
    _include(ctx, mod, sec, targets)
    pairs = list(error_time_pairs(data))
    curves.extend(data.get("series", []))
    for label, t, target in _targets(data):
        targets.rows.append((name, label, f"{t:.4g}", f"{target:.4g}", "yes" if t <= target else "NO"))
    for png in sorted(out.glob(f"{name}*.png")):
        sec.figures.append(Figure(png, f"{name}: {png.stem} (written by {mod.__name__})"))
    table = Table(f"{name}: error/time pairs", ("quantity", "wall time [s]", "error"),
                  [(lbl, f"{t:.4g}", f"{e:.3g}") for lbl, t, e in pairs[:60]],
                  note=f"All measurements: bench/{name}.json." if (out / f"{name}.json").exists() else "")
    sec.tables.append(table)
    (out / f"{name}.validation.json").write_text(json.dumps({"pairs": pairs}, indent=1))
    return [expect(f"benchmark {name}", _SECTION, bool(data),
                   f"ran; {len(pairs)} error/time pairs found" + ("" if pairs else " (none recognised)"))]


def run(ctx: Context) -> Section:
    """Run every benchmark module's short version and draw the combined plot; include the
    exhaustive runs written by ``python -m validation.studies.* --out DIR`` when the run was given
    ``DIR`` (``harvester validate --bench DIR``)."""
    sec = Section("benchmarks", _SECTION)
    curves: list[dict[str, Any]] = []
    targets = Table("Speed targets (reported, not failed)", ("benchmark", "measurement", "time [s]", "target [s]",
                                                             "met"))
    for mod in bench_modules():
        sec.checks += ctx.check(f"benchmark {mod.__name__}", _SECTION,
                                lambda mod=mod: _run_one(ctx, mod, sec, curves, targets))
    if curves:
        sec.figures.insert(0, _plot(ctx, curves))
    if targets.rows:
        sec.tables.insert(0, targets)
    sec.text.append(
        "Each benchmark module measures its own solver and baselines (numpy Euler-Maruyama loop, scipy dense "
        "Lyapunov) in this run, in its short version (the exhaustive sweeps, 1e-6 for every case and long Monte "
        "Carlo extrapolations, are python -m validation.studies.fpe, .montecarlo, .exact; harvester validate "
        "--bench DIR includes their latest output, labelled with its date)."
        + (f" Included: {ctx.bench}." if ctx.bench else " None included in this run.")
        + " The combined figure shows, for four problems, the actual error of eta (against "
        "the best reference of that problem) versus wall time, one line per method; each module's own table "
        "lists every error/time pair it reports (reported errors included)."
    )
    return sec
