from workflow.fidelity.entry_msk import write_msk_study
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p, i = snakemake.params, snakemake.input  # noqa: F821
write_msk_study(
    snakemake.output[0],
    ccd_nc=i.ccd,
    moments_nc=i.moments,
    rsm_nc=i.rsm,  # noqa: F821
    model_osim=i.get("model"),
    points=p.points,
    exercises=p.exercises,
    scaling_cfg=p.scaling,
    anthropometry=p.anthropometry,
    finger="F3",
    config_slice=p.config_slice,
    rule=snakemake.rule,
)  # noqa: F821
