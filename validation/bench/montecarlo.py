"""Benchmark of the Monte Carlo engine: speed, cost at equal error, time-step bias, RNG choice.

Measured in one run:

* the cost of one standard normal with the candidate generators (numba's legacy
  ``np.random`` inside ``prange``, bulk numpy ``Generator`` draws, a ``Generator`` drawn
  inside numba), which decided the engine's choice;
* path-steps per second (one time step of one ring; fine level only) for N = 1 (harmonic,
  kink n = 1) and N = 3 (harmonic, n = 3), on all usable cores;
* for n = 1, a = 0.5, N = 1: relative standard error of eta against wall time, the wall time to
  reach 1e-3 (run in full mode, extrapolated as ``wall * (err/1e-3)^2`` in quick mode), the
  engine's own time-step bias there, and the plain vectorized numpy Euler--Maruyama loop
  (:func:`montecarlo.simulate_naive`) measured in the same run: its throughput, its bias at
  dt = 0.01 and 0.005 against the engine, and the wall time it would need for the same total
  error (bias from the fitted power law, statistics from its measured variance: a model
  evaluated with measured inputs, labelled as such);
* time-step bias: coupled (common-noise) differences eta(dt/2) - eta(dt) for the harmonic unit,
  the kink at a = 2 and the steep n = 1.1 potential, and the naive scheme's error at a = 2;
* control variates (the harmonic twin, :mod:`montecarlo.controls.regression`) for single units n = 1 to 8
  and rings N = 3: the variance-reduction factor of eta, V2 and Pin on one ensemble, the
  twin's cost (interleaved timings, median ratio), and the solver's wall time to a relative
  error of 1e-4 with and without them, measured in the same run within a budget and, where
  the budget runs out, extrapolated as ``wall * (se / se_needed)^2`` (labelled);
* cost and bias against the noise's correlation time tau = 1e-4, 1e-2, 1, 100 (n = 3): the
  solver to 1e-3 against the Fokker--Planck value, which step ran (joint below tau = 10 dt),
  and the coupled time-step differences of the default and the frozen-xi step;
* steep walls n = 8, 12, 16, 32 (a = 0.5, single unit): the solver to 1e-3 against the
  Fokker--Planck value, the escaped paths (none may escape: the system is confined), the
  substeps' cost as path-steps per second against n = 3, and the coupled time-step difference
  eta(0.01) - eta(0.02);
* error-versus-time curves (``series``) for the combined benchmark (:mod:`.combined`);
* martingale control variates (:func:`martingale_rows`): the variance-reduction factor of eta
  and the time to 1e-4 with the new controls, the twin alone and plain, for n in 1, 1.5, 3, 4, 8,
  N = 1 and N = 3 at k = -0.01, -0.2, -0.5, from one ensemble pair per row; and the coverage of
  their error bars over seeds against the exact solution (harmonic pair) and the Fokker--Planck
  solver (single n = 3 unit) (:func:`martingale_coverage`);
* the time-step policy (:func:`policy_rows`, :func:`policy_coverage`): the solver's CPU and wall
  time to 1e-4 with the Richardson extrapolation (three coupled levels, the default) and with
  the old rule (halve dt and restart while the bias estimate exceeds tol/3), for the ring n = 3,
  N = 3, k = -0.5 and single n = 3, n = 1.5 units (a = 0.5), in one run; and the coverage of both
  policies' error bars at tol = 1e-3 over seeds against independent references (Fokker--Planck
  values of ``reference_values.json`` for the single units, :data:`RING_REFERENCE` for the ring);
  and the variance reduction with the end-of-window terms of the martingale controls
  (:func:`boundary_rows`);
* the kink's time-step law (:mod:`validation.kinkstudy`): at a = 0.5, 1, 2, eta at fine steps
  0.04 ... 0.005 from runs with independent seeds, each Richardson-coupled, and the weak order
  p of eta(dt) = eta0 + c dt^p fitted to the independent values and to the coupled differences
  (with chi^2 + 1 intervals), beside the order the solver's Richardson bias uses; the old rule
  (units held at rest once 64 crossings fit in a step) against the default (averaged swings)
  at a = 2 on the same noise: held fraction per dt, eta difference, cost ratio; and the scheme
  minus the independent reference of :mod:`validation.kinkref` on common noise.

``python -m validation.bench.montecarlo [--quick] [--out DIR]`` writes ``bench_montecarlo.json``
and ``bench_montecarlo.png``.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit, prange

from fpe_harvester import Harvester, solve
from fpe_harvester.errors import ParameterError
from fpe_harvester.parallel import default_threads
from montecarlo import MonteCarlo, estimate, simulate, simulate_naive
from validation.bench.cli import bench_main, save_benchmark

__all__ = ["STEM", "run", "martingale_rows", "martingale_coverage", "run_martingale", "policy_rows",
           "policy_coverage", "run_policy", "boundary_rows", "RING_REFERENCE"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo"

TARGET = 1e-3


@njit(parallel=True, cache=True)
def _legacy_prange(nchunks: int, nper: int, seeds: np.ndarray) -> np.ndarray:
    acc = np.zeros(nchunks)
    for c in prange(nchunks):
        np.random.seed(seeds[c])
        s = 0.0
        for _ in range(nper):
            s += np.random.standard_normal()
        acc[c] = s
    return acc


@njit(nogil=True, cache=True)
def _generator_inside(gen: np.random.Generator, nper: int) -> float:
    s = 0.0
    for _ in range(nper):
        s += gen.standard_normal()
    return s


def _rng_costs(n: int, threads: int) -> dict[str, float]:
    """Nanoseconds of wall time per standard normal, all threads busy where possible.

    A hand-written xoshiro256++ + ziggurat generator inlined in numba was also tried while
    building the engine: 10 ns per normal on its fast path alone, no better than numba's own
    ``Generator`` support, so it was dropped.
    """
    nch = 8 * threads
    per = n // nch
    seeds = np.arange(nch, dtype=np.uint32)
    gens = [np.random.default_rng(i) for i in range(nch)]
    _legacy_prange(2, 10, seeds)
    _generator_inside(gens[0], 10)
    out: dict[str, float] = {}
    t0 = time.perf_counter()
    _legacy_prange(nch, per, seeds)
    out["numba_legacy_np_random_prange"] = (time.perf_counter() - t0) / (nch * per) * 1e9
    buf = [np.empty(per) for _ in range(threads)]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as ex:
        list(ex.map(lambda i: gens[i].standard_normal(out=buf[i % threads]), range(nch)))
    out["numpy_generator_bulk_threads"] = (time.perf_counter() - t0) / (nch * per) * 1e9
    t0 = time.perf_counter()
    gens[0].standard_normal(out=buf[0])
    out["numpy_generator_bulk_1thread"] = (time.perf_counter() - t0) / per * 1e9
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as ex:
        list(ex.map(lambda g: _generator_inside(g, per), gens))
    out["generator_inside_numba_threads"] = (time.perf_counter() - t0) / (nch * per) * 1e9
    t0 = time.perf_counter()
    _generator_inside(gens[0], per)
    out["generator_inside_numba_1thread"] = (time.perf_counter() - t0) / per * 1e9
    out["chosen"] = "generator_inside_numba_threads"
    return out


def _rate(h: Harvester, dt: float, paths: int, replicas: int, t_run: float) -> dict[str, float]:
    simulate(h, dt=dt, paths=2, replicas=1, t_burn=0.0, t_run=dt * 4, seed=0)  # compile
    cpu0 = time.process_time()
    e = simulate(h, dt=dt, paths=paths, replicas=replicas, t_burn=0.0, t_run=t_run, seed=1)
    cpu = time.process_time() - cpu0
    # CPU seconds of all threads: on a shared machine the wall rate understates what the
    # cores deliver; per-core rate x cores is what an idle machine would give (an estimate)
    return {"path_steps": e.path_steps, "wall_s": e.wall_time, "cpu_s": cpu,
            "path_steps_per_s": e.path_steps / e.wall_time,
            "unit_steps_per_s": e.path_steps * h.N / e.wall_time,
            "path_steps_per_cpu_s": e.path_steps / cpu if cpu > 0 else None,
            "idle_machine_estimate_path_steps_per_s":
                e.path_steps / cpu * default_threads() if cpu > 0 else None}


def _rel_se(values: np.ndarray) -> float:
    return float(values.std(ddof=1) / math.sqrt(values.size) / abs(values.mean()))


def _eta(e: Any) -> np.ndarray:
    m = e.moments(0)
    return m["V2"] / m["vxi"]


def _equal_error(quick: bool) -> dict[str, Any]:
    """n = 1, a = 0.5, N = 1: engine vs numpy Euler-Maruyama at equal total error."""
    h = Harvester.build(a=0.5, n=1)
    dt = 0.01
    paths, t_burn, t_run = 256, 40.0, 100.0
    # at least 16 replicas before trusting a standard error (4 can be off by a factor 3)
    batch = 8 if quick else 16
    max_batches = 2 if quick else 40
    ens, curve, t_total = None, [], 0.0
    for b in range(max_batches):
        e = simulate(h, dt=dt, paths=paths, replicas=batch, t_burn=t_burn, t_run=t_run, seed=101,
                     first_replica=b * batch)
        ens = e if ens is None else ens.merge(e)
        t_total += e.wall_time
        rel = _rel_se(_eta(ens))
        curve.append({"wall_s": t_total, "replicas": ens.replicas, "rel_se_eta": rel})
        if rel <= TARGET:
            break
    eta = _eta(ens)
    rel = _rel_se(eta)
    reached = rel <= TARGET
    t_target = t_total if reached else t_total * (rel / TARGET) ** 2
    # the engine's own bias at dt: common-noise difference with dt/2 ... dt, at the kink
    # scheme's measured order (montecarlo.estimate.BIAS_ORDER)
    eb = simulate(h, dt=2 * dt, paths=paths, replicas=4 if quick else 16, t_burn=t_burn, t_run=t_run,
                  seed=202, richardson=True)
    est_b = estimate(eb, h)
    ours = {
        "dt": dt, "eta": float(eta.mean()), "rel_se_eta": rel, "replicas": ens.replicas,
        "wall_s": t_total, "path_steps_per_s": ens.path_steps / ens.wall_time,
        "wall_to_1e-3_s": t_target, "extrapolated": not reached,
        "bias_eta_at_dt_0.02_vs_0.01": est_b.bias["eta"], "bias_eta_se": est_b.bias_se["eta"],
        "bias_note": "bias of the dt = 0.01 run, estimated (the kink scheme's measured order) from "
                     "common-noise runs at 0.02 and 0.01; relative to eta",
        "curve": curve,
    }
    ours["rel_bias_eta"] = abs(est_b.bias["eta"]) / ours["eta"]
    # numpy Euler-Maruyama: throughput, bias against the engine, variance per path-time
    em = {}
    em_paths = 1024 if quick else 4096
    for em_dt in (0.02, 0.01):
        en = simulate_naive(h, dt=em_dt, paths=em_paths, replicas=4, t_burn=t_burn,
                            t_run=25.0 if quick else 100.0, seed=303)
        e_eta = _eta(en)
        em[em_dt] = {"eta": float(e_eta.mean()), "rel_se": _rel_se(e_eta), "wall_s": en.wall_time,
                     "path_steps_per_s": en.path_steps / en.wall_time,
                     "path_time": 4 * em_paths * (en.t_run + en.t_burn), "run_time": 4 * em_paths * en.t_run}
    ref = ours["eta"]
    b1, b2 = (em[d]["eta"] / ref - 1.0 for d in (0.02, 0.01))
    order = math.log(abs(b1) / abs(b2)) / math.log(2.0) if b1 * b2 > 0 and abs(b1) > abs(b2) else 1.0
    # an order fitted from two noisy points is clipped to [0.5, 2] (EM: 1, lower at a kink)
    order = min(max(order, 0.5), 2.0)
    C = abs(b2) / 0.01**order
    target_bias = TARGET / math.sqrt(2.0)
    dt_needed = (target_bias / C) ** (1.0 / order)
    # relative variance x measured path-time is ~ constant: scale to a se of TARGET/sqrt(2)
    var_time = 0.5 * sum(em[d]["rel_se"] ** 2 * em[d]["run_time"] for d in em)
    run_time_needed = var_time / (TARGET / math.sqrt(2.0)) ** 2
    steps_needed = run_time_needed * (1.0 + t_burn / 100.0) / dt_needed
    em_rate = em[0.01]["path_steps_per_s"]
    em_wall = steps_needed / em_rate
    # engine at the same total error: its measured bias leaves sqrt(1e-6 - bias^2) for the se
    rb = ours["rel_bias_eta"]
    engine_equal = t_target * (TARGET**2 / (TARGET**2 - rb**2)) if rb < 0.9 * TARGET else None
    return {
        "case": "n = 1, a = 0.5, N = 1, defaults",
        "engine": ours,
        "engine_wall_at_total_error_1e-3_s": engine_equal,
        "numpy_em": {
            "runs": {str(k): v for k, v in em.items()},
            "rel_bias_dt_0.02": b1, "rel_bias_dt_0.01": b2, "fitted_order": order,
            "dt_for_bias_target": dt_needed, "wall_to_equal_error_s": em_wall,
            "model_note": "EM cost at total relative error 1e-3 (bias and standard error 1e-3/sqrt(2) "
                          "each): dt from the measured bias power law, path-time from its measured "
                          "variance at dt = 0.01, wall time from its measured throughput; a model "
                          "evaluated with measured inputs, not a run",
        },
        "modelled_speedup_at_equal_error": (em_wall / engine_equal) if engine_equal else None,
        "modelled_speedup_note": "a model, not a measurement: the numpy Euler-Maruyama side is the wall time "
                                 "the model above predicts (numpy_em.model_note); the engine side is measured "
                                 "(extrapolated in quick mode)",
        "measured_speedup_same_dt_throughput": ours["path_steps_per_s"] / em_rate,
    }


def _bias_study(quick: bool) -> dict[str, Any]:
    """Coupled differences eta(dt/2) - eta(dt) and the naive scheme's error at the kink."""
    out: dict[str, Any] = {}
    cases = {
        "harmonic_a0.5": (Harvester.build(a=0.5), (0.4, 0.2, 0.1), 64),
        "kink_a2_n1": (Harvester.build(a=2.0, n=1), (0.04, 0.02) if quick else (0.08, 0.04, 0.02, 0.01),
                       64 if quick else 128),
        "steep_a0.5_n1.1": (Harvester.build(a=0.5, n=1.1), (0.04, 0.02) if quick else (0.08, 0.04, 0.02), 128),
    }
    for name, (h, dts, paths) in cases.items():
        rows = []
        for dt in dts:
            e = simulate(h, dt=dt, paths=paths if quick else 2 * paths, replicas=6 if quick else 12,
                         t_burn=20.0, t_run=40.0 if quick else 100.0, seed=17, richardson=True)
            m0, m1 = e.moments(0), e.moments(1)
            d = m0["V2"] / m0["vxi"] - m1["V2"] / m1["vxi"]
            eta = float((m0["V2"] / m0["vxi"]).mean())
            rows.append({"dt": dt, "eta_fine": eta, "diff": float(d.mean()),
                         "diff_se": float(d.std(ddof=1) / math.sqrt(d.size)),
                         "rel_diff": float(d.mean()) / eta, "wall_s": e.wall_time})
        fit = None
        good = [r for r in rows if abs(r["diff"]) > 3 * r["diff_se"]]
        if len(good) >= 2:
            logs = np.log([[r["dt"], abs(r["diff"])] for r in good])
            fit = float(np.polyfit(logs[:, 0], logs[:, 1], 1)[0])
        out[name] = {"rows": rows, "fitted_order_from_resolved_points": fit}
    h = Harvester.build(a=2.0, n=1)
    kw = dict(paths=128 if quick else 1024, replicas=6 if quick else 12, t_burn=20.0,
              t_run=40.0 if quick else 100.0)
    naive = estimate(simulate_naive(h, dt=0.01, seed=31, **kw), h)
    ours = estimate(simulate(h, dt=0.02, seed=32, richardson=True, **kw), h)
    out["kink_a2_naive_vs_engine_dt_0.01"] = {
        "naive_eta": naive.mean["eta"], "naive_se": naive.se["eta"],
        "engine_eta": ours.mean["eta"], "engine_se": ours.se["eta"],
        "engine_bias_estimate": ours.bias["eta"], "engine_bias_se": ours.bias_se["eta"],
        "naive_rel_error": naive.mean["eta"] / ours.mean["eta"] - 1.0,
        "naive_V2_ratio": naive.mean["V2"] / ours.mean["V2"], "naive_Pin_ratio": naive.mean["Pin"] / ours.mean["Pin"],
    }
    return out


