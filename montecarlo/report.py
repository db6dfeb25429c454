"""The Monte Carlo solver's result: statistics, status and message, and the run's details.

Private module of :mod:`montecarlo.solver`: everything :meth:`MonteCarlo.solve
<montecarlo.solver.MonteCarlo.solve>` reports once the replicas have run.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fpe_harvester.exact import growth_rate, k_di
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats, Status

from .coefficients import ONSITE_NAMES, linear_stiffness, onsite_kind
from .ensemble import Ensemble
from .estimate import Estimate, bias_order
from .layout import KIND_KINK
from .plan import RunPlan, burn_in
from .steps import STEPPERS

__all__ = ["result", "unresolved_pin", "DRIFT_SIGMAS", "DRIFT_SHARE"]

_RNG = "numpy Generator(PCG64) drawn inside numba, one SeedSequence child per (replica, chunk)"
#: The burn-in drift (eta over the first half of the measured window minus the whole) that
#: counts as a transient, in standard errors and relative to tol.
DRIFT_SIGMAS, DRIFT_SHARE = 3.0, 1.0 / 3.0


def result(h: Harvester, ens: Ensemble, est: Estimate, met: bool, plan: RunPlan, wall: float,
           harmonic_status: str | None, *, name: str, tol: float, threshold: float, batch: int) -> Stats:
    """The :class:`~fpe_harvester.Stats` of a finished run of ``h``.

    ``met``: whether the tolerance ``tol`` was met; ``wall``: the solve's wall time in seconds;
    ``harmonic_status``: the harmonic ring's class (``"unstable"``, ``"marginal"``, ...) or None;
    ``threshold``: the escape amplitude; ``batch``: replicas per batch.
    """
    info = _info(h, ens, est, plan, wall, tol, batch)
    esc = ens.escaped_fraction()
    kd = k_di(h.N, h.a) if h.N > 1 else None
    if harmonic_status == "unstable":
        rate = growth_rate(h)
        return Stats(status=Status.UNSTABLE, method=name, growth_rate=rate, info=info, message=(
            f"unstable: harmonic ring with k = {h.k:g} beyond k_di = {kd:.10g}; the critical "
            f"mode grows like exp({rate:.4g} t). {esc:.1%} of the simulated paths passed "
            f"|x| = {threshold:g} (times in info); no stationary statistics exist."))
    if est.replicas < 2:
        where = (f"(|x| > {threshold:g}) during burn-in (median escape time "
                 f"{info['escape_time_median']})")
        if h.confinement == "metastable":
            return Stats(status=Status.METASTABLE, method=name, info=info, message=(
                f"metastable: {est.replicas} replica(s) measured anything, too few for an error "
                f"bar: the paths escaped {where}. No statistics."))
        return Stats(status=Status.NOT_CONVERGED, method=name, info=info, message=(
            f"not converged: this system is {h.confinement} (it has a stationary state), but "
            f"the simulated paths blew up {where}: a numerical instability of the integrator at "
            f"dt = {plan.dt:g}. Lower dt. No statistics."))
    stats = _stats(h, est, info, name)
    return _label(h, stats, est, esc, met, kd, harmonic_status, tol, threshold)



def unresolved_pin(h: Harvester, est: Estimate, step: str, dt: float) -> float:
    """Bound on the part of Pin that the joint step cannot see where xi decorrelates within a
    step (tau < dt), added to Pin's error in quadrature.

    In the stationary state :math:`(1 + \\gamma\\tau)\\langle v\\xi\\rangle = \\sigma D/m
    - (\\tau/m)\\langle \\partial_x f\\, v\\xi\\rangle - (\\tau K_v/m)\\langle V\\xi\\rangle` (Ito on
    :math:`v\\xi` and :math:`f\\xi`, f the force on the unit): the forces left out of the step's
    linear flow (the kicks and the neighbours' force, held over the step) shift Pin by
    :math:`\\approx\\tau^2\\sigma^2D\\kappa/m^2`, :math:`\\kappa` their stiffness. The step's
    estimator of :math:`v\\xi` (:func:`montecarlo.steps.joint._d_step_joint`) is the linear
    flow's at tau << dt, nearly a constant over replicas, so this term is no part of its spread.
    :math:`\\kappa` is bounded by the virial stiffness :math:`m\\langle v^2\\rangle/\\langle x^2\\rangle`
    (the total stiffness, equal to it for a harmonic unit at K_v = 0) minus the flow's, plus the coupling's
    largest mode stiffness :math:`4|k| + 16|k_4|`. Zero for the other steps and for tau >= dt.
    """
    p = h.params
    if step != "joint" or p.tau >= dt or not est.mean["x2"] > 0.0:
        return 0.0
    kappa = abs(p.m * est.mean["v2"] / est.mean["x2"] - linear_stiffness(h)) + 4.0 * abs(h.k) + 16.0 * abs(h.k4)
    return p.tau**2 * p.sigma**2 * p.D * kappa / p.m**2


def _stats(h: Harvester, est: Estimate, info: dict[str, Any], name: str) -> Stats:
    """The numbers: each mean with its total error (standard error and systematic term)."""
    mean, se = est.mean, est.se
    tot = est.total_error
    info["eta_standard_error"] = se["eta"]
    info["Pin_unresolved"] = unresolved_pin(h, est, info["step"], info["dt"])
    return Stats.from_moments(
        V2=mean["V2"], Pin=mean["Pin"], R=h.params.R, V2_err=tot("V2"),
        Pin_err=math.hypot(tot("Pin"), info["Pin_unresolved"]),
        cov_V2_Pin=est.cov_V2_Pin, eta_err=tot("eta"), v2=mean["v2"],
        v2_err=tot("v2"), vV=mean["vV"], vV_err=tot("vV"), x2=mean["x2"], x2_err=tot("x2"),
        d2=mean["d2"] if h.N > 1 else None, d2_err=tot("d2") if h.N > 1 else None, method=name, info=info)

def _label(h: Harvester, s: Stats, est: Estimate, esc: float, met: bool, kd: float | None,
           harmonic_status: str | None, tol: float, threshold: float) -> Stats:
    """Status and message. The order matters: a problem with the numbers (escapes of a
    system that should not escape, a transient, an unmet tolerance) is reported as
    ``not_converged`` whatever the system's class, which the message then also gives."""
    rel = s.eta_err / abs(s.eta) if s.eta else math.inf
    fields = {f: getattr(s, f) for f in s.__dataclass_fields__}
    bias_rel = est.systematic("eta") / abs(s.eta) if s.eta else 0.0
    why = ("the time-step bias estimate dominates: lower dt" if bias_rel > tol
           else "the time budget max_time or max_replicas ran out: raise them")
    problems = []
    if not met:
        problems.append(f"NOT CONVERGED: relative error on eta {rel:.2e} > tol {tol:g} after "
                        f"{est.replicas} replicas; {why}.")
    drift, drift_se = est.drift["eta"], est.drift_se["eta"]
    if abs(drift) > DRIFT_SIGMAS * drift_se and abs(drift) > DRIFT_SHARE * tol * abs(s.eta):
        problems.append(f"TRANSIENT: eta over the first half of the measured window differs from "
                        f"the whole by {drift:.3g} +- {drift_se:.2g} (burn-in "
                        f"{s.info['t_burn']:g} too short): raise t_burn.")
    metastable = h.confinement == "metastable"
    if esc > 0.0 and not metastable:
        problems.append(f"{esc:.2%} of paths escaped (|x| > {threshold:g}) although the "
                        "system should not: numerical instability, a too-low escape threshold "
                        "or a diffusing marginal mode; numbers are averages before escape. "
                        "Lower dt or raise escape.")
    note = " ".join(problems)
    if harmonic_status == "marginal":
        fields.update(x2=None, x2_err=None, d2=None, d2_err=None)
        head = (f"marginal: k = k_di = {kd:.10g}; x of the critical mode diffuses (x2, d2 not "
                "reported); V2, Pin, eta are finite.")
        status = Status.MARGINAL
    elif metastable:
        head = (f"metastable: n = {h.n:g} < 2 with k = {h.k:g} < 0 is unbounded below at large "
                f"amplitude. {esc:.2%} of paths escaped (|x| > {threshold:g}) within "
                f"t_burn + t_run = {s.info['t_burn'] + s.info['t_run']:g}; the numbers are "
                "quasi-stationary averages over the time before escape.")
        status = Status.METASTABLE
    elif problems:
        head = f"{h.confinement} system;"
        status = Status.STABLE
    else:
        head = (f"stable; relative error on eta {rel:.2e} (standard error over {est.replicas} "
                "replicas and time-step bias estimate in quadrature)")
        status = Status.STABLE
    # a metastable ring whose paths escape has no stationary state to converge to: it stays
    # metastable (more replicas would not help); one that no path left is quasi-stationary
    # and reports an unmet tolerance as not_converged
    if problems and status is not Status.METASTABLE or (metastable and not met and esc == 0.0):
        status = Status.NOT_CONVERGED
    fields.update(status=status, message=(head + " " + note).strip())
    return Stats(**fields)

def _info(h: Harvester, ens: Ensemble, est: Estimate, plan: RunPlan, wall: float, tol: float,
          batch: int) -> dict[str, Any]:
    """The run's details for :attr:`fpe_harvester.Stats.info` (non-finite numbers as None)."""
    esc = ens.escape_times[np.isfinite(ens.escape_times)]
    info: dict[str, Any] = {
        "dt": ens.dts[0],
        "dt_coarse": ens.dts[1] if len(ens.dts) > 1 else None,
        "richardson": len(ens.dts) > 1,
        "bias_order": bias_order(h),
        "paths": ens.paths,
        "replicas": ens.replicas,
        "replicas_valid": est.replicas,
        "t_burn": ens.t_burn,
        "t_run": ens.t_run,
        "relaxation_time": plan.relaxation_time,
        "t_burn_rule": burn_in(plan.relaxation_time, tol, ens.t_run),
        "start": ens.start,
        "plan_notes": dict(plan.notes),
        "control_variates": est.control,
        "control_set": est.controls,
        "twin_kappa": ens.twin_kappa,
        "variance_reduction": est.reduction.get("eta"),
        "variance_reduction_V2": est.reduction.get("V2"),
        "variance_reduction_Pin": est.reduction.get("Pin"),
        "burn_in_drift_eta": [est.drift["eta"], est.drift_se["eta"]],
        "path_steps": ens.path_steps,
        "path_steps_per_s": ens.path_steps / ens.wall_time if ens.wall_time > 0 else None,
        "wall_time": wall,
        "seed": ens.seed_entropy,
        "threads": ens.notes.get("threads"),
        "batch": batch,
        "step": ens.notes["step"],
        "integrator": (f"{STEPPERS[ens.notes['step']].description}; "
                       f"on-site force: {ONSITE_NAMES[onsite_kind(h)]}"),
        "rng": _RNG,
        "bias_eta": est.bias["eta"],
        "bias_eta_se": est.bias_se["eta"],
        "extrapolated": est.extrapolated,
        "eta_systematic": est.systematic("eta"),
        "dt_coarsest": ens.dts[2] if len(ens.dts) > 2 else None,
        "residual_eta": est.residual.get("eta"),
        "residual_eta_se": est.residual_se.get("eta"),
        "bias_V2": est.bias["V2"],
        "bias_Pin": est.bias["Pin"],
        "escape_threshold": ens.threshold,
        "escape_fraction": ens.escaped_fraction(),
        "escaped_paths": int(esc.size),
        "escape_time_mean": float(esc.mean()) if esc.size else None,
        "escape_time_median": float(np.median(esc)) if esc.size else None,
        "escape_times": np.sort(esc)[:200].tolist(),
        "identity_V2_minus_KcTaup_vV": list(est.identity_V2),
        "identity_Pin_minus_mgamma_v2_minus_Kv_vV": list(est.identity_power),
        "confinement": h.confinement,
    }
    if onsite_kind(h) == KIND_KINK:
        slow, crossings, averaged, exhausted = ens.kink_counters
        info.update(stuck_fraction=est.mean["stuck"], kink_slow_steps=slow, kink_crossings=crossings,
                    kink_averaged=averaged, kink_event_budget_exhausted=exhausted)
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in info.items()}
