"""Monte Carlo design study: steep walls n = 8, 12, 16, 32 (a = 0.5, single unit).

The solver to 1e-3 against the Fokker--Planck value, the escaped paths (none may escape: the
system is confined), the substeps' cost as path-steps per second against n = 3, and the coupled
time-step difference eta(0.01) - eta(0.02).

``python -m validation.studies.mc.steep [--quick] [--out DIR]`` writes ``bench_montecarlo_steep.json`` and
``bench_montecarlo_steep.png``.
"""

from __future__ import annotations

import math
from typing import Any

from fpe_harvester import Harvester, solve
from validation.studies.cli import bench_main, study_runner
from validation.studies.mc.bias import coupled_diff
from validation.studies.mc.throughput import rate

__all__ = ["STEM", "STEEP_NS", "steep_study", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_steep"

#: Exponents of the steep-wall study (:func:`steep_study`), a = 0.5, single unit.
STEEP_NS = (8.0, 12.0, 16.0, 32.0)

def steep_study(quick: bool) -> dict[str, Any]:
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
    base = rate(Harvester.build(a=0.5, n=3), 0.01, 256, 4, t_run)["path_steps_per_cpu_s"]
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
        rate = rate(h, 0.01, 256, 4, t_run)["path_steps_per_cpu_s"]
        row.update(path_steps_per_cpu_s=rate, cost_ratio_vs_n3=base / rate)
        row["coupled_diff"] = coupled_diff(h, quick, 90 + i)
        out[f"n_{n:g}"] = row
    return out


def draw(res: dict[str, Any], ax: Any) -> None:
    """The substeps' cost against n = 3 and the Monte Carlo - Fokker--Planck difference, per n."""
    rows = sorted((float(k[2:]), v) for k, v in res.items() if k.startswith("n_"))
    ns = [n for n, _ in rows]
    ax.plot(ns, [r["cost_ratio_vs_n3"] for _, r in rows], "o-", label="cost per path-step / n = 3")
    ax.plot(ns, [abs(r.get("mc_minus_fpe_in_combined_errors") or 0.0) for _, r in rows], "s--",
            label="|mc - fpe| / combined error")
    ax.set_xlabel("wall exponent n")
    ax.set_title("steep walls, a = 0.5", fontsize=8)
    ax.legend(fontsize=7)


#: The steep-wall study (:func:`steep_study`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(steep_study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
