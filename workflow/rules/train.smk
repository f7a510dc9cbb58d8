# Train the ST-GNN per configuration x clip length x seed and gather Fig. 6, Tables 3-4 (SPEC §8-§11).
# The grids come from the profile's `train:` mapping (conf/workflow/<profile>.yaml; the keys, their
# defaults and meaning: workflow/schemas/config.schema.yaml); what each configuration trains and tests
# on and its model size come from conf/experiment/<name>.yaml (palpation.experiments). The helpers
# (train_inputs, train_overrides, sweep_runs, ...) are in common.smk.
# Run folders: results/train/<exp>/L<clip_len>/seed<seed>/ (palpation.report.runs.run_dir).

_CAPTIONS = {"fig6_pr_curves.png": "fig6_pr_curves.rst", "seed_sweep.csv": "seed_sweep.rst",
             "table4_markers.csv": "table4_markers.rst"}
TRAIN_REPORT_FILES = [
    (report(f"{TRAIN_REPORT}/{name}", caption=f"../report/{_CAPTIONS[name]}", category="ST-GNN")
     if name in _CAPTIONS else f"{TRAIN_REPORT}/{name}")
    for name in ("seed_sweep.csv", "seed_sweep.md", "table4_markers.csv", "table4_markers.md",
                 "fig6_pr_curves.png", "fig6_pr_curves.pdf", "bench_train.json")
] + ([report(f"{TRAIN_REPORT}/clip_len_ablation.csv", caption="../report/table3_clip_len.rst", category="ST-GNN"),
      f"{TRAIN_REPORT}/table3_clip_len.md"]
     if TRAIN["ablation"]["clip_lens"] else [])


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
    benchmark:
        f"results/benchmarks/train/{{exp}}_L{{clip_len}}_seed{{seed}}.tsv",
    wildcard_constraints:
        exp="|".join(EXPERIMENTS),
        clip_len=r"\d+",
        seed=r"\d+",
    params:
        rule="train",
        py=PY,
        overrides=train_overrides,
        hydra=lambda wildcards, output: hydra_dir(output.metrics),
        profile=PROFILE,
        device=config["device"],
    threads: TRAIN.get("threads", 1)
    resources:
        gpu=GPU,
    conda:
        CONDA_ENV
    shell:
        # train.threads (paper profile) caps torch's CPU threads so that parallel runs do not oversubscribe
        ("OMP_NUM_THREADS={threads} " if "threads" in TRAIN else "")
        + "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.train"
        " experiment={wildcards.exp} seed={wildcards.seed} clip_len={wildcards.clip_len}"
        " device={params.device} {params.overrides} {params.hydra} > {log} 2>&1"


