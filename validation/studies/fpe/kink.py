"""Benchmark of the kink scheme (n = 1): time to tolerance, reported against actual error,
and the measured convergence in the Hermite degree M, the DG degree p and the layers.

Per a in {0.5, 1, 2} (defaults otherwise), one run:

* the scheme ``xv`` (DG in (x, v) x Hermite in (V, xi)) at tol 1e-3 and 1e-4, against a
  run of the same scheme ten times tighter (1e-5, with its own error where it stops short)
  and against Monte Carlo (a fresh run at 3e-3, and the long runs recorded in
  ``validation/references/data/kink_mc_reference_values.json`` for a = 0.5 and 1), with the ratio of reported to actual error;
* the previous scheme ``x`` (DG in x x Hermite in (v, V, xi)) at 1e-3 in the same run;
* fixed levels: eta against M (p = 3), against p (M = 8) and against the number of layers
  (M = 8, p = 3), and the energy of the Hermite coefficients per degree along the drive F
  (:math:`\\beta_1`) and across it (:math:`\\beta_2`), in the core box of the trap and
  outside it. This is the measurement of where the accuracy is lost;
* the concentration of the law of V at V = 0 from Monte Carlo states
  (:func:`validation.comparisons.kinkdensity.v_concentration`): at a = 2 it is a spike,
  :math:`P(|V| < \\delta\\,\\mathrm{sd}) \\sim \\delta^{0.3}`, which the Hermite series in V cannot
  follow.

``python -m validation.studies.fpe.kink [--quick] [--out DIR]`` runs it and writes
``bench_kink.json`` and ``bench_kink.png``; ``python -m validation.studies.fpe.bench`` includes it.
"""

from __future__ import annotations

import math
import pathlib
import time
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from fpe_harvester.fpe import stationary
from fpe_harvester.fpe.schemes.xv.kinkdisc import KinkDG, KinkSettings
from validation.studies.cli import bench_main, save_benchmark
from validation.comparisons.kinkdensity import v_concentration
from validation.references.reftable import recorded_kink

__all__ = ["STEM", "TARGETS", "run", "convergence", "table"]

STEM = "bench_kink"

#: Speed targets (s): a <= 1 to 1e-3 and 1e-4, a = 2 to 1e-3.
TARGETS = {(0.5, 1e-3): 10.0, (1.0, 1e-3): 10.0, (0.5, 1e-4): 120.0, (1.0, 1e-4): 120.0, (2.0, 1e-3): 60.0}


def _run(h: Harvester, tol: float, max_seconds: float, scheme: str = "auto") -> dict[str, Any]:
    t0 = time.perf_counter()
    sol = stationary(h, tol=tol, max_seconds=max_seconds, grid=3, scheme=scheme)
    s = sol.stats
    return {"tol": tol, "scheme": s.info.get("scheme", scheme), "seconds": time.perf_counter() - t0,
            "status": s.status.value, "eta": s.eta, "eta_err": s.eta_err, "V2": s.V2, "V2_err": s.V2_err,
            "Pin": s.Pin, "Pin_err": s.Pin_err, "M": s.info.get("M"), "order": s.info.get("order"),
            "message": s.message}


def _against(r: dict[str, Any], ref: dict[str, Any], label: str) -> dict[str, Any]:
    """Actual error of run ``r`` against a reference with its own error, and whether the
    reported error covers it (up to the reference's error)."""
    if r["eta"] is None or ref.get("eta") is None:
        return {"reference": label, "status": "no number"}
    actual = abs(r["eta"] - ref["eta"])
    return {"reference": label, "actual_err": actual, "reference_err": ref["eta_err"],
            "reported_over_actual": r["eta_err"] / actual if actual > 0 else math.inf,
            "bounds_actual": bool(r["eta_err"] + ref["eta_err"] >= actual)}


