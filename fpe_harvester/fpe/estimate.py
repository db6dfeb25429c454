"""Error estimates of the Fokker--Planck discretization from sequences of levels.

The discretization has two knobs: the Hermite degree M (steps of 2) and the number of
elements per half-domain :math:`N_h`. Each estimate looks at one observable on a sequence
of levels along one knob, the other fixed.

*Hermite degree, geometric* (:func:`tail_error`, smooth potentials :math:`n \\ge 2`). For
:math:`f_0, f_1, f_2` at :math:`M - 4, M - 2, M` with steps :math:`e_1, e_2` and ratio
:math:`r = |e_2/e_1|`, the error of :math:`f_2` is the tail of a geometric series

.. math::

    \\varepsilon = |e_2|\\,\\max\\Big(1, \\frac{r}{1 - r}\\Big),

never less than the last step (conservative when convergence is fast), never less than
:math:`\\sqrt{|e_1 e_2|}` when the two steps have opposite signs (steep potentials converge
irregularly in M), and :math:`10|e_2|` when the sequence is not contracting
(:math:`r \\ge 0.9`).

*Hermite degree, potentials with n < 2.* The force is not smooth at x = 0 and the density
concentrates there (for n = 1 with a power law in the amplitude of the oscillation: with
viscous damping the oscillations toward rest at the kink decay only exponentially in time),
so the Hermite coefficients decay algebraically. The algebraic tail above then applies to
every moment, and the error of eta is at least the larger relative tail of V2 and Pin: eta
mixes a fast moment (V2 ~ <vV>) with a slow one (Pin ~ <v^2>), and its own sequence shows a
pre-asymptotic exponent. No extrapolation in M is made: one whose error cannot be bounded is
not shipped (the measurements behind it: docs/methods.md, Fokker-Planck design notes). At n = 1 the
default is the kink scheme (:mod:`.schemes.xv.kink`), whose Hermite series runs only in (V, xi).

*Mesh* (:func:`mesh_error`): Richardson from three meshes of sizes :math:`s_0 < s_1 < s_2`
(any ratios) with the observed order capped at the DG order p + 1.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

__all__ = ["tail_error", "mesh_error", "mesh_order", "reported_eta_error"]


def tail_error(values: Sequence[float], degrees: Sequence[int] | None = None) -> tuple[float, bool]:
    """Error estimate of the last of up to three successive refinements.

    Parameters
    ----------
    values : sequence of float
        The observable on successive levels (coarse to fine).
    degrees : sequence of int, optional
        The Hermite degrees of the levels (steps of 2); enables the algebraic tail
        :math:`|e_2| M/(2q)` with q from :math:`r = ((M-2)/M)^{q+1}`.

    Returns
    -------
    (error, asymptotic)
        With two values the last difference and ``False``; with one value ``inf``.

    Examples
    --------
    >>> err, ok = tail_error([1.1, 1.01, 1.001])
    >>> round(err, 6), ok
    (0.009, True)
    """
    if len(values) < 2:
        return math.inf, False
    e2 = abs(values[-1] - values[-2])
    if len(values) < 3:
        return e2, False
    e1 = abs(values[-2] - values[-3])
    if e1 == 0.0:
        return e2, e2 == 0.0
    r = e2 / e1
    if r >= 0.9:
        return 10.0 * e2, False
    err = e2 * max(1.0, r / (1.0 - r))
    if degrees is not None and (values[-1] - values[-2]) * (values[-2] - values[-3]) < 0.0:
        err = max(err, math.sqrt(e1 * e2))
    if degrees is not None and r > 0.0:
        M = degrees[-1]
        q = math.log(r) / math.log((M - 2.0) / M) - 1.0
        err = max(err, e2 * M / (2.0 * q)) if q > 0.0 else max(err, 10.0 * e2)
    return err, True


def mesh_order(sizes: Sequence[float], values: Sequence[float], order: int) -> float | None:
    """Observed convergence order of three meshes (sizes = elements), capped to [1, p + 1];
    None if the sequence is not contracting."""
    if len(values) < 3:
        return None
    e1, e2 = abs(values[-2] - values[-3]), abs(values[-1] - values[-2])
    if e2 == 0.0:
        return float(order + 1)
    if e1 <= e2:
        return None
    return min(max(math.log(e1 / e2) / math.log(sizes[-2] / sizes[-3]), 1.0), order + 1.0)


def mesh_error(sizes: Sequence[float], values: Sequence[float], order: int) -> float:
    """Error of the finest of up to three meshes (``sizes``: elements, increasing).

    With two meshes the last difference :math:`e_2 = |f_2 - f_1|` (a bound for any order
    >= 1 when the sizes double). With three, the observed order q
    (:func:`mesh_order`, capped at p + 1) gives the Richardson estimate
    :math:`e_2 / ((s_2/s_1)^q - 1)`; if the sequence is not contracting, :math:`e_2`.

    Examples
    --------
    >>> round(mesh_error([4, 8], [1.1, 1.01], 3), 6)
    0.09
    >>> round(mesh_error([4, 8, 16], [1.0017, 1.0001, 1.0], 3), 8)  # order 4 = p + 1
    6.67e-06
    """
    if len(values) < 2:
        return math.inf
    e2 = abs(values[-1] - values[-2])
    q = mesh_order(sizes, values, order)
    if q is None or e2 == 0.0:
        return e2
    return e2 / ((sizes[-1] / sizes[-2]) ** q - 1.0)


def reported_eta_error(moments: dict[str, float], errors: dict[str, float]) -> tuple[float, float]:
    """Error on eta to report, and the covariance of the V2 and Pin errors to go with it.

    The error of eta is estimated directly from its own refinement sequence: the
    truncation errors of V2 and Pin are strongly correlated and partly cancel in the
    ratio. The returned covariance (:math:`|\\rho| \\le 1`) makes first-order propagation
    from V2 and Pin as close to that estimate as it can be.
    """
    V2, Pin, eta = moments["V2"], moments["Pin"], abs(moments["eta"])
    a, b = errors["V2"] / V2, errors["Pin"] / Pin
    rel = errors["eta"] / eta
    rel_cov = min(max(rel, abs(a - b)), a + b)
    cov = (a * a + b * b - rel_cov**2) / 2.0 * V2 * Pin
    return errors["eta"], cov
