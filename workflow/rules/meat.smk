# The real Meat set rebuilt from the A-to-C prediction viewer (SPEC §13.5), and the summary table
# of every real set. Needs common.smk (PHOTOS, VIDEOS, hydra_dir); data_summary also needs the
# Silicone set (rule silicone_set, silicone.smk).


rule meat_set:
    input:
        video=f"{VIDEOS}/predictions_sim_to_meat.mp4",
        rest_photo=f"{PHOTOS}/sensor_default_state.png",
        conf=conf_files("meat"),
    output:
        npz="results/data/meat/meat.npz",
        json="results/data/meat/meat.json",
        png=report("results/data/meat/meat_overview.png", caption="../report/meat_overview.rst", category="Real data"),
        pdf="results/data/meat/meat_overview.pdf",
    params:
        rule="meat_set",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.npz),
        figure=lambda wildcards, output: output.png[: -len(".png")],
    log:
        "results/logs/data/meat_set.log",
    benchmark:
        "results/benchmarks/meat_set.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.meat"
        " video={input.video} template_photo={input.rest_photo}"
        " out.npz={output.npz} out.json={output.json} out.figure={params.figure}"
        " {params.hydra} > {log} 2>&1"


rule data_summary:
    input:
        silicone=rules.silicone_set.output.npz,
        meat=rules.meat_set.output.npz,
        conf=conf_files("data_summary"),
    output:
        csv=report("results/data/summary.csv", caption="../report/data_summary.rst", category="Real data"),
        md="results/data/summary.md",
    params:
        rule="data_summary",
        py=PY,
        hydra=lambda wildcards, output: hydra_dir(output.csv),
    log:
        "results/logs/data/data_summary.log",
    benchmark:
        "results/benchmarks/data_summary.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.data_summary"
        " datasets.silicone.path={input.silicone}"
        " datasets.meat.path={input.meat} out.csv={output.csv} out.md={output.md}"
        " {params.hydra} > {log} 2>&1"
