"""The results page (issue 8): every table of a workflow run beside the paper's numbers, and where and
why they differ.

`build_page(root)` reads a run's outputs under a results root (read only) and returns one Markdown page;
`write_page` writes it atomically. The page's order, headings and prose are the Jinja2 template
`templates/results_page.md.j2`; this module gathers what fills it (numbers, tables, links, generated
bullets). Rule `results_page` makes `results/README.md`; `docs/results.md` is a committed copy from a
paper-profile run. A section whose inputs the run did not produce says so. Known
causes of differences live in a data file (conf/results_page/explanations.yaml), shown only when their
table is on the page and, with `when:`, only when the numbers show the difference they explain.
"""

from __future__ import annotations

import glob
import os
from dataclasses import dataclass
from pathlib import Path

import jinja2

from palpation.io import save_text
from palpation.readers import read_csv, read_text, read_yaml
from palpation.report import page_training as training
from palpation.report import page_twin as twin
from palpation.report.compare import SOURCES, TITLES, Section, read_json, read_table
from palpation.report.page_judge import twin_selection_section
from palpation.report.page_transfer import transfer_section
from palpation.report.page_recipe import CROSSFIT_FIGURE, recipe_ablation_section, recipe_crossfit_section
from palpation.report.markdown import markdown, num
from palpation.report.reproduction import BENCHMARKS, benchmark_jobs, per_rule, run_start, span_s

ORDER = ("data", "calibration", "loop", "seed_sweep", "table3", "table4_markers", "table4_maps", "twin_ablation",
         "recipe_ablation", "recipe_crossfit", "twin_selection", "transfer")
FIGURES = (  # (caption, path under the results root; a glob lists every match)
    ("Fig. 4: fitted twin vs the photos", "calibration/fig4.png"),
    ("Fig. 4 at the paper's parameters", "calibration/fig4_paper.png"),
    ("Calibration history", "calibration/history.png"),
    ("Fig. 6: precision–recall curves, mean ± std over seeds", "train/report/fig6_pr_curves.png"),
    ("Fig. 7: vessel maps (TP green, FP blue, FN red, TN black)", "maps/fig7_confusion_maps.png"),
    ("Fig. 7: threshold selection", "maps/fig7_threshold_selection.png"),
    ("Residual loop: MAE per round", "loop/rounds.png"),
    ("Residual loop: residual modes", "loop/modes.png"),
    ("Residual loop: residuals per photo", "loop/residuals/*.png"),
    ("Measured photos: detected markers", "data/photos/markers_overlay.png"),
    ("Silicone set", "data/silicone/silicone_overview.png"),
    ("Meat set", "data/meat/meat_overview.png"),
    ("Twin renders", "twin/render/markers.png"),
    ("Reliability of the test scores, reference vs robust recipe", "recipe/report/reliability.png"),
    ("Reliability of the test scores, calibration cross-fitted between the real sets", CROSSFIT_FIGURE),
    ("Seed-ensemble vessel maps: mean, spread, unsure pixels, coverage-precision", "recipe/report/uncertainty_maps.png"),
    ("Twin on the task: real vs twin marker motion over one Silicone trial", "judge/slide_motion.png"),
)
# Markdown, not HTML: autoescaping would turn `<rule>` and `&` into entities. StrictUndefined: a misspelt name fails.
PAGE = jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"), autoescape=False,
                          trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined,
                          ).get_template("results_page.md.j2")
SIM_TWIN_LINE = "Sim set twin: "  # the first line of simulate_dataset's log (workflow/rules/dataset.smk)
WHEN_KEYS = {"configs", "metrics", "direction", "profiles"}
DIRECTIONS = {"below": -1, "above": 1, "off": 0}


@dataclass(frozen=True)
class Explanation:
    text: str
    when: dict

    def applies(self, section: Section, profile: str) -> bool:
        w = self.when
        if "profiles" in w and profile not in w["profiles"]:
            return False
        configs = set(w.get("configs") or []) or None
        if configs is not None and not configs & section.configs:
            return False
        if "metrics" not in w:
            return True
        sign = DIRECTIONS[w.get("direction", "off")]
        # a gap counts if it is off (outside seed noise, or unjudged) in the asked direction
        return any(g.metric in w["metrics"] and (configs is None or g.config in configs) and g.within is not True
                   and g.diff != 0 and (sign == 0 or (g.diff > 0) == (sign > 0)) for g in section.gaps)


