"""The conf/ files a Hydra app composes, so that Snakemake rules can declare them as inputs.

A rule that declares every YAML file its app reads reruns when one of them is edited (rerun trigger
`mtime`/`input`), and only then. This follows the `defaults:` lists the way Hydra does for the cases
this repository uses: `- name` (same group), `group: option` (a subgroup of the current group, or of the
root in a primary config), `override /group: option` (absolute) and `_self_`; a choice given in
`choices` (the rule's command-line overrides, e.g. {"twin/mesh": "reference"}) wins over the file's, and
`None` drops the group.
Structured configs registered in Python (`base_twin`, ...) have no file and are skipped.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import yaml


def conf_files(app: str, choices: Mapping[str, str | None] | None = None,
               conf_dir: str | Path = "conf") -> list[str]:
    """Sorted paths (as `conf_dir`/...) of `conf_dir/<app>.yaml` and every group file it pulls in."""
    conf_dir = Path(conf_dir)
    choices = dict(choices or {})
    seen: list[Path] = []

    def visit(path: Path, group: str) -> None:
        if not path.is_file() or path in seen:
            return
        seen.append(path)
        for entry in (yaml.safe_load(path.read_text()) or {}).get("defaults", []) or []:
            if isinstance(entry, str):
                if entry != "_self_":
                    visit(conf_dir / group / f"{entry}.yaml", group)
                continue
            for key, option in entry.items():
                key = key.removeprefix("optional ").split("@")[0]
                if key.startswith("override "):
                    sub = key.removeprefix("override ").strip().lstrip("/")
                else:
                    sub = key.lstrip("/") if key.startswith("/") or not group else f"{group}/{key}"
                option = choices.get(sub, option)
                if sub.split("/")[0] == "hydra":  # Hydra's own settings (help text, logging) change no output
                    continue
                if option is not None:
                    visit(conf_dir / sub / f"{option}.yaml", sub)

    visit(conf_dir / f"{app}.yaml", "")
    return sorted(str(p) for p in seen)
