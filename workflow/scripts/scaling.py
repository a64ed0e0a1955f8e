from workflow.doe.entry import write_scaling
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_scaling(
    snakemake.input.ccd,
    snakemake.output[0],
    snakemake.params.scaling,  # noqa: F821
    snakemake.params.anthropometry,
    rule=snakemake.rule,
)  # noqa: F821
