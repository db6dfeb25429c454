"""The Monte Carlo solver: adaptive replicas until a target error on eta, with a status.

``MonteCarlo(...).solve(h)`` runs batches of independent replicas (each ``paths`` rings for
``t_burn + t_run``) until the relative error on eta (standard error and, with
``richardson=True``, the time-step bias estimate, in quadrature) is below ``tol`` or the
wall-time budget ``max_time`` is spent; then the status says ``NOT_CONVERGED``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fpe_harvester.errors import ParameterError, check_int, check_real
from fpe_harvester.exact import classify, growth_rate, k_di, max_sin2, mode_eigenvalues
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats, Status, propagated_eta_error

from .estimate import Estimate, estimate
from .scheme import SCHEME_NAMES, scheme_kind
from .simulate import Ensemble, default_threads, simulate

__all__ = ["MonteCarlo"]

_RNG = "numpy Generator(PCG64) drawn inside numba, one SeedSequence child per (replica, chunk)"


def _auto_burn(h: Harvester) -> float:
    """Burn-in: 8 slowest linear relaxation times for harmonic rings, else 40, in [20, 2000]."""
    if h.is_linear:
        kap = float(max(h.mode_stiffness().min(), 0.0))
        re = mode_eigenvalues(kap, h.params).real
        # at k = k_di the zero eigenvalue is x's free diffusion, which never equilibrates
        re = re[re < -1e-12]
        rate = -float(re.max()) if re.size else 0.0
        return float(min(2000.0, max(20.0, 8.0 / rate))) if rate > 0 else 2000.0
    return 40.0


@dataclass(frozen=True)
class MonteCarlo:
    """Monte Carlo solver for any harvester (any n >= 1, any ring, any k).

    Reports ``V2, Pin, eta, Vrms, v2, vV, x2`` with errors, so that the stationary identities
    :math:`\\langle V^2\\rangle = K_c\\tau_p\\langle vV\\rangle` and
    :math:`\\sigma\\langle v\\xi\\rangle = m\\gamma\\langle v^2\\rangle + K_v\\langle vV\\rangle`
    can be checked from the result (``info`` also carries both residuals with their errors).

    Parameters
    ----------
    seed : int or None
        Root seed (``SeedSequence``); None draws fresh entropy, recorded in ``info``.
    tol : float
        Target relative error on eta, in (0, 1): the standard error over replicas and (with
        ``richardson``) the time-step bias estimate, added in quadrature. Default 1e-2.
    dt : float
        Time step, > 0 (model time units). With ``richardson`` the reported numbers come
        from ``dt/2`` and ``dt`` gives the bias estimate. Default 0.02.
    paths : int
        Paths (rings) per replica, >= 2. Default 256.
    min_replicas, max_replicas : int
        Replicas run at least (>= 2, for an error bar) and at most. Defaults 8 and 4096.
    t_burn : float or None
        Burn-in per path (>= 0); None picks 8 slowest relaxation times (harmonic) or 40.
    t_run : float
        Measured time per path, > 0. Default 100.
    max_time : float
        Wall-time budget in seconds, > 0. Default 600.
    escape : float or None
        Escape threshold on |x_j|, > 0. None (default): 100, or for a metastable ring four
        times the barrier amplitude :math:`x^* = (a n / (4|k| s))^{1/(2-n)}` where the
        anti-phase coupling force :math:`4|k| s x` (:math:`s = \\max_q \\sin^2(\\pi q/N)`)
        overtakes the on-site force, if that is larger.
    progress : bool or None
        tqdm bar on stderr; None shows it only for runs longer than 2 s.
    richardson : bool
        Also run at the coarse step on the same noise and fold the bias into the error.
    threads : int or None
        Worker threads (results do not depend on it). Default: usable CPUs.

    Examples
    --------
    >>> from fpe_harvester import Harvester, solve
    >>> r = solve(Harvester.build(a=0.5), "mc", seed=1, tol=0.05, paths=64, t_run=20,
    ...           progress=False)
    >>> abs(r.eta - 20 / 39) < 4 * r.eta_err
    True
    """

    name: ClassVar[str] = "mc"

    seed: int | None = None
    tol: float = 1e-2
    dt: float = 0.02
    paths: int = 256
    min_replicas: int = 8
    max_replicas: int = 4096
    t_burn: float | None = None
    t_run: float = 100.0
    max_time: float = 600.0
    escape: float | None = None
    progress: bool | None = None
    richardson: bool = True
    threads: int | None = None

    def __post_init__(self) -> None:
        if self.seed is not None:
            object.__setattr__(self, "seed", check_int("seed", self.seed, low=0))
        object.__setattr__(self, "tol", check_real("tol", self.tol, low=0.0, high=1.0, low_open=True,
                                                   high_open=True))
        object.__setattr__(self, "dt", check_real("dt", self.dt, low=0.0, low_open=True))
        object.__setattr__(self, "paths", check_int("paths", self.paths, low=2))
        object.__setattr__(self, "min_replicas", check_int("min_replicas", self.min_replicas, low=2))
        object.__setattr__(self, "max_replicas",
                           check_int("max_replicas", self.max_replicas, low=self.min_replicas))
        if self.t_burn is not None:
            object.__setattr__(self, "t_burn", check_real("t_burn", self.t_burn, low=0.0))
        object.__setattr__(self, "t_run", check_real("t_run", self.t_run, low=0.0, low_open=True))
        if self.dt > self.t_run:
            raise ParameterError(f"dt must not exceed t_run = {self.t_run:g}, got {self.dt!r}")
        object.__setattr__(self, "max_time", check_real("max_time", self.max_time, low=0.0, low_open=True))
        if self.escape is not None:
            object.__setattr__(self, "escape", check_real("escape", self.escape, low=0.0, low_open=True))
        if self.progress is not None and not isinstance(self.progress, bool):
            raise ParameterError(f"progress must be True, False or None, got {self.progress!r} "
                                 f"(type {type(self.progress).__name__})")
        if not isinstance(self.richardson, bool):
            raise ParameterError(f"richardson must be True or False, got {self.richardson!r} "
                                 f"(type {type(self.richardson).__name__})")
        if self.threads is not None:
            object.__setattr__(self, "threads", check_int("threads", self.threads, low=1))

    def unsupported_reason(self, h: Harvester) -> str | None:
        """Always None: Monte Carlo handles every harvester."""
        return None

    # -- running ---------------------------------------------------------------------------

    def _run(self, h: Harvester, replicas: int, first: int, t_burn: float) -> Ensemble:
        return simulate(h, dt=self.dt, paths=self.paths, replicas=replicas, t_burn=t_burn,
                        t_run=self.t_run, seed=self.seed, richardson=self.richardson,
                        threshold=self.threshold(h), threads=self.threads, first_replica=first)

    def threshold(self, h: Harvester) -> float:
        """Escape threshold used for ``h`` (see ``escape``)."""
        if self.escape is not None:
            return self.escape
        if h.confinement == "metastable":
            x_star = (h.a * h.n / (4.0 * abs(h.k) * max_sin2(h.N))) ** (1.0 / (2.0 - h.n))
            return float(max(100.0, 4.0 * x_star))
        return 100.0

    def run(self, h: Harvester) -> tuple[Ensemble, Estimate, bool]:
        """Adaptive replica loop; returns the ensemble, its estimate and whether tol was met."""
        from tqdm import tqdm

        if self.seed is None:
            # one entropy for every batch, so that batches are distinct children of one root
            return dataclasses.replace(self, seed=int(np.random.SeedSequence().entropy)).run(h)
        t_burn = _auto_burn(h) if self.t_burn is None else self.t_burn
        threads = self.threads or default_threads()
        start = time.perf_counter()
        bar = tqdm(desc=f"mc N={h.N} n={h.n:g}", unit="replica",
                   file=sys.stderr, disable=self.progress is False,
                   delay=0.0 if self.progress else 2.0, leave=False)
        ens = self._run(h, self.min_replicas, 0, t_burn)
        bar.update(ens.replicas)
        est = estimate(ens, h)
        met = False
        with bar:
            while True:
                rel = est.rel_error("eta")
                stat_rel = est.se["eta"] / abs(est.mean["eta"]) if est.replicas else math.inf
                bar.set_postfix_str(f"rel err eta {rel:.2e}")
                if rel <= self.tol:
                    met = True
                    break
                if ens.escaped_fraction() >= 0.5 or est.replicas < 2:
                    break
                # bias-dominated: more replicas cannot reach tol
                if est.bias["eta"] != 0.0 and abs(est.bias["eta"]) / abs(est.mean["eta"]) > self.tol \
                        and stat_rel < 0.3 * self.tol:
                    break
                R = ens.replicas
                if R >= self.max_replicas:
                    break
                elapsed = time.perf_counter() - start
                per_rep = max(ens.wall_time, 1e-9) / R
                want = math.ceil(R * (stat_rel / (0.9 * self.tol)) ** 2) - R if math.isfinite(stat_rel) else R
                batch = int(min(max(want, threads), R, self.max_replicas - R))
                batch = min(batch, int((self.max_time - elapsed) / per_rep))
                if batch < 1:
                    break
                ens = ens.merge(self._run(h, batch, R, t_burn))
                bar.update(batch)
                est = estimate(ens, h)
        return ens, est, met

    # -- result ------------------------------------------------------------------------------

    def solve(self, h: Harvester) -> Stats:
        """Stationary statistics of ``h`` with standard errors, bias estimate and a status."""
        if not isinstance(h, Harvester):
            raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
        start = time.perf_counter()
        harmonic_status = classify(h)[0] if h.is_linear else None
        if harmonic_status == "unstable":
            # short run: only to show the escape, statistics do not exist
            short = dataclasses.replace(self, max_replicas=self.min_replicas, tol=0.999)
            ens, est, _ = short.run(h)
        else:
            ens, est, met = self.run(h)
        info = self._info(h, ens, est, time.perf_counter() - start)
        esc = ens.escaped_fraction()
        kd = k_di(h.N, h.a) if h.N > 1 else None
        if harmonic_status == "unstable":
            rate = growth_rate(h)
            return Stats(status=Status.UNSTABLE, method=self.name, growth_rate=rate, info=info, message=(
                f"unstable: harmonic ring with k = {h.k:g} beyond k_di = {kd:.10g}; the critical "
                f"mode grows like exp({rate:.4g} t). {esc:.1%} of the simulated paths passed "
                f"|x| = {self.threshold(h):g} (times in info); no stationary statistics exist."))
        if est.replicas < 2:
            status = Status.METASTABLE if h.confinement == "metastable" else Status.UNSTABLE
            return Stats(status=status, method=self.name, info=info, message=(
                f"{est.replicas} replica(s) measured anything, too few for an error bar: the paths "
                f"escaped (|x| > {self.threshold(h):g}) during burn-in (median escape time "
                f"{info['escape_time_median']}). No statistics."))
        stats = self._stats(h, est, info)
        return self._label(h, stats, est, esc, met, kd, harmonic_status)

    def _stats(self, h: Harvester, est: Estimate, info: dict[str, Any]) -> Stats:
        mean, se = est.mean, est.se
        tot = est.total_error
        eta_stat = propagated_eta_error(mean["eta"], mean["V2"], se["V2"], mean["Pin"], se["Pin"],
                                        est.cov_V2_Pin)
        info["eta_standard_error"] = eta_stat
        return Stats.from_moments(
            V2=mean["V2"], Pin=mean["Pin"], R=h.params.R, V2_err=tot("V2"), Pin_err=tot("Pin"),
            cov_V2_Pin=est.cov_V2_Pin, eta_err=math.hypot(eta_stat, est.bias["eta"]), v2=mean["v2"],
            v2_err=tot("v2"), vV=mean["vV"], vV_err=tot("vV"), x2=mean["x2"], x2_err=tot("x2"),
            method=self.name, info=info)

    def _label(self, h: Harvester, s: Stats, est: Estimate, esc: float, met: bool,
               kd: float | None, harmonic_status: str | None) -> Stats:
        rel = s.eta_err / abs(s.eta) if s.eta else math.inf
        fields = {f: getattr(s, f) for f in s.__dataclass_fields__}
        bias_rel = abs(est.bias["eta"] / s.eta) if s.eta else 0.0
        why = ("the time-step bias estimate dominates: lower dt" if bias_rel > self.tol
               else "the time budget max_time or max_replicas ran out: raise them")
        note = "" if met else (
            f" NOT CONVERGED: relative error on eta {rel:.2e} > tol {self.tol:g} after "
            f"{est.replicas} replicas; {why}.")
        if harmonic_status == "marginal":
            fields.update(status=Status.MARGINAL, x2=None, x2_err=None, message=(
                f"marginal: k = k_di = {kd:.10g}; x of the critical mode diffuses (x2 not reported); "
                "V2, Pin, eta are finite." + note))
        elif h.confinement == "metastable":
            fields.update(status=Status.METASTABLE, message=(
                f"metastable: n = {h.n:g} < 2 with k = {h.k:g} < 0 is unbounded below at large "
                f"amplitude. {esc:.2%} of paths escaped (|x| > {self.threshold(h):g}) within "
                f"t_burn + t_run = {s.info['t_burn'] + s.info['t_run']:g}; the numbers are "
                "quasi-stationary averages over the time before escape." + note))
        elif esc > 0.0:
            fields.update(status=Status.NOT_CONVERGED, message=(
                f"{esc:.2%} of paths escaped (|x| > {self.threshold(h):g}) although this system is "
                "confined: numerical instability or a too-low escape threshold; numbers are "
                "averages before escape. Lower dt or raise escape." + note))
        elif not met:
            fields.update(status=Status.NOT_CONVERGED, message=note.strip())
        else:
            fields.update(status=Status.STABLE, message=(
                f"stable; relative error on eta {rel:.2e} (standard error over {est.replicas} "
                "replicas and time-step bias estimate in quadrature)"))
        return Stats(**fields)

    def _info(self, h: Harvester, ens: Ensemble, est: Estimate, wall: float) -> dict[str, Any]:
        esc = ens.escape_times[np.isfinite(ens.escape_times)]
        info: dict[str, Any] = {
            "dt": ens.dts[0],
            "dt_coarse": ens.dts[1] if len(ens.dts) > 1 else None,
            "richardson": len(ens.dts) > 1,
            "paths": ens.paths,
            "replicas": ens.replicas,
            "replicas_valid": est.replicas,
            "t_burn": ens.t_burn,
            "t_run": ens.t_run,
            "path_steps": ens.path_steps,
            "path_steps_per_s": ens.path_steps / ens.wall_time if ens.wall_time > 0 else None,
            "wall_time": wall,
            "seed": ens.seed_entropy,
            "threads": ens.notes.get("threads"),
            "scheme": SCHEME_NAMES[scheme_kind(h)],
            "rng": _RNG,
            "bias_eta": est.bias["eta"],
            "bias_eta_se": est.bias_se["eta"],
            "bias_V2": est.bias["V2"],
            "bias_Pin": est.bias["Pin"],
            "escape_threshold": ens.threshold,
            "escape_fraction": ens.escaped_fraction(),
            "escaped_paths": int(esc.size),
            "escape_time_mean": float(esc.mean()) if esc.size else None,
            "escape_time_median": float(np.median(esc)) if esc.size else None,
            "escape_times": np.sort(esc)[:200].tolist(),
            "identity_V2_minus_KcTaup_vV": list(est.identity_V2),
            "identity_Pin_minus_mgamma_v2_minus_Kv_vV": list(est.identity_power),
            "confinement": h.confinement,
        }
        if scheme_kind(h) == 2:
            slow, crossings, snaps, exhausted = ens.kink_counters
            info.update(stuck_fraction=est.mean["stuck"], kink_slow_steps=slow, kink_crossings=crossings,
                        kink_snaps=snaps, kink_event_budget_exhausted=exhausted)
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in info.items()}
