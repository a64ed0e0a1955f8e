from workflow.scripts._common import setup_logging
from workflow.unit_moment_check import write_moment_check

setup_logging(snakemake)  # noqa: F821
write_moment_check(
    snakemake.output.nc,  # noqa: F821
    snakemake.output.plot,  # noqa: F821
    snakemake.params.actuator,  # noqa: F821
    snakemake.params.unit_model,  # noqa: F821
    rule=snakemake.rule,  # noqa: F821
    config_slice=snakemake.params.config_slice,  # noqa: F821
)
