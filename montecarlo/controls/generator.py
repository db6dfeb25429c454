"""The generator controls: the martingale form of :math:`\\int L f\\,dt` for f up to degree 4.

For a function f of one unit's state :math:`Y = (x, v, V, \\xi)`, the generator of the model,

.. math::

    L f = v f_x + \\frac{1}{m}\\big(-U'(x) - m\\gamma v - K_v V + \\sigma\\xi + F_c\\big) f_v
    + (K_c v - V/\\tau_p) f_V - \\frac{\\xi}{\\tau} f_\\xi + \\frac{D}{\\tau^2} f_{\\xi\\xi}

(:math:`F_c` the coupling force of the ring, k, k4 and k3 included), gives Ito's formula
:math:`f(Y_T) - f(Y_0) = \\int_0^T Lf\\,dt + \\int_0^T f_\\xi \\frac{\\sqrt{2D}}{\\tau} dW`. Its
martingale part, sampled at points :math:`t_m`, is

.. math::

    M_\\phi = \\sum_m \\phi(Y_{t_m})\\,\\eta_m,\\qquad \\eta_m = \\xi(t_{m+1}) - e^{-(t_{m+1} - t_m)/\\tau}
    \\xi(t_m),\\qquad E[M_\\phi] = 0

for *any* function :math:`\\phi` (here :math:`\\phi = f_\\xi`), because the innovation
:math:`\\eta_m` of the exact Ornstein--Uhlenbeck update is independent of everything before
:math:`t_m`, whatever the step, the potential or the coupling: the force terms of
:math:`L f` never have to be evaluated, and the control has mean exactly 0 for any ``dt``, start
and potential (the time average of :math:`L f` itself would need the stationary law of the
continuous model, and carry the scheme's time-step bias). The sampled form loses the variation of
:math:`\\phi` inside an interval; the second-order Hermite terms
:math:`\\psi(Y_{t_m})(\\eta_m^2 - \\mathrm{var})` (var the conditional variance of
:math:`\\eta_m`, also mean 0) carry :math:`f_{\\xi\\xi}`'s share of it.

Basis, per unit (sums over the units of a ring and its paths), :data:`BASIS`:

``poly``  :math:`\\phi` the monomials of degree <= 3 in (x, v, V, xi) (35: :math:`f_\\xi` for f of
          degree <= 4);
``he2``   :math:`\\psi(\\eta^2 - \\mathrm{var})` for :math:`\\psi` the monomials of degree <= 2 (15);
``abs``   Lipschitz terms :math:`\\phi` = :math:`|x|\\xi^j`, :math:`\\mathrm{sgn}(x)\\xi^j` (j = 1, 2),
          :math:`\\mathrm{sgn}(x)\\,v\\,\\xi^j`, :math:`\\mathrm{sgn}(x)\\,V\\,\\xi^j` (j = 0, 1, 2),
          :math:`|x|`, :math:`|x|v`, :math:`|x|v\\xi`, :math:`|x|V`, :math:`|x|V\\xi` (15): the
          kink's and the unit's own nonsmooth parts;
``hinge`` the kink only (:data:`montecarlo.layout.KIND_KINK`): :math:`\\max(F - c\\,a, 0)` times
          (1, x, v, V, xi), :math:`F = \\sigma\\xi - K_v V` the net drive and c = -2, -1.5, ..., 2
          (45): whether and how far the drive holds the unit in the trap :math:`|F| < a` or pushes
          it out.

The points :math:`t_m` are every ``gen_every``-th step of the fine level in the measured window
(:func:`montecarlo.simulate`'s ``generator_every``), independently of the moments' samples.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from fpe_harvester.model import Harvester

from ..coefficients import onsite_kind
from ..layout import KIND_KINK
from .base import Columns, Control

if TYPE_CHECKING:
    from ..ensemble import Ensemble

__all__ = ["GENERATOR", "GeneratorControl", "BASIS", "HINGE_KNOTS", "basis_names", "gen_measure", "gen_close"]

_VARS = ("x", "v", "V", "xi")


def _monomials(degree: int) -> tuple[str, ...]:
    """Names of the monomials of (x, v, V, xi) of degree <= ``degree`` in the kernel's order."""
    out = ["1"]
    idx: list[tuple[int, ...]] = [()]
    for _ in range(degree):
        idx = [t + (i,) for t in idx for i in range(t[-1] if t else 0, 4)]
        out += ["*".join(_VARS[i] for i in t) for t in idx]
    return tuple(out)


