"""Escape study: how fast paths leave a metastable or unstable state.

For a ring with no stationary state (harmonic beyond k_di) or only a metastable one
(n < 2, k < 0) the useful numbers are the fraction of paths that have crossed
``|x_j| > threshold`` by time t, :math:`F(t)`, and the first-escape times. For a
metastable state with escape rate r, :math:`1 - F(t) \\approx e^{-r t}` after a transient,
and the maximum-likelihood estimates from paths censored at :math:`T` are

.. math::

    \\hat r = \\frac{n_{esc}}{E},\\qquad \\hat\\tau = \\frac{E}{n_{esc}} \\pm \\frac{\\hat\\tau}{\\sqrt{n_{esc}}},
    \\qquad E = \\sum_i \\min(t_i, T)

(:math:`E` the exposure, the total time at risk); with no escape, :math:`\\tau > E/3` (95 %).
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
    exposure : float
        Total time at risk: the sum over paths of their escape time, or ``t_max`` for the
        paths that did not escape.
    mean_escape_time : float or None
        Mean first-escape time among escaped paths (biased low if many paths survive; see
        :attr:`escape_time` for the censored estimate).
    """

    times: np.ndarray
    fraction: np.ndarray
    fraction_err: np.ndarray
    escape_times: np.ndarray
    paths: int
    t_max: float
    exposure: float
    mean_escape_time: float | None

    @property
    def rate(self) -> float | None:
        """Escape rate of the maximum-likelihood exponential fit (escaped / exposure), None
        when nothing escaped."""
        n = self.escape_times.size
        return n / self.exposure if n and self.exposure > 0 else None

    @property
    def escape_time(self) -> float | None:
        """Maximum-likelihood mean escape time (exposure / escaped), None when nothing escaped."""
        n = self.escape_times.size
        return self.exposure / n if n else None

    @property
    def escape_time_err(self) -> float | None:
        """Standard error of :attr:`escape_time`, relative :math:`1/\\sqrt{n_{esc}}`."""
        tau = self.escape_time
        return None if tau is None else tau / math.sqrt(self.escape_times.size)

    @property
    def escape_time_lower(self) -> float | None:
        """95 % lower bound exposure / 3 of the mean escape time when nothing escaped, else None."""
        return None if self.escape_times.size else self.exposure / 3.0

    def to_dict(self) -> dict[str, object]:
        return {
            "times": self.times.tolist(), "fraction": self.fraction.tolist(),
            "fraction_err": self.fraction_err.tolist(), "escape_times": self.escape_times.tolist(),
            "paths": self.paths, "t_max": self.t_max, "exposure": self.exposure, "rate": self.rate,
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
        Escape amplitude on ``|x_j|``, > 0.
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
    exposure = float(np.where(np.isfinite(esc), esc, e.t_run).sum())
    mean = float(escaped.mean()) if escaped.size else None
    return EscapeCurve(times, frac, err, escaped, paths, e.t_run, exposure,
                       None if mean is None or not math.isfinite(mean) else mean)
