"""The exact-flow construction's bias bounds (validation.studies.kink.exactflow_bias): a bias fitted to
all paired differences at once, bounded by it plus two of its standard errors."""

from __future__ import annotations

import numpy as np
import pytest

from validation.studies.kink.exactflow_bias import bounds


def _res(n: float, settings: list[tuple[float, float]], bias, noise: float, paths: int = 400, seed: int = 1):
    """A coupled run's shape: per-path estimates of every variant = truth + bias(setting) + a common
    path effect + a small independent part (the paired differences see only the latter)."""
    rng = np.random.default_rng(seed)
    common = rng.normal(size=(paths, 1))
    per_path = {}
    for q in ("eta", "V2", "Pin", "v2", "vV"):
        b = np.array([bias(h, w) for h, w in settings])
        per_path[q] = 1.0 + b + 0.05 * common + noise * rng.normal(size=(paths, len(settings)))
    variants = [{"step": h, "w_trap": w, "estimates": {q: (1.0, 0.01) for q in per_path}} for h, w in settings]
    return {"system": {"a": 2.0, "n": n}, "variants": variants, "per_path": per_path}


SETTINGS = [(0.0025, 0.001), (0.005, 0.001), (0.01, 0.001), (0.02, 0.001), (0.01, 0.003), (0.01, 0.01)]


def test_a_bias_linear_in_the_knobs_is_recovered_and_bounded():
    res = _res(1.0, SETTINGS, lambda h, w: 0.5 * h + 2.0 * w, noise=1e-4)
    rows = bounds(res)
    prod = next(r for r in rows if r["step"] == 0.01 and r["w_trap"] == 0.003)
    true = 0.5 * 0.01 + 2.0 * 0.003
    assert prod["model"]["eta"]["bias"] == pytest.approx(true, rel=0.05)
    assert true <= prod["relative_bias_bound"]["eta"] <= true + 0.002
    # the finest variant's own bias counts too: the model extrapolates to zero knobs
    assert rows[0]["relative_bias_bound"]["eta"] >= 0.5 * 0.0025 + 2.0 * 0.001


def test_no_bias_gives_a_bound_of_the_statistical_resolution_and_a_misfit_inflates_it():
    flat = bounds(_res(1.0, SETTINGS, lambda h, w: 0.0, noise=1e-3))
    prod = next(r for r in flat if r["step"] == 0.01 and r["w_trap"] == 0.003)
    assert 0.0 < prod["relative_bias_bound"]["eta"] < 0.005
    # a bias the model cannot follow (a jump): chi^2/dof > 1 widens the bound
    jump = bounds(_res(1.0, SETTINGS, lambda h, w: 0.01 if h > 0.015 else 0.0, noise=1e-3))
    fit = jump[0]["model"]["eta"]
    assert fit["chi2"] > 3 * fit["dof"]
    prod_jump = next(r for r in jump if r["step"] == 0.01 and r["w_trap"] == 0.003)
    assert prod_jump["relative_bias_bound"]["eta"] > prod["relative_bias_bound"]["eta"]


def test_beyond_the_kink_the_model_is_quadratic_in_the_step():
    settings = [(0.0025, 0.0), (0.005, 0.0), (0.01, 0.0), (0.02, 0.0), (0.04, 0.0)]
    rows = bounds(_res(1.25, settings, lambda h, w: 3.0 * h * h, noise=1e-6))
    assert rows[3]["model"]["V2"]["bias"] == pytest.approx(3.0 * 0.02**2, rel=0.02)
