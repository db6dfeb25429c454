"""Run plan of the Monte Carlo solver: burn-in from the slowest relaxation, twin stiffness.

The burn-in must outlast the slowest relaxation of the second moments. For a harmonic ring
it is exact: mode q relaxes at the rate :math:`r_q = -\\max\\mathrm{Re}\\,\\lambda(\\kappa_q)`
(:func:`fpe_harvester.exact.mode_eigenvalues`), and the slowest time is
:math:`\\tau_r = 1/\\min_q r_q`. For a nonlinear ring the same formula is applied to its
harmonic twin (statistical linearization, :mod:`.harmonic`), an estimate that the solver then
checks on the data (the first half of the measured window against the whole). A transient
:math:`\\delta_0 e^{-t/\\tau_r}` (relative, :math:`\\delta_0 \\le 1` from rest) biases the mean
over :math:`[t_b, t_b + T]` by at most :math:`\\delta_0\\tau_r e^{-t_b/\\tau_r}/T`; the burn-in
keeps that below a tenth of the tolerance:

.. math::

    t_b = \\tau_r \\ln\\frac{10\\,\\tau_r}{\\mathrm{tol}\\; T}.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fpe_harvester.exact import mode_eigenvalues
from fpe_harvester.model import Harvester

from .harmonic import twin_harvester

__all__ = ["RunPlan", "relaxation_time", "burn_in", "MIN_BURN", "FALLBACK_NOTE"]

#: Shortest burn-in (model time units): a few correlation times of the noise and the load.
MIN_BURN = 20.0

FALLBACK_NOTE = ("no stable harmonic twin: relaxation time of the uncoupled unit of stiffness "
                 "2a, an estimate checked on the data")


def relaxation_time(h: Harvester, kappa: float | None) -> float:
    """Slowest relaxation time of the ring's second moments, in model time units.

    Parameters
    ----------
    h : Harvester
        The system (its k, N and params).
    kappa : float or None
        On-site stiffness of the harmonic ring to use (``2a`` for a harmonic ``h``, the twin's
        for a nonlinear one). None: the uncoupled unit of stiffness ``2a`` (a fallback for
        rings without a stable twin).

    Returns
    -------
    float
        :math:`1/\\min_q r_q`, over the modes with a decaying spectrum (a marginal mode's
        zero eigenvalue, free diffusion of x, never equilibrates and is left out), or inf
        if no mode decays.

    Examples
    --------
    >>> round(relaxation_time(Harvester.build(a=0.5), 1.0), 4)
    4.4241
    """
    if kappa is None:
        stiff = np.array([2.0 * h.a])
    else:
        stiff = twin_harvester(h, kappa).mode_stiffness()
    rates = []
    for kap in np.unique(np.maximum(stiff, 0.0)):
        re = mode_eigenvalues(float(kap), h.params).real
        re = re[re < -1e-12]
        if re.size:
            rates.append(-float(re.max()))
    return 1.0 / min(rates) if rates else math.inf


def burn_in(tau_r: float, tol: float, t_run: float) -> float:
    """Burn-in :math:`t_b = \\tau_r\\ln(10\\tau_r/(\\mathrm{tol}\\,T))`, at least :data:`MIN_BURN`.

    Parameters
    ----------
    tau_r : float
        Slowest relaxation time, > 0.
    tol : float
        Target relative error, in (0, 1).
    t_run : float
        Measured time per path T, > 0.

    Examples
    --------
    >>> round(burn_in(4.4241, 1e-2, 100.0), 1)
    20.0
    >>> round(burn_in(2000.0, 1e-2, 2000.0), 0)
    13816.0
    """
    if not math.isfinite(tau_r):
        return math.inf
    return max(MIN_BURN, tau_r * math.log(max(10.0 * tau_r / (tol * t_run), 1.0)))


@dataclass(frozen=True)
class RunPlan:
    """What the solver runs for one harvester (see :meth:`MonteCarlo.plan`).

    Attributes
    ----------
    dt : float
        Coarse time step (the reported level is ``dt/2`` with Richardson).
    t_burn, t_run : float
        Burn-in and measured time per path.
    paths : int
        Paths per replica.
    twin : float or None
        On-site stiffness of the harmonic twin (None: no twin).
    start : str
        ``"twin"`` (stationary law of the twin, or of a harmonic ring itself) or ``"rest"``.
    relaxation_time : float
        Slowest relaxation time behind ``t_burn`` (:func:`montecarlo.plan.relaxation_time`).
    notes : dict
        How each choice was made.
    generator : bool
        Whether the path loop accumulates the generator controls
        (:mod:`montecarlo.controls.generator`).
    group : int
        Replicas per task of :func:`montecarlo.simulate` (1: a task per replica).
    coarse_ratio : int
        The Richardson coarse level's step over the fine one's (:func:`montecarlo.simulate`'s
        ``coarse_ratio``: 2, or 4 for the level at ``2 dt``).
    coarse_half : bool
        The coarse level runs through the burn-in and the first half of the measured window only
        (:func:`montecarlo.simulate`'s ``coarse_half``).
    """

    dt: float
    t_burn: float
    t_run: float
    paths: int
    twin: float | None
    start: str
    relaxation_time: float
    notes: dict[str, Any]
    generator: bool = False
    group: int = 1
    coarse_ratio: int = 2
    coarse_half: bool = False
