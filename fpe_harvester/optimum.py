"""The optimum of an observable over one parameter, with error bars: ``optimize(h, over="k")``.

Monte Carlo values of :math:`\\eta(k)` are noisy; their *differences* between nearby ``k`` are
far more precise when every ``k`` is simulated on the same noise paths (common random
numbers, CRN: the same seed, time step, burn-in, run length and paths for every ``k``).
Measured for the n = 3 ring (N = 3, a = 0.5, 16 replicas of 16 paths, t_run = 200, six
seeds): eta at k = -0.4 ... -0.6 has a standard deviation of 1.2e-3 to 1.4e-3 across seeds,
while its difference to eta(-0.5) has 2.1e-4 at |dk| = 0.05 and 4.1e-4 to 7.0e-4 at
|dk| = 0.1 (correlation 0.96 to 0.99 at |dk| <= 0.1): the variance of a difference is 10 to
40 times smaller than that of a value. That is what makes the position of a shallow maximum
measurable.

The search (:func:`maximize_noisy`, for any noisy objective ``f(x, batch)``):

1. **Bracket.** A uniform grid of ``points`` over the interval, averaged over the first
   ``pilot`` batches; its best point and its neighbours bracket the maximum.
2. **Local quadratic fit.** ``window`` equally spaced points across the bracket, every batch
   (a batch is one seed, shared by all ``x``: CRN inside a batch, batches independent). A
   quadratic is fitted to the batch-mean curve; its vertex is the optimum and its value there
   the maximum. A vertex outside the window moves the window (at most ``max_shifts`` times).
3. **Error bars by the jackknife over batches.** Batches are independent, points inside one
   batch are strongly correlated (that is CRN): so no per-point error is assumed independent.
   Deleting one batch at a time and refitting gives the standard error of the vertex and of
   its value, Student-t scaled with ``batches - 1`` degrees of freedom for the confidence
   interval. The quadratic's lack of fit is checked with a cubic over the same points: where
   the cubic's maximum, or its value there, differs from the quadratic's by more than twice
   the jackknife error of that difference, the difference is added to the error in quadrature.

The status is ``stable`` (converged: an interior vertex, a negative curvature in every
jackknife fit, the confidence interval inside the window and, with ``tol``, the standard error
of the optimum below it) or ``not_converged`` with a message that says which test failed and
what to do. For a harmonic ring the exact solver makes the objective deterministic: eta(k)
grows monotonically toward the threshold k_di, so its optimum over ``[k_di, 0]`` is the
marginal limit at k_di, a supremum that no stable ring attains: the status is ``marginal``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from .errors import ParameterError, check_choice, check_int, check_real
from .exact import k_di
from .model import Harvester, Params
from .result import QUANTITIES, Stats, Status
from .solve import choose_method, get_solver, solve
from .solvers import METHODS, Capabilities, capabilities

__all__ = ["Optimum", "maximize_noisy", "optimize", "default_bounds", "OVER", "refine_grid_maximum"]

#: Fields an optimization may vary (the ring size N is an integer: a sweep, not an optimum).
OVER = ("a", "n", "k", *(f for f in Params.__dataclass_fields__))


@dataclass(frozen=True)
class Optimum:
    """The maximum of an observable over one parameter, with its errors and a status.

    Attributes
    ----------
    over, maximize : str
        The parameter varied (e.g. ``"k"``) and the observable maximized (e.g. ``"eta"``).
    x_opt, x_opt_err : float or None
        Position of the maximum and its standard error (one sigma; 0 when exact).
    value, value_err : float or None
        The maximum and its standard error (one sigma; 0 when exact).
    x_ci, value_ci : (float, float) or None
        Confidence intervals at level ``confidence``.
    confidence : float
        Level of the confidence intervals, in (0, 1).
    status : Status
        ``stable`` (converged), ``marginal`` (a supremum at the stability threshold) or
        ``not_converged``; ``message`` says why and what to do.
    method : str
        The solver of the objective (``"exact"``, ``"mc"``), or ``"callable"``.
    info : Mapping
        Details: bracket, window, the points evaluated and their batch means, curvature,
        batches, evaluations, wall time.
    """

    over: str
    maximize: str
    x_opt: float | None
    x_opt_err: float | None
    value: float | None
    value_err: float | None
    x_ci: tuple[float, float] | None = None
    value_ci: tuple[float, float] | None = None
    confidence: float = 0.95
    status: Status = Status.NOT_CONVERGED
    message: str = ""
    method: str = ""
    info: Any = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", Status(self.status))
        object.__setattr__(self, "info", MappingProxyType(dict(self.info)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with the attributes' names (``over``, ``maximize``, ``x_opt``,
        ``x_opt_err``, ``value``, ``value_err``, ``x_ci``, ``value_ci``, ...)."""
        from .result import jsonable

        return {"over": self.over, "maximize": self.maximize, "x_opt": self.x_opt, "x_opt_err": self.x_opt_err,
                "value": self.value, "value_err": self.value_err,
                "x_ci": None if self.x_ci is None else list(self.x_ci),
                "value_ci": None if self.value_ci is None else list(self.value_ci),
                "confidence": self.confidence, "method": self.method, "status": self.status.value,
                "message": self.message, "info": jsonable(dict(self.info))}


