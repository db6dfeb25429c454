"""Monte Carlo design study: the kink's (n = 1) time-step law.

At a = 0.5, 1, 2, eta at fine steps 0.04 ... 0.005 from runs with independent seeds, each
Richardson-coupled, and the weak order p of eta(dt) = eta0 + c dt^p fitted to the independent
values and to the coupled differences (with chi^2 + 1 intervals), beside the order the solver's
Richardson bias uses (:mod:`validation.studies.kink.timestep`); the old rule (units held at rest
once 64 crossings fit in a step) against the default (averaged swings) at a = 2 on the same
noise: held fraction per dt, eta difference, cost ratio; and the scheme minus the independent
reference of :mod:`validation.studies.kink.reference` on common noise.

``python -m validation.studies.mc.kink_dt [--quick] [--out DIR]`` writes ``bench_montecarlo_kink_dt.json`` and
``bench_montecarlo_kink_dt.png``.
"""

from __future__ import annotations

from typing import Any

from validation.studies.cli import bench_main, study_runner
from validation.studies.kink.reference import reference_run, summarize
from validation.studies.kink.timestep import draw, rule_comparison, sweep

__all__ = ["STEM", "kink_dt_study", "draw", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_kink_dt"


def kink_dt_study(quick: bool) -> dict[str, Any]:
    """Kink n = 1: the time-step law per a (:mod:`validation.studies.kink.timestep`: independent seeds per
    dt, coupled differences, both fits), the old rule (units held at rest) against the default
    (averaged swings) on the same noise, and the scheme against the independent reference
    (:mod:`validation.studies.kink.reference`) on common noise."""
    from montecarlo.estimate import BIAS_ORDER

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


#: The kink's time-step law (:func:`kink_dt_study`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(kink_dt_study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
