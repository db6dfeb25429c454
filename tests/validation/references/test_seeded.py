"""The seeded results hold: every case of ``validation.references.seeded`` recomputed and compared
with the committed file (Monte Carlo bit for bit, Fokker--Planck to 1e-10 relative). A deliberate
change of results rewrites the file: ``python -m validation.references.seeded --write``."""

from __future__ import annotations

import copy

import pytest

from validation.references import seeded

RECORDED = seeded.load()


def test_every_case_is_recorded():
    assert [c.label for c in seeded.CASES] == list(RECORDED)


@pytest.mark.parametrize("case", seeded.CASES, ids=[c.label for c in seeded.CASES])
def test_seeded_result_unchanged(case):
    recorded = RECORDED[case.label]
    assert recorded["options"] == case.options and recorded["system"] == case.system, (
        "the case's settings changed: rewrite with python -m validation.references.seeded --write")
    problems = seeded.compare(recorded, seeded.compute(case))
    assert not problems, "\n".join(problems)


def test_compare_sees_one_changed_bit():
    mc = next(iter(v for v in RECORDED.values() if v["method"] == "mc"))
    changed = copy.deepcopy(mc)
    eta = float.fromhex(mc["numbers"]["eta"])
    changed["numbers"]["eta"] = (eta + eta * 2.0**-52).hex()
    assert seeded.compare(mc, mc) == []
    assert any("eta" in p for p in seeded.compare(mc, changed))


def test_compare_fpe_to_relative_tolerance():
    fpe = next(iter(v for v in RECORDED.values() if v["method"] == "fpe"))
    near, far = copy.deepcopy(fpe), copy.deepcopy(fpe)
    near["numbers"]["V2"] *= 1 + 1e-12
    far["numbers"]["V2"] *= 1 + 1e-8
    assert seeded.compare(fpe, near) == []
    assert any("V2" in p for p in seeded.compare(fpe, far))
