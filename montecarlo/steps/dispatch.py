"""Compile-time dispatch of the step protocol: each kernel of :class:`~montecarlo.steps.base.Stepper`
as a generic numba function of the stepper's tag.

The path loop calls ``noise(tag, ...)``, ``step(tag, ...)`` etc.; numba resolves each call from
the tag's type (its NamedTuple class) to the stepper's own kernel when the loop is compiled, so
the loop is specialised per stepper and cached like any other kernel. ``step`` is an intrinsic
that calls the stepper's step kernel directly, as the two loops before it did; the small
kernels are inlined (numba IR) (:class:`~montecarlo.steps.base.Stepper` says what the calls
cost).
"""

from __future__ import annotations

import inspect

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, overload

from . import STEPPERS

__all__ = ["normals", "noise", "compose", "step", "advance", "twin_xi", "STEP_ARGS"]

#: The arguments of ``step(tag, ...)`` after the tag, by name; a stepper's step kernel takes the
#: ones it names (:class:`~montecarlo.steps.base.Stepper`).
STEP_ARGS = ("x", "v", "V", "xi", "F", "stuck", "pvx", "eps", "cf", "pp", "kind", "xm", "fext", "cs", "rbm",
             "rbx", "w", "counters", "gen")

_KERNELS = {type(s.tag): s.kernels for s in STEPPERS.values()}


def _kernels(tag):
    return _KERNELS[tag.instance_class]


def normals(tag):
    """Standard normals per unit and step of the stepper ``tag``, a compile-time constant."""
    raise NotImplementedError("numba only")


def noise(tag, cf, z, buf):
    """The level's noise for one step (``kernels.noise`` of the stepper ``tag``)."""
    raise NotImplementedError("numba only")


def compose(tag, cf_a, cf_b, e1, e2, out):
    """The noise of one step from two in a row (``kernels.compose``)."""
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


@intrinsic
def step(typingctx, tag, x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen):
    """Advance one level over one step: a direct call of ``kernels.fast`` of the stepper ``tag``
    and, where it declines (or the stepper has none), of ``kernels.step``, each with the
    arguments (of :data:`STEP_ARGS`) that the kernel's parameters name.

    An intrinsic, not an inlined wrapper: inlined, the wrapper's parameters became copies of
    the loop's arrays, each reference-counted at every step, which cost 15-30 % of the loop at
    the solver's small chunks; a compiled wrapper cost as much in its call.
    """
    given = (x, v, V, xi, F, stuck, pvx, eps, cf, pp, kind, xm, fext, cs, rbm, rbx, w, counters, gen)
    ks = _kernels(tag)
    general = _call(typingctx, ks.step, given)
    fast = _call(typingctx, ks.fast, given) if ks.fast is not None else None

    def codegen(context, builder, sig, args):
        if fast is None:
            general(context, builder, args)
            return context.get_dummy_value()
        # the kinds the fast kernel never takes skip its call (a call that declines cost the
        # kink's unit 10-15 %)
        kind_arg = args[1 + STEP_ARGS.index("kind")]
        done = cgutils.alloca_once_value(builder, cgutils.false_bit)
        with builder.if_then(builder.icmp_signed("!=", kind_arg, ir.Constant(kind_arg.type, ks.slow_kind)),
                             likely=True):
            builder.store(fast(context, builder, args), done)
        with builder.if_then(builder.not_(builder.load(done)), likely=False):
            general(context, builder, args)
        return context.get_dummy_value()
    return types.none(tag, *given), codegen


def _call(typingctx, kernel, given):
    """Code generator of a direct call of ``kernel`` with the arguments of :data:`STEP_ARGS` that
    its parameters name; returns the kernel's value."""
    pick = [STEP_ARGS.index(name) for name in inspect.signature(kernel.py_func).parameters]
    fnty = types.Dispatcher(kernel)
    ksig = typingctx.resolve_function_type(fnty, tuple(given[i] for i in pick), {})

    def gen(context, builder, args):
        return context.get_function(fnty, ksig)(builder, [args[1 + i] for i in pick])
    return gen


@overload(advance, jit_options={"cache": True, "nogil": True}, inline="always")
def _advance(tag, xi, eps, cf):
    f = _kernels(tag).advance
    return lambda tag, xi, eps, cf: f(xi, eps, cf)


@overload(twin_xi, jit_options={"cache": True, "nogil": True}, inline="always")
def _twin_xi(tag, xi):
    f = _kernels(tag).twin_xi
    return lambda tag, xi: f(xi)
