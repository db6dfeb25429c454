"""The kink's time-step law: eta(dt) at n = 1 per a, the fitted weak order, the stuck fraction.

A *sweep* runs, for each time step, one ensemble with its own seed (independent of the other
steps) and with Richardson coupling (:func:`montecarlo.simulate` with ``richardson=True``), so
that every run gives two things:

* ``eta`` at its fine step ``dt/2``: independent estimates across the sweep, fitted by
  :func:`fit_weak_order` to :math:`\\eta(dt) = \\eta_0 + c\\,dt^p`;
* the common-noise difference :math:`\\eta(dt) - \\eta(dt/2)` (its error over replicas), fitted
  by :func:`fit_difference_order` to :math:`c(1 - 2^{-p})dt^p`. The coupled levels stay
  correlated at the kink (0.9997 at a = 0.5, 0.98-0.99 at a = 2, measured), so the differences
  are 5-30 times more precise than independent ones at the same cost.

Both fits profile the weight of the data over p (a linear least-squares problem at each p)
and give the interval where chi^2 rises by 1 from its minimum. Each run also records the
fraction of unit-steps a unit is held at rest (``stuck``, the old rule) or advanced by the
averaged swing map (``averaged``), and the kink's event counters.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from montecarlo import estimate, linearized_stiffness, simulate

__all__ = ["fit_weak_order", "fit_difference_order", "pilot_kappa", "sweep_point", "sweep", "fits",
           "rule_comparison", "draw", "main"]

#: Grid of weak orders profiled by the fits.
P_GRID = np.round(np.arange(0.2, 4.0001, 0.01), 2)


def _profile(p_grid: np.ndarray, design, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, list]:
    """chi^2 over p of the weighted linear least squares y ~ design(p) @ beta, and the betas."""
    chi2, betas = [], []
    for p in p_grid:
        X = design(p)
        A = X * w[:, None]
        beta, *_ = np.linalg.lstsq(A, y * w, rcond=None)
        r = (X @ beta - y) * w
        chi2.append(float(r @ r))
        betas.append((beta, np.linalg.inv(A.T @ A)))
    return np.array(chi2), betas


def _interval(p_grid: np.ndarray, chi2: np.ndarray) -> tuple[float, float, float, bool, bool]:
    i = int(np.argmin(chi2))
    inside = chi2 <= chi2[i] + 1.0
    lo, hi = float(p_grid[inside].min()), float(p_grid[inside].max())
    return float(p_grid[i]), lo, hi, bool(lo <= p_grid[0]), bool(hi >= p_grid[-1])


def fit_weak_order(dt, y, se, p_grid: np.ndarray = P_GRID) -> dict[str, Any]:
    """Fit :math:`y(dt) = y_0 + c\\,dt^p` to independent estimates with standard errors ``se``.

    Returns the best p with its chi^2 + 1 interval (``p_lo, p_hi``; ``open_low``/``open_high``
    when it reaches the end of ``p_grid``: p is then not bounded by the data), ``y0`` and its
    error at the best p, the range of ``y0`` over the interval, chi^2 and the degrees of freedom.

    >>> dt = np.array([0.04, 0.02, 0.01, 0.005])
    >>> f = fit_weak_order(dt, 1.0 + 2.0 * dt**1.5, np.full(4, 1e-5))
    >>> abs(f["p"] - 1.5) < 0.02 and abs(f["y0"] - 1.0) < 1e-4
    True
    """
    dt, y, se = (np.asarray(v, dtype=float) for v in (dt, y, se))
    chi2, betas = _profile(p_grid, lambda p: np.column_stack([np.ones_like(dt), dt**p]), y, 1.0 / se)
    p, lo, hi, open_lo, open_hi = _interval(p_grid, chi2)
    i = int(np.argmin(chi2))
    beta, cov = betas[i]
    inside = chi2 <= chi2[i] + 1.0
    y0s = [betas[j][0][0] for j in np.flatnonzero(inside)]
    return {"p": p, "p_lo": lo, "p_hi": hi, "open_low": open_lo, "open_high": open_hi,
            "y0": float(beta[0]), "y0_err": math.sqrt(cov[0, 0]), "c": float(beta[1]),
            "y0_range": [float(min(y0s)), float(max(y0s))], "chi2": float(chi2[i]),
            "dof": int(dt.size - 3)}


def fit_difference_order(dt, d, se, p_grid: np.ndarray = P_GRID) -> dict[str, Any]:
    """Fit coupled differences :math:`d(dt) = y(dt) - y(dt/2) = c(1 - 2^{-p})dt^p`.

    Returns p, its chi^2 + 1 interval, c with its error at the best p, chi^2 and dof.

    >>> dt = np.array([0.08, 0.04, 0.02, 0.01])
    >>> f = fit_difference_order(dt, 3.0 * (1 - 2**-1.2) * dt**1.2, 1e-6 * np.ones(4))
    >>> abs(f["p"] - 1.2) < 0.02
    True
    """
    dt, d, se = (np.asarray(v, dtype=float) for v in (dt, d, se))
    chi2, betas = _profile(p_grid, lambda p: ((1.0 - 2.0**-p) * dt**p)[:, None], d, 1.0 / se)
    p, lo, hi, open_lo, open_hi = _interval(p_grid, chi2)
    beta, cov = betas[int(np.argmin(chi2))]
    return {"p": p, "p_lo": lo, "p_hi": hi, "open_low": open_lo, "open_high": open_hi,
            "c": float(beta[0]), "c_err": math.sqrt(cov[0, 0]), "chi2": float(chi2.min()),
            "dof": int(dt.size - 2)}


def pilot_kappa(h: Harvester, seed: int = 1) -> float:
    """Stiffness of the harmonic twin (control variates) from a short run's <x U'>/<x^2>."""
    m = simulate(h, dt=0.02, paths=16, replicas=4, t_burn=40.0, t_run=100.0, seed=seed).moments(0)
    return float(linearized_stiffness(h, float(m["xdU"].mean()), float(m["x2"].mean())))


def sweep_point(h: Harvester, dt: float, *, seed: int, kappa: float, target: float, budget: float,
                batch: int = 16, paths: int = 64, t_burn: float = 30.0, t_run: float = 100.0,
                **kw: Any) -> dict[str, Any]:
    """One coupled run (coarse ``dt``, fine ``dt/2``), batches until the fine level's relative
    standard error on eta is below ``target`` or ``budget`` seconds are spent."""
    ens = None
    t0 = time.perf_counter()
    while True:
        e = simulate(h, dt=dt, paths=paths, replicas=batch, t_burn=t_burn, t_run=t_run, seed=seed,
                     twin=kappa, start="twin", richardson=True,
                     first_replica=0 if ens is None else ens.replicas, **kw)
        ens = e if ens is None else ens.merge(e)
        est = estimate(ens, h, order=1.0)  # order 1: bias = coarse - fine, the raw difference
        if est.se["eta"] <= target * abs(est.mean["eta"]) or time.perf_counter() - t0 > budget:
            break
    m0, m1 = ens.moments(0), ens.moments(1)
    slow, crossings, averaged, exhausted = ens.kink_counters[:4]
    row = {"dt": dt / 2, "dt_coarse": dt, "replicas": ens.replicas, "paths": paths, "t_run": t_run,
           "eta": est.mean["eta"], "eta_se": est.se["eta"], "V2": est.mean["V2"], "V2_se": est.se["V2"],
           "Pin": est.mean["Pin"], "Pin_se": est.se["Pin"], "diff": est.bias["eta"],
           "diff_se": est.bias_se["eta"],
           "diff_V2": est.bias["V2"], "diff_V2_se": est.bias_se["V2"], "diff_Pin": est.bias["Pin"],
           "diff_Pin_se": est.bias_se["Pin"], "control": est.control, "vrf": est.reduction.get("eta"),
           "stuck": float(np.nanmean(m0["stuck"])), "stuck_coarse": float(np.nanmean(m1["stuck"])),
           "kink_counters": list(ens.kink_counters), "path_steps": ens.path_steps,
           "wall_s": ens.wall_time, "seed": seed}
    row.update(slow=slow, crossings=crossings, averaged=averaged, exhausted=exhausted)
    return row


def sweep(a: float, dts: tuple[float, ...], *, seed: int, target: float, budget: float,
          log=None, **kw: Any) -> dict[str, Any]:
    """:func:`sweep_point` for each coarse step in ``dts`` (seed ``seed + i``), then both fits;
    ``log(a, partial_result)`` after each point."""
    h = Harvester.build(a=a, n=1.0)
    kappa = pilot_kappa(h)
    rows = []
    for i, dt in enumerate(dts):
        rows.append(sweep_point(h, dt, seed=seed + i, kappa=kappa, target=target, budget=budget, **kw))
        if log is not None:
            log(a, {"a": a, "twin_kappa": kappa, "rows": rows})
    return {"a": a, "twin_kappa": kappa, "rows": rows, **fits(rows)}


def fits(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Weak-order fits of a sweep's rows: independent fine levels, and coupled differences."""
    dt = np.array([r["dt"] for r in rows])
    out: dict[str, Any] = {}
    if len(rows) >= 3:
        out["fit_independent"] = fit_weak_order(dt, [r["eta"] for r in rows], [r["eta_se"] for r in rows])
    if len(rows) >= 2:
        out["fit_coupled"] = fit_difference_order([r["dt_coarse"] for r in rows], [r["diff"] for r in rows],
                                                  [r["diff_se"] for r in rows])
    return out


