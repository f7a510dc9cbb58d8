# Twin trajectories (palpation.apps.simulate), their rendering and the twin benchmark.
# Needs common.smk (hydra_dir, twin_mesh, TWIN_ARGS, GPU) and twin.smk (rule mesh).
# Output format: docs/sim_format.md.

CANONICAL = ["press", "twist_z", "twist_x", "slide"]
# conf/ files of palpation.apps.simulate; the dataset group (draw options) matters to set=randomised only
SIM_CONF = conf_files("simulate", {"twin/mesh": config["twin_resolution"], "dataset": None})


rule simulate_canonical:
    input:
        mesh=twin_mesh(),
        conf=SIM_CONF,
    output:
        manifest="results/twin/canonical/manifest.json",
        npz=expand("results/twin/canonical/{kind}.npz", kind=CANONICAL),
    params:
        rule="simulate_canonical",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.manifest),
        outdir=lambda wildcards, output: Path(output.manifest).parent,
        twin=TWIN_ARGS,
    resources:
        gpu=GPU,
    log:
        "results/logs/twin/simulate_canonical.log",
    benchmark:
        "results/benchmarks/simulate_canonical.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.simulate"
        " set=canonical {params.twin} mesh={input.mesh}"
        " out.dir={params.outdir} {params.hydra} > {log} 2>&1"


rule simulate_vessel_slide:
    input:
        mesh=twin_mesh(),
        conf=SIM_CONF,
    output:
        manifest="results/twin/vessel_slide/manifest.json",
        npz="results/twin/vessel_slide/vessel_slide.npz",
    params:
        rule="simulate_vessel_slide",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.manifest),
        outdir=lambda wildcards, output: Path(output.manifest).parent,
        twin=TWIN_ARGS,
    resources:
        gpu=GPU,
    log:
        "results/logs/twin/simulate_vessel_slide.log",
    benchmark:
        "results/benchmarks/simulate_vessel_slide.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.simulate"
        " set=vessel_slide {params.twin} mesh={input.mesh}"
        " out.dir={params.outdir} {params.hydra} > {log} 2>&1"


rule render_twin:
    input:
        canonical=rules.simulate_canonical.output.manifest,
        slide=rules.simulate_vessel_slide.output.manifest,
        conf=conf_files("render_twin"),
    output:
        png=report("results/twin/render/markers.png", caption="../report/twin_render.rst", category="Twin"),
        pdf="results/twin/render/markers.pdf",
        mp4=expand(
            "results/twin/render/{name}.mp4",
            name=[f"canonical_{k}" for k in CANONICAL] + ["vessel_slide_vessel_slide"],
        ),
    params:
        rule="render_twin",
        py=PY,
        outdir=lambda wildcards, output: Path(output.png).parent,
        hydra=lambda wildcards, output: hydra_dir(output.png),
    log:
        "results/logs/twin/render_twin.log",
    benchmark:
        "results/benchmarks/render_twin.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.render_twin"
        " 'manifests=[{input.canonical},{input.slide}]' out.dir={params.outdir} {params.hydra} > {log} 2>&1"


rule bench_twin:
    input:
        meshes=[twin_mesh(resolution) for resolution in ("coarse", "reference")],
    output:
        json="results/bench/twin.json",
    params:
        py=PY,
        # CPU: ~20 s of timed frames per point, extrapolated (the JSON's field names say so);
        # a GPU times every point's full 398-frame batch
        budget="--budget-s 20" if config["device"] == "cpu" else "",
        device=config["device"],
        mesh_dir=lambda wildcards, input: Path(input.meshes[0]).parent,
    resources:
        gpu=GPU,
    log:
        "results/logs/bench/twin.log",
    benchmark:
        "results/benchmarks/bench_twin.tsv",
    conda:
        CONDA_ENV
    shell:
        "{params.py} palpation.twin.benchmark --device {params.device} --mesh-dir {params.mesh_dir}"
        " {params.budget} --out {output.json} > {log} 2>&1"
