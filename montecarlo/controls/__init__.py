"""Control variates of the Monte Carlo estimator: quantities with exactly known means, run on
the same noise as the system, and the regression that uses them.

* :mod:`.twin` -- the harmonic twin ring: its exact moments at the integrator's step, the
  start from its stationary law, and its accumulator in the path loop;
* :mod:`.martingale` -- martingale sums (mean 0 for any start) and their accumulator;
* :mod:`.sets` -- the registry of controls (:data:`CONTROLS`), the candidate sets
  (:data:`CONTROL_SETS`) and the choice among them;
* :mod:`.regression` -- the regression (control-variate) estimator over replicas.
"""

from __future__ import annotations

from .regression import MIN_DOF, Regression, enough_dof, regression_estimate
from .sets import CONTROL_SETS, CONTROLS, choose_controls, control_columns
from .twin import linearized_stiffness, twin_expectations

__all__ = [
    "Regression",
    "regression_estimate",
    "enough_dof",
    "MIN_DOF",
    "CONTROLS",
    "CONTROL_SETS",
    "choose_controls",
    "control_columns",
    "twin_expectations",
    "linearized_stiffness",
]
