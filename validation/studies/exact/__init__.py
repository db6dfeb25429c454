"""Studies of the exact harmonic solver: :mod:`.bench`, its run time against its error beside
scipy's dense Lyapunov solve (``python -m validation.studies.exact.bench``)."""

from __future__ import annotations

__all__: list[str] = []
