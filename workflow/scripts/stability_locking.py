from workflow.scripts._common import setup_logging
from workflow.stability.entry_fem import write_locking

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_locking(
    snakemake.output[0],
    locking_cfg=p.locking,
    actuator=p.actuator,
    config_slice=p.config_slice,  # noqa: F821
    rule=snakemake.rule,
)  # noqa: F821
