r"""Hybrid of the candidate kink scheme (:mod:`.xvw`): Hermite functions in V on the (x, v)
elements of the bulk, the V mesh graded toward 0 only on the elements of the trap.

An (x, v) element is of the bulk when its lowest energy :math:`E = m v^2/2 + a x^n` is at
least ``e_split`` (:class:`~.xvw.XVWMesh`); there the V dependence is spanned by ``kv``
Hermite functions :math:`\mathrm{He}_k(y)\,e^{-y^2/2}`, :math:`y = (V - c_e)/s_e`
(orthonormalized), in a frame :math:`(c_e, s_e)` of its own: the mean and standard deviation
of V over the element's states in a short simulation (the half space x >= 0 of the mirror
symmetry, so a frame per element is also a frame per sign of x). On the trap's elements V is
the DG mesh of :mod:`.xvw`. Every element carries its own V basis, so the unknowns are
ordered element by element ((x, v) element outer, then x, v, V within it).

Faces between (x, v) elements couple two V bases through the exact projections
:math:`\int \psi^{e}_k \psi^{e'}_l\,dV` (x faces, the mirror at x = 0 with
:math:`\psi^{e'}(-V)`) and, on the v faces, through
:math:`\int u^\pm\,\psi^{e}_k \psi^{e'}_l\,dV` with the speed
:math:`u = (F(x) + \sigma\lambda_i)/m - \gamma v_f - (K_v/m) V` split at its root in V.
These integrals use one composite Gauss--Legendre rule in V whose breakpoints hold the V
mesh's nodes and the root: exact on the mesh's polynomials, and with intervals of at most
a quarter of the narrowest frame, exact to rounding on the Hermite functions. The force
:math:`F = -a n x^{n-1}` (x > 0) enters the volume term exactly (Gauss--Jacobi) and the v faces
by Gauss--Legendre in x (``2p + 10`` points); at n = 1 it is the constant -a and the
hybrid with no bulk element is the V variant of :mod:`.xvw` (tested to rounding).

Petrov--Galerkin in V on the bulk: trial functions :math:`\mathrm{He}_k(y)e^{-y^2/2}`, test
functions the polynomials :math:`\mathrm{He}_k(y)` (biorthogonal), so that the test function 1
is in every element's span and the scheme conserves mass (with trial = test functions, eta
came out 13 at a = 0.5). Measured (``validation/data/xvw.json``; scheme xv's (x, v) mesh, p = 2,
K = 5, 10 V elements on the trap, ``e_split`` = 1e-2, ``kv`` = 6, exact LU blocks; ILU blocks
break GMRES down):

* a = 0.5: 58320 unknowns (V mesh everywhere, ILU blocks: 194400), eta +0.23 % (V mesh:
  +0.12 %), identities 9e-7 and 2e-5, negative mass 0.047 (0.043), 116 iterations (78),
  72 CPU-s (69), 1.3 GB (0.62);
* a = 1: 58320 unknowns, eta -0.45 % (-1.0 %), identities 1.5e-5 and 1.2e-4, negative mass
  0.40 (0.053), 96 iterations (88), 48 CPU-s (64), 1.4 GB (0.60);
* a = 2: not a density (K = 5: eta 0.358 against 0.12288, negative mass 4750 times the mass,
  GMRES stalls at a true residual 6e-4; K = 3: stalls at 0.058). The bulk's test polynomials
  take the inflow from the trap's V mesh, which reaches :math:`L_V` = 127 frame widths at
  a = 2 (39 at a = 1): the largest transport entry grows from 4.4e5 to 1.2e8.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.polynomial import hermite_e as herm
from numpy.polynomial import legendre as npleg

from fpe_harvester.fpe.plane import DGLine, lobatto_points
from fpe_harvester.model import Harvester

from .xvw_mesh import XVWMesh, axes, xi_modes

__all__ = ["VBasis", "VRule", "element_frames", "assemble_hybrid", "element_order"]

#: Gauss points per interval of the V rule.
_NG = 12


@dataclass(frozen=True)
class VBasis:
    """Functions of V on one (x, v) element: the DG mesh ``line`` (``k = 0``) or ``k``
    orthonormal Hermite functions in the frame (``c``, ``s``) [V units]."""

    line: DGLine | None
    c: float = 0.0
    s: float = 1.0
    k: int = 0

    @property
    def size(self) -> int:
        return self.line.size if self.k == 0 else self.k

    def values(self, V: np.ndarray, test: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        r"""Values at the points ``V`` (shape (len(V), size)) of the trial functions, or of the
        test functions (``test``), and for Hermite functions their derivatives (the mesh's are
        not needed: its matrices come from :class:`DGLine`). Hermite trial functions are
        :math:`\mathrm{He}_k(y)e^{-y^2/2}/(s\sqrt{2\pi}\,k!)`, their test functions
        :math:`\mathrm{He}_k(y)`: biorthogonal, and the test function 1 is in every element's
        span, so that the scheme conserves mass."""
        V = np.asarray(V, dtype=float)
        if self.k == 0:
            inside = (V >= self.line.nodes[0]) & (V <= self.line.nodes[-1])
            return self.line.evaluate(np.eye(self.line.size), V) * inside[:, None], None
        y = (V - self.c) / self.s
        raw = herm.hermevander(y, self.k - 1)
        draw = np.zeros_like(raw)
        draw[:, 1:] = raw[:, :-1] * np.arange(1, self.k)
        root = np.sqrt(_factorials(self.k))
        if test:
            return raw / root, draw / (self.s * root)
        g = (np.exp(-0.5 * y**2) / (self.s * math.sqrt(2.0 * math.pi)))[:, None] / root
        return raw * g, (draw - y[:, None] * raw) * g / self.s


@functools.cache
def _factorials(k: int) -> np.ndarray:
    return np.array([math.factorial(j) for j in range(k)], dtype=float)


class VRule:
    """Composite Gauss--Legendre rule in V on the intervals between ``breaks`` (the values of
    the bases at its points are kept, keyed by the basis object)."""

    def __init__(self, breaks: np.ndarray) -> None:
        self.breaks = np.asarray(breaks, dtype=float)
        g, w = npleg.leggauss(_NG)
        lo, hi = self.breaks[:-1, None], self.breaks[1:, None]
        self.V = (lo + 0.5 * (hi - lo) * (g + 1.0)).ravel()
        self.w = (0.5 * (hi - lo) * w).ravel()
        self._vals: dict[tuple[int, bool], tuple[np.ndarray, np.ndarray | None]] = {}
        self._cum: dict[tuple[int, int], list[np.ndarray]] = {}

    def values(self, b: VBasis, test: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """Values (and Hermite derivatives) of ``b``'s trial (or test) functions at the rule's points."""
        if (id(b), test) not in self._vals:
            self._vals[(id(b), test)] = b.values(self.V, test)
        return self._vals[(id(b), test)]

    def pair(self, a: VBasis, b: VBasis, flip: bool = False) -> np.ndarray:
        r""":math:`\int\theta^a_k(V)\psi^b_l(\pm V)\,dV` (test functions of a, trial functions
        of b; minus for ``flip``)."""
        fb = b.values(-self.V)[0] if flip else self.values(b)[0]
        return (self.values(a, True)[0] * self.w[:, None]).T @ fb

    def _cumulative(self, a: VBasis, b: VBasis) -> list[np.ndarray]:
        key = (id(a), id(b))
        if key not in self._cum:
            fa, fb = self.values(a, True)[0], self.values(b)[0]
            n = self.breaks.size - 1
            per = [np.einsum("iqk,iq,iql->ikl", fa.reshape(n, _NG, -1), (self.w * self.V**j).reshape(n, _NG),
                             fb.reshape(n, _NG, -1)) for j in (0, 1)]
            self._cum[key] = [np.concatenate([np.zeros((1,) + p.shape[1:]), np.cumsum(p, axis=0)])
                              for p in per]
        return self._cum[key]

    def split(self, a: VBasis, b: VBasis, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        r""":math:`\int_{V<t} V^j\theta^a_k\psi^b_l\,dV` for j = 0, 1 at every root in ``t``
        (shape (len(t), ka, kb) each) and the whole integral of :math:`V\theta^a\psi^b`."""
        cum = self._cumulative(a, b)
        n = self.breaks.size - 1
        t = np.clip(np.asarray(t, dtype=float), self.breaks[0], self.breaks[-1])
        j = np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, n - 1)
        g, gw = npleg.leggauss(_NG)
        lo = self.breaks[j]
        pts = lo[:, None] + 0.5 * (t - lo)[:, None] * (g + 1.0)
        wts = 0.5 * (t - lo)[:, None] * gw
        pa, pb = (x.values(pts.ravel(), test)[0].reshape(t.size, _NG, -1)
                  for x, test in ((a, True), (b, False)))
        below = [cum[i][j] + np.einsum("tqk,tq,tql->tkl", pa, wts * pts**i, pb) for i in (0, 1)]
        return below[0], below[1], cum[1][-1]


def element_order(X: DGLine, Vv: DGLine, sizes: np.ndarray) -> np.ndarray:
    """Offsets of the (x, v) elements' unknowns (element (ix, iv) is number ``ix * Ev + iv``)."""
    p1 = (X.p + 1) * (Vv.p + 1)
    return np.concatenate([[0], np.cumsum(p1 * sizes.ravel())])