def _fit(x: np.ndarray, y: np.ndarray, x0: float, scale: float) -> tuple[float, float, float, float, float]:
    """Vertex, value there and curvature of the least-squares quadratic through (x, y), and the
    cubic fit's local maximum and its value (the model check; NaN with fewer than 5 points or no
    maximum)."""
    u = (x - x0) / scale
    c2, c1, c0 = np.polyfit(u, y, 2)
    cubic = cubic_value = math.nan
    if u.size >= 5:
        d3, d2, d1, d0 = np.polyfit(u, y, 3)
        roots = np.roots([3 * d3, 2 * d2, d1])
        maxima = [r.real for r in roots if abs(r.imag) < 1e-12 and 6 * d3 * r.real + 2 * d2 < 0]
        if maxima:
            r = min(maxima, key=lambda r: abs(r - u.mean()))
            cubic, cubic_value = x0 + scale * r, float(((d3 * r + d2) * r + d1) * r + d0)
    if c2 >= 0.0:
        return math.nan, math.nan, float(c2), cubic, cubic_value
    v = -c1 / (2.0 * c2)
    return x0 + scale * v, c0 + c1 * v + c2 * v * v, float(c2), cubic, cubic_value


def _student(confidence: float, dof: int) -> float:
    from scipy.stats import t

    return float(t.ppf(0.5 + confidence / 2.0, dof))


