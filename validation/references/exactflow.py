"""A second Monte Carlo construction for one unit, independent of :mod:`montecarlo`.

At the strong kink (n = 1 and n near 1, a = 2) Fokker--Planck does not converge, so the report
checks the product's Monte Carlo against this one. It shares no integrator code with
:mod:`montecarlo` (its kernels are in :mod:`._flowkernel`) and is built differently:

* **the linear flow is exact, noise included.** Between events of the on-site force the state
  ``y = (x, v, V, xi)`` obeys :math:`dy = (Ay + b f)\\,dt + g\\,dW`; a step of length ``h`` is
  :math:`y(h) = e^{Ah}y(0) + \\int_0^h e^{A(h-u)}b f(u)\\,du + \\eta` with
  :math:`\\eta \\sim N(0, Q(h))` drawn exactly (the Van Loan matrices, computed here in 40-digit
  arithmetic), so for a constant force the step has no time-step error at all;
* **n = 1: the kink's force is exact on each side.** The zero crossings of x within a step are
  located on the conditional mean of the path given the step's noise
  (:math:`E[\\eta(t)\\mid\\eta(h)] = Q(t)e^{A^T(h-t)}Q(h)^{-1}\\eta`), and the force switches
  there; a unit whose crossing speed falls below ``w_trap`` while the drive cannot move it
  (:math:`|\\sigma\\xi - K_vV| < a`) is set at rest until the drive exceeds a (its swings would
  shrink like :math:`e^{-\\gamma t/3}` with ever more crossings; docs/model.md);
* **n > 1: the force over a step is the discrete gradient** :math:`-(U(x_1) - U(x_0))/(x_1 - x_0)`,
  solved implicitly: exact for a path linear in time and continuous across x = 0, where
  :math:`U'` is not smooth.

States are sampled at the steps' ends (exact in law for an exact step, so the averages carry no
quadrature error). Errors are standard errors over independent paths. What remains is the step's
bias (crossing times, the trap threshold and the release's timing for n = 1, the discrete gradient
for n > 1), measured against step size and ``w_trap`` by
:mod:`validation.studies.kink.exactflow_bias` on common noise (:func:`coupled`) and recorded in
``validation/data/exactflow_bias.json``; :func:`solve_flow` adds the recorded bound to its errors.
"""

from __future__ import annotations

import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mpmath
import numba
import numpy as np

from fpe_harvester import Harvester, Stats, Status
from fpe_harvester.errors import ParameterError, check_int, check_real

from . import _flowkernel as fk

__all__ = ["FlowSettings", "StepMatrices", "Variant", "step_matrices", "coupled", "difference", "solve_flow",
           "BIAS_PATH", "bias_bound", "DEGREE"]

#: Names of the kernels' event counters (:data:`._flowkernel.N_COUNTS`).
_EVENTS = ("crossings", "collapses", "releases", "overflows", "dg_unsolved", "searches")
#: Degree of the polynomials (in t/h) of the path within a step.
DEGREE = 12
#: The recorded bias study (:mod:`validation.studies.kink.exactflow_bias`).
BIAS_PATH = Path(__file__).resolve().parents[1] / "data" / "exactflow_bias.json"