#: Correlation times of the noise study (:func:`_tau_study`), n = 3, a = 0.5.
TAUS = (1e-4, 1e-2, 1.0, 100.0)


def _coupled_diff(h: Harvester, quick: bool, seed: int, joint: bool | None) -> dict[str, Any]:
    """eta(0.01) - eta(0.02) on common noise (``joint`` as in :func:`montecarlo.simulate`)."""
    e = simulate(h, dt=0.02, paths=64, replicas=6 if quick else 16, t_burn=20.0, t_run=50.0, seed=seed,
                 richardson=True, joint=joint)
    m0, m1 = e.moments(0), e.moments(1)
    d = m0["V2"] / m0["vxi"] - m1["V2"] / m1["vxi"]
    # V2 too: with xi frozen at tau << dt the plain v xi has the variance D/tau and eta per
    # replica is meaningless
    dv = m0["V2"] - m1["V2"]
    return {"joint_step": bool(e.notes["joint_step"]), "dt": 0.02, "diff": float(d.mean()),
            "diff_se": float(d.std(ddof=1) / math.sqrt(d.size)),
            "rel_diff": float(d.mean() / (m0["V2"] / m0["vxi"]).mean()),
            "rel_diff_V2": float(dv.mean() / m0["V2"].mean()),
            "rel_diff_V2_se": float(dv.std(ddof=1) / math.sqrt(dv.size) / m0["V2"].mean()),
            "wall_s": e.wall_time}


