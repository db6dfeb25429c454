"""Monte Carlo design study: do the solver's error bars hold? Coverage over seeds.

For each case the solver (``threads=1, batch=2``) runs over many seeds, and each reported value
is compared with an exact one in units of its reported error, ``z = (value - exact) / error``:
the mean of z (a bias shows as a mean away from 0), its rms (1 for honest bars) and the share
within one and two errors (nominal 68.3 % and 95.4 %).

Part ``white``: the white-noise limit tau = 1e-4 of the joint step. With K_v = 0 the stationary
law is Boltzmann at T = sigma^2 D/(m gamma) and Pin = sigma^2 D/(m (1 + gamma tau)) up to
O(tau^2 <U''>) (~2e-8 here, against errors of ~5e-7); <x^2> (one unit) and the bond's <d^2>
(N = 2) by quadrature of the Boltzmann law; a harmonic ring N = 3 at the defaults (K_v = 1)
against the exact solver at the same tau (V2, Pin, eta).

Part ``ring``: eta of rings at tol 3e-3 over seeds, the spread of the values against the
reported errors, where no exact value exists: the n = 1, N = 3 ring near its best coupling, the
same ring far from its coexistence coupling, and the n = 3 ring.

``python -m validation.studies.mc.errorbars [--part white|ring] [--seeds N] [--case I] [--label NAME]``
adds its rows under ``NAME`` to ``validation/data/bench_montecarlo_errorbars.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from typing import Any

import numpy as np
from scipy.integrate import quad

from fpe_harvester import Harvester, solve
from montecarlo import MonteCarlo
from validation.studies.cli import DATA

__all__ = ["STEM", "WHITE_CASES", "RING_CASES", "coverage", "white_rows", "ring_rows", "main"]

#: Name of the written ``.json``.
STEM = "bench_montecarlo_errorbars"

_WHITE = dict(Kv=0.0, tau=1e-4)

#: (label, build arguments, tol) of the white-noise cases.
WHITE_CASES = (
    ("harmonic unit a=0.5", dict(a=0.5, n=2, N=1, **_WHITE), 1e-2),
    ("harmonic N=2 k=-0.2 k3=0.1", dict(a=0.5, n=2, N=2, k=-0.2, k3=0.1, **_WHITE), 1e-2),
    ("n=3 unit a=0.5", dict(a=0.5, n=3, N=1, **_WHITE), 1e-2),
    ("n=1.5 N=2 k=-0.1 k3=0.1", dict(a=0.5, n=1.5, N=2, k=-0.1, k3=0.1, **_WHITE), 1e-2),
    ("n=3 N=2 k=-0.3 k3=0.1", dict(a=0.5, n=3, N=2, k=-0.3, k3=0.1, **_WHITE), 1e-2),
    ("harmonic N=3 k=-0.2 Kv=1", dict(a=0.5, n=2, N=3, k=-0.2, tau=1e-4), 1e-2),
    ("kink n=1 a=1 N=2 k=-0.5 k3=0.1", dict(a=1.0, n=1, N=2, k=-0.5, k3=0.1, **_WHITE), 3e-2),
)

#: (label, build arguments, tol) of the rings without an exact value.
#: The first is the n = 1 ring's recorded best coupling for k3 = 0.003 (validation/data/coupling.json:
#: k_opt = -0.136, at its coexistence coupling k_co = -0.1363, fold -0.108).
RING_CASES = (
    ("n=1 N=3 k3=0.003 k=-0.136", dict(a=0.5, n=1, N=3, k=-0.136, k3=0.003), 3e-3),
    ("n=1 N=3 k3=0.003 k=-0.05", dict(a=0.5, n=1, N=3, k=-0.05, k3=0.003), 3e-3),
    ("n=3 N=3 k=-0.5", dict(a=0.5, n=3, N=3, k=-0.5), 3e-3),
)


def _boltzmann(h: Harvester) -> dict[str, float]:
    """Exact white-noise values at K_v = 0: Pin, and <x^2> (N = 1) or the bond's <d^2> (N = 2)."""
    p = h.params
    T = p.sigma**2 * p.D / (p.m * p.gamma)
    out = {"Pin": p.sigma**2 * p.D / (p.m * (1.0 + p.gamma * p.tau))}
    if h.N == 1:
        w = lambda x: math.exp(-h.a * abs(x) ** h.n / T)  # noqa: E731
        out["x2"] = quad(lambda x: x * x * w(x), 0, 60)[0] / quad(w, 0, 60)[0]
    elif h.N == 2:
        # the bond law after integrating out the centre of mass s = (x1 + x2)/2 (d = x1 - x2)
        def onsite(d: float) -> float:
            return quad(lambda s: math.exp(-h.a * (abs(s + d / 2) ** h.n + abs(s - d / 2) ** h.n) / T),
                        -40, 40, points=[-d / 2, d / 2], limit=200)[0]

        def w(d: float) -> float:
            return onsite(d) * math.exp(-((h.k + 4.0 * h.k4) * d * d + 0.5 * h.k3 * d**4) / T)

        z = quad(w, 0, 30, limit=200)[0]
        out["d2"] = quad(lambda d: d * d * w(d), 0, 30, limit=200)[0] / z
    return out


