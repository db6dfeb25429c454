"""Compile-time dispatch of the step protocol: each kernel of :class:`~montecarlo.steps.base.StepScheme`
as a generic numba function of the scheme's tag.

The path loop calls ``noise(tag, ...)``, ``step(tag, ...)`` etc.; numba resolves each call from
the tag's type (its NamedTuple class) to the scheme's own kernel when the loop is compiled, so
the loop is specialised per scheme and cached like any other kernel. Every kernel is inlined
(numba IR), so that the loop calls the scheme's own step as the two loops before it did
(:class:`~montecarlo.steps.base.StepScheme` says what the calls cost).
"""

from __future__ import annotations

from numba.extending import overload

from . import STEPS

__all__ = ["normals", "noise", "compose", "step", "advance", "twin_xi"]

_KERNELS = {type(s.tag): s.kernels for s in STEPS.values()}


def _kernels(tag):
    return _KERNELS[tag.instance_class]


def normals(tag):
    """Standard normals per unit and step of the scheme ``tag``, a compile-time constant."""
    raise NotImplementedError("numba only")


def noise(tag, cf, z, buf):
    """The level's noise for one step (``kernels.noise`` of the scheme ``tag``)."""
    raise NotImplementedError("numba only")


def compose(tag, cf_a, cf_b, e1, e2, out):
    """The noise of one step from two in a row (``kernels.compose``)."""
    raise NotImplementedError("numba only")


def step(tag, x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen):
    """Advance one level over one step (``kernels.step``)."""
    raise NotImplementedError("numba only")


def advance(tag, xi, eps, cf):
    """The noise the step left, after the measurement (``kernels.advance``)."""
    raise NotImplementedError("numba only")


def twin_xi(tag, xi):
    """The twin's xi array (``kernels.twin_xi``)."""
    raise NotImplementedError("numba only")


@overload(normals, jit_options={"cache": True, "nogil": True}, inline="always")
def _normals(tag):
    n = _kernels(tag).normals
    return lambda tag: n


@overload(noise, jit_options={"cache": True, "nogil": True}, inline="always")
def _noise(tag, cf, z, buf):
    f = _kernels(tag).noise

    def impl(tag, cf, z, buf):
        f(cf, z, buf)
    return impl


@overload(compose, jit_options={"cache": True, "nogil": True}, inline="always")
def _compose(tag, cf_a, cf_b, e1, e2, out):
    f = _kernels(tag).compose
    return lambda tag, cf_a, cf_b, e1, e2, out: f(cf_a, cf_b, e1, e2, out)


@overload(step, jit_options={"cache": True, "nogil": True}, inline="always")
def _step(tag, x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen):
    f = _kernels(tag).step

    def impl(tag, x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen):
        f(x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen)
    return impl


@overload(advance, jit_options={"cache": True, "nogil": True}, inline="always")
def _advance(tag, xi, eps, cf):
    f = _kernels(tag).advance
    return lambda tag, xi, eps, cf: f(xi, eps, cf)


@overload(twin_xi, jit_options={"cache": True, "nogil": True}, inline="always")
def _twin_xi(tag, xi):
    f = _kernels(tag).twin_xi
    return lambda tag, xi: f(xi)
