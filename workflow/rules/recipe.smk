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
    benchmark:
        f"results/benchmarks/train_recipe/{{recipe}}_{{switch}}_{{exp}}_L{{clip_len}}_seed{{seed}}.tsv",
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



# train.seeds_together (the paper profile): one job per (recipe, switch_off, training group) trains all seeds
# of the ablation together (palpation.model.stacked) and scores every configuration of its group
# (recipe_groups: A-to-B and A-to-C train the same models on Sim, so they share one training); each
# (configuration, seed) keeps its own outputs and MLflow run. One rule per group, as a rule's outputs
# cannot depend on its wildcards: train_recipe_seeds_sim_large, train_recipe_seeds_meat_compact, ...
# Robust minus `calibration` trains exactly as robust (the calibration is fitted afterwards), so where the
# ablation has that row the robust job also writes its models' raw scores there (train_recipe_robust_<group>,
# app key also_uncalibrated) instead of a second training.
_SEEDS_SHELL = (("OMP_NUM_THREADS={threads} " if "threads" in TRAIN else "")
                + "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.train"
                " experiment={params.exp} 'seeds={params.seeds}' clip_len={wildcards.clip_len}"
                " device={params.device} {params.overrides} {params.hydra} > {log} 2>&1")
# the app writes seed s of the first configuration to <run dir>/seed<s>/, the others beside it
_SEEDS_HYDRA = lambda wildcards, output: (f"hydra.run.dir={Path(output.metrics[0]).parents[1]}"
                                          " hydra.output_subdir=.hydra/seeds")
_ROBUST = SimpleNamespace(recipe="robust", switch="none")
_UNCALIBRATED = str(recipe_root(RECIPE_DIR, "robust", "calibration"))
if TRAIN["seeds_together"] and RECIPE_ABL["seeds"]:
    for _group, _exps in recipe_groups().items():

        rule:
            name:
                f"train_recipe_seeds_{_group}"
            input:
                unpack(partial(recipe_inputs, exps=_exps)),
            output:
                **recipe_seed_outputs(_exps, "{recipe}", "{switch}"),
            log:
                f"results/logs/recipe/{{recipe}}_{{switch}}_{_group}_L{{clip_len}}_seeds.log",
            benchmark:
                f"results/benchmarks/train_recipe_seeds_{_group}/{{recipe}}_{{switch}}_L{{clip_len}}_seeds.tsv",
            wildcard_constraints:
                recipe="reference|robust",
                switch=r"[a-z_]+",
                clip_len=str(TRAIN["clip_len"]),
            params:
                rule=f"train_recipe_seeds_{_group}",
                py=PY,
                exp=_exps[0],
                overrides=partial(recipe_overrides, exps=_exps),
                seeds=yaml_list(RECIPE_ABL["seeds"]),
                hydra=_SEEDS_HYDRA,
                profile=PROFILE,
                device=config["device"],
            threads: TRAIN.get("threads", 1)
            resources:
                gpu=GPU,
            conda:
                CONDA_ENV
            shell:
                _SEEDS_SHELL

        workflow.ruleorder(f"train_recipe_seeds_{_group}", "train_recipe")  # `ruleorder:` takes literal names
        if not recipe_shares_calibration(_exps):
            continue

        rule:
            name:
                f"train_recipe_robust_{_group}"
            input:
                unpack(lambda wildcards, exps=_exps: recipe_inputs(_ROBUST, exps)),
            output:
                **recipe_seed_outputs(_exps, "robust", "none", "calibration"),
            log:
                f"results/logs/recipe/robust_none_{_group}_L{{clip_len}}_seeds.log",
            benchmark:
                f"results/benchmarks/train_recipe_robust_{_group}/robust_none_L{{clip_len}}_seeds.tsv",
            wildcard_constraints:
                clip_len=str(TRAIN["clip_len"]),
            params:
                rule=f"train_recipe_robust_{_group}",
                py=PY,
                exp=_exps[0],
                overrides=lambda wildcards, exps=_exps: (f"{recipe_overrides(_ROBUST, exps)}"
                                                         f" also_uncalibrated={_UNCALIBRATED}"),
                seeds=yaml_list(RECIPE_ABL["seeds"]),
                hydra=_SEEDS_HYDRA,
                profile=PROFILE,
                device=config["device"],
            threads: TRAIN.get("threads", 1)
            resources:
                gpu=GPU,
            conda:
                CONDA_ENV
            shell:
                _SEEDS_SHELL

        workflow.ruleorder(f"train_recipe_robust_{_group}", f"train_recipe_seeds_{_group}")
        workflow.ruleorder(f"train_recipe_robust_{_group}", "train_recipe")