def load_explanations(path: str | Path) -> dict[str, list[Explanation]]:
    """{table key: [Explanation]}; unknown keys or conditions raise, naming the file (typos would hide text)."""
    path = Path(path)
    data = read_yaml(path, "write a mapping of table keys to lists of {text, when} entries", "explanations file",
                     default={})
    out = {}
    for key, items in data.items():
        if key not in TITLES and key != "run":
            raise ValueError(f"{path}: unknown table key {key!r}; use one of {['run', *TITLES]}")
        out[key] = []
        for n, item in enumerate(items or []):
            item = item if isinstance(item, dict) else {"bad": item}
            raw = item.get("when")
            when = raw if isinstance(raw, dict) else ({} if raw is None else {"bad": raw})
            bad = set(item) - {"text", "when"} or set(when) - WHEN_KEYS
            if "text" not in item or bad or when.get("direction", "off") not in DIRECTIONS:
                raise ValueError(f"{path}: {key}[{n}] needs `text` and an optional `when` with keys "
                                 f"{sorted(WHEN_KEYS)} (direction: {sorted(DIRECTIONS)}); got {item}")
            out[key].append(Explanation(" ".join(str(item["text"]).split()), when))
    return out


def _records(root: Path) -> list[dict]:
    path = root / "bench" / "reproduction.json"
    records = read_json(path) or []
    if not isinstance(records, list) or any(not isinstance(r, dict) or "profile" not in r for r in records):
        raise ValueError(f"{path}: expected a list of run records with a 'profile' each "
                         "(palpation.report.reproduction.record_run writes it)")
    return records


def run_info(root: Path, profile: str | None) -> dict:
    """Profile, device, commit and timing: the latest reproduction record of the profile, else the tables' labels."""
    records = _records(root)
    if profile is None and records:
        profile = records[-1]["profile"]
    record = next((r for r in reversed(records) if r["profile"] == profile), None)
    train = read_json(root / "train" / "report" / "bench_train.json") or {}
    maps = read_json(root / "maps" / "vessel_maps.json") or {}
    profile = profile or maps.get("profile") or train.get("profile") or "unknown"
    device = (record or {}).get("device") or next((r.get("device") for r in train.get("runs", [])), None)
    return {"profile": profile, "device": device or "not recorded", "record": record}


def timing(root: Path, rec: dict | None, built_commit: str) -> dict:
    """The `## Timing` section's facts: per rule from Snakemake's benchmark files when the root has them (a page
    built inside a run lists the jobs finished before it), else the profile's record in bench/reproduction.json."""
    jobs = benchmark_jobs(root)
    if len(jobs):
        start = run_start(root)
        rules = per_rule(jobs)
        rows = [[rule, int(r.jobs), f"{r.s:.1f}", num(r.max_rss, 0)] for rule, r in rules.iterrows()]
        return {"jobs": len(jobs), "earlier": int((jobs["end"] < start).sum()) if start is not None else 0,
                "span_s": num(span_s(jobs), 1), "span_min": num(span_s(jobs) / 60, 1),
                "table": markdown(["rule", "jobs", "s", "max RSS (MB)"], rows)}
    if rec is None:
        return {"jobs": 0, "record": False}
    per = sorted(rec.get("per_rule", {}).items(), key=lambda kv: -kv[1])
    commit = str(rec.get("commit") or "")
    built = str(built_commit or "")
    same = bool(commit) and (commit == built or (len(commit) >= 7 and built.startswith(commit)))  # or its short hash
    return {"jobs": 0, "record": True, "record_commit": commit or "unknown", "wall_s": num(rec["wall_s"], 1),
            "wall_min": num(rec["wall_s"] / 60, 1), "stale": not same,
            "table": markdown(["rule", "s"], [[k, f"{v:.1f}"] for k, v in per])}


def sim_set_twin(root: Path) -> str | None:
    """Which twin made the main Sim set, in words: rule twin_choice's record, else the first line of
    simulate_dataset's log (it names dataset.twin and the fit read); None where the root holds neither."""
    choice = read_json(root / "judge" / "choice" / "choice.json")
    if choice:
        return f"the `{choice['sim_set_twin']}` twin ({choice['how']}; `judge/choice/choice.json`)"
    log = root / "logs" / "sim" / "simulate_dataset.log"
    first = read_text(log, "rerun rule simulate_dataset", empty_ok=True).split("\n", 1)[0] if log.exists() else ""
    if first.startswith(SIM_TWIN_LINE):
        return f"{first[len(SIM_TWIN_LINE):]} (`logs/sim/simulate_dataset.log`)"
    return None


