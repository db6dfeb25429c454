"""The control protocol: what :func:`montecarlo.simulate` and the control sets use of a control variate."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fpe_harvester.model import Harvester

if TYPE_CHECKING:
    from ..ensemble import Ensemble

__all__ = ["Control", "Columns"]

#: Columns of one control: (values per replica, values over the first half of the measured
#: window, exact means), one entry per control variate.
Columns = tuple[list[np.ndarray], list[np.ndarray], list[float]]


class Control:
    """One group of control variates: per-replica quantities run on the same noise as the system
    whose means are known exactly, so that a regression on them (:mod:`.regression`) removes
    variance and adds no bias.

    A control lives in its own module of :mod:`montecarlo.controls` and has one entry in
    :data:`montecarlo.controls.CONTROLS`; the candidate sets (:data:`~montecarlo.controls.CONTROL_SETS`)
    name it. What the path loop accumulates for it is the one explicit place
    (:mod:`montecarlo._loop`): its kernel's call, and the ``Setup`` fields :meth:`loop_fields`
    fills.

    Attributes
    ----------
    name : str
        Its key in :data:`montecarlo.controls.CONTROLS`.
    accumulated : bool
        Whether the path loop accumulates sums for it when it is named in ``simulate(...,
        controls=...)`` (:meth:`sums`); False for a control that reads what the ensemble holds
        anyway (the twin's moments, the martingale's end-of-window terms).
    crossfit : bool
        Whether a set that contains this control is fitted by cross-fitting
        (:func:`montecarlo.controls.regression.crossfit_estimate`) instead of the in-sample
        regression: True for a control of many columns.
    """

    name: str = ""
    accumulated: bool = False
    crossfit: bool = False

    def sums(self, h: Harvester) -> tuple[str, ...]:
        """Names of the per-replica sums the path loop accumulates for this control on ``h``, in
        the order of its kernel (empty when not :attr:`accumulated`)."""
        return ()

    def loop_fields(self, h: Harvester, offset: int) -> dict[str, int]:
        """The path loop's ``Setup`` fields that place this control's sums at columns
        ``offset .. offset + len(sums(h)) - 1`` of its control accumulator."""
        return {}

    def columns(self, e: Ensemble, valid: np.ndarray) -> Columns | None:
        """The control variates of the replicas ``valid`` of ``e`` (values, values over the first
        half of the window, exact means), or None where ``e`` does not have them."""
        raise NotImplementedError