def element_frames(h: Harvester, X: DGLine, Vv: DGLine, samples: np.ndarray, least: int = 400
                   ) -> tuple[np.ndarray, np.ndarray]:
    r"""Mean and standard deviation of V on every (x, v) element (shape (Ex, Ev)) from
    ``samples`` (rows (x, v, V), mirrored into x >= 0); an element with fewer than ``least``
    states takes the least-squares plane :math:`c = \beta_0 + \beta_x x + \beta_v v` of all
    states at its centre and the spread about that plane."""
    x, v, V = samples.T
    flip = x < 0.0
    x, v, V = np.where(flip, -x, x), np.where(flip, -v, v), np.where(flip, -V, V)
    A = np.stack([np.ones_like(x), x, v], axis=1)
    beta = np.linalg.lstsq(A, V, rcond=None)[0]
    spread = float(np.std(V - A @ beta))
    ix = np.clip(np.searchsorted(X.nodes, x, side="right") - 1, 0, X.elements - 1)
    iv = np.clip(np.searchsorted(Vv.nodes, v, side="right") - 1, 0, Vv.elements - 1)
    xc, vc = 0.5 * (X.nodes[1:] + X.nodes[:-1]), 0.5 * (Vv.nodes[1:] + Vv.nodes[:-1])
    c = beta[0] + beta[1] * xc[:, None] + beta[2] * vc[None, :]
    s = np.full(c.shape, spread)
    key = ix * Vv.elements + iv
    count = np.bincount(key, minlength=c.size)
    mean = np.bincount(key, V, minlength=c.size) / np.maximum(count, 1)
    sd = np.sqrt(np.maximum(np.bincount(key, V**2, minlength=c.size) / np.maximum(count, 1) - mean**2, 0.0))
    ok = (count >= least) & (sd > 0.0)
    return np.where(ok, mean, c.ravel()).reshape(c.shape), np.where(ok, sd, s.ravel()).reshape(c.shape)


