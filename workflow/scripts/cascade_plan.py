from workflow.actuator.pressure_limit import material_limit
from workflow.actuator.sampled_region import SampledRegion
from workflow.actuator.surrogates import load_surrogate
from workflow.actuator.unit_model import UnitModel
from workflow.cascade.entry import write_cascade_plan
from workflow.common.provenance import open_result
from workflow.layout.units import chosen_units, top_units
from workflow.scripts._common import setup_logging

log = setup_logging(snakemake)  # noqa: F821
p = snakemake.params  # noqa: F821
i = snakemake.input  # noqa: F821
cascade = dict(p.cascade)
if "layout" in i.keys():
    # a designed layout: the one the layout design chose, or the search's rank-k candidate (its FEA check)
    lay = open_result(i.layout)
    cascade["units_per_group"] = chosen_units(lay) if "chosen_units" in lay else top_units(lay, int(p.layout_rank))
    log.info("units per group from %s: %s", i.layout, cascade["units_per_group"])
surrogate = load_surrogate(i.unit_response)
unit = UnitModel.from_surrogate(surrogate, **p.unit_model)
# which surrogate the plan stands on, and why (fidelity.auto or the CV rule)
notes = {
    "fidelity": f"{surrogate.fea} {surrogate.regressor}",
    "fidelity_reason": surrogate.meta.get("fidelity_reason", ""),
}
# the sweep the surrogate was fitted on: planned pressures outside its converged samples are flagged
region = SampledRegion.from_response(open_result(i.response)) if "response" in i.keys() else None
write_cascade_plan(
    snakemake.wildcards.patient,
    p.patient,
    unit,
    ccd_nc=i.ccd,
    moments_nc=i.moments,  # noqa: F821
    joint_loads_nc=i.joint_loads,
    out_nc=snakemake.output.plan,  # noqa: F821
    out_png=snakemake.output.plot,
    cascade_cfg=cascade,
    anthropometry=p.anthropometry,
    config_slice=p.config_slice,
    rule=snakemake.rule,  # noqa: F821
    sampled_region=region,
    notes=notes,
    calibration_nc=i.get("calibration"),
    material_limit=material_limit(p.pressure_limit),
)