def maximize_noisy(
    f: Callable[[float, int], float | None],
    bounds: tuple[float, float],
    *,
    batches: int = 8,
    pilot: int = 2,
    points: int = 9,
    window: int = 5,
    tol: float | None = None,
    max_batches: int = 32,
    max_shifts: int = 2,
    confidence: float = 0.95,
    progress: Callable[[int], None] | None = None,
) -> Optimum:
    """Maximize a noisy objective evaluated with common random numbers per batch.

    Parameters
    ----------
    f : callable ``f(x, batch) -> float or None``
        The objective at ``x`` on the noise of ``batch`` (0, 1, ...): calls with the same batch
        must share their random numbers, different batches must be independent. ``None`` or a
        non-finite value marks a point without a result (left out).
    bounds : (float, float)
        Search interval ``lo < hi``.
    batches : int
        Independent batches in the fit, >= 3 (default 8): the jackknife's sample size.
    pilot : int
        Batches averaged on the bracketing grid, in [1, batches] (default 2).
    points : int
        Bracketing grid size, >= 3 (default 9).
    window : int
        Points of the local quadratic fit, >= 4 (default 5).
    tol : float, optional
        Target standard error of the optimum's position, > 0: batches are doubled (up to
        ``max_batches``) until it is met; unmet, the status is ``not_converged``.
    max_batches : int
        Upper limit for ``batches`` when ``tol`` asks for more, >= ``batches``.
    max_shifts : int
        How often the fit window may move toward a vertex outside it, >= 0.
    confidence : float
        Level of the confidence intervals, in (0, 1) (default 0.95).
    progress : callable, optional
        Called with the number of new evaluations after each group of them.

    Returns
    -------
    Optimum
        With ``method = "callable"``.

    Examples
    --------
    >>> def f(x, b):  # a common offset per batch, smaller independent noise per point
    ...     r = np.random.default_rng([b, int(x * 1e6) % 2**31])
    ...     return 1 - (x - 0.3) ** 2 + 0.1 * np.random.default_rng(b).normal() + 1e-4 * r.normal()
    >>> opt = maximize_noisy(f, (-1.0, 1.0))
    >>> opt.status.value, abs(opt.x_opt - 0.3) < 4 * opt.x_opt_err
    ('stable', True)
    """
    lo, hi = (check_real("bounds", b) for b in bounds)
    if not lo < hi:
        raise ParameterError(f"bounds must satisfy low < high, got ({lo!r}, {hi!r})")
    batches = check_int("batches", batches, low=3)
    pilot = check_int("pilot", pilot, low=1, high=batches)
    points = check_int("points", points, low=3)
    window = check_int("window", window, low=4)
    if tol is not None:
        tol = check_real("tol", tol, low=0.0, low_open=True)
    max_batches = check_int("max_batches", max_batches, low=batches)
    max_shifts = check_int("max_shifts", max_shifts, low=0)
    confidence = check_real("confidence", confidence, low=0.0, high=1.0, low_open=True, high_open=True)

    cache: dict[tuple[float, int], float] = {}

    def evaluate(xs: np.ndarray, nb: int) -> np.ndarray:
        new = [(float(x), b) for b in range(nb) for x in xs if (float(x), b) not in cache]
        for key in new:
            v = f(*key)
            cache[key] = math.nan if v is None else float(v)
        if progress is not None and new:
            progress(len(new))
        return np.array([[cache[(float(x), b)] for x in xs] for b in range(nb)])

    grid = np.linspace(lo, hi, points)
    coarse = evaluate(grid, pilot)
    good = np.isfinite(coarse).all(axis=0)
    info: dict[str, Any] = {"bounds": [lo, hi], "grid": grid.tolist(),
                            "grid_means": np.where(good, coarse.mean(axis=0), np.nan).tolist()}
    if not good.any():
        return Optimum("x", "f", None, None, None, None, confidence=confidence, status=Status.NOT_CONVERGED,
                       method="callable", info=info,
                       message="not converged: the objective gave no result anywhere on the search grid")
    best = int(np.nanargmax(np.where(good, coarse.mean(axis=0), -np.inf)))
    w = _fit_window(evaluate, float(grid[best]), grid[1] - grid[0], (lo, hi), window, batches, tol,
                    max_batches, max_shifts)
    if w.jack is None:
        return Optimum("x", "f", None, None, None, None, confidence=confidence, method="callable",
                       info={**info, "window": w.xs.tolist()},
                       message=f"not converged: only {w.xs_ok.size} of the {window} points around "
                               f"x = {w.center:.6g} gave a result; a quadratic needs 3")
    info.update(window=w.xs_ok.tolist(), window_means=w.Y.mean(axis=0).tolist(), curvature=w.fit[2] / w.step ** 2,
                batches=w.nb, shifts=w.shifts, evaluations=len(cache),
                jackknife_curvature_max=float(np.nanmax(w.jack[:, 2])) / w.step ** 2)
    t = _student(confidence, w.nb - 1)
    if not w.inside:
        return _edge_optimum(w, (lo, hi), t, confidence, info)
    return _fitted_optimum(w, t, tol, confidence, info)


@dataclass
class _Window:
    """The local fit of :func:`maximize_noisy`: the window's points (``xs``; ``xs_ok`` those with a
    result in every batch), the batch values there (``Y``, batches x points), the fit (vertex,
    value, curvature, cubic maximum and its value, in :func:`_fit`'s units), whether the vertex is
    inside the window, the jackknife fits and their standard errors (``None`` with fewer than 3
    points), the batches, the moves of the window, its centre and the grid step."""

    xs: np.ndarray
    xs_ok: np.ndarray
    Y: np.ndarray
    fit: tuple[float, float, float, float, float]
    inside: bool
    jack: np.ndarray | None
    se: np.ndarray | None
    nb: int
    shifts: int
    center: float
    step: float


