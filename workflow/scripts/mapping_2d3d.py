from workflow.actuator.entry import write_mapping
from workflow.actuator.pressure_limit import material_limit
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_mapping(
    snakemake.input.table,
    snakemake.input.surrogate_3d,
    snakemake.input.surrogate_2d,  # noqa: F821
    snakemake.output.nc,
    config_slice=snakemake.params.config_slice,
    rule=snakemake.rule,  # noqa: F821
    plot=snakemake.output.plot,
    material_limit=material_limit(snakemake.params.pressure_limit),
)  # noqa: F821
