"""The twin control: the harmonic twin's measured moments, whose exact means are known.

The path loop advances a harmonic ring on the fine level's noise (:mod:`montecarlo.harmonic`) and
measures it with the system (:func:`measure_twin`); :data:`TWIN` reads those time averages per
replica, with their exact means at the step used
(:func:`montecarlo.harmonic.twin_expectations`), for the regression
(:mod:`montecarlo.controls.regression`). The paths must start from the twin's stationary law, so
that its time averages have those means over any window.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ..layout import CF_PVX, CF_XI_HALF, M_TWIN
from .base import Columns, Control

if TYPE_CHECKING:
    from ..ensemble import Ensemble

__all__ = ["TWIN_MOMENTS", "TWIN", "TwinControl", "measure_twin", "measure_twin_groups"]

#: The twin's measured moments (the ``t_`` entries of :data:`montecarlo.layout.MOMENTS`):
#: second moments, then fourth moments and :math:`|x|^n` (n the system's exponent).
TWIN_MOMENTS = ("V2", "vV", "v2", "x2", "vxi", "x4", "x2V2", "x2v2", "absxn", "V2v2", "vxiV2")


class TwinControl(Control):
    """The twin's moments :data:`TWIN_MOMENTS` with their exact means at its step; available when
    the ensemble ran a twin (``simulate(..., twin=kappa, start="twin")``)."""

    name = "twin"

    def columns(self, e: Ensemble, valid: np.ndarray) -> Columns | None:
        if e.twin_kappa is None or e.start != "twin":
            return None
        mom, mom_first = e.moments(0), e.moments(-1)
        return ([mom["t_" + name][valid] for name in TWIN_MOMENTS],
                [mom_first["t_" + name][valid] for name in TWIN_MOMENTS],
                [e.twin_mean[name] for name in TWIN_MOMENTS])


#: The twin control.
TWIN = TwinControl()


@njit(cache=True, nogil=True)
def measure_twin(x, v, V, xi, w, cf, acc, nn, pvx) -> None:
    """Add the twin's moments (:data:`TWIN_MOMENTS`, ``nn`` the system's n) to their slots of
    ``acc`` (``t_*`` of :data:`montecarlo.layout.MOMENTS`).

    Second moments and a few fourth moments and :math:`|x|^n`: the twin is Gaussian, so
    each has an exactly known mean (:func:`montecarlo.harmonic.twin_expectations`), and the
    higher ones follow the nonlinear system's amplitude-dependent response better.
    """
    N, P = x.shape
    half = cf[CF_XI_HALF]
    s = np.zeros(11)
    for j in range(N):
        for p in range(P):
            wp = w[p]
            xx, vv, VV = x[j, p] * x[j, p], v[j, p] * v[j, p], V[j, p] * V[j, p]
            vxi = v[j, p] * xi[j, p]
            ax = abs(x[j, p])
            s[0] += wp * VV
            s[1] += wp * v[j, p] * V[j, p]
            s[2] += wp * vv
            s[3] += wp * xx
            s[4] += wp * vxi
            s[5] += wp * xx * xx
            s[6] += wp * xx * VV
            s[7] += wp * xx * vv
            s[8] += wp * (ax if nn == 1.0 else ax**nn)
            s[9] += wp * VV * vv
            s[10] += wp * VV * vxi
    if cf[CF_PVX] == 1.0:
        s[4] = 0.0
        for j in range(N):
            for p in range(P):
                s[4] += w[p] * pvx[j, p]
    s[4] *= half
    s[10] *= half
    for i in range(11):
        acc[M_TWIN + i] += s[i]


@njit(cache=True, nogil=True)
def measure_twin_groups(x, v, V, xi, w, cf, acc, row, nn, pvx) -> None:
    """Add the twin's moments (:data:`TWIN_MOMENTS`, ``nn`` the system's n) to their slots of
    ``acc[g, row]`` (``t_*`` of :data:`montecarlo.layout.MOMENTS`), g the replica of the path
    (``acc`` (G, rows, moments): G replicas of P / G consecutive paths; :func:`measure_twin` is the
    same for one replica).

    Second moments and a few fourth moments and :math:`|x|^n`: the twin is Gaussian, so
    each has an exactly known mean (:func:`montecarlo.harmonic.twin_expectations`), and the
    higher ones follow the nonlinear system's amplitude-dependent response better.
    """
    N, P = x.shape
    G = acc.shape[0]
    per = P // G
    half = cf[CF_XI_HALF]
    s = np.zeros(11)
    for g in range(G):
        p0, p1 = g * per, (g + 1) * per
        for i in range(11):
            s[i] = 0.0
        for j in range(N):
            for p in range(p0, p1):
                wp = w[p]
                xx, vv, VV = x[j, p] * x[j, p], v[j, p] * v[j, p], V[j, p] * V[j, p]
                vxi = v[j, p] * xi[j, p]
                ax = abs(x[j, p])
                s[0] += wp * VV
                s[1] += wp * v[j, p] * V[j, p]
                s[2] += wp * vv
                s[3] += wp * xx
                s[4] += wp * vxi
                s[5] += wp * xx * xx
                s[6] += wp * xx * VV
                s[7] += wp * xx * vv
                s[8] += wp * (ax if nn == 1.0 else ax**nn)
                s[9] += wp * VV * vv
                s[10] += wp * VV * vxi
        if cf[CF_PVX] == 1.0:
            s[4] = 0.0
            for j in range(N):
                for p in range(p0, p1):
                    s[4] += w[p] * pvx[j, p]
        s[4] *= half
        s[10] *= half
        for i in range(11):
            acc[g, row, M_TWIN + i] += s[i]
