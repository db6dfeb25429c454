"""The paper's figures: run every shipped scene (:mod:`fpe_harvester.scenes`) and embed its
figures and data in the report.

Scenes choose the cheapest adequate solver per point (exact, Fokker--Planck, Monte Carlo)
and write CSV/JSON next to each PNG. A scene passes when every point was computed (stable,
marginal, metastable, unstable and not-converged points are results with a status); a
point whose solver is not installed makes the scene *skipped*; a solver error fails it.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from .checks import CheckResult, Context, expect, skipped
from .report import Figure, Section, Table

__all__ = ["MAX_ROWS", "run_exact", "run_solvers"]

_SECTION = "The paper's figures (scenes)"
#: Rows of each scene's data shown in the report (the CSV has them all).
MAX_ROWS = 40


def _fmt(v: object) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _run_one(ctx: Context, name: str, sec: Section) -> list[CheckResult]:
    from fpe_harvester.scenes import load_scene, run_scene

    scene = load_scene(name)
    folder = ctx.out / "scenes" / name
    # A validation run computes afresh: a cache left by an earlier run (older code) must not be reused.
    shutil.rmtree(folder, ignore_errors=True)
    res = run_scene(scene, folder, quick=ctx.quick, progress=False)
    for fig_name, path in res.figures.items():
        sec.figures.append(Figure(Path(path), f"{res.scene.title or name} [{fig_name}] "
                                              f"(scene '{name}', {len(res.rows)} points, {res.elapsed:.1f} s)"))
    cols = res.columns
    obs = list(res.scene.observables)
    table = Table(f"Scene '{name}': data" + (f" (first {MAX_ROWS} of {len(res.rows)} rows)"
                                             if len(res.rows) > MAX_ROWS else ""),
                  (*cols, *(f"{o}_err" for o in obs), "status", "method"))
    for row in res.rows[:MAX_ROWS]:
        table.rows.append((*(_fmt(row.get(c)) for c in cols), *(_fmt(row.values.get(o + "_err")) for o in obs),
                           row.status, row.method))
    paths = [str(p.relative_to(ctx.out)) for p in (res.csv_path, res.json_path) if p is not None]
    table.note = f"Full data: {', '.join(paths)}." if paths else ""
    sec.tables.append(table)
    errors = [r for r in res.rows if r.status == "error"]
    missing = [r for r in res.rows if r.status == "not_available"]
    label = f"scene {name}"
    if errors:
        return [expect(label, _SECTION, False, f"{len(errors)} of {len(res.rows)} points failed: "
                       + "; ".join(r.message for r in errors[:3]))]
    if missing:
        return [skipped(label, _SECTION, f"{len(missing)} of {len(res.rows)} points have no solver available "
                        f"({missing[0].message}); figure drawn from the rest")]
    statuses = sorted({r.status for r in res.rows})
    return [expect(label, _SECTION, bool(res.figures) or not res.scene.figures,
                   f"{len(res.rows)} points ({res.computed} computed, {res.reused} reused), statuses {statuses}, "
                   f"figures {sorted(res.figures)}")]


def _is_exact(name: str) -> bool:
    """True for a scene whose every point is harmonic (exact solver, about a second)."""
    from fpe_harvester.scenes import load_scene

    scene = load_scene(name)
    return scene.system.is_linear and all(ax.name != "n" for ax in scene.axes)


def run_exact(ctx: Context) -> Section:
    """The harmonic scenes (exact solver; cheap)."""
    return _run(ctx, "figures_exact", f"{_SECTION}: harmonic (exact)", True)


def run_solvers(ctx: Context) -> Section:
    """The scenes that need Fokker--Planck or Monte Carlo."""
    return _run(ctx, "figures_solvers", f"{_SECTION}: nonlinear (Fokker-Planck, Monte Carlo)", False)


def _run(ctx: Context, key: str, title: str, exact: bool) -> Section:
    sec = Section(key, title)
    try:
        from fpe_harvester.scenes import list_scenes
    except ImportError as exc:
        sec.checks.append(skipped("paper figures (scenes)", title, f"fpe_harvester.scenes not available ({exc})"))
        return sec
    names = [n for n in list_scenes() if "kdi" not in n.replace("_", "").lower()
             and _is_exact(n) == exact]
    sec.text.append(
        f"Scenes run{' in quick mode (reduced grids, looser accuracy)' if ctx.quick else ''}: {', '.join(names)}. "
        "Each point uses the cheapest adequate solver; error bars where the method has them."
    )
    for name in names:
        sec.checks += ctx.check(f"scene {name}", title, lambda name=name: _run_one(ctx, name, sec))
    return sec
