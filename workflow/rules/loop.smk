# Issue 5: close the loop with measured data (residual -> missing effect -> add it -> error before and after).
# Needs common.smk (hydra_dir, twin_mesh, config: loop, twin_resolution, device), twin.smk (rule mesh)
# and photos.smk (rule measured_photos).
#
# The final twin (output `fit`) is a config-group option in package `twin`, the same mechanism as the
# calibration's: a dataset rule reads it by declaring `fit=rules.loop.output.fit` as an input and adding
# fit_overrides(input.fit) to its Hydra overrides (the loop's file also holds E).
# The Optuna studies (results/loop/study.journal, results/loop/selftest/study.journal) are deliberately not
# outputs: Snakemake would delete them before a rerun, and they let a killed loop resume.

LOOP_DIR = "results/loop"
# loop.twin: extra twin overrides, e.g. a smaller step for a stiff shell on the reference mesh
# ("twin.integrator.dt=5e-6 twin.integrator.substeps=248"); the final twin_fit records dt and substeps
LOOP_TWIN = f"{TWIN_ARGS} {config['loop']['twin']}".strip()
LOOP_CONF = conf_files("loop", {"loop": config["loop"]["preset"], "twin/mesh": config["twin_resolution"]})
LOOP_SHELL = (
    "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.loop"
    " mode={params.mode} loop={params.preset} {params.twin}"
    " measured={params.measured} mesh={input.mesh} out.dir={params.out} {params.hydra} > {log} 2>&1"
)


rule loop:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
        conf=LOOP_CONF,
    output:
        report=f"{LOOP_DIR}/report.md",
        csv=report(f"{LOOP_DIR}/loop_real.csv", caption="../report/loop_table.rst", category="Residual loop"),
        rounds=f"{LOOP_DIR}/rounds.json",
        fit=f"{LOOP_DIR}/twin_fit/fitted.yaml",
        params=f"{LOOP_DIR}/fitted_params.yaml",
        rounds_png=report(f"{LOOP_DIR}/rounds.png", caption="../report/loop_rounds.rst", category="Residual loop"),
        rounds_pdf=f"{LOOP_DIR}/rounds.pdf",
        modes_png=report(f"{LOOP_DIR}/modes.png", caption="../report/loop_modes.rst", category="Residual loop"),
        modes_pdf=f"{LOOP_DIR}/modes.pdf",
        residuals=directory(f"{LOOP_DIR}/residuals"),
        per_state=f"{LOOP_DIR}/tables/per_state.csv",  # report.md's tables as CSV (tables/*.csv)
    params:
        rule="loop",
        py=PY,
        mode="real",
        preset=config["loop"]["preset"],
        twin=LOOP_TWIN,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.report).parent,
        hydra=lambda wildcards, output: hydra_dir(output.report),
    priority: 5  # the longest job of the quick profile (~4 min on one core): it starts beside the calibration
    resources:
        gpu=GPU,
    log:
        "results/logs/loop/loop.log",
    benchmark:
        "results/benchmarks/loop.tsv",
    conda:
        CONDA_ENV
    shell:
        LOOP_SHELL


# Measured-like sets made by the twin with one hidden effect each; the geometry comes from the photo set.
rule loop_selftest:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
        conf=LOOP_CONF,
    output:
        csv=f"{LOOP_DIR}/loop_selftest.csv",
        md=f"{LOOP_DIR}/selftest.md",
        json=f"{LOOP_DIR}/selftest.json",
        sets=directory(f"{LOOP_DIR}/selftest/sets"),
    params:
        rule="loop_selftest",
        py=PY,
        mode="selftest",
        preset=config["loop"]["preset"],
        twin=LOOP_TWIN,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.csv).parent,
        hydra=lambda wildcards, output: hydra_dir(output.csv),
    resources:
        gpu=GPU,
    log:
        "results/logs/loop/loop_selftest.log",
    benchmark:
        "results/benchmarks/loop_selftest.tsv",
    conda:
        CONDA_ENV
    shell:
        LOOP_SHELL


# The generative self-test (loop.selftest.generative): each run draws its truth (0-3 in-list effects, strengths, E, k_s, a
# share with an outside effect). Split `dev` (seeds < 1000) while choosing mechanisms and thresholds; `test` once, at
# the end. Finished runs are kept in general/{split}/generative/runs/ (deliberately not outputs, as the studies: a
# killed run resumes there). Not in `rule all`: snakemake results/loop/general/dev/loop_selftest_general.csv
rule loop_selftest_general:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
        conf=LOOP_CONF,
    output:
        csv=f"{LOOP_DIR}/general/{{split}}/loop_selftest_general.csv",
        md=f"{LOOP_DIR}/general/{{split}}/selftest_general.md",
        json=f"{LOOP_DIR}/general/{{split}}/selftest_general.json",
    wildcard_constraints:
        split="dev|test",
    params:
        rule="loop_selftest_general",
        py=PY,
        mode="generative",
        preset=config["loop"]["preset"],
        twin=lambda wildcards: f"{LOOP_TWIN} loop.generative.split={wildcards.split}".strip(),
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.csv).parent,
        hydra=lambda wildcards, output: hydra_dir(output.csv),
    resources:
        gpu=GPU,
    log:
        "results/logs/loop/loop_selftest_general_{split}.log",
    benchmark:
        "results/benchmarks/loop_selftest_general_{split}.tsv",
    conda:
        CONDA_ENV
    shell:
        LOOP_SHELL


# The full self-test of issue 13 (>= 60 runs: 12 cases x 5, singles, dependent and independent pairs, two
# out-of-list effects), beside the profile's own size; on a GPU with loop=paper it is one batch per twin call.
rule loop_selftest_full:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
        conf=LOOP_CONF,
    output:
        csv=f"{LOOP_DIR}/full/loop_selftest.csv",
        md=f"{LOOP_DIR}/full/selftest.md",
        json=f"{LOOP_DIR}/full/selftest.json",
    params:
        rule="loop_selftest_full",
        py=PY,
        mode="selftest",
        preset=config["loop"]["preset"],
        twin=f"{LOOP_TWIN} loop.selftest.runs_per_case=5".strip(),
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.csv).parent,
        hydra=lambda wildcards, output: hydra_dir(output.csv),
    resources:
        gpu=GPU,
    log:
        "results/logs/loop/loop_selftest_full.log",
    benchmark:
        "results/benchmarks/loop_selftest_full.tsv",
    conda:
        CONDA_ENV
    shell:
        LOOP_SHELL
