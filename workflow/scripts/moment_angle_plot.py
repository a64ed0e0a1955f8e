from workflow.common.provenance import open_result
from workflow.musculoskeletal.plots import plot_moment_angle
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
plot_moment_angle(open_result(snakemake.input.moments), snakemake.output[0])  # noqa: F821
