"""Escape study: how fast paths leave a metastable or unstable state.

For a ring with no stationary state (harmonic beyond k_di) or only a metastable one
(n < 2, k < 0) the useful numbers are the fraction of paths that have crossed
``|x_j| > threshold`` by time t, :math:`F(t)`, and the first-escape times. For a
metastable state with escape rate r, :math:`1 - F(t) \\approx e^{-r t}` after a transient.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fpe_harvester.errors import check_int, check_real
from fpe_harvester.model import Harvester

from .simulate import simulate

__all__ = ["EscapeCurve", "escape_study"]


@dataclass(frozen=True)
class EscapeCurve:
    """Escape statistics of an ensemble started at rest.

    Attributes
    ----------
    times : ndarray
        Time grid (model units) of the curve.
    fraction : ndarray
        Fraction of paths escaped by each time, :math:`F(t)`.
    fraction_err : ndarray
        Binomial standard error of ``fraction``.
    escape_times : ndarray
        Sorted first-escape times of the escaped paths.
    paths : int
        Number of paths.
    t_max : float
        Simulated time per path.
    rate : float or None
        Escape rate from the maximum-likelihood exponential fit (escaped / total time at risk),
        None when nothing escaped.
    mean_escape_time : float or None
        Mean first-escape time among escaped paths (biased low if many paths survive).
    """

    times: np.ndarray
    fraction: np.ndarray
    fraction_err: np.ndarray
    escape_times: np.ndarray
    paths: int
    t_max: float
    rate: float | None
    mean_escape_time: float | None

    def to_dict(self) -> dict[str, object]:
        return {
            "times": self.times.tolist(), "fraction": self.fraction.tolist(),
            "fraction_err": self.fraction_err.tolist(), "escape_times": self.escape_times.tolist(),
            "paths": self.paths, "t_max": self.t_max, "rate": self.rate,
            "mean_escape_time": self.mean_escape_time,
        }


def escape_study(
    h: Harvester,
    t_max: float = 1000.0,
    *,
    paths: int = 512,
    dt: float = 0.02,
    threshold: float = 100.0,
    seed: int | None = None,
    points: int = 101,
) -> EscapeCurve:
    """Run ``paths`` rings from rest for ``t_max`` and record when each first escapes.

    Parameters
    ----------
    h : Harvester
        Typically a metastable ring (n < 2, k < 0) or a harmonic ring beyond k_di.
    t_max : float
        Simulated time per path, > 0.
    paths : int
        Number of paths, >= 2.
    dt : float
        Time step, > 0.
    threshold : float
        Escape amplitude on |x_j|, > 0.
    seed : int or None
        Root seed.
    points : int
        Points of the returned time grid, >= 2.

    Examples
    --------
    >>> c = escape_study(Harvester.build(a=0.5, n=2, N=2, k=-0.5), t_max=100.0, paths=8,
    ...                  seed=1)
    >>> float(c.fraction[-1])
    1.0
    """
    t_max = check_real("t_max", t_max, low=0.0, low_open=True)
    points = check_int("points", points, low=2)
    e = simulate(h, dt=dt, paths=paths, replicas=1, t_burn=0.0, t_run=t_max, seed=seed,
                 threshold=threshold)
    esc = e.escape_times[0]
    times = np.linspace(0.0, e.t_run, points)
    frac = (esc[None, :] <= times[:, None]).mean(axis=1)
    err = np.sqrt(frac * (1.0 - frac) / paths)
    escaped = np.sort(esc[np.isfinite(esc)])
    at_risk = float(np.where(np.isfinite(esc), esc, e.t_run).sum())
    rate = escaped.size / at_risk if escaped.size and at_risk > 0 else None
    mean = float(escaped.mean()) if escaped.size else None
    return EscapeCurve(times, frac, err, escaped, paths, e.t_run, rate,
                       None if mean is None or not math.isfinite(mean) else mean)
