"""Steppers of the Monte Carlo path loop: one module each, one registry, one rule for which runs.

* :mod:`.frozen` -- xi frozen over the step between exact Ornstein--Uhlenbeck updates (Strang
  splitting); every on-site treatment;
* :mod:`.joint` -- the exact joint Gaussian step of (x, v, V, xi); short tau, not the kink;
* :mod:`.averaged` -- the kink's short-tau step: its flow driven by the step's mean of xi.

The protocol is :class:`~montecarlo.steps.base.Stepper`. A new stepper is a module with its tag
class, its kernels and a :class:`Stepper` object, plus one entry in :data:`STEPPERS`; the path
loop (:mod:`montecarlo._loop`) reaches its kernels through :mod:`montecarlo.steps.dispatch`, and
:func:`resolve_step` decides from its declared refusal, preference and priority when it runs.
"""

from __future__ import annotations

from fpe_harvester.errors import ParameterError
from fpe_harvester.model import Harvester

from ..coefficients import onsite_kind
from .averaged import AVERAGED
from .base import Stepper
from .frozen import FROZEN
from .joint import JOINT

__all__ = ["Stepper", "STEPPERS", "STEP_NAMES", "resolve_step"]

#: Steppers by name (the ``step`` option of :func:`montecarlo.simulate` and
#: :class:`montecarlo.MonteCarlo`).
STEPPERS: dict[str, Stepper] = {s.name: s for s in (FROZEN, JOINT, AVERAGED)}

#: The values of the ``step`` option: ``"auto"`` and the registered steppers.
STEP_NAMES = ("auto", *STEPPERS)


def resolve_step(h: Harvester, step: str = "auto", dt: float | None = None, kind: int | None = None,
                 scale: float = 1.0) -> tuple[Stepper, float]:
    """The stepper that runs ``h`` and its coarse time step.

    Parameters
    ----------
    h : Harvester
        The problem.
    step : str
        ``"auto"`` or a name of :data:`STEPPERS`.
    dt : float or None
        The coarse time step, > 0. None: automatic, each stepper judged at its own starting step
        (:meth:`~montecarlo.steps.base.Stepper.start_dt` with ``scale``).
    kind : int or None
        On-site treatment (default :func:`montecarlo.coefficients.onsite_kind`).
    scale : float
        Factor on the automatic starting steps (the solver's 2 with extrapolation).

    Returns
    -------
    (Stepper, float)
        ``"auto"``: the stepper of highest priority that does not refuse ``h`` and prefers the
        step; a name: that stepper unless it refuses. The step is ``dt``, or its starting step.

    Raises
    ------
    ParameterError
        An unknown name, a stepper that refuses ``h``, or (``"auto"``) none that serves, with
        each stepper's reason.

    Examples
    --------
    >>> resolve_step(Harvester.build(a=0.5, n=3, tau=1e-4))[0].name
    'joint'
    >>> resolve_step(Harvester.build(a=0.5, n=3), dt=0.01)[0].name
    'frozen'
    """
    if step not in STEP_NAMES:
        raise ParameterError(f"step must be one of {STEP_NAMES}, got {step!r} (type {type(step).__name__})")
    kind = onsite_kind(h) if kind is None else kind
    candidates = sorted(STEPPERS.values(), key=lambda s: -s.priority) if step == "auto" else [STEPPERS[step]]
    reasons = []
    for s in candidates:
        at = s.start_dt(h, kind, scale) if dt is None else dt
        why = s.refusal(h, kind)
        if why is None and (step != "auto" or s.preferred(h, kind, at)):
            return s, at
        reasons.append(f"{s.name}: {why or s.preference}")
    where = f"dt = {dt:g}" if dt is not None else "its automatic time step"
    if step != "auto":
        raise ParameterError(f"step = {step!r} cannot serve n = {h.n:g}, tau = {h.params.tau:g}: "
                             f"{reasons[0]}")
    raise ParameterError(f"no Monte Carlo step serves n = {h.n:g}, tau = {h.params.tau:g} at {where}: "
                         + "; ".join(reasons))
