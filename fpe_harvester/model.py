"""The harvester model: parameters, potential, and the (possibly coupled) problem.

For each unit :math:`j = 1..N` of a periodic ring (``N = 1``: a single, uncoupled
oscillator)

.. math::

    dx_j &= v_j\\,dt \\\\
    m\\,dv_j &= [-U'(x_j) - m\\gamma v_j - K_v V_j + \\sigma\\xi_j
               + F_j(x)]\\,dt \\\\
    dV_j &= (K_c v_j - V_j/\\tau_p)\\,dt \\\\
    \\tau\\,d\\xi_j &= -\\xi_j\\,dt + \\sqrt{2D}\\,dW_j

with :math:`U(x) = a|x|^n` and the coupling force, :math:`L` the ring Laplacian
:math:`(Lx)_j = x_{j+1} - 2x_j + x_{j-1}` and :math:`d_j = x_{j+1} - x_j` the bonds,

.. math::

    F_j = k(Lx)_j - k_4(L^2x)_j + k_3(d_j^3 - d_{j-1}^3) = -\\partial E_c/\\partial x_j,\\qquad
    E_c = \\frac k2\\sum_j d_j^2 + \\frac{k_4}2\\sum_j (Lx)_j^2 + \\frac{k_3}4\\sum_j d_j^4.

For ``N = 2`` the ring has two bonds, both between the two units, so the diffusive force
is :math:`2k(x_{other} - x_j)`. ``k > 0`` is in-phase (diffusive) coupling, ``k < 0``
counter-phase (anti-diffusive); ``k4`` (bi-Laplacian) and ``k3`` (cubic bonds) are the
next terms of the coupling (docs/model.md §6).

All quantities are dimensionless, in the paper's units.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .errors import ParameterError, check_int, check_real
from .wide import Wide

__all__ = ["Params", "Potential", "Harvester", "mode_sin2", "MAX_EXPONENT"]

#: Largest potential exponent n. Beyond it a|x|^n is a hard wall at |x| = a^(-1/n) (U rises a
#: hundredfold over a 7 % change of |x| at n = 64) that none of the solvers is built for, and
#: |x|^n would overflow double precision well inside the amplitudes the solvers visit
#: (|x| <= 100: 100^64 = 1e128, but 100^155 > 1.8e308). The paper uses 1 <= n <= 8.
MAX_EXPONENT = 64.0


def mode_sin2(N: int) -> np.ndarray:
    """:math:`\\sin^2(\\pi q/N)` for the ring modes q = 0..N-1.

    Mirror modes q and N - q are computed from the same folded index min(q, N - q), so they
    are bit-identical (degenerate stiffnesses stay degenerate near the threshold).
    """
    q = np.arange(N)
    return np.sin(math.pi * np.minimum(q, N - q) / N) ** 2


@dataclass(frozen=True)
class Params:
    """Physical parameters of one harvester unit (the paper's defaults).

    Parameters
    ----------
    m : float
        Mass :math:`m`, > 0. Default 1.
    gamma : float
        Mechanical damping rate :math:`\\gamma`, >= 0. Default 1.
    Kv : float
        Electromechanical coupling on the mechanical side :math:`K_v`, >= 0. Default 1.
        ``Kv = 0``: the circuit does not act back on the mechanics (then ``gamma`` must be > 0,
        or nothing damps the oscillator).
    Kc : float
        Electromechanical coupling on the circuit side :math:`K_c`, > 0. Default 1.
    sigma : float
        Noise amplitude :math:`\\sigma`, > 0. Default 1.
    tau : float
        Correlation time of the Ornstein--Uhlenbeck noise :math:`\\tau`, > 0. Default 1.
    D : float
        Noise intensity :math:`D`, > 0; :math:`\\langle\\xi(t)\\xi(t')\\rangle
        = (D/\\tau) e^{-|t-t'|/\\tau}`. Default 1.
    tau_p : float
        Circuit time constant :math:`\\tau_p = RC`, > 0. Default 2.
    R : float
        Load resistance :math:`R`, > 0; enters only :math:`\\eta = V^2/(R P_{in})`. Default 1.

    Examples
    --------
    >>> Params().tau_p
    2.0
    >>> Params(tau_p=5).tau_p
    5.0
    """

    m: float = 1.0
    gamma: float = 1.0
    Kv: float = 1.0
    Kc: float = 1.0
    sigma: float = 1.0
    tau: float = 1.0
    D: float = 1.0
    tau_p: float = 2.0
    R: float = 1.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in ("gamma", "Kv"):
                checked = check_real(f.name, value, low=0.0)
            else:
                checked = check_real(f.name, value, low=0.0, low_open=True)
            object.__setattr__(self, f.name, checked)
        if self.gamma == 0.0 and self.Kv == 0.0:
            raise ParameterError("gamma = 0 and Kv = 0 leave the oscillator undamped (no stationary state): "
                                 "gamma must be > 0 when Kv = 0, or Kv > 0 when gamma = 0")

    def replace(self, **changes: float) -> Params:
        """Return a copy with some fields changed (validated again)."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            valid = ", ".join(f.name for f in dataclasses.fields(self))
            raise ParameterError(f"unknown parameter(s) {sorted(unknown)}; valid names: {valid}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float]:
        """The parameters as a plain dict (for JSON)."""
        return dataclasses.asdict(self)

    @property
    def noise_variance(self) -> float:
        """Stationary variance of the noise, :math:`\\langle\\xi^2\\rangle = D/\\tau`."""
        return self.D / self.tau


@dataclass(frozen=True)
class Potential:
    """Monostable potential :math:`U(x) = a|x|^n`.

    Parameters
    ----------
    a : float
        Strength :math:`a`, > 0.
    n : float
        Exponent :math:`n`, real, in [1, :data:`MAX_EXPONENT`] = [1, 64]. ``n = 1`` is the
        piecewise-linear potential with a kink at 0 (force :math:`-a\\,\\mathrm{sign}(x)`);
        ``n = 2`` is harmonic with stiffness :math:`U'' = 2a`.

    Examples
    --------
    >>> float(Potential(0.5, 2).force(1.0))
    -1.0
    >>> Potential.from_U0_x0(U0=2.0, x0=2.0, n=2).a
    0.5
    """

    a: float = 0.5
    n: float = 2.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "a", check_real("a", self.a, low=0.0, low_open=True))
        object.__setattr__(self, "n", check_real("n", self.n, low=1.0, high=MAX_EXPONENT))

    @classmethod
    def from_U0_x0(cls, U0: float, x0: float, n: float) -> Potential:
        """Build from the paper's form :math:`U(x) = U_0 |x/x_0|^n`, i.e. :math:`a = U_0/|x_0|^n`.

        Parameters
        ----------
        U0 : float
            Energy scale, > 0.
        x0 : float
            Length scale, nonzero.
        n : float
            Exponent, in [1, :data:`MAX_EXPONENT`].

        Raises
        ------
        ParameterError
            A value out of range, or :math:`U_0/|x_0|^n` beyond double precision.
        """
        U0 = check_real("U0", U0, low=0.0, low_open=True)
        x0 = check_real("x0", x0)
        if x0 == 0.0:
            raise ParameterError("x0 must be a nonzero finite real number, got 0.0")
        n = check_real("n", n, low=1.0, high=MAX_EXPONENT)
        try:
            a = U0 / abs(x0) ** n
        except (OverflowError, ZeroDivisionError):
            a = 0.0
        if not (0.0 < a < math.inf):
            raise ParameterError(f"a = U0/|x0|^n = {U0:g}/|{x0:g}|^{n:g} is beyond double precision; "
                                 "choose U0 and x0 closer to 1")
        return cls(a=a, n=n)

    @property
    def is_harmonic(self) -> bool:
        """True for ``n == 2`` (linear force, exact solver applies)."""
        return self.n == 2.0

    def U(self, x: np.ndarray | float) -> np.ndarray | float:
        """Potential energy :math:`a|x|^n`."""
        return self.a * np.abs(x) ** self.n

    def dU(self, x: np.ndarray | float) -> np.ndarray | float:
        """Derivative :math:`U'(x) = a n |x|^{n-1}\\mathrm{sign}(x)` (0 at x = 0)."""
        return self.a * self.n * np.abs(x) ** (self.n - 1.0) * np.sign(x)

    def force(self, x: np.ndarray | float) -> np.ndarray | float:
        """Restoring force :math:`-U'(x)`."""
        return -self.dU(x)

    def U0_x0(self, x0: float = 1.0) -> tuple[float, float]:
        """The paper's :math:`(U_0, x_0)` for a chosen length scale ``x0``."""
        x0 = check_real("x0", x0)
        if x0 == 0.0:
            raise ParameterError("x0 must be a nonzero finite real number, got 0.0")
        try:
            U0 = self.a * abs(x0) ** self.n
        except OverflowError:
            U0 = math.inf
        if not math.isfinite(U0) or U0 == 0.0:
            raise ParameterError(f"x0 = {x0:g}: U0 = a|x0|^n is beyond double precision; choose |x0| closer to 1")
        return U0, x0


@dataclass(frozen=True)
class Harvester:
    """A harvester of ``N`` identical units in a periodic ring with couplings ``k``, ``k4``, ``k3``.

    The coupling force on unit j is :math:`k(Lx)_j - k_4(L^2x)_j + k_3(d_j^3 - d_{j-1}^3)`
    (see the module docstring). A single unit (``N = 1``) has no neighbours: the three
    couplings have no effect there and must be 0 (their defaults).

    Parameters
    ----------
    potential : Potential
        The on-site potential :math:`U(x) = a|x|^n`. Default ``Potential(a=0.5, n=2)``.
    N : int
        Number of units, >= 1. ``N = 1`` is a single oscillator.
    k : float
        Diffusive nearest-neighbour coupling :math:`k`, any finite real; > 0 in-phase,
        < 0 counter-phase. Default 0.
    params : Params
        Physical parameters shared by all units.
    k4 : float
        Bi-Laplacian coupling :math:`k_4`, any finite real; it adds :math:`k_4\\mu_q^2` to the
        stiffness of ring mode q (:math:`\\mu_q = 4\\sin^2(\\pi q/N)`): > 0 stiffens short
        wavelengths, < 0 softens them. Linear (the exact solver handles it). Default 0.
    k3 : float
        Cubic bond coupling :math:`k_3`, >= 0 (a negative one would make every ring with
        n < 4 unbounded below); energy :math:`(k_3/4)\\sum_j d_j^4`. Nonlinear: a harmonic
        ring with ``k3 > 0`` is solved by Monte Carlo, not exactly. Default 0.

    Examples
    --------
    >>> h = Harvester(Potential(0.5, 2), N=3, k=-0.33)
    >>> h.mode_stiffness().round(4).tolist()
    [1.0, 0.01, 0.01]
    """

    potential: Potential = field(default_factory=Potential)
    N: int = 1
    k: float = 0.0
    params: Params = field(default_factory=Params)
    k4: float = 0.0
    k3: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.potential, Potential):
            raise ParameterError(
                f"potential must be a Potential, got {self.potential!r} "
                f"(type {type(self.potential).__name__})"
            )
        if not isinstance(self.params, Params):
            raise ParameterError(
                f"params must be a Params, got {self.params!r} (type {type(self.params).__name__})"
            )
        object.__setattr__(self, "N", check_int("N", self.N, low=1))
        couplings = {"k": check_real("k", self.k), "k4": check_real("k4", self.k4),
                     "k3": check_real("k3", self.k3, low=0.0)}
        for name, value in couplings.items():
            if self.N == 1 and value != 0.0:
                raise ParameterError(f"{name} must be 0 for a single unit (N = 1: no neighbours, the "
                                     f"coupling has no effect), got {value!r}")
            object.__setattr__(self, name, value)

    @classmethod
    def build(
        cls, a: float = 0.5, n: float = 2.0, N: int = 1, k: float = 0.0, k4: float = 0.0,
        k3: float = 0.0, **params: float
    ) -> Harvester:
        """Shortcut: ``Harvester.build(a=0.5, n=1, N=3, k=-0.01, k3=0.1, tau_p=2)``."""
        return cls(Potential(a, n), N, k, Params().replace(**params), k4=k4, k3=k3)

    def replace(self, **changes: object) -> Harvester:
        """Copy with fields changed; ``a``, ``n`` and any :class:`Params` name are accepted too."""
        pot = {key: changes.pop(key) for key in ("a", "n") if key in changes}
        own = {key: changes.pop(key) for key in ("potential", "N", "k", "params", "k4", "k3") if key in changes}
        new = dataclasses.replace(self, **own)
        if pot:
            new = dataclasses.replace(new, potential=dataclasses.replace(new.potential, **pot))
        if changes:
            new = dataclasses.replace(new, params=new.params.replace(**changes))
        return new

    @property
    def a(self) -> float:
        return self.potential.a

    @property
    def n(self) -> float:
        return self.potential.n

    @property
    def is_linear(self) -> bool:
        """True when every force is linear (harmonic potential and no cubic coupling)."""
        return self.potential.is_harmonic and self.k3 == 0.0

    @property
    def confinement(self) -> str:
        """``"confined"``, ``"metastable"`` or ``"linear"`` (see docs/model.md §3).

        For ``n < 2`` without cubic coupling (``k3 = 0``), a ring whose linear coupling softens
        some mode (:math:`k\\mu_q + k_4\\mu_q^2 < 0` for a q >= 1; for ``k4 = 0``: any ``k < 0``)
        is unbounded below at large amplitude (only metastable); ``k3 > 0`` confines every
        ring (each bond's energy is at least :math:`-k^2/(4k_3)` for ``k4 = 0``, and the quartic
        bonds outgrow any quadratic term); for ``n > 2`` it is always confined. The linear case
        is decided by the mode stiffnesses (:mod:`.exact.stability`).
        """
        if self.is_linear:
            return "linear"
        if self.N > 1 and self.n < 2 and self.k3 == 0.0 and np.any(self.coupling_stiffness()[1:] < 0.0):
            return "metastable"
        return "confined"

    def coupling_stiffness(self) -> np.ndarray:
        """Stiffness the linear coupling adds to ring mode q, :math:`k\\mu_q + k_4\\mu_q^2`,
        :math:`\\mu_q = 4\\sin^2(\\pi q/N)`, q = 0..N-1 (0 for q = 0)."""
        mu = 4.0 * mode_sin2(self.N)
        return self.k * mu + self.k4 * mu**2

    def mode_stiffness(self) -> np.ndarray:
        """Harmonic mode stiffnesses :math:`\\kappa_q = 2a + k\\mu_q + k_4\\mu_q^2`, q = 0..N-1,
        :math:`\\mu_q = 4\\sin^2(\\pi q/N)`.

        Meaningful for ``n = 2`` only (for other n, it is the stiffness the coupling adds
        to a unit stiffness ``2a``). Values beyond the double range are ``inf`` or ``-inf``
        (:func:`fpe_harvester.exact.wide_mode_stiffness` keeps them exactly).
        """
        s2 = Wide.of(mode_sin2(self.N))
        kappa = 2.0 * Wide.of(self.a) + 4.0 * Wide.of(self.k) * s2
        if self.k4 != 0.0:
            kappa = kappa + 16.0 * Wide.of(self.k4) * s2 * s2
        return kappa.to_float()

    def to_dict(self) -> dict[str, object]:
        """Plain-dict description (for JSON).

        ``k4`` and ``k3`` appear only when nonzero, so that a ring without them has the same
        description as before they existed (scene caches and seeds are derived from it).
        """
        out: dict[str, object] = {"a": self.a, "n": self.n, "N": self.N, "k": self.k}
        out.update({name: value for name, value in (("k4", self.k4), ("k3", self.k3)) if value != 0.0})
        out["params"] = self.params.to_dict()
        return out
