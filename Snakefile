# ViTacTip sliding palpation: the whole paper as one DAG. Rules live in workflow/rules/<stage>.smk.
#   snakemake --cores 2                    quick profile (CPU, minutes)
#   snakemake --workflow-profile workflow/profiles/paper   paper profile (one H100)


include: "workflow/rules/common.smk"


rule all:
    default_target: True
    input:
        [],
