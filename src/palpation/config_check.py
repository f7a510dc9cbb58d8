"""Every app's config is checked for unknown keys before any work, and its errors end as one line.

Hydra refuses `twin.Emod=1` but accepts `+twin.Emod=1` (add a key) and `++key=value` (add or
override); `OmegaConf.to_object` then drops a key a structured config does not declare, and a plain
section passes it on to a dataclass constructor (a raw TypeError). So an app's config is refused when
* a structured node (a dataclass such as TwinConfig) holds a key that is not one of its fields, or
* a `+key=value` / `++key=value` override of the command line names a key the app's config does not
  have without it (config *groups* appended with `+group=option` are fine).
The message names the key, the app and a close existing key (difflib). This works with or without
structured configs: the second rule needs only the composed YAML.

Renamed keys (`RENAMED`: `tracking`, now `track`, the MLflow switch of every app) are refused with the
new name. Hydra itself refuses `tracking=false` (no `+`) before any app code runs, in several lines, so a
program run (`python -m palpation.apps.<app>`) also checks its command line for them first.

`app_main(name, ranges)` wraps a Hydra main: it runs the key check, the range check of every numeric or
list setting (`config_ranges.check_ranges`: the structured fields' rules and the app's `ranges` table) and
the MLflow store check (`tracking.check_store`) first, and turns the project's one-line errors (ValueError,
OSError) into exit status 1 with that line on stderr. `PALPATION_TRACEBACK=1` shows the traceback instead.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import os
import re
import sys
from typing import Any, Callable, Mapping

from omegaconf import DictConfig, OmegaConf


class ConfigKeyError(ValueError):
    """An app's config holds a key the app does not read."""


RENAMED = {"tracking": "track"}  # old key -> its one name now (apps had both for the MLflow switch)


def renamed(key: str, app: str, has_new: bool, text: str | None = None) -> str | None:
    """The message for a renamed key, or None when `key` was never renamed."""
    if key not in RENAMED:
        return None
    new = RENAMED[key]
    origin = f" (from the override '{text}')" if text else ""
    if has_new:
        value = text.partition("=")[2] if text and "=" in text else "true or false"
        return f"config key '{key}'{origin} was renamed '{new}' for palpation.apps.{app}: use {new}={value}"
    return (f"config key '{key}'{origin} is not a setting of palpation.apps.{app}, which logs nothing to MLflow "
            f"(the switch is called '{new}' where an app has one); drop it")


def check_argv(app: str, argv: list[str]) -> None:
    """Refuse a renamed key on a command line before Hydra parses it (`tracking=false`, `+tracking=1`, ...)."""
    from palpation.paths import REPO_ROOT

    for text in argv:
        key = re.match(r"^[+~]{0,2}([\w.-]+)(=|$)", text)
        if key and key.group(1) in RENAMED:
            own = OmegaConf.load(REPO_ROOT / "conf" / f"{app}.yaml")
            raise ConfigKeyError(renamed(key.group(1), app, RENAMED[key.group(1)] in own, text))


def dotted_keys(node: Any, prefix: str = "") -> list[str]:
    """Every key path of a config (mappings only; list items are values)."""
    out = []
    keys = node.keys() if isinstance(node, (DictConfig, dict)) else []
    for key in keys:
        path = f"{prefix}{key}"
        out.append(path)
        child = node._get_node(key) if isinstance(node, DictConfig) else node[key]
        if isinstance(child, (DictConfig, dict)):
            out += dotted_keys(child, path + ".")
    return out


def _undeclared(node: Any, prefix: str = "") -> list[str]:
    """Keys of structured (dataclass) nodes that the dataclass does not declare."""
    if not isinstance(node, DictConfig):
        return []
    out = []
    schema = OmegaConf.get_type(node)
    fields = {f.name for f in dataclasses.fields(schema)} if dataclasses.is_dataclass(schema) else None
    for key in node.keys():
        if fields is not None and key not in fields:
            out.append(f"{prefix}{key}")
        out += _undeclared(node._get_node(key), f"{prefix}{key}.")
    return out


def _added_by_override() -> tuple[list[tuple[str, str]], list[str]]:
    """(key, override) of the command line's `+key=` / `++key=` key additions, and the other overrides."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.core.override_parser.overrides_parser import OverridesParser

    try:
        hc = HydraConfig.get()
    except ValueError:  # not inside a Hydra job (tests call run(cfg) directly)
        return [], []
    groups = set(hc.runtime.choices.keys())
    added, kept = [], []
    for text, o in zip(hc.overrides.task, OverridesParser.create().parse_overrides(list(hc.overrides.task))):
        if (o.is_add() or o.is_force_add()) and o.key_or_group not in groups:
            added.append((o.key_or_group, text))
        else:
            kept.append(text)
    return added, kept


def _existing_without(added: list[tuple[str, str]], kept: list[str]) -> set[str]:
    """Key paths of the app's config composed without the key additions (`++` may name existing keys)."""
    if not any(text.startswith("++") for _, text in added):
        return set()
    from hydra import compose
    from hydra.core.hydra_config import HydraConfig

    reference = compose(HydraConfig.get().job.config_name, overrides=kept)
    return set(dotted_keys(reference))


