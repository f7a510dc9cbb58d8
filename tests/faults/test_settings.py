"""Every numeric or list setting is checked before any work: one line naming the key, value, range and fix.

The cases go through each app's real Hydra main (`main(cfg)`, as Hydra calls it after composing) with
`run` replaced by a recorder, so they show the app passes its table and that nothing runs or is written.
The property tests draw values inside and outside every rule of every app (config_ranges).
"""

from __future__ import annotations

import copy
import importlib
import math
import subprocess
import sys

import pytest
from hydra import compose, initialize_config_dir
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from omegaconf import DictConfig, ListConfig, OmegaConf

from palpation.config_ranges import ConfigRangeError, Rule, check_values, rules_of, table_rules
from palpation.paths import REPO_ROOT

APPS = tuple(sorted(p.stem for p in (REPO_ROOT / "conf").glob("*.yaml")))  # every app has conf/<app>.yaml
OUT_KEYS = (("out.dir", ""), ("out_dir", ""), ("out.mesh", "mesh.npz"), ("out", "page.md"))  # where an app writes

# (app, override, dotted key, what is allowed): at least one per app
BAD = [
    ("calibrate", "calibration.n_trials=0", "calibration.n_trials", "an integer >= 1"),
    ("calibrate", "calibration.seed=-1", "calibration.seed", "an integer in [0, 4294967295]"),
    ("calibrate", "calibration.interactions=[]", "calibration.interactions", "a non-empty list of distinct items"),
    ("data_summary", "datasets.silicone.central_trim=-1", "datasets.silicone.central_trim", "an integer >= 0"),
    ("data_summary", "datasets.meat.reference_positive_rate=1.5", "datasets.meat.reference_positive_rate", "[0, 1]"),
    ("loop", "mode=fake", "mode", "one of ['real', 'selftest'"),
    ("loop", "loop.search.n_trials=0", "loop.search.n_trials", "an integer >= 1"),
    ("loop", "loop.effects=[]", "loop.effects", "a non-empty list"),
    ("loop", "loop.selftest.runs_per_case=0", "loop.selftest.runs_per_case", "an integer >= 1"),
    ("meat", "overview_states=[300]", "overview_states", "an integer in [0, 218]"),
    ("meat", "similarity_scope=frame", "similarity_scope", "one of ['video', 'trial', 'state']"),
    ("mesh", "twin.mesh.length_factor=0", "twin.mesh.length_factor", "a finite number > 0"),
    ("mesh", "twin.material.nu=0.5", "twin.material.nu", "a finite number in (0, 0.5)"),
    ("photos", "max_missing=-1", "max_missing", "an integer in [0, 127]"),
    ("photos", "detector.background_px=60", "detector.background_px", "an odd integer >= 3"),
    ("recipe_crossfit", "seeds=[]", "seeds", "a non-empty list of distinct items"),
    ("recipe_crossfit", "calibrations=[bogus]", "calibrations", "'cross_real_shift'"),
    ("recipe_report", "threshold=1.5", "threshold", "a finite number in (0, 1)"),
    ("recipe_report", "seeds=[0,0]", "seeds", "item 1 repeats 0"),
    ("recipe_report", "clip_len=0", "clip_len", "an integer >= 1"),
    ("render_twin", "manifests=[]", "manifests", "a non-empty list"),
    ("results_page", "noise_k=0", "noise_k", "a finite number > 0"),
    ("silicone", "videos=[]", "videos", "a non-empty list of distinct items"),
    ("silicone", "videos=[11]", "videos", "an integer in [1, 10]"),
    ("silicone", "n_frames=0", "n_frames", "an integer in [1, 16]"),
    ("silicone_sequences", "depth_mm=0", "depth_mm", "a finite number > 0"),
    ("silicone_sequences", "bin_mm=-4", "bin_mm", "a finite number > 0"),
    ("simulate", "n_pairs=-3", "n_pairs", "an integer >= 1"),
    ("simulate", "n_pairs=0", "n_pairs", "an integer >= 1"),
    ("simulate", "max_frames=0", "max_frames", "null or an integer >= 1"),
    ("simulate", "batch_size=0", "batch_size", "an integer >= 1"),
    ("simulate", "twin.integrator.substeps=0", "twin.integrator.substeps", "an integer >= 1"),
    ("slide_loop", "trials=[1]", "trials", "a list of at least 2 distinct items"),
    ("slide_loop", "frames=[11,5]", "frames", "increasing"),
    ("slide_loop", "gate.alpha=1.5", "gate.alpha", "a finite number in (0, 1)"),
    ("slide_loop", "effects.friction.mu=[]", "effects.friction.mu", "a non-empty list"),
    ("slide_loop", "fold_workers=3", "fold_workers", "one of [1, 2]"),
    ("train", "train.epochs=0", "train.epochs", "an integer >= 1"),
    ("train", "recipe.sizes.large.batch_size=0", "recipe.sizes.large.batch_size", "an integer >= 1"),
    ("train", "seeds=[]", "seeds", "null or a non-empty list"),
    ("train", "recipe.lr=0", "recipe.lr", "a finite number > 0"),
    ("train", "model.dropout=1.0", "model.dropout", "a finite number in [0, 1)"),
    ("train_tables", "seeds=[]", "seeds", "a non-empty list"),
    ("train_tables", "ablation.clip_lens=[0]", "ablation.clip_lens", "an integer >= 1"),
    ("twin_ablation", "twins.loop=''", "twins", "each value a non-empty string"),
    ("twin_ablation", "clip_len=-1", "clip_len", "an integer >= 1"),
    ("twin_judge", "seeds=[]", "seeds", "a non-empty list"),
    ("twin_judge", "figure_trial=0", "figure_trial", "null or an integer >= 1"),
    ("vessel_maps", "threshold.min_precision=0", "threshold.min_precision", "a finite number in (0, 1]"),
    ("vessel_maps", "sim.max_maps=0", "sim.max_maps", "null or an integer >= 1"),
    ("vessel_maps", "configs=[B-to-A]", "configs", "one of ['A-to-A', 'A-to-B', 'A-to-C', 'C-to-B']"),
]


