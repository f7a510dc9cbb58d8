# ViTacTip sliding palpation: the whole paper as one DAG. Rules live in workflow/rules/<stage>.smk.
#   snakemake --cores 2                                      quick profile (CPU, the default)
#   snakemake --workflow-profile workflow/profiles/paper     paper profile (one GPU)
#   snakemake --cores 2 bench                                benchmark JSONs under results/bench/
#   snakemake --cores 2 selftest                             the residual loop's self-test


include: "workflow/rules/common.smk"
include: "workflow/rules/photos.smk"
include: "workflow/rules/silicone.smk"
include: "workflow/rules/meat.smk"
include: "workflow/rules/twin.smk"
include: "workflow/rules/simulate.smk"
include: "workflow/rules/calibrate.smk"
include: "workflow/rules/loop.smk"
include: "workflow/rules/slides.smk"
include: "workflow/rules/dataset.smk"
include: "workflow/rules/transfer.smk"
include: "workflow/rules/train.smk"
include: "workflow/rules/judge.smk"
include: "workflow/rules/maps.smk"
include: "workflow/rules/recipe.smk"
include: "workflow/rules/results_page.smk"

from palpation.killed_jobs import killed_outputs  # a killed forced rerun's missing outputs (see there)


rule all:
    default_target: True
    input:
        plain(rules.measured_photos.output),
        plain(rules.silicone_set.output),
        plain(rules.silicone_check.output),
        plain(rules.meat_set.output),
        plain(rules.data_summary.output),
        plain(rules.render_twin.output),
        plain(rules.calibrate.output),
        plain(rules.loop.output),
        plain(rules.train_report.output),
        plain(TWIN_ABLATION_FILES),  # common.smk: empty where the profile skips the dataset-twin ablation
        plain(rules.vessel_maps.output),
        plain(RECIPE_REPORT_FILES),  # common.smk: empty where the profile skips the recipe ablation
        plain(RECIPE_CROSSFIT_FILES),  # common.smk: the recipe ablation's calibration cross-fitted (real sets)
        plain(JUDGE_FILES),  # judge.smk: empty where the profile skips the downstream judge (judge.seeds [])
        plain(rules.results_page.output),
        killed_outputs(),


# The loop's self-test (hidden effects in twin-made sets): snakemake --cores 2 selftest
rule selftest:
    input:
        rules.loop_selftest.output,


rule bench:
    input:
        rules.bench_twin.output,
        rules.bench_calibration.output,
        rules.bench_train.output,


onstart:
    from palpation.report.reproduction import stamp_start

    stamp_start()


onsuccess:
    from palpation.report.reproduction import record_run

    record_run(PROFILE, config["device"])
