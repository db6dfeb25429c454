"""The step-scheme protocol: what the path loop and :func:`montecarlo.simulate` use of a step."""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from fpe_harvester.model import Harvester

__all__ = ["StepScheme", "Kernels"]


class Kernels(NamedTuple):
    """A step scheme's numba kernels (signatures in :class:`StepScheme`)."""

    noise: Callable
    compose: Callable
    step: Callable
    advance: Callable
    twin_xi: Callable


class StepScheme:
    """One way of advancing the ring over a time step, with its noise (Python side).

    A scheme lives in its own module of :mod:`montecarlo.steps` and has one entry in
    :data:`montecarlo.steps.STEPS`; nothing else names it. Members used by the driver:

    Attributes
    ----------
    name : str
        Its key in :data:`montecarlo.steps.STEPS`.
    tag : NamedTuple
        An instance of the scheme's own NamedTuple class with the field ``normals`` (standard
        normals drawn per unit and step). Its numba type selects the scheme's kernels when the
        path loop (:func:`montecarlo._loop.run_chunk`) is compiled: one specialised loop per
        scheme, no branch on the scheme at run time.
    kernels : Kernels
        The scheme's numba kernels, with these signatures (arrays
        (N, P), noise arrays (normals, N, P), ``lv`` a :class:`montecarlo._kernels.Level`):

        ``noise(cf, z, buf) -> eps``
            The level's noise for one step from the normals ``z`` (may return ``z`` itself or
            fill and return ``buf``).
        ``compose(cf_a, cf_b, e1, e2, out)``
            The noise of one step ``cf_b`` from two steps ``cf_a`` in a row (Richardson's
            coarse levels run on the fine level's noise).
        ``step(lv, eps, cf, pp, kind, scr, w, counters, gen)``
            Advance one level over one step (``kind``: the on-site treatment,
            :data:`montecarlo._kernels.KIND_LINEAR` / ``KIND_KICK`` / ``KIND_KINK``; ``w`` the
            live paths; ``gen`` for steps that draw extra normals).
        ``advance(lv, eps, cf)``
            After the level was measured: whatever of its noise the step left (e.g. the OU
            update of xi), or nothing.
        ``twin_xi(xi) -> xi_t``
            The harmonic twin's xi array given the fine level's: the same array when the step
            leaves xi to :func:`advance` (the twin is then never advanced), its own otherwise.
    """

    name: str = ""
    tag: NamedTuple
    kernels: Kernels

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        """Coefficient array ``cf`` of one step ``dt`` (layout in :mod:`montecarlo._kernels`)."""
        raise NotImplementedError

    def refusal(self, h: Harvester, kind: int) -> str | None:
        """Why this scheme cannot serve ``h`` with on-site treatment ``kind``, or None."""
        return None
