from workflow.doe.entry import write_scaling_validation
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_scaling_validation(snakemake.input.scaling, snakemake.input.table, snakemake.output[0], rule=snakemake.rule)  # noqa: F821
