from workflow.fea_check.entry_calibration import write_chain_calibration
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
write_chain_calibration(
    p.patient_name,
    p.patient,
    joint_loads_nc=i.joint_loads,
    moments_nc=i.moments,
    ccd_nc=i.ccd,
    surrogate_2d=i.surrogate_2d,
    surrogate_3d=i.surrogate_3d,
    table08_csv=i.table08,
    out_nc=snakemake.output.nc,  # noqa: F821
    out_png=snakemake.output.plot,  # noqa: F821
    calibration_cfg=p.calibration,
    fea_cfg=p.fea_check,
    actuator_cfg=p.actuator,
    cascade_cfg=p.cascade,
    anthropometry=p.anthropometry,
    unit_model_cfg=p.unit_model,
    config_slice=p.config_slice,
    rule=snakemake.rule,  # noqa: F821
)
