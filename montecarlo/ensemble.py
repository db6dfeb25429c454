"""The raw result of a Monte Carlo run: per-replica sums, counts and escape times (:func:`montecarlo.simulate`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fpe_harvester.errors import ParameterError

from .layout import MOMENTS

__all__ = ["Ensemble"]


@dataclass(frozen=True)
class Ensemble:
    """Raw result of :func:`simulate`: per-replica sums, counts and escape times.

    Attributes
    ----------
    sums : ndarray, shape (replicas, levels + 1, len(MOMENTS))
        Sums over measured unit-steps of the moments :data:`montecarlo.layout.MOMENTS`
        (``v xi`` already at the Strang point, or after a joint step its conditional expectation
        given the state before the step and the x reached; the twin's ``t_*`` at level 0 only),
        per level;
        the last row is level 0 over the first half of the measured window.
    counts : ndarray, shape (replicas, levels + 1)
        Number of unit-steps summed (fewer than ``paths * N * t_run/dt`` when paths escaped).
    escape_times : ndarray, shape (replicas, paths)
        Time of the first ``|x_j| > threshold`` of each path (burn-in included), ``inf`` if none.
    dts : tuple of float
        Time step of each level: ``(dt,)``, or ``(dt/2, dt)`` with Richardson coupling, or
        ``(dt/2, dt, 2 dt)`` with its third level.
    twin_kappa : float or None
        On-site stiffness of the harmonic twin run on level 0's noise (None: no twin).
    twin_mean : dict of float
        Exact expectations of the twin's moments at level 0's step
        (:func:`montecarlo.harmonic.twin_expectations`); empty without a twin.
    start : str
        ``"rest"`` or ``"twin"`` (the paths start from the twin's stationary law).
    kink_counters : tuple of int
        Kink treatment: unit-steps on the slow path (near x = 0), located zero crossings, entries
        into the averaged swing map, steps that exhausted the event budget (all levels).
    ctl : ndarray, shape (replicas, 2, columns) or None
        The sums of level 0 that the path loop accumulated for the controls named in
        ``simulate(..., controls=...)`` (:mod:`montecarlo.controls`), over the measured window and
        over its first half; None without such controls.
    ctl_names : dict of str to tuple of str
        Control name -> the names of its sums, which occupy the columns of ``ctl`` in this order.
    coarse_half : bool
        The coarse level ran through the burn-in and the first half of the measured window only
        (``simulate(..., coarse_half=True)``): its row holds that half, to be compared with level 0
        over the same half (the last row).
    """

    sums: np.ndarray
    counts: np.ndarray
    escape_times: np.ndarray
    dts: tuple[float, ...]
    paths: int
    t_burn: float
    t_run: float
    threshold: float
    path_steps: int
    wall_time: float
    kink_counters: tuple[int, int, int, int] = (0, 0, 0, 0)
    seed_entropy: int | None = None
    first_replica: int = 0
    notes: dict[str, object] = field(default_factory=dict)
    twin_kappa: float | None = None
    twin_mean: dict[str, float] = field(default_factory=dict)
    start: str = "rest"
    ctl: np.ndarray | None = None
    ctl_names: dict[str, tuple[str, ...]] = field(default_factory=dict)
    coarse_half: bool = False

    @property
    def replicas(self) -> int:
        return int(self.sums.shape[0])

    @property
    def levels(self) -> int:
        """Number of time-step levels (1, or 2 or 3 with Richardson coupling)."""
        return len(self.dts)

    def moments(self, level: int = 0) -> dict[str, np.ndarray]:
        """Per-replica averages ``{name: array(replicas)}`` of one level (NaN where nothing counted).

        ``level = -1`` gives level 0 over the first half of the measured window.
        """
        cnt = self.counts[:, level]
        safe = np.where(cnt > 0, cnt, 1.0)
        out = {name: np.where(cnt > 0, self.sums[:, level, i] / safe, np.nan) for i, name in enumerate(MOMENTS)}
        return out

    def control_sums(self, control: str, first_half: bool = False) -> dict[str, np.ndarray]:
        """Per-replica sums of the control ``control`` ``{name: array(replicas)}``, each divided by
        the unit-steps counted in its window (NaN where nothing counted). Empty when the loop did
        not accumulate that control."""
        names = self.ctl_names.get(control, ())
        if self.ctl is None or not names:
            return {}
        first = 0
        for name, cols in self.ctl_names.items():
            if name == control:
                break
            first += len(cols)
        cnt = self.counts[:, -1 if first_half else 0]
        safe = np.where(cnt > 0, cnt, 1.0)
        row = self.ctl[:, 1 if first_half else 0, first:first + len(names)]
        return {name: np.where(cnt > 0, row[:, i] / safe, np.nan) for i, name in enumerate(names)}

    def escaped_fraction(self) -> float:
        """Fraction of all paths that crossed the escape threshold."""
        return float(np.isfinite(self.escape_times).mean())

    def merge(self, other: Ensemble) -> Ensemble:
        """Concatenate the replicas of two runs with identical settings."""
        if (other.dts, other.paths, other.t_run, other.t_burn, other.twin_kappa, other.start,
                other.ctl_names, other.coarse_half) != (self.dts, self.paths, self.t_run, self.t_burn,
                                                        self.twin_kappa, self.start, self.ctl_names,
                                                        self.coarse_half):
            raise ParameterError("can only merge ensembles with the same dt, paths, t_run, t_burn, "
                                 "twin, start, accumulated controls and coarse window")
        return Ensemble(
            sums=np.concatenate([self.sums, other.sums]),
            counts=np.concatenate([self.counts, other.counts]),
            escape_times=np.concatenate([self.escape_times, other.escape_times]),
            dts=self.dts, paths=self.paths, t_burn=self.t_burn, t_run=self.t_run,
            threshold=self.threshold,
            path_steps=self.path_steps + other.path_steps,
            wall_time=self.wall_time + other.wall_time,
            kink_counters=tuple(a + b for a, b in zip(self.kink_counters, other.kink_counters)),
            seed_entropy=self.seed_entropy,
            first_replica=min(self.first_replica, other.first_replica),
            notes=dict(self.notes),
            twin_kappa=self.twin_kappa,
            twin_mean=dict(self.twin_mean),
            start=self.start,
            ctl=None if self.ctl is None else np.concatenate([self.ctl, other.ctl]),
            ctl_names=dict(self.ctl_names),
            coarse_half=self.coarse_half,
        )
