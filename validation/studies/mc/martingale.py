"""Monte Carlo design study: the martingale control variates.

The variance-reduction factor of eta and the time to 1e-4 with the new controls, the twin
alone and plain, for n in 1, 1.5, 3, 4, 8, N = 1 and N = 3 at k = -0.01, -0.2, -0.5, from one
ensemble pair per row (:func:`martingale_rows`); and the coverage of their error bars over seeds
against the exact solution (harmonic pair) and the Fokker--Planck solver (single n = 3 unit)
(:func:`martingale_coverage`; the recorded full run is in
``validation/data/bench_montecarlo_martingale_rows.json`` and ``..._coverage.json``).

Both ensembles of a row run the harmonic twin, so the variance-reduction factors compare
variances on ensembles of equal cost, and the plain row's time carries the twin's cost: they are
not speed-ups over a plain run (no twin, no sums), whose steps are cheaper. Measured on the ring
n = 3, N = 3, a = 0.5, k = -0.5 (64 replicas of 4 paths, t_run = 400, one thread, CPU time,
median of 5 interleaved repeats): a step costs 1.21x a plain one with the sums alone, 1.73x with
the twin and the sums; the variance reduction of eta is 5.3 with the sums alone and 4.6 with the
automatic choice (twin and sums), so equal error costs 4.4x and 2.7x less than plain; the
solver's end-to-end curves are in :mod:`validation.studies.work_precision`.

``python -m validation.studies.mc.martingale [--quick] [--out DIR]`` writes ``bench_montecarlo_martingale.json`` and
``bench_montecarlo_martingale.png``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from fpe_harvester import Harvester, solve
from fpe_harvester.errors import ParameterError
from montecarlo import MonteCarlo, estimate, simulate
from fpe_harvester.parallel import default_threads
from validation.studies.cli import axes_plot, bench_main, save_benchmark
from validation.studies.mc.controls import CV_TARGET

__all__ = ["STEM", "MARTINGALE_N", "MARTINGALE_K", "martingale_rows", "martingale_coverage", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_martingale"

#: Rows of the martingale benchmark: n x (single unit, or N = 3 at k), a = 0.5.
MARTINGALE_N = (1.0, 1.5, 3.0, 4.0, 8.0)
MARTINGALE_K = (-0.01, -0.2, -0.5)


def _eta_rel_se(est: Any) -> float:
    return est.se["eta"] / abs(est.mean["eta"]) if est.mean["eta"] else math.inf


def _martingale_row(h: Harvester, seed: int, quick: bool) -> dict[str, Any]:
    """One row: one ensemble with the martingale sums and one without (same seed, the same paths),
    the variance reduction of eta with each control set and the wall time to CV_TARGET
    extrapolated from each, wall * (relative se / target)^2 (the Richardson bias is reported, not
    added)."""
    plan = MonteCarlo(seed=seed, tol=CV_TARGET, extrapolate=False).plan(h)
    reps, paths = (48, 2) if quick else (64, 2)
    t_run = 200.0 if quick else 400.0
    kw = dict(dt=plan.dt, paths=paths, replicas=reps, t_burn=plan.t_burn, t_run=t_run, richardson=True,
              seed=seed, twin=plan.twin, start=plan.start)
    row: dict[str, Any] = {"twin_kappa": plan.twin, "dt": plan.dt, "t_burn": plan.t_burn, "t_run": t_run,
                           "replicas": reps, "paths": paths}
    with_mg = simulate(h, controls=("martingale", "boundary"), **kw)
    without = simulate(h, **kw)
    row.update(wall_martingale_s=with_mg.wall_time, wall_plain_s=without.wall_time,
               escape_fraction=with_mg.escaped_fraction())
    if with_mg.escaped_fraction() > 0.0:
        row["note"] = (f"{with_mg.escaped_fraction():.1%} of paths escaped within t_burn + t_run: no "
                       "stationary statistics, no control variates, no time to target")
        return row
    plain = estimate(with_mg, h, control=False)
    row.update(eta=plain.mean["eta"], rel_bias=abs(plain.bias["eta"] / plain.mean["eta"]))
    for label, ens, controls in (("plain", without, False), ("twin", without, "twin"),
                                 ("martingale", with_mg, "martingale"), ("both", with_mg, "martingale+twin"),
                                 ("auto", with_mg, None)):
        try:
            est = estimate(ens, h, control=False if controls is False else None,
                           controls=controls if isinstance(controls, str) else None)
        except ParameterError as exc:
            row[label] = {"note": str(exc).split(";")[0]}
            continue
        rel = _eta_rel_se(est)
        vrf = (_eta_rel_se(plain) / rel) ** 2 if rel > 0 else None
        row[label] = {"controls": est.controls, "vrf_eta": vrf, "rel_se": rel, "eta": est.mean["eta"],
                      "time_to_1e-4_s": ens.wall_time * (rel / CV_TARGET) ** 2}
    return row


def martingale_rows(quick: bool) -> dict[str, Any]:
    """Variance-reduction factor of eta and time to 1e-4 (relative standard error) with the new
    controls (the estimator's automatic choice among twin, martingale sums, both), the twin alone
    and plain, for n in MARTINGALE_N, N = 1 and N = 3 at each k in MARTINGALE_K, a = 0.5; all
    three from one ensemble pair per row (with and without the martingale sums, same paths).
    Budget per row: 64 replicas of 2 paths, t_run = 400 (quick: 48 of 2, t_run = 200), the
    solver's plan for tol = 1e-4 otherwise (dt, burn-in, twin); the times are extrapolated from
    that run, not measured to the target."""
    out: dict[str, Any] = {}
    cases = [(n, 1, 0.0) for n in MARTINGALE_N] + [(n, 3, k) for n in MARTINGALE_N for k in MARTINGALE_K]
    if quick:
        cases = [(3.0, 1, 0.0), (3.0, 3, -0.5)]
    for i, (n, N, k) in enumerate(cases):
        h = Harvester.build(a=0.5, n=n, N=N, k=k)
        name = f"n{n:g}_N{N}" + (f"_k{k:g}" if N > 1 else "")
        t0 = time.perf_counter()
        out[name] = {"n": n, "N": N, "k": k, "confinement": h.confinement,
                     **_martingale_row(h, 4100 + i, quick), "bench_wall_s": time.perf_counter() - t0}
    return out


def martingale_coverage(quick: bool) -> dict[str, Any]:
    """Coverage of the martingale error bars against independent references over seeds: the
    harmonic pair (N = 2, k = -0.2, a = 0.5) against its exact discrete value (twin_expectations,
    frozen step dt = 0.1), and the single n = 3 unit (a = 0.5) against the Fokker--Planck solver
    (extrapolated value mean - bias against hypot(se, bias_se), and the solver's own error
    hypot(se, bias) around the fine level)."""
    from montecarlo import twin_expectations

    seeds = 24 if quick else 100
    h2 = Harvester.build(a=0.5, N=2, k=-0.2)
    ex = twin_expectations(h2, 0.1)
    eta2 = ex["V2"] / ex["vxi"]
    z2 = []
    for s in range(seeds):
        e = simulate(h2, dt=0.1, paths=2, replicas=48, t_burn=20.0, t_run=100.0, seed=5000 + s, start="twin",
                     controls=("martingale", "boundary"))
        est = estimate(e, h2, controls="martingale")
        z2.append((est.mean["eta"] - eta2) / est.se["eta"])
    h3 = Harvester.build(a=0.5, n=3)
    ref = solve(h3, "fpe", tol=1e-6)
    plan = MonteCarlo(seed=1, tol=1e-3, extrapolate=False).plan(h3)
    z3, z3_solver, vrf = [], [], []
    for s in range(seeds):
        e = simulate(h3, dt=plan.dt, paths=4, replicas=64, t_burn=plan.t_burn, t_run=200.0, seed=6000 + s,
                     twin=plan.twin, start="twin", richardson=True,
                     controls=("martingale", "boundary"))
        est = estimate(e, h3)
        vrf.append(est.reduction.get("eta"))
        z3.append((est.mean["eta"] - est.bias["eta"] - ref.eta)
                  / math.hypot(est.se["eta"], est.bias_se["eta"], ref.eta_err))
        z3_solver.append((est.mean["eta"] - ref.eta) / math.hypot(est.total_error("eta"), ref.eta_err))

    def summary(z: list[float]) -> dict[str, Any]:
        a = np.abs(np.array(z))
        return {"seeds": len(z), "within_1": float((a < 1).mean()), "within_2": float((a < 2).mean()),
                "max_abs_z": float(a.max()), "z": [round(float(v), 3) for v in z]}

    return {"harmonic_N2_vs_exact": summary(z2),
            "n3_N1_vs_fpe_extrapolated": {**summary(z3), "fpe_eta": ref.eta, "fpe_err": ref.eta_err,
                                          "median_vrf_eta": float(np.median([v for v in vrf if v]))},
            "n3_N1_vs_fpe_solver_error": summary(z3_solver),
            "nominal": {"within_1": 0.683, "within_2": 0.954}}


def draw(res: dict[str, Any], ax: Any) -> None:
    """Variance reduction of eta per row with the twin, the martingale sums and the automatic choice."""
    rows = {k: v for k, v in res.get("rows", {}).items() if isinstance(v, dict) and "plain" in v}
    y = np.arange(len(rows))
    for j, label in enumerate(("twin", "martingale", "auto")):
        ax.barh(y + 0.25 * (j - 1), [(r[label].get("vrf_eta") or 0.0) for r in rows.values()], 0.25, label=label)
    ax.set_yticks(y, list(rows), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("variance reduction of eta")
    ax.legend(fontsize=7)


def run(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """:func:`martingale_rows` and :func:`martingale_coverage`; writes ``{STEM}.json`` and
    ``.png`` into ``out`` when given."""
    t0 = time.perf_counter()
    res = {"quick": quick, "threads": default_threads(), "rows": martingale_rows(quick),
           "coverage": martingale_coverage(quick)}
    res["wall_s"] = time.perf_counter() - t0
    save_benchmark(res, out, STEM, axes_plot(draw))
    return res


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