@functools.cache
def _samples(h: Harvester) -> np.ndarray:
    """(x, v, V) of 4e5 stationary states (2000 paths, 200 samples 1 time unit apart, seed 3)."""
    from montecarlo.sample import sample_states

    s = sample_states(h, samples=200, paths=2000, every=1.0, seed=3, threads=1)
    return s[..., 0, :3].reshape(-1, 3)


def _local(mat: sp.spmatrix, line: DGLine) -> np.ndarray:
    """The element blocks (E, p + 1, p + 1) of a block-diagonal 1-D matrix."""
    d, p1 = mat.toarray(), line.p + 1
    return np.stack([d[e * p1:(e + 1) * p1, e * p1:(e + 1) * p1] for e in range(line.elements)])


def _unit(p: int, i: int, j: int) -> np.ndarray:
    out = np.zeros((p + 1, p + 1))
    out[i, j] = 1.0
    return out


def _bases(h: Harvester, ms: XVWMesh, X: DGLine, Vv: DGLine, W: DGLine) -> list[VBasis]:
    """The V basis of every (x, v) element (ix outer): Hermite functions where the element's
    lowest energy reaches ``ms.e_split``, the V mesh elsewhere."""
    mesh = VBasis(W)
    if not math.isfinite(ms.e_split):
        return [mesh] * (X.elements * Vv.elements)
    vlow = np.where(Vv.nodes[:-1] * Vv.nodes[1:] <= 0.0, 0.0, np.minimum(Vv.nodes[:-1]**2, Vv.nodes[1:]**2))
    E = 0.5 * h.params.m * vlow[None, :] + h.a * X.nodes[:-1, None] ** h.n
    bulk = E >= ms.e_split
    c, s = _frames(h, ms, X, Vv, E)
    # equal frames share one object: the V rule's integrals are kept per pair of objects
    frames: dict[tuple[float, float], VBasis] = {}
    for key in zip(c[bulk].tolist(), s[bulk].tolist()):
        frames.setdefault(key, VBasis(None, key[0], key[1], ms.kv))
    return [frames[(float(c[i, j]), float(s[i, j]))] if bulk[i, j] else mesh
            for i in range(X.elements) for j in range(Vv.elements)]


