# Real flat-tip photos -> the measured marker set (docs/measured_format.md), overlay figure and summary.
# The rest template is recomputed from sensor_default_state.png on the fly (~0.2 s), so it has no rule.


rule measured_photos:
    input:
        photos=expand(
            f"{PHOTOS}/{{photo}}",
            photo=[
                "sensor_default_state.png",
                "press_press_depth=0_angle=10_slide_length=50_timestamp=2025-08-30-21-23-00.jpg",
                "press_press_depth=4_angle=10_slide_length=50_timestamp=2025-08-30-21-23-31.jpg",
                "twist_z_press_depth=4_angle=90_slide_length=50_timestamp=2025-08-30-21-26-57.jpg",
                "twist_x_press_depth=2_angle=20_slide_length=50_timestamp=2025-08-30-21-34-40.jpg",
                "slide_press_depth=3_angle=10_slide_length=50_timestamp=2025-08-30-21-49-26.png",
            ],
        ),
        conf=conf_files("photos"),
    output:
        npz="results/data/photos/measured_photos.npz",
        json="results/data/photos/measured_photos.json",
        summary="results/data/photos/photo_summary.json",
        csv="results/data/photos/photo_summary.csv",
        png=report(
            "results/data/photos/markers_overlay.png",
            caption="../report/markers_overlay.rst",
            category="Real data",
        ),
        pdf="results/data/photos/markers_overlay.pdf",
    params:
        rule="measured_photos",
        hydra=lambda wildcards, output: hydra_dir(output.npz),
        outdir=lambda wildcards, output: Path(output.npz).parent,
        py=PY,
        photos_dir=lambda wildcards, input: Path(input.photos[0]).parent,
    log:
        "results/logs/data/measured_photos.log",
    benchmark:
        "results/benchmarks/measured_photos.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.photos"
        " photos_dir={params.photos_dir} out.dir={params.outdir}"
        " {params.hydra} > {log} 2>&1"
