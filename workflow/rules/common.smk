# Shared settings and every helper function of the rule files (rule files hold rules and the constants
# of their own stage, and read nothing from each other but `rules.<name>.output`). Every app rule passes
# params rule=<its name> and py=PY, and names conda: CONDA_ENV.
#   config      conf/workflow/<profile>.yaml, --config on top, checked against workflow/schemas/
#   conf/       experiments and dataset files (palpation.experiments), run folders (palpation.report.runs)
import re
import sys
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import yaml

from snakemake.exceptions import WorkflowError
from snakemake.utils import validate
from snakemake_interface_executor_plugins.settings import DeploymentMethod

from palpation.confdeps import conf_files
from palpation.experiments import dataset_files, experiments
from palpation.report.runs import recipe_root, run_dir


def config_error(message, profile_file):
    """Snakemake's schema error in one line: what is wrong, at which key, where the keys are listed."""
    lines = message.splitlines()  # "Error validating config file.", "ValidationError: ...", "On instance[..]:"
    what = lines[1].removeprefix("ValidationError: ")
    if "is not of type" in what:
        what += " (nested --config values arrive as strings: pass typed ones in a --configfile)"
    path = next((line for line in lines if line.startswith("On instance")), "")
    key = ".".join(re.findall(r"\['?([^]']+)'?\]", path))
    at = f" at key '{key}'" if key else ""
    schema = "workflow/schemas/config.schema.yaml"
    return f"{profile_file} (or --config): {what}{at}; the keys and their defaults: {schema}"


PROFILE = config.get("profile", "quick")
_profile_file = Path("conf/workflow") / f"{PROFILE}.yaml"
if not _profile_file.exists():
    raise ValueError(f"unknown profile '{PROFILE}': {_profile_file} does not exist")


configfile: str(_profile_file)  # --config (and a profile's `config:`) wins, key by key


try:
    validate(config, "../schemas/config.schema.yaml")  # also fills in the schema's defaults
except WorkflowError as e:
    raise ValueError(config_error(str(e), _profile_file)) from None

# Every rule runs in workflow/envs/palpation.yaml under `--sdm conda`; otherwise (the default) in the
# interpreter running Snakemake (the venv, or a GPU node's environment).
CONDA_ENV = "../envs/palpation.yaml"
_CONDA = DeploymentMethod.CONDA in workflow.deployment_settings.deployment_method
PY = "python -m" if _CONDA else f"{sys.executable} -m"

PHOTOS = "data/reference/photos/flat-tip"
VIDEOS = "data/reference/videos"
GPU = 1 if config["device"] == "cuda" else 0  # resources: gpu, so that a profile can cap GPU jobs
TWIN_ARGS = f"twin/mesh={config['twin_resolution']} twin.device={config['device']}" + (
    f" twin.integrator.kernel={config['twin_kernel']}" if config["twin_kernel"] != "streamed" else "")

TRAIN = config["train"]
EXPERIMENTS = experiments()  # conf/experiment/<name>.yaml: sets trained and tested on, model size
TRAIN_DATA = dataset_files()  # conf/train.yaml data: sim, silicone, meat
TRAIN_DIR = "results/train"
TRAIN_REPORT = f"{TRAIN_DIR}/report"
TRAIN_RUN = str(run_dir(TRAIN_DIR, "{exp}", "{clip_len}", "{seed}"))
TWIN_ABL = TRAIN["twin_ablation"]
TWIN_ABL_RUN = str(run_dir(f"{TRAIN_DIR}/twin_calibrated", "{exp}", "{clip_len}", "{seed}"))
# the dataset-twin ablation's tables; empty where the profile skips it (no seeds)
TWIN_ABLATION_FILES = (
    [f"{TRAIN_REPORT}/twin_ablation.csv", f"{TRAIN_REPORT}/twin_ablation.md"] if TWIN_ABL["seeds"] else []
)
JUDGE = config["judge"]  # issue 12, judge.smk: the downstream judge of the candidate twins (seeds [] skips it)
MAPS_CONFIGS = config["maps"].get("configs", TRAIN["experiments"])
# The recipe ablation (issue 15, recipe.smk): runs <RECIPE_DIR>/<recipe>/<switch_off>/<exp>/L<n>/seed<s>/
RECIPE_ABL = TRAIN["recipe_ablation"]
RECIPE_DIR = "results/recipe"
RECIPE_RUN = str(run_dir(f"{RECIPE_DIR}/{{recipe}}/{{switch}}", "{exp}", "{clip_len}", "{seed}"))
RECIPE_REPORT = f"{RECIPE_DIR}/report"
RECIPE_REPORT_FILES = (
    [f"{RECIPE_REPORT}/{name}" for name in ("recipe_ablation.csv", "recipe_ablation.md", "uncertainty.csv",
                                            "reliability.png", "reliability.pdf", "uncertainty_maps.png",
                                            "uncertainty_maps.pdf", "recipe_report.json")]
    if RECIPE_ABL["seeds"] else []
)
# The recipe_crossfit rule (recipe.smk) writes the calibration cross-fitted between the real sets, which the
# results page reads. It joins the run where every ablated configuration's partner (conf/recipe_crossfit.yaml)
# is ablated with the same switch rows; else the page says it was not produced.
RECIPE_CROSSFIT_OUTPUTS = [f"{RECIPE_REPORT}/{name}" for name in (
    "recipe_calibration_crossfit.csv", "recipe_calibration_crossfit.json", "reliability_crossfit.png",
    "reliability_crossfit.pdf")]

