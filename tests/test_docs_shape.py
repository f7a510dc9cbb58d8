"""The README and docs describe the software as it is: short, and free of a run diary's marks.

History (commit hashes, issue numbers, the clock of a run) belongs in docs/journal/; the generated results
page (docs/results.md) and the records under docs/results/ say which commit made them and are exempt.
"""

import re
from pathlib import Path

import pytest

from palpation.paths import REPO_ROOT

README_MAX_LINES = 200
DOC_MAX_LINES = 400
GENERATED = {"results.md"}  # docs/results.md: written by rule results_page
# a commit hash: 7-40 hex characters with at least one digit and one letter (not a word like "defaced" or a count)
HASH = re.compile(r"\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b")
ISSUE = re.compile(r"\bissues? #?\d+", re.I)
UTC = re.compile(r"\b\d{1,2}:\d{2}(?::\d{2})?(?:\s*[–-]\s*\d{1,2}:\d{2}(?::\d{2})?)?\s*UTC\b")


def prose_docs() -> list[Path]:
    """README.md and docs/*.md but the generated page (docs/journal/ and docs/results/ are folders below)."""
    return [REPO_ROOT / "README.md", *(p for p in sorted((REPO_ROOT / "docs").glob("*.md")) if p.name not in GENERATED)]


def diary_marks(text: str) -> list[str]:
    """Each commit hash, issue number and UTC time of `text`, with its line number."""
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        found += [f"line {number}: {m.group(0)!r}" for pattern in (HASH, ISSUE, UTC) for m in pattern.finditer(line)]
    return found


def test_marks_are_found_and_ordinary_text_is_not():
    text = ("at 2d576bf and f8861de0c1; see issue 12 and Issue #7\nran 09:51–09:59 UTC, then 01:17 UTC\n"
            "a defaced facade, 1234567 frames, 0.7824 ± 0.0055, 8:59 of Snakemake, issue-free\n")
    assert diary_marks(text) == ["line 1: '2d576bf'", "line 1: 'f8861de0c1'", "line 1: 'issue 12'",
                                 "line 1: 'Issue #7'", "line 2: '09:51–09:59 UTC'", "line 2: '01:17 UTC'"]


def test_readme_is_short():
    lines = len((REPO_ROOT / "README.md").read_text().splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines (at most {README_MAX_LINES}); link to docs/"


@pytest.mark.parametrize("doc", [p.name for p in prose_docs() if p.parent.name == "docs"])
def test_doc_is_short(doc):
    lines = len((REPO_ROOT / "docs" / doc).read_text().splitlines())
    assert lines <= DOC_MAX_LINES, (f"docs/{doc} has {lines} lines (at most {DOC_MAX_LINES}): keep design and user "
                                    "guide, move the history of experiments to docs/journal/")


@pytest.mark.parametrize("doc", [str(p.relative_to(REPO_ROOT)) for p in prose_docs()])
def test_doc_has_no_diary_marks(doc):
    marks = diary_marks((REPO_ROOT / doc).read_text())
    assert not marks, (f"{doc} states commit hashes, issue numbers or UTC times ({len(marks)}; move the history to "
                       "docs/journal/):\n" + "\n".join(marks[:20]))
