"""Monte Carlo design study: the generator control variates (:mod:`montecarlo.controls.generator`).

Three parts:

* :func:`generator_rows` -- for the single units n = 1, 1.25, 1.5, 3 at a = 0.5, 1, 2 and the ring
  n = 3, N = 3, k = -0.5: one ensemble per case with every control accumulated (the solver's plan
  for tol = 1e-3: dt, burn-in, twin, Richardson; t_run = 400), the variance reduction of eta with
  today's richest set (``martingale+boundary+twin``) and with the generator's (the estimate's own
  choice, and the richest cross-fitted set forced), the CPU cost of accumulating the generator sums
  (one thread, short runs with and without them interleaved, median of three), the reduction per
  unit of CPU against today's, the plain relative variance of eta per unit path time (what the
  solver's rule reads) and the solver's decision at tol = 1e-3 and 1e-4 from this ensemble;
* :func:`generator_coverage` -- the error bars of the controlled estimate over seeds against
  references that share none of its errors: Fokker--Planck (n = 3, n = 1.5 and the kink at
  a = 0.5 and 1, the reference table's values to 1e-5 or better), the reference table's long run at
  the strong kink (n = 1, a = 2), the exact discrete values of the harmonic unit and ring;
* :func:`generator_timings` -- the solver end to end with and without the generator controls
  (``generator=False``), CPU and wall time, for the cases of the issue;
* :func:`solver_timings` -- the solver end to end as it runs by default on the same cases, and
  where it picks the Richardson extrapolation also with the halving policy.

``python -m validation.studies.mc.generator [--quick] [--out DIR] [--part rows|coverage|timings|solver]
[--case LABEL ...]`` writes ``bench_montecarlo_generator.json`` and ``.png`` (the recorded full runs:
``validation/data/bench_montecarlo_generator_*.json``); ``--case`` restricts the coverage part to
those labels of :data:`COVERAGE`.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from fpe_harvester import Harvester, solve
from fpe_harvester.errors import ParameterError
from fpe_harvester.parallel import default_threads
from montecarlo import MonteCarlo, estimate, simulate
from montecarlo.harmonic import twin_expectations
from validation.references.exactflow import FlowSettings, solve_flow
from validation.references.reftable import load
from validation.studies.cli import axes_plot, save_benchmark

__all__ = ["STEM", "ROW_CASES", "TODAY", "GENERATOR_SET", "generator_rows", "generator_coverage",
           "generator_timings", "timing_run", "TIMING_CASES", "FLOW_REFERENCE", "flow_reference", "draw", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_generator"
#: (n, a, N, k) of the table's rows.
ROW_CASES = tuple((n, a, 1, 0.0) for n in (1.0, 1.25, 1.5, 3.0) for a in (0.5, 1.0, 2.0)) + ((3.0, 0.5, 3, -0.5),)
#: Today's richest control set, and the generator's richest.
TODAY, GENERATOR_SET = "martingale+boundary+twin", "martingale+boundary+twin+generator"


def _case(n: float, a: float, N: int, k: float) -> str:
    return f"n{n:g}_a{a:g}" + (f"_N{N}_k{k:g}" if N > 1 else "")


def _cost_ratio(h: Harvester, plan: Any, quick: bool) -> float:
    """CPU time of a short run with the generator sums over one without (one thread, the solver's
    kernels and paths at tol 1e-3, interleaved, median of three)."""
    kw = dict(dt=plan.dt, paths=plan.paths, replicas=2 if quick else 4, t_burn=5.0, t_run=40.0 if quick else 100.0,
              seed=3, twin=plan.twin, start=plan.start, richardson=True, threads=1, generator_every=0.0)
    times: dict[bool, list[float]] = {False: [], True: []}
    for rep in range(4):
        for gen in (False, True):
            t0 = time.process_time()
            simulate(h, controls=("martingale", "boundary", "generator") if gen else ("martingale", "boundary"), **kw)
            if rep:  # the first round compiles
                times[gen].append(time.process_time() - t0)
    return float(np.median(times[True]) / np.median(times[False]))


def _decision(h: Harvester, e: Any, tol: float) -> str:
    """The solver's generator decision at ``tol`` with this ensemble as its first batch."""
    solver = MonteCarlo(seed=1, tol=tol, progress=False)
    plan = solver.plan(h)
    plan, first = solver._generator_plan(h, plan, e, estimate(e, h, control=False))
    return plan.notes["generator"]


