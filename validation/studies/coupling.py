"""Study: does coupling help a ring once the cubic bonds k3 make it stable?

eta against k for several k3 at n = 1 and n = 2 (N = 3, a = 0.5, Monte Carlo), the best stable
n = 1 ring over k at each k3 (:func:`fpe_harvester.optimum.optimize`, Monte Carlo with common
random numbers and error bars), the single unit's eta for comparison, and the landscape's fold
and coexistence couplings in the (k, k3) plane.

``python -m validation.studies.coupling [--quick] [--out validation/data]`` writes ``coupling.json``
and ``coupling.png`` (fold and coexistence lines with the optimum on them).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fpe_harvester import Harvester, solve
from fpe_harvester.landscape import coexistence_coupling, fold_coupling
from fpe_harvester.optimum import optimize
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "A", "N", "K3S", "K3_OPT", "curve", "best_ring", "coupling_study", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "coupling"
#: Unit strength and ring size of the study.
A, N = 0.5, 3
#: Cubic couplings of the eta(k) curves.
K3S = (0.01, 0.1, 1.0)
#: Cubic couplings of the optimum search (a first run found the best ring at the smallest k3).
K3_OPT = (0.003, 0.01, 0.03, 0.1, 1.0)


def curve(n: float, k3: float, ks: np.ndarray, tol: float, seed: int) -> list[dict[str, Any]]:
    """eta (and d2) of the ring (n, a = A, N = N, k3) at each k of ``ks`` by Monte Carlo."""
    rows = []
    for i, k in enumerate(ks):
        r = solve(Harvester.build(a=A, n=n, N=N, k=float(k), k3=k3), "mc", seed=seed + i, tol=tol, progress=False)
        rows.append({"k": float(k), "eta": r.eta, "eta_err": r.eta_err, "d2": r.d2, "d2_err": r.d2_err,
                     "status": r.status.value})
    return rows


def best_ring(k3: float, quick: bool) -> dict[str, Any]:
    """The n = 1 ring's best k at fixed k3 over [2 k_co, 0] (k_co the coexistence coupling, near
    which a first run over [-1, 0] found the maxima; Monte Carlo optimizer, common random numbers)."""
    h = Harvester.build(a=A, n=1.0, N=N, k3=k3)
    opt = optimize(h, over="k", bounds=(2.0 * coexistence_coupling(A, k3), 0.0), batches=3 if quick else 4,
                   points=5 if quick else 7, mc_tol=5e-2 if quick else 2e-2, progress=False)
    return {"k3": k3, "k_opt": opt.x_opt, "k_opt_err": opt.x_opt_err, "eta_max": opt.value,
            "eta_max_err": opt.value_err, "status": opt.status.value, "message": opt.message,
            "k_fold": fold_coupling(A, k3), "k_coexistence": coexistence_coupling(A, k3)}


def coupling_study(quick: bool) -> dict[str, Any]:
    """The curves, the optima, the single unit and the landscape lines (module docstring)."""
    tol = 5e-2 if quick else 2e-2
    k3s = K3S[1:2] if quick else K3S
    unit = solve(Harvester.build(a=A, n=1.0), "fpe")
    out: dict[str, Any] = {"a": A, "N": N, "tol": tol, "unit_eta": unit.eta, "unit_eta_err": unit.eta_err,
                           "curves": {}, "optima": []}
    grids = {1: np.linspace(-1.0, 0.0, 3 if quick else 6), 2: np.linspace(-0.6, 0.0, 3 if quick else 5)}
    for n, ks in grids.items():
        for j, k3 in enumerate(k3s):
            out["curves"][f"n{n}_k3_{k3:g}"] = curve(float(n), k3, ks, tol, 100 * n + 10 * j)
    out["optima"] = [best_ring(k3, quick) for k3 in (k3s if quick else K3_OPT)]
    grid = np.geomspace(1e-3, 2.0, 60)
    out["lines"] = {"k3": grid.tolist(), "fold": [fold_coupling(A, g) for g in grid],
                    "coexistence": [coexistence_coupling(A, g) for g in grid]}
    return out


def draw(res: dict[str, Any], ax: Any) -> None:
    """Fold and coexistence couplings against k3, with the optimum k at each k3."""
    lines = res["lines"]
    ax.semilogy(lines["fold"], lines["k3"], label="fold k_sn (buckled states appear)")
    ax.semilogy(lines["coexistence"], lines["k3"], "--", label="coexistence k_co (buckled = origin)")
    for o in res["optima"]:
        if o["k_opt"] is not None:  # open: not converged (e.g. at the search interval's edge)
            ax.errorbar(o["k_opt"], o["k3"], xerr=o["k_opt_err"] or 0.0, fmt="o", color="k",
                        mfc="k" if o["status"] == "stable" else "none")
    ax.set_xlabel("coupling k")
    ax.set_ylabel("cubic coupling k3")
    ax.set_title(f"n = 1, a = {res['a']:g}, N = {res['N']}: optimum k (dots; open: not converged)", fontsize=8)
    ax.legend(fontsize=7)


#: The study (:func:`coupling_study`), written as ``coupling.json`` and ``.png`` into ``out`` when given.
run = study_runner(coupling_study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__, drop=("curves", "lines"))
