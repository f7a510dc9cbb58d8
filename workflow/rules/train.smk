# Train the ST-GNN per configuration x clip length x seed and gather Fig. 6, Tables 3-4 (SPEC §8-§11).
# The grids come from the profile's `train:` mapping (conf/workflow/<profile>.yaml):
#   experiments, seeds, clip_len            the seed sweep (Fig. 6, Table 4, seed_sweep.csv)
#   ablation: {experiment, clip_lens, seeds} Table 3 (clip_lens: [] skips it)
#   sizes: {large: {...}, compact: {...}}    size knobs passed as train.<key>=<value> overrides
#                                            (batch_size, epochs, train_batches, val_batches; null keeps
#                                            the recipe's value)
#   recipe                                  reference | better
# Run folders: results/train/<exp>/L<clip_len>/seed<seed>/ (palpation.report.runs.run_dir).

TRAIN = config.get("train", {})
TRAIN_DIR = "results/train"
TRAIN_RUN = f"{TRAIN_DIR}/{{exp}}/L{{clip_len}}/seed{{seed}}"
TRAIN_REPORT = f"{TRAIN_DIR}/report"
TRAIN_DATA = {
    "sim": "results/sim/dataset/manifest.json",  # rule simulate_dataset
    "silicone": "results/data/silicone/silicone.npz",
    "meat": "results/data/meat/meat.npz",
}
# datasets and model size per configuration (conf/experiment/*.yaml holds the same choice)
EXPERIMENTS = {
    "A-to-A": (("sim",), "large"),
    "A-to-B": (("sim", "silicone"), "large"),
    "A-to-C": (("sim", "meat"), "large"),
    "C-to-B": (("meat", "silicone"), "compact"),
}


def train_data(wildcards, sim=TRAIN_DATA["sim"]):
    return {name: sim if name == "sim" else TRAIN_DATA[name] for name in EXPERIMENTS[wildcards.exp][0]}


def train_inputs(wildcards, sim=TRAIN_DATA["sim"]):
    """The datasets and the conf/ files of this configuration (experiment overlay, model, recipe)."""
    choices = {"experiment": wildcards.exp, "model": EXPERIMENTS[wildcards.exp][1],
               "recipe": TRAIN.get("recipe", "reference")}
    return {**train_data(wildcards, sim), "conf": conf_files("train", choices)}


def train_overrides(wildcards, sim=TRAIN_DATA["sim"]):
    """Dataset paths and the profile's size knobs for this configuration's model, as Hydra overrides."""
    data = [f"data.{k}={v}" for k, v in train_data(wildcards, sim).items()]
    sizes = TRAIN.get("sizes", {}).get(EXPERIMENTS[wildcards.exp][1]) or {}
    knobs = [f"train.{k}={v}" for k, v in sizes.items() if v is not None]
    return " ".join(data + knobs + [f"recipe={TRAIN.get('recipe', 'reference')}"])


def sweep_runs(name):
    """`name` (metrics.json, scores.npz) of every run the report reads."""
    runs = expand(f"{TRAIN_RUN}/{name}", exp=TRAIN.get("experiments", list(EXPERIMENTS)),
                  clip_len=TRAIN.get("clip_len", 5), seed=TRAIN.get("seeds", [0, 1, 2, 3, 4]))
    abl = TRAIN.get("ablation", {})
    if abl.get("clip_lens"):
        runs += expand(f"{TRAIN_RUN}/{name}", exp=abl.get("experiment", "A-to-B"),
                       clip_len=abl["clip_lens"], seed=abl.get("seeds", [0, 1, 2]))
    return sorted(set(runs))


def yaml_list(values):
    return "[" + ",".join(str(v) for v in values) + "]"


_CAPTIONS = {"fig6_pr_curves.png": "fig6_pr_curves.rst", "seed_sweep.csv": "seed_sweep.rst"}
TRAIN_REPORT_FILES = [
    (report(f"{TRAIN_REPORT}/{name}", caption=f"../report/{_CAPTIONS[name]}", category="ST-GNN")
     if name in _CAPTIONS else f"{TRAIN_REPORT}/{name}")
    for name in ("seed_sweep.csv", "seed_sweep.md", "table4_markers.csv", "table4_markers.md",
                 "fig6_pr_curves.png", "fig6_pr_curves.pdf", "bench_train.json")
] + ([f"{TRAIN_REPORT}/clip_len_ablation.csv", f"{TRAIN_REPORT}/table3_clip_len.md"]
     if TRAIN.get("ablation", {}).get("clip_lens") else [])