def _register_schemas():
    import palpation.calibration.config  # noqa: F401  (the structured configs of the conf groups)
    import palpation.loop.config  # noqa: F401
    import palpation.mapping.config  # noqa: F401
    import palpation.model.config  # noqa: F401
    import palpation.twin.config  # noqa: F401


def _out_override(app: str, tmp_path) -> list[str]:
    """The app's output folder (or file) moved under tmp_path/out (inside hydra_job's context)."""
    cfg = compose(app)
    for key, leaf in OUT_KEYS:
        if isinstance(OmegaConf.select(cfg, key), str):
            return [f"{key}={tmp_path / 'out' / leaf}"]
    return []


def test_every_app_has_a_case():
    assert {app for app, *_ in BAD} == set(APPS)
    assert len(BAD) >= 40


@pytest.mark.parametrize("app, override, key, allowed", BAD, ids=[f"{a}:{o}" for a, o, *_ in BAD])
def test_bad_setting_exits_before_any_work(app, override, key, allowed, hydra_job, tmp_path, monkeypatch):
    _register_schemas()
    module = importlib.import_module(f"palpation.apps.{app}")
    ran = []
    monkeypatch.setattr(module, "run", lambda *a, **k: ran.append(a))
    cfg = hydra_job(app, [override, *_out_override(app, tmp_path)])
    with pytest.raises(SystemExit) as info:
        module.main(cfg)  # Hydra's main with a composed config: the task function, app_main's checks first
    msg = str(info.value.code)
    assert "\n" not in msg and msg.startswith(f"{app}: error: setting {key}="), msg
    for needle in (f"palpation.apps.{app}", allowed, f"give {key} such a value"):
        assert needle in msg, f"{needle!r} not in {msg!r}"
    assert ran == [] and list(tmp_path.rglob("*")) == []


def test_randomised_set_with_negative_pairs(tmp_path, fault):
    """`simulate set=randomised n_pairs=-3`: wrote a Sim set with no trajectory and exited 0"""
    out = tmp_path / "sim"
    cmd = [sys.executable, "-m", "palpation.apps.simulate", "set=randomised", "n_pairs=-3", f"out.dir={out}",
           f"hydra.run.dir={tmp_path / 'hydra'}", "track=false"]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert proc.returncode == 1 and not out.exists()
    with fault(SystemExit, "setting n_pairs=-3", "need an integer >= 1", "give n_pairs such a value"):
        raise SystemExit(proc.stderr.strip())


# ---- the rules themselves: every shipped config passes, every numeric or list leaf has a rule ----

