"""Monte Carlo design study: cost and bias against the noise's correlation time.

tau = 1e-4, 1e-2, 1, 100 (n = 3, a = 0.5): the solver to 1e-3 against the Fokker--Planck
value, which step ran (joint below tau = 10 dt), and the coupled time-step differences of the
default and the frozen-xi step.

``python -m validation.studies.mc.tau [--quick] [--out DIR]`` writes ``bench_montecarlo_tau.json`` and
``bench_montecarlo_tau.png``.
"""

from __future__ import annotations

import math
from typing import Any

from fpe_harvester import Harvester, solve
from validation.studies.cli import bench_main, study_runner
from validation.studies.mc.bias import coupled_diff

__all__ = ["STEM", "TAUS", "tau_study", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_tau"

#: Correlation times of the noise study (:func:`tau_study`), n = 3, a = 0.5.
TAUS = (1e-4, 1e-2, 1.0, 100.0)

def tau_study(quick: bool) -> dict[str, Any]:
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
            "step": r.info["step"], "bias_eta": r.info["bias_eta"],
            "variance_reduction": r.info["variance_reduction"]}
        if r.eta is not None and fp.eta is not None:
            row["mc_minus_fpe_in_combined_errors"] = (r.eta - fp.eta) / math.hypot(r.eta_err, fp.eta_err)
        row["coupled_diff"] = coupled_diff(h, quick, 60 + i)
        if row["coupled_diff"]["step"] == "joint":
            row["coupled_diff_frozen"] = coupled_diff(h, quick, 60 + i, "frozen")
        out[f"tau_{tau:g}"] = row
    return out


def draw(res: dict[str, Any], ax: Any) -> None:
    """|eta(0.01) - eta(0.02)| / eta against tau, default step and (where joint) frozen-xi step."""
    rows = {float(k[4:]): v for k, v in res.items() if k.startswith("tau_")}
    for key, label in (("coupled_diff", "default step"), ("coupled_diff_frozen", "frozen-xi step")):
        pts = sorted((tau, abs(r[key]["rel_diff"])) for tau, r in rows.items() if key in r)
        if pts:
            ax.loglog(*zip(*pts), "o-", label=label)
    ax.set_xlabel("noise correlation time tau")
    ax.set_ylabel("|eta(0.01) - eta(0.02)| / eta")
    ax.set_title("n = 3, a = 0.5", fontsize=8)
    ax.legend(fontsize=7)


#: The correlation-time study (:func:`tau_study`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(tau_study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