def convergence(a: float, quick: bool = False) -> dict[str, Any]:
    """eta at fixed levels: against M, p and layers, and the Hermite energy per direction."""
    h = Harvester.build(a=a, n=1)
    out: dict[str, Any] = {}
    disc = KinkDG.build(h, tol=1e-6)
    Ms = (2, 4, 6) if quick else (2, 4, 6, 8, 10)
    out["M"] = [_level(disc, M, 1) for M in Ms]
    if quick:
        return out
    out["p"] = [_level(disc, 8, s) for s in (1, 2)] + [_level(KinkDG.build(h, KinkSettings(order=2), tol=1e-6), 8, 1)]
    out["layers"] = [_level(KinkDG.build(h, KinkSettings(layers=k), tol=1e-6), 8, 1) for k in (1, 2, 3, 4, 6)]
    out["hermite_energy"] = _energy(disc.solve(10, 1), disc)
    return out


def _level(disc: KinkDG, M: int, size: int) -> dict[str, Any]:
    try:
        lv = disc.solve(M, size)
    except (ArithmeticError, ValueError, RuntimeError) as exc:
        return {"M": M, "p": disc.degree(size), "layers": disc.base.layers, "failed": str(exc)}
    mo = lv.moments
    return {"M": M, "p": lv.order, "layers": lv.mesh.layers, "dofs": lv.dofs, "iterations": lv.iterations,
            "seconds": lv.seconds, "eta": mo["eta"], "V2": mo["V2"], "Pin": mo["Pin"], "v2": mo["v2"],
            "res_V2": mo["res_V2"], "res_power": mo["res_power"]}


def _energy(lv: Any, disc: KinkDG) -> dict[str, list[float]]:
    """Coefficient energy :math:`\\int c_\\beta^2` per degree along F (beta_1) and across
    (beta_2), relative to that of beta = 0, in the core box and outside it."""
    w = np.abs(lv.plane.integrals["1"])
    al = lv.hierarchy.hb.alphas
    xp, vp = lv.plane.X.points(), lv.plane.Vl.points()
    mesh = disc.base
    core = ((xp[:, None] < mesh.Ec / mesh.a) & (np.abs(vp)[None, :] < math.sqrt(2 * mesh.Ec))).ravel()
    out = {}
    for name, sel in (("core", core), ("bulk", ~core)):
        E = (w[sel, None] * lv.coef[sel] ** 2).sum(axis=0)
        E = E / E[0]
        for d in (0, 1):
            out[f"{name}_beta{d + 1}"] = [float(E[al[:, d] == k].sum()) for k in range(lv.M + 1)]
    return out


def _monte_carlo(h: Harvester, rel: float, max_time: float) -> dict[str, Any] | None:
    try:
        from montecarlo import MonteCarlo
    except ImportError:
        return None
    t0 = time.perf_counter()
    r = MonteCarlo(seed=1, tol=rel, max_time=max_time).solve(h)
    return {"seconds": time.perf_counter() - t0, "eta": r.eta, "eta_err": r.eta_err, "status": r.status.value}


def run(quick: bool = False, out: pathlib.Path | None = None) -> dict:
    """Measure the kink scheme (see the module docstring).

    Parameters
    ----------
    quick : bool
        a = 0.5 only, tol 1e-2 and 1e-3 against 1e-4, the convergence in M at M = 2, 4, 6,
        no Monte Carlo (about 20 s).
    out : pathlib.Path, optional
        Directory for ``bench_kink.json`` and ``bench_kink.png``.
    """
    cases: dict[str, Any] = {}
    for a in ((0.5,) if quick else (0.5, 1.0, 2.0)):
        h = Harvester.build(a=a, n=1)
        tols = (1e-2, 1e-3) if quick else ((1e-3, 1e-4) if a <= 1.0 else (1e-2, 1e-3))
        ref_tol = min(tols) / 10
        case: dict[str, Any] = {"a": a, "runs": {}}
        for tol in tols:
            r = _run(h, tol, 600.0)
            target = TARGETS.get((a, tol))
            if target is not None:
                r["time_target_s"], r["time_s"] = target, r["seconds"]
            case["runs"][f"{tol:g}"] = r
        ref = _run(h, ref_tol, 120.0 if quick else 900.0)
        case["reference"] = ref
        if not quick:
            case["previous_scheme"] = _run(h, 1e-3, 300.0, scheme="x")
            case["monte_carlo"] = mc = _monte_carlo(h, 3e-3, 600.0)
        long_mc = None if quick else recorded_kink(a)
        if long_mc is not None:
            case["monte_carlo_reference"] = {k: long_mc[k] for k in ("eta", "eta_err", "V2", "V2_err", "Pin",
                                                                      "Pin_err", "seed", "dt")}
        for r in case["runs"].values():
            r["vs_tighter"] = _against(r, ref, f"scheme xv at tol {ref_tol:g}")
            if not quick and mc is not None and mc.get("eta") is not None:
                r["vs_monte_carlo"] = _against(r, mc, "Monte Carlo at 3e-3")
            if long_mc is not None:
                r["vs_monte_carlo_reference"] = _against(r, long_mc, "long Monte Carlo reference (validation/references/data)")
        case["convergence"] = convergence(a, quick)
        if not quick:
            case["v_concentration"] = v_concentration(h)
        cases[f"a={a:g}"] = case
    result = {"quick": quick, "cases": cases, "summary": _summary(cases)}
    save_benchmark(result, out, STEM, _plot)
    return result