def _fit_window(evaluate: Callable[[np.ndarray, int], np.ndarray], center: float, step: float,
                bounds: tuple[float, float], window: int, nb: int, tol: float | None, max_batches: int,
                max_shifts: int) -> _Window:
    """Fit a quadratic over ``window`` points across the bracket around ``center``; move the window
    toward a vertex outside it (at most ``max_shifts`` times) and double the batches while the
    position's error exceeds ``tol`` (up to ``max_batches``)."""
    lo, hi = bounds
    shifts = 0
    while True:
        left = min(max(lo, center - step), hi - 2 * step)
        xs = np.linspace(left, left + 2 * step, window)
        Y = evaluate(xs, nb)
        ok = np.isfinite(Y).all(axis=0)
        xs_ok, Y = xs[ok], Y[:, ok]
        if xs_ok.size < 3:
            nan = (math.nan,) * 5
            return _Window(xs, xs_ok, Y, nan, False, None, None, nb, shifts, center, step)
        fit = _fit(xs_ok, Y.mean(axis=0), center, step)
        x_v = fit[0]
        inside = math.isfinite(x_v) and xs[0] <= x_v <= xs[-1]
        if not inside and shifts < max_shifts:
            target = x_v if math.isfinite(x_v) else float(xs_ok[np.argmax(Y.mean(axis=0))])
            moved = float(np.clip(target, lo, hi))
            if abs(moved - center) > 0.25 * step and not (xs[0] <= lo and moved <= xs[0]) \
                    and not (xs[-1] >= hi and moved >= xs[-1]):
                center, shifts = moved, shifts + 1
                continue
        jack = np.array([_fit(xs_ok, np.delete(Y, b, axis=0).mean(axis=0), center, step) for b in range(nb)])
        # per column: NaN where some jackknife fit has no maximum (a cubic without one leaves the
        # quadratic's errors intact)
        se = np.sqrt((nb - 1) / nb * ((jack - jack.mean(axis=0)) ** 2).sum(axis=0))
        if tol is not None and inside and se[0] > tol and nb < max_batches:
            nb = min(2 * nb, max_batches)
            continue
        return _Window(xs, xs_ok, Y, fit, inside, jack, se, nb, shifts, center, step)


def _edge_optimum(w: _Window, bounds: tuple[float, float], t: float, confidence: float,
                  info: dict[str, Any]) -> Optimum:
    """No interior vertex: the best point evaluated, without an error on its position."""
    lo, hi = bounds
    means = w.Y.mean(axis=0)
    i = int(np.argmax(means))
    x_b = float(w.xs_ok[i])
    y_se = float(np.std(w.Y[:, i], ddof=1) / math.sqrt(w.nb))
    at_lo, at_hi = w.xs[0] <= lo, w.xs[-1] >= hi
    where = ("at the low end" if at_lo and x_b == w.xs_ok[0] else
             "at the high end" if at_hi and x_b == w.xs_ok[-1] else None)
    why = (f"the maximum is {where} of the search interval [{lo:.6g}, {hi:.6g}]: widen the bounds"
           if where else "the quadratic fit has no interior maximum in its window (flat or noisy "
                         "objective): more batches or a wider interval")
    return Optimum("x", "f", x_b, None, float(means[i]), y_se, value_ci=(means[i] - t * y_se,
                   means[i] + t * y_se), confidence=confidence, status=Status.NOT_CONVERGED,
                   method="callable", info=info, message=f"not converged: {why}; reported: the best "
                   f"point evaluated (no error on its position)")


