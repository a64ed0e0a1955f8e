from workflow.fidelity.entry_check import write_check_study
from workflow.scripts._common import setup_logging

setup_logging(snakemake)  # noqa: F821
p, i = snakemake.params, snakemake.input  # noqa: F821
write_check_study(
    snakemake.output[0],
    exercises=p.check["exercises"],
    h_mm=p.check["h_mm"],  # noqa: F821
    patient_name=snakemake.wildcards.patient,
    patient=p.patient,
    plan_nc=i.plan,  # noqa: F821
    joint_loads_nc=i.joint_loads,
    moments_nc=i.moments,
    ccd_nc=i.ccd,
    surrogate_2d=i.surrogate_2d,
    surrogate_3d=i.surrogate_3d,
    fea_cfg=p.fea_check,
    actuator_cfg=p.actuator,
    cascade_cfg=p.cascade,
    anthropometry=p.anthropometry,
    unit_model_cfg=p.unit_model,
    config_slice=p.config_slice,
    search=p.check.get("search", "coarsest_first"),  # the schema default
    tolerance_deg=p.tolerance_deg,
    penetration_bound_mm=p.penetration_bound_mm,
    rule=snakemake.rule,
)  # noqa: F821
