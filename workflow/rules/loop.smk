# Issue 5: close the loop with measured data (residual -> missing effect -> add it -> error before and after).
# Needs common.smk (PY, hydra_dir, PROFILE, config: twin_resolution, device, optional loop.preset/.twin),
# twin.smk (rule mesh) and photos.smk (rule measured_photos).
#
# The final twin (LOOP_FIT) is a config-group option in package `twin`, the same mechanism as the
# calibration's TWIN_FIT: a dataset rule reads it by declaring `fit=LOOP_FIT` as an input and adding
# LOOP_FIT_ARGS to its Hydra overrides (instead of TWIN_FIT_ARGS; the loop's file also holds E).
# The Optuna studies (results/loop/study.db, results/loop/selftest/study.db) are deliberately not
# outputs: Snakemake would delete them before a rerun, and they let a killed loop resume.

LOOP_DIR = "results/loop"
LOOP_PRESET = config.get("loop", {}).get("preset", "quick" if PROFILE == "quick" else "paper")
# loop.twin: extra twin overrides, e.g. a smaller step for a stiff shell on the reference mesh
# ("twin.integrator.dt=5e-6 twin.integrator.substeps=248"); the final twin_fit records dt and substeps
LOOP_TWIN = (
    f"twin/mesh={config['twin_resolution']} twin.device={config['device']} "
    + config.get("loop", {}).get("twin", "")
).strip()
LOOP_MESH = f"results/twin/mesh_{config['twin_resolution']}.npz"
LOOP_GPU = 1 if config["device"] == "cuda" else 0
LOOP_CONF = conf_files("loop", {"loop": LOOP_PRESET, "twin/mesh": config["twin_resolution"]})
LOOP_FIT = f"{LOOP_DIR}/twin_fit/fitted.yaml"
LOOP_FIT_ARGS = f"'hydra.searchpath=[file://{LOOP_DIR}]' +twin_fit=fitted"
LOOP_SHELL = (
    "SNAKEMAKE_RULE={rule} {params.py} palpation.apps.loop mode={params.mode} loop={params.preset} {params.twin}"
    " measured={params.measured} mesh={input.mesh} out.dir={params.out} {params.hydra} > {log} 2>&1"
)


rule loop:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=LOOP_MESH,
        conf=LOOP_CONF,
    output:
        report=f"{LOOP_DIR}/report.md",
        csv=f"{LOOP_DIR}/loop_real.csv",
        rounds=f"{LOOP_DIR}/rounds.json",
        fit=LOOP_FIT,
        params=f"{LOOP_DIR}/fitted_params.yaml",
        rounds_png=report(f"{LOOP_DIR}/rounds.png", caption="../report/loop_rounds.rst", category="Residual loop"),
        rounds_pdf=f"{LOOP_DIR}/rounds.pdf",
        modes_png=report(f"{LOOP_DIR}/modes.png", caption="../report/loop_modes.rst", category="Residual loop"),
        modes_pdf=f"{LOOP_DIR}/modes.pdf",
        residuals=directory(f"{LOOP_DIR}/residuals"),
    params:
        mode="real",
        preset=LOOP_PRESET,
        twin=LOOP_TWIN,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.report).parent,
        hydra=lambda wildcards, output: hydra_dir(output.report),
        py=PY,
    resources:
        gpu=LOOP_GPU,
    log:
        "results/logs/loop/loop.log",
    shell:
        LOOP_SHELL


# Measured-like sets made by the twin with one hidden effect each; the geometry comes from the photo set.
rule loop_selftest:
    input:
        measured=rules.measured_photos.output.npz,
        mesh=LOOP_MESH,
        conf=LOOP_CONF,
    output:
        csv=f"{LOOP_DIR}/loop_selftest.csv",
        md=f"{LOOP_DIR}/selftest.md",
        json=f"{LOOP_DIR}/selftest.json",
        sets=directory(f"{LOOP_DIR}/selftest/sets"),
    params:
        mode="selftest",
        preset=LOOP_PRESET,
        twin=LOOP_TWIN,
        measured=lambda wildcards, input: input.measured[: -len(".npz")],
        out=lambda wildcards, output: Path(output.csv).parent,
        hydra=lambda wildcards, output: hydra_dir(output.csv),
        py=PY,
    resources:
        gpu=LOOP_GPU,
    log:
        "results/logs/loop/loop_selftest.log",
    shell:
        LOOP_SHELL
