# Calibration of the twin against the flat-tip photos (issue 4) and its benchmark.
# Needs common.smk (PY, hydra_dir, config: twin_resolution, device, optional calibration),
# twin.smk (rule mesh) and photos.smk (rule measured_photos).
#
# Downstream rules read the fit with no copy step: declare `fit=TWIN_FIT` as an input and add
# TWIN_FIT_ARGS to the Hydra app's overrides, e.g. for a dataset rule:
#     "{PY} palpation.apps.simulate set=randomised {TWIN_ARGS} {TWIN_FIT_ARGS} ..."
# TWIN_FIT is a config-group option (package `twin`) that sets the fitted twin parameters.
# The Optuna study (results/calibration/study.db) is deliberately not an output: Snakemake would
# delete it before a rerun, and it is what lets a killed calibration resume.

CAL_DIR = "results/calibration"
CAL_PRESET = config.get("calibration", "quick" if PROFILE == "quick" else "project")
CAL_TWIN = f"twin/mesh={config['twin_resolution']} twin.device={config['device']}"
CAL_MESH = f"results/twin/mesh_{config['twin_resolution']}.npz"
CAL_GPU = 1 if config["device"] == "cuda" else 0
TWIN_FIT = f"{CAL_DIR}/twin_fit/fitted.yaml"
TWIN_FIT_ARGS = f"'hydra.searchpath=[file://{CAL_DIR}]' +twin_fit=fitted"


def calibration_outputs(out):
    return {
        "fit": f"{out}/twin_fit/fitted.yaml",
        "params": f"{out}/fitted_params.yaml",
        "csv": f"{out}/calibration.csv",
        "md": f"{out}/calibration.md",
        "json": f"{out}/calibration.json",
        "trials": f"{out}/trials.csv",
        "fig4": report(
            f"{out}/fig4.png", caption="../report/calibration_fig4.rst", category="Calibration"
        ),
        "fig4_pdf": f"{out}/fig4.pdf",
        "fig4_paper": f"{out}/fig4_paper.png",
        "fig4_paper_pdf": f"{out}/fig4_paper.pdf",
        "history": report(
            f"{out}/history.png",
            caption="../report/calibration_history.rst",
            category="Calibration",
        ),
        "history_pdf": f"{out}/history.pdf",
    }


CAL_SHELL = (
    "SNAKEMAKE_RULE={rule} {PY} palpation.apps.calibrate calibration={params.preset} {params.twin}"
    " measured={params.measured} mesh={input.mesh} out.dir={params.out}"
    " {params.hydra} > {log} 2>&1"
)


rule calibrate:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=CAL_MESH,
        # the preset and the presets it inherits: an edited one reruns the search
        conf=conf_files("calibrate", {"calibration": CAL_PRESET, "twin/mesh": config["twin_resolution"]}),
    output:
        **calibration_outputs(CAL_DIR),
    params:
        preset=CAL_PRESET,
        twin=CAL_TWIN,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=CAL_DIR,
        hydra=lambda wildcards, output: hydra_dir(output.params),
    resources:
        gpu=CAL_GPU,
    log:
        "results/logs/calibration/calibrate.log",
    shell:
        CAL_SHELL


# The paper's joint objective (SPEC §6.2), to compare with the published optimum; not read downstream.
rule calibrate_reference:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=CAL_MESH,
        conf=conf_files("calibrate", {"calibration": "reference", "twin/mesh": config["twin_resolution"]}),
    output:
        **calibration_outputs(f"{CAL_DIR}/reference"),
    params:
        preset="reference",
        twin=CAL_TWIN,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=f"{CAL_DIR}/reference",
        hydra=lambda wildcards, output: hydra_dir(output.params),
    resources:
        gpu=CAL_GPU,
    log:
        "results/logs/calibration/calibrate_reference.log",
    shell:
        CAL_SHELL


rule bench_calibration:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=CAL_MESH,
    output:
        json="results/bench/calibration.json",
    params:
        device=config["device"],
        resolution=config["twin_resolution"],
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
    resources:
        gpu=CAL_GPU,
    log:
        "results/logs/bench/calibration.log",
    shell:
        "{PY} palpation.calibration.benchmark --device {params.device} --resolution {params.resolution}"
        " --mesh {input.mesh} --measured {params.measured} --out {output.json} > {log} 2>&1"
