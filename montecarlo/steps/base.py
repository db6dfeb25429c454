"""The step-scheme protocol: what the path loop and :func:`montecarlo.simulate` use of a step."""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from fpe_harvester.model import Harvester

__all__ = ["StepScheme", "Kernels"]


class Kernels(NamedTuple):
    """A step scheme's numba kernels (signatures in :class:`StepScheme`)."""

    normals: int
    noise: Callable
    compose: Callable
    step: Callable
    advance: Callable
    twin_xi: Callable
    fast: Callable | None = None
    slow_kind: int = -1


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
        The scheme's numba kernels (arrays (N, P); noise arrays (normals, N, P)):

        ``normals`` : int
            Standard normals drawn per unit and step.
        ``noise(cf, z, buf)``
            The level's noise for one step from the normals ``z``, written to ``buf``.
        ``compose(cf_a, cf_b, e1, e2, out)``
            The noise of one step ``cf_b`` from two steps ``cf_a`` in a row (Richardson's
            coarse levels run on the fine level's noise).
        ``step(x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen)``
            Advance one level (x, v, V, xi; ``F`` the kicked on-site force at x, ``stuck`` the
            kink's held units, ``pvx`` the joint step's estimate of v xi) over one step with
            noise ``eps``. ``kind`` is the on-site treatment
            (:data:`montecarlo.layout.KIND_LINEAR`, ``KIND_KICK``, ``KIND_KINK``), ``xm``,
            ``fext``, ``cs``, ``rbm``, ``rbx`` shared scratch, ``w`` the live paths,
            ``counters`` the kink statistics, ``gen`` for steps that draw extra normals. The
            kernel takes the subset of these it needs, by parameter name, in any order (the
            frozen step's is ``_d_step(x, v, V, xi, F, stuck, xm, fext, w, cf, pp, kind,
            counters, cs)``).
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
            ``slow_kind``, which it never takes. The frozen step's made a harmonic
            ring's loop at two paths per chunk 0.88x of 940829b's instead of 1.07-1.21x; the
            joint step has none (one built like it measured no gain, 1.06-1.09x against
            1.05-1.07x).

    Arrays are passed one by one, not in tuples: reading arrays out of tuples in the loop cost
    up to 20 % in reference counting at small chunks. ``step`` is called directly (an
    intrinsic, :func:`montecarlo.steps.dispatch.step`); the small kernels are inlined into the
    loop (``inline="always"``) and ``noise`` fills a fixed buffer instead of returning an
    array. Measured at the solver's chunks (2-16 paths): every numba call with array
    arguments costs tens of ns, so a compiled wrapper layer or a call per small kernel made
    the loop 1.2-1.5x slower than the two loops it replaced, and an inlined wrapper of the
    step 1.15-1.3x (its parameters became reference-counted copies of the loop's arrays).

    The joint step's ``noise`` and ``compose`` are inlined wrappers of compiled kernels, which
    leaves 20 reference-count calls per ring step in the loop: a harmonic ring at tau = 1e-4,
    two paths per chunk, takes 1.04-1.09x the kernel time of the joint loop this one replaced
    (940829b). Measured alternatives: the loop calling those kernels directly, 1.04x, but the
    same convention for the frozen step cost its ring 5 %; their loops inlined, 1.11x; a
    non-inlined overload, 1.13x; arrays without reference counts, no gain.
    """

    name: str = ""
    tag: NamedTuple
    kernels: Kernels

    def coefficients(self, h: Harvester, dt: float) -> np.ndarray:
        """Coefficient array ``cf`` of one step ``dt`` (layout in :mod:`montecarlo.layout`)."""
        raise NotImplementedError

    def refusal(self, h: Harvester, kind: int) -> str | None:
        """Why this scheme cannot serve ``h`` with on-site treatment ``kind``, or None."""
        return None
