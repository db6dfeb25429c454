"""Equilibria of the coupled potential by a deterministic search over sign patterns.

Every unit of an equilibrium is either displaced (sign +1 or -1) or at the origin (0). For
each pattern of signs :math:`s \\in \\{-1, 0, 1\\}^N` the displaced units solve
:math:`\\partial E/\\partial x_j = 0` with :math:`x_j = s_j e^{y_j}` (so they keep their sign
and never touch the nonsmooth point x = 0), by Powell's hybrid method from a fixed set of
seeds; the units at the origin must then be in equilibrium there: for n = 1 (a cusp, with
subgradient :math:`[-a, a]`) the coupling force on them must satisfy :math:`|f_j| \\le a`,
for n > 1 it must vanish.

Stability: for n = 1 a unit at the cusp with :math:`|f_j| < a` is held there to first order
(the energy rises linearly out of it), and for 1 < n < 2 the curvature at x = 0 is infinite,
so for n < 2 the Morse index is that of the Hessian restricted to the displaced units; for
n >= 2 the potential is smooth and the whole Hessian counts.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from .energy import RingEnergy

__all__ = ["Equilibrium", "find_equilibria", "MAX_SEARCH_N"]

#: Largest ring searched: the search tries the 3^N sign patterns up to symmetry (56 classes at N = 6).
MAX_SEARCH_N = 6

#: Seed amplitudes, relative to the landscape's length scale (:func:`_length_scale`).
_SEED_SCALES = np.geomspace(1e-2, 1e2, 9)

#: Relative residual of the force below which a root counts as an equilibrium.
_RESIDUAL_RTOL = 1e-10

#: Eigenvalues below this (relative to the Hessian's largest) count as zero: a degenerate point.
_ZERO_RTOL = 1e-9


@dataclass(frozen=True)
class Equilibrium:
    """One equilibrium of the ring's potential.

    Attributes
    ----------
    x : tuple of float
        Displacements of the N units.
    energy : float
        :math:`E(x)` (the origin has E = 0).
    index : int
        Morse index: the number of independent directions in which E decreases (0: a local
        minimum, 1: a saddle between two minima).
    eigenvalues : tuple of float
        Hessian eigenvalues in the smooth directions (ascending; see the module docstring).
    pinned : tuple of int
        Units held at the nonsmooth point x = 0 (n < 2).
    degenerate : bool
        A zero eigenvalue, or (n = 1) a unit at the cusp with :math:`|f_j| = a`: the index is
        then the count of strictly negative directions and says nothing about the flat ones.
    """

    x: tuple[float, ...]
    energy: float
    index: int
    eigenvalues: tuple[float, ...]
    pinned: tuple[int, ...]
    degenerate: bool

    @property
    def kind(self) -> str:
        """``"minimum"``, ``"saddle"`` (index 1) or ``"index-m saddle"``; ``"degenerate ..."`` if flat."""
        name = "minimum" if self.index == 0 else "saddle" if self.index == 1 else f"index-{self.index} saddle"
        return f"degenerate {name}" if self.degenerate else name

    def to_dict(self) -> dict[str, object]:
        return {"x": list(self.x), "energy": self.energy, "index": self.index, "kind": self.kind,
                "eigenvalues": list(self.eigenvalues), "pinned": list(self.pinned),
                "degenerate": self.degenerate}


def _length_scale(e: RingEnergy) -> float:
    """A typical displacement: where the on-site and the coupling energies compare (1 if none)."""
    scales = []
    if e.k3 > 0:
        scales.append((e.a / e.k3) ** (1.0 / (4.0 - e.n)) if e.n < 4 else math.sqrt(max(abs(e.k), 1e-300) / e.k3))
    stiff = abs(e.k) + abs(e.k4)
    if stiff > 0 and e.n != 2:
        scales.append((e.a / stiff) ** (1.0 / (2.0 - e.n)))
    return float(np.exp(np.mean(np.log(scales)))) if scales else 1.0


def _solve_pattern(e: RingEnergy, s: np.ndarray, scale: float) -> list[np.ndarray]:
    """Equilibria with the sign pattern ``s``, from every seed (duplicates not removed)."""
    import scipy.optimize

    free = np.flatnonzero(s)
    graded = 1.0 + 0.5 * np.cos(2.0 * np.pi * np.arange(free.size) / max(free.size, 1) + 0.3)
    weights = (np.ones(free.size), graded, graded[::-1])

    def embed(y: np.ndarray) -> np.ndarray:
        x = np.zeros(e.N)
        x[free] = s[free] * np.exp(y)
        return x

    def fun(y: np.ndarray) -> np.ndarray:
        return -e.force(embed(y))[free]

    def jac(y: np.ndarray) -> np.ndarray:
        x = embed(y)
        return e.hessian(x)[np.ix_(free, free)] * x[free][None, :]

    found = []
    for r, w in itertools.product(_SEED_SCALES * scale, weights):
        with np.errstate(all="ignore"):
            sol = scipy.optimize.root(fun, np.log(r * w), jac=jac, method="hybr")
        if np.all(np.isfinite(sol.x)) and np.all(np.abs(sol.x) < 700):
            found.append(embed(sol.x))
    return found


def _accept(e: RingEnergy, x: np.ndarray) -> Equilibrium | None:
    """``x`` as an :class:`Equilibrium`, or None if it is not one (residual, or a unit at 0
    the coupling pushes out)."""
    pinned = np.flatnonzero(x == 0.0)
    free = np.flatnonzero(x != 0.0)
    coupling = e.coupling_force(x)
    size = e.a * e.n * np.abs(x) ** (e.n - 1.0) + np.abs(coupling) + e.a * 1e-3
    if np.any(np.abs(e.force(x)[free]) > _RESIDUAL_RTOL * size[free]):
        return None
    hold = e.a if e.n == 1.0 else 0.0
    slack = np.abs(coupling[pinned]) - hold
    tol = 1e-9 * (e.a + np.abs(coupling[pinned]))
    if np.any(slack > tol):
        return None
    smooth = free if e.n < 2 else np.arange(e.N)
    with np.errstate(divide="ignore", invalid="ignore"):
        H = e.hessian(x)[np.ix_(smooth, smooth)]
    eig = np.linalg.eigvalsh(H) if smooth.size else np.zeros(0)
    zero = _ZERO_RTOL * max(float(np.abs(eig).max()) if eig.size else 0.0, e.a)
    degenerate = bool(np.any(np.abs(eig) <= zero) or (e.n == 1.0 and np.any(np.abs(slack) <= tol)))
    return Equilibrium(x=tuple(float(v) for v in x), energy=e.energy(x), index=int(np.sum(eig < -zero)),
                       eigenvalues=tuple(float(v) for v in eig), pinned=tuple(int(j) for j in pinned),
                       degenerate=degenerate)


def _images(x: tuple) -> list[tuple]:
    """``x`` under the ring's symmetries, which leave E unchanged: rotations, the reflection
    j -> -j, and x -> -x (U and every coupling term are even)."""
    out = []
    for y in (x, x[::-1]):
        for r in range(len(x)):
            rolled = y[r:] + y[:r]
            out.extend((rolled, tuple(0.0 - v for v in rolled)))
    return out


def find_equilibria(e: RingEnergy) -> tuple[Equilibrium, ...]:
    """The equilibria a multi-start search finds, by increasing energy (the origin is always one).

    A search, not a proof: a root no seed leads to is missed (at N = 3 with n = 1 it finds every
    state of the closed forms in :mod:`.reduction`; at N >= 4 runs with other seeds found the
    same lowest states but different numbers of high-index saddles).

    Deterministic: one sign pattern of each class under the ring's symmetries (:func:`_images`),
    27 seeds each (9 amplitudes over four decades around the landscape's length scale, uniform
    and graded both ways across the displaced units); each root found stands for all its images.

    Raises
    ------
    ParameterError
        ``N`` above :data:`MAX_SEARCH_N`.
    """
    if e.N > MAX_SEARCH_N:
        raise ParameterError(f"N must be in [1, {MAX_SEARCH_N}] for the equilibrium search (it tries the 3^N "
                             f"sign patterns up to symmetry), got N = {e.N}")
    scale = _length_scale(e)
    candidates = [np.zeros(e.N)]
    for s in itertools.product((-1, 0, 1), repeat=e.N):
        if any(s) and s == min(_images(s)):
            candidates.extend(_solve_pattern(e, np.array(s, dtype=float), scale))
    found: list[Equilibrium] = []

    def known(x: np.ndarray | tuple) -> bool:
        return any(np.allclose(x, other.x, rtol=1e-7, atol=1e-9 * scale) for other in found)

    for x in candidates:
        eq = None if known(x) else _accept(e, x)
        for image in [] if eq is None else sorted(set(_images(eq.x))):
            image_eq = None if known(image) else _accept(e, np.array(image))
            if image_eq is not None:
                found.append(image_eq)
    return tuple(sorted(found, key=lambda q: (q.energy, q.x)))
