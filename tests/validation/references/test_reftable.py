"""The project's reference table (validation.references.reftable): complete, and a regression anchor that can fail."""

from __future__ import annotations

import dataclasses

import pytest

from fpe_harvester import Harvester, Stats, Status, solve
from validation.references import reftable
from validation.references.reftable import CASES, compare, load


def test_every_case_has_an_entry_with_its_provenance() -> None:
    table = load()
    for case in CASES:
        entry = table[case.label]
        assert entry["eta_err"] is not None and entry["eta_err"] > 0, case.label
        for key in ("command", "commit", "date", "seconds", "method", "options", "system"):
            assert key in entry, (case.label, key)
        assert entry["system"] == case.system and entry["method"] == case.method


def test_a_fresh_solve_agrees_with_the_table_and_a_wrong_one_does_not() -> None:
    r = solve(Harvester.build(a=0.5, n=4.0), "fpe", tol=1e-6)
    checks = compare("fpe n = 4, a = 0.5", r)
    assert len(checks) == 3 and all(ok for _, ok, _ in checks), checks
    off = dataclasses.replace(r, eta=r.eta * (1 + 1e-4))
    assert not compare("fpe n = 4, a = 0.5", off)[0][1]
    assert not compare("no such case", r)[0][1]


#: Fokker--Planck entries cheap enough (recorded wall time [s]) for the normal suite; the others
#: are marked slow.
CHEAP_S = 20.0


def _fpe_params() -> list:
    table = load()
    return [pytest.param(c, id=c.label, marks=() if table[c.label]["seconds"] <= CHEAP_S else pytest.mark.slow)
            for c in CASES if c.method == "fpe"]


@pytest.mark.parametrize("case", _fpe_params())
def test_a_fokker_planck_entry_matches_a_fresh_solve_at_its_tolerance(case) -> None:
    """A change to the solver that moves a result by more than 4 combined errors (the entry's
    and the fresh one's) shows here: regenerate the entry (python -m validation.references.reftable
    --only LABEL) or fix the solver."""
    r = solve(case.h, case.method, **case.options)
    checks = compare(case.label, r)
    assert all(ok for _, ok, _ in checks), checks


def test_no_entry_is_stamped_with_an_uncommitted_tree() -> None:
    for label, entry in load().items():
        assert "+" not in entry["commit"] and entry["commit"] != "unknown", (label, entry["commit"])


def test_staleness_names_what_is_wrong() -> None:
    head = reftable._git("rev-parse", "--short", "HEAD")
    assert reftable.staleness(None, "fpe") == "missing"
    assert "not a commit" in reftable.staleness({"commit": "96b6666+changes"}, "mc")
    assert reftable.staleness({"commit": head}, "fpe") is None
    first = reftable._git("rev-list", "--max-parents=0", "HEAD").split()[0]
    assert "changed its solver's code before the seeded results" in reftable.staleness({"commit": first}, "mc")
    case = next(c for c in CASES if c.label == "mc n = 3, a = 0.5")
    entry = {"commit": head, "system": case.system, "status": "stable", "seconds": 6.0,
             "options": {**case.options, "max_time": 60.0}}
    assert reftable.staleness(entry, "mc", case) is None  # a guard it never met is no setting
    assert "settings" in reftable.staleness({**entry, "options": {**case.options, "seed": 1}}, "mc", case)
    assert "settings" in reftable.staleness({**entry, "status": "not_converged", "seconds": 100.0}, "mc", case)


