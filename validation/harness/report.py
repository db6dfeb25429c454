"""The validation report: sections of text, tables, figures and checks, written as
Markdown (figures linked) and as one self-contained HTML page (figures embedded as
base64 PNG), plus the plain-text pass/fail summary printed on the terminal.
"""

from __future__ import annotations

import base64
import html
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .checks import CheckResult, Outcome

__all__ = ["Table", "Figure", "Section", "Report", "write_markdown", "write_html", "summary_text", "slowest_checks",
           "count_line"]

#: Outcomes in the order the summaries count them.
_ORDER = (Outcome.PASS, Outcome.RECORDED, Outcome.FINDING, Outcome.FAIL, Outcome.SKIP)


@dataclass
class Table:
    """A table of strings: ``header`` names the columns, each row has one cell per column."""

    title: str
    header: Sequence[str]
    rows: list[Sequence[str]] = field(default_factory=list)
    note: str = ""

    def __post_init__(self) -> None:
        for row in self.rows:
            if len(row) != len(self.header):
                raise ValueError(f"table {self.title!r}: row {row!r} has {len(row)} cells, "
                                 f"header has {len(self.header)}")


@dataclass
class Figure:
    """A PNG file (absolute path) and its caption."""

    path: Path
    caption: str


@dataclass
class Section:
    """One part of the report; filled in by a validation step.

    ``text`` holds Markdown paragraphs (inline code in backticks and ``**bold**`` are the only
    markup the HTML writer translates).
    """

    key: str
    title: str
    text: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    figures: list[Figure] = field(default_factory=list)
    checks: list[CheckResult] = field(default_factory=list)
    seconds: float = 0.0
    #: Processor time [s] of the step (all threads of this process and its finished child
    #: processes); above ``seconds`` when the step ran on several cores.
    cpu_seconds: float = 0.0


@dataclass
class Report:
    """All sections of one validation run."""

    title: str
    sections: list[Section] = field(default_factory=list)
    meta: dict[str, str] = field(default_factory=dict)

    @property
    def checks(self) -> list[CheckResult]:
        return [c for s in self.sections for c in s.checks]

    def counts(self) -> Counter[str]:
        return Counter(c.outcome.value for c in self.checks)

    @property
    def failed(self) -> bool:
        """True if any check failed (skips are not failures here; see ``skipped``)."""
        return any(c.outcome is Outcome.FAIL for c in self.checks)

    @property
    def skipped(self) -> list[CheckResult]:
        """The checks that did not run (a full validation run fails on any)."""
        return [c for c in self.checks if c.outcome is Outcome.SKIP]

    @property
    def findings(self) -> list[CheckResult]:
        """Published values that a second solver shows to be off (not failures of ours)."""
        return [c for c in self.checks if c.outcome is Outcome.FINDING]

    @property
    def recorded(self) -> list[CheckResult]:
        """Checks whose verdict reads committed data only (not passes of this run)."""
        return [c for c in self.checks if c.outcome is Outcome.RECORDED]


def count_line(checks: Sequence[CheckResult]) -> str:
    """``"N passed, R recorded, F findings, M failed, S skipped"`` over ``checks``.

    Recorded checks and findings are named apart from passes and failures, in words a test-log
    reader that looks for ``"N failed"`` does not mistake for failures.

    Examples
    --------
    >>> from validation.harness.checks import CheckResult
    >>> count_line([CheckResult("a", "s", "PASS"), CheckResult("b", "s", "FINDING"), CheckResult("c", "s", "RECORDED")])
    '1 passed, 1 recorded, 1 finding, 0 failed, 0 skipped'
    """
    n = Counter(c.outcome for c in checks)
    f = n[Outcome.FINDING]
    return (f"{n[Outcome.PASS]} passed, {n[Outcome.RECORDED]} recorded, {f} finding{'' if f == 1 else 's'}, "
            f"{n[Outcome.FAIL]} failed, {n[Outcome.SKIP]} skipped")


def _section_rows(report: Report) -> list[tuple[str, ...]]:
    return [(s.title, *(str(sum(c.outcome is o for c in s.checks)) for o in _ORDER), f"{s.seconds:.1f}",
             f"{s.cpu_seconds:.1f}") for s in report.sections]


_SECTION_HEADER = ("section", "pass", "recorded", "finding", "fail", "skip", "time [s]", "CPU [s]")
_NOTE = ("passed: computed in this run; recorded: read from committed data (listed below with the command that "
         "writes it again), not a pass of this run; findings are published values that a second, independent "
         "solver shows to be off: not failures; skipped checks compared nothing: see the reason; they are not "
         "passes")