def _summary(cases: dict[str, Any]) -> dict[str, Any]:
    checks = [r[k]["bounds_actual"] for c in cases.values() for r in c["runs"].values()
              for k in ("vs_tighter", "vs_monte_carlo", "vs_monte_carlo_reference")
              if k in r and "bounds_actual" in r[k]]
    return {"reported_bounds_actual": f"{sum(checks)} of {len(checks)}"}


def table(result: dict) -> str:
    """The runs as text."""
    lines = [f"{'case':8} {'tol':>6} {'status':>13} {'time s':>7} {'M':>3} {'p':>2} {'eta':>10} "
             f"{'reported':>9} {'vs tight':>9} {'vs MC':>9}"]
    for name, case in result["cases"].items():
        for key, r in case["runs"].items():
            rel = r["eta_err"] / r["eta"] if r["eta"] else float("nan")
            act = r.get("vs_tighter", {}).get("actual_err", float("nan")) / (r["eta"] or 1.0)
            vs_mc = r.get("vs_monte_carlo_reference") or r.get("vs_monte_carlo", {})
            mc = vs_mc.get("actual_err", float("nan")) / (r["eta"] or 1.0)
            lines.append(f"{name:8} {key:>6} {r['status']:>13} {r['seconds']:7.2f} {r['M'] or 0:3d} "
                         f"{r['order'] or 0:2d} {r['eta'] or float('nan'):10.7f} {rel:9.1e} {act:9.1e} {mc:9.1e}")
    lines.append(f"reported error bounds the actual one: {result['summary']['reported_bounds_actual']}")
    for name, case in result["cases"].items():
        vc = case.get("v_concentration")
        if vc:
            frac = ", ".join(f"{f:.3g}" for f in vc["fraction"])
            lines.append(f"{name}: P(|V| < delta sd(V)) for delta = {vc['delta_sd']}: {frac}; "
                         f"exponents {[round(b, 2) for b in vc['exponent']]} (1 = smooth)")
    return "\n".join(lines)


def _plot(result: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    ax = axes[0]
    for name, case in result["cases"].items():
        pts = [p for p in case["convergence"]["M"] if "eta" in p]
        if len(pts) > 1:
            best = pts[-1]["eta"]
            ax.semilogy([p["M"] for p in pts[:-1]], [abs(p["eta"] - best) / best for p in pts[:-1]], "o-",
                        label=name)
    ax.set_xlabel("Hermite degree M in (V, xi)")
    ax.set_ylabel("|eta(M) - eta(M_max)| / eta")
    ax.set_title("kink scheme: convergence in M (p = 3)", fontsize=9)
    ax.legend(fontsize=8)
    ax = axes[1]
    for name, case in result["cases"].items():
        en = case["convergence"].get("hermite_energy")
        if en:
            for key, style in (("core_beta1", "o-"), ("core_beta2", "s--")):
                ax.semilogy(en[key], style, label=f"{name} {key.replace('_', ' ')}", mfc="none")
    ax.set_xlabel("degree along F (beta1) / across F (beta2)")
    ax.set_ylabel("coefficient energy / that of beta = 0")
    ax.set_title("Hermite coefficients in the trap's core box (M = 10)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    res = bench_main(run, __doc__, drop=("cases",))
    print(table(res))
