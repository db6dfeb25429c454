"""The stepper protocol: what the path loop, :func:`montecarlo.simulate` and the solver use of a step."""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from fpe_harvester.model import Harvester

__all__ = ["Stepper", "Kernels"]


class Kernels(NamedTuple):
    """A stepper's numba kernels (signatures in :class:`Stepper`)."""

    normals: int
    noise: Callable
    compose: Callable
    step: Callable
    advance: Callable
    twin_xi: Callable
    fast: Callable | None = None
    slow_kind: int = -1


class Stepper:
    """One way of advancing the ring over a time step, with its noise (Python side).

    A stepper lives in its own module of :mod:`montecarlo.steps` and has one entry in
    :data:`montecarlo.steps.STEPPERS`; nothing else names it. Which one runs is decided in one
    place, :func:`montecarlo.steps.resolve_step`, from the members below.

    Attributes
    ----------
    name : str
        Its key in :data:`montecarlo.steps.STEPPERS`, the value of the ``step`` option.
    priority : int
        ``step="auto"`` takes the stepper of highest priority that does not refuse the problem
        and prefers the time step (:meth:`refusal`, :meth:`preferred`).
    description : str
        What it does, for the solver's ``info["integrator"]``.
    preference : str
        When :meth:`preferred` holds, in words (for the message when no stepper serves).
    dt_start : float
        The coarse time step, in model time units, at which the solver's automatic ``dt`` starts
        with this stepper (:meth:`start_dt`).
    twin : bool
        Whether it can run the harmonic twin, whose exact law at this step is
        :meth:`twin_matrices`.
    tag : NamedTuple
        An instance of the stepper's own NamedTuple class with the field ``normals`` (standard
        normals drawn per unit and step). Its numba type selects the stepper's kernels when the
        path loop (:func:`montecarlo._loop.run_chunk`) is compiled: one specialised loop per
        stepper, no branch on the stepper at run time.
    kernels : Kernels
        The stepper's numba kernels (arrays (N, P); noise arrays (normals, N, P)):

        ``normals`` : int
            Standard normals drawn per unit and step.
        ``noise(cf, z, buf)``
            The level's noise for one step from the normals ``z``, written to ``buf``.
        ``compose(cf_a, cf_b, e1, e2, out)``
            The noise of one step ``cf_b`` from two steps ``cf_a`` in a row (Richardson's
            coarse levels run on the fine level's noise).
        ``step(x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen)``
            Advance one level (x, v, V, xi; ``F`` the kicked on-site force at x, ``stuck`` the
            kink's held units, ``pvx`` the step's estimate of v xi) over one step with noise
            ``eps``. ``kind`` is the on-site treatment (:data:`montecarlo.layout.KIND_LINEAR`,
            ``KIND_KICK``, ``KIND_KINK``), ``xm``, ``fext``, ``cs``, ``rbm``, ``rbx`` shared
            scratch, ``w`` the live paths, ``counters`` the kink statistics, ``gen`` for steps
            that draw extra normals. The kernel takes the subset of these it needs, by parameter
            name, in any order (the frozen step's is ``d_step(x, v, V, xi, F, stuck, xm, fext, w,
            cf, pp, kind, counters, cs)``).
        ``advance(xi, eps, cf)``
            After the level was measured: whatever of its noise the step left (the OU update of
            xi), or nothing.
        ``twin_xi(xi) -> xi_t``
            The harmonic twin's xi array given the fine level's: the same array when the step
            leaves xi to ``advance`` (the twin is then never advanced), its own otherwise.
        ``fast(...) -> bool`` (optional)
            ``step`` for the common case in a kernel of its own, taking a subset of ``step``'s
            arguments by name: the same operations (bit-identical), its small kernels inlined;
            it returns False, with nothing changed, where ``step`` must take the step (a stiff
            wall, the kink's flow). The loop calls it first, except for the on-site treatment
            ``slow_kind``, which it never takes.

    Arrays are passed one by one, not in tuples, and ``step`` is called directly (an intrinsic,
    :func:`montecarlo.steps.dispatch.step`) while the small kernels are inlined into the loop
    (``inline="always"``; ``noise`` fills a fixed buffer instead of returning an array): at the
    solver's chunks of 2-16 paths every numba call with array arguments costs tens of
    nanoseconds, and reading arrays out of tuples is reference-counted at every step (the
    measurements behind these choices: docs/methods.md, "Monte Carlo kernels").
    """

    name: str = ""
    priority: int = 0
    description: str = ""
    preference: str = ""
    dt_start: float = 0.02
    twin: bool = True
    tag: NamedTuple
    kernels: Kernels

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        """Coefficient array ``cf`` of one step ``dt`` (layout in :mod:`montecarlo.layout`)."""
        raise NotImplementedError

    def refusal(self, h: Harvester, kind: int) -> str | None:
        """Why this stepper cannot serve ``h`` with on-site treatment ``kind`` at any time step,
        or None."""
        return None

    def preferred(self, h: Harvester, kind: int, dt: float) -> bool:
        """Whether this stepper is the one to take for ``h`` at the coarse time step ``dt``
        (:attr:`preference`)."""
        return True

    def extrapolates(self, h: Harvester, kind: int) -> bool:
        """Whether the solver's ``extrapolate=None`` may report the Richardson extrapolation with this
        stepper for ``h`` (on-site treatment ``kind``): where its time-step bias was measured to be
        in the asymptotic range (order 2, then 3) from twice its starting step. Default False."""
        return False

    def start_dt(self, h: Harvester, kind: int, scale: float) -> float:
        """The coarse step at which an automatic ``dt`` starts: ``scale`` times :attr:`dt_start`
        (the solver's ``scale`` is 2 with extrapolation)."""
        return scale * self.dt_start

    def twin_matrices(self, lin: Harvester, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Per-mode one-step matrices of this step on the harmonic ring ``lin`` (n = 2), from which
        the twin's exact law follows (:mod:`montecarlo.harmonic`).

        Returns
        -------
        M : ndarray (N, 4, 4)
            Mode q's state (x, v, V, xi) before one step -> before the next (without noise).
        T : ndarray (N, 4, 4)
            State before a step -> the measured state.
        Q : ndarray (4, 4)
            Covariance of the noise added per step.
        half : float
            Factor on the measured :math:`v\\xi` (``cf[CF_XI_HALF]``).
        """
        raise NotImplementedError(f"the {self.name} step has no harmonic twin")
