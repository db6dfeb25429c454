"""The harvester model: parameters, potential, and the (possibly coupled) problem.

For each unit :math:`j = 1..N` of a periodic ring (``N = 1``: a single, uncoupled
oscillator)

.. math::

    dx_j &= v_j\\,dt \\\\
    m\\,dv_j &= [-U'(x_j) - m\\gamma v_j - K_v V_j + \\sigma\\xi_j
               + k(x_{j+1} - 2x_j + x_{j-1})]\\,dt \\\\
    dV_j &= (K_c v_j - V_j/\\tau_p)\\,dt \\\\
    \\tau\\,d\\xi_j &= -\\xi_j\\,dt + \\sqrt{2D}\\,dW_j

with :math:`U(x) = a|x|^n`. For ``N = 2`` both neighbours are the same unit, so the
coupling force is :math:`2k(x_{other} - x_j)`. ``k > 0`` is in-phase (diffusive)
coupling, ``k < 0`` counter-phase (anti-diffusive).

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
        Electromechanical coupling on the mechanical side :math:`K_v`, > 0. Default 1.
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
            if f.name == "gamma":
                checked = check_real("gamma", value, low=0.0)
            else:
                checked = check_real(f.name, value, low=0.0, low_open=True)
            object.__setattr__(self, f.name, checked)

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
    """A harvester of ``N`` identical units in a periodic ring with coupling ``k``.

    Parameters
    ----------
    potential : Potential
        The on-site potential :math:`U(x) = a|x|^n`. Default ``Potential(a=0.5, n=2)``.
    N : int
        Number of units, >= 1. ``N = 1`` is a single oscillator (``k`` is ignored and
        must be 0 or left at its default).
    k : float
        Nearest-neighbour coupling, any finite real; > 0 in-phase, < 0 counter-phase.
    params : Params
        Physical parameters shared by all units.

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
        k = check_real("k", self.k)
        if self.N == 1 and k != 0.0:
            raise ParameterError(f"k must be 0 for a single unit (N = 1), got {k!r}")
        object.__setattr__(self, "k", k)

    @classmethod
    def build(
        cls, a: float = 0.5, n: float = 2.0, N: int = 1, k: float = 0.0, **params: float
    ) -> Harvester:
        """Shortcut: ``Harvester.build(a=0.5, n=1, N=3, k=-0.01, tau_p=2)``."""
        return cls(Potential(a, n), N, k, Params().replace(**params))

    def replace(self, **changes: object) -> Harvester:
        """Copy with fields changed; ``a``, ``n`` and any :class:`Params` name are accepted too."""
        pot = {key: changes.pop(key) for key in ("a", "n") if key in changes}
        own = {key: changes.pop(key) for key in ("potential", "N", "k", "params") if key in changes}
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
        """True when every force is linear (harmonic potential)."""
        return self.potential.is_harmonic

    @property
    def confinement(self) -> str:
        """``"confined"``, ``"metastable"`` or ``"linear"`` (see docs/model.md §3).

        For ``n < 2`` any ``k < 0`` makes the coupled potential unbounded below at large
        amplitude (the ring is only metastable); for ``n > 2`` it is always confined.
        The harmonic case is decided by the mode stiffnesses (:mod:`.exact.stability`).
        """
        if self.is_linear:
            return "linear"
        if self.N > 1 and self.k < 0 and self.n < 2:
            return "metastable"
        return "confined"

    def mode_stiffness(self) -> np.ndarray:
        """Harmonic mode stiffnesses :math:`\\kappa_q = 2a + 4k\\sin^2(\\pi q/N)`, q = 0..N-1.

        Meaningful for ``n = 2`` only (for other n, it is the stiffness the coupling adds
        to a unit stiffness ``2a``). Values beyond the double range are ``inf`` or ``-inf``
        (:func:`fpe_harvester.exact.wide_mode_stiffness` keeps them exactly).
        """
        return (2.0 * Wide.of(self.a) + 4.0 * Wide.of(self.k) * Wide.of(mode_sin2(self.N))).to_float()

    def to_dict(self) -> dict[str, object]:
        """Plain-dict description (for JSON)."""
        return {"a": self.a, "n": self.n, "N": self.N, "k": self.k, "params": self.params.to_dict()}
