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


# --- Measured figures come from records: a figure of a run (a wall time, a score, an agreement in px) stated in the
# prose must sit in a `<!-- gen:KEY -->` block filled from docs/results/ (palpation.report.docblocks); a figure with
# no record goes to docs/journal/ with a pointer left behind. A conservative heuristic: durations (s, min, ms, h),
# AUROC / AP / ECE / d̄ with a decimal, "agree ... N.NN px", a change "N → M" ending in %, px, mm, MPa or kPa, and a
# decimal or approximate (~N) px / mm / MPa / kPa on a line that reads as a result (before, after, now, got, reached,
# measured, gave, sits, against, →). Other percentages and mm are not checked (settings and SPEC facts use them
# throughout); scientific notation (dt = 1e-5 s) is a setting and is not matched.
DURATION = re.compile(r"(?<![\w.\-−/^])\d+(?:[.,]\d+)?(?:\s*[-–]\s*\d+(?:\.\d+)?)?\s?"
                      r"(?:s|ms|min|minutes?|seconds?|h|hours?)\b(?![/\w])")
SCORE = re.compile(r"\b(?:AUROC|AP|ECE|d̄)\s*[=:≈]?\s*\d*\.\d+")
AGREEMENT = re.compile(r"\bagree(?:s|d|ment)?\b[^.;()\n]{0,40}?(?<![\w.\-])~?\d*\.?\d+\s*px")
UNITS = r"(?:px|mm|MPa|kPa)"
CHANGE = re.compile(rf"(?<![\w.])~?\d+(?:\.\d+)?\s*(?:%|{UNITS})?\s*→\s*~?\d+(?:\.\d+)?\s*(?:%|{UNITS})(?!\w)")
RESULT_CUE = re.compile(r"\b(?:before|after|now|got|reached|measured|gave|gives|sits?|against)\b|→", re.I)
RESULT_FIGURE = re.compile(rf"(?<![\w.\-−/])(?:~\d+(?:\.\d+)?|\d+\.\d+)\s?{UNITS}(?!\w)")  # on a RESULT_CUE line
GEN_BLOCK = re.compile(r"<!-- gen:[\w.\-]+ -->.*?<!-- /gen -->", re.S)
# Typed figures that are no run's result, each with why (doc name, the exact text; the rest of its line is checked).
SETTINGS = {
    ("README.md", "well under 15 min on 2 cores"): "the test suite's time budget, a rule",
    ("DEVELOPING.md", "well under 15 min on 2 CPU cores"): "the same budget",
    ("recipe.md", "within 20 min"): "the quick profile's time budget",
    ("recipe.md", "`make reproduce`'s 20 minutes"): "the same budget",
    ("README.md", "(~80 s; workflow tests)"): "a command's rough duration, what to expect when running it",
    ("DEVELOPING.md", "~80 s on a quiet"): "the same, for the tiny profile",
    ("DEVELOPING.md", "(marker `workflow`, ~3 min)"): "a test's rough duration",
    ("DEVELOPING.md", "(~10 s)"): "a test's rough duration",
    ("DEVELOPING.md", "(~1 min on 2 cores)"): "a test folder's rough duration",
    ("loop.md", "a GP proposal costs ~0.5 s of CPU"): "an order of magnitude behind a design choice",
    ("DEVELOPING.md", "within 2000 frames of 0.5 s; a frame time far above the reference 0.00124 s"):
        "an error message quoted verbatim (a configured frame time, the reference's frame time)",
    ("calibration.md", "replays agree to ~0.04 px, quirk 26"): "SPEC's quirk 26, a fact of the reference",
    ("loop.md", "sits within ~2 px of a sensor that never deforms (SPEC quirk 2)"): "SPEC's quirk 2, the reference's",
    ("loop.md", "`shell_thickness_mm` (1.5 mm)"): "a config default (the table's other column reads 'ratio 1 → 2')",
    ("loop.md", "(SPEC §13.2's 0.2 px)"): "SPEC's detector noise, a fact of the reference",
    ("measured_format.md", "SPEC §13.6: radius ~2 mm"): "SPEC's vessel radius, a fact of the reference",
    ("twin.md", "(3.2 mm deep, then held)"): "the press's depth, a setting of the run described",
    ("twin.md", "123 steps = 1.23 ms"): "the frame length a setting implies",
    ("twin.md", "within the aim of 0.01 px"): "an aim, not a result",
    ("loop.md", "the earlier quick loop's 196.6 s"): "an aim (no slower than the quick loop it replaced), not a result",
    ("loop.md", "against the paper profile's aim of ≤ 60 s"): "an aim, not a result",
    ("loop.md", "within the aim of ≤ 20 min"): "an aim, not a result",
}