def _row(n: float, a: float, N: int, k: float, replicas: int, paths: int, quick: bool) -> dict[str, Any]:
    h = Harvester.build(n=n, a=a, N=N, k=k)
    plan = MonteCarlo(seed=1, tol=1e-3, extrapolate=False).plan(h)
    t0 = time.process_time()
    e = simulate(h, dt=plan.dt, paths=paths, replicas=replicas, t_burn=plan.t_burn, t_run=400.0, seed=11,
                 twin=plan.twin, start=plan.start, richardson=True, controls=("martingale", "boundary", "generator"),
                 generator_every=0.0)
    row: dict[str, Any] = {"n": n, "a": a, "N": N, "k": k, "replicas": replicas, "paths": paths, "t_run": 400.0,
                           "dt": plan.dt, "simulate_cpu_s": time.process_time() - t0}
    plain = estimate(e, h, control=False)
    row["plain_relvar_per_path_time"] = (plain.se["eta"] / plain.mean["eta"]) ** 2 * replicas * paths * e.t_run
    for label, which in (("today", TODAY), ("generator_forced", GENERATOR_SET), ("auto", None)):
        try:
            est = estimate(e, h, controls=which)
        except ParameterError as exc:
            row[label] = {"note": str(exc).split(";")[0]}
            continue
        row[label] = {"controls": est.controls, "vr_eta": est.reduction.get("eta"), "eta": est.mean["eta"],
                      "se_eta": est.se["eta"], "bias_eta": est.bias["eta"]}
    row["generator_cost_ratio"] = _cost_ratio(h, plan, quick)
    if isinstance(row["today"].get("vr_eta"), float) and isinstance(row["auto"].get("vr_eta"), float):
        row["gain_per_cpu"] = row["auto"]["vr_eta"] / row["today"]["vr_eta"] / row["generator_cost_ratio"]
    row["solver"] = {f"tol={tol:g}": _decision(h, e, tol) for tol in (1e-3, 1e-4)}
    return row


def generator_rows(quick: bool) -> dict[str, Any]:
    """The table of :data:`ROW_CASES` (see the module docstring): 512 replicas of 4 paths per case
    (quick: n = 1 and 3 at a = 2 and 0.5, 96 of 4)."""
    cases = ROW_CASES if not quick else ((1.0, 2.0, 1, 0.0), (3.0, 0.5, 1, 0.0))
    replicas, paths = (96, 4) if quick else (512, 4)
    out = {}
    for case in cases:
        t0 = time.perf_counter()
        out[_case(*case)] = {**_row(*case, replicas, paths, quick), "bench_wall_s": time.perf_counter() - t0}
    return out


def _summary(z: list[float]) -> dict[str, Any]:
    from scipy.stats import binom

    a = np.abs(np.array(z))
    n = a.size
    limits = {f"within_{k}_limits_99": (binom.ppf(0.005, n, p) / n, binom.ppf(0.995, n, p) / n)
              for k, p in ((1, 0.6827), (2, 0.9545))}
    return {"seeds": n, "within_1": float((a < 1).mean()), "within_2": float((a < 2).mean()), **limits,
            "rms_z": float(np.sqrt(np.mean(a**2))), "max_abs_z": float(a.max()), "z": [round(float(v), 3) for v in z]}