#: Knots of the hinge terms, in units of a: every a/2 from -2a to 2a. Measured at n = 1, a = 2 on
#: 3000 one-path replicas (fine dt 0.005, three seeds): variance reduction of eta 42.4 on average
#: against 38.8 with the knots -a, 0, a and 43.4 with every a/4 (docs/methods.md, "Generator
#: controls"); knots at +-3a add nothing there (the drive seldom reaches them).
HINGE_KNOTS = (-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)
_ABS = ("ax*xi", "ax*xi^2", "sx*xi", "sx*xi^2", "sx*v", "sx*v*xi", "sx*v*xi^2", "sx*V", "sx*V*xi", "sx*V*xi^2",
        "ax", "ax*v", "ax*v*xi", "ax*V", "ax*V*xi")
_HINGE = tuple(f"F{c:+g}a*{m}" for c in HINGE_KNOTS for m in ("1",) + _VARS)

#: The basis by part, the names of its functions in the kernel's order.
BASIS: dict[str, tuple[str, ...]] = {
    "poly": _monomials(3),
    "he2": tuple("he2*" + m for m in _monomials(2)),
    "abs": _ABS,
    "hinge": _HINGE,
}
_N_POLY, _N_HE2, _N_ABS, _N_HINGE = (len(BASIS[k]) for k in ("poly", "he2", "abs", "hinge"))


def basis_names(kink: bool) -> tuple[str, ...]:
    """Names of the accumulated sums (``gen_<function>``), the hinge terms only for the kink."""
    parts = ("poly", "he2", "abs") + (("hinge",) if kink else ())
    return tuple("gen_" + name for part in parts for name in BASIS[part])


@njit(cache=True, nogil=True, inline="always")
def _add(acc, rep: int, row: int, k: int, value: float) -> int:
    acc[rep, row, k] += value
    return k + 1


@njit(cache=True, nogil=True)
def _unit(acc, rep: int, row: int, x: float, v: float, V: float, s: float, eta: float, e2: float, kink: bool,
          a: float, sig: float, kv: float) -> None:
    """Add one unit's basis functions at its state (x, v, V, s = xi) at the interval's start, times
    its innovation ``eta`` (and ``e2`` = eta^2 - var for ``he2``), to ``acc[rep, row]``."""
    z = (x, v, V, s)
    k = _add(acc, rep, row, 0, eta)
    for i in range(4):
        k = _add(acc, rep, row, k, z[i] * eta)
    for i in range(4):
        for j in range(i, 4):
            k = _add(acc, rep, row, k, z[i] * z[j] * eta)
    for i in range(4):
        for j in range(i, 4):
            zij = z[i] * z[j] * eta
            for l in range(j, 4):
                k = _add(acc, rep, row, k, zij * z[l])
    k = _add(acc, rep, row, k, e2)
    for i in range(4):
        k = _add(acc, rep, row, k, z[i] * e2)
    for i in range(4):
        for j in range(i, 4):
            k = _add(acc, rep, row, k, z[i] * z[j] * e2)
    ax = abs(x) * eta
    sx = (1.0 if x > 0.0 else -1.0 if x < 0.0 else 0.0) * eta
    k = _add(acc, rep, row, k, ax * s)
    k = _add(acc, rep, row, k, ax * s * s)
    k = _add(acc, rep, row, k, sx * s)
    k = _add(acc, rep, row, k, sx * s * s)
    for u in (v, V):
        k = _add(acc, rep, row, k, sx * u)
        k = _add(acc, rep, row, k, sx * u * s)
        k = _add(acc, rep, row, k, sx * u * s * s)
    k = _add(acc, rep, row, k, ax)
    for u in (v, V):
        k = _add(acc, rep, row, k, ax * u)
        k = _add(acc, rep, row, k, ax * u * s)
    if kink:
        F = sig * s - kv * V
        for c in HINGE_KNOTS:
            r = max(F - c * a, 0.0) * eta
            k = _add(acc, rep, row, k, r)
            for i in range(4):
                k = _add(acc, rep, row, k, r * z[i])


