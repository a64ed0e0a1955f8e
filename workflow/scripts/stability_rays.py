from workflow.scripts._common import setup_logging
from workflow.stability.entry_fem import write_rays

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_rays(
    snakemake.output[0],
    rays_cfg=p.rays,
    actuator=p.actuator,
    config_slice=p.config_slice,  # noqa: F821
    rule=snakemake.rule,
)  # noqa: F821
