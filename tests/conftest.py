"""Shared test set-up: strict floating point, headless plots, seeded rng, fuzz profiles, and
one test process per CPU (pytest-xdist)."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

import montecarlo  # noqa: F401  (its import serializes numba's cache saves: the workers compile at once)
from fpe_harvester.parallel import default_threads

matplotlib.use("Agg")


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto`` (pyproject's addopts): one test process per CPU this process may use, the
    solvers' own count (xdist's own default counts physical cores: it can be one on a two-vCPU runner)."""
    return default_threads()


@pytest.fixture(autouse=True)
def _strict_floats():
    old = np.seterr(all="raise", under="ignore")
    yield
    np.seterr(**old)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20171122)


# Property-based (fuzz) tests: a test that takes the ``fuzz`` fixture runs twice, under the
# hypothesis profile "ci" (its own small number of fixed examples: seconds, reproducible) and
# under "long" (many random examples, marked slow: ``pytest -m slow``).
settings.register_profile("ci", deadline=None, derandomize=True, database=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
settings.register_profile("long", deadline=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "fuzz_profile" in metafunc.fixturenames:
        metafunc.parametrize("fuzz_profile", [pytest.param("ci", id="ci"),
                                              pytest.param("long", id="long", marks=pytest.mark.slow)])


@pytest.fixture
def fuzz(fuzz_profile: str):
    """``fuzz(prop, {"ci": n_ci, "long": n_long}, **strategies)``: run ``prop`` under hypothesis."""

    def run(prop, examples: dict[str, int], **strategies) -> None:
        chosen = settings(settings.get_profile(fuzz_profile), max_examples=examples[fuzz_profile])
        chosen(given(**strategies)(prop))()

    return run
