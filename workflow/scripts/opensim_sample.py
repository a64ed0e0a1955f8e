from workflow.musculoskeletal.opensim_backend import write_run
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
cfg = snakemake.params.opensim  # noqa: F821
write_run(snakemake.input.model, snakemake.input.scaling, int(snakemake.wildcards.run),  # noqa: F821
          snakemake.output[0], fingers=cfg["fingers"], angle_step_deg=cfg["angle_step_deg"],  # noqa: F821
          activations=cfg["activations"], include_gravity=cfg["include_gravity"],
          rule=snakemake.rule, config_slice=snakemake.params.config_slice)  # noqa: F821
