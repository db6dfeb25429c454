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

Scheme: Strang splitting of the exact Ornstein--Uhlenbeck flow of xi with the flow of
(x, v, V) at frozen xi (exact linear part; Strang kick for smooth nonlinear forces;
located zero crossings for the kink force of 1 <= n <= 1.05), numba-compiled,
one :class:`numpy.random.Generator` per (replica, chunk) from a ``SeedSequence``. A harmonic
twin ring on the same noise, whose moments are known exactly at the step used, gives
control variates; the paths start from its stationary law. Martingale sums (functions of the
state times the noise drawn after it, :mod:`.controls.martingale`; mean exactly 0) give more, alone or
with the twin's (:func:`estimate` picks the set).
"""

from __future__ import annotations

# first: it drops stale cached kernels before any kernel module loads them
from . import _cache  # noqa: F401
from .controls import Regression, regression_estimate
from .escape import EscapeCurve, escape_study
from .estimate import Estimate, estimate
from .harmonic import linearized_stiffness, twin_expectations
from .naive import simulate_naive
from .simulate import Ensemble, simulate
from .solver import MonteCarlo, Plan
from .switching import Switching, switching_times

__all__ = [
    "MonteCarlo",
    "Plan",
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
