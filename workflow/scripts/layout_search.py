from workflow.actuator.pressure_limit import material_limit
from workflow.actuator.surrogates import load_surrogate
from workflow.actuator.unit_model import UnitModel
from workflow.layout.entry import write_layout_search
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
unit = UnitModel.from_surrogate(load_surrogate(i.unit_response), **p.unit_model)
write_layout_search(
    snakemake.wildcards.patient,  # noqa: F821
    p.patient,
    unit,
    ccd_nc=i.ccd,
    moments_nc=i.moments,
    joint_loads_nc=i.joint_loads,
    cascade_cfg=p.cascade,
    anthropometry=p.anthropometry,
    layout_cfg=p.layout,
    out_nc=snakemake.output.nc,  # noqa: F821
    config_slice=p.config_slice,
    calibration_nc=i.get("calibration"),
    material_limit=material_limit(p.pressure_limit),
    rule=snakemake.rule,  # noqa: F821
)
