# Issue 12: the residual loop on the real Silicone slides (docs/slides.md). The sequence set comes
# from rule silicone_sequences (silicone.smk); the twin of the scene is built inside the app.
# Needs common.smk (PY, CONDA_ENV, hydra_dir, twin_mesh, TWIN_ARGS, GPU) and twin.smk (rule mesh).
# In `all` only through the downstream judge (judge.smk; judge.seeds): the profile's judge.twin and
# judge.slide_loop set the twin preset and the size (paper: all trials and frames on the GPU).


rule slide_loop:
    input:
        npz=rules.silicone_sequences.output.npz,
        mesh=twin_mesh(),
        conf=conf_files("slide_loop", {"twin/mesh": config["twin_resolution"]}),
    output:
        csv="results/loop_slides/loop_slides.csv",
        json="results/loop_slides/slide_loop.json",
    params:
        rule="slide_loop",
        py=PY,
        twin=f"{TWIN_ARGS} {JUDGE['twin']} {JUDGE['slide_loop']}".strip(),  # profile's judge: twin preset, size
        stem=lambda wildcards, input: input.npz[: -len(".npz")],
        hydra=lambda wildcards, output: hydra_dir(output.csv),
    resources:
        gpu=GPU,
    log:
        "results/logs/loop/slide_loop.log",
    benchmark:
        "results/benchmarks/slide_loop.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.slide_loop {params.twin}"
        " sequences={params.stem} mesh={input.mesh} out.csv={output.csv} out.json={output.json}"
        " {params.hydra} > {log} 2>&1"
