# Issue 12: the downstream judge (docs/slides.md "Twin on the task"). Each candidate twin gets a Sim set and
# A-to-B / A-to-C models (judge.seeds); Silicone trials are scored cross-fitted (a fold twin's models only on
# the other fold's trials); the twin is chosen by its held-out real-slide motion MAE (no test labels).
# Candidates: calibrated (calibrate.smk), photo_loop (loop.smk), slide_loop_odd / slide_loop_even (the
# slide loop's fold twins, slides.smk). Reuses what exists: photo_loop's runs = the main sweep (results/train) where
# dataset.twin pins the main Sim set to photo_loop and judge.recipe is the sweep's; calibrated's Sim set = the twin
# ablation's (dataset.smk). Rule twin_choice picks the main Sim set's twin for dataset.twin auto (common.smk
# dataset_fit) from the replays alone. calibrated and the fold twins train here
# (results/judge/train/<twin>), all seeds of a configuration in one process where train.seeds_together.
# Needs common.smk (JUDGE*, judge_* helpers, PY, TWIN_ARGS, fit_overrides, hydra_dir) and the rule files above.
# Opt-in: judge.seeds [] (quick, tiny) leaves it out of `all`; the paper profile turns it on, and
# workflow/profiles/tiny/judge.yaml does for tiny (the CPU check of workflow/scripts/gpu_judge.sh).

JUDGE_CONF = conf_files("twin_judge", {"twin/mesh": config["twin_resolution"]})


rule judge_fold_twin:
    input:
        json=rules.slide_loop.output.json,
        conf=JUDGE_CONF,
    output:
        fit=f"{JUDGE_DIR}/twins/slide_loop_{{fold}}/twin_fit/fitted.yaml",
    wildcard_constraints:
        fold="|".join(JUDGE_FOLDS),
    params:
        rule="judge_fold_twin",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.fit),
    log:
        "results/logs/judge/fold_twin_{fold}.log",
    benchmark:
        f"results/benchmarks/judge_fold_twin/fold_twin_{{fold}}.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.twin_judge task=fold_twin fold={wildcards.fold}"
        " slide_loop={input.json} out.fit={output.fit} {params.hydra} > {log} 2>&1"


rule judge_slides:
    input:
        fit=lambda wildcards: judge_fit(wildcards.twin),
        json=rules.slide_loop.output.json,
        npz=rules.silicone_sequences.output.npz,
        mesh=twin_mesh(),
        conf=JUDGE_CONF,
    output:
        json=f"{JUDGE_DIR}/slides/{{twin}}.json",
        npz=f"{JUDGE_DIR}/slides/{{twin}}.npz",
    wildcard_constraints:
        twin="|".join(JUDGE_TWINS),
    params:
        rule="judge_slides",
        py=PY,
        twin=f"{TWIN_ARGS} {JUDGE['twin']}".strip(),
        fold=lambda wildcards: wildcards.twin.split("_")[-1] if wildcards.twin.startswith("slide_loop_") else "null",
        fit_args=lambda wildcards, input: fit_overrides(input.fit),
        stem=lambda wildcards, input: input.npz[: -len(".npz")],
        hydra=lambda wildcards, output: hydra_dir(output.json),
    # with dataset.twin auto the replays lie on the main Sim set's path (slide loop -> replays -> twin_choice); the
    # paper run at 9665dd9 had them wait 20-40 s for GPU slots that twin-ablation trainings took first
    priority: 10
    resources:
        gpu=GPU,
    log:
        "results/logs/judge/slides_{twin}.log",
    benchmark:
        f"results/benchmarks/judge_slides/slides_{{twin}}.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.twin_judge task=slides name={wildcards.twin}"
        " fold={params.fold} {params.twin} {params.fit_args} slide_loop={input.json} sequences={params.stem}"
        " mesh={input.mesh} out.json={output.json} out.npz={output.npz} {params.hydra} > {log} 2>&1"


# A candidate's own Sim set (JUDGE_OWN_SETS: the fold twins, and photo_loop where the main set is not pinned to it):
# the same draws as rule simulate_dataset, simulated with that twin. It keeps simulate_dataset's priority: with
# dataset.twin auto the main set waits for photo_loop's (it copies the chosen candidate's set, common.smk
# candidate_sim_sets).
use rule simulate_dataset as judge_dataset with:
    input:
        mesh=twin_mesh(),
        conf=rules.simulate_dataset.input.conf,
        fit=lambda wildcards: judge_fit(wildcards.twin),
    output:
        manifest=f"{JUDGE_DIR}/sim/{{twin}}/manifest.json",
    wildcard_constraints:
        twin="|".join(JUDGE_OWN_SETS),
    params:
        rule="judge_dataset",
        source=lambda wildcards: f"judge candidate {wildcards.twin}",
    log:
        "results/logs/judge/dataset_{twin}.log",
    benchmark:
        f"results/benchmarks/judge_dataset/dataset_{{twin}}.tsv",


# The main Sim set's twin (dataset.twin auto; docs/slides.md "Which twin makes the Sim set"): the candidate the held-out
# slide MAE chooses (report.twin_selection.pick, the table's own function), from the replays alone, so rule
# simulate_dataset waits for the slide loop and the replays but for no training. Its fitted.yaml is the chosen twin's.
rule twin_choice:
    input:
        slides=expand(rules.judge_slides.output.json, twin=JUDGE_TWINS),
        fits=[judge_fit(t) for t in JUDGE_TWINS],
        conf=JUDGE_CONF,
    output:
        fit=f"{JUDGE_DIR}/choice/twin_fit/fitted.yaml",
        json=f"{JUDGE_DIR}/choice/choice.json",
    params:
        rule="twin_choice",
        py=PY,
        twin=DATASET_TWIN,
        slides=" ".join(f"slides.{t}={JUDGE_DIR}/slides/{t}.json" for t in JUDGE_TWINS),
        fits=" ".join(f"fits.{t}={judge_fit(t)}" for t in JUDGE_TWINS),
        hydra=lambda wildcards, output: hydra_dir(output.json),
    log:
        "results/logs/judge/twin_choice.log",
    benchmark:
        "results/benchmarks/twin_choice.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.twin_judge task=choice dataset_twin={params.twin}"
        " {params.slides} {params.fits} out.choice={output.json} out.choice_fit={output.fit} {params.hydra}"
        " > {log} 2>&1"


