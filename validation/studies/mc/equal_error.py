"""Monte Carlo design study: cost at equal error against a plain numpy Euler--Maruyama loop.

For n = 1, a = 0.5, N = 1: relative standard error of eta against wall time, the wall time to
reach 1e-3 (run in full mode, extrapolated as ``wall * (err/1e-3)^2`` in quick mode), the
engine's own time-step bias there, and the plain vectorized numpy Euler--Maruyama loop
(:func:`montecarlo.simulate_naive`) measured in the same run: its throughput, its bias at
dt = 0.01 and 0.005 against the engine, and the wall time it would need for the same total
error (bias from the fitted power law, statistics from its measured variance: a model
evaluated with measured inputs, labelled as such).

``python -m validation.studies.mc.equal_error [--quick] [--out DIR]`` writes ``bench_montecarlo_equal_error.json`` and
``bench_montecarlo_equal_error.png``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from montecarlo import estimate, simulate, simulate_naive
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "TARGET", "equal_error", "draw", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_equal_error"

#: Relative error of eta at which the engine and the numpy loop are compared.
TARGET = 1e-3


def _rel_se(values: np.ndarray) -> float:
    return float(values.std(ddof=1) / math.sqrt(values.size) / abs(values.mean()))


def _eta(e: Any) -> np.ndarray:
    m = e.moments(0)
    return m["V2"] / m["vxi"]


def equal_error(quick: bool) -> dict[str, Any]:
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


def draw(eq: dict[str, Any], ax: Any) -> None:
    """The engine's error against wall time, its time to 1e-3, and the numpy loop's (modelled)."""
    if "engine" in eq:  # not run when a subset of the studies was asked for
        curve = eq["engine"]["curve"]
        ax.loglog([c["wall_s"] for c in curve], [c["rel_se_eta"] for c in curve], "o-", label="engine (se)")
        ax.loglog([eq["engine"]["wall_to_1e-3_s"]], [TARGET], "*", ms=12,
                  label="engine at 1e-3" + (" (extrapolated)" if eq["engine"]["extrapolated"] else ""))
        em = eq["numpy_em"]
        r = em["runs"]["0.01"]
        ax.loglog([r["wall_s"]], [math.hypot(r["rel_se"], em["rel_bias_dt_0.01"])], "s",
                  label="numpy EM dt=0.01 (se+bias)")
        ax.loglog([em["wall_to_equal_error_s"]], [TARGET], "x", ms=10, label="numpy EM at 1e-3 (model)")
        ax.axhline(abs(em["rel_bias_dt_0.01"]), ls=":", color="gray", label="EM bias floor at dt=0.01")
        ax.legend(fontsize=7)
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("relative error of eta")
    ax.set_title("n = 1, a = 0.5, N = 1")


#: The engine against the numpy loop at equal error (:func:`equal_error`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(equal_error, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
