# Top-view vessel maps from the best-of-five runs: operating points, Table 4 lower half and Fig. 7 (SPEC §12).
# Needs common.smk (PY, PROFILE, hydra_dir) and train.smk (TRAIN, TRAIN_RUN, TRAIN_DIR, TRAIN_DATA,
# EXPERIMENTS, yaml_list); include it after both. The profile's optional `maps:` mapping:
#   configs      configurations to map (default: train.experiments)
#   sim_source   test (the Sim test windows) | slide (rescore the dedicated vessel slide densely)
# The best seed is known only after training, so the rule takes every seed's metrics and scores and
# the app picks the best-of-five (highest test AP, AUROC breaks ties; SPEC §11).

MAPS = config.get("maps", {})
MAPS_DIR = "results/maps"
MAPS_CONFIGS = MAPS.get("configs", TRAIN.get("experiments", list(EXPERIMENTS)))
MAPS_SIM_SOURCE = MAPS.get("sim_source", "test")
MAPS_SLIDE = "results/twin/vessel_slide/manifest.json"  # rule simulate_vessel_slide
MAPS_TEST_SET = {"A-to-A": "sim", "A-to-B": "silicone", "A-to-C": "meat", "C-to-B": "silicone"}
MAPS_SEEDS = TRAIN.get("seeds", [0, 1, 2, 3, 4])
MAPS_DATASETS = sorted({MAPS_TEST_SET[c] for c in MAPS_CONFIGS})


def maps_runs(name, configs=MAPS_CONFIGS):
    """`name` of every seed of the mapped configurations (the app picks the best of them)."""
    return expand(f"{TRAIN_RUN}/{name}", exp=configs, clip_len=TRAIN.get("clip_len", 5), seed=MAPS_SEEDS)


def maps_inputs(wildcards):
    inputs = {"metrics": maps_runs("metrics.json"), "scores": maps_runs("scores.npz")}
    inputs.update({ds: TRAIN_DATA[ds] for ds in MAPS_DATASETS})
    inputs["conf"] = conf_files("vessel_maps")
    if "A-to-A" in MAPS_CONFIGS and MAPS_SIM_SOURCE == "slide":
        inputs["checkpoints"] = maps_runs("checkpoint.pt", ["A-to-A"])
        inputs["slide"] = MAPS_SLIDE
    return inputs


rule vessel_maps:
    input:
        unpack(maps_inputs),
    output:
        table="results/maps/table4_maps.csv",
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
    params:
        configs=yaml_list(MAPS_CONFIGS),
        seeds=yaml_list(MAPS_SEEDS),
        clip_len=TRAIN.get("clip_len", 5),
        runs_root=TRAIN_DIR,
        data=" ".join(f"data.{ds}={TRAIN_DATA[ds]}" for ds in MAPS_DATASETS),
        sim=f"sim.source={MAPS_SIM_SOURCE} sim.slide_manifest={MAPS_SLIDE}",
        out_dir=MAPS_DIR,
        hydra=lambda wildcards, output: hydra_dir(output.table),
        profile=PROFILE,
        device=config.get("device", "cpu"),
    shell:
        "PALPATION_PROFILE={params.profile} SNAKEMAKE_RULE={rule} {PY} palpation.apps.vessel_maps"
        " profile={params.profile} 'configs={params.configs}' runs.root={params.runs_root}"
        " 'runs.seeds={params.seeds}' clip_len={params.clip_len} {params.data} {params.sim}"
        " device={params.device} out_dir={params.out_dir} {params.hydra} > {log} 2>&1"
