from workflow.pipeline import write_joint_loads
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
write_joint_loads(snakemake.wildcards.patient, p.patient, snakemake.input.ccd, snakemake.input.moments,  # noqa: F821
                  snakemake.input.rsm, snakemake.output.loads, p.exercises, p.anthropometry,  # noqa: F821
                  p.prediction_alpha, p.config_slice, rule=snakemake.rule, plot=snakemake.output.plot)  # noqa: F821
