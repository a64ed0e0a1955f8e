from workflow.actuator.entry import write_response
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_response(
    list(snakemake.input.shards),
    snakemake.output[0],
    fea=snakemake.wildcards.fea,  # noqa: F821
    sweep_cfg=p.sweep,
    config_slice=p.config_slice,
    rule=snakemake.rule,
)  # noqa: F821
