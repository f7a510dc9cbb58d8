# The domain-randomised Sim dataset (SPEC §7, conf/dataset/sim.yaml): per trial heading, k_n, c_n drawn from one seeded
# stream; even files over the vessel, odd without. Split 70/15/15 by sorted id at load time.
DATASET = config.get("dataset", {})


rule simulate_dataset:
    input:
        mesh=TWIN_MESH,
        conf=conf_files("simulate", {"twin/mesh": config["twin_resolution"]}),
        fit=LOOP_FIT,  # the residual loop's final twin sets every parameter the draws leave alone
    output:
        manifest="results/sim/dataset/manifest.json",
    params:
        hydra=lambda wildcards, output: hydra_dir(output.manifest),
        outdir=lambda wildcards, output: Path(output.manifest).parent,
        twin=TWIN_ARGS,
        n_pairs=DATASET.get("n_pairs", 250),
        seed=DATASET.get("seed", 42),
        recentre=str(DATASET.get("recentre_k_n", False)).lower(),
        fit_args=LOOP_FIT_ARGS,
    resources:
        gpu=GPU,
    log:
        "results/logs/sim/simulate_dataset.log",
    shell:
        "SNAKEMAKE_RULE={rule} {PY} palpation.apps.simulate set=randomised"
        " n_pairs={params.n_pairs} seed={params.seed}"
        " dataset.recentre_k_n={params.recentre}"
        " {params.twin} {params.fit_args} mesh={input.mesh} out.dir={params.outdir}"
        " {params.hydra} > {log} 2>&1"


# Ablation (train.twin_ablation): the same draws simulated with the calibration-only twin, the one
# the paper trains on, so that what the loop's twin does to sim-to-real transfer is measured.
use rule simulate_dataset as simulate_dataset_calibrated with:
    input:
        mesh=TWIN_MESH,
        conf=rules.simulate_dataset.input.conf,
        fit=TWIN_FIT,
    output:
        manifest="results/sim/dataset_calibrated/manifest.json",
    params:
        fit_args=TWIN_FIT_ARGS,
    log:
        "results/logs/sim/simulate_dataset_calibrated.log",