@dataclass(frozen=True)
class FlowSettings:
    """Settings of an exact-flow run.

    Attributes
    ----------
    step : float
        Time step h, in (0, 0.1]. Default 0.02.
    w_trap : float
        n = 1: crossing speed below which a held unit is set at rest, in [0, 1). Default 1e-2.
    paths : int
        Independent paths (>= 2); the standard errors are over them. Default 64.
    t_run : float
        Measured time per path (> 0), after ``t_burn`` (>= 0) from rest. Defaults 4000 and 50.
    seed : int
        Seed (>= 0) of the paths' generators (numpy SeedSequence).
    controls : int
        Largest degree (0 to 4) of the monomials :math:`f` whose generator :math:`\\mathcal{L}f` serves
        as control variate (:func:`controlled`); 0: none. Default 4 (69 controls: at n = 1, a = 2 they
        divide the variance of eta by about 15, V2 by 20, Pin by 10).
    batches : int
        Batches per path (>= 2 with controls) on which the controls' coefficients are fitted.
        Default 30.
    cv_every : int
        The generator is evaluated every ``cv_every`` steps (>= 1; still an exact time average of a
        mean-zero function, at a fraction of the cost). Default 5.
    """

    step: float = 0.02
    w_trap: float = 1e-2
    paths: int = 64
    t_run: float = 4000.0
    t_burn: float = 50.0
    seed: int = 0
    controls: int = 4
    batches: int = 30
    cv_every: int = 5

    def __post_init__(self) -> None:
        check_real("step", self.step, low=0.0, low_open=True, high=0.1)
        check_real("w_trap", self.w_trap, low=0.0, high=1.0, high_open=True)
        check_int("paths", self.paths, low=2)
        check_real("t_run", self.t_run, low=0.0, low_open=True)
        check_real("t_burn", self.t_burn, low=0.0)
        check_int("seed", self.seed, low=0)
        check_int("controls", self.controls, low=0, high=4)
        check_int("batches", self.batches, low=2 if self.controls else 1)
        check_int("cv_every", self.cv_every, low=1)


def _check(h: Harvester) -> None:
    if h.N != 1:
        raise ParameterError(f"the exact-flow construction simulates one unit: N must be 1, got {h.N}")


def _drift(h: Harvester, dps: int) -> tuple[Any, Any, Any]:
    p = h.params
    with mpmath.workdps(dps):
        mf = lambda v: mpmath.mpf(float(v))  # noqa: E731 - the inputs' exact binary values
        m, g, Kv, Kc, s, tau, D, tp = (mf(getattr(p, k)) for k in ("m", "gamma", "Kv", "Kc", "sigma", "tau", "D",
                                                                    "tau_p"))
        A = mpmath.matrix([[0, 1, 0, 0], [0, -g, -Kv / m, s / m], [0, Kc, -1 / tp, 0], [0, 0, 0, -1 / tau]])
        b = mpmath.matrix([0, 1 / m, 0, 0])
        gn = mpmath.matrix([0, 0, 0, mpmath.sqrt(2 * D) / tau])
    return A, b, gn


def _cov(A: Any, gn: Any, t: Any) -> Any:
    """Q(t) = int_0^t e^{Au} g g^T e^{A^T u} du (Van Loan's block exponential)."""
    M = mpmath.zeros(8, 8)
    for i in range(4):
        for j in range(4):
            M[i, j] = -A[i, j] * t
            M[i, 4 + j] = gn[i] * gn[j] * t
            M[4 + i, 4 + j] = A[j, i] * t
    F = mpmath.expm(M)
    F12 = F[0:4, 4:8]
    F22 = F[4:8, 4:8]
    return F22.T * F12


@dataclass(frozen=True)
class StepMatrices:
    """Everything a kernel needs for one step length ``h`` (float64, from 40-digit arithmetic).

    ``E`` = :math:`e^{Ah}`, ``Pv`` = :math:`\\int_0^h e^{Au}b\\,du`, ``L`` the Cholesky factor of
    ``Q(h)``; ``Ex[c, d]``, ``Cx[c, d]``: coefficients of :math:`(t/h)^d` in the x row of
    :math:`e^{At}` and of :math:`Q(t)e^{A^T(h-t)}Q(h)^{-1}`; ``pvec[d]`` = :math:`A^d b/(d+1)!`
    (so that :math:`P(\\tau) = \\sum_d` ``pvec[d]`` :math:`\\tau^{d+1}`)."""

    h: float
    E: np.ndarray
    Pv: np.ndarray
    L: np.ndarray
    Ex: np.ndarray
    Cx: np.ndarray
    pvec: np.ndarray


