# The recipe ablation (issue 15): the large/compact ST-GNN trained with recipe=reference and
# recipe=robust, and robust with one switch turned off (palpation.model.recipe.SWITCHES), per
# configuration x seed of the profile's train.recipe_ablation; then the ablation table, reliability
# diagrams and the seed-ensemble uncertainty maps (palpation.apps.recipe_report). Helpers: common.smk
# (recipe_inputs, recipe_overrides, recipe_runs). Runs: results/recipe/<recipe>/<switch_off>/<exp>/L<n>/seed<s>/.


rule train_recipe:
    input:
        unpack(recipe_inputs),
    output:
        metrics=f"{RECIPE_RUN}/metrics.json",
        scores=f"{RECIPE_RUN}/scores.npz",
        pr=f"{RECIPE_RUN}/pr.npz",
        checkpoint=f"{RECIPE_RUN}/checkpoint.pt",
    log:
        "results/logs/recipe/{recipe}_{switch}_{exp}_L{clip_len}_seed{seed}.log",
    wildcard_constraints:
        recipe="reference|robust",
        switch=r"[a-z_]+",
        exp="|".join(EXPERIMENTS),
        clip_len=r"\d+",
        seed=r"\d+",
    params:
        rule="train_recipe",
        py=PY,
        overrides=recipe_overrides,
        hydra=lambda wildcards, output: hydra_dir(output.metrics),
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
        " experiment={wildcards.exp} seed={wildcards.seed} clip_len={wildcards.clip_len}"
        " device={params.device} {params.overrides} {params.hydra} > {log} 2>&1"


rule recipe_report:
    input:
        metrics=recipe_runs("metrics.json"),
        scores=recipe_runs("scores.npz"),
        data=list(TRAIN_DATA.values()),
        conf=conf_files("recipe_report") + conf_files("vessel_maps"),
    output:
        RECIPE_REPORT_FILES,
    log:
        "results/logs/recipe_report.log",
    params:
        rule="recipe_report",
        py=PY,
        experiments=yaml_list(RECIPE_ABL["experiments"]),
        seeds=yaml_list(RECIPE_ABL["seeds"]),
        switches=yaml_list(RECIPE_ABL["switches"]),
        clip_len=TRAIN["clip_len"],
        profile=PROFILE,
        data=" ".join(f"data.{k}={v}" for k, v in TRAIN_DATA.items()),
        runs_root=lambda wildcards, input: Path(input.metrics[0]).parents[5],
        out_dir=lambda wildcards, output: Path(output[0]).parent,
    conda:
        CONDA_ENV
    shell:
        "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.recipe_report"
        " profile={params.profile} runs_root={params.runs_root} out_dir={params.out_dir}"
        " 'experiments={params.experiments}' 'seeds={params.seeds}' 'switches={params.switches}'"
        " clip_len={params.clip_len} {params.data} hydra.run.dir={params.out_dir} > {log} 2>&1"