def _tau_study(quick: bool) -> dict[str, Any]:
    """Cost and bias against the noise's correlation time tau, n = 3, a = 0.5, single unit.

    Per tau: the solver to a relative error of 1e-3 (1e-2 quick) within a budget (wall time,
    replicas, dt, which step ran, status), against the Fokker--Planck value (tol 1e-5, 1e-4 quick), and the
    coupled difference eta(0.01) - eta(0.02) on common noise of the default step at dt = 0.02
    and, where that is the joint step, of the frozen-xi step too (its bias at tau << dt).
    """
    tol, budget = (1e-2, 30.0) if quick else (1e-3, 300.0)
    out: dict[str, Any] = {"tol": tol, "budget_s": budget}
    for i, tau in enumerate(TAUS):
        h = Harvester.build(a=0.5, n=3, tau=tau)
        fp = solve(h, "fpe", tol=1e-4 if quick else 1e-5)
        r = solve(h, "mc", seed=40 + i, tol=tol, max_time=budget, progress=False)
        row: dict[str, Any] = {
            "fpe_eta": fp.eta, "fpe_eta_err": fp.eta_err, "fpe_status": fp.status.value,
            "mc_eta": r.eta, "mc_eta_err": r.eta_err, "mc_status": r.status.value,
            "wall_s": r.info["wall_time"], "replicas": r.info["replicas"], "dt": r.info["dt"],
            "joint_step": r.info["joint_step"], "bias_eta": r.info["bias_eta"],
            "variance_reduction": r.info["variance_reduction"]}
        if r.eta is not None and fp.eta is not None:
            row["mc_minus_fpe_in_combined_errors"] = (r.eta - fp.eta) / math.hypot(r.eta_err, fp.eta_err)
        row["coupled_diff"] = _coupled_diff(h, quick, 60 + i, None)
        if row["coupled_diff"]["joint_step"]:
            row["coupled_diff_frozen"] = _coupled_diff(h, quick, 60 + i, False)
        out[f"tau_{tau:g}"] = row
    return out