# train.seeds_together (the paper profile): all seeds of a sweep configuration in one process, the seeds'
# models stacked on the GPU (palpation.model.stacked, issue 17); each seed keeps its own draws, early
# stopping, outputs and MLflow run. Clip lengths other than train.clip_len (the Table 3 ablation) still
# train one seed per job through rule train.
if TRAIN["seeds_together"]:

    rule train_seeds:
        input:
            unpack(train_inputs),
        output:
            metrics=expand(f"{TRAIN_RUN}/metrics.json", seed=TRAIN["seeds"], allow_missing=True),
            scores=expand(f"{TRAIN_RUN}/scores.npz", seed=TRAIN["seeds"], allow_missing=True),
            pr=expand(f"{TRAIN_RUN}/pr.npz", seed=TRAIN["seeds"], allow_missing=True),
            checkpoint=expand(f"{TRAIN_RUN}/checkpoint.pt", seed=TRAIN["seeds"], allow_missing=True),
        log:
            "results/logs/train/{exp}_L{clip_len}_seeds.log",
        benchmark:
            f"results/benchmarks/train_seeds/{{exp}}_L{{clip_len}}_seeds.tsv",
        wildcard_constraints:
            exp="|".join(TRAIN["experiments"]),
            clip_len=str(TRAIN["clip_len"]),
        params:
            rule="train_seeds",
            py=PY,
            overrides=train_overrides,
            seeds=yaml_list(TRAIN["seeds"]),
            # the app writes seed s to <run dir>/seed<s>/, so the run dir is the L<clip_len> folder
            hydra=lambda wildcards, output: (f"hydra.run.dir={Path(output.metrics[0]).parents[1]}"
                                             " hydra.output_subdir=.hydra/seeds"),
            profile=PROFILE,
            device=config["device"],
        threads: TRAIN.get("threads", 1)
        resources:
            gpu=GPU,
        conda:
            CONDA_ENV
        shell:
            ("OMP_NUM_THREADS={threads} " if "threads" in TRAIN else "")
            + "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.train"
            " experiment={wildcards.exp} 'seeds={params.seeds}' clip_len={wildcards.clip_len}"
            " device={params.device} {params.overrides} {params.hydra} > {log} 2>&1"

    ruleorder: train_seeds > train

    # The clip-length ablation's other lengths (Table 3): its seeds together too, one job per length.
    _ABL = TRAIN["ablation"]
    _ABL_LENS = [str(n) for n in _ABL["clip_lens"] if n != TRAIN["clip_len"]]
    if _ABL_LENS and _ABL["seeds"]:

        use rule train_seeds as train_ablation_seeds with:
            output:
                metrics=expand(f"{TRAIN_RUN}/metrics.json", seed=_ABL["seeds"], allow_missing=True),
                scores=expand(f"{TRAIN_RUN}/scores.npz", seed=_ABL["seeds"], allow_missing=True),
                pr=expand(f"{TRAIN_RUN}/pr.npz", seed=_ABL["seeds"], allow_missing=True),
                checkpoint=expand(f"{TRAIN_RUN}/checkpoint.pt", seed=_ABL["seeds"], allow_missing=True),
            log:
                "results/logs/train/{exp}_L{clip_len}_ablation_seeds.log",
            benchmark:
                f"results/benchmarks/train_ablation_seeds/{{exp}}_L{{clip_len}}_seeds.tsv",
            wildcard_constraints:
                exp=_ABL["experiment"],
                clip_len="|".join(_ABL_LENS),
            params:
                rule="train_ablation_seeds",
                seeds=yaml_list(_ABL["seeds"]),

        ruleorder: train_ablation_seeds > train


# Configurations that train alike (train_groups: A-to-A, A-to-B and A-to-C all train the large model on Sim) train
# once and score every test set (app key also_test), at the profile's clip length: one job per seed, or per group
# with train.seeds_together. Each keeps its run folder and MLflow run; one seed's outputs are byte for byte rule
# train's (tests/apps/test_train_app.py). The clip-length ablation's other lengths train through rule train (or,
# with seeds together, train_ablation_seeds above).
for _group, _exps in train_groups(TRAIN["experiments"]).items():
    if len(_exps) < 2:
        continue
    _together = TRAIN["seeds_together"]

    rule:
        name:
            f"train_shared_{_group}"
        input:
            unpack(lambda wildcards, e=_exps: group_inputs(e)),
        output:
            **shared_outputs(_exps, None if _together else "{seed}"),
        priority: 5  # the main sweep's models before the ablations' (the paper profile's critical path)
        log:
            f"results/logs/train/{_group}_L{{clip_len}}_" + ("seeds.log" if _together else "seed{seed}.log"),
        benchmark:
            f"results/benchmarks/train_shared_{_group}/L{{clip_len}}_" + ("seeds.tsv" if _together else "seed{seed}.tsv"),
        wildcard_constraints:
            clip_len=str(TRAIN["clip_len"]),
            seed=r"\d+",
        params:
            rule=f"train_shared_{_group}",
            py=PY,
            exp=_exps[0],
            overrides=lambda wildcards, e=_exps: group_overrides(e),
            seeds=lambda wildcards, t=_together: f"'seeds={yaml_list(TRAIN['seeds'])}'" if t else f"seed={wildcards.seed}",
            # the app writes each configuration beside the first's run folder (its L<n> folder with seeds together)
            hydra=lambda wildcards, output, t=_together: (f"hydra.run.dir={Path(output.metrics[0]).parents[1]}"
                                                          " hydra.output_subdir=.hydra/seeds") if t
                                                         else hydra_dir(output.metrics[0]),
            profile=PROFILE,
            device=config["device"],
        threads: TRAIN.get("threads", 1)
        resources:
            gpu=GPU,
        conda:
            CONDA_ENV
        shell:
            ("OMP_NUM_THREADS={threads} " if "threads" in TRAIN else "")
            + "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.train"
            " experiment={params.exp} {params.seeds} clip_len={wildcards.clip_len} device={params.device}"
            " {params.overrides} {params.hydra} > {log} 2>&1"

    workflow.ruleorder(f"train_shared_{_group}", "train")
    if _together:
        workflow.ruleorder(f"train_shared_{_group}", "train_seeds")


