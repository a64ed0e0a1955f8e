
from workflow.plots_report import plot_moment_angle
from workflow.scripts._common import setup_logging
from workflow.provenance import open_result

setup_logging(snakemake)  # noqa: F821
plot_moment_angle(open_result(snakemake.input.moments), snakemake.output[0])  # noqa: F821