@njit(cache=True, nogil=True)
def gen_measure(x, v, V, xi, w, st, acc, first: bool, started: bool, decay: float, var: float, kink: bool,
                a: float, sig: float, kv: float) -> None:
    """At a generator point: close the interval since the previous point (unless this is the
    first) and start the next.

    Unit j's innovation is :math:`\\eta_j = \\xi_j - e^{-\\Delta/\\tau}\\xi_j^{(0)}` (``decay``;
    ``st`` (4, N, P) holds (x, v, V, xi) at the previous point), with conditional mean 0 and
    variance ``var``; the basis at the previous point times it goes to ``acc[r, 1]`` while in the
    first half of the window (``first``), else to ``acc[r, 0]`` (:func:`gen_close` adds the first
    half into the whole), r the replica of the path (``acc`` (G, 2, columns): G replicas of P / G
    consecutive paths). Then the state is kept in ``st``. Live paths only (``w``).
    """
    N, P = x.shape
    per = P // acc.shape[0]
    row = 1 if first else 0
    if started:
        for p in range(P):
            if w[p] == 0.0:
                continue
            rep = p // per
            for j in range(N):
                eta = xi[j, p] - decay * st[3, j, p]
                _unit(acc, rep, row, st[0, j, p], st[1, j, p], st[2, j, p], st[3, j, p], eta, eta * eta - var,
                      kink, a, sig, kv)
    # element loops, not slice copies (numba's shape-checked copy per dimension)
    for j in range(N):
        for p in range(P):
            st[0, j, p], st[1, j, p], st[2, j, p], st[3, j, p] = x[j, p], v[j, p], V[j, p], xi[j, p]


@njit(cache=True, nogil=True)
def gen_close(acc) -> None:
    """After the loop: the whole window's sums are the second half's plus the first half's, per
    replica (``acc`` (G, 2, columns))."""
    for r in range(acc.shape[0]):
        for k in range(acc.shape[2]):
            acc[r, 0, k] += acc[r, 1, k]


class GeneratorControl(Control):
    """The generator basis :data:`BASIS` in martingale form: mean 0 exactly for any start, step,
    potential and ring, accumulated by the path loop (:func:`gen_measure`) every
    ``generator_every`` of :func:`montecarlo.simulate`. Its many columns are fitted by
    cross-fitting (:attr:`crossfit`)."""

    name = "generator"
    accumulated = True
    crossfit = True

    def sums(self, h: Harvester) -> tuple[str, ...]:
        return basis_names(onsite_kind(h) == KIND_KINK)

    def loop_fields(self, h: Harvester, offset: int) -> dict[str, int]:
        return {"gen_at": offset, "n_gen": len(self.sums(h)), "gen_kink": onsite_kind(h) == KIND_KINK}

    def columns(self, e: Ensemble, valid: np.ndarray) -> Columns | None:
        if self.name not in e.ctl_names:
            return None
        whole, first = e.control_sums(self.name), e.control_sums(self.name, first_half=True)
        names = e.ctl_names[self.name]
        return [whole[n][valid] for n in names], [first[n][valid] for n in names], [0.0] * len(names)


#: The generator control.
GENERATOR = GeneratorControl()
