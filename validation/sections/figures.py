"""The paper's figures: run every shipped scene (:mod:`fpe_harvester.scenes`) and embed its
figures and data in the report.

Scenes choose the cheapest adequate solver per point (exact, Fokker--Planck, Monte Carlo)
and write CSV/JSON next to each PNG. Each scene is checked on what it promises
(:func:`row_checks`): every status true for its system, the accuracy asked for met by every
stable or marginal row, harmonic rows equal to the closed form in 60-digit arithmetic, and every
figure asked for drawn. A point whose solver is not installed makes the scene *skipped*; a
solver error fails it.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path
from typing import Any

from fpe_harvester import Params, solve

from ..harness.checks import CheckResult, Context, agree, expect, skipped
from ..harness.report import Figure, Section, Table

__all__ = ["FALLBACK_SIGMAS", "MAX_ROWS", "fallback_check", "row_checks", "run_exact", "run_solvers"]

_SECTION = "The paper's figures (scenes)"
#: Rows of each scene's data shown in the report (the CSV has them all).
MAX_ROWS = 40
#: Combined error bars within which Fokker--Planck and Monte Carlo must agree at a point that was
#: solved by both (three: about one point in 370 outside by chance if both bars are honest).
FALLBACK_SIGMAS = 3.0


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
    # Fokker--Planck points are single-threaded: one process per core (Monte Carlo points run
    # in this process, multi-threaded)
    res = run_scene(scene, folder, quick=ctx.quick, progress=False, workers=os.cpu_count() or 1)
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
    return [expect(f"{label}: figures", _SECTION, len(res.figures) == len(res.scene.figures),
                   f"{len(res.rows)} points ({res.computed} computed, {res.reused} reused), statuses {statuses}, "
                   f"figures drawn {sorted(res.figures)} of {[f.name for f in res.scene.figures]}"),
            *row_checks(label, res.scene, res.rows), *fallback_check(label, res.scene, res.rows)]


def row_checks(label: str, scene: Any, rows: list[Any]) -> list[CheckResult]:
    """What a scene's rows promise, checked: true statuses, the accuracy asked for, exact values.

    * every status is true for its system: ``unstable`` only where the exact solver finds no
      stationary state (harmonic beyond k_di), ``marginal`` only for a harmonic ring,
      ``metastable`` only for an n < 2 ring with k < 0;
    * a stable or marginal row has finite values with errors below them and meets the scene's
      relative accuracy ``rtol`` on eta (a row that does not is a failure, whatever its status:
      the runner reports it as ``not_converged``, and a ``not_converged`` row with numbers fails);
    * harmonic rows agree with the closed form evaluated in 60-digit arithmetic
      (:func:`validation.references.mp_closed_form`) within their stated errors.
    """
    from fpe_harvester.exact import MARGINAL_RTOL

    from ..references.analytic import mp_closed_form

    # the sweep axes and an optimized coupling: every field of the point that defines the system
    fields = {"a", "n", "N", "k", *Params().to_dict()}
    false_status, inaccurate, wrong = [], [], []
    n_exact = 0
    for row in rows:
        h = scene.harvester({key: v for key, v in row.point.items() if key in fields})
        where = ", ".join(f"{key} = {v:g}" for key, v in row.point.items())
        truth = solve(h, "exact").status.value if h.is_linear else h.confinement
        if (row.status == "unstable" and truth != "unstable") or (row.status == "marginal" and truth != "marginal") \
                or (row.status == "metastable" and truth != "metastable"):
            false_status.append(f"({where}) {row.status}, truly {truth}")
        eta, err = row.values.get("eta"), row.values.get("eta_err")
        if row.status == "not_converged" and eta is not None:
            # the scene runner demotes a row that misses rtol to not_converged: still a failure
            inaccurate.append(f"({where}) not converged: eta = {eta} +- {err}")
        if not row.ok:
            continue
        if eta is not None and not (err is not None and math.isfinite(eta) and 0 <= err <= scene.rtol * abs(eta)):
            inaccurate.append(f"({where}) eta = {eta} +- {err}")
        if row.method == "exact":
            n_exact += 1
            ref = mp_closed_form(h, marginal=MARGINAL_RTOL if row.status == "marginal" else 0.0)
            ref["Vrms"] = ref["V2"] ** 0.5
            for q in scene.observables:
                v, e = row.values.get(q), row.values.get(q + "_err")
                if q in ref and v is not None and not abs(v - ref[q]) <= (e or 0.0) + 1e-13 * abs(ref[q]):
                    wrong.append(f"({where}) {q} = {v!r} +- {e}, 60 digits: {float(ref[q])!r}")
    return [
        expect(f"{label}: statuses", _SECTION, not false_status,
               f"{len(rows)} rows; false statuses: {'; '.join(false_status[:5]) or 'none'}"),
        expect(f"{label}: accuracy rtol = {scene.rtol:g} on eta", _SECTION, not inaccurate,
               f"{sum(r.ok for r in rows)} stable/marginal rows; missing the accuracy: "
               f"{'; '.join(inaccurate[:5]) or 'none'}"),
        *([expect(f"{label}: harmonic rows vs the 60-digit closed form", _SECTION, not wrong,
                  f"{n_exact} exact rows; off by more than their errors: {'; '.join(wrong[:3]) or 'none'}")]
          if n_exact else []),
    ]


def fallback_check(label: str, scene: Any, rows: list[Any]) -> list[CheckResult]:
    """The points solved twice (Fokker--Planck missed its tolerance, Monte Carlo was tried):
    counted, and where both solvers gave numbers, held to agree on every observable of the
    scene within :data:`FALLBACK_SIGMAS` combined error bars (a missing error bar counts as 0,
    so it can only make the check stricter). No check when no point was solved twice; a SKIP
    when points were solved twice but no value came from both solvers (nothing compared).

    The other solver's numbers come from the row's ``info["fallback"]``
    (:func:`fpe_harvester.scenes.run_scene` records them).
    """
    twice = [r for r in rows if r.info.get("fallback")]
    if not twice:
        return []
    kept_mc = sum(r.info["fallback"]["kept"] == "mc" for r in twice)
    compared, off = 0, []
    for row in twice:
        other = row.info["fallback"]["other"]
        where = ", ".join(f"{key} = {v:g}" for key, v in row.point.items())
        for q in scene.observables:
            if row.values.get(q) is None or other.get(q) is None:
                continue
            compared += 1
            c = agree(q, _SECTION, row.values[q], row.values.get(q + "_err"), other[q], other.get(q + "_err"),
                      n_sigma=FALLBACK_SIGMAS)
            if not c.passed:
                off.append(f"({where}) {q}: {row.method} vs {other['method']} {c.detail}")
    name = f"{label}: points solved by both Fokker-Planck and Monte Carlo agree"
    if compared == 0:
        return [skipped(name, _SECTION, f"{len(twice)} of {len(rows)} points missed the Fokker-Planck tolerance and "
                        f"were tried with Monte Carlo ({kept_mc} kept Monte Carlo's numbers), but no value came from "
                        "both solvers: nothing compared")]
    return [expect(name, _SECTION, not off,
                   f"{len(twice)} of {len(rows)} points missed the Fokker-Planck tolerance and were tried with "
                   f"Monte Carlo ({kept_mc} kept Monte Carlo's numbers); {compared} values given by both solvers "
                   f"compared within {FALLBACK_SIGMAS:g} combined error bars; outside: {'; '.join(off[:3]) or 'none'}")]


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
