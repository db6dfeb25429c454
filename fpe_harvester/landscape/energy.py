"""The coupled potential energy of a ring, its force and its Hessian.

.. math::

    E(x) = \\sum_j a|x_j|^n + \\frac k2\\sum_j d_j^2 + \\frac{k_4}2\\sum_j (Lx)_j^2
           + \\frac{k_3}4\\sum_j d_j^4,\\qquad d_j = x_{j+1} - x_j,\\quad (Lx)_j = d_j - d_{j-1}

on a periodic ring of N units (N = 2: two bonds, both between the two units). Its force
:math:`-\\nabla E` is the model's: :math:`-U'(x_j) + k(Lx)_j - k_4(L^2x)_j + k_3(d_j^3 - d_{j-1}^3)`
(:math:`\\sum_j d_j^2 = -x^TLx` and L is symmetric, so :math:`\\nabla\\frac{k_4}2|Lx|^2 = k_4L^2x`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import check_int, check_real
from ..model import MAX_EXPONENT, Harvester

__all__ = ["RingEnergy"]


def _laplacian(N: int) -> np.ndarray:
    """The ring Laplacian as a dense matrix (0 for N = 1: a unit is its own neighbour)."""
    eye = np.eye(N)
    return np.roll(eye, 1, axis=1) + np.roll(eye, -1, axis=1) - 2.0 * eye


@dataclass(frozen=True)
class RingEnergy:
    """Energy :math:`E(x)` of a ring of ``N`` units :math:`U = a|x|^n` with couplings k, k4, k3.

    Parameters
    ----------
    n : float
        Exponent, in [1, 64].
    a : float
        Strength, > 0.
    N : int
        Number of units, >= 1.
    k, k4 : float
        Diffusive and bi-Laplacian couplings, any finite real.
    k3 : float
        Cubic bond coupling, >= 0.

    Examples
    --------
    >>> e = RingEnergy(n=1, a=1.0, N=3, k=-2.0, k3=1.0)
    >>> float(e.energy(np.array([1.0, 0.0, 0.0])))  # a u + k u^2 + (k3/2) u^4 at u = 1
    -0.5
    """

    n: float
    a: float
    N: int
    k: float = 0.0
    k4: float = 0.0
    k3: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "n", check_real("n", self.n, low=1.0, high=MAX_EXPONENT))
        object.__setattr__(self, "a", check_real("a", self.a, low=0.0, low_open=True))
        object.__setattr__(self, "N", check_int("N", self.N, low=1))
        for name in ("k", "k4"):
            object.__setattr__(self, name, check_real(name, getattr(self, name)))
        object.__setattr__(self, "k3", check_real("k3", self.k3, low=0.0))

    @classmethod
    def of(cls, h: Harvester) -> RingEnergy:
        """The energy of a harvester's ring (its physical parameters do not enter)."""
        return cls(h.n, h.a, h.N, h.k, h.k4, h.k3)

    def bonds(self, x: np.ndarray) -> np.ndarray:
        """:math:`d_j = x_{j+1} - x_j` (zero for N = 1)."""
        return np.roll(x, -1) - x

    def energy(self, x: np.ndarray) -> float:
        """:math:`E(x)`."""
        x = np.asarray(x, dtype=float)
        d = self.bonds(x)
        lx = d - np.roll(d, 1)
        return float(np.sum(self.a * np.abs(x) ** self.n) + 0.5 * self.k * np.sum(d**2)
                     + 0.5 * self.k4 * np.sum(lx**2) + 0.25 * self.k3 * np.sum(d**4))

    def coupling_force(self, x: np.ndarray) -> np.ndarray:
        """:math:`k(Lx)_j - k_4(L^2x)_j + k_3(d_j^3 - d_{j-1}^3)`, the force of the coupling alone."""
        x = np.asarray(x, dtype=float)
        d = self.bonds(x)
        lx = d - np.roll(d, 1)
        llx = np.roll(lx, -1) - 2.0 * lx + np.roll(lx, 1)
        return self.k * lx - self.k4 * llx + self.k3 * (d**3 - np.roll(d, 1) ** 3)

    def force(self, x: np.ndarray) -> np.ndarray:
        """:math:`-\\nabla E(x)`, with :math:`U'(0) = 0` (for n = 1 see :meth:`coupling_force`)."""
        x = np.asarray(x, dtype=float)
        return -self.a * self.n * np.abs(x) ** (self.n - 1.0) * np.sign(x) + self.coupling_force(x)

    def hessian(self, x: np.ndarray) -> np.ndarray:
        """:math:`\\nabla^2 E(x)`; the on-site curvature :math:`an(n-1)|x|^{n-2}` is ``inf`` at
        x = 0 for n < 2 (``0`` for n = 1 away from 0, where the potential is linear)."""
        x = np.asarray(x, dtype=float)
        L = _laplacian(self.N)
        Dm = np.roll(np.eye(self.N), -1, axis=0) - np.eye(self.N)  # d = Dm x
        d = Dm @ x
        with np.errstate(divide="ignore"):
            onsite = (self.a * self.n * (self.n - 1.0) * np.abs(x) ** (self.n - 2.0) if self.n != 1.0
                      else np.zeros_like(x))
        return (np.diag(onsite) - self.k * L + self.k4 * (L @ L)
                + 3.0 * self.k3 * Dm.T @ (d[:, None] ** 2 * Dm))
