"""Monte Carlo design study: the kink's step near rest, where its time goes and what each candidate moves.

At n = 1 and a = 2 the unit spends most of its time in the trap (|sigma xi - K_v V| < a), swinging
across x = 0 on ever smaller arcs, and the frozen step's exact piecewise flow locates every zero
crossing. Parts (``python -m validation.studies.kink.speed PART [PART ...] --out validation/data``;
each writes its key of ``kink_speed.json`` and keeps the others, under ``--label``):

* ``census``: on the product's D step of the kink (:func:`montecarlo._kink._kink_flow`, one unit at a
  time so that each unit-step's events are seen), per a and dt: the distribution of zero crossings
  per unit-step, the fractions of unit-steps on the slow path and in the averaged swing map, the
  fraction trapped (|F - K_v V| < a) and near rest (E = v^2/2 + a|x| < 1e-3), and crossings by the
  swing's period P over the step h;
* ``parts``: thread-CPU nanoseconds of one unit's frozen step on a sample of the census's slow
  unit-steps (with their crossings and averaged maps per step) and of its fast ones;
* ``throughput``: path-steps per thread-CPU-second of :func:`montecarlo.simulate` at a = 0.5, 1
  (dt 0.005) and 2 (dt 0.01), the solver's fine steps, the cases alternating run by run (a load
  change hits all): fine level alone (``bare``) and as the solver runs it (``solver``: Richardson
  pair, harmonic twin, martingale sums); the ratio a = 2 / a = 0.5 per round and its median;
* ``bias``: per kink rule (the averaging threshold, registered for the run in
  :data:`montecarlo.coefficients.KINK_RULES`), the common-noise Richardson difference
  eta(dt) - eta(dt/2) per coarse dt (the weak order's evidence) and eta minus the reference rule's
  eta on the same noise;
* ``solve``: CPU seconds of ``solve(Harvester.build(a=2, n=1), "mc", tol=1e-3, seed=7)``;
* ``validate``: seeded solves against the Fokker-Planck references (a = 0.5, 1 at tol 1e-4) and
  long runs of the kink at a = 2 and of a kink ring (tol 1e-3), for each tree.

``--tree NAME=PATH`` runs every part but ``bias`` also in another checkout
(its own packages, through ``PYTHONPATH``; ``throughput`` alternates the trees round by round), for
numbers before and after a change of the step.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit

from fpe_harvester import Harvester, solve
from montecarlo import estimate, simulate
from montecarlo.coefficients import KINK_RULES, physical_vector, step_coefficients
from montecarlo.layout import (C_AVERAGED, C_CROSSINGS, C_SLOW, CF_H, CF_XI_DECAY, CF_XI_NOISE, KIND_KINK, N_COUNTERS,
                               P_KINK_FORCE, P_KV, P_M, P_SIGMA, P_XI_VAR)
from montecarlo.steps.frozen import N_TAYLOR, d_step

__all__ = ["STEM", "census", "parts", "throughput", "bias", "solve_time", "validate", "draw", "main"]

#: Name of the written ``.json``.
STEM = "kink_speed"
#: The solver's fine steps: a = 0.5 and 1 run at 0.005, a = 2 at 0.01.
CASES = ((0.5, 0.005), (1.0, 0.005), (2.0, 0.01))
#: Upper edges of the swing-period bins (P / h) of the census.
PERIOD_EDGES = np.array([0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, np.inf])
#: Crossings per unit-step counted one by one up to this many (the rest in the last bin).
MAX_COUNT = 9


@njit(cache=True, nogil=True)
def _one_unit():
    """The arrays one unit's :func:`montecarlo.steps.frozen.d_step` takes, N = P = 1: x, v, V, xi,
    F, xm, f (zeros), stuck (False), the live weight w (1), the counters and the Taylor scratch."""
    x, v, V, xi, F, xm, f = np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), \
        np.zeros((1, 1)), np.zeros((1, 1))
    return (x, v, V, xi, F, xm, f, np.zeros((1, 1), dtype=np.bool_), np.ones(1), np.zeros(N_COUNTERS, dtype=np.int64),
            np.zeros((3, N_TAYLOR + 1)))


# not cached: numba's cache would keep a stale copy of the production kernel it calls
@njit(nogil=True)
def _census(gen, P, nburn, nrun, cf, pp, hist, periods, totals, cap, cap_every):
    """P units from rest through nburn + nrun steps of the frozen step (xi exact OU, f = sigma xi),
    one :func:`montecarlo.steps.frozen.d_step` call per unit so that each unit-step's counters are its own. ``hist``
    (MAX_COUNT + 1, 2): unit-steps by crossings, untrapped / trapped; ``periods`` (bins + 1, 3):
    unit-steps, slow unit-steps, crossings by the swing's period at the start (last row: untrapped);
    ``totals``: unit-steps, slow, crossings, averaged, trapped, near rest; ``cap`` (n, 5): every
    ``cap_every``-th slow and fast unit-step's start (x, v, V, f, slow)."""
    x, v, V, xi, F, xm, f, st, w, cnt, cs = _one_unit()
    xs, vs, Vs, xis = np.zeros(P), np.zeros(P), np.zeros(P), np.zeros(P)
    for p in range(P):
        xis[p] = math.sqrt(pp[P_XI_VAR]) * gen.standard_normal()
    a, m, h = pp[P_KINK_FORCE], pp[P_M], cf[CF_H]
    n_slow = n_fast = 0
    k = 0
    for it in range(nburn + nrun):
        for p in range(P):
            x[0, 0], v[0, 0], V[0, 0] = xs[p], vs[p], Vs[p]
            fp = pp[P_SIGMA] * xis[p]
            xi[0, 0] = xis[p]
            net = fp - pp[P_KV] * Vs[p]
            trapped = abs(net) < a
            b = PERIOD_EDGES.size
            if trapped:
                s = 1.0 if xs[p] > 0.0 else (-1.0 if xs[p] < 0.0 else (1.0 if vs[p] > 0.0 else -1.0))
                speed = math.sqrt(vs[p] ** 2 + 2.0 * (a - s * net) * abs(xs[p]) / m)
                period = 4.0 * a * m * speed / (a * a - net * net) / h
                b = 0
                while period >= PERIOD_EDGES[b]:
                    b += 1
            c0, c1, c2 = cnt[C_SLOW], cnt[C_CROSSINGS], cnt[C_AVERAGED]
            start = (xs[p], vs[p], Vs[p], fp)
            d_step(x, v, V, xi, F, st, xm, f, w, cf, pp, KIND_KINK, cnt, cs)
            xs[p], vs[p], Vs[p] = x[0, 0], v[0, 0], V[0, 0]
            xis[p] = cf[CF_XI_DECAY] * xis[p] + cf[CF_XI_NOISE] * gen.standard_normal()
            if it < nburn:
                continue
            slow, nc = cnt[C_SLOW] - c0, cnt[C_CROSSINGS] - c1
            hist[min(nc, MAX_COUNT), 1 if trapped else 0] += 1
            periods[b, 0] += 1
            periods[b, 1] += slow
            periods[b, 2] += nc
            totals[0] += 1
            totals[1] += slow
            totals[2] += nc
            totals[3] += cnt[C_AVERAGED] - c2
            totals[4] += trapped
            totals[5] += 0.5 * start[1] ** 2 + a * abs(start[0]) < 1e-3
            if k < cap.shape[0]:
                if slow:
                    n_slow += 1
                else:
                    n_fast += 1
                if (n_slow if slow else n_fast) % cap_every == 0:
                    cap[k, 0], cap[k, 1], cap[k, 2], cap[k, 3], cap[k, 4] = start[0], start[1], start[2], start[3], slow
                    k += 1
    return k


