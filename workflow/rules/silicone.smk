# The real Silicone set rebuilt from the annotation video (SPEC §13.4), and the cross-check of its
# labels against the A-to-B prediction viewer's Ground Truth panel (SPEC §13.5).
# Needs common.smk (PHOTOS, VIDEOS, hydra_dir).


rule silicone_set:
    input:
        video=f"{VIDEOS}/dataset_annotations_silicone.mp4",
        rest_photo=f"{PHOTOS}/sensor_default_state.png",
        conf=conf_files("silicone"),
    output:
        npz="results/data/silicone/silicone.npz",
        json="results/data/silicone/silicone.json",
        png=report("results/data/silicone/silicone_overview.png", caption="../report/silicone_overview.rst", category="Real data"),
        pdf="results/data/silicone/silicone_overview.pdf",
    params:
        rule="silicone_set",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.npz),
        figure=lambda wildcards, output: output.png[: -len(".png")],
    # the videos tracked in parallel: the slide loop, the paper profile's critical path, waits for this set
    threads: 4
    # ... and so do the trainings' test sets. First: on 2 cores its threads need both, and behind the residual loop
    # (which takes one core for ~4 min in the quick profile) it waited for the loop's end with one core idle
    priority: 20
    log:
        "results/logs/data/silicone_set.log",
    benchmark:
        "results/benchmarks/silicone_set.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.silicone task=set"
        " video={input.video} template_photo={input.rest_photo}"
        " out.npz={output.npz} out.json={output.json} out.figure={params.figure} workers={threads}"
        " {params.hydra} > {log} 2>&1"


rule silicone_check:
    input:
        npz=rules.silicone_set.output.npz,
        video=f"{VIDEOS}/predictions_sim_to_silicone.mp4",
        conf=conf_files("silicone"),
    output:
        json="results/data/silicone/label_agreement.json",
    params:
        rule="silicone_check",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.json),
    log:
        "results/logs/data/silicone_check.log",
    benchmark:
        "results/benchmarks/silicone_check.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.silicone task=check"
        " out.npz={input.npz} prediction_video={input.video}"
        " out.agreement={output.json} {params.hydra} > {log} 2>&1"


# Issue 12: the Silicone set as measured sequences (markers + reconstructed poses + photo vessels).
rule silicone_sequences:
    input:
        npz=rules.silicone_set.output.npz,
        rest_photo=f"{PHOTOS}/sensor_default_state.png",
        labels="data/reference/phantom/phantom-labels-vgg.json",
        conf=conf_files("silicone_sequences"),
    output:
        npz="results/data/silicone/silicone_sequences.npz",
        json="results/data/silicone/silicone_sequences.json",
    params:
        rule="silicone_sequences",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.npz),
        stem=lambda wildcards, output: output.npz[: -len(".npz")],
    log:
        "results/logs/data/silicone_sequences.log",
    benchmark:
        "results/benchmarks/silicone_sequences.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.silicone_sequences"
        " silicone={input.npz} template_photo={input.rest_photo}"
        " out.sequences={params.stem} {params.hydra} > {log} 2>&1"