def sections(root: Path, k: float = 2.0, link=None) -> dict[str, Section | None]:
    """Every table of ORDER as a Section, or None where its main input is missing; `link(rel)` links a figure."""
    t = {key: read_table(root, key) for key in SOURCES}
    loop_states = root / "loop" / "tables" / "per_state.csv"
    build = {
        "data": lambda: twin.data_sets(t["data"], t["seed_sweep"], t["table4_markers"], sim_set_twin(root)),
        "calibration": lambda: twin.calibration(t["calibration"]),
        "loop": lambda: twin.loop(t["loop"], read_csv(loop_states, fix="rerun rule loop", rows=False)
                                  if loop_states.exists() else None),
        "seed_sweep": lambda: training.seed_sweep_section(t["seed_sweep"], k),
        "table3": lambda: training.table3_section(t["table3"], k),
        "table4_markers": lambda: training.table4_markers_section(t["table4_markers"], t["seed_sweep"], k),
        "table4_maps": lambda: training.table4_maps_section(t["table4_maps"], t["maps_photo"],
                                                    read_json(root / "maps" / "silicone_pose_check.json")),
        "twin_ablation": lambda: training.twin_ablation_section(t["twin_ablation"], k),
        "recipe_ablation": lambda: recipe_ablation_section(
            t["recipe_ablation"], read_json(root / "recipe" / "report" / "recipe_report.json"), t["seed_sweep"], k),
        "recipe_crossfit": lambda: recipe_crossfit_section(
            t["recipe_crossfit"], t["recipe_ablation"],
            read_json(root / "recipe" / "report" / "recipe_calibration_crossfit.json"),
            link(CROSSFIT_FIGURE) if link is not None and (root / CROSSFIT_FIGURE).exists() else None),
        "twin_selection": lambda: twin_selection_section(t["twin_selection"], t["loop_slides"], t["drift_bounds"]),
        "transfer": lambda: transfer_section(t["transfer"], read_json(root / "transfer" / "transfer.json"),
                                             read_json(root / "data" / "meat" / "meat.json")),
    }
    return {key: build[key]() if t[key] is not None else None for key in ORDER}


def figures(root: Path, link) -> list[dict]:
    """The figures the run made: caption, whether it is a single file, and (name, link) per file."""
    out = []
    for caption, pattern in FIGURES:
        found = sorted(glob.glob(str(root / pattern)))
        if found:
            single = len(found) == 1 and "*" not in pattern
            out.append({"caption": caption, "single": single,
                        "links": [(Path(f).stem, link(pattern if single else os.path.relpath(f, root)))
                                  for f in found]})
    return out


def differences(secs: dict[str, Section | None], explanations: dict[str, list[Explanation]],
                profile: str) -> tuple[list[str], list[dict]]:
    """The notes on the whole run, and per present table its generated bullets and the known causes that apply."""
    run = Section("run", "", "", [], [], set())
    run_notes = [e.text for e in explanations.get("run", []) if e.applies(run, profile)]
    per_table = [{"title": sec.title, "bullets": sec.bullets,
                  "causes": [e.text for e in explanations.get(key, []) if e.applies(sec, profile)]}
                 for key, sec in secs.items() if sec is not None]
    return run_notes, per_table


def folders(root: Path, path: str | Path, link) -> str:
    """The table of result folders (conf/results_page/folders.yaml), marking those this run made."""
    entries = read_yaml(path, "write a list of {path, rules, what} entries", "results-page folders file", kind=list,
                        default=[])
    rows = []
    for e in entries:
        missing = [k for k in ("path", "rules", "what") if not isinstance(e, dict) or k not in e]
        if missing:
            raise ValueError(f"{path}: entry {e} lacks {missing}")
        there = "yes" if (root / e["path"]).exists() else "–"
        rows.append([f"[`{e['path']}`]({link(e['path'])})" if there == "yes" else f"`{e['path']}`",
                     ", ".join(r if " " in r else f"`{r}`" for r in e["rules"]), e["what"], there])
    return markdown(["folder", "made by", "what", "in this run"], rows)


def _missing(key: str) -> dict:
    src = SOURCES[key]
    rule = f"rule `{src.rule}`" if src.rule.isidentifier() else f"the rule {src.rule}"
    return {"title": TITLES[key], "body": None, "path": src.path, "rule": rule}


def build_page(root: str | Path, explanations: str | Path, folders_file: str | Path, profile: str | None = None,
               page_dir: str | Path | None = None, links: str | None = None, k: float = 2.0,
               built_commit: str = "unknown") -> tuple[str, dict[str, Section | None]]:
    """The page's Markdown and its sections. Links are relative to `page_dir` (default: the root), or
    `links` + the path under the root when given (e.g. a committed page pointing at ../results)."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"results root {root} is not a folder; run the workflow first or pass root=")
    base = Path(page_dir) if page_dir is not None else root

    def link(rel: str) -> str:
        if links is not None:
            return f"{links.rstrip('/')}/{rel}"
        return Path(os.path.relpath(root / rel, base)).as_posix()

    info = run_info(root, profile)
    secs = sections(root, k, link)
    run_notes, per_table = differences(secs, load_explanations(explanations), info["profile"])
    run_rows = [["profile", info["profile"]], ["device", info["device"]], ["page built at commit", f"`{built_commit}`"]]
    text = PAGE.render(
        profile=info["profile"], root=str(root), run_table=markdown(["run", ""], run_rows), benchmarks=BENCHMARKS,
        timing=timing(root, info["record"], built_commit),
        sections=[_missing(key) if sec is None else {"title": sec.title, "body": sec.body} for key, sec in secs.items()],
        report_link=link("report.html"), figures=figures(root, link), k=f"{k:g}", run_notes=run_notes,
        differences=per_table, folders_table=folders(root, folders_file, link))
    return text, secs


def write_page(path: str | Path, text: str) -> Path:
    save_text(path, text)  # atomic: a killed job never leaves half a page
    return Path(path)