def census(a: float, dt: float, *, paths: int = 256, t_run: float = 200.0, t_burn: float = 20.0, seed: int = 1,
           rule: str = "average", capture: int = 20000) -> tuple[dict[str, Any], np.ndarray]:
    """The census of one (a, dt, kink rule) and a sample of its unit-steps' starts (x, v, V, f, slow)."""
    h = Harvester.build(a=a, n=1)
    cf, pp = step_coefficients(h, dt), physical_vector(h, 1e300, rule)
    hist = np.zeros((MAX_COUNT + 1, 2))
    periods = np.zeros((PERIOD_EDGES.size + 1, 3))
    totals = np.zeros(6)
    cap = np.zeros((capture, 5))
    nrun = int(round(t_run / dt))
    gen = np.random.Generator(np.random.PCG64(seed))
    # one capture in ~cap_every slow (and fast) unit-steps spreads the sample over the run
    cap_every = max(1, int(paths * nrun * 0.3 / capture))
    t0 = time.perf_counter()
    k = _census(gen, paths, int(round(t_burn / dt)), nrun, cf, pp, hist, periods, totals, cap, cap_every)
    n = totals[0]
    edges = [f"<{e:g}" for e in PERIOD_EDGES[:-1]] + [f">={PERIOD_EDGES[-2]:g}", "untrapped"]
    out = {"a": a, "dt": dt, "rule": rule, "paths": paths, "t_run": t_run, "unit_steps": int(n),
           "slow_per_unit_step": totals[1] / n, "crossings_per_unit_step": totals[2] / n,
           "averaged_per_unit_step": totals[3] / n, "trapped_fraction": totals[4] / n,
           "near_rest_fraction": totals[5] / n,
           "crossings_distribution": {"counts": list(range(MAX_COUNT)) + [f">={MAX_COUNT}"],
                                      "untrapped": (hist[:, 0] / n).tolist(), "trapped": (hist[:, 1] / n).tolist()},
           "by_period_over_h": {lab: {"unit_steps": r[0] / n, "slow": r[1] / n, "crossings": r[2] / n}
                                for lab, r in zip(edges, periods)},
           "wall_s": time.perf_counter() - t0}
    return out, cap[:k]