def _fitted_optimum(w: _Window, t: float, tol: float | None, confidence: float, info: dict[str, Any]) -> Optimum:
    """The interior vertex with its jackknife errors, widened by the fit's lack of fit, and a
    status that says whether the maximum is resolved."""
    assert w.jack is not None and w.se is not None
    x_v, y_v, _, x_cubic, y_cubic = w.fit
    se, nb = w.se.copy(), w.nb
    # lack of fit: the cubic's maximum off the quadratic's vertex, or its value off the
    # quadratic's, by more than twice the jackknife error of that difference adds the difference
    # to the position's or the value's error
    model_note = ""
    for i, (name, delta, jk) in enumerate((("position", x_cubic - x_v, w.jack[:, 3] - w.jack[:, 0]),
                                           ("value", y_cubic - y_v, w.jack[:, 4] - w.jack[:, 1]))):
        delta_se = float(np.sqrt((nb - 1) / nb * np.sum((jk - jk.mean()) ** 2)))
        info["model_shift" if i == 0 else "model_value_shift"] = [delta, delta_se]
        if math.isfinite(delta) and math.isfinite(delta_se) and abs(delta) > 2.0 * delta_se:
            se[i] = math.hypot(se[i], delta)
            model_note += (f"; the cubic fit moves the maximum's {name} by {delta:.2g} (+- {delta_se:.1g}), "
                           f"added to its error (a narrower bracket, i.e. more grid points, reduces it)")
    info.update(x_opt_cubic=x_cubic, value_cubic=y_cubic)
    x_ci = (x_v - t * se[0], x_v + t * se[0])
    y_ci = (y_v - t * se[1], y_v + t * se[1])
    problems = []
    if not np.isfinite(se[:3]).all() or info["jackknife_curvature_max"] >= 0.0:
        problems.append("the curvature is not negative in every jackknife fit: the maximum is not "
                        "resolved; use more batches (or more replicas per point)")
    elif x_ci[0] < w.xs_ok[0] or x_ci[1] > w.xs_ok[-1]:
        problems.append(f"the confidence interval [{x_ci[0]:.6g}, {x_ci[1]:.6g}] is wider than the fit "
                        f"window [{w.xs_ok[0]:.6g}, {w.xs_ok[-1]:.6g}]; use more batches")
    if tol is not None and not se[0] <= tol:
        problems.append(f"the standard error {se[0]:.3g} of the optimum exceeds tol = {tol:g} after "
                        f"{nb} batches; raise max_batches")
    x_err = float(se[0]) if math.isfinite(se[0]) else None
    y_err = float(se[1]) if math.isfinite(se[1]) else None
    return Optimum("x", "f", float(x_v), x_err, float(y_v), y_err,
                   x_ci=x_ci if x_err is not None else None, value_ci=y_ci if y_err is not None else None,
                   confidence=confidence, status=Status.NOT_CONVERGED if problems else Status.STABLE,
                   method="callable", info=info,
                   message=("not converged: " + "; ".join(problems)) if problems else
                   f"converged: interior maximum from a quadratic fit over {w.xs_ok.size} points and {nb} "
                   f"independent batches (common random numbers inside each); {confidence:.0%} intervals "
                   "from the jackknife over batches" + model_note)


def default_bounds(h: Harvester, over: str) -> tuple[float, float]:
    """Search interval when none is given: for ``over = "k"``, ``[k_di, 0]`` for a harmonic ring
    (eta's supremum is at k_di) and ``[3 k_di, 0]`` for a nonlinear one (n > 2 rings stay
    confined beyond k_di; the paper's maxima lie within 1.5 k_di).

    Raises
    ------
    ParameterError
        ``over = "k"`` with ``N = 1`` (no coupling), or any other ``over`` (no natural interval).
    """
    if over != "k":
        raise ParameterError(f"bounds: no default search interval for over = {over!r}; give bounds=(low, high)")
    if h.N == 1:
        raise ParameterError("over = 'k' needs a ring: N >= 2 (N = 1 has no coupling); got N = 1")
    kd = k_di(h.N, h.a, h.k4)
    assert kd is not None
    return (kd, 0.0) if h.is_linear else (3.0 * kd, 0.0)