def rule_comparison(a: float, dts: tuple[float, ...], *, replicas: int, seed: int, repeats: int = 3,
                    paths: int = 64, t_burn: float = 30.0, t_run: float = 100.0) -> list[dict[str, Any]]:
    """The kink rules "hold" (old) and "average" (default) on the same noise, per time step.

    For each dt, ``repeats`` rounds of ``replicas`` each, the two rules interleaved (so that a
    load change on a shared machine hits both): the held-at-rest fraction of each, the
    fraction of unit-steps that entered the averaged map, eta(average) - eta(hold) with its
    error over all replicas (paired: same noise), and the wall-time ratio average/hold (median
    over the rounds).
    """
    h = Harvester.build(a=a, n=1.0)
    kappa = pilot_kappa(h)
    out = []
    for dt in dts:
        per: dict[str, list] = {"hold": [], "average": []}
        walls: dict[str, list] = {"hold": [], "average": []}
        counters: dict[str, np.ndarray] = {"hold": np.zeros(4), "average": np.zeros(4)}
        for rep in range(repeats):
            for rule in ("hold", "average"):
                e = simulate(h, dt=dt, paths=paths, replicas=replicas, t_burn=t_burn, t_run=t_run, seed=seed,
                             first_replica=rep * replicas, twin=kappa, start="twin", kink_rule=rule)
                m = e.moments(0)
                per[rule].append(np.column_stack([m["V2"], m["vxi"], m["stuck"]]))
                walls[rule].append(e.wall_time)
                counters[rule] += e.kink_counters
        hold, avg = np.concatenate(per["hold"]), np.concatenate(per["average"])
        d = avg[:, 0] / avg[:, 1] - hold[:, 0] / hold[:, 1]
        ratios = np.array(walls["average"]) / np.array(walls["hold"])
        steps = hold.shape[0] * paths * (t_burn + t_run) / dt  # the counters include the burn-in
        out.append({
            "dt": dt, "replicas": hold.shape[0], "eta_average": float((avg[:, 0] / avg[:, 1]).mean()),
            "eta_average_minus_hold": float(d.mean()), "se": float(d.std(ddof=1) / math.sqrt(d.size)),
            "stuck_hold": float(hold[:, 2].mean()), "stuck_average": float(avg[:, 2].mean()),
            "averaged_entries_per_unit_step": float(counters["average"][2] / steps),
            "hold_budget_exhausted_per_unit_step": float(counters["hold"][3] / steps),
            "crossings_per_unit_step": {r: float(counters[r][1] / steps) for r in counters},
            "wall_s": {r: float(sum(w)) for r, w in walls.items()},
            "cost_ratio_average_over_hold": float(np.median(ratios)), "cost_ratios": ratios.tolist()})
    return out