@njit(nogil=True)
def _time_flow(cap, cf, pp, reps):
    """The frozen step (:func:`montecarlo.steps.frozen.d_step`, one unit) once per captured start,
    ``reps`` times over the sample."""
    x, v, V, xi, F, xm, f, st, w, cnt, cs = _one_unit()
    acc = 0.0
    for _ in range(reps):
        for i in range(cap.shape[0]):
            x[0, 0], v[0, 0], V[0, 0], xi[0, 0] = cap[i, 0], cap[i, 1], cap[i, 2], cap[i, 3] / pp[P_SIGMA]
            d_step(x, v, V, xi, F, st, xm, f, w, cf, pp, KIND_KINK, cnt, cs)
            acc += x[0, 0]
    return acc, cnt


def _ns(fn, n: int, repeats: int = 5) -> float:
    """Median thread-CPU nanoseconds per item of ``fn()`` (which handles ``n`` items)."""
    fn()
    out = []
    for _ in range(repeats):
        t0 = time.thread_time()
        fn()
        out.append((time.thread_time() - t0) / n * 1e9)
    return statistics.median(out)


def parts(a: float, dt: float, cap: np.ndarray, reps: int = 20) -> dict[str, Any]:
    """Nanoseconds of one unit's frozen step on the census's captured starts: its sample of slow
    unit-steps (with their crossings and averaged maps per step) and of fast ones (the call's own
    cost). The split of a slow step into its series, root finding and averaged map is timed on
    the kernel's private functions, which a study does not import: the numbers measured that way
    are in docs/methods.md."""
    h = Harvester.build(a=a, n=1)
    cf, pp = step_coefficients(h, dt), physical_vector(h, 1e300)
    slow = np.ascontiguousarray(cap[(cap[:, 4] > 0) & ~((cap[:, 0] == 0.0) & (cap[:, 1] == 0.0))])
    fast = np.ascontiguousarray(cap[cap[:, 4] == 0])
    out: dict[str, Any] = {"a": a, "dt": dt, "slow_sample": len(slow), "fast_sample": len(fast)}
    _, cnt = _time_flow(slow, cf, pp, 1)
    out["per_slow_step"] = {"crossings": cnt[C_CROSSINGS] / len(slow), "averaged": cnt[C_AVERAGED] / len(slow)}
    out["ns_flow_slow_step"] = _ns(lambda: _time_flow(slow, cf, pp, reps), reps * len(slow))
    out["ns_flow_fast_step"] = _ns(lambda: _time_flow(fast, cf, pp, reps), reps * len(fast))
    return out


