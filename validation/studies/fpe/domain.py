"""Fokker--Planck's measured domain: time to a tolerance, or the failure, over n x a.

Over n in {1, 1.1, 1.25, 1.5, 1.75} x a in {0.5, 1, 1.5, 2, 3} (a single unit
:math:`U = a|x|^n`, every other parameter at its default), the solver
(:class:`~fpe_harvester.fpe.FokkerPlanck`, ``scheme="auto"``, ``force=True`` so that it attempts
every point, also those its domain rule declines) runs once at tol 1e-3 and once at 1e-4,
each with a wall-time budget (:data:`BUDGETS`) generous enough that a loaded machine does not
turn a success into a failure, and a memory bound (:data:`MAX_GB`) that leaves room to the
other jobs of a shared machine. Each run records its status, the reason it stopped, the
relative error on eta it reached (its own estimate), the Hermite degree M and the unknowns of
its last level, the wall time and the process CPU time, and the load average around it.

Where an independent reference exists (Monte Carlo: ``reference_values.json`` and
``kink_mc_reference_values.json`` under ``validation/references/data``) a converged run is
checked against it: correct if :math:`|\\eta - \\eta_{ref}| \\le e + 2 e_{ref}` (e the run's
reported error, :math:`e_{ref}` the reference's standard error). A Fokker--Planck reference
(the same solver at a tighter tolerance) is a convergence check, not a correctness check, and
is labelled so; it counts as agreeing if :math:`|\\eta - \\eta_{ref}| \\le e + e_{ref}`.

Off the defaults (:func:`off_defaults`, ``--off-defaults``): spot checks with one quantity
changed at a time, on the boundary of the hardest band at the defaults (does the trap strength
alone carry the rule off the defaults? It does not: gamma = 0.5 and K_v = 2 fail there) and on
the rule's limit off the defaults (which ranges converge there), plus weak potentials below
the map; they are added to the recorded JSON as ``off_defaults``.

``python -m validation.studies.fpe.domain [--quick] [--out DIR]`` runs the map (30 minutes on
two loaded cores; a run already written to the folder's partial file is not run again when
the study is restarted into it) and writes ``fpe_domain.json`` and ``fpe_domain.png`` (the map,
one panel per tolerance, with the cells the domain rule of :mod:`fpe_harvester.fpe.domain`
declines outlined); ``--off-defaults`` then adds the spot checks (about 40 minutes).
``--replot`` redraws the figure and prints the tables of the recorded JSON and how the rule
sorts its runs, without solving anything.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path
from typing import Any

from fpe_harvester import Harvester
from fpe_harvester.fpe import FokkerPlanck
from validation.references import reftable
from validation.studies.cli import DATA

__all__ = ["STEM", "NS", "AS", "TOLS", "BUDGETS", "MAX_GB", "COMMAND", "BOUNDARY_CHANGES", "LIMIT_CHANGES",
           "WEAK", "run", "off_defaults", "one", "references", "check", "strength_at", "agreement", "table",
           "off_table", "plot"]

STEM = "fpe_domain"

#: The map's axes: the exponent n and the strength a of :math:`U = a|x|^n`.
NS = (1.0, 1.1, 1.25, 1.5, 1.75)
AS = (0.5, 1.0, 1.5, 2.0, 3.0)

#: Tolerances on eta, loosest first (the whole map at the first before the second).
TOLS = (1e-3, 1e-4)

#: Wall-time budget (s) of one run per tolerance: about 5-10 times the slowest success
#: measured on a quiet machine at that tolerance (the kink at a = 1 reaches 1e-4 in about
#: 170 s there).
BUDGETS = {1e-3: 900.0, 1e-4: 1800.0}

#: Memory bound (GB) of one level: a quarter of this machine's memory, shared with other jobs.
MAX_GB = 6.0

#: The quick subset: (n, a, tol, budget).
QUICK = ((1.75, 0.5, 1e-3, 60.0), (1.0, 2.0, 1e-3, 15.0))

COMMAND = "python -m validation.studies.fpe.domain --out validation/data"

#: Spot checks off the defaults (:func:`off_defaults`), one parameter changed at a time.
#: First on the boundary of the hardest band at the defaults (n = 1, tol 1e-3, a chosen so
#: that the trap strength s of :mod:`fpe_harvester.fpe.domain` equals the band's limit): does
#: s alone carry the rule off the defaults?
BOUNDARY_CHANGES = ({"tau": 0.5}, {"tau": 2.0}, {"tau_p": 1.0}, {"tau_p": 4.0}, {"gamma": 0.5},
                    {"gamma": 2.0}, {"Kv": 2.0}, {"m": 2.0}, {"D": 2.0})
BOUNDARY_TOL = 1e-3

#: Then on the rule's limit off the defaults (s of a = 0.5 at the defaults, every band) at
#: tol 1e-4, with wider changes, at n = 1 and at n = 1.5 (where sigma sqrt(D) also counts).
LIMIT_CHANGES = ((1.0, {"gamma": 0.25}), (1.0, {"gamma": 0.5}), (1.0, {"gamma": 4.0}), (1.0, {"tau": 0.25}),
                 (1.0, {"tau": 4.0}), (1.0, {"tau_p": 0.5}), (1.0, {"tau_p": 8.0}), (1.0, {"m": 0.5}),
                 (1.0, {"m": 2.0}), (1.0, {"Kv": 2.0, "Kc": 2.0}), (1.5, {"gamma": 0.25}),
                 (1.5, {"tau_p": 8.0}), (1.5, {"sigma": 2.0}), (1.0, {"gamma": 0.75}), (1.0, {"Kv": 0.5}),
                 (1.0, {"Kv": 2.0}), (1.5, {"sigma": 0.5}))
LIMIT_TOL = 1e-4

#: Budget (s) of the spot checks, and weak potentials below the map (a = 0.25, defaults).
OFF_BUDGET = 1800.0
WEAK = ((1.0, 0.25), (1.5, 0.25))

RECORDED = DATA / f"{STEM}.json"


def _stop(message: str, converged: bool) -> str:
    """The reason a run stopped, in one word (from its message)."""
    if converged:
        return "converged"
    for key, word in (("time budget", "budget"), ("memory", "memory"), ("max_M", "max_M"),
                      ("unphysical", "unphysical"), ("failed", "failed"), ("exceed", "limit")):
        if key in message:
            return word
    return "other"


def one(n: float, a: float, tol: float, budget: float, **params: float) -> dict[str, Any]:
    """One forced Fokker--Planck run at (n, a) (``params`` changed from the defaults) to ``tol``
    within ``budget`` seconds of wall time."""
    h = Harvester.build(a=a, n=n, **params)
    solver = FokkerPlanck(tol=tol, max_seconds=budget, max_gb=MAX_GB, force=True)
    load0 = os.getloadavg()[0]
    w0, c0 = time.perf_counter(), time.process_time()
    r = solver.solve(h)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    history = r.info.get("history", [])
    top = max(history, key=lambda lv: (lv["M"], lv["dofs"]), default={})
    converged = r.status.value == "stable"
    reached = r.eta_err / abs(r.eta) if r.eta is not None and r.eta_err is not None and r.eta else None
    return {"n": n, "a": a, "params": params, "tol": tol, "budget": budget, "status": r.status.value,
            "stop": _stop(r.message, converged), "message": r.message, "eta": r.eta, "eta_err": r.eta_err,
            "error_reached": reached, "scheme": r.info.get("scheme"), "M": r.info.get("M"),
            "dofs": r.info.get("dofs"), "M_max": top.get("M"), "dofs_max": top.get("dofs"),
            "levels": len(history), "wall": wall, "cpu": cpu, "load": [load0, os.getloadavg()[0]]}


def references() -> dict[tuple[float, float], list[dict[str, Any]]]:
    """Recorded references of single units at the defaults, by (n, a): eta, its error, the
    method and whether it is independent of Fokker--Planck (Monte Carlo) or not."""
    refs: dict[tuple[float, float], list[dict[str, Any]]] = {}
    table = json.loads(reftable.PATH.read_text())
    for label, e in table.items():
        if set(e["system"]) != {"a", "n"} or e.get("eta") is None:
            continue
        refs.setdefault((float(e["system"]["n"]), float(e["system"]["a"])), []).append(
            {"label": label, "eta": e["eta"], "eta_err": e["eta_err"], "status": e["status"],
             "independent": e["method"] != "fpe"})
    for key, e in json.loads(reftable.KINK_PATH.read_text()).items():
        refs.setdefault((1.0, float(key[1:])), []).append(
            {"label": f"kink mc {key}", "eta": e["eta"], "eta_err": e["eta_err"], "status": e["status"],
             "independent": True})
    return refs


def check(row: dict[str, Any], refs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The run ``row`` against each reference of its point (see the module docstring)."""
    out = []
    if row["eta"] is None:
        return out
    for ref in refs:
        actual = abs(row["eta"] - ref["eta"])
        bar = row["eta_err"] + (2.0 if ref["independent"] else 1.0) * ref["eta_err"]
        out.append({"reference": ref["label"], "independent": ref["independent"],
                    "reference_status": ref["status"],
                    "actual": actual, "reported": row["eta_err"], "reference_err": ref["eta_err"],
                    "within": bool(actual <= bar)})
    return out