def refine_grid_maximum(f: Callable[[float], float], grid: np.ndarray, values: np.ndarray,
                        xatol: float = 1e-10) -> tuple[float, float, int]:
    """Maximum of a deterministic ``f`` from its ``values`` on an increasing ``grid``: the best
    grid point, then a bounded scalar search (Brent) in the two cells around it when it is
    interior, kept only if it improves on the grid.

    Parameters
    ----------
    f : callable
        The objective; ``-inf`` where it has no value (e.g. no stationary state).
    grid, values : ndarray
        The grid and ``f`` on it (``-inf`` or NaN where undefined).
    xatol : float
        Absolute tolerance of the search relative to ``max(1, |x|)``.

    Returns
    -------
    (x_opt, f_opt, index)
        ``index`` is the best grid point's (0 or ``len(grid) - 1``: the maximum is at an end of
        the interval and no search was made).

    Examples
    --------
    >>> g = np.linspace(-1.0, 1.0, 11)
    >>> x, y, i = refine_grid_maximum(lambda x: -(x - 0.123) ** 2, g, -(g - 0.123) ** 2)
    >>> round(x, 6), i
    (0.123, 6)
    """
    from scipy.optimize import minimize_scalar

    vals = np.where(np.isnan(values), -np.inf, values)
    best = int(np.argmax(vals))
    x_opt, y_opt = float(grid[best]), float(vals[best])
    if 0 < best < len(grid) - 1 and math.isfinite(y_opt):
        found = minimize_scalar(lambda x: -f(float(x)), bounds=(float(grid[best - 1]), float(grid[best + 1])),
                                method="bounded", options={"xatol": xatol * max(1.0, abs(x_opt))})
        if -found.fun >= y_opt:
            x_opt, y_opt = float(found.x), float(-found.fun)
    return x_opt, y_opt, best


def _optimize_exact(h: Harvester, name: str, over: str, maximize: str, lo: float, hi: float,
                    points: int) -> Optimum:
    """An objective exact to round-off (solver ``name``): grid, then a bounded scalar search in the
    best cell."""

    def value(x: float) -> float:
        v = solve(h.replace(**{over: x}), name).value(maximize)[0]
        return -math.inf if v is None else float(v)

    grid = np.linspace(lo, hi, max(points, 41))
    x_opt, y_opt, best = refine_grid_maximum(value, grid, np.array([value(float(x)) for x in grid]))
    info = {"bounds": [lo, hi], "grid_points": len(grid)}
    if not math.isfinite(y_opt):
        return Optimum(over, maximize, None, None, None, None, status=Status.NOT_CONVERGED, method=name,
                       info=info, message=f"not converged: no stationary state in {over} in [{lo:.6g}, {hi:.6g}]")
    kd = k_di(h.N, h.a, h.k4) if h.N > 1 else None
    final = solve(h.replace(**{over: x_opt}), name)
    if final.status is Status.MARGINAL and over == "k":
        return Optimum(over, maximize, x_opt, 0.0, y_opt, 0.0, (x_opt, x_opt), (y_opt, y_opt),
                       status=Status.MARGINAL, method=name, info=info, message=(
                           f"marginal: {maximize} grows monotonically toward the threshold k_di = {kd:.10g}; "
                           f"its supremum {y_opt:.10g} is the finite marginal limit at k_di, approached as "
                           "k -> k_di+ but attained by no stable ring (at k_di x of the critical mode diffuses)"))
    if best in (0, len(grid) - 1):
        end = "low" if best == 0 else "high"
        return Optimum(over, maximize, x_opt, 0.0, y_opt, 0.0, status=Status.NOT_CONVERGED, method=name,
                       info=info, message=f"not converged: the maximum is at the {end} end of the search "
                       f"interval {over} in [{lo:.6g}, {hi:.6g}]: widen the bounds")
    return Optimum(over, maximize, x_opt, 0.0, y_opt, 0.0, (x_opt, x_opt), (y_opt, y_opt), status=Status.STABLE,
                   method=name, info=info, message="converged: exact objective, interior maximum (bounded "
                   "scalar search, |dx| < 1e-10 relative)")


