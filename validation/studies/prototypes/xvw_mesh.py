"""The mesh of the candidate kink scheme (:mod:`.xvw`) and of its hybrid (:mod:`.xvw_hybrid`): the
settings (:class:`XVWMesh`), the moments that scale it, the three 1-D DG spaces in x, v and V
(:func:`axes`) and the discrete ordinates in xi (:func:`xi_modes`).
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass

import numpy as np

from fpe_harvester.fpe.plane import DGLine, PlaneMesh
from fpe_harvester.fpe.schemes.xv.kinkdisc import kink_domain
from fpe_harvester.model import Harvester
from validation.references import reftable

__all__ = ["XVWMesh", "mc_scales", "reference_scales", "axes", "xi_modes"]


@dataclass(frozen=True)
class XVWMesh:
    """Mesh settings of the candidate scheme (x and v as :class:`PlaneMesh`, V graded toward 0).

    Attributes
    ----------
    p : int
        DG degree on every axis.
    K : int
        Hermite functions (discrete ordinates) in xi.
    layers, ratio, bulk_x, bulk_v : int, float, int, int
        The (x, v) mesh (see :class:`PlaneMesh`; core box at the energy :math:`m\\langle v^2\\rangle`).
    v_layers, v_ratio, v_bulk : int, float, int
        V mesh: geometric layers toward 0 (ratio), elements per sign outside them.
    v_core : float
        :math:`V_c` in units of the standard deviation of V (equivalent harmonic unit).
    v_width : float
        :math:`L_V` in the same units.
    v_reach : float
        If > 0, :math:`L_V` is at least this fraction of :math:`K_c\\tau_p L_v`, the voltage a unit
        running at the edge speed :math:`L_v` charges to (the heavy tails of V at the strong kink).
    v_geometric : bool
        Bulk V elements in geometric progression from :math:`V_c` to :math:`L_V` (else spaced
        like :math:`t^{1.5}`).
    pV : int
        DG degree in V (0: p).
    variant : str
        ``"V"``: the third coordinate is V; ``"W"``: it is :math:`W = V - K_c x` (:mod:`.xvw_w`).
    e_split : float
        Hybrid (:mod:`.xvw_hybrid`): (x, v) elements whose lowest energy
        :math:`m v^2/2 + a x^n` reaches ``e_split`` carry ``kv`` Hermite functions in V instead
        of the V mesh (inf: none, the V variant).
    kv : int
        Hermite functions in V per bulk element of the hybrid.
    frame : str
        The hybrid's Hermite frames: ``"sign"`` (one for the bulk of x > 0) or ``"element"``
        (a centre per element) (:func:`.xvw_hybrid._frames`).
    frame_width : float
        The frames' width in units of the standard deviation of V they are built from (> 0).
    """

    p: int = 2
    K: int = 4
    layers: int = 3
    ratio: float = 0.3
    bulk_x: int = 4
    bulk_v: int = 3
    v_layers: int = 3
    v_ratio: float = 0.1
    v_bulk: int = 3
    v_core: float = 0.5
    v_width: float = 6.0
    v_reach: float = 0.0
    v_geometric: bool = False
    pV: int = 0
    variant: str = "V"
    e_split: float = math.inf
    kv: int = 6
    frame: str = "sign"
    frame_width: float = 1.0


@functools.cache
def mc_scales(h: Harvester) -> tuple[float, float]:
    r""":math:`\langle v^2\rangle` and :math:`\langle V^2\rangle` that set the mesh: from a short
    Monte Carlo run (2 % on eta, seed 1). The equivalent harmonic unit's are far off at the
    strong kink (a = 2: V2 50 times too small, the V domain then cuts the density off); scheme
    ``"xv"`` takes them from a pilot level instead."""
    from fpe_harvester import solve

    res = solve(h, "mc", tol=2e-2, seed=1, max_time=60.0, progress=False)
    return float(res.v2), float(res.V2)


def reference_scales(a: float, n: float = 1.0) -> tuple[float, float]:
    r"""(v2, V2) at ``n``, ``a`` from the reference table (Fokker--Planck, else Monte Carlo; at
    n = 1: Fokker--Planck at a <= 1, Monte Carlo at a = 2), v2 by the identities
    :math:`\langle vV\rangle = V^2/(K_c\tau_p)`,
    :math:`m\gamma\langle v^2\rangle = P_{in} - K_v\langle vV\rangle` (defaults)."""
    table = json.loads(reftable.PATH.read_text())
    row = table.get(f"fpe n = {n:g}, a = {a:g}") or table[f"mc n = {n:g}, a = {a:g}"]
    p = Harvester.build(n=n, a=a).params
    vV = row["V2"] / (p.Kc * p.tau_p)
    return (row["Pin"] - p.Kv * vV) / (p.m * p.gamma), row["V2"]


def axes(h: Harvester, ms: XVWMesh, scales: tuple[float, float] | None = None
         ) -> tuple[DGLine, DGLine, DGLine]:
    """The three 1-D DG spaces: x in [0, Lx], v in [-Lv, Lv], V in [-LV, LV], for the moments
    ``scales`` = (v2, V2) (default :func:`mc_scales`)."""
    p = h.params
    v2, V2 = mc_scales(h) if scales is None else scales
    sF = math.sqrt(p.sigma**2 * p.D / p.tau + p.Kv**2 * V2)
    Lx, Lv = kink_domain(h, v2, sF)
    # the core box reaches U(x_c) = a x_c^n = E_c (PlaneMesh sets x_c = E_c / a)
    Ec = p.m * v2
    a_eff = h.a if h.n == 1.0 else Ec / (Ec / h.a) ** (1.0 / h.n)
    plane = PlaneMesh(Lx=Lx, Lv=Lv, Ec=Ec, a=a_eff, layers=ms.layers, ratio=ms.ratio,
                      bulk_x=ms.bulk_x, bulk_v=ms.bulk_v, grading=2.5)
    sV = math.sqrt(V2)
    core = ms.v_core * sV
    edge = max(ms.v_width * sV, ms.v_reach * p.Kc * p.tau_p * Lv)
    if ms.variant == "W":
        edge += p.Kc * Lx   # W = V - Kc x: the same V range at every x of the tensor mesh
    inner = core * ms.v_ratio ** np.arange(ms.v_layers - 1, -1, -1)
    t = np.linspace(0.0, 1.0, ms.v_bulk + 1)[1:]
    outer = core * (edge / core) ** t if ms.v_geometric else core + (edge - core) * t**1.5
    half = np.concatenate([[0.0], inner, outer])
    V_nodes = np.concatenate([-half[:0:-1], half])
    return DGLine(plane.x_nodes(), ms.p), DGLine(plane.v_nodes(), ms.p), DGLine(V_nodes, ms.pV or ms.p)


def xi_modes(h: Harvester, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Nodes lambda (xi values), R (columns: eigenvectors of the xi multiplication in the
    normalized Hermite basis), the noise generator and the parity in the mode basis."""
    p = h.params
    s = math.sqrt(p.D / p.tau)
    J = np.diag(s * np.sqrt(np.arange(1.0, K)), 1)
    lam, R = np.linalg.eigh(J + J.T)
    gen = R.T @ np.diag(-np.arange(K) / p.tau) @ R
    parity = R.T @ np.diag((-1.0) ** np.arange(K)) @ R
    return lam, R, gen, parity
