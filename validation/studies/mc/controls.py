"""Monte Carlo design study: the harmonic twin as a control variate.

For single units n = 1 to 8 and rings N = 3: the variance-reduction factor of eta, V2 and Pin
on one ensemble, the twin's cost (interleaved timings, median ratio), and the solver's wall time
to a relative error of 1e-4 with and without the controls, measured in the same run within a
budget and, where the budget runs out, extrapolated as ``wall * (se / se_needed)^2``
(labelled).

``python -m validation.studies.mc.controls [--quick] [--out DIR]`` writes ``bench_montecarlo_controls.json`` and
``bench_montecarlo_controls.png``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fpe_harvester import Harvester, solve
from montecarlo import MonteCarlo, estimate, simulate
from fpe_harvester.parallel import default_threads
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "CV_CASES", "QUICK_CV_CASES", "CV_TARGET", "control_variates", "draw", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_controls"

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


def control_variates(quick: bool) -> dict[str, Any]:
    """Variance reduction, twin cost and time to 1e-4 with and without control variates."""
    out: dict[str, Any] = {}
    names = QUICK_CV_CASES if quick else tuple(CV_CASES)
    budget = 4.0 if quick else 60.0
    for i, name in enumerate(names):
        h = Harvester.build(**CV_CASES[name])
        plan = MonteCarlo(seed=500 + i, tol=CV_TARGET, extrapolate=False).plan(h)
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


def draw(res: dict[str, Any], ax: Any) -> None:
    """Variance reduction of eta and the time ratio plain / control to 1e-4, per case."""
    cvs = {k: v for k, v in res.items() if isinstance(v, dict) and v.get("vrf")}
    if cvs:
        names = list(cvs)
        y = np.arange(len(names))
        ax.barh(y - 0.2, [cvs[k]["vrf"]["eta"] or 0.0 for k in names], 0.4, label="variance reduction (eta)")
        ratio = [cvs[k].get("time_ratio_plain_over_control") or 0.0 for k in names]
        ax.barh(y + 0.2, ratio, 0.4, label="time to 1e-4: plain / control")
        ax.set_yticks(y, names, fontsize=6)
        ax.axvline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.legend(fontsize=7)
        ax.set_title("control variates (harmonic twin)")


#: The control-variate study (:func:`control_variates`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(control_variates, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