#: Exponents of the steep-wall study (:func:`_steep_study`), a = 0.5, single unit.
STEEP_NS = (8.0, 12.0, 16.0, 32.0)


def _steep_study(quick: bool) -> dict[str, Any]:
    """Steep walls U = a|x|^n, n = 8 ... 32, a = 0.5, single unit: stability, cost and bias.

    Per n (quick: n = 8 and 12 only): the Fokker--Planck value (tol 1e-5, or 1e-4 where that
    does not converge within its budget; quick: 1e-4), the Monte Carlo solver to a relative error of 1e-3 (1e-2 quick) within a
    budget (wall time, replicas, dt, escaped paths, status, difference in combined errors),
    the fine level's path-steps per CPU second relative to n = 3 on the same settings (what the
    wall substeps cost), and the coupled difference eta(0.01) - eta(0.02) on common noise.
    """
    tol, budget = (1e-2, 30.0) if quick else (1e-3, 300.0)
    t_run = 10.0 if quick else 50.0
    # per CPU second: the machine may be shared, and the ratio is what the substeps cost
    base = _rate(Harvester.build(a=0.5, n=3), 0.01, 256, 4, t_run)["path_steps_per_cpu_s"]
    out: dict[str, Any] = {"tol": tol, "budget_s": budget, "n3_path_steps_per_s": base}
    # quick (the validation report's benchmark): the two gentlest walls, Fokker--Planck at 1e-4
    for i, n in enumerate(STEEP_NS[:2] if quick else STEEP_NS):
        h = Harvester.build(a=0.5, n=n)
        row: dict[str, Any] = {}
        for ftol in (1e-4,) if quick else (1e-5, 1e-4):
            fp = solve(h, "fpe", tol=ftol, max_seconds=60.0 if quick else 300.0)
            row.update(fpe_tol=ftol, fpe_eta=fp.eta, fpe_eta_err=fp.eta_err, fpe_status=fp.status.value,
                       fpe_wall_s=fp.info.get("seconds"))
            if fp.ok:
                break
        r = solve(h, "mc", seed=80 + i, tol=tol, max_time=budget, progress=False)
        row.update(mc_eta=r.eta, mc_eta_err=r.eta_err, mc_status=r.status.value, wall_s=r.info["wall_time"],
                   replicas=r.info["replicas"], dt=r.info["dt"], escaped_paths=r.info["escaped_paths"],
                   escape_fraction=r.info["escape_fraction"])
        if r.eta is not None and fp.eta is not None:
            row["mc_minus_fpe_in_combined_errors"] = (r.eta - fp.eta) / math.hypot(r.eta_err, fp.eta_err or 0.0)
        rate = _rate(h, 0.01, 256, 4, t_run)["path_steps_per_cpu_s"]
        row.update(path_steps_per_cpu_s=rate, cost_ratio_vs_n3=base / rate)
        row["coupled_diff"] = _coupled_diff(h, quick, 90 + i, None)
        out[f"n_{n:g}"] = row
    return out


#: Cases of the control-variate study: label -> Harvester.build arguments.
CV_CASES = {
    "N1_n1_a0.5": dict(a=0.5, n=1.0),
    "N1_n1_a1": dict(a=1.0, n=1.0),
    "N1_n1.5_a1": dict(a=1.0, n=1.5),
    "N1_n3_a0.5": dict(a=0.5, n=3.0),
    "N1_n4_a0.5": dict(a=0.5, n=4.0),
    "N1_n8_a0.5": dict(a=0.5, n=8.0),
    "N3_n1_a0.5_k-0.005": dict(a=0.5, n=1.0, N=3, k=-0.005),
    "N3_n1_a0.5_k-0.01": dict(a=0.5, n=1.0, N=3, k=-0.01),
    "N3_n1.5_a1_k-0.01": dict(a=1.0, n=1.5, N=3, k=-0.01),
    "N3_n3_a0.5_k-0.2": dict(a=0.5, n=3.0, N=3, k=-0.2),
    "N3_n3_a0.5_k-0.5": dict(a=0.5, n=3.0, N=3, k=-0.5),
    "N3_n4_a0.5_k-0.5": dict(a=0.5, n=4.0, N=3, k=-0.5),
    "N3_n8_a0.5_k-0.5": dict(a=0.5, n=8.0, N=3, k=-0.5),
}
QUICK_CV_CASES = ("N1_n1_a0.5", "N3_n3_a0.5_k-0.5")
CV_TARGET = 1e-4


def _time_to_target(h: Harvester, control: bool, budget: float, seed: int) -> dict[str, Any]:
    """Solver wall time to CV_TARGET, measured, or extrapolated from a run cut by the budget."""
    r = solve(h, "mc", seed=seed, tol=CV_TARGET, max_time=budget, control=control, progress=False)
    info = r.info
    out = {"status": r.status.value, "wall_s": info["wall_time"], "replicas": info["replicas"],
           "dt": info["dt"], "eta": r.eta, "eta_err": r.eta_err,
           "rel_err": r.eta_err / abs(r.eta) if r.eta else None, "control_used": info["control_variates"],
           "variance_reduction": info["variance_reduction"], "restarts": info["plan_notes"].get("restarts")}
    stat = info["eta_standard_error"] / abs(r.eta)
    bias = abs(info["bias_eta"] / r.eta)
    out.update(rel_se=stat, rel_bias=bias)
    if r.status.value == "stable" and out["rel_err"] <= CV_TARGET:
        out.update(wall_to_target_s=out["wall_s"], extrapolated=False)
    elif bias < 0.9 * CV_TARGET:
        need = math.sqrt((0.9 * CV_TARGET) ** 2 - bias**2)
        out.update(wall_to_target_s=out["wall_s"] * (stat / need) ** 2, extrapolated=True,
                   note="extrapolated as wall * (se / se_needed)^2 from this run (budget ran out)")
    else:
        out.update(wall_to_target_s=None, extrapolated=True,
                   note="bias-limited at this dt: the bias estimate alone exceeds 0.9 x target")
    return out