PRESETS = {"calibrate": [["calibration=reference"], ["calibration=tiny"]], "loop": [["loop=paper"], ["loop=tiny"]],
           "simulate": [["twin=reference"], ["twin=physical"]],
           "train": [[f"experiment={e}", f"recipe={r}"] for e in ("A-to-B", "C-to-B")
                     for r in ("reference", "robust", "better", "quick")]}
_COMPOSED: dict = {}


def composed(app: str, overrides=()) -> tuple[DictConfig, list[tuple[str, Rule]]]:
    key = (app, tuple(overrides))
    if key not in _COMPOSED:
        _register_schemas()
        with initialize_config_dir(str(REPO_ROOT / "conf"), version_base="1.3"):
            cfg = compose(app, overrides=list(overrides))
        table = getattr(importlib.import_module(f"palpation.apps.{app}"), "RANGES", None)
        _COMPOSED[key] = (cfg, rules_of(cfg, table))
    return _COMPOSED[key]


def _leaves(node, prefix=""):
    """The dotted key of every numeric or list leaf, interpolations left out (checked at their source)."""
    for key in node.keys():
        if not prefix and key == "hydra":
            continue
        child, path = node._get_node(key), f"{prefix}{key}"
        if OmegaConf.is_interpolation(node, key):
            continue
        if isinstance(child, DictConfig):
            yield from _leaves(child, path + ".")
        elif isinstance(child, ListConfig) or (isinstance(node[key], (int, float)) and not isinstance(node[key], bool)):
            yield path


def _covered(path: str, rules: dict[str, Rule]) -> bool:
    """A rule of its own, or a mapping or list above it whose rule checks every value."""
    parts = path.split(".")
    return path in rules or any(
        (rule := rules.get(".".join(parts[:i]))) is not None and rule.kind in ("dict", "list") and rule.item is not None
        for i in range(1, len(parts)))


@pytest.mark.parametrize("app, overrides", [(a, o) for a in APPS for o in [[], *PRESETS.get(a, [])]])
def test_shipped_settings_pass_and_are_all_covered(app, overrides):
    cfg, rules = composed(app, overrides)
    check_values(cfg, rules, app)
    assert [p for p in _leaves(cfg) if not _covered(p, dict(rules))] == []


@pytest.mark.parametrize("app", APPS)
def test_every_table_entry_names_a_key(app):
    cfg, _ = composed(app)
    table = getattr(importlib.import_module(f"palpation.apps.{app}"), "RANGES", {})
    assert [k for k, rule in table.items() if not table_rules(cfg, {k: rule})] == []


# ---- properties: inside a rule passes, outside fails with the one-line message ----

RULES = None


def all_rules(leaves_only: bool = False) -> list[tuple[str, str, Rule]]:
    """(app, key, rule) of every app; `leaves_only`: not the mappings whose keys have rules of their own
    (`effects` above `effects.*.*`), where a value the parent's rule allows may break a child's."""
    global RULES
    if RULES is None:
        RULES = [(app, path, rule) for app in APPS for path, rule in composed(app)[1]]
    if not leaves_only:
        return RULES
    return [(app, path, rule) for app, path, rule in RULES
            if not any(a == app and p.startswith(path + ".") for a, p, _ in RULES)]


def _bounds(rule: Rule):
    lo = rule.ge if rule.ge is not None else rule.gt
    hi = rule.le if rule.le is not None else rule.lt
    return lo, hi


def inside(rule: Rule):
    base = _inside(rule)
    return st.one_of(st.none(), base) if rule.null else base


def _inside(rule: Rule):
    lo, hi = _bounds(rule)
    if rule.kind == "int":
        ints = st.integers(None if lo is None else math.floor(lo) + (rule.gt is not None),
                           None if hi is None else math.ceil(hi) - (rule.lt is not None))
        return ints.filter(lambda v: v % 2 == 1) if rule.odd else ints
    if rule.kind == "num":
        return st.floats(lo, hi, exclude_min=rule.gt is not None, exclude_max=rule.lt is not None,
                         allow_nan=False, allow_infinity=False)
    if rule.kind == "choice":
        return st.sampled_from(rule.choices)
    if rule.kind == "text":
        return st.text(min_size=1).filter(str.strip)
    item = inside(rule.item) if rule.item else st.integers()
    if rule.kind == "dict":
        return st.dictionaries(st.text("abcdef", min_size=1), item, min_size=rule.min_len, max_size=rule.min_len + 3)
    most = rule.max_len if rule.max_len is not None else rule.min_len + 3
    if rule.unique and rule.item is not None and rule.item.kind == "choice":
        most = min(most, len(rule.item.choices))
    lists = st.lists(item, min_size=rule.min_len, max_size=most, unique=rule.unique or rule.increasing)
    return lists.map(sorted) if rule.increasing else lists


