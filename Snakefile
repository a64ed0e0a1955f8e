# Patient-specific design workflow for a soft pneumatic finger-rehabilitation
# actuator, after Chung & Venter 2024. This file is only a table of contents:
# the config is validated in rules/common.smk, the rules live in rules/*.smk
# (one file per stage, in DAG order) and call the `workflow` package.
from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "report/workflow.rst"


include: "rules/common.smk"
include: "rules/doe.smk"
include: "rules/musculoskeletal.smk"
include: "rules/tracking.smk"
include: "rules/actuator.smk"
include: "rules/cascade.smk"
include: "rules/fea_check.smk"
include: "rules/authors_study.smk"
include: "rules/layout.smk"
include: "rules/fidelity.smk"
include: "rules/stability.smk"
include: "rules/reporting.smk"


rule all:
    default_target: True
    input:
        get_final_output(),