def _control_variates(quick: bool) -> dict[str, Any]:
    """Variance reduction, twin cost and time to 1e-4 with and without control variates."""
    out: dict[str, Any] = {}
    names = QUICK_CV_CASES if quick else tuple(CV_CASES)
    budget = 4.0 if quick else 60.0
    for i, name in enumerate(names):
        h = Harvester.build(**CV_CASES[name])
        plan = MonteCarlo(seed=500 + i, tol=CV_TARGET).plan(h)
        row: dict[str, Any] = {"case": CV_CASES[name], "twin_kappa": plan.twin, "t_burn": plan.t_burn,
                               "t_run": plan.t_run, "paths": plan.paths, "dt": plan.dt,
                               "twin_source": plan.notes.get("twin")}
        if plan.twin is None:
            out[name] = {**row, "note": "no stable harmonic twin: plain Monte Carlo only"}
            continue
        kw = dict(dt=plan.dt, paths=plan.paths, t_burn=plan.t_burn, t_run=plan.t_run, richardson=True)
        reps = 32 if quick else 128
        e = simulate(h, replicas=reps, seed=600 + i, twin=plan.twin, start="twin", **kw)
        cv, plain = estimate(e, h, control=None), estimate(e, h, control=False)
        row.update(replicas=reps, control_used=cv.control, escape_fraction=e.escaped_fraction(),
                   eta_cv=cv.mean["eta"], se_cv=cv.se["eta"], eta_plain=plain.mean["eta"],
                   se_plain=plain.se["eta"],
                   vrf={q: cv.reduction.get(q) for q in ("eta", "V2", "Pin")})
        # twin cost: same work with and without the twin, interleaved, median of the ratios
        ratios = []
        for rep in range(3 if quick else 5):
            small = dict(kw, replicas=max(2, default_threads()), seed=700 + rep)
            t_tw = simulate(h, twin=plan.twin, start="twin", **small).wall_time
            t_no = simulate(h, **small).wall_time
            ratios.append(t_tw / t_no)
        row["twin_cost_ratio"] = float(np.median(ratios))
        row["twin_cost_ratios"] = ratios
        if cv.control and row["vrf"]["eta"]:
            row["net_speedup"] = row["vrf"]["eta"] / row["twin_cost_ratio"]
        # time to 1e-4, interleaved: with, without
        row["to_1e-4_control"] = _time_to_target(h, True, budget, 800 + i)
        row["to_1e-4_plain"] = _time_to_target(h, False, budget, 900 + i)
        a, b = row["to_1e-4_control"]["wall_to_target_s"], row["to_1e-4_plain"]["wall_to_target_s"]
        row["time_ratio_plain_over_control"] = (b / a) if a and b else None
        out[name] = row
    return out


# -- martingale control variates -------------------------------------------------------------------

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
    plan = MonteCarlo(seed=seed, tol=CV_TARGET).plan(h)
    reps, paths = (48, 2) if quick else (64, 2)
    t_run = 200.0 if quick else 400.0
    kw = dict(dt=plan.dt, paths=paths, replicas=reps, t_burn=plan.t_burn, t_run=t_run, richardson=True,
              seed=seed, twin=plan.twin, start=plan.start)
    row: dict[str, Any] = {"twin_kappa": plan.twin, "dt": plan.dt, "t_burn": plan.t_burn, "t_run": t_run,
                           "replicas": reps, "paths": paths}
    with_mg = simulate(h, martingale=True, **kw)
    without = simulate(h, martingale=False, **kw)
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


def run_martingale(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """Only this section (:func:`martingale_rows`, :func:`martingale_coverage`); writes
    ``bench_montecarlo_martingale.json`` into ``out`` when given."""
    import json

    t0 = time.perf_counter()
    res = {"quick": quick, "threads": default_threads(), "rows": martingale_rows(quick),
           "coverage": martingale_coverage(quick)}
    res["wall_s"] = time.perf_counter() - t0
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / "bench_montecarlo_martingale.json").write_text(json.dumps(res, indent=1))
    return res


# -- time-step policy: Richardson extrapolation against halving dt ------------------------------

#: Independent reference for eta of the ring n = 3, N = 3, a = 0.5, k = -0.5: the old policy
#: (fine level reported, its Richardson bias in quadrature) at a fixed dt = 0.01 (levels 0.005,
#: 0.01), tol = 1e-4, seed 777001, with (value, error, CPU seconds). A second one with the
#: extrapolation at a fixed dt = 0.02 (levels 0.01, 0.02, 0.04), seed 777002: 0.5504542 +- 5.2e-5
#: (89 CPU-s), 0.7 combined errors above it.
RING_REFERENCE = (0.5504025545113229, 4.873396667290318e-05, 154.7)

#: Fokker--Planck values (validation/data/reference_values.json: tol 1e-7 for n = 3, 1e-5
#: requested and 1.3e-5 reached for n = 1.5), with their errors.
_FPE_REFERENCE = {3.0: (0.4840014710439786, 2.4203158585381594e-08),
                  1.5: (0.5479634094655252, 7.312264433032261e-06)}

_POLICY_CASES = (("ring n3 N3 k-0.5", 3.0, 3, -0.5), ("n3 N1", 3.0, 1, 0.0), ("n1.5 N1", 1.5, 1, 0.0))


def _policy_solve(h: Harvester, extrapolate: bool, tol: float, seed: int) -> dict[str, Any]:
    c0, t0 = time.process_time(), time.perf_counter()
    r = solve(h, MonteCarlo(seed=seed, tol=tol, extrapolate=extrapolate, progress=False, max_time=900.0))
    i = r.info
    return {"eta": r.eta, "eta_err": r.eta_err, "status": r.status.value, "cpu_s": time.process_time() - c0,
            "wall_s": time.perf_counter() - t0, "dt": i["dt"], "dt_coarsest": i["dt_coarsest"],
            "restarts": i["plan_notes"].get("restarts"), "replicas": i["replicas"], "paths": i["paths"],
            "t_run": i["t_run"], "se": i["eta_standard_error"], "bias": i["bias_eta"],
            "residual": i["residual_eta"], "residual_se": i["residual_eta_se"],
            "vrf": i["variance_reduction"], "controls": i["control_set"]}