def test_an_entry_goes_stale_when_its_solvers_seeded_results_change(monkeypatch) -> None:
    """Code that changes without changing results (the seeded results held bit for bit) leaves an
    entry current; a later commit that rewrote its solver's seeded results makes it stale, one that
    changed only the other solver's does not."""
    import json

    def seeded(mc_eta: str, fpe_eta: float) -> str:
        return json.dumps({"cases": [{"label": "a", "method": "mc", "numbers": {"eta": mc_eta}},
                                     {"label": "b", "method": "fpe", "numbers": {"eta": fpe_eta}}]})

    versions = {"c1^": seeded("0x1.0p-1", 0.5), "c1": seeded("0x1.0p-1", 0.6), "c2^": seeded("0x1.0p-1", 0.6),
                "c2": seeded("0x1.1p-1", 0.6)}

    def git(*args: str) -> str:
        if args[0] == "show":
            return versions[args[1].split(":")[0]]
        if args[0] == "log" and args[-1] == reftable.SEEDED and "--diff-filter=A" in args:
            return "c0"
        if args[0] == "log" and args[-1] == reftable.SEEDED:
            return "c2\nc1"
        return ""

    monkeypatch.setattr(reftable, "_git_read", git)
    assert reftable._seeded_changed("c1", "fpe") and not reftable._seeded_changed("c1", "mc")
    assert reftable._seeded_changed("c2", "mc") and not reftable._seeded_changed("c2", "fpe")
    assert "seeded mc results changed after it (c2)" in reftable.staleness({"commit": "c0"}, "mc")
    assert "seeded fpe results changed after it (c1)" in reftable.staleness({"commit": "c0"}, "fpe")
    assert reftable.stale_note({"commit": "c0"}, "mc").startswith("; STALE: the seeded mc results")


def test_the_command_refuses_an_uncommitted_tree(monkeypatch, capsys, tmp_path) -> None:
    real = reftable._git
    monkeypatch.setattr(reftable, "_git", lambda *a: " M montecarlo/solver.py" if a[0] == "status" else real(*a))
    monkeypatch.setattr(reftable, "solve", lambda *a, **k: pytest.fail("must not solve"))
    out = tmp_path / "table.json"
    assert reftable.main(["--only", "mc n = 3, a = 0.5", "--out", str(out)]) == 1
    assert "uncommitted changes" in capsys.readouterr().err and not out.exists()


def test_crosscheck_compares_a_system_with_every_entry_it_has() -> None:
    """n = 3, a = 0.5 has a Fokker-Planck and a Monte Carlo entry: a result is held to both."""
    from types import SimpleNamespace

    from validation.sections.crosscheck import table_checks

    h = Harvester.build(a=0.5, n=3.0)
    entry = load()["fpe n = 3, a = 0.5"]
    r = Stats(status=Status.STABLE, method="fpe", **{q: entry[q] for q in ("eta", "V2", "Pin")},
              **{q + "_err": entry[q + "_err"] for q in ("eta", "V2", "Pin")})
    ctx = SimpleNamespace(cache=SimpleNamespace(results=lambda: [(h, "fpe", r)]))
    names = [c.name for c in table_checks(ctx)]
    assert any("fpe n = 3, a = 0.5" in n for n in names) and any("mc n = 3, a = 0.5" in n for n in names)
    assert len(names) == 6


def test_the_report_marks_a_stale_entry_it_uses(monkeypatch) -> None:
    """Every comparison with a table entry, and every entry used as a reference, says STALE and why
    when the entry is stale (a current one says nothing)."""
    entry = load()["fpe n = 4, a = 0.5"]
    r = Stats(status=Status.STABLE, method="fpe", **{q: entry[q] for q in ("eta", "V2", "Pin")},
              **{q + "_err": entry[q + "_err"] for q in ("eta", "V2", "Pin")})
    monkeypatch.setattr(reftable, "staleness", lambda *a: None)
    assert all("STALE" not in d for _, _, d in compare("fpe n = 4, a = 0.5", r))
    monkeypatch.setattr(reftable, "staleness", lambda *a: "the seeded fpe results changed after it (abc1234)")
    assert all("; STALE: the seeded fpe results changed" in d for _, _, d in compare("fpe n = 4, a = 0.5", r))
    stats = reftable.as_stats({**entry, "label": "fpe n = 4, a = 0.5"})
    assert "STALE" in stats.message
    assert "STALE" in reftable.recorded_mc(Harvester.build(a=0.5, n=1)).message