def _kappa(a: float) -> float:
    """The harmonic twin's stiffness from a short run (<x U'>/<x^2>), as the solver's pilot."""
    from montecarlo import linearized_stiffness

    h = Harvester.build(a=a, n=1)
    m = simulate(h, dt=0.02, paths=16, replicas=4, t_burn=40.0, t_run=100.0, seed=1).moments(0)
    return float(linearized_stiffness(h, float(m["xdU"].mean()), float(m["x2"].mean())))


def throughput(mode: str, rounds: int, t_run: float, kappas: dict[float, float] | None = None,
               rules: dict[str, float] | None = None) -> dict[str, Any]:
    """Thread-CPU nanoseconds per path-step of :func:`montecarlo.simulate` for :data:`CASES`, the cases
    alternating run by run, ``rounds`` times (64 paths in chunks of 16, one thread, burn-in 20,
    ``t_run`` measured). ``mode``: ``"bare"`` (fine level alone) or ``"solver"`` (Richardson pair
    at 2 dt and dt, harmonic twin from its law, martingale sums). ``rules`` (name -> swings,
    registered in KINK_RULES for the run) adds a = 2 under each of those kink rules (the
    candidates' costs; ratios to a = 0.5 under the default rule)."""
    kappas = kappas or {a: _kappa(a) for a, _ in CASES}
    cases = [(f"a={a:g}", a, dt, "average") for a, dt in CASES]
    cases += [(f"a=2 rule {name}", 2.0, 0.01, name) for name in (rules or {})]
    hs = {a: Harvester.build(a=a, n=1) for a, _ in CASES}

    def kw(a: float, dt: float, rule: str, seed: int, t: float) -> dict[str, Any]:
        k = {"paths": 64, "chunk": 16, "replicas": 1, "threads": 1, "t_burn": 20.0, "t_run": t, "seed": seed,
             "kink_rule": rule}
        if mode == "solver":
            return {**k, "dt": 2 * dt, "richardson": True, "twin": kappas[a], "start": "twin",
                    "controls": ("martingale", "boundary")}
        return {**k, "dt": dt}

    saved = dict(KINK_RULES)
    KINK_RULES.update(rules or {})
    ns: dict[str, list[float]] = {name: [] for name, *_ in cases}
    try:
        for _, a, dt, rule in cases:
            simulate(hs[a], **kw(a, dt, rule, 0, 1.0))
        for r in range(rounds):
            for name, a, dt, rule in cases:
                t0 = time.thread_time()
                e = simulate(hs[a], **kw(a, dt, rule, 1 + r, t_run))
                ns[name].append((time.thread_time() - t0) / e.path_steps * 1e9)
    finally:
        KINK_RULES.clear()
        KINK_RULES.update(saved)
    ratios = {name: [x / x05 for x, x05 in zip(v, ns["a=0.5"])] for name, v in ns.items() if name.startswith("a=2")}
    return {"mode": mode, "cases": [list(c) for c in cases], "ns_per_path_step": ns,
            "median_ns": {k: statistics.median(v) for k, v in ns.items()},
            "path_steps_per_cpu_s": {k: 1e9 / statistics.median(v) for k, v in ns.items()},
            "ratio_a2_over_a05": ratios["a=2"], "median_ratio_a2_over_a05": statistics.median(ratios["a=2"]),
            "ratios_over_a05": ratios}


