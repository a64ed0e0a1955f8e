from workflow.musculoskeletal.entry import write_validation
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_validation(
    snakemake.input.moments,
    snakemake.input.ccd,
    snakemake.params.reference,  # noqa: F821
    snakemake.output.nc,
    snakemake.output.plot,
    rule=snakemake.rule,  # noqa: F821
    config_slice=snakemake.params.config_slice,
)  # noqa: F821
