"""Benchmarks: run each solver's benchmark module and combine their error-versus-wall-time data.

The modules :mod:`validation.bench.exact`, :mod:`validation.bench.fpe` and
:mod:`validation.bench.montecarlo` each provide ``run(quick, out) -> dict`` and write their own
JSON and PNG (named by their ``STEM``). Their dicts differ in layout, so (time, error) pairs are found by key names:
in every dict (nested ones and rows of lists included) an error key (name contains ``err`` or
the word ``se``)
is paired with the time key (name ends in ``_s`` or contains ``time``/``seconds``) that shares
the longest name prefix with it. The pairs of all modules go on one log-log plot.
Speed targets (``X_target_s`` next to ``X_s``) are tabulated, not failed: timings belong to
the machine, correctness to the checks.
"""

from __future__ import annotations

import importlib
import json
import math
from collections.abc import Iterator, Mapping
from typing import Any

from ..checks import CheckResult, Context, expect, skipped
from ..report import Figure, Section, Table

__all__ = ["BENCH_MODULES", "error_time_pairs", "run"]

_SECTION = "Benchmarks: error versus wall time"
#: Benchmark modules and the solver each measures.
BENCH_MODULES = (("validation.bench.exact", "exact"), ("validation.bench.fpe", "fpe"),
                 ("validation.bench.montecarlo", "mc"))


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


def _series_name(label: str) -> str:
    """Group pairs into curves: the label with list indices removed."""
    import re

    return re.sub(r"\.\d+(\.\d+)?(?= )", "", re.sub(r"\[\d+\]", "", label))


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


def _plot(ctx: Context, curves: dict[str, list[tuple[float, float]]]) -> Figure:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 5.5))
    colors = {"exact": "tab:blue", "fpe": "tab:green", "mc": "tab:red"}
    markers = "os^vDP*Xph<>"
    used: dict[str, int] = {}
    for label, pts in sorted(curves.items()):
        pts = sorted(pts)
        solver = label.split(":")[0]
        baseline = "numpy_em" in label or "dense" in label
        i = used[solver] = used.get(solver, -1) + 1
        style = dict(color="black" if baseline else colors.get(solver, "gray"), marker=markers[i % len(markers)],
                     ls="--" if baseline else "-", lw=1, ms=4)
        # An error of exactly 0 (exact arithmetic agreed to the last bit) is drawn at 1e-17.
        ax.loglog([p[0] for p in pts], [max(p[1], 1e-17) for p in pts], label=label + (" (baseline)" if baseline else ""),
                  **(style if len(pts) > 1 else {**style, "ls": "none"}))
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("error (as reported by each benchmark)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, loc="best")
    fig.tight_layout()
    path = ctx.out / "bench_error_vs_time.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Figure(path, "Error versus wall time of every solver (blue exact, green Fokker-Planck, red Monte Carlo) "
                        "and baseline (black dashed: numpy Euler-Maruyama, scipy dense Lyapunov), measured in "
                        "this run (log-log; an error of exactly 0 is drawn at 1e-17).")


def _run_one(ctx: Context, module: str, solver: str, sec: Section,
             curves: dict[str, list[tuple[float, float]]], targets: Table) -> list[CheckResult]:
    try:
        mod = importlib.import_module(module)
    except ImportError as exc:
        return [skipped(f"benchmark {module}", _SECTION, f"module not available ({exc})")]
    out = ctx.out / "bench"
    out.mkdir(parents=True, exist_ok=True)
    data = mod.run(quick=ctx.quick, out=out)
    name = mod.STEM
    pairs = list(error_time_pairs(data))
    for label, t, e in pairs:
        curves.setdefault(f"{solver}: {_series_name(label)}", []).append((t, e))
    for label, t, target in _targets(data):
        targets.rows.append((name, label, f"{t:.4g}", f"{target:.4g}", "yes" if t <= target else "NO"))
    for png in sorted(out.glob(f"{name}*.png")):
        sec.figures.append(Figure(png, f"{name}: {png.stem} (written by {module})"))
    table = Table(f"{name}: error/time pairs", ("quantity", "wall time [s]", "error"),
                  [(lbl, f"{t:.4g}", f"{e:.3g}") for lbl, t, e in pairs[:60]],
                  note=f"All measurements: bench/{name}.json." if (out / f"{name}.json").exists() else "")
    sec.tables.append(table)
    (out / f"{name}.validation.json").write_text(json.dumps({"pairs": pairs}, indent=1))
    return [expect(f"benchmark {name}", _SECTION, bool(data),
                   f"ran; {len(pairs)} error/time pairs found" + ("" if pairs else " (none recognised)"))]


def run(ctx: Context) -> Section:
    """Run every benchmark module (quick mode in CI) and draw the combined plot."""
    sec = Section("benchmarks", _SECTION)
    curves: dict[str, list[tuple[float, float]]] = {}
    targets = Table("Speed targets (reported, not failed)", ("benchmark", "measurement", "time [s]", "target [s]",
                                                             "met"))
    for module, solver in BENCH_MODULES:
        sec.checks += ctx.check(f"benchmark {module}", _SECTION,
                              lambda module=module, solver=solver: _run_one(ctx, module, solver, sec, curves, targets))
    if curves:
        sec.figures.insert(0, _plot(ctx, curves))
    if targets.rows:
        sec.tables.insert(0, targets)
    sec.text.append(
        "Each benchmark module measures its own solver and baselines (numpy Euler-Maruyama loop, scipy dense "
        "Lyapunov) on the same problems in this run; the combined plot puts every error/time pair they report "
        "on one log-log chart. Errors are as each benchmark defines them (relative error of eta against a "
        "reference, or a reported standard error); see each module's table."
    )
    return sec