# One target rule per row group of the ablation, `recipe_<recipe>_<switch_off>` (e.g. `snakemake recipe_robust_none`):
# its runs for every configuration the report reads, so a device session can run a part of the ablation
# (workflow/scripts/gpu_recipe_ablation.sh PART=...).
for _recipe, _switch in dict.fromkeys(g for exp in RECIPE_ABL["experiments"] for g in recipe_switch_groups(exp)):

    rule:
        name:
            f"recipe_{_recipe}_{_switch}"
        input:
            [f for f in recipe_runs("metrics.json") if f"/{_recipe}/{_switch}/" in f],


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
    benchmark:
        "results/benchmarks/recipe_report.tsv",
    params:
        rule="recipe_report",
        py=PY,
        experiments=yaml_list(RECIPE_ABL["experiments"]),
        seeds=yaml_list(RECIPE_ABL["seeds"]),
        switches=yaml_list(RECIPE_ABL["switches"]),
        switch_experiments=yaml_list(RECIPE_ABL.get("switch_experiments", RECIPE_ABL["experiments"])),
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
        " 'switch_experiments={params.switch_experiments}'"
        " clip_len={params.clip_len} {params.data} hydra.run.dir={params.out_dir} > {log} 2>&1"


# Calibration and map threshold cross-fitted between the two real sets (docs/recipe.md "Cross-fitted calibration"):
# from the stored runs (no retraining), each Sim-trained model calibrated on its own scores on the other real set.
# CPU, about a minute. In the run (rule all, read by results_page) where RECIPE_CROSSFIT_FILES (common.smk) is set;
# else on demand: `snakemake results/recipe/report/recipe_calibration_crossfit.csv`.
if RECIPE_ABL["seeds"]:

    rule recipe_crossfit:
        input:
            metrics=recipe_runs("metrics.json"),
            scores=recipe_runs("scores.npz"),
            data=list(dict.fromkeys(TRAIN_DATA[EXPERIMENTS[e].test_on] for e in RECIPE_ABL["experiments"])),  # the real sets
            conf=conf_files("recipe_crossfit") + conf_files("vessel_maps"),
        output:
            RECIPE_CROSSFIT_OUTPUTS,
        log:
            "results/logs/recipe_crossfit.log",
        benchmark:
            "results/benchmarks/recipe_crossfit.tsv",
        params:
            rule="recipe_crossfit",
            py=PY,
            experiments=yaml_list(RECIPE_ABL["experiments"]),
            seeds=yaml_list(RECIPE_ABL["seeds"]),
            switches=yaml_list(RECIPE_ABL["switches"]),
            switch_experiments=yaml_list(RECIPE_ABL.get("switch_experiments", RECIPE_ABL["experiments"])),
            clip_len=TRAIN["clip_len"],
            profile=PROFILE,
            data=" ".join(f"data.{k}={v}" for k, v in TRAIN_DATA.items()),
            runs_root=lambda wildcards, input: Path(input.metrics[0]).parents[5],
            out_dir=lambda wildcards, output: Path(output[0]).parent,
        conda:
            CONDA_ENV
        shell:
            "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.recipe_crossfit"
            " profile={params.profile} runs_root={params.runs_root} out_dir={params.out_dir}"
            " 'experiments={params.experiments}' 'seeds={params.seeds}' 'switches={params.switches}'"
            " 'switch_experiments={params.switch_experiments}'"
            " clip_len={params.clip_len} {params.data} hydra.run.dir={params.out_dir} > {log} 2>&1"
