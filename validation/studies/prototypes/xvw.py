"""Candidate kink scheme: DG in (x, v, V) with V graded toward 0, discrete ordinates in xi.

A study, not a product scheme (it is not registered in :data:`fpe_harvester.fpe.schemes.SCHEMES`):
it measures whether a V mesh graded geometrically toward 0 resolves the spike of the law of V
at the strong kink (n = 1, a = 2), where the Hermite expansion in V of scheme ``"xv"`` stalls.

Discretization of the half space x >= 0 (the density is symmetric under
:math:`(x, v, V, \\xi) \\to -(x, v, V, \\xi)`), for :math:`U = a|x|`:

* x and v: the nodes of scheme ``"xv"`` (:class:`~fpe_harvester.fpe.plane.PlaneMesh`, graded
  toward the trap), V: nodes symmetric about 0, ``v_layers`` geometric layers of ratio
  ``v_ratio`` toward 0 inside :math:`|V| < V_c` and ``v_bulk`` elements per sign out to
  :math:`L_V`; nodal DG of degree p on each axis (:class:`~fpe_harvester.fpe.plane.DGLine`),
  every 3-D matrix a Kronecker product (x outer, V inner).
* xi: K Hermite functions of the stationary Ornstein--Uhlenbeck law, diagonalized (the
  multiplication by xi becomes the Gauss--Hermite nodes :math:`\\lambda_i`), so that mode i
  is transported with the velocity
  :math:`(v,\\ (-a - m\\gamma v - K_v V + \\sigma\\lambda_i)/m,\\ K_c v - V/\\tau_p)`; the noise
  couples the modes through :math:`R^T \\mathrm{diag}(-k/\\tau) R`.
* Upwind fluxes, exact: on every face the normal speed is linear in one other coordinate,
  and each element is split at its root (:meth:`DGLine.signed_parts`). On x = 0 the inflow
  (v > 0) is the mirror image of the outflow.
* Solve: GMRES on the system bordered by the normalization, preconditioned by the exact
  (sparse LU) or incomplete (ILU) solve of each pair of mirror-coupled modes' 3-D transport
  (block Jacobi across xi-modes; the (x, v) rotation's cycles are inside each block).
* Variant ``"W"`` (:mod:`.xvw_w`): the third coordinate is :math:`W = V - K_c x`.

Measured (``validation/data/xvw.json``; p = 2, K = 5, ILU blocks unless said otherwise):

* Reaching the running units' voltage :math:`K_c\\tau_p L_v` (V bulk geometric) cuts the
  outflow through the edges at a = 2 from 0.077 to 1e-5.
* ILU blocks at drop tolerance 1e-3 give the exact-LU answer (eta to 1e-9) in a third of the
  time and a fifth of the memory (a = 0.5, 54000 unknowns: 61 s, 0.21 GB against 200 s, 1.1 GB).
* On scheme xv's (x, v) mesh (4 layers, 5 + 4 bulk elements), 10 V elements (194400 unknowns):
  a = 0.5 eta +0.12 % (V2 +0.03 %, Pin -0.10 %), identities 3e-4 and 5e-5, 126 iterations,
  359 s; a = 1 eta -1.0 % (V2 +1.6 %, Pin +2.7 %), identities 6e-4 and 8e-6, 88 iterations,
  229 s; a = 2 eta +16 % (V2 +21 %, Pin +4 %), V2 identity 0.44, negative mass 0.63 of the
  mass. With 14 V elements (272160 unknowns) a = 2 gives eta +18 %, V2 identity 0.022,
  negative mass 0.56; with K = 3 xi-modes V2 < 0 (K = 5 is not converged at a = 2; K = 7,
  272160 unknowns, did not finish in 500 s).
* K = 7 xi-modes at a = 2 (10 V elements, 272160 unknowns, 154 iterations, 107 CPU-s): eta
  +1.7 %, but V2 +23 % and Pin +21 %, V2 identity 0.91 and negative mass 0.60: K is not
  converged (K = 5: eta +16 %, V2 +21 %, Pin +4 %).
* Other directions at a = 2 (K = 5, 10 V elements): a fifth trap layer in (x, v) changes
  nothing (eta +15.87 % against +15.89 %); the (x, v) bulk refined from 5 + 4 to 7 + 6
  elements (297000 unknowns, 88 CPU-s) gives eta +14.4 %, V2 identity 0.10 (0.44), negative
  mass 0.59; coarsened to 3 + 2, eta +232 %; degree 3 on that coarse bulk (268800 unknowns)
  did not finish in 600 s (GMRES stalled near 2.5e-3).
* The force :math:`a n x^{n-1}` (through :mod:`.xvw_hybrid`'s assembly, K = 5, 194400
  unknowns): n = 1.5, a = 2 eta -0.94 % (scheme xv 0.20694), identities 7e-3 and 3e-4,
  negative mass 0.098; n = 1.25, a = 2 eta -2.0 % (Monte Carlo 0.16210 +- 0.00019),
  identities 4.6e-3 and 1.3e-3, negative mass 0.16.
* The W variant needs a tensor (x, W) mesh reaching :math:`|W| \\le L_V + K_c L_x`, whose bulk
  is coarse where the mass is: on the small mesh eta 5.2 at a = 0.5 (V: 0.619), and at a = 2
  both variants are far from a density (V 1.19, W 0.076, negative mass 1.15 and 0.64).

The mesh scales come from the reference table (:func:`reference_scales`) in the second series
(:data:`CASES`, one case per process, logged in ``validation/data/xvw.json``).
"""

