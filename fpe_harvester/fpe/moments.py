"""What every scheme's level reads off its coefficients the same way: the statistics of the
harvester from its second moments, and the conditional means on x from their numerators.

The statistics are :math:`P_{in} = \\sigma\\langle v\\xi\\rangle`,
:math:`\\eta = \\langle V^2\\rangle/(R P_{in})` and the relative residuals of the exact
stationary identities (docs/model.md §2)

.. math::

    r_V = \\frac{\\langle V^2\\rangle - K_c\\tau_p\\langle vV\\rangle}{\\langle V^2\\rangle},\\qquad
    r_P = \\frac{P_{in} - m\\gamma\\langle v^2\\rangle - K_v\\langle vV\\rangle}{P_{in}}.
"""

from __future__ import annotations

import numpy as np

from ..model import Params

__all__ = ["harvester_moments", "conditional_fields", "FIELD_FLOOR"]

#: Conditional means are masked where the density is below this fraction of its peak.
FIELD_FLOOR = 1e-9


def harvester_moments(p: Params, v2: float, vV: float, vxi: float, V2: float, x2: float) -> dict[str, float]:
    """``V2, Pin, eta, v2, vV, vxi, x2, res_V2, res_power`` (plain floats) from the second
    moments :math:`\\langle v^2\\rangle, \\langle vV\\rangle, \\langle v\\xi\\rangle,
    \\langle V^2\\rangle, \\langle x^2\\rangle` of a stationary density of parameters ``p``.

    Examples
    --------
    >>> from fpe_harvester.model import Params
    >>> mo = harvester_moments(Params(), 1.0, 0.5, 2.0, 1.0, 1.0)
    >>> round(mo["eta"] * Params().R * mo["Pin"], 12)
    1.0
    """
    Pin = p.sigma * vxi
    return {
        "V2": float(V2), "Pin": float(Pin), "eta": float(V2 / (p.R * Pin)), "v2": float(v2),
        "vV": float(vV), "vxi": float(vxi), "x2": float(x2),
        "res_V2": float((V2 - p.Kc * p.tau_p * vV) / V2),
        "res_power": float((Pin - p.m * p.gamma * v2 - p.Kv * vV) / Pin),
    }


def conditional_fields(density: np.ndarray, numerators: dict[str, np.ndarray],
                       centres: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """The density and the conditional means :math:`\\langle y|x\\rangle = n_y(x)/p(x) + c_y(x)`.

    Parameters
    ----------
    density : ndarray
        x-marginal density :math:`p(x)` at the points.
    numerators : dict
        :math:`n_y(x) = \\int y\\,p\\,dy'` (or its part relative to the centre) by name
        (``v_mean``, ``V_mean``, ``xi_mean``).
    centres : dict, optional
        :math:`c_y(x)` added to each ratio (the centre of a weight; default none).

    Returns
    -------
    dict
        ``density`` and each name as a masked array, masked where
        :math:`p < ` :data:`FIELD_FLOOR` :math:`\\max p`.
    """
    mask = density < FIELD_FLOOR * max(float(density.max()), 1e-300)
    safe = np.where(mask, 1.0, density)
    out: dict[str, np.ndarray] = {"density": density}
    for name, num in numerators.items():
        mean = num / safe if centres is None else num / safe + centres[name]
        out[name] = np.ma.masked_array(np.where(mask, 0.0, mean), mask=mask)
    return out