#: Coverage cases: label -> (system, reference label of the table or "exact", replicas, paths, t_run,
#: and optionally the run's settings that differ from the plan's: ``dt``, ``group`` (replicas per
#: task), ``generator_every``).
COVERAGE: dict[str, tuple[Any, ...]] = {
    "n3_a0.5_vs_fpe": ({"n": 3.0, "a": 0.5}, "fpe n = 3, a = 0.5", 256, 4, 400.0),
    "n1.5_a0.5_vs_fpe": ({"n": 1.5, "a": 0.5}, "fpe n = 1.5, a = 0.5", 256, 4, 400.0),
    "n1_a0.5_vs_fpe": ({"n": 1.0, "a": 0.5}, "fpe n = 1, a = 0.5", 256, 4, 400.0),
    "n1_a1_vs_fpe": ({"n": 1.0, "a": 1.0}, "fpe n = 1, a = 1", 256, 4, 400.0),
    "n1_a2_vs_long_run": ({"n": 1.0, "a": 2.0}, "mc n = 1, a = 2", 512, 2, 200.0),
    # the solver's own layout at tol 1e-3: one-path replicas in tasks of 48, generator points every
    # 0.02, coarse step 0.01
    "n1_a2_solver_layout": ({"n": 1.0, "a": 2.0}, "mc n = 1, a = 2", 1536, 1, 400.0,
                            {"dt": 0.01, "group": 48, "generator_every": 0.02}),
    # the same with the solver's later layout: tasks of 192 and the bias from a coarse level at
    # four times the fine step over the window's first half (simulate's coarse_ratio=4,
    # coarse_half=True)
    "n1_a2_coarse_ratio4": ({"n": 1.0, "a": 2.0}, "mc n = 1, a = 2", 1536, 1, 400.0,
                            {"dt": 0.01, "group": 192, "generator_every": 0.02, "coarse_ratio": 4,
                             "coarse_half": True}),
    "harmonic_unit_vs_exact": ({"a": 0.5}, "exact", 256, 2, 100.0),
    "harmonic_ring_vs_exact": ({"a": 0.5, "N": 3, "k": -0.2}, "exact", 256, 2, 100.0),
}


