from workflow.common.fidelity_choice import check_choice
from workflow.common.provenance import open_result
from workflow.fea_check.entry import write_fea_check
from workflow.scripts._common import setup_logging

log = setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
o = snakemake.output  # noqa: F821
# fidelity.auto: the coarsest mesh whose angles the check study found within the tolerance
study = open_result(i.check_study) if "check_study" in i.keys() else None
h, why = check_choice(study, p.tolerance_deg, p.fea_check["h_actuator_mm"], p.fea_check["penetration_bound_mm"])
log.info("FEA check mesh: h = %g mm: %s", h, why)
fea_cfg = dict(p.fea_check, h_actuator_mm=h, h_finger_mm=h) if study is not None else p.fea_check
write_fea_check(
    snakemake.wildcards.patient,
    p.patient,
    plan_nc=i.plan,
    joint_loads_nc=i.joint_loads,  # noqa: F821
    moments_nc=i.moments,
    ccd_nc=i.ccd,
    out_nc=o.nc,
    out_vtu=list(o.vtu),
    out_png=o.plot,
    fea_cfg=fea_cfg,
    actuator_cfg=p.actuator,
    cascade_cfg=p.cascade,
    anthropometry=p.anthropometry,
    config_slice={"config": p.config_slice, "h_mm": h},
    surrogate_2d=i.get("surrogate_2d"),
    surrogate_3d=i.get("surrogate_3d"),
    unit_model_cfg=p.unit_model,
    unit_stiffness_nc=i.get("unit_stiffness"),
    rule=snakemake.rule,  # noqa: F821
    notes={"fidelity": f"h = {h:g} mm", "fidelity_reason": why},
)
