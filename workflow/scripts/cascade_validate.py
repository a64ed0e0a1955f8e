from workflow.cascade.entry import write_cascade_validation
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
i = snakemake.input  # noqa: F821
write_cascade_validation(
    i.plan,
    {"table08": i.table08, "table10": i.table10},
    snakemake.output.nc,  # noqa: F821
    config_slice=snakemake.params.config_slice,
    rule=snakemake.rule,  # noqa: F821
    plot=snakemake.output.plot,
    rel_floor_kpa=snakemake.params.rel_floor_kpa,  # noqa: F821
    table07=i.table07,
    dummy_plan_nc=i.get("dummy_plan"),
)
