from workflow.scripts._common import setup_logging
from workflow.stability.entry import write_stability

setup_logging(snakemake)  # noqa: F821
i, o, p = snakemake.input, snakemake.output, snakemake.params  # noqa: F821
write_stability(
    o.nc,
    responses={"2d": i.response_2d, "3d": i.response_3d},
    unit_check=i.unit_check,
    rays=i.rays,
    locking=i.locking,
    ccd=i.ccd,
    loads=dict(zip(p.patients, i.loads)),
    plans=dict(zip(p.patients, i.plans)),
    actuator=p.actuator,
    stab_cfg=p.stability,
    cascade_surrogate=p.cascade_surrogate,
    config_slice=p.config_slice,
    plots={
        "failures": o.failures,
        "locking": o.locking,
        "penetration": o.penetration,
        "coverage": o.coverage,
        "design": o.design,
    },
    table_html=o.table,
    rule=snakemake.rule,
    fem_cases=list(i.fem_cases),  # noqa: F821
)
