from workflow.layout.entry_choice import write_layout_choice
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
i = snakemake.input  # noqa: F821
write_layout_choice(
    i.search,
    list(i.checks),
    out_nc=snakemake.output.nc,  # noqa: F821
    out_png=snakemake.output.plot,  # noqa: F821
    config_slice=snakemake.params.config_slice,  # noqa: F821
    default_plan_nc=i.get("default_plan"),
    default_check_nc=i.get("default_check"),
    rule=snakemake.rule,  # noqa: F821
)
