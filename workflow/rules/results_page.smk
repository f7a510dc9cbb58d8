# The results page (issue 8): every table of the run beside the paper's numbers -> results/README.md.
# Needs common.smk (PROFILE, hydra_dir, TWIN_ABLATION_FILES) and the rule files whose tables it reads;
# include it after maps.smk. The inputs are the tables this profile produces; the twin ablation joins
# where the profile runs it (TWIN_ABLATION_FILES not empty). Its Timing section reads the benchmark files
# of the jobs before it (results/benchmarks/, no inputs: a folder made before them must not rerun its
# rules); the page lists every output of `rule all` (silicone_check's too) so that it is the run's last job.


rule results_page:
    input:
        data=plain(rules.data_summary.output.csv),
        calibration=plain(rules.calibrate.output.csv),
        loop=plain(rules.loop.output.csv),
        loop_states=rules.loop.output.per_state,
        train_report=plain(rules.train_report.output),  # seed sweep, Table 4 upper half, Fig. 6 (+ Table 3 if ablated)
        maps=plain(rules.vessel_maps.output.table),
        maps_photo=rules.vessel_maps.output.photo,
        maps_json=rules.vessel_maps.output.json,
        render=plain(rules.render_twin.output.png),  # listed among the figures
        silicone_check=rules.silicone_check.output.json,  # not read: the page comes last, timing every job
        twin_ablation=TWIN_ABLATION_FILES,  # common.smk; empty where the profile skips the ablation
        recipe=RECIPE_REPORT_FILES,  # common.smk; empty where the profile skips the recipe ablation
        recipe_crossfit=RECIPE_CROSSFIT_FILES,  # common.smk; empty where the ablation lacks a partner (or is skipped)
        judge=JUDGE_FILES,  # common.smk; empty where the profile skips the downstream judge (issue 12)
        conf=conf_files("results_page"),
        explanations="conf/results_page/explanations.yaml",
        folders="conf/results_page/folders.yaml",
    output:
        page=report("results/README.md", caption="../report/results_page.rst", category="Results page"),
    log:
        "results/logs/results_page.log",
    benchmark:
        "results/benchmarks/results_page.tsv",
    params:
        rule="results_page",
        py=PY,
        root=lambda wildcards, output: Path(output.page).parent,
        hydra=lambda wildcards, output: hydra_dir(output.page),
        profile=PROFILE,
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.results_page"
        " root={params.root} out={output.page} profile={params.profile}"
        " explanations={input.explanations} folders={input.folders} {params.hydra} > {log} 2>&1"
