"""Step schemes of the Monte Carlo path loop: one module each, one registry.

* :mod:`.frozen` -- the frozen-xi Strang step (default when tau >= 10 dt);
* :mod:`.joint` -- the exact joint Gaussian step of (x, v, V, xi) (default when tau < 10 dt);
* :mod:`.averaged` -- the kink's step for tau < 10 dt: its flow driven by the step's mean of xi.

The protocol is :class:`~montecarlo.steps.base.StepScheme`. A new scheme is a module with its
tag class, its five kernels and a :class:`StepScheme` object, plus one entry in :data:`STEPS`;
the path loop (:mod:`montecarlo._loop`) reaches its kernels through
:mod:`montecarlo.steps.dispatch` and knows no scheme by name.
"""

from __future__ import annotations

from .averaged import AVERAGED
from .base import StepScheme
from .frozen import FROZEN
from .joint import JOINT

__all__ = ["StepScheme", "STEPS"]

#: Step schemes by name.
STEPS: dict[str, StepScheme] = {FROZEN.name: FROZEN, JOINT.name: JOINT, AVERAGED.name: AVERAGED}
