"""Discretizations measured and not adopted: the strong kink's candidate scheme, DG in (x, v, V)
with V graded toward 0 and discrete ordinates in xi (:mod:`.xvw`, ``python -m
validation.studies.prototypes.xvw``), on the mesh of :mod:`.xvw_mesh`, with its W = V - K_c x
variant (:mod:`.xvw_w`) and its hybrid (:mod:`.xvw_hybrid`: Hermite functions in V on the bulk's
(x, v) elements, the V mesh on the trap's; also the force of 1 < n). None is a product scheme:
they record why the strong kink goes to Monte Carlo.
"""

from __future__ import annotations

__all__: list[str] = []
