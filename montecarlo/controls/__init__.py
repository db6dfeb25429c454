"""Control variates of the Monte Carlo estimator: quantities with exactly known means, run on
the same noise as the system, and the regression that uses them.

* :mod:`.base` -- the protocol (:class:`Control`);
* :mod:`.twin` -- the harmonic twin's moments (the twin itself: :mod:`montecarlo.harmonic`) and
  their accumulator in the path loop;
* :mod:`.martingale` -- martingale sums (mean 0 for any start), their end-of-window terms and
  their accumulator;
* :mod:`.sets` -- the registry (:data:`CONTROLS`), the candidate sets (:data:`CONTROL_SETS`) and
  the choice among them;
* :mod:`.regression` -- the regression (control-variate) estimator over replicas.
"""

from __future__ import annotations

from .base import Control
from .regression import MIN_DOF, Regression, enough_dof, regression_estimate
from .sets import CONTROL_SETS, CONTROLS, choose_controls, control_columns

__all__ = [
    "Control",
    "Regression",
    "regression_estimate",
    "enough_dof",
    "MIN_DOF",
    "CONTROLS",
    "CONTROL_SETS",
    "choose_controls",
    "control_columns",
]