# Seeds together vs apart on A-to-A at the recipe's sizes (issue 17; `snakemake bench`, not part of `all`):
# docs/results/bench_train.json is this file from the H100.
rule bench_train:
    input:
        sim=TRAIN_DATA["sim"],
        conf=conf_files("train", {"experiment": "A-to-A", "model": EXPERIMENTS["A-to-A"].model,
                                  "recipe": TRAIN["recipe"]}),
    output:
        json="results/bench/train.json",
    params:
        py=PY,
        device=config["device"],
        seeds=" ".join(str(s) for s in TRAIN["seeds"]),
        recipe=TRAIN["recipe"],
    resources:
        gpu=GPU,
    log:
        "results/logs/bench/train.log",
    benchmark:
        "results/benchmarks/bench_train.tsv",
    conda:
        CONDA_ENV
    shell:
        "{params.py} palpation.model.benchmark --device {params.device} --sim {input.sim} --seeds {params.seeds}"
        " --out {output.json} --override recipe={params.recipe} > {log} 2>&1"


rule train_report:
    input:
        metrics=sweep_runs("metrics.json"),
        scores=sweep_runs("scores.npz"),
        conf=conf_files("train_tables"),
    output:
        TRAIN_REPORT_FILES,
    log:
        "results/logs/train_report.log",
    benchmark:
        "results/benchmarks/train_report.tsv",
    params:
        rule="train_report",
        py=PY,
        experiments=yaml_list(TRAIN["experiments"]),
        seeds=yaml_list(TRAIN["seeds"]),
        clip_len=TRAIN["clip_len"],
        profile=PROFILE,
        runs_root=lambda wildcards, input: runs_root(input.metrics[0]),
        out_dir=lambda wildcards, output: Path(output[0]).parent,
        ablation=(
            f"ablation.experiment={TRAIN['ablation']['experiment']}"
            f" 'ablation.clip_lens={yaml_list(TRAIN['ablation']['clip_lens'])}'"
            f" 'ablation.seeds={yaml_list(TRAIN['ablation']['seeds'])}'"
        ),
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.train_tables profile={params.profile}"
        " runs_root={params.runs_root} out_dir={params.out_dir} 'experiments={params.experiments}'"
        " 'seeds={params.seeds}' clip_len={params.clip_len} {params.ablation} hydra.run.dir={params.out_dir}"
        " > {log} 2>&1"


# Dataset-twin ablation (train.twin_ablation: {experiments, seeds}; empty seeds skip it): the same
# models trained on Sim data from the calibration-only twin, beside the photo loop's twin's data (the main sweep's
# where dataset.twin is photo_loop).
# The calibrated twin's Sim set is rule simulate_dataset_calibrated's (dataset.smk), looked up when a job
# needs it.
use rule train as train_twin_ablation with:
    input:
        unpack(lambda wildcards: train_inputs(wildcards, rules.simulate_dataset_calibrated.output.manifest)),
    output:
        metrics=f"{TWIN_ABL_RUN}/metrics.json",
        scores=f"{TWIN_ABL_RUN}/scores.npz",
        pr=f"{TWIN_ABL_RUN}/pr.npz",
        checkpoint=f"{TWIN_ABL_RUN}/checkpoint.pt",
    log:
        "results/logs/train/twin_calibrated_{exp}_L{clip_len}_seed{seed}.log",
    benchmark:
        f"results/benchmarks/train_twin_ablation/twin_calibrated_{{exp}}_L{{clip_len}}_seed{{seed}}.tsv",
    params:
        rule="train_twin_ablation",
        overrides=lambda wildcards: train_overrides(wildcards, rules.simulate_dataset_calibrated.output.manifest),


