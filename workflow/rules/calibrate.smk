# Calibration of the twin against the flat-tip photos (issue 4) and its benchmark.
# Needs common.smk (hydra_dir, calibration_outputs, twin_mesh, config: calibration, twin_resolution, device),
# twin.smk (rule mesh) and photos.smk (rule measured_photos).
#
# Downstream rules read the fit with no copy step: declare `fit=rules.calibrate.output.fit` as an input
# and add fit_overrides(input.fit) to the Hydra app's overrides (common.smk); the fit is a config-group
# option (package `twin`) that sets the fitted twin parameters.
# The Optuna study (results/calibration/study.db) is deliberately not an output: Snakemake would
# delete it before a rerun, and it is what lets a killed calibration resume.

CAL_PRESET = config["calibration"]
CAL_SHELL = (
    "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.calibrate calibration={params.preset} {params.twin}"
    " measured={params.measured} mesh={input.mesh} out.dir={params.out}"
    " {params.hydra} > {log} 2>&1"
)


rule calibrate:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
        # the preset and the presets it inherits: an edited one reruns the search
        conf=conf_files("calibrate", {"calibration": CAL_PRESET, "twin/mesh": config["twin_resolution"]}),
    output:
        **calibration_outputs("results/calibration"),
    params:
        rule="calibrate",
        py=PY,
        preset=CAL_PRESET,
        twin=TWIN_ARGS,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.params).parent,
        hydra=lambda wildcards, output: hydra_dir(output.params),
    # the head of the Sim set's chain (calibrate -> simulate_dataset -> the trainings): on 2 cores it waited behind
    # the Meat trainings, which need none of it (a quick run started it at 182 s instead of 24 s)
    priority: 10
    resources:
        gpu=GPU,
    log:
        "results/logs/calibration/calibrate.log",
    benchmark:
        "results/benchmarks/calibrate.tsv",
    conda:
        CONDA_ENV
    shell:
        CAL_SHELL


# The paper's joint objective (SPEC §6.2), to compare with the published optimum; not read downstream.
use rule calibrate as calibrate_reference with:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
        conf=conf_files("calibrate", {"calibration": "reference", "twin/mesh": config["twin_resolution"]}),
    output:
        **calibration_outputs("results/calibration/reference"),
    params:
        rule="calibrate_reference",
        preset="reference",
    log:
        "results/logs/calibration/calibrate_reference.log",
    benchmark:
        "results/benchmarks/calibrate_reference.tsv",


rule bench_calibration:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=twin_mesh(),
    output:
        json="results/bench/calibration.json",
    params:
        py=PY,
        device=config["device"],
        resolution=config["twin_resolution"],
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
    resources:
        gpu=GPU,
    log:
        "results/logs/bench/calibration.log",
    benchmark:
        "results/benchmarks/bench_calibration.tsv",
    conda:
        CONDA_ENV
    shell:
        "{params.py} palpation.calibration.benchmark --device {params.device} --resolution {params.resolution}"
        " --mesh {input.mesh} --measured {params.measured} --out {output.json} > {log} 2>&1"