_XFIT_PARTNERS = yaml.safe_load(Path("conf/recipe_crossfit.yaml").read_text())["partners"]
_XFIT_SWITCHED = RECIPE_ABL.get("switch_experiments") or RECIPE_ABL["experiments"]
_XFIT_OK = bool(RECIPE_ABL["seeds"]) and all(
    e in _XFIT_PARTNERS and (_XFIT_PARTNERS[e] is None or (
        _XFIT_PARTNERS[e] in RECIPE_ABL["experiments"] and _XFIT_PARTNERS[e] != e
        and (e not in _XFIT_SWITCHED or _XFIT_PARTNERS[e] in _XFIT_SWITCHED)))
    for e in RECIPE_ABL["experiments"])
RECIPE_CROSSFIT_FILES = RECIPE_CROSSFIT_OUTPUTS if _XFIT_OK else []


def plain(*outputs):
    """Paths without their report() flags. Snakemake's report credits a flagged file to the first job that
    lists it, input or output; consumers (rule all, results_page) list it plain so the producer is credited."""
    return [str(f) for files in outputs for f in ([files] if isinstance(files, str) else files)]


def hydra_dir(path):
    """Pin Hydra's run folder next to a rule's output so .hydra/config.yaml stays with it."""
    return f"hydra.run.dir={Path(path).parent} hydra.output_subdir=.hydra/{Path(path).stem}"


def twin_mesh(resolution=None):
    """The FEM mesh of rule `mesh` (twin.smk) at the profile's resolution."""
    return expand(rules.mesh.output.mesh, resolution=resolution or config["twin_resolution"])[0]


def fit_overrides(fit):
    """Hydra overrides that load a fitted twin, <dir>/twin_fit/fitted.yaml, as config group twin_fit."""
    return f"'hydra.searchpath=[file://{Path(fit).parents[1]}]' +twin_fit={Path(fit).stem}"


def yaml_list(values):
    return "[" + ",".join(str(v) for v in values) + "]"


def runs_root(metrics):
    """The root of training runs from one run's file, <root>/<exp>/L<n>/seed<s>/<file>."""
    return Path(metrics).parents[3]


def calibration_outputs(out):
    return {
        "fit": f"{out}/twin_fit/fitted.yaml",
        "params": f"{out}/fitted_params.yaml",
        "csv": report(f"{out}/calibration.csv", caption="../report/calibration_table.rst", category="Calibration"),
        "md": f"{out}/calibration.md",
        "json": f"{out}/calibration.json",
        "trials": f"{out}/trials.csv",
        "fig4": report(f"{out}/fig4.png", caption="../report/calibration_fig4.rst", category="Calibration"),
        "fig4_pdf": f"{out}/fig4.pdf",
        "fig4_paper": f"{out}/fig4_paper.png",
        "fig4_paper_pdf": f"{out}/fig4_paper.pdf",
        "history": report(
            f"{out}/history.png", caption="../report/calibration_history.rst", category="Calibration"
        ),
        "history_pdf": f"{out}/history.pdf",
    }


# the training helpers (train_inputs, train_overrides, train_groups, group_*, run_files, recipe_*): common_train.smk
include: "common_train.smk"


def sweep_runs(name):
    """`name` (metrics.json, scores.npz) of every run the report reads."""
    runs = expand(f"{TRAIN_RUN}/{name}", exp=TRAIN["experiments"], clip_len=TRAIN["clip_len"], seed=TRAIN["seeds"])
    abl = TRAIN["ablation"]
    if abl["clip_lens"]:
        runs += expand(f"{TRAIN_RUN}/{name}", exp=abl["experiment"], clip_len=abl["clip_lens"], seed=abl["seeds"])
    return sorted(set(runs))