def bias(a: float, dts: tuple[float, ...], rules: dict[str, float], *, reference: str, replicas: int,
         paths: int = 64, t_burn: float = 30.0, t_run: float = 100.0, seed: int = 4000) -> list[dict[str, Any]]:
    """Per coarse dt and kink rule (name -> swings, registered in KINK_RULES for the run): the
    Richardson-coupled difference eta(dt) - eta(dt/2) (common noise, with the twin and martingale
    controls), eta at dt/2, and the fine eta minus ``reference``'s on the same noise (per replica)."""
    h = Harvester.build(a=a, n=1)
    kappa = _kappa(a)
    saved = dict(KINK_RULES)
    KINK_RULES.update(rules)
    rows = []
    try:
        for i, dt in enumerate(dts):
            per: dict[str, np.ndarray] = {}
            for name in rules:
                t0 = time.perf_counter()
                e = simulate(h, dt=dt, paths=paths, replicas=replicas, t_burn=t_burn, t_run=t_run, seed=seed + i,
                             richardson=True, twin=kappa, start="twin", controls=("martingale", "boundary"), kink_rule=name)
                est = estimate(e, h, order=1.0)  # order 1: bias = coarse - fine, the raw difference
                m = e.moments(0)
                per[name] = m["V2"] / m["vxi"]
                rows.append({"a": a, "dt_coarse": dt, "rule": name, "swings": rules[name], "replicas": replicas,
                             "eta": est.mean["eta"], "eta_se": est.se["eta"], "diff": est.bias["eta"],
                             "diff_se": est.bias_se["eta"], "kink_counters": list(e.kink_counters),
                             "path_steps": e.path_steps, "wall_s": time.perf_counter() - t0})
            for row in rows[-len(rules):]:
                d = per[row["rule"]] - per[reference]
                row["minus_reference_eta"] = float(d.mean())
                row["minus_reference_eta_se"] = float(d.std(ddof=1) / math.sqrt(d.size))
    finally:
        KINK_RULES.clear()
        KINK_RULES.update(saved)
    return rows


def solve_time(a: float = 2.0, tol: float = 1e-3, seed: int = 7) -> dict[str, Any]:
    """Process CPU and wall seconds of ``solve(Harvester.build(a=a, n=1), "mc", tol=tol, seed=seed)``
    (no wall-time budget) after a compiling solve, with its result."""
    h = Harvester.build(a=a, n=1)
    solve(h, "mc", tol=3e-2, seed=1, progress=False)
    c0, w0 = time.process_time(), time.perf_counter()
    r = solve(h, "mc", tol=tol, seed=seed, progress=False, max_time=1e6)
    return {"a": a, "tol": tol, "seed": seed, "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0,
            **_result(r)}


def _result(r: Any) -> dict[str, Any]:
    keys = ("dt", "replicas", "path_steps", "path_steps_per_s", "variance_reduction", "bias_eta",
            "kink_crossings", "kink_slow_steps", "kink_averaged", "control_set")
    return {"status": str(r.status), "eta": r.eta, "eta_err": r.eta_err, "V2": r.V2, "V2_err": r.V2_err,
            "Pin": r.Pin, "Pin_err": r.Pin_err, "info": {k: r.info.get(k) for k in keys}}


#: The validation's solves: (label, Harvester.build arguments, tol, seeds).
VALIDATION = (("n = 1, a = 0.5", {"a": 0.5, "n": 1}, 1e-4, (7,)),
              ("n = 1, a = 1", {"a": 1.0, "n": 1}, 1e-4, (7,)),
              ("n = 1, a = 2", {"a": 2.0, "n": 1}, 1e-3, (7,)),
              ("kink ring N = 2, a = 2, k = 0.2", {"a": 2.0, "n": 1, "N": 2, "k": 0.2}, 1e-3, (7,)),
              ("kink ring N = 3, a = 0.5, k = -0.5, k3 = 1, k4 = 0.05",
               {"a": 0.5, "n": 1, "N": 3, "k": -0.5, "k3": 1.0, "k4": 0.05}, 1e-3, (7,)))


def validate(only: tuple[str, ...] = ()) -> dict[str, Any]:
    """The :data:`VALIDATION` solves (CPU seconds and results; no wall-time budget)."""
    out: dict[str, Any] = {}
    for label, system, tol, seeds in VALIDATION:
        if only and label not in only:
            continue
        for seed in seeds:
            c0 = time.process_time()
            r = solve(Harvester.build(**system), "mc", tol=tol, seed=seed, progress=False, max_time=1e6)
            out[f"{label}, seed {seed}"] = {"system": system, "tol": tol, "seed": seed,
                                            "cpu_s": time.process_time() - c0, **_result(r)}
    return out


