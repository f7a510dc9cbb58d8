# The domain-randomised Sim dataset (SPEC §7, conf/dataset/sim.yaml): per trial heading, k_n, c_n drawn from one seeded
# stream; even files over the vessel, odd without. Split 70/15/15 by sorted id at load time. Its twin: config
# dataset.twin (auto: rule twin_choice in judge.smk, which needs only the candidates' held-out slide replays).
DATASET = config["dataset"]


rule simulate_dataset:
    input:
        mesh=twin_mesh(),
        conf=conf_files("simulate", {"twin/mesh": config["twin_resolution"]}),
        # the fitted twin sets every parameter the draws leave alone: dataset.twin's (common.smk dataset_fit; auto:
        # rule twin_choice's, the candidate the held-out real-slide MAE chooses, judge.smk)
        fit=dataset_fit,
        reuse=candidate_sim_sets,
    output:
        manifest="results/sim/dataset/manifest.json",
    params:
        rule="simulate_dataset",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.manifest),
        outdir=lambda wildcards, output: Path(output.manifest).parent,
        twin=TWIN_ARGS,
        n_pairs=DATASET["n_pairs"],
        seed=DATASET["seed"],
        recentre=str(DATASET["recentre_k_n"]).lower(),
        fit_args=lambda wildcards, input: fit_overrides(input.fit),
        source=f"dataset.twin={DATASET_TWIN}",  # logged: which twin, chosen or pinned
        reuse=lambda wildcards, input: "'reuse=[" + ",".join(getattr(input, "reuse", [])) + "]'",
        extra="",  # further app overrides of a variant (transfer.smk: the depths of simulate_dataset_spread)
    # the main Sim set is on the paper profile's critical path (loop -> Sim set -> training): it takes the next GPU
    # slot before the ablations' jobs (a device run lost 20 s to a twin-ablation training taking it first)
    priority: 10
    resources:
        gpu=GPU,
    log:
        "results/logs/sim/simulate_dataset.log",
    benchmark:
        "results/benchmarks/simulate_dataset.tsv",
    conda:
        CONDA_ENV
    shell:
        "echo Sim set twin: {params.source:q}, fit {input.fit:q} > {log};"  # :q, one shell word whatever it holds
        " SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.simulate set=randomised"
        " n_pairs={params.n_pairs} seed={params.seed}"
        " dataset.recentre_k_n={params.recentre}"
        " {params.twin} {params.fit_args} {params.reuse} {params.extra} mesh={input.mesh} out.dir={params.outdir}"
        " {params.hydra} >> {log} 2>&1"


# Ablation (train.twin_ablation): the same draws simulated with the calibration-only twin, the one
# the paper trains on, so that what the loop's twin does to sim-to-real transfer is measured.
use rule simulate_dataset as simulate_dataset_calibrated with:
    input:
        mesh=twin_mesh(),
        conf=rules.simulate_dataset.input.conf,
        fit=rules.calibrate.output.fit,
    output:
        manifest="results/sim/dataset_calibrated/manifest.json",
    priority: 0
    params:
        rule="simulate_dataset_calibrated",
        source="the calibration's twin (twin ablation, judge candidate calibrated)",
    log:
        "results/logs/sim/simulate_dataset_calibrated.log",
    benchmark:
        "results/benchmarks/simulate_dataset_calibrated.tsv",