def twin_ablation_runs(twin_run):
    return expand(f"{twin_run}/metrics.json", exp=TWIN_ABL["experiments"], clip_len=TRAIN["clip_len"],
                  seed=TWIN_ABL["seeds"])


def maps_runs(name, configs=MAPS_CONFIGS):
    """`name` of every seed of the mapped configurations (the app picks the best of them)."""
    return expand(f"{TRAIN_RUN}/{name}", exp=configs, clip_len=TRAIN["clip_len"], seed=TRAIN["seeds"])


def maps_datasets():
    """The test sets of the mapped configurations, sorted."""
    return sorted({EXPERIMENTS[c].test_on for c in MAPS_CONFIGS})


def maps_inputs(wildcards):
    inputs = {"metrics": maps_runs("metrics.json"), "scores": maps_runs("scores.npz")}
    inputs.update({ds: TRAIN_DATA[ds] for ds in maps_datasets()})
    inputs["conf"] = conf_files("vessel_maps")
    tested_on_sim = [c for c in MAPS_CONFIGS if EXPERIMENTS[c].test_on == "sim"]  # A-to-A
    if tested_on_sim and config["maps"]["sim_source"] == "slide":
        inputs["checkpoints"] = maps_runs("checkpoint.pt", tested_on_sim)
        inputs["slide"] = rules.simulate_vessel_slide.output.manifest
    return inputs



# The downstream judge of issue 12 (judge.smk): candidate twins, their fits, Sim sets and training runs.
JUDGE_DIR = "results/judge"
JUDGE_FOLDS = ["odd", "even"]
JUDGE_TWINS = ["calibrated", "photo_loop"] + [f"slide_loop_{f}" for f in JUDGE_FOLDS]
# judge.recipe: the recipe every candidate's models train with (null: the profile's train.recipe); with another
# recipe than the main sweep's, photo_loop trains here too instead of reusing the sweep's runs (docs/loop.md)
JUDGE_RECIPE = JUDGE.get("recipe") or TRAIN["recipe"]
# dataset.twin (schema: auto | calibrated | photo_loop | slide_loop): the main Sim set's twin; auto = rule
# twin_choice's (the held-out slide MAE with the tie rule), a name pins it (docs/slides.md "Which twin makes the Sim set")
DATASET_TWIN = config["dataset"]["twin"]
# photo_loop's judge Sim set is the main one only where the main set is pinned to it; else the judge simulates its own
JUDGE_PHOTO_IS_MAIN = DATASET_TWIN == "photo_loop"
JUDGE_OWN_PHOTO = JUDGE_RECIPE != TRAIN["recipe"] or not JUDGE_PHOTO_IS_MAIN
# the dataset-twin ablation's `loop` row (photo loop's twin vs calibrated): the main sweep where the main Sim set is
# the photo loop's, else runs of its own on photo_loop's own Sim set (rule judge_dataset)
PHOTO_SIM = TRAIN_DATA["sim"] if JUDGE_PHOTO_IS_MAIN else f"{JUDGE_DIR}/sim/photo_loop/manifest.json"
TWIN_ABL_LOOP_RUN = TRAIN_RUN if JUDGE_PHOTO_IS_MAIN else str(
    run_dir(f"{TRAIN_DIR}/twin_loop", "{exp}", "{clip_len}", "{seed}"))
# judge.reuse: {twin: {fit: <dir>/twin_fit/fitted.yaml, runs: <runs root>}}: a candidate's fitted twin and trained
# runs taken as they are (an earlier run's, workflow/scripts/judge_reuse.py), so neither is refitted nor retrained;
# only what changed (e.g. the slide loop) reruns (docs/slides.md "Paper-profile run")
JUDGE_REUSE = JUDGE.get("reuse") or {}
for _twin, _spec in JUDGE_REUSE.items():
    if _twin not in JUDGE_TWINS or not isinstance(_spec, dict) or set(_spec) != {"fit", "runs"}:
        raise ValueError(f"config judge.reuse.{_twin}: need a candidate of {JUDGE_TWINS} with keys fit and runs, "
                         f"got {_spec!r} (workflow/profiles/paper/judge_reuse.yaml shows the form)")
