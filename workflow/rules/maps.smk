# Top-view vessel maps from the best-of-five runs: operating points, Table 4 lower half and Fig. 7 (SPEC §12).
# Needs common.smk (maps_inputs, maps_datasets, MAPS_CONFIGS, TRAIN_DATA, hydra_dir), simulate.smk (rule
# simulate_vessel_slide) and train.smk (rule train). The profile's optional `maps:` mapping
# (workflow/schemas/config.schema.yaml):
#   configs      configurations to map (default: train.experiments)
#   sim_source   test (the Sim test windows) | slide (rescore the dedicated vessel slide densely)
# The best seed is known only after training, so the rule takes every seed's metrics and scores and
# the app picks the best-of-five (highest test AP, AUROC breaks ties; SPEC §11).


rule vessel_maps:
    input:
        unpack(maps_inputs),
    output:
        table=report("results/maps/table4_maps.csv", caption="../report/table4_maps.rst", category="Vessel maps"),
        md="results/maps/table4_maps.md",
        photo="results/maps/table4_maps_photo.csv",
        json="results/maps/vessel_maps.json",
        fig7=report("results/maps/fig7_confusion_maps.png", caption="../report/fig7_maps.rst", category="Vessel maps"),
        fig7_pdf="results/maps/fig7_confusion_maps.pdf",
        threshold=report("results/maps/fig7_threshold_selection.png", caption="../report/fig7_threshold.rst", category="Vessel maps"),
        threshold_pdf="results/maps/fig7_threshold_selection.pdf",
        maps=expand("results/maps/maps_{config}.npz", config=MAPS_CONFIGS),
        confusion=expand("results/maps/{config}_confusion{big}.png", config=MAPS_CONFIGS, big=["", "_big"]),
    log:
        "results/logs/maps/vessel_maps.log",
    benchmark:
        "results/benchmarks/vessel_maps.tsv",
    params:
        rule="vessel_maps",
        py=PY,
        configs=yaml_list(MAPS_CONFIGS),
        seeds=yaml_list(TRAIN["seeds"]),
        clip_len=TRAIN["clip_len"],
        runs_root=lambda wildcards, input: runs_root(input.metrics[0]),
        data=" ".join(f"data.{ds}={TRAIN_DATA[ds]}" for ds in maps_datasets()),
        sim=f"sim.source={config['maps']['sim_source']}"
        f" sim.slide_manifest={rules.simulate_vessel_slide.output.manifest}",
        out_dir=lambda wildcards, output: Path(output.table).parent,
        hydra=lambda wildcards, output: hydra_dir(output.table),
        profile=PROFILE,
        device=config["device"],
    conda:
        CONDA_ENV
    shell:
        "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.vessel_maps"
        " profile={params.profile} 'configs={params.configs}' runs.root={params.runs_root}"
        " 'runs.seeds={params.seeds}' clip_len={params.clip_len} {params.data} {params.sim}"
        " device={params.device} out_dir={params.out_dir} {params.hydra} > {log} 2>&1"
