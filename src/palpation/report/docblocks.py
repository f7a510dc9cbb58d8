"""Fill the marked blocks of README.md and docs/*.md from the committed records (`report.docnumbers`).

A block is `<!-- gen:KEY -->TEXT<!-- /gen -->`, inline in a sentence or around lines of its own (a table):
`write` replaces each TEXT with what `docnumbers.NUMBERS[KEY]` makes of docs/results/; `check` writes
nothing and exits 1 naming every block whose TEXT differs (a record changed, the docs not regenerated):

    python -m palpation.report.docblocks write     # after committing new records under docs/results/
    python -m palpation.report.docblocks check     # CI (tests/report/test_docblocks.py)

Markdown hides the comments, so a reader sees the number; an unknown key is an error, never left as is.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from palpation.io import save_text
from palpation.paths import REPO_ROOT
from palpation.readers import read_text
from palpation.report.docnumbers import NUMBERS

BLOCK = re.compile(r"<!-- gen:(?P<key>[\w.\-]+) -->(?P<text>.*?)<!-- /gen -->", re.S)
START = re.compile(r"<!-- gen:[\w.\-]+ -->")


@dataclass(frozen=True)
class Stale:
    path: Path
    line: int
    key: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: block '{self.key}' differs from its record"


def documents(root: Path) -> list[Path]:
    """README.md and the docs/*.md that are read as prose (docs/journal/ is history, not generated)."""
    return [p for p in [root / "README.md", *sorted((root / "docs").glob("*.md"))] if p.is_file()]


def fill(text: str, results: Path, where: Path) -> tuple[str, list[tuple[int, str]]]:
    """`text` with every block filled, and (line, key) of the blocks that changed."""
    changed = []

    def one(match: re.Match) -> str:
        key, old = match["key"], match["text"]
        if key not in NUMBERS:
            line = text.count("\n", 0, match.start()) + 1
            raise ValueError(f"{where}:{line}: unknown block key '{key}'; use one of {sorted(NUMBERS)} "
                             "(palpation.report.docnumbers)")
        new = NUMBERS[key](results)
        if old.startswith("\n"):  # a block on lines of its own keeps them
            new = f"\n{new}\n"
        if new != old:
            changed.append((text.count("\n", 0, match.start()) + 1, key))
        return f"<!-- gen:{key} -->{new}<!-- /gen -->"

    if len(START.findall(text)) != len(BLOCK.findall(text)):  # a block without its end would never be filled
        raise ValueError(f"{where}: a '<!-- gen:...' block lacks its '<!-- /gen -->' (or holds another block); "
                         "close each block before the next")
    return BLOCK.sub(one, text), changed


def run(root: Path = REPO_ROOT, results: Path | None = None, write: bool = False) -> list[Stale]:
    """The stale blocks under `root` (records from `results`, default root/docs/results); `write` fixes them."""
    results = results or root / "docs" / "results"
    stale = []
    for path in documents(root):
        text = read_text(path, "restore it from git", "document")
        new, changed = fill(text, results, path)
        stale += [Stale(path, line, key) for line, key in changed]
        if write and changed:
            save_text(path, new)
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m palpation.report.docblocks", description=__doc__.split("\n")[0])
    parser.add_argument("action", choices=("write", "check"))
    parser.add_argument("--root", type=Path, default=REPO_ROOT, help="the repository (README.md, docs/)")
    args = parser.parse_args(argv)
    try:
        stale = run(args.root, write=args.action == "write")
    except (ValueError, OSError) as exc:
        print(f"docblocks: error: {exc}", file=sys.stderr)
        return 1
    for s in stale:
        print(("rewrote " if args.action == "write" else "") + str(s))
    if args.action == "check" and stale:
        print("regenerate them: python -m palpation.report.docblocks write", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