def _in_tree(path: str, part: str, args: dict[str, Any]) -> Any:
    """Run ``part`` of this module with ``args`` in the checkout at ``path`` (its packages first
    on ``PYTHONPATH``) and return its JSON result."""
    env = {**os.environ, "PYTHONPATH": os.path.abspath(path)}
    # -P: the script's own folder stays off sys.path (only the tree's packages are imported)
    cmd = [sys.executable, "-P", os.path.abspath(__file__), "--worker", json.dumps({"part": part, **args})]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def _worker(spec: dict[str, Any]) -> Any:
    part = spec.pop("part")
    if part == "census":
        return {f"a={a:g} dt={dt:g}": census(a, dt)[0] for a, dt in CASES}
    if part == "parts":
        return {f"a={a:g} dt={dt:g}": parts(a, dt, census(a, dt)[1]) for a, dt in CASES if a != 0.5}
    if part == "throughput":
        spec["kappas"] = {float(k): v for k, v in spec["kappas"].items()}
        return throughput(**spec)
    if part == "solve":
        return solve_time()
    if part == "validate":
        return validate(tuple(spec.get("only", ())))
    raise ValueError(f"part must be census, parts, throughput, solve or validate, got {part!r}")


def _trees(specs: list[str]) -> dict[str, str]:
    """``NAME=PATH`` arguments as a dict, with this checkout as ``"this"``."""
    trees = {"this": str(Path(__file__).resolve().parents[3])}
    for spec in specs:
        name, _, path = spec.partition("=")
        if not name or not path or not Path(path, "montecarlo").is_dir():
            raise SystemExit(f"--tree must be NAME=PATH of a checkout with a montecarlo package, got {spec!r}")
        trees[name] = path
    return trees


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command line: the parts asked for, each written into ``--out``/kink_speed.json under
    ``--label`` as soon as it is done (the file's other entries kept)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m validation.studies.kink.speed",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="+", choices=("census", "parts", "throughput", "bias", "solve", "validate"))
    ap.add_argument("--out", type=Path, required=True, metavar="DIR")
    ap.add_argument("--label", default="this tree")
    ap.add_argument("--tree", action="append", default=[], metavar="NAME=PATH",
                    help="another checkout to run every part but bias in too")
    ap.add_argument("--rounds", type=int, default=12, help="throughput: alternations per tree")
    ap.add_argument("--t-run", type=float, default=80.0, help="throughput: measured time per run")
    ap.add_argument("--candidates", action="store_true", help="throughput: a = 2 under each of --rules too")
    ap.add_argument("--rules", nargs="+", default=["follow4=4", "average=0.25", "avg8=0.125", "avg16=0.0625"],
                    metavar="NAME=SWINGS", help="bias (the first is the reference) and throughput --candidates: "
                    "kink rules, the swings that must fit in the time left before they are averaged")
    ap.add_argument("--bias-a", type=float, default=2.0)
    ap.add_argument("--bias-dts", type=float, nargs="+", default=[0.08, 0.04, 0.02])
    ap.add_argument("--bias-replicas", type=int, default=128)
    ap.add_argument("--only", nargs="*", default=[], help="validate: these labels only")
    args = ap.parse_args(argv)
    trees = _trees(args.tree)
    rules = {name: float(sw) for name, _, sw in (r.partition("=") for r in args.rules)}
    path = args.out / f"{STEM}.json"
    res = json.loads(path.read_text()) if path.exists() else {}
    entry = res.setdefault(args.label, {})
    entry["command"] = "python -m validation.studies.kink.speed " + " ".join(argv if argv is not None else sys.argv[1:])

    def save(key: str, value: Any) -> None:
        entry[key] = value
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=1, default=float))
        if key in ("throughput", "bias"):
            draw(entry, args.out / f"{STEM}_{args.label.replace(' ', '_')}.png")
        print(f"{key}: written to {path}", flush=True)

    for part in args.parts:
        if part == "census":
            save("census", {name: _in_tree(p, "census", {}) for name, p in trees.items()})
        elif part == "parts":
            save("parts", {name: _in_tree(p, "parts", {}) for name, p in trees.items()})
        elif part == "throughput":
            kappas = {a: _kappa(a) for a, _ in CASES}
            out: dict[str, Any] = {}
            for mode in ("bare", "solver"):
                runs: dict[str, list] = {name: [] for name in trees}
                for _ in range(args.rounds):
                    for name, p in trees.items():
                        # the candidate rules only here: another tree's kernels may read the rule otherwise
                        extra = {"rules": rules} if name == "this" and args.candidates else {}
                        runs[name].append(_in_tree(p, "throughput", {"mode": mode, "rounds": 1, "t_run": args.t_run,
                                                                     "kappas": kappas, **extra}))
                out[mode] = {name: _pool(r) for name, r in runs.items()}
            save("throughput", {"kappas": kappas, **out})
        elif part == "bias":
            save("bias", bias(args.bias_a, tuple(args.bias_dts), rules, reference=next(iter(rules)),
                              replicas=args.bias_replicas))
        elif part == "solve":
            save("solve", {name: _in_tree(p, "solve", {}) for name, p in trees.items()})
        else:
            save("validate", {name: _in_tree(p, "validate", {"only": args.only}) for name, p in trees.items()})
    return res


