from workflow.musculoskeletal.entry import write_rsm
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_rsm(
    snakemake.input.ccd,
    snakemake.input.moments,
    snakemake.output.rsm,
    snakemake.params.exercises,  # noqa: F821
    snakemake.params.alpha,
    rule=snakemake.rule,
    plot=snakemake.output.plot,
)  # noqa: F821
