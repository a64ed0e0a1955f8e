from workflow.fea_check.entry_standalone import write_standalone_exercise
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
write_standalone_exercise(
    snakemake.wildcards.exercise,  # noqa: F821
    plan_nc=i.plan,
    out_nc=snakemake.output.nc,  # noqa: F821
    fea_cfg=p.fea_check,
    actuator_cfg=p.actuator,
    cascade_cfg=p.cascade,
    config_slice=p.config_slice,
    surrogate_2d=i.get("surrogate_2d"),
    surrogate_3d=i.get("surrogate_3d"),
    rule=snakemake.rule,  # noqa: F821
)