def optimize(
    h: Harvester,
    over: str = "k",
    bounds: tuple[float, float] | None = None,
    maximize: str = "eta",
    *,
    method: str = "auto",
    tol: float | None = None,
    seed: int = 2017,
    batches: int = 8,
    replicas: int = 48,
    points: int = 9,
    mc_tol: float = 1e-2,
    confidence: float = 0.95,
    progress: bool | None = None,
) -> Optimum:
    """The ``over`` that maximizes ``maximize`` for the harvester ``h``, with error bars.

    .. math::

        x_{opt} = \\arg\\max_{x \\in [lo, hi]} \\eta(h; x), \\qquad
        \\eta_{max} = \\eta(h; x_{opt})

    Parameters
    ----------
    h : Harvester
        The system; its value of ``over`` is ignored.
    over : str
        Parameter varied: ``"k"`` (coupling, default), ``"a"``, ``"n"`` or a :class:`Params` field.
    bounds : (float, float), optional
        Search interval; default :func:`default_bounds` (``over = "k"`` only).
    maximize : str
        Observable, one of :data:`~fpe_harvester.result.QUANTITIES` (default ``"eta"``).
    method : {"auto", "exact", "fpe", "mc"}
        Solver of the objective. The optimizer takes one whose objective is exact to round-off
        (bounded scalar search) or random with common random numbers across the interval
        (:func:`maximize_noisy`); Fokker--Planck is neither. ``"auto"``: the first solver of
        ``method="auto"``'s order that handles the interval's middle and is of such a kind
        (exact for a harmonic system, Monte Carlo otherwise).
    tol : float, optional
        Random objective: target standard error of the optimum's position, > 0 (batches are
        doubled up to 32 until met). Default: the ``batches`` given.
    seed : int
        Base seed, >= 0: batch ``b`` uses one child seed of it at every point.
    batches : int
        Independent batches of common random numbers, >= 3 (default 8).
    replicas : int
        Monte Carlo replicas per point and batch, >= 2 (default 48). The paths per replica are
        the plan's times 16/replicas (at least 2), so the cost per point does not depend on it;
        with enough replicas (:func:`montecarlo.controls.regression.enough_dof`) every point uses the
        martingale control variates (:func:`montecarlo.estimate`; no harmonic twin).
    points : int
        Bracketing grid size, >= 3 (default 9).
    mc_tol : float
        Random objective: the solver's tolerance, in (0, 1), that plans its runs (for Monte Carlo
        the time step, burn-in and run length), once at the middle of the interval, then frozen so
        that all points share their noise.
    confidence : float
        Level of the confidence intervals, in (0, 1).
    progress : bool or None
        Progress bar on stderr over evaluations (``None``: only on a terminal).

    Returns
    -------
    Optimum
        ``x_opt`` and ``value`` with their errors (``to_dict()`` has the same names). With a
        random solver, ``value_err`` also holds the solver's systematic (time-step) error at the
        optimum where it reports one (Monte Carlo: :meth:`montecarlo.Estimate.systematic`).

    Raises
    ------
    ParameterError
        Invalid ``over``, ``maximize``, ``method``, bounds or settings.

    Examples
    --------
    >>> opt = optimize(Harvester.build(a=0.5, n=2, N=3))
    >>> opt.status.value, round(opt.x_opt, 10) == round(k_di(3, 0.5), 10)
    ('marginal', True)
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    check_choice("over", over, OVER)
    check_choice("maximize", maximize, QUANTITIES)
    check_choice("method", method, ("auto", *METHODS))
    seed = check_int("seed", seed, low=0)
    replicas = check_int("replicas", replicas, low=2)
    mc_tol = check_real("mc_tol", mc_tol, low=0.0, high=1.0, low_open=True, high_open=True)
    if bounds is None:
        lo, hi = default_bounds(h, over)
    else:
        if not isinstance(bounds, (tuple, list)) or len(bounds) != 2:
            raise ParameterError(f"bounds must be (low, high), got {bounds!r} (type {type(bounds).__name__})")
        lo, hi = (check_real("bounds", b) for b in bounds)
        if not lo < hi:
            raise ParameterError(f"bounds must satisfy low < high, got ({lo!r}, {hi!r})")
    mid = h.replace(**{over: 0.5 * (lo + hi)})  # validates over's values (e.g. a > 0) at both ends
    h.replace(**{over: lo}), h.replace(**{over: hi})
    name = _objective_solver(mid, method)
    if capabilities(name).tol is None:
        return _optimize_exact(h, name, over, maximize, lo, hi, points)
    return _optimize_noisy(h, name, over, maximize, lo, hi, mid, tol=tol, seed=seed, batches=batches,
                           replicas=replicas, points=points, mc_tol=mc_tol, confidence=confidence, progress=progress)


def _unusable(caps: Capabilities) -> str | None:
    """Why the optimizer cannot maximize this solver's objective (None: it can): it needs an
    objective exact to round-off or a random one with common random numbers across parameter values."""
    if caps.tol is None or caps.common_random_numbers is not None:
        return None
    return ("the optimizer needs an objective exact to round-off or a random one with common random numbers; "
            f"{caps.title} gives neither")


def _objective_solver(mid: Harvester, method: str) -> str:
    """The solver of the objective: ``method``, or for ``"auto"`` the first solver of
    :func:`~fpe_harvester.solve.choose_method`'s order that handles the interval's middle and
    whose objective the optimizer can use (:func:`_unusable`).

    Raises
    ------
    ParameterError
        ``method`` gives neither an exact nor a common-random-number objective, or does not
        handle the system.
    """
    if method == "auto":
        return choose_method(mid, unusable=_unusable)
    fault = _unusable(capabilities(method))
    if fault:
        raise ParameterError(f"method {method!r} cannot be optimized over: {fault}; use 'auto'")
    reason = get_solver(method).unsupported_reason(mid)
    if reason:
        raise ParameterError(f"method {method!r}: {reason}")
    return method


def _optimize_noisy(h: Harvester, name: str, over: str, maximize: str, lo: float, hi: float, mid: Harvester, *,
                    tol: float | None, seed: int, batches: int, replicas: int, points: int, mc_tol: float,
                    confidence: float, progress: bool | None) -> Optimum:
    """A random objective (solver ``name``): :func:`maximize_noisy` over runs that share their random
    numbers across ``over`` within each batch (the solver's ``common_random_numbers`` settings,
    planned once at the interval's middle ``mid`` at accuracy ``mc_tol``)."""
    import time

    from tqdm import tqdm

    start = time.perf_counter()
    base = get_solver(name, tol=mc_tol, seed=seed, progress=False)
    frozen = {**base.capabilities.common_random_numbers(base, mid, replicas), "progress": False}
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(64)]
    bias: dict[tuple[float, int], float] = {}

    def f(x: float, b: int) -> float | None:
        r: Stats = solve(h.replace(**{over: x}), name, seed=seeds[b], **frozen)
        value = r.value(maximize)[0]
        if value is None or r.status not in (Status.STABLE, Status.NOT_CONVERGED):
            return None
        if maximize == "eta":
            # the solver's own estimate of its systematic (time-step) error on eta, if it has one
            bias[(x, b)] = float(r.info.get("eta_systematic") or 0.0)
        return value

    with tqdm(desc=f"optimize {maximize} over {over}", unit="run", file=sys.stderr, leave=False,
              disable=None if progress is None else not progress) as bar:
        core = maximize_noisy(f, (lo, hi), batches=batches, points=points, tol=tol,
                              max_batches=max(batches, 32 if tol is not None else batches),
                              confidence=confidence, progress=bar.update)
    info = {**core.info, "runs": {"method": name, **frozen, "seeds": seeds[:core.info.get("batches", batches)]},
            "wall_time": time.perf_counter() - start}
    value_err, message = core.value_err, core.message
    if core.x_opt is not None and bias and core.value_err is not None:
        near = min({x for x, _ in bias}, key=lambda x: abs(x - core.x_opt))
        b = float(np.mean([v for (x, _), v in bias.items() if x == near]))
        info["time_step_error_at_optimum"] = b
        value_err = math.hypot(core.value_err, b)
        message += (f"; the error of the maximum includes the solver's estimate {b:.2g} of its systematic "
                    "(time-step) error at the optimum")
    value_ci = core.value_ci
    if value_ci is not None and value_err is not None and core.value_err:
        t = (core.value - value_ci[0]) / core.value_err
        value_ci = (core.value - t * value_err, core.value + t * value_err)
    return Optimum(over, maximize, core.x_opt, core.x_opt_err, core.value, value_err, core.x_ci, value_ci,
                   confidence, core.status, message, name, info)
