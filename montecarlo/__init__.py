"""Monte Carlo engine of fpe-harvester: ensembles of single units and rings, any potential.

Public API:

* :class:`MonteCarlo` -- the solver (``solve(h, "mc", seed=..., tol=...)``);
* :func:`simulate` and :class:`Ensemble` -- raw per-replica moments for validation studies;
* :func:`estimate` and :class:`Estimate` -- means, standard errors, Richardson bias;
* :func:`escape_study` and :class:`EscapeCurve` -- escape fraction and times vs time;
* :func:`switching_times` and :class:`Switching` -- residence times between buckled states;
* :func:`simulate_naive` -- the plain vectorized numpy Euler--Maruyama reference;
* :func:`regression_estimate` -- control variates over replicas (:mod:`.controls.regression`);
* :func:`twin_expectations` and :func:`linearized_stiffness` -- the harmonic twin (:mod:`.harmonic`).

Integrator: a splitting of the exact linear part of (x, v, V) and the exact Ornstein--Uhlenbeck
flow of xi (with xi frozen over a step, or jointly with the rest at short tau; the steppers of
:mod:`.steps`, chosen by :func:`.steps.resolve_step`) with Strang kicks for smooth nonlinear forces
and located zero crossings for the kink force of 1 <= n <= 1.05, numba-compiled (array layouts in
:mod:`.layout`), one :class:`numpy.random.Generator` per (replica, chunk) from a ``SeedSequence``. A harmonic
twin ring on the same noise, whose moments are known exactly at the step used, gives
control variates; the paths start from its stationary law. Martingale sums (functions of the
state times the noise drawn after it, :mod:`.controls.martingale`; mean exactly 0) give more, alone or
with the twin's (:func:`estimate` picks the set).
"""

from __future__ import annotations

# first: it drops stale cached kernels before any kernel module loads them
from . import _cache  # noqa: F401
from .controls import Regression, regression_estimate
from .ensemble import Ensemble
from .escape import EscapeCurve, escape_study
from .estimate import Estimate, estimate
from .harmonic import linearized_stiffness, twin_expectations
from .naive import simulate_naive
from .plan import RunPlan
from .simulate import simulate
from .solver import MonteCarlo
from .switching import Switching, switching_times

__all__ = [
    "MonteCarlo",
    "RunPlan",
    "regression_estimate",
    "Regression",
    "twin_expectations",
    "linearized_stiffness",
    "simulate",
    "Ensemble",
    "estimate",
    "Estimate",
    "escape_study",
    "EscapeCurve",
    "switching_times",
    "Switching",
    "simulate_naive",
]