def policy_rows(quick: bool) -> dict[str, Any]:
    """CPU and wall seconds of the solver to tol = 1e-4 (quick: 1e-3) with ``extrapolate=True``
    (default) and ``False`` (halve dt and restart), for the cases of :data:`_POLICY_CASES`, the two
    policies alternating in one run (one solve each: the halving policy takes minutes)."""
    tol = 1e-3 if quick else 1e-4
    out: dict[str, Any] = {"tol": tol}
    for i, (name, n, N, k) in enumerate(_POLICY_CASES):
        h = Harvester.build(a=0.5, n=n, N=N, k=k)
        row = {pol: _policy_solve(h, pol == "extrapolate", tol, 8100 + i) for pol in ("extrapolate", "halve")}
        row["cpu_ratio_halve_over_extrapolate"] = row["halve"]["cpu_s"] / row["extrapolate"]["cpu_s"]
        out[name] = row
    return out


def policy_coverage(quick: bool, seeds: int | None = None) -> dict[str, Any]:
    """Coverage at tol = 1e-3 of both policies' error bars over ``seeds`` seeds (default 20,
    quick 4) against independent references (:data:`_FPE_REFERENCE`, :data:`RING_REFERENCE`):
    z = (eta - reference) / hypot(eta_err, reference error), and the CPU seconds per solve."""
    seeds = seeds or (4 if quick else 20)
    out: dict[str, Any] = {"tol": 1e-3, "seeds": seeds, "nominal": {"within_1": 0.683, "within_2": 0.954}}
    for name, n, N, k in _POLICY_CASES:
        h = Harvester.build(a=0.5, n=n, N=N, k=k)
        ref, ref_err = _FPE_REFERENCE[n] if N == 1 else RING_REFERENCE[:2]
        row: dict[str, Any] = {"reference": ref, "reference_err": ref_err}
        for pol in ("extrapolate", "halve"):
            runs = [_policy_solve(h, pol == "extrapolate", 1e-3, 9000 + s) for s in range(seeds)]
            z = np.array([(r["eta"] - ref) / math.hypot(r["eta_err"], ref_err) for r in runs])
            a = np.abs(z)
            row[pol] = {"within_1": float((a < 1).mean()), "within_2": float((a < 2).mean()),
                        "max_abs_z": float(a.max()), "mean_z": float(z.mean()),
                        "median_cpu_s": float(np.median([r["cpu_s"] for r in runs])),
                        "median_wall_s": float(np.median([r["wall_s"] for r in runs])),
                        "dts": sorted({r["dt"] for r in runs}), "z": [round(float(v), 3) for v in z]}
        out[name] = row
    return out


def run_policy(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """Only this section (:func:`policy_rows`, :func:`policy_coverage`); writes
    ``bench_montecarlo_policy.json`` into ``out`` when given."""
    import json

    t0 = time.perf_counter()
    res = {"quick": quick, "threads": default_threads(), "rows": policy_rows(quick),
           "coverage": policy_coverage(quick), "boundary": boundary_rows(quick)}
    res["wall_s"] = time.perf_counter() - t0
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / "bench_montecarlo_policy.json").write_text(json.dumps(res, indent=1))
    return res


def boundary_rows(quick: bool) -> dict[str, Any]:
    """Variance reduction of eta with each control set of :data:`montecarlo.controls.CONTROL_SETS`
    (the end-of-window terms with and without the twin among them) on one ensemble per case and
    t_run: ring n = 3, N = 3, k = -0.5, harmonic ring N = 3, k = -0.2, single n = 3 (a = 0.5); 300
    replicas of 2 paths (quick: 120), the solver's plan for tol = 1e-4 otherwise, t_run = 100 and
    400; with each set's eta and standard error, and the CPU seconds of the ensemble."""
    from montecarlo.controls import CONTROL_SETS

    reps = 120 if quick else 300
    out: dict[str, Any] = {"replicas": reps, "paths": 2}
    cases = (("ring n3 N3 k-0.5", Harvester.build(a=0.5, n=3.0, N=3, k=-0.5)),
             ("harmonic ring N3 k-0.2", Harvester.build(a=0.5, N=3, k=-0.2)),
             ("n3 N1", Harvester.build(a=0.5, n=3.0)))
    for name, h in cases:
        plan = MonteCarlo(seed=3, tol=1e-4, progress=False).plan(h)
        for t_run in ((100.0,) if quick else (100.0, 400.0)):
            c0 = time.process_time()
            e = simulate(h, dt=plan.dt, paths=2, replicas=reps, t_burn=plan.t_burn, t_run=t_run, seed=21,
                         twin=plan.twin, start=plan.start, richardson=True, third_level=True, martingale=True)
            row: dict[str, Any] = {"cpu_s": time.process_time() - c0, "dt": plan.dt, "t_burn": plan.t_burn}
            plain = estimate(e, h, control=False)
            for cs in CONTROL_SETS:
                try:
                    est = estimate(e, h, controls=cs)
                except ParameterError as exc:
                    row[cs] = {"note": str(exc).split(";")[0]}
                    continue
                row[cs] = {"vrf_eta": (plain.se["eta"] / est.se["eta"]) ** 2, "eta": est.mean["eta"],
                           "se": est.se["eta"]}
            out[f"{name} t_run {t_run:g}"] = row
    return out


def martingale_coverage(quick: bool) -> dict[str, Any]:
    """Coverage of the martingale error bars against independent references over seeds: the
    harmonic pair (N = 2, k = -0.2, a = 0.5) against its exact discrete value (twin_expectations,
    frozen step dt = 0.1), and the single n = 3 unit (a = 0.5) against the Fokker--Planck solver
    (extrapolated value mean - bias against hypot(se, bias_se), and the solver's own error
    hypot(se, bias) around the fine level)."""
    from montecarlo.controls.twin import twin_expectations

    seeds = 24 if quick else 100
    h2 = Harvester.build(a=0.5, N=2, k=-0.2)
    ex = twin_expectations(h2, 0.1)
    eta2 = ex["V2"] / ex["vxi"]
    z2 = []
    for s in range(seeds):
        e = simulate(h2, dt=0.1, paths=2, replicas=48, t_burn=20.0, t_run=100.0, seed=5000 + s, start="twin",
                     martingale=True)
        est = estimate(e, h2, controls="martingale")
        z2.append((est.mean["eta"] - eta2) / est.se["eta"])
    h3 = Harvester.build(a=0.5, n=3)
    ref = solve(h3, "fpe", tol=1e-6)
    plan = MonteCarlo(seed=1, tol=1e-3).plan(h3)
    z3, z3_solver, vrf = [], [], []
    for s in range(seeds):
        e = simulate(h3, dt=plan.dt, paths=4, replicas=64, t_burn=plan.t_burn, t_run=200.0, seed=6000 + s,
                     twin=plan.twin, start="twin", richardson=True, martingale=True)
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


