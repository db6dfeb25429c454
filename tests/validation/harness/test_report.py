"""The report writer: Markdown with linked figures, self-contained HTML, terminal summary."""

from __future__ import annotations

import base64

import pytest

from validation.harness.checks import Outcome, agree, expect, finding, recorded, skipped
from validation.harness.report import Figure, Report, Section, Table, slowest_checks, summary_text, write_html, write_markdown


@pytest.fixture
def report(tmp_path):
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1])
    png = tmp_path / "fig.png"
    fig.savefig(png)
    plt.close(fig)
    sec = Section("one", "First section", text=["Some `code` and **bold** text."])
    sec.tables.append(Table("numbers", ("a", "b|c"), [("1", "2")], note="a note"))
    sec.figures.append(Figure(png, "a line"))
    sec.checks += [agree("close", "First section", 1.0, 0.1, 1.1, 0.0),
                   expect("wrong", "First section", False, "must fail"),
                   skipped("later", "First section", "solver not available"),
                   finding("paper off", "First section", "a second solver confirms ours", 0.61, 0.609),
                   recorded("old data holds", "First section", True, "2 decades",
                            source="validation/data/x.json", command="python -m validation.studies.x")]
    return Report("Tiny report", [sec], {"mode": "test"})


def test_counts_and_failure(report):
    assert report.counts() == {"PASS": 1, "FAIL": 1, "SKIP": 1, "FINDING": 1, "RECORDED": 1}
    assert [c.name for c in report.findings] == ["paper off"]
    assert [c.name for c in report.recorded] == ["old data holds"]
    assert report.failed


def test_markdown(report, tmp_path):
    text = write_markdown(report, tmp_path / "report.md").read_text()
    assert "# Tiny report" in text
    assert "**1 passed, 1 recorded, 1 finding, 1 failed, 1 skipped**" in text
    assert "### Findings" in text and "| FINDING | paper off |" in text
    assert "### Recorded checks" in text and "validation/data/x.json, written by python -m validation.studies.x" in text
    assert "| First section | 1 | 1 | 1 | 1 | 1 |" in text
    assert "![a line](fig.png)" in text
    assert "| a | b\\|c |" in text
    assert "| FAIL | wrong | must fail |" in text


def test_html_is_self_contained(report, tmp_path):
    page = write_html(report, tmp_path / "report.html").read_text()
    png = (tmp_path / "fig.png").read_bytes()
    assert "data:image/png;base64," + base64.b64encode(png).decode() in page
    assert "src='fig.png'" not in page and 'src="fig.png"' not in page
    assert "<code>code</code>" in page and "<b>bold</b>" in page
    assert "class=\"fail\"" in page and "class=\"skip\"" in page and "class=\"finding\"" in page
    assert "class=\"recorded\"" in page
    assert "1 passed, 1 recorded, 1 finding, 1 failed, 1 skipped" in page


def test_summary_lists_failures_first_and_flags_skips(report):
    text = summary_text(report)
    assert text.splitlines()[2].startswith("First section")
    kinds = ("PASS", "FAIL", "SKIP", "FINDING", "RECORDED")
    results = [ln.split()[0] for ln in text.splitlines() if ln.split()[:1] and ln.split()[0] in kinds]
    assert results == ["FAIL", "SKIP", "FINDING", "RECORDED"]
    full = [ln.split()[0] for ln in summary_text(report, show_passed=True).splitlines()
            if ln.split()[:1] and ln.split()[0] in kinds]
    assert full == ["FAIL", "SKIP", "FINDING", "RECORDED", "PASS"]
    assert "1 passed, 1 recorded, 1 finding, 1 failed, 1 skipped" in text
    assert "NOT passes" in text and "not passes of this run" in text
    rec = next(ln for ln in text.splitlines() if ln.startswith("RECORDED"))
    assert "validation/data/x.json, written by python -m validation.studies.x" in rec


def test_table_rejects_ragged_rows():
    with pytest.raises(ValueError, match="cells"):
        Table("t", ("a", "b"), [("1",)])


def test_outcome_values():
    assert [o.value for o in Outcome] == ["PASS", "RECORDED", "FINDING", "FAIL", "SKIP"]


def test_findings_alone_do_not_fail_the_run_and_are_not_read_as_failures():
    """A run with a finding exits 0; its last count line names no failure a test-log reader
    looking for "N failed" could pick up."""
    import re

    from validation.harness.runner import exit_code

    sec = Section("s", "S", checks=[agree("ok", "S", 1.0, 0.1, 1.0, 0.0), finding("off", "S", "confirmed")])
    rep = Report("r", [sec])
    assert exit_code(rep, quick=True) == 0 and exit_code(rep, quick=False) == 0
    line = next(ln for ln in reversed(summary_text(rep).splitlines()) if "passed" in ln)
    assert line == "1 passed, 0 recorded, 1 finding, 0 failed, 0 skipped"
    assert [int(m) for m in re.findall(r"(\d+) failed", line)] == [0]


def test_summary_names_the_slowest_computations_once_each():
    """Checks of one computation share its time (guarded divides it equally) and count once with
    the whole time; the slowest come first."""
    from dataclasses import replace

    rep = Report("timing")
    sec = Section("s", "S")
    sec.checks += [replace(expect(f"fast {i}", "S", True, "ok"), seconds=0.1 * (i + 1)) for i in range(3)]
    sec.checks += [replace(expect(f"slow: {q}", "S", True, "ok"), seconds=42.0) for q in ("eta", "V2", "Pin")]
    sec.checks.append(replace(expect("single", "S", True, "ok"), seconds=100.0))
    sec.checks.append(expect("untimed", "S", True, "ok"))
    rep.sections.append(sec)
    lines = slowest_checks(rep, k=3)
    assert "3 of 5" in lines[1]
    assert lines[3].split() == ["126.0", "slow:", "eta", "(+2", "more", "checks)"]
    assert lines[4].split() == ["100.0", "single"]
    assert lines[5].split()[:2] == ["0.3", "fast"]
    assert "slowest computations" in summary_text(rep)


def test_recorded_checks_are_counted_apart_and_do_not_fail_the_run_but_a_broken_record_does():
    """A check on committed data is RECORDED when its data holds (not a pass; the run still exits
    0), FAIL when it does not; it must name its file and the command that writes it again."""
    from validation.harness.runner import exit_code

    ok = recorded("old", "S", True, "fine", source="validation/data/a.json", command="python -m a")
    bad = recorded("old", "S", False, "broken", source="validation/data/a.json", command="python -m a")
    assert ok.outcome is Outcome.RECORDED and not ok.passed and ok.source == "validation/data/a.json"
    assert bad.outcome is Outcome.FAIL and "written by python -m a" in bad.detail
    assert exit_code(Report("r", [Section("s", "S", checks=[ok])]), quick=False) == 0
    assert exit_code(Report("r", [Section("s", "S", checks=[ok, bad])]), quick=False) == 1
    with pytest.raises(ValueError, match="command"):
        recorded("x", "S", True, "d", source="a.json", command="")
