from workflow.layout.entry import write_layout_choice
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
i = snakemake.input  # noqa: F821
write_layout_choice(
    i.search,
    list(i.checks),
    out_nc=snakemake.output.nc,  # noqa: F821
    out_png=snakemake.output.plot,  # noqa: F821
    config_slice=snakemake.params.config_slice,  # noqa: F821
    rule=snakemake.rule,  # noqa: F821
)