def outside(rule: Rule):
    """Values the rule must refuse (never a bool that equals a choice: True == 1)."""
    wrong = [st.none()] if not rule.null else []
    lo, hi = _bounds(rule)
    if rule.kind in ("int", "num"):
        wrong += [st.booleans(), st.text(), st.sampled_from([math.nan, math.inf, -math.inf])]
        if rule.kind == "int":
            wrong.append(st.floats(allow_nan=False))  # 2.0: a float where an integer is expected
            if lo is not None:
                wrong.append(st.integers(max_value=math.ceil(lo) - (rule.ge is not None)))
            if hi is not None:
                wrong.append(st.integers(min_value=math.floor(hi) + (rule.le is not None)))
            if rule.odd:
                wrong.append(_inside(Rule("int", rule.ge, rule.gt, rule.le, rule.lt)).filter(lambda v: v % 2 == 0))
        else:
            if lo is not None:
                wrong.append(st.floats(max_value=lo, exclude_max=rule.ge is not None, allow_nan=False,
                                       allow_infinity=False))
            if hi is not None:
                wrong.append(st.floats(min_value=hi, exclude_min=rule.le is not None, allow_nan=False,
                                       allow_infinity=False))
    elif rule.kind == "choice":
        wrong.append(st.one_of(st.text(), st.integers(), st.floats()).filter(
            lambda v: not any(v == c for c in rule.choices)))
    elif rule.kind == "text":
        wrong += [st.sampled_from(["", "  "]), st.integers()]
    elif rule.kind in ("list", "dict"):
        wrong.append(st.integers())
        if rule.min_len:
            wrong.append(st.just({} if rule.kind == "dict" else []))
        if rule.item is not None:
            bad = outside(rule.item)
            if rule.kind == "dict":
                wrong.append(st.builds(lambda ok, b: {**ok, "zz": b}, inside(Rule("dict", item=rule.item)), bad))
            else:
                wrong.append(_with_item(rule, bad))
                if rule.max_len is not None:
                    wrong.append(st.lists(_inside(rule.item), min_size=rule.max_len + 1, max_size=rule.max_len + 2))
                if (rule.unique or rule.increasing) and rule.min_len <= 2 <= (rule.max_len or 2):
                    wrong.append(_inside(rule.item).map(lambda v: [v, v]))
    return st.one_of(*wrong)


def _with_item(rule: Rule, bad):
    """A list of the right size with one item the item rule refuses."""
    size = max(rule.min_len, 1)
    return st.builds(lambda ok, b, i: ok[:i] + [b] + ok[i + 1:],
                     st.lists(_inside(rule.item), min_size=size, max_size=size), bad, st.integers(0, size - 1))


def _set(values: dict, path: str, value) -> dict:
    out = copy.deepcopy(values)
    *parents, last = path.split(".")
    node = out
    for part in parents:
        node = node[int(part)] if isinstance(node, list) else node[part]
    node[int(last) if isinstance(node, list) else last] = value
    return out


_PLAIN: dict = {}


def plain(app: str) -> dict:
    """The app's composed config as plain values (what check_values reads from a DictConfig)."""
    if app not in _PLAIN:
        cfg, _ = composed(app)
        _PLAIN[app] = OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)
    return _PLAIN[app]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_value_inside_a_range_passes(data):
    app, path, rule = data.draw(st.sampled_from(all_rules(leaves_only=True)), label="rule")
    value = data.draw(inside(rule), label="value")
    check_values(_set(plain(app), path, value), composed(app)[1], app)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_value_outside_a_range_fails_in_one_line(data):
    app, path, rule = data.draw(st.sampled_from(all_rules()), label="rule")
    value = data.draw(outside(rule), label="value")
    with pytest.raises(ConfigRangeError) as info:
        check_values(_set(plain(app), path, value), composed(app)[1], app)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"setting {path}="), msg
    assert rule.describe() in msg and f"give {path} such a value" in msg
