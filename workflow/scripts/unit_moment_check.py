from workflow.actuator.entry import write_moment_check
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_moment_check(
    snakemake.output.nc,  # noqa: F821
    snakemake.output.plot,  # noqa: F821
    snakemake.params.actuator,  # noqa: F821
    snakemake.params.unit_model,  # noqa: F821
    rule=snakemake.rule,  # noqa: F821
    config_slice=snakemake.params.config_slice,  # noqa: F821
)
