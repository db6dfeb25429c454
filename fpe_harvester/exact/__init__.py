"""The exact solver for harmonic harvesters (n = 2), any ring size.

A harmonic ring's Fourier modes decouple into single units of stiffness
:math:`\\kappa_q = 2a + k\\mu_q + k_4\\mu_q^2`, :math:`\\mu_q = 4\\sin^2(\\pi q/N)`, whose
stationary moments are closed-form
(:mod:`.moments`). :mod:`.stability` gives the diffusive-instability threshold ``k_di``, the
critical mode and the growth rate beyond it; :mod:`.solver` holds the solver object
:class:`Exact` (``method="exact"``), the vectorized :func:`exact_sweep` and
:func:`exact_stats`, the one path from the closed form to results. The dense
4N x 4N Lyapunov solves in :mod:`.moments` are cross-checks only (scipy is imported
when they are called).
"""

from __future__ import annotations

from .moments import (
    dense_covariance,
    drift_matrix,
    lyapunov_covariance,
    mode_moments,
    noise_matrix,
    ring_drift_matrix,
    ring_moments,
)
from .solver import Exact, exact_stats, exact_sweep
from .stability import (
    MARGINAL_RTOL,
    Threshold,
    classify,
    critical_mode,
    growth_rate,
    k_di,
    max_sin2,
    mode_eigenvalues,
    mode_growth_rate,
    ring_spectrum,
    threshold,
)

__all__ = [
    "MARGINAL_RTOL",
    "Exact",
    "Threshold",
    "classify",
    "critical_mode",
    "dense_covariance",
    "drift_matrix",
    "exact_stats",
    "exact_sweep",
    "growth_rate",
    "k_di",
    "lyapunov_covariance",
    "max_sin2",
    "mode_eigenvalues",
    "mode_growth_rate",
    "mode_moments",
    "noise_matrix",
    "ring_drift_matrix",
    "ring_moments",
    "ring_spectrum",
    "threshold",
]