def _frames(h: Harvester, ms: XVWMesh, X: DGLine, Vv: DGLine, E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres and widths of the bulk elements' frames (shape (Ex, Ev)).

    ``ms.frame == "sign"``: one frame for the bulk of x > 0 (its mirror image for x < 0), the
    mean and standard deviation of V over the simulated bulk states; ``"element"``: each
    element's own mean of V, one width (the widest element's). Measured at a = 0.5 (p = 2,
    K = 3, 5400 unknowns): per-element centres (spread over 12 widths) give a density whose
    negative part is 3 times its mass, the one frame 0.14; per-element widths as well, |f|
    ~ 100 times the mass: the test functions' weight :math:`e^{y^2/2}` of one frame outgrows
    the Gaussian that flows in from a neighbour's frame.
    """
    c, s = element_frames(h, X, Vv, _samples(h))
    bulk = E >= ms.e_split
    if ms.frame == "element":
        return c, np.full(c.shape, ms.frame_width * float(s[bulk].max()) if bulk.any() else 1.0)
    x, v, V = _samples(h).T
    flip = x < 0.0
    x, v, V = np.where(flip, -x, x), np.where(flip, -v, v), np.where(flip, -V, V)
    inbulk = 0.5 * h.params.m * v**2 + h.a * x**h.n >= ms.e_split
    width = ms.frame_width * float(V[inbulk].std())
    return np.full(c.shape, float(V[inbulk].mean())), np.full(c.shape, width)


def _rule(bases: list[VBasis], W: DGLine) -> VRule:
    """The V rule: the mesh's nodes, and where Hermite frames exist, intervals of at most a
    quarter of the narrowest frame out to 12 frame widths."""
    herm_b = [b for b in bases if b.k]
    if not herm_b:
        return VRule(W.nodes)
    L = max(W.nodes[-1], max(abs(b.c) + 12.0 * b.s for b in herm_b))
    step = max(min(b.s for b in herm_b) / 4.0, L / 4000.0)
    grid = np.linspace(-L, L, int(math.ceil(2.0 * L / step)) + 1)
    return VRule(np.unique(np.concatenate([grid, W.nodes])))


def _vmatrices(b: VBasis, rule: VRule) -> tuple[Any, Any, Any, Any]:
    r"""Mass, V-weighted mass, :math:`\int\theta_k'\psi_l` and :math:`\int V\theta_k'\psi_l` of one basis."""
    if b.k == 0:
        W = b.line
        return tuple(m.toarray() for m in (W.mass(), W.mass(power=1), W.derivative(), W.derivative(1)))
    f, df = rule.values(b, True)
    g = rule.values(b)[0]
    w, V = rule.w[:, None], rule.V[:, None]
    return (f * w).T @ g, (f * w * V).T @ g, (df * w).T @ g, (df * w * V).T @ g


class _Blocks:
    """Blocks keyed by (test element, trial element), kept as triplets and summed into one
    sparse matrix (the local blocks are small dense arrays: scipy's per-block overhead
    was most of the assembly time)."""

    def __init__(self, offsets: np.ndarray) -> None:
        self.offsets = offsets
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def add(self, i: int, j: int, blk: Any) -> None:
        if sp.issparse(blk):
            c = blk.tocoo()
            r, k, v = c.row, c.col, c.data
        else:
            r, k = np.nonzero(blk)
            v = blk[r, k]
        self.parts.append((r + self.offsets[i], k + self.offsets[j], v))

    def matrix(self) -> sp.csr_matrix:
        n = self.offsets[-1]
        r, k, v = (np.concatenate(a) for a in zip(*self.parts))
        return sp.csr_matrix((v, (r, k)), shape=(n, n))


def _k3(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Dense Kronecker product of three small matrices (a outer)."""
    return np.kron(np.kron(a, b), c)


