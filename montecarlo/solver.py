"""The Monte Carlo solver: adaptive replicas until a target error on eta, with a status.

``MonteCarlo(...).solve(h)`` plans the run (:meth:`MonteCarlo.plan`: time step, burn-in from
the slowest relaxation time, the harmonic twin whose moments are control variates, paths
started from the twin's stationary law), then runs batches of independent replicas (each
``paths`` rings for ``t_burn + t_run``) until the relative error on eta (standard error and,
with ``richardson=True``, the time-step bias estimate, in quadrature) is below ``tol`` or the
wall-time budget ``max_time`` is spent; then the status says ``NOT_CONVERGED``. A first batch
that the budget cannot cover even at :data:`FASTEST_UNIT_STEPS` (a burn-in of a slowly relaxing
system can take minutes) is not started: the result is ``NOT_CONVERGED`` without numbers, and
the message gives the budget it would need.

Time step, two policies. With extrapolation three coupled levels ``dt/2, dt, 2 dt`` run on the
same noise and the reported numbers are the Richardson extrapolation from ``(dt, dt/2)``; its
error adds the bound of :data:`montecarlo.estimate.RESIDUAL_RULE` on the remaining bias, and
``dt`` (automatic: twice the halving policy's start) is halved only when that bound, resolved,
takes more than a third of ``tol``. With the halving policy the fine level is reported with its
Richardson bias estimate in the error, and an automatic ``dt`` is halved whenever that bias takes
more than a third of ``tol`` (by one of its standard errors where it comes from a coarse level at
four times the fine step). ``extrapolate=None`` (default) picks the extrapolation at tight
tolerances (``tol <= 1e-3``) where the stepper's bias is known to be asymptotic (the frozen step
on a smooth force), the halving policy elsewhere: outside its asymptotic range the
extrapolation's error bars do not hold (docs/methods.md, "Error estimate").
After each batch the burn-in is doubled when the first half of the measured window differs
significantly from the whole (a transient left over); a halving or a doubling restarts the
ensemble.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fpe_harvester.errors import ParameterError, check_int, check_real
from fpe_harvester.exact import classify, max_sin2
from fpe_harvester.model import Harvester
from fpe_harvester.parallel import default_threads
from fpe_harvester.result import Stats, Status
from fpe_harvester.solvers import Capabilities, Tolerance
from fpe_harvester.wide import SMALLEST_NORMAL

from .coefficients import onsite_kind
from .controls.generator import GENERATOR
from .controls import CONTROLS
from .controls.martingale import BOUNDARY, MARTINGALE
from .controls.twin import TWIN_MOMENTS
from .ensemble import Ensemble
from .estimate import Estimate, estimate
from .harmonic import double_range_error, linearized_stiffness, natural_amplitude
from .layout import KIND_KINK
from .plan import FALLBACK_NOTE, RunPlan, burn_in, relaxation_time
from .report import DRIFT_SHARE, DRIFT_SIGMAS, result
from .simulate import simulate
from .steps import STEP_NAMES, STEPPERS, resolve_step

__all__ = ["MonteCarlo"]

#: Replica index where the pilot run's streams start (far from the measured replicas').
_PILOT_FIRST = 2**40
#: Path time (burn-in + measured) per replica at which ``paths`` = 64 is kept; longer paths get
#: proportionally fewer per replica, so that the first batch costs about the same.
_PATH_TIME = 140.0
#: Finest automatic time step, and the share of tol the bias may take.
_DT_MIN, _BIAS_SHARE = 0.02 / 32, 1.0 / 3.0
#: An automatic time step starts at least this far above the finest, so that its halvings can
#: resolve the bias (the stepper's starting step, :meth:`~montecarlo.steps.base.Stepper.start_dt`,
#: is lower for the kink's frozen step at short tau).
_START_ABOVE_MIN = 10.0
#: With ``extrapolate`` the automatic steps start twice as coarse (levels dt/2, dt, 2 dt): the
#: reported extrapolation's remaining error is of higher order (docs/methods.md, "Why the
#: settings are what they are").
_EXTRAPOLATE_COARSER = 2.0
#: ``extrapolate=None`` picks the extrapolation at tol <= this where the stepper allows it (the
#: frozen step on a smooth force, :meth:`~montecarlo.steps.base.Stepper.extrapolates`): there the
#: halving rule restarts the ensemble at least once, each time at ~2x the cost, while the
#: extrapolation's error bars held over seeds; at a looser tol its coarse starting step can lie
#: outside the asymptotic range, where its bound fails (docs/methods.md, "Error estimate").
_EXTRAPOLATE_TOL = 1e-3
#: Restarts allowed for a longer burn-in (the drift that triggers one: :data:`montecarlo.report.DRIFT_SIGMAS`).
_BURN_RESTARTS = 3
#: Tolerance from which the automatic paths per replica drop from 64 to 16.
_LOOSE_TOL = 5e-3
#: An upper bound on the path loop's speed, in unit-steps (one unit of one path advanced by one
#: ``dt``) per second and thread, used to refuse a first batch that ``max_time`` cannot cover
#: (a batch is not interrupted): eight times the fastest rate measured
#: (``python -m validation.studies.mc.throughput``), so that no run the budget could cover is
#: refused on a faster machine.
FASTEST_UNIT_STEPS = 5e8
#: Automatic measured time per path, in burn-ins (when longer than the default below).
_RUN_PER_BURN = 3.0
#: Default measured time per path without and with the martingale controls. The martingale
#: sums cancel the time average's fluctuation up to the boundary term of the Poisson solution,
#: g(Y_start) - g(Y_end), whose share of the variance falls like 1/t_run; the longer run pays
#: only when many replicas are needed anyway, so it applies at tol <= _T_RUN_MART_TOL (the
#: measurements: docs/methods.md, "Why the settings are what they are").
_T_RUN, _T_RUN_MART = 100.0, 400.0
_T_RUN_MART_TOL = 1e-3

#: A batch is sized for a relative error of ``_AIM * tol``: near 1 so that the run does not
#: overshoot tol (at 0.9 it ran about 20 % more replicas than tol asked for), below it so that
#: the run seldom needs one more, small batch for the last percent.
_AIM = 0.97


#: The generator controls (:mod:`montecarlo.controls.generator`) are added, after the first batch,
#: to a single unit whose plain relative variance of eta per unit of path time (the variance of a
#: replica's eta over eta^2, times its paths and t_run) is at least ``_GEN_RELVAR``: where the twin
#: and martingale controls leave much of it (the strong kink), the generator's reduce eta's
#: variance 2-10x more; elsewhere 1.0-1.6x (docs/methods.md, "Generator controls"). The run
#: restarts with them when it is long enough for their fit, ``_GEN_FIT`` replicas per control,
#: given a variance reduction of at least ``_GEN_VR`` (the least measured where the rule adds
#: them). Paths per replica: one, or as few as keep the replicas the run is expected to need below
#: ``_GEN_MAX_REPLICAS``; a task of :func:`montecarlo.simulate` then runs whole replicas, up to
#: ``_GEN_TASK_PATHS`` paths, each batch in whole rounds of equal tasks on the threads
#: (:meth:`MonteCarlo._tasks`; a kernel call over 48 paths costs 0.62x per path-step what it costs
#: over 6, over 192 a further 0.91x, and the fit's variance reduction depends on the simulated time,
#: not on how it is split into replicas: docs/methods.md, "Generator controls").
_GEN_RELVAR, _GEN_VR, _GEN_FIT = 2.4, 40.0, 4.0
_GEN_MAX_REPLICAS, _GEN_TASK_PATHS = 8192, 192
#: Time between the generator's points (:func:`montecarlo.simulate`'s ``generator_every``): as
#: much variance removed as at every step, at less cost (docs/methods.md, "Generator controls").
_GEN_EVERY = 0.02
#: The strong kink (the kink treatment with a plain relative variance of eta of at least
#: ``_STRONG_KINK_RELVAR`` per unit path time) restarts with the generator controls at half the
#: starting step when tol < ``_STRONG_KINK_FINER_TOL``: its time-step bias at the starting step,
#: about 0.06 % of eta at n = 1, a = 2, exceeds a third of such a tol, so the halving rule would
#: restart there anyway, after a batch of hundreds of replicas (docs/methods.md, "Generator
#: controls").
_STRONG_KINK_RELVAR, _STRONG_KINK_FINER_TOL = 20.0, 1.8e-3
#: One-path replicas of the strong kink's first batch (:meth:`MonteCarlo._first_batch`).
_PILOT_REPLICAS = 128
#: The strong kink's generator runs estimate the fine level's bias from a coarse level at four
#: times its step (:func:`montecarlo.simulate`'s ``coarse_ratio``), not two: at n = 1, a = 2 that
#: estimate's standard error is a fifth (8.0e-5 against 4.0e-4 of eta on 4096 replicas; with two,
#: its noise took about 15 % of the error budget), its value the same within errors, and the
#: coarse level costs 5 % less. So little noise is left that the coarse level runs only through the
#: first half of the window (``coarse_half``): the bias estimate's error grows by about sqrt(2), the
#: loop's cost falls by about 14 % (docs/methods.md, "Generator controls").
_STRONG_KINK_RATIO = 4

#: A confined system's escape threshold is at least this many natural amplitudes
#: (:func:`~montecarlo.harmonic.natural_amplitude`), and at least 100.
ESCAPE_AMPLITUDES = 30.0

def _common_random_numbers(solver: MonteCarlo, h: Harvester, replicas: int) -> dict[str, Any]:
    """Settings under which runs at every parameter value near ``h`` share their noise paths:
    ``solver``'s plan for ``h`` frozen (time step, burn-in, run length), ``replicas`` replicas
    (tol = 0.999 is met after the first batch, so no adaptive step depends on the parameter) of
    as many paths as the plan's 16 replicas hold, the plan's time-step policy (its step is the
    extrapolation's where ``solver`` extrapolates), and no harmonic twin (it needs a pilot run per
    point, a third of the point's cost at t_run = 400, and added little near the n = 3 ring's
    optimum: variance reduction of eta 9.3 without, 10.1 with it at N = 3, k = -0.5)."""
    plan = solver.plan(h)
    return {"dt": plan.dt, "t_burn": plan.t_burn, "t_run": plan.t_run,
            "paths": max(2, round(plan.paths * 16 / replicas)), "control": False,
            "min_replicas": replicas, "max_replicas": replicas, "tol": 0.999,
            "extrapolate": solver.extrapolates(h)}


def _group(paths: int) -> int:
    """Replicas of ``paths`` paths per task in a run with the generator controls: about
    ``_GEN_TASK_PATHS`` paths per task."""
    return max(1, _GEN_TASK_PATHS // paths)


def _estimate(ens: Ensemble, h: Harvester) -> Estimate:
    """:func:`~.estimate.estimate`, or :class:`ParameterError` where the parameters' scales leave
    the double range.

    Every parameter is > 0, so V2, Pin and eta are > 0 in exact arithmetic; a mean of 0 (or a
    subnormal or infinite one), an infinite error, or an overflow in the estimate means the
    scales under- or overflow double precision (a subnormal K_c makes V2 ~ K_c^2 = 0; sigma = 1e78
    makes the variance of V2 ~ sigma^8 overflow), and no relative error exists for it.
    """
    def refuse(what: str) -> ParameterError:
        return double_range_error(h, f"the Monte Carlo estimate has {what}")

    try:
        with np.errstate(over="raise"):
            est = estimate(ens, h)
    except FloatingPointError as exc:
        raise refuse(f"an overflow ({exc})") from exc
    if est.replicas:
        bad = {q: est.mean[q] for q in ("V2", "Pin", "eta")
               if not (SMALLEST_NORMAL <= abs(est.mean[q]) < math.inf and math.isfinite(est.se[q]))}
        if bad:
            raise refuse(", ".join(f"{q} = {v:.3g}" for q, v in bad.items()))
    return est


@dataclass(frozen=True)
class MonteCarlo:
    """Monte Carlo solver for any harvester (any n >= 1, any ring, any k).

    Reports ``V2, Pin, eta, Vrms, v2, vV, x2`` with errors, so that the stationary identities
    :math:`\\langle V^2\\rangle = K_c\\tau_p\\langle vV\\rangle` and
    :math:`\\sigma\\langle v\\xi\\rangle = m\\gamma\\langle v^2\\rangle + K_v\\langle vV\\rangle`
    can be checked from the result (``info`` also carries both residuals with their errors).

    Parameters
    ----------
    seed : int or None
        Root seed (``SeedSequence``); None draws fresh entropy, recorded in ``info``.
    tol : float
        Target relative error on eta, in (0, 1): the standard error over replicas and (with
        ``richardson``) the time-step bias estimate, added in quadrature. Default 1e-2.
    dt : float or None
        Time step, > 0 (model time units). With ``richardson`` the reported numbers come
        from ``dt/2`` and ``dt`` (and ``2 dt`` with ``extrapolate``) gives the bias estimate.
        None (default): the stepper's starting step (``step``; 0.02 for the frozen step, at most
        tau at the kink, 0.04 for the joint and averaged steps), twice that with ``extrapolate``,
        halved after a batch (down to 0.02/32) while the time-step error (the bias estimate, or
        with ``extrapolate`` the bound on the extrapolation's remaining bias) exceeds a third of
        ``tol`` by three of its standard errors.
    paths : int or None
        Paths (rings) per replica, >= 2. None: 64 for ``tol`` < 5e-3, else 16 (the first
        batch of ``min_replicas`` then usually meets ``tol`` already); fewer when a path's
        burn-in and measured time together exceed 140 (at least 2).
    min_replicas, max_replicas : int
        Replicas run at least (>= 2, for an error bar; the control variates need 24) and at
        most. Defaults 32 and 16384.
    t_burn : float or None
        Burn-in per path (>= 0); None: from the slowest relaxation time and ``tol``
        (:func:`montecarlo.plan.burn_in`), doubled while the data show a transient.
    t_run : float or None
        Measured time per path, > 0. None: 100 (400 with ``martingale`` at tol <= 1e-3), or three times the
        burn-in if that is longer (so that the burn-in costs at most a quarter of the run).
    max_time : float
        Wall-time budget in seconds, > 0. Default 600.
    escape : float or None
        Escape threshold on ``|x_j|``, > 0. None (default): 100, or for a metastable ring four
        times the barrier amplitude :math:`x^* = (a n / (4|k| s))^{1/(2-n)}` where the
        anti-phase coupling force :math:`4|k| s x` (:math:`s = \\max_q \\sin^2(\\pi q/N)`)
        overtakes the on-site force, if that is larger; for a confined system
        ``ESCAPE_AMPLITUDES`` (30) times the root-mean-square x of the equivalent harmonic
        unit (:func:`~montecarlo.harmonic.natural_amplitude`), if that is larger (strong noise on
        a weak wall: n = 1, D = 100 has sd(x) ~ 94, threshold ~2500).
    progress : bool or None
        tqdm bar on stderr; None shows it only for runs longer than 2 s.
    richardson : bool
        Also run at the coarse step on the same noise and fold the bias into the error (or,
        with ``extrapolate``, remove it).
    threads : int or None
        Worker threads (results do not depend on it, only on ``batch``). Default: usable CPUs.
    batch : int or None
        Replica granularity, >= 1: the pilot run and each extra batch use at least this many
        replicas. Default: ``threads``, or the usable CPUs (so that every thread is busy).
        The results depend on it: fix it (with ``seed``) for the same numbers on machines of
        other sizes or with other ``threads``.
    control : bool
        For a nonlinear potential, run the harmonic twin (stiffness from a pilot run's
        :math:`\\langle xU'\\rangle/\\langle x^2\\rangle`) on the same noise and use its
        exactly known moments as control variates (:mod:`montecarlo.controls.regression`); the paths then
        start from the twin's stationary law. Used whenever a stable twin exists and no path
        escaped; ``info["variance_reduction"]`` gives the factor. Default True.
    step : str
        The stepper (:func:`montecarlo.simulate`, :data:`montecarlo.steps.STEP_NAMES`):
        ``"frozen"`` holds xi over a step, ``"joint"`` advances (x, v, V, xi) together by their
        exact Gaussian transition (not the kink), ``"averaged"`` is the kink's short-tau step
        (tau <= 1e-4). ``"auto"`` (default): the one :func:`montecarlo.steps.resolve_step` picks
        at each time step (joint where tau < 10 dt, averaged for the kink where tau < dt, else
        frozen).
    martingale : bool
        Accumulate the martingale control sums (:mod:`montecarlo.controls.martingale`: basis functions
        of the state times the noise drawn after it, mean 0 exactly, for any potential and
        ring) and use them as control variates, alone or with the twin's: the richest set the
        replicas allow (:func:`montecarlo.controls.choose_controls`). The default ``t_run`` is then 400
        instead of 100 when ``tol <= 1e-3``. Default True.
    generator : bool
        Let the solver add the generator controls (:mod:`montecarlo.controls.generator`: the
        martingale form of the generator applied to a degree-4 basis, cross-fitted) where the
        first batch shows they pay: a single unit whose eta is noisy per unit of path time (the
        strong kink), in a run long enough for their fit; the run then restarts with them, with
        replicas of one path (or a few) run as several whole replicas per task of up to 192 paths
        (``info["plan_notes"]["generator"]`` says why or why not). Where that restart is likely
        (the kink at tol < 1.8e-3, automatic paths) the first batch is 128 one-path replicas that
        only measure eta's variance (``"pilot"`` in ``info["plan_notes"]["restarts"]`` where the
        run then continues in its own layout).
        Needs ``martingale`` and ``control``. Default True.
    extrapolate : bool or None
        True, with ``richardson``: run a third level at ``2 dt`` and report the Richardson
        extrapolation from ``(dt, dt/2)``, with :math:`(|D| + D_{se})/7` in quadrature in the
        error, D the difference of the extrapolations from ``(2 dt, dt)`` and ``(dt, dt/2)``
        (:data:`montecarlo.estimate.RESIDUAL_RULE`); ``info["extrapolated"]``,
        ``info["residual_eta"]``. False: the halving policy (fine level reported, its bias
        estimate in the error). None (default): the solver picks (:meth:`extrapolates`) the
        extrapolation at ``tol <= 1e-3`` with an automatic ``dt`` where the stepper allows it (the
        frozen step on a smooth on-site force), else the halving policy: outside its asymptotic
        range (the kink, a stiff unit at the coarse steps of a loose tol) the extrapolation's bound
        fails, and for the joint and averaged steps its error bars are not measured over seeds (see
        the module docstring).

    Examples
    --------
    >>> from fpe_harvester import Harvester, solve
    >>> r = solve(Harvester.build(a=0.5), "mc", seed=1, tol=0.05, paths=16, t_run=20,
    ...           progress=False)
    >>> abs(r.eta - 20 / 39) < 4 * r.eta_err
    True
    """

    name: ClassVar[str] = "mc"
    #: What the drivers read (:class:`~fpe_harvester.solvers.Capabilities`): tol in (0, 1), random
    #: (``seed``), a wall-time budget ``max_time``, its own progress bar and threads; the replica
    #: ``batch`` shapes the numbers and defaults to this machine's threads (``portable`` fixes it);
    #: :func:`_common_random_numbers` for the noisy optimizer.
    capabilities: ClassVar[Capabilities] = Capabilities(
        title="Monte Carlo", tol=Tolerance(1.0, 1e-2, high_open=True), seed=True, max_time="max_time",
        progress="bar", threads=True,
        portable=lambda s: {"batch": s.get("batch") or s.get("threads") or default_threads()},
        common_random_numbers=_common_random_numbers)

    seed: int | None = None
    tol: float = 1e-2
    dt: float | None = None
    paths: int | None = None
    min_replicas: int = 32
    max_replicas: int = 16384
    t_burn: float | None = None
    t_run: float | None = None
    max_time: float = 600.0
    escape: float | None = None
    progress: bool | None = None
    richardson: bool = True
    threads: int | None = None
    batch: int | None = None
    control: bool = True
    step: str = "auto"
    martingale: bool = True
    extrapolate: bool | None = None
    generator: bool = True

    def __post_init__(self) -> None:
        if self.seed is not None:
            object.__setattr__(self, "seed", check_int("seed", self.seed, low=0))
        object.__setattr__(self, "tol", check_real("tol", self.tol, low=0.0, high=1.0, low_open=True,
                                                   high_open=True))
        if self.dt is not None:
            object.__setattr__(self, "dt", check_real("dt", self.dt, low=0.0, low_open=True))
        if self.paths is not None:
            object.__setattr__(self, "paths", check_int("paths", self.paths, low=2))
        object.__setattr__(self, "min_replicas", check_int("min_replicas", self.min_replicas, low=2))
        object.__setattr__(self, "max_replicas",
                           check_int("max_replicas", self.max_replicas, low=self.min_replicas))
        if self.t_burn is not None:
            object.__setattr__(self, "t_burn", check_real("t_burn", self.t_burn, low=0.0))
        if self.t_run is not None:
            object.__setattr__(self, "t_run", check_real("t_run", self.t_run, low=0.0, low_open=True))
            if self.dt is not None and self.dt > self.t_run:
                raise ParameterError(f"dt must not exceed t_run = {self.t_run:g}, got {self.dt!r}")
        object.__setattr__(self, "max_time", check_real("max_time", self.max_time, low=0.0, low_open=True))
        if self.escape is not None:
            object.__setattr__(self, "escape", check_real("escape", self.escape, low=0.0, low_open=True))
        if self.step not in STEP_NAMES:
            raise ParameterError(f"step must be one of {STEP_NAMES}, got {self.step!r} "
                                 f"(type {type(self.step).__name__})")
        for flag in ("progress", "richardson", "control", "martingale", "extrapolate", "generator"):
            value = getattr(self, flag)
            optional = flag in ("progress", "extrapolate")
            if not isinstance(value, bool) and not (optional and value is None):
                choices = "True, False or None" if optional else "True or False"
                raise ParameterError(f"{flag} must be {choices}, got {value!r} "
                                     f"(type {type(value).__name__})")
        if self.threads is not None:
            object.__setattr__(self, "threads", check_int("threads", self.threads, low=1))
        if self.batch is not None:
            object.__setattr__(self, "batch", check_int("batch", self.batch, low=1))

    def unsupported_reason(self, h: Harvester) -> str | None:
        """None, or why this solver refuses ``h``: no stepper serves it (:func:`resolve_step`: a
        named ``step`` that refuses ``h``, or none preferred at ``dt``, as the kink between the
        averaged step's tau <= 1e-4 and the frozen step's dt <= tau), or the automatic ``dt`` would
        have to start within ``_START_ABOVE_MIN`` of its finest step."""
        try:
            stepper, dt = resolve_step(h, self.step, self.dt, scale=self._dt_scale(h))
        except ParameterError as err:
            return str(err)
        if self.dt is None and dt < _START_ABOVE_MIN * _DT_MIN:
            others = "; ".join(f"{s.name}: {why}" for s in STEPPERS.values()
                               if (why := s.refusal(h, onsite_kind(h))) is not None)
            return (f"tau = {h.params.tau:g} is too short for the automatic time step: the {stepper.name} "
                    f"step ({stepper.preference}) would start at dt = {dt:g}, within {_START_ABOVE_MIN:g} x "
                    f"the finest automatic step {_DT_MIN:g}, too few halvings to resolve its bias; {others}. "
                    f"Give an explicit dt")
        return None

    def threshold(self, h: Harvester) -> float:
        """Escape threshold used for ``h`` (see ``escape``)."""
        if self.escape is not None:
            return self.escape
        if h.confinement == "metastable":
            x_star = (h.a * h.n / (4.0 * abs(h.k) * max_sin2(h.N))) ** (1.0 / (2.0 - h.n))
            return float(max(100.0, 4.0 * x_star))
        # a confined system whose natural amplitude is large (strong noise on a weak wall: n = 1,
        # D = 100 has sd(x) ~ 94) must not count its ordinary paths as blown up
        amp = natural_amplitude(h)
        return float(max(100.0, ESCAPE_AMPLITUDES * amp)) if amp is not None else 100.0

    # -- planning ----------------------------------------------------------------------------

    def plan(self, h: Harvester) -> RunPlan:
        """Time step, burn-in, paths and twin for ``h`` from the settings (None = automatic).

        A nonlinear ring gets a short pilot run from rest (no twin) that measures
        :math:`\\kappa = \\langle xU'(x)\\rangle/\\langle x^2\\rangle`
        (:func:`montecarlo.harmonic.linearized_stiffness`); failing a stable twin there, the
        Gaussian closure; failing that, no twin and a rest start.
        """
        if not math.isfinite(2.0 * h.a):
            raise ParameterError(f"a = {h.a!r}: Monte Carlo needs the unit stiffness 2a in the double "
                                 f"range, a <= {0.5 * sys.float_info.max:.6g}")
        seed = 0 if self.seed is None else self.seed
        stepper, dt = resolve_step(h, self.step, self.dt, scale=self._dt_scale(h))
        notes: dict[str, Any] = {"time_step": self._policy(h)[1]}
        harmonic = classify(h)[0] if h.is_linear else None
        twin = None
        if harmonic is not None:
            kappa = 2.0 * h.a if harmonic == "stable" else None
            start = "twin" if harmonic == "stable" else "rest"
            notes["twin"] = "harmonic: no twin needed" + (", paths start from its own stationary law"
                                                         if start == "twin" else "")
        else:
            kappa = linearized_stiffness(h)
            notes["twin"] = "Gaussian closure" if kappa is not None else "none (no closure root)"
            t_run0 = self.t_run or _T_RUN
            pil_burn = burn_in(relaxation_time(h, kappa), self.tol, t_run0) if self.t_burn is None \
                else self.t_burn
            if self.control and math.isfinite(pil_burn):
                pilot_cost = self.least_seconds(h, dt, 16, max(2, self._batch()), pil_burn + t_run0)
                if pilot_cost > self.max_time:
                    notes["twin"] += f" (no pilot run: it needs >= {pilot_cost:.3g} s, beyond max_time)"
                elif (kp := self._pilot_stiffness(h, dt, pil_burn, t_run0, seed)) is not None:
                    kappa = kp
                    notes["twin"] = "pilot <x U'(x)>/<x^2>"
            twin = kappa if self.control and stepper.twin else None
            start = "twin" if twin is not None else "rest"
        tau_r = relaxation_time(h, kappa)
        if kappa is None and harmonic is None:
            notes["relaxation_time"] = FALLBACK_NOTE
        t_run = self.t_run or self._default_run()
        t_burn = self.t_burn
        if t_burn is None:
            t_burn = burn_in(tau_r, self.tol, t_run)
            if not math.isfinite(t_burn):
                t_burn = 100.0 * t_run
                notes["t_burn"] = "no decaying mode: 100 t_run"
            elif self.t_run is None:
                for _ in range(4):  # t_run follows a long burn-in, which then shortens
                    t_run = max(self._default_run(), _RUN_PER_BURN * t_burn)
                    t_burn = burn_in(tau_r, self.tol, t_run)
        paths = self.paths or self._auto_paths(t_burn, t_run)
        if self.t_run is None and dt > t_run:
            t_run = dt
        return RunPlan(dt=dt, t_burn=t_burn, t_run=t_run, paths=paths, twin=twin, start=start,
                    relaxation_time=tau_r, notes=notes)

    def _pilot_stiffness(self, h: Harvester, dt: float, t_burn: float, t_run: float,
                         seed: int) -> float | None:
        """The twin's stiffness from a short pilot run's <x U'(x)> / <x^2> (None if the pilot's
        moments give none)."""
        pilot = simulate(h, dt=dt, paths=16, replicas=max(2, self._batch()), t_burn=t_burn, t_run=t_run,
                         seed=seed, threshold=self.threshold(h), threads=self.threads,
                         first_replica=_PILOT_FIRST, step=self.step)
        m = pilot.moments(0)
        ok = np.isfinite(m["xdU"]) & np.isfinite(m["x2"])
        if not (ok.any() and m["x2"][ok].mean() > 0 and m["xdU"][ok].mean() > 0):
            return None
        return linearized_stiffness(h, float(m["xdU"][ok].mean()), float(m["x2"][ok].mean()))

    def least_seconds(self, h: Harvester, dt: float, paths: int, replicas: int, t_path: float) -> float:
        """A lower bound on the wall time, in seconds, of ``replicas`` x ``paths`` paths of ``h``
        over a path time ``t_path`` (burn-in + measured) at step ``dt``: their unit-steps at
        :data:`FASTEST_UNIT_STEPS` per second on each thread."""
        threads = self.threads or default_threads()
        return h.N * paths * replicas * (t_path / dt) / (FASTEST_UNIT_STEPS * threads)

    def _beyond_budget(self, h: Harvester, plan: RunPlan, wall: float) -> Stats | None:
        """The ``NOT_CONVERGED`` result, without numbers, when ``max_time`` cannot cover the
        first batch of ``min_replicas`` (``wall``: seconds spent planning, reported); else None."""
        need = self.least_seconds(h, plan.dt, plan.paths, self.min_replicas, plan.t_burn + plan.t_run)
        if need <= self.max_time:
            return None
        info = {"dt": plan.dt, "t_burn": plan.t_burn, "t_run": plan.t_run, "paths": plan.paths,
                "relaxation_time": plan.relaxation_time, "least_seconds": need, "wall_time": wall,
                "seed": self.seed}
        return Stats(status=Status.NOT_CONVERGED, method=self.name, info=info, message=(
            f"not converged: max_time = {self.max_time:g} s cannot cover the first batch "
            f"({self.min_replicas} replicas x {plan.paths} paths over t_burn + t_run = "
            f"{plan.t_burn:.3g} + {plan.t_run:.3g} at dt = {plan.dt:g}, relaxation time "
            f"{plan.relaxation_time:.3g}), which needs at least {need:.3g} s: raise max_time above "
            f"that, or give t_burn. No statistics."))

    def extrapolates(self, h: Harvester) -> bool:
        """Whether the run of ``h`` reports the Richardson extrapolation (three levels): ``extrapolate``
        if given; None picks it at ``tol`` <= :data:`_EXTRAPOLATE_TOL` with an automatic ``dt`` where
        the stepper it starts with allows it (:meth:`~montecarlo.steps.base.Stepper.extrapolates`:
        the frozen step on a smooth on-site force)."""
        return self._policy(h)[0]

    def _policy(self, h: Harvester) -> tuple[bool, str]:
        """:meth:`extrapolates` and why, in words (``info["plan_notes"]["time_step"]``)."""
        def say(extrapolated: bool, why: str) -> tuple[bool, str]:
            return extrapolated, ("Richardson extrapolation" if extrapolated else "halving policy") + why

        if not self.richardson:
            return False, "fine level only (richardson=False): no time-step bias estimate"
        if self.extrapolate is not None:
            return say(self.extrapolate, f" (extrapolate={self.extrapolate})")
        if self.dt is not None:
            return say(False, ": an explicit dt")
        if self.tol > _EXTRAPOLATE_TOL:
            return say(False, f": tol > {_EXTRAPOLATE_TOL:g}")
        try:
            stepper, _ = resolve_step(h, self.step, None, scale=_EXTRAPOLATE_COARSER)
        except ParameterError:
            return say(False, f": tol <= {_EXTRAPOLATE_TOL:g} but no stepper serves the coarser start")
        allowed = stepper.extrapolates(h, onsite_kind(h))
        return say(allowed, f": tol <= {_EXTRAPOLATE_TOL:g} and the {stepper.name} step "
                            + ("allows it" if allowed else "does not allow it for this on-site force"))

    def _dt_scale(self, h: Harvester) -> float:
        """Factor on the steppers' automatic starting steps: coarser with extrapolation."""
        return _EXTRAPOLATE_COARSER if self.extrapolates(h) else 1.0

    def _default_run(self) -> float:
        return _T_RUN_MART if self.martingale and self.tol <= _T_RUN_MART_TOL else _T_RUN

    def _auto_paths(self, t_burn: float, t_run: float) -> int:
        base = 64 if self.tol < _LOOSE_TOL else 16
        return max(2, min(base, int(round(base * _PATH_TIME / (t_burn + t_run)))))

    # -- running -----------------------------------------------------------------------------

    def _batch(self) -> int:
        return self.batch or self.threads or default_threads()

    def _more_replicas(self, est: Estimate, R: int) -> int:
        """Replicas to add to the ``R`` of ``est`` for an expected relative error of eta of
        ``_AIM * tol`` at the end.

        The standard error falls like 1/sqrt(R). The halving policy's bias estimate is a mean
        over the replicas too: its square overestimates the squared bias by its variance, which
        falls like 1/R, so the part that stays is bias^2 - bias_se^2 (at least 0), and bias_se^2
        falls with the standard error's square (taken whole as staying, a fluctuation of two of
        its standard errors doubled the run and then overshot tol: docs/methods.md, "Generator
        controls"). An extrapolated value's systematic part, a bound, stays whole."""
        eta = abs(est.mean["eta"])
        falls = (est.se["eta"] / eta) ** 2
        if est.extrapolated:
            stays = (est.systematic("eta") / eta) ** 2
        else:
            bias, bias_se = est.bias["eta"] / eta, est.bias_se["eta"] / eta
            stays = max(bias * bias - bias_se * bias_se, 0.0)
            falls += bias_se * bias_se
        budget = (_AIM * self.tol) ** 2 - stays
        return math.ceil(R * falls / (budget if budget > 0 else (_AIM * self.tol) ** 2)) - R

    def _tasks(self, replicas: int, group: int) -> tuple[int, int]:
        """Replicas and replicas per task for a batch of about ``replicas`` in tasks of at most
        ``group`` replicas (``group`` > 1): whole rounds of equal tasks on the threads, since a last
        round with idle threads costs a whole task's time; fewer replicas than asked for by less
        than one per task."""
        if group <= 1:
            return replicas, group
        threads = self.threads or default_threads()
        tasks = min(replicas, threads * -(-replicas // (threads * group)))
        per_task = replicas // tasks
        return tasks * per_task, per_task

    def _controls(self, plan: RunPlan) -> tuple[str, ...]:
        """The controls the path loop accumulates: the martingale sums and the end-of-window
        terms, and the generator's sums where the plan takes them. (The generator's functions
        hold the martingale's, but without the martingale sums eta's variance reduction at
        n = 1, a = 2 fell 5-10 % for a path loop 4 % cheaper: measured, docs/methods.md,
        "Generator controls".)"""
        if not self.martingale:
            return ()
        return (MARTINGALE.name, BOUNDARY.name) + ((GENERATOR.name,) if plan.generator else ())

    def _run(self, h: Harvester, plan: RunPlan, replicas: int, first: int) -> Ensemble:
        replicas, group = self._tasks(replicas, plan.group)
        return simulate(h, dt=plan.dt, paths=plan.paths, replicas=replicas, t_burn=plan.t_burn,
                        t_run=plan.t_run, seed=self.seed, richardson=self.richardson,
                        threshold=self.threshold(h), threads=self.threads, first_replica=first,
                        twin=plan.twin, start=plan.start, step=self.step,
                        controls=self._controls(plan),
                        third_level=self.extrapolates(h), generator_every=_GEN_EVERY, group=group,
                        coarse_ratio=plan.coarse_ratio, coarse_half=plan.coarse_half)

    def _restart_reason(self, h: Harvester, plan: RunPlan, est: Estimate) -> tuple[str, RunPlan] | None:
        """After a batch: a finer step or a longer burn-in, if the data ask for one.

        Both tests need three standard errors (they are repeated after every batch) and a
        size that matters for ``tol``: the bias estimate above a third of it (only with an
        automatic ``dt``), or the first half of the measured window off the whole by that much
        (only with an automatic ``t_burn``, at most three doublings). Where the bias comes from a
        coarse level at four times the fine step (the strong kink's generator runs) it must pass
        that third by one of its standard errors: there its bias, 0.15-0.2 of tol and measured
        consistent over three steps, otherwise crossed the third by chance after some batch and
        halved the step, doubling the run. Elsewhere a bias estimate just above the third is taken
        as it is (at n = 1, a = 0.5 to 1e-4 a run that stayed at the coarser step ended two error
        bars from Fokker-Planck: docs/methods.md, "Generator controls").
        """
        eta = abs(est.mean["eta"])
        if not (eta > 0 and math.isfinite(eta)):
            return None
        if est.extrapolated:
            bias, bias_se = abs(est.residual["eta"]), est.residual_se["eta"]
        else:
            bias, bias_se = abs(est.bias["eta"]), est.bias_se["eta"]
        margin = bias_se if plan.coarse_ratio == _STRONG_KINK_RATIO else 0.0
        if (self.dt is None and self.richardson and bias - margin > _BIAS_SHARE * self.tol * eta
                and bias > DRIFT_SIGMAS * bias_se and plan.dt / 2 >= _DT_MIN):
            return "dt", dataclasses.replace(plan, dt=plan.dt / 2)
        drift, drift_se = abs(est.drift["eta"]), est.drift_se["eta"]
        if (self.t_burn is None and drift > DRIFT_SIGMAS * drift_se
                and drift > DRIFT_SHARE * self.tol * eta):
            t_burn = 2.0 * plan.t_burn
            t_run = plan.t_run if self.t_run is not None else max(plan.t_run, _RUN_PER_BURN * t_burn)
            paths = self.paths or self._auto_paths(t_burn, t_run)
            return "t_burn", dataclasses.replace(plan, t_burn=t_burn, t_run=t_run, paths=paths,
                                                 group=_group(paths) if plan.generator else 1)
        return None

    def _first_batch(self, h: Harvester, plan: RunPlan) -> tuple[RunPlan, int]:
        """The first batch: ``plan`` and ``min_replicas``, or where the strong kink's restart with
        the generator controls at half the step is likely (a single unit with the kink treatment,
        tol < ``_STRONG_KINK_FINER_TOL``, automatic paths) ``_PILOT_REPLICAS`` one-path replicas
        (within ``min_replicas .. max_replicas``) in tasks on the threads. That batch only
        measures eta's relative variance for the plan that follows and is discarded either way:
        one-path replicas measure it at a ``plan.paths``-th of the cost per replica, and four
        times as many of them more precisely (an overestimate makes the generator's first batch
        overshoot tol; docs/methods.md, "Generator controls")."""
        if not (self.generator and self.martingale and self.control and self.paths is None and h.N == 1
                and onsite_kind(h) == KIND_KINK and self.tol < _STRONG_KINK_FINER_TOL and plan.paths > 1):
            return plan, self.min_replicas
        replicas = min(self.max_replicas, max(self.min_replicas, _PILOT_REPLICAS))
        per_task = -(-replicas // (self.threads or default_threads()))
        return dataclasses.replace(plan, paths=1, group=per_task), replicas

    def _generator_plan(self, h: Harvester, plan: RunPlan, ens: Ensemble, est: Estimate) -> tuple[RunPlan, int]:
        """After the first batch: the plan with the generator controls and the paths per replica
        for their fit, and the replicas of its first batch (half those it is expected to need),
        where they pay (see ``generator`` and ``_GEN_RELVAR``); else the plan with a note why
        not, and 0."""
        def note(why: str, first: int = 0, **changes: Any) -> tuple[RunPlan, int]:
            return dataclasses.replace(plan, notes={**plan.notes, "generator": why}, **changes), first

        if not (self.generator and self.martingale and self.control) or plan.generator:
            return plan, 0
        if h.N > 1:
            return note("not used: a ring (measured: no gain over the twin and martingale controls)")
        eta = est.mean["eta"]
        if not (est.replicas >= 2 and math.isfinite(eta) and eta != 0.0 and est.se["eta"] > 0):
            return note("not used: no estimate of eta's variance from the first batch")
        relvar = (est.se["eta"] / eta) ** 2 * est.reduction.get("eta", 1.0) * est.replicas * ens.paths * ens.t_run
        if relvar < _GEN_RELVAR:
            return note(f"not used: plain relative variance of eta {relvar:.3g} per unit path time, below "
                        f"{_GEN_RELVAR:g}")
        controls = sum(len(CONTROLS[name].sums(h)) for name in self._controls(plan)) + \
            (len(TWIN_MOMENTS) if plan.twin else 0) + len(GENERATOR.sums(h))
        need = relvar / (_GEN_VR * (_AIM * self.tol) ** 2 * plan.t_run)  # paths to reach tol with them
        paths = self.paths or max(1, min(plan.paths, math.ceil(need / _GEN_MAX_REPLICAS)))
        group = _group(paths)
        if need / paths < _GEN_FIT * controls:
            return note(f"not used: the run (about {need:.3g} paths with them) is too short for the fit of "
                        f"{controls} controls ({_GEN_FIT * controls:.0f} replicas of {paths} paths)")
        first = min(self.max_replicas, max(self.min_replicas, round(0.5 * need / paths)))
        why = f"used: plain relative variance of eta {relvar:.3g} per unit path time; about {need:.3g} paths, " \
              f"{paths} per replica, {group} replicas per task"
        dt, ratio, half = plan.dt, plan.coarse_ratio, plan.coarse_half
        if (self.dt is None and self.richardson and onsite_kind(h) == KIND_KINK and relvar >= _STRONG_KINK_RELVAR
                and self.tol < _STRONG_KINK_FINER_TOL and dt / 2 >= _DT_MIN):
            dt /= 2
            why += f"; dt halved to {dt:g} with them (the strong kink's bias at the starting step exceeds a third of tol)"
            if not self.extrapolates(h):
                ratio, half = _STRONG_KINK_RATIO, True
                why += f"; the bias estimated from a coarse level at {ratio // 2} dt over the window's first half"
        return note(why, first, generator=True, paths=paths, dt=dt, group=group, coarse_ratio=ratio,
                    coarse_half=half)

    def run(self, h: Harvester, plan: RunPlan | None = None) -> tuple[Ensemble, Estimate, bool, RunPlan]:
        """Adaptive replica loop; returns the ensemble, its estimate, whether tol was met, the plan."""
        from tqdm import tqdm

        if self.seed is None:
            # one entropy for every batch, so that batches are distinct children of one root
            return dataclasses.replace(self, seed=int(np.random.SeedSequence().entropy)).run(h, plan)
        plan = plan or self.plan(h)
        granule = self._batch()
        start = time.perf_counter()
        restarts: list[str] = []
        bar = tqdm(desc=f"mc N={h.N} n={h.n:g}", unit="replica",
                   file=sys.stderr, disable=self.progress is False,
                   delay=0.0 if self.progress else 2.0, leave=False)
        with bar:
            pilot, replicas = self._first_batch(h, plan)
            measured_only = pilot is not plan
            ens = self._run(h, pilot, replicas, 0)
            bar.update(ens.replicas)
            est = _estimate(ens, h)
            plan, first = self._generator_plan(h, plan, ens, est)
            if first or measured_only:
                # the generator's plan, or the pilot's one-path replicas were only a measurement
                restarts.append("generator" if first else "pilot")
                ens = self._run(h, plan, first or self.min_replicas, 0)
                bar.update(ens.replicas)
                est = _estimate(ens, h)
            met = False
            while True:
                # the bias or a transient may only show once enough replicas resolve it:
                # checked after every batch, a restart discards the ensemble
                redo = self._restart_reason(h, plan, est)
                if redo is not None and (redo[0] == "dt" or restarts.count("t_burn") < _BURN_RESTARTS) \
                        and 3.0 * (time.perf_counter() - start) < self.max_time:
                    restarts.append(redo[0])
                    plan = redo[1]
                    ens = self._run(h, plan, self.min_replicas, 0)
                    bar.update(ens.replicas)
                    est = _estimate(ens, h)
                    continue
                rel = est.rel_error("eta")
                stat_rel = est.se["eta"] / abs(est.mean["eta"]) if est.replicas else math.inf
                bar.set_postfix_str(f"rel err eta {rel:.2e}")
                if rel <= self.tol:
                    met = True
                    break
                if ens.escaped_fraction() >= 0.5 or est.replicas < 2 or not math.isfinite(stat_rel):
                    break
                # bias-dominated: more replicas cannot reach tol
                systematic = est.systematic("eta")
                if systematic != 0.0 and systematic / abs(est.mean["eta"]) > self.tol \
                        and stat_rel < 0.3 * self.tol:
                    break
                R = ens.replicas
                if R >= self.max_replicas:
                    break
                elapsed = time.perf_counter() - start
                per_rep = max(ens.wall_time, 1e-9) / R
                want = self._more_replicas(est, R)
                batch = int(min(max(want, granule), R, self.max_replicas - R))
                batch = min(batch, int((self.max_time - elapsed) / per_rep))
                if batch < 1:
                    break
                ens = ens.merge(self._run(h, plan, batch, R))
                bar.update(batch)
                est = _estimate(ens, h)
        return ens, est, met, dataclasses.replace(plan, notes={**plan.notes, "restarts": restarts})

    # -- result ------------------------------------------------------------------------------

    def solve(self, h: Harvester) -> Stats:
        """Stationary statistics of ``h`` with standard errors, bias estimate and a status."""
        if not isinstance(h, Harvester):
            raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
        start = time.perf_counter()
        harmonic_status = classify(h)[0] if h.is_linear else None
        if harmonic_status == "unstable":
            # short run from rest: only to show the escape, statistics do not exist
            short = dataclasses.replace(self, max_replicas=self.min_replicas, tol=0.999)
            ens, est, met, plan = short.run(h)
        else:
            plan = self.plan(h)
            refusal = self._beyond_budget(h, plan, time.perf_counter() - start)
            if refusal is not None:
                return refusal
            ens, est, met, plan = self.run(h, plan)
        return result(h, ens, est, met, plan, time.perf_counter() - start, harmonic_status,
                      name=self.name, tol=self.tol, threshold=self.threshold(h), batch=self._batch())
