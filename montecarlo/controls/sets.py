"""The control variates' registry and the choice of a set: which columns a regression gets.

A *control* (:class:`~montecarlo.controls.base.Control`) is one group of per-replica quantities
with an exactly known mean: the harmonic twin's moments (:mod:`.twin`), the martingale sums and
the end-of-window terms (:mod:`.martingale`), the generator's sums (:mod:`.generator`).
:data:`CONTROLS` holds them by name; :func:`montecarlo.simulate` lays out the path loop's
accumulator from the ones it is asked to accumulate, and :func:`control_columns` reads a
candidate set's columns from an ensemble.
:data:`CONTROL_SETS` names the candidate combinations, and :func:`choose_controls` picks one
without looking at the data. A new control is a module with its :class:`Control` object, one
entry in :data:`CONTROLS`, the sets that use it and, if the path loop accumulates it, its call
in :mod:`montecarlo._loop`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from fpe_harvester.errors import ParameterError

from .base import Control
from .generator import GENERATOR
from .martingale import BOUNDARY, MARTINGALE
from .regression import FOLDS, crossfit_dof, enough_dof
from .twin import TWIN

if TYPE_CHECKING:
    from ..ensemble import Ensemble

__all__ = ["CONTROLS", "CONTROL_SETS", "SetColumns", "control_columns", "choose_controls"]

#: Controls by name, in the order of their columns in a set.
CONTROLS: dict[str, Control] = {c.name: c for c in (TWIN, MARTINGALE, BOUNDARY, GENERATOR)}

#: Candidate sets of control variates: name -> the controls it joins. The order breaks ties in
#: :func:`choose_controls`.
CONTROL_SETS: dict[str, tuple[str, ...]] = {
    "twin": ("twin",),
    "martingale": ("martingale",),
    "martingale+twin": ("martingale", "twin"),
    "martingale+boundary": ("martingale", "boundary"),
    "martingale+boundary+twin": ("martingale", "boundary", "twin"),
    "martingale+generator": ("martingale", "generator"),
    "martingale+twin+generator": ("martingale", "twin", "generator"),
    "martingale+boundary+generator": ("martingale", "boundary", "generator"),
    "martingale+boundary+twin+generator": ("martingale", "boundary", "twin", "generator"),
}


class SetColumns(NamedTuple):
    """The columns of a candidate set for the regression.

    Attributes
    ----------
    C, first : ndarray (R, p)
        The controls per replica over the measured window and over its first half.
    mu : ndarray (p,)
        Their exact means.
    crossfit : bool
        Fit by cross-fitting (some control of the set asks for it, :attr:`Control.crossfit`).
    """

    C: np.ndarray
    first: np.ndarray
    mu: np.ndarray
    crossfit: bool


def control_columns(e: Ensemble, valid: np.ndarray, which: str, n: int) -> SetColumns | None:
    """Controls of the candidate set ``which``, or None where the set is not available (a control
    missing, an escaped path, too few replicas ``n`` for
    :func:`montecarlo.controls.regression.enough_dof`, or with cross-fitting for every fold's fit,
    :func:`~montecarlo.controls.regression.crossfit_dof`)."""
    if e.escaped_fraction() > 0.0:
        return None
    cols: list[np.ndarray] = []
    first: list[np.ndarray] = []
    mu: list[float] = []
    crossfit = False
    for name, control in CONTROLS.items():
        if name not in CONTROL_SETS[which]:
            continue
        crossfit |= control.crossfit
        part = control.columns(e, valid)
        if part is None:
            return None
        cols += part[0]
        first += part[1]
        mu += part[2]
    if not (crossfit_dof(n, len(cols)) and n >= 2 * FOLDS if crossfit else enough_dof(n, len(cols))):
        return None
    return SetColumns(np.column_stack(cols), np.column_stack(first), np.array(mu), crossfit)


def choose_controls(sizes: dict[str, int]) -> str:
    """The control set to use among the available ones (name -> number of controls): the one with
    the most controls, ties to the earlier in :data:`CONTROL_SETS`.

    The rule does not look at the data. Choosing the set whose *estimated* variance of eta is
    least picks, among sets of similar merit, the one whose variance happens to be
    underestimated, and its error bar is then too small (docs/methods.md, "Why the settings are
    what they are").
    Each set is contained in the richer ones that add to it (martingale within
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