def _xpoints(h: Harvester, X: DGLine, ix: int, Mx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Weighted x masses :math:`w_q\phi_i(x_q)\phi_j(x_q)` and forces :math:`F(x_q)` of element
    ``ix`` for the v faces (n = 1: the constant force, one term with the whole mass)."""
    if h.n == 1.0:
        return Mx[ix][None], np.array([-h.a])
    g, gw = npleg.leggauss(2 * X.p + 10)
    lo, hi = X.nodes[ix], X.nodes[ix + 1]
    xq = lo + 0.5 * (hi - lo) * (g + 1.0)
    phi = npleg.legvander(g, X.p) @ np.linalg.inv(npleg.legvander(lobatto_points(X.p), X.p))
    return np.einsum("q,qi,qj->qij", 0.5 * (hi - lo) * gw, phi, phi), -h.a * h.n * xq ** (h.n - 1.0)


def _place(px: int, xw: np.ndarray, C: np.ndarray, a: int, b: int, pv: int) -> np.ndarray:
    """:math:`\\sum_q` (x factor ``xw[q]``) x (v unit matrix at (a, b)) x (V factor ``C[q]``),
    ordered x outer, v middle, V inner."""
    out = np.zeros((px, pv, C.shape[1], px, pv, C.shape[2]))
    out[:, a, :, :, b, :] = np.einsum("qij,qkl->ikjl", xw, C)
    return out.reshape(px * pv * C.shape[1], -1)


def _vfaces(h: Harvester, X: DGLine, Vv: DGLine, bases: list[VBasis], rule: VRule, lam: np.ndarray,
            Mx: np.ndarray, out: list[_Blocks]) -> None:
    """Upwind v faces of every xi-mode (node ``lam[i]`` into ``out[i]``), the speed split at its
    root in V at every x point."""
    p, Ev, p1 = h.params, Vv.elements, Vv.p + 1
    kappa = p.Kv / p.m
    for ix in range(X.elements):
        xw, F = _xpoints(h, X, ix, Mx)
        for g in range(Ev + 1):
            s0 = (F[None, :] + p.sigma * lam[:, None]) / p.m - p.gamma * Vv.nodes[g]   # (K, q)
            sides = [(e, sign, end) for e, sign, end in ((ix * Ev + g - 1, 1.0, p1 - 1),
                                                         (ix * Ev + g, -1.0, 0))
                     if (g > 0 if sign > 0 else g < Ev)]
            for et, sign, tend in sides:
                for eu, _, uend in sides:
                    lo0, lo1, tot1 = rule.split(bases[et], bases[eu], (s0 / kappa).ravel())
                    s = s0.reshape(-1, 1, 1)
                    pos = s * lo0 - kappa * lo1
                    part = pos if uend == p1 - 1 else s * rule.pair(bases[et], bases[eu]) - kappa * tot1 - pos
                    part = part.reshape(s0.shape + part.shape[1:])
                    for i in range(lam.size):
                        out[i].add(et, eu, sign * _place(X.p + 1, xw, part[i], tend, uend, p1))


def _xfaces_mirror(X: DGLine, Vv: DGLine, bases: list[VBasis], rule: VRule, common: _Blocks,
                   mirror: _Blocks) -> None:
    """Upwind x faces (speed v) into ``common``; the mirror's inflow at x = 0 into ``mirror``."""
    Ex, Ev, p1 = X.elements, Vv.elements, X.p + 1
    vpos, vneg = (a[0] for a in Vv.signed_parts(np.array([0.0]), 1.0))
    for f in range(Ex + 1):
        for iv in range(Ev):
            sides = [(e, sign, end) for e, sign, end in (((f - 1) * Ev + iv, 1.0, p1 - 1),
                                                         (f * Ev + iv, -1.0, 0))
                     if (f > 0 if sign > 0 else f < Ex)]
            for et, sign, tend in sides:
                for eu, _, uend in sides:
                    vpart = vpos[iv] if uend == p1 - 1 else vneg[iv]
                    C = rule.pair(bases[et], bases[eu])
                    common.add(et, eu, sign * _k3(_unit(X.p, tend, uend), vpart, C))
    flip = np.fliplr(np.eye(Vv.p + 1))
    for iv in range(Ev):
        if Vv.nodes[iv] >= 0.0:
            et, eu = iv, Ev - 1 - iv
            C = rule.pair(bases[et], bases[eu], flip=True)
            mirror.add(et, eu, _k3(_unit(X.p, 0, 0), vpos[iv] @ flip, C))


def _moments(h: Harvester, X: DGLine, Vv: DGLine, bases: list[VBasis], rule: VRule) -> dict[str, Any]:
    """Integrals of every unknown (1, V^2, vV, v xi's mode-1 weight, v^2) and the negative part
    of a (x, v, V) density (nodal in x and v, at the V rule's points on Hermite elements)."""
    Ev, pp = Vv.elements, (X.p + 1) * (Vv.p + 1)
    ix, iv = X.integral().reshape(X.elements, -1), [Vv.integral(k).reshape(Ev, -1) for k in range(3)]
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("one", "V2", "vV", "vxi", "v2")}
    for e, b in enumerate(bases):
        jx, jv = divmod(e, Ev)
        iV = [b.line.integral(k) for k in range(3)] if b.k == 0 else \
            [(rule.values(b)[0] * (rule.w * rule.V**k)[:, None]).sum(axis=0) for k in range(3)]
        for key, kv_, kV in (("one", 0, 0), ("V2", 0, 2), ("vV", 1, 1), ("vxi", 1, 0), ("v2", 2, 0)):
            out[key].append(np.kron(ix[jx], np.kron(iv[kv_][jv], iV[kV])))
    out["vxi"] = [v * math.sqrt(h.params.D / h.params.tau) for v in out["vxi"]]
    vecs = {k: np.concatenate(v) for k, v in out.items()}
    wxv = [np.kron(ix[e // Ev], iv[0][e % Ev]) for e in range(len(bases))]
    sizes = np.array([b.size for b in bases])
    off = np.concatenate([[0], np.cumsum(pp * sizes)])

    def negative(c0: np.ndarray) -> float:
        total = 0.0
        for e, b in enumerate(bases):
            loc = c0[off[e]:off[e + 1]].reshape(pp, b.size)
            if b.k == 0:
                total += float(wxv[e] @ np.minimum(loc, 0.0) @ b.line.integral())
            else:
                total += float(wxv[e] @ np.minimum(loc @ rule.values(b)[0].T, 0.0) @ rule.w)
        return -total

    return {**vecs, "negative": negative}


def _volume(h: Harvester, X: DGLine, Vv: DGLine, W: DGLine, bases: list[VBasis], rule: VRule,
            common: _Blocks, volxi: _Blocks, mass: _Blocks) -> None:
    """Volume terms of every element (the force's noise part :math:`-\\int\\phi\\,\\partial_v\\phi`
    apart, into ``volxi``: each mode scales it by :math:`\\sigma\\lambda_i/m`), the V faces of the
    mesh elements and the mass."""
    p = h.params
    Mx, Dx = _local(X.mass(), X), _local(X.derivative(), X)
    FX = _local(X.mass() if h.n == 1.0 else h.n * X.power_mass(h.n - 1.0), X) * (-h.a / p.m)
    Mv, Mv1, Dv, Dv1 = (_local(m, Vv) for m in (Vv.mass(), Vv.mass(power=1), Vv.derivative(),
                                                 Vv.derivative(1)))
    # V faces of the mesh: speed Kc v - V_f / tau_p, linear in v; per face f the V factors
    # (l_f - r_f) l_f^T (upwind from below) and (l_f - r_f) r_f^T
    sp_pos, sp_neg = Vv.signed_parts(-W.nodes / p.tau_p, p.Kc)
    ends = [(W.left_of(f), W.right_of(f)) for f in range(W.elements + 1)]
    Fp = np.stack([np.outer(lf - rf, lf) for lf, rf in ends])
    Fn = np.stack([np.outer(lf - rf, rf) for lf, rf in ends])
    mats: dict[int, tuple[Any, ...]] = {}
    for e, b in enumerate(bases):
        ix, iv = divmod(e, Vv.elements)
        if id(b) not in mats:
            mats[id(b)] = _vmatrices(b, rule)
        M, M1, D, D1 = mats[id(b)]
        blk = (-_k3(Dx[ix], Mv1[iv], M) + p.gamma * _k3(Mx[ix], Dv1[iv], M)
               + (p.Kv / p.m) * _k3(Mx[ix], Dv[iv], M1) - p.Kc * _k3(Mx[ix], Mv1[iv], D)
               + (1.0 / p.tau_p) * _k3(Mx[ix], Mv[iv], D1) - _k3(FX[ix], Dv[iv], M))
        if b.k == 0:
            face = (np.einsum("fab,fij->aibj", sp_pos[:, iv], Fp)
                    + np.einsum("fab,fij->aibj", sp_neg[:, iv], Fn))
            blk = blk + np.kron(Mx[ix], face.reshape(blk.shape[0] // Mx[ix].shape[0], -1))
        common.add(e, e, blk)
        volxi.add(e, e, -_k3(Mx[ix], Dv[iv], M))
        mass.add(e, e, _k3(Mx[ix], Mv[iv], M))


def assemble_hybrid(h: Harvester, ms: XVWMesh, scales: tuple[float, float] | None = None) -> dict[str, Any]:
    """Transport matrices per xi-mode, mass, mirror and moment vectors of the hybrid (the
    dictionary of :func:`.xvw.assemble`, element by element, plus ``negative``, ``bases``, ``rule``)."""
    p = h.params
    X, Vv, W = axes(h, ms, scales)
    lam, R, gen, parity = xi_modes(h, ms.K)
    bases = _bases(h, ms, X, Vv, W)
    rule = _rule(bases, W)
    off = element_order(X, Vv, np.array([b.size for b in bases]))
    common, volxi, mass, mirror = (_Blocks(off) for _ in range(4))
    _volume(h, X, Vv, W, bases, rule, common, volxi, mass)
    _xfaces_mirror(X, Vv, bases, rule, common, mirror)
    vf = [_Blocks(off) for _ in lam]
    _vfaces(h, X, Vv, bases, rule, lam, _local(X.mass(), X), vf)
    C, Vxi = common.matrix(), volxi.matrix()
    T = [(C + (p.sigma * li / p.m) * Vxi + v.matrix()).tocsr() for li, v in zip(lam, vf)]
    return {"T": T, "mass": mass.matrix(), "mirror": mirror.matrix(), "gen": gen, "parity": parity, "R": R,
            **_moments(h, X, Vv, bases, rule), "lines": (X, Vv, W), "bases": bases, "rule": rule,
            "unit": _unit_vector(bases, (X.p + 1) * (Vv.p + 1))}


def _unit_vector(bases: list[VBasis], pp: int) -> np.ndarray:
    """Coefficients of the test function 1 (the outflow through the edges): all ones on the
    mesh, the first Hermite polynomial on the bulk."""
    return np.concatenate([np.ones(pp * b.size) if b.k == 0 else np.kron(np.ones(pp), np.eye(b.k)[0])
                           for b in bases])