def _exact(h: Harvester) -> dict[str, float]:
    """The exact solver's values for a harmonic system (at K_v = 0 Pin and x2 only, V2 being
    the only noise of eta there), else the Boltzmann ones."""
    if h.is_linear:
        s = solve(h, "exact")
        return {"Pin": s.Pin, "x2": s.x2} if h.params.Kv == 0.0 else {"V2": s.V2, "Pin": s.Pin, "eta": s.eta}
    return _boltzmann(h)


def coverage(z: np.ndarray) -> dict[str, float]:
    """Mean and rms of z, the share within one and two errors."""
    z = np.asarray(z, float)
    return {"mean_z": float(z.mean()), "rms_z": float(np.sqrt((z * z).mean())),
            "within_1": float((abs(z) < 1).mean()), "within_2": float((abs(z) < 2).mean()), "count": int(z.size)}


def _solve(h: Harvester, seed: int, tol: float, t_burn: float | None = None) -> Any:
    return solve(h, MonteCarlo(seed=seed, tol=tol, threads=1, batch=2, progress=False, t_burn=t_burn))


def white_rows(seeds: int, case: int | None = None, first: int = 1) -> list[dict[str, Any]]:
    """Coverage of the white-noise cases (or case number ``case``) over ``seeds`` seeds."""
    rows = []
    for label, kw, tol in WHITE_CASES if case is None else WHITE_CASES[case:case + 1]:
        h = Harvester.build(**kw)
        exact = _exact(h)
        runs, t0 = [], time.perf_counter()
        for seed in range(first, first + seeds):
            s = _solve(h, seed, tol)
            runs.append({name: (getattr(s, name), getattr(s, name + "_err")) for name in exact}
                        | {"bias_Pin": s.info["bias_Pin"], "dt": s.info["dt"]})
        row = {"case": label, "tol": tol, "exact": exact, "wall_s": time.perf_counter() - t0, "runs": runs}
        for name, ref in exact.items():
            z = np.array([(r[name][0] - ref) / r[name][1] for r in runs])
            row[name] = coverage(z) | {"median_err": float(np.median([r[name][1] for r in runs])),
                                       "mean_dev": float(np.mean([r[name][0] - ref for r in runs]))}
        print(label, {k: row[k] for k in exact}, flush=True)
        rows.append(row)
    return rows


def ring_rows(seeds: int, case: int | None = None, first: int = 1,
              t_burn: float | None = None) -> list[dict[str, Any]]:
    """The seed-to-seed spread of eta against the reported errors on rings without an exact value
    (or on case number ``case``), with the automatic burn-in or a fixed ``t_burn``."""
    rows = []
    for label, kw, tol in RING_CASES if case is None else RING_CASES[case:case + 1]:
        h = Harvester.build(**kw)
        runs, t0 = [], time.perf_counter()
        for seed in range(first, first + seeds):
            s = _solve(h, seed, tol, t_burn)
            i = s.info
            runs.append({"eta": s.eta, "eta_err": s.eta_err, "se": i["eta_standard_error"],
                         "bias": i["bias_eta"], "replicas": i["replicas"], "paths": i["paths"],
                         "t_burn": i["t_burn"], "t_run": i["t_run"], "dt": i["dt"], "status": s.status.value})
        eta = np.array([r["eta"] for r in runs])
        err = np.array([r["eta_err"] for r in runs])
        spread = float(eta.std(ddof=1))
        # z against the mean of the other seeds (their mean's own error in quadrature)
        loo = np.array([(eta[i] - np.delete(eta, i).mean()) for i in range(eta.size)])
        z = loo / np.sqrt(err**2 + (spread**2) / (eta.size - 1))
        row = {"case": label, "tol": tol, "t_burn": t_burn, "wall_s": time.perf_counter() - t0, "mean_eta": float(eta.mean()),
               "spread": spread, "median_err": float(np.median(err)), "spread_over_err": spread / float(np.median(err)),
               "eta": coverage(z), "runs": runs}
        print(label, {k: v for k, v in row.items() if k != "runs"}, flush=True)
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("white", "ring"), default="white")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--case", type=int, default=None, help="only this case (index) of the part")
    ap.add_argument("--label", default="current")
    ap.add_argument("--t-burn", type=float, default=None, help="fixed burn-in (part ring)")
    ap.add_argument("--out", default=str(DATA))
    a = ap.parse_args(argv)
    rows = white_rows(a.seeds, a.case) if a.part == "white" else ring_rows(a.seeds, a.case, t_burn=a.t_burn)
    path = DATA.__class__(a.out) / f"{STEM}.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    data.setdefault(a.part, {}).setdefault(a.label, [])
    done = {r["case"] for r in rows}
    data[a.part][a.label] = [r for r in data[a.part][a.label] if r["case"] not in done] + rows
    path.write_text(json.dumps(data, indent=1))
    return data


if __name__ == "__main__":
    main()