def _load(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text()) if path.exists() else {}


def _runs(cases: tuple[tuple[Any, ...], ...], partial: Path | None) -> list[dict[str, Any]]:
    """Run ``cases`` ((n, a, tol, budget, params) each), checking converged runs against the
    references; each finished run goes at once into ``partial`` (a restart takes the runs
    found there)."""
    done = {} if partial is None else _load(partial)
    refs = references()
    for n, a, tol, budget, params in cases:
        key = f"n={n:g} a={a:.6g} tol={tol:g}" + "".join(f" {k}={v:g}" for k, v in params.items())
        if key in done:
            continue
        row = one(n, a, tol, budget, **params)
        at_defaults = refs.get((n, a), []) if not params else []
        row["checks"] = check(row, at_defaults) if row["status"] == "stable" else []
        done[key] = row
        print(f"{key}: {row['status']} ({row['stop']}) err {row['error_reached']} M {row['M_max']} "
              f"dofs {row['dofs_max']} {row['wall']:.1f} s wall {row['cpu']:.1f} s cpu", flush=True)
        if partial is not None:
            partial.parent.mkdir(parents=True, exist_ok=True)
            partial.write_text(json.dumps(done, indent=1))
    return list(done.values())


def run(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """Run the map (or the quick subset) and write ``fpe_domain.json`` and ``.png`` into ``out``
    (the spot checks off the defaults: :func:`off_defaults`)."""
    cases = (tuple((n, a, tol, b, {}) for n, a, tol, b in QUICK) if quick
             else tuple((n, a, tol, BUDGETS[tol], {}) for tol in TOLS for a in AS for n in NS))
    partial = None if out is None else Path(out) / f"{STEM}{'.quick' if quick else ''}.partial.json"
    t0 = time.perf_counter()
    runs = _runs(cases, partial)
    res = {"quick": quick, "command": COMMAND, "ns": list(NS), "as": list(AS), "tols": list(TOLS),
           "budgets": {f"{t:g}": b for t, b in BUDGETS.items()}, "max_gb": MAX_GB,
           "seconds": time.perf_counter() - t0, "runs": runs}
    if out is not None:
        Path(out, f"{STEM}.json").write_text(json.dumps(res, indent=1))
        plot(res, Path(out, f"{STEM}.png"))
        if partial is not None:
            partial.unlink()
    return res


def strength_at(target: float, n: float, **params: float) -> float:
    """The a at which the trap strength of :mod:`fpe_harvester.fpe.domain` is ``target``."""
    from scipy.optimize import brentq

    from fpe_harvester.fpe.domain import trap_strength

    return float(brentq(lambda a: trap_strength(Harvester.build(a=a, n=n, **params)) - target, 1e-2, 50.0,
                        xtol=1e-10))


def off_defaults(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """Spot checks of the rule off the defaults, added to the recorded ``fpe_domain.json`` in ``out``.

    :data:`BOUNDARY_CHANGES` at n = 1 with a on the band's boundary at :data:`BOUNDARY_TOL`,
    :data:`LIMIT_CHANGES` with a on the rule's limit off the defaults at :data:`LIMIT_TOL`
    (the rule lets it in: it should converge), and the weak potentials :data:`WEAK` at the
    defaults; forced runs as in the map, budget :data:`OFF_BUDGET`.
    """
    from fpe_harvester.fpe.domain import strength_limit

    boundary = BOUNDARY_CHANGES[:1] if quick else BOUNDARY_CHANGES
    cases = tuple((1.0, strength_at(strength_limit(1.0, BOUNDARY_TOL), 1.0, **c), BOUNDARY_TOL, OFF_BUDGET, c)
                  for c in boundary)
    if not quick:
        cases += tuple((n, strength_at(strength_limit(n, LIMIT_TOL, defaults=False), n, **c), LIMIT_TOL,
                        OFF_BUDGET, c) for n, c in LIMIT_CHANGES)
        cases += tuple((n, a, LIMIT_TOL, OFF_BUDGET, {}) for n, a in WEAK)
    partial = None if out is None else Path(out) / f"{STEM}.off{'.quick' if quick else ''}.partial.json"
    runs = _runs(cases, partial)
    for row in runs:
        row["strength"] = _strength(row)
    res = _load(Path(out, f"{STEM}.json")) if out is not None else {}
    res["off_defaults"] = {"runs": runs, "command": COMMAND + " --off-defaults"}
    if out is not None:
        Path(out, f"{STEM}.json").write_text(json.dumps(res, indent=1))
        if partial is not None:
            partial.unlink()
    return res


def _strength(row: dict[str, Any]) -> float:
    from fpe_harvester.fpe.domain import trap_strength

    return trap_strength(Harvester.build(a=row["a"], n=row["n"], **row.get("params", {})))


def _cell(row: dict[str, Any]) -> str:
    if row["status"] == "stable":
        return f"{row['wall']:.0f} s" if row["wall"] >= 10 else f"{row['wall']:.1f} s"
    err = "no number" if row["error_reached"] is None else f"{row['error_reached']:.1g}"
    return f"fails: {row['stop']}, {err}, {row['wall']:.0f} s"


def table(res: dict[str, Any]) -> str:
    """The map as Markdown: one table per tolerance, n down, a across; a cell is the wall
    time to converge or how the run failed (its reason, the relative error it reached, its time)."""
    lines = []
    runs = {(r["n"], r["a"], r["tol"]): r for r in res["runs"]}
    for tol in res["tols"]:
        budgets = sorted({r["budget"] for r in res["runs"] if r["tol"] == tol})
        if not budgets:
            continue
        lines += [f"tol = {tol:g} (budget {', '.join(f'{b:.0f}' for b in budgets)} s)", "",
                  "| n \\ a | " + " | ".join(f"{a:g}" for a in res["as"]) + " |",
                  "|---" * (len(res["as"]) + 1) + "|"]
        for n in res["ns"]:
            cells = [_cell(runs[(n, a, tol)]) if (n, a, tol) in runs else "" for a in res["as"]]
            lines.append(f"| {n:g} | " + " | ".join(cells) + " |")
        lines.append("")
    lines.append(_verdicts(res["runs"]))
    return "\n".join(lines) + "\n"


def agreement(runs: list[dict[str, Any]]) -> dict[str, int]:
    """How the domain rule of :mod:`fpe_harvester.fpe.domain` sorts ``runs``: inside and
    converged, outside and failed, inside but failed (a miss of the rule: must be none) and
    outside but converged (the price of its margin)."""
    from fpe_harvester.fpe.domain import outside_reason

    out = {"inside, converged": 0, "outside, failed": 0, "inside, failed": 0, "outside, converged": 0}
    for r in runs:
        inside = outside_reason(Harvester.build(a=r["a"], n=r["n"], **r.get("params", {})), r["tol"]) is None
        ok = r["status"] == "stable"
        out[f"{'inside' if inside else 'outside'}, {'converged' if ok else 'failed'}"] += 1
    return out


def _verdicts(runs: list[dict[str, Any]]) -> str:
    return "The domain rule on these runs: " + ", ".join(f"{k} {v}" for k, v in agreement(runs).items())


def off_table(res: dict[str, Any]) -> str:
    """The spot checks off the defaults as Markdown: n, the parameters changed, a, the trap
    strength s, the tolerance, the rule's limit of s for that unit, the rule's verdict and the
    outcome; the checks on the band's boundary (tol 1e-3) first, then those on the limit."""
    from fpe_harvester.fpe.domain import at_defaults, outside_reason, strength_limit

    off = res.get("off_defaults")
    if not off:
        return ""
    lines = ["| n | changed | a | s | tol | limit of s | rule | outcome |", "|---" * 8 + "|"]
    for r in sorted(off["runs"], key=lambda r: (-r["tol"], not r.get("params"), r["n"], r["strength"])):
        params = r.get("params", {})
        h = Harvester.build(a=r["a"], n=r["n"], **params)
        changed = ", ".join(f"{k} = {v:g}" for k, v in params.items()) or "none"
        limit = strength_limit(r["n"], r["tol"], at_defaults(h))
        verdict = "inside" if outside_reason(h, r["tol"]) is None else "declines"
        lines.append(f"| {r['n']:g} | {changed} | {r['a']:.3g} | {r['strength']:.3g} | {r['tol']:g} | "
                     f"{limit:.3g} | {verdict} | {_cell(r)} |")
    lines += ["", _verdicts(off["runs"])]
    return "\n".join(lines) + "\n"


def plot(res: dict[str, Any], path: Path) -> None:
    """The map: per tolerance a panel of n x a cells, coloured by log10 of the wall time of a
    converged run, hatched grey where the run failed; the cells outside the domain rule outlined."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.patches import Rectangle

    from fpe_harvester.fpe.domain import outside_reason

    runs = {(r["n"], r["a"], r["tol"]): r for r in res["runs"]}
    ns, as_ = res["ns"], res["as"]
    fig, axes = plt.subplots(1, len(res["tols"]), figsize=(5.2 * len(res["tols"]), 4.4), squeeze=False)
    for ax, tol in zip(axes[0], res["tols"]):
        grid = np.full((len(ns), len(as_)), np.nan)
        for i, n in enumerate(ns):
            for j, a in enumerate(as_):
                r = runs.get((n, a, tol))
                if r is not None and r["status"] == "stable":
                    grid[i, j] = math.log10(max(r["wall"], 0.1))
        im = ax.imshow(grid, origin="lower", cmap="viridis", vmin=0.0, vmax=3.3, aspect="auto")
        for i, n in enumerate(ns):
            for j, a in enumerate(as_):
                r = runs.get((n, a, tol))
                if r is None:
                    continue
                if r["status"] != "stable":
                    ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, facecolor="0.85", hatch="//",
                                           edgecolor="0.6"))
                text = _cell(r).replace("fails: ", "").replace(", ", "\n")
                ax.text(j, i, text, ha="center", va="center", fontsize=6.5,
                        color="k" if r["status"] != "stable" or grid[i, j] > 2.0 else "w")
                if outside_reason(Harvester.build(a=a, n=n), tol) is not None:
                    ax.add_patch(Rectangle((j - 0.47, i - 0.47), 0.94, 0.94, fill=False, edgecolor="C3",
                                           lw=2))
        ax.set_xticks(range(len(as_)), [f"{a:g}" for a in as_])
        ax.set_yticks(range(len(ns)), [f"{n:g}" for n in ns])
        ax.set_xlabel("a")
        ax.set_ylabel("n")
        ax.set_title(f"tol {tol:g}: wall time (s) or failure", fontsize=9)
    fig.subplots_adjust(left=0.06, right=0.86, bottom=0.17, top=0.9, wspace=0.25)
    fig.colorbar(im, cax=fig.add_axes((0.89, 0.17, 0.015, 0.73)), label="log10 wall time to converge (s)")
    fig.text(0.01, 0.015, "grey: the forced run failed (its reason, the relative error it reached, its "
             "time); red outline: declined by the domain rule at that tol (force=True attempts it)",
             fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """``python -m validation.studies.fpe.domain [--quick] [--out DIR] [--replot]``."""
    ap = argparse.ArgumentParser(prog="python -m validation.studies.fpe.domain",
                                 description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two points, under a minute")
    ap.add_argument("--out", type=Path, default=Path("validation_report"), metavar="DIR",
                    help="folder for the JSON and PNG (default ./validation_report)")
    ap.add_argument("--replot", action="store_true",
                    help="redraw the figure and print the table of the recorded JSON in --out")
    ap.add_argument("--off-defaults", action="store_true",
                    help="only the spot checks off the defaults, added to the JSON in --out")
    args = ap.parse_args(argv)
    if args.off_defaults:
        res = off_defaults(quick=args.quick, out=args.out)
        print(off_table(res))
        return res
    if args.replot:
        res = json.loads((args.out / f"{STEM}.json").read_text())
        plot(res, args.out / f"{STEM}.png")
    else:
        res = run(quick=args.quick, out=args.out)
    print(table(res))
    if "off_defaults" in res:
        print(off_table(res))
    return res


if __name__ == "__main__":
    main()