from __future__ import annotations

import json
import math
import resource
import sys
import time
import tracemalloc
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fpe_harvester.errors import NotConvergedError
from fpe_harvester.fpe.plane import DGLine
from fpe_harvester.model import Harvester
from validation.studies.cli import bench_main, study_runner

from .xvw_hybrid import assemble_hybrid
from .xvw_mesh import XVWMesh, axes, reference_scales, xi_modes
from .xvw_w import kron3, moments_w, transport_w

__all__ = ["XVWMesh", "XVWResult", "solve_xvw", "reference_scales", "case_row", "log_case", "CASES",
           "QUICK_CASES", "study", "run"]


@dataclass(frozen=True)
class XVWResult:
    r"""One level: eta, V2, Pin (half-space integrals doubled), unknowns, GMRES iterations,
    relative residuals of the exact identities :math:`V^2 = K_c\tau_p\langle vV\rangle` and
    :math:`P_{in} = m\gamma\langle v^2\rangle + K_v\langle vV\rangle` and the outflow rate
    through the domain's edges (``leak``, per unit time and mass), seconds (assembly,
    preconditioner factorization, GMRES) and peak traced memory [GB]."""

    eta: float
    V2: float
    Pin: float
    unknowns: int
    iterations: int
    residuals: dict[str, float]
    seconds: dict[str, float]
    peak_gb: float
    mesh: XVWMesh
    maxrss_gb: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the level (the mesh settings as a dict)."""
        return {"eta": self.eta, "V2": self.V2, "Pin": self.Pin, "unknowns": self.unknowns,
                "iterations": self.iterations, "residuals": self.residuals, "seconds": self.seconds,
                "peak_gb": self.peak_gb, "maxrss_gb": self.maxrss_gb, "mesh": self.mesh.__dict__}


def _block(arrays: np.ndarray) -> sp.csr_matrix:
    """Block-diagonal matrix of per-element arrays (E, p+1, p+1)."""
    return sp.block_diag(list(arrays), format="csr")


def _face_sum(line: DGLine, pos: list[sp.spmatrix], neg: list[sp.spmatrix], outer_first: bool
              ) -> sp.csr_matrix:
    """Upwind face terms along ``line``: sum over its nodes f of
    :math:`(l_f - r_f)(l_f^T \\otimes W^+_f + r_f^T \\otimes W^-_f)`, with ``pos[f]``, ``neg[f]``
    the positive/negative-part weighted masses over the other axes (``outer_first``: the
    line's own factor is the outer one of the Kronecker product, else the inner one)."""
    out = None
    for f in range(line.elements + 1):
        lf, rf = line.left_of(f), line.right_of(f)
        jump = sp.csr_matrix(lf - rf).T
        for vec, W in ((lf, pos[f]), (rf, neg[f])):
            if not vec.any():
                continue
            F = jump @ sp.csr_matrix(vec)
            term = sp.kron(F, W) if outer_first else sp.kron(W, F)
            out = term if out is None else out + term
    return out.tocsr()


def assemble(h: Harvester, ms: XVWMesh, scales: tuple[float, float] | None = None) -> dict[str, Any]:
    """Transport matrices per xi-mode, the 3-D mass, mirror and moment vectors (mesh scales
    ``scales`` = (v2, V2), default :func:`.xvw_mesh.mc_scales`)."""
    p = h.params
    X, Vv, W = axes(h, ms, scales)
    lam, R, gen, parity = xi_modes(h, ms.K)
    Mx, Mv, MW = X.mass(), Vv.mass(), W.mass()
    Dv = Vv.derivative()
    vol_f = -kron3(Mx, Dv, MW)                   # times f_i = (-a + sigma lambda_i) / m
    vpos, vneg = Vv.signed_parts(np.array([0.0]), 1.0)
    Vp, Vn = _block(vpos[0]), _block(vneg[0])
    nf = X.elements + 1
    xface = _face_sum(X, [sp.kron(Vp, MW)] * nf, [sp.kron(Vn, MW)] * nf, True)
    if ms.variant == "W":
        T = transport_w(h, X, Vv, W, lam, xface, vol_f)
        third = moments_w(h, X, Vv, W)
    else:
        Mv1, MW1 = Vv.mass(power=1), W.mass(power=1)
        Dx, Dv1, DW, DW1 = X.derivative(), Vv.derivative(1), W.derivative(), W.derivative(1)
        common = (-kron3(Dx, Mv1, MW) + p.gamma * kron3(Mx, Dv1, MW) + (p.Kv / p.m) * kron3(Mx, Dv, MW1)
                  - p.Kc * kron3(Mx, Mv1, DW) + (1.0 / p.tau_p) * kron3(Mx, Mv, DW1))
        # V faces: speed Kc v - V_f / tau_p, linear in v
        sp_pos, sp_neg = Vv.signed_parts(-W.nodes / p.tau_p, p.Kc)
        wface = sp.kron(Mx, _face_sum(W, [_block(a) for a in sp_pos], [_block(a) for a in sp_neg], False))
        T = [_transport_v(h, X, Vv, W, li, common + xface + wface, vol_f) for li in lam]
        third = {"V2": np.kron(X.integral(), np.kron(Vv.integral(), W.integral(2))),
                 "vV": np.kron(X.integral(), np.kron(Vv.integral(1), W.integral(1)))}
    e0 = np.zeros(X.size)
    e0[0] = 1.0
    flip_v = sp.csr_matrix(np.fliplr(np.eye(Vv.size)))
    flip_W = sp.csr_matrix(np.fliplr(np.eye(W.size)))
    mirror = kron3(sp.csr_matrix(np.outer(e0, e0)), Vp @ flip_v, MW @ flip_W)
    mass = kron3(Mx, Mv, MW)
    ix, iv, iW = X.integral(), Vv.integral(), W.integral()
    return {"T": T, "mass": mass, "mirror": mirror, "gen": gen, "parity": parity, "R": R,
            "one": np.kron(ix, np.kron(iv, iW)), **third,
            "vxi": np.kron(ix, np.kron(Vv.integral(1), iW)) * math.sqrt(p.D / p.tau),
            "v2": np.kron(ix, np.kron(Vv.integral(2), iW)),
            "lines": (X, Vv, W)}


def _transport_v(h: Harvester, X: DGLine, Vv: DGLine, W: DGLine, li: float, shared: sp.csr_matrix,
                 vol_f: sp.csr_matrix) -> sp.csr_matrix:
    """Transport matrix of the xi-mode at the node ``li`` in (x, v, V): ``shared`` (volume
    terms and the x and V faces) plus the mode's force and its v faces."""
    p = h.params
    f = (-h.a + p.sigma * li) / p.m
    # v faces: speed f - gamma v_f - (Kv / m) V, linear in V
    pos, neg = W.signed_parts(f - p.gamma * Vv.nodes, -p.Kv / p.m)
    vface = _face_sum(Vv, [_block(a) for a in pos], [_block(a) for a in neg], True)
    return (shared + f * vol_f + sp.kron(X.mass(), vface)).tocsr()


def _operator_blocks(asm: dict[str, Any], i: int, j: int) -> sp.csr_matrix:
    """Block (i, j) of the full operator: transport on the diagonal, noise and mirror couplings."""
    blk = -asm["gen"][i, j] * asm["mass"] - asm["parity"][i, j] * asm["mirror"]
    return (blk + asm["T"][i]).tocsr() if i == j else blk.tocsr()


def _apply(asm: dict[str, Any]) -> Any:
    """The full operator as a function of the coefficients (xi-mode outer): the transport per
    mode plus the noise and mirror couplings as dense K x K mode products (the assembled
    matrix would hold K mass blocks per row, 2.4 GB at p = 3 on scheme xv's (x, v) mesh)."""
    T, mass, mirror, gen, parity = (asm[k] for k in ("T", "mass", "mirror", "gen", "parity"))
    K, n3 = len(T), mass.shape[0]

    def apply(d: np.ndarray) -> np.ndarray:
        D = d.reshape(K, n3)
        out = np.stack([T[i] @ D[i] for i in range(K)])
        out -= (mass @ (gen @ D).T).T + (mirror @ (parity @ D).T).T
        return out.ravel()

    return apply


def solve_xvw(h: Harvester, ms: XVWMesh, rtol: float = 1e-9, maxiter: int = 600,
              blocks: str = "lu", scales: tuple[float, float] | None = None, drop_tol: float = 1e-4,
              progress: bool = False) -> XVWResult:
    """Assemble and solve one level; raise :class:`NotConvergedError` if GMRES stalls.

    ``blocks``: the preconditioner's solve of each mirror-coupled pair of xi-modes, ``"lu"``
    (exact, SuperLU) or ``"ilu"`` (SuperLU's incomplete LU, drop tolerance ``drop_tol``, fill 10;
    measured on a pair of a = 2 with 30240 unknowns: exact LU 78e6 nonzeros, 15 s, 0.078 s a
    solve; ILU at 1e-3 2.5e6, 2.3 s, 0.007 s, 1.3 % residual of the block solve);
    ``scales`` = (v2, V2) set the mesh (default :func:`.xvw_mesh.mc_scales`); ``progress`` prints
    the phases' seconds and every 20th GMRES residual to stderr (a run stopped by a time limit shows
    where).
    """

    def say(msg: str) -> None:
        if progress:
            print(f"[{time.perf_counter() - t0:7.1f} s] {msg}", file=sys.stderr, flush=True)

    tracemalloc.start()
    t0 = time.perf_counter()
    if math.isfinite(ms.e_split) or h.n != 1.0:
        asm = assemble_hybrid(h, ms, scales)
    else:
        asm = assemble(h, ms, scales)
    K = ms.K
    n3 = asm["mass"].shape[0]
    A = _apply(asm)
    t1 = time.perf_counter()
    say(f"assembled: {K} modes x {n3} unknowns")
    groups, seen = [], set()
    for i in range(K):
        if i in seen:
            continue
        grp = sorted({i, K - 1 - i})
        seen.update(grp)
        blk = sp.bmat([[_operator_blocks(asm, r, c) for c in grp] for r in grp], format="csc")
        lu = spla.splu(blk, permc_spec="COLAMD") if blocks == "lu" else \
            spla.spilu(blk, drop_tol=drop_tol, fill_factor=10.0)
        groups.append((grp, lu))
    t2 = time.perf_counter()
    say("preconditioner factorized")
    u = np.kron(asm["R"][0], asm["one"])
    u /= np.linalg.norm(u)

    def matvec(d: np.ndarray) -> np.ndarray:
        return A(d) + u * float(u @ d)

    def prec(r: np.ndarray) -> np.ndarray:
        out = np.empty_like(r)
        Rm = r.reshape(K, n3)
        for grp, lu in groups:
            out.reshape(K, n3)[grp] = lu.solve(Rm[grp].ravel()).reshape(len(grp), n3)
        return out

    its = [0]

    def count(res: Any) -> None:
        its[0] += 1
        if its[0] % 20 == 0:
            say(f"GMRES iteration {its[0]}: residual {float(res):.2e}")

    N = K * n3
    d, info = spla.gmres(spla.LinearOperator((N, N), matvec=matvec), u, M=spla.LinearOperator((N, N), matvec=prec),
                         rtol=rtol, restart=min(200, maxiter), maxiter=-(-maxiter // 200), callback=count,
                         callback_type="pr_norm")
    t3 = time.perf_counter()
    peak = tracemalloc.get_traced_memory()[1] / 1e9
    tracemalloc.stop()
    # a stalled GMRES whose iterate still solves the system to 1e-3 is kept (its true residual
    # is reported): at a = 2 the hybrid stalls near 1e-5 (measured)
    solved = float(np.linalg.norm(matvec(d) - u))
    if info != 0 and not solved < 1e-3:
        raise NotConvergedError(f"GMRES did not converge in {its[0]} iterations ({N} unknowns, "
                                f"residual {solved:.2e})")
    eta, V2, Pin, residuals = _measure(h, asm, d, A(d))
    residuals["solve"] = solved
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB on Linux
    return XVWResult(eta, V2, Pin, N, its[0], residuals,
                     {"assembly": t1 - t0, "factorization": t2 - t1, "gmres": t3 - t2}, peak, ms, rss)


def _measure(h: Harvester, asm: dict[str, Any], d: np.ndarray, Ad: np.ndarray
             ) -> tuple[float, float, float, dict[str, float]]:
    """eta, V2, Pin and the residuals of the identities, the outflow and the negative mass of
    the solution ``d`` (``Ad``: the operator applied to it; half-space integrals doubled)."""
    q = h.params
    K = len(asm["T"])
    C = d.reshape(K, -1)
    c0, c1 = asm["R"][0] @ C, asm["R"][1] @ C
    mass = 2.0 * float(asm["one"] @ c0)
    V2 = 2.0 * float(asm["V2"] @ c0) / mass
    Pin = q.sigma * 2.0 * float(asm["vxi"] @ c1) / mass
    vV, v2 = (2.0 * float(asm[k] @ c0) / mass for k in ("vV", "v2"))
    # outflow through the edges of the domain per unit time and mass: test function 1 in
    # (x, v, V) and h_0 in xi (the noise and the interior faces conserve mass)
    unit = asm.get("unit", np.ones(C.shape[1]))
    leak = float(np.kron(asm["R"][0], unit) @ Ad) / (0.5 * mass)
    # negative part of the (x, v, V) marginal at the Lobatto nodes (weights: the basis integrals)
    neg = asm["negative"](c0) if "negative" in asm else -float(asm["one"] @ np.minimum(c0, 0.0))
    residuals = {"V2": (V2 - q.Kc * q.tau_p * vV) / V2, "power": (Pin - q.m * q.gamma * v2 - q.Kv * vV) / Pin,
                 "leak": leak, "negative": 2.0 * neg / mass}
    return V2 / (q.R * Pin), V2, Pin, residuals


_REACH = {"v_reach": 1.0, "v_geometric": True}
_ILU = {"blocks": "ilu", "drop_tol": 1e-3}
#: Scheme xv's (x, v) mesh (4 layers toward the trap, 5 + 4 bulk elements), GMRES to 1e-6.
_XV = {"layers": 4, "bulk_x": 5, "bulk_v": 4, **_REACH, **_ILU, "rtol": 1e-6, "maxiter": 400}
#: (a, changes to :data:`BASE`) of the study, one process each (``validation/data/xvw.json``;
#: about 75 min on 2 shared cores, at most 0.8 GB): the V domain reaching the running units'
#: voltage, the W variant, ILU blocks, then scheme xv's (x, v) mesh and V layers at a = 0.5
#: (reference: scheme xv, eta = 0.6103035 +- 4e-5), a = 1 (0.4075292 +- 2.4e-5) and a = 2
#: (Monte Carlo 0.12288 +- 0.00020). A run that passed 570 s was stopped (``failed``).
CASES: tuple[tuple[float, dict[str, Any]], ...] = (
    (0.5, {"p": 2, "K": 5}), (0.5, {"p": 2, "K": 5, "variant": "W"}),
    (0.5, {"p": 2, "K": 5, "v_bulk": 3, **_REACH}),
    (0.5, {"p": 2, "K": 5, "v_bulk": 3, "v_geometric": True, "variant": "W"}),
    (0.5, {"p": 2, "K": 5, "v_bulk": 3, **_REACH, **_ILU}),
    (2.0, {"p": 2, "K": 5, "v_bulk": 4, "v_layers": 3, **_REACH}),
    (2.0, {"p": 2, "K": 5, "v_bulk": 4, "v_layers": 3, **_REACH, "variant": "W"}),
    (2.0, {"p": 2, "K": 5, "v_bulk": 4, "v_layers": 3, **_REACH, **_ILU}),
    (0.5, {"p": 2, "K": 5, **_XV, "v_bulk": 3, "rtol": 1e-9, "maxiter": 600}),
    (2.0, {"p": 2, "K": 5, **_XV, "v_bulk": 4, "v_layers": 3, "rtol": 1e-9, "maxiter": 600}),
    (2.0, {"p": 2, "K": 5, **_XV, "v_bulk": 3, "v_layers": 2}),
    (2.0, {"p": 2, "K": 5, **_XV, "v_bulk": 3, "v_layers": 2, "variant": "W"}),
    (2.0, {"p": 2, "K": 5, **_XV, "v_bulk": 4, "v_layers": 3}),
    (1.0, {"p": 2, "K": 5, **_XV, "v_bulk": 3, "v_layers": 2}),
    (2.0, {"p": 2, "K": 5, "v_bulk": 4, "v_layers": 3, **_REACH, **_ILU, "rtol": 1e-6, "maxiter": 400,
           "variant": "W"}),
    (2.0, {"p": 2, "K": 3, **_XV, "v_bulk": 4, "v_layers": 3}),
    (2.0, {"p": 2, "K": 7, **_XV, "v_bulk": 3, "v_layers": 2}),
)
QUICK_CASES: tuple[tuple[float, dict[str, Any]], ...] = ((0.5, {"p": 1, "K": 3}), (0.5, {"p": 2, "K": 3}))
#: The smallest (x, v) mesh of the study: 2 layers toward the trap, 3 + 2 bulk elements.
BASE = {"layers": 2, "bulk_x": 3, "bulk_v": 2, "v_layers": 2, "v_bulk": 2}


def case_row(a: float, case: dict[str, Any], scales: tuple[float, float] | None = None) -> dict[str, Any]:
    """Solve one case (:data:`BASE` with the mesh changes in ``case``; its keys ``blocks``,
    ``rtol``, ``maxiter`` and ``drop_tol`` go to :func:`solve_xvw`, ``n`` (default 1) to the
    model) at ``a``, on the mesh scales ``scales`` (default :func:`reference_scales`, else
    :func:`.xvw_mesh.mc_scales` where the table has no row); the row of the study's JSON (a case
    whose GMRES stalls is recorded with its message)."""
    changes = dict(case)
    options = {k: changes.pop(k) for k in ("blocks", "rtol", "maxiter", "drop_tol") if k in changes}
    progress = bool(changes.pop("progress", False))
    n = float(changes.pop("n", 1.0))
    ms = XVWMesh(**{**BASE, **changes})
    if scales is None:
        try:
            scales = reference_scales(a, n)
        except KeyError:
            scales = None
    try:
        res = solve_xvw(Harvester.build(n=n, a=a), ms, scales=scales, progress=progress, **options)
        return {"a": a, "n": n, **options, **res.to_dict()}
    except NotConvergedError as exc:
        return {"a": a, "n": n, **options, "mesh": ms.__dict__, "failed": str(exc)}


def study(quick: bool) -> dict[str, Any]:
    """Solve every case (each on :data:`BASE` with its changes); a case whose GMRES stalls is
    recorded with its message."""
    rows = []
    for a, case in QUICK_CASES if quick else CASES:
        rows.append(case_row(a, case))
        print(json.dumps(rows[-1]), flush=True)
    return {"rows": rows}


def _draw(res: dict[str, Any], ax: Any) -> None:
    for a in sorted({r["a"] for r in res["rows"]}):
        pts = [(r["unknowns"], r["eta"]) for r in res["rows"] if r["a"] == a and "eta" in r]
        if pts:
            ax.plot(*zip(*pts), "o", label=f"a = {a:g}")
    ax.set_xscale("log")
    ax.set_xlabel("unknowns")
    ax.set_ylabel("eta")
    ax.legend()


run = study_runner(study, "xvw", _draw)

def log_case(argv: list[str]) -> dict[str, Any]:
    """One case in this process, appended as a JSON line to a log (the study's runs, one per
    process so that ``maxrss_gb`` is the run's own peak): ``--case A CASE_JSON LABEL LOG``."""
    a, case, label, log = float(argv[0]), json.loads(argv[1]), argv[2], argv[3]
    t0 = time.perf_counter()
    row = {"label": label, "case": case, **case_row(a, {**case, "progress": True})}
    row["wall_s"] = time.perf_counter() - t0
    row["cpu_s"] = time.process_time()
    with open(log, "a") as f:
        f.write(json.dumps(row) + "\n")
    return row


if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:2] == ["--case"]:
        print(json.dumps(log_case(sys.argv[2:])))
    else:
        bench_main(run, __doc__)
