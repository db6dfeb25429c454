"""Studies of the Fokker--Planck solver, each ``python -m validation.studies.fpe.<name>``:

* :mod:`.bench`: time to a tolerance against the actual error over n and a, the meshes and the
  schemes (``--meshes``, ``--schemes``); its full run includes :mod:`.kink`, the scheme ``"xv"``
  at the kink n = 1 and where its accuracy is lost;
* :mod:`.xmesh`: the x mesh for 1 < n < 2, algebraic grading against geometric layers;
* :mod:`.xvspeed`: the level solves of scheme ``"xv"``, a base commit against the working tree;
* :mod:`.domain`: the measured domain (time to a tolerance, or the failure, over n x a), from
  which :mod:`fpe_harvester.fpe.domain` declines what it cannot solve.
"""

from __future__ import annotations

__all__: list[str] = []
