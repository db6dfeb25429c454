"""The report writer: Markdown with linked figures, self-contained HTML, terminal summary."""

from __future__ import annotations

import base64

import pytest

from validation.harness.checks import Outcome, agree, expect, skipped
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
                   skipped("later", "First section", "solver not available")]
    return Report("Tiny report", [sec], {"mode": "test"})


def test_counts_and_failure(report):
    assert report.counts() == {"PASS": 1, "FAIL": 1, "SKIP": 1}
    assert report.failed


def test_markdown(report, tmp_path):
    text = write_markdown(report, tmp_path / "report.md").read_text()
    assert "# Tiny report" in text
    assert "**1 passed, 1 failed, 1 skipped**" in text
    assert "![a line](fig.png)" in text
    assert "| a | b\\|c |" in text
    assert "| FAIL | wrong | must fail |" in text


def test_html_is_self_contained(report, tmp_path):
    page = write_html(report, tmp_path / "report.html").read_text()
    png = (tmp_path / "fig.png").read_bytes()
    assert "data:image/png;base64," + base64.b64encode(png).decode() in page
    assert "src='fig.png'" not in page and 'src="fig.png"' not in page
    assert "<code>code</code>" in page and "<b>bold</b>" in page
    assert "class=\"fail\"" in page and "class=\"skip\"" in page


def test_summary_lists_failures_first_and_flags_skips(report):
    text = summary_text(report)
    assert text.splitlines()[2].startswith("First section")
    results = [ln.split()[0] for ln in text.splitlines() if ln[:6].strip() in ("PASS", "FAIL", "SKIP")]
    assert results == ["FAIL", "SKIP"]
    full = [ln.split()[0] for ln in summary_text(report, show_passed=True).splitlines() if ln[:6].strip() in
            ("PASS", "FAIL", "SKIP")]
    assert full == ["FAIL", "SKIP", "PASS"]
    assert "1 passed, 1 failed, 1 skipped" in text
    assert "NOT passes" in text


def test_table_rejects_ragged_rows():
    with pytest.raises(ValueError, match="cells"):
        Table("t", ("a", "b"), [("1",)])


def test_outcome_values():
    assert [o.value for o in Outcome] == ["PASS", "FAIL", "SKIP"]


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
