"""Work-precision diagrams: each solver's actual error on eta against its wall time.

The field's convention (SciMLBenchmarks, DifferentialEquations.jl): every method on the same
axes, over a range of tolerances down to the smallest each reaches within a budget, the error
measured against a reference that does not share its errors. Monte Carlo starts at 5e-2 with
2 paths per replica and at least 8 replicas (:data:`MC_OPTIONS`), so that its loosest points
are not all at the first batch the solver's defaults run (1e-3 to 5e-3 at any tolerance from
1e-2 up), and its curves cover more of the error range; Fokker--Planck starts at 1e-1, the
loosest tolerance it accepts (its error is far below a loose tolerance: at the kink a = 1 it
is 1.4e-3 at 1e-1 and 1e-4 at 1e-2, so a curve that started at 1e-2 would cover only 1.3
decades above its reference's own error).

* **harmonic ring** (a = 0.5, k = -0.2): the exact solver's wall time against the ring size N
  up to 1e6, beside scipy's dense 4N x 4N Lyapunov solve (what a user would otherwise call) for
  small N, each with its error against the closed form in 60-digit arithmetic;
* **smooth unit** (n = 3, a = 0.5), **the kink** (n = 1, a = 0.5 and a = 1) and **the n = 3
  ring** (N = 3, a = 0.5, k = -0.5): Fokker--Planck (single units), Monte Carlo, and the two
  baselines a user would otherwise write: plain Monte Carlo (``control=False,
  martingale=False``: no control variates) and a numpy Euler--Maruyama script vectorised over
  paths (:func:`montecarlo.simulate_naive` at the usual dt = 0.01, its run length chosen from
  a pilot run to meet each tolerance). A Monte Carlo point is the rms actual error over
  several seeds at one tolerance, beside the mean error the runs reported. Each solver's first run
  of a case, at its loosest tolerance, is not timed (numba compiling or loading kernels).

References (:func:`reference`): for Monte Carlo, the reference table's Fokker--Planck entry
(units) or its independent long Monte Carlo run (the ring); for Fokker--Planck, its entry at a
tolerance ten times tighter than the curve's tightest point (:func:`fpe_tols`), which at the
kink agrees with the independent long Monte Carlo runs (:func:`kink_agreement`). An error below the
reference's own is not resolved: the figure shows that floor, and the table's span in decades
(:func:`span`) counts only the errors above it.

``python -m validation.studies.work_precision [--quick] [--out DIR]`` writes
``work_precision.json`` and ``work_precision.png`` (full: 39 min on a quiet 2-core machine, the
recorded run; quick: about 30 s).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fpe_harvester import Harvester, solve
from validation.studies.cli import DATA, bench_main, save_benchmark

__all__ = ["STEM", "RECORDED", "COMMAND", "CAPTION", "CASES", "METHODS", "SOLVERS", "DECADES", "MC_OPTIONS",
           "reference", "fpe_tols", "kink_agreement", "harmonic", "ladder", "run", "draw", "plot", "span",
           "resolved", "summary_rows"]

#: Name of the written ``.json`` and ``.png``.
STEM = "work_precision"
#: The recorded full run that the report and the docs site draw.
RECORDED = DATA / f"{STEM}.json"
#: The command that writes :data:`RECORDED` again.
COMMAND = "python -m validation.studies.work_precision --out validation/data"
#: What the figure shows.
CAPTION = ("Work-precision diagrams. Left: the harmonic ring's exact solver against scipy's dense Lyapunov solve, "
           "wall time against ring size. Other panels: actual relative error of eta against wall time, one curve "
           "per solver over tolerances from 5e-2 (Monte Carlo) or 1e-1 (Fokker-Planck) down (Monte Carlo: rms "
           "over seeds; small dots: the mean error the runs reported), plain Monte Carlo and a numpy "
           "Euler-Maruyama script as the baselines; dotted grey: the reference's own error, below which an error "
           "is not resolved; each panel names its references.")

#: The nonlinear cases: key -> (title, Harvester.build arguments).
CASES: dict[str, tuple[str, dict[str, Any]]] = {
    "unit_n3": ("smooth unit n = 3, a = 0.5", {"n": 3.0, "a": 0.5}),
    "kink_a0.5": ("kink n = 1, a = 0.5", {"n": 1.0, "a": 0.5}),
    "kink_a1": ("kink n = 1, a = 1", {"n": 1.0, "a": 1.0}),
    "ring_n3": ("ring N = 3, n = 3, a = 0.5, k = -0.5", {"n": 3.0, "a": 0.5, "N": 3, "k": -0.5}),
}
#: Solvers and baselines, in drawing order.
METHODS = ("fpe", "mc", "mc plain", "euler-maruyama")
#: The library's solvers among :data:`METHODS` (the others are the baselines a user would write).
SOLVERS = ("fpe", "mc")
#: Decades of resolved error each solver's curve covers in the recorded full run (the report checks it).
DECADES = 2.0
#: Options of every Monte Carlo run (with and without control variates): 2 paths per replica and
#: at least 8 replicas, instead of the solver's 16-64 and 32. At its defaults the solver's first
#: batch already gives an error of 1e-3 to 5e-3 at any tolerance from 1e-2 up, so a curve could
#: not start above it (with 8 replicas of 2 paths: 1.7e-2 to 3.9e-2); and at equal path time, more
#: replicas let the regression use the richest control set (ring n = 3, N = 3, a = 0.5, k = -0.5,
#: t_run = 400: at 32 replicas of 19 paths only the twin, variance reduction 2.5-2.8; at 64 of 4
#: the martingale and twin sets, 3-6). Not fewer than 8: with 2, a run stops on a standard error
#: that 2 replicas happened to make small (full run, tol 1e-2: one seed in four stopped at 2
#: replicas, and the rms actual error of the four was 3e-2, against 4e-3 with 8).
MC_OPTIONS: dict[str, Any] = {"paths": 2, "min_replicas": 8}
#: Euler--Maruyama baseline: time step [s], paths per replica, burn-in and pilot window [s].
EM_DT, EM_PATHS, EM_BURN, EM_PILOT = 0.01, 256, 20.0, 50.0


def _settings(quick: bool) -> dict[str, Any]:
    """Tolerances, seeds and budgets [s] (per run, and per solver and case in total). Monte Carlo
    with its control variates (the solver a user calls) gets a larger budget than the baselines:
    its error falls like one over the square root of the cost, so two decades of error from its
    loosest point (2e-2 to 4e-2, the first batch) cost 1e4 times that point's time, about 300 s
    per seed at its tightest tolerance. Fokker--Planck too: at the kink (a = 1) its tolerance
    1e-4 takes about 170 s, and its loosest point is already at about 1e-3."""
    if quick:
        return {"tols": (5e-2, 1e-2), "fpe_tols": (1e-2, 1e-3), "seeds": 2, "run_s": 8.0, "budget_s": 5.0,
                "mc_run_s": 8.0, "mc_budget_s": 5.0, "fpe_run_s": 8.0, "fpe_budget_s": 5.0,
                "ring_N": (3, 100, 10_000, 1_000_000), "dense_N": (3, 10, 30), "mp_N_max": 100}
    return {"tols": (5e-2, 2e-2, 1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4),
            "fpe_tols": (1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7), "seeds": 4, "run_s": 60.0, "budget_s": 130.0,
            "mc_run_s": 400.0, "mc_budget_s": 900.0, "fpe_run_s": 300.0, "fpe_budget_s": 600.0,
            "ring_N": (3, 10, 100, 1000, 10_000, 100_000, 1_000_000), "dense_N": (3, 10, 30, 100, 200),
            "mp_N_max": 1000}


def reference(key: str) -> dict[str, Any]:
    """The reference of case ``key`` for every solver's errors: ``{"eta", "rel_err", "source",
    "short", "tol"}`` (``tol`` the reference's own tolerance, 0 for a Monte Carlo run).

    Never a solver's own result at a similar setting: Monte Carlo is measured against
    Fokker--Planck (units) or an independent long run (the ring); Fokker--Planck against its
    table entry at a tolerance ten times tighter than its tightest point (:func:`fpe_tols`:
    n = 3 at 1e-8, the kink at 1e-6 and 1e-5), cross-checked by the kink's independent long
    Monte Carlo runs (:func:`kink_agreement`).
    """
    from validation.references.reftable import load

    _, system = CASES[key]
    h = Harvester.build(**system)
    label = (f"mc n = {h.n:g}, N = {h.N}, a = {h.a:g}, k = {h.k:g}" if h.N > 1
             else f"fpe n = {h.n:g}, a = {h.a:g}")
    e = load()[label]
    short = "Monte Carlo" if e["method"] == "mc" else "Fokker-Planck"
    return {"eta": e["eta"], "rel_err": e["eta_err"] / e["eta"], "short": f"{short} table entry",
            "tol": float(e["options"]["tol"]) if e["method"] == "fpe" else 0.0,
            "source": f"reference table '{label}' ({e['method']}, tol {e['options']['tol']:g}, commit {e['commit']})"}


def fpe_tols(tols: tuple[float, ...], ref: dict[str, Any]) -> tuple[float, ...]:
    """The Fokker--Planck tolerances measured against ``ref``: those at least ten times looser
    than the reference's own, so that no point repeats the reference's computation."""
    return tuple(t for t in tols if t >= 10.0 * ref["tol"])


def kink_agreement(a: float) -> dict[str, float]:
    """The kink's Fokker--Planck reference (n = 1, ``a``) against its independent long Monte
    Carlo run: ``{"diff", "sigma"}``, the relative difference and the same in combined
    standard errors."""
    from validation.references.reftable import load, recorded_kink

    ref = load()[f"fpe n = 1, a = {a:g}"]
    mc = recorded_kink(a)
    diff = mc["eta"] / ref["eta"] - 1.0
    return {"diff": diff, "sigma": abs(mc["eta"] - ref["eta"]) / math.hypot(mc["eta_err"], ref["eta_err"])}


def _timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def harmonic(quick: bool) -> dict[str, Any]:
    """The harmonic ring: exact and dense-Lyapunov wall times against N, errors vs 60 digits."""
    from fpe_harvester.exact import dense_covariance
    from validation.references.analytic import mp_closed_form

    cfg = _settings(quick)
    rows = []
    for method, sizes in (("exact", cfg["ring_N"]), ("scipy dense Lyapunov", cfg["dense_N"])):
        for N in sizes:
            h = Harvester.build(a=0.5, N=N, k=-0.2)
            if method == "exact":
                wall = min(_timed(lambda: solve(h))[0] for _ in range(3))
                eta = solve(h).eta
            else:
                wall, C = min((_timed(lambda: dense_covariance(h)) for _ in range(2)), key=lambda tc: tc[0])
                eta = float(np.diag(C)[2::4].mean()) / (float(np.diag(C, 2)[1::4].mean()) * h.params.sigma)
            ref = float(mp_closed_form(h)["eta"]) if N <= cfg["mp_N_max"] else None
            rows.append({"method": method, "N": N, "seconds": wall, "eta": eta,
                         "error": None if ref is None else abs(eta / ref - 1)})
    return {"title": "harmonic ring a = 0.5, k = -0.2", "reference": "closed form in 60-digit arithmetic",
            "rows": rows}


def _em_run(h: Harvester, tol: float, seed: int, pilot: dict[str, float],
            run_s: float) -> tuple[float, float | None, float | None, str]:
    """The Euler--Maruyama baseline at ``tol``: replicas so that the standard error meets it,
    scaled from the pilot (standard error ~ 1/sqrt(replicas)). Returns (wall, eta, err, status);
    a run predicted to take longer than ``run_s`` [s] is not started (no numbers)."""
    from montecarlo import estimate, simulate_naive

    replicas = max(2, math.ceil(pilot["replicas"] * (pilot["rel_se"] / tol) ** 2))
    if pilot["seconds"] * replicas / pilot["replicas"] > run_s:
        return 0.0, None, None, "over budget"
    wall, ens = _timed(lambda: simulate_naive(h, dt=EM_DT, paths=EM_PATHS, replicas=replicas, t_burn=EM_BURN,
                                              t_run=EM_PILOT, seed=seed))
    est = estimate(ens, h, control=False)
    return wall, est.mean["eta"], est.se["eta"], "stable"


def _em_pilot(h: Harvester, seed: int) -> dict[str, float]:
    from montecarlo import estimate, simulate_naive

    wall, ens = _timed(lambda: simulate_naive(h, dt=EM_DT, paths=EM_PATHS, replicas=4, t_burn=EM_BURN,
                                              t_run=EM_PILOT, seed=seed))
    est = estimate(ens, h, control=False)
    return {"replicas": 4, "rel_se": est.se["eta"] / abs(est.mean["eta"]), "seconds": wall}


#: What a point records of each Monte Carlo run's ``info`` (how the time was spent).
_RUN_INFO = ("control_set", "variance_reduction", "replicas", "paths", "t_run", "dt")


def _runner(method: str, h: Harvester, cfg: dict[str, Any]) -> Callable[[float, int], tuple[Any, ...]]:
    """``run(tol, seed) -> (wall [s], eta, reported error, status[, info])`` of one solver; the
    Monte Carlo runs add the entries :data:`_RUN_INFO` of their ``info``."""
    if method == "euler-maruyama":
        pilot = _em_pilot(h, seed=99)
        return lambda tol, seed: _em_run(h, tol, seed, pilot, cfg["run_s"])
    options: dict[str, Any] = {"max_seconds": cfg["fpe_run_s"]} if method == "fpe" else {
        "max_time": cfg["mc_run_s" if method == "mc" else "run_s"], "progress": False, **MC_OPTIONS,
        **({"control": False, "martingale": False} if method == "mc plain" else {})}

    def one(tol: float, seed: int) -> tuple[Any, ...]:
        wall, r = _timed(lambda: solve(h, method.split()[0], tol=tol, **options,
                                       **({} if method == "fpe" else {"seed": seed})))
        info = () if method == "fpe" else ({k: r.info.get(k) for k in _RUN_INFO},)
        return (wall, r.eta, r.eta_err, r.status.value, *info)

    return one


def ladder(run_one: Callable[[float, int], tuple[Any, ...]], tols: tuple[float, ...],
           seeds: int, ref_eta: float, budget_s: float, order: float = 0.0) -> list[dict[str, Any]]:
    """One point per tolerance, tightest last: the rms actual relative error over ``seeds``
    runs and the mean reported relative error, the mean wall time [s], each run's eta (so that
    the errors can be measured again against another reference without running again), and
    each run's info when ``run_one`` returns one (a fifth item).

    Stops after a tolerance at which a run did not converge, and before one whose predicted
    cost would take the total past ``budget_s``: the last point's time times
    ``(reported / tol) ** order`` per seed (``order`` 2 for Monte Carlo, whose standard error
    falls like one over the square root of the cost; 0, the last point's time, for
    Fokker--Planck, whose cost does not follow its error so simply).
    """
    points: list[dict[str, Any]] = []
    spent = 0.0
    for tol in tols:
        if points:
            last = points[-1]
            scale = max(1.0, last["reported"] / tol) ** order if math.isfinite(last["reported"]) else 1.0
            if spent + seeds * last["seconds"] * scale > budget_s:
                break
        runs = [run_one(tol, 1000 + s) for s in range(seeds)]
        spent += sum(r[0] for r in runs)
        done = [r for r in runs if r[1] is not None]
        if not done:
            break
        actual = [(r[1] / ref_eta - 1.0) ** 2 for r in done]
        points.append({"tol": tol, "seconds": float(np.mean([r[0] for r in runs])),
                       "error": math.sqrt(float(np.mean(actual))),
                       "reported": float(np.mean([(r[2] or math.nan) / abs(r[1]) for r in done])),
                       "runs": len(done), "statuses": sorted({r[3] for r in runs}), "etas": [r[1] for r in done],
                       **({"info": [r[4] for r in runs]} if all(len(r) > 4 for r in runs) else {})})
        if any(r[3] != "stable" for r in runs):
            break
    return points


def _case(key: str, quick: bool) -> dict[str, Any]:
    cfg = _settings(quick)
    title, system = CASES[key]
    h = Harvester.build(**system)
    curves = []
    ref = reference(key)
    for method in METHODS:
        if method == "fpe" and h.N > 1:
            continue
        fpe = method == "fpe"
        run_one = _runner(method, h, cfg)
        tols = fpe_tols(cfg["fpe_tols"], ref) if fpe else cfg["tols"]
        if not quick:
            # one untimed run first: numba compiling or loading the kernels is not the solver's cost
            # (measured cold: the n = 3 unit's first Monte Carlo point took 4.8 s, the next 0.1 s)
            run_one(tols[0], 999)
        points = ladder(run_one, tols, 1 if fpe else cfg["seeds"],
                        ref["eta"], cfg[{"mc": "mc_budget_s", "fpe": "fpe_budget_s"}.get(method, "budget_s")],
                        order=0.0 if fpe else 2.0)
        curves.append({"method": method, "reference": ref, "points": points})
    return {"title": title, "system": system, "curves": curves}


def run(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """Run the study; returns (and writes into ``out``, when given) the measurements."""
    t0 = time.perf_counter()
    res: dict[str, Any] = {"quick": quick, "settings": {k: list(v) if isinstance(v, tuple) else v
                                                        for k, v in _settings(quick).items()},
                           "harmonic": harmonic(quick), "cases": {key: _case(key, quick) for key in CASES}}
    res["wall_s"] = time.perf_counter() - t0
    save_benchmark(res, out, STEM, plot)
    return res


_STYLE = {"fpe": ("o-", "C0"), "mc": ("s-", "C1"), "mc plain": ("^--", "C2"), "euler-maruyama": ("v:", "C3"),
          "exact": ("o-", "C0"), "scipy dense Lyapunov": ("s--", "C3")}

#: Method names in the panels' reference notes.
_SHORT = {"euler-maruyama": "EM"}


def draw(res: dict[str, Any], axes: Any) -> None:
    """Draw the diagrams on ``axes`` (at least 1 + len(CASES) matplotlib axes, flat); each panel
    names the reference of each of its curves."""
    from matplotlib.ticker import NullFormatter

    ax = axes[0]
    rows = res["harmonic"]["rows"]
    for method in ("exact", "scipy dense Lyapunov"):
        mine = [r for r in rows if r["method"] == method]
        style, color = _STYLE[method]
        ax.loglog([r["N"] for r in mine], [r["seconds"] for r in mine], style, color=color, label=method)
    ax.set(xlabel="ring size N", ylabel="wall time [s]", title=res["harmonic"]["title"])
    ax.legend(fontsize=7)
    for ax, case in zip(axes[1:], res["cases"].values()):
        floors = {}
        for curve in case["curves"]:
            pts = curve["points"]
            style, color = _STYLE[curve["method"]]
            ax.loglog([p["seconds"] for p in pts], [max(p["error"], 1e-12) for p in pts], style, color=color,
                      label=curve["method"])
            if curve["method"] in ("mc", "mc plain"):
                ax.loglog([p["seconds"] for p in pts], [p["reported"] for p in pts], ".", color=color, alpha=0.5)
            ref = curve["reference"]
            floors.setdefault((ref.get("short", ref["source"]), ref["rel_err"]), []).append(curve["method"])
        for _, rel in floors:
            ax.axhline(rel, color="grey", lw=0.8, ls=":")
        ax.text(0.02, 0.02, "\n".join(f"reference of {'/'.join(_SHORT.get(x, x) for x in m)}:\n  {name} "
                                       f"(rel. error {rel:.1g})" for (name, rel), m in floors.items()),
                transform=ax.transAxes, fontsize=6, va="bottom")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set(xlabel="wall time [s]", ylabel="actual relative error of eta", title=case["title"])
        ax.title.set_fontsize(9)
        ax.legend(fontsize=7)


def span(points: list[dict[str, Any]], floor: float) -> float:
    """Decades of actual error a curve covers, counting only errors above the reference's own
    relative error ``floor`` (smaller ones are not resolved): log10(largest / smallest)."""
    errs = [max(p["error"], floor) for p in points if p["error"] > 0 or floor > 0]
    return math.log10(max(errs) / min(errs)) if errs and min(errs) > 0 else 0.0


def resolved(curve: dict[str, Any]) -> tuple[float, bool]:
    """A curve's :func:`span` above its reference's own error, and whether its smallest error
    reaches that error (then it shows all the reference can resolve, whatever its span)."""
    floor = curve["reference"]["rel_err"]
    return span(curve["points"], floor), min(p["error"] for p in curve["points"]) <= floor


def summary_rows(res: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the table beside the figure: per case and solver, the tolerances
    run, the smallest actual error reached and its wall time, the reported over the actual
    error at that point, and the reference."""
    head = ["case", "solver", "tolerances", "smallest actual error", "wall time there [s]",
            "reported / actual there", "span [decades]", "reference"]
    rows = []
    for case in res["cases"].values():
        for c in case["curves"]:
            pts = c["points"]
            if not pts:
                rows.append([case["title"], c["method"], "-", "no result within the budget", "-", "-", "-",
                             c["reference"]["source"]])
                continue
            best = min(pts, key=lambda p: p["error"])
            ratio = best["reported"] / best["error"] if best["error"] > 0 else math.inf
            rows.append([case["title"], c["method"], f"{pts[0]['tol']:g} ... {pts[-1]['tol']:g}",
                         f"{best['error']:.2g}", f"{best['seconds']:.3g}", f"{ratio:.2g}",
                         f"{span(pts, c['reference']['rel_err']):.2g}", c["reference"]["source"]])
    for method in ("exact", "scipy dense Lyapunov"):
        mine = [r for r in res["harmonic"]["rows"] if r["method"] == method]
        errs = [r["error"] for r in mine if r["error"] is not None]
        rows.append([res["harmonic"]["title"], method, f"N = {mine[0]['N']} ... {mine[-1]['N']}",
                     f"{max(errs):.2g} (largest)" if errs else "-",
                     f"{mine[-1]['seconds']:.3g} (N = {mine[-1]['N']})", "-", "-",
                     res["harmonic"]["reference"]])
    return head, rows


def plot(res: dict[str, Any], path: Path) -> None:
    """Write the figure: one panel per case (harmonic first), log-log."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = 1 + len(res["cases"])
    fig, axes = plt.subplots(2, (panels + 1) // 2, figsize=(4.2 * ((panels + 1) // 2), 7.6))
    flat = list(np.ravel(axes))
    draw(res, flat)
    for ax in flat[panels:]:
        ax.set_visible(False)
    fig.suptitle("work-precision: solid/dashed lines rms actual error over seeds, dots the reported error, "
                 "dotted grey the reference's own error", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__, drop=("harmonic", "cases"))
