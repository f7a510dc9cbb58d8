"""The numbers in README.md and docs/*.md are their records' (report.docblocks, report.docnumbers)."""

import json
import re
import shutil
from pathlib import Path

import pandas as pd
import pytest

from palpation.paths import REPO_ROOT
from palpation.report import docblocks
from palpation.report.docnumbers import NUMBERS


def repo_copy(tmp_path: Path) -> Path:
    """README.md, docs/*.md and the records, in a temporary repository."""
    root = tmp_path / "repo"
    (root / "docs").mkdir(parents=True)
    shutil.copy(REPO_ROOT / "README.md", root / "README.md")
    for doc in (REPO_ROOT / "docs").glob("*.md"):
        shutil.copy(doc, root / "docs" / doc.name)
    shutil.copytree(REPO_ROOT / "docs" / "results", root / "docs" / "results")
    return root


def test_every_block_is_current():
    stale = docblocks.run(REPO_ROOT)
    assert not stale, "stale blocks (python -m palpation.report.docblocks write):\n" + "\n".join(map(str, stale))


def test_every_number_is_used_and_the_readme_states_the_headline():
    text = "\n".join(p.read_text() for p in docblocks.documents(REPO_ROOT))
    used = {m["key"] for m in docblocks.BLOCK.finditer(text)}
    assert set(NUMBERS) <= used, f"keys no document uses: {sorted(set(NUMBERS) - used)}"
    assert "<!-- gen:headline -->" in (REPO_ROOT / "README.md").read_text()


def test_a_changed_record_makes_its_blocks_stale_until_written(tmp_path):
    root = repo_copy(tmp_path)
    sweep = root / "docs" / "results" / "seed_sweep.csv"
    table = pd.read_csv(sweep)
    table.loc[table["config"] == "A-to-B", "auroc"] = 0.5  # every seed: the mean becomes 0.5000 ± 0.0000
    table.to_csv(sweep, index=False)
    assert docblocks.main(["check", "--root", str(root)]) == 1
    assert [s.key for s in docblocks.run(root)] == ["headline"]
    assert docblocks.main(["write", "--root", str(root)]) == 0
    assert docblocks.run(root) == []
    assert "| Sim→Silicone (A-to-B) | 0.5000 ± 0.0000 | 0.7789 ± 0.0043 |" in (root / "README.md").read_text()


def test_inline_block_is_filled_in_place(tmp_path):
    root = tmp_path / "repo"
    (root / "docs" / "results").mkdir(parents=True)
    shutil.copy(REPO_ROOT / "docs" / "results" / "loop_real.csv", root / "docs" / "results")
    (root / "README.md").write_text("The loop adds <!-- gen:loop.effects -->old<!-- /gen --> to the twin.\n")
    assert [(s.line, s.key) for s in docblocks.run(root, write=True)] == [(1, "loop.effects")]
    assert (root / "README.md").read_text() == ("The loop adds <!-- gen:loop.effects -->`surface_contact`, then "
                                                "`marker_anchor`<!-- /gen --> to the twin.\n")


def test_unclosed_block_is_an_error(tmp_path):
    (tmp_path / "README.md").write_text("<!-- gen:loop.effects -->a\n<!-- gen:loop.effects -->b<!-- /gen -->\n")
    with pytest.raises(ValueError, match="lacks its '<!-- /gen -->'"):
        docblocks.run(tmp_path)


def test_unknown_key_names_the_file_and_line(tmp_path, capsys):
    (tmp_path / "README.md").write_text("a\n<!-- gen:nonsense -->1<!-- /gen -->\n")
    with pytest.raises(ValueError, match=re.escape(f"{tmp_path / 'README.md'}:2: unknown block key 'nonsense'")):
        docblocks.run(tmp_path)
    assert docblocks.main(["check", "--root", str(tmp_path)]) == 1
    assert "docblocks: error:" in capsys.readouterr().err


def test_a_changed_selftest_record_makes_the_loop_page_stale(tmp_path):
    root = repo_copy(tmp_path)
    record = root / "docs" / "results" / "loop_selftest_seed7.csv"
    table = pd.read_csv(record)
    table["effects_named"] = table["effects_injected"]  # every run named exactly: 100 %
    table.to_csv(record, index=False)
    assert [s.key for s in docblocks.run(root)] == ["loop.fixed.seed7"]
    docblocks.run(root, write=True)
    assert "<!-- gen:loop.fixed.seed7 -->100 %<!-- /gen -->" in (root / "docs" / "loop.md").read_text()


def test_a_markdown_record_without_its_line_is_an_error(tmp_path):
    root = repo_copy(tmp_path)
    report = root / "docs" / "results" / "paper" / "loop_method" / "report.md"
    report.write_text(report.read_text().replace("beyond the final twin's own parameters", "beyond the final twin"))
    with pytest.raises(ValueError, match="'N× the noise' line"):
        docblocks.run(root)


def test_a_changed_silicone_check_makes_the_maps_page_stale(tmp_path):
    root = repo_copy(tmp_path)
    record = root / "docs" / "results" / "paper" / "maps" / "silicone_pose_check.json"
    data = json.loads(record.read_text())
    data["mirror"]["m"] = 15.0  # the step is 60 / m
    record.write_text(json.dumps(data))
    assert [s.key for s in docblocks.run(root)] == ["maps.silicone.mirror", "maps.silicone.step"]
    docblocks.run(root, write=True)
    assert "<!-- gen:maps.silicone.step -->4.00 mm<!-- /gen -->" in (root / "docs" / "maps.md").read_text()