use rule train as judge_train with:
    input:
        unpack(lambda wildcards: train_inputs(wildcards, judge_sim(wildcards), JUDGE_RECIPE)),
    output:
        metrics=f"{JUDGE_RUN}/metrics.json",
        scores=f"{JUDGE_RUN}/scores.npz",
        pr=f"{JUDGE_RUN}/pr.npz",
        checkpoint=f"{JUDGE_RUN}/checkpoint.pt",
    wildcard_constraints:
        twin="|".join(JUDGE_TRAINED),
        exp="|".join(JUDGE_EXPERIMENTS),
        clip_len=r"\d+",
        seed=r"\d+",
    log:
        "results/logs/judge/train_{twin}_{exp}_L{clip_len}_seed{seed}.log",
    benchmark:
        f"results/benchmarks/judge_train/train_{{twin}}_{{exp}}_L{{clip_len}}_seed{{seed}}.tsv",
    params:
        rule="judge_train",
        overrides=lambda wildcards: train_overrides(wildcards, judge_sim(wildcards), JUDGE_RECIPE),


# train.seeds_together (the paper profile): a candidate's judge.seeds in one process, as rule train_seeds does
# for the main sweep (stacked models, issue 17: five seeds in ~0.46x the time of five runs on the H100). A-to-B
# and A-to-C train the same models on the candidate's Sim set, so one job trains them once and scores both test
# sets (app key also_test, as the recipe ablation does): every candidate alike.
if TRAIN["seeds_together"] and JUDGE["seeds"]:

    rule judge_train_seeds:
        input:
            unpack(lambda wildcards: group_inputs(JUDGE_EXPERIMENTS, judge_sim(wildcards), JUDGE_RECIPE)),
        output:
            **run_files(run_dir(f"{JUDGE_DIR}/train/{{twin}}", e, "{clip_len}", s)
                        for e in JUDGE_EXPERIMENTS for s in JUDGE["seeds"]),
        wildcard_constraints:
            twin="|".join(JUDGE_TRAINED),
            clip_len=str(TRAIN["clip_len"]),
        log:
            "results/logs/judge/train_{twin}_L{clip_len}_seeds.log",
        benchmark:
            f"results/benchmarks/judge_train_seeds/train_{{twin}}_L{{clip_len}}_seeds.tsv",
        params:
            rule="judge_train_seeds",
            py=PY,
            exp=JUDGE_EXPERIMENTS[0],
            overrides=lambda wildcards: group_overrides(JUDGE_EXPERIMENTS, judge_sim(wildcards), JUDGE_RECIPE),
            seeds=yaml_list(JUDGE["seeds"]),
            # the app writes seed s of A-to-B to <run dir>/seed<s>/ (run dir = its L<clip_len> folder), A-to-C beside it
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
            " experiment={params.exp} 'seeds={params.seeds}' clip_len={wildcards.clip_len}"
            " device={params.device} {params.overrides} {params.hydra} > {log} 2>&1"

    ruleorder: judge_train_seeds > judge_train


rule twin_selection:
    input:
        slides=expand(rules.judge_slides.output.json, twin=JUDGE_TWINS),
        markers=expand(rules.judge_slides.output.npz, twin=JUDGE_TWINS),  # the figure's replay
        scores=judge_scores(),
        choice=rules.twin_choice.output.json,  # the table checks it names the same twin
        npz=rules.silicone_sequences.output.npz,
        conf=JUDGE_CONF,
    output:
        csv=f"{JUDGE_DIR}/twin_selection.csv",
        md=f"{JUDGE_DIR}/twin_selection.md",
        png=f"{JUDGE_DIR}/slide_motion.png",
        pdf=f"{JUDGE_DIR}/slide_motion.pdf",
        bounds=f"{JUDGE_DIR}/drift_bounds.csv",  # what a held-out slide MAE can reach without a twin
    params:
        rule="twin_selection",
        py=PY,
        profile=PROFILE,
        seeds=yaml_list(JUDGE["seeds"]),
        clip_len=TRAIN["clip_len"],
        recipe=JUDGE_RECIPE,
        stem=lambda wildcards, input: input.npz[: -len(".npz")],
        runs=" ".join(f"runs.{t}={judge_runs_root(t)}" for t in JUDGE_TWINS),
        slides=" ".join(f"slides.{t}={JUDGE_DIR}/slides/{t}.json" for t in JUDGE_TWINS),
        figure=lambda wildcards, output: output.png[: -len(".png")],
        hydra=lambda wildcards, output: hydra_dir(output.csv),
    log:
        "results/logs/judge/twin_selection.log",
    benchmark:
        "results/benchmarks/twin_selection.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.twin_judge task=table profile={params.profile}"
        " 'seeds={params.seeds}' clip_len={params.clip_len} trained_with={params.recipe} sequences={params.stem}"
        " {params.runs} {params.slides} choice={input.choice}"
        " out.csv={output.csv} out.md={output.md} out.figure={params.figure} out.bounds={output.bounds}"
        " {params.hydra} > {log} 2>&1"
