"""The control variates' registry and the choice of a set: which columns a regression gets.

A *control* is one group of per-replica quantities with an exactly known mean, accumulated by
the path loop (:mod:`montecarlo._loop`): the harmonic twin's moments (:mod:`.twin`), the
martingale sums (:mod:`.martingale`) and their end-of-window terms. :data:`CONTROLS` maps each
to the function that reads its columns from an ensemble; :data:`CONTROL_SETS` names the
candidate combinations, and :func:`choose_controls` picks one without looking at the data.
A new control is one accumulator in the loop, one entry in :data:`CONTROLS` and the sets that
use it.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable

import numpy as np

from fpe_harvester.errors import ParameterError

from .regression import enough_dof
from .twin import TWIN_MOMENTS

if TYPE_CHECKING:
    from ..simulate import Ensemble

__all__ = ["CONTROLS", "CONTROL_SETS", "BOUNDARY_TAIL", "control_columns", "choose_controls", "stationary_window"]

#: Tail probability of the test (Hotelling's T^2 against chi^2) that the end-of-window terms
#: have mean 0; where it fails the candidate sets with them are left out (:func:`stationary_window`).
BOUNDARY_TAIL = 1e-3

#: Columns of one control: (values per replica, values over the first half of the window, means).
Columns = tuple[list[np.ndarray], list[np.ndarray], list[float]]


def _twin(e: Ensemble, valid: np.ndarray) -> Columns | None:
    """The twin's moments :data:`montecarlo.controls.twin.TWIN_MOMENTS`, exact means at its step;
    only for paths started from its stationary law."""
    if e.twin_kappa is None or e.start != "twin":
        return None
    mom, mom_first = e.moments(0), e.moments(-1)
    return ([mom["t_" + name][valid] for name in TWIN_MOMENTS],
            [mom_first["t_" + name][valid] for name in TWIN_MOMENTS],
            [e.twin_mean[name] for name in TWIN_MOMENTS])


def _martingale_part(e: Ensemble, valid: np.ndarray, boundary: bool) -> Columns:
    mg, mg_first = e.martingale(), e.martingale(first_half=True)
    names = [name for name in e.mart_names if name.startswith("bd_") == boundary]
    return [mg[name][valid] for name in names], [mg_first[name][valid] for name in names], [0.0] * len(names)


def _martingale(e: Ensemble, valid: np.ndarray) -> Columns | None:
    """The martingale sums (mean 0 exactly, any start)."""
    return _martingale_part(e, valid, False) if e.mart_names else None


def _boundary(e: Ensemble, valid: np.ndarray) -> Columns | None:
    """The martingale sums' end-of-window terms (``bd_*``): mean 0 only for a stationary window,
    so only where :func:`stationary_window` admits them."""
    if not e.mart_names or not stationary_window(e.martingale(), valid, e.mart_names):
        return None
    return _martingale_part(e, valid, True)


#: Controls by name, in the order of their columns in a set.
CONTROLS: dict[str, Callable[[Ensemble, np.ndarray], Columns | None]] = {
    "twin": _twin,
    "martingale": _martingale,
    "boundary": _boundary,
}

#: Candidate sets of control variates: name -> the controls it joins. The order breaks ties in
#: :func:`choose_controls`.
CONTROL_SETS: dict[str, tuple[str, ...]] = {
    "twin": ("twin",),
    "martingale": ("martingale",),
    "martingale+twin": ("martingale", "twin"),
    "martingale+boundary": ("martingale", "boundary"),
    "martingale+boundary+twin": ("martingale", "boundary", "twin"),
}


def control_columns(e: Ensemble, valid: np.ndarray, which: str, n: int) -> tuple | None:
    """Controls of the candidate set ``which``: (C, C over the first half, mu), or None where the
    set is not available (a control missing, an escaped path, too few replicas ``n`` for
    :func:`montecarlo.controls.regression.enough_dof`)."""
    if e.escaped_fraction() > 0.0:
        return None
    cols: list[np.ndarray] = []
    first: list[np.ndarray] = []
    mu: list[float] = []
    for name, read in CONTROLS.items():
        if name not in CONTROL_SETS[which]:
            continue
        part = read(e, valid)
        if part is None:
            return None
        cols += part[0]
        first += part[1]
        mu += part[2]
    if not enough_dof(n, len(cols)):
        return None
    return np.column_stack(cols), np.column_stack(first), np.array(mu)


def choose_controls(sizes: dict[str, int]) -> str:
    """The control set to use among the available ones (name -> number of controls): the one with
    the most controls, ties to the earlier in :data:`CONTROL_SETS`.

    The rule does not look at the data. Choosing the set whose *estimated* variance of eta is
    least picks, among sets of similar merit, the one whose variance happens to be
    underestimated, and its error bar is then too small. Measured (tol 1e-2, 32 replicas,
    400 seeds each, z against Fokker--Planck at 1e-4): n = 3, a = 0.5, rms z of eta 1.137 with
    the least-variance choice (twin 361 times, martingale 39), 1.083 with the twin always, 0.986
    with the martingale set always (its error 1.4x the chosen one's); n = 8, a = 0.5: 1.009, 1.024
    and 0.948. Each set is contained in the richer ones that add to it (martingale within
    martingale+twin and martingale+boundary, all within martingale+boundary+twin; twin within
    martingale+twin), and a set that contains another never has a larger residual variance in the
    population: the extra controls cost degrees of freedom only, which
    :func:`montecarlo.controls.regression.enough_dof` keeps within a factor 2 of variance. The two sets that
    do not contain each other (martingale+twin, martingale+boundary) are ordered by size.

    >>> choose_controls({"twin": 11, "martingale": 15})
    'martingale'
    """
    if not sizes:
        raise ParameterError("choose_controls needs at least one available set")
    order = list(CONTROL_SETS)
    return max(sizes, key=lambda name: (sizes[name], -order.index(name)))


def stationary_window(mg: dict[str, np.ndarray], valid: np.ndarray, names: tuple[str, ...]) -> bool:
    """Whether the end-of-window terms are usable: present, and their means consistent with 0
    (Hotelling's T^2 below the chi^2 quantile at :data:`BOUNDARY_TAIL`). They have mean 0 only
    for a stationary window; a transient left by the burn-in shows here first (ring n = 3, N = 3,
    k = -0.5 from rest, dt = 0.1, 200 replicas of 4 paths, t_run = 40: refused at t_burn = 5,
    accepted at t_burn = 50)."""
    from scipy.stats import chi2

    cols = [mg[name][valid] for name in names if name.startswith("bd_")]
    n = int(valid.sum())
    if not cols or n < 3:
        return False
    C = np.column_stack(cols)
    sd = C.std(axis=0, ddof=1)
    C = C[:, sd > 0] / sd[sd > 0]
    # Hotelling's T^2 of the means (the terms are strongly correlated), on the resolved rank
    m = C.mean(axis=0)
    Cc = C - m
    _, sv, vt = np.linalg.svd(Cc / math.sqrt(n - 1), full_matrices=False)
    keep = sv > 1e-8 * sv[0] if sv.size else sv > 0
    proj = vt[keep] @ m / sv[keep]
    t2 = n * float(proj @ proj)
    return bool(t2 < chi2.ppf(1.0 - BOUNDARY_TAIL, max(int(keep.sum()), 1)))