def _coverage_case(system: dict[str, Any], ref_label: str, replicas: int, paths: int, t_run: float,
                   seeds: int, settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """z-scores over seeds of the estimate's own choice and of the generator set forced."""
    h = Harvester.build(**system)
    harmonic = ref_label == "exact"
    plan = MonteCarlo(seed=1, tol=1e-3, extrapolate=False).plan(h)
    settings = dict(settings or {})
    dt = settings.pop("dt", 0.2 if harmonic else plan.dt)
    if harmonic:
        exact = twin_expectations(h, dt)  # the frozen step's own discrete law: no time-step bias
        ref, ref_err = exact["V2"] / exact["vxi"], 0.0
    else:
        entry = load()[ref_label]
        ref, ref_err = entry["eta"], entry["eta_err"]
    z: dict[str, list[float]] = {"auto": [], "forced": []}
    chosen, vr = [], []
    for s in range(seeds):
        e = simulate(h, dt=dt, paths=paths, replicas=replicas, t_burn=30.0 if harmonic else plan.t_burn, t_run=t_run,
                     seed=7000 + s, twin=None if harmonic else plan.twin, start="twin", richardson=not harmonic,
                     step="frozen", controls=("martingale", "boundary", "generator"), **settings)
        forced = "martingale+boundary+generator" if harmonic else GENERATOR_SET
        for label, which in (("auto", None), ("forced", forced)):
            try:
                est = estimate(e, h, controls=which)
            except ParameterError:
                # the end-of-window terms refused (a transient): the set without them
                est = estimate(e, h, controls=which.replace("boundary+", ""))
            value = est.mean["eta"] - est.bias["eta"]
            z[label].append((value - ref) / math.hypot(est.se["eta"], est.bias_se["eta"], ref_err))
            if label == "auto":
                chosen.append(est.controls)
                vr.append(est.reduction.get("eta"))
    return {"reference_eta": ref, "reference_err": ref_err, "replicas": replicas, "paths": paths, "t_run": t_run,
            "dt": dt, **settings, "auto": _summary(z["auto"]), "forced": _summary(z["forced"]),
            "auto_sets": {c: chosen.count(c) for c in set(chosen)},
            "median_vr_eta": float(np.median([v for v in vr if v]))}


def generator_coverage(quick: bool, only: tuple[str, ...] = ()) -> dict[str, Any]:
    """Coverage of the controlled error bars over seeds (24; quick: 6 of the cheap cases): the
    fine level minus its Richardson bias estimate against the reference, in units of the standard
    error, the bias estimate's error and the reference's in quadrature. ``only``: these labels of
    :data:`COVERAGE` (default all)."""
    seeds = 6 if quick else 24
    unknown = set(only) - set(COVERAGE)
    if unknown:
        raise ParameterError(f"case must be among {sorted(COVERAGE)}, got {sorted(unknown)}")
    cases = {k: v for k, v in COVERAGE.items() if (not quick or "a2" not in k) and (not only or k in only)}
    out: dict[str, Any] = {"nominal": {"within_1": 0.6827, "within_2": 0.9545}}
    for label, (system, ref, replicas, paths, t_run, *settings) in cases.items():
        t0 = time.perf_counter()
        out[label] = {**_coverage_case(system, ref, replicas, paths, t_run, seeds, *settings),
                      "bench_wall_s": time.perf_counter() - t0}
    return out


#: End-to-end cases: (n, a, N, k, tol, seed, reference: a label of the reference table, or
#: "exactflow" for :func:`flow_reference`).
TIMING_CASES = ((1.0, 2.0, 1, 0.0, 1e-3, 7, "mc n = 1, a = 2"), (1.25, 2.0, 1, 0.0, 1e-3, 7, "exactflow"),
                (1.0, 0.5, 1, 0.0, 1e-4, 7, "fpe n = 1, a = 0.5"), (3.0, 0.5, 1, 0.0, 1e-4, 7, "fpe n = 3, a = 0.5"),
                (3.0, 0.5, 3, -0.5, 1e-4, 7, "mc n = 3, N = 3, a = 0.5, k = -0.5"))


#: Settings of the exact-flow reference (:mod:`validation.references.exactflow`) at n = 1.25, a = 2,
#: where the reference table has no value: 0.05 % on eta (its step bias bound included).
FLOW_REFERENCE = {"step": 0.02, "w_trap": 0.0, "paths": 64, "t_run": 4000.0, "seed": 11}


@functools.lru_cache(maxsize=None)
def flow_reference(n: float, a: float) -> dict[str, float]:
    """eta and its error from the exact-flow construction at :data:`FLOW_REFERENCE` (cached)."""
    r = solve_flow(Harvester.build(n=n, a=a), FlowSettings(**FLOW_REFERENCE))
    return {"eta": r.eta, "eta_err": r.eta_err}


def timing_run(n: float, a: float, N: int, k: float, tol: float, seed: int, ref_label: str | None,
               generator: bool, **options: Any) -> dict[str, Any]:
    """One end-to-end solve of a :data:`TIMING_CASES` case with or without the generator controls
    (and any other solver ``options``): CPU seconds (all threads), wall seconds, the result and its
    distance to the reference in combined error bars."""
    h = Harvester.build(n=n, a=a, N=N, k=k)
    t0, w0 = time.process_time(), time.perf_counter()
    r = solve(h, "mc", seed=seed, tol=tol, generator=generator, max_time=7200.0, progress=False, **options)
    i = r.info
    row = {"cpu_s": time.process_time() - t0, "wall_s": time.perf_counter() - w0, "eta": r.eta,
           "eta_err": r.eta_err, "status": r.status.value, "replicas": i["replicas"], "paths": i["paths"],
           "dt": i["dt"], "control_set": i["control_set"], "vr_eta": i["variance_reduction"],
           "restarts": i["plan_notes"].get("restarts"), "generator": i["plan_notes"].get("generator")}
    if ref_label is not None:
        ref = flow_reference(n, a) if ref_label == "exactflow" else load()[ref_label]
        row["z_vs_reference"] = (r.eta - ref["eta"]) / math.hypot(r.eta_err, ref["eta_err"])
    return row


def generator_timings(quick: bool) -> dict[str, Any]:
    """The solver with the generator controls (default) and without (``generator=False``, today's
    behaviour) on :data:`TIMING_CASES` (quick: at 10x the tolerance), one after the other per case
    (:func:`timing_run`)."""
    out = {}
    for n, a, N, k, tol, seed, ref_label in TIMING_CASES:
        tol = tol * 10 if quick else tol
        row: dict[str, Any] = {"tol": tol, "seed": seed, "reference": ref_label}
        for label, gen in (("new", True), ("today", False)):
            row[label] = timing_run(n, a, N, k, tol, seed, ref_label, gen)
        row["cpu_ratio_today_over_new"] = row["today"]["cpu_s"] / row["new"]["cpu_s"]
        out[_case(n, a, N, k)] = row
    return {"threads": default_threads(), **out}


#: Further seeds of the strong kink's end-to-end run (its wall time varies with the seed: the
#: pilot's estimate of the variance sizes the batches, and the noisy bias estimate of the halving
#: policy enters the error budget).
STRONG_KINK_SEEDS = tuple(range(8, 19))


def solver_timings(quick: bool) -> dict[str, Any]:
    """The solver as it runs by default on :data:`TIMING_CASES` (quick: at 10x the tolerance), and
    where it picks the Richardson extrapolation (``extrapolate=None``) also with the halving policy
    (``extrapolate=False``) right after it, for the ratio measured in one run; then the strong kink
    (n = 1, a = 2) at :data:`STRONG_KINK_SEEDS` too (not in quick runs), with the median wall time
    over all its seeds."""
    out: dict[str, Any] = {}
    for n, a, N, k, tol, seed, ref_label in TIMING_CASES:
        tol = tol * 10 if quick else tol
        row: dict[str, Any] = {"tol": tol, "seed": seed, "reference": ref_label}
        row["default"] = timing_run(n, a, N, k, tol, seed, ref_label, True)
        h = Harvester.build(n=n, a=a, N=N, k=k)
        row["default"]["extrapolated"] = MonteCarlo(tol=tol).extrapolates(h)
        if row["default"]["extrapolated"]:
            row["halving"] = timing_run(n, a, N, k, tol, seed, ref_label, True, extrapolate=False)
            row["wall_ratio_halving_over_default"] = row["halving"]["wall_s"] / row["default"]["wall_s"]
        out[_case(n, a, N, k)] = row
    if not quick:
        n, a, N, k, tol, seed, ref_label = TIMING_CASES[0]
        runs = [out[_case(n, a, N, k)]["default"]] + [
            {"seed": s, **timing_run(n, a, N, k, tol, s, ref_label, True)} for s in STRONG_KINK_SEEDS]
        out["strong_kink_seeds"] = {"seeds": [seed, *STRONG_KINK_SEEDS], "runs": runs[1:],
                                    "median_wall_s": float(np.median([r["wall_s"] for r in runs])),
                                    "max_abs_z": float(max(abs(r["z_vs_reference"]) for r in runs))}
    return {"threads": default_threads(), **out}


def draw(res: dict[str, Any], ax: Any) -> None:
    """Variance reduction of eta per row: today's set and the generator's (the estimate's choice)."""
    rows = {k: v for k, v in res.get("rows", {}).items() if isinstance(v, dict) and "today" in v}
    y = np.arange(len(rows))
    for j, label in enumerate(("today", "auto")):
        ax.barh(y + 0.2 * (2 * j - 1), [(r[label].get("vr_eta") or 0.0) for r in rows.values()], 0.4,
                label={"today": TODAY, "auto": "with the generator"}[label])
    ax.set_yticks(y, list(rows), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("variance reduction of eta")
    ax.legend(fontsize=7)


_PARTS = {"rows": generator_rows, "coverage": generator_coverage, "timings": generator_timings,
          "solver": solver_timings}


def run(quick: bool = False, out: Path | str | None = None, parts: tuple[str, ...] = tuple(_PARTS),
        cases: tuple[str, ...] = ()) -> dict[str, Any]:
    """The ``parts`` of this study (default all; ``cases``: the coverage part's labels, default
    all); writes ``{STEM}.json`` and ``.png`` into ``out``."""
    t0 = time.perf_counter()
    res: dict[str, Any] = {"quick": quick, "threads": default_threads()}
    for part in parts:
        res[part] = generator_coverage(quick, cases) if part == "coverage" else _PARTS[part](quick)
    res["wall_s"] = time.perf_counter() - t0
    save_benchmark(res, out, STEM, axes_plot(draw))
    return res


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """``python -m validation.studies.mc.generator [--quick] [--out DIR] [--part NAME ...] [--case LABEL ...]``."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=None)
    p.add_argument("--part", nargs="*", choices=tuple(_PARTS), default=list(_PARTS))
    p.add_argument("--case", nargs="*", choices=tuple(COVERAGE), default=[])
    args = p.parse_args(argv)
    res = run(args.quick, args.out, tuple(args.part), tuple(args.case))
    print(json.dumps(res, indent=1, default=str))
    return res


if __name__ == "__main__":  # pragma: no cover
    main()
