"""Monte Carlo engine of fpe-harvester: ensembles of single units and rings, any potential.

Public API:

* :class:`MonteCarlo` -- the solver (``solve(h, "mc", seed=..., tol=...)``);
* :func:`simulate` and :class:`Ensemble` -- raw per-replica moments for validation studies;
* :func:`estimate` and :class:`Estimate` -- means, standard errors, Richardson bias;
* :func:`escape_study` and :class:`EscapeCurve` -- escape fraction and times vs time;
* :func:`simulate_naive` -- the plain vectorized numpy Euler--Maruyama reference.

Scheme: Strang splitting of the exact Ornstein--Uhlenbeck flow of xi with the flow of
(x, v, V) at frozen xi (exact linear part; Strang kick for smooth nonlinear forces;
located zero crossings and Filippov sticking for the kink n = 1), numba-compiled,
one :class:`numpy.random.Generator` per (replica, chunk) from a ``SeedSequence``.
"""

from __future__ import annotations

from .escape import EscapeCurve, escape_study
from .estimate import Estimate, estimate
from .naive import simulate_naive
from .simulate import Ensemble, simulate
from .solver import MonteCarlo

__all__ = [
    "MonteCarlo",
    "simulate",
    "Ensemble",
    "estimate",
    "Estimate",
    "escape_study",
    "EscapeCurve",
    "simulate_naive",
]