# Its `loop` row where dataset.twin is not photo_loop (the main sweep then trains on another twin's Sim set): the same
# models on the photo loop's own Sim set (rule judge_dataset, the same draws), so the row keeps its meaning.
if TWIN_ABL_LOOP_RUN != TRAIN_RUN:

    use rule train as train_twin_ablation_loop with:
        input:
            unpack(lambda wildcards: train_inputs(wildcards, PHOTO_SIM)),
        output:
            metrics=f"{TWIN_ABL_LOOP_RUN}/metrics.json",
            scores=f"{TWIN_ABL_LOOP_RUN}/scores.npz",
            pr=f"{TWIN_ABL_LOOP_RUN}/pr.npz",
            checkpoint=f"{TWIN_ABL_LOOP_RUN}/checkpoint.pt",
        log:
            "results/logs/train/twin_loop_{exp}_L{clip_len}_seed{seed}.log",
        benchmark:
            f"results/benchmarks/train_twin_ablation_loop/twin_loop_{{exp}}_L{{clip_len}}_seed{{seed}}.tsv",
        params:
            rule="train_twin_ablation_loop",
            overrides=lambda wildcards: train_overrides(wildcards, PHOTO_SIM),


# With train.seeds_together the ablation's seeds train in one process per twin too, as the main sweep's do (its rows
# move within seed noise, as the sweep's did when its seeds were stacked; docs/journal/2026-11-28-readme-history.md,
# "Wall time"): one job of train.threads instead of one a seed, whose cores the clip-length trainings waited for on the
# paper profile's critical path (issue 17).
if TRAIN["seeds_together"] and TWIN_ABL["seeds"]:
    _TWIN_ABL_TWINS = ["calibrated"] + (["loop"] if TWIN_ABL_LOOP_RUN != TRAIN_RUN else [])

    use rule train_seeds as train_twin_ablation_seeds with:
        input:
            unpack(lambda wildcards: train_inputs(wildcards, twin_ablation_sim(wildcards))),
        output:
            **run_files(expand(run_dir(f"{TRAIN_DIR}/twin_{{twin}}", "{exp}", "{clip_len}", "{seed}"),
                               seed=TWIN_ABL["seeds"], allow_missing=True)),
        log:
            "results/logs/train/twin_{twin}_{exp}_L{clip_len}_seeds.log",
        benchmark:
            "results/benchmarks/train_twin_ablation_seeds/twin_{twin}_{exp}_L{clip_len}_seeds.tsv",
        wildcard_constraints:
            twin="|".join(_TWIN_ABL_TWINS),
            exp="|".join(TWIN_ABL["experiments"]),
            clip_len=str(TRAIN["clip_len"]),
        params:
            rule="train_twin_ablation_seeds",
            seeds=yaml_list(TWIN_ABL["seeds"]),
            overrides=lambda wildcards: train_overrides(wildcards, twin_ablation_sim(wildcards)),

    ruleorder: train_twin_ablation_seeds > train_twin_ablation
    if "loop" in _TWIN_ABL_TWINS:
        workflow.ruleorder("train_twin_ablation_seeds", "train_twin_ablation_loop")


rule twin_ablation_report:
    input:
        loop=twin_ablation_runs(TWIN_ABL_LOOP_RUN),
        calibrated=twin_ablation_runs(TWIN_ABL_RUN),
        conf=conf_files("twin_ablation"),
    output:
        TWIN_ABLATION_FILES,
    log:
        "results/logs/twin_ablation.log",
    benchmark:
        "results/benchmarks/twin_ablation_report.tsv",
    params:
        rule="twin_ablation_report",
        py=PY,
        experiments=yaml_list(TWIN_ABL["experiments"]),
        seeds=yaml_list(TWIN_ABL["seeds"]),
        clip_len=TRAIN["clip_len"],
        profile=PROFILE,
        loop_runs=lambda wildcards, input: runs_root(input.loop[0]),
        calibrated_runs=lambda wildcards, input: runs_root(input.calibrated[0]),
        out_dir=lambda wildcards, output: Path(output[0]).parent,
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.twin_ablation profile={params.profile}"
        " 'experiments={params.experiments}' 'seeds={params.seeds}' clip_len={params.clip_len}"
        " twins.loop={params.loop_runs} twins.calibrated={params.calibrated_runs} out_dir={params.out_dir}"
        " > {log} 2>&1"
