"""Benchmark of the Fokker--Planck solver: error versus wall time, time to a tolerance.

For the single oscillator with a = 0.5 and n = 2, 3, 4, 8 (smooth) and n = 1 (kink):

* an error-versus-time curve over fixed discretization levels (Hermite degree M at a
  fixed mesh), errors against the exact value (n = 2) or against the most accurate
  tolerance-driven run (other n; its own estimated error is recorded with it);
* the wall time of tolerance-driven solves (``tol = 1e-4, 1e-6`` smooth, ``1e-3`` kink),
  the error they report and the error they actually have;
* when the Monte Carlo package is importable, the cost of one Monte Carlo estimate of
  eta for n = 3, extrapolated to 1e-4 relative (time ~ 1/error^2), for the ratio.

``python -m validation.bench.fpe [--quick] [--out DIR]`` runs the benchmark (the full one
takes about 6 minutes) and writes ``bench_fpe.json`` and ``bench_fpe.png`` into DIR
(default ``./validation_report``).
"""

from __future__ import annotations

import pathlib
import time
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from fpe_harvester.exact import mode_moments
from fpe_harvester.fpe import discretize, stationary
from fpe_harvester.fpe.discretize import Whitening, solve_level
from fpe_harvester.fpe.stationary import default_plan as stationary_plan
from validation.bench.cli import bench_main, save_benchmark

__all__ = ["STEM", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_fpe"

TARGETS = {"smooth_1e-4_s": 0.5, "smooth_1e-6_s": 5.0, "kink_1e-3_s": 10.0}


def _curve(h: Harvester, degrees: list[int], half: int) -> list[dict[str, float]]:
    w = Whitening.of(h)
    mesh = stationary_plan(h).mesh(h, w, half)
    out = []
    for M in degrees:
        t0 = time.perf_counter()
        lv = solve_level(h, M, mesh, 3, w)
        out.append({"M": M, "elements": 2 * half, "dofs": lv.dofs, "seconds": time.perf_counter() - t0,
                    "eta": lv.moments["eta"]})
    return out


def _tol_run(h: Harvester, tol: float, max_seconds: float) -> dict[str, Any]:
    """One tolerance-driven solve; runs under 2 s are repeated (3 in all, the scalar DG
    matrices' cache emptied each time: every run starts cold) and ``seconds`` is the median,
    ``seconds_all`` the single times (a virtual machine's timings scatter by ~20 %)."""
    times = []
    while True:
        discretize._X_CACHE.clear()
        t0 = time.perf_counter()
        sol = stationary(h, tol=tol, max_seconds=max_seconds, grid=3)
        times.append(time.perf_counter() - t0)
        if times[0] >= 2.0 or len(times) == 3:
            break
    s = sol.stats
    return {"tol": tol, "seconds": float(np.median(times)), "seconds_all": times, "eta": s.eta,
            "eta_err": s.eta_err, "status": s.status.value, "M": s.info["M"],
            "elements": s.info["elements"], "dofs": s.info["dofs"]}


def _monte_carlo(h: Harvester, quick: bool) -> dict[str, Any] | None:
    try:
        from montecarlo import MonteCarlo
    except ImportError:
        return None
    t0 = time.perf_counter()
    r = MonteCarlo(seed=1, tol=0.05 if quick else 0.01, max_time=60.0 if quick else 300.0).solve(h)
    sec = time.perf_counter() - t0
    if r.eta is None or not r.eta_err:
        return {"seconds": sec, "status": r.status.value}
    rel = r.eta_err / r.eta
    return {"seconds": sec, "eta": r.eta, "eta_err": r.eta_err, "rel_err": rel,
            "seconds_for_1e-4_extrapolated": sec * (rel / 1e-4) ** 2}


def run(quick: bool = False, out: pathlib.Path | None = None) -> dict:
    """Measure accuracy versus wall time of the Fokker--Planck solver.

    Parameters
    ----------
    quick : bool
        n = 2, 3 and 1 only, degrees up to 6, tol = 1e-3 (smooth) and 1e-2 (kink), no
        Monte Carlo (well under a minute on an idle 2-core machine).
    out : pathlib.Path, optional
        Directory for ``bench_fpe.json`` and ``bench_fpe.png``.

    Returns
    -------
    dict
        ``cases`` (per n: curve, tolerance runs, reference), ``targets`` and ``monte_carlo``.
    """
    cases: dict[str, Any] = {}
    smooth = [2.0, 3.0] if quick else [2.0, 3.0, 4.0, 8.0]
    for n in [*smooth, 1.0]:
        h = Harvester.build(a=0.5, n=n)
        kink = n < 2.0
        if quick:
            tols = [1e-2] if kink else [1e-3]
        else:
            tols = [1e-3] if kink else [1e-4, 1e-6]
        runs = [_tol_run(h, tol, 60.0 if quick else 240.0) for tol in tols]
        if n == 2.0:
            mo = mode_moments(1.0, h.params)
            ref, ref_err, ref_src = float(mo["V2"] / mo["Pin"]), 0.0, "exact"
        else:
            best = min(runs, key=lambda r: r["eta_err"])
            ref, ref_err, ref_src = best["eta"], best["eta_err"], f"fpe tol={best['tol']:g}"
        degrees = [2, 4, 6] if quick else ([2, 4, 6, 8, 10, 12] if kink else [2, 4, 6, 8, 10])
        curve = _curve(h, degrees, 8)
        for pt in [*curve, *runs]:
            pt["rel_error"] = abs(pt["eta"] - ref) / abs(ref)
            pt["resolved"] = pt["rel_error"] > ref_err / abs(ref)
        cases[f"n={n:g}"] = {"n": n, "a": 0.5, "reference": ref, "reference_err": ref_err,
                             "reference_source": ref_src, "curve": curve, "tol_runs": runs}
    mc = None if quick else _monte_carlo(Harvester.build(a=0.5, n=3.0), quick)
    result = {"quick": quick, "cases": cases, "targets": TARGETS, "monte_carlo_n3": mc}
    save_benchmark(result, out, STEM, _plot)
    return result


def _plot(result: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for name, case in result["cases"].items():
        pts = [p for p in case["curve"] if p["rel_error"] > 0]
        line, = ax.loglog([p["seconds"] for p in pts], [p["rel_error"] for p in pts], "o-", label=name)
        runs = case["tol_runs"]
        ax.loglog([r["seconds"] for r in runs], [max(r["eta_err"] / r["eta"], 1e-16) for r in runs], "s",
                  mfc="none", color=line.get_color())
    ax.axhline(1e-4, color="0.7", lw=0.8)
    ax.axhline(1e-6, color="0.7", lw=0.8)
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("relative error of eta")
    ax.set_title("FPE, a = 0.5: o fixed levels M = 2, 4, ...; □ tol runs (reported error)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    bench_main(run, __doc__)
