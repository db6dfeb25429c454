"""The project's reference table (validation.references.reftable): complete, and a regression anchor that can fail."""

from __future__ import annotations

import dataclasses

from fpe_harvester import Harvester, solve
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
