"""The range or choices of every numeric or list setting, checked before an app does any work.

One check (`check_ranges`, run by `config_check.app_main` right after the key check), two places that declare:
* structured configs (TwinConfig, CalibrationConfig, LoopConfig, the train and vessel_maps schemas) give a
  field its rule beside it: `E: float = ranged(paper.E, Num(gt=0))`;
* an app's plain YAML settings have a table in the app module, `RANGES = {"n_pairs": Int(ge=1), ...}`, passed
  to `app_main`; a `*` in a dotted key stands for any one key (`effects.*.*`).
A value outside its rule fails with one line naming the dotted key as it is typed on the command line, the
value, what is allowed and the fix. A key whose value interpolates another (`train.batch_size:
${recipe.sizes...}`) is checked where the value lives, so the message names the key the user set.
Cross-key conditions (n_startup <= n_trials, ...) stay with the dataclasses' `validate()`.
"""

from __future__ import annotations

import dataclasses
import math
from enum import Enum
from typing import Any, Mapping

from omegaconf import DictConfig, ListConfig, OmegaConf


class ConfigRangeError(ValueError):
    """A setting outside its range or choices."""


@dataclasses.dataclass(frozen=True)
class Rule:
    kind: str  # int | num | choice | text | list | dict
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    odd: bool = False  # int: an odd kernel size (OpenCV's median blur)
    choices: tuple = ()
    item: "Rule | None" = None  # list: every item's rule; dict: every value's (None: anything)
    min_len: int = 0
    max_len: int | None = None
    unique: bool = False  # list: no item twice
    increasing: bool = False  # list: strictly increasing
    null: bool = False  # null allowed

    def describe(self) -> str:
        text = self._describe()
        return f"null or {text}" if self.null else text

    def _describe(self) -> str:
        if self.kind in ("int", "num"):
            noun = ("an odd integer" if self.odd else "an integer") if self.kind == "int" else "a finite number"
            return noun + self._bounds()
        if self.kind == "choice":
            return f"one of {list(self.choices)}"
        if self.kind == "text":
            return "a non-empty string"
        each = f", each {'value ' if self.kind == 'dict' else ''}{self.item.describe()}" if self.item else ""
        if self.kind == "dict":
            return f"a {'non-empty ' if self.min_len else ''}mapping" + each
        adj = " ".join(a for a, on in (("distinct", self.unique), ("increasing", self.increasing)) if on)
        if self.max_len is not None:
            size = f"{self.min_len}" if self.min_len == self.max_len else f"{self.min_len} to {self.max_len}"
            head = " ".join(w for w in ("a list of", size, adj, "items") if w)
        elif self.min_len > 1:
            head = " ".join(w for w in ("a list of at least", str(self.min_len), adj, "items") if w)
        else:
            head = f"a {'non-empty ' if self.min_len else ''}list" + (f" of {adj} items" if adj else "")
        return head + each

    def _bounds(self) -> str:
        lo = (f"[{_num(self.ge)}" if self.ge is not None else f"({_num(self.gt)}" if self.gt is not None else None)
        hi = (f"{_num(self.le)}]" if self.le is not None else f"{_num(self.lt)})" if self.lt is not None else None)
        if lo and hi:
            return f" in {lo}, {hi}"
        if lo:
            return (" >= " if lo[0] == "[" else " > ") + lo[1:]
        if hi:
            return (" <= " if hi[-1] == "]" else " < ") + hi[:-1]
        return ""

    def problem(self, value: Any) -> str | None:
        """Why `value` breaks the rule (a few words), or None when it is allowed."""
        if isinstance(value, Enum):  # a typed config's enum member: its name is what was typed
            value = value.name
        if value is None:
            return None if self.null else "null is not allowed"
        if self.kind in ("int", "num"):
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or (self.kind == "int" and not isinstance(value, int)):
                return "not an integer" if self.kind == "int" else "not a number"
            if not math.isfinite(value):
                return "not finite"
            inside = ((self.ge is None or value >= self.ge) and (self.gt is None or value > self.gt)
                      and (self.le is None or value <= self.le) and (self.lt is None or value < self.lt))
            if not inside:
                return "out of range"
            return "even" if self.odd and value % 2 == 0 else None
        if self.kind == "choice":
            # True == 1 in Python: a switch's choices and a number's are told apart by type
            same = [c for c in self.choices if isinstance(c, bool) == isinstance(value, bool) and c == value]
            return None if same else "not a choice"
        if self.kind == "text":
            return None if isinstance(value, str) and value.strip() else "not a non-empty string"
        if self.kind == "dict":
            if not isinstance(value, Mapping):
                return "not a mapping"
            return self._size(len(value)) or self._items(value.items())
        if not isinstance(value, (list, tuple)):
            return "not a list"
        bad = self._size(len(value)) or self._items(enumerate(value))
        if bad:
            return bad
        for i in range(1, len(value)):
            if self.unique and value[i] in value[:i]:
                return f"item {i} repeats {_show(value[i])}"
            if self.increasing and not value[i] > value[i - 1]:
                return f"item {i} ({_show(value[i])}) does not increase"
        return None

    def _size(self, n: int) -> str | None:
        if n < self.min_len or (self.max_len is not None and n > self.max_len):
            return f"{n} {'keys' if self.kind == 'dict' else 'items'}"
        return None

    def _items(self, pairs) -> str | None:
        for key, item in pairs:
            why = self.item.problem(item) if self.item else None
            if why:
                return f"{'item ' if self.kind == 'list' else ''}{key} = {_show(item)}: {why}"
        return None