def draw(kink: dict[str, Any], ax: Any) -> None:
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


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command line: run sweeps for the given a and write them (with the fits) to a JSON file
    (``--out``), drawn next to it (the same name with ``.png``)."""
    import argparse
    import json
    from pathlib import Path

    ap = argparse.ArgumentParser(prog="python -m validation.studies.kink.timestep", description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    ap.add_argument("--dts", type=float, nargs="+", default=[0.08, 0.04, 0.02, 0.01, 0.005],
                    help="coarse steps (the fine level runs at half of each)")
    ap.add_argument("--target", type=float, nargs="+", default=[1e-4],
                    help="relative standard error of eta per point, one value or one per a")
    ap.add_argument("--budget", type=float, nargs="+", default=[300.0],
                    help="seconds per point, one value or one per a")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--label", default="")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    per_a = lambda v, i: v[i] if len(v) > 1 else v[0]
    res: dict[str, Any] = {"label": args.label, "dts_coarse": args.dts, "sweeps": {}}

    def log(a: float, partial: dict[str, Any]) -> None:
        res["sweeps"][f"a{a:g}"] = partial
        args.out.write_text(json.dumps(res, indent=1))
        r = partial["rows"][-1]
        print(f"a={a:g} dt={r['dt']:g} eta={r['eta']:.6f}+-{r['eta_se']:.1e} diff={r['diff']:.2e}+-"
              f"{r['diff_se']:.1e} stuck={r['stuck']:.2e} reps={r['replicas']} wall={r['wall_s']:.0f}s",
              flush=True)

    for i, a in enumerate(args.a):
        res["sweeps"][f"a{a:g}"] = sweep(a, tuple(args.dts), seed=args.seed + 100 * i,
                                         target=per_a(args.target, i), budget=per_a(args.budget, i), log=log)
        args.out.write_text(json.dumps(res, indent=1))
    from validation.studies.cli import axes_plot

    axes_plot(draw)(res["sweeps"], args.out.with_suffix(".png"))
    return res


if __name__ == "__main__":  # pragma: no cover
    main()
