"""The identities section (validation.sections.identities): the check on one result, and the
section over a run's results."""

from __future__ import annotations

from fpe_harvester import Harvester, Stats, solve
from fpe_harvester.result import Status
from validation.harness.checks import Context, Outcome, SolveCache
from validation.sections import identities
from validation.sections.identities import identity_checks


def test_identities_pass_on_exact_and_fail_on_a_wrong_result():
    h = Harvester.build(a=0.5, n=2, N=3, k=-0.25)
    r = solve(h, "exact")
    assert all(c.outcome is Outcome.PASS for c in identity_checks("h", r, h))
    bad = Stats.from_moments(V2=r.V2 * 1.01, Pin=r.Pin, R=1.0, V2_err=r.V2 * 1e-3, v2=r.v2, v2_err=0.0,
                             vV=r.vV, vV_err=0.0, method="mc")
    outcomes = [c.outcome for c in identity_checks("h", bad, h)]
    assert outcomes == [Outcome.FAIL, Outcome.PASS]
    lacking = Stats.from_moments(V2=r.V2, Pin=r.Pin, R=1.0, method="mc")
    assert [c.outcome for c in identity_checks("h", lacking, h)] == [Outcome.FAIL]


def test_the_section_checks_each_stationary_result_and_lists_the_rest(tmp_path):
    cache = SolveCache()
    stable = Harvester.build(a=0.5, n=2, N=3, k=-0.25)
    cache.solve(stable, "exact")
    unstable = Harvester.build(a=0.5, n=2, N=3, k=-5.0)
    assert cache.solve(unstable, "exact").status is Status.UNSTABLE
    sec = identities.run(Context(quick=True, out=tmp_path, cache=cache))
    checked = [c for c in sec.checks if c.outcome is Outcome.PASS]
    assert len(checked) == 2 and all(c.name.startswith("identities [exact] a=0.5, n=2, N=3, k=-0.25") for c in checked)
    assert any("exact at a=0.5, n=2, N=3, k=-5 (unstable)" in t for t in sec.text)
    assert [c.name for c in sec.checks if c.outcome is Outcome.SKIP] == ["identities [fpe]", "identities [mc]"]
    assert [row[:3] for row in sec.tables[0].rows] == [(identities.describe(stable), "exact", "stable"),
                                                       (identities.describe(unstable), "exact", "unstable")]