def step_matrices(h: Harvester, step: float, dps: int = 40) -> StepMatrices:
    """The step's matrices for ``h`` (one unit) and step length ``step``."""
    _check(h)
    A, b, gn = _drift(h, dps)
    with mpmath.workdps(dps):
        hs = mpmath.mpf(float(step))
        E = mpmath.expm(A * hs)
        Qh = _cov(A, gn, hs)
        L = mpmath.cholesky(Qh)
        Qinv = mpmath.inverse(Qh)
        powers = [mpmath.eye(4)]
        for _ in range(DEGREE + 1):
            powers.append(A * powers[-1])
        Pv = sum((powers[d] * b * hs ** (d + 1) / mpmath.factorial(d + 1) for d in range(DEGREE + 2)),
                 mpmath.zeros(4, 1))
        Ex = np.array([[float(powers[d][0, c] * hs**d / mpmath.factorial(d)) for d in range(DEGREE + 1)]
                       for c in range(4)])
        pvec = np.array([[float((powers[d] * b)[r] / mpmath.factorial(d + 1)) for r in range(4)]
                         for d in range(DEGREE + 1)])
        # x row of the conditional mean's matrix at Chebyshev nodes of [0, 1], interpolated exactly
        nodes = [(1 - mpmath.cos(mpmath.pi * k / DEGREE)) / 2 for k in range(DEGREE + 1)]
        rows = []
        for s in nodes:
            t = s * hs
            C = (_cov(A, gn, t) if t > 0 else mpmath.zeros(4, 4)) * mpmath.expm(A * (hs - t)).T * Qinv
            rows.append([C[0, c] for c in range(4)])
        V = mpmath.matrix([[s**d for d in range(DEGREE + 1)] for s in nodes])
        Cx = np.array([[float(v) for v in mpmath.lu_solve(V, mpmath.matrix([r[c] for r in rows]))]
                       for c in range(4)])
        to = lambda M, r, c: np.array([[float(M[i, j]) for j in range(c)] for i in range(r)])  # noqa: E731
        return StepMatrices(float(step), to(E, 4, 4), np.array([float(v) for v in Pv]), to(L, 4, 4), Ex, Cx, pvec)


def _pp(h: Harvester) -> np.ndarray:
    p = h.params
    return np.array([p.m, p.gamma, p.Kv, p.Kc, p.sigma, p.tau, p.D, p.tau_p, h.a, h.n], dtype=float)


@dataclass(frozen=True)
class Variant:
    """One construction run on the common noise: its step (a multiple of the fine one) and w_trap."""

    mult: int
    w_trap: float


@dataclass
class _Run:
    means: np.ndarray          # (paths, variants, 4): V^2, v xi, v^2, v V
    counts: np.ndarray         # (paths, variants, N_COUNTS)
    shells: np.ndarray         # (paths, len(edges) - 1)
    bobs: np.ndarray           # (paths, variants, batches, 4): the observables per batch
    bcv: np.ndarray            # (paths, variants, batches, controls): the generator's averages per batch
    seconds: float
    extra: dict[str, Any] = field(default_factory=dict)


def monomials(degree: int) -> np.ndarray:
    """Exponents (i, j, k, l) of every monomial :math:`x^i v^j V^k \\xi^l` of degree 1 to ``degree``."""
    return np.array([e for e in np.ndindex(degree + 1, degree + 1, degree + 1, degree + 1)
                     if 1 <= sum(e) <= degree], dtype=np.int64).reshape(-1, 4)


