from workflow.musculoskeletal.entry_opensim import write_merged
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_merged(
    snakemake.input.runs,
    snakemake.output[0],
    rule=snakemake.rule,  # noqa: F821
    config_slice=snakemake.params.config_slice,
)  # noqa: F821
