import xarray as xr

from workflow.plots_report import plot_moment_angle
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
plot_moment_angle(xr.load_dataset(snakemake.input.moments), snakemake.output[0])  # noqa: F821
