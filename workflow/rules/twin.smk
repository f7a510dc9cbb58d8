# The twin's FEM mesh, built once per resolution and cached (conf/twin/mesh/<resolution>.yaml).


rule mesh:
    input:
        # the app composes twin=quick too but reads only twin.mesh
        conf=lambda wildcards: ["conf/mesh.yaml", f"conf/twin/mesh/{wildcards.resolution}.yaml"],
    output:
        mesh="results/twin/mesh_{resolution}.npz",
        stats="results/twin/mesh_{resolution}.json",
    wildcard_constraints:
        resolution="[a-z]+",
    params:
        rule="mesh",
        py=PY,
        # one Hydra job log per resolution, not a shared results/twin/mesh.log
        hydra=lambda wildcards, output: hydra_dir(output.mesh)
        + f" hydra.job.name=mesh_{wildcards.resolution}",
    log:
        "results/logs/twin/mesh_{resolution}.log",
    benchmark:
        f"results/benchmarks/mesh/mesh_{{resolution}}.tsv",
    conda:
        CONDA_ENV
    shell:
        "SNAKEMAKE_RULE={params.rule} {params.py} palpation.apps.mesh twin/mesh={wildcards.resolution}"
        " out.mesh={output.mesh} out.stats={output.stats} {params.hydra} > {log} 2>&1"