def new_figure(figsize: tuple[float, float] = (6, 4), ncols: int = 1, nrows: int = 1):
    """A matplotlib figure and its axes (``nrows`` x ``ncols``) drawn off-screen (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(nrows, ncols, figsize=figsize)


def save_figure(fig, path: Path, caption: str) -> Figure:
    """Write ``fig`` as PNG to ``path`` (110 dpi), close it, and return the report's :class:`Figure`."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Figure(path, caption)


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    def cell(s: str) -> str:
        return str(s).replace("|", "\\|").replace("\n", " ")

    out = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return out


def _check_rows(checks: Sequence[CheckResult]) -> list[tuple[str, str, str, str]]:
    return [(c.outcome.value, c.name, c.detail, f"{c.seconds:.2f}") for c in checks]


def _rel(path: Path, base: Path) -> str:
    try:
        return path.resolve().relative_to(base.resolve()).as_posix()
    except ValueError:
        return path.resolve().as_posix()


def write_markdown(report: Report, path: Path) -> Path:
    """Write ``report`` as Markdown to ``path``; figures are linked relative to its folder."""
    base = path.parent
    lines = [f"# {report.title}", ""]
    lines += [f"- {k}: {v}" for k, v in report.meta.items()]
    lines += ["", "## Summary", "", f"**{count_line(report.checks)}** ({_NOTE}).", ""]
    lines += _md_table(_SECTION_HEADER, _section_rows(report))
    for title, picked in _listed(report):
        lines += ["", f"### {title}", ""]
        lines += _md_table(("outcome", "check", "detail", "time [s]"), _check_rows(picked))
    for s in report.sections:
        lines += ["", f"## {s.title}", ""]
        for para in s.text:
            lines += [para, ""]
        for t in s.tables:
            lines += [f"**{t.title}**", ""] + _md_table(t.header, t.rows) + [""]
            if t.note:
                lines += [t.note, ""]
        for f in s.figures:
            lines += [f"![{f.caption}]({_rel(f.path, base)})", "", f"*{f.caption}*", ""]
        if s.checks:
            lines += ["**Checks**", ""] + _md_table(("outcome", "check", "detail", "time [s]"),
                                                     _check_rows(s.checks)) + [""]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _listed(report: Report) -> list[tuple[str, list[CheckResult]]]:
    """The summary's lists: findings, recorded checks, then failed and skipped checks (each only
    when not empty)."""
    bad = [c for c in report.checks if c.outcome in (Outcome.FAIL, Outcome.SKIP)]
    return [(title, picked) for title, picked in (
        ("Findings", report.findings),
        ("Recorded checks (committed data, not computed in this run)", report.recorded),
        ("Failed and skipped checks", bad)) if picked]


def _inline(text: str) -> str:
    s = html.escape(text)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)


def _html_table(header: Sequence[str], rows: Sequence[Sequence[str]], outcome_col: int | None = None) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = []
    for row in rows:
        cls = f' class="{str(row[outcome_col]).lower()}"' if outcome_col is not None else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{_inline(str(c))}</td>" for c in row) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


_CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;line-height:1.4}
table{border-collapse:collapse;margin:.5em 0 1em;font-size:.9em}td,th{border:1px solid #bbb;padding:3px 6px;
vertical-align:top}th{background:#eee}tr.pass td:first-child{background:#c8f0c8}
tr.fail td:first-child{background:#f5b5b5;font-weight:bold}tr.finding td:first-child{background:#b9d7f5}tr.skip td:first-child{background:#f7e3a1}
tr.recorded td:first-child{background:#e2e2e2}
img{max-width:100%;border:1px solid #ddd}figure{margin:1em 0}.summary{font-size:1.2em}
code{background:#f4f4f4;padding:0 2px}"""


def write_html(report: Report, path: Path) -> Path:
    """Write ``report`` as one self-contained HTML page (figures embedded as base64 PNG)."""
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(report.title)}"
             f"</title><style>{_CSS}</style></head><body><h1>{html.escape(report.title)}</h1><ul>"]
    parts += [f"<li>{html.escape(k)}: {html.escape(v)}</li>" for k, v in report.meta.items()]
    parts.append("</ul><h2>Summary</h2>")
    parts.append(f"<p class='summary'><b>{html.escape(count_line(report.checks))}</b> ({html.escape(_NOTE)})</p>")
    parts.append(_html_table(_SECTION_HEADER, _section_rows(report)))
    for title, picked in _listed(report):
        parts.append(f"<h3>{title}</h3>")
        parts.append(_html_table(("outcome", "check", "detail", "time [s]"), _check_rows(picked), 0))
    for s in report.sections:
        parts.append(f"<h2>{html.escape(s.title)}</h2>")
        parts += [f"<p>{_inline(p)}</p>" for p in s.text]
        for t in s.tables:
            parts.append(f"<h4>{html.escape(t.title)}</h4>" + _html_table(t.header, t.rows))
            if t.note:
                parts.append(f"<p>{_inline(t.note)}</p>")
        for f in s.figures:
            data = base64.b64encode(Path(f.path).read_bytes()).decode("ascii")
            parts.append(f"<figure><img alt='{html.escape(f.caption)}' src='data:image/png;base64,{data}'>"
                         f"<figcaption>{_inline(f.caption)}</figcaption></figure>")
        if s.checks:
            parts.append("<h4>Checks</h4>" + _html_table(("outcome", "check", "detail", "time [s]"),
                                                          _check_rows(s.checks), 0))
    parts.append("</body></html>")
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


#: How many of the slowest checks the terminal summary lists.
SLOWEST = 8


def slowest_checks(report: Report, k: int = SLOWEST) -> list[str]:
    """Lines naming the ``k`` slowest computations of the run (where the wall time goes).

    Checks made by one computation (for example eta, V2 and Pin of one cross-check) share its
    time equally (:func:`validation.harness.checks.guarded`); they count once, under the first check's
    name, with the computation's whole time and the number of checks made."""
    groups: dict[tuple[str, float], list[str]] = {}
    for c in report.checks:
        if c.seconds > 0.0:
            groups.setdefault((c.section, c.seconds), []).append(c.name)
    top = sorted(groups.items(), key=lambda kv: -kv[0][1] * len(kv[1]))[:k]
    if not top:
        return []
    lines = ["", f"slowest computations ({len(top)} of {len(groups)})", f"{'time [s]':>8}  check"]
    for (_, sec), names in top:
        more = f" (+{len(names) - 1} more checks)" if len(names) > 1 else ""
        lines.append(f"{sec * len(names):8.1f}  {names[0]}{more}")
    return lines


def summary_text(report: Report, width: int = 110, show_passed: bool = False) -> str:
    """Plain-text summary for the terminal.

    A table of pass/recorded/finding/fail/skip counts per section, then every failed, skipped,
    finding and recorded check (and, with ``show_passed``, every passed one), failures first, then
    the slowest computations (:func:`slowest_checks`), and last the counts (:func:`count_line`).
    """
    order = {Outcome.FAIL: 0, Outcome.SKIP: 1, Outcome.FINDING: 2, Outcome.RECORDED: 3, Outcome.PASS: 4}
    title_w = min(max([7, *(len(s.title) for s in report.sections)]), 50)
    lines = [f"{'section':{title_w}}  {'pass':>5} {'rec':>5} {'find':>5} {'fail':>5} {'skip':>5}  {'time [s]':>8}  "
             f"{'CPU [s]':>8}",
             f"{'-' * title_w}  {'-' * 5} {'-' * 5} {'-' * 5} {'-' * 5} {'-' * 5}  {'-' * 8}  {'-' * 8}"]
    for sec in report.sections:
        n = Counter(c.outcome for c in sec.checks)
        lines.append(f"{sec.title[:title_w]:{title_w}}  " + " ".join(f"{n[o]:5d}" for o in _ORDER)
                     + f"  {sec.seconds:8.1f}  {sec.cpu_seconds:8.1f}")
    checks = sorted((c for c in report.checks if show_passed or c.outcome is not Outcome.PASS),
                    key=lambda c: order[c.outcome])
    if checks:
        name_w = min(max([5, *(len(c.name) for c in checks)]), 60)
        room = max(width - name_w - 10, 20)
        lines += ["", f"{'result':8}  {'check':{name_w}}  detail", f"{'-' * 8}  {'-' * name_w}  {'-' * 20}"]
        for c in checks:
            # a recorded check shows where its data comes from, which a cut detail would lose
            text = f"{c.source}, written by {c.command}" if c.outcome is Outcome.RECORDED else c.detail
            detail = text if len(text) <= room else text[: room - 3] + "..."
            lines.append(f"{c.outcome.value:8}  {c.name[:name_w]:{name_w}}  {detail}")
    lines += slowest_checks(report)
    counts = report.counts()
    lines.append("")
    lines.append(count_line(report.checks))
    if counts.get("RECORDED", 0):
        lines.append("Recorded checks read committed data (file and command listed above): they hold for that data "
                     "and are not passes of this run.")
    if counts.get("FINDING", 0):
        lines.append("FINDINGS are published values that a second, independent solver shows to be off: listed "
                     "above, they are not failures.")
    if counts.get("SKIP", 0):
        lines.append("SKIPPED checks compared nothing (time budget, solver or module not available, or no number "
                     "to compare): they are NOT passes.")
    return "\n".join(lines)