def typed_figures(text: str, doc: str = "") -> list[str]:
    """Measured-looking figures of `text` outside gen blocks and outside `doc`'s SETTINGS, with line numbers."""
    text = GEN_BLOCK.sub(lambda m: "\n" * m.group(0).count("\n"), text)  # a block keeps its line breaks
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        for (name, allowed), _why in SETTINGS.items():
            if name == doc:
                line = line.replace(allowed, " ")
        found += [f"line {number}: {m.group(0)!r}" for pattern in (DURATION, SCORE, AGREEMENT, CHANGE)
                  for m in pattern.finditer(line)]
        if RESULT_CUE.search(line):  # a figure already inside a found change is not counted twice
            changes = [m.span() for m in CHANGE.finditer(line)]
            found += [f"line {number}: {m.group(0)!r}" for m in RESULT_FIGURE.finditer(line)
                      if not any(a <= m.start() < b for a, b in changes)]
    return found


def test_typed_figures_are_found_and_settings_are_not():
    text = ("The loop took 123 s on an H200, 851 s on two cores (aim 196.6 s); a step 106-122 → 60-61 ms.\n"
            "Val AUROC 0.741, AP 0.32, d̄ 2.1; CPU and CUDA agree to 0.0018 px; took about 40 min, 3 minutes.\n"
            "dt = 1e-5 s, 1.24e-6 s, 10 µs, 0.2 px noise, 30 %, 127 markers, 4.59 mm, `ap` 0.5, 2 GiB, 25×.\n"
            "The loop adds <!-- gen:loop.effects -->12.3 s, AUROC 0.5<!-- /gen --> and a GP proposal costs ~0.5 s "
            "of CPU.\n")
    assert typed_figures(text) == ["line 1: '123 s'", "line 1: '851 s'", "line 1: '196.6 s'",
                                   "line 1: '60-61 ms'", "line 2: '40 min'", "line 2: '3 minutes'",
                                   "line 2: 'AUROC 0.741'", "line 2: 'AP 0.32'", "line 2: 'd̄ 2.1'",
                                   "line 2: 'agree to 0.0018 px'", "line 4: '0.5 s'"]
    assert typed_figures(text, "loop.md")[-1] == "line 2: 'agree to 0.0018 px'"  # the allowed phrase, in its doc


def test_typed_changes_and_result_figures_are_found_and_settings_are_not():
    text = ("The fix took the marker MAE 6.46 px → 1.40 px and the exact rate 72 → 84 %.\n"
            "A glint drags the centre (~6 px before, < 1 px now); a static offset (~13 px against ~1.5 px of motion).\n"
            "Stability: E·ratio below ~4.5 MPa, a 1.5 mm shell, 4 mm bins, ratio 1 to 2, 0.2 px noise, radius ~2 mm.\n"
            "It <!-- gen:twin.binding -->sits 6.46 px<!-- /gen --> off; the E sweep measured 13.87 MPa.\n")
    assert typed_figures(text) == ["line 1: '6.46 px → 1.40 px'", "line 1: '72 → 84 %'", "line 2: '~6 px'",
                                   "line 2: '~13 px'", "line 2: '~1.5 px'", "line 4: '13.87 MPa'"]


def test_a_typed_marker_change_in_a_doc_is_caught(tmp_path):
    loop = (REPO_ROOT / "docs" / "loop.md").read_text()
    edited = loop.replace("## Limitations", "The anchor took the MAE 6.46 px → 1.40 px.\n\n## Limitations", 1)
    assert [f.split(": ", 1)[1] for f in typed_figures(edited, "loop.md")] == ["'6.46 px → 1.40 px'"]


def test_a_typed_wall_time_in_a_doc_is_caught(tmp_path):
    loop = (REPO_ROOT / "docs" / "loop.md").read_text()
    assert typed_figures(loop, "loop.md") == []
    edited = tmp_path / "loop.md"
    edited.write_text(loop.replace("## Limitations", "The quick loop took 123 s.\n\n## Limitations", 1))
    assert [f.split(": ", 1)[1] for f in typed_figures(edited.read_text(), "loop.md")] == ["'123 s'"]


def test_every_allowed_setting_is_still_in_its_doc():
    texts = {p.name: p.read_text() for p in prose_docs()}
    gone = [f"{doc}: {text!r}" for doc, text in SETTINGS if text not in texts.get(doc, "")]
    assert not gone, "allow-list entries no document states any more (remove them from SETTINGS):\n" + "\n".join(gone)


@pytest.mark.parametrize("doc", [str(p.relative_to(REPO_ROOT)) for p in prose_docs()])
def test_doc_states_no_typed_measured_figure(doc):
    path = REPO_ROOT / doc
    figures = typed_figures(path.read_text(), path.name)
    assert not figures, (f"{doc} types measured-looking figures outside `<!-- gen:KEY -->` blocks ({len(figures)}): "
                         "generate each from its record under docs/results/ (palpation.report.docnumbers), or move "
                         "the sentence to docs/journal/ and leave a pointer; a setting or definition goes in "
                         "SETTINGS with why:\n" + "\n".join(figures[:20]))