rule train:
    input:
        unpack(train_inputs),
    output:
        metrics=f"{TRAIN_RUN}/metrics.json",
        scores=f"{TRAIN_RUN}/scores.npz",
        pr=f"{TRAIN_RUN}/pr.npz",
        checkpoint=f"{TRAIN_RUN}/checkpoint.pt",
    log:
        "results/logs/train/{exp}_L{clip_len}_seed{seed}.log",
    wildcard_constraints:
        exp="|".join(EXPERIMENTS),
        clip_len=r"\d+",
        seed=r"\d+",
    params:
        overrides=train_overrides,
        hydra=lambda wildcards, output: hydra_dir(output.metrics),
        profile=PROFILE,
        device=config.get("device", "cpu"),
    threads: TRAIN.get("threads", 1)
    resources:
        gpu=1 if config.get("device") == "cuda" else 0,
    shell:
        # train.threads (paper profile) caps torch's CPU threads so that parallel runs do not oversubscribe
        ("OMP_NUM_THREADS={threads} " if "threads" in TRAIN else "")
        + "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={rule} {PY} palpation.apps.train"
        " experiment={wildcards.exp} seed={wildcards.seed} clip_len={wildcards.clip_len}"
        " device={params.device} {params.overrides} {params.hydra} > {log} 2>&1"


rule train_report:
    input:
        metrics=sweep_runs("metrics.json"),
        scores=sweep_runs("scores.npz"),
        conf=conf_files("train_tables"),
    output:
        TRAIN_REPORT_FILES,
    log:
        "results/logs/train_report.log",
    params:
        experiments=yaml_list(TRAIN.get("experiments", list(EXPERIMENTS))),
        seeds=yaml_list(TRAIN.get("seeds", [0, 1, 2, 3, 4])),
        clip_len=TRAIN.get("clip_len", 5),
        profile=PROFILE,
        runs_root=lambda wildcards, input: Path(input.metrics[0]).parents[3],  # <root>/<exp>/L<n>/seed<s>
        out_dir=lambda wildcards, output: Path(output[0]).parent,
        ablation=lambda wildcards: (
            f"ablation.experiment={TRAIN.get('ablation', {}).get('experiment', 'A-to-B')}"
            f" 'ablation.clip_lens={yaml_list(TRAIN.get('ablation', {}).get('clip_lens', []))}'"
            f" 'ablation.seeds={yaml_list(TRAIN.get('ablation', {}).get('seeds', [0, 1, 2]))}'"
        ),
    shell:
        "SNAKEMAKE_RULE={rule} {PY} palpation.apps.train_tables profile={params.profile} runs_root={params.runs_root}"
        " out_dir={params.out_dir} 'experiments={params.experiments}' 'seeds={params.seeds}'"
        " clip_len={params.clip_len} {params.ablation} hydra.run.dir={params.out_dir} > {log} 2>&1"


# Dataset-twin ablation (train.twin_ablation: {experiments, seeds}; empty seeds skip it): the same
# models trained on Sim data from the calibration-only twin, beside the main sweep's loop-twin data.
TWIN_ABL = TRAIN.get("twin_ablation") or {}
TWIN_ABL_SIM = "results/sim/dataset_calibrated/manifest.json"  # rule simulate_dataset_calibrated
TWIN_ABL_RUN = f"{TRAIN_DIR}/twin_calibrated/{{exp}}/L{{clip_len}}/seed{{seed}}"
TWIN_ABLATION_FILES = (
    [f"{TRAIN_REPORT}/twin_ablation.csv", f"{TRAIN_REPORT}/twin_ablation.md"] if TWIN_ABL.get("seeds") else []
)


use rule train as train_twin_ablation with:
    input:
        unpack(lambda wildcards: train_inputs(wildcards, TWIN_ABL_SIM)),
    output:
        metrics=f"{TWIN_ABL_RUN}/metrics.json",
        scores=f"{TWIN_ABL_RUN}/scores.npz",
        pr=f"{TWIN_ABL_RUN}/pr.npz",
        checkpoint=f"{TWIN_ABL_RUN}/checkpoint.pt",
    log:
        "results/logs/train/twin_calibrated_{exp}_L{clip_len}_seed{seed}.log",
    params:
        overrides=lambda wildcards: train_overrides(wildcards, TWIN_ABL_SIM),


def twin_ablation_runs(twin_run):
    return expand(f"{twin_run}/metrics.json", exp=TWIN_ABL.get("experiments", ["A-to-B"]),
                  clip_len=TRAIN.get("clip_len", 5), seed=TWIN_ABL.get("seeds", []))


rule twin_ablation_report:
    input:
        loop=twin_ablation_runs(TRAIN_RUN),
        calibrated=twin_ablation_runs(TWIN_ABL_RUN),
        conf=conf_files("twin_ablation"),
    output:
        TWIN_ABLATION_FILES,
    log:
        "results/logs/twin_ablation.log",
    params:
        experiments=yaml_list(TWIN_ABL.get("experiments", ["A-to-B"])),
        seeds=yaml_list(TWIN_ABL.get("seeds", [])),
        clip_len=TRAIN.get("clip_len", 5),
        profile=PROFILE,
    shell:
        "SNAKEMAKE_RULE={rule} {PY} palpation.apps.twin_ablation profile={params.profile} 'experiments={params.experiments}'"
        " 'seeds={params.seeds}' clip_len={params.clip_len} twins.loop={TRAIN_DIR}"
        " twins.calibrated={TRAIN_DIR}/twin_calibrated out_dir={TRAIN_REPORT} > {log} 2>&1"
