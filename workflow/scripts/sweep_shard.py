from workflow.scripts._common import setup_logging
from workflow.sweep import write_shard

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_shard(snakemake.output[0], fea=snakemake.wildcards.fea, shard=int(snakemake.wildcards.shard),  # noqa: F821
            sweep_cfg=p.sweep, actuator_cfg=p.actuator, config_slice=p.config_slice, rule=snakemake.rule)  # noqa: F821
