from workflow import fem
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
fem.write_unit_check(
    snakemake.output.nc,  # noqa: F821
    snakemake.output.vtu,  # noqa: F821
    snakemake.params.actuator,  # noqa: F821
    rule=snakemake.rule,  # noqa: F821
    config_slice=snakemake.params.config_slice,  # noqa: F821
)