def draw(entry: dict[str, Any], path: Path) -> None:
    """Two panels of one label's entry: path-steps per CPU-second per case and tree (throughput),
    and |eta(dt) - eta(dt/2)| per coarse dt and kink rule (bias)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10.0, 4.0))
    for i, (mode, trees) in enumerate((k, v) for k, v in entry.get("throughput", {}).items() if k != "kappas"):
        for j, (tree, r) in enumerate(trees.items()):
            rates = r["path_steps_per_cpu_s"]
            ax1.bar([3 * k + 0.4 * (2 * i + j) for k in range(len(rates))], list(rates.values()), 0.4,
                    label=f"{mode}, {tree} (a=2/a=0.5: {r['median_ratio_a2_over_a05']:.2f})")
            ax1.set_xticks([3 * k + 0.6 for k in range(len(rates))], list(rates))
    ax1.set_yscale("log")
    ax1.set_ylabel("path-steps per CPU second")
    ax1.legend(fontsize=6)
    rows = entry.get("bias", [])
    for rule in dict.fromkeys(r["rule"] for r in rows):
        sel = [r for r in rows if r["rule"] == rule]
        ax2.errorbar([r["dt_coarse"] for r in sel], [abs(r["diff"]) for r in sel], [r["diff_se"] for r in sel],
                     fmt="o-", capsize=3, label=rule)
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("coarse dt")
    ax2.set_ylabel("|eta(dt) - eta(dt/2)| (common noise)")
    if rows:
        ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _pool(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One tree's throughput runs (one round each) pooled: the medians over the rounds."""
    ns = {k: [x for r in runs for x in r["ns_per_path_step"][k]] for k in runs[0]["ns_per_path_step"]}
    ratios = [x for r in runs for x in r["ratio_a2_over_a05"]]
    others = {k: [x for r in runs for x in r.get("ratios_over_a05", {}).get(k, [])]
              for k in runs[0].get("ratios_over_a05", {})}
    return {"rounds": len(ratios), "median_ns": {k: statistics.median(v) for k, v in ns.items()},
            "path_steps_per_cpu_s": {k: 1e9 / statistics.median(v) for k, v in ns.items()},
            "ratio_a2_over_a05": ratios, "median_ratio_a2_over_a05": statistics.median(ratios),
            "ratio_quartiles": [float(q) for q in np.quantile(ratios, [0.25, 0.75])],
            "median_ratios_over_a05": {k: statistics.median(v) for k, v in others.items()}}


if __name__ == "__main__":  # pragma: no cover
    if len(sys.argv) == 3 and sys.argv[1] == "--worker":
        print(json.dumps(_worker(json.loads(sys.argv[2])), default=float))
    else:
        main()
