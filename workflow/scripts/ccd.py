from workflow.doe.entry import write_ccd
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_ccd(snakemake.output[0], snakemake.params.design, rule=snakemake.rule)  # noqa: F821
