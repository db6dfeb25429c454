"""Shared test set-up: strict floating point, headless plots, seeded rng, fuzz profiles, and
numba's on-disk cache made safe for the parallel test workers."""

from __future__ import annotations

import fcntl
import functools
import os

import matplotlib
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from numba.core.caching import IndexDataCacheFile

from fpe_harvester.parallel import default_threads

matplotlib.use("Agg")


def _one_writer_at_a_time(save):  # noqa: ANN001, ANN202
    """``IndexDataCacheFile.save`` under an exclusive lock on the cache folder.

    The suite runs in two processes (pytest-xdist) that compile the same kernels at the same
    time on a cold cache. numba's ``save`` reads a function's index, takes the first free data
    file number, writes the index, then the data file, all unlocked: two processes saving two
    variants of one function (``montecarlo``'s step kinds share a function name) can both take
    number 1, and the index can end up naming the other variant's machine code, which every
    later process would load. Holding a lock on the folder from the read to the last write
    makes the two saves one after the other. A load needs no lock (it finds the data file of
    an entry or compiles again).
    """

    @functools.wraps(save)
    def locked(self: IndexDataCacheFile, key: object, data: object) -> None:
        folder = os.open(self._cache_path, os.O_RDONLY)
        try:
            fcntl.flock(folder, fcntl.LOCK_EX)
            save(self, key, data)
        finally:
            os.close(folder)  # closing releases the lock

    return locked


IndexDataCacheFile.save = _one_writer_at_a_time(IndexDataCacheFile.save)


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
