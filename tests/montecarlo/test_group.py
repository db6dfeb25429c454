"""Several replicas per task (``simulate(..., group=G)``): the same paths as one replica of G times
the paths on the same stream, every sum kept per replica."""

from __future__ import annotations

import numpy as np
import pytest

from fpe_harvester import Harvester
from fpe_harvester.errors import ParameterError
from montecarlo import simulate


@pytest.mark.parametrize("system, kw", [
    # the kink with every accumulated control and the coupled coarse level
    ({"a": 2.0, "n": 1.0}, {"controls": ("martingale", "boundary", "generator"), "richardson": True}),
    # a ring with its twin and the coarsest level, martingale sums across units
    ({"a": 0.5, "n": 3.0, "N": 3, "k": -0.5}, {"controls": ("martingale", "boundary"), "richardson": True, "third_level": True,
                                               "twin": 4.0}),
    # the joint step (its own v xi estimate)
    ({"a": 0.5, "n": 3.0, "tau": 1e-4}, {"controls": ("martingale", "boundary"), "step": "joint"}),
])
def test_a_task_of_g_replicas_splits_the_sums_of_one_replica_of_g_paths(system: dict, kw: dict) -> None:
    # task (replica 0, chunk 0) draws the same normals whether it holds one replica of 6 paths or
    # 6 replicas of one path: the replicas' sums add up to the single replica's
    h = Harvester.build(**system)
    common = dict(dt=0.02, t_burn=2.0, t_run=10.0, seed=3, generator_every=0.04, **kw)
    one = simulate(h, paths=6, replicas=1, **common)
    six = simulate(h, paths=1, replicas=6, group=6, **common)
    assert six.sums.shape[0] == 6 and six.notes["replicas_per_task"] == 6
    np.testing.assert_allclose(six.sums.sum(axis=0), one.sums[0], rtol=1e-12, atol=1e-12 * np.abs(one.sums).max())
    np.testing.assert_array_equal(six.counts.sum(axis=0), one.counts[0])
    np.testing.assert_array_equal(six.escape_times.ravel(), one.escape_times.ravel())
    assert six.path_steps == one.path_steps
    if one.ctl is not None:
        np.testing.assert_allclose(six.ctl.sum(axis=0), one.ctl[0], rtol=1e-12, atol=1e-12 * np.abs(one.ctl).max())
    # the replicas differ (each its own path)
    assert np.unique(six.sums[:, 0, 0]).size == 6


def test_a_partial_last_task_and_continued_runs() -> None:
    # 5 replicas in tasks of 2: the last task holds one; a continued run draws new streams
    h = Harvester.build(a=0.5, n=3.0)
    common = dict(dt=0.05, paths=2, t_burn=1.0, t_run=5.0, seed=4, group=2)
    e = simulate(h, replicas=5, **common)
    assert e.sums.shape[0] == 5 and np.all(e.counts[:, 0] == 2 * 100)
    more = simulate(h, replicas=2, first_replica=5, **common)
    assert not np.isin(more.sums[:, 0, 0], e.sums[:, 0, 0]).any()


def test_group_needs_whole_replicas_per_task() -> None:
    h = Harvester.build(a=0.5, n=3.0)
    with pytest.raises(ParameterError, match=r"group > 1 needs whole replicas per task: paths \(8\) <= chunk \(4\)"):
        simulate(h, dt=0.05, paths=8, chunk=4, group=2, replicas=2, t_run=1.0)
    with pytest.raises(ParameterError, match="group"):
        simulate(h, dt=0.05, paths=2, group=0, replicas=2, t_run=1.0)