def Int(ge=None, gt=None, le=None, lt=None, *, odd=False, null=False) -> Rule:  # noqa: N802 (reads as a type)
    return Rule("int", ge, gt, le, lt, odd=odd, null=null)


def Num(ge=None, gt=None, le=None, lt=None, *, null=False) -> Rule:  # noqa: N802
    return Rule("num", ge, gt, le, lt, null=null)


def Choice(*choices, null=False) -> Rule:  # noqa: N802
    return Rule("choice", choices=tuple(choices), null=null)


def Text(*, null=False) -> Rule:  # noqa: N802
    return Rule("text", null=null)


def ListOf(item: Rule | None = None, min_len=1, max_len=None, *, unique=False, increasing=False,  # noqa: N802
           null=False) -> Rule:
    return Rule("list", item=item, min_len=min_len, max_len=max_len, unique=unique, increasing=increasing, null=null)


def DictOf(item: Rule | None = None, min_len=0, *, null=False) -> Rule:  # noqa: N802
    return Rule("dict", item=item, min_len=min_len, null=null)


SEED = Int(ge=0, le=2**32 - 1)  # numpy's default_rng and Optuna's samplers take 32-bit seeds
SEEDS = ListOf(SEED, unique=True)


def ranged(default: Any = dataclasses.MISSING, rule: Rule | None = None, *, factory: Any = dataclasses.MISSING):
    """A dataclass field with its rule: `n_trials: int = ranged(10, Int(ge=1))`."""
    if factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=factory, metadata={"rule": rule})
    return dataclasses.field(default=default, metadata={"rule": rule})


def _num(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def _show(value: Any) -> str:
    """A value as it is typed in an override (null, true, 'text', [1, 2])."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    text = repr(value.name if isinstance(value, Enum) else value)
    return text if len(text) <= 80 else text[:77] + "..."


def declared_rules(cfg: DictConfig, prefix: str = "") -> list[tuple[str, Rule]]:
    """(dotted key, rule) of every field with a rule in the structured (dataclass) nodes of `cfg`."""
    out = []
    schema = OmegaConf.get_type(cfg)
    rules = {f.name: f.metadata["rule"] for f in dataclasses.fields(schema) if f.metadata.get("rule")} \
        if dataclasses.is_dataclass(schema) else {}
    for key in cfg.keys():
        if not prefix and key == "hydra":
            continue
        path = f"{prefix}{key}"
        if key in rules and not OmegaConf.is_interpolation(cfg, key):
            out.append((path, rules[key]))
        child = cfg._get_node(key)
        if OmegaConf.is_interpolation(cfg, key):
            continue
        if isinstance(child, DictConfig):
            out += declared_rules(child, path + ".")
        elif isinstance(child, ListConfig) and not child._is_none():  # structured items (calibration.params)
            out += [rule for i, item in enumerate(child._iter_ex(resolve=False)) if isinstance(item, DictConfig)
                    for rule in declared_rules(item, f"{path}.{i}.")]
    return out


def table_rules(cfg: DictConfig | Mapping, table: Mapping[str, Rule]) -> list[tuple[str, Rule]]:
    """(dotted key, rule) of every key of `cfg` that a pattern of an app's table names (`*`: any one key)."""
    def expand(node, parts: list[str], prefix: str):
        head, rest = parts[0], parts[1:]
        for key in (list(node.keys()) if head == "*" else [head] if head in node else []):
            if isinstance(node, DictConfig) and OmegaConf.is_interpolation(node, key):
                continue
            child = node._get_node(key) if isinstance(node, DictConfig) else node[key]
            if not rest:
                yield f"{prefix}{key}"
            elif isinstance(child, (DictConfig, Mapping)):
                yield from expand(child, rest, f"{prefix}{key}.")

    return [(path, rule) for pattern, rule in table.items() for path in expand(cfg, pattern.split("."), "")]


_ABSENT = object()


def value_at(values: DictConfig | Mapping, path: str) -> Any:
    """A setting's plain value (lists, dicts, enum members as their names); _ABSENT where there is none."""
    if isinstance(values, DictConfig):
        node = OmegaConf.select(values, path, default=_ABSENT, throw_on_missing=False)
        if isinstance(node, (DictConfig, ListConfig)):
            return OmegaConf.to_container(node, resolve=True, enum_to_str=True)
        return node
    for part in path.split("."):
        if isinstance(values, list) and part.isdigit() and int(part) < len(values):
            values = values[int(part)]
        elif isinstance(values, Mapping) and part in values:
            values = values[part]
        else:
            return _ABSENT
    return values


def check_values(values: DictConfig | Mapping, rules: list[tuple[str, Rule]], app: str) -> None:
    """Raise ConfigRangeError for the first setting of `rules` that breaks its rule (absent keys are not checked:
    the rules come from the config itself, so only a test's hand-made values lack one)."""
    for path, rule in rules:
        value = value_at(values, path)
        why = None if value is _ABSENT else rule.problem(value)
        if why is None:
            continue
        detail = "" if why in ("out of range", "not a choice") else f" ({why})"
        raise ConfigRangeError(
            f"setting {path}={_show(value)} is not allowed for palpation.apps.{app}: need {rule.describe()}{detail}; "
            f"give {path} such a value on the command line or in the config file "
            f"(python -m palpation.apps.{app} --cfg job shows every setting)")


def rules_of(cfg: DictConfig, table: Mapping[str, Rule] | None = None) -> list[tuple[str, Rule]]:
    """Every rule that applies to an app's composed config: its structured fields', then its table's."""
    return declared_rules(cfg) + table_rules(cfg, table or {})


def check_ranges(cfg: DictConfig, app: str, table: Mapping[str, Rule] | None = None) -> None:
    check_values(cfg, rules_of(cfg, table), app)
