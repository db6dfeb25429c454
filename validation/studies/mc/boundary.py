"""Monte Carlo design study: the end-of-window terms of the martingale controls.

Variance reduction of eta with each control set of :data:`montecarlo.controls.CONTROL_SETS`
(the end-of-window terms with and without the twin among them) on one ensemble per case and
t_run (:func:`boundary_rows`).

``python -m validation.studies.mc.boundary [--quick] [--out DIR]`` writes ``bench_montecarlo_boundary.json`` and
``bench_montecarlo_boundary.png``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError
from montecarlo import MonteCarlo, estimate, simulate
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "boundary_rows", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_boundary"


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
        plan = MonteCarlo(seed=3, tol=1e-4, progress=False, extrapolate=False).plan(h)
        for t_run in ((100.0,) if quick else (100.0, 400.0)):
            c0 = time.process_time()
            e = simulate(h, dt=plan.dt, paths=2, replicas=reps, t_burn=plan.t_burn, t_run=t_run, seed=21,
                         twin=plan.twin, start=plan.start, richardson=True, third_level=True,
                         controls=("martingale", "boundary"))
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


def draw(res: dict[str, Any], ax: Any) -> None:
    """Variance reduction of eta per control set, one group of bars per case and t_run."""
    cases = {k: v for k, v in res.items() if isinstance(v, dict)}
    sets = sorted({cs for row in cases.values() for cs, v in row.items() if isinstance(v, dict)})
    y = np.arange(len(cases))
    width = 0.8 / max(len(sets), 1)
    for j, cs in enumerate(sets):
        ax.barh(y + width * (j - (len(sets) - 1) / 2),
                [(row.get(cs, {}).get("vrf_eta") or 0.0) for row in cases.values()], width, label=cs)
    ax.set_yticks(y, list(cases), fontsize=6)
    ax.set_xscale("log")
    ax.set_xlabel("variance reduction of eta")
    ax.legend(fontsize=6)


#: The end-of-window terms (:func:`boundary_rows`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(boundary_rows, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
