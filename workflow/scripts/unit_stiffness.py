from workflow.actuator.entry import write_unit_stiffness
from workflow.scripts._common import setup_logging

setup_logging(snakemake)
write_unit_stiffness(
    snakemake.output.nc,
    snakemake.output.plot,
    snakemake.params.actuator,
    snakemake.input.surrogate_2d,
    snakemake.params.unit_model,
    rule=snakemake.rule,
    config_slice=snakemake.params.config_slice,
)
