"""Independent reference for the kink (n = 1, N = 1) and the Monte Carlo scheme's bias against it.

The reference shares none of the kink scheme's approximations (:mod:`montecarlo._kernels`):

* the noise is the exact Ornstein--Uhlenbeck path sampled every ``delta`` (1e-3 by default,
  10-40 times below the scheme's steps) and interpolated *linearly* in between, not frozen
  over a step (its error is first order in ``delta`` at the kink's threshold |F| = a, second
  order elsewhere: the remaining bias is checked by halving ``delta`` on the same noise);
* each side of x = 0 is integrated in closed form for that linear force (eigenvectors of the
  linear part, not a Taylor series); zero crossings are found by conservative advancement
  with a bound on |x''|, which cannot step over a crossing (no sampling grid, no Newton);
* swings are followed crossing by crossing until the crossing speed falls below ``w_min``
  (1e-3 by default; not tied to a time step), and only then is the unit held at rest, until
  the net force reaches the kink's strength a (the effect of ``w_min`` is checked by
  lowering it on the same noise).

On the same noise path, the production scheme (:func:`montecarlo.steps.frozen.d_step`) runs at
steps ``K * delta`` for each ``(K, rule)`` asked for, with the noise frozen at the centre of
each of its steps as in :func:`montecarlo.simulate`. The scheme's and the reference's time
averages are then strongly correlated, and their difference measures the scheme's time-step
bias against a reference independent of it, at a small fraction of the cost of independent
runs.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import scipy.linalg
from numba import njit

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError, check_real
from fpe_harvester.parallel import default_threads
from montecarlo.coefficients import physical_vector, step_coefficients
from montecarlo.estimate import student_factor
from montecarlo.layout import KIND_KINK, P_SIZE
from montecarlo.steps.frozen import N_TAYLOR, d_step

__all__ = ["reference_run", "summarize", "draw", "main", "MOMENTS"]

#: Event budget of one noise interval (counted when exhausted; the unit keeps its state).
MAX_EVENTS = 100000
#: Moments per level: <V^2>, <vV>, <v^2>, <x^2>, <v xi>, fraction held at rest.
MOMENTS = ("V2", "vV", "v2", "x2", "vxi", "held")


@njit(cache=True, nogil=True)
def _phis(lam: np.ndarray, t: float, out1: np.ndarray, out2: np.ndarray) -> None:
    """phi1 = (e^{lam t} - 1)/lam and phi2 = (e^{lam t} - 1 - lam t)/lam^2 (series for small lam t)."""
    for i in range(lam.size):
        z = lam[i] * t
        if abs(z) < 0.25:
            s1 = 0j
            s2 = 0j
            term = 1.0 + 0j  # z^k / k!
            for k in range(16):
                s1 += term / (k + 1)
                s2 += term / ((k + 1) * (k + 2))
                term = term * z / (k + 1)
            out1[i] = t * s1
            out2[i] = t * t * s2
        else:
            e = np.exp(z)
            out1[i] = (e - 1.0) / lam[i]
            out2[i] = (e - 1.0 - z) / (lam[i] * lam[i])


@njit(cache=True, nogil=True)
def _eval(y0: np.ndarray, c0: float, c1: float, t: float, ed: tuple, out: np.ndarray) -> None:
    """State (x, v, V) after time t from y0 under the force c0 + c1 t (eigen form of the flow)."""
    lam, W, Winv, beta, p1, p2 = ed
    _phis(lam, t, p1, p2)
    eta = np.zeros(3, dtype=np.complex128)
    for i in range(3):
        e0 = 0j
        for j in range(3):
            e0 += Winv[i, j] * y0[j]
        eta[i] = np.exp(lam[i] * t) * e0 + beta[i] * (c0 * p1[i] + c1 * p2[i])
    for r in range(3):
        s = 0j
        for i in range(3):
            s += W[r, i] * eta[i]
        out[r] = s.real


@njit(cache=True, nogil=True)
def _first_root(y0: np.ndarray, s: float, c0: float, c1: float, rem: float, departing: bool,
                M: float, ed: tuple, y: np.ndarray) -> float:
    """First t in (0, rem] with s x(t) <= 0 by conservative advancement, or -1 (y = state at t).

    From a point where s x = X > 0 and s v = U, s x(t + u) >= X + U u - M u^2/2 with M a bound
    on |x''| over the interval, so the step to the first zero of that parabola cannot pass a
    crossing; near a crossing the steps shrink like Newton's.
    """
    t = 0.0
    y[0], y[1], y[2] = y0[0], y0[1], y0[2]
    if departing:
        # from rest, pushed outward: x grows like t^2 or t^3, no crossing right away
        t = rem / 64.0
        _eval(y0, c0, c1, t, ed, y)
        if s * y[0] <= 0.0:
            return t
    for _ in range(10000):
        X, U = s * y[0], s * y[1]
        if X <= 1e-17 and (t > 0.0 or U <= 0.0):
            return t
        u = 2.0 * X / (-U + math.sqrt(U * U + 2.0 * M * X)) if U < 0.0 else \
            (U + math.sqrt(U * U + 2.0 * M * X)) / M
        if t + u >= rem:
            _eval(y0, c0, c1, rem, ed, y)
            if s * y[0] > 0.0:
                return -1.0
            # a crossing the bound did not foresee (it is a bound only up to its safety factor)
            lo, hi = t, rem
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                _eval(y0, c0, c1, mid, ed, y)
                if s * y[0] > 0.0:
                    lo = mid
                else:
                    hi = mid
            _eval(y0, c0, c1, hi, ed, y)
            return hi
        t += u
        _eval(y0, c0, c1, t, ed, y)
        if s * y[0] <= 0.0:
            return t
    return t


@njit(cache=True, nogil=True)
def _exit_time(xi0: float, dxi: float, V: float, rem: float, phys: np.ndarray) -> float:
    """First time in (0, rem] where |sigma xi(t) - Kv V e^{-t/tau_p}| > a (bisection), or -1."""
    Kv, tau_p, sigma, a = phys[2], phys[4], phys[5], phys[7]

    def out(t: float) -> float:
        return abs(sigma * (xi0 + dxi * t) - Kv * V * math.exp(-t / tau_p)) - a

    if out(rem) <= 0.0:
        return -1.0
    lo, hi = 0.0, rem
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if out(mid) > 0.0:
            hi = mid
        else:
            lo = mid
    return hi


@njit(cache=True, nogil=True)
def _ref_interval(st: np.ndarray, xi0: float, xi1: float, delta: float, phys: np.ndarray,
                  E: np.ndarray, ed: tuple, cnt: np.ndarray, y0: np.ndarray, y: np.ndarray) -> None:
    """Advance one reference unit st = (x, v, V, held) over one noise interval, in place."""
    m, gamma, Kv, Kc = phys[0], phys[1], phys[2], phys[3]
    tau_p, sigma, a, w_min = phys[4], phys[5], phys[7], phys[8]
    dxi = (xi1 - xi0) / delta
    x, v, V, held = st[0], st[1], st[2], st[3] != 0.0
    t = 0.0
    departing = False
    for _ in range(MAX_EVENTS):
        rem = delta - t
        if rem <= 0.0:
            break
        xis = xi0 + dxi * t
        if held:
            u = _exit_time(xis, dxi, V, rem, phys)
            if u < 0.0:
                V *= math.exp(-rem / tau_p)
                break
            V *= math.exp(-u / tau_p)
            t += u
            held = False
            departing = True
            x, v = 0.0, 0.0
            continue
        if x != 0.0:
            s = 1.0 if x > 0.0 else -1.0
        elif v != 0.0:
            s = 1.0 if v > 0.0 else -1.0
        else:
            net = sigma * xis - Kv * V
            if abs(net) <= a and not departing:
                held = True
                continue
            s = 1.0 if net > 0.0 else -1.0
            departing = True
        c0, c1 = sigma * xis - a * s, sigma * dxi
        # bound on |x''| over the rest of the interval, with a safety factor 2
        M = 2.0 * ((abs(c0) + abs(c1) * rem + Kv * (abs(V) + Kc * rem)) / m + gamma * (abs(v) + rem)) + 1e-12
        # far from x = 0 (the usual case): one exact affine step over the whole interval
        if t == 0.0 and not departing and s * x > delta * (abs(v) + 0.5 * M * delta):
            y0[0] = E[0, 0] * x + E[0, 1] * v + E[0, 2] * V + E[0, 3] * c0 + E[0, 4] * c1
            y0[1] = E[1, 0] * x + E[1, 1] * v + E[1, 2] * V + E[1, 3] * c0 + E[1, 4] * c1
            y0[2] = E[2, 0] * x + E[2, 1] * v + E[2, 2] * V + E[2, 3] * c0 + E[2, 4] * c1
            x, v, V = y0[0], y0[1], y0[2]
            break
        y0[0], y0[1], y0[2] = x, v, V
        cnt[0] += 1
        tc = _first_root(y0, s, c0, c1, rem, departing, M, ed, y)
        departing = False
        if tc < 0.0:
            x, v, V = y[0], y[1], y[2]
            break
        cnt[1] += 1
        x, v, V = 0.0, y[1], y[2]
        t += tc
        net = sigma * (xi0 + dxi * t) - Kv * V
        if abs(v) < w_min and abs(net) < a:
            held = True
            v = 0.0
            cnt[2] += 1
    else:
        cnt[3] += 1
    st[0], st[1], st[2], st[3] = x, v, V, 1.0 if held else 0.0


# not cached: numba's cache would keep a stale copy of the production kernels it calls
@njit(nogil=True)
def _chunk(gen, P: int, nburn: int, nrun: int, stride: int, delta: float, tau: float, var: float,
           phys: np.ndarray, E: np.ndarray, ed: tuple, Ks: np.ndarray, cfs: np.ndarray, pps: np.ndarray,
           sums: np.ndarray, counts: np.ndarray, cnt: np.ndarray) -> None:
    """P paths: the reference on the fine noise, and one production-scheme level per K in Ks."""
    L = Ks.size
    # this chunk's own scratch for the eigen evaluation (chunks run on concurrent threads)
    ed = (ed[0], ed[1], ed[2], ed[3], np.zeros(3, dtype=np.complex128), np.zeros(3, dtype=np.complex128))
    st = np.zeros((P, 4))
    xi = np.empty(P)
    for p in range(P):
        xi[p] = math.sqrt(var) * gen.standard_normal()
    ex = math.exp(-delta / tau)
    sd = math.sqrt(var * -math.expm1(-2.0 * delta / tau))
    xs, vs, Vs = np.zeros((L, 1, P)), np.zeros((L, 1, P)), np.zeros((L, 1, P))
    Fs, xm, fext = np.zeros((1, P)), np.zeros((1, P)), np.zeros((1, P))
    stuck = np.zeros((L, 1, P), dtype=np.bool_)
    centre = np.zeros((L, 1, P))
    for j in range(L):
        centre[j, 0, :] = xi
    w = np.ones(P)
    cs = np.zeros((3, N_TAYLOR + 1))
    y0, y = np.zeros(3), np.zeros(3)
    kc = np.zeros(5, dtype=np.int64)
    for k in range(nburn + nrun):
        meas = k >= nburn
        for p in range(P):
            xn = ex * xi[p] + sd * gen.standard_normal()
            _ref_interval(st[p], xi[p], xn, delta, phys, E, ed, cnt, y0, y)
            xi[p] = xn
        if meas and (k + 1) % stride == 0:
            for p in range(P):
                x, v, V = st[p, 0], st[p, 1], st[p, 2]
                sums[0, 0] += V * V
                sums[0, 1] += v * V
                sums[0, 2] += v * v
                sums[0, 3] += x * x
                sums[0, 4] += v * xi[p]
                sums[0, 5] += st[p, 3]
            counts[0] += P
        for j in range(L):
            K = Ks[j]
            if (k + 1) % K == K // 2:
                d_step(xs[j], vs[j], Vs[j], centre[j], Fs, stuck[j], xm, fext, w, cfs[j], pps[j],
                        KIND_KINK, kc, cs)
                if meas:
                    for p in range(P):
                        v, V = vs[j, 0, p], Vs[j, 0, p]
                        sums[1 + j, 0] += V * V
                        sums[1 + j, 1] += v * V
                        sums[1 + j, 2] += v * v
                        sums[1 + j, 3] += xs[j, 0, p] * xs[j, 0, p]
                        sums[1 + j, 4] += v * xi[p]
                        sums[1 + j, 5] += 1.0 if stuck[j, 0, p] else 0.0
                    counts[1 + j] += P
            if (k + 1) % K == 0:
                centre[j, 0, :] = xi


def _eigen_data(h: Harvester) -> tuple:
    p = h.params
    A = np.array([[0.0, 1.0, 0.0], [0.0, -p.gamma, -p.Kv / p.m], [0.0, p.Kc, -1.0 / p.tau_p]])
    lam, W = np.linalg.eig(A)
    W = W.astype(np.complex128)
    Winv = np.linalg.inv(W)
    beta = Winv @ np.array([0.0, 1.0 / p.m, 0.0])
    return (lam.astype(np.complex128), W, Winv, beta.astype(np.complex128), np.zeros(0, np.complex128),
            np.zeros(0, np.complex128))


def reference_run(a: float, *, delta: float = 1e-3, schemes: tuple = ((20, "average"),), paths: int = 64,
                  replicas: int = 8, t_burn: float = 30.0, t_run: float = 100.0, seed: int = 0,
                  w_min: float = 1e-3, sample_every: float = 0.05, threads: int | None = None,
                  first_replica: int = 0) -> dict[str, Any]:
    """Run the reference and the scheme levels on common noise; per-replica moment averages.

    Parameters
    ----------
    a : float
        Kink strength (n = 1, N = 1, other parameters at their defaults), > 0.
    delta : float
        Spacing of the exact noise samples, > 0.
    schemes : tuple of (int, str)
        Production-scheme levels: step ``K * delta`` (K even) and kink rule (``"average"``,
        ``"hold"``).
    paths, replicas : int
        Paths per replica and independent replicas (one random stream each).
    w_min : float
        Crossing speed below which the reference holds a swinging unit at rest.

    Returns
    -------
    dict
        ``levels`` (names), ``moments[level][name]`` (array over replicas), ``wall_s``,
        ``counters`` (reference slow intervals, crossings, holds).
    """
    h = Harvester.build(a=a, n=1.0)
    p = h.params
    delta = check_real("delta", delta, low=0.0, low_open=True)
    w_min = check_real("w_min", w_min, low=0.0, low_open=True)
    for K, rule in schemes:
        if not isinstance(K, (int, np.integer)) or K < 2 or K % 2:
            raise ParameterError(f"schemes: each step K must be an even integer >= 2, got {K!r} "
                                 f"(type {type(K).__name__})")
    phys = np.array([p.m, p.gamma, p.Kv, p.Kc, p.tau_p, p.sigma, 0.0, a, w_min])
    M = np.zeros((5, 5))
    M[:3, :3] = [[0.0, 1.0, 0.0], [0.0, -p.gamma, -p.Kv / p.m], [0.0, p.Kc, -1.0 / p.tau_p]]
    M[1, 3] = 1.0 / p.m
    M[3, 4] = 1.0
    E = scipy.linalg.expm(M * delta)[:3]
    ed = _eigen_data(h)
    Ks = np.array([K for K, _ in schemes], dtype=np.int64)
    cfs = np.array([step_coefficients(h, K * delta) for K, _ in schemes]).reshape(len(schemes), -1)
    pps = np.array([physical_vector(h, 1e300, rule) for _, rule in schemes]).reshape(len(schemes), P_SIZE)
    nburn = int(round(t_burn / delta))
    nrun = int(round(t_run / delta))
    stride = max(1, int(round(sample_every / delta)))
    L = len(schemes)
    ss = np.random.SeedSequence(seed)

    def work(r: int):
        child = np.random.SeedSequence(ss.entropy, spawn_key=(first_replica + r,))
        gen = np.random.Generator(np.random.PCG64(child))
        sums, counts, cnt = np.zeros((L + 1, 6)), np.zeros(L + 1), np.zeros(4, dtype=np.int64)
        _chunk(gen, paths, nburn, nrun, stride, delta, p.tau, p.noise_variance, phys, E, ed, Ks, cfs, pps,
               sums, counts, cnt)
        return sums / counts[:, None], cnt

    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads or default_threads()) as pool:
        out = list(pool.map(work, range(replicas)))
    wall = time.perf_counter() - t0
    per = np.array([o[0] for o in out])  # (replicas, levels, moments)
    names = ["reference"] + [f"scheme dt={K * delta:g} {rule}" for K, rule in schemes]
    return {"a": a, "delta": delta, "w_min": w_min, "schemes": [list(s) for s in schemes], "levels": names,
            "per_replica": per, "wall_s": wall, "counters": np.sum([o[1] for o in out], axis=0).tolist(),
            "paths": paths, "replicas": replicas, "t_run": t_run, "t_burn": t_burn}


def _eta(per: np.ndarray) -> np.ndarray:
    return per[..., 0] / per[..., 4]


def summarize(run: dict[str, Any]) -> dict[str, Any]:
    """eta per level with its standard error, and each scheme level minus the reference
    (common noise, error over replicas), also for V2 and Pin (sigma = 1)."""
    per = run["per_replica"]
    n = per.shape[0]
    f = student_factor(n - 1) / math.sqrt(n)
    out: dict[str, Any] = {"levels": {}}
    for i, name in enumerate(run["levels"]):
        e = _eta(per[:, i])
        row = {"eta": float(e.mean()), "eta_se": float(e.std(ddof=1) * f), "V2": float(per[:, i, 0].mean()),
               "Pin": float(per[:, i, 4].mean()), "held": float(per[:, i, 5].mean())}
        if i > 0:
            for key, d in (("eta", e - _eta(per[:, 0])), ("V2", per[:, i, 0] - per[:, 0, 0]),
                           ("Pin", per[:, i, 4] - per[:, 0, 4])):
                row[f"minus_ref_{key}"] = float(d.mean())
                row[f"minus_ref_{key}_se"] = float(d.std(ddof=1) * f)
        out["levels"][name] = row
    return out


def draw(res: dict[str, Any], ax: Any) -> None:
    """Scheme minus reference of eta (relative, with its error over replicas) per level and a."""
    for key, st in res.items():
        levels = {k: v for k, v in st["levels"].items() if "minus_ref_eta" in v}
        ref = st["levels"]["reference"]["eta"]
        ax.errorbar(range(len(levels)), [v["minus_ref_eta"] / ref for v in levels.values()],
                    yerr=[v["minus_ref_eta_se"] / ref for v in levels.values()], fmt="o", capsize=3, label=key)
        ax.set_xticks(range(len(levels)), list(levels), fontsize=6, rotation=20)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_ylabel("(scheme - reference) / reference, eta")
    ax.legend(fontsize=7)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Command line: scheme minus reference per a, written with the per-level summary to JSON
    (``--out``) and drawn next to it (the same name with ``.png``)."""
    import argparse
    import json
    from pathlib import Path

    ap = argparse.ArgumentParser(prog="python -m validation.studies.kink.reference", description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    ap.add_argument("--delta", type=float, default=1e-3)
    ap.add_argument("--w-min", type=float, default=1e-3)
    ap.add_argument("--K", type=int, nargs="+", default=[40, 20, 10, 4],
                    help="scheme steps in units of delta")
    ap.add_argument("--replicas", type=int, nargs="+", default=[64])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    schemes = tuple((K, "average") for K in args.K) + ((20, "hold"),)
    res: dict[str, Any] = {}
    for i, a in enumerate(args.a):
        reps = args.replicas[i] if len(args.replicas) > 1 else args.replicas[0]
        run = reference_run(a, delta=args.delta, w_min=args.w_min, schemes=schemes, replicas=reps,
                            seed=args.seed + i)
        res[f"a{a:g}"] = {**summarize(run), "wall_s": run["wall_s"], "counters": run["counters"],
                         "delta": args.delta, "w_min": args.w_min, "replicas": reps, "paths": run["paths"],
                         "t_run": run["t_run"]}
        args.out.write_text(json.dumps(res, indent=1))
        print(a, json.dumps(res[f"a{a:g}"]["levels"]), flush=True)
    from validation.studies.cli import axes_plot

    axes_plot(draw)(res, args.out.with_suffix(".png"))
    return res


if __name__ == "__main__":  # pragma: no cover
    main()
