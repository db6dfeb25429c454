"""Switching between the buckled states of a multistable ring, from sampled paths.

A ring with cubic bonds (``k3 > 0``) beyond the fold (:func:`fpe_harvester.landscape.fold_coupling`)
has buckled minima: one unit displaced by :math:`\\pm u`, its neighbours near the cusp
(:mod:`fpe_harvester.landscape`). Noise carries the ring from one to another. Each sample is
labelled by its buckled unit and the sign of its displacement (``+-(j + 1)``) where the largest
:math:`|x_j|` exceeds a cut, else 0 (near the origin, or on the way); a switch is a change of the
last nonzero label to a different nonzero one, so that excursions that return to the same
buckled state do not count. The mean residence time is the observed time per switch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fpe_harvester.errors import check_real
from fpe_harvester.model import Harvester

from .sample import sample_states

__all__ = ["Switching", "switching_times", "buckled_labels"]


@dataclass(frozen=True)
class Switching:
    """Switches between buckled states observed on independent paths.

    Attributes
    ----------
    residence : float or None
        Mean residence time in a buckled state [time units]: observed time / switches (None
        without a switch).
    residence_err : float or None
        Its standard error, from the spread of the switch counts over paths (delta method).
    switches : int
        Switches counted on all paths.
    time : float
        Observed time, summed over paths [time units].
    buckled_share : float
        Fraction of samples in some buckled state (label != 0).
    """

    residence: float | None
    residence_err: float | None
    switches: int
    time: float
    buckled_share: float


def buckled_labels(x: np.ndarray, cut: float) -> np.ndarray:
    """Label of each sample of positions ``x`` (..., N): ``sign(x_j) (j + 1)`` for the unit j
    with the largest :math:`|x_j|` where that exceeds ``cut``, else 0."""
    j = np.argmax(np.abs(x), axis=-1)
    xj = np.take_along_axis(x, j[..., None], axis=-1)[..., 0]
    return np.where(np.abs(xj) > cut, np.sign(xj) * (j + 1), 0).astype(np.int64)


def _count_switches(labels: np.ndarray) -> np.ndarray:
    """Switches per path of labels (samples, paths): changes of the last nonzero label."""
    counts = np.zeros(labels.shape[1], dtype=np.int64)
    for p in range(labels.shape[1]):
        seq = labels[:, p]
        seq = seq[seq != 0]
        counts[p] = int(np.count_nonzero(seq[1:] != seq[:-1]))
    return counts


def switching_times(h: Harvester, cut: float, *, t_run: float = 1000.0, paths: int = 16, every: float = 0.5,
                    dt: float = 0.01, t_burn: float = 50.0, seed: int = 0) -> Switching:
    """Mean residence time between switches of the buckled state (module docstring).

    Parameters
    ----------
    h : Harvester
        A ring (N >= 2), typically with ``k3 > 0`` beyond the fold.
    cut : float
        Amplitude above which the largest unit counts as buckled, > 0 (e.g. half the buckled
        minimum's displacement, :func:`fpe_harvester.landscape.landscape`).
    t_run : float
        Observed time per path [time units], > 0.
    paths : int
        Independent paths, >= 2 (the error comes from their spread).
    every : float
        Sampling interval [time units]; residence times much shorter are not resolved.
    dt, t_burn, seed
        As in :func:`montecarlo.sample.sample_states`.

    Examples
    --------
    >>> h = Harvester.build(a=0.5, n=1, N=3, k=-0.6, k3=0.1)
    >>> s = switching_times(h, 1.1, t_run=200.0, paths=4, seed=1)
    >>> s.switches > 0
    True
    """
    cut = check_real("cut", cut, low=0.0, low_open=True)
    t_run = check_real("t_run", t_run, low=0.0, low_open=True)
    samples = max(1, int(round(t_run / every)))
    x = sample_states(h, samples=samples, paths=paths, every=every, t_burn=t_burn, dt=dt, seed=seed)[..., 0]
    labels = buckled_labels(x, cut)
    counts = _count_switches(labels)
    t_path = samples * every
    total = int(counts.sum())
    share = float(np.mean(labels != 0))
    if total == 0:
        return Switching(None, None, 0, t_path * paths, share)
    residence = t_path * paths / total
    rel = float(np.std(counts, ddof=1)) / math.sqrt(paths) / float(counts.mean())
    return Switching(residence, residence * rel, total, t_path * paths, share)
