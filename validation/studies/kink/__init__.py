"""The kink n = 1 in Monte Carlo: what its step gets wrong and how that is measured.

* :mod:`.timestep`: the time-step law, eta(dt) per a with Richardson-coupled differences and the
  fitted weak order (``python -m validation.studies.kink.timestep --out FILE.json``; the Monte
  Carlo benchmark's :mod:`validation.studies.mc.kink_dt` runs it);
* :mod:`.reference`: an independent reference scheme (exact crossings, linearly interpolated
  noise) and the product scheme's bias against it on common noise;
* :mod:`.exactflow_bias`: the bias of the exact-flow construction
  (:mod:`validation.references.exactflow`) against its step and trap threshold, which the strong
  kink's cross-checks add to its errors (``python -m validation.studies.kink.exactflow_bias``).
"""

from __future__ import annotations

__all__: list[str] = []
