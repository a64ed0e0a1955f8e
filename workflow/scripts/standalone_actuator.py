from workflow.fea_check.entry import write_standalone
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
write_standalone(
    snakemake.wildcards.patient,  # noqa: F821
    part_ncs=list(snakemake.input.parts),  # noqa: F821
    out_nc=snakemake.output.nc,  # noqa: F821
    out_png=snakemake.output.plot,  # noqa: F821
    config_slice=snakemake.params.config_slice,  # noqa: F821
    rule=snakemake.rule,  # noqa: F821
)