def _kink_dt_study(quick: bool) -> dict[str, Any]:
    """Kink n = 1: the time-step law per a (:mod:`validation.kinkstudy`: independent seeds per
    dt, coupled differences, both fits), the old rule (units held at rest) against the default
    (averaged swings) on the same noise, and the scheme against the independent reference
    (:mod:`validation.kinkref`) on common noise."""
    from montecarlo.estimate import BIAS_ORDER
    from validation.kinkref import reference_run, summarize
    from validation.kinkstudy import rule_comparison, sweep

    out: dict[str, Any] = {"bias_order_used": BIAS_ORDER["nonsmooth"],
                           "law": "eta(dt) = eta0 + c dt^p; Richardson bias (coarse - fine) / (2^p - 1)"}
    plans = {0.5: ((0.08, 0.04), 3e-4, 10.0)} if quick else {
        0.5: ((0.08, 0.04, 0.02, 0.01), 1e-4, 90.0), 1.0: ((0.08, 0.04, 0.02, 0.01), 1e-4, 90.0),
        2.0: ((0.08, 0.04, 0.02, 0.01), 2e-3, 120.0)}
    for i, (a, (dts, target, budget)) in enumerate(plans.items()):
        out[f"a{a:g}"] = sweep(a, dts, seed=3000 + 100 * i, target=target, budget=budget)
    out["rules_a2"] = rule_comparison(2.0, (0.02,) if quick else (0.04, 0.02, 0.01, 0.005),
                                      replicas=4 if quick else 16, repeats=1 if quick else 3, seed=3500)
    if not quick:
        out["reference"] = {}
        for a in (0.5, 2.0):
            run = reference_run(a, delta=1e-3, schemes=((40, "average"), (20, "average"), (10, "average"),
                                                        (20, "hold")), replicas=64, seed=3600)
            out["reference"][f"a{a:g}"] = {**summarize(run), "wall_s": run["wall_s"], "delta": run["delta"],
                                          "w_min": run["w_min"], "replicas": run["replicas"]}
    return out


def series(quick: bool, res: dict[str, Any]) -> list[dict[str, Any]]:
    """Error-versus-time curves for the combined figure (:mod:`.combined`): the solver at a
    few tolerances with and without control variates, for the kink (n = 1, a = 0.5) and the
    n = 3 ring; references from this run's most precise values (the kink's time-step study at
    dt = 0.02/0.01 with its bias estimate, the ring's run at 1e-4)."""
    cases = {"n1_single": (dict(a=0.5, n=1.0), None), "n3_ring": (dict(a=0.5, n=3.0, N=3, k=-0.5), None)}
    kink = res.get("kink_dt", {})
    rows = kink.get("a0.5", {}).get("rows", [])
    if rows:
        best = min(rows, key=lambda r: r["eta_se"])
        bias = best["diff"] / (2.0 ** kink["bias_order_used"] - 1.0)
        rel = math.hypot(best["eta_se"], bias) / best["eta"]
        cases["n1_single"] = (cases["n1_single"][0], (
            best["eta"], rel, f"Monte Carlo, dt = {best['dt']:g}, {best['replicas']} x 64 paths, "
            "bias estimate folded in"))
    ring = res.get("control_variates", {}).get("N3_n3_a0.5_k-0.5", {}).get("to_1e-4_control")
    if ring and ring.get("eta"):
        cases["n3_ring"] = (cases["n3_ring"][0], (
            ring["eta"], ring["rel_err"],
            f"Monte Carlo + control variates, run at tol 1e-4 ({ring['status']})"))
    out = []
    for problem, (kw, ref) in cases.items():
        h = Harvester.build(**kw)
        for control in (False, True):
            pts = []
            for j, tol in enumerate((3e-2, 1e-2) if quick else (1e-2, 3e-3, 1e-3)):
                r = solve(h, "mc", seed=1000 + j, tol=tol, control=control, max_time=60.0, progress=False)
                if r.eta is not None:
                    pts.append({"seconds": r.info["wall_time"], "eta": r.eta,
                                "reported": r.eta_err / abs(r.eta), "tol": tol})
            cur: dict[str, Any] = {"problem": problem, "points": pts,
                                   "method": "Monte Carlo + control variates" if control else "Monte Carlo"}
            if control and ref is not None:
                cur.update(reference_eta=ref[0], reference_err=ref[1], reference=ref[2])
            out.append(cur)
    return out


#: The studies of :func:`run`, in order.
STUDIES = ("rng", "throughput", "equal_error", "bias", "noise_correlation_time", "steep_walls",
           "control_variates", "martingale", "martingale_coverage", "time_step_policy", "end_of_window_terms",
           "time_step_policy_coverage", "kink_dt", "series")
#: The studies the validation report's benchmark section runs (:mod:`.combined`): throughput,
#: error against time, and what its combined figure needs (the kink's time-step study and the
#: ring's run at 1e-4 give the references of the Monte Carlo curves). The design studies (bias
#: against dt, noise correlation time, steep walls, the martingale terms, the time-step policy,
#: 35 s of the quick run's 66 s) run with ``python -m validation.bench.montecarlo [--quick]``.
REPORT_STUDIES = ("rng", "throughput", "equal_error", "control_variates", "kink_dt", "series")
#: Keyword arguments the report's benchmark section passes to :func:`run`.
REPORT_KW = {"studies": REPORT_STUDIES}


