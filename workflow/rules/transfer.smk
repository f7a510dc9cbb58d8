# The Sim set spread over the real slides' estimated press depths (docs/transfer.md, section 4). Not in `rule all`:
#   snakemake --cores 2 results/sim/dataset_spread/manifest.json
# Needs common.smk (PY, TWIN_ARGS, GPU, twin_mesh, fit_overrides, dataset_fit), loop.smk (rule loop: the twin of the
# photos, whose phantom surface the bank needs: the reference twin's vessel-free slides look alike at every depth),
# silicone.smk and meat.smk (the real slides, read without labels) and dataset.smk (rule simulate_dataset).

TRANSFER_DIR = "results/transfer"
PYTHON = PY[: -len(" -m")]  # the interpreter of the app rules, for a workflow script


rule depth_bank:
    input:
        mesh=twin_mesh(),
        conf=conf_files("simulate", {"twin/mesh": config["twin_resolution"]}),
        fit=rules.loop.output.fit,
    output:
        manifest=f"{TRANSFER_DIR}/bank/manifest.json",
    params:
        rule="depth_bank",
        py=PY,
        twin=TWIN_ARGS,
        fit_args=lambda wildcards, input: fit_overrides(input.fit),
        outdir=lambda wildcards, output: Path(output.manifest).parent,
        hydra=lambda wildcards, output: hydra_dir(output.manifest),
    resources:
        gpu=GPU,
    log:
        "results/logs/transfer/depth_bank.log",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.simulate set=depth_bank {params.twin}"
        " {params.fit_args} mesh={input.mesh} out.dir={params.outdir} {params.hydra} > {log} 2>&1"


rule latent_depth:
    input:
        bank=rules.depth_bank.output.manifest,
        silicone=rules.silicone_set.output.npz,
        meat=rules.meat_set.output.npz,
    output:
        csv=f"{TRANSFER_DIR}/latent_depth.csv",
    params:
        python=PYTHON,
    log:
        "results/logs/transfer/latent_depth.log",
    conda:
        CONDA_ENV
    shell:
        "{params.python} workflow/scripts/latent_depth.py --bank {input.bank} --silicone {input.silicone}"
        " --meat {input.meat} --out {output.csv} > {log} 2>&1"


# simulate_dataset's draws and twin (its fit, the judge's choice), each pair's slide depth drawn over the estimates
use rule simulate_dataset as simulate_dataset_spread with:
    input:
        mesh=twin_mesh(),
        conf=rules.simulate_dataset.input.conf,
        fit=dataset_fit,
        depths=rules.latent_depth.output.csv,
    output:
        manifest="results/sim/dataset_spread/manifest.json",
    priority: 0
    params:
        rule="simulate_dataset_spread",
        reuse="'reuse=[]'",
        extra=lambda wildcards, input: f"dataset.depths_from={input.depths}",
    log:
        "results/logs/sim/simulate_dataset_spread.log",
    benchmark:
        "results/benchmarks/simulate_dataset_spread.tsv",