def suggest(key: str, known: list[str]) -> str | None:
    """The existing key closest to `key`: by whole path or by last name (a prefix counts as close)."""
    leaf = key.rsplit(".", 1)[-1].lower()
    head = key.split(".")[0]

    def score(candidate: str) -> float:
        c_leaf = candidate.rsplit(".", 1)[-1].lower()
        s = max(difflib.SequenceMatcher(None, key.lower(), candidate.lower()).ratio(),
                difflib.SequenceMatcher(None, leaf, c_leaf).ratio())
        if c_leaf and (leaf.startswith(c_leaf) or c_leaf.startswith(leaf)):
            s = max(s, 0.8)
        return s + (0.05 if candidate.split(".")[0] == head else 0.0)

    best = max(known, key=score, default=None)
    return best if best is not None and score(best) >= 0.6 else None


def check_config(cfg: DictConfig, app: str) -> None:
    """Raise ConfigKeyError naming the first unknown key of `cfg` (see the module docstring)."""
    added, kept = _added_by_override()
    existing = _existing_without(added, kept)
    unknown = [(k, text) for k, text in added if not text.startswith("++") or k not in existing]
    unknown += [(k, None) for k in _undeclared(cfg) if k not in dict(added)]
    if not unknown:
        return
    key, text = unknown[0]
    moved = renamed(key, app, key in RENAMED and RENAMED[key] in cfg, text)
    if moved:
        raise ConfigKeyError(moved)
    names = [k for k in dotted_keys(cfg) if k not in {u for u, _ in unknown} and k != "hydra"
             and not k.startswith("hydra.")]
    hint = suggest(key, names)
    origin = f" (from the override '{text}')" if text else ""
    fix = f"did you mean {hint}? " if hint else ""
    raise ConfigKeyError(f"unknown config key '{key}'{origin} for palpation.apps.{app}; {fix}remove it or use "
                         f"an existing key (python -m palpation.apps.{app} --cfg job lists them)")


def _one_line(app: str, check: Callable, *args):
    """Run `check`; a ValueError/OSError becomes SystemExit with `<app>: error: <message>`."""
    try:
        return check(*args)
    except (ValueError, OSError) as exc:
        if os.environ.get("PALPATION_TRACEBACK"):
            raise
        raise SystemExit(f"{app}: error: {exc}") from None


def app_main(app: str, ranges: Mapping | None = None) -> Callable:
    """Decorator for an app's Hydra main (placed under @hydra.main): checks first, errors as one line.
    `ranges`: the app's table of plain YAML settings (config_ranges)."""
    def wrap(main: Callable) -> Callable:
        if main.__module__ == "__main__":  # run as a program: its command line, before Hydra reads it
            _one_line(app, check_argv, app, sys.argv[1:])

        def checks(cfg: DictConfig):
            from palpation.config_ranges import check_ranges
            from palpation.tracking import mark_work_start

            mark_work_start()
            check_config(cfg, app)
            check_ranges(cfg, app, ranges)
            if cfg.get("track", False):
                from palpation.tracking import check_store

                check_store()
            return main(cfg)

        @functools.wraps(main)
        def checked(cfg: DictConfig):
            return _one_line(app, checks, cfg)
        return checked
    return wrap


def _app_doc(app: str) -> str:
    """The app module's docstring: the first block of its `--help` (conf/hydra/help/app.yaml)."""
    import importlib

    doc = importlib.import_module(f"palpation.apps.{app}").__doc__ or ""
    return f"palpation.apps.{app}: " + doc.strip()


def _app_groups(app: str) -> str:
    """The config groups this app composed, with the chosen option (Hydra's own groups left out)."""
    from hydra.core.hydra_config import HydraConfig

    choices = HydraConfig.get().runtime.choices
    lines = [f"  {group}={option}" for group, option in sorted(choices.items())
             if group != "hydra" and not group.startswith("hydra/")]
    return "\n".join(lines) or "  (none: every option is listed below)"


# Imported by every app before hydra.main runs, so `--help` can resolve them.
OmegaConf.register_new_resolver("app_doc", _app_doc, replace=True)
OmegaConf.register_new_resolver("app_groups", _app_groups, replace=True)