JUDGE_TRAINED = [t for t in (["calibrated"] + (["photo_loop"] if JUDGE_OWN_PHOTO else [])
                             + [f"slide_loop_{f}" for f in JUDGE_FOLDS])
                 if t not in JUDGE_REUSE]  # runs judge.smk trains (else photo_loop: the sweep's; reused: as given)
# candidates whose Sim set judge_dataset simulates (calibrated's is the twin ablation's, simulate_dataset_calibrated)
JUDGE_OWN_SETS = ([] if JUDGE_PHOTO_IS_MAIN else ["photo_loop"]) + [f"slide_loop_{f}" for f in JUDGE_FOLDS]
JUDGE_RUN = str(run_dir(f"{JUDGE_DIR}/train/{{twin}}", "{exp}", "{clip_len}", "{seed}"))
JUDGE_EXPERIMENTS = ["A-to-B", "A-to-C"]  # Sim -> Silicone (cross-fitted), Sim -> Meat: both train on Sim
JUDGE_FILES = (
    [f"{JUDGE_DIR}/{n}" for n in ("twin_selection.csv", "twin_selection.md", "slide_motion.png", "slide_motion.pdf",
                                  "drift_bounds.csv")]
    if JUDGE["seeds"] else []
)


def judge_fit(twin):
    if twin in JUDGE_REUSE:
        return JUDGE_REUSE[twin]["fit"]
    if twin == "calibrated":
        return rules.calibrate.output.fit
    if twin == "photo_loop":
        return rules.loop.output.fit
    return f"{JUDGE_DIR}/twins/{twin}/twin_fit/fitted.yaml"


def dataset_fit(wildcards=None):
    """The fitted twin of the main Sim set (simulate_dataset) from dataset.twin: for auto the copy written by
    twin_choice (the evidence's choice, judge.smk), else the pinned candidate's own fit (slide_loop: the first
    fold's twin, as twin_choice takes it)."""
    if DATASET_TWIN == "auto":
        return rules.twin_choice.output.fit
    return judge_fit(f"slide_loop_{JUDGE_FOLDS[0]}" if DATASET_TWIN == "slide_loop" else DATASET_TWIN)


def candidate_sim_sets(wildcards=None):
    """With dataset.twin auto: the calibrated candidate's Sim set, which the twin ablation makes anyway right after
    calibrate, so that simulate_dataset copies it when twin_choice chooses calibrated instead of simulating the same
    draws again (the app compares request keys: draws, twin, mesh; another twin's set is left alone). photo_loop's
    set comes last (after the photo loop and its own simulation): waiting for it held the main set back ~30 s after
    the choice on the paper profile (device run of e80d176), so a chosen photo_loop twin simulates its draws again
    (the same records: neither the streamed gather nor the default resident variant, compact, adds floats atomically)."""
    if DATASET_TWIN != "auto" or not (TWIN_ABL["seeds"] or JUDGE["seeds"]):
        return []
    return [rules.simulate_dataset_calibrated.output.manifest]


def judge_runs_root(twin):
    if twin in JUDGE_REUSE:
        return JUDGE_REUSE[twin]["runs"]
    return TRAIN_DIR if twin == "photo_loop" and not JUDGE_OWN_PHOTO else f"{JUDGE_DIR}/train/{twin}"


def judge_scores():
    return [str(run_dir(judge_runs_root(t), e, TRAIN["clip_len"], s) / "scores.npz")
            for t in JUDGE_TWINS for e in JUDGE_EXPERIMENTS for s in JUDGE["seeds"]]


def judge_sim(wildcards):
    """A trained candidate's Sim set: the calibrated twin's is the twin ablation's (same draws), photo_loop's the main
    one where dataset.twin pins it there, every other its own (rule judge_dataset, the same draws)."""
    if wildcards.twin == "calibrated":
        return rules.simulate_dataset_calibrated.output.manifest
    if wildcards.twin == "photo_loop":
        return PHOTO_SIM
    return f"{JUDGE_DIR}/sim/{wildcards.twin}/manifest.json"


# Every job knows its profile (MLflow tags runs with it) and writes no MLflow artefacts into ./mlruns.
# The prefix is formatted once, not per job, so each shell command starts with `SNAKEMAKE_RULE={params.rule}`
# itself: MLflow tags every run with its rule (palpation.tracking, the job key of a rerun). Each rule passes
# its own name as params.rule and the interpreter as params.py, since `snakemake --lint` flags `{rule}` and
# globals in shell commands.
# Hydra rules declare the conf/ files their app composes (conf_files) so that an edit reruns exactly them.
shell.prefix(f"set -euo pipefail; export PALPATION_PROFILE={PROFILE}; ")
