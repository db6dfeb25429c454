"""Studies of the Monte Carlo solver, each ``python -m validation.studies.mc.<name>``:
:mod:`.bench` runs the design studies below in one go (the report's benchmark section a few of
them): :mod:`.rng` (the generators' cost), :mod:`.throughput` (path-steps per second),
:mod:`.equal_error` (against a numpy Euler--Maruyama loop at equal error), :mod:`.bias` (the
time-step bias), :mod:`.tau` (the noise's correlation time), :mod:`.steep` (steep walls),
:mod:`.controls` (the harmonic twin), :mod:`.martingale` (the martingale controls and their
coverage), :mod:`.policy` (the time-step policy and its coverage), :mod:`.boundary` (the
end-of-window terms) and :mod:`.kink_dt` (the kink's time-step law, with
:mod:`validation.studies.kink`).
"""

from __future__ import annotations

__all__: list[str] = []