def run(quick: bool = False, out: Path | None = None, studies: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Run the benchmark; returns (and writes, when ``out`` is given) the measurements.

    ``studies``: the subset of :data:`STUDIES` to run (default all); the others are listed as not run.
    """
    chosen = STUDIES if studies is None else tuple(studies)
    unknown = set(chosen) - set(STUDIES)
    if unknown:
        raise ValueError(f"studies must be among {STUDIES}, got {sorted(unknown)}")
    threads = default_threads()
    res: dict[str, Any] = {"quick": quick, "threads": threads, "target_path_steps_per_s": 1e8,
                           "target_speedup_vs_numpy_em": 10.0}
    t_run = 10.0 if quick else 50.0
    steps: dict[str, Any] = {
        "rng": lambda: _rng_costs(2**22 if quick else 2**25, threads),
        "throughput": lambda: {
            "N1_harmonic": _rate(Harvester.build(a=0.5), 0.01, 256, 4, t_run),
            "N1_kink_n1_a0.5": _rate(Harvester.build(a=0.5, n=1), 0.01, 256, 4, t_run),
            "N3_harmonic_k-0.2": _rate(Harvester.build(a=0.5, N=3, k=-0.2), 0.01, 256, 4, t_run),
            "N3_n3_k-0.5": _rate(Harvester.build(a=0.5, n=3, N=3, k=-0.5), 0.01, 256, 4, t_run),
        },
        "equal_error": lambda: _equal_error(quick),
        "bias": lambda: _bias_study(quick),
        "noise_correlation_time": lambda: _tau_study(quick),
        "steep_walls": lambda: _steep_study(quick),
        "control_variates": lambda: _control_variates(quick),
        "martingale": lambda: martingale_rows(quick),
        # the coverage studies take minutes: full mode only (quick runs feed `harvester validate`)
        "martingale_coverage": lambda: martingale_coverage(quick) if not quick else {
            "note": "full mode only; CI smoke test: tests/montecarlo/test_martingale.py"},
        "time_step_policy": lambda: policy_rows(quick),
        "end_of_window_terms": lambda: boundary_rows(quick),
        "time_step_policy_coverage": lambda: policy_coverage(quick) if not quick else {
            "note": "full mode only (~8 min); CI checks: tests/montecarlo/test_extrapolate.py"},
        "kink_dt": lambda: _kink_dt_study(quick),
        "series": lambda: series(quick, res),
    }
    for name in STUDIES:
        key = "rng_ns_per_normal" if name == "rng" else name
        res[key] = steps[name]() if name in chosen else {
            "note": "not run here: python -m validation.bench.montecarlo [--quick] runs every study"}
    save_benchmark(res, out, STEM, _plot)
    return res


def _plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2, ax3, ax4) = plt.subplots(1, 4, figsize=(20, 3.8))
    eq = res["equal_error"]
    if "engine" in eq:  # not run when a subset of the studies was asked for
        curve = eq["engine"]["curve"]
        ax1.loglog([c["wall_s"] for c in curve], [c["rel_se_eta"] for c in curve], "o-", label="engine (se)")
        ax1.loglog([eq["engine"]["wall_to_1e-3_s"]], [TARGET], "*", ms=12,
                   label="engine at 1e-3" + (" (extrapolated)" if eq["engine"]["extrapolated"] else ""))
        em = eq["numpy_em"]
        r = em["runs"]["0.01"]
        ax1.loglog([r["wall_s"]], [math.hypot(r["rel_se"], em["rel_bias_dt_0.01"])], "s",
                   label="numpy EM dt=0.01 (se+bias)")
        ax1.loglog([em["wall_to_equal_error_s"]], [TARGET], "x", ms=10, label="numpy EM at 1e-3 (model)")
        ax1.axhline(abs(em["rel_bias_dt_0.01"]), ls=":", color="gray", label="EM bias floor at dt=0.01")
        ax1.legend(fontsize=7)
    ax1.set_xlabel("wall time [s]")
    ax1.set_ylabel("relative error of eta")
    ax1.set_title("n = 1, a = 0.5, N = 1")
    for name, st in res["bias"].items():
        if not isinstance(st, dict) or "rows" not in st:
            continue
        rows = st["rows"]
        ax2.errorbar([r["dt"] for r in rows], [abs(r["rel_diff"]) for r in rows],
                     yerr=[r["diff_se"] / r["eta_fine"] for r in rows], fmt="o-", capsize=3, label=name)
    dts = np.array([0.01, 0.4])
    ax2.loglog(dts, 0.05 * (dts / 0.4) ** 2, "k--", lw=0.8, label="slope 2")
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("dt")
    ax2.set_ylabel("|eta(dt/2) - eta(dt)| / eta")
    ax2.legend(fontsize=7)
    cvs = {k: v for k, v in res.get("control_variates", {}).items() if isinstance(v, dict) and v.get("vrf")}
    if cvs:
        names = list(cvs)
        y = np.arange(len(names))
        ax3.barh(y - 0.2, [cvs[k]["vrf"]["eta"] or 0.0 for k in names], 0.4, label="variance reduction (eta)")
        ratio = [cvs[k].get("time_ratio_plain_over_control") or 0.0 for k in names]
        ax3.barh(y + 0.2, ratio, 0.4, label="time to 1e-4: plain / control")
        ax3.set_yticks(y, names, fontsize=6)
        ax3.axvline(1.0, color="k", lw=0.8)
        ax3.set_xscale("log")
        ax3.legend(fontsize=7)
        ax3.set_title("control variates (harmonic twin)")
    _plot_kink(res.get("kink_dt", {}), ax4)
    thr = {k: v for k, v in res["throughput"].items() if isinstance(v, dict)}
    fig.suptitle("Monte Carlo: " + ", ".join(f"{k} {v['path_steps_per_s']:.2g}/s" for k, v in thr.items()),
                 fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_kink(kink: dict[str, Any], ax: Any) -> None:
    """|eta(dt) - eta(dt/2)| / eta per a with the fitted order, and the old rule's held fraction."""
    for key, st in kink.items():
        if not key.startswith("a") or "rows" not in st:
            continue
        rows = st["rows"]
        dt = np.array([r["dt_coarse"] for r in rows])
        eta = np.array([r["eta"] for r in rows])
        bars = ax.errorbar(dt, np.abs([r["diff"] for r in rows]) / eta,
                           yerr=np.array([r["diff_se"] for r in rows]) / eta, fmt="o", capsize=3,
                           label=f"a = {st['a']:g}")
        fit = st.get("fit_coupled")
        if fit:
            ax.loglog(dt, abs(fit["c"]) * (1 - 2.0 ** -fit["p"]) * dt ** fit["p"] / eta.mean(), "-", lw=0.8,
                      color=bars[0].get_color(),
                      label=f"  p = {fit['p']:.2f} [{fit['p_lo']:.2f}, {fit['p_hi']:.2f}]")
    rules = kink.get("rules_a2", [])
    if rules:
        ax.loglog([r["dt"] for r in rules], [max(r["stuck_hold"], 1e-7) for r in rules], "k--", marker="x",
                  label="held at rest, old rule (a = 2)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("coarse dt")
    ax.set_ylabel("|eta(dt) - eta(dt/2)| / eta; held fraction")
    ax.set_title(f"kink n = 1 (Richardson uses p = {kink.get('bias_order_used', float('nan')):g})")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=6)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
