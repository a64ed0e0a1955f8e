from workflow.musculoskeletal.entry import write_joint_loads
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p, i = snakemake.params, snakemake.input  # noqa: F821
write_joint_loads(
    snakemake.wildcards.patient,
    p.patient,
    i.ccd,
    i.moments,
    i.rsm,  # noqa: F821
    snakemake.output.loads,
    p.exercises,
    p.anthropometry,  # noqa: F821
    p.prediction_alpha,
    p.config_slice,
    rule=snakemake.rule,
    plot=snakemake.output.plot,  # noqa: F821
    msk_study=i.get("msk_study"),
    model_osim=i.get("model"),
    tolerance=p.tolerance,
    scaling=p.scaling,
)
