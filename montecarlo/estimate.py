"""From replica moments to estimates: means, standard errors, covariance, Richardson bias.

Every statistic here is computed over *replicas* (independent), never over the correlated
samples inside a path. Standard errors are Student-t scaled: the sample standard error times
:math:`t_{\\nu}(\\Phi(1))`, the quantile of Student's t with the estimate's residual degrees
of freedom :math:`\\nu` at the one-sigma level (0.8413), so that the reported one-sigma interval
covers 68 % also for few replicas (the factor is 1.84 for 2 replicas, 1.08 for 8, 1.02 for 32).
With control variates in the ensemble, the means are the regression (control-variate)
estimates of :mod:`.controls.regression`; without, plain means. Two kinds exist, both with an exactly known
mean: the harmonic twin's moments (:mod:`.controls.twin`; the paths must start from its stationary law)
and the martingale sums of :mod:`montecarlo.controls.martingale` (mean 0 for any start). The set used
is the richest candidate (:data:`montecarlo.controls.sets.CONTROL_SETS`, most controls) among those whose residual degrees
of freedom meet :func:`montecarlo.controls.regression.enough_dof`: a rule that does not look at the estimated
variances (see :func:`montecarlo.controls.sets.choose_controls`).

Time-step error, two policies. Without extrapolation the reported numbers are the fine level's
(``dt/2``) and the Richardson estimate of its bias is added to the error in quadrature. With
``extrapolate`` (three coupled levels ``dt/2, dt, 2 dt``) the reported numbers are the
Richardson extrapolation from ``(dt, dt/2)``, per replica ``F0 + (F0 - F1)/(2^p - 1)``, whose
remaining bias is of higher order; the difference between the extrapolations from ``(2 dt, dt)``
and from ``(dt, dt/2)`` measures it, and :data:`RESIDUAL_RULE` turns it into the systematic term
added to the error in quadrature.

``eta`` is the ratio of the estimated means, :math:`\\eta = \\overline{V^2}/(R\\,\\overline{P_{in}})`
(not a mean of per-replica ratios, whose bias is of the order of the squared per-replica
relative error), with the first-order (delta-method) error.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import ThreadpoolController

from fpe_harvester.errors import ParameterError
from fpe_harvester.model import Harvester

from .coefficients import onsite_kind
from .controls.regression import crossfit_estimate, regression_estimate
from .controls.sets import CONTROL_SETS, SetColumns, choose_controls, control_columns
from .ensemble import Ensemble
from .layout import KIND_KINK

__all__ = ["Estimate", "estimate", "BIAS_ORDER", "bias_order", "student_factor", "RESIDUAL_RULE"]

#: Weak order assumed when the coarse/fine difference is turned into a bias estimate of the
#: fine level, bias = (coarse - fine) / (2^p - 1) (so fine - bias is the extrapolation), i.e.
#: the time-step law eta(dt) = eta0 + c dt^p, per on-site treatment: smooth forces and the kink
#: (the fitted orders: docs/methods.md, "Why the settings are what they are").
BIAS_ORDER = {"smooth": 2.0, "nonsmooth": 2.0}

#: Systematic error of the extrapolated value, from the difference D = R(2 dt) - R(dt) of the
#: extrapolations from the pairs (2 dt, dt) and (dt, dt/2) and its standard error D_se: with a
#: remaining error c dt^q, R(dt) is off by D / (2^q - 1). The rule is
#: ``(|D| + RESIDUAL_RULE[1] * D_se) / (2^RESIDUAL_RULE[0] - 1)``, i.e. q = 3 (the next order after
#: p = 2) plus one standard error of D; on the exact discrete values of the harmonic steps it
#: bounds the true remaining error (tests/montecarlo/test_extrapolate.py; docs/methods.md, "Why
#: the settings are what they are").
RESIDUAL_RULE = (3.0, 1.0)

#: The controls of a regression: (C, their exact means mu, cross-fitted).
Controls = tuple[np.ndarray, np.ndarray, bool]

#: Observables estimated from the replica moments (``eta`` is derived from V2 and Pin).
_NAMES = ("V2", "Pin", "v2", "vV", "x2", "stuck")
#: Observables estimated in a second pass (:func:`_second_pass`), so that adding them leaves the
#: bits of the first pass's numbers unchanged (a least-squares fit of more columns rounds
#: differently).
_SECOND = ("V2", "Pin", "d2")


def bias_order(h: Harvester, kind: int | None = None) -> float:
    """Weak order of the time-step bias assumed for the on-site treatment ``kind`` (default
    ``h``'s, see :data:`BIAS_ORDER`)."""
    kind = onsite_kind(h) if kind is None else kind
    return BIAS_ORDER["nonsmooth" if kind == KIND_KINK else "smooth"]


@dataclass(frozen=True)
class Estimate:
    """Means, standard errors and bias estimates over the valid replicas of an ensemble.

    Attributes
    ----------
    mean, se : dict of float
        Per observable (``V2, Pin, eta, v2, vV, x2, stuck, d2``): estimate and standard error
        (level 0, the finest step).
    bias : dict of float
        Richardson estimate of the time-step bias of level 0, value(dt/2) - value(0), from the
        coarse level's difference (coarse - fine) / (r^p - 1) at the step ratio r of the two
        levels (0 without a coarse level).
    bias_se : dict of float
        Standard error of ``bias`` over replicas (the levels share their noise, so it is
        much smaller than ``se``).
    extrapolated : bool
        Whether ``mean`` is the Richardson extrapolation (then ``residual`` is the systematic
        part of the error, else ``bias``).
    residual, residual_se : dict of float
        With three levels: the higher-order estimate :math:`(R(2dt) - R(dt))/(2^q - 1)` of the
        extrapolation's remaining bias (q = :data:`RESIDUAL_RULE` [0]) and its standard error;
        0 otherwise.
    cov_V2_Pin : float
        Covariance of the V2 and Pin estimates (of their means).
    replicas : int
        Replicas that measured anything (paths that all escaped in burn-in leave none).
    identity_V2, identity_power : tuple of float
        ``(residual, standard error)`` of :math:`V^2 - K_c\\tau_p\\langle vV\\rangle` and of
        :math:`P_{in} - m\\gamma\\langle v^2\\rangle - K_v\\langle vV\\rangle`.
    drift : dict of float
        Per observable, level 0's first half of the measured window minus the whole window
        (a transient left by a too-short burn-in shows here), and ``drift_se`` its error.
    reduction : dict of float
        Variance-reduction factor of the control variates per observable (plain variance of
        the mean / control-variate variance); empty without controls.
    control : bool
        Whether control variates were used.
    controls : str
        Which set (a name of :data:`CONTROL_SETS`, or ``"none"``).
    """

    mean: dict[str, float]
    se: dict[str, float]
    bias: dict[str, float]
    bias_se: dict[str, float]
    cov_V2_Pin: float
    replicas: int
    identity_V2: tuple[float, float]
    identity_power: tuple[float, float]
    drift: dict[str, float] = field(default_factory=dict)
    drift_se: dict[str, float] = field(default_factory=dict)
    reduction: dict[str, float] = field(default_factory=dict)
    control: bool = False
    controls: str = "none"
    extrapolated: bool = False
    residual: dict[str, float] = field(default_factory=dict)
    residual_se: dict[str, float] = field(default_factory=dict)

    def systematic(self, name: str) -> float:
        """Time-step part of the error: the bias estimate of the fine level, or for an
        extrapolated value the bound of :data:`RESIDUAL_RULE` on its remaining bias."""
        if not self.extrapolated:
            return abs(self.bias[name])
        return abs(self.residual.get(name, 0.0)) + RESIDUAL_RULE[1] * self.residual_se.get(name, 0.0)

    def total_error(self, name: str) -> float:
        """Standard error and the time-step part (:meth:`systematic`) added in quadrature."""
        return math.hypot(self.se[name], self.systematic(name))

    def rel_error(self, name: str = "eta") -> float:
        """Total error relative to the value (inf when the value is 0 or undefined)."""
        value = abs(self.mean[name])
        return self.total_error(name) / value if value > 0 else math.inf


def _per_replica(e: Ensemble, h: Harvester, level: int, names: tuple[str, ...] = _NAMES) -> np.ndarray:
    m = e.moments(level)
    cols = {"V2": m["V2"], "Pin": h.params.sigma * m["vxi"], "v2": m["v2"], "vV": m["vV"],
            "x2": m["x2"], "stuck": m["stuck"], "d2": m["d2"]}
    return np.column_stack([cols[name] for name in names])


def _ratio(mean: np.ndarray, cov: np.ndarray, R: float) -> tuple[float, float]:
    """eta = V2/(R Pin) from the (V2, Pin) entries of a mean vector and its covariance."""
    V2, Pin = mean[0], mean[1]
    if not Pin:
        return math.nan, math.nan
    eta = V2 / (R * Pin)
    grad = np.array([1.0 / (R * Pin), -eta / Pin])
    var = float(grad @ cov[:2, :2] @ grad)
    return float(eta), math.sqrt(max(var, 0.0))


def _linear_eta(delta: np.ndarray, cov: np.ndarray, mean: np.ndarray, R: float) -> tuple[float, float]:
    """First-order change of eta from changes ``delta`` of (V2, Pin) with covariance ``cov``."""
    V2, Pin = mean[0], mean[1]
    grad = np.array([1.0 / (R * Pin), -V2 / (R * Pin * Pin)])
    return float(grad @ delta[:2]), math.sqrt(max(float(grad @ cov[:2, :2] @ grad), 0.0))


def estimate(e: Ensemble, h: Harvester, order: float | None = None, control: bool | None = None,
             controls: str | None = None, extrapolate: bool | None = None) -> Estimate:
    """Statistics of an ensemble of ``h`` (see :class:`Estimate`).

    Parameters
    ----------
    e : Ensemble
        Output of :func:`montecarlo.simulate`.
    h : Harvester
        The simulated problem (for sigma, R, Kc, tau_p, m, gamma, Kv).
    order : float, optional
        Weak order for the Richardson bias; default :func:`bias_order`.
    control : bool, optional
        Use control variates (:mod:`.controls.regression`). None: whenever some set of
        :data:`CONTROL_SETS` is available (the twin's needs the paths started from its stationary
        law; either needs no escaped path and the degrees of freedom of
        :func:`montecarlo.controls.regression.enough_dof`). True raises if none is.
    controls : str, optional
        Use this set of :data:`CONTROL_SETS` only (raises if it is not available). None: the
        richest available set (:func:`choose_controls`).
    extrapolate : bool, optional
        Report the Richardson extrapolation (needs three levels,
        :func:`montecarlo.simulate` ``third_level``). None: whenever the ensemble has three.
    """
    # the regressions' matrices are small (replicas x controls): BLAS threads only contend, and on
    # a loaded machine made a cross-fitted estimate 20-200x slower
    with _blas().limit(limits=1, user_api="blas"):
        return _estimate(e, h, order, control, controls, extrapolate)


@functools.cache
def _blas() -> ThreadpoolController:
    """The BLAS thread-pool controller, made once (making one scans the loaded libraries)."""
    return ThreadpoolController()


def _estimate(e: Ensemble, h: Harvester, order: float | None, control: bool | None, controls: str | None,
              extrapolate: bool | None) -> Estimate:
    """:func:`estimate`'s body."""
    if controls is not None and controls not in CONTROL_SETS:
        raise ParameterError(f"controls must be None or one of {tuple(CONTROL_SETS)}, got {controls!r} "
                             f"(type {type(controls).__name__})")
    if order is None:
        order = bias_order(h, e.notes.get("onsite_kind"))
    if extrapolate and e.levels < 3:
        raise ParameterError(f"extrapolate=True needs three levels (simulate(..., richardson=True, "
                             f"third_level=True)), got dts {e.dts}")
    extrapolate = e.levels >= 3 if extrapolate is None else extrapolate
    fine = _per_replica(e, h, 0)
    coarse = _per_replica(e, h, 1) if e.levels > 1 else None
    coarsest = _per_replica(e, h, 2) if e.levels > 2 else None
    first = _per_replica(e, h, -1)
    valid = np.all(np.isfinite(fine[:, :5]), axis=1) & (fine[:, 1] != 0)
    for other in (coarse, coarsest):
        if other is not None:
            valid &= np.all(np.isfinite(other[:, :5]), axis=1)
    valid &= np.all(np.isfinite(first[:, :5]), axis=1)
    n = int(valid.sum())
    wanted = (controls,) if controls is not None else CONTROL_SETS
    sets = {} if control is False else {
        name: cols for name in wanted if (cols := control_columns(e, valid, name, n)) is not None}
    if (control or controls is not None) and not sets:
        raise ParameterError(
            f"control=True needs an ensemble with control variates ({controls or 'any set'}): a twin "
            f"started from its stationary law (start='twin') or accumulated controls "
            f"(controls=('martingale', 'boundary')), no escaped path and enough replicas; got twin {e.twin_kappa}, "
            f"start {e.start!r}, accumulated {tuple(e.ctl_names)}, escaped fraction "
            f"{e.escaped_fraction():g}, {n} replicas")
    use = bool(sets)
    if n < 2:
        nan = dict.fromkeys(_NAMES + ("eta", "d2"), math.nan)
        zero = dict.fromkeys(_NAMES + ("eta", "d2"), 0.0)
        return Estimate(dict(nan), dict(nan), dict(zero), dict(zero), math.nan, n, (math.nan, math.nan),
                        (math.nan, math.nan), dict(zero), dict(zero))
    R = h.params.R
    reduction: dict[str, float] = {}
    Ff = fine[valid]
    # e(h) = C h^p: coarse - fine = (r^p - 1) e(fine step) for a step ratio r (2, or 4 with
    # simulate's coarse_ratio=4)
    ratio = e.dts[1] / e.dts[0] if e.levels > 1 else 2.0
    scale = 1.0 / (ratio**order - 1.0)
    # the extrapolation per replica: its mean is that of the reported number
    Y = Ff + scale * (Ff - coarse[valid]) if extrapolate else Ff
    chosen = "none"
    if use:
        chosen, (mean, cov, plain_cov) = _choose(sets, Y, R)
        C, C_first, mu, crossfit = sets[chosen]
        for i, name in enumerate(_NAMES):
            if cov[i, i] > 0:
                reduction[name] = float(plain_cov[i, i] / cov[i, i])
    else:
        mean, cov = _plain(Y)
    est_mean = {name: float(mean[i]) for i, name in enumerate(_NAMES)}
    est_se = {name: math.sqrt(max(float(cov[i, i]), 0.0)) for i, name in enumerate(_NAMES)}
    est_mean["eta"], est_se["eta"] = _ratio(mean, cov, R)
    if use and est_se["eta"] > 0:
        reduction["eta"] = (_ratio(mean, plain_cov, R)[1] / est_se["eta"]) ** 2
    zero = dict.fromkeys(_NAMES + ("eta",), 0.0)
    controls_used = (C, mu, crossfit) if use else None
    # the coarse level ran the whole window, or its first half (coarse_half): the fine level and
    # the controls over the same (the controls are the fine level's: the twin runs at its step)
    half_controls = (C_first, mu, crossfit) if use else None
    base, base_controls = (first[valid], half_controls) if e.coarse_half else (Ff, controls_used)
    bias, bias_se = dict(zero), dict(zero)
    if coarse is not None:
        bias, bias_se = _scaled_difference(coarse[valid] - base, base_controls, mean, R, scale)
    residual, residual_se = dict(zero), dict(zero)
    if coarsest is not None:
        # R(2dt) - R(dt) with R(h) = F(h/2) + scale (F(h/2) - F(h)); the remaining error c dt^q of
        # R(dt) is that difference / (2^q - 1)
        Fc, Fcc = coarse[valid], coarsest[valid]
        D = (1.0 + 2.0 * scale) * Fc - scale * Fcc - (1.0 + scale) * Ff
        residual, residual_se = _scaled_difference(D, controls_used, mean, R, 1.0 / (2.0 ** RESIDUAL_RULE[0] - 1.0))
    # the twin's own first-half-minus-whole difference has mean 0 (it is stationary): the
    # control for the system's, which a transient would shift
    drift_controls = (C_first - C, np.zeros(C.shape[1]), crossfit) if use else None
    drift, drift_se = _scaled_difference(first[valid] - Ff, drift_controls, mean, R, 1.0)
    second = _second_pass(e, h, valid, extrapolate, scale, controls_used, drift_controls,
                          half_controls if e.coarse_half else controls_used)
    for out, part in zip((est_mean, est_se, bias, bias_se, residual, residual_se, drift, drift_se), second):
        out["d2"] = part
    p = h.params
    r1 = Ff[:, 0] - p.Kc * p.tau_p * Ff[:, 3]
    r2 = Ff[:, 1] - p.m * p.gamma * Ff[:, 2] - p.Kv * Ff[:, 3]
    return Estimate(
        mean=est_mean, se=est_se, bias=bias, bias_se=bias_se, cov_V2_Pin=float(cov[0, 1]), replicas=n,
        identity_V2=_mean_se(r1), identity_power=_mean_se(r2), drift=drift, drift_se=drift_se,
        reduction=reduction, control=use, controls=chosen, extrapolated=bool(extrapolate),
        residual=residual, residual_se=residual_se)


def _choose(sets: dict[str, SetColumns], Y: np.ndarray, R: float) -> tuple[str, tuple[np.ndarray, ...]]:
    """The set to use (:func:`choose_controls`) and its regression (:func:`_regression`).

    A cross-fitted set (many controls) is kept only where its variance of eta is below that of
    the richest in-sample set: with heavy-tailed replicas (short runs of the strong kink) its
    fit can add more variance than it removes. Both variances come from hundreds of replicas
    (:func:`montecarlo.controls.regression.crossfit_dof`), so the choice's preference for an
    underestimated variance is a few per cent of it (the coverage: docs/methods.md, "Generator
    controls").
    """
    chosen = choose_controls({name: cols.C.shape[1] for name, cols in sets.items()})
    fit = _regression(Y, *_controls(sets[chosen]))
    plain = {name: cols.C.shape[1] for name, cols in sets.items() if not cols.crossfit}
    if not sets[chosen].crossfit or not plain:
        return chosen, fit
    other = choose_controls(plain)
    other_fit = _regression(Y, *_controls(sets[other]))
    if _ratio(other_fit[0], other_fit[1], R)[1] < _ratio(fit[0], fit[1], R)[1]:
        return other, other_fit
    return chosen, fit


def _controls(cols: SetColumns) -> Controls:
    return cols.C, cols.mu, cols.crossfit


@functools.cache
def student_factor(dof: int) -> float:
    """Ratio of Student's t quantile with ``dof`` degrees of freedom to the normal one at 0.8413.

    Multiplying a sample standard error by it gives a one-sigma interval with 68.3 % coverage
    for normal data (the sample standard deviation of few replicas is itself uncertain).

    >>> round(student_factor(1), 3), round(student_factor(31), 3)
    (1.837, 1.016)
    """
    from scipy.stats import norm, t

    return float(t.ppf(norm.cdf(1.0), dof)) if dof >= 1 else math.inf


def _second_pass(e: Ensemble, h: Harvester, valid: np.ndarray, extrapolate: bool, scale: float,
                 controls: Controls | None, drift_controls: Controls | None,
                 bias_controls: Controls | None) -> tuple[float, ...]:
    """The :data:`_SECOND` observables' last entry (``d2``) as :func:`estimate` treats the first
    pass's: mean, standard error, bias and its error, residual and its error, drift and its
    error (0 where a level is missing; ``bias_controls`` those of the coarse level's window)."""
    levels = [_per_replica(e, h, i, _SECOND)[valid] if i < e.levels else None for i in range(3)]
    Ff, coarse, coarsest = levels
    first = _per_replica(e, h, -1, _SECOND)[valid]
    Y = Ff + scale * (Ff - coarse) if extrapolate else Ff
    mean, cov = _plain(Y) if controls is None else _regression(Y, *controls)[:2]
    name, R = _SECOND[-1], h.params.R
    out = [float(mean[-1]), math.sqrt(max(float(cov[-1, -1]), 0.0)), 0.0, 0.0, 0.0, 0.0]
    if coarse is not None:
        b, b_se = _scaled_difference(coarse - (first if e.coarse_half else Ff), bias_controls, mean, R, scale,
                                     _SECOND)
        out[2:4] = b[name], b_se[name]
    if coarsest is not None:
        D = (1.0 + 2.0 * scale) * coarse - scale * coarsest - (1.0 + scale) * Ff
        r, r_se = _scaled_difference(D, controls, mean, R, 1.0 / (2.0 ** RESIDUAL_RULE[0] - 1.0), _SECOND)
        out[4:6] = r[name], r_se[name]
    d, d_se = _scaled_difference(first - Ff, drift_controls, mean, R, 1.0, _SECOND)
    return (*out, d[name], d_se[name])


def _plain(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample mean of the rows of Y and the Student-scaled covariance of that mean."""
    n = Y.shape[0]
    mean = Y.mean(axis=0)
    Yc = Y - mean
    return mean, Yc.T @ Yc / (n - 1) / n * student_factor(n - 1) ** 2


def _regression(Y: np.ndarray, C: np.ndarray, mu: np.ndarray,
                crossfit: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regression mean of Y with controls C (expectation mu; cross-fitted with ``crossfit``,
    :func:`montecarlo.controls.regression.crossfit_estimate`), its Student-scaled covariance,
    and the Student-scaled covariance of the plain mean (for the variance-reduction factor)."""
    reg = (crossfit_estimate if crossfit else regression_estimate)(Y, C, mu)
    n = Y.shape[0]
    return reg.mean, reg.cov * student_factor(reg.dof) ** 2, reg.plain_cov * student_factor(n - 1) ** 2


def _scaled_difference(D: np.ndarray, controls: Controls | None, mean: np.ndarray, R: float, factor: float,
                       names: tuple[str, ...] = _NAMES) -> tuple[dict[str, float], dict[str, float]]:
    """Mean and standard error of a per-replica difference between levels or windows, times
    ``factor``, per observable and for eta (to first order): the regression on the ``controls``
    (C, their expectation mu, cross-fitted or not) when given, the plain mean otherwise.

    No choice between the two by their estimated variances: that choice favours whichever
    variance happens to be underestimated (docs/methods.md, "Why the settings are what they are").
    """
    if controls is None:
        d_mean, d_cov = _plain(D)
    else:
        d_mean, d_cov, _ = _regression(D, *controls)
    value = {name: float(d_mean[i]) * factor for i, name in enumerate(names)}
    se = {name: math.sqrt(max(float(d_cov[i, i]), 0.0)) * factor for i, name in enumerate(names)}
    b, b_se = _linear_eta(d_mean, d_cov, mean, R)
    value["eta"], se["eta"] = b * factor, b_se * factor
    return value, se


def _mean_se(x: np.ndarray) -> tuple[float, float]:
    return float(x.mean()), float(x.std(ddof=1) / math.sqrt(x.size)) * student_factor(x.size - 1)
