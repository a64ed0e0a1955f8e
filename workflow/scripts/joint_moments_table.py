from workflow.musculoskeletal.entry import write_moments_from_table
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_moments_from_table(snakemake.input.ccd, snakemake.input.table, snakemake.output[0], rule=snakemake.rule)  # noqa: F821