def _run(h: Harvester, fine: float, variants: tuple[Variant, ...], paths: int, t_run: float, t_burn: float,
         seed: int, edges: np.ndarray | None = None, degree: int = 0, cv_every: int = 5, batches: int = 1) -> _Run:
    _check(h)
    mults = np.array([v.mult for v in variants], dtype=np.int64)
    every = int(np.lcm.reduce(mults))
    mats = {mu: step_matrices(h, fine * mu) for mu in sorted(set(mults.tolist()))}
    base = mats[1] if 1 in mats else step_matrices(h, fine)
    n_burn = int(math.ceil(t_burn / (fine * every))) * every
    n_run = max(int(round(t_run / (fine * every))), 1) * every
    seeds = np.random.SeedSequence(seed).generate_state(paths, dtype=np.uint32).astype(np.int64)
    edges = np.zeros(0) if edges is None else np.asarray(edges, dtype=float)
    nv = len(variants)
    means = np.zeros((paths, nv, fk.N_OBS))
    counts = np.zeros((paths, nv, fk.N_COUNTS), dtype=np.int64)
    shells = np.zeros((paths, max(edges.size - 1, 0)))
    powers = monomials(degree)
    bobs = np.zeros((paths, nv, batches if degree else 0, fk.N_OBS))
    bcv = np.zeros((paths, nv, batches if degree else 0, powers.shape[0]))
    bjump = np.zeros_like(bcv)
    pick = [mats[v.mult] for v in variants]
    pc, Ex, Cx = _trimmed(base, pick)
    t0 = time.perf_counter()
    args = (seeds, n_burn, n_run, every, base.L, base.E, mults, np.stack([m.E for m in pick]),
            np.stack([m.Pv for m in pick]), base.pvec, np.array([m.h for m in pick]), Ex, Cx, pc,
            np.array([v.w_trap for v in variants]), _pp(h), h.n == 1.0, edges, means, counts, shells, powers,
            cv_every, bobs, bcv, bjump)
    # chunks of paths in threads (the kernel releases the GIL; each path has its own stream)
    workers = max(1, min(numba.get_num_threads(), paths))
    bounds = np.linspace(0, paths, workers + 1).astype(int)
    with ThreadPoolExecutor(workers) as pool:
        list(pool.map(lambda k: fk.run_paths(int(bounds[k]), int(bounds[k + 1]), *args), range(workers)))
    if degree:
        # the controls: the generator's time average plus the collapses' jumps per unit time
        samples = np.bincount(np.arange(n_run // every) * batches // (n_run // every), minlength=batches)
        bcv += bjump / (samples * every * fine)[None, None, :, None]
    return _Run(means, counts, shells, bobs, bcv, time.perf_counter() - t0,
                {"t_run": n_run * fine, "t_burn": n_burn * fine, "every": every * fine})


def _trimmed(base: StepMatrices, pick: list[StepMatrices]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The path's polynomials without the trailing terms that cannot change a double: ``pc``
    (x response to a unit force, in the elapsed time, up to the longest step) and the stacked
    ``Ex``, ``Cx`` (in t/h; a term counts by its size times a state of order 1, or times the
    noise's standard deviation)."""
    longest = max(m.h for m in pick)
    pc = np.concatenate([[0.0], base.pvec[:, 0]])
    size = np.abs(pc) * longest ** np.arange(pc.size)
    keep = int(np.nonzero(size >= 1e-18 * size.max())[0].max()) + 1
    Ex, Cx = np.stack([m.Ex for m in pick]), np.stack([m.Cx for m in pick])
    sd = np.stack([np.sqrt(np.sum(m.L**2, axis=1)) for m in pick])            # (variants, 4)
    col = (np.abs(Ex) + np.abs(Cx) * sd[:, :, None]).max(axis=(0, 1))
    deg = int(np.nonzero(col >= 1e-20)[0].max()) + 1
    return pc[:keep].copy(), Ex[:, :, :deg].copy(), Cx[:, :, :deg].copy()


def _estimate(means: np.ndarray, p_R: float, sigma: float) -> dict[str, tuple[float, float]]:
    """eta, V2, Pin, v2, vV with standard errors over the paths' means (rows of ``means``)."""
    P = means.shape[0]
    V2, vxi, v2, vV = (means[:, q] for q in range(4))
    Pin = sigma * vxi
    mV, mP = float(V2.mean()), float(Pin.mean())
    cov = np.cov(np.stack([V2, Pin]), ddof=1) / P
    eta = mV / (p_R * mP)
    rel2 = cov[0, 0] / mV**2 + cov[1, 1] / mP**2 - 2 * cov[0, 1] / (mV * mP)
    se = lambda a: float(a.std(ddof=1) / math.sqrt(P))  # noqa: E731
    return {"eta": (eta, abs(eta) * math.sqrt(max(rel2, 0.0))), "V2": (mV, math.sqrt(cov[0, 0])),
            "Pin": (mP, math.sqrt(cov[1, 1])), "v2": (float(v2.mean()), se(v2)), "vV": (float(vV.mean()), se(vV))}


def controlled(bobs: np.ndarray, bcv: np.ndarray, folds: int = 2, ridge: float = 1e-6) -> np.ndarray:
    """Each path's mean observables with their control variates subtracted, cross-fitted over paths.

    ``bobs`` (paths, batches, quantities) and ``bcv`` (paths, batches, controls) are batch means;
    the coefficients for one fold of paths are fitted by (ridge-stabilised) least squares on the
    batches of the other folds, so that the result is unbiased however many controls there are
    (their stationary mean is 0) and the batches of a path never fit its own coefficients. Returns
    (paths, quantities)."""
    P, B, _ = bobs.shape
    Y, C = bobs.reshape(P * B, -1), bcv.reshape(P * B, -1)
    scale = C.std(axis=0)
    scale[scale == 0.0] = 1.0
    C = C / scale
    out = np.empty_like(Y)
    fold = np.repeat(np.arange(P) % folds, B)
    for f in range(folds):
        fit = fold != f
        X = C[fit] - C[fit].mean(axis=0)
        Yf = Y[fit] - Y[fit].mean(axis=0)
        beta = np.linalg.solve(X.T @ X + ridge * X.shape[0] * np.eye(X.shape[1]), X.T @ Yf)
        out[fold == f] = Y[fold == f] - C[fold == f] @ beta
    return out.reshape(P, B, -1).mean(axis=1)


def coupled(h: Harvester, fine: float, variants: tuple[Variant, ...], *, paths: int, t_run: float,
            t_burn: float = 50.0, seed: int = 0) -> dict[str, Any]:
    """Run several variants on the same noise: each one's estimates, event rates and per-path
    estimates (``per_path[q]``: array (paths, variants); eta linearised about variant 0's pooled
    ratio), from which :func:`difference` gives any two variants' paired difference.

    Returns a dict: ``variants`` (step, w_trap, estimates, event counts per unit time, JSON-ready),
    ``per_path`` (numpy arrays), ``paths``, ``t_run``, ``seconds``."""
    run = _run(h, fine, variants, paths, t_run, t_burn, seed)
    p = h.params
    out = []
    ref = run.means[:, 0, :]
    per_path = {q: np.stack([_per_path(run.means[:, j, :], p, q, ref) for j in range(len(variants))], axis=1)
                for q in _QUANTITIES}
    for j, v in enumerate(variants):
        rates = run.counts[:, j, :].sum(axis=0) / (paths * run.extra["t_run"])
        out.append({"step": fine * v.mult, "w_trap": v.w_trap,
                    "estimates": _estimate(run.means[:, j, :], p.R, p.sigma),
                    "per_unit_time": dict(zip(_EVENTS, rates.tolist()))})
    return {"system": {"a": h.a, "n": h.n}, "fine_step": fine, "paths": paths, **run.extra,
            "seconds": run.seconds, "variants": out, "per_path": per_path}


def difference(res: dict[str, Any], j: int, k: int, q: str) -> tuple[float, float]:
    """Variant ``j`` minus variant ``k`` of a :func:`coupled` run on quantity ``q``: the mean of
    the paths' paired differences and its standard error."""
    d = res["per_path"][q][:, j] - res["per_path"][q][:, k]
    return float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size))


#: The quantities estimated.
_QUANTITIES = ("eta", "V2", "Pin", "v2", "vV")


def _per_path(means: np.ndarray, p: Any, q: str, ref: np.ndarray | None = None) -> np.ndarray:
    """Each path's estimate of ``q`` from its means (V^2, v xi, v^2, v V). eta is linearised about
    the pooled ratio of ``ref`` (default ``means``), so that the mean of the per-path values is the
    pooled estimate to first order and every variant shares one linearisation."""
    ref = means if ref is None else ref
    V2, Pin = means[:, 0], p.sigma * means[:, 1]
    if q == "eta":
        mV, mP = ref[:, 0].mean(), p.sigma * ref[:, 1].mean()
        return (mV / mP + (V2 - mV) / mP - mV * (Pin - mP) / mP**2) / p.R
    return {"V2": V2, "Pin": Pin, "v2": means[:, 2], "vV": means[:, 3]}[q]


def bias_bound(h: Harvester, settings: FlowSettings, path: Path = BIAS_PATH) -> dict[str, float] | None:
    """The recorded bound on the step's bias (relative, per quantity) for the system and the
    settings' ``h`` and ``w_trap``, or None when the study has no such row."""
    if not path.exists():
        return None
    rows = json.loads(path.read_text()).get("bounds", [])
    for row in rows:
        if (row["system"] == {"a": h.a, "n": h.n} and math.isclose(row["step"], settings.step)
                and math.isclose(row["w_trap"], settings.w_trap if h.n == 1.0 else row["w_trap"])):
            return {q: float(v) for q, v in row["relative_bias_bound"].items()}
    return None


def solve_flow(h: Harvester, settings: FlowSettings = FlowSettings(), edges: np.ndarray | None = None) -> Stats:
    """eta, V2, Pin, v2, vV of one unit by the exact-flow construction.

    The estimates use the generator's control variates (``settings.controls``, :func:`controlled`).
    Each error is the standard error over the paths and, where the bias study recorded a bound
    for this system, step and ``w_trap`` (:func:`bias_bound`), that bound added in quadrature
    (``info["bias_bound"]``; without a recorded bound ``info["bias_bound"]`` is None and the
    message says the step's bias is not included). ``edges`` (optional): the energy shells'
    edges; ``info["shells"]`` and ``info["shells_err"]`` then hold the fraction of time in each.
    """
    run = _run(h, settings.step, (Variant(1, settings.w_trap),), settings.paths, settings.t_run,
               settings.t_burn, settings.seed, edges, settings.controls, settings.cv_every, settings.batches)
    means = controlled(run.bobs[:, 0], run.bcv[:, 0]) if settings.controls else run.means[:, 0, :]
    est = _estimate(means, h.params.R, h.params.sigma)
    bound = bias_bound(h, settings)
    err = {q: math.hypot(e, (bound or {}).get(q, 0.0) * abs(v)) for q, (v, e) in est.items()}
    counts = run.counts[:, 0, :].sum(axis=0)
    info: dict[str, Any] = {"seconds": run.seconds, "settings": settings.__dict__, "bias_bound": bound,
                            "events": dict(zip(_EVENTS,
                                               counts.tolist())), **run.extra}
    if edges is not None:
        info["edges"] = np.asarray(edges, dtype=float).tolist()
        info["shells"] = run.shells.mean(axis=0).tolist()
        info["shells_err"] = (run.shells.std(axis=0, ddof=1) / math.sqrt(settings.paths)).tolist()
    why = (f"step bias bound from {BIAS_PATH.name} included" if bound is not None
           else "no recorded bias bound for this system and step: errors are standard errors only")
    V2, Pin = est["V2"], est["Pin"]
    return Stats.from_moments(V2=V2[0], V2_err=err["V2"], Pin=Pin[0], Pin_err=err["Pin"], R=h.params.R,
                              eta_err=err["eta"], v2=est["v2"][0], v2_err=err["v2"], vV=est["vV"][0],
                              vV_err=err["vV"], status=Status.STABLE, method="exactflow",
                              message=f"exact-flow Monte Carlo, {settings.paths} paths x {run.extra['t_run']:g}, "
                                      f"h = {settings.step:g}" + (f", w_trap = {settings.w_trap:g}" if h.n == 1 else "")
                                      + (f", control variates of degree <= {settings.controls}" if settings.controls
                                         else "") + f"; {why}", info=info)
